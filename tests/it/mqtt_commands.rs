//! Commands over MQTT against a real Mosquitto broker with the ACL docs/integration.md gives
//! (`pattern write surfscan/+/commands/%c`): `mosquitto_pub` queues a job that then runs,
//! pauses, resumes and aborts it, each recorded in the scan's journal and the queue's log
//! with the client id; a refusal has the control socket's words; a client writing another
//! client's command topic is stopped by the broker; a retained command is refused; and with
//! `[mqtt] commands = false` every command is refused and nothing happens.

use crate::common::append_config;
use crate::common::mosquitto::{self, Broker, Seen};
use crate::daemon_e2e::log_path;
use crate::daemon_e2e::{self as e2e, Rig};
use crate::mqtt_broker::{spawn_logged, wait_socket, with_mqtt, STATION};
use std::path::{Path, PathBuf};
use surfscan::control::client::ControlClient;
use surfscan::control::protocol::{Message, Request};
use surfscan::scan::journal::Record;
use surfscan::scan::status::State;

/// Long enough that commands land while it scans (about 0.4 s a line at the rig's speed).
const LONG: &str = r#"description = "a coupon scanned long enough to be commanded"
[plan]
lines = 40
y-step-mm = 0.01
[specification]
limits = ["Ra1 50"]
"#;

fn topic(leaf: &str) -> String {
    format!("surfscan/{STATION}/{leaf}")
}

/// The rig with `[mqtt]` on `broker` (`commands` as given) and the recipe `long`.
fn station(r: &Rig, broker: &Broker, commands: bool) {
    with_mqtt(r, &broker.url(), mosquitto::STATION_PASSWORD);
    let recipes = r.dir.path().join("recipes");
    std::fs::create_dir(&recipes).unwrap();
    std::fs::write(recipes.join("long.toml"), LONG).unwrap();
    // `[mqtt]` is the last table: its key first, then the jobs' table.
    append_config(
        &r.config,
        &format!(
            "commands = {commands}\n[jobs]\nrecipes = {:?}\n",
            recipes.display().to_string()
        ),
    );
}

/// Sends `payload` as `client`'s command and waits for the reply carrying its `id`.
async fn command(
    broker: &Broker,
    out: &Path,
    client: &str,
    id: &str,
    payload: &str,
) -> serde_json::Value {
    let mut v: serde_json::Value = serde_json::from_str(payload).unwrap();
    v["id"] = id.into();
    broker.publish(
        client,
        &topic(&format!("commands/{client}")),
        &v.to_string(),
        false,
    );
    reply(out, client, id).await
}

/// The reply to `client`'s request `id`.
async fn reply(out: &Path, client: &str, id: &str) -> serde_json::Value {
    let t = topic(&format!("replies/{client}"));
    let find = |s: &[Seen]| {
        s.iter()
            .filter(|m| m.topic == t)
            .map(Seen::json)
            .find(|v| v["id"] == id)
    };
    let s = mosquitto::wait_seen(out, &format!("reply {id}"), |s| find(s).is_some()).await;
    let v = find(&s).unwrap();
    assert_eq!(v["client_id"], client, "{v}");
    v
}

/// Waits for the station online; `out` is the subscriber's file.
async fn online(r: &Rig, out: &Path) {
    wait_socket(r).await;
    mosquitto::wait_seen(out, "online", |s| {
        s.iter()
            .any(|m| m.topic == topic("online") && m.payload == "online")
    })
    .await;
}

async fn socket_answer(r: &Rig, request: &Request) -> Message {
    ControlClient::connect(&r.socket)
        .await
        .unwrap()
        .request(request)
        .await
        .unwrap()
        .message
}

/// Every file called `name` below the rig's directory.
fn files_named(r: &Rig, name: &str) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut dirs = vec![r.dir.path().to_path_buf()];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.file_name().is_some_and(|n| n == name) {
                found.push(p);
            }
        }
    }
    found
}

/// Every entry of the queue's log so far (its complete lines: the daemon appends its own
/// entries, such as a job's start and finish, while the test reads).
fn queue_log(r: &Rig) -> Vec<serde_json::Value> {
    files_named(r, "queue-log.jsonl")
        .iter()
        .flat_map(|p| {
            let text = crate::common::complete_lines(p);
            text.lines()
                .map(|l| serde_json::from_str(l).unwrap())
                .collect::<Vec<_>>()
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_queued_over_mqtt_runs_and_is_paused_resumed_and_aborted_by_its_client() {
    let r = e2e::rig().await;
    let broker = Broker::start(r.dir.path());
    station(&r, &broker, true);
    let out = r.dir.path().join("sub.txt");
    let _sub = broker.subscribe("watcher-c", &out);
    // A command left retained on the broker is handed over at every connection: refused.
    broker.publish(
        "mes-1",
        &topic("commands/mes-1"),
        r#"{"class":"queue-add","recipe":"long","specimen":"stale","id":"kept"}"#,
        true,
    );
    let mut d = spawn_logged(&r);
    online(&r, &out).await;
    let v = reply(&out, "mes-1", "kept").await;
    assert_eq!(v["class"], "error", "{v}");
    assert!(v["message"].as_str().unwrap().contains("retained"), "{v}");
    let Message::Queue(q) = socket_answer(&r, &Request::QueueList).await else {
        panic!("no queue");
    };
    assert_eq!(q.pending().count(), 0, "{q:?}");
    broker.publish("mes-1", &topic("commands/mes-1"), "", true);

    // Queued over MQTT, the job runs.
    let v = command(
        &broker,
        &out,
        "mes-1",
        "q1",
        r#"{"class":"queue-add","recipe":"long","specimen":"Q-1"}"#,
    )
    .await;
    assert_eq!(
        (v["class"].as_str(), v["command"].as_str()),
        (Some("ack"), Some("queue-add")),
        "{v}"
    );
    let running = e2e::wait_status(&r, "the queued job scanning", |s| {
        s.state == State::Scanning && s.lines_done >= 1
    })
    .await;
    let scan_id = running.scan_id.clone().unwrap();
    let add = queue_log(&r)
        .into_iter()
        .find(|e| e["command"] == "add")
        .expect("the queue's log records the add");
    assert_eq!(add["peer"]["mqtt"], "mes-1", "{add}");

    // Another client's topic: the broker's ACL drops the message, so the scan goes on. The
    // same client's next request is answered after it (one client's messages keep their
    // order), so by then the forged abort would have been carried out.
    broker.publish(
        "mes-1",
        &topic("commands/mes-2"),
        r#"{"class":"abort","id":"forged"}"#,
        false,
    );
    let v = command(&broker, &out, "mes-1", "s1", r#"{"class":"status"}"#).await;
    assert_eq!(v["class"], "status", "{v}");
    assert_eq!(v["scan_id"], scan_id.as_str(), "{v}");
    let s = e2e::status(&r).await;
    assert_eq!(s.state, State::Scanning, "{s:?}");
    let seen = mosquitto::seen(&out);
    assert!(
        seen.iter().all(|m| !m.topic.ends_with("/mes-2")),
        "nothing reached or came from mes-2's topics: {seen:#?}"
    );
    assert!(!std::fs::read_to_string(log_path(&r))
        .unwrap()
        .contains("mes-2"));

    // Pause and resume.
    let v = command(&broker, &out, "mes-1", "p1", r#"{"class":"pause"}"#).await;
    assert_eq!(v["class"], "ack", "{v}");
    let paused = e2e::wait_status(&r, "paused", |s| s.state == State::Paused).await;
    // A refusal has the socket's words and exit status: a job that is not in the queue.
    let v = command(
        &broker,
        &out,
        "mes-1",
        "x1",
        r#"{"class":"queue-remove","job":999}"#,
    )
    .await;
    assert_eq!(v["class"], "refused", "{v}");
    let Message::Refused { message, exit } =
        socket_answer(&r, &Request::QueueRemove { job: 999 }).await
    else {
        panic!("the socket did not refuse to remove job 999");
    };
    assert_eq!(v["message"], message.as_str());
    assert_eq!(v["exit"], exit);
    let v = command(&broker, &out, "mes-1", "r1", r#"{"class":"resume"}"#).await;
    assert_eq!(v["class"], "ack", "{v}");
    e2e::wait_status(&r, "scanning again", |s| {
        s.state == State::Scanning && s.lines_done > paused.lines_done
    })
    .await;
    // The same id again is a repeated delivery: answered, not carried out.
    broker.publish(
        "mes-1",
        &topic("commands/mes-1"),
        r#"{"class":"abort","id":"r1"}"#,
        false,
    );
    let r1 = |s: &[Seen]| -> Vec<serde_json::Value> {
        s.iter()
            .filter(|m| m.topic == topic("replies/mes-1"))
            .map(Seen::json)
            .filter(|v| v["id"] == "r1")
            .collect()
    };
    let s = mosquitto::wait_seen(&out, "the repeated r1", |s| r1(s).len() >= 2).await;
    let again = &r1(&s)[1];
    assert_eq!(again["class"], "error", "{again}");
    assert!(
        again["message"]
            .as_str()
            .unwrap()
            .contains("already carried out"),
        "{again}"
    );
    assert_eq!(e2e::status(&r).await.state, State::Scanning);

    // Abort.
    let v = command(&broker, &out, "mes-1", "a1", r#"{"class":"abort"}"#).await;
    assert_eq!(v["class"], "ack", "{v}");
    let ended = e2e::wait_status(&r, "aborted", |s| {
        s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    let stop = ended.last_stop.unwrap();
    assert_eq!(stop.scan_id, scan_id);
    assert_eq!(
        stop.status,
        surfscan::scan::ending::StopStatus::Abort,
        "{}",
        stop.reason
    );

    // The journal names the client with each command.
    let peers: Vec<String> = e2e::records(&e2e::scan_dir(&r))
        .iter()
        .filter_map(|rec| match rec {
            Record::Interruption(i) => i.peer.as_ref().and_then(|p| p.mqtt.clone()),
            _ => None,
        })
        .collect();
    assert!(
        peers.len() >= 2 && peers.iter().all(|p| p == "mes-1"),
        "{peers:?}"
    );
    let log = std::fs::read_to_string(log_path(&r)).unwrap();
    assert!(log.contains("MQTT client mes-1 accepted"), "{log}");
    assert!(log.contains("MQTT client mes-1 refused"), "{log}");
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_commands_off_a_command_is_refused_and_nothing_happens() {
    let r = e2e::rig().await;
    let broker = Broker::start(r.dir.path());
    station(&r, &broker, false);
    let out = r.dir.path().join("sub.txt");
    let _sub = broker.subscribe("watcher-c", &out);
    let mut d = spawn_logged(&r);
    online(&r, &out).await;
    for (id, payload) in [
        (
            "q1",
            r#"{"class":"queue-add","recipe":"long","specimen":"Q-1"}"#,
        ),
        ("s1", r#"{"class":"start","specimen":"S-1"}"#),
    ] {
        let v = command(&broker, &out, "mes-1", id, payload).await;
        assert_eq!(v["class"], "error", "{v}");
        assert!(
            v["message"]
                .as_str()
                .unwrap()
                .contains("[mqtt] commands = false"),
            "{v}"
        );
    }
    // Nothing was queued or started, then or since.
    tokio::time::sleep(std::time::Duration::from_secs(2)).await;
    let s = e2e::status(&r).await;
    assert_eq!(s.state, State::Idle, "{s:?}");
    assert!(s.last_stop.is_none() && s.scan_id.is_none(), "{s:?}");
    let Message::Queue(q) = socket_answer(&r, &Request::QueueList).await else {
        panic!("no queue");
    };
    assert_eq!(q.pending().count(), 0, "{q:?}");
    assert!(queue_log(&r).iter().all(|e| e["command"] != "add"));
    assert_eq!(files_named(&r, "journal.jsonl"), Vec::<PathBuf>::new());
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}
