//! The controller's state machine: motion (planner trapezoids), the homing cycle, resets,
//! real-time bytes, line cleaning and execution, status reports. Sans-IO: bytes and simulated
//! time in, timed output out; [`super::serve`] drives it.
//!
//! Depends on [`super::settings`], [`crate::motion`] and [`super::StageShared`].

use super::settings::Settings;
use super::{GrblSimConfig, StageShared};
use crate::motion::Profile;
use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;
use tokio::time::Instant;

const BANNER: &str = "\r\nGrbl 1.1h ['$' for help]\r\n";
const MSG_UNLOCK: &str = "[MSG:'$H'|'$X' to unlock]\r\n";
/// GRBL holds everything for 500 ms after printing an alarm.
const ALARM_PAUSE_S: f64 = 0.5;
/// Planner blocks (BLOCK_BUFFER_SIZE − 1) and serial receive buffer of an ATmega328p build.
const PLANNER_BLOCKS: usize = 15;
const RX_BUFFER: usize = 128;
const LINE_BUFFER: usize = 80;
const MM_PER_INCH: f64 = 25.4;

#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    Idle,
    Jog,
    /// Feed hold at rest (`!` while idle), left with `~`.
    Hold,
    Home,
    Alarm,
    /// After `ALARM:1`/`ALARM:2`: only a soft reset is heard.
    Locked,
}

/// The simulated clock: seconds of simulated time since the board started.
#[derive(Debug, Clone, Copy)]
pub(super) struct Clock {
    t0: Instant,
    scale: f64,
}

impl Clock {
    pub(super) fn sim(&self, at: Instant) -> f64 {
        at.saturating_duration_since(self.t0).as_secs_f64() * self.scale
    }

    /// The first real instant at which simulated time has reached `t`; `None` when it cannot
    /// be represented. Whole nanoseconds can fall a hair short of `t` (56.659000000000006 s
    /// becomes 56.659 s): woken there, the controller would find nothing due and sleep until
    /// the same instant again, for ever. So the instant is stepped up until it is not short.
    fn real(&self, t: f64) -> Option<Instant> {
        let d = Duration::try_from_secs_f64(t / self.scale).ok()?;
        let mut at = self.t0.checked_add(d)?;
        for _ in 0..64 {
            if self.sim(at) >= t {
                return Some(at);
            }
            at = at.checked_add(Duration::from_nanos(1))?;
        }
        // Past 64 ns of rounding (a time scale far below 1): a microsecond later is enough.
        at.checked_add(Duration::from_micros(1))
    }
}

/// One motion of the motor, in physical steps.
#[derive(Debug, Clone, Copy)]
struct Move {
    /// Simulated start time, s.
    start: f64,
    /// Motor position at the start, steps.
    from: i64,
    /// +1 up (towards the switch), −1 down.
    sign: i64,
    /// The planned profile, steps.
    prof: Profile,
    /// Where the motion really ends (a homing approach stops at the switch), steps along the
    /// profile.
    stop_at: f64,
    /// When the carriage trips the switch with hard limits enabled, simulated s.
    hard_limit_at: Option<f64>,
}

impl Move {
    fn end(&self) -> f64 {
        self.start + self.prof.time_at(self.stop_at)
    }

    fn motor_at(&self, t: f64) -> i64 {
        let p = self.prof.position(t - self.start).min(self.stop_at);
        self.from + self.sign * p.round() as i64
    }

    fn speed_at(&self, t: f64) -> f64 {
        if t >= self.end() {
            0.0
        } else {
            self.prof.speed(t - self.start)
        }
    }
}

/// A jog waiting in the planner: target counter position, steps, and feed, mm/min.
#[derive(Debug, Clone, Copy)]
struct Queued {
    target: i64,
    feed_mm_min: f64,
}

/// The phases of GRBL's homing cycle (one locate cycle).
#[derive(Debug, Clone, Copy, PartialEq)]
enum HomePhase {
    Seek,
    PullOff1,
    Locate,
    PullOff2,
}

#[derive(Debug, Clone, Copy)]
struct Homing {
    phase: HomePhase,
    /// End of the debounce pause after the current phase's motion, once it ended.
    debounce_until: Option<f64>,
    /// A `?` arrived during the cycle: one `<Home|…>` report just before the `ok`.
    status_requested: bool,
}

pub(super) struct Machine {
    cfg: GrblSimConfig,
    pub(super) shared: Arc<StageShared>,
    settings: Settings,
    pub(super) clock: Clock,
    state: State,
    /// Motor position, physical steps (0 = the switch trips, moving toward it with the
    /// backlash taken up).
    motor: i64,
    /// Which end of travel the home switch is at: +1 the positive end (travel below it), −1
    /// the negative end (travel above it).
    switch_side: i64,
    /// Motor minus GRBL's position counter.
    offset: i64,
    /// Carriage position, physical steps: within [motor, motor + backlash].
    carriage: i64,
    backlash: i64,
    mv: Option<Move>,
    /// Whether the current motion is a jog being cancelled (still reported as `Jog`).
    cancelling: bool,
    queue: VecDeque<Queued>,
    /// The parser's position: where the last accepted jog ends, counter steps.
    planned: i64,
    homing: Option<Homing>,
    /// Output with the simulated time at which it is written, in order.
    out: VecDeque<(f64, String)>,
    /// Everything (real-time bytes too) waits until then: GRBL's alarm pause.
    hold_all_until: f64,
    /// Bytes that arrived during the alarm pause.
    deferred: Vec<u8>,
    /// Lines wait until then (a dwell).
    hold_lines_until: f64,
    /// The serial receive buffer: line bytes not yet taken by the main loop.
    rx: VecDeque<u8>,
    line: Vec<u8>,
    in_paren: bool,
    in_semicolon: bool,
    overflow: bool,
    wco_counter: u8,
    ovr_counter: u8,
    pub(super) silent: bool,
    pub(super) alarm2_next: bool,
    pub(super) error15_next: bool,
    build_info: String,
}

/// A line's reply: text now, or text after a pause (a dwell's `ok`).
fn reply(s: &str) -> String {
    format!("{s}\r\n")
}

fn error(code: u8) -> String {
    format!("error:{code}\r\n")
}

/// GRBL's number reader: optional sign, digits with at most one point, no exponent.
fn read_number(b: &[u8]) -> Option<(f64, usize)> {
    let mut i = 0;
    if matches!(b.first(), Some(b'-' | b'+')) {
        i = 1;
    }
    let digits_start = i;
    let mut seen_point = false;
    while let Some(&c) = b.get(i) {
        if c.is_ascii_digit() {
            i += 1;
        } else if c == b'.' && !seen_point {
            seen_point = true;
            i += 1;
        } else {
            break;
        }
    }
    let body = b.get(digits_start..i)?;
    if !body.iter().any(u8::is_ascii_digit) {
        return None;
    }
    let v: f64 = std::str::from_utf8(b.get(..i)?).ok()?.parse().ok()?;
    Some((v, i))
}

/// Splits a cleaned G-code block into (letter, value) words; `Err(code)` as GRBL reports.
fn words(b: &[u8]) -> Result<Vec<(u8, f64)>, u8> {
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(&c) = b.get(i) {
        if !c.is_ascii_uppercase() {
            return Err(1); // expected command letter
        }
        let (v, n) = read_number(b.get(i + 1..).unwrap_or(&[])).ok_or(2u8)?;
        out.push((c, v));
        i += 1 + n;
    }
    Ok(out)
}

impl Machine {
    pub(super) fn new(cfg: GrblSimConfig, shared: Arc<StageShared>) -> Machine {
        let scale = if cfg.time_scale.is_finite() && cfg.time_scale > 0.0 {
            cfg.time_scale
        } else {
            1.0
        };
        let settings = if cfg.blank_settings {
            Settings::firmware_defaults()
        } else {
            Settings::programmed(&cfg)
        };
        let motor = (cfg.start_mm * cfg.steps_per_mm).round() as i64;
        let backlash = (cfg.backlash_mm * cfg.steps_per_mm).round() as i64;
        let homed = cfg.homed_at_start && !cfg.blank_settings;
        let mut m = Machine {
            shared,
            clock: Clock {
                t0: Instant::now(),
                scale,
            },
            state: State::Idle,
            motor,
            offset: 0,
            switch_side: if cfg.home_switch_at_negative_end {
                -1
            } else {
                1
            },
            carriage: motor,
            backlash,
            mv: None,
            cancelling: false,
            queue: VecDeque::new(),
            planned: 0,
            homing: None,
            out: VecDeque::new(),
            hold_all_until: 0.0,
            deferred: Vec::new(),
            hold_lines_until: 0.0,
            rx: VecDeque::new(),
            line: Vec::new(),
            in_paren: false,
            in_semicolon: false,
            overflow: false,
            wco_counter: 0,
            ovr_counter: 0,
            silent: false,
            alarm2_next: false,
            error15_next: false,
            build_info: cfg.build_info.clone(),
            settings,
            cfg,
        };
        m.offset = if homed { m.home_offset() } else { motor };
        m.planned = m.counter();
        m.set_motor(motor);
        m.state = if !homed && m.settings.flag(22) {
            State::Alarm
        } else {
            State::Idle
        };
        let mut boot = String::new();
        if m.cfg.blank_settings {
            boot.push_str(&error(7));
            boot.push_str(&m.settings.listing());
        }
        boot.push_str(&m.boot_text());
        if m.cfg.banner_at_open {
            m.emit(0.0, boot);
        }
        m
    }

    /// The banner and the messages GRBL prints after it (limits check, alarm lock).
    fn boot_text(&mut self) -> String {
        let mut s = BANNER.to_string();
        if self.settings.flag(21) && self.switch_pressed() {
            self.state = State::Alarm;
            s.push_str("[MSG:Check Limits]\r\n");
        }
        if self.state == State::Alarm {
            s.push_str(MSG_UNLOCK);
        }
        s
    }

    fn emit(&mut self, t: f64, s: String) {
        if !s.is_empty() {
            self.out.push_back((t, s));
        }
    }

    fn spm(&self) -> f64 {
        self.settings.steps_per_mm()
    }

    /// GRBL's position counter (what MPos reports), steps.
    fn counter(&self) -> i64 {
        self.motor - self.offset
    }

    fn switch_pressed(&self) -> bool {
        self.carriage * self.switch_side >= 0
    }

    /// Where the motor stands when the carriage trips the switch moving toward it: the
    /// carriage is pushed by the motor moving up, and trails it by the backlash moving down.
    fn trip_motor(&self) -> i64 {
        if self.switch_side > 0 {
            0
        } else {
            -self.backlash
        }
    }

    /// How far the motor moves from `from` in direction `sign` until the carriage trips the
    /// switch, steps; `None` when that direction leads away from it.
    fn switch_distance(&self, from: i64, sign: i64) -> Option<f64> {
        (sign == self.switch_side).then(|| ((self.trip_motor() - from) * sign).max(0) as f64)
    }

    /// The direction GRBL's homing cycle approaches the switch in: `$23` bit 1 (Y) set is
    /// negative.
    fn homing_sign(&self) -> i64 {
        if (self.settings.get(23) as u32) & 2 != 0 {
            -1
        } else {
            1
        }
    }

    /// GRBL's counter once a homing cycle has ended (`limits_go_home`): 0 in a
    /// `HOMING_FORCE_SET_ORIGIN` build; otherwise −pull-off, or −`$131` + pull-off for an
    /// axis homing toward negative.
    fn homed_counter(&self) -> i64 {
        let spm = self.spm();
        if self.cfg.force_set_origin {
            0
        } else if self.homing_sign() < 0 {
            ((self.settings.get(27) - self.settings.get(131)) * spm).round() as i64
        } else {
            -(self.settings.get(27) * spm).round() as i64
        }
    }

    /// Motor minus counter after a homing cycle that ended where it should: pulled off the
    /// switch by `$27`.
    fn home_offset(&self) -> i64 {
        let pulloff = (self.settings.get(27) * self.spm()).round() as i64;
        self.trip_motor() - self.switch_side * pulloff - self.homed_counter()
    }

    /// The machine space soft limits hold jog targets to, mm (`system_check_travel_limits`).
    fn soft_travel_mm(&self) -> (f64, f64) {
        let travel = self.settings.get(131);
        if self.cfg.force_set_origin && self.homing_sign() < 0 {
            (0.0, travel)
        } else {
            (-travel, 0.0)
        }
    }

    fn set_motor(&mut self, m: i64) {
        self.motor = m;
        self.carriage = self.carriage.clamp(m, m + self.backlash);
        let nm = (self.carriage as f64 * 1e6 / self.cfg.steps_per_mm).round() as i64;
        self.shared.publish_position_nm(nm);
    }

    /// Accel in steps/s² and a feed in mm/min as steps/s (capped at `$111`).
    fn rates(&self, feed_mm_min: f64) -> (f64, f64) {
        let spm = self.spm();
        let feed = feed_mm_min.min(self.settings.get(111));
        (self.settings.get(121) * spm, feed / 60.0 * spm)
    }

    fn start_move(&mut self, t: f64, distance: f64, sign: i64, speed: f64, accel: f64) {
        let prof = Profile::new(distance, 0.0, speed, accel);
        self.mv = Some(Move {
            start: t,
            from: self.motor,
            sign,
            prof,
            stop_at: prof.distance(),
            hard_limit_at: None,
        });
    }

    fn start_jog(&mut self, t: f64, q: Queued) {
        let d = q.target - self.counter();
        let (accel, speed) = self.rates(q.feed_mm_min);
        self.start_move(t, d.unsigned_abs() as f64, d.signum(), speed, accel);
        // Moving toward the switch, the carriage trips it (a pin change) when the motor
        // reaches the trip point.
        let toward = self.switch_distance(self.motor, d.signum());
        if let (true, false, Some(dist)) = (self.settings.flag(21), self.switch_pressed(), toward) {
            if let Some(mv) = self.mv.as_mut() {
                if dist <= mv.stop_at {
                    mv.hard_limit_at = Some(mv.start + mv.prof.time_at(dist));
                }
            }
        }
        self.cancelling = false;
        self.state = State::Jog;
    }

    /// When the current jog runs onto the switch with hard limits enabled.
    fn hard_limit_time(&self) -> Option<f64> {
        self.mv.as_ref()?.hard_limit_at
    }

    /// The next simulated time at which something happens by itself.
    fn next_event(&self) -> Option<f64> {
        let mut t: Option<f64> = None;
        let mut consider = |x: f64| {
            t = Some(t.map_or(x, |y: f64| y.min(x)));
        };
        if let Some(mv) = &self.mv {
            consider(mv.end());
        }
        if let Some(h) = self.hard_limit_time() {
            consider(h);
        }
        if let Some(d) = self.homing.and_then(|h| h.debounce_until) {
            consider(d);
        }
        if self.hold_all_until > 0.0 {
            consider(self.hold_all_until);
        }
        if self.hold_lines_until > 0.0 {
            consider(self.hold_lines_until);
        }
        t
    }

    /// The real instant of the next self-driven event or pending output.
    pub(super) fn next_deadline(&self) -> Option<Instant> {
        let mut t = self.next_event();
        if let Some(&(o, _)) = self.out.front() {
            t = Some(t.map_or(o, |x| x.min(o)));
        }
        t.and_then(|t| self.clock.real(t))
    }

    /// Advances the machine to simulated time `now`, handling every event on the way.
    pub(super) fn advance(&mut self, now: f64) {
        while let Some(t) = self.next_event().filter(|&t| t <= now) {
            self.handle_event(t);
        }
        if let Some(mv) = self.mv {
            self.set_motor(mv.motor_at(now));
        }
    }

    fn handle_event(&mut self, t: f64) {
        if self.hold_all_until > 0.0 && self.hold_all_until <= t {
            self.hold_all_until = 0.0;
            let bytes = std::mem::take(&mut self.deferred);
            self.receive(&bytes, t);
            return;
        }
        if self.hold_lines_until > 0.0 && self.hold_lines_until <= t {
            self.hold_lines_until = 0.0;
            self.emit(t, reply("ok"));
            self.run_lines(t);
            return;
        }
        if let Some(h) = self.hard_limit_time().filter(|&h| h <= t) {
            // Hard limit: the steppers are killed on the switch.
            self.set_motor(self.trip_motor());
            self.mv = None;
            self.queue.clear();
            self.lock(h, 1);
            return;
        }
        if let Some(mv) = self.mv.filter(|mv| mv.end() <= t) {
            let end = mv.end();
            self.set_motor(mv.motor_at(end));
            self.mv = None;
            if self.homing.is_some() {
                self.homing_motion_done(end);
            } else if let Some(q) = self.queue.pop_front() {
                self.start_jog(end, q);
            } else {
                self.cancelling = false;
                self.planned = self.counter();
                if self.state == State::Jog {
                    self.state = State::Idle;
                }
            }
            return;
        }
        if let Some(h) = self.homing {
            if let Some(d) = h.debounce_until.filter(|&d| d <= t) {
                self.homing_phase_done(d, h);
            }
        }
    }

    /// A critical alarm (1 hard limit, 2 soft limit): reported, then only a reset is heard.
    pub(super) fn lock(&mut self, t: f64, code: u8) {
        self.state = State::Locked;
        self.cancelling = false;
        self.emit(t, format!("ALARM:{code}\r\n"));
        self.emit(t + ALARM_PAUSE_S, reply("[MSG:Reset to continue]"));
        self.hold_all_until = t + ALARM_PAUSE_S;
    }

    // --- homing -------------------------------------------------------------------------

    fn begin_homing(&mut self, t: f64) {
        self.shared.note_homing_started();
        self.state = State::Home;
        self.homing = Some(Homing {
            phase: HomePhase::Seek,
            debounce_until: None,
            status_requested: false,
        });
        self.start_homing_phase(t, HomePhase::Seek);
    }

    fn start_homing_phase(&mut self, t: f64, phase: HomePhase) {
        let spm = self.spm();
        let accel = self.settings.get(121) * spm;
        let pulloff = self.settings.get(27) * spm;
        // Each phase starts with the counter at 0.
        self.offset = self.motor;
        let toward = self.homing_sign();
        let (rate, dist, sign) = match phase {
            HomePhase::Seek => (
                self.settings.get(25),
                1.5 * self.settings.get(131) * spm,
                toward,
            ),
            HomePhase::PullOff1 | HomePhase::PullOff2 => (self.settings.get(25), pulloff, -toward),
            HomePhase::Locate => (self.settings.get(24), 5.0 * pulloff, toward),
        };
        let speed = rate / 60.0 * spm;
        self.start_move(t, dist.round(), sign, speed, accel);
        // An approach stops when the pin reads the switch pressed: at once if it is, else
        // where the carriage trips it. One away from the switch (`$23` not matching the
        // machine) runs its whole distance.
        if sign == toward {
            let trip = if self.switch_pressed() {
                Some(0.0)
            } else {
                self.switch_distance(self.motor, sign)
            };
            if let (Some(trip), Some(mv)) = (trip, self.mv.as_mut()) {
                mv.stop_at = mv.stop_at.min(trip);
            }
        }
        if let Some(h) = self.homing.as_mut() {
            h.phase = phase;
            h.debounce_until = None;
        }
    }

    fn homing_motion_done(&mut self, t: f64) {
        let Some(mut h) = self.homing else { return };
        let failure = match h.phase {
            HomePhase::Seek | HomePhase::Locate if !self.switch_pressed() => Some(9),
            HomePhase::PullOff1 | HomePhase::PullOff2 if self.switch_pressed() => Some(8),
            _ => None,
        };
        if let Some(code) = failure {
            self.homing_failed(t, code);
            return;
        }
        h.debounce_until = Some(t + f64::from(self.settings.get(26) as u32) / 1000.0);
        self.homing = Some(h);
    }

    fn homing_phase_done(&mut self, t: f64, h: Homing) {
        let next = match h.phase {
            HomePhase::Seek => HomePhase::PullOff1,
            HomePhase::PullOff1 => HomePhase::Locate,
            HomePhase::Locate => HomePhase::PullOff2,
            HomePhase::PullOff2 => {
                // The counter is set as `limits_go_home` sets it.
                let c = self.homed_counter();
                self.offset = self.motor - c;
                self.planned = c;
                if h.status_requested {
                    let s = self.status_text(t);
                    self.emit(t, s);
                }
                self.homing = None;
                self.state = State::Idle;
                self.emit(t, reply("ok"));
                self.run_lines(t);
                return;
            }
        };
        self.start_homing_phase(t, next);
    }

    fn homing_failed(&mut self, t: f64, code: u8) {
        self.mv = None;
        self.homing = None;
        self.state = State::Alarm;
        self.emit(t, format!("ALARM:{code}\r\n"));
        // The `$H` line still gets its `ok`, then GRBL resets itself.
        let mut s = reply("ok");
        s.push_str(&self.abort_text());
        self.emit(t + ALARM_PAUSE_S, s);
        self.hold_all_until = t + ALARM_PAUSE_S;
        self.clear_input();
    }

    // --- reset and power ----------------------------------------------------------------

    fn clear_input(&mut self) {
        self.rx.clear();
        self.line.clear();
        self.in_paren = false;
        self.in_semicolon = false;
        self.overflow = false;
        self.hold_lines_until = 0.0;
    }

    /// What GRBL prints when it re-initialises after an abort: the banner, then the lock
    /// message when in Alarm. Resets the report counters as the firmware's re-init does.
    fn abort_text(&mut self) -> String {
        self.wco_counter = 0;
        self.ovr_counter = 0;
        self.planned = self.counter();
        if self.state == State::Locked {
            self.state = State::Alarm;
        }
        if self.state == State::Hold {
            self.state = State::Idle;
        }
        self.boot_text()
    }

    /// 0x18: steppers stop where they are; a reset in motion is `ALARM:3` (in homing
    /// `ALARM:6`); the counter keeps its value.
    fn soft_reset(&mut self, t: f64) {
        let homing = self.homing.take().is_some();
        let moving = self.mv.take().is_some() || homing;
        self.queue.clear();
        self.cancelling = false;
        self.clear_input();
        if moving {
            let code = if homing { 6 } else { 3 };
            self.state = State::Alarm;
            self.emit(t, format!("ALARM:{code}\r\n"));
            let mut s = if homing { reply("ok") } else { String::new() };
            s.push_str(&self.abort_text());
            self.emit(t + ALARM_PAUSE_S, s);
            self.hold_all_until = t + ALARM_PAUSE_S;
        } else {
            let s = self.abort_text();
            self.emit(t, s);
        }
    }

    /// A power cycle: the counter restarts at 0 where the motor stands.
    pub(super) fn power_cycle(&mut self, t: f64) {
        self.mv = None;
        self.homing = None;
        self.queue.clear();
        self.cancelling = false;
        self.clear_input();
        self.deferred.clear();
        self.hold_all_until = 0.0;
        self.offset = self.motor;
        self.state = if self.settings.flag(22) {
            State::Alarm
        } else {
            State::Idle
        };
        let s = self.abort_text();
        self.emit(t, s);
    }

    // --- real-time commands ------------------------------------------------------------

    fn jog_cancel(&mut self, t: f64) {
        if self.state != State::Jog || self.cancelling {
            return;
        }
        self.queue.clear();
        let Some(mv) = self.mv else { return };
        let v = mv.speed_at(t);
        let accel = self.settings.get(121) * self.spm();
        let done = mv.prof.position(t - mv.start);
        let remaining = (mv.stop_at - done).max(0.0);
        let stop = remaining.min(v * v / (2.0 * accel));
        let from = mv.from + mv.sign * done.round() as i64;
        self.set_motor(from);
        let prof = Profile::new(stop.round(), v, v, accel);
        self.mv = Some(Move {
            start: t,
            from,
            sign: mv.sign,
            prof,
            stop_at: prof.distance(),
            hard_limit_at: mv.hard_limit_at.filter(|&h| h <= t + prof.duration()),
        });
        self.cancelling = true;
    }

    fn realtime(&mut self, b: u8, t: f64) {
        match b {
            b'?' => {
                if let Some(h) = self.homing.as_mut() {
                    h.status_requested = true;
                } else if self.state != State::Locked {
                    let s = self.status_text(t);
                    self.emit(t, s);
                }
            }
            b'!' => match self.state {
                State::Jog => self.jog_cancel(t),
                State::Idle => self.state = State::Hold,
                _ => {}
            },
            b'~' if self.state == State::Hold => self.state = State::Idle,
            0x18 => self.soft_reset(t),
            0x85 => self.jog_cancel(t),
            _ => {} // overrides and unknown extended bytes: swallowed
        }
    }

    fn is_realtime(b: u8) -> bool {
        matches!(b, b'?' | b'!' | b'~' | 0x18) || b >= 0x80
    }

    /// Bytes from the host at simulated time `t`.
    pub(super) fn receive(&mut self, bytes: &[u8], t: f64) {
        for (i, &b) in bytes.iter().enumerate() {
            if self.hold_all_until > 0.0 {
                self.deferred
                    .extend_from_slice(bytes.get(i..).unwrap_or(&[]));
                return;
            }
            if Self::is_realtime(b) {
                self.realtime(b, t);
            } else if self.rx.len() < RX_BUFFER - 1 {
                self.rx.push_back(b);
            }
            self.run_lines(t);
        }
    }

    /// The main loop: takes line bytes while nothing blocks it.
    pub(super) fn run_lines(&mut self, t: f64) {
        while self.homing.is_none() && self.hold_lines_until == 0.0 && self.hold_all_until == 0.0 {
            let Some(b) = self.rx.pop_front() else { return };
            if b == b'\n' || b == b'\r' {
                let line = std::mem::take(&mut self.line);
                let overflow = std::mem::replace(&mut self.overflow, false);
                self.in_paren = false;
                self.in_semicolon = false;
                let r = if overflow {
                    error(11)
                } else if self.state == State::Locked {
                    String::new()
                } else {
                    self.execute(&line, t)
                };
                self.emit(t, r);
                continue;
            }
            if self.overflow || self.in_semicolon {
                continue;
            }
            if self.in_paren {
                if b == b')' {
                    self.in_paren = false;
                }
                continue;
            }
            match b {
                0..=b' ' | b'/' => {}
                b'(' => self.in_paren = true,
                b';' => self.in_semicolon = true,
                _ if self.line.len() >= LINE_BUFFER - 1 => self.overflow = true,
                _ => self.line.push(b.to_ascii_uppercase()),
            }
        }
    }

    // --- lines ---------------------------------------------------------------------------

    /// Executes one cleaned line; returns its reply (empty when it comes later).
    fn execute(&mut self, line: &[u8], t: f64) -> String {
        if line.is_empty() {
            return reply("ok");
        }
        if line.first() == Some(&b'$') {
            return self.system(line, t);
        }
        if matches!(self.state, State::Alarm | State::Jog) {
            return error(9); // G-code locked out during alarm or jog
        }
        self.gcode(line, t)
    }

    fn gcode(&mut self, line: &[u8], t: f64) -> String {
        let w = match words(line) {
            Ok(w) => w,
            Err(c) => return error(c),
        };
        let mut dwell = false;
        let mut p = None;
        for &(l, v) in &w {
            match (l, v) {
                (b'G', 4.0) => dwell = true,
                (b'G', v) if [17.0, 20.0, 21.0, 54.0, 90.0, 91.0, 94.0].contains(&v) => {}
                (b'M', v) if v == 5.0 || v == 9.0 => {}
                (b'P', v) => p = Some(v),
                (b'N', _) => {}
                _ => return error(20), // not emulated
            }
        }
        if !dwell {
            return if p.is_some() { error(36) } else { reply("ok") };
        }
        let Some(secs) = p else { return error(28) };
        if secs < 0.0 {
            return error(4);
        }
        // The dwell's ok comes when it is over; later lines wait.
        self.hold_lines_until = t + secs;
        String::new()
    }

    fn system(&mut self, line: &[u8], t: f64) -> String {
        let rest = line.get(1..).unwrap_or(&[]);
        let idle_or_alarm = matches!(self.state, State::Idle | State::Alarm);
        match rest {
            [] => reply(
                "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]\r\nok",
            ),
            [b'J', tail @ ..] => {
                if !matches!(self.state, State::Idle | State::Jog) {
                    return error(8);
                }
                match tail.split_first() {
                    Some((b'=', words)) => self.jog(words, t),
                    _ => error(3),
                }
            }
            [b'$'] if self.state == State::Hold => error(8),
            [b'$'] => {
                let mut s = self.settings.listing();
                s.push_str("ok\r\n");
                s
            }
            [b'G'] => reply("[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]\r\nok"),
            [b'X'] => {
                if self.state == State::Alarm {
                    self.state = State::Idle;
                    reply("[MSG:Caution: Unlocked]\r\nok")
                } else {
                    reply("ok")
                }
            }
            [b'$' | b'G' | b'X' | b'C', ..] => error(3),
            _ if !idle_or_alarm => error(8),
            [b'H'] => {
                if !self.settings.flag(22) {
                    return error(5); // homing not enabled
                }
                self.begin_homing(t);
                String::new()
            }
            [b'I'] => reply(&format!(
                "[VER:1.1h.20190825:{}]\r\n[OPT:V{},{PLANNER_BLOCKS},{RX_BUFFER}]\r\nok",
                self.build_info,
                if self.cfg.force_set_origin { "Z" } else { "" }
            )),
            [b'I', b'=', info @ ..] => {
                self.build_info = String::from_utf8_lossy(info).into_owned();
                reply("ok")
            }
            [b'#'] => {
                let y = self.report_mm(self.cfg.work_offset_y_mm);
                let zero = self.report_mm(0.0);
                let mut s = String::new();
                for g in ["G54", "G55", "G56", "G57", "G58", "G59"] {
                    let yy = if g == "G54" { &y } else { &zero };
                    s.push_str(&format!("[{g}:{zero},{yy},{zero}]\r\n"));
                }
                for g in ["G28", "G30", "G92"] {
                    s.push_str(&format!("[{g}:{zero},{zero},{zero}]\r\n"));
                }
                s.push_str(&format!(
                    "[TLO:{zero}]\r\n[PRB:{zero},{zero},{zero}:0]\r\nok\r\n"
                ));
                s
            }
            [b'N'] => reply("$N0=\r\n$N1=\r\nok"),
            // Single-axis homing, sleep, restore and startup-line storage: not emulated.
            [b'H' | b'#' | b'N' | b'S' | b'R', ..] => error(3),
            _ => self.store_setting(rest),
        }
    }

    fn store_setting(&mut self, rest: &[u8]) -> String {
        let Some((n, used)) = read_number(rest) else {
            return error(2);
        };
        let Some((b'=', value)) = rest.get(used..).and_then(|r| r.split_first()) else {
            return error(3);
        };
        let Some((v, used)) = read_number(value) else {
            return error(2);
        };
        if used != value.len() {
            return error(3);
        }
        match self.settings.store(n, v) {
            Ok(()) => reply("ok"),
            Err(c) => error(c),
        }
    }

    fn jog(&mut self, block: &[u8], t: f64) -> String {
        let w = match words(block) {
            Ok(w) => w,
            Err(c) => return error(c),
        };
        let (mut machine, mut relative, mut inches) = (false, false, false);
        let (mut y, mut f) = (None, None);
        let (mut distance_mode_set, mut units_set) = (false, false);
        for (l, v) in w {
            match l {
                b'G' => {
                    let modal = |set: &mut bool| {
                        if std::mem::replace(set, true) {
                            Err(21) // modal group violation
                        } else {
                            Ok(())
                        }
                    };
                    let r = match v {
                        53.0 => {
                            machine = true;
                            Ok(())
                        }
                        v if v == 90.0 || v == 91.0 => {
                            relative = v == 91.0;
                            modal(&mut distance_mode_set)
                        }
                        v if v == 20.0 || v == 21.0 => {
                            inches = v == 20.0;
                            modal(&mut units_set)
                        }
                        v if [0.0, 1.0, 2.0, 3.0, 4.0, 10.0, 28.0, 30.0, 92.0].contains(&v) => {
                            Err(16) // invalid jog command
                        }
                        _ => Err(20),
                    };
                    if let Err(c) = r {
                        return error(c);
                    }
                }
                b'M' => return error(16),
                b'Y' => y = Some(v),
                b'X' | b'Z' | b'N' => {}
                b'F' if v < 0.0 => return error(4),
                b'F' => f = Some(v),
                b'S' | b'T' | b'P' | b'L' | b'R' | b'I' | b'J' | b'K' => return error(36),
                _ => return error(20),
            }
        }
        let Some(feed) = f.filter(|&f| f > 0.0) else {
            return error(22); // feed rate undefined
        };
        let unit = if inches { MM_PER_INCH } else { 1.0 };
        let feed = feed * unit;
        let spm = self.spm();
        let wco = if machine {
            0.0
        } else {
            self.cfg.work_offset_y_mm
        };
        let Some(yv) = y else {
            return reply("ok"); // no Y word: nothing to move on this axis
        };
        let target_mm = if relative {
            self.planned as f64 / spm + yv * unit
        } else {
            yv * unit + wco
        };
        if self.error15_next
            || (self.settings.flag(20) && {
                let (lo, hi) = self.soft_travel_mm();
                target_mm > hi || target_mm < lo
            })
        {
            self.error15_next = false;
            return error(15); // jog target exceeds machine travel
        }
        if self.alarm2_next {
            // As a G-code move past travel would: the steppers stop, position kept.
            self.alarm2_next = false;
            self.mv = None;
            self.queue.clear();
            self.lock(t, 2);
            return String::new();
        }
        let target = (target_mm * spm).round() as i64;
        let q = Queued {
            target,
            feed_mm_min: feed,
        };
        if self.cancelling {
            // Accepted, then flushed with the planner when the cancel comes to rest.
            return reply("ok");
        }
        self.planned = target;
        self.shared
            .note_move_started((target as f64 * 1e6 / spm).round() as i64);
        if self.state == State::Jog {
            self.queue.push_back(q);
        } else {
            self.start_jog(t, q);
        }
        reply("ok")
    }

    // --- status -------------------------------------------------------------------------

    fn inches(&self) -> bool {
        self.settings.flag(13)
    }

    /// A length in mm as GRBL prints coordinates (3 decimals, or 4 in inches).
    fn report_mm(&self, mm: f64) -> String {
        if self.inches() {
            format!("{:.4}", mm / MM_PER_INCH)
        } else {
            format!("{mm:.3}")
        }
    }

    /// A status report at simulated time `t` (events up to `t` already handled).
    fn status_text(&mut self, t: f64) -> String {
        if let Some(mv) = self.mv {
            self.set_motor(mv.motor_at(t));
        }
        let busy = matches!(self.state, State::Jog | State::Home | State::Hold);
        let state = match self.state {
            State::Idle => "Idle",
            State::Jog => "Jog",
            State::Hold => "Hold:0",
            State::Home => "Home",
            State::Alarm | State::Locked => "Alarm",
        };
        let mask = self.settings.get(10) as u8;
        let mpos = self.counter() as f64 / self.spm();
        let wco = self.cfg.work_offset_y_mm;
        let mut s = format!("<{state}");
        let zero = self.report_mm(0.0);
        if mask & 1 != 0 {
            s.push_str(&format!("|MPos:{zero},{},{zero}", self.report_mm(mpos)));
        } else {
            s.push_str(&format!(
                "|WPos:{zero},{},{zero}",
                self.report_mm(mpos - wco)
            ));
        }
        if mask & 2 != 0 {
            let blocks = self.queue.len() + usize::from(self.mv.is_some() && self.homing.is_none());
            s.push_str(&format!(
                "|Bf:{},{}",
                PLANNER_BLOCKS.saturating_sub(blocks),
                RX_BUFFER - self.rx.len()
            ));
        }
        let speed_mm_min = self.mv.map_or(0.0, |mv| mv.speed_at(t)) / self.spm() * 60.0;
        if self.inches() {
            s.push_str(&format!("|FS:{:.1},0", speed_mm_min / MM_PER_INCH));
        } else {
            s.push_str(&format!("|FS:{speed_mm_min:.0},0"));
        }
        if self.switch_pressed() {
            s.push_str("|Pn:Y");
        }
        if self.wco_counter > 0 {
            self.wco_counter -= 1;
        } else {
            self.wco_counter = if busy { 29 } else { 9 };
            if self.ovr_counter == 0 {
                self.ovr_counter = 1;
            }
            s.push_str(&format!("|WCO:{zero},{},{zero}", self.report_mm(wco)));
        }
        if self.ovr_counter > 0 {
            self.ovr_counter -= 1;
        } else {
            self.ovr_counter = if busy { 19 } else { 9 };
            s.push_str("|Ov:100,100,100");
        }
        s.push_str(">\r\n");
        s
    }

    /// The output due by simulated time `t`, in order.
    pub(super) fn take_output(&mut self, t: f64) -> String {
        let mut s = String::new();
        while let Some((at, _)) = self.out.front() {
            if *at > t {
                break;
            }
            if let Some((_, text)) = self.out.pop_front() {
                s.push_str(&text);
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::Clock;
    use tokio::time::Instant;

    /// Every event's wake-up instant is at or after the event in simulated time, or the
    /// controller would spin on an event it never finds due (a jog ending at
    /// 56.659000000000006 s did, at real speed).
    #[test]
    fn a_wake_up_is_never_before_its_event() {
        for scale in [1.0, 0.5, 3.0, 50.0, 1e9] {
            let clock = Clock {
                t0: Instant::now(),
                scale,
            };
            let mut ts = vec![56.659000000000006, 0.1 + 0.2, 1e-9, 1234.5678901234];
            ts.extend((1..2000).map(|k| f64::from(k) * 0.0283 + 1e-13 * f64::from(k % 7)));
            for t in ts {
                let at = clock.real(t).expect("representable");
                assert!(
                    clock.sim(at) >= t,
                    "scale {scale}: {t} woken at {}",
                    clock.sim(at)
                );
            }
        }
    }
}
