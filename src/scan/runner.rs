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
//! Layer 3 (session): depends on [`super::machine`], [`super::station`] (devices),
//! [`super::ledger`] and [`super::opening`] (disk), [`super::channels`], and the session's
//! own settings, status, command and outcome types.

use super::channels::Control;
use super::command::{OperatorRequest, Peer};
use super::disk::free_bytes;
use super::journal::StopStatus;
use super::ledger::Ledger;
use super::line::{LineMeta, StoredLine};
use super::machine::{
    ended_status, Action, End, Event, FailKind, Machine, Now, Policy, StorageFailure, TracedSummary,
};
use super::opening::{self, expected_points, NewScan};
use super::outcome::{Outcome, ScanRequest};
use super::outputs::Outputs;
use super::settings::RunSettings;
use super::station::{Device, Fault, Station};
use super::status::Ending;
use crate::devices::{FaultClass, Instrument, InstrumentIdentity, ProbeReport, TracedLine, YAxis};
use crate::stage::policy::ScanDirection;
use crate::units::Nm;
use chrono::{DateTime, Utc};
use std::collections::VecDeque;
use std::future::Future;
use std::path::PathBuf;
use std::time::Duration;

pub use super::machine::conditions_difference;
pub use super::opening::estimate_line_seconds;

/// Time allowed for the best-effort abort and stop after an operator abort or shutdown.
const CLEANUP_TIMEOUT: Duration = Duration::from_secs(10);

fn now() -> Now {
    Now {
        mono: tokio::time::Instant::now().into_std(),
        wall: Utc::now(),
    }
}

/// The devices of a running scan and what they reported.
struct Hands<'s, S: Station> {
    station: &'s mut S,
    instrument: Option<S::Instrument>,
    stage: Option<S::Stage>,
    direction: ScanDirection,
    targets: Vec<Nm>,
    /// The instrument's report at the start of a new scan.
    probe: Option<ProbeReport>,
    /// Warnings of the start (instrument and stage), for the journal.
    warnings: Vec<String>,
    /// The stage controller the scan started with, when known.
    stage_identity: Option<String>,
    /// The instrument the scan started with (set once the scan has a start record).
    identity: Option<InstrumentIdentity>,
    /// Read back by the last move.
    readback: Option<Nm>,
}

/// A traced line waiting for its commit.
struct Held {
    traced: TracedLine,
    readback: Option<Nm>,
    started_at: DateTime<Utc>,
    finished_at: DateTime<Utc>,
}

impl<S: Station> Hands<'_, S> {
    /// Performs a device effect; its result as the machine's event.
    async fn perform(&mut self, action: &Action, held: &mut Option<Held>) -> Event {
        match action {
            Action::Open(d) => self.open(*d).await,
            Action::Home => {
                let Some(stage) = self.stage.as_mut() else {
                    return not_open(Device::Stage);
                };
                tracing::info!("homing the stage");
                match stage.home().await {
                    Ok(()) => Event::Homed,
                    Err(e) => fault(Device::Stage, &e),
                }
            }
            Action::EnsureIdle => {
                let Some(i) = self.instrument.as_mut() else {
                    return not_open(Device::Instrument);
                };
                match i.ensure_idle().await {
                    Ok(()) => Event::Idle,
                    Err(e) => fault(Device::Instrument, &e),
                }
            }
            Action::Move(target) => {
                let Some(stage) = self.stage.as_mut() else {
                    return not_open(Device::Stage);
                };
                match stage.move_to(*target).await {
                    Ok(a) => {
                        self.readback = Some(a.readback);
                        Event::Arrived
                    }
                    Err(e) => fault(Device::Stage, &e),
                }
            }
            Action::Trace => {
                let Some(i) = self.instrument.as_mut() else {
                    return not_open(Device::Instrument);
                };
                let before = i.traces_started();
                let started_at = Utc::now();
                match i.trace().await {
                    Ok(traced) => {
                        let p = &traced.profile;
                        let summary = TracedSummary {
                            points: p.len(),
                            pitch_x_mm: p.pitch_x_mm,
                            first_non_finite: p
                                .heights_um
                                .iter()
                                .position(|z| !z.is_finite())
                                .map(|k| (k, p.heights_um[k])),
                            conditions: p.conditions.clone(),
                            ra_um: traced
                                .results
                                .iter()
                                .find(|r| r.name.trim().eq_ignore_ascii_case("ra"))
                                .and_then(|r| r.value),
                        };
                        *held = Some(Held {
                            traced,
                            readback: self.readback,
                            started_at,
                            finished_at: Utc::now(),
                        });
                        Event::Traced(summary)
                    }
                    Err(e) => {
                        // Unknown to the driver: the trace is taken as started.
                        let trace_started = match (before, i.traces_started()) {
                            (Some(b), Some(a)) => a > b,
                            _ => true,
                        };
                        Event::Fault {
                            fault: Fault::of(Device::Instrument, &e),
                            trace_started,
                        }
                    }
                }
            }
            Action::Cleanup => {
                self.cleanup().await;
                Event::CleanedUp
            }
            Action::SetTimer(d) => {
                tokio::time::sleep(*d).await;
                Event::TimerFired
            }
            other => unreachable_effect(other),
        }
    }

    /// Opens and verifies a device: at the start of a new scan its report is kept; once the
    /// scan has a start record a different instrument or controller is a fatal fault.
    async fn open(&mut self, device: Device) -> Event {
        let fatal = |message: String| Event::Fault {
            fault: Fault {
                device,
                class: FaultClass::Fatal,
                ng_code: None,
                message,
            },
            trace_started: false,
        };
        match device {
            Device::Instrument => {
                let mut i = match self.station.open_instrument().await {
                    Ok(i) => i,
                    Err(f) => return open_fault(f),
                };
                let report = match i.probe().await {
                    Ok(r) => r,
                    Err(e) => return fault(Device::Instrument, &e),
                };
                if let Some(want) = &self.identity {
                    let got = &report.identity;
                    if got.model != want.model
                        || got.firmware != want.firmware
                        || got.drive_unit != want.drive_unit
                    {
                        return fatal(format!(
                            "a different instrument answered: model {}, firmware {:?}, drive unit {:?}; the scan started with model {}, firmware {:?}, drive unit {:?}",
                            got.model, got.firmware, got.drive_unit, want.model, want.firmware, want.drive_unit
                        ));
                    }
                } else {
                    for w in &report.warnings {
                        tracing::warn!("instrument: {w}");
                    }
                    self.warnings.extend(report.warnings.iter().cloned());
                    self.probe = Some(report);
                }
                self.instrument = Some(i);
                Event::Opened {
                    device,
                    position_trusted: true,
                }
            }
            Device::Stage => {
                let mut st = match self.station.open_stage(self.direction).await {
                    Ok(s) => s,
                    Err(f) => return open_fault(f),
                };
                let report = match st.connect().await {
                    Ok(r) => r,
                    Err(e) => return fault(Device::Stage, &e),
                };
                match &self.stage_identity {
                    Some(want) if &report.identity != want => {
                        return fatal(format!(
                        "a different stage controller answered: {:?}; the scan started with {:?}",
                        report.identity, want
                    ))
                    }
                    Some(_) => {}
                    None if self.identity.is_none() => {
                        // A new scan: its targets are checked before anything moves.
                        match st.check_targets(&self.targets) {
                            Ok(w) => {
                                for w in &w {
                                    tracing::warn!("stage: {w}");
                                }
                                // Stage warnings first, as the journal always listed them.
                                let mut all = w;
                                all.append(&mut self.warnings);
                                self.warnings = all;
                            }
                            Err(e) => return fatal(Fault::of(Device::Stage, &e).message),
                        }
                        self.stage_identity = Some(report.identity.clone());
                    }
                    None => {}
                }
                self.stage = Some(st);
                Event::Opened {
                    device,
                    position_trusted: report.position_trusted,
                }
            }
        }
    }

    /// Best-effort abort of a running measurement and stop of the stage, bounded in time.
    async fn cleanup(&mut self) {
        if let Some(i) = self.instrument.as_mut() {
            match tokio::time::timeout(CLEANUP_TIMEOUT, i.abort()).await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => tracing::warn!("instrument abort failed: {e}"),
                Err(_) => tracing::warn!("instrument abort timed out"),
            }
        }
        if let Some(s) = self.stage.as_mut() {
            match tokio::time::timeout(CLEANUP_TIMEOUT, s.stop()).await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => tracing::warn!("stage stop failed: {e}"),
                Err(_) => tracing::warn!("stage stop timed out"),
            }
        }
    }
}

fn fault<E: crate::devices::DeviceFault>(device: Device, e: &E) -> Event {
    Event::Fault {
        fault: Fault::of(device, e),
        trace_started: false,
    }
}

fn open_fault(f: Fault) -> Event {
    Event::Fault {
        fault: f,
        trace_started: false,
    }
}

fn not_open(device: Device) -> Event {
    Event::Fault {
        fault: Fault {
            device,
            class: FaultClass::Absent,
            ng_code: None,
            message: "not connected".to_owned(),
        },
        trace_started: false,
    }
}

fn unreachable_effect(a: &Action) -> Event {
    // The machine issues only device effects here; anything else is a bug worth a loud
    // message, not a panic in a night's scan.
    tracing::error!("internal: {a:?} performed as a device effect");
    Event::Fault {
        fault: Fault {
            device: Device::Instrument,
            class: FaultClass::Fatal,
            ng_code: None,
            message: format!("internal: {a:?} is not a device operation"),
        },
        trace_started: false,
    }
}

/// The executor's state besides the devices.
struct Books<'a> {
    settings: &'a RunSettings,
    ledger: Option<Ledger>,
    new_scan: Option<NewScan>,
    held: Option<Held>,
    outputs: Option<Outputs>,
    /// The reply channel of the command being fed.
    reply: Option<tokio::sync::oneshot::Sender<Result<String, String>>>,
    end: Option<End>,
    /// Why the stop record could not be written.
    stop_error: Option<String>,
}

impl Books<'_> {
    /// Performs an immediate action.
    fn immediate(&mut self, ctl: &Control, a: Action) {
        match a {
            Action::Publish(s) => ctl.publish(s),
            Action::Record(n) => match &mut self.ledger {
                Some(l) => l.note(&n),
                None => tracing::warn!("{}", n.reason),
            },
            Action::Notify(kind, reason) => {
                if let Some(l) = &self.ledger {
                    ctl.event(&l.id, &l.dir, kind, &reason);
                }
            }
            Action::Reply(r) => {
                if let Some(tx) = self.reply.take() {
                    let _ = tx.send(r);
                }
            }
            Action::Metrics(m) => {
                if let Some(l) = &self.ledger {
                    l.metrics(&m);
                }
            }
            Action::Stop(end) => {
                self.write_stop(&end);
                self.end = Some(end);
            }
            Action::Close(_) | Action::Cancel => {}
            other => tracing::error!("internal: {other:?} performed as an immediate action"),
        }
    }

    /// Performs a disk effect.
    fn disk(&mut self, a: &Action, probe: Option<&ProbeReport>, station_points: u64) -> Event {
        match a {
            Action::CreateScan => {
                let (Some(who), Some(report)) = (self.new_scan.take(), probe) else {
                    return storage_event(
                        false,
                        "internal: no probe report for the new scan".into(),
                    );
                };
                match opening::create(self.settings, who, report, station_points) {
                    Ok(l) => {
                        let ev = Event::Created {
                            scan_id: l.id.clone(),
                            dir: l.dir.display().to_string(),
                            conditions: l.start.conditions.clone(),
                            points_per_line: station_points,
                        };
                        self.ledger = Some(l);
                        ev
                    }
                    Err(e) => storage_event(e.is_disk_full(), e.to_string()),
                }
            }
            Action::Commit { line, attempt } => {
                let (Some(l), Some(h)) = (self.ledger.as_mut(), self.held.as_ref()) else {
                    return storage_event(false, "internal: no line to commit".into());
                };
                let p = &h.traced.profile;
                let meta = LineMeta {
                    index: *line,
                    y_target_nm: l.plan.target(*line),
                    y_readback_nm: h.readback,
                    pitch_x_mm: p.pitch_x_mm,
                    points: p.len(),
                    kind: p.kind,
                    conditions: p.conditions.clone(),
                    results: h.traced.results.clone(),
                    readout_warnings: h.traced.readout_warnings.clone(),
                    started_at: h.started_at,
                    finished_at: h.finished_at,
                    attempt: *attempt,
                };
                for w in &h.traced.warnings {
                    tracing::warn!(scan_id = %l.id, line = line + 1, "{w}");
                }
                match l.commit(&meta, p) {
                    Ok(()) => Event::Committed,
                    Err(e) => storage_event(e.is_disk_full(), e.to_string()),
                }
            }
            Action::Push { line } => {
                let (Some(l), Some(h)) = (self.ledger.as_mut(), self.held.take()) else {
                    return Event::PushRefused("internal: no committed line to push".into());
                };
                let meta_line = StoredLine {
                    meta: LineMeta {
                        index: *line,
                        y_target_nm: l.plan.target(*line),
                        y_readback_nm: h.readback,
                        pitch_x_mm: h.traced.profile.pitch_x_mm,
                        points: h.traced.profile.len(),
                        kind: h.traced.profile.kind,
                        conditions: h.traced.profile.conditions.clone(),
                        results: h.traced.results,
                        readout_warnings: h.traced.readout_warnings,
                        started_at: h.started_at,
                        finished_at: h.finished_at,
                        attempt: 0,
                    },
                    profile: h.traced.profile,
                };
                let y_mm = meta_line.y_mm();
                match l.push(meta_line) {
                    Ok(()) => {
                        tracing::info!(
                            scan_id = %l.id,
                            line = line + 1,
                            y_mm,
                            "line {}/{} on disk",
                            line + 1,
                            l.plan.lines
                        );
                        Event::Pushed
                    }
                    Err(e) => Event::PushRefused(e.to_string()),
                }
            }
            Action::WriteOutputs => {
                let Some(l) = self.ledger.as_mut() else {
                    return storage_event(false, "internal: no scan to finish".into());
                };
                match l.write_outputs(self.settings.characterise.as_deref()) {
                    Ok(outputs) => {
                        let summary = format!(
                            "{} lines; surface {}",
                            l.plan.lines,
                            outputs
                                .iges
                                .first()
                                .map(|p| p.display().to_string())
                                .unwrap_or_default()
                        );
                        self.outputs = Some(outputs);
                        Event::OutputsWritten { summary }
                    }
                    Err(e) => {
                        let full = e.is_io() && is_disk_full_text(&e);
                        let message = if full {
                            e.to_string()
                        } else {
                            format!(
                                "all lines are on disk but the outputs could not be written: {e}; run `surfscan fit {}` and `surfscan analyze {}` once the cause is cleared",
                                l.dir.display(),
                                l.dir.display()
                            )
                        };
                        storage_event(full, message)
                    }
                }
            }
            Action::CheckSpace => {
                let dir = self
                    .ledger
                    .as_ref()
                    .map_or_else(|| self.settings.output_dir.clone(), |l| l.dir.clone());
                let free_bytes = free_bytes(&dir).unwrap_or_else(|e| {
                    tracing::warn!("cannot read the free space of {}: {e}", dir.display());
                    0
                });
                Event::SpaceChecked { free_bytes }
            }
            other => {
                tracing::error!("internal: {other:?} performed as a disk effect");
                storage_event(
                    false,
                    format!("internal: {other:?} is not a disk operation"),
                )
            }
        }
    }
}

fn storage_event(disk_full: bool, message: String) -> Event {
    Event::StorageFailed(StorageFailure { disk_full, message })
}

/// Whether an outputs error is the disk being full (the error chain carries `ENOSPC`).
fn is_disk_full_text(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(err) = cur {
        if let Some(io) = err.downcast_ref::<std::io::Error>() {
            if io.raw_os_error() == Some(libc::ENOSPC) || io.raw_os_error() == Some(libc::EDQUOT) {
                return true;
            }
        }
        cur = err.source();
    }
    false
}

fn is_device_effect(a: &Action) -> bool {
    matches!(
        a,
        Action::Open(_)
            | Action::Home
            | Action::EnsureIdle
            | Action::Move(_)
            | Action::Trace
            | Action::Cleanup
            | Action::SetTimer(_)
    )
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
    };
    let mut machine = match request {
        ScanRequest::New {
            specimen,
            operator,
            notes,
            peer,
        } => {
            books.new_scan = Some(NewScan {
                specimen,
                operator,
                notes,
                peer: peer.or_else(|| Some(Peer::this_process())),
            });
            Machine::new_scan(settings.plan, policy, before)
        }
        request @ (ScanRequest::Resume(_) | ScanRequest::Continue { .. }) => {
            let (dir, continued_by) = match request {
                ScanRequest::Continue { dir, peer } => (dir, Some(peer)),
                ScanRequest::Resume(dir) => (dir, None),
                ScanRequest::New { .. } => unreachable!("matched above"),
            };
            match reopen(settings, &dir, continued_by) {
                Ok((resumed, l)) => {
                    hands.attach(&l);
                    let plan = l.plan;
                    books.ledger = Some(l);
                    Machine::resumed(plan, policy, before, resumed)
                }
                Err((reason, kind)) => return refused(ctl, reason, kind),
            }
        }
    };
    drive(&mut machine, &mut hands, &mut books, ctl).await;
    finish(ctl, &machine, books)
}

/// Reopens a scan directory for the machine; the refusal (reason and kind) when it cannot
/// be run.
fn reopen(
    settings: &RunSettings,
    dir: &std::path::Path,
    continued_by: Option<Option<Peer>>,
) -> Result<(super::machine::Resumed, Ledger), (String, FailKind)> {
    let r = opening::reopen(settings, dir, continued_by.is_some())
        .map_err(|reason| (reason, FailKind::Scan))?;
    let mut ledger = r.ledger;
    let peer = continued_by.flatten();
    let note = match &r.failed {
        Some(reason) => format!("{}; it had failed: {reason}", r.note),
        None => r.note.clone(),
    };
    if r.failed.is_some() {
        ledger
            .reopen_failed(peer)
            .map_err(|e| (format!("cannot record the continuation: {e}"), FailKind::Io))?;
    }
    ledger.note(&super::machine::Note {
        reason: note,
        device: None,
        line: None,
        peer,
    });
    Ok((r.resumed, ledger))
}

fn refused(ctl: &Control, reason: String, kind: FailKind) -> Outcome {
    tracing::error!("scan cannot start: {reason}");
    let s = ended_status(&ctl.status.borrow(), Ending::Fail, &reason);
    ctl.publish(s);
    Outcome::Failed {
        dir: None,
        reason,
        kind,
    }
}

impl<S: Station> Hands<'_, S> {
    /// Takes the identities of the scan's start record: reopened devices must match them.
    fn attach(&mut self, l: &Ledger) {
        self.identity = Some(InstrumentIdentity {
            model: l.start.instrument_model.clone(),
            firmware: l.start.firmware.clone(),
            drive_unit: l.start.drive_unit.clone(),
        });
        self.direction = ScanDirection::of_step(l.plan.y_step_nm);
        self.targets = l.plan.targets();
    }
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
                match d {
                    Device::Instrument => hands.instrument = None,
                    Device::Stage => hands.stage = None,
                }
            }
            books.immediate(ctl, action);
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
            let fut = hands.perform(&action, &mut held);
            let out = if cleanup {
                Some(fut.await)
            } else {
                guarded(fut, machine, books, ctl, &mut queue, &mut shutdown_fed).await
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

impl<S: Station> Hands<'_, S> {
    fn points(&self) -> u64 {
        match &self.probe {
            Some(r) => {
                expected_points(self.station.expected_pitch_um(&r.conditions), &r.conditions)
            }
            None => opening::LONGEST_PROFILE_POINTS,
        }
    }
}

/// Awaits a device effect while feeding commands and shutdown to the machine; `None` when
/// the machine cancelled it (the actions that follow the cancel are queued).
async fn guarded(
    fut: impl Future<Output = Event>,
    machine: &mut Machine,
    books: &mut Books<'_>,
    ctl: &mut Control,
    queue: &mut VecDeque<Action>,
    shutdown_fed: &mut bool,
) -> Option<Event> {
    tokio::pin!(fut);
    let mut tick = ctl.watchdog_tick();
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
            Some(req) = ctl.commands.recv() => command_event(books, req),
            _ = tick.tick() => {
                ctl.pet();
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

fn command_event(books: &mut Books<'_>, req: OperatorRequest) -> Event {
    books.reply = Some(req.reply);
    Event::Command {
        command: req.command,
        peer: req.peer,
    }
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
                Some(req) => return command_event(books, req),
                // Nobody can ever command (no control channel): wait for shutdown only.
                None => {
                    let _ = ctl.shutdown.wait_for(|v| *v).await;
                }
            },
            _ = tick.tick() => ctl.pet(),
        }
    }
}

impl Books<'_> {
    /// The journal's account of the end, written when the machine stops (before the
    /// notification hook hears of it): the stop record, or for a shutdown the interruption
    /// that leaves the scan resumable.
    fn write_stop(&mut self, end: &End) {
        let Some(l) = self.ledger.as_mut() else {
            return;
        };
        let written = match end {
            End::Success { summary } => l.stop(StopStatus::Success, summary),
            End::Abort { .. } => l.stop(StopStatus::Abort, "aborted by the operator"),
            End::Fail(r) => {
                tracing::error!(scan_id = %l.id, "scan failed: {r}");
                l.stop(StopStatus::Fail, &r.to_string())
            }
            // The machine recorded the interruption: no stop record, the scan resumes.
            End::Shutdown => Ok(()),
        };
        if let Err(e) = written {
            tracing::error!(scan_id = %l.id, "cannot write the stop record: {e}");
            self.stop_error = Some(e.to_string());
        }
    }
}

/// Makes the outcome of the ended scan.
fn finish(ctl: &Control, machine: &Machine, mut books: Books<'_>) -> Outcome {
    let end = books.end.take().unwrap_or(End::Shutdown);
    let Some(l) = books.ledger.take() else {
        // Ended before the scan had a directory.
        return match end {
            End::Fail(r) => {
                let reason = r.to_string();
                tracing::error!("scan cannot start: {reason}");
                Outcome::Failed {
                    dir: None,
                    kind: r.kind(),
                    reason,
                }
            }
            End::Abort { .. } => Outcome::Failed {
                dir: None,
                reason: "aborted before the scan started".into(),
                kind: FailKind::Scan,
            },
            End::Shutdown => Outcome::Failed {
                dir: None,
                reason: "shut down before the scan started".into(),
                kind: FailKind::Scan,
            },
            End::Success { .. } => Outcome::Failed {
                dir: None,
                reason: "internal: a scan without a directory cannot succeed".into(),
                kind: FailKind::Scan,
            },
        };
    };
    let dir: PathBuf = l.dir.clone();
    match end {
        End::Success { summary } => {
            if let Some(e) = books.stop_error.take() {
                let reason = format!("cannot write the stop record: {e}");
                ctl.publish(ended_status(machine.status(), Ending::Fail, &reason));
                return Outcome::Failed {
                    dir: Some(dir),
                    reason,
                    kind: FailKind::Io,
                };
            }
            tracing::info!(scan_id = %l.id, "scan complete: {summary}");
            match books.outputs.take() {
                Some(outputs) => Outcome::Success { dir, outputs },
                None => Outcome::Failed {
                    dir: Some(dir),
                    reason: "internal: the outputs were not kept".into(),
                    kind: FailKind::Io,
                },
            }
        }
        End::Abort { .. } => {
            tracing::warn!(scan_id = %l.id, "scan aborted; {} lines kept", l.lines.len());
            Outcome::Aborted { dir }
        }
        End::Shutdown => Outcome::Interrupted { dir },
        End::Fail(r) => Outcome::Failed {
            dir: Some(dir),
            kind: r.kind(),
            reason: r.to_string(),
        },
    }
}
