//! Every stage error, from the codecs up to the motion policy, and how the scan reacts to
//! each ([`crate::devices::DeviceFault`]).
//!
//! Layer 1: depends on [`crate::devices`], [`crate::units`] and [`crate::transport`]'s error
//! type (no I/O).

use crate::devices::{DeviceFault, FaultClass};
use crate::units::Nm;
use thiserror::Error;

/// Every stage error, from the codecs up to the policy.
#[derive(Debug, Error)]
pub enum StageError {
    /// I/O failure or end of stream: the controller is gone.
    #[error(
        "stage controller vanished: {detail}; check the cable and power, the scan will reconnect"
    )]
    Vanished {
        /// What was observed.
        detail: String,
    },
    /// The port could not be opened.
    #[error(transparent)]
    Transport(#[from] crate::transport::TransportError),
    /// The link did not take a command's bytes in time (flow control, a wedged adapter).
    #[error("stage controller link: {0}")]
    Stalled(crate::transport::SendError),
    /// Nothing came back in time: the controller is silent.
    #[error("stage controller did not answer {waiting_for} within {timeout_ms} ms (check its power and cable; the scan waits for it)")]
    NoReply {
        /// What was awaited.
        waiting_for: String,
        /// The bound.
        timeout_ms: u64,
    },
    /// The controller answers, but a motion did not end in time.
    #[error("stage controller did not report {waiting_for} within {timeout_ms} ms")]
    Timeout {
        /// What was awaited.
        waiting_for: String,
        /// The bound.
        timeout_ms: u64,
    },
    /// A line that the driver could not understand.
    #[error("unexpected reply from the stage controller: {line:?} ({why}){}", swapped_note(.line))]
    Protocol {
        /// The offending line.
        line: String,
        /// What was expected.
        why: String,
    },
    /// The controller refused a command.
    #[error("stage controller rejected {command:?}: {reason}")]
    Rejected {
        /// The command sent.
        command: String,
        /// The controller's reason (error code, RJ reason).
        reason: String,
        /// The controller's numeric error code (GRBL `error:N`), when it gave one.
        code: Option<u16>,
    },
    /// The controller refused a move beyond its own travel limits.
    #[error("stage controller refused {command:?} as beyond its travel ({reason}); check soft-limit-min-mm/max-mm against the controller's travel settings")]
    ControllerLimit {
        /// The command sent.
        command: String,
        /// The controller's reason.
        reason: String,
        /// The controller's numeric error code (GRBL `error:N`), when it gave one.
        code: Option<u16>,
    },
    /// A target outside the configured soft limits; nothing was sent.
    #[error("target {target} is outside the stage soft limits [{min}, {max}]; nothing was sent. Change y-start/step/lines or the limits")]
    SoftLimit {
        /// The refused position.
        target: Nm,
        /// Lower limit.
        min: Nm,
        /// Upper limit.
        max: Nm,
    },
    /// A target outside the travel the controller itself enforces (GRBL soft limits, Zaber
    /// `limit.min`/`limit.max`): it would be refused in the middle of the scan, so the plan
    /// is refused before anything moves.
    #[error("target {target} is outside the travel the stage controller enforces [{min}, {max}]; nothing was sent. Change y-start/step/lines, or the controller's travel (GRBL: $131 with soft limits $20=1 give machine space [-$131, 0], or [0, $131] for a Y axis homing toward negative ($23) on a firmware built with HOMING_FORCE_SET_ORIGIN; Zaber: limit.min, limit.max)")]
    OutsideControllerTravel {
        /// The refused position.
        target: Nm,
        /// Lower end of the controller's travel.
        min: Nm,
        /// Upper end of the controller's travel.
        max: Nm,
    },
    /// The controller is set up differently from what the driver is configured for (steps
    /// per mm, report units, homing disabled…).
    #[error("stage controller settings do not fit: {0}")]
    ControllerSetup(String),
    /// A step that the device cannot represent exactly.
    #[error("target {target} is {units:.4} device units; rounding moves it by {error_nm:.1} nm. Choose a step that is a whole number of device units, or set stage.allow-inexact-step = true")]
    InexactTarget {
        /// The target.
        target: Nm,
        /// Its exact value in device units.
        units: f64,
        /// The rounding error it would cause, nm.
        error_nm: f64,
    },
    /// The controller's position can no longer be trusted.
    #[error("stage position lost ({reason}); the axis must be re-homed before it moves again")]
    PositionLost {
        /// What happened (banner, ALARM:1, WR flag…).
        reason: String,
    },
    /// The controller reported a fault.
    #[error("stage fault: {reason}")]
    Fault {
        /// The flag or alarm and its meaning.
        reason: String,
        /// How the scan should react.
        class: FaultClass,
    },
    /// The axis did not land within the deadband after the allowed attempts.
    #[error("missed target {target}: read back {readback} after {attempts} attempts (deadband {deadband_nm} nm); check for stalls, load or loose couplings")]
    MissedTarget {
        /// The absolute target.
        target: Nm,
        /// The last readback.
        readback: Nm,
        /// Moves issued.
        attempts: u32,
        /// The deadband, nm.
        deadband_nm: i64,
    },
    /// The settings are unusable.
    #[error("invalid stage settings: {0}")]
    Config(String),
}

impl DeviceFault for StageError {
    fn class(&self) -> FaultClass {
        match self {
            StageError::Vanished { .. } => FaultClass::Absent,
            StageError::Transport(t) if t.is_absent() => FaultClass::Absent,
            StageError::Transport(_) => FaultClass::Fatal,
            StageError::NoReply { .. } | StageError::Stalled(_) => FaultClass::Silent,
            StageError::Timeout { .. }
            | StageError::Protocol { .. }
            | StageError::Rejected { .. }
            | StageError::MissedTarget { .. } => FaultClass::Transient,
            StageError::ControllerLimit { .. }
            | StageError::SoftLimit { .. }
            | StageError::InexactTarget { .. }
            | StageError::OutsideControllerTravel { .. }
            | StageError::ControllerSetup(_)
            | StageError::Config(_) => FaultClass::Fatal,
            StageError::PositionLost { .. } => FaultClass::PositionLost,
            StageError::Fault { class, .. } => *class,
        }
    }

    // No `ng_code`: NG codes are the SJ-210's; a controller's own code (GRBL `error:15`) is
    // in the message, and labelled NG it read as the instrument's battery or system code.
}

/// `; ` and the swapped-ports hint when a line the stage's driver cannot read is the
/// instrument's (`OK000`, `NG011`).
fn swapped_note(line: &str) -> String {
    match crate::port_swap::stage_port_hint(line) {
        "" => String::new(),
        hint => format!("; {hint}"),
    }
}
