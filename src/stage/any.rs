//! The motion policy over whichever driver the `[stage]` settings select, generic over the
//! byte stream: the composition (the station) opens the port and hands it in.
//!
//! Layer 2: depends on [`super::policy`], [`super::grbl`], [`super::zaber`] and
//! [`super::settings`].

use super::grbl::GrblStage;
use super::policy::{MotionPolicy, ScanDirection};
use super::settings::{StageProtocol, StageSettings};
use super::zaber::ZaberStage;
use super::StageError;
use crate::devices::{Arrival, StageReport, YAxis};
use crate::units::Nm;
use tokio::io::{AsyncRead, AsyncWrite};

/// A policy over whichever driver the settings select, on a stream of type `T`.
pub enum AnyYAxis<T> {
    /// GRBL / grblHAL.
    Grbl(MotionPolicy<GrblStage<T>>),
    /// Zaber ASCII.
    Zaber(MotionPolicy<ZaberStage<T>>),
}

impl<T: AsyncRead + AsyncWrite + Unpin> AnyYAxis<T> {
    /// The driver and policy the settings select, over an already opened stream (the
    /// caller opens the port; [`StageSettings::validate`] first, so a bad config is
    /// refused before any port is touched). The axis still needs [`YAxis::connect`].
    pub fn new(settings: &StageSettings, io: T) -> Result<Self, StageError> {
        let cfg = settings.policy_config()?;
        Ok(match settings.protocol {
            StageProtocol::Grbl => AnyYAxis::Grbl(MotionPolicy::new(
                GrblStage::new(io, settings.grbl_config()?),
                cfg,
            )),
            StageProtocol::Zaber => AnyYAxis::Zaber(MotionPolicy::new(
                ZaberStage::new(io, settings.zaber_config()),
                cfg,
            )),
        })
    }

    /// Sets the scan direction (from the sign of the plan's step).
    pub fn set_scan_direction(&mut self, d: ScanDirection) {
        match self {
            AnyYAxis::Grbl(p) => p.set_scan_direction(d),
            AnyYAxis::Zaber(p) => p.set_scan_direction(d),
        }
    }
}

impl<T: AsyncRead + AsyncWrite + Unpin> YAxis for AnyYAxis<T> {
    type Error = StageError;

    fn check_targets(&self, targets: &[Nm]) -> Result<Vec<String>, StageError> {
        match self {
            AnyYAxis::Grbl(p) => p.check_targets(targets),
            AnyYAxis::Zaber(p) => p.check_targets(targets),
        }
    }
    async fn connect(&mut self) -> Result<StageReport, StageError> {
        match self {
            AnyYAxis::Grbl(p) => p.connect().await,
            AnyYAxis::Zaber(p) => p.connect().await,
        }
    }
    fn position_trusted(&self) -> bool {
        match self {
            AnyYAxis::Grbl(p) => p.position_trusted(),
            AnyYAxis::Zaber(p) => p.position_trusted(),
        }
    }
    async fn home(&mut self) -> Result<(), StageError> {
        match self {
            AnyYAxis::Grbl(p) => p.home().await,
            AnyYAxis::Zaber(p) => p.home().await,
        }
    }
    async fn move_to(&mut self, target: Nm) -> Result<Arrival, StageError> {
        match self {
            AnyYAxis::Grbl(p) => p.move_to(target).await,
            AnyYAxis::Zaber(p) => p.move_to(target).await,
        }
    }
    async fn stop(&mut self) -> Result<(), StageError> {
        match self {
            AnyYAxis::Grbl(p) => p.stop().await,
            AnyYAxis::Zaber(p) => p.stop().await,
        }
    }
}
