//! GRBL 1.1 / grblHAL: the line-message codec (pure) and a [`Stage`] driver generic over
//! `AsyncRead + AsyncWrite + Unpin`.
//!
//! Moves are jogs to absolute machine coordinates (`$J=G53 G90 Y… F…`); completion is seen
//! by polling `?` until `Idle` (G-code, even `G4`, is refused with `error:9` during a jog).
//! A banner or `ALARM:1`/`ALARM:3` not caused by our own reset means the position is lost.

use super::line::LineFramer;
use super::{Motion, Stage, StageError, StageStatus};
use crate::devices::FaultClass;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

/// Real-time status request.
pub const RT_STATUS: u8 = b'?';
/// Real-time feed hold.
pub const RT_FEED_HOLD: u8 = b'!';
/// Real-time cycle start / resume.
pub const RT_CYCLE_START: u8 = b'~';
/// Real-time soft reset (Ctrl-X).
pub const RT_SOFT_RESET: u8 = 0x18;
/// Real-time jog cancel.
pub const RT_JOG_CANCEL: u8 = 0x85;

/// Machine state from a status report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GrblState {
    /// Idle.
    Idle,
    /// Running G-code motion.
    Run,
    /// Jogging.
    Jog,
    /// Feed hold (with sub-state).
    Hold(Option<u8>),
    /// Alarm lock.
    Alarm,
    /// Safety door (with sub-state).
    Door(Option<u8>),
    /// Check mode.
    Check,
    /// Homing.
    Home,
    /// Sleep.
    Sleep,
}

/// A parsed `<…>` status report; positions in mm.
#[derive(Debug, Clone, PartialEq)]
pub struct StatusReport {
    /// Machine state.
    pub state: GrblState,
    /// Machine position, if reported.
    pub mpos_mm: Option<[f64; 3]>,
    /// Work position, if reported.
    pub wpos_mm: Option<[f64; 3]>,
    /// Work coordinate offset, if reported.
    pub wco_mm: Option<[f64; 3]>,
}

/// One line from the controller.
#[derive(Debug, Clone, PartialEq)]
pub enum GrblMessage {
    /// `ok`.
    Ok,
    /// `error:N`.
    Error(u16),
    /// `ALARM:N`.
    Alarm(u16),
    /// `<…>`.
    Status(StatusReport),
    /// `[MSG:…]`.
    Msg(String),
    /// `[VER:…]`.
    Ver(String),
    /// `[OPT:…]`.
    Opt(String),
    /// Other `[…]` feedback (`[GC:…]`, `[HLP:…]`…).
    Feedback(String),
    /// The start-up banner (`Grbl 1.1h ['$' for help]`, `GrblHAL 1.1f ['$' or '$HELP' for help]`).
    Banner(String),
    /// `>…:ok` start-up block echo or a settings line (`$100=250.000`).
    Other(String),
}

fn parse_axes(s: &str) -> Option<[f64; 3]> {
    let mut out = [0.0; 3];
    let mut n = 0;
    for part in s.split(',') {
        let v: f64 = part.trim().parse().ok()?;
        if !v.is_finite() {
            return None;
        }
        if n < 3 {
            out[n] = v;
        }
        n += 1;
    }
    (n >= 3).then_some(out)
}

fn parse_state(s: &str) -> Option<GrblState> {
    let (name, sub) = match s.split_once(':') {
        Some((n, sub)) => (n, Some(sub.parse::<u8>().ok()?)),
        None => (s, None),
    };
    Some(match name {
        "Idle" => GrblState::Idle,
        "Run" => GrblState::Run,
        "Jog" => GrblState::Jog,
        "Hold" => GrblState::Hold(sub),
        "Alarm" => GrblState::Alarm,
        "Door" => GrblState::Door(sub),
        "Check" => GrblState::Check,
        "Home" => GrblState::Home,
        "Sleep" => GrblState::Sleep,
        _ => return None,
    })
}

/// Parses one line (without terminator). `None` when it is not a GRBL message.
pub fn parse_line(line: &str) -> Option<GrblMessage> {
    let line = line.trim();
    if line == "ok" {
        return Some(GrblMessage::Ok);
    }
    if let Some(n) = line.strip_prefix("error:") {
        return n.parse().ok().map(GrblMessage::Error);
    }
    if let Some(n) = line.strip_prefix("ALARM:") {
        return n.parse().ok().map(GrblMessage::Alarm);
    }
    if let Some(body) = line.strip_prefix('<').and_then(|l| l.strip_suffix('>')) {
        let mut fields = body.split('|');
        let state = parse_state(fields.next()?)?;
        let mut rep = StatusReport {
            state,
            mpos_mm: None,
            wpos_mm: None,
            wco_mm: None,
        };
        for f in fields {
            if let Some(v) = f.strip_prefix("MPos:") {
                rep.mpos_mm = Some(parse_axes(v)?);
            } else if let Some(v) = f.strip_prefix("WPos:") {
                rep.wpos_mm = Some(parse_axes(v)?);
            } else if let Some(v) = f.strip_prefix("WCO:") {
                rep.wco_mm = Some(parse_axes(v)?);
            }
        }
        if rep.mpos_mm.is_none() && rep.wpos_mm.is_none() {
            return None;
        }
        return Some(GrblMessage::Status(rep));
    }
    if let Some(body) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
        return Some(if let Some(m) = body.strip_prefix("MSG:") {
            GrblMessage::Msg(m.to_string())
        } else if let Some(m) = body.strip_prefix("VER:") {
            GrblMessage::Ver(m.to_string())
        } else if let Some(m) = body.strip_prefix("OPT:") {
            GrblMessage::Opt(m.to_string())
        } else {
            GrblMessage::Feedback(body.to_string())
        });
    }
    let lower = line.to_ascii_lowercase();
    if (lower.starts_with("grbl ") || lower.starts_with("grblhal ")) && line.contains("for help") {
        return Some(GrblMessage::Banner(line.to_string()));
    }
    if line.starts_with('>') || line.starts_with('$') {
        return Some(GrblMessage::Other(line.to_string()));
    }
    None
}

/// Encodes a jog to an absolute machine Y coordinate.
pub fn encode_jog_y(y_mm: f64, feed_mm_min: f64) -> String {
    format!("$J=G53 G90 Y{y_mm:.6} F{feed_mm_min:.3}\n")
}

/// Meaning of an `error:N` code (the ones a stage driver meets).
pub fn error_text(code: u16) -> &'static str {
    match code {
        1 => "expected command letter",
        2 => "bad number format",
        3 => "invalid '$' statement",
        8 => "command requires Idle",
        9 => "G-code locked out during alarm or jog",
        15 => "jog target exceeds machine travel",
        16 => "invalid jog command",
        20..=38 => "G-code parser error",
        _ => "see the GRBL error code table",
    }
}

/// Meaning of an `ALARM:N` code.
pub fn alarm_text(code: u16) -> &'static str {
    match code {
        1 => "hard limit triggered (position probably lost)",
        2 => "soft limit: motion target exceeds travel (position kept)",
        3 => "reset while in motion (position lost)",
        4 => "probe fail",
        5 => "probe fail",
        6 => "homing fail: reset during homing",
        7 => "homing fail: door opened during homing",
        8 => "homing fail: pull-off did not clear the switch",
        9 => "homing fail: switch not found",
        _ => "unknown alarm",
    }
}

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
    io: T,
    cfg: GrblConfig,
    framer: LineFramer,
    pending: std::collections::VecDeque<GrblMessage>,
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
            io,
            cfg,
            framer: LineFramer::new(256),
            pending: Default::default(),
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
        let r = async {
            self.io.write_all(bytes).await?;
            self.io.flush().await
        }
        .await;
        r.map_err(|e| StageError::Vanished {
            detail: format!("write failed: {e}"),
        })
    }

    /// Next message, handling push messages that change trust. `Ok(None)` on timeout.
    async fn next_raw(&mut self, timeout: Duration) -> Result<Option<GrblMessage>, StageError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Ok(Some(m));
            }
            let mut buf = [0u8; 256];
            let n = match tokio::time::timeout_at(deadline, self.io.read(&mut buf)).await {
                Err(_) => return Ok(None),
                Ok(Err(e)) => {
                    return Err(StageError::Vanished {
                        detail: format!("read failed: {e}"),
                    })
                }
                Ok(Ok(0)) => {
                    return Err(StageError::Vanished {
                        detail: "end of stream".into(),
                    })
                }
                Ok(Ok(n)) => n,
            };
            for l in self.framer.push(buf.get(..n).unwrap_or(&[])) {
                match l {
                    Ok(line) => match parse_line(&line) {
                        Some(m) => self.pending.push_back(m),
                        None => tracing::debug!(%line, "ignored unrecognised GRBL line"),
                    },
                    Err(e) => tracing::warn!(error = %e, "garbled GRBL line"),
                }
            }
        }
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
        self.framer.clear();
        self.pending.clear();
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_fields_in_any_order_with_substates() {
        let m = parse_line("<Hold:0|FS:0,0|WCO:0.000,-5.000,0.000|WPos:1.000,2.500,0.000>");
        assert_eq!(
            m,
            Some(GrblMessage::Status(StatusReport {
                state: GrblState::Hold(Some(0)),
                mpos_mm: None,
                wpos_mm: Some([1.0, 2.5, 0.0]),
                wco_mm: Some([0.0, -5.0, 0.0]),
            }))
        );
        let m = parse_line("<Jog|MPos:0.000,-12.345,0.000|Bf:15,128|FS:60,0>");
        assert!(
            matches!(m, Some(GrblMessage::Status(StatusReport { state: GrblState::Jog, mpos_mm: Some(p), .. })) if p[1] == -12.345)
        );
    }

    #[test]
    fn acks_alarms_and_feedback() {
        assert_eq!(parse_line("ok"), Some(GrblMessage::Ok));
        assert_eq!(parse_line("error:15"), Some(GrblMessage::Error(15)));
        assert_eq!(parse_line("ALARM:2"), Some(GrblMessage::Alarm(2)));
        assert_eq!(
            parse_line("[MSG:Reset to continue]"),
            Some(GrblMessage::Msg("Reset to continue".into()))
        );
        assert_eq!(
            parse_line("[VER:1.1h.20190825:y-stage]"),
            Some(GrblMessage::Ver("1.1h.20190825:y-stage".into()))
        );
        assert_eq!(
            parse_line("[OPT:V,15,128]"),
            Some(GrblMessage::Opt("V,15,128".into()))
        );
        assert!(matches!(
            parse_line("Grbl 1.1h ['$' for help]"),
            Some(GrblMessage::Banner(_))
        ));
        assert!(matches!(
            parse_line("GrblHAL 1.1f ['$' or '$HELP' for help]"),
            Some(GrblMessage::Banner(_))
        ));
    }

    #[test]
    fn garbage_is_not_a_message() {
        for bad in [
            "error:",
            "error:x",
            "ALARM:",
            "<Idle>",
            "<Flying|MPos:0,0,0>",
            "<Idle|MPos:0,0>",
            "<Idle|MPos:nan,0,0>",
            "Grbl",
            "okay",
            "",
        ] {
            assert_eq!(parse_line(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn jog_is_absolute_machine_coordinates() {
        assert_eq!(
            encode_jog_y(-0.0125, 60.0),
            "$J=G53 G90 Y-0.012500 F60.000\n"
        );
    }
}
