//! The raw-data archive through the `surfscan daemon` binary: a `file://` archive (a share)
//! that is not there while two scans complete, then there after a restart; the copies checked
//! byte for byte and the manifest by `sha256sum -c`, independently of the writer. Retention:
//! nothing leaves the station without `delete-after-days`; with it, a scan whose archived
//! copy verifies again is deleted and one whose copy was damaged is kept and named.

use crate::common::append_config;
use crate::daemon_e2e::{self as e2e, Rig};
use std::path::{Path, PathBuf};
use std::process::Command;
use surfscan::scan::ending::StopStatus;
use surfscan::scan::status::{State, Status};

fn with_archive(r: &Rig, url: &str) {
    append_config(&r.config, &format!("\n[archive]\nurl = {url:?}\n"));
}

pub(crate) fn scan_dirs(r: &Rig) -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(r.out())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("journal.jsonl").exists())
        .collect();
    dirs.sort();
    dirs
}

/// Every regular file below `dir`, relative, sorted (written here, not taken from the code
/// under test).
pub(crate) fn files(dir: &Path) -> Vec<String> {
    let o = Command::new("find")
        .arg(".")
        .args(["-type", "f"])
        .current_dir(dir)
        .output()
        .unwrap();
    let mut v: Vec<String> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| l.trim_start_matches("./").to_owned())
        .collect();
    v.sort();
    v
}

pub(crate) async fn scan_to_the_end(r: &Rig, specimen: &str, starts_before: u64) -> Status {
    e2e::start_scan(r, specimen).await;
    let s = e2e::wait_status(r, "scan ended", |s| {
        s.starts > starts_before && s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    assert_eq!(
        s.last_stop.as_ref().unwrap().status,
        StopStatus::Success,
        "{s:?}"
    );
    s
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scans_complete_while_the_share_is_away_and_are_archived_verified_after_a_restart() {
    let r = e2e::rig().await;
    let share = r.dir.path().join("share");
    with_archive(&r, &format!("file://{}", share.display()));

    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    scan_to_the_end(&r, "arch-1", 0).await;
    // The share is not mounted: named, the scan waits in the queue, the next scan runs.
    let s = e2e::wait_status(&r, "the archive's fault named", |s| {
        s.links
            .get("archive")
            .is_some_and(|l| !l.ok && l.queued == 1)
    })
    .await;
    let link = &s.links["archive"];
    assert!(
        link.message.contains(&share.display().to_string())
            && link.message.contains("is the share mounted"),
        "{link:?}"
    );
    scan_to_the_end(&r, "arch-2", s.starts).await;
    e2e::wait_status(&r, "two scans queued", |s| {
        s.links.get("archive").is_some_and(|l| l.queued == 2)
    })
    .await;
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
    assert!(
        !share.exists(),
        "the archive directory was created by the station"
    );

    // The share is back; a new process archives what the last one left.
    std::fs::create_dir(&share).unwrap();
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    let s = e2e::wait_status(&r, "the queue emptied", |s| {
        s.links
            .get("archive")
            .is_some_and(|l| l.ok && l.queued == 0)
    })
    .await;
    assert!(s.links["archive"].message.contains("archived"), "{s:?}");

    let dirs = scan_dirs(&r);
    assert_eq!(dirs.len(), 2, "{dirs:?}");
    for dir in &dirs {
        let id = dir.file_name().unwrap().to_str().unwrap();
        let copy = share.join(id);
        let local = files(dir);
        assert!(local.iter().any(|f| f == "journal.jsonl"), "{local:?}");
        assert!(local.iter().any(|f| f == "report.json"), "{local:?}");
        let mut archived = files(&copy);
        archived.retain(|f| f != "MANIFEST.sha256");
        assert_eq!(archived, local, "the archive of {id} holds other files");
        for f in &local {
            assert_eq!(
                std::fs::read(copy.join(f)).unwrap(),
                std::fs::read(dir.join(f)).unwrap(),
                "{id}/{f} differs"
            );
        }
        // The manifest names every file, and sha256sum agrees with every line of it.
        let manifest = std::fs::read_to_string(copy.join("MANIFEST.sha256")).unwrap();
        let mut named: Vec<&str> = manifest
            .lines()
            .map(|l| l.split_once("  ").unwrap().1)
            .collect();
        named.sort();
        assert_eq!(named, local);
        let check = Command::new("sha256sum")
            .args(["--check", "--strict", "MANIFEST.sha256"])
            .current_dir(&copy)
            .output()
            .unwrap();
        assert!(
            check.status.success(),
            "{}",
            String::from_utf8_lossy(&check.stdout)
        );
    }
    // Nothing on the station was deleted; each scan is recorded as archived.
    assert_eq!(scan_dirs(&r), dirs);
    let done = std::fs::read_dir(r.out().join("outbox/archive/done"))
        .unwrap()
        .count();
    assert_eq!(done, 2);
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

#[test]
fn a_bad_archive_table_exits_78_naming_the_key() {
    crate::common::assert_tables_refused(
        "archive",
        &[
            ("url = \"/mnt/archive\"", "archive.url"),
            ("url = \"file://mnt/archive\"", "archive.url"),
            (
                "url = \"s3://lab-archive/rough-3\"\naccess-key-id = \"GK1\"",
                "archive.secret-access-key-file",
            ),
            (
                "url = \"s3://lab-archive/rough-3\"\nendpoint = \"127.0.0.1:3900\"",
                "archive.endpoint",
            ),
            (
                "url = \"s3://lab-archive/rough-3\"\nendpoint = \"http://127.0.0.1:3900\"\nca-file = \"/etc/hostname\"",
                "archive.ca-file",
            ),
            (
                "url = \"s3://lab-archive/rough-3\"\nendpoint = \"https://127.0.0.1:3900\"\nca-file = \"/etc/hostname\"",
                "archive.ca-file",
            ),
        ],
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retention_deletes_a_scan_only_when_its_archived_copy_verifies_again() {
    let r = e2e::rig().await;
    let share = r.dir.path().join("share");
    std::fs::create_dir(&share).unwrap();
    with_archive(&r, &format!("file://{}", share.display()));

    // Without a retention setting nothing leaves the station.
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    let s = scan_to_the_end(&r, "keep-1", 0).await;
    scan_to_the_end(&r, "keep-2", s.starts).await;
    let done = r.out().join("outbox/archive/done");
    e2e::wait_status(&r, "both archived", |s| {
        s.links
            .get("archive")
            .is_some_and(|l| l.ok && l.queued == 0)
            && std::fs::read_dir(&done).map_or(0, |d| d.count()) == 2
    })
    .await;
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
    let dirs = scan_dirs(&r);
    assert_eq!(dirs.len(), 2, "{dirs:?}");
    let (first, second) = (&dirs[0], &dirs[1]);
    let id = |p: &Path| p.file_name().unwrap().to_str().unwrap().to_owned();
    let kept = r.dir.path().join("first-as-it-was");
    assert!(Command::new("cp")
        .arg("-a")
        .arg(first)
        .arg(&kept)
        .status()
        .unwrap()
        .success());

    let second_files = files(second);

    // The second scan's copy is damaged in the archive after it was verified.
    let damaged = share.join(id(second)).join("journal.jsonl");
    let mut bytes = std::fs::read(&damaged).unwrap();
    bytes[0] ^= 1;
    std::fs::write(&damaged, bytes).unwrap();

    append_config(&r.config, "delete-after-days = 0\n");
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    let s = e2e::wait_status(&r, "the damaged copy named", |s| {
        s.links.get("archive").is_some_and(|l| {
            !l.ok && l.message.contains(&id(second)) && l.message.contains("kept on the station")
        })
    })
    .await;
    let message = &s.links["archive"].message;
    assert!(message.contains("journal.jsonl"), "{message}");
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());

    // The first scan is gone from the station and whole in the archive; the second is kept.
    assert!(!first.exists(), "{} was not deleted", first.display());
    assert_eq!(files(&share.join(id(first))).len(), files(&kept).len() + 1);
    let diff = Command::new("diff")
        .arg("-r")
        .args(["--exclude", "MANIFEST.sha256"])
        .arg(&kept)
        .arg(share.join(id(first)))
        .output()
        .unwrap();
    assert!(
        diff.status.success(),
        "{}",
        String::from_utf8_lossy(&diff.stdout)
    );
    assert_eq!(files(second), second_files, "the second scan was touched");
    let log = std::fs::read_to_string(r.dir.path().join("daemon.log")).unwrap();
    assert!(
        log.contains(&format!("scan {} deleted from the station", id(first))),
        "{log}"
    );
    assert!(
        !log.contains(&format!("scan {} deleted", id(second))),
        "{log}"
    );
}

/// An `https://` store whose certificate chains to no authority the station trusts (a real
/// TLS server, `openssl s_server`, with a CA made for the test): named in the status with
/// the settings that fix it, the scan unaffected and kept for the archive.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_certificate_that_does_not_verify_is_named_and_the_scan_is_kept() {
    use crate::common::mosquitto::{on_fresh_ports, port_taken, Killed};
    let r = e2e::rig().await;
    let tls = crate::common::throwaway_tls(r.dir.path());
    let said = r.dir.path().join("s_server.log");
    // The server exits naming a port another process took first.
    let (_server, port) = on_fresh_ports("openssl s_server", |[port]| {
        let mut server = Killed(
            Command::new("openssl")
                .args(["s_server", "-quiet", "-www", "-accept", &port.to_string()])
                .arg("-cert")
                .arg(&tls.certificate)
                .arg("-key")
                .arg(&tls.key)
                .stdin(std::process::Stdio::null())
                .stdout(std::process::Stdio::null())
                .stderr(std::fs::File::create(&said).unwrap())
                .spawn()
                .unwrap(),
        );
        let start = std::time::Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            if let Some(st) = server.0.try_wait().unwrap() {
                let log = std::fs::read_to_string(&said).unwrap_or_default();
                if port_taken(&log) {
                    return Err(log);
                }
                panic!("openssl s_server exited ({st}): {log}");
            }
            assert!(
                start.elapsed().as_secs() < 10,
                "openssl s_server does not listen"
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        Ok((server, port))
    });
    let secret = r.dir.path().join("archive.secret");
    std::fs::write(&secret, "s3cret\n").unwrap();
    let endpoint = format!("https://127.0.0.1:{port}");
    append_config(
        &r.config,
        &format!(
            "\n[archive]\nurl = \"s3://lab-archive/rough-3\"\nendpoint = {endpoint:?}\nregion = \"garage\"\naccess-key-id = \"GK1\"\nsecret-access-key-file = {:?}\n",
            secret.display().to_string()
        ),
    );

    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    scan_to_the_end(&r, "tls-1", 0).await;
    let s = e2e::wait_status(&r, "the certificate named", |s| {
        s.links
            .get("archive")
            .is_some_and(|l| !l.ok && l.message.contains("certificate"))
    })
    .await;
    let link = &s.links["archive"];
    assert!(
        link.message.contains("does not verify") && link.message.contains("ca-file"),
        "{link:?}"
    );
    assert_eq!(link.queued, 1, "{link:?}");
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
}
