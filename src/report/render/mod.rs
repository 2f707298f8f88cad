//! The renderers: every file of a characterisation, made from the section results — plots
//! (bearing curves, height map, measured vs model of one line, the Rk construction of each
//! line: [`plots`]), `measured.x3p` and `model.x3p` ([`crate::x3p`]), `summary.csv`
//! ([`summary`]), `report.json` and `report.html` ([`html`]), each replaced atomically. Nothing
//! here computes a result; the numbers come from the sections.
//!
//! Layer 4 (reporting): depends on [`crate::x3p`], [`crate::atomic`] and the report's types.

pub mod html;
pub mod plots;
pub mod summary;
pub mod text_cache;

use super::context::ReportContext;
use super::document::Report;
use super::error::{metrology, ReportError};
use super::model::SampledModel;
use crate::atomic::write_atomically;
use crate::grid::Grid;
use crate::metrology::areal::HeightMap;
use crate::metrology::model::ModelCurveBac;
use crate::metrology::params::LineAnalysis;
use crate::metrology::MetrologyError;
use crate::numfmt::{fmt as nfmt, line_label, line_number, Quantity};
use crate::scan::journal::{read_journal, ResumeState};
use crate::x3p::{to_x3p, X3pMeta};
use plots::{plot_bearing_curves, plot_height_map, plot_profile_overlay, plot_rk_construction};
use std::io::Write;
use std::path::{Path, PathBuf};
use summary::summary_csv;

/// The files written.
#[derive(Debug, Clone, PartialEq)]
pub struct Files {
    /// `report.json`.
    pub report_json: PathBuf,
    /// `report.html`, the report for people (plots embedded).
    pub report_html: PathBuf,
    /// `summary.csv`.
    pub summary_csv: PathBuf,
    /// The PNG and SVG plots (the Rk constructions are in `rk_plots`).
    pub plots: Vec<PathBuf>,
    /// The Rk construction of each line: its title and its PNG and SVG.
    pub rk_plots: Vec<(String, [PathBuf; 2])>,
    /// `measured.x3p`.
    pub measured_x3p: PathBuf,
    /// `model.x3p`, when the model could be sampled.
    pub model_x3p: Option<PathBuf>,
}

pub(crate) fn software() -> String {
    crate::build_info::software()
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

/// The overlay's row: the requested line when it is among the rows (else a warning and the
/// middle row).
fn overlay_row(grid: &Grid, ctx: &mut ReportContext) -> usize {
    let rows = grid.rows();
    match ctx.options.overlay_line {
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
    }
}

/// The overlay of a held-out line: its measured heights, the model refitted without it and
/// the residual, as `(x_mm, z_um)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Overlay {
    /// Measured heights.
    pub measured: Vec<(f64, f64)>,
    /// The refit at the line.
    pub model: Vec<(f64, f64)>,
    /// Model − measured.
    pub residual: Vec<(f64, f64)>,
    /// Title naming the line and what the curve is.
    pub title: String,
}

/// The paper's Figure 2 made honest: the requested overlay line (or the middle one) left
/// out, the surface refitted without it the way the model was made, and drawn against the
/// line's measured heights. When that line cannot be left out (the first or last line) or
/// its refit fails, the held-out line of the verdict `b` nearest it is drawn instead, and a
/// warning says so. `heights_um` are the grid's rows as characterised.
pub fn held_out_overlay(
    grid: &Grid,
    heights_um: &[f64],
    recipe: &crate::metrology::surface_model::ModelRecipe,
    b: Option<&crate::metrology::holdout::BetweenLines>,
    ctx: &mut ReportContext,
) -> Option<Overlay> {
    let wanted = overlay_row(grid, ctx);
    let own = crate::metrology::holdout::model_without_line(
        heights_um,
        grid.cols,
        grid.pitch_x_mm,
        &grid.y_mm,
        recipe.degrees,
        recipe.method,
        wanted,
    );
    let (row, rms, model) = match own {
        Ok(m) => (wanted, m.line.rms_um, m.model_um),
        Err(e) => {
            let b = b?;
            let (k, line) = b
                .lines
                .iter()
                .enumerate()
                .min_by_key(|(_, l)| l.index.abs_diff(wanted))?;
            ctx.warnings.push(format!(
                "the overlay shows line {} (left out of the hold-out refit) instead of line {}: {e}",
                line_label(grid.index_of(line.index)),
                line_label(grid.index_of(wanted))
            ));
            (line.index, line.rms_um, b.model_line(k)?.to_vec())
        }
    };
    let px = grid.pitch_x_mm;
    let measured = heights_um.get(row * grid.cols..(row + 1) * grid.cols)?;
    Some(Overlay {
        measured: measured
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 * px, *v))
            .collect(),
        model: model
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 * px, *v))
            .collect(),
        residual: model
            .iter()
            .zip(measured)
            .enumerate()
            .map(|(i, (m, z))| (i as f64 * px, m - z))
            .collect(),
        title: format!(
            "Line {} ({:04}, y = {} mm) left out: its measured heights and the model refitted without it (rms {} µm)",
            line_number(grid.index_of(row)),
            grid.index_of(row),
            nfmt(
                grid.y_mm.get(row).copied().unwrap_or(f64::NAN),
                Quantity::PositionMm
            ),
            nfmt(rms, Quantity::HeightUm)
        ),
    })
}

/// The plots: bearing curves (the model's when there are any, else the measured grid's
/// pooled curve), the measured height map and the overlay of one line: a held-out line with
/// the model refitted without it when the hold-out could be made, else (with a model) a data
/// line, which the model interpolates by construction.
fn write_plots(
    out: &Path,
    grid: &Grid,
    height_map: Result<[PathBuf; 2], ReportError>,
    sampled: Option<&SampledModel>,
    overlay: Option<&Overlay>,
    report: &Report,
    ctx: &mut ReportContext,
) -> Result<Vec<PathBuf>, ReportError> {
    let caption = caption(ctx);
    let mut plots = Vec::new();
    let plot_err = |e: MetrologyError| ReportError::Metrology {
        what: format!("{}: plots", ctx.input),
        source: e,
    };
    let (bac_curves, pooled): (&[ModelCurveBac], &[[f64; 2]]) =
        match (&report.surface, &report.surface_grid) {
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
    plots.extend(height_map?);
    if let Some(o) = overlay {
        plots.extend(
            plot_profile_overlay(out, &o.measured, &o.model, &o.residual, &o.title, &caption)
                .map_err(plot_err)?,
        );
    } else if let Some(model) = sampled {
        let row = overlay_row(grid, ctx);
        let px = grid.pitch_x_mm;
        let measured_pts: Vec<(f64, f64)> = grid
            .row(row)
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 * px, *v))
            .collect();
        let model_pts: Vec<(f64, f64)> = model
            .heights_um
            .get(row * model.cols..(row + 1) * model.cols)
            .unwrap_or(&[])
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 * model.pitch_x_mm, *v))
            .collect();
        let index = grid.index.get(row).copied().unwrap_or(0);
        let title = format!(
            "Line {} ({index:04}, y = {} mm): measured and model (fitted through these points; no line could be held out)",
            line_number(index),
            nfmt(
                grid.y_mm.get(row).copied().unwrap_or(f64::NAN),
                Quantity::PositionMm
            )
        );
        let plot_err = |e: MetrologyError| ReportError::Metrology {
            what: format!("{}: plots", ctx.input),
            source: e,
        };
        plots.extend(
            plot_profile_overlay(out, &measured_pts, &model_pts, &[], &title, &caption)
                .map_err(plot_err)?,
        );
    }
    Ok(plots)
}

/// The error of the height map thread when it panicked.
pub(crate) fn height_map_panic(ctx: &ReportContext) -> ReportError {
    ReportError::Metrology {
        what: format!("{}: plots", ctx.input),
        source: MetrologyError::BadParameter {
            what: "height map thread",
            value: f64::NAN,
            hint: "drawing the height map panicked; report this with the input",
        },
    }
}

/// The error of an Rk figure thread that panicked.
pub(crate) fn rk_plot_panic(ctx: &ReportContext) -> ReportError {
    ReportError::Metrology {
        what: format!("{}: plots", ctx.input),
        source: MetrologyError::BadParameter {
            what: "Rk plot thread",
            value: f64::NAN,
            hint: "drawing the Rk figures panicked; report this with the input",
        },
    }
}

/// The height map of the measured grid, `heightmap.png|svg`: it needs only the data, so the
/// caller draws it while the model's sections are made and hands the result to
/// [`write_data_files`], which lists it between the bearing area curves and the overlay.
pub(crate) fn draw_height_map(
    out: &Path,
    measured: &HeightMap<'_>,
    ctx: &ReportContext,
) -> Result<[PathBuf; 2], ReportError> {
    plot_height_map(out, measured, "Measured heights", &caption(ctx)).map_err(|source| {
        ReportError::Metrology {
            what: format!("{}: plots", ctx.input),
            source,
        }
    })
}

/// The ISO 13565-2 construction of every line, from the ordinates its Rk family came from:
/// `rk/NNNN.png|svg`, with each figure's title (drawn by the caller beside the other
/// sections, handed to [`write_data_files`]).
pub(crate) fn write_rk_plots(
    out: &Path,
    grid: &Grid,
    analyses: &[LineAnalysis],
    ctx: &ReportContext,
) -> Result<Vec<(String, [PathBuf; 2])>, ReportError> {
    let caption = caption(ctx);
    let plot_err = |e: MetrologyError| ReportError::Metrology {
        what: format!("{}: plots", ctx.input),
        source: e,
    };
    let rk_dir = out.join("rk");
    std::fs::create_dir_all(&rk_dir).map_err(|source| ReportError::Io {
        path: rk_dir.clone(),
        source,
    })?;
    // The figures are independent: drawn in parallel over the available cores, one run of
    // consecutive lines per thread, joined in line order (the first error in line order wins).
    let workers = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, analyses.len().max(1));
    let chunk = analyses.len().div_ceil(workers).max(1);
    let draw = |first_row: usize, part: &[LineAnalysis]| {
        draw_rk_run(&rk_dir, grid, first_row, part, &caption, &plot_err)
    };
    if workers == 1 {
        return draw(0, analyses);
    }
    let parts: Vec<_> = std::thread::scope(|s| {
        let handles: Vec<_> = analyses
            .chunks(chunk)
            .enumerate()
            .map(|(k, part)| s.spawn(move || draw(k * chunk, part)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|_| Err(rk_plot_panic(ctx))))
            .collect()
    });
    let mut rk_plots = Vec::with_capacity(analyses.len());
    for part in parts {
        rk_plots.extend(part?);
    }
    Ok(rk_plots)
}

/// The Rk figures of the consecutive lines `part`, the first of them grid row `first_row`,
/// with their titles; stops at the first error.
fn draw_rk_run(
    rk_dir: &Path,
    grid: &Grid,
    first_row: usize,
    part: &[LineAnalysis],
    caption: &str,
    plot_err: &dyn Fn(MetrologyError) -> ReportError,
) -> Result<Vec<(String, [PathBuf; 2])>, ReportError> {
    let mut rk_plots = Vec::with_capacity(part.len());
    for (k, a) in part.iter().enumerate() {
        let row = first_row + k;
        let index = grid.index_of(row);
        let title = format!(
            "Line {} ({index:04}, y = {} mm): ISO 13565-2 Rk construction",
            line_number(index),
            nfmt(
                grid.y_mm.get(row).copied().unwrap_or(f64::NAN),
                Quantity::PositionMm
            )
        );
        let files = plot_rk_construction(
            rk_dir,
            &format!("{index:04}"),
            &a.rk_curve,
            &a.rk,
            &title,
            caption,
        )
        .map_err(plot_err)?;
        rk_plots.push((title, files));
    }
    Ok(rk_plots)
}

/// Writes the plots and X3P files (which may add warnings to `ctx`), then `summary.csv`;
/// `report.json` and `report.html` are written last by [`write_report`], once the warnings
/// are final. `height_map` is [`draw_height_map`]'s result. `rk_plots` gives the Rk figures'
/// result; it is asked for only once the other plots are drawn, so that a caller drawing the
/// Rk figures on another thread lets the two run side by side.
#[allow(clippy::too_many_arguments)]
pub fn write_data_files(
    out: &Path,
    grid: &Grid,
    height_map: Result<[PathBuf; 2], ReportError>,
    rk_plots: impl FnOnce() -> Result<Vec<(String, [PathBuf; 2])>, ReportError>,
    measured: &HeightMap<'_>,
    sampled: Option<&SampledModel>,
    overlay: Option<&Overlay>,
    report: &Report,
    ctx: &mut ReportContext,
) -> Result<Files, ReportError> {
    // The X3P files are encoded (MD5, deflate) and written beside the plots: they read only
    // the heights and their metadata. Errors are reported in the order the files were
    // written before: the plots, the Rk figures, then the X3P files.
    let measured_meta = x3p_meta(ctx, "measured heights as traced");
    let model_meta = x3p_meta(
        ctx,
        "NURBS model sampled at half the x pitch on the data lines",
    );
    let input = ctx.input.clone();
    let (plots, x3p) = std::thread::scope(|s| {
        let x3p = s.spawn(|| -> Result<(PathBuf, Option<PathBuf>), ReportError> {
            // Encodes one grid of heights at the grid's y pitch and writes it as `name`.
            let write = |name: &str, heights: &[f64], cols, pitch_x_mm, meta: &X3pMeta| {
                let path = out.join(name);
                let bytes = to_x3p(
                    heights,
                    measured.rows,
                    cols,
                    pitch_x_mm,
                    measured.pitch_y_mm,
                    meta,
                )
                .map_err(metrology(format!("{input}: {name}")))?;
                write_file(&path, &bytes)?;
                Ok::<_, ReportError>(path)
            };
            let measured_x3p = write(
                "measured.x3p",
                &grid.heights_um,
                measured.cols,
                measured.pitch_x_mm,
                &measured_meta,
            )?;
            let model_x3p = sampled
                .map(|m| {
                    write(
                        "model.x3p",
                        &m.heights_um,
                        m.cols,
                        m.pitch_x_mm,
                        &model_meta,
                    )
                })
                .transpose()?;
            Ok((measured_x3p, model_x3p))
        });
        let plots = write_plots(out, grid, height_map, sampled, overlay, report, ctx);
        (plots, x3p.join())
    });
    let rk_plots = rk_plots();
    let plots = plots?;
    let rk_plots = rk_plots?;
    let (measured_x3p, model_x3p) = x3p.map_err(|_| ReportError::Metrology {
        what: format!("{input}: measured.x3p"),
        source: MetrologyError::BadParameter {
            what: "X3P encoding thread",
            value: f64::NAN,
            hint: "encoding the X3P files panicked; report this with the input",
        },
    })??;
    let summary = out.join("summary.csv");
    write_file(&summary, summary_csv(&report.lines).as_bytes())?;
    Ok(Files {
        report_json: out.join("report.json"),
        report_html: out.join("report.html"),
        summary_csv: summary,
        plots,
        rk_plots,
        measured_x3p,
        model_x3p,
    })
}

/// Writes `report.json`, then `report.html`, the report for people, with the plots embedded
/// and what the scan's journal recorded.
pub fn write_report(
    out: &Path,
    files: &Files,
    report: &Report,
    ctx: &ReportContext,
) -> Result<(), ReportError> {
    // report.json is encoded and written (and synced) while the HTML page is put together; the
    // page is written only once report.json is on disk, and the errors come in that order.
    std::thread::scope(|s| {
        let json = s.spawn(|| -> Result<(), ReportError> {
            let mut json = serde_json::to_vec_pretty(report)?;
            json.push(b'\n');
            write_file(&files.report_json, &json)
        });
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
        for (title, [png, svg]) in &files.rk_plots {
            figures.extend(html::Figure::from_files(title.clone(), png, svg, true));
        }
        let page =
            serde_json::to_value(report).map(|v| html::render(&v, journal.as_ref(), &figures));
        json.join().unwrap_or_else(|_| {
            Err(ReportError::Metrology {
                what: format!("{}: report.json", ctx.input),
                source: MetrologyError::BadParameter {
                    what: "report.json thread",
                    value: f64::NAN,
                    hint: "writing report.json panicked; report this with the input",
                },
            })
        })?;
        write_file(&files.report_html, page?.as_bytes())
    })
}
