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
//! [`crate::stage`], [`crate::hook`], [`crate::report::header`] and [`crate::web`], on
//! [`crate::units`], and reads one file; nothing from the scan session.

use crate::hook::HookSettings;
use crate::metrology::sj_material_ratio::MaterialRatioReading;
use crate::report::header::LabHeader;
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
    /// `[contact]`: the contact analysis a scan's outputs include (off by default).
    #[serde(default)]
    pub contact: crate::contact::ContactSettings,
    /// `[notify]`: command run when a scan completes, fails or suspends.
    #[serde(default)]
    pub notify: Option<HookSettings>,
    /// `[metrics]`: Prometheus textfile.
    #[serde(default)]
    pub metrics: MetricsSettings,
    /// `[traceability]`: what the reports and X3P files say about the instrument beyond what
    /// it reports itself.
    #[serde(default)]
    pub traceability: TraceabilitySettings,
    /// `[jobs]`: where the recipes are.
    #[serde(default)]
    pub jobs: JobsSettings,
    /// `[mqtt]`: the station on the lab's MQTT broker; none by default.
    #[serde(default)]
    pub mqtt: Option<crate::publish::settings::MqttSettings>,
    /// `[report]`: the laboratory's header, the paper and the signature block of the printed
    /// report.
    #[serde(default)]
    pub report: LabHeader,
    /// `[web]`: the station's page; none unless the table is there.
    #[serde(default)]
    pub web: Option<crate::web::settings::WebSettings>,
    /// `[archive]`: each completed scan copied to the lab's object store; none by default.
    #[serde(default)]
    pub archive: Option<crate::publish::archive_settings::ArchiveSettings>,
    /// `[export]`: each completed scan's DFQ and QIF into the lab's drop directories; none
    /// by default.
    #[serde(default)]
    pub export: Option<crate::publish::export_settings::ExportSettings>,
}

/// `[jobs]`: recipes (named plans with their measuring conditions, analysis and
/// specification; see [`crate::jobs::recipe`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct JobsSettings {
    /// Directory of the recipe files, `NAME.toml` each (default `/etc/surfscan/recipes`).
    #[serde(default = "d_recipes")]
    pub recipes: PathBuf,
}

impl Default for JobsSettings {
    fn default() -> Self {
        JobsSettings {
            recipes: d_recipes(),
        }
    }
}

fn d_recipes() -> PathBuf {
    PathBuf::from("/etc/surfscan/recipes")
}

/// `[traceability]`: facts about the instrument that it does not report over its link, for
/// the reports and X3P files. Every key is optional; a missing one is reported as not
/// recorded. The whole configuration is recorded in each scan's journal, so a scan keeps
/// the values it was made with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct TraceabilitySettings {
    /// The instrument's serial number, when the instrument does not report one.
    pub serial_number: Option<String>,
    /// Radius of the stylus tip, µm (the SJ-210's standard styli: 2 or 5 µm).
    pub stylus_tip_radius_um: Option<f64>,
    /// Date of the instrument's last calibration, ISO 8601 (`YYYY-MM-DD`).
    pub calibration_date: Option<String>,
    /// The expanded (k = 2) relative uncertainty of the instrument's height scale stated by
    /// its calibration certificate, %: combined with the spread of the lines in every mean's
    /// uncertainty, and each line's uncertainty in a specification's verdict. Absent: the
    /// reports say that the instrument's uncertainty is not accounted for.
    pub calibration_uncertainty_pct: Option<f64>,
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
fn d_transient_budget() -> u64 {
    600
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
fn d_spike_sigma() -> f64 {
    crate::metrology::outliers::SpikeOptions::default().threshold_sigma
}
fn d_spike_points() -> usize {
    crate::metrology::outliers::SpikeOptions::default().max_points
}
fn d_holdout_threshold() -> f64 {
    crate::metrology::holdout::SUPPORTED_BELOW_SQ
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
    /// Times a line may be abandoned because the stage lost its position (re-homed each
    /// time) before the scan fails with the last fault (default 3).
    #[serde(default = "d_attempts")]
    pub max_line_attempts: u32,
    /// How long transient faults (NG codes, timeouts, garbage, busy) are retried with
    /// backoff, from the first one since the last committed line, before the scan fails
    /// naming the last fault, s (default 600).
    #[serde(default = "d_transient_budget")]
    pub transient_budget_s: u64,
    /// First wait before reconnecting a vanished device, ms (default 1000); doubles per try.
    #[serde(default = "d_backoff_initial")]
    pub reconnect_initial_ms: u64,
    /// Longest wait between reconnection tries, ms (default 30000).
    #[serde(default = "d_backoff_max")]
    pub reconnect_max_ms: u64,
}

/// `[fit]`: the surface.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct FitSettings {
    /// Degree along x / u (default 5).
    #[serde(default = "d_degree")]
    pub degree_u: usize,
    /// Degree along y / v (default 5).
    #[serde(default = "d_degree")]
    pub degree_v: usize,
    /// How the surface is made across the lines (default `interpolate`, the paper).
    #[serde(default)]
    pub v_method: VMethodSetting,
    /// Poles along v for `v-method = "least-squares"` (default: a quarter of the lines, at least
    /// degree-v + 1); refused with `interpolate`.
    #[serde(default)]
    pub v_control_rows: Option<usize>,
    /// What the fit does with the spikes `[analysis]` finds (default `keep`).
    #[serde(default)]
    pub outliers: FitOutliers,
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings {
            degree_u: 5,
            degree_v: 5,
            v_method: VMethodSetting::default(),
            v_control_rows: None,
            outliers: FitOutliers::default(),
        }
    }
}

impl FitSettings {
    /// The method across the lines for a scan of `lines` lines.
    pub fn v_method_for(&self, lines: usize) -> crate::fit::VMethod {
        match self.v_method {
            VMethodSetting::Interpolate => crate::fit::VMethod::Interpolate,
            VMethodSetting::LeastSquares => crate::fit::VMethod::LeastSquares {
                control_rows: self.v_control_rows.unwrap_or_else(|| {
                    crate::fit::approx_v::default_control_rows(lines, self.degree_v)
                }),
            },
        }
    }
}

/// `[fit] v-method`: the paper's interpolation through every line, or a least-squares
/// approximation across the lines (see [`crate::fit::approx_v`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum VMethodSetting {
    /// The paper (bit-identical to the plain fit).
    #[default]
    Interpolate,
    /// Least squares across the lines with `v-control-rows` poles.
    LeastSquares,
}

/// `[fit] outliers`: whether the fit sees the spikes as measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum FitOutliers {
    /// Fit the data as measured (the paper).
    #[default]
    Keep,
    /// Replace each spike by the straight line between its neighbours before fitting; the
    /// IGES Start section and the report say so and list the spikes.
    Replace,
}

/// `[analysis] outliers`: what characterisation does with the spikes it finds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum OutlierPolicy {
    /// Name them in the warnings and the report; the data stay as measured.
    #[default]
    Flag,
    /// Also leave them out of the per-line parameters and the measured grid's areal
    /// parameters (bridged by the straight line between their neighbours).
    Exclude,
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
    /// Groups (names or numeric ids) whose members may start, pause, resume and abort;
    /// status and watch stay open to everyone who can open the socket. Default: anyone who
    /// can open the socket may command.
    #[serde(default)]
    pub allowed_groups: Option<Vec<String>>,
}

impl Default for ControlSettings {
    fn default() -> Self {
        ControlSettings {
            socket: d_socket(),
            allowed_groups: None,
        }
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
    /// Spikes: `flag` (default; named, data unchanged) or `exclude` from characterisation.
    #[serde(default)]
    pub outliers: OutlierPolicy,
    /// A spike deviates from its line's median roughness by more than this many robust σ
    /// (1.4826 · MAD; default 10).
    #[serde(default = "d_spike_sigma")]
    pub spike_threshold_sigma: f64,
    /// The longest run of points that counts as a spike (default 5).
    #[serde(default = "d_spike_points")]
    pub spike_max_points: usize,
    /// The model between lines is supported when the hold-out rms is at most this × Sq
    /// (default 0.5).
    #[serde(default = "d_holdout_threshold")]
    pub holdout_threshold: f64,
    /// The reading of the material-ratio family (Rmr(c), Rmr, the Rk family) a verdict uses:
    /// `iso` (default, ISO 13565-2 on the continuous profile) or `instrument` (the SJ
    /// series' counted 100-level curve, as its display shows). Both are reported.
    #[serde(default)]
    pub material_ratio: MaterialRatioReading,
}

impl Default for AnalysisSettings {
    fn default() -> Self {
        AnalysisSettings {
            curves: d_curves(),
            levels: d_levels(),
            lambda_c_mm: None,
            no_filter: false,
            outliers: OutlierPolicy::default(),
            spike_threshold_sigma: d_spike_sigma(),
            spike_max_points: d_spike_points(),
            holdout_threshold: d_holdout_threshold(),
            material_ratio: MaterialRatioReading::Iso,
        }
    }
}

impl AnalysisSettings {
    /// The spike rule of these settings.
    pub fn spike_options(&self) -> crate::metrology::outliers::SpikeOptions {
        crate::metrology::outliers::SpikeOptions {
            threshold_sigma: self.spike_threshold_sigma,
            max_points: self.spike_max_points,
        }
    }
}

/// `[metrics]`: the Prometheus textfile (node_exporter textfile collector) and the `/metrics`
/// endpoint.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct MetricsSettings {
    /// File written atomically after every line; none by default.
    #[serde(default)]
    pub file: Option<PathBuf>,
    /// `HOST:PORT` to serve `/metrics` on (e.g. `0.0.0.0:9187`); none by default.
    #[serde(default)]
    pub listen: Option<String>,
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

    /// Checks every numeric key against its range in [`NUMERIC_KEYS`]; the first value out
    /// of range is the error, naming the key, the value and the range.
    pub fn check_ranges(&self, path: &Path) -> Result<(), ConfigError> {
        for k in NUMERIC_KEYS {
            if let Some(v) = k.value(self) {
                k.check(path, v)?;
            }
        }
        Ok(())
    }

    /// Checks what can be checked without devices: first every numeric key against its
    /// range (so nothing below computes with an absurd value), then the relations between
    /// keys and what the owning modules require.
    pub fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        self.check_ranges(path)?;
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
        self.plan_checked(path)?;
        let s = &self.scan;
        if s.reconnect_max_ms < s.reconnect_initial_ms {
            return Err(Config::invalid(
                path,
                "scan.reconnect-initial-ms",
                format!(
                    "reconnect-initial-ms = {} must be at most reconnect-max-ms = {}",
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
        // Ranges are in NUMERIC_KEYS; what remains is the relation between keys.
        let f = &self.fit;
        match (f.v_method, f.v_control_rows) {
            (VMethodSetting::Interpolate, Some(n)) => {
                return Err(Config::invalid(
                    path,
                    "fit.v-control-rows",
                    format!("{n} control rows apply to v-method = \"least-squares\" only; the paper's interpolation has one pole row per line (remove the key or set the method)"),
                ))
            }
            (VMethodSetting::LeastSquares, Some(n))
                if n < f.degree_v + 1 || n > self.scan.lines as usize =>
            {
                return Err(Config::invalid(
                    path,
                    "fit.v-control-rows",
                    format!(
                        "{n} must lie between degree-v + 1 = {} and the {} lines of [scan]",
                        f.degree_v + 1,
                        self.scan.lines
                    ),
                ))
            }
            _ => {}
        }
        if let Some(d) = &self.traceability.calibration_date {
            if chrono::NaiveDate::parse_from_str(d, "%Y-%m-%d").is_err() {
                return Err(Config::invalid(
                    path,
                    "traceability.calibration-date",
                    format!("{d:?} must be a date as YYYY-MM-DD, e.g. \"2026-03-14\""),
                ));
            }
        }
        if let Some(logo) = &self.report.logo {
            if self.report.logo_media_type().is_none() {
                return Err(Config::invalid(
                    path,
                    "report.logo",
                    format!("{} must be a PNG, JPEG or SVG file (by its extension: .png, .jpg, .jpeg, .svg); remove the key to print no logo", logo.display()),
                ));
            }
        }
        if let Some(groups) = &self.control.allowed_groups {
            if groups.is_empty() || groups.iter().any(|g| g.trim().is_empty()) {
                return Err(Config::invalid(
                    path,
                    "control.allowed-groups",
                    format!("{groups:?} must name at least one group, none of them empty, e.g. [\"surfscan-operators\"]; remove the key to let everyone who can open the socket command"),
                ));
            }
        }
        if let Some(l) = &self.metrics.listen {
            l.parse::<std::net::SocketAddr>().map_err(|_| {
                Config::invalid(
                    path,
                    "metrics.listen",
                    format!("{l:?} is not an address and port; write e.g. \"0.0.0.0:9187\" (every interface) or \"127.0.0.1:9187\""),
                )
            })?;
        }
        if let Some(m) = &self.mqtt {
            m.validate()
                .map_err(|(key, message)| Config::invalid(path, key, message))?;
        }
        if let Some(w) = &self.web {
            w.validate()
                .map_err(|(key, message)| Config::invalid(path, key, message))?;
        }
        if let Some(a) = &self.archive {
            a.validate()
                .map_err(|(key, message)| Config::invalid(path, key, message))?;
        }
        if let Some(x) = &self.export {
            x.validate()
                .map_err(|(key, message)| Config::invalid(path, key, message))?;
        }
        self.contact
            .check()
            .map_err(|(key, message)| Config::invalid(path, key, message))?;
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
            let why = if s.y_step_mm == 0.0 {
                "must not be 0 (the paper steps 0.01 mm)".to_owned()
            } else {
                format!(
                    "{} mm rounds to 0 nm: a step must be at least 1 nm (the paper steps 0.01 mm)",
                    s.y_step_mm
                )
            };
            return Err(Config::invalid(path, "scan.y-step-mm", why));
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
        self.steps_checked(path, y_start_nm, y_step_nm)
    }

    /// Every line's y a whole number of the stage's steps (unless
    /// `stage.allow-inexact-step`): the same rule the stage applies when it connects,
    /// named here, at `check-config`, with the steps that would do.
    fn steps_checked(&self, path: &Path, y_start_nm: Nm, y_step_nm: Nm) -> Result<(), ConfigError> {
        if self.stage.allow_inexact_step {
            return Ok(());
        }
        let Ok(unit_nm) = self.stage.nm_per_unit() else {
            return Ok(()); // Named by the stage's own check.
        };
        let unit_mm = unit_nm / Nm::PER_MM as f64;
        let lines = self.scan.lines;
        let (key, value_nm) = match crate::stage::policy::worst_inexact([y_step_nm], unit_nm) {
            Some(_) => ("scan.y-step-mm", y_step_nm),
            None => match crate::stage::policy::worst_inexact(
                (0..lines).map(|k| Nm(y_start_nm.0 + i64::from(k) * y_step_nm.0)),
                unit_nm,
            ) {
                Some(_) => ("scan.y-start-mm", y_start_nm),
                None => return Ok(()),
            },
        };
        let steps = value_nm.0 as f64 / unit_nm;
        let whole = |n: f64| format!("{}", (n * unit_mm * 1e6).round() / 1e6);
        let (below, above) = (steps.floor(), steps.ceil());
        let choices = if key == "scan.y-step-mm" && steps.abs() < 1.0 {
            // Less than one step: the smallest step the stage makes.
            format!("{} mm", whole(steps.signum()))
        } else {
            format!("{} or {} mm", whole(below), whole(above))
        };
        Err(Config::invalid(
            path,
            key,
            format!(
                "{} mm is {steps:.4} of the stage's steps of {} mm ({unit_nm} nm, from [stage]): the stage cannot place the lines there exactly; use a whole number of steps ({choices}) or set stage.allow-inexact-step = true",
                value_nm.to_mm(),
                unit_mm
            ),
        ))
    }
}

/// A numeric configuration value as written: integers stay integers in messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Num {
    /// An integer key's value.
    Int(i128),
    /// A real key's value.
    Real(f64),
}

impl Num {
    fn as_f64(self) -> f64 {
        match self {
            Num::Int(v) => v as f64,
            Num::Real(v) => v,
        }
    }
}

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Num::Int(v) => write!(f, "{v}"),
            // Debug keeps 1e-30 and 1e300 short instead of writing out every digit.
            Num::Real(v) => write!(f, "{v:?}"),
        }
    }
}

/// One numeric key of the file and its valid range (inclusive), checked by
/// [`Config::check_ranges`] before any other validation computes with the value.
#[derive(Debug, Clone, Copy)]
pub struct NumericKey {
    /// The key as written, with its tables: `stage.feed-mm-min`.
    pub key: &'static str,
    /// Smallest valid value.
    pub min: Num,
    /// Largest valid value.
    pub max: Num,
    /// Unit for messages (`ms`, `mm/min`; empty for counts).
    pub unit: &'static str,
    /// What the key is for and what to do, for the message.
    pub hint: &'static str,
    /// Where the value is read from.
    pub get: Getter,
}

/// Where a [`NumericKey`]'s value is read from.
#[derive(Debug, Clone, Copy)]
pub enum Getter {
    /// From the whole file; `None` when an optional key is absent.
    Config(fn(&Config) -> Option<Num>),
    /// From the `[instrument]` table, which `surfscan probe` also reads on its own.
    Instrument(fn(&InstrumentSettings) -> Option<Num>),
}

impl NumericKey {
    /// The value in a parsed configuration; `None` when an optional key is absent.
    pub fn value(&self, c: &Config) -> Option<Num> {
        match self.get {
            Getter::Config(f) => f(c),
            Getter::Instrument(f) => f(&c.instrument),
        }
    }

    /// `Ok` when `v` is in range, else the error naming the key, the value and the range.
    fn check(&self, path: &Path, v: Num) -> Result<(), ConfigError> {
        if self.contains(v) {
            return Ok(());
        }
        Err(Config::invalid(
            path,
            self.key,
            format!(
                "{v}{} is outside its valid range {} to {}{}; {}",
                self.unit_suffix(),
                self.min,
                self.max,
                self.unit_suffix(),
                self.hint
            ),
        ))
    }

    /// Checks `v` given on the command line as `flag`, which sets what this key sets: the
    /// same range, and a message that names the flag and the key.
    pub fn check_flag(&self, flag: &str, v: Num) -> Result<(), String> {
        if self.contains(v) {
            return Ok(());
        }
        Err(format!(
            "{flag} {v}{} is outside its valid range {} to {}{} (as `{}` in a station's configuration); {}",
            self.unit_suffix(),
            self.min,
            self.max,
            self.unit_suffix(),
            self.key,
            self.hint
        ))
    }

    /// The key named `key` in [`NUMERIC_KEYS`].
    pub fn named(key: &str) -> Option<&'static NumericKey> {
        NUMERIC_KEYS.iter().find(|k| k.key == key)
    }

    /// Whether `v` lies within the range (NaN never does).
    pub fn contains(&self, v: Num) -> bool {
        match (v, self.min, self.max) {
            (Num::Int(v), Num::Int(lo), Num::Int(hi)) => lo <= v && v <= hi,
            _ => {
                let v = v.as_f64();
                v >= self.min.as_f64() && v <= self.max.as_f64()
            }
        }
    }

    fn unit_suffix(&self) -> String {
        if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        }
    }
}

macro_rules! int_key {
    (instrument $key:literal, $min:expr, $max:expr, $unit:literal, $hint:literal, |$c:ident| $get:expr) => {
        NumericKey {
            key: $key,
            min: Num::Int($min),
            max: Num::Int($max),
            unit: $unit,
            hint: $hint,
            get: Getter::Instrument(|$c: &InstrumentSettings| $get.map(|v| Num::Int(v as i128))),
        }
    };
    ($key:literal, $min:expr, $max:expr, $unit:literal, $hint:literal, |$c:ident| $get:expr) => {
        NumericKey {
            key: $key,
            min: Num::Int($min),
            max: Num::Int($max),
            unit: $unit,
            hint: $hint,
            get: Getter::Config(|$c: &Config| $get.map(|v| Num::Int(v as i128))),
        }
    };
}

macro_rules! real_key {
    (instrument $key:literal, $min:expr, $max:expr, $unit:literal, $hint:literal, |$c:ident| $get:expr) => {
        NumericKey {
            key: $key,
            min: Num::Real($min),
            max: Num::Real($max),
            unit: $unit,
            hint: $hint,
            get: Getter::Instrument(|$c: &InstrumentSettings| $get.map(Num::Real)),
        }
    };
    ($key:literal, $min:expr, $max:expr, $unit:literal, $hint:literal, |$c:ident| $get:expr) => {
        NumericKey {
            key: $key,
            min: Num::Real($min),
            max: Num::Real($max),
            unit: $unit,
            hint: $hint,
            get: Getter::Config(|$c: &Config| $get.map(Num::Real)),
        }
    };
}

/// Checks the numeric keys of an `[instrument]` table read on its own (as `surfscan probe`
/// reads it) against the same ranges as in a whole file.
pub fn check_instrument_ranges(
    path: &Path,
    instrument: &InstrumentSettings,
) -> Result<(), ConfigError> {
    for k in NUMERIC_KEYS {
        if let Getter::Instrument(f) = k.get {
            if let Some(v) = f(instrument) {
                k.check(path, v)?;
            }
        }
    }
    Ok(())
}

/// Every numeric key of the file with its valid range. The bounds are wide enough for any
/// station we know of and narrow enough that the arithmetic on them (durations, nanometre
/// targets, degrees + 1) cannot overflow; relations between keys (lines ≥ degree-v + 1,
/// soft-limit-min < soft-limit-max, the model's baud rates) are checked afterwards.
#[rustfmt::skip]
pub const NUMERIC_KEYS: &[NumericKey] = &[
    int_key!(instrument "instrument.baud", 300, 115_200, "baud", "set the rate the instrument is set to (9600, 19200, 38400; `surfscan probe` finds it)", |c| Some(c.baud)),
    real_key!(instrument "instrument.pitch-x-um", 0.001, 1000.0, "µm", "the SJ-210 exports 0.5 to 1.5 µm; remove the key to derive it from λs", |c| c.pitch_x_um),
    real_key!(instrument "instrument.measuring-speed-mm-s", 0.01, 100.0, "mm/s", "set the instrument's measuring speed (the SJ-210's are 0.25, 0.5 and 0.75)", |c| Some(c.measuring_speed_mm_s)),
    real_key!(instrument "instrument.detector-range-um", 1.0, 10_000.0, "µm", "the SJ-210's standard detector measures 360 µm (−200 to +160 µm); give the range of the detector fitted", |c| Some(c.detector_range_um)),
    real_key!(instrument "instrument.return-speed-mm-s", 0.01, 100.0, "mm/s", "the SJ-210 returns at 1 mm/s", |c| Some(c.return_speed_mm_s)),
    int_key!(instrument "instrument.timeouts.first-byte-ms", 1, 600_000, "ms", "the default is 2000", |c| Some(c.timeouts.first_byte_ms)),
    int_key!(instrument "instrument.timeouts.inter-byte-ms", 1, 60_000, "ms", "the default is 200", |c| Some(c.timeouts.inter_byte_ms)),
    int_key!(instrument "instrument.timeouts.poll-interval-ms", 1, 60_000, "ms", "the default is 250", |c| Some(c.timeouts.poll_interval_ms)),
    int_key!(instrument "instrument.timeouts.start-deadline-ms", 1, 600_000, "ms", "the default is 5000", |c| Some(c.timeouts.start_deadline_ms)),
    int_key!(instrument "instrument.timeouts.read-retry-budget-ms", 0, 3_600_000, "ms", "the default is 10000; 0 retries nothing", |c| Some(c.timeouts.read_retry_budget_ms)),
    int_key!(instrument "instrument.timeouts.trace-deadline-ms", 1, 3_600_000, "ms", "remove the key to derive it from the measuring conditions", |c| c.timeouts.trace_deadline_ms),
    int_key!("stage.baud", 300, 4_000_000, "baud", "GRBL and Zaber use 115200", |c| Some(c.stage.baud)),
    real_key!("stage.steps-per-mm", 0.001, 10_000_000.0, "steps/mm", "set the controller's $101", |c| c.stage.steps_per_mm),
    real_key!("stage.mm-per-microstep", 1e-9, 1.0, "mm", "take it from the stage's datasheet", |c| c.stage.mm_per_microstep),
    real_key!("stage.nm-per-microstep", 0.001, 1_000_000.0, "nm", "take it from the stage's datasheet", |c| c.stage.nm_per_microstep),
    int_key!("stage.device", 1, 99, "", "Zaber device addresses are 1 to 99 (0 would address every device)", |c| Some(c.stage.device)),
    int_key!("stage.axis", 1, 9, "", "Zaber axes are numbered from 1 (0 would address the whole device)", |c| Some(c.stage.axis)),
    real_key!("stage.soft-limit-min-mm", -10_000.0, 10_000.0, "mm", "set the stage's lowest allowed target in machine coordinates", |c| Some(c.stage.soft_limit_min_mm)),
    real_key!("stage.soft-limit-max-mm", -10_000.0, 10_000.0, "mm", "set the stage's highest allowed target in machine coordinates", |c| Some(c.stage.soft_limit_max_mm)),
    real_key!("stage.backlash-mm", 0.0, 10.0, "mm", "0 disables the backlash take-out", |c| Some(c.stage.backlash_mm)),
    int_key!("stage.settle-ms", 0, 60_000, "ms", "the default is 200", |c| Some(c.stage.settle_ms)),
    real_key!("stage.deadband-um", 0.0, 1000.0, "µm", "the default is 1", |c| Some(c.stage.deadband_um)),
    int_key!("stage.max-move-attempts", 1, 100, "", "the default is 3", |c| Some(c.stage.max_move_attempts)),
    real_key!("stage.feed-mm-min", 0.1, 100_000.0, "mm/min", "the default is 60", |c| Some(c.stage.feed_mm_min)),
    int_key!("stage.poll-interval-ms", 1, 60_000, "ms", "the default is 250 (GRBL needs at least 200)", |c| Some(c.stage.poll_interval_ms)),
    int_key!("scan.lines", 1, 100_000, "", "the paper traces 31 lines", |c| Some(c.scan.lines)),
    real_key!("scan.y-start-mm", -10_000.0, 10_000.0, "mm", "set the first line's y in machine coordinates", |c| Some(c.scan.y_start_mm)),
    real_key!("scan.y-step-mm", -100.0, 100.0, "mm", "the paper steps 0.01 mm", |c| Some(c.scan.y_step_mm)),
    int_key!("scan.max-line-attempts", 1, 100, "", "the default is 3", |c| Some(c.scan.max_line_attempts)),
    int_key!("scan.transient-budget-s", 1, 604_800, "s", "the default is 600 (ten minutes)", |c| Some(c.scan.transient_budget_s)),
    int_key!("scan.reconnect-initial-ms", 1, 600_000, "ms", "the default is 1000", |c| Some(c.scan.reconnect_initial_ms)),
    int_key!("scan.reconnect-max-ms", 1, 3_600_000, "ms", "the default is 30000", |c| Some(c.scan.reconnect_max_ms)),
    int_key!("fit.degree-u", 1, 15, "", "the paper uses 5", |c| Some(c.fit.degree_u)),
    int_key!("fit.degree-v", 1, 15, "", "the paper uses 5", |c| Some(c.fit.degree_v)),
    int_key!("analysis.curves", 1, 10_000, "", "the default is 31", |c| Some(c.analysis.curves)),
    int_key!("analysis.levels", 2, 100_000, "", "the default is 101", |c| Some(c.analysis.levels)),
    real_key!("analysis.lambda-c-mm", 0.001, 100.0, "mm", "the ISO cut-offs are 0.08, 0.25, 0.8, 2.5 and 8 mm", |c| c.analysis.lambda_c_mm),
    real_key!("analysis.spike-threshold-sigma", 1.0, 1000.0, "", "robust standard deviations; the default is 10", |c| Some(c.analysis.spike_threshold_sigma)),
    int_key!("analysis.spike-max-points", 1, 10_000, "", "the longest run of points that is a spike; the default is 5", |c| Some(c.analysis.spike_max_points)),
    real_key!("analysis.holdout-threshold", 0.001, 100.0, "", "a multiple of Sq; the default is 0.5", |c| Some(c.analysis.holdout_threshold)),
    int_key!("fit.v-control-rows", 2, 100_000, "", "pole rows across the lines, at most the number of lines; remove the key for a quarter of the lines", |c| c.fit.v_control_rows),
    int_key!("notify.timeout-s", 1, 86_400, "s", "the default is 30", |c| c.notify.as_ref().map(|n| n.timeout_s)),
    int_key!("mqtt.outbox-max", 1, 1_000_000, "", "messages kept while the broker is away; the default is 10000", |c| c.mqtt.as_ref().map(|m| m.outbox_max)),
    int_key!("mqtt.keep-alive-s", 5, 3600, "s", "the default is 30", |c| c.mqtt.as_ref().map(|m| m.keep_alive_s)),
    int_key!("archive.delete-after-days", 0, 36_500, "days", "days after completion that an archived, verified scan leaves the station; remove the key to keep every scan", |c| c.archive.as_ref().and_then(|a| a.delete_after_days)),
    int_key!("web.max-connections", 1, 4096, "", "connections the page serves at once; the default is 256", |c| c.web.as_ref().map(|w| w.max_connections)),
    int_key!("web.session-hours", 1, 744, "h", "how long a browser stays signed in, at most 31 days; the default is 12", |c| c.web.as_ref().map(|w| w.session_hours)),
    real_key!("contact.young-gpa", 0.001, 1500.0, "GPa", "the specimen's Young's modulus (steel 210, brass 100, aluminium 70)", |c| Some(c.contact.young_gpa)),
    real_key!("contact.poisson", 0.0, 0.5, "", "the specimen's Poisson's ratio (steel 0.30, brass 0.34)", |c| Some(c.contact.poisson)),
    real_key!("contact.young2-gpa", 0.001, 1500.0, "GPa", "the counter-body's Young's modulus; remove the key for a rigid flat", |c| c.contact.young2_gpa),
    real_key!("contact.poisson2", 0.0, 0.5, "", "the counter-body's Poisson's ratio; the default is 0.30", |c| c.contact.poisson2),
    real_key!("contact.hardness-gpa", 0.001, 150.0, "GPa", "the specimen's indentation hardness (mild steel about 1.5, brass about 1); remove the key for an elastic contact", |c| c.contact.hardness_gpa),
    real_key!("contact.model-pitch-y-mm", 0.0001, 100.0, "mm", "the y spacing the model is sampled at between the lines, e.g. 0.002; remove the key for the measured grid only", |c| c.contact.model_pitch_y_mm),
    real_key!("traceability.stylus-tip-radius-um", 0.01, 100.0, "µm", "the SJ-210's standard styli have 2 or 5 µm", |c| c.traceability.stylus_tip_radius_um),
    real_key!("traceability.calibration-uncertainty-pct", 0.001, 100.0, "%", "the expanded (k = 2) relative uncertainty on the calibration certificate, e.g. 3.0", |c| c.traceability.calibration_uncertainty_pct),
];

#[cfg(test)]
pub(crate) mod tests {
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

    /// The error a file that must be refused is refused with.
    fn refused(text: &str) -> String {
        parse(text).unwrap_err().to_string()
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
    fn the_report_table_is_optional_and_its_logo_checked() {
        assert_eq!(parse(MINIMAL).unwrap().report, LabHeader::default());
        let with = format!(
            "{MINIMAL}[report]\nlab = \"Lab\"\naddress = \"1 Road\\nTown\"\nlogo = \"/etc/surfscan/logo.png\"\npaper = \"Letter\"\nsignatures = [\"Measured by\", \"Checked by\", \"Approved by\"]\n"
        );
        let r = parse(&with).unwrap().report;
        assert_eq!(r.address, "1 Road\nTown");
        assert_eq!(r.paper, crate::report::header::Paper::Letter);
        assert_eq!(r.signatures.len(), 3);
        assert!(!r.line_png);
        assert!(
            parse(&format!("{with}line-png = true\n"))
                .unwrap()
                .report
                .line_png
        );
        let e = refused(&with.replace("logo.png", "logo.bmp"));
        assert!(
            e.contains("report.logo") && e.contains("PNG, JPEG or SVG"),
            "{e}"
        );
        let e = refused(&with.replace("\"Letter\"", "\"A3\""));
        assert!(e.contains("A3") || e.contains("paper"), "{e}");
    }

    #[test]
    fn traceability_keys_are_optional_and_checked() {
        assert_eq!(
            parse(MINIMAL).unwrap().traceability,
            TraceabilitySettings::default()
        );
        let with = format!(
            "{MINIMAL}[traceability]\nserial-number = \"SN-7\"\nstylus-tip-radius-um = 2.0\ncalibration-date = \"2026-03-14\"\n"
        );
        let t = parse(&with).unwrap().traceability;
        assert_eq!(t.serial_number.as_deref(), Some("SN-7"));
        assert_eq!(t.stylus_tip_radius_um, Some(2.0));
        assert_eq!(t.calibration_date.as_deref(), Some("2026-03-14"));
        let e = refused(&with.replace("2026-03-14", "14.03.2026"));
        assert!(
            e.contains("traceability.calibration-date") && e.contains("YYYY-MM-DD"),
            "{e}"
        );
        let e = refused(&with.replace("= 2.0", "= -2.0"));
        assert!(e.contains("traceability.stylus-tip-radius-um"), "{e}");
        let e = refused(&with.replace("serial-number", "serial"));
        assert!(e.contains("serial"), "{e}");
    }

    #[test]
    fn too_few_lines_for_the_degree_is_named() {
        let text = MINIMAL.replace("lines = 31", "lines = 5");
        let e = refused(&text);
        assert!(e.contains("scan.lines") && e.contains("at least 6"), "{e}");
    }

    #[test]
    fn inexact_or_zero_step_is_refused() {
        let e = refused(&MINIMAL.replace("y-step-mm = 0.01", "y-step-mm = 0.0100003"));
        assert!(
            e.contains("scan.y-step-mm") && e.contains("nanometres"),
            "{e}"
        );
        let e = refused(&MINIMAL.replace("y-step-mm = 0.01", "y-step-mm = 0.0"));
        assert!(e.contains("must not be 0"), "{e}");
        // A step that is not 0 but rounds to 0 nm is told as such, not as a 0 typed.
        let e = refused(&MINIMAL.replace("y-step-mm = 0.01", "y-step-mm = 1e-12"));
        assert!(
            e.contains("scan.y-step-mm")
                && e.contains("rounds to 0 nm")
                && !e.contains("must not be 0"),
            "{e}"
        );
    }

    #[test]
    fn unknown_keys_and_plans_beyond_the_limits_are_refused() {
        let e = refused(&MINIMAL.replace("lines = 31", "lines = 31\nline = 3"));
        assert!(e.contains("unknown field") && e.contains("line"), "{e}");
        let e = refused(&MINIMAL.replace("soft-limit-max-mm = 50.0", "soft-limit-max-mm = 1.2"));
        assert!(e.contains("line 31") && e.contains("soft limits"), "{e}");
        let e = refused(&MINIMAL.replace("steps-per-mm", "poll-interval-ms = 50\nsteps-per-mm"));
        assert!(
            e.contains("stage") && e.contains("poll-interval-ms = 50"),
            "{e}"
        );
        let e = refused("[scan]\nlines = 3");
        assert!(e.contains("missing field"), "{e}");
    }

    /// The shipped configuration with every commented-out `key = value` line and table
    /// header switched on: a file that sets every key the schema has (not a valid station:
    /// both Zaber scales are set, for one).
    fn every_key_text() -> String {
        let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/config/surfscan.toml"));
        let text = std::fs::read_to_string(path).unwrap();
        let mut out = String::new();
        for line in text.lines() {
            let body = line.strip_prefix("# ").unwrap_or("");
            let is_table = body.starts_with('[') && body.trim_end().ends_with(']');
            let is_key = body.split_once(" = ").is_some_and(|(k, _)| {
                !k.is_empty()
                    && k.chars()
                        .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
            });
            out.push_str(if is_table || is_key { body } else { line });
            out.push('\n');
        }
        out
    }

    fn numeric_leaves(prefix: &str, v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, v) in m {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    numeric_leaves(&key, v, out);
                }
            }
            serde_json::Value::Number(_) => out.push(prefix.to_owned()),
            _ => {}
        }
    }

    fn set_key(table: &mut toml::Table, dotted: &str, value: toml::Value) {
        let mut parts: Vec<&str> = dotted.split('.').collect();
        let last = parts.pop().unwrap();
        let mut t = table;
        for p in parts {
            t = t
                .entry(p)
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .unwrap();
        }
        t.insert(last.to_owned(), value);
    }

    fn toml_value(n: Num) -> toml::Value {
        match n {
            Num::Int(v) => toml::Value::Integer(i64::try_from(v).unwrap()),
            Num::Real(v) => toml::Value::Float(v),
        }
    }

    #[test]
    fn every_numeric_key_of_the_schema_has_a_range() {
        let c: Config = toml::from_str(&every_key_text()).unwrap();
        let mut leaves = Vec::new();
        numeric_leaves("", &serde_json::to_value(&c).unwrap(), &mut leaves);
        leaves.sort();
        let mut table: Vec<String> = NUMERIC_KEYS.iter().map(|k| k.key.to_owned()).collect();
        table.sort();
        assert_eq!(
            leaves, table,
            "every numeric key needs an entry in NUMERIC_KEYS (and config/surfscan.toml)"
        );
        for k in NUMERIC_KEYS {
            assert!(k.value(&c).is_some(), "{} not read from the file", k.key);
        }
    }

    #[test]
    fn each_numeric_key_is_accepted_at_its_bounds_and_refused_beyond() {
        let base: toml::Table = toml::from_str(&every_key_text()).unwrap();
        let base_config: Config = toml::from_str(&every_key_text()).unwrap();
        base_config.check_ranges(Path::new("t.toml")).unwrap();
        let name = |key: &str| key.rsplit('.').next().unwrap().to_owned();
        for k in NUMERIC_KEYS {
            for bound in [k.min, k.max] {
                let mut t = base.clone();
                set_key(&mut t, k.key, toml_value(bound));
                let c: Config = toml::from_str(&toml::to_string(&t).unwrap()).unwrap();
                assert_eq!(k.value(&c), Some(bound), "{}", k.key);
                if let Err(e) = c.check_ranges(Path::new("t.toml")) {
                    panic!("{} = {bound} is its own bound but refused: {e}", k.key);
                }
            }
            let beyond: Vec<toml::Value> = match (k.min, k.max) {
                (Num::Int(lo), Num::Int(hi)) => {
                    [lo - 1, hi + 1, -1, i64::MAX.into(), i64::MIN.into()]
                        .into_iter()
                        .filter(|v| !(lo..=hi).contains(v))
                        .map(|v| toml::Value::Integer(v as i64))
                        .collect()
                }
                (Num::Real(lo), Num::Real(hi)) => [
                    lo - (lo.abs() * 1e-3).max(1e-12),
                    hi + (hi.abs() * 1e-3).max(1e-12),
                    f64::NAN,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    1e300,
                    -1e300,
                ]
                .into_iter()
                .map(toml::Value::Float)
                .collect(),
                _ => panic!("{}: bounds of mixed kinds", k.key),
            };
            for v in beyond {
                let mut t = base.clone();
                set_key(&mut t, k.key, v.clone());
                let text = toml::to_string(&t).unwrap();
                match Config::parse(Path::new("t.toml"), &text) {
                    Ok(_) => panic!("{} = {v} accepted", k.key),
                    // Out of range for the key's type: refused by the parser, which quotes
                    // the key's line.
                    Err(ConfigError::Parse { message, .. }) => {
                        assert!(message.contains(&name(k.key)), "{} = {v}: {message}", k.key)
                    }
                    Err(ConfigError::Invalid { key, message, .. }) => {
                        assert_eq!(key, k.key, "{} = {v}: {message}", k.key);
                        assert!(message.contains("valid range"), "{message}");
                    }
                    Err(e) => panic!("{} = {v}: {e}", k.key),
                }
            }
        }
    }

    #[test]
    fn feed_mm_min_1e_minus_30_is_refused_naming_the_key() {
        // Used to overflow the move-timeout Duration inside validation (a panic, exit 134).
        let text = MINIMAL.replace("steps-per-mm", "feed-mm-min = 1e-30\nsteps-per-mm");
        let e = parse(&text).unwrap_err();
        assert!(
            matches!(
                e,
                ConfigError::Invalid {
                    key: "stage.feed-mm-min",
                    ..
                }
            ),
            "{e}"
        );
        let e = e.to_string();
        assert!(
            e.contains("1e-30 mm/min") && e.contains("0.1 to 100000.0 mm/min"),
            "{e}"
        );
    }

    #[test]
    fn huge_degree_is_refused_before_degree_plus_one_is_computed() {
        let text = format!("{MINIMAL}\n[fit]\ndegree-v = {}\n", i64::MAX);
        let e = parse(&text).unwrap_err();
        assert!(
            matches!(
                e,
                ConfigError::Invalid {
                    key: "fit.degree-v",
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn model_and_outlier_keys_parse_and_are_checked() {
        let c = parse(MINIMAL).unwrap();
        assert_eq!(c.fit.v_method_for(31), crate::fit::VMethod::Interpolate);
        assert_eq!(c.analysis.outliers, OutlierPolicy::Flag);
        assert_eq!(c.fit.outliers, FitOutliers::Keep);
        assert_eq!(c.analysis.spike_options(), Default::default());
        let text = format!(
            "{MINIMAL}[fit]\nv-method = \"least-squares\"\noutliers = \"replace\"\n[analysis]\noutliers = \"exclude\"\nspike-threshold-sigma = 8.0\n"
        );
        let c = parse(&text).unwrap();
        assert_eq!(
            c.fit.v_method_for(31),
            crate::fit::VMethod::LeastSquares { control_rows: 8 }
        );
        assert_eq!(c.fit.outliers, FitOutliers::Replace);
        assert_eq!(c.analysis.outliers, OutlierPolicy::Exclude);
        assert_eq!(c.analysis.spike_options().threshold_sigma, 8.0);
        let rows = text.replace("outliers = \"replace\"", "v-control-rows = 12");
        assert_eq!(
            parse(&rows).unwrap().fit.v_method_for(31),
            crate::fit::VMethod::LeastSquares { control_rows: 12 }
        );
        for (bad, key) in [
            (text.replace("least-squares", "spline"), "unknown variant"),
            (
                rows.replace("v-control-rows = 12", "v-control-rows = 40"),
                "fit.v-control-rows",
            ),
            (
                rows.replace("v-control-rows = 12", "v-control-rows = 5"),
                "fit.v-control-rows",
            ),
            (
                format!("{MINIMAL}[fit]\nv-control-rows = 8\n"),
                "least-squares\" only",
            ),
            (
                text.replace("= 8.0", "= 0.0"),
                "analysis.spike-threshold-sigma",
            ),
            (
                format!("{MINIMAL}[analysis]\nholdout-threshold = -1.0\n"),
                "analysis.holdout-threshold",
            ),
        ] {
            let e = refused(&bad);
            assert!(e.contains(key), "{e}");
        }
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
