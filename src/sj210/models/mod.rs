//! Per-model data of the SJ-210 family: which commands, field widths, baud rates and code
//! tables a model has, merged with the config's overrides.
//!
//! - [`commands`]: the command strings and the `[instrument.commands]` override.
//! - [`codes`]: the status, battery, drive and condition code tables.
//! - [`conditions`]: the `RDCON` record parsers (SJ-210 and SJ-410 layouts).
//!
//! NG codes are not here: they are the same table for every model, in [`super::ng`].
//! Every entry cites its source ([`super::sources`]).
//!
//! Pure (layer 1): depends on [`crate::profile`] and [`super::sources`] only.

pub mod codes;
pub mod commands;
pub mod conditions;

pub use codes::{CodeEntry, ValueEntry};
pub use commands::{CommandOverrides, CommandSpec, Commands};
pub use conditions::ConditionLayout;

use crate::profile::Conditions;
use crate::sj210::sources::{C3, M2_CTL, M2_EVA};
use codes::lookup;
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

/// Everything model-specific the driver needs.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelTable {
    /// Which model.
    pub model: ModelId,
    /// Command strings.
    pub commands: Commands,
    /// Width of the value field in `RDRES…02` replies (7 on the SJ-210, 8 on the SJ-410).
    pub result_value_width: usize,
    /// Whether the results and the profile can be read while the drive returns after a
    /// trace (status `002`), so the read-out overlaps the return. Off in every built-in
    /// table: no manual says, and no instrument was seen doing it
    /// ([`crate::sj210::sources::UNSEEN`]); `reads-during-return = true` in
    /// `[instrument.commands]` turns it on once `surfscan probe --trace --readout` saw it.
    pub reads_during_return: bool,
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

impl ModelTable {
    /// The built-in table of a model.
    pub fn builtin(model: ModelId) -> ModelTable {
        match model {
            ModelId::Sj210 | ModelId::Sj220 | ModelId::Sj310 => ModelTable {
                model,
                commands: commands::sj210_commands(),
                result_value_width: 7,
                reads_during_return: false,
                baud_rates: vec![9600, 19200, 38400],
                condition_layout: ConditionLayout::Sj210,
                status_codes: codes::status_codes(),
                battery_codes: codes::battery_codes(),
                drive_codes: codes::drive_codes(),
                lambda_c_codes: codes::sj210_lambda_c_codes(),
                lambda_s_codes: Vec::new(),
                standard_codes: codes::standard_codes(),
                filter_codes: codes::filter_codes(),
                profile_codes: codes::sj210_profile_codes(),
            },
            ModelId::Sj410 => {
                let mut commands = commands::sj210_commands();
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
                    reads_during_return: false,
                    baud_rates: vec![9600, 19200, 38400, 57600],
                    condition_layout: ConditionLayout::Sj410,
                    status_codes: codes::status_codes(),
                    battery_codes: codes::battery_codes(),
                    drive_codes: codes::drive_codes(),
                    lambda_c_codes: codes::sj410_lambda_c_codes(),
                    lambda_s_codes: codes::sj410_lambda_s_codes(),
                    standard_codes: codes::standard_codes(),
                    filter_codes: codes::filter_codes(),
                    profile_codes: codes::sj410_profile_codes(),
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

    /// Merges a config override: the command strings ([`Commands::apply`]), the result
    /// value width and whether reads are answered during the return.
    pub fn apply(&mut self, o: &CommandOverrides) -> Result<(), ModelError> {
        self.commands.apply(o)?;
        if let Some(r) = o.reads_during_return {
            self.reads_during_return = r;
        }
        if let Some(w) = o.result_value_width {
            if !(1..=20).contains(&w) {
                return Err(ModelError::BadWidth(w));
            }
            self.result_value_width = w;
        }
        Ok(())
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
        conditions::parse_conditions(self, payload)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

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
        // NG codes are one table for every model.
        use crate::sj210::ng::{NgCode, NG_TABLE};
        assert_eq!(NgCode::from_code(101).meaning(), "no calculation results");
        assert!(NG_TABLE.iter().all(|x| !x.source.is_empty()));
        assert!(a
            .status_codes
            .iter()
            .chain(&a.standard_codes)
            .chain(&b.profile_codes)
            .all(|x| !x.source.is_empty()));
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
        assert!(!t.reads_during_return, "off until seen on an instrument");
        assert!(toml::from_str::<CommandOverrides>("statuss = \"X\"").is_err());
        let o: CommandOverrides = toml::from_str("reads-during-return = true").unwrap();
        for model in [ModelId::Sj210, ModelId::Sj410] {
            assert!(!ModelTable::builtin(model).reads_during_return);
            assert!(
                ModelTable::with_overrides(model, &o)
                    .unwrap()
                    .reads_during_return
            );
        }
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
