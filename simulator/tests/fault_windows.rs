//! Time-window faults through the serve loop under tokio's paused clock: a busy instrument
//! for a window, replies and chatter without line ends, a flood of stray replies — each
//! opens at its trigger frame and closes on time, after which the instrument answers
//! normally again.

use std::time::Duration;

use surfscan_sim::fault::{FaultPlan, FaultSpec, NOEOL_FILLER, STRAY_REPLIES};
use surfscan_sim::instrument::Instrument;
use surfscan_sim::server::{serve_connection, Outcome, Pacing, Responder};
use surfscan_sim::{Fault, InstrumentConfig, ProfileSet};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::task::JoinHandle;
use tokio::time::Instant;

fn wire(s: &str) -> Fault {
    match s.parse::<FaultSpec>() {
        Ok(FaultSpec::Wire(f)) => f,
        other => panic!("{s}: {other:?}"),
    }
}

/// The serve loop over a duplex stream with `faults`, no pacing.
fn serve(faults: &[&str]) -> (DuplexStream, JoinHandle<std::io::Result<Outcome>>) {
    let set = ProfileSet::bundled().expect("bundled profiles");
    let inst = Instrument::new(InstrumentConfig::default(), set, None);
    let (host, mut dev) = tokio::io::duplex(1 << 16);
    let mut plan = FaultPlan::new(faults.iter().map(|s| wire(s)).collect());
    let epoch = Instant::now();
    let task = tokio::spawn(async move {
        let (_stop_tx, mut stop) = tokio::sync::watch::channel(false);
        let mut r = Responder::Emulate(Box::new(inst));
        let pacing = Pacing {
            baud: 0,
            time_scale: 0.0,
        };
        serve_connection(&mut dev, &mut r, &mut plan, pacing, epoch, &mut stop, None).await
    });
    (host, task)
}

/// Sends `cmd` and returns everything that arrives within `wait`.
async fn exchange(host: &mut DuplexStream, cmd: &str, wait: Duration) -> Vec<u8> {
    host.write_all(format!("{cmd}\r").as_bytes()).await.unwrap();
    collect(host, wait).await
}

/// Everything that arrives within `wait`.
async fn collect(host: &mut DuplexStream, wait: Duration) -> Vec<u8> {
    let deadline = Instant::now() + wait;
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    while let Ok(r) = tokio::time::timeout_at(deadline, host.read(&mut buf)).await {
        let n = r.unwrap();
        if n == 0 {
            break;
        }
        out.extend_from_slice(&buf[..n]);
    }
    out
}

const MS: fn(u64) -> Duration = Duration::from_millis;

#[tokio::test(start_paused = true)]
async fn a_busy_window_refuses_everything_until_it_closes() {
    let (mut host, task) = serve(&["busy:15000@RDSTU#2"]);
    assert_eq!(exchange(&mut host, "RDSTU00", MS(10)).await, b"OK000\r");
    let opened = Instant::now();
    assert_eq!(exchange(&mut host, "RDSTU00", MS(10)).await, b"NG011\r");
    for cmd in ["CTSTA", "RDRES02,01,00", "RDSTU00"] {
        assert_eq!(exchange(&mut host, cmd, MS(10)).await, b"NG011\r", "{cmd}");
    }
    tokio::time::sleep_until(opened + MS(14_900)).await;
    assert_eq!(exchange(&mut host, "RDSTU00", MS(10)).await, b"NG011\r");
    tokio::time::sleep_until(opened + MS(15_001)).await;
    // The instrument never saw the refused CTSTA: idle, and it starts a trace now.
    assert_eq!(exchange(&mut host, "RDSTU00", MS(10)).await, b"OK000\r");
    assert_eq!(exchange(&mut host, "CTSTA", MS(10)).await, b"OK\r");
    drop(host);
    assert_eq!(task.await.unwrap().unwrap(), Outcome::Closed);
}

#[tokio::test(start_paused = true)]
async fn a_noeol_window_sends_bytes_without_a_line_end_for_its_length() {
    let (mut host, task) = serve(&["noeol:1000@RDSTU"]);
    // The trigger's own reply comes without its CR, then filler flows.
    let got = exchange(&mut host, "RDSTU00", MS(500)).await;
    assert!(got.starts_with(b"OK000"), "{got:?}");
    assert!(!got.contains(&b'\r') && !got.contains(&b'\n'), "{got:?}");
    let fillers = got.len().saturating_sub(5) / NOEOL_FILLER.len();
    assert!((20..=26).contains(&fillers), "{fillers} fillers in 500 ms");
    // Frames sent during the window are answered, without line end.
    let got = exchange(&mut host, "RDSTU00", MS(400)).await;
    assert!(got.windows(5).any(|w| w == b"OK000"), "{got:?}");
    assert!(!got.contains(&b'\r'), "{got:?}");
    // After 1 s the line is quiet and replies end with CR again.
    let _ = collect(&mut host, MS(200)).await;
    assert!(collect(&mut host, MS(200)).await.is_empty());
    assert_eq!(exchange(&mut host, "RDSTU00", MS(10)).await, b"OK000\r");
    drop(host);
    assert_eq!(task.await.unwrap().unwrap(), Outcome::Closed);
}

#[tokio::test(start_paused = true)]
async fn a_flood_window_sends_stray_replies_beside_the_real_ones() {
    let (mut host, task) = serve(&["flood:1000@CTSTA"]);
    assert_eq!(exchange(&mut host, "CTSTA", MS(1)).await, b"OK\r");
    // Polled every 5 ms, as a client does: the strays keep their own cadence.
    let mut got = Vec::new();
    for _ in 0..100 {
        got.extend(exchange(&mut host, "RDSTU00", MS(5)).await);
    }
    let lines: Vec<&[u8]> = got
        .split(|&b| b == b'\r')
        .filter(|l| !l.is_empty())
        .collect();
    let status = lines.iter().filter(|l| l.starts_with(b"OK00")).count();
    let strays = lines.len() - status;
    assert_eq!(status, 100, "every poll answered");
    assert!(
        (22..=26).contains(&strays),
        "{strays} stray lines in 500 ms"
    );
    for l in &lines {
        let line = [*l, b"\r"].concat();
        assert!(
            l.starts_with(b"OK00") || STRAY_REPLIES.contains(&line.as_slice()),
            "{:?}",
            String::from_utf8_lossy(l)
        );
    }
    // Closed after 1 s: nothing unsolicited any more.
    tokio::time::sleep(MS(600)).await;
    let _ = collect(&mut host, MS(1)).await;
    assert!(collect(&mut host, MS(300)).await.is_empty());
    drop(host);
    assert_eq!(task.await.unwrap().unwrap(), Outcome::Closed);
}
