//! A simulated GRBL 1.1 controller driving one Y axis, written from the GRBL documentation
//! (interface.md, commands.md, jogging.md) with its own parser.
//!
//! Emulates: line commands answered `ok`/`error:N`; real-time bytes `?` `!` `~` 0x18 0x85;
//! status reports `<State|MPos:…|FS:…>`; `$I`, `$H`, `$X`; `$J=` jogs (absolute `G90`,
//! relative `G91`, machine `G53`) moving at the feed rate × a time-scale factor; soft limits
//! (jog past travel → `error:15`); every G-code line refused with `error:9` during a jog or
//! an alarm; a backlash dead band between motor and carriage; and injected faults.
//! The carriage's true position is published in nm through [`StageShared`].
//!
//! Depends on tokio and [`crate::data::YPosition`] (the y the instrument reads).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;

use crate::data::YPosition;

/// A fault to inject into a simulated stage (GRBL or Zaber); applied when the next byte
/// arrives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StageFault {
    /// GRBL: the controller resets (banner), position counter restarts at 0, homing needed.
    ResetBanner,
    /// GRBL: the next jog raises `ALARM:2`; everything is ignored until a soft reset.
    Alarm2,
    /// GRBL: the next jog is refused with `error:15`.
    Error15,
    /// Zaber: the next command is rejected (`RJ IDLE -- AGAIN`).
    Reject,
    /// Zaber: the next move stalls half way (`FS`).
    Stall,
    /// Zaber: the device loses its reference (power cycle: position 0, `WR`).
    PositionLostWr,
    /// Stop answering (bytes are still read).
    Silence,
    /// Close the stream (the device vanished).
    Vanish,
}

impl std::str::FromStr for StageFault {
    type Err = String;

    /// Parses `reset-banner`, `alarm2`, `error15`, `reject`, `stall`, `position-lost`,
    /// `silence`, `vanish`.
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "reset-banner" => StageFault::ResetBanner,
            "alarm2" => StageFault::Alarm2,
            "error15" => StageFault::Error15,
            "reject" => StageFault::Reject,
            "stall" => StageFault::Stall,
            "position-lost" => StageFault::PositionLostWr,
            "silence" => StageFault::Silence,
            "vanish" => StageFault::Vanish,
            _ => {
                return Err(format!(
                    "unknown stage fault {s:?}; use reset-banner, alarm2, error15, reject, \
                     stall, position-lost, silence or vanish"
                ))
            }
        })
    }
}

/// A stage fault with its injection time: `KIND[@MS]` queues KIND MS milliseconds after the
/// simulator is ready (default 0); it takes effect when the next bytes from the host arrive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StageFaultSpec {
    /// The fault.
    pub fault: StageFault,
    /// Delay after ready, ms.
    pub after_ms: u64,
}

impl std::str::FromStr for StageFaultSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (kind, after_ms) = match s.split_once('@') {
            Some((k, ms)) => (
                k,
                ms.parse::<u64>().map_err(|_| {
                    format!("stage fault {s:?}: {ms:?} after '@' must be whole milliseconds")
                })?,
            ),
            None => (s, 0),
        };
        Ok(StageFaultSpec {
            fault: kind.parse()?,
            after_ms,
        })
    }
}

/// State shared between a simulated stage and its observers.
#[derive(Debug, Default)]
pub struct StageShared {
    /// The carriage's true position, nm.
    pub true_position_nm: AtomicI64,
    /// Bytes received from the host so far.
    pub bytes_received: AtomicU64,
    /// Moves accepted and started so far (GRBL jogs, Zaber `move abs`/`move rel`; homing
    /// cycles are not counted).
    pub moves_started: AtomicU64,
    faults: Mutex<VecDeque<StageFault>>,
    /// Mirrors the true position for the simulated instrument's profile selection.
    y: OnceLock<YPosition>,
}

impl StageShared {
    /// A new shared handle.
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }

    /// Queues a fault.
    pub fn inject(&self, f: StageFault) {
        if let Ok(mut q) = self.faults.lock() {
            q.push_back(f);
        }
    }

    /// Mirrors every later true-position update into `y` (the instrument serves the line at
    /// that y). Only the first call has an effect.
    pub fn link_y(&self, y: YPosition) {
        y.set_nm(self.true_position_nm());
        let _ = self.y.set(y);
    }

    /// Records the carriage's true position, nm (and mirrors it into the linked y).
    pub fn publish_position_nm(&self, nm: i64) {
        self.true_position_nm.store(nm, Ordering::SeqCst);
        if let Some(y) = self.y.get() {
            y.set_nm(nm);
        }
    }

    /// Takes the next queued fault.
    pub fn take_fault(&self) -> Option<StageFault> {
        self.faults.lock().ok().and_then(|mut q| q.pop_front())
    }

    /// The carriage's true position, nm.
    pub fn true_position_nm(&self) -> i64 {
        self.true_position_nm.load(Ordering::SeqCst)
    }

    /// Bytes received so far.
    pub fn bytes_received(&self) -> u64 {
        self.bytes_received.load(Ordering::SeqCst)
    }

    /// Records that a move was accepted and started.
    pub fn note_move_started(&self) {
        self.moves_started.fetch_add(1, Ordering::SeqCst);
    }

    /// Moves accepted and started so far (homing cycles are not counted).
    pub fn moves_started(&self) -> u64 {
        self.moves_started.load(Ordering::SeqCst)
    }
}

/// Configuration of the simulated GRBL controller.
#[derive(Debug, Clone)]
pub struct GrblSimConfig {
    /// Steps per mm (`$101`).
    pub steps_per_mm: f64,
    /// Travel (`$131`): machine coordinates span [−travel, 0] after homing.
    pub max_travel_mm: f64,
    /// Backlash between motor and carriage, mm.
    pub backlash_mm: f64,
    /// Speed-up of simulated time (1 = real speed).
    pub time_scale: f64,
    /// Homing seek rate, mm/min.
    pub homing_rate_mm_min: f64,
    /// Print the banner when the link opens (Arduino DTR reset).
    pub banner_at_open: bool,
    /// Machine position counter at start (steps); with `homed_at_start` false the board
    /// starts in Alarm.
    pub start_steps: i64,
    /// Whether the board starts homed (Idle) or in Alarm (`$22=1` power-up).
    pub homed_at_start: bool,
}

impl Default for GrblSimConfig {
    fn default() -> Self {
        GrblSimConfig {
            steps_per_mm: 400.0,
            max_travel_mm: 200.0,
            backlash_mm: 0.0,
            time_scale: 1.0,
            homing_rate_mm_min: 500.0,
            banner_at_open: false,
            start_steps: 0,
            homed_at_start: false,
        }
    }
}

const BANNER: &str = "\r\nGrbl 1.1h ['$' for help]\r\n";

#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    Idle,
    Jog,
    Hold,
    Alarm,
    /// ALARM:2 critical: only a soft reset is heard.
    Locked,
}

struct Jog {
    from: i64,
    to: i64,
    start: Instant,
    dur: Duration,
}

struct Machine {
    cfg: GrblSimConfig,
    shared: Arc<StageShared>,
    state: State,
    /// Position counter (what MPos reports), steps.
    counter: i64,
    /// Physical motor position minus counter (changes when a reset zeroes the counter).
    counter_offset: i64,
    /// Carriage position, steps, in the physical frame.
    carriage: i64,
    backlash: i64,
    jog: Option<Jog>,
    feed: f64,
    silent: bool,
    alarm2_next: bool,
    error15_next: bool,
}

impl Machine {
    fn nm_per_step(&self) -> f64 {
        1e6 / self.cfg.steps_per_mm
    }

    fn set_counter(&mut self, c: i64) {
        self.counter = c;
        let phys = c + self.counter_offset;
        self.carriage = self.carriage.clamp(phys, phys + self.backlash);
        let nm = (self.carriage as f64 * self.nm_per_step()).round() as i64;
        self.shared.publish_position_nm(nm);
    }

    fn update(&mut self) {
        let now = Instant::now();
        if let Some(j) = &self.jog {
            let (from, to, start, dur) = (j.from, j.to, j.start, j.dur);
            let el = now.saturating_duration_since(start);
            if el >= dur {
                self.jog = None;
                self.set_counter(to);
                if self.state == State::Jog {
                    self.state = State::Idle;
                }
            } else if self.state == State::Jog {
                let f = el.as_secs_f64() / dur.as_secs_f64().max(1e-9);
                self.set_counter(from + ((to - from) as f64 * f).round() as i64);
            }
        }
    }

    fn status(&mut self) -> String {
        self.update();
        let st = match self.state {
            State::Idle => "Idle",
            State::Jog => "Jog",
            State::Hold => "Hold:0",
            State::Alarm | State::Locked => "Alarm",
        };
        let y = self.counter as f64 / self.cfg.steps_per_mm;
        format!(
            "<{st}|MPos:0.000,{y:.3},0.000|FS:{:.0},0>\r\n",
            if self.state == State::Jog {
                self.feed
            } else {
                0.0
            }
        )
    }

    fn reset(&mut self) -> String {
        self.update();
        // A reset while moving loses steps: ALARM:3 before the banner.
        let prefix = if self.state == State::Jog {
            "ALARM:3\r\n"
        } else {
            ""
        };
        self.jog = None;
        self.state = State::Alarm;
        format!("{prefix}{BANNER}[MSG:'$H'|'$X' to unlock]\r\n")
    }

    /// Power-on style reset: the counter restarts at 0 while the motor stays put.
    fn lose_position(&mut self) -> String {
        self.update();
        self.jog = None;
        self.counter_offset += self.counter;
        self.counter = 0;
        self.state = State::Alarm;
        format!("{BANNER}[MSG:'$H'|'$X' to unlock]\r\n")
    }

    async fn home(&mut self) -> String {
        // Seek the switch at the top of travel, pull off, set machine zero there.
        let phys = self.counter + self.counter_offset;
        let dist_mm = (phys.unsigned_abs() as f64) / self.cfg.steps_per_mm;
        let secs = dist_mm / self.cfg.homing_rate_mm_min * 60.0 / self.cfg.time_scale;
        tokio::time::sleep(Duration::from_secs_f64(secs.max(0.0))).await;
        self.counter_offset = 0;
        let pull_off = (self.cfg.steps_per_mm).round() as i64;
        self.set_counter(pull_off);
        self.set_counter(0);
        self.state = State::Idle;
        "ok\r\n".into()
    }

    fn jog(&mut self, words: &str) -> String {
        let mut absolute = false;
        let mut y: Option<f64> = None;
        let mut f: Option<f64> = None;
        let b = words.as_bytes();
        let mut i = 0;
        while i < b.len() {
            let c = b.get(i).copied().unwrap_or(b' ').to_ascii_uppercase();
            if c == b' ' {
                i += 1;
                continue;
            }
            let mut j = i + 1;
            while j < b.len()
                && b.get(j)
                    .is_some_and(|d| d.is_ascii_digit() || *d == b'.' || *d == b'-' || *d == b'+')
            {
                j += 1;
            }
            let v: f64 = match words.get(i + 1..j).and_then(|s| s.parse().ok()) {
                Some(v) => v,
                None => return "error:2\r\n".into(),
            };
            match (c, v) {
                // G53 (machine coordinates) and G21 (mm) are accepted; no work offsets are
                // emulated, so machine and work coordinates coincide.
                (b'G', v) if v.fract() == 0.0 => match v as i64 {
                    90 => absolute = true,
                    91 => absolute = false,
                    53 | 21 => {}
                    _ => return "error:16\r\n".into(),
                },
                (b'Y', v) => y = Some(v),
                (b'X', _) | (b'Z', _) => {}
                (b'F', v) => f = Some(v),
                _ => return "error:16\r\n".into(),
            }
            i = j;
        }
        let (Some(yv), Some(feed)) = (y, f) else {
            return if f.is_none() {
                "error:22\r\n"
            } else {
                "error:16\r\n"
            }
            .into();
        };
        if feed <= 0.0 {
            return "error:16\r\n".into();
        }
        self.update();
        let cur_mm = self.counter as f64 / self.cfg.steps_per_mm;
        let target_mm = if absolute { yv } else { cur_mm + yv };
        if self.error15_next || target_mm > 0.0 || target_mm < -self.cfg.max_travel_mm {
            self.error15_next = false;
            return "error:15\r\n".into();
        }
        if self.alarm2_next {
            self.alarm2_next = false;
            self.jog = None;
            self.state = State::Locked;
            return "ALARM:2\r\n[MSG:Reset to continue]\r\n".into();
        }
        let to = (target_mm * self.cfg.steps_per_mm).round() as i64;
        let dist_mm = ((to - self.counter) as f64).abs() / self.cfg.steps_per_mm;
        let secs = dist_mm / feed * 60.0 / self.cfg.time_scale;
        self.feed = feed;
        self.jog = Some(Jog {
            from: self.counter,
            to,
            start: Instant::now(),
            dur: Duration::from_secs_f64(secs),
        });
        self.state = State::Jog;
        self.shared.note_move_started();
        "ok\r\n".into()
    }

    async fn line(&mut self, line: &str) -> String {
        self.update();
        let l = line.trim();
        if l.is_empty() {
            return "ok\r\n".into();
        }
        match self.state {
            State::Locked => return String::new(),
            State::Alarm => {
                return match l {
                    "$X" => {
                        self.state = State::Idle;
                        "[MSG:Caution: Unlocked]\r\nok\r\n".into()
                    }
                    "$H" => self.home().await,
                    "$I" => "[VER:1.1h.20190825:]\r\n[OPT:V,15,128]\r\nok\r\n".into(),
                    _ if l.starts_with("$J=") => "error:8\r\n".into(),
                    _ if l.starts_with('$') => "ok\r\n".into(),
                    _ => "error:9\r\n".into(),
                };
            }
            _ => {}
        }
        if let Some(words) = l.strip_prefix("$J=") {
            if !matches!(self.state, State::Idle | State::Jog) {
                return "error:8\r\n".into();
            }
            return self.jog(words);
        }
        match l {
            "$I" => "[VER:1.1h.20190825:]\r\n[OPT:V,15,128]\r\nok\r\n".into(),
            "$H" if self.state == State::Idle => self.home().await,
            "$X" => "ok\r\n".into(),
            _ if l.starts_with('$') => {
                if self.state == State::Idle {
                    "ok\r\n".into()
                } else {
                    "error:8\r\n".into()
                }
            }
            // G-code: locked out during a jog (G4 included); only G4 is emulated at rest.
            _ if self.state == State::Jog || self.state == State::Hold => "error:9\r\n".into(),
            _ if l.starts_with("G4") => "ok\r\n".into(),
            _ => "error:20\r\n".into(),
        }
    }
}

/// Serves the GRBL protocol on `io` until the host closes it or a `Vanish` fault.
pub async fn serve<T: AsyncRead + AsyncWrite + Unpin>(
    mut io: T,
    config: GrblSimConfig,
    shared: Arc<StageShared>,
) -> std::io::Result<()> {
    let backlash = (config.backlash_mm * config.steps_per_mm).round() as i64;
    let mut m = Machine {
        state: if config.homed_at_start {
            State::Idle
        } else {
            State::Alarm
        },
        counter: config.start_steps,
        counter_offset: 0,
        carriage: config.start_steps,
        backlash,
        jog: None,
        feed: 0.0,
        silent: false,
        alarm2_next: false,
        error15_next: false,
        shared,
        cfg: config,
    };
    m.set_counter(m.counter);
    if m.cfg.banner_at_open {
        let mut s = BANNER.to_string();
        if m.state == State::Alarm {
            s.push_str("[MSG:'$H'|'$X' to unlock]\r\n");
        }
        io.write_all(s.as_bytes()).await?;
    }
    let mut line = Vec::new();
    let mut overflow = false;
    let mut buf = [0u8; 256];
    loop {
        let n = io.read(&mut buf).await?;
        if n == 0 {
            return Ok(());
        }
        m.shared
            .bytes_received
            .fetch_add(n as u64, Ordering::SeqCst);
        let mut out = String::new();
        while let Some(f) = m.shared.take_fault() {
            match f {
                StageFault::ResetBanner => out.push_str(&m.lose_position()),
                StageFault::Alarm2 => m.alarm2_next = true,
                StageFault::Error15 => m.error15_next = true,
                StageFault::Silence => m.silent = true,
                StageFault::Vanish => return Ok(()),
                StageFault::Reject | StageFault::Stall | StageFault::PositionLostWr => {}
            }
        }
        for &b in buf.get(..n).unwrap_or(&[]) {
            match b {
                b'?' => {
                    if m.state != State::Locked {
                        out.push_str(&m.status());
                    }
                }
                b'!' => {
                    m.update();
                    if m.state == State::Jog {
                        // A jog in hold is cancelled on resume; model it as stopping here.
                        m.jog = None;
                        m.state = State::Hold;
                    }
                }
                b'~' => {
                    if m.state == State::Hold {
                        m.state = State::Idle;
                    }
                }
                0x18 => {
                    line.clear();
                    out.push_str(&m.reset());
                }
                0x85 => {
                    m.update();
                    if m.state == State::Jog {
                        m.jog = None;
                        m.state = State::Idle;
                    }
                }
                b'\n' | b'\r' if overflow => {
                    overflow = false;
                    line.clear();
                    out.push_str("error:11\r\n");
                }
                b'\n' | b'\r' => {
                    if !line.is_empty() {
                        let l = String::from_utf8_lossy(&line).into_owned();
                        line.clear();
                        out.push_str(&m.line(&l).await);
                    }
                }
                _ if line.len() < 80 => line.push(b),
                _ => overflow = true,
            }
        }
        if !m.silent && !out.is_empty() {
            io.write_all(out.as_bytes()).await?;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_fault_specs_parse_with_and_without_delay() {
        let s: StageFaultSpec = "reset-banner@1500".parse().unwrap();
        assert_eq!(
            s,
            StageFaultSpec {
                fault: StageFault::ResetBanner,
                after_ms: 1500
            }
        );
        let s: StageFaultSpec = "vanish".parse().unwrap();
        assert_eq!((s.fault, s.after_ms), (StageFault::Vanish, 0));
        assert!("stall@soon"
            .parse::<StageFaultSpec>()
            .unwrap_err()
            .contains("soon"));
        assert!("jam".parse::<StageFaultSpec>().unwrap_err().contains("jam"));
    }

    #[test]
    fn linked_y_follows_published_positions() {
        let shared = StageShared::new();
        shared.publish_position_nm(-42);
        let y = YPosition::new();
        shared.link_y(y.clone());
        assert_eq!(y.get_nm(), -42);
        shared.publish_position_nm(1_060_000);
        assert_eq!(y.get_nm(), 1_060_000);
    }
}
