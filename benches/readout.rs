//! Profile read-out at the wire limit: an 8000-point profile read by the real SJ-210 client
//! (`RDEVA00` total, then 160 blocks of `RDEVA50`) from the simulator over a pseudo-terminal,
//! paced at 38400 baud in real time, against the time its bytes need on the wire (10 bits per
//! byte, both directions: every command and every reply).
//!
//! `cargo bench --bench readout` prints the figures; the target is a read-out that takes at
//! most 1.05 × the wire time. Without `--bench` (as `cargo test --all-targets` runs it) it
//! reads a 500-point profile at a hundredth of the pacing, only to check that it runs.
//! `-- --baud B` and `-- --points N` change the link speed and the profile length.

#[path = "shared/mod.rs"]
mod shared;

use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use surfscan::sj210::client::Sj210Client;
use surfscan::sj210::models::{CommandOverrides, ModelId, ModelTable};
use surfscan::sj210::settings::ClientOptions;
use surfscan::transport::{FlowControl, Parity, SerialSettings};
use surfscan_sim::data::ServedProfile;
use surfscan_sim::instrument::Conditions;
use surfscan_sim::{InstrumentConfig, ProfileSet, SimEvent, Simulator};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// Counts the bytes that cross a stream in each direction.
struct Counting<S> {
    inner: S,
    tx: Arc<AtomicU64>,
    rx: Arc<AtomicU64>,
}

impl<S: AsyncRead + Unpin> AsyncRead for Counting<S> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        let r = Pin::new(&mut self.inner).poll_read(cx, buf);
        let n = buf.filled().len() - before;
        self.rx.fetch_add(n as u64, Ordering::Relaxed);
        r
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Counting<S> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write(cx, buf);
        if let Poll::Ready(Ok(n)) = &r {
            self.tx.fetch_add(*n as u64, Ordering::Relaxed);
        }
        r
    }
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }
    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

struct Figures {
    points: usize,
    exchanges: u64,
    tx: u64,
    rx: u64,
    wire_s: f64,
    took_s: f64,
}

async fn read_out(points: usize, baud: u32, pacing: f64) -> Figures {
    let dir = tempfile::tempdir().expect("temp dir");
    let link = dir.path().join("sj210");
    let served = shared::rough_heights_um(points);
    let set = ProfileSet::new(vec![ServedProfile {
        y_mm: 0.0,
        pitch_x_mm: 0.0005,
        z_um: served.clone(),
    }])
    .expect("profile");
    // λc 0.8 mm × 5 at 0.5 µm: 8000 points, as the conditions give; the trace itself runs at
    // a hundred times its speed (only the read-out is measured).
    let cfg = InstrumentConfig {
        time_scale: 0.01,
        conditions: Conditions {
            lambda_c_code: 2,
            sampling_lengths: (points / 1600).clamp(1, 10) as u8,
            ..Conditions::default()
        },
        ..InstrumentConfig::default()
    };
    let mut sim = Simulator::new(&link)
        .instrument(cfg)
        .profiles(set)
        .baud(baud)
        .pacing_time_scale(pacing)
        .start()
        .expect("simulator starts");
    match tokio::time::timeout(Duration::from_secs(10), sim.next_event()).await {
        Ok(Some(SimEvent::Ready(_))) => {}
        other => panic!("simulator not ready: {other:?}"),
    }
    let port = surfscan::transport::open(&SerialSettings {
        path: link.display().to_string(),
        baud,
        parity: Parity::None,
        flow_control: FlowControl::None,
    })
    .expect("pty opens");
    let (tx, rx) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let io = Counting {
        inner: port,
        tx: Arc::clone(&tx),
        rx: Arc::clone(&rx),
    };
    let table = ModelTable::with_overrides(
        ModelId::Sj210,
        &CommandOverrides {
            profile_total: Some("RDEVA00".into()),
            profile_block: Some("RDEVA{n}".into()),
            ..CommandOverrides::default()
        },
    )
    .expect("table");
    let opts = ClientOptions {
        poll_interval: Duration::from_millis(5),
        trace_deadline: Some(Duration::from_secs(30)),
        ..ClientOptions::default()
    };
    let mut client = Sj210Client::new(io, table, opts);
    client.run_trace().await.expect("trace");
    tx.store(0, Ordering::Relaxed);
    rx.store(0, Ordering::Relaxed);
    let mut warnings = Vec::new();
    let t0 = Instant::now();
    let pass = client.read_profile(&mut warnings).await.expect("read-out");
    let took_s = t0.elapsed().as_secs_f64();
    assert_eq!(
        pass.heights_um, served,
        "the read-out must be the served profile"
    );
    assert!(warnings.is_empty(), "{warnings:?}");
    drop(client);
    sim.shutdown().await;
    let (tx, rx) = (tx.load(Ordering::Relaxed), rx.load(Ordering::Relaxed));
    Figures {
        points,
        exchanges: 1 + points.div_ceil(50) as u64,
        tx,
        rx,
        wire_s: (tx + rx) as f64 * 10.0 / f64::from(baud) * pacing,
        took_s,
    }
}

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let full = std::env::args().any(|a| a == "--bench");
    let baud: u32 = arg("--baud").and_then(|b| b.parse().ok()).unwrap_or(38400);
    let points: usize = arg("--points")
        .and_then(|p| p.parse().ok())
        .unwrap_or(if full { 8000 } else { 500 });
    let pacing = if full { 1.0 } else { 0.01 };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    let f = rt.block_on(read_out(points, baud, pacing));
    let ratio = f.took_s / f.wire_s;
    println!(
        "read-out of {} heights at {baud} baud (pacing x{pacing}): {} exchanges, {} bytes to the instrument, {} from it",
        f.points, f.exchanges, f.tx, f.rx
    );
    // At a hundredth of the pacing the fixed cost per exchange dominates: the ratio is
    // judged only at real pacing.
    let verdict = match (full, ratio <= 1.05) {
        (false, _) => "not judged without --bench",
        (true, true) => "met",
        (true, false) => "MISSED",
    };
    println!(
        "wire time {:.3} s, read-out took {:.3} s: {ratio:.4} x the wire time ({:.2} ms per exchange beyond it); target <= 1.05: {verdict}",
        f.wire_s,
        f.took_s,
        (f.took_s - f.wire_s) / f.exchanges as f64 * 1e3,
    );
}
