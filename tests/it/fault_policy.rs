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
