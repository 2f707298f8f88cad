//! The emulated SJ-210 / SJ-410: a sans-IO state machine that takes one parsed frame and the
//! current time (a `Duration` since the simulator started) and returns the reply bytes.
//!
//! Depends on [`crate::command`] (its own parser), [`crate::data`] (served profiles) and
//! [`crate::roughness`] (its own simple Ra/Rq/Rz). Time is an input, so timeline tests need no
//! clock.
//!
//! Status timeline: `000` idle → `CTSTA` → `001` measuring for the trace time → `002` returning
//! for the return time → `000` (or `005`, at the end of travel, when auto-return is off).
//! `CTSTA` while measuring aborts: returning, and no results. Trace time = (evaluation length +
//! λc pre/post-travel) / measuring speed × time scale; return time likewise at the return speed.

use std::time::Duration;

use std::sync::Arc;

use crate::command::{parse, Command};
use crate::data::{ProfileSet, YPosition};
use crate::roughness::{Roughness, PARAMETERS};
use crate::stats::SimStats;

/// Which instrument is emulated; it decides the `{ab}` selector and field widths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    /// SJ-210: no A/B selector, 7-character result values.
    Sj210,
    /// SJ-410: A/B selector byte, 8-character result values, `CTSTP`.
    Sj410,
}

/// Battery states reported by `RDSTU01`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Battery {
    /// `000`: more than 60 %.
    Good,
    /// `001`: below 60 %.
    Low,
    /// `002`: abnormal (temperature, voltage, no battery).
    Abnormal,
    /// `003`: charging.
    Charging,
}

impl Battery {
    fn code(self) -> u8 {
        match self {
            Battery::Good => 0,
            Battery::Low => 1,
            Battery::Abnormal => 2,
            Battery::Charging => 3,
        }
    }
}

/// Measurement conditions reported by `RDCON` (codes as in the SJ-210 manual, p. 17-18).
#[derive(Debug, Clone, PartialEq)]
pub struct Conditions {
    /// Standard: 0 JIS1982, 1 JIS1994, 2 JIS2001, 3 ISO1997, 4 ANSI, 5 VDA, 6 Free.
    pub standard: u8,
    /// Profile: 0 P, 1 R, 2 DF, 3 R-Motif.
    pub profile: u8,
    /// λc code: 0 = 0.08, 1 = 0.25, 2 = 0.8, 3 = 2.5 mm (SJ-410 adds 4 = 8, 5 = 25 mm).
    pub lambda_c_code: u8,
    /// λs code (SJ-410 only): 0 = 2.5 µm, 1 = 8 µm, 2 = 25 µm, 3 = none.
    pub lambda_s_code: u8,
    /// Number of sampling lengths, 0 = arbitrary length.
    pub sampling_lengths: u8,
    /// Filter: 0 2CR75, 1 PC75, 2 GAUSS, 3 None.
    pub filter: u8,
}

impl Default for Conditions {
    /// ISO1997, R profile, λc 2.5 mm, λs 8 µm, arbitrary length, Gaussian: the recording
    /// conditions of the bundled Mitutoyo R profile.
    fn default() -> Self {
        Self {
            standard: 3,
            profile: 1,
            lambda_c_code: 3,
            lambda_s_code: 1,
            sampling_lengths: 0,
            filter: 2,
        }
    }
}

impl Conditions {
    /// λc in mm.
    pub fn lambda_c_mm(&self) -> f64 {
        match self.lambda_c_code {
            0 => 0.08,
            1 => 0.25,
            2 => 0.8,
            4 => 8.0,
            5 => 25.0,
            _ => 2.5,
        }
    }
}

/// How `RDRES` prints a value inside its field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ResultLayout {
    /// As Mitutoyo's own PC export shows the instrument's results: a sign position, then the
    /// number left-justified in the rest of the field (`" 3.308 "`, `" -0.144"`).
    #[default]
    Export,
    /// Right-justified, as the SJ-210 manual's example prints it (`"  3.123"`).
    Manual,
}

/// Which `RDEVA` forms the emulated firmware answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ReadoutForm {
    /// The model's own form: no selector byte on the SJ-210 (`RDEVAnn`), an A/B selector on
    /// the SJ-410 (`RDEVA0nn`, `RDEVA1nn`).
    #[default]
    Model,
    /// Only `RDEVA` with exactly this selector (`None` = `RDEVAnn`, `Some(1)` = `RDEVA1nn`);
    /// every other `RDEVA` form is a known command with a wrong data form (`NG031`).
    Only(Option<u8>),
}

/// Configuration of the emulated instrument. Defaults: SJ-210 with profile read-out, 3 height
/// decimals, auto-return on, reads refused busy while the drive returns, battery good,
/// 0.5 mm/s measuring, 1 mm/s return, real time.
#[derive(Debug, Clone, PartialEq)]
pub struct InstrumentConfig {
    /// The model.
    pub model: Model,
    /// Whether `RDEVA` works (otherwise `NG030`, as the SJ-210 manual documents).
    pub profile_readout: bool,
    /// Which `RDEVA` forms are answered when it works.
    pub readout_form: ReadoutForm,
    /// How `RDRES` values are justified.
    pub result_layout: ResultLayout,
    /// Decimals of heights in `RDEVA` replies (3 = 1 nm).
    pub decimals: u8,
    /// Auto-return after a trace (`000`), or stop at the end of travel (`005`).
    pub auto_return: bool,
    /// Whether results and the profile can be read while the drive returns (status `002`);
    /// otherwise they are refused `NG011` (busy) until it is back. Which one a real SJ-210
    /// does is not documented.
    pub reads_during_return: bool,
    /// Battery state for `RDSTU01`.
    pub battery: Battery,
    /// Firmware string for `RDSJ 01`, 5 characters.
    pub firmware: String,
    /// Conditions for `RDCON`.
    pub conditions: Conditions,
    /// Measuring speed, mm/s.
    pub measure_speed_mm_s: f64,
    /// Return speed, mm/s.
    pub return_speed_mm_s: f64,
    /// Multiplies every simulated duration (0 = instantaneous, 1 = real time).
    pub time_scale: f64,
}

impl Default for InstrumentConfig {
    fn default() -> Self {
        Self {
            model: Model::Sj210,
            profile_readout: true,
            readout_form: ReadoutForm::Model,
            result_layout: ResultLayout::Export,
            decimals: 3,
            auto_return: true,
            reads_during_return: false,
            battery: Battery::Good,
            firmware: "V1.00".to_string(),
            conditions: Conditions::default(),
            measure_speed_mm_s: 0.5,
            return_speed_mm_s: 1.0,
            time_scale: 1.0,
        }
    }
}

/// One reply before framing.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// `OK` + payload.
    Ok(String),
    /// `NG` + 3-digit code.
    Ng(u16),
}

impl Reply {
    /// The bytes on the wire, CR-terminated.
    pub fn to_bytes(&self) -> Vec<u8> {
        match self {
            Reply::Ok(p) => format!("OK{p}\r").into_bytes(),
            Reply::Ng(c) => format!("NG{c:03}\r").into_bytes(),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Phase {
    Idle,
    Measuring {
        start: Duration,
        end: Duration,
        line: usize,
    },
    Returning {
        end: Duration,
    },
    AtEnd,
    Retracting {
        end: Duration,
    },
    Retracted,
}

#[derive(Debug, Clone)]
struct Results {
    heights_um: Vec<f64>,
    roughness: Roughness,
    cursor: usize,
    /// Values served by the last block request (for a `repeat` fault).
    last_block: usize,
}

/// The emulated instrument.
#[derive(Debug)]
pub struct Instrument {
    cfg: InstrumentConfig,
    profiles: ProfileSet,
    stage: Option<YPosition>,
    phase: Phase,
    traces: u64,
    results: Option<Results>,
    last_line: Option<usize>,
    /// Percent by which the result being answered is off (a `skew` fault), 0 normally.
    skew_pct: i32,
    /// Factor of the heights of the trace running or next finished (a `scale` fault), 1
    /// normally.
    scale: f64,
    /// Counters shared with the simulator's host.
    stats: Arc<SimStats>,
}

fn secs(s: f64) -> Duration {
    Duration::try_from_secs_f64(s.max(0.0)).unwrap_or(Duration::MAX)
}

fn round_to(v: f64, decimals: u8) -> f64 {
    let f = 10f64.powi(i32::from(decimals));
    (v * f).round() / f
}

impl Instrument {
    /// A new idle instrument serving `profiles`; `stage` picks the line by y when given.
    pub fn new(cfg: InstrumentConfig, profiles: ProfileSet, stage: Option<YPosition>) -> Self {
        Self {
            cfg,
            profiles,
            stage,
            phase: Phase::Idle,
            traces: 0,
            results: None,
            last_line: None,
            skew_pct: 0,
            scale: 1.0,
            stats: Arc::new(SimStats::default()),
        }
    }

    /// Counts what it is asked into `stats` (shared with the simulator's host).
    pub fn with_stats(mut self, stats: Arc<SimStats>) -> Self {
        self.stats = stats;
        self
    }

    /// Answers a frame as if the read-out cursor had gone back by the last block first: an
    /// `RDEVA` block request then gets the previous block again.
    pub fn respond_repeating_block(&mut self, frame: &[u8], now: Duration) -> Vec<u8> {
        if let Some(r) = self.results.as_mut() {
            r.cursor = r.cursor.saturating_sub(r.last_block);
        }
        self.respond(frame, now)
    }

    /// Answers a frame with any result value off by `pct` percent.
    pub fn respond_skewed(&mut self, frame: &[u8], now: Duration, pct: i32) -> Vec<u8> {
        self.skew_pct = pct;
        let reply = self.respond(frame, now);
        self.skew_pct = 0;
        reply
    }

    /// Answers a frame (a trace's start) so that the trace it starts is served with every
    /// height multiplied by `factor`.
    pub fn respond_scaled(&mut self, frame: &[u8], now: Duration, factor: f64) -> Vec<u8> {
        self.scale = factor;
        self.respond(frame, now)
    }

    /// The configuration.
    pub fn config(&self) -> &InstrumentConfig {
        &self.cfg
    }

    /// Index of the profile served by the last trace started.
    pub fn last_line(&self) -> Option<usize> {
        self.last_line
    }

    /// The heights (µm, rounded as served) the next `RDEVA` read-out returns, if results exist.
    pub fn served_heights_um(&self) -> Option<&[f64]> {
        self.results.as_ref().map(|r| r.heights_um.as_slice())
    }

    /// Power loss (device unplugged): back to idle, measurement and results lost.
    pub fn power_cycle(&mut self) {
        self.phase = Phase::Idle;
        self.results = None;
    }

    fn traverse_mm(&self, line: usize) -> f64 {
        let len = self
            .profiles
            .profiles()
            .get(line)
            .map_or(0.0, |p| p.length_mm());
        len + self.cfg.conditions.lambda_c_mm()
    }

    fn scaled(&self, mm: f64, speed_mm_s: f64) -> Duration {
        if speed_mm_s > 0.0 {
            secs(mm / speed_mm_s * self.cfg.time_scale)
        } else {
            Duration::ZERO
        }
    }

    /// Advances the timeline to `now`.
    fn advance(&mut self, now: Duration) {
        loop {
            match self.phase.clone() {
                Phase::Measuring { end, line, .. } if now >= end => {
                    self.finish_trace(line);
                    self.phase = if self.cfg.auto_return {
                        Phase::Returning {
                            end: end.saturating_add(
                                self.scaled(self.traverse_mm(line), self.cfg.return_speed_mm_s),
                            ),
                        }
                    } else {
                        Phase::AtEnd
                    };
                }
                Phase::Returning { end } if now >= end => self.phase = Phase::Idle,
                Phase::Retracting { end } if now >= end => self.phase = Phase::Retracted,
                _ => return,
            }
        }
    }

    fn finish_trace(&mut self, line: usize) {
        let decimals = self.cfg.decimals;
        let Some(p) = self.profiles.profiles().get(line) else {
            return;
        };
        let scale = std::mem::replace(&mut self.scale, 1.0);
        let heights_um: Vec<f64> = p
            .z_um
            .iter()
            .map(|&z| round_to(z * scale, decimals))
            .collect();
        let segments = usize::from(self.cfg.conditions.sampling_lengths).max(1);
        // An R profile is served as the instrument exports it, already relative to its mean
        // line; other kinds are taken about their arithmetic mean.
        let about_zero = self.cfg.conditions.profile == 1;
        let roughness = Roughness::compute(&heights_um, segments, about_zero);
        self.results = Some(Results {
            heights_um,
            roughness,
            cursor: 0,
            last_block: 0,
        });
    }

    /// The status code `RDSTU00` reports at `now`.
    pub fn status(&mut self, now: Duration) -> u8 {
        self.advance(now);
        match self.phase {
            Phase::Idle => 0,
            Phase::Measuring { .. } => 1,
            Phase::Returning { .. } => 2,
            Phase::Retracting { .. } => 3,
            Phase::Retracted => 4,
            Phase::AtEnd => 5,
        }
    }

    /// Whether a result or profile read is refused busy now: always while measuring or
    /// retracting, while returning unless the firmware reads during the return. Reads during
    /// the return are counted both ways.
    fn refuses_read(&self) -> bool {
        match self.phase {
            Phase::Measuring { .. } | Phase::Retracting { .. } => true,
            Phase::Returning { .. } => {
                let refused = !self.cfg.reads_during_return;
                SimStats::bump(if refused {
                    &self.stats.reads_refused_returning
                } else {
                    &self.stats.reads_answered_returning
                });
                refused
            }
            Phase::Idle | Phase::AtEnd | Phase::Retracted => false,
        }
    }

    /// Handles one frame (terminator removed) at `now`; returns the framed reply bytes.
    pub fn respond(&mut self, frame: &[u8], now: Duration) -> Vec<u8> {
        let reply = match parse(frame) {
            Ok(cmd) => self.handle(cmd, now),
            Err(e) => Reply::Ng(e.ng_code()),
        };
        reply.to_bytes()
    }

    fn selector_ok(&self, ab: Option<u8>) -> bool {
        match self.cfg.model {
            Model::Sj210 => ab.is_none(),
            Model::Sj410 => ab.is_some(),
        }
    }

    /// Handles one parsed command at `now`.
    pub fn handle(&mut self, cmd: Command, now: Duration) -> Reply {
        self.advance(now);
        match cmd {
            Command::Start => self.start_or_abort(now),
            Command::Stop => {
                if self.cfg.model != Model::Sj410 {
                    return Reply::Ng(30);
                }
                if matches!(self.phase, Phase::Measuring { .. }) {
                    self.abort(now);
                }
                Reply::Ok(String::new())
            }
            Command::Off(n) => {
                let max = if self.cfg.model == Model::Sj410 { 4 } else { 2 };
                if n > max {
                    Reply::Ng(32)
                } else {
                    Reply::Ok(String::new())
                }
            }
            Command::Retract => match self.phase {
                Phase::Idle | Phase::AtEnd => {
                    self.phase = Phase::Retracting {
                        end: now.saturating_add(secs(self.cfg.time_scale)),
                    };
                    Reply::Ok(String::new())
                }
                Phase::Retracted => Reply::Ok(String::new()),
                _ => Reply::Ng(11),
            },
            Command::Return => match self.phase {
                Phase::Idle => Reply::Ok(String::new()),
                Phase::AtEnd | Phase::Retracted => {
                    let mm = self.last_line.map_or(0.0, |l| self.traverse_mm(l));
                    self.phase = Phase::Returning {
                        end: now.saturating_add(self.scaled(mm, self.cfg.return_speed_mm_s)),
                    };
                    Reply::Ok(String::new())
                }
                _ => Reply::Ng(11),
            },
            Command::Status => Reply::Ok(format!("{:03}", self.status(now))),
            Command::Battery => Reply::Ok(format!("{:03}", self.cfg.battery.code())),
            Command::DriveType => Reply::Ok("000".to_string()),
            Command::Firmware => Reply::Ok(self.cfg.firmware.clone()),
            Command::Conditions { ab } => {
                if !self.selector_ok(ab) {
                    return Reply::Ng(31);
                }
                Reply::Ok(self.conditions_payload())
            }
            Command::ParamCount { ab } => {
                if !self.selector_ok(ab) {
                    return Reply::Ng(31);
                }
                Reply::Ok(format!("{:02}", PARAMETERS.len()))
            }
            Command::Result {
                ab,
                mode,
                param,
                index,
            } => self.result(ab, mode, param, index),
            Command::Position => Reply::Ok(format!("{:.3}", self.position_um(now))),
            Command::ProfileTotal { ab } => self.profile_read(ab, None),
            Command::ProfileBlock { ab, count } => self.profile_read(ab, Some(count)),
        }
    }

    fn start_or_abort(&mut self, now: Duration) -> Reply {
        match self.phase {
            Phase::Idle => {
                let line = self.profiles.select(self.traces, self.stage.as_ref());
                self.traces += 1;
                self.last_line = Some(line);
                self.results = None;
                let end = now.saturating_add(
                    self.scaled(self.traverse_mm(line), self.cfg.measure_speed_mm_s),
                );
                self.phase = Phase::Measuring {
                    start: now,
                    end,
                    line,
                };
                Reply::Ok(String::new())
            }
            Phase::Measuring { .. } => {
                self.abort(now);
                Reply::Ok(String::new())
            }
            Phase::Retracted => Reply::Ng(18),
            _ => Reply::Ng(11),
        }
    }

    /// Aborts a measurement: return over the distance travelled so far, no results.
    fn abort(&mut self, now: Duration) {
        if let Phase::Measuring { start, end, line } = self.phase {
            let total = end.saturating_sub(start).as_secs_f64();
            let frac = if total > 0.0 {
                (now.saturating_sub(start).as_secs_f64() / total).min(1.0)
            } else {
                1.0
            };
            let mm = self.traverse_mm(line) * frac;
            self.results = None;
            self.phase = Phase::Returning {
                end: now.saturating_add(self.scaled(mm, self.cfg.return_speed_mm_s)),
            };
        }
    }

    fn position_um(&self, now: Duration) -> f64 {
        if let Phase::Measuring { start, end, line } = self.phase {
            let total = end.saturating_sub(start).as_secs_f64();
            if let Some(p) = self.profiles.profiles().get(line) {
                let frac = if total > 0.0 {
                    now.saturating_sub(start).as_secs_f64() / total
                } else {
                    0.0
                };
                let i = ((p.z_um.len() as f64 * frac) as usize).min(p.z_um.len().saturating_sub(1));
                return p.z_um.get(i).copied().unwrap_or(0.0);
            }
        }
        0.0
    }

    fn conditions_payload(&self) -> String {
        let c = &self.cfg.conditions;
        // Arbitrary evaluation length: the served profile's length (first profile before any
        // trace), printed `**.**` mm as on the SJ-210.
        let len = self
            .last_line
            .or(Some(0))
            .and_then(|l| self.profiles.profiles().get(l))
            .map_or(0.0, |p| p.length_mm());
        match self.cfg.model {
            Model::Sj210 => format!(
                "{}{}{}{:02}{:05.2}1{}",
                c.standard,
                c.profile,
                c.lambda_c_code,
                c.sampling_lengths,
                len.min(99.99),
                c.filter
            ),
            // SJ-410 order (manual p. 22-?? CON write data, and one reply seen in public code):
            // A/B, standard, profile, filter, λs, λc, W cut-off, N, arbitrary length, then the
            // motif limits copied from that observed reply.
            Model::Sj410 => format!(
                "0{}{}{}{}{}2{:02}{:.3}220.0030.019",
                c.standard,
                c.profile,
                c.filter,
                c.lambda_s_code,
                c.lambda_c_code,
                c.sampling_lengths,
                len
            ),
        }
    }

    fn result(&mut self, ab: Option<u8>, mode: u8, param: u8, index: u8) -> Reply {
        if !self.selector_ok(ab) {
            return Reply::Ng(31);
        }
        if self.refuses_read() {
            return Reply::Ng(11);
        }
        let Some(res) = &self.results else {
            return Reply::Ng(101);
        };
        let Some(p) = usize::from(param).checked_sub(1) else {
            return Reply::Ng(32);
        };
        let Some(&(name, unit)) = PARAMETERS.get(p) else {
            return Reply::Ng(32);
        };
        let Some(value) = res.roughness.value(p, usize::from(index)) else {
            return Reply::Ng(32);
        };
        let value = value * (1.0 + f64::from(self.skew_pct) / 100.0);
        let width = if self.cfg.model == Model::Sj410 { 8 } else { 7 };
        let field = match self.cfg.result_layout {
            ResultLayout::Export => export_field(value, width),
            ResultLayout::Manual => fit_width(value, width),
        };
        let Some(v) = field else {
            return Reply::Ng(102);
        };
        match mode {
            0 => Reply::Ok(v),
            1 => Reply::Ok("3".to_string()),
            _ => Reply::Ok(format!("{name:<6}{v}{unit:>3}")),
        }
    }

    fn profile_read(&mut self, ab: Option<u8>, count: Option<u8>) -> Reply {
        if !self.cfg.profile_readout {
            return Reply::Ng(30);
        }
        let form_ok = match self.cfg.readout_form {
            ReadoutForm::Model => self.selector_ok(ab),
            ReadoutForm::Only(sel) => ab == sel,
        };
        if !form_ok {
            return Reply::Ng(31);
        }
        if self.refuses_read() {
            return Reply::Ng(11);
        }
        let decimals = usize::from(self.cfg.decimals);
        let Some(res) = self.results.as_mut() else {
            return Reply::Ng(101);
        };
        match count {
            None => {
                res.cursor = 0;
                Reply::Ok(format!("{:05}", res.heights_um.len()))
            }
            Some(n) => {
                let start = res.cursor.min(res.heights_um.len());
                let end = (start + usize::from(n)).min(res.heights_um.len());
                res.cursor = end;
                res.last_block = end - start;
                let Some(block) = res.heights_um.get(start..end) else {
                    return Reply::Ok("00,0.0".to_string());
                };
                if block.is_empty() {
                    // After the last value the manual says the count reads "0.0".
                    return Reply::Ok("00,0.0".to_string());
                }
                let mut s = format!("{:02}", block.len());
                for v in block {
                    s.push_str(&format!(",{v:>9.decimals$}"));
                }
                Reply::Ok(s)
            }
        }
    }
}

/// Formats `value` as Mitutoyo's export shows it: one sign position, then the number with as
/// many of 3 decimals as fit, left-justified in the remaining `width − 1` characters.
fn export_field(value: f64, width: usize) -> Option<String> {
    let inner = width.checked_sub(1)?;
    (0..=3usize)
        .rev()
        .map(|d| format!("{value:.d$}"))
        .find(|s| s.len() <= inner)
        .map(|s| format!(" {s:<inner$}"))
}

/// Formats `value` right-justified in `width` characters with as many of 3 decimals as fit.
fn fit_width(value: f64, width: usize) -> Option<String> {
    (0..=3usize)
        .rev()
        .map(|d| format!("{value:>width$.d$}"))
        .find(|s| s.len() == width)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::ServedProfile;

    fn set() -> ProfileSet {
        // Two 4-point profiles at 0.5 mm pitch: length 2 mm, + λc 2.5 mm = 4.5 mm traverse.
        ProfileSet::new(vec![
            ServedProfile {
                y_mm: 0.0,
                pitch_x_mm: 0.5,
                z_um: vec![1.0, -1.0, 3.0, -3.0],
            },
            ServedProfile {
                y_mm: 0.01,
                pitch_x_mm: 0.5,
                z_um: vec![0.12345, 0.0, 0.0, 0.0],
            },
        ])
        .unwrap()
    }

    fn s(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    fn ask(i: &mut Instrument, cmd: &str, at_ms: u64) -> String {
        String::from_utf8(i.respond(cmd.as_bytes(), s(at_ms))).unwrap()
    }

    #[test]
    fn timeline_measure_return_idle() {
        // 4.5 mm at 0.5 mm/s = 9 s measuring; at 1 mm/s = 4.5 s returning. Results in the
        // manual's right-justified layout.
        let cfg = InstrumentConfig {
            result_layout: ResultLayout::Manual,
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        assert_eq!(ask(&mut i, "RDSTU00", 0), "OK000\r");
        assert_eq!(ask(&mut i, "RDRES02,01,00", 0), "NG101\r");
        assert_eq!(ask(&mut i, "CTSTA", 1000), "OK\r");
        assert_eq!(ask(&mut i, "RDSTU00", 1001), "OK001\r");
        assert_eq!(ask(&mut i, "RDRES02,01,00", 5000), "NG011\r");
        assert_eq!(ask(&mut i, "CTRTN", 5000), "NG011\r");
        assert_eq!(ask(&mut i, "RDSTU00", 9999), "OK001\r");
        assert_eq!(ask(&mut i, "RDSTU00", 10000), "OK002\r");
        assert_eq!(ask(&mut i, "CTSTA", 12000), "NG011\r");
        assert_eq!(ask(&mut i, "RDSTU00", 14499), "OK002\r");
        assert_eq!(ask(&mut i, "RDSTU00", 14500), "OK000\r");
        // Ra of [1,-1,3,-3] (mean 0) = 2; Rq = sqrt(5) = 2.236; Rz = 6.
        assert_eq!(ask(&mut i, "RDRES02,01,00", 14500), "OKRa      2.000 um\r");
        assert_eq!(ask(&mut i, "RDRES02,02,00", 14500), "OKRq      2.236 um\r");
        assert_eq!(ask(&mut i, "RDRES00,03,00", 14500), "OK  6.000\r");
        assert_eq!(ask(&mut i, "RDRES01,03,00", 14500), "OK3\r");
        // Rp 3, Rsk 0 (unitless), beyond the 9 customised parameters NG032.
        assert_eq!(ask(&mut i, "RDRES02,04,00", 14500), "OKRp      3.000 um\r");
        assert_eq!(ask(&mut i, "RDRES02,07,00", 14500), "OKRsk     0.000   \r");
        assert_eq!(ask(&mut i, "RDRES02,10,00", 14500), "NG032\r");
        assert_eq!(ask(&mut i, "RDPAR", 14500), "OK09\r");
    }

    #[test]
    fn reads_during_the_return_are_refused_busy_or_answered_as_configured() {
        // 9 s measuring from 1 s, returning 10 s to 14.5 s (see the timeline test).
        for during in [false, true] {
            let cfg = InstrumentConfig {
                reads_during_return: during,
                result_layout: ResultLayout::Manual,
                ..InstrumentConfig::default()
            };
            let stats = Arc::new(SimStats::default());
            let mut i = Instrument::new(cfg, set(), None).with_stats(stats.clone());
            assert_eq!(ask(&mut i, "CTSTA", 1000), "OK\r");
            // Measuring: busy either way, and not counted as a read during the return.
            assert_eq!(ask(&mut i, "RDEVA00", 9999), "NG011\r");
            assert_eq!(ask(&mut i, "RDSTU00", 10000), "OK002\r");
            let total = ask(&mut i, "RDEVA00", 10001);
            let ra = ask(&mut i, "RDRES00,01,00", 10002);
            if during {
                assert_eq!(total, "OK00004\r");
                assert_eq!(ra, "OK  2.000\r");
                assert_eq!(
                    ask(&mut i, "RDEVA04", 10003),
                    "OK04,    1.000,   -1.000,    3.000,   -3.000\r"
                );
                assert_eq!(SimStats::get(&stats.reads_answered_returning), 3);
                assert_eq!(SimStats::get(&stats.reads_refused_returning), 0);
            } else {
                assert_eq!(total, "NG011\r");
                assert_eq!(ra, "NG011\r");
                assert_eq!(SimStats::get(&stats.reads_answered_returning), 0);
                assert_eq!(SimStats::get(&stats.reads_refused_returning), 2);
            }
            // Back at the start, the same answers either way; the status still says 002
            // until the return is over, whatever was read meanwhile.
            assert_eq!(ask(&mut i, "RDSTU00", 14499), "OK002\r");
            assert_eq!(ask(&mut i, "RDSTU00", 14500), "OK000\r");
            assert_eq!(ask(&mut i, "RDEVA00", 14501), "OK00004\r");
            assert_eq!(ask(&mut i, "RDRES00,01,00", 14502), "OK  2.000\r");
        }
    }

    #[test]
    fn auto_return_off_stops_at_005_until_ctrtn() {
        let cfg = InstrumentConfig {
            auto_return: false,
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        assert_eq!(ask(&mut i, "CTSTA", 0), "OK\r");
        assert_eq!(ask(&mut i, "RDSTU00", 9000), "OK005\r");
        assert_eq!(ask(&mut i, "RDSTU00", 60000), "OK005\r");
        assert_eq!(ask(&mut i, "CTSTA", 60000), "NG011\r");
        assert_eq!(ask(&mut i, "CTRTN", 60000), "OK\r");
        assert_eq!(ask(&mut i, "RDSTU00", 60001), "OK002\r");
        assert_eq!(ask(&mut i, "RDSTU00", 64500), "OK000\r");
    }

    #[test]
    fn abort_returns_over_travelled_distance_without_results() {
        let mut i = Instrument::new(InstrumentConfig::default(), set(), None);
        ask(&mut i, "CTSTA", 0);
        // Abort at 3 s of 9 s: 1.5 mm travelled, 1.5 s return.
        assert_eq!(ask(&mut i, "CTSTA", 3000), "OK\r");
        assert_eq!(ask(&mut i, "RDSTU00", 4499), "OK002\r");
        assert_eq!(ask(&mut i, "RDSTU00", 4500), "OK000\r");
        assert_eq!(ask(&mut i, "RDRES02,01,00", 4500), "NG101\r");
        assert_eq!(ask(&mut i, "RDEVA00", 4500), "NG101\r");
    }

    #[test]
    fn rdeva_cursor_blocks_and_end_marker() {
        let cfg = InstrumentConfig {
            time_scale: 0.0,
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        ask(&mut i, "CTSTA", 0);
        assert_eq!(ask(&mut i, "RDEVA00", 0), "OK00004\r");
        assert_eq!(
            ask(&mut i, "RDEVA03", 0),
            "OK03,    1.000,   -1.000,    3.000\r"
        );
        assert_eq!(ask(&mut i, "RDEVA50", 0), "OK01,   -3.000\r");
        assert_eq!(ask(&mut i, "RDEVA50", 0), "OK00,0.0\r");
        // The total request rewinds the cursor.
        assert_eq!(ask(&mut i, "RDEVA00", 0), "OK00004\r");
        assert_eq!(ask(&mut i, "RDEVA01", 0), "OK01,    1.000\r");
        // SJ-210 has no selector byte.
        assert_eq!(ask(&mut i, "RDEVA100", 0), "NG031\r");
        // Second trace serves the second profile, heights rounded to 3 decimals.
        ask(&mut i, "CTSTA", 0);
        assert_eq!(ask(&mut i, "RDEVA00", 0), "OK00004\r");
        assert_eq!(ask(&mut i, "RDEVA01", 0), "OK01,    0.123\r");
    }

    #[test]
    fn sj410_layouts_and_unsupported_readout() {
        let cfg = InstrumentConfig {
            model: Model::Sj410,
            time_scale: 0.0,
            result_layout: ResultLayout::Manual,
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        ask(&mut i, "CTSTA", 0);
        assert_eq!(ask(&mut i, "RDRES002,01,00", 0), "OKRa       2.000 um\r");
        assert_eq!(ask(&mut i, "RDRES02,01,00", 0), "NG031\r");
        assert_eq!(ask(&mut i, "RDEVA100", 0), "OK00004\r");
        // 0 A, ISO1997 3, R 1, GAUSS 2, λs 8 µm 1, λc 2.5 mm 3, W 2, N 00, 2.000 mm.
        assert_eq!(ask(&mut i, "RDCON1", 0), "OK0312132002.000220.0030.019\r");
        let no_eva = InstrumentConfig {
            profile_readout: false,
            ..InstrumentConfig::default()
        };
        let mut j = Instrument::new(no_eva, set(), None);
        assert_eq!(ask(&mut j, "RDEVA00", 0), "NG030\r");
        // SJ-210 RDCON: ISO1997, R, λc 2.5, N 00, 02.00 mm, motif 1, GAUSS.
        assert_eq!(ask(&mut j, "RDCON", 0), "OK3130002.0012\r");
    }

    #[test]
    fn identity_battery_and_bad_frames() {
        let cfg = InstrumentConfig {
            battery: Battery::Abnormal,
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        assert_eq!(ask(&mut i, "RDSTU01", 0), "OK002\r");
        assert_eq!(ask(&mut i, "RDSJ 00", 0), "OK000\r");
        assert_eq!(ask(&mut i, "RDSJ 01", 0), "OKV1.00\r");
        assert_eq!(ask(&mut i, "CTOFF01", 0), "OK\r");
        assert_eq!(ask(&mut i, "CTOFF07", 0), "NG032\r");
        assert_eq!(ask(&mut i, "HELLO", 0), "NG030\r");
        assert_eq!(ask(&mut i, "CTSTP", 0), "NG030\r");
        assert_eq!(ask(&mut i, "CTESP", 0), "OK\r");
        assert_eq!(ask(&mut i, "RDSTU00", 1), "OK003\r");
        assert_eq!(ask(&mut i, "RDSTU00", 1000), "OK004\r");
        assert_eq!(ask(&mut i, "CTSTA", 1000), "NG018\r");
    }

    #[test]
    fn extreme_time_scale_and_direct_commands_do_not_panic() {
        let cfg = InstrumentConfig {
            time_scale: f64::INFINITY,
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        assert_eq!(ask(&mut i, "CTSTA", 0), "OK\r");
        assert_eq!(ask(&mut i, "RDSTU00", u64::MAX / 2), "OK001\r");
        let mut j = Instrument::new(
            InstrumentConfig {
                time_scale: 0.0,
                ..InstrumentConfig::default()
            },
            set(),
            None,
        );
        j.handle(Command::Start, s(0));
        let r = j.handle(
            Command::Result {
                ab: None,
                mode: 2,
                param: 0,
                index: 0,
            },
            s(0),
        );
        assert_eq!(r, Reply::Ng(32));
    }

    #[test]
    fn results_in_the_export_layout_and_an_r_profile_about_its_mean_line() {
        let cfg = InstrumentConfig {
            time_scale: 0.0,
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        ask(&mut i, "CTSTA", 0);
        ask(&mut i, "CTSTA", 0);
        ask(&mut i, "CTSTA", 0);
        // Third trace serves profile 0 again ([1, -1, 3, -3]): Ra 2, Rq sqrt(5), Rz 6.
        assert_eq!(ask(&mut i, "RDRES02,01,00", 0), "OKRa     2.000  um\r");
        assert_eq!(ask(&mut i, "RDRES00,03,00", 0), "OK 6.000 \r");
        // Profile 1 ([0.123, 0, 0, 0], an R profile): Ra about zero, not about its mean.
        ask(&mut i, "CTSTA", 0);
        assert_eq!(ask(&mut i, "RDRES02,01,00", 0), "OKRa     0.031  um\r");
        assert_eq!(export_field(-0.144, 7).as_deref(), Some(" -0.144"));
        assert_eq!(export_field(3.308, 7).as_deref(), Some(" 3.308 "));
        assert_eq!(export_field(123.456, 7).as_deref(), Some(" 123.46"));
        assert_eq!(export_field(-1234567.0, 7), None);
    }

    #[test]
    fn readout_answers_only_the_configured_form() {
        let cfg = InstrumentConfig {
            time_scale: 0.0,
            readout_form: ReadoutForm::Only(Some(1)),
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        ask(&mut i, "CTSTA", 0);
        assert_eq!(ask(&mut i, "RDEVA00", 0), "NG031\r");
        assert_eq!(ask(&mut i, "RDEVA000", 0), "NG031\r");
        assert_eq!(ask(&mut i, "RDEVA100", 0), "OK00004\r");
        assert_eq!(ask(&mut i, "RDEVA102", 0), "OK02,    1.000,   -1.000\r");
    }

    #[test]
    fn repeated_block_and_skewed_result_faults() {
        let cfg = InstrumentConfig {
            time_scale: 0.0,
            ..InstrumentConfig::default()
        };
        let mut i = Instrument::new(cfg, set(), None);
        ask(&mut i, "CTSTA", 0);
        assert_eq!(ask(&mut i, "RDEVA00", 0), "OK00004\r");
        assert_eq!(ask(&mut i, "RDEVA02", 0), "OK02,    1.000,   -1.000\r");
        let again = String::from_utf8(i.respond_repeating_block(b"RDEVA02", s(0))).unwrap();
        assert_eq!(again, "OK02,    1.000,   -1.000\r");
        assert_eq!(ask(&mut i, "RDEVA02", 0), "OK02,    3.000,   -3.000\r");
        // Ra 2.000 off by +20 %; the next answer is right again.
        let skewed = String::from_utf8(i.respond_skewed(b"RDRES02,01,00", s(0), 20)).unwrap();
        assert_eq!(skewed, "OKRa     2.400  um\r");
        assert_eq!(ask(&mut i, "RDRES02,01,00", 0), "OKRa     2.000  um\r");
    }

    #[test]
    fn fit_width_drops_decimals_then_gives_up() {
        assert_eq!(fit_width(3.1234, 7).as_deref(), Some("  3.123"));
        assert_eq!(fit_width(12345.6, 7).as_deref(), Some("12345.6"));
        assert_eq!(fit_width(-1234567.0, 7), None);
    }
}
