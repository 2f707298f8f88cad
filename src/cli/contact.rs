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
//! levelling) and [`crate::report::render::contact`] (the files, as a characterisation with
//! the contact section writes them).

use super::input_args::{tell_findings, InputArgs};
use super::{CliError, Exit};
use crate::contact::{
    contact_curve, Body, ContactError, ContactGrid, ContactOptions, SolveOptions,
    DEFAULT_PRESSURES_MPA,
};
use crate::metrology::areal::{level_plane, HeightMap};
use crate::report::render::contact::write_contact_files;
use crate::report::sections::contact::{ContactSection, ContactSurface};
use std::path::PathBuf;

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
    /// Iterations of each load's solve before it gives up, naming how far it got (default
    /// 5000; a scan's grid converges in a few hundred to about 1500).
    #[arg(long, value_name = "N", default_value_t = 5000, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub max_iterations: u32,
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
    let counter = Body::counter(args.young2, args.poisson2)?;
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
        solve: SolveOptions {
            max_iterations: args.max_iterations as usize,
            ..SolveOptions::default()
        },
    })
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
    let map = HeightMap::of(grid, pitch_y_mm);
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
    let section = ContactSection {
        specimen: opts.specimen,
        counter_body: opts.counter,
        effective_modulus_gpa: curve.effective_modulus_gpa,
        hardness_gpa: curve.hardness_gpa,
        measured: Some(ContactSurface::of(curve, &map)),
        measured_error: None,
        model: None,
    };
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from("."));
    std::fs::create_dir_all(&out).map_err(|e| {
        CliError::new(
            Exit::Io,
            format!("cannot create output directory {}: {e}", out.display()),
        )
    })?;
    let described = input.described.clone();
    write_contact_files(&out, &section, grid.origin_mm(), &described, &warnings)
        .map_err(|e| CliError::new(Exit::Io, e.to_string()))?;
    let path = out.join("contact.json");
    say!(
        "contact of {} ({} lines × {} points, pitches {} mm × {} mm), E* = {} GPa{}:",
        described,
        rows,
        grid.cols,
        grid.pitch_x_mm,
        pitch_y_mm,
        crate::numfmt::sig(section.effective_modulus_gpa, 4),
        opts.hardness_gpa
            .map_or(String::new(), |h| format!(", hardness {h} GPa"))
    );
    say!("  nominal MPa   area %   mean gap µm   patches");
    for p in section.measured.iter().flat_map(|m| &m.curve) {
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
