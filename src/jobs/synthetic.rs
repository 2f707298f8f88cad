//! Synthetic scan directories — a journal and a small report with chosen facts — for the
//! scan index's tests and its 10,000-scan benchmark (`cargo bench --bench list`). Nothing
//! else writes these; a station never does.
//!
//! Layer 4 (process edge, test support): depends on the journal's record types.

use crate::scan::journal::{
    encode_record, JobRecord, LineRecord, Record, StartRecord, StopRecord, StopStatus, JOURNAL_FILE,
};
use crate::scan::line::LineIdentity;
use crate::scan::plan::Plan;
use crate::specification::Verdict;
use crate::units::Nm;
use chrono::{DateTime, Utc};
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// What a synthetic scan says of itself.
#[derive(Debug, Clone)]
pub struct SyntheticScan {
    /// Directory name and scan id.
    pub id: String,
    /// Sequence number.
    pub sequence: u64,
    /// Start time.
    pub started: DateTime<Utc>,
    /// Specimen id.
    pub specimen: String,
    /// Recipe and job number, when it was a job.
    pub recipe: Option<(String, Option<u64>)>,
    /// Lines planned.
    pub lines: u32,
    /// Lines committed.
    pub done: u32,
    /// How it ended (`None`: unfinished).
    pub stop: Option<StopStatus>,
    /// The report's verdict, Ra per line and Sa, and its warnings; no report when `None`.
    pub report: Option<SyntheticReport>,
}

/// The facts of a synthetic report.
#[derive(Debug, Clone)]
pub struct SyntheticReport {
    /// The verdict, when the recipe had a specification.
    pub verdict: Option<Verdict>,
    /// Ra of each line, µm.
    pub ra_um: Vec<f64>,
    /// Sa of the grid, µm.
    pub sa_um: f64,
    /// Number of warnings.
    pub warnings: usize,
}

/// Writes `scan` under `output_dir`; its directory.
pub fn write(output_dir: &Path, scan: &SyntheticScan) -> std::io::Result<PathBuf> {
    let dir = output_dir.join(&scan.id);
    std::fs::create_dir_all(&dir)?;
    let start = StartRecord {
        scan_id: scan.id.clone(),
        sequence: scan.sequence,
        time: scan.started,
        plan: Plan {
            lines: scan.lines,
            y_start_nm: Nm(0),
            y_step_nm: Nm(10_000),
            degree_u: 5,
            degree_v: 5,
            max_line_attempts: 3,
            v_method: Default::default(),
            replace_spikes: None,
            analysis: None,
        },
        config: serde_json::json!({}),
        config_hash: "ab".repeat(32),
        specimen: scan.specimen.clone(),
        operator: "synthetic".into(),
        notes: String::new(),
        software_version: crate::build_info::software(),
        instrument_model: "SJ-210".into(),
        firmware: String::new(),
        drive_unit: String::new(),
        conditions: Default::default(),
        peer: None,
        job: scan.recipe.as_ref().map(|(name, id)| JobRecord {
            id: *id,
            recipe: name.clone(),
            recipe_sha256: "cd".repeat(32),
            recipe_text: String::new(),
        }),
    };
    let mut out = Vec::new();
    let mut put = |r: &Record| -> std::io::Result<()> {
        out.extend(encode_record(r).map_err(std::io::Error::other)?);
        out.push(b'\n');
        Ok(())
    };
    put(&Record::Start(Box::new(start)))?;
    for k in 0..scan.done {
        put(&Record::Line(LineRecord {
            id: LineIdentity {
                index: k,
                y_target_nm: Nm(i64::from(k) * 10_000),
                y_readback_nm: None,
                attempt: 1,
                points: 8000,
            },
            csv_sha256: "ef".repeat(32),
            time: scan.started,
        }))?;
    }
    if let Some(status) = scan.stop {
        put(&Record::Stop(StopRecord {
            status,
            reason: "synthetic".into(),
            cause: None,
            internal: false,
            time: scan.started + chrono::Duration::minutes(30),
        }))?;
    }
    std::fs::File::create(dir.join(JOURNAL_FILE))?.write_all(&out)?;
    if let Some(r) = &scan.report {
        let mut report = serde_json::json!({
            "lines": r.ra_um.iter().enumerate().map(|(i, ra)| serde_json::json!({"index": i, "Ra_um": ra})).collect::<Vec<_>>(),
            "surface_grid": {"Sa_um": r.sa_um},
            "warnings": (0..r.warnings).map(|i| format!("warning {i}")).collect::<Vec<_>>(),
        });
        if let Some(v) = r.verdict {
            report["specification"] =
                serde_json::json!({"verdict": v, "summary": format!("{v} (synthetic)")});
        }
        std::fs::write(dir.join("report.json"), serde_json::to_vec(&report)?)?;
    }
    Ok(dir)
}
