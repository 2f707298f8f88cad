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

use super::{check_finite, check_pitch, MetrologyError};

/// α = sqrt(ln 2 / π), the constant that puts 50 % transmission at the cut-off.
pub const ALPHA: f64 = 0.469_718_639_349_825_8;

/// Name of the end-effect treatment, as written into recipes.
pub const END_TREATMENT: &str =
    "ISO 16610-28 first-order moment criterion (Gaussian-weighted local line at the ends)";

/// The result of splitting a profile at λc: the mean line (waviness W) and the roughness R = P − W.
#[derive(Debug, Clone, PartialEq)]
pub struct Split {
    /// The λc mean line (waviness profile) in µm, one value per input point.
    pub mean_line_um: Vec<f64>,
    /// The roughness profile R = P − W in µm.
    pub roughness_um: Vec<f64>,
}

/// The sampled, truncated (±`cutoff_mm`) and unnormalised Gaussian weights w_k for offsets
/// k = 0, 1, …, half (the kernel is symmetric).
fn weights(cutoff_mm: f64, pitch_mm: f64) -> Vec<f64> {
    // The small epsilon keeps e.g. 0.8 / 0.0005 at 1600 despite rounding of the quotient.
    let half = (cutoff_mm / pitch_mm + 1e-9).floor() as usize;
    let scale = ALPHA * cutoff_mm;
    (0..=half)
        .map(|k| {
            let u = k as f64 * pitch_mm / scale;
            (-std::f64::consts::PI * u * u).exp()
        })
        .collect()
}

/// The Gaussian mean line (low-pass) of `heights_um` sampled at `pitch_mm`, cut-off `cutoff_mm`,
/// ends by the first-order moment criterion. Also serves as the λs filter (cut-off λs in mm).
pub fn gaussian_mean_line(
    heights_um: &[f64],
    pitch_mm: f64,
    cutoff_mm: f64,
) -> Result<Vec<f64>, MetrologyError> {
    check_pitch(pitch_mm)?;
    if !(cutoff_mm.is_finite() && cutoff_mm > 0.0) {
        return Err(MetrologyError::BadCutoff { cutoff_mm });
    }
    check_finite(heights_um)?;
    let n = heights_um.len();
    let w = weights(cutoff_mm, pitch_mm);
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
        let det = s0 * s2 - s1 * s1;
        // Symmetric window: s1 = 0 and the line's value is the plain weighted mean.
        let value = if s1 == 0.0 || det.abs() <= f64::EPSILON * s0 * s2 {
            t0 / s0
        } else {
            (s2 * t0 - s1 * t1) / det
        };
        out.push(value);
    }
    Ok(out)
}

/// Splits a primary profile at λc into mean line W and roughness R = P − W.
pub fn split(heights_um: &[f64], pitch_mm: f64, cutoff_mm: f64) -> Result<Split, MetrologyError> {
    let mean_line_um = gaussian_mean_line(heights_um, pitch_mm, cutoff_mm)?;
    let roughness_um = heights_um
        .iter()
        .zip(&mean_line_um)
        .map(|(p, w)| p - w)
        .collect();
    Ok(Split {
        mean_line_um,
        roughness_um,
    })
}

/// The mean-line transmission of the ideal (untruncated, continuous) filter at wavelength λ:
/// H_W(λ) = exp(−π·(α·λc/λ)²). Equals 0.5 at λ = λc.
pub fn mean_line_transmission(cutoff_mm: f64, wavelength_mm: f64) -> f64 {
    let r = ALPHA * cutoff_mm / wavelength_mm;
    (-std::f64::consts::PI * r * r).exp()
}
