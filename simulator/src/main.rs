//! The `surfscan-sim` binary: a thin command line over the `surfscan_sim` library. Prints one
//! JSON line per simulator event (the first is `{"event":"ready",...}` once the links can be
//! opened) and runs until SIGTERM, SIGINT or, when its standard input is a pipe or a
//! terminal, that input closing (so a test harness stops it by closing the pipe). Standard
//! input that can never deliver a byte (`/dev/null`, a file, as under systemd or `nohup`)
//! is not watched. The reason it stops is printed on standard error. With `--write-config
//! FILE` it first writes the station configuration for its own links
//! ([`surfscan_sim::station_config`]).

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use clap::{Parser, ValueEnum};
use surfscan_sim::grbl::{GrblSimConfig, StageFaultSpec, StageShared};
use surfscan_sim::instrument::{ReadoutForm, ResultLayout};
use surfscan_sim::line::Mismatch;
use surfscan_sim::replay::Transcript;
use surfscan_sim::station_config::{station_config, SimStage, StationConfigRequest};
use surfscan_sim::zaber::ZaberSimConfig;
use surfscan_sim::{Battery, FaultSpec, InstrumentConfig, Model, ProfileSet, Simulator};
use tokio::io::AsyncReadExt;

#[derive(Debug, Clone, Copy, PartialEq, ValueEnum)]
enum StageProtocolArg {
    Grbl,
    Zaber,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum LayoutArg {
    Export,
    Manual,
}

fn parse_readout_form(s: &str) -> Result<ReadoutForm, String> {
    match s {
        "RDEVA" => Ok(ReadoutForm::Only(None)),
        "RDEVA0" => Ok(ReadoutForm::Only(Some(0))),
        "RDEVA1" => Ok(ReadoutForm::Only(Some(1))),
        _ => Err(format!("{s:?} is not RDEVA, RDEVA0 or RDEVA1")),
    }
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum LineCheckArg {
    Silent,
    Noise,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum ModelArg {
    Sj210,
    Sj410,
}

/// Simulated Mitutoyo SJ-210 / SJ-410 and GRBL / Zaber y stage over pseudo-terminals.
#[derive(Debug, Parser)]
#[command(name = "surfscan-sim", version)]
struct Args {
    /// Path at which to link the instrument's pty (e.g. /tmp/sj210).
    #[arg(long, required_unless_present = "stage_link")]
    instrument_link: Option<PathBuf>,
    /// Path at which to link the simulated stage's pty (e.g. /tmp/ystage).
    #[arg(long, requires = "stage_protocol")]
    stage_link: Option<PathBuf>,
    /// Protocol of the simulated stage.
    #[arg(long, value_enum, requires = "stage_link")]
    stage_protocol: Option<StageProtocolArg>,
    /// Backlash between motor and carriage of the simulated stage, µm.
    #[arg(long, default_value_t = 0.0)]
    stage_backlash_um: f64,
    /// GRBL: the home switch is at the bottom of the travel and `$23=2` (Y homes toward
    /// negative); the stage powers up 50 mm above it.
    #[arg(long)]
    stage_home_at_bottom: bool,
    /// GRBL: firmware built with `HOMING_FORCE_SET_ORIGIN` (`Z` in `[OPT:…]`): homing sets
    /// the counter to 0.
    #[arg(long)]
    stage_force_origin: bool,
    /// Stage fault, KIND[@MS] queued MS ms after ready (repeatable); KIND is reset-banner,
    /// alarm2, error15, reject, stall, position-lost, silence or vanish.
    #[arg(long = "stage-fault")]
    stage_faults: Vec<StageFaultSpec>,
    /// Emulated model.
    #[arg(long, value_enum, default_value = "sj210")]
    model: ModelArg,
    /// Answer RDEVA with NG030, as the SJ-210 manual documents.
    #[arg(long)]
    no_profile_readout: bool,
    /// Answer only this RDEVA form and NG031 to the others: `RDEVA` (no selector byte),
    /// `RDEVA0` or `RDEVA1`. Default: the model's own form.
    #[arg(long, value_parser = parse_readout_form)]
    readout_form: Option<ReadoutForm>,
    /// How RDRES prints values: `export` (a sign position, the number left-justified, as
    /// Mitutoyo's PC export shows them) or `manual` (right-justified, the manual's example).
    #[arg(long, value_enum, default_value = "export")]
    result_layout: LayoutArg,
    /// Serve the whole bundled Mitutoyo R profile (6664 points at 1.5 µm) on every trace,
    /// under the conditions it was recorded with (λc 2.5 mm, N 4); overrides
    /// --sampling-lengths and --profiles.
    #[arg(long)]
    mitutoyo_r: bool,
    /// Profiles to serve: `x_mm,z_um` CSV, `profile,y_mm,x_mm,z_um` CSV, or a header-less grid
    /// CSV (needs --pitch-x-mm). Default: the bundled 31 windows of a Mitutoyo R profile.
    #[arg(long)]
    profiles: Option<PathBuf>,
    /// x pitch of a grid CSV, mm.
    #[arg(long)]
    pitch_x_mm: Option<f64>,
    /// Multiplies trace, return, transfer and stage motion times (1 = real time, 0 =
    /// instantaneous).
    #[arg(long, default_value_t = 1.0)]
    time_scale: f64,
    /// Baud rate used for pacing replies.
    #[arg(long, default_value_t = 38400)]
    baud: u32,
    /// Decimals of heights in RDEVA replies.
    #[arg(long, default_value_t = 3)]
    decimals: u8,
    /// Measuring speed, mm/s (the trace time is traverse length / speed × time scale).
    #[arg(long, default_value_t = 0.5)]
    speed_mm_s: f64,
    /// Number of sampling lengths reported by RDCON and used for Rz (0 = arbitrary length).
    #[arg(long, default_value_t = 0)]
    sampling_lengths: u8,
    /// Stop at the end of travel (status 005) instead of returning.
    #[arg(long)]
    no_auto_return: bool,
    /// Answer result and profile reads while the drive returns (status 002) instead of
    /// refusing them NG011 (busy) until it is back.
    #[arg(long)]
    reads_during_return: bool,
    /// Answer only a host whose line speed is --baud, as an instrument set to one rate does;
    /// a host at another rate gets `silent` (nothing) or `noise` (bytes that are no reply).
    #[arg(long, value_enum)]
    line_check: Option<LineCheckArg>,
    /// Fault to inject, KIND[:ARG]@COMMAND[%TRACE][#N][xK] or battery:low|abnormal (repeatable);
    /// busy:MS, noeol:MS and flood:MS open a time window at the matching frame.
    #[arg(long = "fault")]
    faults: Vec<FaultSpec>,
    /// Replay this recorded transcript (v1) instead of emulating.
    #[arg(long, conflicts_with = "write_config")]
    transcript: Option<PathBuf>,
    /// Write a surfscan station configuration for these links to FILE before serving (its
    /// scans go to `scans/` and its control socket to `control.sock` beside FILE); the
    /// served profiles are placed on its scan's y grid.
    #[arg(long, value_name = "FILE", requires_all = ["instrument_link", "stage_link"])]
    write_config: Option<PathBuf>,
}

/// The simulator to start and, with `--write-config`, the configuration to write first.
struct Built {
    sim: Simulator,
    config: Option<(PathBuf, String)>,
}

/// An absolute form of `p` (the configuration is read from another working directory).
fn absolute(p: &std::path::Path) -> Result<PathBuf, String> {
    std::path::absolute(p).map_err(|e| format!("cannot resolve {}: {e}", p.display()))
}

fn build(args: Args, shared: &Arc<StageShared>) -> Result<Built, String> {
    if !(args.time_scale >= 0.0 && args.time_scale.is_finite()) {
        return Err(format!(
            "--time-scale {} must be a finite number ≥ 0",
            args.time_scale
        ));
    }
    if args.decimals > 6 {
        return Err(format!("--decimals {} must be 0–6", args.decimals));
    }
    if !(args.speed_mm_s > 0.0 && args.speed_mm_s.is_finite()) {
        return Err(format!(
            "--speed-mm-s {} must be a positive number",
            args.speed_mm_s
        ));
    }
    if args.sampling_lengths > 20 {
        return Err(format!(
            "--sampling-lengths {} must be 0–20",
            args.sampling_lengths
        ));
    }
    let defaults = InstrumentConfig::default();
    let mut cfg = InstrumentConfig {
        model: match args.model {
            ModelArg::Sj210 => Model::Sj210,
            ModelArg::Sj410 => Model::Sj410,
        },
        profile_readout: !args.no_profile_readout,
        readout_form: args.readout_form.unwrap_or_default(),
        result_layout: match args.result_layout {
            LayoutArg::Export => ResultLayout::Export,
            LayoutArg::Manual => ResultLayout::Manual,
        },
        decimals: args.decimals,
        auto_return: !args.no_auto_return,
        reads_during_return: args.reads_during_return,
        time_scale: args.time_scale,
        measure_speed_mm_s: args.speed_mm_s,
        conditions: surfscan_sim::instrument::Conditions {
            sampling_lengths: if args.mitutoyo_r {
                4
            } else {
                args.sampling_lengths
            },
            ..defaults.conditions.clone()
        },
        ..defaults
    };
    let mut sim = match &args.instrument_link {
        Some(l) => Simulator::new(l),
        None => Simulator::without_instrument(),
    }
    .baud(args.baud);
    if let Some(check) = args.line_check {
        sim = sim.line_check(match check {
            LineCheckArg::Silent => Mismatch::Silent,
            LineCheckArg::Noise => Mismatch::Noise,
        });
    }
    if !(args.stage_backlash_um >= 0.0 && args.stage_backlash_um.is_finite()) {
        return Err(format!(
            "--stage-backlash-um {} must be a finite number ≥ 0",
            args.stage_backlash_um
        ));
    }
    if (args.stage_home_at_bottom || args.stage_force_origin)
        && args.stage_protocol != Some(StageProtocolArg::Grbl)
    {
        return Err(
            "--stage-home-at-bottom and --stage-force-origin describe a GRBL board; give them with --stage-protocol grbl".into(),
        );
    }
    // The instrument's time scale multiplies durations; the stages' is a speed-up factor.
    let speed_up = if args.time_scale > 0.0 {
        1.0 / args.time_scale
    } else {
        1e9
    };
    let mut grbl = None;
    let mut zaber = None;
    if let (Some(link), Some(protocol)) = (&args.stage_link, args.stage_protocol) {
        match protocol {
            StageProtocolArg::Grbl => {
                let defaults = GrblSimConfig::default();
                let cfg = GrblSimConfig {
                    backlash_mm: args.stage_backlash_um / 1000.0,
                    time_scale: speed_up,
                    home_switch_at_negative_end: args.stage_home_at_bottom,
                    force_set_origin: args.stage_force_origin,
                    // As far from the switch as by default, on the side the travel is.
                    start_mm: if args.stage_home_at_bottom {
                        -defaults.start_mm
                    } else {
                        defaults.start_mm
                    },
                    ..defaults
                };
                sim = sim.grbl_stage(link, cfg.clone(), shared.clone());
                grbl = Some(cfg);
            }
            StageProtocolArg::Zaber => {
                let defaults = ZaberSimConfig::default();
                let cfg = ZaberSimConfig {
                    backlash: (args.stage_backlash_um * 1000.0 / defaults.nm_per_microstep).round()
                        as i64,
                    time_scale: speed_up,
                    ..defaults
                };
                sim = sim.zaber_stage(link, cfg.clone(), shared.clone());
                zaber = Some(cfg);
            }
        }
    }
    for f in args.faults {
        match f {
            FaultSpec::Wire(w) => sim = sim.fault(w),
            FaultSpec::BatteryLow => cfg.battery = Battery::Low,
            FaultSpec::BatteryAbnormal => cfg.battery = Battery::Abnormal,
        }
    }
    sim = sim.instrument(cfg.clone());
    let profiles = if args.mitutoyo_r {
        Some(ProfileSet::bundled_mitutoyo_r().map_err(|e| e.to_string())?)
    } else if let Some(p) = &args.profiles {
        Some(ProfileSet::load(p, args.pitch_x_mm).map_err(|e| e.to_string())?)
    } else {
        None
    };
    let mut config = None;
    if let (Some(file), Some(instrument_link), Some(stage_link)) =
        (&args.write_config, &args.instrument_link, &args.stage_link)
    {
        let profiles = match profiles {
            Some(p) => p,
            None => ProfileSet::bundled().map_err(|e| e.to_string())?,
        };
        let file = absolute(file)?;
        let dir = file.parent().unwrap_or(std::path::Path::new("/"));
        let (instrument_link, stage_link) = (absolute(instrument_link)?, absolute(stage_link)?);
        let (output_dir, control_socket) = (dir.join("scans"), dir.join("control.sock"));
        let stage = match (&grbl, &zaber) {
            (Some(g), _) => SimStage::Grbl(g),
            (None, Some(z)) => SimStage::Zaber(z),
            (None, None) => return Err("--write-config needs --stage-protocol".into()),
        };
        let written = station_config(
            &StationConfigRequest {
                instrument_link: &instrument_link,
                instrument: &cfg,
                baud: args.baud,
                line_check: args.line_check.is_some(),
                stage_link: &stage_link,
                stage,
                output_dir: &output_dir,
                control_socket: &control_socket,
            },
            &profiles,
        )
        .map_err(|e| format!("--write-config: {e}"))?;
        sim = sim.profiles(written.profiles);
        config = Some((file, written.toml));
    } else if let Some(p) = profiles {
        sim = sim.profiles(p);
    }
    if let Some(t) = &args.transcript {
        let text = std::fs::read_to_string(t)
            .map_err(|e| format!("cannot read transcript {}: {e}", t.display()))?;
        let transcript =
            Transcript::parse(&text).map_err(|e| format!("transcript {}: {e}", t.display()))?;
        sim = sim.replay(transcript, args.time_scale);
    }
    Ok(Built { sim, config })
}

/// Writes `text` to `file` whole or not at all (a temporary file beside it, renamed).
fn write_config(file: &std::path::Path, text: &str) -> Result<(), String> {
    let tmp = file.with_extension("toml.tmp");
    std::fs::write(&tmp, text)
        .and_then(|()| std::fs::rename(&tmp, file))
        .map_err(|e| format!("cannot write {}: {e}", file.display()))
}

#[tokio::main]
async fn main() -> ExitCode {
    let args = Args::parse();
    let shared = StageShared::new();
    let stage_faults = args.stage_faults.clone();
    let Built { sim, config } = match build(args, &shared) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("surfscan-sim: {e}");
            return ExitCode::from(2);
        }
    };
    if let Some((file, text)) = config {
        if let Err(e) = write_config(&file, &text) {
            eprintln!("surfscan-sim: {e}");
            return ExitCode::from(1);
        }
        eprintln!(
            "surfscan-sim: station configuration written to {}; run `surfscan scan --config {}`",
            file.display(),
            file.display()
        );
    }
    let mut handle = match sim.start() {
        Ok(h) => h,
        Err(e) => {
            eprintln!("surfscan-sim: {e}");
            return ExitCode::from(1);
        }
    };
    for f in stage_faults {
        // Queued at once, not through a zero-length timer: a timer tick can come after the
        // host's first commands.
        if f.after_ms == 0 {
            shared.inject(f.fault);
            continue;
        }
        let shared = shared.clone();
        tokio::spawn(async move {
            tokio::time::sleep(std::time::Duration::from_millis(f.after_ms)).await;
            shared.inject(f.fault);
        });
    }
    let mut term = match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("surfscan-sim: cannot install SIGTERM handler: {e}");
            return ExitCode::from(1);
        }
    };
    let watch_stdin = stdin_can_close();
    let stdin_closed = async move {
        if !watch_stdin {
            return std::future::pending::<()>().await;
        }
        let mut stdin = tokio::io::stdin();
        let mut buf = [0u8; 64];
        while matches!(stdin.read(&mut buf).await, Ok(n) if n > 0) {}
    };
    tokio::pin!(stdin_closed);
    let why = loop {
        tokio::select! {
            ev = handle.next_event() => match ev {
                Some(ev) => println!("{}", ev.to_json()),
                None => break "the simulator ended",
            },
            _ = term.recv() => break "SIGTERM",
            _ = tokio::signal::ctrl_c() => break "SIGINT",
            _ = &mut stdin_closed => break "standard input closed",
        }
    };
    eprintln!("surfscan-sim: stopping ({why})");
    handle.shutdown().await;
    ExitCode::SUCCESS
}

/// Whether standard input is something that can close while we run: a pipe, a socket or a
/// terminal. `/dev/null` and regular files are at their end from the start, so watching
/// them would stop the simulator at once.
fn stdin_can_close() -> bool {
    use std::io::IsTerminal;
    use std::os::unix::fs::FileTypeExt;
    if std::io::stdin().is_terminal() {
        return true;
    }
    std::fs::metadata("/proc/self/fd/0")
        .map(|m| m.file_type().is_fifo() || m.file_type().is_socket())
        .unwrap_or(false)
}
