//! Zaber ASCII: a [`Stage`] driver generic over `AsyncRead + AsyncWrite + Unpin`, over the
//! pure codec in [`codec`].
//!
//! Positions are integer microsteps; completion is seen by polling `get pos` (whose reply
//! carries `BUSY`/`IDLE`, the worst warning flag and the position in one round trip) until
//! `IDLE`. At connect the driver reads the axis's `maxspeed` and `accel`, so the first poll of
//! a move comes when its trapezoid says it is over and each later one when the rest should be
//! done, never more than the poll interval apart; and `limit.min`/`limit.max`, the travel the
//! device enforces, so a plan leaving it is refused before anything moves.
//!
//! A move fails on a fault flag as soon as one is seen; a home is the exception: an axis that
//! powered up without a reference carries `WR` (or `WH`) on every reply until its home has
//! completed, status polls included, so while homing those two are expected and the flags
//! are judged once the device is idle.
//!
//! Layer 2: depends on [`codec`], [`super::link`], [`super::ramp`] and the stage vocabulary
//! in [`super`].

pub mod codec;

use super::link::LineLink;
use super::ramp::{move_time, MIN_POLL_GAP, POLL_MARGIN};
use super::{Identity, Motion, Stage, StageError, StageStatus};
use codec::{encode_command, flag_fault, parse_line, Reply, ZaberMessage, ZaberParseError};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::time::Instant;

/// Zaber's speed unit: one microstep per second is 1.6384 data units; one microstep per s² of
/// acceleration is 0.16384.
const SPEED_DATA_PER_MICROSTEP_S: f64 = 1.6384;

/// Settings of the Zaber driver.
#[derive(Debug, Clone)]
pub struct ZaberConfig {
    /// Device address.
    pub device: u8,
    /// Axis number.
    pub axis: u8,
    /// Poll interval while busy.
    pub poll_interval: Duration,
    /// Timeout for one reply.
    pub reply_timeout: Duration,
    /// Send a message id (00–99) with every command and accept only the reply carrying it,
    /// so a late reply to an earlier command can never be taken for the current one.
    pub message_ids: bool,
    /// Append a `:CC` checksum to every command.
    pub checksums: bool,
}

/// A move sent and not yet seen to end.
#[derive(Debug, Clone, Copy)]
struct PendingMove {
    target: i64,
    from: Option<i64>,
    sent: Instant,
}

/// The Zaber driver.
pub struct ZaberStage<T> {
    link: LineLink<T>,
    cfg: ZaberConfig,
    /// A reply may still be in flight from an interrupted exchange: drain before talking.
    dirty: bool,
    next_id: u8,
    /// The axis's `maxspeed`, microsteps/s, when it reported one.
    speed: Option<f64>,
    /// The axis's `accel`, microsteps/s², when it reported one.
    accel: Option<f64>,
    /// The position of the last reply to `get pos`, microsteps.
    last_pos: Option<i64>,
    pending: Option<PendingMove>,
}

impl<T: AsyncRead + AsyncWrite + Unpin> ZaberStage<T> {
    /// Wraps an open link.
    pub fn new(io: T, cfg: ZaberConfig) -> Self {
        ZaberStage {
            link: LineLink::new(io, 512, "Zaber", cfg.reply_timeout),
            cfg,
            dirty: false,
            next_id: 0,
            speed: None,
            accel: None,
            last_pos: None,
            pending: None,
        }
    }

    /// How long `distance` microsteps take from `v0` microsteps/s to rest, at the axis's
    /// speed and acceleration; `None` when the axis did not report its speed.
    fn travel_time(&self, distance: i64, v0: f64) -> Option<Duration> {
        let speed = self.speed?;
        Some(move_time(
            distance.unsigned_abs() as f64,
            v0,
            speed,
            self.accel,
        ))
    }

    /// An axis setting by name, `None` when the device rejects it (older firmware).
    async fn get_setting(&mut self, name: &str) -> Result<Option<f64>, StageError> {
        match self.command(&format!("get {name}")).await {
            Ok(r) => Ok(r.data.trim().parse::<f64>().ok().filter(|v| v.is_finite())),
            Err(StageError::Rejected { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }

    async fn next_line(&mut self, deadline: tokio::time::Instant) -> Result<String, StageError> {
        self.link
            .next_line(deadline)
            .await?
            .ok_or_else(|| StageError::NoReply {
                waiting_for: "a Zaber reply".into(),
                timeout_ms: self.cfg.reply_timeout.as_millis() as u64,
            })
    }

    /// Sends a command to this axis and returns its reply (RJ → error). Info and alert lines
    /// and replies from other devices are skipped.
    async fn command(&mut self, command: &str) -> Result<Reply, StageError> {
        if self.dirty {
            // Discard late replies until the link is quiet for a tenth of the reply timeout.
            self.link.discard_queued();
            loop {
                let quiet = tokio::time::Instant::now() + self.cfg.reply_timeout / 10;
                match self.next_line(quiet).await {
                    Ok(l) => tracing::debug!(line = %l, "discarded stale Zaber line"),
                    Err(StageError::NoReply { .. }) => break,
                    Err(e) => return Err(e),
                }
            }
            self.dirty = false;
        }
        let r = self.command_inner(command).await;
        // A rejection consumed its reply; any other failure may leave one in flight.
        if r.is_err()
            && !matches!(
                r,
                Err(StageError::Rejected { .. } | StageError::ControllerLimit { .. })
            )
        {
            self.dirty = true;
        }
        r
    }

    async fn command_inner(&mut self, command: &str) -> Result<Reply, StageError> {
        let id = self.cfg.message_ids.then(|| {
            let id = self.next_id;
            self.next_id = (self.next_id + 1) % 100;
            id
        });
        let line = encode_command(
            self.cfg.device,
            self.cfg.axis,
            id,
            command,
            self.cfg.checksums,
        );
        self.link.write(line.as_bytes()).await?;
        let deadline = tokio::time::Instant::now() + self.cfg.reply_timeout;
        loop {
            let l = self.next_line(deadline).await?;
            match parse_line(&l) {
                Ok(ZaberMessage::Reply(r))
                    if r.device == self.cfg.device
                        && r.axis == self.cfg.axis
                        && (id.is_none() || r.id == id) =>
                {
                    if !r.accepted {
                        let reason = format!("RJ {}", r.data);
                        return Err(if r.data == "BADDATA" && command.starts_with("move") {
                            StageError::ControllerLimit {
                                command: command.to_string(),
                                reason,
                                code: None,
                            }
                        } else {
                            StageError::Rejected {
                                command: command.to_string(),
                                reason,
                                code: None,
                            }
                        });
                    }
                    return Ok(r);
                }
                Ok(ZaberMessage::Alert(_, _, _, Some(f))) => {
                    if let Some(e) = flag_fault(&f) {
                        return Err(e);
                    }
                }
                Ok(_) => {}
                Err(e @ ZaberParseError::Checksum { .. }) => {
                    return Err(StageError::Protocol {
                        line: l,
                        why: e.to_string(),
                    })
                }
                Err(e) => tracing::warn!(error = %e, "unparsed Zaber line"),
            }
        }
    }

    fn check_flag(r: &Reply) -> Result<(), StageError> {
        match r.flag.as_deref().and_then(flag_fault) {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    fn check_flag_while_homing(r: &Reply) -> Result<(), StageError> {
        match r.flag.as_deref() {
            Some("WR" | "WH") | None => Ok(()),
            Some(_) => Self::check_flag(r),
        }
    }

    async fn get_pos(&mut self) -> Result<(Reply, i64), StageError> {
        let r = self.command("get pos").await?;
        let pos = r
            .data
            .trim()
            .parse::<i64>()
            .map_err(|_| StageError::Protocol {
                line: format!("{r:?}"),
                why: "get pos did not return an integer".into(),
            })?;
        self.last_pos = Some(pos);
        Ok((r, pos))
    }

    fn status_of(r: &Reply, pos: i64) -> StageStatus {
        let trusted = !matches!(r.flag.as_deref(), Some("WR" | "WH"));
        StageStatus {
            motion: if r.busy { Motion::Moving } else { Motion::Idle },
            position_trusted: trusted,
            position_units: pos,
            warnings: r.flag.iter().cloned().collect(),
        }
    }

    async fn poll_idle(&mut self, timeout: Duration) -> Result<StageStatus, StageError> {
        let deadline = Instant::now() + timeout;
        // First look when the trapezoid says the move is over.
        let mut wake = match self.pending {
            Some(PendingMove {
                target,
                from: Some(from),
                sent,
            }) => self
                .travel_time(target - from, 0.0)
                .map_or_else(Instant::now, |t| sent + t + POLL_MARGIN),
            _ => Instant::now(),
        };
        loop {
            let at = wake
                .min(Instant::now() + self.cfg.poll_interval)
                .min(deadline);
            tokio::time::sleep_until(at).await;
            let (r, pos) = self.get_pos().await?;
            Self::check_flag(&r)?;
            if !r.busy {
                self.pending = None;
                return Ok(Self::status_of(&r, pos));
            }
            if Instant::now() >= deadline {
                return Err(StageError::Timeout {
                    waiting_for: "the axis to become IDLE".into(),
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            // Still busy: look again when the rest should be done at the axis's speed.
            let left = self
                .pending
                .and_then(|m| self.travel_time(m.target - pos, self.speed.unwrap_or(0.0)));
            wake = match left {
                Some(left) => Instant::now() + (left + POLL_MARGIN).max(MIN_POLL_GAP),
                None => Instant::now() + self.cfg.poll_interval,
            };
        }
    }
}

impl<T: AsyncRead + AsyncWrite + Unpin> Stage for ZaberStage<T> {
    async fn identify(&mut self) -> Result<(Identity, StageStatus), StageError> {
        let axis = self.cfg.axis;
        self.cfg.axis = 0;
        let id = self.command("get deviceid").await;
        self.cfg.axis = axis;
        let id = id?;
        let (r, pos) = self.get_pos().await?;
        self.speed = self
            .get_setting("maxspeed")
            .await?
            .map(|v| v / SPEED_DATA_PER_MICROSTEP_S)
            .filter(|v| *v > 0.0);
        self.accel = self
            .get_setting("accel")
            .await?
            .map(|v| v * 10.0 / SPEED_DATA_PER_MICROSTEP_S)
            .filter(|v| *v > 0.0);
        let lo = self.get_setting("limit.min").await?;
        let hi = self.get_setting("limit.max").await?;
        let travel_units = match (lo, hi) {
            (Some(lo), Some(hi)) if lo < hi => Some((lo.ceil() as i64, hi.floor() as i64)),
            _ => None,
        };
        let mut warnings = Vec::new();
        if self.speed.is_none() {
            warnings.push(
                "the axis did not report its maxspeed: moves are polled every poll-interval-ms"
                    .into(),
            );
        }
        let identity = Identity {
            text: format!("zaber device {} id {}", self.cfg.device, id.data),
            travel_units,
            warnings,
        };
        Ok((identity, Self::status_of(&r, pos)))
    }

    async fn status(&mut self) -> Result<StageStatus, StageError> {
        let (r, pos) = self.get_pos().await?;
        Self::check_flag(&r)?;
        Ok(Self::status_of(&r, pos))
    }

    async fn home(&mut self, timeout: Duration) -> Result<StageStatus, StageError> {
        // Until the home has completed the axis has no reference: WR/WH on the home reply and
        // on every poll while it runs are expected. Any other fault flag ends it at once.
        let r = self.command("home").await?;
        Self::check_flag_while_homing(&r)?;
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let r = self.command("").await?;
            Self::check_flag_while_homing(&r)?;
            if !r.busy {
                break;
            }
            if tokio::time::Instant::now() >= deadline {
                return Err(StageError::Timeout {
                    waiting_for: "the home to complete (IDLE)".into(),
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            tokio::time::sleep(self.cfg.poll_interval).await;
        }
        // Ended: now the flags count, WR/WH included.
        let (r, pos) = self.get_pos().await?;
        match r.flag.as_deref() {
            Some(f @ ("WR" | "WH")) => Err(StageError::PositionLost {
                reason: format!(
                    "{f} after the home completed: the device is still not referenced; check \
                     the home sensor and its cable"
                ),
            }),
            _ => {
                Self::check_flag(&r)?;
                Ok(Self::status_of(&r, pos))
            }
        }
    }

    async fn begin_move_abs(&mut self, target_units: i64) -> Result<(), StageError> {
        self.pending = None;
        let sent = Instant::now();
        let r = self.command(&format!("move abs {target_units}")).await?;
        if let Err(e) = Self::check_flag(&r) {
            if r.busy {
                // Accepted on a lost reference (WR after a power cycle): it would run to the
                // target counted from wherever the axis powered up. Stop it where it stands.
                if let Err(stop) = self.command("stop").await {
                    tracing::warn!(error = %stop, "stopping a move on a lost reference failed");
                }
            }
            return Err(e);
        }
        self.pending = Some(PendingMove {
            target: target_units,
            from: self.last_pos,
            sent,
        });
        Ok(())
    }

    async fn wait_done(&mut self, timeout: Duration) -> Result<StageStatus, StageError> {
        self.poll_idle(timeout).await
    }

    async fn stop(&mut self) -> Result<(), StageError> {
        self.pending = None;
        let r = self.command("stop").await?;
        if r.busy {
            // The axis decelerates after `stop`: wait until it is at rest, so the next move
            // starts from a position read back.
            let deadline = Instant::now() + self.cfg.reply_timeout;
            loop {
                tokio::time::sleep(MIN_POLL_GAP).await;
                let (r, _) = self.get_pos().await?;
                if !r.busy {
                    break;
                }
                if Instant::now() >= deadline {
                    return Err(StageError::Timeout {
                        waiting_for: "the stopped axis to come to rest (IDLE)".into(),
                        timeout_ms: self.cfg.reply_timeout.as_millis() as u64,
                    });
                }
            }
        }
        // Our own stop raises NI (movement interrupted); clear it so it is not read later
        // as a fault.
        self.command("warnings clear").await.map(|_| ())
    }
}
