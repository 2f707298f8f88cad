//! The paper's incremental NURBS surface interpolation (section 2): chord-length parameters averaged over rows and columns, averaged knots, banded collocation solves.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`], [`crate::units`], [`crate::profile`]; no I/O, no tokio.
//!
//! The algorithm is P&T A9.3/A9.4 exactly as `geomdl.fitting.interpolate_surface` does it.
//! Data point Q(k, l) = (k·pitch, y_l, z_kl / 1000) in mm, k = column (u, x), l = row (v, y);
//! every distance, including the chord lengths that define the parameters, is in mm.
//!
//! * Parameters along u: per row, cumulative 3-D chord lengths normalised to [0, 1], averaged
//!   over rows; along v likewise per column, averaged over columns.
//! * Knots by averaging (P&T eq. 9.8), clamped.
//! * The collocation matrix of each direction is the same for every line (the parameters are
//!   averaged), so it is factored once (banded LU without pivoting; totally positive) and
//!   applied to every row (u), then to every column (v, streaming over whole rows).
//! * z goes through both solves. x depends only on u and y only on v, and B-splines sum to
//!   one, so the x poles are the 1-D solve of the x values along u (the same for every row)
//!   and the y poles the 1-D solve of the y values along v. This equals the two-direction
//!   solve up to rounding.
//!
//! [`IncrementalFitter::push_line`] does each line's share on arrival (validation, row
//! parameters, running sums, column chord accumulation); [`IncrementalFitter::finish`] only
//! what needs all lines. [`fit_grid`] goes through the same path, so an incremental fit is
//! bit-identical to a batch fit of the same data.
//!
//! Speed without changing a bit: the hot loops run in one AVX2 dispatch (`simd`, no FMA,
//! so each lane does the scalar IEEE operations in the scalar order), the u solves run eight
//! rows interleaved, and the large stores and the pole net are advised for huge pages
//! (`memory`) so their first touch does not cost a page fault per 4 KiB.
//!
//! One concept per file: `options` ([`FitOptions`]), `error` ([`FitError`]), `result`
//! ([`FitResult`]), `incremental` ([`IncrementalFitter`], the per-line work), `params`
//! (averaged parameters and knots), `solve` (the work after the last line), `banded`
//! ([`BandLu`]), `residual` ([`max_residual_mm`]), `simd` and `memory` (speed without
//! changing a bit).

pub mod approx_v;
mod banded;
mod error;
mod incremental;
pub(crate) mod memory;
mod options;
mod params;
mod residual;
mod result;
mod simd;
mod solve;

pub use approx_v::{fit_grid_with, MethodError, VMethod};
pub use banded::{BandLu, ZeroPivot};
pub use error::FitError;
pub use incremental::IncrementalFitter;
pub use options::FitOptions;
pub use params::averaged_knots;
pub use residual::max_residual_mm;
pub use result::{FitResult, FitTimings};

/// Fits a whole grid at once: rows are lines at `y_mm`, `heights_um` is row-major
/// `y_mm.len() × cols` in µm. Goes through [`IncrementalFitter`], so the result is
/// bit-identical to pushing the rows one by one.
pub fn fit_grid(
    pitch_x_mm: f64,
    y_mm: &[f64],
    heights_um: &[f64],
    cols: usize,
    options: FitOptions,
) -> Result<FitResult, FitError> {
    let rows = y_mm.len();
    if cols == 0 || heights_um.len() != rows * cols {
        return Err(FitError::GridShape {
            len: heights_um.len(),
            rows,
            cols,
        });
    }
    let mut fitter = IncrementalFitter::new(options);
    fitter.reserve_lines(rows, cols);
    for (row, &y) in heights_um.chunks_exact(cols).zip(y_mm) {
        fitter.push_row(y, pitch_x_mm, row)?;
    }
    fitter.finish()
}

#[cfg(test)]
mod tests;
