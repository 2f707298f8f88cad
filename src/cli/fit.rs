//! `surfscan fit`: CSV grid of heights → NURBS surface → IGES file and fit report.
//!
//! Layer 5 (composition).

use super::{CliError, Exit};
use std::path::PathBuf;

/// Arguments of `surfscan fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Grid CSV of heights in µm (rows = traced lines along y, columns = points along x).
    pub input: PathBuf,
    /// Output IGES file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Pitch along x (between columns), mm.
    #[arg(long)]
    pub pitch_x: f64,
    /// Pitch along y (between rows), mm.
    #[arg(long)]
    pub pitch_y: f64,
    /// Degree along u (x).
    #[arg(long, default_value_t = 5)]
    pub degree_u: usize,
    /// Degree along v (y).
    #[arg(long, default_value_t = 5)]
    pub degree_v: usize,
    /// Write a JSON fit report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// Runs `surfscan fit`.
pub fn run(_args: Args) -> Result<(), CliError> {
    Err(CliError::new(
        Exit::Failed,
        "surfscan fit: the fitter is being wired in",
    ))
}
