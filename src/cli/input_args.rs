//! The options every command that reads heights shares (`fit`, `analyze`): the pitches of a
//! grid CSV and the unit of a CSV's heights, handed to the one reader ([`crate::input`]); and
//! how its errors map to exit statuses.
//!
//! Layer 5 (composition).

use super::{CliError, Exit};
use crate::input::{GridInput, InputError, ReadOptions, Unit};
use std::path::Path;

/// How to read the input.
#[derive(Debug, Clone, clap::Args)]
pub struct InputArgs {
    /// Pitch along x (between a grid CSV's columns), mm. A scan and an X3P file store their
    /// own, a profile CSV's x column gives it.
    #[arg(long)]
    pub pitch_x: Option<f64>,
    /// Pitch along y (between a grid CSV's rows), mm. A scan's lines are at their stored y.
    #[arg(long)]
    pub pitch_y: Option<f64>,
    /// The unit of a CSV's heights: nm, um or mm. Default: the unit its header names (z_nm,
    /// "height [mm]", …), else µm. Stating it also reads heights whose scale looks
    /// implausible for a stylus profile (with a warning) instead of refusing them.
    #[arg(long, value_name = "UNIT", value_parser = clap::value_parser!(Unit))]
    pub z_unit: Option<Unit>,
}

impl InputArgs {
    /// Refuses a pitch that is not a positive number of millimetres (a usage error whatever
    /// the file).
    pub fn check(&self) -> Result<(), CliError> {
        for (name, v) in [("--pitch-x", self.pitch_x), ("--pitch-y", self.pitch_y)] {
            if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(CliError::new(
                    Exit::Usage,
                    format!("{name} {v} mm must be a positive number of millimetres"),
                ));
            }
        }
        Ok(())
    }

    /// Reads `path` with these options, printing nothing: the findings are the caller's.
    pub fn read(&self, path: &Path) -> Result<GridInput, CliError> {
        self.check()?;
        crate::input::read(
            path,
            &ReadOptions {
                pitch_x_mm: self.pitch_x,
                pitch_y_mm: self.pitch_y,
                z_unit: self.z_unit,
            },
        )
        .map_err(input_error)
    }
}

/// The exit status of an input that cannot be read: 74 when the system cannot read it, 2 when
/// it does not go with the arguments, 1 when its content cannot be used.
pub fn input_error(e: InputError) -> CliError {
    let exit = match &e {
        e if e.is_io() => Exit::Io,
        InputError::Usage(_) => Exit::Usage,
        _ => Exit::Failed,
    };
    CliError::new(exit, e.to_string())
}

/// Prints the reader's findings as warnings.
pub fn tell_findings(input: &GridInput) {
    for w in &input.findings {
        tell!("surfscan: warning: {w}");
    }
}
