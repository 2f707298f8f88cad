//! The plan of a scan: the lines to trace, the surface to fit and how the lines are
//! characterised, frozen in the journal's start record so that a resumed scan follows it even
//! when the configuration was edited, and `surfscan analyze` of the scan's directory reports
//! as the scan did.
//!
//! Also the plan's disk estimate: the bytes a scan writes and those still to come (pure: the
//! pre-flight and the full-disk suspension compare them with the free space).
//!
//! Layer 0 (vocabulary): depends on [`crate::units`], on the two value types that say how
//! the surface is made ([`crate::fit::VMethod`], [`crate::metrology::outliers::SpikeOptions`])
//! and on those that say how it is characterised ([`MaterialRatioReading`],
//! [`crate::contact::ContactSettings`]).

use crate::contact::ContactSettings;
use crate::fit::VMethod;
use crate::metrology::outliers::SpikeOptions;
use crate::metrology::sj_material_ratio::MaterialRatioReading;
use crate::units::Nm;
use serde::{Deserialize, Serialize};

/// The plan of a scan as frozen in its start record: what a resumed scan follows even
/// when the configuration was edited since.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    /// The reading of the material-ratio family limits are judged in (a plan of an older
    /// version froze none: ISO's).
    #[serde(default)]
    pub material_ratio: MaterialRatioReading,
    /// The contact the outputs include (the station's or the recipe's `[contact]` when it is
    /// enabled; `None`: none, also in plans of older versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact: Option<ContactSettings>,
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

/// Bytes budgeted per stored point in the heights CSV (`x_mm,z_um` shortest round-trip:
/// up to ~22 + ~22 characters, comma, newline).
pub const CSV_BYTES_PER_POINT: u64 = 48;
/// Bytes budgeted per point in the IGES surface (three coordinates of a pole plus a weight
/// at up to ~24 characters each, in 64-column parameter lines with 16-column tails).
pub const IGES_BYTES_PER_POINT: u64 = 125;
/// Bytes budgeted per line for its metadata JSON and journal record.
pub const META_BYTES_PER_LINE: u64 = 8 * 1024;
/// Fixed allowance for the start record, report, plots and metrics: report.html alone may
/// take up to 4.5 MB (it embeds figures up to that size), the figures, report.json and the
/// metrics about as much again.
pub const FIXED_BYTES: u64 = 9 * 1024 * 1024;

/// Estimated bytes a scan of `lines` lines of `points_per_line` points writes.
pub fn estimate_scan_bytes(lines: u32, points_per_line: u64) -> u64 {
    let points = points_per_line.saturating_mul(u64::from(lines));
    points
        .saturating_mul(CSV_BYTES_PER_POINT + IGES_BYTES_PER_POINT)
        .saturating_add(u64::from(lines).saturating_mul(META_BYTES_PER_LINE))
        .saturating_add(FIXED_BYTES)
}

/// Estimated bytes still to be written by a scan of `lines` lines of which `committed` are
/// on disk: the remaining lines' files and records, the surface of the whole grid, and the
/// report.
pub fn remaining_scan_bytes(lines: u32, committed: u32, points_per_line: u64) -> u64 {
    let left = u64::from(lines.saturating_sub(committed));
    points_per_line
        .saturating_mul(left)
        .saturating_mul(CSV_BYTES_PER_POINT)
        .saturating_add(left.saturating_mul(META_BYTES_PER_LINE))
        .saturating_add(
            points_per_line
                .saturating_mul(u64::from(lines))
                .saturating_mul(IGES_BYTES_PER_POINT),
        )
        .saturating_add(FIXED_BYTES)
}

/// Files a scan of `lines` lines of which `committed` are on disk still creates: two per
/// remaining line (heights and metadata, each through a temporary file), the per-line plots
/// of the report (a PNG and an SVG each), and an allowance for the surface, report and
/// other outputs.
pub fn remaining_scan_inodes(lines: u32, committed: u32) -> u64 {
    let left = u64::from(lines.saturating_sub(committed));
    left.saturating_mul(3)
        .saturating_add(u64::from(lines).saturating_mul(2))
        .saturating_add(64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_disk_estimate_is_points_times_their_bytes_plus_per_line_and_fixed_parts() {
        // 31 lines × 8000 points: 248000 × 173 B + 31 × 8 KiB + 9 MiB.
        let e = estimate_scan_bytes(31, 8000);
        assert_eq!(e, 248_000 * 173 + 31 * 8192 + 9 * 1024 * 1024);
    }

    #[test]
    fn the_files_still_to_come_are_three_per_missing_line_two_plots_per_line_and_the_outputs() {
        assert_eq!(remaining_scan_inodes(31, 0), 31 * 3 + 31 * 2 + 64);
        assert_eq!(remaining_scan_inodes(31, 31), 31 * 2 + 64);
    }

    #[test]
    fn what_remains_is_the_missing_lines_plus_the_whole_surface() {
        // Nothing committed: the whole scan.
        assert_eq!(
            remaining_scan_bytes(31, 0, 8000),
            estimate_scan_bytes(31, 8000)
        );
        // 30 of 31 committed: one line's files, the surface of all 31, the fixed part.
        assert_eq!(
            remaining_scan_bytes(31, 30, 8000),
            8000 * 48 + 8192 + 31 * 8000 * 125 + 9 * 1024 * 1024
        );
        // All committed: the surface and report only.
        assert_eq!(
            remaining_scan_bytes(31, 31, 8000),
            31 * 8000 * 125 + 9 * 1024 * 1024
        );
    }
}
