//! The report as data: what `report.json` holds, as typed values the renderers read,
//! [`assemble`]d from the sections' results.
//!
//! Layer 4 (reporting): depends on the metrology result types, the scan's journal records
//! ([`crate::scan::journal`]) and the fit summary of [`crate::scan::outputs`].

use crate::devices::ReadoutWarning;
use crate::fit::VMethod;
use crate::grid::Grid;
use crate::metrology::anisotropy::Anisotropy;
use crate::metrology::areal::ArealParams;
use crate::metrology::folds::ModelChecks;
use crate::metrology::functional::ArealFunctional;
use crate::metrology::holdout::{BetweenLines, Holdout, HoldoutLine};
use crate::metrology::instrument::Comparison;
use crate::metrology::model::ModelCurveBac;
use crate::metrology::outliers::LineSpike;
use crate::metrology::params::{EvaluationLengthMoments, Recipe, RoughnessParams};
use crate::metrology::sj_material_ratio::SjMaterialRatio;
use crate::metrology::spatial::SpatialParams;
use crate::profile::Conditions;
use crate::report::context::{Model, ReportContext};
use crate::report::sections::lines::LinesSection;
use crate::report::sections::model_vs_measured::attach;
use crate::report::sections::Sections;
use crate::scan::journal::{StartRecord, StopRecord};
use crate::scan::outputs::FitSummary;
use serde::Serialize;
use std::collections::BTreeMap;

/// `report.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// `surfscan <version>` that wrote the report.
    pub software: String,
    /// The input as named (a file or a scan directory).
    pub input: String,
    /// `grid` or `scan`.
    pub kind: &'static str,
    /// x of each line's first point, mm: 0 for a scan and a grid CSV, a profile CSV's first
    /// x, an X3P file's x offset (each line's y is in `lines`).
    pub x0_mm: f64,
    /// Which origin every position the report names uses (the warnings, `outliers`,
    /// `model_checks`, `lines`), in words: the input's own coordinates.
    pub positions: String,
    /// The verdict of the lines against the part's specification (a scan of a recipe with
    /// limits): first, as it is what the report is read for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub specification: Option<crate::specification::SpecificationVerdict>,
    /// Every line parameter's mean with its uncertainty.
    pub uncertainty: super::sections::specification::UncertaintyReport,
    /// How the lines were evaluated.
    pub recipe: ReportRecipe,
    /// Per-line ISO parameters.
    pub lines: Vec<LineReport>,
    /// Areal parameters and bearing curves of the NURBS model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface: Option<SurfaceReport>,
    /// Why `surface` is missing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface_error: Option<String>,
    /// Areal parameters of the measured grid as traced.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface_grid: Option<SurfaceReport>,
    /// Why `surface_grid` is missing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface_grid_error: Option<String>,
    /// The hold-out refits (model against points it was not fitted to).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_vs_measured: Option<Holdout>,
    /// Why the hold-out comparison could not be made (e.g. too few lines to refit half).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_vs_measured_error: Option<String>,
    /// How far the surface between lines can be trusted: every 2nd line left out, refitted,
    /// judged against Sq.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub between_lines: Option<BetweenLines>,
    /// Why `between_lines` is missing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub between_lines_error: Option<String>,
    /// The contact of the measured grid and of the model between lines (when asked for).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<crate::report::sections::contact::ContactSection>,
    /// The surface the model sections describe: method, recipe, spikes replaced.
    pub model: ModelReport,
    /// Folds of the control net and the surface, and its height range against the data's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_checks: Option<ModelChecks>,
    /// The spikes found in the lines and what was done with them.
    pub outliers: OutliersReport,
    /// The grid's anisotropy and what it does to Sdq and Sdr.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub anisotropy: Option<Anisotropy>,
    /// Whether every section could be made.
    pub characterisation: Characterisation,
    /// Traceability of a scan, from its journal's start record.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub traceability: Option<Traceability>,
    /// How far a scan got.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scan: Option<ScanStatus>,
    /// The fit the model sections describe (degrees, knots, poles, residual; the IGES files
    /// when the scan wrote them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitSummary>,
    /// Everything that was left out or approximated, for the operator.
    pub warnings: Vec<String>,
    /// Seconds per section.
    pub timings_s: Timings,
    /// The issuing laboratory and the printed layout (`[report]` of the configuration).
    pub lab: super::header::LabHeader,
}

/// What the figures are drawn from beyond the report (the lines' Rk constructions are drawn
/// as their section ends, `model.x3p` as the model is sampled): the line drawn against it.
#[derive(Debug)]
pub struct FigureData {
    /// The line drawn against the model.
    pub overlay: Option<crate::report::sections::overlay::Overlay>,
}

/// The report of `sections` (made from `grid` with `model`, as `ctx` says): each section's
/// result in its place, each line with its share of the hold-out, the failures and the
/// warnings; and the figures' data. The timings are the sections' (the caller adds the
/// writing's).
pub fn assemble(
    sections: Sections,
    grid: &Grid,
    model: &Model<'_>,
    ctx: &ReportContext,
) -> (Report, FigureData) {
    let LinesSection {
        recipe,
        lines: mut line_reports,
        ..
    } = sections.lines;
    if let Ok(h) = &sections.model_vs_measured {
        attach(&mut line_reports, h);
    }
    let (surface_report, surface_error) = split(sections.surface.surface);
    let (surface_grid, surface_grid_error) = split(sections.surface_grid);
    let (model_vs_measured, model_vs_measured_error) = split(sections.model_vs_measured);
    let (between_lines, between_lines_error) = split(sections.between_lines);
    let report = Report {
        software: crate::build_info::software(),
        input: ctx.input.clone(),
        kind: ctx.kind,
        x0_mm: grid.x0_mm,
        positions: positions(grid.x0_mm, ctx.kind),
        specification: sections.specification.verdict,
        uncertainty: sections.specification.uncertainty,
        recipe,
        lines: line_reports,
        surface: surface_report,
        surface_error,
        surface_grid,
        surface_grid_error,
        model_vs_measured,
        model_vs_measured_error,
        between_lines,
        between_lines_error,
        contact: sections.contact,
        model: ModelReport {
            v_method: model.recipe.method,
            description: model.recipe.describe(),
            degree_u: model.recipe.degrees.degree_u,
            degree_v: model.recipe.degrees.degree_v,
            spikes_replaced: model.replaced.to_vec(),
        },
        model_checks: sections.surface.checks,
        outliers: sections.spikes,
        anisotropy: sections.anisotropy.ok(),
        characterisation: Characterisation {
            complete: sections.failed.is_empty() && !grid.is_partial(),
            lines_in_input: grid.lines_in_input(),
            lines_left_out: grid.left_out.clone(),
            failed_sections: sections.failed,
            sections_not_possible: sections.not_possible,
        },
        traceability: ctx.traceability.clone(),
        scan: ctx.scan.clone(),
        fit: ctx.fit.clone(),
        warnings: sections.warnings,
        timings_s: sections.timings,
        lab: ctx.lab.clone(),
    };
    let figures = FigureData {
        overlay: sections.overlay,
    };
    (report, figures)
}

/// The origin of the positions a report of a `kind` input whose lines start at `x0_mm` names.
fn positions(x0_mm: f64, kind: &str) -> String {
    let (x, y) = match kind {
        "x3p" => (" (the file's x offset)", ", from the file's y offset"),
        _ => ("", ""),
    };
    format!(
        "x and y in mm in the input's coordinates: each line's first point at x = {} mm{x}, each line at its own y{y}",
        crate::numfmt::fmt(x0_mm, crate::numfmt::Quantity::PositionMm)
    )
}

/// A section's result as report.json holds it: the value, or why there is none.
pub(crate) fn split<T>(r: Result<T, String>) -> (Option<T>, Option<String>) {
    match r {
        Ok(v) => (Some(v), None),
        Err(e) => (None, Some(e)),
    }
}

/// The surface the model sections describe.
#[derive(Debug, Clone, Serialize)]
pub struct ModelReport {
    /// The method across the lines (with its control rows when least squares).
    pub v_method: VMethod,
    /// The recipe in one sentence.
    pub description: String,
    /// Degrees.
    pub degree_u: usize,
    /// Degrees.
    pub degree_v: usize,
    /// The spikes replaced before fitting (only when asked for).
    pub spikes_replaced: Vec<LineSpike>,
}

/// The spikes of the lines.
#[derive(Debug, Clone, Serialize)]
pub struct OutliersReport {
    /// The rule.
    pub rule: String,
    /// `flag` (data as measured) or `exclude` (bridged in the per-line and measured-grid
    /// parameters).
    pub policy: &'static str,
    /// Every spike: line, points, x, measured height, deviation.
    pub spikes: Vec<LineSpike>,
    /// Lines the rule could not judge, with the reason.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub lines_not_judged: Vec<LineNotJudged>,
}

/// A line the spike rule could not judge.
#[derive(Debug, Clone, Serialize)]
pub struct LineNotJudged {
    /// Line index.
    pub line: u32,
    /// Why.
    pub reason: String,
}

/// Whether the characterisation is complete: made from every line of the input, every
/// section made; and which lines were left out and which sections failed, and why.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Characterisation {
    /// Every line of the input was used and every section was made.
    pub complete: bool,
    /// Lines the input holds (those used and those left out).
    pub lines_in_input: usize,
    /// The lines of the input left out, each with why (each also in `warnings`).
    pub lines_left_out: Vec<crate::grid::LeftOut>,
    /// The sections that failed, each with its reason (each also in `warnings`).
    pub failed_sections: Vec<FailedSection>,
    /// The sections the grid has too few lines for (the fit needs degree-v + 1 lines, a
    /// hold-out more than that after leaving lines out), each with its reason (also in
    /// `warnings`). They are not failures: a complete characterisation of so few lines has
    /// none of them.
    pub sections_not_possible: Vec<FailedSection>,
}

impl Characterisation {
    /// "29 of 31 lines": the lines used of those the input holds.
    pub fn lines_used(&self) -> String {
        format!(
            "{} of {} lines",
            self.lines_in_input - self.lines_left_out.len(),
            self.lines_in_input
        )
    }
}

/// A section that could not be made.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FailedSection {
    /// Its key in the report (e.g. `surface`, `between_lines`).
    pub section: String,
    /// Why.
    pub reason: String,
}

/// The recipe of the report: the lines' recipe, where λc came from and why the filter was or
/// was not applied; `definitions` holds the profile and the areal definition ids.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReportRecipe {
    /// The lines' recipe.
    #[serde(flatten)]
    pub lines: Recipe,
    /// Where λc came from.
    pub lambda_c_source: String,
    /// Why the λc filter was or was not applied.
    pub filter_reason: String,
    /// The spike rule (its threshold in robust σ and longest run of points).
    pub spike_rule: String,
    /// What characterisation does with the spikes: `flag` (named, the data as measured) or
    /// `exclude` (bridged for the per-line and measured-grid parameters).
    pub outliers: &'static str,
    /// The model between lines is supported by the data when the hold-out rms is at most
    /// this × Sq.
    pub holdout_threshold_sq: f64,
    /// The reading of the material-ratio family limits are judged in: `iso` or
    /// `instrument` (`[analysis] material-ratio`; both readings are in every line).
    pub material_ratio: &'static str,
}

/// One line's entry in the report.
#[derive(Debug, Clone, Serialize)]
pub struct LineReport {
    /// Line index (a scan's `NNNN`, a grid's row).
    pub index: u32,
    /// y of the line, mm.
    pub y_mm: f64,
    /// y read back from the stage, mm, when known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub y_readback_mm: Option<f64>,
    /// The ISO parameters.
    #[serde(flatten)]
    pub params: RoughnessParams,
    /// Rmr(c) at depths c = 0, 10, …, 100 % of Rt below the highest peak: `[c_um, Rmr_pct]`.
    #[serde(rename = "Rmr_table")]
    pub rmr_table: Vec<[f64; 2]>,
    /// The instrument's results beside ours (scans only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instrument: Option<Vec<Comparison>>,
    /// This line's share of the hold-out comparison (when it could be made).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_vs_measured: Option<LineHoldout>,
    /// The doubts about its read-out the line was kept with (a scan's line only): the
    /// specification's verdict is weighed with and without it.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub readout_warnings: Vec<ReadoutWarning>,
    /// Ra, Rq, Rsk, Rku over the whole evaluation length (`Ra_ln_um`, …), beside the
    /// per-sampling-length means above.
    pub evaluation_length: EvaluationLengthMoments,
    /// Why a parameter above is blank, by its name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub blank_reasons: BTreeMap<String, String>,
    /// The material-ratio family as the Mitutoyo SJ series reads it (ordinates counted, a
    /// 100-level curve, core limits snapped to it), under the ISO names; `None` when the line
    /// has too few ordinates.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub material_ratio_sj_series: Option<SjMaterialRatio>,
}

/// The hold-out differences of one line: at its own left-out points, and (every 2nd line)
/// for the whole line left out.
#[derive(Debug, Clone, Serialize)]
pub struct LineHoldout {
    /// At the line's left-out points.
    pub points_left_out: Option<HoldoutLine>,
    /// With the whole line left out.
    pub line_left_out: Option<HoldoutLine>,
}

/// Areal results with their curves.
#[derive(Debug, Clone, Serialize)]
pub struct SurfaceReport {
    /// The areal parameters.
    #[serde(flatten)]
    pub params: ArealParams,
    /// Pooled Smr(c): `[height_um, material_ratio_pct]`.
    pub bac: Vec<[f64; 2]>,
    /// How the grid was obtained.
    pub recipe: String,
    /// The paper's per-curve bearing area curves (model only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bac_curves: Option<Vec<ModelCurveBac>>,
    /// How the per-curve tables were made.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bac_curves_recipe: Option<String>,
    /// ISO 25178-2 functional parameters: the Sk family (the profile Rk construction on the
    /// areal material ratio curve) and the volumes (p 10 %, q 80 %, ml/m²).
    #[serde(serialize_with = "ok_or_error")]
    pub functional: Result<ArealFunctional, String>,
    /// ISO 25178-2 spatial parameters: Sal (µm), Str (s = 0.2), Std (degrees).
    #[serde(serialize_with = "ok_or_error")]
    pub spatial: Result<SpatialParams, String>,
}

/// A result as itself, or `{"error": why}` when it could not be computed.
fn ok_or_error<T: Serialize, S: serde::Serializer>(
    r: &Result<T, String>,
    s: S,
) -> Result<S::Ok, S::Error> {
    match r {
        Ok(v) => v.serialize(s),
        Err(e) => serde_json::json!({ "error": e }).serialize(s),
    }
}

/// Seconds spent per section.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Timings {
    /// Per-line ISO parameters.
    pub lines: f64,
    /// Areal parameters of the measured grid.
    pub surface_grid: f64,
    /// Fitting the surface for this report (0 for a surface fitted before, as the runner's is
    /// while its lines arrive).
    pub fit: f64,
    /// The model sections.
    pub model: f64,
    /// The hold-out refits.
    pub holdout: f64,
    /// Writing the files.
    pub write: f64,
    /// Everything.
    pub total: f64,
}

/// Traceability of a scan, from its journal's start record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Traceability {
    /// Scan id.
    pub scan_id: String,
    /// When the scan started (ISO 8601).
    pub started_at: String,
    /// When it finished (ISO 8601): for a complete scan, when its last line was read out;
    /// for one stopped otherwise (abort, fail), its stop record's time; `None` while it has
    /// neither (still running, or stopped without a record).
    pub finished_at: Option<String>,
    /// From start to finish, s (`None` without a finish).
    pub duration_s: Option<f64>,
    /// Specimen id.
    pub specimen: String,
    /// Operator.
    pub operator: String,
    /// Free-text notes.
    pub notes: String,
    /// surfscan version that ran the scan.
    pub software_version: String,
    /// SHA-256 of the configuration file.
    pub config_hash: String,
    /// Instrument model as identified.
    pub instrument_model: String,
    /// Instrument firmware.
    pub firmware: String,
    /// Drive unit.
    pub drive_unit: String,
    /// The instrument's maker (the SJ series is Mitutoyo's), empty when not known.
    pub manufacturer: String,
    /// The instrument's serial number: the SJ series reports none over its link, so this is
    /// `[traceability] serial-number` of the configuration the scan ran with.
    pub instrument_serial: Option<String>,
    /// Stylus tip radius, µm (`[traceability] stylus-tip-radius-um`).
    pub stylus_tip_radius_um: Option<f64>,
    /// The instrument's last calibration, ISO 8601 date (`[traceability] calibration-date`).
    pub calibration_date: Option<String>,
    /// Measurement conditions read at start.
    pub conditions: Conditions,
}

impl Traceability {
    /// Traceability of a scan started as `s` says and finished at `finished`.
    pub fn of_scan(s: &StartRecord, finished: Option<chrono::DateTime<chrono::Utc>>) -> Self {
        // A key of the `[traceability]` table of the configuration the scan recorded.
        let key = |k: &str| s.config.get("traceability")?.get(k);
        let text = |k: &str| key(k).and_then(|v| v.as_str().map(str::to_owned));
        Traceability {
            scan_id: s.scan_id.clone(),
            started_at: s.time.to_rfc3339(),
            finished_at: finished.map(|f| f.to_rfc3339()),
            duration_s: finished.map(|f| (f - s.time).num_milliseconds() as f64 / 1000.0),
            specimen: s.specimen.clone(),
            operator: s.operator.clone(),
            notes: s.notes.clone(),
            software_version: s.software_version.clone(),
            config_hash: s.config_hash.clone(),
            instrument_model: s.instrument_model.clone(),
            firmware: s.firmware.clone(),
            drive_unit: s.drive_unit.clone(),
            manufacturer: manufacturer_of(&s.instrument_model).to_string(),
            instrument_serial: text("serial-number"),
            stylus_tip_radius_um: key("stylus-tip-radius-um").and_then(serde_json::Value::as_f64),
            calibration_date: text("calibration-date"),
            conditions: s.conditions.clone(),
        }
    }
}

/// The maker of an instrument model: the scan daemon drives the Mitutoyo SJ series
/// (recorded as e.g. "sj210" from the config or "SJ-210" from the instrument); any other
/// model is not named.
pub fn manufacturer_of(model: &str) -> &'static str {
    if model.trim_start().to_ascii_lowercase().starts_with("sj") {
        "Mitutoyo"
    } else {
        ""
    }
}

/// Whether a scan's characterisation covers its whole plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Completeness {
    /// Stopped with success (or being completed), no line missing or incomplete.
    Complete,
    /// Anything else: the lines it has.
    Partial,
}

/// How far the scan got.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanStatus {
    /// Complete or partial.
    pub status: Completeness,
    /// The journal's stop record, `None` while the scan has none (running, being completed,
    /// or crashed).
    pub stop: Option<StopRecord>,
    /// Lines the frozen plan asks for.
    pub lines_planned: u32,
    /// Lines characterised.
    pub lines_used: Vec<u32>,
    /// Lines with only one of their two files (left out).
    pub lines_incomplete: Vec<u32>,
    /// Lines the journal records as completed.
    pub lines_in_journal: Vec<u32>,
}
