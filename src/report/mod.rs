//! Characterisation reports: a scan directory (what the scan daemon calls when a scan ends, and
//! what `surfscan analyze SCAN_DIR` runs) or a height grid is characterised line by line and as
//! a surface, and the results are written next to the data: `report.json` (atomically),
//! `report.html` (the report for people, plots embedded: [`html`]), `summary.csv` (values
//! with the significant digits of their quantity, lines 1-based),
//! `bac|heightmap|overlay.png|svg`, `rk/NNNN.png|svg` (the ISO 13565-2 construction of each
//! line), `measured.x3p` and `model.x3p`.
//!
//! `report.json` holds `lines` (one per traced line: `index`, `y_mm`, the ISO 4287 / ISO 13565-2
//! parameters under the names of [`RoughnessParams`], `Rmr_table`, and for scans `instrument`:
//! the instrument's own results beside ours with `ours − instrument`), `surface` (areal
//! parameters of the NURBS model, `bac` pooled `[height_um, material_ratio_pct]`, `bac_curves`
//! the paper's per-curve tables), `surface_grid` (the same on the measured grid),
//! `model_vs_measured` (hold-out refits; each line also carries its own share), `recipe`
//! (filter, λc and why, a definition id per parameter), and for scans `traceability` (from the
//! journal's start record) and `scan` (stop record, `complete`/`partial`, lines used and
//! incomplete), `fit` (what the caller passed, verbatim), `warnings` and `timings_s`.
//!
//! A partial, aborted or failed scan is characterised with the complete lines it has; lines
//! with only one of their two files are named in a warning. A complete but malformed line file
//! is an error naming the file.
//!
//! Layer 4 (reporting at the process edge): depends on [`crate::scan`] (reading the scan
//! directory), [`crate::metrology`], [`crate::fit`] and [`crate::atomic`].

pub mod html;

use crate::atomic::write_atomically;
use crate::fit::{fit_grid, FitError, FitOptions};
use crate::metrology::areal::{self, areal_params, smr_curve, ArealParams, Grid};
use crate::metrology::holdout::{holdout, Holdout, HoldoutLine};
use crate::metrology::instrument::{compare_under, Comparison};
use crate::metrology::model::ModelCurveBac;
use crate::metrology::model::{model_bearing_curves, sample_model_grid, ModelBacOptions};
use crate::metrology::params::{
    analyze_line, material_ratio_curve, rk_family, LineAnalysis, Options, Recipe, RoughnessParams,
};
use crate::metrology::plots::{
    plot_bearing_curves, plot_height_map, plot_profile_overlay, plot_rk_construction,
};
use crate::metrology::x3p::{to_x3p, X3pMeta};
use crate::metrology::MetrologyError;
use crate::numfmt::{fmt as nfmt, fmt_opt as nfmt_opt, line_number, Quantity};
use crate::profile::{Conditions, FilterKind, InstrumentResult, ProfileKind};
use crate::scan::faults::NoFaults;
use crate::scan::journal::{read_journal, ResumeState, StartRecord, StopRecord, StopStatus};
use crate::scan::line::StoredLine;
use crate::scan::store::{csv_name, ScanStore};
use crate::scan::store_error::StoreError;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use thiserror::Error;

/// How a scan is characterised. [`Default`]: 31 model curves, 101 levels, λc and filter from
/// the recorded conditions, the middle line in the overlay, no fit section, output into the
/// scan directory.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanAnalysisOptions {
    /// Profile curves extracted from the model for the bearing area curves (paper: 31).
    pub curves: usize,
    /// Equal height levels per bearing area curve (paper: 101).
    pub levels: usize,
    /// λc in mm overriding the instrument's recorded cut-off (default `None`: the recorded
    /// λc, or 0.8 mm when none is recorded). It is also the sampling length.
    pub lambda_c_mm: Option<f64>,
    /// Never apply the λc filter (default `false`: filter primary profiles, not R profiles).
    pub no_filter: bool,
    /// Line index drawn in the measured-vs-model overlay (default `None`: the middle line used).
    pub overlay_line: Option<u32>,
    /// The caller's own fit statistics, written verbatim under `report.json`'s `fit` key
    /// (default `None`: no `fit` key).
    pub fit: Option<serde_json::Value>,
    /// Where the files go (default `None`: the scan directory itself).
    pub out_dir: Option<PathBuf>,
    /// The scan is being completed by the runner (every planned line on disk; its success
    /// stop record follows this report), so no stop record yet does not make it partial
    /// (default `false`).
    pub completing: bool,
}

impl Default for ScanAnalysisOptions {
    fn default() -> ScanAnalysisOptions {
        ScanAnalysisOptions {
            curves: 31,
            levels: 101,
            lambda_c_mm: None,
            no_filter: false,
            overlay_line: None,
            fit: None,
            out_dir: None,
            completing: false,
        }
    }
}

/// What a characterisation wrote and used.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanOutputs {
    /// `report.json`.
    pub report_json: PathBuf,
    /// `summary.csv`.
    pub summary_csv: PathBuf,
    /// `report.html`, the report for people (plots embedded).
    pub report_html: PathBuf,
    /// The PNG and SVG plots written.
    pub plots: Vec<PathBuf>,
    /// `measured.x3p`, when the grid could be written (every height finite).
    pub measured_x3p: Option<PathBuf>,
    /// `model.x3p`, when the NURBS model could be fitted.
    pub model_x3p: Option<PathBuf>,
    /// Line indices characterised.
    pub lines_used: Vec<u32>,
    /// Line indices with only one of their two files (left out).
    pub incomplete_lines: Vec<u32>,
    /// Everything that was left out or approximated, for the operator.
    pub warnings: Vec<String>,
    /// Wall-clock time of the whole characterisation, s.
    pub elapsed_s: f64,
}

/// Why a scan directory or grid cannot be characterised.
#[derive(Debug, Error)]
pub enum ReportError {
    /// The scan directory or one of its line files cannot be read or is malformed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// No complete line to characterise.
    #[error("{dir}: no complete line to characterise (incomplete: {incomplete:?}); a scan needs at least one line with both NNNN.csv and NNNN.json")]
    NoLines {
        /// The scan directory.
        dir: PathBuf,
        /// Lines with one file only.
        incomplete: Vec<u32>,
    },
    /// The lines cannot form one grid.
    #[error("{path}: {reason}")]
    Lines {
        /// The offending line file.
        path: PathBuf,
        /// What differs, with both values.
        reason: String,
    },
    /// A line or the grid cannot be characterised.
    #[error("{what}: {source}")]
    Metrology {
        /// What was being characterised (file or line).
        what: String,
        /// The cause.
        #[source]
        source: MetrologyError,
    },
    /// An output cannot be written.
    #[error("cannot write {path}: {source}; check the directory's permissions and free space")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The report cannot be encoded (a value serde_json rejects).
    #[error("cannot encode the report: {0}")]
    Encode(#[from] serde_json::Error),
}

/// Traceability of a scan, from its journal's start record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Traceability {
    /// Scan id.
    pub scan_id: String,
    /// When the scan started (ISO 8601).
    pub started_at: String,
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

impl From<&StartRecord> for Traceability {
    fn from(s: &StartRecord) -> Traceability {
        Traceability {
            scan_id: s.scan_id.clone(),
            started_at: s.time.to_rfc3339(),
            specimen: s.specimen.clone(),
            operator: s.operator.clone(),
            notes: s.notes.clone(),
            software_version: s.software_version.clone(),
            config_hash: s.config_hash.clone(),
            instrument_model: s.instrument_model.clone(),
            firmware: s.firmware.clone(),
            drive_unit: s.drive_unit.clone(),
            manufacturer: manufacturer_of(&s.instrument_model).to_string(),
            instrument_serial: traceability_key(s, "serial-number")
                .and_then(|v| v.as_str().map(str::to_owned)),
            stylus_tip_radius_um: traceability_key(s, "stylus-tip-radius-um")
                .and_then(serde_json::Value::as_f64),
            calibration_date: traceability_key(s, "calibration-date")
                .and_then(|v| v.as_str().map(str::to_owned)),
            conditions: s.conditions.clone(),
        }
    }
}

/// A key of the `[traceability]` table of the configuration a scan recorded at its start.
fn traceability_key<'a>(s: &'a StartRecord, key: &str) -> Option<&'a serde_json::Value> {
    s.config.get("traceability")?.get(key)
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

/// How far the scan got.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanStatus {
    /// `complete` (stopped with success, no line missing or incomplete) or `partial`.
    pub status: &'static str,
    /// The journal's stop record, `None` while the scan has none (still running or crashed).
    pub stop: Option<StopRecord>,
    /// Lines the frozen plan asks for, when its `lines` field holds a count.
    pub lines_planned: Option<u64>,
    /// Lines characterised.
    pub lines_used: Vec<u32>,
    /// Lines with only one of their two files (left out).
    pub lines_incomplete: Vec<u32>,
    /// Lines the journal records as completed.
    pub lines_in_journal: Vec<u32>,
}

/// The recipe of the report: the lines' recipe, where λc came from and why the filter was or
/// was not applied; `definitions` holds the profile and the areal definition ids.
#[derive(Debug, Clone, PartialEq, Serialize)]
struct ReportRecipe {
    #[serde(flatten)]
    lines: Recipe,
    lambda_c_source: String,
    filter_reason: String,
}

/// One line's entry in the report.
#[derive(Debug, Clone, Serialize)]
struct LineReport {
    index: u32,
    y_mm: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    y_readback_mm: Option<f64>,
    #[serde(flatten)]
    params: RoughnessParams,
    /// Rmr(c) at depths c = 0, 10, …, 100 % of Rt below the highest peak: `[c_um, Rmr_pct]`.
    #[serde(rename = "Rmr_table")]
    rmr_table: Vec<[f64; 2]>,
    /// The instrument's results beside ours (scans only).
    #[serde(skip_serializing_if = "Option::is_none")]
    instrument: Option<Vec<Comparison>>,
    /// This line's share of the hold-out comparison (when it could be made).
    #[serde(skip_serializing_if = "Option::is_none")]
    model_vs_measured: Option<LineHoldout>,
}

/// The hold-out differences of one line: at its own left-out points, and (every 2nd line)
/// for the whole line left out.
#[derive(Debug, Clone, Serialize)]
struct LineHoldout {
    points_left_out: Option<HoldoutLine>,
    line_left_out: Option<HoldoutLine>,
}

/// Areal results with their curves.
#[derive(Debug, Clone, Serialize)]
struct SurfaceReport {
    #[serde(flatten)]
    params: ArealParams,
    /// Pooled Smr(c): `[height_um, material_ratio_pct]`.
    bac: Vec<[f64; 2]>,
    /// How the grid was obtained.
    recipe: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    bac_curves: Option<Vec<ModelCurveBac>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    bac_curves_recipe: Option<String>,
}

#[derive(Debug, Serialize)]
struct Report {
    software: String,
    input: String,
    kind: &'static str,
    recipe: ReportRecipe,
    lines: Vec<LineReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    surface: Option<SurfaceReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    surface_error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    surface_grid: Option<SurfaceReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    surface_grid_error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    model_vs_measured: Option<Holdout>,
    /// Why the hold-out comparison could not be made (e.g. too few lines to refit half).
    #[serde(skip_serializing_if = "Option::is_none")]
    model_vs_measured_error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    traceability: Option<Traceability>,
    #[serde(skip_serializing_if = "Option::is_none")]
    scan: Option<ScanStatus>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fit: Option<serde_json::Value>,
    warnings: Vec<String>,
    timings_s: Timings,
}

#[derive(Debug, Default, Serialize)]
struct Timings {
    lines: f64,
    surface_grid: f64,
    fit: f64,
    model: f64,
    holdout: f64,
    write: f64,
    total: f64,
}

/// A row-major grid of traced lines to characterise, with what is known about each line.
#[derive(Debug, Clone, PartialEq)]
pub struct LineGrid {
    /// Heights in µm, `y_mm.len() × cols`, row-major.
    pub heights_um: Vec<f64>,
    /// Points per line.
    pub cols: usize,
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// y of each line, mm (increasing).
    pub y_mm: Vec<f64>,
    /// Line index of each row (its `NNNN` in a scan).
    pub index: Vec<u32>,
    /// y read back from the stage, mm, per row when known.
    pub y_readback_mm: Vec<Option<f64>>,
    /// The instrument's results per row (`None`: not a scan, no comparison).
    pub instrument: Option<Vec<Vec<InstrumentResult>>>,
    /// The standard the instrument evaluated each row to (its recorded conditions), which
    /// decides what its `Rz` means.
    pub standard: Vec<Option<String>>,
}

/// Everything besides the grid that goes into a report.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportContext {
    /// The input as named in the report (a file or a scan directory).
    pub input: String,
    /// `"grid"` or `"scan"`.
    pub kind: &'static str,
    /// How every line is evaluated.
    pub line_options: Options,
    /// Where λc came from, for the recipe.
    pub lambda_c_source: String,
    /// Why the λc filter was or was not applied, for the recipe.
    pub filter_reason: String,
    /// Traceability (scans).
    pub traceability: Option<Traceability>,
    /// Scan status (scans).
    pub scan: Option<ScanStatus>,
    /// Model curves, levels, overlay line and the caller's `fit` section.
    pub options: ScanAnalysisOptions,
    /// Warnings gathered so far (e.g. while reading the lines).
    pub warnings: Vec<String>,
}

fn metrology(what: impl Into<String>) -> impl FnOnce(MetrologyError) -> ReportError {
    let what = what.into();
    move |source| ReportError::Metrology { what, source }
}

fn software() -> String {
    crate::build_info::software()
}

fn rmr_table(a: &LineAnalysis) -> Vec<[f64; 2]> {
    (0..=10)
        .map(|k| {
            let c = a.params.rt_um * k as f64 / 10.0;
            [c, a.rmr_pct(c)]
        })
        .collect()
}

/// Characterises every line, in parallel over the available cores (lines are independent).
fn analyse_lines(
    grid: &LineGrid,
    options: &Options,
    label: &str,
) -> Result<Vec<LineAnalysis>, ReportError> {
    let rows: Vec<&[f64]> = grid.heights_um.chunks(grid.cols.max(1)).collect();
    let workers = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, rows.len().max(1));
    let chunk = rows.len().div_ceil(workers).max(1);
    let results: Vec<Vec<Result<LineAnalysis, MetrologyError>>> = std::thread::scope(|s| {
        let handles: Vec<_> = rows
            .chunks(chunk)
            .map(|part| {
                s.spawn(move || {
                    part.iter()
                        .map(|z| analyze_line(z, grid.pitch_x_mm, options))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    vec![Err(MetrologyError::BadParameter {
                        what: "line analysis thread",
                        value: f64::NAN,
                        hint: "a line analysis thread panicked; report this with the input",
                    })]
                })
            })
            .collect()
    });
    results
        .into_iter()
        .flatten()
        .enumerate()
        .map(|(row, r)| {
            let index = grid.index.get(row).copied().unwrap_or(row as u32);
            r.map_err(metrology(format!(
                "{label} line {} ({index:04})",
                line_number(index)
            )))
        })
        .collect()
}

/// The mean y pitch of the lines, and whether they are equally spaced (within 1 %).
fn mean_pitch_y(y_mm: &[f64]) -> (f64, bool) {
    match (y_mm.first(), y_mm.last()) {
        (Some(a), Some(b)) if y_mm.len() >= 2 && b > a => {
            let p = (b - a) / (y_mm.len() - 1) as f64;
            let even = y_mm
                .windows(2)
                .all(|w| matches!(w, [u, v] if ((v - u) - p).abs() <= 0.01 * p));
            (p, even)
        }
        _ => (1.0, true),
    }
}

fn caption(ctx: &ReportContext) -> String {
    match &ctx.traceability {
        Some(t) => {
            let c = &t.conditions;
            let mut cond = Vec::new();
            if let Some(s) = &c.standard {
                cond.push(s.clone());
            }
            if let Some(f) = c.filter {
                cond.push(format!("{f:?}"));
            }
            if let Some(l) = c.lambda_c_mm {
                cond.push(format!("λc {l} mm"));
            }
            if let Some(l) = c.lambda_s_um {
                cond.push(format!("λs {l} µm"));
            }
            match c.sampling_lengths {
                // The SJ series' N = 0: an arbitrary evaluation length, one section.
                Some(0) => cond.push("arbitrary evaluation length".to_string()),
                Some(n) => cond.push(format!("N = {n}")),
                None => {}
            }
            let cond = if cond.is_empty() {
                "conditions not recorded".to_string()
            } else {
                cond.join(" ")
            };
            // The recorded software version already names the program ("surfscan 0.1.0").
            format!(
                "specimen {} · {} fw {} ({}) · {} · scan {} · {}",
                t.specimen,
                t.instrument_model,
                t.firmware,
                t.drive_unit,
                cond,
                t.scan_id,
                t.software_version
            )
        }
        None => format!("{} · {}", ctx.input, software()),
    }
}

fn x3p_meta(ctx: &ReportContext, what: &str) -> X3pMeta {
    match &ctx.traceability {
        Some(t) => {
            let conditions = serde_json::to_string(&t.conditions).unwrap_or_default();
            X3pMeta {
                date: t.started_at.clone(),
                calibration_date: t.calibration_date.clone().unwrap_or_default(),
                probe: match t.stylus_tip_radius_um {
                    Some(r) => format!(
                        "{} stylus, tip radius {} µm",
                        t.instrument_model,
                        crate::numfmt::sig(r, 3)
                    ),
                    None => String::new(),
                },
                creator: t.operator.clone(),
                manufacturer: t.manufacturer.clone(),
                model: t.instrument_model.clone(),
                serial: t.instrument_serial.clone().unwrap_or_default(),
                version: t.firmware.clone(),
                comment: format!(
                    "{what}; specimen {}; scan {}; operator {}; notes: {}; drive unit {}; conditions {}; scanned by surfscan {}, config sha256 {}; written by {}",
                    t.specimen,
                    t.scan_id,
                    t.operator,
                    t.notes,
                    t.drive_unit,
                    conditions,
                    t.software_version,
                    t.config_hash,
                    software()
                ),
            }
        }
        None => X3pMeta {
            date: chrono::Utc::now().to_rfc3339(),
            version: software(),
            comment: format!("{what} of {}", ctx.input),
            ..X3pMeta::default()
        },
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    write_atomically(path, |w| w.write_all(bytes)).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The instrument's value of `name` in our unit, from a line's comparisons.
fn instrument_value(line: &LineReport, name: &str) -> Option<f64> {
    line.instrument
        .as_ref()?
        .iter()
        .find(|c| c.name.trim().eq_ignore_ascii_case(name))
        .and_then(|c| c.instrument)
}

/// `summary.csv` for people and spreadsheets: one row per line, `line` 1-based and `index`
/// the NNNN of its files, every value with the significant digits of its quantity
/// ([`crate::numfmt`]; `report.json` keeps full precision).
fn summary_csv(lines: &[LineReport]) -> String {
    use Quantity::{Area, HeightUm as H, Percent, PositionMm, Ratio};
    let mut csv = String::from(
        "line,index,y_mm,Ra_um,Rq_um,Rz_um,RzJIS_um,Rp_um,Rv_um,Rt_um,Rz1max_um,Rsk,Rku,Rdq,RSm_um,Rk_um,Rpk_um,Rvk_um,Mr1_pct,Mr2_pct,A1_um_pct,A2_um_pct,instrument_Ra_um,instrument_Rq_um,instrument_Rz_um\n",
    );
    for l in lines {
        let p = &l.params;
        let row: Vec<String> = vec![
            line_number(l.index).to_string(),
            format!("{:04}", l.index),
            nfmt(l.y_mm, PositionMm),
            nfmt(p.ra_um, H),
            nfmt(p.rq_um, H),
            nfmt(p.rz_um, H),
            nfmt_opt(p.rzjis_um, H),
            nfmt(p.rp_um, H),
            nfmt(p.rv_um, H),
            nfmt(p.rt_um, H),
            nfmt(p.rz1max_um, H),
            nfmt(p.rsk, Ratio),
            nfmt(p.rku, Ratio),
            nfmt(p.rdq, Ratio),
            nfmt_opt(p.rsm_um, H),
            nfmt(p.rk_um, H),
            nfmt(p.rpk_um, H),
            nfmt(p.rvk_um, H),
            nfmt(p.mr1_pct, Percent),
            nfmt(p.mr2_pct, Percent),
            nfmt(p.a1_um_pct, Area),
            nfmt(p.a2_um_pct, Area),
            nfmt_opt(instrument_value(l, "Ra"), H),
            nfmt_opt(instrument_value(l, "Rq"), H),
            nfmt_opt(instrument_value(l, "Rz"), H),
        ];
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    csv
}

/// Characterises a grid of lines and writes every output into `out`: the work behind both
/// [`characterise_scan`] and `surfscan analyze GRID.csv`.
pub fn characterise_grid(
    grid: &LineGrid,
    mut ctx: ReportContext,
    out: &Path,
) -> Result<ScanOutputs, ReportError> {
    let t_all = Instant::now();
    let mut timings = Timings::default();
    let rows = grid.y_mm.len();
    let cols = grid.cols;
    let px = grid.pitch_x_mm;
    if rows == 0 || cols == 0 || grid.heights_um.len() != rows * cols {
        return Err(ReportError::Metrology {
            what: ctx.input.clone(),
            source: MetrologyError::GridSize {
                rows,
                cols,
                expected: rows.saturating_mul(cols),
                got: grid.heights_um.len(),
            },
        });
    }
    std::fs::create_dir_all(out).map_err(|source| ReportError::Io {
        path: out.to_path_buf(),
        source,
    })?;

    // Lines.
    let t = Instant::now();
    let analyses = analyse_lines(grid, &ctx.line_options, &ctx.input)?;
    let mut recipe =
        analyses
            .first()
            .map(|a| a.recipe.clone())
            .ok_or_else(|| ReportError::NoLines {
                dir: PathBuf::from(&ctx.input),
                incomplete: Vec::new(),
            })?;
    recipe.definitions.extend(areal::definitions());
    let mut lines: Vec<LineReport> = analyses
        .iter()
        .enumerate()
        .map(|(row, a)| LineReport {
            index: grid.index.get(row).copied().unwrap_or(row as u32),
            y_mm: grid.y_mm.get(row).copied().unwrap_or(f64::NAN),
            y_readback_mm: grid.y_readback_mm.get(row).copied().flatten(),
            params: a.params.clone(),
            rmr_table: rmr_table(a),
            instrument: grid.instrument.as_ref().map(|all| {
                compare_under(
                    &a.params,
                    all.get(row).map_or(&[][..], |v| &v[..]),
                    grid.standard.get(row).and_then(|s| s.as_deref()),
                )
            }),
            model_vs_measured: None,
        })
        .collect();
    timings.lines = t.elapsed().as_secs_f64();

    // Measured grid.
    let t = Instant::now();
    let (py, evenly) = mean_pitch_y(&grid.y_mm);
    if !evenly {
        ctx.warnings.push(format!(
            "the lines are not equally spaced in y (y = {:?} mm); the areal parameters, the height map and the X3P files use the mean pitch {py} mm",
            grid.y_mm
        ));
    }
    let measured = Grid {
        heights_um: &grid.heights_um,
        rows,
        cols,
        pitch_x_mm: px,
        pitch_y_mm: py,
    };
    let (surface_grid, surface_grid_error) =
        match areal_params(&measured).and_then(|p| Ok((p, smr_curve(&measured, ctx.options.levels)?))) {
            Ok((params, bac)) => (
                Some(SurfaceReport {
                    params,
                    bac,
                    recipe: format!(
                        "the measured heights as traced ({rows} lines × {cols} points, pitch x {px} mm, mean pitch y {py} mm), no λc filter, least-squares plane removed"
                    ),
                    bac_curves: None,
                    bac_curves_recipe: None,
                }),
                None,
            ),
            Err(e) => (None, Some(e.to_string())),
        };
    timings.surface_grid = t.elapsed().as_secs_f64();

    // Model.
    let t = Instant::now();
    let fitted = fit_grid(
        px,
        &grid.y_mm,
        &grid.heights_um,
        cols,
        FitOptions::default(),
    );
    timings.fit = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let model_cols = 2 * cols - 1;
    let model = match &fitted {
        Ok(fit) => {
            let bac_options = ModelBacOptions {
                curves: ctx.options.curves,
                levels: ctx.options.levels,
                samples_per_curve: None,
            };
            let curves = model_bearing_curves(&fit.surface, &bac_options)
                .map_err(metrology(format!("{}: model bearing curves", ctx.input)))?;
            let model_z = sample_model_grid(&fit.surface, &fit.params_v, 0.0, px / 2.0, model_cols)
                .map_err(metrology(format!("{}: sampling the model", ctx.input)))?;
            Ok((curves, model_z))
        }
        Err(e) => Err(model_error(e)),
    };
    let (surface, surface_error, model_z) = match model {
        Ok((curves, model_z)) => {
            let g = Grid {
                heights_um: &model_z,
                rows,
                cols: model_cols,
                pitch_x_mm: px / 2.0,
                pitch_y_mm: py,
            };
            match areal_params(&g).and_then(|p| Ok((p, smr_curve(&g, ctx.options.levels)?))) {
                Ok((params, bac)) => (
                    Some(SurfaceReport {
                        params,
                        bac,
                        recipe: format!(
                            "the degree 5/5 interpolating NURBS surface sampled on the data lines (their v) at half the x pitch ({model_cols} points per line, x(u) inverted numerically), then levelled and evaluated as surface_grid"
                        ),
                        bac_curves_recipe: Some(format!(
                            "paper Appendix A: {} iso-curves along x of the degree 5/5 interpolating surface at equally spaced v, each sampled at 8 points per control point along u, referenced to its x-weighted mean line, {} equal levels, crossings linear along x",
                            ctx.options.curves, ctx.options.levels
                        )),
                        bac_curves: Some(curves),
                    }),
                    None,
                    Some(model_z),
                ),
                Err(e) => (None, Some(e.to_string()), Some(model_z)),
            }
        }
        Err(msg) => (None, Some(msg), None),
    };
    if let Some(e) = &surface_error {
        ctx.warnings
            .push(format!("no model surface parameters: {e}"));
    }
    timings.model = t.elapsed().as_secs_f64();

    // Hold-out refits.
    let t = Instant::now();
    let (model_vs_measured, model_vs_measured_error) = match holdout(
        &grid.heights_um,
        cols,
        px,
        &grid.y_mm,
        FitOptions::default(),
    ) {
        Ok(mut h) => {
            for l in h
                .points_left_out
                .iter_mut()
                .chain(h.lines_left_out.iter_mut())
            {
                l.index = grid.index.get(l.index).copied().unwrap_or(l.index as u32) as usize;
            }
            (Some(h), None)
        }
        Err(e) => (None, Some(e.to_string())),
    };
    if let Some(h) = &model_vs_measured {
        let find =
            |v: &[HoldoutLine], index: u32| v.iter().find(|l| l.index == index as usize).cloned();
        for line in &mut lines {
            line.model_vs_measured = Some(LineHoldout {
                points_left_out: find(&h.points_left_out, line.index),
                line_left_out: find(&h.lines_left_out, line.index),
            });
        }
    }
    timings.holdout = t.elapsed().as_secs_f64();

    // Files.
    let t = Instant::now();
    let caption = caption(&ctx);
    let mut plots = Vec::new();
    let plot_err = |e: MetrologyError| ReportError::Metrology {
        what: format!("{}: plots", ctx.input),
        source: e,
    };
    let (bac_curves, pooled): (&[ModelCurveBac], &[[f64; 2]]) = match (&surface, &surface_grid) {
        (Some(s), _) => (s.bac_curves.as_deref().unwrap_or(&[]), &s.bac),
        (None, Some(g)) => (&[], &g.bac),
        (None, None) => (&[], &[]),
    };
    let bac_title = if bac_curves.is_empty() {
        "Bearing area curve of the measured grid, pooled".to_string()
    } else {
        format!(
            "Bearing area curves: {} model curves, pooled",
            bac_curves.len()
        )
    };
    plots.extend(
        plot_bearing_curves(out, bac_curves, pooled, &bac_title, &caption).map_err(plot_err)?,
    );
    plots.extend(plot_height_map(out, &measured, "Measured heights", &caption).map_err(plot_err)?);
    let overlay_row = match ctx.options.overlay_line {
        Some(i) => match grid.index.iter().position(|&k| k == i) {
            Some(r) => r,
            None => {
                ctx.warnings.push(format!(
                    "overlay line {i} is not among the lines used ({:?}); the middle line is drawn",
                    grid.index
                ));
                rows / 2
            }
        },
        None => rows / 2,
    };
    if let Some(model_z) = &model_z {
        let measured_pts: Vec<(f64, f64)> = grid
            .heights_um
            .get(overlay_row * cols..(overlay_row + 1) * cols)
            .unwrap_or(&[])
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 * px, *v))
            .collect();
        let model_pts: Vec<(f64, f64)> = model_z
            .get(overlay_row * model_cols..(overlay_row + 1) * model_cols)
            .unwrap_or(&[])
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 * px / 2.0, *v))
            .collect();
        let index = grid.index.get(overlay_row).copied().unwrap_or(0);
        let title = format!(
            "Line {} ({index:04}, y = {} mm): measured and model",
            line_number(index),
            nfmt(
                grid.y_mm.get(overlay_row).copied().unwrap_or(f64::NAN),
                Quantity::PositionMm
            )
        );
        plots.extend(
            plot_profile_overlay(out, &measured_pts, &model_pts, &[], &title, &caption)
                .map_err(plot_err)?,
        );
    }
    // The ISO 13565-2 construction of every line, from the ordinates its Rk family came from.
    let rk_dir = out.join("rk");
    std::fs::create_dir_all(&rk_dir).map_err(|source| ReportError::Io {
        path: rk_dir.clone(),
        source,
    })?;
    let mut rk_plots = Vec::new();
    for (row, a) in analyses.iter().enumerate() {
        let index = grid.index.get(row).copied().unwrap_or(row as u32);
        let rk = rk_family(&a.roughness_um).map_err(plot_err)?;
        let title = format!(
            "Line {} ({index:04}, y = {} mm): ISO 13565-2 Rk construction",
            line_number(index),
            nfmt(
                grid.y_mm.get(row).copied().unwrap_or(f64::NAN),
                Quantity::PositionMm
            )
        );
        let files = plot_rk_construction(
            &rk_dir,
            &format!("{index:04}"),
            &material_ratio_curve(&a.roughness_um, 1001),
            &rk,
            &title,
            &caption,
        )
        .map_err(plot_err)?;
        rk_plots.push((title, files));
    }
    let measured_x3p = out.join("measured.x3p");
    let bytes = to_x3p(
        &grid.heights_um,
        rows,
        cols,
        px,
        py,
        &x3p_meta(&ctx, "measured heights as traced"),
    )
    .map_err(metrology(format!("{}: measured.x3p", ctx.input)))?;
    write_file(&measured_x3p, &bytes)?;
    let model_x3p = match &model_z {
        Some(model_z) => {
            let path = out.join("model.x3p");
            let bytes = to_x3p(
                model_z,
                rows,
                model_cols,
                px / 2.0,
                py,
                &x3p_meta(
                    &ctx,
                    "NURBS model sampled at half the x pitch on the data lines",
                ),
            )
            .map_err(metrology(format!("{}: model.x3p", ctx.input)))?;
            write_file(&path, &bytes)?;
            Some(path)
        }
        None => None,
    };
    let summary = out.join("summary.csv");
    write_file(&summary, summary_csv(&lines).as_bytes())?;
    timings.write = t.elapsed().as_secs_f64();
    timings.total = t_all.elapsed().as_secs_f64();

    let report = Report {
        software: software(),
        input: ctx.input.clone(),
        kind: ctx.kind,
        recipe: ReportRecipe {
            lines: recipe,
            lambda_c_source: ctx.lambda_c_source.clone(),
            filter_reason: ctx.filter_reason.clone(),
        },
        lines,
        surface,
        surface_error,
        surface_grid,
        surface_grid_error,
        model_vs_measured,
        model_vs_measured_error,
        traceability: ctx.traceability.clone(),
        scan: ctx.scan.clone(),
        fit: ctx.options.fit.clone(),
        warnings: ctx.warnings.clone(),
        timings_s: timings,
    };
    let report_json = out.join("report.json");
    let mut json = serde_json::to_vec_pretty(&report)?;
    json.push(b'\n');
    write_file(&report_json, &json)?;

    // The report for people, with the plots embedded and the scan's journal.
    let journal = (ctx.kind == "scan")
        .then(|| {
            let path = Path::new(&ctx.input).join(crate::scan::journal::JOURNAL_FILE);
            read_journal(&path)
                .and_then(|r| ResumeState::from_records(&path, &r.records))
                .ok()
        })
        .flatten();
    let pair = |stem: &str| {
        (
            out.join(format!("{stem}.png")),
            out.join(format!("{stem}.svg")),
        )
    };
    let mut figures = Vec::new();
    for (stem, title) in [
        ("heightmap", "Measured heights"),
        ("bac", "Material ratio curves"),
        ("overlay", "One line: measured and model"),
    ] {
        let (png, svg) = pair(stem);
        figures.extend(html::Figure::from_files(title, &png, &svg, false));
    }
    for (title, [png, svg]) in &rk_plots {
        figures.extend(html::Figure::from_files(title.clone(), png, svg, true));
    }
    let value = serde_json::to_value(&report)?;
    let report_html = out.join("report.html");
    write_file(
        &report_html,
        html::render(
            &value,
            journal.as_ref(),
            &figures,
            ctx.options.completing.then(chrono::Utc::now),
        )
        .as_bytes(),
    )?;
    plots.extend(rk_plots.into_iter().flat_map(|(_, files)| files));
    Ok(ScanOutputs {
        report_json,
        report_html,
        summary_csv: summary,
        plots,
        measured_x3p: Some(measured_x3p),
        model_x3p,
        lines_used: grid.index.clone(),
        incomplete_lines: ctx
            .scan
            .as_ref()
            .map(|s| s.lines_incomplete.clone())
            .unwrap_or_default(),
        warnings: ctx.warnings,
        elapsed_s: t_all.elapsed().as_secs_f64(),
    })
}

fn model_error(e: &FitError) -> String {
    format!("the NURBS fit failed: {e}")
}

/// The complete lines of a scan directory as one grid, with the incomplete ones named.
/// Every line must have the same number of points and the same x pitch (they are one grid);
/// a line that differs is named.
pub fn load_scan_grid(dir: &Path) -> Result<(LineGrid, Vec<StoredLine>, Vec<u32>), ReportError> {
    if !dir.join("lines").is_dir() {
        return Err(ReportError::Lines {
            path: dir.to_path_buf(),
            reason: "is not a scan directory: it has no lines/ folder (a scan holds lines/NNNN.csv + NNNN.json and journal.jsonl)".to_string(),
        });
    }
    let store = ScanStore::open(dir, Arc::new(NoFaults))?;
    let loaded = store.load_all()?;
    let Some(first) = loaded.lines.first() else {
        return Err(ReportError::NoLines {
            dir: dir.to_path_buf(),
            incomplete: loaded.incomplete,
        });
    };
    let (cols, px) = (first.meta.points, first.meta.pitch_x_mm);
    let mut heights_um = Vec::with_capacity(cols * loaded.lines.len());
    for l in &loaded.lines {
        let path = store.lines_dir().join(csv_name(l.meta.index));
        if l.meta.points != cols {
            return Err(ReportError::Lines {
                path,
                reason: format!(
                    "has {} points, line {} has {cols}; every line of a scan must have the same number of points to form a grid",
                    l.meta.points, first.meta.index
                ),
            });
        }
        if (l.meta.pitch_x_mm - px).abs() > 1e-12 * px.abs().max(1.0) {
            return Err(ReportError::Lines {
                path,
                reason: format!(
                    "pitch x {} mm differs from line {}'s {px} mm; every line of a scan must share the x pitch",
                    l.meta.pitch_x_mm, first.meta.index
                ),
            });
        }
        heights_um.extend_from_slice(&l.profile.heights_um);
    }
    let grid = LineGrid {
        heights_um,
        cols,
        pitch_x_mm: px,
        y_mm: loaded.lines.iter().map(StoredLine::y_mm).collect(),
        index: loaded.lines.iter().map(|l| l.meta.index).collect(),
        y_readback_mm: loaded
            .lines
            .iter()
            .map(|l| l.meta.y_readback_nm.map(|n| n.to_mm()))
            .collect(),
        instrument: Some(
            loaded
                .lines
                .iter()
                .map(|l| l.meta.results.clone())
                .collect(),
        ),
        standard: loaded
            .lines
            .iter()
            .map(|l| l.meta.conditions.standard.clone())
            .collect(),
    };
    Ok((grid, loaded.lines, loaded.incomplete))
}

/// How the lines of a scan are evaluated: λc from the override, else the recorded
/// conditions, else 0.8 mm; the λc filter unless `no_filter`, the profile is an R profile
/// (already λc-filtered by the instrument) or the recorded filter is none. Returns the
/// options and, for the recipe, where λc came from and why the filter was or was not applied.
pub fn scan_line_options(
    line: &StoredLine,
    options: &ScanAnalysisOptions,
) -> (Options, String, String) {
    let mut o = Options::from_profile(&line.profile);
    let recorded = line.profile.conditions.lambda_c_mm;
    let lambda_c_source = match (options.lambda_c_mm, recorded) {
        (Some(lc), Some(r)) => {
            o.lambda_c_mm = lc;
            format!("given ({lc} mm, overriding the recorded {r} mm)")
        }
        (Some(lc), None) => {
            o.lambda_c_mm = lc;
            format!("given ({lc} mm; the instrument recorded none)")
        }
        (None, Some(r)) => format!("the instrument's recorded conditions ({r} mm)"),
        (None, None) => format!(
            "default {} mm (the instrument recorded no λc; set --lc to choose)",
            o.lambda_c_mm
        ),
    };
    let kind = line.meta.kind;
    let (apply, filter_reason) = if options.no_filter {
        (false, "no λc filter: asked for (--no-filter)".to_string())
    } else if kind == ProfileKind::R {
        (
            false,
            "no λc filter: the instrument exported an R profile, already λc-filtered".to_string(),
        )
    } else if line.profile.conditions.filter == Some(FilterKind::None) {
        (
            false,
            "no λc filter: the instrument's conditions record the filter as none".to_string(),
        )
    } else {
        (
            true,
            format!("λc filter applied: the stored profile is of kind {kind:?}, not an R profile"),
        )
    };
    o.apply_lambda_c = apply;
    (o, lambda_c_source, filter_reason)
}

/// Characterises the scan in `dir` (a partial, aborted or failed one with the complete lines
/// it has) and writes `report.json`, `summary.csv`, the plots, `measured.x3p` and `model.x3p`
/// into the scan directory (or `options.out_dir`). Returns the paths and the warnings.
pub fn characterise_scan(
    dir: &Path,
    options: &ScanAnalysisOptions,
) -> Result<ScanOutputs, ReportError> {
    let t = Instant::now();
    let (grid, lines, incomplete) = load_scan_grid(dir)?;
    let mut warnings = Vec::new();
    if !incomplete.is_empty() {
        warnings.push(format!(
            "lines {incomplete:?} have only one of their two files in {} and were left out",
            dir.join("lines").display()
        ));
    }
    let journal_path = dir.join(crate::scan::journal::JOURNAL_FILE);
    let state = match read_journal(&journal_path)
        .and_then(|rec| ResumeState::from_records(&journal_path, &rec.records))
    {
        Ok(s) => Some(s),
        Err(e) => {
            warnings.push(format!("no traceability: the journal cannot be used ({e})"));
            None
        }
    };
    let first = lines.first().ok_or_else(|| ReportError::NoLines {
        dir: dir.to_path_buf(),
        incomplete: incomplete.clone(),
    })?;
    let (line_options, lambda_c_source, filter_reason) = scan_line_options(first, options);
    if let Some(l) = lines
        .iter()
        .find(|l| l.meta.conditions != first.meta.conditions || l.meta.kind != first.meta.kind)
    {
        warnings.push(format!(
            "line {} was traced under other conditions than line {}; every line is evaluated as line {} ({})",
            l.meta.index, first.meta.index, first.meta.index, filter_reason
        ));
    }
    let lines_used: Vec<u32> = grid.index.clone();
    let scan = state.as_ref().map(|s| {
        let lines_planned = s
            .start
            .plan
            .get("lines")
            .and_then(serde_json::Value::as_u64);
        let stopped_ok = match &s.stop {
            Some(st) => st.status == StopStatus::Success,
            None => options.completing,
        };
        let complete = stopped_ok
            && incomplete.is_empty()
            && lines_planned.is_none_or(|n| n == lines_used.len() as u64);
        ScanStatus {
            status: if complete { "complete" } else { "partial" },
            stop: s.stop.clone(),
            lines_planned,
            lines_used: lines_used.clone(),
            lines_incomplete: incomplete.clone(),
            lines_in_journal: s.lines.iter().map(|l| l.index).collect(),
        }
    });
    if let Some(s) = &scan {
        if s.status == "partial" {
            warnings.push(format!(
                "partial scan ({}): characterised with the {} lines it has",
                match &s.stop {
                    Some(st) => format!(
                        "stopped: {}, {}",
                        format!("{:?}", st.status).to_lowercase(),
                        st.reason
                    ),
                    None => "no stop record".to_string(),
                },
                lines_used.len()
            ));
        }
    }
    let load_s = t.elapsed().as_secs_f64();
    let ctx = ReportContext {
        input: dir.display().to_string(),
        kind: "scan",
        line_options,
        lambda_c_source,
        filter_reason,
        traceability: state.as_ref().map(|s| Traceability::from(&s.start)),
        scan,
        options: options.clone(),
        warnings,
    };
    let out = options.out_dir.clone().unwrap_or_else(|| dir.to_path_buf());
    let mut outputs = characterise_grid(&grid, ctx, &out)?;
    outputs.elapsed_s += load_s;
    Ok(outputs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::Profile;
    use crate::scan::line::LineMeta;
    use crate::units::Nm;

    fn line(kind: ProfileKind, lambda_c_mm: Option<f64>, filter: Option<FilterKind>) -> StoredLine {
        let conditions = Conditions {
            lambda_c_mm,
            filter,
            ..Conditions::default()
        };
        let t = chrono::Utc::now();
        StoredLine {
            meta: LineMeta {
                index: 0,
                y_target_nm: Nm(0),
                y_readback_nm: None,
                pitch_x_mm: 0.001,
                points: 3,
                kind,
                conditions: conditions.clone(),
                results: Vec::new(),
                readout_warnings: Vec::new(),
                started_at: t,
                finished_at: t,
                attempt: 1,
            },
            profile: Profile {
                pitch_x_mm: 0.001,
                heights_um: vec![0.0; 3],
                kind,
                conditions,
            },
        }
    }

    #[test]
    fn the_recorded_kind_and_filter_decide_and_the_options_override() {
        let defaults = ScanAnalysisOptions::default();
        let (o, src, why) = scan_line_options(&line(ProfileKind::P, Some(2.5), None), &defaults);
        assert!(o.apply_lambda_c && o.lambda_c_mm == 2.5, "{o:?}");
        assert!(
            src.contains("recorded") && why.contains("applied"),
            "{src} / {why}"
        );

        let (o, _, why) = scan_line_options(&line(ProfileKind::R, Some(0.8), None), &defaults);
        assert!(!o.apply_lambda_c && why.contains("R profile"), "{why}");

        let (o, _, why) = scan_line_options(
            &line(ProfileKind::P, None, Some(FilterKind::None)),
            &defaults,
        );
        assert!(!o.apply_lambda_c && why.contains("none"), "{why}");

        let (o, src, _) = scan_line_options(&line(ProfileKind::P, None, None), &defaults);
        assert!(o.lambda_c_mm == 0.8 && src.contains("default"), "{src}");

        let forced = ScanAnalysisOptions {
            lambda_c_mm: Some(0.25),
            no_filter: true,
            ..ScanAnalysisOptions::default()
        };
        let (o, src, why) = scan_line_options(&line(ProfileKind::P, Some(0.8), None), &forced);
        assert!(!o.apply_lambda_c && o.lambda_c_mm == 0.25, "{o:?}");
        assert!(src.contains("overriding the recorded 0.8"), "{src}");
        assert!(why.contains("--no-filter"), "{why}");
    }

    #[test]
    fn mean_pitch_flags_uneven_lines() {
        assert_eq!(mean_pitch_y(&[0.0, 0.01, 0.02]), (0.01, true));
        let (p, even) = mean_pitch_y(&[0.0, 0.01, 0.03]);
        assert!((p - 0.015).abs() < 1e-15 && !even);
        assert_eq!(mean_pitch_y(&[0.5]), (1.0, true));
    }
}
