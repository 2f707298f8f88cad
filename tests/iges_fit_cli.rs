//! `surfscan fit` end to end through the real binary: output directory creation, a readable
//! IGES file whose surface interpolates the grid, the JSON report, and exit codes for bad input.
use std::process::Command;

fn surfscan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
}

/// Heights (µm) of the tilted plane z_mm = 0.5·x_mm + 0.25·y_mm. Interpolation is linear in
/// the data, so the poles and every surface point satisfy the same plane equation.
fn plane_grid(rows: usize, cols: usize, px: f64, py: f64) -> String {
    let mut s = String::new();
    for r in 0..rows {
        let line: Vec<String> = (0..cols)
            .map(|c| format!("{}", 1000.0 * (0.5 * c as f64 * px + 0.25 * r as f64 * py)))
            .collect();
        s.push_str(&line.join(","));
        s.push('\n');
    }
    s
}

#[test]
fn fits_a_plane_and_writes_iges_and_report_into_new_directories() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("plane.csv");
    std::fs::write(&input, plane_grid(7, 12, 0.01, 0.02)).unwrap();
    let out = dir.path().join("new/sub/plane.igs");
    let report = dir.path().join("rep/fit.json");
    let st = surfscan()
        .args(["fit"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .args(["--pitch-x", "0.01", "--pitch-y", "0.02", "--report"])
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let file = surfscan::iges::read_iges(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(file.surfaces.len(), 1);
    let s = &file.surfaces[0];
    assert_eq!((s.count_u(), s.count_v()), (12, 7));
    for a in 0..=8 {
        for b in 0..=8 {
            let p = s.evaluate(a as f64 / 8.0, b as f64 / 8.0);
            assert!((p[2] - (0.5 * p[0] + 0.25 * p[1])).abs() < 1e-12, "{p:?}");
        }
    }
    // Corners are the corner data points (clamped interpolant).
    let c = s.evaluate(1.0, 1.0);
    assert!(
        (c[0] - 0.11).abs() < 1e-14 && (c[1] - 0.12).abs() < 1e-14,
        "{c:?}"
    );
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(rep["grid"]["rows"], 7);
    assert_eq!(rep["grid"]["cols"], 12);
    assert_eq!(rep["knots_u_len"], 18);
    assert_eq!(rep["knots_v_len"], 13);
    assert_eq!(rep["patches"], 1);
    assert_eq!(rep["iges_bytes"], std::fs::metadata(&out).unwrap().len());
    assert!(rep["max_residual_mm"].as_f64().unwrap() < 1e-12);
    assert!(rep["timings_s"]["write_iges"].as_f64().unwrap() >= 0.0);
}

#[test]
fn malformed_csv_names_line_and_column_and_exits_1() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bad.csv");
    std::fs::write(&input, "1,2,3,4,5,6\n1,2,oops,4,5,6\n").unwrap();
    let st = surfscan()
        .arg("fit")
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("x.igs"))
        .args(["--pitch-x", "0.01", "--pitch-y", "0.01"])
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(1));
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(
        err.contains("line 2, column 3") && err.contains("oops"),
        "{err}"
    );
    assert!(!dir.path().join("x.igs").exists());
}

#[test]
fn missing_input_exits_74_and_bad_pitch_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let st = surfscan()
        .arg("fit")
        .arg(dir.path().join("absent.csv"))
        .args(["-o", "x.igs", "--pitch-x", "0.01", "--pitch-y", "0.01"])
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(74));
    let st = surfscan()
        .arg("fit")
        .arg(dir.path().join("absent.csv"))
        .args(["-o", "x.igs", "--pitch-x", "0", "--pitch-y", "0.01"])
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
}
