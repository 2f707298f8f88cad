//! Why a contact analysis cannot be done, each case with the numbers that decided it and what
//! to do instead.
//!
//! Layer 1 (pure logic): depends on [`super::solver`] (the state an unconverged solve
//! reached).

use super::solver::NotConverged;
use thiserror::Error;

/// Why a contact analysis was refused or failed.
#[derive(Debug, Error, PartialEq)]
pub enum ContactError {
    /// A pitch is zero, negative or not finite.
    #[error("{axis} pitch {pitch_mm} mm is not a positive finite number; give the grid's {axis} spacing in mm")]
    Pitch {
        /// "x" or "y".
        axis: &'static str,
        /// The offending pitch.
        pitch_mm: f64,
    },
    /// The heights do not fill the grid.
    #[error("{len} heights do not fill a grid of {rows} × {cols} points")]
    Shape {
        /// Rows (lines).
        rows: usize,
        /// Columns (points per line).
        cols: usize,
        /// Heights given.
        len: usize,
    },
    /// A height is NaN or infinite.
    #[error("height at row {row}, column {col} is {value} (not finite); contact needs a complete grid — fill or crop the invalid points first")]
    Height {
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The value.
        value: f64,
    },
    /// Too few points along an axis to resolve any contact patch.
    #[error("a grid of {rows} × {cols} points is too small to resolve contact: it needs at least {min} points along each axis (lines and points per line)")]
    TooSmall {
        /// Rows (lines).
        rows: usize,
        /// Columns.
        cols: usize,
        /// The minimum per axis.
        min: usize,
    },
    /// Young's modulus out of range.
    #[error("Young's modulus of the {body} {young_gpa} GPa is outside {min}…{max} GPa; give it in GPa (steel 210, brass 100, aluminium 70)", min = super::modulus::MIN_YOUNG_GPA, max = super::modulus::MAX_YOUNG_GPA)]
    Young {
        /// "specimen" or "counter-body".
        body: &'static str,
        /// The offending value.
        young_gpa: f64,
    },
    /// Poisson's ratio out of range.
    #[error("Poisson's ratio of the {body} {poisson} is outside 0…0.5 (steel 0.30, brass 0.34)")]
    Poisson {
        /// "specimen" or "counter-body".
        body: &'static str,
        /// The offending value.
        poisson: f64,
    },
    /// Hardness out of range.
    #[error("hardness {hardness_gpa} GPa is outside {min}…{max} GPa; give the indentation hardness in GPa (mild steel about 1.5, brass about 1)", min = MIN_HARDNESS_GPA, max = MAX_HARDNESS_GPA)]
    Hardness {
        /// The offending value.
        hardness_gpa: f64,
    },
    /// A nominal pressure that is not a positive finite number, or no pressure at all.
    #[error("nominal pressure {pressure_mpa} MPa is not a positive finite number; give the pressures in MPa, e.g. 1,10,100")]
    Pressure {
        /// The offending value (NaN when the list was empty).
        pressure_mpa: f64,
    },
    /// A nominal pressure at or above the hardness: a perfectly plastic surface cannot carry
    /// it even in full contact.
    #[error("nominal pressure {pressure_mpa} MPa is beyond full contact: a perfectly plastic surface of hardness {hardness_mpa} MPa carries at most that mean pressure with every point flowing; give pressures below the hardness")]
    BeyondHardness {
        /// The requested pressure.
        pressure_mpa: f64,
        /// The hardness.
        hardness_mpa: f64,
    },
    /// The whole grid is in contact: the load is at or beyond full contact, where the area
    /// and the gap no longer say anything about the roughness.
    #[error("at {pressure_mpa} MPa the whole grid is in contact: the load is at or beyond full contact; give lower pressures{}", match last_partial_mpa { Some(p) => format!(" (at {p} MPa part of the surface was still open)"), None => String::new() })]
    FullContact {
        /// The pressure that closed the last gap.
        pressure_mpa: f64,
        /// The highest solved pressure that left part of the grid open.
        last_partial_mpa: Option<f64>,
    },
    /// A solve hit its iteration limit.
    #[error("the contact at {pressure_mpa} MPa did not converge in {} iterations (complementarity residual {:.3e} µm against a tolerance of {:.3e} µm, last pressure change {:.2e}, area fraction {:.4}); the surface may be too rough for the grid or the load too close to full contact", state.iterations, state.gap_residual_um, state.gap_tolerance_um, state.pressure_change, state.area_fraction)]
    NotConverged {
        /// The pressure being solved.
        pressure_mpa: f64,
        /// How far it got.
        state: NotConverged,
    },
    /// At every requested load, most of the contact is made of isolated single points: the
    /// grid does not resolve the contact patches.
    #[error("the grid ({rows} × {cols} points, pitch {pitch_x_mm} mm along x, {pitch_y_mm} mm between lines) is too coarse to resolve contact: at every requested load more than half of the contact points are isolated single points (at the highest load, {:.0} %); scan with a finer pitch or sample the model more finely", 100.0 * single_point_fraction)]
    Unresolved {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
        /// Pitch along x, mm.
        pitch_x_mm: f64,
        /// Pitch between lines, mm.
        pitch_y_mm: f64,
        /// Fraction of contact points in single-point patches at the highest load.
        single_point_fraction: f64,
    },
}

/// Smallest accepted hardness, GPa (soft polymers).
pub const MIN_HARDNESS_GPA: f64 = 1e-3;
/// Largest accepted hardness, GPa (diamond is about 100).
pub const MAX_HARDNESS_GPA: f64 = 150.0;
