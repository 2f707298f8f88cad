//! The index of the scans on a station, behind `surfscan list`: one SQLite table
//! (`index.sqlite` in the output directory, through `rusqlite` with SQLite bundled, so no
//! system library is needed) holding per scan its state, recipe, specimen, verdict, Ra and Sa
//! means and number of warnings.
//!
//! The journals stay the truth; the index is a cache of what they (and each scan's
//! `report.json`) say. [`ScanIndex::refresh`] compares every scan directory's journal and
//! report (size and modification time) with what the index recorded and re-reads only the
//! scans that changed, so a listing of 10,000 unchanged scans costs a directory walk and two
//! `stat`s per scan; a missing, damaged or older-format index is rebuilt from the journals.
//! The daemon refreshes it after each scan; `surfscan list` refreshes it before answering.
//!
//! Layer 4 (process edge): depends on the scan's journal reader, the verdict type and
//! `rusqlite`; reads the scan directories, writes its own file.

use crate::scan::journal::{read_journal, ResumeState, JOURNAL_FILE};
use crate::specification::Verdict;
use rusqlite::{params, Connection};
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, HashSet};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The index file's name in the output directory.
pub const INDEX_FILE: &str = "index.sqlite";

/// Bumped whenever the table changes: an index of another version is rebuilt.
const SCHEMA_VERSION: i32 = 1;

/// How long a command waits for another process's write to the index.
const BUSY_TIMEOUT: Duration = Duration::from_secs(5);

/// One scan as the index holds it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanEntry {
    /// The scan directory's name (the scan id).
    pub scan_id: String,
    /// The scan's place among the station's scans.
    pub sequence: u64,
    /// When it started, UTC (RFC 3339).
    pub started_at: String,
    /// When it ended, when it has.
    pub finished_at: Option<String>,
    /// `success`, `fail`, `abort`, `abandoned` (the stop record), `paused`, or
    /// `unfinished` (no stop record: running, or interrupted and to be resumed).
    pub state: String,
    /// The recipe it was made with (`None`: the station's own plan).
    pub recipe: Option<String>,
    /// The queue's job number.
    pub job: Option<u64>,
    /// Specimen id.
    pub specimen: String,
    /// Operator.
    pub operator: String,
    /// Lines committed.
    pub lines_done: u32,
    /// Lines planned.
    pub lines_planned: u32,
    /// The verdict against the specification, when the report holds one.
    pub verdict: Option<Verdict>,
    /// The verdict with its reasons.
    pub verdict_summary: Option<String>,
    /// Mean Ra over the lines, µm.
    pub ra_mean_um: Option<f64>,
    /// Sa of the measured grid, µm.
    pub sa_um: Option<f64>,
    /// Warnings in the report.
    pub warnings: Option<u32>,
}

/// What `surfscan list` asks for; every filter given must hold.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Filter {
    /// Specimen id (`*` and `?` match any text / character).
    pub specimen: Option<String>,
    /// Recipe name (with the same wildcards).
    pub recipe: Option<String>,
    /// Started at or after this instant.
    pub since: Option<chrono::DateTime<chrono::Utc>>,
    /// This verdict.
    pub verdict: Option<Verdict>,
}

/// The index cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum IndexError {
    /// SQLite refused.
    #[error("scan index {path}: {source}")]
    Sqlite {
        /// The index file.
        path: PathBuf,
        /// SQLite's error.
        #[source]
        source: rusqlite::Error,
    },
    /// The index is damaged or of another version.
    #[error("scan index {path}: {what}")]
    Unusable {
        /// The index file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The output directory cannot be listed.
    #[error("cannot list the scans in {path}: {source}")]
    List {
        /// The output directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

/// The open index.
pub struct ScanIndex {
    conn: Connection,
    path: PathBuf,
}

/// Size and modification time (ns) of a file, as the index compares them.
type Stamp = (i64, i64);

fn stamp(path: &Path) -> Option<Stamp> {
    let m = std::fs::metadata(path).ok()?;
    Some((m.size() as i64, m.mtime() * 1_000_000_000 + m.mtime_nsec()))
}

/// What refreshing the index did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Refreshed {
    /// Scans read again (new or changed).
    pub read: usize,
    /// Scans whose journal could not be read (left out, named in the log).
    pub unreadable: usize,
    /// Rows dropped because their directory is gone.
    pub removed: usize,
    /// The index was (re)built from nothing.
    pub rebuilt: bool,
}

const CREATE: &str = "CREATE TABLE IF NOT EXISTS scans (
    dir TEXT PRIMARY KEY,
    scan_id TEXT NOT NULL,
    sequence INTEGER NOT NULL,
    started_ms INTEGER NOT NULL,
    started_at TEXT NOT NULL,
    finished_at TEXT,
    state TEXT NOT NULL,
    recipe TEXT,
    job INTEGER,
    specimen TEXT NOT NULL,
    operator TEXT NOT NULL,
    lines_done INTEGER NOT NULL,
    lines_planned INTEGER NOT NULL,
    verdict TEXT,
    verdict_summary TEXT,
    ra_mean_um REAL,
    sa_um REAL,
    warnings INTEGER,
    journal_size INTEGER NOT NULL,
    journal_mtime INTEGER NOT NULL,
    report_size INTEGER,
    report_mtime INTEGER
);
CREATE INDEX IF NOT EXISTS scans_order ON scans (sequence, started_ms);";

impl ScanIndex {
    /// Opens (creating or rebuilding when missing, damaged or of another version) the index
    /// of `output_dir`.
    pub fn open(output_dir: &Path) -> Result<ScanIndex, IndexError> {
        let path = output_dir.join(INDEX_FILE);
        match ScanIndex::try_open(&path) {
            Ok(i) => Ok(i),
            Err(e) => {
                tracing::warn!("{e}; the index is rebuilt from the journals");
                remove_index_files(&path);
                ScanIndex::try_open(&path)
            }
        }
    }

    /// An index in memory, for a listing where the output directory cannot be written.
    pub fn in_memory() -> Result<ScanIndex, IndexError> {
        let path = PathBuf::from(":memory:");
        let conn = Connection::open_in_memory().map_err(|source| IndexError::Sqlite {
            path: path.clone(),
            source,
        })?;
        let i = ScanIndex { conn, path };
        i.create()?;
        Ok(i)
    }

    fn err(&self, source: rusqlite::Error) -> IndexError {
        IndexError::Sqlite {
            path: self.path.clone(),
            source,
        }
    }

    fn try_open(path: &Path) -> Result<ScanIndex, IndexError> {
        let sql = |source| IndexError::Sqlite {
            path: path.to_path_buf(),
            source,
        };
        let conn = Connection::open(path).map_err(sql)?;
        conn.busy_timeout(BUSY_TIMEOUT).map_err(sql)?;
        let version: i32 = conn
            .query_row("PRAGMA user_version", [], |r| r.get(0))
            .map_err(sql)?;
        let i = ScanIndex {
            conn,
            path: path.to_path_buf(),
        };
        let has_table: bool = i
            .conn
            .query_row(
                "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'scans'",
                [],
                |r| r.get::<_, i64>(0),
            )
            .map_err(|e| i.err(e))?
            > 0;
        if has_table && version != SCHEMA_VERSION {
            return Err(IndexError::Unusable {
                path: path.to_path_buf(),
                what: format!(
                    "written by another version (schema {version}, this one reads {SCHEMA_VERSION})"
                ),
            });
        }
        i.create()?;
        Ok(i)
    }

    fn create(&self) -> Result<(), IndexError> {
        self.conn
            .execute_batch(CREATE)
            .and_then(|_| {
                self.conn
                    .pragma_update(None, "user_version", SCHEMA_VERSION)
            })
            .map_err(|e| self.err(e))
    }

    /// Opens the index of `output_dir` and brings it up to date; an index SQLite finds
    /// damaged on the way (a page that does not read back) is removed and rebuilt once.
    pub fn open_refreshed(output_dir: &Path) -> Result<(ScanIndex, Refreshed), IndexError> {
        let mut index = ScanIndex::open(output_dir)?;
        match index.refresh(output_dir) {
            Ok(r) => Ok((index, r)),
            Err(IndexError::Sqlite { source, .. }) if is_damage(&source) => {
                tracing::warn!(
                    "scan index {}: {source}; it is rebuilt from the journals",
                    index.path.display()
                );
                drop(index);
                remove_index_files(&output_dir.join(INDEX_FILE));
                let mut index = ScanIndex::open(output_dir)?;
                let r = index.refresh(output_dir)?;
                Ok((index, r))
            }
            Err(e) => Err(e),
        }
    }

    /// Brings the index up to date with the scan directories under `output_dir`: the scans
    /// whose journal or report changed (size or modification time) are read again, those
    /// gone are dropped, all in one transaction.
    pub fn refresh(&mut self, output_dir: &Path) -> Result<Refreshed, IndexError> {
        let list_err = |source| IndexError::List {
            path: output_dir.to_path_buf(),
            source,
        };
        let known = self.stamps()?;
        let mut out = Refreshed {
            rebuilt: known.is_empty(),
            ..Refreshed::default()
        };
        let mut seen: HashSet<String> = HashSet::with_capacity(known.len());
        let mut changed: Vec<(String, PathBuf, Stamp, Option<Stamp>)> = Vec::new();
        match std::fs::read_dir(output_dir) {
            Ok(entries) => {
                for entry in entries {
                    let entry = entry.map_err(list_err)?;
                    let Ok(name) = entry.file_name().into_string() else {
                        continue;
                    };
                    let dir = entry.path();
                    let Some(js) = stamp(&dir.join(JOURNAL_FILE)) else {
                        continue;
                    };
                    let rs = stamp(&dir.join("report.json"));
                    if known.get(&name) != Some(&(js, rs)) {
                        changed.push((name.clone(), dir, js, rs));
                    }
                    seen.insert(name);
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(list_err(e)),
        }
        let gone: Vec<&String> = known.keys().filter(|k| !seen.contains(*k)).collect();
        if changed.is_empty() && gone.is_empty() {
            return Ok(out);
        }
        let path = self.path.clone();
        let sql = |source| IndexError::Sqlite {
            path: path.clone(),
            source,
        };
        let tx = self.conn.transaction().map_err(sql)?;
        for (name, dir, js, rs) in changed {
            match read_entry(&name, &dir) {
                Ok(e) => {
                    upsert(&tx, &name, &e, js, rs).map_err(sql)?;
                    out.read += 1;
                }
                Err(why) => {
                    tracing::warn!("scan index: {} left out: {why}", dir.display());
                    out.unreadable += 1;
                    tx.execute("DELETE FROM scans WHERE dir = ?1", [&name])
                        .map_err(sql)?;
                }
            }
        }
        for k in &gone {
            tx.execute("DELETE FROM scans WHERE dir = ?1", [k])
                .map_err(sql)?;
        }
        tx.commit().map_err(sql)?;
        out.removed = gone.len();
        Ok(out)
    }

    fn stamps(&self) -> Result<HashMap<String, (Stamp, Option<Stamp>)>, IndexError> {
        let mut st = self
            .conn
            .prepare(
                "SELECT dir, journal_size, journal_mtime, report_size, report_mtime FROM scans",
            )
            .map_err(|e| self.err(e))?;
        let rows = st
            .query_map([], |r| {
                let rs: Option<i64> = r.get(3)?;
                let rm: Option<i64> = r.get(4)?;
                Ok((r.get::<_, String>(0)?, ((r.get(1)?, r.get(2)?), rs.zip(rm))))
            })
            .map_err(|e| self.err(e))?;
        rows.collect::<Result<_, _>>().map_err(|e| self.err(e))
    }

    /// The scans that pass `filter`, oldest first.
    pub fn query(&self, filter: &Filter) -> Result<Vec<ScanEntry>, IndexError> {
        let mut sql = String::from(
            "SELECT scan_id, sequence, started_at, finished_at, state, recipe, job, specimen, operator, lines_done, lines_planned, verdict, verdict_summary, ra_mean_um, sa_um, warnings FROM scans WHERE 1 = 1",
        );
        let mut args: Vec<Box<dyn rusqlite::ToSql>> = Vec::new();
        if let Some(s) = &filter.specimen {
            sql.push_str(" AND specimen GLOB ?");
            args.push(Box::new(s.clone()));
        }
        if let Some(r) = &filter.recipe {
            sql.push_str(" AND recipe GLOB ?");
            args.push(Box::new(r.clone()));
        }
        if let Some(t) = filter.since {
            sql.push_str(" AND started_ms >= ?");
            args.push(Box::new(t.timestamp_millis()));
        }
        if let Some(v) = filter.verdict {
            sql.push_str(" AND verdict = ?");
            args.push(Box::new(v.as_str()));
        }
        sql.push_str(" ORDER BY sequence, started_ms, scan_id");
        let mut st = self.conn.prepare(&sql).map_err(|e| self.err(e))?;
        let rows = st
            .query_map(rusqlite::params_from_iter(args.iter()), |r| {
                let verdict: Option<String> = r.get(11)?;
                Ok(ScanEntry {
                    scan_id: r.get(0)?,
                    sequence: r.get::<_, i64>(1)? as u64,
                    started_at: r.get(2)?,
                    finished_at: r.get(3)?,
                    state: r.get(4)?,
                    recipe: r.get(5)?,
                    job: r.get::<_, Option<i64>>(6)?.map(|j| j as u64),
                    specimen: r.get(7)?,
                    operator: r.get(8)?,
                    lines_done: r.get(9)?,
                    lines_planned: r.get(10)?,
                    verdict: verdict.as_deref().and_then(Verdict::parse),
                    verdict_summary: r.get(12)?,
                    ra_mean_um: r.get(13)?,
                    sa_um: r.get(14)?,
                    warnings: r.get(15)?,
                })
            })
            .map_err(|e| self.err(e))?;
        rows.collect::<Result<_, _>>().map_err(|e| self.err(e))
    }
}

/// Whether SQLite's error says the file is damaged or no database.
fn is_damage(e: &rusqlite::Error) -> bool {
    matches!(
        e.sqlite_error_code(),
        Some(rusqlite::ErrorCode::DatabaseCorrupt | rusqlite::ErrorCode::NotADatabase)
    )
}

/// Removes the index file and SQLite's files beside it (a cache: the journals are the truth).
fn remove_index_files(path: &Path) {
    for suffix in ["", "-journal", "-wal", "-shm"] {
        let mut p = path.as_os_str().to_owned();
        p.push(suffix);
        let _ = std::fs::remove_file(PathBuf::from(p));
    }
}

fn upsert(
    tx: &rusqlite::Transaction<'_>,
    dir: &str,
    e: &(ScanEntry, i64),
    js: Stamp,
    rs: Option<Stamp>,
) -> rusqlite::Result<usize> {
    let (e, started_ms) = e;
    tx.execute(
        "INSERT OR REPLACE INTO scans (dir, scan_id, sequence, started_ms, started_at, finished_at, state, recipe, job, specimen, operator, lines_done, lines_planned, verdict, verdict_summary, ra_mean_um, sa_um, warnings, journal_size, journal_mtime, report_size, report_mtime) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18, ?19, ?20, ?21, ?22)",
        params![
            dir,
            e.scan_id,
            e.sequence as i64,
            started_ms,
            e.started_at,
            e.finished_at,
            e.state,
            e.recipe,
            e.job.map(|j| j as i64),
            e.specimen,
            e.operator,
            e.lines_done,
            e.lines_planned,
            e.verdict.map(Verdict::as_str),
            e.verdict_summary,
            e.ra_mean_um,
            e.sa_um,
            e.warnings,
            js.0,
            js.1,
            rs.map(|s| s.0),
            rs.map(|s| s.1),
        ],
    )
}

/// The parts of `report.json` the index holds; everything else is skipped unparsed.
#[derive(Deserialize)]
struct ReportHead {
    #[serde(default)]
    specification: Option<SpecificationHead>,
    #[serde(default)]
    lines: Vec<LineHead>,
    #[serde(default)]
    surface_grid: Option<GridHead>,
    #[serde(default)]
    warnings: Vec<serde::de::IgnoredAny>,
}

#[derive(Deserialize)]
struct SpecificationHead {
    verdict: Verdict,
    #[serde(default)]
    summary: Option<String>,
}

#[derive(Deserialize)]
struct LineHead {
    #[serde(rename = "Ra_um")]
    ra_um: Option<f64>,
}

#[derive(Deserialize)]
struct GridHead {
    #[serde(rename = "Sa_um")]
    sa_um: Option<f64>,
}

/// The scans in `out` passing `filter`, with notes for people: from the index there,
/// refreshed first. When the index cannot be written (a reader without write access), the
/// listing is what it holds, with a note; when it cannot even be opened, one is built in
/// memory from the journals. Only an output directory that cannot be listed is an error.
pub fn listing(out: &Path, filter: &Filter) -> Result<(Vec<ScanEntry>, Vec<String>), IndexError> {
    let mut notes = Vec::new();
    let index = match ScanIndex::open_refreshed(out) {
        Ok((index, _)) => index,
        Err(e @ IndexError::List { .. }) => return Err(e),
        Err(e) => match ScanIndex::open(out) {
            // The index is there but cannot be written (a reader without write access): what
            // it holds, said to be possibly behind.
            Ok(index) => {
                notes.push(format!(
                    "{e}: the index was not brought up to date; the daemon updates it after each scan"
                ));
                index
            }
            Err(_) => {
                notes.push(format!("{e}; listing from the journals directly (slower)"));
                let mut index = ScanIndex::in_memory()?;
                index.refresh(out)?;
                index
            }
        },
    };
    Ok((index.query(filter)?, notes))
}

/// Reads one scan directory: its journal (the truth for what the scan is and how far it
/// got) and, when present, its report (verdict, means, warnings).
pub fn read_entry(name: &str, dir: &Path) -> Result<(ScanEntry, i64), String> {
    let jpath = dir.join(JOURNAL_FILE);
    let rec = read_journal(&jpath).map_err(|e| e.to_string())?;
    let st = ResumeState::from_records(&jpath, &rec.records).map_err(|e| e.to_string())?;
    let state = match &st.stop {
        Some(s) => s.status.as_str().to_owned(),
        None if st.paused() => "paused".to_owned(),
        None => "unfinished".to_owned(),
    };
    let rfc =
        |t: chrono::DateTime<chrono::Utc>| t.to_rfc3339_opts(chrono::SecondsFormat::Secs, true);
    let mut e = ScanEntry {
        scan_id: name.to_owned(),
        sequence: st.start.sequence,
        started_at: rfc(st.start.time),
        finished_at: st.stop.as_ref().map(|s| rfc(s.time)),
        state,
        recipe: st.start.job.as_ref().map(|j| j.recipe.clone()),
        job: st.start.job.as_ref().and_then(|j| j.id),
        specimen: st.start.specimen.clone(),
        operator: st.start.operator.clone(),
        lines_done: st.lines.len() as u32,
        lines_planned: st.start.plan.lines,
        verdict: None,
        verdict_summary: None,
        ra_mean_um: None,
        sa_um: None,
        warnings: None,
    };
    if let Ok(bytes) = std::fs::read(dir.join("report.json")) {
        match serde_json::from_slice::<ReportHead>(&bytes) {
            Ok(r) => {
                let ra: Vec<f64> = r.lines.iter().filter_map(|l| l.ra_um).collect();
                e.ra_mean_um = (!ra.is_empty()).then(|| ra.iter().sum::<f64>() / ra.len() as f64);
                e.sa_um = r.surface_grid.and_then(|g| g.sa_um);
                e.warnings = Some(r.warnings.len() as u32);
                if let Some(s) = r.specification {
                    e.verdict = Some(s.verdict);
                    e.verdict_summary = s.summary;
                }
            }
            Err(err) => tracing::warn!(
                "scan index: {}: report.json not read ({err}); its verdict and means are left out",
                dir.display()
            ),
        }
    }
    Ok((e, st.start.time.timestamp_millis()))
}

#[cfg(test)]
mod tests;
