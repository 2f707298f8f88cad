//! The uncertainty of a parameter given as the mean over a scan's lines (GUM, JCGM
//! 100:2008): the n line values, their standard deviation s, the standard uncertainty of the
//! mean s/√n (type A), combined with the instrument's calibration uncertainty when the
//! station states one (type B, relative, from the calibration certificate), and the expanded
//! uncertainty U = k·u_c with k = 2.
//!
//! The calibration of a stylus instrument fixes the scale of its heights: its relative
//! uncertainty carries over in full to every parameter proportional to the heights (Ra, Rz,
//! the slopes Rdq and Rda, the Rk family, A1/A2) and not at all to those the height scale
//! leaves unchanged (Rsk, Rku, Mr1, Mr2) or that are lengths along x (RSm, RPc). For those
//! the report says that the instrument's share is not stated.
//!
//! Layer 1 (pure): depends on [`crate::metrology::params`] for the per-line values.

pub use crate::metrology::parameter_table::Scaling;
use crate::metrology::parameter_table::PARAMETERS;
use crate::metrology::params::RoughnessParams;
use serde::Serialize;

/// The coverage factor of every expanded uncertainty here (about 95 % for a normal
/// distribution).
pub const COVERAGE_K: f64 = 2.0;

/// What the station states about its instrument's uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InstrumentUncertainty {
    /// The expanded (k = 2) relative uncertainty of the height scale from the calibration
    /// certificate, %; `None` when the station states none.
    pub expanded_relative_pct: Option<f64>,
}

impl InstrumentUncertainty {
    /// The expanded uncertainty of one value `v` of a parameter of `scaling`: the stated
    /// relative uncertainty of `|v|` for parameters proportional to the heights, else 0.
    pub fn expanded_of_value(&self, v: f64, scaling: Scaling) -> f64 {
        match (self.expanded_relative_pct, scaling) {
            (Some(pct), Scaling::Height) => pct / 100.0 * v.abs(),
            _ => 0.0,
        }
    }

    /// For people: what the verdicts assume of the instrument.
    pub fn statement(&self) -> String {
        match self.expanded_relative_pct {
            Some(pct) => format!(
                "each line's value carries the instrument's expanded uncertainty of {pct} % (k = 2, from [traceability] calibration-uncertainty-pct) for the parameters proportional to the heights"
            ),
            None => "no calibration uncertainty is stated ([traceability] calibration-uncertainty-pct): the verdict ignores the instrument's uncertainty and takes each line's value as exact".to_owned(),
        }
    }
}

/// A parameter's mean over the lines with its uncertainty, in the parameter's unit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Statistics {
    /// Lines with a finite value.
    pub n: usize,
    /// Their mean.
    pub mean: f64,
    /// Their sample standard deviation (n − 1); `None` for fewer than two values.
    pub s: Option<f64>,
    /// The standard uncertainty of the mean, s/√n (type A).
    pub u_mean: Option<f64>,
    /// The instrument's standard uncertainty of the mean (type B: the calibration's relative
    /// uncertainty, k = 2 on the certificate, of |mean|); `None` when not stated or not
    /// applicable to this parameter.
    pub u_instrument: Option<f64>,
    /// The combined standard uncertainty √(u_mean² + u_instrument²).
    pub u_c: Option<f64>,
    /// The expanded uncertainty k·u_c.
    #[serde(rename = "U")]
    pub expanded: Option<f64>,
    /// The coverage factor (2).
    pub k: f64,
    /// How the instrument's height calibration carries over to this parameter.
    pub scaling: Scaling,
}

/// The statistics of `values` (non-finite ones left out) for a parameter of `scaling`;
/// `None` when no value is finite.
pub fn statistics(
    values: impl IntoIterator<Item = f64>,
    scaling: Scaling,
    instrument: &InstrumentUncertainty,
) -> Option<Statistics> {
    let v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
    let n = v.len();
    if n == 0 {
        return None;
    }
    let mean = v.iter().sum::<f64>() / n as f64;
    let s = (n >= 2).then(|| {
        let ss: f64 = v.iter().map(|x| (x - mean).powi(2)).sum();
        (ss / (n - 1) as f64).sqrt()
    });
    let u_mean = s.map(|s| s / (n as f64).sqrt());
    let u_instrument = match (instrument.expanded_relative_pct, scaling) {
        (Some(pct), Scaling::Height) => Some(pct / 100.0 / COVERAGE_K * mean.abs()),
        _ => None,
    };
    let u_c = u_mean.map(|a| a.hypot(u_instrument.unwrap_or(0.0)));
    Some(Statistics {
        n,
        mean,
        s,
        u_mean,
        u_instrument,
        u_c,
        expanded: u_c.map(|u| COVERAGE_K * u),
        k: COVERAGE_K,
        scaling,
    })
}

/// The statistics of every per-line parameter of [`PARAMETERS`] over `lines`, by report key,
/// in the table's order; parameters no line has are left out.
pub fn all_statistics(
    lines: &[&RoughnessParams],
    instrument: &InstrumentUncertainty,
) -> Vec<(&'static str, Statistics)> {
    PARAMETERS
        .iter()
        .filter_map(|c| {
            let st = statistics(lines.iter().filter_map(|p| c.of(p)), c.scaling, instrument)?;
            Some((c.key, st))
        })
        .collect()
}

/// The paper's Table 1 form, `mean ± s` with the unit: `Ra 0.5770 ± 0.03100 µm`.
pub fn mean_pm_s(label: &str, st: &Statistics, unit: &str) -> String {
    use crate::numfmt::{fmt, Quantity};
    let unit = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    match st.s {
        Some(s) => format!(
            "{label} {} ± {}{unit}",
            fmt(st.mean, Quantity::HeightUm),
            fmt(s, Quantity::HeightUm)
        ),
        None => format!(
            "{label} {}{unit} (one line: no spread)",
            fmt(st.mean, Quantity::HeightUm)
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn type_a_only_without_a_calibration_statement() {
        // Values 1, 2, 3, 4: mean 2.5, s = √(5/3), u = s/2, U = s.
        let st = statistics([1.0, 2.0, 3.0, 4.0], Scaling::Height, &Default::default()).unwrap();
        assert_eq!(st.n, 4);
        assert_eq!(st.mean, 2.5);
        let s = (5.0f64 / 3.0).sqrt();
        assert_relative_eq!(st.s.unwrap(), s, max_relative = 1e-15);
        assert_relative_eq!(st.u_mean.unwrap(), s / 2.0, max_relative = 1e-15);
        assert_eq!(st.u_instrument, None);
        assert_relative_eq!(st.u_c.unwrap(), s / 2.0, max_relative = 1e-15);
        assert_relative_eq!(st.expanded.unwrap(), s, max_relative = 1e-15);
    }

    #[test]
    fn the_calibration_share_is_combined_for_heights_only() {
        // Nine values with mean 1.0 µm and s = 0.3 µm: u_mean = 0.1. A certificate's 4 %
        // (k = 2) is a standard 2 % of 1.0 = 0.02; u_c = √(0.01 + 0.0004) = 0.10198.
        let v = [0.7, 1.3, 0.7, 1.3, 0.7, 1.3, 0.7, 1.3, 1.0];
        let mean = 1.0;
        let s = (v.iter().map(|x: &f64| (x - mean).powi(2)).sum::<f64>() / 8.0).sqrt();
        let inst = InstrumentUncertainty {
            expanded_relative_pct: Some(4.0),
        };
        let st = statistics(v, Scaling::Height, &inst).unwrap();
        assert_relative_eq!(st.mean, 1.0, max_relative = 1e-12);
        assert_relative_eq!(st.u_mean.unwrap(), s / 3.0, max_relative = 1e-12);
        assert_relative_eq!(st.u_instrument.unwrap(), 0.02, max_relative = 1e-12);
        let uc = ((s / 3.0).powi(2) + 0.02f64.powi(2)).sqrt();
        assert_relative_eq!(st.u_c.unwrap(), uc, max_relative = 1e-12);
        assert_relative_eq!(st.expanded.unwrap(), 2.0 * uc, max_relative = 1e-12);
        // Rsk does not scale with the heights: no instrument share.
        let st = statistics(v, Scaling::ScaleFree, &inst).unwrap();
        assert_eq!(st.u_instrument, None);
        assert_relative_eq!(st.u_c.unwrap(), s / 3.0, max_relative = 1e-12);
        // One line: a mean without spread, no uncertainty claimed.
        let st = statistics([0.5, f64::NAN], Scaling::Height, &inst).unwrap();
        assert_eq!((st.n, st.s, st.expanded), (1, None, None));
        assert!(statistics([f64::NAN], Scaling::Height, &inst).is_none());
        assert_eq!(inst.expanded_of_value(2.0, Scaling::Height), 0.08);
        assert_eq!(inst.expanded_of_value(2.0, Scaling::Lateral), 0.0);
    }

    #[test]
    fn the_papers_table_form() {
        let st = statistics([0.5, 0.6, 0.7], Scaling::Height, &Default::default()).unwrap();
        assert_eq!(mean_pm_s("Ra", &st, "µm"), "Ra 0.6000 ± 0.1000 µm");
    }
}
