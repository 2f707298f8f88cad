//! The SJ-210 client: one command in flight, timeouts, recovery, bounded read retries, the
//! capability probe, one trace with result and profile read-out. Implements
//! [`crate::devices::Instrument`].
//!
//! Layer 2 (I/O adapter): generic over `AsyncRead + AsyncWrite + Unpin`, so a serial port, a
//! pty or an in-memory pipe can stand in. Depends on the codec, the model table and the
//! settings of [`super`], and on the vocabulary in [`crate::devices`] / [`crate::profile`].
//! Time comes from `tokio::time`, so tests can pause it.

use super::codec::{encode_command, escape_bytes, NgCode, Reply, Sj210Codec};
use super::error::{LinkError, Sj210Error};
use super::models::ModelTable;
use super::settings::ClientOptions;
use crate::devices::{Battery, InstrumentIdentity, ProbeReport, ProfileReadout, TracedLine};
use crate::profile::{Conditions, InstrumentResult, Profile};
use bytes::BytesMut;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::{sleep, timeout, Instant};
use tokio_util::codec::Decoder;

/// Most values one profile block request may ask for (M2: `01`–`50`).
pub const MAX_BLOCK: u32 = 50;

/// Status codes of `RDSTU00` (M1 p.17-16).
mod status {
    pub const IDLE: u16 = 0;
    pub const MEASURING: u16 = 1;
    pub const RETURNING: u16 = 2;
    pub const RETRACTING: u16 = 3;
    pub const RETRACTED: u16 = 4;
    pub const INTERMEDIATE: u16 = 5;
}

/// The SJ-210 family client over any byte stream.
#[derive(Debug)]
pub struct Sj210Client<S> {
    io: S,
    codec: Sj210Codec,
    buf: BytesMut,
    table: ModelTable,
    opts: ClientOptions,
    battery: Option<Battery>,
    conditions: Option<Conditions>,
    /// A command was sent and its reply not yet consumed: set while a transaction runs, so a
    /// transaction cancelled mid-flight (operator abort, shutdown) leaves it set and the next
    /// one drains the late reply first instead of taking it as its own answer.
    in_flight: bool,
}

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// A client over `io` with a model table and options.
    pub fn new(io: S, table: ModelTable, opts: ClientOptions) -> Sj210Client<S> {
        Sj210Client {
            io,
            codec: Sj210Codec::new(opts.max_line),
            buf: BytesMut::new(),
            table,
            opts,
            battery: None,
            conditions: None,
            in_flight: false,
        }
    }

    /// The model table in use.
    pub fn table(&self) -> &ModelTable {
        &self.table
    }

    /// Gives the byte stream back.
    pub fn into_inner(self) -> S {
        self.io
    }

    /// Sends one command and reads one reply, without recovery or retry.
    async fn transact(&mut self, command: &str) -> Result<Reply, LinkError> {
        let bytes = encode_command(command)?;
        if self.in_flight {
            tracing::info!("the previous command was cancelled before its reply; draining the link before {command:?}");
            self.drain().await;
        }
        if !self.buf.is_empty() {
            tracing::warn!(stale = %escape_bytes(&self.buf), "discarding unsolicited bytes before {command:?}");
            self.buf.clear();
            self.codec.reset();
        }
        tracing::debug!(tx = %escape_bytes(&bytes));
        self.in_flight = true;
        let reply = self.exchange(&bytes).await;
        self.in_flight = false;
        reply
    }

    /// Writes one encoded command and reads its reply line.
    async fn exchange(&mut self, bytes: &[u8]) -> Result<Reply, LinkError> {
        self.io.write_all(bytes).await.map_err(io_err)?;
        self.io.flush().await.map_err(io_err)?;
        let mut got_any = false;
        loop {
            if let Some(reply) = self.codec.decode(&mut self.buf).map_err(io_err)? {
                tracing::debug!(rx = ?reply);
                return Ok(reply);
            }
            let wait = if got_any {
                self.opts.inter_byte
            } else {
                self.opts.first_byte
            };
            let mut chunk = [0u8; 512];
            match timeout(wait, self.io.read(&mut chunk)).await {
                Err(_) if got_any => {
                    return Err(LinkError::InterByteTimeout {
                        partial: escape_bytes(&self.buf),
                        waited_ms: millis(wait),
                    })
                }
                Err(_) => {
                    return Err(LinkError::FirstByteTimeout {
                        waited_ms: millis(wait),
                    })
                }
                Ok(Ok(0)) => {
                    return Err(LinkError::Vanished {
                        detail: "end of file on the port".into(),
                    })
                }
                Ok(Ok(n)) => {
                    got_any = true;
                    self.buf.extend_from_slice(chunk.get(..n).unwrap_or(&[]));
                }
                Ok(Err(e)) => return Err(io_err(e)),
            }
        }
    }

    /// Reads and discards input until the line is quiet for an inter-byte interval, but never
    /// longer than a first-byte timeout in total (a device that streams garbage must not hang
    /// us); forgets partial lines.
    async fn drain(&mut self) {
        let mut chunk = [0u8; 512];
        let drain_end = Instant::now() + self.opts.first_byte;
        while Instant::now() < drain_end {
            match timeout(self.opts.inter_byte, self.io.read(&mut chunk)).await {
                Ok(Ok(n)) if n > 0 => continue,
                _ => break,
            }
        }
        self.buf.clear();
        self.codec.reset();
    }

    /// After a timeout or malformed reply: drain what is still arriving, forget partial
    /// lines, and read the status once so the next command starts on a clean link.
    async fn recover(&mut self) {
        self.drain().await;
        let status = self.table.commands.status.plain();
        match self.transact(&status).await {
            Ok(r) => {
                tracing::info!(reply = ?r, "status after recovery");
                // A reply later than the drain window answers the status request instead,
                // and the real status reply follows it: swallow that one too, or every later
                // answer would be shifted by one.
                self.drain().await;
            }
            Err(e) => {
                tracing::warn!("status re-read after recovery failed: {e}");
                self.buf.clear();
                self.codec.reset();
            }
        }
    }

    /// One command, its `OK` payload, or a named error. `RD` commands are retried on
    /// NG011/NG033/NG101 within the retry budget when `retry` is true; `CT` commands never.
    pub async fn command(&mut self, command: &str, retry: bool) -> Result<String, Sj210Error> {
        let retry = retry && command.starts_with("RD");
        let started = Instant::now();
        loop {
            match self.transact(command).await {
                Ok(Reply::Ok(payload)) => return Ok(payload),
                Ok(Reply::Ng { code, byte_pos }) => {
                    if retry
                        && code.is_retryable_read()
                        && started.elapsed() + self.opts.poll_interval
                            <= self.opts.read_retry_budget
                    {
                        tracing::debug!("{command:?} answered {code}, retrying");
                        sleep(self.opts.poll_interval).await;
                        continue;
                    }
                    return Err(Sj210Error::Device {
                        command: command.to_string(),
                        code,
                        byte_pos,
                        meaning: self.table.error_meaning(code.code()),
                    });
                }
                Ok(Reply::Malformed(raw)) => {
                    self.recover().await;
                    return Err(Sj210Error::Link {
                        command: command.to_string(),
                        source: LinkError::Malformed {
                            raw: escape_bytes(&raw),
                        },
                    });
                }
                Err(source) => {
                    if !matches!(source, LinkError::Vanished { .. } | LinkError::Encode(_)) {
                        self.recover().await;
                    }
                    return Err(Sj210Error::Link {
                        command: command.to_string(),
                        source,
                    });
                }
            }
        }
    }

    async fn read_code(
        &mut self,
        command: String,
        expected: &'static str,
    ) -> Result<u16, Sj210Error> {
        let payload = self.command(&command, true).await?;
        parse_code(&payload).ok_or(Sj210Error::UnexpectedReply {
            command,
            payload,
            expected,
        })
    }

    /// Operating status (`RDSTU00`).
    pub async fn status(&mut self) -> Result<u16, Sj210Error> {
        let c = self.table.commands.status.plain();
        self.read_code(c, "a 3-digit status").await
    }

    /// Battery state (`RDSTU01`).
    pub async fn battery(&mut self) -> Result<Battery, Sj210Error> {
        let c = self.table.commands.battery.plain();
        let code = self.read_code(c, "a 3-digit battery code").await?;
        let b = match code {
            0 => Battery::Good,
            1 => Battery::Low,
            2 => Battery::Abnormal,
            3 => Battery::Charging,
            other => Battery::Unknown(other),
        };
        self.battery = Some(b);
        Ok(b)
    }

    /// Measurement conditions (`RDCON`).
    pub async fn conditions(&mut self) -> Result<Conditions, Sj210Error> {
        let c = self.table.commands.conditions.plain();
        let payload = self.command(&c, true).await?;
        let cond = self.table.parse_conditions(&payload)?;
        self.conditions = Some(cond.clone());
        Ok(cond)
    }

    /// Number of customised parameters (`RDPAR`).
    pub async fn parameter_count(&mut self) -> Result<u32, Sj210Error> {
        let c = self.table.commands.param_count.plain();
        let payload = self.command(&c, true).await?;
        match payload.trim().parse::<u32>() {
            Ok(n) if n <= 99 => Ok(n),
            _ => Err(Sj210Error::UnexpectedReply {
                command: c,
                payload,
                expected: "a 2-digit parameter count",
            }),
        }
    }

    /// Capability probe, read-only except for `auto-sleep-off`: identity, battery,
    /// conditions, parameter count, profile read-out capability. Battery and read-out
    /// problems are reported in the result, not as errors.
    pub async fn probe_report(&mut self) -> Result<ProbeReport, Sj210Error> {
        let mut warnings = Vec::new();
        let fw_cmd = self.table.commands.firmware.plain();
        let firmware = self.command(&fw_cmd, true).await?.trim().to_string();
        let drive_cmd = self.table.commands.drive_type.plain();
        let drive = self
            .read_code(drive_cmd, "a 3-digit drive unit code")
            .await?;
        let identity = InstrumentIdentity {
            model: self.table.model.to_string(),
            firmware,
            drive_unit: format!("{drive:03} {}", self.table.drive_meaning(drive)),
        };
        let battery = self.battery().await?;
        match battery {
            Battery::Low => warnings.push(
                "battery below 60 %: connect the AC adapter for an unattended scan".to_string(),
            ),
            Battery::Abnormal => warnings.push(
                "battery abnormal (002): a scan will be refused until this is fixed".to_string(),
            ),
            Battery::Unknown(c) => warnings.push(format!("unknown battery code {c:03}")),
            Battery::Good | Battery::Charging => {}
        }
        let conditions = self.conditions().await?;
        let parameter_count = self.parameter_count().await?;
        let sleep_cmd = self.table.commands.auto_sleep_off.plain();
        match self.command(&sleep_cmd, false).await {
            Ok(_) => {}
            Err(e @ Sj210Error::Device { .. }) => warnings.push(format!(
                "auto-sleep could not be switched off ({e}); switch it off on the instrument for unattended runs"
            )),
            Err(e) => return Err(e),
        }
        let profile_readout = self.probe_profile_readout().await?;
        match self.pitch_um(&conditions) {
            Ok((p, source)) if source != "config" => warnings.push(format!(
                "x pitch {p} um assumed from {source}; set pitch-x-um when the instrument's pitch is known"
            )),
            Ok(_) => {}
            Err(_) => warnings.push("x pitch unknown: set pitch-x-um in [instrument]".to_string()),
        }
        Ok(ProbeReport {
            identity,
            battery,
            conditions,
            parameter_count,
            profile_readout,
            warnings,
        })
    }

    /// The safe read-out probe: the total-count request.
    async fn probe_profile_readout(&mut self) -> Result<ProfileReadout, Sj210Error> {
        let model = self.table.model;
        let Some(total) = self.table.commands.profile_total.clone() else {
            return Ok(ProfileReadout::Unsupported {
                ng_code: None,
                advice: format!(
                    "the {model} command table has no profile read-out command (the SJ-210 manual documents none). Options: use an SJ-310/SJ-410 (the SJ-410 manual documents RDEVA), or set profile-total and profile-block in [instrument.commands] once the right command is known"
                ),
            });
        };
        let cmd = total.plain();
        match self.command(&cmd, false).await {
            Ok(payload) => match leading_number(&payload) {
                Some(points_now) => Ok(ProfileReadout::Supported { points_now }),
                None => Err(Sj210Error::UnexpectedReply {
                    command: cmd,
                    payload,
                    expected: "a point count",
                }),
            },
            // The command is recognised, there is just no trace in memory yet (a fresh
            // instrument): the read-out works, with nothing to read now.
            Err(Sj210Error::Device {
                code: NgCode::NoResults,
                ..
            }) => Ok(ProfileReadout::Supported { points_now: 0 }),
            Err(Sj210Error::Device { code, .. }) if code.is_unsupported() => {
                Ok(ProfileReadout::Unsupported {
                    ng_code: Some(code.code()),
                    advice: format!(
                        "this firmware answered {code} ({}) to the profile total request {cmd:?}, so it cannot export profiles with this command. Options: use an SJ-310/SJ-410 (the SJ-410 manual documents RDEVA), or set profile-total and profile-block in [instrument.commands] once the right command is known",
                        self.table.error_meaning(code.code())
                    ),
                })
            }
            Err(e) => Err(e),
        }
    }

    /// Pitch in µm and where it came from.
    pub fn pitch_um(&self, c: &Conditions) -> Result<(f64, String), Sj210Error> {
        if let Some(p) = self.opts.pitch_x_um {
            return Ok((p, "config".to_string()));
        }
        let ls = c.lambda_s_um.ok_or(Sj210Error::PitchUnknown)?;
        let p = pitch_from_lambda_s(ls).ok_or(Sj210Error::PitchUnknown)?;
        Ok((p, format!("lambda-s {ls} um")))
    }

    /// Status must be idle; on `005` the detector is returned first, on `002` the return
    /// is awaited.
    pub async fn wait_idle(&mut self) -> Result<(), Sj210Error> {
        let deadline = Instant::now() + self.trace_deadline();
        let mut returned = false;
        loop {
            let s = self.status().await?;
            match s {
                status::IDLE => return Ok(()),
                status::INTERMEDIATE if !returned => {
                    let c = self.table.commands.return_to_start.plain();
                    self.command(&c, false).await?;
                    returned = true;
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
            sleep(self.opts.poll_interval).await;
        }
    }

    fn trace_deadline(&self) -> std::time::Duration {
        if let Some(d) = self.opts.trace_deadline {
            return d;
        }
        let c = self.conditions.clone().unwrap_or_default();
        // Traverse = evaluation length + pre/post travel (≈ λc); the SJ-210 drive range
        // (17.5 mm) when unknown. Speed 0.5 mm/s measuring, 1 mm/s returning unless known.
        let lc = c.lambda_c_mm.unwrap_or(2.5);
        let traverse = c.evaluation_length_mm.map(|l| l + lc).unwrap_or(17.5);
        let speed = c.speed_mm_s.filter(|s| *s > 0.0).unwrap_or(0.5);
        let secs = (traverse / speed + traverse / 1.0 + 10.0) * 2.0;
        std::time::Duration::from_secs_f64(secs.clamp(1.0, 3600.0))
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
        let started = Instant::now();
        let deadline = self.trace_deadline();
        let mut active = false;
        let mut link_failures = 0u32;
        loop {
            sleep(self.opts.poll_interval).await;
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
            match s {
                status::MEASURING | status::RETURNING => active = true,
                status::IDLE | status::INTERMEDIATE if active => return Ok(()),
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

    /// Reads every result parameter (`RDPAR`, then the result command for 01..=n).
    pub async fn read_results(
        &mut self,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<InstrumentResult>, Sj210Error> {
        let n = self.parameter_count().await?;
        let width = self.table.result_value_width;
        let mut out = Vec::with_capacity(n as usize);
        for aa in 1..=n {
            let cmd = self.table.commands.result.render(aa, 0, 0);
            match self.command(&cmd, true).await {
                Ok(payload) => out.push(parse_result(&cmd, &payload, width)?),
                // Calculation errors of one parameter: record it without a value.
                Err(Sj210Error::Device { code, meaning, .. })
                    if (102..=199).contains(&code.code()) =>
                {
                    warnings.push(format!("parameter {aa:02}: {code} ({meaning})"));
                    out.push(InstrumentResult {
                        name: format!("#{aa:02}"),
                        value: None,
                        unit: String::new(),
                    });
                }
                Err(e) => return Err(e),
            }
        }
        Ok(out)
    }

    /// Reads the profile once: total, then blocks; nothing else in between, no block retried.
    async fn read_profile_once(&mut self) -> Result<Vec<f64>, Sj210Error> {
        let (Some(total_c), Some(block_c)) = (
            self.table.commands.profile_total.clone(),
            self.table.commands.profile_block.clone(),
        ) else {
            return Err(Sj210Error::ProfileUnsupported {
                ng_code: None,
                advice: format!(
                    "the {} command table has no profile read-out command",
                    self.table.model
                ),
            });
        };
        let cmd = total_c.plain();
        let payload = self.command(&cmd, false).await?;
        let total = leading_number(&payload).ok_or(Sj210Error::UnexpectedReply {
            command: cmd,
            payload,
            expected: "a point count",
        })?;
        let mut heights = Vec::with_capacity(total as usize);
        while (heights.len() as u32) < total {
            let n = (total - heights.len() as u32).min(MAX_BLOCK);
            let cmd = block_c.render(0, 0, n);
            let payload = self.command(&cmd, false).await?;
            let values = parse_block(&payload).map_err(|what| Sj210Error::ProfileBlock {
                command: cmd.clone(),
                payload: payload.clone(),
                what,
            })?;
            if values.is_empty() {
                break;
            }
            if values.len() as u32 > n {
                return Err(Sj210Error::ProfileBlock {
                    command: cmd,
                    payload,
                    what: format!("{} values for a request of {n}", values.len()),
                });
            }
            heights.extend(values);
        }
        if heights.len() as u32 != total {
            return Err(Sj210Error::ProfileCountMismatch {
                announced: total,
                received: heights.len() as u32,
            });
        }
        Ok(heights)
    }

    /// Reads the profile; any failure restarts the whole read-out once from the total.
    pub async fn read_profile(
        &mut self,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<f64>, Sj210Error> {
        match self.read_profile_once().await {
            Ok(h) => Ok(h),
            Err(e @ Sj210Error::ProfileUnsupported { .. }) => Err(e),
            Err(
                e @ Sj210Error::Link {
                    source: LinkError::Vanished { .. },
                    ..
                },
            ) => Err(e),
            Err(first) => {
                tracing::warn!("profile read-out failed ({first}); restarting it from the total");
                warnings.push(format!("profile read-out restarted after: {first}"));
                self.read_profile_once()
                    .await
                    .map_err(|second| Sj210Error::ProfileReadoutFailed {
                        first: first.to_string(),
                        second: Box::new(second),
                    })
            }
        }
    }

    /// One complete line: trace, results, profile with pitch and conditions.
    pub async fn trace_line(&mut self) -> Result<TracedLine, Sj210Error> {
        if self.battery == Some(Battery::Abnormal) {
            return Err(Sj210Error::BatteryAbnormal);
        }
        // Read the conditions for every line: they are recorded with its profile, and an
        // operator may have changed them on the instrument since the probe.
        let before = self.conditions.clone();
        let conditions = self.conditions().await?;
        let mut warnings = Vec::new();
        if let Some(b) = before.filter(|b| b.raw != conditions.raw) {
            let w = format!(
                "measurement conditions changed on the instrument: {:?} -> {:?}",
                b.raw.unwrap_or_default(),
                conditions.raw.clone().unwrap_or_default()
            );
            tracing::warn!("{w}");
            warnings.push(w);
        }
        let (pitch_um, pitch_source) = self.pitch_um(&conditions)?;
        self.run_trace().await?;
        let results = self.read_results(&mut warnings).await?;
        let heights_um = self.read_profile(&mut warnings).await?;
        if let Some(l) = conditions.evaluation_length_mm {
            let covered = heights_um.len() as f64 * pitch_um / 1000.0;
            if l > 0.0 && ((covered - l) / l).abs() > 0.01 {
                let w = format!(
                    "{} points x {pitch_um} um = {covered:.4} mm differs from the evaluation length {l:.4} mm by more than 1 % (pitch from {pitch_source})",
                    heights_um.len()
                );
                tracing::warn!("{w}");
                warnings.push(w);
            }
        }
        let kind = conditions.profile_kind.unwrap_or_default();
        Ok(TracedLine {
            profile: Profile {
                pitch_x_mm: pitch_um / 1000.0,
                heights_um,
                kind,
                conditions,
            },
            results,
            pitch_source,
            warnings,
        })
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

impl<S: AsyncRead + AsyncWrite + Unpin> crate::devices::Instrument for Sj210Client<S> {
    type Error = Sj210Error;

    async fn probe(&mut self) -> Result<ProbeReport, Sj210Error> {
        let report = self.probe_report().await?;
        if report.battery == Battery::Abnormal {
            return Err(Sj210Error::BatteryAbnormal);
        }
        if let ProfileReadout::Unsupported { ng_code, advice } = &report.profile_readout {
            return Err(Sj210Error::ProfileUnsupported {
                ng_code: *ng_code,
                advice: advice.clone(),
            });
        }
        Ok(report)
    }

    async fn ensure_idle(&mut self) -> Result<(), Sj210Error> {
        self.wait_idle().await
    }

    async fn trace(&mut self) -> Result<TracedLine, Sj210Error> {
        self.trace_line().await
    }

    async fn abort(&mut self) -> Result<(), Sj210Error> {
        self.abort_measurement().await
    }
}

fn io_err(e: std::io::Error) -> LinkError {
    if crate::transport::is_vanished_io(&e) {
        LinkError::Vanished {
            detail: e.to_string(),
        }
    } else {
        LinkError::Io(e)
    }
}

fn millis(d: std::time::Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

/// The exported profile's x pitch in µm for a λs in µm (2.5 → 0.5, 8 → 1, 25 → 5), `None`
/// for any other λs. C3's mapping, confirmed for 2.5 µm by SJ-410 memory-card files (C4).
pub fn pitch_from_lambda_s(lambda_s_um: f64) -> Option<f64> {
    [(2.5, 0.5), (8.0, 1.0), (25.0, 5.0)]
        .into_iter()
        .find(|(ls, _)| (lambda_s_um - ls).abs() < 1e-9)
        .map(|(_, p)| p)
}

/// A 3-digit code payload.
fn parse_code(payload: &str) -> Option<u16> {
    let p = payload.trim();
    if p.len() == 3 && p.bytes().all(|b| b.is_ascii_digit()) {
        p.parse().ok()
    } else {
        None
    }
}

/// The first run of digits (C3 reads the `RDEVA` total this way).
fn leading_number(payload: &str) -> Option<u32> {
    let digits: String = payload
        .trim_start()
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

/// One `RDRES…02` payload: name (6), value (width), unit (3, right-justified).
pub fn parse_result(
    command: &str,
    payload: &str,
    width: usize,
) -> Result<InstrumentResult, Sj210Error> {
    let chars: Vec<char> = payload.chars().collect();
    let bad = || Sj210Error::UnexpectedReply {
        command: command.to_string(),
        payload: payload.to_string(),
        expected: "name (6) + value + unit (3)",
    };
    let name: String = chars.get(..6).ok_or_else(bad)?.iter().collect();
    let value: String = chars.get(6..6 + width).ok_or_else(bad)?.iter().collect();
    let unit: String = chars.get(6 + width..).unwrap_or(&[]).iter().collect();
    let name = name.trim().to_string();
    if name.is_empty() {
        return Err(bad());
    }
    Ok(InstrumentResult {
        name,
        value: value.trim().parse::<f64>().ok().filter(|v| v.is_finite()),
        unit: unit.trim().to_string(),
    })
}

/// One profile block: a value count, then that many heights in µm. Values may be
/// separated by `,`, `;` or spaces, or be fixed 9-character fields after a 2-digit count
/// (the manual's notation). `0.0` alone is the end-of-data marker (no values).
pub fn parse_block(payload: &str) -> Result<Vec<f64>, String> {
    let p = payload.trim();
    if p.is_empty() || p == "0.0" || p == "0" || p == "00" {
        return Ok(Vec::new());
    }
    let is_sep = |c: char| c == ',' || c == ';' || c.is_whitespace();
    let tokens: Vec<String> = if p.contains(is_sep) {
        p.split(is_sep)
            .filter(|t| !t.is_empty())
            .map(str::to_string)
            .collect()
    } else {
        let chars: Vec<char> = p.chars().collect();
        let mut t = vec![chars.iter().take(2).collect::<String>()];
        let rest = chars.get(2..).unwrap_or(&[]);
        if rest.len() % 9 != 0 {
            return Err(format!(
                "{} characters after the count is not a multiple of the 9-character field",
                rest.len()
            ));
        }
        t.extend(rest.chunks(9).map(|c| c.iter().collect::<String>()));
        t
    };
    let (count, values) = tokens.split_first().ok_or("empty block")?;
    let count: usize = count
        .parse()
        .map_err(|_| format!("count field {count:?} is not an integer"))?;
    let values = values
        .iter()
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("value {t:?} is not a number"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    if values.len() != count {
        return Err(format!(
            "count field says {count}, {} values follow",
            values.len()
        ));
    }
    Ok(values)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_formats() {
        assert_eq!(
            parse_block("03,-0.100,0.200,1.5").unwrap(),
            vec![-0.1, 0.2, 1.5]
        );
        assert_eq!(parse_block("02; +0.5; -0.25").unwrap(), vec![0.5, -0.25]);
        assert_eq!(
            parse_block("02   -0.1230    4.5000").unwrap(),
            vec![-0.123, 4.5]
        );
        assert!(parse_block("02 -0001.50+00002.25").is_err());
        assert_eq!(
            parse_block("02-0001.500+0002.250").unwrap(),
            vec![-1.5, 2.25]
        );
        assert!(parse_block("0.0").unwrap().is_empty());
        assert!(parse_block("03,1.0,2.0")
            .unwrap_err()
            .contains("count field says 3"));
        assert!(parse_block("02,1.0,x").unwrap_err().contains("\"x\""));
    }

    #[test]
    fn result_fields_by_width() {
        let r = parse_result("RDRES02,01,00", "Ra      3.123 \u{b5}m", 7).unwrap();
        assert_eq!(r.name, "Ra");
        assert_eq!(r.value, Some(3.123));
        assert_eq!(r.unit, "\u{b5}m");
        let r = parse_result("RDRES002,01,00", "Rz     12.3456 um", 8).unwrap();
        assert_eq!(
            (r.name.as_str(), r.value, r.unit.as_str()),
            ("Rz", Some(12.3456), "um")
        );
        let r = parse_result("RDRES02,02,00", "Rc    Err110 um", 7).unwrap();
        assert_eq!(r.value, None);
        assert!(parse_result("RDRES02,02,00", "Ra   1", 7).is_err());
    }

    #[test]
    fn codes_and_totals() {
        assert_eq!(parse_code("001"), Some(1));
        assert_eq!(parse_code("01"), None);
        assert_eq!(leading_number("08000"), Some(8000));
        assert_eq!(leading_number("x"), None);
    }
}
