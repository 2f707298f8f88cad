//! `surfscan contact` and `surfscan fit --step` end to end through the real binary.
//!
//! The contact of a spherical cap written as a grid CSV is checked against Hertz's solution
//! with the composite modulus of two elastic bodies (E* = E/(2(1 − ν²)) for two equal ones),
//! computed here from the formulas, not by the code under test: the contact radius
//! a = (3FR/(4E*))^(1/3) for the load F = nominal pressure × the grid's projected area
//! (columns × x pitch by rows × y pitch). The outputs, the refusals of bad input with their
//! exit statuses, and the STEP solid of a tilted plane — whose volume OpenCascade measures
//! against the block's volume integrated by hand — are checked as a user meets them.
use super::common::{json_from, reference_script};
use std::process::Command;

fn surfscan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
}

/// A spherical cap of radius `r_um` on a `n` × `n` grid at 1 µm, its apex at the centre:
/// z = −ρ²/(2R) µm.
fn cap_csv(n: usize, r_um: f64) -> String {
    let c = (n - 1) as f64 / 2.0;
    let mut s = String::new();
    for i in 0..n {
        let row: Vec<String> = (0..n)
            .map(|j| {
                let (x, y) = (j as f64 - c, i as f64 - c);
                format!("{}", -(x * x + y * y) / (2.0 * r_um))
            })
            .collect();
        s.push_str(&row.join(","));
        s.push('\n');
    }
    s
}

/// `n` × `n` heights in 0…1 µm, each from a multiplicative hash of its index: no correlation
/// between neighbours.
fn noise_csv(n: usize) -> String {
    let mut s = String::new();
    for i in 0..n {
        let row: Vec<String> = (0..n)
            .map(|j| format!("{}", ((i * n + j) * 2654435761 % 1000) as f64 / 1000.0))
            .collect();
        s.push_str(&row.join(","));
        s.push('\n');
    }
    s
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn sphere_against_an_elastic_flat_follows_hertz_and_writes_curve_and_maps() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("cap.csv");
    let (n, r_um) = (64usize, 1000.0);
    std::fs::write(&input, cap_csv(n, r_um)).unwrap();
    let out = dir.path().join("new/contact");
    let o = surfscan()
        .arg("contact")
        .arg(&input)
        .args(["--pitch-x", "0.001", "--pitch-y", "0.001", "--z-unit", "um"])
        .args(["--young", "210", "--poisson", "0.3"])
        .args(["--young2", "210", "--poisson2", "0.3"])
        .args(["--pressures", "50,100", "--map-pressure", "100", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("contact.json")).unwrap()).unwrap();
    // Two equal steel bodies: E* = 210 / (2 · 0.91) GPa.
    let e_star_gpa = 210.0 / (2.0 * (1.0 - 0.09));
    let got = doc["effective_modulus_gpa"].as_f64().unwrap();
    assert!((got - e_star_gpa).abs() < 1e-9 * e_star_gpa, "{got}");
    let curve = doc["curve"].as_array().unwrap();
    assert_eq!(curve.len(), 2, "{doc}");
    let area_um2 = (n * n) as f64; // 1 µm pixels
    for (point, p_mpa) in curve.iter().zip([50.0, 100.0]) {
        assert_eq!(point["nominal_pressure_mpa"].as_f64().unwrap(), p_mpa);
        let force = p_mpa * area_um2; // MPa · µm² = µN
        let a = (3.0 * force * r_um / (4.0 * e_star_gpa * 1000.0)).cbrt();
        let hertz = std::f64::consts::PI * a * a / area_um2;
        let fraction = point["area_fraction"].as_f64().unwrap();
        // A contact about 25 pixels across: its area counted in pixels is within a few %.
        assert!(
            (fraction - hertz).abs() < 0.05 * hertz,
            "at {p_mpa} MPa: area fraction {fraction}, Hertz {hertz}"
        );
        assert_eq!(point["patches"], 1, "{point}");
        let mean_contact = point["mean_contact_pressure_mpa"].as_f64().unwrap();
        assert!((mean_contact - p_mpa / fraction).abs() < 1e-9 * mean_contact);
        // The mean gap counts every point, a contact point as 0: below the mean depth of the
        // cap under its apex (the flat has moved down onto it) and positive.
        let gap = point["mean_gap_um"].as_f64().unwrap();
        let c = (n - 1) as f64 / 2.0;
        let mean_depth: f64 = (0..n * n)
            .map(|k| {
                let (x, y) = ((k % n) as f64 - c, (k / n) as f64 - c);
                (x * x + y * y) / (2.0 * r_um)
            })
            .sum::<f64>()
            / area_um2;
        assert!(
            gap > 0.0 && gap < mean_depth,
            "gap {gap}, mean depth {mean_depth}"
        );
    }
    // More load, more area, less gap.
    assert!(curve[1]["area_fraction"].as_f64() > curve[0]["area_fraction"].as_f64());
    assert!(curve[1]["mean_gap_um"].as_f64() < curve[0]["mean_gap_um"].as_f64());
    assert_eq!(doc["grid"]["rows"], n);
    assert_eq!(doc["grid"]["cols"], n);
    assert_eq!(doc["hardness_gpa"], serde_json::Value::Null);
    assert_eq!(doc["map"]["nominal_pressure_mpa"], 100.0);
    for f in [
        "load_area.png",
        "load_area.svg",
        "pressure.png",
        "pressure.svg",
    ] {
        let bytes = std::fs::read(out.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(bytes.len() > 1000, "{f} is {} bytes", bytes.len());
    }
    let svg = std::fs::read_to_string(out.join("pressure.svg")).unwrap();
    assert!(
        svg.contains("contact pressure (MPa)"),
        "the map's colour bar"
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("contact.json"), "{stdout}");
}

/// A window of sur-2 (real measured brass, 8 lines × 160 points; smooth, Sq about 2 nm, so
/// the hardness is set low) at 5 MPa, elastic and perfectly plastic at 10 MPa: the elastic
/// contact pressure exceeds 10 MPa on average, the plastic one has points at the hardness
/// and none above it, and a larger area carries the same load.
#[test]
fn plastic_contact_of_a_measured_window_flows_at_the_hardness() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/sur-2.grid.csv"
    ))
    .unwrap();
    let window: Vec<String> = text
        .lines()
        .take(8)
        .map(|l| l.split(',').take(160).collect::<Vec<_>>().join(","))
        .collect();
    let input = dir.path().join("window.csv");
    std::fs::write(&input, window.join("\n")).unwrap();
    let run = |extra: &[&str]| {
        let o = surfscan()
            .arg("contact")
            .arg(&input)
            .args([
                "--pitch-x",
                "0.003484",
                "--pitch-y",
                "0.010452",
                "--z-unit",
                "um",
            ])
            .args([
                "--young",
                "100",
                "--poisson",
                "0.34",
                "--pressures",
                "5",
                "--out",
            ])
            .arg(dir.path())
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let doc: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("contact.json")).unwrap())
                .unwrap();
        doc["curve"][0].clone()
    };
    let elastic = run(&[]);
    let plastic = run(&["--hardness", "0.01"]);
    assert_eq!(elastic["plastic_fraction"], 0.0);
    assert!(
        elastic["mean_contact_pressure_mpa"].as_f64().unwrap() > 10.0,
        "{elastic}"
    );
    assert!(
        plastic["plastic_fraction"].as_f64().unwrap() > 0.0,
        "{plastic}"
    );
    assert!(
        plastic["area_fraction"].as_f64() > elastic["area_fraction"].as_f64(),
        "{plastic} vs {elastic}"
    );
    assert!(plastic["mean_contact_pressure_mpa"].as_f64().unwrap() <= 10.0 + 1e-6);
}

#[test]
fn bad_input_is_refused_with_its_cause_and_status() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap.csv");
    std::fs::write(&cap, cap_csv(32, 1000.0)).unwrap();
    let tiny = dir.path().join("tiny.csv");
    std::fs::write(&tiny, "0,1,0\n1,2,1\n0,1,0\n").unwrap();
    let flat = dir.path().join("flat.csv");
    std::fs::write(&flat, "1,1,1,1,1\n".repeat(5)).unwrap();
    let noise = dir.path().join("noise.csv");
    std::fs::write(&noise, noise_csv(16)).unwrap();
    let cases: [(&std::path::Path, &[&str], i32, &str); 9] = [
        (
            &cap,
            &["--young", "0"],
            2,
            "Young's modulus of the specimen",
        ),
        (
            &cap,
            &["--poisson", "0.7"],
            2,
            "Poisson's ratio of the specimen",
        ),
        (&cap, &["--young2", "5000"], 2, "counter-body"),
        (
            &cap,
            &["--hardness", "0.05", "--pressures", "10,100"],
            2,
            "beyond full contact",
        ),
        (&tiny, &[], 1, "too small to resolve contact"),
        (&flat, &[], 1, "whole grid is in contact"),
        // A rough surface closes at a load far beyond its asperities' reach; the message
        // names the last load that left part of it open.
        (
            &cap,
            &["--pressures", "1,1000000"],
            1,
            "at 1000000 MPa the whole grid is in contact: the load is at or beyond full contact; give lower pressures (at 1 MPa part of the surface was still open)",
        ),
        // Heights uncorrelated from point to point touch at isolated points only.
        (
            &noise,
            &["--pressures", "0.01,0.1"],
            1,
            "(16 × 16 points, pitch 0.001 mm along x, 0.001 mm between lines) is too coarse to resolve contact",
        ),
        // Three iterations cannot solve the cap: the message says how far they got.
        (
            &cap,
            &["--max-iterations", "3", "--pressures", "1"],
            1,
            "the contact at 1 MPa did not converge in 3 iterations (complementarity residual",
        ),
    ];
    for (input, extra, code, says) in cases {
        let o = surfscan()
            .arg("contact")
            .arg(input)
            .args(["--pitch-x", "0.001", "--pitch-y", "0.001", "--z-unit", "um"])
            .arg("--out")
            .arg(dir.path().join("out"))
            .args(extra)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(code), "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{extra:?}: {}", stderr(&o));
        assert!(
            !dir.path().join("out/contact.json").exists(),
            "{extra:?} wrote a result"
        );
    }
    // The iteration limit is at least 1.
    let o = surfscan()
        .arg("contact")
        .arg(&cap)
        .args(["--max-iterations", "0"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--max-iterations"), "{}", stderr(&o));
    // --poisson2 alone names the missing --young2.
    let o = surfscan()
        .arg("contact")
        .arg(&cap)
        .args(["--poisson2", "0.3"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--young2"), "{}", stderr(&o));
}

/// `fit --step` on a tilted plane z = 0.5·x + 0.25·y (mm): OpenCascade finds one valid
/// solid whose volume is the block's, computed here from the plane: the area times (the
/// plane's mean height − the bottom), the bottom `depth` below the lowest corner (z = 0).
#[test]
fn fit_writes_a_step_solid_opencascade_finds_valid_with_the_planes_volume() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols, px, py) = (7usize, 12usize, 0.01, 0.02);
    let mut csv = String::new();
    for r in 0..rows {
        let line: Vec<String> = (0..cols)
            .map(|c| format!("{}", 1000.0 * (0.5 * c as f64 * px + 0.25 * r as f64 * py)))
            .collect();
        csv.push_str(&line.join(","));
        csv.push('\n');
    }
    let input = dir.path().join("plane.csv");
    std::fs::write(&input, csv.as_bytes()).unwrap();
    let step = dir.path().join("solid/plane.step");
    let report = dir.path().join("fit.json");
    let depth = 0.1;
    let o = surfscan()
        .arg("fit")
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("plane.igs"))
        .args(["--pitch-x", "0.01", "--pitch-y", "0.02", "--solid-depth-mm"])
        .arg(depth.to_string())
        .arg("--step")
        .arg(&step)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let bottom = rep["step"]["bottom_z_mm"].as_f64().unwrap();
    assert!((bottom + depth).abs() < 1e-9, "{}", rep["step"]);
    let y_mm: Vec<f64> = (0..rows).map(|r| r as f64 * py).collect();
    let r = json_from(
        reference_script("check_step_occt.py")
            .arg(&step)
            .arg(&input)
            .arg(px.to_string())
            .arg(serde_json::to_string(&y_mm).unwrap())
            .arg(bottom.to_string())
            .arg("0"),
    );
    assert_eq!(r["solids"], 1, "{r}");
    assert_eq!(r["faces"], 6, "{r}");
    assert_eq!(r["valid"], true, "BRepCheck_Analyzer: {r}");
    let (lx, ly) = ((cols - 1) as f64 * px, (rows - 1) as f64 * py);
    let expected = lx * ly * (0.5 * lx / 2.0 + 0.25 * ly / 2.0 + depth);
    let volume = r["volume_mm3"].as_f64().unwrap();
    assert!(
        (volume - expected).abs() < 1e-6 * expected,
        "OpenCascade {volume} mm³, the plane's block {expected} mm³"
    );
    // A depth that is not a length is refused before anything is fitted or written.
    let o = surfscan()
        .arg("fit")
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("again.igs"))
        .args([
            "--pitch-x",
            "0.01",
            "--pitch-y",
            "0.02",
            "--solid-depth-mm=-1",
        ])
        .arg("--step")
        .arg(dir.path().join("again.step"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--solid-depth-mm"), "{}", stderr(&o));
    assert!(!dir.path().join("again.igs").exists());
    assert!(!dir.path().join("again.step").exists());
}
