//! The scan journal `journal.jsonl`: one JSON object per line, each tagged by `class`.
//!
//! Records: a start record (frozen plan and config, traceability), one record per completed
//! line keyed by its 0-based index, interruption records, quarantine records (a committed
//! line whose file was found changed, moved aside to be traced again) and a final stop
//! record. Appends are fsynced.
//!
//! Each record ends with a `"crc"` member: the CRC-32 (IEEE, 8 hex digits) of the record's
//! JSON object written without that member, so a changed byte anywhere in a record is seen.
//! Journals written before records carried a CRC are read as they are; once a record has a
//! CRC, every later one must have one. Opening recovers from a crash: a torn tail (an
//! unterminated last line, or a last line that is not a valid record or fails its CRC) is
//! truncated and reported; an invalid record before the end is damage, a named error.
//! [`ResumeState`] derives what a restarted scan needs; [`survey`] finds the scan to resume
//! from the journals themselves and names the damaged ones, which are skipped.
//!
//! Layer 3 (session): depends on [`crate::profile`], [`crate::devices`] (which device an
//! interruption concerns), the plan, the line identity it shares with the line files
//! ([`super::line`]), the operator's [`Peer`] and the storage fault hook
//! ([`super::faults`]); file I/O only.

use std::collections::BTreeSet;
use std::fs::{self, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};

use crate::profile::Conditions;

use super::command::{PauseMark, Peer};
use super::faults::{StorageFaults, WriteStep};
use super::line::LineIdentity;
use super::plan::Plan;
use crate::devices::Device;

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
    /// The scan's place among the scans of its output directory, independent of the clock:
    /// one more than the highest of the journals there when it started ([`next_sequence`]),
    /// assigned by [`Journal::create`]; 0 in journals of versions before it.
    #[serde(default)]
    pub sequence: u64,
    /// Start time.
    pub time: DateTime<Utc>,
    /// The plan frozen at start (it wins over a config edited since).
    pub plan: Plan,
    /// The whole configuration as loaded, for traceability; the settings in it that shape
    /// the lines (`[stage]`, the instrument's pitch and detector range) are what a resumed
    /// scan runs with ([`super::frozen`], through the station), the rest is never read back.
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
    /// The job the scan was made for: its recipe frozen (`None` for a scan of the station's
    /// own plan).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub job: Option<JobRecord>,
}

/// The job a scan was made for: a recipe's scan, queued or started with `--recipe`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct JobRecord {
    /// The queue's job number; `None` for a scan started with `--recipe` outside the queue.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u64>,
    /// The recipe's name.
    pub recipe: String,
    /// SHA-256 of the recipe's text, hex.
    pub recipe_sha256: String,
    /// The recipe's text as the job froze it: what the scan follows and is judged by.
    pub recipe_text: String,
}

/// A completed, durably stored line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineRecord {
    /// Index, target and read-back y, attempt and points, as in the line's metadata file.
    #[serde(flatten)]
    pub id: LineIdentity,
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
    /// The device concerned, if any (`"instrument"` or `"stage"` in JSON).
    pub device: Option<Device>,
    /// The line being worked on, if any.
    pub line: Option<u32>,
    /// When.
    pub time: DateTime<Utc>,
    /// Who asked, for an operator's command (pause, resume, abort, continue, start over).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peer: Option<Peer>,
    /// Set on the record of a pause taking effect and on that of the resumption, so that a
    /// scan paused when its process stopped is reopened paused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pause: Option<PauseMark>,
}

/// A committed line whose heights file no longer matches the SHA-256 of its line record:
/// its two files were moved aside (under `quarantine/` in the scan directory) and the line is
/// traced again. Its line record no longer counts; a later line record of the same index does.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QuarantineRecord {
    /// 0-based line index.
    pub index: u32,
    /// SHA-256 the line record holds, hex.
    pub expected_sha256: String,
    /// SHA-256 of the file as found, hex (empty when it could not be read).
    pub found_sha256: String,
    /// Where the heights file was moved, relative to the scan directory.
    pub moved_to: String,
    /// What was wrong, for people.
    pub reason: String,
    /// When.
    pub time: DateTime<Utc>,
}

use super::ending::FailCause;
/// How a scan ended, the stop record's word (defined with the scan's ending).
pub use super::ending::StopStatus;

/// The final record of a scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StopRecord {
    /// Exit status.
    pub status: StopStatus,
    /// Why, for people.
    pub reason: String,
    /// What ended a failed scan (records of earlier versions have none: see
    /// [`StopRecord::fail_cause`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cause: Option<FailCause>,
    /// A bug ended the scan (an internal error: making its outputs, or reopening it,
    /// panicked); written only
    /// when true, so a record without it (every earlier version's) reads as false. Its
    /// `cause` stays one every version reads (`operator`): an earlier version ignores this
    /// member, whereas a `cause` it did not know would make it take the record for a torn
    /// tail, cut it off and resume the scan into the same outputs.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub internal: bool,
    /// When.
    pub time: DateTime<Utc>,
}

impl StopRecord {
    /// What ended the scan, when it failed: the record's cause, or (earlier versions) the
    /// one its reason names.
    pub fn fail_cause(&self) -> Option<FailCause> {
        (self.status == StopStatus::Fail).then(|| {
            self.cause
                .unwrap_or_else(|| FailCause::of_reason(&self.reason))
        })
    }

    /// True when the record is a failure the daemon continues by itself
    /// ([`FailCause::continued_by_the_daemon`]): the scan has not ended for its job.
    pub fn continued_by_the_daemon(&self) -> bool {
        self.fail_cause()
            .is_some_and(FailCause::continued_by_the_daemon)
    }
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
    /// A committed line moved aside to be traced again.
    Quarantine(QuarantineRecord),
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
            Record::Quarantine(_) => "quarantine",
            Record::Stop(_) => "stop",
            Record::Continue(_) => "continue",
        }
    }
}

/// The CRC member every record line ends with: `,"crc":"` + 8 hex digits + `"}`.
const CRC_KEY: &[u8] = b",\"crc\":\"";
/// Length of that member with the closing brace.
const CRC_SUFFIX_LEN: usize = 18;

/// One record as its journal line (without the newline): the record's JSON object with a
/// last member `"crc"`, the CRC-32 of the object as written without that member.
pub fn encode_record(record: &Record) -> serde_json::Result<Vec<u8>> {
    let mut line = serde_json::to_vec(record)?;
    let crc = crc32fast::hash(&line);
    // Every record is a JSON object with at least its class: it ends with `}`.
    line.pop();
    line.extend_from_slice(format!(",\"crc\":\"{crc:08x}\"}}").as_bytes());
    Ok(line)
}

/// Splits a record line into the object without its CRC member and the CRC's hex digits,
/// or returns the line whole when it has no CRC member (a journal of an older version).
fn split_crc(line: &[u8]) -> (std::borrow::Cow<'_, [u8]>, Option<&[u8]>) {
    let n = line.len();
    let key = n
        .checked_sub(CRC_SUFFIX_LEN)
        .and_then(|at| line.get(at..at + CRC_KEY.len()));
    match (key, line.get(n.saturating_sub(10)..n.saturating_sub(2))) {
        (Some(k), Some(hex)) if k == CRC_KEY && line.ends_with(b"\"}") => {
            let mut body = line.get(..n - CRC_SUFFIX_LEN).unwrap_or_default().to_vec();
            body.push(b'}');
            (std::borrow::Cow::Owned(body), Some(hex))
        }
        _ => (std::borrow::Cow::Borrowed(line), None),
    }
}

/// Decodes one record line: the record and whether it carried a CRC, or why it is not a
/// valid record.
fn decode_line(line: &[u8]) -> Result<(Record, bool), String> {
    let (body, hex) = split_crc(line);
    if let Some(hex) = hex {
        let recorded = std::str::from_utf8(hex)
            .ok()
            .filter(|h| h.bytes().all(|b| b.is_ascii_hexdigit()))
            .and_then(|h| u32::from_str_radix(h, 16).ok())
            .ok_or_else(|| {
                format!(
                    "its CRC {:?} is not 8 hex digits",
                    String::from_utf8_lossy(hex)
                )
            })?;
        let actual = crc32fast::hash(&body);
        if actual != recorded {
            return Err(format!(
                "its content has CRC-32 {actual:08x}, the record says {recorded:08x}: a byte of it was changed"
            ));
        }
    }
    serde_json::from_slice::<Record>(&body)
        .map(|r| (r, hex.is_some()))
        .map_err(|e| e.to_string())
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

/// Parses journal bytes: every newline-terminated line must be a record (whose CRC, when it
/// has one, matches; after a record with a CRC every record must have one), except that an
/// invalid *last* line and any unterminated tail count as torn.
pub fn parse_journal(path: &Path, bytes: &[u8]) -> Result<Recovery, JournalError> {
    let mut records = Vec::new();
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut crc_seen = false;
    while pos < bytes.len() {
        let rest = bytes.get(pos..).unwrap_or_default();
        let Some(nl) = rest.iter().position(|&b| b == b'\n') else {
            break; // unterminated tail: torn
        };
        line_no += 1;
        let line = rest.get(..nl).unwrap_or_default();
        let next = pos + nl + 1;
        let decoded = decode_line(line).and_then(|(r, crc)| {
            if crc_seen && !crc {
                Err("it has no CRC although the records before it have one".to_owned())
            } else {
                crc_seen |= crc;
                Ok(r)
            }
        });
        match decoded {
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
                    reason: e,
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
    /// Creates the journal of a new scan in `scan_dir` and writes the start record, numbered
    /// after the scans beside it in the output directory (its `sequence` is assigned here).
    pub fn create(
        scan_dir: &Path,
        mut start: StartRecord,
        faults: Arc<dyn StorageFaults>,
    ) -> Result<Journal, JournalError> {
        if let Some(output_dir) = scan_dir.parent() {
            start.sequence = next_sequence(output_dir);
        }
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

    /// Ends the scan whose journal is at `path` by `stop`, from outside a run: a scan given up
    /// for a new one, or one whose reopening panicked.
    pub fn append_stop(path: &Path, stop: StopRecord) -> Result<(), JournalError> {
        let (mut journal, _) = Journal::open(path, Arc::new(super::faults::NoFaults))?;
        journal.append(&Record::Stop(stop))
    }

    /// The journal's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends one record (one `write` of the line with its newline) and fsyncs. When the
    /// write fails part-way (e.g. the disk filled up), the file is cut back to its previous
    /// length (best effort) so a later append cannot leave a damaged record in the middle.
    pub fn append(&mut self, record: &Record) -> Result<(), JournalError> {
        let mut line = encode_record(record).map_err(|source| JournalError::Serialise {
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
    /// Committed lines moved aside to be traced again, in journal order.
    pub quarantined: Vec<QuarantineRecord>,
    /// The stop record, if the scan has ended.
    pub stop: Option<StopRecord>,
}

/// Whether the last pause mark among `interruptions` is a pause (see
/// [`ResumeState::paused`]).
fn pause_in_force(interruptions: &[InterruptionRecord]) -> bool {
    let mut paused = false;
    for x in interruptions {
        let mark = x.pause.or_else(|| {
            if x.reason.starts_with("paused by the operator after line") {
                Some(PauseMark::Paused)
            } else if x.reason.starts_with("resumed by the operator") {
                Some(PauseMark::Resumed)
            } else {
                None
            }
        });
        match mark {
            Some(PauseMark::Paused) => paused = true,
            Some(PauseMark::Resumed) => paused = false,
            None => {}
        }
    }
    paused
}

impl ResumeState {
    /// Whether the operator's pause was in force when the journal ends: the last pause mark
    /// says so. Journals written before the marks existed are read by their reasons.
    pub fn paused(&self) -> bool {
        pause_in_force(&self.interruptions)
    }

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
            quarantined: Vec::new(),
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
                    if seen.insert(l.id.index) {
                        state.lines.push(l.clone());
                    } else {
                        state.duplicates.push(l.id.index);
                    }
                }
                Record::Interruption(x) => state.interruptions.push(x.clone()),
                Record::Quarantine(q) => {
                    // The line's record no longer counts: the line is traced again.
                    if seen.remove(&q.index) {
                        state.lines.retain(|l| l.id.index != q.index);
                    }
                    state.quarantined.push(q.clone());
                }
                Record::Stop(s) => state.stop = Some(s.clone()),
                Record::Continue(_) => state.stop = None,
            }
        }
        Ok(state)
    }

    /// The set of completed line indices.
    pub fn completed(&self) -> BTreeSet<u32> {
        self.lines.iter().map(|l| l.id.index).collect()
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

/// A scan directory whose journal has no stop record.
#[derive(Debug, Clone, PartialEq)]
pub struct Unfinished {
    /// The scan directory.
    pub dir: PathBuf,
    /// Its scan id, from the start record.
    pub scan_id: String,
    /// Its sequence number, from the start record.
    pub sequence: u64,
    /// Its start time, from the start record.
    pub started: DateTime<Utc>,
}

/// A scan directory whose journal ends with a `fail` stop record.
#[derive(Debug, Clone, PartialEq)]
pub struct Failed {
    /// The scan directory.
    pub dir: PathBuf,
    /// Its sequence number, from the start record.
    pub sequence: u64,
    /// Its start time, from the start record.
    pub started: DateTime<Utc>,
    /// What ended it.
    pub cause: FailCause,
    /// A bug ended it (its stop record's `internal`).
    pub internal: bool,
}

/// A scan whose stop record says it succeeded.
#[derive(Debug, Clone)]
pub struct Succeeded {
    /// The scan directory.
    pub dir: PathBuf,
    /// Its scan id.
    pub scan_id: String,
    /// When it ended, from the stop record.
    pub ended: DateTime<Utc>,
    /// The stop record's reason.
    pub reason: String,
}

/// What the journals under an output directory say.
#[derive(Debug, Default)]
pub struct Survey {
    /// Scans that succeeded, in no particular order.
    pub succeeded: Vec<Succeeded>,
    /// Scans without a stop record, started first first: by the start record's sequence
    /// number (which no clock can reorder), then its time (journals of older versions have
    /// sequence 0), then its scan id. The last is the one to resume.
    pub unfinished: Vec<Unfinished>,
    /// Scans whose stop record says they failed, in the same order.
    pub failed: Vec<Failed>,
    /// Journals that cannot be read or hold a damaged record: those scans are skipped.
    pub damaged: Vec<JournalError>,
    /// The highest sequence number of the readable journals (0 when there are none).
    pub max_sequence: u64,
}

impl Survey {
    /// The scan to resume: the unfinished one started last.
    pub fn to_resume(&self) -> Option<&Unfinished> {
        self.unfinished.last()
    }

    /// One warning per skipped journal, naming it, the damaged record and what to do.
    pub fn warnings(&self) -> Vec<String> {
        self.damaged
            .iter()
            .map(|e| {
                format!("{e}; that scan is skipped (it is not resumed), new scans are not held up")
            })
            .collect()
    }
}

/// Reads every scan journal under `output_dir` (each directory holding a `journal.jsonl`)
/// and sorts them into unfinished scans and damaged journals. Which scan is unfinished, and
/// in which order, comes from the journals' own records, not from directory names (a clock
/// set backwards names a newer scan earlier; a directory may be renamed). Directories whose
/// journal holds not even a complete start record are ignored: no line was committed there.
/// Only an output directory that cannot be listed is an error.
pub fn survey(output_dir: &Path) -> Result<Survey, JournalError> {
    let io = |source| JournalError::Io {
        op: "list",
        path: output_dir.to_path_buf(),
        source,
    };
    let entries = match fs::read_dir(output_dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Survey::default()),
        Err(e) => return Err(io(e)),
    };
    let mut out = Survey::default();
    for entry in entries {
        let entry = entry.map_err(io)?;
        let dir = entry.path();
        // A link in the output directory is no scan of this station: never followed (its
        // scan would be written through it).
        if entry.file_type().is_ok_and(|t| t.is_symlink()) {
            if dir.join(JOURNAL_FILE).is_file() {
                tracing::warn!(
                    "{} is a symbolic link to a scan; it is not resumed nor written to (move the scan's directory here instead)",
                    dir.display()
                );
            }
            continue;
        }
        let jpath = dir.join(JOURNAL_FILE);
        if !jpath.is_file() {
            continue;
        }
        let state = read_journal(&jpath).and_then(|rec| {
            if rec.records.is_empty() {
                // Crashed while writing the start record: no line can have been committed
                // (lines follow the start record), so there is nothing to resume.
                return Ok(None);
            }
            ResumeState::from_records(&jpath, &rec.records).map(Some)
        });
        match state {
            Ok(Some(st)) => {
                out.max_sequence = out.max_sequence.max(st.start.sequence);
                let failed = st
                    .stop
                    .as_ref()
                    .and_then(|s| Some((s.fail_cause()?, s.internal)));
                if let Some((cause, internal)) = failed {
                    out.failed.push(Failed {
                        dir: dir.clone(),
                        sequence: st.start.sequence,
                        started: st.start.time,
                        cause,
                        internal,
                    });
                }
                if let Some(stop) = st.stop.as_ref().filter(|s| s.status == StopStatus::Success) {
                    out.succeeded.push(Succeeded {
                        dir: dir.clone(),
                        scan_id: st.start.scan_id.clone(),
                        ended: stop.time,
                        reason: stop.reason.clone(),
                    });
                }
                if !st.is_stopped() {
                    out.unfinished.push(Unfinished {
                        dir,
                        scan_id: st.start.scan_id,
                        sequence: st.start.sequence,
                        started: st.start.time,
                    });
                }
            }
            Ok(None) => {}
            Err(e) => out.damaged.push(e),
        }
    }
    out.unfinished.sort_by(|a, b| {
        (a.sequence, a.started, &a.scan_id, &a.dir)
            .cmp(&(b.sequence, b.started, &b.scan_id, &b.dir))
    });
    out.failed
        .sort_by(|a, b| (a.sequence, a.started, &a.dir).cmp(&(b.sequence, b.started, &b.dir)));
    Ok(out)
}

/// The sequence number of a new scan in `output_dir`: one more than the highest of the
/// journals there (1 for the first; an unlistable directory counts as empty, the scan's own
/// creation then names the problem).
pub fn next_sequence(output_dir: &Path) -> u64 {
    survey(output_dir)
        .map_or(0, |s| s.max_sequence)
        .saturating_add(1)
}

/// Scan directories under `output_dir` whose journal has no stop record, oldest start first
/// (see [`survey`]); damaged journals are skipped with a warning in the log.
pub fn find_unfinished(output_dir: &Path) -> Result<Vec<PathBuf>, JournalError> {
    let s = survey(output_dir)?;
    for w in s.warnings() {
        tracing::warn!("{w}");
    }
    Ok(s.unfinished.into_iter().map(|u| u.dir).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_pause_mark_says_whether_the_scan_was_paused() {
        let rec = |reason: &str, pause: Option<PauseMark>| InterruptionRecord {
            reason: reason.into(),
            device: None,
            line: Some(2),
            time: "2026-12-02T03:22:45Z".parse().unwrap(),
            peer: None,
            pause,
        };
        let paused = rec(
            "paused by the operator after line 3",
            Some(PauseMark::Paused),
        );
        let resumed = rec("resumed by the operator (uid 0)", Some(PauseMark::Resumed));
        let shutdown = rec("shutdown: current line abandoned", None);
        assert!(!pause_in_force(&[]));
        assert!(pause_in_force(&[paused.clone(), shutdown.clone()]));
        assert!(!pause_in_force(&[paused.clone(), resumed.clone()]));
        assert!(pause_in_force(&[paused.clone(), resumed, paused.clone()]));
        // Journals written before the marks: read by the reasons.
        let old_paused = rec("paused by the operator after line 3", None);
        let old_resumed = rec("resumed by the operator (uid 0 gid 0 pid 7)", None);
        assert!(pause_in_force(&[old_paused.clone(), shutdown]));
        assert!(!pause_in_force(&[old_paused, old_resumed]));
        // The mark is written only where it is set, and read back.
        let line =
            String::from_utf8(encode_record(&Record::Interruption(paused)).unwrap()).unwrap();
        assert!(line.contains(r#""pause":"paused""#), "{line}");
        let (back, _) = decode_line(line.as_bytes()).unwrap();
        assert!(matches!(back, Record::Interruption(x) if x.pause == Some(PauseMark::Paused)));
        let line = String::from_utf8(encode_record(&Record::Interruption(rec("x", None))).unwrap())
            .unwrap();
        assert!(!line.contains("pause"), "{line}");
    }

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

    #[test]
    fn a_line_record_is_written_as_before_its_identity_was_shared() {
        let r = Record::Line(LineRecord {
            id: LineIdentity {
                index: 3,
                y_target_nm: crate::units::Nm(-19_970_000),
                y_readback_nm: None,
                attempt: 2,
                points: 160,
            },
            csv_sha256: "ab".repeat(32),
            time: "2026-12-02T03:22:45.411448018Z".parse().unwrap(),
        });
        let body = serde_json::to_string(&r).unwrap();
        let want = format!(
            r#"{{"class":"line","index":3,"y_target_nm":-19970000,"y_readback_nm":null,"attempt":2,"points":160,"csv_sha256":"{}","time":"2026-12-02T03:22:45.411448018Z"}}"#,
            "ab".repeat(32)
        );
        assert_eq!(body, want);
        let (back, crc) = decode_line(&encode_record(&r).unwrap()).unwrap();
        assert!(crc);
        assert_eq!(back, r);
    }

    /// A bug that ended the scan is said by a member of its own, `internal`, written only
    /// when true, beside a `cause` every version reads: an unknown `cause` would make a
    /// version that does not know it take the record for a torn tail (as this version does
    /// with one it does not know, below), cut it off and resume the scan into the same bug.
    #[test]
    fn a_stop_record_says_a_bug_ended_the_scan_in_a_member_earlier_versions_skip() {
        let stop = |internal: bool| {
            Record::Stop(StopRecord {
                status: StopStatus::Fail,
                reason: "internal error: writing the outputs panicked (x)".into(),
                cause: Some(FailCause::Operator),
                internal,
                time: "2026-12-07T18:00:00Z".parse().unwrap(),
            })
        };
        let line = |internal: &str| {
            format!(
                r#"{{"class":"stop","status":"fail","reason":"internal error: writing the outputs panicked (x)","cause":"operator",{internal}"time":"2026-12-07T18:00:00Z"}}"#
            )
        };
        assert_eq!(
            serde_json::to_string(&stop(true)).unwrap(),
            line(r#""internal":true,"#)
        );
        assert_eq!(serde_json::to_string(&stop(false)).unwrap(), line(""));
        let (back, crc) = decode_line(&encode_record(&stop(true)).unwrap()).unwrap();
        assert!(crc);
        assert_eq!(back, stop(true));
        // A record of an earlier version, without the member: no bug.
        let (back, _) = decode_line(line("").as_bytes()).unwrap();
        assert_eq!(back, stop(false));
        let unknown = line("").replace(r#""cause":"operator""#, r#""cause":"internal""#);
        let e = decode_line(unknown.as_bytes()).unwrap_err();
        assert!(e.contains("unknown variant `internal`"), "{e}");
    }

    #[test]
    fn an_interruption_names_its_device_as_older_journals_spell_it() {
        let line = |device: &str| {
            format!(
                r#"{{"class":"interruption","reason":"r","device":{device},"line":2,"time":"2026-12-02T03:22:43Z"}}"#
            )
        };
        for (json, want) in [
            (r#""instrument""#, Some(Device::Instrument)),
            (r#""stage""#, Some(Device::Stage)),
            ("null", None),
        ] {
            let (r, _) = decode_line(line(json).as_bytes()).unwrap();
            let Record::Interruption(i) = &r else {
                panic!("{r:?}")
            };
            assert_eq!(i.device, want, "{json}");
            assert_eq!(serde_json::to_string(&r).unwrap(), line(json), "{json}");
        }
        let e = decode_line(line(r#""disk""#).as_bytes()).unwrap_err();
        assert!(e.contains("unknown variant `disk`"), "{e}");
    }
}
