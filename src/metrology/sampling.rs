//! Dense sampling of iso-curves along u with a basis computed once: the points of a curve
//! whose poles are padded to four lanes (x, y, z, 0), each Σ basis·pole from zero in pole
//! order — the sum `UBasis::for_each_point` and `BSplineCurve::evaluate` make, lane by lane.
//!
//! On a CPU with AVX2 a padded point is summed as one 256-bit vector: every lane is
//! multiplied and added as in the scalar loop (`_mm256_mul_pd` then `_mm256_add_pd`, no FMA,
//! the same order), so the bits are the same; four lanes cost what one costs.
//!
//! Layer 1 (pure logic): depends on `std` only.

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

/// Where the points go.
pub(crate) trait Sink {
    /// Takes the next point (x, y, z, 0).
    fn take(&mut self, p: [f64; 4]);
}

/// x into the first vector, z into the second.
impl Sink for (&mut Vec<f64>, &mut Vec<f64>) {
    #[inline(always)]
    fn take(&mut self, p: [f64; 4]) {
        self.0.push(p[0]);
        self.1.push(p[2]);
    }
}

/// x, y and z.
impl Sink for Vec<[f64; 3]> {
    #[inline(always)]
    fn take(&mut self, p: [f64; 4]) {
        self.push([p[0], p[1], p[2]]);
    }
}

impl Basis<'_> {
    /// Every point of the curve with padded `poles`, in parameter order, into `sink`.
    pub(crate) fn points(&self, poles: &[[f64; 4]], sink: &mut impl Sink) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2, checked just above.
                unsafe { self.points_avx2(poles, sink) };
                return;
            }
        }
        let n = self.degree + 1;
        for (&base, b) in self.first.iter().zip(self.values.chunks_exact(n)) {
            let mut p = [0.0f64; 4];
            for (q, &b) in poles[base..base + n].iter().zip(b) {
                for c in 0..4 {
                    p[c] += b * q[c];
                }
            }
            sink.take(p);
        }
    }

    /// Lane `c` of the point at parameter `k` (the same sum as that lane of
    /// [`Basis::points`]'s point).
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

    /// [`Basis::points`] in 256-bit vectors, four points side by side.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn points_avx2(&self, poles: &[[f64; 4]], sink: &mut impl Sink) {
        use std::arch::x86_64::*;
        let n = self.degree + 1;
        let m = self.first.len();
        let store = |v: __m256d| {
            let mut out = [0.0f64; 4];
            // SAFETY: `out` holds four writable f64.
            unsafe { _mm256_storeu_pd(out.as_mut_ptr(), v) };
            out
        };
        let blocks = m / 4;
        for blk in 0..blocks {
            let k0 = blk * 4;
            let (c0, b0) = self.parts(poles, k0);
            let (c1, b1) = self.parts(poles, k0 + 1);
            let (c2, b2) = self.parts(poles, k0 + 2);
            let (c3, b3) = self.parts(poles, k0 + 3);
            let mut a = [_mm256_setzero_pd(); 4];
            for r in 0..n {
                // SAFETY (each load): `c*[r]` holds four readable f64.
                let q = unsafe {
                    [
                        _mm256_loadu_pd(c0[r].as_ptr()),
                        _mm256_loadu_pd(c1[r].as_ptr()),
                        _mm256_loadu_pd(c2[r].as_ptr()),
                        _mm256_loadu_pd(c3[r].as_ptr()),
                    ]
                };
                a[0] = _mm256_add_pd(a[0], _mm256_mul_pd(_mm256_set1_pd(b0[r]), q[0]));
                a[1] = _mm256_add_pd(a[1], _mm256_mul_pd(_mm256_set1_pd(b1[r]), q[1]));
                a[2] = _mm256_add_pd(a[2], _mm256_mul_pd(_mm256_set1_pd(b2[r]), q[2]));
                a[3] = _mm256_add_pd(a[3], _mm256_mul_pd(_mm256_set1_pd(b3[r]), q[3]));
            }
            for a in a {
                sink.take(store(a));
            }
        }
        for k in blocks * 4..m {
            let (c, b) = self.parts(poles, k);
            let mut a = _mm256_setzero_pd();
            for r in 0..n {
                // SAFETY: `c[r]` holds four readable f64.
                let q = unsafe { _mm256_loadu_pd(c[r].as_ptr()) };
                a = _mm256_add_pd(a, _mm256_mul_pd(_mm256_set1_pd(b[r]), q));
            }
            sink.take(store(a));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vector loop gives each point the bits of the scalar sum, lane by lane, for counts
    /// on and off the blocks of four.
    #[test]
    fn vector_and_scalar_sums_agree_to_the_bit() {
        let mut s = 99u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.3
        };
        let degree = 5;
        let poles: Vec<[f64; 4]> = (0..40)
            .map(|_| [next() * 3.0, next(), next() * 1e-3, 0.0])
            .collect();
        for m in [1, 3, 4, 7, 64, 131] {
            let first: Vec<usize> = (0..m).map(|k| k * (40 - degree - 1) / m).collect();
            let values: Vec<f64> = (0..m * (degree + 1)).map(|_| next()).collect();
            let b = Basis {
                degree,
                first: &first,
                values: &values,
            };
            let (mut xs, mut zs) = (Vec::new(), Vec::new());
            b.points(&poles, &mut (&mut xs, &mut zs));
            let mut pts: Vec<[f64; 3]> = Vec::new();
            b.points(&poles, &mut pts);
            assert_eq!((xs.len(), zs.len(), pts.len()), (m, m, m));
            for k in 0..m {
                assert_eq!(
                    xs[k].to_bits(),
                    b.lane(&poles, k, 0).to_bits(),
                    "{m}: x {k}"
                );
                assert_eq!(
                    zs[k].to_bits(),
                    b.lane(&poles, k, 2).to_bits(),
                    "{m}: z {k}"
                );
                for (c, v) in pts[k].iter().enumerate() {
                    assert_eq!(v.to_bits(), b.lane(&poles, k, c).to_bits(), "{m}: {k}");
                }
            }
        }
    }
}
