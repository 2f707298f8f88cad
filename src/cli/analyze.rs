//! `surfscan analyze`: surface characterisation of a scan directory (as the scan daemon writes
//! it), of a profile CSV (header `x_mm,z_um`) or of a grid CSV of heights in µm (rows = traced
//! lines along y, columns = points along x, as `surfscan fit` reads; pitches required; a
//! row that cannot be used is left out with a warning, the others keep their y).
//! A scan directory and a grid go through [`crate::report`] (the daemon's entry point
//! [`crate::report::characterise_scan`] for scans): `report.json`, `summary.csv`,
//! `measured.x3p`, `model.x3p` (ISO 25178-72), `bac.png|svg`, `heightmap.png|svg` and
//! `overlay.png|svg` (measured vs model of one line). A profile gets `report.json` and
//! `summary.csv`. An X3P file (ISO 25178-72, as Gwyddion, MountainsMap and surfalize write
//! it) is read as a grid with its own pitches (rows along y are the traced lines); a line
//! holding invalid (not measured) points is left out with a warning rather than filled in,
//! and a one-line X3P profile is characterised as a profile.
//!
//! The model is fitted once at `--degree-u/--degree-v` and `--v-method` (default: a scan's
//! frozen plan, else the paper's 5/5 interpolation); the report's model sections describe
//! that surface and the hold-out refits are made the same way. The characterisation's own
//! settings (curves, levels, λc, filter, spike rule and policy, hold-out threshold) default
//! to the `[analysis]` the scan froze in its plan, each flag overriding its part, so a scan
//! directory gives the report its scan wrote. Spikes are named in the warnings and report.json; `--outliers
//! exclude` leaves them out of the per-line and measured-grid parameters, `--replace-spikes`
//! replaces them before fitting.
//!
//! The summary printed names the verdict on the model between lines. Exit status: 0 done,
//! 3 done but part of the characterisation could not be made (report.json's
//! `characterisation.failed_sections` says which and why), 1 the input cannot be
//! characterised at all, 2 usage, 74 I/O.
//!
//! Layer 5 (composition): reads files, calls [`crate::report`] and [`crate::metrology`].

use super::model_args::ModelArgs;
use super::{CliError, Exit};
use crate::metrology::params::{analyze_line, Options, Recipe, RoughnessParams};
use crate::metrology::MAX_HEIGHT_UM;
use crate::report::scan_dir::fit_for_report;
use crate::report::{
    characterise, characterise_scan, LineGrid, Model, ReportContext, ReportError,
    ScanAnalysisOptions, ScanOutputs,
};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Arguments of `surfscan analyze`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scan directory, X3P file, profile CSV (`x_mm,z_um` header) or grid CSV of heights in
    /// µm.
    pub input: PathBuf,
    /// Cut-off λc in mm (also the sampling length). Default: for a scan its frozen
    /// `[analysis]` λc, else the λc the instrument recorded (else 0.8 mm); for a CSV 0.8 mm.
    #[arg(long)]
    pub lc: Option<f64>,
    /// No λc filter (the input already is an R profile). Default: for a scan as its frozen
    /// `[analysis]` says, else filter unless the instrument exported an R profile; for a CSV,
    /// filter.
    #[arg(long)]
    pub no_filter: bool,
    /// Evaluate the central N sampling lengths (λc each) of every line, leaving the rest at
    /// each end out as the filter's run-up and run-out, as an instrument traces N·λc plus λc
    /// (CSV and X3P inputs; a scan's lines carry the instrument's N). Default: the whole
    /// line, N = its length / λc.
    #[arg(long, value_name = "N")]
    pub sampling_lengths: Option<u32>,
    /// Grid pitch along x (between columns), mm.
    #[arg(long)]
    pub pitch_x: Option<f64>,
    /// Grid pitch along y (between rows), mm.
    #[arg(long)]
    pub pitch_y: Option<f64>,
    /// Profile curves extracted from the model for the bearing area curves. Default: a
    /// scan's frozen `[analysis]`, else 31.
    #[arg(long)]
    pub curves: Option<usize>,
    /// Equal height levels per bearing area curve. Default: a scan's frozen `[analysis]`,
    /// else 101.
    #[arg(long)]
    pub levels: Option<usize>,
    /// Line drawn in the measured-vs-model overlay (a scan's line index, a grid's 0-based
    /// row); default the middle line.
    #[arg(long)]
    pub overlay_line: Option<u32>,
    /// Output directory. Default: the scan directory for a scan, `.` for a CSV.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Degree of the model along u (x). Default: a scan's frozen plan, else 5 (the paper).
    #[arg(long)]
    pub degree_u: Option<usize>,
    /// Degree of the model along v (y). Default: a scan's frozen plan, else 5 (the paper).
    #[arg(long)]
    pub degree_v: Option<usize>,
    /// Spikes: flag (named, the data as measured) or exclude (also left out of the per-line
    /// and measured-grid parameters, bridged by the straight line between neighbours).
    /// Default: a scan's frozen `[analysis]`, else flag.
    #[arg(long, value_enum)]
    pub outliers: Option<OutliersArg>,
    /// The surface and the spike rule.
    #[command(flatten)]
    pub model: ModelArgs,
}

/// What characterisation does with the spikes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OutliersArg {
    /// Name them; the data stay as measured.
    Flag,
    /// Also leave them out of the per-line and measured-grid parameters.
    Exclude,
}

/// Default λc in mm for CSV input.
const DEFAULT_LC_MM: f64 = 0.8;

/// One line's entry in the report.
#[derive(Debug, Serialize)]
struct LineReport {
    index: u32,
    y_mm: f64,
    #[serde(flatten)]
    params: RoughnessParams,
    /// Rmr(c) at depths c = 0, 10, …, 100 % of Rt below the highest peak: `[c_um, Rmr_pct]`.
    #[serde(rename = "Rmr_table")]
    rmr_table: Vec<[f64; 2]>,
}

fn rmr_table(a: &crate::metrology::params::LineAnalysis) -> Vec<[f64; 2]> {
    (0..=10)
        .map(|k| {
            let c = a.params.rt_um * k as f64 / 10.0;
            [c, a.rmr_pct(c)]
        })
        .collect()
}

#[derive(Debug, Serialize)]
struct Report {
    software: String,
    input: String,
    kind: &'static str,
    recipe: Recipe,
    lines: Vec<LineReport>,
    /// The spike rule, its policy and every spike found.
    #[serde(skip_serializing_if = "Option::is_none")]
    outliers: Option<crate::report::document::OutliersReport>,
    /// What the operator should know about these numbers.
    warnings: Vec<String>,
}

/// One profile (a profile CSV, an X3P file of one line): its spikes found (and bridged when
/// asked for), its parameters, the warnings printed and in the report, the outputs written
/// and what they say printed.
fn characterise_profile(
    args: &Args,
    input: String,
    mut z: Vec<f64>,
    pitch: f64,
    options: &Options,
    mut warnings: Vec<String>,
    out: &Path,
) -> Result<(), CliError> {
    // Spikes, judged as a grid's lines are, and bridged when asked for.
    let rule = args.model.spikes()?;
    let exclude = args.outliers == Some(OutliersArg::Exclude);
    let lambda_c = options.apply_lambda_c.then_some(options.lambda_c_mm);
    let outliers =
        crate::report::outliers::find(&z, z.len(), &[0], pitch, lambda_c, &rule, exclude);
    crate::report::outliers::warn(&outliers, &[], pitch, &mut warnings);
    if exclude && !outliers.spikes.is_empty() {
        z = crate::metrology::outliers::bridged_grid(&z, z.len(), &[0], &outliers.spikes).0;
    }
    let a = analyze_line(&z, pitch, options)
        .map_err(|e| failed(format!("{}: {e}", args.input.display())))?;
    if !options.apply_lambda_c {
        warnings.extend(uncentred(&z, &a.params));
    }
    for w in &warnings {
        tell!("surfscan: warning: {w}");
    }
    let summary = profile_summary(z.len(), pitch, &a.params, options);
    let report = Report {
        software: crate::build_info::software(),
        input,
        kind: "profile",
        recipe: a.recipe.clone(),
        lines: vec![LineReport {
            index: 0,
            y_mm: 0.0,
            rmr_table: rmr_table(&a),
            params: a.params,
        }],
        outliers: Some(outliers),
        warnings,
    };
    write_outputs(out, &report)?;
    say!("{}: {summary}", out.join("report.json").display());
    Ok(())
}

/// Longest profile taken at face value, mm: far beyond a stylus instrument's traverse (the
/// SJ-210's is 17.5 mm), so a longer one most likely has its x in µm.
const PLAUSIBLE_LENGTH_MM: f64 = 100.0;

/// A warning when `points` at `pitch_mm` make a profile longer than [`PLAUSIBLE_LENGTH_MM`].
fn implausible_length(points: usize, pitch_mm: f64) -> Option<String> {
    let length = points.saturating_sub(1) as f64 * pitch_mm;
    (length > PLAUSIBLE_LENGTH_MM).then(|| {
        format!(
            "the profile is {} mm long ({points} points {} mm apart), longer than any stylus traverse: check that x is in mm",
            crate::numfmt::fmt(length, crate::numfmt::Quantity::LengthMm),
            crate::numfmt::fmt(pitch_mm, crate::numfmt::Quantity::LengthMm)
        )
    })
}

/// With `--no-filter` the heights are taken as a roughness profile about its mean line; a
/// warning when they are not centred (an offset or a form the filter would have removed):
/// their mean is more than half of Rq away from zero, or a peak height or valley depth comes
/// out negative.
fn uncentred(z: &[f64], p: &RoughnessParams) -> Option<String> {
    use crate::numfmt::{fmt, Quantity};
    let mean = z.iter().sum::<f64>() / z.len().max(1) as f64;
    (mean.abs() > 0.5 * p.rq_um || p.rp_um < 0.0 || p.rv_um < 0.0).then(|| {
        format!(
            "with --no-filter the heights are taken as a roughness profile about its mean line, but their mean is {} µm against Rq {} µm (Rp {} µm, Rv {} µm): an offset or form remains; leave out --no-filter to apply the λc filter",
            fmt(mean, Quantity::HeightUm),
            fmt(p.rq_um, Quantity::HeightUm),
            fmt(p.rp_um, Quantity::HeightUm),
            fmt(p.rv_um, Quantity::HeightUm)
        )
    })
}

fn failed(msg: impl Into<String>) -> CliError {
    CliError::new(Exit::Failed, msg)
}

fn parse_numbers(line: &str) -> Option<Vec<f64>> {
    let mut fast = Vec::new();
    if crate::numbers::parse_csv_line(line.as_bytes(), &mut fast).is_some() {
        return Some(fast);
    }
    parse_fields(line).ok()
}

/// A line field by field with `str::parse` (padded fields, NaN: what the fast reader
/// declines), or its first field that is not a number: 0-based column and the field.
fn parse_fields(line: &str) -> Result<Vec<f64>, (usize, &str)> {
    line.split(',')
        .map(str::trim)
        .enumerate()
        .map(|(k, f)| f.parse::<f64>().map_err(|_| (k, f)))
        .collect()
}

/// Reads a profile CSV: returns pitch (mm) and heights (µm). x must be uniformly spaced.
fn read_profile(path: &Path, text: &str) -> Result<(f64, Vec<f64>), CliError> {
    // The header states the units: exactly x in mm and z in µm. Anything else (heights in
    // nm, a third column) would be read as something it is not, a thousand times off or the
    // wrong column, without a word.
    let header = text.lines().next().unwrap_or_default();
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    if columns != ["x_mm", "z_um"] {
        return Err(failed(format!(
            "{}: a profile CSV's header is x_mm,z_um (x in mm, heights in µm, two columns); this one is {:?}: convert the heights to µm and keep only those two columns",
            path.display(),
            header.trim()
        )));
    }
    let mut x = Vec::new();
    let mut z = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        match parse_numbers(line).as_deref() {
            Some([xv, zv]) => {
                x.push(*xv);
                z.push(*zv);
            }
            _ => {
                return Err(failed(format!(
                    "{}: line {} is not two numbers x_mm,z_um: {line:?}",
                    path.display(),
                    n + 1
                )))
            }
        }
    }
    let (first, last) = match (x.first(), x.last()) {
        (Some(f), Some(l)) if x.len() >= 2 => (*f, *l),
        _ => return Err(failed(format!("{}: fewer than 2 points", path.display()))),
    };
    let pitch = (last - first) / (x.len() - 1) as f64;
    if let Some(i) = x
        .windows(2)
        .position(|w| matches!(w, [a, b] if ((b - a) - pitch).abs() > 0.01 * pitch.abs()))
    {
        return Err(failed(format!(
            "{}: x is not uniformly spaced at row {} (pitch {pitch} mm); resample the profile first",
            path.display(),
            i + 2
        )));
    }
    Ok((pitch, z))
}

/// A grid CSV as read: the readable rows' heights, and the rows left out.
#[derive(Debug, PartialEq)]
struct GridCsv {
    /// Heights in µm of the rows kept, row-major.
    heights_um: Vec<f64>,
    /// Points per row.
    cols: usize,
    /// 0-based row of each kept row in the file (its y position is row × pitch y).
    rows: Vec<usize>,
    /// Each row left out: its 1-based line in the file and why.
    left_out: Vec<(usize, String)>,
}

/// At most this many left-out rows are named one by one in the warning.
const LEFT_OUT_NAMED: usize = 10;

impl GridCsv {
    /// The warning naming the rows left out, or `None` when every row was read.
    fn warning(&self) -> Option<String> {
        if self.left_out.is_empty() {
            return None;
        }
        let named: Vec<String> = self
            .left_out
            .iter()
            .take(LEFT_OUT_NAMED)
            .map(|(line, why)| format!("line {line} {why}"))
            .collect();
        let more = self.left_out.len().saturating_sub(LEFT_OUT_NAMED);
        Some(format!(
            "{} of {} rows of the grid CSV cannot be used and were left out (nothing is filled in; the other rows keep their y): {}{}",
            self.left_out.len(),
            self.left_out.len() + self.rows.len(),
            named.join("; "),
            if more > 0 {
                format!("; and {more} more")
            } else {
                String::new()
            }
        ))
    }
}

/// A grid CSV row as read, beside its 1-based line: where its values start in the heights
/// read and how many there are, or why it cannot be used.
type RowRead = Result<(usize, usize), String>;

/// Reads a grid CSV: one row of heights per line, `,` separated; a non-numeric first line
/// is taken as a header and blank lines are skipped. Every other line is a row at the next
/// y. A row that holds a value that is not a number, a non-finite height (NaN, as some
/// software writes for a point not measured) or a number of points unlike the other rows'
/// is left out and named, as an X3P file's lines with invalid points are: one damaged line
/// does not take down the rest. The rows' length is the one most rows have (the first such
/// on a tie). An error only when no row can be used.
fn read_grid(text: &str) -> Result<GridCsv, String> {
    let mut heights_um = Vec::new();
    let mut read: Vec<(usize, RowRead)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let start = heights_um.len();
        if crate::numbers::parse_csv_line(line.as_bytes(), &mut heights_um).is_none() {
            heights_um.truncate(start);
            match parse_fields(line) {
                Ok(values) => heights_um.extend(values),
                Err(_) if n == 0 => continue, // a header
                Err((k, f)) => {
                    let why = format!("(column {}: {f:?} is not a number)", k + 1);
                    read.push((n + 1, Err(why)));
                    continue;
                }
            }
        }
        let count = heights_um.len() - start;
        let values = &heights_um[start..];
        let not_finite = values.iter().filter(|v| !v.is_finite()).count();
        // A height beyond any surface (a value in other units, a damaged digit) leaves its row
        // out as a NaN does, instead of ending the characterisation of every row.
        let beyond = values
            .iter()
            .filter(|v| v.is_finite() && v.abs() > MAX_HEIGHT_UM)
            .count();
        if not_finite > 0 {
            heights_um.truncate(start);
            read.push((
                n + 1,
                Err(format!(
                    "({not_finite} of its {count} heights are not finite: NaN or infinite, not measured)"
                )),
            ));
        } else if beyond > 0 {
            heights_um.truncate(start);
            read.push((
                n + 1,
                Err(format!(
                    "({beyond} of its {count} heights are beyond ±{MAX_HEIGHT_UM:e} µm, no surface height: check the units, heights in µm)"
                )),
            ));
        } else {
            read.push((n + 1, Ok((start, count))));
        }
    }
    // The rows' length: the most common, the first such on a tie. Counted in a map, so a
    // file of many different lengths costs no more than one of few.
    let mut counts: std::collections::HashMap<usize, (usize, usize)> = Default::default();
    for (at, (_, r)) in read.iter().enumerate() {
        if let Ok((_, c)) = r {
            counts.entry(*c).or_insert((0, at)).0 += 1;
        }
    }
    let cols = counts
        .iter()
        .max_by_key(|(_, &(times, first))| (times, std::cmp::Reverse(first)))
        .map(|(&len, _)| len);
    let Some(cols) = cols else {
        // No row was read, so each is an error.
        return Err(
            match read
                .iter()
                .find_map(|(l, r)| r.as_ref().err().map(|w| (l, w)))
            {
                None => "no lines".to_string(),
                Some((line, why)) => format!("no row can be used; the first, line {line} {why}"),
            },
        );
    };
    // Compact the kept rows to the front, in file order.
    let mut grid = GridCsv {
        heights_um: Vec::new(),
        cols,
        rows: Vec::new(),
        left_out: Vec::new(),
    };
    let mut kept = 0usize;
    for (row, (line, r)) in read.into_iter().enumerate() {
        match r {
            Ok((start, count)) if count == cols => {
                heights_um.copy_within(start..start + cols, kept);
                kept += cols;
                grid.rows.push(row);
            }
            Ok((_, count)) => grid.left_out.push((
                line,
                format!("(it has {count} values where the rows have {cols})"),
            )),
            Err(why) => grid.left_out.push((line, why)),
        }
    }
    heights_um.truncate(kept);
    grid.heights_um = heights_um;
    Ok(grid)
}

fn report_error(e: ReportError) -> CliError {
    let exit = match e {
        ReportError::Io { .. } => Exit::Io,
        ReportError::Store(ref s)
            if matches!(s, crate::scan::store_error::StoreError::Io { .. }) =>
        {
            Exit::Io
        }
        _ => Exit::Failed,
    };
    CliError::new(exit, e.to_string())
}

/// Prints the warnings and the summary, and maps a partial characterisation to exit 3.
fn finish(o: &ScanOutputs) -> Result<(), CliError> {
    print_outputs(o);
    say!("{}", o.verdict_line());
    if o.complete() {
        Ok(())
    } else {
        let failed: Vec<String> = o
            .report
            .characterisation
            .failed_sections
            .iter()
            .map(|f| f.section.clone())
            .collect();
        Err(CliError::new(
            Exit::Partial,
            format!(
                "the characterisation is partial: {} could not be made (the reasons are in the warnings above and in {}); every other output is written",
                failed.join(", "),
                o.report_json.display()
            ),
        ))
    }
}

fn print_outputs(o: &ScanOutputs) {
    for w in &o.warnings {
        tell!("surfscan: warning: {w}");
    }
    say!(
        "{}: {} lines characterised in {:.2} s",
        o.report_json.display(),
        o.lines_used.len(),
        o.elapsed_s
    );
}

/// The characterisation settings a scan directory's plan froze (its `[analysis]` when it
/// started), else the defaults: for a journal of an older version, which froze none, or one
/// that cannot be read (characterising the scan names that problem).
fn scan_analysis_defaults(dir: &Path) -> ScanAnalysisOptions {
    let frozen = crate::report::scan_dir::read_scan_journal(dir)
        .ok()
        .and_then(|s| s.start.plan.analysis);
    match frozen {
        Some(a) => ScanAnalysisOptions::default().with_frozen(&a),
        None => ScanAnalysisOptions::default(),
    }
}

/// Refuses a `--lc`, `--curves` or `--levels` outside the range the same setting has in a
/// station's `[analysis]` (λc 0 or NaN, one level, a hundred million levels that would run for
/// minutes) as a usage error, before anything is read.
fn check_analysis_flags(args: &Args) -> Result<(), CliError> {
    use crate::config::{Num, NumericKey};
    let flags = [
        ("--lc", "analysis.lambda-c-mm", args.lc.map(Num::Real)),
        (
            "--curves",
            "analysis.curves",
            args.curves.map(|v| Num::Int(v as i128)),
        ),
        (
            "--levels",
            "analysis.levels",
            args.levels.map(|v| Num::Int(v as i128)),
        ),
    ];
    for (flag, key, value) in flags {
        if let (Some(v), Some(k)) = (value, NumericKey::named(key)) {
            k.check_flag(flag, v)
                .map_err(|m| CliError::new(Exit::Usage, m))?;
        }
    }
    if args.sampling_lengths == Some(0) {
        return Err(CliError::new(
            Exit::Usage,
            "--sampling-lengths 0: give at least 1 sampling length (ISO 4288's default is 5)",
        ));
    }
    Ok(())
}

/// Runs `surfscan analyze`.
pub fn run(args: Args) -> Result<(), CliError> {
    if args.degree_u == Some(0) || args.degree_v == Some(0) {
        return Err(CliError::new(
            Exit::Usage,
            "--degree-u and --degree-v must be at least 1 (the paper uses 5)",
        ));
    }
    check_analysis_flags(&args)?;
    if args.input.is_dir() {
        if args.sampling_lengths.is_some() {
            return Err(CliError::new(
                Exit::Usage,
                "--sampling-lengths is for CSV and X3P inputs; a scan's lines are evaluated with the N the instrument recorded",
            ));
        }
        if args.pitch_x.is_some() || args.pitch_y.is_some() {
            return Err(CliError::new(
                Exit::Usage,
                "--pitch-x/--pitch-y are for a grid CSV; a scan directory's pitch and y come from its line metadata",
            ));
        }
        // The method's default control rows depend on the line count, known once read.
        let lines = crate::report::scan_dir::complete_line_count(&args.input);
        let frozen = scan_analysis_defaults(&args.input);
        let options = ScanAnalysisOptions {
            curves: args.curves.unwrap_or(frozen.curves),
            levels: args.levels.unwrap_or(frozen.levels),
            lambda_c_mm: args.lc.or(frozen.lambda_c_mm),
            no_filter: args.no_filter || frozen.no_filter,
            overlay_line: args.overlay_line,
            degree_u: args.degree_u,
            degree_v: args.degree_v,
            out_dir: args.out.clone(),
            spikes: args.model.spikes_or(frozen.spikes)?,
            exclude_spikes: args
                .outliers
                .map_or(frozen.exclude_spikes, |o| o == OutliersArg::Exclude),
            holdout_threshold: args.model.holdout_threshold_or(frozen.holdout_threshold)?,
            v_method: args.model.v_method(
                lines,
                args.degree_v
                    .unwrap_or(crate::fit::FitOptions::default().degree_v),
            )?,
            replace_spikes: args.model.replace(),
        };
        let outputs = characterise_scan(&args.input, &options).map_err(report_error)?;
        return finish(&outputs);
    }
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from("."));
    let bytes = std::fs::read(&args.input).map_err(|e| {
        CliError::new(
            Exit::Io,
            format!("cannot read {}: {e}", args.input.display()),
        )
    })?;
    if super::fit::sniff_input(&args.input, &bytes) == super::fit::InputKind::X3p {
        return run_x3p(&args, &bytes, &out);
    }
    let text = super::fit::csv_text(
        &args.input,
        bytes,
        "analyze reads a scan directory, an X3P file or a CSV",
    )?;
    let lc = args.lc.unwrap_or(DEFAULT_LC_MM);
    let options = Options {
        lambda_c_mm: lc,
        apply_lambda_c: !args.no_filter,
        lambda_s_um: None,
        sampling_lengths: None,
        central_sections: args.sampling_lengths,
    };
    let lambda_c_source = match args.lc {
        Some(v) => format!("given ({v} mm)"),
        None => format!("default {DEFAULT_LC_MM} mm (set --lc to choose)"),
    };
    let filter_reason = if args.no_filter {
        "no λc filter: asked for (--no-filter)".to_string()
    } else {
        "λc filter applied: a CSV is taken as a primary profile unless --no-filter".to_string()
    };
    let is_profile = text
        .lines()
        .next()
        .is_some_and(|h| h.trim_start().starts_with("x_mm"));
    if is_profile {
        let (pitch, z) = read_profile(&args.input, &text)?;
        let warnings: Vec<String> = implausible_length(z.len(), pitch).into_iter().collect();
        let input = args.input.display().to_string();
        return characterise_profile(&args, input, z, pitch, &options, warnings, &out);
    }
    let (Some(px), Some(py)) = (args.pitch_x, args.pitch_y) else {
        return Err(CliError::new(
            Exit::Usage,
            "a grid CSV needs --pitch-x MM and --pitch-y MM (a profile CSV starts with the header x_mm,z_um; a scan is a directory)",
        ));
    };
    let csv = read_grid(&text).map_err(|e| {
        failed(format!(
            "{}: {e}; a grid CSV holds one row of heights in µm per line, ',' separated",
            args.input.display()
        ))
    })?;
    let mut warnings: Vec<String> = csv.warning().into_iter().collect();
    warnings.extend(implausible_length(csv.cols, px));
    let rows = csv.rows.len();
    let grid = LineGrid {
        y_mm: csv.rows.iter().map(|&j| j as f64 * py).collect(),
        index: csv.rows.iter().map(|&j| j as u32).collect(),
        heights_um: csv.heights_um,
        cols: csv.cols,
        pitch_x_mm: px,
        y_readback_mm: vec![None; rows],
        instrument: None,
        standard: vec![None; rows],
    };
    let ctx = ReportContext {
        input: args.input.display().to_string(),
        kind: "grid",
        line_options: options,
        lambda_c_source,
        filter_reason,
        traceability: None,
        scan: None,
        fit: None,
        options: ScanAnalysisOptions::default(),
        warnings,
    };
    let outputs = fit_and_characterise(&grid, ctx, &args, &out)?;
    finish(&outputs)
}

/// `analyze FILE.x3p`: the grid read with its pitches; lines with invalid points left out.
fn run_x3p(args: &Args, bytes: &[u8], out: &Path) -> Result<(), CliError> {
    if args.pitch_x.is_some() || args.pitch_y.is_some() {
        return Err(CliError::new(
            Exit::Usage,
            "--pitch-x/--pitch-y are for a grid CSV; an X3P file stores its own pitches",
        ));
    }
    let x = crate::metrology::x3p::read_x3p(bytes)
        .map_err(|e| failed(format!("{}: {e}", args.input.display())))?;
    let lc = args.lc.unwrap_or(DEFAULT_LC_MM);
    let options = Options {
        lambda_c_mm: lc,
        apply_lambda_c: !args.no_filter,
        lambda_s_um: None,
        sampling_lengths: None,
        central_sections: args.sampling_lengths,
    };
    let m = &x.meta;
    let source = [
        m.manufacturer.as_str(),
        m.model.as_str(),
        if m.serial.is_empty() { "" } else { "serial" },
        m.serial.as_str(),
    ]
    .iter()
    .filter(|s| !s.is_empty())
    .copied()
    .collect::<Vec<_>>()
    .join(" ");
    let input = format!(
        "{} (X3P {} of {} × {} points{}{})",
        args.input.display(),
        x.feature_type,
        x.rows,
        x.cols,
        if source.is_empty() {
            String::new()
        } else {
            format!(", {source}")
        },
        if m.date.is_empty() {
            String::new()
        } else {
            format!(", measured {}", m.date)
        }
    );
    let mut warnings = Vec::new();
    let complete: Vec<usize> = (0..x.rows)
        .filter(|&r| {
            x.heights_um[r * x.cols..(r + 1) * x.cols]
                .iter()
                .all(|v| v.is_finite())
        })
        .collect();
    if complete.len() < x.rows {
        let left: Vec<String> = (0..x.rows)
            .filter(|r| !complete.contains(r))
            .map(|r| (r + 1).to_string())
            .collect();
        warnings.push(format!(
            "{} of {} points are marked invalid (not measured); lines {} hold them and were left out (nothing is filled in)",
            x.invalid_points,
            x.rows * x.cols,
            left.join(", ")
        ));
    }
    if complete.is_empty() {
        return Err(failed(format!(
            "{}: every line holds invalid (not measured) points ({} of {}); fill or crop them in the software that wrote the file, then analyse again",
            args.input.display(),
            x.invalid_points,
            x.rows * x.cols
        )));
    }
    let lambda_c_source = match args.lc {
        Some(v) => format!("given ({v} mm)"),
        None => format!("default {DEFAULT_LC_MM} mm (set --lc to choose)"),
    };
    let filter_reason = if args.no_filter {
        "no λc filter: asked for (--no-filter)".to_string()
    } else {
        "λc filter applied: an X3P file is taken as a primary surface unless --no-filter"
            .to_string()
    };
    if x.rows == 1 {
        let z = x.heights_um.clone();
        return characterise_profile(args, input, z, x.pitch_x_mm, &options, warnings, out);
    }
    let heights_um: Vec<f64> = complete
        .iter()
        .flat_map(|&r| x.heights_um[r * x.cols..(r + 1) * x.cols].iter().copied())
        .collect();
    let n = complete.len();
    let grid = LineGrid {
        heights_um,
        cols: x.cols,
        pitch_x_mm: x.pitch_x_mm,
        y_mm: complete.iter().map(|&r| r as f64 * x.pitch_y_mm).collect(),
        index: complete.iter().map(|&r| r as u32).collect(),
        y_readback_mm: vec![None; n],
        instrument: None,
        standard: vec![None; n],
    };
    let ctx = ReportContext {
        input,
        kind: "x3p",
        line_options: options,
        lambda_c_source,
        filter_reason,
        traceability: None,
        scan: None,
        fit: None,
        options: ScanAnalysisOptions::default(),
        warnings,
    };
    let outputs = fit_and_characterise(&grid, ctx, args, out)?;
    finish(&outputs)
}

/// Fits `grid` once the way the arguments ask (`--degree-u/--degree-v`, default the paper's
/// 5/5; `--v-method`; spikes replaced only with `--replace-spikes`) and characterises it with
/// that surface (the model sections and the hold-out refits are made the same way).
fn fit_and_characterise(
    grid: &LineGrid,
    mut ctx: ReportContext,
    args: &Args,
    out: &Path,
) -> Result<ScanOutputs, CliError> {
    let defaults = ScanAnalysisOptions::default();
    let analysis = ScanAnalysisOptions {
        curves: args.curves.unwrap_or(defaults.curves),
        levels: args.levels.unwrap_or(defaults.levels),
        overlay_line: args.overlay_line,
        degree_u: args.degree_u,
        degree_v: args.degree_v,
        spikes: args.model.spikes()?,
        exclude_spikes: args.outliers == Some(OutliersArg::Exclude),
        holdout_threshold: args.model.holdout_threshold()?,
        v_method: args.model.v_method(
            grid.rows(),
            args.degree_v
                .unwrap_or(crate::fit::FitOptions::default().degree_v),
        )?,
        replace_spikes: args.model.replace(),
        ..ScanAnalysisOptions::default()
    };
    let mut recipe = crate::report::scan_dir::scan_recipe(&analysis, None, &[]);
    recipe.lambda_c_mm = ctx
        .line_options
        .apply_lambda_c
        .then_some(ctx.line_options.lambda_c_mm);
    let (fitted, summary, fit_s) = fit_for_report(grid, &recipe);
    ctx.fit = summary;
    ctx.options = analysis;
    let model = Model {
        recipe,
        fit: fitted.as_ref().map(|m| &m.fit),
        replaced: fitted.as_ref().map_or(&[][..], |m| &m.replaced[..]),
        fit_s,
    };
    characterise(grid, model, ctx, out).map_err(report_error)
}

/// What `analyze` of a profile CSV says it found, as the instrument's display would show it:
/// `profile of 2000 points (1 mm), λc 0.8 mm filter applied: Ra 0.2345 µm, Rq …, Rz …`.
fn profile_summary(points: usize, pitch_mm: f64, p: &RoughnessParams, options: &Options) -> String {
    use crate::numfmt::{fmt, Quantity};
    let filter = if options.apply_lambda_c {
        format!("λc {} mm filter applied", options.lambda_c_mm)
    } else {
        "no λc filter".to_string()
    };
    format!(
        "profile of {points} points ({} mm), {filter}: Ra {} µm, Rq {} µm, Rz {} µm",
        fmt(points as f64 * pitch_mm, Quantity::LengthMm),
        fmt(p.ra_um, Quantity::HeightUm),
        fmt(p.rq_um, Quantity::HeightUm),
        fmt(p.rz_um, Quantity::HeightUm)
    )
}

fn write_outputs(out: &Path, report: &Report) -> Result<(), CliError> {
    let io = |p: &Path, e: std::io::Error| {
        let hint = crate::atomic::write_hint(p, &e);
        CliError::new(
            Exit::Io,
            format!("cannot write {}: {e}; {hint}", p.display()),
        )
    };
    std::fs::create_dir_all(out).map_err(|e| io(out, e))?;
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| failed(format!("cannot encode the report: {e}")))?;
    let path = out.join("report.json");
    crate::atomic::write_atomically(&path, |w| std::io::Write::write_all(w, json.as_bytes()))
        .map_err(|e| io(&path, e))?;
    // As a scan's summary.csv (without the instrument's columns): 1-based line, values with
    // the digits of their quantity.
    use crate::report::summary::{line_cells, more_cells, LINE_HEADER, MORE_HEADER};
    let mut csv = format!("{LINE_HEADER},{MORE_HEADER}\n");
    for l in &report.lines {
        let mut row = line_cells(l.index, l.y_mm, &l.params);
        row.extend(more_cells(&l.params));
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    let path = out.join("summary.csv");
    crate::atomic::write_atomically(&path, |w| std::io::Write::write_all(w, csv.as_bytes()))
        .map_err(|e| io(&path, e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_csv_is_read_with_its_header_and_blank_lines_skipped() {
        let g = read_grid("a,b,c\n1,2,3\n\n4.5,-6e-1,+7\n\n").unwrap();
        assert_eq!(g.heights_um, vec![1.0, 2.0, 3.0, 4.5, -0.6, 7.0]);
        assert_eq!((g.cols, g.rows.clone()), (3, vec![0, 1]));
        assert!(g.left_out.is_empty());
        assert_eq!(g.warning(), None);
    }

    #[test]
    fn damaged_grid_rows_are_left_out_and_named_and_the_others_keep_their_y() {
        let text = "1,2,3,4\n1,2,x,4\n1,2,3\n1,NaN,3,inf\n5,6,7,8\n1,2e9,3,-4e12\n\n9,10,11,12\n";
        let g = read_grid(text).unwrap();
        assert_eq!(g.cols, 4);
        assert_eq!(g.rows, vec![0, 4, 6], "rows keep their place in the file");
        assert_eq!(
            g.heights_um,
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0]
        );
        let lines: Vec<usize> = g.left_out.iter().map(|(l, _)| *l).collect();
        assert_eq!(lines, vec![2, 3, 4, 6]);
        let w = g.warning().unwrap();
        assert!(w.starts_with("4 of 7 rows of the grid CSV"), "{w}");
        assert!(
            w.contains("line 6 (2 of its 4 heights are beyond ±1e9 µm"),
            "{w}"
        );
        assert!(
            w.contains("line 2 (column 3: \"x\" is not a number)"),
            "{w}"
        );
        assert!(
            w.contains("line 3 (it has 3 values where the rows have 4)"),
            "{w}"
        );
        assert!(
            w.contains("line 4 (2 of its 4 heights are not finite"),
            "{w}"
        );
    }

    #[test]
    fn the_rows_length_is_the_one_most_rows_have() {
        // A short first row does not make every full row wrong.
        let g = read_grid("1,2\n1,2,3\n4,5,6\n7,8,9\n").unwrap();
        assert_eq!((g.cols, g.rows.clone()), (3, vec![1, 2, 3]));
        assert_eq!(g.left_out.len(), 1);
        assert!(g.left_out[0]
            .1
            .contains("has 2 values where the rows have 3"));
        // On a tie, the first length.
        let g = read_grid("1,2\n1,2,3\n").unwrap();
        assert_eq!((g.cols, g.rows.clone()), (2, vec![0]));
    }

    #[test]
    fn many_rows_left_out_are_counted_past_the_first_ten() {
        let mut text = String::from("1,2\n");
        for _ in 0..12 {
            text.push_str("1,?\n");
        }
        let w = read_grid(&text).unwrap().warning().unwrap();
        assert!(w.starts_with("12 of 13 rows"), "{w}");
        assert_eq!(w.matches("is not a number").count(), 10, "{w}");
        assert!(w.ends_with("; and 2 more"), "{w}");
    }

    /// Random grids of good and damaged rows against a plain reading of the same lines: the
    /// rows kept, their place in the file, their heights and the rows left out.
    #[test]
    fn random_damaged_grids_keep_exactly_the_usable_rows() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: u64| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) % n
        };
        for case in 0..2000 {
            let mut lines: Vec<String> = Vec::new();
            if next(4) == 0 {
                lines.push("z_um,z_um,z_um".into());
            }
            for _ in 0..next(9) {
                let len = 3 + next(3) as usize;
                let mut fields: Vec<String> = (0..len)
                    .map(|_| format!("{}", next(2001) as f64 / 100.0 - 10.0))
                    .collect();
                match next(8) {
                    0 => fields[next(len as u64) as usize] = "1.2.3".into(),
                    1 => fields[next(len as u64) as usize] = "NaN".into(),
                    2 => fields = vec![String::new()],
                    3 => fields[0] = format!(" {} ", fields[0]),
                    _ => {}
                }
                lines.push(fields.join(","));
            }
            let text = lines.join("\n");
            // The plain reading: each non-blank line after a header is a row.
            let mut rows: Vec<Option<Vec<f64>>> = Vec::new();
            for (n, l) in text.lines().enumerate() {
                if l.trim().is_empty() {
                    continue;
                }
                let v: Result<Vec<f64>, _> = l.split(',').map(|f| f.trim().parse()).collect();
                match v {
                    Err(_) if n == 0 => {}
                    Err(_) => rows.push(None),
                    Ok(v) if v.iter().all(|x: &f64| x.is_finite()) => rows.push(Some(v)),
                    Ok(_) => rows.push(None),
                }
            }
            let lens: Vec<usize> = rows.iter().flatten().map(Vec::len).collect();
            let cols = lens.iter().copied().max_by_key(|&c| {
                let first = lens.iter().position(|&x| x == c).unwrap();
                (lens.iter().filter(|&&x| x == c).count(), usize::MAX - first)
            });
            let got = read_grid(&text);
            let Some(cols) = cols else {
                assert!(got.is_err(), "case {case}: {text:?}");
                continue;
            };
            let g = got.unwrap_or_else(|e| panic!("case {case}: {e}: {text:?}"));
            let kept: Vec<usize> = (0..rows.len())
                .filter(|&r| rows[r].as_ref().is_some_and(|v| v.len() == cols))
                .collect();
            assert_eq!((g.cols, &g.rows), (cols, &kept), "case {case}: {text:?}");
            let heights: Vec<f64> = kept
                .iter()
                .flat_map(|&r| rows[r].clone().unwrap())
                .collect();
            assert_eq!(g.heights_um, heights, "case {case}: {text:?}");
            assert_eq!(g.left_out.len(), rows.len() - kept.len(), "case {case}");
        }
    }

    #[test]
    fn a_grid_csv_with_no_usable_row_is_an_error_naming_the_first() {
        // The first line is taken as a header; every row after it is damaged.
        let e = read_grid("1,x\n2,y\n3,NaN\n").unwrap_err();
        assert_eq!(
            e,
            "no row can be used; the first, line 2 (column 2: \"y\" is not a number)"
        );
        assert_eq!(read_grid("x_um,y_um\n\n").unwrap_err(), "no lines");
        assert_eq!(read_grid("").unwrap_err(), "no lines");
    }
    use clap::CommandFactory;

    /// The help text of option `id` of subcommand `sub`.
    fn help(sub: &str, id: &str) -> String {
        let cli = crate::cli::Cli::command();
        let sub = cli.find_subcommand(sub).expect("subcommand");
        let text = sub
            .get_arguments()
            .find(|a| a.get_id() == id)
            .and_then(|a| a.get_help())
            .map(|h| h.to_string());
        text.unwrap_or_else(|| panic!("no help for {id}"))
    }

    /// Whether `rest` continues the number before it ("0" after "else 31", ".5" after
    /// "else 0"): "else 31" must not pass for "else 310".
    fn continues_a_number(rest: &str) -> bool {
        let mut c = rest.chars();
        match c.next() {
            Some(d) if d.is_ascii_digit() => true,
            Some('.') => c.next().is_some_and(|d| d.is_ascii_digit()),
            _ => false,
        }
    }

    /// The defaults the help text states are written out as text; each is checked against the
    /// value the code falls back to, so changing one without the other fails here.
    #[test]
    fn the_help_states_the_defaults_the_code_uses() {
        let d = ScanAnalysisOptions::default();
        let paper = crate::fit::FitOptions::default();
        let mut checks = vec![
            ("analyze", "curves", format!("else {}", d.curves)),
            ("analyze", "levels", format!("else {}", d.levels)),
            ("analyze", "lc", format!("(else {DEFAULT_LC_MM} mm)")),
            ("analyze", "lc", format!("for a CSV {DEFAULT_LC_MM} mm")),
        ];
        // The options both commands have, with the same defaults.
        for sub in ["analyze", "fit"] {
            checks.extend([
                (
                    sub,
                    "degree_u",
                    format!("else {} (the paper)", paper.degree_u),
                ),
                (
                    sub,
                    "degree_v",
                    format!("else {} (the paper)", paper.degree_v),
                ),
                (
                    sub,
                    "spike_threshold_sigma",
                    format!("else {}", d.spikes.threshold_sigma),
                ),
                (
                    sub,
                    "spike_max_points",
                    format!("else {}", d.spikes.max_points),
                ),
                (
                    sub,
                    "holdout_threshold",
                    format!("else {}", d.holdout_threshold),
                ),
            ]);
        }
        for (sub, id, want) in checks {
            let h = help(sub, id);
            let whole = h
                .match_indices(&want)
                .any(|(at, _)| !continues_a_number(&h[at + want.len()..]));
            assert!(whole, "{sub} --{id}: {h:?} lacks {want:?}");
        }
    }
}
