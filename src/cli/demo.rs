//! `surfscan demo`: a complete simulated scan on a machine without hardware. The simulator
//! runs in-process (an SJ-210 and a GRBL y stage on pseudo-terminals of their own, replaying
//! 31 windows of a real Mitutoyo roughness profile, time-scaled), and the scan runs against
//! them through the real serial code path — transport, codecs, drivers, motion policy, the
//! runner, durable storage, fit, IGES and the report — exactly as on a station. The
//! configuration written for it (`DIR/demo.toml`) is a working station configuration with
//! the simulator's links as ports. The scan is made for a recipe (`DIR/recipes/demo.toml`)
//! whose specification has one limit the demo's surface meets and one it does not: the demo
//! shows the verdict with its reasons, and exits 0 when its scan completes, whatever the
//! verdict.
//!
//! Layer 5 (composition): the simulator crate, config, station, runner. Built with the
//! default `sim` feature; a station build (`--no-default-features`) leaves it out.

use super::scan::{outcome_result, run_foreground, with_recipe};
use super::station::load_config;
use super::{CliError, Exit};
use crate::scan::outcome::ScanRequest;
use crate::scan::station::SerialStation;
use crate::scan::testhooks::TestHooks;
use std::path::{Path, PathBuf};
use std::time::Duration;
use surfscan_sim::grbl::{GrblSimConfig, StageShared};
use surfscan_sim::{InstrumentConfig, ProfileSet, SimEvent, Simulator};

/// Arguments of `surfscan demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory for the scan, its surface, report and plots (created if missing).
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// Simulated time runs this many times faster than real time (1 = a real station's pace).
    #[arg(long, default_value_t = 50.0)]
    pub speed_up: f64,
}

/// y of the first line in the demo (GRBL machine coordinates are negative after homing).
const Y_START_MM: f64 = -20.0;

/// The demo's recipe: the station's plan, and a drawing's two limits for the replayed
/// profiles (Ra about 3 µm, Rz about 16 µm per line): the 16 % rule on Ra, which the surface
/// meets, and the max rule on Rz, which it does not. The replayed R profiles (λc 2.5 mm as
/// the instrument recorded) are evaluated as one sampling length, and the limits say so
/// (`Ra1`, `Rz1`): with the default five the verdict would be not decidable.
pub const DEMO_RECIPE: &str = r#"# Written by `surfscan demo`: a recipe whose specification the demo's surface meets in
# part. See the operator guide for every key.
description = "demo part: Ra within its limit, Rz beyond its max"

[plan]
lines = 31
y-step-mm = 0.01

[specification]
limits = ["Ra1 6.3", "Rz1 max 12.5"]
"#;

/// The demo's additions to its station configuration: the recipe directory and a
/// calibration uncertainty, so that the verdict and the means carry the instrument's share.
fn demo_station_extras(recipes: &Path) -> String {
    format!(
        "\n[traceability]\n# The expanded (k = 2) relative uncertainty of a calibration certificate.\ncalibration-uncertainty-pct = 3.0\n\n[jobs]\nrecipes = {:?}\n",
        recipes.display().to_string()
    )
}

/// The station configuration of the demo: the simulator's links as ports.
pub fn demo_config(instrument: &Path, stage: &Path, out: &Path) -> String {
    format!(
        r#"# Written by `surfscan demo`: a station configuration whose ports are the simulator's
# pseudo-terminals. See config/surfscan.toml for every key.
[instrument]
port = {instrument:?}
model = "sj210"
baud = 38400
# The replayed profiles are sampled every 1.5 um.
pitch-x-um = 1.5

[instrument.timeouts]
# Simulated time runs faster than real time: poll the status often enough to see it.
poll-interval-ms = 10

[instrument.commands]
# The SJ-210 manual documents no profile read-out; these are the SJ-410's RDEVA commands
# without its profile selector, which the simulated SJ-210 answers (see config/surfscan.toml).
profile-total = "RDEVA00"
profile-block = "RDEVA{{n}}"

[stage]
port = {stage:?}
protocol = "grbl"
steps-per-mm = 400.0
soft-limit-min-mm = -100.0
soft-limit-max-mm = 0.0
backlash-mm = 0.05
settle-ms = 5
poll-interval-ms = 200
home-on-start = true

[scan]
lines = 31
y-start-mm = {Y_START_MM:?}
y-step-mm = 0.01

[output]
dir = {out:?}

[control]
socket = {sock:?}

[report]
# The printed report's header and signature block.
lab = "surfscan demonstration"
address = "A simulated SJ-210 and y stage\nNo part was measured"
paper = "A4"
signatures = ["Measured by", "Approved by"]
"#,
        instrument = instrument.display().to_string(),
        stage = stage.display().to_string(),
        out = out.display().to_string(),
        // Beside the scans' tree, never inside it (check-config refuses that).
        sock = demo_socket(out).display().to_string(),
    )
}

/// The control socket of the demo's station: beside its output directory `out`
/// (`demo-out.control.sock`), outside the scans' tree.
pub fn demo_socket(out: &Path) -> std::path::PathBuf {
    let mut name = out.file_name().unwrap_or_default().to_os_string();
    name.push(".control.sock");
    out.with_file_name(name)
}

/// Runs `surfscan demo`.
pub fn run(args: Args) -> Result<(), CliError> {
    if !(args.speed_up.is_finite() && args.speed_up >= 1.0) {
        return Err(CliError::new(
            Exit::Usage,
            format!("--speed-up {} must be at least 1", args.speed_up),
        ));
    }
    let out = &args.out;
    let sim_dir = out.join("sim");
    std::fs::create_dir_all(&sim_dir).map_err(|e| {
        CliError::new(
            Exit::Io,
            format!("cannot create {}: {e}", sim_dir.display()),
        )
    })?;
    let out = std::fs::canonicalize(out)
        .map_err(|e| CliError::new(Exit::Io, format!("cannot resolve {}: {e}", out.display())))?;
    let sim_dir = out.join("sim");
    let instrument_link = sim_dir.join("sj210");
    let stage_link = sim_dir.join("ystage");
    let config_path = out.join("demo.toml");
    let recipes = out.join("recipes");
    let write = |path: &Path, text: &str| {
        crate::atomic::write_atomically(path, |w| std::io::Write::write_all(w, text.as_bytes()))
            .map_err(|e| CliError::new(Exit::Io, format!("cannot write {}: {e}", path.display())))
    };
    std::fs::create_dir_all(&recipes).map_err(|e| {
        CliError::new(
            Exit::Io,
            format!("cannot create {}: {e}", recipes.display()),
        )
    })?;
    write(&recipes.join("demo.toml"), DEMO_RECIPE)?;
    write(
        &config_path,
        &(demo_config(&instrument_link, &stage_link, &out) + &demo_station_extras(&recipes)),
    )?;
    let (config, config_hash) = load_config(&config_path)?;
    let (config, recipe) = with_recipe(&config, Some("demo"), None)?;
    let mut station = SerialStation::new(config.instrument.clone(), config.stage.clone())
        .map_err(|e| CliError::new(Exit::Config, e))?;
    let settings = super::station::run_settings(&config, config_hash, TestHooks::none())?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| CliError::new(Exit::Failed, format!("cannot start the runtime: {e}")))?;
    let outcome = rt.block_on(async {
        let mut profiles = ProfileSet::bundled()
            .map_err(|e| CliError::new(Exit::Failed, format!("bundled profiles: {e}")))?;
        profiles.y_first_mm = Y_START_MM;
        let instrument = InstrumentConfig {
            time_scale: 1.0 / args.speed_up,
            ..InstrumentConfig::default()
        };
        let grbl = GrblSimConfig {
            steps_per_mm: 400.0,
            max_travel_mm: 100.0,
            backlash_mm: 0.02,
            time_scale: args.speed_up,
            ..GrblSimConfig::default()
        };
        let sim = Simulator::new(&instrument_link)
            .instrument(instrument)
            .profiles(profiles)
            .baud(38400 * args.speed_up.min(100.0) as u32)
            .grbl_stage(&stage_link, grbl, StageShared::new());
        let mut handle = sim
            .start()
            .map_err(|e| CliError::new(Exit::Failed, format!("cannot start the simulator: {e}")))?;
        match tokio::time::timeout(Duration::from_secs(10), handle.next_event()).await {
            Ok(Some(SimEvent::Ready(_))) => {}
            other => {
                return Err(CliError::new(
                    Exit::Failed,
                    format!("the simulator did not become ready: {other:?}"),
                ))
            }
        }
        say!(
            "simulator: SJ-210 on {}, GRBL stage on {}; configuration {}",
            instrument_link.display(),
            stage_link.display(),
            config_path.display()
        );
        let request = ScanRequest::New {
            specimen: "demo: Mitutoyo R profile windows".into(),
            operator: "surfscan demo".into(),
            notes: "simulated station replaying real profiles".into(),
            peer: None,
            job: recipe.map(|r| Box::new(r.new_job(None))),
        };
        let outcome = run_foreground(&mut station, &settings, request).await;
        handle.shutdown().await;
        Ok(outcome)
    })?;
    // The demo shows the verdict; a part that does not conform is what it is made to show.
    match outcome_result(&outcome) {
        Err(e) if e.exit == Exit::DoesNotConform => Ok(()),
        r => r,
    }
}
