//! The command strings of one model ([`Commands`]), each with where it was read, and the
//! `[instrument.commands]` override that replaces any of them from the config.
//!
//! Pure (layer 1): depends on [`crate::sj210::sources`] and [`super::ModelError`].

use super::ModelError;
use crate::sj210::sources::{M1_CON, M1_CTL, M1_LIST, M1_RES, M1_STU};
use serde::{Deserialize, Serialize};

/// One command string with where it was read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CommandSpec {
    /// Template; `{aa}`, `{bb}` and `{n}` are replaced by two-digit numbers.
    pub template: String,
    /// Source of the string.
    pub source: String,
}

impl CommandSpec {
    pub(super) fn new(template: &str, source: &str) -> CommandSpec {
        CommandSpec {
            template: template.to_string(),
            source: source.to_string(),
        }
    }

    /// The command with placeholders filled (`{aa}`, `{bb}`, `{n}` as two digits).
    pub fn render(&self, aa: u32, bb: u32, n: u32) -> String {
        self.template
            .replace("{aa}", &format!("{aa:02}"))
            .replace("{bb}", &format!("{bb:02}"))
            .replace("{n}", &format!("{n:02}"))
    }

    /// The command without placeholders.
    pub fn plain(&self) -> String {
        self.render(0, 0, 0)
    }
}

/// The command strings of one model.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Commands {
    /// Start a measurement.
    pub start: CommandSpec,
    /// Abort a running measurement (same as start on the SJ-210: only after status 001).
    pub abort: CommandSpec,
    /// Operating status.
    pub status: CommandSpec,
    /// Battery status.
    pub battery: CommandSpec,
    /// Firmware version.
    pub firmware: CommandSpec,
    /// Drive unit type.
    pub drive_type: CommandSpec,
    /// Measurement conditions.
    pub conditions: CommandSpec,
    /// Number of customised parameters.
    pub param_count: CommandSpec,
    /// One result: `{aa}` parameter number, `{bb}` value index.
    pub result: CommandSpec,
    /// Detector position.
    pub position: CommandSpec,
    /// Prohibit auto-sleep.
    pub auto_sleep_off: CommandSpec,
    /// Return the detector to the start position.
    pub return_to_start: CommandSpec,
    /// Retract the detector.
    pub retract: CommandSpec,
    /// Profile read-out: total number of points (absent when the model has none).
    pub profile_total: Option<CommandSpec>,
    /// Profile read-out: next block of `{n}` points.
    pub profile_block: Option<CommandSpec>,
}

/// The SJ-210 manual's command strings (the SJ-220 and SJ-310 use the same grammar).
pub(super) fn sj210_commands() -> Commands {
    let c = |t: &str, s: &str| CommandSpec::new(t, s);
    Commands {
        start: c("CTSTA", M1_CTL),
        abort: c("CTSTA", M1_CTL),
        status: c("RDSTU00", M1_STU),
        battery: c("RDSTU01", M1_STU),
        firmware: c("RDSJ 01", M1_STU),
        drive_type: c("RDSJ 00", M1_STU),
        conditions: c("RDCON", M1_CON),
        param_count: c("RDPAR", M1_CON),
        result: c("RDRES02,{aa},{bb}", M1_RES),
        position: c("RDPSA", M1_LIST),
        auto_sleep_off: c(
            "CTOFF01",
            "M1 p.17-13 (OFF 00-02); code 01 as on SJ-410 M2 (inferred)",
        ),
        return_to_start: c("CTRTN", M1_LIST),
        retract: c("CTESP", M1_LIST),
        profile_total: None,
        profile_block: None,
    }
}

impl Commands {
    /// Merges a config override: every given string replaces the built-in one (source
    /// "config"); an empty `profile-total`/`profile-block` removes the read-out.
    pub fn apply(&mut self, o: &CommandOverrides) -> Result<(), ModelError> {
        let c = self;
        let set = |slot: &mut CommandSpec, name: &'static str, val: &Option<String>| {
            if let Some(t) = val {
                check_template(name, t)?;
                *slot = CommandSpec::new(t, "config");
            }
            Ok::<(), ModelError>(())
        };
        set(&mut c.start, "start", &o.start)?;
        set(&mut c.abort, "abort", &o.abort)?;
        set(&mut c.status, "status", &o.status)?;
        set(&mut c.battery, "battery", &o.battery)?;
        set(&mut c.firmware, "firmware", &o.firmware)?;
        set(&mut c.drive_type, "drive-type", &o.drive_type)?;
        set(&mut c.conditions, "conditions", &o.conditions)?;
        set(&mut c.param_count, "param-count", &o.param_count)?;
        set(&mut c.result, "result", &o.result)?;
        set(&mut c.position, "position", &o.position)?;
        set(&mut c.auto_sleep_off, "auto-sleep-off", &o.auto_sleep_off)?;
        set(&mut c.return_to_start, "return", &o.return_to_start)?;
        set(&mut c.retract, "retract", &o.retract)?;
        let opt = |slot: &mut Option<CommandSpec>, name: &'static str, val: &Option<String>| {
            match val.as_deref() {
                None => {}
                Some("") => *slot = None,
                Some(t) => {
                    check_template(name, t)?;
                    *slot = Some(CommandSpec::new(t, "config"));
                }
            }
            Ok::<(), ModelError>(())
        };
        opt(&mut c.profile_total, "profile-total", &o.profile_total)?;
        opt(&mut c.profile_block, "profile-block", &o.profile_block)?;
        if c.profile_total.is_some() != c.profile_block.is_some() {
            return Err(ModelError::HalfProfileReadout);
        }
        Ok(())
    }
}

fn check_template(name: &'static str, t: &str) -> Result<(), ModelError> {
    if t.is_empty() || !t.bytes().all(|b| (0x20..=0x7E).contains(&b)) {
        return Err(ModelError::BadTemplate {
            name,
            template: t.to_string(),
        });
    }
    let stripped = t.replace("{aa}", "").replace("{bb}", "").replace("{n}", "");
    if stripped.contains('{') || stripped.contains('}') {
        return Err(ModelError::BadTemplate {
            name,
            template: t.to_string(),
        });
    }
    Ok(())
}

/// Config override of the command table (`[instrument.commands]`); every field optional.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct CommandOverrides {
    /// Start command.
    pub start: Option<String>,
    /// Abort command.
    pub abort: Option<String>,
    /// Status command.
    pub status: Option<String>,
    /// Battery command.
    pub battery: Option<String>,
    /// Firmware command.
    pub firmware: Option<String>,
    /// Drive type command.
    pub drive_type: Option<String>,
    /// Conditions command.
    pub conditions: Option<String>,
    /// Parameter count command.
    pub param_count: Option<String>,
    /// Result template (`{aa}`, `{bb}`).
    pub result: Option<String>,
    /// Position command.
    pub position: Option<String>,
    /// Auto-sleep-off command.
    pub auto_sleep_off: Option<String>,
    /// Return-to-start command.
    #[serde(rename = "return")]
    pub return_to_start: Option<String>,
    /// Retract command.
    pub retract: Option<String>,
    /// Profile total command; empty string removes the read-out.
    pub profile_total: Option<String>,
    /// Profile block template (`{n}`); empty string removes the read-out.
    pub profile_block: Option<String>,
    /// Width of the result value field.
    pub result_value_width: Option<usize>,
    /// Read the results and the profile while the drive returns (only once seen answered on
    /// this instrument by `surfscan probe --trace --readout`).
    pub reads_during_return: Option<bool>,
}
