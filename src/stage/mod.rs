//! The y stage: GRBL and Zaber drivers behind a thin [`Stage`] trait, and the shared motion
//! policy ([`policy::MotionPolicy`]) that implements [`crate::devices::YAxis`] over any of them.
//!
//! - [`framer`]: bytes into text lines (pure).
//! - [`link`]: the line-reading loop both drivers share (I/O over any byte stream).
//! - [`grbl`], [`zaber`]: one directory per controller, its codec (`codec.rs`, pure) beside
//!   its driver (`mod.rs`, generic over `AsyncRead + AsyncWrite + Unpin`).
//! - [`policy`]: absolute targets, soft limits, backlash, settle, deadband, retries.
//! - [`ramp`]: how long a move takes (trapezoid), to poll again when it should be over.
//! - [`any`]: the policy over whichever driver the settings select, on a stream the caller
//!   opened (composition opens ports; nothing here does).
//! - [`settings`]: the `[stage]` section, validated into driver and policy configurations.
//! - [`error`]: every stage error and its fault class.
//! - [`sim`]: an in-process stage for the policy's unit tests.
//!
//! Layers 1–2. Depends on [`crate::devices`], [`crate::units`] and [`crate::transport`]'s
//! settings and error types; never opens a port.

pub mod any;
pub mod error;
pub mod framer;
pub mod grbl;
pub mod link;
pub mod policy;
pub mod ramp;
pub mod settings;
pub mod sim;
pub mod zaber;

use std::time::Duration;

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

/// What a controller says about itself when it is connected.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Identity {
    /// Model, firmware and build information, for the scan's record.
    pub text: String,
    /// The travel the controller itself enforces, device units (GRBL soft limits, Zaber
    /// `limit.min`/`limit.max`): a target outside it would be refused in the middle of a
    /// scan.
    pub travel_units: Option<(i64, i64)>,
    /// Facts the operator should know (a feed above the controller's maximum…).
    pub warnings: Vec<String>,
}

/// The device layer of a y stage: protocol facts only. Backlash, retries, settle time and
/// soft limits live in [`policy::MotionPolicy`].
#[allow(async_fn_in_trait)]
pub trait Stage {
    /// Identifies the controller, checks its settings against the driver's and reads its
    /// state; reports a reset seen at open.
    async fn identify(&mut self) -> Result<(Identity, StageStatus), StageError>;
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

pub use any::AnyYAxis;
pub use error::StageError;
pub use policy::{MotionPolicy, PolicyConfig, ScanDirection};
pub use settings::{StageProtocol, StageSettings};
