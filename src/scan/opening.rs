//! Opening a scan's directory: creating a new one (pre-flight disk check, directory, start
//! record) once its devices answered, or reopening an unfinished or failed one and loading
//! its committed lines into memory and the fitter.
//!
//! A reopening refused is classed by what can clear it ([`Refusal`]): the file system
//! refusing (an operating-system error) can clear by itself and leaves the scan as it is;
//! the scan's own files unreadable or inconsistent are the operator's, and the refusal is
//! the scan's ending (the runner records it).
//!
//! Layer 3 (session): depends on [`super::store`], [`super::journal`], [`super::disk`],
//! [`super::ledger`], the session's settings, [`super::reasons`]' words for a refusal and
//! [`crate::devices`]' reports.

use super::command::Peer;
use super::disk::preflight_disk;
use super::ending::FailKind;
use super::journal::{Journal, Record, ResumeState, StartRecord};
use super::ledger::Ledger;
use super::machine::Resumed;
use super::reasons;
use super::scan_id::ScanId;
use super::settings::RunSettings;
use super::store::ScanStore;
use super::store_error::{os_error, StoreError};
use crate::devices::ProbeReport;
use crate::profile::Conditions;
use chrono::Utc;
use std::path::Path;

/// Points a line is assumed to have when nothing better is known: the SJ-210's longest
/// profile (16 mm at 0.5 µm).
pub const LONGEST_PROFILE_POINTS: u64 = 32_001;

/// Who asked for a new scan and what it is of.
#[derive(Debug, Clone)]
pub(super) struct NewScan {
    pub specimen: String,
    pub operator: String,
    pub notes: String,
    pub peer: Option<Peer>,
    pub job: Option<Box<super::outcome::NewJob>>,
}

/// Points per line the instrument will deliver under `conditions` at `pitch_um`.
pub fn expected_points(pitch_um: Option<f64>, conditions: &Conditions) -> u64 {
    match (pitch_um, conditions.evaluation_length_mm) {
        (Some(p), Some(l)) if p > 0.0 => (l * 1000.0 / p).ceil() as u64 + 1,
        _ => LONGEST_PROFILE_POINTS,
    }
}

/// A rough duration of one line: traverse at the measuring speed, return at twice that,
/// and the profile read-out at the link's baud rate (about 12 characters per point).
pub fn estimate_line_seconds(conditions: &Conditions, points: u64, baud: u32) -> f64 {
    let length_mm = conditions.evaluation_length_mm.unwrap_or(4.0);
    let speed = conditions.speed_mm_s.filter(|s| *s > 0.0).unwrap_or(0.5);
    // Pre-travel and post-travel of half a cut-off each side, as the SJ series does.
    let traverse = length_mm + conditions.lambda_c_mm.unwrap_or(0.8);
    let trace = traverse / speed * 1.5;
    let readout = points as f64 * 12.0 * 10.0 / f64::from(baud.max(1));
    trace + readout
}

/// Creates a new scan once both devices answered: pre-flight (the disk must hold the
/// whole scan), directory, start record.
pub(super) fn create(
    settings: &RunSettings,
    who: NewScan,
    report: &ProbeReport,
    points: u64,
) -> Result<Ledger, StoreError> {
    let plan = settings.plan.clone();
    let output_dir = &settings.output_dir;
    std::fs::create_dir_all(output_dir).map_err(|e| StoreError::Io {
        op: "create output directory",
        path: output_dir.clone(),
        source: e,
    })?;
    let needed = preflight_disk(output_dir, plan.lines, points)?;
    let line_s = estimate_line_seconds(&report.conditions, points, settings.instrument_baud);
    tracing::info!(
        "pre-flight: {} lines of about {points} points, about {:.0} s per line ({:.1} h), about {:.1} MB on disk",
        plan.lines,
        line_s,
        line_s * f64::from(plan.lines) / 3600.0,
        needed as f64 / 1e6
    );
    let now = Utc::now();
    let faults = settings.hooks.clone();
    let (store, id) =
        ScanStore::create(output_dir, &ScanId::new(now, &who.specimen), faults.clone())?;
    let start = StartRecord {
        scan_id: id.0.clone(),
        // Numbered by `Journal::create`.
        sequence: 0,
        time: now,
        plan,
        config: settings.config.clone(),
        config_hash: settings.config_hash.clone(),
        specimen: who.specimen,
        operator: who.operator,
        notes: who.notes,
        software_version: crate::build_info::software(),
        instrument_model: report.identity.model.clone(),
        firmware: report.identity.firmware.clone(),
        drive_unit: report.identity.drive_unit.clone(),
        conditions: report.conditions.clone(),
        peer: who.peer,
        job: who.job.map(|j| j.record),
    };
    let journal =
        Journal::create(store.root(), start.clone(), faults).map_err(StoreError::Journal)?;
    tracing::info!(scan_id = %id, "scan started in {}", store.root().display());
    Ok(Ledger::new(
        store,
        journal,
        start,
        settings.hooks.clone(),
        settings.metrics_file.clone(),
    ))
}

/// A reopened scan: its ledger with the committed lines loaded and fitted, what the machine
/// needs to know of it, and the note for the journal.
pub(super) struct Reopened {
    pub ledger: Ledger,
    pub resumed: Resumed,
    pub note: String,
    /// The stop record's reason when the scan had failed.
    pub failed: Option<String>,
}

/// Why a scan could not be reopened, as far as what becomes of it depends on it: the
/// project's rule is that what can clear by itself never ends a scan, and what the operator
/// must fix is not tried again by itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Refusal {
    /// There is nothing to reopen: the scan has ended already, or its directory is not one
    /// (a symbolic link). The scan is left as it is.
    Left,
    /// The work was cancelled as the process shuts down: the scan is left as it is and
    /// resumes at the next start, as after a shutdown while it ran.
    Shutdown,
    /// The file system refused reading or writing the scan's files (an operating-system
    /// error: a remount, a permission, a disk that went away): it can clear by itself, so
    /// the scan is left as it is and tried again.
    FileSystem,
    /// The scan's own files cannot be read back as a scan (its journal's records, a line
    /// file, a line the fitter refuses): the operator's to repair or give up; the refusal is
    /// the scan's ending.
    Scan,
    /// A bug: reopening panicked; the refusal is the scan's ending by a bug.
    Bug,
}

impl Refusal {
    /// The exit class.
    pub fn kind(self) -> FailKind {
        match self {
            Refusal::Left | Refusal::Shutdown | Refusal::Scan => FailKind::Scan,
            Refusal::FileSystem => FailKind::Io,
            Refusal::Bug => FailKind::Internal,
        }
    }

    /// Whether the refusal is recorded as the scan's ending (a `fail` stop record), so that
    /// neither the daemon at its start nor its queue reopens the scan again by itself.
    pub fn ends_the_scan(self) -> bool {
        matches!(self, Refusal::Scan | Refusal::Bug)
    }
}

/// The refusal of a reopening by `e` while doing `what`: the file system's when an
/// operating-system error is behind it, else the scan's own; its reason says what to do.
pub(super) fn refusal(what: &str, e: &(dyn std::error::Error + 'static)) -> (String, Refusal) {
    match os_error(e) {
        Some(errno) => (
            reasons::reopening_refused(what, Some(errno), &e.to_string()),
            Refusal::FileSystem,
        ),
        None => (
            reasons::reopening_impossible(what, &e.to_string()),
            Refusal::Scan,
        ),
    }
}

/// Reopens the scan in `dir`: journal (a torn tail truncated), committed lines checked
/// against their hashes, the fitter rebuilt. A scan with a stop record is refused unless
/// `continue_failed` and it failed.
pub(super) fn reopen(
    settings: &RunSettings,
    dir: &Path,
    continue_failed: bool,
) -> Result<Reopened, (String, Refusal)> {
    let faults = settings.hooks.clone();
    // A directory that is not one (a symbolic link) is no scan to record an ending in.
    let store = ScanStore::open(dir, faults.clone()).map_err(|e| {
        match refusal("opening its directory", &e) {
            (why, Refusal::Scan) => (why, Refusal::Left),
            other => other,
        }
    })?;
    let (journal, recovery) = Journal::open(&store.journal_path(), faults)
        .map_err(|e| refusal("reading its journal", &e))?;
    let state = ResumeState::from_records(journal.path(), &recovery.records)
        .map_err(|e| refusal("reading its journal", &e))?;
    let failed = match &state.stop {
        None => None,
        Some(s) if continue_failed && s.status == super::journal::StopStatus::Fail => {
            Some(s.reason.clone())
        }
        Some(s) => {
            return Err((
                format!(
                    "scan {} has ended ({}: {}); it cannot be continued",
                    state.start.scan_id,
                    s.status.as_str(),
                    s.reason
                ),
                Refusal::Left,
            ))
        }
    };
    let plan = state.start.plan.clone();
    if state.start.config_hash != settings.config_hash {
        tracing::warn!(
            "the configuration changed since scan {} started; the plan frozen in its journal is followed",
            state.start.scan_id
        );
    }
    let mut ledger = Ledger::new(
        store,
        journal,
        state.start.clone(),
        settings.hooks.clone(),
        settings.metrics_file.clone(),
    );
    // A committed line that fails its check is moved aside (both hashes journaled) and
    // traced again, instead of refusing to resume.
    let checked = ledger
        .store
        .load_committed_repairing(&state.lines, Utc::now())
        .map_err(|e| refusal("reading its lines back", &e))?;
    for q in &checked.quarantined {
        tracing::warn!(scan_id = %ledger.id, line = q.index + 1, "{} (now {})", q.reason, q.moved_to);
        ledger
            .journal
            .append(&Record::Quarantine(q.clone()))
            .map_err(|e| refusal("recording a line moved aside", &e))?;
    }
    let mut lines = checked.lines;
    lines.sort_by_key(|l| l.meta.id.index);
    let columns = lines.first().map(|l| l.profile.len());
    let pitch_x_mm = lines.first().map(|l| l.profile.pitch_x_mm);
    // The fitter takes lines in order: those after the first gap wait in the ledger.
    let committed = lines
        .iter()
        .zip(0u32..)
        .take_while(|(l, k)| l.meta.id.index == *k)
        .count();
    ledger.ahead = lines
        .split_off(committed)
        .into_iter()
        .map(|l| (l.meta.id.index, l))
        .collect();
    let ahead = ledger.ahead.keys().copied().collect();
    let on_disk = committed + ledger.ahead.len();
    let committed = committed as u32;
    for l in lines {
        let index = l.meta.id.index;
        ledger
            .push(l)
            .map_err(|e| refusal(&format!("rebuilding the fit from line {}", index + 1), &e))?;
    }
    let quarantined: Vec<String> = checked
        .quarantined
        .iter()
        .map(|q| (q.index + 1).to_string())
        .collect();
    let note = format!(
        "{} with {on_disk} of {} lines on disk{}{}",
        if failed.is_some() {
            "continued after a failure"
        } else {
            "resumed after a restart"
        },
        plan.lines,
        if quarantined.is_empty() {
            String::new()
        } else {
            format!(
                "; line(s) {} failed their check, were moved to {}/ and are traced again",
                quarantined.join(", "),
                super::store::QUARANTINE_DIR
            )
        },
        if recovery.torn_bytes > 0 {
            format!(
                "; a torn journal tail of {} bytes was truncated",
                recovery.torn_bytes
            )
        } else {
            String::new()
        }
    );
    tracing::info!(scan_id = %ledger.id, "{note}");
    let resumed = Resumed {
        scan_id: ledger.id.clone(),
        dir: ledger.dir.display().to_string(),
        committed,
        ahead,
        columns,
        pitch_x_mm,
        conditions: state.start.conditions.clone(),
        points_per_line: columns.map_or(LONGEST_PROFILE_POINTS, |c| c as u64),
        paused: state.paused(),
    };
    Ok(Reopened {
        ledger,
        resumed,
        note,
        failed,
    })
}
