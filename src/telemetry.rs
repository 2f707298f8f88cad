//! Logging setup: journald with structured fields when running under systemd's journal,
//! plain stderr otherwise. Started before the config is parsed so config errors are logged.
//!
//! On stderr, colours (ANSI escapes) are used only when stderr is a terminal and `NO_COLOR`
//! is unset, so a log redirected to a file is plain text. While a foreground command shows a
//! progress bar ([`set_progress_bar`]), each log line is printed above the bar instead of
//! over it.
//!
//! Layer 4 (process edge): depends on nothing in the crate.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use tracing_subscriber::fmt::MakeWriter;
use tracing_subscriber::{layer::SubscriberExt, util::SubscriberInitExt, EnvFilter};

/// The progress bar log lines must be printed around, if one is shown.
static BAR: Mutex<Option<indicatif::ProgressBar>> = Mutex::new(None);

/// Sets (or with `None` clears) the progress bar that log lines are printed above.
pub fn set_progress_bar(bar: Option<indicatif::ProgressBar>) {
    if let Ok(mut slot) = BAR.lock() {
        *slot = bar;
    }
}

/// Standard error, written around the progress bar when one is shown. The fmt layer writes
/// each event with one `write_all`, so a line is never split by a redraw of the bar.
#[derive(Debug, Clone, Copy, Default)]
pub struct StderrAroundBar;

impl Write for StderrAroundBar {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let bar = BAR.lock().ok().and_then(|b| b.clone());
        match bar {
            Some(bar) if !bar.is_hidden() => {
                bar.suspend(|| std::io::stderr().write_all(buf))?;
            }
            _ => std::io::stderr().write_all(buf)?,
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

impl<'a> MakeWriter<'a> for StderrAroundBar {
    type Writer = StderrAroundBar;

    fn make_writer(&'a self) -> Self::Writer {
        StderrAroundBar
    }
}

/// Whether log lines on stderr get colours: only on a terminal, and not with `NO_COLOR` set
/// (<https://no-color.org>).
pub fn stderr_colours(stderr_is_terminal: bool, no_color: Option<&std::ffi::OsStr>) -> bool {
    stderr_is_terminal && no_color.is_none_or(|v| v.is_empty())
}

/// Installs the global subscriber. `RUST_LOG` overrides the default level (`info`, or
/// `debug` with `verbose`). Safe to call once per process; later calls are ignored.
pub fn init(verbose: bool) {
    let default = if verbose { "debug" } else { "info" };
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default));
    // JOURNAL_STREAM is set by systemd when stderr is connected to the journal.
    let under_journal = std::env::var_os("JOURNAL_STREAM").is_some();
    if under_journal {
        if let Ok(journald) = tracing_journald::layer() {
            let _ = tracing_subscriber::registry()
                .with(filter)
                .with(journald)
                .try_init();
            return;
        }
    }
    let _ = tracing_subscriber::registry()
        .with(filter)
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(StderrAroundBar)
                .with_ansi(stderr_colours(
                    std::io::stderr().is_terminal(),
                    std::env::var_os("NO_COLOR").as_deref(),
                ))
                .with_target(false)
                // A log line that cannot be written (stderr's reader has gone, a terminal
                // hung up) is dropped: reporting that on stderr would panic, and the scan
                // must go on.
                .log_internal_errors(false),
        )
        .try_init();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_only_on_a_terminal_without_no_color() {
        assert!(stderr_colours(true, None));
        assert!(!stderr_colours(false, None));
        assert!(!stderr_colours(true, Some(std::ffi::OsStr::new("1"))));
        // An empty NO_COLOR does not count (no-color.org).
        assert!(stderr_colours(true, Some(std::ffi::OsStr::new(""))));
    }
}
