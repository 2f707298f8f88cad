//! The y stage: GRBL and Zaber drivers behind a thin [`Stage`] trait, and the shared motion
//! policy ([`policy::MotionPolicy`]) that implements [`crate::devices::YAxis`] over any of them.
//!
//! Layers 1–2: the codecs ([`line`], the message parsers in [`grbl`] and [`zaber`]) are pure;
//! drivers are generic over `AsyncRead + AsyncWrite + Unpin`. Depends on [`crate::devices`],
//! [`crate::units`] and [`crate::transport`] (only in [`connect`]).

pub mod grbl;
pub mod line;
pub mod policy;
pub mod settings;
pub mod sim;
pub mod zaber;

use crate::devices::{DeviceFault, FaultClass};
use crate::units::Nm;
use std::time::Duration;
use thiserror::Error;

/// What the axis is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// At rest and ready.
    Idle,
    /// Moving (jog, run, or Zaber BUSY).
    Moving,
    /// Homing.
    Homing,
    /// Locked in an alarm; needs a reset or unlock.
    Alarm,
}

/// One status reading, in device units (GRBL steps, Zaber microsteps).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StageStatus {
    /// Motion state.
    pub motion: Motion,
    /// Whether the controller's position can be trusted.
    pub position_trusted: bool,
    /// Position read back, device units.
    pub position_units: i64,
    /// Raw warnings for the log (Zaber notice flags, GRBL messages).
    pub warnings: Vec<String>,
}

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
    /// No answer in time.
    #[error("stage controller did not answer {waiting_for} within {timeout_ms} ms")]
    Timeout {
        /// What was awaited.
        waiting_for: String,
        /// The bound.
        timeout_ms: u64,
    },
    /// A line that the driver could not understand.
    #[error("unexpected reply from the stage controller: {line:?} ({why})")]
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
            StageError::Timeout { .. }
            | StageError::Protocol { .. }
            | StageError::Rejected { .. }
            | StageError::MissedTarget { .. } => FaultClass::Transient,
            StageError::ControllerLimit { .. }
            | StageError::SoftLimit { .. }
            | StageError::InexactTarget { .. }
            | StageError::Config(_) => FaultClass::Fatal,
            StageError::PositionLost { .. } => FaultClass::PositionLost,
            StageError::Fault { class, .. } => *class,
        }
    }

    fn ng_code(&self) -> Option<u16> {
        match self {
            StageError::Rejected { code, .. } | StageError::ControllerLimit { code, .. } => *code,
            _ => None,
        }
    }
}

/// The device layer of a y stage: protocol facts only. Backlash, retries, settle time and
/// soft limits live in [`policy::MotionPolicy`].
#[allow(async_fn_in_trait)]
pub trait Stage {
    /// Identifies the controller and reads its state; reports a reset seen at open.
    async fn identify(&mut self) -> Result<(String, StageStatus), StageError>;
    /// Reads the current status.
    async fn status(&mut self) -> Result<StageStatus, StageError>;
    /// Homes the axis and waits until it is done.
    async fn home(&mut self, timeout: Duration) -> Result<StageStatus, StageError>;
    /// Starts an absolute move; returns once the controller accepted it.
    async fn begin_move_abs(&mut self, target_units: i64) -> Result<(), StageError>;
    /// Waits until the axis is at rest, the device's way.
    async fn wait_done(&mut self, timeout: Duration) -> Result<StageStatus, StageError>;
    /// Stops motion (best effort).
    async fn stop(&mut self) -> Result<(), StageError>;
}

pub use policy::{connect, AnyYAxis, MotionPolicy, PolicyConfig, ScanDirection};
pub use settings::{StageProtocol, StageSettings};
