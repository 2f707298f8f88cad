//! End to end: the real `surfscan daemon` binary against the simulator (SJ-210 + GRBL stage,
//! started in-process on pseudo-terminals), driven through its control socket and watched
//! through a `NOTIFY_SOCKET` datagram socket bound by the test, as systemd would.
//!
//! Depends on the `surfscan` binary, the `surfscan_sim` library and the control client.

use crate::common::{demo_config_at, edited};
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use surfscan::control::client::ControlClient;
use surfscan::control::protocol::{Message, Request};
use surfscan::scan::command::StartMode;
use surfscan::scan::journal::{read_journal, Record, StopStatus};
use surfscan::scan::status::{DeviceState, State, Status};
use surfscan_sim::grbl::StageShared;
use surfscan_sim::{SimHandle, Simulator};

pub(crate) const SPEED_UP: f64 = 50.0;
pub(crate) const LINES: u32 = 8;
pub(crate) const DEADLINE: Duration = Duration::from_secs(90);

pub(crate) struct Rig {
    pub(crate) dir: tempfile::TempDir,
    pub(crate) sim: SimHandle,
    pub(crate) config: PathBuf,
    pub(crate) socket: PathBuf,
    pub(crate) notify: UnixDatagram,
}

impl Rig {
    pub(crate) fn out(&self) -> PathBuf {
        self.dir.path().join("scans")
    }
}

pub(crate) async fn rig() -> Rig {
    let dir = tempfile::tempdir().unwrap();
    let inst = dir.path().join("sj210");
    let stage = dir.path().join("ystage");
    let sim = crate::common::started(
        Simulator::sped_up_station(&inst, &stage, SPEED_UP, StageShared::new()).unwrap(),
    )
    .await;
    let socket = dir.path().join("run").join("control.sock");
    let text = edited(
        &demo_config_at(&inst, &stage, &dir.path().join("scans"), &socket),
        "lines = 31",
        &format!("lines = {LINES}"),
    );
    let hook_log = dir.path().join("hook.log");
    let text = format!(
        "{text}\n[fit]\ndegree-v = 3\n[metrics]\nfile = {:?}\n[notify]\ncommand = [\"/bin/sh\", \"-c\", \"env | grep ^SURFSCAN_ | sort >> {}\"]\n",
        dir.path().join("surfscan.prom").display().to_string(),
        hook_log.display()
    );
    let config = dir.path().join("station.toml");
    std::fs::write(&config, text).unwrap();
    let notify = UnixDatagram::bind(dir.path().join("notify.sock")).unwrap();
    notify
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    Rig {
        dir,
        sim,
        config,
        socket,
        notify,
    }
}

/// The daemon process; killed if the test fails before it exits, so no daemon outlives it.
pub(crate) struct Daemon(pub(crate) Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

impl std::ops::Deref for Daemon {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Daemon {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

pub(crate) fn spawn_daemon(r: &Rig) -> Daemon {
    spawn_daemon_to(r, Stdio::null())
}

/// The daemon with its log (stderr) going to `log`.
pub(crate) fn spawn_daemon_to(r: &Rig, log: Stdio) -> Daemon {
    Daemon(
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["daemon", "--config"])
            .arg(&r.config)
            .env("NOTIFY_SOCKET", r.dir.path().join("notify.sock"))
            .env_remove("WATCHDOG_USEC")
            .env_remove("RUST_LOG")
            .env("NO_COLOR", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap(),
    )
}

/// The rig's `daemon.log`, where a daemon spawned with it appends its log.
pub(crate) fn log_path(r: &Rig) -> PathBuf {
    r.dir.path().join("daemon.log")
}

/// The address the daemon's log (the rig's `daemon.log`) last names right after `said`, up to
/// the next `/`, once it names one: where a server configured on port 0 was bound.
pub(crate) fn logged_address(r: &Rig, said: &str) -> std::net::SocketAddr {
    let start = Instant::now();
    loop {
        let log = std::fs::read_to_string(log_path(r)).unwrap_or_default();
        let addr = log.rfind(said).and_then(|at| {
            let rest = &log[at + said.len()..];
            rest[..rest.find('/')?].parse().ok()
        });
        if let Some(addr) = addr {
            return addr;
        }
        assert!(
            start.elapsed() < DEADLINE,
            "the daemon's log names no address after {said:?}: {log}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Reads notify datagrams until one satisfies `want`; returns all seen. Fails at once when
/// the daemon has exited.
pub(crate) fn notify_until(r: &Rig, d: &mut Child, want: impl Fn(&str) -> bool) -> Vec<String> {
    let mut seen = Vec::new();
    let start = Instant::now();
    let mut buf = [0u8; 4096];
    while start.elapsed() < DEADLINE {
        let exited = d.try_wait().unwrap();
        if let Some(status) = exited {
            // Datagrams it sent before exiting may still wait in the socket: read them all
            // before concluding that the notification never came.
            r.notify.set_nonblocking(true).unwrap();
            while let Ok(n) = r.notify.recv(&mut buf) {
                seen.push(String::from_utf8_lossy(&buf[..n]).into_owned());
            }
            r.notify.set_nonblocking(false).unwrap();
            if seen.iter().any(|m: &String| want(m)) {
                return seen;
            }
            panic!("the daemon exited ({status}) before the notification; got {seen:?}");
        }
        if let Ok(n) = r.notify.recv(&mut buf) {
            let m = String::from_utf8_lossy(&buf[..n]).into_owned();
            let done = want(&m);
            seen.push(m);
            if done {
                return seen;
            }
        }
    }
    panic!("notify message not seen; got {seen:?}");
}

async fn client(r: &Rig) -> ControlClient {
    ControlClient::connect(&r.socket).await.unwrap()
}

pub(crate) async fn status(r: &Rig) -> Status {
    match client(r)
        .await
        .request(&Request::Status)
        .await
        .unwrap()
        .message
    {
        Message::Status(s) => *s,
        other => panic!("expected status, got {other:?}"),
    }
}

/// Asks the daemon to start a scan of `specimen` (resuming an unfinished one, as by default).
pub(crate) async fn start_scan(r: &Rig, specimen: &str) {
    client(r)
        .await
        .request(&Request::Start {
            specimen: specimen.into(),
            operator: String::new(),
            notes: String::new(),
            mode: StartMode::Auto,
            recipe: None,
            y_start_mm: None,
        })
        .await
        .unwrap();
}

pub(crate) async fn wait_status(r: &Rig, what: &str, f: impl Fn(&Status) -> bool) -> Status {
    let start = Instant::now();
    loop {
        let s = status(r).await;
        if f(&s) {
            return s;
        }
        assert!(start.elapsed() < DEADLINE, "{what}: last status {s:?}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

pub(crate) fn scan_dir(r: &Rig) -> PathBuf {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(r.out())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("journal.jsonl").exists())
        .collect();
    dirs.sort();
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    dirs.pop().unwrap()
}

pub(crate) fn records(dir: &Path) -> Vec<Record> {
    read_journal(&dir.join("journal.jsonl")).unwrap().records
}

pub(crate) fn line_indices(recs: &[Record]) -> Vec<u32> {
    recs.iter()
        .filter_map(|r| match r {
            Record::Line(l) => Some(l.id.index),
            _ => None,
        })
        .collect()
}

pub(crate) fn wait_exit(child: &mut Child) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(start.elapsed() < DEADLINE, "daemon did not exit");
        std::thread::sleep(Duration::from_millis(20));
    }
}

pub(crate) fn sigterm(child: &Child) {
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ready_after_the_socket_then_pause_resume_and_abort_through_the_socket() {
    let r = rig().await;
    let log_path = r.dir.path().join("daemon.log");
    let mut d = spawn_daemon_to(&r, std::fs::File::create(&log_path).unwrap().into());
    let seen = notify_until(&r, &mut d, |m| m.contains("READY=1"));
    assert!(
        r.socket.exists(),
        "READY=1 before the control socket was bound: {seen:?}"
    );
    // Idle: the greeting comes first, then status; no scan starts by itself.
    let mut c = client(&r).await;
    assert!(matches!(
        c.hello().message,
        Message::Hello { protocol: 1, .. }
    ));
    let s = status(&r).await;
    assert_eq!(s.state, State::Idle);
    // No scan directory: only the station's lock file (the daemon holds the station).
    assert!(
        !r.out().exists()
            || std::fs::read_dir(r.out())
                .unwrap()
                .all(|e| !e.unwrap().path().is_dir())
    );

    let ack = c
        .request(&Request::Start {
            specimen: "B-12".into(),
            operator: "ana".into(),
            notes: "socket test".into(),
            mode: StartMode::Auto,
            recipe: None,
            y_start_mm: None,
        })
        .await
        .unwrap();
    assert!(matches!(ack.message, Message::Ack { .. }), "{ack:?}");
    wait_status(&r, "scanning", |s| s.state == State::Scanning).await;
    // Deferred pause: takes effect once a line is on disk, never mid-line.
    let ack = client(&r).await.request(&Request::Pause).await.unwrap();
    assert!(matches!(ack.message, Message::Ack { .. }), "{ack:?}");
    let paused = wait_status(&r, "paused", |s| s.state == State::Paused).await;
    let dir = scan_dir(&r);
    let done = line_indices(&records(&dir));
    assert_eq!(done.len() as u32, paused.lines_done);
    assert!(paused.lines_done >= 1 && paused.lines_done < LINES);
    // While paused nothing is traced.
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(line_indices(&records(&dir)), done);
    let seen = notify_until(&r, &mut d, |m| {
        m.contains("STATUS=") && m.contains("paused")
    });
    assert!(seen.iter().any(|m| m.contains("STATUS=")), "{seen:?}");

    let ack = client(&r).await.request(&Request::Resume).await.unwrap();
    assert!(matches!(ack.message, Message::Ack { .. }), "{ack:?}");
    wait_status(&r, "progress after resume", |s| {
        s.lines_done > paused.lines_done
    })
    .await;
    let ack = client(&r).await.request(&Request::Abort).await.unwrap();
    assert!(matches!(ack.message, Message::Ack { .. }), "{ack:?}");
    let s = wait_status(&r, "idle after abort", |s| s.state == State::Idle).await;
    assert_eq!(s.last_stop.as_ref().unwrap().status, StopStatus::Abort);
    let recs = records(&dir);
    match recs.last().unwrap() {
        Record::Stop(s) => assert_eq!(s.status, StopStatus::Abort),
        other => panic!("last record {other:?}"),
    }
    assert!(recs.iter().any(
        |r| matches!(r, Record::Interruption(i) if i.reason.contains("paused by the operator"))
    ));
    // The operator's pause, resume and abort are the normal course of a scan: logged at
    // INFO, never as warnings a fault would give.
    let log = std::fs::read_to_string(&log_path).unwrap();
    let paused_at = |level: &str| {
        log.lines()
            .any(|l| l.contains(level) && l.contains("paused by the operator"))
    };
    assert!(paused_at(" INFO "), "{log}");
    assert!(!paused_at(" WARN "), "{log}");
    assert!(
        !log.lines()
            .any(|l| l.contains(" WARN ") && (l.contains("resume") || l.contains("abort"))),
        "{log}"
    );
    let idx = line_indices(&recs);
    let mut sorted = idx.clone();
    sorted.dedup();
    assert_eq!(idx, sorted, "each line exactly once, in order");
    // A foreground scan of the same station is refused while the daemon holds the ports.
    let fg = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["scan", "--config"])
        .arg(&r.config)
        .output()
        .unwrap();
    assert_eq!(fg.status.code(), Some(69));
    let err = String::from_utf8_lossy(&fg.stderr);
    assert!(
        err.contains("in use by surfscan daemon, pid") && err.contains("surfscan start"),
        "{err}"
    );
    // Pausing with no scan running is refused with a reason.
    let e = client(&r).await.request(&Request::Pause).await.unwrap();
    assert!(
        matches!(&e.message, Message::Error { message } if message.contains("no scan")),
        "{e:?}"
    );

    sigterm(&d);
    notify_until(&r, &mut d, |m| m.contains("STOPPING=1"));
    assert!(wait_exit(&mut d).success());
    assert!(!r.socket.exists(), "socket removed at shutdown");
    r.sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_mid_scan_records_an_interruption_and_the_restart_resumes_by_itself() {
    let r = rig().await;
    let mut d = spawn_daemon(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    start_scan(&r, "resume").await;
    wait_status(&r, "two lines", |s| s.lines_done >= 2).await;
    sigterm(&d);
    notify_until(&r, &mut d, |m| m.contains("STOPPING=1"));
    assert!(wait_exit(&mut d).success());
    let dir = scan_dir(&r);
    let recs = records(&dir);
    assert!(
        !recs.iter().any(|r| matches!(r, Record::Stop(_))),
        "SIGTERM must not end the scan"
    );
    assert!(
        matches!(recs.last().unwrap(), Record::Interruption(i) if i.reason.contains("shutdown"))
    );
    let before = line_indices(&recs).len() as u32;
    assert!(before < LINES, "the scan was still running");

    // The restart resumes without a start command and completes.
    let mut d = spawn_daemon(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    let s = wait_status(&r, "complete after restart", |s| {
        s.last_stop
            .as_ref()
            .is_some_and(|l| l.status == StopStatus::Success)
    })
    .await;
    assert_eq!(s.state, State::Idle);
    let recs = records(&dir);
    assert_eq!(line_indices(&recs), (0..LINES).collect::<Vec<_>>());
    assert!(recs.iter().any(
        |r| matches!(r, Record::Interruption(i) if i.reason.contains("resumed after a restart"))
    ));
    assert!(dir.join("surface.igs").exists() && dir.join("report.json").exists());
    // The notification hook ran for the completion with the scan's id, status and directory.
    let id = dir.file_name().unwrap().to_string_lossy().into_owned();
    let start = Instant::now();
    let hook = loop {
        let text = std::fs::read_to_string(r.dir.path().join("hook.log")).unwrap_or_default();
        if text.contains("SURFSCAN_STATUS=success") || start.elapsed() > DEADLINE {
            break text;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert!(hook.contains("SURFSCAN_STATUS=success"), "{hook}");
    assert!(hook.contains(&format!("SURFSCAN_SCAN_ID={id}")), "{hook}");
    assert!(
        hook.contains(&format!("SURFSCAN_SCAN_DIR={}", dir.display())),
        "{hook}"
    );
    // The metrics file counts every line of the plan as done.
    let prom = std::fs::read_to_string(r.dir.path().join("surfscan.prom")).unwrap();
    let done = prom
        .lines()
        .find(|l| l.starts_with("surfscan_lines_done"))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse::<f64>().ok());
    assert_eq!(done, Some(f64::from(LINES)), "{prom}");
    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    r.sim.shutdown().await;
}

/// Starts a scan (specimen `paused`), pauses it, stops the daemon and starts it again: the
/// new daemon, the status once paused, and the status once the restart reopened it paused.
async fn pause_and_restart(r: &Rig) -> (Daemon, Status, Status) {
    let mut d = spawn_daemon(r);
    notify_until(r, &mut d, |m| m.contains("READY=1"));
    start_scan(r, "paused").await;
    wait_status(r, "scanning", |s| s.state == State::Scanning).await;
    client(r).await.request(&Request::Pause).await.unwrap();
    let paused = wait_status(r, "paused", |s| s.state == State::Paused).await;
    sigterm(&d);
    assert!(wait_exit(&mut d).success());

    let mut d = spawn_daemon(r);
    notify_until(r, &mut d, |m| m.contains("READY=1"));
    let restarted = wait_status(r, "paused after the restart", |s| s.state == State::Paused).await;
    (d, paused, restarted)
}

/// A scan the operator paused (to take the specimen off, say) and a restart of the daemon:
/// the restart reopens it paused, nothing is traced or moved, until the operator resumes it;
/// then it completes with every line once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_paused_scan_stays_paused_across_a_restart_until_resumed() {
    let r = rig().await;
    let (mut d, paused, s) = pause_and_restart(&r).await;
    let dir = scan_dir(&r);
    let done = line_indices(&records(&dir));
    assert_eq!(done.len() as u32, paused.lines_done);
    assert!(
        s.reason
            .as_deref()
            .is_some_and(|r| r.contains("surfscan resume")),
        "{s:?}"
    );
    tokio::time::sleep(Duration::from_millis(800)).await;
    assert_eq!(status(&r).await.state, State::Paused);
    assert_eq!(
        line_indices(&records(&dir)),
        done,
        "nothing traced while paused"
    );
    assert!(records(&dir).iter().any(|r| matches!(r,
        Record::Interruption(i) if i.reason.contains("stays paused until `surfscan resume`"))));

    client(&r).await.request(&Request::Resume).await.unwrap();
    wait_status(&r, "complete after resume", |s| {
        s.last_stop
            .as_ref()
            .is_some_and(|l| l.status == StopStatus::Success)
    })
    .await;
    assert_eq!(line_indices(&records(&dir)), (0..LINES).collect::<Vec<_>>());
    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    r.sim.shutdown().await;
}

#[test]
fn a_bad_config_exits_78_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.toml");
    let text = edited(
        &surfscan::cli::demo::demo_config(
            Path::new("/dev/null"),
            Path::new("/dev/null"),
            dir.path(),
        ),
        "y-step-mm = 0.01",
        "y-step-mm = 0.01\ny-stepp-mm = 1",
    );
    std::fs::write(&p, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["daemon", "--config"])
        .arg(&p)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(78));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("y-stepp-mm"), "{err}");

    // A port that can never be a serial device: 78 naming it, as check-config says.
    let text = surfscan::cli::demo::demo_config(dir.path(), Path::new("/dev/null"), dir.path());
    std::fs::write(&p, text).unwrap();
    let mut d = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["daemon", "--config"])
        .arg(&p)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while d.try_wait().unwrap().is_none() && start.elapsed() < DEADLINE {
        std::thread::sleep(Duration::from_millis(20));
    }
    if d.try_wait().unwrap().is_none() {
        let _ = d.kill();
        let _ = d.wait();
        panic!("the daemon started on a port that is a directory");
    }
    let out = d.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(78));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("is a directory, not a serial device"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_damaged_journal_is_named_in_the_status_and_does_not_hold_up_the_daemon() {
    let r = rig().await;
    // An old scan whose journal has a record that is not valid before its last one.
    let old = r.out().join("20250101T000000Z-old");
    std::fs::create_dir_all(old.join("lines")).unwrap();
    let journal = old.join("journal.jsonl");
    std::fs::write(
        &journal,
        "{\"class\":\"start\",\"scan_id\":\"x\"}\n{\"class\":\"li#e\"}\n{\"class\":\"stop\"}\n",
    )
    .unwrap();
    let mut d = spawn_daemon(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    let s = status(&r).await;
    assert_eq!(s.state, State::Idle);
    assert_eq!(s.damaged_journals.len(), 1, "{s:?}");
    assert!(
        s.damaged_journals[0].contains(&journal.display().to_string())
            && s.damaged_journals[0].contains("line 1"),
        "{}",
        s.damaged_journals[0]
    );
    // The daemon still takes a start: the damaged scan holds nothing up.
    let ack = client(&r)
        .await
        .request(&Request::Start {
            specimen: "after-damage".into(),
            operator: "ana".into(),
            notes: String::new(),
            mode: StartMode::Auto,
            recipe: None,
            y_start_mm: None,
        })
        .await
        .unwrap();
    assert!(matches!(ack.message, Message::Ack { .. }), "{ack:?}");
    let s = wait_status(&r, "a new scan", |s| s.scan_id.is_some()).await;
    assert!(!s.scan_id.unwrap().contains("old"));
    drop(d);
}

/// A hang-up (SIGHUP: a reload request, or the session of a daemon started by hand went
/// away) with nobody reading the daemon's output: the scan under way goes on to the end and
/// the daemon keeps serving, instead of ending on the signal or aborting on a log line it
/// cannot write.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hang_up_leaves_the_daemon_scanning_with_nobody_reading_its_log() {
    let r = rig().await;
    let writer = crate::common::unread_pipe();
    let mut d = Daemon(
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["daemon", "--config"])
            .arg(&r.config)
            .env("NOTIFY_SOCKET", r.dir.path().join("notify.sock"))
            .env_remove("WATCHDOG_USEC")
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::from(writer.try_clone().unwrap()))
            .stderr(Stdio::from(writer))
            .spawn()
            .unwrap(),
    );
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    start_scan(&r, "hang-up").await;
    let s = wait_status(&r, "a line on disk", |s| s.lines_done >= 1).await;
    assert!(s.lines_done < LINES, "the scan ended before the hang-up");
    let pid = nix::unistd::Pid::from_raw(d.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGHUP).unwrap();
    let s = wait_status(&r, "the scan's end", |s| s.last_stop.is_some()).await;
    assert_eq!(
        s.last_stop.as_ref().unwrap().status,
        StopStatus::Success,
        "{s:?}"
    );
    assert_eq!(line_indices(&records(&scan_dir(&r))).len() as u32, LINES);
    assert!(d.try_wait().unwrap().is_none(), "the daemon exited");
    sigterm(&d);
    assert!(wait_exit(&mut d).success());
}

/// After a restart a paused scan stays paused; the README tells the operator that `surfscan
/// start` goes on with it, as `surfscan resume` does. It was refused as "running; abort it
/// first", and following that advice would have ended the scan.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_start_resumes_a_scan_paused_before_a_restart() {
    let r = rig().await;
    let (mut d, _, s) = pause_and_restart(&r).await;
    // Not opened while paused, but there: not shown as absent.
    assert_eq!(
        (s.instrument, s.stage),
        (DeviceState::Present, DeviceState::Present),
        "{s:?}"
    );
    let start = |mode| Request::Start {
        specimen: "paused".into(),
        operator: String::new(),
        notes: String::new(),
        mode,
        recipe: None,
        y_start_mm: None,
    };
    // A new scan is refused, saying how to go on with this one.
    let refused = client(&r)
        .await
        .request(&start(StartMode::New))
        .await
        .unwrap();
    match refused.message {
        Message::Error { message } => assert!(message.contains("surfscan resume"), "{message}"),
        other => panic!("{other:?}"),
    }
    assert_eq!(status(&r).await.state, State::Paused);
    // The operator's own command: it answers that the start resumes the scan and sees it
    // under way (it waited its 2 minutes and said "still starting" when a start while
    // paused was not counted).
    let out = tokio::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["start", "--specimen", "paused", "--socket"])
        .arg(&r.socket)
        .output();
    let out = tokio::time::timeout(Duration::from_secs(60), out)
        .await
        .expect("start ends")
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("this start resumes it") && !stdout.contains("still starting"),
        "{stdout}"
    );
    wait_status(&r, "complete after the start", |s| {
        s.last_stop
            .as_ref()
            .is_some_and(|l| l.status == StopStatus::Success)
    })
    .await;
    let dir = scan_dir(&r);
    assert_eq!(line_indices(&records(&dir)), (0..LINES).collect::<Vec<_>>());
    assert!(records(&dir).iter().any(|r| matches!(r,
        Record::Interruption(i) if i.reason.starts_with("resumed by the operator's start"))));
    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    r.sim.shutdown().await;
}

/// `surfscan start` against a station whose instrument is not plugged in: the daemon
/// accepts the start, the scan cannot begin, and the command says so with the reason, exit
/// 1 (it said "starting a scan" and exit 0 before, and the operator walked away).
#[test]
fn a_start_the_devices_cannot_serve_is_reported_by_the_start_command() {
    let dir = tempfile::tempdir().unwrap();
    let (inst, stage) = (dir.path().join("no-sj210"), dir.path().join("no-ystage"));
    let socket = dir.path().join("control.sock");
    let text = demo_config_at(&inst, &stage, &dir.path().join("scans"), &socket);
    let config = dir.path().join("station.toml");
    std::fs::write(&config, text).unwrap();
    let locks = dir.path().join("locks");
    std::fs::create_dir_all(&locks).unwrap();
    let _d = Daemon(
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["daemon", "--config"])
            .arg(&config)
            .env("SURFSCAN_TEST_LOCK_DIR", &locks)
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let start = Instant::now();
    while !socket.exists() {
        assert!(start.elapsed() < DEADLINE, "no control socket");
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["start", "--specimen", "B14", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("the scan did not start: instrument") && stderr.contains("no-sj210"),
        "{stderr}"
    );
}

/// The systemd watchdog is fed only while the session makes progress or knowingly waits:
/// a trace that never ends (a stuck future no driver deadline bounds, injected with
/// `SURFSCAN_TEST_STALL`) keeps it fed only up to the longest a device effect may take, then
/// the pings stop, so that systemd kills the daemon; started again, it resumes the scan at
/// its first missing line and completes it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stuck_trace_starves_the_watchdog_and_the_restarted_daemon_resumes_the_scan() {
    let r = rig().await;
    let log = r.dir.path().join("daemon.log");
    // WATCHDOG_USEC of 1 s: a ping every 0.5 s while fed. The third trace never ends; the
    // longest a device effect may take is then 3 s.
    let mut d = Daemon(
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["daemon", "--config"])
            .arg(&r.config)
            .env("NOTIFY_SOCKET", r.dir.path().join("notify.sock"))
            .env("WATCHDOG_USEC", "1000000")
            .env_remove("WATCHDOG_PID")
            .env("SURFSCAN_TEST_STALL", "3:3")
            .env("NO_COLOR", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap(),
    );
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    start_scan(&r, "stuck").await;
    // Watch the datagrams until 6 s without a ping have passed, or the deadline.
    let start = Instant::now();
    let mut last_ping = Instant::now();
    let mut pings = 0u32;
    let mut buf = [0u8; 4096];
    while last_ping.elapsed() < Duration::from_secs(6) {
        assert!(
            start.elapsed() < DEADLINE,
            "the watchdog was fed all along ({pings} pings): {}",
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        if let Ok(n) = r.notify.recv(&mut buf) {
            if String::from_utf8_lossy(&buf[..n]).contains("WATCHDOG=1") {
                pings += 1;
                last_ping = Instant::now();
            }
        }
    }
    // Fed while it worked (two lines at least), then starved with the daemon still up and
    // the scan on its third line, with the reason in the log.
    assert!(pings >= 4, "{pings} pings");
    assert_eq!(d.try_wait().unwrap(), None, "the daemon is still running");
    let s = status(&r).await;
    assert_eq!(s.state, State::Scanning, "{s:?}");
    // The third trace: line 3, unless a line before it was traced twice.
    assert!((1..=2).contains(&s.lines_done), "{s:?}");
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(
        text.contains("no longer feeding the watchdog, so systemd restarts the daemon"),
        "{text}"
    );
    // What systemd does then (SIGABRT, then SIGKILL), and its restart.
    d.kill().unwrap();
    d.wait().unwrap();
    let mut d = spawn_daemon(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    let s = wait_status(&r, "the resumed scan completes", |s| {
        s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    assert_eq!(s.last_stop.unwrap().status, StopStatus::Success);
    let dir = scan_dir(&r);
    assert_eq!(line_indices(&records(&dir)), (0..LINES).collect::<Vec<_>>());
    sigterm(&d);
    d.wait().unwrap();
}

/// An unfinished scan the file system refuses to reopen when the daemon starts (here a
/// committed line's file replaced by a directory: EISDIR, which fails for root too) is left
/// as it is, the idle daemon saying so and nothing recorded; once the file system allows it,
/// the daemon reopens it by itself with the reconnection backoff and completes it, with no
/// start command nor restart. Before, it was tried again only at the daemon's next start or
/// an operator's start.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_the_file_system_refused_to_reopen_is_reopened_once_it_allows_it() {
    let r = rig().await;
    let mut d = spawn_daemon(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    start_scan(&r, "refused").await;
    wait_status(&r, "two lines", |s| s.lines_done >= 2).await;
    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    let dir = scan_dir(&r);
    let line = dir.join("lines").join("0000.csv");
    let kept = dir.join("0000.csv.kept");
    std::fs::rename(&line, &kept).unwrap();
    std::fs::create_dir(&line).unwrap();

    let mut d = spawn_daemon(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    let s = wait_status(&r, "waiting for the file system", |s| {
        s.reason
            .as_deref()
            .is_some_and(|w| w.contains("waits for the file system"))
    })
    .await;
    assert_eq!(s.state, State::Idle, "{s:?}");
    assert!(
        s.last_stop.is_none() && !records(&dir).iter().any(|r| matches!(r, Record::Stop(_))),
        "{s:?}"
    );

    std::fs::remove_dir(&line).unwrap();
    std::fs::rename(&kept, &line).unwrap();
    wait_status(&r, "complete once the file system allows it", |s| {
        s.last_stop
            .as_ref()
            .is_some_and(|l| l.status == StopStatus::Success)
    })
    .await;
    assert_eq!(line_indices(&records(&dir)), (0..LINES).collect::<Vec<_>>());
    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    r.sim.shutdown().await;
}
