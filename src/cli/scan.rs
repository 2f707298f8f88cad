//! `surfscan scan`: one scan in the foreground, exactly as the daemon runs it — an
//! unfinished scan of this configuration is resumed first — with a progress bar (line k/N,
//! ETA, the last line's Ra). Ctrl-C abandons the current line and leaves the scan
//! resumable, as SIGTERM does for the daemon. A hang-up (SIGHUP: the terminal or SSH session
//! went away) does not stop it: the scan goes on without its terminal, and what it would have
//! printed is dropped.
//!
//! Exit status: 0 success, 1 the scan failed or was aborted, 2 usage, 3 the scan completed
//! but its characterisation is partial (every line, the IGES and every output that could be
//! made are written; report.json names the sections that could not be made and why), 69 a
//! device is unavailable (or another `scan` or the daemon holds the station: its pid and scan
//! are named), 74 I/O error, 78 bad configuration.
//!
//! The end-of-scan summary prints the result (lines, Ra, Sa) and the verdict on the model
//! between lines (the hold-out of [`crate::metrology::holdout`]), not the residual at the data
//! points, which an interpolant makes zero by construction.
//!
//! Layer 5 (composition): config, station, runner, signals, terminal; turns the configuration
//! into the runner's typed settings.

use super::{CliError, Exit};
use crate::config::{Config, ConfigError};
use crate::report::{ScanAnalysisOptions, ScanCharacteriser};
use crate::scan::channels::Control;
use crate::scan::command::{Peer, StartMode};
use crate::scan::faults::NoFaults;
use crate::scan::journal::{
    find_unfinished, read_journal, Journal, Record, ResumeState, StopRecord, StopStatus,
    JOURNAL_FILE,
};
use crate::scan::outcome::{FailKind, Outcome, ScanRequest};
use crate::scan::plan::{AnalysisPlan, Plan};
use crate::scan::policy::Backoff;
use crate::scan::runner::run_scan;
use crate::scan::settings::RunSettings;
use crate::scan::station::SerialStation;
use crate::scan::status::{State, Status};
use crate::scan::testhooks::TestHooks;
use crate::station_lock::{self, LockError, StationLock};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, watch};

/// Arguments of `surfscan scan`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Station configuration (TOML).
    #[arg(long, default_value = super::DEFAULT_CONFIG)]
    pub config: PathBuf,
    /// Specimen id (recorded with the scan).
    #[arg(long, default_value = "")]
    pub specimen: String,
    /// Operator name (recorded with the scan).
    #[arg(long, default_value = "")]
    pub operator: String,
    /// Free-text notes (recorded with the scan).
    #[arg(long, default_value = "")]
    pub notes: String,
    /// Continue the newest unfinished or failed scan at its first missing line (after the
    /// cause of a failure was cleared).
    #[arg(long, conflicts_with = "new")]
    pub resume: bool,
    /// Start a new scan even when one is unfinished (that one is recorded as abandoned).
    #[arg(long)]
    pub new: bool,
}

/// The start mode of `--resume` / `--new` (neither: resume an unfinished scan, else new).
pub fn start_mode(resume: bool, new: bool) -> StartMode {
    match (resume, new) {
        (true, _) => StartMode::Resume,
        (_, true) => StartMode::New,
        _ => StartMode::Auto,
    }
}

/// Loads the configuration and the SHA-256 of its bytes; a bad file is exit 78.
pub fn load_config(path: &Path) -> Result<(Config, String), CliError> {
    let bytes = std::fs::read(path).map_err(|e| {
        CliError::new(
            Exit::Config,
            ConfigError::Read {
                path: path.to_path_buf(),
                source: e,
            }
            .to_string(),
        )
    })?;
    let hash = crate::scan::store::hex_sha256(&bytes);
    let text = String::from_utf8(bytes).map_err(|e| {
        CliError::new(
            Exit::Config,
            format!(
                "config {}: not UTF-8 text (byte {})",
                path.display(),
                e.utf8_error().valid_up_to()
            ),
        )
    })?;
    let config =
        Config::parse(path, &text).map_err(|e| CliError::new(Exit::Config, e.to_string()))?;
    Ok((config, hash))
}

/// The plan of a new scan of this configuration.
pub fn plan_of(config: &Config) -> Result<Plan, ConfigError> {
    let (y_start_nm, y_step_nm) = config.y_grid_nm()?;
    Ok(Plan {
        lines: config.scan.lines,
        y_start_nm,
        y_step_nm,
        degree_u: config.fit.degree_u,
        degree_v: config.fit.degree_v,
        max_line_attempts: config.scan.max_line_attempts,
        v_method: config.fit.v_method_for(config.scan.lines as usize),
        replace_spikes: (config.fit.outliers == crate::config::FitOutliers::Replace)
            .then(|| config.analysis.spike_options()),
        analysis: Some(analysis_of(&config.analysis)),
    })
}

/// The characterisation of `[analysis]`, as a scan's plan freezes it.
pub fn analysis_of(a: &crate::config::AnalysisSettings) -> AnalysisPlan {
    AnalysisPlan {
        curves: a.curves,
        levels: a.levels,
        lambda_c_mm: a.lambda_c_mm,
        no_filter: a.no_filter,
        spikes: a.spike_options(),
        exclude_spikes: a.outliers == crate::config::OutlierPolicy::Exclude,
        holdout_threshold: a.holdout_threshold,
    }
}

/// The runner's settings for a station: the plan and session settings of the configuration,
/// a frozen copy of it and its hash, the test hooks, and the characterisation of `[analysis]`
/// run when a scan completes. A configuration whose plan cannot be made is exit 78.
pub fn run_settings(
    config: &Config,
    config_hash: String,
    hooks: TestHooks,
) -> Result<RunSettings, CliError> {
    let plan = plan_of(config).map_err(|e| CliError::new(Exit::Config, e.to_string()))?;
    // A new scan freezes this in its plan; a resumed scan of an older version, which froze
    // none, is characterised with it.
    let characterise = ScanCharacteriser {
        options: ScanAnalysisOptions::default().with_frozen(&analysis_of(&config.analysis)),
    };
    Ok(RunSettings {
        plan,
        output_dir: config.output.dir.clone(),
        home_on_start: config.stage.home_on_start,
        instrument_baud: config.instrument.baud,
        backoff: Backoff {
            initial: Duration::from_millis(config.scan.reconnect_initial_ms),
            max: Duration::from_millis(config.scan.reconnect_max_ms),
        },
        transient_budget: Duration::from_secs(config.scan.transient_budget_s),
        metrics_file: config.metrics.file.clone(),
        config: serde_json::to_value(config).unwrap_or_default(),
        config_hash,
        hooks: Arc::new(hooks),
        characterise: Some(Arc::new(characterise)),
    })
}

/// Where the device locks go: [`station_lock::DEVICE_LOCK_DIR`], or the directory
/// `SURFSCAN_TEST_LOCK_DIR` names (see [`lock_station`]).
fn device_lock_dir() -> PathBuf {
    std::env::var_os("SURFSCAN_TEST_LOCK_DIR").map_or_else(
        || PathBuf::from(station_lock::DEVICE_LOCK_DIR),
        PathBuf::from,
    )
}

/// A start decided on and not yet carried out: the scan to run, and the unfinished scans to
/// record as abandoned first (a start with [`StartMode::New`]).
#[derive(Debug)]
pub struct StartChoice {
    /// The scan to run.
    pub request: ScanRequest,
    /// Unfinished scans a new one replaces.
    pub abandon: Vec<PathBuf>,
    /// Who asked.
    pub peer: Peer,
}

impl StartChoice {
    /// Records the replaced scans as abandoned (the start's only change on disk before the
    /// scan itself), and hands over the scan to run.
    pub fn commit(self) -> Result<ScanRequest, CliError> {
        for dir in &self.abandon {
            abandon(dir, self.peer)?;
        }
        Ok(self.request)
    }
}

/// The scan to run for this configuration, as `mode` asks: the unfinished one (no stop
/// record) started last, by its journal, else a new one; with [`StartMode::Resume`] a failed
/// one is continued too (refused when there is none); with [`StartMode::New`] unfinished scans
/// are recorded as abandoned and a new one starts. A scan whose journal is damaged is skipped
/// with a warning. `peer` is who asked, for the journal.
///
/// Nothing is changed by the decision: it is carried out with [`StartChoice::commit`] once
/// the start is sure to go ahead (the daemon first tells the operator so, and a start the
/// operator was told had not happened changes nothing).
pub fn decide_request(
    config: &Config,
    specimen: String,
    operator: String,
    notes: String,
    mode: StartMode,
    peer: Peer,
) -> Result<StartChoice, CliError> {
    let decided = |request: ScanRequest, abandon: Vec<PathBuf>| StartChoice {
        request,
        abandon,
        peer,
    };
    let out = &config.output.dir;
    let unfinished = find_unfinished(out).map_err(|e| {
        CliError::new(
            Exit::Io,
            format!("cannot look for unfinished scans in {}: {e}", out.display()),
        )
    })?;
    let new = ScanRequest::New {
        specimen,
        operator,
        notes,
        peer: Some(peer),
    };
    if mode == StartMode::New {
        return Ok(decided(new, unfinished));
    }
    if let Some((last, older)) = unfinished.split_last() {
        for o in older {
            tracing::warn!(
                "{} is also unfinished; only the one started last is resumed (resume it by hand with `surfscan fit`/`analyze`, or add a stop record)",
                o.display()
            );
        }
        tracing::info!("resuming the unfinished scan {}", last.display());
        return Ok(decided(
            ScanRequest::Resume {
                dir: last.clone(),
                peer: Some(peer),
            },
            Vec::new(),
        ));
    }
    let failed = newest_failed(out);
    match (mode, failed) {
        (StartMode::Resume, Some(dir)) => {
            tracing::info!("continuing the failed scan {}", dir.display());
            Ok(decided(
                ScanRequest::Continue {
                    dir,
                    peer: Some(peer),
                },
                Vec::new(),
            ))
        }
        (StartMode::Resume, None) => Err(CliError::new(
            Exit::Failed,
            format!(
                "no unfinished or failed scan in {} to resume; start without --resume for a new one",
                out.display()
            ),
        )),
        (_, Some(dir)) => {
            tracing::warn!(
                "the last scan {} failed; a new scan starts (`--resume` continues the failed one at its first missing line)",
                dir.display()
            );
            Ok(decided(new, Vec::new()))
        }
        (_, None) => Ok(decided(new, Vec::new())),
    }
}

/// The failed scan (stop record `fail`) under `output_dir` that started last, by its start
/// record's sequence number (then its time); scans whose journal cannot be read are skipped
/// with a warning.
fn newest_failed(output_dir: &Path) -> Option<PathBuf> {
    let entries = std::fs::read_dir(output_dir).ok()?;
    let mut best: Option<((u64, chrono::DateTime<chrono::Utc>), PathBuf)> = None;
    for dir in entries.filter_map(|e| e.ok().map(|e| e.path())) {
        let path = dir.join(JOURNAL_FILE);
        if !path.is_file() {
            continue;
        }
        let state =
            match read_journal(&path).and_then(|r| ResumeState::from_records(&path, &r.records)) {
                Ok(s) => s,
                Err(e) => {
                    tracing::warn!("skipping {}: {e}", dir.display());
                    continue;
                }
            };
        if state.stop.as_ref().map(|s| s.status) != Some(StopStatus::Fail) {
            continue;
        }
        // Started last by the sequence number no clock reorders, then (older journals) time.
        let key = (state.start.sequence, state.start.time);
        if best.as_ref().is_none_or(|(k, _)| key > *k) {
            best = Some((key, dir));
        }
    }
    best.map(|(_, d)| d)
}

/// Records in an unfinished scan's journal that it was abandoned for a new one.
fn abandon(dir: &Path, peer: Peer) -> Result<(), CliError> {
    let path = dir.join(JOURNAL_FILE);
    let io = |e: String| {
        CliError::new(
            Exit::Io,
            format!(
                "cannot record that the scan in {} is abandoned: {e}",
                dir.display()
            ),
        )
    };
    let (mut journal, _) =
        Journal::open(&path, Arc::new(NoFaults)).map_err(|e| io(e.to_string()))?;
    let reason = format!(
        "abandoned: a new scan was started instead (--new, by uid {} pid {})",
        peer.uid,
        peer.pid.map_or("unknown".to_owned(), |p| p.to_string())
    );
    journal
        .append(&Record::Stop(StopRecord {
            status: StopStatus::Abandoned,
            reason: reason.clone(),
            time: chrono::Utc::now(),
        }))
        .map_err(|e| io(e.to_string()))?;
    tracing::warn!("{}: {reason}", dir.display());
    Ok(())
}

/// Maps a scan's outcome to the exit status and message of a foreground command.
pub fn outcome_result(outcome: &Outcome) -> Result<(), CliError> {
    match outcome {
        Outcome::Success { dir, outputs } => {
            say!("scan complete: {}", dir.display());
            for p in &outputs.iges {
                say!("  surface  {}", p.display());
            }
            say!("  report   {}", outputs.report.display());
            // The report for people first; the per-line Rk plots as one entry.
            let (rk, files): (Vec<&PathBuf>, Vec<&PathBuf>) = outputs
                .files
                .iter()
                .partition(|p| p.parent().and_then(|d| d.file_name()) == Some("rk".as_ref()));
            for p in files {
                say!("  file     {}", p.display());
            }
            if let Some(dir) = rk.first().and_then(|p| p.parent()) {
                say!(
                    "  file     {}/ ({} Rk construction plots, one PNG and SVG per line)",
                    dir.display(),
                    rk.len()
                );
            }
            if let Some(e) = &outputs.characterisation_error {
                say!("  characterisation failed: {e}; the report holds the fit and the instrument's results");
            }
            let report = std::fs::read(&outputs.report)
                .ok()
                .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok());
            match &report {
                Some(report) => {
                    for (k, v) in result_summary(report) {
                        say!("  {k:<8} {v}");
                    }
                }
                None => say!("  (the report cannot be read back for a summary)"),
            }
            // Without a verdict in the report, say why there is none.
            if report
                .as_ref()
                .and_then(crate::report::html::verdict)
                .is_none()
            {
                say!("  model    {}", outputs.verdict);
            }
            if outputs.characterisation_complete {
                Ok(())
            } else {
                Err(CliError::new(
                    Exit::Partial,
                    format!(
                        "scan complete, but its characterisation is partial (report.json's characterisation and warnings say which sections could not be made and why): {}",
                        outputs.report.display()
                    ),
                ))
            }
        }
        Outcome::Aborted { dir } => Err(CliError::new(
            Exit::Failed,
            format!(
                "scan aborted; the lines traced are kept in {}",
                dir.display()
            ),
        )),
        Outcome::Interrupted { dir } => Err(CliError::new(
            Exit::Failed,
            format!(
                "scan interrupted; run the same command again to resume it ({})",
                dir.display()
            ),
        )),
        Outcome::Failed { dir, reason, kind } => {
            let exit = match kind {
                FailKind::Scan => Exit::Failed,
                FailKind::Unavailable => Exit::Unavailable,
                FailKind::Io => Exit::Io,
            };
            let msg = match dir {
                Some(d) => format!("scan failed: {reason} (lines kept in {})", d.display()),
                None => format!("scan not started: {reason}"),
            };
            Err(CliError::new(exit, msg))
        }
    }
}

/// The result of a characterised scan in a few lines, from its `report.json` (see
/// [`crate::report::html::result_summary`]).
pub fn result_summary(report: &serde_json::Value) -> Vec<(&'static str, String)> {
    crate::report::html::result_summary(report)
}

/// Refuses when a daemon answers on the configured control socket: it holds the ports.
pub fn refuse_if_daemon(config: &Config) -> Result<(), CliError> {
    let sock = &config.control.socket;
    if std::os::unix::net::UnixStream::connect(sock).is_ok() {
        return Err(CliError::new(
            Exit::Unavailable,
            format!(
                "the surfscan daemon is running (it answers on {}) and holds the ports; use `surfscan start` to scan through it, or stop it first",
                sock.display()
            ),
        ));
    }
    Ok(())
}

/// What the progress bar says after its bar: lines done, the ETA only while scanning (a
/// paused or suspended scan has none), the last line's Ra, and the state when it is not
/// scanning.
pub fn progress_message(s: &Status) -> String {
    let mut parts = Vec::new();
    if let Some(eta) = super::control::eta_while_scanning(s) {
        parts.push(format!("ETA {eta}"));
    }
    if let Some(ra) = s.last_ra_um {
        parts.push(format!(
            "last Ra {} µm",
            crate::numfmt::fmt(ra, crate::numfmt::Quantity::HeightUm)
        ));
    }
    if s.state != State::Scanning {
        parts.push(s.summary());
    }
    parts.join("; ")
}

/// Lines done and planned for the bar, `None` while the plan's line count is unknown (before
/// the scan starts) or after it ended (the idle status carries no count): the bar then keeps
/// what it showed.
pub fn bar_position(s: &Status) -> Option<(u64, u64)> {
    (s.lines_total > 0).then(|| {
        (
            u64::from(s.lines_done.min(s.lines_total)),
            u64::from(s.lines_total),
        )
    })
}

/// Draws a progress bar from status snapshots until the channel closes. The bar appears
/// once the plan's line count is known (never a full bar of `0/0`), keeps its length when
/// the scan ends (no `7/0`), and log lines are printed above it (see
/// [`crate::telemetry::set_progress_bar`]).
async fn progress(mut rx: watch::Receiver<Status>) {
    if !std::io::stderr().is_terminal() {
        return;
    }
    let mut bar: Option<indicatif::ProgressBar> = None;
    while rx.changed().await.is_ok() {
        let s = rx.borrow_and_update().clone();
        let Some((pos, len)) = bar_position(&s) else {
            continue;
        };
        let b = bar.get_or_insert_with(|| {
            let b = indicatif::ProgressBar::new(u64::from(s.lines_total));
            b.set_style(
                indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} lines done  {msg}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            crate::telemetry::set_progress_bar(Some(b.clone()));
            b
        });
        b.set_length(len);
        b.set_position(pos);
        b.set_message(progress_message(&s));
    }
    crate::telemetry::set_progress_bar(None);
    if let Some(b) = bar {
        b.finish_and_clear();
    }
}

/// Runs one scan in the foreground on `station`; SIGINT/SIGTERM interrupt it resumably.
pub async fn run_foreground(
    station: &mut SerialStation,
    settings: &RunSettings,
    request: ScanRequest,
) -> Outcome {
    run_foreground_locked(station, settings, request, None).await
}

/// Takes the station's lock for the life of the process (exit 69 when another process holds
/// the output directory or a device, naming it), then sweeps the leftovers of interrupted
/// writes from the output directory.
///
/// The device locks go to the system's lock directory, unless `SURFSCAN_TEST_LOCK_DIR` names
/// another: the end-to-end tests run many simulated stations on one machine, whose
/// pseudo-terminal numbers are reused as soon as a simulated device is unplugged, so each
/// station gets its own lock directory, as separate machines would have. Nothing else sets
/// it.
pub fn lock_station(config: &Config, command: &str) -> Result<Arc<StationLock>, CliError> {
    let devices = [
        Path::new(&config.instrument.port),
        Path::new(&config.stage.port),
    ];
    let lock = StationLock::acquire(command, &config.output.dir, &devices, &device_lock_dir())
        .map_err(|e| match e {
            LockError::Held { .. } => CliError::new(Exit::Unavailable, e.to_string()),
            LockError::Io { .. } => CliError::new(Exit::Io, e.to_string()),
        })?;
    lock.sweep_leftovers();
    Ok(Arc::new(lock))
}

/// Keeps the scan id in the station's lock up to date from the status, until it closes.
pub async fn record_scan_in_lock(lock: Arc<StationLock>, mut status: watch::Receiver<Status>) {
    loop {
        let id = status.borrow_and_update().scan_id.clone();
        lock.set_scan(id.as_deref());
        if status.changed().await.is_err() {
            break;
        }
    }
}

/// [`run_foreground`], recording the scan in the station's `lock` when given.
pub async fn run_foreground_locked(
    station: &mut SerialStation,
    settings: &RunSettings,
    request: ScanRequest,
    lock: Option<Arc<StationLock>>,
) -> Outcome {
    let (_cmd_tx, cmd_rx) = mpsc::channel(8);
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let (status_tx, status_rx) = watch::channel(Status::idle());
    if let Some(lock) = lock {
        tokio::spawn(record_scan_in_lock(lock, status_rx.clone()));
    }
    let bar = tokio::spawn(progress(status_rx));
    let hangups = tokio::spawn(ignore_hangups(
        "the scan goes on; SIGTERM (kill PID) or Ctrl-C in a terminal interrupts it resumably",
    ));
    let signals = tokio::spawn(async move {
        use tokio::signal::unix::{signal, SignalKind};
        let (Ok(mut term), Ok(mut int)) = (
            signal(SignalKind::terminate()),
            signal(SignalKind::interrupt()),
        ) else {
            return;
        };
        tokio::select! {
            _ = term.recv() => {}
            _ = int.recv() => {}
        }
        tracing::warn!("signal received: abandoning the current line; the scan stays resumable");
        let _ = shutdown_tx.send(true);
    });
    let mut ctl = Control::new(cmd_rx, shutdown_rx, status_tx);
    let outcome = run_scan(station, &mut ctl, settings, request).await;
    drop(ctl);
    signals.abort();
    hangups.abort();
    let _ = bar.await;
    outcome
}

/// Takes SIGHUP for as long as it runs, logging each with `then`, instead of letting it end
/// the process. A foreground scan gets one when the terminal or SSH session it was started
/// from goes away: the instrument and the stage are mid-scan, and nobody is left to resume
/// it, so it goes on (its output is dropped, [`super::console`]). The daemon reads its
/// configuration only at start, so a reload request changes nothing either.
pub async fn ignore_hangups(then: &'static str) {
    use tokio::signal::unix::{signal, SignalKind};
    let Ok(mut hangup) = signal(SignalKind::hangup()) else {
        tracing::warn!("cannot watch SIGHUP: a hang-up of the terminal would end the process");
        return;
    };
    while hangup.recv().await.is_some() {
        tracing::warn!(
            "SIGHUP received (a terminal or session hung up, or a reload request): {then}"
        );
    }
}

/// Runs `surfscan scan`.
pub fn run(args: Args) -> Result<(), CliError> {
    let (config, config_hash) = load_config(&args.config)?;
    // A port that can never be a serial device (a directory, a regular file) is a
    // configuration to correct, as `check-config` says, not a scan that failed.
    super::check_config::check_ports(&config).map_err(|e| {
        CliError::new(
            Exit::Config,
            format!("config {}: {e}", args.config.display()),
        )
    })?;
    let lock = lock_station(&config, "scan")?;
    refuse_if_daemon(&config)?;
    let hooks = TestHooks::from_env().map_err(|e| CliError::new(Exit::Usage, e))?;
    let mut station = SerialStation::new(config.instrument.clone(), config.stage.clone())
        .map_err(|e| CliError::new(Exit::Config, e))?;
    let request = decide_request(
        &config,
        args.specimen,
        args.operator,
        args.notes,
        start_mode(args.resume, args.new),
        Peer::this_process(),
    )?
    .commit()?;
    let settings = run_settings(&config, config_hash, hooks)?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::new(Exit::Failed, format!("cannot start the runtime: {e}")))?;
    let outcome = rt.block_on(run_foreground_locked(
        &mut station,
        &settings,
        request,
        Some(lock),
    ));
    outcome_result(&outcome)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scanning() -> Status {
        let mut s = Status::idle();
        s.state = State::Scanning;
        s.scan_id = Some("S1".into());
        s.lines_done = 7;
        s.lines_total = 31;
        s.current_line = Some(8);
        s.eta_s = Some(750.0);
        s.last_ra_um = Some(0.452_149_8);
        s
    }

    #[test]
    fn the_result_summary_gives_lines_ra_sa_and_the_verdict() {
        let report = serde_json::json!({
            "lines": [{"Ra_um": 0.41234}, {"Ra_um": 0.5}, {"Ra_um": 0.45}],
            "scan": {"lines_planned": 31},
            "surface": {"Sa_um": 0.4444444},
            "surface_grid": {"Sa_um": 0.43},
            "between_lines": {"summary": "the model between lines is supported by the data"},
        });
        let s = result_summary(&report);
        assert_eq!(s[0], ("lines", "3 of 31 planned characterised".to_string()));
        assert_eq!(
            s[1],
            (
                "Ra",
                "0.4123 … 0.5000 µm (mean 0.4541 µm, s.d. 0.04397 µm)".to_string()
            )
        );
        assert_eq!(
            s[2],
            (
                "Sa",
                "0.4444 µm (model), 0.4300 µm (measured grid)".to_string()
            )
        );
        assert_eq!(
            s[3],
            (
                "model",
                "the model between lines is supported by the data".to_string()
            )
        );
        // Nothing characterised: only the count.
        assert_eq!(result_summary(&serde_json::json!({})).len(), 1);
    }

    #[test]
    fn the_bar_waits_for_the_plan_and_keeps_its_length_at_the_end() {
        assert_eq!(bar_position(&Status::idle()), None);
        assert_eq!(bar_position(&scanning()), Some((7, 31)));
        // The idle status published when the scan ends: no `7/0`.
        let mut end = Status::idle();
        end.lines_done = 7;
        assert_eq!(bar_position(&end), None);
    }

    #[test]
    fn the_message_has_a_readable_eta_only_while_scanning() {
        assert_eq!(
            progress_message(&scanning()),
            "ETA 12 min 30 s; last Ra 0.4521 µm"
        );
        let mut s = scanning();
        s.eta_s = Some(20.0);
        assert!(
            progress_message(&s).starts_with("ETA 20 s;"),
            "{}",
            progress_message(&s)
        );
        s.state = State::Paused;
        let m = progress_message(&s);
        assert!(!m.contains("ETA"), "{m}");
        assert!(m.contains("paused"), "{m}");
    }
}
