//! The sections of the characterisation: each a pure function of one [`SectionInput`] — the
//! grid, the grid as characterised (spikes bridged when asked for), the model, the options —
//! and, where it needs them, of the results of the sections before it, returning a typed
//! result. Nothing here writes a file or prints; [`super::render`] makes every file from the
//! results.
//!
//! | Section (its report.json key) | File | Reads |
//! |---|---|---|
//! | spikes (`outliers`) | [`spikes`] | the grid |
//! | per-line parameters (`lines`, `recipe`) | [`lines`] | the grid as characterised |
//! | the measured grid (`surface_grid`, `anisotropy`) | [`surface_grid`] | the grid as characterised |
//! | the model (`surface`, `model_checks`) | [`surface`] | the model, the grid |
//! | hold-out and the verdict between lines (`model_vs_measured`, `between_lines`) | [`model_vs_measured`] | the grid as characterised, Sq of `surface_grid` |
//! | the line drawn against the model | [`overlay`] | the grid as characterised, `between_lines` |
//! | the contact of the grid and of the model between lines (`contact`, when asked for) | [`contact`] | the grid as characterised, the model, `between_lines` |
//! | the means' uncertainty and the verdict against the specification (`uncertainty`, `specification`) | [`specification`] | `lines`, the context's specification |
//!
//! [`run`] composes them — the model section beside the others, as it needs only the grid and the
//! model; the lines' analyses handed to the caller (for the Rk figures) as their section ends — and
//! collects the warnings and what failed. A section that fails never takes another down: its error
//! is its result, named in `characterisation.failed_sections`; what the number of lines rules out
//! is named in `characterisation.sections_not_possible` instead.
//!
//! Adding a section: a file here with `pub fn section(input: &SectionInput<'_>, …) ->
//! Result<T, String>` (its earlier results as further arguments), a field in [`Sections`], its
//! line in [`run`], and its rows in the renderers (docs/architecture.md says where).
//!
//! Layer 4 (reporting): depends on [`crate::grid`], [`crate::metrology`],
//! [`crate::specification`] and the report's types.

pub mod contact;
pub mod lines;
pub mod model_vs_measured;
pub mod overlay;
pub mod specification;
pub mod spikes;
pub mod surface;
pub mod surface_grid;

use super::context::{Model, ModelFit, ReportContext};
use super::document::{FailedSection, OutliersReport, SurfaceReport, Timings};
use super::error::ReportError;
use crate::grid::Grid;
use crate::metrology::anisotropy::Anisotropy;
use crate::metrology::areal::HeightMap;
use crate::metrology::holdout::{BetweenLines, Holdout};
use crate::metrology::params::LineAnalysis;
use std::time::Instant;

/// What every section reads.
#[derive(Debug, Clone, Copy)]
pub struct SectionInput<'a> {
    /// The grid as read: what the data files and the height map show.
    pub grid: &'a Grid,
    /// The grid as characterised: `grid` with its spikes bridged when the options exclude
    /// them, else `grid` itself.
    pub characterised: &'a Grid,
    /// The lines' mean y pitch, mm (the areal parameters, the height map and the X3P files
    /// use it).
    pub pitch_y_mm: f64,
    /// The surface the model sections describe.
    pub model: &'a Model<'a>,
    /// How the lines are evaluated, the options, what is known of the scan.
    pub ctx: &'a ReportContext,
}

/// Every section's result.
#[derive(Debug)]
pub struct Sections {
    /// The spikes of the lines.
    pub spikes: OutliersReport,
    /// The per-line parameters (the section every report has).
    pub lines: lines::LinesSection,
    /// The means with their uncertainty, and the verdict against the specification.
    pub specification: specification::SpecificationSection,
    /// The measured grid's areal parameters and pooled bearing curve.
    pub surface_grid: Result<SurfaceReport, String>,
    /// The measured grid's anisotropy.
    pub anisotropy: Result<Anisotropy, String>,
    /// The model: its areal parameters and bearing curves, its samples, its checks.
    pub surface: surface::ModelSection,
    /// The hold-out refits.
    pub model_vs_measured: Result<Holdout, String>,
    /// The verdict on the model between lines.
    pub between_lines: Result<BetweenLines, String>,
    /// The line drawn against the model.
    pub overlay: Option<overlay::Overlay>,
    /// The contact analysis, when the options ask for it.
    pub contact: Option<contact::ContactSection>,
    /// The sections that could not be made, and why.
    pub failed: Vec<FailedSection>,
    /// The sections the number of lines rules out, and why.
    pub not_possible: Vec<FailedSection>,
    /// What the operator should know, in order: the context's warnings, then the sections'.
    pub warnings: Vec<String>,
    /// Seconds per section.
    pub timings: Timings,
}

/// Runs every section on `grid` with `model`. An error only when the lines cannot be
/// characterised at all. The lines' analyses go to `draw_lines` (the caller draws their Rk
/// figures) as soon as their section is done and are not kept: a 1000-line grid's roughness
/// profiles and Rk curves (about 93 MB) are gone before the areal sections' buffers. The
/// model sampled on the data lines goes to `write_model` (the caller writes `model.x3p`) on
/// the model's thread before its areal parameters, whose autocorrelation grows from it: the
/// sampled model is not kept (what it returns comes back, `None` when it was not sampled).
/// The surface `fit` goes to the model's thread, which drops it (when it was handed over)
/// once the model is sampled unless the contact of the model between lines reads it after.
/// `while_waiting` (the caller writes the measured grid's own files) runs once every section
/// but the model's is done, while the model's areal parameters are still being made.
pub fn run<D, M: Send, W>(
    grid: &Grid,
    model: &Model<'_>,
    fit: ModelFit<'_>,
    ctx: &ReportContext,
    draw_lines: impl FnOnce(Vec<LineAnalysis>) -> D,
    write_model: impl FnOnce(&HeightMap<'_>) -> M + Send,
    while_waiting: impl FnOnce() -> W,
) -> Result<(Sections, D, Option<M>, W), ReportError> {
    let mut warnings = ctx.warnings.clone();
    let mut timings = Timings::default();
    let (pitch_y_mm, evenly) = grid.mean_pitch_y();
    let input = SectionInput {
        grid,
        characterised: grid,
        pitch_y_mm,
        model,
        ctx,
    };
    // The model section (the densest work: the fold check, the model's bearing curves) reads
    // only the grid and the model: it runs beside every section below, from the start. Where
    // the build unwinds (tests; the release profile aborts on any panic) a panic becomes its
    // failure, so an early error return below, which joins it, is no panic. It samples a
    // large model (twice the grid's bytes, at half the x pitch; its autocorrelation grows from
    // that to twice as much) only once the grid's sections, the hold-outs and the overlay are
    // done (`areal_go` sent, with the row of the overlay to draw from the sampled model when
    // no line was held out; or dropped by an early return): their buffers would otherwise be
    // held beside it. A small one is sampled before that wait (`surface::section`).
    let keep_fit = ctx.options.contact.as_ref();
    let keep_fit = keep_fit.is_some_and(|c| c.model_pitch_y_mm.is_some());
    let no_fit = fit.as_ref().err().map(ToString::to_string);
    std::thread::scope(|scope| {
        let (areal_go, areal_wait) = std::sync::mpsc::channel::<Option<usize>>();
        let model_thread = scope.spawn(move || {
            let t = Instant::now();
            let (mut waited, mut wrote) = (std::time::Duration::ZERO, std::time::Duration::ZERO);
            let (mut made, mut kept) = ((None, None), None);
            let m = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                let wait = || {
                    let w = Instant::now();
                    let row = areal_wait.recv();
                    waited = w.elapsed();
                    row
                };
                let (section, fit) =
                    surface::section(&input, fit, keep_fit, wait, |row, sampled| {
                        let w = Instant::now();
                        if let Ok(row) = row {
                            let overlay = row.map(|row| overlay::data_line(grid, sampled, row));
                            made = (overlay, Some(write_model(sampled)));
                        }
                        wrote = w.elapsed();
                    });
                kept = fit;
                section
            }))
            .unwrap_or_else(|_| surface::panicked());
            (m, made, (t.elapsed() - waited - wrote).as_secs_f64(), kept)
        });

        let t = Instant::now();
        let spikes = spikes::section(&input);
        spikes::warn(&spikes, model.replaced, grid, &mut warnings);
        // The lines are filtered; the surface as traced is not (no areal λc filter fits the
        // few tenths of a mm a scan covers in y): say so where the two kinds of numbers meet.
        if ctx.line_options.apply_lambda_c && grid.rows() > 1 {
            warnings.push(format!(
                "the line parameters are of the λc {} mm roughness profiles, but the areal parameters, the surface model and its bearing area curves, the height map and the X3P files are of the heights as traced, levelled by a plane: form and waviness longer than λc are in them",
                ctx.line_options.lambda_c_mm
            ));
        }
        let bridged = (ctx.options.exclude_spikes && !spikes.spikes.is_empty())
            .then(|| crate::metrology::outliers::bridged_grid(grid, &spikes.spikes).0);
        let input = SectionInput {
            characterised: bridged.as_ref().unwrap_or(grid),
            ..input
        };
        let (lines, analyses) = lines::section(&input)?;
        let specification = specification::section(&input, &lines);
        timings.lines = t.elapsed().as_secs_f64();
        warnings.extend(lines::cutoff_warning(&lines, &ctx.line_options));
        warnings.extend(lines::uncentred_warning(
            &lines,
            &analyses,
            &ctx.line_options,
        ));
        let drawn = draw_lines(analyses);

        let t = Instant::now();
        if !evenly {
            let y: Vec<String> = grid
                .y_mm
                .iter()
                .map(|y| crate::numfmt::fmt(*y, crate::numfmt::Quantity::PositionMm))
                .collect();
            warnings.push(format!(
                "the lines are not equally spaced in y (y = {} mm); the areal parameters, the height map and the X3P files use the mean pitch {} mm",
                y.join(", "),
                crate::numfmt::fmt(pitch_y_mm, crate::numfmt::Quantity::LengthMm)
            ));
        }
        let surface_grid = surface_grid::section(&input);
        let anisotropy = surface_grid::anisotropy(&input);
        for a in anisotropy.iter().filter(|a| a.slopes_untrustworthy()) {
            warnings.extend(a.caveats.last().cloned());
        }
        timings.surface_grid = t.elapsed().as_secs_f64();

        // The hold-out sections read the grid and the model, as the model section does, and
        // run beside it.
        let t = Instant::now();
        let sq = surface_grid.as_ref().map(|s| s.params.sq_um).ok();
        let (model_vs_measured, mut between_lines) = model_vs_measured::section(&input, sq);
        timings.holdout = t.elapsed().as_secs_f64();
        // The overlay of a held-out line (the rows are still the grid's here) is made, and the
        // hold-out's heights it may draw are dropped, their pages given back, before the ACF.
        let (overlay, said) = overlay::section(&input, between_lines.as_ref().ok());
        if let Ok(b) = &mut between_lines {
            b.model_um = Vec::new();
        }
        crate::fit::memory::release_free_heap();
        let _ = areal_go.send(overlay.as_ref().err().copied());
        let waited = while_waiting();
        let (surface, (model_overlay, written), model_s, kept) = model_thread
            .join()
            .unwrap_or_else(|_| (surface::panicked(), (None, None), 0.0, None));
        timings.model = model_s;
        if let Some(c) = &surface.checks {
            warnings.extend(c.warnings());
        }
        let overlay = overlay.ok().or(model_overlay);
        warnings.extend(said);
        let between_lines = between_lines.map(|mut b| {
            model_vs_measured::rows_to_lines(grid, &mut b.lines);
            if !b.supported {
                warnings.push(b.verdict.clone());
            }
            b
        });

        // The contact (when asked for): of the grid as characterised, and of the model
        // between lines with the verdict between lines beside it.
        let contact = ctx.options.contact.as_ref().map(|opts| {
            let no_fit = no_fit.as_deref().unwrap_or(surface::PANICKED);
            let fit = kept.as_deref().ok_or(no_fit);
            let c = contact::section(&input, opts, between_lines.as_ref(), fit);
            warnings.extend(c.warnings());
            c
        });

        // In the order the sections are made.
        let failure = |section: &str, r: Option<&String>| r.map(|e| surface::failed(section, e));
        let mut failed: Vec<FailedSection> = Vec::new();
        failed.extend(failure("surface_grid", surface_grid.as_ref().err()));
        failed.extend(failure("anisotropy", anisotropy.as_ref().err()));
        failed.extend(surface.failed.iter().cloned());
        let held_out = model_vs_measured.as_ref().err();
        failed.extend(failure("model_vs_measured", held_out));
        failed.extend(failure("between_lines", between_lines.as_ref().err()));
        if let Some(c) = &contact {
            failed.extend(failure("contact", c.measured_error.as_ref()));
            let model = c.model.as_ref().and_then(|m| m.error.as_ref());
            failed.extend(failure("contact.model", model));
        }
        // What the line count rules out is not a failure: the fit needs degree-v + 1 lines, the
        // hold-outs more once lines are left out, the areal sections and the contact two.
        let rows = grid.rows();
        let q = model.recipe.degrees.degree_v;
        let fit_possible = rows > q;
        let holdout_possible =
            fit_possible && crate::metrology::holdout::holdout_every(rows, q).is_some();
        let (not_possible, failed): (Vec<FailedSection>, Vec<FailedSection>) = failed
            .into_iter()
            .partition(|f| match f.section.split('.').next().unwrap_or_default() {
                "surface" => !fit_possible,
                "model_vs_measured" | "between_lines" => !holdout_possible,
                "surface_grid" | "anisotropy" | "contact" => rows < 2,
                _ => false,
            });
        if rows == 1 && !not_possible.is_empty() {
            let names: Vec<&str> = not_possible.iter().map(|f| f.section.as_str()).collect();
            warnings.push(format!(
                "a single profile: {} do not apply (they need two lines or more; characterisation.sections_not_possible says why each)",
                names.join(", ")
            ));
        }
        for f in not_possible.iter().filter(|_| rows > 1) {
            warnings.push(format!(
                "{} not made ({rows} lines are too few): {}",
                f.section, f.reason
            ));
        }
        for f in &failed {
            warnings.push(format!("{} could not be made: {}", f.section, f.reason));
        }
        let sections = Sections {
            spikes,
            lines,
            specification,
            surface_grid,
            anisotropy,
            surface,
            model_vs_measured,
            between_lines,
            overlay,
            contact,
            failed,
            not_possible,
            warnings,
            timings,
        };
        Ok((sections, drawn, written, waited))
    })
}
