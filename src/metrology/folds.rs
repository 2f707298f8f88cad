//! Is the fitted surface still a height map, and does it stay within what was measured?
//!
//! An interpolant can fold: when one line holds a spike, the chord-length parameters give the
//! spike a large share of u, the degree-5 solve swings, and x runs backwards along the
//! iso-curves (the surface then has several heights over one x, which no CAD or FE height
//! model expects). Between uncorrelated lines it can also overshoot far beyond the measured
//! heights. The checks, all on the surface as fitted:
//!
//! * **control net**: x must increase from pole to pole along u in every pole row, and y
//!   along v in every pole column (a fold of the net is where a fold of the surface comes from);
//! * **iso-curves along u** at every data line's v and at `between` equally spaced v inside
//!   each interval between lines, each sampled at `samples_per_pole` points per pole along u:
//!   x must increase; a backward run is reported with its x range and how far x runs back;
//! * **iso-curves along v** at `count_u` equally spaced u, sampled likewise along v: y must
//!   increase;
//! * **height range**: the highest and lowest point of the iso-curve samples against the
//!   measured heights' range; the overshoot (how far the model goes beyond the measured range,
//!   above plus below) is reported in µm and in % of the measured range, and named as a
//!   warning beyond [`OVERSHOOT_WARN_PCT`].
//!
//! Depends on [`crate::nurbs`], [`super::sampling`] (the dense samples), [`crate::extremes`]
//! and [`crate::numfmt`] (the warnings' figures).

use super::sampling::{equally_spaced, Basis, TwoLanes};
use crate::extremes::min_max;
use crate::numfmt::{fmt, Quantity};
use crate::nurbs::{BSplineCurve, NurbsSurface, UBasis};
use serde::Serialize;

/// An overshoot beyond this share of the measured height range is named as a warning (%).
pub const OVERSHOOT_WARN_PCT: f64 = 10.0;

/// How densely the surface is sampled. [`Default`]: 8 samples per pole, 3 iso-curves between
/// consecutive lines.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FoldOptions {
    /// Samples per pole along an iso-curve.
    pub samples_per_pole: usize,
    /// Iso-curves along u inside each interval between data lines.
    pub between: usize,
}

impl Default for FoldOptions {
    fn default() -> FoldOptions {
        FoldOptions {
            samples_per_pole: 8,
            between: 3,
        }
    }
}

/// Where the control net runs backwards in one direction.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NetFold {
    /// "u" (x along pole rows) or "v" (y along pole columns).
    pub direction: &'static str,
    /// Pole rows (u) or columns (v) with at least one backward step.
    pub affected: usize,
    /// Pole rows (u) or columns (v) checked.
    pub checked: usize,
    /// The first backward step: row (u) or column (v) index.
    pub at_line: usize,
    /// The first backward step: pole index i → i + 1 along the direction.
    pub at_pole: usize,
    /// The coordinate (x for u, y for v) at pole i and i + 1, mm.
    pub from_mm: f64,
    /// See `from_mm`.
    pub to_mm: f64,
    /// Largest backward step over the whole net, mm.
    pub worst_back_mm: f64,
}

/// Where sampled iso-curves run backwards in one direction.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IsoFold {
    /// "u" (x along iso-curves of constant v) or "v" (y along iso-curves of constant u).
    pub direction: &'static str,
    /// Iso-curves with a backward run.
    pub affected: usize,
    /// Iso-curves checked.
    pub checked: usize,
    /// The fixed parameter of the worst curve (v for u-curves, u for v-curves).
    pub at_parameter: f64,
    /// The other coordinate of the worst curve at its start, mm (y for u-curves, x for
    /// v-curves).
    pub at_mm: f64,
    /// The coordinate range over which the worst curve runs back, mm (lower, upper).
    pub range_mm: [f64; 2],
    /// How far it runs back, mm.
    pub back_mm: f64,
}

impl IsoFold {
    /// Where and how far the worst curve runs back, in words, with `dots` for a range and
    /// `um` for micrometres (ASCII for an IGES Start section).
    pub fn words(&self, dots: &str, um: &str) -> String {
        let (c, other) = [("x", "y"), ("y", "x")][usize::from(self.direction != "u")];
        let mm = |v: f64| fmt(v, Quantity::PositionMm);
        format!(
            "{c} runs backwards along {} by up to {} {um} ({c} {} {dots} {} mm) on {} of {} iso-curves (worst at {other} = {} mm)",
            self.direction,
            fmt(self.back_mm * 1000.0, Quantity::HeightUm),
            mm(self.range_mm[0]),
            mm(self.range_mm[1]),
            self.affected,
            self.checked,
            mm(self.at_mm)
        )
    }
}

/// The model's sampled height range against the measured one.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HeightRange {
    /// Lowest sampled model height, µm.
    pub model_min_um: f64,
    /// Highest sampled model height, µm.
    pub model_max_um: f64,
    /// (x, y) in mm of the lowest sample.
    pub model_min_at_mm: [f64; 2],
    /// (x, y) in mm of the highest sample.
    pub model_max_at_mm: [f64; 2],
    /// Lowest measured height, µm.
    pub measured_min_um: f64,
    /// Highest measured height, µm.
    pub measured_max_um: f64,
    /// How far the model goes beyond the measured range (above plus below), µm.
    pub overshoot_um: f64,
    /// The same in % of the measured range.
    pub overshoot_pct: f64,
    /// Points sampled.
    pub samples: usize,
}

/// Every check of the module.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelChecks {
    /// Backward steps of the control net, per direction (absent: none).
    pub net: Vec<NetFold>,
    /// Backward runs of the sampled iso-curves, per direction (absent: none).
    pub iso_curves: Vec<IsoFold>,
    /// The height range.
    pub height_range: HeightRange,
    /// How the surface was sampled.
    pub recipe: String,
}

impl ModelChecks {
    /// True when a sampled iso-curve runs backwards (the surface is not a height map).
    pub fn folds(&self) -> bool {
        !self.iso_curves.is_empty()
    }

    /// The warnings of [`ModelChecks::warnings`] that name a fold, of the surface or of its net.
    pub fn fold_warnings(&self) -> Vec<String> {
        let mut w = self.warnings();
        w.truncate(self.iso_curves.len() + self.net.len());
        w
    }

    /// One warning per finding: folds of the surface and of its net, and an overshoot beyond
    /// [`OVERSHOOT_WARN_PCT`].
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        w.extend(
            (self.iso_curves.iter().map(|f| f.words("…", "µm")))
                .map(|f| format!("model fold: {f}; the surface is not a height map there")),
        );
        for f in &self.net {
            let (c, what) = if f.direction == "u" {
                ("x", "pole rows")
            } else {
                ("y", "pole columns")
            };
            w.push(format!(
                "control net fold: {c} decreases from pole {} to {} ({c} {} → {} mm) in {} of {} {what} (largest step back {} µm)",
                f.at_pole + 1,
                f.at_pole + 2,
                fmt(f.from_mm, Quantity::PositionMm),
                fmt(f.to_mm, Quantity::PositionMm),
                f.affected,
                f.checked,
                fmt(f.worst_back_mm * 1000.0, Quantity::HeightUm)
            ));
        }
        let h = &self.height_range;
        if h.overshoot_pct > OVERSHOOT_WARN_PCT {
            let (um, mm) = (Quantity::HeightUm, Quantity::PositionMm);
            w.push(format!(
                "model overshoot: sampled densely, the model spans {} … {} µm where the measured heights span {} … {} µm ({} % beyond the measured range; highest at x = {}, y = {} mm, lowest at x = {}, y = {} mm)",
                fmt(h.model_min_um, um),
                fmt(h.model_max_um, um),
                fmt(h.measured_min_um, um),
                fmt(h.measured_max_um, um),
                fmt(h.overshoot_pct, Quantity::Percent),
                fmt(h.model_max_at_mm[0], mm),
                fmt(h.model_max_at_mm[1], mm),
                fmt(h.model_min_at_mm[0], mm),
                fmt(h.model_min_at_mm[1], mm)
            ));
        }
        w
    }
}

/// Whether a [`UBasis`] of `n` equally spaced parameters on these knots is applied by the
/// shared sampler (a degree its stack buffers hold, a knot vector that fits `count` poles, at
/// least two samples): each point is then the one [`samples`] gives, to the bit.
fn basis_fits(degree: usize, knots: &[f64], count: usize, n: usize) -> bool {
    degree <= 15 && count > degree && knots.len() == count + degree + 1 && n >= 2
}

/// Samples of a curve at `n` equally spaced parameters in [0, 1].
fn samples(curve: &BSplineCurve, n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .filter_map(|k| curve.evaluate(k as f64 / (n - 1) as f64))
        .collect()
}

/// The worst backward run of an iso-curve so far: (fixed parameter, the other coordinate at
/// its start in mm, (lower, upper, back) in mm).
type Worst = (f64, f64, (f64, f64, f64));

/// The worst backward run of the `n` values `at(0..n)`: (lower, upper, back) in mm.
#[inline(always)]
fn backward_run_by(n: usize, at: impl Fn(usize) -> f64) -> Option<(f64, f64, f64)> {
    let mut worst: Option<(f64, f64, f64)> = None;
    let mut k = 1;
    while k < n {
        if at(k) > at(k - 1) {
            k += 1;
            continue;
        }
        let top = at(k - 1);
        let mut bottom = at(k);
        while k + 1 < n && at(k + 1) <= at(k) {
            k += 1;
            bottom = at(k);
        }
        let back = top - bottom;
        if worst.is_none_or(|w| back > w.2) {
            worst = Some((bottom, top, back));
        }
        k += 1;
    }
    worst
}

/// Whether every value is greater than the one before it (NaN never is).
fn strictly_increasing(values: &[f64]) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            return unsafe { strictly_increasing_avx2(values) };
        }
    }
    values.windows(2).all(|w| w[1] > w[0])
}

/// [`strictly_increasing`], four pairs at a time.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn strictly_increasing_avx2(values: &[f64]) -> bool {
    use std::arch::x86_64::*;
    let Some(pairs) = values.len().checked_sub(1) else {
        return true;
    };
    let whole = pairs / 4 * 4;
    let mut k = 0;
    while k < whole {
        let (a, b) = (&values[k..k + 4], &values[k + 1..k + 5]);
        // SAFETY: `a` and `b` hold four readable f64 each.
        let gt = unsafe {
            _mm256_cmp_pd::<_CMP_GT_OQ>(_mm256_loadu_pd(b.as_ptr()), _mm256_loadu_pd(a.as_ptr()))
        };
        if _mm256_movemask_pd(gt) != 0b1111 {
            return false;
        }
        k += 4;
    }
    values[k..].windows(2).all(|w| w[1] > w[0])
}

/// Where the control net of `surface` runs backwards: x from pole to pole along u in a pole
/// row, y along v in a pole column (absent: none). A net that runs forwards everywhere makes a
/// surface that does (every iso-curve is a convex combination of the pole rows, its
/// derivative a positive combination of their steps), so a clean net rules a fold out at the
/// cost of one pass over the poles; only a net with a backward step needs the sampled
/// iso-curves of [`check_model`] to say whether and where the surface itself folds.
pub fn net_folds(surface: &NurbsSurface) -> Vec<NetFold> {
    let (nu, nv) = (surface.count_u(), surface.count_v());
    // The pole rows' views once (x and y read from them, not a pole assembled per step).
    let rows: Vec<_> = surface.net().rows().collect();
    let mut net = Vec::new();
    for (direction, lines, along) in [("u", nv, nu), ("v", nu, nv)] {
        let (mut affected, mut first, mut worst) = (0usize, None, 0.0f64);
        for line in 0..lines {
            let mut hit = false;
            for i in 0..along.saturating_sub(1) {
                let (a, b) = if direction == "u" {
                    (rows[line].x[i], rows[line].x[i + 1])
                } else {
                    (rows[i].y.at(line), rows[i + 1].y.at(line))
                };
                if b <= a {
                    hit = true;
                    worst = worst.max(a - b);
                    first.get_or_insert((line, i, a, b));
                }
            }
            affected += usize::from(hit);
        }
        if let Some((at_line, at_pole, from_mm, to_mm)) = first {
            net.push(NetFold {
                direction,
                affected,
                checked: lines,
                at_line,
                at_pole,
                from_mm,
                to_mm,
                worst_back_mm: worst,
            });
        }
    }
    net
}

/// How many equally spaced u the fold check samples each iso-curve at: `samples_per_pole`
/// per pole (at least one), and never fewer than two.
pub fn iso_curve_sample_count(surface: &NurbsSurface, options: &FoldOptions) -> usize {
    (options.samples_per_pole.max(1) * surface.count_u()).max(2)
}

/// The v of the iso-curves along u: each line's, and `between` equally spaced inside each
/// interval between consecutive lines (0 and 1 without lines).
fn iso_vs_along_u(line_vs: &[f64], between: usize) -> Vec<f64> {
    if line_vs.is_empty() {
        return vec![0.0, 1.0];
    }
    let mut vs = Vec::new();
    for w in line_vs.windows(2) {
        vs.push(w[0]);
        vs.extend((1..=between).map(|b| w[0] + (w[1] - w[0]) * b as f64 / (between + 1) as f64));
    }
    vs.extend(line_vs.last());
    vs
}

/// Checks the control net, the sampled iso-curves and the height range of `surface` fitted to
/// data lines at parameters `line_vs` (increasing), against the measured `heights_um`.
pub fn check_model(
    surface: &NurbsSurface,
    line_vs: &[f64],
    heights_um: &[f64],
    options: &FoldOptions,
) -> ModelChecks {
    check_model_with(surface, line_vs, heights_um, options, None)
}

/// [`check_model`] with the u basis at the `samples_per_pole · count_u` equally spaced u of
/// the iso-curves already computed and regrouped (`TwoLanes` of the `UBasis::new` at
/// `k / (n − 1)`, as the model's bearing curves sample them): used where it has that length
/// and the degree is one the fold check builds its own basis for, so every sum is the one
/// [`check_model`] makes, to the bit.
pub fn check_model_with(
    surface: &NurbsSurface,
    line_vs: &[f64],
    heights_um: &[f64],
    options: &FoldOptions,
    shared_u: Option<&TwoLanes<'_>>,
) -> ModelChecks {
    let (nu, nv) = (surface.count_u(), surface.count_v());
    let per = options.samples_per_pole.max(1);

    let net = net_folds(surface);

    // Iso-curves along u at and between the lines; they also give the height range.
    let vs = iso_vs_along_u(line_vs, options.between);
    let n_u = iso_curve_sample_count(surface, options);
    let us = equally_spaced(n_u);
    let mut range = (f64::INFINITY, [0.0; 2], f64::NEG_INFINITY, [0.0; 2]);
    let mut fold_u: (usize, Option<Worst>) = (0, None);
    // The u basis is computed once for every iso-curve (all are sampled at the same u), and
    // one curve is held at a time. Only x (for the fold) and z (for the range) are summed at
    // every sample; y where a sample becomes the highest or lowest, or starts a folding
    // curve. Each lane is the sum `evaluate_grid` makes for it, to the bit.
    // A shared basis of the right length is the one made here.
    let fits = basis_fits(surface.degree_u(), surface.knots_u(), nu, n_u);
    let shared_u = shared_u.filter(|b| b.basis.first.len() == n_u && fits);
    let own_u = (shared_u.is_none() && fits).then(|| UBasis::new(surface, &us));
    let own_lanes = own_u.as_ref().map(|b| TwoLanes::new(Basis::of(b)));
    let xz_sampler = shared_u.or(own_lanes.as_ref());
    let u_sampler: Option<Basis<'_>> = xz_sampler.map(|l| l.basis);
    let general = u_sampler.is_none().then(|| UBasis::new(surface, &us));
    let mut poles = Vec::new();
    let (mut xs, mut zs): (Vec<f64>, Vec<f64>) = (Vec::with_capacity(n_u), Vec::with_capacity(n_u));
    let mut ys = Vec::new(); // y of every sample where no sampler gives it alone
    for &v in &vs {
        surface.iso_poles_u_padded(v, &mut poles);
        xs.clear();
        ys.clear();
        zs.clear();
        match (&xz_sampler, &general) {
            (Some(b), _) => b.points(&poles, [0, 2], &mut xs, &mut zs),
            (None, Some(g)) => g.for_each_point(&poles, |_, p| {
                xs.push(p[0]);
                ys.push(p[1]);
                zs.push(p[2]);
            }),
            (None, None) => {}
        }
        let y_at = |k| u_sampler.map_or(ys.get(k).copied(), |b| Some(b.lane(&poles, k, 1)));
        let y_at = |k: usize| y_at(k).unwrap_or(f64::NAN);
        // The lowest and highest sample in µm, each where it first occurs: what a running
        // strict comparison over the samples, carried from curve to curve, keeps (scaling
        // keeps the order, so the scaled extremes are the extremes of the scaled samples).
        let (lo, hi) = min_max(&zs);
        let (lo, hi) = (lo * 1000.0, hi * 1000.0);
        let first_equal = |h: f64| zs.iter().position(|&z| z * 1000.0 == h).unwrap_or(0);
        if lo < range.0 {
            let k = first_equal(lo);
            range.0 = zs[k] * 1000.0;
            range.1 = [xs[k], y_at(k)];
        }
        if hi > range.2 {
            let k = first_equal(hi);
            range.2 = zs[k] * 1000.0;
            range.3 = [xs[k], y_at(k)];
        }
        // Most curves do not fold: one vector pass says so.
        let run = if strictly_increasing(&xs) {
            None
        } else {
            backward_run_by(xs.len(), |k| xs[k])
        };
        if let Some(run) = run {
            fold_u.0 += 1;
            if fold_u.1.is_none_or(|(_, _, w)| run.2 > w.2) {
                fold_u.1 = Some((v, y_at(0), run));
            }
        }
    }
    let n_v = (per * nv).max(2);
    let mut fold_v: (usize, Option<Worst>) = (0, None);
    let curves_v = nu.max(2);
    let v_basis = basis_fits(surface.degree_v(), surface.knots_v(), nv, n_v)
        .then(|| UBasis::along_v(surface, &equally_spaced(n_v)));
    // Only y (for the fold) and x (where a folding curve starts) of each sample are needed.
    let v_lanes = v_basis.as_ref().map(|b| TwoLanes::new(Basis::of(b)));
    let (mut ys, mut xs) = (Vec::with_capacity(n_v), Vec::with_capacity(n_v));
    let mut padded = Vec::with_capacity(nv);
    for k in 0..curves_v {
        let u = k as f64 / (curves_v - 1) as f64;
        let iso = surface.iso_curve_v(u);
        ys.clear();
        xs.clear();
        match &v_lanes {
            Some(b) => {
                padded.clear();
                padded.extend(iso.poles.iter().map(|q| [q[0], q[1], q[2], 0.0]));
                b.points(&padded, [1, 0], &mut ys, &mut xs);
            }
            None => samples(&iso, n_v).into_iter().for_each(|p| {
                ys.push(p[1]);
                xs.push(p[0]);
            }),
        }
        if let Some(run) = backward_run_by(ys.len(), |k| ys[k]) {
            fold_v.0 += 1;
            if fold_v.1.is_none_or(|(_, _, w)| run.2 > w.2) {
                fold_v.1 = Some((u, xs.first().copied().unwrap_or(f64::NAN), run));
            }
        }
    }
    // The worst backward run of each direction, u first.
    let mut iso = Vec::new();
    for (direction, (affected, worst), checked) in
        [("u", fold_u, vs.len()), ("v", fold_v, curves_v)]
    {
        if let Some((at_parameter, at_mm, (lo, hi, back_mm))) = worst {
            iso.push(IsoFold {
                direction,
                affected,
                checked,
                at_parameter,
                at_mm,
                range_mm: [lo, hi],
                back_mm,
            });
        }
    }

    let (mmin, mmax) = min_max(heights_um);
    let overshoot = (range.2 - mmax).max(0.0) + (mmin - range.0).max(0.0);
    let span = mmax - mmin;
    ModelChecks {
        net,
        iso_curves: iso,
        height_range: HeightRange {
            model_min_um: range.0,
            model_max_um: range.2,
            model_min_at_mm: range.1,
            model_max_at_mm: range.3,
            measured_min_um: mmin,
            measured_max_um: mmax,
            overshoot_um: overshoot,
            overshoot_pct: if span > 0.0 {
                overshoot / span * 100.0
            } else {
                0.0
            },
            samples: vs.len() * n_u,
        },
        recipe: format!(
            "control net: x strictly increasing along u in every pole row, y along v in every pole column; iso-curves along u at the {} data lines and {} equally spaced v between consecutive lines, iso-curves along v at {} equally spaced u, each sampled at {} points per pole; height range over the u iso-curve samples; overshoot beyond {} % of the measured range is a warning",
            line_vs.len(),
            options.between,
            curves_v,
            per,
            OVERSHOOT_WARN_PCT
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{fit_grid, FitOptions};
    use crate::metrology::{test_fit, test_grid};

    #[test]
    fn iso_curves_along_v_sampled_once_equal_each_curve_evaluated() {
        // The basis along v computed once, applied to every iso-curve along v, gives each
        // point as the curve's own evaluation does, to the bit.
        let (rows, cols) = (11, 90);
        let y: Vec<f64> = (0..rows)
            .map(|r| r as f64 * 0.01 + (r as f64 * 0.7).sin() * 0.002)
            .collect();
        let z: Vec<f64> = (0..rows * cols)
            .map(|k| 2.0 * ((k % cols) as f64 * 0.31).sin() + ((k / cols) as f64 * 1.3).cos())
            .collect();
        let fit = fit_grid(0.002, &y, &z, cols, FitOptions::default()).unwrap();
        let s = &fit.surface;
        for n in [2, 7, 8 * s.count_v()] {
            let b = UBasis::along_v(s, &equally_spaced(n));
            let lanes = TwoLanes::new(Basis::of(&b));
            for k in 0..s.count_u() {
                let iso = s.iso_curve_v(k as f64 / (s.count_u() - 1) as f64);
                let padded: Vec<[f64; 4]> =
                    iso.poles.iter().map(|q| [q[0], q[1], q[2], 0.0]).collect();
                let want = samples(&iso, n);
                for pair in [[1, 0], [2, 1]] {
                    let (mut a, mut c) = (Vec::new(), Vec::new());
                    lanes.points(&padded, pair, &mut a, &mut c);
                    assert_eq!((a.len(), c.len()), (want.len(), want.len()));
                    for (j, q) in want.iter().enumerate() {
                        assert_eq!(
                            [a[j].to_bits(), c[j].to_bits()],
                            [q[pair[0]].to_bits(), q[pair[1]].to_bits()],
                            "curve {k}, {n} samples, point {j}, lanes {pair:?}"
                        );
                    }
                }
            }
        }
        assert!(!basis_fits(s.degree_v(), s.knots_v(), s.count_v() + 1, 10));
    }

    /// The vector extremes and the increase test agree with the running strict comparisons
    /// they replace: on every length up to 13 (whole vectors and remainders), with NaN,
    /// signed zeros, infinities, ties and values that the scale rounds together; the first
    /// index holding the extreme is the one the running comparison keeps, with its bits.
    #[test]
    fn vector_extremes_and_increase_test_are_the_running_comparisons() {
        let specials = [
            f64::NAN,
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e308,
            -1e308,
            1.0,
            1.0 + f64::EPSILON,
            -3.5,
        ];
        // The generator's top 31 bits (its 53 scaled by 2^-22, exactly).
        let mut s = 7u64;
        let mut pick = || (crate::metrology::lcg(&mut s) * (1u64 << 31) as f64) as usize;
        for len in 0..=13 {
            for _ in 0..400 {
                let v: Vec<f64> = (0..len)
                    .map(|_| match pick() % 3 {
                        0 => specials[pick() % specials.len()],
                        1 => (pick() % 7) as f64 * 0.25 - 0.5,
                        _ => (pick() % 1000) as f64 * 1e-3,
                    })
                    .collect();
                // The loop that the check ran over each curve, from an empty range.
                let (mut lo, mut lo_at, mut hi, mut hi_at) =
                    (f64::INFINITY, None, f64::NEG_INFINITY, None);
                for (k, &z) in v.iter().enumerate() {
                    let z = z * 1000.0;
                    if z < lo {
                        (lo, lo_at) = (z, Some(k));
                    }
                    if z > hi {
                        (hi, hi_at) = (z, Some(k));
                    }
                }
                let (l, h) = min_max(&v);
                let (l, h) = (l * 1000.0, h * 1000.0);
                let first = |x: f64| v.iter().position(|&z| z * 1000.0 == x);
                let at = |found: f64| (found < f64::INFINITY).then(|| first(found)).flatten();
                assert_eq!(at(l), lo_at, "{v:?}: lowest at");
                let first_hi = (h > f64::NEG_INFINITY).then(|| first(h)).flatten();
                assert_eq!(first_hi, hi_at, "{v:?}: highest at");
                if let Some(k) = lo_at {
                    assert_eq!((v[k] * 1000.0).to_bits(), lo.to_bits(), "{v:?}");
                }
                let increasing = v.windows(2).all(|w| w[1] > w[0]);
                assert_eq!(strictly_increasing(&v), increasing, "{v:?}");
                assert_eq!(
                    increasing,
                    backward_run_by(v.len(), |k| v[k]).is_none(),
                    "{v:?}: the increase test stands for the backward run"
                );
            }
        }
        assert!(strictly_increasing(
            &(0..1000).map(f64::from).collect::<Vec<_>>()
        ));
    }

    /// The u iso-curve part of [`check_model`] as it was first written: every point of
    /// `evaluate_grid`, then the range and the fold. (fold count, worst, range.)
    #[allow(clippy::type_complexity)]
    fn u_checks_by_evaluate_grid(
        surface: &NurbsSurface,
        vs: &[f64],
        n_u: usize,
    ) -> ((usize, Option<Worst>), (f64, [f64; 2], f64, [f64; 2])) {
        let us = equally_spaced(n_u);
        let grid = surface.evaluate_grid(&us, vs);
        let mut range = (f64::INFINITY, [0.0; 2], f64::NEG_INFINITY, [0.0; 2]);
        let mut fold: (usize, Option<Worst>) = (0, None);
        for (&v, pts) in vs.iter().zip(grid.chunks_exact(n_u)) {
            for p in pts {
                let z = p[2] * 1000.0;
                if z < range.0 {
                    range = (z, [p[0], p[1]], range.2, range.3);
                }
                if z > range.2 {
                    range = (range.0, range.1, z, [p[0], p[1]]);
                }
            }
            if let Some(run) = backward_run_by(pts.len(), |k| pts[k][0]) {
                fold.0 += 1;
                if fold.1.is_none_or(|(_, _, w)| run.2 > w.2) {
                    fold.1 = Some((v, pts[0][1], run));
                }
            }
        }
        (fold, range)
    }

    /// A 9×120 grid fitted as it is (smooth) and with a 400 µm spike on one line (the fit
    /// folds): whether it has the spike, its heights and the fit.
    fn smooth_and_folding_fits() -> Vec<(bool, Vec<f64>, crate::fit::FitResult)> {
        let wavy = |r: usize, c: usize| 2.0 * (c as f64 * 0.21).sin() + (r as f64 * 0.9).cos();
        let mut g = test_grid(9, 120, 0.0005, wavy);
        let mut fits = Vec::new();
        for spike in [false, true] {
            if spike {
                g.heights_um[4 * 120 + 60] += 400.0;
            }
            fits.push((spike, g.heights_um.clone(), test_fit(&g)));
        }
        fits
    }

    #[test]
    fn the_u_checks_equal_those_of_every_point_evaluated() {
        // A smooth fit and one that folds (a spike on one line): the range, its places and
        // the folds are the bits of the straightforward evaluation.
        for (spike, z, fit) in smooth_and_folding_fits() {
            let s = &fit.surface;
            let options = FoldOptions::default();
            let c = check_model(s, &fit.params_v, &z, &options);
            let vs = iso_vs_along_u(&fit.params_v, options.between);
            let n_u = options.samples_per_pole * s.count_u();
            let ((count, worst), range) = u_checks_by_evaluate_grid(s, &vs, n_u);
            let h = &c.height_range;
            assert_eq!(
                (
                    h.model_min_um,
                    h.model_min_at_mm,
                    h.model_max_um,
                    h.model_max_at_mm
                ),
                range,
                "spike {spike}"
            );
            let fold = c.iso_curves.iter().find(|f| f.direction == "u");
            match worst {
                None => assert!(fold.is_none(), "spike {spike}: {fold:?}"),
                Some((v, y0, (lo, hi, back))) => {
                    let f = fold.expect("a fold along u");
                    assert_eq!(
                        (f.affected, f.at_parameter, f.at_mm, f.range_mm, f.back_mm),
                        (count, v, y0, [lo, hi], back)
                    );
                }
            }
            assert_eq!(spike, worst.is_some(), "the spike folds the surface");
        }
    }

    #[test]
    fn a_shared_u_basis_gives_the_checks_of_the_own_one() {
        // The u basis computed elsewhere (as the bearing curves compute theirs) for the same
        // samples: every figure is the bits of the fold check's own basis, on a smooth fit and
        // on one that folds; a basis of another length is not used.
        for (spike, z, fit) in smooth_and_folding_fits() {
            let s = &fit.surface;
            let options = FoldOptions::default();
            let own = check_model(s, &fit.params_v, &z, &options);
            assert_eq!(spike, own.folds(), "{own:?}");
            let n_u = options.samples_per_pole * s.count_u();
            for n in [n_u, n_u - 1] {
                let us = equally_spaced(n);
                let basis = UBasis::new(s, &us);
                let lanes = TwoLanes::new(Basis::of(&basis));
                let shared = check_model_with(s, &fit.params_v, &z, &options, Some(&lanes));
                assert_eq!(
                    format!("{shared:?}"),
                    format!("{own:?}"),
                    "spike {spike}, {n}"
                );
                assert_eq!(shared, own);
            }
        }
    }

    #[test]
    fn a_smooth_surface_neither_folds_nor_overshoots() {
        let wavy = |r: usize, c: usize| 2.0 * (c as f64 * 0.05).sin() + (r as f64 * 0.3).cos();
        let g = test_grid(8, 60, 0.002, wavy);
        let (fit, z) = (test_fit(&g), &g.heights_um);
        let c = check_model(&fit.surface, &fit.params_v, z, &FoldOptions::default());
        assert!(c.net.is_empty() && !c.folds(), "{c:?}");
        assert!(c.height_range.overshoot_pct < 2.0, "{:?}", c.height_range);
        assert!(c.warnings().is_empty(), "{:?}", c.warnings());
    }

    #[test]
    fn a_net_that_runs_back_is_named_with_its_place() {
        // A bilinear patch stretched so x goes 0 → 2 → 1 → 3 along u: the net and the
        // surface fold between the second and third pole.
        let mut poles = Vec::new();
        for y in [0.0, 1.0] {
            for x in [0.0, 2.0, 1.0, 3.0] {
                poles.push([x, y, 0.001 * x]);
            }
        }
        let s = NurbsSurface::try_new(
            1,
            1,
            vec![0.0, 0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0, 1.0],
            vec![0.0, 0.0, 1.0, 1.0],
            4,
            2,
            poles,
        )
        .unwrap();
        // 4 samples per pole put samples on the knots 1/3 and 2/3 (16 samples, 15 steps).
        let options = FoldOptions {
            samples_per_pole: 4,
            between: 3,
        };
        let c = check_model(&s, &[0.0, 1.0], &[0.0, 3.0], &options);
        let n = &c.net[0];
        assert_eq!((n.direction, n.affected, n.at_pole), ("u", 2, 1));
        assert_eq!((n.from_mm, n.to_mm), (2.0, 1.0));
        let f = &c.iso_curves[0];
        assert_eq!((f.direction, f.affected, f.checked), ("u", 5, 5));
        assert!(
            (f.back_mm - 1.0).abs() < 1e-12 && f.range_mm == [1.0, 2.0],
            "{f:?}"
        );
        let w = c.warnings().join("\n");
        assert!(
            w.contains("model fold: x runs backwards") && w.contains("x 1.0000 … 2.0000 mm"),
            "{w}"
        );
        assert!(w.contains("control net fold"), "{w}");
    }

    #[test]
    fn overshoot_is_measured_against_the_data_range() {
        // Lines alternating ±1 µm: the interpolant between them swings beyond ±1.
        let g = test_grid(12, 30, 0.002, |r, c| {
            let sign = if r % 3 == 0 { 1.0 } else { -1.0 };
            sign * (1.0 + 0.1 * c as f64 / 30.0)
        });
        let (fit, z) = (test_fit(&g), &g.heights_um);
        let c = check_model(&fit.surface, &fit.params_v, z, &FoldOptions::default());
        let h = &c.height_range;
        assert!(h.measured_max_um <= 1.1 && h.measured_min_um >= -1.1);
        assert!(
            h.model_max_um > h.measured_max_um && h.overshoot_pct > OVERSHOOT_WARN_PCT,
            "{h:?}"
        );
        assert!(
            (h.overshoot_um
                - ((h.model_max_um - h.measured_max_um).max(0.0)
                    + (h.measured_min_um - h.model_min_um).max(0.0)))
            .abs()
                < 1e-12
        );
        assert!(c
            .warnings()
            .iter()
            .any(|w| w.starts_with("model overshoot")));
    }
}
