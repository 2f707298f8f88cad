//! The simulated GRBL 1.1 controller against what the firmware sends, byte for byte, under
//! tokio's paused clock. Expected timings are worked out from the settings (trapezoids at
//! `$121`), not read off the simulator.

mod stage_host;

use stage_host::Host;
use std::time::Duration;
use surfscan_sim::grbl::{serve, GrblSimConfig, StageFault};
use tokio::time::Instant;

fn start(cfg: GrblSimConfig) -> Host {
    Host::start(|dev, shared| serve(dev, cfg, shared))
}

impl Host {
    async fn ask(&mut self, cmd: &str) -> String {
        self.send(format!("{cmd}\n").as_bytes()).await;
        self.line().await
    }

    /// Sends `cmd` and collects the lines before its `ok`.
    async fn lines_until_ok(&mut self, cmd: &str) -> Vec<String> {
        self.send(format!("{cmd}\n").as_bytes()).await;
        let mut lines = Vec::new();
        loop {
            let l = self.line().await;
            if l == "ok" {
                return lines;
            }
            lines.push(l);
        }
    }

    async fn status(&mut self) -> String {
        self.send(b"?").await;
        let l = self.line().await;
        assert!(l.starts_with('<') && l.ends_with('>'), "{l}");
        l
    }
}

/// The field of a status report that starts with `key` (e.g. `"MPos:"`), without the key.
fn field<'a>(report: &'a str, key: &str) -> Option<&'a str> {
    report
        .trim_start_matches('<')
        .trim_end_matches('>')
        .split('|')
        .find_map(|f| f.strip_prefix(key))
}

fn mpos_y(report: &str) -> f64 {
    let v = field(report, "MPos:").expect("MPos");
    v.split(',').nth(1).unwrap().parse().unwrap()
}

fn feed(report: &str) -> f64 {
    let v = field(report, "FS:").expect("FS");
    v.split(',').next().unwrap().parse().unwrap()
}

fn homed() -> GrblSimConfig {
    GrblSimConfig {
        homed_at_start: true,
        start_mm: -1.0,
        ..GrblSimConfig::default()
    }
}

async fn sleep(secs: f64) {
    tokio::time::sleep(Duration::from_secs_f64(secs)).await;
}

/// The start position is published when the controller is created, before its task first
/// runs: the simulated instrument's first trace reads it (on a single-threaded runtime the
/// spawned task has not run yet here).
#[tokio::test(start_paused = true)]
async fn the_start_position_is_published_before_the_controller_first_runs() {
    let h = start(GrblSimConfig::default());
    assert_eq!(h.shared.true_position_nm(), -50_000_000);
    let h = start(homed());
    assert_eq!(h.shared.true_position_nm(), -1_000_000);
}

#[tokio::test(start_paused = true)]
async fn powers_up_in_alarm_at_zero_with_wco_and_ov_on_their_own_cadence() {
    let mut h = start(GrblSimConfig::default());
    // Just powered up 50 mm below the switch: the counter reads 0 where the stage stands.
    let r1 = h.status().await;
    assert_eq!(
        r1,
        "<Alarm|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>"
    );
    let r2 = h.status().await;
    assert_eq!(r2, "<Alarm|MPos:0.000,0.000,0.000|FS:0,0|Ov:100,100,100>");
    let mut with_wco = vec![1];
    let mut with_ov = vec![2];
    for k in 3..=23 {
        let r = h.status().await;
        if field(&r, "WCO:").is_some() {
            with_wco.push(k);
        }
        if field(&r, "Ov:").is_some() {
            with_ov.push(k);
        }
    }
    // At rest GRBL refreshes WCO every 10th report and Ov on the report after it.
    assert_eq!(with_wco, vec![1, 11, 21]);
    assert_eq!(with_ov, vec![2, 12, 22]);
    assert_eq!(h.ask("$J=G53 G90 Y-1 F100").await, "error:8");
    assert_eq!(h.ask("G4 P0.1").await, "error:9");
    assert_eq!(h.ask("$X").await, "[MSG:Caution: Unlocked]");
    assert_eq!(h.line().await, "ok");
    assert!(h.status().await.starts_with("<Idle|"));
}

#[tokio::test(start_paused = true)]
async fn homing_seeks_pulls_off_locates_and_ends_at_minus_pulloff() {
    let mut h = start(GrblSimConfig {
        backlash_mm: 0.05,
        ..GrblSimConfig::default()
    });
    h.send(b"$H\n").await;
    let t0 = Instant::now();
    // Seek 50 mm at 500 mm/min (8.333 mm/s, 10 mm/s²): 0.8333 s ramp + 46.528 mm cruise
    // = 6.4167 s, stopped on the switch; pull-off 1 mm (triangle: 2·sqrt(1/10) = 0.6325 s);
    // locate 1 mm at 25 mm/min: 0.0417 s ramp + 0.99132 mm / 0.41667 mm/s = 2.4208 s;
    // pull-off 0.6325 s; four 250 ms debounces. Total 11.1025 s.
    let expected = 6.4167 + 0.6325 + 2.4208 + 0.6325 + 1.0;
    sleep(1.0).await;
    // `?` during the cycle is not answered now ...
    h.send(b"?").await;
    assert_eq!(h.line_within(expected - 1.0 - 0.05).await, None);
    // ... but once, as `Home`, just before the `ok`.
    let r = h
        .line_within(0.1)
        .await
        .expect("report at the end of the cycle");
    let took = t0.elapsed().as_secs_f64();
    assert!((took - expected).abs() < 0.01, "homing took {took} s");
    assert!(r.starts_with("<Home|MPos:0.000,-1.000,0.000|"), "{r}");
    assert_eq!(h.line().await, "ok");
    assert_eq!(
        h.status().await,
        "<Idle|MPos:0.000,-1.000,0.000|FS:0,0|Ov:100,100,100>"
    );
    // The pull-off was a move down: the carriage trails the motor by the backlash.
    assert_eq!(h.shared.true_position_nm(), -1_000_000 + 50_000);
    // Machine space is [−$131, 0].
    assert_eq!(h.ask("$J=G53 G90 Y0.001 F100").await, "error:15");
    assert_eq!(h.ask("$J=G53 G90 Y-200.001 F100").await, "error:15");
    assert_eq!(h.ask("$J=G53 G90 Y-200 F100").await, "ok");
}

/// The Y home switch at the negative end, `$23=2`: homing approaches it moving down and
/// GRBL 1.1's `limits_go_home` sets the counter to −`$131` + pull-off, so machine space is
/// still [−`$131`, 0] with the axis near its bottom.
#[tokio::test(start_paused = true)]
async fn homing_toward_negative_ends_at_pulloff_above_minus_travel() {
    let mut h = start(GrblSimConfig {
        home_switch_at_negative_end: true,
        start_mm: 50.0,
        backlash_mm: 0.05,
        ..GrblSimConfig::default()
    });
    assert!(h.lines_until_ok("$$").await.contains(&"$23=2".to_string()));
    assert_eq!(h.ask("$H").await, "ok");
    let r = h.status().await;
    assert!(r.starts_with("<Idle|MPos:0.000,-199.000,0.000|"), "{r}");
    assert_eq!(field(&r, "Pn:"), None, "pulled off the switch: {r}");
    // The locate stopped with the carriage on the switch, trailing the motor by the
    // backlash; the 1 mm pull-off up first takes the backlash up, so the carriage rises
    // 1 − 0.05 mm.
    assert_eq!(h.shared.true_position_nm(), 950_000);
    assert_eq!(h.ask("$J=G53 G90 Y0.001 F100").await, "error:15");
    assert_eq!(h.ask("$J=G53 G90 Y-200.001 F100").await, "error:15");
    // 49 mm up from −199 (MPos −150): the carriage, pushed up, moves with the motor.
    assert_eq!(h.ask("$J=G53 G90 Y-150 F500").await, "ok");
    sleep(30.0).await;
    assert!(h.status().await.starts_with("<Idle|MPos:0.000,-150.000,"));
    assert_eq!(h.shared.true_position_nm(), 49_950_000);
}

/// A `HOMING_FORCE_SET_ORIGIN` build (`Z` in `[OPT:…]`): homing ends with the counter at 0;
/// homing toward negative, soft limits then hold Y to [0, `$131`]; homing toward positive,
/// to [−`$131`, 0] as usual.
#[tokio::test(start_paused = true)]
async fn a_force_origin_build_homes_to_zero_and_keeps_travel_on_the_far_side() {
    let mut h = start(GrblSimConfig {
        home_switch_at_negative_end: true,
        force_set_origin: true,
        start_mm: 50.0,
        ..GrblSimConfig::default()
    });
    let info = h.lines_until_ok("$I").await;
    assert_eq!(info.get(1).map(String::as_str), Some("[OPT:VZ,15,128]"));
    assert_eq!(h.ask("$H").await, "ok");
    assert!(h
        .status()
        .await
        .starts_with("<Idle|MPos:0.000,0.000,0.000|"));
    // Pulled 1 mm up off the switch at the bottom.
    assert_eq!(h.shared.true_position_nm(), 1_000_000);
    assert_eq!(h.ask("$J=G53 G90 Y-0.001 F100").await, "error:15");
    assert_eq!(h.ask("$J=G53 G90 Y200.001 F100").await, "error:15");
    assert_eq!(h.ask("$J=G53 G90 Y20 F500").await, "ok");
    sleep(10.0).await;
    assert!(h.status().await.starts_with("<Idle|MPos:0.000,20.000,"));
    assert_eq!(h.shared.true_position_nm(), 21_000_000);

    let mut h = start(GrblSimConfig {
        force_set_origin: true,
        ..GrblSimConfig::default()
    });
    assert_eq!(h.ask("$H").await, "ok");
    assert!(h
        .status()
        .await
        .starts_with("<Idle|MPos:0.000,0.000,0.000|"));
    assert_eq!(h.shared.true_position_nm(), -1_000_000);
    assert_eq!(h.ask("$J=G53 G90 Y0.001 F100").await, "error:15");
    assert_eq!(h.ask("$J=G53 G90 Y-200 F100").await, "ok");
}

/// `$23` is the firmware's direction, not the machine's: written so that homing runs away
/// from the switch, the seek finds nothing within 1.5 × `$131` (`ALARM:9`); homed the right
/// way, a board already resting on the switch stops the approach at once, and the pull-off
/// away from it succeeds.
#[tokio::test(start_paused = true)]
async fn homing_away_from_the_switch_is_alarm_9() {
    let mut h = start(GrblSimConfig {
        home_switch_at_negative_end: true,
        start_mm: 50.0,
        ..GrblSimConfig::default()
    });
    assert_eq!(h.ask("$23=0").await, "ok");
    h.send(b"$H\n").await;
    assert_eq!(h.line().await, "ALARM:9");
    assert_eq!(h.line().await, "ok");
    // It ran 300 mm up, away from the switch at the bottom.
    assert_eq!(h.shared.true_position_nm(), 350_000_000);

    let mut h = start(GrblSimConfig {
        home_switch_at_negative_end: true,
        start_mm: 0.0,
        ..GrblSimConfig::default()
    });
    assert_eq!(field(&h.status().await, "Pn:"), Some("Y"));
    assert_eq!(h.ask("$H").await, "ok");
    assert!(h.status().await.starts_with("<Idle|MPos:0.000,-199.000,"));
    assert_eq!(h.shared.true_position_nm(), 1_000_000);
}

/// A board homed toward negative before the link opened reports the counter homing set.
#[tokio::test(start_paused = true)]
async fn a_board_homed_toward_negative_at_start_reports_its_machine_position() {
    let mut h = start(GrblSimConfig {
        home_switch_at_negative_end: true,
        homed_at_start: true,
        start_mm: 10.0,
        ..GrblSimConfig::default()
    });
    // 10 mm above the switch, which is 1 mm (the pull-off) below MPos −199.
    assert!(h.status().await.starts_with("<Idle|MPos:0.000,-190.000,"));
}

#[tokio::test(start_paused = true)]
async fn homing_without_a_switch_in_reach_is_alarm_9_then_a_reset() {
    // 200 mm travel, searched over 1.5 × 200 = 300 mm; the switch is 400 mm away.
    let mut h = start(GrblSimConfig {
        start_mm: -400.0,
        ..GrblSimConfig::default()
    });
    h.send(b"$H\n").await;
    assert_eq!(h.line().await, "ALARM:9");
    assert_eq!(h.line().await, "ok");
    assert_eq!(h.line().await, "Grbl 1.1h ['$' for help]");
    assert_eq!(h.line().await, "[MSG:'$H'|'$X' to unlock]");
    assert!(h.status().await.starts_with("<Alarm|"));
}

#[tokio::test(start_paused = true)]
async fn homing_disabled_is_error_5_and_the_board_powers_up_idle() {
    let mut h = start(GrblSimConfig {
        homing_enabled: false,
        soft_limits: false,
        ..GrblSimConfig::default()
    });
    assert!(h.status().await.starts_with("<Idle|MPos:0.000,0.000,"));
    assert_eq!(h.ask("$H").await, "error:5");
    // Soft limits need homing: refused with error:10.
    assert_eq!(h.ask("$20=1").await, "error:10");
    // Without soft limits a jog past 0 is not refused.
    assert_eq!(h.ask("$J=G91 Y5 F500").await, "ok");
}

#[tokio::test(start_paused = true)]
async fn feed_ramps_at_the_axis_acceleration_and_is_capped_at_max_rate() {
    let mut h = start(homed());
    assert_eq!(h.ask("$J=G53 G90 Y-21 F6000").await, "ok");
    let t0 = Instant::now();
    sleep(0.1).await;
    // 0.1 s into a 10 mm/s² ramp: 1 mm/s = 60 mm/min.
    let r = h.status().await;
    assert!(r.starts_with("<Jog|"), "{r}");
    assert!((feed(&r) - 60.0).abs() <= 1.0, "{r}");
    sleep(1.0).await;
    // Cruising at $111 = 500 mm/min, not the commanded 6000.
    assert_eq!(feed(&h.status().await), 500.0);
    // 20 mm: 0.8333 s ramps of 3.472 mm each, 13.056 mm cruise (1.5667 s) = 3.2333 s.
    loop {
        let r = h.status().await;
        if r.starts_with("<Idle") {
            assert_eq!(mpos_y(&r), -21.0);
            break;
        }
        sleep(0.01).await;
    }
    let took = t0.elapsed().as_secs_f64();
    assert!((took - 3.2333).abs() < 0.02, "jog took {took} s");
}

#[tokio::test(start_paused = true)]
async fn jog_cancel_decelerates_at_the_axis_acceleration() {
    let mut h = start(homed());
    assert_eq!(h.ask("$J=G53 G90 Y-100 F500").await, "ok");
    sleep(2.0).await;
    let before = h.status().await;
    // 2 s in: 3.472 mm ramp + 1.1667 s × 8.333 mm/s = 13.194 mm below −1.
    let y0 = mpos_y(&before);
    assert!((y0 - (-1.0 - 13.194)).abs() < 0.01, "{before}");
    h.send(&[0x85]).await;
    let t0 = Instant::now();
    // Still `Jog` while it slows down ...
    sleep(0.4).await;
    let r = h.status().await;
    assert!(r.starts_with("<Jog|"), "{r}");
    let v = feed(&r);
    assert!((v - (500.0 - 10.0 * 0.4 * 60.0)).abs() <= 1.0, "{r}");
    // ... and at rest after v/a = 0.8333 s, v²/2a = 3.472 mm further on.
    loop {
        let r = h.status().await;
        if r.starts_with("<Idle") {
            let took = t0.elapsed().as_secs_f64();
            assert!((took - 0.8333).abs() < 0.02, "stopped after {took} s");
            assert!((mpos_y(&r) - (y0 - 3.472)).abs() < 0.01, "{r}");
            break;
        }
        sleep(0.01).await;
    }
}

#[tokio::test(start_paused = true)]
async fn soft_reset_during_a_jog_is_alarm_3_and_keeps_the_counter() {
    let mut h = start(homed());
    assert_eq!(h.ask("$J=G53 G90 Y-50 F500").await, "ok");
    sleep(2.0).await;
    h.send(&[0x18]).await;
    let t0 = Instant::now();
    assert_eq!(h.line().await, "ALARM:3");
    // GRBL pauses 500 ms after an alarm, then re-initialises.
    assert_eq!(h.line().await, "Grbl 1.1h ['$' for help]");
    assert!((t0.elapsed().as_secs_f64() - 0.5).abs() < 0.01);
    assert_eq!(h.line().await, "[MSG:'$H'|'$X' to unlock]");
    let r = h.status().await;
    assert!(r.starts_with("<Alarm|"), "{r}");
    // Where the stepper stopped, 2 s in: −1 − 13.194 mm.
    assert!((mpos_y(&r) - (-14.194)).abs() < 0.01, "{r}");
    // A soft reset at rest: the banner only, still Alarm, nothing moved.
    h.send(&[0x18]).await;
    assert_eq!(h.line().await, "Grbl 1.1h ['$' for help]");
    assert_eq!(h.line().await, "[MSG:'$H'|'$X' to unlock]");
    assert_eq!(mpos_y(&h.status().await), mpos_y(&r));
}

#[tokio::test(start_paused = true)]
async fn power_cycle_zeroes_the_counter_where_the_stage_stands() {
    let mut h = start(homed());
    assert_eq!(h.ask("$J=G53 G90 Y-20 F500").await, "ok");
    sleep(5.0).await;
    assert_eq!(mpos_y(&h.status().await), -20.0);
    let carriage = h.shared.true_position_nm();
    h.shared.inject(StageFault::ResetBanner);
    h.send(b"?").await;
    assert_eq!(h.line().await, "Grbl 1.1h ['$' for help]");
    assert_eq!(h.line().await, "[MSG:'$H'|'$X' to unlock]");
    let r = h.line().await;
    assert!(r.starts_with("<Alarm|MPos:0.000,0.000,0.000|"), "{r}");
    assert_eq!(
        h.shared.true_position_nm(),
        carriage,
        "the stage did not move"
    );
}

#[tokio::test(start_paused = true)]
async fn first_boot_with_blank_settings_prints_error_7_and_the_defaults_before_the_banner() {
    let mut h = start(GrblSimConfig {
        blank_settings: true,
        banner_at_open: true,
        ..GrblSimConfig::default()
    });
    assert_eq!(h.line().await, "error:7");
    let mut settings = Vec::new();
    loop {
        let l = h.line().await;
        if l.starts_with("Grbl ") {
            assert_eq!(l, "Grbl 1.1h ['$' for help]");
            break;
        }
        settings.push(l);
    }
    assert_eq!(settings.first().map(String::as_str), Some("$0=10"));
    assert!(settings.contains(&"$22=0".to_string()));
    assert!(settings.contains(&"$101=250.000".to_string()));
    assert_eq!(settings.last().map(String::as_str), Some("$132=200.000"));
    // GRBL's defaults: homing off, so no alarm lock; `$$` lists the same bare lines.
    assert!(h.status().await.starts_with("<Idle|"));
    let listed = h.lines_until_ok("$$").await;
    assert_eq!(listed, settings);
    assert!(listed
        .iter()
        .all(|l| l.starts_with('$') && l.contains('=') && !l.contains(' ')));
}

#[tokio::test(start_paused = true)]
async fn settings_are_listed_and_written_with_grbls_checks() {
    let mut h = start(homed());
    let listed = h.lines_until_ok("$$").await;
    for want in [
        "$10=1",
        "$20=1",
        "$22=1",
        "$27=1.000",
        "$101=400.000",
        "$111=500.000",
        "$121=10.000",
        "$131=200.000",
    ] {
        assert!(listed.contains(&want.to_string()), "{want} in {listed:?}");
    }
    assert_eq!(h.ask("$121=20").await, "ok");
    assert_eq!(h.ask("$121=-1").await, "error:4");
    assert_eq!(h.ask("$999=1").await, "error:3");
    assert_eq!(h.ask("$22=0").await, "ok");
    let after = h.lines_until_ok("$$").await;
    assert!(after.contains(&"$121=20.000".to_string()));
    // Disabling homing also disables soft limits.
    assert!(after.contains(&"$20=0".to_string()));
}

#[tokio::test(start_paused = true)]
async fn switch_shows_as_pn_y_and_a_hard_limit_locks_until_reset() {
    let mut h = start(GrblSimConfig {
        soft_limits: false,
        hard_limits: true,
        ..homed()
    });
    assert_eq!(field(&h.status().await, "Pn:"), None);
    // Up 2 mm from −1: onto the switch at 0.
    assert_eq!(h.ask("$J=G91 Y2 F100").await, "ok");
    assert_eq!(h.line().await, "ALARM:1");
    assert_eq!(h.line().await, "[MSG:Reset to continue]");
    // Locked: status requests and lines are not answered.
    h.send(b"?$I\n").await;
    assert_eq!(h.line_within(2.0).await, None);
    h.send(&[0x18]).await;
    assert_eq!(h.line().await, "Grbl 1.1h ['$' for help]");
    // Re-initialised with hard limits on and the switch pressed.
    assert_eq!(h.line().await, "[MSG:Check Limits]");
    assert_eq!(h.line().await, "[MSG:'$H'|'$X' to unlock]");
    let r = h.status().await;
    assert_eq!(field(&r, "Pn:"), Some("Y"), "{r}");
    assert!(r.starts_with("<Alarm|MPos:0.000,0.000,"), "{r}");
}

#[tokio::test(start_paused = true)]
async fn lines_are_cleaned_as_grbl_does_and_gcode_is_locked_out_during_a_jog() {
    let mut h = start(homed());
    assert_eq!(h.ask("$j = g53 g90 y-2 (one mm) f60 ; down").await, "ok");
    assert_eq!(h.ask("G4 P0.01").await, "error:9");
    assert_eq!(h.ask("$I").await, "error:8");
    assert_eq!(h.ask("$J=G53 G90 Y-3").await, "error:22");
    assert_eq!(h.ask("$J=G1 Y-3 F10").await, "error:16");
    let long = format!("$J=G53 G90 Y-2 F60{}", " ".repeat(10) + &"0".repeat(80));
    assert_eq!(h.ask(&long).await, "error:11");
    sleep(2.0).await;
    // Dwell: its ok comes after P seconds.
    h.send(b"G4 P1.5\n").await;
    let t0 = Instant::now();
    assert_eq!(h.line().await, "ok");
    assert!((t0.elapsed().as_secs_f64() - 1.5).abs() < 0.01);
    assert_eq!(h.line_within(0.1).await, None);
}

#[tokio::test(start_paused = true)]
async fn wpos_reports_subtract_the_work_offset() {
    let mut h = start(GrblSimConfig {
        status_report_mask: 0,
        work_offset_y_mm: -5.0,
        ..homed()
    });
    let r = h.status().await;
    assert_eq!(
        r, "<Idle|WPos:0.000,4.000,0.000|FS:0,0|WCO:0.000,-5.000,0.000>",
        "MPos −1 = WPos 4 + WCO −5"
    );
    // A G90 jog without G53 is in work coordinates: Y0 is MPos −5.
    assert_eq!(h.ask("$J=G90 Y0 F500").await, "ok");
    sleep(3.0).await;
    let r = h.status().await;
    assert!(r.starts_with("<Idle|WPos:0.000,0.000,"), "{r}");
}
