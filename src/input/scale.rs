//! Is the scale of a grid plausible for a stylus profile in µm? A file in other units than
//! it is read in passes every other check: heights in mm read as µm give an Sq in the nm range,
//! heights in nm read as µm a range of metres, x in µm read as mm a profile of a few µm. The
//! bounds: Sq (about the least-squares plane, or line for one line) below [`MIN_SQ_UM`] — an
//! SJ-210 resolves 2 nm at best — unless the heights lie on a plane (no roughness to judge), a
//! height range above [`MAX_RANGE_UM`], a profile whose x spans less than [`MIN_X_SPAN_MM`].
//! Each finding names the likely mix-up and what fixes it. The Sq about the plane (three
//! passes over every height) is computed only when the first row cannot prove on its own that
//! it reaches the bound, which for a rough grid it does.
//!
//! Pure (no I/O), inside the reading layer: numbers in, findings out; depends on
//! [`crate::grid`], [`crate::extremes`] and [`crate::numfmt`].

use crate::extremes::min_max;
use crate::grid::Grid;
use crate::numfmt::{fmt, Quantity};

/// Smallest plausible Sq of a stylus profile, µm (5 nm).
pub const MIN_SQ_UM: f64 = 0.005;
/// Largest plausible height range, µm (2 mm).
pub const MAX_RANGE_UM: f64 = 2000.0;
/// Shortest plausible x span of a profile, mm.
pub const MIN_X_SPAN_MM: f64 = 0.01;

/// A scale the grid is unlikely to be read in, with the figure that says so.
#[derive(Debug, Clone, PartialEq)]
pub enum Implausible {
    /// Sq about the least-squares plane, µm.
    SqTooSmall(f64),
    /// Highest minus lowest height, µm.
    RangeTooLarge(f64),
    /// The x span of a profile, mm.
    XSpanTooShort(f64),
}

impl Implausible {
    /// The finding in words: the figure, the likely mix-up and, in `fix`, what the reader was
    /// told or how to tell it.
    pub fn describe(&self, fix: &str) -> String {
        match self {
            Implausible::SqTooSmall(sq) => format!(
                "the heights have Sq {} nm, below the {} nm a stylus profile in µm has (an SJ-210 resolves 2 nm at best): heights in mm read as µm look like this; {fix}",
                fmt(sq * 1000.0, Quantity::HeightUm),
                MIN_SQ_UM * 1000.0
            ),
            Implausible::RangeTooLarge(range) => format!(
                "the heights span {} µm, more than a stylus profiler's {} mm: heights in nm read as µm look like this; {fix}",
                fmt(*range, Quantity::HeightUm),
                MAX_RANGE_UM / 1000.0
            ),
            Implausible::XSpanTooShort(span) => format!(
                "the profile's x spans {} mm, less than {MIN_X_SPAN_MM} mm: x in µm read as mm looks like this; name x's unit in the header (x_um or x_mm)",
                fmt(*span, Quantity::LengthMm)
            ),
        }
    }
}

/// Longest line taken at face value, mm: far beyond a stylus instrument's traverse (the
/// SJ-210's is 17.5 mm), so a longer one most likely has its x in µm.
pub const PLAUSIBLE_LENGTH_MM: f64 = 100.0;

/// A warning when the lines of `grid` are longer than [`PLAUSIBLE_LENGTH_MM`] (a pitch given
/// in µm where mm are meant); never a refusal.
pub fn too_long(grid: &Grid) -> Option<String> {
    let length = grid.cols.saturating_sub(1) as f64 * grid.pitch_x_mm;
    (length > PLAUSIBLE_LENGTH_MM).then(|| {
        format!(
            "the lines are {} mm long ({} points {} mm apart), longer than any stylus traverse: check that x (or --pitch-x) is in mm",
            fmt(length, Quantity::LengthMm),
            grid.cols,
            fmt(grid.pitch_x_mm, Quantity::LengthMm)
        )
    })
}

/// The implausible scales of `grid`; `profile` also checks the x span.
pub fn implausible(grid: &Grid, profile: bool) -> Vec<Implausible> {
    let mut out = Vec::new();
    let z = &grid.heights_um;
    if z.is_empty() || grid.cols == 0 {
        return out;
    }
    let (lo, hi) = min_max(z);
    if hi - lo > MAX_RANGE_UM {
        out.push(Implausible::RangeTooLarge(hi - lo));
    }
    if !rough_beyond_doubt(grid, lo, hi) {
        let sq = sq_about_plane(grid);
        // Heights on a plane (to rounding) have no roughness whose size could tell the unit.
        let plane = sq <= 1e-9 * lo.abs().max(hi.abs());
        if sq < MIN_SQ_UM && !plane {
            out.push(Implausible::SqTooSmall(sq));
        }
    }
    let span = grid.cols.saturating_sub(1) as f64 * grid.pitch_x_mm;
    if profile && span < MIN_X_SPAN_MM {
        out.push(Implausible::XSpanTooShort(span));
    }
    out
}

/// Whether the first row alone proves that [`sq_about_plane`], as computed, is at least
/// [`MIN_SQ_UM`], so that its three passes over every height can be skipped with the same
/// findings.
///
/// Why it is a proof (u = ε/2, m = the row's length, n = the grid's heights, R = |z|max +
/// range). Restricted to one row, any plane is a line in the column index, so the exact sum
/// of squared residuals of all n heights about the plane `sq_about_plane` fits is at least L,
/// the row's least-squares line's. Rounding moves each residual that function computes by at
/// most 4u·(|z| + |mean| + |b·x| + |c·y|), where |b·x| and |c·y| are each at most
/// √(Σ(z − mean)²) ≤ √n·range (Cauchy–Schwarz, with x² ≤ Σx² and y² ≤ Σy²): the residual
/// vector's length moves by less than 9u·n·R. Here, in the same centred way, the row's rounded
/// mean and slope put the residual sum L̂ above L by their errors' parts (orthogonal in the
/// centred basis), whose lengths are under 1.1u·m·√m·R and 2.2u·m·√m·R, and rounding the
/// residuals moves the length by under 7u·(√m + m)·R. Sums, quotients and roots of squares
/// lose under (n + 3)u relatively, far below 1 % for any grid that fits in memory. So when
/// √L̂ ≥ 2·MIN_SQ_UM·√n + 8ε·(n + m·√m + m)·R, the result is at least MIN_SQ_UM. Nothing
/// that is not finite proves anything: then the passes run.
fn rough_beyond_doubt(grid: &Grid, lo: f64, hi: f64) -> bool {
    if grid.rows() == 0 {
        return false;
    }
    let z = grid.row(0);
    let cols = z.len() as f64;
    let kc = (cols - 1.0) / 2.0;
    let mean = z.iter().sum::<f64>() / cols;
    let (mut skk, mut skz) = (0.0, 0.0);
    for (k, &v) in z.iter().enumerate() {
        let x = k as f64 - kc;
        skk += x * x;
        skz += x * (v - mean);
    }
    let slope = if skk > 0.0 { skz / skk } else { 0.0 };
    let l: f64 = z
        .iter()
        .enumerate()
        .map(|(k, &v)| {
            let e = v - mean - slope * (k as f64 - kc);
            e * e
        })
        .sum();
    let n = (grid.rows() * grid.cols) as f64;
    let margin = 8.0
        * f64::EPSILON
        * (n + cols * (cols.sqrt() + 1.0))
        * (lo.abs().max(hi.abs()) + (hi - lo));
    l.sqrt() >= 2.0 * MIN_SQ_UM * n.sqrt() + margin
}

/// The rms of the heights about their least-squares plane z = a + b·x + c·y (a line when the
/// grid has one line, or its lines share one y), in µm.
fn sq_about_plane(grid: &Grid) -> f64 {
    let (rows, cols) = (grid.rows(), grid.cols);
    let n = (rows * cols) as f64;
    // Centred coordinates: column k at x = k − (cols − 1)/2, line r at its y − mean y.
    let xc = (cols as f64 - 1.0) / 2.0;
    let ym = grid.y_mm.iter().sum::<f64>() / rows as f64;
    let zm = grid.heights_um.iter().sum::<f64>() / n;
    let (mut sxx, mut syy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0);
    for r in 0..rows {
        let y = grid.y_mm[r] - ym;
        for (k, &z) in grid.row(r).iter().enumerate() {
            let x = k as f64 - xc;
            let dz = z - zm;
            sxx += x * x;
            syy += y * y;
            sxz += x * dz;
            syz += y * dz;
        }
    }
    // With the columns the same for every line, x and y are uncorrelated about their means.
    let b = if sxx > 0.0 { sxz / sxx } else { 0.0 };
    let c = if syy > 0.0 { syz / syy } else { 0.0 };
    let mut ss = 0.0;
    for r in 0..rows {
        let y = grid.y_mm[r] - ym;
        for (k, &z) in grid.row(r).iter().enumerate() {
            let e = z - zm - b * (k as f64 - xc) - c * y;
            ss += e * e;
        }
    }
    (ss / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(rows: usize, cols: usize, pitch_x_mm: f64, f: impl Fn(usize, usize) -> f64) -> Grid {
        let z = (0..rows)
            .flat_map(|r| (0..cols).map(move |k| (r, k)))
            .map(|(r, k)| f(r, k))
            .collect();
        Grid::new(
            z,
            cols,
            pitch_x_mm,
            (0..rows).map(|r| r as f64 * 0.01).collect(),
        )
    }

    #[test]
    fn a_tilted_plane_has_no_roughness_and_a_rough_one_is_measured() {
        // A plane of any tilt leaves nothing: Sq 0.
        let g = grid(5, 50, 0.001, |r, k| 3.0 + 0.2 * k as f64 - 7.0 * r as f64);
        assert!(sq_about_plane(&g) < 1e-12, "{}", sq_about_plane(&g));
        // ±1 alternating about a plane: Sq 1.
        let g = grid(4, 40, 0.001, |r, k| {
            0.5 * k as f64 + r as f64 + if (r + k) % 2 == 0 { 1.0 } else { -1.0 }
        });
        assert!(
            (sq_about_plane(&g) - 1.0).abs() < 1e-3,
            "{}",
            sq_about_plane(&g)
        );
    }

    #[test]
    fn each_implausible_scale_is_found_with_its_figure() {
        let rough = |r: usize, k: usize| ((r * 31 + k * 17) % 7) as f64 - 3.0;
        assert!(implausible(&grid(3, 100, 0.001, rough), true).is_empty());
        // A plane has no roughness to judge by, whatever its unit.
        let plane = |r: usize, k: usize| 1e-3 * (2.0 + k as f64 * 0.1 - r as f64);
        assert!(implausible(&grid(3, 100, 0.001, plane), true).is_empty());
        // The same heights in mm read as µm.
        let mm = implausible(&grid(3, 100, 0.001, |r, k| rough(r, k) * 1e-3), false);
        assert!(
            matches!(mm.as_slice(), [Implausible::SqTooSmall(sq)] if *sq < 0.005),
            "{mm:?}"
        );
        // In nm read as µm: 6000 µm of range.
        let nm = implausible(&grid(3, 100, 0.001, |r, k| rough(r, k) * 1e3), false);
        assert!(
            matches!(nm.as_slice(), [Implausible::RangeTooLarge(r)] if (*r - 6000.0).abs() < 1e-9),
            "{nm:?}"
        );
        // x in µm read as mm: 100 points 1 µm apart written as 0.000001 mm.
        let x = implausible(&grid(1, 100, 1e-6, rough), true);
        assert!(
            matches!(x.as_slice(), [Implausible::XSpanTooShort(_)]),
            "{x:?}"
        );
        let words = x[0].describe("");
        assert!(
            words.contains("x in µm read as mm") && words.contains("x_um"),
            "{words}"
        );
        let words = mm[0].describe("give --z-unit mm");
        assert!(
            words.contains("heights in mm read as µm") && words.ends_with("give --z-unit mm"),
            "{words}"
        );
    }

    /// The findings as `implausible` gave them before the first row could prove roughness:
    /// the three passes always.
    fn findings_of_the_three_passes(g: &Grid) -> Option<Implausible> {
        let (lo, hi) = min_max(&g.heights_um);
        let sq = sq_about_plane(g);
        (sq < MIN_SQ_UM && sq > 1e-9 * lo.abs().max(hi.abs()))
            .then_some(Implausible::SqTooSmall(sq))
    }

    #[test]
    fn a_row_proves_roughness_only_where_the_three_passes_find_it() {
        // Noise from 0.1 nm to 1 µm (the threshold is 5 nm rms) on tilted planes near zero
        // and far from it, one line to 31: the findings are those of the three passes, and
        // where the first row proves the roughness the passes find Sq at or above the bound.
        let mut s: u64 = 0x2545_F491_4F6C_DD1D;
        let mut noise = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for case in 0..360 {
            let amp_um = 1e-4 * 10f64.powf(f64::from(case % 40) / 10.0);
            let offset_um = [0.0, 250.0, -1.0e4][case as usize % 3];
            let (rows, cols) = (
                [1, 3, 31][(case / 40) as usize % 3],
                [2, 60, 900][(case / 120) as usize],
            );
            let n: Vec<f64> = (0..rows * cols).map(|_| noise()).collect();
            let g = grid(rows, cols, 0.001, |r, k| {
                offset_um + 0.3 * k as f64 - 0.7 * r as f64 + amp_um * n[r * cols + k]
            });
            let (lo, hi) = min_max(&g.heights_um);
            let proved = rough_beyond_doubt(&g, lo, hi);
            if proved {
                assert!(sq_about_plane(&g) >= MIN_SQ_UM, "case {case}");
            }
            // The common case, a rough grid, is proved: noise of 0.3 µm or more (0.087 µm rms)
            // in rows of 60 points or more, where the bound asks the first row for at most
            // 2 × 0.005 × √31 = 0.056 µm rms.
            if amp_um >= 0.3 && cols >= 60 {
                assert!(proved, "case {case}");
            }
            let sq_finding = implausible(&g, false)
                .into_iter()
                .find(|f| matches!(f, Implausible::SqTooSmall(_)));
            assert_eq!(sq_finding, findings_of_the_three_passes(&g), "case {case}");
        }
    }
}
