//! Areal parameters of a tilted cosine grid against closed forms.

use std::f64::consts::PI;
use surfscan::metrology::areal::{areal_params, level_plane, smr_curve, HeightMap};
use surfscan::metrology::MetrologyError;

/// z = 2 + 0.5·x_mm − 0.3·y_mm + A·cos(2πx/λ): 200 points per period, 4 periods plus the
/// closing point, so cos is symmetric about the centre and uncorrelated with x and y: the
/// least-squares plane is the tilt plus the mean of the cosine samples, A/(NM + 1) (the closing
/// point's cos = 1 is not cancelled).
fn grid() -> (Vec<f64>, usize, usize, f64, f64, f64, usize) {
    let (amp, m, periods, rows) = (0.8, 200usize, 4usize, 7usize);
    let cols = m * periods + 1;
    let (px, py) = (0.0005, 0.01);
    let mut z = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let (x, y) = (c as f64 * px, r as f64 * py);
            z.push(2.0 + 0.5 * x - 0.3 * y + amp * (2.0 * PI * c as f64 / m as f64).cos());
        }
    }
    (z, rows, cols, px, py, amp, m)
}

#[test]
fn tilted_cosine_grid_matches_closed_forms() {
    let (z, rows, cols, px, py, amp, m) = grid();
    let g = HeightMap {
        heights_um: &z,
        rows,
        cols,
        pitch_x_mm: px,
        pitch_y_mm: py,
    };
    let p = areal_params(&g).unwrap();
    let nm = (cols - 1) as f64;
    let e = amp / (nm + 1.0);
    assert!((p.plane_um[0] - 2.0 - e).abs() < 1e-9, "{:?}", p.plane_um);
    assert!((p.plane_um[1] - 0.5).abs() < 1e-9);
    assert!((p.plane_um[2] + 0.3).abs() < 1e-9);
    // Levelled z = A·cos − e. Σ cos² over NM + 1 points (NM = 800) is NM/2 + 1 (the closing
    // point adds cos² = 1), so mean z² = A²·(NM/2 + 1)/(NM + 1) − e².
    let sq = (amp * amp * (nm / 2.0 + 1.0) / (nm + 1.0) - e * e).sqrt();
    assert!((p.sq_um - sq).abs() < 1e-9, "Sq {} vs {sq}", p.sq_um);
    assert!((p.sp_um - (amp - e)).abs() < 1e-9 && (p.sv_um - (amp + e)).abs() < 1e-9);
    assert!((p.sz_um - 2.0 * amp).abs() < 1e-9);
    assert!(p.ssk.abs() < 0.01);
    // Forward differences of A·cos(ki): 2A·sin(k/2)·sin(k(i+½)); mean square over whole periods
    // 2A²·sin²(k/2), divided by dx²; no y slope after levelling.
    let k = 2.0 * PI / m as f64;
    let dx = px * 1000.0;
    let sdq = (2.0f64).sqrt() * amp * (k / 2.0).sin() / dx;
    assert!(
        (p.sdq - sdq).abs() < 1e-9 * sdq.max(1.0),
        "Sdq {} vs {sdq}",
        p.sdq
    );
    // z constant along y after levelling: each cell is a flat strip of width dy and slant length
    // sqrt(dx² + Δz²); Sdr = (polyline length / projected length − 1)·100.
    let len: f64 = (0..cols - 1)
        .map(|i| {
            let dz = amp * ((k * (i + 1) as f64).cos() - (k * i as f64).cos());
            (dx * dx + dz * dz).sqrt()
        })
        .sum();
    let sdr = (len / (nm * dx) - 1.0) * 100.0;
    assert!((p.sdr_pct - sdr).abs() < 1e-9, "Sdr {} vs {sdr}", p.sdr_pct);
}

#[test]
fn smr_curve_of_a_cosine_grid_is_arccos() {
    let (z, rows, cols, px, py, amp, _) = grid();
    let g = HeightMap {
        heights_um: &z,
        rows,
        cols,
        pitch_x_mm: px,
        pitch_y_mm: py,
    };
    let e = amp / cols as f64; // the levelled frame is shifted by the samples' mean
    let smr = smr_curve(&level_plane(&g).unwrap().0, g.cols, 101).unwrap();
    assert_eq!(smr.len(), 101);
    for [h, mr] in &smr {
        // Fraction of a period where cos θ ≥ h/A is arccos(h/A)/π.
        let expected = ((h + e) / amp).clamp(-1.0, 1.0).acos() / PI * 100.0;
        assert!((mr - expected).abs() < 0.05, "h {h}: {mr} vs {expected}");
    }
}

#[test]
fn grid_shape_errors_are_named() {
    let z = vec![0.0; 10];
    let g = HeightMap {
        heights_um: &z,
        rows: 3,
        cols: 4,
        pitch_x_mm: 0.001,
        pitch_y_mm: 0.01,
    };
    assert_eq!(
        areal_params(&g).unwrap_err(),
        MetrologyError::GridSize {
            rows: 3,
            cols: 4,
            expected: 12,
            got: 10
        }
    );
    let g = HeightMap {
        heights_um: &z,
        rows: 1,
        cols: 10,
        pitch_x_mm: 0.001,
        pitch_y_mm: 0.01,
    };
    assert_eq!(
        areal_params(&g).unwrap_err(),
        MetrologyError::GridTooSmall { rows: 1, cols: 10 }
    );
}
