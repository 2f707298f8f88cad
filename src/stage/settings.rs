//! The `[stage]` settings (TOML, kebab-case) and their validation into driver and policy
//! configurations.
//!
//! Pure: depends on [`crate::transport`] (link settings types), [`crate::units`], and the
//! configuration types of the policy and the drivers (which import nothing from here).

use super::grbl::GrblConfig;
use super::policy::{PolicyConfig, ScanDirection};
use super::zaber::ZaberConfig;
use super::StageError;
use crate::transport::{FlowControl, Parity, SerialSettings};
use crate::units::Nm;
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// Which controller protocol the stage speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StageProtocol {
    /// GRBL 1.1 or grblHAL.
    Grbl,
    /// Zaber ASCII.
    Zaber,
}

fn d_baud() -> u32 {
    115_200
}
fn d_one() -> u8 {
    1
}
fn d_settle() -> u64 {
    200
}
fn d_deadband() -> f64 {
    1.0
}
fn d_attempts() -> u32 {
    3
}
fn d_feed() -> f64 {
    60.0
}
fn d_poll() -> u64 {
    250
}

/// The `[stage]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct StageSettings {
    /// Serial device path (prefer `/dev/serial/by-id/…`).
    pub port: String,
    /// `grbl` or `zaber`.
    pub protocol: StageProtocol,
    /// Baud rate (115200 by default).
    #[serde(default = "d_baud")]
    pub baud: u32,
    /// Parity.
    #[serde(default)]
    pub parity: Parity,
    /// Flow control.
    #[serde(default)]
    pub flow_control: FlowControl,
    /// GRBL: steps per mm of the Y axis (`$101`).
    #[serde(default)]
    pub steps_per_mm: Option<f64>,
    /// Zaber: millimetres per microstep.
    #[serde(default)]
    pub mm_per_microstep: Option<f64>,
    /// Zaber: nanometres per microstep (alternative to `mm-per-microstep`).
    #[serde(default)]
    pub nm_per_microstep: Option<f64>,
    /// Zaber device address.
    #[serde(default = "d_one")]
    pub device: u8,
    /// Zaber axis number.
    #[serde(default = "d_one")]
    pub axis: u8,
    /// Lowest allowed target, mm (machine coordinates).
    pub soft_limit_min_mm: f64,
    /// Highest allowed target, mm (machine coordinates).
    pub soft_limit_max_mm: f64,
    /// Backlash take-out distance, mm (0 disables the pre-approach).
    #[serde(default)]
    pub backlash_mm: f64,
    /// Settle time after a move, ms.
    #[serde(default = "d_settle")]
    pub settle_ms: u64,
    /// Retry deadband, µm.
    #[serde(default = "d_deadband")]
    pub deadband_um: f64,
    /// Moves issued per target before "missed target".
    #[serde(default = "d_attempts")]
    pub max_move_attempts: u32,
    /// GRBL jog feed rate, mm/min.
    #[serde(default = "d_feed")]
    pub feed_mm_min: f64,
    /// Status poll interval, ms (≥ 200 for GRBL, which asks for at most 5 Hz).
    #[serde(default = "d_poll")]
    pub poll_interval_ms: u64,
    /// Home when the scan starts.
    #[serde(default)]
    pub home_on_start: bool,
    /// Accept targets that are not a whole number of device units (recorded as a warning).
    #[serde(default)]
    pub allow_inexact_step: bool,
}

fn cfg_err(s: String) -> StageError {
    StageError::Config(s)
}

impl StageSettings {
    /// The serial link settings.
    pub fn serial(&self) -> SerialSettings {
        SerialSettings {
            path: self.port.clone(),
            baud: self.baud,
            parity: self.parity,
            flow_control: self.flow_control,
        }
    }

    /// Size of one device unit (GRBL step, Zaber microstep) in nm.
    pub fn nm_per_unit(&self) -> Result<f64, StageError> {
        let v = match self.protocol {
            StageProtocol::Grbl => {
                let spm = self.steps_per_mm.ok_or_else(|| {
                    cfg_err("protocol \"grbl\" needs steps-per-mm (the controller's $101)".into())
                })?;
                if !(spm.is_finite() && spm > 0.0) {
                    return Err(cfg_err(format!("steps-per-mm must be positive, got {spm}")));
                }
                Nm::PER_MM as f64 / spm
            }
            StageProtocol::Zaber => match (self.mm_per_microstep, self.nm_per_microstep) {
                (Some(mm), None) => mm * Nm::PER_MM as f64,
                (None, Some(nm)) => nm,
                _ => return Err(cfg_err(
                    "protocol \"zaber\" needs exactly one of mm-per-microstep or nm-per-microstep"
                        .into(),
                )),
            },
        };
        if !(v.is_finite() && v > 0.0) {
            return Err(cfg_err(format!(
                "the device unit must be a positive length, got {v} nm"
            )));
        }
        Ok(v)
    }

    fn mm_to_nm(name: &str, mm: f64) -> Result<Nm, StageError> {
        Nm::try_from_mm(mm)
            .ok_or_else(|| cfg_err(format!("{name} = {mm} is not a whole number of nanometres")))
    }

    /// The motion policy's configuration.
    pub fn policy_config(&self) -> Result<PolicyConfig, StageError> {
        let min = Self::mm_to_nm("soft-limit-min-mm", self.soft_limit_min_mm)?;
        let max = Self::mm_to_nm("soft-limit-max-mm", self.soft_limit_max_mm)?;
        if min >= max {
            return Err(cfg_err(format!(
                "soft-limit-min-mm ({}) must be below soft-limit-max-mm ({})",
                self.soft_limit_min_mm, self.soft_limit_max_mm
            )));
        }
        let backlash = Self::mm_to_nm("backlash-mm", self.backlash_mm)?;
        if backlash.0 < 0 {
            return Err(cfg_err(format!(
                "backlash-mm must not be negative, got {}",
                self.backlash_mm
            )));
        }
        if !(self.deadband_um.is_finite() && self.deadband_um >= 0.0) {
            return Err(cfg_err(format!(
                "deadband-um must be ≥ 0, got {}",
                self.deadband_um
            )));
        }
        if self.max_move_attempts == 0 {
            return Err(cfg_err("max-move-attempts must be at least 1".into()));
        }
        if !(self.feed_mm_min.is_finite() && self.feed_mm_min > 0.0) {
            return Err(cfg_err(format!(
                "feed-mm-min must be positive, got {}",
                self.feed_mm_min
            )));
        }
        let travel_mm = (max.0 - min.0) as f64 / Nm::PER_MM as f64;
        let move_timeout =
            Duration::from_secs_f64(travel_mm / self.feed_mm_min * 60.0 * 2.0 + 10.0);
        Ok(PolicyConfig {
            nm_per_unit: self.nm_per_unit()?,
            min,
            max,
            backlash,
            settle: Duration::from_millis(self.settle_ms),
            deadband: Nm((self.deadband_um * 1000.0).round() as i64),
            max_attempts: self.max_move_attempts,
            move_timeout,
            home_timeout: move_timeout + Duration::from_secs(60),
            allow_inexact_step: self.allow_inexact_step,
            direction: ScanDirection::Positive,
        })
    }

    /// Checks every setting the policy and the selected driver use, before a port is
    /// opened.
    pub fn validate(&self) -> Result<(), StageError> {
        self.policy_config()?;
        match self.protocol {
            StageProtocol::Grbl => self.grbl_config().map(|_| ()),
            StageProtocol::Zaber => Ok(()),
        }
    }

    /// The GRBL driver's configuration.
    pub fn grbl_config(&self) -> Result<GrblConfig, StageError> {
        if self.poll_interval_ms < 200 {
            return Err(cfg_err(format!(
                "poll-interval-ms = {} polls GRBL faster than 5 Hz; use 200 or more",
                self.poll_interval_ms
            )));
        }
        Ok(GrblConfig {
            steps_per_mm: Nm::PER_MM as f64 / self.nm_per_unit()?,
            feed_mm_min: self.feed_mm_min,
            poll_interval: Duration::from_millis(self.poll_interval_ms),
            reply_timeout: Duration::from_secs(2),
            open_grace: Duration::from_millis(2500),
        })
    }

    /// The Zaber driver's configuration.
    pub fn zaber_config(&self) -> ZaberConfig {
        ZaberConfig {
            device: self.device,
            axis: self.axis,
            poll_interval: Duration::from_millis(self.poll_interval_ms),
            reply_timeout: Duration::from_secs(2),
            message_ids: false,
            checksums: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GRBL: &str = r#"
port = "/dev/ttyUSB0"
protocol = "grbl"
steps-per-mm = 400
soft-limit-min-mm = -50
soft-limit-max-mm = 0
backlash-mm = 0.05
"#;

    #[test]
    fn kebab_case_with_defaults() {
        let s: StageSettings = toml::from_str(GRBL).unwrap();
        assert_eq!(s.baud, 115_200);
        let p = s.policy_config().unwrap();
        assert_eq!(p.nm_per_unit, 2500.0);
        assert_eq!(p.min, Nm(-50_000_000));
        assert_eq!(p.backlash, Nm(50_000));
        assert_eq!(p.deadband, Nm(1000));
    }

    #[test]
    fn unknown_fields_and_missing_scale_are_refused() {
        assert!(toml::from_str::<StageSettings>(&format!("{GRBL}\nbacklash = 1")).is_err());
        let s: StageSettings =
            toml::from_str(&GRBL.replace("protocol = \"grbl\"", "protocol = \"zaber\"")).unwrap();
        assert!(matches!(s.policy_config(), Err(StageError::Config(m)) if m.contains("microstep")));
    }
}
