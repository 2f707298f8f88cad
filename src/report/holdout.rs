//! Section: model versus measured — the hold-out refits (every 2nd point, every 2nd line
//! left out), with the model's degrees, and each line's share of them. These refits are the
//! only fits the report makes.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::holdout`].

use super::document::{LineHoldout, LineReport};
use super::grid::LineGrid;
use crate::fit::FitOptions;
use crate::metrology::holdout::{holdout, Holdout, HoldoutLine};

/// Runs the section: the refits at the model's `degrees`, with line indices mapped to the
/// grid's.
pub fn characterise(grid: &LineGrid, degrees: FitOptions) -> Result<Holdout, String> {
    let mut h = holdout(
        &grid.heights_um,
        grid.cols,
        grid.pitch_x_mm,
        &grid.y_mm,
        degrees,
    )
    .map_err(|e| e.to_string())?;
    for l in h
        .points_left_out
        .iter_mut()
        .chain(h.lines_left_out.iter_mut())
    {
        l.index = grid.index.get(l.index).copied().unwrap_or(l.index as u32) as usize;
    }
    Ok(h)
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
