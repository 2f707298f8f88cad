//! What the runner is asked to run and how a run ended, for the front ends (exit codes,
//! messages).
//!
//! Layer 3 (session): plain data; depends on the session's command, outputs and machine
//! types.

use super::command::Peer;
use super::outputs::Outputs;
use std::path::PathBuf;

pub use super::machine::FailKind;

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

/// How a scan ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// All lines traced, surface and report written.
    Success {
        /// Scan directory.
        dir: PathBuf,
        /// Files written at the end.
        outputs: Outputs,
    },
    /// The operator aborted it.
    Aborted {
        /// Scan directory.
        dir: PathBuf,
    },
    /// It failed; the reason is in the journal's stop record when `dir` is set.
    Failed {
        /// Scan directory, when one was created.
        dir: Option<PathBuf>,
        /// Why.
        reason: String,
        /// For the exit code.
        kind: FailKind,
    },
    /// Shut down (SIGTERM) mid-scan: no stop record, it resumes at the next start.
    Interrupted {
        /// Scan directory.
        dir: PathBuf,
    },
}
