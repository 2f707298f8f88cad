//! The motion policy shared by every stage driver: absolute targets in integer nm rounded to
//! device units once, host-side soft limits, unidirectional backlash approach, settle, read
//! back, deadband, bounded retries, "missed target", position-lost handling. Implements
//! [`crate::devices::YAxis`].
//!
//! Layer 2: generic over any [`super::Stage`]; depends on [`crate::devices`] and
//! [`crate::units`]. It knows no protocol, no settings file and no port.

use super::{Stage, StageError};
use crate::devices::{Arrival, DeviceFault, FaultClass, StageReport, YAxis};
use crate::units::Nm;
use std::time::Duration;

/// The direction the scan moves in; backlash is taken out by approaching from the
/// opposite side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScanDirection {
    /// Targets increase (step > 0).
    Positive,
    /// Targets decrease (step < 0).
    Negative,
}

impl ScanDirection {
    /// +1 or −1.
    pub fn sign(self) -> i64 {
        match self {
            ScanDirection::Positive => 1,
            ScanDirection::Negative => -1,
        }
    }

    /// The direction of a step (zero counts as positive).
    pub fn of_step(step: Nm) -> Self {
        if step.0 < 0 {
            ScanDirection::Negative
        } else {
            ScanDirection::Positive
        }
    }
}

/// The policy's parameters (built from [`super::StageSettings::policy_config`]).
#[derive(Debug, Clone)]
pub struct PolicyConfig {
    /// One device unit in nm.
    pub nm_per_unit: f64,
    /// Lowest allowed position.
    pub min: Nm,
    /// Highest allowed position.
    pub max: Nm,
    /// Pre-approach distance (0 = none).
    pub backlash: Nm,
    /// Settle time after the controller reports done.
    pub settle: Duration,
    /// Retry deadband.
    pub deadband: Nm,
    /// Moves per target before "missed target".
    pub max_attempts: u32,
    /// Bound on one move.
    pub move_timeout: Duration,
    /// Bound on homing.
    pub home_timeout: Duration,
    /// Accept inexact targets with a warning.
    pub allow_inexact_step: bool,
    /// Scan direction.
    pub direction: ScanDirection,
}

/// Rounding error below which a target counts as exactly representable, nm.
const EXACT_NM: f64 = 1e-3;

/// The target among `targets` that a stage whose device unit is `nm_per_unit` nm reaches
/// least exactly, with its exact value in device units and the rounding error in nm; `None`
/// when every target is a whole number of device units. The same rule decides at
/// `check-config` (from the configured plan) and when the stage connects.
pub fn worst_inexact(
    targets: impl IntoIterator<Item = Nm>,
    nm_per_unit: f64,
) -> Option<(Nm, f64, f64)> {
    let mut worst: Option<(Nm, f64, f64)> = None;
    for t in targets {
        let exact = t.0 as f64 / nm_per_unit;
        let err = (exact.round() - exact) * nm_per_unit;
        if err.abs() > EXACT_NM && worst.is_none_or(|w| err.abs() > w.2.abs()) {
            worst = Some((t, exact, err));
        }
    }
    worst
}

/// The policy over one driver.
pub struct MotionPolicy<S> {
    stage: S,
    cfg: PolicyConfig,
    trusted: bool,
    /// Direction of the last completed move (+1/−1); `None` when unknown.
    last_dir: Option<i64>,
    /// Last position read back, device units.
    position_units: Option<i64>,
    /// The travel the controller enforces itself, when it said (from `connect`).
    controller_travel: Option<(Nm, Nm)>,
}

impl<S: Stage> MotionPolicy<S> {
    /// Wraps a driver. The position is untrusted until `connect` says otherwise.
    pub fn new(stage: S, cfg: PolicyConfig) -> Self {
        MotionPolicy {
            stage,
            cfg,
            trusted: false,
            last_dir: None,
            position_units: None,
            controller_travel: None,
        }
    }

    /// Sets the scan direction (from the sign of the plan's step).
    pub fn set_scan_direction(&mut self, d: ScanDirection) {
        self.cfg.direction = d;
    }

    /// The driver, for inspection.
    pub fn stage(&self) -> &S {
        &self.stage
    }

    /// The driver, mutably.
    pub fn stage_mut(&mut self) -> &mut S {
        &mut self.stage
    }

    /// Exact device units of a position, rounded, and the rounding error in nm.
    pub fn to_units(&self, p: Nm) -> (i64, f64, f64) {
        let exact = p.0 as f64 / self.cfg.nm_per_unit;
        let r = exact.round();
        (r as i64, exact, (r - exact) * self.cfg.nm_per_unit)
    }

    /// Device units to nm (rounded to the nearest nm).
    pub fn to_nm(&self, units: i64) -> Nm {
        Nm((units as f64 * self.cfg.nm_per_unit).round() as i64)
    }

    fn approach_point(&self, target: Nm) -> Nm {
        Nm(target.0 - self.cfg.direction.sign() * self.cfg.backlash.0)
    }

    fn check_limits(&self, target: Nm) -> Result<(), StageError> {
        for p in [target, self.approach_point(target)] {
            if p < self.cfg.min || p > self.cfg.max {
                return Err(StageError::SoftLimit {
                    target: p,
                    min: self.cfg.min,
                    max: self.cfg.max,
                });
            }
            if let Some((min, max)) = self.controller_travel {
                if p < min || p > max {
                    return Err(StageError::OutsideControllerTravel {
                        target: p,
                        min,
                        max,
                    });
                }
            }
        }
        Ok(())
    }

    /// After a failed command: position loss untrusts the axis; other failures make the
    /// history unknown and the state is re-read (the motion is not retried).
    async fn after_error(&mut self, e: StageError) -> StageError {
        self.last_dir = None;
        match e.class() {
            FaultClass::PositionLost => self.trusted = false,
            FaultClass::Transient => match self.stage.status().await {
                Ok(st) => {
                    self.position_units = Some(st.position_units);
                    if !st.position_trusted {
                        self.trusted = false;
                    }
                }
                Err(e2) => {
                    tracing::warn!(error = %e2, "re-reading stage state after a failed move also failed");
                    self.position_units = None;
                }
            },
            _ => self.position_units = None,
        }
        e
    }

    /// One move to device units, waiting until done and recording its direction.
    async fn raw_move(&mut self, units: i64) -> Result<(), StageError> {
        let from = self.position_units;
        if let Err(e) = self.stage.begin_move_abs(units).await {
            return Err(self.after_error(e).await);
        }
        let st = match self.stage.wait_done(self.cfg.move_timeout).await {
            Ok(st) => st,
            Err(e) => return Err(self.after_error(e).await),
        };
        if !st.position_trusted {
            self.trusted = false;
        }
        self.last_dir = match from {
            Some(f) if units != f => Some((units - f).signum()),
            Some(_) => self.last_dir,
            None => None,
        };
        self.position_units = Some(st.position_units);
        Ok(())
    }
}

impl<S: Stage> YAxis for MotionPolicy<S> {
    type Error = StageError;

    fn check_targets(&self, targets: &[Nm]) -> Result<Vec<String>, StageError> {
        for &t in targets {
            self.check_limits(t)?;
        }
        match worst_inexact(targets.iter().copied(), self.cfg.nm_per_unit) {
            None => Ok(Vec::new()),
            Some((target, units, error_nm)) if !self.cfg.allow_inexact_step => {
                Err(StageError::InexactTarget {
                    target,
                    units,
                    error_nm,
                })
            }
            Some((target, units, error_nm)) => {
                let w = format!(
                    "inexact stage targets allowed by allow-inexact-step: e.g. {target} is {units:.4} device units, rounded by {error_nm:.1} nm"
                );
                tracing::warn!("{w}");
                Ok(vec![w])
            }
        }
    }

    async fn connect(&mut self) -> Result<StageReport, StageError> {
        let (identity, st) = self.stage.identify().await?;
        for w in identity.warnings.iter().chain(&st.warnings) {
            tracing::warn!(warning = %w, "stage at connect");
        }
        self.controller_travel = identity
            .travel_units
            .map(|(lo, hi)| (self.to_nm(lo), self.to_nm(hi)));
        if let Some((min, max)) = self.controller_travel {
            if self.cfg.min < min || self.cfg.max > max {
                tracing::warn!(
                    "stage soft limits [{}, {}] reach beyond the controller's own travel [{min}, {max}]; targets outside it are refused",
                    self.cfg.min,
                    self.cfg.max
                );
            }
        }
        self.trusted = st.position_trusted;
        self.position_units = Some(st.position_units);
        self.last_dir = None;
        // Connecting never homes: whoever drives the scan decides when (once at start with
        // home-on-start, or because the position is not trusted), so a cycle is never run
        // twice in a row.
        Ok(StageReport {
            identity: identity.text,
            position_trusted: self.trusted,
            position: self.to_nm(self.position_units.unwrap_or(st.position_units)),
        })
    }

    fn position_trusted(&self) -> bool {
        self.trusted
    }

    async fn home(&mut self) -> Result<(), StageError> {
        self.last_dir = None;
        match self.stage.home(self.cfg.home_timeout).await {
            Ok(st) => {
                self.trusted = st.position_trusted;
                self.position_units = Some(st.position_units);
                if !self.trusted {
                    return Err(StageError::PositionLost {
                        reason:
                            "the controller still reports an unreferenced position after homing"
                                .into(),
                    });
                }
                Ok(())
            }
            Err(e) => {
                self.trusted = false;
                self.position_units = None;
                Err(e)
            }
        }
    }

    async fn move_to(&mut self, target: Nm) -> Result<Arrival, StageError> {
        if !self.trusted {
            return Err(StageError::PositionLost {
                reason: "position not trusted (reset, alarm or not referenced); refusing to move"
                    .into(),
            });
        }
        self.check_limits(target)?;
        let dir = self.cfg.direction.sign();
        let (tu, _, _) = self.to_units(target);
        let (au, _, _) = self.to_units(self.approach_point(target));
        let backlash = self.cfg.backlash.0 > 0;
        let mut readback = self.position_units.map(|u| self.to_nm(u));
        for attempt in 1..=self.cfg.max_attempts {
            let reverse = self.position_units.is_none_or(|p| (tu - p) * dir < 0);
            let need_approach = backlash && (self.last_dir != Some(dir) || reverse);
            if need_approach {
                self.raw_move(au).await?;
            }
            if need_approach || self.position_units != Some(tu) {
                self.raw_move(tu).await?;
            }
            if !self.trusted {
                return Err(StageError::PositionLost {
                    reason: "the controller reported an unreferenced position after a move".into(),
                });
            }
            tokio::time::sleep(self.cfg.settle).await;
            let st = match self.stage.status().await {
                Ok(st) => st,
                Err(e) => return Err(self.after_error(e).await),
            };
            self.position_units = Some(st.position_units);
            let rb = self.to_nm(st.position_units);
            readback = Some(rb);
            // Compare with the target as the device can represent it: an inexact target
            // (allowed and recorded by `check_targets`) must not count as a miss.
            if (rb.0 - self.to_nm(tu).0).abs() <= self.cfg.deadband.0 {
                return Ok(Arrival {
                    target,
                    readback: rb,
                    attempts: attempt,
                });
            }
            tracing::warn!(%target, readback = %rb, attempt, "stage outside the deadband");
        }
        Err(StageError::MissedTarget {
            target,
            readback: readback.unwrap_or(Nm(i64::MIN)),
            attempts: self.cfg.max_attempts,
            deadband_nm: self.cfg.deadband.0,
        })
    }

    async fn stop(&mut self) -> Result<(), StageError> {
        self.last_dir = None;
        self.stage.stop().await
    }
}
