//! The station configuration that points `surfscan` at this simulator: `surfscan-sim
//! --write-config FILE` writes it, so a simulated station runs with `surfscan scan --config
//! FILE` and nothing edited by hand.
//!
//! Every key is derived from what the simulator serves: the links as ports, the model and the
//! `RDEVA` form it answers and whether it reads during the drive's return, the served
//! profiles' x pitch, the stage's protocol, resolution and machine space (soft limits inside
//! it, one millimetre clear of each end), and the drive's speeds and status polls at the time
//! scale. The scan's first line sits 20 mm inside the travel from
//! the home switch, and the served profiles are placed on the scan's y grid
//! ([`StationConfig::profiles`]), so line k of the scan is served profile k.
//!
//! Pure: paths, the simulator's own settings and the profile set in, TOML text out. The text
//! is written here, not with the daemon's config types: the simulator shares no code with
//! `surfscan`. Depends on [`crate::data`], [`crate::instrument`], [`crate::grbl`] and
//! [`crate::zaber`] (their settings only).

use std::fmt::Write as _;
use std::path::Path;

use crate::data::ProfileSet;
use crate::grbl::GrblSimConfig;
use crate::instrument::{InstrumentConfig, Model, ReadoutForm};
use crate::zaber::ZaberSimConfig;

/// y step between the scan's lines, mm (the paper's 0.01 mm).
pub const Y_STEP_MM: f64 = 0.01;
/// Distance of the first line from the home end of the travel, mm.
pub const FIRST_LINE_FROM_HOME_MM: f64 = 20.0;
/// Clearance of the soft limits from each end of the travel, mm.
pub const SOFT_LIMIT_CLEARANCE_MM: f64 = 1.0;
/// The shortest "measuring" phase a configuration is written for, ms: a surfscan polling its
/// status every [`MIN_POLL_MS`] must see it several times, also on a loaded machine.
pub const MIN_MEASURING_MS: f64 = 50.0;
/// The fastest status poll written, ms.
pub const MIN_POLL_MS: u64 = 5;
/// Lines the surface needs at least: the default degree across lines (5) plus one.
pub const MIN_LINES: usize = 6;

/// The simulated stage a configuration is written for.
#[derive(Debug, Clone, Copy)]
pub enum SimStage<'a> {
    /// The GRBL controller.
    Grbl(&'a GrblSimConfig),
    /// The Zaber device.
    Zaber(&'a ZaberSimConfig),
}

/// What the configuration is written from.
#[derive(Debug, Clone, Copy)]
pub struct StationConfigRequest<'a> {
    /// The instrument's link (an absolute path, as the daemon may run elsewhere).
    pub instrument_link: &'a Path,
    /// The emulated instrument.
    pub instrument: &'a InstrumentConfig,
    /// The baud rate the simulator paces replies at.
    pub baud: u32,
    /// The simulator answers only a host at `baud` (`--line-check`).
    pub line_check: bool,
    /// The stage's link.
    pub stage_link: &'a Path,
    /// The simulated stage.
    pub stage: SimStage<'a>,
    /// `[output] dir` of the configuration.
    pub output_dir: &'a Path,
    /// `[control] socket` of the configuration.
    pub control_socket: &'a Path,
}

/// A written configuration and the profiles to serve with it.
#[derive(Debug, Clone, PartialEq)]
pub struct StationConfig {
    /// The TOML text.
    pub toml: String,
    /// The profile set placed on the scan's y grid (in the stage's true positions, which
    /// select the served line): serve this one.
    pub profiles: ProfileSet,
    /// y of the first line, mm (machine coordinates).
    pub y_start_mm: f64,
    /// Lines of the scan.
    pub lines: usize,
}

/// Why no configuration can be written for these settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StationConfigError {
    /// The instrument answers no profile read-out, which a scan needs.
    #[error("the simulated instrument answers no profile read-out (--no-profile-readout), which a scan needs")]
    NoReadout,
    /// The simulator answers only at a rate the model does not offer.
    #[error("the simulated instrument answers only at {baud} baud (--line-check), which an {model} does not offer")]
    BaudNotOffered {
        /// The rate.
        baud: u32,
        /// The model.
        model: &'static str,
    },
    /// The served profiles do not share one x pitch.
    #[error("the served profiles have different x pitches ({first_mm} mm and {other_mm} mm); a station has one")]
    MixedPitch {
        /// The first profile's pitch, mm.
        first_mm: f64,
        /// A different one, mm.
        other_mm: f64,
    },
    /// The traces are too short at this time scale for status polls to see them.
    #[error(
        "at time scale {time_scale} the shortest trace measures for {measuring_ms:.1} ms, too short for status polls to see; use a time scale of at least {minimum}"
    )]
    TooFast {
        /// The instrument's time scale.
        time_scale: f64,
        /// The shortest trace's measuring phase, ms.
        measuring_ms: f64,
        /// The least time scale that works.
        minimum: f64,
    },
}

/// The stage's machine space after homing, where homing leaves it, and how its machine
/// coordinates relate to the carriage's true position (which selects the served line), mm.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Travel {
    low_mm: f64,
    high_mm: f64,
    /// The home switch is at the low end.
    home_low: bool,
    /// True position minus machine position once homed.
    true_minus_machine_mm: f64,
}

fn travel(stage: SimStage<'_>) -> Travel {
    match stage {
        SimStage::Grbl(g) => {
            // GRBL's machine space is [−$131, 0], except in a HOMING_FORCE_SET_ORIGIN build
            // homing toward negative: [0, $131] (grbl/src/system.c, system_check_travel_limits).
            let (t, pulloff) = (g.max_travel_mm, g.homing_pulloff_mm);
            let home_low = g.home_switch_at_negative_end;
            let (low_mm, high_mm) = if g.force_set_origin && home_low {
                (0.0, t)
            } else {
                (-t, 0.0)
            };
            // The true position is measured from the switch. surfscan approaches every line
            // from below (its scan steps up), which leaves the carriage at the motor's
            // position; the motor's is what matters. Homing pulls the motor off the switch
            // by $27 from where the switch tripped: at 0 for a switch at the top, at
            // −backlash for one at the bottom (moving down, the carriage leads the motor by
            // the backlash). There GRBL sets its counter (limits_go_home): to 0 in a
            // HOMING_FORCE_SET_ORIGIN build, else to −$27 below a switch at the top and to
            // −$131 + $27 above one at the bottom.
            let homed_true = if home_low {
                pulloff - g.backlash_mm
            } else {
                -pulloff
            };
            let homed_machine = match (g.force_set_origin, home_low) {
                (true, _) => 0.0,
                (false, false) => -pulloff,
                (false, true) => pulloff - t,
            };
            Travel {
                low_mm,
                high_mm,
                home_low,
                true_minus_machine_mm: homed_true - homed_machine,
            }
        }
        // Positions are microsteps from the home sensor, the true position's origin.
        SimStage::Zaber(z) => Travel {
            low_mm: 0.0,
            high_mm: z.limit_max as f64 * z.nm_per_microstep / 1e6,
            home_low: true,
            true_minus_machine_mm: 0.0,
        },
    }
}

/// A number as TOML writes it, to whole nanometres (mm) or picometres (µm).
fn num(v: f64, decimals: i32) -> String {
    let scale = 10f64.powi(decimals);
    let r = (v * scale).round() / scale;
    format!("{r:?}")
}

/// Writes the station configuration for `req` and places `profiles` on its y grid.
pub fn station_config(
    req: &StationConfigRequest<'_>,
    profiles: &ProfileSet,
) -> Result<StationConfig, StationConfigError> {
    let inst = req.instrument;
    if !inst.profile_readout {
        return Err(StationConfigError::NoReadout);
    }
    let served = profiles.profiles();
    let pitch_mm = served.first().map_or(0.0, |p| p.pitch_x_mm);
    if let Some(other) = served
        .iter()
        .find(|p| (p.pitch_x_mm - pitch_mm).abs() > 1e-12)
    {
        return Err(StationConfigError::MixedPitch {
            first_mm: pitch_mm,
            other_mm: other.pitch_x_mm,
        });
    }
    let lambda_c_mm = inst.conditions.lambda_c_mm();
    // The measuring phase lasts (profile length + λc) / speed, times the time scale.
    let shortest_mm = served
        .iter()
        .map(|p| p.length_mm())
        .fold(f64::INFINITY, f64::min)
        + lambda_c_mm;
    let real_ms = shortest_mm / inst.measure_speed_mm_s * 1000.0;
    let measuring_ms = real_ms * inst.time_scale;
    if measuring_ms.is_nan() || measuring_ms < MIN_MEASURING_MS {
        return Err(StationConfigError::TooFast {
            time_scale: inst.time_scale,
            measuring_ms,
            minimum: (MIN_MEASURING_MS / real_ms * 1e4).ceil() / 1e4,
        });
    }
    // Ten polls at least while it measures; never slower than the daemon's default.
    let poll_ms = ((measuring_ms / 10.0).floor() as u64).clamp(MIN_POLL_MS, 250);

    let t = travel(req.stage);
    let y_start_mm = if t.home_low {
        t.low_mm + FIRST_LINE_FROM_HOME_MM
    } else {
        t.high_mm - FIRST_LINE_FROM_HOME_MM
    };
    let lines = served.len().max(MIN_LINES);
    let mut placed = profiles.clone();
    placed.y_first_mm = y_start_mm + t.true_minus_machine_mm;
    placed.y_step_mm = Y_STEP_MM;

    let mut s = String::new();
    let q = |p: &Path| format!("{:?}", p.display().to_string());
    let model = match inst.model {
        Model::Sj210 => "sj210",
        Model::Sj410 => "sj410",
    };
    let bauds: &[u32] = match inst.model {
        Model::Sj210 => &[9600, 19200, 38400],
        Model::Sj410 => &[9600, 19200, 38400, 57600],
    };
    let _ = writeln!(
        s,
        "# Written by surfscan-sim --write-config: a station configuration whose ports are the\n\
         # simulator's pseudo-terminals. Run `surfscan scan --config` with it while the simulator\n\
         # runs. config/surfscan.toml lists every key.\n\
         \n[instrument]\nport = {}\nmodel = \"{model}\"",
        q(req.instrument_link)
    );
    if bauds.contains(&req.baud) {
        let _ = writeln!(s, "baud = {}", req.baud);
    } else if req.line_check {
        return Err(StationConfigError::BaudNotOffered {
            baud: req.baud,
            model,
        });
    } else {
        let _ = writeln!(
            s,
            "# The simulator paces at {} baud, which an {model} does not offer; a pseudo-terminal\n\
             # ignores the rate.\nbaud = 38400",
            req.baud
        );
    }
    let _ = writeln!(
        s,
        "# The served profiles' x pitch.\npitch-x-um = {}",
        num(pitch_mm * 1000.0, 6)
    );
    // The drive's speeds as the host sees them: the simulator's, sped up by the time scale.
    let _ = writeln!(
        s,
        "# The simulated drive's speeds, {} and {} mm/s, at time scale {}.\n\
         measuring-speed-mm-s = {}\nreturn-speed-mm-s = {}",
        inst.measure_speed_mm_s,
        inst.return_speed_mm_s,
        inst.time_scale,
        num(inst.measure_speed_mm_s / inst.time_scale, 6),
        num(inst.return_speed_mm_s / inst.time_scale, 6),
    );
    let n = u32::from(inst.conditions.sampling_lengths);
    if n > 0 {
        // The daemon expects N × ⌊λc / pitch⌋ points (computed in whole nanometres).
        let per = ((lambda_c_mm * 1e6).round() / (pitch_mm * 1e6).round()).floor() as usize;
        let expected = per * n as usize;
        if served.iter().any(|p| p.z_um.len() != expected) {
            let _ = writeln!(
                s,
                "# The served profiles are not N × ⌊λc / pitch⌋ = {expected} points long.\n\
                 check-point-count = false"
            );
        }
    }
    let _ = writeln!(
        s,
        "\n[instrument.timeouts]\n\
         # A trace measures for {measuring_ms:.0} ms at time scale {}: poll its status ten times at least.\n\
         poll-interval-ms = {poll_ms}",
        inst.time_scale
    );
    let (total, block) = match (inst.readout_form, inst.model) {
        (ReadoutForm::Only(None), _) | (ReadoutForm::Model, Model::Sj210) => {
            ("RDEVA00".to_string(), "RDEVA{n}".to_string())
        }
        (ReadoutForm::Only(Some(d)), _) => (format!("RDEVA{d}00"), format!("RDEVA{d}{{n}}")),
        (ReadoutForm::Model, Model::Sj410) => ("RDEVA000".to_string(), "RDEVA0{n}".to_string()),
    };
    let _ = writeln!(
        s,
        "\n[instrument.commands]\n\
         # The profile read-out form the simulated firmware answers.\n\
         profile-total = \"{total}\"\nprofile-block = \"{block}\""
    );
    if inst.reads_during_return {
        let _ = writeln!(
            s,
            "# The simulated firmware answers reads while its drive returns.\nreads-during-return = true"
        );
    }

    let _ = writeln!(s, "\n[stage]\nport = {}", q(req.stage_link));
    let (unit_mm, protocol_keys) = match req.stage {
        SimStage::Grbl(g) => (
            1.0 / g.steps_per_mm,
            format!(
                "protocol = \"grbl\"\nsteps-per-mm = {}",
                num(g.steps_per_mm, 6)
            ),
        ),
        SimStage::Zaber(z) => (
            z.nm_per_microstep / 1e6,
            format!(
                "protocol = \"zaber\"\nnm-per-microstep = {}\ndevice = {}\naxis = 1",
                num(z.nm_per_microstep, 6),
                z.device
            ),
        ),
    };
    let backlash_mm = match req.stage {
        SimStage::Grbl(g) => g.backlash_mm,
        SimStage::Zaber(z) => z.backlash as f64 * z.nm_per_microstep / 1e6,
    };
    // Take out twice the simulated backlash, in whole hundredths of a millimetre.
    let take_out_mm = ((2.0 * backlash_mm * 100.0).ceil() / 100.0).max(0.05);
    let steps = Y_STEP_MM / unit_mm;
    let _ = writeln!(
        s,
        "{protocol_keys}\n\
         # Machine space [{}, {}] mm, the home switch at its {} end.\n\
         soft-limit-min-mm = {}\nsoft-limit-max-mm = {}\n\
         backlash-mm = {}\nsettle-ms = {}\npoll-interval-ms = 200\nhome-on-start = true",
        num(t.low_mm, 6),
        num(t.high_mm, 6),
        if t.home_low { "low" } else { "high" },
        num(t.low_mm + SOFT_LIMIT_CLEARANCE_MM, 6),
        num(t.high_mm - SOFT_LIMIT_CLEARANCE_MM, 6),
        num(take_out_mm, 6),
        ((200.0 * inst.time_scale).round() as u64).clamp(2, 200),
    );
    if (steps - steps.round()).abs() > 1e-9 {
        let _ = writeln!(
            s,
            "# {Y_STEP_MM} mm is {steps:.3} device units: each target is rounded once.\n\
             allow-inexact-step = true"
        );
    }
    let _ = writeln!(
        s,
        "\n[scan]\n\
         # Line k is the simulator's profile k (served at y-start + k × y-step{}).\n\
         lines = {lines}\ny-start-mm = {}\ny-step-mm = {Y_STEP_MM:?}\n\
         \n[output]\ndir = {}\n\
         \n[control]\nsocket = {}",
        if lines > served.len() {
            "; the profiles repeat"
        } else {
            ""
        },
        num(y_start_mm, 6),
        q(req.output_dir),
        q(req.control_socket),
    );
    Ok(StationConfig {
        toml: s,
        profiles: placed,
        y_start_mm,
        lines,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::ServedProfile;

    fn set(points: usize, pitch_mm: f64, count: usize) -> ProfileSet {
        ProfileSet::new(
            (0..count)
                .map(|k| ServedProfile {
                    y_mm: k as f64,
                    pitch_x_mm: pitch_mm,
                    z_um: vec![0.0; points],
                })
                .collect(),
        )
        .unwrap()
    }

    fn request<'a>(inst: &'a InstrumentConfig, stage: SimStage<'a>) -> StationConfigRequest<'a> {
        StationConfigRequest {
            instrument_link: Path::new("/tmp/s/sj210"),
            instrument: inst,
            baud: 38400,
            line_check: false,
            stage_link: Path::new("/tmp/s/ystage"),
            stage,
            output_dir: Path::new("/tmp/s/scans"),
            control_socket: Path::new("/tmp/s/control.sock"),
        }
    }

    fn key<'t>(toml: &'t str, name: &str) -> Vec<&'t str> {
        toml.lines()
            .filter_map(|l| l.strip_prefix(name)?.strip_prefix(" = "))
            .collect()
    }

    #[test]
    fn the_first_line_is_twenty_mm_inside_the_travel_from_the_home_switch() {
        let inst = InstrumentConfig {
            time_scale: 0.02,
            ..InstrumentConfig::default()
        };
        // 200 mm of travel: GRBL's [−200, 0] with the switch at 0, at −200, and a
        // HOMING_FORCE_SET_ORIGIN build homing down, [0, 200].
        let top = GrblSimConfig::default();
        let bottom = GrblSimConfig {
            home_switch_at_negative_end: true,
            ..GrblSimConfig::default()
        };
        let origin = GrblSimConfig {
            force_set_origin: true,
            ..bottom.clone()
        };
        // 800000 microsteps of 125 nm: 100 mm from the home sensor.
        let zaber = ZaberSimConfig::default();
        let bottom_lash = GrblSimConfig {
            backlash_mm: 0.02,
            ..bottom.clone()
        };
        let top_origin = GrblSimConfig {
            force_set_origin: true,
            ..GrblSimConfig::default()
        };
        // The true position counts from the switch; $27 = 1 mm of pull-off after homing.
        for (stage, start, min, max, true_start) in [
            // Homed at MPos −1, 1 mm below the switch: machine = true.
            (SimStage::Grbl(&top), "-20.0", "-199.0", "-1.0", -20.0),
            // Homed at MPos 0, 1 mm below the switch.
            (
                SimStage::Grbl(&top_origin),
                "-20.0",
                "-199.0",
                "-1.0",
                -21.0,
            ),
            // Homed at MPos −199, 1 mm above the switch.
            (SimStage::Grbl(&bottom), "-180.0", "-199.0", "-1.0", 20.0),
            // The same with 20 µm of backlash: the switch trips with the motor 20 µm below.
            (
                SimStage::Grbl(&bottom_lash),
                "-180.0",
                "-199.0",
                "-1.0",
                19.98,
            ),
            // Homed at MPos 0, 1 mm above the switch.
            (SimStage::Grbl(&origin), "20.0", "1.0", "199.0", 21.0),
            (SimStage::Zaber(&zaber), "20.0", "1.0", "99.0", 20.0),
        ] {
            let c = station_config(&request(&inst, stage), &set(100, 0.0015, 31)).unwrap();
            assert_eq!(key(&c.toml, "y-start-mm"), [start], "{stage:?}");
            assert_eq!(key(&c.toml, "soft-limit-min-mm"), [min], "{stage:?}");
            assert_eq!(key(&c.toml, "soft-limit-max-mm"), [max], "{stage:?}");
            assert!(
                (c.profiles.y_first_mm - true_start).abs() < 1e-9,
                "{stage:?}: {}",
                c.profiles.y_first_mm
            );
            assert_eq!(c.profiles.y_step_mm, 0.01);
        }
    }

    #[test]
    fn each_line_of_the_scan_selects_the_profile_of_the_same_index() {
        let inst = InstrumentConfig {
            time_scale: 0.02,
            ..InstrumentConfig::default()
        };
        let bottom = GrblSimConfig {
            home_switch_at_negative_end: true,
            ..GrblSimConfig::default()
        };
        let c = station_config(
            &request(&inst, SimStage::Grbl(&bottom)),
            &set(100, 0.0015, 31),
        )
        .unwrap();
        let y = crate::data::YPosition::new();
        for k in 0..31 {
            // The daemon's target of line k is −180 mm + k × 10 µm in machine coordinates:
            // 200 mm above the switch's true position 0 at the machine's −200.
            y.set_nm(20_000_000 + 10_000 * k);
            assert_eq!(c.profiles.select(0, Some(&y)), k as usize);
        }
        assert_eq!(key(&c.toml, "lines"), ["31"]);
    }

    #[test]
    fn readout_commands_follow_the_form_the_firmware_answers() {
        for (model, form, total, block) in [
            (Model::Sj210, ReadoutForm::Model, "RDEVA00", "RDEVA{n}"),
            (Model::Sj410, ReadoutForm::Model, "RDEVA000", "RDEVA0{n}"),
            (
                Model::Sj210,
                ReadoutForm::Only(Some(1)),
                "RDEVA100",
                "RDEVA1{n}",
            ),
            (Model::Sj410, ReadoutForm::Only(None), "RDEVA00", "RDEVA{n}"),
        ] {
            let inst = InstrumentConfig {
                model,
                readout_form: form,
                time_scale: 1.0,
                ..InstrumentConfig::default()
            };
            let g = GrblSimConfig::default();
            let c =
                station_config(&request(&inst, SimStage::Grbl(&g)), &set(100, 0.0015, 8)).unwrap();
            assert_eq!(key(&c.toml, "profile-total"), [format!("\"{total}\"")]);
            assert_eq!(key(&c.toml, "profile-block"), [format!("\"{block}\"")]);
        }
    }

    #[test]
    fn a_firmware_that_reads_during_the_return_is_said_so() {
        let g = GrblSimConfig::default();
        for during in [false, true] {
            let inst = InstrumentConfig {
                time_scale: 0.02,
                reads_during_return: during,
                ..InstrumentConfig::default()
            };
            let c =
                station_config(&request(&inst, SimStage::Grbl(&g)), &set(100, 0.0015, 8)).unwrap();
            let said = key(&c.toml, "reads-during-return");
            assert_eq!(said, if during { vec!["true"] } else { vec![] });
        }
    }

    #[test]
    fn polls_fit_the_time_scale_and_too_fast_a_scale_is_refused() {
        // 100 points at 1.5 µm plus λc 2.5 mm at 0.5 mm/s: 5.3 s of measuring in real time.
        let at = |time_scale: f64| {
            let inst = InstrumentConfig {
                time_scale,
                ..InstrumentConfig::default()
            };
            let g = GrblSimConfig::default();
            station_config(&request(&inst, SimStage::Grbl(&g)), &set(100, 0.0015, 8))
        };
        let poll = |c: StationConfig| key(&c.toml, "poll-interval-ms")[0].to_string();
        let real = at(1.0).unwrap();
        assert_eq!(key(&real.toml, "measuring-speed-mm-s"), ["0.5"]);
        assert_eq!(key(&real.toml, "return-speed-mm-s"), ["1.0"]);
        assert_eq!(poll(real), "250");
        // 50 times faster: the drive moves at 25 mm/s and returns at 50 mm/s.
        let fast = at(0.02).unwrap();
        assert_eq!(key(&fast.toml, "measuring-speed-mm-s"), ["25.0"]);
        assert_eq!(key(&fast.toml, "return-speed-mm-s"), ["50.0"]);
        assert_eq!(poll(at(0.02).unwrap()), "10"); // 106 ms of measuring
        assert_eq!(poll(at(0.01).unwrap()), "5"); // 53 ms
        match at(0.0) {
            Err(StationConfigError::TooFast { minimum, .. }) => {
                assert_eq!(minimum, 0.0095) // 50 ms / 5300 ms, rounded up
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn settings_no_scan_can_use_are_refused() {
        let g = GrblSimConfig::default();
        let off = InstrumentConfig {
            profile_readout: false,
            ..InstrumentConfig::default()
        };
        assert_eq!(
            station_config(&request(&off, SimStage::Grbl(&g)), &set(100, 0.0015, 8)),
            Err(StationConfigError::NoReadout)
        );
        let inst = InstrumentConfig::default();
        let fast = StationConfigRequest {
            baud: 115200,
            line_check: true,
            ..request(&inst, SimStage::Grbl(&g))
        };
        assert!(matches!(
            station_config(&fast, &set(100, 0.0015, 8)),
            Err(StationConfigError::BaudNotOffered { baud: 115200, .. })
        ));
        let paced = StationConfigRequest {
            line_check: false,
            ..fast
        };
        let c = station_config(&paced, &set(100, 0.0015, 8)).unwrap();
        assert_eq!(key(&c.toml, "baud")[0], "38400");
        let mut mixed = set(100, 0.0015, 8).profiles().to_vec();
        mixed[3].pitch_x_mm = 0.0005;
        let mixed = ProfileSet::new(mixed).unwrap();
        assert!(matches!(
            station_config(&request(&inst, SimStage::Grbl(&g)), &mixed),
            Err(StationConfigError::MixedPitch { .. })
        ));
    }

    #[test]
    fn a_point_count_the_conditions_do_not_give_turns_the_check_off() {
        let g = GrblSimConfig::default();
        let n4 = InstrumentConfig {
            conditions: crate::instrument::Conditions {
                sampling_lengths: 4,
                ..Default::default()
            },
            ..InstrumentConfig::default()
        };
        // λc 2.5 mm, pitch 1.5 µm: 4 × 1666 = 6664 points.
        let ok = station_config(&request(&n4, SimStage::Grbl(&g)), &set(6664, 0.0015, 6)).unwrap();
        assert!(key(&ok.toml, "check-point-count").is_empty(), "{}", ok.toml);
        let short =
            station_config(&request(&n4, SimStage::Grbl(&g)), &set(1067, 0.0015, 6)).unwrap();
        assert_eq!(key(&short.toml, "check-point-count"), ["false"]);
    }
}
