//! ISO 25178-2 areal height parameters of a regular height grid after least-squares plane
//! levelling, and the pooled areal material ratio curve Smr(c).
//!
//! Grids are row-major: `rows` traced lines along y, `cols` points along x. Discretisations
//! (ISO 25178-2:2021 Annex D): Sdq from the forward differences, each direction averaged over its
//! own differences; Sdr from the developed area with every cell split into two triangles along
//! each diagonal and the two triangulations averaged (D.3), over the projected area of the
//! (cols − 1)·(rows − 1) cells. Smr(c) pools the lines: at each level the cross-line lengths of
//! all lines (crossings interpolated linearly along x) over their total length.
//!
//! Depends on [`super::bearing`] and [`super::MetrologyError`].

use super::bearing::{curve_between_extremes, material_ratios_pct};
use super::{check_heights, check_pitch, MetrologyError};
use serde::Serialize;
use std::collections::BTreeMap;

/// The areal parameters of a levelled grid (heights in µm, slopes dimensionless).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ArealParams {
    /// Arithmetic mean height.
    #[serde(rename = "Sa_um")]
    pub sa_um: f64,
    /// Root mean square height.
    #[serde(rename = "Sq_um")]
    pub sq_um: f64,
    /// Maximum peak height.
    #[serde(rename = "Sp_um")]
    pub sp_um: f64,
    /// Maximum pit depth.
    #[serde(rename = "Sv_um")]
    pub sv_um: f64,
    /// Maximum height Sp + Sv.
    #[serde(rename = "Sz_um")]
    pub sz_um: f64,
    /// Skewness.
    #[serde(rename = "Ssk")]
    pub ssk: f64,
    /// Kurtosis (3 for a Gaussian).
    #[serde(rename = "Sku")]
    pub sku: f64,
    /// Root mean square gradient.
    #[serde(rename = "Sdq")]
    pub sdq: f64,
    /// Developed interfacial area ratio in %.
    #[serde(rename = "Sdr_pct")]
    pub sdr_pct: f64,
    /// The levelling plane z = a + b·x + c·y removed (a µm, b and c µm/mm, x and y in mm from
    /// the first point).
    pub plane_um: [f64; 3],
    /// Definition id per parameter.
    pub definitions: BTreeMap<String, String>,
}

/// Heights on a regular lattice, borrowed, as the areal parameters read them: the measured
/// grid's lines at their mean y pitch ([`crate::grid::Grid`] holds them), the model sampled,
/// a grid with its spikes bridged.
#[derive(Debug, Clone, Copy)]
pub struct HeightMap<'a> {
    /// Heights in µm, `rows × cols`, row-major.
    pub heights_um: &'a [f64],
    /// Lines along y.
    pub rows: usize,
    /// Points along x.
    pub cols: usize,
    /// Pitch along x in mm.
    pub pitch_x_mm: f64,
    /// Pitch along y in mm.
    pub pitch_y_mm: f64,
}

/// The map of `heights_um`, `rows` × `cols` at pitches `px` and `py` mm: the tests' maps.
#[cfg(test)]
pub(crate) fn test_map(
    heights_um: &[f64],
    rows: usize,
    cols: usize,
    px: f64,
    py: f64,
) -> HeightMap<'_> {
    HeightMap {
        heights_um,
        rows,
        cols,
        pitch_x_mm: px,
        pitch_y_mm: py,
    }
}

impl HeightMap<'_> {
    /// `grid`'s heights, its rows taken `pitch_y_mm` apart (the lines' mean y pitch, or the
    /// one the input states).
    pub fn of(grid: &crate::grid::Grid, pitch_y_mm: f64) -> HeightMap<'_> {
        HeightMap {
            heights_um: &grid.heights_um,
            rows: grid.rows(),
            cols: grid.cols,
            pitch_x_mm: grid.pitch_x_mm,
            pitch_y_mm,
        }
    }

    /// Checks the pitches, and that the heights fill `rows × cols`, each at least `min`.
    pub(crate) fn check_size(&self, min: usize) -> Result<(), MetrologyError> {
        check_pitch(self.pitch_x_mm)?;
        check_pitch(self.pitch_y_mm)?;
        let (rows, cols, got) = (self.rows, self.cols, self.heights_um.len());
        if rows.checked_mul(cols) != Some(got) || rows.min(cols) < min {
            let expected = rows.saturating_mul(cols).max(min * min);
            return Err(MetrologyError::GridSize {
                rows,
                cols,
                expected,
                got,
            });
        }
        Ok(())
    }

    fn check(&self) -> Result<(), MetrologyError> {
        self.check_size(0)?;
        if self.rows < 2 || self.cols < 2 {
            return Err(MetrologyError::GridTooSmall {
                rows: self.rows,
                cols: self.cols,
            });
        }
        check_heights(self.heights_um)
    }
}

/// The least-squares plane of a grid, z = a + b·x + c·y in points from the grid's centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    a: f64,
    b: f64,
    c: f64,
    xc: f64,
    yc: f64,
}

impl Plane {
    /// The plane of `grid`'s heights (checked first).
    pub fn of(grid: &HeightMap<'_>) -> Result<Plane, MetrologyError> {
        grid.check()?;
        // Centred coordinates make the normal equations diagonal on a full regular grid.
        let xc = (grid.cols - 1) as f64 * 0.5;
        let yc = (grid.rows - 1) as f64 * 0.5;
        // Row by row, point by point: the same x, y and sums, in the same order, as indexing
        // k = row·cols + col, without two integer divisions per point.
        let (mut sz, mut sxz, mut syz, mut sxx, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (row, line) in grid.heights_um.chunks_exact(grid.cols).enumerate() {
            let y = row as f64 - yc;
            for (col, z) in line.iter().enumerate() {
                let x = col as f64 - xc;
                sz += z;
                sxz += x * z;
                syz += y * z;
                sxx += x * x;
                syy += y * y;
            }
        }
        let n = grid.heights_um.len() as f64;
        Ok(Plane {
            a: sz / n,
            b: sxz / sxx,
            c: syz / syy,
            xc,
            yc,
        })
    }

    /// Row `row`'s heights `line` less the plane, into `out` (as long as `line`): a consumer
    /// that reads the levelled grid a row at a time needs no levelled copy of it.
    pub fn level_row(&self, row: usize, line: &[f64], out: &mut [f64]) {
        for (col, (o, z)) in out.iter_mut().zip(line).enumerate() {
            *o = self.level_at(row, col, *z);
        }
    }

    /// `grid`'s heights less the plane, and (a, b, c) of z = a + b·x + c·y in mm from the
    /// first point: what [`level_plane`] returns, for a caller that keeps the plane.
    pub fn level(&self, grid: &HeightMap<'_>) -> (Vec<f64>, [f64; 3]) {
        let mut levelled = vec![0.0; grid.heights_um.len()];
        let rows = grid.heights_um.chunks_exact(grid.cols);
        for (row, (line, out)) in rows.zip(levelled.chunks_exact_mut(grid.cols)).enumerate() {
            self.level_row(row, line, out);
        }
        let (b_mm, c_mm) = (self.b / grid.pitch_x_mm, self.c / grid.pitch_y_mm);
        let a_mm = self.a - self.b * self.xc - self.c * self.yc;
        (levelled, [a_mm, b_mm, c_mm])
    }

    /// The height `z` at (`row`, `col`) less the plane.
    pub fn level_at(&self, row: usize, col: usize, z: f64) -> f64 {
        let (x, y) = (col as f64 - self.xc, row as f64 - self.yc);
        z - (self.a + self.b * x + self.c * y)
    }
}

/// Removes the least-squares plane z = a + b·x + c·y; returns the residual heights and (a, b, c).
pub fn level_plane(grid: &HeightMap<'_>) -> Result<(Vec<f64>, [f64; 3]), MetrologyError> {
    Ok(Plane::of(grid)?.level(grid))
}

/// The definition ids of the areal parameters.
pub fn definitions() -> BTreeMap<String, String> {
    #[rustfmt::skip]
    let more = [
        ("levelling", "least-squares plane z = a + b x + c y removed first"),
        ("Smr(c)", "ISO25178-2/Smr(c) pooled lines, linear crossings along x, levels equal over the range"),
    ];
    super::parameter_table::areal_definitions("", &more)
}

/// Sa … Sdr of a grid after plane levelling.
pub fn areal_params(grid: &HeightMap<'_>) -> Result<ArealParams, MetrologyError> {
    let (z, plane) = level_plane(grid)?;
    Ok(areal_params_of_levelled(grid, &z, plane))
}

/// [`areal_params`] from `grid`'s heights `z` and `plane` as [`level_plane`] gives them.
pub fn areal_params_of_levelled(grid: &HeightMap<'_>, z: &[f64], plane: [f64; 3]) -> ArealParams {
    let m = super::params::EvaluationLengthMoments::of(z);
    let sp = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let sv = -z.iter().copied().fold(f64::INFINITY, f64::min);
    let (rows, cols) = (grid.rows, grid.cols);
    let dx = grid.pitch_x_mm * 1000.0;
    let dy = grid.pitch_y_mm * 1000.0;
    let at = |r: usize, c: usize| z.get(r * cols + c).copied().unwrap_or(0.0);
    let (mut gx, mut gy) = (0.0, 0.0);
    for r in 0..rows {
        for c in 0..cols {
            if c + 1 < cols {
                gx += ((at(r, c + 1) - at(r, c)) / dx).powi(2);
            }
            if r + 1 < rows {
                gy += ((at(r + 1, c) - at(r, c)) / dy).powi(2);
            }
        }
    }
    let sdq = (gx / (rows * (cols - 1)) as f64 + gy / ((rows - 1) * cols) as f64).sqrt();
    let mut area = 0.0;
    let zz = (dx * dy).powi(2);
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let xb = (dy * (at(r, c + 1) - at(r, c))).powi(2);
            let xt = (dy * (at(r + 1, c + 1) - at(r + 1, c))).powi(2);
            let yl = (dx * (at(r + 1, c) - at(r, c))).powi(2);
            let yr = (dx * (at(r + 1, c + 1) - at(r, c + 1))).powi(2);
            area += 0.25
                * ((xb + yl + zz).sqrt()
                    + (xb + yr + zz).sqrt()
                    + (xt + yr + zz).sqrt()
                    + (xt + yl + zz).sqrt());
        }
    }
    let projected = (cols - 1) as f64 * dx * (rows - 1) as f64 * dy;
    ArealParams {
        sa_um: m.ra_um,
        sq_um: m.rq_um,
        sp_um: sp,
        sv_um: sv,
        sz_um: sp + sv,
        ssk: m.rsk,
        sku: m.rku,
        sdq,
        sdr_pct: (area / projected - 1.0) * 100.0,
        plane_um: plane,
        definitions: definitions(),
    }
}

/// Sq alone of a grid after plane levelling: the bits of [`areal_params`]' `sq_um` (the same
/// levelling and sum, in order, a row at a time with no levelled copy), for callers that need
/// only Sq (the verdict between lines in `surfscan fit`).
pub fn sq_um(grid: &HeightMap<'_>) -> Result<f64, MetrologyError> {
    let (p, mut row, mut m2) = (Plane::of(grid)?, vec![0.0; grid.cols], 0.0);
    for (r, line) in grid.heights_um.chunks_exact(grid.cols).enumerate() {
        p.level_row(r, line, &mut row);
        m2 = row.iter().fold(m2, |s, v| s + v * v);
    }
    Ok((m2 / grid.heights_um.len() as f64).sqrt())
}

/// The pooled areal material ratio curve Smr(c) of heights `z` (lines of `cols`) levelled by
/// [`level_plane`]: `levels` equal steps from the highest to the lowest point, `[µm, %]` pairs.
pub fn smr_curve(z: &[f64], cols: usize, levels: usize) -> Result<Vec<[f64; 2]>, MetrologyError> {
    curve_between_extremes(z, levels, |interior| {
        let rows: Vec<Vec<f64>> = z
            .chunks_exact(cols)
            .map(|row| material_ratios_pct(row, interior))
            .collect();
        let mean_of = |k: usize| rows.iter().map(|r| r[k]).sum::<f64>() / rows.len() as f64;
        (0..interior.len()).map(mean_of).collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrology::bearing::material_ratio_pct;

    #[test]
    fn smr_curve_equals_the_per_level_pooled_ratio() {
        // A rough tilted grid, and one of quantised heights whose levels fall on samples.
        let (rows, cols) = (7, 900);
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut noise = || crate::metrology::lcg(&mut seed);
        let rough: Vec<f64> = (0..rows * cols)
            .map(|k| 0.001 * k as f64 + ((k % cols) as f64 * 0.02).sin() + noise())
            .collect();
        let steps: Vec<f64> = (0..rows * cols).map(|_| (noise() * 6.0).floor()).collect();
        for heights in [rough, steps] {
            let grid = test_map(&heights, rows, cols, 0.0005, 0.01);
            let (z, _) = level_plane(&grid).unwrap();
            let curve = smr_curve(&z, cols, 101).unwrap();
            for (k, p) in curve.iter().enumerate() {
                let slow = match k {
                    0 => 0.0,
                    100 => 100.0,
                    _ => {
                        z.chunks_exact(cols)
                            .map(|row| material_ratio_pct(row, p[0]))
                            .sum::<f64>()
                            / rows as f64
                    }
                };
                assert!(
                    (p[1] - slow).abs() <= 1e-12 * slow.abs(),
                    "level {k}: {} vs {slow} per level",
                    p[1]
                );
            }
        }
    }

    /// Sq alone is Sq of all the parameters, to the bit, and fails where they fail.
    #[test]
    fn sq_alone_is_the_sq_of_all_parameters() {
        for (rows, cols, tilt) in [(2, 2, 0.0), (3, 7, 0.3), (31, 500, -0.01), (5, 1001, 2.0)] {
            let heights: Vec<f64> = (0..rows * cols)
                .map(|k| ((k as f64) * 0.71).sin() * 3.0 + tilt * k as f64 + 40.0)
                .collect();
            let grid = test_map(&heights, rows, cols, 0.0005, 0.01);
            let all = areal_params(&grid).unwrap().sq_um;
            assert!(all > 0.1, "{rows}×{cols}: Sq {all}");
            assert_eq!(
                sq_um(&grid).unwrap().to_bits(),
                all.to_bits(),
                "{rows}×{cols}"
            );
        }
        let short = [1.0; 5];
        let bad = test_map(&short, 2, 3, 0.0005, 0.01);
        assert_eq!(sq_um(&bad).unwrap_err(), areal_params(&bad).unwrap_err());
    }

    /// The row-by-row levelling is the plane of the point-by-point definition with k = row·cols
    /// + col, to the bit: residuals and coefficients, on grids that are not square.
    #[test]
    fn levelling_row_by_row_is_the_indexed_definition_to_the_bit() {
        for (rows, cols) in [(2, 2), (3, 7), (31, 50), (5, 1001)] {
            let heights: Vec<f64> = (0..rows * cols)
                .map(|k| ((k as f64) * 0.37).sin() + 0.01 * k as f64 - 2.0)
                .collect();
            let grid = test_map(&heights, rows, cols, 0.0005, 0.01);
            let (xc, yc) = ((cols - 1) as f64 * 0.5, (rows - 1) as f64 * 0.5);
            let (mut sz, mut sxz, mut syz, mut sxx, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (k, z) in heights.iter().enumerate() {
                let x = (k % cols) as f64 - xc;
                let y = (k / cols) as f64 - yc;
                sz += z;
                sxz += x * z;
                syz += y * z;
                sxx += x * x;
                syy += y * y;
            }
            let (a, b, c) = (sz / heights.len() as f64, sxz / sxx, syz / syy);
            let want: Vec<u64> = heights
                .iter()
                .enumerate()
                .map(|(k, z)| {
                    let (x, y) = ((k % cols) as f64 - xc, (k / cols) as f64 - yc);
                    (z - (a + b * x + c * y)).to_bits()
                })
                .collect();
            let (got, plane) = level_plane(&grid).unwrap();
            let got: Vec<u64> = got.iter().map(|v| v.to_bits()).collect();
            assert_eq!(got, want, "{rows}×{cols}");
            let want_plane = [a - b * xc - c * yc, b / 0.0005, c / 0.01];
            assert_eq!(plane.map(f64::to_bits), want_plane.map(f64::to_bits));
        }
    }
}
