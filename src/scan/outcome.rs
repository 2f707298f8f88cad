//! What the runner is asked to run and what it gives back, for the front ends (exit codes,
//! messages).
//!
//! Layer 3 (session): plain data; depends on the session's command, outputs and ending
//! types.

use super::command::Peer;
use super::expected::ExpectedConditions;
use super::journal::JobRecord;
use super::outputs::Outputs;
use std::path::PathBuf;

use super::ending::End;

/// What a recipe's new scan carries besides the plan: the job it is made for (frozen into
/// its start record) and the measuring conditions the instrument must report at its start.
#[derive(Debug, Clone, PartialEq)]
pub struct NewJob {
    /// The job, recorded in the start record.
    pub record: JobRecord,
    /// The conditions the recipe expects; a start whose instrument reports others is
    /// refused before the scan's directory is made, naming both.
    pub expected: ExpectedConditions,
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub enum ScanRequest {
    /// A new scan of the configured plan.
    New {
        /// Specimen id.
        specimen: String,
        /// Operator.
        operator: String,
        /// Notes.
        notes: String,
        /// Who asked (recorded in the start record; this process when `None`).
        peer: Option<Peer>,
        /// The recipe's job, when the scan is one (`None`: the station's own plan).
        job: Option<Box<NewJob>>,
    },
    /// Resume the unfinished scan in this directory.
    Resume {
        /// The scan directory.
        dir: PathBuf,
        /// Who asked (none: the daemon resuming at start-up).
        peer: Option<Peer>,
    },
    /// Continue a scan that failed, at its first missing line, after the operator cleared
    /// the cause.
    Continue {
        /// The scan directory.
        dir: PathBuf,
        /// Who asked.
        peer: Option<Peer>,
    },
}

/// What a run of the runner gives back: how the scan ended, where it is, what it wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// How it ended (a shutdown leaves it resumable: no stop record).
    pub end: End,
    /// The scan directory, when one was created or reopened.
    pub dir: Option<PathBuf>,
    /// The files written at the end, after a success.
    pub outputs: Option<Outputs>,
}

impl Outcome {
    /// An end before any scan directory was created or reopened.
    pub fn without_scan(end: End) -> Outcome {
        Outcome {
            end,
            dir: None,
            outputs: None,
        }
    }
}
