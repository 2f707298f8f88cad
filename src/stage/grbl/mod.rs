//! GRBL 1.1 / grblHAL: a [`Stage`] driver generic over `AsyncRead + AsyncWrite + Unpin`,
//! over the pure line codec in [`codec`].
//!
//! Moves are jogs to absolute machine coordinates (`$J=G53 G90 Y… F…`); completion is seen
//! by polling `?` until `Idle` (G-code, even `G4`, is refused with `error:9` during a jog).
//! A banner or `ALARM:1`/`ALARM:3` not caused by our own reset means the position is lost.
//!
//! Layer 2: depends on [`codec`], [`super::link`] and the stage vocabulary in [`super`].

pub mod codec;

use super::link::LineLink;
use super::{Motion, Stage, StageError, StageStatus};
use crate::devices::FaultClass;
use codec::{
    alarm_text, encode_jog_y, error_text, parse_line, GrblMessage, GrblState, StatusReport,
    RT_JOG_CANCEL, RT_SOFT_RESET, RT_STATUS,
};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite};

/// Settings of the GRBL driver.
#[derive(Debug, Clone)]
pub struct GrblConfig {
    /// Steps per mm of the Y axis (`$101`).
    pub steps_per_mm: f64,
    /// Jog feed rate, mm/min.
    pub feed_mm_min: f64,
    /// Status poll interval (GRBL asks for ≤ 5 Hz).
    pub poll_interval: Duration,
    /// Timeout for one line's `ok`/`error` or a status report.
    pub reply_timeout: Duration,
    /// How long to listen for a start-up banner after opening (Arduino DTR reset).
    pub open_grace: Duration,
}

/// The GRBL driver.
pub struct GrblStage<T> {
    link: LineLink<T>,
    cfg: GrblConfig,
    wco_mm: [f64; 3],
    trusted: bool,
    expect_banner: bool,
    needs_reset: bool,
    /// A reply may still be in flight from an interrupted exchange: drain before talking.
    dirty: bool,
    warnings: Vec<String>,
}

impl<T: AsyncRead + AsyncWrite + Unpin> GrblStage<T> {
    /// Wraps an open link.
    pub fn new(io: T, cfg: GrblConfig) -> Self {
        GrblStage {
            link: LineLink::new(io, 256, "GRBL"),
            cfg,
            wco_mm: [0.0; 3],
            trusted: false,
            expect_banner: false,
            needs_reset: false,
            dirty: false,
            warnings: Vec::new(),
        }
    }

    /// Steps (device units) for a machine position in mm.
    fn mm_to_units(&self, mm: f64) -> i64 {
        (mm * self.cfg.steps_per_mm).round() as i64
    }

    async fn write(&mut self, bytes: &[u8]) -> Result<(), StageError> {
        self.link.write(bytes).await
    }

    /// Next message, handling push messages that change trust. `Ok(None)` on timeout.
    async fn next_raw(&mut self, timeout: Duration) -> Result<Option<GrblMessage>, StageError> {
        let deadline = tokio::time::Instant::now() + timeout;
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
            Some(GrblMessage::Alarm(n)) => {
                self.needs_reset = true;
                let class = if *n == 2 {
                    FaultClass::Fatal
                } else {
                    FaultClass::PositionLost
                };
                if class == FaultClass::PositionLost {
                    self.trusted = false;
                }
                return Err(StageError::Fault {
                    reason: format!("ALARM:{n}: {}", alarm_text(*n)),
                    class,
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
                    return Err(StageError::Timeout {
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
                    return Err(StageError::Timeout {
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
            self.wco_mm = w;
        }
        let y_mm = match (r.mpos_mm, r.wpos_mm) {
            (Some(m), _) => m[1],
            (None, Some(w)) => w[1] + self.wco_mm[1],
            (None, None) => {
                return Err(StageError::Protocol {
                    line: format!("{r:?}"),
                    why: "status report without a position".into(),
                })
            }
        };
        let motion = match r.state {
            GrblState::Idle | GrblState::Sleep | GrblState::Check => Motion::Idle,
            GrblState::Run | GrblState::Jog | GrblState::Hold(_) | GrblState::Door(_) => {
                Motion::Moving
            }
            GrblState::Home => Motion::Homing,
            GrblState::Alarm => Motion::Alarm,
        };
        Ok(StageStatus {
            motion,
            position_trusted: self.trusted,
            position_units: self.mm_to_units(y_mm),
            warnings: std::mem::take(&mut self.warnings),
        })
    }

    /// Soft reset, waiting for the banner it causes (which is not a position-lost event).
    async fn soft_reset(&mut self) -> Result<(), StageError> {
        self.expect_banner = true;
        self.link.clear();
        self.write(&[RT_SOFT_RESET]).await?;
        let deadline = tokio::time::Instant::now() + self.cfg.reply_timeout;
        while self.expect_banner {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            match self.next_raw(left).await? {
                None => {
                    return Err(StageError::Timeout {
                        waiting_for: "the banner after a soft reset".into(),
                        timeout_ms: self.cfg.reply_timeout.as_millis() as u64,
                    })
                }
                Some(GrblMessage::Banner(_)) => self.expect_banner = false,
                Some(GrblMessage::Alarm(3)) => self.trusted = false,
                Some(_) => {}
            }
        }
        self.needs_reset = false;
        self.dirty = false;
        Ok(())
    }
}

impl<T: AsyncRead + AsyncWrite + Unpin> Stage for GrblStage<T> {
    async fn identify(&mut self) -> Result<(String, StageStatus), StageError> {
        // An Arduino resets when the port opens: its banner arrives within the grace time.
        let mut reset_at_open = false;
        let deadline = tokio::time::Instant::now() + self.cfg.open_grace;
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            if left.is_zero() {
                break;
            }
            match self.next_raw(left).await? {
                None => break,
                Some(GrblMessage::Banner(_)) => reset_at_open = true,
                Some(_) => {}
            }
        }
        let lines = self.command("$I", self.cfg.reply_timeout).await?;
        let mut ident = Vec::new();
        for m in lines {
            match m {
                GrblMessage::Ver(v) => ident.push(format!("VER:{v}")),
                GrblMessage::Opt(o) => ident.push(format!("OPT:{o}")),
                _ => {}
            }
        }
        if ident.is_empty() {
            return Err(StageError::Protocol {
                line: "$I".into(),
                why: "no [VER:…] line before ok; is this a GRBL controller?".into(),
            });
        }
        let r = self.query_status().await?;
        self.trusted = !reset_at_open && r.state != GrblState::Alarm;
        let mut st = self.status_from(&r)?;
        if reset_at_open {
            st.warnings.push(
                "controller reset when the port was opened (Arduino DTR auto-reset): position lost, homing required".into(),
            );
        }
        Ok((ident.join(" "), st))
    }

    async fn status(&mut self) -> Result<StageStatus, StageError> {
        let r = self.query_status().await?;
        self.status_from(&r)
    }

    async fn home(&mut self, timeout: Duration) -> Result<StageStatus, StageError> {
        if self.needs_reset {
            self.soft_reset().await?;
        }
        // `?` is not answered during homing; `$H` answers ok when the cycle is over.
        self.command("$H", timeout).await?;
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
        self.command(&line, self.cfg.reply_timeout).await?;
        Ok(())
    }

    async fn wait_done(&mut self, timeout: Duration) -> Result<StageStatus, StageError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let r = self.query_status().await?;
            let st = self.status_from(&r)?;
            match st.motion {
                Motion::Idle => return Ok(st),
                Motion::Alarm => {
                    self.needs_reset = true;
                    return Err(StageError::Fault {
                        reason: "controller in Alarm state during a move".into(),
                        class: FaultClass::PositionLost,
                    });
                }
                Motion::Moving | Motion::Homing => {}
            }
            if tokio::time::Instant::now() >= deadline {
                return Err(StageError::Timeout {
                    waiting_for: "the jog to finish (state Idle)".into(),
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            tokio::time::sleep(self.cfg.poll_interval).await;
        }
    }

    async fn stop(&mut self) -> Result<(), StageError> {
        self.write(&[RT_JOG_CANCEL]).await
    }
}
