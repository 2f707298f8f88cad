//! The command line: one subcommand per file, each with its own arguments and `run`.
//!
//! Exit codes follow sysexits(3) so scripts and systemd can tell causes apart: 0 success,
//! 1 the job failed (`contact`: the contact cannot be computed), 2 usage, 3 done but the result is partial (`scan`, `demo`, `analyze`,
//! `fit`: every output that could be made is written; made from fewer lines than the input
//! holds, "N of M lines", or report.json's `characterisation.failed_sections` names each
//! section that could not be made and why),
//! 69 device unavailable, 74 I/O error, 78 bad configuration.
//!
//! Layer 5 (composition): may depend on everything.

use clap::{Parser, Subcommand};
use std::fmt;

/// A line on standard output that never panics ([`console`]).
macro_rules! say {
    () => {
        $crate::cli::console::out(format_args!(""), true)
    };
    ($($arg:tt)*) => {
        $crate::cli::console::out(format_args!($($arg)*), true)
    };
}

/// Text on standard output as it is, without a newline ([`console`]).
macro_rules! say_text {
    ($($arg:tt)*) => {
        $crate::cli::console::out(format_args!($($arg)*), false)
    };
}

/// A line on standard error that never panics ([`console`]).
macro_rules! tell {
    ($($arg:tt)*) => {
        $crate::cli::console::err(format_args!($($arg)*))
    };
}

pub mod analyze;
pub mod check_config;
pub mod console;
pub mod contact;
pub mod control;
pub mod daemon;
mod daemon_jobs;
#[cfg(feature = "sim")]
pub mod demo;
pub mod docs;
pub mod export;
pub mod fit;
pub mod input_args;
pub mod list;
pub mod model_args;
pub mod probe;
pub mod queue;
pub mod report;
pub mod scan;
pub mod start_args;
pub mod station;

/// The station configuration read when `--config` is not given.
pub const DEFAULT_CONFIG: &str = "/etc/surfscan/surfscan.toml";

/// surfscan: unattended surface-roughness scanning with an SJ-210 and a y stage.
#[derive(Debug, Parser)]
#[command(name = "surfscan", version = crate::build_info::LONG_VERSION, about)]
pub struct Cli {
    /// More detailed logging (same as RUST_LOG=debug).
    #[arg(short, long, global = true)]
    pub verbose: bool,
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit a NURBS surface to a grid CSV or a scan directory and write it as IGES.
    Fit(fit::Args),
    /// Read-only first-hour checklist on the instrument (moves the stylus only with --trace).
    Probe(probe::Args),
    /// Characterise a scan directory, an X3P file, or a profile or grid CSV: ISO roughness per line, areal parameters, bearing area curves, plots, X3P.
    Analyze(analyze::Args),
    /// The contact of a measured surface with a rigid flat or a second elastic body: load–area curve, pressure map (contact.json).
    Contact(contact::Args),
    /// Run one scan in the foreground (resuming an unfinished scan of this configuration).
    Scan(scan::Args),
    /// The station service (systemd Type=notify): resumes unfinished scans, takes commands on the control socket.
    Daemon(daemon::Args),
    /// A complete simulated scan: simulator in-process, real serial code path, IGES and report.
    #[cfg(feature = "sim")]
    Demo(demo::Args),
    /// Show the daemon's status (with --watch: on every change).
    Status(control::StatusArgs),
    /// Pause the running scan after the current line is on disk.
    Pause(control::CommandArgs),
    /// Resume a paused scan.
    Resume(control::CommandArgs),
    /// Abort the running scan (recorded as abort).
    Abort(control::CommandArgs),
    /// Start a scan of the configured plan, and wait until it is under way (exit 1 with the reason when it cannot begin).
    Start(control::StartArgs),
    /// Check a station configuration and its recipes without opening any device (exit 78 when invalid).
    CheckConfig(check_config::Args),
    /// List the scans on the station: state, recipe, specimen, verdict, Ra and Sa, warnings.
    List(list::Args),
    /// Write completed scans' Q-DAS (.dfq) and QIF (.qif) files into the drop directories again.
    Export(export::Args),
    /// Write a report as a PDF (`--pdf`): the printed report, without a browser.
    Report(report::Args),
    /// The job queue: add a recipe's scan of a specimen, list, remove, clear, continue.
    Queue(queue::Args),
    /// The specimen of the job waiting for loading is in place: let the job start.
    Ready(queue::ReadyArgs),
    /// Print the shell completion script for bash, zsh, fish, elvish or powershell.
    Completions(docs::CompletionsArgs),
    /// Write the man pages (surfscan.1 and one per subcommand) into a directory.
    Manpages(docs::ManpagesArgs),
}

/// Process exit status (sysexits).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    /// 0: success.
    Ok = 0,
    /// 1: the job ran and failed.
    Failed = 1,
    /// 2: usage error.
    Usage = 2,
    /// 3: the job is done and its outputs are written, but the result is partial: made from
    /// fewer lines than the input holds, or part of the characterisation could not be made
    /// (report.json's `characterisation` says which and why).
    Partial = 3,
    /// 4: the scan is complete and characterised, and the part does not conform to its
    /// recipe's specification (report.json's `specification` says which limits and lines).
    DoesNotConform = 4,
    /// 69: a device is unavailable.
    Unavailable = 69,
    /// 70: internal error: a part of the process panicked (`panics`); report it.
    Internal = 70,
    /// 74: input/output error (files, disk).
    Io = 74,
    /// 78: configuration error.
    Config = 78,
}

/// A command's failure: the exit status and a message that names the cause and the fix.
#[derive(Debug)]
pub struct CliError {
    /// Exit status.
    pub exit: Exit,
    /// Message for the operator.
    pub message: String,
}

impl CliError {
    /// Builds an error with an exit status.
    pub fn new(exit: Exit, message: impl Into<String>) -> CliError {
        CliError {
            exit,
            message: message.into(),
        }
    }
}

/// A start that could not be decided or carried out: an I/O error (exit 74) or a refusal
/// (exit 1), named.
impl From<crate::scan::choice::ChoiceError> for CliError {
    fn from(e: crate::scan::choice::ChoiceError) -> CliError {
        use crate::scan::choice::ChoiceError;
        match e {
            ChoiceError::Io(m) => CliError::new(Exit::Io, m),
            ChoiceError::Refused(m) => CliError::new(Exit::Failed, m),
        }
    }
}

/// A recipe refused as given (a usage error, exit 2) or not fit for the station (exit 78), named.
impl From<crate::jobs::recipe::RecipeError> for CliError {
    fn from(e: crate::jobs::recipe::RecipeError) -> CliError {
        let exit = if e.is_usage() {
            Exit::Usage
        } else {
            Exit::Config
        };
        CliError::new(exit, e.to_string())
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// Reads a TOML file as a plain table, for commands that take one table of a station
/// configuration and ignore the rest; unreadable or invalid files are exit 78.
pub fn read_toml_table(path: &std::path::Path) -> Result<toml::Table, CliError> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        CliError::new(
            Exit::Config,
            format!("cannot read config {}: {e}", path.display()),
        )
    })?;
    toml::from_str(&text).map_err(|e| {
        CliError::new(
            Exit::Config,
            format!("config {} is not valid TOML: {e}", path.display()),
        )
    })
}

/// Runs the parsed command.
pub fn run(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::Fit(args) => fit::run(args),
        Command::Probe(args) => probe::run(args),
        Command::Analyze(args) => analyze::run(args),
        Command::Contact(args) => contact::run(args),
        Command::Scan(args) => scan::run(args),
        Command::Daemon(args) => daemon::run(args),
        #[cfg(feature = "sim")]
        Command::Demo(args) => demo::run(args),
        Command::Status(args) => control::run_status(args),
        Command::Pause(args) => control::run_command(control::Verb::Pause, args),
        Command::Resume(args) => control::run_command(control::Verb::Resume, args),
        Command::Abort(args) => control::run_command(control::Verb::Abort, args),
        Command::Start(args) => control::run_start(args),
        Command::CheckConfig(args) => check_config::run(args),
        Command::List(args) => list::run(args),
        Command::Export(args) => export::run(args),
        Command::Report(args) => report::run(args),
        Command::Queue(args) => queue::run(args),
        Command::Ready(args) => queue::run_ready(args),
        Command::Completions(args) => docs::run_completions(args),
        Command::Manpages(args) => docs::run_manpages(args),
    }
}
