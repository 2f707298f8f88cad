//! A stored line: its metadata (`NNNN.json`) and its profile (`NNNN.csv`).
//!
//! The metadata is made of the two descriptions it shares: the line's [`LineIdentity`]
//! (also the journal's line record) and its profile's header ([`ProfileHeader`], the same
//! struct as [`Profile`] without the heights). Each is embedded with `serde(flatten)`, so
//! the file keeps one flat JSON object, and `deny_unknown_fields` still refuses a member
//! none of them knows (serde checks what the flattened structs left over).
//!
//! Layer 3 (session): depends on [`crate::profile`], [`crate::devices`] (the read-out
//! warnings) and [`crate::units`]; no I/O.

use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};

use crate::devices::ReadoutWarning;
use crate::profile::{InstrumentResult, Profile, ProfileHeader};
use crate::units::Nm;

/// Which line, where, from which attempt and how many points: the facts a line's metadata
/// file and its journal record share (both embed this struct, its fields at their top level).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct LineIdentity {
    /// 0-based line index.
    pub index: u32,
    /// Target y of the line.
    pub y_target_nm: Nm,
    /// y read back from the stage after settling, when the stage reports one.
    pub y_readback_nm: Option<Nm>,
    /// 1-based attempt that produced this line.
    pub attempt: u32,
    /// Number of points in the heights file.
    pub points: usize,
}

/// The metadata stored next to a line's heights in `NNNN.json`: its identity, its profile's
/// description (pitch, kind, conditions; the heights are in `NNNN.csv`), the instrument's
/// results and the read-out's times. Every member sits at the top level of the JSON object,
/// and a member this struct does not know is an error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineMeta {
    /// Index, target and read-back y, attempt, points.
    #[serde(flatten)]
    pub id: LineIdentity,
    /// Pitch, kind and conditions of the profile.
    #[serde(flatten)]
    pub profile: ProfileHeader,
    /// The instrument's own results for this trace.
    pub results: Vec<InstrumentResult>,
    /// Doubts about the profile read-out that a re-read did not clear.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub readout_warnings: Vec<ReadoutWarning>,
    /// When the trace was started.
    pub started_at: DateTime<Utc>,
    /// When the profile had been read out.
    pub finished_at: DateTime<Utc>,
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
        self.meta.id.y_target_nm.to_mm()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A line file as the store writes it, members in the order of the struct before the
    /// identity and the profile header were factored out.
    const LINE_FILE: &str = r#"{
        "index": 2, "y_target_nm": -19980000, "y_readback_nm": -19979997,
        "pitch_x_mm": 0.0015, "points": 3, "kind": "R",
        "conditions": {"standard": "ISO1997", "profile_kind": "R", "filter": "Gaussian",
            "lambda_c_mm": 2.5, "lambda_s_um": 8.0, "sampling_lengths": 5,
            "evaluation_length_mm": 12.5, "speed_mm_s": null, "raw": "x"},
        "results": [{"name": "Ra", "value": 0.971, "unit": "um", "printed": "0.971"}],
        "started_at": "2026-12-02T03:22:43Z", "finished_at": "2026-12-02T03:22:44Z",
        "attempt": 2
    }"#;

    fn with(member: &str) -> String {
        LINE_FILE.replacen("\"attempt\": 2", &format!("\"attempt\": 2, {member}"), 1)
    }

    #[test]
    fn a_line_file_reads_into_its_identity_and_profile_header() {
        let m: LineMeta = serde_json::from_str(LINE_FILE).unwrap();
        assert_eq!(
            m.id,
            LineIdentity {
                index: 2,
                y_target_nm: Nm(-19_980_000),
                y_readback_nm: Some(Nm(-19_979_997)),
                attempt: 2,
                points: 3,
            }
        );
        assert_eq!(m.profile.pitch_x_mm, 0.0015);
        assert_eq!(m.profile.kind, crate::profile::ProfileKind::R);
        assert_eq!(m.profile.conditions.lambda_c_mm, Some(2.5));
        assert_eq!(m.profile.conditions.sampling_lengths, Some(5));
        assert_eq!(m.results[0].printed.as_deref(), Some("0.971"));
        assert!(m.readout_warnings.is_empty());
        // Written back, it has the same members with the same values (no `heights_um`).
        let back = serde_json::to_value(&m).unwrap();
        let want: serde_json::Value = serde_json::from_str(LINE_FILE).unwrap();
        assert_eq!(back, want);
    }

    #[test]
    fn a_line_file_with_a_member_it_does_not_know_is_refused() {
        for member in [
            r#""operator": "x""#,
            r#""heights_um": [1.0, 2.0, 3.0]"#,
            r#""csv_sha256": "00""#,
        ] {
            let e = serde_json::from_str::<LineMeta>(&with(member)).unwrap_err();
            assert!(
                e.to_string().contains("unknown field") || e.to_string().contains("invalid type"),
                "{member}: {e}"
            );
        }
        // A missing member is refused too.
        let without = LINE_FILE.replacen("\"points\": 3, ", "", 1);
        let e = serde_json::from_str::<LineMeta>(&without).unwrap_err();
        assert!(e.to_string().contains("points"), "{e}");
    }
}
