//! What a completed scan leaves besides its lines, in one pass from memory: the fitter's
//! surface is written as IGES ([`super::surface_files`]) with the scan's traceability in its
//! Start section, and the characterisation ([`Characterise`], supplied by the composition
//! layer) is given the lines the runner holds and that same surface. No line file is read
//! back and nothing is refitted here. Without a characterisation, or when it fails,
//! `report.json` holds the fit summary and the instrument's own results per line.
//!
//! Layer 3 (session): depends on [`crate::fit`], [`crate::grid`] (the lines as one grid),
//! [`crate::metrology::surface_model`] (a fit other than the paper's), [`super::surface_files`],
//! [`super::traceability`], [`super::line`] and [`crate::atomic`].

use super::journal::StartRecord;
use super::line::StoredLine;
use super::plan::Plan;
use super::surface_files::{write_surface_files, SurfaceWriteError, WrittenIges};
use super::traceability::{traceability_json, traceability_lines};
use crate::atomic::write_json_atomically;
use crate::fit::{
    max_residual_mm, FitError, FitOptions, FitResult, IncrementalFitter, MethodError,
};
use crate::grid::Grid;
use crate::iges::IgesOptions;
use crate::metrology::holdout::BetweenLines;
use crate::metrology::outliers::LineSpike;
use crate::metrology::surface_model::{fit_model, ModelRecipe};
use crate::nurbs::NurbsSurface;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The degrees, knot-vector lengths and pole counts of a surface, for fit reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct SurfaceShape {
    /// Degree along u (x).
    pub degree_u: usize,
    /// Degree along v (y).
    pub degree_v: usize,
    /// Length of the u knot vector.
    pub knots_u_len: usize,
    /// Length of the v knot vector.
    pub knots_v_len: usize,
    /// Poles along u.
    pub poles_u: usize,
    /// Poles along v.
    pub poles_v: usize,
}

impl SurfaceShape {
    /// The shape of `s`.
    pub fn of(s: &NurbsSurface) -> SurfaceShape {
        SurfaceShape {
            degree_u: s.degree_u(),
            degree_v: s.degree_v(),
            knots_u_len: s.knots_u().len(),
            knots_v_len: s.knots_v().len(),
            poles_u: s.count_u(),
            poles_v: s.count_v(),
        }
    }
}

/// Lines and points per line of a fitted grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct GridShape {
    /// Lines.
    pub rows: usize,
    /// Points per line.
    pub cols: usize,
}

/// Seconds per stage of a fit and of writing it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitTimes {
    /// Chord lengths and parameters.
    pub fit_params: f64,
    /// Knot vectors and factorisations.
    pub fit_knots_factor: f64,
    /// Solves along u.
    pub fit_solve_u: f64,
    /// Solves along v.
    pub fit_solve_v: f64,
    /// The whole final fit (the incremental part ran while the lines arrived).
    pub finish: f64,
    /// Writing the IGES file(s), when they were written.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub write_iges: Option<f64>,
}

/// The fit a scan's outputs describe: the `fit` section of `report.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitSummary {
    /// The grid fitted.
    pub grid: GridShape,
    /// Largest distance between the surface and a measured point, mm.
    pub max_residual_mm: f64,
    /// The IGES files written (none when only characterised).
    pub iges_files: Vec<WrittenIges>,
    /// Seconds per stage.
    pub timings_s: FitTimes,
    /// Degrees, knots and poles.
    #[serde(flatten)]
    pub shape: SurfaceShape,
}

impl FitSummary {
    /// The summary of `fit` through a `rows × cols` grid.
    pub fn new(
        fit: &FitResult,
        grid: GridShape,
        max_residual_mm: f64,
        finish_s: f64,
        iges_files: Vec<WrittenIges>,
        write_iges_s: Option<f64>,
    ) -> FitSummary {
        FitSummary {
            grid,
            max_residual_mm,
            iges_files,
            timings_s: FitTimes {
                fit_params: fit.timings.params_s,
                fit_knots_factor: fit.timings.knots_factor_s,
                fit_solve_u: fit.timings.solve_u_s,
                fit_solve_v: fit.timings.solve_v_s,
                finish: finish_s,
                write_iges: write_iges_s,
            },
            shape: SurfaceShape::of(&fit.surface),
        }
    }
}

/// A completed scan as the characterisation receives it.
#[derive(Debug, Clone, Copy)]
pub struct CompletedScan<'a> {
    /// The scan directory (where the files go).
    pub dir: &'a Path,
    /// Its start record.
    pub start: &'a StartRecord,
    /// Its lines, in index order, exactly as committed.
    pub lines: &'a [StoredLine],
    /// The surface written to `surface.igs`, with its data parameters.
    pub fit: &'a FitResult,
    /// How that surface was made (the plan's degrees, method across the lines and spike
    /// replacement), which the hold-out refits follow too.
    pub recipe: ModelRecipe,
    /// The spikes replaced before fitting (empty unless the plan asks for it).
    pub replaced: &'a [LineSpike],
    /// The fit summary for the report.
    pub summary: &'a FitSummary,
}

/// What a characterisation wrote besides `report.json`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Characterised {
    /// The other files (summary, plots, X3P).
    pub files: Vec<PathBuf>,
    /// What was left out or approximated, for the operator.
    pub warnings: Vec<String>,
    /// Every section was made (`false`: report.json's `characterisation` names the failed
    /// ones).
    pub complete: bool,
    /// The verdict on the surface between lines in one line, or why there is none.
    pub verdict: String,
    /// The verdict against the specification, the means and the warnings in a few figures.
    pub results: Option<super::results::ScanResults>,
}

/// The characterisation of a completed scan, supplied by the composition layer: it writes
/// `report.json` and its files into the scan directory.
pub trait Characterise: Send + Sync {
    /// Characterises `scan`.
    fn characterise(
        &self,
        scan: &CompletedScan<'_>,
    ) -> Result<Characterised, Box<dyn std::error::Error + Send + Sync>>;
}

/// The files a completed scan wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Outputs {
    /// The IGES file(s), in v order.
    pub iges: Vec<PathBuf>,
    /// `report.json`.
    pub report: PathBuf,
    /// Other files of the characterisation (summary, plots, X3P).
    pub files: Vec<PathBuf>,
    /// Why the characterisation could not be made, when it could not (the report then
    /// holds the fit and the instrument's own results only).
    pub characterisation_error: Option<String>,
    /// The characterisation was made and every section of it (`false` when it failed or
    /// some section failed).
    pub characterisation_complete: bool,
    /// The verdict on the surface between lines in one line, or why there is none.
    pub verdict: String,
    /// What the characterisation found in a few figures (none without one).
    pub results: Option<super::results::ScanResults>,
    /// Largest distance between the surface and a measured point, mm.
    pub max_residual_mm: f64,
}

/// Why the outputs of a completed scan could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputsError {
    /// The lines cannot be interpolated.
    #[error("fit: {0}")]
    Fit(#[from] FitError),
    /// The lines cannot be fitted with the plan's method across the lines.
    #[error("fit: {0}")]
    Method(#[from] MethodError),
    /// The IGES file(s) cannot be written.
    #[error(transparent)]
    Iges(#[from] SurfaceWriteError),
    /// `report.json` cannot be written.
    #[error("cannot write {path}: {source}")]
    Report {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

impl OutputsError {
    /// True when the disk refused (full, read-only), not the data.
    pub fn is_io(&self) -> bool {
        matches!(
            self,
            OutputsError::Report { .. } | OutputsError::Iges(SurfaceWriteError::Io { .. })
        )
    }
}

/// The heights of `lines` as one row-major grid (µm) and their y (mm).
/// How the plan says the surface is made; the spike rule judges the roughness profile the
/// lines are evaluated on (λc-filtered when they are primary profiles).
pub fn recipe_of(plan: &Plan, lines: &[StoredLine]) -> ModelRecipe {
    let lambda_c_mm = lines.first().and_then(|l| {
        let o = crate::metrology::params::Options::from_profile(&l.profile);
        o.apply_lambda_c.then_some(o.lambda_c_mm)
    });
    ModelRecipe {
        degrees: FitOptions::degrees(plan.degree_u, plan.degree_v),
        method: plan.v_method,
        replace_spikes: plan.replace_spikes,
        lambda_c_mm,
    }
}

/// The scan's committed lines as the one [`Grid`] (each line was checked against the plan as
/// it was committed, so they share their points and x pitch), for the fit and its residual.
fn grid_of(lines: &[StoredLine]) -> Grid {
    let cols = lines.first().map_or(0, |l| l.profile.len());
    let mut z = Vec::with_capacity(lines.len() * cols);
    for l in lines {
        z.extend_from_slice(&l.profile.heights_um);
    }
    let pitch_x_mm = lines.first().map_or(f64::NAN, |l| l.profile.pitch_x_mm);
    Grid {
        index: lines.iter().map(|l| l.meta.id.index).collect(),
        ..Grid::new(
            z,
            cols,
            pitch_x_mm,
            lines.iter().map(StoredLine::y_mm).collect(),
        )
    }
}

/// Finishes the fit, writes the IGES, then the characterisation (or, without one or when it
/// fails, a `report.json` with the fit and the instrument's own results) into the scan
/// directory `dir`. `lines` are the scan's lines as committed, the ones `fitter` holds.
pub fn write_outputs(
    dir: &Path,
    start: &StartRecord,
    plan: &Plan,
    fitter: IncrementalFitter,
    lines: &[StoredLine],
    characterise: Option<&dyn Characterise>,
) -> Result<Outputs, OutputsError> {
    let t_fit = Instant::now();
    let grid = grid_of(lines);
    let recipe = recipe_of(plan, lines);
    // The paper's surface is the incremental fitter's; anything else is fitted here from the
    // lines as committed.
    let (fit, replaced) = if recipe.is_paper() {
        (fitter.finish()?, Vec::new())
    } else {
        drop(fitter);
        let m = fit_model(&grid, &recipe)?;
        (m.fit, m.replaced)
    };
    let finish_s = t_fit.elapsed().as_secs_f64();
    let residual = if lines.is_empty() {
        f64::NAN
    } else {
        max_residual_mm(&fit, &grid)
    };
    let cols = grid.cols;
    drop(grid);
    let iges_path = dir.join("surface.igs");
    let mut start_lines = traceability_lines(start, plan);
    start_lines.extend(recipe.start_lines(&replaced));
    let opts = IgesOptions {
        start_lines,
        timestamp: chrono::Utc::now().naive_utc(),
        ..IgesOptions::default()
    };
    let t_write = Instant::now();
    let files = write_surface_files(&iges_path, &fit.surface, &opts)?;
    let write_s = t_write.elapsed().as_secs_f64();
    let iges_files: Vec<PathBuf> = files.iter().map(|f| f.path.clone()).collect();
    let summary = FitSummary::new(
        &fit,
        GridShape {
            rows: lines.len(),
            cols,
        },
        residual,
        finish_s,
        files,
        Some(write_s),
    );
    let report_path = dir.join("report.json");
    let mut characterisation_error = None;
    if let Some(ch) = characterise {
        let scan = CompletedScan {
            dir,
            start,
            lines,
            fit: &fit,
            recipe,
            replaced: &replaced,
            summary: &summary,
        };
        match ch.characterise(&scan) {
            Ok(done) => {
                for w in &done.warnings {
                    tracing::warn!("characterisation: {w}");
                }
                return Ok(Outputs {
                    iges: iges_files,
                    report: report_path,
                    files: done.files,
                    characterisation_error: None,
                    characterisation_complete: done.complete,
                    verdict: done.verdict,
                    results: done.results,
                    max_residual_mm: residual,
                });
            }
            Err(e) => {
                tracing::error!("characterisation of {} failed: {e}", dir.display());
                characterisation_error = Some(e.to_string());
            }
        }
    }
    let line_json: Vec<serde_json::Value> = lines
        .iter()
        .map(|l| {
            serde_json::json!({
                "index": l.meta.id.index,
                "y_mm": l.y_mm(),
                "y_readback_mm": l.meta.id.y_readback_nm.map(|n| n.to_mm()),
                "points": l.meta.id.points,
                "attempt": l.meta.id.attempt,
                "instrument": l.meta.results,
            })
        })
        .collect();
    let report = serde_json::json!({
        "software": start.software_version,
        "traceability": traceability_json(start),
        "fit": summary,
        "model": {
            "description": recipe.describe(),
            "v_method": recipe.method,
            "spikes_replaced": replaced,
        },
        "lines": line_json,
        "characterisation_error": characterisation_error,
    });
    write_json_atomically(&report_path, &report).map_err(|source| OutputsError::Report {
        path: report_path.clone(),
        source,
    })?;
    Ok(Outputs {
        iges: iges_files,
        report: report_path,
        files: Vec::new(),
        verdict: BetweenLines::line(Err(Some(
            characterisation_error
                .as_deref()
                .unwrap_or("no characterisation was run"),
        ))),
        characterisation_error,
        characterisation_complete: false,
        results: None,
        max_residual_mm: residual,
    })
}
