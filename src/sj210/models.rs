//! Per-model data of the SJ-210 family: command strings, field widths, baud rates and code
//! tables, each entry citing where it was read, plus the config override and the `RDCON`
//! parsers for the SJ-210 and SJ-410 layouts.
//!
//! Sources: M1 = SJ-210 manual 99MBB122A (page 17-xx), M2 = SJ-410 manual 99MBB765A,
//! C2 = the public SJ-220 program (ali2644/bachelor-3d-loop), C3 = the public SJ-410 program
//! (KuoKuanLiang/SM9SurfJudgeC). "inferred" marks what no source states.
//!
//! Pure (layer 1): depends on [`crate::profile`] only.

use crate::profile::{Conditions, FilterKind, ProfileKind};
use serde::{Deserialize, Serialize};
use std::fmt;
use thiserror::Error;

/// The supported instrument models.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ModelId {
    /// Surftest SJ-210.
    #[default]
    Sj210,
    /// Surftest SJ-220 (SJ-210 successor, same grammar per C2).
    Sj220,
    /// Surftest SJ-310.
    Sj310,
    /// Surftest SJ-410.
    Sj410,
}

impl fmt::Display for ModelId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ModelId::Sj210 => "sj210",
            ModelId::Sj220 => "sj220",
            ModelId::Sj310 => "sj310",
            ModelId::Sj410 => "sj410",
        })
    }
}

/// One command string with where it was read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CommandSpec {
    /// Template; `{aa}`, `{bb}` and `{n}` are replaced by two-digit numbers.
    pub template: String,
    /// Source of the string.
    pub source: String,
}

impl CommandSpec {
    fn new(template: &str, source: &str) -> CommandSpec {
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

/// One entry of a code table.
#[derive(Debug, Clone, PartialEq)]
pub struct CodeEntry {
    /// The code.
    pub code: u16,
    /// What it means.
    pub meaning: &'static str,
    /// Where it was read.
    pub source: &'static str,
}

/// One entry of a condition code table with its numeric value.
#[derive(Debug, Clone, PartialEq)]
pub struct ValueEntry {
    /// Digit in the record.
    pub code: u8,
    /// Value (mm for λc, µm for λs).
    pub value: f64,
    /// Where it was read.
    pub source: &'static str,
}

/// Which `RDCON` record layout the model returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConditionLayout {
    /// SJ-210: standard, profile, λc, N (2), arbitrary length (5), motif, filter (M1 p.17-18).
    Sj210,
    /// SJ-410: A/B, standard, profile, filter, λs, λc, W cut-off, N (2), arbitrary length (5)
    /// (M2 p.22 CON write layout; real reply in C3).
    Sj410,
}

/// Everything model-specific the driver needs.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelTable {
    /// Which model.
    pub model: ModelId,
    /// Command strings.
    pub commands: Commands,
    /// Width of the value field in `RDRES…02` replies (7 on the SJ-210, 8 on the SJ-410).
    pub result_value_width: usize,
    /// Baud rates the instrument can be set to.
    pub baud_rates: Vec<u32>,
    /// `RDCON` layout.
    pub condition_layout: ConditionLayout,
    /// `RDSTU00` codes.
    pub status_codes: Vec<CodeEntry>,
    /// `RDSTU01` codes.
    pub battery_codes: Vec<CodeEntry>,
    /// `RDSJ 00` codes.
    pub drive_codes: Vec<CodeEntry>,
    /// NG codes.
    pub error_codes: Vec<CodeEntry>,
    /// λc digit → mm.
    pub lambda_c_codes: Vec<ValueEntry>,
    /// λs digit → µm (empty when the record has no λs field).
    pub lambda_s_codes: Vec<ValueEntry>,
    /// Standard digit → name.
    pub standard_codes: Vec<CodeEntry>,
    /// Filter digit → name.
    pub filter_codes: Vec<CodeEntry>,
    /// Profile digit → name.
    pub profile_codes: Vec<CodeEntry>,
}

const M1_CTL: &str = "M1 p.17-13 (SJ-210 control commands)";
const M1_STU: &str = "M1 p.17-16/17 (SJ-210 STU, SJ_)";
const M1_CON: &str = "M1 p.17-18 (SJ-210 CON, PAR)";
const M1_RES: &str = "M1 p.17-19 (SJ-210 RES)";
const M1_LIST: &str = "M1 p.17-13 command list (detail page not stored)";
const M2_CTL: &str = "M2 p.22 (SJ-410 STP, OFF, ESP)";
const M2_EVA: &str = "M2 p.22 (SJ-410 PSA, EVA)";
const M2_CON: &str = "M2 p.22 (SJ-410 CON write layout)";
const C2: &str = "C2 sj220_exceptions.py (SJ-220 device table)";
const C3: &str = "C3 Main.cs (SJ-410 program)";

fn e(code: u16, meaning: &'static str, source: &'static str) -> CodeEntry {
    CodeEntry {
        code,
        meaning,
        source,
    }
}

fn v(code: u8, value: f64, source: &'static str) -> ValueEntry {
    ValueEntry {
        code,
        value,
        source,
    }
}

fn error_table(model: ModelId) -> Vec<CodeEntry> {
    let mut t = vec![
        e(3, "origin position not reached in time", C2),
        e(4, "retraction position not reached in time", C2),
        e(5, "origin limit remains active", C2),
        e(6, "retraction limit remains active", C2),
        e(7, "detector over-range", C2),
        e(11, "command sent while busy", C2),
        e(12, "control timeout", C2),
        e(13, "communication buffer overflow", C2),
        e(14, "flash erase error", C2),
        e(15, "flash write error", C2),
        e(16, "program error", C2),
        e(17, "system error", C2),
        e(18, "invalid measurement start position", C2),
        e(19, "invalid setting value", C2),
        e(22, "detector disconnected", C2),
        e(30, "illegal command", C2),
        e(31, "invalid command format", C2),
        e(32, "invalid command value", C2),
        e(33, "command still being processed", C2),
        e(71, "SPC communication error", C2),
        e(101, "no calculation results", C2),
        e(102, "result out of range", C2),
        e(103, "measurement interrupted by result over-range", C2),
        e(110, "calculation error: too few peaks/valleys", C2),
        e(111, "calculation error: too few data points", C2),
        e(112, "calculation error: invalid region", C2),
        e(113, "calculation error: no profile element", C2),
        e(114, "calculation error: BAC/ADC", C2),
        e(115, "calculation error: Rk", C2),
        e(116, "calculation error: R-Motif", C2),
        e(117, "calculation error: W-Motif", C2),
        e(118, "calculation error: other", C2),
        e(121, "calculation error", C2),
        e(130, "calculation error", C2),
        e(184, "printer access timeout", C2),
    ];
    if model == ModelId::Sj410 {
        t.push(e(
            20,
            "stylus at the end of travel: return and re-measure",
            C3,
        ));
    }
    t
}

fn sj210_commands() -> Commands {
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

impl ModelTable {
    /// The built-in table of a model.
    pub fn builtin(model: ModelId) -> ModelTable {
        let status_codes = vec![
            e(0, "idle", M1_STU),
            e(1, "measuring", M1_STU),
            e(2, "returning", M1_STU),
            e(3, "retracting", M1_STU),
            e(4, "retracted", M1_STU),
            e(5, "neither at origin nor retracted", M1_STU),
        ];
        let battery_codes = vec![
            e(0, "more than 60 %", M1_STU),
            e(1, "below 60 %", M1_STU),
            e(2, "abnormal (temperature, voltage or no battery)", M1_STU),
            e(3, "charging", M1_STU),
        ];
        let drive_codes = vec![
            e(0, "standard", M1_STU),
            e(1, "transverse tracing", M1_STU),
            e(2, "retracting", M1_STU),
        ];
        let standard_codes = vec![
            e(0, "JIS1982", M1_CON),
            e(1, "JIS1994", M1_CON),
            e(2, "JIS2001", M1_CON),
            e(3, "ISO1997", M1_CON),
            e(4, "ANSI", M1_CON),
            e(5, "VDA", M1_CON),
            e(6, "Free", M1_CON),
        ];
        let filter_codes = vec![
            e(0, "2CR75", M1_CON),
            e(1, "PC75", M1_CON),
            e(2, "GAUSS", M1_CON),
            e(3, "None", M1_CON),
        ];
        match model {
            ModelId::Sj210 | ModelId::Sj220 | ModelId::Sj310 => ModelTable {
                model,
                commands: sj210_commands(),
                result_value_width: 7,
                baud_rates: vec![9600, 19200, 38400],
                condition_layout: ConditionLayout::Sj210,
                status_codes,
                battery_codes,
                drive_codes,
                error_codes: error_table(model),
                lambda_c_codes: vec![
                    v(0, 0.08, M1_CON),
                    v(1, 0.25, M1_CON),
                    v(2, 0.8, M1_CON),
                    v(3, 2.5, M1_CON),
                ],
                lambda_s_codes: Vec::new(),
                standard_codes,
                filter_codes,
                profile_codes: vec![
                    e(0, "P", M1_CON),
                    e(1, "R", M1_CON),
                    e(2, "DF", M1_CON),
                    e(3, "R-Motif", M1_CON),
                ],
            },
            ModelId::Sj410 => {
                let mut commands = sj210_commands();
                commands.abort = CommandSpec::new("CTSTP", M2_CTL);
                commands.auto_sleep_off = CommandSpec::new("CTOFF01", M2_CTL);
                commands.conditions = CommandSpec::new("RDCON0", C3);
                commands.param_count = CommandSpec::new("RDPAR0", C3);
                commands.result = CommandSpec::new("RDRES002,{aa},{bb}", C3);
                commands.profile_total = Some(CommandSpec::new("RDEVA000", M2_EVA));
                commands.profile_block = Some(CommandSpec::new("RDEVA0{n}", M2_EVA));
                ModelTable {
                    model,
                    commands,
                    result_value_width: 8,
                    baud_rates: vec![9600, 19200, 38400, 57600],
                    condition_layout: ConditionLayout::Sj410,
                    status_codes,
                    battery_codes,
                    drive_codes,
                    error_codes: error_table(model),
                    lambda_c_codes: vec![
                        v(0, 0.08, M2_CON),
                        v(1, 0.25, M2_CON),
                        v(2, 0.8, M2_CON),
                        v(3, 2.5, M2_CON),
                        v(4, 8.0, M2_CON),
                        v(5, 25.0, M2_CON),
                    ],
                    lambda_s_codes: vec![v(0, 2.5, M2_CON), v(1, 8.0, M2_CON), v(2, 25.0, M2_CON)],
                    standard_codes,
                    filter_codes,
                    profile_codes: vec![
                        e(0, "P", M2_CON),
                        e(1, "R", M2_CON),
                        e(2, "DF", M2_CON),
                        e(3, "R-Motif", M2_CON),
                        e(4, "W-Motif", M2_CON),
                        e(5, "W", M2_CON),
                    ],
                }
            }
        }
    }

    /// The built-in table with a config override merged over it.
    pub fn with_overrides(model: ModelId, o: &CommandOverrides) -> Result<ModelTable, ModelError> {
        let mut t = ModelTable::builtin(model);
        t.apply(o)?;
        Ok(t)
    }

    /// Merges a config override: every given string replaces the built-in one (source
    /// "config"); an empty `profile-total`/`profile-block` removes the read-out.
    pub fn apply(&mut self, o: &CommandOverrides) -> Result<(), ModelError> {
        let c = &mut self.commands;
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
        if let Some(w) = o.result_value_width {
            if !(1..=20).contains(&w) {
                return Err(ModelError::BadWidth(w));
            }
            self.result_value_width = w;
        }
        Ok(())
    }

    /// Meaning of an NG code, or "unknown error code".
    pub fn error_meaning(&self, code: u16) -> &'static str {
        lookup(&self.error_codes, code).unwrap_or("unknown error code")
    }

    /// Meaning of a status code.
    pub fn status_meaning(&self, code: u16) -> &'static str {
        lookup(&self.status_codes, code).unwrap_or("unknown status")
    }

    /// Meaning of a drive-unit code.
    pub fn drive_meaning(&self, code: u16) -> &'static str {
        lookup(&self.drive_codes, code).unwrap_or("unknown drive unit")
    }

    /// Parses an `RDCON` payload in this model's layout.
    pub fn parse_conditions(&self, payload: &str) -> Result<Conditions, ModelError> {
        parse_conditions(self, payload)
    }
}

fn lookup(t: &[CodeEntry], code: u16) -> Option<&'static str> {
    t.iter().find(|x| x.code == code).map(|x| x.meaning)
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
}

/// A bad model table or `RDCON` record.
#[derive(Debug, Error, PartialEq)]
pub enum ModelError {
    /// A command template is empty, not printable ASCII, or has an unknown placeholder.
    #[error("command template {name} = {template:?} is invalid: it must be printable ASCII and may only use the placeholders {{aa}}, {{bb}}, {{n}}. Fix [instrument.commands] in the config")]
    BadTemplate {
        /// Which command.
        name: &'static str,
        /// The template.
        template: String,
    },
    /// Only one of the two profile read-out commands is set.
    #[error(
        "profile-total and profile-block must both be set (or both empty) in [instrument.commands]"
    )]
    HalfProfileReadout,
    /// Result width out of range.
    #[error("result-value-width {0} is out of range 1..=20")]
    BadWidth(usize),
    /// The `RDCON` payload is too short or holds an unknown code.
    #[error("conditions record {payload:?} cannot be read: {what}. Check the configured model, or record a transcript with `surfscan probe --record` and report it")]
    BadConditions {
        /// The payload.
        payload: String,
        /// What is wrong.
        what: String,
    },
}

fn parse_conditions(t: &ModelTable, payload: &str) -> Result<Conditions, ModelError> {
    let chars: Vec<char> = payload.chars().collect();
    let bad = |what: String| ModelError::BadConditions {
        payload: payload.to_string(),
        what,
    };
    let digit = |i: usize, name: &str| -> Result<u8, ModelError> {
        chars
            .get(i)
            .and_then(|c| c.to_digit(10))
            .map(|d| d as u8)
            .ok_or_else(|| bad(format!("{name} at offset {i} is not a digit")))
    };
    let field = |from: usize, len: usize| -> Option<String> {
        chars.get(from..from + len).map(|s| s.iter().collect())
    };
    let (std_i, prof_i, lc_i, n_i, len_i, filt_i, ls_i) = match t.condition_layout {
        ConditionLayout::Sj210 => (0, 1, 2, 3, 5, Some(11), None),
        ConditionLayout::Sj410 => (1, 2, 5, 7, 9, Some(3), Some(4)),
    };
    let min_len = match t.condition_layout {
        ConditionLayout::Sj210 => 12,
        ConditionLayout::Sj410 => 14,
    };
    if chars.len() < min_len {
        return Err(bad(format!(
            "{} characters, the {:?} layout needs at least {min_len}",
            chars.len(),
            t.condition_layout
        )));
    }
    let std_code = digit(std_i, "standard")?;
    let standard = lookup(&t.standard_codes, u16::from(std_code))
        .ok_or_else(|| bad(format!("unknown standard code {std_code}")))?;
    let prof_code = digit(prof_i, "profile")?;
    let prof_name = lookup(&t.profile_codes, u16::from(prof_code))
        .ok_or_else(|| bad(format!("unknown profile code {prof_code}")))?;
    let profile_kind = match prof_name {
        "P" => ProfileKind::P,
        "R" => ProfileKind::R,
        "W" => ProfileKind::W,
        _ => ProfileKind::Other,
    };
    let lc_code = digit(lc_i, "lambda-c")?;
    let lambda_c_mm = t
        .lambda_c_codes
        .iter()
        .find(|x| x.code == lc_code)
        .map(|x| x.value)
        .ok_or_else(|| bad(format!("unknown lambda-c code {lc_code}")))?;
    let n = u32::from(digit(n_i, "N")?) * 10 + u32::from(digit(n_i + 1, "N")?);
    let arbitrary = field(len_i, 5).unwrap_or_default();
    let evaluation_length_mm = if n == 0 {
        Some(
            arbitrary
                .trim()
                .parse::<f64>()
                .map_err(|_| bad(format!("arbitrary length {arbitrary:?} is not a number")))?,
        )
    } else {
        Some(f64::from(n) * lambda_c_mm)
    };
    let filter = match filt_i {
        Some(i) => {
            let code = digit(i, "filter")?;
            Some(match lookup(&t.filter_codes, u16::from(code)) {
                Some("2CR75") => FilterKind::TwoRc,
                Some("PC75") => FilterKind::Pc75,
                Some("GAUSS") => FilterKind::Gaussian,
                Some("None") => FilterKind::None,
                _ => return Err(bad(format!("unknown filter code {code}"))),
            })
        }
        None => None,
    };
    let lambda_s_um = match ls_i {
        Some(i) => {
            let code = digit(i, "lambda-s")?;
            // Code 3 is "none" on the SJ-410 (M2); other unknown codes are errors.
            match t.lambda_s_codes.iter().find(|x| x.code == code) {
                Some(x) => Some(x.value),
                None if code == 3 => None,
                None => return Err(bad(format!("unknown lambda-s code {code}"))),
            }
        }
        // SJ-210: "λs is set according to λc" (M1); ISO 3274 pairs 2.5 µm with λc ≤ 0.8 mm
        // and 8 µm with λc 2.5 mm (inferred).
        None if lambda_c_mm <= 0.8 + 1e-9 => Some(2.5),
        None => Some(8.0),
    };
    Ok(Conditions {
        standard: Some(standard.to_string()),
        profile_kind: Some(profile_kind),
        filter,
        lambda_c_mm: Some(lambda_c_mm),
        lambda_s_um,
        sampling_lengths: Some(n),
        evaluation_length_mm,
        speed_mm_s: None,
        raw: Some(payload.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sj210_conditions_iso_r_08_x5_gauss() {
        // standard 3 ISO1997, profile 1 R, λc 2 = 0.8, N 05, length field, motif 1, filter 2.
        let t = ModelTable::builtin(ModelId::Sj210);
        let c = t.parse_conditions("3120504.0012").unwrap();
        assert_eq!(c.standard.as_deref(), Some("ISO1997"));
        assert_eq!(c.profile_kind, Some(ProfileKind::R));
        assert_eq!(c.lambda_c_mm, Some(0.8));
        assert_eq!(c.lambda_s_um, Some(2.5));
        assert_eq!(c.sampling_lengths, Some(5));
        assert!((c.evaluation_length_mm.unwrap() - 4.0).abs() < 1e-12);
        assert_eq!(c.filter, Some(FilterKind::Gaussian));
    }

    #[test]
    fn sj210_arbitrary_length_and_lambda_s_8() {
        let t = ModelTable::builtin(ModelId::Sj210);
        let c = t.parse_conditions("3030012.5010").unwrap();
        assert_eq!(c.sampling_lengths, Some(0));
        assert_eq!(c.evaluation_length_mm, Some(12.5));
        assert_eq!(c.lambda_c_mm, Some(2.5));
        assert_eq!(c.lambda_s_um, Some(8.0));
        assert_eq!(c.profile_kind, Some(ProfileKind::P));
        assert_eq!(c.filter, Some(FilterKind::TwoRc));
    }

    #[test]
    fn sj410_conditions_from_c3_example() {
        // C3's real reply: 0 3 0 2 2 3 2 05 0.500 2 2 0.003 0.019
        let t = ModelTable::builtin(ModelId::Sj410);
        let c = t.parse_conditions("0302232050.500220.0030.019").unwrap();
        assert_eq!(c.standard.as_deref(), Some("ISO1997"));
        assert_eq!(c.profile_kind, Some(ProfileKind::P));
        assert_eq!(c.filter, Some(FilterKind::Gaussian));
        assert_eq!(c.lambda_s_um, Some(25.0));
        assert_eq!(c.lambda_c_mm, Some(2.5));
        assert_eq!(c.sampling_lengths, Some(5));
        assert!((c.evaluation_length_mm.unwrap() - 12.5).abs() < 1e-12);
    }

    #[test]
    fn short_or_bad_conditions_are_named_errors() {
        let t = ModelTable::builtin(ModelId::Sj210);
        assert!(matches!(
            t.parse_conditions("3120"),
            Err(ModelError::BadConditions { .. })
        ));
        assert!(matches!(
            t.parse_conditions("3190504.0012"),
            Err(ModelError::BadConditions { what, .. }) if what.contains("lambda-c code 9")
        ));
    }

    #[test]
    fn tables_differ_where_the_manuals_do() {
        let a = ModelTable::builtin(ModelId::Sj210);
        let b = ModelTable::builtin(ModelId::Sj410);
        assert_eq!(a.result_value_width, 7);
        assert_eq!(b.result_value_width, 8);
        assert!(!a.baud_rates.contains(&57600));
        assert!(b.baud_rates.contains(&57600));
        assert!(a.commands.profile_total.is_none());
        assert_eq!(
            b.commands.profile_block.as_ref().unwrap().render(0, 0, 50),
            "RDEVA050"
        );
        assert_eq!(a.commands.result.render(3, 0, 0), "RDRES02,03,00");
        assert_eq!(a.error_meaning(101), "no calculation results");
        assert!(a.error_codes.iter().all(|x| !x.source.is_empty()));
    }

    #[test]
    fn override_from_toml_merges_and_enables_readout() {
        let o: CommandOverrides = toml::from_str(
            "profile-total = \"RDEVA00\"\nprofile-block = \"RDEVA{n}\"\nreturn = \"CTRTN\"\n",
        )
        .unwrap();
        let t = ModelTable::with_overrides(ModelId::Sj210, &o).unwrap();
        assert_eq!(
            t.commands.profile_total.as_ref().unwrap().template,
            "RDEVA00"
        );
        assert_eq!(t.commands.profile_block.as_ref().unwrap().source, "config");
        assert_eq!(t.commands.status.template, "RDSTU00");
        assert!(toml::from_str::<CommandOverrides>("statuss = \"X\"").is_err());
    }

    #[test]
    fn bad_override_is_refused() {
        let o = CommandOverrides {
            result: Some("RDRES02,{a},{bb}".into()),
            ..Default::default()
        };
        assert!(matches!(
            ModelTable::with_overrides(ModelId::Sj210, &o),
            Err(ModelError::BadTemplate { name: "result", .. })
        ));
        let half = CommandOverrides {
            profile_total: Some("RDEVA00".into()),
            ..Default::default()
        };
        assert_eq!(
            ModelTable::with_overrides(ModelId::Sj210, &half),
            Err(ModelError::HalfProfileReadout)
        );
    }
}
