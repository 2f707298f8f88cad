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
    /// Our parameter it was compared with (`RzJIS` for the instrument's `Rz` under JIS1982 /
    /// JIS1994, where Rz is the ten-point height), `None` for names we do not compute.
    pub compared_with: Option<&'static str>,
    /// Unit of `instrument`, `ours` and `difference` ("um", "%", "" for ratios).
    pub unit: &'static str,
}

/// Our value for an instrument parameter name, with its unit; `None` for names we do not map.
/// (value, unit, our parameter name).
type Ours = (Option<f64>, &'static str, &'static str);

fn ours_for(name: &str, p: &RoughnessParams, jis_ten_point_rz: bool) -> Option<Ours> {
    let key: String = name
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect::<String>()
        .to_ascii_lowercase();
    Some(match key.as_str() {
        "ra" => (Some(p.ra_um), "um", "Ra"),
        "rq" => (Some(p.rq_um), "um", "Rq"),
        "rz" if jis_ten_point_rz => (p.rzjis_um, "um", "RzJIS"),
        "rz" => (Some(p.rz_um), "um", "Rz"),
        "rp" => (Some(p.rp_um), "um", "Rp"),
        "rv" => (Some(p.rv_um), "um", "Rv"),
        "rt" => (Some(p.rt_um), "um", "Rt"),
        "rz1max" => (Some(p.rz1max_um), "um", "Rz1max"),
        "rzjis" => (p.rzjis_um, "um", "RzJIS"),
        "rsk" => (Some(p.rsk), "", "Rsk"),
        "rku" => (Some(p.rku), "", "Rku"),
        "rdq" | "rδq" | "rΔq" | "rdeltaq" => (Some(p.rdq), "", "Rdq"),
        "rsm" => (p.rsm_um, "um", "RSm"),
        "rk" => (Some(p.rk_um), "um", "Rk"),
        "rpk" => (Some(p.rpk_um), "um", "Rpk"),
        "rvk" => (Some(p.rvk_um), "um", "Rvk"),
        "mr1" => (Some(p.mr1_pct), "%", "Mr1"),
        "mr2" => (Some(p.mr2_pct), "%", "Mr2"),
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
/// The instrument's `Rz` is the ISO 4287:1997 maximum height (see [`compare_under`] for
/// the JIS ten-point Rz of the older JIS standards).
pub fn compare(params: &RoughnessParams, instrument: &[InstrumentResult]) -> Vec<Comparison> {
    compare_under(params, instrument, None)
}

/// Like [`compare`] for results evaluated under the instrument's `standard` (as recorded in
/// its conditions, e.g. "ISO1997", "JIS1994"): under JIS1982 and JIS1994 the instrument's `Rz`
/// is the ten-point height and is compared with our `RzJIS`.
pub fn compare_under(
    params: &RoughnessParams,
    instrument: &[InstrumentResult],
    standard: Option<&str>,
) -> Vec<Comparison> {
    let jis = standard.is_some_and(|s| {
        let s: String = s
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .collect::<String>()
            .to_ascii_uppercase();
        s == "JIS1982" || s == "JIS1994" || s == "JIS82" || s == "JIS94"
    });
    instrument
        .iter()
        .map(|r| match ours_for(&r.name, params, jis) {
            Some((ours, unit, ours_name)) => {
                let inst = r.value.zip(factor(&r.unit, unit)).map(|(v, f)| v * f);
                Comparison {
                    name: r.name.clone(),
                    instrument: inst,
                    ours,
                    difference: ours.zip(inst).map(|(o, i)| o - i),
                    unit,
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
            },
        })
        .collect()
}
