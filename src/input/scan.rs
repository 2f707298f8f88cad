//! A scan directory read back as a grid: its complete lines (both `NNNN.csv` and
//! `NNNN.json`), each checked against the SHA-256 its journal record holds before it is read.
//! A line file changed since it was traced (a bit flip, an edit), a line the journal never
//! committed, one that cannot be read and one with only one of its two files are left out and
//! named, never characterised as measured: one bad line does not take down the others. A file
//! that matches its record and still cannot be read is an error naming it. Without a readable
//! journal every complete line is read as it is.
//!
//! The runner hands over its completed scan's lines in memory; [`grid_of_lines`] makes the
//! same grid of them.
//!
//! Layer 4 (reading at the process edge): depends on [`crate::scan`] (its store, journal and
//! line types) and [`crate::grid`].

use super::InputError;
use crate::grid::{Grid, LeftOut};
use crate::scan::faults::NoFaults;
use crate::scan::journal::{read_journal, ResumeState, StopStatus, JOURNAL_FILE};
use crate::scan::line::StoredLine;
use crate::scan::store::{csv_name, ScanStore};
use std::path::Path;
use std::sync::Arc;

/// Why a complete line of a scan is left out: its journal does not vouch for it as it is.
#[derive(Debug, Clone, PartialEq)]
pub enum NotVouched {
    /// On disk, but the journal never committed it (the scan stopped before its record).
    Uncommitted,
    /// Its heights file differs from its journal record.
    Changed {
        /// The file's SHA-256.
        file_sha256: String,
        /// The journal's.
        journal_sha256: String,
    },
    /// Its heights file cannot be read (a bad sector, no permission), with why.
    Unreadable(String),
}

impl NotVouched {
    /// The reason in a few words, as the IGES Start section and `fit --report` give it.
    pub fn short(&self) -> &'static str {
        match self {
            NotVouched::Uncommitted => "never committed to the journal",
            NotVouched::Changed { .. } => "changed after it was traced",
            NotVouched::Unreadable(_) => "cannot be read",
        }
    }
}

/// A scan's line left out, as the grid lists it.
fn left_out(index: u32, why: &str) -> LeftOut {
    LeftOut {
        line: crate::numfmt::line_number(index),
        file: Some(csv_name(index)),
        why: why.to_string(),
    }
}

/// Line indices as a person reads them: 1-based, each with the heights file it is stored
/// in, `21 (0020.csv), 22 (0021.csv)`.
pub fn line_files(indices: &[u32]) -> String {
    indices
        .iter()
        .map(|&i| format!("{} ({})", crate::numfmt::line_number(i), csv_name(i)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The warning for `count` lines (`list`) on disk that the journal never committed.
pub fn uncommitted_lines_warning(list: &str, count: usize) -> String {
    let (noun, are, them, their, were) = if count == 1 {
        ("line", "is", "it", "its", "it was")
    } else {
        ("lines", "are", "them", "their", "they were")
    };
    format!(
        "{noun} {list} {are} on disk but the journal never committed {them} (the scan stopped before {their} record); {were} left out"
    )
}

/// Checks the heights file of each line of `index` in `store` against the SHA-256 its
/// journal record holds (`state`): the lines without a record, whose file changed since, or
/// whose file cannot be read, each with why. A journal that cannot be read vouches for
/// nothing and leaves nothing out.
fn not_vouched(
    store: &ScanStore,
    state: Option<&ResumeState>,
    index: &[u32],
) -> Vec<(u32, NotVouched)> {
    let Some(state) = state else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for &i in index {
        let Some(record) = state.lines.iter().find(|l| l.id.index == i) else {
            out.push((i, NotVouched::Uncommitted));
            continue;
        };
        let why = match store.heights_sha256(i) {
            Ok(sha) if sha == record.csv_sha256 => continue,
            Ok(sha) => NotVouched::Changed {
                file_sha256: sha,
                journal_sha256: record.csv_sha256.clone(),
            },
            Err(e) => NotVouched::Unreadable(e.to_string()),
        };
        out.push((i, why));
    }
    out
}

/// How many lines of scan directory `dir` have both their files (0 when it is not a scan
/// directory): a count, without reading a line.
pub fn complete_line_count(dir: &Path) -> usize {
    ScanStore::open(dir, Arc::new(NoFaults))
        .and_then(|s| s.stored_indices())
        .map_or(0, |(complete, _)| complete.len())
}

/// The lines of a scan directory that its journal vouches for, read after their check.
#[derive(Debug)]
pub struct VouchedLines {
    /// The complete lines whose heights file is as the journal recorded it (every complete
    /// line when the journal cannot be read), in index order.
    pub lines: Vec<StoredLine>,
    /// Indices with only one of their two files (not read).
    pub incomplete: Vec<u32>,
    /// The complete lines the journal does not vouch for (not read), each with why.
    pub not_vouched: Vec<(u32, NotVouched)>,
    /// The journal, or why it cannot be read.
    pub journal: Result<ResumeState, crate::scan::journal::JournalError>,
}

impl VouchedLines {
    /// The warnings for the lines the journal does not vouch for, in the operator's words,
    /// each naming what to do.
    pub fn warnings(&self, lines_dir: &Path) -> Vec<String> {
        let uncommitted: Vec<u32> = self
            .not_vouched
            .iter()
            .filter(|(_, why)| *why == NotVouched::Uncommitted)
            .map(|(i, _)| *i)
            .collect();
        let mut out = Vec::new();
        if !uncommitted.is_empty() {
            out.push(uncommitted_lines_warning(
                &line_files(&uncommitted),
                uncommitted.len(),
            ));
        }
        let file = |i: u32| lines_dir.join(csv_name(i));
        // The changed lines first, then the unreadable ones.
        for (i, why) in &self.not_vouched {
            if let NotVouched::Changed {
                file_sha256,
                journal_sha256,
            } = why
            {
                out.push(format!(
                    "line {} ({}) was changed after it was traced: its SHA-256 {file_sha256} differs from the journal's {journal_sha256}; it was left out (restore the file to use it, or fit the edited heights as a grid CSV)",
                    crate::numfmt::line_number(*i),
                    file(*i).display()
                ));
            }
        }
        for (i, why) in &self.not_vouched {
            if let NotVouched::Unreadable(e) = why {
                out.push(format!(
                    "line {} ({}) cannot be read ({e}); it was left out (check the disk and the file's permissions)",
                    crate::numfmt::line_number(*i),
                    file(*i).display()
                ));
            }
        }
        out
    }

    /// Every line left out, incomplete or not vouched for, in line order.
    pub fn left_out(&self) -> Vec<LeftOut> {
        let mut out: Vec<LeftOut> = self
            .incomplete
            .iter()
            .map(|&i| left_out(i, "one of its two files missing"))
            .chain(
                self.not_vouched
                    .iter()
                    .map(|(i, why)| left_out(*i, why.short())),
            )
            .collect();
        out.sort_by_key(|l| l.line);
        out
    }

    /// The scan stopped with success, by its journal.
    pub fn completed(&self) -> bool {
        self.journal.as_ref().is_ok_and(|s| {
            s.stop
                .as_ref()
                .is_some_and(|s| s.status == StopStatus::Success)
        })
    }
}

/// The complete lines of scan directory `dir` checked against its journal before they are
/// read: a line file changed since it was traced (a bit flip, an
/// edit) or never committed is left out and named, never characterised as measured, and
/// one bad line does not take down the others. A file that matches its record and still
/// cannot be read is an error naming it. Without a readable journal every complete line is
/// read as it is.
pub fn load_vouched_lines(dir: &Path) -> Result<VouchedLines, InputError> {
    if !dir.join("lines").is_dir() {
        return Err(InputError::Lines {
            path: dir.to_path_buf(),
            reason: "is not a scan directory: it has no lines/ folder (a scan holds lines/NNNN.csv + NNNN.json and journal.jsonl)".to_string(),
        });
    }
    let store = ScanStore::open(dir, Arc::new(NoFaults))?;
    let (complete, incomplete) = store.stored_indices()?;
    let complete: Vec<u32> = complete.into_iter().collect();
    let journal = read_scan_journal(dir);
    let not_vouched = not_vouched(&store, journal.as_ref().ok(), &complete);
    let lines = complete
        .iter()
        .filter(|&&i| !not_vouched.iter().any(|(j, _)| *j == i))
        .map(|&i| store.load_line(i))
        .collect::<Result<Vec<_>, _>>()?;
    let vouched = VouchedLines {
        lines,
        incomplete: incomplete.into_iter().collect(),
        not_vouched,
        journal,
    };
    if vouched.lines.is_empty() {
        return Err(if complete.is_empty() {
            InputError::NoLines {
                dir: dir.to_path_buf(),
                incomplete: vouched.incomplete,
            }
        } else {
            InputError::Lines {
                path: dir.to_path_buf(),
                reason: format!(
                    "no line is as its journal recorded it: {}",
                    vouched.warnings(&dir.join("lines")).join("; ")
                ),
            }
        });
    }
    Ok(vouched)
}

/// The journal of a scan directory, when it can be read.
pub fn read_scan_journal(dir: &Path) -> Result<ResumeState, crate::scan::journal::JournalError> {
    let path = dir.join(JOURNAL_FILE);
    read_journal(&path).and_then(|rec| ResumeState::from_records(&path, &rec.records))
}

/// The warning for `count` lines (listed in `list`) that have only one of their two files in
/// `lines_dir` and were left out, in the singular for one.
pub fn incomplete_lines_warning(list: &str, count: usize, lines_dir: &Path) -> String {
    let (noun, has, their, were) = if count == 1 {
        ("line", "has", "its", "was")
    } else {
        ("lines", "have", "their", "were")
    };
    format!(
        "{noun} {list} {has} only one of {their} two files in {} and {were} left out",
        lines_dir.display()
    )
}

/// The grid of a scan's `lines` (in index order), nothing left out. Every line must have the
/// same number of points and the same x pitch (they are one grid); a line that differs is
/// named by its heights file in `lines_dir`.
pub fn grid_of_lines(lines: &[StoredLine], lines_dir: &Path) -> Result<Grid, InputError> {
    let Some(first) = lines.first() else {
        return Err(InputError::NoLines {
            dir: lines_dir.parent().unwrap_or(lines_dir).to_path_buf(),
            incomplete: Vec::new(),
        });
    };
    let (cols, px) = (first.meta.id.points, first.meta.profile.pitch_x_mm);
    let mut heights_um = Vec::with_capacity(cols * lines.len());
    for l in lines {
        let path = lines_dir.join(csv_name(l.meta.id.index));
        if l.meta.id.points != cols {
            return Err(InputError::Lines {
                path,
                reason: format!(
                    "has {} points, line {} has {cols}; every line of a scan must have the same number of points to form a grid",
                    l.meta.id.points, first.meta.id.index
                ),
            });
        }
        if (l.meta.profile.pitch_x_mm - px).abs() > 1e-12 * px.abs().max(1.0) {
            return Err(InputError::Lines {
                path,
                reason: format!(
                    "pitch x {} mm differs from line {}'s {px} mm; every line of a scan must share the x pitch",
                    l.meta.profile.pitch_x_mm, first.meta.id.index
                ),
            });
        }
        heights_um.extend_from_slice(&l.profile.heights_um);
    }
    Ok(Grid {
        heights_um,
        cols,
        pitch_x_mm: px,
        x0_mm: 0.0,
        y_mm: lines.iter().map(StoredLine::y_mm).collect(),
        index: lines.iter().map(|l| l.meta.id.index).collect(),
        y_readback_mm: lines
            .iter()
            .map(|l| l.meta.id.y_readback_nm.map(|n| n.to_mm()))
            .collect(),
        instrument: Some(lines.iter().map(|l| l.meta.results.clone()).collect()),
        standard: lines
            .iter()
            .map(|l| l.meta.profile.conditions.standard.clone())
            .collect(),
        readout_warnings: lines
            .iter()
            .map(|l| l.meta.readout_warnings.clone())
            .collect(),
        left_out: Vec::new(),
    })
}

/// Scan directory `dir` as a grid of the lines its journal vouches for, the lines left out
/// listed in the grid, with what was read (the lines, the journal) and the reader's warnings.
pub fn read_scan(dir: &Path) -> Result<(Grid, VouchedLines, Vec<String>), InputError> {
    let vouched = load_vouched_lines(dir)?;
    let lines_dir = dir.join("lines");
    let mut grid = grid_of_lines(&vouched.lines, &lines_dir)?;
    grid.left_out = vouched.left_out();
    let mut findings = vouched.warnings(&lines_dir);
    if !vouched.incomplete.is_empty() {
        findings.push(incomplete_lines_warning(
            &line_files(&vouched.incomplete),
            vouched.incomplete.len(),
            &lines_dir,
        ));
    }
    if let Err(e) = &vouched.journal {
        findings.push(format!(
            "no traceability: the journal cannot be used ({e}); the line files are used as they are, unchecked"
        ));
    }
    Ok((grid, vouched, findings))
}

#[cfg(test)]
mod tests {

    #[test]
    fn lines_the_journal_never_committed_are_counted_in_the_warning() {
        assert_eq!(
            super::uncommitted_lines_warning("21 (0020.csv)", 1),
            "line 21 (0020.csv) is on disk but the journal never committed it (the scan stopped before its record); it was left out"
        );
        assert_eq!(
            super::uncommitted_lines_warning("21, 22", 2),
            "lines 21, 22 are on disk but the journal never committed them (the scan stopped before their record); they were left out"
        );
    }

    #[test]
    fn a_single_incomplete_line_is_named_in_the_singular() {
        let d = std::path::Path::new("/scan/lines");
        assert_eq!(
            super::incomplete_lines_warning("6 (0005.csv)", 1, d),
            "line 6 (0005.csv) has only one of its two files in /scan/lines and was left out"
        );
        assert_eq!(
            super::incomplete_lines_warning("6, 7", 2, d),
            "lines 6, 7 have only one of their two files in /scan/lines and were left out"
        );
    }
}
