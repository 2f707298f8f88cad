//! Sections `surface_grid` and `anisotropy`: areal parameters (ISO 25178: height, functional,
//! spatial), the pooled bearing
//! area curve and the anisotropy of the measured grid as characterised. Need no model.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::areal`],
//! [`crate::metrology::functional`], [`crate::metrology::spatial`] and
//! [`crate::metrology::anisotropy`].

use super::SectionInput;
use crate::metrology::anisotropy::Anisotropy;
use crate::metrology::areal::{areal_params, smr_curve, HeightMap};
use crate::metrology::functional::areal_functional;
use crate::metrology::spatial::spatial_params;
use crate::report::document::SurfaceReport;

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
        functional: areal_functional(g).map_err(|e| e.to_string()),
        spatial: spatial_params(g).map_err(|e| e.to_string()),
    })
}

/// The areal parameters and pooled bearing curve of the grid as characterised.
pub fn section(input: &SectionInput<'_>) -> Result<SurfaceReport, String> {
    let measured = HeightMap::of(input.characterised, input.pitch_y_mm);
    surface_report(
        &measured,
        input.ctx.options.levels,
        format!(
            "the measured heights as traced ({} lines × {} points, pitch x {} mm, mean pitch y {} mm), no λc filter, least-squares plane removed",
            measured.rows, measured.cols, measured.pitch_x_mm, measured.pitch_y_mm
        ),
    )
}

/// The anisotropy of the grid as characterised, and what it does to Sdq and Sdr.
pub fn anisotropy(input: &SectionInput<'_>) -> Result<Anisotropy, String> {
    crate::metrology::anisotropy::anisotropy(&HeightMap::of(input.characterised, input.pitch_y_mm))
        .map_err(|e| e.to_string())
}
