//! The bearing area curve from a fitted NURBS model of a known surface, against its closed form.

use std::f64::consts::PI;
use surfscan::fit::{fit_grid, FitOptions};
use surfscan::metrology::model::{model_bearing_curves, ModelBacOptions};

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
    let bac = model_bearing_curves(&fit.surface, &options).unwrap();
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
