//! The surfaces a user can choose between, judged by the same between-line hold-out: the
//! paper's interpolation at the chosen degrees, and least-squares approximations across the
//! lines with fewer control rows (a quarter and half of the lines, and the fewest the degree
//! allows) at degree v and at degree 3 — so `surfscan fit --compare` can print their hold-out
//! figures side by side and the choice is made with numbers.
//!
//! Depends on [`super::holdout`], [`crate::fit`] and [`crate::grid`].

use super::holdout::{between_lines, BetweenLines};
use crate::fit::approx_v::default_control_rows;
use crate::fit::{FitOptions, VMethod};
use crate::grid::Grid;

/// One candidate surface and how it held out.
#[derive(Debug, Clone, PartialEq)]
pub struct Alternative {
    /// Degrees.
    pub options: FitOptions,
    /// Method across the lines.
    pub method: VMethod,
    /// Control rows along v of the full surface (one per line when interpolating).
    pub poles_v: usize,
    /// The hold-out, or why it could not be made.
    pub holdout: Result<BetweenLines, String>,
}

/// The candidates for `lines` lines at `options` (deduplicated, the paper's first).
pub fn candidates(lines: usize, options: FitOptions) -> Vec<(FitOptions, VMethod)> {
    let mut out = vec![(options, VMethod::Interpolate)];
    // Degree 3 twice when it is the chosen one: its candidates are already in.
    for q in [options.degree_v, 3] {
        let o = FitOptions::degrees(options.degree_u, q);
        for rows in [
            default_control_rows(lines, q),
            lines.div_ceil(2).max(q + 1),
            q + 1,
        ] {
            let c = (o, VMethod::LeastSquares { control_rows: rows });
            if rows <= lines && !out.contains(&c) {
                out.push(c);
            }
        }
    }
    out
}

/// Judges every candidate of [`candidates`] with [`between_lines`] (every `every`-th line
/// left out, against `sq_um` and `threshold`).
pub fn compare(
    grid: &Grid,
    options: FitOptions,
    every: usize,
    sq_um: f64,
    threshold: f64,
) -> Vec<Alternative> {
    candidates(grid.rows(), options)
        .into_iter()
        .map(|(o, method)| Alternative {
            options: o,
            method,
            poles_v: match method {
                VMethod::Interpolate => grid.rows(),
                VMethod::LeastSquares { control_rows } => control_rows,
            },
            holdout: between_lines(grid, o, method, every, sq_um, threshold)
                .map_err(|e| e.to_string()),
        })
        .collect()
}

/// The alternatives as a plain-text table, one row each, for a terminal.
pub fn table(alternatives: &[Alternative]) -> String {
    let mut s = format!(
        "{:<26} {:>6} {:>7} {:>14} {:>7} {:>12}  verdict\n",
        "method across the lines", "p/q", "v poles", "hold-out rms", "× Sq", "max"
    );
    for a in alternatives {
        let name = match a.method {
            VMethod::Interpolate => "interpolate (the paper)",
            VMethod::LeastSquares { .. } => "least-squares",
        };
        let degrees = format!("{}/{}", a.options.degree_u, a.options.degree_v);
        s.push_str(&format!("{name:<26} {degrees:>6} {:>7}", a.poles_v));
        match &a.holdout {
            Ok(h) => s.push_str(&format!(
                " {:>11.3} µm {:>7.2} {:>9.3} µm  {}\n",
                h.rms_um,
                h.rms_over_sq,
                h.max_abs_um,
                if h.supported {
                    "supported"
                } else {
                    "not supported"
                }
            )),
            Err(e) => s.push_str(&format!("  no hold-out: {e}\n")),
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_start_with_the_paper_and_stay_within_the_lines() {
        let c = candidates(31, FitOptions::default());
        assert_eq!(c[0], (FitOptions::default(), VMethod::Interpolate));
        let ls: Vec<(usize, usize)> = c
            .iter()
            .filter_map(|(o, m)| match m {
                VMethod::LeastSquares { control_rows } => Some((o.degree_v, *control_rows)),
                VMethod::Interpolate => None,
            })
            .collect();
        assert_eq!(ls, vec![(5, 8), (5, 16), (5, 6), (3, 8), (3, 16), (3, 4)]);
        // Few lines: no candidate asks for more rows than there are lines.
        for (o, m) in candidates(6, FitOptions::default()) {
            if let VMethod::LeastSquares { control_rows } = m {
                assert!(
                    control_rows <= 6 && control_rows > o.degree_v,
                    "{o:?} {m:?}"
                );
            }
        }
    }

    #[test]
    fn the_table_names_every_alternative_and_its_verdict() {
        let rows = 13;
        let grid = crate::metrology::test_grid(rows, 40, 0.002, |r, c| {
            (c as f64 * 0.3).sin() * (1.0 + 0.01 * r as f64)
        });
        let alts = compare(&grid, FitOptions::default(), 2, 0.7, 0.5);
        assert_eq!(alts.len(), candidates(rows, FitOptions::default()).len());
        let t = table(&alts);
        assert!(t.lines().count() == alts.len() + 1, "{t}");
        assert!(
            t.contains("interpolate (the paper)") && t.contains("least-squares"),
            "{t}"
        );
        assert!(t.contains("supported"), "{t}");
    }
}
