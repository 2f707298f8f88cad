//! Our parameters side by side with the values the instrument reported (`RDRES`), with the
//! difference and whether it lies within a documented tolerance, so a user can see at a glance
//! where the two agree.
//!
//! **Tolerances** ([`tolerance_for`]): |ours − instrument| ≤ rel · |instrument| + abs, the
//! same form and, for the amplitude parameters, the same numbers as the read-out's Ra check
//! ([`crate::sj210::sanity`]). They allow for what legitimately separates our number from the
//! instrument's on the same trace: the printed resolution of the heights and of its result
//! (0.001 µm each) and where the sampling lengths split, and, for a primary profile we
//! filter ourselves (`filtered_here`), the λc filter near the ends (the instrument filters its
//! whole traverse, run-up and run-out included, which the exported evaluation length lacks).
//! On the instrument's own R profile our heights, Rp/Rv/Rz/Rt and lr-averaged moments
//! reproduce its values (Mitutoyo's export agrees to the last printed digit), so a value
//! outside its tolerance points at a wrong condition, a read-out error or a different
//! definition, not at rounding.
//!
//! | parameters | rel (R profile) | rel (filtered here) | abs |
//! |---|---|---|---|
//! | Ra Rq Rp Rv Rz Rt Rz1max RzJIS | 2 % | 10 % | 0.005 µm |
//! | Rsk Rku | 5 % | 15 % | 0.02 |
//! | RΔq RΔa | 3 % | 10 % | 0.002 |
//! | RSm Rc RPc Rppi (element rules: hysteresis and end elements differ between implementations) | 5 % | 10 % | 0.5 µm, 0.005 µm, 1 /cm, 2.5 /in |
//! | Rk Rpk Rvk Rδc (the instrument's material ratio curve is binned at 1 % of Rt) | 5 % | 10 % | 0.005 µm |
//! | Mr1 Mr2 Rmr Rmr(c) | — | — | 1 (R) or 2 (filtered here) percentage points |
//!
//! Depends on [`super::params`] and [`crate::profile`].

use super::parameter_table::parameter;
use super::params::RoughnessParams;
use crate::profile::InstrumentResult;
use serde::Serialize;
use std::collections::HashMap;

/// One parameter as the instrument and as we computed it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    /// Parameter name as the instrument displayed it.
    pub name: String,
    /// The instrument's value converted to our unit, `None` when it reported an error or its
    /// unit is not understood.
    pub instrument: Option<f64>,
    /// Our value, `None` when we do not compute this parameter or it is undefined here.
    pub ours: Option<f64>,
    /// ours − instrument, when both exist.
    pub difference: Option<f64>,
    /// Our parameter it was compared with (`RzJIS` for the instrument's `Rz` under JIS1982 /
    /// JIS1994, where Rz is the ten-point height; `Rmr(c)@10%Rt` for the first `Rmr(c)`),
    /// `None` for names we do not compute.
    pub compared_with: Option<String>,
    /// Unit of `instrument`, `ours` and `difference` ("um", "%", "/cm", "/in", "" for ratios).
    pub unit: &'static str,
    /// The largest |difference| still in agreement ([`tolerance_for`]), when both exist.
    pub tolerance: Option<f64>,
    /// |difference| ≤ tolerance, when both exist.
    pub within_tolerance: Option<bool>,
}

/// A tolerance: |ours − instrument| ≤ rel · |instrument| + abs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Tolerance {
    /// Relative part (0.02 = 2 %).
    pub rel: f64,
    /// Absolute floor, in the parameter's unit.
    pub abs: f64,
}

impl Tolerance {
    /// The allowed |difference| at the instrument's value `instrument`.
    pub fn allowed(&self, instrument: f64) -> f64 {
        self.rel * instrument.abs() + self.abs
    }
}

fn key(name: &str) -> String {
    name.chars()
        .filter(|c| !c.is_whitespace())
        .collect::<String>()
        .to_lowercase()
}

/// The tolerance of the module docs for our parameter `name` (as in `compared_with`, e.g.
/// "Ra", "Rmr(c)@10%Rt"), for a profile we filtered ourselves (`filtered_here`) or the
/// instrument's own R profile; `None` for names without one.
pub fn tolerance_for(name: &str, filtered_here: bool) -> Option<Tolerance> {
    let k = key(name);
    let base = k.split('@').next().unwrap_or("");
    let t = |rel_r: f64, rel_p: f64, abs: f64| {
        Some(Tolerance {
            rel: if filtered_here { rel_p } else { rel_r },
            abs,
        })
    };
    match base {
        "ra" | "rq" | "rp" | "rv" | "rz" | "rt" | "rz1max" | "rzjis" => t(0.02, 0.10, 0.005),
        "rsk" | "rku" => t(0.05, 0.15, 0.02),
        "rdq" | "rda" => t(0.03, 0.10, 0.002),
        "rsm" => t(0.05, 0.10, 0.5),
        "rpc" => t(0.05, 0.10, 1.0),
        "rppi" => t(0.05, 0.10, 2.5),
        "rc" | "rk" | "rpk" | "rvk" | "rdc" => t(0.05, 0.10, 0.005),
        "mr1" | "mr2" | "rmr" | "rmr(c)" => t(0.0, 0.0, if filtered_here { 2.0 } else { 1.0 }),
        _ => None,
    }
}

/// Our value for an instrument parameter name, with its unit: (value, unit, our name).
/// `occurrence` counts earlier results of the same name (the instrument reports `Rmr(c)` once
/// per level, in the order of its settings). `None` for names we do not map.
type Ours = (Option<f64>, &'static str, String);

fn ours_for(
    name: &str,
    p: &RoughnessParams,
    jis_ten_point_rz: bool,
    occurrence: usize,
) -> Option<Ours> {
    let k = key(name);
    let stem = match k.as_str() {
        "rz" if jis_ten_point_rz => "rzjis",
        "rδq" | "rdeltaq" => "rdq",
        "rδa" | "rdeltaa" | "da" => "rda",
        "pc" => "rpc",
        "ppi" => "rppi",
        "rδc" | "rdeltac" => "rdc",
        "rmr(c)" | "mr(c)" | "mr[c]" => {
            let level = p.material.rmr_c.get(occurrence)?;
            let name = format!("Rmr(c)@{}%Rt", level.depth_pct_rt);
            return Some((Some(level.value_pct), "%", name));
        }
        // The instrument's A1 and A2 are areas of its own counted 100-level curve: the SJ
        // series' reading reproduces them (`sj_material_ratio`), ISO's is not compared.
        "a1" | "a2" => return None,
        k => k,
    };
    let t = parameter(stem)?;
    let unit = if t.unit == "µm" { "um" } else { t.unit };
    Some((t.of(p), unit, t.stem().to_owned()))
}

/// Factor from the instrument's unit to ours, `None` when not understood.
fn factor(unit_in: &str, ours: &str) -> Option<f64> {
    let u = unit_in.trim().to_lowercase();
    match (ours, u.as_str()) {
        ("um", "um" | "µm" | "μm" | "micron") => Some(1.0),
        ("um", "mm") => Some(1000.0),
        ("um", "nm") => Some(0.001),
        ("%", "%" | "") => Some(1.0),
        ("/cm", "/cm" | "1/cm" | "cm-1") => Some(1.0),
        ("/cm", "/mm" | "1/mm") => Some(10.0),
        ("/in", "/in" | "1/in" | "/inch" | "ppi") => Some(1.0),
        ("", "" | "-") => Some(1.0),
        _ => None,
    }
}

/// Pairs each instrument result with our value; names we do not compute get `ours: None`.
/// Under `standard` (as the instrument's conditions record it, e.g. "ISO1997", "JIS1994") the
/// instrument's `Rz` is the ISO 4287:1997 maximum height, except under JIS1982 and JIS1994,
/// where it is the ten-point height and is compared with our `RzJIS`. The tolerances are those
/// of the instrument's own R profile, or of a profile we filtered ourselves when
/// `filtered_here` (a primary profile).
pub fn compare_profile(
    params: &RoughnessParams,
    instrument: &[InstrumentResult],
    standard: Option<&str>,
    filtered_here: bool,
) -> Vec<Comparison> {
    let jis = standard.is_some_and(|s| {
        let s: String = s.chars().filter(char::is_ascii_alphanumeric).collect();
        matches!(
            s.to_ascii_uppercase().as_str(),
            "JIS1982" | "JIS1994" | "JIS82" | "JIS94"
        )
    });
    let mut seen: HashMap<String, usize> = HashMap::new();
    instrument
        .iter()
        .map(|r| {
            let count = seen.entry(key(&r.name)).or_insert(0);
            let occurrence = *count;
            *count += 1;
            match ours_for(&r.name, params, jis, occurrence) {
                Some((ours, unit, ours_name)) => {
                    let inst = r.value.zip(factor(&r.unit, unit)).map(|(v, f)| v * f);
                    let difference = ours.zip(inst).map(|(o, i)| o - i);
                    let tolerance = tolerance_for(&ours_name, filtered_here)
                        .zip(inst)
                        .filter(|_| difference.is_some())
                        .map(|(t, i)| t.allowed(i));
                    Comparison {
                        name: r.name.clone(),
                        instrument: inst,
                        ours,
                        difference,
                        unit,
                        within_tolerance: difference.zip(tolerance).map(|(d, t)| d.abs() <= t),
                        tolerance,
                        compared_with: Some(ours_name),
                    }
                }
                None => Comparison {
                    name: r.name.clone(),
                    instrument: r.value,
                    ours: None,
                    difference: None,
                    unit: "",
                    compared_with: None,
                    tolerance: None,
                    within_tolerance: None,
                },
            }
        })
        .collect()
}
