//! The work after the last line: averaged parameters, knots, the factorised collocation
//! matrices and the banded solves along u (each row) and v (all columns), assembled into the
//! control net.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] and the fit's own modules; no I/O.

use super::incremental::secs;
use super::params::{average_params_u, average_params_v, averaged_knots};
use super::{simd, BandLu, FitError, FitOptions, FitResult, FitTimings, IncrementalFitter};
use crate::nurbs::{NurbsSurface, PoleNet};
use std::time::Instant;

impl IncrementalFitter {
    /// Averages, knots, factorisations and solves; `z` is the row-major height grid in mm and
    /// becomes the z coordinates of the poles.
    /// The averaged parameters ū and v̄ from the running sums, and the seconds it took.
    pub(super) fn averaged_params(&self) -> (Vec<f64>, Vec<f64>, f64) {
        let (rows, cols) = (self.lines(), self.cols);
        let t = Instant::now();
        let params_u = average_params_u(&self.sum_u, rows);
        let params_v = simd::wide(|| {
            average_params_v(&self.z_mm[..rows * cols], &self.y_mm, cols, &self.cum_v)
        });
        (params_u, params_v, secs(t))
    }

    /// Knots, factorisations and solves from the averaged parameters (see
    /// [`IncrementalFitter::averaged_params`], which needs the column chords; the solve does
    /// not, so [`IncrementalFitter::finish`] frees them first).
    pub(super) fn solve(
        &self,
        mut z: Vec<f64>,
        (params_u, params_v, params_s): (Vec<f64>, Vec<f64>, f64),
    ) -> Result<FitResult, FitError> {
        let FitOptions {
            degree_u: p,
            degree_v: q,
        } = self.options;
        let (rows, cols) = (self.lines(), self.cols);
        let mut timings = FitTimings {
            params_s: self.params_s + params_s,
            ..FitTimings::default()
        };

        let t = Instant::now();
        let knots_u = averaged_knots(&params_u, p);
        let knots_v = averaged_knots(&params_v, q);
        let lu_u = BandLu::collocation(p, &knots_u, &params_u).map_err(|e| {
            FitError::SingularCollocation {
                direction: "u",
                index: e.index,
                pivot: e.pivot,
            }
        })?;
        let lu_v = BandLu::collocation(q, &knots_v, &params_v).map_err(|e| {
            FitError::SingularCollocation {
                direction: "v",
                index: e.index,
                pivot: e.pivot,
            }
        })?;
        timings.knots_factor_s = secs(t);

        let t = Instant::now();
        lu_u.solve_each_row(&mut z);
        let mut px: Vec<f64> = (0..cols).map(|k| k as f64 * self.pitch_x_mm).collect();
        lu_u.solve_in_place(&mut px);
        timings.solve_u_s = secs(t);

        let t = Instant::now();
        let mut py = self.y_mm.clone();
        lu_v.solve_in_place(&mut py);
        // The heights solved in place are the poles' z; x is per column and y per row (module
        // docs of `fit`), so the net is those three, not three coordinates per pole.
        lu_v.solve_rows_in_place(&mut z, cols);
        let net = PoleNet::separable(px, py, z).ok_or(FitError::GridShape {
            len: rows * cols,
            rows,
            cols,
        })?;
        let surface = NurbsSurface::try_from_net(p, q, knots_u, knots_v, cols, rows, net)?;
        timings.solve_v_s = secs(t);

        Ok(FitResult {
            surface,
            params_u,
            params_v,
            timings,
            x0_mm: 0.0,
        })
    }
}
