//! `surfscan fit`: the heights of a scan directory, a grid CSV or an X3P file, read by the one
//! reader ([`crate::input`], whose findings it prints), → NURBS surface → IGES file and fit
//! report.
//!
//! A scan's lines are fitted at their y (the target `y_target_nm`) with the x pitch stored
//! with them; the default output is `SCAN_DIR/surface.igs`, and an existing one (a completed
//! scan's surface) is not replaced unless `--force` is given or `-o` names the output. Other
//! inputs need `-o`. The lines the reader leaves out are named in the IGES Start section and
//! the report, and the fit is partial: "N of M lines", exit 3, the surface written.
//!
//! The surface is checked to be a height map as the report's model checks check it (the
//! control net first: one that runs forwards everywhere rules a fold out; else the sampled
//! iso-curves): a fold is named on stderr, in the report's `height_map` and in the IGES Start
//! section, the surface is written as fitted, and the exit status is 3.
//!
//! `-o -` writes the IGES to standard output and the summary to standard error; a device or
//! a FIFO at the output path is written into, never replaced ([`crate::atomic`]).
//!
//! Exit status: 0 done; 3 done from fewer lines than the input holds, or the surface folds; 2 bad pitch or degree
//! arguments, an input of the wrong kind, or an existing surface not to be replaced; 74 the
//! input cannot be read or an output cannot be written; 1 the data cannot be used (the
//! message names what and where) or cannot be interpolated.
//!
//! A surface whose IGES text does not fit one file (the P section is capped at 9,999,999
//! lines) is written as several complete IGES files of whole exact patches: `OUT.igs` is then
//! not written; part i of n goes to `OUT.part<i>-of-<n>.igs` (see [`part_path`]), its Start
//! section names the part and its v range, and the report lists every file.
//!
//! The degrees are `--degree-u/--degree-v`, by default those of a scan's frozen plan (its
//! journal's start record), else the paper's 5/5; likewise the method across the lines
//! (`--v-method`, the paper's interpolation by default) and spike replacement before fitting
//! (`--replace-spikes`, only when asked; for a grid CSV the spike rule judges the heights
//! minus their least-squares line). The IGES Start section and the report name the method
//! and every replaced spike.
//!
//! The summary printed is the verdict on the model between lines (every 2nd line left out,
//! refitted the same way, judged against Sq), not the residual at the data points, which an
//! interpolant makes zero by construction (only `--report` computes it). `--compare` prints the
//! hold-out figures of the paper's interpolation and of least-squares alternatives side by
//! side, so the method is chosen with numbers.
//!
//! `--step OUT.step --solid-depth-mm D` also writes the surface as the top face of a closed
//! block (STEP AP214, [`crate::step`]) whose flat bottom is D mm below the surface's lowest
//! point, for FE models; the report's `step` names its bottom and extent.
//!
//! Layer 5 (composition).

use super::input_args::{tell_findings, InputArgs};
use super::model_args::ModelArgs;
use super::{CliError, Exit};
use crate::atomic::{write_atomically, write_json_atomically};
use crate::fit::{max_residual_mm, FitOptions, FitResult, IncrementalFitter};
use crate::grid::{Grid, LeftOut};
use crate::iges::{IgesOptions, MAX_SECTION_LINES};
use crate::input::{GridInput, Source};
use crate::metrology::alternatives::{
    compare as compare_alternatives, table as alternatives_table,
};
use crate::metrology::areal::{sq_um as areal_sq_um, HeightMap};
use crate::metrology::folds::{check_model, net_folds, FoldOptions, IsoFold, ModelChecks};
use crate::metrology::holdout::{between_lines, holdout_every_or_reason, ordinal, BetweenLines};
use crate::metrology::outliers::LineSpike;
use crate::metrology::surface_model::{fit_model, ModelRecipe};
use crate::scan::outputs::SurfaceShape;
use crate::scan::surface_files::{write_surface_files, SurfaceWriteError, WrittenIges};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `surfscan fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scan directory, grid CSV of heights (rows = traced lines along y, columns = points
    /// along x) or X3P file.
    pub input: PathBuf,
    /// Output IGES file (required for a grid CSV; default `SCAN_DIR/surface.igs`). `-` is
    /// standard output (the summary then goes to standard error); a device or a FIFO is
    /// written into, never replaced.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// The pitches of a grid CSV and the unit of a CSV's heights.
    #[command(flatten)]
    pub read: InputArgs,
    /// Write a JSON fit report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Largest number of IGES Parameter Data lines per file (at most 9999999); a larger
    /// surface is written as several files `OUT.part<i>-of-<n>.igs`.
    #[arg(long, default_value_t = MAX_SECTION_LINES)]
    pub max_iges_lines_per_file: usize,
    /// Largest number of IGES Parameter Data lines per entity 128; a larger surface is split
    /// along v into exact patches.
    #[arg(long, default_value_t = MAX_SECTION_LINES)]
    pub max_iges_lines_per_entity: usize,
    /// Also print the between-line hold-out of the paper's interpolation and of least-squares
    /// alternatives side by side.
    #[arg(long)]
    pub compare: bool,
    /// The surface and the spike rule.
    #[command(flatten)]
    pub model: ModelArgs,
    /// Replace an existing SCAN_DIR/surface.igs (by default it is kept: it is the surface the
    /// scan wrote when it completed).
    #[arg(long)]
    pub force: bool,
    /// Also write the surface as the top face of a closed solid (a block under the specimen's
    /// area, flat bottom) to this STEP AP214 file, for FE models (needs --solid-depth-mm).
    #[arg(long, value_name = "OUT.step", requires = "solid_depth_mm")]
    pub step: Option<PathBuf>,
    /// The solid's depth from the surface's lowest point to its flat bottom, mm (with
    /// --step).
    #[arg(long, value_name = "D", requires = "step")]
    pub solid_depth_mm: Option<f64>,
}

/// Writes the STEP solid of `surface` when `--step` asks for it; `lowest_data_z_mm` is the
/// lowest height the surface interpolates (None when it does not interpolate the heights as
/// read).
fn write_step_solid(
    args: &Args,
    surface: &crate::nurbs::NurbsSurface,
    lowest_data_z_mm: Option<f64>,
) -> Result<Option<serde_json::Value>, CliError> {
    let (Some(path), Some(depth_mm)) = (&args.step, args.solid_depth_mm) else {
        return Ok(None);
    };
    let opts = crate::step::StepOptions {
        depth_mm,
        file_name: path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        timestamp: chrono::Utc::now()
            .naive_utc()
            .format("%Y-%m-%dT%H:%M:%S")
            .to_string(),
        product_name: format!("surfscan solid of {}", args.input.display()),
        description: format!(
            "surface fitted by surfscan {} as the top face of a block {depth_mm} mm deep below its lowest point; units mm",
            env!("CARGO_PKG_VERSION")
        ),
        lowest_data_z_mm,
    };
    // The surface is checked (and the text made) before the file is opened.
    let mut text = Vec::new();
    let stats = crate::step::write_solid_step(&mut text, surface, &opts).map_err(|e| match e {
        crate::step::StepError::Io(e) => io_err("cannot write STEP", path, e),
        e => CliError::new(Exit::Failed, format!("{}: {e}", path.display())),
    })?;
    ensure_parent(path)?;
    write_atomically(path, |w| std::io::Write::write_all(w, &text))
        .map_err(|e| io_err("cannot write STEP", path, e))?;
    Ok(Some(serde_json::json!({
        "path": path.display().to_string(),
        "bytes": stats.bytes,
        "entities": stats.entities,
        "depth_mm": depth_mm,
        "lowest_z_mm": stats.lowest_z_mm,
        "bottom_z_mm": stats.bottom_z_mm,
        "x_mm": stats.x_mm,
        "y_mm": stats.y_mm,
    })))
}

pub use crate::scan::surface_files::part_path;

fn io_err(what: &str, path: &Path, e: impl std::fmt::Display) -> CliError {
    CliError::new(Exit::Io, format!("{what} {}: {e}", path.display()))
}

fn ensure_parent(path: &Path) -> Result<(), CliError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| {
            let hint = crate::atomic::write_hint(dir, &e);
            io_err("cannot create directory", dir, format!("{e}; {hint}"))
        })?;
    }
    Ok(())
}

/// The lines to fit, however they were read, and what the fit follows.
struct Input {
    input: GridInput,
    output: PathBuf,
    /// The degrees to fit with.
    degrees: FitOptions,
    /// The scan's frozen plan, when the input is a scan with a readable journal.
    plan: Option<crate::scan::plan::Plan>,
    /// λc of the roughness the spike rule judges (a scan of primary profiles).
    lambda_c_mm: Option<f64>,
}

/// The IGES Start section's words for the lines of the input a fit left out, so the file
/// itself says which lines its surface does not pass through.
fn left_out_start_line(left_out: &[LeftOut]) -> Option<String> {
    (!left_out.is_empty()).then(|| {
        let each: Vec<String> = left_out
            .iter()
            .map(|l| match &l.file {
                Some(f) => format!("{} ({f}, {})", l.line, l.why),
                None => format!("{} ({})", l.line, l.why),
            })
            .collect();
        format!("Lines left out: {}.", each.join("; "))
    })
}

/// Reads the input, prints what the reader found, and decides the output and the degrees: a
/// scan's own (its frozen plan; `SCAN_DIR/surface.igs`, kept unless `--force` or `-o`),
/// else the paper's and `-o`.
fn read_input(args: &Args) -> Result<Input, CliError> {
    let input = args.read.read(&args.input)?;
    let vouched = match &input.source {
        Source::Scan(vouched) => Some(vouched),
        _ => None,
    };
    let output = match (&args.output, vouched) {
        (Some(output), _) => output.clone(),
        (None, Some(vouched)) => {
            let default_output = args.input.join("surface.igs");
            if let Some(existing) = existing_surface(&default_output).filter(|_| !args.force) {
                return Err(CliError::new(
                    Exit::Usage,
                    format!(
                        "{} exists ({}); it is kept: pass --force to replace it, or -o OTHER.igs to write the new fit elsewhere",
                        existing.display(),
                        if vouched.completed() {
                            "the surface the completed scan wrote"
                        } else {
                            "an earlier fit of this scan"
                        }
                    ),
                ));
            }
            default_output
        }
        (None, None) => {
            return Err(CliError::new(
                Exit::Usage,
                format!(
                    "{} needs -o OUT.igs (only a scan directory has a default output)",
                    match input.source {
                        Source::X3p { .. } => "an X3P file",
                        Source::ProfileCsv => "a profile CSV",
                        _ => "a grid CSV",
                    }
                ),
            ))
        }
    };
    let start = vouched
        .and_then(|v| v.journal.as_ref().ok())
        .map(|s| &s.start);
    let degrees =
        crate::report::scan_dir::scan_degrees(args.model.degree_u, args.model.degree_v, start);
    let plan = start.map(|s| s.plan.clone());
    let lambda_c_mm = vouched.and_then(|v| v.lines.first()).and_then(|l| {
        let o = crate::metrology::params::Options::from_profile(&l.profile);
        o.apply_lambda_c.then_some(o.lambda_c_mm)
    });
    tell_findings(&input);
    Ok(Input {
        input,
        output,
        degrees,
        plan,
        lambda_c_mm,
    })
}

/// The existing surface at `output` (or the first part of a split one), if any.
fn existing_surface(output: &Path) -> Option<PathBuf> {
    if output.exists() {
        return Some(output.to_path_buf());
    }
    let first_part = format!("{}.part1-of-", output.file_stem()?.to_string_lossy());
    std::fs::read_dir(output.parent()?)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(&first_part))
        })
}

/// Grids up to this many heights have the verdict between lines and the residual check
/// computed beside the fit and the IGES write (the heights then stay in memory while the file
/// is written); larger ones run each step in turn and free the heights before the write.
const SIDE_BY_SIDE_MAX_POINTS: usize = 1 << 22;

/// The result of a scoped thread; a panic in it is carried on to the caller.
fn joined<T>(h: std::thread::ScopedJoinHandle<'_, T>) -> T {
    h.join()
        .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
}

/// The fit the recipe asks for: the paper's surface through the incremental fitter line by
/// line (with progress), anything else from the whole grid; with the spikes it replaced.
fn fit_surface(
    input: &Path,
    grid: &Grid,
    recipe: &ModelRecipe,
    progress: &indicatif::ProgressBar,
) -> Result<(FitResult, Vec<LineSpike>), CliError> {
    let failed = |e: &dyn std::fmt::Display| {
        CliError::new(Exit::Failed, format!("{}: {e}", input.display()))
    };
    if recipe.is_paper() {
        let mut fitter = IncrementalFitter::new(recipe.degrees);
        // The stores at their final size at once: no regrowing (and copying) as lines come.
        fitter.reserve_lines(grid.rows(), grid.cols);
        for (row, &y) in grid.heights_um.chunks_exact(grid.cols).zip(&grid.y_mm) {
            fitter
                .push_row(y, grid.pitch_x_mm, row)
                .map_err(|e| failed(&e))?;
            progress.inc(1);
        }
        let mut fit = fitter.finish().map_err(|e| failed(&e))?;
        // Where it was measured, as `fit_model` places its surface (an X3P input's x offset).
        fit.place_at_x(grid.x0_mm);
        Ok((fit, Vec::new()))
    } else {
        let m = fit_model(grid, recipe).map_err(|e| failed(&e))?;
        Ok((m.fit, m.replaced))
    }
}

/// The checks that decide whether the surface is a height map: none when its control net runs
/// forwards everywhere (then no iso-curve can run back, [`net_folds`]), else the report's
/// model checks on the sampled iso-curves, which say whether, where and by how much it folds.
fn shape_checks(fit: &FitResult, fitted_heights_um: &[f64]) -> Option<ModelChecks> {
    (!net_folds(&fit.surface).is_empty()).then(|| {
        check_model(
            &fit.surface,
            &fit.params_v,
            fitted_heights_um,
            &FoldOptions::default(),
        )
    })
}

/// The IGES Start section's words for a fold of the surface (ASCII, as the section is).
fn fold_start_line(f: &IsoFold) -> String {
    let words = f.words("..", "um");
    format!("NOT A HEIGHT MAP: the surface folds, {words}.")
}

/// What a fit follows once the input is read: the arguments, the output, the recipe, and the
/// grid's lines without their heights (each step is given the heights, so that a large grid's
/// can be freed before the IGES write).
struct Fitting<'a> {
    args: &'a Args,
    output: PathBuf,
    recipe: ModelRecipe,
    /// The grid as read, its heights left out ([`Grid::layout`]).
    lines: Grid,
    /// The input's kind, as the report names it.
    kind: &'static str,
    /// The input's y pitch (`None`: a scan's lines, each at its own y).
    pitch_y_mm: Option<f64>,
    progress: indicatif::ProgressBar,
}

/// What the fit made, and how long each step took.
struct Fitted {
    fit: FitResult,
    replaced: Vec<LineSpike>,
    fit_s: f64,
    /// The checks that decide whether the surface is a height map (`None`: its control net
    /// rules a fold out).
    shape: Option<ModelChecks>,
    shape_s: f64,
    /// The largest residual at the data points, mm, and the seconds it took (only for
    /// `--report`, which shows it).
    residual: Option<(f64, f64)>,
    judged: Judged,
    written: Vec<WrittenIges>,
    write_s: f64,
    /// The STEP solid written (`--step`): its report entry, and the seconds it took.
    step: Option<(serde_json::Value, f64)>,
}

/// The verdict on the model between lines, and the alternatives when asked for.
struct Judged {
    threshold: f64,
    sq: Result<f64, String>,
    every: Result<usize, String>,
    verdict: Result<BetweenLines, String>,
    alternatives: Option<Vec<crate::metrology::alternatives::Alternative>>,
    holdout_s: f64,
}

impl Fitted {
    /// The surface is not a height map somewhere.
    fn folds(&self) -> bool {
        self.shape.as_ref().is_some_and(ModelChecks::folds)
    }

    /// The IGES files' patches, bytes and parameter lines, all parts together.
    fn stats(&self) -> crate::iges::IgesStats {
        let mut stats = crate::iges::IgesStats::default();
        for w in &self.written {
            stats.patches += w.patches;
            stats.bytes += w.bytes;
            stats.parameter_lines += w.parameter_lines;
        }
        stats
    }
}

impl<'a> Fitting<'a> {
    /// The recipe for `input`: the arguments' degrees, method and spike rule, else the scan's
    /// frozen plan's, else the paper's.
    fn new(args: &'a Args, input: &Input) -> Result<Fitting<'a>, CliError> {
        let grid = &input.input.grid;
        let method = args
            .model
            .v_method(grid.rows(), input.degrees.degree_v)?
            .or(input.plan.as_ref().map(|p| p.v_method))
            .unwrap_or_default();
        let replace_spikes = match args.model.replace() {
            Some(true) => Some(args.model.spikes()?),
            _ => input.plan.as_ref().and_then(|p| p.replace_spikes),
        };
        let progress = if std::io::stderr().is_terminal() && grid.heights_um.len() >= 1_000_000 {
            indicatif::ProgressBar::new(grid.rows() as u64)
        } else {
            indicatif::ProgressBar::hidden()
        };
        Ok(Fitting {
            args,
            output: input.output.clone(),
            recipe: ModelRecipe {
                degrees: input.degrees,
                method,
                replace_spikes,
                lambda_c_mm: input.lambda_c_mm,
            },
            lines: grid.layout(),
            kind: input.input.kind(),
            pitch_y_mm: input.input.pitch_y_mm(),
            progress,
        })
    }

    /// Fits `grid`, checks the surface, judges it between lines and writes it. A grid up to
    /// [`SIDE_BY_SIDE_MAX_POINTS`] has the verdict computed beside the fit and the write;
    /// a larger one runs each step in turn and frees its heights before the write.
    fn run(&self, mut grid: Grid) -> Result<Fitted, CliError> {
        let lowest_data_um = grid
            .heights_um
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min);
        // A threshold given wrongly is refused after the fit and before anything is written,
        // in both orders.
        let threshold = self.args.model.holdout_threshold();
        let (
            (fit, replaced, fit_s, (shape, shape_s)),
            residual_at_points,
            judged,
            (written, write_s),
        ) = match threshold {
            Ok(threshold) if grid.heights_um.len() <= SIDE_BY_SIDE_MAX_POINTS => {
                // The verdict between lines needs only the heights the surface is fitted
                // to (the grid's own for the paper's fit, which replaces no spike), so it
                // runs beside the fit and the IGES write, and the residual check runs while
                // the file is formatted and synced: the same computations on the same
                // inputs, so the same numbers, in about the time of the longest.
                let grid = &grid;
                std::thread::scope(|outer| {
                    let early = self
                        .recipe
                        .is_paper()
                        .then(|| outer.spawn(move || self.judge(grid, threshold)));
                    let fitted = self.fit(grid)?;
                    let judging = match early {
                        Some(h) => h,
                        None => {
                            let replaced = fitted.1.clone();
                            outer
                                .spawn(move || self.judge(&self.fitted(grid, &replaced), threshold))
                        }
                    };
                    let (residual, written) = std::thread::scope(|inner| {
                        let writing =
                            inner.spawn(|| self.write(&fitted.0, &fitted.1, &fitted.3 .0));
                        let residual = self.residual(&fitted.0, grid);
                        (residual, joined(writing))
                    });
                    let written = written?;
                    Ok::<_, CliError>((fitted, residual, joined(judging), written))
                })?
            }
            threshold => {
                // The paper's surface (which replaces no spike) is judged on the heights as
                // read before it is fitted, so the refit's memory is freed before the fitter
                // takes its own; a recipe that replaces spikes is judged after its fit, on
                // the grid with them bridged.
                let early = match &threshold {
                    Ok(t) if self.recipe.is_paper() => Some(self.judge(&grid, *t)),
                    _ => None,
                };
                let fitted = self.fit(&grid)?;
                let residual = self.residual(&fitted.0, &grid);
                let judged = match early {
                    Some(judged) => judged,
                    None => self.judge(&self.fitted(&grid, &fitted.1), threshold?),
                };
                // The heights are not needed past the residual check and the verdict: free
                // them before the IGES files are planned and written, which is when a large
                // surface needs the most memory.
                grid.heights_um = Vec::new();
                let written = self.write(&fitted.0, &fitted.1, &fitted.3 .0)?;
                (fitted, residual, judged, written)
            }
        };
        // The surface passes through the heights only when it interpolates them as read.
        let interpolates = matches!(self.recipe.method, crate::fit::VMethod::Interpolate)
            && replaced.is_empty()
            && lowest_data_um.is_finite();
        let t_step = Instant::now();
        let step = write_step_solid(
            self.args,
            &fit.surface,
            interpolates.then_some(lowest_data_um / 1000.0),
        )?
        .map(|v| (v, t_step.elapsed().as_secs_f64()));
        Ok(Fitted {
            step,
            fit,
            replaced,
            fit_s,
            shape,
            shape_s,
            residual: residual_at_points,
            judged,
            written,
            write_s,
        })
    }

    /// The fit (timed), the spikes it replaced (named), and the height-map checks (timed; a
    /// fold named).
    #[allow(clippy::type_complexity)]
    fn fit(
        &self,
        grid: &Grid,
    ) -> Result<(FitResult, Vec<LineSpike>, f64, (Option<ModelChecks>, f64)), CliError> {
        let t_fit = Instant::now();
        let fitted = fit_surface(&self.args.input, grid, &self.recipe, &self.progress);
        self.progress.finish_and_clear();
        let (fit, replaced) = fitted?;
        // Every spike replaced before fitting named (only ever when asked for).
        for r in &replaced {
            tell!(
                "surfscan: replaced before fitting (asked for): spike in line {} at x = {} mm, height {} µm",
                crate::numfmt::line_label(r.line),
                crate::numfmt::fmt(r.spike.x_mm, crate::numfmt::Quantity::PositionMm),
                crate::numfmt::fmt(r.spike.height_um, crate::numfmt::Quantity::HeightUm)
            );
        }
        let fit_s = t_fit.elapsed().as_secs_f64();
        let t_shape = Instant::now();
        let shape = shape_checks(&fit, &self.fitted(grid, &replaced).heights_um);
        for w in shape.iter().flat_map(ModelChecks::fold_warnings) {
            tell!("surfscan: warning: {w}");
        }
        Ok((
            fit,
            replaced,
            fit_s,
            (shape, t_shape.elapsed().as_secs_f64()),
        ))
    }

    /// The largest residual at the data points in mm (timed), computed only for `--report`,
    /// which alone shows it.
    fn residual(&self, fit: &FitResult, grid: &Grid) -> Option<(f64, f64)> {
        self.args.report.as_ref().map(|_| {
            let t_res = Instant::now();
            (max_residual_mm(fit, grid), t_res.elapsed().as_secs_f64())
        })
    }

    /// Writes the surface's IGES files (timed), their Start section naming the recipe, the
    /// replaced spikes, the lines left out and any fold.
    fn write(
        &self,
        fit: &FitResult,
        replaced: &[LineSpike],
        shape: &Option<ModelChecks>,
    ) -> Result<(Vec<WrittenIges>, f64), CliError> {
        let mut opts = self.iges_options();
        opts.start_lines.extend(self.recipe.start_lines(replaced));
        opts.start_lines
            .extend(left_out_start_line(&self.lines.left_out));
        opts.start_lines.extend(
            shape
                .iter()
                .flat_map(|c| c.iso_curves.iter().map(fold_start_line)),
        );
        ensure_parent(&self.output)?;
        let t_write = Instant::now();
        let written = write_surface_files(&self.output, &fit.surface, &opts).map_err(|e| {
            let exit = match e {
                SurfaceWriteError::Format { .. } => Exit::Failed,
                SurfaceWriteError::Io { .. } => Exit::Io,
            };
            CliError::new(exit, e.to_string())
        })?;
        Ok((written, t_write.elapsed().as_secs_f64()))
    }

    /// The grid the surface was fitted to: `grid`, with any replaced spike bridged.
    fn fitted<'g>(&self, grid: &'g Grid, replaced: &[LineSpike]) -> std::borrow::Cow<'g, Grid> {
        if replaced.is_empty() {
            std::borrow::Cow::Borrowed(grid)
        } else {
            std::borrow::Cow::Owned(crate::metrology::outliers::bridged_grid(grid, replaced).0)
        }
    }

    /// Every 2nd line left out (or every k-th when too few lines remain for that, as the
    /// report does), refitted the same way and judged against Sq of `fitted`.
    fn judge(&self, fitted: &Grid, threshold: f64) -> Judged {
        let t_holdout = Instant::now();
        let (rows, y_mm) = (fitted.rows(), &fitted.y_mm[..]);
        let mean_py = match (y_mm.first(), y_mm.last()) {
            (Some(a), Some(b)) if rows > 1 => (b - a).abs() / (rows - 1) as f64,
            _ => self.pitch_y_mm.unwrap_or(1.0),
        };
        let sq = areal_sq_um(&HeightMap::of(fitted, mean_py)).map_err(|e| e.to_string());
        let degrees = self.recipe.degrees;
        let every = holdout_every_or_reason(rows, degrees.degree_v).map_err(|e| e.to_string());
        let verdict = sq.clone().and_then(|sq| {
            let every = every.clone()?;
            between_lines(fitted, degrees, self.recipe.method, every, sq, threshold)
                // The refit's heights at the held-out lines are not reported here; only the
                // figures are kept.
                .map(|mut b| {
                    b.model_um = Vec::new();
                    b
                })
                .map_err(|e| e.to_string())
        });
        let alternatives = match (&sq, &every, self.args.compare) {
            (Ok(sq), Ok(every), true) => Some(compare_alternatives(
                fitted, degrees, *every, *sq, threshold,
            )),
            _ => None,
        };
        Judged {
            threshold,
            sq,
            every,
            verdict,
            alternatives,
            holdout_s: t_holdout.elapsed().as_secs_f64(),
        }
    }

    /// The Start and Global section contents of the surface's IGES files (the replaced spikes,
    /// the lines left out and any fold are added by [`Fitting::write`]).
    fn iges_options(&self) -> IgesOptions {
        let (args, recipe, l) = (self.args, &self.recipe, &self.lines);
        let options = recipe.degrees;
        let (rows, cols, pitch_x_mm, y_mm) = (l.rows(), l.cols, l.pitch_x_mm, &l.y_mm);
        let file_name = self
            .output
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        // A grid's y pitch, else a scan's lines at their own y.
        let end = |y: Option<&f64>| y.copied().unwrap_or(f64::NAN);
        let (scan, y) = match self.pitch_y_mm {
            Some(py) => ("", format!("pitch y {py} mm")),
            None => (
                "scan ",
                format!("y {} .. {} mm", end(y_mm.first()), end(y_mm.last())),
            ),
        };
        IgesOptions {
            file_name,
            start_lines: vec![
                format!(
                    "Surface fitted by surfscan {} ({}, p={}, q={}); units mm.",
                    env!("CARGO_PKG_VERSION"),
                    recipe.method.in_brief(),
                    options.degree_u,
                    options.degree_v
                ),
                format!(
                    "Input: {scan}{} ({rows} lines x {cols} points, pitch x {pitch_x_mm} mm, {y}, heights um).",
                    args.input.display()
                ),
            ],
            timestamp: chrono::Utc::now().naive_utc(),
            max_parameter_lines_per_file: args.max_iges_lines_per_file,
            max_parameter_lines_per_entity: args.max_iges_lines_per_entity,
            ..IgesOptions::default()
        }
    }

    /// The fit report (`--report`): the input, the surface's shape and files, the model and
    /// its checks, the verdict between lines, the timings.
    fn report(&self, f: &Fitted, read_s: f64) -> serde_json::Value {
        let (l, judged, stats) = (&self.lines, &f.judged, f.stats());
        let files: Vec<serde_json::Value> = f
            .written
            .iter()
            .map(|w| {
                serde_json::json!({
                    "path": w.path.display().to_string(),
                    "part": w.part,
                    "v_range": w.v_range,
                    "patches": w.patches,
                    "bytes": w.bytes,
                    "parameter_lines": w.parameter_lines,
                })
            })
            .collect();
        let mut report = serde_json::json!({
            "input": self.args.input.display().to_string(),
            "input_kind": self.kind,
            "output": self.output.display().to_string(),
            "grid": { "rows": l.rows(), "cols": l.cols },
            "lines_in_input": l.lines_in_input(),
            "x0_mm": l.x0_mm,
            "pitch_x_mm": l.pitch_x_mm,
            "pitch_y_mm": self.pitch_y_mm,
            "y_mm": l.y_mm,
            "lines": l.index,
            "lines_left_out": l.left_out,
            "max_residual_mm": f.residual.map(|r| r.0),
            "patches": stats.patches,
            "iges_bytes": stats.bytes,
            "iges_parameter_lines": stats.parameter_lines,
            "iges_files": files,
            "model": {
                "description": self.recipe.describe(),
                "v_method": self.recipe.method,
                "spikes_replaced": f.replaced,
            },
            "height_map": {
                "folds": f.folds(),
                "checked": match &f.shape {
                    None => "the control net runs forwards in u and v everywhere, so the surface cannot fold (its iso-curves were not sampled)",
                    Some(_) => "the control net runs back somewhere: the iso-curves were sampled as the report's model checks sample them",
                },
                "model_checks": &f.shape,
            },
            "between_lines": judged.verdict.as_ref().ok(),
            "between_lines_error": judged.verdict.as_ref().err(),
            "alternatives": judged.alternatives.as_ref().map(|alts| alts
                .iter()
                .map(|a| serde_json::json!({
                    "degree_u": a.options.degree_u,
                    "degree_v": a.options.degree_v,
                    "v_method": a.method,
                    "poles_v": a.poles_v,
                    "between_lines": a.holdout.as_ref().ok(),
                    "error": a.holdout.as_ref().err(),
                }))
                .collect::<Vec<_>>()),
            "timings_s": {
                "holdout": judged.holdout_s,
                "read": read_s,
                "fit_params": f.fit.timings.params_s,
                "fit_knots_factor": f.fit.timings.knots_factor_s,
                "fit_solve_u": f.fit.timings.solve_u_s,
                "fit_solve_v": f.fit.timings.solve_v_s,
                "fit_total": f.fit_s,
                "shape_check": f.shape_s,
                "residual": f.residual.map(|r| r.1),
                "write_iges": f.write_s,
                "write_step": f.step.as_ref().map(|s| s.1),
            },
            "step": f.step.as_ref().map(|s| &s.0),
        });
        if let (Some(o), Ok(serde_json::Value::Object(shape))) = (
            report.as_object_mut(),
            serde_json::to_value(SurfaceShape::of(&f.fit.surface)),
        ) {
            o.extend(shape);
        }
        report
    }

    /// Prints what was written and the verdict between lines (and the alternatives when
    /// asked for).
    fn tell(&self, f: &Fitted) {
        let (output, n_files, judged, stats) =
            (&self.output, f.written.len(), &f.judged, f.stats());
        let s = &f.fit.surface;
        let written = if n_files == 1 {
            output.display().to_string()
        } else {
            format!(
                "{} too large for one IGES file; wrote {} files {} .. {}",
                output.display(),
                n_files,
                part_path(output, 1, n_files).display(),
                part_path(output, n_files, n_files).display()
            )
        };
        say!(
            "{}: {}x{} grid, {}x{} poles, {} patch(es), {} bytes; fit {:.1} ms, write {:.1} ms",
            written,
            self.lines.rows(),
            self.lines.cols,
            s.count_u(),
            s.count_v(),
            stats.patches,
            stats.bytes,
            f.fit_s * 1e3,
            f.write_s * 1e3
        );
        if let Some((step, _)) = &f.step {
            say!(
                "{}: the surface as the top face of a solid {} mm deep (bottom at z = {} mm), {} bytes",
                step["path"].as_str().unwrap_or_default(),
                step["depth_mm"],
                step["bottom_z_mm"],
                step["bytes"]
            );
        }
        say!(
            "{}",
            BetweenLines::line(judged.verdict.as_ref().map_err(|e| Some(&e[..])))
        );
        if let Some(alts) = &judged.alternatives {
            say!(
                "\nhold-out of the alternatives (every {} line left out and refitted; supported means rms ≤ {} × Sq):",
                ordinal(*judged.every.as_ref().unwrap_or(&2)),
                judged.threshold
            );
            say_text!("{}", alternatives_table(alts));
        } else if self.args.compare {
            match (&judged.sq, &judged.every) {
                (Err(e), _) => say!("no comparison: the grid has no Sq ({e})"),
                (_, Err(e)) => say!("no comparison: {e}"),
                _ => {}
            }
        }
    }

    /// Exit 3 when the surface is partial (lines left out) or folds, naming which; else 0.
    fn status(&self, f: &Fitted) -> Result<(), CliError> {
        let mut partial = Vec::new();
        if self.lines.is_partial() {
            partial.push(format!(
                "the surface is partial: fitted from {} (the others cannot be used, see the warnings above; the IGES Start section names them)",
                self.lines.lines_used()
            ));
        }
        if f.folds() {
            partial.push(
                "the surface folds (see the model fold warning above; the IGES Start section and the report name it): it is not a height map there".to_string(),
            );
        }
        if partial.is_empty() {
            return Ok(());
        }
        Err(CliError::new(
            Exit::Partial,
            format!("{}; it is written", partial.join("; ")),
        ))
    }
}

/// The arguments no input could make valid: a degree of 0, a line limit of 0.
fn check_args(args: &Args) -> Result<(), CliError> {
    args.model.check_degrees()?;
    // 0 lines would be taken as 1 and the refusal would then name a limit never given.
    for (name, v) in [
        ("--max-iges-lines-per-file", args.max_iges_lines_per_file),
        (
            "--max-iges-lines-per-entity",
            args.max_iges_lines_per_entity,
        ),
    ] {
        if v == 0 {
            return Err(CliError::new(
                Exit::Usage,
                format!("{name} must be at least 1 (default and largest {MAX_SECTION_LINES})"),
            ));
        }
    }
    if let Some(d) = args.solid_depth_mm.filter(|d| !(d.is_finite() && *d > 0.0)) {
        return Err(CliError::new(
            Exit::Usage,
            format!("--solid-depth-mm {d} must be a positive number of millimetres (the block's depth below the surface's lowest point)"),
        ));
    }
    Ok(())
}

/// Runs `surfscan fit`: read, fit, check, judge and write, report, say, exit status.
pub fn run(args: Args) -> Result<(), CliError> {
    let dash = Path::new("-");
    if args.output.as_deref() == Some(dash) || args.report.as_deref() == Some(dash) {
        super::console::stdout_carries_data();
    }
    check_args(&args)?;
    let t_read = Instant::now();
    let input = read_input(&args)?;
    let read_s = t_read.elapsed().as_secs_f64();
    let fitting = Fitting::new(&args, &input)?;
    let fitted = fitting.run(input.input.grid)?;
    if let Some(path) = &args.report {
        ensure_parent(path)?;
        let report = fitting.report(&fitted, read_s);
        write_json_atomically(path, &report).map_err(|e| io_err("cannot write report", path, e))?;
    }
    fitting.tell(&fitted);
    fitting.status(&fitted)
}
