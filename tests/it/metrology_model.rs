//! The bearing area curve from a fitted NURBS model of a known surface, against its closed form.

use std::f64::consts::PI;
use surfscan::fit::{fit_grid, FitOptions};
use surfscan::grid::Grid;
use surfscan::metrology::model::{model_bearing_curves_with, ModelBacOptions};

#[test]
fn model_bac_of_a_sinusoidal_grid_is_arccos() {
    // z = A·sin(2πx/λ + 2πy/λy): every line along x holds 4 whole periods of a sine, so its
    // material ratio at height h (from its mean line) is the fraction of the phase where
    // sin θ ≥ h/A, i.e. (π − 2·asin(h/A)) / 2π = arccos(h/A)/π.
    let (amp_um, lambda_mm, lambda_y_mm) = (1.5, 0.1, 0.37);
    let (cols, rows, pitch_x, pitch_y) = (81usize, 31usize, 0.005, 0.01);
    let y_mm: Vec<f64> = (0..rows).map(|j| j as f64 * pitch_y).collect();
    let mut z = Vec::with_capacity(rows * cols);
    for &y in &y_mm {
        for i in 0..cols {
            let x = i as f64 * pitch_x;
            z.push(amp_um * (2.0 * PI * (x / lambda_mm + y / lambda_y_mm)).sin());
        }
    }
    let fit = fit_grid(pitch_x, &y_mm, &z, cols, FitOptions::default()).unwrap();
    let options = ModelBacOptions {
        samples_per_curve: Some(8000),
        ..ModelBacOptions::default()
    };
    let bac = model_bearing_curves_with(&fit.surface, &options, None).unwrap();
    assert_eq!(bac.len(), 31);
    let mut worst: f64 = 0.0;
    for c in &bac {
        assert_eq!(c.curve.points.len(), 101);
        assert!(
            c.curve.mean_line_um.abs() < 0.01,
            "mean {}",
            c.curve.mean_line_um
        );
        // The model's extremes sit within a hair of ±A (dense sampling finds them).
        assert!((c.curve.points[0][0] - amp_um).abs() < 0.01 * amp_um);
        for [h, mr] in &c.curve.points {
            let expected = (h / amp_um).clamp(-1.0, 1.0).acos() / PI * 100.0;
            worst = worst.max((mr - expected).abs());
            assert!(
                (mr - expected).abs() < 0.05,
                "y {} h {h}: {mr} vs {expected}",
                c.y_mm
            );
        }
    }
    assert!(
        worst > 0.0,
        "the model is not the sine exactly; a zero error means no model was sampled"
    );
    // The curves are at the lines' y (equally spaced v on a uniform grid ⇒ uniform y).
    assert!(bac[0].y_mm.abs() < 1e-9);
    assert!((bac[30].y_mm - 0.30).abs() < 1e-9);
}

#[test]
fn model_sampled_on_the_real_31_line_grid_reproduces_data_and_keeps_sa_sq() {
    use surfscan::metrology::areal::{areal_params, HeightMap};
    use surfscan::metrology::model::sample_model_grid;
    let dir = match std::env::var_os("SURFSCAN_REAL_DATA") {
        Some(d) => std::path::PathBuf::from(d),
        None => std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/real"),
    };
    let path = dir.join("sur-2.31profiles.y_mm_x_mm_z_um.csv");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e}; set SURFSCAN_REAL_DATA", path.display()));
    let z: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(3).unwrap().trim().parse::<f64>().unwrap())
        .collect();
    let (rows, cols, px, py) = (31usize, 563usize, 0.003484, 0.010452);
    assert_eq!(z.len(), rows * cols);
    let y: Vec<f64> = (0..rows).map(|j| j as f64 * py).collect();
    let fit = fit_grid(px, &y, &z, cols, FitOptions::default()).unwrap();
    let model =
        sample_model_grid(&fit.surface, &fit.params_v, 0.0, px / 2.0, 2 * cols - 1).unwrap();
    // An interpolant passes through the data: every 2nd model column is a data point. The
    // fitter's x(u) is not exactly linear, so the inversion must land on the data x.
    for r in 0..rows {
        for c in 0..cols {
            let m = model[r * (2 * cols - 1) + 2 * c];
            let d = z[r * cols + c];
            assert!(
                (m - d).abs() < 1e-6,
                "line {r} point {c}: model {m} vs data {d}"
            );
        }
    }
    let raw = areal_params(&HeightMap {
        heights_um: &z,
        rows,
        cols,
        pitch_x_mm: px,
        pitch_y_mm: py,
    })
    .unwrap();
    let dense = areal_params(&HeightMap {
        heights_um: &model,
        rows,
        cols: 2 * cols - 1,
        pitch_x_mm: px / 2.0,
        pitch_y_mm: py,
    })
    .unwrap();
    // Sa/Sq are dominated by the many smooth points and move little (measured: −0.15 %, −0.4 %);
    // the model rings around the deep pit, so Sp/Sv/Sz differ and are only reported.
    assert!(
        (dense.sa_um - raw.sa_um).abs() < 0.02 * raw.sa_um,
        "Sa {} vs {}",
        dense.sa_um,
        raw.sa_um
    );
    assert!(
        (dense.sq_um - raw.sq_um).abs() < 0.02 * raw.sq_um,
        "Sq {} vs {}",
        dense.sq_um,
        raw.sq_um
    );
}

#[test]
fn holdout_predicts_a_smooth_surface_and_misses_a_held_out_spike() {
    use surfscan::fit::VMethod;
    use surfscan::metrology::holdout::holdout_with;
    // z = A·cos(2πx/λx)·cos(2πy/λy), 40 points per λx and 16 lines per λy: a degree 5 model of
    // the kept half predicts the held-out half to a small fraction of A.
    let (rows, cols, px, py, amp) = (21usize, 161usize, 0.001, 0.01, 1.0);
    let mut z: Vec<f64> = (0..rows * cols)
        .map(|k| {
            let (r, c) = (k / cols, k % cols);
            amp * (2.0 * PI * c as f64 / 40.0).cos() * (2.0 * PI * r as f64 / 16.0).cos()
        })
        .collect();
    let y: Vec<f64> = (0..rows).map(|r| r as f64 * py).collect();
    let h = holdout_with(
        &Grid::new(z.clone(), cols, px, y.clone()),
        FitOptions::default(),
        VMethod::Interpolate,
    )
    .unwrap();
    assert_eq!(h.points_left_out.len(), rows);
    assert!(h.points_left_out.iter().all(|l| l.points == 80));
    // Odd rows between the first and last kept (even) rows: 1, 3, …, 19.
    assert_eq!(h.lines_left_out.len(), 10);
    assert_eq!(h.lines_left_out[0].index, 1);
    for l in h.points_left_out.iter().chain(&h.lines_left_out) {
        assert!(
            l.max_abs_um < 0.02 * amp,
            "line {}: {}",
            l.index,
            l.max_abs_um
        );
        assert!(l.rms_um <= l.max_abs_um);
    }
    // A spike at a held-out point (line 3, column 81) is invisible to the refit: the difference
    // there is about the spike's height, and only line 3 sees it.
    z[3 * cols + 81] += 5.0;
    let h = holdout_with(
        &Grid::new(z.clone(), cols, px, y.clone()),
        FitOptions::default(),
        VMethod::Interpolate,
    )
    .unwrap();
    assert!(
        (h.points_left_out[3].max_abs_um - 5.0).abs() < 0.1,
        "{}",
        h.points_left_out[3].max_abs_um
    );
    assert!(h.points_left_out[4].max_abs_um < 0.02 * amp);
}
