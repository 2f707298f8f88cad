//! The renderers: every file of a characterisation, made from the section results — plots
//! (bearing curves, height map, measured vs model of one line, the Rk construction of each
//! line: [`plots`]; the PSD, the ACF and the 3D view beside the areal parameters:
//! [`areal_plots`]), the contact's `contact.json` and figures ([`contact`]), `measured.x3p` and `model.x3p` ([`crate::x3p`]), `summary.csv`
//! ([`summary`]), `report.json` and `report.html` ([`html`], laid out for paper by
//! [`print`]), each replaced atomically. Nothing here computes a result; the numbers come from
//! the sections. The files for the lab's quality systems (DFQ, QIF) are not made from the
//! sections but from a completed scan's directory read back: [`crate::publish`] makes them.
//!
//! Layer 4 (reporting): depends on [`crate::x3p`], [`crate::atomic`] and the report's types.

pub mod areal_plots;
pub mod contact;
pub mod decimate;
pub mod html;
pub mod plots;
pub mod print;
pub mod summary;
pub mod text_cache;

use super::context::ReportContext;
use super::document::{FigureData, Report};
use super::error::{io, metrology, ReportError};
use super::header::LabHeader;
use super::sections::overlay::Overlay;
use crate::atomic::write_atomically;
use crate::grid::Grid;
use crate::input::scan::read_scan_journal;
use crate::metrology::areal::HeightMap;
use crate::metrology::model::ModelCurveBac;
use crate::metrology::params::LineAnalysis;
use crate::metrology::MetrologyError;
use crate::numfmt::{fmt as nfmt, line_number, Quantity};
use crate::x3p::{x3p, X3pMeta};
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
    /// Every plot written, the Rk constructions last (their PNGs only with `[report]
    /// line-png`).
    pub plots: Vec<PathBuf>,
    /// The Rk construction of each line: its title and its PNG (written only when
    /// `[report] line-png` asks for it) and SVG.
    pub rk_plots: Vec<(String, [PathBuf; 2])>,
    /// `measured.x3p`.
    pub measured_x3p: PathBuf,
    /// `model.x3p`, when the model could be sampled.
    pub model_x3p: Option<PathBuf>,
}

fn caption(ctx: &ReportContext) -> String {
    match &ctx.traceability {
        Some(t) => {
            let c = &t.conditions;
            let cond: Vec<String> = [
                c.standard.clone(),
                c.filter.map(|f| format!("{f:?}")),
                c.lambda_c_mm.map(|l| format!("λc {l} mm")),
                c.lambda_s_um.map(|l| format!("λs {l} µm")),
                // The SJ series' N = 0: an arbitrary evaluation length, one section.
                c.sampling_lengths.map(|n| match n {
                    0 => "arbitrary evaluation length".to_string(),
                    n => format!("N = {n}"),
                }),
            ]
            .into_iter()
            .flatten()
            .collect();
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
        None => format!("{} · {}", ctx.input, crate::build_info::software()),
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
                    "{what}; specimen {}; scan {}; operator {}; notes: {}; drive unit {}; conditions {}; scanned by {}, config sha256 {}; written by {}",
                    t.specimen,
                    t.scan_id,
                    t.operator,
                    t.notes,
                    t.drive_unit,
                    conditions,
                    t.software_version,
                    t.config_hash,
                    crate::build_info::software()
                ),
            }
        }
        None => X3pMeta {
            date: chrono::Utc::now().to_rfc3339(),
            version: crate::build_info::software(),
            comment: format!("{what} of {}", ctx.input),
            ..X3pMeta::default()
        },
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    write_atomically(path, |w| w.write_all(bytes)).map_err(io(path))
}

/// The plots: bearing curves (the model's when there are any, else the measured grid's
/// pooled curve), the measured height map and the overlay of one line: a held-out line with
/// the model refitted without it when the hold-out could be made, else (with a model) a data
/// line, which the model interpolates by construction.
fn write_plots(
    out: &Path,
    height_map: Result<Vec<PathBuf>, ReportError>,
    overlay: Option<&Overlay>,
    report: &Report,
    ctx: &ReportContext,
) -> Result<Vec<PathBuf>, ReportError> {
    let caption = caption(ctx);
    let mut plots = Vec::new();
    let plot_err = metrology(format!("{}: plots", ctx.input));
    let (bac_curves, pooled): (&[ModelCurveBac], &[[f64; 2]]) =
        match (&report.surface, &report.surface_grid) {
            (Some(s), _) => (s.bac_curves.as_deref().unwrap_or(&[]), &s.bac),
            (None, Some(g)) => (&[], &g.bac),
            (None, None) => (&[], &[]),
        };
    let bac_title = match bac_curves.len() {
        0 => "Bearing area curve of the measured grid, pooled".to_string(),
        n => format!("Bearing area curves: {n} model curves, pooled"),
    };
    if !(bac_curves.is_empty() && pooled.is_empty()) {
        let bac = plot_bearing_curves(out, bac_curves, pooled, &bac_title, &caption);
        plots.extend(bac.map_err(&plot_err)?);
    }
    plots.extend(height_map?);
    // The spatial curves of the measured grid, drawn beside its areal parameters.
    if let Some(Ok(spatial)) = report.surface_grid.as_ref().map(|g| &g.spatial) {
        let curves = &spatial.curves;
        let title = "Power spectral density of the measured grid";
        let psd = areal_plots::plot_psd(out, curves, title, &caption);
        plots.extend(psd.map_err(&plot_err)?);
        let title = "Autocorrelation of the measured grid";
        let acf = areal_plots::plot_acf(out, curves, spatial.s, title, &caption);
        plots.extend(acf.map_err(&plot_err)?);
    }
    if let Some(o) = overlay {
        let (title, caption) = (&o.title, &caption);
        let overlay = plot_profile_overlay(out, &o.measured, &o.model, &o.residual, title, caption);
        plots.extend(overlay.map_err(&plot_err)?);
    }
    Ok(plots)
}

/// The error of a renderer's `thread` that panicked making `file` of the input `input`;
/// `hint` says what it was doing.
fn panicked(input: &str, file: &str, thread: &'static str, hint: &'static str) -> ReportError {
    metrology(format!("{input}: {file}"))(MetrologyError::BadParameter {
        what: thread,
        value: f64::NAN,
        hint,
    })
}

/// The height map of the measured grid, `heightmap.png|svg`, and its 3D view,
/// `surface3d.png|svg`, listed between the bearing area curves and the overlay; none for a
/// grid of fewer than 2 × 2 points.
fn draw_height_map(
    out: &Path,
    measured: &HeightMap<'_>,
    origin_mm: (f64, f64),
    ctx: &ReportContext,
) -> Result<Vec<PathBuf>, ReportError> {
    let err = metrology(format!("{}: plots", ctx.input));
    // One profile is no map: its figure is its assessed profile.
    if measured.rows < 2 || measured.cols < 2 {
        return Ok(Vec::new());
    }
    let mut files = plot_height_map(out, measured, origin_mm, "Measured heights", &caption(ctx))
        .map_err(&err)?
        .to_vec();
    let (view, _) = areal_plots::plot_surface_view(
        out,
        measured,
        origin_mm,
        "Measured surface, 3D view",
        &caption(ctx),
    )
    .map_err(&err)?;
    files.extend(view);
    Ok(files)
}

/// The ISO 13565-2 construction of every line, from the ordinates its Rk family came from:
/// `rk/NNNN.svg` (and `rk/NNNN.png` when `[report] line-png` asks for it), with each figure's
/// title. Drawn as the lines' section ends ([`super::sections::run`]): the analyses are then
/// dropped and their pages given back before the areal sections; [`write_data_files`] reports
/// the result in its turn.
pub fn write_rk_plots(
    out: &Path,
    grid: &Grid,
    analyses: Vec<LineAnalysis>,
    ctx: &ReportContext,
) -> Result<Vec<(String, [PathBuf; 2])>, ReportError> {
    let rk_dir = out.join("rk");
    std::fs::create_dir_all(&rk_dir).map_err(io(&rk_dir))?;
    // The figures are independent: drawn in parallel over the available cores, one run of
    // consecutive lines per thread, joined in line order (the first error in line order wins).
    let caption = caption(ctx);
    let plot_err = metrology(format!("{}: plots", ctx.input));
    let draw = |row: usize, a: &LineAnalysis| {
        let index = grid.index_of(row);
        let title = rk_title(index, grid.y_mm.get(row).copied().unwrap_or(f64::NAN));
        let profile = plots::AssessedProfile {
            z_um: &a.roughness_um,
            pitch_mm: a.recipe.pitch_mm,
            x0_mm: grid.x_mm(a.recipe.first_point),
            sampling_length_mm: a.recipe.section_length_mm,
            sampling_lengths: a.recipe.sampling_lengths,
            kind: a.recipe.profile,
        };
        let files = plot_rk_construction(
            plots::FigureFiles {
                dir: &rk_dir,
                stem: &format!("{index:04}"),
                png: ctx.lab.line_png,
            },
            &a.rk_curve,
            &a.params.material.rk,
            Some(&profile),
            &title,
            &caption,
        )
        .map_err(&plot_err)?;
        Ok((title, files))
    };
    let hint = "drawing the Rk figures panicked; report this with the input";
    let panicked = |_| Err(panicked(&ctx.input, "plots", "Rk plot thread", hint));
    let drawn = crate::metrology::map_in_parallel(&analyses, draw, panicked);
    drop(analyses);
    crate::fit::memory::release_free_heap();
    drawn.into_iter().collect()
}

/// The title of line `index`'s figure (its assessed profile and Rk construction).
fn rk_title(index: u32, y_mm: f64) -> String {
    let y = nfmt(y_mm, Quantity::PositionMm);
    let n = line_number(index);
    format!("Line {n} ({index:04}, y = {y} mm): assessed profile and ISO 13565-2 Rk construction")
}

/// Encodes `map` (`what` it holds) as `out/name` and writes it, streamed (the archive's bytes
/// are never held whole), its origin `grid`'s first point: the model is sampled on the
/// measured points. `model.x3p` is written as the model section samples it, before its areal
/// parameters take the heights ([`super::sections::run`]), and reported by
/// [`write_data_files`] in its turn.
pub fn write_x3p(
    out: &Path,
    name: &str,
    grid: &Grid,
    map: &HeightMap<'_>,
    ctx: &ReportContext,
    what: &str,
) -> Result<PathBuf, ReportError> {
    let path = out.join(name);
    let file = x3p(map, grid.origin_mm(), &x3p_meta(ctx, what));
    let file = file.map_err(metrology(format!("{}: {name}", ctx.input)))?;
    write_atomically(&path, |w| file.write_to(w)).map_err(io(&path))?;
    Ok(path)
}

/// The files of the measured grid alone, made by [`write_measured`]: its height map and 3D
/// view, and `measured.x3p`, each or why not; or why the earlier figures could not be removed
/// (then nothing was made).
pub struct Measured(Result<(HeightMapFiles, Result<PathBuf, ReportError>), ReportError>);

/// The height map's and the 3D view's files, or why not.
type HeightMapFiles = Result<Vec<PathBuf>, ReportError>;

/// Removes the figures an earlier analysis left ([`remove_earlier_outputs`]), then draws the
/// measured height map and its 3D view and writes `measured.x3p` (encoded on a thread of its
/// own): they read only the grid, so the caller makes them while the model's areal parameters
/// are still being made. [`write_data_files`] reports what they gave in its turn.
pub fn write_measured(out: &Path, grid: &Grid, ctx: &ReportContext) -> Measured {
    Measured(remove_earlier_outputs(out).map(|()| {
        let measured = &HeightMap::of(grid, grid.mean_pitch_y().0);
        std::thread::scope(|s| {
            let what = "measured heights as traced";
            let x3p = s.spawn(|| write_x3p(out, "measured.x3p", grid, measured, ctx, what));
            let height_map = s.spawn(|| draw_height_map(out, measured, grid.origin_mm(), ctx));
            let height_map = height_map.join().unwrap_or_else(|_| {
                let hint = "drawing the height map panicked; report this with the input";
                Err(panicked(&ctx.input, "plots", "height map thread", hint))
            });
            let x3p = x3p.join().unwrap_or_else(|_| {
                let hint = "encoding the X3P files panicked; report this with the input";
                Err(panicked(
                    &ctx.input,
                    "measured.x3p",
                    "X3P encoding thread",
                    hint,
                ))
            });
            (height_map, x3p)
        })
    }))
}

/// The files written while the sections ran, each or why not.
pub struct Early {
    /// The Rk figures.
    pub rk_plots: Result<Vec<(String, [PathBuf; 2])>, ReportError>,
    /// `model.x3p`, `None` when the model was not sampled.
    pub model_x3p: Option<Result<PathBuf, ReportError>>,
    /// The measured grid's own ([`write_measured`]).
    pub measured: Measured,
}

/// Writes the plots, the contact's files (when the report has a contact), then `summary.csv`,
/// with the files written before (`early`; an earlier `model.x3p` is removed when none was
/// written this time); `report.json` and `report.html` are written last by [`write_report`],
/// once the report's timings are final. Errors are reported in the order the files were
/// written: the plots, the Rk figures, then the X3P files.
pub fn write_data_files(
    out: &Path,
    grid: &Grid,
    report: &Report,
    figures: &FigureData,
    early: Early,
    ctx: &ReportContext,
) -> Result<Files, ReportError> {
    let Early {
        rk_plots,
        model_x3p,
        measured,
    } = early;
    let (height_map, measured_x3p) = measured.0?;
    if !matches!(model_x3p, Some(Ok(_))) {
        let path = out.join("model.x3p");
        remove_if_there(&path).map_err(io(&path))?;
    }
    let mut plots = write_plots(out, height_map, figures.overlay.as_ref(), report, ctx)?;
    let rk_plots = rk_plots?;
    let measured_x3p = measured_x3p?;
    let model_x3p = model_x3p.transpose()?;
    if let Some(c) = &report.contact {
        plots.extend(contact::write_contact_files(
            out,
            c,
            grid.origin_mm(),
            &ctx.input,
            &c.warnings(),
        )?);
    }
    let summary = out.join("summary.csv");
    write_file(
        &summary,
        summary_csv(&report.lines, report.specification.as_ref()).as_bytes(),
    )?;
    let line_png = ctx.lab.line_png;
    let rk_files = rk_plots
        .iter()
        .flat_map(|(_, [png, svg])| [line_png.then_some(png), Some(svg)]);
    plots.extend(rk_files.flatten().cloned());
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

/// The logo of `[report]`, read for embedding; a logo that cannot be read costs the logo
/// and adds a warning that says why and what to do, never the report.
pub fn read_logo(lab: &LabHeader, warnings: &mut Vec<String>) -> Option<html::Figure> {
    let path = lab.logo.as_ref()?;
    let Some(media_type) = lab.logo_media_type() else {
        warnings.push(format!(
            "[report] logo {}: not a PNG, JPEG or SVG file; the report is printed without a logo",
            path.display()
        ));
        return None;
    };
    match std::fs::read(path) {
        Ok(bytes) => Some(html::Figure {
            title: "logo".into(),
            media_type,
            bytes,
            ..html::Figure::default()
        }),
        Err(e) => {
            warnings.push(format!(
                "[report] logo {}: cannot be read ({e}); the report is printed without a logo — put the file there or correct the path",
                path.display()
            ));
            None
        }
    }
}

/// The size `report.html` keeps to when it embeds the per-line figures: those that would
/// take it beyond are linked to their files instead. A 31-line scan's Rk figures take about
/// 1.7 MB and are all embedded; a 1000-line grid's would make a page of tens of MB that a
/// browser opens slowly and a mail server refuses.
pub const REPORT_HTML_BYTES: usize = 4_500_000;

/// What one linked per-line figure adds to the page, at most (its `<details>` element).
const LINKED_FIGURE_HTML_BYTES: usize = 400;

/// The bytes of per-line figure files (before base64) that fit in [`REPORT_HTML_BYTES`]
/// beside a page of `page_bytes` without them, `lines` of them to link at most.
fn per_line_budget(page_bytes: usize, lines: usize) -> usize {
    REPORT_HTML_BYTES.saturating_sub(page_bytes + LINKED_FIGURE_HTML_BYTES * lines) / 4 * 3
}

/// The per-line figures of `report.html` in line order: each embedded while the file bytes
/// embedded stay within `budget`, the rest linked to their SVG file (a path relative to
/// `out`, where the report is); those of the lines `printed` (file indices) always embedded,
/// marked to print and counted against `budget` before any other.
fn per_line_figures(
    out: &Path,
    plots: &[(String, [PathBuf; 2])],
    budget: usize,
    printed: &[u32],
) -> Vec<html::Figure> {
    let is_printed = |png: &Path| {
        png.file_stem()
            .and_then(|s| s.to_str()?.parse::<u32>().ok())
            .is_some_and(|i| printed.contains(&i))
    };
    // The printed lines' figures are embedded whatever the budget: theirs comes off it first.
    let mut embedded: usize = plots
        .iter()
        .filter(|(_, [png, _])| is_printed(png))
        .filter_map(|(title, [png, svg])| html::Figure::from_files(title, png, svg, false))
        .map(|f| f.bytes.len())
        .sum();
    let mut budget_left = true;
    plots
        .iter()
        .filter_map(|(title, [png, svg])| {
            let print = is_printed(png);
            if budget_left || print {
                // A figure that cannot be read is left out, as any figure is.
                let mut f = html::Figure::from_files(title.clone(), png, svg, false)?;
                (f.collapsed, f.printed) = (true, print);
                if print {
                    return Some(f);
                }
                if embedded + f.bytes.len() <= budget {
                    embedded += f.bytes.len();
                    return Some(f);
                }
                budget_left = false;
            }
            let href = svg.strip_prefix(out).unwrap_or(svg);
            let href = href
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join("/");
            Some(html::Figure {
                title: title.clone(),
                collapsed: true,
                link: Some(href),
                ..html::Figure::default()
            })
        })
        .collect()
}

/// The figures a report's page shows open, in order: file stem, title, whether it is shown
/// beside the areal parameters, whether only a report with contact analysis has it.
const PAGE_FIGURES: [(&str, &str, bool, bool); 8] = [
    ("heightmap", "Measured heights", false, false),
    ("bac", "Material ratio curves", false, false),
    ("overlay", "One line: measured and model", false, false),
    ("load_area", "Contact: load–area curve", false, true),
    ("pressure", "Contact: pressure map", false, true),
    ("psd", "Power spectral density", true, false),
    ("acf", "Autocorrelation", true, false),
    ("surface3d", "3D view of the measured surface", true, false),
];

/// Removes what an earlier analysis left in `out` that this one writes only where it applies:
/// the [`PAGE_FIGURES`] (the page embeds what the folder holds; a profile analysed where a grid
/// was would show that grid's height map) and `contact.json`; `model.x3p` is removed by
/// [`write_data_files`] when none was written this time.
fn remove_earlier_outputs(out: &Path) -> Result<(), ReportError> {
    let figures = PAGE_FIGURES
        .iter()
        .flat_map(|(stem, ..)| ["png", "svg"].map(|ext| format!("{stem}.{ext}")));
    for name in figures.chain(["contact.json".into()]) {
        let path = out.join(name);
        remove_if_there(&path).map_err(io(&path))?;
    }
    Ok(())
}

/// Removes the file `path` unless there is none.
fn remove_if_there(path: &Path) -> std::io::Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        r => r,
    }
}

/// The figures of [`PAGE_FIGURES`] on screen only: the pooled material ratio curves
/// (summarised by the Sk family, drawn per line in the printed lines' Rk constructions) and
/// the line left out of the model (summarised by the model section's hold-out figures).
const SCREEN_ONLY: [&str; 2] = ["bac", "overlay"];

/// The figure `stem` of `dir` (`stem.png|svg`) titled `title`, read as
/// [`html::Figure::from_files`] reads it.
fn figure_file(dir: &Path, stem: &str, title: String, vector: bool) -> Option<html::Figure> {
    let [png, svg] = ["png", "svg"].map(|ext| dir.join(format!("{stem}.{ext}")));
    html::Figure::from_files(title, &png, &svg, vector)
}

/// The figures of [`PAGE_FIGURES`] that `dir` holds, the contact ones only when `report` (as
/// report.json holds it) has the measured grid's contact.
fn page_figures(dir: &Path, report: &serde_json::Value, vector: bool) -> Vec<html::Figure> {
    let contact = !report["contact"]["measured"].is_null();
    PAGE_FIGURES
        .iter()
        .filter(|f| contact || !f.3)
        .filter_map(|(stem, title, beside_areal, _)| {
            let f = figure_file(dir, stem, title.to_string(), vector)?;
            Some(html::Figure {
                beside_areal: *beside_areal,
                printed: !SCREEN_ONLY.contains(stem),
                ..f
            })
        })
        .collect()
}

/// The report written into `dir` (`report` as its report.json holds it) as the PDF of its
/// printed page, and what was left out of it: the page made again from the report, the
/// scan's journal and the plots' SVG files (so the figures are vector drawings; a figure
/// with only its PNG is an image), typeset by [`crate::pdf`]. Of the per-line figures, those
/// of the lines [`print::printed_lines`] names, as on the printed page.
pub fn report_pdf(
    dir: &Path,
    report: &serde_json::Value,
) -> Result<(Vec<u8>, Vec<String>), crate::pdf::PdfError> {
    let mut warnings = Vec::new();
    let journal = (report["kind"] == "scan")
        .then(|| {
            read_scan_journal(dir)
                .map_err(|e| {
                    let path = dir.join(crate::scan::journal::JOURNAL_FILE);
                    warnings.push(format!(
                        "{}: {e}; the PDF says nothing of what happened during the scan",
                        path.display()
                    ))
                })
                .ok()
        })
        .flatten();
    let open = page_figures(dir, report, true);
    let lines = report["lines"].as_array().map_or(&[][..], Vec::as_slice);
    let mut printed = Vec::new();
    for (index, _) in print::printed_lines(report).0 {
        let y = lines.iter().find(|l| l["index"] == index);
        let title = rk_title(
            index,
            y.and_then(|l| l["y_mm"].as_f64()).unwrap_or(f64::NAN),
        );
        let f = figure_file(&dir.join("rk"), &format!("{index:04}"), title, true);
        printed.extend(f.map(|f| html::Figure {
            collapsed: true,
            printed: true,
            ..f
        }));
    }
    let lab: LabHeader = serde_json::from_value(report["lab"].clone()).unwrap_or_default();
    let mut logo = read_logo(&lab, &mut warnings);
    if let (Some(f), Some(path)) = (&logo, &lab.logo) {
        if let Some(e) = crate::pdf::image_error(f.media_type, &f.bytes) {
            let path = path.display();
            warnings.push(format!(
                "[report] logo {path}: {e}; the report is printed without a logo"
            ));
            logo = None;
        }
    }
    let page = html::render(report, journal.as_ref(), &open, logo.as_ref(), |_| printed);
    let (left, software) = print::running(report);
    let running = crate::pdf::layout::Running {
        top_left: left.to_string(),
        top_right: html::title(report),
        bottom_left: software,
    };
    let title = format!("Surface report: {}", running.top_right);
    let letter = lab.paper == super::header::Paper::Letter;
    let creator = report["software"].as_str().unwrap_or("surfscan");
    let made =
        crate::pdf::html_to_pdf(&page, letter, &running, &title, creator, chrono::Utc::now())?;
    warnings.extend(made.warnings);
    Ok((made.pdf, warnings))
}

/// Writes `report.json`, then `report.html`, the report for people, with the plots embedded
/// and what the scan's journal recorded, headed by the laboratory's `logo`.
pub fn write_report(
    out: &Path,
    files: &Files,
    report: &Report,
    ctx: &ReportContext,
    logo: Option<&html::Figure>,
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
            .then(|| read_scan_journal(Path::new(&ctx.input)).ok())
            .flatten();
        let page = serde_json::to_value(report).map(|v| {
            let figures = page_figures(out, &v, false);
            let printed: Vec<u32> = print::printed_lines(&v).0.iter().map(|p| p.0).collect();
            html::render(&v, journal.as_ref(), &figures, logo, |bare| {
                let budget = per_line_budget(bare, files.rk_plots.len());
                per_line_figures(out, &files.rk_plots, budget, &printed)
            })
        });
        json.join().unwrap_or_else(|_| {
            let hint = "writing report.json panicked; report this with the input";
            Err(panicked(
                &ctx.input,
                "report.json",
                "report.json thread",
                hint,
            ))
        })?;
        write_file(&files.report_html, page?.as_bytes())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Per-line figures are embedded in line order while they fit in what the printed lines'
    /// figures leave of the budget; the first that does not and all after it are linked to
    /// their SVG file by a path relative to the report; a figure with no file is left out.
    #[test]
    fn per_line_figures_beyond_the_budget_are_linked_to_their_files() {
        let dir = tempfile::tempdir().unwrap();
        let rk = dir.path().join("rk");
        std::fs::create_dir(&rk).unwrap();
        let budget = 3_000_000;
        let size = budget / 3 + 1;
        let mut plots = Vec::new();
        for k in 0..5 {
            let [png, svg] = ["png", "svg"].map(|ext| rk.join(format!("{k:04}.{ext}")));
            if k != 1 {
                std::fs::write(&png, vec![1u8; size]).unwrap();
                std::fs::write(&svg, vec![b'<'; size + 10]).unwrap();
            }
            plots.push((format!("line {k}"), [png, svg]));
        }
        // Line 4 is one a print shows: embedded whatever the budget, and marked to print; its
        // bytes are set aside first, so the others embedded leave the page within its budget.
        let figures = per_line_figures(dir.path(), &plots, budget, &[4]);
        let embedded: usize = figures.iter().map(|f| f.bytes.len()).sum();
        assert!(
            embedded <= budget,
            "{embedded} bytes embedded, budget {budget}"
        );
        let shown: Vec<(&str, Option<&str>, usize, bool)> = figures
            .iter()
            .map(|f| {
                (
                    f.title.as_str(),
                    f.link.as_deref(),
                    f.bytes.len(),
                    f.printed,
                )
            })
            .collect();
        assert_eq!(
            shown,
            [
                ("line 0", None, size, false),
                ("line 2", Some("rk/0002.svg"), 0, false),
                ("line 3", Some("rk/0003.svg"), 0, false),
                ("line 4", None, size, true),
            ]
        );
        assert!(figures.iter().all(|f| f.collapsed));
        let page = html::render(&serde_json::json!({}), None, &[], None, |_| figures);
        assert!(
            page.contains("<a href=\"rk/0003.svg\">rk/0003.svg</a>"),
            "{page}"
        );
        assert_eq!(page.matches("data:image/png;base64,").count(), 2);
        assert_eq!(page.matches("<details class=\"print\">").count(), 1);
    }

    /// The room left for per-line figures: the page's limit less the page without them and a
    /// link's worth for each line, in file bytes (base64 takes 4 for 3).
    #[test]
    fn the_per_line_budget_is_what_the_page_leaves_in_file_bytes() {
        assert_eq!(per_line_budget(1_500_000, 0), 2_250_000);
        assert_eq!(
            per_line_budget(1_500_000, 1000),
            (3_000_000 - 400_000) / 4 * 3
        );
        assert_eq!(per_line_budget(REPORT_HTML_BYTES + 1, 3), 0);
    }

    #[test]
    fn a_logo_that_cannot_be_read_costs_the_logo_and_says_why() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("logo.png");
        std::fs::write(&png, b"\x89PNG").unwrap();
        let mut warnings = Vec::new();
        let lab = |p: &Path| LabHeader {
            logo: Some(p.to_path_buf()),
            ..LabHeader::default()
        };
        let f = read_logo(&lab(&png), &mut warnings).unwrap();
        assert_eq!((f.media_type, f.bytes.len()), ("image/png", 4));
        assert!(warnings.is_empty());
        let missing = dir.path().join("gone.svg");
        assert!(read_logo(&lab(&missing), &mut warnings).is_none());
        assert_eq!(warnings.len(), 1);
        assert!(
            warnings[0].contains("gone.svg") && warnings[0].contains("without a logo"),
            "{warnings:?}"
        );
        assert!(read_logo(&LabHeader::default(), &mut warnings).is_none());
        assert_eq!(warnings.len(), 1);
    }
}
