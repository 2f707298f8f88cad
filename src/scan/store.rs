//! Durable per-line storage of a scan directory: `lines/NNNN.csv` + `lines/NNNN.json`.
//!
//! Every file is written to a temporary name, fsynced, renamed into place and the directory
//! fsynced, so a line file is either absent or complete after a crash. [`ScanStore::commit_line`]
//! performs the full per-line durability order (line files, then the journal record) — only
//! after it returns may the stage move. A [`StorageFaults`] hook injected into the store lets
//! tests fail a chosen write (e.g. with `ENOSPC`) to show that a scan fails cleanly.
//!
//! Layer 3 (session): depends on [`crate::profile`], [`crate::units`] and [`super::journal`];
//! file I/O only, no devices.

use std::collections::BTreeSet;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::profile::{Conditions, InstrumentResult, Profile, ProfileKind};
use crate::units::Nm;

use super::journal::{Journal, JournalError, LineRecord, Record};

/// The write a [`StorageFaults`] hook is asked about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WriteStep {
    /// The `NNNN.csv` heights file of a line.
    LineCsv,
    /// The `NNNN.json` metadata file of a line.
    LineJson,
    /// A journal append.
    Journal,
    /// The metrics file.
    Metrics,
}

/// Injected before every durable write; returning an error makes that write fail as if the
/// operating system had refused it. Production code uses [`NoFaults`].
pub trait StorageFaults: Send + Sync {
    /// Called before `step` writes `path`; an `Err` aborts that write with this error.
    fn before_write(&self, step: WriteStep, path: &Path) -> io::Result<()>;
}

/// The hook that never fails.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoFaults;

impl StorageFaults for NoFaults {
    fn before_write(&self, _step: WriteStep, _path: &Path) -> io::Result<()> {
        Ok(())
    }
}

/// Errors of the scan directory and its line files.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A file system operation failed.
    #[error("{op} {path}: {source} (check the output directory's permissions and free space)")]
    Io {
        /// What was being done ("create", "write", "rename", …).
        op: &'static str,
        /// The path concerned.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: io::Error,
    },
    /// The heights file does not start with the `x_mm,z_um` header.
    #[error("{path}: line 1 is {found:?}, expected the header \"x_mm,z_um\"")]
    CsvHeader {
        /// The file.
        path: PathBuf,
        /// The first line as found.
        found: String,
    },
    /// A data row of a heights file is malformed.
    #[error("{path}: line {line}: {content:?}: {reason}")]
    CsvRow {
        /// The file.
        path: PathBuf,
        /// 1-based line number in the file.
        line: usize,
        /// The row as found.
        content: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A metadata file is not valid line metadata.
    #[error("{path}: not valid line metadata: {source}")]
    MetaJson {
        /// The file.
        path: PathBuf,
        /// The parser's error (with its line and column).
        #[source]
        source: serde_json::Error,
    },
    /// One of the two files of a line is missing.
    #[error("{path}: its companion {missing} is missing; the line is incomplete (re-trace it or remove the file)")]
    MissingCompanion {
        /// The file that exists.
        path: PathBuf,
        /// The file that should exist next to it.
        missing: PathBuf,
    },
    /// The metadata disagrees with the file name or with the heights file.
    #[error("{path}: {reason}")]
    Inconsistent {
        /// The file.
        path: PathBuf,
        /// What disagrees, with both values.
        reason: String,
    },
    /// A journal operation failed.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// The file system cannot hold the planned scan.
    #[error("{path}: the scan needs about {needed_bytes} bytes but only {available_bytes} are free; free space or choose another output.dir")]
    DiskTooSmall {
        /// The output directory checked.
        path: PathBuf,
        /// Estimated bytes the scan will write.
        needed_bytes: u64,
        /// Bytes available to an unprivileged writer.
        available_bytes: u64,
    },
}

impl StoreError {
    /// True when the underlying cause is a full disk or exhausted quota.
    pub fn is_disk_full(&self) -> bool {
        let code = match self {
            StoreError::Io { source, .. } => source.raw_os_error(),
            StoreError::Journal(JournalError::Io { source, .. }) => source.raw_os_error(),
            StoreError::DiskTooSmall { .. } => return true,
            _ => None,
        };
        matches!(code, Some(libc::ENOSPC) | Some(libc::EDQUOT))
    }
}

fn io_err<'a>(op: &'static str, path: &'a Path) -> impl FnOnce(io::Error) -> StoreError + 'a {
    move |source| StoreError::Io {
        op,
        path: path.to_path_buf(),
        source,
    }
}

/// A scan's identifier: `YYYYMMDDTHHMMSSZ-<specimen-slug>`, also its directory name.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ScanId(pub String);

impl ScanId {
    /// Builds the id from the start time and the specimen id; the specimen is reduced to
    /// `[a-z0-9-]` (runs of other characters become one `-`, at most 40 characters) and an
    /// empty result becomes `scan`.
    pub fn new(start: DateTime<Utc>, specimen: &str) -> ScanId {
        let mut slug = String::new();
        for c in specimen.chars() {
            if c.is_ascii_alphanumeric() {
                slug.push(c.to_ascii_lowercase());
            } else if !slug.is_empty() && !slug.ends_with('-') {
                slug.push('-');
            }
            if slug.len() >= 40 {
                break;
            }
        }
        let slug = slug.trim_end_matches('-');
        let slug = if slug.is_empty() { "scan" } else { slug };
        ScanId(format!("{}-{}", start.format("%Y%m%dT%H%M%SZ"), slug))
    }
}

impl std::fmt::Display for ScanId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

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

/// The lines of a scan directory as found by [`ScanStore::load_all`].
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedLines {
    /// Complete lines, in index order.
    pub lines: Vec<StoredLine>,
    /// Indices with only one of their two files (not loaded).
    pub incomplete: Vec<u32>,
}

/// Renders the heights file: header `x_mm,z_um`, one row per point, both numbers in Rust's
/// shortest round-trip decimal form, so reading back yields bit-identical values.
pub fn render_csv(profile: &Profile) -> String {
    let mut s = String::with_capacity(16 + profile.heights_um.len() * 24);
    s.push_str("x_mm,z_um\n");
    for (i, z) in profile.heights_um.iter().enumerate() {
        s.push_str(&format!("{},{}\n", profile.x_mm(i), z));
    }
    s
}

/// Parses a heights file (as written by [`render_csv`]); `path` names it in errors.
/// Returns the heights and checks the x column against `pitch_x_mm` (within 1e-9 mm).
pub fn parse_csv(path: &Path, text: &str, pitch_x_mm: f64) -> Result<Vec<f64>, StoreError> {
    let mut lines = text.lines();
    let header = lines.next().unwrap_or("");
    if header.trim_end_matches('\r') != "x_mm,z_um" {
        return Err(StoreError::CsvHeader {
            path: path.to_path_buf(),
            found: header.to_string(),
        });
    }
    let mut heights = Vec::new();
    for (n, row) in lines.enumerate() {
        let row_err = |reason: String| StoreError::CsvRow {
            path: path.to_path_buf(),
            line: n + 2,
            content: row.to_string(),
            reason,
        };
        let r = row.trim_end_matches('\r');
        let Some((x, z)) = r.split_once(',') else {
            return Err(row_err("expected two comma-separated numbers".into()));
        };
        let x: f64 = crate::numbers::parse_f64(x.trim())
            .map_err(|e| row_err(format!("x_mm is not a number: {e}")))?;
        let z: f64 = crate::numbers::parse_f64(z.trim())
            .map_err(|e| row_err(format!("z_um is not a number: {e}")))?;
        if !z.is_finite() || !x.is_finite() {
            return Err(row_err("values must be finite".into()));
        }
        let expect = heights.len() as f64 * pitch_x_mm;
        if (x - expect).abs() > 1e-9 {
            return Err(row_err(format!(
                "x_mm {x} does not match point {} × pitch {pitch_x_mm} mm = {expect}",
                heights.len()
            )));
        }
        heights.push(z);
    }
    Ok(heights)
}

/// Writes `bytes` to `dir/name` durably: temp file, fsync, rename, fsync of `dir`.
/// On failure the temporary file is removed (best effort) and the target is untouched.
pub fn write_durably(
    dir: &Path,
    name: &str,
    bytes: &[u8],
    step: WriteStep,
    faults: &dyn StorageFaults,
) -> Result<PathBuf, StoreError> {
    let target = dir.join(name);
    let tmp = dir.join(format!(".{name}.tmp"));
    let result = (|| {
        faults
            .before_write(step, &target)
            .map_err(io_err("write", &tmp))?;
        let mut f = File::create(&tmp).map_err(io_err("create", &tmp))?;
        f.write_all(bytes).map_err(io_err("write", &tmp))?;
        f.sync_all().map_err(io_err("fsync", &tmp))?;
        drop(f);
        fs::rename(&tmp, &target).map_err(io_err("rename", &target))?;
        sync_dir(dir)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result.map(|()| target)
}

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
    /// Creates `<output_dir>/<id>/lines/` (the output directory too) and fsyncs the parents.
    pub fn create(
        output_dir: &Path,
        id: &ScanId,
        faults: Arc<dyn StorageFaults>,
    ) -> Result<ScanStore, StoreError> {
        let root = output_dir.join(&id.0);
        let lines = root.join("lines");
        fs::create_dir_all(&lines).map_err(io_err("create directory", &lines))?;
        sync_dir(&root)?;
        sync_dir(output_dir)?;
        Ok(ScanStore { root, faults })
    }

    /// Opens an existing scan directory (which must hold `lines/`).
    pub fn open(root: &Path, faults: Arc<dyn StorageFaults>) -> Result<ScanStore, StoreError> {
        let lines = root.join("lines");
        fs::metadata(&lines).map_err(io_err("open directory", &lines))?;
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
        self.root.join("journal.jsonl")
    }

    /// The injected fault hook (for the journal and metrics writers).
    pub fn faults(&self) -> Arc<dyn StorageFaults> {
        Arc::clone(&self.faults)
    }

    /// Writes a line's two files durably (heights first, metadata second); returns the
    /// SHA-256 of the heights file, hex. When the metadata cannot be written the heights
    /// file is removed again (best effort), so a failed line leaves nothing behind.
    pub fn write_line(&self, meta: &LineMeta, profile: &Profile) -> Result<String, StoreError> {
        let dir = self.lines_dir();
        let csv = render_csv(profile);
        if meta.points != profile.heights_um.len() {
            return Err(StoreError::Inconsistent {
                path: dir.join(meta_name(meta.index)),
                reason: format!(
                    "metadata says {} points but the profile has {}",
                    meta.points,
                    profile.heights_um.len()
                ),
            });
        }
        let json = serde_json::to_vec_pretty(meta).map_err(|source| StoreError::MetaJson {
            path: dir.join(meta_name(meta.index)),
            source,
        })?;
        write_durably(
            &dir,
            &csv_name(meta.index),
            csv.as_bytes(),
            WriteStep::LineCsv,
            &*self.faults,
        )?;
        if let Err(e) = write_durably(
            &dir,
            &meta_name(meta.index),
            &json,
            WriteStep::LineJson,
            &*self.faults,
        ) {
            // Never half-keep a line: without its metadata the heights file goes too.
            let _ = fs::remove_file(dir.join(csv_name(meta.index)));
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
            index: meta.index,
            y_target_nm: meta.y_target_nm,
            y_readback_nm: meta.y_readback_nm,
            attempt: meta.attempt,
            points: meta.points,
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
        let meta_text = fs::read_to_string(&meta_path).map_err(|e| {
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
        let meta: LineMeta =
            serde_json::from_str(&meta_text).map_err(|source| StoreError::MetaJson {
                path: meta_path.clone(),
                source,
            })?;
        if meta.index != index {
            return Err(StoreError::Inconsistent {
                path: meta_path,
                reason: format!("holds line index {} but is named for {index}", meta.index),
            });
        }
        let csv_text = fs::read_to_string(&csv_path).map_err(|e| {
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
        let heights = parse_csv(&csv_path, &csv_text, meta.pitch_x_mm)?;
        if heights.len() != meta.points {
            return Err(StoreError::Inconsistent {
                path: csv_path,
                reason: format!(
                    "has {} points, its metadata says {}",
                    heights.len(),
                    meta.points
                ),
            });
        }
        let profile = Profile {
            pitch_x_mm: meta.pitch_x_mm,
            heights_um: heights,
            kind: meta.kind,
            conditions: meta.conditions.clone(),
        };
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
            let line = self.load_line(r.index)?;
            let csv_path = self.lines_dir().join(csv_name(r.index));
            let bytes = fs::read(&csv_path).map_err(io_err("read", &csv_path))?;
            let sha = hex_sha256(&bytes);
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

/// Bytes budgeted per stored point in the heights CSV (`x_mm,z_um` shortest round-trip:
/// up to ~22 + ~22 characters, comma, newline).
pub const CSV_BYTES_PER_POINT: u64 = 48;
/// Bytes budgeted per point in the IGES surface (three coordinates of a pole plus a weight
/// at up to ~24 characters each, in 64-column parameter lines with 16-column tails).
pub const IGES_BYTES_PER_POINT: u64 = 125;
/// Bytes budgeted per line for its metadata JSON and journal record.
pub const META_BYTES_PER_LINE: u64 = 8 * 1024;
/// Fixed allowance for the start record, report, plots and metrics.
pub const FIXED_BYTES: u64 = 4 * 1024 * 1024;

/// Estimated bytes a scan of `lines` lines of `points_per_line` points writes.
pub fn estimate_scan_bytes(lines: u32, points_per_line: u64) -> u64 {
    let points = points_per_line.saturating_mul(u64::from(lines));
    points
        .saturating_mul(CSV_BYTES_PER_POINT + IGES_BYTES_PER_POINT)
        .saturating_add(u64::from(lines).saturating_mul(META_BYTES_PER_LINE))
        .saturating_add(FIXED_BYTES)
}

/// Bytes available to an unprivileged writer on the file system holding `dir`.
pub fn free_bytes(dir: &Path) -> Result<u64, StoreError> {
    let st = nix::sys::statvfs::statvfs(dir).map_err(|e| StoreError::Io {
        op: "statvfs",
        path: dir.to_path_buf(),
        source: io::Error::from(e),
    })?;
    // The libc types are u64 on 64-bit Linux but narrower elsewhere: keep the widening.
    #[allow(clippy::useless_conversion)]
    let (blocks, size) = (
        u64::from(st.blocks_available()),
        u64::from(st.fragment_size()),
    );
    Ok(blocks.saturating_mul(size))
}

/// Refuses (with [`StoreError::DiskTooSmall`]) when `available_bytes` cannot hold
/// `needed_bytes`; pure so that it can be tested without filling a disk.
pub fn check_space(path: &Path, needed_bytes: u64, available_bytes: u64) -> Result<(), StoreError> {
    if needed_bytes > available_bytes {
        return Err(StoreError::DiskTooSmall {
            path: path.to_path_buf(),
            needed_bytes,
            available_bytes,
        });
    }
    Ok(())
}

/// Pre-flight: estimates the scan's disk use and checks the free space of `output_dir`.
/// Returns the estimate on success.
pub fn preflight_disk(
    output_dir: &Path,
    lines: u32,
    points_per_line: u64,
) -> Result<u64, StoreError> {
    let needed = estimate_scan_bytes(lines, points_per_line);
    check_space(output_dir, needed, free_bytes(output_dir)?)?;
    Ok(needed)
}

/// Appends to a file with `O_APPEND` (used by the journal).
pub(crate) fn open_append(path: &Path) -> io::Result<File> {
    OpenOptions::new().append(true).create(true).open(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use chrono::TimeZone;

    #[test]
    fn scan_id_is_timestamp_and_slug() {
        let t = Utc.with_ymd_and_hms(2026, 3, 4, 5, 6, 7).unwrap();
        assert_eq!(
            ScanId::new(t, "Block #12 / Ra 0.4").0,
            "20260304T050607Z-block-12-ra-0-4"
        );
        assert_eq!(ScanId::new(t, "  ").0, "20260304T050607Z-scan");
    }

    #[test]
    fn csv_round_trips_bit_identically() {
        let p = Profile::new(
            0.0015,
            vec![0.1, -1.23456789012345, 1e-300, 0.30000000000000004],
        );
        let text = render_csv(&p);
        assert!(text.starts_with("x_mm,z_um\n0,0.1\n0.0015,-1.23456789012345\n"));
        let back = parse_csv(Path::new("a.csv"), &text, 0.0015).unwrap();
        assert_eq!(back, p.heights_um);
    }

    #[test]
    fn malformed_csv_names_path_line_and_content() {
        let e = parse_csv(Path::new("l/0003.csv"), "x_mm,z_um\n0,1\n0.5,abc\n", 0.5).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("l/0003.csv") && msg.contains("line 3") && msg.contains("0.5,abc"),
            "{msg}"
        );
        let e = parse_csv(Path::new("a"), "x,z\n", 0.5).unwrap_err();
        assert!(matches!(e, StoreError::CsvHeader { found, .. } if found == "x,z"));
        let e = parse_csv(Path::new("a"), "x_mm,z_um\n0,1\n0.7,2\n", 0.5).unwrap_err();
        assert!(matches!(e, StoreError::CsvRow { line: 3, .. }));
    }

    #[test]
    fn csv_budget_bounds_worst_case_rows() {
        // Pitches and heights that are not exact binary fractions print with 17 significant
        // digits; the per-point budget must still hold.
        let n = 20_000;
        let heights: Vec<f64> = (0..n).map(|i| -(i as f64) / 3.0e4 - 1.0e-7).collect();
        let p = Profile::new(0.0001, heights);
        let csv = render_csv(&p);
        assert!(
            csv.len() as u64 <= CSV_BYTES_PER_POINT * n as u64,
            "{} bytes for {n} points",
            csv.len()
        );
    }

    #[test]
    fn disk_estimate_and_check() {
        // 31 lines × 8000 points: 248000 × 173 B + 31 × 8 KiB + 4 MiB.
        let e = estimate_scan_bytes(31, 8000);
        assert_eq!(e, 248_000 * 173 + 31 * 8192 + 4 * 1024 * 1024);
        assert!(check_space(Path::new("/x"), e, e).is_ok());
        let err = check_space(Path::new("/x"), e, e - 1).unwrap_err();
        assert!(err.is_disk_full());
        assert!(err.to_string().contains(&e.to_string()));
    }
}
