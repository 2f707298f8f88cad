//! The lowest and the highest of a run of numbers, in one pass that does not chain each
//! comparison on the one before (in AVX2 registers where the CPU has them): the scale check of
//! a read grid, the IGES writer's largest coordinate, the metrology's level ranges, Rt and the
//! fold check's sampled heights, and the figures' axes all take it.
//!
//! Layer 0 (vocabulary): depends on nothing else in the crate; no I/O.

/// The lowest and the highest of `values` (NaN is neither; +∞ and −∞ when there is none).
///
/// Value i is taken by the i mod 8-th of eight running pairs, so that the comparisons of one
/// value need not wait for those of the value before (one chain of dependent comparisons
/// through a grid's heights is what this avoids); the extremes are exact in any order. Of
/// equal values the one met first in its pair, and then in the lower pair, is kept, which
/// shows only when −0.0 and +0.0 are both the lowest (or the highest): which zero comes back
/// then depends on where they stand.
pub fn min_max(values: &[f64]) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    {
        if values.len() >= 32 && std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            return unsafe { min_max_avx2(values) };
        }
    }
    let mut pairs = [(f64::INFINITY, f64::NEG_INFINITY); 8];
    let blocks = values.chunks_exact(8);
    let rest = blocks.remainder();
    for block in blocks {
        for (pair, &v) in pairs.iter_mut().zip(block) {
            *pair = take(*pair, v);
        }
    }
    for (pair, &v) in pairs.iter_mut().zip(rest) {
        *pair = take(*pair, v);
    }
    merged(pairs)
}

/// `(lo, hi)` with `v` taken in: `<` and `>` are false for NaN, which is therefore skipped.
fn take((lo, hi): (f64, f64), v: f64) -> (f64, f64) {
    (if v < lo { v } else { lo }, if v > hi { v } else { hi })
}

/// The lowest of the pairs' lowest and the highest of their highest, the lower pair's on a tie.
fn merged(pairs: impl IntoIterator<Item = (f64, f64)>) -> (f64, f64) {
    pairs
        .into_iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, (lo, hi)| {
            (take(a, lo).0, take(a, hi).1)
        })
}

/// [`min_max`] with eight pairs in two AVX2 registers of four: value i in pair i mod 8, the
/// values after the last whole eight taken by the pairs from the first on, as there.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn min_max_avx2(values: &[f64]) -> (f64, f64) {
    use std::arch::x86_64::*;
    let (mut lo, mut hi) = (
        [_mm256_set1_pd(f64::INFINITY); 2],
        [_mm256_set1_pd(f64::NEG_INFINITY); 2],
    );
    let blocks = values.chunks_exact(8);
    let rest = blocks.remainder();
    for block in blocks {
        for h in 0..2 {
            // SAFETY: `block` holds eight readable f64, four from 4·h.
            let v = unsafe { _mm256_loadu_pd(block.as_ptr().add(4 * h)) };
            // The ordered comparisons are false for NaN: the pair keeps its value.
            lo[h] = _mm256_blendv_pd(lo[h], v, _mm256_cmp_pd::<_CMP_LT_OQ>(v, lo[h]));
            hi[h] = _mm256_blendv_pd(hi[h], v, _mm256_cmp_pd::<_CMP_GT_OQ>(v, hi[h]));
        }
    }
    let (mut l, mut u) = ([0.0f64; 8], [0.0f64; 8]);
    // SAFETY: `l` and `u` hold eight writable f64 each, four from 4·h.
    unsafe {
        for h in 0..2 {
            _mm256_storeu_pd(l.as_mut_ptr().add(4 * h), lo[h]);
            _mm256_storeu_pd(u.as_mut_ptr().add(4 * h), hi[h]);
        }
    }
    let mut pairs: [(f64, f64); 8] = std::array::from_fn(|k| (l[k], u[k]));
    for (pair, &v) in pairs.iter_mut().zip(rest) {
        *pair = take(*pair, v);
    }
    merged(pairs)
}

#[cfg(test)]
mod tests {
    use super::min_max;

    #[test]
    fn the_extremes_wherever_they_stand_and_none_for_no_values() {
        // Every position of the lowest and the highest among 8 lanes and a tail of 1..7, below
        // and above the length where AVX2 takes over (where the CPU has it).
        for n in 1..=43 {
            for at in 0..n {
                let v: Vec<f64> = (0..n)
                    .map(|i| if i == at { -5.0 } else { i as f64 * 0.25 })
                    .collect();
                let top = (0..n).filter(|&i| i != at).map(|i| i as f64 * 0.25);
                let want_hi = top.fold(-5.0f64, |a, b| if b > a { b } else { a });
                assert_eq!(min_max(&v), (-5.0, want_hi), "n {n} at {at}");
            }
        }
        assert_eq!(min_max(&[]), (f64::INFINITY, f64::NEG_INFINITY));
    }

    #[test]
    fn nan_is_skipped_and_infinities_count() {
        let v = [
            f64::NAN,
            2.0,
            f64::NAN,
            -1.0,
            3.5,
            f64::NAN,
            0.0,
            1.0,
            f64::NAN,
            7.0,
        ];
        assert_eq!(min_max(&v), (-1.0, 7.0));
        assert_eq!(min_max(&v.repeat(5)), (-1.0, 7.0));
        assert_eq!(min_max(&[f64::NAN; 11]), (f64::INFINITY, f64::NEG_INFINITY));
        assert_eq!(min_max(&[f64::NAN; 41]), (f64::INFINITY, f64::NEG_INFINITY));
        let v = [1.0, f64::NEG_INFINITY, 2.0, f64::INFINITY];
        assert_eq!(min_max(&v), (f64::NEG_INFINITY, f64::INFINITY));
        assert_eq!(min_max(&v.repeat(9)), (f64::NEG_INFINITY, f64::INFINITY));
    }
}
