//! The contact section (`contact` in report.json): the load–area curve of the measured grid
//! pressed against a rigid or an elastic flat (the two bodies through their composite
//! modulus), and — when asked for — of the
//! model sampled at a chosen y spacing between the lines, with the verdict between lines
//! beside it: a contact computed on a model the data do not support says so.
//!
//! Both surfaces are levelled by their least-squares plane first (a scan's tilt is the
//! fixture's, not the part's) and solved by [`crate::contact::contact_curve`] with the same
//! options. The model is sampled at the data's x pitch on rows `y₀, y₀ + s, …` up to the
//! last line (`s` the chosen spacing), each row's v found by inverting the surface's y(v)
//! between the data lines it lies between.
//!
//! Layer 4 (reporting): depends on [`crate::contact`], [`crate::metrology`] (levelling and
//! sampling the model), [`crate::metrology::holdout`]'s verdict and the report's types.

use super::SectionInput;
use crate::contact::{contact_curve, ContactCurve, ContactGrid, ContactOptions};
use crate::fit::FitResult;
use crate::grid::Grid;
use crate::metrology::areal::{level_plane, HeightMap};
use crate::metrology::bisect;
use crate::metrology::holdout::BetweenLines;
use crate::metrology::model::sample_model_grid;
use crate::nurbs::NurbsSurface;
use crate::report::document::split;
use serde::Serialize;

/// What the contact section is asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactSectionOptions {
    /// The bodies, loads, hardness and solver limits.
    pub contact: ContactOptions,
    /// Also solve the model sampled at this y spacing, mm (`None`: the measured grid only).
    pub model_pitch_y_mm: Option<f64>,
}

impl ContactSectionOptions {
    /// The section of `[contact]` (a station's, a recipe's or a scan's frozen plan).
    pub fn of(settings: &crate::contact::ContactSettings) -> ContactSectionOptions {
        ContactSectionOptions {
            contact: settings.options(),
            model_pitch_y_mm: settings.model_pitch_y_mm,
        }
    }
}

/// One surface's contact, as report.json shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ContactSurface {
    /// Rows × columns solved.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// y pitch, mm.
    pub pitch_y_mm: f64,
    /// The zero-padded grid the convolutions ran on, (rows, columns).
    pub padded: (usize, usize),
    /// The load–area curve, ascending in pressure.
    pub curve: Vec<crate::contact::CurvePoint>,
    /// The load of the pressure map, MPa, and its largest pressure.
    pub map_pressure_mpa: f64,
    /// The largest pixel pressure at the map load, MPa.
    pub map_max_pressure_mpa: f64,
    /// The pressure of each point at the map load, MPa, row-major (for the map's figure).
    #[serde(skip)]
    pub map_pressure_field_mpa: Vec<f64>,
}

impl ContactSurface {
    /// The contact of `grid` (its size and pitches), as solved.
    pub fn of(curve: ContactCurve, grid: &HeightMap<'_>) -> ContactSurface {
        let ContactCurve {
            points,
            map,
            padded,
            ..
        } = curve;
        ContactSurface {
            rows: grid.rows,
            cols: grid.cols,
            pitch_x_mm: grid.pitch_x_mm,
            pitch_y_mm: grid.pitch_y_mm,
            padded,
            curve: points,
            map_pressure_mpa: map.nominal_pressure_mpa,
            map_max_pressure_mpa: map.pressure_mpa.iter().cloned().fold(0.0, f64::max),
            map_pressure_field_mpa: map.pressure_mpa,
        }
    }
}

/// The model's contact with the verdict between lines beside it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelContact {
    /// Whether the data support the model between lines (the hold-out verdict); `false`
    /// also when it could not be judged.
    pub supported: bool,
    /// The verdict between lines in words, or why there is none.
    pub verdict: String,
    /// The contact of the sampled model, or why it could not be computed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<ContactSurface>,
    /// Why `contact` is missing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The section's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ContactSection {
    /// The measured body.
    pub specimen: crate::contact::Body,
    /// The counter-body (`None`: a rigid flat).
    pub counter_body: Option<crate::contact::Body>,
    /// E* used, GPa.
    pub effective_modulus_gpa: f64,
    /// The specimen's hardness, GPa (None: elastic).
    pub hardness_gpa: Option<f64>,
    /// The measured grid's contact, or why it could not be computed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured: Option<ContactSurface>,
    /// Why `measured` is missing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured_error: Option<String>,
    /// The model sampled between the lines, when asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelContact>,
}

impl ContactSection {
    /// What the operator should know: a model contact the data do not support, loads the
    /// grid does not resolve.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        let model = self.model.as_ref();
        if let Some(m) = model.filter(|m| m.contact.is_some() && !m.supported) {
            w.push(format!(
                "contact.model is computed on a model the data do not support between lines: {}",
                m.verdict
            ));
        }
        for (what, s) in [
            ("measured grid", self.measured.as_ref()),
            ("model", model.and_then(|m| m.contact.as_ref())),
        ] {
            let Some(s) = s else { continue };
            let unresolved: Vec<String> = s
                .curve
                .iter()
                .filter(|p| !p.resolved)
                .map(|p| crate::numfmt::sig(p.nominal_pressure_mpa, 4))
                .collect();
            if !unresolved.is_empty() {
                w.push(format!(
                    "contact of the {what}: the grid does not resolve the contact at {} MPa (most contact points are isolated single points)",
                    unresolved.join(", ")
                ));
            }
        }
        w
    }
}

/// Runs the section on the grid as characterised and, when asked for, on the model (`fit`, or
/// why there is none) sampled at `opts.model_pitch_y_mm`, judged by `between_lines`.
pub fn section(
    input: &SectionInput<'_>,
    opts: &ContactSectionOptions,
    between_lines: Result<&BetweenLines, &String>,
    fit: Result<&FitResult, &str>,
) -> ContactSection {
    let g = input.characterised;
    let e_gpa = crate::contact::effective_modulus_gpa(opts.contact.specimen, opts.contact.counter);
    let measured = solve(HeightMap::of(g, input.pitch_y_mm), &opts.contact);
    let model = opts.model_pitch_y_mm.map(|s| {
        let (supported, verdict) = match between_lines {
            Ok(b) => (b.supported, b.verdict.clone()),
            Err(e) => (
                false,
                format!("the model between lines could not be judged: {e}"),
            ),
        };
        let contact = match fit {
            Ok(fit) => sample_between(fit, g, s).and_then(|(h, rows)| {
                let map = HeightMap {
                    heights_um: &h,
                    rows,
                    ..HeightMap::of(g, s)
                };
                solve(map, &opts.contact)
            }),
            Err(e) => Err(format!("there is no model: {e}")),
        };
        let (contact, error) = split(contact);
        ModelContact {
            supported,
            verdict,
            contact,
            error,
        }
    });
    let (measured, measured_error) = split(measured);
    ContactSection {
        specimen: opts.contact.specimen,
        counter_body: opts.contact.counter,
        effective_modulus_gpa: e_gpa,
        hardness_gpa: opts.contact.hardness_gpa,
        measured,
        measured_error,
        model,
    }
}

/// Levels `map` by its least-squares plane and solves its contact.
fn solve(map: HeightMap<'_>, opts: &ContactOptions) -> Result<ContactSurface, String> {
    let (levelled, _) = level_plane(&map).map_err(|e| e.to_string())?;
    let grid = ContactGrid {
        heights_um: &levelled,
        rows: map.rows,
        cols: map.cols,
        pitch_x_mm: map.pitch_x_mm,
        pitch_y_mm: map.pitch_y_mm,
    };
    let curve = contact_curve(&grid, opts).map_err(|e| e.to_string())?;
    Ok(ContactSurface::of(curve, &map))
}

/// The v of each row `y₀ + k·s` (k = 0, 1, … while ≤ the last line's y): the surface's y(v)
/// inverted by bisection between the parameters of the two data lines the row lies between
/// (the lines' y ascending or descending).
fn rows_v(
    surface: &NurbsSurface,
    params_v: &[f64],
    y_mm: &[f64],
    spacing_mm: f64,
) -> Result<Vec<f64>, String> {
    if !(spacing_mm.is_finite() && spacing_mm > 0.0) {
        return Err(format!(
            "the model's y spacing {spacing_mm} mm is not a positive length"
        ));
    }
    let n = y_mm.len();
    if n < 2 || params_v.len() != n {
        return Err("the model needs at least two lines to be sampled between them".into());
    }
    let sign = if y_mm[n - 1] >= y_mm[0] { 1.0 } else { -1.0 };
    let span = (y_mm[n - 1] - y_mm[0]).abs();
    let rows = (span / spacing_mm + 1e-9).floor() as usize + 1;
    if rows > 100_000 {
        return Err(format!(
            "the model's y spacing {spacing_mm} mm makes {rows} rows over {span} mm; choose a coarser one"
        ));
    }
    let u_mid = {
        let k = surface.knots_u();
        0.5 * (k[0] + k[k.len() - 1])
    };
    let y_at = |v: f64| surface.evaluate(u_mid, v)[1];
    let mut vs = Vec::with_capacity(rows);
    let mut seg = 0;
    for k in 0..rows {
        // Distance along the lines' direction from the first line.
        let d = k as f64 * spacing_mm;
        while seg + 2 < n && sign * (y_mm[seg + 1] - y_mm[0]) < d {
            seg += 1;
        }
        let (a, b) = (params_v[seg], params_v[seg + 1]);
        let target = y_mm[0] + sign * d;
        let (fa, fb) = (y_at(a) - target, y_at(b) - target);
        if fa == 0.0 {
            vs.push(a);
            continue;
        }
        if fb == 0.0 || fa.signum() == fb.signum() {
            // The row is on the segment's end (rounding), or y(v) is not monotone here.
            if fb.abs() <= 1e-9 * spacing_mm.max(1e-6) || fa.abs() <= 1e-9 * spacing_mm.max(1e-6) {
                vs.push(if fb.abs() < fa.abs() { b } else { a });
                continue;
            }
            return Err(format!(
                "the model's y does not pass {target} mm between lines {seg} and {} (y(v) is not monotone there)",
                seg + 1
            ));
        }
        vs.push(bisect(a, b, |m| (y_at(m) - target).signum() == fa.signum()));
    }
    Ok(vs)
}

/// The model sampled at the data's x pitch on rows `spacing_mm` apart; returns the heights
/// (µm, row-major) and the number of rows.
fn sample_between(fit: &FitResult, g: &Grid, spacing_mm: f64) -> Result<(Vec<f64>, usize), String> {
    let vs = rows_v(&fit.surface, &fit.params_v, &g.y_mm, spacing_mm)?;
    let h = sample_model_grid(&fit.surface, &vs, fit.x0_mm, g.pitch_x_mm, g.cols)
        .map_err(|e| format!("sampling the model at a {spacing_mm} mm y spacing: {e}"))?;
    Ok((h, vs.len()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{fit_grid, FitOptions};

    /// A fit of 8 unequally spaced lines (y ascending, then descending): rows at the lines'
    /// own y fall on their parameters, and every row's v gives back its y.
    #[test]
    fn rows_fall_on_the_lines_and_their_y_is_the_chosen_one() {
        let cols = 40;
        for sign in [1.0, -1.0] {
            let y_mm: Vec<f64> = [0.0, 0.01, 0.02, 0.035, 0.045, 0.06, 0.07, 0.08]
                .iter()
                .map(|y| sign * y)
                .collect();
            let h: Vec<f64> = (0..y_mm.len() * cols)
                .map(|i| ((i % cols) as f64 * 0.3).sin() + (i / cols) as f64 * 0.1)
                .collect();
            let fit = fit_grid(0.001, &y_mm, &h, cols, FitOptions::default()).unwrap();
            let vs = rows_v(&fit.surface, &fit.params_v, &y_mm, 0.005).unwrap();
            // 0.08 mm in 0.005 mm steps: 17 rows, every line but 0.035 and 0.045 on one.
            assert_eq!(vs.len(), 17);
            for (k, &v) in vs.iter().enumerate() {
                let y = fit.surface.evaluate(0.5, v)[1];
                assert!((y - sign * 0.005 * k as f64).abs() < 1e-9, "row {k}: y {y}");
            }
            for (line, &y) in y_mm.iter().enumerate() {
                let k = (y.abs() / 0.005).round() as usize;
                if (k as f64 * 0.005 - y.abs()).abs() < 1e-12 {
                    assert!((vs[k] - fit.params_v[line]).abs() < 1e-9, "line {line}");
                }
            }
        }
    }

    #[test]
    fn bad_spacings_are_named() {
        let y_mm = [0.0, 0.01, 0.02, 0.03, 0.04, 0.05];
        let h: Vec<f64> = (0..6 * 20).map(|i| (i as f64 * 0.37).sin()).collect();
        let fit = fit_grid(0.001, &y_mm, &h, 20, FitOptions::default()).unwrap();
        for s in [0.0, -0.01, f64::NAN] {
            let e = rows_v(&fit.surface, &fit.params_v, &y_mm, s).unwrap_err();
            assert!(e.contains("not a positive length"), "{e}");
        }
        let e = rows_v(&fit.surface, &fit.params_v, &y_mm, 1e-8).unwrap_err();
        assert!(e.contains("coarser"), "{e}");
    }
}
