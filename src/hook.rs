//! The notification hook: an operator-configured command run when a scan completes, fails,
//! is aborted or suspends, e.g. to send a mail or a chat message.
//!
//! The hook can never hold up or endanger the scan: it is spawned as its own task, run
//! without a shell (an argv list), in its own process group so that everything it starts is
//! killed when its time is up, with stdin closed and stdout/stderr going to the daemon's log
//! stream. Whatever happens to it (cannot start, non-zero exit, killed on timeout) is logged
//! with the command and the cause and otherwise ignored.
//!
//! The command sees the event's `SURFSCAN_*` variables (set where it is spawned) and a
//! completed scan's results ([`crate::scan::results::ScanResults::env`]; every one set, empty
//! when it does not apply); their one full list, for the people who write hooks, is
//! docs/integration.md's "The notification hook". systemd's notification variables are
//! removed so the hook cannot speak to the service manager on the daemon's behalf.
//!
//! Layer 4 (process edge): depends on the scan's events ([`crate::scan::event`]), tokio's
//! process support, nix for the process group and serde for [`HookSettings`].

use crate::scan::event::ScanEvent;
use serde::{Deserialize, Serialize};
use std::process::{ExitStatus, Stdio};
use std::time::Duration;

fn default_timeout_s() -> u64 {
    30
}

/// `[notify]` in the config: the hook command and how long it may run.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct HookSettings {
    /// Program and arguments, e.g. `["/usr/local/bin/scan-done", "--mail", "lab@example.org"]`;
    /// no shell is involved. Empty: no hook.
    #[serde(default)]
    pub command: Vec<String>,
    /// Seconds the hook may run before it (and everything it started) is killed; default 30.
    #[serde(default = "default_timeout_s")]
    pub timeout_s: u64,
}

impl Default for HookSettings {
    fn default() -> HookSettings {
        HookSettings {
            command: Vec::new(),
            timeout_s: default_timeout_s(),
        }
    }
}

/// A `[notify]` table that cannot work.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HookSettingsError {
    /// `command = [""]` or similar.
    #[error("[notify] command starts with an empty program name; give the program's path first, e.g. command = [\"/usr/local/bin/scan-done\"]")]
    EmptyProgram,
    /// `timeout-s = 0`.
    #[error("[notify] timeout-s must be at least 1 second (got 0); the default is 30")]
    ZeroTimeout,
}

impl HookSettings {
    /// Checks the settings; the config module reports the error with exit status 78.
    pub fn validate(&self) -> Result<(), HookSettingsError> {
        if self.command.first().is_some_and(|p| p.is_empty()) {
            return Err(HookSettingsError::EmptyProgram);
        }
        if self.timeout_s == 0 {
            return Err(HookSettingsError::ZeroTimeout);
        }
        Ok(())
    }
}

/// How one hook run ended.
#[derive(Debug)]
pub enum HookOutcome {
    /// Exit status 0.
    Succeeded,
    /// It ran and exited non-zero or was killed by a signal.
    Failed(ExitStatus),
    /// It was still running after the timeout and was killed with its process group.
    TimedOut,
    /// It could not be started (missing program, not executable, …).
    NotStarted(std::io::Error),
    /// Waiting for it failed.
    WaitFailed(std::io::Error),
}

/// A configured hook, ready to fire.
#[derive(Debug, Clone)]
pub struct Hook {
    command: Vec<String>,
    timeout: Duration,
}

impl Hook {
    /// The hook the settings describe, or `None` when no command is configured.
    pub fn new(settings: &HookSettings) -> Option<Hook> {
        let program = settings.command.first()?;
        if program.is_empty() {
            return None;
        }
        Some(Hook {
            command: settings.command.clone(),
            timeout: Duration::from_secs(settings.timeout_s.max(1)),
        })
    }

    /// Starts the hook in its own task and returns at once; the outcome is logged, and the
    /// handle may be awaited or dropped. Must be called inside a tokio runtime.
    pub fn fire(&self, event: ScanEvent) -> tokio::task::JoinHandle<HookOutcome> {
        let hook = self.clone();
        tokio::spawn(async move { hook.run(&event).await })
    }

    /// Runs the hook to completion or timeout and logs anything but success.
    pub async fn run(&self, event: &ScanEvent) -> HookOutcome {
        let outcome = self.run_quietly(event).await;
        let command = self.command.join(" ");
        let scan = event.scan_id.as_str();
        let status = event.kind.as_str();
        match &outcome {
            HookOutcome::Succeeded => {
                tracing::info!(command, scan, status, "notification hook done")
            }
            HookOutcome::Failed(exit) => {
                tracing::warn!(command, scan, status, %exit, "notification hook failed: {exit}")
            }
            HookOutcome::TimedOut => tracing::warn!(
                command,
                scan,
                status,
                timeout_s = self.timeout.as_secs(),
                "notification hook killed: still running after {} s",
                self.timeout.as_secs()
            ),
            HookOutcome::NotStarted(e) => tracing::warn!(
                command,
                scan,
                status,
                error = %e,
                "notification hook could not be started: {e}; check [notify] command"
            ),
            HookOutcome::WaitFailed(e) => {
                tracing::warn!(command, scan, status, error = %e, "notification hook: waiting failed: {e}")
            }
        }
        outcome
    }

    async fn run_quietly(&self, event: &ScanEvent) -> HookOutcome {
        let mut cmd = tokio::process::Command::new(&self.command[0]);
        cmd.args(&self.command[1..])
            .env("SURFSCAN_SCAN_ID", &event.scan_id)
            .env("SURFSCAN_STATUS", event.kind.as_str())
            .env("SURFSCAN_REASON", &event.reason)
            .env("SURFSCAN_SCAN_DIR", &event.dir)
            .env("SURFSCAN_INTERNAL", if event.internal { "1" } else { "0" })
            .envs(event.results.clone().unwrap_or_default().env())
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .env_remove("WATCHDOG_PID")
            .env_remove("LISTEN_FDS")
            .env_remove("LISTEN_PID")
            .stdin(Stdio::null())
            .process_group(0)
            .kill_on_drop(true);
        let mut child = match cmd.spawn() {
            Ok(c) => c,
            Err(e) => return HookOutcome::NotStarted(e),
        };
        match tokio::time::timeout(self.timeout, child.wait()).await {
            Ok(Ok(exit)) if exit.success() => HookOutcome::Succeeded,
            Ok(Ok(exit)) => HookOutcome::Failed(exit),
            Ok(Err(e)) => HookOutcome::WaitFailed(e),
            Err(_elapsed) => {
                if let Some(pid) = child.id() {
                    // The hook leads its own group (process_group(0)): kill what it started too.
                    let group = nix::unistd::Pid::from_raw(pid as i32);
                    let _ = nix::sys::signal::killpg(group, nix::sys::signal::Signal::SIGKILL);
                }
                let _ = child.start_kill();
                let _ = child.wait().await;
                HookOutcome::TimedOut
            }
        }
    }
}
