//! GRBL 1.1 / grblHAL: a [`Stage`] driver generic over `AsyncRead + AsyncWrite + Unpin`,
//! over the pure line codec in [`codec`] and the settings check in [`controller`].
//!
//! At connect the driver reads `$I` and `$$`: the board's steps per mm must be the
//! configured ones, reports must be in mm, and the board's own travel (soft limits,
//! [−`$131`, 0]) goes to the policy so a plan that would hit it is refused up front. `$H` on a
//! board without homing is a named error; after `$H` the axis stands at MPos −`$27`.
//!
//! Moves are jogs to absolute machine coordinates (`$J=G53 G90 Y… F…`); completion is seen
//! by polling `?` until `Idle` (G-code, even `G4`, is refused with `error:9` during a jog).
//! The first poll comes when the planner's trapezoid (feed capped at `$111`, ramps at `$121`)
//! says the jog is over, and each later one when the rest should be done, from the reported
//! position and real speed (`FS:`), never more than the poll interval apart.
//! A banner or `ALARM:1`/`ALARM:3` not caused by our own reset means the position is lost, and
//! so does a report in `Alarm` or a jog refused with `error:8` because the board is in Alarm.
//! `ALARM:2` (soft limit) for a target inside the limits is a stale position the first time
//! (re-homed, the move tried again) and the board's travel and the configuration disagreeing
//! the second time in a row (fatal, named).
//! Stopping cancels the jog (0x85) and waits while GRBL decelerates at `$121` to `Idle`.
//! Reports in work coordinates (`$10=0`) are turned into machine coordinates with the `WCO:`
//! GRBL sends every few reports; the driver waits for one at connect.
//!
//! Layer 2: depends on [`codec`], [`controller`], [`super::link`], [`super::ramp`] and the
//! stage vocabulary in [`super`].

pub mod codec;
pub mod controller;

use super::link::LineLink;
use super::ramp::{braking_time, move_time, MIN_POLL_GAP, POLL_MARGIN};
use super::{Identity, Motion, Stage, StageError, StageStatus};
use crate::devices::FaultClass;
use codec::{
    alarm_text, encode_jog_y, error_text, parse_line, GrblMessage, GrblState, StatusReport,
    RT_JOG_CANCEL, RT_SOFT_RESET, RT_STATUS,
};
use controller::{BuildOptions, ControllerSettings};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::time::Instant;

/// Settings of the GRBL driver.
#[derive(Debug, Clone)]
pub struct GrblConfig {
    /// Steps per mm of the Y axis (`$101`).
    pub steps_per_mm: f64,
    /// Jog feed rate, mm/min.
    pub feed_mm_min: f64,
    /// Longest wait between two status polls while a jog runs (GRBL asks for ≤ 5 Hz).
    pub poll_interval: Duration,
    /// Timeout for one line's `ok`/`error` or a status report.
    pub reply_timeout: Duration,
    /// How long to listen for a start-up banner after opening (Arduino DTR reset).
    pub open_grace: Duration,
}

/// GRBL sends `WCO:` at least every 30th report (every 10th at rest).
const REPORTS_PER_WCO: usize = 31;

/// A jog sent and not yet seen to end.
#[derive(Debug, Clone, Copy)]
struct Jog {
    target_units: i64,
    from_units: Option<i64>,
    sent: Instant,
}

/// The GRBL driver.
pub struct GrblStage<T> {
    link: LineLink<T>,
    cfg: GrblConfig,
    wco_mm: Option<[f64; 3]>,
    trusted: bool,
    expect_banner: bool,
    needs_reset: bool,
    /// A reply may still be in flight from an interrupted exchange: drain before talking.
    dirty: bool,
    warnings: Vec<String>,
    /// What `$$` said at connect.
    board: ControllerSettings,
    /// The position of the last status report, steps.
    last_units: Option<i64>,
    jog: Option<Jog>,
    /// An `ALARM:2` came since the last move that ended at rest: a second one is real.
    alarm2_before: bool,
}

impl<T: AsyncRead + AsyncWrite + Unpin> GrblStage<T> {
    /// Wraps an open link.
    pub fn new(io: T, cfg: GrblConfig) -> Self {
        GrblStage {
            link: LineLink::new(io, 256, "GRBL", cfg.reply_timeout),
            cfg,
            wco_mm: None,
            trusted: false,
            expect_banner: false,
            needs_reset: false,
            dirty: false,
            warnings: Vec::new(),
            board: ControllerSettings::default(),
            last_units: None,
            jog: None,
            alarm2_before: false,
        }
    }

    /// Steps (device units) for a machine position in mm.
    fn mm_to_units(&self, mm: f64) -> i64 {
        (mm * self.cfg.steps_per_mm).round() as i64
    }

    /// The feed the board really jogs at, mm/min (capped at `$111`).
    fn effective_feed_mm_min(&self) -> f64 {
        match self.board.max_rate_mm_min() {
            Some(max) => self.cfg.feed_mm_min.min(max),
            None => self.cfg.feed_mm_min,
        }
    }

    /// How long the rest of a jog takes: `distance_units` to go at `speed_mm_min` now.
    fn remaining_time(&self, distance_units: i64, speed_mm_min: f64) -> Duration {
        let mm = distance_units.unsigned_abs() as f64 / self.cfg.steps_per_mm;
        move_time(
            mm,
            speed_mm_min / 60.0,
            self.effective_feed_mm_min() / 60.0,
            self.board.acceleration_mm_s2(),
        )
    }

    async fn write(&mut self, bytes: &[u8]) -> Result<(), StageError> {
        self.link.write(bytes).await
    }

    /// Next message, handling push messages that change trust. `Ok(None)` on timeout.
    async fn next_raw(&mut self, timeout: Duration) -> Result<Option<GrblMessage>, StageError> {
        let deadline = Instant::now() + timeout;
        while let Some(line) = self.link.next_line(deadline).await? {
            match parse_line(&line) {
                Some(m) => return Ok(Some(m)),
                None => tracing::debug!(%line, "ignored unrecognised GRBL line"),
            }
        }
        Ok(None)
    }

    /// Next message, turning unexpected resets and alarms into errors.
    async fn next(&mut self, timeout: Duration) -> Result<Option<GrblMessage>, StageError> {
        let m = self.next_raw(timeout).await?;
        match &m {
            Some(GrblMessage::Banner(b)) => {
                if self.expect_banner {
                    self.expect_banner = false;
                } else {
                    self.trusted = false;
                    return Err(StageError::PositionLost {
                        reason: format!("controller reset (banner {b:?})"),
                    });
                }
            }
            Some(GrblMessage::Alarm(n @ (1 | 3))) => {
                self.trusted = false;
                self.needs_reset = true;
                return Err(StageError::PositionLost {
                    reason: format!("ALARM:{n}: {}", alarm_text(*n)),
                });
            }
            Some(GrblMessage::Alarm(2)) => {
                // Every target sent lies inside the configured limits and the board's own
                // travel (checked before the plan starts): a soft-limit alarm then means the
                // controller's position is stale, once; re-homed, the same refusal is real.
                self.needs_reset = true;
                if self.alarm2_before {
                    return Err(StageError::Fault {
                        reason: "ALARM:2 (soft limit) again after re-homing, for a target inside the configured limits: the controller's travel ($130/$131) and the stage's soft limits in the configuration disagree; make them agree".into(),
                        class: FaultClass::Fatal,
                    });
                }
                self.alarm2_before = true;
                self.trusted = false;
                return Err(StageError::PositionLost {
                    reason: "ALARM:2 (soft limit) for a target inside the configured limits: the controller's position may be stale".into(),
                });
            }
            Some(GrblMessage::Alarm(n)) => {
                self.needs_reset = true;
                self.trusted = false;
                return Err(StageError::Fault {
                    reason: format!("ALARM:{n}: {}", alarm_text(*n)),
                    class: FaultClass::PositionLost,
                });
            }
            Some(GrblMessage::Msg(msg)) => self.warnings.push(msg.clone()),
            _ => {}
        }
        Ok(m)
    }

    /// Discards whatever is still arriving from an interrupted exchange (until the link
    /// has been quiet for a tenth of the reply timeout), noting resets and lost positions.
    async fn drain(&mut self) -> Result<(), StageError> {
        let quiet = self.cfg.reply_timeout / 10;
        while let Some(m) = self.next_raw(quiet).await? {
            match m {
                GrblMessage::Banner(_) if !self.expect_banner => self.trusted = false,
                GrblMessage::Banner(_) => self.expect_banner = false,
                GrblMessage::Alarm(1 | 3) => {
                    self.trusted = false;
                    self.needs_reset = true;
                }
                GrblMessage::Alarm(_) => self.needs_reset = true,
                other => tracing::debug!(?other, "discarded stale GRBL message"),
            }
        }
        self.dirty = false;
        Ok(())
    }

    /// Sends one line and waits for its `ok`/`error`, collecting the lines before it.
    async fn command(
        &mut self,
        line: &str,
        timeout: Duration,
    ) -> Result<Vec<GrblMessage>, StageError> {
        if self.dirty {
            self.drain().await?;
        }
        let r = self.command_inner(line, timeout).await;
        if r.is_err() {
            self.dirty = true;
        }
        r
    }

    async fn command_inner(
        &mut self,
        line: &str,
        timeout: Duration,
    ) -> Result<Vec<GrblMessage>, StageError> {
        self.write(format!("{}\n", line.trim_end()).as_bytes())
            .await?;
        let mut seen = Vec::new();
        loop {
            match self.next(timeout).await? {
                None => {
                    return Err(StageError::NoReply {
                        waiting_for: format!("the reply to {line:?}"),
                        timeout_ms: timeout.as_millis() as u64,
                    })
                }
                Some(GrblMessage::Ok) => return Ok(seen),
                Some(GrblMessage::Error(15)) => {
                    return Err(StageError::ControllerLimit {
                        command: line.to_string(),
                        reason: format!("error:15 {}", error_text(15)),
                        code: Some(15),
                    })
                }
                Some(GrblMessage::Error(n)) => {
                    return Err(StageError::Rejected {
                        command: line.to_string(),
                        reason: format!("error:{n} {}", error_text(n)),
                        code: Some(n),
                    })
                }
                Some(m) => seen.push(m),
            }
        }
    }

    async fn query_status(&mut self) -> Result<StatusReport, StageError> {
        if self.dirty {
            self.drain().await?;
        }
        let r = self.query_status_inner().await;
        if r.is_err() {
            self.dirty = true;
        }
        r
    }

    async fn query_status_inner(&mut self) -> Result<StatusReport, StageError> {
        self.write(&[RT_STATUS]).await?;
        loop {
            match self.next(self.cfg.reply_timeout).await? {
                None => {
                    return Err(StageError::NoReply {
                        waiting_for: "a status report to '?'".into(),
                        timeout_ms: self.cfg.reply_timeout.as_millis() as u64,
                    })
                }
                Some(GrblMessage::Status(r)) => return Ok(r),
                Some(_) => {}
            }
        }
    }

    fn status_from(&mut self, r: &StatusReport) -> Result<StageStatus, StageError> {
        if let Some(w) = r.wco_mm {
            self.wco_mm = Some(w);
        }
        let y_mm = match (r.mpos_mm, r.wpos_mm, self.wco_mm) {
            (Some(m), _, _) => m[1],
            (None, Some(w), Some(wco)) => w[1] + wco[1],
            (None, Some(_), None) => {
                return Err(StageError::Protocol {
                    line: format!("{r:?}"),
                    why: "a work-coordinate report (WPos) before any WCO: the machine position \
                          is unknown; set $10=1 on the controller for machine positions"
                        .into(),
                })
            }
            (None, None, _) => {
                return Err(StageError::Protocol {
                    line: format!("{r:?}"),
                    why: "status report without a position".into(),
                })
            }
        };
        if r.state == GrblState::Alarm {
            // Alarm locks the board until $H (or $X): whatever caused it (a reset in motion, a
            // power-up with homing enabled, a limit), the position needs a home.
            self.trusted = false;
        }
        let motion = match r.state {
            GrblState::Idle | GrblState::Sleep | GrblState::Check => Motion::Idle,
            GrblState::Run | GrblState::Jog | GrblState::Hold(_) | GrblState::Door(_) => {
                Motion::Moving
            }
            GrblState::Home => Motion::Homing,
            GrblState::Alarm => Motion::Alarm,
        };
        let mut warnings = std::mem::take(&mut self.warnings);
        if r.pins.as_deref().is_some_and(|p| p.contains('Y')) {
            warnings.push("the Y limit/home switch is pressed (Pn:Y)".into());
        }
        let units = self.mm_to_units(y_mm);
        self.last_units = Some(units);
        Ok(StageStatus {
            motion,
            position_trusted: self.trusted,
            position_units: units,
            warnings,
        })
    }

    /// Soft reset, waiting for the banner it causes (which is not a position-lost event).
    async fn soft_reset(&mut self) -> Result<(), StageError> {
        self.expect_banner = true;
        self.link.clear();
        self.write(&[RT_SOFT_RESET]).await?;
        // A reset in motion prints ALARM:3 and pauses half a second before the banner.
        let timeout = self.cfg.reply_timeout + Duration::from_millis(500);
        let deadline = Instant::now() + timeout;
        while self.expect_banner {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.next_raw(left).await? {
                None => {
                    return Err(StageError::NoReply {
                        waiting_for: "the banner after a soft reset".into(),
                        timeout_ms: timeout.as_millis() as u64,
                    })
                }
                Some(GrblMessage::Banner(_)) => self.expect_banner = false,
                Some(GrblMessage::Alarm(3)) => self.trusted = false,
                Some(_) => {}
            }
        }
        self.needs_reset = false;
        self.dirty = false;
        self.jog = None;
        Ok(())
    }

    /// Reads `$$` and checks it against the configuration.
    async fn read_settings(&mut self) -> Result<Vec<String>, StageError> {
        let lines = self.command("$$", self.cfg.reply_timeout).await?;
        self.board = ControllerSettings::from_pairs(lines.into_iter().filter_map(|m| match m {
            GrblMessage::Setting(n, v) => Some((n, v)),
            _ => None,
        }));
        self.board
            .check(self.cfg.steps_per_mm, self.cfg.feed_mm_min)
    }

    /// The homing cycle is off on the board: `$H` cannot give a reference.
    fn homing_disabled() -> StageError {
        StageError::ControllerSetup(
            "the controller's homing cycle is disabled ($22=0), so $H cannot reference the \
             axis: fit a home switch and set $22=1 (with $20=1 for soft limits); without one \
             the position after a reset or power cycle cannot be trusted"
                .into(),
        )
    }
}

impl<T: AsyncRead + AsyncWrite + Unpin> Stage for GrblStage<T> {
    async fn identify(&mut self) -> Result<(Identity, StageStatus), StageError> {
        // An Arduino resets when the port opens: its banner arrives within the grace time
        // (after `error:7` and the settings when its EEPROM was blank).
        let mut reset_at_open = false;
        let mut eeprom_reset = false;
        let deadline = Instant::now() + self.cfg.open_grace;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            match self.next_raw(left).await? {
                None => break,
                Some(GrblMessage::Banner(_)) => reset_at_open = true,
                Some(GrblMessage::Error(7)) => eeprom_reset = true,
                Some(_) => {}
            }
        }
        let lines = self.command("$I", self.cfg.reply_timeout).await?;
        let mut ident = Vec::new();
        let mut build = BuildOptions::default();
        for m in lines {
            match m {
                GrblMessage::Ver(v) => ident.push(format!("VER:{v}")),
                GrblMessage::Opt(o) => {
                    build = BuildOptions::from_opt(&o);
                    ident.push(format!("OPT:{o}"));
                }
                _ => {}
            }
        }
        if ident.is_empty() {
            return Err(StageError::Protocol {
                line: "$I".into(),
                why: "no [VER:…] line before ok; is this a GRBL controller?".into(),
            });
        }
        let mut warnings = Vec::new();
        if eeprom_reset {
            warnings.push(
                "the controller reported error:7 at start-up: its settings were unreadable and \
                 were restored to GRBL's defaults"
                    .into(),
            );
        }
        match self.read_settings().await {
            Ok(w) => warnings.extend(w),
            Err(StageError::ControllerSetup(why)) if eeprom_reset => {
                return Err(StageError::ControllerSetup(format!(
                    "the controller reported error:7 at start-up (its EEPROM settings were \
                     unreadable and GRBL's defaults are in force): program the board's settings \
                     again ($$ lists them); {why}"
                )))
            }
            Err(e) => return Err(e),
        }
        let mut r = self.query_status().await?;
        // Work-coordinate reports: wait for the WCO GRBL sends every few reports.
        let mut polls = 1;
        while r.mpos_mm.is_none() && r.wco_mm.is_none() && self.wco_mm.is_none() {
            if polls >= REPORTS_PER_WCO {
                break;
            }
            tokio::time::sleep(self.cfg.poll_interval).await;
            r = self.query_status().await?;
            polls += 1;
        }
        self.trusted = !reset_at_open && r.state != GrblState::Alarm;
        let mut st = self.status_from(&r)?;
        if reset_at_open {
            st.warnings.push(
                "controller reset when the port was opened (Arduino DTR auto-reset): position lost, homing required".into(),
            );
        }
        let spm = self.cfg.steps_per_mm;
        let travel_units = self.board.enforced_travel_mm(build).map(|(lo, hi)| {
            (
                (lo * spm).ceil() as i64, // whole steps inside the travel
                (hi * spm).floor() as i64,
            )
        });
        let id = Identity {
            text: ident.join(" "),
            travel_units,
            warnings,
        };
        Ok((id, st))
    }

    async fn status(&mut self) -> Result<StageStatus, StageError> {
        let r = self.query_status().await?;
        self.status_from(&r)
    }

    async fn home(&mut self, timeout: Duration) -> Result<StageStatus, StageError> {
        if self.board.homing_enabled() == Some(false) {
            return Err(Self::homing_disabled());
        }
        if self.needs_reset {
            self.soft_reset().await?;
        }
        self.jog = None;
        // `?` is not answered during homing; `$H` answers ok when the cycle is over (after
        // an ALARM:8/9 when it failed, which `next` turns into an error first).
        match self.command("$H", timeout).await {
            Ok(_) => {}
            Err(StageError::Rejected { code: Some(5), .. }) => return Err(Self::homing_disabled()),
            Err(e) => return Err(e),
        }
        self.trusted = true;
        self.status().await
    }

    async fn begin_move_abs(&mut self, target_units: i64) -> Result<(), StageError> {
        if self.needs_reset {
            return Err(StageError::Fault {
                reason: "controller is locked by an alarm; home the axis (soft reset, $H)".into(),
                class: FaultClass::PositionLost,
            });
        }
        let y_mm = target_units as f64 / self.cfg.steps_per_mm;
        let line = encode_jog_y(y_mm, self.cfg.feed_mm_min);
        let sent = Instant::now();
        self.jog = None;
        match self.command(&line, self.cfg.reply_timeout).await {
            Ok(_) => {}
            Err(e @ StageError::Rejected { code: Some(8), .. }) => {
                // `$J=` outside Idle/Jog is error:8. In Alarm (a reset or power-up whose banner
                // was missed, a limit) the position needs a home; anything else (a hold) is
                // the refusal itself.
                let r = self.query_status().await?;
                if r.state == GrblState::Alarm {
                    self.trusted = false;
                    return Err(StageError::PositionLost {
                        reason: format!("{e}: the controller is in Alarm"),
                    });
                }
                return Err(e);
            }
            Err(e) => return Err(e),
        }
        self.jog = Some(Jog {
            target_units,
            from_units: self.last_units,
            sent,
        });
        Ok(())
    }

    async fn wait_done(&mut self, timeout: Duration) -> Result<StageStatus, StageError> {
        let deadline = Instant::now() + timeout;
        // First look when the planner's trapezoid says the jog is over.
        let mut wake = match self.jog {
            Some(j) => match j.from_units {
                Some(from) => {
                    j.sent + self.remaining_time(j.target_units - from, 0.0) + POLL_MARGIN
                }
                None => Instant::now(),
            },
            None => Instant::now(),
        };
        loop {
            let at = wake
                .min(Instant::now() + self.cfg.poll_interval)
                .min(deadline);
            tokio::time::sleep_until(at).await;
            let r = self.query_status().await?;
            let st = self.status_from(&r)?;
            match st.motion {
                Motion::Idle => {
                    if self.jog.take().is_some() {
                        self.alarm2_before = false;
                    }
                    return Ok(st);
                }
                Motion::Alarm => {
                    self.needs_reset = true;
                    self.jog = None;
                    return Err(StageError::Fault {
                        reason: "controller in Alarm state during a move".into(),
                        class: FaultClass::PositionLost,
                    });
                }
                Motion::Moving | Motion::Homing => {}
            }
            if Instant::now() >= deadline {
                return Err(StageError::Timeout {
                    waiting_for: "the jog to finish (state Idle)".into(),
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            // Still moving: look again when the rest should be done, from where it is and
            // how fast it goes now.
            let left = match self.jog {
                Some(j) => self.remaining_time(
                    j.target_units - st.position_units,
                    r.feed_mm_min
                        .unwrap_or_else(|| self.effective_feed_mm_min()),
                ),
                None => self.cfg.poll_interval,
            };
            wake = Instant::now() + (left + POLL_MARGIN).max(MIN_POLL_GAP);
        }
    }

    async fn stop(&mut self) -> Result<(), StageError> {
        let moving = self.jog.take().is_some();
        self.write(&[RT_JOG_CANCEL]).await?;
        if !moving {
            return Ok(());
        }
        // GRBL decelerates at $121 and reports Jog until at rest: wait for Idle, so the next
        // move starts from rest at a position read back.
        let feed = self.effective_feed_mm_min() / 60.0;
        let braking = braking_time(feed, self.board.acceleration_mm_s2());
        let deadline = Instant::now() + braking + self.cfg.reply_timeout;
        let mut wake = Instant::now() + braking + POLL_MARGIN;
        loop {
            tokio::time::sleep_until(wake.min(deadline)).await;
            let r = self.query_status().await?;
            let st = self.status_from(&r)?;
            if st.motion != Motion::Moving {
                return Ok(());
            }
            if Instant::now() >= deadline {
                return Err(StageError::Timeout {
                    waiting_for: "the cancelled jog to come to rest (state Idle)".into(),
                    timeout_ms: (braking + self.cfg.reply_timeout).as_millis() as u64,
                });
            }
            wake = Instant::now() + MIN_POLL_GAP;
        }
    }
}
