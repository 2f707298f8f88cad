//! Durable scan storage: durability order, journal recovery, resume state, disk-full
//! handling, the metrics file format and the systemd unit's required directives.

use std::io;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use chrono::{TimeZone, Utc};
use surfscan::profile::{Conditions, InstrumentResult, NoHeights, Profile, ProfileKind};
use surfscan::scan::faults::{NoFaults, StorageFaults, WriteStep};
use surfscan::scan::journal::{
    find_unfinished, parse_journal, InterruptionRecord, Journal, JournalError, Record, ResumeState,
    StartRecord, StopRecord, StopStatus,
};
use surfscan::scan::line::{LineIdentity, LineMeta};
use surfscan::scan::metrics::ScanMetrics;
use surfscan::scan::metrics_file::write_metrics;
use surfscan::scan::scan_id::ScanId;
use surfscan::scan::store::ScanStore;
use surfscan::scan::store_error::StoreError;
use surfscan::units::Nm;

/// Fails the `nth` (0-based) write of `step` with `errno`, once; records every write asked.
struct FailNth {
    step: WriteStep,
    nth: usize,
    errno: i32,
    seen: AtomicUsize,
    log: Mutex<Vec<(WriteStep, String)>>,
}

impl FailNth {
    fn new(step: WriteStep, nth: usize, errno: i32) -> Arc<FailNth> {
        Arc::new(FailNth {
            step,
            nth,
            errno,
            seen: AtomicUsize::new(0),
            log: Mutex::new(Vec::new()),
        })
    }
}

impl StorageFaults for FailNth {
    fn before_write(&self, step: WriteStep, path: &Path) -> io::Result<()> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        self.log.lock().unwrap().push((step, name));
        if step == self.step && self.seen.fetch_add(1, Ordering::SeqCst) == self.nth {
            return Err(io::Error::from_raw_os_error(self.errno));
        }
        Ok(())
    }
}

fn start_record(id: &ScanId, lines: u32) -> StartRecord {
    StartRecord {
        scan_id: id.0.clone(),
        sequence: 1,
        time: Utc.with_ymd_and_hms(2026, 1, 2, 3, 4, 5).unwrap(),
        plan: surfscan::scan::plan::Plan {
            lines,
            y_start_nm: Nm(0),
            y_step_nm: Nm(10_000),
            degree_u: 5,
            degree_v: 5,
            max_line_attempts: 3,
            v_method: Default::default(),
            replace_spikes: None,
            analysis: None,
        },
        config: serde_json::json!({"scan": {"lines": lines}}),
        config_hash: "ab".repeat(32),
        specimen: "block-7".into(),
        operator: "kim".into(),
        notes: "night run".into(),
        software_version: "0.1.0".into(),
        instrument_model: "SJ-210".into(),
        firmware: "2.00".into(),
        drive_unit: "standard".into(),
        conditions: Conditions::default(),
        peer: None,
        job: None,
    }
}

/// Line `k`: 5 points with heights that need full round-trip precision.
fn line(k: u32) -> (LineMeta, Profile) {
    let heights: Vec<f64> = (0..5)
        .map(|i| f64::from(k) * 0.1 + f64::from(i) / 3.0 - 0.7)
        .collect();
    let mut p = Profile::new(0.0005, heights);
    p.kind = ProfileKind::R;
    let t = Utc.with_ymd_and_hms(2026, 1, 2, 3, 10, k).unwrap();
    let meta = LineMeta {
        id: LineIdentity {
            index: k,
            y_target_nm: Nm(i64::from(k) * 10_000),
            y_readback_nm: Some(Nm(i64::from(k) * 10_000 + 3)),
            attempt: 1,
            points: 5,
        },
        profile: Profile {
            pitch_x_mm: 0.0005,
            heights_um: NoHeights,
            kind: ProfileKind::R,
            conditions: Conditions::default(),
        },
        results: vec![InstrumentResult {
            name: "Ra".into(),
            value: Some(0.123),
            unit: "um".into(),
            printed: None,
            ng_code: None,
        }],
        readout_warnings: Vec::new(),
        started_at: t,
        finished_at: t,
    };
    (meta, p)
}

fn new_scan(
    out: &Path,
    lines: u32,
    faults: Arc<dyn StorageFaults>,
) -> (ScanStore, Journal, ScanId) {
    let id = ScanId::new(
        Utc.with_ymd_and_hms(2026, 1, 2, 3, 4, 5).unwrap(),
        "Block 7",
    );
    let store = ScanStore::create(out, &id, faults.clone()).unwrap().0;
    let journal = Journal::create(store.root(), start_record(&id, lines), faults).unwrap();
    (store, journal, id)
}

fn state_of(store: &ScanStore) -> ResumeState {
    let (_, rec) = Journal::open(&store.journal_path(), Arc::new(NoFaults)).unwrap();
    ResumeState::from_records(&store.journal_path(), &rec.records).unwrap()
}

#[test]
fn lines_round_trip_with_their_y_and_heights_bit_identical() {
    let tmp = tempfile::tempdir().unwrap();
    let (store, mut journal, id) = new_scan(tmp.path(), 3, Arc::new(NoFaults));
    assert_eq!(id.0, "20260102T030405Z-block-7");
    for k in 0..3 {
        let (m, p) = line(k);
        store.commit_line(&mut journal, &m, &p).unwrap();
    }
    let loaded = store.load_all().unwrap();
    assert!(loaded.incomplete.is_empty());
    let all = loaded.lines;
    assert_eq!(all.len(), 3);
    for (k, l) in all.iter().enumerate() {
        let (m, p) = line(k as u32);
        assert_eq!(l.meta, m);
        assert_eq!(l.profile, p, "heights must be bit-identical");
        assert_eq!(l.y_mm(), k as f64 * 0.01);
    }
    let st = state_of(&store);
    assert_eq!(st.first_missing(3), None);
    assert_eq!(store.load_committed(&st.lines).unwrap().len(), 3);
    // no temporary files are left behind
    let names: Vec<String> = std::fs::read_dir(store.lines_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".tmp")), "{names:?}");
    assert_eq!(names.len(), 6);
}

#[test]
fn durability_order_is_csv_then_json_then_journal() {
    let tmp = tempfile::tempdir().unwrap();
    let hook = FailNth::new(WriteStep::Metrics, usize::MAX, 0);
    let (store, mut journal, _) = new_scan(tmp.path(), 2, hook.clone());
    hook.log.lock().unwrap().clear();
    let (m, p) = line(0);
    store.commit_line(&mut journal, &m, &p).unwrap();
    let log = hook.log.lock().unwrap().clone();
    assert_eq!(
        log,
        vec![
            (WriteStep::LineCsv, "0000.csv".to_string()),
            (WriteStep::LineJson, "0000.json".to_string()),
            (WriteStep::Journal, "journal.jsonl".to_string()),
        ]
    );
}

#[test]
fn journal_write_failure_leaves_the_line_file_but_resume_retraces_it_exactly_once() {
    let tmp = tempfile::tempdir().unwrap();
    // journal write #0 is the start record; #1 line 0; #2 line 1 fails.
    let hook = FailNth::new(WriteStep::Journal, 2, libc::EIO);
    let (store, mut journal, _) = new_scan(tmp.path(), 3, hook);
    let (m0, p0) = line(0);
    store.commit_line(&mut journal, &m0, &p0).unwrap();
    let (m1, p1) = line(1);
    let err = store.commit_line(&mut journal, &m1, &p1).unwrap_err();
    assert!(
        matches!(err, StoreError::Journal(JournalError::Io { .. })),
        "{err}"
    );
    drop(journal);

    // The line file was renamed into place before the journal append was attempted.
    assert!(store.lines_dir().join("0001.csv").is_file());
    assert!(store.lines_dir().join("0001.json").is_file());
    let st = state_of(&store);
    assert_eq!(st.completed().into_iter().collect::<Vec<_>>(), vec![0]);
    assert_eq!(st.first_missing(3), Some(1));

    // Resume: re-trace line 1 (attempt 2), then line 2.
    let (mut journal, rec) = Journal::open(&store.journal_path(), Arc::new(NoFaults)).unwrap();
    assert_eq!(rec.torn_bytes, 0);
    let (mut m1b, mut p1b) = line(1);
    m1b.id.attempt = 2;
    p1b.heights_um[0] = 42.0;
    store.commit_line(&mut journal, &m1b, &p1b).unwrap();
    let (m2, p2) = line(2);
    store.commit_line(&mut journal, &m2, &p2).unwrap();

    let st = state_of(&store);
    assert!(st.duplicates.is_empty());
    let idx: Vec<u32> = st.lines.iter().map(|l| l.id.index).collect();
    assert_eq!(idx, vec![0, 1, 2], "every line exactly once");
    let lines = store.load_committed(&st.lines).unwrap();
    assert_eq!(lines[1].meta.id.attempt, 2);
    assert_eq!(lines[1].profile.heights_um[0], 42.0);
}

#[test]
fn a_crash_between_the_two_line_files_leaves_an_incomplete_line_that_is_skipped_and_named() {
    let tmp = tempfile::tempdir().unwrap();
    // Line 1's journal append fails; then its JSON is removed, as if the process had been
    // killed between the rename of the CSV and that of the JSON.
    let hook = FailNth::new(WriteStep::Journal, 2, libc::EIO);
    let (store, mut journal, _) = new_scan(tmp.path(), 3, hook);
    let (m0, p0) = line(0);
    store.commit_line(&mut journal, &m0, &p0).unwrap();
    let (m1, p1) = line(1);
    assert!(store.commit_line(&mut journal, &m1, &p1).is_err());
    std::fs::remove_file(store.lines_dir().join("0001.json")).unwrap();
    let loaded = store.load_all().unwrap();
    assert_eq!(loaded.lines.len(), 1);
    assert_eq!(loaded.lines[0].profile, p0);
    assert_eq!(loaded.incomplete, vec![1]);
    let err = store.load_line(1).unwrap_err();
    assert!(matches!(err, StoreError::MissingCompanion { .. }), "{err}");
    drop(journal);
    assert_eq!(state_of(&store).first_missing(3), Some(1));
}

#[test]
fn disk_full_during_a_line_fails_cleanly_with_earlier_lines_intact() {
    for step in [WriteStep::LineCsv, WriteStep::LineJson] {
        let tmp = tempfile::tempdir().unwrap();
        // The third write of this step (line 2) fails with ENOSPC.
        let hook = FailNth::new(step, 2, libc::ENOSPC);
        let (store, mut journal, _) = new_scan(tmp.path(), 4, hook);
        for k in 0..2 {
            let (m, p) = line(k);
            store.commit_line(&mut journal, &m, &p).unwrap();
        }
        let (m2, p2) = line(2);
        let err = store.commit_line(&mut journal, &m2, &p2).unwrap_err();
        assert!(err.is_disk_full(), "{step:?}: {err}");
        assert!(err.to_string().contains("0002"), "names the file: {err}");
        // The scan records its failure and stops.
        journal
            .append(&Record::Stop(StopRecord {
                status: StopStatus::Fail,
                reason: format!("disk full: {err}"),
                cause: None,
                internal: false,
                time: Utc::now(),
            }))
            .unwrap();
        drop(journal);

        let leftovers: Vec<String> = std::fs::read_dir(store.lines_dir())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");
        let st = state_of(&store);
        assert_eq!(st.lines.len(), 2);
        assert_eq!(st.stop.as_ref().map(|s| s.status), Some(StopStatus::Fail));
        let kept = store.load_committed(&st.lines).unwrap();
        for (k, l) in kept.iter().enumerate() {
            assert_eq!(l.profile, line(k as u32).1);
        }
        assert!(!store.lines_dir().join("0002.json").exists());
        assert!(
            !store.lines_dir().join("0002.csv").exists(),
            "{step:?}: never half-kept"
        );
        assert!(store.load_all().unwrap().incomplete.is_empty());
        // a failed scan is not offered for resume
        assert!(find_unfinished(tmp.path()).unwrap().is_empty());
    }
}

fn journal_bytes_with_records(dir: &Path) -> (Vec<u8>, usize) {
    let id = ScanId("s".into());
    let mut j = Journal::create(dir, start_record(&id, 3), Arc::new(NoFaults)).unwrap();
    for k in 0..2u32 {
        let (m, _) = line(k);
        j.append(&Record::Line(surfscan::scan::journal::LineRecord {
            id: m.id,
            csv_sha256: "00".repeat(32),
            time: m.finished_at,
        }))
        .unwrap();
    }
    let before_last = std::fs::read(dir.join("journal.jsonl")).unwrap().len();
    j.append(&Record::Interruption(InterruptionRecord {
        reason: "instrument unplugged".into(),
        device: Some(surfscan::scan::station::Device::Instrument),
        line: Some(2),
        time: Utc.with_ymd_and_hms(2026, 1, 2, 4, 0, 0).unwrap(),
        peer: None,
        pause: None,
    }))
    .unwrap();
    (
        std::fs::read(dir.join("journal.jsonl")).unwrap(),
        before_last,
    )
}

#[test]
fn journal_truncated_at_every_offset_of_its_last_record_recovers_the_previous_records() {
    let tmp = tempfile::tempdir().unwrap();
    let (full, before_last) = journal_bytes_with_records(tmp.path());
    let full_rec = parse_journal(Path::new("j"), &full).unwrap();
    assert_eq!(full_rec.records.len(), 4);
    assert_eq!(full_rec.torn_bytes, 0);
    let previous = &full_rec.records[..3];
    for cut in before_last..full.len() {
        let path = tmp.path().join(format!("j{cut}.jsonl"));
        std::fs::write(&path, &full[..cut]).unwrap();
        let (mut j, rec) = Journal::open(&path, Arc::new(NoFaults)).unwrap();
        assert_eq!(rec.records, previous, "cut at {cut}");
        assert_eq!(rec.torn_bytes, (cut - before_last) as u64, "cut at {cut}");
        assert_eq!(
            std::fs::metadata(&path).unwrap().len(),
            before_last as u64,
            "torn tail truncated on disk (cut at {cut})"
        );
        // Appending after recovery yields a well-formed journal.
        j.append(&full_rec.records[3]).unwrap();
        drop(j);
        assert_eq!(std::fs::read(&path).unwrap(), full, "cut at {cut}");
    }
}

#[test]
fn garbage_after_the_last_record_is_dropped_but_damage_in_the_middle_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let (full, before_last) = journal_bytes_with_records(tmp.path());
    // Zero-filled block after a power loss: invalid last line, terminated.
    let mut zeros = full.clone();
    zeros.extend_from_slice(&[0u8; 37]);
    zeros.push(b'\n');
    let rec = parse_journal(Path::new("j"), &zeros).unwrap();
    assert_eq!(rec.records.len(), 4);
    assert_eq!(rec.torn_bytes, 38);

    // Corrupt the second record (a line record) in the middle.
    let mut bad = full.clone();
    let second_line_start = full.iter().position(|&b| b == b'\n').unwrap() + 1;
    bad[second_line_start + 2] = b'#';
    let err = parse_journal(Path::new("journal.jsonl"), &bad).unwrap_err();
    match &err {
        JournalError::BadRecord {
            line, offset, path, ..
        } => {
            assert_eq!(*line, 2);
            assert_eq!(*offset, second_line_start as u64);
            assert_eq!(path, Path::new("journal.jsonl"));
        }
        other => panic!("expected BadRecord, got {other}"),
    }
    assert!(err.to_string().contains("line 2"));
    let _ = before_last;
}

#[test]
fn duplicate_line_records_keep_the_first_and_are_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let (store, mut journal, _) = new_scan(tmp.path(), 3, Arc::new(NoFaults));
    let (m0, p0) = line(0);
    store.commit_line(&mut journal, &m0, &p0).unwrap();
    let (m1, p1) = line(1);
    store.commit_line(&mut journal, &m1, &p1).unwrap();
    let first_l1 = state_of(&store).lines[1].clone();
    let (mut m1b, p1b) = line(1);
    m1b.id.attempt = 3;
    store.commit_line(&mut journal, &m1b, &p1b).unwrap();
    let st = state_of(&store);
    assert_eq!(st.duplicates, vec![1]);
    assert_eq!(st.lines.len(), 2);
    assert_eq!(st.lines[1], first_l1);
    assert_eq!(st.lines[1].id.attempt, 1);
    assert_eq!(st.first_missing(3), Some(2));
}

#[test]
fn resume_state_and_unfinished_scan_discovery() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path();
    // finished scan
    let id_a = ScanId("20260101T000000Z-a".into());
    let a = ScanStore::create(out, &id_a, Arc::new(NoFaults)).unwrap().0;
    let mut ja = Journal::create(a.root(), start_record(&id_a, 1), Arc::new(NoFaults)).unwrap();
    ja.append(&Record::Stop(StopRecord {
        status: StopStatus::Success,
        reason: "complete".into(),
        cause: None,
        internal: false,
        time: Utc::now(),
    }))
    .unwrap();
    // unfinished scan with line 0 and 2 done (line 1 missing), an interruption
    let id_b = ScanId("20260102T000000Z-b".into());
    let b = ScanStore::create(out, &id_b, Arc::new(NoFaults)).unwrap().0;
    let mut jb = Journal::create(b.root(), start_record(&id_b, 4), Arc::new(NoFaults)).unwrap();
    for k in [0, 2] {
        let (m, p) = line(k);
        b.commit_line(&mut jb, &m, &p).unwrap();
    }
    jb.append(&Record::Interruption(InterruptionRecord {
        reason: "SIGTERM".into(),
        device: None,
        line: Some(3),
        time: Utc::now(),
        peer: None,
        pause: None,
    }))
    .unwrap();
    // a directory without a journal is ignored
    std::fs::create_dir(out.join("not-a-scan")).unwrap();

    assert_eq!(find_unfinished(out).unwrap(), vec![b.root().to_path_buf()]);
    let st = state_of(&b);
    assert!(!st.is_stopped());
    assert_eq!(st.first_missing(4), Some(1));
    assert_eq!(st.interruptions.len(), 1);
    assert_eq!(st.start.plan.lines, 4);
    assert_eq!(st.start.specimen, "block-7");
    assert!(find_unfinished(&out.join("absent")).unwrap().is_empty());

    // A journal without a start record is a named error.
    let p = out.join("x.jsonl");
    std::fs::write(&p, b"{\"class\":\"stop\",\"status\":\"abort\",\"reason\":\"r\",\"time\":\"2026-01-01T00:00:00Z\"}\n").unwrap();
    let rec = parse_journal(&p, &std::fs::read(&p).unwrap()).unwrap();
    let err = ResumeState::from_records(&p, &rec.records).unwrap_err();
    assert!(
        matches!(err, JournalError::NoStart { ref found, .. } if found == "stop"),
        "{err}"
    );
}

#[test]
fn malformed_line_files_are_named_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let (store, mut journal, _) = new_scan(tmp.path(), 3, Arc::new(NoFaults));
    let (m, p) = line(0);
    store.commit_line(&mut journal, &m, &p).unwrap();
    let csv = store.lines_dir().join("0000.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    std::fs::write(&csv, text.replacen("0.0005,", "0.0005;", 1)).unwrap();
    let err = store.load_line(0).unwrap_err();
    assert!(matches!(err, StoreError::CsvRow { line: 3, .. }), "{err}");
    assert!(err.to_string().contains("0000.csv"));

    // heights file changed after commit: checksum mismatch
    std::fs::write(&csv, {
        let changed = text.replace("x_mm,z_um\n0,-0.7\n", "x_mm,z_um\n0,-0.75\n");
        assert_ne!(changed, text);
        changed
    })
    .unwrap();
    let st = state_of(&store);
    let err = store.load_committed(&st.lines).unwrap_err();
    assert!(err.to_string().contains("SHA-256"), "{err}");

    // metadata without heights
    std::fs::remove_file(&csv).unwrap();
    let err = store.load_line(0).unwrap_err();
    assert!(matches!(err, StoreError::MissingCompanion { .. }), "{err}");

    // bad metadata JSON
    let (m1, p1) = line(1);
    store.commit_line(&mut journal, &m1, &p1).unwrap();
    std::fs::write(store.lines_dir().join("0001.json"), "{\"index\": 1").unwrap();
    let err = store.load_line(1).unwrap_err();
    assert!(matches!(err, StoreError::MetaJson { .. }), "{err}");
}

#[test]
fn preflight_refuses_a_scan_larger_than_the_free_space() {
    let tmp = tempfile::tempdir().unwrap();
    let free = surfscan::scan::disk::free_bytes(tmp.path()).unwrap();
    assert!(free > 0);
    assert!(surfscan::scan::disk::preflight_disk(tmp.path(), 31, 1000).is_ok());
    // More points than could fit even at one byte each.
    let err = surfscan::scan::disk::preflight_disk(tmp.path(), u32::MAX, u64::MAX).unwrap_err();
    assert!(matches!(err, StoreError::DiskTooSmall { .. }), "{err}");
}

#[test]
fn metrics_file_is_prometheus_exposition_text() {
    let tmp = tempfile::tempdir().unwrap();
    let mut m = ScanMetrics {
        scan_id: "20260102T030405Z-block-7".into(),
        lines_done: 12,
        lines_total: 31,
        last_line_seconds: Some(41.5),
        line_seconds_sum: 498.0,
        line_seconds_count: 12,
        retries: 2,
        suspensions: 1,
        last_line_unix_seconds: Some(1767323405.0),
        fit_residual_um: Some(0.0125),
        ..Default::default()
    };
    m.reconnects.insert("instrument".into(), 3);
    m.reconnects.insert("stage".into(), 0);
    let path = tmp.path().join("surfscan.prom");
    write_metrics(&path, &m, &NoFaults).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let l = "scan=\"20260102T030405Z-block-7\"";
    for expected in [
        "# TYPE surfscan_lines_done gauge".to_string(),
        format!("surfscan_lines_done{{{l}}} 12"),
        format!("surfscan_lines_planned{{{l}}} 31"),
        format!("surfscan_last_line_duration_seconds{{{l}}} 41.5"),
        "# TYPE surfscan_line_duration_seconds summary".to_string(),
        format!("surfscan_line_duration_seconds_sum{{{l}}} 498"),
        format!("surfscan_line_duration_seconds_count{{{l}}} 12"),
        "# TYPE surfscan_line_retries_total counter".to_string(),
        format!("surfscan_line_retries_total{{{l}}} 2"),
        format!("surfscan_reconnects_total{{{l},device=\"instrument\"}} 3"),
        format!("surfscan_reconnects_total{{{l},device=\"stage\"}} 0"),
        format!("surfscan_suspensions_total{{{l}}} 1"),
        format!("surfscan_last_line_timestamp_seconds{{{l}}} 1767323405"),
        format!("surfscan_fit_residual_micrometres{{{l}}} 0.0125"),
    ] {
        assert!(
            text.lines().any(|x| x == expected),
            "missing {expected:?} in\n{text}"
        );
    }
    // Exposition grammar, checked line by line: comments are HELP/TYPE with a valid type,
    // every sample is `name{labels} value` with a metric name, a TYPE declared before it
    // (summary samples use _sum/_count), and a parseable value.
    let mut declared: Vec<String> = Vec::new();
    assert!(text.ends_with('\n'));
    for line in text.lines() {
        if let Some(rest) = line.strip_prefix("# ") {
            let mut parts = rest.splitn(3, ' ');
            let kw = parts.next().unwrap();
            let name = parts.next().unwrap();
            let tail = parts.next().unwrap();
            assert!(kw == "HELP" || kw == "TYPE", "{line}");
            if kw == "TYPE" {
                assert!(["gauge", "counter", "summary"].contains(&tail), "{line}");
                declared.push(name.to_string());
            }
            continue;
        }
        let (name, rest) = line.split_once('{').expect(line);
        assert!(
            name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !name.starts_with(|c: char| c.is_ascii_digit()),
            "{line}"
        );
        let base = name
            .strip_suffix("_sum")
            .or_else(|| name.strip_suffix("_count"))
            .filter(|b| declared.iter().any(|d| d == b))
            .unwrap_or(name);
        assert!(declared.iter().any(|d| d == base), "undeclared {line}");
        let (labels, value) = rest.rsplit_once("} ").expect(line);
        for pair in labels.split(',') {
            let (k, v) = pair.split_once('=').expect(line);
            assert!(
                k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'),
                "{line}"
            );
            assert!(v.starts_with('"') && v.ends_with('"'), "{line}");
        }
        assert!(value.parse::<f64>().is_ok(), "{line}");
    }
    // No temporary file is left, and a failing write leaves the previous file in place.
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1);
    m.lines_done = 13;
    let hook = FailNth::new(WriteStep::Metrics, 0, libc::ENOSPC);
    assert!(write_metrics(&path, &m, &*hook).unwrap_err().is_disk_full());
    assert_eq!(std::fs::read_to_string(&path).unwrap(), text);
}

// ---- systemd unit -------------------------------------------------------------------

/// `(key, value)` of every directive in `[Service]`.
fn service_directives(unit: &str) -> Vec<(String, String)> {
    let mut section = String::new();
    let mut out = Vec::new();
    for raw in unit.lines() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with(';') {
            continue;
        }
        if line.starts_with('[') {
            section = line.to_string();
            continue;
        }
        if section == "[Service]" {
            let (k, v) = line.split_once('=').expect(line);
            out.push((k.trim().to_string(), v.trim().to_string()));
        }
    }
    out
}

fn seconds(v: &str) -> u64 {
    if let Some(m) = v.strip_suffix("min") {
        m.parse::<u64>().unwrap() * 60
    } else {
        v.trim_end_matches('s').parse().unwrap()
    }
}

#[test]
fn service_unit_has_the_required_directives() {
    let unit = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("systemd/surfscan.service"),
    )
    .unwrap();
    let d = service_directives(&unit);
    let get = |k: &str| -> Vec<&str> {
        d.iter()
            .filter(|(kk, _)| kk == k)
            .map(|(_, v)| v.as_str())
            .collect()
    };
    assert_eq!(get("Type"), ["notify"]);
    assert_eq!(
        get("ExecStart"),
        ["/usr/bin/surfscan daemon --config /etc/surfscan/surfscan.toml"]
    );
    assert!(seconds(get("WatchdogSec")[0]) > 0);
    assert!(
        get("PrivateDevices").is_empty(),
        "PrivateDevices hides the serial ports"
    );
    assert!(get("DynamicUser").is_empty());
    assert_eq!(get("DevicePolicy"), ["closed"]);
    let allow = get("DeviceAllow");
    assert!(
        allow.contains(&"char-ttyUSB rw") && allow.contains(&"char-ttyACM rw"),
        "{allow:?}"
    );
    assert_eq!(get("SupplementaryGroups"), ["dialout"]);
    assert_eq!(get("User"), ["surfscan"]);
    assert_eq!(get("Group"), ["surfscan"]);
    assert_eq!(get("StateDirectory"), ["surfscan"]);
    assert_eq!(get("RuntimeDirectory"), ["surfscan"]);
    assert_eq!(get("ProtectSystem"), ["strict"]);
    assert_eq!(get("ProtectHome"), ["yes"]);
    assert_eq!(get("NoNewPrivileges"), ["yes"]);
    assert_eq!(get("RestrictAddressFamilies"), ["AF_UNIX"]);
    assert_eq!(get("Restart"), ["on-failure"]);
    // Neither a bad configuration nor a station held by another process is cleared by a
    // restart: the unit must not loop on them.
    let no_restart: Vec<&str> = get("RestartPreventExitStatus")
        .iter()
        .flat_map(|v| v.split_whitespace())
        .collect();
    assert!(
        no_restart.contains(&"69") && no_restart.contains(&"78"),
        "{no_restart:?}"
    );
    assert!(seconds(get("TimeoutStopSec")[0]) >= 120);

    let sysusers = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("systemd/surfscan.sysusers"),
    )
    .unwrap();
    assert!(sysusers.lines().any(|l| l.starts_with("g surfscan ")));
    assert!(sysusers.lines().any(|l| l.starts_with("u surfscan ")));
    let rules = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("systemd/99-surfscan.rules"),
    )
    .unwrap();
    let rules: Vec<&str> = rules
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .collect();
    assert_eq!(rules.len(), 2);
    for (rule, link) in rules
        .iter()
        .zip(["SYMLINK+=\"sj210\"", "SYMLINK+=\"ystage\""])
    {
        for needed in [
            link,
            "GROUP=\"dialout\"",
            "ENV{ID_MM_DEVICE_IGNORE}=\"1\"",
            "TAG+=\"systemd\"",
            "ATTRS{serial}==",
        ] {
            assert!(rule.contains(needed), "{needed} missing in {rule}");
        }
    }
}

/// The journal bytes with the CRC member of every record removed, as an older version wrote
/// them.
fn without_crcs(bytes: &[u8]) -> Vec<u8> {
    let text = String::from_utf8(bytes.to_vec()).unwrap();
    let mut out = String::new();
    for line in text.split_inclusive('\n') {
        let at = line.rfind(",\"crc\":\"").expect("every record has a CRC");
        out.push_str(&line[..at]);
        out.push_str("}\n");
    }
    out.into_bytes()
}

/// Byte offset of the first digit of `key`'s value in record `n` (0-based) of `bytes`.
fn digit_of(bytes: &[u8], n: usize, key: &str) -> usize {
    let start: usize = bytes
        .split_inclusive(|&b| b == b'\n')
        .take(n)
        .map(<[u8]>::len)
        .sum();
    let line = std::str::from_utf8(&bytes[start..]).unwrap();
    let at = line.find(&format!("\"{key}\":")).unwrap() + key.len() + 3;
    assert!(
        line.as_bytes()[at].is_ascii_digit(),
        "{}",
        &line[at..at + 10]
    );
    start + at
}

fn flip_digit(bytes: &mut [u8], at: usize) {
    bytes[at] = if bytes[at] == b'9' {
        b'8'
    } else {
        bytes[at] + 1
    };
}

#[test]
fn a_flipped_digit_is_damage_in_the_middle_and_a_torn_tail_at_the_end() {
    let tmp = tempfile::tempdir().unwrap();
    let (full, before_last) = journal_bytes_with_records(tmp.path());
    let intact = parse_journal(Path::new("j"), &full).unwrap().records;

    // The second line record (journal line 3) with its index one digit off is still valid
    // JSON, so only the CRC can tell: the journal is damaged there.
    let mut bad = full.clone();
    let at = digit_of(&full, 2, "index");
    flip_digit(&mut bad, at);
    assert!(serde_json::from_slice::<serde_json::Value>(
        bad.split(|&b| b == b'\n').nth(2).unwrap()
    )
    .is_ok());
    let err = parse_journal(Path::new("journal.jsonl"), &bad).unwrap_err();
    match &err {
        JournalError::BadRecord { line, reason, .. } => {
            assert_eq!(*line, 3);
            assert!(reason.contains("CRC-32"), "{reason}");
        }
        other => panic!("expected BadRecord, got {other}"),
    }

    // The same flip in the last record: a torn tail, truncated on open.
    let mut torn = full.clone();
    let at = digit_of(&full, 3, "line");
    flip_digit(&mut torn, at);
    let path = tmp.path().join("torn.jsonl");
    std::fs::write(&path, &torn).unwrap();
    let (_, rec) = Journal::open(&path, Arc::new(NoFaults)).unwrap();
    assert_eq!(rec.records, intact[..3]);
    assert_eq!(rec.torn_bytes, (full.len() - before_last) as u64);
    assert_eq!(std::fs::read(&path).unwrap(), full[..before_last]);
}

#[test]
fn journals_without_crcs_are_read_and_appended_to_with_crcs() {
    let tmp = tempfile::tempdir().unwrap();
    let (full, before_last) = journal_bytes_with_records(tmp.path());
    let intact = parse_journal(Path::new("j"), &full).unwrap().records;
    let old = without_crcs(&full);
    assert!(!String::from_utf8_lossy(&old).contains("crc"));
    let path = tmp.path().join("old.jsonl");
    std::fs::write(&path, &old).unwrap();
    let (mut j, rec) = Journal::open(&path, Arc::new(NoFaults)).unwrap();
    assert_eq!(rec.records, intact);
    assert_eq!(rec.torn_bytes, 0);
    // An old journal goes on with records that carry a CRC.
    j.append(&intact[3]).unwrap();
    drop(j);
    let appended = std::fs::read(&path).unwrap();
    assert_eq!(appended[old.len()..], full[before_last..]);
    let rec = parse_journal(&path, &appended).unwrap();
    assert_eq!(rec.records.len(), 5);

    // But once a record has a CRC, one without it (its CRC member mangled into another key)
    // is damage, not an old record.
    let mut mangled = full.clone();
    let second = full.iter().position(|&b| b == b'\n').unwrap() + 1;
    let crc_at = second
        + std::str::from_utf8(&full[second..])
            .unwrap()
            .find(",\"crc\":")
            .unwrap();
    mangled[crc_at + 4] = b'x'; // "crc" -> "cxc"
    let err = parse_journal(Path::new("j"), &mangled).unwrap_err();
    assert!(err.to_string().contains("no CRC"), "{err}");
}

#[test]
fn the_scan_to_resume_comes_from_the_journals_and_a_damaged_one_is_skipped_and_named() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path();
    let scan = |name: &str, stopped: bool| {
        let id = ScanId(name.into());
        let s = ScanStore::create(out, &id, Arc::new(NoFaults)).unwrap().0;
        let mut j = Journal::create(s.root(), start_record(&id, 3), Arc::new(NoFaults)).unwrap();
        let (m, p) = line(0);
        s.commit_line(&mut j, &m, &p).unwrap();
        if stopped {
            j.append(&Record::Stop(StopRecord {
                status: StopStatus::Success,
                reason: "complete".into(),
                cause: None,
                internal: false,
                time: Utc::now(),
            }))
            .unwrap();
        }
        s
    };
    // Started in this order, the clock set back in between: names (and start times, all the
    // same here) say nothing about which came last.
    let first = scan("20270101T000000Z-first", false);
    let finished = scan("20260601T000000Z-finished", true);
    let last = scan("20250101T000000Z-last", false);
    let survey = surfscan::scan::journal::survey(out).unwrap();
    assert!(survey.damaged.is_empty());
    let order: Vec<&std::path::Path> = survey.unfinished.iter().map(|u| u.dir.as_path()).collect();
    assert_eq!(order, vec![first.root(), last.root()]);
    assert_eq!(survey.to_resume().unwrap().dir, last.root());
    assert_eq!(
        survey
            .unfinished
            .iter()
            .map(|u| u.sequence)
            .collect::<Vec<_>>(),
        vec![1, 3]
    );
    assert_eq!(survey.max_sequence, 3);
    assert_eq!(surfscan::scan::journal::next_sequence(out), 4);

    // A damaged record in the finished scan's journal: that scan is named and skipped, the
    // others are found as before.
    let jpath = finished.journal_path();
    let mut bytes = std::fs::read(&jpath).unwrap();
    let at = digit_of(&bytes, 1, "index");
    flip_digit(&mut bytes, at);
    std::fs::write(&jpath, &bytes).unwrap();
    let survey = surfscan::scan::journal::survey(out).unwrap();
    assert_eq!(survey.unfinished.len(), 2);
    assert_eq!(survey.to_resume().unwrap().dir, last.root());
    let warnings = survey.warnings();
    assert_eq!(warnings.len(), 1);
    assert!(
        warnings[0].contains(&jpath.display().to_string())
            && warnings[0].contains("line 2")
            && warnings[0].contains("skipped"),
        "{}",
        warnings[0]
    );
    assert_eq!(
        find_unfinished(out).unwrap(),
        vec![first.root(), last.root()]
    );
}

#[test]
fn a_committed_line_changed_on_disk_is_moved_aside_with_both_hashes_and_traced_again() {
    let tmp = tempfile::tempdir().unwrap();
    let (store, mut journal, _) = new_scan(tmp.path(), 4, Arc::new(NoFaults));
    for k in 0..4 {
        let (m, p) = line(k);
        store.commit_line(&mut journal, &m, &p).unwrap();
    }
    let st = state_of(&store);
    let csv = store.lines_dir().join("0001.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    // One flipped digit in a height.
    let changed = text.replacen("-0.6", "-0.7", 1);
    assert_ne!(changed, text);
    std::fs::write(&csv, &changed).unwrap();
    // And line 3's heights file gone altogether.
    std::fs::remove_file(store.lines_dir().join("0003.csv")).unwrap();

    let now = Utc.with_ymd_and_hms(2026, 1, 3, 0, 0, 0).unwrap();
    let got = store.load_committed_repairing(&st.lines, now).unwrap();
    let kept: Vec<u32> = got.lines.iter().map(|l| l.meta.id.index).collect();
    assert_eq!(kept, vec![0, 2]);
    assert_eq!(got.quarantined.len(), 2);
    let q = &got.quarantined[0];
    assert_eq!(q.index, 1);
    assert_eq!(q.expected_sha256, st.lines[1].csv_sha256);
    assert_eq!(
        q.found_sha256,
        surfscan::scan::store::hex_sha256(changed.as_bytes())
    );
    assert_eq!(q.moved_to, "quarantine/0001.csv");
    assert_eq!(
        std::fs::read_to_string(store.root().join(&q.moved_to)).unwrap(),
        changed
    );
    assert!(store.root().join("quarantine/0001.json").exists());
    assert!(!csv.exists() && !store.lines_dir().join("0001.json").exists());
    assert_eq!(got.quarantined[1].index, 3);
    assert_eq!(got.quarantined[1].found_sha256, "");

    // Journaled, the lines no longer count; traced again, the new records do.
    for q in &got.quarantined {
        journal.append(&Record::Quarantine(q.clone())).unwrap();
    }
    let st = state_of(&store);
    assert_eq!(st.completed().into_iter().collect::<Vec<_>>(), vec![0, 2]);
    assert_eq!(st.first_missing(4), Some(1));
    assert_eq!(st.quarantined.len(), 2);
    for k in [1, 3] {
        let (mut m, p) = line(k);
        m.id.attempt = 2;
        store.commit_line(&mut journal, &m, &p).unwrap();
    }
    let st = state_of(&store);
    assert!(st.duplicates.is_empty());
    assert_eq!(st.first_missing(4), None);
    let again = store.load_committed_repairing(&st.lines, now).unwrap();
    assert_eq!(again.lines.len(), 4);
    assert!(again.quarantined.is_empty());

    // Quarantined a second time, the line gets the next free name.
    std::fs::write(&csv, &changed).unwrap();
    let third = store.load_committed_repairing(&st.lines, now).unwrap();
    assert_eq!(third.quarantined[0].moved_to, "quarantine/0001-2.csv");
}

#[test]
fn a_byte_that_is_not_utf8_in_a_line_file_is_damage_set_aside_not_a_read_failure() {
    let tmp = tempfile::tempdir().unwrap();
    let (store, mut journal, _) = new_scan(tmp.path(), 3, Arc::new(NoFaults));
    for k in 0..3 {
        let (m, p) = line(k);
        store.commit_line(&mut journal, &m, &p).unwrap();
    }
    let st = state_of(&store);
    // One byte of line 1's metadata turned into 0xFF: its heights file still matches its
    // journal record, but the line cannot be read. The scan resumes without it.
    let meta = store.lines_dir().join("0001.json");
    let mut bytes = std::fs::read(&meta).unwrap();
    bytes[7] = 0xFF;
    std::fs::write(&meta, &bytes).unwrap();
    // Read for fit or analyze: a damaged file, named with the byte, not an I/O error.
    let e = store.load_all().unwrap_err();
    assert!(
        matches!(&e, StoreError::NotText { path, byte: 7 } if *path == meta),
        "{e:?}"
    );
    assert!(e.to_string().contains("byte 7 is not UTF-8 text"), "{e}");
    let now = Utc.with_ymd_and_hms(2026, 1, 3, 0, 0, 0).unwrap();
    let got = store.load_committed_repairing(&st.lines, now).unwrap();
    let kept: Vec<u32> = got.lines.iter().map(|l| l.meta.id.index).collect();
    assert_eq!(kept, vec![0, 2]);
    assert_eq!(got.quarantined.len(), 1);
    assert_eq!(got.quarantined[0].index, 1);
    assert!(
        got.quarantined[0].reason.contains("is not UTF-8 text"),
        "{}",
        got.quarantined[0].reason
    );
    assert!(store.root().join("quarantine/0001.json").exists());
}

/// A link planted in the output directory (at the next predictable scan id, dangling; or to a
/// real scan elsewhere) neither keeps a scan from starting nor redirects its writes.
#[test]
fn a_planted_link_neither_blocks_a_new_scan_nor_is_written_through() {
    use std::os::unix::fs::symlink;
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let elsewhere = tmp.path().join("elsewhere");
    std::fs::create_dir_all(&out).unwrap();
    let id = ScanId::new(
        Utc.with_ymd_and_hms(2026, 1, 2, 3, 4, 5).unwrap(),
        "Block 7",
    );
    // Dangling, to where the scan would then have been created.
    symlink(elsewhere.join("victim"), out.join(&id.0)).unwrap();
    let (store, got) = ScanStore::create(&out, &id, Arc::new(NoFaults)).unwrap();
    assert_eq!(got.0, format!("{}-2", id.0));
    assert_eq!(store.root(), out.join(&got.0));
    assert!(std::fs::symlink_metadata(store.root()).unwrap().is_dir());
    assert!(!elsewhere.exists(), "nothing was created through the link");

    // An unfinished scan reached through a link in the output directory: not surveyed (so
    // never resumed nor written to), and a store is never opened through it.
    let real = ScanStore::create(
        &elsewhere,
        &ScanId("20260101T000000Z-b".into()),
        Arc::new(NoFaults),
    )
    .unwrap()
    .0;
    let mut j = Journal::create(real.root(), start_record(&id, 4), Arc::new(NoFaults)).unwrap();
    let (m, p) = line(0);
    real.commit_line(&mut j, &m, &p).unwrap();
    let linked = out.join("20260101T000000Z-b");
    symlink(real.root(), &linked).unwrap();
    let survey = surfscan::scan::journal::survey(&out).unwrap();
    assert!(survey.unfinished.is_empty(), "{:?}", survey.unfinished);
    let e = ScanStore::open(&linked, Arc::new(NoFaults)).unwrap_err();
    assert!(e.to_string().contains("symbolic link"), "{e}");
    // A link inside a scan's directory in place of a line's file is refused on write.
    let lines = store.root().join("lines");
    let planted = lines.join(surfscan::scan::store::csv_name(m.id.index));
    symlink(tmp.path().join("target.csv"), &planted).unwrap();
    let j2 = Journal::create(store.root(), start_record(&got, 4), Arc::new(NoFaults));
    let mut j2 = j2.unwrap();
    let e = store.commit_line(&mut j2, &m, &p).unwrap_err();
    assert!(e.to_string().contains("symbolic link"), "{e}");
    assert!(!tmp.path().join("target.csv").exists());
}
