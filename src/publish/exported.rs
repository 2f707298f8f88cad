//! What a completed scan hands to the lab's quality systems (the Q-DAS DFQ and QIF renderers,
//! [`super::dfq`] and [`super::qif`]): the part, the specimen, the operator,
//! the instrument, and one characteristic per specified parameter with its limits, each
//! line's value, the mean with its uncertainty and the verdict.
//!
//! It is read back from the scan directory — `report.json` (the sections' results as the
//! report documents them) and the journal (the recipe the scan's job froze, each line's
//! time) — so a scan exported when it completes and a scan exported again later by
//! `surfscan export` give the same files, and a process restarted between the two needs
//! nothing but the directory.
//!
//! A scan without a specification exports Ra, Rq and Rz without limits (one characteristic
//! each), so an SPC system still receives its values.
//!
//! Layer 4 (the lab's systems): depends on [`crate::scan::journal`] (the records), the
//! report's documented JSON (read as JSON, not through the report's types) and
//! [`crate::specification::Verdict`]; no writing.

use crate::scan::journal::{read_journal, Record};
use crate::specification::Verdict;
use chrono::{DateTime, Utc};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// The part the scan was judged for.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// The recipe's name (a part number as the lab names its recipes), or `surface` for a
    /// scan of the station's own plan.
    pub number: String,
    /// The recipe's description, else its name.
    pub description: String,
}

/// The instrument the lines were traced with.
#[derive(Debug, Clone, PartialEq)]
pub struct Instrument {
    /// `Mitutoyo`, or empty when not known.
    pub manufacturer: String,
    /// The model as identified (`SJ-210`).
    pub model: String,
    /// `[traceability] serial-number`.
    pub serial: Option<String>,
    /// The firmware it reported.
    pub firmware: String,
    /// `[traceability] calibration-date`.
    pub calibration_date: Option<String>,
}

/// One traced line used by the report.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportLine {
    /// 1-based, as summary.csv and the verdict's lists number it.
    pub number: u64,
    /// y of the line, mm.
    pub y_mm: f64,
    /// When its read-out was committed (the journal's line record), if known.
    pub time: Option<DateTime<Utc>>,
}

/// One characteristic: a parameter with the limits the specification sets on it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Characteristic {
    /// `Ra`, `Rz`, … (the callout's parameter).
    pub parameter: String,
    /// The callouts that set its limits, as written (`Rz max 6.3`); empty without any.
    pub callouts: Vec<String>,
    /// The lower limit, µm.
    pub lower_um: Option<f64>,
    /// The upper limit, µm.
    pub upper_um: Option<f64>,
    /// The verdict on its limits (the worst of them), `None` without limits.
    pub verdict: Option<Verdict>,
    /// The verdict in words, one per limit.
    pub reasons: Vec<String>,
    /// Each line's value, µm, in the order of [`Exported::lines`] (`None`: the line has no
    /// finite one).
    pub values_um: Vec<Option<f64>>,
    /// Lines (1-based) beyond a limit by more than their uncertainty.
    pub lines_beyond: Vec<u64>,
    /// Lines (1-based) within their uncertainty of a limit.
    pub lines_undecided: Vec<u64>,
    /// Mean over the lines, µm.
    pub mean_um: Option<f64>,
    /// Standard deviation of the lines' values, µm.
    pub s_um: Option<f64>,
    /// Expanded uncertainty of the mean (k = 2), µm.
    pub expanded_u_um: Option<f64>,
    /// Number of lines with a value.
    pub n: usize,
}

/// The results a scan exports.
#[derive(Debug, Clone, PartialEq)]
pub struct Exported {
    /// The scan id (the batch the values belong to).
    pub scan_id: String,
    /// The specimen (the part's identification).
    pub specimen: String,
    /// Who ran it.
    pub operator: String,
    /// Notes given with the scan.
    pub notes: String,
    /// When it started.
    pub started_at: DateTime<Utc>,
    /// When its last line was read out.
    pub finished_at: Option<DateTime<Utc>>,
    /// The version of this software that characterised it.
    pub software: String,
    /// The part.
    pub part: Part,
    /// The instrument.
    pub instrument: Instrument,
    /// The evaluation's cut-off λc, mm, and its number of sampling lengths, when the lines
    /// were R profiles.
    pub lambda_c_mm: Option<f64>,
    /// The sampling lengths per evaluation length.
    pub sampling_lengths: Option<u64>,
    /// The verdict against the specification, `None` without one.
    pub verdict: Option<Verdict>,
    /// The verdict with the limits that decide it.
    pub verdict_summary: Option<String>,
    /// The lines used, in the report's order.
    pub lines: Vec<ExportLine>,
    /// One per specified parameter (Ra, Rq, Rz without a specification).
    pub characteristics: Vec<Characteristic>,
}

/// The parameters exported for a scan without a specification.
const UNSPECIFIED: [&str; 3] = ["Ra", "Rq", "Rz"];

fn time(v: &Value) -> Option<DateTime<Utc>> {
    DateTime::parse_from_rfc3339(v.as_str()?)
        .ok()
        .map(|t| t.with_timezone(&Utc))
}

fn text(v: &Value, key: &str) -> String {
    v[key].as_str().unwrap_or_default().to_owned()
}

/// A value as both renderers write it (QIF's `xs:decimal`, DFQ's value fields): a decimal
/// point, every digit of the value and never an exponent (Rust's shortest round-trip form).
pub fn decimal(v: f64) -> String {
    format!("{v}")
}

fn numbers(v: &Value) -> Vec<u64> {
    v.as_array()
        .map(|a| a.iter().filter_map(Value::as_u64).collect())
        .unwrap_or_default()
}

/// The worse of two verdicts: does not conform, then not decidable, then conforms.
fn worse(a: Verdict, b: Verdict) -> Verdict {
    let rank = |v: Verdict| match v {
        Verdict::Conforms => 0,
        Verdict::NotDecidable => 1,
        Verdict::DoesNotConform => 2,
    };
    if rank(b) > rank(a) {
        b
    } else {
        a
    }
}

impl Exported {
    /// Reads a completed scan's results from its directory: `report.json` and
    /// `journal.jsonl`. The error names the file and what is wrong.
    pub fn read(scan_dir: &Path) -> Result<Exported, String> {
        let report_path = scan_dir.join("report.json");
        let bytes = std::fs::read(&report_path).map_err(|e| {
            format!(
                "{}: {e}; a scan is exported once it has a report (`surfscan analyze {}` makes one)",
                report_path.display(),
                scan_dir.display()
            )
        })?;
        let report: Value = serde_json::from_slice(&bytes)
            .map_err(|e| format!("{}: not a report: {e}", report_path.display()))?;
        let journal_path = scan_dir.join("journal.jsonl");
        let journal =
            read_journal(&journal_path).map_err(|e| format!("{}: {e}", journal_path.display()))?;
        Exported::from_parts(&report, &journal.records)
            .map_err(|e| format!("{}: {e}", report_path.display()))
    }

    /// The results from a report's JSON and the scan's journal records.
    pub fn from_parts(report: &Value, records: &[Record]) -> Result<Exported, String> {
        let start = records
            .iter()
            .find_map(|r| match r {
                Record::Start(s) => Some(s),
                _ => None,
            })
            .ok_or("the scan's journal has no start record")?;
        let tr = report
            .get("traceability")
            .ok_or("no traceability: this is not the report of a scan")?;
        let mut line_times: BTreeMap<u64, DateTime<Utc>> = BTreeMap::new();
        for r in records {
            if let Record::Line(l) = r {
                line_times.insert(u64::from(l.id.index), l.time);
            }
        }
        let line_values = report["lines"].as_array().ok_or("no lines")?;
        let lines: Vec<ExportLine> = line_values
            .iter()
            .map(|l| {
                let index = l["index"].as_u64().unwrap_or_default();
                ExportLine {
                    number: index + 1,
                    y_mm: l["y_mm"].as_f64().unwrap_or(f64::NAN),
                    time: line_times.get(&index).copied(),
                }
            })
            .collect();
        let value_of = |parameter: &str| -> Vec<Option<f64>> {
            let key = format!("{parameter}_um");
            line_values
                .iter()
                .map(|l| l[&key].as_f64().filter(|v| v.is_finite()))
                .collect()
        };
        let stats: BTreeMap<String, &Value> = (report["uncertainty"]["parameters"].as_array())
            .map(|a| {
                a.iter()
                    .filter_map(|p| Some((p["parameter"].as_str()?.to_owned(), p)))
                    .collect()
            })
            .unwrap_or_default();
        let with_stats = |mut c: Characteristic| {
            if let Some(s) = stats.get(&format!("{}_um", c.parameter)) {
                c.mean_um = s["mean"].as_f64();
                c.s_um = s["s"].as_f64();
                c.expanded_u_um = s["U"].as_f64();
                c.n = s["n"].as_u64().unwrap_or_default() as usize;
            }
            c
        };
        let blank = |parameter: &str| Characteristic {
            parameter: parameter.to_owned(),
            values_um: value_of(parameter),
            ..Characteristic::default()
        };
        let spec = report.get("specification").filter(|s| !s.is_null());
        let mut characteristics: Vec<Characteristic> = Vec::new();
        if let Some(spec) = spec {
            for l in spec["limits"].as_array().into_iter().flatten() {
                let parameter = text(l, "parameter");
                let at = match characteristics
                    .iter()
                    .position(|c| c.parameter == parameter)
                {
                    Some(i) => i,
                    None => {
                        characteristics.push(blank(&parameter));
                        characteristics.len() - 1
                    }
                };
                let c = &mut characteristics[at];
                let limit = l["limit_um"].as_f64();
                match l["side"].as_str() {
                    Some("lower") => c.lower_um = limit,
                    _ => c.upper_um = limit,
                }
                c.callouts.push(text(l, "callout"));
                c.reasons.push(text(l, "reason"));
                if let Some(v) = l["verdict"].as_str().and_then(Verdict::parse) {
                    c.verdict = Some(c.verdict.map_or(v, |w| worse(w, v)));
                }
                let lists = [
                    ("lines_beyond", &mut c.lines_beyond),
                    ("lines_undecided", &mut c.lines_undecided),
                ];
                for (key, list) in lists {
                    for n in numbers(&l[key]) {
                        if !list.contains(&n) {
                            list.push(n);
                        }
                    }
                }
            }
        } else {
            characteristics = UNSPECIFIED.iter().map(|p| blank(p)).collect();
        }
        let characteristics = characteristics.into_iter().map(with_stats).collect();
        let recipe = &report["recipe"];
        let is_r = recipe["profile"] == "R";
        let (number, description) = match &start.job {
            Some(job) => {
                let description = toml::from_str::<toml::Table>(&job.recipe_text)
                    .ok()
                    .and_then(|t| t.get("description")?.as_str().map(str::to_owned))
                    .filter(|d| !d.trim().is_empty())
                    .unwrap_or_else(|| job.recipe.clone());
                (job.recipe.clone(), description)
            }
            None => ("surface".to_owned(), "the station's own plan".to_owned()),
        };
        Ok(Exported {
            scan_id: start.scan_id.clone(),
            specimen: start.specimen.clone(),
            operator: start.operator.clone(),
            notes: start.notes.clone(),
            started_at: start.time,
            finished_at: tr.get("finished_at").and_then(time),
            software: text(report, "software"),
            part: Part {
                number,
                description,
            },
            instrument: Instrument {
                manufacturer: text(tr, "manufacturer"),
                model: text(tr, "instrument_model"),
                serial: tr["instrument_serial"].as_str().map(str::to_owned),
                firmware: text(tr, "firmware"),
                calibration_date: tr["calibration_date"].as_str().map(str::to_owned),
            },
            lambda_c_mm: recipe["lambda_c_mm"].as_f64().filter(|_| is_r),
            sampling_lengths: recipe["sampling_lengths"].as_u64().filter(|_| is_r),
            verdict: spec
                .and_then(|s| s["verdict"].as_str())
                .and_then(Verdict::parse),
            verdict_summary: spec.and_then(|s| s["summary"].as_str().map(str::to_owned)),
            lines,
            characteristics,
        })
    }
}
