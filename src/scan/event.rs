//! What a scan tells the outside world happened to it, besides its status snapshots: it
//! completed, failed, was aborted or suspended. The daemon passes these to the notification
//! hook ([`crate::hook`]).
//!
//! Layer 3 (session): plain data, no I/O.

use std::fmt;
use std::path::PathBuf;

/// What happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScanEventKind {
    /// All lines done and the surface written.
    Success,
    /// The scan failed.
    Fail,
    /// The operator aborted it.
    Abort,
    /// A condition that clears by itself suspended it; it continues on its own.
    Suspended,
}

impl ScanEventKind {
    /// `success`, `fail`, `abort` or `suspended` (the hook's `SURFSCAN_STATUS`).
    pub fn as_str(self) -> &'static str {
        match self {
            ScanEventKind::Success => "success",
            ScanEventKind::Fail => "fail",
            ScanEventKind::Abort => "abort",
            ScanEventKind::Suspended => "suspended",
        }
    }
}

impl fmt::Display for ScanEventKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One event of a scan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScanEvent {
    /// Scan id.
    pub scan_id: String,
    /// Scan directory.
    pub dir: PathBuf,
    /// What happened.
    pub kind: ScanEventKind,
    /// Why, for people (may be empty).
    pub reason: String,
}
