//! Integration tests that change or measure process-wide state: the systemd environment
//! variables (`NOTIFY_SOCKET`, `WATCHDOG_*`) and this process's resident memory. They sit
//! apart from `tests/it/` so no other test runs in the same process while they do.

mod control_slow_watcher;
mod hook_run;
mod service_notify;

use std::sync::{Mutex, MutexGuard};

/// Held by every test here that reads or writes the process environment or measures this
/// process's memory, so the test harness's threads cannot run two of them at once.
pub fn process_state() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}
