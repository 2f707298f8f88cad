//! What the grid's geometry does to the areal numbers: a stylus grid is sampled finely along
//! the lines (x) and coarsely across them (y, the stage step), so slopes across the lines are
//! differences between heights one stage step apart. When the lines are barely correlated at
//! that distance, dz/dy is the difference of two independent heights divided by the y pitch,
//! and Sdq and Sdr measure the grid, not the surface.
//!
//! On the plane-levelled grid (as [`super::areal`] levels it):
//!
//! * the pitch ratio y/x;
//! * the line-to-line correlation at the y pitch: the Pearson correlation of adjacent lines
//!   (each about its own mean), averaged over the pairs;
//! * for comparison, the correlation along the lines at the same distance (each line with
//!   itself shifted by the y pitch, linearly interpolated between points), averaged over the
//!   lines; on an isotropic surface the two agree;
//! * Sdq split by direction, Sdq_x = sqrt(mean (dz/dx)²) and Sdq_y = sqrt(mean (dz/dy)²)
//!   (forward differences, as in Sdq, so Sdq² = Sdq_x² + Sdq_y²), and the share of Sdq² that
//!   comes from dz/dy;
//! * Sdr from each direction's slopes alone, mean(sqrt(1 + (dz/dx)²)) − 1 and likewise in y,
//!   in %, to say which direction makes the developed area.
//!
//! Depends on [`super::areal`] and [`super::MetrologyError`].

use super::areal::{level_plane, HeightMap};
use super::MetrologyError;
use serde::Serialize;

/// A y/x pitch ratio from which the grid is called anisotropic in the caveats.
pub const ANISOTROPIC_RATIO: f64 = 2.0;

/// The anisotropy of a grid and its effect on the slope parameters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Anisotropy {
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// y pitch, mm.
    pub pitch_y_mm: f64,
    /// pitch y / pitch x.
    pub pitch_ratio_y_over_x: f64,
    /// Mean Pearson correlation of adjacent lines (at the y pitch).
    pub line_correlation_at_pitch_y: f64,
    /// Mean correlation along the lines at a lag of one y pitch; `None` when the lines are
    /// shorter than two y pitches.
    pub along_x_correlation_at_pitch_y: Option<f64>,
    /// rms dz/dx (forward differences).
    pub sdq_x: f64,
    /// rms dz/dy (forward differences).
    pub sdq_y: f64,
    /// Share of Sdq² that comes from dz/dy, %.
    pub sdq_y_share_pct: f64,
    /// Developed area ratio from dz/dx alone, %.
    pub sdr_x_pct: f64,
    /// Developed area ratio from dz/dy alone, %.
    pub sdr_y_pct: f64,
    /// The direction whose slopes dominate Sdq and Sdr: "x" or "y".
    pub dominant: &'static str,
    /// The caveats in words.
    pub caveats: Vec<String>,
}

impl Anisotropy {
    /// True when the slope parameters are dominated by differences across lines that are
    /// barely correlated (|r| < 0.5 at the y pitch): then Sdq and Sdr describe the grid more
    /// than the surface, and the caveat belongs in the report's warnings.
    pub fn slopes_untrustworthy(&self) -> bool {
        self.dominant == "y" && self.line_correlation_at_pitch_y.abs() < 0.5
    }
}

fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len().min(b.len());
    if n < 2 {
        return None;
    }
    let ma = a.iter().take(n).sum::<f64>() / n as f64;
    let mb = b.iter().take(n).sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b).take(n) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    (saa > 0.0 && sbb > 0.0).then(|| sab / (saa * sbb).sqrt())
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    (n > 0).then(|| s / n as f64)
}

/// The anisotropy of `grid` (see the module docs).
pub fn anisotropy(grid: &HeightMap<'_>) -> Result<Anisotropy, MetrologyError> {
    let (z, _) = level_plane(grid)?;
    let (rows, cols) = (grid.rows, grid.cols);
    let (px, py) = (grid.pitch_x_mm, grid.pitch_y_mm);
    let row = |r: usize| z.get(r * cols..(r + 1) * cols).unwrap_or(&[]);
    let line_r = mean((0..rows - 1).filter_map(|r| pearson(row(r), row(r + 1)))).unwrap_or(0.0);
    let ratio = py / px;
    let along = if ratio < (cols as f64) / 2.0 {
        let whole = ratio.floor() as usize;
        let t = ratio - whole as f64;
        let n = cols - whole - 1;
        mean((0..rows).filter_map(|r| {
            let line = row(r);
            let shifted: Vec<f64> = (0..n)
                .map(|i| (1.0 - t) * line[i + whole] + t * line[i + whole + 1])
                .collect();
            pearson(&line[..n], &shifted)
        }))
    } else {
        None
    };
    let (dx, dy) = (px * 1000.0, py * 1000.0);
    let (mut gx2, mut gy2, mut ax, mut ay) = (0.0, 0.0, 0.0, 0.0);
    for r in 0..rows {
        for c in 0..cols {
            let here = z[r * cols + c];
            if c + 1 < cols {
                let s = (z[r * cols + c + 1] - here) / dx;
                gx2 += s * s;
                ax += (1.0 + s * s).sqrt() - 1.0;
            }
            if r + 1 < rows {
                let s = (z[(r + 1) * cols + c] - here) / dy;
                gy2 += s * s;
                ay += (1.0 + s * s).sqrt() - 1.0;
            }
        }
    }
    let (nx, ny) = ((rows * (cols - 1)) as f64, ((rows - 1) * cols) as f64);
    let (sx2, sy2) = (gx2 / nx, gy2 / ny);
    let share = if sx2 + sy2 > 0.0 {
        sy2 / (sx2 + sy2) * 100.0
    } else {
        0.0
    };
    let (sdr_x, sdr_y) = (ax / nx * 100.0, ay / ny * 100.0);
    let dominant = if sy2 > sx2 { "y" } else { "x" };
    let mut a = Anisotropy {
        pitch_x_mm: px,
        pitch_y_mm: py,
        pitch_ratio_y_over_x: ratio,
        line_correlation_at_pitch_y: line_r,
        along_x_correlation_at_pitch_y: along,
        sdq_x: sx2.sqrt(),
        sdq_y: sy2.sqrt(),
        sdq_y_share_pct: share,
        sdr_x_pct: sdr_x,
        sdr_y_pct: sdr_y,
        dominant,
        caveats: Vec::new(),
    };
    if ratio >= ANISOTROPIC_RATIO {
        a.caveats.push(format!(
            "anisotropic grid: the y pitch ({py} mm) is {ratio:.1} × the x pitch ({px} mm); across the lines the surface is sampled {ratio:.1} times more coarsely than along them"
        ));
    }
    a.caveats.push(match along {
        Some(r_x) => format!(
            "adjacent lines ({py} mm apart) correlate at r = {line_r:.2}; along a line, points {py} mm apart correlate at r = {r_x:.2}{}",
            if line_r < r_x - 0.2 {
                ": the lines are too far apart to follow the texture across them"
            } else {
                ""
            }
        ),
        None => format!("adjacent lines ({py} mm apart) correlate at r = {line_r:.2}"),
    });
    a.caveats.push(format!(
        "Sdq is dominated by dz/d{dominant}: {share:.0} % of Sdq² comes from dz/dy (rms dz/dx {:.3}, dz/dy {:.3}); Sdr from dz/dx alone {sdr_x:.2} %, from dz/dy alone {sdr_y:.2} %{}",
        a.sdq_x,
        a.sdq_y,
        if a.slopes_untrustworthy() {
            "; with lines this weakly correlated, Sdq and Sdr measure differences between independent lines, not slopes of the surface"
        } else {
            ""
        }
    ));
    Ok(a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrology::areal::test_map;
    use crate::metrology::test_grid;

    #[test]
    fn identical_lines_correlate_fully_and_have_no_y_slope() {
        let z = test_grid(10, 200, 0.001, |_, c| (c as f64 * 0.3).sin()).heights_um;
        let g = test_map(&z, 10, 200, 0.001, 0.01);
        let a = anisotropy(&g).unwrap();
        assert!((a.line_correlation_at_pitch_y - 1.0).abs() < 1e-12);
        assert!(a.sdq_y < 1e-12 && a.sdq_y_share_pct < 1e-9 && a.dominant == "x");
        assert!((a.pitch_ratio_y_over_x - 10.0).abs() < 1e-12);
        // Along x at a lag of 10 points: cos(3) for a sine of 0.3 rad per point.
        let r = a.along_x_correlation_at_pitch_y.unwrap();
        assert!((r - 3.0f64.cos()).abs() < 0.02, "{r}");
        assert!(!a.slopes_untrustworthy());
        assert!(
            a.caveats[0].contains("10.0 × the x pitch"),
            "{:?}",
            a.caveats
        );
    }

    #[test]
    fn alternating_lines_anticorrelate_and_dominate_the_slopes() {
        let z = test_grid(12, 100, 0.001, |r, c| {
            let sign = if r % 2 == 0 { 1.0 } else { -1.0 };
            sign * (1.0 + 0.01 * (c as f64 * 0.7).sin())
        })
        .heights_um;
        let g = test_map(&z, 12, 100, 0.001, 0.001);
        let a = anisotropy(&g).unwrap();
        assert!(a.line_correlation_at_pitch_y < -0.99, "{a:?}");
        assert_eq!(a.dominant, "y");
        assert!(a.sdq_y_share_pct > 99.0 && a.sdr_y_pct > a.sdr_x_pct);
        // Sdq² = Sdq_x² + Sdq_y², as the areal Sdq.
        let sdq = crate::metrology::areal::areal_params(&g).unwrap().sdq;
        assert!((sdq * sdq - (a.sdq_x.powi(2) + a.sdq_y.powi(2))).abs() < 1e-12 * sdq * sdq);
        // Isotropic pitches: no anisotropy caveat, but the slope caveat names y.
        assert!(!a.caveats.iter().any(|c| c.starts_with("anisotropic")));
        assert!(a.caveats.iter().any(|c| c.contains("dominated by dz/dy")));
    }
}
