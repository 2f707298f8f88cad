//! The fault policy as one table: what went wrong (the fault's kind) and where the scan
//! stands (the situation) decide the reaction, in one pure function, [`react`]. The session
//! machine ([`super::machine`]) asks it for every fault and carries the reaction out; the
//! texts people read are made apart from the decision ([`super::reasons`]). `docs/fault-policy.md`
//! is this table as an operator reads it, and the tests below assert it row by row.
//!
//! The rule behind the rows: a condition that can clear by itself suspends the scan and is
//! waited for; only a fault the operator must clear (or one that went on past the transient
//! budget while the device kept answering wrongly) ends it; and before a new scan exists, when
//! nothing has been acquired, a fault refuses the start instead of waiting.
//!
//! Also here: the [`Backoff`] of every wait the reactions call for.
//!
//! Layer 3 (session), pure: depends on [`crate::devices`]' fault classes and std.

use crate::devices::FaultClass;
use std::time::Duration;

/// Exponential backoff between reconnection tries, transient retries and storage checks:
/// the first wait, doubling up to `max`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    /// First wait.
    pub initial: Duration,
    /// Longest wait.
    pub max: Duration,
}

impl Backoff {
    /// The wait after `current` (zero before the first wait): `initial`, then doubling, at
    /// most `max`.
    pub fn next(&self, current: Duration) -> Duration {
        if current.is_zero() {
            self.initial
        } else {
            (current * 2).min(self.max)
        }
    }
}

/// What went wrong, as the policy tells faults apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// A device operation failed; the driver classed it.
    Device(FaultClass),
    /// A traced line that a trace again may fix (a height that is not a number, another
    /// point count than the scan's lines).
    LineRetryable,
    /// A traced line that cannot belong to the scan (another x pitch, conditions changed on
    /// the instrument).
    LineForeign,
    /// The fitter refused a committed line.
    FitterRefused,
    /// The file system refused a durable write.
    Storage(StorageClass),
    /// The outputs cannot be made from the lines on disk (the fit refused them), though no
    /// file system refused anything.
    OutputsImpossible,
}

/// How the file system refused a write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageClass {
    /// No space, or no inode, left (`ENOSPC`, `EDQUOT`): the free space and inodes are
    /// checked before the write is made again.
    Full,
    /// Any other refusal (`EPERM`, `EACCES`, `EROFS`, `EIO`: an immutable directory, a
    /// permission repaired later, a remount, a USB disk or NFS hiccup): the write is made
    /// again with backoff.
    Refused,
}

/// Where in its work the scan is when the fault happens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Opening and verifying a device.
    Opening,
    /// Creating the scan's directory and start record.
    Creating,
    /// Homing the stage.
    Homing,
    /// Making the instrument read idle.
    EnsuringIdle,
    /// Moving the stage to the line.
    Moving,
    /// Tracing and reading the line out.
    Tracing,
    /// Checking the traced line against the scan.
    Checking,
    /// Committing the traced line to disk.
    Committing,
    /// Pushing the committed line into the fitter.
    Pushing,
    /// Writing the surface, report and other outputs.
    Outputs,
}

/// The scan's situation, as far as the reaction depends on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Situation {
    /// The step the fault happened in.
    pub step: Step,
    /// The scan's directory and start record exist (a new scan being started has acquired
    /// nothing yet).
    pub created: bool,
    /// The transient budget of the current line is spent (this fault included).
    pub budget_spent: bool,
    /// Re-homes after a lost position already done on the current line.
    pub rehomes: u32,
    /// Re-homes allowed per line (`max-line-attempts` − 1).
    pub rehomes_allowed: u32,
}

/// What the scan does about a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reaction {
    /// Nothing is acquired yet: the scan does not start, and says why.
    Refuse,
    /// Suspended: the device is closed and reopened (at once after a fault in a line, then
    /// with backoff), with no time limit; the line is traced again and this costs no attempt.
    Reopen,
    /// Suspended: the line is tried again after a backoff wait, within the transient budget.
    Retry,
    /// The stage is re-homed, then the line is tried again.
    Rehome,
    /// Suspended: what is in memory is kept, the storage is checked with backoff and the
    /// write is made again when it can succeed; no time limit.
    WaitForStorage,
    /// The scan ends with a `fail` stop record (the rule that ended it named).
    Fail(FailRule),
}

/// Which rule ended a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailRule {
    /// A fault the operator must clear.
    Fatal,
    /// Transient faults went on past the budget.
    BudgetSpent,
    /// The stage lost its position more often than a line allows.
    RehomesSpent,
    /// The traced line cannot belong to the scan.
    LineRefused,
    /// The fitter refused a committed line.
    FitterRefused,
    /// The file system refused a write before the scan existed (a start refused).
    Storage,
    /// The outputs cannot be made from the lines on disk.
    Outputs,
}

/// The table: the reaction to a fault of `kind` in situation `s`.
pub fn react(kind: FaultKind, s: &Situation) -> Reaction {
    use FaultClass::*;
    use Reaction::*;
    use Step::*;
    if !s.created {
        // A new scan being started: nothing acquired, nothing to keep; the start is refused
        // and names the cause (a device missing is exit 69, the disk 74).
        return Refuse;
    }
    match (kind, s.step) {
        // A device that cannot be opened again while its scan exists: waited for.
        (FaultKind::Device(Absent | Silent | Transient), Opening) => Reopen,
        (FaultKind::Device(PositionLost | Fatal), Opening) => Fail(FailRule::Fatal),
        // A device gone or silent in a line: waited for without a time limit, whatever the
        // transient budget says (it bounds only a device that answers wrongly).
        (FaultKind::Device(Absent | Silent), _) => Reopen,
        (FaultKind::Device(Transient), _) | (FaultKind::LineRetryable, _) => {
            if s.budget_spent {
                Fail(FailRule::BudgetSpent)
            } else {
                Retry
            }
        }
        (FaultKind::Device(PositionLost), _) => {
            if s.rehomes < s.rehomes_allowed {
                Rehome
            } else {
                Fail(FailRule::RehomesSpent)
            }
        }
        (FaultKind::Device(Fatal), _) => Fail(FailRule::Fatal),
        (FaultKind::LineForeign, _) => Fail(FailRule::LineRefused),
        (FaultKind::FitterRefused, _) => Fail(FailRule::FitterRefused),
        // Every refusal of the file system, a full disk or not: what is in memory is kept,
        // and the write made again when it can succeed; no time limit.
        (FaultKind::Storage(_), _) => WaitForStorage,
        (FaultKind::OutputsImpossible, _) => Fail(FailRule::Outputs),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use FaultClass::*;
    use Reaction::*;
    use Step::*;

    fn at(step: Step) -> Situation {
        Situation {
            step,
            created: true,
            budget_spent: false,
            rehomes: 0,
            rehomes_allowed: 2,
        }
    }

    const LINE_STEPS: [Step; 4] = [Homing, EnsuringIdle, Moving, Tracing];

    #[test]
    fn backoff_doubles_up_to_its_limit() {
        let b = Backoff {
            initial: Duration::from_secs(1),
            max: Duration::from_secs(4),
        };
        let mut d = Duration::ZERO;
        let waits: Vec<u64> = (0..5)
            .map(|_| {
                d = b.next(d);
                d.as_secs()
            })
            .collect();
        assert_eq!(waits, vec![1, 2, 4, 4, 4]);
    }

    #[test]
    fn before_the_scan_exists_every_fault_refuses_the_start() {
        let kinds = [
            FaultKind::Device(Absent),
            FaultKind::Device(Silent),
            FaultKind::Device(Transient),
            FaultKind::Device(PositionLost),
            FaultKind::Device(Fatal),
            FaultKind::Storage(StorageClass::Full),
            FaultKind::Storage(StorageClass::Refused),
        ];
        for step in [Opening, Creating] {
            for k in kinds {
                let s = Situation {
                    created: false,
                    ..at(step)
                };
                assert_eq!(react(k, &s), Refuse, "{k:?} while {step:?}");
            }
        }
    }

    #[test]
    fn a_device_that_cannot_be_opened_again_is_waited_for_unless_it_needs_the_operator() {
        assert_eq!(react(FaultKind::Device(Absent), &at(Opening)), Reopen);
        assert_eq!(react(FaultKind::Device(Silent), &at(Opening)), Reopen);
        assert_eq!(react(FaultKind::Device(Transient), &at(Opening)), Reopen);
        assert_eq!(
            react(FaultKind::Device(Fatal), &at(Opening)),
            Fail(FailRule::Fatal)
        );
        assert_eq!(
            react(FaultKind::Device(PositionLost), &at(Opening)),
            Fail(FailRule::Fatal)
        );
    }

    #[test]
    fn device_faults_in_a_line_row_by_row() {
        for step in LINE_STEPS {
            let s = at(step);
            assert_eq!(react(FaultKind::Device(Absent), &s), Reopen, "{step:?}");
            assert_eq!(react(FaultKind::Device(Transient), &s), Retry, "{step:?}");
            assert_eq!(
                react(FaultKind::Device(PositionLost), &s),
                Rehome,
                "{step:?}"
            );
            assert_eq!(
                react(FaultKind::Device(Fatal), &s),
                Fail(FailRule::Fatal),
                "{step:?}"
            );
            let spent = Situation {
                budget_spent: true,
                ..s
            };
            assert_eq!(
                react(FaultKind::Device(Transient), &spent),
                Fail(FailRule::BudgetSpent),
                "{step:?}"
            );
            // A spent budget changes nothing for an absent or a silent device.
            assert_eq!(react(FaultKind::Device(Absent), &spent), Reopen, "{step:?}");
            assert_eq!(react(FaultKind::Device(Silent), &s), Reopen, "{step:?}");
            assert_eq!(react(FaultKind::Device(Silent), &spent), Reopen, "{step:?}");
            let rehomed = Situation { rehomes: 2, ..s };
            assert_eq!(
                react(FaultKind::Device(PositionLost), &rehomed),
                Fail(FailRule::RehomesSpent),
                "{step:?}"
            );
            let once = Situation { rehomes: 1, ..s };
            assert_eq!(
                react(FaultKind::Device(PositionLost), &once),
                Rehome,
                "{step:?}"
            );
        }
    }

    #[test]
    fn a_traced_line_that_does_not_fit_the_scan() {
        let s = at(Checking);
        assert_eq!(react(FaultKind::LineRetryable, &s), Retry);
        assert_eq!(
            react(
                FaultKind::LineRetryable,
                &Situation {
                    budget_spent: true,
                    ..s
                }
            ),
            Fail(FailRule::BudgetSpent)
        );
        assert_eq!(
            react(FaultKind::LineForeign, &s),
            Fail(FailRule::LineRefused)
        );
        assert_eq!(
            react(FaultKind::FitterRefused, &at(Pushing)),
            Fail(FailRule::FitterRefused)
        );
    }

    #[test]
    fn every_storage_failure_of_a_scan_is_waited_for_and_none_ends_it() {
        for step in [Committing, Outputs] {
            for class in [StorageClass::Full, StorageClass::Refused] {
                let spent = Situation {
                    budget_spent: true,
                    ..at(step)
                };
                assert_eq!(
                    react(FaultKind::Storage(class), &spent),
                    WaitForStorage,
                    "{class:?} while {step:?}"
                );
            }
        }
        assert_eq!(
            react(FaultKind::OutputsImpossible, &at(Outputs)),
            Fail(FailRule::Outputs)
        );
    }
}
