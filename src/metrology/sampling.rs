//! Dense sampling of iso-curves with a basis computed once: two coordinates of the points of a
//! curve whose poles are padded to four lanes (x, y, z, 0), each Σ basis·pole from zero in
//! pole order — the sum `UBasis::for_each_point` and `BSplineCurve::evaluate` make, lane by
//! lane.
//!
//! On a CPU with AVX2 four points are summed side by side in one 256-bit vector per
//! coordinate: every lane is multiplied and added as in the scalar loop (`_mm256_mul_pd` then
//! `_mm256_add_pd`, no FMA, the same order), so the bits are the same.
//!
//! Layer 1 (pure logic): depends on `std` and, for the basis it takes, [`crate::nurbs::UBasis`].

/// `n` equally spaced parameters in [0, 1] (`k / (n − 1)`).
pub(crate) fn equally_spaced(n: usize) -> Vec<f64> {
    (0..n).map(|k| k as f64 / (n - 1) as f64).collect()
}

/// A basis along u at many parameters: for parameter k, `first[k]` is the first pole its
/// `degree + 1` values `values[k·(degree+1)..]` apply to.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Basis<'a> {
    /// Degree of the curve.
    pub degree: usize,
    /// First pole per parameter.
    pub first: &'a [usize],
    /// `degree + 1` values per parameter.
    pub values: &'a [f64],
}

impl<'a> Basis<'a> {
    /// The basis `u` holds, as the samplers here take it.
    pub(crate) fn of(u: &'a crate::nurbs::UBasis) -> Basis<'a> {
        Basis {
            degree: u.degree(),
            first: u.first_poles(),
            values: u.values(),
        }
    }
    /// Lane `c` (0 x, 1 y, 2 z) of the point at parameter `k`: Σ basis·pole from zero in pole
    /// order, the sum every sampler here must reproduce to the bit.
    pub(crate) fn lane(&self, poles: &[[f64; 4]], k: usize, c: usize) -> f64 {
        let n = self.degree + 1;
        let base = self.first[k];
        let mut p = 0.0;
        for (q, b) in poles[base..base + n]
            .iter()
            .zip(&self.values[k * n..(k + 1) * n])
        {
            p += b * q[c];
        }
        p
    }

    /// The poles and basis values of parameter `k`, each exactly `degree + 1` long, so that
    /// sums over them index without checks.
    #[inline(always)]
    fn parts<'p>(&'p self, poles: &'p [[f64; 4]], k: usize) -> (&'p [[f64; 4]], &'p [f64]) {
        let n = self.degree + 1;
        (&poles[self.first[k]..][..n], &self.values[k * n..][..n])
    }
}

/// A [`Basis`] regrouped for two lanes only, four parameters at a time: where the iso-curves
/// along u are checked for folds and cut into bearing curves only x and z are needed (along v,
/// y and x), and summing whole padded poles spends half of its work on the other lanes.
///
/// For each block of four consecutive parameters it keeps the window of poles their bases
/// cover together and, per pole of the window, the four parameters' basis values side by side,
/// 0.0 where a pole is outside a parameter's own `degree + 1`. A lane then sums over the window
/// in pole order, one vector multiply and add per pole for four points. The padded terms do
/// not change a single bit: each running sum starts at +0.0 and, rounding to nearest, a sum
/// that starts at +0.0 is never −0.0, so adding 0·q (±0 for a finite pole coordinate q) before
/// or after its own terms leaves it as it was. A curve with a pole coordinate that is not
/// finite (where 0·q would be NaN), or a CPU without AVX2, is summed point by point, lane by
/// lane, as [`Basis::lane`] sums it. Hand-written: the equal-bits contract with the other
/// samplers is this project's own.
#[derive(Debug, Clone)]
pub struct TwoLanes<'a> {
    /// The basis regrouped.
    pub(crate) basis: Basis<'a>,
    /// Per whole block of four parameters: the first pole of its window and where its
    /// window's values start in `values`.
    blocks: Vec<(usize, usize)>,
    /// Per block, per pole of its window (from the block's first pole to the next block's
    /// offset), the four parameters' basis values.
    values: Vec<[f64; 4]>,
}

impl<'a> TwoLanes<'a> {
    /// Regroups `basis` (its parameters' poles must lie within the poles it is later given).
    pub(crate) fn new(basis: Basis<'a>) -> TwoLanes<'a> {
        let n = basis.degree + 1;
        let blocks_n = basis.first.len() / 4;
        let mut blocks = Vec::with_capacity(blocks_n);
        let mut values = Vec::with_capacity(blocks_n * (n + 1));
        for blk in 0..blocks_n {
            let k0 = blk * 4;
            let firsts = &basis.first[k0..k0 + 4];
            let lo = firsts.iter().copied().min().unwrap_or(0);
            let hi = firsts.iter().copied().max().unwrap_or(0) + n;
            blocks.push((lo, values.len()));
            let start = values.len();
            values.resize(start + (hi - lo), [0.0; 4]);
            for (j, &f) in firsts.iter().enumerate() {
                let b = &basis.values[(k0 + j) * n..(k0 + j + 1) * n];
                for (r, &v) in b.iter().enumerate() {
                    values[start + f - lo + r][j] = v;
                }
            }
        }
        TwoLanes {
            basis,
            blocks,
            values,
        }
    }

    /// Lanes `lanes[0]` and `lanes[1]` (0 x, 1 y, 2 z) of every point of the curve with
    /// padded `poles`, in parameter order, appended to `a` and `b`: the bits of
    /// [`Basis::lane`].
    pub(crate) fn points(
        &self,
        poles: &[[f64; 4]],
        lanes: [usize; 2],
        a: &mut Vec<f64>,
        b: &mut Vec<f64>,
    ) {
        let [la, lb] = lanes.map(|l| l.min(3));
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2")
                && poles.iter().all(|q| q[la].is_finite() && q[lb].is_finite())
            {
                // SAFETY: the CPU supports AVX2, checked just above.
                unsafe { self.points_avx2(poles, [la, lb], a, b) };
                return;
            }
        }
        let (n, m) = (self.basis.degree + 1, self.basis.first.len());
        a.reserve(m);
        b.reserve(m);
        for k in 0..m {
            let (c, w) = self.basis.parts(poles, k);
            let (mut x, mut z) = (0.0, 0.0);
            for (q, &w) in c.iter().zip(w).take(n) {
                x += w * q[la];
                z += w * q[lb];
            }
            a.push(x);
            b.push(z);
        }
    }

    /// [`TwoLanes::points`] in 256-bit vectors (`lanes` below 4).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn points_avx2(
        &self,
        poles: &[[f64; 4]],
        lanes: [usize; 2],
        out_a: &mut Vec<f64>,
        out_b: &mut Vec<f64>,
    ) {
        use std::arch::x86_64::*;
        let m = self.basis.first.len();
        // The points are written into the vectors' spare room (not zeroed first: zeroing
        // costs as much memory traffic as the points themselves) and the lengths set after.
        out_a.reserve(m);
        out_b.reserve(m);
        let (ao, bo) = (
            &mut out_a.spare_capacity_mut()[..m],
            &mut out_b.spare_capacity_mut()[..m],
        );
        let (a_blocks, b_blocks) = (ao.chunks_exact_mut(4), bo.chunks_exact_mut(4));
        for (blk, ((&(lo, off), ao), bo)) in
            self.blocks.iter().zip(a_blocks).zip(b_blocks).enumerate()
        {
            let end = self.blocks.get(blk + 1).map_or(self.values.len(), |b| b.1);
            let b = &self.values[off..end];
            let q = &poles[lo..lo + b.len()];
            // The common window widths with their loops unrolled; the same sums.
            // SAFETY (each call): the CPU supports AVX2, as this function requires.
            let (sa, sb) = match b.len() {
                6 => unsafe { window::<6>(b, q, lanes) },
                7 => unsafe { window::<7>(b, q, lanes) },
                8 => unsafe { window::<8>(b, q, lanes) },
                _ => unsafe { window_any(b, q, lanes) },
            };
            // SAFETY: `ao` and `bo` each hold four writable f64 (`MaybeUninit<f64>` has the
            // layout of `f64`).
            unsafe {
                _mm256_storeu_pd(ao.as_mut_ptr().cast::<f64>(), sa);
                _mm256_storeu_pd(bo.as_mut_ptr().cast::<f64>(), sb);
            }
        }
        let n = self.basis.degree + 1;
        for k in self.blocks.len() * 4..m {
            let (c, b) = self.basis.parts(poles, k);
            let (mut sa, mut sb) = (0.0, 0.0);
            for (q, &b) in c.iter().zip(b).take(n) {
                sa += b * q[lanes[0]];
                sb += b * q[lanes[1]];
            }
            ao[k].write(sa);
            bo[k].write(sb);
        }
        // SAFETY: the first `m` spare elements of each vector were written just above: four
        // per whole block, then one per remaining parameter.
        unsafe {
            out_a.set_len(out_a.len() + m);
            out_b.set_len(out_b.len() + m);
        }
    }
}

/// The two lanes' sums of one block over a window of `W` poles (`b` and `q` are `W` long).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn window<const W: usize>(
    b: &[[f64; 4]],
    q: &[[f64; 4]],
    [la, lb]: [usize; 2],
) -> (std::arch::x86_64::__m256d, std::arch::x86_64::__m256d) {
    use std::arch::x86_64::*;
    let (b, q): (&[[f64; 4]; W], &[[f64; 4]; W]) = match (b.try_into(), q.try_into()) {
        (Ok(b), Ok(q)) => (b, q),
        // SAFETY: the CPU supports AVX2, as this function requires.
        _ => return unsafe { window_any(b, q, [la, lb]) },
    };
    let (mut ax, mut az) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    for r in 0..W {
        // SAFETY: `b[r]` holds four readable f64.
        let bv = unsafe { _mm256_loadu_pd(b[r].as_ptr()) };
        ax = _mm256_add_pd(ax, _mm256_mul_pd(bv, _mm256_set1_pd(q[r][la])));
        az = _mm256_add_pd(az, _mm256_mul_pd(bv, _mm256_set1_pd(q[r][lb])));
    }
    (ax, az)
}

/// [`window`] for a window of any width.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn window_any(
    b: &[[f64; 4]],
    q: &[[f64; 4]],
    [la, lb]: [usize; 2],
) -> (std::arch::x86_64::__m256d, std::arch::x86_64::__m256d) {
    use std::arch::x86_64::*;
    let (mut ax, mut az) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    for (b, q) in b.iter().zip(q) {
        // SAFETY: `b` holds four readable f64.
        let bv = unsafe { _mm256_loadu_pd(b.as_ptr()) };
        ax = _mm256_add_pd(ax, _mm256_mul_pd(bv, _mm256_set1_pd(q[la])));
        az = _mm256_add_pd(az, _mm256_mul_pd(bv, _mm256_set1_pd(q[lb])));
    }
    (ax, az)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> f64 {
            crate::metrology::lcg(&mut self.0) - 0.3
        }

        fn below(&mut self, n: usize) -> usize {
            ((self.next() + 0.3) * n as f64) as usize % n.max(1)
        }
    }

    /// Checks both lanes of every point of `TwoLanes` against [`Basis::lane`], to the bit.
    fn check(b: Basis<'_>, poles: &[[f64; 4]], what: &str) {
        let sampler = TwoLanes::new(b);
        for lanes in [[0, 2], [1, 0], [2, 1], [2, 2]] {
            // Appended after what the vectors already hold.
            let (mut xs, mut zs) = (vec![7.0], vec![7.0, 8.0]);
            sampler.points(poles, lanes, &mut xs, &mut zs);
            let m = b.first.len();
            assert_eq!((xs.len(), zs.len()), (m + 1, m + 2), "{what}");
            assert_eq!((xs[0], zs[..2].to_vec()), (7.0, vec![7.0, 8.0]), "{what}");
            for k in 0..m {
                for (got, lane) in [(xs[1 + k], lanes[0]), (zs[2 + k], lanes[1])] {
                    assert_eq!(
                        got.to_bits(),
                        b.lane(poles, k, lane).to_bits(),
                        "{what}: lanes {lanes:?}, point {k} of {m}, lane {lane}"
                    );
                }
            }
        }
    }

    /// The two-lane sampler gives each point the bits of the scalar sum, lane by lane: for
    /// counts on and off the blocks of four; for parameters that share a span, that cross one
    /// or several, or whose first poles run backwards; for zero and negative-zero poles and
    /// basis values (the padded terms must not turn a +0.0 into −0.0 or back); and for curves
    /// with a pole that is not finite or a basis value that is NaN.
    #[test]
    fn two_lanes_equal_the_scalar_sums_to_the_bit() {
        let mut rng = Rng(99);
        let count = 40;
        for degree in [0, 1, 3, 5] {
            let n = degree + 1;
            let last = count - n;
            for m in [1, 3, 4, 5, 7, 64, 131] {
                let layouts: Vec<(&str, Vec<usize>)> = vec![
                    (
                        "spans of about 8",
                        (0..m).map(|k| (k / 8).min(last)).collect(),
                    ),
                    ("even", (0..m).map(|k| k * last / m.max(2)).collect()),
                    (
                        "a span per point",
                        (0..m).map(|k| (k * 3).min(last)).collect(),
                    ),
                    ("random", (0..m).map(|_| rng.below(last + 1)).collect()),
                    ("one span", vec![last / 2; m]),
                ];
                for (layout, first) in layouts {
                    let mut values: Vec<f64> = (0..m * n).map(|_| rng.next()).collect();
                    for k in (0..values.len()).step_by(5) {
                        values[k] = if k % 2 == 0 { 0.0 } else { -0.0 };
                    }
                    let b = Basis {
                        degree,
                        first: &first,
                        values: &values,
                    };
                    let mut poles: Vec<[f64; 4]> = (0..count)
                        .map(|_| [rng.next() * 3.0, rng.next(), rng.next() * 1e-3, 0.0])
                        .collect();
                    let what = format!("degree {degree}, {m} points, {layout}");
                    check(b, &poles, &what);
                    // Signed zeros in every lane, and z that cancels exactly.
                    for (i, p) in poles.iter_mut().enumerate() {
                        p[1] = if i % 2 == 0 { -0.0 } else { 0.0 };
                        p[2] = -0.0;
                        if i % 3 == 0 {
                            p[0] = -0.0;
                        }
                    }
                    check(b, &poles, &format!("{what}, signed zeros"));
                    // A pole that is not finite: the point-by-point path.
                    poles[count / 2][0] = f64::INFINITY;
                    poles[count / 3][2] = f64::NAN;
                    check(b, &poles, &format!("{what}, a pole not finite"));
                    // A basis value that is NaN.
                    let mut bad = values.clone();
                    bad[values.len() / 2] = f64::NAN;
                    let poles: Vec<[f64; 4]> = (0..count)
                        .map(|_| [rng.next(), rng.next(), rng.next(), 0.0])
                        .collect();
                    check(
                        Basis {
                            degree,
                            first: &first,
                            values: &bad,
                        },
                        &poles,
                        &format!("{what}, a NaN basis value"),
                    );
                }
            }
        }
    }
}
