//! A scan directory: `lines/NNNN.csv` + `lines/NNNN.json` per line, `journal.jsonl`, and the
//! final artefacts.
//!
//! Every file is written to a temporary name, fsynced, renamed into place and the directory
//! fsynced ([`crate::atomic`]), so a line file is either absent or complete after a crash.
//! [`ScanStore::commit_line`] performs the full per-line durability order (line files, then
//! the journal record) — only after it returns may the stage move. The [`StorageFaults`] hook
//! injected into the store lets tests fail a chosen write (e.g. with `ENOSPC`) to show that a
//! scan fails cleanly.
//!
//! Layer 3 (session): depends on [`super::line`], [`super::line_csv`], [`super::journal`],
//! [`super::faults`] and [`super::store_error`]; file I/O only, no devices.

use std::collections::BTreeSet;
use std::fs::{self, File};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use chrono::{DateTime, Utc};
use sha2::{Digest, Sha256};

use crate::profile::Profile;

use super::faults::{write_file_durably, StorageFaults, WriteStep};
use super::journal::{Journal, LineRecord, QuarantineRecord, Record, JOURNAL_FILE};
use super::line::{LineMeta, LoadedLines, StoredLine};
use super::line_csv::{parse_csv, render_csv};
use super::scan_id::ScanId;
use super::store_error::{io_err, StoreError};

/// fsyncs a directory so that renames and creations inside it are durable.
pub fn sync_dir(dir: &Path) -> Result<(), StoreError> {
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(io_err("fsync directory", dir))
}

/// Name of the heights file of line `index` (`0007.csv`).
pub fn csv_name(index: u32) -> String {
    format!("{index:04}.csv")
}

/// Name of the metadata file of line `index` (`0007.json`).
pub fn meta_name(index: u32) -> String {
    format!("{index:04}.json")
}

/// A scan directory: `lines/`, `journal.jsonl` and the final artefacts.
#[derive(Clone)]
pub struct ScanStore {
    root: PathBuf,
    faults: Arc<dyn StorageFaults>,
}

impl std::fmt::Debug for ScanStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScanStore")
            .field("root", &self.root)
            .finish()
    }
}

impl ScanStore {
    /// Creates the scan directory `<output_dir>/<id>` exclusively (nothing, not even a link
    /// to nothing, may be there: then `<id>-2`, `<id>-3`, … is taken) with its `lines/` (the
    /// output directory too), fsyncs the parents, and returns the store and the id it got.
    pub fn create(
        output_dir: &Path,
        id: &ScanId,
        faults: Arc<dyn StorageFaults>,
    ) -> Result<(ScanStore, ScanId), StoreError> {
        fs::create_dir_all(output_dir).map_err(io_err("create directory", output_dir))?;
        let mut taken = id.clone();
        let mut n = 1u32;
        let root = loop {
            let root = output_dir.join(&taken.0);
            match fs::create_dir(&root) {
                Ok(()) => break root,
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && n < 10_000 => {
                    n += 1;
                    taken = ScanId(format!("{}-{n}", id.0));
                }
                Err(e) => return Err(io_err("create directory", &root)(e)),
            }
        };
        let lines = root.join("lines");
        fs::create_dir(&lines).map_err(io_err("create directory", &lines))?;
        sync_dir(&root)?;
        sync_dir(output_dir)?;
        Ok((ScanStore { root, faults }, taken))
    }

    /// Opens an existing scan directory (which must hold `lines/`); the directory and its
    /// `lines/` must be directories themselves, never symbolic links.
    pub fn open(root: &Path, faults: Arc<dyn StorageFaults>) -> Result<ScanStore, StoreError> {
        let lines = root.join("lines");
        for dir in [root, lines.as_path()] {
            let meta = fs::symlink_metadata(dir).map_err(io_err("open directory", dir))?;
            if !meta.is_dir() {
                return Err(StoreError::Inconsistent {
                    path: dir.to_path_buf(),
                    reason: if meta.file_type().is_symlink() {
                        "is a symbolic link; a scan's directories are never followed through links (move the scan's directory there instead)".into()
                    } else {
                        "is not a directory".into()
                    },
                });
            }
        }
        Ok(ScanStore {
            root: root.to_path_buf(),
            faults,
        })
    }

    /// The scan directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The `lines/` directory.
    pub fn lines_dir(&self) -> PathBuf {
        self.root.join("lines")
    }

    /// The journal's path.
    pub fn journal_path(&self) -> PathBuf {
        self.root.join(JOURNAL_FILE)
    }

    /// The injected fault hook (for the journal and metrics writers).
    pub fn faults(&self) -> Arc<dyn StorageFaults> {
        Arc::clone(&self.faults)
    }

    /// Writes one file of `lines/` durably, asking the fault hook first.
    fn write_file(&self, name: &str, bytes: &[u8], step: WriteStep) -> Result<(), StoreError> {
        let path = self.lines_dir().join(name);
        write_file_durably(&path, bytes, step, &*self.faults).map_err(io_err("write", &path))
    }

    /// Writes a line's two files durably (heights first, metadata second); returns the
    /// SHA-256 of the heights file, hex. When the metadata cannot be written the heights
    /// file is removed again (best effort), so a failed line leaves nothing behind.
    pub fn write_line(&self, meta: &LineMeta, profile: &Profile) -> Result<String, StoreError> {
        let dir = self.lines_dir();
        let csv = render_csv(profile);
        if meta.id.points != profile.heights_um.len() {
            return Err(StoreError::Inconsistent {
                path: dir.join(meta_name(meta.id.index)),
                reason: format!(
                    "metadata says {} points but the profile has {}",
                    meta.id.points,
                    profile.heights_um.len()
                ),
            });
        }
        let json = serde_json::to_vec_pretty(meta).map_err(|source| StoreError::MetaJson {
            path: dir.join(meta_name(meta.id.index)),
            source,
        })?;
        self.write_file(&csv_name(meta.id.index), csv.as_bytes(), WriteStep::LineCsv)?;
        if let Err(e) = self.write_file(&meta_name(meta.id.index), &json, WriteStep::LineJson) {
            // Never half-keep a line: without its metadata the heights file goes too.
            let _ = fs::remove_file(dir.join(csv_name(meta.id.index)));
            let _ = sync_dir(&dir);
            return Err(e);
        }
        Ok(hex_sha256(csv.as_bytes()))
    }

    /// The per-line durability order: line files (temp, fsync, rename, fsync dir), then the
    /// journal record (append, fsync). Only after this returns `Ok` may the stage move.
    pub fn commit_line(
        &self,
        journal: &mut Journal,
        meta: &LineMeta,
        profile: &Profile,
    ) -> Result<(), StoreError> {
        let sha = self.write_line(meta, profile)?;
        journal.append(&Record::Line(LineRecord {
            id: meta.id,
            csv_sha256: sha,
            time: meta.finished_at,
        }))?;
        Ok(())
    }

    /// Loads one line's files.
    pub fn load_line(&self, index: u32) -> Result<StoredLine, StoreError> {
        let dir = self.lines_dir();
        let csv_path = dir.join(csv_name(index));
        let meta_path = dir.join(meta_name(index));
        let meta_text = fs::read(&meta_path).map_err(|e| {
            if e.kind() == io::ErrorKind::NotFound && csv_path.exists() {
                StoreError::MissingCompanion {
                    path: csv_path.clone(),
                    missing: meta_path.clone(),
                }
            } else {
                StoreError::Io {
                    op: "read",
                    path: meta_path.clone(),
                    source: e,
                }
            }
        })?;
        let meta_text = text(&meta_path, meta_text)?;
        let meta: LineMeta =
            serde_json::from_str(&meta_text).map_err(|source| StoreError::MetaJson {
                path: meta_path.clone(),
                source,
            })?;
        if meta.id.index != index {
            return Err(StoreError::Inconsistent {
                path: meta_path,
                reason: format!(
                    "holds line index {} but is named for {index}",
                    meta.id.index
                ),
            });
        }
        let csv_text = fs::read(&csv_path).map_err(|e| {
            if e.kind() == io::ErrorKind::NotFound {
                StoreError::MissingCompanion {
                    path: meta_path.clone(),
                    missing: csv_path.clone(),
                }
            } else {
                StoreError::Io {
                    op: "read",
                    path: csv_path.clone(),
                    source: e,
                }
            }
        })?;
        let csv_text = text(&csv_path, csv_text)?;
        let heights = parse_csv(&csv_path, &csv_text, meta.profile.pitch_x_mm)?;
        if heights.len() != meta.id.points {
            return Err(StoreError::Inconsistent {
                path: csv_path,
                reason: format!(
                    "has {} points, its metadata says {}",
                    heights.len(),
                    meta.id.points
                ),
            });
        }
        let profile = meta.profile.clone().with_heights(heights);
        Ok(StoredLine { meta, profile })
    }

    /// Indices of the lines in `lines/`, split into complete ones (both files present) and
    /// incomplete ones (only one of the two: a crash between the two renames). Temporary
    /// files are ignored.
    pub fn stored_indices(&self) -> Result<(BTreeSet<u32>, BTreeSet<u32>), StoreError> {
        let dir = self.lines_dir();
        let mut csv = BTreeSet::new();
        let mut json = BTreeSet::new();
        for entry in fs::read_dir(&dir).map_err(io_err("list", &dir))? {
            let entry = entry.map_err(io_err("list", &dir))?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            let Some((stem, ext)) = name.rsplit_once('.') else {
                continue;
            };
            if stem.is_empty() || !stem.bytes().all(|b| b.is_ascii_digit()) {
                continue;
            }
            let Ok(i) = stem.parse::<u32>() else { continue };
            match ext {
                "csv" => csv.insert(i),
                "json" => json.insert(i),
                _ => false,
            };
        }
        let complete = csv.intersection(&json).copied().collect();
        let incomplete = csv.symmetric_difference(&json).copied().collect();
        Ok((complete, incomplete))
    }

    /// Loads every complete line stored in the directory, in index order (for `fit` and
    /// `analyze` of a partial, aborted or failed scan: the lines it has), and names the
    /// incomplete ones. A complete but malformed line is an error.
    pub fn load_all(&self) -> Result<LoadedLines, StoreError> {
        let (complete, incomplete) = self.stored_indices()?;
        let lines = complete
            .into_iter()
            .map(|i| self.load_line(i))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(LoadedLines {
            lines,
            incomplete: incomplete.into_iter().collect(),
        })
    }

    /// Loads the lines the journal records as completed, checking each heights file against
    /// the SHA-256 in its journal record. This is what a resumed scan rebuilds its fit from.
    pub fn load_committed(&self, records: &[LineRecord]) -> Result<Vec<StoredLine>, StoreError> {
        let mut out = Vec::with_capacity(records.len());
        for r in records {
            let line = self.load_line(r.id.index)?;
            let csv_path = self.lines_dir().join(csv_name(r.id.index));
            let sha = self
                .heights_sha256(r.id.index)
                .map_err(io_err("read", &csv_path))?;
            if sha != r.csv_sha256 {
                return Err(StoreError::Inconsistent {
                    path: csv_path,
                    reason: format!(
                        "SHA-256 {sha} differs from the journal's {}; the file was changed after the line was committed",
                        r.csv_sha256
                    ),
                });
            }
            out.push(line);
        }
        Ok(out)
    }

    /// The SHA-256 of line `index`'s heights file as it is on disk, what its journal record
    /// is checked against; the read's own error when it cannot be read (missing included).
    pub fn heights_sha256(&self, index: u32) -> io::Result<String> {
        fs::read(self.lines_dir().join(csv_name(index))).map(|bytes| hex_sha256(&bytes))
    }
}

/// Name of the directory inside a scan directory where damaged committed lines are moved.
pub const QUARANTINE_DIR: &str = "quarantine";

/// What [`ScanStore::load_committed_repairing`] found: the committed lines that check out,
/// and the ones moved aside to be traced again (each as the record the journal gets).
#[derive(Debug)]
pub struct CommittedLines {
    /// Lines whose heights file matches its journal record, in record order.
    pub lines: Vec<StoredLine>,
    /// Lines moved to `quarantine/`, in record order.
    pub quarantined: Vec<QuarantineRecord>,
}

impl ScanStore {
    /// Like [`ScanStore::load_committed`], but a committed line whose heights file fails its
    /// SHA-256, is missing, or whose files cannot be read as a line is not obeyed: its files
    /// are moved (durably) to `quarantine/NNNN.csv` / `.json` (`NNNN-2.csv`, … when that name
    /// is taken) and it is reported, both hashes with it, so the caller records it in the
    /// journal and traces the line again. Other I/O errors (a disk that cannot be read) are
    /// errors: nothing can be decided about the line then.
    pub fn load_committed_repairing(
        &self,
        records: &[LineRecord],
        now: DateTime<Utc>,
    ) -> Result<CommittedLines, StoreError> {
        let mut out = CommittedLines {
            lines: Vec::with_capacity(records.len()),
            quarantined: Vec::new(),
        };
        for r in records {
            let found = match self.heights_sha256(r.id.index) {
                Ok(sha) => Some(sha),
                Err(e) if e.kind() == io::ErrorKind::NotFound => None,
                Err(e) => {
                    let csv_path = self.lines_dir().join(csv_name(r.id.index));
                    return Err(io_err("read", &csv_path)(e));
                }
            };
            let problem = match &found {
                None => Some("its heights file is missing".to_owned()),
                Some(sha) if *sha != r.csv_sha256 => Some(format!(
                    "its heights file has SHA-256 {sha}, the journal's line record {}: the file was changed after the line was committed",
                    r.csv_sha256
                )),
                Some(_) => match self.load_line(r.id.index) {
                    Ok(line) => {
                        out.lines.push(line);
                        None
                    }
                    Err(e)
                        if matches!(&e, StoreError::Io { source, .. }
                            if source.kind() != io::ErrorKind::NotFound) =>
                    {
                        return Err(e);
                    }
                    Err(e) => Some(format!("its files cannot be read as a line: {e}")),
                },
            };
            if let Some(reason) = problem {
                let moved_to = self.quarantine(r.id.index)?;
                out.quarantined.push(QuarantineRecord {
                    index: r.id.index,
                    expected_sha256: r.csv_sha256.clone(),
                    found_sha256: found.unwrap_or_default(),
                    moved_to,
                    reason: format!(
                        "line {}: {reason}; moved aside, it is traced again",
                        r.id.index + 1
                    ),
                    time: now,
                });
            }
        }
        Ok(out)
    }

    /// Moves line `index`'s files (those present) into `quarantine/` under a name not yet
    /// taken, fsyncing both directories; returns the heights file's new path relative to the
    /// scan directory.
    fn quarantine(&self, index: u32) -> Result<String, StoreError> {
        let qdir = self.root.join(QUARANTINE_DIR);
        fs::create_dir_all(&qdir).map_err(io_err("create directory", &qdir))?;
        let stem = (1u32..)
            .map(|n| match n {
                1 => format!("{index:04}"),
                n => format!("{index:04}-{n}"),
            })
            .find(|stem| {
                !qdir.join(format!("{stem}.csv")).exists()
                    && !qdir.join(format!("{stem}.json")).exists()
            })
            .unwrap_or_else(|| format!("{index:04}"));
        let lines = self.lines_dir();
        for (from, ext) in [(csv_name(index), "csv"), (meta_name(index), "json")] {
            let src = lines.join(from);
            let dst = qdir.join(format!("{stem}.{ext}"));
            match fs::rename(&src, &dst) {
                Ok(()) => {}
                Err(e) if e.kind() == io::ErrorKind::NotFound => {}
                Err(e) => return Err(io_err("move aside", &src)(e)),
            }
        }
        sync_dir(&qdir)?;
        sync_dir(&lines)?;
        sync_dir(&self.root)?;
        Ok(format!("{QUARANTINE_DIR}/{stem}.csv"))
    }
}

/// A line file's bytes as text; bytes that are not UTF-8 are damage to the file, not a
/// failure to read it (so the line is set aside at resume like any other damaged line).
fn text(path: &Path, bytes: Vec<u8>) -> Result<String, StoreError> {
    String::from_utf8(bytes).map_err(|e| StoreError::NotText {
        path: path.to_path_buf(),
        byte: e.utf8_error().valid_up_to(),
    })
}

/// Hex SHA-256 of `bytes`.
pub fn hex_sha256(bytes: &[u8]) -> String {
    let d = Sha256::digest(bytes);
    let mut s = String::with_capacity(64);
    for b in d {
        s.push_str(&format!("{b:02x}"));
    }
    s
}
