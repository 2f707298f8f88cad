//! One request carried out, whichever front end received it (the control socket, the
//! station's page): a status snapshot, an operator command forwarded to the scan runner
//! with a bounded wait for its answer, or a queue command carried out by the daemon's
//! [`QueueService`](crate::jobs::service::QueueService). The front end decides who sent it and whether they may
//! command; `watch` is the front end's own (a stream, not an answer).
//!
//! Layer 4 (process edge): depends on [`super::protocol`], the scan's status and command types,
//! the job queue's service and tokio's channels and timer.

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
        Request::Status => return with_queue(channels.status.borrow().clone(), channels),
        Request::Watch => {
            return Message::Error {
                message: "watch is a stream of status messages, served by the front end".into(),
            }
        }
        Request::QueueList => {
            return match &channels.queue {
                Some(q) => Message::Queue(Box::new(q.snapshot())),
                None => no_queue("queue-list"),
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
            recipe,
            y_start_mm,
        } => {
            let recipe = match recipe {
                None if y_start_mm.is_some() => {
                    return Message::Refused {
                        message: "--y-start-mm belongs to a recipe's scan: give --recipe NAME too (the station's plan has its own [scan] y-start-mm)".into(),
                        exit: 2,
                    }
                }
                None => None,
                Some(name) => match recipe_start(name, y_start_mm, channels, reply_timeout).await {
                    Ok(r) => Some(Box::new(r)),
                    Err(refusal) => return refusal,
                },
            };
            OperatorCommand::Start {
                specimen,
                operator,
                notes,
                mode,
                recipe,
            }
        }
        queue_request => return queue_command(queue_request, channels, who, reply_timeout).await,
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

/// `status` with the job queue's state as it is now (the queue changes while a scan runs;
/// the runner's snapshots do not follow it).
fn with_queue(mut s: Status, channels: &ControlChannels) -> Message {
    if let Some(q) = &channels.queue {
        s.queue = Some(Box::new(q.status()));
    }
    Message::Status(Box::new(s))
}

/// The latest status with the job queue's state; `mark_seen` marks it seen for a watcher's
/// `changed()`.
pub fn status_with_queue(channels: &mut ControlChannels, mark_seen: bool) -> Message {
    let s = if mark_seen {
        channels.status.borrow_and_update().clone()
    } else {
        channels.status.borrow().clone()
    };
    with_queue(s, channels)
}

/// `start --recipe NAME`: the recipe read and validated now by the queue's keeper (which
/// knows the station's configuration), frozen for the daemon; else the refusal with its
/// exit status.
async fn recipe_start(
    name: String,
    y_start_mm: Option<f64>,
    channels: &ControlChannels,
    reply_timeout: Duration,
) -> Result<crate::scan::command::RecipeStart, Message> {
    let Some(queue) = channels.queue.clone() else {
        return Err(no_queue("start --recipe"));
    };
    let done = tokio::task::spawn_blocking(move || queue.recipe_start(&name, y_start_mm));
    match tokio::time::timeout(reply_timeout, done).await {
        Ok(Ok(Ok(r))) => Ok(r),
        Ok(Ok(Err(e))) => Err(Message::Refused {
            message: e.to_string(),
            exit: e.exit_code(),
        }),
        Ok(Err(e)) => Err(Message::Error {
            message: format!("start --recipe: reading the recipe failed ({e})"),
        }),
        Err(_) => Err(Message::Error {
            message: format!(
                "start --recipe: the recipe could not be read within {} s (a slow disk?); nothing was started",
                reply_timeout.as_secs()
            ),
        }),
    }
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

fn no_queue(name: &str) -> Message {
    Message::Error {
        message: format!(
            "{name}: this process keeps no job queue; the station's daemon does (`surfscan daemon`)"
        ),
    }
}

/// A queue command carried out by the queue's keeper (blocking: it writes the queue
/// durably), answered with `Ack`, or `Refused` with the exit status the command gives.
async fn queue_command(
    request: Request,
    channels: &ControlChannels,
    who: impl FnOnce(&'static str) -> Result<Peer, Message>,
    reply_timeout: Duration,
) -> Message {
    use crate::jobs::service::{AddJob, QueueService, ServiceError};
    type Work = Box<dyn FnOnce(&QueueService, Peer) -> Result<String, ServiceError> + Send>;
    let (name, work): (&'static str, Work) = match request {
        Request::QueueAdd {
            recipe,
            specimen,
            operator,
            notes,
            y_start_mm,
            needs_loading,
        } => (
            "queue-add",
            Box::new(move |q: &QueueService, peer| {
                let add = AddJob {
                    recipe,
                    specimen,
                    operator,
                    notes,
                    y_start_mm,
                    needs_loading,
                };
                q.add(add, Some(peer)).map(|j| {
                    let ahead = q.snapshot().pending().filter(|p| p.id < j.id).count();
                    let when = match ahead {
                        0 => "it is next".to_owned(),
                        n => format!("{n} before it"),
                    };
                    format!("queued {} ({when})", j.describe())
                })
            }),
        ),
        Request::QueueRemove { job } => (
            "queue-remove",
            Box::new(move |q: &QueueService, peer| {
                q.remove(job, Some(peer))
                    .map(|j| format!("removed {}", j.describe()))
            }),
        ),
        Request::QueueClear => (
            "queue-clear",
            Box::new(|q: &QueueService, peer| {
                q.clear(Some(peer)).map(|gone| match gone.len() {
                    0 => "no job was queued".to_owned(),
                    n => format!("{n} queued jobs removed (a running job goes on)"),
                })
            }),
        ),
        Request::QueueContinue => (
            "queue-continue",
            Box::new(|q: &QueueService, peer| {
                q.release(Some(peer))
                    .map(|()| "the queue runs on with its next job".to_owned())
            }),
        ),
        Request::Ready { job } => {
            (
                "ready",
                Box::new(move |q: &QueueService, peer| {
                    q.ready(job, Some(peer))
                    .map(|id| format!("job {id}: specimen loaded; the job starts as soon as the station is free"))
                }),
            )
        }
        other => {
            return Message::Error {
                message: format!("{other:?} is not a queue request"),
            }
        }
    };
    let peer = match who(name) {
        Ok(p) => p,
        Err(refusal) => return refusal,
    };
    let Some(queue) = channels.queue.clone() else {
        return no_queue(name);
    };
    let done = tokio::task::spawn_blocking(move || work(&queue, peer));
    match tokio::time::timeout(reply_timeout, done).await {
        Ok(Ok(Ok(detail))) => Message::Ack {
            command: name.to_owned(),
            detail,
        },
        Ok(Ok(Err(e))) => Message::Refused {
            message: e.to_string(),
            exit: e.exit_code(),
        },
        Ok(Err(e)) => Message::Error {
            message: format!("{name}: the queue's keeper failed ({e}); see `journalctl -u surfscan`"),
        },
        Err(_) => Message::Error {
            message: format!(
                "{name}: the queue did not answer within {} s (a slow disk?); the command may still be carried out — check `surfscan queue list`",
                reply_timeout.as_secs()
            ),
        },
    }
}
