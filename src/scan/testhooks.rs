//! Fault injection for end-to-end tests of the real binary: a crash (`abort()`, like
//! `kill -9` at an exact point) or a refused write (`ENOSPC`, like a full disk) at a chosen
//! step of a chosen line. Selected by environment variables that nothing else sets:
//!
//! - `SURFSCAN_TEST_CRASH=LINE:STEP` — abort the process at STEP of line LINE (0-based);
//!   STEP is `before-csv`, `before-json`, `before-journal` or `after-commit`.
//! - `SURFSCAN_TEST_ENOSPC=LINE:STEP` — make that write fail with "No space left on device";
//!   STEP is `before-csv`, `before-json` or `before-journal`. Only that one write fails: the
//!   records that follow it (the stop record saying why) are written.
//!
//! - `SURFSCAN_TEST_STALL=N:SECONDS` — the N-th trace of the process (1-based) never ends, a
//!   stuck future that no deadline of the drivers bounds, and the longest a device effect may
//!   take becomes SECONDS: the runner then stops feeding the systemd watchdog after SECONDS,
//!   as it would after the longest real effect.
//!
//! Without those variables the hook does nothing. It is the [`StorageFaults`] the store
//! and journal consult before every durable write.
//!
//! Layer 3 (session): depends on [`super::faults`]; reads two environment variables.

use super::faults::{StorageFaults, WriteStep};
use std::io;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// The points a test can stop at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Before the heights file is written.
    BeforeCsv,
    /// After the heights file, before the metadata file.
    BeforeJson,
    /// After both line files, before the journal record.
    BeforeJournal,
    /// After the journal record, before the fitter and the next move.
    AfterCommit,
}

impl Step {
    fn parse(s: &str) -> Option<Step> {
        Some(match s {
            "before-csv" => Step::BeforeCsv,
            "before-json" => Step::BeforeJson,
            "before-journal" => Step::BeforeJournal,
            "after-commit" => Step::AfterCommit,
            _ => return None,
        })
    }

    fn of_write(step: WriteStep) -> Option<Step> {
        match step {
            WriteStep::LineCsv => Some(Step::BeforeCsv),
            WriteStep::LineJson => Some(Step::BeforeJson),
            WriteStep::Journal => Some(Step::BeforeJournal),
            WriteStep::Metrics => None,
        }
    }
}

fn parse_point(value: &str) -> Result<(u32, Step), String> {
    let (line, step) = value
        .split_once(':')
        .ok_or_else(|| format!("{value:?}: expected LINE:STEP"))?;
    let line = line
        .parse()
        .map_err(|_| format!("{value:?}: {line:?} is not a line index"))?;
    let step = Step::parse(step).ok_or_else(|| {
        format!("{value:?}: step must be before-csv, before-json, before-journal or after-commit")
    })?;
    Ok((line, step))
}

fn parse_stall(value: &str) -> Result<(u32, u64), String> {
    let (n, secs) = value
        .split_once(':')
        .ok_or_else(|| format!("{value:?}: expected N:SECONDS"))?;
    match (n.parse::<u32>(), secs.parse::<u64>()) {
        (Ok(n), Ok(secs)) if n >= 1 => Ok((n, secs)),
        _ => Err(format!(
            "{value:?}: N (from 1) and SECONDS must be whole numbers"
        )),
    }
}

/// The injected faults of one process.
#[derive(Debug, Default)]
pub struct TestHooks {
    crash: Option<(u32, Step)>,
    enospc: Option<(u32, Step)>,
    enospc_done: AtomicBool,
    line: AtomicU32,
    stall: Option<(u32, u64)>,
    traces: AtomicU32,
}

impl TestHooks {
    /// No faults.
    pub fn none() -> TestHooks {
        TestHooks::default()
    }

    /// Reads `SURFSCAN_TEST_CRASH` and `SURFSCAN_TEST_ENOSPC`; a malformed value is an error
    /// (a test that means to crash must not silently run to the end).
    pub fn from_env() -> Result<TestHooks, String> {
        let get = |name: &str| -> Result<Option<(u32, Step)>, String> {
            match std::env::var(name) {
                Ok(v) => parse_point(&v)
                    .map(Some)
                    .map_err(|e| format!("{name}: {e}")),
                Err(_) => Ok(None),
            }
        };
        Ok(TestHooks {
            crash: get("SURFSCAN_TEST_CRASH")?,
            enospc: get("SURFSCAN_TEST_ENOSPC")?,
            enospc_done: AtomicBool::new(false),
            line: AtomicU32::new(0),
            stall: match std::env::var("SURFSCAN_TEST_STALL") {
                Ok(v) => Some(parse_stall(&v).map_err(|e| format!("SURFSCAN_TEST_STALL: {e}"))?),
                Err(_) => None,
            },
            traces: AtomicU32::new(0),
        })
    }

    /// Called as a trace begins: the longest the effect may take instead of the real one
    /// when this trace is the one to stall (it then never ends), else `None`.
    pub fn trace_stalls(&self) -> Option<std::time::Duration> {
        let n = self.traces.fetch_add(1, Ordering::SeqCst) + 1;
        match self.stall {
            Some((at, secs)) if at == n => {
                eprintln!("surfscan: SURFSCAN_TEST_STALL: trace {n} never ends");
                Some(std::time::Duration::from_secs(secs))
            }
            _ => None,
        }
    }

    /// Tells the hook which line the next writes belong to.
    pub fn set_line(&self, index: u32) {
        self.line.store(index, Ordering::SeqCst);
    }

    /// Called at `step`; aborts the process when a crash is due there.
    pub fn at(&self, step: Step) {
        if self.crash == Some((self.line.load(Ordering::SeqCst), step)) {
            eprintln!("surfscan: SURFSCAN_TEST_CRASH: aborting at {step:?}");
            std::process::abort();
        }
    }
}

impl StorageFaults for TestHooks {
    fn before_write(&self, step: WriteStep, _path: &Path) -> io::Result<()> {
        let Some(step) = Step::of_write(step) else {
            return Ok(());
        };
        self.at(step);
        if self.enospc == Some((self.line.load(Ordering::SeqCst), step))
            && !self.enospc_done.swap(true, Ordering::SeqCst)
        {
            return Err(io::Error::from_raw_os_error(libc::ENOSPC));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_parse_and_bad_ones_are_named() {
        assert_eq!(parse_point("3:before-json"), Ok((3, Step::BeforeJson)));
        assert!(parse_point("3").unwrap_err().contains("LINE:STEP"));
        assert!(parse_point("x:before-csv")
            .unwrap_err()
            .contains("line index"));
        assert!(parse_point("1:later").unwrap_err().contains("before-csv"));
    }

    #[test]
    fn only_the_chosen_trace_stalls() {
        assert_eq!(parse_stall("3:5"), Ok((3, 5)));
        assert!(parse_stall("0:5").is_err() && parse_stall("3").is_err());
        let h = TestHooks {
            stall: Some((2, 5)),
            ..TestHooks::default()
        };
        assert_eq!(h.trace_stalls(), None);
        assert_eq!(h.trace_stalls(), Some(std::time::Duration::from_secs(5)));
        assert_eq!(h.trace_stalls(), None);
        assert_eq!(TestHooks::none().trace_stalls(), None);
    }

    #[test]
    fn enospc_hits_only_the_chosen_line_and_step() {
        let h = TestHooks {
            enospc: Some((2, Step::BeforeJournal)),
            ..TestHooks::default()
        };
        let p = Path::new("x");
        h.set_line(1);
        assert!(h.before_write(WriteStep::Journal, p).is_ok());
        h.set_line(2);
        assert!(h.before_write(WriteStep::LineCsv, p).is_ok());
        let e = h.before_write(WriteStep::Journal, p).unwrap_err();
        assert_eq!(e.raw_os_error(), Some(libc::ENOSPC));
        assert!(h.before_write(WriteStep::Metrics, p).is_ok());
        // The stop record that follows (same line, same step) is written.
        assert!(h.before_write(WriteStep::Journal, p).is_ok());
    }
}
