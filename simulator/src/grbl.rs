//! A simulated GRBL 1.1h controller driving one Y axis, written from GRBL's documentation and
//! firmware behaviour with its own parser.
//!
//! What it does as the firmware does:
//! * Lines are cleaned as GRBL cleans them (spaces and control bytes dropped, `(…)` and `;`
//!   comments removed, letters upper-cased, 80-byte line buffer → `error:11`) and answered
//!   `ok`/`error:N`; real-time bytes (`?` `!` `~` 0x18 0x85, any other byte ≥ 0x80 swallowed)
//!   act at once, even while a line is being executed.
//! * A settings store (`$$` prints bare `$N=value` lines; `$N=value` writes, with GRBL's
//!   checks: `$20=1` without homing → `error:10`, `$22=0` also clears `$20`). A first boot with
//!   blank settings prints `error:7` and the default settings before the banner and runs on
//!   GRBL's generic defaults (250 steps/mm, homing off) whatever the mechanics are.
//! * Status reports `<State|MPos:…|FS:rate,0|Pn:Y|WCO:…|Ov:100,100,100>`: `MPos` or `WPos`
//!   by `$10`, `Bf:` with `$10` bit 1, `WCO:` every 10th report at rest (30th when busy) and
//!   `Ov:` on the report after it, then every 10th (20th), `Pn:Y` while the home switch is
//!   pressed, `FS:` the real, ramping speed (planner trapezoid at `$121`, feed capped at `$111`).
//! * `$J=` jogs (`G53`, `G90`/`G91`, `G20`/`G21`; feed required) queue in the planner; with
//!   soft limits a target outside [−`$131`, 0] is `error:15`; `$J=` outside Idle/Jog is
//!   `error:8`; other G-code during a jog or an alarm is `error:9`; `G4 P…` dwells.
//! * Jog cancel (0x85, or a feed hold `!` during a jog) decelerates at `$121` and reports `Jog`
//!   until at rest, then `Idle`.
//! * `$H` (`error:5` with homing disabled) runs GRBL's cycle: seek the switch at `$25` (up to
//!   1.5 × `$131`), pull off `$27`, locate at `$24`, pull off again, a `$26` debounce after each;
//!   machine space is then [−`$131`, 0] with the axis at MPos −`$27`. `?` is not answered
//!   during the cycle; one request is answered with `<Home|…>` just before the `ok`. Switch not
//!   found → `ALARM:9`, switch still pressed after the pull-off → `ALARM:8`, a reset during
//!   the cycle → `ALARM:6`.
//! * Soft reset (0x18): during motion `ALARM:3`, GRBL's 500 ms alarm pause, the banner and
//!   `[MSG:'$H'|'$X' to unlock]`; the position counter keeps where the stepper stopped. A
//!   power cycle (fault `reset-banner`) is what zeroes it; with homing enabled the board then
//!   powers up in Alarm.
//! * With hard limits (`$21=1`) a jog that runs onto the switch stops there: `ALARM:1`,
//!   `[MSG:Reset to continue]`, nothing but a soft reset is heard.
//!
//! The mechanics: the home switch sits at the top of travel (GRBL's default homing direction)
//! at physical 0, the carriage trails the motor by a backlash dead band on reversal, and the
//! motor moves the configured steps per mm whatever `$101` says. The carriage's true position is
//! published in nm through [`StageShared`]. Not emulated: G-code motion (`G0`/`G1`; answered
//! `error:20`), check mode, sleep, `$RST`, safety door, spindle and coolant, X and Z.
//!
//! Depends on tokio, [`crate::motion`] and [`crate::data::YPosition`] (the y the instrument
//! reads).

use std::collections::VecDeque;
use std::future::Future;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;

use crate::data::YPosition;
use machine::Machine;

mod machine;
mod settings;

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
    /// Homing cycles started so far (GRBL `$H`, Zaber `home`).
    pub homing_cycles: AtomicU64,
    /// The target of each move started, nm in the controller's reported frame (MPos, or the
    /// Zaber's `pos`), in order: what a test asserts of the motion itself.
    move_targets_nm: Mutex<Vec<i64>>,
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

    /// Records that a move to `target_nm` was accepted and started.
    pub fn note_move_started(&self, target_nm: i64) {
        self.moves_started.fetch_add(1, Ordering::SeqCst);
        if let Ok(mut m) = self.move_targets_nm.lock() {
            m.push(target_nm);
        }
    }

    /// The targets of the moves started so far, nm, in order.
    pub fn move_targets_nm(&self) -> Vec<i64> {
        self.move_targets_nm
            .lock()
            .map(|m| m.clone())
            .unwrap_or_default()
    }

    /// Records that a homing cycle started.
    pub fn note_homing_started(&self) {
        self.homing_cycles.fetch_add(1, Ordering::SeqCst);
    }

    /// Homing cycles started so far.
    pub fn homing_cycles(&self) -> u64 {
        self.homing_cycles.load(Ordering::SeqCst)
    }

    /// Moves accepted and started so far (homing cycles are not counted).
    pub fn moves_started(&self) -> u64 {
        self.moves_started.load(Ordering::SeqCst)
    }
}

/// Configuration of the simulated GRBL controller: the mechanics and the settings the board
/// was programmed with.
#[derive(Debug, Clone)]
pub struct GrblSimConfig {
    /// Steps per mm of the mechanics, and the board's `$101` (unless `blank_settings`).
    pub steps_per_mm: f64,
    /// `$111`: maximum rate, mm/min (jog feeds are capped to it).
    pub max_rate_mm_min: f64,
    /// `$121`: acceleration, mm/s².
    pub acceleration_mm_s2: f64,
    /// `$131`: maximum travel, mm; machine space is [−travel, 0] after homing (or [0, travel]
    /// in a `force_set_origin` build homing toward negative).
    pub max_travel_mm: f64,
    /// `$22`: homing cycle enabled (the board then powers up in Alarm).
    pub homing_enabled: bool,
    /// `$20`: soft limits (needs homing).
    pub soft_limits: bool,
    /// `$21`: hard limits (the home switch doubles as the limit switch).
    pub hard_limits: bool,
    /// `$24`: homing locate feed, mm/min.
    pub homing_feed_mm_min: f64,
    /// `$25`: homing seek rate, mm/min.
    pub homing_seek_mm_min: f64,
    /// `$26`: homing switch debounce, ms.
    pub homing_debounce_ms: u32,
    /// `$27`: homing pull-off, mm.
    pub homing_pulloff_mm: f64,
    /// `$10`: status report mask (bit 0 MPos instead of WPos, bit 1 buffer state).
    pub status_report_mask: u8,
    /// The G54 work offset of Y, mm (what `WCO:` reports; `WPos = MPos − WCO`).
    pub work_offset_y_mm: f64,
    /// Backlash between motor and carriage, mm.
    pub backlash_mm: f64,
    /// Speed-up of simulated time (1 = real speed): motion, dwells, debounce, alarm pauses.
    pub time_scale: f64,
    /// Print the boot messages when the link opens (Arduino DTR reset).
    pub banner_at_open: bool,
    /// Where the motor stands at start, mm from the home switch (machine coordinates once
    /// homed; negative is below the switch).
    pub start_mm: f64,
    /// The board was homed before the link opened and has not been reset since (Idle, the
    /// counter in machine coordinates); otherwise it has just powered up (counter 0, Alarm
    /// when homing is enabled).
    pub homed_at_start: bool,
    /// First boot with blank EEPROM: `error:7`, the settings and then the banner (with
    /// `banner_at_open`), and GRBL's generic defaults in force.
    pub blank_settings: bool,
    /// The `$I` build-info string (settable with `$I=`).
    pub build_info: String,
    /// The Y home switch is at the negative end of travel, and `$23` is programmed with the
    /// Y bit (2) so that homing approaches it moving negative. `start_mm` is then positive
    /// (above the switch). A `$23` written later changes only the firmware's direction, not
    /// where the switch is: homing away from it ends in `ALARM:9`, as on a real board.
    pub home_switch_at_negative_end: bool,
    /// The firmware was built with `HOMING_FORCE_SET_ORIGIN` (`Z` among the `[OPT:…]`
    /// letters): homing ends with the counter at 0, and soft limits hold an axis that homes
    /// toward negative to [0, `$131`] instead of [−`$131`, 0].
    pub force_set_origin: bool,
}

impl Default for GrblSimConfig {
    /// A lab y stage: 400 steps/mm, 500 mm/min, 10 mm/s², 200 mm travel, home switch with
    /// homing and soft limits enabled, just powered up 50 mm below the switch.
    fn default() -> Self {
        GrblSimConfig {
            steps_per_mm: 400.0,
            max_rate_mm_min: 500.0,
            acceleration_mm_s2: 10.0,
            max_travel_mm: 200.0,
            homing_enabled: true,
            soft_limits: true,
            hard_limits: false,
            homing_feed_mm_min: 25.0,
            homing_seek_mm_min: 500.0,
            homing_debounce_ms: 250,
            homing_pulloff_mm: 1.0,
            status_report_mask: 1,
            work_offset_y_mm: 0.0,
            backlash_mm: 0.0,
            time_scale: 1.0,
            banner_at_open: false,
            start_mm: -50.0,
            homed_at_start: false,
            blank_settings: false,
            build_info: String::new(),
            home_switch_at_negative_end: false,
            force_set_origin: false,
        }
    }
}

/// Serves the GRBL protocol on `io` until the host closes it or a `Vanish` fault.
///
/// The controller is built, and its start position published through `shared`, when this is
/// called, not when the returned future is first polled.
pub fn serve<T: AsyncRead + AsyncWrite + Unpin>(
    io: T,
    config: GrblSimConfig,
    shared: Arc<StageShared>,
) -> impl Future<Output = std::io::Result<()>> {
    let m = Machine::new(config, shared);
    serve_machine(io, m)
}

async fn serve_machine<T: AsyncRead + AsyncWrite + Unpin>(
    mut io: T,
    mut m: Machine,
) -> std::io::Result<()> {
    let mut buf = [0u8; 256];
    loop {
        let now = m.clock.sim(Instant::now());
        m.advance(now);
        m.run_lines(now);
        let out = m.take_output(now);
        if !m.silent && !out.is_empty() {
            io.write_all(out.as_bytes()).await?;
            io.flush().await?;
        }
        let deadline = m.next_deadline();
        let n = tokio::select! {
            r = io.read(&mut buf) => r?,
            _ = async {
                match deadline {
                    Some(d) => tokio::time::sleep_until(d).await,
                    None => std::future::pending().await,
                }
            } => continue,
        };
        if n == 0 {
            return Ok(());
        }
        m.shared
            .bytes_received
            .fetch_add(n as u64, Ordering::SeqCst);
        let now = m.clock.sim(Instant::now());
        m.advance(now);
        while let Some(f) = m.shared.take_fault() {
            match f {
                StageFault::ResetBanner => m.power_cycle(now),
                StageFault::Alarm2 => m.alarm2_next = true,
                StageFault::Error15 => m.error15_next = true,
                StageFault::Silence => m.silent = true,
                StageFault::Vanish => return Ok(()),
                StageFault::Reject | StageFault::Stall | StageFault::PositionLostWr => {}
            }
        }
        m.receive(buf.get(..n).unwrap_or(&[]), now);
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
