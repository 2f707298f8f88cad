//! A stored line: its metadata (`NNNN.json`) and its profile (`NNNN.csv`).
//!
//! Layer 3 (session): depends on [`crate::profile`], [`crate::devices`] (the read-out
//! warnings) and [`crate::units`]; no I/O.

use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};

use crate::devices::ReadoutWarning;
use crate::profile::{Conditions, InstrumentResult, Profile, ProfileKind};
use crate::units::Nm;

/// The metadata stored next to a line's heights in `NNNN.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineMeta {
    /// 0-based line index.
    pub index: u32,
    /// Target y of the line.
    pub y_target_nm: Nm,
    /// y read back from the stage after settling, when the stage reports one.
    pub y_readback_nm: Option<Nm>,
    /// Distance between points along x, mm.
    pub pitch_x_mm: f64,
    /// Number of points in the heights file.
    pub points: usize,
    /// Profile kind.
    pub kind: ProfileKind,
    /// Conditions of the trace.
    pub conditions: Conditions,
    /// The instrument's own results for this trace.
    pub results: Vec<InstrumentResult>,
    /// Doubts about the profile read-out that a re-read did not clear.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub readout_warnings: Vec<ReadoutWarning>,
    /// When the trace was started.
    pub started_at: DateTime<Utc>,
    /// When the profile had been read out.
    pub finished_at: DateTime<Utc>,
    /// 1-based attempt that produced this line.
    pub attempt: u32,
}

/// A line loaded back from a scan directory.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredLine {
    /// Its metadata.
    pub meta: LineMeta,
    /// Its profile (pitch, heights, kind and conditions from the files).
    pub profile: Profile,
}

impl StoredLine {
    /// Target y of the line in mm.
    pub fn y_mm(&self) -> f64 {
        self.meta.y_target_nm.to_mm()
    }
}

/// The lines of a scan directory as found by [`ScanStore::load_all`](super::store::ScanStore::load_all).
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedLines {
    /// Complete lines, in index order.
    pub lines: Vec<StoredLine>,
    /// Indices with only one of their two files (not loaded).
    pub incomplete: Vec<u32>,
}
