//! The `[instrument]` section of the configuration: port, model, link settings, pitch,
//! timeouts and command overrides, validated into what the client needs.
//!
//! Layer 4 (settings owned by the driver): depends on [`crate::transport`] types and
//! [`super::models`]; no I/O.

use super::models::{CommandOverrides, ModelError, ModelId, ModelTable};
use super::timing::DriveSpeeds;
use crate::transport::{FlowControl, Parity, SerialSettings};
use serde::{Deserialize, Serialize};
use std::time::Duration;
use thiserror::Error;

/// `[instrument]`: how to reach and drive the profiler.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct InstrumentSettings {
    /// Serial device path; prefer `/dev/serial/by-id/…` or a udev symlink.
    pub port: String,
    /// Model: `sj210` (default), `sj220`, `sj310`, `sj410`.
    #[serde(default)]
    pub model: ModelId,
    /// Baud rate as set on the instrument (default 38400, the SJ-210's fastest: the
    /// read-out of a profile runs at this rate).
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// Parity as set on the instrument: `none` (default), `even`, `odd`.
    #[serde(default)]
    pub parity: Parity,
    /// Flow control: `none` (default) or `rts-cts`.
    #[serde(default)]
    pub flow_control: FlowControl,
    /// x pitch of the exported profile in µm; when absent it is derived from λs
    /// (2.5 → 0.5, 8 → 1.5, 25 → 5 µm, ISO 3274).
    #[serde(default)]
    pub pitch_x_um: Option<f64>,
    /// Refuse a profile whose point count is not N × ⌊λc / pitch⌋ (default true). Set false
    /// only for a firmware whose export is known to follow another rule.
    #[serde(default = "default_true")]
    pub check_point_count: bool,
    /// Measuring range of the detector in µm (default 360, the SJ-210's standard detector,
    /// −200 to +160 µm): a profile whose heights span more cannot be the surface's (heights
    /// in the wrong unit, nm read as µm) and is read again, then kept with a named warning.
    #[serde(default = "default_detector_range")]
    pub detector_range_um: f64,
    /// Measuring speed of the drive as set on the instrument, mm/s (default 0.5): with the
    /// traverse it gives when a trace is expected to end, where its status is asked.
    #[serde(default = "default_measuring_speed")]
    pub measuring_speed_mm_s: f64,
    /// Return speed of the drive, mm/s (default 1.0).
    #[serde(default = "default_return_speed")]
    pub return_speed_mm_s: f64,
    /// Timeouts and pacing.
    #[serde(default)]
    pub timeouts: TimeoutSettings,
    /// Overrides of the built-in command table.
    #[serde(default)]
    pub commands: CommandOverrides,
}

fn default_baud() -> u32 {
    38_400
}

fn default_true() -> bool {
    true
}

/// The SJ-210's standard detector (178-296): −200 to +160 µm.
pub const STANDARD_DETECTOR_RANGE_UM: f64 = 360.0;

fn default_detector_range() -> f64 {
    STANDARD_DETECTOR_RANGE_UM
}

fn default_measuring_speed() -> f64 {
    0.5
}

fn default_return_speed() -> f64 {
    1.0
}

/// `[instrument.timeouts]`, all in milliseconds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields, default)]
pub struct TimeoutSettings {
    /// Wait for the first byte of a reply (default 2000).
    pub first_byte_ms: u64,
    /// Wait between bytes of one reply (default 200).
    pub inter_byte_ms: u64,
    /// Status poll interval during a trace (default 250, i.e. 4 Hz).
    pub poll_interval_ms: u64,
    /// Time for the status to reach "measuring" after start (default 5000).
    pub start_deadline_ms: u64,
    /// Total time reads may be retried on NG011/NG033/NG101 (default 10000).
    pub read_retry_budget_ms: u64,
    /// Overall trace deadline; derived from the conditions when absent.
    pub trace_deadline_ms: Option<u64>,
}

impl Default for TimeoutSettings {
    fn default() -> Self {
        TimeoutSettings {
            first_byte_ms: 2000,
            inter_byte_ms: 200,
            poll_interval_ms: 250,
            start_deadline_ms: 5000,
            read_retry_budget_ms: 10_000,
            trace_deadline_ms: None,
        }
    }
}

/// Client options derived from the settings.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientOptions {
    /// Wait for the first byte of a reply.
    pub first_byte: Duration,
    /// Wait between bytes of one reply.
    pub inter_byte: Duration,
    /// Status poll interval during a trace and between read retries.
    pub poll_interval: Duration,
    /// Time for the status to reach "measuring" after start.
    pub start_deadline: Duration,
    /// Total time a read may be retried on busy codes.
    pub read_retry_budget: Duration,
    /// Overall trace deadline override.
    pub trace_deadline: Option<Duration>,
    /// Configured x pitch in µm.
    pub pitch_x_um: Option<f64>,
    /// Refuse a profile whose point count is not the one its conditions give.
    pub check_point_count: bool,
    /// The detector's measuring range, µm: the widest span a profile's heights can have.
    pub detector_range_um: f64,
    /// The drive's speeds, for when a trace is expected to end.
    pub speeds: DriveSpeeds,
    /// Longest accepted reply line in bytes.
    pub max_line: usize,
}

impl Default for ClientOptions {
    fn default() -> Self {
        ClientOptions::from_timeouts(&TimeoutSettings::default(), None)
    }
}

impl ClientOptions {
    /// Options from the timeout settings and the configured pitch.
    pub fn from_timeouts(t: &TimeoutSettings, pitch_x_um: Option<f64>) -> ClientOptions {
        ClientOptions {
            first_byte: Duration::from_millis(t.first_byte_ms),
            inter_byte: Duration::from_millis(t.inter_byte_ms),
            poll_interval: Duration::from_millis(t.poll_interval_ms),
            start_deadline: Duration::from_millis(t.start_deadline_ms),
            read_retry_budget: Duration::from_millis(t.read_retry_budget_ms),
            trace_deadline: t.trace_deadline_ms.map(Duration::from_millis),
            pitch_x_um,
            check_point_count: true,
            detector_range_um: STANDARD_DETECTOR_RANGE_UM,
            speeds: DriveSpeeds {
                measuring_mm_s: default_measuring_speed(),
                return_mm_s: default_return_speed(),
            },
            max_line: super::codec::DEFAULT_MAX_LINE,
        }
    }
}

/// A bad `[instrument]` section.
#[derive(Debug, Error, PartialEq)]
pub enum SettingsError {
    /// The baud rate is not one the model offers.
    #[error("[instrument] baud = {baud} is not offered by the {model} (it offers {allowed:?}); set the instrument and the config to one of these")]
    Baud {
        /// Configured baud.
        baud: u32,
        /// Model.
        model: ModelId,
        /// What the model offers.
        allowed: Vec<u32>,
    },
    /// The pitch is not a positive finite number.
    #[error("[instrument] pitch-x-um = {0} must be a positive number of micrometres")]
    Pitch(f64),
    /// A drive speed is not a positive finite number.
    #[error("[instrument] {0} = {1} must be a positive number of mm/s (the SJ-210 measures at 0.25, 0.5 or 0.75 mm/s)")]
    Speed(&'static str, f64),
    /// A timeout is zero.
    #[error("[instrument.timeouts] {0} must be greater than zero")]
    ZeroTimeout(&'static str),
    /// The command override is invalid.
    #[error(transparent)]
    Commands(#[from] ModelError),
}

impl InstrumentSettings {
    /// Checks the settings and builds the model table with the overrides merged.
    pub fn validate(&self) -> Result<ModelTable, SettingsError> {
        let table = ModelTable::with_overrides(self.model, &self.commands)?;
        if !table.baud_rates.contains(&self.baud) {
            return Err(SettingsError::Baud {
                baud: self.baud,
                model: self.model,
                allowed: table.baud_rates.clone(),
            });
        }
        if let Some(p) = self.pitch_x_um {
            if !(p.is_finite() && p > 0.0) {
                return Err(SettingsError::Pitch(p));
            }
        }
        for (v, name) in [
            (self.measuring_speed_mm_s, "measuring-speed-mm-s"),
            (self.return_speed_mm_s, "return-speed-mm-s"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SettingsError::Speed(name, v));
            }
        }
        let t = &self.timeouts;
        for (v, name) in [
            (t.first_byte_ms, "first-byte-ms"),
            (t.inter_byte_ms, "inter-byte-ms"),
            (t.poll_interval_ms, "poll-interval-ms"),
            (t.start_deadline_ms, "start-deadline-ms"),
        ] {
            if v == 0 {
                return Err(SettingsError::ZeroTimeout(name));
            }
        }
        if t.trace_deadline_ms == Some(0) {
            return Err(SettingsError::ZeroTimeout("trace-deadline-ms"));
        }
        Ok(table)
    }

    /// The serial link settings for [`crate::transport::open`].
    pub fn serial(&self) -> SerialSettings {
        SerialSettings {
            path: self.port.clone(),
            baud: self.baud,
            parity: self.parity,
            flow_control: self.flow_control,
        }
    }

    /// The client options.
    pub fn client_options(&self) -> ClientOptions {
        ClientOptions {
            check_point_count: self.check_point_count,
            detector_range_um: self.detector_range_um,
            speeds: DriveSpeeds {
                measuring_mm_s: self.measuring_speed_mm_s,
                return_mm_s: self.return_speed_mm_s,
            },
            ..ClientOptions::from_timeouts(&self.timeouts, self.pitch_x_um)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimal_section_gets_defaults() {
        let s: InstrumentSettings = toml::from_str("port = \"/dev/ttyUSB0\"").unwrap();
        assert_eq!(s.model, ModelId::Sj210);
        assert_eq!(s.baud, 38400);
        assert_eq!(s.timeouts.poll_interval_ms, 250);
        assert!(s.validate().is_ok());
        assert_eq!(
            s.client_options().speeds,
            DriveSpeeds {
                measuring_mm_s: 0.5,
                return_mm_s: 1.0
            }
        );
    }

    #[test]
    fn full_section_parses_kebab_case() {
        let s: InstrumentSettings = toml::from_str(
            "port = \"/dev/x\"\nmodel = \"sj410\"\nbaud = 57600\nparity = \"even\"\nflow-control = \"rts-cts\"\npitch-x-um = 0.5\n[timeouts]\nfirst-byte-ms = 500\n[commands]\nprofile-total = \"RDEVA100\"\nprofile-block = \"RDEVA1{n}\"\n",
        )
        .unwrap();
        let t = s.validate().unwrap();
        assert_eq!(s.parity, Parity::Even);
        assert_eq!(s.flow_control, FlowControl::RtsCts);
        assert_eq!(s.client_options().first_byte, Duration::from_millis(500));
        assert_eq!(t.commands.profile_total.unwrap().template, "RDEVA100");
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        assert!(toml::from_str::<InstrumentSettings>("port = \"x\"\nbaudrate = 9600").is_err());
        let s: InstrumentSettings = toml::from_str("port = \"x\"\nbaud = 57600").unwrap();
        assert!(matches!(
            s.validate(),
            Err(SettingsError::Baud { baud: 57600, .. })
        ));
        let s: InstrumentSettings = toml::from_str("port = \"x\"\npitch-x-um = -1.0").unwrap();
        assert_eq!(s.validate(), Err(SettingsError::Pitch(-1.0)));
        let s: InstrumentSettings =
            toml::from_str("port = \"x\"\nreturn-speed-mm-s = 0.0").unwrap();
        assert_eq!(
            s.validate(),
            Err(SettingsError::Speed("return-speed-mm-s", 0.0))
        );
    }
}
