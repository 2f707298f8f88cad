//! The paper's incremental NURBS surface interpolation (section 2): chord-length parameters averaged over rows and columns, averaged knots, banded collocation solves.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`], [`crate::units`], [`crate::profile`]; no I/O, no tokio.
//!
//! The algorithm is P&T A9.3/A9.4 exactly as `geomdl.fitting.interpolate_surface` does it.
//! Data point Q(k, l) = (k·pitch, y_l, z_kl / 1000) in mm, k = column (u, x), l = row (v, y);
//! every distance, including the chord lengths that define the parameters, is in mm.
//!
//! * Parameters along u: per row, cumulative 3-D chord lengths normalised to [0, 1], averaged
//!   over rows; along v likewise per column, averaged over columns.
//! * Knots by averaging (P&T eq. 9.8), clamped.
//! * The collocation matrix of each direction is the same for every line (the parameters are
//!   averaged), so it is factored once (banded LU without pivoting; totally positive) and
//!   applied to every row (u), then to every column (v, streaming over whole rows).
//! * z goes through both solves. x depends only on u and y only on v, and B-splines sum to
//!   one, so the x poles are the 1-D solve of the x values along u (the same for every row)
//!   and the y poles the 1-D solve of the y values along v. This equals the two-direction
//!   solve up to rounding.
//!
//! [`IncrementalFitter::push_line`] does each line's share on arrival (validation, row
//! parameters, running sums, column chord accumulation); [`IncrementalFitter::finish`] only
//! what needs all lines. [`fit_grid`] goes through the same path, so an incremental fit is
//! bit-identical to a batch fit of the same data.
//!
//! Speed without changing a bit: the hot loops run in one AVX2 dispatch (`simd`, no FMA,
//! so each lane does the scalar IEEE operations in the scalar order), the u solves run eight
//! rows interleaved, and the large stores and the pole net are advised for huge pages
//! (`memory`) so their first touch does not cost a page fault per 4 KiB.

pub mod approx_v;
mod banded;
mod memory;
mod simd;

pub use approx_v::{fit_grid_with, MethodError, VMethod};
pub use banded::{BandLu, ZeroPivot};

use memory::{advise_huge_pages, zeroed_huge};

use crate::nurbs::{NurbsSurface, SurfaceError};
use crate::profile::Profile;
use std::time::Instant;
use thiserror::Error;

/// Degrees of the fitted surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FitOptions {
    /// Degree along u (x, columns). The paper uses 5.
    pub degree_u: usize,
    /// Degree along v (y, rows). The paper uses 5.
    pub degree_v: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            degree_u: 5,
            degree_v: 5,
        }
    }
}

/// Why a grid cannot be interpolated. Every variant carries the offending numbers.
#[derive(Debug, Error, PartialEq)]
pub enum FitError {
    /// A degree is zero.
    #[error(
        "degrees must be at least 1 (got u={degree_u}, v={degree_v}); use 5/5 as in the paper"
    )]
    InvalidDegree {
        /// Degree along u.
        degree_u: usize,
        /// Degree along v.
        degree_v: usize,
    },
    /// A line has a different number of points than the first line.
    #[error("line {line} has {got} points but the first line had {expected}; all lines must have the same length")]
    RowLength {
        /// Line index (0-based).
        line: usize,
        /// Points in this line.
        got: usize,
        /// Points in the first line.
        expected: usize,
    },
    /// A height is NaN or infinite.
    #[error(
        "line {line}, point {index}: height {value} µm is not finite; re-measure or drop the line"
    )]
    NonFinite {
        /// Line index.
        line: usize,
        /// Point index within the line.
        index: usize,
        /// The value.
        value: f64,
    },
    /// A line's y position is NaN or infinite.
    #[error("line {line}: y = {y_mm} mm is not finite")]
    NonFiniteY {
        /// Line index.
        line: usize,
        /// The value.
        y_mm: f64,
    },
    /// The lines' y positions are not strictly monotone (repeated or reversed).
    #[error("line {line}: y = {y_mm} mm does not continue the strictly monotone order after {previous_y_mm} mm")]
    LineOrder {
        /// Line index.
        line: usize,
        /// Its y.
        y_mm: f64,
        /// y of the previous line.
        previous_y_mm: f64,
    },
    /// The x pitch is not a positive finite number.
    #[error("line {line}: x pitch {pitch_x_mm} mm must be positive and finite")]
    BadPitch {
        /// Line index.
        line: usize,
        /// The pitch.
        pitch_x_mm: f64,
    },
    /// The x pitch differs from the first line's.
    #[error("line {line}: x pitch {got} mm differs from the first line's {expected} mm; all lines must share one pitch")]
    PitchMismatch {
        /// Line index.
        line: usize,
        /// Its pitch.
        got: f64,
        /// The first line's pitch.
        expected: f64,
    },
    /// Fewer lines than degree_v + 1.
    #[error("{got} lines is fewer than degree_v + 1 = {need}; trace more lines or lower degree_v")]
    TooFewRows {
        /// Lines so far.
        got: usize,
        /// Lines needed.
        need: usize,
    },
    /// Fewer points per line than degree_u + 1.
    #[error("{got} points per line is fewer than degree_u + 1 = {need}; lower degree_u or measure longer lines")]
    TooFewColumns {
        /// Points per line.
        got: usize,
        /// Points needed.
        need: usize,
    },
    /// Two consecutive points coincide (zero chord), so chord-length parameters are undefined.
    #[error("{direction} direction, line {line}, point {index}: zero chord length to the previous point ({previous:?} → {point:?} mm); remove duplicate points")]
    CoincidentPoints {
        /// "u" (along a line) or "v" (across lines, within a column).
        direction: &'static str,
        /// Line index (row).
        line: usize,
        /// Point index (column).
        index: usize,
        /// The previous point (x, y, z) in mm.
        previous: [f64; 3],
        /// The point (x, y, z) in mm.
        point: [f64; 3],
    },
    /// A chord length overflowed (heights or positions far too large).
    #[error("{direction} direction, line {line}, point {index}: chord length {chord} mm is not finite; check units of the heights (µm) and positions (mm)")]
    ChordOverflow {
        /// "u" or "v".
        direction: &'static str,
        /// Line index.
        line: usize,
        /// Point index.
        index: usize,
        /// The chord.
        chord: f64,
    },
    /// `fit_grid` was given a height array that is not rows × cols.
    #[error("grid has {len} heights, expected {rows} rows × {cols} columns")]
    GridShape {
        /// Heights given.
        len: usize,
        /// Rows (y values given).
        rows: usize,
        /// Columns given.
        cols: usize,
    },
    /// A zero or non-finite pivot in the collocation factorisation.
    #[error("{direction} collocation matrix has pivot {pivot} at row {index}; the parameters are degenerate")]
    SingularCollocation {
        /// "u" or "v".
        direction: &'static str,
        /// Row.
        index: usize,
        /// Pivot value.
        pivot: f64,
    },
    /// The assembled surface failed its invariants.
    #[error("fitted surface is invalid: {0}")]
    Surface(#[from] SurfaceError),
}

/// Seconds spent per stage of a fit.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FitTimings {
    /// Chord lengths and parameters (summed over `push_line` calls plus the final averaging).
    pub params_s: f64,
    /// Knot vectors, collocation matrices and their factorisations.
    pub knots_factor_s: f64,
    /// Solves along u (one per row).
    pub solve_u_s: f64,
    /// Solves along v (all columns at once) and assembly of the control net.
    pub solve_v_s: f64,
}

impl FitTimings {
    /// Sum of all stages.
    pub fn total_s(&self) -> f64 {
        self.params_s + self.knots_factor_s + self.solve_u_s + self.solve_v_s
    }
}

/// A fitted surface with its data parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct FitResult {
    /// The interpolating surface (mm).
    pub surface: NurbsSurface,
    /// Averaged parameters ū_k of the columns.
    pub params_u: Vec<f64>,
    /// Averaged parameters v̄_l of the rows.
    pub params_v: Vec<f64>,
    /// Time per stage.
    pub timings: FitTimings,
}

/// Accumulates traced lines and fits the paper's surface through them.
#[derive(Debug, Clone)]
pub struct IncrementalFitter {
    options: FitOptions,
    cols: usize,
    pitch_x_mm: f64,
    y_mm: Vec<f64>,
    /// Heights in mm, row-major.
    z_mm: Vec<f64>,
    /// Σ over rows of each row's normalised cumulative chord, per column.
    sum_u: Vec<f64>,
    /// Cumulative chord along v per column, row-major (row 0 is zeros).
    cum_v: Vec<f64>,
    /// Scratch for one row's chords, then its cumulative chords.
    scratch: Vec<f64>,
    params_s: f64,
}

fn secs(t: Instant) -> f64 {
    t.elapsed().as_secs_f64()
}

impl IncrementalFitter {
    /// A fitter with no lines.
    pub fn new(options: FitOptions) -> Self {
        IncrementalFitter {
            options,
            cols: 0,
            pitch_x_mm: 0.0,
            y_mm: Vec::new(),
            z_mm: Vec::new(),
            sum_u: Vec::new(),
            cum_v: Vec::new(),
            scratch: Vec::new(),
            params_s: 0.0,
        }
    }

    /// Reserves room for `lines` more lines of `cols` points (avoids regrowing the stores when
    /// the scan size is known).
    pub fn reserve_lines(&mut self, lines: usize, cols: usize) {
        self.z_mm.reserve(lines.saturating_mul(cols));
        advise_huge_pages(&self.z_mm);
        self.cum_v.reserve(lines.saturating_mul(cols));
        advise_huge_pages(&self.cum_v);
        self.y_mm.reserve(lines);
    }

    /// Adds a traced line at `y_mm` (see [`IncrementalFitter::push_row`]).
    pub fn push_line(&mut self, y_mm: f64, profile: &Profile) -> Result<(), FitError> {
        self.push_row(y_mm, profile.pitch_x_mm, &profile.heights_um)
    }

    /// Adds a line of heights (µm) at `y_mm` with x pitch `pitch_x_mm`: validates it, computes
    /// its chord-length parameters and adds them to the running sums, accumulates the chords
    /// to the previous line per column, and stores z in mm. On error nothing is changed.
    pub fn push_row(
        &mut self,
        y_mm: f64,
        pitch_x_mm: f64,
        heights_um: &[f64],
    ) -> Result<(), FitError> {
        simd::wide(|| self.push_row_kernel(y_mm, pitch_x_mm, heights_um))
    }

    /// The body of [`IncrementalFitter::push_row`], inlined into the SIMD dispatch.
    #[inline(always)]
    fn push_row_kernel(
        &mut self,
        y_mm: f64,
        pitch_x_mm: f64,
        heights_um: &[f64],
    ) -> Result<(), FitError> {
        let start = Instant::now();
        let line = self.y_mm.len();
        let FitOptions { degree_u, degree_v } = self.options;
        if degree_u == 0 || degree_v == 0 {
            return Err(FitError::InvalidDegree { degree_u, degree_v });
        }
        if !(pitch_x_mm.is_finite() && pitch_x_mm > 0.0) {
            return Err(FitError::BadPitch { line, pitch_x_mm });
        }
        if !y_mm.is_finite() {
            return Err(FitError::NonFiniteY { line, y_mm });
        }
        let n = heights_um.len();
        if line == 0 {
            if n < degree_u + 1 {
                return Err(FitError::TooFewColumns {
                    got: n,
                    need: degree_u + 1,
                });
            }
        } else {
            if n != self.cols {
                return Err(FitError::RowLength {
                    line,
                    got: n,
                    expected: self.cols,
                });
            }
            if (pitch_x_mm - self.pitch_x_mm).abs() > 1e-9 * self.pitch_x_mm {
                return Err(FitError::PitchMismatch {
                    line,
                    got: pitch_x_mm,
                    expected: self.pitch_x_mm,
                });
            }
            let prev = self.y_mm[line - 1];
            let increasing = if line >= 2 {
                self.y_mm[1] > self.y_mm[0]
            } else {
                y_mm > prev
            };
            if y_mm == prev || (y_mm > prev) != increasing {
                return Err(FitError::LineOrder {
                    line,
                    y_mm,
                    previous_y_mm: prev,
                });
            }
        }
        // The row is written straight into the stores (heights in mm, cumulative column
        // chords) and the stores are truncated back if a check fails, so on error nothing is
        // changed and on success no copy is needed. Each pass below is branch-free so it
        // vectorises; the checks only accumulate flags, and the culprit is located afterwards
        // in the order: non-finite height, u chord, u total, v chord, v cumulative chord.
        let pitch = if line == 0 {
            pitch_x_mm
        } else {
            self.pitch_x_mm
        };
        let base = line * n;
        debug_assert_eq!(self.z_mm.len(), base);

        // Heights in mm, once (the division, not a multiplication by 1e-3, fixes the bits).
        grow_for_row(&mut self.z_mm, n);
        grow_for_row(&mut self.cum_v, n);
        let mut non_finite = false;
        self.z_mm.extend(heights_um.iter().map(|&h| {
            non_finite |= !h.is_finite();
            h / 1000.0
        }));
        if non_finite {
            self.z_mm.truncate(base);
            let index = heights_um.iter().position(|h| !h.is_finite()).unwrap_or(0);
            return Err(FitError::NonFinite {
                line,
                index,
                value: heights_um.get(index).copied().unwrap_or(f64::NAN),
            });
        }

        // One pass over the row: the chord along u to the left neighbour (3-D, mm) and, from
        // the second line on, the chord along v to the previous line in the same column added
        // to that column's cumulative chord. Per value the operations are the same as
        // computing the two chord rows separately, so the bits are too.
        let p2 = pitch * pitch;
        self.scratch.clear();
        self.scratch.resize(n, 0.0);
        let (bad_u, bad_v, bad_cum, dy2) = {
            let (stored, zrow) = self.z_mm.split_at(base);
            let mut bad_u = false;
            for ((d, &z1), &z0) in self.scratch[1..].iter_mut().zip(&zrow[1..]).zip(zrow) {
                let dz = z1 - z0;
                *d = (p2 + dz * dz).sqrt();
                bad_u |= (*d == 0.0) | !d.is_finite();
            }
            if line == 0 {
                self.cum_v.resize(n, 0.0);
                (bad_u, false, false, 0.0)
            } else {
                let dy = y_mm - self.y_mm[line - 1];
                let dy2 = dy * dy;
                let prev_row = &stored[base - n..];
                let (bad_v, bad_cum) = extend_column_chords(&mut self.cum_v, zrow, prev_row, dy2);
                (bad_u, bad_v, bad_cum, dy2)
            }
        };
        let mut acc = 0.0;
        if !bad_u {
            // Cumulative u chords: a serial sum, in index order.
            for d in self.scratch.iter_mut() {
                acc += *d;
                *d = acc;
            }
        }
        if bad_u || !acc.is_finite() || bad_v || bad_cum {
            let err = self.row_error(line, y_mm, pitch, dy2, bad_u, acc, bad_v);
            self.z_mm.truncate(base);
            self.cum_v.truncate(base);
            return Err(err);
        }

        // Commit: nothing below can fail.
        if line == 0 {
            self.cols = n;
            self.pitch_x_mm = pitch_x_mm;
            self.sum_u = vec![0.0; n];
        }
        let total = acc;
        for (s, &c) in self.sum_u.iter_mut().zip(&self.scratch) {
            *s += c / total;
        }
        self.y_mm.push(y_mm);
        self.params_s += secs(start);
        Ok(())
    }

    /// The error for a row whose checks failed in [`IncrementalFitter::push_row`], with the
    /// row still in the stores (`z_mm` and `cum_v` hold it as their last `n` values) and the
    /// u chords in `scratch` (cumulated only when they were all valid). Reports the first
    /// failure in the order: u chord, u total, v chord, v cumulative chord.
    #[allow(clippy::too_many_arguments)]
    #[cold]
    fn row_error(
        &self,
        line: usize,
        y_mm: f64,
        pitch: f64,
        dy2: f64,
        bad_u: bool,
        acc: f64,
        bad_v: bool,
    ) -> FitError {
        let n = self.scratch.len();
        let base = line * n;
        let zrow = &self.z_mm[base..base + n];
        if bad_u {
            let k = self.scratch[1..]
                .iter()
                .position(|&d| d == 0.0 || !d.is_finite())
                .unwrap_or(0)
                + 1;
            return Self::chord_error(
                "u",
                line,
                k,
                self.scratch[k],
                [(k - 1) as f64 * pitch, y_mm, zrow[k - 1]],
                [k as f64 * pitch, y_mm, zrow[k]],
            );
        }
        if !acc.is_finite() {
            return FitError::ChordOverflow {
                direction: "u",
                line,
                index: n - 1,
                chord: acc,
            };
        }
        let prev_y = self.y_mm[line - 1];
        let prev_row = &self.z_mm[base - n..base];
        if bad_v {
            let chord = |k: usize| {
                let dz = zrow[k] - prev_row[k];
                (dy2 + dz * dz).sqrt()
            };
            let k = (0..n)
                .position(|k| {
                    let d = chord(k);
                    d == 0.0 || !d.is_finite()
                })
                .unwrap_or(0);
            let x = k as f64 * pitch;
            return Self::chord_error(
                "v",
                line,
                k,
                chord(k),
                [x, prev_y, prev_row[k]],
                [x, y_mm, zrow[k]],
            );
        }
        let cum = &self.cum_v[base..base + n];
        let k = cum.iter().position(|c| !c.is_finite()).unwrap_or(0);
        FitError::ChordOverflow {
            direction: "v",
            line,
            index: k,
            chord: cum[k],
        }
    }

    fn chord_error(
        direction: &'static str,
        line: usize,
        index: usize,
        chord: f64,
        previous: [f64; 3],
        point: [f64; 3],
    ) -> FitError {
        if chord == 0.0 {
            FitError::CoincidentPoints {
                direction,
                line,
                index,
                previous,
                point,
            }
        } else {
            FitError::ChordOverflow {
                direction,
                line,
                index,
                chord,
            }
        }
    }

    /// Number of lines pushed so far.
    pub fn lines(&self) -> usize {
        self.y_mm.len()
    }

    /// Points per line (0 before the first line).
    pub fn columns(&self) -> usize {
        self.cols
    }

    /// The surface through the lines so far (needs at least `degree_v + 1` lines), for a live
    /// preview. The fitter is unchanged and the result equals what [`IncrementalFitter::finish`]
    /// would give now.
    pub fn provisional(&self) -> Result<FitResult, FitError> {
        self.check_ready()?;
        let mut z = Vec::with_capacity(self.z_mm.len());
        advise_huge_pages(&z);
        z.extend_from_slice(&self.z_mm);
        self.solve(z)
    }

    /// The surface through all lines.
    pub fn finish(mut self) -> Result<FitResult, FitError> {
        self.check_ready()?;
        let z = std::mem::take(&mut self.z_mm);
        self.solve(z)
    }

    fn check_ready(&self) -> Result<(), FitError> {
        let FitOptions { degree_u, degree_v } = self.options;
        if degree_u == 0 || degree_v == 0 {
            return Err(FitError::InvalidDegree { degree_u, degree_v });
        }
        let rows = self.lines();
        if rows < degree_v + 1 {
            return Err(FitError::TooFewRows {
                got: rows,
                need: degree_v + 1,
            });
        }
        Ok(())
    }

    /// Averages, knots, factorisations and solves; `z` is the row-major height grid in mm and
    /// becomes the z coordinates of the poles.
    fn solve(&self, mut z: Vec<f64>) -> Result<FitResult, FitError> {
        let FitOptions {
            degree_u: p,
            degree_v: q,
        } = self.options;
        let (rows, cols) = (self.lines(), self.cols);
        let mut timings = FitTimings {
            params_s: self.params_s,
            ..FitTimings::default()
        };

        let t = Instant::now();
        let params_u = average_params_u(&self.sum_u, rows);
        let params_v = simd::wide(|| average_params_v(&self.cum_v, rows, cols));
        timings.params_s += secs(t);

        let t = Instant::now();
        let knots_u = averaged_knots(&params_u, p);
        let knots_v = averaged_knots(&params_v, q);
        let lu_u = BandLu::collocation(p, &knots_u, &params_u).map_err(|e| {
            FitError::SingularCollocation {
                direction: "u",
                index: e.index,
                pivot: e.pivot,
            }
        })?;
        let lu_v = BandLu::collocation(q, &knots_v, &params_v).map_err(|e| {
            FitError::SingularCollocation {
                direction: "v",
                index: e.index,
                pivot: e.pivot,
            }
        })?;
        timings.knots_factor_s = secs(t);

        let t = Instant::now();
        lu_u.solve_each_row(&mut z);
        let mut px: Vec<f64> = (0..cols).map(|k| k as f64 * self.pitch_x_mm).collect();
        lu_u.solve_in_place(&mut px);
        timings.solve_u_s = secs(t);

        let t = Instant::now();
        let mut py = self.y_mm.clone();
        lu_v.solve_in_place(&mut py);
        // Rows of the solution are final last to first; each goes straight into the net.
        let mut poles = zeroed_huge([0.0f64; 3], rows * cols);
        lu_v.solve_rows_in_place_then(&mut z, cols, |j, zrow| {
            let y = py[j];
            for ((out, &zz), &x) in poles[j * cols..(j + 1) * cols]
                .iter_mut()
                .zip(zrow)
                .zip(&px)
            {
                *out = [x, y, zz];
            }
        });
        drop(z);
        let surface = NurbsSurface::try_new(p, q, knots_u, knots_v, cols, rows, poles)?;
        timings.solve_v_s = secs(t);

        Ok(FitResult {
            surface,
            params_u,
            params_v,
            timings,
        })
    }
}

/// Makes room for one more row of `n` values in a row-major store, growing it geometrically
/// and advising the new allocation for huge pages before it is written.
fn grow_for_row(store: &mut Vec<f64>, n: usize) {
    if store.capacity() - store.len() < n {
        store.reserve(n);
        advise_huge_pages(store);
    }
}

/// Appends one row of cumulative column chords to `cum_v` (whose last `zrow.len()` values are
/// the previous line's): chord (√(dy² + Δz²), mm) to the previous line's height plus the
/// previous cumulative value. Returns (some chord is zero or not finite, some cumulative value
/// is not finite); branch-free so it vectorises.
#[inline(always)]
fn extend_column_chords(
    cum_v: &mut Vec<f64>,
    zrow: &[f64],
    prev_row: &[f64],
    dy2: f64,
) -> (bool, bool) {
    let n = zrow.len();
    let base = cum_v.len();
    cum_v.resize(base + n, 0.0);
    let (before, row) = cum_v.split_at_mut(base);
    let prev_cum = &before[base - n..];
    let (mut bad_v, mut bad_cum) = (false, false);
    for (((c, &pc), &z), &pz) in row.iter_mut().zip(prev_cum).zip(zrow).zip(prev_row) {
        let dz = z - pz;
        let d = (dy2 + dz * dz).sqrt();
        bad_v |= (d == 0.0) | !d.is_finite();
        *c = d + pc;
        bad_cum |= !c.is_finite();
    }
    (bad_v, bad_cum)
}

/// ū_k: mean over rows of the normalised cumulative chords; exactly 0 and 1 at the ends.
fn average_params_u(sum_u: &[f64], rows: usize) -> Vec<f64> {
    let r = rows as f64;
    let mut out: Vec<f64> = sum_u.iter().map(|s| s / r).collect();
    if let Some(f) = out.first_mut() {
        *f = 0.0;
    }
    if let Some(l) = out.last_mut() {
        *l = 1.0;
    }
    out
}

/// v̄_l: mean over columns of each column's cumulative chord normalised by its total.
#[inline(always)]
fn average_params_v(cum_v: &[f64], rows: usize, cols: usize) -> Vec<f64> {
    let totals = &cum_v[(rows - 1) * cols..rows * cols];
    let c = cols as f64;
    let mut out: Vec<f64> = cum_v
        .chunks_exact(cols)
        .map(|row| sum_ratios(row, totals) / c)
        .collect();
    if let Some(f) = out.first_mut() {
        *f = 0.0;
    }
    if let Some(l) = out.last_mut() {
        *l = 1.0;
    }
    out
}

/// Σ a_k / t_k with four partial sums (a fixed order, so results are reproducible).
#[inline(always)]
fn sum_ratios(a: &[f64], t: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (a4, t4) = (a.chunks_exact(4), t.chunks_exact(4));
    let (ar, tr) = (a4.remainder(), t4.remainder());
    for (x, y) in a4.zip(t4) {
        for l in 0..4 {
            acc[l] += x[l] / y[l];
        }
    }
    let tail: f64 = ar.iter().zip(tr).map(|(x, y)| x / y).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Clamped knot vector by averaging (P&T eq. 9.8): `degree + 1` zeros,
/// `u_{j+p} = (1/p) Σ_{i=j}^{j+p−1} ū_i` for j = 1..n−p, `degree + 1` ones.
pub fn averaged_knots(params: &[f64], degree: usize) -> Vec<f64> {
    let count = params.len();
    let mut knots = Vec::with_capacity(count + degree + 1);
    knots.extend(std::iter::repeat_n(0.0, degree + 1));
    let inv = 1.0 / degree as f64;
    for j in 1..count.saturating_sub(degree) {
        knots.push(inv * params[j..j + degree].iter().sum::<f64>());
    }
    knots.extend(std::iter::repeat_n(1.0, degree + 1));
    knots
}

/// Fits a whole grid at once: rows are lines at `y_mm`, `heights_um` is row-major
/// `y_mm.len() × cols` in µm. Goes through [`IncrementalFitter`], so the result is
/// bit-identical to pushing the rows one by one.
pub fn fit_grid(
    pitch_x_mm: f64,
    y_mm: &[f64],
    heights_um: &[f64],
    cols: usize,
    options: FitOptions,
) -> Result<FitResult, FitError> {
    let rows = y_mm.len();
    if cols == 0 || heights_um.len() != rows * cols {
        return Err(FitError::GridShape {
            len: heights_um.len(),
            rows,
            cols,
        });
    }
    let mut fitter = IncrementalFitter::new(options);
    fitter.reserve_lines(rows, cols);
    for (row, &y) in heights_um.chunks_exact(cols).zip(y_mm) {
        fitter.push_row(y, pitch_x_mm, row)?;
    }
    fitter.finish()
}

/// Largest distance |S(ū_k, v̄_l) − Q(k, l)| in mm over all data points of the grid the result
/// was fitted to. Returns infinity when the grid's shape does not match the result.
pub fn max_residual_mm(
    result: &FitResult,
    pitch_x_mm: f64,
    y_mm: &[f64],
    heights_um: &[f64],
    cols: usize,
) -> f64 {
    let rows = y_mm.len();
    if cols != result.params_u.len()
        || rows != result.params_v.len()
        || heights_um.len() != rows * cols
    {
        return f64::INFINITY;
    }
    let mut worst = 0.0f64;
    for ((row, &y), &v) in heights_um
        .chunks_exact(cols)
        .zip(y_mm)
        .zip(&result.params_v)
    {
        let pts = result.surface.evaluate_grid(&result.params_u, &[v]);
        for (k, (p, &h)) in pts.iter().zip(row).enumerate() {
            let q = [k as f64 * pitch_x_mm, y, h / 1000.0];
            let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
            worst = worst.max(d);
        }
    }
    worst
}

#[cfg(test)]
mod tests;
