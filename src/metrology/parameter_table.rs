//! The one table of the per-line parameters: for each, the report's key, its name and unit as
//! people read them, the digits it is written with, how the instrument's height calibration
//! carries over to it, its value on a line and the definition id written into every recipe.
//! Every renderer (report.html, summary.csv, the instrument comparison) and the verdict's
//! statistics read the parameters from here, so a parameter is named once.
//!
//! Adding a per-line parameter: its field in [`RoughnessParams`] (or [`MaterialRatio`] for
//! the material-ratio family, which the SJ series' reading then has as well), its computation
//! in [`super::params`], and one row of [`PARAMETERS`] (`docs/architecture.md`).
//!
//! Depends on [`super::params`] (the values) and [`crate::numfmt`] (the quantities).

use super::params::{MaterialRatio, RoughnessParams};
use crate::numfmt::Quantity::{self, Area, HeightUm, PerLength, Percent, Ratio};
use serde::Serialize;
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
    Parameter { key: "Rk_um", name: "Rk", unit: "µm", quantity: HeightUm, scaling: Height, source: Family(|m| m.rk_um), definition: "ISO13565-2/Rk min-gradient 40% secant on linear-quantile Rmc(mr) over ln, 0.1% search step" },
    Parameter { key: "Rpk_um", name: "Rpk", unit: "µm", quantity: HeightUm, scaling: Height, source: Family(|m| m.rpk_um), definition: "ISO13565-2/Rpk = 2*A1/Mr1" },
    Parameter { key: "Rvk_um", name: "Rvk", unit: "µm", quantity: HeightUm, scaling: Height, source: Family(|m| m.rvk_um), definition: "ISO13565-2/Rvk = 2*A2/(100-Mr2)" },
    Parameter { key: "Mr1_pct", name: "Mr1", unit: "%", quantity: Percent, scaling: ScaleFree, source: Family(|m| m.mr1_pct), definition: "ISO13565-2/Mr1 = Rmr at the upper core level C" },
    Parameter { key: "Mr2_pct", name: "Mr2", unit: "%", quantity: Percent, scaling: ScaleFree, source: Family(|m| m.mr2_pct), definition: "ISO13565-2/Mr2 = Rmr at the lower core level D" },
    Parameter { key: "A1", name: "A1", unit: "µm·%", quantity: Area, scaling: Height, source: Family(|m| m.a1_um_pct), definition: "ISO13565-2/A1 area above C for mr in [0, Mr1], um*%" },
    Parameter { key: "A2", name: "A2", unit: "µm·%", quantity: Area, scaling: Height, source: Family(|m| m.a2_um_pct), definition: "ISO13565-2/A2 area below D for mr in [Mr2, 100], um*%" },
];

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
}
