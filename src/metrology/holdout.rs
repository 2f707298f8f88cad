//! Model versus measured, honestly: an interpolant matches its data points by construction, so
//! the surface is refitted with every 2nd point of each line left out (and, separately, every
//! 2nd line left out) and evaluated at the held-out points; max and RMS differences per line.
//!
//! Depends on [`crate::fit`] (refits), [`super::model`] (sampling) and [`crate::nurbs`].

use super::model::sample_model_grid;
use super::MetrologyError;
use crate::fit::{fit_grid, FitOptions};
use serde::Serialize;

/// Differences at the held-out points of one line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HoldoutLine {
    /// Line index in the full grid.
    pub index: usize,
    /// y of the line, mm.
    pub y_mm: f64,
    /// Held-out points compared on this line.
    pub points: usize,
    /// Largest |model − measured|, µm.
    pub max_abs_um: f64,
    /// RMS of model − measured, µm.
    pub rms_um: f64,
}

/// Both hold-out comparisons.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Holdout {
    /// Every 2nd point (odd columns) of every line left out, per line.
    pub points_left_out: Vec<HoldoutLine>,
    /// Every 2nd line (odd rows inside the kept range) left out, per held-out line.
    pub lines_left_out: Vec<HoldoutLine>,
}

fn stats(index: usize, y_mm: f64, model: &[f64], measured: &[f64]) -> HoldoutLine {
    let d: Vec<f64> = model.iter().zip(measured).map(|(m, z)| m - z).collect();
    let n = d.len().max(1) as f64;
    HoldoutLine {
        index,
        y_mm,
        points: d.len(),
        max_abs_um: d.iter().fold(0.0, |a, v| a.max(v.abs())),
        rms_um: (d.iter().map(|v| v * v).sum::<f64>() / n).sqrt(),
    }
}

/// Runs both hold-out refits on a row-major grid (heights µm, one row per line at `y_mm[j]`,
/// increasing; the lines need not be equally spaced, e.g. a scan with a line missing).
pub fn holdout(
    heights_um: &[f64],
    cols: usize,
    pitch_x_mm: f64,
    y_mm: &[f64],
    options: FitOptions,
) -> Result<Holdout, MetrologyError> {
    super::check_pitch(pitch_x_mm)?;
    let rows = y_mm.len();
    if let Some(w) = y_mm.windows(2).find(|w| !matches!(w, [a, b] if b > a)) {
        return Err(MetrologyError::BadParameter {
            what: "y (mm) of a line",
            value: w.get(1).copied().unwrap_or(f64::NAN),
            hint: "line y values must be finite and strictly increasing",
        });
    }
    if rows.checked_mul(cols) != Some(heights_um.len()) {
        return Err(MetrologyError::GridSize {
            rows,
            cols,
            expected: rows.saturating_mul(cols),
            got: heights_um.len(),
        });
    }
    let row = |r: usize| heights_um.get(r * cols..(r + 1) * cols).unwrap_or(&[]);
    let y = y_mm;

    // Every 2nd point of each line out: fit the even columns at twice the pitch.
    let kept_cols = cols.div_ceil(2);
    let sub: Vec<f64> = (0..rows)
        .flat_map(|r| row(r).iter().step_by(2).copied().collect::<Vec<f64>>())
        .collect();
    let fit = fit_grid(2.0 * pitch_x_mm, y, &sub, kept_cols, options)?;
    let held = (cols.saturating_sub(1)) / 2;
    let model = sample_model_grid(
        &fit.surface,
        &fit.params_v,
        pitch_x_mm,
        2.0 * pitch_x_mm,
        held,
    )?;
    let points_left_out = (0..rows)
        .map(|r| {
            let measured: Vec<f64> = row(r)
                .iter()
                .skip(1)
                .step_by(2)
                .take(held)
                .copied()
                .collect();
            let m = model.get(r * held..(r + 1) * held).unwrap_or(&[]);
            stats(r, y.get(r).copied().unwrap_or(0.0), m, &measured)
        })
        .collect();

    // Every 2nd line out: fit the even rows, evaluate at the odd rows' y.
    let kept_rows: Vec<usize> = (0..rows).step_by(2).collect();
    let sub: Vec<f64> = kept_rows.iter().flat_map(|&r| row(r).to_vec()).collect();
    let ky: Vec<f64> = kept_rows
        .iter()
        .map(|&r| y.get(r).copied().unwrap_or(f64::NAN))
        .collect();
    let fit = fit_grid(pitch_x_mm, &ky, &sub, cols, options)?;
    let last_kept = kept_rows.last().copied().unwrap_or(0);
    let mut lines_left_out = Vec::new();
    for r in (1..last_kept).step_by(2) {
        let target = y.get(r).copied().unwrap_or(f64::NAN);
        // y depends on v only (every line has constant y), so bisect y(0, v).
        let (mut a, mut b) = (0.0f64, 1.0f64);
        for _ in 0..50 {
            let m = 0.5 * (a + b);
            if fit.surface.evaluate(0.0, m)[1] < target {
                a = m;
            } else {
                b = m;
            }
        }
        let v = 0.5 * (a + b);
        let m = sample_model_grid(&fit.surface, &[v], 0.0, pitch_x_mm, cols)?;
        lines_left_out.push(stats(r, target, &m, row(r)));
    }
    Ok(Holdout {
        points_left_out,
        lines_left_out,
    })
}
