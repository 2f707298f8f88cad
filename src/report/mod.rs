//! Characterisation reports: a scan (when it completes, from the runner's own lines and
//! surface; or read back from its directory by `surfscan analyze SCAN_DIR`) or a height grid
//! is characterised line by line and as a surface, and the results are written next to the
//! data: `report.json` (atomically), `summary.csv`, `bac|heightmap|overlay.png|svg`,
//! `measured.x3p` and `model.x3p`.
//!
//! The characterisation is a sequence of sections, each in its own file, each filling its
//! part of the typed [`Report`]:
//!
//! - [`lines`]: per-line ISO 4287 / ISO 13565-2 parameters under the names of
//!   [`RoughnessParams`](crate::metrology::params::RoughnessParams), `Rmr_table`, and for
//!   scans the instrument's own results beside ours (`instrument`, with `ours − instrument`);
//! - [`areal`]: `surface_grid`, the areal parameters and pooled bearing curve of the measured
//!   grid as traced;
//! - [`model`]: `surface`, the areal parameters of the NURBS model the caller fitted (for a
//!   scan the surface of `surface.igs`, at the plan's degrees) and the paper's per-curve
//!   bearing tables `bac_curves`;
//! - [`holdout`]: `model_vs_measured`, refits at the same degrees with points or lines left
//!   out (each line also carries its own share) — the only fits the report makes;
//! - [`files`]: the plots, the X3P files, `summary.csv`, `report.json` and `report.html` (the
//!   report for people, plots embedded: [`html`]).
//!
//! `report.json` also holds `recipe` (filter, λc and why, a definition id per parameter),
//! for scans `traceability` (from the journal's start record) and `scan` (stop record,
//! `complete`/`partial`, lines used and incomplete), `fit` (degrees, knots, poles, residual,
//! the IGES files when the scan wrote them), `warnings` and `timings_s`. The scan-facing
//! entry points are in [`scan_dir`].
//!
//! Layer 4 (reporting at the process edge): depends on [`crate::scan`] (its records, lines
//! and the characterisation contract of its runner), [`crate::metrology`], [`crate::fit`]
//! and [`crate::atomic`].

pub mod areal;
pub mod context;
pub mod document;
pub mod error;
pub mod holdout;
pub mod lines;
pub mod model;
pub mod outliers;
pub mod render;
pub mod scan_dir;

pub use context::{Model, ReportContext, ScanAnalysisOptions};
pub use document::{manufacturer_of, Report, ScanStatus, Traceability};
pub use error::ReportError;
pub use scan_dir::{characterise_scan, scan_line_options, ScanCharacteriser};

use crate::grid::Grid;
use crate::metrology::anisotropy::anisotropy;
use crate::metrology::MetrologyError;
use document::{Characterisation, FailedSection, ModelReport, Timings};
use render::software;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What a characterisation wrote and used.
#[derive(Debug, Clone)]
pub struct ScanOutputs {
    /// The report as written to `report.json`.
    pub report: Report,
    /// `report.json`.
    pub report_json: PathBuf,
    /// `report.html`, the report for people (plots embedded).
    pub report_html: PathBuf,
    /// `summary.csv`.
    pub summary_csv: PathBuf,
    /// The PNG and SVG plots written.
    pub plots: Vec<PathBuf>,
    /// `measured.x3p`, when the grid could be written (every height finite).
    pub measured_x3p: Option<PathBuf>,
    /// `model.x3p`, when the NURBS model could be sampled.
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

/// Characterises a grid of lines with `model` (the surface fitted through them, or why there
/// is none) and writes every output into `out`: the work behind the scan entry points of
/// [`scan_dir`] and `surfscan analyze GRID.csv`.
///
/// Sections fail alone: a failure in a model section (the fit, the model's bearing curves or
/// areal parameters, the hold-out refits, the verdict) never removes the per-line
/// parameters, the measured grid's areal parameters, `measured.x3p` or the plots of the
/// data; each failure is named in `warnings` and in `characterisation.failed_sections`, and
/// [`ScanOutputs::complete`] is false. A section the grid has too few lines for (no fit
/// below degree-v + 1 lines, no hold-out without lines to spare) is named in `warnings` and
/// `characterisation.sections_not_possible` instead: it is not a failure.
pub fn characterise(
    grid: &Grid,
    model: Model<'_>,
    mut ctx: ReportContext,
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
    let mut timings = Timings::default();
    let (rows, cols) = (grid.rows(), grid.cols);
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
    let mut failed_sections: Vec<FailedSection> = Vec::new();
    let (py, evenly) = grid.mean_pitch_y();
    // The model section (the densest work: the fold check, the model's bearing curves, the
    // sampled model) reads only the grid and the model: it runs beside every section below,
    // from the start. It never unwinds (a panic becomes its failure), so an early error
    // return below, which joins it, cannot turn into a panic.
    let model_options = ctx.options.clone();
    std::thread::scope(|scope| {
        let model_thread = scope.spawn(|| {
            let t = Instant::now();
            let m = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                model::characterise(
                    &model,
                    &grid.heights_um,
                    rows,
                    cols,
                    grid.pitch_x_mm,
                    py,
                    &model_options,
                )
            }))
            .unwrap_or_else(|_| model_section_panicked());
            (m, t.elapsed().as_secs_f64())
        });

        // Spikes, judged on each line's roughness profile; bridged for characterisation only
        // when asked for.
        let t = Instant::now();
        let outliers = outliers::characterise(grid, &ctx);
        outliers::warn(
            &outliers,
            model.replaced,
            grid.pitch_x_mm,
            &mut ctx.warnings,
        );
        // The lines are filtered; the surface as traced is not (no areal λc filter fits the
        // few tenths of a mm a scan covers in y): say so where the two kinds of numbers meet.
        if ctx.line_options.apply_lambda_c {
            ctx.warnings.push(format!(
                "the line parameters are of the λc {} mm roughness profiles, but the areal parameters, the surface model and its bearing area curves, the height map and the X3P files are of the heights as traced, levelled by a plane: form and waviness longer than λc are in them",
                ctx.line_options.lambda_c_mm
            ));
        }
        let bridged = if ctx.options.exclude_spikes && !outliers.spikes.is_empty() {
            Some(outliers::bridged(grid, &outliers.spikes))
        } else {
            None
        };
        let cgrid = bridged.as_ref().unwrap_or(grid);

        let lines::LinesSection {
            recipe,
            lines: mut line_reports,
            analyses,
        } = lines::characterise(cgrid, &ctx)?;
        timings.lines = t.elapsed().as_secs_f64();
        // The Rk figures need only the line analyses: they are drawn while the sections below
        // are made.
        let rk_ctx = ctx.clone();
        let map_ctx = ctx.clone();
        let rk_plots = scope.spawn(move || render::write_rk_plots(out, grid, &analyses, &rk_ctx));
        // So is the height map, which needs only the data.
        let map_grid = areal::measured(grid, py);
        let height_map = scope.spawn(move || render::draw_height_map(out, &map_grid, &map_ctx));

        let t = Instant::now();
        if !evenly {
            let y: Vec<String> = grid
                .y_mm
                .iter()
                .map(|y| crate::numfmt::fmt(*y, crate::numfmt::Quantity::PositionMm))
                .collect();
            ctx.warnings.push(format!(
            "the lines are not equally spaced in y (y = {} mm); the areal parameters, the height map and the X3P files use the mean pitch {} mm",
            y.join(", "),
            crate::numfmt::fmt(py, crate::numfmt::Quantity::LengthMm)
        ));
        }
        let measured = areal::measured(grid, py);
        let characterised = areal::measured(cgrid, py);
        let surface_grid = areal::characterise(&characterised, ctx.options.levels);
        if let Err(e) = &surface_grid {
            failed_sections.push(FailedSection {
                section: "surface_grid".into(),
                reason: e.clone(),
            });
        }
        let anisotropy = match anisotropy(&characterised) {
            Ok(a) => {
                if a.slopes_untrustworthy() {
                    if let Some(c) = a.caveats.last() {
                        ctx.warnings.push(c.clone());
                    }
                }
                Some(a)
            }
            Err(e) => {
                failed_sections.push(FailedSection {
                    section: "anisotropy".into(),
                    reason: e.to_string(),
                });
                None
            }
        };
        timings.surface_grid = t.elapsed().as_secs_f64();

        // The two hold-out sections are independent of the model section (each reads the
        // grid and the model, none writes anything) and run beside it. They share one refit
        // (every k-th line left out), made once beside the every-2nd-point refit.
        let sq = surface_grid.as_ref().map(|s| s.params.sq_um).ok();
        let options = &ctx.options;
        let ((model_section, model_s), (model_vs_measured, verdict, holdout_s)) = {
            let t = Instant::now();
            let (model_vs_measured, verdict) = holdout::characterise_and_judge(
                grid,
                &cgrid.heights_um,
                &model.recipe,
                sq,
                options.holdout_threshold,
            );
            let holdout_s = t.elapsed().as_secs_f64();
            let model = model_thread
                .join()
                .unwrap_or_else(|_| (model_section_panicked(), 0.0));
            (model, (model_vs_measured, verdict, holdout_s))
        };
        failed_sections.extend(model_section.failed.iter().cloned());
        if let Some(c) = &model_section.checks {
            ctx.warnings.extend(c.warnings());
        }
        timings.model = model_s;
        if let Ok(h) = &model_vs_measured {
            holdout::attach(&mut line_reports, h);
        }
        timings.holdout = holdout_s;
        for (section, r) in [
            ("model_vs_measured", model_vs_measured.as_ref().err()),
            ("between_lines", verdict.as_ref().err()),
        ] {
            if let Some(e) = r {
                failed_sections.push(FailedSection {
                    section: section.into(),
                    reason: e.clone(),
                });
            }
        }
        // The overlay draws the model at a held-out line: the rows are still the grid's here.
        let overlay = render::held_out_overlay(
            grid,
            &cgrid.heights_um,
            &model.recipe,
            verdict.as_ref().ok(),
            &mut ctx,
        );
        let mut verdict = verdict;
        if let Ok(b) = &mut verdict {
            holdout::rows_to_lines(grid, b);
            if !b.supported {
                ctx.warnings.push(b.verdict.clone());
            }
        }
        // What the line count rules out is not a failure: the fit needs degree-v + 1 lines, the
        // hold-outs more than that once lines are left out.
        let q = model.recipe.degrees.degree_v;
        let fit_possible = rows > q;
        let holdout_possible =
            fit_possible && crate::metrology::holdout::holdout_every(rows, q).is_some();
        let (not_possible, failed_sections): (Vec<FailedSection>, Vec<FailedSection>) =
            failed_sections.into_iter().partition(|f| {
                match f.section.split('.').next().unwrap_or_default() {
                    "surface" => !fit_possible,
                    "model_vs_measured" | "between_lines" => !holdout_possible,
                    _ => false,
                }
            });
        for f in &not_possible {
            ctx.warnings.push(format!(
                "{} not made ({rows} lines are too few): {}",
                f.section, f.reason
            ));
        }
        for f in &failed_sections {
            ctx.warnings
                .push(format!("{} could not be made: {}", f.section, f.reason));
        }

        let (surface, surface_error) = split(model_section.surface);
        let (surface_grid, surface_grid_error) = split(surface_grid);
        let (model_vs_measured, model_vs_measured_error) = split(model_vs_measured);
        let (between_lines, between_lines_error) = split(verdict);
        let mut report = Report {
            software: software(),
            input: ctx.input.clone(),
            kind: ctx.kind,
            recipe,
            lines: line_reports,
            surface,
            surface_error,
            surface_grid,
            surface_grid_error,
            model_vs_measured,
            model_vs_measured_error,
            between_lines,
            between_lines_error,
            model: ModelReport {
                v_method: model.recipe.method,
                description: model.recipe.describe(),
                degree_u: model.recipe.degrees.degree_u,
                degree_v: model.recipe.degrees.degree_v,
                spikes_replaced: model.replaced.to_vec(),
            },
            model_checks: model_section.checks,
            outliers,
            anisotropy,
            characterisation: Characterisation {
                complete: failed_sections.is_empty() && !grid.is_partial(),
                lines_in_input: grid.lines_in_input(),
                lines_left_out: grid.left_out.clone(),
                failed_sections,
                sections_not_possible: not_possible,
            },
            traceability: ctx.traceability.clone(),
            scan: ctx.scan.clone(),
            fit: ctx.fit.clone(),
            warnings: Vec::new(),
            timings_s: Timings::default(),
        };

        let t = Instant::now();
        let rk_panic = render::rk_plot_panic(&ctx);
        let height_map = height_map
            .join()
            .unwrap_or_else(|_| Err(render::height_map_panic(&ctx)));
        let written = render::write_data_files(
            out,
            grid,
            height_map,
            move || rk_plots.join().unwrap_or(Err(rk_panic)),
            &measured,
            model_section.sampled.as_ref(),
            overlay.as_ref(),
            &report,
            &mut ctx,
        )?;
        timings.write = t.elapsed().as_secs_f64();
        // The fit came before this call; it is part of the whole.
        timings.fit = model.fit_s;
        timings.total = t_all.elapsed().as_secs_f64() + model.fit_s;
        report.warnings = ctx.warnings.clone();
        report.timings_s = timings;
        render::write_report(out, &written, &report, &ctx)?;
        let mut plots = written.plots;
        plots.extend(written.rk_plots.into_iter().flat_map(|(_, files)| files));
        Ok(ScanOutputs {
            report_json: written.report_json,
            report_html: written.report_html,
            summary_csv: written.summary_csv,
            plots,
            measured_x3p: Some(written.measured_x3p),
            model_x3p: written.model_x3p,
            lines_used: grid.index.clone(),
            incomplete_lines: ctx
                .scan
                .as_ref()
                .map(|s| s.lines_incomplete.clone())
                .unwrap_or_default(),
            warnings: ctx.warnings,
            elapsed_s: t_all.elapsed().as_secs_f64() + model.fit_s,
            report,
        })
    })
}

/// The model section when it panicked: a failed `surface` section that says so.
fn model_section_panicked() -> model::ModelSection {
    let reason = "internal: the model section panicked; report this with the input".to_string();
    model::ModelSection {
        surface: Err(reason.clone()),
        sampled: None,
        checks: None,
        failed: vec![FailedSection {
            section: "surface".into(),
            reason,
        }],
    }
}

impl ScanOutputs {
    /// True when every section of the characterisation was made.
    pub fn complete(&self) -> bool {
        self.report.characterisation.complete
    }

    /// The verdict on the surface between lines in one line for a terminal, or why there is
    /// none.
    pub fn verdict_line(&self) -> String {
        match (&self.report.between_lines, &self.report.between_lines_error) {
            (Some(b), _) => b.short(),
            (None, Some(e)) => format!("no verdict on the model between lines: {e}"),
            (None, None) => "no verdict on the model between lines".to_string(),
        }
    }
}

fn split<T>(r: Result<T, String>) -> (Option<T>, Option<String>) {
    match r {
        Ok(v) => (Some(v), None),
        Err(e) => (None, Some(e)),
    }
}
