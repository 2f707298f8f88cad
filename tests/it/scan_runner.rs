//! The scan runner in-process against a scripted station (fake instrument and y axis, no
//! serial ports) under paused tokio time: operator pause/resume/abort through the command
//! channel, the attempt bound, the rule that the stage moves only after the instrument read
//! idle, and the reconnection backoff after a device vanished.

use std::collections::VecDeque;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use surfscan::config::Config;
use surfscan::devices::{
    Arrival, Battery, DeviceFault, FaultClass, Instrument, InstrumentIdentity, ProbeReport,
    ProfileReadout, StageReport, TracedLine, YAxis,
};
use surfscan::profile::{Conditions, Profile, ProfileKind};
use surfscan::publish::{event_payload, sweep};
use surfscan::scan::channels::Control;
use surfscan::scan::choice::{choose, Asker, Choice};
use surfscan::scan::command::{OperatorCommand, OperatorRequest, Peer, StartMode};
use surfscan::scan::ending::{End, FailCause, FailKind};
use surfscan::scan::event::{ScanEvent, ScanEventKind};
use surfscan::scan::journal::{read_journal, survey, Record, StopStatus};
use surfscan::scan::outcome::{Outcome, ScanRequest};
use surfscan::scan::runner::run_scan;
use surfscan::scan::settings::RunSettings;
use surfscan::scan::station::{Device, Fault, Station};
use surfscan::scan::status::{State, Status};
use surfscan::scan::testhooks::TestHooks;
use surfscan::stage::policy::ScanDirection;
use surfscan::units::Nm;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::time::Instant;

const LINES: u32 = 5;
const POINTS: usize = 24;

#[derive(Debug, thiserror::Error)]
#[error("scripted {class:?} fault")]
struct FakeError {
    class: FaultClass,
}

impl DeviceFault for FakeError {
    fn class(&self) -> FaultClass {
        self.class
    }
}

/// What the devices did, in order.
#[derive(Debug, Clone, PartialEq)]
enum Event {
    OpenInstrument(Instant, bool),
    EnsureIdle(bool),
    Move(Nm),
    TraceStart,
    TraceEnd(bool),
    Home,
    Abort,
    Stop,
}

/// The script and the log shared by the fake devices and the test.
#[derive(Default)]
struct World {
    log: Vec<Event>,
    /// Outcome of successive traces: `None` succeeds, `Some(class)` fails.
    traces: VecDeque<Option<FaultClass>>,
    /// Outcome of successive `ensure_idle` calls (missing = success).
    idle: VecDeque<Option<FaultClass>>,
    /// `open_instrument` calls that fail as absent before one succeeds, after the first.
    absent_opens: u32,
    opens: u32,
    /// y of the carriage, nm.
    y: Option<Nm>,
    /// Told when a trace starts, with the carriage's y.
    trace_started: Option<mpsc::UnboundedSender<Nm>>,
}

type Shared = Arc<Mutex<World>>;

fn with<T>(w: &Shared, f: impl FnOnce(&mut World) -> T) -> T {
    f(&mut w.lock().expect("world lock"))
}

fn conditions() -> Conditions {
    Conditions {
        standard: Some("ISO1997".into()),
        lambda_c_mm: Some(0.8),
        evaluation_length_mm: Some(0.023),
        ..Conditions::default()
    }
}

struct FakeInstrument(Shared);
struct FakeStage(Shared);
struct FakeStation(Shared);

impl Instrument for FakeInstrument {
    type Error = FakeError;

    async fn probe(&mut self) -> Result<ProbeReport, FakeError> {
        Ok(ProbeReport {
            identity: InstrumentIdentity {
                model: "sj210".into(),
                firmware: "V1.00".into(),
                drive_unit: "standard".into(),
            },
            battery: Battery::Good,
            conditions: conditions(),
            parameter_count: 3,
            profile_readout: ProfileReadout::Supported { points_now: 0 },
            warnings: Vec::new(),
        })
    }

    async fn ensure_idle(&mut self) -> Result<(), FakeError> {
        let r = with(&self.0, |w| w.idle.pop_front().flatten());
        with(&self.0, |w| w.log.push(Event::EnsureIdle(r.is_none())));
        match r {
            None => Ok(()),
            Some(class) => Err(FakeError { class }),
        }
    }

    async fn trace(&mut self) -> Result<TracedLine, FakeError> {
        let (y, tx) = with(&self.0, |w| {
            w.log.push(Event::TraceStart);
            (w.y.unwrap_or(Nm(0)), w.trace_started.clone())
        });
        if let Some(tx) = tx {
            let _ = tx.send(y);
        }
        tokio::time::sleep(Duration::from_secs(10)).await;
        let r = with(&self.0, |w| w.traces.pop_front().flatten());
        with(&self.0, |w| w.log.push(Event::TraceEnd(r.is_none())));
        if let Some(class) = r {
            return Err(FakeError { class });
        }
        let k = y.0 as f64 / 10_000.0;
        Ok(TracedLine {
            profile: Profile {
                pitch_x_mm: 0.001,
                heights_um: (0..POINTS)
                    .map(|i| ((i as f64) * 0.7 + k).sin() * 2.0)
                    .collect(),
                kind: ProfileKind::R,
                conditions: conditions(),
            },
            results: Vec::new(),
            pitch_source: "config".into(),
            warnings: Vec::new(),
            readout_warnings: Vec::new(),
        })
    }

    async fn abort(&mut self) -> Result<(), FakeError> {
        with(&self.0, |w| w.log.push(Event::Abort));
        Ok(())
    }
}

impl YAxis for FakeStage {
    type Error = FakeError;

    fn check_targets(&self, _targets: &[Nm]) -> Result<Vec<String>, FakeError> {
        Ok(Vec::new())
    }

    async fn connect(&mut self) -> Result<StageReport, FakeError> {
        Ok(StageReport {
            identity: "fake stage".into(),
            position_trusted: true,
            position: Nm(0),
        })
    }

    fn position_trusted(&self) -> bool {
        true
    }

    async fn home(&mut self) -> Result<(), FakeError> {
        with(&self.0, |w| w.log.push(Event::Home));
        Ok(())
    }

    async fn move_to(&mut self, target: Nm) -> Result<Arrival, FakeError> {
        with(&self.0, |w| {
            w.log.push(Event::Move(target));
            w.y = Some(target);
        });
        tokio::time::sleep(Duration::from_millis(500)).await;
        Ok(Arrival {
            target,
            readback: target,
            attempts: 1,
        })
    }

    async fn stop(&mut self) -> Result<(), FakeError> {
        with(&self.0, |w| w.log.push(Event::Stop));
        Ok(())
    }
}

impl Station for FakeStation {
    type Instrument = FakeInstrument;
    type Stage = FakeStage;

    async fn open_instrument(&mut self) -> Result<FakeInstrument, Fault> {
        let absent = with(&self.0, |w| {
            w.opens += 1;
            let absent = w.opens > 1 && w.absent_opens > 0;
            if absent {
                w.absent_opens -= 1;
            }
            w.log.push(Event::OpenInstrument(Instant::now(), !absent));
            absent
        });
        if absent {
            return Err(Fault {
                device: Device::Instrument,
                class: FaultClass::Absent,
                ng_code: None,
                message: "no such port".into(),
            });
        }
        Ok(FakeInstrument(self.0.clone()))
    }

    async fn open_stage(&mut self, _direction: ScanDirection) -> Result<FakeStage, Fault> {
        Ok(FakeStage(self.0.clone()))
    }

    fn instrument_present(&self) -> bool {
        true
    }

    fn stage_present(&self) -> bool {
        true
    }

    fn expected_pitch_um(&self, _conditions: &Conditions) -> Option<f64> {
        Some(1.0)
    }
}

fn settings(out: &Path) -> RunSettings {
    let config = runner_config(out);
    RunSettings {
        characterise: None,
        ..surfscan::cli::station::run_settings(&config, "0".repeat(64), TestHooks::none())
            .expect("settings")
    }
}

fn runner_config(out: &Path) -> Config {
    let text = format!(
        r#"[instrument]
port = "/nonexistent/sj210"
[stage]
port = "/nonexistent/ystage"
protocol = "grbl"
steps-per-mm = 400.0
soft-limit-min-mm = -100.0
soft-limit-max-mm = 0.0
[scan]
lines = {LINES}
y-start-mm = -20.0
y-step-mm = 0.01
max-line-attempts = 3
reconnect-initial-ms = 1000
reconnect-max-ms = 4000
[fit]
degree-u = 3
degree-v = 3
[output]
dir = {out:?}
"#,
        out = out.display().to_string()
    );
    Config::parse(Path::new("runner-test.toml"), &text).expect("config")
}

fn target(k: u32) -> Nm {
    Nm(-20_000_000 + 10_000 * i64::from(k))
}

struct Harness {
    world: Shared,
    tmp: tempfile::TempDir,
    commands: mpsc::Sender<OperatorRequest>,
    status: watch::Receiver<Status>,
    ctl: Control,
    started: mpsc::UnboundedReceiver<Nm>,
    _shutdown: watch::Sender<bool>,
}

fn harness() -> Harness {
    let (cmd_tx, cmd_rx) = mpsc::channel(8);
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let (status_tx, status_rx) = watch::channel(Status::idle());
    let (started_tx, started) = mpsc::unbounded_channel();
    let world = Arc::new(Mutex::new(World {
        trace_started: Some(started_tx),
        ..World::default()
    }));
    Harness {
        world,
        tmp: tempfile::tempdir().expect("tmp"),
        commands: cmd_tx,
        status: status_rx,
        ctl: Control::new(cmd_rx, shutdown_rx, status_tx),
        started,
        _shutdown: shutdown_tx,
    }
}

/// What a start by `asker` runs over the scans in `out` (the choice made and committed).
fn start(out: &Path, asker: Asker) -> Option<ScanRequest> {
    choose(out, asker, Peer::this_process(), Default::default())
        .and_then(Choice::commit)
        .expect("a decision")
}

fn new_scan() -> ScanRequest {
    ScanRequest::New {
        specimen: "fake".into(),
        operator: "test".into(),
        notes: String::new(),
        peer: None,
        job: None,
    }
}

/// The last of the events told so far (the scan's ending, once it ended).
fn last_told(told: &mut mpsc::UnboundedReceiver<ScanEvent>) -> ScanEvent {
    let mut last = None;
    while let Ok(ev) = told.try_recv() {
        last = Some(ev);
    }
    last.expect("an event was told")
}

/// The events topic's `internal` member of `ev`.
fn internal_member(ev: &ScanEvent) -> Option<serde_json::Value> {
    event_payload(ev, "rough-3").get("internal").cloned()
}

async fn request(tx: &mpsc::Sender<OperatorRequest>, command: OperatorCommand) -> String {
    let (reply, rx) = oneshot::channel();
    tx.send(OperatorRequest {
        command,
        peer: surfscan::scan::command::Peer::this_process(),
        reply,
    })
    .await
    .expect("runner listens");
    rx.await.expect("runner answers").expect("command accepted")
}

fn records(dir: &Path) -> Vec<Record> {
    read_journal(&dir.join("journal.jsonl"))
        .expect("journal")
        .records
}

fn line_indices(records: &[Record]) -> Vec<u32> {
    records
        .iter()
        .filter_map(|r| match r {
            Record::Line(l) => Some(l.id.index),
            _ => None,
        })
        .collect()
}

fn stop_status(records: &[Record]) -> Option<StopStatus> {
    records.iter().find_map(|r| match r {
        Record::Stop(s) => Some(s.status),
        _ => None,
    })
}

fn scan_dir_of(outcome: &Outcome) -> std::path::PathBuf {
    outcome.dir.clone().expect("scan dir")
}

/// Every move is preceded, since the previous move, by an `ensure_idle` that succeeded, and
/// no trace runs between that check and the move.
fn assert_moves_follow_idle(log: &[Event]) {
    let mut idle_ok = false;
    for (i, e) in log.iter().enumerate() {
        match e {
            Event::EnsureIdle(ok) => idle_ok = *ok,
            Event::TraceStart | Event::TraceEnd(_) | Event::OpenInstrument(..) => idle_ok = false,
            Event::Move(t) => {
                assert!(
                    idle_ok,
                    "move to {t:?} (event {i}) without a successful ensure_idle: {log:?}"
                );
                idle_ok = false;
            }
            _ => {}
        }
    }
}

#[tokio::test(start_paused = true)]
async fn pause_waits_for_the_line_on_disk_and_resume_continues() {
    let mut h = harness();
    let settings = settings(h.tmp.path());
    let mut station = FakeStation(h.world.clone());
    let world = h.world.clone();
    let commands = h.commands.clone();
    let mut status = h.status.clone();
    let driver = async {
        // Line 0 traces, then line 1: pause while line 1 is being traced.
        assert_eq!(h.started.recv().await, Some(target(0)));
        assert_eq!(h.started.recv().await, Some(target(1)));
        let reply = request(&commands, OperatorCommand::Pause).await;
        assert!(
            reply.contains("once the current line is on disk"),
            "{reply}"
        );
        assert_eq!(status.borrow().state, State::Pausing);
        status
            .wait_for(|s| s.state == State::Paused)
            .await
            .expect("paused");
        let dir = std::path::PathBuf::from(status.borrow().scan_dir.clone().expect("dir"));
        // Paused only once line 1 is on disk; nothing moved towards line 2.
        assert_eq!(line_indices(&records(&dir)), vec![0, 1]);
        assert!(dir.join("lines/0001.csv").exists());
        tokio::time::sleep(Duration::from_secs(600)).await;
        let moves: Vec<Event> = with(&world, |w| w.log.clone())
            .into_iter()
            .filter(|e| matches!(e, Event::Move(_)))
            .collect();
        assert_eq!(moves, vec![Event::Move(target(0)), Event::Move(target(1))]);
        // A resume whose requester stopped waiting (the control socket told the operator it
        // was not carried out) is dropped: the scan stays paused.
        let (reply, gone) = oneshot::channel();
        drop(gone);
        commands
            .send(OperatorRequest {
                command: OperatorCommand::Resume,
                peer: surfscan::scan::command::Peer::this_process(),
                reply,
            })
            .await
            .expect("runner listens");
        tokio::time::sleep(Duration::from_secs(60)).await;
        assert_eq!(status.borrow().state, State::Paused);
        assert_eq!(line_indices(&records(&dir)), vec![0, 1]);
        // Repeated commands are answered alike (exit 0 at the command line): the scan is
        // in the state asked for, and the reply names it by its id.
        let id = status.borrow().scan_id.clone().expect("id");
        let reply = request(&commands, OperatorCommand::Pause).await;
        assert_eq!(reply, format!("scan {id} is already paused"));
        let reply = request(&commands, OperatorCommand::Resume).await;
        assert!(reply.contains("resumes"), "{reply}");
        status
            .wait_for(|s| s.state == State::Scanning)
            .await
            .expect("scanning again");
        let reply = request(&commands, OperatorCommand::Resume).await;
        assert_eq!(
            reply,
            format!("scan {id} is not paused; it goes on scanning")
        );
    };
    let (outcome, ()) = tokio::join!(
        run_scan(&mut station, &mut h.ctl, &settings, new_scan()),
        driver
    );
    assert!(matches!(outcome.end, End::Success { .. }), "{outcome:?}");
    let recs = records(&scan_dir_of(&outcome));
    assert_eq!(line_indices(&recs), (0..LINES).collect::<Vec<_>>());
    assert_eq!(stop_status(&recs), Some(StopStatus::Success));
    let notes: Vec<String> = recs
        .iter()
        .filter_map(|r| match r {
            Record::Interruption(i) => Some(i.reason.clone()),
            _ => None,
        })
        .collect();
    assert!(
        notes
            .iter()
            .any(|n| n.contains("paused by the operator after line 2")),
        "{notes:?}"
    );
    assert!(
        notes.iter().any(|n| n.contains("resumed by the operator")),
        "{notes:?}"
    );
    assert_moves_follow_idle(&with(&h.world, |w| w.log.clone()));
}

/// A characterisation that takes a while (a large scan's report, plots and X3P) and notes
/// how often the watchdog was fed when it began and when it ended.
struct SlowCharacterisation {
    pets: Arc<Mutex<u32>>,
    seen: Arc<Mutex<Option<(u32, u32)>>>,
}

impl surfscan::scan::outputs::Characterise for SlowCharacterisation {
    fn characterise(
        &self,
        _scan: &surfscan::scan::outputs::CompletedScan<'_>,
    ) -> Result<surfscan::scan::outputs::Characterised, Box<dyn std::error::Error + Send + Sync>>
    {
        let before = *self.pets.lock().unwrap();
        std::thread::sleep(std::time::Duration::from_millis(300));
        let after = *self.pets.lock().unwrap();
        *self.seen.lock().unwrap() = Some((before, after));
        Err("a characterisation that only takes time".into())
    }
}

/// While a scan's outputs are written, the runner goes on feeding systemd's watchdog: the
/// daemon of a large scan was killed as hung while it wrote them (and then resumed into the
/// same outputs, again and again). Before, the loop stood still for the whole write.
#[test]
fn the_watchdog_is_fed_while_the_outputs_are_written() {
    let mut h = harness();
    // Every line on disk, the stop record not yet written (as after a power loss then): the
    // scan resumes straight into its outputs, with no device to wait for.
    let paused = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .unwrap();
    let plain = settings(h.tmp.path());
    let mut station = FakeStation(h.world.clone());
    let outcome = paused.block_on(run_scan(&mut station, &mut h.ctl, &plain, new_scan()));
    let dir = scan_dir_of(&outcome);
    let journal = dir.join("journal.jsonl");
    let text = std::fs::read_to_string(&journal).unwrap();
    let kept = &text[..text.trim_end().rfind('\n').unwrap() + 1];
    assert!(
        text[kept.len()..].contains("stop"),
        "the last record is the stop"
    );
    std::fs::write(&journal, kept).unwrap();

    let pets = Arc::new(Mutex::new(0u32));
    let seen = Arc::new(Mutex::new(None));
    let settings = RunSettings {
        characterise: Some(Arc::new(SlowCharacterisation {
            pets: pets.clone(),
            seen: seen.clone(),
        })),
        ..plain
    };
    let counter = pets.clone();
    h.ctl.watchdog = Some((
        Duration::from_millis(20),
        Arc::new(move || *counter.lock().unwrap() += 1),
    ));
    let real_time = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let request = ScanRequest::Resume { dir, peer: None };
    let outcome = real_time.block_on(run_scan(&mut station, &mut h.ctl, &settings, request));
    assert!(matches!(outcome.end, End::Success { .. }), "{outcome:?}");
    let (before, after) = seen.lock().unwrap().expect("the characterisation ran");
    assert!(
        after > before,
        "the watchdog was not fed while the outputs were written ({before} before, {after} after)"
    );
}

/// A characterisation with a bug that panics.
struct PanickingCharacterisation;

impl surfscan::scan::outputs::Characterise for PanickingCharacterisation {
    fn characterise(
        &self,
        _scan: &surfscan::scan::outputs::CompletedScan<'_>,
    ) -> Result<surfscan::scan::outputs::Characterised, Box<dyn std::error::Error + Send + Sync>>
    {
        panic!("a bug in the characterisation of {} lines", LINES)
    }
}

/// A panic while a completed scan's outputs are written fails that scan as an internal error
/// (a bug, exit 70 for `surfscan scan`, not the disk's 74), in the outcome and in the
/// journal's stop record (`internal`, with a cause the operator clears, so neither a restart
/// nor a plain start runs it into the same outputs), and the runner goes on: the next scan
/// runs and succeeds. Only `--resume` continues it, which writes the outputs again without
/// tracing a line. Built with `panic = "abort"`, as the release build was, the process died
/// here.
#[tokio::test(start_paused = true)]
async fn a_panic_while_the_outputs_are_written_fails_the_scan_and_the_runner_goes_on() {
    let mut h = harness();
    let plain = settings(h.tmp.path());
    let panicking = RunSettings {
        characterise: Some(Arc::new(PanickingCharacterisation)),
        ..plain.clone()
    };
    let (tx, mut told) = mpsc::unbounded_channel();
    h.ctl.events = Some(tx);
    let mut station = FakeStation(h.world.clone());
    let outcome = run_scan(&mut station, &mut h.ctl, &panicking, new_scan()).await;
    let dir = scan_dir_of(&outcome);
    let d = dir.display();
    let why = format!(
        "internal error: writing the outputs panicked (a bug in the characterisation of {LINES} lines); every line is on disk, but the outputs were not made because of a bug: report it with the scan's directory and the log; make them by hand with `surfscan fit {d}` and `surfscan analyze {d}`, or again with `surfscan scan --resume`"
    );
    match &outcome.end {
        End::Fail(reason) => {
            assert_eq!(reason.to_string(), why);
            assert_eq!(reason.kind(), FailKind::Internal);
        }
        other => panic!("{other:?}"),
    }
    let exit = surfscan::cli::scan::outcome_result(&outcome).unwrap_err();
    assert_eq!(exit.exit as i32, 70, "{}", exit.message);
    assert_eq!(
        exit.message,
        format!("scan failed: {why} (lines kept in {d})")
    );
    let last = h.ctl.status.borrow().last_stop.clone().expect("last stop");
    assert_eq!((last.status, last.internal), (StopStatus::Fail, true));
    assert_eq!(last.reason, why);
    // Its `fail` event says the bug in a member of its own (the hook's SURFSCAN_INTERNAL, the
    // events topic's `internal: true`), not only in words.
    let fail = last_told(&mut told);
    assert_eq!(
        (fail.kind, fail.internal, fail.reason.as_str()),
        (ScanEventKind::Fail, true, why.as_str())
    );
    assert_eq!(internal_member(&fail), Some(serde_json::Value::Bool(true)));
    let recs = records(&dir);
    let stop = recs.iter().find_map(|r| match r {
        Record::Stop(s) => Some((s.status, s.reason.clone(), s.cause, s.internal)),
        _ => None,
    });
    assert_eq!(
        stop,
        Some((StopStatus::Fail, why, Some(FailCause::Operator), true))
    );
    let lines = line_indices(&recs);
    assert_eq!(lines, (0..LINES).collect::<Vec<_>>());

    // Neither the daemon at its start nor an operator's plain start continues it.
    let out = runner_config(h.tmp.path()).output.dir;
    assert_eq!(start(&out, Asker::DaemonStartUp), None);
    let auto = start(&out, Asker::Operator(StartMode::Auto)).expect("a scan to run");
    assert!(matches!(auto, ScanRequest::New { .. }), "{auto:?}");
    let next = run_scan(&mut station, &mut h.ctl, &plain, new_scan()).await;
    assert!(matches!(next.end, End::Success { .. }), "{next:?}");
    assert_ne!(next.dir, outcome.dir);

    // `--resume` writes its outputs again, tracing nothing: its lines are the same.
    let resume = start(&out, Asker::Operator(StartMode::Resume)).expect("a scan to run");
    assert_eq!(
        resume,
        ScanRequest::Continue {
            dir: dir.clone(),
            peer: Some(Peer::this_process())
        }
    );
    let traces = || {
        with(&h.world, |w| {
            w.log.iter().filter(|e| **e == Event::TraceStart).count()
        })
    };
    let before = traces();
    let again = run_scan(&mut station, &mut h.ctl, &plain, resume).await;
    assert!(matches!(again.end, End::Success { .. }), "{again:?}");
    assert_eq!(again.dir.as_deref(), Some(dir.as_path()));
    assert_eq!(traces(), before, "no line traced again");
    let recs = records(&dir);
    assert_eq!(line_indices(&recs), lines);
    assert!(matches!(recs.last(), Some(Record::Stop(s)) if s.status == StopStatus::Success));
    assert!(dir.join("report.json").is_file());
    // Its success is no bug's, and its events-topic JSON is what it was before the member.
    let success = last_told(&mut told);
    assert_eq!(
        (success.kind, success.internal, success.dir.as_path()),
        (ScanEventKind::Success, false, dir.as_path())
    );
    assert_eq!(internal_member(&success), None);
    // The same ending read back from the journal at a start (the sweep of a success whose
    // event never reached a publisher) is the same event, but for the results, which a
    // publisher reads from the directory.
    let known = sweep::Known {
        since: chrono::DateTime::<chrono::Utc>::MIN_UTC,
        scans: Default::default(),
    };
    let replayed = sweep::missed(&survey(&out).expect("survey").succeeded, &known);
    let replayed = replayed
        .iter()
        .find(|e| e.scan_id == success.scan_id)
        .expect("the sweep replays the success");
    assert_eq!(
        *replayed,
        ScanEvent {
            results: None,
            ..success
        }
    );
}

#[tokio::test(start_paused = true)]
async fn abort_mid_trace_stops_the_devices_and_records_abort() {
    let mut h = harness();
    let settings = settings(h.tmp.path());
    let mut station = FakeStation(h.world.clone());
    let commands = h.commands.clone();
    let driver = async {
        for k in 0..3 {
            assert_eq!(h.started.recv().await, Some(target(k)));
        }
        let reply = request(&commands, OperatorCommand::Abort).await;
        assert!(reply.contains("aborting"), "{reply}");
    };
    let (outcome, ()) = tokio::join!(
        run_scan(&mut station, &mut h.ctl, &settings, new_scan()),
        driver
    );
    assert!(matches!(outcome.end, End::Abort { .. }), "{outcome:?}");
    let dir = scan_dir_of(&outcome);
    let recs = records(&dir);
    assert_eq!(line_indices(&recs), vec![0, 1]);
    assert_eq!(stop_status(&recs), Some(StopStatus::Abort));
    assert!(
        !dir.join("lines/0002.csv").exists(),
        "the aborted line is not kept"
    );
    let log = with(&h.world, |w| w.log.clone());
    // The trace of line 2 was cancelled (never ended), then abort and stop were sent.
    let tail: Vec<&Event> = log.iter().rev().take(3).collect();
    assert_eq!(
        tail,
        vec![&Event::Stop, &Event::Abort, &Event::TraceStart],
        "{log:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn transient_faults_are_retried_within_the_time_budget() {
    // Line 1 fails twice, then succeeds on its third trace.
    let mut h = harness();
    with(&h.world, |w| {
        w.traces = [
            None,
            Some(FaultClass::Transient),
            Some(FaultClass::Transient),
        ]
        .into();
    });
    let settings = settings(h.tmp.path());
    let mut station = FakeStation(h.world.clone());
    let outcome = run_scan(&mut station, &mut h.ctl, &settings, new_scan()).await;
    assert!(matches!(outcome.end, End::Success { .. }), "{outcome:?}");
    let recs = records(&scan_dir_of(&outcome));
    let attempts: Vec<u32> = recs
        .iter()
        .filter_map(|r| match r {
            Record::Line(l) => Some(l.id.attempt),
            _ => None,
        })
        .collect();
    assert_eq!(attempts, vec![1, 3, 1, 1, 1]);

    // Faults on every trace of line 1 for longer than the budget (30 s): each trace takes
    // 10 s, the waits are 1, 2 and 4 s, so the faults come 0, 11, 23 and 37 s after the
    // first; the fourth finds the budget spent and the scan fails naming it, with no
    // further trace.
    let mut h = harness();
    with(&h.world, |w| {
        w.traces = std::iter::once(None)
            .chain(std::iter::repeat_n(Some(FaultClass::Transient), 100))
            .collect();
    });
    let settings = RunSettings {
        transient_budget: Duration::from_secs(30),
        ..settings_for(&h)
    };
    let mut station = FakeStation(h.world.clone());
    let outcome = run_scan(&mut station, &mut h.ctl, &settings, new_scan()).await;
    match &outcome.end {
        End::Fail(reason) => {
            let reason = reason.to_string();
            assert!(
                reason.contains("line 2: transient faults since")
                    && reason.contains("outlasted the 30 s budget"),
                "{reason}"
            )
        }
        other => panic!("{other:?}"),
    }
    let traces = with(&h.world, |w| {
        w.log.iter().filter(|e| **e == Event::TraceStart).count()
    });
    assert_eq!(traces, 5, "one trace of line 0, four of line 1");
    let recs = records(&scan_dir_of(&outcome));
    assert_eq!(line_indices(&recs), vec![0]);
    assert_eq!(stop_status(&recs), Some(StopStatus::Fail));
}

fn settings_for(h: &Harness) -> RunSettings {
    settings(h.tmp.path())
}

#[tokio::test(start_paused = true)]
async fn the_stage_moves_only_after_the_instrument_read_idle() {
    let mut h = harness();
    with(&h.world, |w| {
        // Line 0 fine; line 1's first idle check fails (busy), its retry passes.
        w.idle = [None, Some(FaultClass::Transient), None].into();
    });
    let settings = settings(h.tmp.path());
    let mut station = FakeStation(h.world.clone());
    let outcome = run_scan(&mut station, &mut h.ctl, &settings, new_scan()).await;
    assert!(matches!(outcome.end, End::Success { .. }), "{outcome:?}");
    let log = with(&h.world, |w| w.log.clone());
    assert_moves_follow_idle(&log);
    let moves = log.iter().filter(|e| matches!(e, Event::Move(_))).count();
    assert_eq!(
        moves, LINES as usize,
        "one move per line, none after the failed check"
    );
    // The failed check is directly followed by another check, not by a move.
    let failed = log
        .iter()
        .position(|e| *e == Event::EnsureIdle(false))
        .expect("the scripted failure happened");
    assert_eq!(
        log.get(failed + 1),
        Some(&Event::EnsureIdle(true)),
        "{log:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_vanished_instrument_is_reopened_with_exponential_backoff() {
    let mut h = harness();
    with(&h.world, |w| {
        // Line 1's trace finds the instrument gone; four reopen attempts fail.
        w.traces = [None, Some(FaultClass::Absent)].into();
        w.absent_opens = 4;
    });
    let settings = settings(h.tmp.path());
    let mut station = FakeStation(h.world.clone());
    let outcome = run_scan(&mut station, &mut h.ctl, &settings, new_scan()).await;
    assert!(matches!(outcome.end, End::Success { .. }), "{outcome:?}");
    let opens: Vec<(Instant, bool)> = with(&h.world, |w| {
        w.log
            .iter()
            .filter_map(|e| match e {
                Event::OpenInstrument(t, ok) => Some((*t, *ok)),
                _ => None,
            })
            .collect()
    });
    // The first open at start, then the reconnection: immediately, then after 1, 2, 4, 4 s.
    assert_eq!(
        opens.iter().map(|o| o.1).collect::<Vec<_>>(),
        vec![true, false, false, false, false, true]
    );
    let gaps_ms: Vec<u128> = opens
        .windows(2)
        .skip(1)
        .map(|w| w[1].0.duration_since(w[0].0).as_millis())
        .collect();
    assert_eq!(gaps_ms, vec![1000, 2000, 4000, 4000]);
    let recs = records(&scan_dir_of(&outcome));
    assert_eq!(line_indices(&recs), (0..LINES).collect::<Vec<_>>());
    let attempts: Vec<u32> = recs
        .iter()
        .filter_map(|r| match r {
            Record::Line(l) => Some(l.id.attempt),
            _ => None,
        })
        .collect();
    assert_eq!(
        attempts,
        vec![1; LINES as usize],
        "a suspension uses up no attempt"
    );
    let notes: Vec<String> = recs
        .iter()
        .filter_map(|r| match r {
            Record::Interruption(i) => Some(i.reason.clone()),
            _ => None,
        })
        .collect();
    let gone = notes
        .iter()
        .position(|n| n.contains("instrument unavailable"));
    let back = notes.iter().position(|n| n.contains("instrument back"));
    assert!(
        matches!((gone, back), (Some(g), Some(b)) if g < b),
        "{notes:?}"
    );
}

/// A failed scan is continued at its first missing line once the cause is cleared: the lines
/// before stay as they were, the journal records the continuation, and it ends in success
/// with every line once.
#[tokio::test(start_paused = true)]
async fn a_failed_scan_continues_at_its_first_missing_line() {
    let mut h = harness();
    with(&h.world, |w| {
        w.traces = [None, None, Some(FaultClass::Fatal)].into();
    });
    let settings = settings_for(&h);
    let (tx, mut told) = mpsc::unbounded_channel();
    h.ctl.events = Some(tx);
    let mut station = FakeStation(h.world.clone());
    let outcome = run_scan(&mut station, &mut h.ctl, &settings, new_scan()).await;
    assert!(matches!(outcome.end, End::Fail(_)), "{outcome:?}");
    let dir = scan_dir_of(&outcome);
    assert_eq!(stop_status(&records(&dir)), Some(StopStatus::Fail));
    // A device's fault is no bug: the `fail` event says so, and its JSON has no `internal`.
    let fail = last_told(&mut told);
    assert_eq!((fail.kind, fail.internal), (ScanEventKind::Fail, false));
    assert_eq!(internal_member(&fail), None);
    let csv0 = std::fs::read(dir.join("lines/0000.csv")).expect("line 1");

    // Without asking for it, a failed scan is not resumed: a new one would start.
    let config = runner_config(h.tmp.path());
    let auto = start(&config.output.dir, Asker::Operator(StartMode::Auto)).expect("a scan to run");
    assert!(matches!(auto, ScanRequest::New { .. }), "{auto:?}");
    let request =
        start(&config.output.dir, Asker::Operator(StartMode::Resume)).expect("a scan to run");
    assert_eq!(
        request,
        ScanRequest::Continue {
            dir: dir.clone(),
            peer: Some(Peer::this_process())
        }
    );
    let traces_before = with(&h.world, |w| {
        w.log.iter().filter(|e| **e == Event::TraceStart).count()
    });
    let outcome = run_scan(&mut station, &mut h.ctl, &settings, request).await;
    assert!(matches!(outcome.end, End::Success { .. }), "{outcome:?}");
    let recs = records(&dir);
    assert_eq!(line_indices(&recs), (0..LINES).collect::<Vec<_>>());
    assert!(recs
        .iter()
        .any(|r| matches!(r, Record::Continue(c) if c.peer.is_some())));
    assert!(matches!(recs.last(), Some(Record::Stop(s)) if s.status == StopStatus::Success));
    let traces = with(&h.world, |w| {
        w.log.iter().filter(|e| **e == Event::TraceStart).count()
    }) - traces_before;
    assert_eq!(
        traces as u32,
        LINES - 2,
        "only the missing lines are traced"
    );
    assert_eq!(
        std::fs::read(dir.join("lines/0000.csv")).expect("line 1"),
        csv0
    );
}

/// `--new` over an unfinished scan records it as abandoned, so it is never resumed.
#[tokio::test(start_paused = true)]
async fn starting_over_records_the_unfinished_scan_as_abandoned() {
    let mut h = harness();
    let settings = settings_for(&h);
    let mut station = FakeStation(h.world.clone());
    let (ctl, started, shutdown) = (&mut h.ctl, &mut h.started, &h._shutdown);
    let outcome = tokio::join!(run_scan(&mut station, ctl, &settings, new_scan()), async {
        assert_eq!(started.recv().await, Some(target(0)));
        shutdown.send(true).expect("shutdown");
    })
    .0;
    let dir = scan_dir_of(&outcome);
    assert!(matches!(outcome.end, End::Shutdown), "{outcome:?}");
    let config = runner_config(h.tmp.path());
    let request =
        start(&config.output.dir, Asker::Operator(StartMode::New)).expect("a scan to run");
    assert!(matches!(request, ScanRequest::New { .. }), "{request:?}");
    let recs = records(&dir);
    match recs.last() {
        Some(Record::Stop(s)) => {
            assert_eq!(s.status, StopStatus::Abandoned);
            assert!(s.reason.contains("--new"), "{}", s.reason);
        }
        other => panic!("{other:?}"),
    }
    assert!(surfscan::scan::journal::find_unfinished(&config.output.dir)
        .expect("scan list")
        .is_empty());
}

/// A scan whose lines are all committed but whose surface was never written (killed after
/// the last commit) writes its outputs on resume without opening either device.
#[tokio::test(start_paused = true)]
async fn a_scan_with_every_line_committed_writes_its_outputs_without_devices() {
    let mut h = harness();
    let settings = settings_for(&h);
    let mut station = FakeStation(h.world.clone());
    let outcome = run_scan(&mut station, &mut h.ctl, &settings, new_scan()).await;
    let dir = scan_dir_of(&outcome);
    // As if killed after the last commit: no stop record, no outputs.
    let journal = dir.join("journal.jsonl");
    let text = std::fs::read_to_string(&journal).expect("journal");
    let kept: Vec<&str> = text
        .lines()
        .filter(|l| !l.contains(r#""class":"stop""#))
        .collect();
    assert_eq!(
        kept.len() + 1,
        text.lines().count(),
        "one stop record dropped"
    );
    std::fs::write(&journal, kept.join("\n") + "\n").expect("journal");
    std::fs::remove_file(dir.join("surface.igs")).expect("surface");
    with(&h.world, |w| w.log.clear());
    let request = ScanRequest::Resume {
        dir: dir.clone(),
        peer: None,
    };
    let outcome = run_scan(&mut station, &mut h.ctl, &settings, request).await;
    assert!(matches!(outcome.end, End::Success { .. }), "{outcome:?}");
    assert!(dir.join("surface.igs").exists());
    assert_eq!(
        with(&h.world, |w| w.log.clone()),
        Vec::<Event>::new(),
        "no device was opened, moved or traced"
    );
    assert_eq!(line_indices(&records(&dir)), (0..LINES).collect::<Vec<_>>());
}
