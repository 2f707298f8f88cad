//! The material-ratio family as the Mitutoyo SJ series evaluates it, beside the ISO reading
//! of [`super::params`]: the numbers an operator compares with the instrument's display.
//!
//! ISO 4287, ISO 13565-2 and ISO 21920-2 define the material ratio on the continuous profile
//! (crossings interpolated between ordinates) with no height classes; that is the reading
//! [`super::params`] reports. The SJ series works on a grid (reproduced from a Mitutoyo
//! SurfTest export and the printed results beside it, `docs/metrology.md`):
//!
//! * **Counted ordinates.** Rmr(c), Rmr and the curve are the share of the evaluated ordinates
//!   strictly above the level (`z > c`), not a length of the interpolated profile: 0 % at the
//!   highest point, as the instrument's exported curve has it.
//! * **A 100-level bearing area curve.** Levels `L_k = zmin + k·Rt/100`, k = 1 … 100 (the
//!   instrument's 100 points), and at each the counted share `mr_k = #(z > L_k)/n`; the lowest
//!   point (k = 0) closes the curve at 100 %, the highest (k = 100) at 0 %.
//! * **The Rk family on that curve.** The curve is the polyline through `(mr_k, L_k)`; the
//!   equivalent straight line is the secant between two of its points 40 % apart in mr with
//!   the least gradient, its start searched in 1 % steps of mr (the curve's own resolution;
//!   the first if tied). Its heights at mr = 0 and 100 % are C and D, Rk = C − D. The core
//!   limits are then snapped to the grid: C and D in % of Rt rounded to the nearest level,
//!   plus one level (`kc`, `kd`). Mr1 = mr_kc, Mr2 = mr_kd; A1 = Σ_{k ≥ kc} mr_k·Rt/100 and
//!   A2 = Σ_{1 ≤ k ≤ kd} (100 − mr_k)·Rt/100 in µm·% (the areas of the curve's classes),
//!   Rpk = 2·A1/Mr1 and Rvk = 2·A2/(100 − Mr2).
//!
//! On the Mitutoyo export this reproduces the instrument's own exported curve at 97 of its 100
//! levels (the other three by one ordinate lying within 0.012 nm of the level, below the
//! export's 0.1 nm rounding) and the printed Rmr(c), Rmr, Mr1, Mr2, A1, A2, Rpk and Rvk to the
//! last printed digit; Rk comes out 0.19 % below the printed value (no reading of the secant on
//! this curve, nor any other convention tried, reaches it: `docs/metrology.md` lists them). The
//! "plus one level" snap rests on two data points (the export's C and D) and is stated as
//! such.
//!
//! Both readings are always reported (ISO's first); [`MaterialRatioReading`] (`[analysis]
//! material-ratio`, `analyze --material-ratio`) picks the one a verdict and a summary line use.
//!
//! Depends on [`super::params`] (the levels of the material ratio parameters, the one
//! [`MaterialRatio`] result both readings fill, the Rk family's assembly from its core) and
//! [`super::MetrologyError`].

use super::params::{
    checked_sorted_desc, MaterialLevels, MaterialRatio, RkFamily, RoughnessParams,
};
use super::MetrologyError;
use serde::{Deserialize, Serialize};

/// Which reading of the material-ratio family (Rmr(c), Rmr, Rk, Rpk, Rvk, Mr1, Mr2, A1, A2) a
/// verdict against a drawing's limits and the summary line use. Both are reported either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum MaterialRatioReading {
    /// ISO 13565-2 / ISO 4287 on the continuous profile (the default).
    #[default]
    Iso,
    /// The instrument's own (the SJ series' 100-level curve and counted ordinates), so that
    /// a verdict agrees with the SJ-210's display.
    Instrument,
}

impl MaterialRatioReading {
    /// The name as the configuration and the command line write it.
    pub fn name(self) -> &'static str {
        match self {
            MaterialRatioReading::Iso => "iso",
            MaterialRatioReading::Instrument => "instrument",
        }
    }

    /// Parses `iso` or `instrument` (a command-line value), naming both when it is neither.
    pub fn parse(s: &str) -> Result<MaterialRatioReading, String> {
        match s.trim() {
            "iso" => Ok(MaterialRatioReading::Iso),
            "instrument" => Ok(MaterialRatioReading::Instrument),
            other => Err(format!(
                "{other:?} is not a material-ratio reading: use iso (ISO 13565-2 on the continuous profile) or instrument (the SJ series' counted 100-level curve)"
            )),
        }
    }

    /// What the reading is, for the report beside the verdict.
    pub fn statement(self) -> &'static str {
        match self {
            MaterialRatioReading::Iso => {
                "Rmr(c), Rmr and the Rk family as ISO 13565-2 defines them on the continuous profile"
            }
            MaterialRatioReading::Instrument => {
                "Rmr(c), Rmr and the Rk family as the Mitutoyo SJ series reads them (100-level curve, counted ordinates), as its display shows them"
            }
        }
    }

    /// A line's parameters with the material-ratio family of this reading: `params` as they
    /// are for ISO, or with the SJ series' values (`sj`, the line's reading) for
    /// `instrument`. A line without the SJ reading (it exists wherever the ISO one does)
    /// keeps ISO's.
    pub fn applied(
        self,
        params: &RoughnessParams,
        sj: Option<&SjMaterialRatio>,
    ) -> RoughnessParams {
        match (self, sj) {
            (MaterialRatioReading::Instrument, Some(sj)) => RoughnessParams {
                material: sj.material.clone(),
                ..params.clone()
            },
            _ => params.clone(),
        }
    }
}

/// Height classes of the SJ series' bearing area curve (1 % of Rt each).
pub const LEVELS: usize = 100;

/// The convention in words, written beside the values in the report.
pub const CONVENTION: &str = "Mitutoyo SJ series: ordinates counted (z > level); bearing area curve on 100 levels of 1 % Rt; Rk from the least-gradient 40 % secant on that curve searched in 1 % steps of mr; core limits snapped to round(% Rt) + 1 level; A1/A2 summed over the levels";

/// The material-ratio family as the SJ series computes it, under the ISO parameter names.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SjMaterialRatio {
    /// How the values were obtained ([`CONVENTION`]).
    pub convention: &'static str,
    /// Rmr(c), Rmr and the Rk family, counted ordinates, the core limits snapped to the grid.
    #[serde(flatten)]
    pub material: MaterialRatio,
    /// The upper core level C in % of Rt above the lowest point (before the snap).
    pub upper_level_pct_rt: f64,
    /// The lower core level D in % of Rt above the lowest point (before the snap).
    pub lower_level_pct_rt: f64,
    /// Where the least-gradient secant starts, % (it ends 40 % later).
    pub secant_start_pct: f64,
    /// The bearing area curve, `[mr_pct, height_um]` at the 101 levels from the lowest point
    /// (k = 0, 100 %) to the highest (k = 100), heights above the lowest point.
    pub curve: Vec<[f64; 2]>,
}

/// The SJ series' reading of the material-ratio family of the evaluated ordinates `z` (µm,
/// about the mean line), at `levels` (the Rmr(c) depths and Rmr's reference and δc).
pub fn sj_material_ratio(
    z: &[f64],
    levels: &MaterialLevels,
) -> Result<SjMaterialRatio, MetrologyError> {
    let sorted = checked_sorted_desc(z)?;
    let n = sorted.len() as f64;
    let top = sorted.first().copied().unwrap_or(0.0);
    let bottom = sorted.last().copied().unwrap_or(0.0);
    let rt = top - bottom;
    // The share strictly above a level, by binary search in the descending sort.
    let above = |c: f64| 100.0 * sorted.partition_point(|v| *v > c) as f64 / n;
    let level = |k: usize| bottom + k as f64 * rt / LEVELS as f64;
    // The top closes the curve at 0 %: float noise can put level(100) an ulp below it.
    let mr: Vec<f64> = (0..LEVELS)
        .map(|k| if k == 0 { 100.0 } else { above(level(k)) })
        .chain([0.0])
        .collect();

    let (start, gradient) = least_gradient_secant(&mr, rt);
    let h_start = height_at(&mr, start) * rt;
    let c = h_start + gradient * start;
    let d = c - gradient * 100.0;
    let (c_pct, d_pct) = if rt > 0.0 {
        (c / rt * 100.0, d / rt * 100.0)
    } else {
        (0.0, 0.0)
    };
    let snap = |pct: f64| (pct.round().max(0.0) as usize + 1).min(LEVELS);
    let (kc, kd) = (snap(c_pct), snap(d_pct));
    let mr1 = mr.get(kc).copied().unwrap_or(0.0);
    let mr2 = mr.get(kd).copied().unwrap_or(100.0);
    let class = rt / LEVELS as f64;
    let a1 = mr.iter().skip(kc).sum::<f64>() * class;
    let a2 = mr.iter().take(kd + 1).map(|m| 100.0 - m).sum::<f64>() * class;
    let rk = RkFamily::of_core(
        gradient * 100.0,
        (bottom + c, bottom + d),
        start,
        (mr1, a1),
        (mr2, a2),
    );
    Ok(SjMaterialRatio {
        convention: CONVENTION,
        material: MaterialRatio::read(
            levels,
            (top, rt),
            above,
            // C(mr) on the grid: the lowest level whose share is at most mr (the top for 0 %).
            |m| {
                (m > 0.0)
                    .then(|| mr.iter().position(|v| *v <= m))
                    .flatten()
                    .map_or(top, level)
            },
            rk,
        ),
        upper_level_pct_rt: c_pct,
        lower_level_pct_rt: d_pct,
        secant_start_pct: start,
        curve: (0..=LEVELS)
            .map(|k| [mr.get(k).copied().unwrap_or(0.0), k as f64 * class])
            .collect(),
    })
}

/// The curve's height at `mr` in units of Rt above the lowest point: the polyline through
/// `(mr_k, k/100)`, mr falling as k rises; where several levels share one mr (no ordinate
/// between them) the lowest of them is taken, so the polyline is a function of mr.
fn height_at(curve: &[f64], mr: f64) -> f64 {
    // The lowest level k whose share is at most mr, and the level below it.
    let k = curve.iter().position(|m| *m <= mr).unwrap_or(LEVELS);
    if k == 0 {
        return 0.0;
    }
    let (m_hi, m_lo) = (
        curve.get(k).copied().unwrap_or(0.0),
        curve.get(k - 1).copied().unwrap_or(100.0),
    );
    // m_lo > mr >= m_hi: k is the first level at or below mr.
    ((k - 1) as f64 + (m_lo - mr) / (m_lo - m_hi)) / LEVELS as f64
}

/// The least-gradient 40 % secant: its start in % (1 % steps, the first if tied) and its
/// gradient in µm per % of mr.
fn least_gradient_secant(curve: &[f64], rt: f64) -> (f64, f64) {
    let mut best = (f64::MAX, 0.0);
    for a in (0..=60u32).map(f64::from) {
        let drop = (height_at(curve, a) - height_at(curve, a + 40.0)) * rt;
        if drop < best.0 - 1e-12 * best.0.abs() {
            best = (drop, a);
        }
    }
    (best.1, best.0 / 40.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A uniform ramp: every level holds the same share, the curve is the straight line from
    /// (0 %, top) to (100 %, bottom), Rk = Rt. The snap puts D one level above the bottom, so
    /// the valley zone holds the lowest class: Rvk = 2 classes (0.2 µm), and C above the top
    /// leaves no peak zone.
    #[test]
    fn a_ramp_is_all_core() {
        let z: Vec<f64> = (0..=10_000).map(|i| i as f64 * 1e-3).collect();
        let m = sj_material_ratio(&z, &MaterialLevels::default()).unwrap();
        assert!(
            (m.material.rk.rk_um - 10.0).abs() < 2e-3,
            "{}",
            m.material.rk.rk_um
        );
        assert!(
            m.material.rk.rpk_um == 0.0 && (m.material.rk.rvk_um - 0.2).abs() < 1e-9,
            "{m:?}"
        );
        // 10 % of Rt below the top is 9 µm, an ordinate of its own: the 1000 above it count.
        assert_eq!(m.material.rmr_c[0].value_pct, 100.0 * 1000.0 / 10_001.0);
        assert_eq!(m.curve.len(), 101);
    }

    #[test]
    fn one_point_is_refused() {
        assert!(sj_material_ratio(&[1.0], &MaterialLevels::default()).is_err());
        assert!(sj_material_ratio(&[1.0, f64::NAN], &MaterialLevels::default()).is_err());
    }
}
