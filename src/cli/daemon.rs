//! `surfscan daemon`: the station service (systemd `Type=notify`).
//!
//! Start-up: logging is already on; the configuration is loaded (exit 78 on a bad file),
//! the station locked (exit 69 naming the process that holds it) and leftovers of
//! interrupted writes swept, the control socket bound, then `READY=1` — devices may appear later and are reported in
//! `STATUS=`. An unfinished scan in `output.dir` is resumed at once (one the file system
//! refused to reopen is tried again with the reconnection backoff; one failed for its transient
//! budget is continued once its devices answer, a continuation the file system refused
//! tried again so, with the same backoff); otherwise the daemon
//! waits for `surfscan start`, and never starts a scan by itself. Every status change is
//! sent as `STATUS=`; `WATCHDOG=1` comes from the scan loop itself (also while it reopens a
//! scan or writes its outputs, beside that work) and the idle loop.
//! SIGTERM/SIGINT: `STOPPING=1`, the current line is abandoned cleanly and an interruption
//! (not a stop) is recorded, so the scan resumes at the next start. SIGHUP is logged and
//! otherwise ignored: the configuration is read only at start. The notification hook
//! runs when a scan completes, fails, is aborted or suspends; every event and the status go
//! to the configured publishers ([`crate::publish`]).
//!
//! Which scan a start runs (and which one the daemon resumes at its own start) is
//! [`crate::scan::choice`]'s decision.
//!
//! With `[web]`, the station's page ([`crate::web`]) is started beside the control socket,
//! before READY (a token file or certificate it cannot use is exit 78, an address it cannot
//! listen on exit 69), and stopped after the scan loop.
//!
//! Layer 5 (composition): [`super::station`], [`super::check_config`]'s port check, control
//! server, the station's page, runner, service notifications, hook.

use super::daemon_jobs::{Jobs, Turn};
use super::station::{
    ignore_hangups, lock_station, recipe_conflict, record_scan_in_lock, run_settings, with_job,
};
use super::{CliError, Exit};
use crate::config::Config;
use crate::control::protocol::ControlChannels;
use crate::control::server;
use crate::devices::Fault;
use crate::hook::Hook;
use crate::jobs::service::QueueService;
use crate::panics::spawn_vital;
use crate::publish::Publishers;
use crate::scan::channels::Control;
use crate::scan::choice::{self, Asker};
use crate::scan::command::{OperatorCommand, OperatorRequest, Peer, RecipeStart, StartMode};
use crate::scan::ending::{End, FailCause, StopStatus};
use crate::scan::event::ScanEvent;
use crate::scan::outcome::{NewJob, Outcome, ScanRequest};
use crate::scan::runner::run_scan;
use crate::scan::settings::RunSettings;
use crate::scan::station::{devices_answer, SerialStation, Station};
use crate::scan::status::{ended_status, DeviceState, State, Status};
use crate::scan::testhooks::TestHooks;
use crate::service::Notifier;
use crate::stage::ScanDirection;
use crate::station_lock::StationLock;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, watch};

/// Arguments of `surfscan daemon`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Station configuration (TOML).
    #[arg(long, default_value = super::DEFAULT_CONFIG)]
    pub config: PathBuf,
}

/// How often device presence is refreshed while idle.
const IDLE_TICK: Duration = Duration::from_secs(2);

/// Runs `surfscan daemon`.
pub fn run(args: Args) -> Result<(), CliError> {
    // A port that can never be a serial device (a directory, a regular file) is a
    // configuration to correct, as `check-config` and `scan` say: exit 78, which the unit's
    // RestartPreventExitStatus= keeps from restarting in a loop. An absent device is not: it
    // may be plugged in later.
    let (config, config_hash, _) = super::check_config::load_checked(&args.config)?;
    let control = server::ServerOptions {
        allowed_groups: match &config.control.allowed_groups {
            Some(names) => Some(server::resolve_groups(names).map_err(|e| {
                let path = args.config.display();
                CliError::new(
                    Exit::Config,
                    format!("config {path}: control.allowed-groups: {e}"),
                )
            })?),
            None => None,
        },
        ..server::ServerOptions::default()
    };
    let lock = lock_station(&config, "daemon")?;
    let hooks = TestHooks::from_env().map_err(|e| CliError::new(Exit::Usage, e))?;
    let station = SerialStation::new(config.instrument.clone(), config.stage.clone())
        .map_err(|e| CliError::new(Exit::Config, e))?;
    let settings = run_settings(&config, config_hash.clone(), hooks)?;
    // The job queue: read (a damaged file is kept aside and named), and a job that was
    // running when the daemon stopped settled by the journals.
    let (queue, damaged) =
        QueueService::open(config.clone()).map_err(|e| CliError::new(Exit::Io, e.to_string()))?;
    if let Some(w) = damaged {
        tracing::error!("{w}");
    }
    match queue.reconcile() {
        Ok(notes) => notes.iter().for_each(|n| tracing::info!("queue: {n}")),
        Err(e) => tracing::error!("queue: {e}"),
    }
    let jobs = Jobs::new(queue, config_hash);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| CliError::new(Exit::Failed, format!("cannot start the runtime: {e}")))?;
    // A panic in the daemon's own loop (the scan's state machine, the idle loop) leaves no
    // state to go on from: the runtime is stopped and the process exits with status 70, which
    // systemd restarts (the unfinished scan resumes from its journal). `panics` says where a
    // panic ends less than the process.
    let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        rt.block_on(daemon(&config, settings, jobs, station, control, lock))
    }));
    ran.unwrap_or_else(|p| {
        rt.shutdown_timeout(Duration::from_secs(5));
        crate::panics::exit_internal("the daemon's loop", crate::panics::message(&*p))
    })
}

fn presence(present: bool) -> DeviceState {
    if present {
        DeviceState::Present
    } else {
        DeviceState::Absent
    }
}

async fn daemon(
    config: &Config,
    settings: RunSettings,
    mut jobs: Jobs,
    mut station: SerialStation,
    control: server::ServerOptions,
    lock: Arc<StationLock>,
) -> Result<(), CliError> {
    let notifier = Arc::new(Notifier::from_env());
    let srv = server::bind_with_options(&config.control.socket, control)
        .await
        .map_err(|e| CliError::new(Exit::Unavailable, e.to_string()))?;
    // The scans skipped for a damaged journal are in the status from the first request on,
    // and so are the devices: a scan reopened at once (paused, or straight into its outputs)
    // would otherwise show them absent until the idle loop first looks.
    let (status_tx, status_rx) = watch::channel(Status {
        damaged_journals: damaged_journal_warnings(&config.output.dir),
        instrument: presence(station.instrument_present()),
        stage: presence(station.stage_present()),
        ..Status::idle()
    });
    let (cmd_tx, cmd_rx) = mpsc::channel::<OperatorRequest>(16);
    let (shutdown_tx, shutdown_rx) = watch::channel(false);

    // The station's page, when configured: its own thread, the same channels as the socket.
    // A token file or certificate that cannot be used is a configuration error; an address
    // that cannot be listened on is named in the log and the status's links, and the station
    // scans on without its page, as it does without /metrics.
    let web = match &config.web {
        Some(w) => {
            let channels = ControlChannels {
                status: status_rx.clone(),
                commands: cmd_tx.clone(),
                queue: Some(jobs.queue.clone()),
            };
            match crate::web::start(w, channels, config.output.dir.clone()) {
                Ok(page) => {
                    tracing::info!("the station's page is at {}", page.url());
                    Some(page)
                }
                Err(e @ crate::web::WebError::Config(_)) => {
                    return Err(CliError::new(Exit::Config, e.to_string()))
                }
                Err(e) => {
                    crate::publish::fail(&status_tx, crate::web::LINK, e.to_string());
                    None
                }
            }
        }
        None => None,
    };
    let mut srv_shutdown = shutdown_rx.clone();
    let server_task = spawn_vital(
        "the control socket's server",
        srv.serve(
            ControlChannels {
                status: status_rx.clone(),
                commands: cmd_tx.clone(),
                queue: Some(jobs.queue.clone()),
            },
            async move {
                let _ = srv_shutdown.wait_for(|v| *v).await;
            },
        ),
    );
    tracing::info!(
        "surfscan daemon {} ready: control socket {}, scans in {}",
        env!("CARGO_PKG_VERSION"),
        config.control.socket.display(),
        config.output.dir.display()
    );
    notifier.ready();

    spawn_vital(
        "the station lock's record",
        record_scan_in_lock(lock, status_rx.clone()),
    );

    // STATUS= on every change.
    let n = notifier.clone();
    let mut rx = status_rx.clone();
    spawn_vital("the systemd status", async move {
        let mut last = String::new();
        loop {
            let text = rx.borrow_and_update().summary();
            if text != last {
                n.status(&text);
                last = text;
            }
            if rx.changed().await.is_err() {
                break;
            }
        }
    });

    // SIGHUP changes nothing: the configuration is read once, at start.
    spawn_vital("the SIGHUP handler", ignore_hangups(
        "ignored; the daemon reads its configuration only at start (systemctl restart surfscan applies a change; an unfinished scan resumes)",
    ));

    // SIGTERM / SIGINT.
    let n = notifier.clone();
    spawn_vital("the SIGTERM handler", async move {
        use tokio::signal::unix::{signal, SignalKind};
        let (Ok(mut term), Ok(mut int)) = (
            signal(SignalKind::terminate()),
            signal(SignalKind::interrupt()),
        ) else {
            tracing::error!("cannot install signal handlers");
            return;
        };
        tokio::select! {
            _ = term.recv() => tracing::info!("SIGTERM: stopping"),
            _ = int.recv() => tracing::info!("SIGINT: stopping"),
        }
        n.stopping();
        let _ = shutdown_tx.send(true);
    });

    // The publishers (MQTT) and the notification hook. Neither is on the scan's path: the
    // runner only sends into this channel.
    let publishers = Publishers::start(
        config,
        &status_tx,
        Some(ControlChannels {
            status: status_rx.clone(),
            commands: cmd_tx.clone(),
            queue: Some(jobs.queue.clone()),
        }),
    );
    let to_publishers = publishers.sender();
    let (ev_tx, mut ev_rx) = mpsc::unbounded_channel::<ScanEvent>();
    let hook = config.notify.as_ref().and_then(Hook::new);
    let events_task = spawn_vital("the scan's events", async move {
        while let Some(ev) = ev_rx.recv().await {
            if let Some(h) = hook.as_ref().filter(|_| ev.kind.runs_hook()) {
                h.fire(ev.clone());
            }
            if let Some(tx) = &to_publishers {
                let _ = tx.send(ev);
            }
        }
    });

    let mut ctl = Control::new(cmd_rx, shutdown_rx.clone(), status_tx);
    if let Some(period) = notifier.watchdog_interval() {
        let n = notifier.clone();
        ctl.watchdog = Some((period, Arc::new(move || n.watchdog())));
    }
    ctl.events = Some(ev_tx);
    ctl.metrics = publishers.scan_metrics();

    // Resume an unfinished scan at start-up (a job's scan among them: the queue then
    // records its end).
    let mut stop = false;
    let mut awaiting: Option<Awaiting> = None;
    match choice::choose(
        &config.output.dir,
        Asker::DaemonStartUp,
        Peer::this_process(),
        Default::default(),
    )
    .and_then(|c| match &c.decision {
        choice::Decision::AwaitDevices(dir) => {
            awaiting = Some(Awaiting::new(dir.clone(), &settings));
            Ok(None)
        }
        _ => c.commit(),
    }) {
        Ok(Some(request)) => {
            // Reopened by the daemon itself: no operator asked (a paused scan stays paused).
            let req = match request {
                ScanRequest::Resume { dir, .. } => ScanRequest::Resume { dir, peer: None },
                ScanRequest::Continue { dir, .. } => ScanRequest::Continue { dir, peer: None },
                other => other,
            };
            ctl.status.send_modify(Status::begin_start);
            (stop, awaiting) = unqueued(
                &mut station,
                &mut ctl,
                &mut jobs,
                &settings,
                &settings,
                req,
                None,
            )
            .await;
        }
        Ok(None) => {}
        Err(e) => tracing::error!("{e}"),
    }

    let mut tick = tokio::time::interval(
        notifier
            .watchdog_interval()
            .map_or(IDLE_TICK, |w| w.min(IDLE_TICK)),
    );
    let mut shutdown = shutdown_rx.clone();
    let mut queue_changes = jobs.queue.subscribe();
    while !stop && !*shutdown.borrow() {
        // No scan runs: the queue's turn, unless a failed scan waits to be continued (a
        // job's among them: its job is not over).
        if awaiting.is_none() {
            let present = station.instrument_present() && station.stage_present();
            let turn = tokio::task::block_in_place(|| {
                jobs.turn(&settings, present, std::time::Instant::now())
            });
            match turn {
                Turn::Run {
                    job,
                    request,
                    settings: job_settings,
                } => {
                    waiting(&ctl.status, None);
                    ctl.status.send_modify(|s| {
                        s.begin_start();
                        s.queue = Some(Box::new(jobs.queue.status()));
                    });
                    let outcome = run_scan(&mut station, &mut ctl, &job_settings, request).await;
                    stop = outcome.end == End::Shutdown;
                    awaiting = Awaiting::after(&outcome, &job_settings, None);
                    tokio::task::block_in_place(|| jobs.settle(job, &outcome, &settings));
                    note_damaged_journals(&config.output.dir, &ctl.status);
                    continue;
                }
                // A scan the file system refused to reopen, tried again with backoff.
                Turn::Reopen(request) => {
                    waiting(&ctl.status, None);
                    ctl.status.send_modify(Status::begin_start);
                    (stop, awaiting) = unqueued(
                        &mut station,
                        &mut ctl,
                        &mut jobs,
                        &settings,
                        &settings,
                        request,
                        None,
                    )
                    .await;
                    continue;
                }
                Turn::Wait(why) => waiting(&ctl.status, Some(why)),
                Turn::Nothing => waiting(&ctl.status, None),
            }
        }
        let q = jobs.queue.status();
        ctl.status.send_if_modified(|s| {
            let changed = s.queue.as_deref() != Some(&q);
            s.queue = Some(Box::new(q));
            changed
        });
        tokio::select! {
            Ok(()) = shutdown.changed() => {}
            // A job added, loaded or removed, or the queue continued: look at it again.
            Ok(()) = queue_changes.changed() => {}
            req = ctl.commands.recv() => {
                let Some(req) = req else { break };
                let Some(req) = req.unless_abandoned() else { continue };
                match req.command {
                    OperatorCommand::Start { specimen, operator, notes, mode, recipe } => {
                        let busy = !matches!(ctl.status.borrow().state, State::Idle | State::Waiting);
                        if busy {
                            let running = match ctl.status.borrow().scan_id.clone() {
                                Some(id) => format!("scan {id} is running"),
                                None => "a scan is being started (no id yet)".to_owned(),
                            };
                            let _ = req.reply.send(Err(format!(
                                "{running}; abort it first or wait until it ends"
                            )));
                            continue;
                        }
                        let start = match operator_start(config, &jobs, &settings, (specimen, operator, notes), mode, recipe, req.peer) {
                            Ok(s) => s,
                            Err(why) => {
                                tracing::error!("{why}");
                                let _ = req.reply.send(Err(why));
                                continue;
                            }
                        };
                        // Nothing is changed, on disk or at the station, unless the operator
                        // is told the start goes ahead.
                        let told = req.reply.send(Ok(format!(
                            "{}; follow it with `surfscan status --watch`", start.what
                        )));
                        if told.is_err() {
                            tracing::warn!("dropped a start: the control socket stopped waiting for it and told the operator it was not carried out");
                            continue;
                        }
                        waiting(&ctl.status, None);
                        ctl.status.send_modify(Status::begin_start);
                        // The operator's start takes over from a continuation the daemon
                        // was waiting to make.
                        awaiting = None;
                        let request = match start.choice.commit().map_err(CliError::from) {
                            Ok(Some(r)) => with_job(r, start.job),
                            Ok(None) => {
                                ctl.status.send_modify(|s| s.state = State::Idle);
                                continue;
                            }
                            Err(e) => {
                                tracing::error!("{e}");
                                let ended = ended_status(&ctl.status.borrow(), StopStatus::Fail, &e.to_string());
                                ctl.status.send_replace(ended);
                                note_damaged_journals(&config.output.dir, &ctl.status);
                                continue;
                            }
                        };
                        (stop, awaiting) = unqueued(&mut station, &mut ctl, &mut jobs, &start.settings, &settings, request, None).await;
                    }
                    OperatorCommand::Pause | OperatorCommand::Resume | OperatorCommand::Abort => {
                        let _ = req.reply.send(Err(
                            "no scan is running; `surfscan start` starts one".into(),
                        ));
                    }
                }
            }
            _ = tick.tick() => {
                notifier.watchdog();
                let (i, s) = (presence(station.instrument_present()), presence(station.stage_present()));
                ctl.status.send_if_modified(|st| {
                    let changed = st.instrument != i || st.stage != s;
                    st.instrument = i;
                    st.stage = s;
                    changed
                });
                let due = awaiting.as_ref().is_some_and(|a| tokio::time::Instant::now() >= a.next);
                if let (true, Some(a)) = (due, awaiting.as_mut()) {
                    let answered = watched_probe(&mut station, &settings, &notifier).await;
                    match answered {
                        Ok(()) => {
                            let dir = a.dir.clone();
                            tracing::info!("the devices answer again: continuing the scan {} that failed for its transient budget", dir.display());
                            ctl.status.send_modify(|s| {
                                s.begin_start();
                                s.reason = None;
                            });
                            let req = ScanRequest::Continue { dir, peer: None };
                            // Awaited again when the file system refuses it.
                            let awaited = awaiting.take();
                            (stop, awaiting) = unqueued(&mut station, &mut ctl, &mut jobs, &settings, &settings, req, awaited).await;
                        }
                        Err(fault) => {
                            let reason = a.not_yet(&fault, &settings);
                            ctl.status.send_modify(|s| s.reason = Some(reason));
                        }
                    }
                }
            }
        }
    }
    notifier.stopping();
    if let Some(page) = web {
        let _ = tokio::time::timeout(
            Duration::from_secs(5),
            tokio::task::spawn_blocking(move || page.stop()),
        )
        .await;
    }
    // The server stops on the shutdown signal; on a closed command channel tell it too.
    drop(ctl);
    if *shutdown_rx.borrow() {
        let _ = tokio::time::timeout(Duration::from_secs(5), server_task).await;
    }
    // What the scan told last is stored in the outbox before the links say `offline`.
    let _ = tokio::time::timeout(Duration::from_secs(2), events_task).await;
    publishers.finish(Duration::from_secs(4)).await;
    tracing::info!("surfscan daemon stopped");
    Ok(())
}

/// Runs `request`, a scan not started as a job (the daemon's own resumption or continuation,
/// an operator's start), with `settings`; a job's scan among them settles its job, and a
/// refused reopening is remembered ([`Jobs::settle_if_a_job`], with the station's settings
/// `base`). Whether the daemon stops (a shutdown ended the scan), and the continuation it
/// then awaits (`awaited`, the one `request` carries out, again when the file system refused
/// it: [`Awaiting::after`]).
async fn unqueued(
    station: &mut SerialStation,
    ctl: &mut Control,
    jobs: &mut Jobs,
    settings: &RunSettings,
    base: &RunSettings,
    request: ScanRequest,
    awaited: Option<Awaiting>,
) -> (bool, Option<Awaiting>) {
    let outcome = run_scan(station, ctl, settings, request).await;
    let awaiting = Awaiting::after(&outcome, settings, awaited);
    tokio::task::block_in_place(|| jobs.settle_if_a_job(&outcome, base));
    note_damaged_journals(&base.output_dir, &ctl.status);
    (outcome.end == End::Shutdown, awaiting)
}

/// A scan that failed for its transient budget (a device kept answering wrongly), which the
/// daemon continues by itself once both devices answer properly again; they are asked with
/// the scan's backoff. A continuation the file system refused is awaited again, the wait
/// going on doubling.
#[derive(Debug)]
struct Awaiting {
    dir: PathBuf,
    next: tokio::time::Instant,
    wait: Duration,
}

impl Awaiting {
    fn new(dir: PathBuf, settings: &RunSettings) -> Awaiting {
        let wait = settings.backoff.next(Duration::ZERO);
        tracing::info!(
            "the scan {} failed for its transient budget; it is continued once its devices answer again",
            dir.display()
        );
        Awaiting {
            dir,
            next: tokio::time::Instant::now() + wait,
            wait,
        }
    }

    /// What to wait for after a scan ended: its continuation when it failed for its budget;
    /// the continuation `awaited` (the one that ran) again, after the backoff's next step,
    /// when the file system refused it, which can clear by itself (the scan's stop record
    /// stays, so nothing else tries it before the next start).
    fn after(
        outcome: &Outcome,
        settings: &RunSettings,
        awaited: Option<Awaiting>,
    ) -> Option<Awaiting> {
        match (&outcome.end, &outcome.dir) {
            (End::Fail(r), Some(dir)) if r.cause() == FailCause::Budget => {
                Some(Awaiting::new(dir.clone(), settings))
            }
            (End::Fail(r), Some(dir)) if r.refused_by_the_file_system() => {
                let mut a = awaited.filter(|a| a.dir == *dir)?;
                a.later(settings);
                tracing::info!(
                    "the file system refused continuing the scan {}; it is continued once it allows it and the devices answer, tried again in {} s",
                    dir.display(),
                    a.wait.as_secs()
                );
                Some(a)
            }
            _ => None,
        }
    }

    /// The next try after the backoff's next step.
    fn later(&mut self, settings: &RunSettings) {
        self.wait = settings.backoff.next(self.wait);
        self.next = tokio::time::Instant::now() + self.wait;
    }

    /// The devices did not answer yet: the next try after a longer wait; the status's reason.
    fn not_yet(&mut self, fault: &Fault, settings: &RunSettings) -> String {
        self.later(settings);
        tracing::debug!("devices not answering yet: {fault}");
        format!(
            "the scan {} failed for its transient budget and is continued once the devices answer again; last try: {fault}",
            self.dir.display()
        )
    }
}

/// Asks both devices whether they answer ([`crate::scan::station::devices_answer`]), feeding
/// the watchdog meanwhile.
async fn watched_probe(
    station: &mut SerialStation,
    settings: &RunSettings,
    notifier: &Notifier,
) -> Result<(), Fault> {
    let direction = ScanDirection::of_step(settings.plan.y_step_nm);
    let probe = devices_answer(station, direction);
    tokio::pin!(probe);
    let mut tick = tokio::time::interval(IDLE_TICK);
    loop {
        tokio::select! {
            r = &mut probe => return r,
            _ = tick.tick() => notifier.watchdog(),
        }
    }
}

/// A start the daemon will carry out: the choice, the settings it runs with, the recipe's
/// job (for `start --recipe`) and what the operator is told.
struct OperatorStart {
    choice: choice::Choice,
    settings: RunSettings,
    job: Option<Box<NewJob>>,
    what: String,
}

/// Decides an operator's start: the scan choice, and with `--recipe` the recipe's plan and
/// job (an unfinished scan of another recipe, or of the station's plan, is not resumed under
/// a recipe's name: the reason says what to do).
fn operator_start(
    config: &Config,
    jobs: &Jobs,
    base: &RunSettings,
    traceability: (String, String, String),
    mode: StartMode,
    recipe: Option<Box<RecipeStart>>,
    peer: Peer,
) -> Result<OperatorStart, String> {
    let choice = choice::choose(
        &config.output.dir,
        Asker::Operator(mode),
        peer,
        traceability,
    )
    .map_err(|e| e.to_string())?;
    if let choice::Decision::Refuse(why) = &choice.decision {
        return Err(why.clone());
    }
    let Some(r) = recipe else {
        let what = choice.describe(config.scan.lines);
        return Ok(OperatorStart {
            choice,
            settings: base.clone(),
            job: None,
            what,
        });
    };
    let (settings, job) = jobs.recipe_settings(&r, base)?;
    if let Some(why) = recipe_conflict(&choice.decision, &r.record.recipe, "surfscan start") {
        return Err(why);
    }
    let what = match &choice.decision {
        choice::Decision::New { .. } => format!(
            "starting a scan of recipe {} ({} lines)",
            r.record.recipe, settings.plan.lines
        ),
        _ => choice.describe(settings.plan.lines),
    };
    Ok(OperatorStart {
        choice,
        settings,
        job: Some(Box::new(job)),
        what,
    })
}

/// Shows the queue's reason to wait (`Waiting`), or clears it, when no scan runs.
fn waiting(status: &watch::Sender<Status>, why: Option<String>) {
    status.send_if_modified(|s| match (&why, s.state) {
        (Some(w), State::Idle | State::Waiting) => {
            let changed = s.state != State::Waiting || s.reason.as_ref() != Some(w);
            s.state = State::Waiting;
            s.reason = Some(w.clone());
            changed
        }
        (None, State::Waiting) => {
            s.state = State::Idle;
            s.reason = None;
            true
        }
        _ => false,
    });
}

/// Shows in the status the scans skipped because their journal is damaged (the snapshot a
/// scan's end publishes starts afresh, so this is noted again after each scan).
fn note_damaged_journals(output_dir: &Path, status: &watch::Sender<Status>) {
    let warnings = damaged_journal_warnings(output_dir);
    status.send_if_modified(|s| {
        let changed = s.damaged_journals != warnings;
        s.damaged_journals = warnings;
        changed
    });
}

/// One warning per scan of the output directory whose journal is damaged (also logged).
fn damaged_journal_warnings(output_dir: &Path) -> Vec<String> {
    let warnings = crate::scan::journal::survey(output_dir)
        .map(|s| s.warnings())
        .unwrap_or_default();
    for w in &warnings {
        tracing::warn!("{w}");
    }
    warnings
}

#[cfg(test)]
mod tests {
    use super::Awaiting;
    use crate::jobs::service::tests::station;
    use crate::scan::ending::{End, FailKind, FailReason};
    use crate::scan::outcome::Outcome;
    use crate::scan::policy::Backoff;
    use crate::scan::testhooks::TestHooks;
    use std::time::Duration;

    /// A budget-failed scan's continuation that the file system refused (a full or read-only
    /// disk) is awaited again, after the backoff's next step, as a refused reopening is tried
    /// again. Before, the daemon stopped waiting on it, and the retry of refused reopenings
    /// skipped it for its stop record: it was continued only at the daemon's next start.
    /// A refusal with nothing awaited, or of another scan, awaits nothing.
    #[test]
    fn a_continuation_the_file_system_refused_is_awaited_again_with_backoff() {
        let tmp = tempfile::tempdir().expect("tmp");
        let mut settings = super::super::station::run_settings(
            &station(tmp.path()),
            "ab".repeat(32),
            TestHooks::default(),
        )
        .expect("settings");
        settings.backoff = Backoff {
            initial: Duration::from_secs(2),
            max: Duration::from_secs(60),
        };
        let dir = settings.output_dir.join("20261207-2200-C-1");
        let refused = |dir: &std::path::Path| Outcome {
            end: End::Fail(FailReason::Refused {
                message: "the file system refused reading its lines back (EIO: …); …".into(),
                kind: FailKind::Io,
            }),
            dir: Some(dir.to_path_buf()),
            outputs: None,
        };

        let awaited = Awaiting::new(dir.clone(), &settings);
        assert_eq!(awaited.wait, Duration::from_secs(2));
        let before = tokio::time::Instant::now();
        let again = Awaiting::after(&refused(&dir), &settings, Some(awaited))
            .expect("the refused continuation is no longer awaited");
        assert_eq!(again.dir, dir);
        // 2 s, doubled.
        assert_eq!(again.wait, Duration::from_secs(4));
        assert!(again.next >= before + Duration::from_secs(4));
        // Refused again: 8 s.
        let again = Awaiting::after(&refused(&dir), &settings, Some(again)).expect("awaited");
        assert_eq!(again.wait, Duration::from_secs(8));

        assert!(Awaiting::after(&refused(&dir), &settings, None).is_none());
        let other = Awaiting::new(dir.with_file_name("20261207-2300-C-2"), &settings);
        assert!(Awaiting::after(&refused(&dir), &settings, Some(other)).is_none());
    }
}
