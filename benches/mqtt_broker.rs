//! Whether the MQTT broker can slow a scan: the real `surfscan daemon` with `[mqtt]` scans the
//! simulator alternately with a real Mosquitto broker up (status, events and results
//! delivered as they come) and with it stopped (the link failing to connect and trying again
//! with backoff, the events and results waiting in the outbox on disk). Each line's period is
//! read back from the scan's journal (from the previous line's record to its own); the periods
//! with the broker up and down are compared. After each scan with the broker down, the broker
//! is started again and the time until the outbox is empty is printed with how many messages
//! waited.
//!
//! The instrument and the stage are sped up (default 50×), so that a line's period is mostly
//! the software's own work and any slowing by the link shows large, not hidden behind the
//! device time of a real line.
//!
//! `cargo bench --bench mqtt_broker [-- --lines L --rounds R --speed-up S]` (defaults 16
//! lines, 3 rounds of a scan with the broker up and one with it down, 50×). Needs `mosquitto`
//! (Debian package, which `bash .ci/run` installs). Without `--bench` (as `cargo test
//! --all-targets` runs it) one round of 6 lines, only to check that it runs.

#[path = "shared/mod.rs"]
mod shared;
#[path = "shared/station.rs"]
mod station;

use station::{free_port, scan, status, summary, wait_status, Daemon};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use surfscan::cli::demo::demo_socket;
use surfscan::scan::status::{LinkStatus, State};

struct Args {
    lines: usize,
    rounds: usize,
    speed_up: f64,
}

fn args() -> Args {
    let (lines, rounds) = if shared::full_run() { (16, 3) } else { (6, 1) };
    let number =
        |name: &str, default: usize| shared::number_arg(name).map_or(default, |v| v as usize);
    Args {
        lines: number("--lines", lines).clamp(3, 200),
        rounds: number("--rounds", rounds).clamp(1, 20),
        speed_up: shared::number_arg("--speed-up").unwrap_or(50.0),
    }
}

/// A Mosquitto broker on a loopback port, started and stopped by the benchmark.
struct Broker {
    conf: PathBuf,
    port: u16,
    process: Option<Child>,
}

impl Broker {
    fn new(dir: &Path) -> Broker {
        let port = free_port();
        let conf = dir.join("mosquitto.conf");
        let user = if nix::unistd::geteuid().is_root() {
            "user root\n"
        } else {
            ""
        };
        std::fs::write(
            &conf,
            format!(
                "{user}listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\nlog_dest file {}\n",
                dir.join("mosquitto.log").display()
            ),
        )
        .expect("broker configuration");
        Broker {
            conf,
            port,
            process: None,
        }
    }

    fn start(&mut self) {
        let program = ["/usr/sbin/mosquitto", "/usr/bin/mosquitto"]
            .into_iter()
            .find(|p| Path::new(p).exists())
            .expect("mosquitto is not installed: `bash .ci/run` installs it (apt-get install mosquitto)");
        let mut child = Command::new(program)
            .arg("-c")
            .arg(&self.conf)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("mosquitto starts");
        let t0 = Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            if let Ok(Some(st)) = child.try_wait() {
                panic!("mosquitto exited: {st}");
            }
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "mosquitto does not listen"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        self.process = Some(child);
    }

    fn stop(&mut self) {
        if let Some(mut p) = self.process.take() {
            let _ = p.kill();
            let _ = p.wait();
        }
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        self.stop();
    }
}

async fn link(socket: &Path) -> Option<LinkStatus> {
    status(socket)
        .await
        .and_then(|s| s.links.get("mqtt").cloned())
}

/// Waits until the link is connected with nothing left in the outbox; how long that took.
async fn drained(socket: &Path) -> Duration {
    let t0 = Instant::now();
    wait_status(socket, "the outbox delivered", |s| {
        s.links.get("mqtt").is_some_and(|l| l.ok && l.queued == 0)
    })
    .await;
    t0.elapsed()
}

async fn run(a: Args) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let (sim, inst, stage) = station::simulator(tmp.path(), a.speed_up).await;
    let mut broker = Broker::new(tmp.path());
    broker.start();
    let out = tmp.path().join("scans");
    let text = shared::demo_config(&inst, &stage, &out, a.lines);
    let cfg = tmp.path().join("station.toml");
    std::fs::write(
        &cfg,
        format!(
            "{text}\n[fit]\ndegree-v = 3\n[mqtt]\nurl = \"mqtt://127.0.0.1:{}\"\nstation = \"bench\"\n",
            broker.port
        ),
    )
    .expect("config");
    let socket = demo_socket(&out);
    let d = Daemon::spawn(&cfg);
    wait_status(&socket, "the daemon idle and connected", |s| {
        s.state == State::Idle && s.links.get("mqtt").is_some_and(|l| l.ok)
    })
    .await;
    println!(
        "mqtt_broker: {} lines a scan, instrument and stage sped up {}x; Mosquitto on 127.0.0.1:{}",
        a.lines, a.speed_up, broker.port
    );
    // Scans with the broker up and down alternate, so that a change in the machine's other
    // load falls on both alike.
    let (mut up, mut down) = (Vec::new(), Vec::new());
    let (mut waited, mut drain) = (Vec::new(), Vec::new());
    for _ in 0..a.rounds {
        up.extend(scan(&socket, "broker-up").await.1);
        drained(&socket).await;
        broker.stop();
        wait_status(&socket, "the link down", |s| {
            s.links.get("mqtt").is_some_and(|l| !l.ok)
        })
        .await;
        let (_, p) = scan(&socket, "broker-down").await;
        down.extend(p);
        let l = link(&socket).await.expect("the link's status");
        assert!(!l.ok, "the broker is stopped, yet the link says {l:?}");
        waited.push(l.queued);
        broker.start();
        drain.push(drained(&socket).await);
    }
    let (med0, mean0) = summary("broker up", &up);
    let (med1, mean1) = summary("broker down", &down);
    println!(
        "  difference with the broker down: median {:+.1} ms ({:+.1} %), mean {:+.1} ms ({:+.1} %)",
        med1 - med0,
        (med1 - med0) / med0 * 100.0,
        mean1 - mean0,
        (mean1 - mean0) / mean0 * 100.0
    );
    for (k, (n, t)) in waited.iter().zip(&drain).enumerate() {
        println!(
            "  round {}: {n} messages waited in the outbox at the scan's end; delivered {:.2} s after the broker was back",
            k + 1,
            t.as_secs_f64()
        );
    }
    d.stop();
    broker.stop();
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
