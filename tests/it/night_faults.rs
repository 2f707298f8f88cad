//! An operator's worst night, end to end: each finding of the adversarial campaign as the
//! real binaries meet it. The simulator runs in-process where a wire fault is enough, and as
//! its own `surfscan-sim` process where the test stops and continues it with signals.
//!
//! Every test here runs in CI (as root on Debian, as `.ci/run` does); one that needs a
//! capability checks for it and fails loudly without it.

use crate::common::*;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};
use surfscan::control::client::ControlClient;
use surfscan::control::protocol::{Message, Request};
use surfscan::scan::command::StartMode;
use surfscan::scan::ending::{FailCause, StopStatus};
use surfscan::scan::journal::Record;
use surfscan::scan::status::{State, Status};
use tokio::io::AsyncBufReadExt;

/// A link that stops taking the host's bytes for longer than the write deadline (the
/// instrument holds the host back by flow control for 5 s, from the third trace on), with a
/// transient budget of 2 s: the scan suspends, the stalled write is named, nothing fails for
/// the budget, and the scan completes with every line once and on target.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_link_that_takes_no_bytes_suspends_the_scan_which_then_completes() {
    let rig = Rig::start(RigOptions {
        faults: vec!["deaf:5000@CTSTA#3".into()],
        extra_scan: "transient-budget-s = 2\n".into(),
        ..RigOptions::default()
    })
    .await;
    let n = rig.options.lines;
    let t0 = Instant::now();
    let o = run_scan(&rig.config("out"), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    assert!(t0.elapsed() >= Duration::from_secs(5), "{:?}", t0.elapsed());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("byte(s) and then none for 2000 ms"),
        "the stalled write is named: {stderr}"
    );
    let dir = scan_dir(&rig.out_dir("out"));
    assert_lines_exactly(&dir, n);
    let notes = interruptions(&assert_journal_complete(&dir, n));
    assert!(
        notes
            .iter()
            .any(|r| r.starts_with("line 3 abandoned: instrument:")),
        "{notes:?}"
    );
    assert!(
        notes
            .iter()
            .any(|r| r.starts_with("instrument not answering (")),
        "{notes:?}"
    );
    assert!(
        notes.iter().any(|r| r.starts_with("instrument back after")),
        "{notes:?}"
    );
    rig.shutdown().await;
}

/// The `surfscan-sim` binary beside `surfscan` (built by `cargo test --workspace`, as
/// `.ci/run` runs it).
fn simulator_binary() -> PathBuf {
    let p = Path::new(env!("CARGO_BIN_EXE_surfscan")).with_file_name("surfscan-sim");
    assert!(
        p.is_file(),
        "{} is missing: this test runs the simulator as a process of its own; build it with `cargo build -p surfscan-sim` (`cargo test --workspace` does)",
        p.display()
    );
    p
}

/// A station of two processes: `surfscan-sim` serving the devices and `surfscan daemon`
/// scanning them, both killed when the test ends.
struct Station {
    dir: tempfile::TempDir,
    sim: tokio::process::Child,
    daemon: tokio::process::Child,
    socket: PathBuf,
}

impl Station {
    /// Starts the simulator (with `sim_args`) writing its station configuration, sets `scan`
    /// and `[instrument.timeouts]` keys into it, and starts the daemon on it.
    async fn start(sim_args: &[&str], scan: &str, timeouts: &str) -> Station {
        let dir = tempfile::tempdir().unwrap();
        let config = dir.path().join("station.toml");
        let mut sim = tokio::process::Command::new(simulator_binary())
            .arg("--instrument-link")
            .arg(dir.path().join("sj210"))
            .arg("--stage-link")
            .arg(dir.path().join("ystage"))
            .args(["--stage-protocol", "grbl", "--time-scale", "0.02"])
            .args(sim_args)
            .arg("--write-config")
            .arg(&config)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .kill_on_drop(true)
            .spawn()
            .expect("surfscan-sim starts");
        let mut lines = tokio::io::BufReader::new(sim.stdout.take().unwrap()).lines();
        let ready = tokio::time::timeout(Duration::from_secs(20), lines.next_line())
            .await
            .expect("the simulator is ready within 20 s")
            .unwrap()
            .unwrap_or_default();
        assert!(ready.contains("\"event\":\"ready\""), "{ready}");
        tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
        let text = std::fs::read_to_string(&config).expect("the station configuration");
        let text = text
            .replacen("[scan]\n", &format!("[scan]\n{scan}"), 1)
            .replacen("lines = 31\n", "lines = 8\n", 1);
        let text = text.replacen(
            "[instrument.timeouts]\n",
            &format!("[instrument.timeouts]\n{timeouts}"),
            1,
        );
        std::fs::write(&config, text).unwrap();
        let locks = dir.path().join("locks");
        std::fs::create_dir_all(&locks).unwrap();
        let daemon = tokio::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["daemon", "--config"])
            .arg(&config)
            .env("SURFSCAN_TEST_LOCK_DIR", &locks)
            .env("RUST_LOG", "info")
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(dir.path().join("daemon.log")).unwrap())
            .kill_on_drop(true)
            .spawn()
            .expect("the daemon starts");
        let socket = dir.path().join("control.sock");
        let s = Station {
            dir,
            sim,
            daemon,
            socket,
        };
        s.wait("the control socket", Duration::from_secs(20), |_| true)
            .await;
        s
    }

    fn out(&self) -> PathBuf {
        self.dir.path().join("scans")
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("daemon.log")).unwrap_or_default()
    }

    async fn status(&self) -> Option<Status> {
        let mut c = ControlClient::connect(&self.socket).await.ok()?;
        match c.request(&Request::Status).await.ok()?.message {
            Message::Status(s) => Some(*s),
            _ => None,
        }
    }

    /// Waits until the daemon's status satisfies `f`, for at most `limit`.
    async fn wait(&self, what: &str, limit: Duration, f: impl Fn(&Status) -> bool) -> Status {
        let t0 = Instant::now();
        loop {
            if let Some(s) = self.status().await {
                if f(&s) {
                    return s;
                }
            }
            assert!(
                t0.elapsed() < limit,
                "{what}: last status {:?}\n--- daemon log\n{}",
                self.status().await,
                self.log()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    async fn start_scan(&self) {
        let ack = ControlClient::connect(&self.socket)
            .await
            .unwrap()
            .request(&Request::Start {
                specimen: "night".into(),
                operator: String::new(),
                notes: String::new(),
                mode: StartMode::Auto,
                recipe: None,
                y_start_mm: None,
            })
            .await
            .unwrap();
        assert!(matches!(ack.message, Message::Ack { .. }), "{ack:?}");
    }

    fn signal_simulator(&self, sig: nix::sys::signal::Signal) {
        let pid = nix::unistd::Pid::from_raw(self.sim.id().expect("simulator runs") as i32);
        nix::sys::signal::kill(pid, sig).unwrap();
    }

    async fn stop(mut self) {
        if let Some(pid) = self.daemon.id() {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(pid as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
        let _ = tokio::time::timeout(Duration::from_secs(20), self.daemon.wait()).await;
        let _ = self.sim.kill().await;
    }
}

/// The records of the one scan under `out`.
fn the_scan(out: &Path) -> (PathBuf, Vec<Record>) {
    let dir = scan_dir(out);
    let (records, _) = journal(&dir);
    (dir, records)
}

/// The simulator stopped (SIGSTOP) mid-scan for four times the transient budget, then
/// continued (SIGCONT): a silent instrument and stage are waited for without a time limit,
/// the daemon shows the scan suspended "not answering" meanwhile, and the same scan goes on
/// by itself and completes; nothing fails, no new scan starts.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stopped_simulator_past_the_budget_is_waited_for_and_the_scan_completes() {
    let station = Station::start(
        &[],
        "transient-budget-s = 2\nreconnect-initial-ms = 200\nreconnect-max-ms = 1000\n",
        "",
    )
    .await;
    station.start_scan().await;
    station
        .wait("two lines on disk", Duration::from_secs(60), |s| {
            s.lines_done >= 2
        })
        .await;
    station.signal_simulator(nix::sys::signal::Signal::SIGSTOP);
    let s = station
        .wait("suspended, not answering", Duration::from_secs(30), |s| {
            s.state == State::Suspended
                && s.reason
                    .as_deref()
                    .is_some_and(|r| r.contains("not answering"))
        })
        .await;
    let held = s.lines_done;
    tokio::time::sleep(Duration::from_secs(8)).await;
    let s = station.status().await.expect("status");
    assert_eq!(s.state, State::Suspended, "{s:?}");
    assert_eq!(
        s.lines_done, held,
        "nothing is traced while the devices are silent"
    );
    assert!(s.last_stop.is_none(), "nothing ended: {s:?}");
    station.signal_simulator(nix::sys::signal::Signal::SIGCONT);
    let s = station
        .wait("the scan completes", Duration::from_secs(120), |s| {
            s.state == State::Idle && s.last_stop.is_some()
        })
        .await;
    let stop = s.last_stop.expect("last stop");
    assert_eq!(
        stop.status,
        StopStatus::Success,
        "{stop:?}\n{}",
        station.log()
    );
    let (_, records) = the_scan(&station.out());
    let stops: Vec<&Record> = records
        .iter()
        .filter(|r| matches!(r, Record::Stop(_)))
        .collect();
    assert_eq!(stops.len(), 1, "one stop record, the success: {stops:?}");
    let notes = interruptions(&records);
    assert!(
        notes.iter().any(|r| r.contains("not answering")),
        "{notes:?}"
    );
    station.stop().await;
}

/// An instrument that answers busy (NG011) for longer than the transient budget (and the
/// driver's own read retries, 0.5 s here) fails the scan for its budget; the daemon then asks
/// the devices with backoff and, once they answer properly again, continues the same scan by
/// itself to its end.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_failed_for_its_budget_is_continued_by_the_daemon_when_the_devices_answer() {
    let station = Station::start(
        &["--fault", "busy:6000@CTSTA#3"],
        "transient-budget-s = 2\nreconnect-initial-ms = 200\nreconnect-max-ms = 1000\n",
        "read-retry-budget-ms = 500\n",
    )
    .await;
    station.start_scan().await;
    let s = station
        .wait(
            "the scan fails for its budget",
            Duration::from_secs(60),
            |s| {
                s.last_stop
                    .as_ref()
                    .is_some_and(|l| l.status == StopStatus::Fail)
            },
        )
        .await;
    assert!(
        s.last_stop
            .as_ref()
            .is_some_and(|l| l.reason.contains("outlasted the 2 s budget")),
        "{s:?}"
    );
    let s = station
        .wait(
            "the continued scan completes",
            Duration::from_secs(120),
            |s| {
                s.state == State::Idle
                    && s.last_stop
                        .as_ref()
                        .is_some_and(|l| l.status == StopStatus::Success)
            },
        )
        .await;
    assert_eq!(s.lines_total, 0, "idle: {s:?}");
    let (_, records) = the_scan(&station.out());
    let fail = records
        .iter()
        .position(|r| matches!(r, Record::Stop(s) if s.status == StopStatus::Fail))
        .expect("the fail stop record");
    match &records[fail] {
        Record::Stop(s) => assert_eq!(s.fail_cause(), Some(FailCause::Budget), "{s:?}"),
        _ => unreachable!(),
    }
    assert!(
        matches!(records.get(fail + 1), Some(Record::Continue(c)) if c.peer.is_none()),
        "continued by the daemon itself: {:?}",
        records.get(fail + 1)
    );
    assert!(
        matches!(records.last(), Some(Record::Stop(s)) if s.status == StopStatus::Success),
        "{:?}",
        records.last()
    );
    let n = line_record_indices(&records);
    let mut sorted = n.clone();
    sorted.sort();
    sorted.dedup();
    assert_eq!(n.len(), sorted.len(), "each line once: {n:?}");
    station.stop().await;
}

/// Runs `cmd`, failing loudly (the tests run as root, as `.ci/run` does) when it fails.
fn run(cmd: &[&str], path: &Path) {
    let o = std::process::Command::new(cmd[0])
        .args(&cmd[1..])
        .arg(path)
        .output()
        .unwrap_or_else(|e| panic!("{} cannot run: {e}", cmd[0]));
    assert!(
        o.status.success(),
        "{cmd:?} {}: {} (these tests need root and {}, as .ci/run provides)",
        path.display(),
        String::from_utf8_lossy(&o.stderr),
        cmd[0]
    );
}

/// How a test makes the scan's storage refuse writes mid-scan.
#[derive(Debug, Clone, Copy)]
enum Refuse {
    /// The scan's `lines/` bind-mounted on itself and remounted read-only (`EROFS`; a file
    /// system with a file open for writing cannot be remounted read-only but by force, which
    /// the journal's would be).
    ReadOnlyRemount,
    /// The scan's `lines/` made immutable (`chattr +i`: `EPERM`).
    Immutable,
}

/// A scan whose storage refuses writes after two lines and takes them again seconds later:
/// the scan suspends (the traced line held in memory, the refusal named with its errno in
/// the journal), never fails, and the same scan completes; no new scan starts.
async fn storage_refuses_mid_scan(how: Refuse) {
    const N: usize = 6;
    let rig = Rig::start(RigOptions {
        lines: N,
        ..RigOptions::default()
    })
    .await;
    let out = rig.out_dir("out");
    std::fs::create_dir_all(&out).unwrap();
    let (mut scan, metrics) = rig.scan_past_two_lines("out").await;
    let dir = scan_dir(&out);
    let lines = dir.join("lines");
    let bind = match how {
        Refuse::ReadOnlyRemount => {
            run(&["mount", "--bind", lines.to_str().expect("UTF-8")], &lines);
            let bind = BindMount(lines.clone());
            run(&["mount", "-o", "remount,ro,bind"], &lines);
            Some(bind)
        }
        Refuse::Immutable => {
            run(&["chattr", "+i"], &lines);
            None
        }
    };
    wait_for_suspension(&metrics).await;
    let held = committed_lines(&out);
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_eq!(
        committed_lines(&out),
        held,
        "nothing is committed meanwhile"
    );
    assert!(
        scan.try_wait().unwrap().is_none(),
        "{how:?}: the scan waits instead of ending"
    );
    match how {
        Refuse::ReadOnlyRemount => run(&["mount", "-o", "remount,rw,bind"], &lines),
        Refuse::Immutable => run(&["chattr", "-i"], &lines),
    }
    let o = tokio::time::timeout(Duration::from_secs(120), scan.wait_with_output())
        .await
        .expect("the scan ends")
        .unwrap();
    assert!(o.status.success(), "{how:?}: {}", describe(&o));
    assert_eq!(scan_dir(&out), dir, "the same scan, no new one");
    assert_lines_exactly(&dir, N);
    let notes = interruptions(&assert_journal_complete(&dir, N));
    let errno = match how {
        Refuse::ReadOnlyRemount => "EROFS",
        Refuse::Immutable => "EPERM",
    };
    let suspended: Vec<&String> = notes
        .iter()
        .filter(|r| r.starts_with("suspended:"))
        .collect();
    assert_eq!(suspended.len(), 1, "{how:?}: one suspension: {notes:?}");
    assert!(
        suspended[0].starts_with(&format!(
            "suspended: the file system refused writing line {} ({errno}: ",
            held + 1
        )),
        "{how:?}: {notes:?}"
    );
    assert!(
        notes
            .iter()
            .any(|r| r.starts_with("the output directory takes writes again after")),
        "{how:?}: {notes:?}"
    );
    drop(bind);
    rig.shutdown().await;
}

/// A bind mount, unmounted when the test ends (also on failure).
struct BindMount(PathBuf);

impl Drop for BindMount {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg("-l")
            .arg(&self.0)
            .status();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_read_only_remount_mid_scan_suspends_the_scan_which_completes_when_writable() {
    storage_refuses_mid_scan(Refuse::ReadOnlyRemount).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_immutable_lines_directory_mid_scan_suspends_the_scan_which_completes_after() {
    storage_refuses_mid_scan(Refuse::Immutable).await;
}

/// The output directory's file system runs out of inodes mid-scan (a tmpfs with few, and
/// empty ballast files taking the rest): the scan suspends without flapping — one
/// suspension recorded, a handful of journal records at most while it waits — and completes
/// when the ballast is deleted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn out_of_inodes_suspends_without_flapping_and_completes_when_files_are_freed() {
    const N: usize = 6;
    let rig = Rig::start(RigOptions {
        lines: N,
        ..RigOptions::default()
    })
    .await;
    let out = rig.out_dir("out");
    let mount = Mount::tmpfs_with_inodes(&out, 64 << 20, 400);
    let config = rig.config("out");
    let mut scan = scan_command(&config, &[]).spawn().expect("scan starts");
    wait_until(Duration::from_secs(60), "two lines on disk", || {
        committed_lines(&out) >= 2 || scan.try_wait().is_ok_and(|s| s.is_some())
    })
    .await;
    assert!(
        scan.try_wait().unwrap().is_none(),
        "the scan runs: {}",
        describe(&scan.wait_with_output().await.unwrap())
    );
    let dir = scan_dir(&out);
    // Empty ballast files beside the scan directory take every inode left.
    let ballast = |k: usize| out.join(format!("ballast-{k}"));
    let mut made = 0usize;
    while std::fs::File::create(ballast(made)).is_ok() {
        made += 1;
    }
    assert!(made > 0, "the ballast took the free inodes");
    let records = || {
        surfscan::scan::journal::read_journal(&dir.join("journal.jsonl"))
            .map(|r| r.records.len())
            .unwrap_or(0)
    };
    // Waiting for inodes for a while: the journal does not grow by a record per try.
    tokio::time::sleep(Duration::from_secs(2)).await;
    let before = records();
    tokio::time::sleep(Duration::from_secs(4)).await;
    let grown = records() - before;
    assert!(
        grown <= 2,
        "{grown} journal records in 4 s while waiting for inodes"
    );
    assert!(scan.try_wait().unwrap().is_none(), "the scan waits");
    for k in 0..made {
        std::fs::remove_file(ballast(k)).unwrap();
    }
    let o = tokio::time::timeout(Duration::from_secs(120), scan.wait_with_output())
        .await
        .expect("the scan ends")
        .unwrap();
    assert!(o.status.success(), "{}", describe(&o));
    assert_lines_exactly(&dir, N);
    let notes = interruptions(&assert_journal_complete(&dir, N));
    let suspended = notes.iter().filter(|r| r.starts_with("suspended:")).count();
    assert_eq!(suspended, 1, "{notes:?}");
    assert!(
        notes.len() <= 4,
        "a handful of records about the suspension: {notes:?}"
    );
    drop(mount);
    rig.shutdown().await;
}

/// The instrument's and the stage's ports swapped in the configuration: the scan refuses to
/// start and says the ports look swapped (the GRBL controller answered the instrument's
/// command with `error:N`), instead of blaming the baud rate and parity.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn swapped_ports_are_named_as_swapped() {
    let rig = Rig::start(RigOptions::default()).await;
    let config = rig.config("out");
    let (i, s) = swap_ports(&config, &rig.instrument_link, &rig.stage_link);
    let o = tokio::time::timeout(Duration::from_secs(120), run_scan(&config, &[]))
        .await
        .expect("the scan ends");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{}", describe(&o));
    // Both configured ports named, with the keys that hold them.
    assert!(
        err.contains("ports look swapped")
            && err.contains(&format!(
                "exchange the values of [instrument] port = {s} and [stage] port = {i}"
            )),
        "{}",
        describe(&o)
    );
    assert!(!err.contains("check baud and parity"), "{err}");
    rig.shutdown().await;
}

/// Settings that shape a scan's lines are frozen with it: killed after line 3, its
/// configuration's backlash edited, the scan resumed by a plain start keeps its own
/// backlash (named in the journal and the log, with the edited value applied to the next
/// scan) and completes; a new scan then starts with the edited configuration.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_resumed_scan_keeps_its_own_stage_settings_over_an_edited_configuration() {
    let rig = Rig::start(RigOptions::default()).await;
    let n = rig.options.lines;
    let config = rig.config("out");
    let o = run_scan(&config, &[("SURFSCAN_TEST_CRASH", "2:after-commit")]).await;
    assert!(o.status.code().is_none(), "{}", describe(&o));
    edit_file(&config, "backlash-mm = 0.05", "backlash-mm = 0.08");

    let before = rig.stage.move_targets_nm().len();
    let o = run_scan(&config, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    // The motion itself: the resumed scan takes the backlash out once, approaching its
    // first target from 0.05 mm before it (the frozen value), never from 0.08 mm.
    let resumed = rig.stage.move_targets_nm()[before..].to_vec();
    assert_approach_nm(&resumed, 50_000);
    let dir = scan_dir(&rig.out_dir("out"));
    assert_lines_exactly(&dir, n);
    let records = assert_journal_complete(&dir, n);
    let notes = interruptions(&records);
    let kept = "[stage] backlash-mm: the scan keeps 0.05; the configuration now says 0.08";
    assert!(notes.iter().any(|r| r.starts_with(kept)), "{notes:?}");
    assert!(
        String::from_utf8_lossy(&o.stderr).contains(kept),
        "named in the log: {}",
        describe(&o)
    );
    // One start record: the same scan, resumed, not a new one.
    assert_eq!(
        records
            .iter()
            .filter(|r| matches!(r, Record::Start(_)))
            .count(),
        1
    );
    // A new scan moves with the edited backlash: the same measure sees the change.
    let before = rig.stage.move_targets_nm().len();
    let o = run_scan(&config, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    assert_approach_nm(&rig.stage.move_targets_nm()[before..], 80_000);
    let scans = std::fs::read_dir(rig.out_dir("out"))
        .unwrap()
        .filter(|e| e.as_ref().is_ok_and(|e| e.path().is_dir()))
        .count();
    assert_eq!(scans, 2, "the edited configuration started a new scan");
    rig.shutdown().await;
}

/// Asserts that a scan's stage moves (targets, nm) begin with one backlash approach of
/// `backlash_nm` (the first target that far before the second) and take no other approach
/// of any size: every later step goes on in the scan's direction by 0.01 mm, or returns.
fn assert_approach_nm(moves: &[i64], backlash_nm: i64) {
    assert!(moves.len() >= 3, "moves {moves:?}");
    let d: Vec<i64> = moves.windows(2).map(|w| w[1] - w[0]).collect();
    assert_eq!(d[0].abs(), backlash_nm, "approach then target: {moves:?}");
    let sign = d[0].signum();
    for (k, dk) in d.iter().enumerate().skip(1) {
        assert!(
            *dk == 10_000 * sign || dk.signum() == -sign,
            "move {k} steps {dk} nm, neither a 0.01 mm line step nor a return: {moves:?}"
        );
    }
}
