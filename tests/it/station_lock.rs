//! One process per station, end to end: a second `surfscan scan` or `surfscan daemon` on a
//! station that another process drives exits 69 naming that process's pid and scan id, touches
//! nothing, and the first finishes its scan with every line once; a full disk does not keep
//! the lock from being taken. The tests run as root, as on a station, where the serial
//! port's exclusive mode would not have stopped the second.

use crate::common::*;
use std::time::Duration;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_scan_on_one_config_exits_69_naming_the_first_and_the_first_completes() {
    let rig = Rig::start(RigOptions {
        lines: 12,
        ..RigOptions::default()
    })
    .await;
    let config = rig.config("out");
    let out = rig.out_dir("out");
    let first = scan_command(&config, &[])
        .spawn()
        .expect("first scan starts");
    let first_pid = first.id().expect("pid");
    wait_until(
        Duration::from_secs(60),
        "the first scan commits a line",
        || committed_lines(&out) >= 1,
    )
    .await;
    let id = scan_dir(&out)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();

    let second = run_scan(&config, &[]).await;
    assert_eq!(second.status.code(), Some(69), "{}", describe(&second));
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert!(
        stderr.contains(&format!("pid {first_pid}")) && stderr.contains(&id),
        "{stderr}"
    );

    let first = tokio::time::timeout(Duration::from_secs(120), first.wait_with_output())
        .await
        .expect("first scan ends")
        .unwrap();
    assert!(first.status.success(), "{}", describe(&first));
    let dir = scan_dir(&out);
    assert_lines_exactly(&dir, 12);
    assert_journal_complete(&dir, 12);
    rig.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_daemon_exits_69_naming_the_first() {
    let rig = Rig::start(RigOptions::default()).await;
    let config = rig.config("out");
    let daemon = |config: &std::path::Path| {
        let mut c = tokio::process::Command::new(env!("CARGO_BIN_EXE_surfscan"));
        c.arg("daemon")
            .arg("--config")
            .arg(config)
            .env("RUST_LOG", "info")
            .env_remove("NOTIFY_SOCKET")
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .kill_on_drop(true);
        c
    };
    let first = daemon(&config).spawn().unwrap();
    let first_pid = first.id().unwrap();
    let socket = rig.tmp.path().join("control.sock");
    wait_until(Duration::from_secs(30), "the first daemon's socket", || {
        socket.exists()
    })
    .await;
    let second = tokio::time::timeout(Duration::from_secs(30), daemon(&config).output())
        .await
        .expect("the second daemon exits by itself")
        .unwrap();
    assert_eq!(second.status.code(), Some(69), "{}", describe(&second));
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert!(
        stderr.contains(&format!("surfscan daemon, pid {first_pid}")),
        "{stderr}"
    );
    // The first is unaffected: it still answers on its socket.
    assert!(std::os::unix::net::UnixStream::connect(&socket).is_ok());
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(first_pid as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let first = tokio::time::timeout(Duration::from_secs(30), first.wait_with_output())
        .await
        .unwrap()
        .unwrap();
    assert!(first.status.success(), "{}", describe(&first));
    rig.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn leftovers_of_a_killed_write_are_removed_at_start_and_named_in_the_log() {
    let rig = Rig::start(RigOptions::default()).await;
    let config = rig.config("out");
    let out = rig.out_dir("out");
    // What a process killed while writing a finished scan's surface leaves behind.
    let old = out.join("20250101T000000Z-old");
    std::fs::create_dir_all(old.join("lines")).unwrap();
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let dead = child.id();
    child.wait().unwrap();
    let leftover = old.join(format!(".surface.igs.tmp{dead}"));
    let line_tmp = old.join("lines").join(".0003.csv.tmp");
    // A write in progress by a live process (pid 1) and an ordinary file stay.
    let live = old.join(".report.json.tmp1");
    let kept = old.join("notes.txt");
    for p in [&leftover, &line_tmp, &live, &kept] {
        std::fs::write(p, b"partial").unwrap();
    }
    let o = run_scan(&config, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    assert!(!leftover.exists() && !line_tmp.exists());
    assert!(live.exists() && kept.exists());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("removed the leftover of an interrupted write")
            && stderr.contains(&leftover.display().to_string()),
        "{stderr}"
    );
    rig.shutdown().await;
}

/// A scan suspended because its output directory's file system is full, then a restart
/// (power loss, the service restarted): the station lock is taken on the full disk, so the
/// scan can resume and wait for space instead of the process exiting 74. The lock still
/// refuses a second process.
#[test]
fn the_station_lock_is_taken_on_a_full_disk_and_still_refuses_a_second_process() {
    use surfscan::station_lock::{LockError, StationLock};
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let _mount = Mount::tmpfs(&out, 64 << 10);
    assert!(fill(&out.join("ballast")) > 0);
    let locks = tmp.path().join("locks");
    std::fs::create_dir_all(&locks).unwrap();
    let first = StationLock::acquire("daemon", &out, &[], &locks);
    let first = match first {
        Ok(l) => l,
        Err(e) => panic!("the lock is refused on a full disk: {e}"),
    };
    match StationLock::acquire("scan", &out, &[], &locks) {
        Err(LockError::Held { .. }) => {}
        other => panic!("a second process must be refused: {other:?}"),
    }
    drop(first);
}

/// A `LCK..` file planted for the instrument's port by another local user (owned by nobody),
/// naming pid 1, which is always alive: the scan is not kept from starting. The lock is not
/// obeyed, with a warning naming the pid, its command and the file's owner; the scan
/// completes and the lock file is then the scan's own.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_planted_device_lock_naming_pid_1_as_another_user_does_not_keep_a_scan_off() {
    let rig = Rig::start(RigOptions::default()).await;
    let config = rig.config("out");
    let out = rig.out_dir("out");
    let locks = config.parent().unwrap().join("locks");
    std::fs::create_dir_all(&locks).unwrap();
    let lck = locks.join(surfscan::station_lock::device_lock_name(
        &rig.instrument_link,
    ));
    std::fs::write(&lck, format!("{:>10}\n", 1)).unwrap();
    // CI runs as root, as a station's tests must: chown fails loudly otherwise.
    nix::unistd::chown(&lck, Some(nix::unistd::Uid::from_raw(65534)), None)
        .expect("chown needs root (run the tests as root)");
    let o = run_scan(&config, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("is not obeyed")
            && stderr.contains("of pid 1 (")
            && stderr.contains("owned by nobody (uid 65534)")
            && stderr.contains("does not have the device open"),
        "{stderr}"
    );
    assert_eq!(committed_lines(&out), RigOptions::default().lines);
    rig.shutdown().await;
}
