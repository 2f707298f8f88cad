//! The incremental fitter: each traced line's share of the work on arrival (validation, its
//! chord-length parameters added to the running sums, the column chords to the previous line
//! checked and added to each column's running total, heights stored in mm); the solve after
//! the last line is in `solve.rs`.
//!
//! Only the heights are stored per point: the cumulative column chords that v̄ needs are one
//! row of running totals, and the averaging after the last line recomputes each row's chords
//! from the stored heights with the same operations (so the same bits), instead of holding a
//! second grid of them.
//!
//! Layer 1 (pure logic): depends on [`crate::profile`] and the fit's own modules; no I/O.

use super::memory::advise_huge_pages;
use super::{simd, FitError, FitOptions, FitResult};
use crate::profile::Profile;
use std::time::Instant;

/// Accumulates traced lines and fits the paper's surface through them.
#[derive(Debug, Clone)]
pub struct IncrementalFitter {
    pub(super) options: FitOptions,
    pub(super) cols: usize,
    pub(super) pitch_x_mm: f64,
    pub(super) y_mm: Vec<f64>,
    /// Heights in mm, row-major.
    pub(super) z_mm: Vec<f64>,
    /// Σ over rows of each row's normalised cumulative chord, per column.
    pub(super) sum_u: Vec<f64>,
    /// Cumulative chord along v per column up to the last line (zeros after the first).
    pub(super) cum_v: Vec<f64>,
    /// The next line's cumulative column chords while it is checked.
    pub(super) next_cum_v: Vec<f64>,
    /// Scratch for one row's chords, then its cumulative chords.
    pub(super) scratch: Vec<f64>,
    pub(super) params_s: f64,
}

pub(super) fn secs(t: Instant) -> f64 {
    t.elapsed().as_secs_f64()
}

/// What the checks of one row found, for [`IncrementalFitter::row_error`].
#[derive(Debug, Clone, Copy)]
struct RowChecks {
    /// A chord along u is zero or not finite.
    bad_u: bool,
    /// The cumulative u chord at the row's end (not finite when the chords overflowed).
    u_total: f64,
    /// A chord along v to the previous line is zero or not finite.
    bad_v: bool,
    /// The squared y step to the previous line, mm².
    dy2: f64,
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
            next_cum_v: Vec::new(),
            scratch: Vec::new(),
            params_s: 0.0,
        }
    }

    /// Reserves room for `lines` more lines of `cols` points (avoids regrowing the stores when
    /// the scan size is known).
    pub fn reserve_lines(&mut self, lines: usize, cols: usize) {
        self.z_mm.reserve(lines.saturating_mul(cols));
        advise_huge_pages(&self.z_mm);
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
                (bad_u, false, false, 0.0)
            } else {
                let dy = y_mm - self.y_mm[line - 1];
                let dy2 = dy * dy;
                let prev_row = &stored[base - n..];
                self.next_cum_v.resize(n, 0.0);
                let (bad_v, bad_cum) =
                    next_column_chords(&mut self.next_cum_v, &self.cum_v, zrow, prev_row, dy2);
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
            let checks = RowChecks {
                bad_u,
                u_total: acc,
                bad_v,
                dy2,
            };
            let err = self.row_error(line, y_mm, pitch, checks);
            self.z_mm.truncate(base);
            return Err(err);
        }

        // Commit: nothing below can fail.
        if line == 0 {
            self.cols = n;
            self.pitch_x_mm = pitch_x_mm;
            self.sum_u = vec![0.0; n];
            self.cum_v = vec![0.0; n];
        } else {
            std::mem::swap(&mut self.cum_v, &mut self.next_cum_v);
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
    /// row still in the stores (`z_mm` holds it as its last `n` values, `next_cum_v` its
    /// cumulative column chords) and the u chords in `scratch` (cumulated only when they were
    /// all valid). Reports the first
    /// failure in the order: u chord, u total, v chord, v cumulative chord.
    #[cold]
    fn row_error(&self, line: usize, y_mm: f64, pitch: f64, checks: RowChecks) -> FitError {
        let RowChecks {
            bad_u,
            u_total: acc,
            bad_v,
            dy2,
        } = checks;
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
        let cum = &self.next_cum_v[..n];
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
        let params = self.averaged_params();
        self.solve(z, params)
    }

    /// The surface through all lines.
    pub fn finish(mut self) -> Result<FitResult, FitError> {
        self.check_ready()?;
        let params = self.averaged_params();
        let z = std::mem::take(&mut self.z_mm);
        self.solve(z, params)
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
}

/// Makes room for one more row of `n` values in a row-major store, growing it geometrically
/// and advising the new allocation for huge pages before it is written.
pub(super) fn grow_for_row(store: &mut Vec<f64>, n: usize) {
    if store.capacity() - store.len() < n {
        store.reserve(n);
        advise_huge_pages(store);
    }
}

/// One row of cumulative column chords into `row`: chord (√(dy² + Δz²), mm) to the previous
/// line's height plus the previous cumulative value `prev_cum`. Returns (some chord is zero or
/// not finite, some cumulative value is not finite); branch-free so it vectorises. The
/// averaging of v̄ recomputes the rows with this same function, so their bits agree.
#[inline(always)]
pub(super) fn next_column_chords(
    row: &mut [f64],
    prev_cum: &[f64],
    zrow: &[f64],
    prev_row: &[f64],
    dy2: f64,
) -> (bool, bool) {
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
