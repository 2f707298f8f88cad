//! `surfscan probe`: the read-only first-hour checklist on a real instrument — identity,
//! link check, conditions, parameters, profile capability, battery — printed as a summary
//! and optionally recorded as a replayable transcript. The stylus only moves with `--trace`.
//!
//! When the configured baud rate and parity get no answer, the status command alone is asked
//! at the model's other settings ([`crate::sj210::rate_search`] orders them and reads each
//! outcome); the checklist goes on at the one that answers, the `[instrument]` lines to paste
//! are printed, and the exit status is 78 (the configuration is wrong).
//!
//! `--readout` then looks for the profile read-out command on the trace the instrument holds
//! (candidate forms, verdicts, a ready-to-paste `[instrument.commands]` snippet, and what
//! remains when every form is refused); with `--trace` it also asks a result, a read-out total
//! and a block while the drive returns ([`crate::sj210::return_reads`]), and adds
//! `reads-during-return = true` to the snippet when they were answered; `--passthrough PC_PORT` instead relays a session
//! between Mitutoyo's PC software on a second serial port and the instrument, recording
//! every exchange.
//!
//! Layer 5 (composition): depends on [`crate::sj210`], [`crate::transport`], and the
//! vocabulary of [`crate::devices`] and [`crate::profile`] it prints.

use super::{CliError, Exit};
use crate::devices::{Battery, DeviceFault, FaultClass, ProbeReport, ProfileReadout};
use crate::profile::{FilterKind, ProfileKind};
use crate::sj210::client::Sj210Client;
use crate::sj210::client::{TraceEnd, TraceUntil};
use crate::sj210::error::Sj210Error;
use crate::sj210::rate_search::{self, Attempt, LineSetting, RateSearch};
use crate::sj210::readout_probe::{Conclusion, ReadoutForm, ReadoutProbe};
use crate::sj210::recorder::{Recorder, SharedTranscript, Transcript, TranscriptHeader};
use crate::sj210::return_reads::ReturnProbe;
use crate::sj210::settings::InstrumentSettings;
use crate::transport::{FlowControl, SerialSettings};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use tokio_serial::SerialStream;

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
    /// Look for the profile read-out command on the trace the instrument holds (status 000
    /// or 005 after a finished trace; with --trace, after that one): tries RDEVA00, RDEVA000,
    /// RDEVA100 and every --form, and prints the verdicts and the config snippet. With
    /// --trace, also finds out whether a result and the read-out are answered while that
    /// trace's drive returns (reads-during-return). Read-only.
    #[arg(long)]
    pub readout: bool,
    /// Another read-out form for --readout, tried after the candidates: TOTAL ending in 00
    /// (the block command is TOTAL with the block's two-digit count in place of the 00), or
    /// TOTAL=BLOCK (repeatable).
    #[arg(long = "form", requires = "readout", value_parser = parse_form)]
    pub forms: Vec<ReadoutForm>,
    /// Relay between Mitutoyo's PC software on this serial port and the instrument, recording
    /// every exchange into --record (which it needs); ends on Ctrl-C, SIGTERM, --for-s, or
    /// when either side goes away. Nothing else is sent.
    #[arg(long, value_name = "PC_PORT", requires = "record", conflicts_with_all = ["trace", "readout"])]
    pub passthrough: Option<PathBuf>,
    /// End the pass-through after this many seconds (more than 0, at most a week).
    #[arg(long, requires = "passthrough", value_parser = parse_for_s)]
    pub for_s: Option<f64>,
}

fn parse_form(s: &str) -> Result<ReadoutForm, String> {
    ReadoutForm::parse(s)
}

/// The longest pass-through `--for-s` accepts: a week.
const MAX_PASSTHROUGH_S: f64 = 7.0 * 86_400.0;

fn parse_for_s(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v <= MAX_PASSTHROUGH_S => Ok(v),
        _ => Err(format!(
            "{s:?} is not a number of seconds between 0 (exclusive) and {MAX_PASSTHROUGH_S} (a week)"
        )),
    }
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
    let settings: InstrumentSettings = section.try_into().map_err(|e: toml::de::Error| {
        CliError::new(
            Exit::Config,
            format!("[instrument] in {}: {e}", path.display()),
        )
    })?;
    crate::config::check_instrument_ranges(path, &settings)
        .map_err(|e| CliError::new(Exit::Config, e.to_string()))?;
    Ok(settings)
}

/// The profile length the wire-time note speaks of: 4 mm (λc 0.8 mm × 5) at 0.5 µm.
const TYPICAL_POINTS: u32 = 8000;

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
    let log: SharedTranscript = Arc::new(Mutex::new(Transcript::new()));
    let date = chrono::Utc::now().to_rfc3339();
    if let Some(pc_port) = &args.passthrough {
        let port = crate::transport::open(&settings.serial())
            .map_err(|e| CliError::new(Exit::Unavailable, e.to_string()))?;
        let io = Recorder::new(port, Arc::clone(&log));
        let outcome = rt.block_on(passthrough(io, &settings, pc_port, args.for_s));
        let header = TranscriptHeader {
            instrument: format!(
                "pass-through: instrument {} at {} baud, PC software on {}",
                settings.port,
                settings.baud,
                pc_port.display()
            ),
            model: settings.model.to_string(),
            firmware: None,
            date,
            notes: args.notes.clone(),
        };
        write_transcript(args.record.as_deref(), &log, &header)?;
        return outcome;
    }
    let reached = rt.block_on(reach(&settings, &table, &log));
    let (mut client, status, search) = match reached {
        Ok(r) => r,
        Err(e) => {
            let header = TranscriptHeader {
                instrument: format!("{}: no answer at any link setting", settings.port),
                model: settings.model.to_string(),
                firmware: None,
                date,
                notes: args.notes.clone(),
            };
            write_transcript(args.record.as_deref(), &log, &header)?;
            return Err(e);
        }
    };
    let link = search.found().unwrap_or(search.configured);
    if let Some(note) = rate_search::slower_than_fastest(link, &table.baud_rates, TYPICAL_POINTS) {
        say!("note      {note}");
    }
    let forms = ReadoutForm::candidates(&args.forms);
    let outcome = rt.block_on(checklist(
        &mut client,
        status,
        args.trace,
        args.readout.then_some(forms.as_slice()),
    ));
    let mut readout = None;
    let outcome = match outcome {
        Ok((report, during_return)) if args.readout => {
            match rt.block_on(client.probe_readout_forms(&forms)) {
                Ok(p) => {
                    print_readout(&p, during_return.as_ref());
                    readout = Some(p);
                    Ok(report)
                }
                Err(e) => Err(e),
            }
        }
        other => other.map(|(report, _)| report),
    };
    if args.record.is_some() {
        let firmware = outcome.as_ref().ok().map(|r| r.identity.firmware.clone());
        let header = TranscriptHeader {
            instrument: format!("{} at {link}", settings.port),
            model: settings.model.to_string(),
            firmware,
            date,
            notes: args.notes.clone(),
        };
        write_transcript(args.record.as_deref(), &log, &header)?;
    }
    outcome.map_err(|e| {
        let exit = match e.class() {
            FaultClass::Absent => Exit::Unavailable,
            _ => Exit::Failed,
        };
        CliError::new(exit, format!("probe failed: {e}"))
    })?;
    match readout.map(|p| p.conclusion()) {
        None | Some(Conclusion::Works(_)) | Some(Conclusion::WorksWithDoubts(..)) => {}
        Some(_) => {
            return Err(CliError::new(
                Exit::Failed,
                "probe: no profile read-out form works on this instrument (see the verdicts above)",
            ))
        }
    }
    match search.snippet() {
        None => Ok(()),
        Some(snippet) => {
            Err(CliError::new(
                Exit::Config,
                format!(
                    "probe: the instrument answers at {link}, not at the configured {}; set {} in [instrument] of {}",
                    search.configured,
                    snippet.trim_end().replace('\n', " and "),
                    args.config.display()
                ),
            ))
        }
    }
}

/// Opens the port at the configured link settings and asks the status; when that gets no
/// answer, tries the model's other baud rates and parities (read-only: the status command
/// only) until one answers. Every exchange goes into the transcript. Returns the client on
/// the link that answered, the status it read, and the search.
async fn reach(
    settings: &InstrumentSettings,
    table: &crate::sj210::models::ModelTable,
    log: &SharedTranscript,
) -> Result<(Sj210Client<Recorder<SerialStream>>, u16, RateSearch), CliError> {
    let configured = LineSetting {
        baud: settings.baud,
        parity: settings.parity,
    };
    let flow = flow_name(settings.flow_control);
    say!(
        "link      {} {configured}, flow control {flow}, model {}",
        settings.port,
        settings.model
    );
    let mut search = RateSearch::new(configured);
    let status_cmd = table.commands.status.plain();
    for candidate in rate_search::candidates(configured, &table.baud_rates) {
        let port = crate::transport::open(&SerialSettings {
            baud: candidate.baud,
            parity: candidate.parity,
            ..settings.serial()
        })
        .map_err(|e| CliError::new(Exit::Unavailable, e.to_string()))?;
        let io = Recorder::new(port, Arc::clone(log));
        let mut client = Sj210Client::new(io, table.clone(), settings.client_options());
        let asked = client.status().await;
        let status = asked.as_ref().ok().copied();
        let attempt = rate_search::attempt_of(asked)
            .map_err(|e| CliError::new(Exit::Unavailable, format!("probe failed: {e}")))?;
        search.record(candidate, attempt.clone());
        match attempt {
            Attempt::Answered { .. } => {
                if let Some(snippet) = search.snippet() {
                    say!("rate      {candidate}: the instrument answers");
                    say!("snippet   the instrument is set to {candidate}; paste into [instrument] of the station config:");
                    say_text!("{snippet}");
                }
                return match status {
                    Some(s) => Ok((client, s, search)),
                    // An NG to the status command at the right rate: the checklist cannot go on.
                    None => Err(CliError::new(
                        Exit::Failed,
                        format!(
                            "probe: the instrument answers at {candidate} but refuses {status_cmd:?}; record a transcript with --record and check the model"
                        ),
                    )),
                };
            }
            Attempt::NoAnswer { why } if candidate == configured => say!(
                "link      no answer at {candidate} ({why}); trying the {}'s other rates and parities (read-only: {status_cmd})",
                settings.model
            ),
            Attempt::NoAnswer { why } => say!("rate      {candidate}: no answer ({why})"),
        }
    }
    Err(CliError::new(
        Exit::Unavailable,
        format!("probe: {}", search.guidance().unwrap_or_default()),
    ))
}

/// Writes the transcript to `path` when one was asked for.
fn write_transcript(
    path: Option<&Path>,
    log: &SharedTranscript,
    header: &TranscriptHeader,
) -> Result<(), CliError> {
    let Some(path) = path else { return Ok(()) };
    let text = match log.lock() {
        Ok(g) => g.render(header),
        Err(p) => p.into_inner().render(header),
    };
    std::fs::write(path, text).map_err(|e| {
        CliError::new(
            Exit::Io,
            format!("cannot write transcript {}: {e}", path.display()),
        )
    })?;
    say!("transcript written to {}", path.display());
    Ok(())
}

/// Relays bytes between the PC software's port and the instrument (through the recorder,
/// so every exchange lands in the transcript) until a signal, the time limit, or either side
/// going away.
async fn passthrough<S>(
    mut instrument: S,
    settings: &InstrumentSettings,
    pc_port: &Path,
    for_s: Option<f64>,
) -> Result<(), CliError>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin,
{
    let limit = match for_s.map(std::time::Duration::try_from_secs_f64) {
        Some(Ok(d)) if !d.is_zero() && d.as_secs_f64() <= MAX_PASSTHROUGH_S => Some(d),
        Some(_) => {
            return Err(CliError::new(
                Exit::Usage,
                format!(
                    "--for-s {} must be a number of seconds between 0 (exclusive) and {MAX_PASSTHROUGH_S} (a week)",
                    for_s.unwrap_or(f64::NAN)
                ),
            ))
        }
        None => None,
    };
    let mut pc = crate::transport::open(&crate::transport::SerialSettings {
        path: pc_port.display().to_string(),
        ..settings.serial()
    })
    .map_err(|e| CliError::new(Exit::Unavailable, format!("PC side: {e}")))?;
    say!(
        "passthrough relaying {} (PC software) <-> {} (instrument) at {} baud; pull a profile in the PC software, then stop with Ctrl-C",
        pc_port.display(),
        settings.port,
        settings.baud
    );
    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .map_err(|e| CliError::new(Exit::Failed, format!("cannot watch SIGTERM: {e}")))?;
    let until = async {
        match limit {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    let (mut pc_rx, mut pc_tx) = tokio::io::split(&mut pc);
    let (mut inst_rx, mut inst_tx) = tokio::io::split(&mut instrument);
    // Whichever direction ends first (a side closed or failed) ends the relay.
    tokio::select! {
        r = tokio::io::copy(&mut pc_rx, &mut inst_tx) => match r {
            Ok(n) => say!("passthrough the PC side closed after {n} bytes to the instrument"),
            Err(e) => say!("passthrough the PC side ended: {e}"),
        },
        r = tokio::io::copy(&mut inst_rx, &mut pc_tx) => match r {
            Ok(n) => say!("passthrough the instrument side closed after {n} bytes to the PC"),
            Err(e) => say!("passthrough the instrument side ended: {e}"),
        },
        _ = tokio::signal::ctrl_c() => say!("passthrough stopped (interrupt)"),
        _ = term.recv() => say!("passthrough stopped (SIGTERM)"),
        _ = until => say!("passthrough stopped after --for-s"),
    }
    Ok(())
}

fn print_readout(p: &ReadoutProbe, during_return: Option<&ReturnProbe>) {
    match &p.pitch {
        Some((pitch, source)) => say!("readout   x pitch {pitch} um ({source})"),
        None => say!("readout   x pitch unknown: no count or Ra check (set pitch-x-um)"),
    }
    for r in &p.results {
        say!("readout   {}: {}", r.form, r.verdict.describe());
    }
    match during_return {
        Some(r) => {
            for line in r.lines() {
                say!("return    {line}");
            }
            say!("return    {}", r.describe());
        }
        None => say!(
            "return    not tried: whether the read-out is answered while the drive returns needs a trace (--trace)"
        ),
    }
    match p.conclusion() {
        Conclusion::Works(f) => say!("verdict   {} reads the profile", f.total),
        Conclusion::WorksWithDoubts(f, _) => {
            say!("verdict   {} reads the profile, with doubts", f.total)
        }
        Conclusion::NeedsTrace => say!("verdict   no profile held"),
        Conclusion::NotSupported => say!("verdict   no read-out command (NG030 on every form)"),
        Conclusion::NoFormFound => say!("verdict   no form read the profile"),
    }
    if let Some(mut s) = p.snippet() {
        if let Some(line) = during_return.and_then(ReturnProbe::snippet_line) {
            s.push_str(line);
        }
        say!("snippet   paste into the station config:");
        say_text!("{s}");
    }
    if let Some(g) = p.guidance() {
        say!("next      {g}");
    }
}

async fn checklist<S>(
    c: &mut Sj210Client<S>,
    status: u16,
    trace: bool,
    readout: Option<&[ReadoutForm]>,
) -> Result<(ProbeReport, Option<ReturnProbe>), Sj210Error>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin,
{
    say!(
        "status    {status:03} ({}): the link answers",
        c.table().status_meaning(status)
    );
    let report = c.probe_report().await?;
    print_report(&report);
    let pos_cmd = c.table().commands.position.plain();
    match c.command(&pos_cmd, true).await {
        Ok(p) => say!("position  {} (detector, {pos_cmd})", p.trim()),
        Err(e) => say!("position  unreadable: {e}"),
    }
    if !trace {
        return Ok((report, None));
    }
    if report.battery == crate::devices::Battery::Abnormal {
        return Err(Sj210Error::BatteryAbnormal);
    }
    say!("trace     starting one trace (the stylus moves)");
    // With --readout, the trace stops being waited for once it is measured, and the reads
    // are asked while the drive returns; the line is read once it is back.
    let during_return = match readout {
        Some(forms) => {
            let returning = c.run_trace_until(TraceUntil::Measured).await?;
            let probe = if returning == TraceEnd::Returning {
                c.probe_reads_during_return(forms).await?
            } else {
                ReturnProbe::NotSeenReturning {
                    status: c.status().await?,
                }
            };
            c.wait_idle().await?;
            Some(probe)
        }
        None => None,
    };
    match (&report.profile_readout, during_return.is_some()) {
        (ProfileReadout::Supported { .. }, traced) => {
            let line = if traced {
                c.read_held_line().await?
            } else {
                c.trace_line().await?
            };
            say!(
                "trace     {} points at {} mm pitch ({}), profile {}",
                line.profile.len(),
                line.profile.pitch_x_mm,
                line.pitch_source,
                profile_kind_name(line.profile.kind)
            );
            print_results(&line.results);
            for w in &line.warnings {
                say!("warning   {w}");
            }
        }
        (ProfileReadout::Unsupported { .. }, traced) => {
            if !traced {
                c.run_trace().await?;
            }
            let mut warnings = Vec::new();
            let results = c.read_results(&mut warnings).await?;
            say!("trace     done; results only (profile read-out unavailable)");
            print_results(&results);
            for w in &warnings {
                say!("warning   {w}");
            }
        }
    }
    Ok((report, during_return))
}

fn print_results(results: &[crate::profile::InstrumentResult]) {
    for r in results {
        match r.value {
            Some(v) => say!("result    {:<6} {v} {}", r.name, r.unit),
            None => say!("result    {:<6} (no value) {}", r.name, r.unit),
        }
    }
}

fn print_report(r: &ProbeReport) {
    for line in report_lines(r) {
        say!("{line}");
    }
}

/// The checklist's lines for what the instrument reported, in the words an operator reads
/// them in (a value the instrument did not give is `?`, never a program's `None`).
fn report_lines(r: &ProbeReport) -> Vec<String> {
    let c = &r.conditions;
    let mut lines = vec![
        format!(
            "identity  model {}, firmware {}, drive unit {}",
            r.identity.model, r.identity.firmware, r.identity.drive_unit
        ),
        format!("battery   {}", battery_name(r.battery)),
        format!(
            "conditions standard {}, profile {}, filter {}, lambda-c {} mm, lambda-s {} um, N {}, evaluation length {} mm (raw {})",
            c.standard.as_deref().unwrap_or("?"),
            c.profile_kind.map_or("?", profile_kind_name),
            c.filter.map_or("?", filter_name),
            fmt_opt(c.lambda_c_mm),
            fmt_opt(c.lambda_s_um),
            c.sampling_lengths.map(|n| n.to_string()).unwrap_or_else(|| "?".into()),
            fmt_opt(c.evaluation_length_mm),
            c.raw.as_deref().unwrap_or("?")
        ),
        format!("parameters {}", r.parameter_count),
    ];
    lines.push(match &r.profile_readout {
        ProfileReadout::Supported { points_now } => {
            format!("profile   read-out supported ({points_now} points held now)")
        }
        ProfileReadout::Unsupported { advice, .. } => format!("profile   UNSUPPORTED: {advice}"),
    });
    lines.extend(r.warnings.iter().map(|w| format!("warning   {w}")));
    lines
}

/// A profile kind as the instrument names it (ISO 4287).
fn profile_kind_name(k: ProfileKind) -> &'static str {
    match k {
        ProfileKind::P => "P",
        ProfileKind::R => "R",
        ProfileKind::W => "W",
        ProfileKind::Other => "other",
    }
}

/// A filter as the instrument names it on its display.
fn filter_name(f: FilterKind) -> &'static str {
    match f {
        FilterKind::Gaussian => "GAUSS",
        FilterKind::TwoRc => "2CR75",
        FilterKind::Pc75 => "PC75",
        FilterKind::None => "none",
    }
}

fn battery_name(b: Battery) -> String {
    match b {
        Battery::Good => "good (above 60 %)".into(),
        Battery::Low => "low (below 60 %): charge it before a long scan".into(),
        Battery::Abnormal => {
            "ABNORMAL (temperature, voltage or no battery): scans are refused".into()
        }
        Battery::Charging => "charging".into(),
        Battery::Unknown(code) => format!("unknown state (code {code:03})"),
    }
}

/// Flow control as the configuration spells it.
fn flow_name(flow: FlowControl) -> &'static str {
    match flow {
        FlowControl::None => "none",
        FlowControl::RtsCts => "rts-cts",
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

    #[test]
    fn the_checklist_names_what_the_instrument_reported_in_its_own_words() {
        use crate::devices::InstrumentIdentity;
        use crate::profile::Conditions;
        let mut report = ProbeReport {
            identity: InstrumentIdentity {
                model: "sj210".into(),
                firmware: "V1.01".into(),
                drive_unit: "standard".into(),
            },
            battery: Battery::Low,
            conditions: Conditions {
                standard: Some("ISO1997".into()),
                profile_kind: Some(ProfileKind::R),
                filter: Some(FilterKind::TwoRc),
                lambda_c_mm: Some(0.8),
                sampling_lengths: Some(5),
                evaluation_length_mm: Some(4.0),
                raw: Some("3120504.0012".into()),
                ..Conditions::default()
            },
            parameter_count: 2,
            profile_readout: ProfileReadout::Supported { points_now: 0 },
            warnings: vec![],
        };
        let lines = report_lines(&report);
        assert_eq!(
            lines[..3],
            [
                "identity  model sj210, firmware V1.01, drive unit standard",
                "battery   low (below 60 %): charge it before a long scan",
                "conditions standard ISO1997, profile R, filter 2CR75, lambda-c 0.8 mm, lambda-s ? um, N 5, evaluation length 4 mm (raw 3120504.0012)",
            ]
        );
        // What the instrument did not report is `?`, never a program's `None`.
        report.conditions = Conditions::default();
        report.battery = Battery::Unknown(7);
        let text = report_lines(&report).join("\n");
        assert!(text.contains("profile ?, filter ?"), "{text}");
        assert!(text.contains("unknown state (code 007)"), "{text}");
        for debug in ["Some(", "None", "\""] {
            assert!(!text.contains(debug), "{debug} in {text}");
        }
    }
}
