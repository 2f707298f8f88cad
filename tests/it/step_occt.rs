//! Independent CAD check of the FE-ready solid: a fit of real data (windows of the bundled
//! sur-2 grid) is written as a STEP block (`write_solid_step`) and read back by OpenCascade
//! and gmsh through `tests/python/check_step_occt.py`: exactly one solid of one closed shell
//! and six faces, valid for `BRepCheck_Analyzer`, whose volume equals the block's computed
//! from the measured heights and the bottom the writer reports (∫(z − z_bottom) dA by the
//! trapezoidal rule) to within 5 % of the roughness part of that volume (∫|z − z̄| dA, what
//! the top face adds to a flat block: an error in the writer — the bottom misplaced, a face
//! reversed, the net transposed — moves the volume by that much or more, while the
//! trapezoidal rule and the degree-5 interpolant, which swings between lines 10 µm apart,
//! differ by a few per cent of it at most), and that
//! gmsh meshes into tetrahedra whose volumes add up to OpenCascade's within 0.1 %. The
//! mirrored case (y decreasing along the surface's v) takes the writer's other orientation.
//! Fails (does not skip) when python3, OCP or gmsh is missing.
use super::common::{json_from, reference_script};
use surfscan::fit::{fit_grid, FitOptions};
use surfscan::nurbs::NurbsSurface;
use surfscan::step::{write_solid_step, StepOptions};

use super::common::{
    sur2_window as window, SUR2_PITCH_X_MM as PITCH_X_MM, SUR2_PITCH_Y_MM as PITCH_Y_MM,
};

fn options(depth_mm: f64, heights_um: &[f64]) -> StepOptions {
    StepOptions {
        lowest_data_z_mm: Some(heights_um.iter().cloned().fold(f64::MAX, f64::min) / 1000.0),
        depth_mm,
        file_name: "solid.step".into(),
        timestamp: "2024-01-01T00:00:00".into(),
        product_name: "sur-2 window".into(),
        description: "FE solid of a sur-2 window".into(),
    }
}

/// Runs the check and asserts everything but the volume's reference (returned).
fn check(
    surface: &NurbsSurface,
    heights_um: &[f64],
    cols: usize,
    y_mm: &[f64],
    depth: f64,
    mesh: bool,
) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let step = dir.path().join("solid.step");
    let mut bytes = Vec::new();
    let stats = write_solid_step(&mut bytes, surface, &options(depth, heights_um)).unwrap();
    std::fs::write(&step, &bytes).unwrap();
    assert_eq!(stats.bytes as usize, bytes.len());
    let grid = dir.path().join("grid.csv");
    let text: Vec<String> = heights_um
        .chunks(cols)
        .map(|r| {
            r.iter()
                .map(|v| format!("{v}"))
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect();
    std::fs::write(&grid, text.join("\n")).unwrap();
    let r = json_from(
        reference_script("check_step_occt.py")
            .arg(&step)
            .arg(&grid)
            .arg(PITCH_X_MM.to_string())
            .arg(serde_json::to_string(y_mm).unwrap())
            .arg(stats.bottom_z_mm.to_string())
            .arg(if mesh { "1" } else { "0" }),
    );
    assert_eq!(r["solids"], 1, "{r}");
    assert_eq!(r["shells"], 1, "{r}");
    assert_eq!(r["faces"], 6, "{r}");
    assert_eq!(r["valid"], true, "BRepCheck_Analyzer: {r}");
    // The bottom is where the writer put it (OpenCascade's box includes the vertices'
    // tolerance, the file's 1e-7 mm): depth below the surface's lowest point, which is no
    // higher than the lowest measured height (the surface passes through the data).
    let bottom = r["bottom_mm"].as_f64().unwrap();
    assert!(
        (bottom - stats.bottom_z_mm).abs() <= 1.5e-7,
        "{r} vs {stats:?}"
    );
    let lowest_data = heights_um.iter().cloned().fold(f64::MAX, f64::min) / 1000.0;
    assert!(stats.lowest_z_mm <= lowest_data + 1e-12, "{stats:?}");
    // …and not far below it: a degree-5 interpolant rings a little between points.
    assert!((stats.lowest_z_mm - lowest_data).abs() < 1e-3, "{stats:?}");
    // Volume against the measured grid.
    let area = (cols - 1) as f64 * PITCH_X_MM * (y_mm[y_mm.len() - 1] - y_mm[0]).abs();
    let mean_um = heights_um.iter().sum::<f64>() / heights_um.len() as f64;
    let roughness_mm3 = heights_um.iter().map(|z| (z - mean_um).abs()).sum::<f64>()
        / heights_um.len() as f64
        / 1000.0
        * area;
    let volume = r["volume_mm3"].as_f64().unwrap();
    let expected = r["expected_mm3"].as_f64().unwrap();
    eprintln!(
        "volume {volume} mm³, from the data {expected} mm³: differ by {:.2} % of the roughness part",
        100.0 * (volume - expected).abs() / roughness_mm3
    );
    assert!(
        (volume - expected).abs() <= 0.05 * roughness_mm3,
        "volume {volume} vs {expected} (roughness part {roughness_mm3}): {r}"
    );
    // The block alone (depth × area) is most of it: the bottom is really `depth` down.
    assert!(
        volume > depth * area && volume < (depth + 0.01) * area,
        "{r}"
    );
    if mesh {
        let tets = r["tetrahedra"].as_u64().unwrap();
        assert!(tets > 100, "{r}");
        let mesh_volume = r["mesh_volume_mm3"].as_f64().unwrap();
        assert!((mesh_volume - volume).abs() <= 1e-3 * volume, "{r}");
    }
    r
}

#[test]
fn step_solid_of_a_fit_is_valid_has_the_block_volume_and_meshes() {
    let (rows, cols) = (12, 40);
    let heights_um = window(rows, cols);
    let y_mm: Vec<f64> = (0..rows).map(|r| r as f64 * PITCH_Y_MM).collect();
    let fit = fit_grid(PITCH_X_MM, &y_mm, &heights_um, cols, FitOptions::default()).unwrap();
    check(&fit.surface, &heights_um, cols, &y_mm, 0.05, true);
}

#[test]
fn step_solid_of_a_surface_with_y_decreasing_is_valid_too() {
    let (rows, cols) = (8, 30);
    let heights_um = window(rows, cols);
    let y_mm: Vec<f64> = (0..rows).map(|r| r as f64 * PITCH_Y_MM).collect();
    let fit = fit_grid(PITCH_X_MM, &y_mm, &heights_um, cols, FitOptions::default()).unwrap();
    let s = &fit.surface;
    // The same surface with y negated: v now runs towards −y.
    let poles: Vec<[f64; 3]> = (0..s.count_v())
        .flat_map(|j| (0..s.count_u()).map(move |i| (i, j)))
        .map(|(i, j)| {
            let p = s.pole(i, j);
            [p[0], -p[1], p[2]]
        })
        .collect();
    let mirrored = NurbsSurface::try_new(
        s.degree_u(),
        s.degree_v(),
        s.knots_u().to_vec(),
        s.knots_v().to_vec(),
        s.count_u(),
        s.count_v(),
        poles,
    )
    .unwrap();
    let neg_y: Vec<f64> = y_mm.iter().map(|y| -y).collect();
    let m = check(&mirrored, &heights_um, cols, &neg_y, 0.02, false);
    // Mirroring changes no volume: the same block as the unmirrored surface's.
    let u = check(s, &heights_um, cols, &y_mm, 0.02, false);
    let (vm, vu) = (
        m["volume_mm3"].as_f64().unwrap(),
        u["volume_mm3"].as_f64().unwrap(),
    );
    assert!((vm - vu).abs() <= 1e-9 * vu, "mirrored {vm} vs {vu}");
}

#[test]
fn step_solid_of_the_whole_sur2_grid_is_valid() {
    let (rows, cols) = (31, 563);
    let heights_um = window(rows, cols);
    let y_mm: Vec<f64> = (0..rows).map(|r| r as f64 * PITCH_Y_MM).collect();
    let fit = fit_grid(PITCH_X_MM, &y_mm, &heights_um, cols, FitOptions::default()).unwrap();
    check(&fit.surface, &heights_um, cols, &y_mm, 0.1, false);
}
