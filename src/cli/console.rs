//! What the commands print for the operator, on standard output and standard error, written
//! so that a reader who has gone away never stops the work: a pipe whose reader exited
//! (`surfscan status | head -1`), a terminal that hung up under a foreground scan, or a closed
//! descriptor. `println!` panics on such a write ("failed printing to stdout") and the
//! release build aborts; here the text is dropped instead, and a command whose output is
//! the point of it (`status --watch`) asks [`stdout_gone`] and ends.
//!
//! The macros `say!` (a line on standard output), `say_text!` (text as it is) and `tell!`
//! (a line on standard error) are defined in [`super`] for every command's module.
//!
//! Layer 5 (composition): depends on `std` only.

use std::fmt;
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set once a write to standard output has failed.
static STDOUT_GONE: AtomicBool = AtomicBool::new(false);

/// Set when standard output carries a command's data (`fit -o -`): the operator's lines go
/// to standard error instead.
static STDOUT_IS_DATA: AtomicBool = AtomicBool::new(false);

/// Sends every later `say!` line to standard error: standard output carries data.
pub fn stdout_carries_data() {
    STDOUT_IS_DATA.store(true, Ordering::Relaxed);
}

/// Writes `args` to standard output (standard error once [`stdout_carries_data`]), followed
/// by a newline when `newline`; a failure is remembered ([`stdout_gone`]) and the text
/// dropped.
pub fn out(args: fmt::Arguments<'_>, newline: bool) {
    if STDOUT_IS_DATA.load(Ordering::Relaxed) {
        let mut stderr = std::io::stderr().lock();
        let _ = stderr.write_fmt(args).and_then(|()| {
            if newline {
                stderr.write_all(b"\n")
            } else {
                Ok(())
            }
        });
        return;
    }
    let mut stdout = std::io::stdout().lock();
    let written = stdout
        .write_fmt(args)
        .and_then(|()| {
            if newline {
                stdout.write_all(b"\n")
            } else {
                Ok(())
            }
        })
        .and_then(|()| stdout.flush());
    if written.is_err() {
        STDOUT_GONE.store(true, Ordering::Relaxed);
    }
}

/// Writes `bytes` to standard output as they are (see [`out`]).
pub fn out_bytes(bytes: &[u8]) {
    let mut stdout = std::io::stdout().lock();
    if stdout
        .write_all(bytes)
        .and_then(|()| stdout.flush())
        .is_err()
    {
        STDOUT_GONE.store(true, Ordering::Relaxed);
    }
}

/// Writes `args` and a newline to standard error; a failure drops the text (there is nowhere
/// left to say so).
pub fn err(args: fmt::Arguments<'_>) {
    let mut stderr = std::io::stderr().lock();
    let _ = stderr
        .write_fmt(args)
        .and_then(|()| stderr.write_all(b"\n"));
}

/// Whether a write to standard output has failed: its reader is gone, so a command that
/// only prints may stop.
pub fn stdout_gone() -> bool {
    STDOUT_GONE.load(Ordering::Relaxed)
}
