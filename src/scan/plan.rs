//! The plan of a scan: the lines to trace, the surface to fit and how the lines are
//! characterised, frozen in the journal's start record so that a resumed scan follows it even
//! when the configuration was edited, and `surfscan analyze` of the scan's directory reports
//! as the scan did.
//!
//! Layer 0 (vocabulary): depends on [`crate::units`], and on the two value types that say
//! how the surface is made ([`crate::fit::VMethod`], [`crate::metrology::outliers::SpikeOptions`]).

use crate::fit::VMethod;
use crate::metrology::outliers::SpikeOptions;
use crate::units::Nm;
use serde::{Deserialize, Serialize};

/// The plan of a scan as frozen in its start record: what a resumed scan follows even
/// when the configuration was edited since.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    /// Number of lines.
    pub lines: u32,
    /// y of the first line.
    pub y_start_nm: Nm,
    /// y step between lines.
    pub y_step_nm: Nm,
    /// Degree along u.
    pub degree_u: usize,
    /// Degree along v.
    pub degree_v: usize,
    /// Attempts per line.
    pub max_line_attempts: u32,
    /// How the surface is made across the lines (journals written before the key existed
    /// read as the paper's interpolation).
    #[serde(default)]
    pub v_method: VMethod,
    /// Replace the spikes this rule finds before fitting (`None`, the default and what older
    /// journals read as: fit the data as measured).
    #[serde(default)]
    pub replace_spikes: Option<SpikeOptions>,
    /// How the lines are characterised when the scan completes (`None` in journals written
    /// before it was frozen: the characterisation then takes the settings of the run that
    /// completes the scan, and `analyze` its defaults).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub analysis: Option<AnalysisPlan>,
}

/// How a scan's lines are characterised (the station's `[analysis]` when the scan started).
/// The degrees, the method across the lines and the spike replacement are the plan's own.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnalysisPlan {
    /// Profile curves extracted from the model for the bearing area curves.
    pub curves: usize,
    /// Equal height levels per bearing area curve.
    pub levels: usize,
    /// λc in mm overriding the instrument's recorded cut-off (`None`: the recorded one).
    pub lambda_c_mm: Option<f64>,
    /// Never apply the λc filter.
    pub no_filter: bool,
    /// The spike rule.
    pub spikes: SpikeOptions,
    /// Leave the spikes out of the per-line and measured-grid parameters (else flag them).
    pub exclude_spikes: bool,
    /// The model between lines is supported when the hold-out rms is at most this × Sq.
    pub holdout_threshold: f64,
}

impl Plan {
    /// Absolute y target of line `index` (0-based).
    pub fn target(&self, index: u32) -> Nm {
        Nm(self.y_start_nm.0 + i64::from(index) * self.y_step_nm.0)
    }

    /// Every target, in line order.
    pub fn targets(&self) -> Vec<Nm> {
        (0..self.lines).map(|k| self.target(k)).collect()
    }
}
