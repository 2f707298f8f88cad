//! The verdict section on hand-made lines whose counts are worked out by hand.

use super::*;
use crate::metrology::params::{MaterialRatio, RkFamily};

fn params(ra: f64, rz: f64, rsm: Option<f64>) -> RoughnessParams {
    RoughnessParams {
        ra_um: ra,
        rq_um: ra * 1.25,
        rp_um: rz / 2.0,
        rv_um: rz / 2.0,
        rz_um: rz,
        rt_um: rz * 1.2,
        rz1max_um: rz * 1.1,
        rzjis_um: None,
        rsk: 0.0,
        rku: 3.0,
        rdq: 0.1,
        rda: 0.08,
        rsm_um: rsm,
        rc_um: None,
        rpc_per_cm: None,
        rppi_per_inch: None,
        rdc_um: 1.0,
        material: MaterialRatio {
            rmr_c: Vec::new(),
            rmr_pct: 50.0,
            rk: RkFamily {
                rk_um: 1.0,
                rpk_um: 0.3,
                rvk_um: 0.4,
                mr1_pct: 10.0,
                mr2_pct: 90.0,
                a1_um_pct: 1.0,
                a2_um_pct: 2.0,
                upper_level_um: 0.5,
                lower_level_um: -0.5,
                secant_start_pct: 0.0,
            },
        },
    }
}

const BAND: EvaluatedBand = EvaluatedBand {
    lambda_c_mm: 0.8,
    lambda_s_um: Some(2.5),
    sampling_lengths: 5,
};

fn lines(p: &[RoughnessParams]) -> Vec<LineValues<'_>> {
    p.iter()
        .enumerate()
        .map(|(i, params)| LineValues {
            index: i as u32,
            params,
            flagged: false,
        })
        .collect()
}

/// 31 lines: Ra 0.5 µm everywhere; Rz 5.0 µm except on lines 3, 7, 11, …, 31 (every fourth
/// from the third, eight of them) at 7.0 µm.
fn surface() -> Vec<RoughnessParams> {
    (0..31)
        .map(|i| {
            let rz = if i % 4 == 2 { 7.0 } else { 5.0 };
            params(0.5, rz, Some(100.0))
        })
        .collect()
}

#[test]
fn a_surface_with_nine_of_31_lines_above_does_not_conform() {
    let mut p = surface();
    p[0].rz_um = 6.5;
    let spec = Specification::parse(&["Ra 0.8", "Rz 6.3"]).unwrap();
    let v = judge(&spec, &lines(&p), None, Some(&BAND), &Default::default());
    assert_eq!(v.verdict, Verdict::DoesNotConform);
    let rz = &v.limits[1];
    assert_eq!(
        (rz.n_values, rz.n_beyond, rz.n_undecided, rz.n_allowed),
        (31, 9, 0, 4)
    );
    assert_eq!(rz.lines_beyond, vec![1, 3, 7, 11, 15, 19, 23, 27, 31]);
    assert_eq!(
        rz.reason,
        "Rz 16 % rule: 9 of 31 lines above 6.3 µm (at most 4 allowed)"
    );
    assert_eq!(v.limits[0].verdict, Verdict::Conforms);
    assert_eq!(
        v.summary,
        "does not conform (Rz 16 % rule: 9 of 31 lines above 6.3 µm (at most 4 allowed))"
    );
    assert!(v
        .instrument_uncertainty
        .contains("ignores the instrument's uncertainty"));
    let json = serde_json::to_value(&v).unwrap();
    assert_eq!(json["verdict"], "does not conform");
    assert_eq!(json["limits"][1]["callout"], "Rz 6.3");
    assert_eq!(json["limits"][1]["n_beyond"], 9);
    assert_eq!(json["limits"][1]["rule"], "16 %");
}

#[test]
fn four_of_25_lines_above_is_sixteen_percent_and_conforms() {
    let mut p: Vec<RoughnessParams> = (0..25).map(|_| params(0.7, 5.0, None)).collect();
    for l in &mut p[..4] {
        l.ra_um = 0.9;
    }
    let spec = Specification::parse(&["Ra 0.8", "Ra max 1.0"]).unwrap();
    let v = judge(&spec, &lines(&p), None, Some(&BAND), &Default::default());
    assert_eq!(v.limits[0].verdict, Verdict::Conforms);
    assert_eq!(v.limits[0].n_beyond, 4);
    assert_eq!(v.verdict, Verdict::Conforms);
    p[4].ra_um = 0.9;
    let v = judge(&spec, &lines(&p), None, Some(&BAND), &Default::default());
    assert_eq!(v.verdict, Verdict::DoesNotConform, "5 of 25 is 20 %");
}

#[test]
fn the_instrument_uncertainty_makes_values_near_a_limit_undecided() {
    // Upper Rz max 6.3; values 5.0 and one at 6.2. With 3 % (k = 2): U(6.2) = 0.186,
    // 6.2 + 0.186 > 6.3, undecided: the max rule is not decidable. U(5.0) = 0.15: within.
    let mut p: Vec<RoughnessParams> = (0..10).map(|_| params(0.5, 5.0, None)).collect();
    p[5].rz_um = 6.2;
    let spec = Specification::parse(&["Rz max 6.3"]).unwrap();
    let none = judge(&spec, &lines(&p), None, Some(&BAND), &Default::default());
    assert_eq!(none.verdict, Verdict::Conforms);
    let inst = InstrumentUncertainty {
        expanded_relative_pct: Some(3.0),
    };
    let v = judge(&spec, &lines(&p), None, Some(&BAND), &inst);
    assert_eq!(v.verdict, Verdict::NotDecidable);
    assert_eq!(v.limits[0].lines_undecided, vec![6]);
    assert_eq!(v.limits[0].line_u_pct, 3.0);
    assert_eq!(
        v.limits[0].reason,
        "Rz max rule: none of 10 lines above 6.3 µm, 1 more within U of it"
    );
    // 6.5 is beyond 6.3 by more than its U (0.195): proven non-conforming.
    p[5].rz_um = 6.5;
    assert_eq!(
        judge(&spec, &lines(&p), None, Some(&BAND), &inst).verdict,
        Verdict::DoesNotConform
    );
    // A lower limit alike: L Ra 0.4 with Ra 0.41 and 3 %: U = 0.0123, 0.41 − U < 0.4.
    let mut p: Vec<RoughnessParams> = (0..10).map(|_| params(0.6, 5.0, None)).collect();
    p[2].ra_um = 0.41;
    let spec = Specification::parse(&["L Ra max 0.4"]).unwrap();
    let v = judge(&spec, &lines(&p), None, Some(&BAND), &inst);
    assert_eq!(v.verdict, Verdict::NotDecidable);
    assert!(
        v.limits[0].reason.contains("below 0.4 µm"),
        "{}",
        v.limits[0].reason
    );
}

#[test]
fn a_callout_for_other_conditions_is_named_and_not_decided() {
    let p = surface();
    let spec = Specification::parse(&["0.0025-2.5/Ra 0.8", "Rz3 6.3", "0.008-0.8/Rq 1", "Ra 0.8"])
        .unwrap();
    let v = judge(&spec, &lines(&p), None, Some(&BAND), &Default::default());
    assert_eq!(v.limits[0].verdict, Verdict::NotDecidable);
    assert!(
        v.limits[0].conditions_differ[0].contains("λc = 2.5 mm"),
        "{:?}",
        v.limits[0]
    );
    assert!(v.limits[1].conditions_differ[0].contains("Rz3 is over 3 sampling lengths"));
    assert!(v.limits[2].conditions_differ[0].contains("λs = 0.008 mm"));
    assert_eq!(v.limits[3].verdict, Verdict::Conforms);
    assert_eq!(v.verdict, Verdict::NotDecidable);
    assert!(
        v.summary.starts_with("not decidable (Ra 16 % rule"),
        "{}",
        v.summary
    );
    // The scan evaluated over 3 sampling lengths: `Rz3` matches, a bare `Ra` (5) does not.
    let three = EvaluatedBand {
        sampling_lengths: 3,
        ..BAND
    };
    let v = judge(&spec, &lines(&p), None, Some(&three), &Default::default());
    assert!(v.limits[1].conditions_differ.is_empty());
    assert!(v.limits[3].conditions_differ[0].contains("the default, none written"));
    // Lines that are not roughness profiles decide nothing.
    let v = judge(&spec, &lines(&p), None, None, &Default::default());
    assert!(v.limits.iter().all(|l| l.verdict == Verdict::NotDecidable));
}

#[test]
fn lines_without_a_value_are_not_measured_values() {
    let mut p = surface();
    p[3].rsm_um = None;
    p[4].rsm_um = None;
    let spec = Specification::parse(&["RSm 120"]).unwrap();
    let v = judge(&spec, &lines(&p), None, Some(&BAND), &Default::default());
    assert_eq!(v.limits[0].n_values, 29);
    assert_eq!(v.limits[0].lines_without_value, vec![4, 5]);
    let p: Vec<RoughnessParams> = (0..6).map(|_| params(0.5, 5.0, None)).collect();
    let v = judge(&spec, &lines(&p), None, Some(&BAND), &Default::default());
    assert_eq!(v.verdict, Verdict::NotDecidable);
    assert!(v.limits[0].reason.contains("no line has a value of RSm"));
}

#[test]
fn limits_that_contradict_each_other_are_refused() {
    let e = Specification::parse(&["U Ra 0.3", "L Ra 0.4"]).unwrap_err();
    assert_eq!(e.index, 1);
    assert!(e.message.contains("not below the upper limit"), "{e}");
    let e = Specification::parse(&["L Ra 0.8", "Ra 0.8"]).unwrap_err();
    assert!(e.message.contains("not below"), "{e}");
    let e = Specification::parse(&["Ra 0.8", "U Ra 1.6"]).unwrap_err();
    assert!(e.message.contains("repeats the upper Ra limit"), "{e}");
    // Different rules, bands or evaluation lengths are different limits.
    Specification::parse(&[
        "Rz 6.3",
        "Rz max 8",
        "Rz3 6.3",
        "-2.5/Ra 3",
        "L Ra 0.4",
        "U Ra 1.6",
    ])
    .unwrap();
    let e = Specification::parse(&["Ra 0.8", "Ra0.8x"]).unwrap_err();
    assert_eq!(e.index, 1);
    assert!(e.to_string().starts_with("limits[1]: \"Ra0.8x\""), "{e}");
}

#[test]
fn a_frozen_recipe_text_gives_its_limits_or_names_what_is_wrong() {
    let text = "description = \"x\"\n[plan]\nlines = 5\ny-step-mm = 0.01\n[specification]\nlimits = [\"Ra 0.8\", \"Rz max 6.3\"]\n";
    let s = Specification::of_recipe_text(text).unwrap();
    assert_eq!(
        s.limits.iter().map(|c| c.text.as_str()).collect::<Vec<_>>(),
        ["Ra 0.8", "Rz max 6.3"]
    );
    assert_eq!(s.limits[1].rule, Rule::Max);
    // No [specification]: nothing to judge, not an error.
    assert!(Specification::of_recipe_text("[plan]\nlines = 5\n")
        .unwrap()
        .is_empty());
    let e = Specification::of_recipe_text("[specification]\nlimits = [\"Ra0.8x\"]\n").unwrap_err();
    assert!(e.starts_with("specification.limits[0]:"), "{e}");
    let e = Specification::of_recipe_text("[specification]\nlimits = \"Ra 0.8\"\n").unwrap_err();
    assert!(e.contains("not a list of callouts"), "{e}");
    assert!(Specification::of_recipe_text("[plan\n").is_err());
}

#[test]
fn a_scan_that_ended_after_20_of_31_lines_is_judged_over_the_31() {
    // The first 20 lines of the surface: Rz 7.0 µm on lines 3, 7, 11, 15 and 19.
    let p: Vec<RoughnessParams> = surface().into_iter().take(20).collect();
    let spec = Specification::parse(&["Ra 0.8", "Rz 6.3"]).unwrap();
    let v = judge(
        &spec,
        &lines(&p),
        Some(31),
        Some(&BAND),
        &Default::default(),
    );
    let (ra, rz) = (&v.limits[0], &v.limits[1]);
    // Ra: none of 20 above, but 11 lines not measured might all be (11 of 31 > 16 %).
    assert_eq!(ra.verdict, Verdict::NotDecidable);
    assert_eq!((ra.n_values, ra.n_not_measured, ra.n_allowed), (20, 11, 4));
    // Rz: 5 of 31 (16.1 %) is beyond the rule whatever the 11 hold.
    assert_eq!(rz.verdict, Verdict::DoesNotConform);
    assert_eq!(
        rz.reason,
        "Rz 16 % rule: 5 of 20 lines above 6.3 µm, 11 of the 31 planned lines not measured (counted as undecided) (at most 4 of 31 allowed)"
    );
    assert_eq!(v.verdict, Verdict::DoesNotConform);
    // Over the 20 lines alone Ra would conform: the plan is what keeps it open.
    let alone = judge(&spec, &lines(&p), None, Some(&BAND), &Default::default());
    assert_eq!(alone.limits[0].verdict, Verdict::Conforms);
    assert_eq!(alone.limits[0].n_not_measured, 0);
    // One line short of 21 planned, none above: 1 of 21 counted beyond still meets 16 %.
    let v = judge(
        &spec,
        &lines(&p),
        Some(21),
        Some(&BAND),
        &Default::default(),
    );
    assert_eq!(v.limits[0].verdict, Verdict::Conforms);
    assert_eq!(
        v.limits[0].reason,
        "Ra 16 % rule: none of 20 lines above 0.8 µm, 1 of the 21 planned lines not measured (counted as undecided) (at most 3 of 21 allowed)"
    );
    // Under the max rule a missing line keeps the surface from conforming.
    let max = Specification::parse(&["Ra max 0.8"]).unwrap();
    let v = judge(&max, &lines(&p), Some(21), Some(&BAND), &Default::default());
    assert_eq!(v.verdict, Verdict::NotDecidable);
}

#[test]
fn a_verdict_that_lines_with_warnings_decide_is_not_decidable() {
    // 31 lines, Ra 0.5 µm; under the max rule one line at 0.9 µm decides "does not conform".
    let mut p = surface();
    p[4].ra_um = 0.9;
    let spec = Specification::parse(&["Ra max 0.8", "Rz 6.3"]).unwrap();
    let flag = |flagged: &[usize]| -> Vec<LineValues<'_>> {
        let mut l = lines(&p);
        for &k in flagged {
            l[k].flagged = true;
        }
        l
    };
    // Line 5 (index 4) is the one above, and it was kept with a warning: without it the
    // surface conforms, with it it does not; the limit is not decidable, naming line 5.
    let v = judge(&spec, &flag(&[4]), None, Some(&BAND), &Default::default());
    let ra = &v.limits[0];
    assert_eq!(ra.verdict, Verdict::NotDecidable);
    assert_eq!(ra.lines_with_warnings, vec![5]);
    assert_eq!(ra.verdict_without_them, Some(Verdict::Conforms));
    assert!(
        ra.reason.ends_with(
            "; rests on line 5 kept with a read-out warning: does not conform with it, conforms without"
        ),
        "{}",
        ra.reason
    );
    // Rz: 8 of 31 lines above 6.3 µm fails the 16 % rule whether line 5 counts or not.
    assert_eq!(v.limits[1].verdict, Verdict::DoesNotConform);
    assert_eq!(
        v.limits[1].verdict_without_them,
        Some(Verdict::DoesNotConform)
    );
    assert_eq!(v.verdict, Verdict::DoesNotConform);
    // A flagged line that decides nothing leaves the verdict as it is.
    let v = judge(&spec, &flag(&[0]), None, Some(&BAND), &Default::default());
    assert_eq!(v.limits[0].verdict, Verdict::DoesNotConform);
    assert_eq!(v.limits[0].lines_with_warnings, vec![1]);
    // Every line flagged: nothing is left to judge without them.
    let all: Vec<usize> = (0..31).collect();
    let v = judge(
        &Specification::parse(&["Ra max 0.8"]).unwrap(),
        &flag(&all),
        None,
        Some(&BAND),
        &Default::default(),
    );
    assert_eq!(v.verdict, Verdict::NotDecidable);
    assert!(
        v.summary.contains("rests on lines 1, 2, 3"),
        "{}",
        v.summary
    );
}
