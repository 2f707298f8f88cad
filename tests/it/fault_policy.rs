//! The fault policy end to end, the real `surfscan scan` against the simulator: damage on
//! disk is repaired or stepped around, never obeyed — a damaged record in another scan's
//! journal is named and that scan skipped while a new one runs to completion.

use crate::common::*;
use std::path::PathBuf;

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
