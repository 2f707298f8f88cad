//! The scan runner: performs the session machine's actions ([`super::machine`]) on the
//! devices, the disk and the channels, and feeds each result back as an event with the time
//! it happened. Every decision (fault classes, retries, suspension, pause, abort) is the
//! machine's; the runner only executes, answers commands while a device operation is in
//! flight, and drops that operation when the machine cancels it.
//!
//! Per line the machine asks, in order: instrument idle, move, trace, commit (line files,
//! then the journal record; [`ScanStore::commit_line`](super::store::ScanStore::commit_line)),
//! push into the fitter. Only then does the next move happen.
//!
//! Layer 3 (session): depends on [`super::machine`], [`super::device_ops`] (devices),
//! [`super::disk_ops`], [`super::ledger`] and [`super::opening`] (disk),
//! [`super::channels`], the session's own settings, status, command, event and outcome types,
//! [`super::reasons`]' words for a bug in the outputs, and [`super::journal`], whose stop
//! record a reopening that panicked is recorded by.

use super::channels::Control;
use super::command::{OperatorRequest, PauseMark, Peer};
use super::device_ops::{is_device_effect, Hands};
use super::disk_ops::Books;
use super::ending::{End, FailKind, FailReason, StopStatus};
use super::event::ScanEvent;
use super::journal::{Journal, StopRecord, JOURNAL_FILE};
use super::ledger::Ledger;
use super::machine::{Action, Event, Machine, Now, Policy};
use super::opening::{self, NewScan, Refusal};
use super::outcome::{Outcome, ScanRequest};
use super::reasons;
use super::settings::RunSettings;
use super::station::Station;
use super::status::ended_status;
use crate::devices::InstrumentIdentity;
use crate::stage::policy::ScanDirection;
use chrono::Utc;
use std::collections::VecDeque;
use std::future::Future;
use std::path::PathBuf;

pub use super::line_check::conditions_difference;
pub use super::opening::estimate_line_seconds;

fn now() -> Now {
    Now {
        mono: tokio::time::Instant::now().into_std(),
        wall: Utc::now(),
    }
}

/// Runs one scan to its end.
pub async fn run_scan<S: Station>(
    station: &mut S,
    ctl: &mut Control,
    settings: &RunSettings,
    request: ScanRequest,
) -> Outcome {
    let policy = Policy {
        backoff: settings.backoff,
        transient_budget: settings.transient_budget,
        home_on_start: settings.home_on_start,
    };
    let before = ctl.status.borrow().clone();
    let mut books = Books {
        settings,
        ledger: None,
        new_scan: None,
        held: None,
        committed: None,
        outputs: None,
        reply: None,
        end: None,
        stop_error: None,
    };
    let mut hands = Hands {
        station,
        instrument: None,
        stage: None,
        direction: ScanDirection::of_step(settings.plan.y_step_nm),
        targets: settings.plan.targets(),
        probe: None,
        warnings: Vec::new(),
        stage_identity: None,
        identity: None,
        readback: None,
        ra_before: Vec::new(),
        closing: Vec::new(),
    };
    let reopening = match request {
        ScanRequest::New {
            specimen,
            operator,
            notes,
            peer,
            job,
        } => {
            books.new_scan = Some(NewScan {
                specimen,
                operator,
                notes,
                peer: peer.or_else(|| Some(Peer::this_process())),
                job,
            });
            None
        }
        ScanRequest::Resume { dir, peer } => Some((dir, peer, false)),
        ScanRequest::Continue { dir, peer } => Some((dir, peer, true)),
    };
    // A new scan runs with the configuration's settings; a resumed one with those its start
    // record froze (set below, once its journal is read).
    hands.station.freeze(None);
    let mut machine = match reopening {
        None => Machine::new_scan(settings.plan.clone(), policy, before),
        Some((dir, peer, after_failure)) => {
            // Reading back every committed line and refitting them takes seconds for a large
            // scan: done beside the loop, which meanwhile feeds the watchdog.
            let settings = settings.clone();
            let at = dir.clone();
            match reopened(ctl, at, move || {
                reopen(&settings, &dir, peer, after_failure)
            })
            .await
            {
                Ok((resumed, mut l)) => {
                    for kept in hands.station.freeze(Some(&l.start.config)) {
                        l.note(&super::machine::Note {
                            reason: kept,
                            device: None,
                            line: None,
                            peer: None,
                            pause: None,
                        });
                    }
                    hands.attach(&l);
                    let plan = l.plan.clone();
                    books.ledger = Some(l);
                    Machine::resumed(plan, policy, before, resumed)
                }
                Err(refusal) => return refusal,
            }
        }
    };
    drive(&mut machine, &mut hands, &mut books, ctl).await;
    finish(ctl, &machine, books)
}

/// Reopens a scan directory for the machine; the refusal (reason and class) when it cannot
/// be run.
fn reopen(
    settings: &RunSettings,
    dir: &std::path::Path,
    peer: Option<Peer>,
    after_failure: bool,
) -> Result<(super::machine::Resumed, Ledger), (String, Refusal)> {
    let r = opening::reopen(settings, dir, after_failure)?;
    let (mut ledger, mut resumed) = (r.ledger, r.resumed);
    let mut note = match &r.failed {
        Some(reason) => format!("{}; it had failed: {reason}", r.note),
        None => r.note.clone(),
    };
    // A scan the operator had paused stays paused when the daemon reopens it by itself at
    // start-up (no peer); an operator's own start (`surfscan scan`, `surfscan start`) is the
    // resumption.
    let mut pause = None;
    if resumed.paused {
        if peer.is_some() {
            resumed.paused = false;
            pause = Some(PauseMark::Resumed);
            note.push_str("; it had been paused by the operator, and this start resumes it");
        } else {
            note.push_str(
                "; it had been paused by the operator and stays paused until `surfscan resume`",
            );
        }
    }
    if r.failed.is_some() {
        ledger
            .reopen_failed(peer.clone())
            .map_err(|e| opening::refusal("recording the continuation", &e))?;
    }
    ledger.note(&super::machine::Note {
        reason: note,
        device: None,
        line: None,
        peer,
        pause,
    });
    Ok((resumed, ledger))
}

/// Reopens the scan in `dir` by `work` ([`watched`]); the outcome when it cannot be run.
///
/// A refusal that is the scan's ending ([`Refusal::ends_the_scan`]: its files cannot be read
/// back as a scan, or reopening panicked, a bug) is recorded as such in its journal (`fail`,
/// cause `operator`, `internal` for a bug): the daemon at start-up and its queue leave such a
/// scan alone, so it is not reopened again at every start and every turn of the queue; only
/// the operator's `--resume` tries it again. The status's last stop, the `fail` event and the
/// outcome (exit 1, or 70 for a bug) say the same. A refusal by the file system can clear
/// by itself: the scan is left as it is (no record, no event, its last stop not a stop:
/// the idle status's reason names it and the fix), and the outcome names it for its job to
/// wait. So is a scan whose ending the file system refused to record (a full or read-only
/// disk): nothing tells it ended before its journal says so, and the next reopening, once
/// the file system takes the record, records it. Work cancelled as the process shuts down
/// is a shutdown's outcome with the scan: nothing recorded, its job goes on, and the scan
/// resumes at the next start.
/// Any other refusal (the scan has ended, a directory that is not one) is without the scan.
async fn reopened<T: Send + 'static>(
    ctl: &Control,
    dir: PathBuf,
    work: impl FnOnce() -> Result<T, (String, Refusal)> + Send + 'static,
) -> Result<T, Outcome> {
    let (message, refusal) = match refusal_of(watched(ctl, "reopening the scan", work).await) {
        Ok(reopened) => return Ok(reopened),
        Err(refusal) => refusal,
    };
    if refusal == Refusal::Shutdown {
        tracing::warn!(
            "{}: {message}; the scan is left as it was and resumes at the next start",
            dir.display()
        );
        return Err(Outcome {
            end: End::Shutdown,
            dir: Some(dir),
            outputs: None,
        });
    }
    let end = End::Fail(FailReason::Refused {
        message,
        kind: refusal.kind(),
    });
    let words = match end.stop_record() {
        Some(words) if refusal != Refusal::Left => words,
        _ => return Err(refused(ctl, end)),
    };
    if !refusal.ends_the_scan() {
        tracing::error!("{}: {}", dir.display(), words.reason);
        return Err(waits_for_the_file_system(ctl, dir, words.reason));
    }
    let path = dir.join(JOURNAL_FILE);
    let stop = StopRecord {
        status: words.status,
        reason: words.reason.clone(),
        cause: words.cause,
        internal: words.internal,
        time: Utc::now(),
    };
    let time = stop.time;
    let recorded = refusal_of(
        watched(ctl, "recording the scan's ending", move || {
            Journal::append_stop(&path, stop)
                .map_err(|e| opening::refusal("recording the scan's ending", &e))
        })
        .await,
    );
    match recorded {
        Ok(()) => tracing::error!(
            "{}: {}; recorded as its ending: the daemon does not reopen it again, `surfscan scan --resume` does",
            dir.display(),
            words.reason
        ),
        // Told as ended only once recorded as ended: the scan is left as it is, as when
        // the file system refused reopening it, and its ending is recorded when it is
        // reopened again and the file system takes the record.
        Err((why, Refusal::FileSystem)) => {
            tracing::error!(
                "{}: {}; its ending could not be recorded: {why}",
                dir.display(),
                words.reason
            );
            return Err(waits_for_the_file_system(ctl, dir, why));
        }
        Err((why, Refusal::Shutdown)) => {
            tracing::warn!(
                "{}: {}; its ending was not recorded ({why}): the scan is left as it was and reopened at the next start",
                dir.display(),
                words.reason
            );
            return Err(Outcome {
                end: End::Shutdown,
                dir: Some(dir),
                outputs: None,
            });
        }
        // The journal cannot be read back to append to (a damaged record): the daemon
        // skips such a scan, as it skips any damaged journal, and never reopens it.
        Err((why, _)) => tracing::error!(
            "{}: {}; its ending could not be recorded ({why}): the scan is skipped as long as its journal is damaged",
            dir.display(),
            words.reason
        ),
    }
    let scan_id = scan_id_of(&dir);
    let mut s = ended_status(&ctl.status.borrow(), words.status, &words.reason);
    if let Some(last) = s.last_stop.as_mut() {
        last.scan_id.clone_from(&scan_id);
        last.dir = dir.display().to_string();
        last.internal = words.internal;
    }
    ctl.publish(s);
    if let Some(kind) = end.event(true) {
        ctl.event(ScanEvent {
            scan_id,
            dir: dir.clone(),
            kind,
            reason: words.reason,
            time,
            internal: end.tells_internal(kind),
            results: None,
        });
    }
    Err(Outcome {
        end,
        dir: Some(dir),
        outputs: None,
    })
}

/// The scan's id: its directory's name.
fn scan_id_of(dir: &std::path::Path) -> String {
    dir.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The outcome of a scan in `dir` left as it is because the file system refused reopening
/// it or recording its ending, `why` (with the fix): nothing recorded, no event; the idle
/// status's reason names the scan, and its last stop stays the last scan that ended (this
/// one has not); the outcome (exit 74) names the scan for its job, which waits.
fn waits_for_the_file_system(ctl: &Control, dir: PathBuf, why: String) -> Outcome {
    let mut s = ended_status(&ctl.status.borrow(), StopStatus::Fail, &why);
    s.last_stop.clone_from(&ctl.status.borrow().last_stop);
    s.reason = Some(format!(
        "scan {} ({}) waits for the file system: {why}",
        scan_id_of(&dir),
        dir.display()
    ));
    ctl.publish(s);
    Outcome {
        end: End::Fail(FailReason::Refused {
            message: why,
            kind: FailKind::Io,
        }),
        dir: Some(dir),
        outputs: None,
    }
}

/// The reopening's result, or its refusal: [`watched`] work that panicked is a bug's,
/// work the runtime cancelled as it shuts down a shutdown's.
fn refusal_of<T>(
    done: Result<Result<T, (String, Refusal)>, (String, FailKind)>,
) -> Result<T, (String, Refusal)> {
    match done {
        Ok(reopened) => reopened,
        Err((message, FailKind::Internal)) => Err((message, Refusal::Bug)),
        Err((message, _)) => Err((message, Refusal::Shutdown)),
    }
}

fn refused(ctl: &Control, end: End) -> Outcome {
    let message = end.reason(false);
    tracing::error!("scan cannot start: {message}");
    let s = ended_status(&ctl.status.borrow(), StopStatus::Fail, &message);
    ctl.publish(s);
    Outcome::without_scan(end)
}

/// The executor loop: actions out of the machine performed, results fed back, commands and
/// shutdown fed while a device operation is in flight.
async fn drive<S: Station>(
    machine: &mut Machine,
    hands: &mut Hands<'_, S>,
    books: &mut Books<'_>,
    ctl: &mut Control,
) {
    let mut queue: VecDeque<Action> = machine.start(now()).into();
    let mut shutdown_fed = false;
    loop {
        let Some(action) = queue.pop_front() else {
            if machine.ended() {
                return;
            }
            // Nothing in flight (paused): wait for a command or the shutdown.
            let ev = wait_for_operator(ctl, books, &mut shutdown_fed).await;
            queue.extend(machine.handle(ev, now()));
            continue;
        };
        if !action.is_effect() {
            if let Action::Close(d) = action {
                // Closing a serial port waits for its unsent bytes to drain (up to the
                // driver's closing wait, 30 s by default): never on this loop's thread.
                hands.close(d);
            }
            books.immediate(ctl, action);
            continue;
        }
        if action == Action::WriteOutputs {
            let ev = write_outputs_watched(books, ctl).await;
            queue.extend(machine.handle(ev, now()));
            continue;
        }
        if !is_device_effect(&action) {
            let points = hands.points();
            let ev = books.disk(&action, hands.probe.as_ref(), points);
            if matches!(ev, Event::Created { .. }) {
                if let Some(l) = &books.ledger {
                    hands.identity = Some(InstrumentIdentity {
                        model: l.start.instrument_model.clone(),
                        firmware: l.start.firmware.clone(),
                        drive_unit: l.start.drive_unit.clone(),
                    });
                }
                if let Some(l) = books.ledger.as_mut() {
                    for w in std::mem::take(&mut hands.warnings) {
                        l.note(&super::machine::Note {
                            reason: format!("warning at start: {w}"),
                            device: None,
                            line: None,
                            peer: None,
                            pause: None,
                        });
                    }
                }
            }
            queue.extend(machine.handle(ev, now()));
            continue;
        }
        if !shutdown_fed && ctl.shutting_down() && action != Action::Cleanup {
            shutdown_fed = true;
            queue.clear();
            queue.extend(machine.handle(Event::Shutdown, now()));
            continue;
        }
        let cleanup = action == Action::Cleanup;
        let ev = {
            let mut held = books.held.take();
            // A test's stuck future (SURFSCAN_TEST_STALL), with its shorter limit.
            let stall = match action {
                Action::Trace => books.settings.hooks.trace_stalls(),
                _ => None,
            };
            if action == Action::Trace {
                hands.ra_before = books
                    .ledger
                    .as_ref()
                    .map(|l| l.ra_before(machine.line()))
                    .unwrap_or_default();
            }
            let perform = hands.perform(&action, &mut held);
            let fut = async move {
                if stall.is_some() {
                    std::future::pending::<()>().await;
                }
                perform.await
            };
            let out = if cleanup {
                Some(fut.await)
            } else {
                let limit = stall.unwrap_or(books.settings.longest_effect);
                guarded(
                    fut,
                    limit,
                    machine,
                    books,
                    ctl,
                    &mut queue,
                    &mut shutdown_fed,
                )
                .await
            };
            if held.is_some() {
                books.held = held;
            }
            out
        };
        if let Some(ev) = ev {
            queue.extend(machine.handle(ev, now()));
        }
    }
}

/// How long [`watched`] work may keep the watchdog fed. Writing the outputs of the largest
/// scans (10⁷ points: the IGES parts, the report, the plots) takes minutes; work that runs
/// longer than this is taken for hung, and systemd restarts the daemon (an unfinished scan
/// then resumes).
const WATCHED_LIMIT: std::time::Duration = std::time::Duration::from_secs(3600);

/// Runs `work` (disk and CPU work of seconds: reopening a scan, writing its outputs) on a
/// blocking thread of its own while this loop goes on feeding the watchdog, so that systemd
/// does not take a long piece of work for a hung daemon; for at most [`WATCHED_LIMIT`].
/// `Err` if the runtime cancelled the work (it shuts down) or `work` panicked ([`joined`]):
/// the scan then fails with that reason (a reopening cancelled is a shutdown's,
/// [`refusal_of`]), and the daemon serves on.
async fn watched<T: Send + 'static>(
    ctl: &Control,
    what: &str,
    work: impl FnOnce() -> T + Send + 'static,
) -> Result<T, (String, FailKind)> {
    let mut task = tokio::task::spawn_blocking(work);
    let mut tick = ctl.watchdog_tick();
    let started = tokio::time::Instant::now();
    let mut warned = false;
    loop {
        tokio::select! {
            done = &mut task => return joined(done, what),
            _ = tick.tick() => {
                if started.elapsed() < WATCHED_LIMIT {
                    ctl.pet();
                } else if !warned {
                    warned = true;
                    tracing::error!(
                        "{what} has taken over {} s; no longer feeding the watchdog, so systemd restarts the daemon if it is hung",
                        WATCHED_LIMIT.as_secs()
                    );
                }
            }
        }
    }
}

/// The result of [`watched`] work: a panic in it as the reason the scan stops, in words
/// (its place and message are in the log, printed by the panic hook), of the class of a bug
/// (exit 70); work the runtime cancelled as it shuts down, of the scan's.
fn joined<T>(done: Result<T, tokio::task::JoinError>, what: &str) -> Result<T, (String, FailKind)> {
    match done {
        Ok(v) => Ok(v),
        Err(e) if e.is_panic() => Err((panicked(what, &*e.into_panic()), FailKind::Internal)),
        Err(e) => Err((
            format!("internal: {what} was cancelled: {e}"),
            FailKind::Scan,
        )),
    }
}

/// Why the scan stops after `what` panicked with `payload`.
fn panicked(what: &str, payload: &(dyn std::any::Any + Send)) -> String {
    let message = crate::panics::message(payload);
    format!("internal error: {what} panicked ({message}); report this with the scan's directory and the log")
}

/// Writes the scan's outputs [`watched`], with the ledger moved to the worker and back. A
/// panic is [`Event::OutputsPanicked`]: an internal error, not the disk's.
async fn write_outputs_watched(books: &mut Books<'_>, ctl: &Control) -> Event {
    let Some(mut ledger) = books.ledger.take() else {
        // Says so as the effect itself does.
        return books.disk(&Action::WriteOutputs, None, 0);
    };
    let dir = ledger.dir.clone();
    let characterise = books.settings.characterise.clone();
    // A panic is caught here rather than by `watched`, so that the ledger comes back to
    // write the failed scan's stop record (the journal then says why, and the scan is not
    // resumed into the same outputs at the next start). Only its journal is used after it.
    let done = watched(ctl, "writing the outputs", move || {
        let written = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            ledger.write_outputs(characterise.as_deref())
        }));
        (ledger, written)
    })
    .await;
    match done {
        Ok((ledger, written)) => {
            books.ledger = Some(ledger);
            match written {
                Ok(written) => books.outputs_event(written),
                Err(p) => Event::OutputsPanicked(reasons::outputs_internal(
                    crate::panics::message(&*p),
                    &dir,
                )),
            }
        }
        // Cancelled by the runtime's shutdown (the panic is caught above): the ledger is
        // gone, so no stop record can say it.
        Err((message, _)) => Event::OutputsPanicked(message),
    }
}

/// Awaits a device effect while feeding commands and shutdown to the machine; `None` when
/// the machine cancelled it (the actions that follow the cancel are queued). The watchdog is
/// fed while the effect is within `limit`, the longest any device effect can take (every
/// device operation has its own deadline): an effect that outlasts it is a stuck future,
/// and the unfed watchdog gets the daemon restarted (the scan then resumes).
async fn guarded(
    fut: impl Future<Output = Event>,
    limit: std::time::Duration,
    machine: &mut Machine,
    books: &mut Books<'_>,
    ctl: &mut Control,
    queue: &mut VecDeque<Action>,
    shutdown_fed: &mut bool,
) -> Option<Event> {
    tokio::pin!(fut);
    let mut tick = ctl.watchdog_tick();
    let started = tokio::time::Instant::now();
    let mut stuck = false;
    loop {
        let ev = tokio::select! {
            out = &mut fut => return Some(out),
            Ok(()) = ctl.shutdown.changed() => {
                if !ctl.shutting_down() || *shutdown_fed {
                    continue;
                }
                *shutdown_fed = true;
                Event::Shutdown
            }
            Some(req) = ctl.commands.recv() => match command_event(books, req) {
                Some(ev) => ev,
                None => continue,
            },
            _ = tick.tick() => {
                if started.elapsed() < limit {
                    ctl.pet();
                } else if !stuck {
                    stuck = true;
                    tracing::error!(
                        "a device operation has taken over {} s, longer than any can; no longer feeding the watchdog, so systemd restarts the daemon and the scan resumes",
                        limit.as_secs()
                    );
                }
                continue;
            }
        };
        let actions = machine.handle(ev, now());
        let mut it = actions.into_iter();
        let mut cancelled = false;
        for a in it.by_ref() {
            if a == Action::Cancel {
                cancelled = true;
                break;
            }
            if a.is_effect() {
                queue.push_back(a);
                continue;
            }
            books.immediate(ctl, a);
        }
        if cancelled {
            queue.clear();
            queue.extend(it);
            return None;
        }
    }
}

/// The machine's event for a command; `None` (and the command dropped, with a log line)
/// when its requester was already told it was not carried out.
fn command_event(books: &mut Books<'_>, req: OperatorRequest) -> Option<Event> {
    let req = req.unless_abandoned()?;
    books.reply = Some(req.reply);
    Some(Event::Command {
        command: req.command,
        peer: req.peer,
    })
}

/// Waits (nothing in flight) for a command or the shutdown, feeding the watchdog.
async fn wait_for_operator(
    ctl: &mut Control,
    books: &mut Books<'_>,
    shutdown_fed: &mut bool,
) -> Event {
    let mut tick = ctl.watchdog_tick();
    loop {
        if ctl.shutting_down() && !*shutdown_fed {
            *shutdown_fed = true;
            return Event::Shutdown;
        }
        tokio::select! {
            Ok(()) = ctl.shutdown.changed() => {}
            req = ctl.commands.recv() => match req {
                Some(req) => {
                    if let Some(ev) = command_event(books, req) {
                        return ev;
                    }
                }
                // Nobody can ever command (no control channel): wait for shutdown only.
                None => {
                    let _ = ctl.shutdown.wait_for(|v| *v).await;
                }
            },
            _ = tick.tick() => ctl.pet(),
        }
    }
}

/// Makes the outcome of the ended scan.
fn finish(ctl: &Control, machine: &Machine, mut books: Books<'_>) -> Outcome {
    let end = books.end.take().unwrap_or(End::Shutdown);
    let Some(l) = books.ledger.take() else {
        // Ended before the scan had a directory.
        if let End::Fail(r) = &end {
            tracing::error!("scan cannot start: {r}");
        }
        let end = match end {
            End::Success { .. } => End::Fail(FailReason::Refused {
                message: "internal: a scan without a directory cannot succeed".into(),
                kind: FailKind::Scan,
            }),
            end => end,
        };
        return Outcome::without_scan(end);
    };
    let dir: PathBuf = l.dir.clone();
    let outputs = books.outputs.take();
    let end = match end {
        End::Success { .. } if books.stop_error.is_some() => {
            let message = format!(
                "cannot write the stop record: {}",
                books.stop_error.take().unwrap_or_default()
            );
            ctl.publish(ended_status(machine.status(), StopStatus::Fail, &message));
            End::Fail(FailReason::Refused {
                message,
                kind: FailKind::Io,
            })
        }
        End::Success { .. } if outputs.is_none() => End::Fail(FailReason::Refused {
            message: "internal: the outputs were not kept".into(),
            kind: FailKind::Io,
        }),
        End::Success { summary } => {
            tracing::info!(scan_id = %l.id, "scan complete: {summary}");
            End::Success { summary }
        }
        End::Abort { peer } => {
            tracing::info!(scan_id = %l.id, "scan aborted; {} lines kept", l.lines.len());
            End::Abort { peer }
        }
        end => end,
    };
    Outcome {
        end,
        dir: Some(dir),
        outputs,
    }
}

#[cfg(test)]
mod tests {
    use super::{joined, refusal_of, reopened};
    use crate::jobs::synthetic::{self, SyntheticScan};
    use crate::scan::channels::Control;
    use crate::scan::choice::{decide, Asker, Decision};
    use crate::scan::command::StartMode;
    use crate::scan::ending::{End, FailCause, FailKind, FailReason, StopStatus};
    use crate::scan::event::ScanEventKind;
    use crate::scan::journal::JournalError;
    use crate::scan::journal::{read_journal, survey, Record, StopRecord, JOURNAL_FILE};
    use crate::scan::opening::{refusal, Refusal};
    use crate::scan::status::{State, Status};
    use crate::scan::store_error::StoreError;
    use std::path::{Path, PathBuf};
    use tokio::sync::{mpsc, watch};

    /// An unfinished scan of 3 lines with 1 done in `out`, as the daemon finds it at start-up.
    fn unfinished(out: &Path) -> PathBuf {
        let scan = SyntheticScan {
            id: "20261207-2200-block".into(),
            sequence: 1,
            started: "2026-12-07T22:00:00Z".parse().expect("a time"),
            specimen: "block".into(),
            recipe: None,
            lines: 3,
            done: 1,
            stop: None,
            report: None,
        };
        let dir = synthetic::write(out, &scan).expect("written");
        assert_eq!(
            decide(&survey(out).expect("survey"), Asker::DaemonStartUp, out).decision,
            Decision::Resume(dir.clone())
        );
        dir
    }

    /// What the daemon at start-up, a plain start and `--resume` each run in `out`.
    fn decisions(out: &Path) -> [Decision; 3] {
        let s = survey(out).expect("survey");
        [
            Asker::DaemonStartUp,
            Asker::Operator(StartMode::Auto),
            Asker::Operator(StartMode::Resume),
        ]
        .map(|asker| decide(&s, asker, out).decision)
    }

    /// A reopening that panicked is the scan's ending by a bug, said alike by the outcome
    /// (exit 70), the journal's stop record, the status's last stop and the `fail` event;
    /// recorded, it is not reopened again by the daemon at its next start (nor by its queue,
    /// which takes the same decision): a plain start begins a new scan, only `--resume`
    /// tries it again. Without the record the daemon resumed it into the same panic at every
    /// start.
    #[tokio::test]
    async fn a_reopening_that_panicked_is_recorded_as_the_scans_ending_by_a_bug() {
        let out = tempfile::tempdir().expect("tmp");
        let dir = unfinished(out.path());
        let (ctl, seen, mut told) = control();

        let outcome = reopened(&ctl, dir.clone(), || -> Result<(), (String, Refusal)> {
            panic!("no knot vector for {} lines", 1)
        })
        .await
        .expect_err("refused");
        let why = "internal error: reopening the scan panicked (no knot vector for 1 lines); report this with the scan's directory and the log";
        assert_eq!(
            outcome.end,
            End::Fail(FailReason::Refused {
                message: why.into(),
                kind: FailKind::Internal
            })
        );
        assert_eq!(outcome.dir.as_deref(), Some(dir.as_path()));
        let exit = crate::cli::scan::outcome_result(&outcome).expect_err("a failure");
        assert_eq!(exit.exit as i32, 70, "{}", exit.message);

        let stop = last_stop_record(&dir);
        assert_eq!(
            (stop.status, stop.reason.as_str(), stop.cause, stop.internal),
            (StopStatus::Fail, why, Some(FailCause::Operator), true)
        );
        let last = seen.borrow().last_stop.clone().expect("last stop");
        assert_eq!(
            (last.scan_id.as_str(), last.status, last.reason.as_str()),
            ("20261207-2200-block", StopStatus::Fail, why)
        );
        assert_eq!((last.dir, last.internal), (dir.display().to_string(), true));
        let ev = told.try_recv().expect("the fail event");
        assert_eq!(
            (ev.kind, ev.internal, ev.reason.as_str(), ev.time, &ev.dir),
            (ScanEventKind::Fail, true, why, stop.time, &dir)
        );
        assert!(told.try_recv().is_err(), "one event");

        let [daemon, plain, resume] = decisions(out.path());
        assert_eq!(daemon, Decision::Nothing);
        assert!(matches!(plain, Decision::New { .. }), "{plain:?}");
        assert_eq!(resume, Decision::Continue(dir));
    }

    /// A reopening cancelled as the runtime shuts down (`systemctl stop` while the daemon
    /// reopens a scan) is a shutdown's outcome with the scan: no stop record, no event, the
    /// status's last stop untouched, so its job stays running with its scan (the queue
    /// leaves a job running after a shutdown) and the daemon resumes the scan at its next
    /// start. Before, it was a refusal without the scan, and the scan's job ended `refused`.
    #[tokio::test]
    async fn a_reopening_cancelled_by_a_shutdown_leaves_the_scan_to_resume() {
        let cancelled = tokio::spawn(std::future::pending::<Result<(), (String, Refusal)>>());
        cancelled.abort();
        let (why, class) =
            refusal_of(joined(cancelled.await, "reopening the scan")).expect_err("cancelled");
        assert_eq!(class, Refusal::Shutdown, "{why}");

        let out = tempfile::tempdir().expect("tmp");
        let dir = unfinished(out.path());
        let before = std::fs::read(dir.join(JOURNAL_FILE)).expect("journal");
        let (ctl, seen, mut told) = control();
        let outcome = reopened(&ctl, dir.clone(), move || -> Result<(), _> {
            Err((why, class))
        })
        .await
        .expect_err("not reopened");
        assert_eq!(
            (outcome.end, outcome.dir),
            (End::Shutdown, Some(dir.clone()))
        );
        assert_eq!(
            std::fs::read(dir.join(JOURNAL_FILE)).expect("journal"),
            before
        );
        assert!(seen.borrow().last_stop.is_none(), "no last stop");
        assert!(told.try_recv().is_err(), "no event");
        assert_eq!(decisions(out.path())[0], Decision::Resume(dir));
    }

    /// The last record of the journal in `dir`, which the test expects to be a stop record.
    fn last_stop_record(dir: &Path) -> StopRecord {
        let journal = read_journal(&dir.join(JOURNAL_FILE)).expect("journal");
        match journal.records.last() {
            Some(Record::Stop(stop)) => stop.clone(),
            last => panic!("no stop record: {last:?}"),
        }
    }

    /// A control channel whose status and events the test reads.
    fn control() -> (
        Control,
        watch::Receiver<Status>,
        mpsc::UnboundedReceiver<crate::scan::event::ScanEvent>,
    ) {
        let (_commands, commands) = mpsc::channel(1);
        let (_shutdown, shutdown) = watch::channel(false);
        let (status, seen) = watch::channel(Status::idle());
        let mut ctl = Control::new(commands, shutdown, status);
        let (events, told) = mpsc::unbounded_channel();
        ctl.events = Some(events);
        (ctl, seen, told)
    }

    /// What each class of refusal means, as a table: its exit class and whether it is the
    /// scan's ending. The file system refusing can clear by itself (a remount, a permission
    /// given back): never an ending. The scan's own files, or a bug, cannot: recorded, so
    /// that nothing reopens the scan again without the operator. A scan that has ended, or a
    /// shutdown, leaves nothing to record.
    #[test]
    fn each_refusal_class_says_whether_it_ends_the_scan() {
        let table = [
            (Refusal::Left, FailKind::Scan, false),
            (Refusal::Shutdown, FailKind::Scan, false),
            (Refusal::FileSystem, FailKind::Io, false),
            (Refusal::Scan, FailKind::Scan, true),
            (Refusal::Bug, FailKind::Internal, true),
        ];
        for (r, kind, ends) in table {
            assert_eq!((r.kind(), r.ends_the_scan()), (kind, ends), "{r:?}");
        }
    }

    /// An operating-system error anywhere behind the error is the file system's refusal,
    /// named with its errno and its fix; an error of what was read (a second start record
    /// in the journal) is the scan's own, with what the operator may do.
    #[test]
    fn a_refusal_is_the_file_systems_when_an_os_error_is_behind_it() {
        let io = StoreError::Io {
            op: "read",
            path: "lines/0002.csv".into(),
            source: std::io::Error::from_raw_os_error(libc::EIO),
        };
        let (why, class) = refusal("reading its lines back", &io);
        assert_eq!(class, Refusal::FileSystem);
        assert!(
            why.starts_with(
                "the file system refused reading its lines back (EIO: read lines/0002.csv"
            ) && why
                .ends_with("check the disk (a USB disk or a network file system that went away)"),
            "{why}"
        );
        let journal = StoreError::Journal(JournalError::Io {
            op: "open",
            path: "journal.jsonl".into(),
            source: std::io::Error::from_raw_os_error(libc::EROFS),
        });
        assert_eq!(
            refusal("reading its journal", &journal).1,
            Refusal::FileSystem
        );
        let second = JournalError::SecondStart {
            path: "journal.jsonl".into(),
            line: 5,
        };
        let (why, class) = refusal("reading its journal", &second);
        assert_eq!(class, Refusal::Scan);
        assert_eq!(
            why,
            "the scan cannot be reopened: reading its journal: journal.jsonl: line 5 is a second start record; nothing reopens it by itself: repair its files and continue it with `surfscan start --resume`, or begin a new scan with a plain `surfscan start`"
        );
    }

    /// A reopening refused by the file system leaves the scan as it was (no stop record, no
    /// event: the daemon resumes it at its next start), but names it: the outcome carries its
    /// directory (for its job, which waits) with the exit class of a file error (74), and the
    /// status's reason its id, directory and the fix; its last stop is not the scan's, which
    /// has not ended (it read `fail`).
    #[tokio::test]
    async fn a_reopening_refused_by_the_file_system_leaves_the_scan_and_names_it() {
        let out = tempfile::tempdir().expect("tmp");
        let dir = unfinished(out.path());
        let (ctl, seen, mut told) = control();
        let records = read_journal(&dir.join(JOURNAL_FILE))
            .expect("journal")
            .records;

        let outcome = reopened(&ctl, dir.clone(), || -> Result<(), (String, Refusal)> {
            let e = StoreError::Io {
                op: "list",
                path: "lines".into(),
                source: std::io::Error::from_raw_os_error(libc::EACCES),
            };
            Err(refusal("reading its lines back", &e))
        })
        .await
        .expect_err("refused");
        assert_eq!(outcome.dir.as_deref(), Some(dir.as_path()));
        let exit = crate::cli::scan::outcome_result(&outcome).expect_err("a failure");
        assert_eq!(exit.exit as i32, 74, "{}", exit.message);
        assert_eq!(
            read_journal(&dir.join(JOURNAL_FILE))
                .expect("journal")
                .records,
            records,
            "the journal is left as it was"
        );
        assert!(told.try_recv().is_err(), "no event");
        // The scan has not ended: no last stop (none ended since the daemon started), the
        // daemon idle, the reason naming the scan, its directory and the fix.
        let status = seen.borrow().clone();
        assert!(status.last_stop.is_none(), "{:?}", status.last_stop);
        assert_eq!(status.state, State::Idle);
        let reason = status.reason.expect("a reason");
        let head = format!(
            "scan 20261207-2200-block ({}) waits for the file system: the file system refused reading its lines back",
            dir.display()
        );
        assert!(reason.starts_with(&head), "{reason}");
        assert!(
            reason.ends_with("give the daemon's user write permission on the output directory"),
            "{reason}"
        );
        assert_eq!(decisions(out.path())[0], Decision::Resume(dir));
    }

    /// A reopening refused because the scan's own files cannot be read back is the scan's
    /// ending, the operator's: a `fail` stop record (cause `operator`, no bug), the status's
    /// last stop and one `fail` event with its id, and the outcome with its directory (exit
    /// 1); the daemon no longer reopens it at its start, a plain start begins a new scan and
    /// `--resume` tries it again. Before, nothing was recorded and the daemon reopened it
    /// into the same refusal at every start.
    #[tokio::test]
    async fn a_reopening_refused_for_the_scans_own_files_is_its_ending() {
        let out = tempfile::tempdir().expect("tmp");
        let dir = unfinished(out.path());
        let (ctl, seen, mut told) = control();

        let outcome = reopened(&ctl, dir.clone(), || -> Result<(), (String, Refusal)> {
            let e = JournalError::SecondStart {
                path: "journal.jsonl".into(),
                line: 3,
            };
            Err(refusal("reading its journal", &e))
        })
        .await
        .expect_err("refused");
        let why = "the scan cannot be reopened: reading its journal: journal.jsonl: line 3 is a second start record; nothing reopens it by itself: repair its files and continue it with `surfscan start --resume`, or begin a new scan with a plain `surfscan start`";
        assert_eq!(outcome.dir.as_deref(), Some(dir.as_path()));
        let exit = crate::cli::scan::outcome_result(&outcome).expect_err("a failure");
        assert_eq!(exit.exit as i32, 1, "{}", exit.message);
        let stop = last_stop_record(&dir);
        assert_eq!(
            (stop.status, stop.reason.as_str(), stop.cause, stop.internal),
            (StopStatus::Fail, why, Some(FailCause::Operator), false)
        );
        let last = seen.borrow().last_stop.clone().expect("last stop");
        assert_eq!(
            (last.scan_id.as_str(), last.reason.as_str(), last.internal),
            ("20261207-2200-block", why, false)
        );
        let ev = told.try_recv().expect("the fail event");
        assert_eq!(
            (ev.kind, ev.internal, ev.scan_id.as_str(), ev.time),
            (ScanEventKind::Fail, false, "20261207-2200-block", stop.time)
        );
        assert!(told.try_recv().is_err(), "one event");
        let [daemon, plain, resume] = decisions(out.path());
        assert_eq!(daemon, Decision::Nothing);
        assert!(matches!(plain, Decision::New { .. }), "{plain:?}");
        assert_eq!(resume, Decision::Continue(dir));
    }

    /// A reopening that ends the scan (its own files refused) whose ending the file system
    /// will not record (here its journal's path is a directory, which fails for root too, as
    /// a full or read-only disk does) is not told as ended: the scan is left as it is, as
    /// when the file system refuses reopening it (no event, so no hook; no last stop; the
    /// idle status's reason names it; exit 74, so its job stays running and is tried again
    /// with backoff), and the daemon still reopens it. Once the file system takes the
    /// record, the next reopening records the ending and tells it. Before, the scan was told
    /// `fail` (event, last stop, its job ended) with nothing recorded, and the daemon
    /// reopened it at every start.
    #[tokio::test]
    async fn an_ending_the_file_system_will_not_record_leaves_the_scan_to_reopen() {
        let out = tempfile::tempdir().expect("tmp");
        let dir = unfinished(out.path());
        let (ctl, seen, mut told) = control();
        let own_files = || -> Result<(), (String, Refusal)> {
            let e = JournalError::SecondStart {
                path: "journal.jsonl".into(),
                line: 3,
            };
            Err(refusal("reading its journal", &e))
        };
        let journal = dir.join(JOURNAL_FILE);
        let kept = dir.join("journal.kept");
        std::fs::rename(&journal, &kept).expect("moved aside");
        std::fs::create_dir(&journal).expect("a directory in its place");

        let outcome = reopened(&ctl, dir.clone(), own_files)
            .await
            .expect_err("refused");
        assert_eq!(outcome.dir.as_deref(), Some(dir.as_path()));
        let exit = crate::cli::scan::outcome_result(&outcome).expect_err("a failure");
        assert_eq!(exit.exit as i32, 74, "{}", exit.message);
        assert!(told.try_recv().is_err(), "no event");
        let status = seen.borrow().clone();
        assert!(status.last_stop.is_none(), "{:?}", status.last_stop);
        assert_eq!(status.state, State::Idle);
        let reason = status.reason.expect("a reason");
        let head = format!(
            "scan 20261207-2200-block ({}) waits for the file system: the file system refused recording the scan's ending (",
            dir.display()
        );
        assert!(reason.starts_with(&head), "{reason}");

        std::fs::remove_dir(&journal).expect("the directory removed");
        std::fs::rename(&kept, &journal).expect("put back");
        assert!(
            !matches!(
                read_journal(&journal).expect("journal").records.last(),
                Some(Record::Stop(_))
            ),
            "nothing recorded"
        );
        assert_eq!(decisions(out.path())[0], Decision::Resume(dir.clone()));

        let outcome = reopened(&ctl, dir.clone(), own_files)
            .await
            .expect_err("refused");
        let exit = crate::cli::scan::outcome_result(&outcome).expect_err("a failure");
        assert_eq!(exit.exit as i32, 1, "{}", exit.message);
        let stop = last_stop_record(&dir);
        assert_eq!(
            (stop.status, stop.cause),
            (StopStatus::Fail, Some(FailCause::Operator))
        );
        let ev = told.try_recv().expect("the fail event");
        assert_eq!((ev.kind, ev.time), (ScanEventKind::Fail, stop.time));
        assert_eq!(
            seen.borrow().last_stop.as_ref().map(|l| l.status),
            Some(StopStatus::Fail)
        );
        assert_eq!(decisions(out.path())[0], Decision::Nothing);
    }

    /// A panic in [`super::watched`] work becomes the scan's reason, naming the work and the
    /// panic's message, instead of going on up the daemon's loop, and is a bug's (exit 70 for
    /// `surfscan scan`, also when reopening a scan panicked); work cancelled as the runtime
    /// shuts down is no bug; a value passes through.
    #[tokio::test]
    async fn a_panic_in_watched_work_is_the_scans_reason() {
        let done =
            tokio::task::spawn_blocking(|| -> u32 { panic!("no knot vector for {} lines", 3) })
                .await;
        assert_eq!(
            joined(done, "reopening the scan"),
            Err(("internal error: reopening the scan panicked (no knot vector for 3 lines); report this with the scan's directory and the log".to_string(), FailKind::Internal))
        );
        let cancelled = tokio::spawn(std::future::pending::<u32>());
        cancelled.abort();
        let (why, kind) = joined(cancelled.await, "reopening the scan").unwrap_err();
        assert!(
            why.starts_with("internal: reopening the scan was cancelled"),
            "{why}"
        );
        assert_eq!(kind, FailKind::Scan);
        let done = tokio::task::spawn_blocking(|| 7u32).await;
        assert_eq!(joined(done, "reopening the scan"), Ok(7));
    }
}
