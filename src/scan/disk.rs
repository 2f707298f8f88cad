//! The disk pre-flight: how many bytes a planned scan writes, and whether the output
//! directory's file system can hold them before the first line is traced; and, while a full
//! disk suspends the scan, the space its own earlier outputs take.
//!
//! Layer 3 (session): depends on [`super::store_error`], the file names of [`super::store`]
//! and [`super::journal`], and `statvfs`.

use std::io;
use std::path::Path;

use super::store_error::StoreError;

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

/// Estimated bytes still to be written by a scan of `lines` lines of which `committed` are
/// on disk: the remaining lines' files and records, the surface of the whole grid, and the
/// report.
pub fn remaining_scan_bytes(lines: u32, committed: u32, points_per_line: u64) -> u64 {
    let left = u64::from(lines.saturating_sub(committed));
    points_per_line
        .saturating_mul(left)
        .saturating_mul(CSV_BYTES_PER_POINT)
        .saturating_add(left.saturating_mul(META_BYTES_PER_LINE))
        .saturating_add(
            points_per_line
                .saturating_mul(u64::from(lines))
                .saturating_mul(IGES_BYTES_PER_POINT),
        )
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
    check_space(output_dir, needed, free_bytes(output_dir)?)?;
    Ok(needed)
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn what_remains_is_the_missing_lines_plus_the_whole_surface() {
        // Nothing committed: the whole scan.
        assert_eq!(
            remaining_scan_bytes(31, 0, 8000),
            estimate_scan_bytes(31, 8000)
        );
        // 30 of 31 committed: one line's files, the surface of all 31, the fixed part.
        assert_eq!(
            remaining_scan_bytes(31, 30, 8000),
            8000 * 48 + 8192 + 31 * 8000 * 125 + 4 * 1024 * 1024
        );
        // All committed: the surface and report only.
        assert_eq!(
            remaining_scan_bytes(31, 31, 8000),
            31 * 8000 * 125 + 4 * 1024 * 1024
        );
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
