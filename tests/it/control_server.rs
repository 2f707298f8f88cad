//! The control-socket server over a real Unix socket, against a fake scan runner that answers
//! commands and publishes status the way the real runner does.

use crate::common::control_channels;
use serde_json::{json, Value};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use surfscan::control::client::{ClientError, ControlClient};
use surfscan::control::protocol::{ControlChannels, PROTOCOL_VERSION};
use surfscan::control::server::{self, ControlError, ServerOptions};
use surfscan::scan::command::{OperatorCommand, OperatorRequest, Peer, StartMode};
use surfscan::scan::status::{DeviceState, State, Status};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader, Lines};
use tokio::net::unix::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::UnixStream;
use tokio::sync::{mpsc, oneshot, watch};

/// The fake runner's published state, the commands it has seen and who sent them.
struct Runner {
    status: watch::Sender<Status>,
    seen: Arc<Mutex<Vec<OperatorCommand>>>,
    peers: Arc<Mutex<Vec<Peer>>>,
}

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
    s.stage = DeviceState::Connected;
    s
}

/// A runner that pauses only a scanning scan, resumes only a paused one, and accepts
/// abort and start.
fn fake_runner(initial: Status) -> (ControlChannels, Runner) {
    let (status_tx, status_rx) = watch::channel(initial);
    let (cmd_tx, mut cmd_rx) = mpsc::channel::<OperatorRequest>(4);
    let seen = Arc::new(Mutex::new(Vec::new()));
    let peers = Arc::new(Mutex::new(Vec::new()));
    let peer_log = Arc::clone(&peers);
    let publisher = status_tx.clone();
    let log = Arc::clone(&seen);
    tokio::spawn(async move {
        while let Some(req) = cmd_rx.recv().await {
            log.lock().unwrap().push(req.command.clone());
            peer_log.lock().unwrap().push(req.peer);
            let state = publisher.borrow().state;
            let answer = match (&req.command, state) {
                (OperatorCommand::Pause, State::Scanning) => {
                    publisher.send_modify(|s| s.state = State::Pausing);
                    Ok("pausing after line 12 is on disk".to_owned())
                }
                (OperatorCommand::Pause, _) => Err("no scan is scanning; nothing to pause".into()),
                (OperatorCommand::Resume, State::Paused) => Ok("resuming".into()),
                (OperatorCommand::Resume, _) => {
                    Err("the scan is not paused; resume releases an operator pause".into())
                }
                (OperatorCommand::Abort, _) => Ok("aborting".into()),
                (OperatorCommand::Start { specimen, .. }, _) => {
                    Ok(format!("starting a scan of {specimen}"))
                }
            };
            let _ = req.reply.send(answer);
        }
    });
    (
        control_channels(status_rx, cmd_tx),
        Runner {
            status: status_tx,
            seen,
            peers,
        },
    )
}

/// A served socket in a fresh directory; dropping the sender shuts the server down.
struct Served {
    _dir: tempfile::TempDir,
    path: PathBuf,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<()>,
}

impl Served {
    async fn shutdown(mut self) {
        let _ = self.stop.take().unwrap().send(());
        tokio::time::timeout(Duration::from_secs(5), &mut self.task)
            .await
            .expect("serve returns after shutdown")
            .unwrap();
    }
}

async fn serve(channels: ControlChannels, options: ServerOptions) -> Served {
    let dir = tempfile::tempdir().unwrap();
    // A parent that does not exist yet: bind creates it.
    let path = dir.path().join("run").join("control.sock");
    let server = server::bind_with_options(&path, options).await.unwrap();
    let (stop, stopped) = oneshot::channel::<()>();
    let task = tokio::spawn(server.serve(channels, async {
        let _ = stopped.await;
    }));
    Served {
        _dir: dir,
        path,
        stop: Some(stop),
        task,
    }
}

struct Conn {
    lines: Lines<BufReader<OwnedReadHalf>>,
    writer: OwnedWriteHalf,
}

impl Conn {
    async fn open(path: &Path) -> Conn {
        let (r, w) = UnixStream::connect(path).await.unwrap().into_split();
        Conn {
            lines: BufReader::new(r).lines(),
            writer: w,
        }
    }

    async fn recv(&mut self) -> Value {
        let line = tokio::time::timeout(Duration::from_secs(5), self.lines.next_line())
            .await
            .expect("a message within 5 s")
            .unwrap()
            .expect("connection still open");
        serde_json::from_str(&line).unwrap()
    }

    async fn send_raw(&mut self, bytes: &[u8]) {
        self.writer.write_all(bytes).await.unwrap();
    }

    async fn ask(&mut self, request: Value) -> Value {
        let mut line = serde_json::to_vec(&request).unwrap();
        line.push(b'\n');
        self.send_raw(&line).await;
        self.recv().await
    }

    /// Opens a connection and consumes the greeting.
    async fn greeted(path: &Path) -> Conn {
        let mut c = Conn::open(path).await;
        assert_eq!(c.recv().await["class"], "hello");
        c
    }
}

fn status_of(m: &Value) -> Status {
    assert_eq!(m["class"], "status", "{m}");
    let mut v = m.clone();
    v.as_object_mut().unwrap().remove("class");
    serde_json::from_value(v).unwrap()
}

#[tokio::test]
async fn greeting_comes_first_with_the_protocol_version() {
    let (channels, _runner) = fake_runner(Status::idle());
    let served = serve(channels, ServerOptions::default()).await;
    let mut c = Conn::open(&served.path).await;
    // Nothing sent yet: the greeting arrives unprompted.
    let hello = c.recv().await;
    assert_eq!(hello["class"], "hello");
    assert_eq!(hello["protocol"], json!(1));
    assert_eq!(PROTOCOL_VERSION, 1);
    assert_eq!(hello["pid"], json!(std::process::id()));
    assert_eq!(
        hello["software"],
        json!(format!("surfscan {}", env!("CARGO_PKG_VERSION")))
    );
    served.shutdown().await;
}

#[tokio::test]
async fn status_returns_the_runners_snapshot() {
    let (channels, runner) = fake_runner(Status::idle());
    let served = serve(channels, ServerOptions::default()).await;
    let mut c = Conn::greeted(&served.path).await;
    assert_eq!(
        status_of(&c.ask(json!({"class":"status"})).await),
        Status::idle()
    );
    runner.status.send_replace(scanning());
    let m = c.ask(json!({"class":"status"})).await;
    assert_eq!(m["state"], "scanning");
    assert_eq!(status_of(&m), scanning());
    served.shutdown().await;
}

#[tokio::test]
async fn pause_is_forwarded_and_acked_and_a_refusal_comes_back_as_error() {
    let (channels, runner) = fake_runner(scanning());
    let served = serve(channels, ServerOptions::default()).await;
    let mut c = Conn::greeted(&served.path).await;
    let ack = c.ask(json!({"class":"pause"})).await;
    assert_eq!(
        ack,
        json!({"class":"ack","command":"pause","detail":"pausing after line 12 is on disk"})
    );
    assert_eq!(runner.status.borrow().state, State::Pausing);
    // The runner refuses a resume of a scan that is not paused.
    let refused = c.ask(json!({"class":"resume"})).await;
    assert_eq!(
        refused,
        json!({"class":"error","message":"the scan is not paused; resume releases an operator pause"})
    );
    let started = c
        .ask(json!({"class":"start","specimen":"B12","operator":"ana","notes":"lapped"}))
        .await;
    assert_eq!(started["class"], "ack");
    assert_eq!(started["command"], "start");
    assert_eq!(started["detail"], "starting a scan of B12");
    assert_eq!(
        *runner.seen.lock().unwrap(),
        vec![
            OperatorCommand::Pause,
            OperatorCommand::Resume,
            OperatorCommand::Start {
                specimen: "B12".into(),
                operator: "ana".into(),
                notes: "lapped".into(),
                mode: StartMode::Auto,
                recipe: None,
            }
        ]
    );
    served.shutdown().await;
}

#[tokio::test]
async fn malformed_and_unknown_requests_get_errors_and_the_connection_still_answers() {
    let (channels, runner) = fake_runner(scanning());
    let served = serve(channels, ServerOptions::default()).await;
    let mut c = Conn::greeted(&served.path).await;

    c.send_raw(b"{\"class\": \"status\"\n").await;
    let e = c.recv().await;
    assert_eq!(e["class"], "error");
    assert!(
        e["message"].as_str().unwrap().contains("not valid JSON"),
        "{e}"
    );

    let e = c.ask(json!({"class":"raw","cmd":"CTSTA"})).await;
    assert_eq!(e["class"], "error");
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("unknown request class \"raw\""),
        "{e}"
    );

    let e = c.ask(json!({"class":"start","specimn":"B"})).await;
    assert_eq!(e["class"], "error");
    assert!(e["message"].as_str().unwrap().contains("specimn"), "{e}");

    // Longer than the 64 KiB bound: refused, and the rest of the stream is still read.
    let mut long = vec![b'x'; 70 * 1024];
    long.push(b'\n');
    c.send_raw(&long).await;
    let e = c.recv().await;
    assert_eq!(e["class"], "error");
    assert!(e["message"].as_str().unwrap().contains("65536"), "{e}");

    c.send_raw(b"\xff\xfe\n").await;
    assert_eq!(c.recv().await["class"], "error");

    // Still usable, and nothing malformed reached the runner.
    assert_eq!(
        status_of(&c.ask(json!({"class":"status"})).await),
        scanning()
    );
    assert!(runner.seen.lock().unwrap().is_empty());
    served.shutdown().await;
}

#[tokio::test]
async fn watch_sends_the_current_snapshot_then_every_change() {
    let (channels, runner) = fake_runner(Status::idle());
    let served = serve(channels, ServerOptions::default()).await;
    let mut c = Conn::greeted(&served.path).await;
    assert_eq!(
        status_of(&c.ask(json!({"class":"watch"})).await),
        Status::idle()
    );
    for k in 1..=3u32 {
        runner.status.send_modify(|s| s.lines_done = k);
        assert_eq!(status_of(&c.recv().await).lines_done, k);
    }
    // A watcher can still ask questions.
    let e = c.ask(json!({"class":"pause"})).await;
    assert_eq!(e["class"], "error");
    served.shutdown().await;
}

#[tokio::test]
async fn socket_mode_is_0660_and_its_directory_is_created() {
    let (channels, _runner) = fake_runner(Status::idle());
    let served = serve(channels, ServerOptions::default()).await;
    let mode = std::fs::metadata(&served.path)
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o777, 0o660, "mode {:o}", mode & 0o777);
    served.shutdown().await;
}

#[tokio::test]
async fn a_stale_socket_is_replaced_and_a_live_one_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    // A crashed daemon leaves its socket file behind: nothing listens on it.
    drop(std::os::unix::net::UnixListener::bind(&path).unwrap());
    assert!(path.exists());
    let (channels, _runner) = fake_runner(Status::idle());
    let first = server::bind(&path).await.expect("stale socket replaced");
    let (stop, stopped) = oneshot::channel::<()>();
    let task = tokio::spawn(first.serve(channels, async {
        let _ = stopped.await;
    }));
    // The replacement really serves.
    Conn::greeted(&path).await;

    let err = server::bind(&path).await.unwrap_err();
    assert!(
        matches!(err, ControlError::AlreadyRunning { .. }),
        "{err:?}"
    );
    let msg = err.to_string();
    assert!(msg.contains("another surfscan daemon is running"), "{msg}");
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    // The refused attempt left the live socket alone.
    Conn::greeted(&path).await;
    let _ = stop.send(());
    task.await.unwrap();
}

#[tokio::test]
async fn a_file_that_is_not_a_socket_is_left_alone() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    std::fs::write(&path, "keep me").unwrap();
    let err = server::bind(&path).await.unwrap_err();
    assert!(matches!(err, ControlError::NotASocket { .. }), "{err:?}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "keep me");
}

#[tokio::test]
async fn shutdown_closes_connections_and_removes_the_socket_file() {
    let (channels, _runner) = fake_runner(Status::idle());
    let served = serve(channels, ServerOptions::default()).await;
    let path = served.path.clone();
    let mut c = Conn::greeted(&path).await;
    assert_eq!(c.ask(json!({"class":"watch"})).await["class"], "status");
    served.shutdown().await;
    assert!(!path.exists(), "socket file left behind");
    let eof = tokio::time::timeout(Duration::from_secs(5), c.lines.next_line())
        .await
        .expect("connection closed promptly")
        .unwrap();
    assert_eq!(eof, None);
}

#[tokio::test]
async fn a_runner_that_is_gone_or_silent_gives_an_error_not_a_hang() {
    // Gone: the command receiver has been dropped.
    let (status_tx, status_rx) = watch::channel(Status::idle());
    let (cmd_tx, cmd_rx) = mpsc::channel::<OperatorRequest>(1);
    drop(cmd_rx);
    let served = serve(
        control_channels(status_rx, cmd_tx),
        ServerOptions::default(),
    )
    .await;
    let mut c = Conn::greeted(&served.path).await;
    let e = c.ask(json!({"class":"abort"})).await;
    assert_eq!(e["class"], "error");
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("scan runner is not running"),
        "{e}"
    );
    served.shutdown().await;
    drop(status_tx);

    // Silent: it takes the command and never answers.
    let (_status_tx, status_rx) = watch::channel(Status::idle());
    let (cmd_tx, mut cmd_rx) = mpsc::channel::<OperatorRequest>(1);
    let held = tokio::spawn(async move {
        let mut kept = Vec::new();
        while let Some(r) = cmd_rx.recv().await {
            kept.push(r);
        }
        kept.len()
    });
    let options = ServerOptions {
        reply_timeout: Duration::from_millis(300),
        ..ServerOptions::default()
    };
    let served = serve(control_channels(status_rx, cmd_tx), options).await;
    let mut c = Conn::greeted(&served.path).await;
    let t0 = std::time::Instant::now();
    let e = c.ask(json!({"class":"pause"})).await;
    assert_eq!(e["class"], "error");
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("did not answer pause"),
        "{e}"
    );
    assert!(
        t0.elapsed() >= Duration::from_millis(250),
        "{:?}",
        t0.elapsed()
    );
    served.shutdown().await;
    assert_eq!(held.await.unwrap(), 1);
}

#[tokio::test]
async fn connections_beyond_the_limit_are_told_so_and_closed() {
    let (channels, _runner) = fake_runner(Status::idle());
    // One slot, which a watcher may take: then nobody waits for a request whose slot could
    // be given to the newcomer.
    let options = ServerOptions {
        max_connections: 1,
        reserved_for_requests: 0,
        ..ServerOptions::default()
    };
    let served = serve(channels, options).await;
    let mut first = Conn::greeted(&served.path).await;
    assert_eq!(first.ask(json!({"class":"watch"})).await["class"], "status");
    let mut second = Conn::open(&served.path).await;
    let e = second.recv().await;
    assert_eq!(e["class"], "error");
    assert!(
        e["message"].as_str().unwrap().contains("already serves 1"),
        "{e}"
    );
    let eof = tokio::time::timeout(Duration::from_secs(5), second.lines.next_line())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(eof, None);
    // The command line's client says so in the daemon's words, not as a broken protocol.
    match ControlClient::connect(&served.path).await {
        Err(e @ ClientError::Refused { .. }) => {
            assert!(e.to_string().contains("already serves 1"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    // The first is unaffected, and its slot is free again once it leaves.
    assert_eq!(
        first.ask(json!({"class":"status"})).await["class"],
        "status"
    );
    drop(first);
    let deadline = std::time::Instant::now() + Duration::from_secs(5);
    loop {
        let mut c = Conn::open(&served.path).await;
        if c.recv().await["class"] == "hello" {
            break;
        }
        assert!(std::time::Instant::now() < deadline, "slot never freed");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    served.shutdown().await;
}

#[tokio::test]
async fn an_unknown_field_is_refused_naming_it_and_nothing_is_carried_out() {
    let (channels, runner) = fake_runner(scanning());
    let served = serve(channels, ServerOptions::default()).await;
    let mut c = Conn::greeted(&served.path).await;
    for (request, field) in [
        (json!({"class":"pause","force":true}), "force"),
        (json!({"class":"abort","now":1}), "now"),
        (json!({"class":"resume","all":true}), "all"),
        (json!({"class":"status","verbose":true}), "verbose"),
        (json!({"class":"watch","every":5}), "every"),
        (
            json!({"class":"start","specimen":"B","force":true}),
            "force",
        ),
    ] {
        let e = c.ask(request.clone()).await;
        assert_eq!(e["class"], "error", "{request}: {e}");
        let message = e["message"].as_str().unwrap();
        assert!(
            message.contains("unknown field") && message.contains(field),
            "{request}: {message}"
        );
    }
    assert!(runner.seen.lock().unwrap().is_empty());
    // The same connection still carries out a well-formed request.
    assert_eq!(c.ask(json!({"class":"pause"})).await["class"], "ack");
    assert_eq!(*runner.seen.lock().unwrap(), vec![OperatorCommand::Pause]);
    served.shutdown().await;
}

#[tokio::test]
async fn each_command_carries_the_senders_uid_and_pid_to_the_runner() {
    let (channels, runner) = fake_runner(scanning());
    let served = serve(channels, ServerOptions::default()).await;
    let mut c = Conn::greeted(&served.path).await;
    assert_eq!(c.ask(json!({"class":"pause"})).await["class"], "ack");
    assert_eq!(c.ask(json!({"class":"abort"})).await["class"], "ack");
    let me = Peer {
        uid: nix::unistd::geteuid().as_raw(),
        gid: nix::unistd::getegid().as_raw(),
        pid: Some(std::process::id()),
        web: None,
        mqtt: None,
    };
    assert_eq!(*runner.peers.lock().unwrap(), vec![me.clone(), me]);
    served.shutdown().await;
}

#[tokio::test]
async fn a_client_without_a_complete_request_in_time_is_dropped_but_a_watcher_is_not() {
    let (channels, runner) = fake_runner(scanning());
    let options = ServerOptions {
        request_timeout: Duration::from_millis(400),
        ..ServerOptions::default()
    };
    let served = serve(channels, options).await;

    // Silent after the greeting.
    let mut idle = Conn::greeted(&served.path).await;
    let t0 = std::time::Instant::now();
    let e = idle.recv().await;
    assert_eq!(e["class"], "error", "{e}");
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("no complete request within 0.4 s"),
        "{e}"
    );
    assert!(
        t0.elapsed() >= Duration::from_millis(350),
        "{:?}",
        t0.elapsed()
    );
    assert_eq!(idle.lines.next_line().await.unwrap(), None);

    // Dripping bytes without ever ending the line does not keep it alive.
    let mut drip = Conn::greeted(&served.path).await;
    let mut writer = drip.writer;
    let dripper = tokio::spawn(async move {
        for b in b"{\"class\":\"status\"".iter().cycle() {
            if writer.write_all(&[*b]).await.is_err() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    let e = tokio::time::timeout(Duration::from_secs(5), drip.lines.next_line())
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    assert!(e.contains("no complete request"), "{e}");
    assert_eq!(drip.lines.next_line().await.unwrap(), None);
    dripper.abort();

    // Each answer starts the period again: two requests 300 ms apart outlive one period.
    let mut steady = Conn::greeted(&served.path).await;
    for _ in 0..3 {
        tokio::time::sleep(Duration::from_millis(250)).await;
        assert_eq!(
            steady.ask(json!({"class":"status"})).await["class"],
            "status"
        );
    }

    // A watcher sends nothing after `watch` and still gets every change.
    let mut watcher = Conn::greeted(&served.path).await;
    assert_eq!(
        watcher.ask(json!({"class":"watch"})).await["class"],
        "status"
    );
    tokio::time::sleep(Duration::from_millis(1000)).await;
    runner.status.send_modify(|s| s.lines_done = 12);
    let s = watcher.recv().await;
    assert_eq!(status_of(&s).lines_done, 12);
    served.shutdown().await;
}

/// `n` connections that have been greeted and then send nothing.
async fn idle_clients(path: &Path, n: usize) -> Vec<Conn> {
    let mut out = Vec::new();
    for _ in 0..n {
        out.push(Conn::greeted(path).await);
    }
    out
}

#[tokio::test]
async fn thirty_two_idle_or_slow_drip_clients_do_not_lock_out_status_and_pause() {
    let (channels, runner) = fake_runner(scanning());
    // A request period far longer than the test: the operator gets through because the
    // connection that waited longest without a request makes room, not because the squatters
    // time out.
    let options = ServerOptions {
        request_timeout: Duration::from_secs(600),
        ..ServerOptions::default()
    };
    assert_eq!(options.max_connections, 32);
    let served = serve(channels, options).await;

    let mut idle = idle_clients(&served.path, 32).await;
    let mut op = Conn::greeted(&served.path).await;
    assert_eq!(op.ask(json!({"class":"status"})).await["class"], "status");
    let mut op2 = Conn::greeted(&served.path).await;
    assert_eq!(op2.ask(json!({"class":"pause"})).await["class"], "ack");
    // The two that waited longest were told why they were closed; the rest are untouched.
    for c in &mut idle[..2] {
        let e = c.recv().await;
        assert!(
            e["message"]
                .as_str()
                .unwrap()
                .contains("closed to let another client in"),
            "{e}"
        );
        assert_eq!(c.lines.next_line().await.unwrap(), None);
    }
    drop((idle, op, op2));

    // 32 clients sending one byte at a time and never a newline.
    runner.status.send_replace(scanning());
    let mut drips = Vec::new();
    for _ in 0..32 {
        let Conn { lines, mut writer } = Conn::greeted(&served.path).await;
        drips.push(tokio::spawn(async move {
            let _lines = lines;
            while writer.write_all(b" ").await.is_ok() {
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }));
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut op = Conn::greeted(&served.path).await;
    assert_eq!(
        status_of(&op.ask(json!({"class":"status"})).await).state,
        State::Scanning
    );
    assert_eq!(op.ask(json!({"class":"pause"})).await["class"], "ack");
    assert_eq!(
        *runner.seen.lock().unwrap(),
        vec![OperatorCommand::Pause, OperatorCommand::Pause]
    );
    for d in drips {
        d.abort();
    }
    served.shutdown().await;
}

#[tokio::test]
async fn watchers_cannot_take_the_slots_kept_for_requests() {
    let (channels, runner) = fake_runner(scanning());
    let options = ServerOptions {
        max_connections: 6,
        reserved_for_requests: 2,
        request_timeout: Duration::from_secs(600),
        ..ServerOptions::default()
    };
    let served = serve(channels, options).await;
    let mut watchers = idle_clients(&served.path, 4).await;
    for w in &mut watchers {
        assert_eq!(w.ask(json!({"class":"watch"})).await["class"], "status");
    }
    // A fifth watcher is refused (and stays connected as an ordinary client).
    let mut fifth = Conn::greeted(&served.path).await;
    let e = fifth.ask(json!({"class":"watch"})).await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("4 clients already watch"),
        "{e}"
    );
    assert_eq!(
        fifth.ask(json!({"class":"status"})).await["class"],
        "status"
    );
    // Every slot taken (4 watchers, 2 idle): a request still gets in, and the watchers keep
    // their streams.
    let _idle = idle_clients(&served.path, 1).await;
    let mut op = Conn::greeted(&served.path).await;
    assert_eq!(op.ask(json!({"class":"pause"})).await["class"], "ack");
    runner.status.send_modify(|s| s.lines_done = 20);
    for w in &mut watchers {
        // The pause's own change may come first.
        while status_of(&w.recv().await).lines_done != 20 {}
    }
    served.shutdown().await;
}

/// The process's groups (effective and supplementary) and a gid outside them.
fn my_groups_and_another() -> (Vec<u32>, u32) {
    let mut mine: Vec<u32> = nix::unistd::getgroups()
        .unwrap()
        .into_iter()
        .map(|g| g.as_raw())
        .collect();
    mine.push(nix::unistd::getegid().as_raw());
    let other = (40_000..).find(|g| !mine.contains(g)).unwrap();
    (mine, other)
}

#[tokio::test]
async fn allowed_groups_narrow_who_may_command_and_leave_status_open() {
    let (mine, other) = my_groups_and_another();
    let (channels, runner) = fake_runner(scanning());
    let options = ServerOptions {
        allowed_groups: Some(vec![other]),
        ..ServerOptions::default()
    };
    let served = serve(channels, options).await;
    let mut c = Conn::greeted(&served.path).await;
    for class in ["pause", "resume", "abort", "start"] {
        let e = c.ask(json!({"class": class})).await;
        assert_eq!(e["class"], "error", "{class}: {e}");
        let message = e["message"].as_str().unwrap();
        assert!(
            message.contains(&format!("{class} refused"))
                && message.contains("allowed-groups")
                && message.contains(&format!("uid {}", nix::unistd::geteuid())),
            "{message}"
        );
    }
    assert!(runner.seen.lock().unwrap().is_empty());
    assert_eq!(c.ask(json!({"class":"status"})).await["class"], "status");
    assert_eq!(c.ask(json!({"class":"watch"})).await["class"], "status");
    served.shutdown().await;

    // A group the process is in: commands pass.
    let (channels, runner) = fake_runner(scanning());
    let options = ServerOptions {
        allowed_groups: Some(vec![other, mine[0]]),
        ..ServerOptions::default()
    };
    let served = serve(channels, options).await;
    let mut c = Conn::greeted(&served.path).await;
    assert_eq!(c.ask(json!({"class":"pause"})).await["class"], "ack");
    assert_eq!(*runner.seen.lock().unwrap(), vec![OperatorCommand::Pause]);
    served.shutdown().await;
}

/// `surfscan <verb> --socket PATH` run with the primary group `gid` and only `groups` as its
/// supplementary groups (root may set both; the test suite runs as root, as CI does).
fn client_with_groups(verb: &str, socket: &Path, gid: u32, groups: &[u32]) -> std::process::Output {
    use std::os::unix::process::CommandExt;
    assert!(
        nix::unistd::geteuid().is_root(),
        "giving a client other groups needs root; run the suite as root (CI does)"
    );
    let groups: Vec<libc::gid_t> = groups.to_vec();
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"));
    c.args([verb, "--socket"]).arg(socket);
    // SAFETY: between fork and exec the closure only makes two system calls on data
    // prepared before the fork; it allocates nothing.
    unsafe {
        c.pre_exec(move || {
            if libc::setgroups(groups.len(), groups.as_ptr()) != 0 || libc::setgid(gid) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    c.output().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_supplementary_group_of_the_peer_counts_for_allowed_groups() {
    let (_, other) = my_groups_and_another();
    let (operators, primary) = (other, other + 1);
    let (channels, runner) = fake_runner(scanning());
    let options = ServerOptions {
        allowed_groups: Some(vec![operators]),
        ..ServerOptions::default()
    };
    let served = serve(channels, options).await;
    let path = served.path.clone();
    // Only in the operators' group through a supplementary group: allowed.
    let ok = tokio::task::spawn_blocking(move || {
        client_with_groups("pause", &path, primary, &[operators])
    })
    .await
    .unwrap();
    assert!(ok.status.success(), "{}", crate::common::describe(&ok));
    let peers = runner.peers.lock().unwrap().clone();
    assert_eq!(peers.len(), 1);
    assert_eq!((peers[0].uid, peers[0].gid), (0, primary));
    // Without it: refused, naming the groups it has.
    let path = served.path.clone();
    let refused = tokio::task::spawn_blocking(move || {
        client_with_groups("pause", &path, primary, &[primary + 1])
    })
    .await
    .unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{stderr}");
    assert!(
        stderr.contains("allowed-groups") && stderr.contains(&format!("{}", primary + 1)),
        "{stderr}"
    );
    assert_eq!(runner.seen.lock().unwrap().len(), 1);
    served.shutdown().await;
}

/// A runner busy past the reply timeout (writing a large scan's outputs) comes to a queued
/// `start` only after the operator was told it was not carried out: the request then says its
/// requester has gone, so the runner drops it instead of starting a scan nobody expects. One
/// answered in time is not marked so.
#[tokio::test]
async fn a_command_the_operator_was_told_failed_reaches_the_runner_marked_abandoned() {
    let (_status_tx, status_rx) = watch::channel(Status::idle());
    let (cmd_tx, mut cmd_rx) = mpsc::channel::<OperatorRequest>(4);
    let options = ServerOptions {
        reply_timeout: Duration::from_millis(200),
        ..ServerOptions::default()
    };
    let served = serve(control_channels(status_rx, cmd_tx), options).await;
    let mut c = Conn::greeted(&served.path).await;
    let e = c
        .ask(json!({"class":"start","specimen":"GHOST","operator":"","notes":""}))
        .await;
    assert_eq!(e["class"], "error", "{e}");
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("start was not carried out"),
        "{e}"
    );
    // The runner is free again and takes the queued command.
    let late = cmd_rx.recv().await.unwrap();
    assert!(matches!(late.command, OperatorCommand::Start { .. }));
    assert!(late.abandoned(), "the operator was told it failed");
    // A command answered in time is a live one.
    let asking = tokio::spawn(async move { c.ask(json!({"class":"pause"})).await });
    let live = cmd_rx.recv().await.unwrap();
    assert!(!live.abandoned());
    live.reply.send(Ok("pausing".into())).unwrap();
    assert_eq!(asking.await.unwrap()["class"], "ack");
    served.shutdown().await;
}
