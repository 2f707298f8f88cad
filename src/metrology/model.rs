//! The bearing area curves of the fitted NURBS surface, as the paper's Appendix A: profile
//! curves are extracted from the model (iso-curves along x at equally spaced v, 31 by default),
//! each is sampled densely along its parameter (not only at the data points), referenced to its
//! mean line and cut at equal height levels (101 by default); MAR(h) = ΣL_i / L0 × 100 % from the
//! x-lengths of the cross lines, crossings interpolated linearly between the dense samples.
//!
//! Depends on [`crate::nurbs`] (evaluation), [`super::sampling`] (dense samples) and
//! [`super::bearing`].

use super::bearing::{bearing_curve_xz, BearingCurve};
use super::sampling::{equally_spaced, Basis, TwoLanes};
use super::MetrologyError;
use crate::nurbs::{basis_funs, find_span, BSplineCurve, NurbsSurface, UBasis};
use serde::Serialize;

/// Options for the model's bearing area curves, with the paper's defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelBacOptions {
    /// Number of iso-curves along x, at equally spaced v from 0 to 1 (paper: 31).
    pub curves: usize,
    /// Equal height levels per curve (paper: 101).
    pub levels: usize,
    /// Samples per curve, equally spaced in u; `None` = 8 per control point along u.
    pub samples_per_curve: Option<usize>,
}

impl Default for ModelBacOptions {
    fn default() -> ModelBacOptions {
        ModelBacOptions {
            curves: 31,
            levels: 101,
            samples_per_curve: None,
        }
    }
}

/// The bearing area curve of one model profile curve.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelCurveBac {
    /// Surface parameter v of the iso-curve.
    pub v: f64,
    /// y of the curve in mm (at its first sample).
    pub y_mm: f64,
    /// Samples the curve was evaluated at.
    pub samples: usize,
    /// Its bearing area curve (heights in µm relative to its mean line).
    pub curve: BearingCurve,
}

/// The u at which [`model_bearing_curves_with`] samples every curve: `samples` equally spaced
/// from 0 to 1 (`k / (samples − 1)`), as the fold check samples its iso-curves.
pub fn bearing_sample_us(surface: &NurbsSurface, options: &ModelBacOptions) -> Vec<f64> {
    equally_spaced(bearing_samples(surface, options))
}

/// How many u [`bearing_sample_us`] gives: `samples_per_curve`, by default 8 per pole.
fn bearing_samples(surface: &NurbsSurface, options: &ModelBacOptions) -> usize {
    let n = options.samples_per_curve.unwrap_or(8 * surface.count_u());
    n.max(2)
}

/// The bearing area curves of `options.curves` iso-curves of `surface` (coordinates in mm;
/// heights are reported in µm), with the u basis at [`bearing_sample_us`] when the caller
/// has computed and regrouped it (`TwoLanes` of the `UBasis::new` of exactly those u; one of
/// another length is not used).
pub fn model_bearing_curves_with(
    surface: &NurbsSurface,
    options: &ModelBacOptions,
    shared_u: Option<&TwoLanes<'_>>,
) -> Result<Vec<ModelCurveBac>, MetrologyError> {
    if options.curves == 0 {
        return Err(MetrologyError::BadParameter {
            what: "curves",
            value: 0.0,
            hint: "extract at least 1 profile curve from the model (the paper uses 31)",
        });
    }
    let samples = bearing_samples(surface, options);
    // Every curve is sampled at the same u, so the basis along u is computed once.
    let (own, own_lanes);
    let xz = match shared_u.filter(|b| b.basis.first.len() == samples) {
        Some(b) => b,
        None => {
            own = UBasis::new(surface, &bearing_sample_us(surface, options));
            own_lanes = TwoLanes::new(Basis::of(&own));
            &own_lanes
        }
    };
    let sampler = xz.basis;
    let mut poles = Vec::new();
    let mut out = Vec::with_capacity(options.curves);
    for j in 0..options.curves {
        let v = if options.curves == 1 {
            0.5
        } else {
            j as f64 / (options.curves - 1) as f64
        };
        surface.iso_poles_u_padded(v, &mut poles);
        let mut xs = Vec::with_capacity(samples);
        let mut zs = Vec::with_capacity(samples);
        xz.points(&poles, [0, 2], &mut xs, &mut zs);
        for z in &mut zs {
            *z *= 1000.0;
        }
        let y_mm = sampler.lane(&poles, 0, 1);
        let curve = bearing_curve_xz(&xs, &zs, options.levels)?;
        out.push(ModelCurveBac {
            v,
            y_mm,
            samples,
            curve,
        });
    }
    Ok(out)
}

/// Samples the model on a regular grid: one row per v in `vs` (e.g. the data lines'
/// parameters, where the model's y equals the line's y), `cols` points at x = `x0_mm` +
/// k·`pitch_x_mm` found by inverting x(u) along each iso-curve (x must increase with u).
/// The inversion is the Illinois variant of false position, bracketed from the previous
/// point's u (the targets increase), stopped at |x(u) − x| ≤ 1e-13 mm or a bracket of 1e-15 in
/// u; a few evaluations per point instead of the 50 of plain bisection. When the net's x is
/// constant down each column (every fit's is: x depends on u alone), x(u) is the same on every
/// iso-curve up to rounding, so it is inverted once on the net's own x and the basis at the
/// found u serves every line. Heights in µm, row-major.
pub fn sample_model_grid(
    surface: &NurbsSurface,
    vs: &[f64],
    x0_mm: f64,
    pitch_x_mm: f64,
    cols: usize,
) -> Result<Vec<f64>, MetrologyError> {
    super::check_pitch(pitch_x_mm)?;
    if !x_depends_on_u_only(surface) {
        return sample_per_line(surface, vs, x0_mm, pitch_x_mm, cols);
    }
    let mut out = Vec::with_capacity(vs.len().saturating_mul(cols));
    let mut poles = Vec::new();
    let x_curve = XOfU::new(surface);
    let us = invert_row(&|u| x_curve.at(u), x0_mm, pitch_x_mm, cols)?;
    let basis = UBasis::new(surface, &us);
    // Only z is kept; the two-lane sampler sums z (and x, unused) with the bits of
    // `UBasis::for_each_point`, without the y and padding lanes.
    let lanes = TwoLanes::new(Basis::of(&basis));
    let mut xs = Vec::with_capacity(cols);
    for &v in vs {
        surface.iso_poles_u_padded(v, &mut poles);
        let start = out.len();
        xs.clear();
        lanes.points(&poles, [2, 0], &mut out, &mut xs);
        for z in &mut out[start..] {
            *z *= 1000.0;
        }
    }
    Ok(out)
}

/// x(u) of a surface whose x depends on u alone: the x of the iso-curve along u through the
/// first pole row, evaluated as [`BSplineCurve::evaluate`] evaluates it (the same span, the same
/// basis values, Σ basis·x from zero in pole order, so the same bits) but for x alone and with
/// the knot span of the previous call tried first: the inversion evaluates x(u) a few times
/// per target at nearby u, and a binary search over thousands of knots per evaluation cost as
/// much as the rest of it.
struct XOfU {
    degree: usize,
    knots: Vec<f64>,
    x: Vec<f64>,
    /// The curve for degrees above the stack buffers (evaluated the general way).
    general: Option<BSplineCurve>,
    /// The span of the last evaluation.
    hint: std::cell::Cell<usize>,
}

/// Degrees up to this use stack buffers for the basis values.
const MAX_FAST_DEGREE: usize = 15;

impl XOfU {
    fn new(surface: &NurbsSurface) -> XOfU {
        let degree = surface.degree_u();
        let x: Vec<f64> = (0..surface.count_u())
            .map(|i| surface.pole(i, 0)[0])
            .collect();
        let general = (degree > MAX_FAST_DEGREE).then(|| BSplineCurve {
            degree,
            knots: surface.knots_u().to_vec(),
            poles: x.iter().map(|&x| [x, 0.0, 0.0]).collect(),
        });
        XOfU {
            degree,
            knots: surface.knots_u().to_vec(),
            x,
            general,
            hint: std::cell::Cell::new(degree),
        }
    }

    /// x at `u` (clamped into the knot range), mm.
    fn at(&self, u: f64) -> f64 {
        if let Some(c) = &self.general {
            return c.evaluate(u).map_or(f64::NAN, |p| p[0]);
        }
        let (d, n) = (self.degree, self.x.len());
        if n < d + 1 || self.knots.len() != n + d + 1 {
            return f64::NAN;
        }
        let (lo, hi) = (self.knots[d], self.knots[n]);
        let t = if u.is_nan() { lo } else { u.clamp(lo, hi) };
        let span = self.span(t);
        self.hint.set(span);
        let mut b = [0.0; MAX_FAST_DEGREE + 1];
        let mut left = [0.0; MAX_FAST_DEGREE + 1];
        let mut right = [0.0; MAX_FAST_DEGREE + 1];
        basis_funs(span, t, d, &self.knots, &mut b, &mut left, &mut right);
        let mut p = 0.0;
        for (r, b) in b[..=d].iter().enumerate() {
            p += b * self.x[span - d + r];
        }
        p
    }

    /// [`find_span`] of `t` (inside the knot range), the last span or its neighbours tried
    /// first: inside the domain the span is the one `s` with `knots[s] <= t < knots[s + 1]`,
    /// so a candidate that satisfies it is the span the search would find.
    fn span(&self, t: f64) -> usize {
        let (d, n) = (self.degree, self.x.len());
        let (lo, hi) = (self.knots[d], self.knots[n]);
        if t > lo && t < hi {
            let h = self.hint.get();
            for s in [h, h + 1, h.wrapping_sub(1)] {
                if (d..n).contains(&s) && self.knots[s] <= t && t < self.knots[s + 1] {
                    return s;
                }
            }
        }
        find_span(d, &self.knots, n, t)
    }
}

/// [`sample_model_grid`] for any net: x(u) inverted along each line's own iso-curve.
fn sample_per_line(
    surface: &NurbsSurface,
    vs: &[f64],
    x0_mm: f64,
    pitch_x_mm: f64,
    cols: usize,
) -> Result<Vec<f64>, MetrologyError> {
    let mut out = Vec::with_capacity(vs.len().saturating_mul(cols));
    for &v in vs {
        let iso = surface.iso_curve_u(v);
        let at = |u: f64| iso.evaluate(u).map_or(f64::NAN, |p| p[0]);
        let us = invert_row(&at, x0_mm, pitch_x_mm, cols)?;
        for u in us {
            out.push(iso.evaluate(u).map_or(f64::NAN, |p| p[2]) * 1000.0);
        }
    }
    Ok(out)
}

/// Whether every pole's x equals the x of the pole below it in the first row, so that x on the
/// surface depends on u alone.
fn x_depends_on_u_only(surface: &NurbsSurface) -> bool {
    let net = surface.net();
    let first = net.row(0).x;
    net.rows().all(|row| row.x == first)
}

/// The u of each target x = `x0_mm` + k·`pitch_x_mm`, k < `cols`, along a curve whose x is
/// `x_at(u)` (increasing), each bracketed from the previous one's u and x (the x its search
/// ended on, not evaluated again).
fn invert_row<F: Fn(f64) -> f64>(
    x_at: &F,
    x0_mm: f64,
    pitch_x_mm: f64,
    cols: usize,
) -> Result<Vec<f64>, MetrologyError> {
    let bad = |what: &'static str, value: f64| MetrologyError::BadParameter {
        what,
        value,
        hint: "the model's x must increase along u and cover the requested x range",
    };
    let (lo_x, hi_x) = (x_at(0.0), x_at(1.0));
    let mut us = Vec::with_capacity(cols);
    let mut from = (0.0f64, lo_x);
    for k in 0..cols {
        let x = x0_mm + k as f64 * pitch_x_mm;
        if x < lo_x - 1e-9 * pitch_x_mm.max(1.0) || x > hi_x + 1e-9 * hi_x.abs().max(1.0) {
            return Err(bad("x (mm) outside the model", x));
        }
        from = invert_x(x_at, x, from, hi_x);
        us.push(from.0);
    }
    Ok(us)
}

/// The u in [u, 1] where the curve's x equals `x_mm` (Illinois false position) and `at` of it,
/// from `from` = (u, `at(u)`).
fn invert_x(at: &impl Fn(f64) -> f64, x_mm: f64, from: (f64, f64), x_at_1: f64) -> (f64, f64) {
    const X_TOL_MM: f64 = 1e-13;
    let (mut a, mut b) = (from.0, 1.0f64);
    let mut fa = from.1 - x_mm;
    let mut fb = x_at_1 - x_mm;
    if fa >= -X_TOL_MM {
        return from;
    }
    if fb <= X_TOL_MM {
        return (b, x_at_1);
    }
    // 0: no side repeated yet; 1: a kept last time; 2: b kept last time.
    let mut side = 0u8;
    for _ in 0..200 {
        let c = if fb != fa {
            (a * fb - b * fa) / (fb - fa)
        } else {
            0.5 * (a + b)
        };
        // Keep c strictly inside the bracket (rounding can put it on an end).
        let c = if c > a && c < b { c } else { 0.5 * (a + b) };
        let xc = at(c);
        let fc = xc - x_mm;
        if fc.abs() <= X_TOL_MM || b - a <= 1e-15 {
            return (c, xc);
        }
        if fc < 0.0 {
            a = c;
            fa = fc;
            if side == 1 {
                fb *= 0.5;
            }
            side = 1;
        } else {
            b = c;
            fb = fc;
            if side == 2 {
                fa *= 0.5;
            }
            side = 2;
        }
    }
    (0.5 * (a + b), at(0.5 * (a + b)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrology::{test_fit, test_grid};

    /// A smooth wavy 7×300 grid at 0.5 µm pitch, fitted.
    fn wavy_fit() -> crate::fit::FitResult {
        test_fit(&test_grid(7, 300, 0.0005, |r, c| {
            (c as f64 * 0.17).sin() + 0.3 * ((r * 300 + c) as f64 * 0.013).cos()
        }))
    }

    #[test]
    fn bearing_curves_from_a_shared_u_basis_are_those_of_their_own() {
        // The basis at `bearing_sample_us` made by the caller gives the curves to the bit; one
        // of another length is ignored.
        let fit = wavy_fit();
        let s = &fit.surface;
        let options = ModelBacOptions {
            curves: 5,
            levels: 21,
            samples_per_curve: None,
        };
        let own = model_bearing_curves_with(s, &options, None).unwrap();
        let us = bearing_sample_us(s, &options);
        assert_eq!(us.len(), 8 * s.count_u());
        assert_eq!((us[0], us[us.len() - 1]), (0.0, 1.0));
        let wrong = UBasis::new(s, &us[1..]);
        for basis in [UBasis::new(s, &us), wrong] {
            let lanes = TwoLanes::new(Basis::of(&basis));
            let shared = model_bearing_curves_with(s, &options, Some(&lanes)).unwrap();
            assert_eq!(format!("{shared:?}"), format!("{own:?}"));
            assert_eq!(shared, own);
        }
    }

    #[test]
    fn x_of_u_is_the_curves_x_to_the_bit() {
        // A fitted net's x(u) against the general evaluation of the same curve, at the
        // knots, between them in increasing and in jumping order (the span hint is stale),
        // at the ends, outside the domain and at NaN.
        let fit = wavy_fit();
        let s = &fit.surface;
        let general = BSplineCurve {
            degree: s.degree_u(),
            knots: s.knots_u().to_vec(),
            poles: (0..s.count_u())
                .map(|i| [s.pole(i, 0)[0], 0.0, 0.0])
                .collect(),
        };
        let fast = XOfU::new(s);
        let mut us: Vec<f64> = s.knots_u().to_vec();
        us.extend((0..5000).map(|k| k as f64 / 4999.0));
        us.extend((0..5000).map(|k| (k as f64 * 0.618_033_988_7).fract()));
        us.extend([
            -0.5,
            1.5,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e-300,
        ]);
        for u in us {
            let want = general.evaluate(u).unwrap()[0];
            assert_eq!(fast.at(u).to_bits(), want.to_bits(), "x({u})");
        }
    }

    #[test]
    fn one_inversion_for_all_lines_equals_one_per_line() {
        // A fitted net (x constant down each column) sampled both ways, at half the pitch as
        // the report does and at an offset, unrelated pitch.
        let (cols, px) = (400, 0.0005);
        let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
        let fit = test_fit(&test_grid(9, cols, px, |r, c| {
            let noise = crate::metrology::lcg(&mut s) - 0.5;
            c as f64 * 0.002 + ((r * cols + c) as f64 * 0.05).sin() + 0.4 * noise
        }));
        assert!(x_depends_on_u_only(&fit.surface));
        for (x0, pitch, n) in [(0.0, px / 2.0, 2 * cols - 1), (0.00013, 0.00071, 250)] {
            let shared = sample_model_grid(&fit.surface, &fit.params_v, x0, pitch, n).unwrap();
            // The heights are the whole points' z, as `UBasis::for_each_point` sums them, to
            // the bit.
            let x_curve = XOfU::new(&fit.surface);
            let us = invert_row(&|u| x_curve.at(u), x0, pitch, n).unwrap();
            let basis = UBasis::new(&fit.surface, &us);
            let (mut whole, mut poles) = (Vec::new(), Vec::new());
            for &v in &fit.params_v {
                fit.surface.iso_poles_u_padded(v, &mut poles);
                basis.for_each_point(&poles, |_, p| whole.push((p[2] * 1000.0).to_bits()));
            }
            assert_eq!(
                shared.iter().map(|z| z.to_bits()).collect::<Vec<_>>(),
                whole
            );
            let per_line = sample_per_line(&fit.surface, &fit.params_v, x0, pitch, n).unwrap();
            let scale = per_line.iter().map(|z| z.abs()).fold(0.0, f64::max);
            for (k, (a, b)) in shared.iter().zip(&per_line).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-12 * scale,
                    "point {k}: shared {a} vs per line {b}"
                );
            }
        }
    }
}
