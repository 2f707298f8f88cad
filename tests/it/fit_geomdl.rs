//! Compares the fitter with an independent implementation of the same algorithm,
//! `geomdl.fitting.interpolate_surface` (P&T A9.4, dense Doolittle LU per line), run through
//! `tests/python/fit_geomdl.py`. Fails (never skips) when python3 or geomdl is missing.

use crate::common::{json_from, reference_script};
use std::io::Write;
use surfscan::fit::{fit_grid, FitOptions};

/// Deterministic rough heights (µm).
fn heights(rows: usize, cols: usize, seed: u64) -> Vec<f64> {
    let mut s = seed;
    let mut out = Vec::new();
    for l in 0..rows {
        for k in 0..cols {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5;
            out.push(2.0 * (0.3 * k as f64 + 0.7 * l as f64).sin() + noise);
        }
    }
    out
}

fn check(rows: usize, cols: usize, pitch_x_mm: f64, y_mm: &[f64], p: usize, q: usize) {
    let h = heights(rows, cols, (rows * 1000 + cols) as u64);
    let ours = fit_grid(pitch_x_mm, y_mm, &h, cols, FitOptions::degrees(p, q)).expect("fit");

    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("grid.csv");
    let mut f = std::fs::File::create(&csv).expect("create csv");
    for (l, row) in h.chunks_exact(cols).enumerate() {
        let cells: Vec<String> = std::iter::once(y_mm[l])
            .chain(row.iter().copied())
            .map(|v| format!("{v:e}"))
            .collect();
        writeln!(f, "{}", cells.join(",")).expect("write csv");
    }
    drop(f);

    let v = json_from(
        reference_script("fit_geomdl.py")
            .arg(&csv)
            .arg(format!("{pitch_x_mm:e}"))
            .arg(p.to_string())
            .arg(q.to_string()),
    );
    let nums = |key: &str| -> Vec<f64> {
        v[key]
            .as_array()
            .unwrap_or_else(|| panic!("missing {key}"))
            .iter()
            .map(|x| x.as_f64().expect("number"))
            .collect()
    };
    let s = &ours.surface;
    for (name, mine, theirs) in [
        ("u", s.knots_u().to_vec(), nums("knots_u")),
        ("v", s.knots_v().to_vec(), nums("knots_v")),
    ] {
        assert_eq!(mine.len(), theirs.len(), "{name} knot count");
        for (i, (a, b)) in mine.iter().zip(&theirs).enumerate() {
            assert!(
                (a - b).abs() <= 1e-9,
                "{rows}x{cols} {name} knot {i}: {a} vs geomdl {b}"
            );
        }
    }
    let ctrl: Vec<Vec<f64>> = v["ctrlpts"]
        .as_array()
        .expect("ctrlpts")
        .iter()
        .map(|p| {
            p.as_array()
                .expect("point")
                .iter()
                .map(|x| x.as_f64().expect("coord"))
                .collect()
        })
        .collect();
    assert_eq!(ctrl.len(), cols * rows);
    // Tolerance: 1e-9 relative to the largest magnitude of each coordinate over the net.
    let mut scale = [0.0f64; 3];
    for p in &ctrl {
        for c in 0..3 {
            scale[c] = scale[c].max(p[c].abs());
        }
    }
    let mut worst = 0.0f64;
    for i in 0..cols {
        for j in 0..rows {
            let mine = s.pole(i, j);
            let theirs = &ctrl[i * rows + j];
            for c in 0..3 {
                let rel = (mine[c] - theirs[c]).abs() / scale[c].max(f64::MIN_POSITIVE);
                worst = worst.max(rel);
                assert!(
                    rel <= 1e-9,
                    "{rows}x{cols} deg {p}/{q}: pole ({i},{j}) coord {c}: {} vs geomdl {}",
                    mine[c],
                    theirs[c]
                );
            }
        }
    }
    eprintln!("{rows}x{cols} deg {p}/{q}: worst relative pole difference {worst:e}");
}

#[test]
fn matches_geomdl_7x12_degree_5() {
    let y: Vec<f64> = (0..7).map(|l| 0.01 * l as f64).collect();
    check(7, 12, 0.0005, &y, 5, 5);
}

#[test]
fn matches_geomdl_8x30_degree_5_uneven_y() {
    let y: Vec<f64> = (0..8)
        .map(|l| 0.01 * l as f64 + 0.002 * (l * l) as f64)
        .collect();
    check(8, 30, 0.001, &y, 5, 5);
}

#[test]
fn matches_geomdl_6x9_degree_3_2() {
    let y: Vec<f64> = (0..6).map(|l| 0.05 * l as f64).collect();
    check(6, 9, 0.01, &y, 3, 2);
}
