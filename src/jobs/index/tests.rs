//! The scan index against synthetic scan directories.

use super::*;
use crate::jobs::synthetic::{write, SyntheticReport, SyntheticScan};
use crate::scan::journal::StopStatus;

fn t(day: u32) -> chrono::DateTime<chrono::Utc> {
    use chrono::TimeZone;
    chrono::Utc
        .with_ymd_and_hms(2026, 3, day, 22, 0, 0)
        .unwrap()
}

fn scan(k: u64, specimen: &str, recipe: Option<&str>, verdict: Option<Verdict>) -> SyntheticScan {
    SyntheticScan {
        id: format!("2026030{k}T220000Z-{specimen}"),
        sequence: k,
        started: t(k as u32),
        specimen: specimen.into(),
        recipe: recipe.map(|r| (r.to_owned(), Some(k))),
        lines: 31,
        done: 31,
        stop: Some(StopStatus::Success),
        report: Some(SyntheticReport {
            verdict,
            ra_um: vec![0.5, 0.7, 0.6],
            sa_um: 0.8,
            warnings: 2,
        }),
    }
}

fn ids(v: &[ScanEntry]) -> Vec<u64> {
    v.iter().map(|e| e.sequence).collect()
}

#[test]
fn the_index_holds_what_the_journals_and_reports_say() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    write(out, &scan(1, "C-1", Some("brass"), Some(Verdict::Conforms))).unwrap();
    write(
        out,
        &scan(2, "C-2", Some("brass"), Some(Verdict::DoesNotConform)),
    )
    .unwrap();
    write(
        out,
        &scan(3, "S-1", Some("steel"), Some(Verdict::NotDecidable)),
    )
    .unwrap();
    let mut unfinished = scan(4, "C-3", None, None);
    unfinished.stop = None;
    unfinished.done = 12;
    unfinished.report = None;
    write(out, &unfinished).unwrap();
    // Not scans: a file, a directory without a journal, the queue's files.
    std::fs::write(out.join("queue.json"), "{}").unwrap();
    std::fs::create_dir(out.join("empty")).unwrap();

    let mut idx = ScanIndex::open(out).unwrap();
    let r = idx.refresh(out).unwrap();
    assert_eq!((r.read, r.removed, r.rebuilt), (4, 0, true));
    let all = idx.query(&Filter::default()).unwrap();
    assert_eq!(ids(&all), vec![1, 2, 3, 4]);
    let e = &all[1];
    assert_eq!(e.state, "success");
    assert_eq!(e.recipe.as_deref(), Some("brass"));
    assert_eq!(e.job, Some(2));
    assert_eq!(e.verdict, Some(Verdict::DoesNotConform));
    assert_eq!(
        e.verdict_summary.as_deref(),
        Some("does not conform (synthetic)")
    );
    assert!((e.ra_mean_um.unwrap() - 0.6).abs() < 1e-12);
    assert_eq!((e.sa_um, e.warnings), (Some(0.8), Some(2)));
    assert_eq!(e.started_at, "2026-03-02T22:00:00Z");
    let u = &all[3];
    assert_eq!(
        (u.state.as_str(), u.lines_done, u.lines_planned),
        ("unfinished", 12, 31)
    );
    assert_eq!(
        (u.recipe.as_ref(), u.verdict, u.ra_mean_um),
        (None, None, None)
    );

    let q = |f: Filter| ids(&idx.query(&f).unwrap());
    assert_eq!(
        q(Filter {
            specimen: Some("C-*".into()),
            ..Default::default()
        }),
        vec![1, 2, 4]
    );
    assert_eq!(
        q(Filter {
            recipe: Some("brass".into()),
            ..Default::default()
        }),
        vec![1, 2]
    );
    assert_eq!(
        q(Filter {
            since: Some(t(3)),
            ..Default::default()
        }),
        vec![3, 4]
    );
    assert_eq!(
        q(Filter {
            verdict: Some(Verdict::DoesNotConform),
            ..Default::default()
        }),
        vec![2]
    );
    assert_eq!(
        q(Filter {
            specimen: Some("C-?".into()),
            verdict: Some(Verdict::Conforms),
            ..Default::default()
        }),
        vec![1]
    );
}

#[test]
fn only_changed_scans_are_read_again_and_gone_ones_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    for k in 1..=3 {
        write(out, &scan(k, "C", None, None)).unwrap();
    }
    let mut idx = ScanIndex::open(out).unwrap();
    idx.refresh(out).unwrap();
    assert_eq!(idx.refresh(out).unwrap(), Refreshed::default());
    // A scan re-analysed: its report changes, only it is read again.
    let mut again = scan(2, "C", None, Some(Verdict::Conforms));
    again.report.as_mut().unwrap().warnings = 5;
    write(out, &again).unwrap();
    let r = idx.refresh(out).unwrap();
    assert_eq!((r.read, r.removed), (1, 0));
    let all = idx.query(&Filter::default()).unwrap();
    assert_eq!(
        (all[1].warnings, all[1].verdict),
        (Some(5), Some(Verdict::Conforms))
    );
    std::fs::remove_dir_all(out.join(&scan(3, "C", None, None).id)).unwrap();
    assert_eq!(idx.refresh(out).unwrap().removed, 1);
    assert_eq!(ids(&idx.query(&Filter::default()).unwrap()), vec![1, 2]);
}

#[test]
fn a_damaged_or_foreign_index_is_rebuilt_from_the_journals() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    for k in 1..=2 {
        write(out, &scan(k, "C", None, None)).unwrap();
    }
    {
        let mut idx = ScanIndex::open(out).unwrap();
        idx.refresh(out).unwrap();
    }
    // Garbage over the file: opened afresh and rebuilt.
    std::fs::write(
        out.join(INDEX_FILE),
        b"this is not a database, it is a pear",
    )
    .unwrap();
    let mut idx = ScanIndex::open(out).unwrap();
    let r = idx.refresh(out).unwrap();
    assert!(r.rebuilt && r.read == 2, "{r:?}");
    drop(idx);
    // An index of another schema version: rebuilt too.
    let c = Connection::open(out.join(INDEX_FILE)).unwrap();
    c.pragma_update(None, "user_version", 99).unwrap();
    drop(c);
    let mut idx = ScanIndex::open(out).unwrap();
    assert!(idx.refresh(out).unwrap().rebuilt);
    assert_eq!(idx.query(&Filter::default()).unwrap().len(), 2);
    // A scan whose journal is damaged is left out, not fatal.
    std::fs::write(
        out.join(&scan(2, "C", None, None).id).join(JOURNAL_FILE),
        b"{\"class\":\"line\"}\n",
    )
    .unwrap();
    let r = idx.refresh(out).unwrap();
    assert_eq!(r.unreadable, 1);
    assert_eq!(ids(&idx.query(&Filter::default()).unwrap()), vec![1]);
}
