//! End to end over an in-memory duplex link: the GRBL driver and the motion policy against
//! the simulated GRBL controller (own parser, backlash dead band, fault injection).

use std::sync::Arc;
use std::time::Duration;
use surfscan::devices::{DeviceFault, FaultClass, YAxis};
use surfscan::stage::grbl::GrblStage;
use surfscan::stage::{MotionPolicy, ScanDirection, StageError, StageSettings};
use surfscan::units::Nm;
use surfscan_sim::grbl::{serve, GrblSimConfig, StageFault, StageShared};
use tokio::io::DuplexStream;

const SETTINGS: &str = r#"
port = "/dev/null"
protocol = "grbl"
steps-per-mm = 400
soft-limit-min-mm = -100
soft-limit-max-mm = 0
backlash-mm = 0.05
settle-ms = 50
deadband-um = 1
max-move-attempts = 3
feed-mm-min = 60
poll-interval-ms = 200
"#;

/// 0.05 mm backlash at 400 steps/mm.
const BACKLASH_NM: i64 = 50_000;

type Axis = MotionPolicy<GrblStage<DuplexStream>>;

fn start(sim: GrblSimConfig) -> (Axis, Arc<StageShared>) {
    start_with(SETTINGS, sim)
}

fn start_with(settings: &str, sim: GrblSimConfig) -> (Axis, Arc<StageShared>) {
    let settings: StageSettings = toml::from_str(settings).unwrap();
    let (host, dev) = tokio::io::duplex(4096);
    let shared = StageShared::new();
    tokio::spawn(serve(dev, sim, shared.clone()));
    let mut g = settings.grbl_config().unwrap();
    g.open_grace = Duration::from_millis(300);
    let axis = MotionPolicy::new(GrblStage::new(host, g), settings.policy_config().unwrap());
    (axis, shared)
}

fn sim_cfg() -> GrblSimConfig {
    GrblSimConfig {
        steps_per_mm: 400.0,
        max_travel_mm: 100.0,
        backlash_mm: 0.05,
        start_mm: -10.0,
        homed_at_start: false,
        ..Default::default()
    }
}

async fn homed() -> (Axis, Arc<StageShared>) {
    let (mut a, s) = start(sim_cfg());
    a.connect().await.unwrap();
    a.home().await.unwrap();
    (a, s)
}

#[tokio::test(start_paused = true)]
async fn homing_makes_the_position_trusted() {
    let (mut a, shared) = start(sim_cfg());
    let r = a.connect().await.unwrap();
    assert!(r.identity.contains("VER:1.1h"), "{}", r.identity);
    assert!(!r.position_trusted, "powered up in Alarm: not referenced");
    // Just powered up 10 mm below the switch: the counter reads 0 where the stage stands.
    assert_eq!(r.position, Nm(0));
    assert_eq!(shared.true_position_nm(), -10_000_000);
    let e = a.move_to(Nm(-5_000_000)).await.unwrap_err();
    assert_eq!(e.class(), FaultClass::PositionLost);
    a.home().await.unwrap();
    assert!(a.position_trusted());
    // Homing ends 1 mm ($27) below the switch after a move down: the carriage lags by the
    // backlash.
    assert_eq!(shared.true_position_nm(), -1_000_000 + BACKLASH_NM);
}

#[tokio::test(start_paused = true)]
async fn thirty_one_steps_land_exactly_with_backlash_taken_out() {
    let (mut a, shared) = homed().await;
    let y_start = Nm(-20_000_000);
    let step = Nm(10_000);
    let targets: Vec<Nm> = (0..31).map(|k| Nm(y_start.0 + k * step.0)).collect();
    assert!(a.check_targets(&targets).unwrap().is_empty());
    for (k, &t) in targets.iter().enumerate() {
        let arr = a.move_to(t).await.unwrap();
        assert_eq!(arr.readback, t, "line {k}");
        assert_eq!(arr.attempts, 1, "line {k}");
        // 0.01 mm = 4 steps at 400 steps/mm: the target is exactly -8000 + 4k steps.
        assert_eq!(a.to_units(t).0, -8000 + 4 * k as i64);
        assert_eq!(shared.true_position_nm(), t.0, "carriage at line {k}");
    }
}

#[tokio::test(start_paused = true)]
async fn backlash_is_taken_out_only_when_direction_reverses() {
    let (mut a, shared) = homed().await;
    for k in 0..5 {
        a.move_to(Nm(-1_000_000 + k * 10_000)).await.unwrap();
        assert_eq!(shared.true_position_nm(), -1_000_000 + k * 10_000);
    }
    // Resume at an earlier line: a reverse move. Without the approach from below the
    // carriage would sit BACKLASH_NM above the target.
    a.move_to(Nm(-990_000)).await.unwrap();
    assert_eq!(shared.true_position_nm(), -990_000);
    // A reverse move made behind the policy's back (e.g. a jog) is visible only through the
    // readback; the policy sees a reverse target and re-approaches.
    a.move_to(Nm(-2_000_000)).await.unwrap();
    assert_eq!(shared.true_position_nm(), -2_000_000);
}

#[tokio::test(start_paused = true)]
async fn negative_step_scan_approaches_from_above_consistently() {
    let (mut a, shared) = homed().await;
    a.set_scan_direction(ScanDirection::Negative);
    for k in 0..6 {
        let t = -1_000_000 - k * 10_000;
        let arr = a.move_to(Nm(t)).await.unwrap();
        assert_eq!(arr.readback, Nm(t));
        // Approached from above: the carriage trails the motor by the full backlash, the
        // same on every line.
        assert_eq!(shared.true_position_nm(), t + BACKLASH_NM);
    }
}

#[tokio::test(start_paused = true)]
async fn soft_limit_violation_sends_nothing() {
    let (mut a, shared) = homed().await;
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
    assert_eq!(e.class(), FaultClass::Fatal);
    let e = a.check_targets(&[Nm(-100_000_001)]).unwrap_err();
    assert!(matches!(e, StageError::SoftLimit { .. }));
    tokio::task::yield_now().await;
    assert_eq!(shared.bytes_received(), before);
}

#[tokio::test(start_paused = true)]
async fn reset_banner_mid_session_is_position_lost_until_rehomed() {
    let (mut a, shared) = homed().await;
    a.move_to(Nm(-1_000_000)).await.unwrap();
    shared.inject(StageFault::ResetBanner);
    let e = a.move_to(Nm(-990_000)).await.unwrap_err();
    assert_eq!(e.class(), FaultClass::PositionLost, "{e}");
    assert!(!a.position_trusted());
    let e = a.move_to(Nm(-990_000)).await.unwrap_err();
    assert!(matches!(e, StageError::PositionLost { .. }));
    a.home().await.unwrap();
    a.move_to(Nm(-990_000)).await.unwrap();
    assert_eq!(shared.true_position_nm(), -990_000);
}

#[tokio::test(start_paused = true)]
async fn alarm2_inside_the_limits_is_a_stale_position_once_and_real_the_second_time() {
    let (mut a, shared) = homed().await;
    a.move_to(Nm(-1_000_000)).await.unwrap();
    shared.inject(StageFault::Alarm2);
    let e = a.move_to(Nm(-990_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::PositionLost { reason } if reason.contains("ALARM:2") && reason.contains("stale")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::PositionLost);
    assert!(!a.position_trusted(), "a stale position is re-homed");
    // Recovery: soft reset (its banner is expected) then $H; the move then succeeds.
    a.home().await.unwrap();
    assert!(a.position_trusted());
    a.move_to(Nm(-990_000)).await.unwrap();
    assert_eq!(shared.true_position_nm(), -990_000);
    // A move that ended at rest forgets it: a later one-off ALARM:2 is stale again.
    shared.inject(StageFault::Alarm2);
    let e = a.move_to(Nm(-980_000)).await.unwrap_err();
    assert_eq!(e.class(), FaultClass::PositionLost, "{e}");
    // Refused again right after the re-home: real, and named.
    a.home().await.unwrap();
    shared.inject(StageFault::Alarm2);
    let e = a.move_to(Nm(-980_000)).await.unwrap_err();
    assert!(
        matches!(&e, StageError::Fault { reason, class: FaultClass::Fatal } if reason.contains("again after re-homing") && reason.contains("$130")),
        "{e}"
    );
}

#[tokio::test(start_paused = true)]
async fn error15_is_a_controller_limit() {
    let (mut a, shared) = homed().await;
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
}

#[tokio::test(start_paused = true)]
async fn silence_times_out_and_vanishing_is_absent() {
    let (mut a, shared) = homed().await;
    shared.inject(StageFault::Silence);
    let e = a.move_to(Nm(-1_000_000)).await.unwrap_err();
    assert!(matches!(e, StageError::NoReply { .. }), "{e}");
    assert_eq!(e.class(), FaultClass::Silent);

    let (mut a, shared) = homed().await;
    shared.inject(StageFault::Vanish);
    let e = a.move_to(Nm(-1_000_000)).await.unwrap_err();
    assert!(matches!(e, StageError::Vanished { .. }), "{e}");
    assert_eq!(e.class(), FaultClass::Absent);
}

#[tokio::test(start_paused = true)]
async fn reset_at_open_is_detected_and_reported() {
    let (mut a, _shared) = start(GrblSimConfig {
        banner_at_open: true,
        homed_at_start: true,
        ..sim_cfg()
    });
    let r = a.connect().await.unwrap();
    assert!(
        !r.position_trusted,
        "an Arduino reset at open loses the position"
    );

    let (mut a, _shared) = start(GrblSimConfig {
        homed_at_start: true,
        ..sim_cfg()
    });
    let r = a.connect().await.unwrap();
    assert!(
        r.position_trusted,
        "no banner, Idle: the controller kept its reference"
    );
}

#[tokio::test(start_paused = true)]
async fn hard_limit_alarm_mid_session_is_position_lost_and_wpos_reports_use_wco() {
    use surfscan::stage::Stage;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let settings: StageSettings = toml::from_str(SETTINGS).unwrap();
    let (host, mut dev) = tokio::io::duplex(4096);
    let mut g = GrblStage::new(host, settings.grbl_config().unwrap());
    let script = tokio::spawn(async move {
        let mut b = [0u8; 1];
        // First `?`: a WPos report with its offset (MPos y = 2.5 + (−5) = −2.5 mm).
        dev.read_exact(&mut b).await.unwrap();
        assert_eq!(b[0], b'?');
        dev.write_all(b"<Idle|WPos:0.000,2.500,0.000|FS:0,0|WCO:0.000,-5.000,0.000>\r\n")
            .await
            .unwrap();
        // Second `?`: a WPos report without WCO reuses the last offset (−1.25 mm).
        dev.read_exact(&mut b).await.unwrap();
        dev.write_all(b"<Idle|WPos:0.000,3.750,0.000|FS:0,0>\r\n")
            .await
            .unwrap();
        // Third `?`: a hard-limit alarm arrives first.
        dev.read_exact(&mut b).await.unwrap();
        dev.write_all(b"ALARM:1\r\n[MSG:Reset to continue]\r\n")
            .await
            .unwrap();
        dev
    });
    assert_eq!(g.status().await.unwrap().position_units, -1000); // −2.5 mm × 400
    assert_eq!(g.status().await.unwrap().position_units, -500); // −1.25 mm × 400
    let e = g.status().await.unwrap_err();
    assert!(
        matches!(&e, StageError::PositionLost { reason } if reason.contains("ALARM:1")),
        "{e}"
    );
    script.await.unwrap();
}

#[test]
fn connect_to_a_missing_port_is_absent() {
    let mut s: StageSettings = toml::from_str(SETTINGS).unwrap();
    s.port = "/dev/surfscan-no-such-port".into();
    let e = match surfscan::scan::station::open_stage(&s) {
        Err(e) => e,
        Ok(_) => panic!("opened a port that does not exist"),
    };
    assert_eq!(e.class(), FaultClass::Absent, "{e}");
    s.poll_interval_ms = 100;
    let e = match surfscan::scan::station::open_stage(&s) {
        Err(e) => e,
        Ok(_) => panic!("accepted a 10 Hz GRBL poll"),
    };
    assert!(
        matches!(e, StageError::Config(ref m) if m.contains("5 Hz")),
        "{e}"
    );
}

#[tokio::test(start_paused = true)]
async fn garbage_and_over_long_lines_are_skipped_by_the_driver() {
    use surfscan::stage::Stage;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let settings: StageSettings = toml::from_str(SETTINGS).unwrap();
    let (host, mut dev) = tokio::io::duplex(4096);
    let mut g = GrblStage::new(host, settings.grbl_config().unwrap());
    let script = tokio::spawn(async move {
        let mut b = [0u8; 1];
        dev.read_exact(&mut b).await.unwrap();
        let mut junk = vec![0xffu8, 0x00, 0xfe, b'\r', b'\n'];
        junk.extend(std::iter::repeat_n(b'x', 600));
        junk.extend_from_slice(b"\r\n<Idle|MPos:0.000,-1.000,0.000>\r\n");
        // Delivered in two pieces, splitting the status report.
        let (a, rest) = junk.split_at(junk.len() - 10);
        dev.write_all(a).await.unwrap();
        tokio::task::yield_now().await;
        dev.write_all(rest).await.unwrap();
        dev
    });
    assert_eq!(g.status().await.unwrap().position_units, -400);
    script.await.unwrap();
}

#[tokio::test(start_paused = true)]
async fn a_board_with_blank_settings_is_refused_by_its_steps_per_mm() {
    // First boot with a blank EEPROM: error:7, GRBL's defaults ($101=250) and the banner.
    let (mut a, _shared) = start(GrblSimConfig {
        blank_settings: true,
        banner_at_open: true,
        ..sim_cfg()
    });
    let e = a.connect().await.unwrap_err();
    assert!(
        matches!(&e, StageError::ControllerSetup(m)
            if m.contains("error:7") && m.contains("$101 is 250") && m.contains("400")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::Fatal);
}

#[tokio::test(start_paused = true)]
async fn homing_on_a_board_without_homing_is_a_named_error_not_a_retry() {
    let (mut a, shared) = start(GrblSimConfig {
        homing_enabled: false,
        soft_limits: false,
        ..sim_cfg()
    });
    // Powered up Idle (no homing lock), but the position is still not referenced.
    let r = a.connect().await.unwrap();
    assert_eq!(r.position, Nm(0));
    let e = a.home().await.unwrap_err();
    assert!(
        matches!(&e, StageError::ControllerSetup(m) if m.contains("$22=0")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::Fatal);
    assert_eq!(shared.homing_cycles(), 0);
}

#[tokio::test(start_paused = true)]
async fn a_plan_beyond_the_boards_own_travel_is_refused_before_anything_moves() {
    // Host limits reach to −150 mm; the board enforces [−$131, 0] = [−100, 0].
    let wide = crate::common::edited(
        SETTINGS,
        "soft-limit-min-mm = -100",
        "soft-limit-min-mm = -150",
    );
    let (mut a, shared) = start_with(&wide, sim_cfg());
    a.connect().await.unwrap();
    a.home().await.unwrap();
    let before = shared.bytes_received();
    let plan: Vec<Nm> = (0..31).map(|k| Nm(-120_000_000 + k * 10_000)).collect();
    let e = a.check_targets(&plan).unwrap_err();
    crate::common::assert_outside_controller_travel(&e, Nm(-100_000_000), Nm(0));
    assert_eq!(e.class(), FaultClass::Fatal);
    tokio::task::yield_now().await;
    assert_eq!(shared.bytes_received(), before);
    // Inside it, the plan is fine.
    let plan: Vec<Nm> = (0..31).map(|k| Nm(-99_000_000 + k * 10_000)).collect();
    assert!(a.check_targets(&plan).unwrap().is_empty());
}

/// A board whose firmware was built with `HOMING_FORCE_SET_ORIGIN` (`Z` in `[OPT:…]`) and
/// whose Y axis homes toward a switch at the bottom (`$23=2`) holds Y to [0, `$131`] (GRBL
/// 1.1's `system_check_travel_limits`): a plan below 0 is refused before anything moves, one
/// in positive space is scanned, each line landing where the counter says above the point
/// homing zeroed it.
#[tokio::test(start_paused = true)]
async fn a_force_origin_board_homing_toward_negative_holds_y_to_positive_space() {
    let positive = crate::common::edited(
        &crate::common::edited(
            SETTINGS,
            "soft-limit-min-mm = -100",
            "soft-limit-min-mm = -20",
        ),
        "soft-limit-max-mm = 0",
        "soft-limit-max-mm = 100",
    );
    let (mut a, shared) = start_with(
        &positive,
        GrblSimConfig {
            home_switch_at_negative_end: true,
            force_set_origin: true,
            start_mm: 10.0,
            ..sim_cfg()
        },
    );
    let r = a.connect().await.unwrap();
    assert!(r.identity.contains("OPT:VZ"), "{}", r.identity);
    let before = shared.bytes_received();
    let below: Vec<Nm> = (0..31).map(|k| Nm(-10_000_000 + k * 10_000)).collect();
    let e = a.check_targets(&below).unwrap_err();
    crate::common::assert_outside_controller_travel(&e, Nm(0), Nm(100_000_000));
    assert!(e.to_string().contains("HOMING_FORCE_SET_ORIGIN"), "{e}");
    assert_eq!(e.class(), FaultClass::Fatal);
    tokio::task::yield_now().await;
    assert_eq!(shared.bytes_received(), before);

    a.home().await.unwrap();
    assert!(a.position_trusted());
    let plan: Vec<Nm> = (0..31).map(|k| Nm(50_000_000 + k * 10_000)).collect();
    assert!(a.check_targets(&plan).unwrap().is_empty());
    for (k, &t) in plan.iter().enumerate() {
        let arr = a.move_to(t).await.unwrap();
        assert_eq!(arr.readback, t, "line {k}");
        // Homing pulled the carriage 1 mm ($27) up off the switch, less the 0.05 mm of
        // backlash the motor took up first; counter 0 is there.
        assert_eq!(
            shared.true_position_nm(),
            t.0 + 1_000_000 - BACKLASH_NM,
            "carriage at line {k}"
        );
    }
}

#[tokio::test(start_paused = true)]
async fn work_coordinate_reports_are_turned_into_machine_positions() {
    // $10=0: WPos in the reports, WCO only on every tenth; G54 Y offset −5 mm.
    let (mut a, shared) = start(GrblSimConfig {
        status_report_mask: 0,
        work_offset_y_mm: -5.0,
        ..sim_cfg()
    });
    a.connect().await.unwrap();
    a.home().await.unwrap();
    for k in 0..12 {
        // Twelve lines: more reports than one WCO refresh period.
        let t = Nm(-20_000_000 + k * 10_000);
        assert_eq!(a.move_to(t).await.unwrap().readback, t, "line {k}");
        assert_eq!(shared.true_position_nm(), t.0, "carriage at line {k}");
    }
}

/// The jog's end is polled when the planner says it is over, not a poll interval later.
#[tokio::test(start_paused = true)]
async fn a_scan_step_is_polled_when_its_trapezoid_ends() {
    let (mut a, _shared) = homed().await;
    a.move_to(Nm(-20_000_000)).await.unwrap();
    let t0 = tokio::time::Instant::now();
    a.move_to(Nm(-19_990_000)).await.unwrap();
    let took = t0.elapsed().as_secs_f64();
    // 0.01 mm at 60 mm/min and 10 mm/s² ($121): a triangle of 2·sqrt(0.01/10) = 63.2 ms,
    // then 50 ms settle. Polling every 200 ms would make it 250 ms.
    let device = 0.063_246 + 0.050;
    assert!(took >= device, "{took}");
    assert!(
        took < device + 0.010,
        "{took} s for {device} s of device time"
    );
}

/// `$J=` outside Idle/Jog is `error:8`; in Alarm that means the position needs a home, so the
/// driver says position lost (the scan re-homes) rather than a refusal to retry as it is.
#[tokio::test(start_paused = true)]
async fn a_jog_refused_in_alarm_with_error_8_is_position_lost() {
    use surfscan::stage::Stage;
    // Just powered up with homing enabled: the board is in Alarm.
    let (mut a, shared) = start(sim_cfg());
    assert!(!a.connect().await.unwrap().position_trusted);
    let e = a.stage_mut().begin_move_abs(-4_000).await.unwrap_err();
    assert!(
        matches!(&e, StageError::PositionLost { reason }
            if reason.contains("error:8") && reason.contains("Alarm")),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::PositionLost);
    assert_eq!(shared.moves_started(), 0);
    a.home().await.unwrap();
    assert_eq!(
        a.move_to(Nm(-10_000_000)).await.unwrap().readback,
        Nm(-10_000_000)
    );
}

/// Stopping cancels the jog (0x85) and returns once GRBL has decelerated at `$121` to Idle,
/// so the next move starts from rest at a position read back.
#[tokio::test(start_paused = true)]
async fn stop_cancels_a_jog_and_returns_once_it_is_at_rest() {
    use surfscan::stage::{Motion, Stage};
    let (mut a, _shared) = homed().await;
    let s = a.stage_mut();
    // From MPos −1 (−$27) towards −50 mm at 1 mm/s: after 2 s it has covered the 0.05 mm
    // ramp and 1.9 mm of cruise; braking at 10 mm/s² takes 0.1 s over 0.05 mm more.
    s.begin_move_abs(-20_000).await.unwrap();
    tokio::time::sleep(Duration::from_secs(2)).await;
    let t0 = tokio::time::Instant::now();
    s.stop().await.unwrap();
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(100),
        "returned after {took:?}"
    );
    assert!(took < Duration::from_millis(200), "returned after {took:?}");
    let st = s.status().await.unwrap();
    assert_eq!(st.motion, Motion::Idle);
    // −3.000 mm = −1200 steps, give or take the step the cancel lands on.
    assert!((st.position_units + 1_200).abs() <= 2, "{st:?}");
}
