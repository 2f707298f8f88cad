//! The grid of traced lines a report characterises: heights row-major, one row per line,
//! with what is known about each line (index, y, read-back, the instrument's results).
//!
//! Layer 4 (reporting): depends on [`crate::profile`] and [`crate::scan::line`] (a scan's
//! lines, in memory or read back from its directory).

use super::error::ReportError;
use crate::profile::InstrumentResult;
use crate::scan::line::StoredLine;
use crate::scan::store::csv_name;
use std::path::Path;

/// A row-major grid of traced lines to characterise, with what is known about each line.
#[derive(Debug, Clone, PartialEq)]
pub struct LineGrid {
    /// Heights in µm, `y_mm.len() × cols`, row-major.
    pub heights_um: Vec<f64>,
    /// Points per line.
    pub cols: usize,
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// y of each line, mm (increasing).
    pub y_mm: Vec<f64>,
    /// Line index of each row (its `NNNN` in a scan).
    pub index: Vec<u32>,
    /// y read back from the stage, mm, per row when known.
    pub y_readback_mm: Vec<Option<f64>>,
    /// The instrument's results per row (`None`: not a scan, no comparison).
    pub instrument: Option<Vec<Vec<InstrumentResult>>>,
    /// The standard the instrument evaluated each row to (its recorded conditions), which
    /// decides what its `Rz` means.
    pub standard: Vec<Option<String>>,
}

impl LineGrid {
    /// The grid of a scan's lines (in index order). Every line must have the same number of
    /// points and the same x pitch (they are one grid); a line that differs is named by its
    /// heights file in `lines_dir`.
    pub fn of_scan(lines: &[StoredLine], lines_dir: &Path) -> Result<LineGrid, ReportError> {
        let Some(first) = lines.first() else {
            return Err(ReportError::NoLines {
                dir: lines_dir.parent().unwrap_or(lines_dir).to_path_buf(),
                incomplete: Vec::new(),
            });
        };
        let (cols, px) = (first.meta.id.points, first.meta.profile.pitch_x_mm);
        let mut heights_um = Vec::with_capacity(cols * lines.len());
        for l in lines {
            let path = lines_dir.join(csv_name(l.meta.id.index));
            if l.meta.id.points != cols {
                return Err(ReportError::Lines {
                    path,
                    reason: format!(
                        "has {} points, line {} has {cols}; every line of a scan must have the same number of points to form a grid",
                        l.meta.id.points, first.meta.id.index
                    ),
                });
            }
            if (l.meta.profile.pitch_x_mm - px).abs() > 1e-12 * px.abs().max(1.0) {
                return Err(ReportError::Lines {
                    path,
                    reason: format!(
                        "pitch x {} mm differs from line {}'s {px} mm; every line of a scan must share the x pitch",
                        l.meta.profile.pitch_x_mm, first.meta.id.index
                    ),
                });
            }
            heights_um.extend_from_slice(&l.profile.heights_um);
        }
        Ok(LineGrid {
            heights_um,
            cols,
            pitch_x_mm: px,
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
        })
    }

    /// Number of lines.
    pub fn rows(&self) -> usize {
        self.y_mm.len()
    }

    /// The heights of row `r`.
    pub fn row(&self, r: usize) -> &[f64] {
        self.heights_um
            .get(r * self.cols..(r + 1) * self.cols)
            .unwrap_or(&[])
    }

    /// The line index of row `r`.
    pub fn index_of(&self, r: usize) -> u32 {
        self.index.get(r).copied().unwrap_or(r as u32)
    }
}

/// The mean y pitch of the lines, and whether they are equally spaced (within 1 %).
pub fn mean_pitch_y(y_mm: &[f64]) -> (f64, bool) {
    match (y_mm.first(), y_mm.last()) {
        (Some(a), Some(b)) if y_mm.len() >= 2 && b > a => {
            let p = (b - a) / (y_mm.len() - 1) as f64;
            let even = y_mm
                .windows(2)
                .all(|w| matches!(w, [u, v] if ((v - u) - p).abs() <= 0.01 * p));
            (p, even)
        }
        _ => (1.0, true),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_pitch_flags_uneven_lines() {
        assert_eq!(mean_pitch_y(&[0.0, 0.01, 0.02]), (0.01, true));
        let (p, even) = mean_pitch_y(&[0.0, 0.01, 0.03]);
        assert!((p - 0.015).abs() < 1e-15 && !even);
        assert_eq!(mean_pitch_y(&[0.5]), (1.0, true));
    }
}
