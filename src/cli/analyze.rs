//! `surfscan analyze`: surface characterisation of a scan directory (as the scan daemon writes
//! it), a grid CSV, an X3P file or a profile CSV, read by the one reader ([`crate::input`]:
//! its findings and the lines it left out are the report's first warnings, and a report made
//! from fewer lines than the input holds is partial, exit 3). Every input goes through
//! [`crate::report`] (the daemon's entry point [`crate::report::characterise_scan`] for
//! scans): `report.json`, `report.html`, `summary.csv`, `rk/NNNN.svg` (each line's assessed
//! profile and Rk construction), `measured.x3p`, `model.x3p` (ISO 25178-72), `bac.png|svg`,
//! `heightmap.png|svg`, `overlay.png|svg` (measured vs model of one line) and
//! `psd|acf|surface3d.png|svg` (the areal PSD, ACF and 3D view). A profile (a profile CSV, an
//! X3P file of one line) is a grid of one line: what needs two lines or more is named as not
//! applying to it, and its summary line gives its parameters as the instrument's display does.
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
//! `--recipe` judges a scan directory or a grid against a recipe's specification (a scan
//! is otherwise judged by the recipe its job froze, a grid not at all).
//!
//! The summary printed names the verdict on the model between lines and, for a judged scan
//! or grid, the verdict against the specification with each limit's. Exit status: 0 done,
//! 3 done but partial (lines left out, or part of the characterisation could not be made:
//! report.json's `characterisation` says which and why), 4 (with `--recipe`) the part does
//! not conform, 1 the input cannot be characterised at all, 2 usage, 74 I/O, 78 a bad
//! configuration or recipe.
//!
//! Layer 5 (composition): reads files, calls [`crate::report`] and [`crate::metrology`].

use super::input_args::InputArgs;
use super::model_args::ModelArgs;
use super::{CliError, Exit};
use crate::input::{GridInput, Source};
use crate::jobs::recipe::Recipe;
use crate::metrology::params::Options;
use crate::metrology::sj_material_ratio::MaterialRatioReading;
use crate::report::header::LabHeader;
use crate::report::scan_dir::fit_for_report;
use crate::report::{
    characterise, characterise_scan, Model, ReportContext, ReportError, ScanAnalysisOptions,
    ScanOutputs,
};
use crate::specification::InstrumentUncertainty;
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
    /// The λs short-wave filter in µm (ISO 3274's 2.5, 8 or 25 µm) applied to a CSV or X3P
    /// file's profiles before λc (default none: a scan's lines are as the instrument filtered
    /// them).
    #[arg(long, value_name = "UM")]
    pub ls: Option<f64>,
    /// Form-only evaluation of a CSV or X3P file: remove this least-squares form (`line`, or
    /// `poly2` … `poly6`) and no λc filter; P parameters over the whole length.
    #[arg(long, value_name = "FORM", value_parser = crate::metrology::form::Form::parse)]
    pub form: Option<crate::metrology::form::Form>,
    /// A station configuration whose `[report]` table (laboratory, address, logo, paper,
    /// signatures) heads the report. Default: for a scan the table its journal recorded; for
    /// a file none.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Judge the lines against this recipe's `[specification] limits` instead of those a
    /// scan's job froze: a recipe file, or with `--config` a recipe name in its `[jobs]
    /// recipes` directory (checked against that station as `check-config` checks it). Only
    /// the limits are taken; a limit asking for another band or evaluation length than the
    /// lines were evaluated with is named and not decidable. For a grid the calibration
    /// uncertainty of `--config`'s `[traceability]` applies. Exit 4 when the part does not
    /// conform.
    #[arg(long, value_name = "FILE")]
    pub recipe: Option<PathBuf>,
    /// Evaluate the central N sampling lengths (λc each) of every line, leaving the rest at
    /// each end out as the filter's run-up and run-out, as an instrument traces N·λc plus λc
    /// (CSV and X3P inputs; a scan's lines carry the instrument's N). Default: the whole
    /// line, N = its length / λc.
    #[arg(long, value_name = "N")]
    pub sampling_lengths: Option<u32>,
    /// The pitches of a grid CSV and the unit of a CSV's heights.
    #[command(flatten)]
    pub read: InputArgs,
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
    /// Also write each line's Rk figure as a PNG (`rk/NNNN.png`) beside its SVG, as
    /// `[report] line-png = true` does.
    #[arg(long)]
    pub line_png: bool,
    /// Add the contact of the surface with a flat (rigid or elastic) to the report (`contact` in
    /// report.json, a table in report.html, contact.json and its plots): the load–area curve
    /// of the measured grid. A scan whose plan froze an enabled `[contact]` has it without.
    #[arg(long)]
    pub contact: bool,
    /// The contact's nominal pressures, MPa, comma-separated (default 1,2,5,10,20,50,100).
    #[arg(
        long,
        value_name = "MPA,…",
        value_delimiter = ',',
        requires = "contact"
    )]
    pub contact_pressures: Vec<f64>,
    /// Young's modulus of the measured body for the contact, GPa (default 210, steel).
    #[arg(long, value_name = "GPA", requires = "contact")]
    pub contact_young: Option<f64>,
    /// Poisson's ratio of the measured body for the contact (default 0.30, steel).
    #[arg(long, value_name = "NU", requires = "contact")]
    pub contact_poisson: Option<f64>,
    /// Young's modulus of the counter-body, GPa (default: a rigid flat); the bodies act through
    /// their composite modulus.
    #[arg(long, value_name = "GPA", requires = "contact")]
    pub contact_young2: Option<f64>,
    /// Poisson's ratio of the counter-body (default 0.30; needs --contact-young2).
    #[arg(long, value_name = "NU", requires = "contact_young2")]
    pub contact_poisson2: Option<f64>,
    /// Hardness of the measured body, GPa: the contact is perfectly plastic at it (default:
    /// elastic).
    #[arg(long, value_name = "GPA", requires = "contact")]
    pub contact_hardness: Option<f64>,
    /// Also the contact of the model sampled at this y spacing between the lines, mm, with
    /// the verdict between lines beside it.
    #[arg(long, value_name = "MM", requires = "contact")]
    pub contact_model_pitch_y: Option<f64>,
    /// Spikes: flag (named, the data as measured) or exclude (also left out of the per-line
    /// and measured-grid parameters, bridged by the straight line between neighbours).
    /// Default: a scan's frozen `[analysis]`, else flag.
    #[arg(long, value_enum)]
    pub outliers: Option<OutliersArg>,
    /// The reading of the material-ratio family (Rmr(c), Rmr, the Rk family) a verdict and
    /// the summary line use: iso (ISO 13565-2 on the continuous profile) or instrument (the
    /// SJ series' counted 100-level curve, as its display shows). Both are reported. Default:
    /// a scan's frozen `[analysis] material-ratio`, else iso.
    #[arg(long, value_name = "READING", value_parser = MaterialRatioReading::parse)]
    pub material_ratio: Option<MaterialRatioReading>,
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

/// The contact section's options from `--contact…`, every value checked (exit 2 naming the
/// value); `None` without `--contact`.
fn contact_options(
    args: &Args,
) -> Result<Option<crate::report::sections::contact::ContactSectionOptions>, CliError> {
    if !args.contact {
        return Ok(None);
    }
    if let Some(s) = args.contact_model_pitch_y {
        if !(s.is_finite() && s > 0.0) {
            return Err(CliError::new(
                Exit::Usage,
                format!("--contact-model-pitch-y {s}: the model's y spacing must be a positive length in mm"),
            ));
        }
    }
    let d = crate::contact::ContactSettings::default();
    let settings = crate::contact::ContactSettings {
        enabled: true,
        pressures_mpa: if args.contact_pressures.is_empty() {
            d.pressures_mpa
        } else {
            args.contact_pressures.clone()
        },
        young_gpa: args.contact_young.unwrap_or(d.young_gpa),
        poisson: args.contact_poisson.unwrap_or(d.poisson),
        young2_gpa: args.contact_young2,
        poisson2: args.contact_poisson2,
        hardness_gpa: args.contact_hardness,
        model_pitch_y_mm: args.contact_model_pitch_y,
    };
    settings
        .check()
        .map_err(|(_, message)| CliError::new(Exit::Usage, message))?;
    Ok(Some(
        crate::report::sections::contact::ContactSectionOptions::of(&settings),
    ))
}

fn report_error(e: ReportError) -> CliError {
    match e {
        ReportError::Input(e) => super::input_args::input_error(e),
        ReportError::Io { .. } => CliError::new(Exit::Io, e.to_string()),
        e => CliError::new(Exit::Failed, e.to_string()),
    }
}

/// Prints the warnings and the summary (a profile's `profile` line; else the verdict against
/// the specification first, with each limit's, and the verdict between lines), and maps a
/// part that does not conform to exit 4 when `judged` (`--recipe`), else a partial
/// characterisation to exit 3.
fn finish(o: &ScanOutputs, judged: bool, profile: Option<String>) -> Result<(), CliError> {
    for w in &o.warnings {
        tell!("surfscan: warning: {w}");
    }
    let c = &o.report.characterisation;
    let summary = profile
        .unwrap_or_else(|| format!("{} characterised in {:.2} s", c.lines_used(), o.elapsed_s));
    say!("{}: {summary}", o.files.report_json.display());
    if let Some(spec) = &o.report.specification {
        say!("verdict: {}", spec.verdict);
        for l in &spec.limits {
            say!("  {}: {} ({})", l.callout, l.verdict, l.reason);
        }
        if judged && spec.verdict == crate::specification::Verdict::DoesNotConform {
            say!("{}", o.verdict_line());
            return Err(CliError::new(
                Exit::DoesNotConform,
                format!(
                    "the part does not conform to its specification (report.json's specification names the limits and lines): {}",
                    o.files.report_json.display()
                ),
            ));
        }
    }
    if o.report.kind != "profile" {
        say!("{}", o.verdict_line());
    }
    if o.complete() {
        return Ok(());
    }
    let mut partial = Vec::new();
    if c.lines_in_input > o.lines_used.len() {
        partial.push(format!(
            "it is made from {} (the others cannot be used, see the warnings above)",
            c.lines_used()
        ));
    }
    if !c.failed_sections.is_empty() {
        let failed: Vec<&str> = c
            .failed_sections
            .iter()
            .map(|f| f.section.as_str())
            .collect();
        partial.push(format!(
            "{} could not be made (the reasons are in the warnings above and in {})",
            failed.join(", "),
            o.files.report_json.display()
        ));
    }
    Err(CliError::new(
        Exit::Partial,
        format!(
            "the characterisation is partial: {}; every other output is written",
            partial.join("; ")
        ),
    ))
}

/// Refuses, as a usage error before anything is read: a degree of 0; a `--lc`, `--curves` or
/// `--levels` outside the range the same setting has in a station's `[analysis]` (λc 0 or NaN,
/// one level, a hundred million levels that would run for minutes); `--sampling-lengths 0`, a
/// `--ls` that is no length; and the flags for files given with a scan directory.
fn check_args(args: &Args) -> Result<(), CliError> {
    use crate::config::{Num, NumericKey};
    args.model.check_degrees()?;
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
    let usage = |m: String| Err(CliError::new(Exit::Usage, m));
    if args.sampling_lengths == Some(0) {
        return usage(
            "--sampling-lengths 0: give at least 1 sampling length (ISO 4288's default is 5)"
                .into(),
        );
    }
    if args.input.is_dir() && (args.ls.is_some() || args.form.is_some()) {
        return usage("--ls and --form are for CSV and X3P inputs; a scan's lines are evaluated as the instrument filtered them (its λs is in the recorded conditions)".into());
    }
    if let Some(l) = args.ls.filter(|l| !(l.is_finite() && *l > 0.0)) {
        return usage(format!(
            "--ls {l} must be a positive length in µm, e.g. 2.5 or 8"
        ));
    }
    if args.input.is_dir() && args.sampling_lengths.is_some() {
        return usage("--sampling-lengths is for CSV and X3P inputs; a scan's lines are evaluated with the N the instrument recorded".into());
    }
    Ok(())
}

/// Runs `surfscan analyze`: the flags checked, the station and recipe loaded, the input read
/// by the one reader, then the characterisation of a scan or a grid (a profile being a grid
/// of one line) with the options the flags and the scan's frozen plan make.
pub fn run(args: Args) -> Result<(), CliError> {
    check_args(&args)?;
    let station = args.config.as_deref().map(super::station::load_config);
    let station = station.transpose()?.map(|(config, _)| config);
    let recipe = (args.recipe.as_deref())
        .map(|r| recipe_of(r, station.as_ref()))
        .transpose()?;
    let judged = recipe.is_some();
    let input = args.read.read(&args.input)?;
    if input.is_profile() && judged {
        return Err(CliError::new(
            Exit::Usage,
            "--recipe is for scan directories and grids: a single profile is one value, and the 16 % and max rules judge a surface's lines",
        ));
    }
    let options = analysis_options(&args, &input, station.as_ref(), recipe)?;
    let outputs = match &input.source {
        Source::Scan(_) => characterise_scan(&input, &options),
        _ => characterise_grid(&args, &input, options),
    }
    .map_err(report_error)?;
    let profile = input
        .is_profile()
        .then(|| profile_summary(&outputs, &args, input.grid.cols));
    finish(&outputs, judged, profile)
}

/// How a file's lines are evaluated: `--lc` (default 0.8 mm), `--no-filter`, `--ls`,
/// `--sampling-lengths` and `--form`.
fn line_options(args: &Args) -> Options {
    Options {
        lambda_c_mm: args.lc.unwrap_or(DEFAULT_LC_MM),
        apply_lambda_c: !args.no_filter,
        lambda_s_um: args.ls,
        sampling_lengths: None,
        central_sections: args.sampling_lengths,
        form: args.form,
    }
}

/// The recipe `--recipe` names: a file (checked by itself, or against `station` when
/// `--config` names one), else a name in `station`'s recipe directory. A recipe without limits
/// is a usage error: there is nothing to judge.
fn recipe_of(arg: &Path, station: Option<&crate::config::Config>) -> Result<Recipe, CliError> {
    use crate::jobs::recipe::valid_name;
    let name_arg = arg.to_str().filter(|n| valid_name(n) && !arg.exists());
    let recipe = match (name_arg, station) {
        (Some(name), Some(c)) => Recipe::load(&c.jobs.recipes, name, c)?,
        (Some(name), None) if !name.ends_with(".toml") => {
            return Err(CliError::new(
                Exit::Usage,
                format!("--recipe {name}: no such file; give a recipe file, or --config with a station whose [jobs] recipes directory holds {name}.toml"),
            ))
        }
        _ => {
            let text = std::fs::read_to_string(arg).map_err(|e| {
                let exit = if e.kind() == std::io::ErrorKind::NotFound {
                    Exit::Usage
                } else {
                    Exit::Io
                };
                CliError::new(exit, format!("cannot read recipe {}: {e}", arg.display()))
            })?;
            let name = arg
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            match station {
                Some(c) => Recipe::from_text(&name, arg, &text, c),
                None => Recipe::parse(&name, arg, &text),
            }?
        }
    };
    if recipe.specification.is_empty() {
        return Err(CliError::new(
            Exit::Usage,
            format!(
                "recipe {}: its [specification] limits are empty, so there is nothing to judge; write the drawing's limits (limits = [\"Ra 0.8\"])",
                recipe.path.display()
            ),
        ));
    }
    Ok(recipe)
}

/// The characterisation's options: a scan's frozen `[analysis]` (the defaults for a file or
/// a journal of an older version), each flag given overriding its part; the output
/// directory, `--config`'s laboratory header and `--recipe`'s limits. A judged grid takes the
/// calibration uncertainty of `--config`'s `[traceability]` (a scan its journal's).
fn analysis_options(
    args: &Args,
    input: &GridInput,
    station: Option<&crate::config::Config>,
    recipe: Option<Recipe>,
) -> Result<ScanAnalysisOptions, CliError> {
    let journal = match &input.source {
        Source::Scan(v) => v.journal.as_ref().ok(),
        _ => None,
    };
    let frozen = journal.and_then(|s| s.start.plan.analysis.as_ref());
    let base = frozen.map_or_else(ScanAnalysisOptions::default, |a| {
        ScanAnalysisOptions::default().with_frozen(a)
    });
    let scan = matches!(input.source, Source::Scan(_));
    let paper_q = crate::fit::FitOptions::default().degree_v;
    Ok(ScanAnalysisOptions {
        curves: args.curves.unwrap_or(base.curves),
        levels: args.levels.unwrap_or(base.levels),
        lambda_c_mm: args.lc.or(base.lambda_c_mm),
        no_filter: args.no_filter || base.no_filter,
        overlay_line: args.overlay_line,
        degree_u: args.model.degree_u,
        degree_v: args.model.degree_v,
        spikes: args.model.spikes_or(base.spikes)?,
        exclude_spikes: args
            .outliers
            .map_or(base.exclude_spikes, |o| o == OutliersArg::Exclude),
        holdout_threshold: args.model.holdout_threshold_or(base.holdout_threshold)?,
        v_method: args
            .model
            .v_method(input.grid.rows(), args.model.degree_v.unwrap_or(paper_q))?,
        replace_spikes: args.model.replace(),
        material_ratio: args.material_ratio.unwrap_or(base.material_ratio),
        contact: contact_options(args)?.or(base.contact),
        out_dir: args.out.clone(),
        // `--config`'s header, else the one a scan's journal recorded (a grid's default one),
        // with the per-line PNGs when `--line-png` asks for them.
        lab: station
            .map(|c| c.report.clone())
            .or_else(|| journal.map(|s| LabHeader::of_frozen_config(&s.start.config)))
            .or_else(|| (!scan).then(LabHeader::default))
            .map(|lab| LabHeader {
                line_png: lab.line_png || args.line_png,
                ..lab
            }),
        instrument: (recipe.is_some() && !scan).then(|| InstrumentUncertainty {
            expanded_relative_pct: station.and_then(|c| c.traceability.calibration_uncertainty_pct),
        }),
        specification: recipe.map(|r| r.specification),
    })
}

/// Characterises a grid CSV or an X3P file with `options`: fits it once the way they ask
/// (`--degree-u/--degree-v`, default the paper's 5/5; `--v-method`; spikes replaced only with
/// `--replace-spikes`) and describes that surface (the model sections and the hold-out refits
/// are made the same way); the lines are evaluated as [`line_options`] says.
fn characterise_grid(
    args: &Args,
    input: &GridInput,
    options: ScanAnalysisOptions,
) -> Result<ScanOutputs, ReportError> {
    let line_options = line_options(args);
    let mut recipe = crate::report::scan_dir::scan_recipe(&options, None, &[]);
    recipe.lambda_c_mm = line_options
        .apply_lambda_c
        .then_some(line_options.lambda_c_mm);
    let ((surface, replaced), fit, fit_s) = fit_for_report(&input.grid, &recipe);
    let lambda_c_source = match args.lc {
        Some(v) => format!("given ({v} mm)"),
        None => format!("default {DEFAULT_LC_MM} mm (set --lc to choose)"),
    };
    let filter_reason = match (args.no_filter, &input.source) {
        (true, _) => "no λc filter: asked for (--no-filter)",
        (false, Source::X3p { .. }) => {
            "λc filter applied: an X3P file is taken as a primary surface unless --no-filter"
        }
        _ => "λc filter applied: a CSV is taken as a primary profile unless --no-filter",
    };
    let ctx = ReportContext {
        input: input.described.clone(),
        kind: if input.is_profile() {
            "profile"
        } else {
            input.kind()
        },
        line_options,
        lambda_c_source,
        filter_reason: filter_reason.to_string(),
        traceability: None,
        scan: None,
        fit,
        lab: options.lab.clone().unwrap_or_default(),
        options,
        warnings: input.findings.clone(),
    };
    let model = Model {
        recipe,
        replaced: &replaced,
        fit_s,
    };
    // A file's outputs go to `--out`, else the working directory.
    let out = args.out.as_deref().unwrap_or(Path::new("."));
    characterise(&input.grid, model, surface, ctx, out)
}

/// What `analyze` of a profile says it found, as the instrument's display would show it:
/// `profile of 2000 points (1 mm), λc 0.8 mm filter applied: Ra 0.2345 µm, Rq …, Rz …; Rk …`,
/// the Rk family in the reading `--material-ratio` asks for (named when it is the
/// instrument's).
fn profile_summary(o: &ScanOutputs, args: &Args, points: usize) -> String {
    use crate::numfmt::{fmt, Quantity};
    let options = line_options(args);
    let Some(line) = o.report.lines.first() else {
        return "no line characterised".into();
    };
    let reading = args.material_ratio.unwrap_or_default();
    let p = reading.applied(&line.params, line.material_ratio_sj_series.as_ref());
    let ls = options
        .lambda_s_um
        .map(|l| format!("λs {l} µm, "))
        .unwrap_or_default();
    let (filter, name) = match options.form {
        Some(f) => (format!("{ls}{} removed, no λc filter", f.describe()), "P"),
        None if options.apply_lambda_c => (
            format!("{ls}λc {} mm filter applied", options.lambda_c_mm),
            "R",
        ),
        None => (format!("{ls}no λc filter"), "R"),
    };
    let read_as = match reading {
        MaterialRatioReading::Iso => "",
        MaterialRatioReading::Instrument => " (as the SJ series reads them)",
    };
    let rk = &p.material.rk;
    let [a, q, z, k, pk, vk] = [p.ra_um, p.rq_um, p.rz_um, rk.rk_um, rk.rpk_um, rk.rvk_um]
        .map(|v| fmt(v, Quantity::HeightUm));
    format!(
        "profile of {points} points ({} mm), {filter}: {name}a {a} µm, {name}q {q} µm, {name}z {z} µm; {name}k {k} µm, {name}pk {pk} µm, {name}vk {vk} µm{read_as}",
        fmt(points as f64 * o.report.recipe.lines.pitch_mm, Quantity::LengthMm),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

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
