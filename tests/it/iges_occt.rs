//! Independent CAD check: a fit of a real 12×40 window of the bundled sur-2 grid is written as
//! IGES (once whole, once forced into patches) and read back by OpenCascade through
//! `tests/python/check_iges_occt.py`, which must find one B-spline face per patch with the
//! right degrees, pole counts and bit-identical knots, that passes through the measured points within 1e-10 mm.
//! An X3P input's surface is found where the file places the data (its CX and CY offsets).
//! Fails (does not skip) when python3 or OCP is missing.
use surfscan::fit::{fit_grid, FitOptions, FitResult};
use surfscan::iges::{parameter_lines_bound, write_iges, IgesOptions};

use super::common::{
    sur2_window as window, SUR2_PITCH_X_MM as PITCH_X_MM, SUR2_PITCH_Y_MM as PITCH_Y_MM,
};

/// Writes `expect` beside `igs` and has OpenCascade check the file against it.
fn occt_check(igs: &std::path::Path, expect: &serde_json::Value) {
    let json = igs.with_extension("expect.json");
    std::fs::write(&json, serde_json::to_vec(expect).unwrap()).unwrap();
    let out = crate::common::reference_script("check_iges_occt.py")
        .arg(igs)
        .arg(&json)
        .output()
        .expect("python3 must be installed for the OpenCascade check");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && stdout.lines().any(|l| l.starts_with("OK:")),
        "OpenCascade check failed ({}):\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The data points Q(k, l) = (x0 + k·pitch_x, y_l, z/1000) as `[u, v, x, y, z]` at the fit's
/// parameters, those of the lines whose v lies in `v0..=v1`.
fn data_points(
    fit: &FitResult,
    heights_um: &[f64],
    y_mm: &[f64],
    x0: f64,
    (v0, v1): (f64, f64),
) -> Vec<[f64; 5]> {
    let cols = fit.params_u.len();
    let mut points = Vec::new();
    for (l, &v) in fit.params_v.iter().enumerate() {
        if v < v0 || v > v1 {
            continue;
        }
        for (k, &u) in fit.params_u.iter().enumerate() {
            let z = heights_um[l * cols + k] / 1000.0;
            points.push([u, v, x0 + k as f64 * PITCH_X_MM, y_mm[l], z]);
        }
    }
    points
}

/// `split`: force patches by limiting an entity to 3/4 of the lines the whole surface needs.
fn check(split: bool, expect_patches_at_least: usize) {
    let (rows, cols) = (12, 40);
    let heights_um = window(rows, cols);
    let y_mm: Vec<f64> = (0..rows).map(|r| r as f64 * PITCH_Y_MM).collect();
    let fit = fit_grid(PITCH_X_MM, &y_mm, &heights_um, cols, FitOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let igs = dir.path().join("sur-2-window.igs");
    let opts = IgesOptions {
        file_name: "sur-2-window.igs".into(),
        start_lines: vec!["sur-2 window 12x40 for the OpenCascade check".into()],
        ..IgesOptions::default()
    };
    // Patches are planned from the bound on their P lines (token counts, no formatting).
    let lines = parameter_lines_bound(&fit.surface);
    let opts = IgesOptions {
        max_parameter_lines_per_entity: if split { lines * 3 / 4 } else { lines },
        ..opts
    };
    let mut bytes = Vec::new();
    let stats = write_iges(&mut bytes, std::slice::from_ref(&fit.surface), &opts).unwrap();
    assert!(stats.patches >= expect_patches_at_least, "{stats:?}");
    std::fs::write(&igs, &bytes).unwrap();
    let patches = surfscan::iges::read_iges(&bytes).unwrap().surfaces;
    // Data points Q(k, l) = (k·pitch_x, l·pitch_y, z/1000) at the fit's parameters, each
    // assigned to the patch whose v range holds it.
    let mut expect_patches = Vec::new();
    for p in &patches {
        let v_range = (p.knots_v()[0], *p.knots_v().last().unwrap());
        let points = data_points(&fit, &heights_um, &y_mm, 0.0, v_range);
        assert!(!points.is_empty());
        expect_patches.push(serde_json::json!({
            "degree_u": 5, "degree_v": 5,
            "poles_u": p.count_u(), "poles_v": p.count_v(),
            "knots_u": p.knots_u(), "knots_v": p.knots_v(),
            "points": points,
        }));
    }
    assert_eq!(patches[0].count_u(), cols);
    let expect = serde_json::json!({
        "faces": stats.patches,
        "patches": expect_patches,
        "tolerance_mm": 1e-10,
    });
    occt_check(&igs, &expect);
}

#[test]
fn opencascade_reads_the_fitted_window_exactly() {
    check(false, 1);
}

#[test]
fn opencascade_reads_split_patches_exactly() {
    check(true, 2);
}

/// A window of sur-2 as an X3P file whose first point is at x = 0.25 mm (CX offset) and whose
/// first line is at the machine's y = −20 mm (CY offset): `surfscan fit` writes the surface
/// there, and OpenCascade finds it through every data point at x = 0.25 + k·pitch,
/// y = −20 + l·pitch (a surface written from x = 0 misses them by 0.25 mm).
#[test]
fn opencascade_finds_an_x3p_inputs_surface_where_it_was_measured() {
    use surfscan::metrology::areal::HeightMap;
    use surfscan::x3p::{read_x3p, to_x3p, X3pMeta};
    let (rows, cols, (x0, y0)) = (12, 40, (0.25, -20.0));
    let map = HeightMap {
        heights_um: &window(rows, cols),
        rows,
        cols,
        pitch_x_mm: PITCH_X_MM,
        pitch_y_mm: PITCH_Y_MM,
    };
    let dir = tempfile::tempdir().unwrap();
    let (x3p, igs) = (dir.path().join("w.x3p"), dir.path().join("w.igs"));
    let file = to_x3p(&map, (x0, y0), &X3pMeta::default()).unwrap();
    std::fs::write(&x3p, file).unwrap();
    let report = dir.path().join("fit.json");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("fit")
        .arg(&x3p)
        .arg("-o")
        .arg(&igs)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", crate::common::describe(&run));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(report["x0_mm"], 0.25);
    // The heights as the file holds them; the fit's parameters depend on differences of x and
    // y alone, so the fit from 0 gives them.
    let read = read_x3p(&std::fs::read(&x3p).unwrap()).unwrap();
    let y_mm: Vec<f64> = (0..rows).map(|r| y0 + r as f64 * PITCH_Y_MM).collect();
    let fit = fit_grid(
        PITCH_X_MM,
        &y_mm,
        &read.heights_um,
        cols,
        FitOptions::default(),
    )
    .unwrap();
    let points = data_points(&fit, &read.heights_um, &y_mm, x0, (f64::MIN, f64::MAX));
    let expect = serde_json::json!({
        "faces": 1,
        "patches": [{"degree_u": 5, "degree_v": 5, "poles_u": cols, "poles_v": rows, "points": points}],
        "tolerance_mm": 1e-10,
    });
    occt_check(&igs, &expect);
}
