//! Banded collocation matrices and their LU factorisation without pivoting.
//!
//! B-spline collocation matrices are totally positive (de Boor), so Gauss elimination without
//! pivoting is stable and keeps the band: the factors are stored in the matrix's own band.
//! One factorisation serves every right-hand side of a direction.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] (basis functions) only.

use crate::nurbs::{basis_funs, find_span};

/// A square banded matrix with `lower` sub- and `upper` super-diagonals, row-major band storage:
/// entry (i, j) lives at `i * width + (j + lower - i)`. After [`BandLu::factor`] it holds the unit
/// lower factor L below the diagonal and U on and above it.
#[derive(Debug, Clone)]
pub struct BandLu {
    n: usize,
    lower: usize,
    upper: usize,
    width: usize,
    band: Vec<f64>,
    /// 1 / U(i, i).
    recip_pivot: Vec<f64>,
}

/// A pivot that is zero or not finite: the parameters and knots do not give a solvable system.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZeroPivot {
    /// Row of the pivot.
    pub index: usize,
    /// Its value.
    pub pivot: f64,
}

impl BandLu {
    /// Builds the collocation matrix `N_{i,degree}(params[k])` (row k, column i) for a clamped
    /// knot vector, then factors it. `params.len()` is the number of poles; `knots` has
    /// `params.len() + degree + 1` values (the caller guarantees both).
    pub fn collocation(degree: usize, knots: &[f64], params: &[f64]) -> Result<BandLu, ZeroPivot> {
        let n = params.len();
        let mut spans = Vec::with_capacity(n);
        let (mut lower, mut upper) = (0usize, 0usize);
        for (k, &t) in params.iter().enumerate() {
            let s = find_span(degree, knots, n, t);
            lower = lower.max(k.saturating_sub(s - degree));
            upper = upper.max(s.saturating_sub(k));
            spans.push(s);
        }
        let width = lower + upper + 1;
        let mut band = vec![0.0; n * width];
        let mut basis = vec![0.0; degree + 1];
        let mut left = vec![0.0; degree + 1];
        let mut right = vec![0.0; degree + 1];
        for (k, (&t, &s)) in params.iter().zip(&spans).enumerate() {
            basis_funs(s, t, degree, knots, &mut basis, &mut left, &mut right);
            for (r, &b) in basis.iter().enumerate() {
                let j = s - degree + r;
                band[k * width + j + lower - k] = b;
            }
        }
        let mut lu = BandLu {
            n,
            lower,
            upper,
            width,
            band,
            recip_pivot: vec![0.0; n],
        };
        lu.factor()?;
        Ok(lu)
    }

    /// Number of sub-diagonals.
    pub fn lower(&self) -> usize {
        self.lower
    }

    /// Number of super-diagonals.
    pub fn upper(&self) -> usize {
        self.upper
    }

    #[inline]
    fn at(&self, i: usize, j: usize) -> f64 {
        self.band[i * self.width + j + self.lower - i]
    }

    /// Doolittle elimination without pivoting inside the band.
    fn factor(&mut self) -> Result<(), ZeroPivot> {
        let (n, lo, up, w) = (self.n, self.lower, self.upper, self.width);
        for k in 0..n {
            let pivot = self.band[k * w + lo];
            if pivot == 0.0 || !pivot.is_finite() {
                return Err(ZeroPivot { index: k, pivot });
            }
            let rp = 1.0 / pivot;
            self.recip_pivot[k] = rp;
            let last_row = (k + lo).min(n - 1);
            let last_col = (k + up).min(n - 1);
            for i in k + 1..=last_row {
                let l = self.band[i * w + k + lo - i] * rp;
                self.band[i * w + k + lo - i] = l;
                if l != 0.0 {
                    for j in k + 1..=last_col {
                        let ukj = self.band[k * w + j + lo - k];
                        self.band[i * w + j + lo - i] -= l * ukj;
                    }
                }
            }
        }
        Ok(())
    }

    /// Solves A x = b in place for one contiguous right-hand side of length n.
    pub fn solve_in_place(&self, b: &mut [f64]) {
        let (n, lo, up, w) = (self.n, self.lower, self.upper, self.width);
        let b = &mut b[..n];
        for i in 1..n {
            let j0 = i.saturating_sub(lo);
            let row = &self.band[i * w + j0 + lo - i..i * w + lo];
            let mut s = b[i];
            for (a, x) in row.iter().zip(&b[j0..i]) {
                s -= a * x;
            }
            b[i] = s;
        }
        for i in (0..n).rev() {
            let j1 = (i + up).min(n - 1);
            let row = &self.band[i * w + lo + 1..i * w + lo + 1 + (j1 - i)];
            let mut s = b[i];
            for (a, x) in row.iter().zip(&b[i + 1..=j1]) {
                s -= a * x;
            }
            b[i] = s * self.recip_pivot[i];
        }
    }

    /// Solves A x = b in place for four interleaved right-hand sides (lane l of every entry
    /// belongs to system l). Each lane sees exactly the operations of
    /// [`BandLu::solve_in_place`], so results are bit-identical to it.
    fn solve_lanes(&self, b: &mut [[f64; 4]]) {
        let (n, lo, up, w) = (self.n, self.lower, self.upper, self.width);
        let b = &mut b[..n];
        for i in 1..n {
            let j0 = i.saturating_sub(lo);
            let row = &self.band[i * w + j0 + lo - i..i * w + lo];
            let mut s = b[i];
            for (a, x) in row.iter().zip(&b[j0..i]) {
                for l in 0..4 {
                    s[l] -= a * x[l];
                }
            }
            b[i] = s;
        }
        for i in (0..n).rev() {
            let j1 = (i + up).min(n - 1);
            let row = &self.band[i * w + lo + 1..i * w + lo + 1 + (j1 - i)];
            let mut s = b[i];
            for (a, x) in row.iter().zip(&b[i + 1..=j1]) {
                for l in 0..4 {
                    s[l] -= a * x[l];
                }
            }
            let rp = self.recip_pivot[i];
            for v in s.iter_mut() {
                *v *= rp;
            }
            b[i] = s;
        }
    }

    /// Solves A x = b for every contiguous row of length n of the row-major block `data`
    /// (one system per row). Rows are solved four at a time, interleaved, so the four
    /// substitution chains run in parallel; results equal [`BandLu::solve_in_place`] per row.
    pub fn solve_each_row(&self, data: &mut [f64]) {
        let n = self.n;
        let mut buf = vec![[0.0f64; 4]; n];
        let mut quads = data.chunks_exact_mut(4 * n);
        for quad in &mut quads {
            let (r0, rest) = quad.split_at_mut(n);
            let (r1, rest) = rest.split_at_mut(n);
            let (r2, r3) = rest.split_at_mut(n);
            for (k, b) in buf.iter_mut().enumerate() {
                *b = [r0[k], r1[k], r2[k], r3[k]];
            }
            self.solve_lanes(&mut buf);
            for (k, b) in buf.iter().enumerate() {
                r0[k] = b[0];
                r1[k] = b[1];
                r2[k] = b[2];
                r3[k] = b[3];
            }
        }
        for row in quads.into_remainder().chunks_exact_mut(n) {
            self.solve_in_place(row);
        }
    }

    /// Solves A X = B in place where B is row-major with n rows of `cols` values: every
    /// column is a right-hand side. Rows are combined whole, so memory is read sequentially.
    pub fn solve_rows_in_place(&self, data: &mut [f64], cols: usize) {
        self.solve_rows_in_place_then(data, cols, |_, _| {});
    }

    /// As [`BandLu::solve_rows_in_place`], calling `done(i, row)` as soon as row i of the
    /// solution is final (rows are finished last to first), while it is still in cache.
    pub fn solve_rows_in_place_then(
        &self,
        data: &mut [f64],
        cols: usize,
        mut done: impl FnMut(usize, &[f64]),
    ) {
        let (n, lo, up) = (self.n, self.lower, self.upper);
        if cols == 0 {
            return;
        }
        let data = &mut data[..n * cols];
        for i in 1..n {
            let (before, rest) = data.split_at_mut(i * cols);
            let target = &mut rest[..cols];
            for j in i.saturating_sub(lo)..i {
                let a = self.at(i, j);
                if a != 0.0 {
                    let src = &before[j * cols..(j + 1) * cols];
                    for (t, s) in target.iter_mut().zip(src) {
                        *t -= a * s;
                    }
                }
            }
        }
        for i in (0..n).rev() {
            let (head, after) = data.split_at_mut((i + 1) * cols);
            let target = &mut head[i * cols..];
            let j1 = (i + up).min(n - 1);
            for j in i + 1..=j1 {
                let a = self.at(i, j);
                if a != 0.0 {
                    let src = &after[(j - i - 1) * cols..(j - i) * cols];
                    for (t, s) in target.iter_mut().zip(src) {
                        *t -= a * s;
                    }
                }
            }
            let rp = self.recip_pivot[i];
            for t in target.iter_mut() {
                *t *= rp;
            }
            done(i, target);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dense reference: Gaussian elimination with partial pivoting (textbook index form).
    #[allow(clippy::needless_range_loop)]
    fn dense_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
        let n = b.len();
        for k in 0..n {
            let p = (k..n)
                .max_by(|&x, &y| a[x][k].abs().total_cmp(&a[y][k].abs()))
                .unwrap();
            a.swap(k, p);
            b.swap(k, p);
            for i in k + 1..n {
                let f = a[i][k] / a[k][k];
                for j in k..n {
                    a[i][j] -= f * a[k][j];
                }
                b[i] -= f * b[k];
            }
        }
        let mut x = vec![0.0; n];
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|j| a[i][j] * x[j]).sum();
            x[i] = (b[i] - s) / a[i][i];
        }
        x
    }

    #[test]
    fn banded_solves_match_dense_pivoted_elimination() {
        // Cubic, 9 uneven parameters, averaged knots.
        let params = [0.0, 0.05, 0.2, 0.3, 0.45, 0.6, 0.8, 0.9, 1.0];
        let p = 3;
        let mut knots = vec![0.0; p + 1];
        for j in 1..params.len() - p {
            knots.push(params[j..j + p].iter().sum::<f64>() / p as f64);
        }
        knots.extend(std::iter::repeat_n(1.0, p + 1));
        let lu = BandLu::collocation(p, &knots, &params).unwrap();
        let n = params.len();
        let mut dense = vec![vec![0.0; n]; n];
        for (k, &t) in params.iter().enumerate() {
            let s = find_span(p, &knots, n, t);
            let (mut b, mut l, mut r) = ([0.0; 4], [0.0; 4], [0.0; 4]);
            basis_funs(s, t, p, &knots, &mut b, &mut l, &mut r);
            for q in 0..=p {
                dense[k][s - p + q] = b[q];
            }
        }
        let rhs: Vec<f64> = (0..n).map(|i| ((i * 7 + 3) % 5) as f64 - 1.5).collect();
        let expect = dense_solve(dense, rhs.clone());
        let mut x = rhs.clone();
        lu.solve_in_place(&mut x);
        for (a, e) in x.iter().zip(&expect) {
            assert!((a - e).abs() < 1e-12, "{a} vs {e}");
        }
        // Several right-hand sides as rows (four interleaved plus a remainder).
        let mut rows_block: Vec<f64> = (0..6)
            .flat_map(|r| rhs.iter().map(move |v| v * (r as f64 - 2.0)))
            .collect();
        lu.solve_each_row(&mut rows_block);
        for (r, row) in rows_block.chunks_exact(n).enumerate() {
            for (a, e) in row.iter().zip(&expect) {
                assert!((a - e * (r as f64 - 2.0)).abs() < 1e-12);
            }
        }
        // Several right-hand sides as columns of a row-major block.
        let cols = 3;
        let mut block = vec![0.0; n * cols];
        for i in 0..n {
            for c in 0..cols {
                block[i * cols + c] = rhs[i] * (c as f64 + 1.0);
            }
        }
        lu.solve_rows_in_place(&mut block, cols);
        for i in 0..n {
            for c in 0..cols {
                assert!((block[i * cols + c] - expect[i] * (c as f64 + 1.0)).abs() < 1e-12);
            }
        }
    }
}
