//! Scan metrics in the Prometheus text exposition format, written atomically to a file for
//! node_exporter's textfile collector (no network listener).
//!
//! The numbers and their text only: [`ScanMetrics::render`] is a pure formatter, and
//! [`super::metrics_file::write_metrics`] writes the text durably.
//!
//! Layer 3 (session), pure: std only.

use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The numbers a station is monitored by.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScanMetrics {
    /// The current scan's id (a label on every sample), empty when idle.
    pub scan_id: String,
    /// Lines durably completed.
    pub lines_done: u32,
    /// Lines planned.
    pub lines_total: u32,
    /// Duration of the last completed line, seconds.
    pub last_line_seconds: Option<f64>,
    /// Sum of completed line durations, seconds.
    pub line_seconds_sum: f64,
    /// Number of durations summed.
    pub line_seconds_count: u64,
    /// Line re-traces after a fault.
    pub retries: u64,
    /// Reconnects by device name.
    pub reconnects: BTreeMap<String, u64>,
    /// Times the scan suspended while a device was absent.
    pub suspensions: u64,
    /// Unix time of the last completed line, seconds.
    pub last_line_unix_seconds: Option<f64>,
    /// RMS fit residual, µm.
    pub fit_residual_um: Option<f64>,
}

/// Escapes a label value (backslash, double quote, newline) per the exposition format.
pub fn escape_label(v: &str) -> String {
    let mut s = String::with_capacity(v.len());
    for c in v.chars() {
        match c {
            '\\' => s.push_str("\\\\"),
            '"' => s.push_str("\\\""),
            '\n' => s.push_str("\\n"),
            c => s.push(c),
        }
    }
    s
}

/// Formats a sample value: Prometheus floats, with `NaN`/`+Inf`/`-Inf` spelled its way.
fn value(v: f64) -> String {
    if v.is_nan() {
        "NaN".into()
    } else if v == f64::INFINITY {
        "+Inf".into()
    } else if v == f64::NEG_INFINITY {
        "-Inf".into()
    } else {
        format!("{v}")
    }
}

/// Appends one metric family: HELP, TYPE and its samples (`labels` without braces; empty
/// for none).
pub fn family(out: &mut String, name: &str, kind: &str, help: &str, samples: &[(String, f64)]) {
    let _ = writeln!(out, "# HELP {name} {help}");
    let _ = writeln!(out, "# TYPE {name} {kind}");
    for (labels, v) in samples {
        if labels.is_empty() {
            let _ = writeln!(out, "{name} {}", value(*v));
        } else {
            let _ = writeln!(out, "{name}{{{labels}}} {}", value(*v));
        }
    }
}

impl ScanMetrics {
    /// Renders the exposition text (HELP/TYPE then samples per family, newline-terminated).
    pub fn render(&self) -> String {
        let id = escape_label(&self.scan_id);
        let mut out = String::new();
        let scan = format!("scan=\"{id}\"");
        family(
            &mut out,
            "surfscan_lines_done",
            "gauge",
            "Lines of the current scan durably completed.",
            &[(scan.clone(), f64::from(self.lines_done))],
        );
        family(
            &mut out,
            "surfscan_lines_planned",
            "gauge",
            "Lines planned for the current scan.",
            &[(scan.clone(), f64::from(self.lines_total))],
        );
        if let Some(s) = self.last_line_seconds {
            family(
                &mut out,
                "surfscan_last_line_duration_seconds",
                "gauge",
                "Duration of the last completed line.",
                &[(scan.clone(), s)],
            );
        }
        let _ = writeln!(
            out,
            "# HELP surfscan_line_duration_seconds Durations of completed lines.\n# TYPE surfscan_line_duration_seconds summary\nsurfscan_line_duration_seconds_sum{{{scan}}} {}\nsurfscan_line_duration_seconds_count{{{scan}}} {}",
            value(self.line_seconds_sum),
            self.line_seconds_count
        );
        family(
            &mut out,
            "surfscan_line_retries_total",
            "counter",
            "Line re-traces after a fault.",
            &[(scan.clone(), self.retries as f64)],
        );
        let reconnects: Vec<(String, f64)> = self
            .reconnects
            .iter()
            .map(|(d, n)| (format!("{scan},device=\"{}\"", escape_label(d)), *n as f64))
            .collect();
        family(
            &mut out,
            "surfscan_reconnects_total",
            "counter",
            "Device reconnects by device.",
            &reconnects,
        );
        family(
            &mut out,
            "surfscan_suspensions_total",
            "counter",
            "Times the scan suspended while a device was absent.",
            &[(scan.clone(), self.suspensions as f64)],
        );
        if let Some(t) = self.last_line_unix_seconds {
            family(
                &mut out,
                "surfscan_last_line_timestamp_seconds",
                "gauge",
                "Unix time of the last completed line.",
                &[(scan.clone(), t)],
            );
        }
        if let Some(r) = self.fit_residual_um {
            family(
                &mut out,
                "surfscan_fit_residual_micrometres",
                "gauge",
                "RMS residual of the surface fit.",
                &[(scan.clone(), r)],
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_escaping() {
        assert_eq!(escape_label("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
    }

    #[test]
    fn special_values() {
        assert_eq!(value(f64::NAN), "NaN");
        assert_eq!(value(f64::INFINITY), "+Inf");
        assert_eq!(value(2.5), "2.5");
    }
}
