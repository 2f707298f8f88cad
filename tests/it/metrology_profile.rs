//! Analytic checks of the Gaussian filter, the ISO 4287 parameters, the Rk family and the bearing
//! area curve. Expected values are closed forms derived in the comments, never the code's output.

// Index loops mirror the formulas (several arrays at the same index).
#![allow(clippy::needless_range_loop)]

use std::f64::consts::PI;
use surfscan::metrology::bearing::{bearing_curve_xz, material_ratio_pct, material_ratio_pct_at};
use surfscan::metrology::filter::{gaussian_mean_line, roughness};
use surfscan::metrology::params::{analyze_line, rk_family_and_curve, Options};
use surfscan::metrology::MetrologyError;

fn sine(n: usize, pitch_mm: f64, wavelength_mm: f64, amp: f64) -> Vec<f64> {
    (0..n)
        .map(|i| amp * (2.0 * PI * i as f64 * pitch_mm / wavelength_mm).sin())
        .collect()
}

/// Amplitude of the interior part (one λc away from each end) by projection on sin/cos.
fn amplitude(z: &[f64], pitch_mm: f64, wavelength_mm: f64, skip: usize, periods_pts: usize) -> f64 {
    let (mut s, mut c) = (0.0, 0.0);
    for i in skip..skip + periods_pts {
        let ph = 2.0 * PI * i as f64 * pitch_mm / wavelength_mm;
        s += z[i] * ph.sin();
        c += z[i] * ph.cos();
    }
    2.0 * (s * s + c * c).sqrt() / periods_pts as f64
}

#[test]
fn gaussian_filter_transmits_half_at_cutoff_for_every_standard_cutoff() {
    for lc in [0.08, 0.25, 0.8, 2.5] {
        let pitch = lc / 400.0;
        let z = sine(4000, pitch, lc, 1.0);
        let w = gaussian_mean_line(&z, pitch, lc).unwrap();
        // Interior: skip λc at the start, average over 5 whole periods.
        let a = amplitude(&w, pitch, lc, 400, 2000);
        assert!((a - 0.5).abs() < 0.001, "λc {lc}: transmission {a}");
    }
}

#[test]
fn gaussian_filter_follows_exp_minus_pi_alpha_ratio_squared() {
    let lc: f64 = 0.8;
    let pitch: f64 = 0.0005;
    for ratio in [0.3f64, 0.5, 0.7, 1.0, 1.5, 2.0, 4.0] {
        let lambda = ratio * lc;
        let n_per = (lambda / pitch).round() as usize;
        let z = sine(1600 + 12 * n_per + 1600, pitch, lambda, 1.0);
        let w = gaussian_mean_line(&z, pitch, lc).unwrap();
        let a = amplitude(&w, pitch, lambda, 1600, 10 * n_per);
        // H_W(λ) = exp(−π (α λc / λ)²), α² = ln2/π  ⇒  H_W = 2^(−(λc/λ)²).
        let expected = 2f64.powf(-(1.0 / ratio).powi(2));
        assert!(
            (a - expected).abs() < 0.002,
            "λ/λc {ratio}: {a} vs {expected}"
        );
    }
}

#[test]
fn roughness_plus_waviness_is_primary() {
    let p: Vec<f64> = (0..3000)
        .map(|i| {
            let x = i as f64 * 0.001;
            0.3 * x * x + (x * 37.0).sin() + 0.2 * (x * 411.0).cos()
        })
        .collect();
    let r = roughness(&p, 0.001, 0.8).unwrap();
    let w = gaussian_mean_line(&p, 0.001, 0.8).unwrap();
    for i in 0..p.len() {
        assert!((r[i] + w[i] - p[i]).abs() < 1e-12);
    }
}

#[test]
fn end_treatment_keeps_a_tilted_line_as_its_own_mean_line() {
    // First-order moment criterion: a straight line is reproduced exactly, ends included.
    // A plain renormalised kernel would bend towards the interior by ~0.2·λc·slope at the ends.
    let p: Vec<f64> = (0..2000).map(|i| 3.0 + 0.01 * i as f64).collect();
    let w = gaussian_mean_line(&p, 0.001, 0.8).unwrap();
    for i in 0..p.len() {
        assert!(
            (w[i] - p[i]).abs() < 1e-9,
            "point {i}: {} vs {}",
            w[i],
            p[i]
        );
    }
}

fn no_filter(lc: f64) -> Options {
    Options {
        lambda_c_mm: lc,
        apply_lambda_c: false,
        lambda_s_um: None,
        sampling_lengths: None,
        central_sections: None,
        form: None,
    }
}

#[test]
fn sine_parameters_match_closed_forms() {
    // A = 1 µm, λ = 0.1 mm, pitch 0.5 µm, L = 4 mm ⇒ N = 5 sections of 8 whole periods.
    let (amp, lambda, pitch) = (1.0, 0.1, 0.0005);
    let z = sine(8000, pitch, lambda, amp);
    let a = analyze_line(&z, pitch, &no_filter(0.8)).unwrap();
    let p = &a.params;
    assert_eq!(a.recipe.sampling_lengths, 5);
    assert_eq!(a.recipe.points_per_section, 1600);
    // M = 200 samples per period, starting at phase 0: mean |sin| = (2/M)·cot(π/M) (→ 2A/π).
    let ra = amp * 2.0 / 200.0 / (PI / 200.0).tan();
    assert!((ra - 2.0 * amp / PI).abs() < 1e-4);
    assert!((p.ra_um - ra).abs() < 1e-9, "Ra {} vs {ra}", p.ra_um);
    assert!((p.rq_um - amp / 2f64.sqrt()).abs() < 1e-9, "Rq {}", p.rq_um);
    assert!(p.rsk.abs() < 1e-9, "Rsk {}", p.rsk);
    assert!((p.rku - 1.5).abs() < 1e-9, "Rku {}", p.rku);
    assert!((p.rp_um - amp).abs() < 1e-9 && (p.rv_um - amp).abs() < 1e-9);
    assert!((p.rz_um - 2.0 * amp).abs() < 1e-9);
    assert!((p.rt_um - 2.0 * amp).abs() < 1e-9);
    assert!((p.rz1max_um - 2.0 * amp).abs() < 1e-9);
    assert!((p.rzjis_um.unwrap() - 2.0 * amp).abs() < 1e-9);
    assert!(
        (p.rsm_um.unwrap() - lambda * 1000.0).abs() < 1e-6,
        "RSm {:?}",
        p.rsm_um
    );
    // Slope A·(2π/λ)·cos ⇒ rms = A·2π/(λ·√2), λ in µm.
    let k = 2.0 * PI / (lambda * 1000.0);
    let rdq = amp * k / 2f64.sqrt();
    assert!((p.rdq - rdq).abs() < 5e-4 * rdq, "Rdq {} vs {rdq}", p.rdq);
    // Exactly: the analytic slope A·k·cos at the points that have a 7-point slope (not the
    // first 3 and last 3 of the evaluation length), rms per section, averaged.
    let mut sum = 0.0;
    for s in 0..5 {
        let idx: Vec<usize> = (s * 1600..(s + 1) * 1600)
            .filter(|i| (3..7997).contains(i))
            .collect();
        let ms = idx
            .iter()
            .map(|&i| (amp * k * (k * i as f64 * pitch * 1000.0).cos()).powi(2))
            .sum::<f64>()
            / idx.len() as f64;
        sum += ms.sqrt();
    }
    assert!(
        (p.rdq - sum / 5.0).abs() < 1e-9,
        "Rdq {} vs {}",
        p.rdq,
        sum / 5.0
    );
    // Rmc(mr) = A·cos(π·mr/100) is flattest at its ends: the 40 % secants from 0 % and from
    // 60 % tie with the least drop A·(1 − cos 0.4π); the first one wins. Extended to 100 %:
    // C = A, D = A − 2.5·A·(1 − cos 0.4π), Rk = C − D; Mr1 = 0; Mr2 = arccos(D/A)/π·100;
    // A2 = ∫[Mr2,100] (D − A cos(πm/100)) dm = D·(100 − Mr2) + (100A/π)·sin(π·Mr2/100).
    let rk = 2.5 * amp * (1.0 - (0.4 * PI).cos());
    let d = amp - rk;
    let mr2 = (d / amp).acos() / PI * 100.0;
    let a2 = d * (100.0 - mr2) + 100.0 * amp / PI * (PI * mr2 / 100.0).sin();
    assert!(
        (p.material.rk.rk_um - rk).abs() < 1e-3,
        "Rk {} vs {rk}",
        p.material.rk.rk_um
    );
    assert_eq!(p.material.rk.mr1_pct, 0.0);
    assert_eq!(p.material.rk.rpk_um, 0.0);
    // 200 samples per period hit each height twice: mr is resolved to about 1 %.
    assert!(
        (p.material.rk.mr2_pct - mr2).abs() < 0.6,
        "Mr2 {} vs {mr2}",
        p.material.rk.mr2_pct
    );
    // Densely: ordinates A·cos(π(k + ½)/n) are the sine's heights at uniform phase.
    let n = 200_000;
    let dense: Vec<f64> = (0..n)
        .map(|k| amp * (PI * (k as f64 + 0.5) / n as f64).cos())
        .collect();
    let (f, _) = rk_family_and_curve(&dense, 2).unwrap();
    assert!((f.rk_um - rk).abs() < 1e-4, "Rk {} vs {rk}", f.rk_um);
    assert!((f.mr2_pct - mr2).abs() < 0.01, "Mr2 {} vs {mr2}", f.mr2_pct);
    assert!(
        (f.a2_um_pct - a2).abs() < 1e-3 * a2,
        "A2 {} vs {a2}",
        f.a2_um_pct
    );
    assert!((f.rvk_um - 2.0 * a2 / (100.0 - mr2)).abs() < 1e-3 * f.rvk_um);
    assert_eq!(f.mr1_pct, 0.0);
    // Rmr at depth A below the top (the mean line) is 50 %.
    // (4000 of the 7999 segments lie at or above the mean line.)
    let top = a
        .roughness_um
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let rmr = material_ratio_pct(&a.roughness_um, top - amp);
    assert!((rmr - 4000.0 / 7999.0 * 100.0).abs() < 1e-9, "{rmr}");
}

#[test]
fn material_ratios_from_one_pass_are_each_levels_own_bits() {
    // A rough profile with flats (levels on samples and between them), and the short ones.
    let z: Vec<f64> = (0..5000)
        .map(|k| ((k as f64 * 0.37).sin() * 3.0 + (k as f64 * 0.011).cos()).round() / 4.0)
        .chain((0..3000).map(|k| (k as f64 * 0.05).sin() * 0.731))
        .collect();
    let levels: [f64; 11] = std::array::from_fn(|k| 1.0 - 0.31 * k as f64);
    for h in [&z[..], &z[..1], &[][..]] {
        let each = material_ratio_pct_at(h, levels);
        for (got, level) in each.iter().zip(levels) {
            assert_eq!(
                got.to_bits(),
                material_ratio_pct(h, level).to_bits(),
                "{level}"
            );
        }
    }
    // Not the trivial answer: the levels cut the profile.
    let each = material_ratio_pct_at(&z, levels);
    assert!(each.iter().any(|m| *m > 1.0 && *m < 99.0), "{each:?}");
}

#[test]
fn triangle_wave_parameters_match_closed_forms() {
    // Heights uniform in [−A, A]: Ra = A/2, Rq = A/√3, Rku = 9/5, |slope| = 4A/λ.
    let (amp, lambda, pitch) = (2.0, 0.2, 0.0005);
    let per = (lambda / pitch) as usize; // 400 points per period
    let z: Vec<f64> = (0..8000)
        .map(|i| {
            let t = (i % per) as f64 / per as f64; // phase in [0, 1)
            let u = (t + 0.25).fract();
            amp * (if u < 0.5 {
                4.0 * u - 1.0
            } else {
                3.0 - 4.0 * u
            })
        })
        .collect();
    let p = analyze_line(&z, pitch, &no_filter(0.8)).unwrap().params;
    assert!((p.ra_um - amp / 2.0).abs() < 1e-4, "Ra {}", p.ra_um);
    assert!((p.rq_um - amp / 3f64.sqrt()).abs() < 1e-4, "Rq {}", p.rq_um);
    assert!((p.rku - 1.8).abs() < 1e-3, "Rku {}", p.rku);
    assert!(p.rsk.abs() < 1e-6);
    let slope = 4.0 * amp / (lambda * 1000.0);
    assert!(
        (p.rdq - slope).abs() < 0.03 * slope,
        "Rdq {} vs {slope}",
        p.rdq
    );
    // Uniform heights: Rmc is a straight line, every secant ties, Rk = full range.
    assert!(
        (p.material.rk.rk_um - 2.0 * amp).abs() < 1e-3,
        "Rk {}",
        p.material.rk.rk_um
    );
    assert!((p.rsm_um.unwrap() - lambda * 1000.0).abs() < 1e-6);
}

#[test]
fn rz_is_per_section_mean_and_rz1max_the_largest() {
    // Two sections of 10 points; section 0 spans +3/−1, section 1 spans +1/−1.
    let mut z = vec![0.0; 20];
    z[2] = 3.0;
    z[5] = -1.0;
    z[12] = 1.0;
    z[15] = -1.0;
    let o = Options {
        sampling_lengths: Some(2),
        ..no_filter(0.01)
    };
    let p = analyze_line(&z, 0.001, &o).unwrap().params;
    assert!((p.rz_um - 3.0).abs() < 1e-12); // ((3+1) + (1+1)) / 2
    assert!((p.rz1max_um - 4.0).abs() < 1e-12);
    assert!((p.rt_um - 4.0).abs() < 1e-12);
    assert!((p.rp_um - 2.0).abs() < 1e-12); // (3 + 1) / 2
    assert!((p.rv_um - 1.0).abs() < 1e-12);
    // Ra per section: 4/10 and 2/10, mean 0.3.
    assert!((p.ra_um - 0.3).abs() < 1e-12);
}

#[test]
fn sampling_lengths_round_within_one_percent_and_truncate_otherwise() {
    // The Mitutoyo export: 6664 × 1.5 µm = 9.996 mm, λc 2.5 ⇒ 3.9984 ⇒ N = 4, 1666 points each.
    let z = sine(6664, 0.0015, 0.1, 1.0);
    let a = analyze_line(&z, 0.0015, &no_filter(2.5)).unwrap();
    assert_eq!(a.recipe.sampling_lengths, 4);
    assert_eq!(a.recipe.points_per_section, 1666);
    assert_eq!(a.recipe.points_not_evaluated, 0);
    // 4.5 mm at λc 0.8: 5.625 is not within 1 % ⇒ N = 5 of 1600 points, 1000 points left out.
    let z = sine(9000, 0.0005, 0.1, 1.0);
    let a = analyze_line(&z, 0.0005, &no_filter(0.8)).unwrap();
    assert_eq!(a.recipe.sampling_lengths, 5);
    assert_eq!(a.recipe.points_per_section, 1600);
    assert_eq!(a.recipe.points_not_evaluated, 1000);
}

#[test]
fn gaussian_heights_give_rk_2_622_rq() {
    // Rmc of N(0, σ²) between 30 % and 70 % drops 2·Φ⁻¹(0.7)·σ = 1.04880σ; /0.4 ⇒ 2.6220σ.
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut uni = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let z: Vec<f64> = (0..200_000)
        .map(|_| (-2.0 * uni().ln()).sqrt() * (2.0 * PI * uni()).cos())
        .collect();
    let (rk, _) = rk_family_and_curve(&z, 2).unwrap();
    assert!((rk.rk_um - 2.622).abs() < 0.03, "Rk {}", rk.rk_um);
    assert!(rk.mr1_pct > 3.0 && rk.mr1_pct < 15.0, "Mr1 {}", rk.mr1_pct);
    assert!(rk.mr2_pct > 85.0 && rk.mr2_pct < 97.0, "Mr2 {}", rk.mr2_pct);
    // Rpk is the triangle height: A1 = Rpk·Mr1/2.
    assert!((rk.a1_um_pct - rk.rpk_um * rk.mr1_pct / 2.0).abs() < 1e-9);
}

#[test]
fn filtered_sine_far_below_cutoff_keeps_its_parameters() {
    // λ = λc/8: H_R = 1 − 2^(−64) ≈ 1, so Ra ≈ 2A/π even with the filter and its ends.
    // In the interior (≥ λc from the ends, full kernel) R equals P to the kernel's tail weight.
    let z = sine(8000, 0.0005, 0.1, 1.0);
    let r = roughness(&z, 0.0005, 0.8).unwrap();
    for i in 1600..6400 {
        assert!((r[i] - z[i]).abs() < 1e-6, "point {i}");
    }
    // Within λc of the ends the one-sided local-line kernel leaks about 1 % of the sine into
    // the mean line; those zones are 40 % of this profile, so Ra stays within 0.5 %.
    let p = analyze_line(&z, 0.0005, &Options::default())
        .unwrap()
        .params;
    assert!(
        (p.ra_um - 2.0 / PI).abs() < 0.005 * 2.0 / PI,
        "Ra {}",
        p.ra_um
    );
    assert!((p.rq_um - 1.0 / 2f64.sqrt()).abs() < 0.005 / 2f64.sqrt());
}

#[test]
fn bad_input_gets_named_errors() {
    let mut z = sine(2000, 0.001, 0.1, 1.0);
    z[17] = f64::NAN;
    assert!(matches!(
        analyze_line(&z, 0.001, &Options::default()),
        Err(MetrologyError::NonFiniteHeight { index: 17, .. })
    ));
    // A finite height no surface has (a file in other units, or damaged numbers) is named as
    // itself, not as the infinity its square would become inside the parameters.
    let mut z = sine(2000, 0.001, 0.1, 1.0);
    z[40] = -7.5e298;
    let e = analyze_line(&z, 0.001, &Options::default()).unwrap_err();
    assert_eq!(
        e,
        MetrologyError::HeightOutOfRange {
            index: 40,
            value: -7.5e298
        }
    );
    assert!(e.to_string().contains("-7.5e298 µm, beyond ±1e9 µm"), "{e}");
    // The bound itself is a height (1 km); just past it is not.
    let mut z = sine(2000, 0.001, 0.1, 1.0);
    z[3] = 1e9;
    assert!(analyze_line(&z, 0.001, &Options::default()).is_ok());
    z[3] = 1.000_000_1e9;
    assert!(matches!(
        analyze_line(&z, 0.001, &Options::default()),
        Err(MetrologyError::HeightOutOfRange { index: 3, .. })
    ));
    let z = sine(2000, 0.001, 0.1, 1.0);
    assert_eq!(
        analyze_line(&z, 0.0, &Options::default()),
        Err(MetrologyError::BadPitch { pitch_mm: 0.0 })
    );
    assert!(matches!(
        analyze_line(&z[..500], 0.001, &Options::default()),
        Err(MetrologyError::TooShort { points: 500, .. })
    ));
    let o = Options {
        lambda_c_mm: -1.0,
        ..Options::default()
    };
    assert!(matches!(
        analyze_line(&z, 0.001, &o),
        Err(MetrologyError::BadCutoff { .. })
    ));
}

#[test]
fn bearing_curve_of_a_sine_is_arccos() {
    // z = A sin θ over whole periods: z ≥ h for θ ∈ [asin(h/A), π − asin(h/A)], a fraction
    // (π − 2 asin(h/A)) / 2π = arccos(h/A)/π of the length.
    let amp = 1.5;
    let curve = |x: f64| 4.0 + amp * (2.0 * PI * x / 0.25).sin(); // offset removed by mean line
    let x: Vec<f64> = (0..40_001).map(|i| i as f64 / 40_000.0).collect();
    let z: Vec<f64> = x.iter().map(|&x| curve(x)).collect();
    let b = bearing_curve_xz(&x, &z, 101).unwrap();
    assert_eq!(b.points.len(), 101);
    assert!((b.mean_line_um - 4.0).abs() < 1e-9);
    for [h, mr] in &b.points {
        let expected = (h / amp).clamp(-1.0, 1.0).acos() / PI * 100.0;
        assert!((mr - expected).abs() < 0.05, "h {h}: {mr} vs {expected}");
    }
    assert!((b.points[0][0] - amp).abs() < 1e-6);
    assert!((b.points[100][0] + amp).abs() < 1e-6);
}

#[test]
fn material_ratio_interpolates_crossings() {
    // One segment from 0 to 1: at level 0.25 three quarters of it is above.
    assert!((material_ratio_pct(&[0.0, 1.0], 0.25) - 75.0).abs() < 1e-12);
    // 0,2,0: at level 1 half of each segment.
    assert!((material_ratio_pct(&[0.0, 2.0, 0.0], 1.0) - 50.0).abs() < 1e-12);
}

#[test]
fn instrument_results_are_paired_with_ours_in_our_units() {
    use surfscan::metrology::instrument::compare_profile;
    use surfscan::profile::InstrumentResult;
    let z = sine(8000, 0.0005, 0.1, 1.0);
    let p = analyze_line(&z, 0.0005, &no_filter(0.8)).unwrap().params;
    let r = |name: &str, value: Option<f64>, unit: &str| InstrumentResult {
        name: name.to_string(),
        value,
        unit: unit.to_string(),
        printed: None,
        ng_code: None,
    };
    let c = compare_profile(
        &p,
        &[
            r("Ra", Some(0.6), "µm"),
            r("RSm", Some(0.1), "mm"),
            r("Rz", None, "um"),
            r("HSC", Some(12.0), ""),
            r("Ppi", Some(250.0), "/in"),
        ],
        None,
        false,
    );
    assert_eq!(c.len(), 5);
    assert!((c[0].difference.unwrap() - (p.ra_um - 0.6)).abs() < 1e-12);
    // 0.1 mm = 100 µm; our RSm is the wavelength, 100 µm.
    assert!((c[1].instrument.unwrap() - 100.0).abs() < 1e-12);
    assert!(c[1].difference.unwrap().abs() < 1e-6);
    assert_eq!(c[2].instrument, None);
    assert_eq!(c[2].difference, None);
    // A parameter we do not compute (the high spot count needs a count level we are not given).
    assert_eq!(c[3].ours, None);
    assert_eq!(c[3].compared_with, None);
    // Ppi is Pc per inch: 25.4 mm / 0.1 mm = 254 peaks per inch.
    assert_eq!(c[4].compared_with.as_deref(), Some("Rppi"));
    assert!((c[4].difference.unwrap() - 4.0).abs() < 1e-4, "{:?}", c[4]);
    assert_eq!(c[2].compared_with.as_deref(), Some("Rz"));

    // Under JIS1994 the instrument's Rz is the ten-point height: compared with our RzJIS.
    let rz = [r("Rz", Some(1.0), "um")];
    let iso = compare_profile(&p, &rz, Some("ISO1997"), false);
    assert_eq!(iso[0].compared_with.as_deref(), Some("Rz"));
    assert!((iso[0].difference.unwrap() - (p.rz_um - 1.0)).abs() < 1e-12);
    let jis = compare_profile(&p, &rz, Some("JIS1994"), false);
    assert_eq!(jis[0].compared_with.as_deref(), Some("RzJIS"));
    let rzjis = p.rzjis_um.unwrap();
    assert!((jis[0].difference.unwrap() - (rzjis - 1.0)).abs() < 1e-12);
}

#[test]
fn a_pitch_coarser_than_a_sampling_length_needs_is_named_not_called_too_short() {
    // 2000 points at 0.5 "mm" (a pitch in µm taken as mm): 1000 mm of profile, but one
    // point per 0.8 mm sampling length. The profile is not short; the pitch is the cause.
    let z = sine(2000, 0.5, 100.0, 1.0);
    let e = analyze_line(&z, 0.5, &Options::default()).unwrap_err();
    assert_eq!(
        e,
        MetrologyError::PitchTooCoarse {
            pitch_mm: 0.5,
            points_per_sampling_length: 1,
            sampling_length_mm: 0.8,
            min_points: 8,
        }
    );
    let said = e.to_string();
    assert!(
        said.contains("pitch 0.5 mm leaves 1 points in a sampling length of 0.8 mm"),
        "{said}"
    );
    assert!(said.contains("check that the pitch (x) is in mm"), "{said}");
    // A pitch so coarse that L/λc is beyond any count of sampling lengths: the same cause.
    assert!(matches!(
        analyze_line(&z, 1e300, &Options::default()),
        Err(MetrologyError::PitchTooCoarse {
            points_per_sampling_length: 0,
            ..
        })
    ));
    // A profile shorter than one sampling length is still called short.
    assert!(matches!(
        analyze_line(&z[..1], 0.5, &Options::default()),
        Err(MetrologyError::TooShort { .. })
    ));
}

/// Sections of different amplitude: the per-section means and the whole-length values differ
/// by closed forms. Five sections of 8 sine periods with amplitudes a_i: lr-mean
/// Rq = Σ(a_i/√2)/5, whole-length Rq = √(Σ a_i²/2 / 5); Ra likewise with 2a/π.
#[test]
fn whole_length_moments_stand_beside_the_per_section_means() {
    let (lambda, pitch) = (0.1, 0.0005);
    let amps = [0.5, 1.0, 1.5, 2.0, 4.0];
    let z: Vec<f64> = amps
        .iter()
        .flat_map(|a| sine(1600, pitch, lambda, *a))
        .collect();
    let a = analyze_line(&z, pitch, &no_filter(0.8)).unwrap();
    let s2 = std::f64::consts::SQRT_2;
    let mean_rq = amps.iter().map(|a| a / s2).sum::<f64>() / 5.0;
    let ln_rq = (amps.iter().map(|a| a * a / 2.0).sum::<f64>() / 5.0).sqrt();
    let ln_ra = amps.iter().map(|a| 2.0 * a / PI).sum::<f64>() / 5.0;
    assert!(
        (a.params.rq_um - mean_rq).abs() < 1e-3,
        "{}",
        a.params.rq_um
    );
    assert!(
        (a.evaluation_length.rq_um - ln_rq).abs() < 1e-3,
        "{:?}",
        a.evaluation_length
    );
    assert!((a.evaluation_length.ra_um - ln_ra).abs() < 1e-3);
    // Each section is a symmetric sine (Rku 1.5); the mixture over the length is heavier
    // tailed: Rku_ln = (Σ 3a⁴/8 / 5) / Rq_ln⁴.
    let ln_rku = amps.iter().map(|a| 3.0 * a.powi(4) / 8.0).sum::<f64>() / 5.0 / ln_rq.powi(4);
    assert!((a.params.rku - 1.5).abs() < 1e-3 && (a.evaluation_length.rku - ln_rku).abs() < 1e-3);
    assert!(a
        .recipe
        .averaging
        .contains("per sampling length, then averaged"));
}

/// A section with fewer than 5 peaks leaves RzJIS blank with the reason; a profile without
/// two elements in any section leaves RSm blank with the reason.
#[test]
fn a_blank_parameter_carries_its_reason() {
    // 8 periods per section, but section 3 holds only 3 (a slow wave there).
    let pitch = 0.0005;
    let mut z = Vec::new();
    for s in 0..5 {
        let periods = if s == 2 { 3.0 } else { 8.0 };
        z.extend((0..1600).map(|i| (2.0 * PI * periods * i as f64 / 1600.0).sin()));
    }
    let a = analyze_line(&z, pitch, &no_filter(0.8)).unwrap();
    assert!(a.params.rzjis_um.is_none());
    let why = &a.blank_reasons["RzJIS"];
    assert!(why.starts_with("sampling length 3 of 5 has "), "{why}");
    assert!(why.contains("fewer than the 5"), "{why}");
    assert!(a.params.rsm_um.is_some() && !a.blank_reasons.contains_key("RSm"));
    // A straight ramp about zero: no element anywhere.
    let ramp: Vec<f64> = (0..8000).map(|i| (i as f64 - 4000.0) * 1e-4).collect();
    let b = analyze_line(&ramp, pitch, &no_filter(0.8)).unwrap();
    assert!(
        b.params.rsm_um.is_none()
            && b.blank_reasons["RSm"].contains("no sampling length holds a profile element")
    );
}

/// Form-only: a tilted, curved sine evaluated with the stated form removed and no λc filter
/// gives the sine's own parameters as P parameters over the whole length as one section.
#[test]
fn form_only_evaluates_the_primary_profile_about_its_form() {
    use surfscan::metrology::form::Form;
    let (amp, lambda, pitch) = (1.0, 0.1, 0.0005);
    let z: Vec<f64> = sine(8000, pitch, lambda, amp)
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let x = i as f64 * pitch;
            v + 40.0 + 3.0 * x - 2.0 * (x - 2.0) * (x - 2.0)
        })
        .collect();
    let options = Options {
        form: Some(Form::Polynomial(2)),
        ..Options::default()
    };
    let a = analyze_line(&z, pitch, &options).unwrap();
    assert_eq!(a.recipe.profile, "P");
    assert_eq!(a.recipe.sampling_lengths, 1);
    assert!(
        a.recipe.filter.starts_with("none: form-only"),
        "{}",
        a.recipe.filter
    );
    // Pa = 2A/π, Pq = A/√2, Pt = 2A, but for what the least-squares form takes of the sine
    // itself: over whole periods ∫x·sin = −L·λ/2π, so the fitted line tilts by
    // 12·A·λ/(2π·L²) per mm, ±0.024 µm at the ends of 4 mm, which Pt gains (2.3 %).
    assert!(
        (a.params.ra_um - 2.0 * amp / PI).abs() < 2e-3,
        "{}",
        a.params.ra_um
    );
    assert!((a.params.rq_um - amp / 2f64.sqrt()).abs() < 2e-3);
    let tilt = 12.0 * amp * lambda / (2.0 * PI * 16.0) * 4.0;
    assert!(
        (a.params.rt_um - (2.0 * amp + tilt)).abs() < 0.01,
        "{} vs {}",
        a.params.rt_um,
        2.0 * amp + tilt
    );
}

/// A section shorter than λc (an instrument's arbitrary evaluation length) is said plainly.
#[test]
fn a_section_shorter_than_lambda_c_is_said_plainly() {
    let z = sine(1067, 0.0015, 0.1, 1.0);
    let options = Options {
        lambda_c_mm: 2.5,
        apply_lambda_c: false,
        sampling_lengths: Some(1),
        ..Options::default()
    };
    let a = analyze_line(&z, 0.0015, &options).unwrap();
    assert!((a.recipe.section_length_mm - 1.6005).abs() < 1e-9);
    assert!(
        a.recipe
            .sampling_lengths_rule
            .contains("each section is 1.601 mm long, shorter than λc 2.5 mm"),
        "{}",
        a.recipe.sampling_lengths_rule
    );
}
