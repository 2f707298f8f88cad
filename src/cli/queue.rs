//! `surfscan queue add|list|remove|clear|continue` and `surfscan ready`: the job queue the
//! daemon runs one job after another from ([`crate::jobs::queue`]), through the control
//! socket. Each command that changes the queue is recorded with its sender (the socket's
//! peer) in `queue-log.jsonl`; `list` is open to everyone who can open the socket, like
//! `status`.
//!
//! Exit status: 0 done, 1 refused for another reason (the daemon names it), 2 usage (an
//! unknown recipe or job, a `--y-start-mm` outside the stage's travel), 69 the daemon cannot be
//! reached, 74 the queue could not be written (nothing changed), 78 the recipe is not valid.
//!
//! Layer 5 (composition): depends on the control client ([`super::control`]) and the queue's
//! types for the listing.

use super::control::{send_command, Target};
use super::start_args;
use super::CliError;
use crate::control::protocol::Request;
use crate::jobs::queue::{Job, JobState, Queue};
use crate::numfmt::{fmt, Quantity};
use std::fmt::Write as _;

/// Arguments of `surfscan queue`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// What to do with the queue.
    #[command(subcommand)]
    pub command: QueueCommand,
}

/// The queue's subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum QueueCommand {
    /// Queue a job: a recipe's scan of one specimen (validated now, run in its turn).
    Add(AddArgs),
    /// The jobs running, waiting and queued, and the last ones finished.
    List(TargetArgs),
    /// Remove a queued job (a running one is a scan: `surfscan abort` ends it).
    Remove(RemoveArgs),
    /// Remove every queued job (the running one goes on).
    Clear(TargetArgs),
    /// Run the next job after a failure that stopped the queue (`[queue] stop-on-failure`).
    Continue(TargetArgs),
}

/// The daemon only.
#[derive(Debug, clap::Args)]
pub struct TargetArgs {
    /// The daemon.
    #[command(flatten)]
    pub target: Target,
}

/// Arguments of `surfscan queue add`.
#[derive(Debug, clap::Args)]
pub struct AddArgs {
    /// The daemon.
    #[command(flatten)]
    pub target: Target,
    /// The recipe (`NAME.toml` in the station's `[jobs] recipes` directory); its text is
    /// frozen into the job now.
    #[arg(long, value_name = "NAME")]
    pub recipe: String,
    /// Specimen id, recorded with the scan.
    #[arg(long, value_name = "ID")]
    pub specimen: String,
    /// y of the first line, mm (machine coordinates): where this specimen sits on the
    /// fixture [default: the recipe's, else the station's].
    #[arg(long, value_name = "Y", allow_negative_numbers = true)]
    pub y_start_mm: Option<f64>,
    /// A person must load the specimen first: the job waits in its turn until `surfscan ready`.
    #[arg(long)]
    pub needs_loading: bool,
    /// Operator name, recorded with the scan [default: $USER].
    #[arg(long, value_name = "NAME")]
    pub operator: Option<String>,
    /// Free-text notes, recorded with the scan.
    #[arg(long, value_name = "TEXT", default_value = "")]
    pub notes: String,
}

/// Arguments of `surfscan queue remove`.
#[derive(Debug, clap::Args)]
pub struct RemoveArgs {
    /// The daemon.
    #[command(flatten)]
    pub target: Target,
    /// The job's number (`surfscan queue list`).
    #[arg(value_name = "JOB")]
    pub job: u64,
}

/// Arguments of `surfscan ready`.
#[derive(Debug, clap::Args)]
pub struct ReadyArgs {
    /// The daemon.
    #[command(flatten)]
    pub target: Target,
    /// The job whose specimen is loaded [default: the one waiting].
    #[arg(value_name = "JOB")]
    pub job: Option<u64>,
}

/// Runs `surfscan queue …`.
pub fn run(args: Args) -> Result<(), CliError> {
    match args.command {
        QueueCommand::Add(a) => {
            let y_start_mm = start_args::y_start_mm(a.y_start_mm)?;
            send_command(
                &a.target,
                Request::QueueAdd {
                    recipe: a.recipe,
                    specimen: a.specimen,
                    operator: start_args::operator_or_user(a.operator),
                    notes: a.notes,
                    y_start_mm,
                    needs_loading: a.needs_loading,
                },
            )
        }
        QueueCommand::List(a) => send_command(&a.target, Request::QueueList),
        QueueCommand::Remove(a) => send_command(&a.target, Request::QueueRemove { job: a.job }),
        QueueCommand::Clear(a) => send_command(&a.target, Request::QueueClear),
        QueueCommand::Continue(a) => send_command(&a.target, Request::QueueContinue),
    }
}

/// Runs `surfscan ready`.
pub fn run_ready(args: ReadyArgs) -> Result<(), CliError> {
    send_command(&args.target, Request::Ready { job: args.job })
}

/// Finished jobs `queue list` shows (the file keeps more; `surfscan list` has every scan).
const FINISHED_SHOWN: usize = 10;

fn state_text(q: &Queue, j: &Job) -> String {
    match &j.state {
        JobState::Running {
            scan_id: Some(s), ..
        } => format!("running: scan {s}"),
        JobState::Running { scan_id: None, .. } => "starting".to_owned(),
        JobState::Queued { loaded } => {
            let next = q.pending().find(|p| p.is_queued()).map(|p| p.id) == Some(j.id);
            let running = q
                .pending()
                .any(|p| matches!(p.state, JobState::Running { .. }));
            match (j.request.needs_loading, loaded, next && !running) {
                (true, false, true) => {
                    "waiting for its specimen: load it, then `surfscan ready`".to_owned()
                }
                (true, false, false) => "queued (needs loading)".to_owned(),
                (true, true, _) => "queued (specimen loaded)".to_owned(),
                _ => "queued".to_owned(),
            }
        }
        JobState::Finished {
            outcome,
            verdict,
            scan_id,
            ..
        } => {
            let mut s = outcome.clone();
            if let Some(v) = verdict {
                let _ = write!(s, ": {v}");
            }
            if let Some(id) = scan_id {
                let _ = write!(s, " (scan {id})");
            }
            s
        }
    }
}

fn row(q: &Queue, j: &Job) -> String {
    let r = &j.request;
    let y = r
        .y_start_mm
        .map(|y| format!(" at y = {} mm", fmt(y, Quantity::PositionMm)))
        .unwrap_or_default();
    format!(
        "  {:>4}  {} {:?}{y} — {}\n",
        j.id,
        r.recipe.name,
        r.specimen,
        state_text(q, j)
    )
}

/// The queue for people: the pending jobs in the order they run, why the queue is stopped,
/// and the last finished jobs.
pub fn render(q: &Queue) -> String {
    let mut out = String::new();
    let pending: Vec<&Job> = q.pending().collect();
    if pending.is_empty() {
        out.push_str("no job is queued\n");
    } else {
        let _ = writeln!(out, "{} jobs, in the order they run:", pending.len());
        for j in &pending {
            out.push_str(&row(q, j));
        }
    }
    if let Some(why) = &q.held {
        let _ = writeln!(out, "the queue is stopped: {why}");
    }
    let finished: Vec<&Job> = q
        .jobs
        .iter()
        .filter(|j| matches!(j.state, JobState::Finished { .. }))
        .collect();
    if !finished.is_empty() {
        let shown = &finished[finished.len().saturating_sub(FINISHED_SHOWN)..];
        let _ = writeln!(out, "finished (the last {}):", shown.len());
        for j in shown {
            out.push_str(&row(q, j));
        }
    }
    out
}
