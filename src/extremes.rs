//! The lowest and the highest of a run of numbers, in one pass that does not chain each
//! comparison on the one before: the scale check of a read grid, the IGES writer's largest
//! coordinate, the metrology's level ranges and Rt, and the figures' axes all take it.
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
    // `<` and `>` are false for NaN, which is therefore skipped.
    fn take((lo, hi): (f64, f64), v: f64) -> (f64, f64) {
        (if v < lo { v } else { lo }, if v > hi { v } else { hi })
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
    pairs
        .into_iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, (lo, hi)| {
            (take(a, lo).0, take(a, hi).1)
        })
}

#[cfg(test)]
mod tests {
    use super::min_max;

    #[test]
    fn the_extremes_wherever_they_stand_and_none_for_no_values() {
        // Every position of the lowest and the highest among 8 lanes and a tail of 1..7.
        for n in 1..=27 {
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
        assert_eq!(min_max(&[f64::NAN; 11]), (f64::INFINITY, f64::NEG_INFINITY));
        let v = [1.0, f64::NEG_INFINITY, 2.0, f64::INFINITY];
        assert_eq!(min_max(&v), (f64::NEG_INFINITY, f64::INFINITY));
    }
}
