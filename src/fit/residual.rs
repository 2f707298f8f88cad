//! How well a fitted surface meets its data: the largest distance to a data point.
//!
//! Layer 1 (pure logic): depends on the fit's result type and [`crate::nurbs`] evaluation.
//!
//! The basis functions along u are the same for every row (the parameters ū_k are shared), so
//! they are computed once; each row then reduces the net to its iso-curve and evaluates it at
//! every ū_k with the stored basis. The arithmetic per point is that of
//! [`NurbsSurface::evaluate_grid`](crate::nurbs::NurbsSurface::evaluate_grid) (same products,
//! same order), so the residual is the same to the bit.

use super::{simd, FitResult};
use crate::nurbs::UBasis;

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
    let surface = &result.surface;
    let basis = UBasis::new(surface, &result.params_u);
    let mut curve = Vec::new();
    simd::wide(|| {
        let mut worst = 0.0f64;
        for ((row, &y), &v) in heights_um
            .chunks_exact(cols)
            .zip(y_mm)
            .zip(&result.params_v)
        {
            surface.iso_poles_u_padded(v, &mut curve);
            basis.for_each_point(&curve, |k, p| {
                let q = [k as f64 * pitch_x_mm, y, row[k] / 1000.0];
                let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                let d = (dx * dx + dy * dy + dz * dz).sqrt();
                worst = worst.max(d);
            });
        }
        worst
    })
}
