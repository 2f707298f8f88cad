//! The one table of the per-line parameters: for each, the report's key, its name and unit as
//! people read them, the digits it is written with, how the instrument's height calibration
//! carries over to it, its value on a line and the definition id written into every recipe.
//! Every renderer (report.html, summary.csv, the instrument comparison) and the verdict's
//! statistics read the parameters from here, so a parameter is named once. [`AREAL`] is the
//! same for the areal parameters: their recipes' definitions and report.html's rows.
//!
//! Adding a per-line parameter: its field in [`RoughnessParams`] (or [`MaterialRatio`] for
//! the material-ratio family, which the SJ series' reading then has as well), its computation
//! in [`super::params`], and one row of [`PARAMETERS`] (`docs/architecture.md`).
//!
//! Depends on [`super::params`] (the values) and [`crate::numfmt`] (the quantities).

use super::params::{MaterialRatio, RoughnessParams};
use crate::numfmt::Quantity::{self, Area, HeightUm, PerLength, Percent, Ratio};
use serde::Serialize;
use std::collections::BTreeMap;
use Scaling::{Height, Lateral, Other, ScaleFree};
use Source::{Family, Line};

/// How a parameter responds to the instrument's height scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scaling {
    /// Proportional to the heights: the height calibration's relative uncertainty applies.
    Height,
    /// Unchanged by the height scale (Rsk, Rku, material ratios).
    ScaleFree,
    /// A length along x or a count per length: the height calibration says nothing.
    Lateral,
    /// Depends on the height scale, but not proportionally (Rmr at a fixed depth).
    Other,
}

/// Where a parameter's value is found.
pub enum Source {
    /// A member of the line's parameters; `None` when the line has none (RSm, RzJIS).
    Line(fn(&RoughnessParams) -> Option<f64>),
    /// A member of the material-ratio family, which each reading (ISO's, the SJ series') has.
    Family(fn(&MaterialRatio) -> f64),
}

/// One per-line parameter.
pub struct Parameter {
    /// The report's key, a member of a line's entry in report.json (`Ra_um`, `Rsk`, `A1`).
    pub key: &'static str,
    /// Its name as people read it (`Ra`, `RΔq`, `Rδc`).
    pub name: &'static str,
    /// Its unit as people read it (`µm`, `%`, `µm·%`, `/cm`); empty for a ratio.
    pub unit: &'static str,
    /// The digits it is written with.
    pub quantity: Quantity,
    /// How the instrument's height calibration carries over.
    pub scaling: Scaling,
    /// Where its value is.
    pub source: Source,
    /// The definition id written into every recipe, under [`Parameter::stem`].
    pub definition: &'static str,
}

impl Parameter {
    /// The value on a line of ISO's reading.
    pub fn of(&self, p: &RoughnessParams) -> Option<f64> {
        match self.source {
            Source::Line(f) => f(p),
            Source::Family(f) => Some(f(&p.material)),
        }
    }

    /// The key without its unit (`Ra_um` → `Ra`, `RPc_per_cm` → `RPc`): the name in ASCII,
    /// under which the recipe defines it.
    pub fn stem(&self) -> &'static str {
        self.key.split('_').next().unwrap_or(self.key)
    }

    /// A table's heading: the name and the unit (`Ra µm`, `Rsk`).
    pub fn heading(&self) -> String {
        format!("{} {}", self.name, self.unit).trim_end().to_owned()
    }
}

/// The parameter whose key or stem is `name` (`Ra_um`, `Ra`, `A1_um_pct`), ASCII case ignored.
pub fn parameter(name: &str) -> Option<&'static Parameter> {
    let stem = name.split('_').next().unwrap_or(name);
    PARAMETERS
        .iter()
        .find(|p| p.stem().eq_ignore_ascii_case(stem))
}

/// Every scalar per-line parameter, in the order of a line's parameters in report.json (and
/// of its `statistics`).
#[rustfmt::skip]
pub const PARAMETERS: &[Parameter] = &[
    Parameter { key: "Ra_um", name: "Ra", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| Some(p.ra_um)), definition: "ISO4287:1997/Ra mean|Z| per lr, lr-mean, filter mean line" },
    Parameter { key: "Rq_um", name: "Rq", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| Some(p.rq_um)), definition: "ISO4287:1997/Rq rms Z per lr, lr-mean, filter mean line" },
    Parameter { key: "Rp_um", name: "Rp", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| Some(p.rp_um)), definition: "ISO4287:1997/Rp max Z per lr, lr-mean" },
    Parameter { key: "Rv_um", name: "Rv", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| Some(p.rv_um)), definition: "ISO4287:1997/Rv |min Z| per lr, lr-mean" },
    Parameter { key: "Rz_um", name: "Rz", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| Some(p.rz_um)), definition: "ISO4287:1997/Rz max height Rp+Rv per lr, lr-mean (RzDIN)" },
    Parameter { key: "Rt_um", name: "Rt", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| Some(p.rt_um)), definition: "ISO4287:1997/Rt max-min over ln" },
    Parameter { key: "Rz1max_um", name: "Rz1max", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| Some(p.rz1max_um)), definition: "ISO4287:1997/Rz1max largest per-lr Rz" },
    Parameter { key: "RzJIS_um", name: "RzJIS", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| p.rzjis_um), definition: "JIS-B0601:2001/RzJIS ten-point: 5 highest peaks + 5 deepest valleys (extremes between mean-line crossings) per lr, lr-mean" },
    Parameter { key: "Rsk", name: "Rsk", unit: "", quantity: Ratio, scaling: ScaleFree, source: Line(|p| Some(p.rsk)), definition: "ISO4287:1997/Rsk mean Z^3/Rq^3 per lr (no mean removal), lr-mean" },
    Parameter { key: "Rku", name: "Rku", unit: "", quantity: Ratio, scaling: ScaleFree, source: Line(|p| Some(p.rku)), definition: "ISO4287:1997/Rku mean Z^4/Rq^4 per lr (3 for Gaussian), lr-mean" },
    Parameter { key: "Rdq", name: "RΔq", unit: "", quantity: Ratio, scaling: Height, source: Line(|p| Some(p.rdq)), definition: "ISO4287:1997/Rdq rms 7-point slope per lr, lr-mean" },
    Parameter { key: "Rda", name: "RΔa", unit: "", quantity: Ratio, scaling: Height, source: Line(|p| Some(p.rda)), definition: "SJ series RΔa (Da): mean |7-point slope| per lr, lr-mean" },
    Parameter { key: "RSm_um", name: "RSm", unit: "µm", quantity: HeightUm, scaling: Lateral, source: Line(|p| p.rsm_um), definition: "ISO4287:1997/RSm elements between upward mean-line crossings; peak >= 10% Rz, valley <= -10% Rz of the lr; elements < 1% lr merged; lr-mean" },
    Parameter { key: "Rc_um", name: "Rc", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| p.rc_um), definition: "ISO4287:1997/Rc mean Zt = Zp + Zv of the RSm elements (SJ series Zp/Zv: 10% of Rz, 1% lr), lr-mean" },
    Parameter { key: "RPc_per_cm", name: "RPc", unit: "/cm", quantity: PerLength, scaling: Lateral, source: Line(|p| p.rpc_per_cm), definition: "SJ series Pc/RPc = 1 cm / RSm, per cm (not the ASME count of +-c crossings)" },
    Parameter { key: "Rppi_per_inch", name: "Rppi", unit: "/in", quantity: PerLength, scaling: Lateral, source: Line(|p| p.rppi_per_inch), definition: "SJ series Ppi = 1 inch / RSm (Pc for a unit length of 1 inch), per inch" },
    Parameter { key: "Rdc_um", name: "Rδc", unit: "µm", quantity: HeightUm, scaling: Height, source: Line(|p| Some(p.rdc_um)), definition: "ISO4287:1997/Rdc = C(Rmr1) - C(Rmr2) on the piecewise-linear material ratio curve over ln; SJ series levels 10% and 25%" },
    Parameter { key: "Rmr_pct", name: "Rmr", unit: "%", quantity: Percent, scaling: Other, source: Family(|m| m.rmr_pct), definition: "ISO4287:1997/Rmr relative material ratio at C(Rmr0) - Rdc; SJ series Rmr0 = 0% (the highest peak), Rdc = 0.10 um" },
    Parameter { key: "Rk_um", name: "Rk", unit: "µm", quantity: HeightUm, scaling: Height, source: Family(|m| m.rk.rk_um), definition: "ISO13565-2/Rk min-gradient 40% secant on linear-quantile Rmc(mr) over ln, 0.1% search step" },
    Parameter { key: "Rpk_um", name: "Rpk", unit: "µm", quantity: HeightUm, scaling: Height, source: Family(|m| m.rk.rpk_um), definition: "ISO13565-2/Rpk = 2*A1/Mr1" },
    Parameter { key: "Rvk_um", name: "Rvk", unit: "µm", quantity: HeightUm, scaling: Height, source: Family(|m| m.rk.rvk_um), definition: "ISO13565-2/Rvk = 2*A2/(100-Mr2)" },
    Parameter { key: "Mr1_pct", name: "Mr1", unit: "%", quantity: Percent, scaling: ScaleFree, source: Family(|m| m.rk.mr1_pct), definition: "ISO13565-2/Mr1 = Rmr at the upper core level C" },
    Parameter { key: "Mr2_pct", name: "Mr2", unit: "%", quantity: Percent, scaling: ScaleFree, source: Family(|m| m.rk.mr2_pct), definition: "ISO13565-2/Mr2 = Rmr at the lower core level D" },
    Parameter { key: "A1", name: "A1", unit: "µm·%", quantity: Area, scaling: Height, source: Family(|m| m.rk.a1_um_pct), definition: "ISO13565-2/A1 area above C for mr in [0, Mr1], um*%" },
    Parameter { key: "A2", name: "A2", unit: "µm·%", quantity: Area, scaling: Height, source: Family(|m| m.rk.a2_um_pct), definition: "ISO13565-2/A2 area below D for mr in [Mr2, 100], um*%" },
];

/// One areal parameter (ISO 25178-2) of a surface (the measured grid's or the model's).
pub struct ArealParameter {
    /// Its member in a surface's entry of report.json, a `.` stepping into the part of the
    /// characterisation that computes it (`Sa_um`, `functional.Sk_um`, `spatial.Str`).
    pub key: &'static str,
    /// Its heading in report.html: name, unit and the levels it is read at.
    pub heading: &'static str,
    /// The digits it is written with.
    pub quantity: Quantity,
    /// The definition id in its part's recipe, under its name (the key's stem).
    pub definition: &'static str,
}

/// Every areal parameter, in the order of report.html's rows.
#[rustfmt::skip]
pub const AREAL: &[ArealParameter] = &[
    ArealParameter { key: "Sa_um", heading: "Sa µm", quantity: HeightUm, definition: "ISO25178-2/Sa mean |z| over the grid" },
    ArealParameter { key: "Sq_um", heading: "Sq µm", quantity: HeightUm, definition: "ISO25178-2/Sq rms z over the grid" },
    ArealParameter { key: "Sp_um", heading: "Sp µm", quantity: HeightUm, definition: "ISO25178-2/Sp max z" },
    ArealParameter { key: "Sv_um", heading: "Sv µm", quantity: HeightUm, definition: "ISO25178-2/Sv |min z|" },
    ArealParameter { key: "Sz_um", heading: "Sz µm", quantity: HeightUm, definition: "ISO25178-2/Sz Sp + Sv (maximum height, not S10z)" },
    ArealParameter { key: "Ssk", heading: "Ssk", quantity: Ratio, definition: "ISO25178-2/Ssk mean z^3 / Sq^3" },
    ArealParameter { key: "Sku", heading: "Sku", quantity: Ratio, definition: "ISO25178-2/Sku mean z^4 / Sq^4" },
    ArealParameter { key: "Sdq", heading: "Sdq", quantity: Ratio, definition: "ISO25178-2:2021 D/Sdq sqrt(mean (dz/dx)^2 + mean (dz/dy)^2), forward differences" },
    ArealParameter { key: "Sdr_pct", heading: "Sdr %", quantity: Percent, definition: "ISO25178-2:2021 D.3/Sdr two-diagonal triangulation averaged, over (cols-1)(rows-1) cells" },
    ArealParameter { key: "functional.Sk_um", heading: "Sk µm", quantity: HeightUm, definition: "ISO25178-2/Sk min-gradient 40% secant on the linear-quantile areal material ratio curve of the levelled grid, 0.1% search step (the profile Rk construction)" },
    ArealParameter { key: "functional.Spk_um", heading: "Spk µm", quantity: HeightUm, definition: "ISO25178-2/Spk = 2*A1/Smr1" },
    ArealParameter { key: "functional.Svk_um", heading: "Svk µm", quantity: HeightUm, definition: "ISO25178-2/Svk = 2*A2/(100-Smr2)" },
    ArealParameter { key: "functional.Smr1_pct", heading: "Smr1 %", quantity: Percent, definition: "ISO25178-2/Smr1 areal material ratio at the upper core limit" },
    ArealParameter { key: "functional.Smr2_pct", heading: "Smr2 %", quantity: Percent, definition: "ISO25178-2/Smr2 areal material ratio at the lower core limit" },
    ArealParameter { key: "functional.Vmp_ml_per_m2", heading: "Vmp ml/m² (p 10 %)", quantity: HeightUm, definition: "ISO25178-2/Vmp = Vm(p), p = 10%, exact integral of the linear-quantile curve, ml/m2" },
    ArealParameter { key: "functional.Vmc_ml_per_m2", heading: "Vmc ml/m² (p 10 %, q 80 %)", quantity: HeightUm, definition: "ISO25178-2/Vmc = Vm(q) - Vm(p), p = 10%, q = 80%, ml/m2" },
    ArealParameter { key: "functional.Vvc_ml_per_m2", heading: "Vvc ml/m² (p 10 %, q 80 %)", quantity: HeightUm, definition: "ISO25178-2/Vvc = Vv(p) - Vv(q), p = 10%, q = 80%, ml/m2" },
    ArealParameter { key: "functional.Vvv_ml_per_m2", heading: "Vvv ml/m² (q 80 %)", quantity: HeightUm, definition: "ISO25178-2/Vvv = Vv(q), q = 80%, ml/m2" },
    ArealParameter { key: "spatial.Sal_um", heading: "Sal µm (s 0.2)", quantity: HeightUm, definition: "ISO25178-2/Sal shortest lag at which f_ACF first falls below s = 0.2, along rays every 0.5 deg, bilinear ACF, linear crossing, um" },
    ArealParameter { key: "spatial.Str", heading: "Str (s 0.2)", quantity: Ratio, definition: "ISO25178-2/Str fastest / slowest decay length to s = 0.2 (blank when a direction does not decay within the field)" },
    ArealParameter { key: "spatial.Std_deg", heading: "Std °", quantity: Ratio, definition: "ISO25178-2:2021/Std angle of the maximum of the angular amplitude spectrum (|DFT| in 0.5 deg bins of the frequency direction, lower bin edge), deg counter-clockwise from +x, y along the scan" },
];

/// The definition ids of the areal parameters of `part` (`""`, `functional`, `spatial`: the
/// module that computes them) under their names, and the `more` that part defines.
pub fn areal_definitions(part: &str, more: &[(&str, &str)]) -> BTreeMap<String, String> {
    let in_part = |p: &&ArealParameter| p.key.rsplit_once('.').map_or("", |(s, _)| s) == part;
    let name = |key: &'static str| key.rsplit('.').next().and_then(|k| k.split('_').next());
    AREAL
        .iter()
        .filter(in_part)
        .filter_map(|p| Some((name(p.key)?, p.definition)))
        .chain(more.iter().copied())
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The renderers and the instrument comparison find a parameter by its stem: two rows
    /// with one stem would give one of them the other's value.
    #[test]
    fn each_parameter_is_found_by_its_key_and_by_its_stem() {
        for p in PARAMETERS {
            assert_eq!(parameter(p.key).map(|t| t.key), Some(p.key));
            assert_eq!(parameter(p.stem()).map(|t| t.key), Some(p.key));
        }
        assert_eq!(parameter("A1_um_pct").map(|p| p.key), Some("A1"));
        assert!(parameter("y_mm").is_none());
    }

    /// Each areal parameter is defined in the recipe of the part that computes it, under its
    /// name, and in no other.
    #[test]
    fn each_areal_parameter_is_defined_in_its_parts_recipe() {
        let names = |part| areal_definitions(part, &[]).into_keys().collect::<Vec<_>>();
        assert_eq!(names("").join(" "), "Sa Sdq Sdr Sku Sp Sq Ssk Sv Sz");
        let functional = "Sk Smr1 Smr2 Spk Svk Vmc Vmp Vvc Vvv";
        assert_eq!(names("functional").join(" "), functional);
        assert_eq!(names("spatial").join(" "), "Sal Std Str");
    }
}
