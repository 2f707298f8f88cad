//! The raw-data archive to a real S3 server: the `surfscan daemon` binary archiving into a
//! Garage bucket the test starts on loopback, every object read back with `curl --aws-sigv4`
//! (independently of the writer) and compared byte for byte with the station's files, the
//! manifest checked by `sha256sum --check`. A refused key is named and nothing is written
//! until it is right; a store that is away while scans complete gets them all once it is
//! back, without a restart and without holding up a scan.

use crate::archive_store::{files, scan_dirs, scan_to_the_end};
use crate::common::append_config;
use crate::common::garage::{Garage, BUCKET, REGION};
use crate::daemon_e2e::{self as e2e, Rig};
use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};
use surfscan::scan::status::Status;

const PREFIX: &str = "rough-3";

/// Adds `[archive]` for the bucket of `g`, with `secret` in the key's secret file.
fn with_s3_archive(r: &Rig, g: &Garage, secret: &str) {
    write_secret(r, secret);
    append_config(
        &r.config,
        &format!(
            "\n[archive]\nurl = \"s3://{BUCKET}/{PREFIX}\"\nendpoint = {:?}\nregion = {REGION:?}\naccess-key-id = {:?}\nsecret-access-key-file = {:?}\n",
            g.endpoint,
            g.key_id,
            secret_path(r).display().to_string()
        ),
    );
}

fn secret_path(r: &Rig) -> std::path::PathBuf {
    r.dir.path().join("archive.secret")
}

fn write_secret(r: &Rig, secret: &str) {
    std::fs::write(secret_path(r), format!("{secret}\n")).unwrap();
}

async fn archive_link(r: &Rig, what: &str, f: impl Fn(bool, &str, u64) -> bool) -> Status {
    e2e::wait_status(r, what, |s| {
        s.links
            .get("archive")
            .is_some_and(|l| f(l.ok, &l.message, l.queued))
    })
    .await
}

/// The bucket holds exactly the files of `dir` and the manifest under `PREFIX/<scan id>/`,
/// each object equal to its file, and the manifest is what `sha256sum --check` accepts in
/// `dir`.
fn assert_archived(g: &Garage, dir: &Path) {
    let id = dir.file_name().unwrap().to_str().unwrap();
    let local = files(dir);
    assert!(local.iter().any(|f| f == "journal.jsonl"), "{local:?}");
    assert!(local.iter().any(|f| f == "report.json"), "{local:?}");
    let folder = format!("{PREFIX}/{id}/");
    let mut want: Vec<String> = local.iter().map(|f| format!("{folder}{f}")).collect();
    want.push(format!("{folder}MANIFEST.sha256"));
    want.sort();
    assert_eq!(g.list(&folder), want, "the bucket's objects of {id}");
    for f in &local {
        assert_eq!(
            g.get(&format!("{folder}{f}")).expect("listed"),
            std::fs::read(dir.join(f)).unwrap(),
            "{id}/{f} differs in the bucket"
        );
    }
    let manifest = g.get(&format!("{folder}MANIFEST.sha256")).unwrap();
    let mut named: Vec<String> = String::from_utf8(manifest.clone())
        .unwrap()
        .lines()
        .map(|l| l.split_once("  ").unwrap().1.to_owned())
        .collect();
    named.sort();
    assert_eq!(named, local, "the manifest of {id}");
    let mut check = Command::new("sha256sum")
        .args(["--check", "--strict", "-"])
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    check.stdin.take().unwrap().write_all(&manifest).unwrap();
    let out = check.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_key_is_named_and_the_scan_is_archived_verified_once_the_secret_is_right() {
    let r = e2e::rig().await;
    let g = Garage::start(r.dir.path());
    with_s3_archive(&r, &g, &"0".repeat(64));

    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    scan_to_the_end(&r, "s3-1", 0).await;
    let s = archive_link(&r, "the refused key named", |ok, m, q| {
        !ok && q == 1 && m.contains("refused the key")
    })
    .await;
    let message = &s.links["archive"].message;
    assert!(
        message.contains("access-key-id") && message.contains("secret-access-key-file"),
        "{message}"
    );
    assert!(
        g.list(&format!("{PREFIX}/")).is_empty(),
        "objects written with a wrong key"
    );
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());

    // The right secret, a new process: the queue it left is archived.
    write_secret(&r, &g.secret);
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    archive_link(&r, "the queue emptied", |ok, m, q| {
        ok && q == 0 && m.contains("archived")
    })
    .await;
    let dirs = scan_dirs(&r);
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    assert_archived(&g, &dirs[0]);
    assert_eq!(scan_dirs(&r), dirs, "a scan directory was deleted");
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scans_complete_while_the_store_is_away_and_are_archived_when_it_is_back() {
    let r = e2e::rig().await;
    let mut g = Garage::start(r.dir.path());
    let secret = g.secret.clone();
    with_s3_archive(&r, &g, &secret);
    g.stop();

    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    scan_to_the_end(&r, "s3-away-1", 0).await;
    let s = archive_link(&r, "the store away named", |ok, _, q| !ok && q == 1).await;
    let message = &s.links["archive"].message;
    assert!(
        message.contains("is the store reachable") && message.contains("trying again"),
        "{message}"
    );
    // The next scan is not held up by the first one's copy.
    scan_to_the_end(&r, "s3-away-2", s.starts).await;
    archive_link(&r, "two scans waiting", |ok, _, q| !ok && q == 2).await;

    // The store is back: the same process tries again and archives both.
    g.restart();
    archive_link(&r, "the queue emptied", |ok, _, q| ok && q == 0).await;
    let dirs = scan_dirs(&r);
    assert_eq!(dirs.len(), 2, "{dirs:?}");
    for dir in &dirs {
        assert_archived(&g, dir);
    }
    let done = std::fs::read_dir(r.out().join("outbox/archive/done"))
        .unwrap()
        .count();
    assert_eq!(done, 2);
    e2e::sigterm(&d);
    assert!(e2e::wait_exit(&mut d).success());
}
