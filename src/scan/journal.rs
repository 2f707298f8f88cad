//! The scan journal `journal.jsonl`: one JSON object per line, each tagged by `class`.
//!
//! Records: a start record (frozen plan and config, traceability), one record per completed
//! line keyed by its 0-based index, interruption records and a final stop record. Appends are
//! fsynced. Opening recovers from a crash: a torn tail (an unterminated last line, or an
//! invalid last line) is truncated and reported; an invalid record before the end is a named
//! error. [`ResumeState`] derives what a restarted scan needs.
//!
//! Layer 3 (session): depends on [`crate::profile`], [`crate::units`], the plan, the operator's
//! [`Peer`] and the storage fault hook ([`super::faults`]); file I/O only.

use std::collections::BTreeSet;
use std::fs::{self, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};

use crate::profile::Conditions;
use crate::units::Nm;

use super::command::Peer;
use super::faults::{StorageFaults, WriteStep};
use super::plan::Plan;

/// The journal's file name inside a scan directory.
pub const JOURNAL_FILE: &str = "journal.jsonl";

/// Errors of the journal.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// A file system operation failed.
    #[error("{op} {path}: {source}")]
    Io {
        /// What was being done.
        op: &'static str,
        /// The journal.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: io::Error,
    },
    /// A record before the last one is not a valid record: the journal was damaged.
    #[error("{path}: line {line} (byte {offset}) is not a valid journal record ({reason}): {content:?}; the journal is damaged, inspect it by hand")]
    BadRecord {
        /// The journal.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Byte offset of the line.
        offset: u64,
        /// The line (at most 200 characters of it).
        content: String,
        /// The parser's message.
        reason: String,
    },
    /// The first record is not a start record.
    #[error("{path}: the first record is {found:?}, not a start record")]
    NoStart {
        /// The journal.
        path: PathBuf,
        /// The class of the first record, or "nothing" for an empty journal.
        found: String,
    },
    /// A second start record.
    #[error("{path}: line {line} is a second start record")]
    SecondStart {
        /// The journal.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
    },
    /// A record could not be serialised.
    #[error("{path}: cannot serialise a record: {source}")]
    Serialise {
        /// The journal.
        path: PathBuf,
        /// The serialiser's error.
        #[source]
        source: serde_json::Error,
    },
}

/// Traceability and frozen inputs of a scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartRecord {
    /// The scan id.
    pub scan_id: String,
    /// Start time.
    pub time: DateTime<Utc>,
    /// The plan frozen at start (it wins over a config edited since).
    pub plan: Plan,
    /// The whole configuration as loaded, for traceability: its types belong to the process
    /// edge above the session, which never reads this copy back.
    pub config: serde_json::Value,
    /// SHA-256 of the configuration file, hex.
    pub config_hash: String,
    /// Specimen id.
    pub specimen: String,
    /// Operator.
    pub operator: String,
    /// Free-text notes.
    pub notes: String,
    /// surfscan version.
    pub software_version: String,
    /// Instrument model as identified.
    pub instrument_model: String,
    /// Instrument firmware.
    pub firmware: String,
    /// Drive unit.
    pub drive_unit: String,
    /// Measurement conditions read at start.
    pub conditions: Conditions,
    /// Who started the scan (the control socket's peer, or this process).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peer: Option<Peer>,
}

/// A completed, durably stored line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineRecord {
    /// 0-based line index.
    pub index: u32,
    /// Target y.
    pub y_target_nm: Nm,
    /// y read back after settling.
    pub y_readback_nm: Option<Nm>,
    /// 1-based attempt that produced the line.
    pub attempt: u32,
    /// Number of points.
    pub points: usize,
    /// SHA-256 of the heights file, hex.
    pub csv_sha256: String,
    /// When the line was read out.
    pub time: DateTime<Utc>,
}

/// A fault, a shutdown or a pause that interrupted the scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InterruptionRecord {
    /// What happened, for people.
    pub reason: String,
    /// The device concerned ("instrument", "stage"), if any.
    pub device: Option<String>,
    /// The line being worked on, if any.
    pub line: Option<u32>,
    /// When.
    pub time: DateTime<Utc>,
    /// Who asked, for an operator's command (pause, resume, abort, continue, start over).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peer: Option<Peer>,
}

/// How a scan ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StopStatus {
    /// All lines traced, fit and IGES written.
    Success,
    /// Aborted by the operator.
    Abort,
    /// Ended by an unrecoverable fault.
    Fail,
}

impl StopStatus {
    /// `success`, `abort` or `fail`, as the journal spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            StopStatus::Success => "success",
            StopStatus::Abort => "abort",
            StopStatus::Fail => "fail",
        }
    }
}

/// The final record of a scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StopRecord {
    /// Exit status.
    pub status: StopStatus,
    /// Why, for people.
    pub reason: String,
    /// When.
    pub time: DateTime<Utc>,
}

/// The operator continued a failed scan after clearing the cause: the stop record before
/// it no longer ends the scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContinueRecord {
    /// The failure the scan is continued after.
    pub after: String,
    /// Who asked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peer: Option<Peer>,
    /// When.
    pub time: DateTime<Utc>,
}

/// One journal record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "class", rename_all = "lowercase")]
pub enum Record {
    /// The start record.
    Start(Box<StartRecord>),
    /// A completed line.
    Line(LineRecord),
    /// An interruption.
    Interruption(InterruptionRecord),
    /// The stop record.
    Stop(StopRecord),
    /// A failed scan continued (`--resume`).
    Continue(ContinueRecord),
}

impl Record {
    fn class(&self) -> &'static str {
        match self {
            Record::Start(_) => "start",
            Record::Line(_) => "line",
            Record::Interruption(_) => "interruption",
            Record::Stop(_) => "stop",
            Record::Continue(_) => "continue",
        }
    }
}

/// What reading a journal found.
#[derive(Debug, Clone, PartialEq)]
pub struct Recovery {
    /// The valid records, in order.
    pub records: Vec<Record>,
    /// Length in bytes of the valid prefix.
    pub valid_len: u64,
    /// Bytes of torn tail after the valid prefix (dropped by [`Journal::open`]).
    pub torn_bytes: u64,
}

/// Parses journal bytes: every newline-terminated line must be a record, except that an
/// invalid *last* line and any unterminated tail count as torn.
pub fn parse_journal(path: &Path, bytes: &[u8]) -> Result<Recovery, JournalError> {
    let mut records = Vec::new();
    let mut pos = 0usize;
    let mut line_no = 0usize;
    while pos < bytes.len() {
        let rest = bytes.get(pos..).unwrap_or_default();
        let Some(nl) = rest.iter().position(|&b| b == b'\n') else {
            break; // unterminated tail: torn
        };
        line_no += 1;
        let line = rest.get(..nl).unwrap_or_default();
        let next = pos + nl + 1;
        match serde_json::from_slice::<Record>(line) {
            Ok(r) => records.push(r),
            Err(e) => {
                if next >= bytes.len() {
                    break; // invalid last line: torn
                }
                let content: String = String::from_utf8_lossy(line).chars().take(200).collect();
                return Err(JournalError::BadRecord {
                    path: path.to_path_buf(),
                    line: line_no,
                    offset: pos as u64,
                    content,
                    reason: e.to_string(),
                });
            }
        }
        pos = next;
    }
    Ok(Recovery {
        records,
        valid_len: pos as u64,
        torn_bytes: (bytes.len() - pos) as u64,
    })
}

/// Reads a journal without modifying it.
pub fn read_journal(path: &Path) -> Result<Recovery, JournalError> {
    let bytes = fs::read(path).map_err(|source| JournalError::Io {
        op: "read",
        path: path.to_path_buf(),
        source,
    })?;
    parse_journal(path, &bytes)
}

/// An open journal, appending with fsync.
pub struct Journal {
    path: PathBuf,
    file: fs::File,
    faults: Arc<dyn StorageFaults>,
    /// Length of the well-formed journal: a failed append is rolled back to it.
    len: u64,
}

impl std::fmt::Debug for Journal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Journal").field("path", &self.path).finish()
    }
}

impl Journal {
    /// Creates the journal of a new scan in `scan_dir` and writes the start record.
    pub fn create(
        scan_dir: &Path,
        start: StartRecord,
        faults: Arc<dyn StorageFaults>,
    ) -> Result<Journal, JournalError> {
        let path = scan_dir.join(JOURNAL_FILE);
        let file = OpenOptions::new()
            .append(true)
            .create_new(true)
            .open(&path)
            .map_err(|source| JournalError::Io {
                op: "create",
                path: path.clone(),
                source,
            })?;
        fs::File::open(scan_dir)
            .and_then(|d| d.sync_all())
            .map_err(|source| JournalError::Io {
                op: "fsync directory",
                path: scan_dir.to_path_buf(),
                source,
            })?;
        let mut j = Journal {
            path,
            file,
            faults,
            len: 0,
        };
        j.append(&Record::Start(Box::new(start)))?;
        Ok(j)
    }

    /// Opens an existing journal for appending after recovery: a torn tail is truncated
    /// (durably) and reported in the returned [`Recovery`].
    pub fn open(
        path: &Path,
        faults: Arc<dyn StorageFaults>,
    ) -> Result<(Journal, Recovery), JournalError> {
        let rec = read_journal(path)?;
        let io = |op| {
            let path = path.to_path_buf();
            move |source| JournalError::Io { op, path, source }
        };
        if rec.torn_bytes > 0 {
            let f = OpenOptions::new()
                .write(true)
                .open(path)
                .map_err(io("open"))?;
            f.set_len(rec.valid_len).map_err(io("truncate"))?;
            f.sync_all().map_err(io("fsync"))?;
        }
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(io("open"))?;
        Ok((
            Journal {
                path: path.to_path_buf(),
                file,
                faults,
                len: rec.valid_len,
            },
            rec,
        ))
    }

    /// The journal's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends one record (one `write` of the line with its newline) and fsyncs. When the
    /// write fails part-way (e.g. the disk filled up), the file is cut back to its previous
    /// length (best effort) so a later append cannot leave a damaged record in the middle.
    pub fn append(&mut self, record: &Record) -> Result<(), JournalError> {
        let mut line = serde_json::to_vec(record).map_err(|source| JournalError::Serialise {
            path: self.path.clone(),
            source,
        })?;
        line.push(b'\n');
        let io = |op| {
            let path = self.path.clone();
            move |source| JournalError::Io { op, path, source }
        };
        self.faults
            .before_write(WriteStep::Journal, &self.path)
            .map_err(io("append"))?;
        if let Err(e) = self.file.write_all(&line) {
            let _ = self.file.set_len(self.len);
            return Err(io("append")(e));
        }
        self.file.sync_data().map_err(io("fsync"))?;
        self.len += line.len() as u64;
        Ok(())
    }
}

/// What a restarted scan needs to know, derived from the journal's records.
#[derive(Debug, Clone, PartialEq)]
pub struct ResumeState {
    /// The start record (frozen plan and config).
    pub start: StartRecord,
    /// Completed lines, first record of each index, in journal order.
    pub lines: Vec<LineRecord>,
    /// Line indices that appeared more than once (the first record was kept).
    pub duplicates: Vec<u32>,
    /// Interruptions recorded so far.
    pub interruptions: Vec<InterruptionRecord>,
    /// The stop record, if the scan has ended.
    pub stop: Option<StopRecord>,
}

impl ResumeState {
    /// Derives the state from a record sequence; `path` names the journal in errors.
    pub fn from_records(path: &Path, records: &[Record]) -> Result<ResumeState, JournalError> {
        let mut it = records.iter();
        let start = match it.next() {
            Some(Record::Start(s)) => (**s).clone(),
            other => {
                return Err(JournalError::NoStart {
                    path: path.to_path_buf(),
                    found: other.map_or("nothing", Record::class).to_string(),
                })
            }
        };
        let mut seen = BTreeSet::new();
        let mut state = ResumeState {
            start,
            lines: Vec::new(),
            duplicates: Vec::new(),
            interruptions: Vec::new(),
            stop: None,
        };
        for (i, r) in it.enumerate() {
            match r {
                Record::Start(_) => {
                    return Err(JournalError::SecondStart {
                        path: path.to_path_buf(),
                        line: i + 2,
                    })
                }
                Record::Line(l) => {
                    if seen.insert(l.index) {
                        state.lines.push(l.clone());
                    } else {
                        state.duplicates.push(l.index);
                    }
                }
                Record::Interruption(x) => state.interruptions.push(x.clone()),
                Record::Stop(s) => state.stop = Some(s.clone()),
                Record::Continue(_) => state.stop = None,
            }
        }
        Ok(state)
    }

    /// The set of completed line indices.
    pub fn completed(&self) -> BTreeSet<u32> {
        self.lines.iter().map(|l| l.index).collect()
    }

    /// The first line index in `0..total` that is not completed, `None` when all are.
    pub fn first_missing(&self, total: u32) -> Option<u32> {
        let done = self.completed();
        (0..total).find(|i| !done.contains(i))
    }

    /// True when the scan has a stop record.
    pub fn is_stopped(&self) -> bool {
        self.stop.is_some()
    }
}

/// Scan directories under `output_dir` whose journal has no stop record, sorted by name
/// (oldest id first). Directories without a journal, or whose journal holds not even a
/// complete start record, are ignored; a damaged journal is an error.
pub fn find_unfinished(output_dir: &Path) -> Result<Vec<PathBuf>, JournalError> {
    let io = |source| JournalError::Io {
        op: "list",
        path: output_dir.to_path_buf(),
        source,
    };
    let entries = match fs::read_dir(output_dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io(e)),
    };
    let mut out = Vec::new();
    for entry in entries {
        let dir = entry.map_err(io)?.path();
        let jpath = dir.join(JOURNAL_FILE);
        if !jpath.is_file() {
            continue;
        }
        let rec = read_journal(&jpath)?;
        if rec.records.is_empty() {
            // Crashed while writing the start record: no line can have been committed
            // (lines follow the start record), so there is nothing to resume.
            continue;
        }
        let state = ResumeState::from_records(&jpath, &rec.records)?;
        if !state.is_stopped() {
            out.push(dir);
        }
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_and_unterminated_journals() {
        let p = Path::new("j");
        let r = parse_journal(p, b"").unwrap();
        assert_eq!((r.records.len(), r.valid_len, r.torn_bytes), (0, 0, 0));
        let r = parse_journal(p, b"{\"class\":\"st").unwrap();
        assert_eq!((r.records.len(), r.valid_len, r.torn_bytes), (0, 0, 12));
        let e = ResumeState::from_records(p, &r.records).unwrap_err();
        assert!(matches!(e, JournalError::NoStart { ref found, .. } if found == "nothing"));
    }

    #[test]
    fn a_complete_record_without_its_newline_counts_as_torn() {
        let rec =
            br#"{"class":"stop","status":"success","reason":"done","time":"2026-01-01T00:00:00Z"}"#;
        let r = parse_journal(Path::new("j"), rec).unwrap();
        assert!(r.records.is_empty());
        assert_eq!(r.torn_bytes, rec.len() as u64);
        let mut with_nl = rec.to_vec();
        with_nl.push(b'\n');
        let r = parse_journal(Path::new("j"), &with_nl).unwrap();
        assert_eq!(r.records.len(), 1);
        assert!(matches!(&r.records[0], Record::Stop(s) if s.status == StopStatus::Success));
    }

    #[test]
    fn find_unfinished_skips_a_journal_torn_inside_its_start_record() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path().join("20260101T000000Z-x");
        fs::create_dir(&d).unwrap();
        fs::write(d.join(JOURNAL_FILE), b"{\"class\":\"start\",\"sc").unwrap();
        assert!(find_unfinished(tmp.path()).unwrap().is_empty());
    }
}
