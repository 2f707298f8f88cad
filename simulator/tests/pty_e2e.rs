//! End-to-end tests: a client opens the linked pty path the way the daemon would (raw termios,
//! no tokio-serial) and talks to the simulator running in-process or as the binary.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::os::fd::AsFd;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use surfscan_sim::data::{ServedProfile, YPosition};
use surfscan_sim::grbl::StageShared;
use surfscan_sim::pty::Pty;
use surfscan_sim::replay::Transcript;
use surfscan_sim::server::GARBAGE;
use surfscan_sim::zaber::ZaberSimConfig;
use surfscan_sim::{
    Battery, FaultSpec, InstrumentConfig, Model, ProfileSet, SimEvent, SimHandle, Simulator,
};

const T: Duration = Duration::from_secs(10);

struct Client {
    port: File,
}

impl Client {
    fn open(path: &Path) -> Client {
        let port = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .expect("open the linked pty");
        let mut t = tcgetattr(port.as_fd()).unwrap();
        cfmakeraw(&mut t);
        tcsetattr(port.as_fd(), SetArg::TCSANOW, &t).unwrap();
        Client { port }
    }

    /// Waits up to `timeout` for readable bytes and returns what one read gives (empty on
    /// timeout).
    fn read_some(&mut self, timeout: Duration) -> std::io::Result<Vec<u8>> {
        let mut fds = [PollFd::new(self.port.as_fd(), PollFlags::POLLIN)];
        let ms = PollTimeout::try_from(timeout.as_millis() as i32).unwrap();
        if poll(&mut fds, ms).unwrap() == 0 {
            return Ok(Vec::new());
        }
        let mut buf = [0u8; 4096];
        let n = self.port.read(&mut buf)?;
        Ok(buf[..n].to_vec())
    }

    fn send(&mut self, cmd: &str) {
        self.port.write_all(format!("{cmd}\r").as_bytes()).unwrap();
    }

    /// Reads until CR, or panics after `T`.
    fn line(&mut self) -> String {
        let deadline = Instant::now() + T;
        let mut out = Vec::new();
        while !out.ends_with(b"\r") {
            assert!(Instant::now() < deadline, "no CR within {T:?}; got {out:?}");
            out.extend(self.read_some(Duration::from_millis(100)).unwrap());
        }
        String::from_utf8_lossy(&out).into_owned()
    }

    fn ask(&mut self, cmd: &str) -> String {
        self.send(cmd);
        self.line()
    }

    /// Collects bytes until nothing arrives for `quiet`.
    fn drain(&mut self, quiet: Duration) -> Vec<u8> {
        let mut out = Vec::new();
        loop {
            let b = self.read_some(quiet).unwrap_or_default();
            if b.is_empty() {
                return out;
            }
            out.extend(b);
        }
    }

    /// Polls status every 20 ms until `want`; returns the statuses seen.
    fn poll_until(&mut self, want: &str) -> Vec<String> {
        let deadline = Instant::now() + T;
        let mut seen = Vec::new();
        loop {
            let s = self.ask("RDSTU00");
            let done = s == want;
            if seen.last() != Some(&s) {
                seen.push(s);
            }
            if done {
                return seen;
            }
            assert!(
                Instant::now() < deadline,
                "never reached {want:?}: {seen:?}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

fn link(dir: &tempfile::TempDir) -> PathBuf {
    dir.path().join("sj210")
}

/// The bundled fixture, read independently of the simulator's loader.
fn fixture() -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/mitutoyo_R.31windows.profile_y_mm_x_mm_z_um.csv"
    ))
    .unwrap();
    let mut out: Vec<Vec<f64>> = Vec::new();
    for l in text.lines().skip(1) {
        let f: Vec<&str> = l.split(',').collect();
        let i: usize = f[0].parse().unwrap();
        if out.len() <= i {
            out.push(Vec::new());
        }
        out[i].push(f[3].parse().unwrap());
    }
    out
}

fn fast() -> InstrumentConfig {
    InstrumentConfig {
        time_scale: 0.05,
        ..InstrumentConfig::default()
    }
}

async fn next(h: &mut SimHandle) -> SimEvent {
    tokio::time::timeout(T, h.next_event())
        .await
        .expect("event within timeout")
        .expect("simulator running")
}

async fn start(sim: Simulator) -> SimHandle {
    let mut h = sim.start().unwrap();
    assert!(matches!(next(&mut h).await, SimEvent::Ready(_)));
    h
}

fn parse_block(reply: &str) -> (usize, Vec<f64>) {
    let body = reply.strip_prefix("OK").unwrap().trim_end_matches('\r');
    let mut parts = body.split(',');
    let n: usize = parts.next().unwrap().parse().unwrap();
    (n, parts.map(|v| v.trim().parse().unwrap()).collect())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clean_trace_results_and_readout_match_the_fixture() {
    let dir = tempfile::tempdir().unwrap();
    let h = start(Simulator::new(link(&dir)).instrument(fast())).await;
    let mut c = Client::open(&link(&dir));
    assert_eq!(c.ask("RDSTU00"), "OK000\r");
    assert_eq!(c.ask("RDRES02,01,00"), "NG101\r");
    assert_eq!(c.ask("RDEVA00"), "NG101\r");
    assert_eq!(c.ask("CTSTA"), "OK\r");
    let seen = c.poll_until("OK000\r");
    assert_eq!(seen, vec!["OK001\r", "OK002\r", "OK000\r"]);

    // Independent Ra/Rq of profile 0 rounded to 3 decimals. It is an R profile, served as
    // the instrument exports it: relative to the instrument's mean line, i.e. about zero.
    let z: Vec<f64> = fixture()[0]
        .iter()
        .map(|v| (v * 1000.0).round() / 1000.0)
        .collect();
    let mean = 0.0;
    let ra = z.iter().map(|v| (v - mean).abs()).sum::<f64>() / z.len() as f64;
    let rq = (z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / z.len() as f64).sqrt();
    let ra_reply = c.ask("RDRES02,01,00");
    assert_eq!(ra_reply.len(), 2 + 6 + 7 + 3 + 1);
    assert_eq!(&ra_reply[..8], "OKRa    ");
    assert_eq!(&ra_reply[15..], " um\r");
    let ra_sim: f64 = ra_reply[8..15].trim().parse().unwrap();
    assert!((ra_sim - ra).abs() < 0.0006, "Ra {ra_sim} vs {ra}");
    assert!(ra > 2.0, "the demo data must be visibly rough, Ra {ra}");
    let rq_sim: f64 = c
        .ask("RDRES00,02,00")
        .trim_start_matches("OK")
        .trim()
        .parse()
        .unwrap();
    assert!((rq_sim - rq).abs() < 0.0006);

    assert_eq!(c.ask("RDEVA00"), "OK01067\r");
    let mut values = Vec::new();
    for _ in 0..22 {
        let (n, v) = parse_block(&c.ask("RDEVA50"));
        assert_eq!(n, v.len());
        values.extend(v);
    }
    assert_eq!(values.len(), 1067);
    for (a, b) in values.iter().zip(&z) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
    assert_eq!(c.ask("RDEVA50"), "OK00,0.0\r");

    // The second trace serves the second window.
    assert_eq!(c.ask("CTSTA"), "OK\r");
    c.poll_until("OK000\r");
    assert_eq!(c.ask("RDEVA00"), "OK01067\r");
    let (_, v) = parse_block(&c.ask("RDEVA01"));
    assert!((v[0] - (fixture()[1][0] * 1000.0).round() / 1000.0).abs() < 1e-9);
    h.shutdown().await;
    assert!(!link(&dir).exists(), "shutdown removes the link");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn abort_returns_without_results_and_busy_gives_ng011() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = InstrumentConfig {
        time_scale: 1.0,
        ..InstrumentConfig::default()
    };
    let h = start(Simulator::new(link(&dir)).instrument(cfg)).await;
    let mut c = Client::open(&link(&dir));
    assert_eq!(c.ask("CTSTA"), "OK\r");
    assert_eq!(c.ask("RDSTU00"), "OK001\r");
    assert_eq!(c.ask("RDRES02,01,00"), "NG011\r");
    assert_eq!(c.ask("CTRTN"), "NG011\r");
    // Abort after a second of tracing (0.5 mm travelled): the return then takes 0.5 s, long
    // enough for the first poll to see it even on a loaded machine.
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(c.ask("CTSTA"), "OK\r");
    let seen = c.poll_until("OK000\r");
    assert_eq!(seen.first().map(String::as_str), Some("OK002\r"));
    assert_eq!(c.ask("RDRES02,01,00"), "NG101\r");
    h.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_profile_readout_answers_ng030_and_sj410_uses_selectors() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = InstrumentConfig {
        profile_readout: false,
        time_scale: 0.0,
        ..InstrumentConfig::default()
    };
    let h = start(Simulator::new(link(&dir)).instrument(cfg)).await;
    let mut c = Client::open(&link(&dir));
    assert_eq!(c.ask("RDEVA00"), "NG030\r");
    assert_eq!(c.ask("CTSTA"), "OK\r");
    assert_eq!(c.ask("RDEVA00"), "NG030\r");
    h.shutdown().await;

    let cfg = InstrumentConfig {
        model: Model::Sj410,
        time_scale: 0.0,
        ..InstrumentConfig::default()
    };
    let h = start(Simulator::new(link(&dir)).instrument(cfg)).await;
    let mut c = Client::open(&link(&dir));
    assert_eq!(c.ask("CTSTA"), "OK\r");
    assert_eq!(c.ask("RDEVA100"), "OK01067\r");
    assert_eq!(c.ask("RDRES002,03,00").len(), 2 + 6 + 8 + 3 + 1);
    h.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unplug_mid_trace_and_replug() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = InstrumentConfig {
        time_scale: 1.0,
        ..InstrumentConfig::default()
    };
    let f = match "unplug:300@CTSTA#1".parse::<FaultSpec>().unwrap() {
        FaultSpec::Wire(f) => f,
        other => panic!("{other:?}"),
    };
    let mut h = start(Simulator::new(link(&dir)).instrument(cfg).fault(f)).await;
    let mut c = Client::open(&link(&dir));
    assert_eq!(c.ask("CTSTA"), "OK\r");
    assert!(matches!(next(&mut h).await, SimEvent::Unplugged { .. }));
    assert!(!link(&dir).exists(), "unplug removes the link");
    // The client's side of the vanished device: hang-up (EIO or end of file).
    match c.read_some(Duration::from_secs(2)) {
        Err(e) => assert_eq!(e.raw_os_error(), Some(libc::EIO)),
        Ok(b) => assert!(b.is_empty()),
    }
    assert!(matches!(next(&mut h).await, SimEvent::Replugged { .. }));
    let mut c = Client::open(&link(&dir));
    // Powered up again: idle, the interrupted trace left no results.
    assert_eq!(c.ask("RDSTU00"), "OK000\r");
    assert_eq!(c.ask("RDRES02,01,00"), "NG101\r");
    h.shutdown().await;
}

fn wire(s: &str) -> surfscan_sim::Fault {
    match s.parse::<FaultSpec>().unwrap() {
        FaultSpec::Wire(f) => f,
        other => panic!("{other:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_wire_fault_is_observable() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = InstrumentConfig {
        time_scale: 0.0,
        battery: Battery::Low,
        ..InstrumentConfig::default()
    };
    let sim = Simulator::new(link(&dir))
        .instrument(cfg)
        .fault(wire("ng:011@RDSJ 01x2"))
        .fault(wire("ng:007@CTSTA"))
        .fault(wire("drop@RDSTU00#2"))
        .fault(wire("truncate@RDCON"))
        .fault(wire("garbage@RDPAR"))
        .fault(wire("split@RDSJ 00"))
        .fault(wire("silence:600@RDPSA"))
        .fault(wire("lf@RDSTU01"));
    let h = start(sim).await;
    let mut c = Client::open(&link(&dir));
    assert_eq!(c.ask("RDSJ 01"), "NG011\r");
    assert_eq!(c.ask("RDSJ 01"), "NG011\r");
    assert_eq!(c.ask("RDSJ 01"), "OKV1.00\r");
    // NG007 on the first CTSTA: no trace started.
    assert_eq!(c.ask("CTSTA"), "NG007\r");
    assert_eq!(c.ask("RDSTU00"), "OK000\r");
    c.send("RDSTU00");
    assert!(
        c.drain(Duration::from_millis(300)).is_empty(),
        "dropped reply"
    );
    assert_eq!(c.ask("RDSTU00"), "OK000\r");
    c.send("RDCON");
    // Full reply would be "OK3130001.6012\r" (15 bytes): the first 7 only, no CR.
    assert_eq!(c.drain(Duration::from_millis(300)), b"OK31300");
    c.send("RDPAR");
    let g = c.drain(Duration::from_millis(300));
    assert_eq!(&g[..GARBAGE.len()], GARBAGE);
    assert_eq!(&g[GARBAGE.len()..], b"OK09\r");
    c.send("RDSJ 00");
    let first = c.read_some(T).unwrap();
    assert_eq!(
        first, b"OK0",
        "first write of a split reply is half of OK000\\r"
    );
    assert_eq!(c.line(), "00\r");
    c.send("RDPSA");
    assert!(c.read_some(Duration::from_millis(300)).unwrap().is_empty());
    assert_eq!(c.line(), "OK0.000\r");
    c.send("RDSTU01");
    assert_eq!(c.drain(Duration::from_millis(300)), b"OK001\r\n");
    h.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stage_position_selects_the_served_line() {
    let dir = tempfile::tempdir().unwrap();
    let set = ProfileSet::new(
        (0..5)
            .map(|i| ServedProfile {
                y_mm: 1.0 + 0.02 * i as f64,
                pitch_x_mm: 0.001,
                z_um: vec![i as f64, 0.5, -0.5],
            })
            .collect(),
    )
    .unwrap();
    let cfg = InstrumentConfig {
        time_scale: 0.0,
        ..InstrumentConfig::default()
    };
    let sim = Simulator::new(link(&dir)).instrument(cfg).profiles(set);
    let y: YPosition = sim.y_position();
    let (held_tx, held_rx) = tokio::sync::oneshot::channel::<()>();
    let stage_link = dir.path().join("stage");
    let sim = sim.stage(
        &stage_link,
        Box::new(move |pty: Pty, _y| {
            Box::pin(async move {
                let _pty = pty;
                let _ = held_rx.await;
                Ok(())
            })
        }),
    );
    let h = sim.start().unwrap();
    assert_eq!(h.ready().stage.as_deref(), Some(stage_link.as_path()));
    assert!(stage_link.exists());
    let mut c = Client::open(&link(&dir));
    for (y_nm, line) in [
        (1_060_000, 3),
        (1_060_000, 3),
        (1_000_000, 0),
        (1_099_000, 0),
    ] {
        y.set_nm(y_nm);
        assert_eq!(c.ask("CTSTA"), "OK\r");
        assert_eq!(c.ask("RDEVA00"), "OK00003\r");
        assert_eq!(c.ask("RDEVA01"), format!("OK01,{:>9.3}\r", line as f64));
    }
    drop(held_tx);
    h.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn replays_a_recorded_transcript_over_the_pty() {
    let dir = tempfile::tempdir().unwrap();
    let t = Transcript::parse(
        "# surfscan transcript v1\n# instrument: SJ-210\n\
0.000000 > RDSJ 01\\r\n0.010000 < OKV2.03\\r\n\
1.000000 > CTSTA\\r\n1.010000 < OK\\r\n\
1.200000 > RDSTU00\\r\n1.210000 < OK001\\r\n\
3.000000 > RDSTU00\\r\n3.010000 < OK000\\r\n\
3.100000 > RDRES02,01,00\\r\n3.110000 < OKRa     \\xB50.5 um\\r\n",
    )
    .unwrap();
    // Scale 0.1: the recorded 2 s to idle becomes 0.2 s.
    let h = start(Simulator::new(link(&dir)).replay(t, 0.1)).await;
    let mut c = Client::open(&link(&dir));
    assert_eq!(c.ask("RDSJ 01"), "OKV2.03\r");
    assert_eq!(c.ask("CTSTA"), "OK\r");
    let seen = c.poll_until("OK000\r");
    assert_eq!(seen, vec!["OK001\r", "OK000\r"]);
    c.send("RDRES02,01,00");
    assert_eq!(
        c.drain(Duration::from_millis(300)),
        b"OKRa     \xb50.5 um\r"
    );
    h.shutdown().await;
}

/// The simulator binary with `args` and `stdin`, its output piped, once it has printed its
/// ready line: the child, the rest of its output, and the ready line parsed.
fn spawn_sim(
    args: &[&str],
    stdin: std::process::Stdio,
) -> (
    std::process::Child,
    BufReader<std::process::ChildStdout>,
    serde_json::Value,
) {
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan-sim"))
        .args(args)
        .stdin(stdin)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut ready = String::new();
    out.read_line(&mut ready).unwrap();
    let v: serde_json::Value = serde_json::from_str(&ready).unwrap();
    assert_eq!(v["event"], "ready", "{ready}");
    (child, out, v)
}

#[test]
fn binary_prints_ready_line_and_exits_when_stdin_closes() {
    let dir = tempfile::tempdir().unwrap();
    let l = link(&dir);
    let (mut child, _out, v) = spawn_sim(
        &[
            "--instrument-link",
            l.to_str().unwrap(),
            "--time-scale",
            "0",
            "--fault",
            "battery:abnormal",
            "--model",
            "sj410",
        ],
        std::process::Stdio::piped(),
    );
    assert_eq!(v["instrument"], l.to_str().unwrap());
    assert_eq!(v["stage"], serde_json::Value::Null);
    assert_eq!(v["model"], "sj410");
    let mut c = Client::open(&l);
    assert_eq!(c.ask("RDSTU01"), "OK002\r");
    assert_eq!(c.ask("RDPAR0"), "OK09\r");
    drop(child.stdin.take());
    let deadline = Instant::now() + T;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success());
            break;
        }
        assert!(
            Instant::now() < deadline,
            "simulator did not exit on stdin EOF"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(!l.exists(), "exit removes the link");
}

#[test]
fn binary_with_stdin_from_dev_null_keeps_running_until_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let l = link(&dir);
    let (mut child, _out, _) = spawn_sim(
        &[
            "--instrument-link",
            l.to_str().unwrap(),
            "--time-scale",
            "0",
        ],
        std::process::Stdio::null(),
    );
    // Still serving well after the ready line: /dev/null's end of file is no stop signal.
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "quit with stdin at /dev/null"
    );
    let mut c = Client::open(&l);
    assert!(c.ask("RDSTU01").starts_with("OK"));
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
    let output = child.wait_with_output().unwrap();
    assert!(output.status.success());
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(err.contains("stopping (SIGTERM)"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_completes_while_a_reply_is_blocked_on_an_unread_pty() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = InstrumentConfig {
        time_scale: 0.0,
        ..InstrumentConfig::default()
    };
    let h = start(Simulator::new(link(&dir)).instrument(cfg)).await;
    let mut c = Client::open(&link(&dir));
    assert_eq!(c.ask("CTSTA"), "OK\r");
    assert_eq!(c.ask("RDEVA00"), "OK01067\r");
    // 8 read-outs of 22 blocks of ~500 bytes (~88 kB), never read: far more than the pty
    // buffers hold, so the simulator's write blocks.
    for _ in 0..8 {
        c.send("RDEVA00");
        for _ in 0..22 {
            c.send("RDEVA50");
        }
    }
    tokio::time::timeout(T, h.shutdown())
        .await
        .expect("shutdown must not hang on a blocked write");
    assert!(!link(&dir).exists());
}

/// Reads one stage reply (GRBL and Zaber end lines with CR LF), or panics after `T`.
fn reply_crlf(c: &mut Client) -> String {
    let deadline = Instant::now() + T;
    let mut out = Vec::new();
    while !out.ends_with(b"\r\n") {
        assert!(
            Instant::now() < deadline,
            "no CR LF within {T:?}; got {out:?}"
        );
        out.extend(c.read_some(Duration::from_millis(100)).unwrap());
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// GRBL replies up to and including their `ok` (several lines may come in one read).
fn until_ok(c: &mut Client) -> String {
    let deadline = Instant::now() + T;
    let mut out = Vec::new();
    while !out.ends_with(b"ok\r\n") {
        assert!(Instant::now() < deadline, "no ok within {T:?}; got {out:?}");
        out.extend(c.read_some(Duration::from_millis(100)).unwrap());
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The binary's GRBL board with its home switch at the bottom and a force-origin build: the
/// build letter and `$23=2` are what a host reads, and homing zeroes the counter. The two
/// flags describe a GRBL board only, so with a Zaber stage they are refused.
#[test]
fn binary_serves_a_grbl_board_homing_to_a_switch_at_the_bottom() {
    let dir = tempfile::tempdir().unwrap();
    let l = dir.path().join("ystage");
    let (mut child, _out, _) = spawn_sim(
        &[
            "--stage-link",
            l.to_str().unwrap(),
            "--stage-protocol",
            "grbl",
            "--stage-home-at-bottom",
            "--stage-force-origin",
            "--time-scale",
            "0",
        ],
        std::process::Stdio::piped(),
    );
    let mut c = Client::open(&l);
    c.send("$I");
    assert!(until_ok(&mut c).contains("[OPT:VZ,15,128]"));
    c.send("$$");
    assert!(until_ok(&mut c).contains("$23=2\r\n"));
    c.send("$H");
    assert_eq!(until_ok(&mut c), "ok\r\n");
    c.port.write_all(b"?").unwrap();
    let r = reply_crlf(&mut c);
    assert!(r.starts_with("<Idle|MPos:0.000,0.000,0.000|"), "{r}");
    drop(child.stdin.take());
    assert!(child.wait().unwrap().success());

    let refused = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan-sim"))
        .args([
            "--stage-link",
            dir.path().join("zaber").to_str().unwrap(),
            "--stage-protocol",
            "zaber",
            "--stage-force-origin",
        ])
        .output()
        .unwrap();
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("--stage-protocol grbl"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn simulated_zaber_position_selects_the_served_line() {
    let dir = tempfile::tempdir().unwrap();
    // Lines at y = 1.00, 1.02, … 1.08 mm; line i has first height i.
    let set = ProfileSet::new(
        (0..5)
            .map(|i| ServedProfile {
                y_mm: 1.0 + 0.02 * i as f64,
                pitch_x_mm: 0.001,
                z_um: vec![i as f64, 0.5, -0.5],
            })
            .collect(),
    )
    .unwrap();
    let cfg = InstrumentConfig {
        time_scale: 0.0,
        ..InstrumentConfig::default()
    };
    let stage_link = dir.path().join("zaber");
    let shared = StageShared::new();
    // 125 nm per microstep: 8160 microsteps = 1.02 mm (line 1).
    let zaber = ZaberSimConfig {
        nm_per_microstep: 125.0,
        start: 8160,
        homed_at_start: true,
        time_scale: 1000.0,
        ..ZaberSimConfig::default()
    };
    let sim = Simulator::new(link(&dir))
        .instrument(cfg)
        .profiles(set)
        .zaber_stage(&stage_link, zaber, shared.clone());
    let h = start(sim).await;
    // Published by the time the simulator is ready, so the first trace serves line 1.
    assert_eq!(shared.true_position_nm(), 1_020_000);
    assert_eq!(h.ready().stage.as_deref(), Some(stage_link.as_path()));
    assert_eq!(h.ready().instrument.as_deref(), Some(link(&dir).as_path()));
    let mut inst = Client::open(&link(&dir));
    let mut stage = Client::open(&stage_link);
    assert_eq!(inst.ask("CTSTA"), "OK\r");
    assert_eq!(inst.ask("RDEVA00"), "OK00003\r");
    assert_eq!(inst.ask("RDEVA01"), format!("OK01,{:>9.3}\r", 1.0));
    // Move to 1.06 mm = 8480 microsteps (line 3) and wait for IDLE.
    stage.port.write_all(b"/1 1 move abs 8480\r\n").unwrap();
    assert!(reply_crlf(&mut stage).starts_with("@01 1 OK"));
    loop {
        stage.port.write_all(b"/1 1\r\n").unwrap();
        if reply_crlf(&mut stage).contains(" IDLE ") {
            break;
        }
    }
    assert_eq!(shared.true_position_nm(), 1_060_000);
    inst.poll_until("OK000\r");
    assert_eq!(inst.ask("CTSTA"), "OK\r");
    assert_eq!(inst.ask("RDEVA00"), "OK00003\r");
    assert_eq!(inst.ask("RDEVA01"), format!("OK01,{:>9.3}\r", 3.0));
    h.shutdown().await;
    assert!(!stage_link.exists(), "shutdown removes the stage link");
}

#[test]
fn binary_runs_a_grbl_stage_alone_with_an_injected_fault() {
    let dir = tempfile::tempdir().unwrap();
    let l = dir.path().join("grbl");
    let (mut child, _out, v) = spawn_sim(
        &[
            "--stage-link",
            l.to_str().unwrap(),
            "--stage-protocol",
            "grbl",
            "--time-scale",
            "0.001",
            "--stage-fault",
            "error15",
        ],
        std::process::Stdio::piped(),
    );
    assert_eq!(v["instrument"], serde_json::Value::Null);
    assert_eq!(v["stage"], l.to_str().unwrap());
    let mut c = Client::open(&l);
    // Powered up in Alarm: unlock, then the first jog meets the injected error:15 and the
    // second one, identical and within travel, is accepted.
    c.port.write_all(b"$X\n").unwrap();
    assert_eq!(reply_crlf(&mut c), "[MSG:Caution: Unlocked]\r\nok\r\n");
    c.port.write_all(b"$J=G53 G90 Y-1.000 F600\n").unwrap();
    assert_eq!(reply_crlf(&mut c), "error:15\r\n");
    c.port.write_all(b"$J=G53 G90 Y-1.000 F600\n").unwrap();
    assert_eq!(reply_crlf(&mut c), "ok\r\n");
    drop(child.stdin.take());
    let deadline = Instant::now() + T;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success());
            break;
        }
        assert!(
            Instant::now() < deadline,
            "simulator did not exit on stdin EOF"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(!l.exists(), "exit removes the stage link");
}

/// `--write-config FILE` writes the station configuration for the binary's own links before
/// its ready line, with absolute paths (the links were given relative to the simulator's
/// working directory) and the scans and control socket beside FILE; settings no scan can use
/// are refused before anything is served.
#[test]
fn binary_writes_the_station_config_for_its_own_links() {
    let dir = tempfile::tempdir().unwrap();
    let sim = |args: &[&str]| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan-sim"));
        c.current_dir(dir.path()).args(args);
        c
    };
    let mut child = sim(&[
        "--instrument-link",
        "sj210",
        "--stage-link",
        "ystage",
        "--stage-protocol",
        "zaber",
        "--model",
        "sj410",
        "--time-scale",
        "0.02",
        "--write-config",
        "station.toml",
    ])
    .stdin(std::process::Stdio::piped())
    .stdout(std::process::Stdio::piped())
    .stderr(std::process::Stdio::piped())
    .spawn()
    .unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut ready = String::new();
    out.read_line(&mut ready).unwrap();
    assert!(ready.contains("\"event\":\"ready\""), "{ready}");
    let text = std::fs::read_to_string(dir.path().join("station.toml")).unwrap();
    let toml: std::collections::BTreeMap<String, toml::Value> = toml::from_str(&text).unwrap();
    let path = |p: &str| dir.path().join(p).display().to_string();
    assert_eq!(
        toml["instrument"]["port"].as_str(),
        Some(path("sj210").as_str())
    );
    assert_eq!(toml["instrument"]["model"].as_str(), Some("sj410"));
    assert_eq!(
        toml["instrument"]["commands"]["profile-total"].as_str(),
        Some("RDEVA000")
    );
    assert_eq!(
        toml["stage"]["port"].as_str(),
        Some(path("ystage").as_str())
    );
    assert_eq!(toml["stage"]["protocol"].as_str(), Some("zaber"));
    assert_eq!(toml["stage"]["nm-per-microstep"].as_float(), Some(125.0));
    assert_eq!(toml["scan"]["lines"].as_integer(), Some(31));
    assert_eq!(toml["output"]["dir"].as_str(), Some(path("scans").as_str()));
    assert_eq!(
        toml["control"]["socket"].as_str(),
        Some(path("control.sock").as_str())
    );
    // The links the configuration names are served (battery good).
    let mut c = Client::open(&dir.path().join("sj210"));
    assert_eq!(c.ask("RDSTU01"), "OK000\r");
    drop(child.stdin.take());
    assert!(child.wait().unwrap().success());

    for (args, why) in [
        (&["--no-profile-readout"][..], "--no-profile-readout"),
        (&["--time-scale", "0"][..], "time scale of at least 0.0061"),
    ] {
        let mut all = vec![
            "--instrument-link",
            "sj210b",
            "--stage-link",
            "ystageb",
            "--stage-protocol",
            "grbl",
            "--write-config",
            "refused.toml",
        ];
        all.extend_from_slice(args);
        let o = sim(&all)
            .stdin(std::process::Stdio::null())
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(why), "{args:?}: {err}");
        assert!(!dir.path().join("refused.toml").exists());
        assert!(!dir.path().join("sj210b").exists());
    }
    let no_stage = sim(&["--instrument-link", "sj210c", "--write-config", "x.toml"])
        .output()
        .unwrap();
    assert_eq!(no_stage.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&no_stage.stderr).contains("--stage-link"));
}
