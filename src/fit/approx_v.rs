//! Beyond the paper, as an addition: a least-squares approximation across the traced lines.
//!
//! The paper interpolates in both directions, so the surface passes through every measured
//! point, and between lines it is whatever a degree-5 interpolant makes of heights measured
//! 10 µm apart. When the lines are not correlated at that distance the interpolant swings
//! beyond the data. [`VMethod::LeastSquares`] keeps the paper along the lines (u: chord-length
//! parameters averaged over the lines, averaged knots, interpolation) and replaces the
//! interpolation across the lines by a least-squares fit with fewer control rows:
//!
//! * parameters across the lines are proportional to the lines' positions,
//!   v_l = (y_l − y_0)/(y_last − y_0) (across lines there is no curve to follow, only
//!   positions; the chord lengths of the paper would let the height differences between
//!   uncorrelated lines decide where the lines sit);
//! * `control_rows` = n_v poles along v, degree q = `degree_v`, clamped knots placed by
//!   P&T eq. 9.68–9.69 (d = lines/(n_v − q), u_{q+j} = (1 − α)·v_{i−1} + α·v_i with
//!   i = ⌊j·d⌋, α = j·d − i), which puts at least one line in every knot span, so the normal
//!   equations are positive definite (Schoenberg–Whitney);
//! * the poles minimise Σ_{k,l} (S(ū_k, v_l) − z_kl)², the sum over every measured point.
//!   Because the u collocation matrix N_u is square and invertible, this is solved
//!   separably and exactly: C = N_u⁻¹·Z row by row (the paper's u solve), then
//!   (MᵀM)·P = Mᵀ·C across the lines (M the v collocation matrix, MᵀM solved by Cholesky);
//!   the normal equations of the full problem reduce to exactly these;
//! * x poles are the paper's (x depends on u only); y poles are the Greville abscissae mapped
//!   to y, y_j = y_0 + (y_last − y_0)·(t_{j+1} + … + t_{j+q})/q, which reproduces the linear
//!   y(v) exactly, so the model's y at v_l is the line's y.
//!
//! Nothing here changes [`super::fit_grid`]: [`VMethod::Interpolate`] calls it as it is.
//!
//! Layer 1 (pure logic): depends on [`super`] (the paper's fit, its banded solver and knots)
//! and [`crate::nurbs`]; nalgebra for the small normal equations.

use super::{fit_grid, BandLu, FitError, FitOptions, FitResult, FitTimings};
use crate::nurbs::{basis_funs, find_span, NurbsSurface, PoleNet};
use serde::{Deserialize, Serialize};
use std::time::Instant;
use thiserror::Error;

/// How the surface is made across the traced lines (along v, y).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case", tag = "method")]
pub enum VMethod {
    /// The paper: interpolation through every line (bit-identical to [`super::fit_grid`]).
    #[default]
    Interpolate,
    /// Least squares across the lines with `control_rows` poles along v (module docs).
    LeastSquares {
        /// Poles along v, from degree_v + 1 to the number of lines.
        control_rows: usize,
    },
}

impl VMethod {
    /// The method's name in configuration and reports: `interpolate` or `least-squares`.
    pub fn name(&self) -> &'static str {
        match self {
            VMethod::Interpolate => "interpolate",
            VMethod::LeastSquares { .. } => "least-squares",
        }
    }

    /// The method in a few words, as the IGES Start section of a surface names it.
    pub fn in_brief(&self) -> String {
        match self {
            VMethod::Interpolate => "global B-spline interpolation".to_string(),
            VMethod::LeastSquares { control_rows } => format!(
                "B-spline interpolation along x, least squares across the lines with {control_rows} control rows"
            ),
        }
    }

    /// One sentence for IGES Start sections and reports.
    pub fn describe(&self, options: FitOptions) -> String {
        match self {
            VMethod::Interpolate => format!(
                "global B-spline interpolation (the paper: p={}, q={}, chord-length parameters averaged over rows and columns, averaged knots)",
                options.degree_u, options.degree_v
            ),
            VMethod::LeastSquares { control_rows } => format!(
                "interpolation along the lines (p={}, the paper's u parameters and knots) and least-squares approximation across them (q={}, {} control rows, parameters proportional to y, knots by P&T eq. 9.69)",
                options.degree_u, options.degree_v, control_rows
            ),
        }
    }
}

/// The default number of control rows of [`VMethod::LeastSquares`] for `lines` lines: a
/// quarter of the lines (rounded up), at least degree_v + 1. On the project's test grids (the
/// demo's real profile windows, 31 lines of a real areal map, white noise, a smooth sine) a
/// quarter held out better than half the lines, which come close to interpolating with the
/// knots of eq. 9.69 crowded at the ends and swing between lines; `surfscan fit --compare`
/// shows the figures for a given grid.
pub fn default_control_rows(lines: usize, degree_v: usize) -> usize {
    lines.div_ceil(4).max(degree_v + 1)
}

/// Why a surface cannot be made with the chosen method.
#[derive(Debug, Error, PartialEq)]
pub enum MethodError {
    /// The paper's fit (or its u half) failed.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// Control rows outside [degree_v + 1, lines].
    #[error("{got} control rows across {lines} lines: a least-squares surface of degree-v {degree_v} needs between {min} and {lines}; set the control rows in that range (`--v-control-rows`, or `v-control-rows` in `[fit]`)")]
    ControlRows {
        /// Control rows asked for.
        got: usize,
        /// Lines available.
        lines: usize,
        /// degree_v.
        degree_v: usize,
        /// degree_v + 1.
        min: usize,
    },
    /// The normal equations are not positive definite (lines at coincident y).
    #[error("the least-squares normal equations across the lines are singular ({control_rows} control rows, {lines} lines); use fewer control rows")]
    Singular {
        /// Control rows.
        control_rows: usize,
        /// Lines.
        lines: usize,
    },
}

/// Fits a row-major grid (µm, `y_mm.len() × cols`) with `method` across the lines.
/// [`VMethod::Interpolate`] is exactly [`super::fit_grid`].
pub fn fit_grid_with(
    pitch_x_mm: f64,
    y_mm: &[f64],
    heights_um: &[f64],
    cols: usize,
    options: FitOptions,
    method: VMethod,
) -> Result<FitResult, MethodError> {
    match method {
        VMethod::Interpolate => Ok(fit_grid(pitch_x_mm, y_mm, heights_um, cols, options)?),
        VMethod::LeastSquares { control_rows } => {
            approximate_v(pitch_x_mm, y_mm, heights_um, cols, options, control_rows)
        }
    }
}

/// Clamped knots for a least-squares fit (P&T eq. 9.68–9.69) of `params` with `poles` poles.
fn lsq_knots(params: &[f64], poles: usize, degree: usize) -> Vec<f64> {
    let m1 = params.len() as f64;
    let d = m1 / (poles - degree) as f64;
    let mut knots = vec![0.0; degree + 1];
    for j in 1..poles - degree {
        let jd = j as f64 * d;
        let i = jd.floor() as usize;
        let a = jd - i as f64;
        let lo = params.get(i.saturating_sub(1)).copied().unwrap_or(0.0);
        let hi = params.get(i).copied().unwrap_or(1.0);
        knots.push((1.0 - a) * lo + a * hi);
    }
    knots.extend(std::iter::repeat_n(1.0, degree + 1));
    knots
}

/// The least-squares surface of the module docs.
pub fn approximate_v(
    pitch_x_mm: f64,
    y_mm: &[f64],
    heights_um: &[f64],
    cols: usize,
    options: FitOptions,
    control_rows: usize,
) -> Result<FitResult, MethodError> {
    let rows = y_mm.len();
    let q = options.degree_v;
    if control_rows < q + 1 || control_rows > rows {
        // The paper's checks first, so a grid that cannot be fitted at all says why.
        fit_grid(pitch_x_mm, y_mm, heights_um, cols, options)?;
        return Err(MethodError::ControlRows {
            got: control_rows,
            lines: rows,
            degree_v: q,
            min: q + 1,
        });
    }
    let t0 = Instant::now();
    // The paper's fit validates the grid and gives the u parameters, knots and x poles.
    let paper = fit_grid(pitch_x_mm, y_mm, heights_um, cols, options)?;
    let p = options.degree_u;
    let knots_u = paper.surface.knots_u().to_vec();
    let lu_u = BandLu::collocation(p, &knots_u, &paper.params_u).map_err(|e| {
        FitError::SingularCollocation {
            direction: "u",
            index: e.index,
            pivot: e.pivot,
        }
    })?;
    let params_s = secs(t0);

    let t = Instant::now();
    let (y0, y1) = (y_mm[0], y_mm[rows - 1]);
    let mut params_v: Vec<f64> = y_mm.iter().map(|y| (y - y0) / (y1 - y0)).collect();
    params_v[0] = 0.0;
    params_v[rows - 1] = 1.0;
    let knots_v = lsq_knots(&params_v, control_rows, q);
    // Basis of every line: (first pole index, q + 1 values).
    let mut basis = vec![0.0; q + 1];
    let (mut left, mut right) = (vec![0.0; q + 1], vec![0.0; q + 1]);
    let lines_basis: Vec<(usize, Vec<f64>)> = params_v
        .iter()
        .map(|&v| {
            let s = find_span(q, &knots_v, control_rows, v);
            basis_funs(s, v, q, &knots_v, &mut basis, &mut left, &mut right);
            (s - q, basis.clone())
        })
        .collect();
    let mut ata = nalgebra::DMatrix::<f64>::zeros(control_rows, control_rows);
    for (first, b) in &lines_basis {
        for (r, br) in b.iter().enumerate() {
            for (c, bc) in b.iter().enumerate() {
                ata[(first + r, first + c)] += br * bc;
            }
        }
    }
    let chol = nalgebra::linalg::Cholesky::new(ata).ok_or(MethodError::Singular {
        control_rows,
        lines: rows,
    })?;
    let knots_factor_s = secs(t);

    // C = N_u⁻¹ Z, row by row, in mm.
    let t = Instant::now();
    let mut c: Vec<f64> = heights_um.iter().map(|h| h / 1000.0).collect();
    lu_u.solve_each_row(&mut c);
    let solve_u_s = secs(t);

    // Mᵀ C, then (MᵀM)⁻¹ for every column.
    let t = Instant::now();
    let mut rhs = nalgebra::DMatrix::<f64>::zeros(control_rows, cols);
    for ((first, b), row) in lines_basis.iter().zip(c.chunks_exact(cols)) {
        for (r, br) in b.iter().enumerate() {
            let mut out = rhs.row_mut(first + r);
            for (o, v) in out.iter_mut().zip(row) {
                *o += br * v;
            }
        }
    }
    drop(c);
    let z = chol.solve(&rhs);
    // x per column (the paper's), y per control row, z per pole.
    let px = paper.surface.row(0).x.to_vec();
    let py: Vec<f64> = (0..control_rows)
        .map(|j| {
            let greville = knots_v[j + 1..=j + q].iter().sum::<f64>() / q as f64;
            y0 + (y1 - y0) * greville
        })
        .collect();
    let pz: Vec<f64> = (0..control_rows)
        .flat_map(|j| (0..cols).map(move |i| (j, i)))
        .map(|ji| z[ji])
        .collect();
    let net = PoleNet::separable(px, py, pz).ok_or(FitError::GridShape {
        len: heights_um.len(),
        rows,
        cols,
    })?;
    let surface = NurbsSurface::try_from_net(p, q, knots_u, knots_v, cols, control_rows, net)
        .map_err(FitError::from)?;
    let solve_v_s = secs(t);
    Ok(FitResult {
        surface,
        params_u: paper.params_u,
        params_v,
        x0_mm: 0.0,
        timings: FitTimings {
            params_s,
            knots_factor_s,
            solve_u_s,
            solve_v_s,
        },
    })
}

fn secs(t: Instant) -> f64 {
    t.elapsed().as_secs_f64()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(rows: usize, cols: usize, f: impl Fn(f64, f64) -> f64) -> (Vec<f64>, Vec<f64>) {
        let y: Vec<f64> = (0..rows).map(|r| r as f64 * 0.01).collect();
        let z = (0..rows * cols)
            .map(|k| f((k % cols) as f64 * 0.002, y[k / cols]))
            .collect();
        (y, z)
    }

    #[test]
    fn interpolate_is_the_papers_fit_bit_for_bit() {
        let (y, z) = grid(8, 40, |x, y| (x * 50.0).sin() + (y * 70.0).cos());
        let a = fit_grid(0.002, &y, &z, 40, FitOptions::default()).unwrap();
        let b = fit_grid_with(
            0.002,
            &y,
            &z,
            40,
            FitOptions::default(),
            VMethod::Interpolate,
        )
        .unwrap();
        assert_eq!(a.surface, b.surface);
        assert_eq!(a.params_v, b.params_v);
    }

    #[test]
    fn a_surface_in_the_spline_space_is_reproduced_exactly() {
        // z cubic in y and smooth in x: the least-squares surface of degree 3 in v holds it
        // exactly, whatever the number of control rows (≥ 4), so the residual is rounding only.
        let f = |x: f64, y: f64| {
            (x * 40.0).sin() * (1.0 + 30.0 * y - 400.0 * y * y + 2000.0 * y * y * y)
        };
        let (y, z) = grid(21, 30, f);
        let options = FitOptions::degrees(5, 3);
        for rows in [4, 7, 12] {
            let r = approximate_v(0.002, &y, &z, 30, options, rows).unwrap();
            assert_eq!(r.surface.count_v(), rows);
            for (l, &v) in r.params_v.iter().enumerate() {
                let pts = r.surface.evaluate_grid(&r.params_u, &[v]);
                for (k, pt) in pts.iter().enumerate() {
                    assert!((pt[1] - y[l]).abs() < 1e-14, "y at line {l}: {}", pt[1]);
                    assert!((pt[0] - k as f64 * 0.002).abs() < 1e-13);
                    let want = z[l * 30 + k] / 1000.0;
                    assert!(
                        (pt[2] - want).abs() < 1e-12,
                        "{rows} rows, ({k}, {l}): {} vs {want}",
                        pt[2]
                    );
                }
            }
        }
    }

    #[test]
    fn the_residual_is_orthogonal_to_every_basis_function_across_lines() {
        // The least-squares condition itself: for every control row j and column k,
        // Σ_l M_j(v_l) (S(ū_k, v_l) − z_kl) = 0.
        let (y, z) = grid(17, 25, |x, y| {
            (x * 313.0).sin() * 7.0 + (y * 911.0).sin() * 5.0
        });
        let options = FitOptions::default();
        let r = approximate_v(0.002, &y, &z, 25, options, 8).unwrap();
        let knots = r.surface.knots_v();
        let q = options.degree_v;
        let mut sums = vec![0.0f64; 8 * 25];
        let mut basis = vec![0.0; q + 1];
        let (mut l1, mut r1) = (vec![0.0; q + 1], vec![0.0; q + 1]);
        for (l, &v) in r.params_v.iter().enumerate() {
            let pts = r.surface.evaluate_grid(&r.params_u, &[v]);
            let s = find_span(q, knots, 8, v);
            basis_funs(s, v, q, knots, &mut basis, &mut l1, &mut r1);
            for (b_i, b) in basis.iter().enumerate() {
                let j = s - q + b_i;
                for k in 0..25 {
                    sums[j * 25 + k] += b * (pts[k][2] - z[l * 25 + k] / 1000.0);
                }
            }
        }
        let worst = sums.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!(worst < 1e-15, "largest normal-equation residual {worst}");
    }

    #[test]
    fn control_rows_out_of_range_are_named() {
        let (y, z) = grid(10, 20, |x, _| x);
        let e = approximate_v(0.002, &y, &z, 20, FitOptions::default(), 5).unwrap_err();
        assert!(
            matches!(e, MethodError::ControlRows { got: 5, min: 6, .. }),
            "{e}"
        );
        let e = approximate_v(0.002, &y, &z, 20, FitOptions::default(), 11).unwrap_err();
        assert!(e.to_string().contains("between 6 and 10"), "{e}");
        // Named both ways it can be given: `fit`'s flag and the station's key.
        assert!(
            e.to_string().contains("--v-control-rows") && e.to_string().contains("[fit]"),
            "{e}"
        );
        assert_eq!(default_control_rows(31, 5), 8);
        assert_eq!(default_control_rows(8, 5), 6);
        assert_eq!(default_control_rows(31, 3), 8);
        assert_eq!(default_control_rows(100, 3), 25);
    }
}
