//! ISO 16610-21 Gaussian profile filter (phase correct, 50 % transmission at the cut-off), with
//! the end effects handled by the ISO 16610-28 first-order moment criterion.
//!
//! The weighting function is s(x) = 1/(α·λc)·exp(−π·(x/(α·λc))²), α = sqrt(ln 2 / π), truncated
//! at ±λc (the tail beyond holds about 1e-7 of the weight) and sampled at the profile pitch.
//!
//! **Ends.** The SJ series exports the evaluation length only, so the kernel runs off the data
//! within λc of each end. ISO 16610-28 corrects this by choosing end weights that keep the
//! kernel's moments: we apply the first-order moment criterion, i.e. at every point the mean line
//! is the value at that point of the Gaussian-weighted least-squares straight line over the
//! points available. Where the full kernel fits (the interior), its first moment is zero and the
//! result is exactly the plain Gaussian convolution; near the ends a tilted profile keeps an
//! unbiased mean line instead of bending towards the inside values.
//!
//! Depends on [`super::MetrologyError`] only.

use super::{check_heights, check_pitch, MetrologyError};

/// α = sqrt(ln 2 / π), the constant that puts 50 % transmission at the cut-off.
pub const ALPHA: f64 = 0.469_718_639_349_825_8;

/// Name of the end-effect treatment, as written into recipes.
pub const END_TREATMENT: &str =
    "ISO 16610-28 first-order moment criterion (Gaussian-weighted local line at the ends)";

/// The sampled, truncated (±`cutoff_mm`) and unnormalised Gaussian weights w_k for offsets
/// k = 0, 1, …, half (the kernel is symmetric), for a profile of `points` points: taps farther
/// than `points` samples meet no data, so half is at most `points`. Without that bound a pitch
/// far below the cut-off (1e-9 mm against 0.8 mm: 8e8 taps) would ask for more memory than a
/// station has, whatever the profile's length.
fn weights(cutoff_mm: f64, pitch_mm: f64, points: usize) -> Vec<f64> {
    // The small epsilon keeps e.g. 0.8 / 0.0005 at 1600 despite rounding of the quotient.
    let taps = (cutoff_mm / pitch_mm + 1e-9).floor();
    let half = if taps < points as f64 {
        taps as usize
    } else {
        points
    };
    let scale = ALPHA * cutoff_mm;
    (0..=half)
        .map(|k| {
            let u = k as f64 * pitch_mm / scale;
            (-std::f64::consts::PI * u * u).exp()
        })
        .collect()
}

/// Kernels up to this half-width (in samples) are summed directly: the λs filter (a few taps)
/// and short cut-offs, where a transform would cost more than the sums.
const DIRECT_MAX_HALF: usize = 64;

/// The Gaussian mean line (low-pass) of `heights_um` sampled at `pitch_mm`, cut-off `cutoff_mm`,
/// ends by the first-order moment criterion. Also serves as the λs filter (cut-off λs in mm).
///
/// Short kernels are summed directly ([`mean_line_direct`], O(n·k) for k taps); long ones (λc
/// at a fine pitch: ±1600 taps for 0.8 mm at 0.5 µm) go through [`mean_line_fft`], which
/// computes the same sums in O(n log n). Both give the same mean line up to rounding (a test
/// holds them to 1e-12 of the profile's range).
pub fn gaussian_mean_line(
    heights_um: &[f64],
    pitch_mm: f64,
    cutoff_mm: f64,
) -> Result<Vec<f64>, MetrologyError> {
    check_pitch(pitch_mm)?;
    if !(cutoff_mm.is_finite() && cutoff_mm > 0.0) {
        return Err(MetrologyError::BadCutoff { cutoff_mm });
    }
    check_heights(heights_um)?;
    let w = weights(cutoff_mm, pitch_mm, heights_um.len());
    if w.len() - 1 <= DIRECT_MAX_HALF {
        Ok(mean_line_direct(heights_um, &w))
    } else {
        Ok(mean_line_fft(heights_um, &w))
    }
}

/// The mean line by direct summation over the taps `w` (offsets 0..=half): the definition,
/// and the reference the transform is checked against.
fn mean_line_direct(heights_um: &[f64], w: &[f64]) -> Vec<f64> {
    let n = heights_um.len();
    let half = w.len() - 1;
    let mut out = Vec::with_capacity(n);
    // Interior points, where the whole kernel fits: s1 = 0, so the value is the plain weighted
    // mean, summed pairwise over the symmetric taps (about a fifth of the work of the general
    // moment sums below, which the ends still need).
    let full: f64 = w.first().copied().unwrap_or(0.0) + 2.0 * w.iter().skip(1).sum::<f64>();
    for i in 0..n {
        if i >= half && i + half < n {
            let mut t0 = w.first().copied().unwrap_or(0.0) * heights_um[i];
            for (k, wk) in w.iter().enumerate().skip(1) {
                t0 += wk * (heights_um[i - k] + heights_um[i + k]);
            }
            out.push(t0 / full);
            continue;
        }
        let lo = i.saturating_sub(half);
        let hi = (i + half).min(n.saturating_sub(1));
        let (mut s0, mut s1, mut s2, mut t0, mut t1) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (j, &z) in heights_um.iter().enumerate().take(hi + 1).skip(lo) {
            let d = j as f64 - i as f64;
            let wk = w.get(i.abs_diff(j)).copied().unwrap_or(0.0);
            s0 += wk;
            s1 += wk * d;
            s2 += wk * d * d;
            t0 += wk * z;
            t1 += wk * d * z;
        }
        out.push(local_line_value(s0, s1, s2, t0, t1));
    }
    out
}

/// The value at the point of the weighted least-squares line over its window, from the
/// window's moment sums: Σw, Σw·d, Σw·d², Σw·z, Σw·d·z (d = offset from the point).
#[inline]
fn local_line_value(s0: f64, s1: f64, s2: f64, t0: f64, t1: f64) -> f64 {
    let det = s0 * s2 - s1 * s1;
    // Symmetric window: s1 = 0 and the line's value is the plain weighted mean.
    if s1 == 0.0 || det.abs() <= f64::EPSILON * s0 * s2 {
        t0 / s0
    } else {
        (s2 * t0 - s1 * t1) / det
    }
}

/// What a transform-based filter of one profile length, pitch and cut-off needs besides the
/// data: the FFT plans, the spectra of the two kernels, and the prefix sums of the taps' moments.
struct Prepared {
    /// (transform length, taps, the taps' bits): the key this preparation serves.
    key: (usize, Vec<u64>),
    forward: std::sync::Arc<dyn realfft::RealToComplex<f64>>,
    inverse: std::sync::Arc<dyn realfft::ComplexToReal<f64>>,
    /// Spectrum of h0(k) = w(|k|) (gives Σ w·z over each window).
    even: Vec<Complex64>,
    /// Spectrum of h1(k) = −k·w(|k|) (gives Σ w·d·z, d = j − i).
    odd: Vec<Complex64>,
    /// Prefix sums over k = 0..=m of w(k), k·w(k), k²·w(k).
    p0: Vec<f64>,
    p1: Vec<f64>,
    p2: Vec<f64>,
}

use realfft::num_complex::Complex64;

thread_local! {
    /// The last preparation on this thread: a scan's lines share length, pitch and cut-off.
    static PREPARED: std::cell::RefCell<Option<Prepared>> = const { std::cell::RefCell::new(None) };
}

/// The smallest even length ≥ `min` whose only prime factors are 2, 3 and 5 (fast for the FFT).
pub(super) fn fft_len(min: usize) -> usize {
    let mut len = min.max(2);
    loop {
        let mut m = len;
        for p in [2, 3, 5] {
            while m % p == 0 {
                m /= p;
            }
        }
        if m == 1 && len % 2 == 0 {
            return len;
        }
        len += 1;
    }
}

fn prepare(len: usize, w: &[f64]) -> Prepared {
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let forward = planner.plan_fft_forward(len);
    let inverse = planner.plan_fft_inverse(len);
    let half = w.len() - 1;
    let spectrum = |h: &mut Vec<f64>| {
        let mut out = forward.make_output_vec();
        // Lengths come from the plan itself, so the transform cannot refuse them.
        let _ = forward.process(h, &mut out);
        out
    };
    let mut h0 = vec![0.0; len];
    let mut h1 = vec![0.0; len];
    for (k, &wk) in w.iter().enumerate() {
        h0[k] = wk;
        h1[k] = -(k as f64) * wk;
        if k > 0 {
            h0[len - k] = wk;
            h1[len - k] = k as f64 * wk;
        }
    }
    let (mut p0, mut p1, mut p2) = (
        Vec::with_capacity(half + 1),
        Vec::with_capacity(half + 1),
        Vec::with_capacity(half + 1),
    );
    let (mut a0, mut a1, mut a2) = (0.0, 0.0, 0.0);
    for (k, &wk) in w.iter().enumerate() {
        let d = k as f64;
        a0 += wk;
        a1 += wk * d;
        a2 += wk * d * d;
        p0.push(a0);
        p1.push(a1);
        p2.push(a2);
    }
    Prepared {
        key: (len, w.iter().map(|x| x.to_bits()).collect()),
        even: spectrum(&mut h0),
        odd: spectrum(&mut h1),
        forward,
        inverse,
        p0,
        p1,
        p2,
    }
}

/// The mean line with the window sums computed as two convolutions by FFT: Σ w·z and Σ w·d·z
/// over each point's window are the convolutions of the profile (zero outside it) with the even
/// kernel w(|k|) and the odd kernel −k·w(|k|), and the windows' moment sums Σw, Σw·d, Σw·d²
/// come from prefix sums of the taps. The end treatment is [`mean_line_direct`]'s, unchanged;
/// only the order of the additions differs. The profile's mean is taken out before the
/// transform and added back (the filter keeps constants), so the rounding of the transform
/// scales with the roughness, not with the height offset.
fn mean_line_fft(heights_um: &[f64], w: &[f64]) -> Vec<f64> {
    let n = heights_um.len();
    let half = w.len() - 1;
    if n == 0 {
        return Vec::new();
    }
    // A circular convolution of this length wraps no tap onto the profile (needs n + half).
    let len = fft_len(n + half);
    PREPARED.with(|cell| {
        let mut cell = cell.borrow_mut();
        let same = |p: &Prepared| {
            p.key.0 == len
                && p.key.1.len() == w.len()
                && p.key.1.iter().zip(w).all(|(a, b)| *a == b.to_bits())
        };
        let prep: &Prepared = match &mut *cell {
            Some(p) if same(p) => p,
            slot => slot.insert(prepare(len, w)),
        };
        let offset = heights_um.iter().sum::<f64>() / n as f64;
        let mut input = vec![0.0; len];
        for (x, &z) in input.iter_mut().zip(heights_um) {
            *x = z - offset;
        }
        let mut spectrum = prep.forward.make_output_vec();
        let _ = prep.forward.process(&mut input, &mut spectrum);
        let scale = 1.0 / len as f64;
        let convolve = |kernel: &[Complex64]| {
            let mut product: Vec<Complex64> = spectrum
                .iter()
                .zip(kernel)
                .map(|(a, b)| a * b * scale)
                .collect();
            // Spectra of real signals: the first and last bins are real.
            product[0].im = 0.0;
            if let Some(last) = product.last_mut() {
                last.im = 0.0;
            }
            let mut out = vec![0.0; len];
            let _ = prep.inverse.process(&mut product, &mut out);
            out.truncate(n);
            out
        };
        let t0 = convolve(&prep.even);
        let t1 = convolve(&prep.odd);
        let full: f64 = w[0] + 2.0 * w.iter().skip(1).sum::<f64>();
        let w0 = w[0];
        (0..n)
            .map(|i| {
                let a = i.min(half);
                let b = (n - 1 - i).min(half);
                let value = if a == half && b == half {
                    t0[i] / full
                } else {
                    let s0 = prep.p0[a] + prep.p0[b] - w0;
                    let s1 = prep.p1[b] - prep.p1[a];
                    let s2 = prep.p2[a] + prep.p2[b];
                    local_line_value(s0, s1, s2, t0[i], t1[i])
                };
                value + offset
            })
            .collect()
    })
}

/// The roughness profile R = P − W of a primary profile P, W its λc mean line, µm.
pub fn roughness(
    heights_um: &[f64],
    pitch_mm: f64,
    cutoff_mm: f64,
) -> Result<Vec<f64>, MetrologyError> {
    let mean_line_um = gaussian_mean_line(heights_um, pitch_mm, cutoff_mm)?;
    Ok(heights_um
        .iter()
        .zip(&mean_line_um)
        .map(|(p, w)| p - w)
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rough profile with a tilt, an offset and waves of several lengths (µm).
    fn profile(n: usize, offset: f64, tilt: f64) -> Vec<f64> {
        let mut s: u64 = 0x2545_F491_4F6C_DD1D;
        (0..n)
            .map(|i| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let noise = (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                let x = i as f64;
                offset + tilt * x + 0.8 * (x * 0.004).sin() + 0.3 * (x * 0.05).cos() + 0.2 * noise
            })
            .collect()
    }

    #[test]
    fn transform_equals_direct_sums_to_1e_12_of_the_range() {
        // Profiles longer and shorter than the kernel (half = 1600 taps for 0.8 mm at 0.5 µm;
        // 160 for 0.08 mm), with offsets and tilts that exercise the end treatment.
        for (n, cutoff, offset, tilt) in [
            (8000, 0.8, 0.0, 0.0),
            (8000, 0.8, 10.0, 1e-3),
            (9601, 0.8, -250.0, -2e-4),
            (3000, 0.8, 0.0, 5e-4),
            (1000, 0.8, 3.0, 0.0),
            (2, 0.8, 1.0, 0.5),
            (1, 0.8, 1.0, 0.0),
            (5000, 0.08, 0.0, 1e-3),
            (321, 0.08, 0.0, 1e-3),
        ] {
            let z = profile(n, offset, tilt);
            let w = weights(cutoff, 0.0005, usize::MAX);
            assert!(w.len() - 1 > DIRECT_MAX_HALF);
            let direct = mean_line_direct(&z, &w);
            let fft = mean_line_fft(&z, &w);
            let range = z.iter().copied().fold(f64::MIN, f64::max)
                - z.iter().copied().fold(f64::MAX, f64::min);
            let scale = range.max(z.iter().map(|v| v.abs()).fold(0.0, f64::max) * 1e-3);
            for (i, (a, b)) in direct.iter().zip(&fft).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-12 * scale,
                    "n {n}, λc {cutoff}, point {i}: direct {a} vs transform {b}"
                );
            }
        }
    }

    #[test]
    fn long_kernels_keep_lines_and_constants_at_the_ends() {
        // The first-order moment criterion reproduces a straight line everywhere, ends included.
        let z: Vec<f64> = (0..5000).map(|i| 2.5 + 1e-3 * i as f64).collect();
        let m = gaussian_mean_line(&z, 0.0005, 0.8).unwrap();
        for (i, (a, b)) in z.iter().zip(&m).enumerate() {
            assert!((a - b).abs() < 1e-11, "point {i}: {a} vs {b}");
        }
    }

    #[test]
    fn a_pitch_far_below_the_cut_off_takes_no_more_taps_than_the_profile_has_points() {
        // 0.8 mm at 1e-300 mm would be 8e299 taps (capacity overflow), at 1e-9 mm 8e8 taps
        // (6.4 GB): the taps beyond the profile's points meet no data and are not made.
        let z = profile(300, 1.0, 1e-3);
        for pitch in [1e-300, 1e-9, f64::MIN_POSITIVE] {
            assert_eq!(weights(0.8, pitch, z.len()).len(), z.len() + 1);
            let m = gaussian_mean_line(&z, pitch, 0.8).unwrap();
            assert_eq!(m.len(), z.len());
        }
        // The same mean line as the full kernel gives, the kernel being wider than the data.
        let full = mean_line_fft(&z, &weights(0.8, 0.0005, usize::MAX));
        let capped = gaussian_mean_line(&z, 0.0005, 0.8).unwrap();
        for (i, (a, b)) in full.iter().zip(&capped).enumerate() {
            assert!((a - b).abs() <= 1e-12, "point {i}: {a} vs {b}");
        }
    }

    #[test]
    fn transform_lengths_are_even_and_5_smooth() {
        assert_eq!(fft_len(9600), 9600);
        assert_eq!(fft_len(9601), 9720);
        assert_eq!(fft_len(1), 2);
        assert_eq!(fft_len(7), 8);
    }
}
