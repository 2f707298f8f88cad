//! The contact section of the characterisation (`surfscan analyze --contact`) end to end
//! through the real binary: report.json's `contact` and report.html's table.
//!
//! Expected values are reasoned independently of the code under test:
//! - a spherical cap scanned with lines 4 µm apart (1 µm along them): the contact of the
//!   measured grid and of the model sampled at 1 µm between the lines against Hertz's contact
//!   radius a = (3FR/(4E*))^(1/3), the load F = nominal pressure × the grid's projected area;
//!   the model of a paraboloid is smooth, so the data support it between lines;
//! - the interpolating model passes through every measured point, so sampled at the lines'
//!   own spacing and x pitch it is the measured grid again: the same contact, point for point;
//! - lines that are each a smooth crest but whose phases are unrelated from line to line: the
//!   model between them is invented, the hold-out says so, and the contact of the model is
//!   reported with that verdict and a warning;
//! - the cap against an elastic flat: Hertz with the composite modulus of the two bodies
//!   (Johnson eq. 4.22, computed here);
//! - bad `--contact…` values are refused (exit 2) naming the value.
use std::path::Path;
use std::process::{Command, Output};

fn surfscan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

const PITCH_X_UM: f64 = 1.0;
const PITCH_Y_UM: f64 = 4.0;
const ROWS: usize = 24;
const COLS: usize = 96;

/// Writes `z(x_um, y_um)` sampled on the ROWS × COLS grid as a CSV of µm heights.
fn write_grid(path: &Path, z: impl Fn(f64, f64) -> f64) {
    let mut s = String::new();
    for i in 0..ROWS {
        let row: Vec<String> = (0..COLS)
            .map(|j| format!("{}", z(j as f64 * PITCH_X_UM, i as f64 * PITCH_Y_UM)))
            .collect();
        s.push_str(&row.join(","));
        s.push('\n');
    }
    std::fs::write(path, s).unwrap();
}

/// `surfscan analyze INPUT --contact … --out OUT`; returns report.json.
fn analyze(input: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let o = surfscan()
        .arg("analyze")
        .arg(input)
        .args(["--pitch-x", "0.001", "--pitch-y", "0.004", "--z-unit", "um"])
        .args(["--no-filter", "--lc", "0.025", "--contact"])
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(
        o.status.code() == Some(0) || o.status.code() == Some(3),
        "{}",
        stderr(&o)
    );
    serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap()
}

/// `analyze --contact` of the crests, written to `dir`/crests.csv, at `pressures` (MPa, comma
/// separated) with the model sampled every `model_pitch_y` mm; the report (in `dir`/out).
fn analyze_crests_model(dir: &Path, pressures: &str, model_pitch_y: &str) -> serde_json::Value {
    let input = dir.join("crests.csv");
    write_grid(&input, crests);
    analyze(
        &input,
        &dir.join("out"),
        &[
            "--contact-pressures",
            pressures,
            "--contact-model-pitch-y",
            model_pitch_y,
        ],
    )
}

/// Steel on a rigid flat: E* = 210 / (1 − 0.3²) GPa, in MPa.
const E_STAR_MPA: f64 = 210_000.0 / 0.91;
const R_UM: f64 = 2000.0;
/// The load making a = 20 µm.
fn hertz_pressure_mpa() -> f64 {
    let force = 4.0 * E_STAR_MPA * 20f64.powi(3) / (3.0 * R_UM);
    force / ((COLS as f64 * PITCH_X_UM) * (ROWS as f64 * PITCH_Y_UM))
}

fn cap(x: f64, y: f64) -> f64 {
    let (xc, yc) = (
        (COLS - 1) as f64 * PITCH_X_UM / 2.0,
        (ROWS - 1) as f64 * PITCH_Y_UM / 2.0,
    );
    -((x - xc).powi(2) + (y - yc).powi(2)) / (2.0 * R_UM)
}

/// Each line a smooth crest (wavelength 37 µm, not a divisor of the 96 µm line, 0.5 µm
/// high) at a phase unrelated to its neighbours'.
fn crests(x: f64, y: f64) -> f64 {
    let line = (y / PITCH_Y_UM).round() as u64;
    let phase = ((line * 2654435761) % 1000) as f64 / 1000.0 * std::f64::consts::TAU;
    0.5 * (x * std::f64::consts::TAU / 37.0 + phase).sin()
}

#[test]
fn cap_contact_of_grid_and_model_between_lines_follow_hertz() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("cap.csv");
    write_grid(&input, cap);
    let p = hertz_pressure_mpa();
    let pressures = format!("{p}");
    let report = analyze(
        &input,
        &dir.path().join("out"),
        &[
            "--contact-pressures",
            &pressures,
            "--contact-model-pitch-y",
            "0.001",
        ],
    );
    let c = &report["contact"];
    assert!((c["effective_modulus_gpa"].as_f64().unwrap() - E_STAR_MPA / 1000.0).abs() < 1e-9);
    let area_um2 = (COLS as f64 * PITCH_X_UM) * (ROWS as f64 * PITCH_Y_UM);
    let hertz = std::f64::consts::PI * 400.0 / area_um2;
    let measured = &c["measured"];
    assert_eq!(measured["rows"], ROWS, "{c}");
    let got = measured["curve"][0]["area_fraction"].as_f64().unwrap();
    // Ten lines across the contact: its area counted in 4 µm × 1 µm pixels within 8 %.
    assert!(
        (got - hertz).abs() < 0.08 * hertz,
        "measured {got}, Hertz {hertz}"
    );
    // The model: sampled every 1 µm from the first line to the last, at the data's x pitch.
    let m = &c["model"];
    assert_eq!(m["supported"], true, "{m}");
    assert_eq!(m["verdict"], report["between_lines"]["verdict"]);
    let mc = &m["contact"];
    assert_eq!(mc["rows"], (ROWS - 1) * 4 + 1, "{m}");
    assert_eq!(mc["cols"], COLS);
    assert!((mc["pitch_y_mm"].as_f64().unwrap() - 0.001).abs() < 1e-15);
    let got = mc["curve"][0]["area_fraction"].as_f64().unwrap();
    // 1 µm pixels over the model's slightly smaller area (the last line is at 92 µm).
    let model_area_um2 = COLS as f64 * PITCH_X_UM * ((ROWS - 1) * 4 + 1) as f64;
    let force = p * area_um2;
    let model_hertz = std::f64::consts::PI
        * (3.0 * force * R_UM / (4.0 * E_STAR_MPA)).powf(2.0 / 3.0)
        / model_area_um2;
    let model_p = mc["curve"][0]["nominal_pressure_mpa"].as_f64().unwrap();
    assert!(
        (model_p - p).abs() < 1e-12 * p,
        "the same nominal pressure on both: {model_p} vs {p}"
    );
    // The same nominal pressure over a smaller area is a smaller load: Hertz's a for it.
    let model_force = p * model_area_um2;
    let a = (3.0 * model_force * R_UM / (4.0 * E_STAR_MPA)).cbrt();
    let model_hertz_same_p = std::f64::consts::PI * a * a / model_area_um2;
    assert!(
        (got - model_hertz_same_p).abs() < 0.04 * model_hertz_same_p,
        "model {got}, Hertz {model_hertz_same_p} (at the grid's load {model_hertz})"
    );
    assert_eq!(mc["curve"][0]["patches"], 1);
    // report.html shows the table and the verdict.
    let html = std::fs::read_to_string(dir.path().join("out/report.html")).unwrap();
    assert!(html.contains("id=\"t-contact\""), "the contact table");
    assert!(
        html.contains("id=\"contact-verdict\""),
        "the verdict beside it"
    );
    assert!(
        !html.contains("the data do not support."),
        "a supported model"
    );
}

#[test]
fn cap_against_an_elastic_flat_follows_hertz_with_the_composite_modulus() {
    // Aluminium (70 GPa, ν 0.33) against the steel cap: 1/E* = 0.91/210 + (1 − 0.33²)/70,
    // about a quarter of steel on a rigid flat, so the same load makes a contact radius
    // (E*_rigid/E*)^(1/3) ≈ 1.58 times larger (Hertz).
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("cap.csv");
    write_grid(&input, cap);
    let p = hertz_pressure_mpa();
    let pressures = format!("{p}");
    let report = analyze(
        &input,
        &dir.path().join("out"),
        &[
            "--contact-pressures",
            &pressures,
            "--contact-young2",
            "70",
            "--contact-poisson2",
            "0.33",
        ],
    );
    let c = &report["contact"];
    let e_star_mpa = 1000.0 / (0.91 / 210.0 + (1.0 - 0.33 * 0.33) / 70.0);
    assert!(
        (c["effective_modulus_gpa"].as_f64().unwrap() - e_star_mpa / 1000.0).abs() < 1e-9,
        "{c}"
    );
    assert_eq!(c["counter_body"]["young_gpa"], 70.0, "{c}");
    assert_eq!(c["counter_body"]["poisson"], 0.33, "{c}");
    assert_eq!(c["specimen"]["young_gpa"], 210.0, "{c}");
    let area_um2 = (COLS as f64 * PITCH_X_UM) * (ROWS as f64 * PITCH_Y_UM);
    let a = (3.0 * p * area_um2 * R_UM / (4.0 * e_star_mpa)).cbrt();
    let hertz = std::f64::consts::PI * a * a / area_um2;
    let got = c["measured"]["curve"][0]["area_fraction"].as_f64().unwrap();
    assert!(
        (got - hertz).abs() < 0.08 * hertz,
        "measured {got}, Hertz with the composite modulus {hertz}"
    );
    let html = std::fs::read_to_string(dir.path().join("out/report.html")).unwrap();
    assert!(
        html.contains("against an elastic flat (E 70 GPa, ν 0.33)"),
        "the counter-body in report.html"
    );
}

#[test]
fn model_sampled_at_the_lines_own_spacing_is_the_measured_grid_again() {
    // Not the cap: a shift along x or y would leave its levelled contact as it is.
    let dir = tempfile::tempdir().unwrap();
    let report = analyze_crests_model(dir.path(), "5,50", "0.004");
    let c = &report["contact"];
    let (g, m) = (&c["measured"], &c["model"]["contact"]);
    assert_eq!(m["rows"], ROWS, "{c}");
    let n = (ROWS * COLS) as f64;
    for (a, b) in g["curve"]
        .as_array()
        .unwrap()
        .iter()
        .zip(m["curve"].as_array().unwrap())
    {
        let f = |p: &serde_json::Value, k: &str| p[k].as_f64().unwrap();
        assert!(
            (f(a, "area_fraction") - f(b, "area_fraction")).abs() <= 1.0 / n,
            "{a} vs {b}"
        );
        assert!(
            (f(a, "mean_gap_um") - f(b, "mean_gap_um")).abs() <= 1e-5 * f(a, "mean_gap_um"),
            "{a} vs {b}"
        );
    }
}

#[test]
fn contact_of_an_unsupported_model_is_reported_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let report = analyze_crests_model(dir.path(), "50", "0.002");
    assert_eq!(
        report["between_lines"]["supported"], false,
        "{}",
        report["between_lines"]
    );
    let m = &report["contact"]["model"];
    assert_eq!(m["supported"], false, "{m}");
    assert_eq!(m["verdict"], report["between_lines"]["verdict"]);
    assert!(
        m["contact"]["curve"][0]["area_fraction"].as_f64().unwrap() > 0.0,
        "{m}"
    );
    let warnings = crate::common::report_warnings(&report);
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("contact.model is computed on a model the data do not support")),
        "{warnings:?}"
    );
    let html = std::fs::read_to_string(dir.path().join("out/report.html")).unwrap();
    assert!(
        html.contains("computed on a surface the data do not support."),
        "the verdict beside the model's contact"
    );
}

#[test]
fn bad_contact_options_are_refused_naming_the_value() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("cap.csv");
    write_grid(&input, cap);
    for (args, says) in [
        (vec!["--contact", "--contact-young", "-1"], "-1"),
        (vec!["--contact", "--contact-pressures", "10,-5"], "-5"),
        (
            vec![
                "--contact",
                "--contact-hardness",
                "0.01",
                "--contact-pressures",
                "20",
            ],
            "beyond full contact",
        ),
        (
            vec!["--contact", "--contact-model-pitch-y", "0"],
            "--contact-model-pitch-y",
        ),
        (vec!["--contact-pressures", "10"], "--contact"),
        (
            vec!["--contact", "--contact-young2", "5000"],
            "Young's modulus of the counter-body",
        ),
        (
            vec!["--contact", "--contact-poisson2", "0.3"],
            "--contact-young2",
        ),
    ] {
        let o = surfscan()
            .arg("analyze")
            .arg(&input)
            .args(["--pitch-x", "0.001", "--pitch-y", "0.004", "--z-unit", "um"])
            .args(&args)
            .arg("--out")
            .arg(dir.path().join("bad"))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{args:?}: {}", stderr(&o));
        assert!(!dir.path().join("bad/report.json").exists(), "{args:?}");
    }
}

/// A contact that cannot be computed costs the contact, not the report: uncorrelated heights
/// are too coarse to resolve it, named in `failed_sections` and `measured_error` (exit 3,
/// partial), and no contact.json is written.
#[test]
fn a_contact_the_grid_cannot_resolve_is_named_and_the_report_kept() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("noise.csv");
    write_grid(&input, |x, y| {
        let k = (y / PITCH_Y_UM).round() as u64 * COLS as u64 + x.round() as u64;
        (k * 2654435761 % 1000) as f64 / 1000.0
    });
    let out = dir.path().join("out");
    let o = surfscan()
        .arg("analyze")
        .arg(&input)
        .args(["--pitch-x", "0.001", "--pitch-y", "0.004", "--z-unit", "um"])
        .args(["--no-filter", "--lc", "0.025", "--contact"])
        .args(["--contact-pressures", "0.01,0.1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let why = report["contact"]["measured_error"].as_str().unwrap();
    assert!(why.contains("too coarse to resolve contact"), "{why}");
    let failed = report["characterisation"]["failed_sections"]
        .as_array()
        .unwrap();
    assert!(
        failed
            .iter()
            .any(|f| f["section"] == "contact" && f["reason"].as_str() == Some(why)),
        "named among the failed sections: {failed:?}"
    );
    assert!(
        report["surface_grid"].is_object(),
        "the rest of the report is there"
    );
    assert!(!out.join("contact.json").exists());
}
