//! Banded collocation matrices and their LU factorisation without pivoting.
//!
//! B-spline collocation matrices are totally positive (de Boor), so Gauss elimination without
//! pivoting is stable and keeps the band: the factors are stored in the matrix's own band.
//! One factorisation serves every right-hand side of a direction.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] (basis functions) and the fit's SIMD
//! dispatch only.

use super::simd;
use crate::nurbs::{basis_funs, find_span};

/// Right-hand sides solved side by side by [`BandLu::solve_each_row`].
const LANES: usize = 8;

/// A square banded matrix with `lower` sub- and `upper` super-diagonals, row-major band storage:
/// entry (i, j) lives at `i * width + (j + lower - i)`. After factoring it holds the unit
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

    /// Solves A x = b in place for [`LANES`] interleaved right-hand sides (lane l of every
    /// entry belongs to system l). Each lane sees exactly the operations of
    /// [`BandLu::solve_in_place`], in the same order, so results are bit-identical to it.
    #[inline(always)]
    fn solve_lanes(&self, b: &mut [[f64; LANES]]) {
        let (n, lo, up, w) = (self.n, self.lower, self.upper, self.width);
        let b = &mut b[..n];
        for i in 1..n {
            let j0 = i.saturating_sub(lo);
            let row = &self.band[i * w + j0 + lo - i..i * w + lo];
            let mut s = b[i];
            for (a, x) in row.iter().zip(&b[j0..i]) {
                for l in 0..LANES {
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
                for l in 0..LANES {
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
    /// (one system per row). The factor is the same for every row, so rows are solved
    /// eight at a time, interleaved: the substitution chains of a block run side by side
    /// in vector registers (a short last block is padded with zero systems). Results equal
    /// [`BandLu::solve_in_place`] per row, bit for bit.
    pub fn solve_each_row(&self, data: &mut [f64]) {
        let n = self.n;
        if n == 0 {
            return;
        }
        let whole = data.len() / n * n;
        let data = &mut data[..whole];
        simd::wide(|| {
            let mut buf = vec![[0.0f64; LANES]; n];
            for block in data.chunks_mut(LANES * n) {
                let used = block.len() / n;
                if used < LANES {
                    buf.fill([0.0; LANES]);
                }
                for (l, row) in block.chunks_exact(n).enumerate() {
                    for (b, &v) in buf.iter_mut().zip(row) {
                        b[l] = v;
                    }
                }
                self.solve_lanes(&mut buf);
                for (l, row) in block.chunks_exact_mut(n).enumerate() {
                    for (v, b) in row.iter_mut().zip(&buf) {
                        *v = b[l];
                    }
                }
            }
        });
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
        simd::wide(|| {
            let mut terms: Vec<(f64, usize)> = Vec::with_capacity(lo.max(up));
            for i in 1..n {
                let (before, rest) = data.split_at_mut(i * cols);
                terms.clear();
                for j in i.saturating_sub(lo)..i {
                    let a = self.at(i, j);
                    if a != 0.0 {
                        terms.push((a, j * cols));
                    }
                }
                subtract_rows(&mut rest[..cols], before, &terms, None);
            }
            for i in (0..n).rev() {
                let (head, after) = data.split_at_mut((i + 1) * cols);
                let target = &mut head[i * cols..];
                let j1 = (i + up).min(n - 1);
                terms.clear();
                for j in i + 1..=j1 {
                    let a = self.at(i, j);
                    if a != 0.0 {
                        terms.push((a, (j - i - 1) * cols));
                    }
                }
                subtract_rows(target, after, &terms, Some(self.recip_pivot[i]));
                done(i, target);
            }
        });
    }
}

/// Columns per block of [`subtract_rows`]: the target block stays in L1 while every source
/// row is subtracted from it.
const ROW_BLOCK: usize = 512;

/// `target[c] = ((target[c] − a₀·s₀[c]) − a₁·s₁[c] − …) · scale` for every column c, where
/// term (a, offset) names the source row `rows[offset..offset + target.len()]`; the
/// terms subtracted one at a time in the order given and `scale` applied last, exactly as
/// subtracting whole rows one after another would (so the bits are the same); blocked so
/// the target is read and written once per block instead of once per term.
#[inline(always)]
fn subtract_rows(target: &mut [f64], rows: &[f64], terms: &[(f64, usize)], scale: Option<f64>) {
    let cols = target.len();
    let mut start = 0;
    while start < cols {
        let end = (start + ROW_BLOCK).min(cols);
        let t = &mut target[start..end];
        for &(a, offset) in terms {
            for (x, &s) in t.iter_mut().zip(&rows[offset + start..offset + end]) {
                *x -= a * s;
            }
        }
        if let Some(rp) = scale {
            for x in t.iter_mut() {
                *x *= rp;
            }
        }
        start = end;
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

    /// A degree-5 collocation factor on `n` uneven parameters (averaged knots).
    fn quintic(n: usize) -> BandLu {
        let p = 5;
        let mut params: Vec<f64> = (0..n)
            .map(|k| k as f64 + 0.4 * ((k * 37 % 11) as f64 / 11.0))
            .collect();
        let last = params[n - 1];
        for t in params.iter_mut() {
            *t /= last;
        }
        params[0] = 0.0;
        let mut knots = vec![0.0; p + 1];
        for j in 1..n - p {
            knots.push(params[j..j + p].iter().sum::<f64>() / p as f64);
        }
        knots.extend(std::iter::repeat_n(1.0, p + 1));
        BandLu::collocation(p, &knots, &params).unwrap()
    }

    fn rhs(rows: usize, n: usize) -> Vec<f64> {
        (0..rows * n)
            .map(|k| ((k * 7919 % 1013) as f64 - 506.0) * 1.37e-4)
            .collect()
    }

    #[test]
    fn interleaved_row_solves_are_bit_identical_to_single_solves() {
        let n = 57;
        let lu = quintic(n);
        // Full blocks, a padded short block, and fewer rows than one block.
        for rows in [1, 3, LANES - 1, LANES, LANES + 1, 3 * LANES + 7] {
            let mut block = rhs(rows, n);
            let mut single = block.clone();
            lu.solve_each_row(&mut block);
            for row in single.chunks_exact_mut(n) {
                lu.solve_in_place(row);
            }
            let same = block
                .iter()
                .zip(&single)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(
                same,
                "{rows} rows: interleaved solve differs from single solves"
            );
        }
    }

    #[test]
    fn column_solves_are_bit_identical_to_single_solves() {
        let n = 40;
        let lu = quintic(n);
        // More columns than one block of subtract_rows, and a ragged last block.
        let cols = ROW_BLOCK + 77;
        let data = rhs(n, cols);
        let mut block = data.clone();
        let mut order = Vec::new();
        lu.solve_rows_in_place_then(&mut block, cols, |i, row| {
            assert_eq!(row.len(), cols);
            order.push(i);
        });
        assert_eq!(order, (0..n).rev().collect::<Vec<_>>());
        for c in [0, 1, ROW_BLOCK - 1, ROW_BLOCK, cols - 1] {
            let mut col: Vec<f64> = (0..n).map(|i| data[i * cols + c]).collect();
            lu.solve_in_place(&mut col);
            for (i, v) in col.iter().enumerate() {
                assert_eq!(
                    v.to_bits(),
                    block[i * cols + c].to_bits(),
                    "column {c}, row {i}"
                );
            }
        }
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
