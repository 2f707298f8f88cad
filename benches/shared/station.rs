//! What the benchmarks that run the real `surfscan daemon` against the simulator share: the
//! simulated station (instrument and stage sped up alike), the daemon process, its status
//! over the control socket, a scan started and waited for, each line's period read back from
//! the journal, and the periods' summary. Included by path (`#[path = "shared/station.rs"]
//! mod station;`) by those benchmarks only.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use surfscan::control::client::ControlClient;
use surfscan::control::protocol::{Message, Request};
use surfscan::scan::command::StartMode;
use surfscan::scan::ending::StopStatus;
use surfscan::scan::journal::{read_journal, Record};
use surfscan::scan::status::{State, Status};
use surfscan_sim::grbl::StageShared;
use surfscan_sim::{SimEvent, SimHandle, Simulator};

/// The longest a benchmark waits for one state of the daemon.
pub const DEADLINE: Duration = Duration::from_secs(600);

/// The simulated SJ-210 and GRBL stage, `speed_up` times faster than real, on pseudo-terminals
/// below `dir`; with the instrument's and the stage's device paths.
pub async fn simulator(dir: &Path, speed_up: f64) -> (SimHandle, PathBuf, PathBuf) {
    let inst = dir.join("sj210");
    let stage = dir.join("ystage");
    let mut sim = Simulator::sped_up_station(&inst, &stage, speed_up, StageShared::new())
        .and_then(Simulator::start)
        .expect("simulator starts");
    match tokio::time::timeout(Duration::from_secs(10), sim.next_event()).await {
        Ok(Some(SimEvent::Ready(_))) => {}
        other => panic!("simulator not ready: {other:?}"),
    }
    (sim, inst, stage)
}

/// The daemon; killed if the benchmark fails before it stops it.
pub struct Daemon(pub Child);

impl Daemon {
    /// `surfscan daemon --config cfg`, its output discarded.
    pub fn spawn(cfg: &Path) -> Daemon {
        Daemon(
            Command::new(env!("CARGO_BIN_EXE_surfscan"))
                .args(["daemon", "--config"])
                .arg(cfg)
                .env_remove("NOTIFY_SOCKET")
                .env_remove("WATCHDOG_USEC")
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("surfscan daemon runs"),
        )
    }

    /// SIGTERM, and up to 30 s for it to exit.
    pub fn stop(mut self) {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(self.0.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
        let t0 = Instant::now();
        while self.0.try_wait().ok().flatten().is_none() && t0.elapsed() < Duration::from_secs(30) {
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// A free loopback TCP port (bound and released; the caller binds it next).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("a free port")
        .local_addr()
        .expect("its address")
        .port()
}

/// The daemon's status, if it answers.
pub async fn status(socket: &Path) -> Option<Status> {
    let mut c = ControlClient::connect(socket).await.ok()?;
    match c.request(&Request::Status).await.ok()?.message {
        Message::Status(s) => Some(*s),
        _ => None,
    }
}

/// Waits (up to [`DEADLINE`]) for a status that satisfies `f`.
pub async fn wait_status(socket: &Path, what: &str, f: impl Fn(&Status) -> bool) -> Status {
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

/// Starts a new scan and waits for its end; its status then and its line periods, s.
pub async fn scan(socket: &Path, specimen: &str) -> (Status, Vec<f64>) {
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
    let stop = s.last_stop.clone().expect("a last stop");
    assert_eq!(
        stop.status,
        StopStatus::Success,
        "the scan did not succeed: {}",
        stop.reason
    );
    let p = periods(Path::new(&stop.dir));
    (s, p)
}

/// Each line's period, s: from the previous line's journal record to its own.
pub fn periods(dir: &Path) -> Vec<f64> {
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

/// Prints the periods' median, mean and maximum, ms; returns the median and the mean.
pub fn summary(label: &str, periods: &[f64]) -> (f64, f64) {
    let mut p: Vec<f64> = periods.iter().map(|s| s * 1000.0).collect();
    let mean = p.iter().sum::<f64>() / p.len() as f64;
    let max = p.iter().copied().fold(f64::MIN, f64::max);
    let med = crate::shared::median(&mut p);
    println!(
        "  {label}: line period median {med:.1} ms, mean {mean:.1} ms, max {max:.1} ms over {} periods",
        periods.len()
    );
    (med, mean)
}
