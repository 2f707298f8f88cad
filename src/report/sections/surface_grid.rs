//! Sections `surface_grid` and `anisotropy`: areal parameters (ISO 25178: height, functional,
//! spatial), the pooled bearing
//! area curve and the anisotropy of the measured grid as characterised. Need no model.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::areal`],
//! [`crate::metrology::functional`], [`crate::metrology::spatial`] and
//! [`crate::metrology::anisotropy`].

use super::SectionInput;
use crate::metrology::anisotropy::Anisotropy;
use crate::metrology::areal::{areal_params_of_levelled, smr_curve, HeightMap, Plane};
use crate::metrology::functional::areal_functional;
use crate::metrology::spatial::spatial_params;
use crate::report::document::SurfaceReport;
use std::borrow::Cow;

/// Areal parameters and the pooled Smr curve of `heights` in the shape of `shape` at `levels`
/// levels; owned heights are dropped as the spatial parameters take their buffer.
pub fn surface_report(
    heights: Cow<'_, [f64]>,
    shape: &HeightMap<'_>,
    levels: usize,
    recipe: String,
) -> Result<SurfaceReport, String> {
    let g = &HeightMap {
        heights_um: &heights,
        ..*shape
    };
    let plane = Plane::of(g).map_err(|e| e.to_string())?;
    let (z, coefficients) = plane.level(g);
    let params = areal_params_of_levelled(g, &z, coefficients);
    let bac = smr_curve(&z, g.cols, levels).map_err(|e| e.to_string())?;
    Ok(SurfaceReport {
        params,
        bac,
        recipe,
        bac_curves: None,
        bac_curves_recipe: None,
        functional: areal_functional(z).map_err(|e| e.to_string()),
        spatial: Ok(spatial_params(heights, shape, &plane)),
    })
}

/// The areal parameters and pooled bearing curve of the grid as characterised.
pub fn section(input: &SectionInput<'_>) -> Result<SurfaceReport, String> {
    let measured = HeightMap::of(input.characterised, input.pitch_y_mm);
    let (heights, recipe) = (Cow::Borrowed(measured.heights_um), grid_recipe(&measured));
    surface_report(heights, &measured, input.ctx.options.levels, recipe)
}

/// How the grid's areal parameters were obtained, its pitches to the nanometre (the
/// resolution of the stage's targets: a mean of y positions carries float noise below it).
fn grid_recipe(measured: &HeightMap<'_>) -> String {
    format!(
        "the measured heights as traced ({} lines × {} points, pitch x {:.6} mm, mean pitch y {:.6} mm), no λc filter, least-squares plane removed",
        measured.rows, measured.cols, measured.pitch_x_mm, measured.pitch_y_mm
    )
}

/// The anisotropy of the grid as characterised, and what it does to Sdq and Sdr.
pub fn anisotropy(input: &SectionInput<'_>) -> Result<Anisotropy, String> {
    crate::metrology::anisotropy::anisotropy(&HeightMap::of(input.characterised, input.pitch_y_mm))
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recipe_states_the_pitches_to_the_nanometre() {
        let z = [0.0; 6];
        let map = HeightMap {
            heights_um: &z,
            rows: 3,
            cols: 2,
            pitch_x_mm: 0.0015,
            // The demo's mean pitch: (y_last − y_first) / 30 of positions near −19.7 mm.
            pitch_y_mm: 0.010000000000000024,
        };
        let recipe = grid_recipe(&map);
        assert!(
            recipe.contains("(3 lines × 2 points, pitch x 0.001500 mm, mean pitch y 0.010000 mm)"),
            "{recipe}"
        );
    }
}
