//! The capability probe at start-up: identity, battery, conditions, parameter count,
//! auto-sleep off, whether the profile read-out answers, and the x pitch and where it comes
//! from. Read-only except for auto-sleep.
//!
//! Layer 2: part of [`super::Sj210Client`].

use super::Sj210Client;
use crate::devices::{Battery, InstrumentIdentity, ProbeReport, ProfileReadout};
use crate::profile::Conditions;
use crate::sj210::error::Sj210Error;
use crate::sj210::ng::NgCode;
use crate::sj210::replies::leading_number;
use crate::sj210::sampling::pitch_from_lambda_s;
use tokio::io::{AsyncRead, AsyncWrite};

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// Capability probe, read-only except for `auto-sleep-off`: identity, battery,
    /// conditions, parameter count, profile read-out capability. Battery and read-out
    /// problems are reported in the result, not as errors.
    pub async fn probe_report(&mut self) -> Result<ProbeReport, Sj210Error> {
        let mut warnings = Vec::new();
        let fw_cmd = self.table.commands.firmware.plain();
        let firmware = self.command(&fw_cmd, true).await?.trim().to_string();
        let drive_cmd = self.table.commands.drive_type.plain();
        let drive = self
            .read_code(drive_cmd, "a 3-digit drive unit code")
            .await?;
        let identity = InstrumentIdentity {
            model: self.table.model.to_string(),
            firmware,
            drive_unit: format!("{drive:03} {}", self.table.drive_meaning(drive)),
        };
        let battery = self.battery().await?;
        match battery {
            Battery::Low => warnings.push(
                "battery below 60 %: connect the AC adapter for an unattended scan".to_string(),
            ),
            Battery::Abnormal => warnings.push(
                "battery abnormal (002): a scan will be refused until this is fixed".to_string(),
            ),
            Battery::Unknown(c) => warnings.push(format!("unknown battery code {c:03}")),
            Battery::Good | Battery::Charging => {}
        }
        let conditions = self.conditions().await?;
        let parameter_count = self.parameter_count().await?;
        let sleep_cmd = self.table.commands.auto_sleep_off.plain();
        match self.command(&sleep_cmd, false).await {
            Ok(_) => {}
            Err(e @ Sj210Error::Device { .. }) => warnings.push(format!(
                "auto-sleep could not be switched off ({e}); switch it off on the instrument for unattended runs"
            )),
            Err(e) => return Err(e),
        }
        let profile_readout = self.probe_profile_readout().await?;
        match self.pitch_um(&conditions) {
            Ok((p, source)) if source != "config" => warnings.push(format!(
                "x pitch {p} um assumed from {source}; set pitch-x-um when the instrument's pitch is known"
            )),
            Ok(_) => {}
            Err(_) => warnings.push("x pitch unknown: set pitch-x-um in [instrument]".to_string()),
        }
        Ok(ProbeReport {
            identity,
            battery,
            conditions,
            parameter_count,
            profile_readout,
            warnings,
        })
    }

    /// The safe read-out probe: the total-count request.
    async fn probe_profile_readout(&mut self) -> Result<ProfileReadout, Sj210Error> {
        let model = self.table.model;
        let Some(total) = self.table.commands.profile_total.clone() else {
            return Ok(ProfileReadout::Unsupported {
                ng_code: None,
                advice: format!(
                    "the {model} command table has no profile read-out command (the SJ-210 manual documents none). Options: use an SJ-310/SJ-410 (the SJ-410 manual documents RDEVA), or set profile-total and profile-block in [instrument.commands] once the right command is known"
                ),
            });
        };
        let cmd = total.plain();
        match self.command(&cmd, false).await {
            Ok(payload) => match leading_number(&payload) {
                Some(points_now) => Ok(ProfileReadout::Supported { points_now }),
                None => Err(Sj210Error::UnexpectedReply {
                    command: cmd,
                    payload,
                    expected: "a point count",
                }),
            },
            // The command is recognised, there is just no trace in memory yet (a fresh
            // instrument): the read-out works, with nothing to read now.
            Err(Sj210Error::Device {
                code: NgCode::NoResults,
                ..
            }) => Ok(ProfileReadout::Supported { points_now: 0 }),
            Err(Sj210Error::Device { code, .. }) if code.is_unsupported() => {
                Ok(ProfileReadout::Unsupported {
                    ng_code: Some(code.code()),
                    advice: format!(
                        "this firmware answered {code} ({}) to the profile total request {cmd:?}, so it cannot export profiles with this command. Options: use an SJ-310/SJ-410 (the SJ-410 manual documents RDEVA), or set profile-total and profile-block in [instrument.commands] once the right command is known",
                        code.meaning()
                    ),
                })
            }
            Err(e) => Err(e),
        }
    }

    /// Pitch in µm and where it came from.
    pub fn pitch_um(&self, c: &Conditions) -> Result<(f64, String), Sj210Error> {
        if let Some(p) = self.opts.pitch_x_um {
            return Ok((p, "config".to_string()));
        }
        let ls = c.lambda_s_um.ok_or(Sj210Error::PitchUnknown)?;
        let p = pitch_from_lambda_s(ls).ok_or(Sj210Error::PitchUnknown)?;
        Ok((p, format!("lambda-s {ls} um")))
    }
}
