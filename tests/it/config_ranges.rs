//! A configuration value out of its range ends `surfscan scan` and `surfscan daemon` with
//! exit status 78 naming the key, before any device is opened (systemd's unit does not
//! restart on 78; a panic would be 134 and restarted in a loop).

use std::process::Command;

fn config(dir: &std::path::Path, stage_extra: &str) -> std::path::PathBuf {
    let text = format!(
        r#"[instrument]
port = "/nonexistent/sj210"
[stage]
port = "/nonexistent/ystage"
protocol = "grbl"
steps-per-mm = 400.0
soft-limit-min-mm = -100.0
soft-limit-max-mm = 0.0
{stage_extra}
[scan]
lines = 8
y-start-mm = -20.0
y-step-mm = 0.01
[output]
dir = {out:?}
[control]
socket = {sock:?}
"#,
        out = dir.join("out").display().to_string(),
        sock = dir.join("control.sock").display().to_string(),
    );
    let path = dir.join("station.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn feed_mm_min_1e_minus_30_exits_78_naming_the_key() {
    let tmp = tempfile::tempdir().unwrap();
    let path = config(tmp.path(), "feed-mm-min = 1e-30");
    for command in ["scan", "daemon"] {
        let out = Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args([command, "--config"])
            .arg(&path)
            .env("RUST_LOG", "warn")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(78), "{command}: {stderr}");
        assert!(
            stderr.contains("stage.feed-mm-min") && stderr.contains("1e-30"),
            "{command}: {stderr}"
        );
        assert!(
            !tmp.path().join("out").exists(),
            "{command} created the output dir"
        );
    }
}

#[test]
fn an_unknown_allowed_group_exits_78_naming_the_key() {
    let tmp = tempfile::tempdir().unwrap();
    let path = config(tmp.path(), "");
    let text =
        std::fs::read_to_string(&path).unwrap() + "allowed-groups = [\"no-such-group-here\"]\n";
    std::fs::write(&path, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["daemon", "--config"])
        .arg(&path)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(78), "{stderr}");
    assert!(
        stderr.contains("control.allowed-groups") && stderr.contains("no-such-group-here"),
        "{stderr}"
    );
    assert!(!tmp.path().join("control.sock").exists());
}

#[test]
fn a_material_ratio_reading_that_is_neither_iso_nor_instrument_exits_78_naming_the_key() {
    crate::common::assert_tables_refused(
        "analysis",
        &[
            ("material-ratio = \"sj\"", "material-ratio"),
            ("material-ratio = 1", "material-ratio"),
        ],
    );
}

#[test]
fn a_malformed_contact_table_exits_78_naming_the_key() {
    crate::common::assert_tables_refused(
        "contact",
        &[
            ("enabled = true\nyoung-gpa = -1.0", "contact.young-gpa"),
            ("poisson = 0.7", "contact.poisson"),
            ("young2-gpa = 5000.0", "contact.young2-gpa"),
            ("poisson2 = 0.3", "contact.poisson2"),
            ("hardness-gpa = 0.0", "contact.hardness-gpa"),
            ("pressures-mpa = [10.0, -5.0]", "contact.pressures-mpa"),
            (
                "hardness-gpa = 0.05\npressures-mpa = [10.0, 100.0]",
                "contact.pressures-mpa",
            ),
            ("model-pitch-y-mm = 0.0", "contact.model-pitch-y-mm"),
            ("enable = true", "enable"),
            ("pressures-mpa = 10.0", "pressures-mpa"),
        ],
    );
}
