//! `surfscan probe`: the read-only first-hour checklist on a real instrument — identity,
//! link check, conditions, parameters, profile capability, battery — printed as a summary
//! and optionally recorded as a replayable transcript. The stylus only moves with `--trace`.
//!
//! Layer 5 (composition): depends on [`crate::sj210`] and [`crate::transport`].

use super::{CliError, Exit};
use crate::devices::{DeviceFault, FaultClass, ProbeReport, ProfileReadout};
use crate::sj210::client::Sj210Client;
use crate::sj210::error::Sj210Error;
use crate::sj210::recorder::{Recorder, SharedTranscript, Transcript, TranscriptHeader};
use crate::sj210::settings::InstrumentSettings;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Arguments of `surfscan probe`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Config file; only its `[instrument]` table is read.
    #[arg(long)]
    pub config: PathBuf,
    /// Write the transcript of the conversation here (format v1, replayable by the simulator).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Also trace one line (moves the stylus) and read results and profile.
    #[arg(long)]
    pub trace: bool,
    /// Free text for the transcript's `notes` header.
    #[arg(long, default_value = "")]
    pub notes: String,
}

/// Reads the `[instrument]` table of a TOML config, ignoring every other table.
pub fn load_instrument_settings(path: &Path) -> Result<InstrumentSettings, CliError> {
    let mut doc = super::read_toml_table(path)?;
    let section = doc.remove("instrument").ok_or_else(|| {
        CliError::new(
            Exit::Config,
            format!(
                "config {} has no [instrument] section; add one with at least `port = \"/dev/serial/by-id/…\"`",
                path.display()
            ),
        )
    })?;
    section.try_into().map_err(|e: toml::de::Error| {
        CliError::new(
            Exit::Config,
            format!("[instrument] in {}: {e}", path.display()),
        )
    })
}

/// Runs `surfscan probe`.
pub fn run(args: Args) -> Result<(), CliError> {
    let settings = load_instrument_settings(&args.config)?;
    let table = settings
        .validate()
        .map_err(|e| CliError::new(Exit::Config, e.to_string()))?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::new(Exit::Failed, format!("cannot start the runtime: {e}")))?;
    // The serial stream registers with the reactor, so it is opened inside the runtime.
    let _guard = rt.enter();
    let port = crate::transport::open(&settings.serial())
        .map_err(|e| CliError::new(Exit::Unavailable, e.to_string()))?;
    let log: SharedTranscript = Arc::new(Mutex::new(Transcript::new()));
    let date = chrono::Utc::now().to_rfc3339();
    let io = Recorder::new(port, Arc::clone(&log));
    let mut client = Sj210Client::new(io, table, settings.client_options());
    let outcome = rt.block_on(checklist(&mut client, &settings, args.trace));
    if let Some(path) = &args.record {
        let firmware = outcome.as_ref().ok().map(|r| r.identity.firmware.clone());
        let header = TranscriptHeader {
            instrument: format!("{} at {} baud", settings.port, settings.baud),
            model: settings.model.to_string(),
            firmware,
            date,
            notes: args.notes.clone(),
        };
        let text = match log.lock() {
            Ok(g) => g.render(&header),
            Err(p) => p.into_inner().render(&header),
        };
        std::fs::write(path, text).map_err(|e| {
            CliError::new(
                Exit::Io,
                format!("cannot write transcript {}: {e}", path.display()),
            )
        })?;
        println!("transcript written to {}", path.display());
    }
    outcome.map(|_| ()).map_err(|e| {
        let exit = match e.class() {
            FaultClass::Absent => Exit::Unavailable,
            _ => Exit::Failed,
        };
        CliError::new(exit, format!("probe failed: {e}"))
    })
}

async fn checklist<S>(
    c: &mut Sj210Client<S>,
    settings: &InstrumentSettings,
    trace: bool,
) -> Result<ProbeReport, Sj210Error>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin,
{
    println!(
        "link      {} {} baud, parity {:?}, flow control {:?}, model {}",
        settings.port, settings.baud, settings.parity, settings.flow_control, settings.model
    );
    let status = c.status().await?;
    println!(
        "status    {status:03} ({}): the link answers",
        c.table().status_meaning(status)
    );
    let report = c.probe_report().await?;
    print_report(&report);
    let pos_cmd = c.table().commands.position.plain();
    match c.command(&pos_cmd, true).await {
        Ok(p) => println!("position  {} (detector, {pos_cmd})", p.trim()),
        Err(e) => println!("position  unreadable: {e}"),
    }
    if trace {
        if report.battery == crate::devices::Battery::Abnormal {
            return Err(Sj210Error::BatteryAbnormal);
        }
        println!("trace     starting one trace (the stylus moves)");
        match &report.profile_readout {
            ProfileReadout::Supported { .. } => {
                let line = c.trace_line().await?;
                println!(
                    "trace     {} points at {} mm pitch ({}), kind {:?}",
                    line.profile.len(),
                    line.profile.pitch_x_mm,
                    line.pitch_source,
                    line.profile.kind
                );
                print_results(&line.results);
                for w in &line.warnings {
                    println!("warning   {w}");
                }
            }
            ProfileReadout::Unsupported { .. } => {
                c.run_trace().await?;
                let mut warnings = Vec::new();
                let results = c.read_results(&mut warnings).await?;
                println!("trace     done; results only (profile read-out unavailable)");
                print_results(&results);
                for w in &warnings {
                    println!("warning   {w}");
                }
            }
        }
    }
    Ok(report)
}

fn print_results(results: &[crate::profile::InstrumentResult]) {
    for r in results {
        match r.value {
            Some(v) => println!("result    {:<6} {v} {}", r.name, r.unit),
            None => println!("result    {:<6} (no value) {}", r.name, r.unit),
        }
    }
}

fn print_report(r: &ProbeReport) {
    println!(
        "identity  model {}, firmware {:?}, drive unit {}",
        r.identity.model, r.identity.firmware, r.identity.drive_unit
    );
    println!("battery   {:?}", r.battery);
    let c = &r.conditions;
    println!(
        "conditions standard {}, profile {:?}, filter {:?}, lambda-c {} mm, lambda-s {} um, N {}, evaluation length {} mm (raw {:?})",
        c.standard.as_deref().unwrap_or("?"),
        c.profile_kind,
        c.filter,
        fmt_opt(c.lambda_c_mm),
        fmt_opt(c.lambda_s_um),
        c.sampling_lengths.map(|n| n.to_string()).unwrap_or_else(|| "?".into()),
        fmt_opt(c.evaluation_length_mm),
        c.raw.as_deref().unwrap_or("")
    );
    println!("parameters {}", r.parameter_count);
    match &r.profile_readout {
        ProfileReadout::Supported { points_now } => {
            println!("profile   read-out supported ({points_now} points held now)")
        }
        ProfileReadout::Unsupported { advice, .. } => println!("profile   UNSUPPORTED: {advice}"),
    }
    for w in &r.warnings {
        println!("warning   {w}");
    }
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map(|x| x.to_string()).unwrap_or_else(|| "?".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn takes_only_the_instrument_table() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.toml");
        std::fs::write(
            &p,
            "[scan]\nlines = 3\n[instrument]\nport = \"/dev/ttyUSB0\"\nbaud = 38400\n",
        )
        .unwrap();
        let s = load_instrument_settings(&p).unwrap();
        assert_eq!(s.baud, 38400);
        std::fs::write(&p, "[scan]\nlines = 3\n").unwrap();
        let e = load_instrument_settings(&p).unwrap_err();
        assert_eq!(e.exit, Exit::Config);
        assert!(e.message.contains("no [instrument] section"));
        std::fs::write(&p, "[instrument]\nport = \"x\"\nspeed = 1\n").unwrap();
        assert_eq!(load_instrument_settings(&p).unwrap_err().exit, Exit::Config);
    }
}
