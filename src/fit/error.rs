//! Why a grid cannot be interpolated: every variant names the line, point or direction and
//! carries the offending numbers. Messages count lines from 1 with the 0-based file index
//! beside it (`line 5 (0004)`), and write positions and pitches with the digits a person
//! reads ([`crate::numfmt`]); the variants keep the full values.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] (the surface's own invariants) and
//! [`crate::numfmt`].

use crate::numfmt::{fmt, Quantity};
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
    #[error("line {} ({:04}) has {got} points but the first line had {expected}; all lines must have the same length", .line + 1, .line)]
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
        "line {} ({:04}), point {index}: height {value} µm is not finite; re-measure or drop the line", .line + 1, .line
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
    #[error("line {} ({:04}): y = {y_mm} mm is not finite", .line + 1, .line)]
    NonFiniteY {
        /// Line index.
        line: usize,
        /// The value.
        y_mm: f64,
    },
    /// The lines' y positions are not strictly monotone (repeated or reversed).
    #[error("line {} ({:04}): y = {} mm does not continue the strictly monotone order after {} mm", .line + 1, .line, pos(*.y_mm), pos(*.previous_y_mm))]
    LineOrder {
        /// Line index.
        line: usize,
        /// Its y.
        y_mm: f64,
        /// y of the previous line.
        previous_y_mm: f64,
    },
    /// The x pitch is not a positive finite number.
    #[error("line {} ({:04}): x pitch {} mm must be positive and finite", .line + 1, .line, len(*.pitch_x_mm))]
    BadPitch {
        /// Line index.
        line: usize,
        /// The pitch.
        pitch_x_mm: f64,
    },
    /// The x pitch differs from the first line's.
    #[error("line {} ({:04}): x pitch {} mm differs from the first line's {} mm; all lines must share one pitch", .line + 1, .line, len(*.got), len(*.expected))]
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
    #[error("{direction} direction, line {} ({:04}), point {index}: zero chord length to the previous point ({previous:?} → {point:?} mm); remove duplicate points", .line + 1, .line)]
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
    #[error("{direction} direction, line {} ({:04}), point {index}: chord length {chord} mm is not finite; check units of the heights (µm) and positions (mm)", .line + 1, .line)]
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

/// A lateral position for a message.
fn pos(v: f64) -> String {
    fmt(v, Quantity::PositionMm)
}

/// A pitch or length for a message.
fn len(v: f64) -> String {
    fmt(v, Quantity::LengthMm)
}
