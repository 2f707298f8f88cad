//! Errors of the SJ-210 driver, in two layers: the conversation failed ([`LinkError`]), or
//! the instrument answered with an NG code ([`Sj210Error::Device`]); plus the named failures
//! of a trace. Each carries the command that failed and says what to do.
//!
//! Layer 1: depends on [`super::codec`], [`super::models`], [`super::sampling`] and
//! [`crate::devices`].

use super::codec::{EncodeError, NgCode};
use super::models::ModelError;
use super::sampling::PointCountMismatch;
use crate::devices::{DeviceFault, FaultClass};
use thiserror::Error;

/// The conversation failed: nothing usable came back.
#[derive(Debug, Error)]
pub enum LinkError {
    /// No byte arrived after the command.
    #[error("no reply within {waited_ms} ms (check cable, baud and parity, and that the instrument is on and not asleep)")]
    FirstByteTimeout {
        /// How long it waited.
        waited_ms: u64,
    },
    /// The link did not take the command's bytes within the first-byte timeout: as silent as
    /// a device that answers nothing.
    #[error("{0}")]
    WriteStalled(crate::transport::SendError),
    /// The reply stopped before its CR.
    #[error("reply stalled after {partial:?} with no byte for {waited_ms} ms")]
    InterByteTimeout {
        /// Bytes received so far, escaped.
        partial: String,
        /// Inter-byte timeout.
        waited_ms: u64,
    },
    /// The reply was neither `OK…` nor `NGnnn[,bb]`, or was over-long.
    #[error("malformed reply {raw:?} ({})", crate::port_swap::instrument_port_hint(.raw))]
    Malformed {
        /// The raw bytes, escaped.
        raw: String,
    },
    /// The device went away (EOF, EIO, ENXIO).
    #[error("the device vanished: {detail}")]
    Vanished {
        /// What was observed.
        detail: String,
    },
    /// Another I/O error.
    #[error("I/O error: {0}")]
    Io(std::io::Error),
    /// The command could not be encoded.
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

/// Everything the SJ-210 driver can fail with.
#[derive(Debug, Error)]
pub enum Sj210Error {
    /// The conversation failed.
    #[error("{command:?}: {source}")]
    Link {
        /// Command that failed.
        command: String,
        /// What went wrong.
        source: LinkError,
    },
    /// The instrument answered NG.
    #[error("{command:?}: the instrument answered {code} ({meaning}){}", byte_pos.map(|p| format!(" at data byte {p}")).unwrap_or_default())]
    Device {
        /// Command that was refused.
        command: String,
        /// The NG code.
        code: NgCode,
        /// Position of the offending byte, when given.
        byte_pos: Option<u8>,
        /// Meaning from the model's error table.
        meaning: &'static str,
    },
    /// `OK` came back but the payload is not what the command returns.
    #[error("{command:?}: unexpected reply payload {payload:?}, expected {expected}. Check the configured model")]
    UnexpectedReply {
        /// Command.
        command: String,
        /// The payload.
        payload: String,
        /// What was expected.
        expected: &'static str,
    },
    /// The instrument is not idle when a trace or a stage move needs it to be.
    #[error("the instrument is not idle (status {status:03}: {meaning}); finish or return the detector on the instrument, then retry")]
    NotIdle {
        /// Status code.
        status: u16,
        /// Meaning.
        meaning: &'static str,
    },
    /// The status never reached "measuring" after the start command.
    #[error("stylus not on the workpiece: the status never reached 001 (measuring) within {waited_ms} ms after start (last status {last_status:03}). Check the part is under the stylus and the instrument shows its home screen")]
    StylusNotOnWorkpiece {
        /// How long it waited.
        waited_ms: u64,
        /// Last status read.
        last_status: u16,
    },
    /// Detector over-range (NG007) during the trace.
    #[error("detector over-range (NG007) during the trace; detector position {}. Check the part height and levelling, then re-trace", position.as_deref().unwrap_or("unreadable"))]
    OverRange {
        /// `RDPSA` reply, when it could be read.
        position: Option<String>,
    },
    /// The detector went to a retract state during the trace.
    #[error("the detector is retracting/retracted (status {status:03}) instead of tracing; return it to the start position and re-trace")]
    Retracted {
        /// Status code (003 or 004).
        status: u16,
    },
    /// The trace did not finish in time.
    #[error("the trace did not finish within {waited_ms} ms (last status {last_status:03}); check the instrument")]
    TraceDeadline {
        /// The deadline.
        waited_ms: u64,
        /// Last status read.
        last_status: u16,
    },
    /// Battery abnormal: the scan must not start.
    #[error("battery abnormal (RDSTU01 = 002: temperature, voltage or no battery); connect the AC adapter or replace the battery")]
    BatteryAbnormal,
    /// This firmware / model table cannot export profiles.
    #[error("profile read-out is not available: {advice}")]
    ProfileUnsupported {
        /// NG code the probe got, if any.
        ng_code: Option<u16>,
        /// The operator's options.
        advice: String,
    },
    /// The profile read-out delivered a different number of points than announced.
    #[error("profile read-out delivered {received} points but announced {announced}")]
    ProfileCountMismatch {
        /// Announced total.
        announced: u32,
        /// Points received.
        received: u32,
    },
    /// A profile block could not be read as numbers.
    #[error("{command:?}: profile block {payload:?} cannot be read: {what}")]
    ProfileBlock {
        /// Command.
        command: String,
        /// Payload.
        payload: String,
        /// What is wrong.
        what: String,
    },
    /// The read-out failed twice (first attempt and the restart); the line must be re-traced.
    #[error("profile read-out failed twice, the line must be re-traced: first {first}; restart {second}")]
    ProfileReadoutFailed {
        /// First failure.
        first: String,
        /// Failure of the restart.
        second: Box<Sj210Error>,
    },
    /// The profile's point count is not the one its conditions and pitch give.
    #[error("{mismatch} ({}; pitch from {pitch_source}): the x pitch or the conditions do not describe this profile, so the line was not kept. Set [instrument] pitch-x-um to the instrument's pitch; if this firmware's export is known to differ from N x floor(lambda-c / pitch), set [instrument] check-point-count = false", mismatch.expected)]
    PointCount {
        /// Expected and received counts with the rule's numbers.
        mismatch: PointCountMismatch,
        /// Where the pitch came from ("config", "lambda-s 8 um").
        pitch_source: String,
    },
    /// No pitch configured and no λs known.
    #[error("the x pitch is unknown: the conditions give no λs; set [instrument] pitch-x-um")]
    PitchUnknown,
    /// The conditions record could not be read.
    #[error(transparent)]
    Conditions(#[from] ModelError),
}

impl Sj210Error {
    /// The NG code when the instrument refused.
    pub fn code(&self) -> Option<NgCode> {
        match self {
            Sj210Error::Device { code, .. } => Some(*code),
            Sj210Error::ProfileReadoutFailed { second, .. } => second.code(),
            _ => None,
        }
    }
}

impl DeviceFault for Sj210Error {
    fn class(&self) -> FaultClass {
        match self {
            Sj210Error::Link { source, .. } => match source {
                LinkError::Vanished { .. } => FaultClass::Absent,
                LinkError::FirstByteTimeout { .. } | LinkError::WriteStalled(_) => {
                    FaultClass::Silent
                }
                LinkError::Encode(_) => FaultClass::Fatal,
                _ => FaultClass::Transient,
            },
            Sj210Error::Device { code, .. } => match code.code() {
                // Command not understood: the model table is wrong for this firmware.
                30..=32 => FaultClass::Fatal,
                // Flash/program/system errors, detector disconnected.
                14..=17 | 22 => FaultClass::Fatal,
                _ => FaultClass::Transient,
            },
            Sj210Error::ProfileReadoutFailed { second, .. } => match second.class() {
                c @ (FaultClass::Absent | FaultClass::Silent) => c,
                _ => FaultClass::Transient,
            },
            Sj210Error::UnexpectedReply { .. }
            | Sj210Error::StylusNotOnWorkpiece { .. }
            | Sj210Error::OverRange { .. }
            | Sj210Error::TraceDeadline { .. }
            | Sj210Error::ProfileCountMismatch { .. }
            | Sj210Error::ProfileBlock { .. }
            | Sj210Error::NotIdle { .. } => FaultClass::Transient,
            Sj210Error::Retracted { .. }
            | Sj210Error::BatteryAbnormal
            | Sj210Error::ProfileUnsupported { .. }
            | Sj210Error::PitchUnknown
            | Sj210Error::PointCount { .. }
            | Sj210Error::Conditions(_) => FaultClass::Fatal,
        }
    }

    fn ng_code(&self) -> Option<u16> {
        match self {
            Sj210Error::ProfileUnsupported { ng_code, .. } => *ng_code,
            Sj210Error::OverRange { .. } => Some(7),
            other => other.code().map(NgCode::code),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ng(code: u16) -> Sj210Error {
        Sj210Error::Device {
            command: "RDSTU00".into(),
            code: NgCode::from_code(code),
            byte_pos: None,
            meaning: "",
        }
    }

    #[test]
    fn classification_follows_what_the_runner_must_do() {
        assert_eq!(ng(11).class(), FaultClass::Transient);
        assert_eq!(ng(33).class(), FaultClass::Transient);
        assert_eq!(ng(30).class(), FaultClass::Fatal);
        assert_eq!(ng(22).class(), FaultClass::Fatal);
        assert_eq!(ng(30).ng_code(), Some(30));
        let vanished = Sj210Error::Link {
            command: "RDSTU00".into(),
            source: LinkError::Vanished {
                detail: "EIO".into(),
            },
        };
        assert_eq!(vanished.class(), FaultClass::Absent);
        let wrapped = Sj210Error::ProfileReadoutFailed {
            first: "x".into(),
            second: Box::new(ng(11)),
        };
        assert_eq!(wrapped.class(), FaultClass::Transient);
        assert_eq!(wrapped.ng_code(), Some(11));
        assert_eq!(Sj210Error::BatteryAbnormal.class(), FaultClass::Fatal);
    }

    #[test]
    fn messages_name_the_command_and_the_code() {
        let e = Sj210Error::Device {
            command: "RDEVA00".into(),
            code: NgCode::InvalidFormat,
            byte_pos: Some(5),
            meaning: "invalid command format",
        };
        let m = e.to_string();
        assert!(m.contains("\"RDEVA00\""), "{m}");
        assert!(m.contains("NG031"), "{m}");
        assert!(m.contains("data byte 5"), "{m}");
    }
}
