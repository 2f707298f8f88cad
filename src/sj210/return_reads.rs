//! Whether the instrument answers reads while its drive returns after a trace: what each read
//! asked then got, the verdict, and the `[instrument.commands]` line that lets a scan read
//! out during the return.
//!
//! No manual says whether an SJ-210 answers `RDRES` and the read-out while its status reads
//! `002` (returning) or refuses them busy (`NG011`). Reading out during the return saves up to
//! the return's time on every line, so `surfscan probe --trace --readout` asks, during that
//! one trace's return, one result, a read-out total and one block, then the status again:
//! only answers given while the status still read `002` before and after count.
//!
//! Pure (layer 1): depends on [`super::ng`] only.

use super::ng::NgCode;

/// What one read asked during the return got.
#[derive(Debug, Clone, PartialEq)]
pub enum ReadAnswer {
    /// An `OK` reply.
    Answered,
    /// Refused for now: busy (`NG011`), still processing (`NG033`), no results (`NG101`).
    NotNow(NgCode),
    /// This command or form is not known to the firmware (`NG030`–`NG032`): says nothing
    /// about the return.
    NotUnderstood(NgCode),
    /// Another NG code, silence or noise.
    Failed(String),
}

impl ReadAnswer {
    /// The answer to an NG code.
    pub fn of_code(code: NgCode) -> ReadAnswer {
        if code.is_retryable_read() {
            ReadAnswer::NotNow(code)
        } else if code.is_unsupported() {
            ReadAnswer::NotUnderstood(code)
        } else {
            ReadAnswer::Failed(code.to_string())
        }
    }

    fn describe(&self) -> String {
        match self {
            ReadAnswer::Answered => "answered".into(),
            ReadAnswer::NotNow(c) => format!("refused {c} ({})", c.meaning()),
            ReadAnswer::NotUnderstood(c) => format!("not understood ({c})"),
            ReadAnswer::Failed(e) => format!("failed: {e}"),
        }
    }
}

/// What the reads during one trace's return found.
#[derive(Debug, Clone, PartialEq)]
pub enum ReturnProbe {
    /// The drive was seen returning and these reads were asked; `still_returning` is whether
    /// the status read `002` again after them.
    Asked {
        /// Each command with its answer, in order.
        reads: Vec<(String, ReadAnswer)>,
        /// Whether the drive was still returning after the last read.
        still_returning: bool,
    },
    /// The drive was never seen returning (it stopped at the end of travel, `005`, or was
    /// back before the first poll after the measurement).
    NotSeenReturning {
        /// The status it was seen in instead.
        status: u16,
    },
}

/// The verdict on reading out during the return.
#[derive(Debug, Clone, PartialEq)]
pub enum ReturnVerdict {
    /// A result, a read-out total and a block were answered while the drive returned.
    Answers,
    /// A read was refused for now while the drive returned: read after the return.
    Refuses(NgCode),
    /// A result was answered, but no read-out form is known yet to try the profile with.
    ResultsOnly,
    /// Nothing can be said (why).
    Unknown(String),
}

impl ReturnProbe {
    /// The verdict from the answers.
    pub fn verdict(&self) -> ReturnVerdict {
        let (reads, still_returning) = match self {
            ReturnProbe::NotSeenReturning { status } => {
                return ReturnVerdict::Unknown(format!(
                    "the drive was not seen returning (status {status:03}{}); set the instrument to return automatically after a trace, or trace a longer line, and probe again",
                    if *status == 5 { ", at the end of travel" } else { "" }
                ))
            }
            ReturnProbe::Asked {
                reads,
                still_returning,
            } => (reads, *still_returning),
        };
        if let Some(code) = reads.iter().find_map(|(_, a)| match a {
            ReadAnswer::NotNow(c) => Some(*c),
            _ => None,
        }) {
            return ReturnVerdict::Refuses(code);
        }
        if let Some((cmd, ReadAnswer::Failed(e))) = reads
            .iter()
            .find(|(_, a)| matches!(a, ReadAnswer::Failed(_)))
        {
            return ReturnVerdict::Unknown(format!("{cmd} failed during the return: {e}"));
        }
        if !still_returning {
            return ReturnVerdict::Unknown(
                "the drive was back before the reads were done, so they may have been answered after the return; probe again with a longer trace".into(),
            );
        }
        let answered = reads
            .iter()
            .filter(|(_, a)| *a == ReadAnswer::Answered)
            .count();
        let result = reads
            .first()
            .is_some_and(|(_, a)| *a == ReadAnswer::Answered);
        match (result, answered) {
            (true, 3..) => ReturnVerdict::Answers,
            (true, _) => ReturnVerdict::ResultsOnly,
            (false, _) => ReturnVerdict::Unknown("no read was answered during the return".into()),
        }
    }

    /// One line per read, for the operator.
    pub fn lines(&self) -> Vec<String> {
        match self {
            ReturnProbe::NotSeenReturning { .. } => Vec::new(),
            ReturnProbe::Asked {
                reads,
                still_returning,
            } => reads
                .iter()
                .map(|(c, a)| format!("{c} while the drive returned: {}", a.describe()))
                .chain(std::iter::once(format!(
                    "status after the reads: {}",
                    if *still_returning {
                        "002, still returning"
                    } else {
                        "back"
                    }
                )))
                .collect(),
        }
    }

    /// The verdict in words, with what to do.
    pub fn describe(&self) -> String {
        match self.verdict() {
            ReturnVerdict::Answers => "the instrument answers the read-out while its drive returns: a scan can read each line out during the return".into(),
            ReturnVerdict::Refuses(c) => format!(
                "the instrument refuses reads while its drive returns ({c}): leave reads-during-return off; the read-out follows the return"
            ),
            ReturnVerdict::ResultsOnly => "results are answered while the drive returns; the read-out could not be tried (no read-out form known yet): configure profile-total and profile-block, then probe again".into(),
            ReturnVerdict::Unknown(why) => format!("not found out: {why}"),
        }
    }

    /// The `[instrument.commands]` key to add when the instrument answers.
    pub fn snippet_line(&self) -> Option<&'static str> {
        (self.verdict() == ReturnVerdict::Answers).then_some("reads-during-return = true\n")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn asked(answers: &[ReadAnswer], still: bool) -> ReturnProbe {
        let cmds = ["RDRES02,01,00", "RDEVA00", "RDEVA50"];
        ReturnProbe::Asked {
            reads: cmds
                .iter()
                .zip(answers)
                .map(|(c, a)| (c.to_string(), a.clone()))
                .collect(),
            still_returning: still,
        }
    }

    use ReadAnswer::*;

    #[test]
    fn three_reads_answered_while_still_returning_is_the_one_yes() {
        let yes = asked(&[Answered, Answered, Answered], true);
        assert_eq!(yes.verdict(), ReturnVerdict::Answers);
        assert_eq!(yes.snippet_line(), Some("reads-during-return = true\n"));
        assert_eq!(yes.lines().len(), 4);
        assert!(yes.lines()[3].contains("still returning"));
        // The drive back before the reads were done: they may have come after the return.
        let late = asked(&[Answered, Answered, Answered], false);
        assert!(matches!(late.verdict(), ReturnVerdict::Unknown(w) if w.contains("back before")));
        assert_eq!(late.snippet_line(), None);
    }

    #[test]
    fn a_busy_answer_anywhere_is_a_no_and_an_unknown_form_only_limits_the_yes() {
        let busy = NgCode::from_code(11);
        let no = asked(&[Answered, NotNow(busy), Answered], true);
        assert_eq!(no.verdict(), ReturnVerdict::Refuses(busy));
        assert!(no.describe().contains("leave reads-during-return off"));
        assert_eq!(no.snippet_line(), None);
        assert_eq!(
            ReadAnswer::of_code(NgCode::from_code(11)),
            NotNow(NgCode::from_code(11))
        );
        assert_eq!(
            ReadAnswer::of_code(NgCode::from_code(31)),
            NotUnderstood(NgCode::from_code(31))
        );
        assert_eq!(
            ReadAnswer::of_code(NgCode::from_code(7)),
            Failed("NG007".into())
        );
        // The result answered, the read-out form not known: the profile was not tried.
        let results = asked(&[Answered, NotUnderstood(NgCode::from_code(30))], true);
        assert_eq!(results.verdict(), ReturnVerdict::ResultsOnly);
        assert_eq!(results.snippet_line(), None);
        let failed = asked(&[Failed("no reply within 2000 ms".into())], true);
        assert!(
            matches!(failed.verdict(), ReturnVerdict::Unknown(w) if w.contains("RDRES02,01,00 failed"))
        );
        let stopped = ReturnProbe::NotSeenReturning { status: 5 };
        assert!(
            matches!(stopped.verdict(), ReturnVerdict::Unknown(w) if w.contains("end of travel"))
        );
    }
}
