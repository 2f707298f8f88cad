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

use super::{check_finite, MetrologyError};
use serde::Serialize;

/// Material ratio in % of a piecewise-linear curve through `heights` (uniform spacing) at
/// `level`: the fraction of its length where the curve is at or above `level`.
pub fn material_ratio_pct(heights: &[f64], level: f64) -> f64 {
    if heights.len() < 2 {
        return match heights.first() {
            Some(z) if *z >= level => 100.0,
            _ => 0.0,
        };
    }
    let mut inside = 0.0;
    for w in heights.windows(2) {
        let (a, b) = match w {
            [a, b] => (*a, *b),
            _ => continue,
        };
        let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
        if lo >= level {
            inside += 1.0;
        } else if hi > level {
            inside += (hi - level) / (hi - lo);
        }
    }
    inside / (heights.len() - 1) as f64 * 100.0
}

/// C(mr): the level at which the material ratio of the piecewise-linear curve through
/// `heights` (uniform spacing) is `mr_pct`, the inverse of [`material_ratio_pct`] (which falls
/// continuously from 100 % at the lowest point to 0 % at the highest). C(0) is the highest
/// point, C(100) the lowest; in between, bisection to 1e-12 of the height range. Where the
/// curve is flat (a level holding a whole segment) the highest such level is returned.
pub fn level_at_material_ratio(heights: &[f64], mr_pct: f64) -> f64 {
    let top = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let bottom = heights.iter().copied().fold(f64::INFINITY, f64::min);
    if !(top.is_finite() && bottom.is_finite()) || mr_pct <= 0.0 {
        return top;
    }
    if mr_pct >= 100.0 {
        return bottom;
    }
    // material_ratio_pct(level) is non-increasing in level: find its crossing of mr_pct.
    let (mut lo, mut hi) = (bottom, top);
    while hi - lo > 1e-12 * (top - bottom).max(f64::MIN_POSITIVE) {
        let mid = 0.5 * (lo + hi);
        if material_ratio_pct(heights, mid) >= mr_pct {
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
    check_finite(zs)?;
    check_finite(xs)?;
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
    if levels < 2 {
        return Err(MetrologyError::BadParameter {
            what: "levels",
            value: levels as f64,
            hint: "give at least 2 height levels (the paper uses 101)",
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
    Ok(curve_about_mean(zs, mean, levels, |z, h| {
        material_ratio_xz_pct(xs, z, h)
    }))
}

/// Heights referenced to `mean`, `levels` equal levels from the highest point (0 %) to the
/// lowest (100 %), the ratio at each interior level from `ratio(referenced heights, level)`.
fn curve_about_mean(
    heights: &[f64],
    mean: f64,
    levels: usize,
    ratio: impl Fn(&[f64], f64) -> f64,
) -> BearingCurve {
    let z: Vec<f64> = heights.iter().map(|h| h - mean).collect();
    let top = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let bottom = z.iter().copied().fold(f64::INFINITY, f64::min);
    let points = (0..levels)
        .map(|k| {
            let h = top - (top - bottom) * k as f64 / (levels - 1) as f64;
            let mr = if k == 0 {
                0.0
            } else if k == levels - 1 {
                100.0
            } else {
                ratio(&z, h)
            };
            [h, mr]
        })
        .collect();
    BearingCurve {
        mean_line_um: mean,
        points,
    }
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

/// The bearing area curve of a uniformly sampled curve with `levels` equal height levels
/// (101 in the paper) spanning its range. The mean line is the mean of the piecewise-linear
/// curve (trapezoidal rule).
pub fn bearing_curve(heights: &[f64], levels: usize) -> Result<BearingCurve, MetrologyError> {
    check_finite(heights)?;
    if heights.len() < 2 {
        return Err(MetrologyError::TooShort {
            points: heights.len(),
            length_mm: 0.0,
            sampling_length_mm: 0.0,
            min_points: 2,
        });
    }
    if levels < 2 {
        return Err(MetrologyError::BadParameter {
            what: "levels",
            value: levels as f64,
            hint: "give at least 2 height levels (the paper uses 101)",
        });
    }
    let n = heights.len();
    let first = heights.first().copied().unwrap_or(0.0);
    let last = heights.last().copied().unwrap_or(0.0);
    let mean = (heights.iter().sum::<f64>() - 0.5 * (first + last)) / (n - 1) as f64;
    Ok(curve_about_mean(heights, mean, levels, material_ratio_pct))
}

/// The bearing area curve of a curve given as a function of x (mm, heights in µm), sampled at
/// `samples` uniform points over `[x0_mm, x1_mm]` (dense, not just at the data points).
pub fn bearing_curve_of<F: Fn(f64) -> f64>(
    curve: F,
    x0_mm: f64,
    x1_mm: f64,
    samples: usize,
    levels: usize,
) -> Result<BearingCurve, MetrologyError> {
    if !(x0_mm.is_finite() && x1_mm.is_finite() && x1_mm > x0_mm) {
        return Err(MetrologyError::BadParameter {
            what: "x range length (mm)",
            value: x1_mm - x0_mm,
            hint: "the curve's x range must be finite with x1 > x0",
        });
    }
    if samples < 2 {
        return Err(MetrologyError::BadParameter {
            what: "samples",
            value: samples as f64,
            hint: "sample the curve at 2 points or more (densely: several per data point)",
        });
    }
    let dx = (x1_mm - x0_mm) / (samples - 1) as f64;
    let z: Vec<f64> = (0..samples).map(|i| curve(x0_mm + i as f64 * dx)).collect();
    bearing_curve(&z, levels)
}

/// The pooled material ratio curve of several curves of equal length and spacing: at each level
/// the cross-line lengths of all curves are summed over their total length. Heights are each
/// referenced to their own mean line; levels span the pooled range.
pub fn pooled_bearing_curve(
    curves: &[Vec<f64>],
    levels: usize,
) -> Result<BearingCurve, MetrologyError> {
    let mut centred = Vec::with_capacity(curves.len());
    for c in curves {
        let b = bearing_curve(c, 2)?;
        centred.push(c.iter().map(|h| h - b.mean_line_um).collect::<Vec<f64>>());
    }
    if centred.is_empty() {
        return Err(MetrologyError::BadParameter {
            what: "curves",
            value: 0.0,
            hint: "give at least one curve",
        });
    }
    if levels < 2 {
        return Err(MetrologyError::BadParameter {
            what: "levels",
            value: levels as f64,
            hint: "give at least 2 height levels (the paper uses 101)",
        });
    }
    let top = centred
        .iter()
        .flatten()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let bottom = centred
        .iter()
        .flatten()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let weights: Vec<f64> = centred.iter().map(|c| (c.len() - 1) as f64).collect();
    let total: f64 = weights.iter().sum();
    let points = (0..levels)
        .map(|k| {
            let h = top - (top - bottom) * k as f64 / (levels - 1) as f64;
            let mr = centred
                .iter()
                .zip(&weights)
                .map(|(c, w)| material_ratio_pct(c, h) * w)
                .sum::<f64>()
                / total;
            [h, mr]
        })
        .collect();
    Ok(BearingCurve {
        mean_line_um: 0.0,
        points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
