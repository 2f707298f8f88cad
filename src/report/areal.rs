//! Section: areal parameters (ISO 25178) and the pooled bearing area curve of the measured
//! grid as traced. Needs no model.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::areal`].

use super::document::SurfaceReport;
use crate::metrology::areal::{areal_params, smr_curve, HeightMap};

/// The measured heights as a grid for the areal parameters, plots and X3P: the grid's rows
/// at the mean y pitch.
pub fn measured(grid: &crate::grid::Grid, pitch_y_mm: f64) -> HeightMap<'_> {
    HeightMap {
        heights_um: &grid.heights_um,
        rows: grid.rows(),
        cols: grid.cols,
        pitch_x_mm: grid.pitch_x_mm,
        pitch_y_mm,
    }
}

/// Areal parameters and the pooled Smr curve of `g` at `levels` levels.
pub fn surface_report(
    g: &HeightMap<'_>,
    levels: usize,
    recipe: String,
) -> Result<SurfaceReport, String> {
    let params = areal_params(g).map_err(|e| e.to_string())?;
    let bac = smr_curve(g, levels).map_err(|e| e.to_string())?;
    Ok(SurfaceReport {
        params,
        bac,
        recipe,
        bac_curves: None,
        bac_curves_recipe: None,
    })
}

/// Runs the section on the measured grid.
pub fn characterise(measured: &HeightMap<'_>, levels: usize) -> Result<SurfaceReport, String> {
    surface_report(
        measured,
        levels,
        format!(
            "the measured heights as traced ({} lines × {} points, pitch x {} mm, mean pitch y {} mm), no λc filter, least-squares plane removed",
            measured.rows, measured.cols, measured.pitch_x_mm, measured.pitch_y_mm
        ),
    )
}
