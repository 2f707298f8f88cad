//! `surfscan scan`: one scan in the foreground, exactly as the daemon runs it — an
//! unfinished scan of this configuration is resumed first — with a progress bar (line k/N,
//! ETA, the last line's Ra). Ctrl-C abandons the current line and leaves the scan
//! resumable, as SIGTERM does for the daemon. A hang-up (SIGHUP: the terminal or SSH session
//! went away) does not stop it: the scan goes on without its terminal, and what it would have
//! printed is dropped.
//!
//! Exit status: 0 success, 1 the scan failed or was aborted, 2 usage, 3 the scan completed
//! but its characterisation is partial (every line, the IGES and every output that could be
//! made are written; report.json names the sections that could not be made and why), 4 the
//! scan completed and the part does not conform to its recipe's specification, 69 a
//! device is unavailable (or another `scan` or the daemon holds the station: its pid and scan
//! are named), 74 I/O error, 78 bad configuration.
//!
//! The end-of-scan summary prints the result (the verdict against the recipe's specification
//! with each limit's, lines, Ra, Sa) and the verdict on the model
//! between lines (the hold-out of [`crate::metrology::holdout`]), not the residual at the data
//! points, which an interpolant makes zero by construction.
//!
//! Which scan runs is [`crate::scan::choice`]'s decision, as for the daemon.
//!
//! Layer 5 (composition): [`super::station`] (the configuration as the runner's settings, the
//! station's lock), [`super::check_config`]'s port check, the runner, signals, terminal.

use super::start_args::{self, StartChoiceArgs};
use super::station::{
    ignore_hangups, lock_station, recipe_conflict, record_scan_in_lock, run_settings, with_job,
};
use super::{CliError, Exit};
use crate::config::Config;
use crate::panics::spawn_vital;
use crate::publish::Publishers;
use crate::scan::channels::Control;
use crate::scan::choice::{self, Asker};
use crate::scan::command::Peer;
use crate::scan::ending::{End, FailKind};
use crate::scan::outcome::{Outcome, ScanRequest};
use crate::scan::runner::run_scan;
use crate::scan::settings::RunSettings;
use crate::scan::station::SerialStation;
use crate::scan::status::{State, Status};
use crate::scan::testhooks::TestHooks;
use crate::specification::Verdict;
use crate::station_lock::StationLock;
use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Arc;
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
    /// Which scan: resume, new, a recipe.
    #[command(flatten)]
    pub choice: StartChoiceArgs,
}

/// The station's configuration with the recipe's plan and analysis, and the recipe's job for
/// a new scan; the station's own without `--recipe`. A bad recipe is exit 78, an unknown name
/// or a bad `--y-start-mm` exit 2.
pub(super) fn with_recipe(
    config: &Config,
    recipe: Option<&str>,
    y_start_mm: Option<f64>,
) -> Result<(Config, Option<crate::jobs::recipe::Recipe>), CliError> {
    let Some(name) = recipe else {
        return Ok((config.clone(), None));
    };
    let y_start_mm = start_args::y_start_mm(y_start_mm)?;
    let r = crate::jobs::recipe::Recipe::load(&config.jobs.recipes, name, config)?;
    let c = r.config_for(config, y_start_mm)?;
    Ok((c, Some(r)))
}

/// Maps a scan's outcome to the exit status and message of a foreground command.
pub fn outcome_result(outcome: &Outcome) -> Result<(), CliError> {
    let kept = |d: &Option<PathBuf>| match d {
        Some(d) => format!(" (lines kept in {})", d.display()),
        None => String::new(),
    };
    match (&outcome.end, &outcome.outputs, &outcome.dir) {
        (End::Success { .. }, Some(outputs), Some(dir)) => success_summary(dir, outputs),
        (End::Abort { .. }, _, Some(dir)) => Err(CliError::new(
            Exit::Failed,
            format!(
                "scan aborted; the lines traced are kept in {}",
                dir.display()
            ),
        )),
        (End::Abort { .. }, _, None) => Err(CliError::new(
            Exit::Failed,
            "scan not started: aborted before the scan started".to_owned(),
        )),
        (End::Shutdown, _, Some(dir)) => Err(CliError::new(
            Exit::Failed,
            format!(
                "scan interrupted; run the same command again to resume it ({})",
                dir.display()
            ),
        )),
        (End::Shutdown, _, None) => Err(CliError::new(
            Exit::Failed,
            "scan not started: shut down before the scan started".to_owned(),
        )),
        (End::Fail(reason), _, dir) => {
            let exit = match reason.kind() {
                FailKind::Scan => Exit::Failed,
                FailKind::Unavailable => Exit::Unavailable,
                FailKind::Io => Exit::Io,
                FailKind::Internal => Exit::Internal,
            };
            let msg = match dir {
                Some(_) => format!("scan failed: {reason}{}", kept(dir)),
                None => format!("scan not started: {reason}"),
            };
            Err(CliError::new(exit, msg))
        }
        (End::Success { .. }, _, dir) => Err(CliError::new(
            Exit::Io,
            format!(
                "internal: a scan that succeeded without its outputs{}",
                kept(dir)
            ),
        )),
    }
}

/// What a completed scan prints: the files it wrote and its result in a few lines (the verdict
/// and each limit's first, for a recipe with limits); exit 4 when the part does not conform,
/// else 3 when its characterisation is partial.
fn success_summary(
    dir: &std::path::Path,
    outputs: &crate::scan::outputs::Outputs,
) -> Result<(), CliError> {
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
        let svg = rk.iter().filter(|p| p.extension() == Some("svg".as_ref()));
        let lines = svg.count();
        let each = if rk.len() > lines {
            "a PNG and an SVG"
        } else {
            "an SVG"
        };
        say!(
            "  file     {}/ ({lines} Rk construction plots, {each} per line)",
            dir.display()
        );
    }
    if let Some(e) = &outputs.characterisation_error {
        say!(
            "  characterisation failed: {e}; the report holds the fit and the instrument's results"
        );
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
        .and_then(crate::report::render::html::verdict)
        .is_none()
    {
        say!("  model    {}", outputs.verdict);
    }
    let verdict = report
        .as_ref()
        .and_then(|r| r["specification"]["verdict"].as_str().map(str::to_owned));
    if verdict.as_deref() == Some(Verdict::DoesNotConform.as_str()) {
        Err(CliError::new(
            Exit::DoesNotConform,
            format!(
                "scan complete; the part does not conform to its specification (report.json's specification names the limits and lines): {}",
                outputs.report.display()
            ),
        ))
    } else if outputs.characterisation_complete {
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

/// The result of a characterised scan in a few lines, from its `report.json` (see
/// [`crate::report::render::html::result_summary`]).
pub fn result_summary(report: &serde_json::Value) -> Vec<(&'static str, String)> {
    crate::report::render::html::result_summary(report)
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
    run_foreground_locked(station, settings, request, None, None).await
}

/// [`run_foreground`], recording the scan in the station's `lock` when given, and publishing
/// its status and events as `config` asks ([`crate::publish`]), as the daemon would.
pub async fn run_foreground_locked(
    station: &mut SerialStation,
    settings: &RunSettings,
    request: ScanRequest,
    lock: Option<Arc<StationLock>>,
    config: Option<&Config>,
) -> Outcome {
    let (_cmd_tx, cmd_rx) = mpsc::channel(8);
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let (status_tx, status_rx) = watch::channel(Status::idle());
    if let Some(lock) = lock {
        spawn_vital(
            "the station lock's record",
            record_scan_in_lock(lock, status_rx.clone()),
        );
    }
    let bar = spawn_vital("the progress bar", progress(status_rx));
    let hangups = spawn_vital(
        "the SIGHUP handler",
        ignore_hangups(
            "the scan goes on; SIGTERM (kill PID) or Ctrl-C in a terminal interrupts it resumably",
        ),
    );
    let signals = spawn_vital("the SIGTERM handler", async move {
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
    let publishers = config.map(|c| Publishers::start(c, &status_tx, None));
    let mut ctl = Control::new(cmd_rx, shutdown_rx, status_tx);
    ctl.events = publishers.as_ref().and_then(Publishers::sender);
    ctl.metrics = publishers.as_ref().and_then(Publishers::scan_metrics);
    let outcome = run_scan(station, &mut ctl, settings, request).await;
    drop(ctl);
    if let Some(p) = publishers {
        p.finish(std::time::Duration::from_secs(4)).await;
    }
    signals.abort();
    hangups.abort();
    let _ = bar.await;
    outcome
}

/// Runs `surfscan scan`.
pub fn run(args: Args) -> Result<(), CliError> {
    // A port that can never be a serial device (a directory, a regular file) is a
    // configuration to correct, as `check-config` says, not a scan that failed.
    let (config, config_hash, _) = super::check_config::load_checked(&args.config)?;
    let lock = lock_station(&config, "scan")?;
    refuse_if_daemon(&config)?;
    let hooks = TestHooks::from_env().map_err(|e| CliError::new(Exit::Usage, e))?;
    let mut station = SerialStation::new(config.instrument.clone(), config.stage.clone())
        .map_err(|e| CliError::new(Exit::Config, e))?;
    let recipe = args.choice.recipe.as_deref();
    let (run_config, recipe) = with_recipe(&config, recipe, args.choice.y_start_mm)?;
    let choice = choice::choose(
        &config.output.dir,
        Asker::Operator(args.choice.mode()),
        Peer::this_process(),
        (args.specimen, args.operator, args.notes),
    )
    .map_err(CliError::from)?;
    if let Some(r) = &recipe {
        if let Some(why) = recipe_conflict(&choice.decision, &r.name, "surfscan scan") {
            return Err(CliError::new(Exit::Usage, why));
        }
    }
    let request = choice.commit().map_err(CliError::from)?.ok_or_else(|| {
        CliError::new(Exit::Failed, "internal: an operator's start chose nothing")
    })?;
    let request = with_job(request, recipe.map(|r| Box::new(r.new_job(None))));
    let settings = run_settings(&run_config, config_hash, hooks)?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::new(Exit::Failed, format!("cannot start the runtime: {e}")))?;
    let outcome = rt.block_on(run_foreground_locked(
        &mut station,
        &settings,
        request,
        Some(lock),
        Some(&config),
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
