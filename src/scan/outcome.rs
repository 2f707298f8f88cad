//! What the runner is asked to run and what it gives back, for the front ends (exit codes,
//! messages).
//!
//! Layer 3 (session): plain data; depends on the session's command, outputs and ending
//! types.

use super::command::Peer;
use super::outputs::Outputs;
use std::path::PathBuf;

use super::ending::End;

/// What to run.
#[derive(Debug, Clone, PartialEq, Eq)]
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
