//! The simulated Zaber axis against what a real one sends, reply for reply, under tokio's
//! paused clock: `WR` on every reply (status polls included) from power-up until a home has
//! completed, a stall that stops the carriage where it happens, a power cycle that reads 0
//! where the stage stands.

mod stage_host;

use stage_host::Host;
use std::time::Duration;
use surfscan_sim::grbl::StageFault;
use surfscan_sim::zaber::{serve, ZaberSimConfig};

fn start(cfg: ZaberSimConfig) -> Host {
    Host::start(|dev, shared| serve(dev, cfg, shared))
}

trait Ask {
    /// Sends `cmd` to device 1 axis 1 and returns the reply line.
    async fn ask(&mut self, cmd: &str) -> String;
}

impl Ask for Host {
    async fn ask(&mut self, cmd: &str) -> String {
        self.send(format!("/1 1 {cmd}\r\n").as_bytes()).await;
        self.line().await
    }
}

/// 125 nm microsteps, 100 000 microsteps/s after 0.1 s ramps (10⁶/s²), 400 microsteps of
/// backlash, powered up 40 000 microsteps (5 mm) above the home sensor.
fn powered_up() -> ZaberSimConfig {
    ZaberSimConfig {
        backlash: 400,
        start: 40_000,
        ..ZaberSimConfig::default()
    }
}

async fn sleep(secs: f64) {
    tokio::time::sleep(Duration::from_secs_f64(secs)).await;
}

/// The start position is published when the device is created, before its task first runs:
/// the simulated instrument's first trace reads it (on a single-threaded runtime the spawned
/// task has not run yet here).
#[tokio::test(start_paused = true)]
async fn the_start_position_is_published_before_the_device_first_runs() {
    let h = start(powered_up());
    assert_eq!(h.shared.true_position_nm(), 40_000 * 125);
}

#[tokio::test(start_paused = true)]
async fn wr_on_every_reply_until_the_home_has_completed() {
    let mut h = start(powered_up());
    assert_eq!(h.ask("get pos").await, "@01 1 OK IDLE WR 0");
    assert_eq!(h.ask("home").await, "@01 1 OK BUSY WR 0");
    // Retract 40 410 microsteps (past the sensor by the backlash and a margin): 0.1 s ramps,
    // 35 410 at full speed → 0.5541 s; then 410 back onto it: a triangle of
    // 2·sqrt(410/10⁶) = 0.0405 s. The reference is set only at the end, so every poll on the
    // way still says WR.
    let total = 0.5541 + 0.0405;
    let mut t = 0.0;
    while t + 0.05 < total {
        assert_eq!(h.ask("").await, "@01 1 OK BUSY WR 0", "at {t:.2} s");
        sleep(0.05).await;
        t += 0.05;
    }
    sleep(total - t + 0.005).await;
    assert_eq!(h.ask("").await, "@01 1 OK IDLE -- 0");
    assert_eq!(h.ask("get pos").await, "@01 1 OK IDLE -- 0");
    // Onto the sensor from below: the backlash is taken out, the carriage is at 0.
    assert_eq!(h.shared.true_position_nm(), 0);
    assert_eq!(h.shared.homing_cycles(), 1);
}

#[tokio::test(start_paused = true)]
async fn a_stall_stops_the_carriage_where_it_happens() {
    let mut h = start(ZaberSimConfig {
        homed_at_start: true,
        ..powered_up()
    });
    h.shared.inject(StageFault::Stall);
    // 80 000 microsteps: 0.1 s ramp, then full speed; it stalls after 40 000, at
    // 0.1 + 35 000/100 000 = 0.45 s.
    assert_eq!(h.ask("move abs 120000").await, "@01 1 OK BUSY -- 0");
    sleep(0.4).await;
    assert_eq!(h.ask("").await, "@01 1 OK BUSY -- 0");
    sleep(0.1).await;
    assert_eq!(h.ask("").await, "@01 1 OK IDLE FS 0");
    assert_eq!(h.ask("get pos").await, "@01 1 OK IDLE FS 80000");
    assert_eq!(h.shared.true_position_nm(), 80_000 * 125);
    // Stalled: moves are refused until the fault is dealt with.
    assert_eq!(h.ask("move abs 0").await, "@01 1 RJ IDLE FS STATUSBUSY");
}

#[tokio::test(start_paused = true)]
async fn a_power_cycle_reads_zero_where_the_stage_stands_with_wr() {
    let mut h = start(ZaberSimConfig {
        homed_at_start: true,
        ..powered_up()
    });
    assert_eq!(h.ask("get pos").await, "@01 1 OK IDLE -- 40000");
    let stood = h.shared.true_position_nm();
    h.shared.inject(StageFault::PositionLostWr);
    assert_eq!(h.ask("get pos").await, "@01 1 OK IDLE WR 0");
    assert_eq!(h.shared.true_position_nm(), stood);
    // Power cycled during a move: it stops there, and still reads 0 there.
    let mut h = start(ZaberSimConfig {
        homed_at_start: true,
        ..powered_up()
    });
    assert_eq!(h.ask("move abs 140000").await, "@01 1 OK BUSY -- 0");
    sleep(0.5).await;
    h.shared.inject(StageFault::PositionLostWr);
    assert_eq!(h.ask("").await, "@01 1 OK IDLE WR 0");
    // 0.5 s in: 5000 + 0.4 s × 100 000 = 45 000 microsteps travelled.
    let stopped = h.shared.true_position_nm();
    assert_eq!(stopped, (40_000 + 45_000) * 125);
    sleep(1.0).await;
    assert_eq!(h.ask("get pos").await, "@01 1 OK IDLE WR 0");
    assert_eq!(h.shared.true_position_nm(), stopped);
}

/// Speed and acceleration in Zaber's data units (microsteps/s × 1.6384, microsteps/s² ×
/// 1.6384 / 10) and the travel, as a host reads them to time its polls and check a plan.
#[tokio::test(start_paused = true)]
async fn settings_are_reported_in_zabers_data_units() {
    let mut h = start(ZaberSimConfig {
        speed_per_s: 50_000.0,
        accel_per_s2: 400_000.0,
        limit_max: 305_381,
        ..powered_up()
    });
    assert_eq!(h.ask("get maxspeed").await, "@01 1 OK IDLE WR 81920");
    assert_eq!(h.ask("get accel").await, "@01 1 OK IDLE WR 65536");
    assert_eq!(h.ask("get limit.min").await, "@01 1 OK IDLE WR 0");
    assert_eq!(h.ask("get limit.max").await, "@01 1 OK IDLE WR 305381");
}
