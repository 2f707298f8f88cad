//! The page's history: the station's scans from the scan index (what `surfscan list` shows),
//! newest first, each with the files in its directory; and the one way a scan's file is
//! reached from the page, by a name checked to be a plain file directly in that scan's
//! directory (no path, no hidden or temporary file, no symbolic link).
//!
//! Layer 4 (process edge): depends on the scan index ([`crate::jobs::index::listing`]); reads
//! the output directory. Blocking: the server calls it on a blocking thread.

use crate::jobs::index::{listing, Filter, ScanEntry};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Most scans one history answer holds.
pub const MAX_SCANS: usize = 1000;

/// A file of a scan, for a link.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ScanFile {
    /// Its name in the scan directory.
    pub name: String,
    /// Bytes.
    pub bytes: u64,
}

/// One scan of the history.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HistoryEntry {
    /// What the index says.
    #[serde(flatten)]
    pub entry: ScanEntry,
    /// The files of its directory (`lines/` not included), by name.
    pub files: Vec<ScanFile>,
}

/// The history answer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct History {
    /// Newest first, at most the limit asked.
    pub scans: Vec<HistoryEntry>,
    /// Scans on the station in all.
    pub total: usize,
    /// What people should know about the listing (an index that could not be updated).
    pub notes: Vec<String>,
}

/// Whether `name` may name a scan directory or a file in one: one path component of
/// letters, digits, `.`, `_`, `-`, not starting with `.` (no `..`, no hidden or temporary
/// file, no separator).
pub fn safe_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 255
        && !name.starts_with('.')
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b))
}

/// The regular files directly in `dir` with safe names, by name.
pub fn scan_files(dir: &Path) -> Vec<ScanFile> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<ScanFile> = entries
        .filter_map(Result::ok)
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let meta = e.metadata().ok()?;
            (safe_name(&name) && e.file_type().ok()?.is_file()).then_some(ScanFile {
                name,
                bytes: meta.len(),
            })
        })
        .collect();
    files.sort_by(|a, b| a.name.cmp(&b.name));
    files
}

/// The `limit` newest scans of `out` with their files.
pub fn history(out: &Path, limit: usize) -> Result<History, String> {
    let (mut entries, notes) = listing(out, &Filter::default()).map_err(|e| e.to_string())?;
    let total = entries.len();
    entries.reverse();
    entries.truncate(limit.min(MAX_SCANS));
    let scans = entries
        .into_iter()
        .map(|entry| {
            let files = scan_files(&out.join(&entry.scan_id));
            HistoryEntry { entry, files }
        })
        .collect();
    Ok(History {
        scans,
        total,
        notes,
    })
}

/// The path of file `name` of scan `scan` in `out`, when both names are safe and it is a
/// regular file (not a link) directly in that scan's directory, itself a directory directly
/// in `out`.
pub fn scan_file(out: &Path, scan: &str, name: &str) -> Option<PathBuf> {
    if !safe_name(scan) || !safe_name(name) {
        return None;
    }
    let dir = out.join(scan);
    if !std::fs::symlink_metadata(&dir).ok()?.is_dir() {
        return None;
    }
    let path = dir.join(name);
    std::fs::symlink_metadata(&path)
        .ok()?
        .is_file()
        .then_some(path)
}

/// The media type of a scan's file, and whether the browser should save it rather than
/// show it.
pub fn media_type(name: &str) -> (&'static str, bool) {
    let ext = name.rsplit_once('.').map_or("", |(_, e)| e);
    match ext {
        "html" => ("text/html; charset=utf-8", false),
        "json" => ("application/json", false),
        "png" => ("image/png", false),
        "svg" => ("image/svg+xml", false),
        "csv" => ("text/csv; charset=utf-8", true),
        "jsonl" => ("application/x-ndjson", true),
        "igs" | "iges" => ("model/iges", true),
        "x3p" => ("application/octet-stream", true),
        _ => ("application/octet-stream", true),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_plain_names_reach_a_file() {
        for bad in [
            "",
            ".",
            "..",
            ".journal.jsonl.tmp",
            "a/b",
            "../x",
            "a\\b",
            "a b",
            "é",
        ] {
            assert!(!safe_name(bad), "{bad:?}");
        }
        for good in [
            "report.html",
            "surface.part1-of-2.igs",
            "20261206T035907Z-practice-2",
        ] {
            assert!(safe_name(good), "{good:?}");
        }
    }

    #[test]
    fn a_scan_file_is_a_regular_file_directly_in_a_scan_directory() {
        let out = tempfile::tempdir().unwrap();
        let scan = out.path().join("S1");
        std::fs::create_dir_all(scan.join("lines")).unwrap();
        std::fs::write(scan.join("report.html"), "<p>").unwrap();
        std::fs::write(out.path().join("secret.txt"), "no").unwrap();
        std::os::unix::fs::symlink(out.path().join("secret.txt"), scan.join("link.txt")).unwrap();
        std::os::unix::fs::symlink(&scan, out.path().join("S2")).unwrap();
        assert_eq!(
            scan_file(out.path(), "S1", "report.html"),
            Some(scan.join("report.html"))
        );
        assert_eq!(scan_file(out.path(), "S1", "link.txt"), None);
        assert_eq!(scan_file(out.path(), "S1", "lines"), None);
        assert_eq!(scan_file(out.path(), "S2", "report.html"), None);
        assert_eq!(scan_file(out.path(), "..", "secret.txt"), None);
        assert_eq!(scan_file(out.path(), "S1", "../secret.txt"), None);
        let names: Vec<String> = scan_files(&scan).into_iter().map(|f| f.name).collect();
        assert_eq!(names, ["report.html"]);
    }

    #[test]
    fn data_files_are_saved_and_pages_shown() {
        assert_eq!(
            media_type("report.html"),
            ("text/html; charset=utf-8", false)
        );
        assert!(media_type("surface.igs").1);
        assert!(media_type("measured.x3p").1);
        assert!(media_type("journal.jsonl").1);
        assert!(!media_type("heightmap.png").1);
    }
}
