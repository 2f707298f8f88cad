//! Control-socket wire format and the server's side of the runner ⇄ server contract.
//!
//! One JSON object per line in both directions, each with a `class` field. The daemon
//! greets every connection with [`Message::Hello`] before anything else; the client then
//! sends one [`Request`] per line. The command set is closed: there is no passthrough to
//! the instrument or the stage.
//!
//! The status snapshot and the operator commands are the scan's own types
//! ([`crate::scan::status`], [`crate::scan::command`]); this module only puts them on the wire.
//!
//! The job queue's requests (`queue-add`, `queue-list`, `queue-remove`, `queue-clear`,
//! `queue-continue`, `ready`) are served by the daemon's [`QueueService`], also while a scan
//! runs; a refusal names its exit status ([`Message::Refused`]).
//!
//! Layer 4 (process edge): serde types plus tokio channel types; depends on the scan's status
//! and command types and the job queue's; no I/O.

use crate::jobs::queue::Queue;
use crate::jobs::service::QueueService;
use crate::scan::command::{OperatorRequest, StartMode};
use crate::scan::status::Status;
use serde::{Deserialize, Serialize};
use tokio::sync::{mpsc, watch};

/// Version of this protocol, sent in the greeting; bumped on incompatible changes.
pub const PROTOCOL_VERSION: u32 = 1;

/// Client → daemon.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "class", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Request {
    /// One status snapshot.
    Status,
    /// A snapshot now and another on every change, until the client disconnects.
    Watch,
    /// Deferred pause: after the current line is on disk.
    Pause,
    /// Release an operator pause.
    Resume,
    /// End the scan now (best-effort instrument abort, stage stop); recorded as `abort`.
    Abort,
    /// Start a scan of the configured plan.
    Start {
        /// Specimen id.
        #[serde(default)]
        specimen: String,
        /// Operator name.
        #[serde(default)]
        operator: String,
        /// Free-text notes.
        #[serde(default)]
        notes: String,
        /// `auto` (default: resume an unfinished scan, else a new one), `resume` (also
        /// continue a failed one) or `new` (start over).
        #[serde(default)]
        mode: StartMode,
        /// A recipe's scan (`NAME.toml` in the station's recipe directory) instead of the
        /// station's plan.
        #[serde(default)]
        recipe: Option<String>,
        /// y of the first line for the recipe's scan, mm.
        #[serde(default)]
        y_start_mm: Option<f64>,
    },
    /// Queue a job of a recipe (`surfscan queue add`).
    QueueAdd {
        /// The recipe's name (`NAME.toml` in the station's recipe directory).
        recipe: String,
        /// Specimen id.
        #[serde(default)]
        specimen: String,
        /// Operator name.
        #[serde(default)]
        operator: String,
        /// Free-text notes.
        #[serde(default)]
        notes: String,
        /// y of the first line, mm (overrides the recipe's).
        #[serde(default)]
        y_start_mm: Option<f64>,
        /// Wait for `ready` before the job starts.
        #[serde(default)]
        needs_loading: bool,
    },
    /// The queue (answered with [`Message::Queue`]).
    QueueList,
    /// Remove a queued job.
    QueueRemove {
        /// Its number.
        job: u64,
    },
    /// Remove every queued job (not the running one).
    QueueClear,
    /// Run the jobs after a failure that stopped the queue.
    QueueContinue,
    /// The specimen of the job waiting for loading is in place.
    Ready {
        /// That job's number (default: whichever is waiting).
        #[serde(default)]
        job: Option<u64>,
    },
}

/// Daemon → client.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "class", rename_all = "kebab-case")]
pub enum Message {
    /// First message on every connection.
    Hello {
        /// [`PROTOCOL_VERSION`].
        protocol: u32,
        /// `surfscan <version>`.
        software: String,
        /// Daemon process id.
        pid: u32,
    },
    /// A status snapshot (reply to `status`, and every change for `watch`).
    Status(Box<Status>),
    /// A command was accepted; `detail` says what will happen.
    Ack {
        /// The command's class (`pause`, `start`, …).
        command: String,
        /// For people.
        detail: String,
    },
    /// A request was refused or malformed; `message` names the cause and what to do.
    Error {
        /// For people.
        message: String,
    },
    /// A queue request was refused; `exit` is the status its command exits with (2 usage,
    /// 74 the queue could not be written, 78 the recipe is not valid).
    Refused {
        /// For people.
        message: String,
        /// Exit status.
        exit: u8,
    },
    /// The job queue (reply to `queue-list`).
    Queue(Box<Queue>),
}

/// The server's side of the contract: where it reads status and sends commands.
#[derive(Debug, Clone)]
pub struct ControlChannels {
    /// The runner's latest status.
    pub status: watch::Receiver<Status>,
    /// Commands to the runner.
    pub commands: mpsc::Sender<OperatorRequest>,
    /// The job queue, when this process keeps one (the daemon).
    pub queue: Option<QueueService>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_are_tagged_by_class_and_closed() {
        let r: Request = serde_json::from_str(r#"{"class":"start","specimen":"B12"}"#).unwrap();
        assert_eq!(
            r,
            Request::Start {
                specimen: "B12".into(),
                operator: String::new(),
                notes: String::new(),
                mode: StartMode::Auto,
                recipe: None,
                y_start_mm: None,
            }
        );
        assert_eq!(
            serde_json::from_str::<Request>(r#"{"class":"pause"}"#).unwrap(),
            Request::Pause
        );
        // No raw passthrough: an unknown class is refused, so is a misspelt start field.
        assert!(serde_json::from_str::<Request>(r#"{"class":"raw","cmd":"CTSTA"}"#).is_err());
        assert!(serde_json::from_str::<Request>(r#"{"class":"start","specimn":"B"}"#).is_err());
    }

    #[test]
    fn a_status_message_is_the_snapshot_tagged_by_class() {
        let mut s = Status::idle();
        s.state = crate::scan::status::State::Suspended;
        let m = serde_json::to_value(Message::Status(Box::new(s))).unwrap();
        assert_eq!(m["class"], "status");
        assert_eq!(m["state"], "suspended");
    }
}
