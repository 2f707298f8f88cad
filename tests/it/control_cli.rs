//! The `surfscan status|pause|resume|abort|start` binary against a real control socket served
//! in this process, and against sockets where no daemon (or a wrong one) answers.

use crate::common::control_channels;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use surfscan::control::protocol::ControlChannels;
use surfscan::control::server::{self, ServerOptions};
use surfscan::scan::command::{OperatorCommand, OperatorRequest, StartMode};
use surfscan::scan::status::{DeviceState, State, Status};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::sync::{mpsc, oneshot, watch};

fn scanning() -> Status {
    let mut s = Status::idle();
    s.state = State::Scanning;
    s.scan_id = Some("G-0142".into());
    s.scan_dir = Some("/var/lib/surfscan/scans/G-0142".into());
    s.lines_done = 11;
    s.lines_total = 31;
    s.current_line = Some(12);
    s.y_mm = Some(0.11);
    s.last_ra_um = Some(0.452);
    s.eta_s = Some(750.0);
    s.instrument = DeviceState::Connected;
    s.stage = DeviceState::Present;
    s
}

struct Daemon {
    _dir: tempfile::TempDir,
    path: PathBuf,
    _status: watch::Sender<Status>,
    seen: Arc<Mutex<Vec<OperatorCommand>>>,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<()>,
}

impl Daemon {
    /// A served socket with a runner that acks pause and start and refuses resume.
    async fn start() -> Daemon {
        let (status_tx, status_rx) = watch::channel(scanning());
        let (cmd_tx, mut cmd_rx) = mpsc::channel::<OperatorRequest>(4);
        let seen = Arc::new(Mutex::new(Vec::new()));
        let log = Arc::clone(&seen);
        let publish = status_tx.clone();
        tokio::spawn(async move {
            while let Some(req) = cmd_rx.recv().await {
                log.lock().unwrap().push(req.command.clone());
                let answer = match &req.command {
                    OperatorCommand::Pause => Ok("pausing after line 12 is on disk".to_owned()),
                    OperatorCommand::Resume => Err("the scan is not paused".to_owned()),
                    OperatorCommand::Abort => Ok("aborting".to_owned()),
                    OperatorCommand::Start { specimen, .. } => Ok(format!("starting {specimen}")),
                };
                let started = matches!(req.command, OperatorCommand::Start { .. });
                let _ = req.reply.send(answer);
                if started {
                    // As the daemon does: the start is counted, the scan begins (here, at
                    // once, on a new line).
                    publish.send_modify(|s| {
                        s.starts += 1;
                        s.current_line = Some(1);
                        s.lines_done = 0;
                        s.y_mm = Some(0.0);
                    });
                }
            }
        });
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("control.sock");
        let (stop, task) = serve_with(&path, control_channels(status_rx, cmd_tx)).await;
        Daemon {
            _dir: dir,
            path,
            _status: status_tx,
            seen,
            stop: Some(stop),
            task,
        }
    }

    async fn shutdown(mut self) {
        let _ = self.stop.take().unwrap().send(());
        (&mut self.task).await.unwrap();
    }
}

fn surfscan() -> tokio::process::Command {
    let mut c = tokio::process::Command::new(env!("CARGO_BIN_EXE_surfscan"));
    c.env_remove("RUST_LOG").kill_on_drop(true);
    c
}

async fn run(args: &[&str], socket: &Path) -> Output {
    let out = surfscan().args(args).arg("--socket").arg(socket).output();
    tokio::time::timeout(Duration::from_secs(30), out)
        .await
        .expect("the command finishes")
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[tokio::test]
async fn status_prints_the_summary_and_the_fields_people_want() {
    let d = Daemon::start().await;
    let out = run(&["status"], &d.path).await;
    let stdout = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}{}", text(&out.stderr));
    for want in [
        "scan G-0142: line 12/31, y=0.110 mm\n",
        "lines      11/31 done, on line 12\n",
        "y          0.110 mm\n",
        "last Ra    0.452 µm\n",
        "ETA        12 min 30 s\n",
        "devices    instrument connected, stage present\n",
    ] {
        assert!(stdout.contains(want), "missing {want:?} in:\n{stdout}");
    }
    d.shutdown().await;
}

#[tokio::test]
async fn status_json_prints_the_raw_status_message() {
    let d = Daemon::start().await;
    let out = run(&["status", "--json"], &d.path).await;
    assert_eq!(out.status.code(), Some(0));
    let stdout = text(&out.stdout);
    assert_eq!(stdout.lines().count(), 1, "{stdout}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(v["class"], "status");
    assert_eq!(v["state"], "scanning");
    assert_eq!(v["lines_done"], 11);
    assert_eq!(v["stage"], "present");
    d.shutdown().await;
}

#[tokio::test]
async fn commands_are_acked_or_refused_with_the_daemons_message() {
    let d = Daemon::start().await;
    let out = run(&["pause"], &d.path).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(
        text(&out.stdout),
        "pause: pausing after line 12 is on disk\n"
    );

    let out = run(&["resume"], &d.path).await;
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("the scan is not paused"), "{stderr}");

    let out = run(
        &[
            "start",
            "--specimen",
            "B12",
            "--operator",
            "ana",
            "--notes",
            "lapped steel",
        ],
        &d.path,
    )
    .await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    // The ack, then the scan seen under way.
    assert_eq!(
        text(&out.stdout),
        "start: starting B12\nscan G-0142: line 1/31, y=0.000 mm\n"
    );
    assert_eq!(
        *d.seen.lock().unwrap(),
        vec![
            OperatorCommand::Pause,
            OperatorCommand::Resume,
            OperatorCommand::Start {
                specimen: "B12".into(),
                operator: "ana".into(),
                notes: "lapped steel".into(),
                mode: StartMode::Auto,
                recipe: None,
            }
        ]
    );
    d.shutdown().await;
}

#[tokio::test]
async fn config_names_the_socket_through_its_control_table() {
    let d = Daemon::start().await;
    let cfg = d.path.with_file_name("surfscan.toml");
    std::fs::write(
        &cfg,
        format!(
            "[instrument]\nport = \"/dev/sj210\"\n\n[control]\nsocket = {:?}\n",
            d.path.display().to_string()
        ),
    )
    .unwrap();
    let out = surfscan()
        .arg("abort")
        .arg("--config")
        .arg(&cfg)
        .output()
        .await
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "abort: aborting\n");
    d.shutdown().await;
}

#[tokio::test]
async fn nothing_listening_is_exit_69_with_a_hint() {
    let dir = tempfile::tempdir().unwrap();
    // No file at all.
    let missing = dir.path().join("missing.sock");
    let out = run(&["status"], &missing).await;
    assert_eq!(out.status.code(), Some(69));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("is the daemon running? systemctl status surfscan"),
        "{stderr}"
    );
    assert!(stderr.contains(&missing.display().to_string()), "{stderr}");
    // A stale socket file: connection refused.
    let stale = dir.path().join("stale.sock");
    drop(std::os::unix::net::UnixListener::bind(&stale).unwrap());
    let out = run(&["pause"], &stale).await;
    assert_eq!(out.status.code(), Some(69), "{}", text(&out.stderr));
}

/// A listener that greets with `greeting` (if any) and then closes each connection.
async fn fake_daemon(path: &Path, greeting: Option<&'static str>) -> tokio::task::JoinHandle<()> {
    let listener = tokio::net::UnixListener::bind(path).unwrap();
    tokio::spawn(async move {
        while let Ok((mut s, _)) = listener.accept().await {
            if let Some(g) = greeting {
                let _ = s.write_all(g.as_bytes()).await;
            }
            let _ = s.shutdown().await;
        }
    })
}

#[tokio::test]
async fn an_incompatible_greeting_is_refused_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("future.sock");
    let task = fake_daemon(
        &path,
        Some("{\"class\":\"hello\",\"protocol\":99,\"software\":\"surfscan 9.0.0\",\"pid\":1}\n"),
    )
    .await;
    let out = run(&["status"], &path).await;
    assert_eq!(out.status.code(), Some(69));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("protocol 99"), "{stderr}");
    assert!(stderr.contains("surfscan 9.0.0"), "{stderr}");
    task.abort();
}

#[tokio::test]
async fn a_conversation_cut_short_is_exit_74() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.sock");
    // Greets, then hangs up before answering.
    let task = fake_daemon(
        &path,
        Some("{\"class\":\"hello\",\"protocol\":1,\"software\":\"surfscan 0.1.0\",\"pid\":1}\n"),
    )
    .await;
    let out = run(&["status"], &path).await;
    assert_eq!(out.status.code(), Some(74), "{}", text(&out.stderr));
    // Depending on timing the hang-up shows as end of stream or as a broken pipe on sending.
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("control conversation with")
            && stderr.contains(&path.display().to_string()),
        "{stderr}"
    );
    task.abort();
}

/// A served socket at `path` answering with `status`; stopping it ends the server.
async fn serve_at(
    path: &Path,
    status: Status,
) -> (
    watch::Sender<Status>,
    oneshot::Sender<()>,
    tokio::task::JoinHandle<()>,
) {
    let (status_tx, status_rx) = watch::channel(status);
    let (cmd_tx, _cmd_rx) = mpsc::channel::<OperatorRequest>(4);
    let (stop, task) = serve_with(path, control_channels(status_rx, cmd_tx)).await;
    (status_tx, stop, task)
}

/// Serves `channels` at `path`; sending on the stop channel ends the server.
async fn serve_with(
    path: &Path,
    channels: ControlChannels,
) -> (oneshot::Sender<()>, tokio::task::JoinHandle<()>) {
    let server = server::bind_with_options(path, ServerOptions::default())
        .await
        .unwrap();
    let (stop, stopped) = oneshot::channel::<()>();
    let task = tokio::spawn(server.serve(channels, async {
        let _ = stopped.await;
    }));
    (stop, task)
}

#[tokio::test]
async fn watch_prints_every_change_and_reconnects_when_the_daemon_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    let (status, stop, task) = serve_at(&path, scanning()).await;
    let mut child = surfscan()
        .args(["status", "--watch", "--json", "--socket"])
        .arg(&path)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let mut errs = BufReader::new(child.stderr.take().unwrap()).lines();
    let mut next = async || -> serde_json::Value {
        let l = tokio::time::timeout(Duration::from_secs(20), lines.next_line())
            .await
            .expect("a line within 20 s")
            .unwrap()
            .expect("still running");
        serde_json::from_str(&l).unwrap()
    };
    assert_eq!(next().await["lines_done"], 11);
    status.send_modify(|s| {
        s.lines_done = 12;
        s.current_line = Some(13);
    });
    let v = next().await;
    assert_eq!(v["lines_done"], 12);
    assert_eq!(v["current_line"], 13);

    // The daemon stops (its socket file goes with it) and comes back on the same path.
    let _ = stop.send(());
    task.await.unwrap();
    let note = tokio::time::timeout(Duration::from_secs(10), errs.next_line())
        .await
        .expect("a note within 10 s")
        .unwrap()
        .expect("stderr open");
    assert!(note.contains("reconnecting"), "{note}");
    let _ = std::fs::remove_file(&path);
    let mut back = scanning();
    back.lines_done = 20;
    let (_status, stop, task) = serve_at(&path, back).await;
    let v = next().await;
    assert_eq!(v["lines_done"], 20, "{v}");
    let note = tokio::time::timeout(Duration::from_secs(10), errs.next_line())
        .await
        .expect("a note within 10 s")
        .unwrap()
        .expect("stderr open");
    assert!(note.contains("reconnected"), "{note}");
    // Still watching: no exit of its own.
    assert!(child.try_wait().unwrap().is_none());
    child.kill().await.unwrap();
    let _ = stop.send(());
    task.await.unwrap();
}

/// `status --watch | head -1`: once nobody reads what it prints, watching ends (exit 0);
/// `status` alone likewise exits 0. Neither aborts on the write to a closed pipe.
#[tokio::test]
async fn status_and_watch_end_quietly_when_nobody_reads_them() {
    let d = Daemon::start().await;
    for args in [
        &["status"][..],
        &["status", "--watch"],
        &["status", "--json"],
    ] {
        // Spawned, not `output()`, which would capture stdout through a pipe of its own.
        let child = surfscan()
            .args(args)
            .arg("--socket")
            .arg(&d.path)
            .stdout(std::process::Stdio::from(crate::common::unread_pipe()))
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let out = tokio::time::timeout(Duration::from_secs(30), child.wait_with_output())
            .await
            .unwrap_or_else(|_| panic!("{args:?} did not end once its output was unread"))
            .unwrap();
        assert_eq!(
            out.status.code(),
            Some(0),
            "{args:?}: {}",
            text(&out.stderr)
        );
        assert!(
            !text(&out.stderr).contains("panicked"),
            "{}",
            text(&out.stderr)
        );
    }
    d.shutdown().await;
}

/// The daemon publishes on every step of a scan, and many steps change nothing a person sees
/// on the watch's line: such a snapshot is not printed again (it was, once per step).
#[tokio::test]
async fn watch_prints_a_line_only_when_it_reads_differently() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    let (status, stop, task) = serve_at(&path, scanning()).await;
    let mut child = surfscan()
        .args(["status", "--watch", "--socket"])
        .arg(&path)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let mut next = async || {
        tokio::time::timeout(Duration::from_secs(20), lines.next_line())
            .await
            .expect("a line within 20 s")
            .unwrap()
            .expect("still running")
    };
    // The first status is the block; wait for its last line.
    loop {
        if next().await.starts_with("  devices") {
            break;
        }
    }
    // Three snapshots that read the same (one sent unchanged, one whose change the line does
    // not show), then one that reads differently: only that one is printed.
    // (Apart in time, so the daemon's side sends each rather than only the latest.)
    for change in [
        (|_: &mut Status| {}) as fn(&mut Status),
        |s| s.scan_dir = Some("/elsewhere/G-0142".into()),
        |_| {},
    ] {
        status.send_modify(change);
        tokio::time::sleep(Duration::from_millis(150)).await;
    }
    status.send_modify(|s| {
        s.lines_done = 12;
        s.current_line = Some(13);
    });
    let line = next().await;
    assert!(line.contains("line 13/31"), "{line}");
    child.kill().await.unwrap();
    let _ = stop.send(());
    task.await.unwrap();
}

/// `surfscan start` follows its start to the scan under way or to its end: a scan that
/// cannot begin (its devices missing) is exit 1 with the daemon's reason, not a silent exit 0
/// an operator walks away from.
#[tokio::test]
async fn a_start_that_fails_at_once_is_reported_as_failed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    let (status_tx, status_rx) = watch::channel(Status::idle());
    let (cmd_tx, mut cmd_rx) = mpsc::channel::<OperatorRequest>(4);
    let publish = status_tx.clone();
    tokio::spawn(async move {
        while let Some(req) = cmd_rx.recv().await {
            let _ = req.reply.send(Ok("starting a scan of 31 lines".to_owned()));
            // Starting, then ended: the instrument is not plugged in.
            publish.send_modify(|s| {
                s.starts += 1;
                s.state = State::Starting;
            });
            tokio::time::sleep(Duration::from_millis(100)).await;
            publish.send_modify(|s| {
                s.state = State::Idle;
                s.last_stop = Some(surfscan::scan::status::LastStop {
                    scan_id: String::new(),
                    status: surfscan::scan::ending::StopStatus::Fail,
                    reason: "instrument unavailable: /dev/sj210 is absent".into(),
                    dir: String::new(),
                    internal: false,
                    verdict: None,
                    results: None,
                });
            });
        }
    });
    let (stop, task) = serve_with(&path, control_channels(status_rx, cmd_tx)).await;
    let out = run(&["start", "--specimen", "B13"], &path).await;
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("the scan did not start: instrument unavailable: /dev/sj210 is absent"),
        "{stderr}"
    );
    assert_eq!(text(&out.stdout), "start: starting a scan of 31 lines\n");
    drop(status_tx);
    let _ = stop.send(());
    task.await.unwrap();
}
