//! The ISO 25178-2 functional and spatial parameters against independent implementations
//! (`tests/python/areal_reference.py`: numpy from the definitions, surfalize, and
//! SurfaceTopography), on the two real grids: sur-2's 31 profiles and the demo's grid
//! (`tests/data/demo.grid.csv`). Tolerances are stated per comparison; where a reference
//! follows another convention the bound covers that difference and the doc names it
//! (`docs/metrology.md`, "Areal functional and spatial parameters").
//!
//! Requires `bash .ci/run` (tests/python/requirements.txt in .venv/).

use crate::common::{json_from, reference_script};
use serde_json::Value;
use std::path::{Path, PathBuf};
use surfscan::metrology::areal::{level_plane, HeightMap, Plane};
use surfscan::metrology::functional::areal_functional;
use surfscan::metrology::spatial::{autocorrelation, psd_along_x, psd_along_y, spatial_params};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn read_grid(path: &Path) -> (Vec<f64>, usize, usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut z = Vec::new();
    let mut rows = 0;
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        z.extend(line.split(',').map(|v| v.trim().parse::<f64>().unwrap()));
        rows += 1;
    }
    let cols = z.len() / rows;
    (z, rows, cols)
}

fn reference(path: &Path, px: f64, py: f64) -> Value {
    json_from(
        reference_script("areal_reference.py")
            .arg(path)
            .arg(px.to_string())
            .arg(py.to_string()),
    )
}

/// report.json of `surfscan analyze` of the grid at `path` with its pitches.
fn analyze_report(path: &Path, px: f64, py: f64) -> Value {
    let out = tempfile::tempdir().unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(path)
        .args([
            "--pitch-x",
            &px.to_string(),
            "--pitch-y",
            &py.to_string(),
            "--out",
        ])
        .arg(out.path())
        .output()
        .unwrap();
    assert!(
        o.status.code().is_some_and(|c| c == 0 || c == 3),
        "analyze {}: {}",
        path.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(out.path().join("report.json")).unwrap()).unwrap()
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("reference lacks {key}: {v}"))
}

/// |got − want| ≤ rel·|want| + abs.
fn close(what: &str, got: f64, want: f64, rel: f64, abs: f64) {
    assert!(
        (got - want).abs() <= rel * want.abs() + abs,
        "{what}: ours {got} vs reference {want} (allowed {rel} relative + {abs})"
    );
}

/// What each grid is compared with, and how closely.
struct Bounds {
    /// Sk, Spk, Svk against surfalize's least-squares line (relative).
    sk_family_surfalize: f64,
    /// Smr1, Smr2 against surfalize, percentage points.
    smr_surfalize_pts: f64,
    /// Sal and Str against surfalize (relative).
    sal_surfalize: f64,
}

fn check(name: &str, px: f64, py: f64, bounds: Bounds) {
    let path = data(name);
    let (z, rows, cols) = read_grid(&path);
    let grid = HeightMap {
        heights_um: &z,
        rows,
        cols,
        pitch_x_mm: px,
        pitch_y_mm: py,
    };
    let r = reference(&path, px, py);
    let f = areal_functional(level_plane(&grid).unwrap().0).unwrap();
    let s = spatial_params(grid.heights_um.into(), &grid, &Plane::of(&grid).unwrap());
    let ours = [
        ("Sk", f.sk_um),
        ("Spk", f.spk_um),
        ("Svk", f.svk_um),
        ("Smr1", f.smr1_pct),
        ("Smr2", f.smr2_pct),
        ("Vmp", f.vmp_ml_m2),
        ("Vmc", f.vmc_ml_m2),
        ("Vvc", f.vvc_ml_m2),
        ("Vvv", f.vvv_ml_m2),
    ];
    // Our construction re-implemented in numpy: the same numbers but for rounding (the A1/A2
    // trapezoids on 2000 steps are the same steps in both).
    let np = &r["numpy_ours"];
    for (k, v) in ours {
        close(
            &format!("{name} {k} (numpy, same construction)"),
            v,
            num(np, k),
            1e-9,
            1e-12,
        );
    }
    // The report of that grid (`surfscan analyze`) carries the same numbers under their ISO
    // names with the units in the key, as the references have them.
    let report = analyze_report(&path, px, py);
    let functional = &report["surface_grid"]["functional"];
    for (k, unit) in [
        ("Sk", "_um"),
        ("Spk", "_um"),
        ("Svk", "_um"),
        ("Smr1", "_pct"),
        ("Smr2", "_pct"),
        ("Vmp", "_ml_per_m2"),
        ("Vmc", "_ml_per_m2"),
        ("Vvc", "_ml_per_m2"),
        ("Vvv", "_ml_per_m2"),
    ] {
        close(
            &format!("{name} report.json surface_grid.functional.{k}{unit} (numpy)"),
            num(functional, &format!("{k}{unit}")),
            num(np, k),
            1e-9,
            1e-12,
        );
    }
    let spatial = &report["surface_grid"]["spatial"];
    close(
        &format!("{name} report.json Std_deg (surfalize)"),
        num(spatial, "Std_deg"),
        num(&r["surfalize"], "Std"),
        0.0,
        1e-9,
    );
    for (key, k) in [("Sal_um", "Sal"), ("Str", "Str")] {
        close(
            &format!("{name} report.json {key} (surfalize)"),
            num(spatial, key),
            num(&r["surfalize"], k),
            bounds.sal_surfalize,
            0.0,
        );
    }
    // surfalize: the same material ratio curve but its equivalent line is a least-squares fit
    // inside the 40 % window, and its volumes take the nearest of 10000 classes.
    let sz = &r["surfalize"];
    for k in ["Sk", "Spk", "Svk"] {
        let v = ours.iter().find(|(n, _)| *n == k).unwrap().1;
        close(
            &format!("{name} {k} (surfalize, least-squares line)"),
            v,
            num(sz, k),
            bounds.sk_family_surfalize,
            0.0,
        );
    }
    close(
        &format!("{name} Smr1 (surfalize)"),
        f.smr1_pct,
        num(sz, "Smr1"),
        0.0,
        bounds.smr_surfalize_pts,
    );
    close(
        &format!("{name} Smr2 (surfalize)"),
        f.smr2_pct,
        num(sz, "Smr2"),
        0.0,
        bounds.smr_surfalize_pts,
    );
    for (k, v) in [
        ("Vmp", f.vmp_ml_m2),
        ("Vmc", f.vmc_ml_m2),
        ("Vvc", f.vvc_ml_m2),
        ("Vvv", f.vvv_ml_m2),
    ] {
        close(
            &format!("{name} {k} (surfalize, nearest of 10000 classes)"),
            v,
            num(sz, k),
            5e-3,
            0.0,
        );
    }

    // The ACF: the same unbiased estimator in numpy and in surfalize, to rounding.
    let acf = autocorrelation(&grid).unwrap();
    for src in ["numpy_acf_lags", "surfalize_acf_lags"] {
        for lag in r[src].as_array().unwrap() {
            let (ky, kx, want) = (
                lag[0].as_i64().unwrap(),
                lag[1].as_i64().unwrap(),
                lag[2].as_f64().unwrap(),
            );
            let got = acf.at(ky as isize, kx as isize).unwrap();
            close(
                &format!("{name} ACF({ky},{kx}) ({src})"),
                got,
                want,
                0.0,
                1e-9,
            );
        }
    }
    // SurfaceTopography's ACF along x (height-difference form, turned into height-height).
    let st_acf: Vec<f64> = r["st_acf_x"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    // Our 2-D ACF at zero y lag averages every pair of every line: the profile ACF averaged
    // over the lines, which is SurfaceTopography's.
    for (k, want) in st_acf.iter().enumerate().take(cols - 1) {
        close(
            &format!("{name} ACF along x at lag {k} (SurfaceTopography)"),
            acf.at(0, k as isize).unwrap(),
            *want,
            0.0,
            1e-9,
        );
    }

    // Sal and Str: surfalize measures along the rays to the edge pixels of the region above
    // s with cubic interpolation, we along rays every 0.5° with bilinear interpolation.
    match (s.sal_um, sz["Sal"].as_f64()) {
        (Some(a), Some(b)) => close(
            &format!("{name} Sal (surfalize)"),
            a,
            b,
            bounds.sal_surfalize,
            0.0,
        ),
        (a, b) => panic!("{name} Sal: ours {a:?}, surfalize {b:?}"),
    }
    match (s.str_ratio, sz["Str"].as_f64()) {
        (Some(a), Some(b)) => close(
            &format!("{name} Str (surfalize)"),
            a,
            b,
            bounds.sal_surfalize,
            0.0,
        ),
        (a, b) => panic!("{name} Str: ours {a:?}, surfalize {b:?}"),
    }
    // Std: the same angular amplitude spectrum and bins.
    close(
        &format!("{name} Std (surfalize)"),
        s.std_deg,
        num(sz, "Std"),
        0.0,
        1e-9,
    );

    // PSD along x and y: SurfaceTopography's convention, to rounding.
    for (dir, psd) in [
        ("x", psd_along_x(&grid, &Plane::of(&grid).unwrap())),
        ("y", psd_along_y(&grid, &Plane::of(&grid).unwrap())),
    ] {
        let st = &r[format!("st_psd_{dir}")];
        let q: Vec<f64> = st["q"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let c: Vec<f64> = st["C"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(q.len(), psd.q_per_um.len(), "{name} PSD {dir} length");
        for k in 0..q.len() {
            close(
                &format!("{name} PSD {dir} q[{k}]"),
                psd.q_per_um[k],
                q[k],
                1e-12,
                0.0,
            );
            close(
                &format!("{name} PSD {dir} C[{k}]"),
                psd.c_um3[k],
                c[k],
                1e-9,
                1e-18,
            );
        }
    }
}

#[test]
fn sur_2_functional_and_spatial_parameters_agree_with_the_references() {
    check(
        "sur-2.grid.csv",
        0.003484,
        0.010452,
        // One pit holds the dales: the least-squares line through the window tilts towards
        // it (surfalize: Svk 16 % lower, Smr2 3.7 points lower).
        Bounds {
            sk_family_surfalize: 0.17,
            smr_surfalize_pts: 4.0,
            sal_surfalize: 0.04,
        },
    );
}

#[test]
fn the_demos_grid_functional_and_spatial_parameters_agree_with_the_references() {
    check(
        "demo.grid.csv",
        0.0015,
        0.01,
        // surfalize's least-squares line: Sk 7.8 % lower, Smr1 3.2 points higher.
        Bounds {
            sk_family_surfalize: 0.09,
            smr_surfalize_pts: 3.5,
            sal_surfalize: 0.04,
        },
    );
}

/// Sal, Str and Std as the full complex transform of the padded grid gave them (the whole
/// two-sided ACF, 16 bytes a padded lag; `surfscan analyze` at fceb3a6, report.json's
/// `surface_grid.spatial`), before the half-plane real-to-complex autocorrelation: the change
/// of transform may move them by rounding only.
#[test]
fn sal_str_std_are_those_of_the_full_complex_transform() {
    // (grid, px, py, Sal µm, Str, Std °, fastest °, slowest °, slowest decay µm)
    let pinned = [
        (
            "sur-2.grid.csv",
            0.003484,
            0.010452,
            7.495274668604162,
            0.7864294670929525,
            0.0,
            13.0,
            90.0,
            9.530765290764789,
        ),
        (
            "demo.grid.csv",
            0.0015,
            0.01,
            5.612738093495181,
            0.064942667330446,
            0.0,
            89.5,
            0.0,
            86.42604814699155,
        ),
    ];
    for (name, px, py, sal, str_ratio, std, fastest, slowest, slowest_um) in pinned {
        let (z, rows, cols) = read_grid(&data(name));
        let grid = HeightMap {
            heights_um: &z,
            rows,
            cols,
            pitch_x_mm: px,
            pitch_y_mm: py,
        };
        let s = spatial_params(grid.heights_um.into(), &grid, &Plane::of(&grid).unwrap());
        close(&format!("{name} Sal"), s.sal_um.unwrap(), sal, 1e-9, 0.0);
        close(
            &format!("{name} Str"),
            s.str_ratio.unwrap(),
            str_ratio,
            1e-9,
            0.0,
        );
        close(
            &format!("{name} slowest decay"),
            s.slowest_decay_um.unwrap(),
            slowest_um,
            1e-9,
            0.0,
        );
        assert_eq!(s.std_deg, std, "{name} Std");
        assert_eq!(s.fastest_decay_direction_deg, Some(fastest), "{name}");
        assert_eq!(s.slowest_decay_direction_deg, Some(slowest), "{name}");
    }
}
