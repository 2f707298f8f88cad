//! What a panic ends: its own piece of work where the process can go on without it, the
//! process where a part of it would be left stopped.
//!
//! The release build unwinds (`[profile.release] panic = "unwind"`; this crate does not
//! build without it), so a panic ends its thread, not the process, and is handled by layer:
//! - a report's sections and figures: the thread's join (or `catch_unwind`) gives the
//!   section's "internal: … panicked; report this with the input" and the rest of the
//!   report is written (`report`);
//! - a scan's reopening or outputs: the scan is refused or fails with that reason in its
//!   journal, and the daemon serves on (`scan::runner`);
//! - one request or connection (control socket, station's page, a notification): that one
//!   ends, the server serves on;
//! - a part of the process that must keep running (the control socket's server, the signal
//!   and status tasks, the publishers' links and writers, the station's page, the daemon's
//!   loop itself): [`spawn_vital`] and [`exit_internal`] end the process with
//!   [`EXIT_INTERNAL`], since a daemon scanning on without one of them would be half-alive
//!   (no stop on SIGTERM, no control socket, a status no longer sent). systemd's
//!   `Restart=on-failure` starts it again and an unfinished scan resumes from its journal.
//!
//! The panic's own message and place are printed by the standard hook (the journal has
//! them); what is logged here says what stopped and what happens next.
//!
//! Layer 2: tokio, futures and tracing only.

use futures::FutureExt;
use std::any::Any;
use std::future::Future;
use std::panic::AssertUnwindSafe;

#[cfg(not(panic = "unwind"))]
compile_error!(
    "surfscan handles panics by unwinding (src/panics.rs): build it with panic = \"unwind\""
);

/// The exit status of a process ended by a panic in one of its vital parts (sysexits'
/// `EX_SOFTWARE`); the unit restarts on it (`Restart=on-failure`).
pub const EXIT_INTERNAL: i32 = 70;

/// The text a panic was raised with (`panic!`'s message), or a placeholder.
pub fn message(payload: &(dyn Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("no message")
}

/// Logs that `what` panicked with `message` and ends the process with [`EXIT_INTERNAL`].
/// Files the process was writing are left as a kill leaves them: every durable write is
/// atomic (`atomic`), and the scan's journal is read back at the next start.
pub fn exit_internal(what: &str, message: &str) -> ! {
    tracing::error!(
        "internal error: {what} panicked ({message}); surfscan exits with status {EXIT_INTERNAL} (systemd restarts the daemon, and an unfinished scan resumes); report this with the log and the input"
    );
    std::process::exit(EXIT_INTERNAL)
}

/// Spawns `fut` on the current tokio runtime as a part the process cannot run without: its
/// panic ends the process ([`exit_internal`]) instead of only its task.
pub fn spawn_vital<F>(what: &'static str, fut: F) -> tokio::task::JoinHandle<F::Output>
where
    F: Future + Send + 'static,
    F::Output: Send + 'static,
{
    tokio::spawn(async move {
        match AssertUnwindSafe(fut).catch_unwind().await {
            Ok(v) => v,
            Err(p) => exit_internal(what, message(&*p)),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Set in the copy of this test binary that the test below starts.
    const CHILD: &str = "SURFSCAN_TEST_VITAL_PANIC";

    /// A panic in a [`spawn_vital`] task ends the whole process with status 70 while the
    /// rest of it (here the runtime's main future, asleep) would go on; the panic's message
    /// is on its standard error. The panic is raised in a copy of this test binary (the exit
    /// ends it), which runs only this test.
    #[test]
    fn a_vital_part_that_panics_ends_the_process() {
        if std::env::var_os(CHILD).is_some() {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(1)
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async {
                spawn_vital("the test's part", async {
                    panic!("a vital part failed after {} s", 0)
                });
                tokio::time::sleep(std::time::Duration::from_secs(10)).await;
            });
            return;
        }
        let name = "panics::tests::a_vital_part_that_panics_ends_the_process";
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--exact", name, "--nocapture"])
            .env(CHILD, "1")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(EXIT_INTERNAL), "{stderr}");
        assert!(stderr.contains("a vital part failed after 0 s"), "{stderr}");
    }

    /// The message of `panic!` with a literal (`&str`) and with arguments (`String`).
    #[test]
    fn a_panics_message_is_its_text() {
        let literal = std::panic::catch_unwind(|| panic!("literal")).unwrap_err();
        assert_eq!(message(&*literal), "literal");
        let formatted = std::panic::catch_unwind(|| panic!("line {}", 7)).unwrap_err();
        assert_eq!(message(&*formatted), "line 7");
    }
}
