//! Zaber ASCII: a [`Stage`] driver generic over `AsyncRead + AsyncWrite + Unpin`, over the
//! pure codec in [`codec`].
//!
//! Positions are integer microsteps; completion is seen by polling until `IDLE`. Every reply
//! carries the device's worst warning flag and a move fails on a fault flag as soon as one is
//! seen; a home is the exception: an axis that powered up without a reference carries `WR`
//! (or `WH`) on every reply until its home has completed, status polls included, so while
//! homing those two are expected and the flags are judged once the device is idle.
//!
//! Layer 2: depends on [`codec`], [`super::link`] and the stage vocabulary in [`super`].

pub mod codec;

use super::link::LineLink;
use super::{Identity, Motion, Stage, StageError, StageStatus};
use codec::{encode_command, flag_fault, parse_line, Reply, ZaberMessage, ZaberParseError};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite};

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

/// The Zaber driver.
pub struct ZaberStage<T> {
    link: LineLink<T>,
    cfg: ZaberConfig,
    /// A reply may still be in flight from an interrupted exchange: drain before talking.
    dirty: bool,
    next_id: u8,
}

impl<T: AsyncRead + AsyncWrite + Unpin> ZaberStage<T> {
    /// Wraps an open link.
    pub fn new(io: T, cfg: ZaberConfig) -> Self {
        ZaberStage {
            link: LineLink::new(io, 512, "Zaber"),
            cfg,
            dirty: false,
            next_id: 0,
        }
    }

    async fn next_line(&mut self, deadline: tokio::time::Instant) -> Result<String, StageError> {
        self.link
            .next_line(deadline)
            .await?
            .ok_or_else(|| StageError::Timeout {
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
                    Err(StageError::Timeout { .. }) => break,
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
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let r = self.command("").await?;
            Self::check_flag(&r)?;
            if !r.busy {
                let (r, pos) = self.get_pos().await?;
                Self::check_flag(&r)?;
                return Ok(Self::status_of(&r, pos));
            }
            if tokio::time::Instant::now() >= deadline {
                return Err(StageError::Timeout {
                    waiting_for: "the axis to become IDLE".into(),
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            tokio::time::sleep(self.cfg.poll_interval).await;
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
        let identity = Identity {
            text: format!("zaber device {} id {}", self.cfg.device, id.data),
            ..Identity::default()
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
                    "{f} after the home completed: the device is still not referenced; check                      the home sensor and its cable"
                ),
            }),
            _ => {
                Self::check_flag(&r)?;
                Ok(Self::status_of(&r, pos))
            }
        }
    }

    async fn begin_move_abs(&mut self, target_units: i64) -> Result<(), StageError> {
        let r = self.command(&format!("move abs {target_units}")).await?;
        Self::check_flag(&r)
    }

    async fn wait_done(&mut self, timeout: Duration) -> Result<StageStatus, StageError> {
        self.poll_idle(timeout).await
    }

    async fn stop(&mut self) -> Result<(), StageError> {
        self.command("stop").await?;
        // Our own stop raises NI (movement interrupted); clear it so it is not read later
        // as a fault.
        self.command("warnings clear").await.map(|_| ())
    }
}
