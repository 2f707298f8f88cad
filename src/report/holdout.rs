//! Section: model versus measured — the hold-out refits (every 2nd point, every 2nd line
//! left out) made the way the model was made (degrees and method across the lines), each
//! line's share of them, and the verdict on the surface between lines: every 2nd line left
//! out, the rest refitted, the refit judged against Sq of the measured grid
//! ([`crate::metrology::holdout::between_lines`]). These refits are the only fits the report
//! makes.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::holdout`].

use super::document::{LineHoldout, LineReport};
use super::grid::LineGrid;
use crate::metrology::holdout::{
    between_lines, holdout_every_or_reason, holdout_with, BetweenLines, Holdout, HoldoutLine,
};
use crate::metrology::surface_model::ModelRecipe;

fn line_index(grid: &LineGrid, row: usize) -> usize {
    grid.index.get(row).copied().unwrap_or(row as u32) as usize
}

/// Runs the refits of `model_vs_measured` on `heights_um` (the grid's rows; the spikes
/// bridged when characterisation excludes them), with line indices mapped to the grid's.
pub fn characterise(
    grid: &LineGrid,
    heights_um: &[f64],
    recipe: &ModelRecipe,
) -> Result<Holdout, String> {
    let mut h = holdout_with(
        heights_um,
        grid.cols,
        grid.pitch_x_mm,
        &grid.y_mm,
        recipe.degrees,
        recipe.method,
    )
    .map_err(|e| e.to_string())?;
    for l in h
        .points_left_out
        .iter_mut()
        .chain(h.lines_left_out.iter_mut())
    {
        l.index = line_index(grid, l.index);
    }
    Ok(h)
}

/// The verdict on the surface between lines (every 2nd line left out, or every k-th when
/// there are too few lines for that, [`holdout_every`](crate::metrology::holdout::holdout_every)) against `sq_um`. The held-out lines
/// keep their row in `BetweenLines::lines[i].index` until [`rows_to_lines`].
pub fn verdict(
    grid: &LineGrid,
    heights_um: &[f64],
    recipe: &ModelRecipe,
    sq_um: f64,
    threshold: f64,
) -> Result<BetweenLines, String> {
    let every = holdout_every_or_reason(grid.rows(), recipe.degrees.degree_v)?;
    between_lines(
        heights_um,
        grid.cols,
        grid.pitch_x_mm,
        &grid.y_mm,
        recipe.degrees,
        recipe.method,
        every,
        sq_um,
        threshold,
    )
    .map_err(|e| e.to_string())
}

/// Maps the verdict's held-out rows to the grid's line indices.
pub fn rows_to_lines(grid: &LineGrid, b: &mut BetweenLines) {
    for l in &mut b.lines {
        l.index = line_index(grid, l.index);
    }
}

/// Gives every line its share of the hold-out comparison.
pub fn attach(lines: &mut [LineReport], h: &Holdout) {
    let find =
        |v: &[HoldoutLine], index: u32| v.iter().find(|l| l.index == index as usize).cloned();
    for line in lines {
        line.model_vs_measured = Some(LineHoldout {
            points_left_out: find(&h.points_left_out, line.index),
            line_left_out: find(&h.lines_left_out, line.index),
        });
    }
}
