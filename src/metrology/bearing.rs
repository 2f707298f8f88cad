//! Bearing area (material ratio) curves of sampled curves, as the paper's Appendix A computes
//! them from the NURBS model: each curve is referenced to its mean line (the "parallel centre
//! line"), its height range is divided into equal levels, and the material area ratio at a level
//! is MAR(h) = ΣL_i / L0 × 100 %, the summed lengths of the cross line inside the material over
//! the curve's length. Crossings are interpolated linearly between the (dense) samples, so the
//! ratio is exact for the piecewise-linear curve through them.
//!
//! The input is a generic sampled curve (heights at uniform x, or a closure sampled densely), so
//! any model that can be evaluated along x can be characterised.
//!
//! Depends on [`super::MetrologyError`] only.

use super::{check_heights, MetrologyError};
use serde::Serialize;

/// Material ratio in % of a piecewise-linear curve through `heights` (uniform spacing) at
/// `level`: the fraction of its length where the curve is at or above `level`.
pub fn material_ratio_pct(heights: &[f64], level: f64) -> f64 {
    material_ratio_pct_at(heights, [level])[0]
}

/// [`material_ratio_pct`] at each of `levels` from one pass over the curve: each level's terms
/// are added in the same order as there, so each ratio is the same bits.
pub fn material_ratio_pct_at<const L: usize>(heights: &[f64], levels: [f64; L]) -> [f64; L] {
    if heights.len() < 2 {
        return levels.map(|level| match heights.first() {
            Some(z) if *z >= level => 100.0,
            _ => 0.0,
        });
    }
    let mut inside = [0.0; L];
    for w in heights.windows(2) {
        let (a, b) = match w {
            [a, b] => (*a, *b),
            _ => continue,
        };
        let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
        for (s, level) in inside.iter_mut().zip(levels) {
            *s += segment_inside(hi, lo, level);
        }
    }
    inside.map(|s| s / (heights.len() - 1) as f64 * 100.0)
}

/// C(mr): the level at which the material ratio of the piecewise-linear curve through
/// `heights` (uniform spacing) is `mr_pct`, the inverse of [`material_ratio_pct`] (which falls
/// continuously from 100 % at the lowest point to 0 % at the highest). C(0) is the highest
/// point, C(100) the lowest; in between, bisection to 1e-12 of the height range. Where the
/// curve is flat (a level holding a whole segment) the highest such level is returned.
///
/// Each bisection step needs only whether the ratio at the midpoint reaches `mr_pct`, and
/// only the segments that straddle the bracket can change from step to step: the rest are
/// wholly inside the material (counted) or wholly outside (dropped) for every later
/// midpoint. The ratio is estimated from the counted segments and the straddling ones, with
/// a bound on how far any order of summing the same terms can be from the sum
/// [`material_ratio_pct`] makes; only when the bound does not decide the comparison is the
/// ratio computed as there. Every step therefore goes the way the plain bisection goes and
/// the level is the same to the bit, from a few passes over the curve instead of one per
/// step.
pub fn level_at_material_ratio(heights: &[f64], mr_pct: f64) -> f64 {
    let (bottom, top) = crate::extremes::min_max(heights);
    if !(top.is_finite() && bottom.is_finite()) || mr_pct <= 0.0 {
        return top;
    }
    if mr_pct >= 100.0 {
        return bottom;
    }
    if heights.len() < 2 || heights.iter().any(|h| h.is_nan()) {
        return bisect_by_full_passes(heights, mr_pct, top, bottom);
    }
    let segments = heights.len() - 1;
    let ratio = |inside: f64| inside / segments as f64 * 100.0;
    // A sequential sum of m terms in [0, 1] is within γ_m·Σ ≈ m·2^-53·Σ of the exact sum of
    // the same terms, in any order; twice that separates two orders. This bound is 16 times
    // as wide (it also covers the rounding of the bound itself).
    let slack = 8.0 * segments as f64 * f64::EPSILON;
    // (upper, lower) end of each straddling segment, and the count wholly inside.
    let mut open: Vec<(f64, f64)> = heights
        .windows(2)
        .map(|w| {
            if w[0] >= w[1] {
                (w[0], w[1])
            } else {
                (w[1], w[0])
            }
        })
        .collect();
    let mut inside_count = 0usize;
    bisect(top, bottom, |mid, (lo, hi)| {
        // Every midpoint from here on lies in [lo, hi]: a segment whose lower end is at or
        // above hi is wholly inside for all of them, one whose upper end is below lo wholly
        // outside.
        open.retain(|&(a, b)| {
            inside_count += usize::from(b >= hi);
            b < hi && a >= lo
        });
        let inside = open.iter().fold(inside_count as f64, |s, &(a, b)| {
            s + segment_inside(a, b, mid)
        });
        let margin = slack * (inside + 1.0);
        if ratio(inside - margin) >= mr_pct {
            true
        } else if ratio(inside + margin) < mr_pct {
            false
        } else {
            material_ratio_pct(heights, mid) >= mr_pct
        }
    })
}

/// The share (0 to 1) of one segment with upper end `hi` and lower end `lo` at or above
/// `level`, as [`material_ratio_pct`] computes it.
#[inline(always)]
fn segment_inside(hi: f64, lo: f64, level: f64) -> f64 {
    if lo >= level {
        1.0
    } else if hi > level {
        (hi - level) / (hi - lo)
    } else {
        0.0
    }
}

/// The bisection of [`level_at_material_ratio`] with the ratio computed over the whole curve
/// at every step (for curves holding NaN, where the bound on the sums does not hold).
fn bisect_by_full_passes(heights: &[f64], mr_pct: f64, top: f64, bottom: f64) -> f64 {
    bisect(top, bottom, |mid, _| {
        material_ratio_pct(heights, mid) >= mr_pct
    })
}

/// Bisection from [bottom, top] to 1e-12 of the range (or until the bracket stops shrinking):
/// the lower end moves up to each midpoint where `reaches(midpoint, bracket)`; the last one.
fn bisect(top: f64, bottom: f64, mut reaches: impl FnMut(f64, (f64, f64)) -> bool) -> f64 {
    let (mut lo, mut hi) = (bottom, top);
    while hi - lo > 1e-12 * (top - bottom).max(f64::MIN_POSITIVE) {
        let mid = 0.5 * (lo + hi);
        if reaches(mid, (lo, hi)) {
            lo = mid;
        } else {
            hi = mid;
        }
        if mid == lo && mid == hi {
            break;
        }
    }
    lo
}

/// Material ratio in % of a piecewise-linear curve through points (`xs[i]`, `zs[i]`) with
/// increasing x (any spacing) at `level`: the x-length at or above `level` over the x range.
/// Returns 0 when fewer than two points or a zero x range are given.
pub fn material_ratio_xz_pct(xs: &[f64], zs: &[f64], level: f64) -> f64 {
    let mut inside = 0.0;
    let mut total = 0.0;
    for (xw, zw) in xs.windows(2).zip(zs.windows(2)) {
        let (x0, x1, a, b) = match (xw, zw) {
            ([x0, x1], [a, b]) => (*x0, *x1, *a, *b),
            _ => continue,
        };
        let dx = x1 - x0;
        total += dx;
        let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
        if lo >= level {
            inside += dx;
        } else if hi > level {
            inside += dx * (hi - level) / (hi - lo);
        }
    }
    if total > 0.0 {
        inside / total * 100.0
    } else {
        0.0
    }
}

/// The bearing area curve of a curve sampled at increasing, not necessarily uniform x (mm):
/// the mean line is the x-weighted (trapezoidal) mean, levels are equal steps over the range.
pub fn bearing_curve_xz(
    xs: &[f64],
    zs: &[f64],
    levels: usize,
) -> Result<BearingCurve, MetrologyError> {
    check_heights(zs)?;
    check_heights(xs)?;
    if xs.len() != zs.len() || xs.len() < 2 {
        return Err(MetrologyError::BadParameter {
            what: "points",
            value: xs.len().min(zs.len()) as f64,
            hint: "give at least 2 (x, z) points, as many x as z",
        });
    }
    if let Some(i) = xs.windows(2).position(|w| matches!(w, [a, b] if b <= a)) {
        return Err(MetrologyError::BadParameter {
            what: "x (mm) not increasing at index",
            value: (i + 1) as f64,
            hint: "sample the curve at strictly increasing x",
        });
    }
    let (mut area, mut total) = (0.0, 0.0);
    for (xw, zw) in xs.windows(2).zip(zs.windows(2)) {
        if let ([x0, x1], [a, b]) = (xw, zw) {
            area += 0.5 * (a + b) * (x1 - x0);
            total += x1 - x0;
        }
    }
    let mean = area / total;
    let z: Vec<f64> = zs.iter().map(|h| h - mean).collect();
    Ok(BearingCurve {
        mean_line_um: mean,
        points: curve_between_extremes(&z, levels, |hs| material_ratios_xz_pct(xs, &z, hs))?,
    })
}

/// The curve `[height, material ratio %]` of heights `z` at `levels` equal levels from the
/// highest (0 %) to the lowest (100 %), the ratios at the levels between from `interior`.
pub(crate) fn curve_between_extremes(
    z: &[f64],
    levels: usize,
    interior: impl FnOnce(&[f64]) -> Vec<f64>,
) -> Result<Vec<[f64; 2]>, MetrologyError> {
    let hs = levels_spanning(z, levels)?;
    let inner = interior(&hs[1..levels - 1]);
    Ok(hs
        .iter()
        .enumerate()
        .map(|(k, &h)| {
            let mr = if k == 0 {
                0.0
            } else if k == levels - 1 {
                100.0
            } else {
                inner[k - 1]
            };
            [h, mr]
        })
        .collect())
}

/// [`equal_levels`] from the highest of `z` to the lowest, refused for fewer than 2 levels.
fn levels_spanning(z: &[f64], levels: usize) -> Result<Vec<f64>, MetrologyError> {
    if levels < 2 {
        return Err(MetrologyError::BadParameter {
            what: "levels",
            value: levels as f64,
            hint: "give at least 2 height levels (the paper uses 101)",
        });
    }
    let (bottom, top) = crate::extremes::min_max(z);
    Ok(equal_levels(top, bottom, levels))
}

/// `levels` (at least 2) equal steps from `top` down to `bottom`, level k at
/// `top − (top − bottom)·k/(levels − 1)`: non-increasing in k, as the rounding of each step
/// is monotone.
pub(crate) fn equal_levels(top: f64, bottom: f64, levels: usize) -> Vec<f64> {
    (0..levels)
        .map(|k| top - (top - bottom) * k as f64 / (levels - 1) as f64)
        .collect()
}

/// [`material_ratio_pct`] at each of `levels`. The same terms per segment, each computed as
/// there to the bit, but added up per level in another order, so the ratios agree to rounding
/// (about 1e-15 relative). For non-increasing levels (as a bearing curve's are) each segment
/// touches only the levels it crosses: O(n log L + crossings) instead of O(n·L); other level
/// lists take the per-level way.
pub fn material_ratios_pct(heights: &[f64], levels: &[f64]) -> Vec<f64> {
    if heights.len() < 2 || !is_non_increasing(levels) || !all_finite(heights) {
        return levels
            .iter()
            .map(|&h| material_ratio_pct(heights, h))
            .collect();
    }
    let segments = (heights.len() - 1) as f64;
    inside_lengths_wide(heights, |_| 1.0, levels)
        .into_iter()
        .map(|inside| inside / segments * 100.0)
        .collect()
}

/// [`material_ratio_xz_pct`] at each of `levels`, as [`material_ratios_pct`] is to
/// [`material_ratio_pct`]: the same terms, summed per level in another order.
pub fn material_ratios_xz_pct(xs: &[f64], zs: &[f64], levels: &[f64]) -> Vec<f64> {
    if xs.len() != zs.len()
        || xs.len() < 2
        || !is_non_increasing(levels)
        || !all_finite(xs)
        || !all_finite(zs)
    {
        return levels
            .iter()
            .map(|&h| material_ratio_xz_pct(xs, zs, h))
            .collect();
    }
    // The total in the order the per-level function sums it, so the divisor is the same bits.
    let total: f64 = xs.windows(2).fold(0.0, |t, w| t + (w[1] - w[0]));
    let inside = inside_lengths_wide(zs, |i| xs[i + 1] - xs[i], levels);
    inside
        .into_iter()
        .map(|inside| {
            if total > 0.0 {
                inside / total * 100.0
            } else {
                0.0
            }
        })
        .collect()
}

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn is_non_increasing(levels: &[f64]) -> bool {
    levels.windows(2).all(|w| w[1] <= w[0])
}

/// [`inside_lengths`], compiled for AVX2 when the running CPU has it: the same operations
/// (the guess's `ceil` becomes one instruction instead of a library call), the same bits.
fn inside_lengths_wide(zs: &[f64], weight: impl Fn(usize) -> f64, levels: &[f64]) -> Vec<f64> {
    #[cfg(target_arch = "x86_64")]
    {
        /// # Safety
        /// The CPU must support AVX2.
        #[target_feature(enable = "avx2")]
        unsafe fn avx2(zs: &[f64], weight: impl Fn(usize) -> f64, levels: &[f64]) -> Vec<f64> {
            inside_lengths(zs, weight, levels)
        }
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            return unsafe { avx2(zs, weight, levels) };
        }
    }
    inside_lengths(zs, weight, levels)
}

/// For each of `levels` (non-increasing, finite), the summed length inside the material of
/// the piecewise-linear curve through `zs`, segment i weighing `weight(i)`: the whole weight
/// where the segment's lower end is at or above the level, `weight·(hi − level)/(hi − lo)`
/// where the level cuts it, nothing where it lies below. Each segment's whole weight is added
/// once, at the first level it is entirely above, and carried down by a running sum; only the
/// levels strictly inside its height range get a fraction.
#[inline(always)]
fn inside_lengths(zs: &[f64], weight: impl Fn(usize) -> f64, levels: &[f64]) -> Vec<f64> {
    let l = levels.len();
    // first_at_or_below(z): the first level index k with levels[k] <= z; first_below(z): the
    // first with levels[k] < z. Both are partition points of a monotone predicate. The first
    // is found from where equally spaced levels would put z and then stepped to the exact
    // point (the predicate decides, so the index is the binary search's); a guess more than a
    // few steps off (levels far from equally spaced) falls back to the binary search.
    let guess = Guesser::new(levels);
    // Written out at each use (not as closures), so that all of it is compiled inline.
    macro_rules! first_at_or_below {
        ($z:expr) => {{
            let z = $z;
            partition_near(levels, guess.at(z), |h| h > z)
        }};
    }
    macro_rules! first_below {
        ($z:expr, $at:expr) => {{
            step_over_equal(levels, $at, $z)
        }};
    }
    let mut whole = vec![0.0f64; l + 1];
    let mut cut = vec![0.0f64; l];
    let Some(&z0) = zs.first() else {
        return cut;
    };
    let at0 = first_at_or_below!(z0);
    let mut prev = (z0, at0, first_below!(z0, at0));
    for (i, &z) in zs.iter().enumerate().skip(1) {
        let at = first_at_or_below!(z);
        let next = (z, at, first_below!(z, at));
        let ((lo, lo_at, _), (hi, _, hi_below)) = if prev.0 >= next.0 {
            (next, prev)
        } else {
            (prev, next)
        };
        let w = weight(i - 1);
        // Levels k >= lo_at are at or below lo: the whole segment is inside.
        whole[lo_at] += w;
        // Levels hi_below <= k < lo_at lie strictly between lo and hi.
        for k in hi_below..lo_at {
            cut[k] += w * (hi - levels[k]) / (hi - lo);
        }
        prev = next;
    }
    let mut running = 0.0;
    for (c, &w) in cut.iter_mut().zip(&whole) {
        running += w;
        *c += running;
    }
    cut
}

/// The first level below `z` (the partition point of `h >= z`) from `at`, the first level at
/// or below it (the partition point of `h > z`), over non-increasing `levels`: the levels from
/// `at` on are at or below z and those equal to z come first, so stepping over them reaches
/// it, without a second search.
#[inline(always)]
fn step_over_equal(levels: &[f64], at: usize, z: f64) -> usize {
    let mut k = at;
    while k < levels.len() && levels[k] >= z {
        k += 1;
    }
    k
}

/// Where z would fall among `levels` (non-increasing) if they were equally spaced from the
/// first to the last: an index in 0..=len, only a starting point for [`partition_near`].
struct Guesser {
    n: usize,
    first: f64,
    scale: f64,
}

impl Guesser {
    fn new(levels: &[f64]) -> Guesser {
        let n = levels.len();
        let (first, last) = (
            levels.first().copied().unwrap_or(0.0),
            levels.last().copied().unwrap_or(0.0),
        );
        let span = first - last;
        let scale = if n > 1 && span > 0.0 && span.is_finite() {
            (n - 1) as f64 / span
        } else {
            0.0
        };
        Guesser { n, first, scale }
    }

    #[inline(always)]
    fn at(&self, z: f64) -> usize {
        let k = (self.first - z) * self.scale;
        if k.is_nan() || k <= 0.0 {
            0
        } else {
            (k.ceil() as usize).min(self.n)
        }
    }
}

/// The partition point of `pred` over `levels` (true then false), searched from `start`
/// outwards for a few steps, then by bisection: the same index as `partition_point`.
#[inline(always)]
fn partition_near(levels: &[f64], start: usize, pred: impl Fn(f64) -> bool) -> usize {
    const STEPS: usize = 4;
    let n = levels.len();
    let mut k = start.min(n);
    for _ in 0..STEPS {
        let left_ok = k == 0 || pred(levels[k - 1]);
        let here_false = k == n || !pred(levels[k]);
        match (left_ok, here_false) {
            (true, true) => return k,
            (false, _) => k -= 1,
            (true, false) => k += 1,
        }
    }
    levels.partition_point(|&h| pred(h))
}

/// One bearing area curve: levels from the highest to the lowest point, with their ratios.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BearingCurve {
    /// Mean of the curve (the parallel centre line) that heights are referenced to, µm.
    pub mean_line_um: f64,
    /// `[height_um, material_ratio_pct]` pairs, heights relative to the mean line, from the
    /// highest level (0 %) down to the lowest (100 %).
    pub points: Vec<[f64; 2]>,
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::metrology::lcg;

    fn assert_close(fast: &[f64], slow: &[f64], what: &str) {
        assert_eq!(fast.len(), slow.len(), "{what}");
        for (k, (a, b)) in fast.iter().zip(slow).enumerate() {
            assert!(
                (a - b).abs() <= 1e-12 * a.abs().max(b.abs()),
                "{what}, level {k}: {a} vs {b} per level"
            );
        }
    }

    /// Curves that stress the level bookkeeping: rough noise, a dense smooth wave on uneven x,
    /// quantised heights whose levels fall exactly on samples, plateaus and flat segments,
    /// a constant curve.
    fn test_curves() -> Vec<(Vec<f64>, Vec<f64>)> {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut out = Vec::new();
        let n = 3000;
        let rough: Vec<f64> = (0..n)
            .map(|i| (i as f64 * 0.013).sin() + 0.8 * lcg(&mut seed))
            .collect();
        let mut x = 0.0;
        let uneven: Vec<f64> = (0..n)
            .map(|_| {
                x += 0.0002 + 0.0003 * lcg(&mut seed);
                x
            })
            .collect();
        let smooth: Vec<f64> = uneven.iter().map(|x| (x * 40.0).sin() * 1.7).collect();
        let steps: Vec<f64> = (0..n)
            .map(|_| (lcg(&mut seed) * 10.0).floor() - 5.0)
            .collect();
        let mut plateau = vec![2.0; 50];
        plateau.extend((0..200).map(|i| (i as f64 * 0.1).cos()));
        plateau.extend(vec![-1.0; 80]);
        let uniform = |m: usize| (0..m).map(|i| i as f64 * 0.0005).collect::<Vec<f64>>();
        out.push((uniform(n), rough));
        out.push((uneven, smooth));
        out.push((uniform(n), steps));
        out.push((uniform(plateau.len()), plateau));
        out.push((uniform(40), vec![0.25; 40]));
        out
    }

    #[test]
    fn the_guessed_partition_point_is_the_binary_searchs() {
        // Equally spaced levels (the guess lands at once), unevenly spaced and repeated ones
        // (stepped or bisected), single and empty lists; heights on, between and outside
        // the levels.
        let mut lists = vec![
            equal_levels(3.0, -2.0, 99),
            equal_levels(1e-3, -1e-3, 7),
            vec![5.0, 4.9, 4.8, 0.0, -0.1, -7.0],
            vec![1.0, 1.0, 1.0, 0.0, 0.0, -1.0],
            vec![0.5; 9],
            vec![2.0],
            vec![],
        ];
        lists.push((0..50).map(|k| -((k * k) as f64) * 0.01).collect());
        for levels in &lists {
            let guess = Guesser::new(levels);
            let mut zs: Vec<f64> = levels.clone();
            zs.extend(levels.windows(2).map(|w| 0.5 * (w[0] + w[1])));
            zs.extend([1e9, -1e9, 0.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY]);
            for &z in &zs {
                for pred in [|h: f64, z: f64| h > z, |h: f64, z: f64| h >= z] {
                    let want = levels.partition_point(|&h| pred(h, z));
                    assert_eq!(
                        partition_near(levels, guess.at(z), |h| pred(h, z)),
                        want,
                        "z = {z} in {levels:?}"
                    );
                }
                // The first level below z, stepped to from the first at or below it.
                let at = levels.partition_point(|&h| h > z);
                assert_eq!(
                    step_over_equal(levels, at, z),
                    levels.partition_point(|&h| h >= z),
                    "below z = {z} in {levels:?}"
                );
            }
        }
    }

    #[test]
    fn ratios_at_many_levels_equal_the_ratio_at_each_level() {
        for (xs, zs) in test_curves() {
            let (bottom, top) = crate::extremes::min_max(&zs);
            // The bearing curve's levels (on the quantised curve 101 levels over a range of 9
            // fall on every sample height), levels outside the range, and repeated levels.
            let mut cases = vec![
                equal_levels(top, bottom, 101),
                equal_levels(top, bottom, 10),
            ];
            cases.push(vec![
                top + 1.0,
                top,
                0.5 * (top + bottom),
                bottom,
                bottom - 1.0,
            ]);
            cases.push(vec![0.0, 0.0, 0.0, -0.5, -0.5]);
            for levels in &cases {
                let slow: Vec<f64> = levels.iter().map(|&h| material_ratio_pct(&zs, h)).collect();
                assert_close(&material_ratios_pct(&zs, levels), &slow, "uniform");
                let slow: Vec<f64> = levels
                    .iter()
                    .map(|&h| material_ratio_xz_pct(&xs, &zs, h))
                    .collect();
                assert_close(&material_ratios_xz_pct(&xs, &zs, levels), &slow, "x, z");
            }
            // Levels in no order take the per-level way: the same bits.
            let shuffled = [
                bottom,
                top,
                0.3 * top + 0.7 * bottom,
                0.9 * top + 0.1 * bottom,
            ];
            let slow: Vec<f64> = shuffled
                .iter()
                .map(|&h| material_ratio_pct(&zs, h))
                .collect();
            assert_eq!(material_ratios_pct(&zs, &shuffled), slow);
        }
    }

    #[test]
    fn bearing_curves_equal_the_per_level_computation() {
        for (xs, zs) in test_curves() {
            let curve = bearing_curve_xz(&xs, &zs, 101).unwrap();
            // As the curve was computed before: heights about the mean, equal levels, each
            // level's ratio on its own.
            let z: Vec<f64> = zs.iter().map(|h| h - curve.mean_line_um).collect();
            let (bottom, top) = crate::extremes::min_max(&z);
            let (heights, ratios): (Vec<f64>, Vec<f64>) =
                curve.points.iter().map(|p| (p[0], p[1])).unzip();
            let slow: Vec<f64> = (0..101)
                .map(|k| {
                    let h = top - (top - bottom) * k as f64 / 100.0;
                    assert_eq!(heights[k].to_bits(), h.to_bits(), "level {k}");
                    match k {
                        0 => 0.0,
                        100 => 100.0,
                        _ => material_ratio_xz_pct(&xs, &z, h),
                    }
                })
                .collect();
            assert_close(&ratios, &slow, "bearing curve");
        }
    }

    #[test]
    fn the_level_at_a_material_ratio_inverts_the_ratio() {
        // A ramp from 0 to 1: the ratio at level h is (1 − h) · 100 %, so C(mr) = 1 − mr/100.
        let ramp: Vec<f64> = (0..=100).map(|i| i as f64 / 100.0).collect();
        for mr in [0.0, 2.5, 10.0, 25.0, 50.0, 99.0, 100.0] {
            let c = level_at_material_ratio(&ramp, mr);
            assert!((c - (1.0 - mr / 100.0)).abs() < 1e-10, "mr {mr}: {c}");
        }
        // A flat top holding 20 % of the length: every level up to it has at least 20 %.
        let mut plateau = vec![1.0; 21];
        plateau.extend((0..80).map(|i| 1.0 - (i + 1) as f64 / 80.0));
        let c = level_at_material_ratio(&plateau, 10.0);
        assert!((c - 1.0).abs() < 1e-10, "{c}");
        assert!((material_ratio_pct(&plateau, c) - 20.0).abs() < 1e-9);
    }

    /// The bisection over the straddling segments takes every step the plain bisection takes:
    /// the same level to the bit, on rough curves, ramps, plateaus, steps and a curve with a
    /// NaN.
    #[test]
    fn the_narrowed_bisection_gives_the_plain_bisections_level() {
        let mut seed = 7u64;
        let mut curves: Vec<Vec<f64>> = test_curves().into_iter().map(|(_, z)| z).collect();
        curves.push((0..8000).map(|_| lcg(&mut seed) * 4.0 - 2.0).collect());
        curves.push(
            (0..3000)
                .map(|i| ((i as f64) * 0.01).sin() + 0.01 * lcg(&mut seed))
                .collect(),
        );
        let mut plateau = vec![1.0; 21];
        plateau.extend((0..80).map(|i| 1.0 - (i + 1) as f64 / 80.0));
        curves.push(plateau);
        curves.push((0..500).map(|i| f64::from((i / 50) % 3 == 0)).collect());
        curves.push(vec![0.25, -0.5]);
        curves.push(vec![3.0, 3.0, 3.0]);
        curves.push(vec![0.0, 1.0, f64::NAN, 0.5, 0.2]);
        let mut checked = 0;
        for z in &curves {
            let (bottom, top) = crate::extremes::min_max(z);
            for mr in [1e-9, 0.5, 2.5, 10.0, 20.0, 33.3, 50.0, 80.0, 97.5, 99.999] {
                let fast = level_at_material_ratio(z, mr);
                let plain = bisect_by_full_passes(z, mr, top, bottom);
                assert_eq!(
                    fast.to_bits(),
                    plain.to_bits(),
                    "{} points, mr {mr}",
                    z.len()
                );
                checked += 1;
            }
        }
        assert_eq!(checked, curves.len() * 10);
    }
}
