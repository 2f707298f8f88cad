//! Recipes, the queue's commands and the list of scans, through the real binary: what an
//! operator types and what a program reads.

use crate::common::{append_config, edited};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use surfscan::cli::demo::demo_config;
use surfscan::jobs::synthetic::{write, SyntheticReport, SyntheticScan};
use surfscan::scan::journal::StopStatus;
use surfscan::specification::Verdict;

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

/// A station configuration (the demo's, with character devices as ports) whose recipes are
/// in `dir/recipes`.
fn station(dir: &Path) -> PathBuf {
    let out = dir.join("out");
    with_recipes(
        dir,
        demo_config(Path::new("/dev/null"), Path::new("/dev/zero"), &out),
    )
}

/// Writes the configuration `text` with `[jobs] recipes` in `dir/recipes` (made) as
/// `dir/station.toml`; its path.
fn with_recipes(dir: &Path, mut text: String) -> PathBuf {
    let p = dir.join("station.toml");
    let recipes = dir.join("recipes");
    text.push_str(&format!("\n[jobs]\nrecipes = \"{}\"\n", recipes.display()));
    std::fs::write(&p, text).unwrap();
    std::fs::create_dir_all(recipes).unwrap();
    p
}

const BRASS: &str = r#"description = "brass coupon, turned face"
[plan]
lines = 11
y-step-mm = 0.01
[conditions]
lambda-c-mm = 0.8
[specification]
limits = ["Ra 0.8", "Rz max 6.3"]
"#;

#[test]
fn check_config_checks_every_recipe_and_names_a_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = station(dir.path());
    let cfg = cfg.to_str().unwrap();
    let out = surfscan(&["check-config", cfg]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("no recipe (NAME.toml)"),
        "{}",
        text(&out.stderr)
    );

    std::fs::write(dir.path().join("recipes/brass.toml"), BRASS).unwrap();
    let out = surfscan(&["check-config", cfg]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("recipe      brass: 11 lines from y = -20.0000 mm (the station's; --y-start-mm sets it per job) in steps of 0.0100 mm, 2 limits (Ra 0.8, Rz max 6.3)"),
        "{stdout}"
    );

    // Each malformed recipe: exit 78 naming the file, the key and what is accepted.
    let bad = dir.path().join("recipes/steel.toml");
    for (text_of, says) in [
        (edited(BRASS, "\"Ra 0.8\"", "\"Ra0.8x\""), "specification.limits: limits[0]: \"Ra0.8x\": put a space between the parameter and the limit"),
        (edited(BRASS, "\"Ra 0.8\"", "\"Ra 0.8 mm\""), "the limit is in mm: limits are written in µm"),
        (edited(BRASS, "\"Rz max 6.3\"", "\"L Ra 1.2\""), "is not below the upper limit"),
        (edited(BRASS, "\"Rz max 6.3\"", "\"Sq 1\""), "not a parameter a scan computes (accepted: Ra, Rq"),
        (edited(BRASS, "lines = 11", "lines = 11\ny-start-mm = 400.0"), "plan: line 1 at y = 400 mm lies outside the stage's soft limits"),
        (edited(BRASS, "lambda-c-mm = 0.8", "lambda-c-mm = 0.8\nspeed = 1"), "unknown field `speed`"),
    ] {
        std::fs::write(&bad, &text_of).unwrap();
        let out = surfscan(&["check-config", cfg]);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(78), "{err}");
        assert!(err.contains(&format!("recipe {}", bad.display())), "{err}");
        assert!(err.contains(says), "{says}: {err}");
    }
}

fn synthetic(k: u64, specimen: &str, recipe: &str, verdict: Verdict) -> SyntheticScan {
    SyntheticScan {
        id: format!("2026031{k}T220000Z-{specimen}"),
        sequence: k,
        started: chrono::DateTime::parse_from_rfc3339(&format!("2026-03-1{k}T22:00:00Z"))
            .unwrap()
            .into(),
        specimen: specimen.into(),
        recipe: Some((recipe.into(), Some(k))),
        lines: 31,
        done: 31,
        stop: Some(StopStatus::Success),
        report: Some(SyntheticReport {
            verdict: Some(verdict),
            ra_um: vec![0.61, 0.63],
            sa_um: 0.75,
            warnings: k as usize,
        }),
    }
}

#[test]
fn list_shows_the_scans_and_filters_them() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("out");
    write(&out_dir, &synthetic(1, "C-1", "brass", Verdict::Conforms)).unwrap();
    write(
        &out_dir,
        &synthetic(2, "C-2", "brass", Verdict::DoesNotConform),
    )
    .unwrap();
    write(
        &out_dir,
        &synthetic(3, "S-1", "steel", Verdict::NotDecidable),
    )
    .unwrap();
    let d = out_dir.to_str().unwrap();
    let out = surfscan(&["list", "--dir", d]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let t = text(&out.stdout);
    let lines: Vec<&str> = t.lines().collect();
    assert_eq!(lines.len(), 4, "{t}");
    assert!(
        lines[0].starts_with("SCAN") && lines[0].contains("VERDICT"),
        "{t}"
    );
    assert!(
        lines[2].contains("20260312T220000Z-C-2")
            && lines[2].contains("success")
            && lines[2].contains("brass")
            && lines[2].contains("does not conform")
            && lines[2].contains("0.6200")
            && lines[2].contains("0.7500"),
        "{t}"
    );
    // The configuration's [output] dir is listed the same; filters combine.
    let cfg = station(dir.path());
    let out = surfscan(&[
        "list",
        "--config",
        cfg.to_str().unwrap(),
        "--recipe",
        "brass",
        "--verdict",
        "does-not-conform",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = v.as_array().unwrap();
    assert_eq!(rows.len(), 1, "{v}");
    assert_eq!(rows[0]["specimen"], "C-2");
    assert_eq!(rows[0]["verdict"], "does not conform");
    assert_eq!(rows[0]["warnings"], 2);
    let out = surfscan(&[
        "list",
        "--dir",
        d,
        "--since",
        "2026-03-12",
        "--specimen",
        "*-1",
    ]);
    let t = text(&out.stdout);
    assert!(
        t.contains("S-1") && !t.contains("C-1") && !t.contains("C-2"),
        "{t}"
    );
    // What cannot be read is a usage error naming the accepted forms.
    let out = surfscan(&["list", "--dir", d, "--since", "12/03/2026"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("YYYY-MM-DD"),
        "{}",
        text(&out.stderr)
    );
    let out = surfscan(&["list", "--dir", d, "--verdict", "pass"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("does-not-conform"));
}

/// The daemon of a station whose devices are not plugged in: it serves the socket, queues
/// jobs and says why they wait.
struct IdleDaemon(std::process::Child);

impl Drop for IdleDaemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn idle_daemon(dir: &Path) -> (IdleDaemon, PathBuf) {
    let socket = dir.join("control.sock");
    let out = dir.join("out");
    let t =
        crate::common::demo_config_at(&dir.join("no-sj210"), &dir.join("no-stage"), &out, &socket);
    let p = with_recipes(dir, t);
    std::fs::write(dir.join("recipes/brass.toml"), BRASS).unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["daemon", "--config"])
        .arg(&p)
        .env("SURFSCAN_TEST_LOCK_DIR", dir)
        .env_remove("NOTIFY_SOCKET")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while !socket.exists() {
        assert!(
            start.elapsed() < std::time::Duration::from_secs(30),
            "no socket"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    (IdleDaemon(child), socket)
}

#[test]
fn the_queue_commands_add_list_remove_and_refuse_with_their_exit_status() {
    let dir = tempfile::tempdir().unwrap();
    let (_d, socket) = idle_daemon(dir.path());
    let s = socket.to_str().unwrap();
    let q = |args: &[&str]| {
        let mut v = args.to_vec();
        v.extend(["--socket", s]);
        surfscan(&v)
    };
    let out = q(&[
        "queue",
        "add",
        "--recipe",
        "brass",
        "--specimen",
        "C-1",
        "--y-start-mm",
        "-10",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout)
            .contains("queued job 1: recipe brass, specimen \"C-1\" from y = -10 mm (it is next)"),
        "{}",
        text(&out.stdout)
    );
    let out = q(&[
        "queue",
        "add",
        "--recipe",
        "brass",
        "--specimen",
        "C-2",
        "--needs-loading",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    // What cannot be queued, with the status a script tells apart.
    let out = q(&["queue", "add", "--recipe", "bras", "--specimen", "C-3"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("the recipes there are brass"),
        "{}",
        text(&out.stderr)
    );
    let out = q(&[
        "queue",
        "add",
        "--recipe",
        "brass",
        "--specimen",
        "C-3",
        "--y-start-mm",
        "50",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("soft limits"),
        "{}",
        text(&out.stderr)
    );
    std::fs::write(
        dir.path().join("recipes/bad.toml"),
        edited(BRASS, "\"Ra 0.8\"", "\"Ra0.8x\""),
    )
    .unwrap();
    let out = q(&["queue", "add", "--recipe", "bad", "--specimen", "C-3"]);
    assert_eq!(out.status.code(), Some(78), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("bad.toml: specification.limits"),
        "{}",
        text(&out.stderr)
    );
    // The list: job 1 first (its devices are missing: it waits), job 2 needs loading.
    let out = q(&["queue", "list"]);
    let t = text(&out.stdout);
    assert!(t.starts_with("2 jobs, in the order they run:"), "{t}");
    assert!(
        t.contains("     1  brass \"C-1\" at y = -10.0000 mm — queued"),
        "{t}"
    );
    assert!(
        t.contains("     2  brass \"C-2\" — queued (needs loading)"),
        "{t}"
    );
    // The status says why nothing runs.
    let out = q(&["status", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["state"], "waiting", "{v}");
    assert!(
        v["reason"]
            .as_str()
            .unwrap()
            .contains("waits for the instrument and the stage"),
        "{v}"
    );
    assert_eq!(v["queue"]["queued"], 2, "{v}");
    // `ready` names the job that runs first; removing and clearing.
    let out = q(&["ready", "2"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("job 1 runs before it"),
        "{}",
        text(&out.stderr)
    );
    let out = q(&["queue", "remove", "1"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let out = q(&["queue", "remove", "1"]);
    assert_eq!(out.status.code(), Some(2));
    let out = q(&["ready"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let out = q(&["queue", "list", "--json"]);
    let v: serde_json::Value = serde_json::from_str(text(&out.stdout).trim()).unwrap();
    assert_eq!(v["class"], "queue");
    assert_eq!(v["jobs"][0]["id"], 2);
    assert_eq!(v["jobs"][0]["loaded"], true, "{v}");
    assert_eq!(v["jobs"][0]["recipe"]["text"], BRASS);
    let out = q(&["queue", "clear"]);
    assert!(
        text(&out.stdout).contains("1 queued jobs removed"),
        "{}",
        text(&out.stdout)
    );
    assert!(text(&q(&["queue", "list"]).stdout).starts_with("no job is queued"));
    // Each command is logged with who sent it.
    let log = std::fs::read_to_string(dir.path().join("out/queue-log.jsonl")).unwrap();
    let commands: Vec<String> = log
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["command"]
                .as_str()
                .unwrap()
                .to_owned()
        })
        .collect();
    assert_eq!(
        commands,
        vec!["add", "add", "remove", "ready", "clear"],
        "{log}"
    );
    // `start --recipe` is validated by the daemon the same way.
    let out = q(&["start", "--recipe", "bad", "--specimen", "X"]);
    assert_eq!(out.status.code(), Some(78), "{}", text(&out.stderr));
    let out = q(&["start", "--recipe", "nope", "--specimen", "X"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
}

/// A grid CSV of `amplitudes.len()` lines, each a cosine of 50 µm period and its amplitude
/// (µm), 1251 points at 1 µm: five λc of 0.25 mm, so the lines are evaluated over the five
/// sampling lengths a callout means by default. Whole periods far below λc: each line's Ra is
/// 2A/π.
fn cosine_grid(path: &Path, amplitudes: &[f64]) {
    let mut csv = String::new();
    for a in amplitudes {
        let row: Vec<String> = (0..1251)
            .map(|c| {
                format!(
                    "{:.12}",
                    a * (std::f64::consts::TAU * c as f64 / 50.0).cos()
                )
            })
            .collect();
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    std::fs::write(path, csv).unwrap();
}

fn analyze_grid(grid: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "analyze",
        grid.to_str().unwrap(),
        "--lc",
        "0.25",
        "--pitch-x",
        "0.001",
        "--pitch-y",
        "0.01",
        "--curves",
        "3",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    surfscan(&args)
}

#[test]
fn analyze_recipe_judges_a_grid_and_exits_4_when_the_part_does_not_conform() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Ra = 2A/π: eight lines at A 0.5 µm (Ra 0.318), two at A 2 µm (Ra 1.27).
    let mut amplitudes = vec![0.5; 10];
    amplitudes[3] = 2.0;
    amplitudes[8] = 2.0;
    let grid = d.join("grid.csv");
    cosine_grid(&grid, &amplitudes);
    let recipe = d.join("flange.toml");
    std::fs::write(
        &recipe,
        "[plan]\nlines = 10\ny-step-mm = 0.01\n\n[specification]\nlimits = [\"Ra 0.8\", \"Ra max 3.2\"]\n",
    )
    .unwrap();
    // 2 of 10 lines (20 %) above 0.8 µm breaks the 16 % rule (at most 1 of 10); no line
    // reaches 3.2 µm. No station: the instrument's uncertainty is not stated, U = 0.
    let out = d.join("judged");
    let o = analyze_grid(&grid, &out, &["--recipe", recipe.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(4), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(stdout.contains("verdict: does not conform\n"), "{stdout}");
    assert!(
        stdout.contains("  Ra 0.8: does not conform (Ra 16 % rule: 2 of 10 lines above 0.8 µm (at most 1 allowed))"),
        "{stdout}"
    );
    assert!(text(&o.stderr).contains("the part does not conform"));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let spec = &report["specification"];
    assert_eq!(spec["verdict"], "does not conform");
    assert_eq!(spec["limits"][0]["lines_beyond"], serde_json::json!([4, 9]));
    assert_eq!(spec["limits"][1]["verdict"], "conforms");
    for (l, a) in report["lines"].as_array().unwrap().iter().zip(&amplitudes) {
        let ra = l["Ra_um"].as_f64().unwrap();
        assert!(
            (ra - 2.0 * a / std::f64::consts::PI).abs() < 0.01 * a,
            "{l}"
        );
    }
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert!(csv
        .lines()
        .next()
        .unwrap()
        .ends_with(",limit: Ra 0.8,limit: Ra max 3.2,scan_verdict"));
    assert!(csv
        .lines()
        .nth(4)
        .unwrap()
        .ends_with(",beyond,within,does not conform"));

    // One line of ten above (10 %) meets the rule: exit 0, and without --recipe the grid is
    // not judged at all.
    amplitudes[8] = 0.5;
    cosine_grid(&grid, &amplitudes);
    let o = analyze_grid(
        &grid,
        &d.join("ok"),
        &["--recipe", recipe.to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("verdict: conforms\n"));
    let o = analyze_grid(&grid, &d.join("plain"), &[]);
    assert_eq!(o.status.code(), Some(0));
    let plain: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("plain/report.json")).unwrap())
            .unwrap();
    assert!(
        plain["specification"].is_null(),
        "{}",
        plain["specification"]
    );

    // A station's recipe by name, with its calibration uncertainty: 3 % of 1.27 µm does not
    // bring the line within 0.8 µm; the uncertainty is stated in the verdict.
    let config = station(d);
    append_config(
        &config,
        "\n[traceability]\ncalibration-uncertainty-pct = 3.0\n",
    );
    std::fs::copy(&recipe, d.join("recipes/flange.toml")).unwrap();
    let by_name = d.join("by-name");
    let o = analyze_grid(
        &grid,
        &by_name,
        &["--recipe", "flange", "--config", config.to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(by_name.join("report.json")).unwrap())
            .unwrap();
    assert_eq!(report["specification"]["limits"][0]["line_u_pct"], 3.0);
    assert_eq!(report["specification"]["limits"][0]["n_beyond"], 1);

    // Refused before anything is read: a name without a station (2), a bad callout (78,
    // naming the file and the key), a recipe without limits (2).
    let o = analyze_grid(&grid, &d.join("x"), &["--recipe", "flange"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--config"), "{}", text(&o.stderr));
    std::fs::write(
        &recipe,
        "[plan]\nlines = 10\ny-step-mm = 0.01\n\n[specification]\nlimits = [\"Ra0.8x\"]\n",
    )
    .unwrap();
    let o = analyze_grid(&grid, &d.join("x"), &["--recipe", recipe.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(78), "{}", text(&o.stderr));
    let e = text(&o.stderr);
    assert!(
        e.contains("flange.toml") && e.contains("specification.limits") && e.contains("Ra0.8x"),
        "{e}"
    );
    std::fs::write(&recipe, "[plan]\nlines = 5\ny-step-mm = 0.01\n").unwrap();
    let o = analyze_grid(&grid, &d.join("x"), &["--recipe", recipe.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("nothing to judge"));
    assert!(!d.join("x").exists());
}
