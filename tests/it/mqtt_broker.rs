//! The station on a real Mosquitto broker: the `surfscan daemon` binary against the
//! simulator, publishing to a broker the test starts (password file and ACL), watched by
//! `mosquitto_sub` as an independent subscriber. What a lab relies on: every event of a scan
//! arrives once (by id) and in order, also when the broker was down for part of the scan,
//! absent when the daemon started, or when the daemon was killed before it could deliver;
//! the retained status and `online` say where the station is; a completed scan's results
//! (recipe, specimen, verdict, each parameter's mean, s and U, the files with their SHA-256)
//! arrive once after its success event, checked against report.json and `sha256sum`; a wrong
//! password, and a broker certificate that does not verify, are named in the status and
//! the log; and none of it touches the scan.

use crate::common::append_config;
use crate::common::mosquitto::{self, Broker, Seen};
use crate::daemon_e2e::{self as e2e, log_path, Daemon, Rig};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;
use surfscan::scan::ending::StopStatus;
use surfscan::scan::journal::Record;
use surfscan::scan::status::{State, Status};

pub(crate) const STATION: &str = "st-1";

/// Adds `[mqtt]` for `url` to the rig's configuration, with `password` in its file.
pub(crate) fn with_mqtt(r: &Rig, url: &str, password: &str) {
    let pw = r.dir.path().join("mqtt.pw");
    std::fs::write(&pw, format!("{password}\n")).unwrap();
    append_config(
        &r.config,
        &format!(
            "\n[mqtt]\nurl = {url:?}\nstation = {STATION:?}\nusername = {:?}\npassword-file = {:?}\n",
            mosquitto::STATION_USER,
            pw.display().to_string()
        ),
    );
}

/// The daemon with its log in `daemon.log` of the rig's directory.
pub(crate) fn spawn_logged(r: &Rig) -> Daemon {
    Daemon(
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["daemon", "--config"])
            .arg(&r.config)
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(crate::common::appending(&log_path(r)))
            .spawn()
            .unwrap(),
    )
}

pub(crate) async fn wait_socket(r: &Rig) {
    let start = std::time::Instant::now();
    while surfscan::control::client::ControlClient::connect(&r.socket)
        .await
        .is_err()
    {
        assert!(start.elapsed() < e2e::DEADLINE, "the daemon never listened");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn topic(leaf: &str) -> String {
    format!("surfscan/{STATION}/{leaf}")
}

/// The events seen, each id once (a QoS 1 redelivery may repeat one), in arrival order.
fn events(seen: &[Seen]) -> Vec<serde_json::Value> {
    let mut ids = std::collections::HashSet::new();
    seen.iter()
        .filter(|m| m.topic == topic("events"))
        .map(Seen::json)
        .filter(|e| ids.insert(e["id"].as_str().unwrap().to_owned()))
        .collect()
}

fn kinds(events: &[serde_json::Value]) -> Vec<String> {
    events
        .iter()
        .map(|e| e["kind"].as_str().unwrap().to_owned())
        .collect()
}

/// Where the message with `e`'s id first arrived among everything `seen`.
fn arrival(seen: &[Seen], e: &serde_json::Value) -> usize {
    seen.iter()
        .position(|m| {
            serde_json::from_str::<serde_json::Value>(&m.payload).is_ok_and(|v| v["id"] == e["id"])
        })
        .unwrap_or_else(|| panic!("{e} never arrived"))
}

/// Asserts `e`'s id is `<station>/<scan id>/<kind>/<time>` with the time its `time` member
/// gives to the millisecond: made from what it reports, as docs/integration.md says.
fn assert_id_names(e: &serde_json::Value, kind: &str) {
    let id = e["id"].as_str().unwrap();
    let head = format!("{STATION}/{}/{kind}/", e["scan_id"].as_str().unwrap());
    let time = e["time"].as_str().unwrap();
    let rest = id
        .strip_prefix(&head)
        .unwrap_or_else(|| panic!("id {id:?} is not {head}<time>"));
    assert_eq!(
        (rest.len(), &rest[..23], rest.ends_with('Z')),
        (27, &time[..23], true),
        "id {id:?}, time {time:?}"
    );
}

fn has_kind(seen: &[Seen], kind: &str) -> bool {
    kinds(&events(seen)).iter().any(|k| k == kind)
}

/// Asserts the scan's events arrived complete and in order: started first, success last,
/// nothing in between but suspensions and resumptions, times in arrival order, each event
/// naming the scan.
fn assert_complete_in_order(events: &[serde_json::Value], scan_id: &str) {
    let k = kinds(events);
    assert_eq!(
        k.first().map(String::as_str),
        Some("started"),
        "{events:#?}"
    );
    assert_eq!(k.last().map(String::as_str), Some("success"), "{events:#?}");
    assert!(
        k[1..k.len() - 1]
            .iter()
            .all(|k| k == "suspended" || k == "resumed"),
        "{k:?}"
    );
    let times: Vec<&str> = events.iter().map(|e| e["time"].as_str().unwrap()).collect();
    assert!(
        times.windows(2).all(|w| w[0] <= w[1]),
        "events out of order: {times:?}"
    );
    for e in events {
        assert_id_names(e, e["kind"].as_str().unwrap());
        assert_eq!(e["scan_id"], scan_id, "{e}");
        assert!(e["time"].as_str().unwrap().ends_with('Z'), "{e}");
        assert!(!e["reason"].as_str().unwrap().is_empty(), "{e}");
    }
}

fn outbox_files(r: &Rig) -> usize {
    std::fs::read_dir(r.out().join("outbox").join("mqtt"))
        .map(|d| {
            d.filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .ends_with(".json")
            })
            .count()
        })
        .unwrap_or(0)
}

async fn scan_to_success(r: &Rig, specimen: &str) -> Status {
    e2e::start_scan(r, specimen).await;
    e2e::wait_status(r, "scan ended", |s| {
        s.state == State::Idle && s.last_stop.is_some()
    })
    .await
}

fn line_seconds(dir: &Path) -> Vec<f64> {
    let times: Vec<chrono::DateTime<chrono::Utc>> = e2e::records(dir)
        .iter()
        .filter_map(|r| match r {
            Record::Line(l) => Some(l.time),
            _ => None,
        })
        .collect();
    times
        .windows(2)
        .map(|w| (w[1] - w[0]).num_milliseconds() as f64 / 1000.0)
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_is_seen_by_a_subscriber_with_its_status_events_and_last_will() {
    let r = e2e::rig().await;
    let broker = Broker::start(r.dir.path());
    with_mqtt(&r, &broker.url(), mosquitto::STATION_PASSWORD);
    let out = r.dir.path().join("sub.txt");
    let _sub = broker.subscribe("watcher-a", &out);
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    mosquitto::wait_seen(&out, "online", |s| {
        s.iter()
            .any(|m| m.topic == topic("online") && m.payload == "online")
    })
    .await;
    let ended = scan_to_success(&r, "mqtt-1").await;
    let stop = ended.last_stop.unwrap();
    assert_eq!(stop.status, StopStatus::Success, "{}", stop.reason);
    let seen = mosquitto::wait_seen(&out, "success event", |s| has_kind(s, "success")).await;
    let ev = events(&seen);
    assert_complete_in_order(&ev, &stop.scan_id);
    assert_eq!(kinds(&ev), ["started", "success"]);
    // The status: retained, the same fields as `surfscan status --json`; it showed the scan
    // running and, once the scan ended, its ending.
    let statuses: Vec<serde_json::Value> = seen
        .iter()
        .filter(|m| m.topic == topic("status"))
        .map(Seen::json)
        .collect();
    assert!(
        statuses
            .iter()
            .any(|s| s["state"] == "scanning" && s["scan_id"] == stop.scan_id.as_str()),
        "{statuses:#?}"
    );
    let last = mosquitto::wait_seen(&out, "idle status", |s| {
        s.iter()
            .rev()
            .find(|m| m.topic == topic("status"))
            .is_some_and(|m| {
                let v = m.json();
                v["state"] == "idle" && v["last_stop"]["status"] == "success"
            })
    })
    .await;
    let status_msg = last
        .iter()
        .rev()
        .find(|m| m.topic == topic("status"))
        .unwrap()
        .json();
    let parsed: Status = serde_json::from_value(status_msg.clone()).unwrap();
    assert_eq!(parsed.last_stop.unwrap().scan_id, stop.scan_id);
    assert_eq!(status_msg["station"], STATION);
    assert_eq!(status_msg["links"]["mqtt"]["ok"], true, "{status_msg}");
    // Nothing is left to deliver: the outbox drains (a message written just after the last
    // status, such as a later status or event, may still be on its way at this instant).
    let until = std::time::Instant::now() + e2e::DEADLINE;
    while outbox_files(&r) != 0 && std::time::Instant::now() < until {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(outbox_files(&r), 0);
    // A new subscriber gets the retained status and online at once.
    let late = r.dir.path().join("late.txt");
    let _late = broker.subscribe("watcher-late", &late);
    let s = mosquitto::wait_seen(&late, "retained", |s| {
        s.iter().any(|m| m.topic == topic("status") && m.retained)
            && s.iter().any(|m| m.topic == topic("online") && m.retained)
    })
    .await;
    assert!(
        s.iter().all(|m| m.topic != topic("events")),
        "events are not retained"
    );
    // A clean stop says offline (a clean disconnect sends no last will).
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
    mosquitto::wait_seen(&out, "offline", |s| {
        s.iter()
            .rev()
            .find(|m| m.topic == topic("online"))
            .is_some_and(|m| m.payload == "offline")
    })
    .await;
}

/// A recipe whose limit no turned surface meets: its scan succeeds and does not conform.
const MIRROR: &str = r#"description = "held to a mirror finish"
[plan]
lines = 5
y-step-mm = 0.01
[specification]
limits = ["Ra1 max 0.001"]
"#;

/// The results messages seen, each id once, in arrival order.
fn results(seen: &[Seen]) -> Vec<serde_json::Value> {
    let mut ids = std::collections::HashSet::new();
    seen.iter()
        .filter(|m| m.topic == topic("results"))
        .map(Seen::json)
        .filter(|e| ids.insert(e["id"].as_str().unwrap().to_owned()))
        .collect()
}

/// The SHA-256 of each top-level file of `dir`, by `sha256sum` (not the code under test).
fn sha256sums(dir: &Path) -> Vec<(String, String)> {
    let o = Command::new("sh")
        .arg("-c")
        .arg("find . -maxdepth 1 -type f ! -name '.*' -printf '%P\\0' | sort -z | xargs -0 sha256sum")
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(o.status.success());
    String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let (h, n) = l.split_once("  ").unwrap();
            (n.to_owned(), h.to_owned())
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_completed_scan_s_results_reach_the_subscriber_with_its_verdict_statistics_and_files() {
    let r = e2e::rig().await;
    let broker = Broker::start(r.dir.path());
    with_mqtt(&r, &broker.url(), mosquitto::STATION_PASSWORD);
    let recipes = r.dir.path().join("recipes");
    std::fs::create_dir(&recipes).unwrap();
    std::fs::write(recipes.join("mirror.toml"), MIRROR).unwrap();
    append_config(
        &r.config,
        &format!("\n[jobs]\nrecipes = {:?}\n", recipes.display().to_string()),
    );
    let out = r.dir.path().join("sub.txt");
    let _sub = broker.subscribe("watcher-r", &out);
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    let reply = surfscan::control::client::ControlClient::connect(&r.socket)
        .await
        .unwrap()
        .request(&surfscan::control::protocol::Request::Start {
            specimen: "coupon-7".into(),
            operator: "kim".into(),
            notes: String::new(),
            mode: surfscan::scan::command::StartMode::Auto,
            recipe: Some("mirror".into()),
            y_start_mm: None,
        })
        .await
        .unwrap();
    assert!(
        !matches!(
            reply.message,
            surfscan::control::protocol::Message::Refused { .. }
        ),
        "{reply:?}"
    );
    let ended = e2e::wait_status(&r, "scan ended", |s| {
        s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    let stop = ended.last_stop.unwrap();
    assert_eq!(stop.status, StopStatus::Success, "{}", stop.reason);
    let seen = mosquitto::wait_seen(&out, "results", |s| !results(s).is_empty()).await;
    let res = results(&seen);
    assert_eq!(res.len(), 1, "{res:#?}");
    let m = &res[0];
    // After its success event, in the same outbox order.
    let success = events(&seen)
        .into_iter()
        .find(|e| e["kind"] == "success")
        .expect("a success event before the results");
    assert!(arrival(&seen, m) > arrival(&seen, &success), "{m}");
    assert_id_names(m, "results");
    assert_eq!(m["time"], success["time"]);
    assert_eq!(m["scan_id"], stop.scan_id.as_str());
    assert_eq!(m["station"], STATION);
    assert_eq!(m["recipe"], "mirror");
    assert_eq!(m["specimen"], "coupon-7");
    assert_eq!(m["operator"], "kim");
    assert_eq!(m["verdict"], "does not conform", "{m}");
    assert!(
        m["verdict_summary"]
            .as_str()
            .unwrap()
            .contains("Ra1 max rule"),
        "{m}"
    );
    // Each parameter's mean and s are those of the lines' values in report.json, worked out
    // here; without a stated instrument uncertainty U = 2 s / sqrt(n).
    let dir = PathBuf::from(m["scan_dir"].as_str().unwrap());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    let ra: Vec<f64> = report["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["Ra_um"].as_f64().unwrap())
        .collect();
    assert_eq!(ra.len(), 5);
    let n = ra.len() as f64;
    let mean = ra.iter().sum::<f64>() / n;
    let s = (ra.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let p = m["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["parameter"] == "Ra_um")
        .unwrap_or_else(|| panic!("no Ra_um in {m}"));
    assert_eq!(p["n"], 5);
    let close =
        |a: &serde_json::Value, b: f64| (a.as_f64().unwrap() - b).abs() <= 1e-9 * b.abs().max(1e-6);
    assert!(close(&p["mean"], mean), "{p} vs mean {mean}");
    assert!(close(&p["s"], s), "{p} vs s {s}");
    assert!(
        close(&p["U"], 2.0 * s / n.sqrt()),
        "{p} vs U {}",
        2.0 * s / n.sqrt()
    );
    assert_eq!(m["warnings"], report["warnings"]);
    // The files: every top-level file of the scan directory with the SHA-256 sha256sum gives.
    let listed: Vec<(String, String)> = m["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["name"].as_str().unwrap().to_owned(),
                f["sha256"].as_str().unwrap().to_owned(),
            )
        })
        .collect();
    let want = sha256sums(&dir);
    assert!(want.iter().any(|(n, _)| n == "report.json"), "{want:?}");
    assert_eq!(listed, want);
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_broker_stopped_mid_scan_and_the_daemon_killed_lose_nothing_and_reorder_nothing() {
    let r = e2e::rig().await;
    let mut broker = Broker::start(r.dir.path());
    with_mqtt(&r, &broker.url(), mosquitto::STATION_PASSWORD);
    let out = r.dir.path().join("sub.txt");
    let mut sub = broker.subscribe("watcher-b", &out);
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    mosquitto::wait_seen(&out, "online", |s| {
        s.iter().any(|m| m.topic == topic("online"))
    })
    .await;
    e2e::start_scan(&r, "mqtt-2").await;
    mosquitto::wait_seen(&out, "started", |s| has_kind(s, "started")).await;
    e2e::wait_status(&r, "a line done", |s| s.lines_done >= 1).await;
    broker.stop();
    let stopped_at = e2e::status(&r).await.lines_done;
    // The scan goes on without the broker, and the status says what is wrong.
    let ended = e2e::wait_status(&r, "scan ended", |s| {
        s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    let stop = ended.last_stop.clone().unwrap();
    assert_eq!(stop.status, StopStatus::Success, "{}", stop.reason);
    let link = e2e::wait_status(&r, "link down", |s| {
        s.links.get("mqtt").is_some_and(|l| !l.ok)
    })
    .await
    .links["mqtt"]
        .clone();
    assert!(
        link.message.contains("not listening") || link.message.contains("broke"),
        "{link:?}"
    );
    // The success event waits on disk (stored a moment after the scan's end). The daemon
    // is killed before it could deliver it.
    e2e::wait_status(&r, "the success event in the outbox", |s| {
        s.links.get("mqtt").is_some_and(|l| l.queued >= 1)
    })
    .await;
    assert!(
        outbox_files(&r) >= 1,
        "the success event is not in the outbox"
    );
    d.0.kill().unwrap();
    e2e::wait_exit(&mut d);
    let dir = e2e::scan_dir(&r);
    println!(
        "line periods, s (broker stopped after line {stopped_at}): {:?}",
        line_seconds(&dir)
    );
    broker.restart();
    if sub.0.try_wait().unwrap().is_some() {
        sub = broker.subscribe("watcher-b", &out);
    }
    let mut d = spawn_logged(&r);
    let seen = mosquitto::wait_seen(&out, "success after the restarts", |s| {
        has_kind(s, "success")
    })
    .await;
    assert_complete_in_order(&events(&seen), &stop.scan_id);
    // The scan's results were kept in the outbox with its events: once, after its success.
    let seen = mosquitto::wait_seen(&out, "results after the restarts", |s| {
        !results(s).is_empty()
    })
    .await;
    let res = results(&seen);
    assert_eq!(res.len(), 1, "{res:#?}");
    assert_eq!(res[0]["scan_id"], stop.scan_id.as_str());
    let success = events(&seen)
        .into_iter()
        .find(|e| e["kind"] == "success")
        .unwrap();
    assert!(arrival(&seen, &res[0]) > arrival(&seen, &success));
    let start = std::time::Instant::now();
    while outbox_files(&r) > 0 {
        assert!(start.elapsed() < e2e::DEADLINE, "the outbox is not emptied");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
    drop(sub);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broker_absent_when_the_daemon_starts_gets_the_scan_once_it_is_there() {
    let r = e2e::rig().await;
    let mut broker = Broker::start(r.dir.path());
    broker.stop();
    with_mqtt(&r, &broker.url(), mosquitto::STATION_PASSWORD);
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    let ended = scan_to_success(&r, "mqtt-3").await;
    let stop = ended.last_stop.unwrap();
    assert_eq!(stop.status, StopStatus::Success, "{}", stop.reason);
    // Its events and results wait on disk, and the status says how many.
    let s = e2e::wait_status(&r, "two events and the results queued", |s| {
        s.links.get("mqtt").is_some_and(|l| !l.ok && l.queued >= 3)
    })
    .await;
    assert!(
        s.links["mqtt"].message.contains("not listening"),
        "{:?}",
        s.links
    );
    assert_eq!(outbox_files(&r), 3);
    broker.restart();
    let out = r.dir.path().join("sub.txt");
    // Events are not retained: a subscriber that is there when the broker comes back sees
    // them. The daemon's next try is at most its backoff away.
    let _sub = broker.subscribe("watcher-c", &out);
    let seen = mosquitto::wait_seen(&out, "success", |s| has_kind(s, "success")).await;
    assert_complete_in_order(&events(&seen), &stop.scan_id);
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

/// Runs the daemon until the MQTT link is down with a message containing `status`, then a scan
/// of `specimen` to success, then stops the daemon; its log must contain `logged`. Returns the
/// link's message.
async fn link_fault_named(r: &Rig, status: &str, specimen: &str, logged: &str) -> String {
    let mut d = spawn_logged(r);
    wait_socket(r).await;
    let s = e2e::wait_status(r, &format!("{status} in the status"), |s| {
        s.links
            .get("mqtt")
            .is_some_and(|l| !l.ok && l.message.contains(status))
    })
    .await;
    let message = s.links["mqtt"].message.clone();
    let ended = scan_to_success(r, specimen).await;
    assert_eq!(ended.last_stop.unwrap().status, StopStatus::Success);
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
    let log = std::fs::read_to_string(log_path(r)).unwrap();
    assert!(
        log.contains(logged),
        "the log does not hold {logged:?}: {log}"
    );
    message
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrong_password_is_named_in_the_status_and_the_log_and_the_scan_is_unaffected() {
    let r = e2e::rig().await;
    let broker = Broker::start(r.dir.path());
    with_mqtt(&r, &broker.url(), "not-the-password");
    let message = link_fault_named(
        &r,
        "credentials",
        "mqtt-4",
        "refused the station's credentials",
    )
    .await;
    assert!(message.contains("password-file"), "{message}");
    drop(broker);
}

/// A broker whose certificate chains to no authority the station trusts: named in the status
/// and the log with the setting that fixes it, the scan unaffected. The same broker with its
/// CA in `[mqtt] ca-file` is trusted, so it was the verification that failed, not TLS.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broker_certificate_that_does_not_verify_is_named_and_the_scan_is_unaffected() {
    let r = e2e::rig().await;
    let mut broker = Broker::start(r.dir.path());
    let ca = broker.with_tls();
    let url = format!("mqtts://127.0.0.1:{}", broker.port);
    with_mqtt(&r, &url, mosquitto::STATION_PASSWORD);
    let message = link_fault_named(&r, "TLS", "mqtt-tls", "TLS with").await;
    assert!(message.contains("ca-file"), "{message}");

    crate::common::edit_file(
        &r.config,
        &format!("url = {url:?}\n"),
        &format!("url = {url:?}\nca-file = {:?}\n", ca.display().to_string()),
    );
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    e2e::wait_status(&r, "the link up with the CA trusted", |s| {
        s.links.get("mqtt").is_some_and(|l| l.ok)
    })
    .await;
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

#[test]
fn a_bad_mqtt_table_exits_78_naming_the_key() {
    crate::common::assert_tables_refused(
        "mqtt",
        &[
        ("url = \"http://h\"\nstation = \"a\"", "mqtt.url"),
        ("url = \"mqtt://h\"\nstation = \"a/b\"", "mqtt.station"),
        (
            "url = \"mqtt://h\"\nstation = \"a\"\nusername = \"u\"\npassword-file = \"/nonexistent/pw\"",
            "mqtt.password-file",
        ),
        (
            "url = \"mqtt://h\"\nstation = \"a\"\nca-file = \"/etc/hostname\"",
            "mqtt.ca-file",
        ),
        ("url = \"mqtt://h\"\nstation = \"a\"\noutbox-max = 0", "mqtt.outbox-max"),
        ],
    );
}

/// A proxy between the station and the broker that holds back what the broker sends (its
/// acknowledgements) while `hold` is set; returns its port.
async fn holding_proxy(
    broker_port: u16,
    hold: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> u16 {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    tokio::spawn(async move {
        while let Ok((down, _)) = listener.accept().await {
            let Ok(up) = tokio::net::TcpStream::connect(("127.0.0.1", broker_port)).await else {
                continue;
            };
            let ((mut down_r, mut down_w), (mut up_r, mut up_w)) =
                (down.into_split(), up.into_split());
            tokio::spawn(async move { tokio::io::copy(&mut down_r, &mut up_w).await });
            let hold = hold.clone();
            tokio::spawn(async move {
                let mut buf = vec![0u8; 64 * 1024];
                while let Ok(n @ 1..) = up_r.read(&mut buf).await {
                    while hold.load(std::sync::atomic::Ordering::SeqCst) {
                        tokio::time::sleep(Duration::from_millis(10)).await;
                    }
                    if down_w.write_all(&buf[..n]).await.is_err() {
                        break;
                    }
                }
            });
        }
    });
    port
}

/// A results message the broker has acknowledged is not sent again at the next start when
/// its acknowledgement arrives during a clean stop: the stop waits for it (within its
/// deadline) and removes the message from the outbox. The broker's acknowledgement is held
/// back by a proxy until the stop has begun (the broker has the station's `offline`); after
/// the link has stopped, the outbox is empty (before, the stop ignored the acknowledgement
/// and the message stayed, to be sent again).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_message_acknowledged_during_a_clean_stop_is_not_sent_again() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{Arc, Mutex};
    use surfscan::publish::mqtt::MqttLink;
    use surfscan::publish::outbox::Outbox;
    let tmp = tempfile::tempdir().unwrap();
    let broker = Broker::start(tmp.path());
    let seen_file = tmp.path().join("seen.txt");
    let _watcher = broker.subscribe("watcher-stop", &seen_file);
    let hold = Arc::new(AtomicBool::new(false));
    let port = holding_proxy(broker.port, hold.clone()).await;
    let password = tmp.path().join("password");
    std::fs::write(&password, format!("{}\n", mosquitto::STATION_PASSWORD)).unwrap();
    let settings = toml::from_str(&format!(
        "url = \"mqtt://127.0.0.1:{port}\"\nstation = {STATION:?}\nusername = {:?}\npassword-file = {:?}\n",
        mosquitto::STATION_USER,
        password
    ))
    .unwrap();
    let outbox = Arc::new(Mutex::new(
        Outbox::open(&tmp.path().join("outbox"), 100).unwrap(),
    ));
    let wake = Arc::new(tokio::sync::Notify::new());
    let (status, _status_rx) = tokio::sync::watch::channel(Status::idle());
    let link = MqttLink::new(settings, outbox.clone(), wake.clone(), status, None).unwrap();
    let (stop, stop_rx) = tokio::sync::watch::channel(false);
    let running = tokio::spawn(link.run(stop_rx));
    let seen = |what: &str| {
        std::fs::read_to_string(&seen_file)
            .unwrap_or_default()
            .contains(what)
    };
    let wait_for = |what: &str| {
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        while !seen(what) {
            assert!(
                std::time::Instant::now() < deadline,
                "the watcher never saw {what:?}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    wait_for(&format!("{} online", topic("online")));
    // From here the broker's acknowledgements wait in the proxy.
    hold.store(true, Ordering::SeqCst);
    let mut payload = serde_json::Map::new();
    payload.insert("scan_id".into(), "held-ack".into());
    outbox.lock().unwrap().push("results", payload).unwrap();
    wake.notify_one();
    // The broker has the message (and has acknowledged it): then the station stops.
    wait_for("held-ack");
    stop.send(true).unwrap();
    // The stop has begun when the broker has its `offline` (what the station sends passes).
    wait_for(&format!("{} offline", topic("online")));
    hold.store(false, Ordering::SeqCst);
    tokio::time::timeout(Duration::from_secs(10), running)
        .await
        .expect("the link stops within its deadlines")
        .unwrap();
    assert!(
        outbox.lock().unwrap().is_empty(),
        "the acknowledged message is still in the outbox: it would be sent again"
    );
}
