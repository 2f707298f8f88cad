//! `surfscan contact`: the contact of a measured surface with a rigid flat or a second
//! elastic body ([`crate::contact`]), from a scan directory, a grid CSV or an X3P file read
//! by the one reader ([`crate::input`]).
//!
//! The heights are levelled by their least-squares plane first (as the areal parameters
//! are): a scan's tilt is the fixture's, not the part's, and would press one edge alone. A
//! scan whose lines are not equally spaced is solved at their mean spacing, with a warning.
//! Writes into `--out` (default `.`): `contact.json` (the load–area curve, the moduli, the
//! grid, the warnings), `load_area.png|svg` (real contact area against nominal pressure) and
//! `pressure.png|svg` (the contact pressure map at the map load; zero is no contact).
//!
//! Exit status: 0 done, 1 the contact cannot be computed (the grid too small or too coarse to
//! resolve it, a load at or beyond full contact, no convergence — the message names which
//! and how far it got), 2 usage (a modulus, ratio, hardness or pressure out of range), 74
//! I/O.
//!
//! Layer 5 (composition): reads files, calls [`crate::contact`], [`crate::metrology`] (the
//! levelling) and [`crate::report::render::plots`].

use super::input_args::{tell_findings, InputArgs};
use super::{CliError, Exit};
use crate::contact::{
    contact_curve, Body, ContactCurve, ContactError, ContactGrid, ContactOptions,
    DEFAULT_PRESSURES_MPA,
};
use crate::metrology::areal::{level_plane, HeightMap};
use crate::report::render::plots::{plot_load_area, plot_map, LoadAreaPoint, MapValues};
use serde_json::json;
use std::path::{Path, PathBuf};

/// Arguments of `surfscan contact`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scan directory, X3P file or grid CSV of heights.
    pub input: PathBuf,
    /// The pitches of a grid CSV and the unit of its heights.
    #[command(flatten)]
    pub read: InputArgs,
    /// Young's modulus of the measured body, GPa (default 210, steel).
    #[arg(long, value_name = "GPA", default_value_t = Body::STEEL.young_gpa)]
    pub young: f64,
    /// Poisson's ratio of the measured body (default 0.30, steel).
    #[arg(long, value_name = "NU", default_value_t = Body::STEEL.poisson)]
    pub poisson: f64,
    /// Young's modulus of the counter-body, GPa. Without it the counter-body is a rigid flat.
    #[arg(long, value_name = "GPA")]
    pub young2: Option<f64>,
    /// Poisson's ratio of the counter-body (default 0.30; needs --young2).
    #[arg(long, value_name = "NU", requires = "young2")]
    pub poisson2: Option<f64>,
    /// Hardness of the measured body, GPa: points whose pressure reaches it flow (perfectly
    /// plastic). Without it the contact is purely elastic.
    #[arg(long, value_name = "GPA")]
    pub hardness: Option<f64>,
    /// Nominal pressures, MPa, comma-separated (default 1,2,5,10,20,50,100).
    #[arg(long, value_name = "MPA,…", value_delimiter = ',')]
    pub pressures: Vec<f64>,
    /// The nominal pressure of the pressure map, MPa (default the middle of the list; added
    /// to the curve when not among the pressures).
    #[arg(long, value_name = "MPA")]
    pub map_pressure: Option<f64>,
    /// Output directory (default `.`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The exit status of a refused analysis: its inputs out of range are usage errors, the rest
/// failures of the job.
fn contact_error(e: ContactError) -> CliError {
    let exit = match e {
        ContactError::Young { .. }
        | ContactError::Poisson { .. }
        | ContactError::Hardness { .. }
        | ContactError::Pressure { .. }
        | ContactError::BeyondHardness { .. } => Exit::Usage,
        _ => Exit::Failed,
    };
    CliError::new(exit, e.to_string())
}

/// The options from the arguments, every value checked.
pub fn options(args: &Args) -> Result<ContactOptions, ContactError> {
    let specimen = Body::try_new("specimen", args.young, args.poisson)?;
    let counter = args
        .young2
        .map(|e| {
            Body::try_new(
                "counter-body",
                e,
                args.poisson2.unwrap_or(Body::STEEL.poisson),
            )
        })
        .transpose()?;
    Ok(ContactOptions {
        specimen,
        counter,
        hardness_gpa: args.hardness,
        pressures_mpa: if args.pressures.is_empty() {
            DEFAULT_PRESSURES_MPA.to_vec()
        } else {
            args.pressures.clone()
        },
        map_pressure_mpa: args.map_pressure,
        ..ContactOptions::default()
    })
}

/// What the contact was computed on, for `contact.json` and the figures.
struct Solved {
    curve: ContactCurve,
    rows: usize,
    cols: usize,
    pitch_x_mm: f64,
    pitch_y_mm: f64,
}

/// Runs `surfscan contact`.
pub fn run(args: Args) -> Result<(), CliError> {
    let opts = options(&args).map_err(contact_error)?;
    let input = args.read.read(&args.input)?;
    tell_findings(&input);
    let grid = &input.grid;
    let mut warnings: Vec<String> = input.findings.clone();
    let rows = grid.rows();
    let (pitch_y_mm, evenly) = grid.mean_pitch_y();
    if !evenly {
        let w = format!(
            "the lines are not equally spaced; the contact is solved at their mean spacing {pitch_y_mm} mm"
        );
        tell!("surfscan: warning: {w}");
        warnings.push(w);
    }
    if !grid.left_out.is_empty() {
        let w = format!(
            "{} of the input's lines were left out ({}); the contact is of the lines used, side by side",
            grid.left_out.len(),
            grid.lines_used()
        );
        tell!("surfscan: warning: {w}");
        warnings.push(w);
    }
    let map = HeightMap {
        heights_um: &grid.heights_um,
        rows,
        cols: grid.cols,
        pitch_x_mm: grid.pitch_x_mm,
        pitch_y_mm,
    };
    let (levelled, _) = level_plane(&map)
        .map_err(|e| CliError::new(Exit::Failed, format!("{}: {e}", args.input.display())))?;
    let cgrid = ContactGrid {
        heights_um: &levelled,
        rows,
        cols: grid.cols,
        pitch_x_mm: grid.pitch_x_mm,
        pitch_y_mm,
    };
    let curve = contact_curve(&cgrid, &opts).map_err(|e| {
        let e = contact_error(e);
        CliError::new(e.exit, format!("{}: {}", args.input.display(), e.message))
    })?;
    for p in curve.points.iter().filter(|p| !p.resolved) {
        let w = format!(
            "at {} MPa the grid does not resolve the contact: {:.0} % of the contact points are isolated single points",
            p.nominal_pressure_mpa,
            100.0 * p.single_point_patch_fraction
        );
        tell!("surfscan: warning: {w}");
        warnings.push(w);
    }
    let solved = Solved {
        curve,
        rows,
        cols: grid.cols,
        pitch_x_mm: grid.pitch_x_mm,
        pitch_y_mm,
    };
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from("."));
    std::fs::create_dir_all(&out).map_err(|e| {
        CliError::new(
            Exit::Io,
            format!("cannot create output directory {}: {e}", out.display()),
        )
    })?;
    let described = input.described.clone();
    let figures = write_figures(&out, &solved, &opts, &described)?;
    let doc = document(&solved, &opts, &described, &warnings, &figures);
    let path = out.join("contact.json");
    crate::atomic::write_atomically(&path, |w| {
        serde_json::to_writer_pretty(&mut *w, &doc).map_err(std::io::Error::other)?;
        std::io::Write::write_all(w, b"\n")
    })
    .map_err(|e| {
        CliError::new(
            Exit::Io,
            format!(
                "cannot write {}: {}",
                path.display(),
                crate::atomic::write_hint(&path, &e)
            ),
        )
    })?;
    say!(
        "contact of {} ({} lines × {} points, pitches {} mm × {} mm), E* = {} GPa{}:",
        described,
        rows,
        solved.cols,
        solved.pitch_x_mm,
        pitch_y_mm,
        crate::numfmt::sig(solved.curve.effective_modulus_gpa, 4),
        opts.hardness_gpa
            .map_or(String::new(), |h| format!(", hardness {h} GPa"))
    );
    say!("  nominal MPa   area %   mean gap µm   patches");
    for p in &solved.curve.points {
        say!(
            "  {:>11}  {:>7.3}  {:>12.4}  {:>8}{}",
            p.nominal_pressure_mpa,
            100.0 * p.area_fraction,
            p.mean_gap_um,
            p.patches,
            if p.resolved { "" } else { "  (not resolved)" }
        );
    }
    say!("wrote {}", path.display());
    Ok(())
}

/// Writes the load–area curve and the pressure map; returns their file names.
fn write_figures(
    out: &Path,
    solved: &Solved,
    opts: &ContactOptions,
    described: &str,
) -> Result<Vec<String>, CliError> {
    let curve = &solved.curve;
    let against = against(opts, curve.effective_modulus_gpa);
    let points: Vec<LoadAreaPoint> = curve
        .points
        .iter()
        .map(|p| LoadAreaPoint {
            nominal_pressure_mpa: p.nominal_pressure_mpa,
            area_pct: 100.0 * p.area_fraction,
            resolved: p.resolved,
        })
        .collect();
    let plot_error = |e: crate::metrology::MetrologyError| CliError::new(Exit::Io, e.to_string());
    let mut files = Vec::new();
    let written = plot_load_area(
        out,
        &points,
        "Load–area curve",
        &against,
        &format!("{described}; heights levelled by their least-squares plane"),
    )
    .map_err(plot_error)?;
    files.extend(written.iter().map(|p| file_name(p)));
    let pressure_map = HeightMap {
        heights_um: &curve.map.pressure_mpa,
        rows: solved.rows,
        cols: solved.cols,
        pitch_x_mm: solved.pitch_x_mm,
        pitch_y_mm: solved.pitch_y_mm,
    };
    let written = plot_map(
        out,
        &pressure_map,
        &MapValues {
            stem: "pressure",
            name: "pressures",
            unit: "MPa",
            bar: "contact pressure (MPa)",
        },
        &format!(
            "Contact pressure at {} MPa nominal (0: no contact)",
            curve.map.nominal_pressure_mpa
        ),
        &format!("{described}; {against}"),
    )
    .map_err(plot_error)?;
    files.extend(written.iter().map(|p| file_name(p)));
    Ok(files)
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// "steel-like specimen (E 210 GPa, ν 0.3) against a rigid flat, E* 230.8 GPa, elastic".
fn against(opts: &ContactOptions, e_star_gpa: f64) -> String {
    let s = opts.specimen;
    let counter = match opts.counter {
        None => "a rigid flat".to_string(),
        Some(c) => format!("an elastic flat (E {} GPa, ν {})", c.young_gpa, c.poisson),
    };
    let law = match opts.hardness_gpa {
        None => "elastic".to_string(),
        Some(h) => format!("elastic–perfectly plastic at hardness {h} GPa"),
    };
    format!(
        "specimen (E {} GPa, ν {}) against {counter}: E* {} GPa, {law}",
        s.young_gpa,
        s.poisson,
        crate::numfmt::sig(e_star_gpa, 4)
    )
}

/// `contact.json`.
fn document(
    solved: &Solved,
    opts: &ContactOptions,
    described: &str,
    warnings: &[String],
    figures: &[String],
) -> serde_json::Value {
    let body = |b: Body| json!({"young_gpa": b.young_gpa, "poisson": b.poisson});
    let curve = &solved.curve;
    json!({
        "input": described,
        "surface": "measured grid",
        "heights": "levelled by their least-squares plane",
        "grid": {
            "rows": solved.rows,
            "cols": solved.cols,
            "pitch_x_mm": solved.pitch_x_mm,
            "pitch_y_mm": solved.pitch_y_mm,
            "padded": [curve.padded.0, curve.padded.1],
        },
        "specimen": body(opts.specimen),
        "counter_body": opts.counter.map(body),
        "effective_modulus_gpa": curve.effective_modulus_gpa,
        "hardness_gpa": curve.hardness_gpa,
        "curve": curve.points,
        "map": {
            "nominal_pressure_mpa": curve.map.nominal_pressure_mpa,
            "max_pressure_mpa": curve.map.pressure_mpa.iter().cloned().fold(0.0, f64::max),
        },
        "figures": figures,
        "warnings": warnings,
    })
}
