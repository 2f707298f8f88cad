//! A whole scan on a Zaber axis: the real `surfscan scan` binary against the simulated SJ-210
//! and a simulated Zaber axis over pseudo-terminals — powered up without a reference,
//! power-cycled or stalled in the middle of the scan, or with microsteps that make the
//! 0.01 mm step inexact — and what the scan left on disk.
//!
//! The instrument serves line k's heights only while the carriage stands at line k's y, so a
//! stored line with the served heights proves the stage was where the line says.

use crate::common::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use surfscan::scan::journal::Record;
use surfscan_sim::grbl::{StageFault, StageShared};
use surfscan_sim::zaber::ZaberSimConfig;
use surfscan_sim::{InstrumentConfig, SimHandle, Simulator};

/// y of line 0, mm: Zaber positions are microsteps above the home sensor, all positive.
const Y0_MM: f64 = 20.0;
const LINES: usize = 8;

fn target_nm(k: usize) -> i64 {
    20_000_000 + 10_000 * k as i64
}

struct ZaberRig {
    tmp: tempfile::TempDir,
    sim: Option<SimHandle>,
    stage: Arc<StageShared>,
    instrument_link: PathBuf,
    stage_link: PathBuf,
}

/// An axis just powered up 30 mm above its home sensor (position 0 there, `WR` until homed).
fn powered_up(nm_per_microstep: f64) -> ZaberSimConfig {
    let per_mm = 1e6 / nm_per_microstep;
    ZaberSimConfig {
        nm_per_microstep,
        limit_max: (95.0 * per_mm) as i64,
        backlash: (0.02 * per_mm).round() as i64,
        start: (30.0 * per_mm) as i64,
        homed_at_start: false,
        time_scale: STAGE_SPEED_UP,
        ..ZaberSimConfig::default()
    }
}

impl ZaberRig {
    async fn start(axis: ZaberSimConfig) -> ZaberRig {
        let tmp = tempfile::tempdir().expect("temp dir");
        let instrument_link = tmp.path().join("sj210");
        let stage_link = tmp.path().join("ystage");
        let stage = StageShared::new();
        let mut profiles = profile_set(LINES);
        profiles.y_first_mm = Y0_MM;
        let sim = Simulator::new(&instrument_link)
            .instrument(InstrumentConfig {
                time_scale: 1.0 / SPEED_UP,
                ..InstrumentConfig::default()
            })
            .profiles(profiles)
            .baud(38400 * 100)
            .zaber_stage(&stage_link, axis, stage.clone());
        let handle = crate::common::started(sim).await;
        ZaberRig {
            tmp,
            sim: Some(handle),
            stage,
            instrument_link,
            stage_link,
        }
    }

    /// A station configuration for this rig; `stage_extra` is appended to `[stage]`.
    fn config(&self, out: &str, nm_per_microstep: f64, stage_extra: &str) -> PathBuf {
        let text = format!(
            r#"{instrument}
[stage]
port = {stage:?}
protocol = "zaber"
nm-per-microstep = {nm_per_microstep:?}
soft-limit-min-mm = 1.0
soft-limit-max-mm = 90.0
backlash-mm = 0.05
settle-ms = 2
poll-interval-ms = 100
home-on-start = false
{stage_extra}

[scan]
lines = {LINES}
y-start-mm = {Y0_MM:?}
y-step-mm = {Y_STEP_MM:?}
max-line-attempts = 3
reconnect-initial-ms = 50
reconnect-max-ms = 400

[fit]
degree-u = 5
degree-v = 3

[output]
dir = {dir:?}

[control]
socket = {sock:?}
"#,
            instrument = instrument_section(&self.instrument_link),
            stage = self.stage_link.display().to_string(),
            dir = self.out(out).display().to_string(),
            sock = self.tmp.path().join("control.sock").display().to_string(),
        );
        let path = self.tmp.path().join(format!("{out}.toml"));
        std::fs::write(&path, text).expect("write config");
        path
    }

    fn out(&self, out: &str) -> PathBuf {
        self.tmp.path().join(out)
    }

    async fn shutdown(mut self) {
        if let Some(h) = self.sim.take() {
            h.shutdown().await;
        }
    }
}

/// Every line 0..LINES stored once with the heights served at its y, the target recorded,
/// and a read-back within `tolerance_nm` of it; the scan's stop record is a success.
fn assert_scan_lands_every_line(dir: &Path, tolerance_nm: i64) -> Vec<Record> {
    let records = assert_journal_complete(dir, LINES);
    for k in 0..LINES {
        let csv = std::fs::read_to_string(dir.join(format!("lines/{k:04}.csv"))).expect("csv");
        let heights: Vec<f64> = csv
            .lines()
            .skip(1)
            .map(|row| row.split_once(',').expect("two columns").1.parse().unwrap())
            .collect();
        assert_eq!(
            heights,
            served_heights_um(k),
            "line {k}: the heights of another y were stored"
        );
        let meta = line_meta(dir, k as u32);
        assert_eq!(meta["y_target_nm"], target_nm(k), "line {k}");
        let readback = meta["y_readback_nm"].as_i64().expect("a read-back");
        assert!(
            (readback - target_nm(k)).abs() <= tolerance_nm,
            "line {k}: read back {readback} nm for {} nm",
            target_nm(k)
        );
    }
    records
}

/// The issue's symptom: an axis that powers up un-referenced answers `WR` on every poll of
/// its running home; the scan must home it once and run, not refuse to start.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_starts_on_an_axis_powered_up_without_a_reference() {
    let rig = ZaberRig::start(powered_up(125.0)).await;
    let o = run_scan(&rig.config("out", 125.0, ""), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    assert_eq!(rig.stage.homing_cycles(), 1, "{}", describe(&o));
    let records = assert_scan_lands_every_line(&scan_dir(&rig.out("out")), 0);
    assert!(
        interruptions(&records).is_empty(),
        "{:?}",
        interruptions(&records)
    );
    assert_eq!(rig.stage.true_position_nm(), target_nm(LINES - 1));
    rig.shutdown().await;
}

/// Runs a scan, injects `fault` into the axis once three lines are committed, and checks
/// that the scan re-homed (the journal naming `flag`) and still landed every line at its y.
async fn scan_through(fault: StageFault, flag: &str) {
    let rig = ZaberRig::start(powered_up(125.0)).await;
    let cfg = rig.config("out", 125.0, "");
    let scan = tokio::spawn(async move { run_scan(&cfg, &[]).await });
    let out = rig.out("out");
    wait_until(Duration::from_secs(60), "three lines committed", || {
        committed_lines(&out) >= 3
    })
    .await;
    rig.stage.inject(fault);
    let o = scan.await.expect("scan task");
    assert!(o.status.success(), "{}", describe(&o));
    assert_eq!(rig.stage.homing_cycles(), 2, "{}", describe(&o));
    let records = assert_scan_lands_every_line(&scan_dir(&out), 0);
    let why = interruptions(&records);
    assert!(
        why.iter()
            .any(|r| r.contains(flag) && r.contains("re-homing")),
        "{why:?}"
    );
    rig.shutdown().await;
}

/// A power cycle in the middle of the scan: the axis reads 0 where it stands with `WR`. The
/// scan must notice before it traces at a wrong y, re-home and go on where it was.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_power_cycle_mid_scan_rehomes_and_every_line_lands_at_its_y() {
    scan_through(StageFault::PositionLostWr, "WR").await;
}

/// A stall during a move: the carriage stops half way (`FS`). The line is re-traced after a
/// home, never traced where the carriage happened to stop.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stall_mid_scan_rehomes_and_every_line_lands_at_its_y() {
    scan_through(StageFault::Stall, "FS").await;
}

/// 0.047625 µm microsteps (a fine lead-screw axis): 0.01 mm is 209.97 microsteps. Without
/// `allow-inexact-step` the configuration is refused (exit 78) before anything moves, naming
/// the key, the microstep and the setting; with
/// it every target is rounded once to the nearest microstep (never more than half of one
/// off, no drift along the scan), and the rounding is recorded with the scan.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_microstep_that_makes_the_step_inexact_is_refused_or_rounded_and_recorded() {
    let fine = 47.625;
    let rig = ZaberRig::start(powered_up(fine)).await;
    let o = run_scan(&rig.config("refused", fine, ""), &[]).await;
    assert_eq!(o.status.code(), Some(78), "{}", describe(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("scan.y-step-mm")
            && err.contains("0.01 mm is 209.9738 of the stage's steps")
            && err.contains("allow-inexact-step"),
        "{}",
        describe(&o)
    );
    assert_eq!(rig.stage.moves_started(), 0, "nothing moved");
    assert_eq!(rig.stage.homing_cycles(), 0, "nothing homed");

    let o = run_scan(&rig.config("out", fine, "allow-inexact-step = true"), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    // Half a microstep, and the nm the read-back is rounded to.
    let records = assert_scan_lands_every_line(&scan_dir(&rig.out("out")), 24);
    let why = interruptions(&records);
    assert!(
        why.iter()
            .any(|r| r.contains("warning at start") && r.contains("rounded")),
        "{why:?}"
    );
    let off = (rig.stage.true_position_nm() - target_nm(LINES - 1)).abs();
    assert!(off <= 24, "the last line's carriage is {off} nm off");
    rig.shutdown().await;
}

/// The instrument's and the Zaber stage's ports swapped in the configuration. A Zaber
/// ignores the SJ-210's lines (it answers only lines that begin with `/`), so the
/// instrument's port is silent from the start; asked as a stage would be, it answers as a
/// Zaber, and the scan refuses to start naming the swap with both configured ports and the
/// keys that hold them, instead of waiting for a silent instrument. Nothing moves.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn swapped_ports_with_a_zaber_stage_are_named_as_swapped() {
    let rig = ZaberRig::start(powered_up(125.0)).await;
    let config = rig.config("out", 125.0, "");
    let (i, s) = swap_ports(&config, &rig.instrument_link, &rig.stage_link);
    let o = tokio::time::timeout(Duration::from_secs(120), run_scan(&config, &[]))
        .await
        .expect("the scan ends");
    assert!(!o.status.success(), "{}", describe(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("ports look swapped")
            && err.contains(&format!(
                "exchange the values of [instrument] port = {s} and [stage] port = {i}"
            ))
            && err.contains("\"@01 "),
        "{}",
        describe(&o)
    );
    assert_eq!(rig.stage.moves_started(), 0, "nothing moved");
    rig.shutdown().await;
}
