//! One request carried out, whichever front end received it (the control socket, the
//! station's page): a status snapshot, or an operator command forwarded to the scan runner
//! with a bounded wait for its answer. The front end decides who sent it and whether they may
//! command; `watch` is the front end's own (a stream, not an answer).
//!
//! Layer 4 (process edge): depends on [`super::protocol`], the scan's status and command types
//! and tokio's channels and timer.

use super::protocol::{ControlChannels, Message, Request};
use crate::scan::command::{OperatorCommand, OperatorRequest, Peer};
use crate::scan::status::Status;
use std::time::Duration;
use tokio::sync::{oneshot, watch};

/// The answer to `request`. `who(name)` is asked only for a command (`name` is its class) and
/// gives the peer to record with it, or the refusal to answer with; `reply_timeout` bounds
/// the wait for the runner. `watch` is answered with an error: the front end streams it.
pub async fn dispatch(
    request: Request,
    channels: &ControlChannels,
    who: impl FnOnce(&'static str) -> Result<Peer, Message>,
    reply_timeout: Duration,
) -> Message {
    let command = match request {
        Request::Status => return Message::Status(Box::new(channels.status.borrow().clone())),
        Request::Watch => {
            return Message::Error {
                message: "watch is a stream of status messages, served by the front end".into(),
            }
        }
        Request::Pause => OperatorCommand::Pause,
        Request::Resume => OperatorCommand::Resume,
        Request::Abort => OperatorCommand::Abort,
        Request::Start {
            specimen,
            operator,
            notes,
            mode,
        } => OperatorCommand::Start {
            specimen,
            operator,
            notes,
            mode,
        },
    };
    let peer = match who(command_name(&command)) {
        Ok(peer) => peer,
        Err(refusal) => return refusal,
    };
    forward(command, peer, channels, reply_timeout).await
}

/// The latest status as a message; `mark_seen` marks it seen for a watcher's `changed()`.
pub fn snapshot(status: &mut watch::Receiver<Status>, mark_seen: bool) -> Message {
    let s = if mark_seen {
        status.borrow_and_update().clone()
    } else {
        status.borrow().clone()
    };
    Message::Status(Box::new(s))
}

/// The request class a command is sent as.
pub fn command_name(command: &OperatorCommand) -> &'static str {
    match command {
        OperatorCommand::Pause => "pause",
        OperatorCommand::Resume => "resume",
        OperatorCommand::Abort => "abort",
        OperatorCommand::Start { .. } => "start",
    }
}

/// Sends a command to the runner and turns its answer into `Ack` or `Error`.
async fn forward(
    command: OperatorCommand,
    peer: Peer,
    channels: &ControlChannels,
    reply_timeout: Duration,
) -> Message {
    let name = command_name(&command);
    let gone = || {
        Message::Error {
        message: format!(
            "the scan runner is not running, so {name} cannot be carried out; see `journalctl -u surfscan` and restart the daemon"
        ),
    }
    };
    let (reply, mut answer) = oneshot::channel();
    let exchange = async {
        channels
            .commands
            .send(OperatorRequest {
                command,
                peer,
                reply,
            })
            .await
            .map_err(|_| ())?;
        (&mut answer).await.map_err(|_| ())
    };
    let answered = |r: Result<String, String>| match r {
        Ok(detail) => Message::Ack {
            command: name.to_owned(),
            detail,
        },
        Err(message) => Message::Error { message },
    };
    match tokio::time::timeout(reply_timeout, exchange).await {
        Ok(Ok(r)) => answered(r),
        Ok(Err(())) => gone(),
        Err(_elapsed) => {
            // The operator is told the command was not carried out, so it must not be: a
            // closed channel tells the runner, when it comes to the command, that its
            // requester has gone ([`OperatorRequest::abandoned`]). An answer sent before the
            // close still counts.
            answer.close();
            match answer.try_recv() {
                Ok(r) => answered(r),
                Err(_) => Message::Error {
                    message: format!(
                        "the scan runner did not answer {name} within {} s (it is busy with a device, or writing a scan's outputs); {name} was not carried out: try again, or see `journalctl -u surfscan`",
                        reply_timeout.as_secs_f64()
                    ),
                },
            }
        }
    }
}
