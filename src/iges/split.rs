//! Exact splitting of a B-spline surface along v by knot insertion (P&T A5.1 applied until
//! the split knot has multiplicity q, as in A5.4's decomposition): the two patches share the
//! pole row at the split and together evaluate exactly like the original.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] only.

use crate::nurbs::NurbsSurface;

/// Splits `surface` at the interior v knot `v_split` (which must lie strictly inside the v
/// domain). Returns the lower (v ≤ v_split) and upper (v ≥ v_split) patches, each keeping the
/// original parameter values, or `None` when `v_split` is not strictly inside the domain.
pub fn split_v(surface: &NurbsSurface, v_split: f64) -> Option<(NurbsSurface, NurbsSurface)> {
    let q = surface.degree_v();
    let nu = surface.count_u();
    let mut knots = surface.knots_v().to_vec();
    let mut rows: Vec<Vec<[f64; 3]>> = surface
        .poles()
        .chunks_exact(nu)
        .map(|r| r.to_vec())
        .collect();
    let (lo, hi) = (knots[q], knots[rows.len()]);
    if !(v_split > lo && v_split < hi) {
        return None;
    }
    loop {
        let mult = knots.iter().filter(|&&k| k == v_split).count();
        if mult >= q {
            break;
        }
        // Span k: knots[k] <= v < knots[k+1].
        let k = knots.iter().rposition(|&t| t <= v_split)?;
        let mut new_rows = Vec::with_capacity(rows.len() + 1);
        for i in 0..=rows.len() {
            if i + q <= k {
                new_rows.push(rows[i].clone());
            } else if i > k {
                new_rows.push(rows[i - 1].clone());
            } else {
                let a = (v_split - knots[i]) / (knots[i + q] - knots[i]);
                let row: Vec<[f64; 3]> = rows[i]
                    .iter()
                    .zip(&rows[i - 1])
                    .map(|(p, r)| {
                        [
                            a * p[0] + (1.0 - a) * r[0],
                            a * p[1] + (1.0 - a) * r[1],
                            a * p[2] + (1.0 - a) * r[2],
                        ]
                    })
                    .collect();
                new_rows.push(row);
            }
        }
        knots.insert(k + 1, v_split);
        rows = new_rows;
    }
    let a = knots.iter().position(|&t| t == v_split)?;
    let mut lower_knots = knots[..a + q].to_vec();
    lower_knots.push(v_split);
    let mut upper_knots = vec![v_split];
    upper_knots.extend_from_slice(&knots[a..]);
    let flat = |rs: &[Vec<[f64; 3]>]| rs.iter().flatten().copied().collect::<Vec<_>>();
    let lower = NurbsSurface::try_new(
        surface.degree_u(),
        q,
        surface.knots_u().to_vec(),
        lower_knots,
        nu,
        a,
        flat(&rows[..a]),
    )
    .ok()?;
    let upper = NurbsSurface::try_new(
        surface.degree_u(),
        q,
        surface.knots_u().to_vec(),
        upper_knots,
        nu,
        rows.len() + 1 - a,
        flat(&rows[a - 1..]),
    )
    .ok()?;
    Some((lower, upper))
}

/// Splits at the interior v knot nearest the middle of the pole rows, or `None` when the
/// surface has no interior v knot (a single Bézier span cannot be split this way).
pub fn split_v_middle(surface: &NurbsSurface) -> Option<(NurbsSurface, NurbsSurface)> {
    let q = surface.degree_v();
    let n = surface.count_v();
    let knots = surface.knots_v();
    let (lo, hi) = (knots[q], knots[n]);
    let mid = (q + 1 + n) / 2;
    let interior: Vec<usize> = (q + 1..n)
        .filter(|&i| knots[i] > lo && knots[i] < hi)
        .collect();
    let best = interior.iter().min_by_key(|&&i| i.abs_diff(mid))?;
    split_v(surface, knots[*best])
}
