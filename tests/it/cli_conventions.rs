//! What a daemon's users expect of its command line: `--version` naming the commit, man
//! pages and shell completions generated from the same definition as the parser, and
//! `check-config` (and `scan` refusing what it refuses).

use crate::common::edited;
use std::path::Path;
use std::process::{Command, Output};

fn surfscan(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(args)
        .env_remove("RUST_LOG")
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn version_names_the_commit_it_was_built_from() {
    let out = surfscan(&["--version"]);
    assert_eq!(out.status.code(), Some(0));
    let v = text(&out.stdout);
    let expected_commit = Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| text(&o.stdout).trim().to_string())
        .filter(|c| !c.is_empty());
    let commit = match (std::env::var("SURFSCAN_COMMIT"), expected_commit) {
        (Ok(c), _) if !c.is_empty() => c,
        (_, Some(c)) => c,
        _ => "unknown".to_string(),
    };
    assert_eq!(
        v,
        format!("surfscan {} (commit {commit})\n", env!("CARGO_PKG_VERSION"))
    );
}

#[test]
fn completions_know_every_subcommand_and_option() {
    for shell in ["bash", "zsh", "fish"] {
        let out = surfscan(&["completions", shell]);
        assert_eq!(out.status.code(), Some(0), "{shell}: {}", text(&out.stderr));
        let script = text(&out.stdout);
        // fish names long options without their dashes (`-l speed-up`).
        for word in ["check-config", "analyze", "speed-up", "watch", "manpages"] {
            assert!(script.contains(word), "{shell} completion lacks {word}");
        }
    }
    let out = surfscan(&["completions", "tcsh"]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "an unknown shell is a usage error"
    );
}

#[test]
fn man_pages_cover_the_command_and_every_subcommand() {
    let dir = tempfile::tempdir().unwrap();
    let man = dir.path().join("man1");
    let out = surfscan(&["manpages", man.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    // roff escapes a hyphen as `\-`; read the pages as a person would see them.
    let read = |p: &Path| {
        std::fs::read_to_string(p)
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
            .replace("\\-", "-")
    };
    let main = read(&man.join("surfscan.1"));
    assert!(main.contains(".TH surfscan 1"), "title header: {main}");
    assert!(
        main.contains(env!("CARGO_PKG_VERSION")),
        "version in the page"
    );
    for sub in [
        "scan",
        "daemon",
        "demo",
        "fit",
        "analyze",
        "status",
        "pause",
        "resume",
        "abort",
        "start",
        "probe",
        "check-config",
        "completions",
        "manpages",
    ] {
        let text = read(&man.join(format!("surfscan-{sub}.1")));
        assert!(
            text.contains(&format!(".TH surfscan-{sub} 1")),
            "{sub}: {text}"
        );
        assert!(main.contains(sub), "surfscan.1 does not list {sub}");
    }
    let scan = read(&man.join("surfscan-scan.1"));
    assert!(
        scan.contains("/etc/surfscan/surfscan.toml"),
        "default config"
    );
    assert!(
        scan.contains("verbose"),
        "the global option is on the subcommand's page"
    );
    assert!(
        scan.contains(env!("CARGO_PKG_VERSION")),
        "the version on the subcommand's page"
    );
    assert!(
        !scan.contains("--version"),
        "a subcommand takes no --version, so its page offers none: {scan}"
    );
    // The one-line summary of analyze names every input it reads.
    let help = text(&surfscan(&["--help"]).stdout);
    let analyze = help
        .lines()
        .find(|l| l.trim_start().starts_with("analyze"))
        .unwrap_or_else(|| panic!("no analyze line in {help}"));
    for input in ["scan directory", "X3P file", "profile", "grid CSV"] {
        assert!(analyze.contains(input), "{input} missing from {analyze:?}");
    }
}

fn demo_config(dir: &Path, instrument: &Path, stage: &Path) -> std::path::PathBuf {
    let p = dir.join("station.toml");
    std::fs::write(
        &p,
        surfscan::cli::demo::demo_config(instrument, stage, &dir.join("out")),
    )
    .unwrap();
    p
}

/// The instrument and the stage on one port (also under two names): refused by
/// `check-config` naming both (exit 78), where a scan used to say the port "is not present".
#[test]
fn check_config_refuses_one_port_for_both_devices() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ystage");
    std::os::unix::fs::symlink("/dev/null", &link).unwrap();
    for stage in [Path::new("/dev/null"), link.as_path()] {
        let cfg = demo_config(dir.path(), Path::new("/dev/null"), stage);
        let out = surfscan(&["check-config", cfg.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(78), "{}", text(&out.stderr));
        let stderr = text(&out.stderr);
        assert!(
            stderr.contains("[instrument] port /dev/null and [stage] port")
                && stderr.contains("are the same device"),
            "{stderr}"
        );
    }
}

/// `check-config` of the demo's station with `edit` applied to its text: the exit status and
/// standard error.
fn check_edited(edit: impl Fn(String) -> String) -> (Option<i32>, String) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = demo_config(dir.path(), Path::new("/dev/null"), Path::new("/dev/zero"));
    let edited = edit(std::fs::read_to_string(&cfg).unwrap());
    std::fs::write(&cfg, edited).unwrap();
    let out = surfscan(&["check-config", cfg.to_str().unwrap()]);
    (out.status.code(), text(&out.stderr))
}

/// The line after the table header `[table]` in the configuration `t` (its first key).
fn first_key_of(t: &str, table: &str) -> String {
    let header = format!("[{table}]");
    t.lines()
        .skip_while(|l| *l != header)
        .nth(1)
        .unwrap()
        .to_owned()
}

/// A y step the stage cannot make exactly (the demo's stage: 400 steps/mm, a step of
/// 2.5 µm): refused at `check-config` naming the key, the stage's step and whole-step
/// choices, where the scan used to find out only when the stage connected.
#[test]
fn check_config_refuses_a_y_step_that_is_no_whole_number_of_stage_steps() {
    // 0.011 mm is 4.4 steps of 0.0025 mm: 0.01 or 0.0125 mm would do.
    let (code, err) = check_edited(|t| edited(&t, "y-step-mm = 0.01", "y-step-mm = 0.011"));
    assert_eq!(code, Some(78), "{err}");
    assert!(
        err.contains("scan.y-step-mm")
            && err.contains("0.011 mm is 4.4000 of the stage's steps of 0.0025 mm")
            && err.contains("0.01 or 0.0125 mm")
            && err.contains("allow-inexact-step"),
        "{err}"
    );
    // Less than one step (it was printed as "steps of 0.0000 mm"): the smallest step named.
    let (code, err) = check_edited(|t| edited(&t, "y-step-mm = 0.01", "y-step-mm = 0.001"));
    assert_eq!(code, Some(78), "{err}");
    assert!(
        err.contains("0.001 mm is 0.4000 of the stage's steps") && err.contains("(0.0025 mm)"),
        "{err}"
    );
    // A first line between two steps, with a whole step: named by its own key.
    let (code, err) = check_edited(|t| {
        let start = t
            .lines()
            .find(|l| l.starts_with("y-start-mm"))
            .unwrap()
            .to_owned();
        edited(&t, &start, "y-start-mm = -20.0001")
    });
    assert_eq!(code, Some(78), "{err}");
    assert!(err.contains("scan.y-start-mm"), "{err}");
    // Allowed explicitly: valid (the stage rounds each target once, with a warning).
    let (code, err) = check_edited(|t| {
        edited(
            &edited(&t, "y-step-mm = 0.01", "y-step-mm = 0.011"),
            "home-on-start = true",
            "home-on-start = true\nallow-inexact-step = true",
        )
    });
    assert_eq!(code, Some(0), "{err}");
}

/// An output directory on a tree that keeps no files, or holding the control socket:
/// refused by `check-config` (and so by `scan` and `daemon`), naming the key.
#[test]
fn check_config_refuses_output_dirs_that_keep_no_files_and_a_socket_inside_them() {
    for bad in [
        "/proc/self",
        "/proc/self/scans",
        "/sys/kernel",
        "/dev/surfscan",
    ] {
        let (code, err) =
            check_edited(|t| edited(&t, &first_key_of(&t, "output"), &format!("dir = {bad:?}")));
        assert_eq!(code, Some(78), "{bad}: {err}");
        assert!(
            err.contains(&format!("output.dir = {bad} lies on")) && err.contains("keeps no files"),
            "{bad}: {err}"
        );
    }
    // A regular file named as the directory.
    let (code, err) =
        check_edited(|t| edited(&t, &first_key_of(&t, "output"), "dir = \"/etc/passwd\""));
    assert_eq!(code, Some(78), "{err}");
    assert!(err.contains("is not a directory"), "{err}");
    // The socket inside the scans' tree, even in a directory not made yet.
    let (code, err) = check_edited(|t| {
        let dir = first_key_of(&t, "output");
        let out = dir.trim_start_matches("dir = ").trim_matches('"');
        let sock = first_key_of(&t, "control");
        edited(&t, &sock, &format!("socket = \"{out}/run/control.sock\""))
    });
    assert_eq!(code, Some(78), "{err}");
    assert!(
        err.contains("control.socket") && err.contains("lies inside output.dir"),
        "{err}"
    );
}

#[test]
fn check_config_validates_without_opening_devices() {
    let dir = tempfile::tempdir().unwrap();
    // Character devices as ports: valid, and the summary says what would be done.
    let cfg = demo_config(dir.path(), Path::new("/dev/null"), Path::new("/dev/zero"));
    let out = surfscan(&["check-config", cfg.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains(": valid (sha256 "), "{stdout}");
    assert!(
        stdout.contains("instrument  sj210 on /dev/null at 38400 baud"),
        "{stdout}"
    );
    assert!(stdout.contains("stage       grbl on /dev/zero"), "{stdout}");
    assert!(
        stdout.contains("scan        31 lines from y = -20.0000 mm in steps of 0.0100 mm"),
        "{stdout}"
    );

    // The file given as `--config FILE`, as `scan` and `daemon` take it: the same check; a
    // path given both ways is a usage error, not a silent choice of one.
    let out = surfscan(&["check-config", "--config", cfg.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).starts_with(&format!("{}: valid", cfg.display())),
        "{}",
        text(&out.stdout)
    );
    let out = surfscan(&[
        "check-config",
        cfg.to_str().unwrap(),
        "--config",
        "/elsewhere.toml",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));

    // An absent device is a note, not a failure: it may be plugged in later.
    let absent = dir.path().join("ttyUSB7");
    let cfg = demo_config(dir.path(), &absent, Path::new("/dev/null"));
    let out = surfscan(&["check-config", cfg.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("is not present now"),
        "{}",
        text(&out.stderr)
    );
    // With --require-devices (what the package's install script asks before it starts the
    // service) the same absence is exit 69 naming the port; present devices pass.
    let out = surfscan(&["check-config", "--require-devices", cfg.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(69), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(
        err.contains(&format!(
            "[instrument] port {} is not present now",
            absent.display()
        )),
        "{err}"
    );
    // Two different device nodes: one port for both devices is refused on its own.
    let present = demo_config(dir.path(), Path::new("/dev/null"), Path::new("/dev/zero"));
    let out = surfscan(&[
        "check-config",
        "--require-devices",
        present.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));

    // A regular file can never be a serial port: exit 78 naming the cause.
    let file = dir.path().join("port.txt");
    std::fs::write(&file, "not a device").unwrap();
    let cfg = demo_config(dir.path(), &file, Path::new("/dev/null"));
    let out = surfscan(&["check-config", cfg.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(78));
    let err = text(&out.stderr);
    assert!(
        err.contains("is a regular file, not a serial device"),
        "{err}"
    );
    assert!(!err.contains("Not a typewriter"), "{err}");

    // A misspelt key: exit 78 naming it.
    let text_ok = std::fs::read_to_string(&cfg).unwrap();
    std::fs::write(&cfg, edited(&text_ok, "y-step-mm", "y-stepp-mm")).unwrap();
    let out = surfscan(&["check-config", cfg.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(78));
    assert!(
        text(&out.stderr).contains("y-stepp-mm"),
        "{}",
        text(&out.stderr)
    );

    // The default path, absent here: exit 78 naming it.
    if !Path::new("/etc/surfscan/surfscan.toml").exists() {
        let out = surfscan(&["check-config"]);
        assert_eq!(out.status.code(), Some(78));
        assert!(
            text(&out.stderr).contains("/etc/surfscan/surfscan.toml"),
            "{}",
            text(&out.stderr)
        );
    }
}

#[test]
fn scan_refuses_a_port_that_can_never_be_a_serial_device_as_bad_configuration() {
    // What check-config calls a bad configuration (exit 78) is one for scan as well, before
    // anything is locked or created, not a scan that failed (exit 1).
    let dir = tempfile::tempdir().unwrap();
    let not_a_port = dir.path().join("ports");
    std::fs::create_dir(&not_a_port).unwrap();
    let cfg = demo_config(dir.path(), &not_a_port, Path::new("/dev/null"));
    let check = surfscan(&["check-config", cfg.to_str().unwrap()]);
    assert_eq!(check.status.code(), Some(78), "{}", text(&check.stderr));
    let out = surfscan(&["scan", "--config", cfg.to_str().unwrap()]);
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(78), "{err}");
    assert!(
        err.contains("[instrument] port: ") && err.contains("is a directory, not a serial device"),
        "{err}"
    );
    assert!(!dir.path().join("out").exists(), "nothing is created");
}

#[test]
fn fit_names_the_real_cause_for_a_missing_or_wrong_input() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.csv");
    let out = surfscan(&["fit", missing.to_str().unwrap(), "-o", "x.igs"]);
    assert_eq!(out.status.code(), Some(74));
    let err = text(&out.stderr);
    assert!(
        err.contains("missing.csv") && err.contains("No such file"),
        "{err}"
    );
    assert!(!err.contains("--pitch-x"), "{err}");

    // An IGES file (here one fit wrote) is named as such, with or without its extension.
    let grid = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sur-2.grid.csv");
    let iges = dir.path().join("s.igs");
    let out = surfscan(&[
        "fit",
        grid.to_str().unwrap(),
        "-o",
        iges.to_str().unwrap(),
        "--pitch-x",
        "0.003484",
        "--pitch-y",
        "0.010452",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let renamed = dir.path().join("surface.dat");
    std::fs::copy(&iges, &renamed).unwrap();
    for input in [&iges, &renamed] {
        let out = surfscan(&[
            "fit",
            input.to_str().unwrap(),
            "--pitch-x",
            "1",
            "--pitch-y",
            "1",
        ]);
        assert_eq!(out.status.code(), Some(2));
        let err = text(&out.stderr);
        assert!(err.contains("is an IGES file"), "{err}");
    }
}

/// Runs `surfscan ARGS` with standard output and standard error on a pipe whose reader has
/// already gone (`surfscan … | head -0`, a closed terminal).
fn surfscan_unread(args: &[&str]) -> std::process::ExitStatus {
    let writer = crate::common::unread_pipe();
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(args)
        .env("RUST_LOG", "info")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::from(writer.try_clone().unwrap()))
        .stderr(std::process::Stdio::from(writer))
        .status()
        .unwrap()
}

#[test]
fn output_nobody_reads_neither_aborts_a_command_nor_stops_its_work() {
    // Each of these prints on both streams (a warning, the verdict, the summary); the
    // release build aborted at the first write with "failed printing to stdout".
    let dir = tempfile::tempdir().unwrap();
    let grid = dir.path().join("grid.csv");
    let rows: Vec<String> = (0..7)
        .map(|r| {
            (0..1800)
                .map(|k| format!("{:.4}", ((k as f64) * 0.037 + r as f64).sin()))
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect();
    std::fs::write(&grid, rows.join("\n")).unwrap();
    let (grid, iges, out) = (
        grid.to_str().unwrap(),
        dir.path().join("s.igs"),
        dir.path().join("analysis"),
    );
    let pitches = ["--pitch-x", "0.0005", "--pitch-y", "0.01"];
    let fit = [&["fit", grid, "-o", iges.to_str().unwrap()][..], &pitches].concat();
    assert_eq!(surfscan_unread(&fit).code(), Some(0));
    assert!(iges.exists());
    let analyze = [
        &["analyze", grid, "--out", out.to_str().unwrap()][..],
        &pitches,
    ]
    .concat();
    assert_eq!(surfscan_unread(&analyze).code(), Some(0));
    assert!(out.join("report.json").exists());
    assert_eq!(surfscan_unread(&["completions", "bash"]).code(), Some(0));
    assert_eq!(
        surfscan_unread(&["check-config", "config/surfscan.toml"]).code(),
        Some(0)
    );
    // A failure keeps its own exit status (74: the input cannot be read), not an abort.
    let missing = dir.path().join("missing.csv");
    let fit = [
        &["fit", missing.to_str().unwrap(), "-o", "x.igs"][..],
        &pitches,
    ]
    .concat();
    assert_eq!(surfscan_unread(&fit).code(), Some(74));
}

#[test]
fn an_output_under_a_file_names_the_file_in_the_way() {
    // `-o notes.txt/surface.igs` where notes.txt is a file: "File exists" and "Not a
    // directory" alone leave the operator guessing which part of the path is wrong.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("notes.txt");
    std::fs::write(&file, "x").unwrap();
    let grid = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sur-2.grid.csv");
    let (iges, analysis) = (file.join("s.igs"), file.join("analysis"));
    let (iges, analysis) = (iges.to_str().unwrap(), analysis.to_str().unwrap());
    let pitches = ["--pitch-x", "0.003484", "--pitch-y", "0.010452"];
    let fit = [&["fit", grid.to_str().unwrap(), "-o", iges][..], &pitches].concat();
    let analyze = [
        &["analyze", grid.to_str().unwrap(), "--out", analysis][..],
        &pitches,
    ]
    .concat();
    for args in [fit, analyze] {
        let out = surfscan(&args);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(74), "{args:?}: {err}");
        assert!(
            err.contains(&format!("{} is a file, not a directory", file.display())),
            "{args:?}: {err}"
        );
    }
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "x");
}
