//! Why a grid cannot be interpolated: every variant names the line, point or direction and
//! carries the offending numbers.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] (the surface's own invariants).

use crate::nurbs::SurfaceError;
use thiserror::Error;

/// Why a grid cannot be interpolated. Every variant carries the offending numbers.
#[derive(Debug, Error, PartialEq)]
pub enum FitError {
    /// A degree is zero.
    #[error(
        "degrees must be at least 1 (got u={degree_u}, v={degree_v}); use 5/5 as in the paper"
    )]
    InvalidDegree {
        /// Degree along u.
        degree_u: usize,
        /// Degree along v.
        degree_v: usize,
    },
    /// A line has a different number of points than the first line.
    #[error("line {line} has {got} points but the first line had {expected}; all lines must have the same length")]
    RowLength {
        /// Line index (0-based).
        line: usize,
        /// Points in this line.
        got: usize,
        /// Points in the first line.
        expected: usize,
    },
    /// A height is NaN or infinite.
    #[error(
        "line {line}, point {index}: height {value} µm is not finite; re-measure or drop the line"
    )]
    NonFinite {
        /// Line index.
        line: usize,
        /// Point index within the line.
        index: usize,
        /// The value.
        value: f64,
    },
    /// A line's y position is NaN or infinite.
    #[error("line {line}: y = {y_mm} mm is not finite")]
    NonFiniteY {
        /// Line index.
        line: usize,
        /// The value.
        y_mm: f64,
    },
    /// The lines' y positions are not strictly monotone (repeated or reversed).
    #[error("line {line}: y = {y_mm} mm does not continue the strictly monotone order after {previous_y_mm} mm")]
    LineOrder {
        /// Line index.
        line: usize,
        /// Its y.
        y_mm: f64,
        /// y of the previous line.
        previous_y_mm: f64,
    },
    /// The x pitch is not a positive finite number.
    #[error("line {line}: x pitch {pitch_x_mm} mm must be positive and finite")]
    BadPitch {
        /// Line index.
        line: usize,
        /// The pitch.
        pitch_x_mm: f64,
    },
    /// The x pitch differs from the first line's.
    #[error("line {line}: x pitch {got} mm differs from the first line's {expected} mm; all lines must share one pitch")]
    PitchMismatch {
        /// Line index.
        line: usize,
        /// Its pitch.
        got: f64,
        /// The first line's pitch.
        expected: f64,
    },
    /// Fewer lines than degree_v + 1.
    #[error("{got} lines is fewer than degree_v + 1 = {need}; trace more lines or lower degree_v")]
    TooFewRows {
        /// Lines so far.
        got: usize,
        /// Lines needed.
        need: usize,
    },
    /// Fewer points per line than degree_u + 1.
    #[error("{got} points per line is fewer than degree_u + 1 = {need}; lower degree_u or measure longer lines")]
    TooFewColumns {
        /// Points per line.
        got: usize,
        /// Points needed.
        need: usize,
    },
    /// Two consecutive points coincide (zero chord), so chord-length parameters are undefined.
    #[error("{direction} direction, line {line}, point {index}: zero chord length to the previous point ({previous:?} → {point:?} mm); remove duplicate points")]
    CoincidentPoints {
        /// "u" (along a line) or "v" (across lines, within a column).
        direction: &'static str,
        /// Line index (row).
        line: usize,
        /// Point index (column).
        index: usize,
        /// The previous point (x, y, z) in mm.
        previous: [f64; 3],
        /// The point (x, y, z) in mm.
        point: [f64; 3],
    },
    /// A chord length overflowed (heights or positions far too large).
    #[error("{direction} direction, line {line}, point {index}: chord length {chord} mm is not finite; check units of the heights (µm) and positions (mm)")]
    ChordOverflow {
        /// "u" or "v".
        direction: &'static str,
        /// Line index.
        line: usize,
        /// Point index.
        index: usize,
        /// The chord.
        chord: f64,
    },
    /// `fit_grid` was given a height array that is not rows × cols.
    #[error("grid has {len} heights, expected {rows} rows × {cols} columns")]
    GridShape {
        /// Heights given.
        len: usize,
        /// Rows (y values given).
        rows: usize,
        /// Columns given.
        cols: usize,
    },
    /// A zero or non-finite pivot in the collocation factorisation.
    #[error("{direction} collocation matrix has pivot {pivot} at row {index}; the parameters are degenerate")]
    SingularCollocation {
        /// "u" or "v".
        direction: &'static str,
        /// Row.
        index: usize,
        /// Pivot value.
        pivot: f64,
    },
    /// The assembled surface failed its invariants.
    #[error("fitted surface is invalid: {0}")]
    Surface(#[from] SurfaceError),
}
