//! Whether open pages slow a scan: the real `surfscan daemon` with its page (`[web]`) scans
//! the simulator twice, first with no page open, then with N pages open (default 100), each
//! following the live stream (`GET /api/live`, server-sent events) and reading everything
//! it is sent, as a browser does. Each line's period is read back from the scan's journal
//! (from the previous line's record to its own); the periods with and without the pages are
//! compared. The scans alternate (alone, with the pages, alone, …) so that the machine's other
//! load falls on both alike.
//!
//! The instrument is sped up (default 50×) and the stage too, so that a line's period is
//! mostly the software's own work and any slowing by the page shows large, not hidden
//! behind the device time of a real line.
//!
//! `cargo bench --bench web_load [-- --lines L --pages N --rounds R --speed-up S]` (defaults
//! 16 lines, 100 pages, 3 rounds of a scan alone and a scan with the pages, 50×). Without
//! `--bench` (as `cargo test --all-targets` runs it) one round of 6 lines with 5 pages, only
//! to check that it runs.

#[path = "shared/mod.rs"]
mod shared;

use std::net::SocketAddr;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use surfscan::cli::demo::{demo_config, demo_socket};
use surfscan::control::client::ControlClient;
use surfscan::control::protocol::{Message, Request};
use surfscan::scan::command::StartMode;
use surfscan::scan::ending::StopStatus;
use surfscan::scan::journal::{read_journal, Record};
use surfscan::scan::status::{State, Status};
use surfscan_sim::grbl::{GrblSimConfig, StageShared};
use surfscan_sim::{InstrumentConfig, ProfileSet, SimEvent, Simulator};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

const TOKEN: &str = "bench-page-token-0b6f41d2c9";
const DEADLINE: Duration = Duration::from_secs(600);

struct Args {
    lines: usize,
    pages: usize,
    rounds: usize,
    speed_up: f64,
}

fn args() -> Args {
    let bench = std::env::args().any(|a| a == "--bench");
    let mut a = if bench {
        Args {
            lines: 16,
            pages: 100,
            rounds: 3,
            speed_up: 50.0,
        }
    } else {
        Args {
            lines: 6,
            pages: 5,
            rounds: 1,
            speed_up: 50.0,
        }
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut value = || it.next().and_then(|v| v.parse::<f64>().ok());
        match k.as_str() {
            "--lines" => a.lines = value().map_or(a.lines, |v| v as usize),
            "--pages" => a.pages = value().map_or(a.pages, |v| v as usize),
            "--rounds" => a.rounds = value().map_or(a.rounds, |v| v as usize),
            "--speed-up" => a.speed_up = value().unwrap_or(a.speed_up),
            _ => {} // cargo bench passes --bench
        }
    }
    a.lines = a.lines.clamp(3, 200);
    a.pages = a.pages.min(250);
    a.rounds = a.rounds.clamp(1, 20);
    a
}

/// The daemon; killed if the benchmark fails before it exits.
struct Daemon(Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("a free port")
        .local_addr()
        .expect("its address")
        .port()
}

async fn status(socket: &Path) -> Option<Status> {
    let mut c = ControlClient::connect(socket).await.ok()?;
    match c.request(&Request::Status).await.ok()?.message {
        Message::Status(s) => Some(*s),
        _ => None,
    }
}

async fn wait_status(socket: &Path, what: &str, f: impl Fn(&Status) -> bool) -> Status {
    let t0 = Instant::now();
    loop {
        if let Some(s) = status(socket).await {
            if f(&s) {
                return s;
            }
        }
        assert!(t0.elapsed() < DEADLINE, "{what}: not within {DEADLINE:?}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Starts a new scan and waits for its end; its line periods, s.
async fn scan(socket: &Path, specimen: &str) -> Vec<f64> {
    let before = status(socket).await.expect("the daemon answers").starts;
    let mut c = ControlClient::connect(socket)
        .await
        .expect("control socket");
    let reply = c
        .request(&Request::Start {
            specimen: specimen.into(),
            operator: "bench".into(),
            notes: String::new(),
            mode: StartMode::New,
            recipe: None,
            y_start_mm: None,
        })
        .await
        .expect("start answered");
    assert!(
        matches!(reply.message, Message::Ack { .. }),
        "{:?}",
        reply.message
    );
    let s = wait_status(socket, "the scan's end", |s| {
        s.starts > before && s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    let stop = s.last_stop.expect("a last stop");
    assert_eq!(
        stop.status,
        StopStatus::Success,
        "the scan did not succeed: {}",
        stop.reason
    );
    periods(Path::new(&stop.dir))
}

fn periods(dir: &Path) -> Vec<f64> {
    let rec = read_journal(&dir.join("journal.jsonl")).expect("journal reads");
    let times: Vec<f64> = rec
        .records
        .iter()
        .filter_map(|r| match r {
            Record::Line(l) => Some(l.time.timestamp_micros() as f64 / 1e6),
            _ => None,
        })
        .collect();
    times.windows(2).map(|w| w[1] - w[0]).collect()
}

/// One open page: follows `/api/live` and reads everything; counts the bytes received.
async fn open_page(addr: SocketAddr, bytes: Arc<AtomicU64>) -> tokio::task::JoinHandle<()> {
    let mut s = tokio::net::TcpStream::connect(addr)
        .await
        .expect("the page's port");
    let req = format!(
        "GET /api/live HTTP/1.1\r\nhost: {addr}\r\nauthorization: Bearer {TOKEN}\r\naccept: text/event-stream\r\n\r\n"
    );
    s.write_all(req.as_bytes()).await.expect("request sent");
    let mut head = [0u8; 12];
    s.read_exact(&mut head).await.expect("an answer");
    assert_eq!(&head, b"HTTP/1.1 200", "{}", String::from_utf8_lossy(&head));
    bytes.fetch_add(head.len() as u64, Ordering::Relaxed);
    tokio::spawn(async move {
        let mut buf = vec![0u8; 64 * 1024];
        while let Ok(n) = s.read(&mut buf).await {
            if n == 0 {
                break;
            }
            bytes.fetch_add(n as u64, Ordering::Relaxed);
        }
    })
}

fn summary(label: &str, periods: &[f64]) -> (f64, f64) {
    let mut p: Vec<f64> = periods.iter().map(|s| s * 1000.0).collect();
    let mean = p.iter().sum::<f64>() / p.len() as f64;
    let max = p.iter().copied().fold(f64::MIN, f64::max);
    let med = shared::median(&mut p);
    println!(
        "  {label}: line period median {med:.1} ms, mean {mean:.1} ms, max {max:.1} ms over {} periods",
        periods.len()
    );
    (med, mean)
}

fn config(dir: &Path, inst: &Path, stage: &Path, lines: usize) -> (PathBuf, PathBuf, SocketAddr) {
    let out = dir.join("scans");
    let tokens = dir.join("web-tokens");
    std::fs::write(&tokens, format!("bench {TOKEN}\n")).expect("token file");
    std::fs::set_permissions(&tokens, std::fs::Permissions::from_mode(0o600)).expect("mode");
    let addr: SocketAddr = format!("127.0.0.1:{}", free_port())
        .parse()
        .expect("address");
    let text = demo_config(inst, stage, &out).replace("lines = 31", &format!("lines = {lines}"));
    let text = format!(
        "{text}\n[fit]\ndegree-v = 3\n[web]\nlisten = \"{addr}\"\ntoken-file = {:?}\n",
        tokens.display().to_string()
    );
    let cfg = dir.join("station.toml");
    std::fs::write(&cfg, text).expect("config");
    (cfg, out, addr)
}

async fn run(a: Args) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let inst = tmp.path().join("sj210");
    let stage = tmp.path().join("ystage");
    let mut profiles = ProfileSet::bundled().expect("bundled profiles");
    profiles.y_first_mm = -20.0;
    let mut sim = Simulator::new(&inst)
        .instrument(InstrumentConfig {
            time_scale: 1.0 / a.speed_up,
            ..InstrumentConfig::default()
        })
        .profiles(profiles)
        .baud(1_000_000)
        .grbl_stage(
            &stage,
            GrblSimConfig {
                steps_per_mm: 400.0,
                max_travel_mm: 100.0,
                time_scale: a.speed_up * 10.0,
                ..GrblSimConfig::default()
            },
            StageShared::new(),
        )
        .start()
        .expect("simulator starts");
    match tokio::time::timeout(Duration::from_secs(10), sim.next_event()).await {
        Ok(Some(SimEvent::Ready(_))) => {}
        other => panic!("simulator not ready: {other:?}"),
    }
    let (cfg, out, addr) = config(tmp.path(), &inst, &stage, a.lines);
    let socket = demo_socket(&out);
    let mut d = Daemon(
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["daemon", "--config"])
            .arg(&cfg)
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("surfscan daemon runs"),
    );
    wait_status(&socket, "the daemon idle", |s| s.state == State::Idle).await;
    let page_up = status(&socket)
        .await
        .and_then(|s| s.links.get("web").cloned());
    assert!(
        page_up.as_ref().is_none_or(|l| l.ok),
        "the page is not up: {page_up:?}"
    );

    println!(
        "web_load: {} lines a scan, instrument and stage sped up {}x; the daemon's page on {addr}",
        a.lines, a.speed_up
    );
    // Scans without and with the pages alternate, so that a change in the machine's other
    // load falls on both alike.
    let (mut alone, mut watched) = (Vec::new(), Vec::new());
    let (mut sent, mut least) = (0u64, u64::MAX);
    for _ in 0..a.rounds {
        alone.extend(scan(&socket, "no-page").await);
        let bytes: Vec<Arc<AtomicU64>> = (0..a.pages).map(|_| Arc::default()).collect();
        let mut pages = Vec::new();
        for b in &bytes {
            pages.push(open_page(addr, b.clone()).await);
        }
        let before: u64 = bytes.iter().map(|b| b.load(Ordering::Relaxed)).sum();
        watched.extend(scan(&socket, "pages").await);
        let got: Vec<u64> = bytes.iter().map(|b| b.load(Ordering::Relaxed)).collect();
        least = least.min(got.iter().copied().min().unwrap_or(0));
        sent += got.iter().sum::<u64>() - before;
        // Closing the connections: the pages go away before the next scan alone.
        for p in pages {
            p.abort();
        }
    }
    let (med0, mean0) = summary("no page open", &alone);
    let label = format!("{} pages open", a.pages);
    let (med1, mean1) = summary(&label, &watched);
    println!(
        "  the pages received {:.1} MB during their scans; each page at least {:.1} kB a scan",
        sent as f64 / 1e6,
        least as f64 / 1e3
    );
    println!(
        "  difference with the pages open: median {:+.1} ms ({:+.1} %), mean {:+.1} ms ({:+.1} %)",
        med1 - med0,
        (med1 - med0) / med0 * 100.0,
        mean1 - mean0,
        (mean1 - mean0) / mean0 * 100.0
    );
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(d.0.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    );
    let t0 = Instant::now();
    while d.0.try_wait().ok().flatten().is_none() && t0.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(50));
    }
    sim.shutdown().await;
}

fn main() {
    let a = args();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(run(a));
}
