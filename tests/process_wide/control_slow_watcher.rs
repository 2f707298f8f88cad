//! A watcher that never reads is dropped, not buffered for, while another watcher keeps
//! receiving. Its own test binary, because it measures this process's resident memory.

use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use std::os::fd::AsFd;
use std::time::{Duration, Instant};
use surfscan::control::protocol::ControlChannels;
use surfscan::control::server::{self, ServerOptions};
use surfscan::scan::command::OperatorRequest;
use surfscan::scan::status::{State, Status};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::sync::{mpsc, oneshot, watch};

/// Resident set size of this process, KiB.
fn rss_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap()
}

/// Whether the peer has closed `sock`, without reading any of the data queued on it.
fn peer_closed(sock: &std::os::unix::net::UnixStream) -> bool {
    let mut fds = [PollFd::new(sock.as_fd(), PollFlags::empty())];
    poll(&mut fds, PollTimeout::ZERO).unwrap();
    fds[0]
        .revents()
        .is_some_and(|r| r.contains(PollFlags::POLLHUP))
}

// The guard is held across awaits on purpose: no other test of this binary may allocate while
// this one measures resident memory, and nothing inside this test contends for it.
#[allow(clippy::await_holding_lock)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_watcher_that_never_reads_is_dropped_and_another_keeps_receiving() {
    let _memory = crate::process_state();
    // Each snapshot carries 32 KiB of reason text, so a server that queued every change for
    // the stuck watcher would hold 5000 × 32 KiB ≈ 160 MiB.
    const CHANGES: u32 = 5000;
    let reason = "r".repeat(32 * 1024);
    let mut initial = Status::idle();
    initial.state = State::Scanning;
    initial.scan_id = Some("W".into());
    initial.lines_total = CHANGES;
    initial.reason = Some(reason.clone());
    let (status_tx, status_rx) = watch::channel(initial);
    let (cmd_tx, _cmd_rx) = mpsc::channel::<OperatorRequest>(1);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    let options = ServerOptions {
        write_timeout: Duration::from_millis(200),
        ..ServerOptions::default()
    };
    let server = server::bind_with_options(&path, options).await.unwrap();
    let (stop, stopped) = oneshot::channel::<()>();
    let served = tokio::spawn(server.serve(
        ControlChannels {
            status: status_rx,
            commands: cmd_tx,
            queue: None,
        },
        async {
            let _ = stopped.await;
        },
    ));

    // The stuck watcher: asks to watch, then never reads again.
    let stuck = std::os::unix::net::UnixStream::connect(&path).unwrap();
    {
        use std::io::Write;
        (&stuck).write_all(b"{\"class\":\"watch\"}\n").unwrap();
    }

    // The live watcher reads everything and reports the highest line count seen.
    let (r, mut w) = tokio::net::UnixStream::connect(&path)
        .await
        .unwrap()
        .into_split();
    w.write_all(b"{\"class\":\"watch\"}\n").await.unwrap();
    let (seen_tx, mut seen_rx) = watch::channel(0u32);
    let reader = tokio::spawn(async move {
        let mut lines = BufReader::new(r).lines();
        let mut count = 0u32;
        while let Ok(Some(line)) = lines.next_line().await {
            let v: serde_json::Value = serde_json::from_str(&line).unwrap();
            if v["class"] == "status" {
                count += 1;
                let _ = seen_tx.send(v["lines_done"].as_u64().unwrap() as u32);
            }
        }
        count
    });
    // Both watchers are registered once the live one has its first snapshot.
    tokio::time::timeout(Duration::from_secs(5), seen_rx.changed())
        .await
        .unwrap()
        .unwrap();
    let rss_before = rss_kib();

    let publish = |k: u32| {
        status_tx.send_modify(|s| {
            s.lines_done = k;
            s.reason = Some(reason.clone());
        })
    };

    // Phase 1: changes arrive at about 1 kHz until the stuck watcher's socket buffer is full
    // and a write to it has waited out the bound.
    let t0 = Instant::now();
    let mut k = 0;
    while !peer_closed(&stuck) {
        assert!(
            t0.elapsed() < Duration::from_secs(10) && k < CHANGES / 2,
            "the stuck watcher was not disconnected after {k} changes"
        );
        k += 1;
        publish(k);
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    println!(
        "stuck watcher dropped after {k} changes, {:?}",
        t0.elapsed()
    );

    // Phase 2: after the drop the live watcher still gets every change up to the last.
    for k in k + 1..=CHANGES {
        publish(k);
        tokio::task::yield_now().await;
    }
    tokio::time::timeout(Duration::from_secs(10), seen_rx.wait_for(|&k| k == CHANGES))
        .await
        .expect("the live watcher received the final snapshot")
        .unwrap();
    let rss_after = rss_kib();
    let grown_kib = rss_after.saturating_sub(rss_before);
    println!("rss before {rss_before} KiB, after {rss_after} KiB, grew {grown_kib} KiB");
    assert!(
        grown_kib < 32 * 1024,
        "memory grew by {grown_kib} KiB while a watcher was stuck"
    );

    // What the stuck watcher did get is a prefix of whole snapshots followed by end of stream.
    stuck.set_nonblocking(false).unwrap();
    stuck
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let mut got = Vec::new();
    {
        use std::io::Read;
        (&stuck)
            .read_to_end(&mut got)
            .expect("end of stream, not a read timeout");
    }
    let lines = got.split(|&b| b == b'\n').filter(|l| !l.is_empty()).count();
    assert!(
        (got.len() as u64) < u64::from(CHANGES) * 32 * 1024 / 4,
        "the stuck watcher was sent {} bytes",
        got.len()
    );
    assert!(lines >= 2, "greeting and at least the first snapshot");

    let _ = stop.send(());
    served.await.unwrap();
    let received = reader.await.unwrap();
    assert!(received >= 2, "live watcher saw {received} snapshots");
}
