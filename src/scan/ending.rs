//! How a scan ended — the one value ([`End`]) from which the journal's stop record, the
//! status's last stop, the notification hook's event and a command's exit status are
//! derived; and the word for it ([`StopStatus`]) as the journal and the status spell it.
//!
//! Layer 3 (session), pure: depends on the session's command (who aborted), event and status
//! vocabulary, [`super::line_check`]'s line problems and [`crate::devices`]' faults.

use super::command::Peer;
use super::event::ScanEventKind;
use super::line_check::LineProblem;
use super::reasons::stamp;
use crate::devices::{Fault, FaultClass};
use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};
use std::fmt;

/// How a scan ended, as its journal's stop record and the status's last stop spell it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StopStatus {
    /// All lines traced, fit and IGES written.
    Success,
    /// Aborted by the operator.
    Abort,
    /// Ended by a fault the operator must clear (`--resume` continues it).
    Fail,
    /// Left unfinished and given up for a new scan (`--new`).
    Abandoned,
    /// Shut down (SIGTERM) before it started, or mid-scan: it resumes at the next start.
    /// Never a stop record (a shut-down scan has none); the status's word for it.
    Interrupted,
}

impl StopStatus {
    /// `success`, `abort`, `fail`, `abandoned` or `interrupted`.
    pub fn as_str(self) -> &'static str {
        match self {
            StopStatus::Success => "success",
            StopStatus::Abort => "abort",
            StopStatus::Fail => "fail",
            StopStatus::Abandoned => "abandoned",
            StopStatus::Interrupted => "interrupted",
        }
    }
}

impl fmt::Display for StopStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Why a scan failed: what the operator must clear before continuing it.
#[derive(Debug, Clone, PartialEq)]
pub enum FailReason {
    /// A device could not be opened or verified when a new scan was to start.
    NotStarted(Fault),
    /// A fault the operator must fix.
    Fatal {
        /// The line being worked on (0-based), if any.
        line: Option<u32>,
        /// The fault.
        fault: Fault,
    },
    /// Transient faults went on for longer than the budget.
    BudgetExhausted {
        /// The line (0-based).
        line: u32,
        /// The budget, seconds.
        budget_s: u64,
        /// When the first fault of the run happened.
        since: DateTime<Utc>,
        /// Traces started for the line in that time.
        traces: u32,
        /// The last fault.
        last: String,
    },
    /// The stage lost its position again and again on one line.
    PositionLostRepeatedly {
        /// The line (0-based).
        line: u32,
        /// How often.
        times: u32,
        /// The last fault.
        last: Fault,
    },
    /// The traced line cannot belong to this scan.
    LineRefused {
        /// The line (0-based).
        line: u32,
        /// Why.
        problem: LineProblem,
    },
    /// The fitter refused a committed line.
    FitterRefused {
        /// The line (0-based).
        line: u32,
        /// The fitter's message.
        message: String,
    },
    /// The disk refused for a reason that does not clear by itself (permissions,
    /// read-only file system, damage).
    Storage(String),
    /// Every line is on disk but the outputs could not be made (the message says how to
    /// make them by hand).
    Outputs(String),
    /// Every line is on disk but the outputs were not made because of a bug: making them
    /// panicked (an internal error). The message says what panicked, that the lines are safe,
    /// that it is to be reported with the scan's directory, and how to make the outputs by
    /// hand.
    OutputsInternal(String),
    /// The scan could not be begun or reopened, or its end not recorded: the message says
    /// why. A reopening that panicked (kind [`FailKind::Internal`]) is the scan's ending by a
    /// bug, and one refused for the scan's own files the operator's, each recorded as such;
    /// one the file system refused (kind [`FailKind::Io`]: reopening, or recording such an
    /// ending) records nothing.
    Refused {
        /// Why.
        message: String,
        /// The exit class.
        kind: FailKind,
    },
}

impl FailReason {
    /// What may continue the scan. An internal error is the operator's: only their
    /// `--resume` makes the outputs again, never a plain start or the daemon by itself (the
    /// same bug would panic again).
    pub fn cause(&self) -> FailCause {
        match self {
            FailReason::BudgetExhausted { .. } => FailCause::Budget,
            FailReason::Storage(_) => FailCause::Storage,
            _ => FailCause::Operator,
        }
    }

    /// True when a bug, not the devices, the disk or the lines, ended the scan (the stop
    /// record's `internal`): its outputs, or reopening it, panicked.
    pub fn is_internal(&self) -> bool {
        self.kind() == FailKind::Internal
    }

    /// True when the file system refused reopening the scan, or recording its ending: the
    /// scan is left as it is, to be reopened again, since the cause can clear by itself.
    pub fn refused_by_the_file_system(&self) -> bool {
        matches!(
            self,
            FailReason::Refused {
                kind: FailKind::Io,
                ..
            }
        )
    }

    /// The exit-code class of the failure.
    pub fn kind(&self) -> FailKind {
        match self {
            FailReason::NotStarted(f)
                if matches!(f.class, FaultClass::Absent | FaultClass::Silent) =>
            {
                FailKind::Unavailable
            }
            FailReason::Storage(_) | FailReason::Outputs(_) => FailKind::Io,
            FailReason::OutputsInternal(_) => FailKind::Internal,
            FailReason::Refused { kind, .. } => *kind,
            _ => FailKind::Scan,
        }
    }
}

impl fmt::Display for FailReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FailReason::NotStarted(fault) => write!(f, "{fault}"),
            FailReason::Fatal {
                line: Some(k),
                fault,
            } => write!(f, "line {}: {fault}", k + 1),
            FailReason::Fatal { line: None, fault } => write!(f, "{fault}"),
            FailReason::BudgetExhausted {
                line,
                budget_s,
                since,
                traces,
                last,
            } => write!(
                f,
                "line {}: transient faults since {} outlasted the {budget_s} s budget ({traces} trace(s) started); last: {last}",
                line + 1,
                stamp(*since)
            ),
            FailReason::PositionLostRepeatedly { line, times, last } => write!(
                f,
                "line {}: the stage lost its position {times} time(s); last: {last}",
                line + 1
            ),
            FailReason::LineRefused { line, problem } => write!(f, "line {}: {problem}", line + 1),
            FailReason::FitterRefused { line, message } => write!(
                f,
                "line {}: the fitter refused the stored line: {message}",
                line + 1
            ),
            FailReason::Storage(m) => write!(f, "storage: {m}"),
            FailReason::Outputs(m) | FailReason::OutputsInternal(m) => f.write_str(m),
            FailReason::Refused { message, .. } => f.write_str(message),
        }
    }
}

/// What ended a failed scan, as far as what may continue it depends on it (the stop
/// record's `cause`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FailCause {
    /// Transient faults outlasted the budget: the device kept answering wrongly. The daemon
    /// continues the scan once its devices answer properly again.
    Budget,
    /// The file system refused a write (only earlier versions ended a scan for it; this one
    /// waits): a plain start continues the scan.
    Storage,
    /// A fault the operator must clear; `--resume` continues the scan after.
    Operator,
}

impl FailCause {
    /// True when the daemon continues a scan that failed for this cause by itself, so that
    /// the failure does not end its job: its transient budget (once its devices answer
    /// again) and the file system refusing a write (an earlier version's ending, which a
    /// plain start continues). The one rule for the daemon's start-up choice
    /// ([`super::choice::decide`]), a running job's turn and the queue's settling after a
    /// restart.
    pub fn continued_by_the_daemon(self) -> bool {
        matches!(self, FailCause::Budget | FailCause::Storage)
    }

    /// The cause of a stop record written before records named it, read from its reason.
    pub fn of_reason(reason: &str) -> FailCause {
        if reason.starts_with("storage: ")
            || reason.starts_with("all lines are on disk but the outputs could not be written")
        {
            FailCause::Storage
        } else if reason.contains("transient faults since") && reason.contains("budget") {
            FailCause::Budget
        } else {
            FailCause::Operator
        }
    }
}

/// Why a scan could not complete, for exit codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailKind {
    /// The scan ran and failed (device fault, exhausted budget, changed conditions).
    Scan,
    /// A device was not there when a new scan was to start.
    Unavailable,
    /// The disk refused (read-only, permissions).
    Io,
    /// A bug: part of the work panicked (exit 70, to be reported).
    Internal,
}

/// What a stop record says of an ending: its status, reason, a failure's cause, and whether
/// a bug ended it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StopWords {
    /// How it ended.
    pub status: StopStatus,
    /// Why, for people.
    pub reason: String,
    /// What may continue a failed scan.
    pub cause: Option<FailCause>,
    /// A bug ended it (an internal error).
    pub internal: bool,
}

/// How the scan ends.
#[derive(Debug, Clone, PartialEq)]
pub enum End {
    /// Every line committed and the outputs written.
    Success {
        /// What was written, for the stop record.
        summary: String,
    },
    /// The operator aborted it.
    Abort {
        /// Who.
        peer: Option<Peer>,
    },
    /// Shut down (SIGTERM): no stop record, it resumes at the next start.
    Shutdown,
    /// It failed.
    Fail(FailReason),
}

impl End {
    /// The word for it: the stop record's status, the status's last stop.
    pub fn status(&self) -> StopStatus {
        match self {
            End::Success { .. } => StopStatus::Success,
            End::Abort { .. } => StopStatus::Abort,
            End::Shutdown => StopStatus::Interrupted,
            End::Fail(_) => StopStatus::Fail,
        }
    }

    /// Why, for people: the stop record's and the last stop's reason. `created`: the scan's
    /// directory existed (an abort before it is an abort before the first line).
    pub fn reason(&self, created: bool) -> String {
        match self {
            End::Success { summary } => summary.clone(),
            End::Abort { .. } if created => "aborted by the operator".to_owned(),
            End::Abort { .. } => "aborted before the first line".to_owned(),
            End::Shutdown => "shutdown".to_owned(),
            End::Fail(r) => r.to_string(),
        }
    }

    /// What the journal's stop record says (its time is added as it is written); none
    /// after a shutdown, which leaves the scan resumable.
    pub fn stop_record(&self) -> Option<StopWords> {
        match self {
            End::Shutdown => None,
            End::Fail(r) => Some(StopWords {
                status: StopStatus::Fail,
                reason: r.to_string(),
                cause: Some(r.cause()),
                internal: r.is_internal(),
            }),
            end => Some(StopWords {
                status: end.status(),
                reason: end.reason(true),
                cause: None,
                internal: false,
            }),
        }
    }

    /// True when a bug ended the scan ([`FailReason::is_internal`]).
    pub fn is_internal(&self) -> bool {
        matches!(self, End::Fail(r) if r.is_internal())
    }

    /// Whether the scan's event of `kind` says a bug ended it ([`super::event::ScanEvent`]'s
    /// `internal`): the ending's own event when [`End::is_internal`], as its stop record
    /// says; never a start, suspension or resumption told before.
    pub fn tells_internal(&self, kind: ScanEventKind) -> bool {
        kind.is_ending() && self.is_internal()
    }

    /// The notification hook's event, for a scan that was created (a start that failed
    /// before has no scan to tell of).
    pub fn event(&self, created: bool) -> Option<ScanEventKind> {
        match self {
            _ if !created => None,
            End::Success { .. } => Some(ScanEventKind::Success),
            End::Abort { .. } => Some(ScanEventKind::Abort),
            End::Fail(_) => Some(ScanEventKind::Fail),
            End::Shutdown => None,
        }
    }

    /// The exit class of an end that is no success (`None` for a success).
    pub fn fail_kind(&self) -> Option<FailKind> {
        match self {
            End::Success { .. } => None,
            End::Fail(r) => Some(r.kind()),
            End::Abort { .. } | End::Shutdown => Some(FailKind::Scan),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn budget() -> FailReason {
        FailReason::BudgetExhausted {
            line: 2,
            budget_s: 600,
            since: "2026-12-02T01:00:00Z".parse().unwrap(),
            traces: 4,
            last: "line 3: instrument: NG011".into(),
        }
    }

    /// The journal's stop record, the status's last stop and the hook's event all come from
    /// the one ending.
    #[test]
    fn every_spelling_of_an_ending_is_derived_from_it() {
        let fail = End::Fail(budget());
        assert_eq!(fail.status(), StopStatus::Fail);
        assert_eq!(fail.event(true), Some(ScanEventKind::Fail));
        assert_eq!(
            fail.event(false),
            None,
            "a start that failed has no scan to tell of"
        );
        let words = fail.stop_record().unwrap();
        assert_eq!(
            (words.status, words.cause, words.internal),
            (StopStatus::Fail, Some(FailCause::Budget), false)
        );
        assert_eq!(
            words.reason,
            "line 3: transient faults since 2026-12-02T01:00:00Z outlasted the 600 s budget (4 trace(s) started); last: line 3: instrument: NG011"
        );
        assert_eq!(fail.fail_kind(), Some(FailKind::Scan));

        let abort = End::Abort { peer: None };
        assert_eq!(abort.reason(true), "aborted by the operator");
        assert_eq!(abort.reason(false), "aborted before the first line");
        assert_eq!(
            abort.stop_record(),
            Some(StopWords {
                status: StopStatus::Abort,
                reason: "aborted by the operator".into(),
                cause: None,
                internal: false,
            })
        );
        assert_eq!(abort.event(true), Some(ScanEventKind::Abort));

        assert_eq!(
            End::Shutdown.stop_record(),
            None,
            "a shutdown stays resumable"
        );
        assert_eq!(End::Shutdown.status(), StopStatus::Interrupted);
        assert_eq!(End::Shutdown.event(true), None);

        let ok = End::Success {
            summary: "3 lines".into(),
        };
        assert_eq!(
            ok.stop_record(),
            Some(StopWords {
                status: StopStatus::Success,
                reason: "3 lines".into(),
                cause: None,
                internal: false,
            })
        );
        assert_eq!(ok.fail_kind(), None);
    }

    /// Outputs not made because of a bug are an internal error (exit 70), not the disk's
    /// (74, as outputs the lines cannot make are): the stop record says so, and what may
    /// continue the scan is the operator's `--resume` alone (a cause every version reads).
    #[test]
    fn outputs_not_made_because_of_a_bug_are_an_internal_error() {
        let bug =
            FailReason::OutputsInternal("internal error: writing the outputs panicked".into());
        assert_eq!(bug.kind(), FailKind::Internal);
        assert_eq!(bug.cause(), FailCause::Operator);
        assert!(bug.is_internal());
        let end = End::Fail(bug);
        assert_eq!(end.fail_kind(), Some(FailKind::Internal));
        assert_eq!(end.event(true), Some(ScanEventKind::Fail));
        assert!(end.is_internal());
        assert_eq!(
            end.stop_record(),
            Some(StopWords {
                status: StopStatus::Fail,
                reason: "internal error: writing the outputs panicked".into(),
                cause: Some(FailCause::Operator),
                internal: true,
            })
        );
        // The ordinary outputs failure stays the disk's class, and no bug.
        let unmade =
            FailReason::Outputs("all lines are on disk but the outputs could not be made".into());
        assert_eq!(
            (unmade.kind(), unmade.cause()),
            (FailKind::Io, FailCause::Operator)
        );
        assert!(!unmade.is_internal());
        assert!(!End::Fail(unmade).stop_record().unwrap().internal);
    }

    /// The events say a bug ended the scan exactly where its stop record does: only the
    /// `fail` event of outputs or a reopening that panicked, not an ordinary failure (of the
    /// outputs, the budget, a refused reopening), a success or an abort, and no event but the
    /// ending.
    #[test]
    fn an_event_says_a_bug_ended_the_scan_as_its_stop_record_does() {
        let ends = [
            (
                End::Fail(FailReason::OutputsInternal("panicked".into())),
                true,
            ),
            (
                End::Fail(FailReason::Outputs("cannot be made".into())),
                false,
            ),
            (End::Fail(budget()), false),
            // A reopening that panicked, and one refused for the scan's own reason.
            (
                End::Fail(FailReason::Refused {
                    message: "internal error: reopening the scan panicked".into(),
                    kind: FailKind::Internal,
                }),
                true,
            ),
            (
                End::Fail(FailReason::Refused {
                    message: "scan X has ended; it cannot be continued".into(),
                    kind: FailKind::Scan,
                }),
                false,
            ),
            (
                End::Success {
                    summary: "5 lines".into(),
                },
                false,
            ),
            (End::Abort { peer: None }, false),
        ];
        for (end, bug) in ends {
            let kind = end.event(true).expect("a created scan's ending is told");
            assert_eq!(end.tells_internal(kind), bug, "{end:?}");
            assert_eq!(end.stop_record().map(|w| w.internal), Some(bug), "{end:?}");
            for before in [
                ScanEventKind::Started,
                ScanEventKind::Suspended,
                ScanEventKind::Resumed,
            ] {
                assert!(!end.tells_internal(before), "{end:?} {before}");
            }
        }
        // A shutdown is told by no event and records nothing.
        assert_eq!(End::Shutdown.event(true), None);
        assert!(!End::Shutdown.is_internal());
    }

    #[test]
    fn the_cause_of_a_stop_record_of_an_earlier_version_is_read_from_its_reason() {
        assert_eq!(
            FailCause::of_reason("storage: write lines/0003.csv: Operation not permitted"),
            FailCause::Storage
        );
        assert_eq!(
            FailCause::of_reason(
                "all lines are on disk but the outputs could not be written: report.json: Read-only file system"
            ),
            FailCause::Storage
        );
        assert_eq!(
            FailCause::of_reason(&budget().to_string()),
            FailCause::Budget
        );
        assert_eq!(
            FailCause::of_reason("line 2: instrument: battery abnormal"),
            FailCause::Operator
        );
        let storage = FailReason::Storage("x".into());
        assert_eq!(storage.cause(), FailCause::Storage);
        assert_eq!(storage.kind(), FailKind::Io);
    }
}
