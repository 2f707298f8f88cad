//! The measuring conditions a job expects the instrument to be set to (a recipe's
//! `[conditions]`): a scan whose instrument reports other conditions at its start is refused
//! before the first line, naming what the job expects and what the instrument is set to.
//!
//! Layer 0 (vocabulary): depends on [`crate::profile::Conditions`]; no I/O.

use crate::profile::Conditions;
use serde::{Deserialize, Serialize};

/// The conditions a job expects; a condition not stated is not checked.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct ExpectedConditions {
    /// Cut-off λc, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lambda_c_mm: Option<f64>,
    /// Short-wave cut-off λs, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lambda_s_um: Option<f64>,
    /// Number of sampling lengths N.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampling_lengths: Option<u32>,
    /// Traverse speed, mm/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_mm_s: Option<f64>,
}

impl ExpectedConditions {
    /// Whether nothing is expected.
    pub fn is_empty(&self) -> bool {
        *self == ExpectedConditions::default()
    }

    /// Each expected condition the instrument does not report as expected, named with both
    /// values (empty when all match).
    pub fn mismatches(&self, reported: &Conditions) -> Vec<String> {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
        let mut out = Vec::new();
        let mut real = |name: &str, unit: &str, want: Option<f64>, got: Option<f64>| {
            let Some(w) = want else { return };
            match got {
                Some(g) if close(w, g) => {}
                Some(g) => out.push(format!(
                    "{name}: the recipe expects {w} {unit}, the instrument is set to {g} {unit}"
                )),
                None => out.push(format!(
                    "{name}: the recipe expects {w} {unit}, the instrument does not report it"
                )),
            }
        };
        real("λc", "mm", self.lambda_c_mm, reported.lambda_c_mm);
        real("λs", "µm", self.lambda_s_um, reported.lambda_s_um);
        real("speed", "mm/s", self.speed_mm_s, reported.speed_mm_s);
        if let Some(w) = self.sampling_lengths {
            match reported.sampling_lengths {
                Some(g) if g == w => {}
                Some(g) => out.push(format!(
                    "sampling lengths: the recipe expects N = {w}, the instrument is set to N = {g}"
                )),
                None => out.push(format!(
                    "sampling lengths: the recipe expects N = {w}, the instrument does not report N"
                )),
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_condition_that_differs_is_named_with_both_values() {
        let reported = Conditions {
            lambda_c_mm: Some(2.5),
            lambda_s_um: Some(8.0),
            sampling_lengths: Some(5),
            speed_mm_s: None,
            ..Default::default()
        };
        assert!(ExpectedConditions::default()
            .mismatches(&reported)
            .is_empty());
        let want = ExpectedConditions {
            lambda_c_mm: Some(0.8),
            lambda_s_um: Some(8.0),
            sampling_lengths: Some(3),
            speed_mm_s: Some(0.5),
        };
        let m = want.mismatches(&reported);
        assert_eq!(
            m,
            vec![
                "λc: the recipe expects 0.8 mm, the instrument is set to 2.5 mm",
                "speed: the recipe expects 0.5 mm/s, the instrument does not report it",
                "sampling lengths: the recipe expects N = 3, the instrument is set to N = 5",
            ]
        );
        let same = ExpectedConditions {
            lambda_c_mm: Some(2.5),
            sampling_lengths: Some(5),
            ..Default::default()
        };
        assert!(same.mismatches(&reported).is_empty());
    }
}
