//! Errors of a scan directory and its line files, shared by the store, the line file format
//! and the disk pre-flight.
//!
//! Layer 3 (session): depends on [`super::journal`] (whose errors it can carry) and std.

use std::io;
use std::path::{Path, PathBuf};

use super::journal::JournalError;

/// Errors of the scan directory and its line files.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A file system operation failed.
    #[error("{op} {path}: {source} ({})", io_hint(op))]
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
    /// A line's file holds bytes that are not UTF-8: the file was damaged after it was
    /// written (the store writes both files as ASCII text).
    #[error(
        "{path}: byte {byte} is not UTF-8 text: the file was damaged after the line was written"
    )]
    NotText {
        /// The file.
        path: PathBuf,
        /// Offset of the first byte that is not UTF-8.
        byte: usize,
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
    /// The file system holding the output directory has fewer free inodes (files) than the
    /// scan creates.
    #[error("{path}: the scan creates about {needed} files but the file system has only {available} inodes free; delete files there or choose another output.dir")]
    TooFewInodes {
        /// The output directory checked.
        path: PathBuf,
        /// Files the scan creates.
        needed: u64,
        /// Inodes free.
        available: u64,
    },
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
            StoreError::DiskTooSmall { .. } | StoreError::TooFewInodes { .. } => return true,
            _ => None,
        };
        matches!(code, Some(libc::ENOSPC) | Some(libc::EDQUOT))
    }
}

/// The operating system's error number behind `e`, the first along its sources: the file
/// system refused, as opposed to what was read being wrong.
pub(crate) fn os_error(e: &(dyn std::error::Error + 'static)) -> Option<i32> {
    std::iter::successors(Some(e), |e| e.source()).find_map(|e| {
        e.downcast_ref::<io::Error>()
            .and_then(io::Error::raw_os_error)
    })
}

/// What to check after a failed `op`: a read needs a readable file (free space has nothing
/// to do with it), a listing a readable directory; whatever writes needs permission and space.
fn io_hint(op: &str) -> &'static str {
    match op {
        "read" => "check that it is a readable file",
        "list" | "open directory" => "check that it is a readable directory",
        _ => "check the output directory's permissions and free space",
    }
}

/// Maps an I/O error of `op` on `path` to [`StoreError::Io`].
pub(crate) fn io_err<'a>(
    op: &'static str,
    path: &'a Path,
) -> impl FnOnce(io::Error) -> StoreError + 'a {
    move |source| StoreError::Io {
        op,
        path: path.to_path_buf(),
        source,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_read_asks_for_a_readable_file_not_for_free_space() {
        let read =
            io_err("read", Path::new("lines/0003.csv"))(io::Error::from_raw_os_error(libc::EISDIR))
                .to_string();
        assert!(read.starts_with("read lines/0003.csv: "), "{read}");
        assert!(
            read.ends_with("(check that it is a readable file)"),
            "{read}"
        );
        let list = io_err("list", Path::new("lines"))(io::Error::from_raw_os_error(libc::EACCES))
            .to_string();
        assert!(list.contains("a readable directory"), "{list}");
        let write = io_err("write", Path::new("lines/.0003.csv.tmp"))(
            io::Error::from_raw_os_error(libc::EROFS),
        )
        .to_string();
        assert!(
            write.contains("output directory's permissions and free space"),
            "{write}"
        );
    }
}
