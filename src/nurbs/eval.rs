//! Evaluation of B-spline curves and of [`NurbsSurface`]: knot span search (P&T A2.1), the
//! non-vanishing basis functions (A2.2), surface points (A3.5), iso-parametric curves and a
//! fast path for a whole grid of parameters.
//!
//! Layer 0 (vocabulary): depends only on the surface type in [`crate::nurbs`]; no I/O.
//! Parameters outside the knot range are clamped to it, so evaluation never panics.

use super::NurbsSurface;

/// Largest supported degree for the stack buffers used while evaluating.
const MAX_STACK_DEGREE: usize = 15;

/// Index of the knot span containing `t` (P&T A2.1) for a clamped knot vector with `count`
/// poles and degree `degree`: the `s` with `knots[s] <= t < knots[s+1]`, `degree <= s < count`.
/// `t` is clamped into `[knots[degree], knots[count]]`; the last span is used at the right end.
pub fn find_span(degree: usize, knots: &[f64], count: usize, t: f64) -> usize {
    let lo_t = knots[degree];
    let hi_t = knots[count];
    if t.is_nan() || t <= lo_t {
        // First non-empty span starting at the domain start.
        let mut s = degree;
        while s + 1 < count && knots[s + 1] <= lo_t {
            s += 1;
        }
        return s;
    }
    if t >= hi_t {
        let mut s = count - 1;
        while s > degree && knots[s] >= hi_t {
            s -= 1;
        }
        return s;
    }
    let (mut low, mut high) = (degree, count);
    let mut mid = (low + high) / 2;
    while t < knots[mid] || t >= knots[mid + 1] {
        if t < knots[mid] {
            high = mid;
        } else {
            low = mid;
        }
        mid = (low + high) / 2;
    }
    mid
}

/// The `degree + 1` non-vanishing basis functions `N_{span-degree..=span, degree}(t)` (P&T A2.2),
/// written into `out[..=degree]`. `out`, `left` and `right` must hold at least `degree + 1` values.
pub fn basis_funs(
    span: usize,
    t: f64,
    degree: usize,
    knots: &[f64],
    out: &mut [f64],
    left: &mut [f64],
    right: &mut [f64],
) {
    out[0] = 1.0;
    for j in 1..=degree {
        left[j] = t - knots[span + 1 - j];
        right[j] = knots[span + j] - t;
        let mut saved = 0.0;
        for r in 0..j {
            let temp = out[r] / (right[r + 1] + left[j - r]);
            out[r] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        out[j] = saved;
    }
}

/// Basis functions into a freshly allocated vector (for degrees above the stack limit).
fn basis_vec(span: usize, t: f64, degree: usize, knots: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; degree + 1];
    let mut left = vec![0.0; degree + 1];
    let mut right = vec![0.0; degree + 1];
    basis_funs(span, t, degree, knots, &mut out, &mut left, &mut right);
    out
}

/// Span and basis values at `t`, clamped into the domain.
fn span_basis(degree: usize, knots: &[f64], count: usize, t: f64) -> (usize, Vec<f64>) {
    let lo = knots[degree];
    let hi = knots[count];
    let t = if t.is_nan() { lo } else { t.clamp(lo, hi) };
    let span = find_span(degree, knots, count, t);
    if degree <= MAX_STACK_DEGREE {
        let mut out = [0.0; MAX_STACK_DEGREE + 1];
        let mut left = [0.0; MAX_STACK_DEGREE + 1];
        let mut right = [0.0; MAX_STACK_DEGREE + 1];
        basis_funs(span, t, degree, knots, &mut out, &mut left, &mut right);
        (span, out[..=degree].to_vec())
    } else {
        (span, basis_vec(span, t, degree, knots))
    }
}

/// Span and basis values at `t` (clamped into the domain), the values written into
/// `out[..=degree]` without allocating (for degrees up to the stack limit). The same
/// arithmetic as [`span_basis`].
fn span_basis_into(degree: usize, knots: &[f64], count: usize, t: f64, out: &mut [f64]) -> usize {
    let lo = knots[degree];
    let hi = knots[count];
    let t = if t.is_nan() { lo } else { t.clamp(lo, hi) };
    let span = find_span(degree, knots, count, t);
    if degree <= MAX_STACK_DEGREE {
        let mut left = [0.0; MAX_STACK_DEGREE + 1];
        let mut right = [0.0; MAX_STACK_DEGREE + 1];
        basis_funs(span, t, degree, knots, out, &mut left, &mut right);
    } else {
        out[..=degree].copy_from_slice(&basis_vec(span, t, degree, knots));
    }
    span
}

/// [`span_basis_into`] for a parameter at or after the one whose span was `previous` (the
/// parameters of a grid or of dense samples increase): the span is found by stepping on from
/// `previous` (a few steps at most, else the binary search), the same span since only one
/// non-empty span holds an interior parameter. Degrees up to the stack limit only.
fn span_basis_after(
    degree: usize,
    knots: &[f64],
    count: usize,
    t: f64,
    previous: usize,
    out: &mut [f64],
) -> usize {
    let (lo, hi) = (knots[degree], knots[count]);
    let t = if t.is_nan() { lo } else { t.clamp(lo, hi) };
    // From a span whose start is at or below t, the first span ending above t is the one
    // holding t (t < hi = knots[count] stops the steps by count − 1).
    let stepped = (lo < t && t < hi && previous < count && knots[previous] <= t)
        .then(|| (previous..previous + 8).find(|&s| t < knots[s + 1]))
        .flatten();
    let span = stepped.unwrap_or_else(|| find_span(degree, knots, count, t));
    let mut left = [0.0; MAX_STACK_DEGREE + 1];
    let mut right = [0.0; MAX_STACK_DEGREE + 1];
    basis_funs(span, t, degree, knots, out, &mut left, &mut right);
    span
}

/// The non-vanishing basis functions along u (or, [`UBasis::along_v`], along v) of a surface
/// at a list of parameters, computed once and applied to any number of iso-curves (every row
/// of a grid shares its u values; every iso-curve along v has the surface's v knots).
#[derive(Debug, Clone)]
pub struct UBasis {
    degree: usize,
    /// Index of the first pole each parameter's basis applies to (span − degree).
    first: Vec<usize>,
    /// `degree + 1` values per parameter.
    values: Vec<f64>,
}

impl UBasis {
    /// The basis along u of `surface` at each of `us` (clamped into the domain).
    pub fn new(surface: &NurbsSurface, us: &[f64]) -> UBasis {
        UBasis::of_knots(surface.degree_u, &surface.knots_u, surface.count_u, us)
    }

    /// The basis along v of `surface` at each of `vs` (clamped into the domain): applied to
    /// the poles of an iso-curve along v ([`NurbsSurface::iso_curve_v`]), each point is the
    /// one [`BSplineCurve::evaluate`] gives, to the bit.
    pub fn along_v(surface: &NurbsSurface, vs: &[f64]) -> UBasis {
        UBasis::of_knots(surface.degree_v, &surface.knots_v, surface.count_v, vs)
    }

    /// The basis of degree `d` on `knots` (for `count` poles) at each of `ts`.
    fn of_knots(d: usize, knots: &[f64], count: usize, ts: &[f64]) -> UBasis {
        let mut first = Vec::with_capacity(ts.len());
        let mut values = vec![0.0; ts.len() * (d + 1)];
        let mut last = None;
        for (&u, out) in ts.iter().zip(values.chunks_exact_mut(d + 1)) {
            let span = match last {
                Some(s) if d <= MAX_STACK_DEGREE => span_basis_after(d, knots, count, u, s, out),
                _ => span_basis_into(d, knots, count, u, out),
            };
            last = Some(span);
            first.push(span - d);
        }
        UBasis {
            degree: d,
            first,
            values,
        }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.first.len()
    }

    /// Degree of the basis (the surface's degree along u).
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Whether there are no parameters.
    pub fn is_empty(&self) -> bool {
        self.first.is_empty()
    }

    /// For each parameter, the index of the first pole its basis functions apply to.
    pub fn first_poles(&self) -> &[usize] {
        &self.first
    }

    /// The `degree + 1` basis values of each parameter, one parameter after another.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Calls `f(k, point)` for each parameter k with the point of the curve whose poles are
    /// `curve` (as [`NurbsSurface::iso_poles_u_padded`] makes them; lane 3 is zero), in the
    /// arithmetic of [`BSplineCurve::evaluate`]: Σ basis·pole from zero, in pole order.
    #[inline(always)]
    pub fn for_each_point(&self, curve: &[[f64; 4]], f: impl FnMut(usize, [f64; 4])) {
        self.for_each_point_from(0, curve, f);
    }

    /// [`UBasis::for_each_point`] with `curve` holding the poles from index `offset` on (as
    /// [`NurbsSurface::iso_poles_u_padded_range`] makes them for [`UBasis::pole_range`]).
    #[inline(always)]
    pub fn for_each_point_from(
        &self,
        offset: usize,
        curve: &[[f64; 4]],
        mut f: impl FnMut(usize, [f64; 4]),
    ) {
        let n = self.degree + 1;
        // Four parameters at a time, so that four independent sums are in flight instead of
        // one chain of dependent additions; each sum is still Σ basis·pole from zero in pole
        // order, and `f` still sees the parameters in order.
        const BLOCK: usize = 4;
        let blocks = self.first.len() / BLOCK;
        for blk in 0..blocks {
            let k0 = blk * BLOCK;
            let bases: [usize; BLOCK] = std::array::from_fn(|j| self.first[k0 + j] - offset);
            let b = &self.values[k0 * n..(k0 + BLOCK) * n];
            let mut p = [[0.0f64; 4]; BLOCK];
            for r in 0..n {
                for j in 0..BLOCK {
                    let q = curve[bases[j] + r];
                    let nu = b[j * n + r];
                    for c in 0..4 {
                        p[j][c] += nu * q[c];
                    }
                }
            }
            for (j, p) in p.into_iter().enumerate() {
                f(k0 + j, p);
            }
        }
        for k in blocks * BLOCK..self.first.len() {
            let base = self.first[k] - offset;
            let poles = &curve[base..base + n];
            let mut p = [0.0f64; 4];
            for (q, &nu) in poles.iter().zip(&self.values[k * n..(k + 1) * n]) {
                for c in 0..4 {
                    p[c] += nu * q[c];
                }
            }
            f(k, p);
        }
    }

    /// The poles (along u) the basis functions touch: from the first parameter's first pole
    /// to the last one's last (parameters in increasing order touch only these).
    pub fn pole_range(&self) -> std::ops::Range<usize> {
        let lo = self.first.iter().copied().min().unwrap_or(0);
        let hi = self
            .first
            .iter()
            .copied()
            .max()
            .map_or(0, |f| f + self.degree + 1);
        lo..hi
    }
}

/// A non-rational B-spline curve in millimetres (an iso-parametric curve of a surface, or a
/// fitted profile).
#[derive(Debug, Clone, PartialEq)]
pub struct BSplineCurve {
    /// Degree.
    pub degree: usize,
    /// Clamped knot vector, `poles.len() + degree + 1` values.
    pub knots: Vec<f64>,
    /// Control points.
    pub poles: Vec<[f64; 3]>,
}

impl BSplineCurve {
    /// Point at parameter `t` (clamped into the knot range). A curve whose knot vector does
    /// not match its poles (`knots.len() != poles.len() + degree + 1`) or that has fewer than
    /// `degree + 1` poles evaluates to `None`.
    pub fn evaluate(&self, t: f64) -> Option<[f64; 3]> {
        let n = self.poles.len();
        if n < self.degree + 1 || self.knots.len() != n + self.degree + 1 {
            return None;
        }
        let mut stack = [0.0; MAX_STACK_DEGREE + 1];
        let heap;
        let (span, basis): (usize, &[f64]) = if self.degree <= MAX_STACK_DEGREE {
            let span = span_basis_into(self.degree, &self.knots, n, t, &mut stack);
            (span, &stack[..=self.degree])
        } else {
            let (span, b) = span_basis(self.degree, &self.knots, n, t);
            heap = b;
            (span, &heap)
        };
        let mut p = [0.0; 3];
        for (r, b) in basis.iter().enumerate() {
            let q = self.poles[span - self.degree + r];
            p[0] += b * q[0];
            p[1] += b * q[1];
            p[2] += b * q[2];
        }
        Some(p)
    }
}

impl NurbsSurface {
    /// Surface point S(u, v) in mm (P&T A3.5; unit weights). Parameters are clamped to [0, 1]
    /// (the knot range).
    pub fn evaluate(&self, u: f64, v: f64) -> [f64; 3] {
        let (su, bu) = span_basis(self.degree_u, &self.knots_u, self.count_u, u);
        let (sv, bv) = span_basis(self.degree_v, &self.knots_v, self.count_v, v);
        let mut p = [0.0; 3];
        for (l, nv) in bv.iter().enumerate() {
            let row = self.net.row(sv - self.degree_v + l);
            let first = su - self.degree_u;
            let mut t = [0.0; 3];
            for (k, nu) in bu.iter().enumerate() {
                let q = row.get(first + k);
                t[0] += nu * q[0];
                t[1] += nu * q[1];
                t[2] += nu * q[2];
            }
            p[0] += nv * t[0];
            p[1] += nv * t[1];
            p[2] += nv * t[2];
        }
        p
    }

    /// The iso-parametric curve at fixed `v`, running along u (x).
    pub fn iso_curve_u(&self, v: f64) -> BSplineCurve {
        let (sv, bv) = span_basis(self.degree_v, &self.knots_v, self.count_v, v);
        let mut poles = vec![[0.0; 3]; self.count_u];
        for (l, nv) in bv.iter().enumerate() {
            let row = self.net.row(sv - self.degree_v + l);
            for (i, out) in poles.iter_mut().enumerate() {
                let q = row.get(i);
                out[0] += nv * q[0];
                out[1] += nv * q[1];
                out[2] += nv * q[2];
            }
        }
        BSplineCurve {
            degree: self.degree_u,
            knots: self.knots_u.clone(),
            poles,
        }
    }

    /// The poles of the iso-parametric curve at fixed `v` (as [`NurbsSurface::iso_curve_u`]
    /// computes them, to the bit) into `out`, each padded to four lanes with a zero so that a
    /// point's three coordinates are one vector.
    pub fn iso_poles_u_padded(&self, v: f64, out: &mut Vec<[f64; 4]>) {
        self.iso_poles_u_padded_range(v, 0..self.count_u, out);
    }

    /// [`NurbsSurface::iso_poles_u_padded`] for the poles `columns` only (`out[0]` is pole
    /// `columns.start`), to the bit.
    pub fn iso_poles_u_padded_range(
        &self,
        v: f64,
        columns: std::ops::Range<usize>,
        out: &mut Vec<[f64; 4]>,
    ) {
        let columns = columns.start.min(self.count_u)..columns.end.min(self.count_u);
        out.clear();
        out.resize(columns.len(), [0.0; 4]);
        let mut bv = [0.0; MAX_STACK_DEGREE + 1];
        if self.degree_v <= MAX_STACK_DEGREE {
            let sv = span_basis_into(self.degree_v, &self.knots_v, self.count_v, v, &mut bv);
            self.accumulate_rows(sv, &bv[..=self.degree_v], columns, out);
        } else {
            let (sv, b) = span_basis(self.degree_v, &self.knots_v, self.count_v, v);
            self.accumulate_rows(sv, &b, columns, out);
        }
    }

    /// Adds Σ_l bv[l] · (pole row sv − degree_v + l) into `out`, over the poles `columns`: each
    /// output pole gets its products added in row order, as a pass per row would (one pass
    /// over the output instead of one per row; the same operations in the same order).
    fn accumulate_rows(
        &self,
        sv: usize,
        bv: &[f64],
        columns: std::ops::Range<usize>,
        out: &mut [[f64; 4]],
    ) {
        let first = sv - self.degree_v;
        let rows: Vec<super::PoleRow<'_>> =
            (0..bv.len()).map(|l| self.net.row(first + l)).collect();
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2, checked just above.
                unsafe { accumulate_rows_avx2(&rows, bv, columns, out) };
                return;
            }
        }
        let add = |acc: &mut [f64; 4], nv: f64, q: [f64; 3]| {
            acc[0] += nv * q[0];
            acc[1] += nv * q[1];
            acc[2] += nv * q[2];
        };
        // Four output poles at a time, so that four independent sums are in flight.
        const BLOCK: usize = 4;
        let start = columns.start;
        let done = out.len() / BLOCK * BLOCK;
        let mut blocks = out.chunks_exact_mut(BLOCK);
        for (blk, o) in (&mut blocks).enumerate() {
            let i0 = start + blk * BLOCK;
            let mut acc: [[f64; 4]; BLOCK] = std::array::from_fn(|j| o[j]);
            for (row, &nv) in rows.iter().zip(bv) {
                for (j, a) in acc.iter_mut().enumerate() {
                    add(a, nv, row.get(i0 + j));
                }
            }
            o.copy_from_slice(&acc);
        }
        for (j, o) in blocks.into_remainder().iter_mut().enumerate() {
            let i = start + done + j;
            let mut acc = *o;
            for (row, &nv) in rows.iter().zip(bv) {
                add(&mut acc, nv, row.get(i));
            }
            *o = acc;
        }
    }

    /// The iso-parametric curve at fixed `u`, running along v (y).
    pub fn iso_curve_v(&self, u: f64) -> BSplineCurve {
        let (su, bu) = span_basis(self.degree_u, &self.knots_u, self.count_u, u);
        let poles = (0..self.count_v)
            .map(|j| {
                let row = self.net.row(j);
                let base = su - self.degree_u;
                let mut p = [0.0; 3];
                for (k, nu) in bu.iter().enumerate() {
                    let q = row.get(base + k);
                    p[0] += nu * q[0];
                    p[1] += nu * q[1];
                    p[2] += nu * q[2];
                }
                p
            })
            .collect();
        BSplineCurve {
            degree: self.degree_v,
            knots: self.knots_v.clone(),
            poles,
        }
    }

    /// Points `S(us[a], vs[b])` for the whole grid, v-outer / u-inner (`b * us.len() + a`).
    /// Basis functions are computed once per parameter and each v reduces the net to an
    /// iso-curve first, so a point costs about `degree_u + 1` multiply-adds per coordinate.
    pub fn evaluate_grid(&self, us: &[f64], vs: &[f64]) -> Vec<[f64; 3]> {
        let basis = UBasis::new(self, us);
        let mut out = Vec::with_capacity(us.len() * vs.len());
        let mut curve = Vec::new();
        for &v in vs {
            self.iso_poles_u_padded(v, &mut curve);
            basis.for_each_point(&curve, |_, p| out.push([p[0], p[1], p[2]]));
        }
        out
    }
}

/// [`NurbsSurface::accumulate_rows`] four output poles at a time, one coordinate per 256-bit
/// vector: the x, y and z of four neighbouring poles of a row are contiguous in the net, so
/// each product and sum of the scalar loop is made in its own lane (`_mm256_mul_pd` then
/// `_mm256_add_pd`, no FMA, in row order from the value already in `out`): the same bits.
/// The fourth lane of `out` is left as it is, as the scalar loop leaves it.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn accumulate_rows_avx2(
    rows: &[super::PoleRow<'_>],
    bv: &[f64],
    columns: std::ops::Range<usize>,
    out: &mut [[f64; 4]],
) {
    use std::arch::x86_64::*;
    let start = columns.start;
    let done = out.len() / 4 * 4;
    // Each row's x, y and z from `start` on, as long as `out` (the rows hold the columns).
    let len = out.len();
    let four = |v: &[f64], i: usize| -> __m256d {
        let v = &v[i..i + 4];
        // SAFETY: `v` holds four readable f64.
        unsafe { _mm256_loadu_pd(v.as_ptr()) }
    };
    let store = |v: __m256d| {
        let mut a = [0.0f64; 4];
        // SAFETY: `a` holds four writable f64.
        unsafe { _mm256_storeu_pd(a.as_mut_ptr(), v) };
        a
    };
    /// A row's coordinates over the columns: y as one value unless the row has its own.
    struct Slices<'a> {
        x: &'a [f64],
        ys: Option<&'a [f64]>,
        y: f64,
        z: &'a [f64],
    }
    let parts: Vec<Slices<'_>> = rows
        .iter()
        .map(|row| {
            let (ys, y) = match row.y {
                super::RowY::One(y) => (None, y),
                super::RowY::Each(ys) => (Some(&ys[start..start + len]), 0.0),
            };
            Slices {
                x: &row.x[start..start + len],
                ys,
                y,
                z: &row.z[start..start + len],
            }
        })
        .collect();
    for (blk, o) in out[..done].chunks_exact_mut(4).enumerate() {
        let i = blk * 4;
        let lane = |c: usize| _mm256_setr_pd(o[0][c], o[1][c], o[2][c], o[3][c]);
        let (mut ax, mut ay, mut az) = (lane(0), lane(1), lane(2));
        for (r, &nv) in parts.iter().zip(bv) {
            let n = _mm256_set1_pd(nv);
            let yv = match r.ys {
                Some(ys) => four(ys, i),
                None => _mm256_set1_pd(r.y),
            };
            ax = _mm256_add_pd(ax, _mm256_mul_pd(n, four(r.x, i)));
            ay = _mm256_add_pd(ay, _mm256_mul_pd(n, yv));
            az = _mm256_add_pd(az, _mm256_mul_pd(n, four(r.z, i)));
        }
        let (x, y, z) = (store(ax), store(ay), store(az));
        for (j, o) in o.iter_mut().enumerate() {
            o[0] = x[j];
            o[1] = y[j];
            o[2] = z[j];
        }
    }
    for (j, o) in out[done..].iter_mut().enumerate() {
        let i = done + j;
        for (r, &nv) in parts.iter().zip(bv) {
            let y = r.ys.map_or(r.y, |ys| ys[i]);
            o[0] += nv * r.x[i];
            o[1] += nv * y;
            o[2] += nv * r.z[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// S(u, v) the way P&T A3.5 states it, from the full net of three coordinates per pole
    /// (independent of how the surface holds its net): the same products in the same order
    /// as [`NurbsSurface::evaluate`].
    fn evaluate_full(s: &NurbsSurface, full: &[[f64; 3]], u: f64, v: f64) -> [f64; 3] {
        let (su, bu) = span_basis(s.degree_u(), s.knots_u(), s.count_u(), u);
        let (sv, bv) = span_basis(s.degree_v(), s.knots_v(), s.count_v(), v);
        let mut p = [0.0; 3];
        for (l, nv) in bv.iter().enumerate() {
            let row = (sv - s.degree_v() + l) * s.count_u() + su - s.degree_u();
            let mut t = [0.0; 3];
            for (k, nu) in bu.iter().enumerate() {
                for c in 0..3 {
                    t[c] += nu * full[row + k][c];
                }
            }
            for c in 0..3 {
                p[c] += nv * t[c];
            }
        }
        p
    }

    /// S(u, v) as [`NurbsSurface::evaluate_grid`] orders the arithmetic (the iso-curve at v
    /// first, then the curve at u), from the full net.
    fn evaluate_full_iso(s: &NurbsSurface, full: &[[f64; 3]], u: f64, v: f64) -> [f64; 3] {
        let (su, bu) = span_basis(s.degree_u(), s.knots_u(), s.count_u(), u);
        let (sv, bv) = span_basis(s.degree_v(), s.knots_v(), s.count_v(), v);
        let mut p = [0.0; 3];
        for (k, nu) in bu.iter().enumerate() {
            let i = su - s.degree_u() + k;
            let mut iso = [0.0; 3];
            for (l, nv) in bv.iter().enumerate() {
                let j = sv - s.degree_v() + l;
                for c in 0..3 {
                    iso[c] += nv * full[j * s.count_u() + i][c];
                }
            }
            for c in 0..3 {
                p[c] += nu * iso[c];
            }
        }
        p
    }

    #[test]
    fn a_compact_net_evaluates_as_the_full_net_does_to_the_bit() {
        let (nu, nv, p, q) = (9usize, 7usize, 3usize, 2usize);
        let clamped = |n: usize, d: usize| {
            let mut k = vec![0.0; d + 1];
            k.extend((1..n - d).map(|i| i as f64 / (n - d) as f64));
            k.extend(vec![1.0; d + 1]);
            k
        };
        let (ku, kv) = (clamped(nu, p), clamped(nv, q));
        let x: Vec<f64> = (0..nu).map(|i| i as f64 * 0.0005 + 1e-4 / 3.0).collect();
        let y: Vec<f64> = (0..nv).map(|j| j as f64 * 0.01 + 1e-5 / 7.0).collect();
        let z = |i: usize, j: usize| ((i * 31 + j * 17) % 11) as f64 * 1.1e-4 - 3.7e-4;
        let separable: Vec<[f64; 3]> = (0..nv)
            .flat_map(|j| (0..nu).map(move |i| (i, j)))
            .map(|(i, j)| [x[i], y[j], z(i, j)])
            .collect();
        // Not separable: row 3's x off by one bit in one column, row 5's y varying.
        let mut general = separable.clone();
        general[3 * nu + 4][0] = f64::from_bits(general[3 * nu + 4][0].to_bits() + 1);
        for i in 0..nu {
            general[5 * nu + i][1] += i as f64 * 1e-9;
        }
        let built = NurbsSurface::try_from_net(
            p,
            q,
            ku.clone(),
            kv.clone(),
            nu,
            nv,
            super::super::PoleNet::separable(
                x.clone(),
                y.clone(),
                separable.iter().map(|p| p[2]).collect(),
            )
            .unwrap(),
        )
        .unwrap();
        let us = [0.0, 0.13, 0.5, 0.77, 1.0];
        let vs = [0.0, 0.31, 0.62, 1.0];
        for full in [&separable, &general] {
            let s =
                NurbsSurface::try_new(p, q, ku.clone(), kv.clone(), nu, nv, full.clone()).unwrap();
            assert_eq!(s.net().is_separable(), std::ptr::eq(full, &separable));
            let bits = |p: [f64; 3]| p.map(f64::to_bits);
            let grid = s.evaluate_grid(&us, &vs);
            for (b, &v) in vs.iter().enumerate() {
                let iso = s.iso_curve_u(v);
                let mut padded = Vec::new();
                s.iso_poles_u_padded_range(v, 2..7, &mut padded);
                for (k, pad) in padded.iter().enumerate() {
                    assert_eq!(pad[..3], iso.poles[2 + k][..]);
                }
                for (a, &u) in us.iter().enumerate() {
                    let point = evaluate_full(&s, full, u, v);
                    let want = bits(point);
                    assert_eq!(bits(s.evaluate(u, v)), want, "u {u} v {v}");
                    let iso_order = bits(evaluate_full_iso(&s, full, u, v));
                    assert_eq!(bits(grid[b * us.len() + a]), iso_order, "grid u {u} v {v}");
                    let along_v = s.iso_curve_v(u).evaluate(v).unwrap();
                    assert!((0..3).all(|c| (along_v[c] - point[c]).abs() < 1e-15));
                }
            }
            assert_eq!(
                s.poles().map(bits).collect::<Vec<_>>(),
                full.iter().map(|&p| bits(p)).collect::<Vec<_>>()
            );
        }
        let s = NurbsSurface::try_new(p, q, ku, kv, nu, nv, separable.clone()).unwrap();
        assert_eq!(built, s);
    }

    /// The padded poles of an iso-curve along u (four columns at a time on AVX2, one by one
    /// at the ends) are Σ_l basis·pole of the full net in row order, to the bit: on a
    /// separable net and on one with a row of its own x (one bit off) and a row of its own y,
    /// for whole and partial column ranges, with the fourth lane zero.
    #[test]
    fn padded_iso_poles_are_the_row_sums_of_the_full_net_to_the_bit() {
        let (nu, nv, p, q) = (23usize, 8usize, 3usize, 5usize);
        let clamped = |n: usize, d: usize| {
            let mut k = vec![0.0; d + 1];
            k.extend((1..n - d).map(|i| (i as f64 / (n - d) as f64).powf(1.3)));
            k.extend(vec![1.0; d + 1]);
            k
        };
        let (ku, kv) = (clamped(nu, p), clamped(nv, q));
        let mut full: Vec<[f64; 3]> = (0..nv)
            .flat_map(|j| (0..nu).map(move |i| (i, j)))
            .map(|(i, j)| {
                [
                    i as f64 * 0.0005 + 1e-4 / 3.0,
                    j as f64 * 0.01 + 1e-5 / 7.0,
                    ((i * 31 + j * 17) % 11) as f64 * 1.1e-4 - 3.7e-4,
                ]
            })
            .collect();
        let separable = full.clone();
        full[3 * nu + 9][0] = f64::from_bits(full[3 * nu + 9][0].to_bits() + 1);
        for i in 0..nu {
            full[5 * nu + i][1] += i as f64 * 1e-9;
        }
        for net in [separable, full] {
            let s =
                NurbsSurface::try_new(p, q, ku.clone(), kv.clone(), nu, nv, net.clone()).unwrap();
            for v in [0.0, 0.17, 0.5, 0.93, 1.0] {
                let (sv, bv) = span_basis(q, s.knots_v(), nv, v);
                for range in [0..nu, 1..nu, 3..14, 5..6, 8..12, nu - 2..nu + 3] {
                    let mut padded = Vec::new();
                    s.iso_poles_u_padded_range(v, range.clone(), &mut padded);
                    let cols = range.start..range.end.min(nu);
                    assert_eq!(padded.len(), cols.len(), "{range:?}");
                    for (k, i) in cols.enumerate() {
                        let mut want = [0.0f64; 4];
                        for (l, nv_l) in bv.iter().enumerate() {
                            let pole = net[(sv - q + l) * nu + i];
                            for c in 0..3 {
                                want[c] += nv_l * pole[c];
                            }
                        }
                        assert_eq!(
                            padded[k].map(f64::to_bits),
                            want.map(f64::to_bits),
                            "v {v}, columns {range:?}, column {i}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn stepping_on_from_the_previous_span_finds_the_binary_searchs_span() {
        // Repeated interior knots (empty spans), parameters on knots, at and beyond the ends,
        // NaN, repeated and decreasing parameters, and jumps of many spans.
        let knots = [
            0.0, 0.0, 0.0, 0.0, 0.1, 0.2, 0.2, 0.3, 0.4, 0.5, 0.7, 0.7, 0.7, 0.8, 0.9, 1.0, 1.0,
            1.0, 1.0,
        ];
        let (degree, count) = (3, knots.len() - 4);
        let mut ts: Vec<f64> = (0..=400).map(|k| k as f64 / 400.0).collect();
        ts.extend([
            0.2,
            0.2,
            0.7,
            0.05,
            -1.0,
            0.0,
            f64::NAN,
            0.95,
            2.0,
            1.0,
            0.69,
            0.7,
        ]);
        ts.extend([0.0, 0.99, 0.01, 0.6999999999999999, 0.7000000000000001]);
        let mut checked = 0;
        for w in ts.windows(2) {
            let (mut a, mut b) = ([0.0; 4], [0.0; 4]);
            let previous = span_basis_into(degree, &knots, count, w[0], &mut a);
            let want = span_basis_into(degree, &knots, count, w[1], &mut a);
            let got = span_basis_after(degree, &knots, count, w[1], previous, &mut b);
            assert_eq!(got, want, "{} after {}", w[1], w[0]);
            assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits), "{}", w[1]);
            checked += 1;
        }
        assert_eq!(checked, ts.len() - 1);
    }

    #[test]
    fn basis_is_partition_of_unity_and_matches_hand_values() {
        // Quadratic, knots 0 0 0 1 2 3 4 4 5 5 5 (P&T ex. 2.3): at u = 5/2,
        // N_{2,2} = 1/8, N_{3,2} = 6/8, N_{4,2} = 1/8.
        let knots = [0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 4.0, 5.0, 5.0, 5.0];
        let span = find_span(2, &knots, 8, 2.5);
        assert_eq!(span, 4);
        let (mut n, mut l, mut r) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        basis_funs(span, 2.5, 2, &knots, &mut n, &mut l, &mut r);
        assert!((n[0] - 0.125).abs() < 1e-15);
        assert!((n[1] - 0.75).abs() < 1e-15);
        assert!((n[2] - 0.125).abs() < 1e-15);
        // Right end uses the last non-empty span.
        assert_eq!(find_span(2, &knots, 8, 5.0), 7);
        assert_eq!(find_span(2, &knots, 8, 9.0), 7);
        assert_eq!(find_span(2, &knots, 8, -1.0), 2);
    }

    #[test]
    fn bilinear_patch_evaluates_to_closed_form() {
        let s = NurbsSurface::try_new(
            1,
            1,
            vec![0.0, 0.0, 1.0, 1.0],
            vec![0.0, 0.0, 1.0, 1.0],
            2,
            2,
            vec![
                [0.0, 0.0, 0.0],
                [2.0, 0.0, 1.0],
                [0.0, 3.0, 2.0],
                [2.0, 3.0, 5.0],
            ],
        )
        .unwrap();
        let (u, v) = (0.3, 0.6);
        let z =
            (1.0 - u) * (1.0 - v) * 0.0 + u * (1.0 - v) * 1.0 + (1.0 - u) * v * 2.0 + u * v * 5.0;
        let p = s.evaluate(u, v);
        assert!((p[0] - 2.0 * u).abs() < 1e-15);
        assert!((p[1] - 3.0 * v).abs() < 1e-15);
        assert!((p[2] - z).abs() < 1e-15);
        let cu = s.iso_curve_u(v).evaluate(u).unwrap();
        let cv = s.iso_curve_v(u).evaluate(v).unwrap();
        let g = s.evaluate_grid(&[u], &[v]);
        for q in [cu, cv, g[0]] {
            for c in 0..3 {
                assert!((q[c] - p[c]).abs() < 1e-15);
            }
        }
    }
}
