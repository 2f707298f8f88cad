//! The grid of traced lines: the one value every input becomes (a scan directory, a grid CSV,
//! an X3P file, a profile CSV as a grid of one line) and every section of the
//! characterisation, the fit and the contact analysis read. Heights in µm, row-major, one row
//! per line used; what is known about each line (its index in the input, its y, the stage's
//! read-back, the instrument's own results, the warnings it was kept with); and each line of the input left out, with why,
//! so that a result made from fewer lines than the input holds says so ("29 of 31 lines").
//!
//! [`crate::input::read`] makes one from a file or a scan directory under one bad-data policy.
//!
//! Layer 0 (vocabulary): depends on [`crate::profile`] (the instrument's results),
//! [`crate::devices`] (a line's read-out warnings) and [`crate::numfmt`] only; no I/O.

use crate::devices::ReadoutWarning;
use crate::profile::InstrumentResult;
use serde::Serialize;

/// A row-major grid of traced lines, with what is known about each line and the lines of the
/// input left out.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Grid {
    /// Heights in µm, `y_mm.len() × cols`, row-major.
    pub heights_um: Vec<f64>,
    /// Points per line.
    pub cols: usize,
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// x of each line's first point, mm: 0 for a scan and a grid CSV, the first x of a
    /// profile CSV, the x axis offset of an X3P file.
    pub x0_mm: f64,
    /// y of each line, mm (increasing).
    pub y_mm: Vec<f64>,
    /// Index of each line in the input: a scan's `NNNN`, a grid CSV's or an X3P file's
    /// 0-based row (its y is the row × the y pitch).
    pub index: Vec<u32>,
    /// y read back from the stage, mm, per line when known.
    pub y_readback_mm: Vec<Option<f64>>,
    /// The instrument's results per line (`None`: not a scan, no comparison).
    pub instrument: Option<Vec<Vec<InstrumentResult>>>,
    /// The standard the instrument evaluated each line to (its recorded conditions), which
    /// decides what its `Rz` means.
    pub standard: Vec<Option<String>>,
    /// The doubts about each line's read-out it was kept with (empty but for a scan's).
    pub readout_warnings: Vec<Vec<ReadoutWarning>>,
    /// The lines of the input that are not in the grid, in input order, each with why.
    pub left_out: Vec<LeftOut>,
}

/// A line of the input that is not in the grid.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LeftOut {
    /// Where a person finds it, 1-based: a scan's line number, a grid CSV's line in the file,
    /// an X3P file's row.
    pub line: u64,
    /// A scan line's heights file (`0005.csv`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// Why, in a few words.
    pub why: String,
}

impl Grid {
    /// A grid of `heights_um` (`y_mm.len()` lines of `cols` points at `pitch_x_mm`), lines
    /// indexed 0, 1, … with nothing else known about them and none left out.
    pub fn new(heights_um: Vec<f64>, cols: usize, pitch_x_mm: f64, y_mm: Vec<f64>) -> Grid {
        let rows = y_mm.len();
        Grid {
            heights_um,
            cols,
            pitch_x_mm,
            x0_mm: 0.0,
            index: (0..rows as u32).collect(),
            y_readback_mm: vec![None; rows],
            instrument: None,
            standard: vec![None; rows],
            readout_warnings: vec![Vec::new(); rows],
            left_out: Vec::new(),
            y_mm,
        }
    }

    /// Number of lines in the grid.
    pub fn rows(&self) -> usize {
        self.y_mm.len()
    }

    /// The heights of row `r`.
    pub fn row(&self, r: usize) -> &[f64] {
        self.heights_um
            .get(r * self.cols..(r + 1) * self.cols)
            .unwrap_or(&[])
    }

    /// x of point `col` of every line, mm, in the input's coordinates (from [`Grid::x0_mm`]):
    /// where every position a report names along x comes from.
    pub fn x_mm(&self, col: usize) -> f64 {
        self.x0_mm + col as f64 * self.pitch_x_mm
    }

    /// Where the grid starts in the input's coordinates, mm: (x of each line's first point,
    /// y of the first line); (0, 0) for a grid without lines.
    pub fn origin_mm(&self) -> (f64, f64) {
        (self.x0_mm, self.y_mm.first().copied().unwrap_or(0.0))
    }

    /// The line index of row `r`.
    pub fn index_of(&self, r: usize) -> u32 {
        self.index.get(r).copied().unwrap_or(r as u32)
    }

    /// Lines the input holds: those in the grid and those left out.
    pub fn lines_in_input(&self) -> usize {
        self.rows() + self.left_out.len()
    }

    /// The grid holds fewer lines than its input: a result made from it is partial.
    pub fn is_partial(&self) -> bool {
        !self.left_out.is_empty()
    }

    /// "29 of 31 lines": the lines used of those the input holds.
    pub fn lines_used(&self) -> String {
        format!("{} of {} lines", self.rows(), self.lines_in_input())
    }

    /// The mean y pitch of the lines, and whether they are equally spaced (within 1 %); 1 mm
    /// and equally spaced for fewer than two lines.
    pub fn mean_pitch_y(&self) -> (f64, bool) {
        mean_pitch_y(&self.y_mm)
    }

    /// Everything but the heights: what is known about the lines and those left out, for a
    /// caller that frees the heights while it still needs the rest.
    pub fn layout(&self) -> Grid {
        Grid {
            heights_um: Vec::new(),
            cols: self.cols,
            pitch_x_mm: self.pitch_x_mm,
            x0_mm: self.x0_mm,
            y_mm: self.y_mm.clone(),
            index: self.index.clone(),
            y_readback_mm: self.y_readback_mm.clone(),
            instrument: self.instrument.clone(),
            standard: self.standard.clone(),
            readout_warnings: self.readout_warnings.clone(),
            left_out: self.left_out.clone(),
        }
    }

    /// Only the rows `keep` (indices into this grid, increasing), with what is known about
    /// them; the lines left out stay as they are.
    pub fn select_rows(&self, keep: &[usize]) -> Grid {
        Grid {
            heights_um: keep
                .iter()
                .flat_map(|&r| self.row(r).iter().copied())
                .collect(),
            cols: self.cols,
            pitch_x_mm: self.pitch_x_mm,
            x0_mm: self.x0_mm,
            y_mm: keep.iter().map(|&r| self.y_mm[r]).collect(),
            index: keep.iter().map(|&r| self.index_of(r)).collect(),
            y_readback_mm: keep.iter().map(|&r| self.y_readback_mm[r]).collect(),
            instrument: self
                .instrument
                .as_ref()
                .map(|i| keep.iter().map(|&r| i[r].clone()).collect()),
            standard: keep.iter().map(|&r| self.standard[r].clone()).collect(),
            readout_warnings: keep
                .iter()
                .map(|&r| self.readout_warnings[r].clone())
                .collect(),
            left_out: self.left_out.clone(),
        }
    }

    /// The warning naming the lines left out (at most ten one by one), or `None` when every
    /// line of the input is in the grid.
    pub fn left_out_warning(&self) -> Option<String> {
        const NAMED: usize = 10;
        if self.left_out.is_empty() {
            return None;
        }
        let named: Vec<String> = self
            .left_out
            .iter()
            .take(NAMED)
            .map(|l| match &l.file {
                Some(f) => format!("line {} ({f}: {})", l.line, l.why),
                None => format!("line {} ({})", l.line, l.why),
            })
            .collect();
        let more = self.left_out.len().saturating_sub(NAMED);
        Some(format!(
            "{} of the input's {} lines cannot be used and were left out (nothing is filled in; the others keep their y): {}{}",
            self.left_out.len(),
            self.lines_in_input(),
            named.join("; "),
            if more > 0 {
                format!("; and {more} more")
            } else {
                String::new()
            }
        ))
    }
}

/// The mean y pitch of lines at `y_mm`, and whether they are equally spaced (within 1 %).
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

    #[test]
    fn a_grid_with_lines_left_out_counts_them_and_names_them() {
        let mut g = Grid::new(vec![1.0, 2.0, 3.0, 4.0], 2, 0.001, vec![0.0, 0.02]);
        assert_eq!(g.lines_used(), "2 of 2 lines");
        assert!(!g.is_partial() && g.left_out_warning().is_none());
        g.left_out.push(LeftOut {
            line: 2,
            file: None,
            why: "3 of its 2 heights are NaN".into(),
        });
        assert!(g.is_partial());
        assert_eq!(g.lines_used(), "2 of 3 lines");
        let w = g.left_out_warning().unwrap();
        assert!(w.starts_with("1 of the input's 3 lines"), "{w}");
        assert!(w.ends_with("line 2 (3 of its 2 heights are NaN)"), "{w}");
        let one = g.select_rows(&[1]);
        assert_eq!(
            (one.heights_um, one.y_mm, one.index),
            (vec![3.0, 4.0], vec![0.02], vec![1])
        );
    }
}
