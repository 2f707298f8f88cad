//! `surfscan status|pause|resume|abort|start`: the operator's commands to a running daemon
//! over its control socket, with output for people (or the raw JSON messages with `--json`).
//!
//! Exit codes: 0 done, 1 the daemon refused (its message is printed), 69 the daemon is not
//! reachable or speaks another protocol version, 74 the conversation broke off, 78 the
//! `--config` file is unreadable or its `[control] socket` is not a string.
//!
//! `pause` and `resume` are idempotent: both exit 0 when the scan ends up in the state asked
//! for, including when it already was (`already paused`, `not paused; it goes on scanning`),
//! and 1 when there is no scan to pause or resume. `start` while a scan runs exits 1 with the
//! running scan's id; an accepted start is followed until the scan is under way (exit 0) or
//! ended (a scan that cannot begin, a device missing, is exit 1 with its reason), for up to
//! [`START_WAIT`]. `status --watch` outlives the daemon: when the connection closes it
//! says so on standard error and reconnects (every 0.5 s at first, then every 5 s) until
//! the daemon is back or it is interrupted.
//!
//! Without `--socket` and `--config`, the `[control] socket` of `/etc/surfscan/surfscan.toml`
//! is used when that file exists and can be read, else `/run/surfscan/control.sock`.
//!
//! Layer 5 (composition): depends on [`crate::control`].

use super::start_args::{self, StartChoiceArgs};
use super::{CliError, Exit};
use crate::control::client::{ClientError, ControlClient, Received};
use crate::control::protocol::{Message, Request};
use crate::scan::ending::StopStatus;
use crate::scan::status::{DeviceState, State, Status};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Where the daemon listens unless told otherwise (under the unit's `RuntimeDirectory`).
pub const DEFAULT_SOCKET: &str = "/run/surfscan/control.sock";

/// Which daemon to talk to.
#[derive(Debug, Clone, clap::Args)]
pub struct Target {
    /// Control socket of the daemon [default: the config's `[control] socket`, else
    /// /run/surfscan/control.sock]. Wins over --config.
    #[arg(long, value_name = "PATH")]
    pub socket: Option<PathBuf>,
    /// Config file; only its `[control]` table's `socket` key is read [default:
    /// /etc/surfscan/surfscan.toml when it exists].
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print the daemon's replies as the raw JSON lines it sent, one per line.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `surfscan status`.
#[derive(Debug, Clone, clap::Args)]
pub struct StatusArgs {
    /// The daemon.
    #[command(flatten)]
    pub target: Target,
    /// Keep printing the status on every change until interrupted.
    #[arg(long)]
    pub watch: bool,
}

/// Arguments of `surfscan pause|resume|abort`.
#[derive(Debug, Clone, clap::Args)]
pub struct CommandArgs {
    /// The daemon.
    #[command(flatten)]
    pub target: Target,
}

/// Arguments of `surfscan start`.
#[derive(Debug, Clone, clap::Args)]
pub struct StartArgs {
    /// The daemon.
    #[command(flatten)]
    pub target: Target,
    /// Specimen id, recorded with the scan.
    #[arg(long, value_name = "ID", default_value = "")]
    pub specimen: String,
    /// Operator name, recorded with the scan [default: $USER].
    #[arg(long, value_name = "NAME")]
    pub operator: Option<String>,
    /// Free-text notes, recorded with the scan.
    #[arg(long, value_name = "TEXT", default_value = "")]
    pub notes: String,
    /// Which scan: resume, new, a recipe.
    #[command(flatten)]
    pub choice: StartChoiceArgs,
}

/// Which operator command to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verb {
    /// `pause`.
    Pause,
    /// `resume`.
    Resume,
    /// `abort`.
    Abort,
}

/// The socket to use: `--socket`, else the `[control] socket` of `--config`, else that of
/// the default configuration, else the default socket.
pub fn socket_path(target: &Target) -> Result<PathBuf, CliError> {
    socket_path_with_default(target, Path::new(super::DEFAULT_CONFIG))
}

/// [`socket_path`] with `default_config` standing for `/etc/surfscan/surfscan.toml`: an
/// absent default is skipped silently, an unreadable or invalid one with a warning (an
/// operator may not be allowed to read the station's file, and the default socket is then
/// the best guess).
pub fn socket_path_with_default(
    target: &Target,
    default_config: &Path,
) -> Result<PathBuf, CliError> {
    if let Some(s) = &target.socket {
        return Ok(s.clone());
    }
    let from_config = match &target.config {
        Some(config) => config_socket(config)?,
        None if default_config.exists() => match config_socket(default_config) {
            Ok(s) => s,
            Err(e) => {
                tell!("surfscan: warning: {e}; trying {DEFAULT_SOCKET}");
                None
            }
        },
        None => None,
    };
    Ok(from_config.unwrap_or_else(|| PathBuf::from(DEFAULT_SOCKET)))
}

/// Reads only `[control] socket` from a TOML config, ignoring every other table.
pub fn config_socket(path: &Path) -> Result<Option<PathBuf>, CliError> {
    let mut doc = super::read_toml_table(path)?;
    let Some(control) = doc.remove("control") else {
        return Ok(None);
    };
    let toml::Value::Table(control) = control else {
        return Err(CliError::new(
            Exit::Config,
            format!(
                "`control` in {} must be a table ([control])",
                path.display()
            ),
        ));
    };
    match control.get("socket") {
        None => Ok(None),
        Some(toml::Value::String(s)) if !s.is_empty() => Ok(Some(PathBuf::from(s))),
        Some(other) => Err(CliError::new(
            Exit::Config,
            format!(
                "[control] socket in {} must be a non-empty path string, found {other}",
                path.display()
            ),
        )),
    }
}

/// First and longest wait between reconnection attempts of `status --watch`.
pub const WATCH_RECONNECT: (Duration, Duration) =
    (Duration::from_millis(500), Duration::from_secs(5));

/// Runs `surfscan status`.
pub fn run_status(args: StatusArgs) -> Result<(), CliError> {
    let path = socket_path(&args.target)?;
    let json = args.target.json;
    block_on(async move {
        let mut client = ControlClient::connect(&path).await.map_err(client_error)?;
        if !args.watch {
            let first = client
                .request(&Request::Status)
                .await
                .map_err(client_error)?;
            return print_reply(&first, json, false);
        }
        let first = client
            .request(&Request::Watch)
            .await
            .map_err(client_error)?;
        print_reply(&first, json, false)?;
        // A snapshot that reads as the line printed last (the daemon publishes on every step,
        // not only on a change people see) is not printed again.
        let mut last = status_line(&first);
        // Watching is only printing: once nobody reads the output (`status --watch | head`),
        // the watch ends.
        while !super::console::stdout_gone() {
            let why = match client.next().await {
                Ok(Some(m)) => {
                    let line = status_line(&m);
                    if json || line.is_none() || line != last {
                        print_reply(&m, json, true)?;
                    }
                    if line.is_some() {
                        last = line;
                    }
                    continue;
                }
                Ok(None) => "closed the connection".to_string(),
                Err(e) => e.to_string(),
            };
            tell!(
                "surfscan: the daemon at {} {why} (stopped or restarted?); reconnecting",
                path.display()
            );
            let (again, first) = reconnect_watch(&path, json).await?;
            client = again;
            last = status_line(&first);
        }
        Ok(())
    })
}

/// Connects again until the daemon answers, then asks to watch and prints the first status
/// (with a note that the connection is back), which it returns with the client; a daemon of
/// another protocol version is an error, as at the first connection.
async fn reconnect_watch(path: &Path, json: bool) -> Result<(ControlClient, Received), CliError> {
    let (mut wait, max) = WATCH_RECONNECT;
    loop {
        tokio::time::sleep(wait).await;
        wait = (wait * 2).min(max);
        let mut client = match ControlClient::connect(path).await {
            Ok(c) => c,
            Err(e @ ClientError::Incompatible { .. }) => return Err(client_error(e)),
            Err(_) => continue,
        };
        match client.request(&Request::Watch).await {
            Ok(first) => {
                tell!("surfscan: reconnected to the daemon at {}", path.display());
                print_reply(&first, json, true)?;
                return Ok((client, first));
            }
            Err(e @ ClientError::Incompatible { .. }) => return Err(client_error(e)),
            Err(_) => continue,
        }
    }
}

/// Runs `surfscan pause|resume|abort`.
pub fn run_command(verb: Verb, args: CommandArgs) -> Result<(), CliError> {
    let request = match verb {
        Verb::Pause => Request::Pause,
        Verb::Resume => Request::Resume,
        Verb::Abort => Request::Abort,
    };
    send_command(&args.target, request)
}

/// Runs `surfscan start`.
pub fn run_start(args: StartArgs) -> Result<(), CliError> {
    let request = Request::Start {
        specimen: args.specimen,
        operator: start_args::operator_or_user(args.operator),
        notes: args.notes,
        mode: args.choice.mode(),
        y_start_mm: args.choice.y_start_mm()?,
        recipe: args.choice.recipe,
    };
    let path = socket_path(&args.target)?;
    let json = args.target.json;
    block_on(async move {
        let mut client = ControlClient::connect(&path).await.map_err(client_error)?;
        let before = match client
            .request(&Request::Status)
            .await
            .map_err(client_error)?
        {
            Received {
                message: Message::Status(s),
                ..
            } => s.starts,
            other => {
                return Err(CliError::new(
                    Exit::Io,
                    format!("the daemon answered status with {}", other.raw),
                ))
            }
        };
        let reply = client.request(&request).await.map_err(client_error)?;
        print_reply(&reply, json, false)?;
        confirm_start(&path, before, json).await
    })
}

/// How long `surfscan start` waits to see its scan under way (the devices opened and the scan
/// directory made, or the paused scan going on) or ended, before it leaves the rest to
/// `surfscan status --watch`.
pub const START_WAIT: Duration = Duration::from_secs(120);

/// Follows the status after a start the daemon accepted until it shows that start's outcome
/// (the daemon's count of scans begun has grown past `before`): under way, or ended (a scan
/// that cannot start, the devices missing say, is exit 1 with the reason) — so an operator
/// who walks away after `surfscan start` knows the scan really began.
async fn confirm_start(path: &Path, before: u64, json: bool) -> Result<(), CliError> {
    let mut client = ControlClient::connect(path).await.map_err(client_error)?;
    let mut m = client
        .request(&Request::Watch)
        .await
        .map_err(client_error)?;
    let deadline = tokio::time::Instant::now() + START_WAIT;
    loop {
        if let Message::Status(s) = &m.message {
            if let Some(outcome) = start_outcome(before, s) {
                if json {
                    say!("{}", m.raw);
                } else if outcome.is_ok() {
                    say!("{}", s.summary());
                }
                return outcome.map_err(|reason| {
                    CliError::new(Exit::Failed, format!("the scan did not start: {reason}"))
                });
            }
        }
        m = match tokio::time::timeout_at(deadline, client.next()).await {
            Ok(Ok(Some(next))) => next,
            Ok(Ok(None)) | Ok(Err(_)) => {
                return Err(CliError::new(
                    Exit::Io,
                    "the daemon stopped answering before the scan was under way; see `surfscan status` and `journalctl -u surfscan`",
                ))
            }
            Err(_) => {
                say!(
                    "still starting after {} s (opening the devices, homing); follow it with `surfscan status --watch`",
                    START_WAIT.as_secs()
                );
                return Ok(());
            }
        };
    }
}

/// What a status snapshot says of a start accepted when `before` scans had begun: nothing
/// yet (`None`: the count has not grown, or the scan is still starting), under way or ended
/// (`Ok`), or ended without starting (`Err` with the stop's reason, or the reason of an idle
/// daemon: the scan to reopen was refused by the file system and has not ended).
fn start_outcome(before: u64, s: &Status) -> Option<Result<(), String>> {
    if s.starts <= before || s.state == State::Starting {
        return None;
    }
    Some(match (&s.state, &s.last_stop, &s.reason) {
        // The scan the start reopens was refused by the file system: it has not ended.
        (State::Idle, _, Some(why)) => Err(why.clone()),
        (State::Idle, Some(stop), _) if stop.status == StopStatus::Fail => Err(stop.reason.clone()),
        _ => Ok(()),
    })
}

/// Sends one request and prints its reply (`--json`: as the daemon sent it).
pub(super) fn send_command(target: &Target, request: Request) -> Result<(), CliError> {
    let path = socket_path(target)?;
    let json = target.json;
    block_on(async move {
        let mut client = ControlClient::connect(&path).await.map_err(client_error)?;
        let reply = client.request(&request).await.map_err(client_error)?;
        print_reply(&reply, json, false)
    })
}

fn block_on<F: std::future::Future<Output = Result<(), CliError>>>(f: F) -> Result<(), CliError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::new(Exit::Failed, format!("cannot start the runtime: {e}")))?
        .block_on(f)
}

fn client_error(e: ClientError) -> CliError {
    let exit = match &e {
        ClientError::Unreachable { .. }
        | ClientError::Incompatible { .. }
        | ClientError::Refused { .. } => Exit::Unavailable,
        ClientError::Io { .. } => Exit::Io,
    };
    CliError::new(exit, e.to_string())
}

/// The one-line form of a status message ([`render_status_line`]), `None` for other messages.
fn status_line(m: &Received) -> Option<String> {
    match &m.message {
        Message::Status(s) => Some(render_status_line(s)),
        _ => None,
    }
}

/// Prints one reply; an `Error` from the daemon becomes exit status 1.
fn print_reply(m: &Received, json: bool, compact: bool) -> Result<(), CliError> {
    if json {
        say!("{}", m.raw);
    }
    match &m.message {
        Message::Error { message } => Err(CliError::new(
            Exit::Failed,
            format!("the daemon refused: {message}"),
        )),
        Message::Refused { message, exit } => Err(CliError::new(
            match exit {
                2 => Exit::Usage,
                74 => Exit::Io,
                78 => Exit::Config,
                _ => Exit::Failed,
            },
            format!("the daemon refused: {message}"),
        )),
        _ if json => Ok(()),
        Message::Queue(q) => {
            say_text!("{}", super::queue::render(q));
            Ok(())
        }
        Message::Status(s) if compact => {
            say!(
                "{} {}",
                chrono::Local::now().format("%H:%M:%S"),
                render_status_line(s)
            );
            Ok(())
        }
        Message::Status(s) => {
            say_text!("{}", render_status(s));
            Ok(())
        }
        Message::Ack { command, detail } => {
            say!("{command}: {detail}");
            Ok(())
        }
        Message::Hello { .. } => Err(CliError::new(
            Exit::Io,
            format!("the daemon sent a second greeting: {}", m.raw),
        )),
    }
}

fn kebab<T: serde::Serialize>(v: T) -> String {
    serde_json::to_value(v)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default()
}

fn devices(s: &Status) -> String {
    let name = |d: DeviceState| kebab(d);
    format!("instrument {}, stage {}", name(s.instrument), name(s.stage))
}

/// The ETA as people read it, only while lines are being traced: paused, suspended or
/// starting, the estimate (the scanning time still needed) does not count down, and shown
/// then it would promise an end that recedes for as long as the scan waits.
pub fn eta_while_scanning(s: &Status) -> Option<String> {
    if s.state == State::Scanning {
        s.eta_s.and_then(crate::numfmt::duration)
    } else {
        None
    }
}

/// The status as a block of labelled lines for people.
pub fn render_status(s: &Status) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "{}", s.summary());
    let _ = writeln!(out, "  state      {}", kebab(s.state));
    if let Some(id) = &s.scan_id {
        match &s.scan_dir {
            Some(dir) => {
                let _ = writeln!(out, "  scan       {id} in {dir}");
            }
            None => {
                let _ = writeln!(out, "  scan       {id}");
            }
        }
    }
    if s.lines_total > 0 || s.scan_id.is_some() {
        let _ = write!(out, "  lines      {}/{} done", s.lines_done, s.lines_total);
        match s.current_line {
            Some(k) if s.state != State::Idle => {
                let _ = writeln!(out, ", on line {k}");
            }
            _ => out.push('\n'),
        }
    }
    if let Some(y) = s.y_mm {
        let _ = writeln!(out, "  y          {y:.3} mm");
    }
    if let Some(ra) = s.last_ra_um {
        let _ = writeln!(out, "  last Ra    {ra:.3} µm");
    }
    if let Some(eta) = eta_while_scanning(s) {
        let _ = writeln!(out, "  ETA        {eta}");
    }
    let _ = writeln!(out, "  devices    {}", devices(s));
    if let Some(r) = &s.reason {
        let _ = writeln!(out, "  reason     {r}");
    }
    if let Some(l) = &s.last_stop {
        let _ = if l.scan_id.is_empty() {
            // The scan never started (a device missing at start): no id, no directory.
            writeln!(out, "  last start {}: {}", l.status, l.reason)
        } else {
            writeln!(
                out,
                "  last stop  {}: {} ({}) in {}",
                l.scan_id, l.status, l.reason, l.dir
            )
        };
        if let Some(v) = &l.verdict {
            let _ = writeln!(out, "  verdict    {v}");
        }
    }
    if let Some(q) = &s.queue {
        let _ = write!(out, "  queue      {} job(s) queued", q.queued);
        if let Some(j) = q.running {
            let _ = write!(out, ", job {j} running");
        }
        out.push('\n');
        if let Some(h) = &q.held {
            let _ = writeln!(out, "  queue      stopped: {h}");
        }
    }
    for d in &s.damaged_journals {
        let _ = writeln!(out, "  warning    {d}");
    }
    out
}

/// The status on one line, for `--watch`.
pub fn render_status_line(s: &Status) -> String {
    let mut out = s.summary();
    if let Some(ra) = s.last_ra_um {
        let _ = write!(out, "; last Ra {ra:.3} µm");
    }
    if let Some(eta) = eta_while_scanning(s) {
        let _ = write!(out, "; ETA {eta}");
    }
    let _ = write!(out, "; {}", devices(s));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::status::LastStop;

    /// Scan G-0141's stop in `/d/G-0141`, without a verdict.
    fn stop(status: StopStatus, reason: &str) -> LastStop {
        LastStop {
            scan_id: "G-0141".into(),
            status,
            reason: reason.into(),
            dir: "/d/G-0141".into(),
            internal: false,
            verdict: None,
            results: None,
        }
    }

    fn scanning() -> Status {
        let mut s = Status::idle();
        s.state = State::Scanning;
        s.scan_id = Some("G-0142".into());
        s.scan_dir = Some("/var/lib/surfscan/scans/G-0142".into());
        s.lines_done = 11;
        s.lines_total = 31;
        s.current_line = Some(12);
        s.y_mm = Some(0.11);
        s.last_ra_um = Some(0.4521);
        s.eta_s = Some(750.0);
        s.instrument = DeviceState::Connected;
        s.stage = DeviceState::Reconnecting;
        s
    }

    /// The daemon's start as `surfscan start` sees it: from the first snapshot with the
    /// grown count on, the outcome is the scan's own. The count grown beside the idle state
    /// from before was taken for a start that went ahead, so a start whose devices could not
    /// be opened a moment later exited 0 (seen on a loaded machine).
    #[test]
    fn a_start_is_decided_by_the_scans_own_snapshots() {
        let mut s = Status::idle();
        s.last_stop = Some(stop(StopStatus::Success, "31 lines"));
        let before = s.starts;
        assert_eq!(start_outcome(before, &s), None, "nothing begun yet");
        s.begin_start();
        assert_eq!(start_outcome(before, &s), None, "begun, not yet decided");
        let failed = crate::scan::status::ended_status(
            &s,
            StopStatus::Fail,
            "the instrument is not at /dev/sj210",
        );
        assert_eq!(
            start_outcome(before, &failed),
            Some(Err("the instrument is not at /dev/sj210".into()))
        );
        // The scan it reopens refused by the file system: not ended, so the last stop is
        // the earlier scan's success; the reason says why, and the start did not go ahead.
        let mut refused = failed.clone();
        refused.last_stop.clone_from(&s.last_stop);
        refused.reason = Some("scan B-1 (/scans/B-1) waits for the file system: …".into());
        assert_eq!(
            start_outcome(before, &refused),
            Some(Err(
                "scan B-1 (/scans/B-1) waits for the file system: …".into()
            ))
        );
        let mut under_way = scanning();
        under_way.starts = before + 1;
        assert_eq!(start_outcome(before, &under_way), Some(Ok(())));
        assert_eq!(
            start_outcome(before + 1, &under_way),
            None,
            "an earlier start's"
        );
    }

    #[test]
    fn status_block_shows_what_an_operator_asks_for() {
        let text = render_status(&scanning());
        let expected = "scan G-0142: line 12/31, y=0.110 mm\n  state      scanning\n  scan       G-0142 in /var/lib/surfscan/scans/G-0142\n  lines      11/31 done, on line 12\n  y          0.110 mm\n  last Ra    0.452 µm\n  ETA        12 min 30 s\n  devices    instrument connected, stage reconnecting\n";
        assert_eq!(text, expected);
    }

    #[test]
    fn the_last_scans_verdict_and_the_queue_are_shown() {
        let mut s = Status::idle();
        let results = crate::scan::results::ScanResults {
            verdict: Some(crate::specification::Verdict::DoesNotConform),
            verdict_summary: Some(
                "does not conform (Rz 16 % rule: 9 of 31 lines above 6.3 µm)".into(),
            ),
            warnings: 3,
            ..Default::default()
        };
        s.last_stop = Some(LastStop {
            verdict: Some(results.line("success")),
            results: Some(Box::new(results)),
            ..stop(StopStatus::Success, "31 lines")
        });
        s.queue = Some(Box::new(crate::scan::status::QueueStatus {
            queued: 2,
            running: None,
            held: Some("job 4 (brass) ended fail".into()),
        }));
        let text = render_status(&s);
        assert!(
            text.contains("  verdict    success, 3 warnings: does not conform (Rz 16 % rule: 9 of 31 lines above 6.3 µm)\n"),
            "{text}"
        );
        assert!(text.contains("  queue      2 job(s) queued\n"), "{text}");
        assert!(text.contains("  queue      stopped: job 4"), "{text}");
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(json["last_stop"]["results"]["verdict"], "does not conform");
        assert!(json["last_stop"]["verdict"]
            .as_str()
            .unwrap()
            .starts_with("success, 3 warnings: does not conform"));
        let mut w = Status::idle();
        w.state = State::Waiting;
        w.reason = Some("waiting for specimen to be loaded — job 5".into());
        assert_eq!(
            w.summary(),
            "waiting: waiting for specimen to be loaded — job 5"
        );
    }

    #[test]
    fn idle_block_shows_the_last_stop_and_no_scan_fields() {
        let mut s = Status::idle();
        s.last_stop = Some(stop(StopStatus::Fail, "stage following error"));
        s.reason = Some("stage following error".into());
        let text = render_status(&s);
        assert!(!text.contains("lines"), "{text}");
        assert!(!text.contains("ETA"), "{text}");
        assert!(
            text.contains("  devices    instrument absent, stage absent\n"),
            "{text}"
        );
        assert!(
            text.contains("  last stop  G-0141: fail (stage following error) in /d/G-0141\n"),
            "{text}"
        );
    }

    #[test]
    fn no_eta_is_shown_while_the_scan_waits() {
        // Paused or suspended, the estimate does not count down: shown, it would promise an
        // end that moves away while the scan waits.
        for state in [
            State::Paused,
            State::Suspended,
            State::Pausing,
            State::Starting,
        ] {
            let mut s = scanning();
            s.state = state;
            assert!(!render_status(&s).contains("ETA"), "{state:?}");
            assert!(!render_status_line(&s).contains("ETA"), "{state:?}");
        }
    }

    #[test]
    fn watch_line_is_one_line() {
        let line = render_status_line(&scanning());
        assert_eq!(
            line,
            "scan G-0142: line 12/31, y=0.110 mm; last Ra 0.452 µm; ETA 12 min 30 s; instrument connected, stage reconnecting"
        );
    }

    #[test]
    fn socket_comes_from_flag_then_config_then_default() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = dir.path().join("s.toml");
        std::fs::write(
            &cfg,
            "[instrument]\nport = 3\n[control]\nsocket = \"/tmp/x.sock\"\nother = 1\n",
        )
        .unwrap();
        let mut t = Target {
            socket: None,
            config: Some(cfg.clone()),
            json: false,
        };
        assert_eq!(socket_path(&t).unwrap(), PathBuf::from("/tmp/x.sock"));
        t.socket = Some("/tmp/flag.sock".into());
        assert_eq!(socket_path(&t).unwrap(), PathBuf::from("/tmp/flag.sock"));
        std::fs::write(&cfg, "[instrument]\nport = \"/dev/sj210\"\n").unwrap();
        t.socket = None;
        assert_eq!(socket_path(&t).unwrap(), PathBuf::from(DEFAULT_SOCKET));
        std::fs::write(&cfg, "[control]\nsocket = 5\n").unwrap();
        let e = socket_path(&t).unwrap_err();
        assert_eq!(e.exit, Exit::Config);
        assert!(e.message.contains("[control] socket"), "{}", e.message);
        t.config = Some(dir.path().join("missing.toml"));
        assert_eq!(socket_path(&t).unwrap_err().exit, Exit::Config);
    }

    #[test]
    fn the_default_config_names_the_socket_when_it_exists() {
        let dir = tempfile::tempdir().unwrap();
        let default = dir.path().join("surfscan.toml");
        let t = Target {
            socket: None,
            config: None,
            json: false,
        };
        // Absent: the default socket.
        assert_eq!(
            socket_path_with_default(&t, &default).unwrap(),
            PathBuf::from(DEFAULT_SOCKET)
        );
        std::fs::write(&default, "[control]\nsocket = \"/tmp/station.sock\"\n").unwrap();
        assert_eq!(
            socket_path_with_default(&t, &default).unwrap(),
            PathBuf::from("/tmp/station.sock")
        );
        // Broken: a warning and the default socket, not a failure of `status`.
        std::fs::write(&default, "[control\n").unwrap();
        assert_eq!(
            socket_path_with_default(&t, &default).unwrap(),
            PathBuf::from(DEFAULT_SOCKET)
        );
    }
}
