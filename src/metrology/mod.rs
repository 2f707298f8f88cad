//! Surface characterisation: ISO 4287 / 21920 roughness per traced line, the ISO 13565-2 Rk
//! family and the bearing area curves of sampled curves and of the fitted NURBS model as the
//! paper's Appendix A computes them, and ISO 25178 areal parameters of a levelled height grid.
//!
//! Every number is computed the way the SJ series computes it (filter mean line as reference,
//! per-sampling-length averaging, 7-point slope, minimum-gradient 40 % secant) and carries a
//! [`Recipe`](params::Recipe) naming the filter, λc, λs, N, the standard and a definition id per
//! parameter, so it can be compared honestly with other software.
//!
//! Layer 1 (pure logic): numbers in, values out, no I/O: what the report shows is drawn and
//! written by [`crate::report`]'s renderers. Depends only on [`crate::profile`],
//! [`crate::grid`], [`crate::nurbs`] and [`crate::extremes`], and [`crate::fit`] for the
//! hold-out refits.

pub mod alternatives;
pub mod anisotropy;
pub mod areal;
pub mod bearing;
pub mod cutoff;
pub mod filter;
pub mod folds;
pub mod form;
pub mod functional;
pub mod holdout;
pub mod instrument;
pub mod model;
pub mod outliers;
pub mod parameter_table;
pub mod params;
mod sampling;
pub(crate) use sampling::{Basis, TwoLanes};
pub mod sj_material_ratio;
pub mod spatial;
pub mod surface_model;

use thiserror::Error;

/// Why a profile or grid cannot be characterised.
#[derive(Debug, Error, PartialEq)]
pub enum MetrologyError {
    /// The lateral pitch is zero, negative or not finite.
    #[error(
        "pitch {pitch_mm} mm is not a positive finite number; give the sampling interval in mm"
    )]
    BadPitch {
        /// The offending pitch in mm.
        pitch_mm: f64,
    },
    /// A cut-off wavelength is zero, negative or not finite.
    #[error("cut-off {cutoff_mm} mm is not a positive finite number; use e.g. 0.08, 0.25, 0.8, 2.5 or 8 mm")]
    BadCutoff {
        /// The offending cut-off in mm.
        cutoff_mm: f64,
    },
    /// A height is NaN or infinite.
    #[error(
        "height at index {index} is {value} (not finite); remove invalid points before analysis"
    )]
    NonFiniteHeight {
        /// Index of the point.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A height is finite but beyond any surface ([`MAX_HEIGHT_UM`]): a file in other units or
    /// with damaged numbers. Refused before the parameters' squares and sums overflow.
    #[error(
        "height at index {index} is {value:e} µm, beyond ±{max:e} µm (1 km): no surface height; check the data's units (heights in µm) and whether the file is damaged",
        max = MAX_HEIGHT_UM
    )]
    HeightOutOfRange {
        /// Index of the point.
        index: usize,
        /// Its value, µm.
        value: f64,
    },
    /// The profile is shorter than one sampling length, or too short for the 7-point slope.
    #[error("profile of {points} points ({length_mm} mm) is shorter than one sampling length of {sampling_length_mm} mm or than {min_points} points; trace a longer profile or choose a shorter λc")]
    TooShort {
        /// Points in the profile.
        points: usize,
        /// Its length in mm.
        length_mm: f64,
        /// The sampling length asked for, in mm.
        sampling_length_mm: f64,
        /// Minimum points per sampling length.
        min_points: usize,
    },
    /// The profile is longer than a sampling length, but the pitch leaves fewer points in one
    /// than the parameters need: typically x or the pitch given in µm where mm are meant.
    #[error("pitch {pitch_mm} mm leaves {points_per_sampling_length} points in a sampling length of {sampling_length_mm} mm, fewer than {min_points}; check that the pitch (x) is in mm, or choose a longer λc")]
    PitchTooCoarse {
        /// The pitch, mm.
        pitch_mm: f64,
        /// Whole points in one sampling length at that pitch.
        points_per_sampling_length: usize,
        /// The sampling length asked for, in mm.
        sampling_length_mm: f64,
        /// Minimum points per sampling length.
        min_points: usize,
    },
    /// The requested number of sampling lengths is zero.
    #[error("number of sampling lengths must be at least 1 (got {got})")]
    ZeroSections {
        /// The number given.
        got: u32,
    },
    /// The grid dimensions do not match the number of heights.
    #[error("grid of {rows} rows × {cols} columns needs {expected} heights, got {got}")]
    GridSize {
        /// Rows (lines along y).
        rows: usize,
        /// Columns (points along x).
        cols: usize,
        /// rows × cols.
        expected: usize,
        /// Heights given.
        got: usize,
    },
    /// A grid needs at least 2 × 2 points for slopes and levelling.
    #[error(
        "grid of {rows} × {cols} is too small; at least 2 × 2 points (3 × 3 for slopes) are needed"
    )]
    GridTooSmall {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
    },
    /// The NURBS fit of a hold-out grid failed.
    #[error("the NURBS fit for the hold-out comparison failed: {0}")]
    Fit(#[from] crate::fit::FitError),
    /// The surface fit with a method across the lines (e.g. least squares) failed.
    #[error("the surface fit for the hold-out comparison failed: {0}")]
    FitMethod(#[from] crate::fit::MethodError),
    /// A plot could not be drawn or written.
    #[error(
        "cannot write the plot {path}: {message}; check the directory's permissions and free space"
    )]
    Plot {
        /// The file.
        path: String,
        /// What plotters reported.
        message: String,
    },
    /// An X3P file cannot be read.
    #[error("not a readable X3P file: {reason}")]
    X3p {
        /// What is wrong, with the value found.
        reason: String,
    },
    /// Too few lines to leave one out and refit the rest (the hold-outs and the verdict
    /// between lines).
    #[error("{rows} lines cannot verify the surface between them: leaving one out leaves at most degree-v + 1 = {} for the refit; trace more lines or lower degree-v", degree_v + 1)]
    NoLineToHoldOut {
        /// The lines of the grid.
        rows: usize,
        /// The refit's degree across the lines.
        degree_v: usize,
    },
    /// A bearing-area parameter is out of range.
    #[error("{what} = {value} is out of range; {hint}")]
    BadParameter {
        /// Parameter name.
        what: &'static str,
        /// Its value.
        value: f64,
        /// What is accepted.
        hint: &'static str,
    },
}

/// The largest height magnitude characterised, µm (1 km): far beyond anything a stylus
/// traces, and small enough that fourth powers and sums over any grid stay finite.
pub const MAX_HEIGHT_UM: f64 = 1e9;

/// Checks that every height is finite and within ±[`MAX_HEIGHT_UM`]; the first that is not is
/// named.
pub(crate) fn check_heights(heights: &[f64]) -> Result<(), MetrologyError> {
    // One comparison per height: false for NaN and ±∞ as for a finite height out of range.
    match heights.iter().position(|z| !z.abs().le(&MAX_HEIGHT_UM)) {
        Some(index) => {
            let value = heights.get(index).copied().unwrap_or(f64::NAN);
            Err(if value.is_finite() {
                MetrologyError::HeightOutOfRange { index, value }
            } else {
                MetrologyError::NonFiniteHeight { index, value }
            })
        }
        None => Ok(()),
    }
}

/// Checks a lateral pitch in mm.
pub(crate) fn check_pitch(pitch_mm: f64) -> Result<(), MetrologyError> {
    if pitch_mm.is_finite() && pitch_mm > 0.0 {
        Ok(())
    } else {
        Err(MetrologyError::BadPitch { pitch_mm })
    }
}

/// `f(index, item)` of every item, in their order, worked out in parallel: one run of
/// consecutive items per available core, each run in its own thread. The items of a run whose
/// thread panicked get `panicked(index)`.
pub(crate) fn map_in_parallel<T: Sync, R: Send>(
    items: &[T],
    f: impl Fn(usize, &T) -> R + Sync,
    panicked: impl Fn(usize) -> R,
) -> Vec<R> {
    let workers = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, items.len().max(1));
    let chunk = items.len().div_ceil(workers).max(1);
    let f = &f;
    std::thread::scope(|s| {
        let runs: Vec<_> = (0..items.len())
            .step_by(chunk)
            .map(|first| {
                let run = first..(first + chunk).min(items.len());
                let work = run.clone();
                (
                    run,
                    s.spawn(move || work.map(|i| f(i, &items[i])).collect::<Vec<R>>()),
                )
            })
            .collect();
        runs.into_iter()
            .flat_map(|(run, h)| h.join().unwrap_or_else(|_| run.map(&panicked).collect()))
            .collect()
    })
}

/// The middle of the bracket [`a`, `b`] after 60 halvings: each midpoint `m` replaces `a`
/// when `below(m)` (the sought point lies beyond `m`), else `b`.
pub(crate) fn bisect(mut a: f64, mut b: f64, below: impl Fn(f64) -> bool) -> f64 {
    for _ in 0..60 {
        let m = 0.5 * (a + b);
        if below(m) {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

/// Uniform in [0, 1) from a linear congruential generator: deterministic noise for the tests.
#[cfg(test)]
pub(crate) fn lcg(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*seed >> 11) as f64 / (1u64 << 53) as f64
}

/// `rows` lines 0.01 mm apart of `cols` points at `pitch_x_mm`, heights `f(row, col)`: the
/// tests' grids.
#[cfg(test)]
pub(crate) fn test_grid(
    rows: usize,
    cols: usize,
    pitch_x_mm: f64,
    mut f: impl FnMut(usize, usize) -> f64,
) -> crate::grid::Grid {
    let y = (0..rows).map(|r| r as f64 * 0.01).collect();
    let z = (0..rows * cols).map(|k| f(k / cols, k % cols)).collect();
    crate::grid::Grid::new(z, cols, pitch_x_mm, y)
}

/// The paper's fit (degrees 5/5) of `grid`: the tests' fitted surfaces.
#[cfg(test)]
pub(crate) fn test_fit(grid: &crate::grid::Grid) -> crate::fit::FitResult {
    let (z, o) = (&grid.heights_um, crate::fit::FitOptions::default());
    crate::fit::fit_grid(grid.pitch_x_mm, &grid.y_mm, z, grid.cols, o).unwrap()
}
