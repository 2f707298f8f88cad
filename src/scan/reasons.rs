//! The texts people read about a scan's faults and suspensions — the status's reason, the
//! journal's interruption notes, the notification hook's reason — made apart from the
//! decisions ([`super::policy`]), so that a wording can change without touching a rule and
//! a rule without touching a wording. Each function says what one text is for.
//!
//! Layer 3 (session), pure: depends on [`crate::devices`] and chrono for the time stamps.

use crate::devices::{Device, Fault, FaultClass};
use chrono::{DateTime, SecondsFormat, Utc};
use std::time::Duration;

/// A time stamp as the texts show it (RFC 3339, seconds, `Z`).
pub fn stamp(t: DateTime<Utc>) -> String {
    t.to_rfc3339_opts(SecondsFormat::Secs, true)
}

/// Bytes as megabytes with one decimal.
pub fn mb(bytes: u64) -> String {
    format!("{:.1}", bytes as f64 / 1e6)
}

/// Why a scan failed when writing its outputs panicked (a bug; `panic` is its message): the
/// lines in `dir` are safe, the bug is to be reported, and the outputs can be made by hand.
pub fn outputs_internal(panic: &str, dir: &std::path::Path) -> String {
    let d = dir.display();
    format!(
        "internal error: writing the outputs panicked ({panic}); every line is on disk, but the outputs were not made because of a bug: report it with the scan's directory and the log; make them by hand with `surfscan fit {d}` and `surfscan analyze {d}`, or again with `surfscan scan --resume`"
    )
}

/// A fault on line `line` (0-based), as the last fault of a retried line names it.
pub fn on_line(line: u32, what: &dyn std::fmt::Display) -> String {
    format!("line {}: {what}", line + 1)
}

/// The status reason (and first journal note) while a device cannot be opened again, or
/// does not answer.
pub fn unavailable(device: Device, fault: &Fault) -> String {
    match fault.class {
        FaultClass::Silent => {
            format!("{device} not answering ({fault}); trying it again, without a time limit")
        }
        _ => format!("{device} unavailable ({fault}); reconnecting"),
    }
}

/// Why a scan started: a new one, or one reopened with `done` of its `total` lines on disk.
pub fn started(done: u32, total: u32) -> String {
    if done == 0 {
        format!("a scan of {total} lines started")
    } else {
        format!("continued with {done} of {total} lines on disk")
    }
}

/// The note when a device the scan waited for is back.
pub fn back_after(device: Device, waited: Duration) -> String {
    format!(
        "{device} back after {:.0} s; scan continues",
        waited.as_secs_f64()
    )
}

/// The note when a device vanished in the middle of line `line` (0-based).
pub fn line_abandoned(line: u32, fault: &Fault) -> String {
    format!("line {} abandoned: {fault}", line + 1)
}

/// The note when the stage lost its position on line `line` and is re-homed (the
/// `done`-th re-home of `allowed`).
pub fn rehoming(line: u32, fault: &Fault, done: u32, allowed: u32) -> String {
    format!(
        "line {} abandoned: {fault}; re-homing ({done} of {allowed} allowed)",
        line + 1
    )
}

/// What a line is retried for within the transient budget, as its reason names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Retried {
    /// The device said "not now" (busy, still processing).
    Busy,
    /// The device answered wrongly or not in time (garbled, cut off, a trace or move that
    /// does not end, a missed target).
    Wrong,
    /// The traced line cannot be used as read (a height that is no number, another point
    /// count than the scan's).
    UnusableLine,
}

/// The status reason while a line is retried within the transient budget, for `why`.
pub fn retried(
    device: Device,
    why: Retried,
    since: DateTime<Utc>,
    left: Duration,
    last: &str,
) -> String {
    let what = match why {
        Retried::Busy => "busy",
        Retried::Wrong => "answering wrongly or not in time",
        Retried::UnusableLine => "giving lines that cannot be used",
    };
    format!(
        "{device} {what} since {}; retrying the line (budget left {} s); last: {last}",
        stamp(since),
        left.as_secs()
    )
}

/// The journal note of one retry.
pub fn retrying(reason: &str, wait: Duration) -> String {
    format!(
        "suspended: {reason}; trying again in {:.1} s",
        wait.as_secs_f64()
    )
}

/// The note when line `line` is on disk after a suspension of `waited`.
pub fn on_disk_after_faults(line: u32, waited: Duration) -> String {
    format!(
        "line {} on disk after {:.0} s of faults; scan continues",
        line + 1,
        waited.as_secs_f64()
    )
}

/// What a full disk held up: the outputs, or line `line` (0-based).
pub fn held_up(outputs: bool, line: u32) -> String {
    if outputs {
        "the surface and report".to_owned()
    } else {
        format!("line {}", line + 1)
    }
}

/// The status reason (and the note, after `suspended: `) when the disk is full.
pub fn disk_full(what: &str, message: &str, needed_bytes: u64) -> String {
    format!(
        "disk full while writing {what} ({message}); the remaining lines need about {} MB; waiting for space",
        mb(needed_bytes)
    )
}

/// The status reason while the disk stays too full (of bytes or of inodes).
pub fn still_full(
    since: DateTime<Utc>,
    free_bytes: u64,
    free_inodes: u64,
    needed_bytes: u64,
    needed_inodes: u64,
) -> String {
    if free_inodes < needed_inodes {
        format!(
            "disk full since {}: {free_inodes} inodes (files) free, the remaining lines need about {needed_inodes}; delete files in the output directory's file system",
            stamp(since)
        )
    } else {
        format!(
            "disk full since {}: {} MB free, the remaining lines need about {} MB; free space in the output directory",
            stamp(since),
            mb(free_bytes),
            mb(needed_bytes)
        )
    }
}

/// The symbolic name of an error number the file system gives a refused write.
pub fn errno_name(errno: i32) -> Option<&'static str> {
    Some(match errno {
        libc::EPERM => "EPERM",
        libc::EACCES => "EACCES",
        libc::EROFS => "EROFS",
        libc::EIO => "EIO",
        libc::ENOSPC => "ENOSPC",
        libc::EDQUOT => "EDQUOT",
        libc::ENOENT => "ENOENT",
        libc::ENOTDIR => "ENOTDIR",
        libc::EISDIR => "EISDIR",
        libc::ESTALE => "ESTALE",
        libc::ENODEV => "ENODEV",
        libc::ENXIO => "ENXIO",
        libc::ETIMEDOUT => "ETIMEDOUT",
        _ => return None,
    })
}

/// The status reason (and the note, after `suspended: `) when the file system refused a
/// write for another reason than space.
pub fn storage_refused(what: &str, errno: Option<i32>, message: &str) -> String {
    let (code, fix) = refusal_words(errno);
    format!(
        "the file system refused writing {what} ({code}{message}); it is kept in memory and written again with backoff, and the scan goes on by itself; {fix}"
    )
}

/// The error's symbolic name (`EROFS: `, empty when not known) and the fix the operator can
/// make, for a refusal of the file system with `errno`.
fn refusal_words(errno: Option<i32>) -> (String, &'static str) {
    let code = errno
        .and_then(errno_name)
        .map_or(String::new(), |n| format!("{n}: "));
    let fix = match errno {
        Some(libc::EROFS) => "remount the output directory's file system read-write",
        Some(libc::EPERM) => {
            "make the output directory writable (an immutable attribute: chattr -i)"
        }
        Some(libc::EACCES) => "give the daemon's user write permission on the output directory",
        Some(libc::EIO) => "check the disk (a USB disk or a network file system that went away)",
        _ => "make the output directory writable",
    };
    (code, fix)
}

/// The reason a scan is not reopened when the file system refused `what` (reading or
/// writing its files): a condition that can clear, so the scan is left as it is.
pub fn reopening_refused(what: &str, errno: Option<i32>, message: &str) -> String {
    let (code, fix) = refusal_words(errno);
    format!(
        "the file system refused {what} ({code}{message}); the scan is left as it is and reopened once the file system allows it (the daemon tries it again with the reconnection backoff); {fix}"
    )
}

/// The reason a scan is not reopened when its own files cannot be read back as a scan
/// (`what`: its journal's records, a line the fitter refuses): the operator's to repair or
/// give up; nothing reopens it by itself.
pub fn reopening_impossible(what: &str, message: &str) -> String {
    format!(
        "the scan cannot be reopened: {what}: {message}; nothing reopens it by itself: repair its files and continue it with `surfscan start --resume`, or begin a new scan with a plain `surfscan start`"
    )
}

/// The note when the file system takes writes again after refusing them.
pub fn storage_back(waited: Duration) -> String {
    format!(
        "the output directory takes writes again after {:.0} s; scan continues",
        waited.as_secs_f64()
    )
}

/// The note when space is back.
pub fn space_back(free_bytes: u64, waited: Duration) -> String {
    format!(
        "space is back ({} MB free) after {:.0} s; scan continues",
        mb(free_bytes),
        waited.as_secs_f64()
    )
}

/// The note and status reason when the operator's pause takes effect after line `line`.
pub fn paused_after(line: u32) -> String {
    format!("paused by the operator after line {}", line + 1)
}

/// The status reason of a scan reopened paused after a restart.
pub fn paused_before_restart() -> String {
    "paused by the operator before a restart; `surfscan resume` continues it".to_owned()
}

/// The note of a shutdown while paused, `done` of `total` lines on disk.
pub fn shutdown_while_paused(done: u32, total: u32) -> String {
    format!(
        "shutdown (SIGTERM/SIGINT) while paused with {done} of {total} lines on disk; the daemon reopens it paused at its next start"
    )
}

/// The note of a shutdown in the middle of a line.
pub fn shutdown_mid_line() -> String {
    "shutdown (SIGTERM/SIGINT): current line abandoned; the scan resumes at the next start"
        .to_owned()
}
