//! Independent check of the contact solver against ContactMechanics (the solver behind
//! contact.engineering, `tests/python/contact_reference.py`): the same grids, pitches,
//! modulus, hardness and nominal pressures, solved by both; the real contact area fraction,
//! the fraction flowing at the hardness and the mean gap must agree. Both solve the same
//! discrete problem (pixel-wise constant pressure, Love's influence coefficients,
//! non-periodic by zero padding), so the tolerances are tight: area and plastic fraction
//! within 0.1 % of the grid's points (absolute 1e-3), mean gap within 0.1 %.
//!
//! Grids, small enough for a debug build in CI (the whole check takes well under a minute):
//! a synthetic self-affine surface (SurfaceTopography's Fourier synthesis, Hurst 0.8, fixed
//! seed; 64 × 64 at 1 µm × 4 µm), the first 16 lines × 512 points of the demo's grid (the
//! bundled Mitutoyo R profile's windows, 1.5 µm × 10 µm) and the first 16 lines × 256 points
//! of sur-2 (3.484 µm × 10.452 µm); each elastic at two loads and perfectly plastic at one
//! whose hardness makes part of the contact flow. Both sides are solved in the test; nothing
//! is precomputed. Fails (does not skip) when python3, SurfaceTopography or ContactMechanics
//! is missing.
use super::common::{json_from, reference_script};
use std::path::Path;
use surfscan::contact::{contact_curve, Body, ContactGrid, ContactOptions};

struct Case {
    name: &'static str,
    csv: std::path::PathBuf,
    dx_um: f64,
    dy_um: f64,
    specimen: Body,
    hardness_gpa: Option<f64>,
    pressures_mpa: Vec<f64>,
}

fn read_grid(path: &Path) -> (Vec<f64>, usize, usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .collect();
    let cols = rows[0].len();
    assert!(rows.iter().all(|r| r.len() == cols));
    (rows.concat(), rows.len(), cols)
}

/// Writes rows `rows` × columns `cols` of a grid as CSV (µm, one row per line).
fn write_window(path: &Path, lines: &[Vec<f64>], rows: usize, cols: usize) {
    assert!(lines.len() >= rows && lines.iter().all(|l| l.len() >= cols));
    let text: Vec<String> = lines[..rows]
        .iter()
        .map(|l| {
            l[..cols]
                .iter()
                .map(|z| format!("{z}"))
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect();
    std::fs::write(path, text.join("\n")).unwrap();
}

/// The first 16 lines × 512 points of the demo's grid (the bundled Mitutoyo R profile's
/// windows, 1.5 µm along x, 10 µm between lines).
fn write_demo_window(path: &Path) {
    let set = surfscan_sim::ProfileSet::bundled().unwrap();
    let lines: Vec<Vec<f64>> = set
        .profiles()
        .iter()
        .map(|p| {
            assert!((p.pitch_x_mm - 0.0015).abs() < 1e-12);
            p.z_um.clone()
        })
        .collect();
    write_window(path, &lines, 16, 512);
}

/// The first 16 lines × 256 points of sur-2.
fn write_sur2_window(path: &Path) {
    let (h, rows, cols) =
        read_grid(&Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sur-2.grid.csv"));
    let lines: Vec<Vec<f64>> = h.chunks(cols).map(|c| c.to_vec()).collect();
    assert_eq!(lines.len(), rows);
    write_window(path, &lines, 16, 256);
}

#[test]
fn contact_agrees_with_contactmechanics_elastic_and_plastic() {
    let dir = tempfile::tempdir().unwrap();
    let selfaffine = dir.path().join("selfaffine.csv");
    let out = reference_script("contact_reference.py")
        .arg("selfaffine")
        .arg(&selfaffine)
        .args(["64", "64", "1.0", "4.0", "7"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", crate::common::describe(&out));
    let demo = dir.path().join("demo.csv");
    write_demo_window(&demo);
    let sur2 = dir.path().join("sur2.csv");
    write_sur2_window(&sur2);
    let steel = Body::STEEL;
    let brass = Body::try_new("specimen", 100.0, 0.34).unwrap();
    let case = |name, csv: &Path, (dx_um, dy_um), specimen, hardness_gpa, pressures: &[f64]| Case {
        name,
        csv: csv.to_path_buf(),
        dx_um,
        dy_um,
        specimen,
        hardness_gpa,
        pressures_mpa: pressures.to_vec(),
    };
    let cases = vec![
        case(
            "self-affine elastic",
            &selfaffine,
            (1.0, 4.0),
            steel,
            None,
            &[10.0, 100.0],
        ),
        case(
            "self-affine plastic",
            &selfaffine,
            (1.0, 4.0),
            steel,
            Some(2.0),
            &[100.0],
        ),
        case(
            "demo elastic",
            &demo,
            (1.5, 10.0),
            steel,
            None,
            &[10.0, 100.0],
        ),
        case(
            "demo plastic",
            &demo,
            (1.5, 10.0),
            steel,
            Some(2.0),
            &[30.0],
        ),
        case(
            "sur-2 elastic",
            &sur2,
            (3.484, 10.452),
            brass,
            None,
            &[1.0, 10.0],
        ),
        case(
            "sur-2 plastic",
            &sur2,
            (3.484, 10.452),
            brass,
            Some(0.1),
            &[10.0],
        ),
    ];
    let mut request = Vec::new();
    let mut ours = Vec::new();
    for case in &cases {
        let (h, rows, cols) = read_grid(&case.csv);
        let grid = ContactGrid {
            heights_um: &h,
            rows,
            cols,
            pitch_x_mm: case.dx_um / 1000.0,
            pitch_y_mm: case.dy_um / 1000.0,
        };
        let opts = ContactOptions {
            specimen: case.specimen,
            hardness_gpa: case.hardness_gpa,
            pressures_mpa: case.pressures_mpa.clone(),
            ..ContactOptions::default()
        };
        let t = std::time::Instant::now();
        let curve = contact_curve(&grid, &opts).unwrap_or_else(|e| panic!("{}: {e}", case.name));
        eprintln!(
            "{}: {rows} × {cols}, {:.1} s, iterations {:?}",
            case.name,
            t.elapsed().as_secs_f64(),
            curve
                .points
                .iter()
                .map(|p| p.iterations)
                .collect::<Vec<_>>()
        );
        request.push(serde_json::json!({
            "csv": case.csv,
            "dx_um": case.dx_um,
            "dy_um": case.dy_um,
            "e_star_mpa": curve.effective_modulus_gpa * 1000.0,
            "hardness_mpa": case.hardness_gpa.map(|h| h * 1000.0),
            "pressures_mpa": case.pressures_mpa,
        }));
        ours.push(curve);
    }
    let req = dir.path().join("request.json");
    std::fs::write(&req, serde_json::to_vec(&request).unwrap()).unwrap();
    let t = std::time::Instant::now();
    let theirs = json_from(
        reference_script("contact_reference.py")
            .arg("solve")
            .arg(&req),
    );
    eprintln!("ContactMechanics: {:.1} s", t.elapsed().as_secs_f64());
    let theirs: Vec<Vec<serde_json::Value>> = serde_json::from_value(theirs).unwrap();
    for ((case, curve), reference) in cases.iter().zip(&ours).zip(&theirs) {
        assert_eq!(curve.points.len(), reference.len(), "{}", case.name);
        for (p, r) in curve.points.iter().zip(reference) {
            let what = format!(
                "{} at {} MPa: ours {p:?}, ContactMechanics {r}",
                case.name, p.nominal_pressure_mpa
            );
            assert_eq!(
                p.nominal_pressure_mpa,
                r["nominal_pressure_mpa"].as_f64().unwrap()
            );
            let area = r["area_fraction"].as_f64().unwrap();
            assert!(area > 0.0 && area < 1.0, "{what}");
            assert!((p.area_fraction - area).abs() <= 1e-3, "{what}");
            let flowing = r["plastic_fraction"].as_f64().unwrap();
            assert!((p.plastic_fraction - flowing).abs() <= 1e-3, "{what}");
            if case.hardness_gpa.is_some() {
                assert!(
                    flowing > 0.0,
                    "the cap must act in the plastic case: {what}"
                );
            }
            let gap = r["mean_gap_um"].as_f64().unwrap();
            eprintln!(
                "{} at {} MPa: area {:.5} vs {area:.5}, flowing {:.5} vs {flowing:.5}, \
                 mean gap {:.6} vs {gap:.6} µm",
                case.name,
                p.nominal_pressure_mpa,
                p.area_fraction,
                p.plastic_fraction,
                p.mean_gap_um
            );
            assert!((p.mean_gap_um - gap).abs() <= 1e-3 * gap, "{what}");
        }
    }
}
