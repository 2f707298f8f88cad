//! Recipes: named plans for a part type, one `NAME.toml` each in the directory of the
//! station's `[jobs] recipes` key, read at each start (no restart to measure another part).
//!
//! ```toml
//! description = "Brass coupon, turned face"   # optional, for people
//!
//! [plan]                 # required
//! lines = 31
//! y-start-mm = 1.0       # optional: --y-start-mm, else the station's [scan] y-start-mm
//! y-step-mm = 0.01
//!
//! [conditions]           # optional: what the instrument must be set to (refused otherwise)
//! lambda-c-mm = 0.8
//! lambda-s-um = 2.5
//! sampling-lengths = 5
//! speed-mm-s = 0.5
//!
//! [analysis]             # optional: keys of the station's [analysis] this part overrides
//! outliers = "exclude"
//!
//! [contact]              # optional: keys of the station's [contact] this part overrides
//! enabled = true
//! young-gpa = 100.0
//!
//! [specification]        # optional: the drawing's limits (see crate::specification)
//! limits = ["Ra 0.8", "Rz max 6.3"]
//!
//! [queue]                # optional
//! stop-on-failure = false  # a job of this recipe that fails stops the queue (default false)
//! ```
//!
//! A recipe is validated with the station's configuration it will run under: its plan and
//! analysis replace the station's `[scan]` lines and y, `[analysis]` and `[contact]` in a copy of the
//! configuration, which is validated as a whole (the same ranges, soft limits and messages
//! as the station file, the keys named as the recipe writes them); its limits are parsed and
//! checked against each other and against its stated conditions. A job freezes the recipe's
//! text (and its SHA-256) when it is queued or started, and runs that text, not the file.
//!
//! Layer 4 (process edge): depends on [`crate::config`], [`crate::specification`] and the
//! scan's [`ExpectedConditions`]; reads the recipe files.

use crate::config::{Config, ConfigError};
use crate::scan::expected::ExpectedConditions;
use crate::specification::callout::DEFAULT_SAMPLING_LENGTHS;
use crate::specification::Specification;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A recipe file as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct RecipeFile {
    /// What the recipe is for.
    #[serde(default)]
    pub description: Option<String>,
    /// `[plan]`: the lines.
    pub plan: RecipePlan,
    /// `[conditions]`: the measuring conditions the instrument must be set to.
    #[serde(default)]
    pub conditions: ExpectedConditions,
    /// `[analysis]`: keys of the station's `[analysis]` overridden for this part.
    #[serde(default)]
    pub analysis: toml::Table,
    /// `[contact]`: keys of the station's `[contact]` overridden for this part.
    #[serde(default)]
    pub contact: toml::Table,
    /// `[specification]`: the limits.
    #[serde(default)]
    pub specification: SpecificationTable,
    /// `[queue]`: what a failed job of this recipe does to the queue.
    #[serde(default)]
    pub queue: QueuePolicy,
}

/// `[plan]` of a recipe.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct RecipePlan {
    /// Number of lines.
    pub lines: u32,
    /// y of the first line, mm; `None`: `--y-start-mm`, else the station's.
    #[serde(default)]
    pub y_start_mm: Option<f64>,
    /// y step between lines, mm.
    pub y_step_mm: f64,
}

/// `[specification]` of a recipe.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct SpecificationTable {
    /// The limits as callouts (`"Ra 0.8"`).
    #[serde(default)]
    pub limits: Vec<String>,
}

/// `[queue]` of a recipe.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct QueuePolicy {
    /// A failed job of this recipe stops the queue: the jobs after it wait until
    /// `surfscan queue continue`. Default false: the next job runs.
    #[serde(default)]
    pub stop_on_failure: bool,
}

/// A recipe that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum RecipeError {
    /// The name is not a recipe in the directory (a usage error).
    #[error("no recipe {name:?} in {dir}: {}", available_text(.available))]
    Unknown {
        /// The name asked for.
        name: String,
        /// The recipe directory.
        dir: PathBuf,
        /// The names there.
        available: Vec<String>,
    },
    /// The name cannot name a file of the directory (a usage error).
    #[error("{name:?} is not a recipe name: a name is letters, digits, '.', '-' and '_', not starting with '.' (the file NAME.toml in the recipe directory)")]
    BadName {
        /// The name asked for.
        name: String,
    },
    /// The recipe file cannot be read.
    #[error("cannot read recipe {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A key is missing, unknown, of the wrong type, out of range or inconsistent.
    #[error("recipe {path}: {key}{sep}{message}", sep = if .key.is_empty() { "" } else { ": " })]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The key as the recipe writes it (`plan.lines`, `specification.limits`); empty
        /// when the parser names it in the message.
        key: String,
        /// What is wrong and what is accepted.
        message: String,
    },
    /// A value given on the command line for this recipe is out of range (a usage error).
    #[error("{flag}: {message}")]
    Flag {
        /// The flag.
        flag: &'static str,
        /// What is wrong.
        message: String,
    },
}

impl RecipeError {
    /// Whether the error is in what the operator typed (exit 2) rather than in a file (78).
    pub fn is_usage(&self) -> bool {
        matches!(
            self,
            RecipeError::Unknown { .. } | RecipeError::BadName { .. } | RecipeError::Flag { .. }
        )
    }
}

fn available_text(names: &[String]) -> String {
    if names.is_empty() {
        "the directory holds no recipe (NAME.toml); write one, see the operator guide".to_owned()
    } else {
        format!("the recipes there are {}", names.join(", "))
    }
}

/// A recipe read and validated against a station configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Recipe {
    /// Its name (the file name without `.toml`).
    pub name: String,
    /// Where it was read from (for messages; a frozen recipe keeps the path it was read from).
    pub path: PathBuf,
    /// Its text as read: what a job freezes.
    pub text: String,
    /// SHA-256 of the text, hex.
    pub sha256: String,
    /// The file's values.
    pub file: RecipeFile,
    /// The parsed limits.
    pub specification: Specification,
}

/// Whether `name` can name a recipe file: no path separators, no leading dot.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 128
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_'))
}

/// The recipe names in `dir` (files `NAME.toml` with a valid name), sorted; an absent
/// directory holds none.
pub fn names(dir: &Path) -> std::io::Result<Vec<String>> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let mut out = Vec::new();
    for entry in entries {
        let entry = entry?;
        let file = entry.file_name();
        let Some(name) = file.to_str().and_then(|f| f.strip_suffix(".toml")) else {
            continue;
        };
        if valid_name(name) && entry.path().is_file() {
            out.push(name.to_owned());
        }
    }
    out.sort();
    Ok(out)
}

/// A numeric key of a recipe's `[conditions]` with its range (the station's keys are checked
/// in the station's configuration the recipe is validated with).
struct ConditionKey {
    key: &'static str,
    min: f64,
    max: f64,
    unit: &'static str,
    hint: &'static str,
    get: fn(&ExpectedConditions) -> Option<f64>,
}

macro_rules! condition_key {
    ($key:literal, $min:expr, $max:expr, $unit:literal, $hint:literal, |$c:ident| $get:expr) => {
        ConditionKey {
            key: $key,
            min: $min,
            max: $max,
            unit: $unit,
            hint: $hint,
            get: |$c| $get,
        }
    };
}

#[rustfmt::skip]
const CONDITION_KEYS: [ConditionKey; 4] = [
    condition_key!("conditions.lambda-c-mm", 0.001, 100.0, "mm", "the ISO cut-offs are 0.08, 0.25, 0.8, 2.5 and 8 mm", |c| c.lambda_c_mm),
    condition_key!("conditions.lambda-s-um", 0.1, 1000.0, "µm", "the ISO λs are 2.5, 8 and 25 µm", |c| c.lambda_s_um),
    condition_key!("conditions.sampling-lengths", 1.0, 50.0, "", "the SJ-210 evaluates 1 to 5 sampling lengths (5 by default)", |c| c.sampling_lengths.map(f64::from)),
    condition_key!("conditions.speed-mm-s", 0.01, 10.0, "mm/s", "the SJ-210 traces at 0.25, 0.5 or 0.75 mm/s", |c| c.speed_mm_s),
];

/// A station key as the recipe writes it: its plan is `[plan]`.
fn recipe_key(station_key: &str) -> Option<String> {
    match station_key {
        "scan" => Some("plan".to_owned()),
        "scan.lines" | "scan.y-start-mm" | "scan.y-step-mm" => {
            Some(station_key.replacen("scan.", "plan.", 1))
        }
        k if k.starts_with("analysis.") || k.starts_with("contact.") => Some(k.to_owned()),
        _ => None,
    }
}

impl Recipe {
    /// Reads recipe `name` from `dir` and validates it against `station`.
    pub fn load(dir: &Path, name: &str, station: &Config) -> Result<Recipe, RecipeError> {
        if !valid_name(name) {
            return Err(RecipeError::BadName {
                name: name.to_owned(),
            });
        }
        let path = dir.join(format!("{name}.toml"));
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(RecipeError::Unknown {
                    name: name.to_owned(),
                    dir: dir.to_path_buf(),
                    available: names(dir).unwrap_or_default(),
                })
            }
            Err(source) => return Err(RecipeError::Read { path, source }),
        };
        Recipe::from_text(name, &path, &text, station)
    }

    /// Parses and validates recipe text (a file's, or a job's frozen copy) against `station`.
    pub fn from_text(
        name: &str,
        path: &Path,
        text: &str,
        station: &Config,
    ) -> Result<Recipe, RecipeError> {
        let recipe = Recipe::parse(name, path, text)?;
        recipe.config_for(station, None)?;
        Ok(recipe)
    }

    /// Parses recipe text and checks what it says by itself (its keys and ranges, its
    /// limits against each other and against its `[conditions]`), without a station: what
    /// `analyze --recipe` needs to judge lines measured elsewhere. [`Recipe::from_text`] also
    /// checks the plan against a station.
    pub fn parse(name: &str, path: &Path, text: &str) -> Result<Recipe, RecipeError> {
        let invalid = |key: &str, message: String| RecipeError::Invalid {
            path: path.to_path_buf(),
            key: key.to_owned(),
            message,
        };
        let file: RecipeFile =
            toml::from_str(text).map_err(|e| invalid("", e.to_string().trim_end().to_owned()))?;
        for k in &CONDITION_KEYS {
            let Some(v) = (k.get)(&file.conditions) else {
                continue;
            };
            // Written so that NaN is outside too.
            if !(v >= k.min && v <= k.max) {
                let u = if k.unit.is_empty() {
                    String::new()
                } else {
                    format!(" {}", k.unit)
                };
                return Err(invalid(
                    k.key,
                    format!(
                        "{v}{u} is outside its valid range {} to {}{u}; {}",
                        k.min, k.max, k.hint
                    ),
                ));
            }
        }
        let specification = Specification::parse(&file.specification.limits)
            .map_err(|e| invalid("specification.limits", e.to_string()))?;
        for (i, c) in specification.limits.iter().enumerate() {
            let conflict = conflicts_with_conditions(c, &file.conditions);
            if let Some(why) = conflict {
                return Err(invalid(
                    "specification.limits",
                    format!("limits[{i}] {:?} {why}: no scan of this recipe could decide it; correct the limit or [conditions]", c.text),
                ));
            }
        }
        Ok(Recipe {
            name: name.to_owned(),
            path: path.to_path_buf(),
            text: text.to_owned(),
            sha256: crate::scan::store::hex_sha256(text.as_bytes()),
            file,
            specification,
        })
    }

    /// The station's configuration with this recipe's plan (y of the first line from
    /// `y_start_mm`, else the recipe's, else the station's) and analysis, validated as a
    /// whole. Errors name the recipe's keys (or the flag for `y_start_mm`).
    pub fn config_for(
        &self,
        station: &Config,
        y_start_mm: Option<f64>,
    ) -> Result<Config, RecipeError> {
        let mut c = station.clone();
        c.scan.lines = self.file.plan.lines;
        c.scan.y_step_mm = self.file.plan.y_step_mm;
        c.scan.y_start_mm = y_start_mm
            .or(self.file.plan.y_start_mm)
            .unwrap_or(station.scan.y_start_mm);
        let invalid = |key: &str| {
            let path = self.path.clone();
            let key = key.to_owned();
            move |message: String| RecipeError::Invalid { path, key, message }
        };
        c.analysis =
            overlay(&station.analysis, &self.file.analysis).map_err(invalid("analysis"))?;
        c.contact = overlay(&station.contact, &self.file.contact).map_err(invalid("contact"))?;
        match c.validate(&self.path) {
            Ok(()) => Ok(c),
            Err(ConfigError::Invalid { key, message, .. }) => {
                let from_flag = y_start_mm.is_some()
                    && (key == "scan.y-start-mm"
                        || (key == "scan" && message.contains("soft limits")));
                if from_flag {
                    return Err(RecipeError::Flag {
                        flag: "--y-start-mm",
                        message: format!("{message} (recipe {})", self.name),
                    });
                }
                Err(match recipe_key(key) {
                    Some(k) => RecipeError::Invalid {
                        path: self.path.clone(),
                        key: k,
                        message,
                    },
                    None => RecipeError::Invalid {
                        path: self.path.clone(),
                        key: "plan".into(),
                        message: format!("with the station's configuration, {key}: {message}"),
                    },
                })
            }
            Err(e) => Err(RecipeError::Invalid {
                path: self.path.clone(),
                key: String::new(),
                message: e.to_string(),
            }),
        }
    }

    /// The record a scan of this recipe carries in its start record (`id`: the queue's job
    /// number, `None` for `start --recipe` and `scan --recipe`).
    pub fn job_record(&self, id: Option<u64>) -> crate::scan::journal::JobRecord {
        crate::scan::journal::JobRecord {
            id,
            recipe: self.name.clone(),
            recipe_sha256: self.sha256.clone(),
            recipe_text: self.text.clone(),
        }
    }

    /// What a new scan of this recipe carries: its job record and the conditions the
    /// instrument must be set to.
    pub fn new_job(&self, id: Option<u64>) -> crate::scan::outcome::NewJob {
        crate::scan::outcome::NewJob {
            record: self.job_record(id),
            expected: self.file.conditions,
        }
    }

    /// One line for people: `31 lines from y = 1.0000 mm in steps of 0.0100 mm, 2 limits`.
    pub fn summary(&self, station: &Config) -> String {
        use crate::numfmt::{fmt, Quantity};
        let p = &self.file.plan;
        let y = match p.y_start_mm {
            Some(y) => format!("from y = {} mm", fmt(y, Quantity::PositionMm)),
            None => format!(
                "from y = {} mm (the station's; --y-start-mm sets it per job)",
                fmt(station.scan.y_start_mm, Quantity::PositionMm)
            ),
        };
        let limits = match self.specification.limits.len() {
            0 => "no specification".to_owned(),
            1 => format!("1 limit ({})", self.specification.limits[0].text),
            n => format!(
                "{n} limits ({})",
                self.specification
                    .limits
                    .iter()
                    .map(|c| c.text.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        format!(
            "{} lines {y} in steps of {} mm, {limits}",
            p.lines,
            fmt(p.y_step_mm, Quantity::PositionMm)
        )
    }
}

/// Where a callout asks for other conditions than the recipe states (only what both state
/// is compared; the instrument's own conditions are compared when a scan starts).
fn conflicts_with_conditions(
    c: &crate::specification::Callout,
    cond: &ExpectedConditions,
) -> Option<String> {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
    if let (Some(lc), Some(want)) = (c.band.and_then(|b| b.lambda_c_mm), cond.lambda_c_mm) {
        if !close(lc, want) {
            return Some(format!(
                "asks λc = {lc} mm but [conditions] lambda-c-mm = {want}"
            ));
        }
    }
    if let (Some(ls), Some(want)) = (c.band.and_then(|b| b.lambda_s_mm), cond.lambda_s_um) {
        if !close(ls * 1000.0, want) {
            return Some(format!(
                "asks λs = {ls} mm but [conditions] lambda-s-um = {want}"
            ));
        }
    }
    if let Some(n) = cond.sampling_lengths {
        let asked = c.evaluation_sampling_lengths();
        if asked != n {
            let written = if c.sampling_lengths.is_none() {
                format!(" (none written: the default {DEFAULT_SAMPLING_LENGTHS})")
            } else {
                String::new()
            };
            return Some(format!(
                "asks {asked} sampling lengths{written} but [conditions] sampling-lengths = {n}"
            ));
        }
    }
    None
}

/// The station's `[analysis]` with the recipe's keys written over it.
fn overlay<T: Serialize + serde::de::DeserializeOwned + Clone>(
    station: &T,
    over: &toml::Table,
) -> Result<T, String> {
    if over.is_empty() {
        return Ok(station.clone());
    }
    let mut t = toml::Table::try_from(station).map_err(|e| e.to_string())?;
    for (k, v) in over {
        t.insert(k.clone(), v.clone());
    }
    T::deserialize(toml::Value::Table(t)).map_err(|e| e.to_string().trim_end().to_owned())
}

#[cfg(test)]
mod tests;
