//! A completed scan's results in a few figures — the verdict against its recipe's
//! specification, the Ra and Rz means, Sa, the number of warnings — for what reports a scan
//! without reading its report: the status (`status`, `status --json`), the notification
//! hook's environment, the job queue and the end of `surfscan scan`.
//!
//! Layer 3 (session): plain data from the characterisation; depends on the verdict type and
//! [`crate::numfmt`].

use crate::numfmt::{fmt, Quantity};
use crate::specification::Verdict;
use serde::{Deserialize, Serialize};

/// What a scan's characterisation found.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ScanResults {
    /// The verdict against the specification, when the scan's recipe has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    /// The verdict with the reasons that decide it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict_summary: Option<String>,
    /// Mean Ra over the lines, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ra_mean_um: Option<f64>,
    /// Mean Rz over the lines, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rz_mean_um: Option<f64>,
    /// Sa of the measured grid, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sa_um: Option<f64>,
    /// Warnings in the report (each a thing a reader must know before using a number).
    pub warnings: usize,
}

impl ScanResults {
    /// The last scan in one line after its stop status: `success: does not conform (Rz 16 %
    /// rule: 9 of 31 lines above 6.3 µm …)`, `success, 3 warnings: conforms (…)`, or
    /// `success, 3 warnings` for a scan without a specification.
    pub fn line(&self, status: &str) -> String {
        let mut s = status.to_owned();
        match self.warnings {
            0 => {}
            1 => s.push_str(", 1 warning"),
            n => s.push_str(&format!(", {n} warnings")),
        }
        if let Some(v) = &self.verdict_summary {
            s.push_str(": ");
            s.push_str(v);
        }
        s
    }

    /// The notification hook's variables: `SURFSCAN_VERDICT` (`conforms`, `does not
    /// conform`, `not decidable`, or empty without a specification),
    /// `SURFSCAN_VERDICT_SUMMARY`, `SURFSCAN_WARNINGS`, `SURFSCAN_RA_MEAN_UM`,
    /// `SURFSCAN_RZ_MEAN_UM`, `SURFSCAN_SA_UM` (empty when not computed).
    pub fn env(&self) -> Vec<(&'static str, String)> {
        let num = |v: Option<f64>| v.map(|v| fmt(v, Quantity::HeightUm)).unwrap_or_default();
        vec![
            (
                "SURFSCAN_VERDICT",
                self.verdict
                    .map(|v| v.as_str().to_owned())
                    .unwrap_or_default(),
            ),
            (
                "SURFSCAN_VERDICT_SUMMARY",
                self.verdict_summary.clone().unwrap_or_default(),
            ),
            ("SURFSCAN_WARNINGS", self.warnings.to_string()),
            ("SURFSCAN_RA_MEAN_UM", num(self.ra_mean_um)),
            ("SURFSCAN_RZ_MEAN_UM", num(self.rz_mean_um)),
            ("SURFSCAN_SA_UM", num(self.sa_um)),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_status_line_says_the_verdict_and_the_warnings() {
        let mut r = ScanResults {
            verdict: Some(Verdict::DoesNotConform),
            verdict_summary: Some(
                "does not conform (Rz 16 % rule: 9 of 31 lines above 6.3 µm)".into(),
            ),
            ra_mean_um: Some(0.61234),
            rz_mean_um: None,
            sa_um: Some(0.7),
            warnings: 0,
        };
        assert_eq!(
            r.line("success"),
            "success: does not conform (Rz 16 % rule: 9 of 31 lines above 6.3 µm)"
        );
        r.warnings = 3;
        assert!(r
            .line("success")
            .starts_with("success, 3 warnings: does not conform"));
        let plain = ScanResults {
            warnings: 3,
            ..ScanResults::default()
        };
        assert_eq!(plain.line("success"), "success, 3 warnings");
        let env: std::collections::HashMap<_, _> = r.env().into_iter().collect();
        assert_eq!(env["SURFSCAN_VERDICT"], "does not conform");
        assert_eq!(env["SURFSCAN_RA_MEAN_UM"], "0.6123");
        assert_eq!(env["SURFSCAN_RZ_MEAN_UM"], "");
        assert_eq!(env["SURFSCAN_WARNINGS"], "3");
    }
}
