//! The station configuration the simulator writes for its own links (`surfscan-sim
//! --write-config`) runs a real scan unedited: `surfscan check-config` accepts it and `surfscan
//! scan` completes with line k holding the simulator's profile k, for GRBL stages homing at
//! either end (and a HOMING_FORCE_SET_ORIGIN build) with backlash, and for a Zaber stage.
//! The served profiles are the independent reference for every stored height.

use crate::common::*;
use std::path::Path;
use std::process::Command;
use surfscan_sim::grbl::{GrblSimConfig, StageShared};
use surfscan_sim::station_config::{station_config, SimStage, StationConfigRequest};
use surfscan_sim::zaber::ZaberSimConfig;
use surfscan_sim::{InstrumentConfig, Simulator};

/// Six lines: the fewest a degree-5 surface needs, each different from the others.
const LINES: usize = 6;

enum Stage {
    Grbl(GrblSimConfig),
    Zaber(ZaberSimConfig),
}

/// Writes the simulator's configuration, serves it, scans with it and checks every line.
async fn scan_with_the_written_config(stage: Stage) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path();
    let (instrument_link, stage_link) = (dir.join("sj210"), dir.join("ystage"));
    let instrument = InstrumentConfig {
        time_scale: 1.0 / SPEED_UP,
        ..InstrumentConfig::default()
    };
    let written = station_config(
        &StationConfigRequest {
            instrument_link: &instrument_link,
            instrument: &instrument,
            baud: 38400,
            line_check: false,
            stage_link: &stage_link,
            stage: match &stage {
                Stage::Grbl(g) => SimStage::Grbl(g),
                Stage::Zaber(z) => SimStage::Zaber(z),
            },
            output_dir: &dir.join("scans"),
            control_socket: &dir.join("control.sock"),
        },
        &profile_set(LINES),
    )
    .expect("a configuration for these settings");
    let config = dir.join("station.toml");
    std::fs::write(&config, &written.toml).expect("write the configuration");

    let checked = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["check-config", "--config"])
        .arg(&config)
        .output()
        .expect("check-config runs");
    assert!(
        checked.status.success(),
        "{}\n{}",
        describe(&checked),
        written.toml
    );

    let mut sim = Simulator::new(&instrument_link)
        .instrument(instrument)
        .profiles(written.profiles.clone());
    sim = match stage {
        Stage::Grbl(g) => sim.grbl_stage(&stage_link, g, StageShared::new()),
        Stage::Zaber(z) => sim.zaber_stage(&stage_link, z, StageShared::new()),
    };
    let handle = crate::common::started(sim).await;
    let o = run_scan(&config, &[]).await;
    handle.shutdown().await;
    assert!(o.status.success(), "{}\n{}", describe(&o), written.toml);

    let scan = scan_dir(&dir.join("scans"));
    assert_journal_complete(&scan, LINES);
    let y_start_nm = (written.y_start_mm * 1e6).round() as i64;
    for k in 0..LINES {
        assert_eq!(
            stored_heights_um(&scan, k),
            served_heights_um(k),
            "line {k} holds the simulator's profile {k}\n{}",
            written.toml
        );
        let meta: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(scan.join(format!("lines/{k:04}.json"))).expect("line json"),
        )
        .expect("line json parses");
        assert_eq!(meta["y_target_nm"], y_start_nm + 10_000 * k as i64);
    }
}

/// The heights of a stored line file, µm.
fn stored_heights_um(scan: &Path, k: usize) -> Vec<f64> {
    let text = std::fs::read_to_string(scan.join(format!("lines/{k:04}.csv"))).expect("line csv");
    text.lines()
        .skip(1)
        .map(|row| {
            let (_, z) = row.split_once(',').expect("two columns");
            z.parse().expect("a height")
        })
        .collect()
}

fn grbl() -> GrblSimConfig {
    GrblSimConfig {
        time_scale: STAGE_SPEED_UP,
        backlash_mm: 0.02,
        ..GrblSimConfig::default()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_written_config_scans_a_grbl_stage_homing_at_the_top() {
    scan_with_the_written_config(Stage::Grbl(grbl())).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_written_config_scans_a_grbl_stage_homing_at_the_bottom() {
    scan_with_the_written_config(Stage::Grbl(GrblSimConfig {
        home_switch_at_negative_end: true,
        start_mm: 50.0,
        ..grbl()
    }))
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_written_config_scans_a_force_set_origin_grbl_stage_homing_at_the_bottom() {
    scan_with_the_written_config(Stage::Grbl(GrblSimConfig {
        home_switch_at_negative_end: true,
        force_set_origin: true,
        start_mm: 50.0,
        ..grbl()
    }))
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_written_config_scans_a_zaber_stage() {
    scan_with_the_written_config(Stage::Zaber(ZaberSimConfig {
        time_scale: STAGE_SPEED_UP,
        backlash: 160, // 20 µm of 125 nm microsteps
        ..ZaberSimConfig::default()
    }))
    .await;
}
