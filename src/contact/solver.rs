//! The contact of a rough surface with a rigid flat on an elastic half-space, at a given
//! nominal pressure: Polonsky and Keer's constrained conjugate gradient (Wear 231, 1999),
//! optionally with a perfectly plastic pressure cap at the hardness (Almqvist et al. 2007).
//!
//! Unknowns are the pixel pressures p (MPa) on the grid. With s = h_max − h the initial
//! separation (µm) and u = K p the elastic displacements, the gap is g = u + s − δ, where the
//! approach δ is the Lagrange multiplier of the load. The solution satisfies, and is returned
//! only when it satisfies within the stated tolerances:
//! - bounds: 0 ≤ p ≤ H (H = ∞ when elastic);
//! - complementarity: g = 0 where 0 < p < H, g ≥ 0 where p = 0, g ≤ 0 where p = H (the
//!   material flowed);
//! - balance: the mean pixel pressure equals the nominal pressure (to the pressure
//!   tolerance).
//!
//! The iteration is Polonsky–Keer's: a conjugate-gradient step on the gap over the points
//! whose pressure is free (between the bounds), with the mean of the gap removed (which
//! estimates δ), projection onto zero, the cap at the hardness, and a restart whenever
//! points must join or leave the contact (a zero-pressure point that penetrates, a point at
//! the hardness whose gap opened). The load is then balanced on the free points alone: the
//! points at the hardness carry exactly H and the free ones are scaled to carry the rest.
//! (Scaling every point and capping afterwards, as the elastic method would, takes load off
//! the contact at every step a flowing region exists; on a smooth sphere whose centre flows
//! it did not converge within the iteration limit.) A plastic state whose free set is empty
//! (every contact point at the hardness) is restarted from the bearing-area solution of the
//! current displacements: the ⌈W/H⌉ points with the smallest gap carry H, the last of them
//! the remainder.
//!
//! Every solve stops after [`SolveOptions::max_iterations`] at the latest and then returns a
//! [`NotConverged`] naming how far it got; it never loops without bound.
//!
//! Layer 1 (pure logic): depends on [`super::halfspace`]; no I/O.

use super::halfspace::HalfSpace;

/// How hard the solver tries.
#[derive(Debug, Clone, PartialEq)]
pub struct SolveOptions {
    /// Iterations before giving up (default 5000; a grid of a scan converges in a few
    /// hundred).
    pub max_iterations: usize,
    /// Largest allowed violation of complementarity (a gap inside the contact, a penetration
    /// outside it), relative to the surface's peak-to-valley height (default 1e-7).
    pub gap_tolerance: f64,
    /// Largest allowed change of the pressures in the last iteration, Σ|Δp| / Σp
    /// (default 1e-9).
    pub pressure_tolerance: f64,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions {
            max_iterations: 5000,
            gap_tolerance: 1e-7,
            pressure_tolerance: 1e-9,
        }
    }
}

/// The converged contact at one load.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Pixel pressures, MPa, row-major like the heights (0 outside the contact).
    pub pressure_mpa: Vec<f64>,
    /// Gap between the deformed surface and the flat, µm (0 inside the contact, negative
    /// where the material flowed at the hardness).
    pub gap_um: Vec<f64>,
    /// Approach of the flat beyond first touch of the highest point, µm.
    pub approach_um: f64,
    /// Iterations used.
    pub iterations: usize,
}

/// A solve that hit its iteration limit: how far it got.
#[derive(Debug, Clone, PartialEq)]
pub struct NotConverged {
    /// Iterations run.
    pub iterations: usize,
    /// Largest complementarity violation at the end, µm.
    pub gap_residual_um: f64,
    /// The tolerance it had to reach, µm.
    pub gap_tolerance_um: f64,
    /// Σ|Δp| / Σp of the last iteration.
    pub pressure_change: f64,
    /// Fraction of the points in contact at the end.
    pub area_fraction: f64,
}

/// Solves the contact of the `heights_um` grid (row-major, the operator's shape) at mean
/// pixel pressure `mean_pressure_mpa`, perfectly plastic at `hardness_mpa` when given,
/// starting from `start` (pressures of a nearby solution, e.g. the previous load) or from a
/// uniform pressure. The caller has checked the inputs: finite heights of the operator's
/// shape, 0 < mean pressure < hardness.
pub fn solve(
    space: &mut HalfSpace,
    heights_um: &[f64],
    mean_pressure_mpa: f64,
    hardness_mpa: Option<f64>,
    start: Option<&[f64]>,
    opts: &SolveOptions,
) -> Result<Solution, NotConverged> {
    let n = heights_um.len();
    let hard = hardness_mpa.unwrap_or(f64::INFINITY);
    let (lo, hi) = heights_um
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(h), b.max(h))
        });
    // A floor of 1e-12 µm keeps a nearly flat grid from asking for a zero tolerance.
    let gap_tol = opts.gap_tolerance * (hi - lo).max(1e-12);
    let sep: Vec<f64> = heights_um.iter().map(|h| hi - h).collect();
    let load = mean_pressure_mpa * n as f64;
    let mut p = match start {
        Some(s) if s.len() == n && s.iter().any(|&v| v > 0.0) => s.to_vec(),
        _ => vec![mean_pressure_mpa; n],
    };
    scale_onto(&mut p, load, hard);
    let mut u = vec![0.0; n];
    space.displacements(&p, &mut u);
    let mut g: Vec<f64> = u.iter().zip(&sep).map(|(u, s)| u + s).collect();
    let mut t = vec![0.0; n];
    let mut r = vec![0.0; n];
    let mut p_old = vec![0.0; n];
    let mut flow = vec![false; n];
    let mut viol = vec![false; n];
    let mut restart = true;
    let mut sumsq_old = 1.0;
    let mut delta = mean_free(&p, &g, hard).unwrap_or(0.0);
    let mut last = NotConverged {
        iterations: 0,
        gap_residual_um: f64::INFINITY,
        gap_tolerance_um: gap_tol,
        pressure_change: f64::INFINITY,
        area_fraction: 0.0,
    };
    for it in 1..=opts.max_iterations {
        let free = |v: f64| v > 0.0 && v < hard;
        if !p.iter().any(|&v| free(v)) {
            // Every contact point flows: restart from the bearing-area state.
            delta = bearing_state(&mut p, &g, load, hard);
            restart = true;
        }
        g.iter_mut().for_each(|v| *v -= delta);
        let sumsq: f64 = p
            .iter()
            .zip(&g)
            .filter(|(p, _)| free(**p))
            .map(|(_, g)| g * g)
            .sum();
        let beta = if restart || sumsq_old <= 0.0 {
            0.0
        } else {
            sumsq / sumsq_old
        };
        for i in 0..n {
            t[i] = if free(p[i]) { g[i] + beta * t[i] } else { 0.0 };
        }
        space.displacements(&t, &mut r);
        let (mut r_sum, mut count) = (0.0, 0usize);
        for i in 0..n {
            if free(p[i]) {
                r_sum += r[i];
                count += 1;
            }
        }
        let r_mean = r_sum / count.max(1) as f64;
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..n {
            if free(p[i]) {
                num += g[i] * t[i];
                den += (r[i] - r_mean) * t[i];
            }
        }
        let tau = if den > 0.0 && num.is_finite() {
            num / den
        } else {
            0.0
        };
        p_old.copy_from_slice(&p);
        for i in 0..n {
            if free(p[i]) {
                p[i] -= tau * t[i];
            }
        }
        // Points that must join (penetrating at zero pressure) or leave the cap (open at
        // the hardness) move by the same step along their gap; the CG restarts.
        let step = if tau > 0.0 {
            tau
        } else {
            1.0 / space.self_compliance()
        };
        restart = false;
        for i in 0..n {
            flow[i] = false;
            viol[i] = false;
            if p[i] <= 0.0 {
                p[i] = 0.0;
                viol[i] = g[i] < 0.0;
            } else if p[i] >= hard {
                flow[i] = true;
                viol[i] = g[i] > 0.0;
            }
        }
        for i in 0..n {
            if flow[i] {
                p[i] = hard;
            }
            if viol[i] {
                p[i] = (p[i] - step * g[i]).clamp(0.0, hard);
                restart = true;
            }
        }
        if p.iter().all(|&v| v <= 0.0) {
            p.iter_mut().for_each(|v| *v = mean_pressure_mpa);
        }
        balance(&mut p, load, hard);
        space.displacements(&p, &mut u);
        for i in 0..n {
            g[i] = u[i] + sep[i];
        }
        sumsq_old = sumsq;
        let change = p
            .iter()
            .zip(&p_old)
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
            / load;
        let contact = p.iter().filter(|&&v| v > 0.0).count();
        last = NotConverged {
            iterations: it,
            gap_residual_um: f64::INFINITY,
            gap_tolerance_um: gap_tol,
            pressure_change: change,
            area_fraction: contact as f64 / n as f64,
        };
        let Some(d) = mean_free(&p, &g, hard) else {
            continue;
        };
        delta = d;
        let residual = p
            .iter()
            .zip(&g)
            .map(|(&p, &g)| {
                let g = g - d;
                if p <= 0.0 {
                    (-g).max(0.0)
                } else if p >= hard {
                    g.max(0.0)
                } else {
                    g.abs()
                }
            })
            .fold(0.0, f64::max);
        last.gap_residual_um = residual;
        let imbalance = (p.iter().sum::<f64>() - load).abs() / load;
        if residual <= gap_tol
            && change <= opts.pressure_tolerance
            && imbalance <= opts.pressure_tolerance
        {
            let gap_um = p
                .iter()
                .zip(&g)
                .map(|(&p, &g)| if p > 0.0 && p < hard { 0.0 } else { g - d })
                .collect();
            return Ok(Solution {
                pressure_mpa: p,
                gap_um,
                approach_um: d,
                iterations: it,
            });
        }
    }
    Err(last)
}

/// Mean gap over the free points (0 < p < H): the approach that makes the gap's projection
/// onto the load constraint vanish; `None` when no point is free.
fn mean_free(p: &[f64], g: &[f64], hard: f64) -> Option<f64> {
    let (mut sum, mut count) = (0.0, 0usize);
    for (&p, &g) in p.iter().zip(g) {
        if p > 0.0 && p < hard {
            sum += g;
            count += 1;
        }
    }
    (count > 0).then(|| sum / count as f64)
}

/// Puts `p` back onto the load by scaling only the free points (0 < p < H): the points at
/// the hardness carry exactly H and the rest of the load goes to the others. A free point
/// that the scaling lifts to H joins the cap and the rest is scaled again (at most once per
/// point). When the cap alone carries more than the load, every point is scaled down
/// instead and so leaves the cap. When no point is free the load stays unbalanced; the
/// caller restarts from the bearing-area state.
fn balance(p: &mut [f64], load: f64, hard: f64) {
    for _ in 0..p.len() {
        let (mut capped, mut free) = (0.0, 0.0);
        for &v in p.iter() {
            if v >= hard {
                capped += hard;
            } else {
                free += v;
            }
        }
        let rest = load - capped;
        if rest <= 0.0 {
            let c = load / (capped + free);
            p.iter_mut().for_each(|v| *v = v.min(hard) * c);
            return;
        }
        if free <= 0.0 {
            return;
        }
        let c = rest / free;
        let mut lifted = false;
        for v in p.iter_mut().filter(|v| **v < hard) {
            *v *= c;
            if *v >= hard {
                *v = hard;
                lifted = true;
            }
        }
        if !lifted {
            return;
        }
    }
}

/// Scales the starting pressures onto the load and caps them at the hardness.
fn scale_onto(p: &mut [f64], load: f64, hard: f64) {
    let sum: f64 = p.iter().sum();
    let n = p.len() as f64;
    p.iter_mut()
        .for_each(|v| *v = if sum > 0.0 { *v * load / sum } else { load / n }.clamp(0.0, hard));
}

/// Sets `p` to the bearing-area state of gaps `g`: the ⌈load/H⌉ points with the smallest gap
/// carry H, the last of them the remainder; returns that point's gap as the approach.
fn bearing_state(p: &mut [f64], g: &[f64], load: f64, hard: f64) -> f64 {
    let mut order: Vec<usize> = (0..g.len()).collect();
    let k = ((load / hard).ceil() as usize).clamp(1, g.len());
    order.select_nth_unstable_by(k - 1, |&a, &b| g[a].total_cmp(&g[b]));
    p.iter_mut().for_each(|v| *v = 0.0);
    for &i in &order[..k - 1] {
        p[i] = hard;
    }
    let last = order[k - 1];
    p[last] = (load - hard * (k - 1) as f64).clamp(0.0, hard);
    g[last]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::influence::pixel_displacement;

    /// A deterministic rough grid: a few sines and a hash-like term.
    fn rough(rows: usize, cols: usize) -> Vec<f64> {
        (0..rows * cols)
            .map(|i| {
                let (r, c) = ((i / cols) as f64, (i % cols) as f64);
                (c * 0.7).sin() * 0.3
                    + (r * 1.3 + c * 0.2).cos() * 0.2
                    + (((i * 7919) % 101) as f64 / 101.0 - 0.5) * 0.1
            })
            .collect()
    }

    /// The returned field satisfies the guarantees, checked against displacements summed
    /// directly from the influence coefficients (not through the FFT operator).
    fn assert_guarantees(
        h: &[f64],
        (rows, cols): (usize, usize),
        (dx, dy): (f64, f64),
        e: f64,
        mean: f64,
        hard: Option<f64>,
    ) {
        let mut space = HalfSpace::new(rows, cols, dx, dy, e);
        let opts = SolveOptions::default();
        let sol = solve(&mut space, h, mean, hard, None, &opts).unwrap();
        let hmax = h.iter().cloned().fold(f64::MIN, f64::max);
        let hmin = h.iter().cloned().fold(f64::MAX, f64::min);
        let tol = 10.0 * opts.gap_tolerance * (hmax - hmin);
        let cap = hard.unwrap_or(f64::INFINITY);
        let p = &sol.pressure_mpa;
        let sum: f64 = p.iter().sum();
        assert!(
            (sum / (rows * cols) as f64 - mean).abs() < 1e-8 * mean,
            "load {sum}"
        );
        let (mut free, mut flowing, mut open) = (0, 0, 0);
        for i in 0..rows * cols {
            let (r, c) = (i / cols, i % cols);
            let mut u = 0.0;
            for (j, &pj) in p.iter().enumerate() {
                let (r2, c2) = (j / cols, j % cols);
                u += pixel_displacement(
                    (c as f64 - c2 as f64) * dx,
                    (r as f64 - r2 as f64) * dy,
                    dx,
                    dy,
                ) / e
                    * pj;
            }
            let g = u + hmax - h[i] - sol.approach_um;
            assert!(p[i] >= 0.0 && p[i] <= cap, "bounds at {i}: {}", p[i]);
            if p[i] == 0.0 {
                assert!(g >= -tol, "penetration {g} at open point {i}");
                open += 1;
            } else if p[i] >= cap {
                assert!(g <= tol, "open gap {g} at flowing point {i}");
                flowing += 1;
            } else {
                assert!(g.abs() <= tol, "gap {g} inside the contact at {i}");
                free += 1;
            }
            // The reported gap is the same gap (0 in the elastic contact).
            let reported = sol.gap_um[i];
            assert!((reported - if p[i] > 0.0 && p[i] < cap { 0.0 } else { g }).abs() <= tol);
        }
        assert!(free > 0 && open > 0, "free {free} open {open}");
        if hard.is_some() {
            assert!(flowing > 0, "the cap must act in the plastic case");
        }
    }

    #[test]
    fn elastic_solution_satisfies_complementarity_bounds_and_balance() {
        let (rows, cols) = (12, 20);
        assert_guarantees(
            &rough(rows, cols),
            (rows, cols),
            (0.5, 2.0),
            1e3,
            20.0,
            None,
        );
    }

    #[test]
    fn plastic_solution_satisfies_complementarity_bounds_and_balance() {
        let (rows, cols) = (12, 20);
        assert_guarantees(
            &rough(rows, cols),
            (rows, cols),
            (0.5, 2.0),
            1e3,
            20.0,
            Some(60.0),
        );
    }

    /// A smooth sphere whose centre flows: the contact converges with a flowing disc inside
    /// an elastic ring, and as the hardness falls the contact area approaches the
    /// bearing-area limit W/H from above.
    #[test]
    fn plastic_sphere_converges_with_a_flowing_core() {
        let (rows, cols) = (40, 40);
        let (dx, dy) = (1.0, 1.0);
        let radius = 1e3;
        let h: Vec<f64> = (0..rows * cols)
            .map(|i| {
                let (x, y) = ((i % cols) as f64 - 19.5, (i / cols) as f64 - 19.5);
                -(x * x + y * y) / (2.0 * radius)
            })
            .collect();
        // Elastic Hertz at this load: a = 10 µm, p0 ≈ 640 MPa.
        let e = 1e5;
        let mean = 4.0 * e * 1000.0 / (3.0 * radius) / (rows * cols) as f64;
        assert_guarantees(&h, (rows, cols), (dx, dy), e, mean, Some(400.0));
        let opts = SolveOptions::default();
        let mut last_excess = f64::INFINITY;
        for hard in [500.0, 300.0, 150.0] {
            let mut space = HalfSpace::new(rows, cols, dx, dy, e);
            let sol = solve(&mut space, &h, mean, Some(hard), None, &opts).unwrap();
            let contact = sol.pressure_mpa.iter().filter(|&&p| p > 0.0).count() as f64;
            let flowing = sol.pressure_mpa.iter().filter(|&&p| p >= hard).count() as f64;
            let bearing = mean * (rows * cols) as f64 / hard;
            assert!(
                contact >= bearing && flowing <= bearing,
                "H {hard}: {contact} {flowing}"
            );
            let excess = contact / bearing - 1.0;
            assert!(
                excess < last_excess,
                "H {hard}: {excess} after {last_excess}"
            );
            last_excess = excess;
            // The flowing points are the innermost ones.
            let centre = |i: usize| {
                let (x, y) = ((i % cols) as f64 - 19.5, (i / cols) as f64 - 19.5);
                x * x + y * y
            };
            let r_flow = (0..rows * cols)
                .filter(|&i| sol.pressure_mpa[i] >= hard)
                .map(centre)
                .fold(0.0, f64::max);
            let r_free = (0..rows * cols)
                .filter(|&i| sol.pressure_mpa[i] > 0.0 && sol.pressure_mpa[i] < hard)
                .map(centre)
                .fold(f64::INFINITY, f64::min);
            assert!(
                r_flow.sqrt() < r_free.sqrt() + 1.0,
                "H {hard}: {r_flow} vs {r_free}"
            );
        }
        assert!(last_excess < 0.5, "{last_excess}");
    }

    /// An iteration limit ends the solve with how far it got, never a hang.
    #[test]
    fn iteration_limit_names_how_far_it_got() {
        let (rows, cols) = (12, 20);
        let mut space = HalfSpace::new(rows, cols, 0.5, 2.0, 1e3);
        let opts = SolveOptions {
            max_iterations: 3,
            ..SolveOptions::default()
        };
        let err = solve(&mut space, &rough(rows, cols), 20.0, None, None, &opts).unwrap_err();
        assert_eq!(err.iterations, 3);
        assert!(err.gap_residual_um > err.gap_tolerance_um);
        assert!(err.area_fraction > 0.0 && err.area_fraction < 1.0);
    }

    /// Starting from the solution converges at once to the same field.
    #[test]
    fn warm_start_from_the_solution_returns_it() {
        let (rows, cols) = (12, 20);
        let h = rough(rows, cols);
        let mut space = HalfSpace::new(rows, cols, 0.5, 2.0, 1e3);
        let opts = SolveOptions::default();
        let a = solve(&mut space, &h, 20.0, None, None, &opts).unwrap();
        let b = solve(&mut space, &h, 20.0, None, Some(&a.pressure_mpa), &opts).unwrap();
        assert!(b.iterations <= 3, "{}", b.iterations);
        let diff: f64 = a
            .pressure_mpa
            .iter()
            .zip(&b.pressure_mpa)
            .map(|(x, y)| (x - y).abs())
            .sum();
        assert!(diff < 1e-6 * 20.0 * (rows * cols) as f64);
    }
}
