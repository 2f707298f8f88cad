//! How well a fitted surface meets its data: the largest distance to a data point.
//!
//! Layer 1 (pure logic): depends on the fit's result type, [`crate::grid`] (the data) and
//! [`crate::nurbs`] evaluation.
//!
//! The basis functions along u are the same for every row (the parameters ū_k are shared), so
//! they are computed once; each row then reduces the net to its iso-curve and evaluates it at
//! every ū_k with the stored basis. The arithmetic per point is that of
//! [`NurbsSurface::evaluate_grid`](crate::nurbs::NurbsSurface::evaluate_grid) (same products,
//! same order), so the residual is the same to the bit.
//!
//! Speed without changing a bit: the largest squared distance is found and its square root
//! taken once (the square root is correctly rounded and never decreasing, so the root of the
//! largest is the largest root), and a large grid is split by columns over a few threads, each
//! with the basis and the iso-curve poles of its own columns (the maximum does not depend on
//! the order it is taken in). On a CPU with AVX2 the loop is written in 256-bit vectors: the
//! iso-curve's x, y and z of four poles at a time (as the net holds them), a padded point
//! (x, y, z, 0) as one vector, four points side by side; each lane is multiplied and added as
//! the scalar loop does it (no FMA, the same order), so the bits are the same.

use super::FitResult;
use crate::grid::Grid;
use crate::nurbs::{NurbsSurface, UBasis};

/// Grids with at least this many points are split over threads.
const PARALLEL_POINTS: usize = 100_000;

/// Largest distance |S(ū_k, v̄_l) − Q(k, l)| in mm over all data points of `grid`, the grid the
/// result was fitted to. Returns infinity when the grid's shape does not match the result.
pub fn max_residual_mm(result: &FitResult, grid: &Grid) -> f64 {
    let (rows, cols) = (grid.y_mm.len(), grid.cols);
    if cols != result.params_u.len()
        || rows != result.params_v.len()
        || grid.heights_um.len() != rows * cols
    {
        return f64::INFINITY;
    }
    let threads = if rows * cols >= PARALLEL_POINTS {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .clamp(1, 4)
            .min(cols)
    } else {
        1
    };
    let beside = Beside {
        surface: &result.surface,
        params_u: &result.params_u,
        params_v: &result.params_v,
        x0_mm: result.x0_mm,
        pitch_x_mm: grid.pitch_x_mm,
        y_mm: &grid.y_mm,
        heights_um: &grid.heights_um,
        cols,
    };
    let worst_sq = if threads <= 1 {
        beside.worst_squared(0..cols)
    } else {
        let chunk = cols.div_ceil(threads);
        std::thread::scope(|scope| {
            let beside = &beside;
            let handles: Vec<_> = (0..cols)
                .step_by(chunk)
                .map(|lo| scope.spawn(move || beside.worst_squared(lo..(lo + chunk).min(cols))))
                .collect();
            handles
                .into_iter()
                // A panic goes on to the caller's handler (a scan's outputs, the command;
                // `crate::panics`), rather than reading as a surface infinitely far off.
                .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                .fold(0.0f64, f64::max)
        })
    };
    worst_sq.sqrt()
}

/// The data grid beside the surface fitted to it.
struct Beside<'a> {
    surface: &'a NurbsSurface,
    params_u: &'a [f64],
    params_v: &'a [f64],
    /// x of the first column (where the surface was placed, [`FitResult::place_at_x`]).
    x0_mm: f64,
    pitch_x_mm: f64,
    y_mm: &'a [f64],
    heights_um: &'a [f64],
    cols: usize,
}

impl Beside<'_> {
    /// Largest squared distance over the data columns `columns` of every row, computed by the
    /// AVX2 loop when the running CPU has it.
    fn worst_squared(&self, columns: std::ops::Range<usize>) -> f64 {
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2, checked just above.
                if let Some(w) = unsafe { self.worst_squared_avx2(columns.clone()) } {
                    return w;
                }
            }
        }
        self.worst_squared_in(columns)
    }

    /// The loop for every target: the basis along u of the columns, then per row the
    /// iso-curve poles and the points.
    #[inline(always)]
    fn worst_squared_in(&self, columns: std::ops::Range<usize>) -> f64 {
        let basis = UBasis::new(self.surface, &self.params_u[columns.clone()]);
        let poles = basis.pole_range();
        let mut curve = Vec::new();
        let mut worst = 0.0f64;
        for ((row, &y), &v) in self
            .heights_um
            .chunks_exact(self.cols)
            .zip(self.y_mm)
            .zip(self.params_v)
        {
            let row = &row[columns.clone()];
            self.surface
                .iso_poles_u_padded_range(v, poles.clone(), &mut curve);
            basis.for_each_point_from(poles.start, &curve, |k, p| {
                let q = [
                    self.x0_mm + (columns.start + k) as f64 * self.pitch_x_mm,
                    y,
                    row[k] / 1000.0,
                ];
                let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                worst = worst.max(dx * dx + dy * dy + dz * dz);
            });
        }
        worst
    }
}

/// The curve poles and basis values of point `k` (its first pole at `base` in `curve`), each
/// exactly `n` long, so that sums over them index without checks.
#[inline(always)]
fn parts<'a>(
    curve: &'a [[f64; 4]],
    values: &'a [f64],
    base: usize,
    k: usize,
    n: usize,
) -> (&'a [[f64; 4]], &'a [f64]) {
    (&curve[base..][..n], &values[k * n..][..n])
}

/// The residual loop written for AVX2 (256-bit vectors of f64): x, y or z of four iso-curve
/// poles, or a padded point (x, y, z, 0), is one vector, and every lane is multiplied and
/// added as the scalar loop does it
/// (`_mm256_mul_pd` then `_mm256_add_pd`: two roundings, no FMA), in the same order, so each
/// point has the bits of [`Beside::worst_squared_in`]'s.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{parts, Beside};
    use crate::nurbs::{basis_funs, find_span, RowY, UBasis};
    use std::arch::x86_64::*;

    /// Degrees up to this have their basis along v in stack buffers (beyond: the scalar loop).
    const MAX_DEGREE: usize = 15;

    impl Beside<'_> {
        /// [`Beside::worst_squared_in`] in 256-bit vectors; `None` for a surface of a degree above
        /// [`MAX_DEGREE`] (the caller then runs the scalar loop).
        ///
        /// # Safety
        /// The CPU must support AVX2.
        #[target_feature(enable = "avx2")]
        pub(super) unsafe fn worst_squared_avx2(
            &self,
            columns: std::ops::Range<usize>,
        ) -> Option<f64> {
            let s = self.surface;
            let (p, q) = (s.degree_u(), s.degree_v());
            if p > MAX_DEGREE || q > MAX_DEGREE {
                return None;
            }
            let nv = s.count_v();
            let knots_v = s.knots_v();
            let net = s.net();
            let mut rows = Vec::with_capacity(q + 1);
            let basis = UBasis::new(s, &self.params_u[columns.clone()]);
            let poles = basis.pole_range();
            let (first, values) = (basis.first_poles(), basis.values());
            let n = p + 1;
            let mut curve = vec![[0.0f64; 4]; poles.len()];
            let thousand = _mm256_set1_pd(1000.0);
            let (lo_v, hi_v) = (knots_v[q], knots_v[nv]);
            let (mut bv, mut left, mut right) = (
                [0.0; MAX_DEGREE + 1],
                [0.0; MAX_DEGREE + 1],
                [0.0; MAX_DEGREE + 1],
            );
            let mut worst = 0.0f64;
            for ((row, &y), &v) in self
                .heights_um
                .chunks_exact(self.cols)
                .zip(self.y_mm)
                .zip(self.params_v)
            {
                // The iso-curve's poles: Σ_l N_l(v)·P(l, i) from zero in row order, as
                // `NurbsSurface::iso_poles_u_padded_range` sums them.
                let t = if v.is_nan() {
                    lo_v
                } else {
                    v.clamp(lo_v, hi_v)
                };
                let sv = find_span(q, knots_v, nv, t);
                basis_funs(sv, t, q, knots_v, &mut bv, &mut left, &mut right);
                rows.clear();
                rows.extend((0..=q).map(|l| net.row(sv - q + l)));
                let load4 = |v: &[f64]| {
                    let v = &v[..4];
                    // SAFETY: `v` holds four readable f64.
                    unsafe { _mm256_loadu_pd(v.as_ptr()) }
                };
                // Four poles at a time, x, y and z each as a vector of the four (the net holds
                // them so), then transposed into four padded poles (lane 3 unused).
                // Where every row holds one y (a separable net), y is the same sum for every
                // pole: Σ_l N_l(v)·y_l from zero in row order, taken once as a scalar (each
                // lane's operations, so the same bits) instead of once per four poles.
                let one_y =
                    rows.iter()
                        .zip(&bv[..=q])
                        .try_fold(0.0f64, |acc, (row, &b)| match row.y {
                            RowY::One(y) => Some(acc + b * y),
                            RowY::Each(_) => None,
                        });
                let done = poles.start + curve.len() / 4 * 4;
                let mut blocks = curve.chunks_exact_mut(4);
                for (blk, out) in (&mut blocks).enumerate() {
                    let i0 = poles.start + blk * 4;
                    let (mut ax, mut az) = (_mm256_setzero_pd(), _mm256_setzero_pd());
                    for (row, &b) in rows.iter().zip(&bv[..=q]) {
                        let b = _mm256_set1_pd(b);
                        ax = _mm256_add_pd(ax, _mm256_mul_pd(b, load4(&row.x[i0..])));
                        az = _mm256_add_pd(az, _mm256_mul_pd(b, load4(&row.z[i0..])));
                    }
                    let ay = match one_y {
                        Some(y) => _mm256_set1_pd(y),
                        None => {
                            let mut ay = _mm256_setzero_pd();
                            for (row, &b) in rows.iter().zip(&bv[..=q]) {
                                let y = match row.y {
                                    RowY::One(y) => _mm256_set1_pd(y),
                                    RowY::Each(ys) => load4(&ys[i0..]),
                                };
                                ay = _mm256_add_pd(ay, _mm256_mul_pd(_mm256_set1_pd(b), y));
                            }
                            ay
                        }
                    };
                    let (xy_lo, xy_hi) = (_mm256_unpacklo_pd(ax, ay), _mm256_unpackhi_pd(ax, ay));
                    let (zz_lo, zz_hi) = (_mm256_unpacklo_pd(az, az), _mm256_unpackhi_pd(az, az));
                    let padded = [
                        _mm256_permute2f128_pd::<0x20>(xy_lo, zz_lo),
                        _mm256_permute2f128_pd::<0x20>(xy_hi, zz_hi),
                        _mm256_permute2f128_pd::<0x31>(xy_lo, zz_lo),
                        _mm256_permute2f128_pd::<0x31>(xy_hi, zz_hi),
                    ];
                    for (o, p) in out.iter_mut().zip(padded) {
                        // SAFETY: `o` holds four writable f64.
                        unsafe { _mm256_storeu_pd(o.as_mut_ptr(), p) };
                    }
                }
                for (j, o) in blocks.into_remainder().iter_mut().enumerate() {
                    let mut acc = _mm256_setzero_pd();
                    for (row, &b) in rows.iter().zip(&bv[..=q]) {
                        let [x, y, z] = row.get(done + j);
                        let p = _mm256_set_pd(0.0, z, y, x);
                        acc = _mm256_add_pd(acc, _mm256_mul_pd(_mm256_set1_pd(b), p));
                    }
                    // SAFETY: `o` holds four writable f64.
                    unsafe { _mm256_storeu_pd(o.as_mut_ptr(), acc) };
                }
                // The points: Σ_r N_r(u)·C(r) from zero in pole order, as
                // `UBasis::for_each_point_from` sums them.
                let row = &row[columns.clone()];
                let term = |(c, b): (&[[f64; 4]], &[f64]), r: usize| {
                    // SAFETY: `c[r]` holds four readable f64.
                    let c = unsafe { _mm256_loadu_pd(c[r].as_ptr()) };
                    _mm256_mul_pd(_mm256_set1_pd(b[r]), c)
                };
                // Four points at a time: their sums side by side, then transposed into x, y
                // and z of the four, and the squared distance ((dx² + dy²) + dz², as below)
                // of all four at once. `_mm256_max_pd(d, worst)` keeps `worst` where `d` is
                // NaN, as `f64::max` does.
                let blocks = row.len() / 4;
                let (yv, pitch, four, x0) = (
                    _mm256_set1_pd(y),
                    _mm256_set1_pd(self.pitch_x_mm),
                    _mm256_set1_pd(4.0),
                    _mm256_set1_pd(self.x0_mm),
                );
                let s0 = columns.start as f64;
                let mut kv = _mm256_set_pd(s0 + 3.0, s0 + 2.0, s0 + 1.0, s0);
                let mut worst4 = _mm256_setzero_pd();
                for blk in 0..blocks {
                    let k0 = blk * 4;
                    let mut acc = [_mm256_setzero_pd(); 4];
                    let at = &first[k0..k0 + 4];
                    let four_parts = [
                        parts(&curve, values, at[0] - poles.start, k0, n),
                        parts(&curve, values, at[1] - poles.start, k0 + 1, n),
                        parts(&curve, values, at[2] - poles.start, k0 + 2, n),
                        parts(&curve, values, at[3] - poles.start, k0 + 3, n),
                    ];
                    for r in 0..n {
                        for (a, &p) in acc.iter_mut().zip(&four_parts) {
                            *a = _mm256_add_pd(*a, term(p, r));
                        }
                    }
                    let [a, b, c, d] = acc;
                    let (ab_lo, ab_hi) = (_mm256_unpacklo_pd(a, b), _mm256_unpackhi_pd(a, b));
                    let (cd_lo, cd_hi) = (_mm256_unpacklo_pd(c, d), _mm256_unpackhi_pd(c, d));
                    let xs = _mm256_permute2f128_pd::<0x20>(ab_lo, cd_lo);
                    let ys = _mm256_permute2f128_pd::<0x20>(ab_hi, cd_hi);
                    let zs = _mm256_permute2f128_pd::<0x31>(ab_lo, cd_lo);
                    let h = &row[k0..k0 + 4];
                    // SAFETY: `h` holds four readable f64.
                    let h = unsafe { _mm256_loadu_pd(h.as_ptr()) };
                    let dx = _mm256_sub_pd(xs, _mm256_add_pd(x0, _mm256_mul_pd(kv, pitch)));
                    let dy = _mm256_sub_pd(ys, yv);
                    let dz = _mm256_sub_pd(zs, _mm256_div_pd(h, thousand));
                    let d2 = _mm256_add_pd(
                        _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                        _mm256_mul_pd(dz, dz),
                    );
                    worst4 = _mm256_max_pd(d2, worst4);
                    kv = _mm256_add_pd(kv, four);
                }
                let mut lanes = [0.0f64; 4];
                // SAFETY: `lanes` holds four writable f64.
                unsafe { _mm256_storeu_pd(lanes.as_mut_ptr(), worst4) };
                worst = lanes.into_iter().fold(worst, f64::max);
                for (k, &h) in row.iter().enumerate().skip(blocks * 4) {
                    let mut acc = _mm256_setzero_pd();
                    let p = parts(&curve, values, first[k] - poles.start, k, n);
                    for r in 0..n {
                        acc = _mm256_add_pd(acc, term(p, r));
                    }
                    let mut pt = [0.0f64; 4];
                    // SAFETY: `pt` holds four writable f64.
                    unsafe { _mm256_storeu_pd(pt.as_mut_ptr(), acc) };
                    let x = self.x0_mm + (columns.start + k) as f64 * self.pitch_x_mm;
                    let (dx, dy, dz) = (pt[0] - x, pt[1] - y, pt[2] - h / 1000.0);
                    worst = worst.max(dx * dx + dy * dy + dz * dz);
                }
            }
            Some(worst)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{fit_grid, FitOptions};

    /// The AVX2 loop and the scalar loop give the same bits (on a CPU without AVX2 both are
    /// the scalar loop), over column ranges that start and end off the blocks of four.
    #[test]
    fn wide_and_baseline_loops_agree_to_the_bit() {
        let (rows, cols) = (9, 203);
        let pitch = 0.0005;
        let y: Vec<f64> = (0..rows).map(|i| i as f64 * 0.01).collect();
        let mut s = 12345u64;
        let h: Vec<f64> = (0..rows * cols)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 3.0
            })
            .collect();
        let r = fit_grid(pitch, &y, &h, cols, FitOptions::default()).unwrap();
        let grid = Beside {
            surface: &r.surface,
            params_u: &r.params_u,
            params_v: &r.params_v,
            x0_mm: 0.0,
            pitch_x_mm: pitch,
            y_mm: &y,
            heights_um: &h,
            cols,
        };
        for columns in [0..cols, 0..1, 5..6, 17..cols, 3..150] {
            let wide = grid.worst_squared(columns.clone());
            let base = grid.worst_squared_in(columns.clone());
            assert_eq!(wide.to_bits(), base.to_bits(), "{columns:?}");
        }
        let all = grid.worst_squared(0..cols);
        assert!(all > 0.0 && all < 1e-24, "{all:e}");
        // A net that is not separable (one row's x off by a bit, one row's y varying, as a
        // net read from a file may be): the rows that keep their own x and y.
        let s = &r.surface;
        let mut poles: Vec<[f64; 3]> = s.poles().collect();
        let nu = s.count_u();
        poles[3 * nu + 7][0] = f64::from_bits(poles[3 * nu + 7][0].to_bits() + 1);
        for (i, p) in poles[5 * nu..6 * nu].iter_mut().enumerate() {
            p[1] += i as f64 * 1e-7;
        }
        let general = crate::nurbs::NurbsSurface::try_new(
            s.degree_u(),
            s.degree_v(),
            s.knots_u().to_vec(),
            s.knots_v().to_vec(),
            nu,
            s.count_v(),
            poles,
        )
        .unwrap();
        assert!(!general.net().is_separable());
        let grid = Beside {
            surface: &general,
            ..grid
        };
        for columns in [0..cols, 2..9, 17..cols] {
            let wide = grid.worst_squared(columns.clone());
            let base = grid.worst_squared_in(columns.clone());
            assert_eq!(wide.to_bits(), base.to_bits(), "{columns:?}");
            assert!(wide > 1e-20, "{columns:?}: {wide:e}");
        }
        // Placed at x = 0.25 mm (the rows with their own x too) and compared with data from
        // there: the same distances to rounding, the same bits from both loops.
        let mut placed = general.clone();
        placed.shift_x(0.25);
        let at = Beside {
            surface: &placed,
            x0_mm: 0.25,
            ..grid
        };
        let (wide, base) = (at.worst_squared(0..cols), at.worst_squared_in(0..cols));
        assert_eq!(wide.to_bits(), base.to_bits());
        let here = grid.worst_squared(0..cols).sqrt();
        assert!(
            (wide.sqrt() - here).abs() < 1e-15,
            "{} vs {here}",
            wide.sqrt()
        );
    }
}
