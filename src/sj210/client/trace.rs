//! One trace's motion: waiting for idle (returning the detector from `005`), starting the
//! measurement, polling the status until it is back — on the poll interval, and at each
//! phase's expected end ([`crate::sj210::timing`]) — the deadline from the conditions,
//! over-range with the detector position, and the best-effort abort.
//!
//! Layer 2: part of [`super::Sj210Client`]. Time comes from `tokio::time`.

use super::{millis, status, Sj210Client};
use crate::sj210::codec::NgCode;
use crate::sj210::error::{LinkError, Sj210Error};
use crate::sj210::timing::{self, PhaseWatch, TraceTiming};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::time::{sleep, Instant};

/// What a trace's wait waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceUntil {
    /// The drive back at its start (`000`), or stopped at the end of travel (`005`).
    Back,
    /// The measurement done: the drive returning (`002`) is enough.
    Measured,
}

/// How a trace's wait ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceEnd {
    /// Back at the start (`000`).
    Back,
    /// Stopped at the end of travel (`005`, auto-return off).
    AtEnd,
    /// Measured, and the drive returning (`002`).
    Returning,
}

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// Status must be idle; on `005` the detector is returned first, on `002` the return
    /// is awaited, its status asked when the last trace's return is expected to end.
    pub async fn wait_idle(&mut self) -> Result<(), Sj210Error> {
        let origin = Instant::now();
        let deadline = origin + self.trace_deadline();
        let back_at = self
            .back_at
            .take()
            .map(|t| t.saturating_duration_since(origin));
        let mut watch = PhaseWatch::returning(Duration::ZERO, back_at);
        let mut returned = false;
        loop {
            let s = self.status().await?;
            watch.saw_other(origin.elapsed());
            match s {
                status::IDLE => return Ok(()),
                status::INTERMEDIATE if !returned => {
                    let c = self.table.commands.return_to_start.plain();
                    self.command(&c, false).await?;
                    returned = true;
                    let at = origin.elapsed();
                    let back = self.timing().map(|t| at.saturating_add(t.returning));
                    watch = PhaseWatch::returning(at, back);
                }
                status::RETURNING | status::INTERMEDIATE => {}
                status::RETRACTING | status::RETRACTED => {
                    return Err(Sj210Error::Retracted { status: s })
                }
                other => {
                    return Err(Sj210Error::NotIdle {
                        status: other,
                        meaning: self.table.status_meaning(other),
                    })
                }
            }
            if Instant::now() >= deadline {
                return Err(Sj210Error::NotIdle {
                    status: s,
                    meaning: self.table.status_meaning(s),
                });
            }
            sleep(watch.next_poll(origin.elapsed(), self.opts.poll_interval)).await;
        }
    }

    fn trace_deadline(&self) -> std::time::Duration {
        if let Some(d) = self.opts.trace_deadline {
            return d;
        }
        let c = self.conditions.clone().unwrap_or_default();
        timing::trace_deadline(&c, self.opts.speeds)
    }

    /// How long the drive measures and returns under the conditions read last.
    fn timing(&self) -> Option<TraceTiming> {
        let c = self.conditions.as_ref()?;
        timing::trace_timing(c, self.opts.speeds)
    }

    /// Over-range: read the detector position for the log, then the named error.
    async fn over_range(&mut self) -> Sj210Error {
        let c = self.table.commands.position.plain();
        let position = match self.command(&c, false).await {
            Ok(p) => Some(p.trim().to_string()),
            Err(e) => {
                tracing::warn!("detector position after over-range unreadable: {e}");
                None
            }
        };
        tracing::error!(position = ?position, "detector over-range");
        Sj210Error::OverRange { position }
    }

    /// Starts a trace and polls the status until the instrument is back (idle or `005`).
    pub async fn run_trace(&mut self) -> Result<(), Sj210Error> {
        self.run_trace_until(TraceUntil::Back).await.map(|_| ())
    }

    /// Starts a trace and polls the status until the drive is back (idle or `005`), or, with
    /// [`TraceUntil::Measured`], until the measurement is done and the drive returns (`002`):
    /// then the next [`Sj210Client::wait_idle`] asks the status when the return is expected
    /// to end.
    pub async fn run_trace_until(&mut self, until: TraceUntil) -> Result<TraceEnd, Sj210Error> {
        let s = self.status().await?;
        if s != status::IDLE {
            return Err(Sj210Error::NotIdle {
                status: s,
                meaning: self.table.status_meaning(s),
            });
        }
        let start = self.table.commands.start.plain();
        match self.command(&start, false).await {
            Ok(p) if p.is_empty() => {}
            Ok(payload) => {
                return Err(Sj210Error::UnexpectedReply {
                    command: start,
                    payload,
                    expected: "an empty OK",
                })
            }
            Err(e) if e.code() == Some(NgCode::OverRange) => return Err(self.over_range().await),
            Err(e) => return Err(e),
        }
        self.traces_started += 1;
        let started = Instant::now();
        let deadline = self.trace_deadline();
        let mut watch = PhaseWatch::started(self.timing());
        self.back_at = None;
        let mut active = false;
        let mut link_failures = 0u32;
        loop {
            sleep(watch.next_poll(started.elapsed(), self.opts.poll_interval)).await;
            let s = match self.status().await {
                Ok(s) => {
                    link_failures = 0;
                    s
                }
                Err(e) if e.code() == Some(NgCode::OverRange) => {
                    return Err(self.over_range().await)
                }
                Err(Sj210Error::Link { source, command })
                    if !matches!(source, LinkError::Vanished { .. }) && link_failures < 2 =>
                {
                    tracing::warn!("{command:?} failed during the trace: {source}; polling on");
                    link_failures += 1;
                    continue;
                }
                Err(e) => return Err(e),
            };
            let at = started.elapsed();
            match s {
                status::MEASURING => watch.saw_measuring(at),
                status::RETURNING => watch.saw_returning(at),
                _ => watch.saw_other(at),
            }
            match s {
                status::RETURNING if until == TraceUntil::Measured => {
                    self.back_at = watch.back_at().map(|d| started + d);
                    return Ok(TraceEnd::Returning);
                }
                status::MEASURING | status::RETURNING => active = true,
                status::IDLE if active => return Ok(TraceEnd::Back),
                status::INTERMEDIATE if active => return Ok(TraceEnd::AtEnd),
                status::IDLE | status::INTERMEDIATE => {
                    if started.elapsed() >= self.opts.start_deadline {
                        return Err(Sj210Error::StylusNotOnWorkpiece {
                            waited_ms: millis(started.elapsed()),
                            last_status: s,
                        });
                    }
                }
                status::RETRACTING | status::RETRACTED => {
                    return Err(Sj210Error::Retracted { status: s })
                }
                other => {
                    return Err(Sj210Error::UnexpectedReply {
                        command: self.table.commands.status.plain(),
                        payload: format!("{other:03}"),
                        expected: "a status 000-005",
                    })
                }
            }
            if started.elapsed() >= deadline {
                return Err(Sj210Error::TraceDeadline {
                    waited_ms: millis(deadline),
                    last_status: s,
                });
            }
        }
    }

    /// Best-effort abort: sends the abort command only after reading "measuring".
    pub async fn abort_measurement(&mut self) -> Result<(), Sj210Error> {
        if self.status().await? == status::MEASURING {
            let c = self.table.commands.abort.plain();
            self.command(&c, false).await?;
        }
        Ok(())
    }
}
