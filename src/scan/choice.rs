//! Which scan a start runs: resume the unfinished one, continue a failed one, or begin a new
//! one (recording the unfinished ones as abandoned). The decision ([`decide`]) is a pure
//! function of the survey of the output directory ([`super::journal::survey`]), the start's
//! mode and who asks; [`choose`] surveys and decides, and [`Choice::commit`] writes the only
//! records a start makes before its scan runs (the abandoned scans' stop records). The CLI's
//! `scan`, the daemon at start-up and the daemon's `start` all go through here.
//!
//! The rows, in order:
//! - a new scan asked for (`--new`): the unfinished scans are abandoned, a new one starts;
//! - an unfinished scan (no stop record): the one started last is resumed, the others named;
//! - the scan started last failed for a cause that clears by itself (a storage error, which
//!   earlier versions ended a scan for): it is continued;
//! - `--resume`: the failed scan started last is continued; refused when there is none;
//! - the daemon at start-up continues the scan started last when it failed for its transient
//!   budget (a device that kept answering wrongly), once its devices answer properly again,
//!   and starts nothing else; an operator's plain start begins a new scan, warning when the
//!   scan started last failed.
//!
//! The failures the daemon continues by itself (the two rows above: storage, budget) are
//! [`FailCause::continued_by_the_daemon`]'s, the rule a running job's turn and the queue's
//! settling after a restart ask too: such a failure does not end a job.
//!
//! A scan that failed with an internal error (a bug: writing its outputs, every line on disk,
//! or reopening it panicked) is the operator's: only `--resume` continues it (it writes a
//! complete scan's outputs again and traces nothing); the daemon never does by itself (the
//! same bug would panic again).
//!
//! Layer 3 (session): the decision is pure; [`choose`] reads the journals and
//! [`Choice::commit`] appends to them ([`super::journal`]).

use super::command::{Peer, StartMode};
use super::ending::{FailCause, StopStatus};
use super::journal::{survey, Journal, StopRecord, Survey, JOURNAL_FILE};
use super::outcome::ScanRequest;
use std::path::{Path, PathBuf};

/// Who asks for the start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Asker {
    /// An operator (`surfscan scan`, `surfscan start`), with the mode of their flags.
    Operator(StartMode),
    /// The daemon at its own start: it resumes what is unfinished and never begins a scan.
    DaemonStartUp,
}

/// What to run, as decided.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Decision {
    /// Resume this unfinished scan.
    Resume(PathBuf),
    /// Continue this failed scan at its first missing line.
    Continue(PathBuf),
    /// Begin a new scan, after recording these unfinished scans as abandoned.
    New {
        /// The unfinished scans the new one replaces.
        abandon: Vec<PathBuf>,
    },
    /// Continue this scan, which failed for its transient budget, once its devices answer
    /// properly again (the daemon at start-up; it asks them with backoff).
    AwaitDevices(PathBuf),
    /// Nothing to run (the daemon at start-up with nothing unfinished).
    Nothing,
    /// The start is refused: why.
    Refuse(String),
}

/// The decision, and what to tell the operator about the scans it passed over.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Decided {
    /// What to run.
    pub decision: Decision,
    /// Warnings for the log: unfinished scans not resumed, a failed scan not continued,
    /// damaged journals skipped.
    pub warnings: Vec<String>,
}

/// The table: what a start asked by `asker` runs, given the survey of the output directory
/// `out` (named in messages).
pub fn decide(s: &Survey, asker: Asker, out: &Path) -> Decided {
    let mut warnings = s.warnings();
    let newest_failed = s.failed.last();
    // The failed scan that is also the scan started last (a newer scan, finished or not,
    // makes it history).
    let last_failed = newest_failed.filter(|f| f.sequence >= s.max_sequence);
    let decision = match asker {
        Asker::Operator(StartMode::New) => Decision::New {
            abandon: s.unfinished.iter().map(|u| u.dir.clone()).collect(),
        },
        _ if !s.unfinished.is_empty() => {
            let (last, older) = s.unfinished.split_last().expect("not empty");
            for o in older {
                warnings.push(format!(
                    "{} is also unfinished; only the one started last is resumed (resume it by hand with `surfscan fit`/`analyze`, or add a stop record)",
                    o.dir.display()
                ));
            }
            Decision::Resume(last.dir.clone())
        }
        _ if last_failed.is_some_and(|f| f.cause == FailCause::Storage) => {
            Decision::Continue(last_failed.expect("checked").dir.clone())
        }
        Asker::Operator(StartMode::Resume) => match newest_failed {
            Some(f) => Decision::Continue(f.dir.clone()),
            None => Decision::Refuse(format!(
                "no unfinished or failed scan in {} to resume; start without --resume for a new one",
                out.display()
            )),
        },
        // Of the failures the daemon continues by itself, the file system's is continued
        // above; its transient budget's waits for its devices.
        Asker::DaemonStartUp => match last_failed {
            Some(f) if f.cause.continued_by_the_daemon() => Decision::AwaitDevices(f.dir.clone()),
            _ => Decision::Nothing,
        },
        Asker::Operator(StartMode::Auto) => {
            match last_failed {
                Some(f) if f.internal => warnings.push(format!(
                    "the last scan {} failed with an internal error (a bug: writing its outputs or reopening it panicked, as its stop record says); a new scan starts (`--resume` tries the failed one again, and writes its outputs again when every line is on disk; `surfscan fit`/`analyze` on its directory makes them by hand)",
                    f.dir.display()
                )),
                Some(f) => warnings.push(format!(
                    "the last scan {} failed; a new scan starts (`--resume` continues the failed one at its first missing line)",
                    f.dir.display()
                )),
                None => {}
            }
            Decision::New {
                abandon: Vec::new(),
            }
        }
    };
    Decided { decision, warnings }
}

/// Why no choice could be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ChoiceError {
    /// The output directory or a journal could not be read or written.
    #[error("{0}")]
    Io(String),
    /// The start was refused (e.g. `--resume` with nothing to resume).
    #[error("{0}")]
    Refused(String),
}

/// A start decided on and not yet carried out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Choice {
    /// What to run.
    pub decision: Decision,
    /// Who asked (for the journal).
    pub peer: Peer,
    /// The new scan's traceability (specimen, operator, notes), when one begins.
    pub traceability: (String, String, String),
}

impl Choice {
    /// What the start does, for the operator's answer.
    pub fn describe(&self, lines: u32) -> String {
        match &self.decision {
            Decision::New { .. } => format!("starting a scan of {lines} lines"),
            Decision::Resume(dir) => format!("resuming the unfinished scan {}", dir.display()),
            Decision::Continue(dir) => format!("continuing the failed scan {}", dir.display()),
            Decision::AwaitDevices(dir) => format!(
                "continuing the scan {} once its devices answer again",
                dir.display()
            ),
            Decision::Nothing => "nothing to resume".to_owned(),
            Decision::Refuse(why) => why.clone(),
        }
    }

    /// Carries the choice out: records the replaced scans as abandoned (the start's only
    /// change on disk before the scan itself) and hands over the scan to run (`None`:
    /// nothing to run).
    pub fn commit(self) -> Result<Option<ScanRequest>, ChoiceError> {
        let peer = Some(self.peer.clone());
        match self.decision {
            Decision::New { abandon } => {
                for dir in &abandon {
                    record_abandoned(dir, &self.peer)?;
                }
                let (specimen, operator, notes) = self.traceability;
                Ok(Some(ScanRequest::New {
                    specimen,
                    operator,
                    notes,
                    peer,
                    job: None,
                }))
            }
            Decision::Resume(dir) => {
                tracing::info!("resuming the unfinished scan {}", dir.display());
                Ok(Some(ScanRequest::Resume { dir, peer }))
            }
            Decision::Continue(dir) => {
                tracing::info!("continuing the failed scan {}", dir.display());
                Ok(Some(ScanRequest::Continue { dir, peer }))
            }
            Decision::AwaitDevices(_) | Decision::Nothing => Ok(None),
            Decision::Refuse(why) => Err(ChoiceError::Refused(why)),
        }
    }
}

/// Surveys `output_dir` and decides what a start asked by `asker` (`peer`) runs; the
/// warnings go to the log. Nothing is changed: [`Choice::commit`] carries it out once the
/// start is sure to go ahead (the daemon first tells the operator so, and a start the
/// operator was told had not happened changes nothing).
pub fn choose(
    output_dir: &Path,
    asker: Asker,
    peer: Peer,
    traceability: (String, String, String),
) -> Result<Choice, ChoiceError> {
    let s = survey(output_dir).map_err(|e| {
        ChoiceError::Io(format!(
            "cannot look for unfinished scans in {}: {e}",
            output_dir.display()
        ))
    })?;
    let d = decide(&s, asker, output_dir);
    for w in &d.warnings {
        tracing::warn!("{w}");
    }
    Ok(Choice {
        decision: d.decision,
        peer,
        traceability,
    })
}

/// Records in an unfinished scan's journal that it was abandoned for a new one.
fn record_abandoned(dir: &Path, peer: &Peer) -> Result<(), ChoiceError> {
    let path = dir.join(JOURNAL_FILE);
    let io = |e: String| {
        ChoiceError::Io(format!(
            "cannot record that the scan in {} is abandoned: {e}",
            dir.display()
        ))
    };
    let reason = format!(
        "abandoned: a new scan was started instead (--new, by {})",
        peer.describe_briefly()
    );
    let stop = StopRecord {
        status: StopStatus::Abandoned,
        reason: reason.clone(),
        cause: None,
        internal: false,
        time: chrono::Utc::now(),
    };
    Journal::append_stop(&path, stop).map_err(|e| io(e.to_string()))?;
    tracing::warn!("{}: {reason}", dir.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::journal::{Failed, Unfinished};
    use chrono::{DateTime, Utc};

    fn at(minute: u32) -> DateTime<Utc> {
        format!("2026-12-02T01:{minute:02}:00Z").parse().unwrap()
    }

    fn unfinished(name: &str, sequence: u64) -> Unfinished {
        Unfinished {
            dir: PathBuf::from(name),
            scan_id: name.to_owned(),
            sequence,
            started: at(sequence as u32),
        }
    }

    fn failed(name: &str, sequence: u64, cause: FailCause) -> Failed {
        Failed {
            dir: PathBuf::from(name),
            sequence,
            started: at(sequence as u32),
            cause,
            internal: false,
        }
    }

    fn survey_of(unfinished: Vec<Unfinished>, failed: Vec<Failed>, max: u64) -> Survey {
        Survey {
            unfinished,
            failed,
            damaged: Vec::new(),
            max_sequence: max,
            ..Survey::default()
        }
    }

    const AUTO: Asker = Asker::Operator(StartMode::Auto);
    const RESUME: Asker = Asker::Operator(StartMode::Resume);
    const NEW: Asker = Asker::Operator(StartMode::New);
    const ALL: [Asker; 4] = [AUTO, RESUME, NEW, Asker::DaemonStartUp];
    /// A new scan that leaves no unfinished one behind.
    const FRESH: Decision = Decision::New {
        abandon: Vec::new(),
    };

    fn decision(s: &Survey, asker: Asker) -> Decision {
        decide(s, asker, Path::new("/out")).decision
    }

    #[test]
    fn an_empty_output_directory() {
        let s = Survey::default();
        assert_eq!(decision(&s, AUTO), FRESH);
        assert_eq!(decision(&s, NEW), FRESH);
        assert_eq!(decision(&s, Asker::DaemonStartUp), Decision::Nothing);
        match decision(&s, RESUME) {
            Decision::Refuse(why) => assert!(
                why.contains("no unfinished or failed scan in /out")
                    && why.contains("without --resume"),
                "{why}"
            ),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_unfinished_scan_started_last_is_resumed_and_the_others_named() {
        let s = survey_of(vec![unfinished("a", 1), unfinished("b", 2)], Vec::new(), 2);
        for asker in [AUTO, RESUME, Asker::DaemonStartUp] {
            let d = decide(&s, asker, Path::new("/out"));
            assert_eq!(d.decision, Decision::Resume("b".into()), "{asker:?}");
            assert!(
                d.warnings
                    .iter()
                    .any(|w| w.starts_with("a is also unfinished")),
                "{:?}",
                d.warnings
            );
        }
        // A new scan abandons both.
        assert_eq!(
            decision(&s, NEW),
            Decision::New {
                abandon: vec!["a".into(), "b".into()]
            }
        );
    }

    #[test]
    fn an_unfinished_scan_comes_before_a_failed_one() {
        let s = survey_of(
            vec![unfinished("u", 1)],
            vec![failed("f", 2, FailCause::Storage)],
            2,
        );
        for asker in [AUTO, RESUME, Asker::DaemonStartUp] {
            assert_eq!(
                decision(&s, asker),
                Decision::Resume("u".into()),
                "{asker:?}"
            );
        }
    }

    #[test]
    fn a_scan_failed_for_storage_is_continued_by_any_start_but_a_new_one() {
        let s = survey_of(Vec::new(), vec![failed("f", 3, FailCause::Storage)], 3);
        for asker in [AUTO, RESUME, Asker::DaemonStartUp] {
            assert_eq!(
                decision(&s, asker),
                Decision::Continue("f".into()),
                "{asker:?}"
            );
        }
        assert_eq!(decision(&s, NEW), FRESH);
        // Not when a newer scan ran since: it is history.
        let s = survey_of(Vec::new(), vec![failed("f", 3, FailCause::Storage)], 4);
        assert_eq!(decision(&s, AUTO), FRESH);
        assert_eq!(decision(&s, Asker::DaemonStartUp), Decision::Nothing);
    }

    #[test]
    fn a_scan_failed_for_its_budget_is_awaited_by_the_daemon() {
        let s = survey_of(Vec::new(), vec![failed("f", 2, FailCause::Budget)], 2);
        assert_eq!(
            decision(&s, Asker::DaemonStartUp),
            Decision::AwaitDevices("f".into())
        );
        // Not when a newer scan ran since.
        let s = survey_of(Vec::new(), vec![failed("f", 2, FailCause::Budget)], 3);
        assert_eq!(decision(&s, Asker::DaemonStartUp), Decision::Nothing);
    }

    #[test]
    fn a_scan_failed_for_the_operator_is_continued_only_by_resume() {
        for cause in [FailCause::Operator, FailCause::Budget] {
            let s = survey_of(
                Vec::new(),
                vec![failed("old", 1, cause), failed("f", 2, cause)],
                2,
            );
            assert_eq!(decision(&s, RESUME), Decision::Continue("f".into()));
            if cause == FailCause::Operator {
                assert_eq!(decision(&s, Asker::DaemonStartUp), Decision::Nothing);
            }
            let d = decide(&s, AUTO, Path::new("/out"));
            assert_eq!(d.decision, FRESH);
            assert!(
                d.warnings
                    .iter()
                    .any(|w| w.starts_with("the last scan f failed") && w.contains("--resume")),
                "{:?}",
                d.warnings
            );
            // --resume continues the newest failed one even when a newer scan succeeded.
            let s = survey_of(Vec::new(), vec![failed("f", 2, cause)], 5);
            assert_eq!(decision(&s, RESUME), Decision::Continue("f".into()));
            let d = decide(&s, AUTO, Path::new("/out"));
            assert!(d.warnings.is_empty(), "{:?}", d.warnings);
        }
    }

    /// A bug ended the scan while its outputs were written: only the operator's `--resume`
    /// continues it (writing the outputs again); a plain start begins a new scan and says how
    /// to get the outputs; the daemon at start-up leaves it alone, so a panic is never
    /// repeated in a loop.
    #[test]
    fn a_scan_ended_by_an_internal_error_is_continued_only_by_resume() {
        let bug = Failed {
            internal: true,
            ..failed("f", 2, FailCause::Operator)
        };
        let s = survey_of(Vec::new(), vec![bug], 2);
        assert_eq!(decision(&s, RESUME), Decision::Continue("f".into()));
        assert_eq!(decision(&s, Asker::DaemonStartUp), Decision::Nothing);
        let d = decide(&s, AUTO, Path::new("/out"));
        assert_eq!(d.decision, FRESH);
        assert!(
            d.warnings.iter().any(|w| w
                .starts_with("the last scan f failed with an internal error")
                && w.contains("`--resume` tries the failed one again")
                && w.contains("`surfscan fit`/`analyze`")),
            "{:?}",
            d.warnings
        );
    }

    #[test]
    fn every_asker_gets_a_decision_and_only_resume_or_daemon_never_begins_a_scan() {
        let surveys = [
            Survey::default(),
            survey_of(vec![unfinished("u", 1)], Vec::new(), 1),
            survey_of(Vec::new(), vec![failed("f", 1, FailCause::Operator)], 1),
        ];
        for s in &surveys {
            for asker in ALL {
                let d = decision(s, asker);
                if asker == Asker::DaemonStartUp {
                    assert!(!matches!(d, Decision::New { .. }), "{d:?}");
                }
                if asker == RESUME {
                    assert!(!matches!(d, Decision::New { .. }), "{d:?}");
                }
            }
        }
    }
}
