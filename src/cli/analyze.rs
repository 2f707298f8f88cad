//! `surfscan analyze`: surface characterisation of a profile CSV (header `x_mm,z_um`) or of a
//! grid CSV of heights in µm (rows = traced lines along y, columns = points along x, as
//! `surfscan fit` reads; pitches required). Writes `report.json` and `summary.csv` into the
//! output directory, and for a grid also `measured.x3p`, `model.x3p` (ISO 25178-72), `bac.png|svg`
//! `heightmap.png|svg` and `overlay.png|svg` (measured vs model of one line).
//!
//! Layer 5 (composition): reads files, calls [`crate::metrology`] and [`crate::fit`].

use super::{CliError, Exit};
use crate::fit::{fit_grid, FitOptions};
use crate::metrology::areal::{areal_params, smr_curve, Grid};
use crate::metrology::holdout::{holdout, Holdout};
use crate::metrology::model::{model_bearing_curves, sample_model_grid, ModelBacOptions};
use crate::metrology::params::{analyze_line, Options, Recipe, RoughnessParams};
use crate::metrology::plots::{plot_bearing_curves, plot_height_map, plot_profile_overlay};
use crate::metrology::x3p::{to_x3p, X3pMeta};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Arguments of `surfscan analyze`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Profile CSV (`x_mm,z_um` header) or grid CSV of heights in µm.
    pub input: PathBuf,
    /// Cut-off λc in mm (also the sampling length).
    #[arg(long, default_value_t = 0.8)]
    pub lc: f64,
    /// The input already is an R profile: no λc filter.
    #[arg(long)]
    pub no_filter: bool,
    /// Grid pitch along x (between columns), mm.
    #[arg(long)]
    pub pitch_x: Option<f64>,
    /// Grid pitch along y (between rows), mm.
    #[arg(long)]
    pub pitch_y: Option<f64>,
    /// Profile curves extracted from the model for the bearing area curves.
    #[arg(long, default_value_t = 31)]
    pub curves: usize,
    /// Equal height levels per bearing area curve.
    #[arg(long, default_value_t = 101)]
    pub levels: usize,
    /// Line (0-based) drawn in the measured-vs-model overlay; default the middle line.
    #[arg(long)]
    pub overlay_line: Option<usize>,
    /// Output directory for report.json and summary.csv.
    #[arg(long, default_value = ".")]
    pub out: PathBuf,
}

/// One line's entry in the report.
#[derive(Debug, Serialize)]
struct LineReport {
    index: usize,
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

/// Areal results with their curve.
#[derive(Debug, Serialize)]
struct SurfaceReport {
    #[serde(flatten)]
    params: crate::metrology::areal::ArealParams,
    /// Pooled Smr(c): `[height_um, material_ratio_pct]`.
    bac: Vec<[f64; 2]>,
}

#[derive(Debug, Serialize)]
struct Report {
    software: String,
    input: String,
    kind: &'static str,
    recipe: Recipe,
    lines: Vec<LineReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    surface: Option<SurfaceReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    surface_recipe: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    surface_grid: Option<SurfaceReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    bac_curves: Option<Vec<crate::metrology::model::ModelCurveBac>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    bac_curves_recipe: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    model_vs_measured: Option<Holdout>,
    /// Why the hold-out comparison could not be made (e.g. too few lines to refit half).
    #[serde(skip_serializing_if = "Option::is_none")]
    model_vs_measured_error: Option<String>,
}

fn failed(msg: impl Into<String>) -> CliError {
    CliError::new(Exit::Failed, msg)
}

fn parse_numbers(line: &str) -> Option<Vec<f64>> {
    line.split(',')
        .map(|f| f.trim().parse::<f64>().ok())
        .collect::<Option<Vec<f64>>>()
}

/// Reads a profile CSV: returns pitch (mm) and heights (µm). x must be uniformly spaced.
fn read_profile(path: &Path, text: &str) -> Result<(f64, Vec<f64>), CliError> {
    let mut x = Vec::new();
    let mut z = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        match parse_numbers(line).as_deref() {
            Some([xv, zv, ..]) => {
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

/// Reads a grid CSV: rows of equal length (a non-numeric first line is taken as a header).
fn read_grid(path: &Path, text: &str) -> Result<(Vec<f64>, usize, usize), CliError> {
    let mut z = Vec::new();
    let mut cols = 0;
    let mut rows = 0;
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let Some(values) = parse_numbers(line) else {
            if n == 0 {
                continue;
            }
            return Err(failed(format!(
                "{}: line {} holds a value that is not a number",
                path.display(),
                n + 1
            )));
        };
        if rows == 0 {
            cols = values.len();
        } else if values.len() != cols {
            return Err(failed(format!(
                "{}: line {} has {} values, the first row had {cols}; all rows must be equally long",
                path.display(),
                n + 1,
                values.len()
            )));
        }
        z.extend(values);
        rows += 1;
    }
    Ok((z, rows, cols))
}

/// Runs `surfscan analyze`.
pub fn run(args: Args) -> Result<(), CliError> {
    let text = std::fs::read_to_string(&args.input).map_err(|e| {
        CliError::new(
            Exit::Io,
            format!("cannot read {}: {e}", args.input.display()),
        )
    })?;
    let options = Options {
        lambda_c_mm: args.lc,
        apply_lambda_c: !args.no_filter,
        lambda_s_um: None,
        sampling_lengths: None,
    };
    let is_profile = text
        .lines()
        .next()
        .is_some_and(|h| h.trim_start().starts_with("x_mm"));
    let mut grid_for_plots = None;
    let report = if is_profile {
        let (pitch, z) = read_profile(&args.input, &text)?;
        let a = analyze_line(&z, pitch, &options)
            .map_err(|e| failed(format!("{}: {e}", args.input.display())))?;
        let rmr = rmr_table(&a);
        Report {
            software: format!("surfscan {}", env!("CARGO_PKG_VERSION")),
            input: args.input.display().to_string(),
            kind: "profile",
            recipe: a.recipe,
            lines: vec![LineReport {
                index: 0,
                y_mm: 0.0,
                rmr_table: rmr,
                params: a.params,
            }],
            surface: None,
            surface_recipe: None,
            surface_grid: None,
            bac_curves: None,
            bac_curves_recipe: None,
            model_vs_measured: None,
            model_vs_measured_error: None,
        }
    } else {
        let (Some(px), Some(py)) = (args.pitch_x, args.pitch_y) else {
            return Err(CliError::new(
                Exit::Usage,
                "a grid CSV needs --pitch-x MM and --pitch-y MM (a profile CSV starts with the header x_mm,z_um)",
            ));
        };
        let (z, rows, cols) = read_grid(&args.input, &text)?;
        let mut lines = Vec::with_capacity(rows);
        let mut recipe = None;
        for (index, row) in z.chunks_exact(cols.max(1)).enumerate() {
            let a = analyze_line(row, px, &options)
                .map_err(|e| failed(format!("{} line {index}: {e}", args.input.display())))?;
            let rmr = rmr_table(&a);
            recipe.get_or_insert(a.recipe);
            lines.push(LineReport {
                index,
                y_mm: index as f64 * py,
                rmr_table: rmr,
                params: a.params,
            });
        }
        let recipe = recipe.ok_or_else(|| failed(format!("{}: no lines", args.input.display())))?;
        let grid = Grid {
            heights_um: &z,
            rows,
            cols,
            pitch_x_mm: px,
            pitch_y_mm: py,
        };
        let err =
            |e: crate::metrology::MetrologyError| failed(format!("{}: {e}", args.input.display()));
        let surface_grid = SurfaceReport {
            params: areal_params(&grid).map_err(err)?,
            bac: smr_curve(&grid, args.levels).map_err(err)?,
        };
        let y: Vec<f64> = (0..rows).map(|j| j as f64 * py).collect();
        let fit = fit_grid(px, &y, &z, cols, FitOptions::default()).map_err(|e| {
            failed(format!(
                "{}: the NURBS fit failed: {e}",
                args.input.display()
            ))
        })?;
        let bac_options = ModelBacOptions {
            curves: args.curves,
            levels: args.levels,
            samples_per_curve: None,
        };
        let curves = model_bearing_curves(&fit.surface, &bac_options).map_err(err)?;
        let model_cols = 2 * cols - 1;
        let model_z = sample_model_grid(&fit.surface, &fit.params_v, 0.0, px / 2.0, model_cols)
            .map_err(err)?;
        let model_grid = Grid {
            heights_um: &model_z,
            rows,
            cols: model_cols,
            pitch_x_mm: px / 2.0,
            pitch_y_mm: py,
        };
        // A grid too small to refit half of it still gets everything else.
        let (model_vs_measured, model_vs_measured_error) =
            match holdout(&z, rows, cols, px, py, FitOptions::default()) {
                Ok(h) => (Some(h), None),
                Err(e) => (None, Some(e.to_string())),
            };
        let surface = SurfaceReport {
            params: areal_params(&model_grid).map_err(err)?,
            bac: smr_curve(&model_grid, args.levels).map_err(err)?,
        };
        let report = Report {
            software: format!("surfscan {}", env!("CARGO_PKG_VERSION")),
            input: args.input.display().to_string(),
            kind: "grid",
            recipe,
            lines,
            surface: Some(surface),
            surface_recipe: Some(format!(
                "the degree 5/5 interpolating NURBS surface sampled on the data lines (their v) at half the x pitch ({} points per line, x(u) inverted by bisection), then levelled and evaluated as surface_grid",
                model_cols
            )),
            surface_grid: Some(surface_grid),
            bac_curves: Some(curves),
            model_vs_measured,
            model_vs_measured_error,
            bac_curves_recipe: Some(format!(
                "paper Appendix A: {} iso-curves along x of the degree 5/5 interpolating surface at equally spaced v, each sampled at 8 points per control point along u, referenced to its x-weighted mean line, {} equal levels, crossings linear along x",
                args.curves, args.levels
            )),
        };
        let meta = |what: &str| X3pMeta {
            date: chrono::Utc::now().to_rfc3339(),
            version: format!("surfscan {}", env!("CARGO_PKG_VERSION")),
            comment: format!("{what} of {}", args.input.display()),
            ..X3pMeta::default()
        };
        let x3p = [
            (
                "measured.x3p",
                to_x3p(&z, rows, cols, px, py, &meta("measured grid")).map_err(err)?,
            ),
            (
                "model.x3p",
                to_x3p(
                    &model_z,
                    rows,
                    model_cols,
                    px / 2.0,
                    py,
                    &meta("NURBS model sampled at half the x pitch on the data lines"),
                )
                .map_err(err)?,
            ),
        ];
        std::fs::create_dir_all(&args.out).map_err(|e| {
            CliError::new(
                Exit::Io,
                format!("cannot create {}: {e}", args.out.display()),
            )
        })?;
        for (name, bytes) in x3p {
            let path = args.out.join(name);
            std::fs::write(&path, bytes).map_err(|e| {
                CliError::new(Exit::Io, format!("cannot write {}: {e}", path.display()))
            })?;
        }
        grid_for_plots = Some((z, rows, cols, model_z));
        report
    };
    write_outputs(&args.out, &report)?;
    if let (Some(curves), Some(surface), Some((z, rows, cols, model_z))) =
        (&report.bac_curves, &report.surface, grid_for_plots)
    {
        let err = |e: crate::metrology::MetrologyError| CliError::new(Exit::Io, e.to_string());
        let title = format!("Bearing area curves: {} model curves, pooled", curves.len());
        plot_bearing_curves(&args.out, curves, &surface.bac, &title).map_err(err)?;
        let (px, py) = (args.pitch_x.unwrap_or(1.0), args.pitch_y.unwrap_or(1.0));
        plot_height_map(&args.out, &z, rows, cols, px, py, "Measured heights").map_err(err)?;
        let line = args
            .overlay_line
            .unwrap_or(rows / 2)
            .min(rows.saturating_sub(1));
        let mc = 2 * cols - 1;
        let measured: Vec<(f64, f64)> = z
            .get(line * cols..(line + 1) * cols)
            .unwrap_or(&[])
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 * px, *v))
            .collect();
        let model: Vec<(f64, f64)> = model_z
            .get(line * mc..(line + 1) * mc)
            .unwrap_or(&[])
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 * px / 2.0, *v))
            .collect();
        let title = format!(
            "Line {line} (y = {:.4} mm): measured and model",
            line as f64 * py
        );
        plot_profile_overlay(&args.out, &measured, &model, &title).map_err(err)?;
    }
    Ok(())
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map(|v| format!("{v}")).unwrap_or_default()
}

fn write_outputs(out: &Path, report: &Report) -> Result<(), CliError> {
    let io = |p: &Path, e: std::io::Error| {
        CliError::new(Exit::Io, format!("cannot write {}: {e}", p.display()))
    };
    std::fs::create_dir_all(out).map_err(|e| io(out, e))?;
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| failed(format!("cannot encode the report: {e}")))?;
    let path = out.join("report.json");
    std::fs::write(&path, json).map_err(|e| io(&path, e))?;
    let mut csv = String::from(
        "index,y_mm,Ra_um,Rq_um,Rz_um,RzJIS_um,Rp_um,Rv_um,Rt_um,Rz1max_um,Rsk,Rku,Rdq,RSm_um,Rk_um,Rpk_um,Rvk_um,Mr1_pct,Mr2_pct\n",
    );
    for l in &report.lines {
        let p = &l.params;
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            l.index,
            l.y_mm,
            p.ra_um,
            p.rq_um,
            p.rz_um,
            fmt_opt(p.rzjis_um),
            p.rp_um,
            p.rv_um,
            p.rt_um,
            p.rz1max_um,
            p.rsk,
            p.rku,
            p.rdq,
            fmt_opt(p.rsm_um),
            p.rk_um,
            p.rpk_um,
            p.rvk_um,
            p.mr1_pct,
            p.mr2_pct
        ));
    }
    let path = out.join("summary.csv");
    std::fs::write(&path, csv).map_err(|e| io(&path, e))?;
    Ok(())
}
