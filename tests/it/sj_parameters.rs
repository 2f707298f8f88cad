//! The SJ series' parameters beyond Ra/Rq/Rz, against values derived by hand:
//! profile elements (RSm, Rc, RPc, Rppi with the 10 % Rz / 1 % lr discrimination), RΔa, the material
//! ratio parameters at the instrument's reference levels (Rmr(c) peak reference, Rδc, Rmr),
//! and the comparison with the instrument's own values, its tolerance flag included.

use std::f64::consts::PI;
use surfscan::metrology::instrument::{compare_profile, tolerance_for};
use surfscan::metrology::params::{analyze_line, MaterialLevels, Options};
use surfscan::profile::InstrumentResult;

fn no_filter() -> Options {
    Options {
        lambda_c_mm: 0.8,
        apply_lambda_c: false,
        lambda_s_um: None,
        sampling_lengths: None,
        central_sections: None,
        form: None,
    }
}

/// A sine of amplitude `amp` µm and wavelength `lambda` mm over 4 mm at 0.5 µm pitch
/// (5 sections of 8 whole periods).
fn sine(amp: f64, lambda: f64) -> Vec<f64> {
    (0..8000)
        .map(|i| amp * (2.0 * PI * i as f64 * 0.0005 / lambda).sin())
        .collect()
}

#[test]
fn a_sine_has_elements_of_its_wavelength_and_twice_its_amplitude() {
    let (amp, lambda) = (1.5, 0.1);
    let p = analyze_line(&sine(amp, lambda), 0.0005, &no_filter())
        .unwrap()
        .params;
    // Every period is one element: a peak of +A and a valley of −A, λ wide.
    assert!((p.rsm_um.unwrap() - 100.0).abs() < 1e-6, "{:?}", p.rsm_um);
    // Zt is the sampled extremes' sum: within (1 − cos(π·pitch/λ·…)) of 2A; 200 points per
    // period put the samples within 2.5e-4 of the crest.
    let rc = p.rc_um.unwrap();
    assert!((rc - 2.0 * amp).abs() < 2e-3, "Rc {rc}");
    // RPc = 1 cm / RSm = 10 mm / 0.1 mm; Rppi = 1 inch / RSm = 25.4 mm / 0.1 mm.
    assert!((p.rpc_per_cm.unwrap() - 100.0).abs() < 1e-5);
    assert!((p.rppi_per_inch.unwrap() - 254.0).abs() < 1e-5);
    // The slope is (2πA/λ)·cos: its mean modulus is (2/π)·2πA/λ = 4A/λ (λ = 100 µm), its
    // rms 2πA/(λ√2), so RΔq / RΔa = π / (2√2) for any sine.
    let rda = 4.0 * amp / 100.0;
    assert!((p.rda - rda).abs() < 1e-3 * rda, "RΔa {} vs {rda}", p.rda);
    let ratio = p.rdq / p.rda;
    assert!((ratio - PI / (2.0 * 2f64.sqrt())).abs() < 2e-3, "{ratio}");
}

#[test]
fn elements_below_the_height_discrimination_are_not_counted() {
    // Periods of 0.1 mm alternating between amplitude 1 µm and `s`: each section holds 4 of
    // each, so its Rz is 2 µm and the height discrimination 10 % of Rz = 0.2 µm. A small
    // period below it is no element of its own: it joins the big one before it (RSm 200 µm,
    // Zt of the pair = 1 + 1 µm). Above it, every period is an element (RSm 100 µm, Rc the
    // mean of 2 and 2s).
    let profile = |s: f64| -> Vec<f64> {
        (0..8000)
            .map(|i| {
                let amp = if (i / 200) % 2 == 0 { 1.0 } else { s };
                amp * (2.0 * PI * (i % 200) as f64 / 200.0).sin()
            })
            .collect()
    };
    let below = analyze_line(&profile(0.15), 0.0005, &no_filter())
        .unwrap()
        .params;
    assert!((below.rz_um - 2.0).abs() < 1e-3, "{}", below.rz_um);
    assert!(
        (below.rsm_um.unwrap() - 200.0).abs() < 1e-6,
        "{:?}",
        below.rsm_um
    );
    assert!(
        (below.rc_um.unwrap() - 2.0).abs() < 1e-3,
        "{:?}",
        below.rc_um
    );
    assert!((below.rpc_per_cm.unwrap() - 50.0).abs() < 1e-6);
    let above = analyze_line(&profile(0.5), 0.0005, &no_filter())
        .unwrap()
        .params;
    assert!(
        (above.rsm_um.unwrap() - 100.0).abs() < 1e-6,
        "{:?}",
        above.rsm_um
    );
    assert!(
        (above.rc_um.unwrap() - 1.5).abs() < 1e-3,
        "{:?}",
        above.rc_um
    );
}

#[test]
fn material_ratio_parameters_of_a_sine_follow_the_arccos() {
    // For z = A sin θ the material ratio at level h is arccos(h/A)/π, so C(mr) = A cos(π mr).
    let amp = 2.0;
    let a = analyze_line(&sine(amp, 0.1), 0.0005, &no_filter()).unwrap();
    let p = &a.params;
    let levels = MaterialLevels::default();
    assert_eq!(levels.rmr_c_depths_pct_rt, vec![10.0, 15.0]);
    let rt = p.rt_um;
    assert!((rt - 2.0 * amp).abs() < 1e-3);
    assert_eq!(p.material.rmr_c.len(), 2);
    for c in &p.material.rmr_c {
        let h = amp - c.depth_um;
        let expected = (h / amp).acos() / PI * 100.0;
        assert!((c.depth_um - rt * c.depth_pct_rt / 100.0).abs() < 1e-12);
        assert!(
            (c.value_pct - expected).abs() < 0.02,
            "Rmr(c) at {} % of Rt: {} vs {expected}",
            c.depth_pct_rt,
            c.value_pct
        );
    }
    let rdc = amp * ((0.10 * PI).cos() - (0.25 * PI).cos());
    assert!((p.rdc_um - rdc).abs() < 1e-3, "Rdc {} vs {rdc}", p.rdc_um);
    let rmr = ((amp - 0.1) / amp).acos() / PI * 100.0;
    assert!(
        (p.material.rmr_pct - rmr).abs() < 0.05,
        "Rmr {} vs {rmr}",
        p.material.rmr_pct
    );
}

#[test]
fn material_ratio_parameters_of_a_triangle_wave_are_linear() {
    // A symmetric triangle wave from −1 to +1 µm: the ratio at level h is (1 − h)/2 · 100 %.
    let z: Vec<f64> = (0..8000)
        .map(|i| {
            let t = (i % 200) as f64 / 200.0;
            if t < 0.5 {
                -1.0 + 4.0 * t
            } else {
                3.0 - 4.0 * t
            }
        })
        .collect();
    let p = analyze_line(&z, 0.0005, &no_filter()).unwrap().params;
    // The 8000 points hold 40 periods less their last segment (7999 segments), so a ratio
    // can be off by up to 1/7999 = 0.0125 %, a level by that times 2 µm / 100 %.
    let (mr_tol, c_tol) = (0.0125, 0.0125 * 0.02);
    // C(10 %) − C(25 %) = (1 − 0.2) − (1 − 0.5) = 0.3 µm.
    assert!((p.rdc_um - 0.3).abs() < 2.0 * c_tol, "{}", p.rdc_um);
    // 0.1 µm below the top: 0.1/2 = 5 %.
    assert!(
        (p.material.rmr_pct - 5.0).abs() < mr_tol,
        "{}",
        p.material.rmr_pct
    );
    // 10 % of Rt = 0.2 µm below the top: 10 %; 15 % of Rt: 15 %.
    assert!((p.material.rmr_c[0].value_pct - 10.0).abs() < mr_tol);
    assert!((p.material.rmr_c[1].value_pct - 15.0).abs() < mr_tol);
}

#[test]
fn the_instruments_values_are_compared_within_a_documented_tolerance() {
    let p = analyze_line(&sine(1.0, 0.1), 0.0005, &no_filter())
        .unwrap()
        .params;
    let r = |name: &str, value: f64, unit: &str| InstrumentResult {
        name: name.to_string(),
        value: Some(value),
        unit: unit.to_string(),
        ..InstrumentResult::default()
    };
    let c = compare_profile(
        &p,
        &[
            r("Rc", p.rc_um.unwrap() * 1.01, "um"),
            r("RPc", p.rpc_per_cm.unwrap() * 1.2, "/cm"),
            r("Rmr(c)", p.material.rmr_c[0].value_pct + 0.5, "%"),
            r("Rmr(c)", p.material.rmr_c[1].value_pct - 3.0, "%"),
            r("Rdc", p.rdc_um, "um"),
            r("Rmr", p.material.rmr_pct, "%"),
            r("Ra", p.ra_um + 0.004, "um"),
            r("Ra", p.ra_um * 1.05, "um"),
            r("RΔa", p.rda * 1.02, ""),
            r("Ppi", p.rppi_per_inch.unwrap() * 1.2, "/in"),
        ],
        None,
        false,
    );
    let names: Vec<&str> = c
        .iter()
        .filter_map(|c| c.compared_with.as_deref())
        .collect();
    assert_eq!(
        names,
        [
            "Rc",
            "RPc",
            "Rmr(c)@10%Rt",
            "Rmr(c)@15%Rt",
            "Rdc",
            "Rmr",
            "Ra",
            "Ra",
            "Rda",
            "Rppi"
        ]
    );
    let within: Vec<Option<bool>> = c.iter().map(|c| c.within_tolerance).collect();
    // Rc 1 % off (tolerance 5 % + 5 nm): in; RPc 20 % off: out; Rmr(c) 0.5 point: in;
    // 3 points: out; exact: in; Ra 4 nm: in (2 % + 5 nm); Ra 5 %: out; RΔa 2 %: in (3 %);
    // Ppi 20 %: out (5 %).
    assert_eq!(
        within,
        [
            Some(true),
            Some(false),
            Some(true),
            Some(false),
            Some(true),
            Some(true),
            Some(true),
            Some(false),
            Some(true),
            Some(false)
        ]
    );
    let ra = tolerance_for("Ra", false).unwrap();
    assert!((c[7].tolerance.unwrap() - ra.allowed(p.ra_um * 1.05)).abs() < 1e-15);
    assert!((ra.allowed(10.0) - 0.205).abs() < 1e-12);
    // The same numbers as the read-out's Ra check.
    use surfscan::sj210::sanity::{RA_ABS_TOL_UM, RA_REL_TOL_P, RA_REL_TOL_R};
    let p_tol = tolerance_for("Ra", true).unwrap();
    assert_eq!((ra.rel, ra.abs), (RA_REL_TOL_R, RA_ABS_TOL_UM));
    assert_eq!((p_tol.rel, p_tol.abs), (RA_REL_TOL_P, RA_ABS_TOL_UM));
    assert!(tolerance_for("Ppi", false).is_none());
    // A primary profile we filter ourselves is allowed more: 5 % off Ra is then within.
    let filtered = surfscan::metrology::instrument::compare_profile(
        &p,
        &[r("Ra", p.ra_um * 1.05, "um")],
        None,
        true,
    );
    assert_eq!(filtered[0].within_tolerance, Some(true));
}
