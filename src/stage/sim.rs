//! An in-process simulated stage implementing [`Stage`], for unit tests of the motion
//! policy: instant moves, a backlash dead band, and scripted faults.
//!
//! Depends only on the [`Stage`] trait; no I/O.

use super::{Identity, Motion, Stage, StageError, StageStatus};
use crate::devices::FaultClass;
use std::collections::VecDeque;
use std::time::Duration;

/// A fault the next move suffers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimFault {
    /// The move lands this many device units off.
    LandOff(i64),
    /// `begin_move_abs` fails with a timeout (the command may or may not have run).
    TransportTimeout,
    /// `wait_done` reports that the controller lost its position.
    PositionLost,
}

/// The simulated stage.
#[derive(Debug, Clone, Default)]
pub struct SimStage {
    /// Motor (reported) position, device units.
    pub motor_units: i64,
    /// Carriage (true) position, device units: lags the motor by up to `backlash_units`
    /// after a reversal (carriage ∈ [motor, motor + backlash]).
    pub carriage_units: i64,
    /// Backlash, device units.
    pub backlash_units: i64,
    /// Whether the position is referenced.
    pub referenced: bool,
    /// Every `begin_move_abs` target, in order.
    pub moves: Vec<i64>,
    /// Homing cycles run.
    pub homes: u32,
    /// Faults applied to the next moves, in order.
    pub faults: VecDeque<SimFault>,
    pending: Option<SimFault>,
}

impl SimStage {
    /// A stage at `units`, referenced, with the given backlash.
    pub fn new(units: i64, backlash_units: i64) -> Self {
        SimStage {
            motor_units: units,
            carriage_units: units,
            backlash_units,
            referenced: true,
            ..Default::default()
        }
    }

    fn set_motor(&mut self, m: i64) {
        self.motor_units = m;
        self.carriage_units = self.carriage_units.clamp(m, m + self.backlash_units);
    }

    fn st(&self) -> StageStatus {
        StageStatus {
            motion: Motion::Idle,
            position_trusted: self.referenced,
            position_units: self.motor_units,
            warnings: Vec::new(),
        }
    }
}

impl Stage for SimStage {
    async fn identify(&mut self) -> Result<(Identity, StageStatus), StageError> {
        let id = Identity {
            text: "sim stage".into(),
            ..Identity::default()
        };
        Ok((id, self.st()))
    }

    async fn status(&mut self) -> Result<StageStatus, StageError> {
        Ok(self.st())
    }

    async fn home(&mut self, _timeout: Duration) -> Result<StageStatus, StageError> {
        self.homes += 1;
        self.set_motor(-1000);
        self.set_motor(0);
        self.referenced = true;
        Ok(self.st())
    }

    async fn begin_move_abs(&mut self, target_units: i64) -> Result<(), StageError> {
        self.moves.push(target_units);
        match self.faults.pop_front() {
            Some(SimFault::TransportTimeout) => {
                return Err(StageError::Timeout {
                    waiting_for: "sim".into(),
                    timeout_ms: 0,
                })
            }
            Some(SimFault::LandOff(d)) => self.set_motor(target_units + d),
            Some(f @ SimFault::PositionLost) => {
                self.set_motor(target_units);
                self.pending = Some(f);
            }
            None => self.set_motor(target_units),
        }
        Ok(())
    }

    async fn wait_done(&mut self, _timeout: Duration) -> Result<StageStatus, StageError> {
        if self.pending.take() == Some(SimFault::PositionLost) {
            self.referenced = false;
            return Err(StageError::Fault {
                reason: "sim: position lost".into(),
                class: FaultClass::PositionLost,
            });
        }
        Ok(self.st())
    }

    async fn stop(&mut self) -> Result<(), StageError> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::{DeviceFault, YAxis};
    use crate::stage::{MotionPolicy, PolicyConfig, ScanDirection};
    use crate::units::Nm;

    /// 400 steps/mm: 2500 nm per unit, 0.01 mm = 4 units; backlash 0.05 mm = 20 units.
    fn cfg(dir: ScanDirection) -> PolicyConfig {
        PolicyConfig {
            nm_per_unit: 2500.0,
            min: Nm(-50_000_000),
            max: Nm(50_000_000),
            backlash: Nm(50_000),
            settle: Duration::ZERO,
            deadband: Nm(1000),
            max_attempts: 3,
            move_timeout: Duration::from_secs(1),
            home_timeout: Duration::from_secs(1),
            allow_inexact_step: false,
            direction: dir,
        }
    }

    async fn policy(dir: ScanDirection, start: i64) -> MotionPolicy<SimStage> {
        let mut p = MotionPolicy::new(SimStage::new(start, 20), cfg(dir));
        p.connect().await.unwrap();
        p
    }

    #[tokio::test]
    async fn backlash_taken_out_at_start_and_only_after_reversal() {
        let mut p = policy(ScanDirection::Positive, 1000).await;
        // First move: history unknown → approach from 20 units below.
        p.move_to(Nm(1_000_000)).await.unwrap(); // 400 units
        assert_eq!(p.stage().moves, vec![380, 400]);
        // Forward steps: one move each, no approach.
        p.move_to(Nm(1_010_000)).await.unwrap();
        p.move_to(Nm(1_020_000)).await.unwrap();
        assert_eq!(p.stage().moves, vec![380, 400, 404, 408]);
        assert_eq!(p.stage().carriage_units, 408);
        // Going back (resume): reverse → approach again.
        p.move_to(Nm(1_010_000)).await.unwrap();
        assert_eq!(p.stage().moves[4..], [384, 404]);
        assert_eq!(
            p.stage().carriage_units,
            404,
            "carriage lands on target after the approach"
        );
    }

    #[tokio::test]
    async fn connect_reports_an_unreferenced_stage_without_homing_it() {
        let mut s = SimStage::new(777, 0);
        s.referenced = false;
        let mut p = MotionPolicy::new(s, cfg(ScanDirection::Positive));
        let r = p.connect().await.unwrap();
        assert!(!r.position_trusted);
        assert_eq!(r.position, Nm(777 * 2500));
        assert_eq!(p.stage().homes, 0, "connecting must not home");
        assert!(matches!(
            p.move_to(Nm(0)).await,
            Err(StageError::PositionLost { .. })
        ));
        p.home().await.unwrap();
        assert_eq!(p.stage().homes, 1);
        assert!(p.position_trusted());
        assert_eq!(p.stage().motor_units, 0);
    }

    #[tokio::test]
    async fn negative_scan_direction_approaches_from_above() {
        let mut p = policy(ScanDirection::Negative, -4000).await;
        p.move_to(Nm(-10_000_000)).await.unwrap(); // -4000 units
        p.move_to(Nm(-10_010_000)).await.unwrap();
        assert_eq!(p.stage().moves, vec![-3980, -4000, -4004]);
    }

    #[tokio::test]
    async fn soft_limits_refused_before_any_move() {
        let mut p = policy(ScanDirection::Positive, 0).await;
        let e = p.move_to(Nm(50_010_000)).await.unwrap_err();
        assert!(matches!(
            e,
            StageError::SoftLimit {
                target: Nm(50_010_000),
                ..
            }
        ));
        // The approach point counts too: 0.03 mm above the lower limit is too close.
        let e = p.move_to(Nm(-49_970_000)).await.unwrap_err();
        assert!(matches!(
            e,
            StageError::SoftLimit {
                target: Nm(-50_020_000),
                ..
            }
        ));
        assert_eq!(e.class(), FaultClass::Fatal);
        assert!(p.stage().moves.is_empty());
    }

    #[tokio::test]
    async fn retries_then_missed_target_with_readback() {
        let mut p = policy(ScanDirection::Positive, 0).await;
        p.move_to(Nm(100_000)).await.unwrap(); // 40 units, direction now known
        p.stage_mut().faults.extend([SimFault::LandOff(-1)]);
        let a = p.move_to(Nm(110_000)).await.unwrap(); // 44 units, first lands on 43
        assert_eq!(a.attempts, 2);
        assert_eq!(a.readback, Nm(110_000));
        // Overshoot by 2 units every time: each retry is a reverse move, so it re-approaches
        // (approach + target = 2 moves); 1 + 2 + 2 faulty moves exhaust 3 attempts.
        p.stage_mut().faults.extend([SimFault::LandOff(2); 5]);
        let e = p.move_to(Nm(120_000)).await.unwrap_err(); // 48 units
        assert_eq!(
            p.stage().moves[p.stage().moves.len() - 5..],
            [48, 28, 48, 28, 48]
        );
        match e {
            StageError::MissedTarget {
                target,
                readback,
                attempts,
                ..
            } => {
                assert_eq!(target, Nm(120_000));
                assert_eq!(readback, Nm(125_000)); // 50 units × 2500 nm
                assert_eq!(attempts, 3);
            }
            other => panic!("{other}"),
        }
    }

    #[tokio::test]
    async fn transport_error_is_not_retried_and_position_loss_blocks_moves() {
        let mut p = policy(ScanDirection::Positive, 0).await;
        p.stage_mut().faults.push_back(SimFault::TransportTimeout);
        let e = p.move_to(Nm(100_000)).await.unwrap_err();
        assert_eq!(e.class(), FaultClass::Transient);
        assert_eq!(p.stage().moves.len(), 1, "the failed move was not re-sent");
        p.stage_mut().faults.push_back(SimFault::PositionLost);
        let e = p.move_to(Nm(100_000)).await.unwrap_err();
        assert_eq!(e.class(), FaultClass::PositionLost);
        assert!(!p.position_trusted());
        let n = p.stage().moves.len();
        let e = p.move_to(Nm(110_000)).await.unwrap_err();
        assert!(matches!(e, StageError::PositionLost { .. }));
        assert_eq!(p.stage().moves.len(), n, "no move on a guessed position");
        p.home().await.unwrap();
        assert!(p.move_to(Nm(110_000)).await.is_ok());
    }

    #[tokio::test]
    async fn inexact_steps_refused_with_their_rounding_error() {
        // 250 steps/mm: 4000 nm per step; 0.01 mm = 2.5 steps → 2000 nm rounding error.
        let mut c = cfg(ScanDirection::Positive);
        c.nm_per_unit = 4000.0;
        let p = MotionPolicy::new(SimStage::new(0, 0), c.clone());
        let targets: Vec<Nm> = (0..31).map(|k| Nm(k * 10_000)).collect();
        match p.check_targets(&targets) {
            Err(StageError::InexactTarget {
                target,
                units,
                error_nm,
            }) => {
                assert_eq!(target, Nm(10_000));
                assert_eq!(units, 2.5);
                assert_eq!(error_nm.abs(), 2000.0);
            }
            other => panic!("{other:?}"),
        }
        c.allow_inexact_step = true;
        let p = MotionPolicy::new(SimStage::new(0, 0), c);
        assert_eq!(p.check_targets(&targets).unwrap().len(), 1);
        // Allowed: moving to 0.01 mm lands on 3 steps (2.5 rounded half away from zero) =
        // 12 000 nm, and that is an arrival, not a miss.
        let mut c = cfg(ScanDirection::Positive);
        c.nm_per_unit = 4000.0;
        c.allow_inexact_step = true;
        let mut p = MotionPolicy::new(SimStage::new(0, 0), c);
        p.connect().await.unwrap();
        let a = p.move_to(Nm(10_000)).await.unwrap();
        assert_eq!((a.readback, a.attempts), (Nm(12_000), 1));
        // 400 steps/mm: exact, no warning.
        let p = MotionPolicy::new(SimStage::new(0, 0), cfg(ScanDirection::Positive));
        assert!(p.check_targets(&targets).unwrap().is_empty());
    }
}
