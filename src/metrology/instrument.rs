//! Our parameters side by side with the values the instrument reported (`RDRES`), with the
//! difference, so a user can see at a glance where the two agree.
//!
//! Depends on [`super::params`] and [`crate::profile`].

use super::params::RoughnessParams;
use crate::profile::InstrumentResult;
use serde::Serialize;

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
    /// Unit of `instrument`, `ours` and `difference` ("um", "%", "" for ratios).
    pub unit: &'static str,
}

/// Our value for an instrument parameter name, with its unit; `None` for names we do not map.
fn ours_for(name: &str, p: &RoughnessParams) -> Option<(Option<f64>, &'static str)> {
    let key: String = name
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect::<String>()
        .to_ascii_lowercase();
    Some(match key.as_str() {
        "ra" => (Some(p.ra_um), "um"),
        "rq" => (Some(p.rq_um), "um"),
        "rz" => (Some(p.rz_um), "um"),
        "rp" => (Some(p.rp_um), "um"),
        "rv" => (Some(p.rv_um), "um"),
        "rt" => (Some(p.rt_um), "um"),
        "rz1max" => (Some(p.rz1max_um), "um"),
        "rzjis" => (p.rzjis_um, "um"),
        "rsk" => (Some(p.rsk), ""),
        "rku" => (Some(p.rku), ""),
        "rdq" | "rδq" | "rΔq" | "rdeltaq" => (Some(p.rdq), ""),
        "rsm" => (p.rsm_um, "um"),
        "rk" => (Some(p.rk_um), "um"),
        "rpk" => (Some(p.rpk_um), "um"),
        "rvk" => (Some(p.rvk_um), "um"),
        "mr1" => (Some(p.mr1_pct), "%"),
        "mr2" => (Some(p.mr2_pct), "%"),
        _ => return None,
    })
}

/// Factor from the instrument's unit to ours, `None` when not understood.
fn factor(unit_in: &str, ours: &str) -> Option<f64> {
    let u = unit_in.trim().to_ascii_lowercase();
    match (ours, u.as_str()) {
        ("um", "um" | "µm" | "μm" | "micron") => Some(1.0),
        ("um", "mm") => Some(1000.0),
        ("um", "nm") => Some(0.001),
        ("%", "%" | "") => Some(1.0),
        ("", "" | "-") => Some(1.0),
        _ => None,
    }
}

/// Pairs each instrument result with our value. Names we do not compute get `ours: None`.
pub fn compare(params: &RoughnessParams, instrument: &[InstrumentResult]) -> Vec<Comparison> {
    instrument
        .iter()
        .map(|r| match ours_for(&r.name, params) {
            Some((ours, unit)) => {
                let inst = r.value.zip(factor(&r.unit, unit)).map(|(v, f)| v * f);
                Comparison {
                    name: r.name.clone(),
                    instrument: inst,
                    ours,
                    difference: ours.zip(inst).map(|(o, i)| o - i),
                    unit,
                }
            }
            None => Comparison {
                name: r.name.clone(),
                instrument: r.value,
                ours: None,
                difference: None,
                unit: "",
            },
        })
        .collect()
}
