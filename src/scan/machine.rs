//! The scan session as a sans-IO state machine: events in, each with the time it happened;
//! actions out. It owns the plan, the line being worked on, the attempt counters, the
//! pause and suspension state, the backoff and the transient-fault budget, the status
//! snapshot and the metrics; it performs nothing. The runner ([`super::runner`]) performs
//! each action and feeds its result back as an event.
//!
//! The protocol: [`Machine::start`] and every [`Machine::handle`] return a batch of actions.
//! All but the last are immediate (publish, record, notify, reply, metrics, close, cancel,
//! stop); the last may be an *effect* ([`Action::is_effect`]) whose result is the next
//! event. While an effect is in flight the runner feeds operator commands and shutdown; a
//! batch answering one of them may begin with [`Action::Cancel`] (drop the effect in
//! flight) followed by a new effect. After [`Action::Stop`] the machine takes no more
//! events.
//!
//! The order of a line k: the instrument must read idle before the stage moves; then move,
//! trace, check the line against the scan, commit it durably, push it into the fitter; only
//! then line k+1. A scan whose lines are all committed writes its outputs without opening any
//! device. Pause is deferred until the current line is on disk; abort and shutdown cancel what
//! is in flight, make a best-effort device clean-up, then end (shutdown leaves the scan
//! resumable: no stop record).
//!
//! Every fault goes through one door ([`Machine`]'s `trouble`): the transient budget is
//! charged when the fault is one it bounds (it runs from the first such fault of a line and
//! starts again when a line commits; time a device was waited for is not spent from it), the
//! table [`policy::react`] decides, and the reaction is carried out: reopen a device (no time
//! limit, no attempt spent), retry the line with backoff, re-home, wait for the storage with
//! the traced line held in memory, refuse a start, or fail naming the fault. The texts are
//! [`reasons`]'.
//!
//! Layer 3 (session), pure: depends on the session's own plan (and its disk estimate),
//! policy, reasons, status, command, event and metrics types, and [`crate::devices`]' device
//! and fault vocabulary. No tokio, no files, no clock reads: time is an input.

use super::command::{OperatorCommand, PauseMark, Peer, StartMode};
use super::ending::{End, FailKind, FailReason};
use super::event::ScanEventKind;
use super::line_check::{conditions_difference, LineProblem};
use super::metrics::ScanMetrics;
use super::plan::{remaining_scan_bytes, remaining_scan_inodes, Plan};
use super::policy::{self, Backoff, FailRule, FaultKind, Reaction, Situation, Step, StorageClass};
use super::reasons;
use super::status::{ended_status, DeviceState, State, Status};
use crate::devices::{Device, Fault, FaultClass};
use crate::profile::Conditions;
use crate::units::Nm;
use chrono::{DateTime, Utc};
use std::collections::BTreeSet;
use std::time::{Duration, Instant};

/// When an event happened: a monotonic instant (for budgets and durations) and the wall
/// clock (for what people read).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Now {
    /// Monotonic time.
    pub mono: Instant,
    /// Wall-clock time.
    pub wall: DateTime<Utc>,
}

/// The session's fault policy, from the station's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Policy {
    /// Backoff of reconnection tries, transient retries and free-space checks.
    pub backoff: Backoff,
    /// How long transient faults may go on (from the first one since the last committed
    /// line) before the scan fails.
    pub transient_budget: Duration,
    /// Home before the first line of a new scan even when the position is trusted.
    pub home_on_start: bool,
}

/// What a resumed scan already has on disk.
#[derive(Debug, Clone, PartialEq)]
pub struct Resumed {
    /// Scan id.
    pub scan_id: String,
    /// Scan directory, for people.
    pub dir: String,
    /// Lines committed without a gap (they are lines `0..committed`).
    pub committed: u32,
    /// Lines committed after the first gap (a committed line moved aside at resume, to be
    /// traced again): the machine skips them; the ledger feeds them to the fitter after the
    /// line before them.
    pub ahead: BTreeSet<u32>,
    /// Points per committed line, when a line is committed.
    pub columns: Option<usize>,
    /// x pitch of the committed lines, mm.
    pub pitch_x_mm: Option<f64>,
    /// Conditions the scan started under.
    pub conditions: Conditions,
    /// Estimated points per line, for the disk-space need.
    pub points_per_line: u64,
    /// The operator's pause was in force when the scan's process stopped: the scan is
    /// reopened paused, and nothing moves until it is resumed.
    pub paused: bool,
}

/// A traced line as the machine checks it (the heights stay with the runner).
#[derive(Debug, Clone, PartialEq)]
pub struct TracedSummary {
    /// Number of points.
    pub points: usize,
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// The first height that is not a finite number: its 0-based index and value.
    pub first_non_finite: Option<(usize, f64)>,
    /// Conditions it was traced under.
    pub conditions: Conditions,
    /// The instrument's Ra of the line, µm, when it reported one.
    pub ra_um: Option<f64>,
}

/// What a failed durable write was.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StorageFailure {
    /// How the file system refused it; `None` when no file system did (the outputs cannot be
    /// made from the lines, or an internal error).
    pub class: Option<StorageClass>,
    /// The operating system's error number, when it gave one.
    pub errno: Option<i32>,
    /// The error, naming the file.
    pub message: String,
}

impl StorageFailure {
    /// The disk (or a quota) is full.
    pub fn full(message: String) -> StorageFailure {
        StorageFailure {
            class: Some(StorageClass::Full),
            errno: Some(libc::ENOSPC),
            message,
        }
    }

    /// A failure that is no refusal of the file system.
    pub fn not_storage(message: String) -> StorageFailure {
        StorageFailure {
            class: None,
            errno: None,
            message,
        }
    }
}

/// A fault as the machine holds it: its kind for the policy's table, its details for the
/// reasons.
#[derive(Debug, Clone, PartialEq)]
enum Trouble {
    /// A device operation failed.
    Device(Fault),
    /// The traced line does not fit the scan.
    Line(LineProblem),
    /// The fitter refused the committed line.
    Fitter(String),
    /// A durable write failed.
    Storage(StorageFailure),
}

impl Trouble {
    fn kind(&self) -> FaultKind {
        match self {
            Trouble::Device(f) => FaultKind::Device(f.class),
            Trouble::Line(p) if p.retry_may_help() => FaultKind::LineRetryable,
            Trouble::Line(_) => FaultKind::LineForeign,
            Trouble::Fitter(_) => FaultKind::FitterRefused,
            Trouble::Storage(s) => s
                .class
                .map_or(FaultKind::OutputsImpossible, FaultKind::Storage),
        }
    }

    /// The device concerned, if one is.
    fn device(&self) -> Option<Device> {
        match self {
            Trouble::Device(f) => Some(f.device),
            Trouble::Line(_) => Some(Device::Instrument),
            Trouble::Fitter(_) | Trouble::Storage(_) => None,
        }
    }

    /// The fault as the last one of a retried line names it.
    fn on_line(&self, line: u32) -> String {
        match self {
            Trouble::Device(f) => reasons::on_line(line, f),
            Trouble::Line(p) => reasons::on_line(line, p),
            Trouble::Fitter(m) => reasons::on_line(line, m),
            Trouble::Storage(s) => reasons::on_line(line, &s.message),
        }
    }
}

/// An interruption for the journal: what happened, to which device, on which line, asked
/// by whom.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Note {
    /// For people.
    pub reason: String,
    /// The device concerned.
    pub device: Option<Device>,
    /// The line being worked on (0-based).
    pub line: Option<u32>,
    /// The operator's connection, for commands.
    pub peer: Option<Peer>,
    /// The pause taking effect, or its resumption.
    pub pause: Option<PauseMark>,
}

impl Note {
    /// Whether the note records what an operator asked for (a pause taking effect, a resume,
    /// an abort, a command refused), which is the normal course of a scan and logged as
    /// such, not as a fault.
    pub fn is_operators(&self) -> bool {
        self.peer.is_some() || self.pause.is_some()
    }
}

/// An event of the session.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The device is open and verified; `position_trusted` is the stage's (ignored for the
    /// instrument).
    Opened {
        /// Which.
        device: Device,
        /// Whether the stage's position can be trusted.
        position_trusted: bool,
    },
    /// The new scan's directory and start record are on disk.
    Created {
        /// Scan id.
        scan_id: String,
        /// Scan directory, for people.
        dir: String,
        /// Conditions the scan starts under.
        conditions: Conditions,
        /// Estimated points per line.
        points_per_line: u64,
    },
    /// The stage is homed.
    Homed,
    /// The instrument reads idle.
    Idle,
    /// The stage arrived at the line's target.
    Arrived,
    /// The line was traced and read out.
    Traced(TracedSummary),
    /// The line is durably committed (files and journal record).
    Committed,
    /// The fitter took the committed line.
    Pushed,
    /// The fitter refused the committed line.
    PushRefused(String),
    /// The outputs are written.
    OutputsWritten {
        /// What was written, for the stop record.
        summary: String,
    },
    /// A device operation failed; `trace_started` says whether a trace was really started
    /// (false for faults outside a trace, and for a trace refused before it began).
    Fault {
        /// The fault.
        fault: Fault,
        /// Whether a trace was started.
        trace_started: bool,
    },
    /// A durable write failed (commit, or the outputs when finishing).
    StorageFailed(StorageFailure),
    /// Writing the outputs panicked (a bug): the scan fails with
    /// [`FailReason::OutputsInternal`] and these words.
    OutputsPanicked(String),
    /// The new scan must not be made: the instrument is not set as its recipe expects
    /// (what differs, named). The scan fails before its directory exists.
    CreateRefused(String),
    /// The free space of the output directory, as asked by [`Action::CheckSpace`].
    SpaceChecked {
        /// Bytes free (0 when it could not be read).
        free_bytes: u64,
        /// Inodes free (`u64::MAX` when the file system does not count them, 0 when they
        /// could not be read).
        free_inodes: u64,
        /// Bytes the scan's own outputs already take (an earlier try's surface, report and
        /// plots, which the next try replaces); 0 before the outputs.
        outputs_bytes: u64,
    },
    /// The timer set by [`Action::SetTimer`] fired.
    TimerFired,
    /// The best-effort clean-up is done.
    CleanedUp,
    /// An operator command (the runner holds its reply channel and sends [`Action::Reply`]).
    Command {
        /// The command.
        command: OperatorCommand,
        /// Who sent it.
        peer: Peer,
    },
    /// SIGTERM / SIGINT.
    Shutdown,
}

/// Something for the runner to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Open the device and verify it (probe / connect; identity against the scan's once it
    /// has a start record). Result: [`Event::Opened`] or [`Event::Fault`].
    Open(Device),
    /// Drop a device that vanished (immediate).
    Close(Device),
    /// Pre-flight disk check, create the scan directory and its start record. Result:
    /// [`Event::Created`], [`Event::StorageFailed`] or [`Event::CreateRefused`].
    CreateScan,
    /// Home the stage. Result: [`Event::Homed`] or [`Event::Fault`].
    Home,
    /// Make the instrument read idle. Result: [`Event::Idle`] or [`Event::Fault`].
    EnsureIdle,
    /// Move to the target. Result: [`Event::Arrived`] or [`Event::Fault`].
    Move(Nm),
    /// Trace the line. Result: [`Event::Traced`] or [`Event::Fault`].
    Trace,
    /// Commit the traced line (held by the runner) durably as line `line`, produced by trace
    /// `attempt`. Result: [`Event::Committed`] or [`Event::StorageFailed`].
    Commit {
        /// 0-based line index.
        line: u32,
        /// 1-based number of the trace that produced it.
        attempt: u32,
    },
    /// Push the committed line into the fitter. Result: [`Event::Pushed`] or
    /// [`Event::PushRefused`].
    Push {
        /// 0-based line index.
        line: u32,
    },
    /// Finish the fit and write IGES, report, X3P, plots. Result:
    /// [`Event::OutputsWritten`], [`Event::StorageFailed`] (a refused write, or outputs the
    /// lines cannot make, without a storage class) or [`Event::OutputsPanicked`] (a bug).
    WriteOutputs,
    /// Read the free space of the output directory. Result: [`Event::SpaceChecked`].
    CheckSpace,
    /// Wait. Result: [`Event::TimerFired`].
    SetTimer(Duration),
    /// Best-effort instrument abort and stage stop. Result: [`Event::CleanedUp`].
    Cleanup,
    /// Drop the effect in flight (immediate; an abort or shutdown arrived).
    Cancel,
    /// Publish this status snapshot (immediate).
    Publish(Status),
    /// Append an interruption record (immediate).
    Record(Note),
    /// Tell the notification hook (immediate).
    Notify(ScanEventKind, String),
    /// Answer the command last fed (immediate).
    Reply(Result<String, String>),
    /// Write the metrics file (immediate).
    Metrics(ScanMetrics),
    /// The scan ends (immediate; the stop record, except after a shutdown).
    Stop(End),
}

impl Action {
    /// True for actions whose result is the next event.
    pub fn is_effect(&self) -> bool {
        !matches!(
            self,
            Action::Close(_)
                | Action::Cancel
                | Action::Publish(_)
                | Action::Record(_)
                | Action::Notify(..)
                | Action::Reply(_)
                | Action::Metrics(_)
                | Action::Stop(_)
        )
    }
}

/// The effect in flight, i.e. what the next event answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Doing {
    Open(Device),
    Create,
    Home,
    Idle,
    Move,
    Trace,
    Commit,
    Push,
    Outputs,
    CheckSpace,
    /// A wait; what follows it.
    Wait(AfterWait),
    Cleanup,
    /// Paused by the operator: nothing in flight.
    Paused,
    Nothing,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum AfterWait {
    /// Reopen this device.
    Open(Device),
    /// Start the line again.
    Retry,
    /// Check the free space.
    CheckSpace,
    /// Make the refused write again.
    Rewrite,
}

/// Why the scan is suspended.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Cause {
    Absent(Device),
    Busy(Device),
    /// The file system refused committing the held line (`outputs` false) or writing the
    /// outputs; for a full disk, the space and inodes the rest of the scan needs.
    Storage {
        class: StorageClass,
        needed_bytes: u64,
        needed_inodes: u64,
        outputs: bool,
        /// Free bytes at the last check.
        free_bytes: Option<u64>,
    },
}

#[derive(Debug, Clone)]
struct Suspension {
    cause: Cause,
    since: Now,
    /// The last wait.
    wait: Duration,
}

/// The transient-fault budget of the current line.
#[derive(Debug, Clone)]
struct Budget {
    since: Now,
    last: String,
    /// Time since `since` that a device was absent: a suspension without a time limit,
    /// so not spent from the budget.
    absent: Duration,
    /// The suspension was announced (counted, the hook told) at the budget's first retry.
    announced: bool,
}

/// The session core.
#[derive(Debug, Clone)]
pub struct Machine {
    plan: Plan,
    policy: Policy,
    status: Status,
    metrics: ScanMetrics,
    /// True once the scan directory and start record exist.
    created: bool,
    /// The next line to commit (lines `0..line` are committed).
    line: u32,
    /// Lines committed after the next one (resumed after a gap); skipped when reached.
    ahead: BTreeSet<u32>,
    doing: Doing,
    instrument_open: bool,
    stage_open: bool,
    need_home: bool,
    pause_requested: bool,
    /// Traces started for the current line.
    traces: u32,
    /// Re-homes after a lost position on the current line.
    rehomes: u32,
    /// When the current line's work began.
    line_began: Option<Instant>,
    line_seconds: Vec<f64>,
    budget: Option<Budget>,
    /// Backoff of transient retries on the current line.
    retry_wait: Duration,
    suspension: Option<Suspension>,
    /// Points per committed line, and the scan's pitch.
    columns: Option<usize>,
    pitch_x_mm: Option<f64>,
    conditions: Option<Conditions>,
    points_per_line: u64,
    /// Ra of the traced line waiting for its commit.
    held_ra: Option<f64>,
    ending: Option<End>,
    ended: bool,
}

impl Machine {
    /// A new scan of `plan`; `status` is the snapshot before it (device states and the last
    /// stop are carried on).
    pub fn new_scan(plan: Plan, policy: Policy, status: Status) -> Machine {
        Machine::build(plan, policy, status, None)
    }

    /// A scan resumed from its directory.
    pub fn resumed(plan: Plan, policy: Policy, status: Status, r: Resumed) -> Machine {
        Machine::build(plan, policy, status, Some(r))
    }

    fn build(plan: Plan, policy: Policy, mut status: Status, r: Option<Resumed>) -> Machine {
        status.state = State::Starting;
        status.reason = None;
        let lines_total = plan.lines;
        let mut m = Machine {
            plan,
            policy,
            status,
            metrics: ScanMetrics {
                lines_total,
                ..ScanMetrics::default()
            },
            created: false,
            line: 0,
            doing: Doing::Nothing,
            instrument_open: false,
            stage_open: false,
            need_home: false,
            pause_requested: false,
            traces: 0,
            rehomes: 0,
            line_began: None,
            line_seconds: Vec::new(),
            budget: None,
            retry_wait: Duration::ZERO,
            suspension: None,
            columns: None,
            pitch_x_mm: None,
            conditions: None,
            points_per_line: 0,
            ahead: BTreeSet::new(),
            held_ra: None,
            ending: None,
            ended: false,
        };
        if let Some(r) = r {
            m.created = true;
            m.line = r.committed.min(lines_total);
            m.ahead = r.ahead;
            m.skip_ahead();
            m.columns = r.columns;
            m.pitch_x_mm = r.pitch_x_mm;
            m.conditions = Some(r.conditions);
            m.points_per_line = r.points_per_line;
            if r.paused {
                m.doing = Doing::Paused;
            }
            m.metrics.scan_id = r.scan_id.clone();
            m.metrics.lines_done = m.done();
            m.status.scan_id = Some(r.scan_id);
            m.status.scan_dir = Some(r.dir);
        }
        m
    }

    /// The status snapshot as the machine last published it.
    pub fn status(&self) -> &Status {
        &self.status
    }

    /// The plan.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The next line to commit (0-based); equals the plan's line count when all are.
    pub fn line(&self) -> u32 {
        self.line
    }

    /// True once [`Action::Stop`] was returned.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// The first actions: open the devices of a new scan, or (resumed) go on where the
    /// scan stands.
    pub fn start(&mut self, now: Now) -> Vec<Action> {
        let mut out = Vec::new();
        if self.created && self.doing == Doing::Paused {
            // Paused by the operator before the process stopped: it stays paused, with no
            // device opened, until the operator resumes it.
            self.status.state = State::Paused;
            self.status.reason = Some(reasons::paused_before_restart());
            self.publish_progress(&mut out, None);
        } else if self.created {
            self.publish_progress(&mut out, None);
            self.next_step(now, &mut out);
        } else {
            self.publish(&mut out);
            self.effect(&mut out, Doing::Open(Device::Instrument));
        }
        out
    }

    /// One event in; the actions it calls for.
    pub fn handle(&mut self, event: Event, now: Now) -> Vec<Action> {
        let mut out = Vec::new();
        if self.ended {
            if let Event::Command { command, .. } = event {
                out.push(Action::Reply(Err(self.refusal(&command))));
            }
            return out;
        }
        match event {
            Event::Command { command, peer } => self.command(command, peer, now, &mut out),
            Event::Shutdown => self.interrupt(End::Shutdown, &mut out),
            Event::CleanedUp => {
                if self.doing == Doing::Cleanup {
                    let end = self.ending.take().unwrap_or(End::Shutdown);
                    self.stop(end, &mut out);
                }
            }
            _ if self.ending.is_some() => {}
            ev => self.progress(ev, now, &mut out),
        }
        out
    }

    fn refusal(&self, _command: &OperatorCommand) -> String {
        "the scan has ended".to_owned()
    }

    // ---- the line loop -------------------------------------------------------------

    fn progress(&mut self, ev: Event, now: Now, out: &mut Vec<Action>) {
        match (self.doing, ev) {
            (
                Doing::Open(d),
                Event::Opened {
                    device,
                    position_trusted,
                },
            ) if d == device => self.opened(device, position_trusted, now, out),
            (Doing::Open(_), Event::Fault { fault, .. }) => {
                self.trouble(Step::Opening, Trouble::Device(fault), now, out)
            }
            (
                Doing::Create,
                Event::Created {
                    scan_id,
                    dir,
                    conditions,
                    points_per_line,
                },
            ) => {
                self.created = true;
                out.push(Action::Notify(
                    ScanEventKind::Started,
                    reasons::started(self.done(), self.plan.lines),
                ));
                self.metrics.scan_id = scan_id.clone();
                self.status.scan_id = Some(scan_id);
                self.status.scan_dir = Some(dir);
                self.conditions = Some(conditions);
                self.points_per_line = points_per_line;
                self.publish_progress(out, None);
                // A pause asked for while the scan was being started still stands.
                self.status.state = if self.pause_requested {
                    State::Pausing
                } else {
                    State::Scanning
                };
                self.next_step(now, out);
            }
            (Doing::Create, Event::CreateRefused(message)) => self.fail(
                FailReason::Refused {
                    message,
                    kind: FailKind::Scan,
                },
                out,
            ),
            (Doing::Create, Event::StorageFailed(s)) => {
                self.trouble(Step::Creating, Trouble::Storage(s), now, out)
            }
            (Doing::Home, Event::Homed) => {
                self.need_home = false;
                self.effect(out, Doing::Move);
            }
            // The drive is at rest (a trace's return may still run when its read-out ended
            // first): only now may the stage move, to home or to the line.
            (Doing::Idle, Event::Idle) if self.need_home => self.effect(out, Doing::Home),
            (Doing::Idle, Event::Idle) => self.effect(out, Doing::Move),
            (Doing::Move, Event::Arrived) => self.effect(out, Doing::Trace),
            (Doing::Trace, Event::Traced(t)) => {
                self.traces += 1;
                match self.check(&t) {
                    None => {
                        self.held_ra = t.ra_um;
                        self.columns.get_or_insert(t.points);
                        self.pitch_x_mm.get_or_insert(t.pitch_x_mm);
                        self.commit(out);
                    }
                    Some(problem) => self.trouble(Step::Checking, Trouble::Line(problem), now, out),
                }
            }
            (
                Doing::Home | Doing::Idle | Doing::Move | Doing::Trace,
                Event::Fault {
                    fault,
                    trace_started,
                },
            ) => {
                // A trace cut off by a vanished or silent device is the suspension's, not an
                // attempt.
                if self.doing == Doing::Trace
                    && trace_started
                    && !matches!(fault.class, FaultClass::Absent | FaultClass::Silent)
                {
                    self.traces += 1;
                }
                let step = match self.doing {
                    Doing::Home => Step::Homing,
                    Doing::Idle => Step::EnsuringIdle,
                    Doing::Move => Step::Moving,
                    _ => Step::Tracing,
                };
                self.trouble(step, Trouble::Device(fault), now, out);
            }
            (Doing::Commit, Event::Committed) => {
                self.storage_back(now, out);
                self.effect_push(out);
            }
            (Doing::Commit, Event::StorageFailed(s)) => {
                self.trouble(Step::Committing, Trouble::Storage(s), now, out)
            }
            (Doing::Push, Event::Pushed) => self.line_done(now, out),
            (Doing::Push, Event::PushRefused(message)) => {
                self.trouble(Step::Pushing, Trouble::Fitter(message), now, out)
            }
            (Doing::Outputs, Event::OutputsWritten { summary }) => {
                self.stop(End::Success { summary }, out)
            }
            (Doing::Outputs, Event::StorageFailed(s)) => {
                self.trouble(Step::Outputs, Trouble::Storage(s), now, out)
            }
            (Doing::Outputs, Event::OutputsPanicked(words)) => {
                self.fail(FailReason::OutputsInternal(words), out)
            }
            (
                Doing::CheckSpace,
                Event::SpaceChecked {
                    free_bytes,
                    free_inodes,
                    outputs_bytes,
                },
            ) => self.space_checked(free_bytes, free_inodes, outputs_bytes, out),
            (Doing::Wait(after), Event::TimerFired) => match after {
                AfterWait::Open(d) => self.effect(out, Doing::Open(d)),
                AfterWait::Retry => self.next_step(now, out),
                AfterWait::CheckSpace => self.effect(out, Doing::CheckSpace),
                AfterWait::Rewrite => self.rewrite(out),
            },
            // An answer to something not asked (a late result after a cancel): ignored.
            _ => {}
        }
    }

    /// Issues the effect `doing` stands for.
    fn effect(&mut self, out: &mut Vec<Action>, doing: Doing) {
        self.doing = doing;
        out.push(match doing {
            Doing::Open(d) => Action::Open(d),
            Doing::Create => Action::CreateScan,
            Doing::Home => Action::Home,
            Doing::Idle => Action::EnsureIdle,
            Doing::Move => Action::Move(self.plan.target(self.line)),
            Doing::Trace => Action::Trace,
            Doing::Commit => Action::Commit {
                line: self.line,
                attempt: self.traces.max(1),
            },
            Doing::Push => Action::Push { line: self.line },
            Doing::Outputs => Action::WriteOutputs,
            Doing::CheckSpace => Action::CheckSpace,
            Doing::Cleanup => Action::Cleanup,
            Doing::Wait(_) | Doing::Paused | Doing::Nothing => return,
        });
    }

    fn wait(&mut self, out: &mut Vec<Action>, d: Duration, after: AfterWait) {
        self.doing = Doing::Wait(after);
        out.push(Action::SetTimer(d));
    }

    fn commit(&mut self, out: &mut Vec<Action>) {
        self.effect(out, Doing::Commit);
    }

    fn effect_push(&mut self, out: &mut Vec<Action>) {
        self.effect(out, Doing::Push);
    }

    /// What the current line needs next: devices, homing, idle, then move and trace; the
    /// outputs once every line is committed.
    fn next_step(&mut self, now: Now, out: &mut Vec<Action>) {
        if self.line >= self.plan.lines {
            self.status.state = State::Finishing;
            self.status.current_line = None;
            self.status.y_mm = None;
            self.publish(out);
            self.effect(out, Doing::Outputs);
            return;
        }
        if !self.instrument_open {
            return self.effect(out, Doing::Open(Device::Instrument));
        }
        if !self.stage_open {
            return self.effect(out, Doing::Open(Device::Stage));
        }
        self.line_began.get_or_insert(now.mono);
        if self.status.state != State::Pausing && self.suspension.is_none() {
            self.status.state = State::Scanning;
        }
        self.publish_progress(out, Some(self.line));
        self.effect(out, Doing::Idle);
    }

    fn opened(&mut self, device: Device, trusted: bool, now: Now, out: &mut Vec<Action>) {
        match device {
            Device::Instrument => {
                self.instrument_open = true;
                self.status.instrument = DeviceState::Connected;
            }
            Device::Stage => {
                self.stage_open = true;
                self.status.stage = DeviceState::Connected;
                if !trusted || (!self.created && self.policy.home_on_start) {
                    self.need_home = true;
                }
            }
        }
        if let Some(s) = &self.suspension {
            if s.cause == Cause::Absent(device) {
                let absent = now.mono.saturating_duration_since(s.since.mono);
                if let Some(b) = &mut self.budget {
                    b.absent += absent;
                }
                let back = reasons::back_after(device, absent);
                out.push(self.note(back.clone(), Some(device)));
                out.push(Action::Notify(ScanEventKind::Resumed, back));
                *self
                    .metrics
                    .reconnects
                    .entry(device.name().to_owned())
                    .or_default() += 1;
                self.suspension = None;
                self.status.state = State::Scanning;
                self.status.reason = None;
            }
        }
        if !self.created {
            self.publish(out);
            match device {
                Device::Instrument => self.effect(out, Doing::Open(Device::Stage)),
                Device::Stage => self.effect(out, Doing::Create),
            }
            return;
        }
        self.next_step(now, out);
    }

    // ---- faults: the policy's table decides, these carry its reactions out -------------

    /// A fault in `step`: the budget is charged when the fault is one it bounds, the table
    /// ([`policy::react`]) is asked, and its reaction carried out.
    fn trouble(&mut self, step: Step, t: Trouble, now: Now, out: &mut Vec<Action>) {
        let kind = t.kind();
        let budget_spent = match kind {
            FaultKind::Device(FaultClass::Transient) | FaultKind::LineRetryable if self.created => {
                let why = t.on_line(self.line);
                self.charge_budget(why, now)
            }
            _ => false,
        };
        let situation = Situation {
            step,
            created: self.created,
            budget_spent,
            rehomes: self.rehomes,
            rehomes_allowed: self.plan.max_line_attempts.saturating_sub(1),
        };
        match (policy::react(kind, &situation), t) {
            (Reaction::Reopen, Trouble::Device(fault)) if step == Step::Opening => {
                self.wait_for_device(fault, now, out)
            }
            (Reaction::Reopen, Trouble::Device(fault)) => self.reopen(fault, out),
            (Reaction::Retry, t) => {
                let device = t.device().unwrap_or(Device::Instrument);
                let why = match &t {
                    Trouble::Device(f) if f.is_busy() => reasons::Retried::Busy,
                    Trouble::Line(_) => reasons::Retried::UnusableLine,
                    _ => reasons::Retried::Wrong,
                };
                self.retry(device, why, now, out)
            }
            (Reaction::Rehome, Trouble::Device(fault)) => self.rehome(fault, now, out),
            (Reaction::WaitForStorage, Trouble::Storage(s)) => {
                self.wait_for_storage(s, step == Step::Outputs, now, out)
            }
            (Reaction::Refuse, t) => {
                let reason = self.start_refused(t);
                self.fail(reason, out)
            }
            (Reaction::Fail(rule), t) => {
                let reason = self.failure(rule, step, t);
                self.fail(reason, out)
            }
            // A reaction the table gives no such fault: ended, named, rather than guessed.
            (reaction, t) => {
                let reason = self.failure(FailRule::Fatal, step, t);
                tracing::error!("internal: the fault policy gave {reaction:?}; the scan ends");
                self.fail(reason, out)
            }
        }
    }

    /// Why a start is refused.
    fn start_refused(&self, t: Trouble) -> FailReason {
        match t {
            Trouble::Device(fault) => FailReason::NotStarted(fault),
            Trouble::Storage(s) => FailReason::Storage(s.message),
            t => self.failure(FailRule::Fatal, Step::Creating, t),
        }
    }

    /// Why a scan fails under `rule`.
    fn failure(&self, rule: FailRule, step: Step, t: Trouble) -> FailReason {
        let line = self.line;
        match (rule, t) {
            (FailRule::BudgetSpent, t) => {
                let (since, last) = match &self.budget {
                    Some(b) => (b.since.wall, b.last.clone()),
                    None => (chrono::DateTime::<Utc>::UNIX_EPOCH, t.on_line(line)),
                };
                FailReason::BudgetExhausted {
                    line,
                    budget_s: self.policy.transient_budget.as_secs(),
                    since,
                    traces: self.traces,
                    last,
                }
            }
            (FailRule::RehomesSpent, Trouble::Device(last)) => FailReason::PositionLostRepeatedly {
                line,
                times: self.rehomes + 1,
                last,
            },
            (_, Trouble::Line(problem)) => FailReason::LineRefused { line, problem },
            (_, Trouble::Fitter(message)) => FailReason::FitterRefused { line, message },
            (_, Trouble::Storage(s)) if step == Step::Outputs => FailReason::Outputs(s.message),
            (_, Trouble::Storage(s)) => FailReason::Storage(s.message),
            (_, Trouble::Device(fault)) => FailReason::Fatal {
                line: self.current(),
                fault,
            },
        }
    }

    /// A device that cannot be opened again: suspended (once), then tried again with
    /// backoff, without a time limit.
    fn wait_for_device(&mut self, fault: Fault, now: Now, out: &mut Vec<Action>) {
        let device = fault.device;
        let wait = match &mut self.suspension {
            Some(s) if s.cause == Cause::Absent(device) => {
                s.wait = self.policy.backoff.next(s.wait);
                s.wait
            }
            _ => {
                let reason = reasons::unavailable(device, &fault);
                out.push(self.note(reason.clone(), Some(device)));
                out.push(Action::Notify(ScanEventKind::Suspended, reason.clone()));
                self.metrics.suspensions += 1;
                let wait = self.policy.backoff.next(Duration::ZERO);
                self.suspension = Some(Suspension {
                    cause: Cause::Absent(device),
                    since: now,
                    wait,
                });
                self.status.state = State::Suspended;
                self.status.reason = Some(reason);
                match device {
                    Device::Instrument => self.status.instrument = DeviceState::Reconnecting,
                    Device::Stage => self.status.stage = DeviceState::Reconnecting,
                }
                self.publish(out);
                out.push(Action::Metrics(self.metrics.clone()));
                wait
            }
        };
        self.wait(out, wait, AfterWait::Open(device));
    }

    /// A device that vanished in a line: closed, the line abandoned, reopened at once.
    fn reopen(&mut self, fault: Fault, out: &mut Vec<Action>) {
        out.push(Action::Close(fault.device));
        match fault.device {
            Device::Instrument => self.instrument_open = false,
            Device::Stage => self.stage_open = false,
        }
        out.push(self.note(
            reasons::line_abandoned(self.line, &fault),
            Some(fault.device),
        ));
        self.effect(out, Doing::Open(fault.device));
    }

    /// The stage lost its position: re-homed before the line is tried again.
    fn rehome(&mut self, fault: Fault, now: Now, out: &mut Vec<Action>) {
        self.rehomes += 1;
        self.need_home = true;
        self.metrics.retries += 1;
        out.push(self.note(
            reasons::rehoming(
                self.line,
                &fault,
                self.rehomes,
                self.plan.max_line_attempts.saturating_sub(1),
            ),
            Some(fault.device),
        ));
        self.next_step(now, out);
    }

    /// Charges the transient budget of the current line with a fault (`why`); true when
    /// it is spent.
    fn charge_budget(&mut self, why: String, now: Now) -> bool {
        let budget = self.budget.get_or_insert(Budget {
            since: now,
            last: String::new(),
            absent: Duration::ZERO,
            announced: false,
        });
        budget.last = why;
        self.budget_spent(now) >= self.policy.transient_budget
    }

    /// Time spent from the transient budget by `now` (zero before its first fault).
    fn budget_spent(&self, now: Now) -> Duration {
        self.budget.as_ref().map_or(Duration::ZERO, |b| {
            now.mono
                .saturating_duration_since(b.since.mono)
                .saturating_sub(b.absent)
        })
    }

    /// A fault that may clear by itself: the line retried with backoff while the budget
    /// lasts (the budget already charged with it).
    fn retry(&mut self, device: Device, why: reasons::Retried, now: Now, out: &mut Vec<Action>) {
        let (since, last, first) = match &mut self.budget {
            Some(b) => (
                b.since,
                b.last.clone(),
                !std::mem::replace(&mut b.announced, true),
            ),
            None => (now, String::new(), true),
        };
        self.retry_wait = self.policy.backoff.next(self.retry_wait);
        let left = self
            .policy
            .transient_budget
            .saturating_sub(self.budget_spent(now));
        let wait = self.retry_wait.min(left);
        let reason = reasons::retried(device, why, since.wall, left, &last);
        out.push(self.note(reasons::retrying(&reason, wait), Some(device)));
        self.metrics.retries += 1;
        if first {
            self.metrics.suspensions += 1;
            out.push(Action::Notify(ScanEventKind::Suspended, reason.clone()));
        }
        self.suspension = Some(Suspension {
            cause: Cause::Busy(device),
            since,
            wait,
        });
        self.status.state = State::Suspended;
        self.status.reason = Some(reason);
        self.publish(out);
        out.push(Action::Metrics(self.metrics.clone()));
        self.wait(out, wait, AfterWait::Retry);
    }

    /// Storage that refused a write: what is in memory is kept, and the write is made again
    /// with backoff (after checking the free space and inodes, when the disk was full). One
    /// suspension is recorded however often the write fails again, and its backoff keeps
    /// growing until a write succeeds.
    fn wait_for_storage(
        &mut self,
        s: StorageFailure,
        outputs: bool,
        now: Now,
        out: &mut Vec<Action>,
    ) {
        let class = s.class.unwrap_or(StorageClass::Refused);
        let columns = self.columns.map_or(self.points_per_line, |c| c as u64);
        let needed_bytes = remaining_scan_bytes(self.plan.lines, self.line, columns);
        let needed_inodes = remaining_scan_inodes(self.plan.lines, self.line);
        let what = reasons::held_up(outputs, self.line);
        let reason = match class {
            StorageClass::Full => reasons::disk_full(&what, &s.message, needed_bytes),
            StorageClass::Refused => reasons::storage_refused(&what, s.errno, &s.message),
        };
        let wait = match &mut self.suspension {
            Some(sus) if matches!(sus.cause, Cause::Storage { .. }) => {
                // The same suspension goes on: a longer wait, no new record.
                sus.wait = self.policy.backoff.next(sus.wait);
                if let Cause::Storage { class: c, .. } = &mut sus.cause {
                    *c = class;
                }
                sus.wait
            }
            _ => {
                let wait = self.policy.backoff.next(Duration::ZERO);
                out.push(self.note(format!("suspended: {reason}"), None));
                self.metrics.suspensions += 1;
                out.push(Action::Notify(ScanEventKind::Suspended, reason.clone()));
                self.suspension = Some(Suspension {
                    cause: Cause::Storage {
                        class,
                        needed_bytes,
                        needed_inodes,
                        outputs,
                        free_bytes: None,
                    },
                    since: now,
                    wait,
                });
                out.push(Action::Metrics(self.metrics.clone()));
                wait
            }
        };
        self.status.state = State::Suspended;
        self.status.reason = Some(reason);
        self.publish(out);
        let after = match class {
            StorageClass::Full => AfterWait::CheckSpace,
            StorageClass::Refused => AfterWait::Rewrite,
        };
        self.wait(out, wait, after);
    }

    fn space_checked(
        &mut self,
        free: u64,
        free_inodes: u64,
        outputs_bytes: u64,
        out: &mut Vec<Action>,
    ) {
        let Some(Suspension {
            cause:
                Cause::Storage {
                    needed_bytes,
                    needed_inodes,
                    outputs,
                    ..
                },
            since,
            wait,
        }) = self.suspension.clone()
        else {
            return;
        };
        if let Some(Suspension {
            cause: Cause::Storage { free_bytes, .. },
            ..
        }) = &mut self.suspension
        {
            *free_bytes = Some(free);
        }
        // The outputs' estimate covers the whole surface and report: what an earlier try
        // already wrote of them is space they keep when written again.
        let available = if outputs {
            free.saturating_add(outputs_bytes)
        } else {
            free
        };
        if available < needed_bytes || free_inodes < needed_inodes {
            let next = self.policy.backoff.next(wait);
            if let Some(s) = &mut self.suspension {
                s.wait = next;
            }
            self.status.reason = Some(reasons::still_full(
                since.wall,
                free,
                free_inodes,
                needed_bytes,
                needed_inodes,
            ));
            self.publish(out);
            return self.wait(out, next, AfterWait::CheckSpace);
        }
        // Room again: the write is made again; the suspension ends only when it succeeds.
        self.rewrite(out);
    }

    /// Makes the refused write again: the held line's commit, or the outputs.
    fn rewrite(&mut self, out: &mut Vec<Action>) {
        let outputs = matches!(
            self.suspension.as_ref().map(|s| &s.cause),
            Some(Cause::Storage { outputs: true, .. })
        );
        if outputs {
            self.effect(out, Doing::Outputs);
        } else {
            self.commit(out);
        }
    }

    /// A write succeeded: a storage suspension ends, recorded once.
    fn storage_back(&mut self, now: Now, out: &mut Vec<Action>) {
        let Some(Suspension {
            cause: Cause::Storage {
                class, free_bytes, ..
            },
            since,
            ..
        }) = self.suspension.clone()
        else {
            return;
        };
        let waited = now.mono.saturating_duration_since(since.mono);
        let note = match (class, free_bytes) {
            (StorageClass::Full, Some(free)) => reasons::space_back(free, waited),
            _ => reasons::storage_back(waited),
        };
        out.push(self.note(note.clone(), None));
        out.push(Action::Notify(ScanEventKind::Resumed, note));
        self.suspension = None;
        self.status.state = State::Scanning;
        self.status.reason = None;
        self.publish(out);
    }

    fn line_done(&mut self, now: Now, out: &mut Vec<Action>) {
        let k = self.line;
        if let Some(s) = self.suspension.take() {
            let back =
                reasons::on_disk_after_faults(k, now.mono.saturating_duration_since(s.since.mono));
            out.push(self.note(back.clone(), None));
            out.push(Action::Notify(ScanEventKind::Resumed, back));
            self.status.reason = None;
        }
        let secs = self
            .line_began
            .take()
            .map_or(0.0, |t| (now.mono - t).as_secs_f64());
        self.line_seconds.push(secs);
        self.line += 1;
        self.skip_ahead();
        self.traces = 0;
        self.rehomes = 0;
        self.budget = None;
        self.retry_wait = Duration::ZERO;
        let done = self.done();
        let m = &mut self.metrics;
        m.lines_done = done;
        m.last_line_seconds = Some(secs);
        m.line_seconds_sum += secs;
        m.line_seconds_count += 1;
        m.last_line_unix_seconds = Some(now.wall.timestamp_millis() as f64 / 1000.0);
        out.push(Action::Metrics(self.metrics.clone()));
        if self.status.state == State::Suspended {
            self.status.state = State::Scanning;
        }
        self.status.last_ra_um = self.held_ra.take().or(self.status.last_ra_um);
        self.publish_progress(out, None);
        if self.pause_requested && self.line < self.plan.lines {
            self.pause_requested = false;
            let reason = reasons::paused_after(k);
            out.push(Action::Record(Note {
                reason: reason.clone(),
                device: None,
                line: Some(k),
                peer: None,
                pause: Some(PauseMark::Paused),
            }));
            self.status.state = State::Paused;
            self.status.reason = Some(reason);
            self.status.current_line = None;
            self.publish(out);
            self.doing = Doing::Paused;
            return;
        }
        self.next_step(now, out);
    }

    /// A traced line must fit the scan: finite heights, the scan's point count and pitch,
    /// unchanged conditions.
    fn check(&self, t: &TracedSummary) -> Option<LineProblem> {
        if let Some((point, value)) = t.first_non_finite {
            return Some(LineProblem::NotFinite {
                point,
                points: t.points,
                value,
            });
        }
        if let Some(cols) = self.columns {
            if t.points != cols {
                return Some(LineProblem::PointCount {
                    points: t.points,
                    scan: cols,
                });
            }
        }
        if let Some(px) = self.pitch_x_mm {
            if px != t.pitch_x_mm {
                return Some(LineProblem::Pitch {
                    pitch_x_mm: t.pitch_x_mm,
                    scan: px,
                });
            }
        }
        let scan = self.conditions.as_ref()?;
        conditions_difference(scan, &t.conditions).map(LineProblem::ConditionsChanged)
    }

    // ---- operator commands and the end ---------------------------------------------

    fn command(&mut self, command: OperatorCommand, peer: Peer, now: Now, out: &mut Vec<Action>) {
        let scan = match &self.status.scan_id {
            Some(id) => format!("scan {id}"),
            None => "the scan being started (no id yet)".to_owned(),
        };
        let paused = self.doing == Doing::Paused;
        let by = peer.describe();
        let note = |reason: String, line: Option<u32>| {
            Action::Record(Note {
                reason,
                device: None,
                line,
                peer: Some(peer.clone()),
                pause: None,
            })
        };
        if self.ending.is_some() {
            out.push(Action::Reply(Err(format!("{scan} is ending"))));
            return;
        }
        match command {
            OperatorCommand::Pause if paused => {
                out.push(Action::Reply(Ok(format!("{scan} is already paused"))))
            }
            OperatorCommand::Pause => {
                self.pause_requested = true;
                if self.status.state == State::Scanning {
                    self.status.state = State::Pausing;
                }
                out.push(Action::Reply(Ok(format!(
                    "{scan} pauses once the current line is on disk"
                ))));
                if self.created {
                    out.push(note(format!("pause requested by {by}"), self.current()));
                }
                self.publish(out);
            }
            OperatorCommand::Resume if paused => self.resume_paused(
                format!("{scan} resumes"),
                format!("resumed by the operator ({by})"),
                peer,
                now,
                out,
            ),
            OperatorCommand::Resume if self.pause_requested => {
                self.pause_requested = false;
                if self.status.state == State::Pausing {
                    self.status.state = State::Scanning;
                }
                out.push(Action::Reply(Ok("pause request withdrawn".to_owned())));
                if self.created {
                    out.push(note(
                        format!("pause request withdrawn by {by}"),
                        self.current(),
                    ));
                }
                self.publish(out);
            }
            OperatorCommand::Resume => out.push(Action::Reply(Ok(format!(
                "{scan} is not paused; it goes on scanning"
            )))),
            OperatorCommand::Abort => {
                out.push(Action::Reply(Ok(format!(
                    "aborting {scan}; lines on disk are kept"
                ))));
                if self.created {
                    out.push(note(format!("abort requested by {by}"), self.current()));
                }
                self.interrupt(End::Abort { peer: Some(peer) }, out);
            }
            // A start while paused is the operator's resumption (as `surfscan scan` or a
            // start resumes a scan paused before a restart); a new scan needs this one
            // aborted first.
            OperatorCommand::Start { mode, .. } if paused && mode != StartMode::New => {
                // Counted as a start, as the daemon counts the scans it begins, so that
                // `surfscan start` sees its outcome in the status.
                self.status.starts += 1;
                self.resume_paused(
                    format!("{scan} was paused; this start resumes it"),
                    format!("resumed by the operator's start ({by})"),
                    peer,
                    now,
                    out,
                );
            }
            OperatorCommand::Start { .. } if paused => out.push(Action::Reply(Err(format!(
                "{scan} is paused; `surfscan resume` continues it, or `surfscan abort` ends it (its lines are kept) before a new scan can start"
            )))),
            OperatorCommand::Start { .. } => out.push(Action::Reply(Err(format!(
                "{scan} is running; abort it first or wait until it ends"
            )))),
        }
    }

    /// Leaves the pause: answers `reply`, records `reason` as the resumption, and goes on.
    fn resume_paused(
        &mut self,
        reply: String,
        reason: String,
        peer: Peer,
        now: Now,
        out: &mut Vec<Action>,
    ) {
        out.push(Action::Reply(Ok(reply)));
        out.push(Action::Record(Note {
            reason,
            device: None,
            line: Some(self.line),
            peer: Some(peer),
            pause: Some(PauseMark::Resumed),
        }));
        self.status.state = State::Scanning;
        self.status.reason = None;
        self.publish(out);
        self.next_step(now, out);
    }

    /// Abort or shutdown: cancel what is in flight, clean up the devices, then stop.
    fn interrupt(&mut self, end: End, out: &mut Vec<Action>) {
        if self.ending.is_some() {
            return;
        }
        if self.doing.is_effect() {
            out.push(Action::Cancel);
        }
        if self.instrument_open || self.stage_open {
            self.ending = Some(end);
            self.effect(out, Doing::Cleanup);
        } else {
            self.stop(end, out);
        }
    }

    fn fail(&mut self, reason: FailReason, out: &mut Vec<Action>) {
        self.stop(End::Fail(reason), out);
    }

    fn stop(&mut self, end: End, out: &mut Vec<Action>) {
        self.ended = true;
        self.doing = Doing::Nothing;
        let (ending, kind, reason) = (
            end.status(),
            end.event(self.created),
            end.reason(self.created),
        );
        // The state stays `Paused` through the clean-up: nothing is in progress then.
        if matches!(end, End::Shutdown) && self.created && self.status.state == State::Paused {
            // Paused, nothing was in progress: no line to abandon, and the pause stands.
            out.push(Action::Record(Note {
                reason: reasons::shutdown_while_paused(self.done(), self.plan.lines),
                device: None,
                line: None,
                peer: None,
                pause: None,
            }));
        } else if matches!(end, End::Shutdown) && self.created {
            out.push(self.note(reasons::shutdown_mid_line(), None));
        }
        out.push(Action::Stop(end.clone()));
        if let Some(kind) = kind {
            out.push(Action::Notify(kind, reason.clone()));
        }
        if matches!(end, End::Shutdown) && self.created {
            self.status.state = State::Stopping;
        } else {
            self.status = ended_status(&self.status, ending, &reason);
            if let Some(stop) = self.status.last_stop.as_mut() {
                stop.internal = end.is_internal();
            }
        }
        self.publish(out);
    }

    // ---- helpers -----------------------------------------------------------------

    /// The line being worked on, if any.
    fn current(&self) -> Option<u32> {
        (self.created && self.line < self.plan.lines).then_some(self.line)
    }

    fn note(&self, reason: String, device: Option<Device>) -> Action {
        Action::Record(Note {
            reason,
            device,
            line: self.current(),
            peer: None,
            pause: None,
        })
    }

    fn publish(&self, out: &mut Vec<Action>) {
        out.push(Action::Publish(self.status.clone()));
    }

    /// Steps the next line past the lines already committed after a gap.
    fn skip_ahead(&mut self) {
        while self.ahead.remove(&self.line) {
            self.line += 1;
        }
    }

    /// Lines committed: those before the next line and those committed ahead of it.
    fn done(&self) -> u32 {
        self.line.saturating_add(self.ahead.len() as u32)
    }

    fn publish_progress(&mut self, out: &mut Vec<Action>, current: Option<u32>) {
        self.status.lines_done = self.done();
        self.status.lines_total = self.plan.lines;
        self.status.current_line = current.map(|k| k + 1);
        self.status.y_mm = current.map(|k| self.plan.target(k).to_mm());
        self.status.eta_s = (!self.line_seconds.is_empty()).then(|| {
            let mean = self.line_seconds.iter().sum::<f64>() / self.line_seconds.len() as f64;
            mean * f64::from(self.plan.lines.saturating_sub(self.done()))
        });
        self.publish(out);
    }
}

impl Doing {
    fn is_effect(self) -> bool {
        !matches!(self, Doing::Paused | Doing::Nothing)
    }
}

#[cfg(test)]
mod tests;
