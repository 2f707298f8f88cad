//! The station configuration file (TOML): one table per concern, each owned by the module
//! that uses it, validated as a whole at load so a bad file is refused before anything
//! opens a port. Unknown keys are refused everywhere (`deny_unknown_fields`); a bad file
//! maps to exit status 78 (`EX_CONFIG`) with a message naming the file, the key and the fix.
//!
//! The tables no lower module owns (`[scan]`, `[fit]`, `[output]`, …) are defined here; the
//! composition layer turns them into the typed settings of the modules that use them (the
//! scan runner never sees this file's types).
//!
//! Layer 4 (process edge): depends on the settings types of [`crate::sj210`],
//! [`crate::stage`] and [`crate::hook`], on [`crate::units`], and reads one file; nothing
//! from the scan session.

use crate::hook::HookSettings;
use crate::sj210::settings::InstrumentSettings;
use crate::stage::settings::StageSettings;
use crate::units::Nm;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The whole configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct Config {
    /// `[instrument]`: the SJ-210 link and driver.
    pub instrument: InstrumentSettings,
    /// `[stage]`: the y stage link, protocol and motion policy.
    pub stage: StageSettings,
    /// `[scan]`: the grid to trace.
    pub scan: ScanSettings,
    /// `[fit]`: surface degrees.
    #[serde(default)]
    pub fit: FitSettings,
    /// `[output]`: where scans are stored.
    pub output: OutputSettings,
    /// `[control]`: the operator's socket.
    #[serde(default)]
    pub control: ControlSettings,
    /// `[analysis]`: characterisation at the end of a scan.
    #[serde(default)]
    pub analysis: AnalysisSettings,
    /// `[notify]`: command run when a scan completes, fails or suspends.
    #[serde(default)]
    pub notify: Option<HookSettings>,
    /// `[metrics]`: Prometheus textfile.
    #[serde(default)]
    pub metrics: MetricsSettings,
}

fn d_attempts() -> u32 {
    3
}
fn d_backoff_initial() -> u64 {
    1000
}
fn d_backoff_max() -> u64 {
    30_000
}
fn d_degree() -> usize {
    5
}
fn d_socket() -> PathBuf {
    PathBuf::from("/run/surfscan/control.sock")
}
fn d_curves() -> usize {
    31
}
fn d_levels() -> usize {
    101
}

/// `[scan]`: the grid of traced lines.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct ScanSettings {
    /// Number of traced lines (≥ degree-v + 1).
    pub lines: u32,
    /// y of the first line, mm (stage machine coordinates); a whole number of nanometres.
    pub y_start_mm: f64,
    /// y distance between lines, mm (the paper: 0.01); a whole number of nanometres, ≠ 0.
    pub y_step_mm: f64,
    /// Attempts per line before the scan fails with the last fault (default 3).
    #[serde(default = "d_attempts")]
    pub max_line_attempts: u32,
    /// First wait before reconnecting a vanished device, ms (default 1000); doubles per try.
    #[serde(default = "d_backoff_initial")]
    pub reconnect_initial_ms: u64,
    /// Longest wait between reconnection tries, ms (default 30000).
    #[serde(default = "d_backoff_max")]
    pub reconnect_max_ms: u64,
}

/// `[fit]`: the interpolating surface.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct FitSettings {
    /// Degree along x / u (default 5).
    #[serde(default = "d_degree")]
    pub degree_u: usize,
    /// Degree along y / v (default 5).
    #[serde(default = "d_degree")]
    pub degree_v: usize,
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings {
            degree_u: 5,
            degree_v: 5,
        }
    }
}

/// `[output]`: storage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct OutputSettings {
    /// Directory holding one sub-directory per scan (created if missing).
    pub dir: PathBuf,
}

/// `[control]`: the operator's socket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct ControlSettings {
    /// Unix socket path (default `/run/surfscan/control.sock`).
    #[serde(default = "d_socket")]
    pub socket: PathBuf,
}

impl Default for ControlSettings {
    fn default() -> Self {
        ControlSettings { socket: d_socket() }
    }
}

/// `[analysis]`: characterisation when a scan completes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct AnalysisSettings {
    /// Profile curves extracted from the model for the bearing area curves (default 31).
    #[serde(default = "d_curves")]
    pub curves: usize,
    /// Equal height levels per bearing area curve (default 101).
    #[serde(default = "d_levels")]
    pub levels: usize,
    /// λc override in mm; default: the instrument's condition.
    #[serde(default)]
    pub lambda_c_mm: Option<f64>,
    /// Treat profiles as R profiles (no λc filter), whatever the instrument says.
    #[serde(default)]
    pub no_filter: bool,
}

impl Default for AnalysisSettings {
    fn default() -> Self {
        AnalysisSettings {
            curves: d_curves(),
            levels: d_levels(),
            lambda_c_mm: None,
            no_filter: false,
        }
    }
}

/// `[metrics]`: the Prometheus textfile (node_exporter textfile collector).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct MetricsSettings {
    /// File written atomically after every line; none by default.
    #[serde(default)]
    pub file: Option<PathBuf>,
}

/// A configuration that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("cannot read config {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML for this schema (unknown key, wrong type, missing key).
    #[error("config {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message, with line and column.
        message: String,
    },
    /// A value is out of range or inconsistent with another.
    #[error("config {path}: {key}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The key, e.g. `scan.lines`.
        key: &'static str,
        /// What is wrong and what to do.
        message: String,
    },
}

impl Config {
    /// Reads, parses and validates a configuration file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Config::parse(path, &text)
    }

    /// Parses and validates configuration text (`path` is for messages).
    pub fn parse(path: &Path, text: &str) -> Result<Config, ConfigError> {
        let config: Config = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        config.validate(path)?;
        Ok(config)
    }

    fn invalid(path: &Path, key: &'static str, message: String) -> ConfigError {
        ConfigError::Invalid {
            path: path.to_path_buf(),
            key,
            message,
        }
    }

    /// Checks what can be checked without devices.
    pub fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        self.instrument
            .validate()
            .map_err(|e| Config::invalid(path, "instrument", e.to_string()))?;
        self.stage
            .policy_config()
            .map_err(|e| Config::invalid(path, "stage", e.to_string()))?;
        if self.stage.protocol == crate::stage::settings::StageProtocol::Grbl {
            self.stage
                .grbl_config()
                .map_err(|e| Config::invalid(path, "stage", e.to_string()))?;
        }
        let f = &self.fit;
        if f.degree_u == 0 || f.degree_v == 0 {
            return Err(Config::invalid(
                path,
                "fit",
                format!(
                    "degree-u = {} and degree-v = {} must both be at least 1 (the paper uses 5)",
                    f.degree_u, f.degree_v
                ),
            ));
        }
        self.plan_checked(path)?;
        let s = &self.scan;
        if s.reconnect_initial_ms == 0 || s.reconnect_max_ms < s.reconnect_initial_ms {
            return Err(Config::invalid(
                path,
                "scan.reconnect-initial-ms",
                format!(
                    "reconnect-initial-ms = {} must be > 0 and at most reconnect-max-ms = {}",
                    s.reconnect_initial_ms, s.reconnect_max_ms
                ),
            ));
        }
        if self.output.dir.as_os_str().is_empty() {
            return Err(Config::invalid(
                path,
                "output.dir",
                "must name a directory, e.g. \"/var/lib/surfscan/scans\"".into(),
            ));
        }
        if self.control.socket.as_os_str().is_empty() {
            return Err(Config::invalid(
                path,
                "control.socket",
                "must name a socket path, e.g. \"/run/surfscan/control.sock\"".into(),
            ));
        }
        let a = &self.analysis;
        if a.curves == 0 || a.levels < 2 {
            return Err(Config::invalid(
                path,
                "analysis",
                format!(
                    "curves = {} must be ≥ 1 and levels = {} ≥ 2",
                    a.curves, a.levels
                ),
            ));
        }
        if let Some(lc) = a.lambda_c_mm {
            if !(lc.is_finite() && lc > 0.0) {
                return Err(Config::invalid(
                    path,
                    "analysis.lambda-c-mm",
                    format!("{lc} must be a positive length in mm (0.08, 0.25, 0.8, 2.5 or 8)"),
                ));
            }
        }
        if let Some(n) = &self.notify {
            if n.command.is_empty() {
                return Err(Config::invalid(
                    path,
                    "notify.command",
                    "must name a program and its arguments, e.g. [\"/usr/local/bin/page-me\"]; remove [notify] to run none".into(),
                ));
            }
        }
        Ok(())
    }

    /// y of the first line and the step between lines in whole nanometres (the grid of the
    /// scan's plan), checked.
    pub fn y_grid_nm(&self) -> Result<(Nm, Nm), ConfigError> {
        self.y_grid_checked(Path::new("(config)"))
    }

    fn y_grid_checked(&self, path: &Path) -> Result<(Nm, Nm), ConfigError> {
        let s = &self.scan;
        let y_start_nm = Nm::try_from_mm(s.y_start_mm).ok_or_else(|| {
            Config::invalid(
                path,
                "scan.y-start-mm",
                format!(
                    "{} mm is not a whole number of nanometres; round it",
                    s.y_start_mm
                ),
            )
        })?;
        let y_step_nm = Nm::try_from_mm(s.y_step_mm).ok_or_else(|| {
            Config::invalid(
                path,
                "scan.y-step-mm",
                format!(
                    "{} mm is not a whole number of nanometres; round it",
                    s.y_step_mm
                ),
            )
        })?;
        if y_step_nm.0 == 0 {
            return Err(Config::invalid(
                path,
                "scan.y-step-mm",
                "must not be 0 (the paper steps 0.01 mm)".into(),
            ));
        }
        Ok((y_start_nm, y_step_nm))
    }

    /// The plan's rules: enough lines for the degree, whole-nanometre y, every line inside
    /// the stage's soft limits, at least one attempt per line.
    fn plan_checked(&self, path: &Path) -> Result<(), ConfigError> {
        let s = &self.scan;
        let min_lines = self.fit.degree_v + 1;
        if (s.lines as usize) < min_lines {
            return Err(Config::invalid(
                path,
                "scan.lines",
                format!(
                    "{} lines cannot carry a surface of degree-v {}: at least {min_lines} are needed",
                    s.lines, self.fit.degree_v
                ),
            ));
        }
        let (y_start_nm, y_step_nm) = self.y_grid_checked(path)?;
        if s.max_line_attempts == 0 {
            return Err(Config::invalid(
                path,
                "scan.max-line-attempts",
                "must be at least 1".into(),
            ));
        }
        let (lo, hi) = (self.stage.soft_limit_min_mm, self.stage.soft_limit_max_mm);
        for k in [0, s.lines - 1] {
            let y = Nm(y_start_nm.0 + i64::from(k) * y_step_nm.0).to_mm();
            if y < lo || y > hi {
                return Err(Config::invalid(
                    path,
                    "scan",
                    format!(
                        "line {} at y = {y} mm lies outside the stage's soft limits [{lo}, {hi}] mm; change y-start-mm / y-step-mm or the limits",
                        k + 1
                    ),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) const MINIMAL: &str = r#"
[instrument]
port = "/dev/ttyUSB0"
[stage]
port = "/dev/ttyACM0"
protocol = "grbl"
steps-per-mm = 1000.0
soft-limit-min-mm = 0.0
soft-limit-max-mm = 50.0
[scan]
lines = 31
y-start-mm = 1.0
y-step-mm = 0.01
[output]
dir = "/var/lib/surfscan/scans"
"#;

    fn parse(text: &str) -> Result<Config, ConfigError> {
        Config::parse(Path::new("t.toml"), text)
    }

    #[test]
    fn minimal_file_gets_documented_defaults() {
        let c = parse(MINIMAL).unwrap();
        assert_eq!(c.fit, FitSettings::default());
        assert_eq!(c.scan.max_line_attempts, 3);
        assert_eq!(
            c.control.socket,
            PathBuf::from("/run/surfscan/control.sock")
        );
        let (start, step) = c.y_grid_nm().unwrap();
        assert_eq!(start, Nm(1_000_000));
        // 0.01 mm steps are exact integers: line 30 at 1.3 mm, no accumulated rounding.
        assert_eq!(Nm(start.0 + 30 * step.0), Nm(1_300_000));
    }

    #[test]
    fn too_few_lines_for_the_degree_is_named() {
        let text = MINIMAL.replace("lines = 31", "lines = 5");
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains("scan.lines") && e.contains("at least 6"), "{e}");
    }

    #[test]
    fn inexact_or_zero_step_is_refused() {
        let e = parse(&MINIMAL.replace("y-step-mm = 0.01", "y-step-mm = 0.0100003"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("scan.y-step-mm") && e.contains("nanometres"),
            "{e}"
        );
        let e = parse(&MINIMAL.replace("y-step-mm = 0.01", "y-step-mm = 0.0"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("must not be 0"), "{e}");
    }

    #[test]
    fn unknown_keys_and_plans_beyond_the_limits_are_refused() {
        let e = parse(&MINIMAL.replace("lines = 31", "lines = 31\nline = 3"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown field") && e.contains("line"), "{e}");
        let e = parse(&MINIMAL.replace("soft-limit-max-mm = 50.0", "soft-limit-max-mm = 1.2"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 31") && e.contains("soft limits"), "{e}");
        let e = parse(&MINIMAL.replace("steps-per-mm", "poll-interval-ms = 50\nsteps-per-mm"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("stage") && e.contains("poll-interval-ms = 50"),
            "{e}"
        );
        let e = parse("[scan]\nlines = 3").unwrap_err().to_string();
        assert!(e.contains("missing field"), "{e}");
    }

    #[test]
    fn the_shipped_station_config_is_valid_and_complete() {
        let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/config/surfscan.toml"));
        let c = Config::load(path).unwrap();
        assert_eq!(c.scan.lines, 31);
        assert_eq!(c.y_grid_nm().unwrap().1, Nm(10_000));
        // Every documented key is present (commented-out optional ones included), so the
        // file stays the reference: compare against the keys the schema serialises.
        let text = std::fs::read_to_string(path).unwrap();
        let v = serde_json::to_value(&c).unwrap();
        for (table, keys) in v.as_object().unwrap() {
            let Some(keys) = keys.as_object() else {
                continue;
            };
            for key in keys.keys() {
                if key == "commands" || key == "timeouts" {
                    continue;
                }
                assert!(
                    text.contains(&format!("{key} =")) || text.contains(&format!("# {key} =")),
                    "[{table}] {key} is not documented in config/surfscan.toml"
                );
            }
        }
    }
}
