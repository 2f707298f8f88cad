//! The station's metrics as a lab's monitoring reads them: the `surfscan daemon` binary with
//! `[metrics] listen`, its `/metrics` and its textfile checked by `promtool check metrics`,
//! and a real Prometheus server (Debian package `prometheus`, started on a loopback port)
//! scraping it through a simulated scan and seeing the lines go by.

use crate::common::mosquitto::{on_fresh_ports, port_taken, Killed};
use crate::daemon_e2e::{self as e2e, Rig};
use std::io::{Read as _, Write as _};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use surfscan::scan::ending::StopStatus;
use surfscan::scan::status::State;

/// `GET path` on 127.0.0.1:`port` (HTTP/1.0, so the server closes): status line, headers,
/// body.
fn get(port: u16, path: &str) -> std::io::Result<(String, String, String)> {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    write!(s, "GET {path} HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n")?;
    let mut text = String::new();
    s.read_to_string(&mut text)?;
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let (status, headers) = head.split_once("\r\n").unwrap_or((head, ""));
    Ok((
        status.to_owned(),
        headers.to_ascii_lowercase(),
        body.to_owned(),
    ))
}

/// Percent-encodes a query value.
fn encode(v: &str) -> String {
    v.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// `promtool check metrics` of `text`: its exit status and what it said.
fn promtool(text: &str) -> (bool, String) {
    let mut c = Command::new("promtool")
        .args(["check", "metrics"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("promtool is not installed: `bash .ci/run` installs the Debian package prometheus");
    c.stdin.take().unwrap().write_all(text.as_bytes()).unwrap();
    let o = c.wait_with_output().unwrap();
    (
        o.status.success(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        ),
    )
}

/// `[metrics] listen` on 127.0.0.1:`port`; 0 lets the system pick a free port, which the
/// daemon's log names ([`metrics_port`]): a port picked here and let go could be taken by
/// another process before the daemon binds it.
fn with_listen(r: &Rig, port: u16) {
    crate::common::edit_file(
        &r.config,
        "[metrics]\n",
        &format!("[metrics]\nlisten = \"127.0.0.1:{port}\"\n"),
    );
}

/// The port the daemon serves `/metrics` on, as its log names it once it is bound.
fn metrics_port(r: &Rig) -> u16 {
    e2e::logged_address(r, "metrics on http://").port()
}

/// A Prometheus server scraping 127.0.0.1:`target` every 250 ms; its own port returned.
fn prometheus(r: &Rig, target: u16) -> (Killed, u16) {
    let dir = r.dir.path().join("prometheus");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("prometheus.yml"),
        format!(
            "global:\n  scrape_interval: 250ms\n  scrape_timeout: 200ms\nscrape_configs:\n  - job_name: surfscan\n    static_configs:\n      - targets: ['127.0.0.1:{target}']\n"
        ),
    )
    .unwrap();
    // Prometheus exits naming a port another process took first.
    on_fresh_ports("prometheus", |[port]| {
        launch_prometheus(&dir, port).map(|child| (child, port))
    })
}

/// Starts Prometheus with `dir`'s configuration on `port` and waits until it is ready; `Err`
/// with its log when it exits first.
fn launch_prometheus(dir: &std::path::Path, port: u16) -> Result<Killed, String> {
    let child = Command::new("prometheus")
        .arg(format!(
            "--config.file={}",
            dir.join("prometheus.yml").display()
        ))
        .arg(format!(
            "--storage.tsdb.path={}",
            dir.join("data").display()
        ))
        .arg(format!("--web.listen-address=127.0.0.1:{port}"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("prometheus.log")).unwrap())
        .spawn()
        .expect(
            "prometheus is not installed: `bash .ci/run` installs the Debian package prometheus",
        );
    let mut child = Killed(child);
    let start = Instant::now();
    loop {
        if let Ok((status, _, _)) = get(port, "/-/ready") {
            if status.contains(" 200 ") {
                break;
            }
        }
        if let Some(st) = child.0.try_wait().unwrap() {
            let said = std::fs::read_to_string(dir.join("prometheus.log")).unwrap_or_default();
            if port_taken(&said) {
                return Err(said);
            }
            panic!("prometheus exited ({st}): {said}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "prometheus is not ready"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(child)
}

/// The samples Prometheus holds for `series` over the last ten minutes.
fn samples(port: u16, series: &str) -> Vec<f64> {
    let (status, _, body) = get(
        port,
        &format!("/api/v1/query?query={}", encode(&format!("{series}[10m]"))),
    )
    .unwrap();
    assert!(status.contains(" 200 "), "{status}: {body}");
    let v: serde_json::Value = serde_json::from_str(&body).unwrap();
    v["data"]["result"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r["values"].as_array().unwrap().clone())
        .map(|p| p[1].as_str().unwrap().parse().unwrap())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_real_prometheus_scrapes_the_station_and_sees_the_scan_progress() {
    let r = e2e::rig().await;
    with_listen(&r, 0);
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    let port = metrics_port(&r);
    // Served before any scan, in a form promtool accepts.
    let (status, headers, body) = get(port, "/metrics").unwrap();
    assert!(status.contains(" 200 "), "{status}");
    assert!(
        headers.contains("content-type: text/plain; version=0.0.4"),
        "{headers}"
    );
    assert!(
        body.contains("surfscan_state{state=\"idle\"} 1\n"),
        "{body}"
    );
    let (ok, said) = promtool(&body);
    assert!(
        ok,
        "promtool check metrics refused /metrics: {said}\n{body}"
    );
    let (status, _, _) = get(port, "/other").unwrap();
    assert!(status.contains(" 404 "), "{status}");

    let (_prom, prom_port) = prometheus(&r, port);
    // Prometheus sees the target up before the scan starts.
    let start = Instant::now();
    while samples(prom_port, "up").last() != Some(&1.0) {
        assert!(
            start.elapsed() < e2e::DEADLINE,
            "prometheus never scraped the station"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    e2e::start_scan(&r, "prom-1").await;
    let ended = e2e::wait_status(&r, "scan ended", |s| {
        s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    assert_eq!(ended.last_stop.unwrap().status, StopStatus::Success);
    // Wait for a scrape after the scan's end (one every 250 ms, later on a loaded machine),
    // then ask what it saw of the lines.
    let total = f64::from(e2e::LINES);
    let start = Instant::now();
    let done = loop {
        let done = samples(prom_port, "surfscan_lines_done{scan!=\"\"}");
        if done.last() == Some(&total) || start.elapsed() > e2e::DEADLINE {
            break done;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(done.last(), Some(&total), "{done:?}");
    assert!(
        done.iter().any(|v| *v > 0.0 && *v < total),
        "no scrape saw the scan part-way: {done:?}"
    );
    assert!(
        done.windows(2).all(|w| w[0] <= w[1]),
        "lines done went backwards: {done:?}"
    );
    let scanning = samples(prom_port, "surfscan_state{state=\"scanning\"}");
    assert!(scanning.contains(&1.0), "{scanning:?}");

    // The textfile of the same scan passes promtool too.
    let file = std::fs::read_to_string(r.dir.path().join("surfscan.prom")).unwrap();
    let (ok, said) = promtool(&file);
    assert!(
        ok,
        "promtool check metrics refused the textfile: {said}\n{file}"
    );
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

#[test]
fn a_listen_address_that_is_no_address_exits_78_naming_the_key() {
    crate::common::assert_tables_refused(
        "metrics",
        &[("listen = \"localhost\"", "metrics.listen")],
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_port_already_in_use_is_named_in_the_status_and_the_station_scans_on() {
    let r = e2e::rig().await;
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    with_listen(&r, port);
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    let s = e2e::wait_status(&r, "the metrics link named", |s| {
        s.links.contains_key("metrics")
    })
    .await;
    let link = &s.links["metrics"];
    assert!(!link.ok, "{link:?}");
    assert!(
        link.message.contains(&format!("127.0.0.1:{port}"))
            && link.message.contains("[metrics] listen"),
        "{link:?}"
    );
    e2e::start_scan(&r, "prom-2").await;
    let ended = e2e::wait_status(&r, "scan ended", |s| {
        s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    assert_eq!(ended.last_stop.unwrap().status, StopStatus::Success);
    let log = std::fs::read_to_string(r.dir.path().join("daemon.log")).unwrap();
    assert!(log.contains("cannot serve /metrics"), "{log}");
    drop(taken);
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_never_finishes_its_request_is_closed_and_others_are_still_served() {
    let r = e2e::rig().await;
    with_listen(&r, 0);
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    let port = metrics_port(&r);
    let start = Instant::now();
    while get(port, "/metrics").is_err() {
        assert!(start.elapsed() < e2e::DEADLINE, "/metrics never answered");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // Half a request line, then nothing: the server must hang up on its own.
    let mut idle = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    idle.write_all(b"GET /metr").unwrap();
    let silent = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    for s in [&idle, &silent] {
        s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    }
    // Meanwhile a scraper is served.
    let (status, _, body) = get(port, "/metrics").unwrap();
    assert!(status.contains("200"), "{status}");
    assert!(body.contains("surfscan_"), "{body}");
    for (what, mut s) in [("half a request", idle), ("nothing", silent)] {
        let mut rest = Vec::new();
        match s.read_to_end(&mut rest) {
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => {}
            Err(e) => panic!("a client that sent {what} was not closed within 60 s: {e}"),
        }
    }
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}
