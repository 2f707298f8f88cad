//! The scan runner: drives instrument, stage, storage and fitter through one scan, new or
//! resumed, and survives what a night can throw at it.
//!
//! Per line k: the instrument must read idle (`000`; `CTRTN` on `005`) — the stage never
//! moves otherwise — then move to y_k (absolute target, settle, read back), trace, read
//! results and profile, check the line against the scan (conditions, pitch, point count),
//! **commit it durably** (line files, then the journal record; [`ScanStore::commit_line`]),
//! push it into the incremental fitter and publish status. Only then does the next move
//! happen.
//!
//! Faults are handled by class ([`FaultClass`]): a device that vanished suspends the scan
//! (interruption recorded, notification hook, reconnect with exponential backoff, identity
//! re-verified, then the line is traced again — suspension does not use up attempts); a
//! transient fault abandons the line and re-traces it, at most `max-line-attempts` times;
//! a lost stage position re-homes first; a fatal fault, a full disk or exhausted attempts
//! end the scan with `fail` and the specific reason. A line is never half-kept.
//!
//! Operator commands arrive on a channel while any device operation is in flight: pause is
//! deferred until the current line is on disk, abort cancels the operation and makes a
//! best-effort instrument abort and stage stop. Shutdown (SIGTERM) abandons the current line
//! and records an interruption, not a stop, so the scan resumes at the next start.
//!
//! Layer 3 (session): depends on [`super::station`] (devices), [`super::store`] and
//! [`super::journal`] (disk), [`crate::fit`], [`super::outputs`], and the session's own
//! status, command and settings types.

use super::command::{OperatorCommand, OperatorRequest};
use super::disk::preflight_disk;
use super::event::{ScanEvent, ScanEventKind};
use super::faults::StorageFaults;
use super::journal::{
    InterruptionRecord, Journal, JournalError, Record, ResumeState, StartRecord, StopRecord,
    StopStatus,
};
use super::line::{LineMeta, StoredLine};
use super::metrics::{write_metrics, ScanMetrics};
use super::outputs::{write_outputs, Outputs};
use super::plan::Plan;
use super::scan_id::ScanId;
use super::settings::{Backoff, RunSettings};
use super::station::{Device, Fault, Station};
use super::status::{DeviceState, Ending, LastStop, State, Status};
use super::store::{csv_name, meta_name, sync_dir, ScanStore};
use super::store_error::StoreError;
use super::testhooks::{Step, TestHooks};
use crate::devices::{FaultClass, Instrument, InstrumentIdentity, TracedLine, YAxis};
use crate::fit::{FitOptions, IncrementalFitter};
use crate::profile::{Conditions, Profile};
use crate::stage::policy::ScanDirection;
use chrono::{DateTime, Utc};
use std::future::Future;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};

/// Time allowed for the best-effort abort and stop after an operator abort or shutdown.
const CLEANUP_TIMEOUT: Duration = Duration::from_secs(10);

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
    },
    /// Resume the unfinished scan in this directory.
    Resume(PathBuf),
}

/// Why a scan could not complete, for exit codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailKind {
    /// The scan ran and failed (device fault, exhausted attempts, changed conditions).
    Scan,
    /// A device was not there when a new scan was to start.
    Unavailable,
    /// The disk refused (full, read-only, permissions).
    Io,
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

/// The runner's connection to the outside: commands in, status out, watchdog, shutdown.
pub struct Control {
    /// Operator commands (from the control socket; a closed channel means none).
    pub commands: mpsc::Receiver<OperatorRequest>,
    /// Becomes `true` on SIGTERM/SIGINT.
    pub shutdown: watch::Receiver<bool>,
    /// Where status snapshots are published.
    pub status: watch::Sender<Status>,
    /// Called at `watchdog_interval` from inside the scan loop (systemd `WATCHDOG=1`).
    pub watchdog: Option<(Duration, Arc<dyn Fn() + Send + Sync>)>,
    /// Scan events (complete, fail, abort, suspended) for the notification hook.
    pub events: Option<mpsc::UnboundedSender<ScanEvent>>,
    pause_requested: bool,
}

impl std::fmt::Debug for Control {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Control")
            .field("pause_requested", &self.pause_requested)
            .finish_non_exhaustive()
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Interrupt {
    Abort,
    Shutdown,
}

impl Control {
    /// A control with the given channels, no watchdog and no event sink.
    pub fn new(
        commands: mpsc::Receiver<OperatorRequest>,
        shutdown: watch::Receiver<bool>,
        status: watch::Sender<Status>,
    ) -> Control {
        Control {
            commands,
            shutdown,
            status,
            watchdog: None,
            events: None,
            pause_requested: false,
        }
    }

    fn publish(&self, f: impl FnOnce(&mut Status)) {
        self.status.send_modify(f);
    }

    fn event(&self, scan_id: &str, dir: &Path, kind: ScanEventKind, reason: &str) {
        if let Some(tx) = &self.events {
            let _ = tx.send(ScanEvent {
                scan_id: scan_id.to_owned(),
                dir: dir.to_path_buf(),
                kind,
                reason: reason.to_owned(),
            });
        }
    }

    fn shutting_down(&self) -> bool {
        *self.shutdown.borrow()
    }

    /// The watchdog ticker (hourly, i.e. idle, without a watchdog).
    fn watchdog_tick(&self) -> tokio::time::Interval {
        let period = self
            .watchdog
            .as_ref()
            .map_or(Duration::from_secs(3600), |w| w.0);
        tokio::time::interval(period)
    }

    fn pet(&self) {
        if let Some((_, f)) = &self.watchdog {
            f();
        }
    }

    /// Answers a command that arrived while a scan runs; `Some` when it interrupts.
    fn on_command(&mut self, req: OperatorRequest, paused: bool) -> Option<Interrupt> {
        // Before its start record exists a new scan has no id yet: say so, never "scan  …".
        let scan = match self.status.borrow().scan_id.clone() {
            Some(id) => format!("scan {id}"),
            None => "the scan being started (no id yet)".to_owned(),
        };
        let (reply, interrupt) = match req.command {
            OperatorCommand::Pause if paused => (Ok(format!("{scan} is already paused")), None),
            OperatorCommand::Pause => {
                self.pause_requested = true;
                self.publish(|s| {
                    if s.state == State::Scanning {
                        s.state = State::Pausing;
                    }
                });
                (
                    Ok(format!("{scan} pauses once the current line is on disk")),
                    None,
                )
            }
            OperatorCommand::Resume if paused => (Ok(format!("{scan} resumes")), None),
            OperatorCommand::Resume if self.pause_requested => {
                self.pause_requested = false;
                self.publish(|s| {
                    if s.state == State::Pausing {
                        s.state = State::Scanning;
                    }
                });
                (Ok("pause request withdrawn".to_owned()), None)
            }
            // Resume is idempotent like pause: the scan is in the state asked for.
            OperatorCommand::Resume => (
                Ok(format!("{scan} is not paused; it goes on scanning")),
                None,
            ),
            OperatorCommand::Abort => (
                Ok(format!("aborting {scan}; lines on disk are kept")),
                Some(Interrupt::Abort),
            ),
            OperatorCommand::Start { .. } => (
                Err(format!(
                    "{scan} is running; abort it first or wait until it ends"
                )),
                None,
            ),
        };
        let _ = req.reply.send(reply);
        interrupt
    }

    /// Awaits `fut` while answering commands, watching for shutdown and feeding the
    /// watchdog; an abort or a shutdown cancels `fut`.
    async fn guarded<T>(&mut self, fut: impl Future<Output = T>) -> Result<T, Interrupt> {
        tokio::pin!(fut);
        if self.shutting_down() {
            return Err(Interrupt::Shutdown);
        }
        let mut tick = self.watchdog_tick();
        loop {
            tokio::select! {
                out = &mut fut => return Ok(out),
                Ok(()) = self.shutdown.changed() => {
                    if self.shutting_down() {
                        return Err(Interrupt::Shutdown);
                    }
                }
                Some(req) = self.commands.recv() => {
                    if let Some(i) = self.on_command(req, false) {
                        return Err(i);
                    }
                }
                _ = tick.tick() => self.pet(),
            }
        }
    }

    /// Waits while paused; returns on resume, or the interrupt.
    async fn paused(&mut self) -> Result<(), Interrupt> {
        let mut tick = self.watchdog_tick();
        loop {
            if self.shutting_down() {
                return Err(Interrupt::Shutdown);
            }
            tokio::select! {
                Ok(()) = self.shutdown.changed() => {}
                req = self.commands.recv() => match req {
                    Some(req) => {
                        let resume = req.command == OperatorCommand::Resume;
                        if let Some(i) = self.on_command(req, true) {
                            return Err(i);
                        }
                        if resume {
                            self.pause_requested = false;
                            return Ok(());
                        }
                    }
                    // Nobody can ever resume (no control channel): wait for shutdown only.
                    None => {
                        let _ = self.shutdown.wait_for(|v| *v).await;
                        return Err(Interrupt::Shutdown);
                    }
                },
                _ = tick.tick() => self.pet(),
            }
        }
    }
}

/// Why a line attempt ended without a committed line.
#[derive(Debug)]
enum LineError {
    Fault(Fault),
    Interrupt(Interrupt),
    /// The line is not acceptable for this scan and retrying cannot help.
    Refused(String),
    /// The line was not acceptable but a re-trace may give a good one.
    Retry(String),
    Storage(StoreError),
}

impl From<Interrupt> for LineError {
    fn from(i: Interrupt) -> Self {
        LineError::Interrupt(i)
    }
}

/// The end of a scan as decided inside the loop.
#[derive(Debug)]
enum End {
    Abort,
    Shutdown,
    Fail { reason: String, kind: FailKind },
}

impl From<Interrupt> for End {
    fn from(i: Interrupt) -> Self {
        match i {
            Interrupt::Abort => End::Abort,
            Interrupt::Shutdown => End::Shutdown,
        }
    }
}

fn fail(reason: impl Into<String>) -> End {
    End::Fail {
        reason: reason.into(),
        kind: FailKind::Scan,
    }
}

fn storage_fail(e: &StoreError) -> End {
    let reason = if e.is_disk_full() {
        format!("disk full: {e}")
    } else {
        format!("storage: {e}")
    };
    End::Fail {
        reason,
        kind: FailKind::Io,
    }
}

fn journal_fail(e: JournalError) -> End {
    storage_fail(&StoreError::Journal(e))
}

/// The open devices of a running scan.
struct Devices<S: Station> {
    instrument: Option<S::Instrument>,
    stage: Option<S::Stage>,
    need_home: bool,
    stage_identity: Option<String>,
}

/// One running scan's state.
struct Scan {
    id: String,
    dir: PathBuf,
    store: ScanStore,
    journal: Journal,
    plan: Plan,
    start: StartRecord,
    fitter: IncrementalFitter,
    /// The committed lines, in index order, as the fitter holds them.
    lines: Vec<StoredLine>,
    pitch_x_mm: Option<f64>,
    metrics: ScanMetrics,
    line_durations: Vec<f64>,
    hooks: Arc<TestHooks>,
    metrics_path: Option<PathBuf>,
    /// Reconnection backoff.
    backoff: Backoff,
}

impl Scan {
    fn interruption(&mut self, reason: &str, device: Option<Device>, line: Option<u32>) {
        tracing::warn!(scan_id = %self.id, line = line.map(|l| l + 1), "interruption: {reason}");
        let r = Record::Interruption(InterruptionRecord {
            reason: reason.to_owned(),
            device: device.map(|d| d.name().to_owned()),
            line,
            time: Utc::now(),
        });
        if let Err(e) = self.journal.append(&r) {
            tracing::error!(scan_id = %self.id, "cannot record the interruption in the journal: {e}");
        }
    }

    fn stop(&mut self, status: StopStatus, reason: &str) -> Result<(), JournalError> {
        self.journal.append(&Record::Stop(StopRecord {
            status,
            reason: reason.to_owned(),
            time: Utc::now(),
        }))
    }

    fn eta_s(&self) -> Option<f64> {
        if self.line_durations.is_empty() {
            return None;
        }
        let mean = self.line_durations.iter().sum::<f64>() / self.line_durations.len() as f64;
        let left = self.plan.lines.saturating_sub(self.fitter.lines() as u32);
        Some(mean * f64::from(left))
    }
}

/// Compares the conditions a line was traced under with the scan's; the first difference,
/// named, when they differ.
pub fn conditions_difference(scan: &Conditions, line: &Conditions) -> Option<String> {
    fn differs<T: PartialEq + std::fmt::Debug>(
        name: &str,
        at_start: &Option<T>,
        now: &Option<T>,
    ) -> Option<String> {
        let show = |v: &Option<T>| {
            v.as_ref()
                .map_or("unknown".to_owned(), |x| format!("{x:?}"))
        };
        (at_start != now).then(|| {
            format!(
                "{name} was {} at the start of the scan, now {}",
                show(at_start),
                show(now)
            )
        })
    }
    let (a, b) = (scan, line);
    differs("standard", &a.standard, &b.standard)
        .or_else(|| differs("profile", &a.profile_kind, &b.profile_kind))
        .or_else(|| differs("filter", &a.filter, &b.filter))
        .or_else(|| differs("lambda-c mm", &a.lambda_c_mm, &b.lambda_c_mm))
        .or_else(|| differs("lambda-s um", &a.lambda_s_um, &b.lambda_s_um))
        .or_else(|| differs("sampling lengths", &a.sampling_lengths, &b.sampling_lengths))
        .or_else(|| {
            differs(
                "evaluation length mm",
                &a.evaluation_length_mm,
                &b.evaluation_length_mm,
            )
        })
        .or_else(|| differs("speed mm/s", &a.speed_mm_s, &b.speed_mm_s))
}

/// A rough duration of one line: traverse at the measuring speed, return at twice that,
/// and the profile read-out at the link's baud rate (about 12 characters per point).
pub fn estimate_line_seconds(conditions: &Conditions, points: u64, baud: u32) -> f64 {
    let length_mm = conditions.evaluation_length_mm.unwrap_or(4.0);
    let speed = conditions.speed_mm_s.filter(|s| *s > 0.0).unwrap_or(0.5);
    // Pre-travel and post-travel of half a cut-off each side, as the SJ series does.
    let traverse = length_mm + conditions.lambda_c_mm.unwrap_or(0.8);
    let trace = traverse / speed * 1.5;
    let readout = points as f64 * 12.0 * 10.0 / f64::from(baud.max(1));
    trace + readout
}

/// Runs one scan to its end.
pub async fn run_scan<S: Station>(
    station: &mut S,
    ctl: &mut Control,
    settings: &RunSettings,
    request: ScanRequest,
) -> Outcome {
    ctl.pause_requested = false;
    let mut devices: Devices<S> = Devices {
        instrument: None,
        stage: None,
        need_home: false,
        stage_identity: None,
    };
    ctl.publish(|s| {
        s.state = State::Starting;
        s.reason = None;
    });
    let mut scan = match begin(station, ctl, settings, request, &mut devices).await {
        Ok(v) => v,
        Err((End::Fail { reason, kind }, dir)) => {
            tracing::error!("scan cannot start: {reason}");
            publish_end(ctl, None, dir.as_deref(), Ending::Fail, &reason);
            return Outcome::Failed { dir, reason, kind };
        }
        Err((End::Abort, dir)) => {
            publish_end(
                ctl,
                None,
                dir.as_deref(),
                Ending::Abort,
                "aborted before the first line",
            );
            return match dir {
                Some(dir) => Outcome::Aborted { dir },
                None => Outcome::Failed {
                    dir: None,
                    reason: "aborted before the scan started".into(),
                    kind: FailKind::Scan,
                },
            };
        }
        Err((End::Shutdown, dir)) => {
            publish_end(ctl, None, dir.as_deref(), Ending::Interrupted, "shutdown");
            return match dir {
                Some(dir) => Outcome::Interrupted { dir },
                None => Outcome::Failed {
                    dir: None,
                    reason: "shut down before the scan started".into(),
                    kind: FailKind::Scan,
                },
            };
        }
    };
    let end = scan_lines(station, ctl, &mut scan, &mut devices).await;
    finish(ctl, settings, scan, devices, end).await
}

fn publish_end(ctl: &Control, id: Option<&str>, dir: Option<&Path>, status: Ending, reason: &str) {
    ctl.publish(|s| {
        let scan_id = id
            .map(str::to_owned)
            .or_else(|| s.scan_id.clone())
            .unwrap_or_default();
        *s = Status {
            last_stop: Some(LastStop {
                scan_id,
                status,
                reason: reason.to_owned(),
                dir: dir.map(|d| d.display().to_string()).unwrap_or_default(),
            }),
            instrument: s.instrument,
            stage: s.stage,
            ..Status::idle()
        };
        s.instrument = downgrade(s.instrument);
        s.stage = downgrade(s.stage);
    });
}

fn downgrade(d: DeviceState) -> DeviceState {
    match d {
        DeviceState::Connected | DeviceState::Reconnecting => DeviceState::Present,
        other => other,
    }
}

type BeginError = (End, Option<PathBuf>);

/// An interrupt before the scan directory exists.
fn interrupted(i: Interrupt) -> BeginError {
    (End::from(i), None)
}

/// Opens and verifies the devices, creates or reopens the scan directory, rebuilds the
/// fitter on resume.
async fn begin<S: Station>(
    station: &mut S,
    ctl: &mut Control,
    settings: &RunSettings,
    request: ScanRequest,
    devices: &mut Devices<S>,
) -> Result<Scan, BeginError> {
    match request {
        ScanRequest::New {
            specimen,
            operator,
            notes,
        } => {
            let plan = settings.plan;
            let direction = ScanDirection::of_step(plan.y_step_nm);
            // Devices first: a scan directory is created only for a scan that can start.
            let unavailable = |f: Fault| {
                let kind = if f.class == FaultClass::Absent {
                    FailKind::Unavailable
                } else {
                    FailKind::Scan
                };
                (
                    End::Fail {
                        reason: f.to_string(),
                        kind,
                    },
                    None,
                )
            };
            let mut instrument = ctl
                .guarded(station.open_instrument())
                .await
                .map_err(interrupted)?
                .map_err(unavailable)?;
            let report = ctl
                .guarded(instrument.probe())
                .await
                .map_err(interrupted)?
                .map_err(|e| unavailable(Fault::of(Device::Instrument, &e)))?;
            for w in &report.warnings {
                tracing::warn!("instrument: {w}");
            }
            ctl.publish(|s| s.instrument = DeviceState::Connected);
            let mut stage = ctl
                .guarded(station.open_stage(direction))
                .await
                .map_err(interrupted)?
                .map_err(unavailable)?;
            let stage_report = ctl
                .guarded(stage.connect())
                .await
                .map_err(interrupted)?
                .map_err(|e| unavailable(Fault::of(Device::Stage, &e)))?;
            ctl.publish(|s| s.stage = DeviceState::Connected);
            let warnings = stage
                .check_targets(&plan.targets())
                .map_err(|e| (fail(Fault::of(Device::Stage, &e).to_string()), None))?;
            for w in &warnings {
                tracing::warn!("stage: {w}");
            }
            // Pre-flight: the disk must hold the whole scan.
            let pitch_um = station.expected_pitch_um(&report.conditions);
            let points = match (pitch_um, report.conditions.evaluation_length_mm) {
                (Some(p), Some(l)) if p > 0.0 => (l * 1000.0 / p).ceil() as u64 + 1,
                // Unknown: assume the SJ-210's longest profile (16 mm at 0.5 µm).
                _ => 32_001,
            };
            let output_dir = &settings.output_dir;
            std::fs::create_dir_all(output_dir).map_err(|e| {
                (
                    End::Fail {
                        reason: format!(
                            "cannot create output directory {}: {e}",
                            output_dir.display()
                        ),
                        kind: FailKind::Io,
                    },
                    None,
                )
            })?;
            let needed = preflight_disk(output_dir, plan.lines, points)
                .map_err(|e| (storage_fail(&e), None))?;
            let line_s =
                estimate_line_seconds(&report.conditions, points, settings.instrument_baud);
            tracing::info!(
                "pre-flight: {} lines of about {points} points, about {:.0} s per line ({:.1} h), about {:.1} MB on disk",
                plan.lines,
                line_s,
                line_s * f64::from(plan.lines) / 3600.0,
                needed as f64 / 1e6
            );
            let now = Utc::now();
            let id = unique_id(output_dir, now, &specimen);
            let faults: Arc<dyn StorageFaults> = settings.hooks.clone();
            let store = ScanStore::create(output_dir, &id, faults.clone())
                .map_err(|e| (storage_fail(&e), None))?;
            let dir = store.root().to_path_buf();
            let start = StartRecord {
                scan_id: id.0.clone(),
                time: now,
                plan,
                config: settings.config.clone(),
                config_hash: settings.config_hash.clone(),
                specimen,
                operator,
                notes,
                software_version: crate::build_info::software(),
                instrument_model: report.identity.model.clone(),
                firmware: report.identity.firmware.clone(),
                drive_unit: report.identity.drive_unit.clone(),
                conditions: report.conditions.clone(),
            };
            let journal = Journal::create(&dir, start.clone(), faults)
                .map_err(|e| (journal_fail(e), Some(dir.clone())))?;
            tracing::info!(scan_id = %id, "scan started in {}", dir.display());
            devices.need_home = settings.home_on_start || !stage_report.position_trusted;
            devices.stage_identity = Some(stage_report.identity.clone());
            devices.instrument = Some(instrument);
            devices.stage = Some(stage);
            let mut scan = new_scan(settings, id.0, dir, store, journal, plan, start);
            for w in warnings.iter().chain(&report.warnings) {
                scan.interruption(&format!("warning at start: {w}"), None, None);
            }
            publish_progress(ctl, &scan, None);
            Ok(scan)
        }
        ScanRequest::Resume(dir) => {
            let some_dir = Some(dir.clone());
            let faults: Arc<dyn StorageFaults> = settings.hooks.clone();
            let store =
                ScanStore::open(&dir, faults.clone()).map_err(|e| (storage_fail(&e), None))?;
            let (journal, recovery) = Journal::open(&store.journal_path(), faults)
                .map_err(|e| (fail(e.to_string()), None))?;
            let state = ResumeState::from_records(journal.path(), &recovery.records)
                .map_err(|e| (fail(e.to_string()), None))?;
            let plan = state.start.plan;
            if state.start.config_hash != settings.config_hash {
                tracing::warn!(
                    "the configuration changed since scan {} started; the plan frozen in its journal is followed",
                    state.start.scan_id
                );
            }
            let id = state.start.scan_id.clone();
            let start = state.start.clone();
            let mut scan = new_scan(settings, id, dir.clone(), store, journal, plan, start);
            let lines = scan.store.load_committed(&state.lines).map_err(|e| {
                (
                    fail(format!("cannot rebuild the fit: {e}")),
                    some_dir.clone(),
                )
            })?;
            for l in &lines {
                scan.fitter.push_line(l.y_mm(), &l.profile).map_err(|e| {
                    (
                        fail(format!(
                            "cannot rebuild the fit from line {}: {e}",
                            l.meta.index + 1
                        )),
                        some_dir.clone(),
                    )
                })?;
                scan.pitch_x_mm.get_or_insert(l.profile.pitch_x_mm);
            }
            scan.metrics.lines_done = lines.len() as u32;
            let note = format!(
                "resumed after a restart with {} of {} lines on disk{}",
                lines.len(),
                plan.lines,
                if recovery.torn_bytes > 0 {
                    format!(
                        "; a torn journal tail of {} bytes was truncated",
                        recovery.torn_bytes
                    )
                } else {
                    String::new()
                }
            );
            scan.lines = lines;
            tracing::info!(scan_id = %scan.id, "{note}");
            scan.interruption(&note, None, None);
            publish_progress(ctl, &scan, None);
            // Devices: a resumed scan waits for them like a suspended one.
            if let Err(end) =
                reconnect(station, ctl, &mut scan, devices, Device::Instrument, None).await
            {
                return Err((end, some_dir));
            }
            if let Err(end) = reconnect(station, ctl, &mut scan, devices, Device::Stage, None).await
            {
                return Err((end, some_dir));
            }
            Ok(scan)
        }
    }
}

fn scan_identity(s: &StartRecord) -> InstrumentIdentity {
    InstrumentIdentity {
        model: s.instrument_model.clone(),
        firmware: s.firmware.clone(),
        drive_unit: s.drive_unit.clone(),
    }
}

fn unique_id(output_dir: &Path, now: DateTime<Utc>, specimen: &str) -> ScanId {
    let base = ScanId::new(now, specimen);
    if !output_dir.join(&base.0).exists() {
        return base;
    }
    (2..)
        .map(|n| ScanId(format!("{}-{n}", base.0)))
        .find(|id| !output_dir.join(&id.0).exists())
        .unwrap_or(base)
}

fn new_scan(
    settings: &RunSettings,
    id: String,
    dir: PathBuf,
    store: ScanStore,
    journal: Journal,
    plan: Plan,
    start: StartRecord,
) -> Scan {
    let fitter = IncrementalFitter::new(FitOptions {
        degree_u: plan.degree_u,
        degree_v: plan.degree_v,
    });
    Scan {
        metrics: ScanMetrics {
            scan_id: id.clone(),
            lines_total: plan.lines,
            ..ScanMetrics::default()
        },
        id,
        dir,
        store,
        journal,
        plan,
        start,
        fitter,
        lines: Vec::new(),
        pitch_x_mm: None,
        line_durations: Vec::new(),
        hooks: settings.hooks.clone(),
        metrics_path: settings.metrics_file.clone(),
        backoff: settings.backoff,
    }
}

fn publish_progress(ctl: &Control, scan: &Scan, current: Option<u32>) {
    let done = scan.fitter.lines() as u32;
    let eta = scan.eta_s();
    ctl.publish(|s| {
        s.scan_id = Some(scan.id.clone());
        s.scan_dir = Some(scan.dir.display().to_string());
        s.lines_done = done;
        s.lines_total = scan.plan.lines;
        s.current_line = current.map(|k| k + 1);
        s.y_mm = current.map(|k| scan.plan.target(k).to_mm());
        s.eta_s = eta;
    });
}

/// Suspends until `device` is open and verified again (or there already).
async fn reconnect<S: Station>(
    station: &mut S,
    ctl: &mut Control,
    scan: &mut Scan,
    devices: &mut Devices<S>,
    device: Device,
    line: Option<u32>,
) -> Result<(), End> {
    let present = match device {
        Device::Instrument => devices.instrument.is_some(),
        Device::Stage => devices.stage.is_some(),
    };
    if present {
        return Ok(());
    }
    let started = Instant::now();
    let mut backoff = Duration::ZERO;
    let mut suspended = false;
    let mut last = String::new();
    loop {
        if !backoff.is_zero() {
            ctl.guarded(tokio::time::sleep(backoff)).await?;
        }
        let attempt = match device {
            Device::Instrument => open_instrument_verified(station, ctl, scan)
                .await?
                .map(|i| {
                    devices.instrument = Some(i);
                }),
            Device::Stage => {
                let direction = ScanDirection::of_step(scan.plan.y_step_nm);
                open_stage_verified(station, ctl, devices, direction)
                    .await?
                    .map(|(st, trusted)| {
                        devices.stage = Some(st);
                        if !trusted {
                            devices.need_home = true;
                        }
                    })
            }
        };
        match attempt {
            Ok(()) => {
                ctl.publish(|s| match device {
                    Device::Instrument => s.instrument = DeviceState::Connected,
                    Device::Stage => s.stage = DeviceState::Connected,
                });
                if suspended {
                    let msg = format!(
                        "{device} back after {:.0} s; scan continues",
                        started.elapsed().as_secs_f64()
                    );
                    scan.interruption(&msg, Some(device), line);
                    *scan
                        .metrics
                        .reconnects
                        .entry(device.name().to_owned())
                        .or_default() += 1;
                    ctl.publish(|s| {
                        s.state = State::Scanning;
                        s.reason = None;
                    });
                }
                return Ok(());
            }
            Err(f) if matches!(f.class, FaultClass::Absent | FaultClass::Transient) => {
                if !suspended {
                    suspended = true;
                    let reason = format!("{device} unavailable ({f}); reconnecting");
                    scan.interruption(&reason, Some(device), line);
                    scan.metrics.suspensions += 1;
                    ctl.event(&scan.id, &scan.dir, ScanEventKind::Suspended, &reason);
                    ctl.publish(|s| {
                        s.state = State::Suspended;
                        s.reason = Some(reason.clone());
                        match device {
                            Device::Instrument => s.instrument = DeviceState::Reconnecting,
                            Device::Stage => s.stage = DeviceState::Reconnecting,
                        }
                    });
                    write_scan_metrics(scan);
                } else if f.message != last {
                    tracing::info!(scan_id = %scan.id, "still waiting for the {device}: {f}");
                }
                last = f.message.clone();
                backoff = scan.backoff.next(backoff);
            }
            Err(f) => return Err(fail(f.to_string())),
        }
    }
}

async fn open_instrument_verified<S: Station>(
    station: &mut S,
    ctl: &mut Control,
    scan: &Scan,
) -> Result<Result<S::Instrument, Fault>, End> {
    let mut i = match ctl.guarded(station.open_instrument()).await? {
        Ok(i) => i,
        Err(f) => return Ok(Err(f)),
    };
    let report = match ctl.guarded(i.probe()).await? {
        Ok(r) => r,
        Err(e) => return Ok(Err(Fault::of(Device::Instrument, &e))),
    };
    let want = scan_identity(&scan.start);
    if report.identity.model != want.model
        || report.identity.firmware != want.firmware
        || report.identity.drive_unit != want.drive_unit
    {
        return Err(fail(format!(
            "a different instrument answered: model {}, firmware {:?}, drive unit {:?}; the scan started with model {}, firmware {:?}, drive unit {:?}",
            report.identity.model,
            report.identity.firmware,
            report.identity.drive_unit,
            want.model,
            want.firmware,
            want.drive_unit
        )));
    }
    Ok(Ok(i))
}

async fn open_stage_verified<S: Station>(
    station: &mut S,
    ctl: &mut Control,
    devices: &Devices<S>,
    direction: ScanDirection,
) -> Result<Result<(S::Stage, bool), Fault>, End> {
    let mut st = match ctl.guarded(station.open_stage(direction)).await? {
        Ok(s) => s,
        Err(f) => return Ok(Err(f)),
    };
    let report = match ctl.guarded(st.connect()).await? {
        Ok(r) => r,
        Err(e) => return Ok(Err(Fault::of(Device::Stage, &e))),
    };
    if let Some(want) = &devices.stage_identity {
        if &report.identity != want {
            return Err(fail(format!(
                "a different stage controller answered: {:?}; the scan started with {:?}",
                report.identity, want
            )));
        }
    }
    Ok(Ok((st, report.position_trusted)))
}

fn write_scan_metrics(scan: &Scan) {
    if let Some(p) = &scan.metrics_path {
        if let Err(e) = write_metrics(p, &scan.metrics, &*scan.store.faults()) {
            tracing::warn!("cannot write metrics {}: {e}", p.display());
        }
    }
}

/// The line loop from the first missing line to the last.
async fn scan_lines<S: Station>(
    station: &mut S,
    ctl: &mut Control,
    scan: &mut Scan,
    devices: &mut Devices<S>,
) -> Option<End> {
    // Lines are committed in order, so the fitter holds lines 0..n and n is next.
    let first = scan.fitter.lines() as u32;
    ctl.publish(|s| s.state = State::Scanning);
    for k in first..scan.plan.lines {
        if let Err(end) = one_line(station, ctl, scan, devices, k).await {
            return Some(end);
        }
        if ctl.pause_requested && k + 1 < scan.plan.lines {
            let reason = format!("paused by the operator after line {}", k + 1);
            scan.interruption(&reason, None, Some(k));
            ctl.publish(|s| {
                s.state = State::Paused;
                s.reason = Some(reason.clone());
                s.current_line = None;
            });
            if let Err(i) = ctl.paused().await {
                return Some(End::from(i));
            }
            scan.interruption("resumed by the operator", None, Some(k + 1));
            ctl.publish(|s| {
                s.state = State::Scanning;
                s.reason = None;
            });
        }
    }
    None
}

/// Traces line `k` until it is committed, within the attempt bound.
async fn one_line<S: Station>(
    station: &mut S,
    ctl: &mut Control,
    scan: &mut Scan,
    devices: &mut Devices<S>,
    k: u32,
) -> Result<(), End> {
    let mut attempt = 1u32;
    let started = Instant::now();
    loop {
        reconnect(station, ctl, scan, devices, Device::Instrument, Some(k)).await?;
        reconnect(station, ctl, scan, devices, Device::Stage, Some(k)).await?;
        publish_progress(ctl, scan, Some(k));
        ctl.publish(|s| {
            if s.state != State::Pausing {
                s.state = State::Scanning;
            }
        });
        match try_line(ctl, scan, devices, k, attempt).await {
            Ok(ra) => {
                let secs = started.elapsed().as_secs_f64();
                scan.line_durations.push(secs);
                let m = &mut scan.metrics;
                m.lines_done = scan.fitter.lines() as u32;
                m.last_line_seconds = Some(secs);
                m.line_seconds_sum += secs;
                m.line_seconds_count += 1;
                m.last_line_unix_seconds = Some(Utc::now().timestamp_millis() as f64 / 1000.0);
                write_scan_metrics(scan);
                publish_progress(ctl, scan, None);
                ctl.publish(|s| s.last_ra_um = ra);
                tracing::info!(
                    scan_id = %scan.id,
                    line = k + 1,
                    y_mm = scan.plan.target(k).to_mm(),
                    "line {}/{} on disk ({secs:.1} s{})",
                    k + 1,
                    scan.plan.lines,
                    ra.map(|r| format!(", Ra {r} um")).unwrap_or_default()
                );
                return Ok(());
            }
            // `finish` makes the best-effort abort and stop, once, for every interrupt.
            Err(LineError::Interrupt(i)) => return Err(End::from(i)),
            Err(LineError::Storage(e)) => return Err(storage_fail(&e)),
            Err(LineError::Refused(reason)) => {
                return Err(fail(format!("line {}: {reason}", k + 1)))
            }
            Err(LineError::Retry(reason)) => {
                retry_or_fail(scan, k, &mut attempt, &reason, None)?;
            }
            Err(LineError::Fault(f)) => match f.class {
                FaultClass::Absent => {
                    match f.device {
                        Device::Instrument => devices.instrument = None,
                        Device::Stage => devices.stage = None,
                    }
                    scan.interruption(
                        &format!("line {} abandoned: {f}", k + 1),
                        Some(f.device),
                        Some(k),
                    );
                }
                FaultClass::Transient => {
                    retry_or_fail(scan, k, &mut attempt, &f.to_string(), Some(f.device))?;
                }
                FaultClass::PositionLost => {
                    devices.need_home = true;
                    retry_or_fail(
                        scan,
                        k,
                        &mut attempt,
                        &format!("{f}; re-homing"),
                        Some(f.device),
                    )?;
                }
                FaultClass::Fatal => return Err(fail(format!("line {}: {f}", k + 1))),
            },
        }
    }
}

fn retry_or_fail(
    scan: &mut Scan,
    k: u32,
    attempt: &mut u32,
    reason: &str,
    device: Option<Device>,
) -> Result<(), End> {
    if *attempt >= scan.plan.max_line_attempts {
        return Err(fail(format!(
            "line {}: {} attempt(s) failed; last: {reason}",
            k + 1,
            attempt
        )));
    }
    scan.interruption(
        &format!(
            "line {} attempt {attempt} of {} abandoned: {reason}; tracing it again",
            k + 1,
            scan.plan.max_line_attempts
        ),
        device,
        Some(k),
    );
    scan.metrics.retries += 1;
    *attempt += 1;
    Ok(())
}

/// Best-effort abort of a running measurement and stop of the stage, bounded in time.
async fn cleanup<S: Station>(devices: &mut Devices<S>) {
    if let Some(i) = devices.instrument.as_mut() {
        match tokio::time::timeout(CLEANUP_TIMEOUT, i.abort()).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::warn!("instrument abort failed: {e}"),
            Err(_) => tracing::warn!("instrument abort timed out"),
        }
    }
    if let Some(s) = devices.stage.as_mut() {
        match tokio::time::timeout(CLEANUP_TIMEOUT, s.stop()).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::warn!("stage stop failed: {e}"),
            Err(_) => tracing::warn!("stage stop timed out"),
        }
    }
}

/// One attempt at line `k`; returns the instrument's Ra when it reported one.
async fn try_line<S: Station>(
    ctl: &mut Control,
    scan: &mut Scan,
    devices: &mut Devices<S>,
    k: u32,
    attempt: u32,
) -> Result<Option<f64>, LineError> {
    let target = scan.plan.target(k);
    let (Some(instrument), Some(stage)) = (devices.instrument.as_mut(), devices.stage.as_mut())
    else {
        return Err(LineError::Retry("a device is not connected".into()));
    };
    if devices.need_home {
        tracing::info!(scan_id = %scan.id, "homing the stage");
        ctl.guarded(stage.home())
            .await?
            .map_err(|e| LineError::Fault(Fault::of(Device::Stage, &e)))?;
        devices.need_home = false;
    }
    // The stage never moves unless the instrument reads idle.
    ctl.guarded(instrument.ensure_idle())
        .await?
        .map_err(|e| LineError::Fault(Fault::of(Device::Instrument, &e)))?;
    let arrival = ctl
        .guarded(stage.move_to(target))
        .await?
        .map_err(|e| LineError::Fault(Fault::of(Device::Stage, &e)))?;
    let started_at = Utc::now();
    let traced = ctl
        .guarded(instrument.trace())
        .await?
        .map_err(|e| LineError::Fault(Fault::of(Device::Instrument, &e)))?;
    let finished_at = Utc::now();
    check_line(scan, &traced)?;
    for w in &traced.warnings {
        tracing::warn!(scan_id = %scan.id, line = k + 1, "{w}");
    }
    for w in &traced.readout_warnings {
        tracing::warn!(scan_id = %scan.id, line = k + 1, "kept with a read-out warning: {w}");
    }
    let profile = &traced.profile;
    let meta = LineMeta {
        index: k,
        y_target_nm: target,
        y_readback_nm: Some(arrival.readback),
        pitch_x_mm: profile.pitch_x_mm,
        points: profile.len(),
        kind: profile.kind,
        conditions: profile.conditions.clone(),
        results: traced.results.clone(),
        readout_warnings: traced.readout_warnings.clone(),
        started_at,
        finished_at,
        attempt,
    };
    scan_commit(scan, &meta, profile)?;
    scan.fitter
        .push_line(target.to_mm(), profile)
        .map_err(|e| LineError::Refused(format!("the fitter refused the stored line: {e}")))?;
    scan.pitch_x_mm.get_or_insert(profile.pitch_x_mm);
    let ra = traced
        .results
        .iter()
        .find(|r| r.name.trim().eq_ignore_ascii_case("ra"))
        .and_then(|r| r.value);
    scan.lines.push(StoredLine {
        meta,
        profile: traced.profile,
    });
    Ok(ra)
}

fn scan_commit(scan: &mut Scan, meta: &LineMeta, profile: &Profile) -> Result<(), LineError> {
    // The hook learns the line before any of its writes.
    scan.hooks.set_line(meta.index);
    if let Err(e) = scan.store.commit_line(&mut scan.journal, meta, profile) {
        discard_uncommitted(scan, meta.index);
        return Err(LineError::Storage(e));
    }
    scan.hooks.at(Step::AfterCommit);
    Ok(())
}

/// After a failed commit: when the journal holds no record of line `index` (its append
/// failed or never happened), the line's files are removed so that nothing reading the
/// directory (`fit`, `analyze`) takes a line the scan never committed. A record that did
/// reach the journal (e.g. only its fsync failed) keeps the files it vouches for.
fn discard_uncommitted(scan: &Scan, index: u32) {
    let recorded = super::journal::read_journal(scan.journal.path()).is_ok_and(|r| {
        r.records
            .iter()
            .any(|rec| matches!(rec, Record::Line(l) if l.index == index))
    });
    if recorded {
        return;
    }
    let dir = scan.store.lines_dir();
    for name in [csv_name(index), meta_name(index)] {
        match std::fs::remove_file(dir.join(&name)) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!(
                scan_id = %scan.id,
                "cannot remove {} of the uncommitted line {}: {e}",
                name,
                index + 1
            ),
        }
    }
    let _ = sync_dir(&dir);
}

/// A traced line must fit the scan: finite heights, the scan's point count and pitch,
/// unchanged conditions.
fn check_line(scan: &Scan, t: &TracedLine) -> Result<(), LineError> {
    let p = &t.profile;
    if let Some(i) = p.heights_um.iter().position(|z| !z.is_finite()) {
        return Err(LineError::Retry(format!(
            "point {} of {} is {} (not a finite height)",
            i + 1,
            p.len(),
            p.heights_um[i]
        )));
    }
    let cols = scan.fitter.columns();
    if cols > 0 && p.len() != cols {
        return Err(LineError::Retry(format!(
            "{} points, but the scan's lines have {cols}",
            p.len()
        )));
    }
    if let Some(px) = scan.pitch_x_mm {
        if px != p.pitch_x_mm {
            return Err(LineError::Refused(format!(
                "x pitch {} mm differs from the scan's {px} mm",
                p.pitch_x_mm
            )));
        }
    }
    if let Some(d) = conditions_difference(&scan.start.conditions, &p.conditions) {
        return Err(LineError::Refused(format!(
            "measurement conditions changed on the instrument: {d}; restore them and start a new scan (the lines so far are kept)"
        )));
    }
    Ok(())
}

/// Closes the scan: outputs and stop record on success, stop record on abort or failure,
/// an interruption record on shutdown.
async fn finish<S: Station>(
    ctl: &mut Control,
    settings: &RunSettings,
    mut scan: Scan,
    mut devices: Devices<S>,
    end: Option<End>,
) -> Outcome {
    let dir = scan.dir.clone();
    let id = scan.id.clone();
    match end {
        None => {
            ctl.publish(|s| {
                s.state = State::Finishing;
                s.current_line = None;
            });
            let fitter = std::mem::replace(
                &mut scan.fitter,
                IncrementalFitter::new(FitOptions::default()),
            );
            match write_outputs(
                &scan.dir,
                &scan.start,
                &scan.plan,
                fitter,
                &scan.lines,
                settings.characterise.as_deref(),
            ) {
                Ok(outputs) => {
                    scan.metrics.fit_residual_um = Some(outputs.max_residual_mm * 1000.0);
                    write_scan_metrics(&scan);
                    let reason = format!(
                        "{} lines; surface {}",
                        scan.plan.lines,
                        outputs
                            .iges
                            .first()
                            .map(|p| p.display().to_string())
                            .unwrap_or_default()
                    );
                    if let Err(e) = scan.stop(StopStatus::Success, &reason) {
                        let reason = format!("cannot write the stop record: {e}");
                        publish_end(ctl, Some(&id), Some(&dir), Ending::Fail, &reason);
                        return Outcome::Failed {
                            dir: Some(dir),
                            reason,
                            kind: FailKind::Io,
                        };
                    }
                    tracing::info!(scan_id = %id, "scan complete: {reason}");
                    ctl.event(&id, &dir, ScanEventKind::Success, &reason);
                    publish_end(ctl, Some(&id), Some(&dir), Ending::Success, &reason);
                    Outcome::Success { dir, outputs }
                }
                Err(e) => {
                    let reason = format!(
                        "all lines are on disk but the outputs could not be written: {e}; free space and run `surfscan fit {}` and `surfscan analyze {}`",
                        dir.display(),
                        dir.display()
                    );
                    close_failed(ctl, &mut scan, &reason, FailKind::Io)
                }
            }
        }
        Some(End::Abort) => {
            cleanup(&mut devices).await;
            let reason = "aborted by the operator".to_owned();
            if let Err(e) = scan.stop(StopStatus::Abort, &reason) {
                tracing::error!(scan_id = %id, "cannot write the stop record: {e}");
            }
            tracing::warn!(scan_id = %id, "scan aborted; {} lines kept", scan.fitter.lines());
            ctl.event(&id, &dir, ScanEventKind::Abort, &reason);
            publish_end(ctl, Some(&id), Some(&dir), Ending::Abort, &reason);
            Outcome::Aborted { dir }
        }
        Some(End::Shutdown) => {
            cleanup(&mut devices).await;
            let line = scan.fitter.lines() as u32;
            scan.interruption(
                "shutdown (SIGTERM/SIGINT): current line abandoned; the scan resumes at the next start",
                None,
                (line < scan.plan.lines).then_some(line),
            );
            ctl.publish(|s| s.state = State::Stopping);
            Outcome::Interrupted { dir }
        }
        Some(End::Fail { reason, kind }) => close_failed(ctl, &mut scan, &reason, kind),
    }
}

fn close_failed(ctl: &Control, scan: &mut Scan, reason: &str, kind: FailKind) -> Outcome {
    tracing::error!(scan_id = %scan.id, "scan failed: {reason}");
    if let Err(e) = scan.stop(StopStatus::Fail, reason) {
        tracing::error!(scan_id = %scan.id, "cannot write the stop record: {e}");
    }
    ctl.event(&scan.id, &scan.dir, ScanEventKind::Fail, reason);
    publish_end(ctl, Some(&scan.id), Some(&scan.dir), Ending::Fail, reason);
    Outcome::Failed {
        dir: Some(scan.dir.clone()),
        reason: reason.to_owned(),
        kind,
    }
}
