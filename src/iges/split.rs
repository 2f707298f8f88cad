//! Exact splitting of a B-spline surface along v by knot insertion (P&T A5.1 applied until
//! the split knot has multiplicity q, as in A5.4's decomposition): the two patches share the
//! pole row at the split and together evaluate exactly like the original.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] only.
//!
//! Each insertion changes at most q pole rows next to the split and shifts the rows above it
//! by one, so the rows being changed are held apart and every other row is
//! read from the original net: splitting a net of any size costs the two patches and a few
//! rows, never a copy of the net per insertion.

use crate::nurbs::{NurbsSurface, PoleNet, PoleRow};

/// The pole rows of a net during knot insertion: rows `[0, start)` are the original's rows
/// `[0, start)`, rows `[start, start + changed.len())` are held here, and the rows after them
/// are the original's from `resume` on.
struct RowWindow<'a> {
    original: &'a NurbsSurface,
    start: usize,
    changed: Vec<Vec<[f64; 3]>>,
    resume: usize,
}

/// A row of the window: one of the original net's, or one held apart.
enum WindowRow<'a> {
    Original(PoleRow<'a>),
    Changed(&'a [[f64; 3]]),
}

impl WindowRow<'_> {
    fn get(&self, k: usize) -> [f64; 3] {
        match self {
            WindowRow::Original(row) => row.get(k),
            WindowRow::Changed(row) => row[k],
        }
    }

    fn to_vec(&self) -> Vec<[f64; 3]> {
        match self {
            WindowRow::Original(row) => (0..row.len()).map(|k| row.get(k)).collect(),
            WindowRow::Changed(row) => row.to_vec(),
        }
    }
}

impl<'a> RowWindow<'a> {
    fn new(surface: &'a NurbsSurface) -> RowWindow<'a> {
        RowWindow {
            original: surface,
            start: 0,
            changed: Vec::new(),
            resume: 0,
        }
    }

    fn len(&self) -> usize {
        self.start + self.changed.len() + self.original.count_v() - self.resume
    }

    fn row(&self, i: usize) -> WindowRow<'_> {
        if i < self.start {
            WindowRow::Original(self.original.row(i))
        } else if i < self.start + self.changed.len() {
            WindowRow::Changed(&self.changed[i - self.start])
        } else {
            let r = i - self.start - self.changed.len() + self.resume;
            WindowRow::Original(self.original.row(r))
        }
    }

    /// Inserts `v` once into `knots` (span `k`: `knots[k] <= v < knots[k + 1]`) for degree
    /// `q`: new row i is row i for i + q <= k, row i − 1 for i > k, and the blend
    /// a·row i + (1 − a)·row (i − 1) with a = (v − knots[i]) / (knots[i + q] − knots[i])
    /// between (P&T A5.1).
    fn insert(&mut self, knots: &[f64], k: usize, q: usize, v: f64) {
        let blend_lo = (k + 1).saturating_sub(q);
        // While every row is still the original's in place (nothing held, nothing shifted),
        // the window is the blended rows alone; after that it grows to cover what it held.
        let untouched = self.changed.is_empty() && self.resume == self.start;
        let lo = if untouched {
            blend_lo
        } else {
            self.start.min(blend_lo)
        };
        let hi = (self.start + self.changed.len() + 1).max(k + 1);
        let width = self.original.count_u();
        let mut changed = Vec::with_capacity(hi - lo);
        for i in lo..hi {
            if i + q <= k {
                changed.push(self.row(i).to_vec());
            } else if i > k {
                changed.push(self.row(i - 1).to_vec());
            } else {
                let a = (v - knots[i]) / (knots[i + q] - knots[i]);
                let (pr, rr) = (self.row(i), self.row(i - 1));
                let row: Vec<[f64; 3]> = (0..width)
                    .map(|c| {
                        let (p, r) = (pr.get(c), rr.get(c));
                        [
                            a * p[0] + (1.0 - a) * r[0],
                            a * p[1] + (1.0 - a) * r[1],
                            a * p[2] + (1.0 - a) * r[2],
                        ]
                    })
                    .collect();
                changed.push(row);
            }
        }
        // New row `hi` is old row `hi − 1`, which lies past the window: in the original at
        // `hi − 1 − (start + changed) + resume`.
        self.resume += hi - 1 - self.start - self.changed.len();
        self.start = lo;
        self.changed = changed;
    }

    /// Rows `[from, to)` as one net: the original's rows as they are laid out there (x per
    /// column, y per row where that holds), the rows held apart laid out likewise where their
    /// bits allow.
    fn net(&self, from: usize, to: usize) -> PoleNet {
        let column_x = self.original.net().column_x().to_vec();
        let mut out = PoleNet::with_columns(column_x, to - from);
        for i in from..to {
            match self.row(i) {
                WindowRow::Original(row) => out.push_row(row),
                WindowRow::Changed(row) => out.push_poles(row),
            }
        }
        out
    }
}

/// The v knot vectors of the two patches of a split at `v_split` (see [`split_v`]), found
/// from the knots alone: the insertions they take, the lower patch's pole rows (`a`) and the
/// rows after all insertions (`rows`).
struct SplitKnots {
    /// Span of each insertion, in order.
    spans: Vec<usize>,
    /// The knot vector before each insertion, in order.
    knots_before: Vec<Vec<f64>>,
    lower: Vec<f64>,
    upper: Vec<f64>,
    a: usize,
    rows: usize,
}

fn split_knots(knots_v: &[f64], q: usize, count_v: usize, v_split: f64) -> Option<SplitKnots> {
    let mut knots = knots_v.to_vec();
    let (lo, hi) = (knots[q], knots[count_v]);
    if !(v_split > lo && v_split < hi) {
        return None;
    }
    let (mut spans, mut knots_before) = (Vec::new(), Vec::new());
    loop {
        let mult = knots.iter().filter(|&&k| k == v_split).count();
        if mult >= q {
            break;
        }
        // Span k: knots[k] <= v < knots[k+1].
        let k = knots.iter().rposition(|&t| t <= v_split)?;
        spans.push(k);
        knots_before.push(knots.clone());
        knots.insert(k + 1, v_split);
    }
    let a = knots.iter().position(|&t| t == v_split)?;
    let mut lower = knots[..a + q].to_vec();
    lower.push(v_split);
    let mut upper = vec![v_split];
    upper.extend_from_slice(&knots[a..]);
    Some(SplitKnots {
        rows: count_v + spans.len(),
        spans,
        knots_before,
        lower,
        upper,
        a,
    })
}

/// Which patch of a split to build.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// v ≤ v_split.
    Lower,
    /// v ≥ v_split.
    Upper,
}

/// The patches of `surface` split at `v_split` that `want` asks for, each `None` unless
/// asked for or when `v_split` is not strictly inside the domain.
fn split_sides(
    surface: &NurbsSurface,
    v_split: f64,
    want: [bool; 2],
) -> Option<[Option<NurbsSurface>; 2]> {
    let q = surface.degree_v();
    let nu = surface.count_u();
    let plan = split_knots(surface.knots_v(), q, surface.count_v(), v_split)?;
    let mut rows = RowWindow::new(surface);
    for (&k, knots) in plan.spans.iter().zip(&plan.knots_before) {
        rows.insert(knots, k, q, v_split);
    }
    let (a, n) = (plan.a, plan.rows);
    debug_assert_eq!(rows.len(), n);
    let lower = if want[0] {
        Some(
            NurbsSurface::try_from_net(
                surface.degree_u(),
                q,
                surface.knots_u().to_vec(),
                plan.lower,
                nu,
                a,
                rows.net(0, a),
            )
            .ok()?,
        )
    } else {
        None
    };
    let upper = if want[1] {
        Some(
            NurbsSurface::try_from_net(
                surface.degree_u(),
                q,
                surface.knots_u().to_vec(),
                plan.upper,
                nu,
                n + 1 - a,
                rows.net(a - 1, n),
            )
            .ok()?,
        )
    } else {
        None
    };
    Some([lower, upper])
}

/// Splits `surface` at the interior v knot `v_split` (which must lie strictly inside the v
/// domain). Returns the lower (v ≤ v_split) and upper (v ≥ v_split) patches, each keeping the
/// original parameter values, or `None` when `v_split` is not strictly inside the domain.
pub fn split_v(surface: &NurbsSurface, v_split: f64) -> Option<(NurbsSurface, NurbsSurface)> {
    let [lower, upper] = split_sides(surface, v_split, [true, true])?;
    Some((lower?, upper?))
}

/// One patch of [`split_v`] (the same bits), without building the other.
pub fn split_v_side(surface: &NurbsSurface, v_split: f64, side: Side) -> Option<NurbsSurface> {
    let want = [side == Side::Lower, side == Side::Upper];
    let [lower, upper] = split_sides(surface, v_split, want)?;
    match side {
        Side::Lower => lower,
        Side::Upper => upper,
    }
}

/// The interior v knot nearest the middle of the pole rows, where [`split_v_middle`] splits.
fn middle_knot(knots: &[f64], q: usize, n: usize) -> Option<f64> {
    let (lo, hi) = (knots[q], knots[n]);
    let mid = (q + 1 + n) / 2;
    let interior: Vec<usize> = (q + 1..n)
        .filter(|&i| knots[i] > lo && knots[i] < hi)
        .collect();
    let best = interior.iter().min_by_key(|&&i| i.abs_diff(mid))?;
    Some(knots[*best])
}

/// The shape of a patch: what the line bound of its entity depends on.
#[derive(Debug, Clone, PartialEq)]
pub struct PatchShape {
    /// The v knot vector.
    pub knots_v: Vec<f64>,
    /// Pole rows along v.
    pub count_v: usize,
}

/// The shapes of both halves of [`split_v_middle`] of a surface of this v degree and shape
/// (the knots alone decide them), with the knot split at; `None` without an interior knot.
pub fn split_middle_shapes(q: usize, shape: &PatchShape) -> Option<(f64, PatchShape, PatchShape)> {
    let v = middle_knot(&shape.knots_v, q, shape.count_v)?;
    let plan = split_knots(&shape.knots_v, q, shape.count_v, v)?;
    let lower = PatchShape {
        knots_v: plan.lower,
        count_v: plan.a,
    };
    let upper = PatchShape {
        knots_v: plan.upper,
        count_v: plan.rows + 1 - plan.a,
    };
    Some((v, lower, upper))
}

/// One half of [`split_v_middle`] (the same bits), without building the other.
pub fn split_v_middle_side(surface: &NurbsSurface, side: Side) -> Option<NurbsSurface> {
    let v = middle_knot(surface.knots_v(), surface.degree_v(), surface.count_v())?;
    split_v_side(surface, v, side)
}

/// Splits at the interior v knot nearest the middle of the pole rows, or `None` when the
/// surface has no interior v knot (a single Bézier span cannot be split this way).
pub fn split_v_middle(surface: &NurbsSurface) -> Option<(NurbsSurface, NurbsSurface)> {
    let v = middle_knot(surface.knots_v(), surface.degree_v(), surface.count_v())?;
    split_v(surface, v)
}
