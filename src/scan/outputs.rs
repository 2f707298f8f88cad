//! What a completed scan leaves besides its lines: the fitted surface as IGES
//! (`surface.igs`, or `surface.part<i>-of-<n>.igs` when one file cannot hold it) with the
//! scan's traceability in its Start section, and `report.json` with the fit statistics,
//! the instrument's own results per line and the traceability of the scan. Every file is
//! replaced atomically (temporary name, fsync, rename).
//!
//! Layer 3 (session): depends on [`crate::fit`], [`crate::iges`], [`crate::atomic`],
//! [`super::store`] and [`super::journal`] (to read the lines and the start record).

use super::journal::StartRecord;
use super::line::StoredLine;
use super::plan::Plan;
use super::store::ScanStore;
use crate::atomic::write_atomically;
use crate::fit::{max_residual_mm, FitResult, IncrementalFitter};
use crate::iges::{plan_parts, write_iges_seekable, IgesError, IgesOptions};
use crate::nurbs::NurbsSurface;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// The files a completed scan wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Outputs {
    /// The IGES file(s), in v order.
    pub iges: Vec<PathBuf>,
    /// `report.json`.
    pub report: PathBuf,
    /// Other files of the characterisation (summary, plots, X3P).
    pub files: Vec<PathBuf>,
    /// Why the characterisation could not be made, when it could not (the report then
    /// holds the fit and the instrument's own results only).
    pub characterisation_error: Option<String>,
    /// Largest distance between the surface and a measured point, mm.
    pub max_residual_mm: f64,
}

/// The characterisation of a finished scan directory, supplied by the composition layer
/// (the CLI passes `crate::report::characterise_scan`): it is given the scan directory and
/// the fit section for `report.json`, writes the report and its files, and returns the
/// paths of the files other than `report.json`.
pub type Characterise =
    Arc<dyn Fn(&Path, serde_json::Value) -> Result<Vec<PathBuf>, String> + Send + Sync>;

/// Where part `index` (1-based) of `count` goes when the surface needs several files:
/// `dir/name.igs` → `dir/name.part2-of-3.igs` (an output without extension gets
/// `.part2-of-3`).
pub fn part_path(output: &Path, index: usize, count: usize) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match output.extension() {
        Some(ext) => format!("{stem}.part{index}-of-{count}.{}", ext.to_string_lossy()),
        None => format!("{stem}.part{index}-of-{count}"),
    };
    output.with_file_name(name)
}

/// The v parameter range covered by a group of consecutive patches.
fn v_range(patches: &[NurbsSurface]) -> [f64; 2] {
    let lo = patches
        .first()
        .and_then(|s| s.knots_v().get(s.degree_v()).copied())
        .unwrap_or(f64::NAN);
    let hi = patches
        .last()
        .and_then(|s| s.knots_v().get(s.count_v()).copied())
        .unwrap_or(f64::NAN);
    [lo, hi]
}

/// One IGES file written by [`write_surface_files`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WrittenIges {
    /// Path.
    pub path: PathBuf,
    /// 1-based part number.
    pub part: usize,
    /// v parameter range of the part.
    pub v_range: [f64; 2],
    /// Entities 128 in it.
    pub patches: usize,
    /// Bytes.
    pub bytes: u64,
    /// Parameter Data lines.
    pub parameter_lines: usize,
}

/// Why the IGES files could not be written.
#[derive(Debug, thiserror::Error)]
pub enum SurfaceWriteError {
    /// The surface cannot be represented in the format (a data problem).
    #[error("cannot write IGES {path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What the writer refused.
        message: String,
    },
    /// The file system refused (full disk, permissions).
    #[error("cannot write IGES {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

fn write_error(path: &Path, e: std::io::Error) -> SurfaceWriteError {
    let format = e
        .get_ref()
        .and_then(|inner| inner.downcast_ref::<IgesError>())
        .filter(|ie| !matches!(ie, IgesError::Io(_)))
        .map(|ie| ie.to_string());
    match format {
        Some(message) => SurfaceWriteError::Format {
            path: path.to_path_buf(),
            message,
        },
        None => SurfaceWriteError::Io {
            path: path.to_path_buf(),
            source: e,
        },
    }
}

/// Writes `surface` as IGES at `output`, or as several complete files
/// `output.part<i>-of-<n>.igs` when one P section cannot hold it; each file atomically.
/// Errors carry the path and say whether the format or the disk refused.
pub fn write_surface_files(
    output: &Path,
    surface: &NurbsSurface,
    opts: &IgesOptions,
) -> Result<Vec<WrittenIges>, SurfaceWriteError> {
    let groups = plan_parts(surface, opts).map_err(|e| SurfaceWriteError::Format {
        path: output.to_path_buf(),
        message: e.to_string(),
    })?;
    let n_files = groups.len();
    let mut files = Vec::with_capacity(n_files);
    for (k, group) in groups.iter().enumerate() {
        let range = v_range(group);
        let path = if n_files == 1 {
            output.to_path_buf()
        } else {
            part_path(output, k + 1, n_files)
        };
        let mut part_opts = opts.clone();
        part_opts.file_name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if n_files > 1 {
            part_opts.start_lines.push(format!(
                "part {} of {}, v range [{}, {}]; {} exact patch(es); adjacent parts share their boundary pole row, the union of all parts is the surface.",
                k + 1,
                n_files,
                range[0],
                range[1],
                group.len()
            ));
        }
        let st = write_atomically(&path, |w| {
            write_iges_seekable(w, group, &part_opts).map_err(std::io::Error::other)
        })
        .map_err(|e| write_error(&path, e))?;
        files.push(WrittenIges {
            path,
            part: k + 1,
            v_range: range,
            patches: st.patches,
            bytes: st.bytes,
            parameter_lines: st.parameter_lines,
        });
    }
    Ok(files)
}

/// The degrees, knot-vector lengths and pole counts of a surface, for fit reports.
pub fn surface_fields(s: &NurbsSurface) -> serde_json::Map<String, serde_json::Value> {
    let mut m = serde_json::Map::new();
    m.insert("degree_u".into(), s.degree_u().into());
    m.insert("degree_v".into(), s.degree_v().into());
    m.insert("knots_u_len".into(), s.knots_u().len().into());
    m.insert("knots_v_len".into(), s.knots_v().len().into());
    m.insert("poles_u".into(), s.count_u().into());
    m.insert("poles_v".into(), s.count_v().into());
    m
}

/// The Start-section lines that make an IGES file of a scan traceable.
pub fn traceability_lines(start: &StartRecord, plan: &Plan) -> Vec<String> {
    let c = &start.conditions;
    vec![
        format!(
            "Surface fitted by {} (global B-spline interpolation, p={}, q={}); units mm.",
            start.software_version, plan.degree_u, plan.degree_v
        ),
        format!(
            "Scan {}: specimen {:?}, operator {:?}, notes {:?}.",
            start.scan_id, start.specimen, start.operator, start.notes
        ),
        format!(
            "Instrument Mitutoyo {} firmware {:?}, drive unit {:?}; conditions: standard {}, profile {}, lambda-c {} mm, lambda-s {} um, evaluation length {} mm.",
            start.instrument_model,
            start.firmware,
            start.drive_unit,
            c.standard.as_deref().unwrap_or("unknown"),
            c.profile_kind.map_or("unknown".to_owned(), |k| format!("{k:?}")),
            c.lambda_c_mm.map_or("unknown".to_owned(), |v| v.to_string()),
            c.lambda_s_um.map_or("unknown".to_owned(), |v| v.to_string()),
            c.evaluation_length_mm.map_or("unknown".to_owned(), |v| v.to_string()),
        ),
        format!(
            "Grid: {} lines from y = {} mm by {} mm; config sha256 {}; started {}.",
            plan.lines,
            plan.y_start_nm.to_mm(),
            plan.y_step_nm.to_mm(),
            start.config_hash,
            start.time.to_rfc3339()
        ),
    ]
}

/// The traceability block of `report.json`.
pub fn traceability_json(start: &StartRecord) -> serde_json::Value {
    serde_json::json!({
        "scan_id": start.scan_id,
        "specimen": start.specimen,
        "operator": start.operator,
        "notes": start.notes,
        "software_version": start.software_version,
        "config_hash": start.config_hash,
        "instrument_model": start.instrument_model,
        "firmware": start.firmware,
        "drive_unit": start.drive_unit,
        "conditions": start.conditions,
        "started": start.time,
    })
}

/// Fits the lines, writes the IGES, then the characterisation (or, without one or when it
/// fails, a `report.json` with the fit and the instrument's own results) into the scan
/// directory.
pub fn write_outputs(
    store: &ScanStore,
    start: &StartRecord,
    plan: &Plan,
    fitter: IncrementalFitter,
    characterise: Option<&Characterise>,
) -> Result<Outputs, String> {
    let t_fit = Instant::now();
    let fit = fitter.finish().map_err(|e| format!("fit: {e}"))?;
    let finish_s = t_fit.elapsed().as_secs_f64();
    let loaded = store.load_all().map_err(|e| e.to_string())?;
    let lines = loaded.lines;
    let residual = residual_of(&fit, &lines);
    let iges_path = store.root().join("surface.igs");
    let opts = IgesOptions {
        start_lines: traceability_lines(start, plan),
        timestamp: chrono::Utc::now().naive_utc(),
        ..IgesOptions::default()
    };
    let t_write = Instant::now();
    let files = write_surface_files(&iges_path, &fit.surface, &opts).map_err(|e| e.to_string())?;
    let write_s = t_write.elapsed().as_secs_f64();
    let iges_files: Vec<PathBuf> = files.iter().map(|f| f.path.clone()).collect();
    let mut fit_json = serde_json::json!({
        "grid": { "rows": lines.len(), "cols": lines.first().map_or(0, |l| l.profile.len()) },
        "max_residual_mm": residual,
        "iges_files": files,
        "timings_s": {
            "fit_params": fit.timings.params_s,
            "fit_knots_factor": fit.timings.knots_factor_s,
            "fit_solve_u": fit.timings.solve_u_s,
            "fit_solve_v": fit.timings.solve_v_s,
            "finish": finish_s,
            "write_iges": write_s,
        },
    });
    if let Some(o) = fit_json.as_object_mut() {
        o.extend(surface_fields(&fit.surface));
    }
    let report_path = store.root().join("report.json");
    let mut characterisation_error = None;
    if let Some(ch) = characterise {
        match ch(store.root(), fit_json.clone()) {
            Ok(files) => {
                return Ok(Outputs {
                    iges: iges_files,
                    report: report_path,
                    files,
                    characterisation_error: None,
                    max_residual_mm: residual,
                })
            }
            Err(e) => {
                tracing::error!("characterisation of {} failed: {e}", store.root().display());
                characterisation_error = Some(e);
            }
        }
    }
    let line_json: Vec<serde_json::Value> = lines
        .iter()
        .map(|l| {
            serde_json::json!({
                "index": l.meta.index,
                "y_mm": l.y_mm(),
                "y_readback_mm": l.meta.y_readback_nm.map(|n| n.to_mm()),
                "points": l.meta.points,
                "attempt": l.meta.attempt,
                "instrument": l.meta.results,
            })
        })
        .collect();
    let report = serde_json::json!({
        "software": start.software_version,
        "traceability": traceability_json(start),
        "fit": fit_json,
        "lines": line_json,
        "characterisation_error": characterisation_error,
    });
    write_atomically(&report_path, |w| {
        serde_json::to_writer_pretty(&mut *w, &report).map_err(std::io::Error::other)?;
        std::io::Write::write_all(w, b"\n")
    })
    .map_err(|e| format!("cannot write {}: {e}", report_path.display()))?;
    Ok(Outputs {
        iges: iges_files,
        report: report_path,
        files: Vec::new(),
        characterisation_error,
        max_residual_mm: residual,
    })
}

fn residual_of(fit: &FitResult, lines: &[StoredLine]) -> f64 {
    let Some(first) = lines.first() else {
        return f64::NAN;
    };
    let cols = first.profile.len();
    let y: Vec<f64> = lines.iter().map(StoredLine::y_mm).collect();
    let mut z = Vec::with_capacity(lines.len() * cols);
    for l in lines {
        z.extend_from_slice(&l.profile.heights_um);
    }
    max_residual_mm(fit, first.profile.pitch_x_mm, &y, &z, cols)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_names_keep_directory_and_extension() {
        assert_eq!(
            part_path(Path::new("/data/run 7/sur-2.igs"), 2, 3),
            PathBuf::from("/data/run 7/sur-2.part2-of-3.igs")
        );
        assert_eq!(
            part_path(Path::new("out/a.b.IGES"), 10, 12),
            PathBuf::from("out/a.b.part10-of-12.IGES")
        );
        assert_eq!(
            part_path(Path::new("surface"), 1, 2),
            PathBuf::from("surface.part1-of-2")
        );
    }
}
