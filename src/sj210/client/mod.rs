//! The SJ-210 client over any byte stream. Implements [`crate::devices::Instrument`].
//!
//! One concern per file, all `impl` blocks of [`Sj210Client`]:
//! - `link.rs`: one command in flight, timeouts, recovery, bounded read retries;
//! - `reads.rs`: status, battery, conditions, parameter count, results;
//! - `probe.rs`: the capability probe;
//! - `trace.rs`: waiting for idle, one trace, abort;
//! - `readout.rs`: the profile read-out;
//! - `line.rs`: one complete line (trace, results, profile), read during the drive's return
//!   where the model table says the instrument answers then;
//! - `forms.rs`: the read-out probe that finds the read-out command.
//!
//! Reply payloads are read by the pure parsers in [`super::replies`], beside the codec.
//!
//! Layer 2 (I/O adapter): generic over `AsyncRead + AsyncWrite + Unpin`, so a serial port, a
//! pty or an in-memory pipe can stand in. Depends on the codec, the parsers, the model table
//! and the settings of [`super`], and on the vocabulary in [`crate::devices`] /
//! [`crate::profile`]. Time comes from `tokio::time`, so tests can pause it.

mod forms;
mod line;
mod link;
mod probe;
mod readout;
mod reads;
mod trace;

pub use readout::ReadoutPass;
pub use trace::{TraceEnd, TraceUntil};

use super::codec::Sj210Codec;
use super::error::{LinkError, Sj210Error};
use super::models::ModelTable;
use super::settings::ClientOptions;
use crate::devices::{Battery, ProbeReport, ProfileReadout, TracedLine};
use crate::profile::Conditions;
use bytes::BytesMut;
use tokio::io::{AsyncRead, AsyncWrite};

/// Most values one profile block request may ask for (M2: `01`–`50`).
pub const MAX_BLOCK: u32 = 50;

/// Status codes of `RDSTU00` (M1 p.17-16).
pub(super) mod status {
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
    /// Traces whose start command the instrument accepted.
    traces_started: u64,
    /// When the drive of the last trace is expected back at its start, once seen returning:
    /// the next wait for idle asks the status then.
    back_at: Option<tokio::time::Instant>,
    /// Commands and their mnemonics (`RDCON`, `RDSTU`, …) the instrument has answered `OK`
    /// on this link: a "command not understood" answer that contradicts them is a stray or
    /// late reply, not a model table that is wrong for the firmware.
    answered: std::collections::BTreeSet<String>,
    /// Whether any byte at all has come from the port on this link (a reply, a late one,
    /// noise): a link that has ever spoken is not a stage controller ignoring our lines.
    heard: bool,
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
            traces_started: 0,
            back_at: None,
            answered: std::collections::BTreeSet::new(),
            heard: false,
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
}

impl<S: AsyncRead + AsyncWrite + Unpin> crate::devices::Instrument for Sj210Client<S> {
    type Error = Sj210Error;

    async fn probe(&mut self) -> Result<ProbeReport, Sj210Error> {
        let report = match self.probe_report().await {
            Ok(r) => r,
            // Silent from the first command: a stage controller ignores the instrument's
            // lines (a Zaber answers only lines that begin with `/`). Asked in its own
            // language, it tells the ports are swapped. Only a link that never gave a
            // byte (neither the reply nor the recovery's status read) is asked: an
            // instrument that is merely late has spoken by then, and the question would only
            // leave it one more late reply (NG030) for the next command to take as its own.
            Err(Sj210Error::Link {
                command,
                source: first @ LinkError::FirstByteTimeout { .. },
            }) if self.answered.is_empty() && !self.heard => {
                let source = match self.stage_instead().await {
                    Some(raw) => LinkError::Malformed { raw },
                    None => first,
                };
                return Err(Sj210Error::Link { command, source });
            }
            Err(e) => return Err(e),
        };
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

    async fn read_again(&mut self) -> Result<Option<TracedLine>, Sj210Error> {
        self.read_held_line().await.map(Some)
    }

    fn traces_started(&self) -> Option<u64> {
        Some(self.traces_started)
    }
}

pub(super) fn io_err(e: std::io::Error) -> LinkError {
    if crate::transport::is_vanished_io(&e) {
        LinkError::Vanished {
            detail: e.to_string(),
        }
    } else {
        LinkError::Io(e)
    }
}

pub(super) fn millis(d: std::time::Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}
