//! Shared rig of the end-to-end scan tests: an in-process simulator (SJ-210 and a GRBL y
//! stage on pseudo-terminals) serving a small profile set the test owns, a station
//! configuration pointing at it, and helpers to run the real `surfscan scan` binary and read
//! back what it left on disk (journal, line files, surface).
//!
//! The profile heights are integers of nanometres, so the instrument's three printed
//! decimals carry them exactly and a stored height must equal the served one bit for bit.

#![allow(dead_code)]

pub mod cdp;
pub mod chromium;
pub mod garage;
pub mod http;
pub mod mosquitto;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::time::{Duration, Instant};
use surfscan::scan::journal::{read_journal, Record, ResumeState};
use surfscan_sim::data::ServedProfile;
use surfscan_sim::grbl::{GrblSimConfig, StageShared};
use surfscan_sim::{FaultSpec, InstrumentConfig, ProfileSet, SimEvent, SimHandle, Simulator};

/// The control socket's channels to a runner the test plays (its status and commands), no job
/// queue.
pub fn control_channels(
    status: tokio::sync::watch::Receiver<surfscan::scan::status::Status>,
    commands: tokio::sync::mpsc::Sender<surfscan::scan::command::OperatorRequest>,
) -> surfscan::control::protocol::ControlChannels {
    surfscan::control::protocol::ControlChannels {
        status,
        commands,
        queue: None,
    }
}

/// Starts the simulator `sim` and waits (up to 10 s) for its ready event.
pub async fn started(sim: Simulator) -> SimHandle {
    let mut handle = sim.start().expect("simulator starts");
    match tokio::time::timeout(Duration::from_secs(10), handle.next_event()).await {
        Ok(Some(SimEvent::Ready(_))) => handle,
        other => panic!("simulator not ready: {other:?}"),
    }
}

/// The writing end of a pipe whose reader has already gone, to stand for a terminal that
/// hung up or a `| head` that exited: a write to it fails with EPIPE. Both ends are
/// close-on-exec, so no process another test starts meanwhile keeps the reader open (the
/// child given it as stdout or stderr gets its own copy).
pub fn unread_pipe() -> std::os::fd::OwnedFd {
    let (reader, writer) = nix::unistd::pipe2(nix::fcntl::OFlag::O_CLOEXEC).expect("pipe");
    drop(reader);
    writer
}

/// y of line 0 (GRBL machine coordinates are negative after homing), mm.
pub const Y_START_MM: f64 = -20.0;
/// y step of the plan and of the served lines, mm.
pub const Y_STEP_MM: f64 = 0.01;
/// Points per served profile.
pub const POINTS: usize = 160;
/// x pitch of the served profiles, mm.
pub const PITCH_X_MM: f64 = 0.0015;
/// The instrument's simulated time runs this many times faster than real time. A trace then
/// reads "measuring" or "returning" for about 80 ms, long enough for the client's status
/// polls to see it on a loaded machine (at 1000 it is 8 ms and polls can miss it).
pub const SPEED_UP: f64 = 100.0;
/// The stage's simulated motion runs this many times faster than real time.
pub const STAGE_SPEED_UP: f64 = 1000.0;

/// `path` opened for a child's output to be appended to (created if missing): a daemon's log
/// that a restarted daemon goes on writing.
pub fn appending(path: &Path) -> std::process::Stdio {
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .unwrap()
        .into()
}

/// Height of point `i` of line `k` in integer nanometres: a smooth form plus a
/// line-dependent ripple, different for every line so a trace at the wrong y is caught.
pub fn height_nm(k: usize, i: usize) -> i64 {
    let x = i as f64 * PITCH_X_MM;
    let form = 1500.0 * (x * 40.0).sin() + 400.0 * ((k as f64) * 0.7 + x * 90.0).cos();
    let ripple = ((k * 7919 + i * 104_729) % 601) as f64 - 300.0;
    (form + ripple + 37.0 * k as f64).round() as i64
}

/// The heights of line `k` as the instrument prints them (3 decimals), µm.
pub fn served_heights_um(k: usize) -> Vec<f64> {
    (0..POINTS)
        .map(|i| height_nm(k, i) as f64 / 1000.0)
        .collect()
}

/// The profile set served for `lines` lines.
pub fn profile_set(lines: usize) -> ProfileSet {
    let profiles = (0..lines)
        .map(|k| ServedProfile {
            y_mm: Y_START_MM + k as f64 * Y_STEP_MM,
            pitch_x_mm: PITCH_X_MM,
            z_um: served_heights_um(k),
        })
        .collect();
    let mut set = ProfileSet::new(profiles).expect("profile set");
    // The grid is the plan's exactly (the mean spacing of the y values may be off by an ulp).
    set.y_first_mm = Y_START_MM;
    set.y_step_mm = Y_STEP_MM;
    set
}

/// Target y of line `k` in integer nm, as the plan computes it.
pub fn target_nm(k: usize) -> i64 {
    -20_000_000 + 10_000 * k as i64
}

/// What the rig is built with.
#[derive(Debug, Clone)]
pub struct RigOptions {
    /// Lines of the scan (and of the served set).
    pub lines: usize,
    /// Wire faults (`--fault` specs) of the instrument.
    pub faults: Vec<String>,
    /// `max-line-attempts`.
    pub max_line_attempts: u32,
    /// Extra TOML appended to `[scan]`.
    pub extra_scan: String,
    /// `[fit]` degree-u and degree-v.
    pub degrees: (usize, usize),
    /// Changes the emulated instrument's configuration (its drive, how it answers).
    pub instrument: fn(InstrumentConfig) -> InstrumentConfig,
}

impl Default for RigOptions {
    fn default() -> Self {
        RigOptions {
            lines: 8,
            faults: Vec::new(),
            max_line_attempts: 3,
            extra_scan: String::new(),
            degrees: (5, 3),
            instrument: |c| c,
        }
    }
}

/// A running simulator with its configuration.
pub struct Rig {
    pub tmp: tempfile::TempDir,
    pub sim: Option<SimHandle>,
    pub stage: Arc<StageShared>,
    pub options: RigOptions,
    pub instrument_link: PathBuf,
    pub stage_link: PathBuf,
}

impl Rig {
    /// Starts the simulator and waits for its ready event.
    pub async fn start(options: RigOptions) -> Rig {
        let tmp = tempfile::tempdir().expect("temp dir");
        let instrument_link = tmp.path().join("sj210");
        let stage_link = tmp.path().join("ystage");
        let stage = StageShared::new();
        let instrument = (options.instrument)(InstrumentConfig {
            time_scale: 1.0 / SPEED_UP,
            ..InstrumentConfig::default()
        });
        let grbl = GrblSimConfig {
            steps_per_mm: 400.0,
            max_travel_mm: 100.0,
            backlash_mm: 0.02,
            time_scale: STAGE_SPEED_UP,
            ..GrblSimConfig::default()
        };
        let mut sim = Simulator::new(&instrument_link)
            .instrument(instrument)
            .profiles(profile_set(options.lines))
            .baud(38400 * 100)
            .grbl_stage(&stage_link, grbl, stage.clone());
        for spec in &options.faults {
            match spec.parse::<FaultSpec>() {
                Ok(FaultSpec::Wire(f)) => sim = sim.fault(f),
                other => panic!("fault spec {spec}: {other:?}"),
            }
        }
        Rig {
            tmp,
            sim: Some(started(sim).await),
            stage,
            options,
            instrument_link,
            stage_link,
        }
    }

    /// Writes a configuration whose output directory is `out` (relative to the rig's temp
    /// dir); returns its path.
    pub fn config(&self, out: &str) -> PathBuf {
        self.config_with(out, "")
    }

    /// As [`Rig::config`], with `extra` TOML lines appended to the `[scan]` table.
    pub fn config_with(&self, out: &str, extra: &str) -> PathBuf {
        let dir = self.tmp.path().join(out);
        let text = format!(
            r#"{instrument}
[stage]
port = {stage:?}
protocol = "grbl"
steps-per-mm = 400.0
soft-limit-min-mm = -100.0
soft-limit-max-mm = 0.0
backlash-mm = 0.05
settle-ms = 2
poll-interval-ms = 200
home-on-start = true

[scan]
lines = {lines}
y-start-mm = {Y_START_MM:?}
y-step-mm = {Y_STEP_MM:?}
max-line-attempts = {attempts}
reconnect-initial-ms = 50
reconnect-max-ms = 400
{extra_scan}{extra}

[fit]
degree-u = {degree_u}
degree-v = {degree_v}

[output]
dir = {dir:?}

[control]
socket = {sock:?}
"#,
            instrument = instrument_section(&self.instrument_link),
            stage = self.stage_link.display().to_string(),
            lines = self.options.lines,
            attempts = self.options.max_line_attempts,
            extra_scan = self.options.extra_scan,
            degree_u = self.options.degrees.0,
            degree_v = self.options.degrees.1,
            dir = dir.display().to_string(),
            sock = self.tmp.path().join("control.sock").display().to_string(),
        );
        let path = self.tmp.path().join(format!("{out}.toml"));
        std::fs::write(&path, text).expect("write config");
        path
    }

    /// The output directory of configuration `out`.
    pub fn out_dir(&self, out: &str) -> PathBuf {
        self.tmp.path().join(out)
    }

    /// Starts `surfscan scan` into `out` with a metrics file and waits until two of its lines
    /// are on disk: the running scan and the metrics file.
    pub async fn scan_past_two_lines(&self, out: &str) -> (tokio::process::Child, PathBuf) {
        let metrics = self.tmp.path().join("surfscan.prom");
        let config = self.config_with(
            out,
            &format!("\n[metrics]\nfile = {:?}\n", metrics.display().to_string()),
        );
        let scan = scan_command(&config, &[]).spawn().expect("scan starts");
        let dir = self.out_dir(out);
        wait_until(Duration::from_secs(60), "two lines on disk", || {
            committed_lines(&dir) >= 2
        })
        .await;
        (scan, metrics)
    }

    /// Stops the simulator.
    pub async fn shutdown(mut self) {
        if let Some(h) = self.sim.take() {
            h.shutdown().await;
        }
    }
}

/// The `[instrument]` tables of the rigs' configurations: the simulated SJ-210 at `link`.
pub fn instrument_section(link: &Path) -> String {
    format!(
        r#"[instrument]
port = {link:?}
model = "sj210"
baud = 38400
pitch-x-um = 1.5

[instrument.timeouts]
poll-interval-ms = 5

[instrument.commands]
profile-total = "RDEVA00"
profile-block = "RDEVA{{n}}"
"#,
        link = link.display().to_string()
    )
}

/// `surfscan scan --config CONFIG` with the traceability arguments and `env`. Its device locks
/// go to `locks/` beside the configuration: the rig is a station of its own, and another
/// rig's scan that holds the lock of a pseudo-terminal number it no longer uses (its device
/// was unplugged, the number given to this rig's device) must not refuse this one.
pub fn scan_command(config: &Path, env: &[(&str, &str)]) -> tokio::process::Command {
    let locks = config.parent().unwrap_or(Path::new(".")).join("locks");
    std::fs::create_dir_all(&locks).expect("lock directory");
    let mut c = tokio::process::Command::new(env!("CARGO_BIN_EXE_surfscan"));
    c.arg("scan")
        .arg("--config")
        .arg(config)
        .args(["--specimen", "coupon A-17", "--operator", "R. Tester"])
        .env_remove("SURFSCAN_TEST_CRASH")
        .env_remove("SURFSCAN_TEST_ENOSPC")
        .env("SURFSCAN_TEST_LOCK_DIR", &locks)
        .env("RUST_LOG", "info")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .kill_on_drop(true);
    for (k, v) in env {
        c.env(k, v);
    }
    c
}

/// Runs the scan to its end (at most two minutes).
pub async fn run_scan(config: &Path, env: &[(&str, &str)]) -> Output {
    let child = scan_command(config, env).output();
    tokio::time::timeout(Duration::from_secs(120), child)
        .await
        .expect("surfscan scan finished within 120 s")
        .expect("surfscan scan ran")
}

/// Exit code and captured output, for assertion messages.
pub fn describe(o: &Output) -> String {
    format!(
        "status {:?}\n--- stdout\n{}\n--- stderr\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The one scan directory under `out`.
pub fn scan_dir(out: &Path) -> PathBuf {
    let dirs: Vec<PathBuf> = std::fs::read_dir(out)
        .expect("output dir")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.is_dir())
        .collect();
    assert_eq!(
        dirs.len(),
        1,
        "exactly one scan directory in {out:?}: {dirs:?}"
    );
    dirs.into_iter().next().unwrap_or_default()
}

/// The journal's records and the resume state derived from them.
pub fn journal(dir: &Path) -> (Vec<Record>, ResumeState) {
    let path = dir.join("journal.jsonl");
    let rec = read_journal(&path).expect("journal readable");
    assert_eq!(
        rec.torn_bytes, 0,
        "journal of a finished run has no torn tail"
    );
    let state = ResumeState::from_records(&path, &rec.records).expect("resume state");
    (rec.records, state)
}

/// Line indices of the journal's line records, in order, duplicates included.
pub fn line_record_indices(records: &[Record]) -> Vec<u32> {
    records
        .iter()
        .filter_map(|r| match r {
            Record::Line(l) => Some(l.id.index),
            _ => None,
        })
        .collect()
}

/// Reasons of the interruption records.
pub fn interruptions(records: &[Record]) -> Vec<String> {
    records
        .iter()
        .filter_map(|r| match r {
            Record::Interruption(i) => Some(i.reason.clone()),
            _ => None,
        })
        .collect()
}

/// Checks that `lines/` holds exactly lines `0..n` (each a csv and a json, nothing else),
/// each with the header `x_mm,z_um`, the pitch, and the heights the simulator served.
pub fn assert_lines_exactly(dir: &Path, n: usize) {
    let lines_dir = dir.join("lines");
    let mut names: Vec<String> = std::fs::read_dir(&lines_dir)
        .expect("lines dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let expect: Vec<String> = (0..n)
        .flat_map(|k| [format!("{k:04}.csv"), format!("{k:04}.json")])
        .collect();
    assert_eq!(names, expect, "files in {lines_dir:?}");
    for k in 0..n {
        let text = std::fs::read_to_string(lines_dir.join(format!("{k:04}.csv"))).expect("csv");
        let mut rows = text.lines();
        assert_eq!(rows.next(), Some("x_mm,z_um"), "header of line {k}");
        let want = served_heights_um(k);
        let mut got = Vec::new();
        for (i, row) in rows.enumerate() {
            let (x, z) = row.split_once(',').expect("two columns");
            let x: f64 = x.parse().expect("x number");
            assert!(
                (x - i as f64 * PITCH_X_MM).abs() < 1e-12,
                "line {k} point {i}: x {x}"
            );
            got.push(z.parse::<f64>().expect("z number"));
        }
        assert_eq!(got.len(), POINTS, "points of line {k}");
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(
                g.to_bits(),
                w.to_bits(),
                "line {k} point {i}: stored {g} µm, served {w} µm"
            );
        }
        let meta: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(lines_dir.join(format!("{k:04}.json"))).expect("json"),
        )
        .expect("json parses");
        assert_eq!(meta["index"], k as u64);
        assert_eq!(meta["points"], POINTS as u64);
        assert_eq!(meta["y_target_nm"], target_nm(k));
        assert_eq!(
            meta["y_readback_nm"],
            target_nm(k),
            "line {k}: stage read back at the target"
        );
    }
}

/// Checks the journal of a successful scan: start first, one line record per index in
/// order, the stop record `success` last.
pub fn assert_journal_complete(dir: &Path, n: usize) -> Vec<Record> {
    let (records, state) = journal(dir);
    assert!(matches!(records.first(), Some(Record::Start(_))));
    assert_eq!(
        line_record_indices(&records),
        (0..n as u32).collect::<Vec<_>>(),
        "one line record per index"
    );
    assert!(state.duplicates.is_empty());
    match records.last() {
        Some(Record::Stop(s)) => assert_eq!(
            s.status,
            surfscan::scan::journal::StopStatus::Success,
            "{s:?}"
        ),
        other => panic!("last record is not a stop record: {other:?}"),
    }
    let stops = records
        .iter()
        .filter(|r| matches!(r, Record::Stop(_)))
        .count();
    assert_eq!(stops, 1, "one stop record");
    records
}

/// Knots and poles of every surface in an IGES file, as f64 bit patterns.
pub fn surface_bits(path: &Path) -> Vec<Vec<u64>> {
    let file = surfscan::iges::read_iges(&std::fs::read(path).expect("iges")).expect("iges reads");
    file.surfaces
        .iter()
        .map(|s| {
            let mut bits: Vec<u64> = vec![s.degree_u() as u64, s.degree_v() as u64];
            bits.extend(s.knots_u().iter().map(|v| v.to_bits()));
            bits.extend(s.knots_v().iter().map(|v| v.to_bits()));
            bits.extend(s.poles().flat_map(|p| p.map(|v| v.to_bits())));
            bits
        })
        .collect()
}

/// Polls `cond` every 10 ms until it holds or `limit` passes.
pub async fn wait_until(limit: Duration, what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + limit;
    while !cond() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// The complete lines of a file another process appends to (up to its last newline; empty
/// while there is no file). A line may reach the file in more than one write (a buffered
/// writer's 4 KiB blocks; a write that crosses a page of the page cache is seen a page at a
/// time), so a line without its newline is still being written and is left for the next
/// read.
pub fn complete_lines(path: &Path) -> String {
    let mut bytes = std::fs::read(path).unwrap_or_default();
    bytes.truncate(bytes.iter().rposition(|b| *b == b'\n').map_or(0, |i| i + 1));
    String::from_utf8_lossy(&bytes).into_owned()
}

/// Number of line records in the journal of the one scan under `out` (0 while none).
pub fn committed_lines(out: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(out) else {
        return 0;
    };
    for e in entries.flatten() {
        let j = e.path().join("journal.jsonl");
        if let Ok(rec) = read_journal(&j) {
            return line_record_indices(&rec.records).len();
        }
    }
    0
}

/// Waits until the metrics file `metrics` counts a suspension of the scan.
pub async fn wait_for_suspension(metrics: &Path) {
    wait_until(Duration::from_secs(60), "the scan suspended", || {
        std::fs::read_to_string(metrics).is_ok_and(|m| {
            m.lines()
                .any(|l| l.starts_with("surfscan_suspensions_total{") && !l.ends_with(" 0"))
        })
    })
    .await;
}

/// The Python interpreter of the independent reference checks: `$SURFSCAN_PYTHON` when set,
/// else the virtual environment `.ci/run` creates in the checkout (`.venv/`). A missing
/// interpreter fails the calling test with what to do; the checks are never skipped.
pub fn python() -> std::process::Command {
    let python = match std::env::var_os("SURFSCAN_PYTHON") {
        Some(p) => PathBuf::from(p),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python3"),
    };
    assert!(
        python.exists(),
        "no Python for the reference checks at {}: run `bash .ci/run` once (it creates .venv/ \
         from tests/python/requirements.txt), or set SURFSCAN_PYTHON to an interpreter that has \
         those packages",
        python.display()
    );
    std::process::Command::new(python)
}

/// The reference script `tests/python/NAME` under [`python`]; its arguments follow.
pub fn reference_script(name: &str) -> Command {
    let mut c = python();
    c.arg(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/python")
            .join(name),
    );
    c
}

/// Runs a reference script and returns the JSON it prints; a script that fails fails the test
/// with its command line and standard error.
pub fn json_from(script: &mut Command) -> serde_json::Value {
    let out = script.output().unwrap();
    assert!(
        out.status.success(),
        "{script:?} failed (run `bash .ci/run`, which installs tests/python/requirements.txt into .venv/):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("a reference script prints JSON")
}

/// Copies the directory tree `from` to `to` (created), files and subdirectories.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dest = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dest);
        } else {
            std::fs::copy(e.path(), dest).unwrap();
        }
    }
}

/// Checks a report.json's timings for a surface the characterisation fitted itself: the fit
/// is timed, and counted in the total with the model sections.
pub fn assert_fit_timed(report: &serde_json::Value) {
    let t = &report["timings_s"];
    let fit_s = t["fit"].as_f64().unwrap();
    assert!(fit_s > 0.0, "{t}");
    assert!(
        t["total"].as_f64().unwrap() >= fit_s + t["model"].as_f64().unwrap(),
        "{t}"
    );
}

/// Asserts that `e` refuses a plan as outside the travel the stage controller itself
/// enforces, [`min`, `max`].
pub fn assert_outside_controller_travel(
    e: &surfscan::stage::StageError,
    min: surfscan::units::Nm,
    max: surfscan::units::Nm,
) {
    assert!(
        matches!(
            e,
            surfscan::stage::StageError::OutsideControllerTravel { min: lo, max: hi, .. }
                if *lo == min && *hi == max
        ),
        "{e}"
    );
}

/// A file system mounted for one test and unmounted when the test ends (also on failure).
pub struct Mount(PathBuf);

impl Mount {
    /// A tmpfs of `bytes` at `dir` (created). The tests run as root, as `.ci/run` does.
    pub fn tmpfs(dir: &std::path::Path, bytes: u64) -> Mount {
        Mount::mount_tmpfs(dir, &format!("size={bytes}"))
    }

    /// A tmpfs of `bytes` with room for `inodes` files at `dir` (created).
    pub fn tmpfs_with_inodes(dir: &std::path::Path, bytes: u64, inodes: u64) -> Mount {
        Mount::mount_tmpfs(dir, &format!("size={bytes},nr_inodes={inodes}"))
    }

    fn mount_tmpfs(dir: &std::path::Path, options: &str) -> Mount {
        std::fs::create_dir_all(dir).unwrap();
        let o = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", options])
            .arg("tmpfs")
            .arg(dir)
            .output()
            .expect("run mount");
        assert!(
            o.status.success(),
            "this test mounts a small tmpfs to fill it for real and needs root (as .ci/run runs): {}",
            String::from_utf8_lossy(&o.stderr)
        );
        Mount(dir.to_path_buf())
    }
}

impl Drop for Mount {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg("-l")
            .arg(&self.0)
            .status();
    }
}

/// Writes zeros into `path` until the file system refuses (ENOSPC); returns the bytes written.
pub fn fill(path: &std::path::Path) -> u64 {
    use std::io::Write;
    let mut f = std::fs::File::create(path).unwrap();
    let chunk = vec![0u8; 64 * 1024];
    let mut n = 0u64;
    loop {
        match f.write(&chunk) {
            Ok(0) => break,
            Ok(k) => n += k as u64,
            Err(e) if e.raw_os_error() == Some(libc::ENOSPC) => break,
            Err(e) => panic!("filling {}: {e}", path.display()),
        }
    }
    let _ = f.sync_all();
    n
}

/// Runs the real `surfscan probe` with `args` (at most `limit_s` seconds): its exit code,
/// standard output and standard error.
pub async fn run_probe<S: AsRef<std::ffi::OsStr>>(
    args: &[S],
    limit_s: u64,
) -> (Option<i32>, String, String) {
    let child = tokio::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("probe")
        .args(args)
        .kill_on_drop(true)
        .output();
    let out = tokio::time::timeout(Duration::from_secs(limit_s), child)
        .await
        .unwrap_or_else(|_| panic!("surfscan probe did not finish within {limit_s} s"))
        .expect("surfscan probe ran");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The commands a recorded transcript (format v1) sent to the instrument, in order.
pub fn sent_commands(transcript: &str) -> Vec<String> {
    let t = surfscan_sim::replay::Transcript::parse(transcript).expect("transcript parses");
    t.entries
        .iter()
        .filter(|e| e.dir == surfscan_sim::replay::Dir::ToDevice)
        .map(|e| String::from_utf8_lossy(&e.bytes).trim_end().to_string())
        .collect()
}

/// `check-config` of the demo's station configuration with `[section]` holding each `table`
/// in turn must exit 78 and name its `key`.
pub fn assert_tables_refused(section: &str, cases: &[(&str, &str)]) {
    let dir = tempfile::tempdir().unwrap();
    let base = surfscan::cli::demo::demo_config(
        &dir.path().join("i"),
        &dir.path().join("s"),
        &dir.path().join("scans"),
    );
    for (table, key) in cases {
        let config = dir.path().join("station.toml");
        std::fs::write(&config, format!("{base}\n[{section}]\n{table}\n")).unwrap();
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["check-config", "--config"])
            .arg(&config)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(78), "{table}: {err}");
        assert!(err.contains(key), "{table}: {err}");
    }
}

/// The bundled sur-2 grid's pitches (mm).
pub const SUR2_PITCH_X_MM: f64 = 0.003484;
pub const SUR2_PITCH_Y_MM: f64 = 0.010452;

/// The first `rows` lines and `cols` columns of the bundled sur-2 grid, row after row, in µm.
pub fn sur2_window(rows: usize, cols: usize) -> Vec<f64> {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/sur-2.grid.csv"
    ))
    .unwrap();
    text.lines()
        .take(rows)
        .flat_map(|l| {
            l.split(',')
                .take(cols)
                .map(|f| f.trim().parse::<f64>().unwrap())
                .collect::<Vec<_>>()
        })
        .collect()
}

/// xmllint's verdict on `file` against the schema `xsd` (relative to the checkout), named
/// `what` in the failure.
pub fn assert_validates(file: &Path, xsd: &str, what: &str) {
    let o = Command::new("xmllint")
        .args(["--noout", "--schema"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join(xsd))
        .arg(file)
        .output()
        .unwrap_or_else(|e| {
            panic!("cannot run xmllint ({e}); `bash .ci/run` installs libxml2-utils")
        });
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success() && err.contains("validates"),
        "{} does not validate against {what}:\n{err}",
        file.display()
    );
}

/// `text` with every `from` replaced by `to`, failing when `text` has no `from`: an edit of a
/// config, recipe or data file that matches nothing would leave a test checking the text as it
/// was, and passing for the wrong reason.
#[track_caller]
pub fn edited(text: &str, from: &str, to: &str) -> String {
    assert!(
        text.contains(from),
        "the text to edit has no {from:?}:\n{text}"
    );
    text.replace(from, to)
}

/// Replaces `from` with `to` in the file at `path`, failing as [`edited`] does when it has no
/// `from`.
#[track_caller]
pub fn edit_file(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    std::fs::write(path, edited(&text, from, to)).unwrap();
}

/// Appends `text` (a table or a key the test needs) to the configuration file `config`.
#[track_caller]
pub fn append_config(config: &Path, text: &str) {
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(config)
        .unwrap();
    std::io::Write::write_all(&mut f, text.as_bytes()).unwrap();
}

/// Swaps the instrument's and the stage's ports (`instrument`, `stage`) in the configuration
/// file `config`; returns them as the file quotes them, the instrument's first.
pub fn swap_ports(config: &Path, instrument: &Path, stage: &Path) -> (String, String) {
    let (i, s) = (
        format!("{:?}", instrument.display().to_string()),
        format!("{:?}", stage.display().to_string()),
    );
    let text = std::fs::read_to_string(config).unwrap();
    let held = "\"@INSTRUMENT@\"";
    let swapped = edited(&edited(&edited(&text, &i, held), &s, &i), held, &s);
    std::fs::write(config, swapped).unwrap();
    (i, s)
}

/// Line `k`'s metadata (`lines/NNNN.json`) in the scan directory `dir`.
pub fn line_meta(dir: &Path, k: u32) -> serde_json::Value {
    let path = dir.join(format!("lines/{k:04}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path:?}: {e}"))
}

/// Asserts that none of the lines `lines` of the scan directory `dir` carries a read-out
/// warning in its metadata.
pub fn assert_no_readout_warnings(dir: &Path, lines: impl IntoIterator<Item = u32>) {
    for k in lines {
        let m = line_meta(dir, k);
        assert!(m.get("readout_warnings").is_none(), "line {k}: {m}");
    }
}

/// The warnings of a report (report.json's `warnings`).
pub fn report_warnings(report: &serde_json::Value) -> Vec<&str> {
    report["warnings"]
        .as_array()
        .expect("report warnings")
        .iter()
        .filter_map(|w| w.as_str())
        .collect()
}

/// The demo's configuration for devices `inst` and `stage`, scans under `scans`, with its
/// control socket at `socket`.
pub fn demo_config_at(inst: &Path, stage: &Path, scans: &Path, socket: &Path) -> String {
    edited(
        &surfscan::cli::demo::demo_config(inst, stage, scans),
        &format!(
            "{:?}",
            surfscan::cli::demo::demo_socket(scans)
                .display()
                .to_string()
        ),
        &format!("{:?}", socket.display().to_string()),
    )
}

/// A server certificate and key for IP 127.0.0.1, signed by a CA made for the test; no
/// system authority knows that CA.
pub struct ThrowawayTls {
    /// The CA's certificate (PEM), the one a client must be told to trust.
    pub ca: PathBuf,
    /// The server's certificate (PEM).
    pub certificate: PathBuf,
    /// The server's private key (PEM).
    pub key: PathBuf,
}

/// Makes a [`ThrowawayTls`] in `dir` with `openssl` (Debian package `openssl`, which
/// `.ci/run` installs).
pub fn throwaway_tls(dir: &Path) -> ThrowawayTls {
    let openssl = |args: &[&str]| {
        let out = std::process::Command::new("openssl")
            .args(args)
            .current_dir(dir)
            .output()
            .expect(
                "openssl is not installed: `bash .ci/run` installs it (apt-get install openssl)",
            );
        assert!(
            out.status.success(),
            "openssl {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let rsa = ["-newkey", "rsa:2048", "-nodes"];
    openssl(
        &[
            &["req", "-x509"][..],
            &rsa,
            &[
                "-days",
                "2",
                "-subj",
                "/CN=throwaway test CA",
                "-keyout",
                "ca.key",
                "-out",
                "ca.pem",
            ],
        ]
        .concat(),
    );
    openssl(
        &[
            &["req"][..],
            &rsa,
            &[
                "-subj",
                "/CN=127.0.0.1",
                "-keyout",
                "server.key",
                "-out",
                "server.csr",
            ],
        ]
        .concat(),
    );
    std::fs::write(dir.join("san.ext"), "subjectAltName = IP:127.0.0.1\n").unwrap();
    openssl(&[
        "x509",
        "-req",
        "-in",
        "server.csr",
        "-CA",
        "ca.pem",
        "-CAkey",
        "ca.key",
        "-CAcreateserial",
        "-days",
        "2",
        "-extfile",
        "san.ext",
        "-out",
        "server.pem",
    ]);
    ThrowawayTls {
        ca: dir.join("ca.pem"),
        certificate: dir.join("server.pem"),
        key: dir.join("server.key"),
    }
}

/// The standard output of `command`, a tool from the Debian package `package`: a tool that is
/// missing names the package, and one that fails shows what it said.
pub fn tool_output(command: &mut std::process::Command, package: &str) -> Vec<u8> {
    let tool = command.get_program().to_string_lossy().into_owned();
    let out = command.output().unwrap_or_else(|e| {
        panic!("{tool}: {e}; run `bash .ci/run` or `apt-get install {package}`")
    });
    assert!(
        out.status.success(),
        "{tool}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// The second column of a CSV file with a header row in `tests/data/real`.
pub fn second_column(name: &str) -> Vec<f64> {
    let path = format!("{}/tests/data/real/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect()
}

/// The Mitutoyo export's R profile (6664 ordinates 1.5 µm apart), heights in µm.
pub fn mitutoyo_r_profile() -> Vec<f64> {
    second_column("mitutoyo_surftest_R.x_mm_z_um.csv")
}
