//! The fault policy end to end, the real `surfscan scan` against the simulator: faults that
//! clear by themselves suspend the scan, which then completes with every line once and on
//! target — the instrument busy, bytes without line ends and a flood of stray replies for
//! seconds (the simulator's time-window faults; the night's 15 s, 60 s and 30 s scaled down,
//! still longer than a few quick attempts take), a file system that really fills up — and
//! damage on disk is repaired or stepped around, never obeyed: a changed committed line is
//! quarantined and traced again, a damaged record in another scan's journal is named and that
//! scan skipped while a new one runs to completion.

use crate::common::*;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The scan directories under `out`, sorted by name.
fn scan_dirs(out: &std::path::Path) -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(out)
        .expect("output dir")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    dirs
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_damaged_record_in_an_old_finished_journal_is_named_and_a_new_scan_completes() {
    let rig = Rig::start(RigOptions {
        lines: 4,
        ..RigOptions::default()
    })
    .await;
    let config = rig.config("out");
    let out = rig.out_dir("out");
    let o = run_scan(&config, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let old = scan_dir(&out);
    // One byte of the old scan's second line record changed: not valid as a record.
    let jpath = old.join("journal.jsonl");
    let text = std::fs::read_to_string(&jpath).unwrap();
    let second_line_record = text.match_indices("{\"class\":\"line\"").nth(1).unwrap().0;
    let mut bytes = text.into_bytes();
    bytes[second_line_record + 10] = b'!';
    std::fs::write(&jpath, &bytes).unwrap();

    let o = run_scan(&config, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains(&jpath.display().to_string())
            && stderr.contains("line 3")
            && stderr.contains("skipped"),
        "the damaged journal is named: {stderr}"
    );
    let dirs = scan_dirs(&out);
    assert_eq!(dirs.len(), 2, "{dirs:?}");
    let new = dirs.into_iter().find(|d| *d != old).unwrap();
    assert_lines_exactly(&new, 4);
    assert_journal_complete(&new, 4);
    // The damaged journal is left as it was found, for inspection.
    assert_eq!(std::fs::read(&jpath).unwrap(), bytes);
    rig.shutdown().await;
}

/// A flipped digit in a committed line's heights file, found at resume: the line is moved
/// aside (both hashes journaled), traced again, the lines committed after it are kept, and
/// the surface is the one an undisturbed scan writes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flipped_digit_in_a_committed_line_is_quarantined_and_the_line_traced_again() {
    use surfscan::scan::journal::{Record, StopStatus};
    const N: usize = 6;
    let rig = Rig::start(RigOptions {
        lines: N,
        ..RigOptions::default()
    })
    .await;
    let o = run_scan(&rig.config("reference"), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let reference = surface_bits(&scan_dir(&rig.out_dir("reference")).join("surface.igs"));

    // Killed after line 4 is on disk, then a digit of line 2 changes.
    let config = rig.config("out");
    let o = run_scan(&config, &[("SURFSCAN_TEST_CRASH", "3:after-commit")]).await;
    assert!(!o.status.success(), "{}", describe(&o));
    let dir = scan_dir(&rig.out_dir("out"));
    let csv = dir.join("lines").join("0001.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let (head, rest) = text.split_at(text.find('\n').unwrap() + 1);
    let row = rest.lines().nth(5).unwrap();
    let digit = row.rfind(|c: char| c.is_ascii_digit()).unwrap();
    let mut flipped_row = row.to_owned();
    let d = row.as_bytes()[digit];
    flipped_row.replace_range(digit..=digit, &((d - b'0' + 1) % 10).to_string());
    let flipped = format!("{head}{}", rest.replacen(row, &flipped_row, 1));
    assert_ne!(flipped, text);
    std::fs::write(&csv, &flipped).unwrap();

    let o = run_scan(&config, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    assert_lines_exactly(&dir, N);
    let (records, state) = journal(&dir);
    // Line 2 is recorded again after its quarantine; lines 5 and 6 once, after it.
    assert_eq!(line_record_indices(&records), vec![0, 1, 2, 3, 1, 4, 5]);
    assert_eq!(state.first_missing(N as u32), None);
    let q: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::Quarantine(q) => Some(q.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(q.len(), 1, "{q:?}");
    assert_eq!(q[0].index, 1);
    assert_eq!(
        q[0].found_sha256,
        surfscan::scan::store::hex_sha256(flipped.as_bytes())
    );
    assert_eq!(
        q[0].expected_sha256,
        surfscan::scan::store::hex_sha256(text.as_bytes())
    );
    assert_eq!(
        std::fs::read_to_string(dir.join(&q[0].moved_to)).unwrap(),
        flipped,
        "the damaged file is kept for inspection"
    );
    assert!(matches!(records.last(), Some(Record::Stop(s)) if s.status == StopStatus::Success));
    assert_eq!(surface_bits(&dir.join("surface.igs")), reference);
    rig.shutdown().await;
}

/// Runs an 8-line scan with `fault` (a window opening at the third trace) and a 60 s budget;
/// checks it completed with every line once and on target; returns the interruption notes
/// and how long the scan took.
async fn scan_through(fault: &str) -> (Vec<String>, Duration) {
    let rig = Rig::start(RigOptions {
        faults: vec![fault.to_owned()],
        extra_scan: "transient-budget-s = 60\n".into(),
        ..RigOptions::default()
    })
    .await;
    let n = rig.options.lines;
    let t0 = Instant::now();
    let o = run_scan(&rig.config("out"), &[]).await;
    let took = t0.elapsed();
    assert!(o.status.success(), "{fault}: {}", describe(&o));
    let dir = scan_dir(&rig.out_dir("out"));
    assert_lines_exactly(&dir, n);
    let records = assert_journal_complete(&dir, n);
    rig.shutdown().await;
    (interruptions(&records), took)
}

/// The notes say the scan was suspended on line 3 for `what` (the instrument `busy`, or
/// `answering wrongly or not in time`) and went on once line 3 was on disk.
fn assert_suspended_on_line_3(fault: &str, what: &str, notes: &[String]) {
    let suspended = format!("suspended: instrument {what} since");
    assert!(
        notes.iter().any(|r| r.starts_with(&suspended)),
        "{fault}: {notes:?}"
    );
    assert!(
        notes
            .iter()
            .any(|r| r.starts_with("line 3 on disk after") && r.ends_with("scan continues")),
        "{fault}: {notes:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_instrument_busy_for_a_window_suspends_the_scan_which_then_completes() {
    let fault = "busy:4000@CTSTA#3";
    let (notes, took) = scan_through(fault).await;
    assert_suspended_on_line_3(fault, "busy", &notes);
    assert!(
        notes.iter().any(|r| r.contains("NG011")),
        "the busy answer is named: {notes:?}"
    );
    assert!(took >= Duration::from_secs(4), "{took:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bytes_without_line_ends_for_a_window_suspend_the_scan_which_then_completes() {
    let fault = "noeol:4000@CTSTA#3";
    let (notes, took) = scan_through(fault).await;
    // Not labelled busy: the instrument answered, but not with a line the host can read.
    assert_suspended_on_line_3(fault, "answering wrongly or not in time", &notes);
    assert!(!notes.iter().any(|r| r.contains("busy")), "{notes:?}");
    assert!(took >= Duration::from_secs(4), "{took:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_stray_replies_for_a_window_never_ends_the_scan() {
    let fault = "flood:4000@CTSTA#3";
    let (notes, took) = scan_through(fault).await;
    // Strays that arrive between exchanges are set aside before the next command, so whether
    // the flood breaks an exchange at all (a stray inside one) depends on timing. What it
    // breaks is retried within the budget: every note is a suspension or a line committed
    // after one, on line 3 (where the flood starts) or later.
    let recovered: Vec<u32> = notes
        .iter()
        .filter(|r| r.ends_with("scan continues"))
        .filter_map(|r| r.strip_prefix("line ")?.split(' ').next()?.parse().ok())
        .collect();
    assert!(
        notes.iter().all(|r| r
            .starts_with("suspended: instrument answering wrongly or not in time since")
            || r.starts_with("suspended: instrument busy since")
            || r.ends_with("scan continues")),
        "{fault}: {notes:?}"
    );
    assert!(recovered.iter().all(|&k| k >= 3), "{fault}: {notes:?}");
    assert_eq!(
        recovered.is_empty(),
        notes.is_empty(),
        "a suspension ends with its line committed: {notes:?}"
    );
    assert!(took >= Duration::from_secs(4), "{took:?}");
}

/// The output directory's file system really fills up mid-scan (a small tmpfs and a ballast
/// file): the scan suspends instead of failing, and when the ballast is removed it goes on by
/// itself and completes with every line once and on target.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_really_full_disk_suspends_the_scan_which_goes_on_when_space_is_freed() {
    const N: usize = 8;
    let rig = Rig::start(RigOptions {
        lines: N,
        ..RigOptions::default()
    })
    .await;
    let out = rig.out_dir("out");
    // Room for the pre-flight estimate of 8 short lines (about 9.7 MB), not much more.
    let mount = Mount::tmpfs(&out, 11 << 20);
    let (mut scan, metrics) = rig.scan_past_two_lines("out").await;
    let ballast = out.join("ballast");
    assert!(fill(&ballast) > 0);
    wait_for_suspension(&metrics).await;
    let held = committed_lines(&out);
    assert!(held < N, "suspended before the end");
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(
        committed_lines(&out),
        held,
        "nothing is committed while the disk is full"
    );
    assert!(
        scan.try_wait().unwrap().is_none(),
        "the scan waits for space instead of ending"
    );
    std::fs::remove_file(&ballast).unwrap();
    let o = tokio::time::timeout(Duration::from_secs(120), scan.wait_with_output())
        .await
        .expect("the scan ends")
        .unwrap();
    assert!(o.status.success(), "{}", describe(&o));
    let dir = scan_dir(&out);
    assert_lines_exactly(&dir, N);
    let records = assert_journal_complete(&dir, N);
    // The suspension itself is in the journal (written once there was room), before the
    // note that space is back.
    let notes = interruptions(&records);
    let back = notes.iter().position(|r| r.starts_with("space is back"));
    let full = notes
        .iter()
        .position(|r| r.starts_with("suspended: disk full while writing"));
    assert!(
        matches!((full, back), (Some(f), Some(b)) if f < b),
        "{notes:?}"
    );
    drop(mount);
    rig.shutdown().await;
}
