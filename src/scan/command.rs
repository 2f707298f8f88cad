//! Operator commands as the scan runner receives them: the control socket (or any other
//! front end) forwards each with a channel for the runner's answer.
//!
//! Layer 3 (session): depends on tokio's oneshot channel, serde, nix for this process's
//! credentials, and tracing.

use tokio::sync::oneshot;

/// Which scan a start runs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StartMode {
    /// Resume the newest unfinished scan (no stop record), else start a new one.
    #[default]
    Auto,
    /// Resume the newest unfinished scan, else continue the newest failed one at its first
    /// missing line; refused when there is neither.
    Resume,
    /// Start a new scan; unfinished scans are recorded as abandoned.
    New,
}

impl StartMode {
    /// The mode of the `--resume` / `--new` flags (neither: resume an unfinished scan, else
    /// a new one).
    pub fn from_flags(resume: bool, new: bool) -> StartMode {
        match (resume, new) {
            (true, _) => StartMode::Resume,
            (_, true) => StartMode::New,
            _ => StartMode::Auto,
        }
    }
}

/// The operator's pause as the journal's interruption records mark it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PauseMark {
    /// The scan paused after a line (nothing moves until it is resumed).
    Paused,
    /// The paused scan was resumed.
    Resumed,
}

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
        /// Which scan.
        mode: StartMode,
        /// A recipe's scan instead of the station's plan (`start --recipe`), validated by the
        /// control socket before it is forwarded.
        recipe: Option<Box<RecipeStart>>,
    },
}

/// `surfscan start --recipe`: the recipe as read when the command came, and the y of the
/// first line the operator gave.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecipeStart {
    /// The recipe, frozen (no queue number: it is not a queued job).
    pub record: super::journal::JobRecord,
    /// y of the first line (overrides the recipe's).
    pub y_start: Option<crate::units::Nm>,
}

/// Who sent a command: the peer's credentials as the kernel gave them when it connected
/// to the control socket (`SO_PEERCRED`), for the journal. A command given on the station's
/// page is carried out by the daemon's own process on behalf of the page's user: its
/// credentials are the daemon's, and [`Peer::web`] names the user and where they were; one
/// given over MQTT likewise, and [`Peer::mqtt`] names the client id it came from.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Peer {
    /// User id.
    pub uid: u32,
    /// Primary group id.
    pub gid: u32,
    /// Process id; `None` when the kernel could not name it (a peer in another PID
    /// namespace).
    pub pid: Option<u32>,
    /// The page's user who gave the command, when it came from the station's page.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub web: Option<WebUser>,
    /// The MQTT client id of the command's topic, when it came over MQTT (the broker's ACL
    /// lets a client write only its own command topic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mqtt: Option<String>,
}

/// The user of the station's page who gave a command, as the journal records it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct WebUser {
    /// The user's name in `[web] token-file`.
    pub user: String,
    /// The address the request came from (`IP:port`).
    pub address: String,
}

impl Peer {
    /// This process, for commands that do not come over the socket.
    pub fn this_process() -> Peer {
        Peer {
            uid: nix::unistd::geteuid().as_raw(),
            gid: nix::unistd::getegid().as_raw(),
            pid: Some(std::process::id()),
            web: None,
            mqtt: None,
        }
    }

    /// The daemon's process on behalf of the page's `user` at `address`.
    pub fn on_behalf_of(user: &str, address: &str) -> Peer {
        Peer {
            web: Some(WebUser {
                user: user.to_owned(),
                address: address.to_owned(),
            }),
            ..Peer::this_process()
        }
    }

    /// The daemon's process on behalf of the MQTT client `client_id`.
    pub fn mqtt_client(client_id: &str) -> Peer {
        Peer {
            mqtt: Some(client_id.to_owned()),
            ..Peer::this_process()
        }
    }

    /// Who it is, for the journal's words and logs: `uid 1000 gid 100 pid 4242`,
    /// `web user alice from 10.0.0.7:51234`, or `MQTT client line-3-mes`.
    pub fn describe(&self) -> String {
        if let Some(id) = &self.mqtt {
            return format!("MQTT client {id}");
        }
        match &self.web {
            Some(w) => format!("web user {} from {}", w.user, w.address),
            None => format!(
                "uid {} gid {} pid {}",
                self.uid,
                self.gid,
                self.pid.map_or("unknown".to_owned(), |p| p.to_string())
            ),
        }
    }

    /// The same without the group: `uid 1000 pid 4242`, or the web user or MQTT client.
    pub fn describe_briefly(&self) -> String {
        if self.web.is_some() || self.mqtt.is_some() {
            return self.describe();
        }
        format!(
            "uid {} pid {}",
            self.uid,
            self.pid.map_or("unknown".to_owned(), |p| p.to_string())
        )
    }
}

/// A forwarded command with the channel for the runner's answer: `Ok(detail)` when it was
/// accepted (the control socket sends an `ack`), `Err(message)` when refused.
#[derive(Debug)]
pub struct OperatorRequest {
    /// The command.
    pub command: OperatorCommand,
    /// Who sent it.
    pub peer: Peer,
    /// Where the runner answers.
    pub reply: oneshot::Sender<Result<String, String>>,
}

impl OperatorRequest {
    /// Whether whoever sent it has stopped waiting for the answer: the control socket gave
    /// up on the runner and told the operator the command was not carried out. Such a
    /// command is dropped, never carried out late (a `start` queued while the runner was
    /// busy would otherwise begin a scan the operator was told had not started).
    pub fn abandoned(&self) -> bool {
        self.reply.is_closed()
    }

    /// The request, unless it is [abandoned](Self::abandoned): then it is dropped and the
    /// drop logged with the command and its sender.
    pub fn unless_abandoned(self) -> Option<OperatorRequest> {
        if !self.abandoned() {
            return Some(self);
        }
        tracing::warn!(
            "dropped {:?} from {}: the control socket stopped waiting for it and told the operator it was not carried out",
            self.command,
            self.peer.describe_briefly()
        );
        None
    }
}
