//! Unit tests of the fitter: closed forms, hand-computed parameters and knots, interpolation
//! and error reporting.

use super::*;
use crate::profile::Profile;

/// Deterministic roughness-like heights (µm): a few waves plus LCG noise.
fn rough_grid(rows: usize, cols: usize, seed: u64) -> Vec<f64> {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut out = Vec::with_capacity(rows * cols);
    for l in 0..rows {
        for k in 0..cols {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5;
            let x = k as f64;
            let y = l as f64;
            out.push(1.5 * (x * 0.013 + y * 0.2).sin() + 0.4 * (x * 0.11).cos() + 0.8 * noise);
        }
    }
    out
}

fn ys(rows: usize, pitch: f64) -> Vec<f64> {
    (0..rows).map(|l| l as f64 * pitch).collect()
}

/// The grid of heights `h` (µm, `y.len() × cols`) at x pitch `pitch_x_mm`.
fn grid(pitch_x_mm: f64, y: &[f64], h: &[f64], cols: usize) -> crate::grid::Grid {
    crate::grid::Grid {
        heights_um: h.to_vec(),
        cols,
        pitch_x_mm,
        y_mm: y.to_vec(),
        ..Default::default()
    }
}

#[test]
fn averaged_knots_match_hand_values() {
    let k = averaged_knots(&[0.0, 0.25, 0.5, 0.75, 1.0], 2);
    assert_eq!(k, vec![0.0, 0.0, 0.0, 0.375, 0.625, 1.0, 1.0, 1.0]);
    let k = averaged_knots(&[0.0, 0.1, 0.4, 1.0], 3);
    assert_eq!(k, vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]);
}

#[test]
fn parameters_are_averaged_chord_lengths_in_mm() {
    // 2 rows × 3 columns, pitch 1 mm, degree 1/1.
    // Row 0 flat: chords 1, 1 → 0, 1/2, 1.
    // Row 1: z = 0, 0, √3 mm → chords 1, 2 → 0, 1/3, 1.  ū_1 = (1/2 + 1/3)/2 = 5/12.
    // Columns (dy = 1): chords 1, 1, 2 → each column normalises to 0, 1 → v̄ = 0, 1.
    let s3 = 3f64.sqrt() * 1000.0;
    let r = fit_grid(
        1.0,
        &[0.0, 1.0],
        &[0.0, 0.0, 0.0, 0.0, 0.0, s3],
        3,
        FitOptions::degrees(1, 1),
    )
    .unwrap();
    assert_eq!(r.params_u.len(), 3);
    assert_eq!(r.params_u[0], 0.0);
    assert!((r.params_u[1] - 5.0 / 12.0).abs() < 1e-15);
    assert_eq!(r.params_u[2], 1.0);
    assert_eq!(r.params_v, vec![0.0, 1.0]);
    // Degree 1: poles are the data points themselves.
    assert!((r.surface.pole(2, 1)[2] - 3f64.sqrt()).abs() < 1e-15);
    assert!((r.surface.pole(1, 1)[0] - 1.0).abs() < 1e-15);
}

#[test]
fn knots_and_parameters_are_well_formed() {
    let (rows, cols) = (9, 60);
    let h = rough_grid(rows, cols, 7);
    for (p, q) in [(5, 5), (3, 2), (1, 4)] {
        let r = fit_grid(0.0005, &ys(rows, 0.01), &h, cols, FitOptions::degrees(p, q)).unwrap();
        for (params, n) in [(&r.params_u, cols), (&r.params_v, rows)] {
            assert_eq!(params.len(), n);
            assert_eq!(params[0], 0.0);
            assert_eq!(params[n - 1], 1.0);
            assert!(
                params.windows(2).all(|w| w[0] < w[1]),
                "params not strictly increasing"
            );
        }
        for (knots, deg, n) in [
            (r.surface.knots_u(), p, cols),
            (r.surface.knots_v(), q, rows),
        ] {
            assert_eq!(knots.len(), n + deg + 1);
            assert!(knots.windows(2).all(|w| w[0] <= w[1]));
            assert!(knots[..=deg].iter().all(|&k| k == 0.0));
            assert!(knots[n..].iter().all(|&k| k == 1.0));
            assert!(
                knots[deg + 1] > 0.0 && knots[n - 1] < 1.0,
                "end multiplicity exceeds degree + 1"
            );
        }
    }
}

#[test]
fn plane_is_reproduced_everywhere() {
    let (a, b, c) = (0.03, -0.02, 0.004); // z_mm = a x + b y + c
    let (rows, cols) = (8, 40);
    let pitch = 0.01;
    let y: Vec<f64> = (0..rows)
        .map(|l| 0.05 * l as f64 + 0.003 * (l * l) as f64)
        .collect();
    let mut h = Vec::new();
    for &yy in &y {
        for k in 0..cols {
            h.push(1000.0 * (a * k as f64 * pitch + b * yy + c));
        }
    }
    for (p, q) in [(5, 5), (3, 2), (1, 1)] {
        let r = fit_grid(pitch, &y, &h, cols, FitOptions::degrees(p, q)).unwrap();
        for i in 0..=50 {
            for j in 0..=30 {
                let s = r.surface.evaluate(i as f64 / 50.0, j as f64 / 30.0);
                let err = (s[2] - (a * s[0] + b * s[1] + c)).abs();
                assert!(
                    err <= 1e-12,
                    "degree {p}/{q}: plane error {err} at ({i},{j})"
                );
            }
        }
    }
}

#[test]
fn surface_passes_through_every_point_of_a_rough_grid() {
    let (rows, cols) = (31, 2000);
    let h = rough_grid(rows, cols, 42);
    let y = ys(rows, 0.01);
    let r = fit_grid(0.0005, &y, &h, cols, FitOptions::default()).unwrap();
    let res = max_residual_mm(&r, &grid(0.0005, &y, &h, cols));
    assert!(res <= 1e-10, "max residual {res} mm");
    // Spot-check with the independent single-point evaluator.
    let s = r.surface.evaluate(r.params_u[777], r.params_v[13]);
    assert!((s[2] - h[13 * cols + 777] / 1000.0).abs() <= 1e-10);
    assert!((s[0] - 777.0 * 0.0005).abs() <= 1e-10);
    assert!((s[1] - 0.13).abs() <= 1e-10);
}

#[test]
fn incremental_equals_batch_bit_for_bit_and_provisional_after_q_plus_1_lines() {
    let (rows, cols) = (12, 80);
    let h = rough_grid(rows, cols, 3);
    let y = ys(rows, 0.01);
    let opts = FitOptions::default();
    let batch = fit_grid(0.0005, &y, &h, cols, opts).unwrap();
    let mut f = IncrementalFitter::new(opts);
    for (l, row) in h.chunks_exact(cols).enumerate() {
        let prof = Profile::new(0.0005, row.to_vec());
        f.push_line(y[l], &prof).unwrap();
        assert_eq!(f.lines(), l + 1);
        match f.provisional() {
            Err(FitError::TooFewRows { got, need }) => {
                assert!(l + 1 < 6);
                assert_eq!((got, need), (l + 1, 6));
            }
            Ok(p) => {
                assert!(l + 1 >= 6);
                assert_eq!(p.surface.count_v(), l + 1);
                let res = max_residual_mm(&p, &grid(0.0005, &y[..=l], &h[..(l + 1) * cols], cols));
                assert!(res <= 1e-10, "provisional residual {res}");
            }
            Err(e) => panic!("unexpected {e}"),
        }
    }
    let inc = f.finish().unwrap();
    assert_eq!(inc.surface, batch.surface);
    assert_eq!(inc.params_u, batch.params_u);
    assert_eq!(inc.params_v, batch.params_v);
}

#[test]
fn errors_name_the_offending_numbers() {
    let opts = FitOptions::default();
    let row: Vec<f64> = (0..10).map(|i| i as f64 * 0.1).collect();

    let mut f = IncrementalFitter::new(FitOptions::degrees(0, 2));
    assert_eq!(
        f.push_row(0.0, 0.001, &row),
        Err(FitError::InvalidDegree {
            degree_u: 0,
            degree_v: 2
        })
    );

    let mut f = IncrementalFitter::new(opts);
    assert_eq!(
        f.push_row(0.0, 0.001, &row[..5]),
        Err(FitError::TooFewColumns { got: 5, need: 6 })
    );
    assert_eq!(
        f.push_row(0.0, -0.001, &row),
        Err(FitError::BadPitch {
            line: 0,
            pitch_x_mm: -0.001
        })
    );
    assert_eq!(
        f.push_row(f64::NAN, 0.001, &row).unwrap_err().to_string(),
        "line 1 (0000): y = NaN mm is not finite"
    );
    let mut bad = row.clone();
    bad[3] = f64::INFINITY;
    assert_eq!(
        f.push_row(0.0, 0.001, &bad),
        Err(FitError::NonFinite {
            line: 0,
            index: 3,
            value: f64::INFINITY
        })
    );
    assert_eq!(f.lines(), 0, "a rejected line must not be stored");

    f.push_row(0.0, 0.001, &row).unwrap();
    assert_eq!(
        f.push_row(0.01, 0.001, &row[..9]),
        Err(FitError::RowLength {
            line: 1,
            got: 9,
            expected: 10
        })
    );
    assert_eq!(
        f.push_row(0.01, 0.002, &row),
        Err(FitError::PitchMismatch {
            line: 1,
            got: 0.002,
            expected: 0.001
        })
    );
    // A repeated y is rejected before any chord is computed.
    assert_eq!(
        f.push_row(0.0, 0.001, &row),
        Err(FitError::LineOrder {
            line: 1,
            y_mm: 0.0,
            previous_y_mm: 0.0
        })
    );
    f.push_row(0.01, 0.001, &row).unwrap();
    assert_eq!(
        f.push_row(0.005, 0.001, &row),
        Err(FitError::LineOrder {
            line: 2,
            y_mm: 0.005,
            previous_y_mm: 0.01
        })
    );
    assert_eq!(
        f.provisional().unwrap_err(),
        FitError::TooFewRows { got: 2, need: 6 }
    );

    // Coincident points along u: a pitch so small that the chord underflows to zero.
    let mut f = IncrementalFitter::new(FitOptions::degrees(1, 1));
    let flat = [1.0, 1.0, 1.0];
    match f.push_row(0.5, 1e-170, &flat) {
        Err(FitError::CoincidentPoints {
            direction: "u",
            line: 0,
            index: 1,
            previous,
            point,
        }) => {
            assert_eq!(previous[1], 0.5);
            assert_eq!(point[2], 0.001);
        }
        other => panic!("expected CoincidentPoints, got {other:?}"),
    }
    // Coincident along v: y step that underflows with identical heights.
    f.push_row(0.0, 0.001, &flat).unwrap();
    match f.push_row(1e-170, 0.001, &flat) {
        Err(FitError::CoincidentPoints {
            direction: "v",
            line: 1,
            index: 0,
            ..
        }) => {}
        other => panic!("expected CoincidentPoints along v, got {other:?}"),
    }
    // Overflowing chord.
    assert!(matches!(
        f.push_row(1.0, 0.001, &[1e306, -1e306, 0.0]),
        Err(FitError::ChordOverflow {
            direction: "u",
            line: 1,
            index: 1,
            ..
        })
    ));

    assert_eq!(
        fit_grid(0.001, &[0.0, 1.0], &[0.0; 7], 3, opts),
        Err(FitError::GridShape {
            len: 7,
            rows: 2,
            cols: 3
        })
    );
}

/// The residual check as it was first written: each row's iso-curve evaluated at every ū_k
/// through the public curve evaluation (basis recomputed per point). The fast check must give
/// the same number to the bit, since it only reuses the basis instead of recomputing it.
fn residual_by_curve_evaluation(r: &FitResult, pitch: f64, y: &[f64], h: &[f64]) -> f64 {
    let cols = r.params_u.len();
    let mut worst = 0.0f64;
    for ((row, &yy), &v) in h.chunks_exact(cols).zip(y).zip(&r.params_v) {
        let curve = r.surface.iso_curve_u(v);
        for (k, (&u, &z)) in r.params_u.iter().zip(row).enumerate() {
            let p = curve.evaluate(u).unwrap();
            let q = [k as f64 * pitch, yy, z / 1000.0];
            let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
            worst = worst.max(d);
        }
    }
    worst
}

#[test]
fn residual_reusing_the_basis_equals_per_point_evaluation_to_the_bit() {
    // The last grid is large enough to be split by columns over threads.
    for (rows, cols, p, q) in [
        (31, 700, 5, 5),
        (9, 40, 3, 2),
        (6, 6, 5, 5),
        (31, 3300, 5, 5),
    ] {
        let h = rough_grid(rows, cols, (rows * cols) as u64);
        let y = ys(rows, 0.01);
        let r = fit_grid(0.0005, &y, &h, cols, FitOptions::degrees(p, q)).unwrap();
        let fast = max_residual_mm(&r, &grid(0.0005, &y, &h, cols));
        let slow = residual_by_curve_evaluation(&r, 0.0005, &y, &h);
        assert_eq!(
            fast.to_bits(),
            slow.to_bits(),
            "{rows}x{cols}: {fast:e} vs {slow:e}"
        );
        assert!(fast > 0.0 && fast < 1e-12, "{fast:e}");
        // The grid evaluation shares the code path; it must agree with the curves too.
        let g = r.surface.evaluate_grid(&r.params_u, &r.params_v[1..2]);
        let c = r.surface.iso_curve_u(r.params_v[1]);
        for (pt, &u) in g.iter().zip(&r.params_u) {
            assert_eq!(*pt, c.evaluate(u).unwrap());
        }
    }
    // A grid that does not match the result is refused, not misread.
    let h = rough_grid(7, 20, 1);
    let r = fit_grid(0.0005, &ys(7, 0.01), &h, 20, FitOptions::default()).unwrap();
    assert_eq!(
        max_residual_mm(&r, &grid(0.0005, &ys(7, 0.01), &h[..139], 20)),
        f64::INFINITY
    );
}

#[test]
fn v_parameters_recomputed_from_the_heights_equal_those_of_a_stored_chord_grid_to_the_bit() {
    // The fitter keeps one row of running column chords and recomputes each line's chords
    // from the stored heights when it averages; this is the grid of cumulative chords built
    // line by line as they arrived (as a fitter storing them all would), averaged the same
    // way. Uneven y steps and rough heights, with a line rejected on the way.
    let (rows, cols) = (23, 37);
    let h = rough_grid(rows, cols, 11);
    let y: Vec<f64> = (0..rows)
        .map(|l| l as f64 * 0.01 + (l * l) as f64 * 3e-4)
        .collect();
    let mut f = IncrementalFitter::new(FitOptions::default());
    for (l, row) in h.chunks_exact(cols).enumerate() {
        if l == 9 {
            let mut bad = row.to_vec();
            bad[5] = f64::NAN;
            assert!(f.push_row(y[l], 0.0005, &bad).is_err());
        }
        f.push_row(y[l], 0.0005, row).unwrap();
    }
    let fit = f.finish().unwrap();
    let z: Vec<f64> = h.iter().map(|v| v / 1000.0).collect();
    let mut cum = vec![vec![0.0f64; cols]];
    for l in 1..rows {
        let dy = y[l] - y[l - 1];
        let prev = cum[l - 1].clone();
        cum.push(
            (0..cols)
                .map(|k| {
                    let dz = z[l * cols + k] - z[(l - 1) * cols + k];
                    (dy * dy + dz * dz).sqrt() + prev[k]
                })
                .collect(),
        );
    }
    let totals = cum[rows - 1].clone();
    let mut want: Vec<f64> = cum
        .iter()
        .map(|row| super::params::sum_ratios(row, &totals) / cols as f64)
        .collect();
    want[0] = 0.0;
    want[rows - 1] = 1.0;
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&fit.params_v), bits(&want));
}
