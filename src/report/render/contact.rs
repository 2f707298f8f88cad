//! The contact's own files, written wherever a contact is computed (`surfscan contact`, and a
//! characterisation whose options ask for the contact section — `analyze --contact` or a
//! scan's enabled `[contact]`): `contact.json` (the load–area curve of the measured grid with
//! the bodies, the grid and the warnings; with the model's contact and its verdict between
//! lines when it was asked for), `load_area.png|svg` and `pressure.png|svg`.
//!
//! Layer 4 (reporting): depends on [`crate::atomic`], the section's result and [`super::plots`].

use super::plots::{plot_load_area, plot_map, LoadAreaPoint, MapValues};
use crate::metrology::areal::HeightMap;
use crate::report::error::{io, metrology, ReportError};
use crate::report::sections::contact::{ContactSection, ContactSurface};
use serde_json::json;
use std::path::{Path, PathBuf};

/// Writes `contact.json` and the figures of the measured grid's contact into `out`, `described`
/// naming the input, its pressure map from `origin_mm` (the input's coordinates); returns the
/// figures written (none, and no file, when the measured grid's contact could not be computed).
pub fn write_contact_files(
    out: &Path,
    section: &ContactSection,
    origin_mm: (f64, f64),
    described: &str,
    warnings: &[String],
) -> Result<Vec<PathBuf>, ReportError> {
    let Some(measured) = &section.measured else {
        return Ok(Vec::new());
    };
    let figures = write_figures(out, section, origin_mm, measured, described)?;
    let names: Vec<String> = figures
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let mut doc = json!({
        "input": described,
        "surface": "measured grid",
        "heights": "levelled by their least-squares plane",
        "grid": {
            "rows": measured.rows,
            "cols": measured.cols,
            "pitch_x_mm": measured.pitch_x_mm,
            "pitch_y_mm": measured.pitch_y_mm,
            "padded": [measured.padded.0, measured.padded.1],
        },
        "specimen": section.specimen,
        "counter_body": section.counter_body,
        "effective_modulus_gpa": section.effective_modulus_gpa,
        "hardness_gpa": section.hardness_gpa,
        "curve": measured.curve,
        "map": {
            "nominal_pressure_mpa": measured.map_pressure_mpa,
            "max_pressure_mpa": measured.map_max_pressure_mpa,
        },
        "figures": names,
        "warnings": warnings,
    });
    if let Some(m) = &section.model {
        doc["model"] = serde_json::to_value(m)?;
    }
    let path = out.join("contact.json");
    crate::atomic::write_json_atomically(&path, &doc).map_err(io(&path))?;
    Ok(figures)
}

/// The load–area curve and the pressure map of the measured grid.
fn write_figures(
    out: &Path,
    section: &ContactSection,
    origin_mm: (f64, f64),
    measured: &ContactSurface,
    described: &str,
) -> Result<Vec<PathBuf>, ReportError> {
    let against = against(section);
    let points: Vec<LoadAreaPoint> = measured
        .curve
        .iter()
        .map(|p| LoadAreaPoint {
            nominal_pressure_mpa: p.nominal_pressure_mpa,
            area_pct: 100.0 * p.area_fraction,
            resolved: p.resolved,
        })
        .collect();
    let plot_error = metrology(format!("{described}: the contact's figures"));
    let load_area = plot_load_area(
        out,
        &points,
        "Load–area curve",
        &against,
        &format!("{described}; heights levelled by their least-squares plane"),
    )
    .map_err(&plot_error)?;
    let pressure_map = HeightMap {
        heights_um: &measured.map_pressure_field_mpa,
        rows: measured.rows,
        cols: measured.cols,
        pitch_x_mm: measured.pitch_x_mm,
        pitch_y_mm: measured.pitch_y_mm,
    };
    let pressure = plot_map(
        out,
        &pressure_map,
        origin_mm,
        &MapValues {
            stem: "pressure",
            name: "pressures",
            unit: "MPa",
            bar: "contact pressure (MPa)",
        },
        &format!(
            "Contact pressure at {} MPa nominal (0: no contact)",
            measured.map_pressure_mpa
        ),
        &format!("{described}; {against}"),
    )
    .map_err(&plot_error)?;
    Ok([load_area, pressure].concat())
}

/// "specimen (E 210 GPa, ν 0.3) against a rigid flat: E* 230.8 GPa, elastic".
pub fn against(section: &ContactSection) -> String {
    let s = section.specimen;
    let counter = match section.counter_body {
        None => "a rigid flat".to_string(),
        Some(c) => format!("an elastic flat (E {} GPa, ν {})", c.young_gpa, c.poisson),
    };
    let law = match section.hardness_gpa {
        None => "elastic".to_string(),
        Some(h) => format!("elastic–perfectly plastic at hardness {h} GPa"),
    };
    format!(
        "specimen (E {} GPa, ν {}) against {counter}: E* {} GPa, {law}",
        s.young_gpa,
        s.poisson,
        crate::numfmt::sig(section.effective_modulus_gpa, 4)
    )
}
