//! Sections `surface` and `model_checks`: the NURBS model — its checks (folds of the control net and of the surface, its
//! height range against the data's), the paper's bearing area curves of iso-curves of the
//! surface, and the areal parameters of the surface sampled on the data lines. The surface is
//! the one the caller fitted (for a scan, the same one written to `surface.igs`); nothing is
//! refitted here. Each part fails alone: a surface that folds has no bearing curves and
//! cannot be sampled as a height map, and says so, but its checks are still reported.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::model`] and
//! [`crate::metrology::folds`] and the areal section.

use super::surface_grid::surface_report;
use super::SectionInput;
use crate::fit::FitResult;
use crate::metrology::areal::HeightMap;
use crate::metrology::folds::{check_model_with, iso_curve_sample_count, FoldOptions, ModelChecks};
use crate::metrology::model::{
    bearing_sample_us, model_bearing_curves_with, sample_model_grid, ModelBacOptions,
};
use crate::metrology::{Basis, TwoLanes};
use crate::nurbs::UBasis;
use crate::report::context::ModelFit;
use crate::report::document::{FailedSection, SurfaceReport};
use std::borrow::Cow;

/// The most model samples (f64, 8 MiB) sampled and characterised before the caller's wait.
const EARLY_SAMPLES: usize = 1 << 20;

/// What the section produces.
#[derive(Debug, Clone)]
pub struct ModelSection {
    /// The areal parameters and bearing curves of the model, or why there are none.
    pub surface: Result<SurfaceReport, String>,
    /// The checks, when there is a surface.
    pub checks: Option<ModelChecks>,
    /// The parts that failed.
    pub failed: Vec<FailedSection>,
}

/// The section `section` failed, for `reason`.
pub(super) fn failed(section: &str, reason: impl Into<String>) -> FailedSection {
    FailedSection {
        section: section.to_string(),
        reason: reason.into(),
    }
}

/// The section with no surface, for `reason`.
fn no_surface(reason: impl Into<String>) -> ModelSection {
    let reason = reason.into();
    ModelSection {
        surface: Err(reason.clone()),
        checks: None,
        failed: vec![failed("surface", reason)],
    }
}

/// Why there is no model when its section panicked.
pub const PANICKED: &str = "internal: the model section panicked; report this with the input";

/// The section when it panicked: a failed `surface` section that says so.
pub fn panicked() -> ModelSection {
    no_surface(PANICKED)
}

/// Runs the section: the model of `input` against the grid's measured heights. Once it is
/// checked (and unless it folds) the model is sampled; `before_areal` is given what
/// `wait` returned and the sampled model, for all that reads it beyond its areal
/// parameters (`model.x3p`, a data line's overlay). A caller running other sections beside
/// this one returns from `wait` once their own large buffers are gone: a large
/// model is sampled after that wait and its areal parameters (whose autocorrelation takes
/// twice its bytes and grows from them) made after `before_areal`, so the peaks do not add; a
/// model of at most [`EARLY_SAMPLES`] samples is sampled and its areal parameters made before
/// the wait, while the other sections run, when the process may use more than one core.
/// `fit` is dropped once the model is sampled (its net, as large as the grid, is then not
/// held beside the areal parameters' autocorrelation) and returned only when `keep_fit`.
pub fn section<'f, W>(
    input: &SectionInput<'_>,
    fit: ModelFit<'f>,
    keep_fit: bool,
    wait: impl FnOnce() -> W,
    before_areal: impl FnOnce(W, &HeightMap<'_>),
) -> (ModelSection, Option<Cow<'f, FitResult>>) {
    let (model, options, g) = (input.model, &input.ctx.options, input.grid);
    let (heights_um, rows, cols) = (&g.heights_um[..], g.rows(), g.cols);
    let (pitch_x_mm, pitch_y_mm) = (g.pitch_x_mm, input.pitch_y_mm);
    let fit = match fit {
        Ok(fit) => fit,
        Err(e) => return (no_surface(format!("the NURBS fit failed: {e}")), None),
    };
    let mut fails = Vec::new();
    let model_cols = 2 * cols - 1;
    // The checks and the bearing curves read the same surface: they run side by side. A
    // surface that folds is not sampled (below), as the checks say.
    let bac_options = ModelBacOptions {
        curves: options.curves,
        levels: options.levels,
        samples_per_curve: None,
    };
    let fold_options = FoldOptions::default();
    // The fold check's iso-curves and the bearing curves are sampled at the same u when their
    // densities agree (the defaults do): the u basis is computed and regrouped once for both.
    let us = bearing_sample_us(&fit.surface, &bac_options);
    let fold_n_u = iso_curve_sample_count(&fit.surface, &fold_options);
    let basis = (us.len() == fold_n_u).then(|| UBasis::new(&fit.surface, &us));
    let lanes = basis.as_ref().map(|b| TwoLanes::new(Basis::of(b)));
    let (checks, bac) = std::thread::scope(|inner| {
        let checks = inner.spawn(|| {
            check_model_with(
                &fit.surface,
                &fit.params_v,
                heights_um,
                &fold_options,
                lanes.as_ref(),
            )
        });
        let bac = model_bearing_curves_with(&fit.surface, &bac_options, lanes.as_ref());
        (checks.join(), bac)
    });
    // The u basis is not held while the model is sampled.
    drop(lanes);
    drop((basis, us));
    let Ok(checks) = checks else {
        let why = "internal: the model checks panicked; report this with the input";
        return (no_surface(why), keep_fit.then_some(fit));
    };
    let folds = checks.folds();
    let (p, q) = (model.recipe.degrees.degree_u, model.recipe.degrees.degree_v);
    let what = match model.recipe.method {
        crate::fit::VMethod::Interpolate => format!("degree {p}/{q} interpolating"),
        crate::fit::VMethod::LeastSquares { control_rows } => {
            format!("degree {p}/{q} (least squares across the lines, {control_rows} control rows)")
        }
    };
    let curves = match bac {
        Ok(c) => Some(c),
        Err(e) => {
            fails.push(failed(
                "surface.bac_curves",
                if folds {
                    format!("the model folds (x runs backwards along its iso-curves, see model_checks), so its profile curves have no bearing area curve: {e}")
                } else {
                    format!("the model's bearing area curves: {e}")
                },
            ));
            None
        }
    };
    let shape = HeightMap {
        heights_um: &[],
        rows,
        cols: model_cols,
        pitch_x_mm: pitch_x_mm / 2.0,
        pitch_y_mm,
    };
    let areal = |heights: Cow<'_, [f64]>| {
        surface_report(
            heights,
            &shape,
            options.levels,
            format!(
                "the {what} NURBS surface sampled on the data lines (their v) at half the x pitch ({model_cols} points per line, x(u) inverted numerically), then levelled and evaluated as surface_grid"
            ),
        )
    };
    // The model sampled on the data lines (their v) at half the x pitch: what `model.x3p` shows.
    // Once sampled the fit is let go, unless it is kept for the caller.
    let sample = |f: Cow<'f, FitResult>| {
        let sampled = sample_model_grid(
            &f.surface,
            &f.params_v,
            f.x0_mm,
            pitch_x_mm / 2.0,
            model_cols,
        )
        .map_err(|e| format!("sampling the model on the data lines: {e}"));
        (sampled, keep_fit.then_some(f))
    };
    // Over a fold the surface has several heights at one x: no grid of heights describes it,
    // whichever branch an inversion of x(u) would pick. A small model's buffers add little to
    // the other sections' peak: it does not wait (see above), unless the process has one core,
    // where there is no idle time to fill and the areal section's copy of the samples is only
    // a cost.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (surface, fit) = if folds {
        (Err("the model folds (x runs backwards along its iso-curves, see model_checks), so it is not a height map: no model.x3p and no areal parameters of the model".to_string()), keep_fit.then_some(fit))
    } else if rows * model_cols <= EARLY_SAMPLES && cores > 1 {
        let (sampled, fit) = sample(fit);
        let surface = sampled.and_then(|heights| {
            let surface = areal(Cow::Borrowed(&heights));
            let map = HeightMap {
                heights_um: &heights,
                ..shape
            };
            before_areal(wait(), &map);
            surface
        });
        (surface, fit)
    } else {
        let w = wait();
        let (sampled, fit) = sample(fit);
        let surface = sampled.and_then(|heights| {
            let map = HeightMap {
                heights_um: &heights,
                ..shape
            };
            before_areal(w, &map);
            areal(Cow::Owned(heights))
        });
        (surface, fit)
    };
    let surface = surface.map(|mut s| {
        if let Some(curves) = curves {
            s.bac_curves_recipe = Some(format!(
                "paper Appendix A: {} iso-curves along x of the {what} surface at equally spaced v, each sampled at 8 points per control point along u, referenced to its x-weighted mean line, {} equal levels, crossings linear along x",
                options.curves, options.levels
            ));
            s.bac_curves = Some(curves);
        }
        s
    });
    if let Err(e) = &surface {
        fails.push(failed("surface", e.clone()));
    }
    let section = ModelSection {
        surface,
        checks: Some(checks),
        failed: fails,
    };
    (section, fit)
}
