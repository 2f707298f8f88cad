//! ISO 4287:1997 profile parameters and the ISO 13565-2 Rk family of one traced line, computed
//! as the SJ series computes them, each with its [`Recipe`].
//!
//! Conventions (see the recipe's definition ids):
//! * heights are referenced to the λc filter mean line (no extra mean removal); with no filter
//!   the exported R profile is taken as it is;
//! * N = L/λc (L = points × pitch), rounded to the nearest whole number when within 1 % of it,
//!   else truncated and the central N·lr evaluated; each sampling length holds an equal share
//!   ⌊n/N⌋ of the points (a remainder of fewer than N points at the end is not evaluated);
//!   a recorded N (the instrument's) takes the whole line as N equal sections, and a given
//!   central N ([`Options::central_sections`]) the middle N·λc of a longer traverse, the
//!   filter having run over all of it;
//! * Ra, Rq, Rp, Rv, Rz, Rsk, Rku, RΔq, RSm and RzJIS per sampling length, then averaged;
//!   Rt, Rz1max and the Rk family over the evaluation length;
//! * RΔq (and RΔa, the mean |slope| the SJ series also reports) from the ISO 4287 7-point
//!   derivative, computed over the evaluation length and pooled per sampling length (points
//!   within 3 of either end have no slope);
//! * the Rk family from the material ratio curve Rmc(mr) (linear quantiles of the ordinates),
//!   the equivalent straight line being the 40 % secant of least gradient (the first if tied,
//!   mr searched in 0.1 % steps), A1/A2 in µm·%, Rpk = 2·A1/Mr1, Rvk = 2·A2/(100 − Mr2);
//! * profile elements (RSm, Rc, RPc) as the SJ series discriminates them: an element is a peak
//!   and the valley after it, bounded by upward mean-line crossings; its peak must reach
//!   +10 % of the section's Rz and its valley −10 % (the instrument's "Zp/Zv: 10 %"), and an
//!   element narrower than 1 % of the sampling length is merged into the next; RSm and Rc
//!   (mean Zt = Zp + Zv) per sampling length, then averaged; RPc = 1 cm / RSm, in 1/cm (the
//!   SJ manuals: "Pc = unit length / Sm", not ASME's count of ±c crossings), and Rppi the
//!   same for one inch (the SJ series' Ppi);
//! * the material ratio parameters the SJ series reports, over the evaluation length on the
//!   piecewise-linear profile ([`MaterialLevels`], the levels the SJ-410's own result files
//!   show): Rmr(c) with the "peak reference" (depth below the highest peak in % of Rt),
//!   Rδc = C(Rmr1) − C(Rmr2) and the relative material ratio Rmr at Rδc below C(Rmr0),
//!   C(mr) being the level at which the material ratio is mr.
//!
//! Depends on [`super::filter`], [`super::bearing`] and [`crate::profile`].

use super::bearing::{level_at_material_ratio, material_ratio_pct};
use super::filter::{self, END_TREATMENT};
use super::form::{remove_form, Form};
use super::parameter_table::PARAMETERS;
use super::{check_heights, check_pitch, MetrologyError};
use crate::profile::{FilterKind, Profile, ProfileKind};
use serde::Serialize;
use std::collections::BTreeMap;

/// How a line is evaluated. Defaults: λc = 0.8 mm with the Gaussian filter, no λs, N from the
/// length.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Cut-off λc in mm; also the sampling length lr.
    pub lambda_c_mm: f64,
    /// Apply the λc Gaussian filter (false for profiles that already are R profiles).
    pub apply_lambda_c: bool,
    /// Short-wave cut-off λs in µm, applied first when given.
    pub lambda_s_um: Option<f64>,
    /// Number of sampling lengths; `None` derives it from the length (see module docs).
    pub sampling_lengths: Option<u32>,
    /// Evaluate only the central this many sampling lengths (each λc long) of a longer
    /// traverse, leaving the rest at each end out as the filter's run-up and run-out, as an
    /// instrument traces N·λc plus λc (`analyze --sampling-lengths`); takes precedence over
    /// `sampling_lengths`.
    pub central_sections: Option<u32>,
    /// Form-only evaluation (`analyze --form-only`): the primary profile with this form
    /// removed by least squares and no λc filter, evaluated as P parameters over the whole
    /// length as one section (ISO 4287: for P the sampling length is the evaluation length)
    /// unless `sampling_lengths` says otherwise. `apply_lambda_c` is then ignored.
    pub form: Option<Form>,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            lambda_c_mm: 0.8,
            apply_lambda_c: true,
            lambda_s_um: None,
            sampling_lengths: None,
            central_sections: None,
            form: None,
        }
    }
}

impl Options {
    /// Options from a profile's recorded conditions: its λc, N and λs where known, and no λc
    /// filter when the profile is already an R profile or the filter is recorded as none.
    pub fn from_profile(profile: &Profile) -> Options {
        let c = &profile.conditions;
        let kind = c.profile_kind.unwrap_or(profile.kind);
        Options {
            lambda_c_mm: c.lambda_c_mm.unwrap_or(0.8),
            apply_lambda_c: kind != ProfileKind::R && c.filter != Some(FilterKind::None),
            // An exported R profile has had λs applied by the instrument already.
            lambda_s_um: c.lambda_s_um.filter(|_| kind != ProfileKind::R),
            // The SJ series reports N = 0 for an arbitrary evaluation length: its
            // parameters are then taken over the whole length as one section.
            sampling_lengths: c.sampling_lengths.map(|n| n.max(1)),
            central_sections: None,
            form: None,
        }
    }
}

/// How a set of numbers was obtained: enough to reproduce them in other software.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Recipe {
    /// Standards followed.
    pub standard: String,
    /// Profile filter, e.g. "ISO 16610-21 Gaussian" or "none (input is an R profile)".
    pub filter: String,
    /// End-effect treatment of the filter, or "none".
    pub end_treatment: String,
    /// Cut-off λc in mm (sampling length).
    pub lambda_c_mm: f64,
    /// Short-wave cut-off λs in µm when applied by this software.
    pub lambda_s_um: Option<f64>,
    /// Number of sampling lengths N.
    pub sampling_lengths: u32,
    /// How N was chosen.
    pub sampling_lengths_rule: String,
    /// Points per sampling length.
    pub points_per_section: usize,
    /// Points of the input left out of the evaluation (remainder or truncation).
    pub points_not_evaluated: usize,
    /// The input's point the evaluation length starts at (the first of the ordinates).
    #[serde(skip)]
    pub first_point: usize,
    /// Pitch in mm.
    pub pitch_mm: f64,
    /// Reference line for heights.
    pub mean_line: String,
    /// The profile evaluated: "R" (roughness) or "P" (primary, form-only evaluation: the
    /// parameters are P parameters, Pa … under the R names).
    pub profile: &'static str,
    /// The form removed in a form-only evaluation, in words.
    pub form: Option<String>,
    /// Length of one section (sampling length as evaluated), mm; shorter than λc when the
    /// line is (a plain statement is in `sampling_lengths_rule`).
    pub section_length_mm: f64,
    /// Which parameters are averaged over the sampling lengths and which are over the
    /// evaluation length.
    pub averaging: String,
    /// Definition id per parameter name.
    pub definitions: BTreeMap<String, String>,
}

/// The parameters of one line; field names in JSON follow the report's naming (`Ra_um`, …).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RoughnessParams {
    /// Arithmetic mean deviation, lr-mean.
    #[serde(rename = "Ra_um")]
    pub ra_um: f64,
    /// Root mean square deviation, lr-mean.
    #[serde(rename = "Rq_um")]
    pub rq_um: f64,
    /// Maximum peak height, lr-mean.
    #[serde(rename = "Rp_um")]
    pub rp_um: f64,
    /// Maximum valley depth, lr-mean.
    #[serde(rename = "Rv_um")]
    pub rv_um: f64,
    /// Maximum height Rp + Rv per sampling length, lr-mean (ISO 4287:1997).
    #[serde(rename = "Rz_um")]
    pub rz_um: f64,
    /// Total height over the evaluation length.
    #[serde(rename = "Rt_um")]
    pub rt_um: f64,
    /// Largest single-section Rz.
    #[serde(rename = "Rz1max_um")]
    pub rz1max_um: f64,
    /// JIS ten-point height, lr-mean; `None` when a section has fewer than 5 peaks or valleys.
    #[serde(rename = "RzJIS_um")]
    pub rzjis_um: Option<f64>,
    /// Skewness, lr-mean.
    #[serde(rename = "Rsk")]
    pub rsk: f64,
    /// Kurtosis (3 for a Gaussian), lr-mean.
    #[serde(rename = "Rku")]
    pub rku: f64,
    /// Root mean square slope (7-point), lr-mean, dimensionless.
    #[serde(rename = "Rdq")]
    pub rdq: f64,
    /// Arithmetic mean slope |dZ/dX| (the same 7-point slope), lr-mean, dimensionless: the
    /// SJ series' RΔa (Da on the SJ-301).
    #[serde(rename = "Rda")]
    pub rda: f64,
    /// Mean width of profile elements, lr-mean; `None` when no section holds two elements.
    #[serde(rename = "RSm_um")]
    pub rsm_um: Option<f64>,
    /// Mean height Zt = Zp + Zv of the same profile elements, lr-mean; `None` as RSm.
    #[serde(rename = "Rc_um")]
    pub rc_um: Option<f64>,
    /// Peak count per centimetre, 10 mm / RSm; `None` as RSm.
    #[serde(rename = "RPc_per_cm")]
    pub rpc_per_cm: Option<f64>,
    /// Peak count per inch, 25.4 mm / RSm (the SJ series' Ppi: Pc for a unit length of one
    /// inch); `None` as RSm.
    #[serde(rename = "Rppi_per_inch")]
    pub rppi_per_inch: Option<f64>,
    /// Rδc = C(Rmr1) − C(Rmr2) at [`MaterialLevels::rdc_pct`], µm.
    #[serde(rename = "Rdc_um")]
    pub rdc_um: f64,
    /// Rmr(c), Rmr and the Rk family as ISO 13565-2 and ISO 4287 read them (the report's
    /// keys at this level).
    #[serde(flatten)]
    pub material: MaterialRatio,
}

/// The material-ratio family of one evaluated profile under one reading: ISO's in
/// [`RoughnessParams::material`], the SJ series' in
/// [`super::sj_material_ratio::SjMaterialRatio`]. The same names and units either way.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaterialRatio {
    /// Rmr(c) at the peak-reference depths of [`MaterialLevels::rmr_c_depths_pct_rt`].
    #[serde(rename = "Rmr(c)")]
    pub rmr_c: Vec<RmrC>,
    /// Relative material ratio at [`MaterialLevels::rmr_delta_um`] below C(Rmr0), %.
    #[serde(rename = "Rmr_pct")]
    pub rmr_pct: f64,
    /// The Rk family: its seven values under their report keys (`Rk_um` … `A2`).
    #[serde(flatten)]
    pub rk: RkFamily,
}

impl MaterialRatio {
    /// The family at `levels` of a profile whose highest point is `top` and whose height is
    /// `rt`, under a reading: the material ratio at a height, `ratio_pct(c)`, the height at a
    /// material ratio, `level_at(mr_pct)`, and `rk`, the Rk family it constructs, all on its
    /// own material ratio curve.
    pub(super) fn read(
        levels: &MaterialLevels,
        (top, rt): (f64, f64),
        ratio_pct: impl Fn(f64) -> f64,
        level_at: impl Fn(f64) -> f64,
        rk: RkFamily,
    ) -> MaterialRatio {
        let rmr_c = levels
            .rmr_c_depths_pct_rt
            .iter()
            .map(|&d| {
                let depth_um = rt * d / 100.0;
                RmrC {
                    depth_pct_rt: d,
                    depth_um,
                    value_pct: ratio_pct(top - depth_um),
                }
            })
            .collect();
        MaterialRatio {
            rmr_c,
            rmr_pct: ratio_pct(level_at(levels.rmr_reference_pct) - levels.rmr_delta_um),
            rk,
        }
    }
}

/// One Rmr(c) value with its level.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RmrC {
    /// Depth below the highest peak in % of Rt (the SJ series' "P:10 %").
    pub depth_pct_rt: f64,
    /// The same depth in µm.
    pub depth_um: f64,
    /// The material ratio there, %.
    pub value_pct: f64,
}

/// The levels of the material ratio parameters. [`Default`] is the set an SJ-410 reports in its
/// own result files (`Rmr(c)` "P:10,0%" and "P:15,0%", `Rdc` "10,0%:25,0%", `Rmr`
/// "0,0%:0,10um", public SJ-410 memory-card files, firmware V.1.014); the SJ-210's defaults are
/// not documented in what we found and are taken to be the same.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaterialLevels {
    /// Rmr(c) depths below the highest peak, % of Rt.
    pub rmr_c_depths_pct_rt: Vec<f64>,
    /// Rδc between these two material ratios (Rmr1, Rmr2), %.
    pub rdc_pct: [f64; 2],
    /// Rmr's reference material ratio Rmr0, %.
    pub rmr_reference_pct: f64,
    /// Rmr's depth below C(Rmr0), µm.
    pub rmr_delta_um: f64,
}

impl Default for MaterialLevels {
    fn default() -> MaterialLevels {
        MaterialLevels {
            rmr_c_depths_pct_rt: vec![10.0, 15.0],
            rdc_pct: [10.0, 25.0],
            rmr_reference_pct: 0.0,
            rmr_delta_um: 0.1,
        }
    }
}

/// A characterised line: its parameters, its recipe and the evaluated R profile.
#[derive(Debug, Clone, PartialEq)]
pub struct LineAnalysis {
    /// The parameters.
    pub params: RoughnessParams,
    /// How they were computed.
    pub recipe: Recipe,
    /// The evaluated roughness ordinates (evaluation length only) in µm.
    pub roughness_um: Vec<f64>,
    /// Their material ratio curve, [Mr %, height µm] at [`RK_CURVE_POINTS`] equal steps of
    /// Mr, from the same sort as `params.material.rk`: what the Rk construction plot draws.
    pub rk_curve: Vec<[f64; 2]>,
    /// Ra, Rq, Rsk, Rku over the whole evaluation length (ISO 21920-2, ANSI), beside the
    /// per-sampling-length means of `params` (ISO 4287:1997, the SJ series).
    pub evaluation_length: EvaluationLengthMoments,
    /// Why a parameter of `params` is blank, by its name (`RzJIS`, `RSm`, …).
    pub blank_reasons: BTreeMap<String, String>,
}

/// Amplitude parameters over the whole evaluation length, heights about the same reference
/// line as `params` (no further mean removal).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvaluationLengthMoments {
    /// mean |Z| over ln.
    #[serde(rename = "Ra_ln_um")]
    pub ra_um: f64,
    /// rms Z over ln.
    #[serde(rename = "Rq_ln_um")]
    pub rq_um: f64,
    /// mean Z³ / Rq³ over ln.
    #[serde(rename = "Rsk_ln")]
    pub rsk: f64,
    /// mean Z⁴ / Rq⁴ over ln.
    #[serde(rename = "Rku_ln")]
    pub rku: f64,
}

impl EvaluationLengthMoments {
    /// The moments of the heights `z` about zero, each sum taken in order: a line's over its
    /// evaluation length or one sampling length, a levelled grid's Sa, Sq, Ssk and Sku.
    pub(super) fn of(z: &[f64]) -> EvaluationLengthMoments {
        let n = z.len().max(1) as f64;
        let m2 = z.iter().map(|v| v * v).sum::<f64>() / n;
        let rq = m2.sqrt();
        EvaluationLengthMoments {
            ra_um: z.iter().map(|v| v.abs()).sum::<f64>() / n,
            rq_um: rq,
            rsk: if rq > 0.0 {
                z.iter().map(|v| v * v * v).sum::<f64>() / n / rq.powi(3)
            } else {
                0.0
            },
            rku: if rq > 0.0 {
                z.iter().map(|v| v * v * v * v).sum::<f64>() / n / (m2 * m2)
            } else {
                0.0
            },
        }
    }
}

/// The averaging convention, as written into every recipe.
pub const AVERAGING: &str = "Ra Rq Rp Rv Rz Rsk Rku RDq RDa RSm Rc RzJIS: per sampling length, then averaged over the N lengths (ISO 4287:1997, the SJ series); Rt Rz1max Rmr(c) Rdc Rmr and the Rk family: over the evaluation length; Ra_ln Rq_ln Rsk_ln Rku_ln: over the evaluation length (ISO 21920-2, ANSI)";

/// Points of [`LineAnalysis::rk_curve`] (0.1 % steps of Mr).
pub const RK_CURVE_POINTS: usize = 1001;

/// The definition ids written into every recipe: each parameter's of
/// [`super::parameter_table::PARAMETERS`], and Rmr(c)'s as ISO and the SJ series state it.
pub fn definitions() -> BTreeMap<String, String> {
    let rmr_c = [
        ("Rmr(c)_SJ", "SJ series mr[c] peak reference: Rmr at a depth below the highest peak of ln given in % of Rt, linear crossings"),
        ("Rmr(c)", "ISO4287:1997/Rmr(c) bearing length at depth c below the highest peak over ln, linear crossings"),
    ];
    PARAMETERS
        .iter()
        .map(|p| (p.stem(), p.definition))
        .chain(rmr_c)
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

/// Minimum points per sampling length (the 7-point slope and meaningful moments need some).
const MIN_POINTS_PER_SECTION: usize = 8;

/// How the evaluation length is divided: `n_sec` sections of `per` points from point `start`,
/// the rule that chose them in words, and a section's length.
struct SectionPlan {
    n_sec: usize,
    per: usize,
    start: usize,
    rule: String,
    section_length_mm: f64,
}

/// A line of `points` at `pitch_mm` too short to evaluate with the cut-off `lc` mm.
fn too_short(points: usize, pitch_mm: f64, lc: f64) -> MetrologyError {
    MetrologyError::TooShort {
        points,
        length_mm: points as f64 * pitch_mm,
        sampling_length_mm: lc,
        min_points: MIN_POINTS_PER_SECTION,
    }
}

/// The sections of `n_all` points at `pitch_mm` for the cut-off `lc`: the central `central`
/// sampling lengths when given, else `sampling_lengths` of ⌊n/N⌋ points each when given, else
/// N from L/λc (within 1 % of a whole number, or truncated with the central N·lr evaluated).
fn plan_sections(
    n_all: usize,
    pitch_mm: f64,
    lc: f64,
    central: Option<u32>,
    sampling_lengths: Option<u32>,
) -> Result<SectionPlan, MetrologyError> {
    let length_mm = n_all as f64 * pitch_mm;
    let ratio = length_mm / lc;
    let (n_sec, rule, start, per) = match (central, sampling_lengths) {
        (Some(0), _) | (None, Some(0)) => return Err(MetrologyError::ZeroSections { got: 0 }),
        (Some(k), _) => {
            let k = k as usize;
            let per = (lc / pitch_mm).round() as usize;
            let used = k.saturating_mul(per);
            if used > n_all {
                return Err(too_short(n_all, pitch_mm, lc));
            }
            let left = (n_all - used) / 2;
            (
                k,
                format!(
                    "given N = {k}: the central N·lr of the traverse, {left} points before it and {} after left out (the filter's run-up and run-out)",
                    n_all - used - left
                ),
                left,
                per,
            )
        }
        (None, Some(k)) => {
            let k = k as usize;
            (k, format!("given N = {k}, ⌊n/N⌋ points each"), 0, n_all / k)
        }
        (None, None) => {
            let nearest = ratio.round();
            if nearest >= 1.0 && (ratio - nearest).abs() <= 0.01 * nearest {
                let k = nearest as usize;
                (
                    k,
                    format!("L/λc = {ratio:.4} within 1 % of {k}, ⌊n/N⌋ points each"),
                    0,
                    n_all / k,
                )
            } else {
                let k = ratio.floor() as usize;
                if k == 0 {
                    return Err(too_short(n_all, pitch_mm, lc));
                }
                let per = (lc / pitch_mm).round() as usize;
                let used = (k * per).min(n_all);
                (
                    k,
                    format!("L/λc = {ratio:.4} truncated to {k}, central N·lr evaluated"),
                    (n_all - used) / 2,
                    per,
                )
            }
        }
    };
    if per < MIN_POINTS_PER_SECTION {
        if sampling_lengths.is_none() && central.is_none() && ratio >= 1.0 {
            return Err(MetrologyError::PitchTooCoarse {
                pitch_mm,
                points_per_sampling_length: per,
                sampling_length_mm: lc,
                min_points: MIN_POINTS_PER_SECTION,
            });
        }
        return Err(too_short(n_all, pitch_mm, lc));
    }
    let section_length_mm = per as f64 * pitch_mm;
    // Say plainly when a section is not a sampling length of λc (an instrument's arbitrary
    // evaluation length shorter than λc, a short form-only trace).
    let rule = if section_length_mm < lc * 0.99 {
        format!(
            "{rule}; each section is {} mm long, shorter than λc {lc} mm: the parameters are over that length, not over a sampling length of λc",
            crate::numfmt::fmt(section_length_mm, crate::numfmt::Quantity::LengthMm)
        )
    } else {
        rule
    };
    Ok(SectionPlan {
        n_sec,
        per,
        start,
        rule,
        section_length_mm,
    })
}

/// The local slope (µm/µm) at each point of the evaluated profile `r`, the 7-point central
/// difference; `None` within three points of either end.
fn slopes_7_point(r: &[f64], pitch_mm: f64) -> Vec<Option<f64>> {
    let used = r.len();
    (0..used)
        .map(|i| {
            if i < 3 || i + 3 >= used {
                return None;
            }
            let z = |k: usize| r.get(k).copied().unwrap_or(0.0);
            Some(
                (z(i + 3) - 9.0 * z(i + 2) + 45.0 * z(i + 1) - 45.0 * z(i - 1) + 9.0 * z(i - 2)
                    - z(i - 3))
                    / (60.0 * pitch_mm * 1000.0),
            )
        })
        .collect()
}

/// Characterises one line of heights (µm) sampled at `pitch_mm`: the profile filtered, its
/// sampling lengths planned and evaluated, the material-ratio family of the evaluation
/// length, and the recipe that says how.
pub fn analyze_line(
    heights_um: &[f64],
    pitch_mm: f64,
    options: &Options,
) -> Result<LineAnalysis, MetrologyError> {
    check_pitch(pitch_mm)?;
    check_heights(heights_um)?;
    let lc = options.lambda_c_mm;
    if !(lc.is_finite() && lc > 0.0) {
        return Err(MetrologyError::BadCutoff { cutoff_mm: lc });
    }
    let (r_all, lambda_c) = filtered_profile(heights_um, pitch_mm, options)?;
    // Form-only: P parameters, the whole length one section unless N is given.
    let sampling_lengths = options.sampling_lengths.or(options.form.map(|_| 1));
    let n_all = heights_um.len();
    let plan = plan_sections(
        n_all,
        pitch_mm,
        lc,
        options.central_sections,
        sampling_lengths,
    )?;
    let used = plan.n_sec * plan.per;
    let Some(r) = r_all.get(plan.start..plan.start + used) else {
        return Err(too_short(n_all, pitch_mm, lc));
    };
    let r = r.to_vec();
    let acc = Acc::of_sections(&r, &plan, pitch_mm);
    let (rk, rk_curve) = rk_family_and_curve(&r, RK_CURVE_POINTS)?;
    Ok(LineAnalysis {
        params: acc.params(&r, plan.n_sec, rk),
        recipe: line_recipe(options, lambda_c, &plan, n_all - used, pitch_mm),
        evaluation_length: EvaluationLengthMoments::of(&r),
        blank_reasons: acc.blank_reasons(plan.n_sec),
        roughness_um: r,
        rk_curve,
    })
}

/// λs, then λc or (form-only) the stated form, as `options` say: the roughness profile over
/// the whole traced length (the primary profile where λc does not apply), and whether the λc
/// filter made it.
fn filtered_profile(
    heights_um: &[f64],
    pitch_mm: f64,
    options: &Options,
) -> Result<(Vec<f64>, bool), MetrologyError> {
    let primary = match options.lambda_s_um {
        Some(ls) => filter::gaussian_mean_line(heights_um, pitch_mm, ls / 1000.0)?,
        None => heights_um.to_vec(),
    };
    let primary = match options.form {
        Some(form) => remove_form(&primary, form)?,
        None => primary,
    };
    if !options.apply_lambda_c || options.form.is_some() {
        return Ok((primary, false));
    }
    Ok((
        filter::roughness(&primary, pitch_mm, options.lambda_c_mm)?,
        true,
    ))
}

/// How a line was evaluated: the standard, the filter and its end treatment, the sampling
/// lengths `plan` cut (`not_evaluated` points left out), the mean line, the definitions.
fn line_recipe(
    options: &Options,
    filtered: bool,
    plan: &SectionPlan,
    not_evaluated: usize,
    pitch_mm: f64,
) -> Recipe {
    Recipe {
        standard: "ISO 4287:1997 (as the SJ series, standard ISO1997), ISO 13565-2, ISO 16610-21"
            .to_string(),
        filter: match (options.form, filtered) {
            (Some(form), _) => format!(
                "none: form-only evaluation of the primary profile, {} removed",
                form.describe()
            ),
            (None, true) => "ISO 16610-21 Gaussian, kernel truncated at ±λc".to_string(),
            (None, false) => "none (input is an R profile)".to_string(),
        },
        end_treatment: if filtered { END_TREATMENT } else { "none" }.to_string(),
        lambda_c_mm: options.lambda_c_mm,
        lambda_s_um: options.lambda_s_um,
        sampling_lengths: plan.n_sec as u32,
        sampling_lengths_rule: plan.rule.clone(),
        points_per_section: plan.per,
        points_not_evaluated: not_evaluated,
        first_point: plan.start,
        pitch_mm,
        mean_line: match (options.form, filtered) {
            (Some(form), _) => format!("the {} of the primary profile", form.describe()),
            (None, true) => "λc Gaussian filter mean line".to_string(),
            (None, false) => "zero line of the R profile as given".to_string(),
        },
        profile: if options.form.is_some() { "P" } else { "R" },
        form: options.form.map(Form::describe),
        section_length_mm: plan.section_length_mm,
        averaging: AVERAGING.to_string(),
        definitions: definitions(),
    }
}

/// Characterises a [`Profile`] with options from its conditions ([`Options::from_profile`]).
pub fn analyze_profile(profile: &Profile) -> Result<LineAnalysis, MetrologyError> {
    analyze_line(
        &profile.heights_um,
        profile.pitch_x_mm,
        &Options::from_profile(profile),
    )
}

/// Sums of per-section values.
#[derive(Default)]
struct Acc {
    ra: f64,
    rq: f64,
    rp: f64,
    rv: f64,
    rz: f64,
    rz1max: f64,
    rzjis: Option<f64>,
    /// Peaks and valleys of the last section when it had too few for RzJIS.
    ten_point_short: Option<(usize, usize)>,
    /// The first section with too few peaks or valleys for RzJIS: (index, peaks, valleys).
    rzjis_short_section: Option<(usize, usize, usize)>,
    rsk: f64,
    rku: f64,
    rdq: f64,
    rda: f64,
    rsm: f64,
    rc: f64,
    rsm_n: usize,
}

impl Acc {
    /// The sums over the sampling lengths of `plan` of the evaluated profile `r`.
    fn of_sections(r: &[f64], plan: &SectionPlan, pitch_mm: f64) -> Acc {
        let (n_sec, per) = (plan.n_sec, plan.per);
        let slopes = slopes_7_point(r, pitch_mm);
        let mut acc = Acc::default();
        let lr_um = per as f64 * pitch_mm * 1000.0;
        for s in 0..n_sec {
            let sec = r.get(s * per..(s + 1) * per).unwrap_or(&[]);
            let sl = slopes.get(s * per..(s + 1) * per).unwrap_or(&[]);
            acc.add_section(sec, sl, pitch_mm * 1000.0, lr_um);
            if let (Some((peaks, valleys)), None) = (acc.ten_point_short, acc.rzjis_short_section) {
                acc.rzjis_short_section = Some((s, peaks, valleys));
            }
        }
        acc
    }

    /// Why a parameter is blank, by name: RzJIS without five peaks and valleys in a sampling
    /// length, the element parameters without a profile element.
    fn blank_reasons(&self, n_sec: usize) -> BTreeMap<String, String> {
        let mut blank_reasons = BTreeMap::new();
        if let Some((s, peaks, valleys)) = self.rzjis_short_section {
            blank_reasons.insert(
                "RzJIS".to_string(),
                format!(
                    "sampling length {} of {n_sec} has {peaks} peaks and {valleys} valleys between mean-line crossings, fewer than the 5 of each the ten-point height needs",
                    s + 1
                ),
            );
        }
        if self.rsm_n == 0 {
            for name in ["RSm", "Rc", "RPc", "Rppi"] {
                blank_reasons.insert(
                    name.to_string(),
                    format!("no sampling length holds a profile element (a peak reaching +10 % and a valley reaching −10 % of its Rz between upward mean-line crossings, at least 1 % of the sampling length wide), so {name} is undefined"),
                );
            }
        }
        blank_reasons
    }

    /// The parameters: the sums averaged over the `n_sec` sampling lengths, Rt and the
    /// material-ratio family over the evaluation length `r`, the Rk family `rk`.
    fn params(&self, r: &[f64], n_sec: usize, rk: RkFamily) -> RoughnessParams {
        let k = n_sec as f64;
        let (min, max) = crate::extremes::min_max(r);
        let levels = MaterialLevels::default();
        let rt = max - min;
        let rsm_um = (self.rsm_n > 0).then(|| self.rsm / self.rsm_n as f64);
        RoughnessParams {
            ra_um: self.ra / k,
            rq_um: self.rq / k,
            rp_um: self.rp / k,
            rv_um: self.rv / k,
            rz_um: self.rz / k,
            rt_um: max - min,
            rz1max_um: self.rz1max,
            rzjis_um: self.rzjis.map(|v| v / k),
            rsk: self.rsk / k,
            rku: self.rku / k,
            rdq: self.rdq / k,
            rda: self.rda / k,
            rsm_um,
            rc_um: (self.rsm_n > 0).then(|| self.rc / self.rsm_n as f64),
            rpc_per_cm: rsm_um.filter(|w| *w > 0.0).map(|w| 10_000.0 / w),
            rppi_per_inch: rsm_um.filter(|w| *w > 0.0).map(|w| 25_400.0 / w),
            rdc_um: level_at_material_ratio(r, levels.rdc_pct[0])
                - level_at_material_ratio(r, levels.rdc_pct[1]),
            material: MaterialRatio::read(
                &levels,
                (max, rt),
                |c| material_ratio_pct(r, c),
                |mr| level_at_material_ratio(r, mr),
                rk,
            ),
        }
    }

    fn add_section(&mut self, z: &[f64], slopes: &[Option<f64>], pitch_um: f64, lr_um: f64) {
        let m = EvaluationLengthMoments::of(z);
        let rp = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let rv = -z.iter().copied().fold(f64::INFINITY, f64::min);
        self.ra += m.ra_um;
        self.rq += m.rq_um;
        self.rp += rp;
        self.rv += rv;
        self.rz += rp + rv;
        self.rz1max = self.rz1max.max(rp + rv);
        self.rsk += m.rsk;
        self.rku += m.rku;
        let sl: Vec<f64> = slopes.iter().flatten().copied().collect();
        if !sl.is_empty() {
            self.rdq += (sl.iter().map(|s| s * s).sum::<f64>() / sl.len() as f64).sqrt();
            self.rda += sl.iter().map(|s| s.abs()).sum::<f64>() / sl.len() as f64;
        }
        // RzJIS is blank once a section has too few peaks or valleys.
        let rzjis = ten_point(z);
        self.ten_point_short = rzjis.err();
        self.rzjis = match rzjis {
            Ok(v) if self.rzjis_short_section.is_none() => Some(self.rzjis.unwrap_or(0.0) + v),
            _ => None,
        };
        let elements = profile_elements(z, pitch_um, 0.1 * (rp + rv), 0.01 * lr_um);
        if !elements.is_empty() {
            let n = elements.len() as f64;
            self.rsm += elements.iter().map(|e| e.width_um).sum::<f64>() / n;
            self.rc += elements.iter().map(|e| e.zp + e.zv).sum::<f64>() / n;
            self.rsm_n += 1;
        }
    }
}

/// Ten-point height of a section: peaks are the maxima of the portions above the mean line,
/// valleys the minima of the portions below; mean of the 5 highest plus mean of the 5 deepest.
/// Fewer than 5 of either: the counts of peaks and valleys found.
fn ten_point(z: &[f64]) -> Result<f64, (usize, usize)> {
    let mut peaks = Vec::new();
    let mut valleys = Vec::new();
    let mut cur: Option<(bool, f64)> = None;
    for &v in z {
        if v == 0.0 {
            continue;
        }
        let above = v > 0.0;
        cur = match cur {
            Some((a, ext)) if a == above => Some((a, if above { ext.max(v) } else { ext.min(v) })),
            Some((a, ext)) => {
                if a { &mut peaks } else { &mut valleys }.push(ext);
                Some((above, v))
            }
            None => Some((above, v)),
        };
    }
    // The portions cut by the section ends are incomplete and do not count: the first was
    // pushed when the second began (the last is still `cur`).
    if let Some(&first) = z.iter().find(|v| **v != 0.0) {
        let list = if first > 0.0 {
            &mut peaks
        } else {
            &mut valleys
        };
        if !list.is_empty() {
            list.remove(0);
        }
    }
    if peaks.len() < 5 || valleys.len() < 5 {
        return Err((peaks.len(), valleys.len()));
    }
    peaks.sort_by(|a, b| b.total_cmp(a));
    valleys.sort_by(|a, b| a.total_cmp(b));
    let p: f64 = peaks.iter().take(5).sum::<f64>() / 5.0;
    let v: f64 = valleys.iter().take(5).sum::<f64>() / 5.0;
    Ok(p - v)
}

/// A profile element of a section: a peak and the valley after it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Element {
    /// Width Xs, µm.
    width_um: f64,
    /// Highest point above the mean line, µm.
    zp: f64,
    /// Depth of the lowest point below the mean line, µm.
    zv: f64,
}

/// The profile elements of a section: boundaries at the upward mean-line crossings (linearly
/// interpolated) that precede a peak reaching `+h` after a valley reaching `−h`; an element
/// narrower than `min_width_um` is merged into the following one (its boundary is dropped).
/// Zp and Zv are the extremes of the ordinates between consecutive boundaries.
fn profile_elements(z: &[f64], pitch_um: f64, h: f64, min_width_um: f64) -> Vec<Element> {
    let mut bounds: Vec<f64> = Vec::new();
    let mut last_up: Option<f64> = None;
    let mut seen_valley = false;
    for (i, pair) in z.windows(2).enumerate() {
        let (a, b) = (pair[0], pair[1]);
        if a <= 0.0 && b > 0.0 {
            let t = a / (a - b);
            last_up = Some((i as f64 + t) * pitch_um);
        }
        if b <= -h {
            seen_valley = true;
        }
        if b >= h && seen_valley {
            if let Some(x) = last_up {
                // An element narrower than the width discrimination merges with its neighbour.
                if bounds.last().is_none_or(|&l| x - l >= min_width_um) {
                    bounds.push(x);
                }
            }
            seen_valley = false;
        }
    }
    bounds
        .windows(2)
        .filter_map(|w| {
            let (a, b) = (*w.first()?, *w.get(1)?);
            // Ordinates strictly inside the element (a crossing lies between two points).
            let first = (a / pitch_um).ceil() as usize;
            let last = ((b / pitch_um).floor() as usize).min(z.len().saturating_sub(1));
            let inside = z.get(first..=last)?;
            let zp = inside.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let zv = -inside.iter().copied().fold(f64::INFINITY, f64::min);
            Some(Element {
                width_um: b - a,
                zp,
                zv,
            })
        })
        .collect()
}

/// The Rk family of a set of ordinates under one reading, with its construction (the core
/// levels and the secant, which the report's keys leave out: the plots draw them).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RkFamily {
    /// Core depth C − D, µm.
    #[serde(rename = "Rk_um")]
    pub rk_um: f64,
    /// Reduced peak height, µm.
    #[serde(rename = "Rpk_um")]
    pub rpk_um: f64,
    /// Reduced valley depth, µm.
    #[serde(rename = "Rvk_um")]
    pub rvk_um: f64,
    /// Material ratio at C, %.
    #[serde(rename = "Mr1_pct")]
    pub mr1_pct: f64,
    /// Material ratio at D, %.
    #[serde(rename = "Mr2_pct")]
    pub mr2_pct: f64,
    /// Area above C, µm·% (report key `A1`, unit in the recipe's definition).
    #[serde(rename = "A1")]
    pub a1_um_pct: f64,
    /// Area below D, µm·% (report key `A2`, unit in the recipe's definition).
    #[serde(rename = "A2")]
    pub a2_um_pct: f64,
    /// Upper core level C (the equivalent straight line at mr = 0 %), µm.
    #[serde(skip)]
    pub upper_level_um: f64,
    /// Lower core level D (the equivalent straight line at mr = 100 %), µm.
    #[serde(skip)]
    pub lower_level_um: f64,
    /// Where the 40 % secant of least gradient starts, % (it ends 40 % later).
    #[serde(skip)]
    pub secant_start_pct: f64,
}

/// Rmc(mr): height at material ratio `mr_pct` by linear quantiles of `sorted_desc`.
pub(super) fn rmc(sorted_desc: &[f64], mr_pct: f64) -> f64 {
    let n = sorted_desc.len();
    let p = (mr_pct / 100.0).clamp(0.0, 1.0) * (n.saturating_sub(1)) as f64;
    let i = p.floor() as usize;
    let t = p - i as f64;
    let a = sorted_desc.get(i).copied().unwrap_or(0.0);
    let b = sorted_desc.get(i + 1).copied().unwrap_or(a);
    a + t * (b - a)
}

/// Material ratio (%) at level `c` on the quantile curve: the inverse of [`rmc`].
fn mr_at(sorted_desc: &[f64], c: f64) -> f64 {
    let n = sorted_desc.len();
    if n < 2 {
        return 0.0;
    }
    let first = sorted_desc.first().copied().unwrap_or(0.0);
    let last = sorted_desc.last().copied().unwrap_or(0.0);
    if c >= first {
        return 0.0;
    }
    if c <= last {
        return 100.0;
    }
    // First index with value < c (values are non-increasing).
    let k = sorted_desc.partition_point(|v| *v >= c).max(1);
    let hi = sorted_desc.get(k - 1).copied().unwrap_or(first);
    let lo = sorted_desc.get(k).copied().unwrap_or(last);
    let t = if hi > lo { (hi - c) / (hi - lo) } else { 0.0 };
    ((k - 1) as f64 + t) / (n - 1) as f64 * 100.0
}

/// The ordinates highest first, after the checks the Rk family needs: all finite, at least two.
pub(super) fn checked_sorted_desc(z: impl Into<Vec<f64>>) -> Result<Vec<f64>, MetrologyError> {
    let z = z.into();
    check_heights(&z)?;
    if z.len() < 2 {
        return Err(MetrologyError::TooShort {
            points: z.len(),
            length_mm: 0.0,
            sampling_length_mm: 0.0,
            min_points: 2,
        });
    }
    Ok(sorted_desc(z))
}

/// The ordinates highest first, sorted where they are (an owned grid is not copied), in the
/// order of `total_cmp`, which compares the bits as integers with all but the sign bit
/// flipped when it is set: those keys' complements are sorted, a comparison one instruction.
/// Only identical bits compare equal, so the unstable sort gives the stable sort's sequence;
/// a grid's million ordinates and more are split at their median, each half on a thread.
fn sorted_desc(mut s: Vec<f64>) -> Vec<f64> {
    let total_key = |k: i64| k ^ (((k >> 63) as u64) >> 1) as i64;
    let keys: &mut [i64] = bytemuck::cast_slice_mut(&mut s);
    keys.iter_mut().for_each(|k| *k = !total_key(*k));
    if keys.len() < 1 << 20 {
        keys.sort_unstable();
    } else {
        let (high, _, low) = keys.select_nth_unstable(keys.len() / 2);
        std::thread::scope(|t| {
            t.spawn(|| high.sort_unstable());
            low.sort_unstable();
        });
    }
    keys.iter_mut().for_each(|k| *k = total_key(!*k));
    s
}

/// The ISO 13565-2 Rk family of ordinates `z` (µm) and the material ratio curve it is built on,
/// `points` pairs `[mr_pct, height_um]`, from one sort of them: what a line's Rk plot draws.
pub fn rk_family_and_curve(
    z: &[f64],
    points: usize,
) -> Result<(RkFamily, Vec<[f64; 2]>), MetrologyError> {
    let s = checked_sorted_desc(z)?;
    Ok((rk_of_sorted(&s), curve_of_sorted(&s, points)))
}

/// The Rk family of at least two ordinates sorted highest first: the minimum-gradient 40 %
/// secant on their linear-quantile material ratio curve, searched in 0.1 % steps.
pub(super) fn rk_of_sorted(s: &[f64]) -> RkFamily {
    const STEPS: usize = 1000; // 0.1 % grid
    let h: Vec<f64> = (0..=STEPS)
        .map(|k| rmc(s, k as f64 * 100.0 / STEPS as f64))
        .collect();
    let win = STEPS * 40 / 100;
    let mut best: Option<(f64, usize)> = None;
    for a in 0..=(STEPS - win) {
        let drop = h.get(a).copied().unwrap_or(0.0) - h.get(a + win).copied().unwrap_or(0.0);
        // Strictly smaller beyond rounding: the first secant wins a tie.
        if best.is_none_or(|(b, _)| drop < b - 1e-12 * b.abs()) {
            best = Some((drop, a));
        }
    }
    let best = best.unwrap_or((0.0, 0));
    let a_pct = best.1 as f64 * 100.0 / STEPS as f64;
    let slope = -best.0 / 40.0; // µm per %
    let h_a = h.get(best.1).copied().unwrap_or(0.0);
    let c = h_a - slope * a_pct;
    let d = h_a + slope * (100.0 - a_pct);
    let mr1 = mr_at(s, c);
    let mr2 = mr_at(s, d);
    // Areas by trapezoids on a fine grid of the quantile curve.
    let area = |from: f64, to: f64, f: &dyn Fn(f64) -> f64| -> f64 {
        if to <= from {
            return 0.0;
        }
        let m = 2000usize;
        let dx = (to - from) / m as f64;
        (0..m)
            .map(|k| {
                let x0 = from + k as f64 * dx;
                0.5 * (f(x0) + f(x0 + dx)) * dx
            })
            .sum()
    };
    let a1 = area(0.0, mr1, &|mr| (rmc(s, mr) - c).max(0.0));
    let a2 = area(mr2, 100.0, &|mr| (d - rmc(s, mr)).max(0.0));
    RkFamily::of_core(c - d, (c, d), a_pct, (mr1, a1), (mr2, a2))
}

impl RkFamily {
    /// The family of a core `rk_um` deep between the levels `(c, d)` whose secant starts at
    /// `start_pct`, from the material ratio and the area beyond each limit (`(Mr1, A1)` above
    /// C, `(Mr2, A2)` below D): Rpk = 2·A1/Mr1, Rvk = 2·A2/(100 − Mr2).
    pub(super) fn of_core(
        rk_um: f64,
        (c, d): (f64, f64),
        start_pct: f64,
        (mr1, a1): (f64, f64),
        (mr2, a2): (f64, f64),
    ) -> RkFamily {
        RkFamily {
            rk_um,
            rpk_um: if mr1 > 0.0 { 2.0 * a1 / mr1 } else { 0.0 },
            rvk_um: if mr2 < 100.0 {
                2.0 * a2 / (100.0 - mr2)
            } else {
                0.0
            },
            mr1_pct: mr1,
            mr2_pct: mr2,
            a1_um_pct: a1,
            a2_um_pct: a2,
            upper_level_um: c,
            lower_level_um: d,
            secant_start_pct: start_pct,
        }
    }
}

/// The material ratio curve Rmc(mr) of ordinates `s` sorted highest first, as `points` pairs
/// `[mr_pct, height_um]` at equal steps of mr from 0 to 100 % (linear quantiles of the
/// ordinates, the highest at 0 %); empty for fewer than 2 ordinates or points.
fn curve_of_sorted(s: &[f64], points: usize) -> Vec<[f64; 2]> {
    if s.len() < 2 || points < 2 {
        return Vec::new();
    }
    (0..points)
        .map(|k| {
            let mr = 100.0 * k as f64 / (points - 1) as f64;
            [mr, rmc(s, mr)]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_sorted_in_two_halves_is_the_one_sort_to_the_bit() {
        // Above the split's threshold and below it, with ties, both zeros, infinities, NaN of
        // both signs and runs at the median: every value where one sort by `total_cmp` puts it.
        for n in [(1 << 20) + 7, 1000] {
            let z: Vec<f64> = (0..n)
                .map(|k| match k % 9 {
                    0 => 0.0,
                    1 => -0.0,
                    2 => [f64::INFINITY, f64::NEG_INFINITY, f64::NAN, -f64::NAN][k % 4],
                    _ => ((k as f64 * 0.618).sin() * 64.0).round() / 16.0,
                })
                .collect();
            let mut want = z.clone();
            want.sort_by(|a, b| b.total_cmp(a));
            let bits = |v: &[f64]| bytemuck::cast_slice::<f64, u64>(v).to_vec();
            assert_eq!(bits(&sorted_desc(z)), bits(&want));
        }
    }

    /// The Rk family and curve of `z` from the standard library's sort by `total_cmp`.
    fn by_std_sort(z: &[f64], points: usize) -> (RkFamily, Vec<[f64; 2]>) {
        let mut s = z.to_vec();
        s.sort_by(|a, b| b.total_cmp(a));
        (rk_of_sorted(&s), curve_of_sorted(&s, points))
    }

    #[test]
    fn rk_family_and_curve_are_those_of_the_ordinates_sorted() {
        // Ties, a constant run, negative heights and a short line: the figures and the curve
        // are the bits of the construction on the ordinates sorted by the standard library.
        let mut z: Vec<f64> = (0..5000)
            .map(|k| ((k as f64 * 0.37).sin() * 2.0 + (k as f64 * 0.011).cos()).round() / 8.0)
            .collect();
        z.extend(std::iter::repeat_n(0.25, 300));
        for (zs, points) in [(&z[..], 1001), (&z[..], 2), (&z[..], 1), (&z[..7], 1001)] {
            let (rk, curve) = rk_family_and_curve(zs, points).unwrap();
            let (want_rk, want) = by_std_sort(zs, points);
            assert_eq!(format!("{rk:?}"), format!("{want_rk:?}"));
            assert_eq!(curve.len(), want.len());
            for (a, b) in curve.iter().zip(&want) {
                assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
            }
        }
        for bad in [&[1.0][..], &[], &[1.0, f64::NAN, 2.0]] {
            assert!(rk_family_and_curve(bad, 11).is_err(), "{bad:?}");
        }
    }

    /// A line's stored Rk family and curve are those of its roughness ordinates, and its Rk
    /// parameters are that family's.
    #[test]
    fn a_line_carries_the_rk_family_and_curve_of_its_roughness() {
        let z: Vec<f64> = (0..6000)
            .map(|k| (k as f64 * 0.0123).sin() + 0.3 * (k as f64 * 0.21).cos())
            .collect();
        let a = analyze_line(&z, 0.0005, &Options::default()).unwrap();
        let (rk, want) = by_std_sort(&a.roughness_um, RK_CURVE_POINTS);
        assert_eq!(a.params.material.rk, rk);
        assert_eq!(a.rk_curve.len(), RK_CURVE_POINTS);
        for (got, want) in a.rk_curve.iter().zip(&want) {
            assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits));
        }
    }
}
