//! Control-socket wire format and the runner ⇄ server contract.
//!
//! One JSON object per line in both directions, each with a `class` field. The daemon
//! greets every connection with [`Message::Hello`] before anything else; the client then
//! sends one [`Request`] per line. The command set is closed: there is no passthrough to
//! the instrument or the stage.
//!
//! Layer 4 (process edge): serde types plus tokio channel types; no I/O.

use serde::{Deserialize, Serialize};
use tokio::sync::{mpsc, oneshot, watch};

/// Version of this protocol, sent in the greeting; bumped on incompatible changes.
pub const PROTOCOL_VERSION: u32 = 1;

/// Client → daemon.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
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
}

/// What the daemon is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum State {
    /// No scan running; waiting for `start`.
    Idle,
    /// Probing devices, homing, pre-flight.
    Starting,
    /// Tracing lines.
    Scanning,
    /// A pause was requested; the current line finishes first.
    Pausing,
    /// Paused by the operator; `resume` continues.
    Paused,
    /// A device fault suspended the scan; it resumes by itself when the cause clears.
    Suspended,
    /// All lines done: fitting, writing IGES and the report.
    Finishing,
    /// Shutting down (SIGTERM): the current line is abandoned, the scan resumes at next start.
    Stopping,
}

/// Presence of a device as last seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DeviceState {
    /// Not opened (no scan running) and its port path does not exist.
    Absent,
    /// Not opened, but its port path exists.
    Present,
    /// Open and verified.
    Connected,
    /// Lost during a scan; reconnecting with backoff.
    Reconnecting,
}

/// How the last scan ended.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LastStop {
    /// Scan id.
    pub scan_id: String,
    /// `success`, `abort` or `fail`.
    pub status: String,
    /// Why.
    pub reason: String,
    /// Scan directory.
    pub dir: String,
}

/// The status snapshot the runner publishes on every state change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Current state.
    pub state: State,
    /// Scan id of the running (or suspended/paused) scan.
    pub scan_id: Option<String>,
    /// Scan directory.
    pub scan_dir: Option<String>,
    /// Lines completed and on disk.
    pub lines_done: u32,
    /// Lines in the plan.
    pub lines_total: u32,
    /// 1-based number of the line being worked on, for people.
    pub current_line: Option<u32>,
    /// y target of the current line, mm.
    pub y_mm: Option<f64>,
    /// Ra of the last completed line as the instrument reported it, µm.
    pub last_ra_um: Option<f64>,
    /// Estimated seconds until the scan completes.
    pub eta_s: Option<f64>,
    /// Why the scan is suspended/paused/stopping, or the last error.
    pub reason: Option<String>,
    /// The instrument.
    pub instrument: DeviceState,
    /// The stage.
    pub stage: DeviceState,
    /// How the previous scan ended, if one ended since the daemon started.
    pub last_stop: Option<LastStop>,
}

impl Status {
    /// The idle snapshot with no devices known.
    pub fn idle() -> Status {
        Status {
            state: State::Idle,
            scan_id: None,
            scan_dir: None,
            lines_done: 0,
            lines_total: 0,
            current_line: None,
            y_mm: None,
            last_ra_um: None,
            eta_s: None,
            reason: None,
            instrument: DeviceState::Absent,
            stage: DeviceState::Absent,
            last_stop: None,
        }
    }

    /// One line for systemd's `STATUS=` and for logs, e.g.
    /// `scan X: line 12/31, y=0.110 mm`.
    pub fn summary(&self) -> String {
        let state = serde_json::to_value(self.state)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default();
        match (&self.scan_id, self.state) {
            (None, State::Idle) => match &self.last_stop {
                Some(s) if s.scan_id.is_empty() => {
                    format!("idle; last start: {} ({})", s.status, s.reason)
                }
                Some(s) => format!("idle; last scan {}: {} ({})", s.scan_id, s.status, s.reason),
                None => "idle".to_owned(),
            },
            (Some(id), State::Scanning) => {
                let line = self.current_line.unwrap_or(self.lines_done + 1);
                match self.y_mm {
                    Some(y) => format!("scan {id}: line {line}/{}, y={y:.3} mm", self.lines_total),
                    None => format!("scan {id}: line {line}/{}", self.lines_total),
                }
            }
            (Some(id), _) => {
                let mut s = format!(
                    "scan {id}: {state}, {}/{} lines done",
                    self.lines_done, self.lines_total
                );
                if let Some(r) = &self.reason {
                    s.push_str(": ");
                    s.push_str(r);
                }
                s
            }
            (None, _) => state,
        }
    }
}

/// A command for the runner, as the socket server forwards it.
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

/// A forwarded command with the channel for the runner's answer: `Ok(detail)` becomes
/// [`Message::Ack`], `Err(message)` becomes [`Message::Error`].
#[derive(Debug)]
pub struct OperatorRequest {
    /// The command.
    pub command: OperatorCommand,
    /// Where the runner answers.
    pub reply: oneshot::Sender<Result<String, String>>,
}

/// The server's side of the contract: where it reads status and sends commands.
#[derive(Debug, Clone)]
pub struct ControlChannels {
    /// The runner's latest status.
    pub status: watch::Receiver<Status>,
    /// Commands to the runner.
    pub commands: mpsc::Sender<OperatorRequest>,
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
                notes: String::new()
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
    fn status_summary_is_what_systemd_shows() {
        let mut s = Status::idle();
        assert_eq!(s.summary(), "idle");
        s.state = State::Scanning;
        s.scan_id = Some("X".into());
        s.lines_total = 31;
        s.lines_done = 11;
        s.current_line = Some(12);
        s.y_mm = Some(0.11);
        assert_eq!(s.summary(), "scan X: line 12/31, y=0.110 mm");
        s.state = State::Suspended;
        s.reason = Some("instrument absent".into());
        assert_eq!(
            s.summary(),
            "scan X: suspended, 11/31 lines done: instrument absent"
        );
        let m = serde_json::to_value(Message::Status(Box::new(s))).unwrap();
        assert_eq!(m["class"], "status");
        assert_eq!(m["state"], "suspended");
    }
}
