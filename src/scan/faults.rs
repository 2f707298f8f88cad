//! The storage fault hook: consulted before every durable write of a scan (line files,
//! journal appends, metrics), so that tests can make a chosen write fail as the operating
//! system would (e.g. `ENOSPC`) and show that a scan fails cleanly. Production uses
//! [`NoFaults`].
//!
//! Layer 3 (session): depends on [`crate::atomic`] (the one durable-write primitive) and std.

use std::io;
use std::path::Path;

/// The write a [`StorageFaults`] hook is asked about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WriteStep {
    /// The `NNNN.csv` heights file of a line.
    LineCsv,
    /// The `NNNN.json` metadata file of a line.
    LineJson,
    /// A journal append.
    Journal,
    /// The metrics file.
    Metrics,
}

/// Injected before every durable write; returning an error makes that write fail as if the
/// operating system had refused it. Production code uses [`NoFaults`].
pub trait StorageFaults: Send + Sync {
    /// Called before `step` writes `path`; an `Err` aborts that write with this error.
    fn before_write(&self, step: WriteStep, path: &Path) -> io::Result<()>;
}

/// The hook that never fails.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoFaults;

impl StorageFaults for NoFaults {
    fn before_write(&self, _step: WriteStep, _path: &Path) -> io::Result<()> {
        Ok(())
    }
}

/// Replaces `path` with `bytes` durably ([`crate::atomic::write_regular_atomically`] for a
/// scan's files: only a regular file is replaced, never through a link; temporary file,
/// fsync, rename, fsync of the directory) after asking `faults` about `step`. On failure the
/// target is untouched and no temporary file is left.
pub fn write_file_durably(
    path: &Path,
    bytes: &[u8],
    step: WriteStep,
    faults: &dyn StorageFaults,
) -> io::Result<()> {
    faults.before_write(step, path)?;
    let body = |w: &mut io::BufWriter<std::fs::File>| io::Write::write_all(w, bytes);
    match step {
        // The operator's metrics path may be a link into the collector's directory.
        WriteStep::Metrics => crate::atomic::write_atomically(path, body),
        _ => crate::atomic::write_regular_atomically(path, body),
    }
}
