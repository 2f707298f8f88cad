//! The options `surfscan fit` and `surfscan analyze` share for the surface and the spikes:
//! the degrees, the method across the lines, spike replacement before fitting (only when asked), the
//! spike rule and the hold-out threshold of the verdict on the model between lines. Each
//! defaults to a scan's frozen plan where it has one, else to the paper.
//!
//! Layer 5 (composition).

use super::{CliError, Exit};
use crate::fit::VMethod;
use crate::metrology::outliers::SpikeOptions;

/// The method across the lines, as given on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum VMethodArg {
    /// The paper: interpolation through every line.
    Interpolate,
    /// Interpolation along the lines, least squares across them (`--v-control-rows`).
    LeastSquares,
}

/// Surface and spike options.
#[derive(Debug, Clone, clap::Args)]
pub struct ModelArgs {
    /// Degree of the model along u (x). Default: a scan's frozen plan, else 5 (the paper).
    #[arg(long)]
    pub degree_u: Option<usize>,
    /// Degree of the model along v (y). Default: a scan's frozen plan, else 5 (the paper).
    #[arg(long)]
    pub degree_v: Option<usize>,
    /// Across the lines: interpolate (the paper) or least-squares. Default: a scan's frozen
    /// plan, else interpolate.
    #[arg(long, value_enum)]
    pub v_method: Option<VMethodArg>,
    /// Pole rows across the lines for --v-method least-squares (default: a quarter of the
    /// lines, at least degree-v + 1).
    #[arg(long)]
    pub v_control_rows: Option<usize>,
    /// Replace each spike by the straight line between its neighbours before fitting
    /// (recorded in the IGES Start section and the report). Default: as a scan's frozen plan
    /// says, else the data are fitted as measured.
    #[arg(long)]
    pub replace_spikes: bool,
    /// A spike deviates from its line's median roughness by more than this many robust σ
    /// (1.4826 · MAD). Default: a scan's frozen `[analysis]` (for `analyze`), else 10.
    #[arg(long)]
    pub spike_threshold_sigma: Option<f64>,
    /// The longest run of points that counts as a spike. Default: a scan's frozen
    /// `[analysis]` (for `analyze`), else 5.
    #[arg(long)]
    pub spike_max_points: Option<usize>,
    /// The model between lines is supported by the data when the hold-out rms is at most
    /// this × Sq. Default: a scan's frozen `[analysis]` (for `analyze`), else 0.5.
    #[arg(long)]
    pub holdout_threshold: Option<f64>,
}

impl ModelArgs {
    /// Refuses a degree of 0, which no input could make valid.
    pub fn check_degrees(&self) -> Result<(), CliError> {
        if self.degree_u == Some(0) || self.degree_v == Some(0) {
            return Err(CliError::new(
                Exit::Usage,
                "--degree-u and --degree-v must be at least 1 (the paper uses 5)",
            ));
        }
        Ok(())
    }

    /// The spike rule, checked: as given, else the default rule.
    pub fn spikes(&self) -> Result<SpikeOptions, CliError> {
        self.spikes_or(SpikeOptions::default())
    }

    /// The spike rule, checked: each part as given, else as `base` has it.
    pub fn spikes_or(&self, base: SpikeOptions) -> Result<SpikeOptions, CliError> {
        let s = SpikeOptions {
            threshold_sigma: self.spike_threshold_sigma.unwrap_or(base.threshold_sigma),
            max_points: self.spike_max_points.unwrap_or(base.max_points),
        };
        s.validate()
            .map_err(|e| CliError::new(Exit::Usage, format!("--spike-*: {e}")))?;
        Ok(s)
    }

    /// The method across the lines for `lines` lines at degree `degree_v`, `None` when not
    /// given (then the scan's plan or the paper decides).
    pub fn v_method(&self, lines: usize, degree_v: usize) -> Result<Option<VMethod>, CliError> {
        match (self.v_method, self.v_control_rows) {
            (None | Some(VMethodArg::Interpolate), Some(_)) => Err(CliError::new(
                Exit::Usage,
                "--v-control-rows is for --v-method least-squares; the paper's interpolation has one pole row per line",
            )),
            (None, None) => Ok(None),
            (Some(VMethodArg::Interpolate), None) => Ok(Some(VMethod::Interpolate)),
            (Some(VMethodArg::LeastSquares), rows) => {
                let rows = rows.unwrap_or_else(|| {
                    crate::fit::approx_v::default_control_rows(lines, degree_v)
                });
                Ok(Some(VMethod::LeastSquares { control_rows: rows }))
            }
        }
    }

    /// The hold-out threshold (× Sq), checked: as given, else the default.
    pub fn holdout_threshold(&self) -> Result<f64, CliError> {
        self.holdout_threshold_or(crate::metrology::holdout::SUPPORTED_BELOW_SQ)
    }

    /// The hold-out threshold (× Sq), checked: as given, else `base`.
    pub fn holdout_threshold_or(&self, base: f64) -> Result<f64, CliError> {
        let v = self.holdout_threshold.unwrap_or(base);
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(CliError::new(
                Exit::Usage,
                format!(
                    "--holdout-threshold {v} must be a positive multiple of Sq (default {})",
                    crate::metrology::holdout::SUPPORTED_BELOW_SQ
                ),
            ))
        }
    }

    /// `Some(true)` when spike replacement was asked for, `None` otherwise (the plan decides).
    pub fn replace(&self) -> Option<bool> {
        self.replace_spikes.then_some(true)
    }
}
