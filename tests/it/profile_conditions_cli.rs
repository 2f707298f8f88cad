//! `surfscan analyze` of a profile under stated input conditions, against closed forms:
//! the λs filter (`--ls`, ISO 16610-21's Gaussian transmission), the form-only evaluation
//! (`--form`: a stated form removed, no λc), ISO 4288's cut-off check naming the band the
//! result falls in, the whole-evaluation-length moments beside the per-sampling-length means,
//! and both material-ratio readings of the Mitutoyo export (ISO's, and the SJ series' which
//! reproduces the instrument's printout).

use serde_json::Value;
use std::f64::consts::PI;
use std::path::Path;
use std::process::Command;

/// Writes a profile CSV of `n` points at `pitch_mm` with heights `z(x_mm)`.
fn profile(path: &Path, n: usize, pitch_mm: f64, z: impl Fn(f64) -> f64) {
    let mut s = String::from("x_mm,z_um\n");
    for i in 0..n {
        let x = i as f64 * pitch_mm;
        s.push_str(&format!("{x:.6},{:.9}\n", z(x)));
    }
    std::fs::write(path, s).unwrap();
}

/// report.json and stdout of `surfscan analyze input args… --out`.
fn analyze(input: &Path, args: &[&str]) -> (Value, String) {
    let out = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(input)
        .args(args)
        .arg("--out")
        .arg(out.path())
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "analyze {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let report =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("report.json")).unwrap())
            .unwrap();
    (report, String::from_utf8_lossy(&o.stdout).into_owned())
}

fn close(what: &str, got: f64, want: f64, rel: f64) {
    assert!(
        (got - want).abs() <= rel * want.abs(),
        "{what}: {got}, want {want} within {} %",
        rel * 100.0
    );
}

#[test]
fn ls_removes_what_its_gaussian_transmission_says() {
    // A 200 µm wave of amplitude 1 µm and a 2 µm wave of 0.5 µm. λs 8 µm passes the first
    // (transmission exp(-π (α·8/200)²) = 0.9989, α = √(ln 2 / π)) and removes the second
    // (exp(-π (α·8/2)²) < 2e-5); λc 0.8 mm passes both.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("two.csv");
    profile(&csv, 16000, 0.00025, |x| {
        (2.0 * PI * x / 0.2).cos() + 0.5 * (2.0 * PI * x / 0.002).cos()
    });
    let alpha = (2f64.ln() / PI).sqrt();
    let pass = (-PI * (alpha * 8.0 / 200.0).powi(2)).exp();
    let (plain, _) = analyze(&csv, &[]);
    close(
        "Rq without λs",
        plain["lines"][0]["Rq_um"].as_f64().unwrap(),
        (0.5f64 + 0.125).sqrt(),
        0.01,
    );
    let (filtered, stdout) = analyze(&csv, &["--ls", "8"]);
    close(
        "Rq with λs 8 µm",
        filtered["lines"][0]["Rq_um"].as_f64().unwrap(),
        pass / 2f64.sqrt(),
        0.01,
    );
    assert_eq!(filtered["recipe"]["lambda_s_um"].as_f64(), Some(8.0));
    assert!(
        stdout.contains("λs 8 µm, λc 0.8 mm filter applied"),
        "{stdout}"
    );
}

#[test]
fn a_form_only_evaluation_removes_the_stated_form_and_gives_p_parameters() {
    // 10 µm/mm of tilt and a 100 µm cosine of amplitude 1 µm over 40 whole periods: the
    // least-squares line is the tilt (the cosine is orthogonal to 1 and x there), and the
    // primary profile left is the cosine, Pa = 2/π, Pq = 1/√2, Pz = 2 µm.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("tilt.csv");
    profile(&csv, 4001, 0.001, |x| 10.0 * x + (2.0 * PI * x / 0.1).cos());
    let (r, stdout) = analyze(&csv, &["--form", "line"]);
    assert_eq!(r["recipe"]["profile"], "P", "{}", r["recipe"]);
    let l = &r["lines"][0];
    close("Pa", l["Ra_um"].as_f64().unwrap(), 2.0 / PI, 1e-3);
    close("Pq", l["Rq_um"].as_f64().unwrap(), 0.5f64.sqrt(), 1e-3);
    close("Pz", l["Rz_um"].as_f64().unwrap(), 2.0, 1e-3);
    assert!(
        stdout.contains("least-squares straight line removed, no λc filter: Pa 0.6365"),
        "{stdout}"
    );
    // With the tilt left in (no form, no filter) the same profile is 10 µm/mm off: the
    // form-only mode is what makes the difference.
    let (raw, _) = analyze(&csv, &["--no-filter"]);
    assert!(raw["lines"][0]["Ra_um"].as_f64().unwrap() > 5.0);
    let bad = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["analyze", csv.to_str().unwrap(), "--form", "poly9"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("poly2"));
}

#[test]
fn the_cut_off_check_names_the_band_the_result_falls_in() {
    // Ra 2/π µm and Rz 2 µm are both in ISO 4288's 0.8 mm band (Ra 0.1 … 2 µm, Rz 0.5 …
    // 10 µm): λc 0.8 mm fits, λc 2.5 mm does not.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("cos.csv");
    profile(&csv, 8001, 0.001, |x| (2.0 * PI * x / 0.1).cos());
    let (fits, _) = analyze(&csv, &["--lc", "0.8"]);
    let words = |r: &Value| r["warnings"].to_string();
    assert!(!words(&fits).contains("ISO 4288"), "{}", words(&fits));
    let (wide, _) = analyze(&csv, &["--lc", "2.5"]);
    let w = words(&wide);
    assert!(
        w.contains("λc 2.5 mm does not fit the result")
            && w.contains("µm falls in ISO 4288's 0.8 mm band (Ra > 0.1 … 2 µm)")
            && w.contains("µm falls in ISO 4288's 0.8 mm band (Rz > 0.5 … 10 µm)"),
        "{w}"
    );
}

#[test]
fn whole_length_moments_stand_beside_the_sampling_length_means() {
    // One sampling length holds a tall spike, the others none: per-sampling-length Rsk is
    // the mean of one large and four zero skews, the whole-length Rsk that of one profile.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("spike.csv");
    let n = 4000;
    let pitch = 0.001;
    let z = |i: usize| {
        let x = i as f64 * pitch;
        let base = (2.0 * PI * x / 0.05).cos();
        if (300..303).contains(&i) {
            base + 20.0
        } else {
            base
        }
    };
    let mut s = String::from("x_mm,z_um\n");
    for i in 0..n {
        s.push_str(&format!("{:.6},{:.9}\n", i as f64 * pitch, z(i)));
    }
    std::fs::write(&csv, s).unwrap();
    let (r, _) = analyze(&csv, &["--no-filter", "--lc", "0.8"]);
    let l = &r["lines"][0];
    // The whole length about the zero line, by the definitions.
    let zs: Vec<f64> = (0..n).map(z).collect();
    let m = |k: i32| zs.iter().map(|v| v.powi(k)).sum::<f64>() / n as f64;
    let rq = m(2).sqrt();
    close(
        "Rq_ln",
        l["evaluation_length"]["Rq_ln_um"].as_f64().unwrap(),
        rq,
        1e-6,
    );
    close(
        "Rsk_ln",
        l["evaluation_length"]["Rsk_ln"].as_f64().unwrap(),
        m(3) / rq.powi(3),
        1e-6,
    );
    close(
        "Rku_ln",
        l["evaluation_length"]["Rku_ln"].as_f64().unwrap(),
        m(4) / rq.powi(4),
        1e-6,
    );
    let mean_rsk = l["Rsk"].as_f64().unwrap();
    let ln_rsk = l["evaluation_length"]["Rsk_ln"].as_f64().unwrap();
    assert!(
        (mean_rsk - ln_rsk).abs() > 0.5,
        "the two conventions differ here: {mean_rsk} and {ln_rsk}"
    );
}

#[test]
fn both_material_ratio_readings_of_the_mitutoyo_export_are_reported_iso_first() {
    let csv = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/real/mitutoyo_surftest_R.x_mm_z_um.csv");
    let (r, summary) = analyze(&csv, &["--no-filter", "--lc", "2.5"]);
    let l = &r["lines"][0];
    // ISO's continuous reading as it was (docs/metrology.md: Rpk 2.722 µm) …
    close("ISO Rpk", l["Rpk_um"].as_f64().unwrap(), 2.722, 2e-4);
    // … and the SJ series' under the ISO names, the instrument's printout to its digit.
    let sj = &l["material_ratio_sj_series"];
    for (key, printed, unit) in [
        ("Rpk_um", 2.912, 1e-3),
        ("Rvk_um", 3.980, 1e-3),
        ("Mr1_pct", 5.822, 1e-3),
        ("Mr2_pct", 92.617, 1e-3),
        ("Rmr_pct", 0.030, 1e-3),
        ("A1", 8.48, 1e-2),
        ("A2", 14.69, 1e-2),
    ] {
        let got = sj[key].as_f64().unwrap();
        assert!(
            (got - printed).abs() <= unit * 1.000_001,
            "{key}: {got} against the printed {printed}"
        );
    }
    let rmr_c: Vec<f64> = sj["Rmr(c)"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["value_pct"].as_f64().unwrap())
        .collect();
    assert!((rmr_c[0] - 2.911).abs() <= 1e-3 && (rmr_c[1] - 5.822).abs() <= 1e-3);
    close("SJ Rk", sj["Rk_um"].as_f64().unwrap(), 11.440, 2e-3);
    assert!(sj["convention"].as_str().unwrap().contains("100 levels"));
    // The summary line gives ISO's reading by default …
    assert!(
        summary.contains("Rpk 2.722 µm") && !summary.contains("SJ series"),
        "{summary}"
    );
    assert_eq!(r["recipe"]["material_ratio"], "iso");
    // … and the instrument's, as its display shows it, when asked for; report.json keeps
    // both readings, ISO's under the plain names.
    let (r, summary) = analyze(
        &csv,
        &[
            "--no-filter",
            "--lc",
            "2.5",
            "--material-ratio",
            "instrument",
        ],
    );
    assert!(
        summary.contains("Rpk 2.912 µm, Rvk 3.980 µm (as the SJ series reads them)"),
        "{summary}"
    );
    assert_eq!(r["recipe"]["material_ratio"], "instrument");
    close(
        "ISO Rpk",
        r["lines"][0]["Rpk_um"].as_f64().unwrap(),
        2.722,
        2e-4,
    );
    // A reading that is neither is a usage error naming both.
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(&csv)
        .args(["--material-ratio", "sj"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("iso") && err.contains("instrument"), "{err}");
}
