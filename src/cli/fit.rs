//! `surfscan fit`: CSV grid of heights, or a scan directory, → NURBS surface → IGES file and
//! fit report.
//!
//! A scan directory (`lines/NNNN.csv` + `NNNN.json`, as the scan daemon writes it) is fitted
//! from its complete lines in index order: y of each line is its target `y_target_nm`, the x
//! pitch is the one stored with the lines, the default output is `SCAN_DIR/surface.igs`.
//! Lines with only one of their two files are left out and named in a warning. Each line's
//! heights file is checked against the SHA-256 its journal record holds before it is read: a
//! file changed after it was traced, and a line the journal never committed, are left out and
//! named in a warning, and the other lines are fitted. An existing `SCAN_DIR/surface.igs` (a completed scan's surface) is not replaced
//! unless `--force` is given or `-o` names the output. A grid CSV needs `--pitch-x`,
//! `--pitch-y` and `-o`; an IGES file or another non-grid input is named as such.
//!
//! Exit status: 0 done; 2 bad pitch or degree arguments, an input of the wrong kind, or an
//! existing surface not to be replaced; 74 the input cannot be read or an output cannot be
//! written; 1 the data are malformed (the message names line, column and content), a line
//! file does not match its journal record, or the data cannot be interpolated.
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
//! interpolant makes zero by construction (the report keeps it). `--compare` prints the
//! hold-out figures of the paper's interpolation and of least-squares alternatives side by
//! side, so the method is chosen with numbers.
//!
//! Layer 5 (composition).

use super::model_args::ModelArgs;
use super::{CliError, Exit};
use crate::atomic::write_atomically;
use crate::fit::{max_residual_mm, FitOptions, FitResult, IncrementalFitter};
use crate::iges::{IgesOptions, MAX_SECTION_LINES};
use crate::metrology::alternatives::{
    compare as compare_alternatives, table as alternatives_table,
};
use crate::metrology::areal::{sq_um as areal_sq_um, Grid as ArealGrid};
use crate::metrology::holdout::{between_lines, holdout_every_or_reason, ordinal};
use crate::metrology::outliers::{bridged_grid, LineSpike};
use crate::metrology::surface_model::{fit_model, ModelRecipe};
use crate::scan::outputs::SurfaceShape;
use crate::scan::surface_files::{write_surface_files, SurfaceWriteError};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `surfscan fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scan directory, or grid CSV of heights in µm (rows = traced lines along y, columns =
    /// points along x).
    pub input: PathBuf,
    /// Output IGES file (required for a grid CSV; default `SCAN_DIR/surface.igs`).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Pitch along x (between columns), mm (grid CSV only; a scan stores its own).
    #[arg(long)]
    pub pitch_x: Option<f64>,
    /// Pitch along y (between rows), mm (grid CSV only; a scan's lines are at their stored y).
    #[arg(long)]
    pub pitch_y: Option<f64>,
    /// Degree along u (x). Default: a scan's frozen plan, else 5 (the paper).
    #[arg(long)]
    pub degree_u: Option<usize>,
    /// Degree along v (y). Default: a scan's frozen plan, else 5 (the paper).
    #[arg(long)]
    pub degree_v: Option<usize>,
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
}

/// What a file given to `fit` is, from its name and first bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// Text that may be a grid CSV.
    GridCsv,
    /// An IGES file (`.igs`/`.iges`, or 80-column lines with `S` in column 73).
    Iges,
    /// A zip archive or an `.x3p` file.
    X3p,
}

/// A CSV file's bytes as text, without the byte-order mark that spreadsheet programs put
/// before "UTF-8 CSV" (it is no part of the first value or header). Bytes that are not UTF-8
/// are a file that is not such a CSV (exit 1, not an I/O error), named with their offset;
/// `reads` says what the command reads instead.
pub(crate) fn csv_text(path: &Path, bytes: Vec<u8>, reads: &str) -> Result<String, CliError> {
    let mut text = String::from_utf8(bytes).map_err(|e| {
        CliError::new(
            Exit::Failed,
            format!(
                "{}: not text (byte {} is not UTF-8); {reads}",
                path.display(),
                e.utf8_error().valid_up_to()
            ),
        )
    })?;
    if text.starts_with('\u{feff}') {
        text.drain(..'\u{feff}'.len_utf8());
    }
    Ok(text)
}

/// Classifies a file from its name and its first bytes (at least the first line).
pub fn sniff_input(path: &Path, head: &[u8]) -> InputKind {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if ext == "x3p" || head.starts_with(b"PK\x03\x04") {
        return InputKind::X3p;
    }
    let first = head.split(|b| *b == b'\n').next().unwrap_or(&[]);
    let first = first.strip_suffix(b"\r").unwrap_or(first);
    let iges_line = first.len() == 80 && first.get(72) == Some(&b'S');
    if ext == "igs" || ext == "iges" || iges_line {
        return InputKind::Iges;
    }
    InputKind::GridCsv
}

pub use crate::scan::surface_files::part_path;

fn iges_write_error(e: SurfaceWriteError) -> CliError {
    let exit = match e {
        SurfaceWriteError::Format { .. } => Exit::Failed,
        SurfaceWriteError::Io { .. } => Exit::Io,
    };
    CliError::new(exit, e.to_string())
}

/// A height grid read from CSV: row-major heights in µm.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Number of rows (traced lines).
    pub rows: usize,
    /// Number of columns (points per line).
    pub cols: usize,
    /// Heights in µm, row-major.
    pub heights_um: Vec<f64>,
}

/// Grid CSVs of at least this many bytes are read in two halves side by side.
const PARALLEL_CSV_BYTES: usize = 256 << 10;

/// Parses the grid CSV: no header, `,` separated, one row per line; blank lines at the end
/// are ignored. Errors name the 1-based line and column and the offending content. A large
/// file is read as two runs of whole lines on two threads; the values, and the error (the
/// first in line order), are those of reading it line by line.
pub fn parse_grid(text: &str) -> Result<Grid, String> {
    parse_grid_split(text, PARALLEL_CSV_BYTES)
}

/// [`parse_grid`] of a text it takes over: the text is freed once both runs have read it,
/// before the second run's values join the first's, so the text and the grid whole are never
/// in memory beside the second run's own copy (the large fit's peak).
pub fn parse_grid_owned(text: String) -> Result<Grid, String> {
    parse_grid_owned_split(text, PARALLEL_CSV_BYTES)
}

/// [`parse_grid_owned`], reading in two runs when `text` has at least `parallel_bytes` bytes.
fn parse_grid_owned_split(text: String, parallel_bytes: usize) -> Result<Grid, String> {
    let runs = read_runs(&text, parallel_bytes);
    drop(text);
    runs.into_grid()
}

/// [`parse_grid`], reading in two runs when `text` has at least `parallel_bytes` bytes.
fn parse_grid_split(text: &str, parallel_bytes: usize) -> Result<Grid, String> {
    read_runs(text, parallel_bytes).into_grid()
}

/// What the runs of [`read_runs`] read: the first run's values (with room for all), its
/// lines, and the second run's lines and values when there is one.
struct Runs {
    heights_um: Vec<f64>,
    first: GridLines,
    second: Option<(GridLines, Vec<f64>)>,
}

/// Reads `text` in one run, or in two side by side when it has at least `parallel_bytes`
/// bytes; nothing of the result borrows `text`.
fn read_runs(text: &str, parallel_bytes: usize) -> Runs {
    let lines: Vec<&str> = text.lines().collect();
    let last = lines
        .iter()
        .rposition(|l| !l.trim().is_empty())
        .map_or(0, |i| i + 1);
    let lines = &lines[..last];
    // The second run starts at the first line past the middle byte.
    let split = if text.len() >= parallel_bytes && lines.len() >= 2 {
        let mut bytes = 0usize;
        lines
            .iter()
            .position(|l| {
                bytes += l.len() + 1;
                bytes >= text.len() / 2
            })
            .map_or(lines.len(), |i| (i + 1).min(lines.len()))
    } else {
        lines.len()
    };
    let (head, tail) = lines.split_at(split);
    // Room for every field at once (one per ',' plus one per line), so a large grid is not
    // copied while it grows; the second run's share is counted apart (one pass over the text
    // in all), so its buffer too is made once at its size.
    let separators = |b: &[u8]| b.iter().filter(|&&b| b == b',' || b == b'\n').count();
    let tail_start = tail
        .first()
        .map_or(text.len(), |l| l.as_ptr() as usize - text.as_ptr() as usize);
    let (head_seps, tail_seps) = (
        separators(&text.as_bytes()[..tail_start]),
        separators(&text.as_bytes()[tail_start..]),
    );
    let mut heights_um = Vec::with_capacity(head_seps + tail_seps + 1);
    let (first, second) = if tail.is_empty() {
        (parse_grid_lines(0, head, &mut heights_um), None)
    } else {
        let tail_fields = tail_seps + 1;
        std::thread::scope(|s| {
            let second = s.spawn(|| {
                let mut values = Vec::with_capacity(tail_fields);
                let run = parse_grid_lines(split, tail, &mut values);
                (run, values)
            });
            let first = parse_grid_lines(0, head, &mut heights_um);
            let second = second
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            (first, Some(second))
        })
    };
    Runs {
        heights_um,
        first,
        second,
    }
}

impl Runs {
    /// The grid: row lengths checked against line 1 and any unreadable line reported, in
    /// line order; then the second run's values after the first's.
    fn into_grid(self) -> Result<Grid, String> {
        let Runs {
            mut heights_um,
            first,
            second,
        } = self;
        let cols = first.counts.first().copied().unwrap_or(0);
        let mut rows = 0usize;
        let runs = std::iter::once(&first).chain(second.as_ref().map(|(run, _)| run));
        for run in runs {
            for (k, &n) in run.counts.iter().enumerate() {
                if n != cols {
                    return Err(format!(
                        "line {}: {n} values, but line 1 has {cols}; every row must have the same number of points",
                        run.first_line + k + 1
                    ));
                }
                rows += 1;
            }
            if let Some(e) = &run.error {
                return Err(e.clone());
            }
        }
        if rows == 0 {
            return Err("the file holds no data rows".into());
        }
        if let Some((_, values)) = second {
            heights_um.extend_from_slice(&values);
        }
        Ok(Grid {
            rows,
            cols,
            heights_um,
        })
    }
}

/// The lines of a run of grid lines read so far: each line's number of values, and the error
/// of the first line that cannot be read (where the run stops).
struct GridLines {
    /// 0-based index of the run's first line in the file.
    first_line: usize,
    counts: Vec<usize>,
    error: Option<String>,
}

/// Reads `lines` (the file's lines from 0-based index `first_line` on) into `heights_um`,
/// stopping at the first line that cannot be read.
fn parse_grid_lines(first_line: usize, lines: &[&str], heights_um: &mut Vec<f64>) -> GridLines {
    let mut run = GridLines {
        first_line,
        counts: Vec::with_capacity(lines.len()),
        error: None,
    };
    for (k, line) in lines.iter().enumerate() {
        // Plain lines of finite numbers take one pass; anything else is read (and its error
        // worded) field by field below.
        let n = match crate::numbers::parse_csv_line(line.as_bytes(), heights_um) {
            Some(n) => n,
            None => match parse_grid_line(first_line + k, line, heights_um) {
                Ok(n) => n,
                Err(e) => {
                    run.error = Some(e);
                    break;
                }
            },
        };
        run.counts.push(n);
    }
    run
}

/// One grid line field by field with `str::parse`; errors name the 1-based line and column.
fn parse_grid_line(li: usize, line: &str, heights_um: &mut Vec<f64>) -> Result<usize, String> {
    let mut n = 0usize;
    for (ci, field) in line.split(',').enumerate() {
        let f = field.trim();
        let v: f64 = f.parse().map_err(|_| {
            format!(
                "line {}, column {}: {f:?} is not a number (expected heights in µm, ',' separated, no header)",
                li + 1,
                ci + 1
            )
        })?;
        if !v.is_finite() {
            return Err(format!(
                "line {}, column {}: {f:?} is not a finite height",
                li + 1,
                ci + 1
            ));
        }
        heights_um.push(v);
        n += 1;
    }
    Ok(n)
}

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

/// The lines to fit, however they were read.
struct Input {
    grid: Grid,
    pitch_x_mm: f64,
    /// `Some` for a grid CSV (equally spaced rows).
    pitch_y_mm: Option<f64>,
    y_mm: Vec<f64>,
    /// Line indices (a scan's `NNNN`; rows for a CSV).
    index: Vec<u32>,
    output: PathBuf,
    kind: &'static str,
    /// The degrees to fit with.
    degrees: FitOptions,
    /// The scan's frozen plan, when the input is a scan with a readable journal.
    plan: Option<crate::scan::plan::Plan>,
    /// λc of the roughness the spike rule judges (a scan of primary profiles).
    lambda_c_mm: Option<f64>,
    /// A scan's lines left out, each with its file and why (none for a grid CSV).
    left_out: Vec<crate::report::scan_dir::LeftOut>,
}

/// The IGES Start section's words for the lines a fit of a scan left out, so the file itself
/// says which lines its surface does not pass through.
fn left_out_start_line(left_out: &[crate::report::scan_dir::LeftOut]) -> Option<String> {
    (!left_out.is_empty()).then(|| {
        let each: Vec<String> = left_out
            .iter()
            .map(|l| format!("{} ({}, {})", l.line, l.file, l.why))
            .collect();
        format!("Lines left out: {}.", each.join("; "))
    })
}

fn read_scan(args: &Args) -> Result<Input, CliError> {
    for (name, given) in [
        ("--pitch-x", args.pitch_x.is_some()),
        ("--pitch-y", args.pitch_y.is_some()),
    ] {
        if given {
            return Err(CliError::new(
                Exit::Usage,
                format!(
                    "{name} is for a grid CSV; a scan directory's pitch and y come from its line metadata"
                ),
            ));
        }
    }
    let report_error = |e: crate::report::ReportError| {
        let exit = match &e {
            crate::report::ReportError::Store(crate::scan::store_error::StoreError::Io {
                ..
            }) => Exit::Io,
            _ => Exit::Failed,
        };
        CliError::new(exit, e.to_string())
    };
    // Only the lines the journal vouches for are fitted; the others are named below.
    let vouched = crate::report::load_vouched_lines(&args.input).map_err(report_error)?;
    let stored = &vouched.lines;
    let lines = crate::report::grid::LineGrid::of_scan(stored, &args.input.join("lines"))
        .map_err(report_error)?;
    if !vouched.incomplete.is_empty() {
        tell!(
            "surfscan: warning: {}",
            crate::report::scan_dir::incomplete_lines_warning(
                &crate::report::scan_dir::line_files(&vouched.incomplete),
                vouched.incomplete.len(),
                &args.input.join("lines"),
            )
        );
    }
    if let Err(e) = &vouched.journal {
        tell!(
            "surfscan: warning: the line files cannot be checked against the journal ({e}); they are used as they are"
        );
    }
    for w in vouched.warnings(&args.input.join("lines")) {
        tell!("surfscan: warning: {w}");
    }
    let default_output = args.input.join("surface.igs");
    if args.output.is_none() && !args.force {
        if let Some(existing) = existing_surface(&default_output) {
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
    }
    let start = vouched.journal.as_ref().ok().map(|s| &s.start);
    Ok(Input {
        grid: Grid {
            rows: lines.y_mm.len(),
            cols: lines.cols,
            heights_um: lines.heights_um,
        },
        pitch_x_mm: lines.pitch_x_mm,
        pitch_y_mm: None,
        y_mm: lines.y_mm,
        index: lines.index,
        output: args
            .output
            .clone()
            .unwrap_or_else(|| args.input.join("surface.igs")),
        kind: "scan",
        degrees: crate::report::scan_dir::scan_degrees(args.degree_u, args.degree_v, start),
        plan: start.map(|s| s.plan),
        lambda_c_mm: stored.first().and_then(|l| {
            let o = crate::metrology::params::Options::from_profile(&l.profile);
            o.apply_lambda_c.then_some(o.lambda_c_mm)
        }),
        left_out: vouched.left_out(),
    })
}

/// The existing surface at `output` (or the first part of a split one), if any.
fn existing_surface(output: &Path) -> Option<PathBuf> {
    if output.exists() {
        return Some(output.to_path_buf());
    }
    let stem = output.file_stem()?.to_string_lossy().into_owned();
    let dir = output.parent()?;
    std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .map(|n| {
                    n.to_string_lossy()
                        .starts_with(&format!("{stem}.part1-of-"))
                })
                .unwrap_or(false)
        })
}

fn read_csv(args: &Args) -> Result<Input, CliError> {
    let (Some(pitch_x), Some(pitch_y)) = (args.pitch_x, args.pitch_y) else {
        return Err(CliError::new(
            Exit::Usage,
            "a grid CSV needs --pitch-x MM and --pitch-y MM (a scan directory stores its own)",
        ));
    };
    for (name, v) in [("--pitch-x", pitch_x), ("--pitch-y", pitch_y)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(CliError::new(
                Exit::Usage,
                format!("{name} {v} mm must be a positive number of millimetres"),
            ));
        }
    }
    let Some(output) = args.output.clone() else {
        return Err(CliError::new(
            Exit::Usage,
            "a grid CSV needs -o OUT.igs (only a scan directory has a default output)",
        ));
    };
    let bytes =
        std::fs::read(&args.input).map_err(|e| io_err("cannot read grid", &args.input, e))?;
    let text = csv_text(
        &args.input,
        bytes,
        "fit reads a grid CSV or a scan directory",
    )?;
    let grid = parse_grid_owned(text)
        .map_err(|m| CliError::new(Exit::Failed, format!("{}: {m}", args.input.display())))?;
    let rows = grid.rows;
    Ok(Input {
        grid,
        pitch_x_mm: pitch_x,
        pitch_y_mm: Some(pitch_y),
        y_mm: (0..rows).map(|r| r as f64 * pitch_y).collect(),
        index: (0..rows as u32).collect(),
        output,
        kind: "grid",
        degrees: crate::report::scan_dir::scan_degrees(args.degree_u, args.degree_v, None),
        plan: None,
        lambda_c_mm: None,
        left_out: Vec::new(),
    })
}

/// Refuses a file that is absent, or that is not a grid CSV, naming what it is.
fn check_input_file(path: &Path) -> Result<(), CliError> {
    use std::io::Read;
    let mut head = vec![0u8; 256];
    let n = std::fs::File::open(path)
        .and_then(|mut f| f.read(&mut head))
        .map_err(|e| {
            CliError::new(
                Exit::Io,
                format!(
                    "cannot read {}: {e}; fit reads a grid CSV of heights in µm or a scan directory",
                    path.display()
                ),
            )
        })?;
    head.truncate(n);
    match sniff_input(path, &head) {
        InputKind::GridCsv => Ok(()),
        InputKind::Iges => Err(CliError::new(
            Exit::Usage,
            format!(
                "{} is an IGES file (a fitted surface), not heights to fit; fit reads a grid CSV of heights in µm or a scan directory",
                path.display()
            ),
        )),
        InputKind::X3p => Err(CliError::new(
            Exit::Usage,
            format!(
                "{} is an X3P archive; fit reads a grid CSV of heights in µm or a scan directory (`surfscan analyze` reads X3P)",
                path.display()
            ),
        )),
    }
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
    pitch_x_mm: f64,
    y_mm: &[f64],
    index: &[u32],
    recipe: &ModelRecipe,
    progress: &indicatif::ProgressBar,
) -> Result<(FitResult, Vec<LineSpike>), CliError> {
    let failed = |e: &dyn std::fmt::Display| {
        CliError::new(Exit::Failed, format!("{}: {e}", input.display()))
    };
    if recipe.is_paper() {
        let mut fitter = IncrementalFitter::new(recipe.degrees);
        // The stores at their final size at once: no regrowing (and copying) as lines come.
        fitter.reserve_lines(grid.rows, grid.cols);
        for (row, &y) in grid.heights_um.chunks_exact(grid.cols).zip(y_mm) {
            fitter
                .push_row(y, pitch_x_mm, row)
                .map_err(|e| failed(&e))?;
            progress.inc(1);
        }
        Ok((fitter.finish().map_err(|e| failed(&e))?, Vec::new()))
    } else {
        let m = fit_model(&grid.heights_um, grid.cols, index, pitch_x_mm, y_mm, recipe)
            .map_err(|e| failed(&e))?;
        Ok((m.fit, m.replaced))
    }
}

/// Names every spike replaced before fitting (only ever when asked for).
fn report_replaced(replaced: &[LineSpike]) {
    for r in replaced {
        tell!(
            "surfscan: replaced before fitting (asked for): spike in line {} at x = {} mm, height {} µm",
            crate::numfmt::line_label(r.line),
            crate::numfmt::fmt(r.spike.x_mm, crate::numfmt::Quantity::PositionMm),
            crate::numfmt::fmt(r.spike.height_um, crate::numfmt::Quantity::HeightUm)
        );
    }
}

/// The heights the surface was fitted to: the grid's, with any replaced spike bridged.
fn fitted_heights<'a>(
    heights_um: &'a [f64],
    cols: usize,
    index: &[u32],
    replaced: &[LineSpike],
) -> std::borrow::Cow<'a, [f64]> {
    if replaced.is_empty() {
        std::borrow::Cow::Borrowed(heights_um)
    } else {
        std::borrow::Cow::Owned(bridged_grid(heights_um, cols, index, replaced).0)
    }
}

/// What the verdict on the model between lines is computed from (besides the heights).
#[derive(Clone, Copy)]
struct Judge<'a> {
    cols: usize,
    pitch_x_mm: f64,
    pitch_y_mm: Option<f64>,
    y_mm: &'a [f64],
    recipe: &'a ModelRecipe,
    compare: bool,
}

/// The verdict on the model between lines, and the alternatives when asked for.
struct Judged {
    threshold: f64,
    sq: Result<f64, String>,
    every: Result<usize, String>,
    verdict: Result<crate::metrology::holdout::BetweenLines, String>,
    alternatives: Option<Vec<crate::metrology::alternatives::Alternative>>,
    holdout_s: f64,
}

impl Judge<'_> {
    /// Every 2nd line left out (or every k-th when too few lines remain for that, as the
    /// report does), refitted the same way and judged against Sq of `fitted_z`.
    fn run(&self, fitted_z: &[f64], threshold: f64) -> Judged {
        let t_holdout = Instant::now();
        let rows = self.y_mm.len();
        let mean_py = match (self.y_mm.first(), self.y_mm.last()) {
            (Some(a), Some(b)) if rows > 1 => (b - a).abs() / (rows - 1) as f64,
            _ => self.pitch_y_mm.unwrap_or(1.0),
        };
        let sq = areal_sq_um(&ArealGrid {
            heights_um: fitted_z,
            rows,
            cols: self.cols,
            pitch_x_mm: self.pitch_x_mm,
            pitch_y_mm: mean_py,
        })
        .map_err(|e| e.to_string());
        let degrees = self.recipe.degrees;
        let every = holdout_every_or_reason(rows, degrees.degree_v);
        let verdict = sq.clone().and_then(|sq| {
            let every = every.clone()?;
            between_lines(
                fitted_z,
                self.cols,
                self.pitch_x_mm,
                self.y_mm,
                degrees,
                self.recipe.method,
                every,
                sq,
                threshold,
            )
            // The refit's heights at the held-out lines are not reported here; only the
            // figures are kept.
            .map(|mut b| {
                b.model_um = Vec::new();
                b
            })
            .map_err(|e| e.to_string())
        });
        let alternatives = match (&sq, &every, self.compare) {
            (Ok(sq), Ok(every), true) => Some(compare_alternatives(
                fitted_z,
                self.cols,
                self.pitch_x_mm,
                self.y_mm,
                degrees,
                *every,
                *sq,
                threshold,
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
}

/// The Start and Global section contents of the surface's IGES files (the replaced spikes
/// are added by the caller).
fn iges_options(
    args: &Args,
    output: &Path,
    recipe: &ModelRecipe,
    (rows, cols): (usize, usize),
    pitch_x_mm: f64,
    pitch_y_mm: Option<f64>,
    y_mm: &[f64],
) -> IgesOptions {
    let options = recipe.degrees;
    let now = chrono::Utc::now().naive_utc();
    let file_name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    IgesOptions {
        file_name,
        start_lines: vec![
            format!(
                "Surface fitted by surfscan {} ({}, p={}, q={}); units mm.",
                env!("CARGO_PKG_VERSION"),
                match recipe.method {
                    crate::fit::VMethod::Interpolate => "global B-spline interpolation".to_string(),
                    crate::fit::VMethod::LeastSquares { control_rows } => format!(
                        "B-spline interpolation along x, least squares across the lines with {control_rows} control rows"
                    ),
                },
                options.degree_u,
                options.degree_v
            ),
            match pitch_y_mm {
                Some(py) => format!(
                    "Input: {} ({} lines x {} points, pitch x {} mm, pitch y {} mm, heights um).",
                    args.input.display(),
                    rows,
                    cols,
                    pitch_x_mm,
                    py
                ),
                None => format!(
                    "Input: scan {} ({} lines x {} points, pitch x {} mm, y {} .. {} mm, heights um).",
                    args.input.display(),
                    rows,
                    cols,
                    pitch_x_mm,
                    y_mm.first().copied().unwrap_or(f64::NAN),
                    y_mm.last().copied().unwrap_or(f64::NAN)
                ),
            },
        ],
        timestamp: now,
        max_parameter_lines_per_file: args.max_iges_lines_per_file,
        max_parameter_lines_per_entity: args.max_iges_lines_per_entity,
        ..IgesOptions::default()
    }
}

/// Runs `surfscan fit`.
pub fn run(args: Args) -> Result<(), CliError> {
    if args.degree_u == Some(0) || args.degree_v == Some(0) {
        return Err(CliError::new(
            Exit::Usage,
            "--degree-u and --degree-v must be at least 1 (the paper uses 5)",
        ));
    }
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
    let t_read = Instant::now();
    let input = if args.input.is_dir() {
        read_scan(&args)?
    } else {
        // Arguments first (a bad value is a usage error whatever the file), then the file
        // itself, then what a grid CSV needs: a missing file is never reported as a
        // missing pitch.
        for (name, v) in [("--pitch-x", args.pitch_x), ("--pitch-y", args.pitch_y)] {
            if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(CliError::new(
                    Exit::Usage,
                    format!("{name} {v} mm must be a positive number of millimetres"),
                ));
            }
        }
        check_input_file(&args.input)?;
        read_csv(&args)?
    };
    let read_s = t_read.elapsed().as_secs_f64();
    let Input {
        mut grid,
        pitch_x_mm,
        pitch_y_mm,
        y_mm,
        index,
        output,
        kind,
        degrees: options,
        plan,
        lambda_c_mm,
        left_out,
    } = input;
    let method = args
        .model
        .v_method(grid.rows, options.degree_v)?
        .or(plan.map(|p| p.v_method))
        .unwrap_or_default();
    let replace_spikes = match args.model.replace() {
        Some(true) => Some(args.model.spikes()?),
        _ => plan.and_then(|p| p.replace_spikes),
    };
    let recipe = ModelRecipe {
        degrees: options,
        method,
        replace_spikes,
        lambda_c_mm,
    };

    let progress = if std::io::stderr().is_terminal() && grid.heights_um.len() >= 1_000_000 {
        indicatif::ProgressBar::new(grid.rows as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let (rows, cols) = (grid.rows, grid.cols);
    let judge = Judge {
        cols,
        pitch_x_mm,
        pitch_y_mm,
        y_mm: &y_mm,
        recipe: &recipe,
        compare: args.compare,
    };
    let fit_step = || {
        let t_fit = Instant::now();
        let fitted = fit_surface(
            &args.input,
            &grid,
            pitch_x_mm,
            &y_mm,
            &index,
            &recipe,
            &progress,
        );
        progress.finish_and_clear();
        let (fit, replaced) = fitted?;
        report_replaced(&replaced);
        Ok::<_, CliError>((fit, replaced, t_fit.elapsed().as_secs_f64()))
    };
    let residual_step = |fit: &FitResult, heights_um: &[f64]| {
        let t_res = Instant::now();
        let r = max_residual_mm(fit, pitch_x_mm, &y_mm, heights_um, cols);
        (r, t_res.elapsed().as_secs_f64())
    };
    let write_step = |fit: &FitResult, replaced: &[LineSpike]| {
        let mut opts = iges_options(
            &args,
            &output,
            &recipe,
            (rows, cols),
            pitch_x_mm,
            pitch_y_mm,
            &y_mm,
        );
        opts.start_lines.extend(recipe.start_lines(replaced));
        opts.start_lines.extend(left_out_start_line(&left_out));
        ensure_parent(&output)?;
        let t_write = Instant::now();
        let written =
            write_surface_files(&output, &fit.surface, &opts).map_err(iges_write_error)?;
        Ok::<_, CliError>((written, t_write.elapsed().as_secs_f64()))
    };
    // A threshold given wrongly is refused after the fit and before anything is written, as
    // in the serial order below.
    let threshold = args.model.holdout_threshold();
    let (fit, replaced, fit_s, (residual_mm, residual_s), judged, (written, write_s)) =
        match threshold {
            Ok(threshold) if grid.heights_um.len() <= SIDE_BY_SIDE_MAX_POINTS => {
                // The verdict between lines needs only the heights the surface is fitted to (the
                // grid's own for the paper's fit, which replaces no spike), so it runs beside the
                // fit and the IGES write, and the residual check runs while the file is formatted
                // and synced: the same computations on the same inputs, so the same numbers, in
                // about the time of the longest.
                let (heights, index) = (&grid.heights_um, &index);
                std::thread::scope(|outer| {
                    let early = recipe
                        .is_paper()
                        .then(|| outer.spawn(move || judge.run(heights, threshold)));
                    let (fit, replaced, fit_s) = fit_step()?;
                    let judging = match early {
                        Some(h) => h,
                        None => {
                            let replaced = replaced.clone();
                            outer.spawn(move || {
                                judge.run(
                                    &fitted_heights(heights, cols, index, &replaced),
                                    threshold,
                                )
                            })
                        }
                    };
                    let (residual, written) = std::thread::scope(|inner| {
                        let writing = inner.spawn(|| write_step(&fit, &replaced));
                        let residual = residual_step(&fit, heights);
                        (residual, joined(writing))
                    });
                    let written = written?;
                    Ok::<_, CliError>((fit, replaced, fit_s, residual, joined(judging), written))
                })?
            }
            threshold => {
                // The paper's surface (which replaces no spike) is judged on the heights as
                // read before it is fitted, so the refit's memory is freed before the fitter
                // takes its own; a recipe that replaces spikes is judged after its fit, on the
                // grid with them bridged.
                let early = match &threshold {
                    Ok(t) if recipe.is_paper() => Some(judge.run(&grid.heights_um, *t)),
                    _ => None,
                };
                let (fit, replaced, fit_s) = fit_step()?;
                let residual = residual_step(&fit, &grid.heights_um);
                let judged = match early {
                    Some(judged) => judged,
                    None => judge.run(
                        &fitted_heights(&grid.heights_um, cols, &index, &replaced),
                        threshold?,
                    ),
                };
                // The heights are not needed past the residual check and the verdict: free them
                // before the IGES files are planned and written, which is when a large surface
                // needs the most memory.
                grid.heights_um = Vec::new();
                let written = write_step(&fit, &replaced)?;
                (fit, replaced, fit_s, residual, judged, written)
            }
        };
    let Judged {
        threshold,
        sq,
        every,
        verdict,
        alternatives,
        holdout_s,
    } = judged;
    let n_files = written.len();
    let mut stats = crate::iges::IgesStats::default();
    for w in &written {
        stats.patches += w.patches;
        stats.bytes += w.bytes;
        stats.parameter_lines += w.parameter_lines;
    }
    let files: Vec<serde_json::Value> = written
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

    let s = &fit.surface;
    let mut report = serde_json::json!({
        "input": args.input.display().to_string(),
        "input_kind": kind,
        "output": output.display().to_string(),
        "grid": { "rows": grid.rows, "cols": grid.cols },
        "pitch_x_mm": pitch_x_mm,
        "pitch_y_mm": pitch_y_mm,
        "y_mm": y_mm,
        "lines": index,
        "lines_left_out": left_out,
        "max_residual_mm": residual_mm,
        "patches": stats.patches,
        "iges_bytes": stats.bytes,
        "iges_parameter_lines": stats.parameter_lines,
        "iges_files": files,
        "model": {
            "description": recipe.describe(),
            "v_method": recipe.method,
            "spikes_replaced": replaced,
        },
        "between_lines": verdict.as_ref().ok(),
        "between_lines_error": verdict.as_ref().err(),
        "alternatives": alternatives.as_ref().map(|alts| alts
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
            "holdout": holdout_s,
            "read": read_s,
            "fit_params": fit.timings.params_s,
            "fit_knots_factor": fit.timings.knots_factor_s,
            "fit_solve_u": fit.timings.solve_u_s,
            "fit_solve_v": fit.timings.solve_v_s,
            "fit_total": fit_s,
            "residual": residual_s,
            "write_iges": write_s,
        },
    });
    if let (Some(o), Ok(serde_json::Value::Object(shape))) = (
        report.as_object_mut(),
        serde_json::to_value(SurfaceShape::of(s)),
    ) {
        o.extend(shape);
    }
    if let Some(path) = &args.report {
        ensure_parent(path)?;
        write_atomically(path, |w| {
            serde_json::to_writer_pretty(&mut *w, &report).map_err(std::io::Error::other)?;
            std::io::Write::write_all(w, b"\n")
        })
        .map_err(|e| io_err("cannot write report", path, e))?;
    }
    let written = if n_files == 1 {
        output.display().to_string()
    } else {
        format!(
            "{} too large for one IGES file; wrote {} files {} .. {}",
            output.display(),
            n_files,
            part_path(&output, 1, n_files).display(),
            part_path(&output, n_files, n_files).display()
        )
    };
    say!(
        "{}: {}x{} grid, {}x{} poles, {} patch(es), {} bytes; fit {:.1} ms, write {:.1} ms",
        written,
        grid.rows,
        grid.cols,
        s.count_u(),
        s.count_v(),
        stats.patches,
        stats.bytes,
        fit_s * 1e3,
        write_s * 1e3
    );
    match &verdict {
        Ok(b) => say!("{}", b.short()),
        Err(e) => say!("no verdict on the model between lines: {e}"),
    }
    if let Some(alts) = &alternatives {
        say!(
            "\nhold-out of the alternatives (every {} line left out and refitted; supported means rms ≤ {threshold} × Sq):",
            ordinal(*every.as_ref().unwrap_or(&2))
        );
        say_text!("{}", alternatives_table(alts));
    } else if args.compare {
        match (&sq, &every) {
            (Err(e), _) => say!("no comparison: the grid has no Sq ({e})"),
            (_, Err(e)) => say!("no comparison: {e}"),
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_grid_and_ignores_trailing_blank_lines() {
        let g = parse_grid("1, 2.5,3\n-4,5e-1,6\n\n").unwrap();
        assert_eq!((g.rows, g.cols), (2, 3));
        assert_eq!(g.heights_um, vec![1.0, 2.5, 3.0, -4.0, 0.5, 6.0]);
    }

    #[test]
    fn names_line_column_and_content_of_bad_values() {
        let e = parse_grid("1,2,3\n4,x5,6\n").unwrap_err();
        assert!(
            e.contains("line 2, column 2") && e.contains("\"x5\""),
            "{e}"
        );
        let e = parse_grid("1,2,3\n4,NaN,6\n").unwrap_err();
        assert!(e.contains("line 2, column 2"), "{e}");
        let e = parse_grid("1,2,3\n4,5\n").unwrap_err();
        assert!(
            e.contains("line 2: 2 values") && e.contains("line 1 has 3"),
            "{e}"
        );
        assert!(parse_grid("\n\n").is_err());
    }

    #[test]
    fn a_grid_read_in_two_runs_equals_it_read_line_by_line() {
        let (rows, cols) = (40usize, 7usize);
        let base: Vec<String> = (0..rows)
            .map(|r| {
                (0..cols)
                    .map(|c| format!("{:.4}", (r * cols + c) as f64 * 0.37 - 5.0))
                    .collect::<Vec<_>>()
                    .join(",")
            })
            .collect();
        let join = |t: &[String], end: &str| t.join(end) + end;
        let mut texts = vec![
            join(&base, "\n"),
            join(&base, "\r\n"),
            join(&base, "\n") + "\n \n",
        ];
        // A bad line (a non-number, a row too short or too long, a blank line) at the start,
        // on either side of the split and at the end; and one in each run.
        let spoil = |t: &mut Vec<String>, at: usize, how: usize| match how {
            0 => t[at] = t[at].replacen(',', ",1e,", 1),
            1 => t[at] = t[at].rsplit_once(',').unwrap().0.to_string(),
            2 => t[at].push_str(",1.5"),
            _ => t[at].clear(),
        };
        for at in [0, 1, 19, 20, 21, 38, 39] {
            for how in 0..4 {
                let mut t = base.clone();
                spoil(&mut t, at, how);
                texts.push(join(&t, "\n"));
            }
        }
        for (a, b) in [(0, 1), (1, 0), (2, 3), (3, 2)] {
            let mut t = base.clone();
            spoil(&mut t, 5, a);
            spoil(&mut t, 30, b);
            texts.push(join(&t, "\n"));
        }
        for text in &texts {
            let serial = parse_grid_split(text, usize::MAX);
            assert_eq!(parse_grid_split(text, 0), serial, "{text:?}");
            // The owned form (the text freed before the runs are joined) too.
            assert_eq!(parse_grid_owned_split(text.clone(), 0), serial, "{text:?}");
        }
        // And the values are the numbers written.
        let g = parse_grid_split(&texts[0], 0).unwrap();
        let want: Vec<f64> = base
            .iter()
            .flat_map(|l| l.split(',').map(|f| f.parse::<f64>().unwrap()))
            .collect();
        assert_eq!((g.rows, g.cols), (rows, cols));
        assert_eq!(g.heights_um, want);
    }
}
