//! The station's configuration turned into what the commands that run it need: the file
//! loaded and hashed, the plan and the runner's settings, the station's lock, and the
//! process-wide signal habits (a hang-up ignored). Shared by `scan`, `daemon`, `demo` and
//! `check-config`, so that none of them imports another subcommand's file.
//!
//! Layer 5 (composition): depends on [`crate::config`], [`crate::report`] (the
//! characterisation run when a scan completes), [`crate::scan`]'s settings and
//! [`crate::station_lock`].

use super::{CliError, Exit};
use crate::config::{Config, ConfigError};
use crate::report::{ScanAnalysisOptions, ScanCharacteriser};
use crate::scan::plan::{AnalysisPlan, Plan};
use crate::scan::policy::Backoff;
use crate::scan::settings::RunSettings;
use crate::scan::status::Status;
use crate::scan::testhooks::TestHooks;
use crate::station_lock::{self, LockError, StationLock};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

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
        analysis: Some(analysis_of(config)),
    })
}

/// The characterisation of `[analysis]` and `[contact]`, as a scan's plan freezes it.
pub fn analysis_of(config: &Config) -> AnalysisPlan {
    let a = &config.analysis;
    AnalysisPlan {
        curves: a.curves,
        levels: a.levels,
        lambda_c_mm: a.lambda_c_mm,
        no_filter: a.no_filter,
        spikes: a.spike_options(),
        exclude_spikes: a.outliers == crate::config::OutlierPolicy::Exclude,
        holdout_threshold: a.holdout_threshold,
        material_ratio: a.material_ratio,
        contact: config.contact.enabled.then(|| config.contact.clone()),
    }
}

/// The runner's settings for a station: the plan and session settings of the configuration,
/// a frozen copy of it and its hash, the test hooks, and the characterisation of `[analysis]`
/// and `[contact]`
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
        options: ScanAnalysisOptions::default().with_frozen(&analysis_of(config)),
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
        longest_effect: longest_effect(config),
        metrics_file: config.metrics.file.clone(),
        config: serde_json::to_value(config).unwrap_or_default(),
        config_hash,
        hooks: Arc::new(hooks),
        characterise: Some(Arc::new(characterise)),
    })
}

/// The longest one device operation of the station can take: a trace over the drive's whole
/// range with four read-outs of the longest profile at the instrument's baud, or the stage's
/// home or moves with all their attempts; and a minute for the conversation around them.
pub fn longest_effect(config: &Config) -> Duration {
    let trace = crate::sj210::timing::longest_trace(
        config.instrument.client_options().speeds,
        config.instrument.baud,
        crate::scan::opening::LONGEST_PROFILE_POINTS,
    );
    let stage = config.stage.policy_config().map_or(Duration::ZERO, |p| {
        p.home_timeout
            .max(p.move_timeout * p.max_attempts.saturating_add(1))
    });
    trace.max(stage) + Duration::from_secs(60)
}

/// The request with a recipe's job given to a new scan (a resumed scan keeps its own).
pub fn with_job(
    request: crate::scan::outcome::ScanRequest,
    job: Option<Box<crate::scan::outcome::NewJob>>,
) -> crate::scan::outcome::ScanRequest {
    use crate::scan::outcome::ScanRequest;
    match request {
        ScanRequest::New {
            specimen,
            operator,
            notes,
            peer,
            job: None,
        } => ScanRequest::New {
            specimen,
            operator,
            notes,
            peer,
            job,
        },
        other => other,
    }
}

/// Why a start with recipe `recipe` must not go ahead with `decision`: it would resume or
/// continue a scan of another recipe, or of the station's plan, under this recipe's name.
/// `command` names the start for the way out.
pub fn recipe_conflict(
    decision: &crate::scan::choice::Decision,
    recipe: &str,
    command: &str,
) -> Option<String> {
    use crate::scan::choice::Decision;
    use crate::scan::journal::{read_journal, ResumeState, JOURNAL_FILE};
    let (Decision::Resume(dir) | Decision::Continue(dir)) = decision else {
        return None;
    };
    let path = dir.join(JOURNAL_FILE);
    let of = read_journal(&path)
        .ok()
        .and_then(|r| ResumeState::from_records(&path, &r.records).ok())
        .and_then(|s| s.start.job)
        .map(|j| j.recipe);
    if of.as_deref() == Some(recipe) {
        return None;
    }
    let what = match of {
        Some(r) => format!("of recipe {r}"),
        None => "of the station's plan".to_owned(),
    };
    Some(format!(
        "the unfinished scan {} is {what}, not of recipe {recipe}: finish it first (`{command}` without --recipe resumes it) or give --new to abandon it",
        dir.display()
    ))
}

/// Where the device locks go: [`station_lock::DEVICE_LOCK_DIR`], or the directory
/// `SURFSCAN_TEST_LOCK_DIR` names (see [`lock_station`]).
fn device_lock_dir() -> PathBuf {
    std::env::var_os("SURFSCAN_TEST_LOCK_DIR").map_or_else(
        || PathBuf::from(station_lock::DEVICE_LOCK_DIR),
        PathBuf::from,
    )
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
