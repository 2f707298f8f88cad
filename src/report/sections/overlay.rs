//! The line drawn against the model (the paper's Figure 2 made honest): the requested line
//! (or the middle one) left out, the surface refitted without it the way the model was made,
//! beside the line's measured heights and the residual. Without a hold-out, a data line
//! against the sampled model, which passes through it by construction (and says so).
//!
//! Layer 4 (reporting): depends on [`crate::metrology::holdout`] (the refit).

use super::SectionInput;
use crate::grid::Grid;
use crate::metrology::areal::HeightMap;
use crate::metrology::holdout::BetweenLines;
use crate::numfmt::{fmt as nfmt, line_label, line_number, Quantity};
use crate::report::context::ReportContext;

/// The curves of the figure with its title, held out; else the row to draw with
/// [`data_line`]. The hold-out's heights in `verdict` are read here only: they can be
/// dropped after.
pub fn section(
    input: &SectionInput<'_>,
    verdict: Option<&BetweenLines>,
) -> (Result<Overlay, usize>, Vec<String>) {
    let mut warnings = Vec::new();
    let row = overlay_row(input.grid, input.ctx, &mut warnings);
    let held_out = held_out_overlay(
        input.characterised,
        &input.model.recipe,
        verdict,
        row,
        &mut warnings,
    );
    (held_out.ok_or(row), warnings)
}

/// Line `row` of `grid` against the model sampled on it.
pub fn data_line(grid: &Grid, model: &HeightMap<'_>, row: usize) -> Overlay {
    Overlay {
        measured: along_x(grid.row(row), grid.x0_mm, grid.pitch_x_mm),
        model: along_x(
            model
                .heights_um
                .get(row * model.cols..(row + 1) * model.cols)
                .unwrap_or(&[]),
            grid.x0_mm,
            model.pitch_x_mm,
        ),
        residual: Vec::new(),
        title: format!(
            "{}: measured and model (fitted through these points; no line could be held out)",
            line_named(grid, row)
        ),
    }
}

/// "Line 5 (0004, y = 0.040 mm)": how a title names row `row` of `grid`.
fn line_named(grid: &Grid, row: usize) -> String {
    let (index, y_mm) = (grid.index_of(row), grid.y_mm.get(row).copied());
    let y = nfmt(y_mm.unwrap_or(f64::NAN), Quantity::PositionMm);
    format!("Line {} ({index:04}, y = {y} mm)", line_number(index))
}

/// `z` as `(x_mm, z)` points `pitch_mm` apart from `x0_mm` (the input's coordinates, as
/// [`Grid::x_mm`]).
pub(crate) fn along_x(z: &[f64], x0_mm: f64, pitch_mm: f64) -> Vec<(f64, f64)> {
    let x = |i: usize| x0_mm + i as f64 * pitch_mm;
    z.iter().enumerate().map(|(i, v)| (x(i), *v)).collect()
}

/// The overlay's row: the requested line when it is among the rows (else a warning and the
/// middle row).
fn overlay_row(grid: &Grid, ctx: &ReportContext, warnings: &mut Vec<String>) -> usize {
    let middle = grid.rows() / 2;
    let Some(i) = ctx.options.overlay_line else {
        return middle;
    };
    grid.index.iter().position(|&k| k == i).unwrap_or_else(|| {
        warnings.push(format!(
            "overlay line {i} is not among the lines used ({:?}); the middle line is drawn",
            grid.index
        ));
        middle
    })
}

/// The overlay of a held-out line: its measured heights, the model refitted without it and
/// the residual, as `(x_mm, z_um)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Overlay {
    /// Measured heights.
    pub measured: Vec<(f64, f64)>,
    /// The refit at the line.
    pub model: Vec<(f64, f64)>,
    /// Model − measured.
    pub residual: Vec<(f64, f64)>,
    /// Title naming the line and what the curve is.
    pub title: String,
}

/// The paper's Figure 2 made honest: the requested overlay line (or the middle one) left
/// out, the surface refitted without it the way the model was made, and drawn against the
/// line's measured heights. When that line cannot be left out (the first or last line) or
/// its refit fails, the held-out line of the verdict `b` nearest it is drawn instead, and a
/// warning says so. `grid` is the grid as characterised.
fn held_out_overlay(
    grid: &Grid,
    recipe: &crate::metrology::surface_model::ModelRecipe,
    b: Option<&BetweenLines>,
    wanted: usize,
    warnings: &mut Vec<String>,
) -> Option<Overlay> {
    let own =
        crate::metrology::holdout::model_without_line(grid, recipe.degrees, recipe.method, wanted);
    let (row, rms, model) = match own {
        Ok((line, model)) => (wanted, line.rms_um, model),
        Err(e) => {
            let b = b?;
            let (k, line) = b
                .lines
                .iter()
                .enumerate()
                .min_by_key(|(_, l)| l.index.abs_diff(wanted))?;
            warnings.push(format!(
                "the overlay shows line {} (left out of the hold-out refit) instead of line {}: {e}",
                line_label(grid.index_of(line.index)),
                line_label(grid.index_of(wanted))
            ));
            (line.index, line.rms_um, b.model_line(k)?.to_vec())
        }
    };
    let (x0, px, measured) = (grid.x0_mm, grid.pitch_x_mm, grid.row(row));
    let residual: Vec<f64> = model.iter().zip(measured).map(|(m, z)| m - z).collect();
    Some(Overlay {
        measured: along_x(measured, x0, px),
        model: along_x(&model, x0, px),
        residual: along_x(&residual, x0, px),
        title: format!(
            "{} left out: its measured heights and the model refitted without it (rms {} µm)",
            line_named(grid, row),
            nfmt(rms, Quantity::HeightUm)
        ),
    })
}
