//! The paper's parameters and knots: averaged chord-length parameters (P&T eq. 9.5 with A9.3)
//! from the fitter's running sums, and clamped knots by averaging (eq. 9.8).
//!
//! Layer 1 (pure logic): depends on the fitter's column chords only.

use super::incremental::next_column_chords;

/// ū_k: mean over rows of the normalised cumulative chords; exactly 0 and 1 at the ends.
pub(super) fn average_params_u(sum_u: &[f64], rows: usize) -> Vec<f64> {
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

/// v̄_l: mean over columns of each column's cumulative chord normalised by its total
/// (`totals`, the last line's cumulative chords). The cumulative chords of each line are
/// recomputed from the heights in mm (`z_mm`, row-major, `y_mm.len()` rows of `cols`) one row
/// at a time, as the lines' arrival computed them.
#[inline(always)]
pub(super) fn average_params_v(
    z_mm: &[f64],
    y_mm: &[f64],
    cols: usize,
    totals: &[f64],
) -> Vec<f64> {
    let c = cols as f64;
    let mut cum = vec![0.0f64; cols];
    let mut next = vec![0.0f64; cols];
    let mut out = Vec::with_capacity(y_mm.len());
    if !y_mm.is_empty() {
        out.push(sum_ratios(&cum, totals) / c);
    }
    let rows: Vec<&[f64]> = z_mm.chunks_exact(cols).collect();
    for (pair, y) in rows.windows(2).zip(y_mm.windows(2)) {
        let dy = y[1] - y[0];
        next_column_chords(&mut next, &cum, pair[1], pair[0], dy * dy);
        std::mem::swap(&mut cum, &mut next);
        out.push(sum_ratios(&cum, totals) / c);
    }
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
pub(super) fn sum_ratios(a: &[f64], t: &[f64]) -> f64 {
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
