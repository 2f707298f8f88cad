//! Scan directories written by an earlier surfscan still load, resume and analyse: the
//! fixture `tests/data/scan-e46f88d/` is a scan of the rig's 8-line profile set (see
//! [`crate::common`]) written by the binary of commit e46f88d, with a stage reset before
//! line 1, the instrument unplugged during line 3, and a crash (`kill -9`) after line 6 was
//! committed. The expected values come from how that scan was run (the plan, the served
//! heights, what the faults do), not from reading the files with the current code.

use crate::common::*;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use surfscan::profile::ProfileKind;
use surfscan::scan::faults::NoFaults;
use surfscan::scan::journal::{encode_record, read_journal, ResumeState};
use surfscan::scan::station::Device;
use surfscan::scan::store::ScanStore;

/// The scan directory name inside the fixture.
const SCAN: &str = "20261202T032241Z-coupon-a-17";
/// Lines the crashed scan had committed.
const COMMITTED: usize = 6;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/scan-e46f88d")
        .join(SCAN)
}

#[test]
fn line_files_of_an_older_version_load_with_their_values() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join(SCAN);
    copy_dir(&fixture(), &dir);
    let store = ScanStore::open(&dir, Arc::new(NoFaults)).unwrap();
    let loaded = store.load_all().unwrap();
    assert!(loaded.incomplete.is_empty());
    assert_eq!(loaded.lines.len(), COMMITTED);
    for (k, line) in loaded.lines.iter().enumerate() {
        let id = line.meta.id;
        assert_eq!(id.index, k as u32);
        assert_eq!(
            id.y_target_nm.0,
            target_nm(k),
            "line {k}: the plan's target"
        );
        assert_eq!(
            id.y_readback_nm.map(|n| n.0),
            Some(target_nm(k)),
            "line {k}: GRBL reads back its target"
        );
        // Every line was committed on its first attempt: the faults struck between lines
        // (the stage reset) or abandoned a trace that never reached the disk (the unplug).
        assert_eq!(id.attempt, 1, "line {k}");
        assert_eq!(id.points, POINTS, "line {k}");
        let p = &line.meta.profile;
        // The rig's `pitch-x-um = 1.5`; the simulator exports an R profile under its default
        // conditions (ISO 1997, Gaussian, λc 2.5 mm, λs 8 µm).
        assert_eq!(p.pitch_x_mm, 0.0015);
        assert_eq!(p.kind, ProfileKind::R);
        assert_eq!(p.conditions.standard.as_deref(), Some("ISO1997"));
        assert_eq!(p.conditions.lambda_c_mm, Some(2.5));
        assert_eq!(p.conditions.lambda_s_um, Some(8.0));
        // The profile is the header with the heights the simulator served, bit for bit.
        assert_eq!(line.profile.header(), *p);
        let want = served_heights_um(k);
        assert_eq!(line.profile.heights_um.len(), want.len());
        for (i, (g, w)) in line.profile.heights_um.iter().zip(&want).enumerate() {
            assert_eq!(g.to_bits(), w.to_bits(), "line {k} point {i}");
        }
        let names: Vec<&str> = line.meta.results.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names.first(), Some(&"Ra"), "line {k}: {names:?}");
        assert!(line.meta.started_at < line.meta.finished_at, "line {k}");
    }
    // Written back, each metadata file has the members and values it was read from.
    for k in 0..COMMITTED {
        let path = dir.join("lines").join(format!("{k:04}.json"));
        let text = std::fs::read_to_string(&path).unwrap();
        let as_read: serde_json::Value = serde_json::from_str(&text).unwrap();
        let meta: surfscan::scan::line::LineMeta = serde_json::from_str(&text).unwrap();
        assert_eq!(serde_json::to_value(&meta).unwrap(), as_read, "{path:?}");
    }
}

#[test]
fn a_journal_of_an_older_version_reads_and_every_record_encodes_to_its_bytes() {
    let path = fixture().join("journal.jsonl");
    let bytes = std::fs::read(&path).unwrap();
    let rec = read_journal(&path).unwrap();
    assert_eq!(rec.torn_bytes, 0);
    // Each record, written again, is the line that was read, CRC included.
    let lines: Vec<&[u8]> = bytes
        .split(|&b| b == b'\n')
        .filter(|l| !l.is_empty())
        .collect();
    assert_eq!(lines.len(), rec.records.len());
    for (r, line) in rec.records.iter().zip(&lines) {
        assert_eq!(
            encode_record(r).unwrap(),
            *line,
            "{}",
            String::from_utf8_lossy(line)
        );
    }
    let state = ResumeState::from_records(&path, &rec.records).unwrap();
    assert!(state.stop.is_none(), "the scan crashed: no stop record");
    assert_eq!(state.start.plan.lines, 8);
    assert_eq!(
        (state.start.plan.degree_u, state.start.plan.degree_v),
        (5, 3)
    );
    assert_eq!(state.start.specimen, "coupon A-17");
    assert_eq!(state.first_missing(8), Some(COMMITTED as u32));
    for (k, l) in state.lines.iter().enumerate() {
        assert_eq!(l.id.index, k as u32);
        assert_eq!(l.id.y_target_nm.0, target_nm(k));
        assert_eq!(l.id.points, POINTS);
        let csv = std::fs::read(fixture().join("lines").join(format!("{k:04}.csv"))).unwrap();
        let sha: String = Sha256::digest(&csv)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(l.csv_sha256, sha, "line {k}");
    }
    // The stage reset before line 1 and the instrument unplugged during line 3 (index 2):
    // each interruption names its device, typed.
    let devices: Vec<(Option<Device>, Option<u32>)> = state
        .interruptions
        .iter()
        .map(|i| (i.device, i.line))
        .collect();
    assert_eq!(devices.first(), Some(&(Some(Device::Stage), Some(0))));
    assert!(
        devices.len() >= 3
            && devices[1..]
                .iter()
                .all(|d| *d == (Some(Device::Instrument), Some(2))),
        "{devices:?}"
    );
    for i in &state.interruptions {
        let named = i.device.map(|d| d.name()).unwrap_or("none");
        assert!(i.reason.contains(named), "{named}: {}", i.reason);
    }
}

/// The older scan, resumed by this binary, completes to the surface an uninterrupted scan of
/// the same lines gives, and then analyses.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_of_an_older_version_resumes_to_the_uninterrupted_surface_and_analyses() {
    let rig = Rig::start(RigOptions::default()).await;
    assert_eq!(rig.options.lines, 8);
    assert_eq!(rig.options.degrees, (5, 3));
    let reference = {
        let o = run_scan(&rig.config("reference"), &[]).await;
        assert!(o.status.success(), "{}", describe(&o));
        let dir = scan_dir(&rig.out_dir("reference"));
        surface_bits(&dir.join("surface.igs"))
    };
    let target = rig.out_dir("out").join(SCAN);
    copy_dir(&fixture(), &target);
    let o = run_scan(&rig.config("out"), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    assert_eq!(
        scan_dir(&rig.out_dir("out")),
        target,
        "the older scan resumed"
    );
    assert_lines_exactly(&target, 8);
    assert_journal_complete(&target, 8);
    assert_eq!(surface_bits(&target.join("surface.igs")), reference);

    let partial = rig.tmp.path().join("partial").join(SCAN);
    copy_dir(&fixture(), &partial);
    let analysed = rig.tmp.path().join("analysed");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(&partial)
        .arg("--out")
        .arg(&analysed)
        .output()
        .unwrap();
    // The fixture is a partial scan: characterised with its 6 lines (exit 0 or 3 by
    // whether every section could be made, never an error).
    assert!(matches!(o.status.code(), Some(0 | 3)), "{}", describe(&o));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(analysed.join("report.json")).unwrap()).unwrap();
    assert_eq!(
        report["scan"]["lines_used"],
        serde_json::json!([0, 1, 2, 3, 4, 5])
    );
    rig.shutdown().await;
}
