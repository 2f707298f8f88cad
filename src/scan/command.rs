//! Operator commands as the scan runner receives them: the control socket (or any other
//! front end) forwards each with a channel for the runner's answer.
//!
//! Layer 3 (session): depends on tokio's oneshot channel only.

use tokio::sync::oneshot;

/// A command for the runner.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OperatorCommand {
    /// Deferred pause.
    Pause,
    /// Release a pause.
    Resume,
    /// Abort the scan.
    Abort,
    /// Start a scan.
    Start {
        /// Specimen id.
        specimen: String,
        /// Operator.
        operator: String,
        /// Notes.
        notes: String,
    },
}

/// A forwarded command with the channel for the runner's answer: `Ok(detail)` when it was
/// accepted (the control socket sends an `ack`), `Err(message)` when refused.
#[derive(Debug)]
pub struct OperatorRequest {
    /// The command.
    pub command: OperatorCommand,
    /// Where the runner answers.
    pub reply: oneshot::Sender<Result<String, String>>,
}
