//! End to end over real pseudo-terminals: `surfscan::scan::station::open_stage` opens the
//! simulated GRBL and Zaber stages (started in-process through the `surfscan_sim` library)
//! with the real transport code, and the motion policy drives them; the simulator's true
//! carriage position is the independent check.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;
use surfscan::devices::{DeviceFault, FaultClass, YAxis};
use surfscan::scan::station::open_stage;
use surfscan::stage::{AnyYAxis, StageError, StageSettings};
use surfscan::units::Nm;
use surfscan_sim::grbl::{GrblSimConfig, StageFault, StageShared};
use surfscan_sim::zaber::ZaberSimConfig;
use surfscan_sim::{SimEvent, SimHandle, Simulator};
use tokio_serial::SerialStream;

/// Simulated motion runs this many times faster than real time.
const SPEED_UP: f64 = 1000.0;

async fn ready(sim: Simulator, link: &Path) -> SimHandle {
    let mut h = sim.start().expect("simulator starts");
    let ev = tokio::time::timeout(Duration::from_secs(5), h.next_event())
        .await
        .expect("ready event in time");
    match ev {
        Some(SimEvent::Ready(r)) => {
            assert_eq!(r.instrument, None);
            assert_eq!(r.stage.as_deref(), Some(link));
        }
        other => panic!("expected Ready, got {other:?}"),
    }
    h
}

fn settings(toml_text: &str, link: &Path) -> StageSettings {
    let text = format!("port = {:?}\n{toml_text}", link.display().to_string());
    toml::from_str(&text).expect("stage settings parse")
}

const GRBL: &str = r#"
protocol = "grbl"
steps-per-mm = 400
soft-limit-min-mm = -100
soft-limit-max-mm = 0
backlash-mm = 0.05
settle-ms = 5
deadband-um = 1
max-move-attempts = 3
feed-mm-min = 60
poll-interval-ms = 200
"#;

async fn grbl() -> (
    tempfile::TempDir,
    SimHandle,
    AnyYAxis<SerialStream>,
    Arc<StageShared>,
) {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("grbl");
    let shared = StageShared::new();
    let cfg = GrblSimConfig {
        steps_per_mm: 400.0,
        max_travel_mm: 100.0,
        backlash_mm: 0.05,
        time_scale: SPEED_UP,
        start_mm: -10.0,
        homed_at_start: false,
        ..Default::default()
    };
    let sim = Simulator::without_instrument().grbl_stage(&link, cfg, shared.clone());
    let h = ready(sim, &link).await;
    let mut axis = open_stage(&settings(GRBL, &link)).expect("opens the pty");
    let r = axis.connect().await.unwrap();
    assert!(r.identity.contains("VER:1.1h"), "{}", r.identity);
    assert!(!r.position_trusted, "powered up in Alarm");
    // Just powered up 10 mm below the switch: the counter reads 0 where the stage stands.
    assert_eq!(r.position, Nm(0));
    assert_eq!(shared.true_position_nm(), -10_000_000);
    (dir, h, axis, shared)
}

/// Line k of a scan from `y_start` by 0.01 mm.
fn target(y_start_nm: i64, k: i64) -> Nm {
    Nm(y_start_nm + k * 10_000)
}

#[tokio::test]
async fn grbl_homes_and_lands_31_steps_exactly_over_a_pty() {
    let (_dir, h, mut a, shared) = grbl().await;
    a.home().await.unwrap();
    assert!(a.position_trusted());
    for k in 0..31 {
        let t = target(-20_000_000, k);
        let arr = a.move_to(t).await.unwrap();
        assert_eq!(arr.readback, t, "line {k}");
        assert_eq!(shared.true_position_nm(), t.0, "carriage at line {k}");
    }
    h.shutdown().await;
}

#[tokio::test]
async fn grbl_reset_banner_mid_scan_is_position_lost_then_rehome_and_continue() {
    let (_dir, h, mut a, shared) = grbl().await;
    a.home().await.unwrap();
    for k in 0..3 {
        a.move_to(target(-20_000_000, k)).await.unwrap();
    }
    shared.inject(StageFault::ResetBanner);
    let e = a.move_to(target(-20_000_000, 3)).await.unwrap_err();
    assert_eq!(e.class(), FaultClass::PositionLost, "{e}");
    // Still refused without re-homing: no move on a guessed position.
    let e = a.move_to(target(-20_000_000, 3)).await.unwrap_err();
    assert!(matches!(e, StageError::PositionLost { .. }), "{e}");
    a.home().await.unwrap();
    for k in 3..6 {
        let t = target(-20_000_000, k);
        assert_eq!(a.move_to(t).await.unwrap().readback, t);
        assert_eq!(shared.true_position_nm(), t.0, "carriage at line {k}");
    }
    h.shutdown().await;
}

#[tokio::test]
async fn grbl_soft_limit_refused_before_any_byte_is_sent() {
    let (_dir, h, mut a, shared) = grbl().await;
    a.home().await.unwrap();
    let before = shared.bytes_received();
    let e = a.move_to(Nm(10_000)).await.unwrap_err();
    assert!(
        matches!(
            e,
            StageError::SoftLimit {
                target: Nm(10_000),
                ..
            }
        ),
        "{e}"
    );
    // SoftLimit (not ControllerLimit): the host refused it; the controller would have
    // answered error:15. Nothing reached the simulator.
    assert_eq!(e.class(), FaultClass::Fatal);
    tokio::task::yield_now().await;
    assert_eq!(shared.bytes_received(), before);
    // The link is intact: the next legal target is reached.
    let t = Nm(-1_000_000);
    assert_eq!(a.move_to(t).await.unwrap().readback, t);
    assert_eq!(shared.true_position_nm(), t.0);
    h.shutdown().await;
}

const ZABER: &str = r#"
protocol = "zaber"
baud = 115200
nm-per-microstep = 125
device = 1
axis = 1
soft-limit-min-mm = 0
soft-limit-max-mm = 100
backlash-mm = 0.05
settle-ms = 5
deadband-um = 0.5
poll-interval-ms = 20
"#;

async fn zaber() -> (
    tempfile::TempDir,
    SimHandle,
    AnyYAxis<SerialStream>,
    Arc<StageShared>,
) {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("zaber");
    let shared = StageShared::new();
    let cfg = ZaberSimConfig {
        nm_per_microstep: 125.0,
        limit_max: 800_000,
        backlash: 400,
        start: 123_456,
        time_scale: SPEED_UP,
        homed_at_start: false,
        ..Default::default()
    };
    let sim = Simulator::without_instrument().zaber_stage(&link, cfg, shared.clone());
    let h = ready(sim, &link).await;
    let mut axis = open_stage(&settings(ZABER, &link)).expect("opens the pty");
    let r = axis.connect().await.unwrap();
    assert!(r.identity.contains("50081"), "{}", r.identity);
    assert!(!r.position_trusted, "WR at power-up");
    // Just powered up: the position reads 0 where the axis stands.
    assert_eq!(r.position, Nm(0));
    assert_eq!(shared.true_position_nm(), 123_456 * 125);
    (dir, h, axis, shared)
}

#[tokio::test]
async fn zaber_homes_and_lands_31_steps_exactly_over_a_pty() {
    let (_dir, h, mut a, shared) = zaber().await;
    a.home().await.unwrap();
    assert_eq!(shared.true_position_nm(), 0);
    for k in 0..31 {
        let t = target(10_000_000, k);
        let arr = a.move_to(t).await.unwrap();
        assert_eq!(arr.readback, t, "line {k}");
        assert_eq!(shared.true_position_nm(), t.0, "carriage at line {k}");
    }
    h.shutdown().await;
}

#[tokio::test]
async fn zaber_unplugged_is_absent() {
    let (dir, h, mut a, shared) = zaber().await;
    a.home().await.unwrap();
    a.move_to(Nm(10_000_000)).await.unwrap();
    shared.inject(StageFault::Vanish);
    let e = a.move_to(Nm(10_010_000)).await.unwrap_err();
    assert_eq!(e.class(), FaultClass::Absent, "{e}");
    // The device node is gone with it.
    assert!(!dir.path().join("zaber").exists());
    h.shutdown().await;
}

#[tokio::test]
async fn grbl_alarm2_is_a_stale_position_recovered_by_reset_and_home() {
    let (_dir, h, mut a, shared) = grbl().await;
    a.home().await.unwrap();
    a.move_to(Nm(-1_000_000)).await.unwrap();
    shared.inject(StageFault::Alarm2);
    let e = a.move_to(Nm(-990_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::PositionLost { reason } if reason.contains("ALARM:2")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::PositionLost);
    assert!(!a.position_trusted(), "a stale position is re-homed");
    // Recovery: soft reset (its banner is expected, not a lost position) then $H.
    a.home().await.unwrap();
    assert!(a.position_trusted());
    let t = Nm(-990_000);
    assert_eq!(a.move_to(t).await.unwrap().readback, t);
    assert_eq!(shared.true_position_nm(), t.0);
    h.shutdown().await;
}

#[tokio::test]
async fn grbl_error15_is_a_controller_limit() {
    let (_dir, h, mut a, shared) = grbl().await;
    a.home().await.unwrap();
    shared.inject(StageFault::Error15);
    let e = a.move_to(Nm(-1_000_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::ControllerLimit { reason, .. } if reason.contains("error:15")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::Fatal);
    // GRBL's code is named in the message as GRBL spells it, never as an SJ-210 NG code.
    assert_eq!(e.ng_code(), None);
    let said = surfscan::devices::Fault::of(surfscan::devices::Device::Stage, &e).to_string();
    assert!(said.contains("error:15") && !said.contains("NG"), "{said}");
    h.shutdown().await;
}

#[tokio::test]
async fn grbl_silence_is_a_transient_timeout() {
    let (_dir, h, mut a, shared) = grbl().await;
    a.home().await.unwrap();
    shared.inject(StageFault::Silence);
    let e = a.move_to(Nm(-1_000_000)).await.unwrap_err();
    assert!(matches!(e, StageError::NoReply { .. }), "{e}");
    assert_eq!(e.class(), FaultClass::Silent);
    h.shutdown().await;
}

#[tokio::test]
async fn grbl_unplugged_is_absent() {
    let (dir, h, mut a, shared) = grbl().await;
    a.home().await.unwrap();
    a.move_to(Nm(-1_000_000)).await.unwrap();
    shared.inject(StageFault::Vanish);
    let e = a.move_to(Nm(-990_000)).await.unwrap_err();
    assert!(matches!(e, StageError::Vanished { .. }), "{e}");
    assert_eq!(e.class(), FaultClass::Absent, "{e}");
    assert!(!dir.path().join("grbl").exists());
    h.shutdown().await;
}

/// Up, up, down, up from `base_nm` by 0.01 mm steps. Scanning upwards, every target is
/// approached from below: a move that continues upwards is one move; the first move after
/// homing and a reversal are two (down past the target by the backlash, then up onto it).
/// The simulated carriage lags the motor by the backlash after any downward move, so it lands
/// exactly on the target only if the last move onto it was upwards.
async fn backlash_only_on_reversal(
    a: &mut AnyYAxis<SerialStream>,
    shared: &StageShared,
    base_nm: i64,
) {
    a.home().await.unwrap();
    let steps: [(i64, u64); 5] = [(0, 2), (1, 1), (2, 1), (1, 2), (2, 1)];
    for (i, (k, moves)) in steps.into_iter().enumerate() {
        let t = target(base_nm, k);
        let before = shared.moves_started();
        let arr = a.move_to(t).await.unwrap();
        assert_eq!(arr.readback, t, "step {i}");
        assert_eq!(shared.true_position_nm(), t.0, "carriage at step {i}");
        assert_eq!(shared.moves_started() - before, moves, "moves for step {i}");
    }
}

#[tokio::test]
async fn grbl_backlash_is_taken_out_only_when_direction_reverses() {
    let (_dir, h, mut a, shared) = grbl().await;
    backlash_only_on_reversal(&mut a, &shared, -20_000_000).await;
    h.shutdown().await;
}

#[tokio::test]
async fn zaber_backlash_is_taken_out_only_when_direction_reverses() {
    let (_dir, h, mut a, shared) = zaber().await;
    backlash_only_on_reversal(&mut a, &shared, 10_000_000).await;
    h.shutdown().await;
}

#[tokio::test]
async fn zaber_reject_is_transient_and_the_retry_lands() {
    let (_dir, h, mut a, shared) = zaber().await;
    a.home().await.unwrap();
    a.move_to(Nm(10_000_000)).await.unwrap();
    shared.inject(StageFault::Reject);
    let e = a.move_to(Nm(10_010_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::Rejected { reason, .. } if reason.contains("AGAIN")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::Transient);
    assert!(a.position_trusted(), "a rejected command moves nothing");
    let t = Nm(10_010_000);
    assert_eq!(a.move_to(t).await.unwrap().readback, t);
    assert_eq!(shared.true_position_nm(), t.0);
    h.shutdown().await;
}

#[tokio::test]
async fn zaber_stall_is_position_lost_until_rehomed() {
    let (_dir, h, mut a, shared) = zaber().await;
    a.home().await.unwrap();
    a.move_to(Nm(10_000_000)).await.unwrap();
    shared.inject(StageFault::Stall);
    let e = a.move_to(Nm(20_000_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::Fault { reason, .. } if reason.starts_with("FS")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::PositionLost);
    assert!(!a.position_trusted());
    let e = a.move_to(Nm(20_000_000)).await.unwrap_err();
    assert!(matches!(e, StageError::PositionLost { .. }), "{e}");
    a.home().await.unwrap();
    let t = Nm(20_000_000);
    assert_eq!(a.move_to(t).await.unwrap().readback, t);
    assert_eq!(shared.true_position_nm(), t.0);
    h.shutdown().await;
}

#[tokio::test]
async fn zaber_wr_flag_is_position_lost_until_rehomed() {
    let (_dir, h, mut a, shared) = zaber().await;
    a.home().await.unwrap();
    a.move_to(Nm(20_000_000)).await.unwrap();
    shared.inject(StageFault::PositionLostWr);
    let e = a.move_to(Nm(20_010_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::PositionLost { reason } if reason.starts_with("WR")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::PositionLost);
    assert!(!a.position_trusted());
    a.home().await.unwrap();
    assert!(a.position_trusted());
    let t = Nm(20_010_000);
    assert_eq!(a.move_to(t).await.unwrap().readback, t);
    assert_eq!(shared.true_position_nm(), t.0);
    h.shutdown().await;
}
