//! Characterisation reports: a scan (when it completes, from the runner's own lines and
//! surface; or read back from its directory by `surfscan analyze SCAN_DIR`) or a grid is
//! characterised line by line and as a surface, and the results are written next to the
//! data: `report.json` (atomically), `report.html`, `summary.csv`,
//! `bac|heightmap|overlay.png|svg`, the areal figures `psd|acf|surface3d.png|svg`,
//! `rk/NNNN.svg` (and `.png` with `[report] line-png`), `measured.x3p` and `model.x3p`.
//!
//! One pipeline, in three steps ([`characterise`]):
//!
//! 1. [`sections`]: each section a pure function of the [`Grid`] (and the fitted surface)
//!    returning a typed result — the spikes, the per-line parameters, the measured grid's areal
//!    parameters and anisotropy, the means' uncertainty and the verdict against the part's
//!    specification, the model, the hold-out and the verdict between lines, the line drawn
//!    against the model;
//! 2. [`document`]: the typed report (`report.json`'s shape) assembled from the results, with
//!    `recipe`, for scans `traceability` and `scan`, `fit`, `characterisation`, `warnings`
//!    and `timings_s`;
//! 3. [`render`]: every file made from the report and the figures' data, nothing computed.
//!
//! [`scan_dir`] holds the scan-facing entry points (a scan directory read back, the runner's
//! [`ScanCharacteriser`]); [`context`] what the pipeline is given besides the grid.
//!
//! Layer 4 (reporting at the process edge): depends on [`crate::grid`], [`crate::input`],
//! [`crate::scan`] (its records, lines and the characterisation contract of its runner),
//! [`crate::metrology`], [`crate::specification`], [`crate::fit`], [`crate::x3p`] and
//! [`crate::atomic`].

pub mod context;
pub mod document;
pub mod error;
pub mod header;
pub mod render;
pub mod scan_dir;
pub mod sections;

pub use context::{Model, ModelFit, ReportContext, ScanAnalysisOptions};
pub use document::Report;
pub use error::ReportError;
pub use scan_dir::{characterise_scan, ScanCharacteriser};

use crate::grid::Grid;
use crate::metrology::holdout::BetweenLines;
use crate::metrology::MetrologyError;
use std::path::Path;
use std::time::Instant;

/// What a characterisation wrote and used.
#[derive(Debug, Clone)]
pub struct ScanOutputs {
    /// The report as written to `report.json`.
    pub report: Report,
    /// The files written: `report.json`, `report.html`, `summary.csv`, the plots, the X3P
    /// files.
    pub files: render::Files,
    /// Line indices characterised.
    pub lines_used: Vec<u32>,
    /// Line indices with only one of their two files (left out).
    pub incomplete_lines: Vec<u32>,
    /// Everything that was left out or approximated, for the operator.
    pub warnings: Vec<String>,
    /// Wall-clock time of the whole characterisation, s.
    pub elapsed_s: f64,
}

/// Characterises a grid of lines with `fit` (the surface fitted through them as `model` says,
/// or why there is none) and writes every output into `out`: the work behind the scan entry
/// points of [`scan_dir`] and `surfscan analyze GRID.csv`. A `fit` handed over is dropped once
/// the model is sampled, unless the contact of the model between lines still needs it.
///
/// Sections fail alone: a failure in a model section (the fit, the model's bearing curves or
/// areal parameters, the hold-out refits, the verdict) never removes the per-line
/// parameters, the measured grid's areal parameters, `measured.x3p` or the plots of the
/// data; each failure is named in `warnings` and in `characterisation.failed_sections`, and
/// [`ScanOutputs::complete`] is false. A section the grid has too few lines for (no fit below
/// degree-v + 1 lines, no hold-out without lines to spare, no areal section or contact of one
/// line) is named in `warnings` and `characterisation.sections_not_possible` instead.
pub fn characterise(
    grid: &Grid,
    model: Model<'_>,
    fit: ModelFit<'_>,
    ctx: ReportContext,
    out: &Path,
) -> Result<ScanOutputs, ReportError> {
    // The figures drawn on this thread leave their texts in its memo; the next report (the
    // daemon's next scan) shares few of them, so they are forgotten however this returns.
    struct ForgetTexts;
    impl Drop for ForgetTexts {
        fn drop(&mut self) {
            crate::report::render::text_cache::forget();
        }
    }
    let _forget = ForgetTexts;
    let t_all = Instant::now();
    let (rows, cols) = (grid.rows(), grid.cols);
    if rows == 0 || cols == 0 || grid.heights_um.len() != rows * cols {
        return Err(error::metrology(&ctx.input)(MetrologyError::GridSize {
            rows,
            cols,
            expected: rows.saturating_mul(cols),
            got: grid.heights_um.len(),
        }));
    }
    std::fs::create_dir_all(out).map_err(error::io(out))?;
    let (sections, (rk_plots, rk_s), model_x3p, (measured, measured_s)) = sections::run(
        grid,
        &model,
        fit,
        &ctx,
        |analyses| timed(|| render::write_rk_plots(out, grid, analyses, &ctx)),
        |m| {
            let what = "NURBS model sampled at half the x pitch on the data lines";
            timed(|| render::write_x3p(out, "model.x3p", grid, m, &ctx, what))
        },
        || timed(|| render::write_measured(out, grid, &ctx)),
    )?;
    let (model_x3p, x3p_s) = model_x3p.unzip();
    let (mut report, figures) = document::assemble(sections, grid, &model, &ctx);
    let logo = render::read_logo(&report.lab, &mut report.warnings);
    let t = Instant::now();
    let early = render::Early {
        rk_plots,
        model_x3p,
        measured,
    };
    let written = render::write_data_files(out, grid, &report, &figures, early, &ctx)?;
    let before = rk_s + x3p_s.unwrap_or_default() + measured_s;
    let timings = &mut report.timings_s;
    timings.write = (t.elapsed() + before).as_secs_f64();
    // The fit came before this call; it is part of the whole.
    timings.fit = model.fit_s;
    timings.total = t_all.elapsed().as_secs_f64() + model.fit_s;
    render::write_report(out, &written, &report, &ctx, logo.as_ref())?;
    Ok(ScanOutputs {
        files: written,
        lines_used: grid.index.clone(),
        incomplete_lines: ctx
            .scan
            .as_ref()
            .map(|s| s.lines_incomplete.clone())
            .unwrap_or_default(),
        warnings: report.warnings.clone(),
        elapsed_s: t_all.elapsed().as_secs_f64() + model.fit_s,
        report,
    })
}

/// What `f` returns and how long it took.
fn timed<R>(f: impl FnOnce() -> R) -> (R, std::time::Duration) {
    let t = Instant::now();
    (f(), t.elapsed())
}

impl ScanOutputs {
    /// True when every section of the characterisation was made.
    pub fn complete(&self) -> bool {
        self.report.characterisation.complete
    }

    /// The verdict on the surface between lines in one line for a terminal, or why there is
    /// none.
    pub fn verdict_line(&self) -> String {
        let (b, e) = (&self.report.between_lines, &self.report.between_lines_error);
        BetweenLines::line(b.as_ref().ok_or(e.as_deref()))
    }
}
