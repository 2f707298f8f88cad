//! End to end over an in-memory duplex link: the Zaber driver and the motion policy against
//! the simulated Zaber device (own parser, backlash dead band, fault injection).

use std::sync::Arc;
use surfscan::devices::{DeviceFault, FaultClass, YAxis};
use surfscan::stage::zaber::ZaberStage;
use surfscan::stage::{MotionPolicy, StageError, StageSettings};
use surfscan::units::Nm;
use surfscan_sim::grbl::{StageFault, StageShared};
use surfscan_sim::zaber::{serve, ZaberSimConfig};
use tokio::io::DuplexStream;

const SETTINGS: &str = r#"
port = "/dev/null"
protocol = "zaber"
nm-per-microstep = 125
device = 1
axis = 1
soft-limit-min-mm = 0
soft-limit-max-mm = 100
backlash-mm = 0.05
settle-ms = 50
deadband-um = 0.5
poll-interval-ms = 100
"#;

type Axis = MotionPolicy<ZaberStage<DuplexStream>>;

fn sim_cfg() -> ZaberSimConfig {
    ZaberSimConfig {
        nm_per_microstep: 125.0,
        limit_max: 800_000,
        backlash: 400, // 0.05 mm
        start: 123_456,
        homed_at_start: false,
        ..Default::default()
    }
}

fn start() -> (Axis, Arc<StageShared>) {
    start_with(SETTINGS, sim_cfg())
}

fn start_with(settings: &str, sim: ZaberSimConfig) -> (Axis, Arc<StageShared>) {
    let settings: StageSettings = toml::from_str(settings).unwrap();
    let (host, dev) = tokio::io::duplex(4096);
    let shared = StageShared::new();
    tokio::spawn(serve(dev, sim, shared.clone()));
    let axis = MotionPolicy::new(
        ZaberStage::new(host, settings.zaber_config()),
        settings.policy_config().unwrap(),
    );
    (axis, shared)
}

async fn homed() -> (Axis, Arc<StageShared>) {
    let (mut a, s) = start();
    a.connect().await.unwrap();
    a.home().await.unwrap();
    (a, s)
}

#[tokio::test(start_paused = true)]
async fn not_referenced_until_homed() {
    let (mut a, shared) = start();
    let r = a.connect().await.unwrap();
    assert!(r.identity.contains("50081"), "{}", r.identity);
    assert!(!r.position_trusted, "WR at power-up");
    // Just powered up: the position reads 0 where the axis stands.
    assert_eq!(r.position, Nm(0));
    assert_eq!(shared.true_position_nm(), 123_456 * 125);
    assert!(matches!(
        a.move_to(Nm(10_000_000)).await,
        Err(StageError::PositionLost { .. })
    ));
    // The device answers every poll of the running home with WR; the home still succeeds.
    a.home().await.unwrap();
    assert!(a.position_trusted());
    assert_eq!(shared.true_position_nm(), 0);
    assert_eq!(shared.homing_cycles(), 1);
}

#[tokio::test(start_paused = true)]
async fn thirty_one_steps_land_exactly_with_backlash_taken_out() {
    let (mut a, shared) = homed().await;
    // Start high, then scan: the first move is a reverse move from wherever we are.
    a.move_to(Nm(50_000_000)).await.unwrap();
    let targets: Vec<Nm> = (0..31).map(|k| Nm(10_000_000 + k * 10_000)).collect();
    assert!(a.check_targets(&targets).unwrap().is_empty());
    for (k, &t) in targets.iter().enumerate() {
        let arr = a.move_to(t).await.unwrap();
        // 0.01 mm = 80 microsteps of 125 nm.
        assert_eq!(a.to_units(t).0, 80_000 + 80 * k as i64);
        assert_eq!(arr.readback, t, "line {k}");
        assert_eq!(shared.true_position_nm(), t.0, "carriage at line {k}");
    }
}

#[tokio::test(start_paused = true)]
async fn faults_map_to_named_errors() {
    let (mut a, shared) = homed().await;
    a.move_to(Nm(10_000_000)).await.unwrap();

    shared.inject(StageFault::Reject);
    let e = a.move_to(Nm(10_010_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::Rejected { reason, .. } if reason.contains("AGAIN")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::Transient);
    a.move_to(Nm(10_010_000)).await.unwrap();
    assert_eq!(shared.true_position_nm(), 10_010_000);

    shared.inject(StageFault::Stall);
    let e = a.move_to(Nm(20_000_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::Fault { reason, .. } if reason.starts_with("FS")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::PositionLost);
    assert!(!a.position_trusted());
    a.home().await.unwrap();
    a.move_to(Nm(20_000_000)).await.unwrap();
    assert_eq!(shared.true_position_nm(), 20_000_000);

    shared.inject(StageFault::PositionLostWr);
    let e = a.move_to(Nm(20_010_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::PositionLost { reason } if reason.starts_with("WR")),
        "{e}"
    );
    assert!(!a.position_trusted());
}

#[tokio::test(start_paused = true)]
async fn soft_limit_violation_sends_nothing_and_silence_and_vanishing_are_named() {
    let (mut a, shared) = homed().await;
    let before = shared.bytes_received();
    let e = a.move_to(Nm(100_000_001)).await.unwrap_err();
    assert!(matches!(e, StageError::SoftLimit { .. }), "{e}");
    tokio::task::yield_now().await;
    assert_eq!(shared.bytes_received(), before);

    shared.inject(StageFault::Silence);
    let e = a.move_to(Nm(1_000_000)).await.unwrap_err();
    assert!(matches!(e, StageError::NoReply { .. }), "{e}");
    assert_eq!(e.class(), FaultClass::Silent);

    let (mut a, shared) = homed().await;
    shared.inject(StageFault::Vanish);
    let e = a.move_to(Nm(1_000_000)).await.unwrap_err();
    assert_eq!(e.class(), FaultClass::Absent, "{e}");
}

#[tokio::test(start_paused = true)]
async fn stop_halts_a_move_and_clears_its_own_interruption_flag() {
    use surfscan::stage::Stage;
    let (mut a, shared) = homed().await;
    let s = a.stage_mut();
    // 800 000 microsteps at 100 000 per second after a 0.1 s ramp at 10⁶/s² (5000
    // microsteps): 2 s in, it stands at 5000 + 1.9 s × 100 000.
    s.begin_move_abs(800_000).await.unwrap();
    tokio::time::sleep(std::time::Duration::from_secs(2)).await;
    s.stop().await.unwrap();
    let st = s.status().await.unwrap();
    assert_eq!(st.position_units, 195_000);
    assert!(st.warnings.is_empty(), "{:?}", st.warnings);
    assert_eq!(shared.true_position_nm(), 195_000 * 125);
}

#[tokio::test(start_paused = true)]
async fn message_ids_and_checksums_work_end_to_end_and_skip_stale_replies() {
    use surfscan::stage::zaber::codec::encode_command;
    use tokio::io::AsyncWriteExt;
    let settings: StageSettings = toml::from_str(SETTINGS).unwrap();
    let (host, dev) = tokio::io::duplex(4096);
    let (dev_r, mut dev_w) = tokio::io::split(dev);
    let shared = StageShared::new();
    // A stale reply (id 42) to a device-level command is already in the pipe: without ids
    // it would be taken as the answer to `get deviceid`.
    dev_w
        .write_all(b"@01 0 42 OK IDLE -- 999\r\n")
        .await
        .unwrap();
    let sim = ZaberSimConfig {
        homed_at_start: true,
        start: 4_000,
        ..Default::default()
    };
    tokio::spawn(serve(tokio::io::join(dev_r, dev_w), sim, shared.clone()));
    let mut z = settings.zaber_config();
    z.message_ids = true;
    z.checksums = true;
    let mut a = MotionPolicy::new(ZaberStage::new(host, z), settings.policy_config().unwrap());
    let r = a.connect().await.unwrap();
    assert!(r.identity.ends_with("id 50081"), "{}", r.identity);
    assert_eq!(r.position, Nm(4_000 * 125));
    a.move_to(Nm(1_000_000)).await.unwrap();
    assert_eq!(shared.true_position_nm(), 1_000_000);
    // The simulator answers only commands whose checksum verifies, so the replies above
    // show the checksums were right; the encoding puts the id before the command.
    assert!(encode_command(1, 1, Some(3), "get pos", true).contains(" 03 get pos:"));
}

#[tokio::test(start_paused = true)]
async fn a_power_cycle_mid_scan_reads_zero_with_wr_until_rehomed_then_the_scan_lands_again() {
    use surfscan::stage::Stage;
    let (mut a, shared) = homed().await;
    let target = |k: i64| Nm(10_000_000 + k * 10_000);
    for k in 0..3 {
        assert_eq!(a.move_to(target(k)).await.unwrap().readback, target(k));
    }
    let stood = shared.true_position_nm();
    shared.inject(StageFault::PositionLostWr);
    // The next line's move is refused as soon as the device answers WR.
    let e = a.move_to(target(3)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::PositionLost { reason } if reason.starts_with("WR")),
        "{e}"
    );
    assert!(!a.position_trusted());
    // The device reads 0 where the stage stands, and says WR on every reply.
    let e = a.stage_mut().status().await.unwrap_err();
    assert!(matches!(e, StageError::PositionLost { .. }), "{e}");
    let (id, st) = a.stage_mut().identify().await.unwrap();
    assert!(id.text.contains("50081"));
    assert_eq!((st.position_units, st.position_trusted), (0, false));
    assert_eq!(
        shared.true_position_nm(),
        stood,
        "a power cycle moves nothing"
    );
    // Nothing moves on the lost position; homing restores it and the scan goes on exactly.
    assert!(matches!(
        a.move_to(target(3)).await,
        Err(StageError::PositionLost { .. })
    ));
    a.home().await.unwrap();
    for k in 3..6 {
        assert_eq!(a.move_to(target(k)).await.unwrap().readback, target(k));
        assert_eq!(
            shared.true_position_nm(),
            target(k).0,
            "carriage at line {k}"
        );
    }
}

#[tokio::test(start_paused = true)]
async fn a_stall_during_a_move_stops_the_carriage_there_and_is_position_lost() {
    use surfscan::stage::Stage;
    let (mut a, shared) = homed().await;
    a.move_to(Nm(10_000_000)).await.unwrap(); // 80 000 microsteps
    shared.inject(StageFault::Stall);
    let s = a.stage_mut();
    s.begin_move_abs(160_000).await.unwrap();
    // Moving normally at first: no fault flag yet.
    let st = s.status().await.unwrap();
    assert_eq!(st.motion, surfscan::stage::Motion::Moving);
    // It stalls half way and stops there: FS.
    let e = s
        .wait_done(std::time::Duration::from_secs(10))
        .await
        .unwrap_err();
    assert!(
        matches!(&e, StageError::Fault { reason, .. } if reason.starts_with("FS")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::PositionLost);
    assert_eq!(shared.true_position_nm(), 120_000 * 125);
    // Through the policy: the move fails, the axis is untrusted until homed.
    let (mut a, shared) = homed().await;
    a.move_to(Nm(10_000_000)).await.unwrap();
    shared.inject(StageFault::Stall);
    let e = a.move_to(Nm(20_000_000)).await.unwrap_err();
    assert_eq!(e.class(), FaultClass::PositionLost, "{e}");
    assert!(!a.position_trusted());
    a.home().await.unwrap();
    assert_eq!(
        a.move_to(Nm(20_000_000)).await.unwrap().readback,
        Nm(20_000_000)
    );
}

/// A lead-screw stage with 0.047625 µm microsteps: 0.01 mm is 209.974 microsteps.
#[tokio::test(start_paused = true)]
async fn a_microstep_that_makes_the_step_inexact_is_refused_or_rounded_once_per_target() {
    let fine = crate::common::edited(
        SETTINGS,
        "nm-per-microstep = 125",
        "nm-per-microstep = 47.625",
    );
    let sim = ZaberSimConfig {
        nm_per_microstep: 47.625,
        limit_max: 2_000_000,
        backlash: 1050, // 0.05 mm
        ..sim_cfg()
    };
    let targets: Vec<Nm> = (0..31).map(|k| Nm(10_000_000 + k * 10_000)).collect();
    let (a, _) = start_with(&fine, sim.clone());
    let e = a.check_targets(&targets).unwrap_err();
    assert!(matches!(e, StageError::InexactTarget { .. }), "{e}");
    assert_eq!(e.class(), FaultClass::Fatal);

    let allowed = format!("{fine}\nallow-inexact-step = true\n");
    let (mut a, shared) = start_with(&allowed, sim);
    a.connect().await.unwrap();
    a.home().await.unwrap();
    let w = a.check_targets(&targets).unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("rounded"), "{w:?}");
    for (k, &t) in targets.iter().enumerate() {
        a.move_to(t).await.unwrap();
        // Each absolute target is rounded once, so the carriage is never more than half a
        // microstep off, on the last line as on the first. Stepping by a rounded 210
        // microsteps instead would drift 0.026 microsteps a line: 37 nm by line 30.
        let off = (shared.true_position_nm() - t.0).abs() as f64;
        assert!(off <= 47.625 / 2.0 + 0.5, "line {k}: {off} nm off");
    }
}

/// The step is polled when its trapezoid (the axis's `maxspeed` and `accel`, read at
/// connect) says it is over, not a poll interval later.
#[tokio::test(start_paused = true)]
async fn a_scan_step_is_polled_when_its_trapezoid_ends() {
    let (mut a, _shared) = homed().await;
    a.move_to(Nm(10_000_000)).await.unwrap();
    let t0 = tokio::time::Instant::now();
    a.move_to(Nm(10_010_000)).await.unwrap();
    let took = t0.elapsed().as_secs_f64();
    // 80 microsteps at 10⁵/s and 10⁶/s²: a triangle of 2·sqrt(80/10⁶) = 17.9 ms, then the
    // 50 ms settle. Polling every 100 ms would make it 150 ms.
    let device = 0.017_889 + 0.050;
    assert!(took >= device, "{took}");
    assert!(
        took < device + 0.010,
        "{took} s for {device} s of device time"
    );
}

/// The travel the device enforces (`limit.min`/`limit.max`) is read at connect: a plan
/// leaving it is refused before anything moves, not by `BADDATA` in the middle of a scan.
#[tokio::test(start_paused = true)]
async fn a_plan_beyond_the_devices_own_travel_is_refused_before_anything_moves() {
    // The device's travel ends at 50 mm; the host limits reach to 100 mm.
    let (mut a, shared) = start_with(
        SETTINGS,
        ZaberSimConfig {
            limit_max: 400_000,
            ..sim_cfg()
        },
    );
    a.connect().await.unwrap();
    a.home().await.unwrap();
    let before = shared.bytes_received();
    let plan: Vec<Nm> = (0..31).map(|k| Nm(60_000_000 + k * 10_000)).collect();
    let e = a.check_targets(&plan).unwrap_err();
    crate::common::assert_outside_controller_travel(&e, Nm(0), Nm(50_000_000));
    assert_eq!(e.class(), FaultClass::Fatal);
    tokio::task::yield_now().await;
    assert_eq!(shared.bytes_received(), before);
    let plan: Vec<Nm> = (0..31).map(|k| Nm(40_000_000 + k * 10_000)).collect();
    assert!(a.check_targets(&plan).unwrap().is_empty());
}

/// A move answered with `WR` (the axis lost its reference) is stopped at once: the device
/// would otherwise run to the target counted from wherever it powered up.
#[tokio::test(start_paused = true)]
async fn a_move_answered_with_wr_is_stopped_where_it_stands() {
    let (mut a, shared) = homed().await;
    a.move_to(Nm(10_000_000)).await.unwrap();
    shared.inject(StageFault::PositionLostWr);
    let e = a.move_to(Nm(10_010_000)).await.unwrap_err();
    assert_eq!(e.class(), FaultClass::PositionLost, "{e}");
    // Counted from the power cycle, 10.01 mm would be 10 mm further up.
    tokio::time::sleep(std::time::Duration::from_secs(2)).await;
    let off = (shared.true_position_nm() - 10_000_000).abs();
    assert!(
        off < 100_000,
        "the carriage ran {off} nm on a lost reference"
    );
}
