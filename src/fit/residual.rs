//! How well a fitted surface meets its data: the largest distance to a data point.
//!
//! Layer 1 (pure logic): depends on the fit's result type and [`crate::nurbs`] evaluation.

use super::FitResult;

/// Largest distance |S(ū_k, v̄_l) − Q(k, l)| in mm over all data points of the grid the result
/// was fitted to. Returns infinity when the grid's shape does not match the result.
pub fn max_residual_mm(
    result: &FitResult,
    pitch_x_mm: f64,
    y_mm: &[f64],
    heights_um: &[f64],
    cols: usize,
) -> f64 {
    let rows = y_mm.len();
    if cols != result.params_u.len()
        || rows != result.params_v.len()
        || heights_um.len() != rows * cols
    {
        return f64::INFINITY;
    }
    let mut worst = 0.0f64;
    for ((row, &y), &v) in heights_um
        .chunks_exact(cols)
        .zip(y_mm)
        .zip(&result.params_v)
    {
        let pts = result.surface.evaluate_grid(&result.params_u, &[v]);
        for (k, (p, &h)) in pts.iter().zip(row).enumerate() {
            let q = [k as f64 * pitch_x_mm, y, h / 1000.0];
            let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
            worst = worst.max(d);
        }
    }
    worst
}
