//! Section: the NURBS model — the paper's bearing area curves of iso-curves of the surface,
//! and the areal parameters of the surface sampled on the data lines. The surface is the one
//! the caller fitted (for a scan, the same one written to `surface.igs`); nothing is refitted
//! here.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::model`] and the areal section.

use super::areal::surface_report;
use super::context::{Model, ScanAnalysisOptions};
use super::document::SurfaceReport;
use super::error::{metrology, ReportError};
use crate::metrology::areal::Grid;
use crate::metrology::model::{model_bearing_curves, sample_model_grid, ModelBacOptions};

/// The model sampled on the data lines (their v) at half the x pitch, row-major: what
/// `model.x3p` and the overlay plot show.
#[derive(Debug, Clone, PartialEq)]
pub struct SampledModel {
    /// Heights in µm, `rows × cols`.
    pub heights_um: Vec<f64>,
    /// Points per line (2 × the data's − 1).
    pub cols: usize,
    /// x pitch of the samples, mm (half the data's).
    pub pitch_x_mm: f64,
}

/// What the section produces.
#[derive(Debug, Clone)]
pub struct ModelSection {
    /// The areal parameters and bearing curves of the model, or why there are none.
    pub surface: Result<SurfaceReport, String>,
    /// The sampled model, when the surface could be sampled.
    pub sampled: Option<SampledModel>,
}

/// Runs the section for a grid of `rows` lines of `cols` points at `pitch_x_mm`, its lines
/// `pitch_y_mm` apart on average.
pub fn characterise(
    model: &Model<'_>,
    rows: usize,
    cols: usize,
    pitch_x_mm: f64,
    pitch_y_mm: f64,
    options: &ScanAnalysisOptions,
    input: &str,
) -> Result<ModelSection, ReportError> {
    let fit = match model.fit {
        Ok(fit) => fit,
        Err(e) => {
            return Ok(ModelSection {
                surface: Err(format!("the NURBS fit failed: {e}")),
                sampled: None,
            })
        }
    };
    let (p, q) = (model.degrees.degree_u, model.degrees.degree_v);
    let bac_options = ModelBacOptions {
        curves: options.curves,
        levels: options.levels,
        samples_per_curve: None,
    };
    let curves = model_bearing_curves(&fit.surface, &bac_options)
        .map_err(metrology(format!("{input}: model bearing curves")))?;
    let model_cols = 2 * cols - 1;
    let heights = sample_model_grid(
        &fit.surface,
        &fit.params_v,
        0.0,
        pitch_x_mm / 2.0,
        model_cols,
    )
    .map_err(metrology(format!("{input}: sampling the model")))?;
    let g = Grid {
        heights_um: &heights,
        rows,
        cols: model_cols,
        pitch_x_mm: pitch_x_mm / 2.0,
        pitch_y_mm,
    };
    let surface = surface_report(
        &g,
        options.levels,
        format!(
            "the degree {p}/{q} interpolating NURBS surface sampled on the data lines (their v) at half the x pitch ({model_cols} points per line, x(u) inverted numerically), then levelled and evaluated as surface_grid"
        ),
    )
    .map(|mut s| {
        s.bac_curves_recipe = Some(format!(
            "paper Appendix A: {} iso-curves along x of the degree {p}/{q} interpolating surface at equally spaced v, each sampled at 8 points per control point along u, referenced to its x-weighted mean line, {} equal levels, crossings linear along x",
            options.curves, options.levels
        ));
        s.bac_curves = Some(curves);
        s
    });
    Ok(ModelSection {
        surface,
        sampled: Some(SampledModel {
            heights_um: heights,
            cols: model_cols,
            pitch_x_mm: pitch_x_mm / 2.0,
        }),
    })
}
