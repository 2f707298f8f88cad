//! ISO 25178-2 functional parameters of a levelled height grid, from its areal material
//! ratio curve: the Sk family (Sk, Spk, Svk, Smr1, Smr2) and the volume parameters (Vmp,
//! Vmc, Vvc, Vvv).
//!
//! **The curve.** Smc(mr), the height at areal material ratio mr, is the linear-quantile curve
//! of the plane-levelled heights (the highest at 0 %, the lowest at 100 %, linear between the
//! ordinates at equal steps of mr): the curve the profile Rk family is built on
//! ([`super::params::rk_family_and_curve`]).
//!
//! **Sk family** by the same construction as the profile's Rk family: the 40 % secant of
//! least gradient (searched in 0.1 % steps, the first if tied) extended to 0 % and 100 % gives
//! the core limits; Sk is their height difference, Smr1/Smr2 the material ratios at them,
//! Spk = 2·A1/Smr1 and Svk = 2·A2/(100 − Smr2).
//!
//! **Volumes** (p = 10 %, q = 80 %, ISO 25178-2's defaults), integrated exactly on the
//! piecewise-linear curve, mr as a fraction:
//! Vm(mr) = ∫₀^mr (Smc(x) − Smc(mr)) dx and Vv(mr) = ∫_mr^1 (Smc(mr) − Smc(x)) dx;
//! Vmp = Vm(p), Vmc = Vm(q) − Vm(p), Vvv = Vv(q), Vvc = Vv(p) − Vv(q). A height in µm times a
//! fraction of the area is µm³/µm², and 1 µm³/µm² = 1 ml/m², the unit ISO 25178-2 gives.
//!
//! Depends on [`super::areal`] (levelling), [`super::params`] (the material ratio curve and the
//! Rk construction) and [`super::MetrologyError`].

use super::params::{checked_sorted_desc, rk_of_sorted, rmc};
use super::MetrologyError;
use serde::Serialize;
use std::collections::BTreeMap;

/// Material ratio p of Vmp, Vmc and Vvc, % (ISO 25178-2 default).
pub const P_PCT: f64 = 10.0;
/// Material ratio q of Vmc, Vvc and Vvv, % (ISO 25178-2 default).
pub const Q_PCT: f64 = 80.0;

/// The functional parameters of a levelled grid, under their ISO 25178-2 names with units.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ArealFunctional {
    /// Core height.
    #[serde(rename = "Sk_um")]
    pub sk_um: f64,
    /// Reduced peak height.
    #[serde(rename = "Spk_um")]
    pub spk_um: f64,
    /// Reduced dale height.
    #[serde(rename = "Svk_um")]
    pub svk_um: f64,
    /// Material ratio at the upper core limit.
    #[serde(rename = "Smr1_pct")]
    pub smr1_pct: f64,
    /// Material ratio at the lower core limit.
    #[serde(rename = "Smr2_pct")]
    pub smr2_pct: f64,
    /// Peak material volume at p.
    #[serde(rename = "Vmp_ml_per_m2")]
    pub vmp_ml_m2: f64,
    /// Core material volume between p and q.
    #[serde(rename = "Vmc_ml_per_m2")]
    pub vmc_ml_m2: f64,
    /// Core void volume between p and q.
    #[serde(rename = "Vvc_ml_per_m2")]
    pub vvc_ml_m2: f64,
    /// Dale void volume at q.
    #[serde(rename = "Vvv_ml_per_m2")]
    pub vvv_ml_m2: f64,
    /// p, %.
    pub p_pct: f64,
    /// q, %.
    pub q_pct: f64,
    /// Definition id per parameter.
    pub definitions: BTreeMap<String, String>,
}

/// The definition ids of the functional parameters.
pub fn definitions() -> BTreeMap<String, String> {
    super::parameter_table::areal_definitions("functional", &[])
}

/// The Sk family and the volume parameters of a grid from its heights `z` levelled by
/// [`super::areal::level_plane`].
pub fn areal_functional(z: Vec<f64>) -> Result<ArealFunctional, MetrologyError> {
    let s = checked_sorted_desc(z)?;
    let rk = rk_of_sorted(&s);
    let curve = QuantileCurve::new(&s);
    let (vm_p, vm_q) = (curve.vm(P_PCT), curve.vm(Q_PCT));
    let (vv_p, vv_q) = (curve.vv(P_PCT), curve.vv(Q_PCT));
    Ok(ArealFunctional {
        sk_um: rk.rk_um,
        spk_um: rk.rpk_um,
        svk_um: rk.rvk_um,
        smr1_pct: rk.mr1_pct,
        smr2_pct: rk.mr2_pct,
        vmp_ml_m2: vm_p,
        vmc_ml_m2: vm_q - vm_p,
        vvc_ml_m2: vv_p - vv_q,
        vvv_ml_m2: vv_q,
        p_pct: P_PCT,
        q_pct: Q_PCT,
        definitions: definitions(),
    })
}

/// The linear-quantile curve Smc(mr) of ordinates sorted highest first.
struct QuantileCurve<'a> {
    sorted_desc: &'a [f64],
    /// Distance between nodes, %.
    step_pct: f64,
}

impl<'a> QuantileCurve<'a> {
    /// At least two ordinates (as [`checked_sorted_desc`] guarantees).
    fn new(sorted_desc: &'a [f64]) -> QuantileCurve<'a> {
        let step_pct = 100.0 / (sorted_desc.len().max(2) - 1) as f64;
        QuantileCurve {
            sorted_desc,
            step_pct,
        }
    }

    /// ∫₀^mr Smc(x) dx, µm·%: the trapezoids up to the node below mr summed in order (a
    /// pass over the ordinates per call, which the few volume levels afford, rather than a
    /// running sum held for every node), then the part to mr.
    fn integral_to(&self, mr_pct: f64) -> f64 {
        let mr = mr_pct.clamp(0.0, 100.0);
        let last = self.sorted_desc.len().max(1) - 1;
        let i = ((mr / self.step_pct).floor() as usize).min(last);
        let x_i = i as f64 * self.step_pct;
        let s_i = self.sorted_desc.get(i).copied().unwrap_or(0.0);
        let to_node = (self.sorted_desc.get(..=i).unwrap_or_default())
            .windows(2)
            .fold(0.0, |sum, w| sum + 0.5 * (w[0] + w[1]) * self.step_pct);
        to_node + 0.5 * (mr - x_i) * (s_i + rmc(self.sorted_desc, mr))
    }

    /// Vm(mr), µm (= ml/m²).
    fn vm(&self, mr_pct: f64) -> f64 {
        (self.integral_to(mr_pct) - mr_pct * rmc(self.sorted_desc, mr_pct)) / 100.0
    }

    /// Vv(mr), µm (= ml/m²).
    fn vv(&self, mr_pct: f64) -> f64 {
        let tail = self.integral_to(100.0) - self.integral_to(mr_pct);
        ((100.0 - mr_pct) * rmc(self.sorted_desc, mr_pct) - tail) / 100.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrology::areal::{level_plane, test_map};

    /// Ordinates uniform on [−h, h]: Smc is the straight line h·(1 − 2x) over x in [0, 1], so
    /// Vm(p) = h·p² and Vv(p) = h·(1 − p)² exactly on the polyline; the secant is the curve
    /// itself: Sk = 2h, Spk = Svk = 0.
    #[test]
    fn a_uniform_height_distribution_has_closed_form_volumes() {
        let (n, h) = (2001usize, 1.5);
        let s: Vec<f64> = (0..n)
            .map(|i| h * (1.0 - 2.0 * i as f64 / (n - 1) as f64))
            .collect();
        let c = QuantileCurve::new(&s);
        for p in [0.0, 10.0, 33.3, 80.0, 100.0] {
            let x = p / 100.0;
            assert!((c.vm(p) - h * x * x).abs() < 1e-12, "Vm({p}) {}", c.vm(p));
            assert!(
                (c.vv(p) - h * (1.0 - x) * (1.0 - x)).abs() < 1e-12,
                "Vv({p}) {}",
                c.vv(p)
            );
        }
        let rk = rk_of_sorted(&s);
        assert!((rk.rk_um - 2.0 * h).abs() < 1e-9 && rk.rpk_um < 1e-9 && rk.rvk_um < 1e-9);
    }

    /// A grid holding one deep pit: the volumes of the dales grow, the peaks' stay.
    #[test]
    fn a_pit_adds_dale_void_volume_only() {
        let (rows, cols) = (5usize, 400usize);
        let base: Vec<f64> = (0..rows * cols)
            .map(|k| 0.1 * ((k % cols) as f64 * 0.37).sin() + 0.05 * ((k / cols) as f64).cos())
            .collect();
        let mut pitted = base.clone();
        pitted[2 * cols + 200] -= 50.0;
        let g = |z: &[f64]| {
            let g = test_map(z, rows, cols, 0.001, 0.01);
            areal_functional(level_plane(&g).unwrap().0).unwrap()
        };
        let (a, b) = (g(&base), g(&pitted));
        assert!(b.vvv_ml_m2 > a.vvv_ml_m2, "{a:?}\n{b:?}");
        assert!(
            (b.vmp_ml_m2 - a.vmp_ml_m2).abs() < 0.01 * a.vmp_ml_m2,
            "{a:?}\n{b:?}"
        );
    }
}
