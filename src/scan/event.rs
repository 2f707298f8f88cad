//! What a scan tells the outside world happened to it, besides its status snapshots: it
//! started, was suspended, resumed after a suspension, completed, failed or was aborted. The
//! publishers ([`crate::publish`]) send every one; the notification hook ([`crate::hook`])
//! runs for the endings and suspensions ([`ScanEventKind::runs_hook`]).
//!
//! Layer 3 (session): plain data, no I/O.

use std::fmt;
use std::path::PathBuf;

/// What happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScanEventKind {
    /// The scan was created, or reopened to continue (the reason says which).
    Started,
    /// A suspension cleared by itself and the scan goes on.
    Resumed,
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
    /// `started`, `resumed`, `success`, `fail`, `abort` or `suspended` (the hook's
    /// `SURFSCAN_STATUS`, the events' `kind`).
    pub fn as_str(self) -> &'static str {
        match self {
            ScanEventKind::Started => "started",
            ScanEventKind::Resumed => "resumed",
            ScanEventKind::Success => "success",
            ScanEventKind::Fail => "fail",
            ScanEventKind::Abort => "abort",
            ScanEventKind::Suspended => "suspended",
        }
    }

    /// True for an ending (success, fail, abort): what a stop record says.
    pub fn is_ending(self) -> bool {
        matches!(
            self,
            ScanEventKind::Success | ScanEventKind::Fail | ScanEventKind::Abort
        )
    }
}

impl ScanEventKind {
    /// True for what the notification hook is run for: an ending or a suspension (a start
    /// and a resumption are not worth waking anyone for).
    pub fn runs_hook(self) -> bool {
        !matches!(self, ScanEventKind::Started | ScanEventKind::Resumed)
    }
}

impl fmt::Display for ScanEventKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One event of a scan.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanEvent {
    /// Scan id.
    pub scan_id: String,
    /// Scan directory.
    pub dir: PathBuf,
    /// What happened.
    pub kind: ScanEventKind,
    /// Why, for people (may be empty).
    pub reason: String,
    /// When it happened: for an ending, the time of the journal's stop record (so the same
    /// ending read back from the journal is the same event); otherwise when it was told.
    pub time: chrono::DateTime<chrono::Utc>,
    /// A bug ended the scan (an internal error): true only for the `fail` event of an ending
    /// whose [`super::ending::End::is_internal`], as the stop record's `internal`.
    pub internal: bool,
    /// A completed scan's verdict, means and warnings.
    pub results: Option<super::results::ScanResults>,
}
