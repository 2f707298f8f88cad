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
#[path = "shared/station.rs"]
mod station;

use station::{free_port, scan, status, summary, wait_status, Daemon};
use std::net::SocketAddr;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use surfscan::cli::demo::demo_socket;
use surfscan::scan::status::State;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

const TOKEN: &str = "bench-page-token-0b6f41d2c9";

struct Args {
    lines: usize,
    pages: usize,
    rounds: usize,
    speed_up: f64,
}

fn args() -> Args {
    let (lines, pages, rounds) = if shared::full_run() {
        (16, 100, 3)
    } else {
        (6, 5, 1)
    };
    let number =
        |name: &str, default: usize| shared::number_arg(name).map_or(default, |v| v as usize);
    Args {
        lines: number("--lines", lines).clamp(3, 200),
        pages: number("--pages", pages).min(250),
        rounds: number("--rounds", rounds).clamp(1, 20),
        speed_up: shared::number_arg("--speed-up").unwrap_or(50.0),
    }
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

fn config(dir: &Path, inst: &Path, stage: &Path, lines: usize) -> (PathBuf, PathBuf, SocketAddr) {
    let out = dir.join("scans");
    let tokens = dir.join("web-tokens");
    std::fs::write(&tokens, format!("bench {TOKEN}\n")).expect("token file");
    std::fs::set_permissions(&tokens, std::fs::Permissions::from_mode(0o600)).expect("mode");
    let addr: SocketAddr = format!("127.0.0.1:{}", free_port())
        .parse()
        .expect("address");
    let text = shared::demo_config(inst, stage, &out, lines);
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
    let (sim, inst, stage) = station::simulator(tmp.path(), a.speed_up).await;
    let (cfg, out, addr) = config(tmp.path(), &inst, &stage, a.lines);
    let socket = demo_socket(&out);
    let d = Daemon::spawn(&cfg);
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
        alone.extend(scan(&socket, "no-page").await.1);
        let bytes: Vec<Arc<AtomicU64>> = (0..a.pages).map(|_| Arc::default()).collect();
        let mut pages = Vec::new();
        for b in &bytes {
            pages.push(open_page(addr, b.clone()).await);
        }
        let before: u64 = bytes.iter().map(|b| b.load(Ordering::Relaxed)).sum();
        watched.extend(scan(&socket, "pages").await.1);
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
    d.stop();
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
