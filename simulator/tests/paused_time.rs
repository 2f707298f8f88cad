//! The serve loop under tokio's paused clock: the status timeline and serial pacing follow
//! simulated time exactly, over an in-memory duplex stream instead of a pty.

use std::time::Duration;

use surfscan_sim::data::ServedProfile;
use surfscan_sim::fault::FaultPlan;
use surfscan_sim::instrument::Instrument;
use surfscan_sim::server::{serve_connection, Outcome, Pacing, Responder};
use surfscan_sim::{InstrumentConfig, ProfileSet};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::time::Instant;

async fn ask(host: &mut DuplexStream, cmd: &str) -> (String, Duration) {
    let t0 = Instant::now();
    host.write_all(format!("{cmd}\r").as_bytes()).await.unwrap();
    let mut out = Vec::new();
    let mut b = [0u8; 1];
    while !out.ends_with(b"\r") {
        host.read_exact(&mut b).await.unwrap();
        out.push(b[0]);
    }
    (String::from_utf8(out).unwrap(), t0.elapsed())
}

type Served = tokio::task::JoinHandle<std::io::Result<Outcome>>;

/// Serves `inst` at 9600 baud, real pacing, over an in-memory duplex stream; returns the
/// host's end and the serve loop, which ends `Closed` once the host's end is dropped.
fn serve_at_9600(inst: Instrument) -> (DuplexStream, Served) {
    let (host, mut dev) = tokio::io::duplex(4096);
    let epoch = Instant::now();
    let server = tokio::spawn(async move {
        // The stop sender lives as long as the loop, so only the host's drop ends it.
        let (_stop_tx, mut stop) = tokio::sync::watch::channel(false);
        let mut r = Responder::Emulate(Box::new(inst));
        let mut faults = FaultPlan::default();
        let pacing = Pacing {
            baud: 9600,
            time_scale: 1.0,
        };
        serve_connection(
            &mut dev,
            &mut r,
            &mut faults,
            pacing,
            epoch,
            &mut stop,
            None,
        )
        .await
    });
    (host, server)
}

#[tokio::test(start_paused = true)]
async fn timeline_and_pacing_follow_the_clock() {
    // One 2000-point profile at 1 µm pitch: 2 mm + λc 2.5 mm = 4.5 mm traverse:
    // 9 s measuring at 0.5 mm/s, 4.5 s returning at 1 mm/s.
    let set = ProfileSet::new(vec![ServedProfile {
        y_mm: 0.0,
        pitch_x_mm: 0.001,
        z_um: (0..2000)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect(),
    }])
    .unwrap();
    // Results in the manual's right-justified layout.
    let cfg = InstrumentConfig {
        result_layout: surfscan_sim::instrument::ResultLayout::Manual,
        ..InstrumentConfig::default()
    };
    let inst = Instrument::new(cfg, set, None);
    let (mut host, server) = serve_at_9600(inst);

    // "RDSTU00\r" and "OK000\r" are 8 + 6 bytes = 140 bits at 9600 baud = 14.583 ms (tokio
    // timers round up to 1 ms): the command's time on the wire and the reply's.
    let (reply, took) = ask(&mut host, "RDSTU00").await;
    assert_eq!(reply, "OK000\r");
    assert!(
        took >= Duration::from_micros(14_583) && took <= Duration::from_millis(15),
        "{took:?}"
    );
    let (reply, _) = ask(&mut host, "CTSTA").await;
    assert_eq!(reply, "OK\r");
    let started = Instant::now();
    tokio::time::sleep_until(started + Duration::from_millis(8900)).await;
    assert_eq!(ask(&mut host, "RDSTU00").await.0, "OK001\r");
    tokio::time::sleep_until(started + Duration::from_millis(9100)).await;
    assert_eq!(ask(&mut host, "RDSTU00").await.0, "OK002\r");
    tokio::time::sleep_until(started + Duration::from_millis(13600)).await;
    assert_eq!(ask(&mut host, "RDSTU00").await.0, "OK000\r");
    // Square wave ±1: Ra = Rq = 1, Rz = 2.
    assert_eq!(
        ask(&mut host, "RDRES02,03,00").await.0,
        "OKRz      2.000 um\r"
    );

    drop(host);
    assert_eq!(server.await.unwrap().unwrap(), Outcome::Closed);
}

#[tokio::test(start_paused = true)]
async fn many_short_exchanges_run_at_the_baud_rate_not_at_the_timer_tick() {
    // 40 status reads back to back, 14 bytes each at 9600 baud: 14.583 ms of wire each,
    // 583.3 ms in all. A timer rounds each wait up to the next millisecond (15 ms, 600 ms in
    // all when every reply waits its own rounded time); on the wire's timeline the lateness
    // of one reply is taken off the next, so the read-out ends within a tick of the wire
    // time, and no reply comes before the wire time counted from the first command.
    let set = ProfileSet::new(vec![ServedProfile {
        y_mm: 0.0,
        pitch_x_mm: 0.001,
        z_um: vec![0.0; 100],
    }])
    .unwrap();
    let inst = Instrument::new(InstrumentConfig::default(), set, None);
    let (mut host, server) = serve_at_9600(inst);
    let wire = Duration::from_secs_f64(14.0 * 10.0 / 9600.0);
    let t0 = Instant::now();
    for k in 1..=40u32 {
        let (reply, _) = ask(&mut host, "RDSTU00").await;
        assert_eq!(reply, "OK000\r");
        assert!(
            t0.elapsed() >= wire * k,
            "reply {k} after {:?}",
            t0.elapsed()
        );
    }
    let took = t0.elapsed();
    assert!(took <= wire * 40 + Duration::from_millis(1), "{took:?}");
    drop(host);
    assert_eq!(server.await.unwrap().unwrap(), Outcome::Closed);
}
