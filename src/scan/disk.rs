//! The disk pre-flight: whether the output directory's file system can hold what a planned
//! scan writes (the estimate is the plan's, [`super::plan::estimate_scan_bytes`]) before the
//! first line is traced; and, while a full
//! disk suspends the scan, the space its own earlier outputs take.
//!
//! Layer 3 (session): depends on [`super::store_error`], the file names of [`super::store`]
//! and [`super::journal`], and `statvfs`.

use std::io;
use std::path::Path;

use super::plan::estimate_scan_bytes;
use super::store_error::StoreError;

/// Bytes and inodes available to an unprivileged writer on the file system holding `dir`
/// (inodes `u64::MAX` when the file system does not count them).
pub fn free_space(dir: &Path) -> Result<(u64, u64), StoreError> {
    let st = nix::sys::statvfs::statvfs(dir).map_err(|e| StoreError::Io {
        op: "statvfs",
        path: dir.to_path_buf(),
        source: io::Error::from(e),
    })?;
    // The libc types are u64 on 64-bit Linux but narrower elsewhere: keep the widening.
    #[allow(clippy::useless_conversion)]
    let (blocks, size, files, files_free) = (
        u64::from(st.blocks_available()),
        u64::from(st.fragment_size()),
        u64::from(st.files()),
        u64::from(st.files_available()),
    );
    let inodes = if files == 0 { u64::MAX } else { files_free };
    Ok((blocks.saturating_mul(size), inodes))
}

/// Bytes available to an unprivileged writer on the file system holding `dir`.
pub fn free_bytes(dir: &Path) -> Result<u64, StoreError> {
    free_space(dir).map(|(bytes, _)| bytes)
}

/// Bytes of the files in scan directory `scan_dir` besides its lines (`lines/`,
/// `quarantine/`) and its journal: the surface, report, plots and X3P files of an earlier try
/// at the outputs, which the next try replaces. Files that cannot be read count 0.
pub fn outputs_bytes(scan_dir: &Path) -> u64 {
    fn walk(dir: &Path, top: bool) -> u64 {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return 0;
        };
        let mut n = 0u64;
        for e in entries.flatten() {
            let name = e.file_name();
            if top
                && matches!(
                    name.to_str(),
                    Some("lines" | super::store::QUARANTINE_DIR | super::journal::JOURNAL_FILE)
                )
            {
                continue;
            }
            let Ok(t) = e.file_type() else { continue };
            if t.is_dir() {
                n = n.saturating_add(walk(&e.path(), false));
            } else if t.is_file() {
                n = n.saturating_add(e.metadata().map_or(0, |m| m.len()));
            }
        }
        n
    }
    walk(scan_dir, true)
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
    let (free, inodes) = free_space(output_dir)?;
    check_space(output_dir, needed, free)?;
    let needed_inodes = super::plan::remaining_scan_inodes(lines, 0);
    if inodes < needed_inodes {
        return Err(StoreError::TooFewInodes {
            path: output_dir.to_path_buf(),
            needed: needed_inodes,
            available: inodes,
        });
    }
    Ok(needed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_space_check_refuses_one_byte_short_and_names_the_need() {
        let e = 1_000_000;
        assert!(check_space(Path::new("/x"), e, e).is_ok());
        let err = check_space(Path::new("/x"), e, e - 1).unwrap_err();
        assert!(err.is_disk_full());
        assert!(err.to_string().contains(&e.to_string()));
    }

    #[test]
    fn the_outputs_are_what_the_scan_directory_holds_besides_lines_and_journal() {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path();
        std::fs::create_dir_all(dir.join("lines")).unwrap();
        std::fs::create_dir_all(dir.join("quarantine")).unwrap();
        std::fs::create_dir_all(dir.join("rk")).unwrap();
        std::fs::write(dir.join("lines/0000.csv"), [0u8; 1000]).unwrap();
        std::fs::write(dir.join("quarantine/0001.csv"), [0u8; 1000]).unwrap();
        std::fs::write(dir.join("journal.jsonl"), [0u8; 1000]).unwrap();
        assert_eq!(outputs_bytes(dir), 0);
        std::fs::write(dir.join("surface.igs"), [0u8; 300]).unwrap();
        std::fs::write(dir.join("rk/0001.png"), [0u8; 20]).unwrap();
        assert_eq!(outputs_bytes(dir), 320);
        assert_eq!(outputs_bytes(&dir.join("absent")), 0);
    }
}
