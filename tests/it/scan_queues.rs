//! The queues of completed scans that the archive and the exports keep on disk
//! (`outbox/archive/`, `outbox/export/`), one code for both, and the start-up sweep. Entries
//! as the earlier versions wrote them (written here by hand, field by field) are carried out
//! after the upgrade, each once. A scan that succeeded while the process was killed before
//! the scan was queued (the journal's stop record written, the queue's entry not: the state
//! on disk is made here by removing the entries a run wrote) is queued at the next start for
//! the archive, the exports and its MQTT results (with the same message ids as the first
//! time), and a scan that was queued is not queued again. And the real thing: the daemon
//! killed by SIGKILL the moment its scan's stop record is in the journal, then restarted.

use crate::common::append_config;
use crate::common::mosquitto::{self, Broker};
use crate::daemon_e2e::log_path;
use crate::daemon_e2e::{self as e2e, Rig};
use crate::mqtt_broker::{spawn_logged, wait_socket, with_mqtt, STATION};
use std::path::{Path, PathBuf};
use surfscan::scan::ending::StopStatus;
use surfscan::scan::status::{State, Status};

/// `[export] dfq-dir` and `[archive]` to a directory, both created; their paths.
fn with_publishers(r: &Rig) -> (PathBuf, PathBuf) {
    let spc = r.dir.path().join("spc");
    let archive = r.dir.path().join("archive");
    std::fs::create_dir(&spc).unwrap();
    std::fs::create_dir(&archive).unwrap();
    append_config(
        &r.config,
        &format!(
            "\n[export]\ndfq-dir = {:?}\n[archive]\nurl = \"file://{}\"\n",
            spc.display().to_string(),
            archive.display()
        ),
    );
    (spc, archive)
}

async fn scan(r: &Rig, specimen: &str) -> (String, PathBuf) {
    let before = e2e::status(r).await.starts;
    e2e::start_scan(r, specimen).await;
    let s = e2e::wait_status(r, "the scan ended", |s| {
        s.starts > before && s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    let stop = s.last_stop.unwrap();
    assert_eq!(stop.status, StopStatus::Success, "{}", stop.reason);
    (stop.scan_id, PathBuf::from(stop.dir))
}

/// Waits until the archive and the exports have nothing left to do.
async fn settled(r: &Rig) -> Status {
    e2e::wait_status(r, "the archive and the exports done", |s| {
        ["archive", "export"]
            .iter()
            .all(|l| s.links.get(*l).is_some_and(|l| l.ok && l.queued == 0))
    })
    .await
}

/// The names of the entries in `dir` (`.json` and set-aside `.json.failed`).
fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".json") || n.ends_with(".json.failed"))
        .collect();
    v.sort();
    v
}

/// Removes the entries naming `scan_id` below `dir` (and its `done/`).
fn forget(dir: &Path, scan_id: &str) {
    for d in [dir.to_path_buf(), dir.join("done")] {
        for n in entries(&d) {
            if n.contains(scan_id) {
                std::fs::remove_file(d.join(n)).unwrap();
            }
        }
    }
}

/// Waits until the archive's and the exports' `done/` hold an entry of `scan_id`.
async fn done_with(r: &Rig, scan_id: &str) {
    let t0 = std::time::Instant::now();
    while !["archive", "export"].iter().all(|q| {
        entries(&r.out().join("outbox").join(q).join("done"))
            .iter()
            .any(|n| n.contains(scan_id))
    }) {
        assert!(t0.elapsed() < e2e::DEADLINE, "{scan_id} never done");
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
}

/// The ids of the messages on `surfscan/<station>/<leaf>` about `scan_id` (of `kind` if
/// given), in arrival order.
fn ids_of(seen: &[mosquitto::Seen], leaf: &str, scan_id: &str, kind: Option<&str>) -> Vec<String> {
    seen.iter()
        .filter(|m| m.topic == format!("surfscan/{STATION}/{leaf}"))
        .map(mosquitto::Seen::json)
        .filter(|v| v["scan_id"] == scan_id && kind.is_none_or(|k| v["kind"] == k))
        .map(|v| v["id"].as_str().unwrap().to_owned())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn entries_left_by_the_earlier_version_are_carried_out_once() {
    let r = e2e::rig().await;
    // A scan completed with nothing configured.
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    let (id, dir) = scan(&r, "old-1").await;
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
    // Its entries as the earlier version wrote them: `<time>-<scan id>.json` holding the scan
    // id, its directory, and what was done (`files` archived, `done` formats exported).
    let name = format!("20260101T000000.000000000Z-{id}.json");
    for (queue, done_field) in [("archive", "files"), ("export", "done")] {
        let q = r.out().join("outbox").join(queue);
        std::fs::create_dir_all(q.join("done")).unwrap();
        let text = format!(
            "{{\n  \"scan_id\": {id:?},\n  \"dir\": {:?},\n  \"{done_field}\": []\n}}",
            dir.display().to_string()
        );
        std::fs::write(q.join(&name), text).unwrap();
    }
    let (spc, archive) = with_publishers(&r);
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    settled(&r).await;
    assert!(spc.join(format!("{id}.dfq")).is_file());
    let copy = archive.join(&id);
    let check = std::process::Command::new("sha256sum")
        .args(["--check", "--quiet", "MANIFEST.sha256"])
        .current_dir(&copy)
        .output()
        .unwrap();
    assert!(check.status.success(), "{check:?}");
    for queue in ["archive", "export"] {
        let q = r.out().join("outbox").join(queue);
        assert_eq!(entries(&q), Vec::<String>::new(), "{queue}");
        assert_eq!(
            entries(&q.join("done")),
            std::slice::from_ref(&name),
            "{queue}: done once"
        );
    }
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_completed_but_never_queued_is_queued_at_the_next_start() {
    let r = e2e::rig().await;
    let broker = Broker::start(r.dir.path());
    with_mqtt(&r, &broker.url(), mosquitto::STATION_PASSWORD);
    let (spc, archive) = with_publishers(&r);
    let out = r.dir.path().join("sub.txt");
    let _sub = broker.subscribe("watcher-s", &out);
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    let (a, _) = scan(&r, "sweep-a").await;
    let (b, _) = scan(&r, "sweep-b").await;
    done_with(&r, &a).await;
    done_with(&r, &b).await;
    settled(&r).await;
    let results_of = |id: &str| {
        let id = id.to_owned();
        move |s: &[mosquitto::Seen]| {
            s.iter()
                .filter(|m| m.topic == format!("surfscan/{STATION}/results"))
                .filter(|m| m.json()["scan_id"] == id.as_str())
                .count()
        }
    };
    mosquitto::wait_seen(&out, "both results", |s| {
        results_of(&a)(s) == 1 && results_of(&b)(s) == 1
    })
    .await;
    // The subscriber may see b's results before the daemon has the broker's PUBACK for
    // them; stopped then, the daemon would send them again at its next start (at least
    // once, as it should), which is not the sweep's doing. Stopped once its outbox is empty.
    e2e::wait_status(&r, "the MQTT outbox empty", |s| {
        s.links.get("mqtt").is_some_and(|l| l.queued == 0)
    })
    .await;
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());

    // Scan a as a kill between its journal's end and its queues would leave it: no entry
    // anywhere, nothing exported or archived. Scan b was queued and done; its DFQ removed
    // by hand must not come back.
    for q in ["archive", "export", "mqtt-results"] {
        forget(&r.out().join("outbox").join(q), &a);
    }
    std::fs::remove_file(spc.join(format!("{a}.dfq"))).unwrap();
    std::fs::remove_dir_all(archive.join(&a)).unwrap();
    std::fs::remove_file(spc.join(format!("{b}.dfq"))).unwrap();

    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    let seen = mosquitto::wait_seen(&out, "a's results again", |s| results_of(&a)(s) == 2).await;
    // Sent twice, with one id each time: a consumer that drops repeated ids sees them once.
    for (leaf, kind) in [("results", None), ("events", Some("success"))] {
        let ids = ids_of(&seen, leaf, &a, kind);
        assert!(
            ids.len() >= 2 && ids.iter().all(|i| *i == ids[0]),
            "{leaf}: {ids:?}"
        );
    }
    done_with(&r, &a).await;
    settled(&r).await;
    assert!(spc.join(format!("{a}.dfq")).is_file());
    assert!(
        !spc.join(format!("{b}.dfq")).exists(),
        "b was exported again"
    );
    let check = std::process::Command::new("sha256sum")
        .args(["--check", "--quiet", "MANIFEST.sha256"])
        .current_dir(archive.join(&a))
        .output()
        .unwrap();
    assert!(check.status.success(), "{check:?}");
    let log = std::fs::read_to_string(log_path(&r)).unwrap();
    for link in ["archive", "export", "mqtt"] {
        assert!(
            log.contains(&format!("{link}: scan {a} succeeded, but the process stopped before it was queued; queued now")),
            "{link}: {log}"
        );
    }
    assert!(!log.contains(&format!("scan {b} succeeded, but")), "{log}");
    // b's results were not sent again.
    assert_eq!(results_of(&b)(&mosquitto::seen(&out)), 1);
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
}

/// The daemon killed (SIGKILL) the moment its scan's journal holds the stop record, polled
/// from here: what it had queued by then is whatever it was. After the restart the scan is
/// archived and exported, each once, and its MQTT results and success event arrive with one
/// id however many times they are sent.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_daemon_killed_as_its_scan_ends_delivers_the_scan_once_after_a_restart() {
    let r = e2e::rig().await;
    let broker = Broker::start(r.dir.path());
    with_mqtt(&r, &broker.url(), mosquitto::STATION_PASSWORD);
    let (spc, archive) = with_publishers(&r);
    let out = r.dir.path().join("sub.txt");
    let _sub = broker.subscribe("watcher-k", &out);
    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    e2e::start_scan(&r, "killed").await;
    let t0 = std::time::Instant::now();
    let journal = loop {
        if let Some(j) = std::fs::read_dir(r.out())
            .into_iter()
            .flatten()
            .map(|e| e.unwrap().path().join("journal.jsonl"))
            .find(|j| j.is_file())
        {
            break j;
        }
        assert!(t0.elapsed() < e2e::DEADLINE, "no journal");
        std::thread::sleep(std::time::Duration::from_millis(5));
    };
    while !std::fs::read_to_string(&journal)
        .unwrap()
        .contains(r#""class":"stop""#)
    {
        assert!(t0.elapsed() < e2e::DEADLINE, "no stop record");
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
    d.0.kill().unwrap();
    let killed = d.0.wait().unwrap();
    assert!(!killed.success(), "{killed:?}");
    let dir = journal.parent().unwrap().to_path_buf();
    let id = dir.file_name().unwrap().to_string_lossy().into_owned();
    let stop = e2e::records(&dir)
        .into_iter()
        .find_map(|rec| match rec {
            surfscan::scan::journal::Record::Stop(s) => Some(s),
            _ => None,
        })
        .unwrap();
    assert_eq!(stop.status, StopStatus::Success, "{}", stop.reason);
    // What the kill left queued, for the record (the test passes either way, and checks
    // the same outcome).
    let queued: Vec<(&str, usize)> = ["archive", "export", "mqtt-results"]
        .into_iter()
        .map(|q| {
            let q_dir = r.out().join("outbox").join(q);
            let n = [q_dir.clone(), q_dir.join("done")]
                .iter()
                .map(|d| entries(d).iter().filter(|n| n.contains(&id)).count())
                .sum();
            (q, n)
        })
        .collect();
    eprintln!("queued when killed: {queued:?}");

    let mut d = spawn_logged(&r);
    wait_socket(&r).await;
    let seen = mosquitto::wait_seen(&out, "the results", |s| {
        !ids_of(s, "results", &id, None).is_empty()
    })
    .await;
    done_with(&r, &id).await;
    settled(&r).await;
    assert!(spc.join(format!("{id}.dfq")).is_file());
    let check = std::process::Command::new("sha256sum")
        .args(["--check", "--quiet", "MANIFEST.sha256"])
        .current_dir(archive.join(&id))
        .output()
        .unwrap();
    assert!(check.status.success(), "{check:?}");
    for q in ["archive", "export"] {
        let q_dir = r.out().join("outbox").join(q);
        assert_eq!(entries(&q_dir), Vec::<String>::new(), "{q}");
        let done: Vec<String> = entries(&q_dir.join("done"))
            .into_iter()
            .filter(|n| n.contains(&id))
            .collect();
        assert_eq!(done.len(), 1, "{q}: done once: {done:?}");
    }
    let expected = format!(
        "{STATION}/{id}/results/{}",
        stop.time
            .to_rfc3339_opts(chrono::SecondsFormat::Micros, true)
    );
    for (leaf, kind, want) in [
        ("results", None, expected.clone()),
        (
            "events",
            Some("success"),
            expected.replace("/results/", "/success/"),
        ),
    ] {
        let ids = ids_of(&seen, leaf, &id, kind);
        assert!(
            !ids.is_empty() && ids.iter().all(|i| *i == want),
            "{leaf}: {ids:?}, want {want}"
        );
    }
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
}
