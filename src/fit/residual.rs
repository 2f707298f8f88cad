//! How well a fitted surface meets its data: the largest distance to a data point.
//!
//! Layer 1 (pure logic): depends on the fit's result type and [`crate::nurbs`] evaluation.
//!
//! The basis functions along u are the same for every row (the parameters ū_k are shared), so
//! they are computed once; each row then reduces the net to its iso-curve and evaluates it at
//! every ū_k with the stored basis. The arithmetic per point is that of
//! [`NurbsSurface::evaluate_grid`](crate::nurbs::NurbsSurface::evaluate_grid) (same products,
//! same order), so the residual is the same to the bit.
//!
//! Speed without changing a bit: the largest squared distance is found and its square root
//! taken once (the square root is correctly rounded and never decreasing, so the root of the
//! largest is the largest root), and a large grid is split by columns over a few threads, each
//! with the basis and the iso-curve poles of its own columns (the maximum does not depend on
//! the order it is taken in).

use super::{simd, FitResult};
use crate::nurbs::{NurbsSurface, UBasis};

/// Grids with at least this many points are split over threads.
const PARALLEL_POINTS: usize = 100_000;

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
    let threads = if rows * cols >= PARALLEL_POINTS {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .clamp(1, 4)
            .min(cols)
    } else {
        1
    };
    let grid = Grid {
        surface: &result.surface,
        params_u: &result.params_u,
        params_v: &result.params_v,
        pitch_x_mm,
        y_mm,
        heights_um,
        cols,
    };
    let worst_sq = if threads <= 1 {
        grid.worst_squared(0..cols)
    } else {
        let chunk = cols.div_ceil(threads);
        std::thread::scope(|scope| {
            let grid = &grid;
            let handles: Vec<_> = (0..cols)
                .step_by(chunk)
                .map(|lo| scope.spawn(move || grid.worst_squared(lo..(lo + chunk).min(cols))))
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or(f64::INFINITY))
                .fold(0.0f64, f64::max)
        })
    };
    worst_sq.sqrt()
}

/// The data grid beside the surface fitted to it.
struct Grid<'a> {
    surface: &'a NurbsSurface,
    params_u: &'a [f64],
    params_v: &'a [f64],
    pitch_x_mm: f64,
    y_mm: &'a [f64],
    heights_um: &'a [f64],
    cols: usize,
}

impl Grid<'_> {
    /// Largest squared distance over the data columns `columns` of every row.
    fn worst_squared(&self, columns: std::ops::Range<usize>) -> f64 {
        let basis = UBasis::new(self.surface, &self.params_u[columns.clone()]);
        let poles = basis.pole_range();
        let mut curve = Vec::new();
        simd::wide(|| {
            let mut worst = 0.0f64;
            for ((row, &y), &v) in self
                .heights_um
                .chunks_exact(self.cols)
                .zip(self.y_mm)
                .zip(self.params_v)
            {
                let row = &row[columns.clone()];
                self.surface
                    .iso_poles_u_padded_range(v, poles.clone(), &mut curve);
                basis.for_each_point_from(poles.start, &curve, |k, p| {
                    let q = [
                        (columns.start + k) as f64 * self.pitch_x_mm,
                        y,
                        row[k] / 1000.0,
                    ];
                    let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                    worst = worst.max(dx * dx + dy * dy + dz * dz);
                });
            }
            worst
        })
    }
}
