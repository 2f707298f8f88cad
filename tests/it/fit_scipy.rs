//! Compares the fitter with an independent banded implementation of the paper's algorithm,
//! `tests/python/fit_scipy_banded.py` (scipy's B-spline basis, LAPACK's banded solver), on
//! grids far beyond what geomdl can fit, through the same grid CSV `surfscan fit` reads. The
//! same script is the reference the `process` benchmark times. Fails (never skips) when the
//! Python environment is missing.

use surfscan::fit::{fit_grid, FitOptions};

/// Deterministic rough heights (µm), four decimals as a profiler exports them.
fn heights(rows: usize, cols: usize) -> Vec<f64> {
    let mut s: u64 = 0x2545_F491_4F6C_DD1D;
    let mut out = Vec::with_capacity(rows * cols);
    for l in 0..rows {
        for k in 0..cols {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5;
            let h = 1.2 * (k as f64 * 0.0123 + l as f64 * 0.3).sin() + 0.6 * noise;
            out.push((h * 1e4).round() / 1e4);
        }
    }
    out
}

/// The JSON `script` (in `tests/python/`) prints for the grid `h` with `--json`.
fn reference_json(
    script: &str,
    h: &[f64],
    cols: usize,
    pitch_x: f64,
    pitch_y: f64,
    p: usize,
    q: usize,
) -> serde_json::Value {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("grid.csv");
    let text: String = h
        .chunks_exact(cols)
        .map(|row| {
            let cells: Vec<String> = row.iter().map(|v| format!("{v}")).collect();
            cells.join(",") + "\n"
        })
        .collect();
    std::fs::write(&csv, text).expect("write csv");
    crate::common::json_from(
        crate::common::reference_script(script)
            .arg(&csv)
            .arg(format!("{pitch_x:e}"))
            .arg(format!("{pitch_y:e}"))
            .arg(p.to_string())
            .arg(q.to_string())
            .arg("--json"),
    )
}

fn check(rows: usize, cols: usize, pitch_x: f64, pitch_y: f64, p: usize, q: usize) {
    let h = heights(rows, cols);
    let y: Vec<f64> = (0..rows).map(|l| l as f64 * pitch_y).collect();
    let ours = fit_grid(pitch_x, &y, &h, cols, FitOptions::degrees(p, q)).expect("fit");
    let v = reference_json("fit_scipy_banded.py", &h, cols, pitch_x, pitch_y, p, q);
    let nums = |value: &serde_json::Value| -> Vec<f64> {
        value
            .as_array()
            .expect("array")
            .iter()
            .map(|x| x.as_f64().expect("number"))
            .collect()
    };
    let s = &ours.surface;
    for (name, mine, theirs) in [
        ("u knots", s.knots_u().to_vec(), nums(&v["knots_u"])),
        ("v knots", s.knots_v().to_vec(), nums(&v["knots_v"])),
    ] {
        assert_eq!(mine.len(), theirs.len(), "{name}");
        for (i, (a, b)) in mine.iter().zip(&theirs).enumerate() {
            assert!(
                (a - b).abs() <= 1e-12,
                "{rows}x{cols} {name} {i}: {a} vs {b}"
            );
        }
    }
    let (x, yv) = (nums(&v["x"]), nums(&v["y"]));
    let z: Vec<Vec<f64>> = v["z"].as_array().expect("z").iter().map(nums).collect();
    assert_eq!((x.len(), yv.len(), z.len()), (cols, rows, rows));
    // Poles relative to the largest magnitude of their coordinate over the net: the two
    // solvers differ in the order of their operations only (LAPACK pivots, ours does not).
    let scale = |c: usize| {
        (0..rows)
            .flat_map(|j| (0..cols).map(move |i| (i, j)))
            .map(|(i, j)| s.pole(i, j)[c].abs())
            .fold(f64::MIN_POSITIVE, f64::max)
    };
    let (sx, sy, sz) = (scale(0), scale(1), scale(2));
    let mut worst = 0.0f64;
    for j in 0..rows {
        for i in 0..cols {
            let mine = s.pole(i, j);
            for (c, theirs, sc) in [(0, x[i], sx), (1, yv[j], sy), (2, z[j][i], sz)] {
                let rel = (mine[c] - theirs).abs() / sc;
                worst = worst.max(rel);
                assert!(
                    rel <= 1e-11,
                    "{rows}x{cols} deg {p}/{q}: pole ({i},{j}) coord {c}: {} vs reference {theirs}",
                    mine[c]
                );
            }
        }
    }
    eprintln!("{rows}x{cols} deg {p}/{q}: worst relative pole difference {worst:e}");
}

#[test]
fn matches_the_banded_reference_31x2000_degree_5() {
    check(31, 2000, 0.0005, 0.01, 5, 5);
}

#[test]
fn matches_the_banded_reference_12x300_degree_3_2() {
    check(12, 300, 0.001, 0.02, 3, 2);
}

/// The fit against `fit_scipy_banded_xyz.py`, which interpolates the points as 3-vectors
/// (every pole its own x, y and z, as the paper's P(x, y, z)): every coordinate of every pole
/// agrees, so holding x per pole column and y per pole row loses nothing.
fn check_xyz(rows: usize, cols: usize, pitch_x: f64, pitch_y: f64, p: usize, q: usize) {
    let h = heights(rows, cols);
    let y: Vec<f64> = (0..rows).map(|l| l as f64 * pitch_y).collect();
    let options = FitOptions::degrees(p, q);
    let ours = fit_grid(pitch_x, &y, &h, cols, options).expect("fit");
    let v = reference_json("fit_scipy_banded_xyz.py", &h, cols, pitch_x, pitch_y, p, q);
    let grid = |name: &str| -> Vec<Vec<f64>> {
        v[name]
            .as_array()
            .unwrap_or_else(|| panic!("{name}"))
            .iter()
            .map(|row| {
                row.as_array()
                    .expect("row")
                    .iter()
                    .map(|x| x.as_f64().expect("number"))
                    .collect()
            })
            .collect()
    };
    let s = &ours.surface;
    let coords = [grid("x"), grid("y"), grid("z")];
    for c in &coords {
        assert_eq!(c.len(), rows);
        assert!(c.iter().all(|r| r.len() == cols));
    }
    let mut worst = 0.0f64;
    for (c, theirs) in coords.iter().enumerate() {
        let scale = theirs
            .iter()
            .flatten()
            .map(|v| v.abs())
            .fold(f64::MIN_POSITIVE, f64::max);
        for j in 0..rows {
            for i in 0..cols {
                let (mine, theirs) = (s.pole(i, j)[c], theirs[j][i]);
                let rel = (mine - theirs).abs() / scale;
                worst = worst.max(rel);
                assert!(
                    rel <= 1e-11,
                    "{rows}x{cols} deg {p}/{q}: pole ({i},{j}) coord {c}: {mine} vs the xyz reference {theirs}"
                );
            }
        }
    }
    eprintln!("{rows}x{cols} deg {p}/{q}: worst relative pole difference to the xyz fit {worst:e}");
}

#[test]
fn matches_the_full_xyz_reference_31x2000_degree_5() {
    check_xyz(31, 2000, 0.0005, 0.01, 5, 5);
}

#[test]
fn matches_the_full_xyz_reference_12x300_degree_3_2() {
    check_xyz(12, 300, 0.001, 0.02, 3, 2);
}
