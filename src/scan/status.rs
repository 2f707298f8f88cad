//! The status snapshot a running scan publishes (what the control socket serves, what
//! systemd's `STATUS=` shows, what the progress bar draws).
//!
//! Layer 3 (session): serde types only (and the snapshot after an end); the control socket
//! serves them, it does not own them.

use super::ending::StopStatus;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A link to the lab's systems (the MQTT broker, the archive) as its publisher sees it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LinkStatus {
    /// Connected and delivering.
    pub ok: bool,
    /// What it is doing, or what is wrong and what to do.
    pub message: String,
    /// Messages waiting on disk to be delivered.
    pub queued: u64,
}

/// What the daemon is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum State {
    /// No scan running; waiting for `start` (or the queue's next job).
    Idle,
    /// No scan running, and the queue's next job cannot begin yet: its specimen is to be
    /// loaded (`surfscan ready`), or a device it needs is missing; `reason` says which.
    Waiting,
    /// Probing devices, homing, pre-flight.
    Starting,
    /// Tracing lines.
    Scanning,
    /// A pause was requested; the current line finishes first.
    Pausing,
    /// Paused by the operator; `resume` continues.
    Paused,
    /// A device fault suspended the scan; it resumes by itself when the cause clears.
    Suspended,
    /// All lines done: fitting, writing IGES and the report.
    Finishing,
    /// Shutting down (SIGTERM): the current line is abandoned, the scan resumes at next start.
    Stopping,
}

/// Presence of a device as last seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DeviceState {
    /// Not opened (no scan running) and its port path does not exist.
    Absent,
    /// Not opened, but its port path exists.
    Present,
    /// Open and verified.
    Connected,
    /// Lost during a scan; reconnecting with backoff.
    Reconnecting,
}

/// How the last scan ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LastStop {
    /// Scan id (empty when the scan never started).
    pub scan_id: String,
    /// How it ended.
    pub status: StopStatus,
    /// Why.
    pub reason: String,
    /// Scan directory.
    pub dir: String,
    /// A bug ended the scan (an internal error, as the journal's stop record says); present
    /// only when true.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub internal: bool,
    /// A completed scan in one line with its verdict and warnings: `success: does not
    /// conform (Rz 16 % rule: 9 of 31 lines above 6.3 µm …)`, `success, 3 warnings`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<String>,
    /// A completed scan's verdict, means and warnings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub results: Option<Box<super::results::ScanResults>>,
}

/// The status snapshot the runner publishes on every state change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Current state.
    pub state: State,
    /// Scan id of the running (or suspended/paused) scan.
    pub scan_id: Option<String>,
    /// Scan directory.
    pub scan_dir: Option<String>,
    /// Lines completed and on disk.
    pub lines_done: u32,
    /// Lines in the plan.
    pub lines_total: u32,
    /// 1-based number of the line being worked on, for people.
    pub current_line: Option<u32>,
    /// y target of the current line, mm.
    pub y_mm: Option<f64>,
    /// Ra of the last completed line as the instrument reported it, µm.
    pub last_ra_um: Option<f64>,
    /// Estimated scanning time still needed, s: the mean line time so far times the lines
    /// left, as of the last line. It counts down only while scanning; paused or suspended,
    /// it is the time still needed once the scan goes on.
    pub eta_s: Option<f64>,
    /// Why the scan is suspended/paused/stopping, or the last error.
    pub reason: Option<String>,
    /// The instrument.
    pub instrument: DeviceState,
    /// The stage.
    pub stage: DeviceState,
    /// How the previous scan ended, if one ended since the daemon started.
    pub last_stop: Option<LastStop>,
    /// Scans skipped because their journal is damaged, one message each (path, record, why).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub damaged_journals: Vec<String>,
    /// The links to the lab's systems (`mqtt`, …), each as its publisher last saw it; owned
    /// by the publishers, carried through every snapshot the scan publishes.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub links: BTreeMap<String, LinkStatus>,
    /// Scans the daemon has begun since it started (a resumption at start-up included):
    /// `surfscan start` knows the status shows its own start's outcome once this has grown.
    #[serde(default)]
    pub starts: u64,
    /// The job queue, when the daemon keeps one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub queue: Option<Box<QueueStatus>>,
}

/// The job queue in the status: how many jobs wait their turn, the one running, and why the
/// queue is stopped.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct QueueStatus {
    /// Jobs queued (not running, not finished).
    pub queued: usize,
    /// The job whose scan is running.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub running: Option<u64>,
    /// Why the queue is stopped (`surfscan queue continue` runs the next job).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held: Option<String>,
}

impl Status {
    /// The idle snapshot with no devices known.
    pub fn idle() -> Status {
        Status {
            state: State::Idle,
            scan_id: None,
            scan_dir: None,
            lines_done: 0,
            lines_total: 0,
            current_line: None,
            y_mm: None,
            last_ra_um: None,
            eta_s: None,
            reason: None,
            instrument: DeviceState::Absent,
            stage: DeviceState::Absent,
            last_stop: None,
            damaged_journals: Vec::new(),
            links: BTreeMap::new(),
            starts: 0,
            queue: None,
        }
    }

    /// A scan begins: the count of scans begun grows and the state is Starting in one
    /// update, so that whoever waits for a start's outcome (`surfscan start`) never sees the
    /// new count beside the idle state from before it; the scan's own snapshots say the rest.
    /// What the idle daemon waited for (`reason`) is not the new scan's.
    pub fn begin_start(&mut self) {
        self.starts += 1;
        self.state = State::Starting;
        self.reason = None;
    }

    /// One line for systemd's `STATUS=` and for logs, e.g.
    /// `scan X: line 12/31, y=0.110 mm`.
    pub fn summary(&self) -> String {
        let state = serde_json::to_value(self.state)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default();
        match (&self.scan_id, self.state) {
            (None, State::Idle) => {
                let mut s = match &self.last_stop {
                    Some(s) if s.scan_id.is_empty() => {
                        format!("idle; last start: {} ({})", s.status, s.reason)
                    }
                    Some(s) => {
                        format!("idle; last scan {}: {} ({})", s.scan_id, s.status, s.reason)
                    }
                    None => "idle".to_owned(),
                };
                // What the idle daemon waits for (a failed scan's continuation).
                if let Some(r) = &self.reason {
                    s.push_str("; ");
                    s.push_str(r);
                }
                s
            }
            (Some(id), State::Scanning)
                if self.current_line.is_none() && self.lines_done >= self.lines_total =>
            {
                // Every line on disk, the outputs being written: no line is being traced.
                format!(
                    "scan {id}: all {} lines done, writing the outputs",
                    self.lines_total
                )
            }
            (Some(id), State::Scanning) => {
                let line = self.current_line.unwrap_or(self.lines_done + 1);
                match self.y_mm {
                    Some(y) => format!("scan {id}: line {line}/{}, y={y:.3} mm", self.lines_total),
                    None => format!("scan {id}: line {line}/{}", self.lines_total),
                }
            }
            (Some(id), _) => {
                let mut s = format!(
                    "scan {id}: {state}, {}/{} lines done",
                    self.lines_done, self.lines_total
                );
                if let Some(r) = &self.reason {
                    s.push_str(": ");
                    s.push_str(r);
                }
                s
            }
            (None, State::Waiting) => match &self.reason {
                Some(r) => format!("waiting: {r}"),
                None => state,
            },
            (None, _) => state,
        }
    }
}

/// The snapshot after a scan (or an attempt to start one) ended: idle, the last stop named,
/// the devices no longer connected.
pub fn ended_status(s: &Status, ending: StopStatus, reason: &str) -> Status {
    let downgrade = |d: DeviceState| match d {
        DeviceState::Connected | DeviceState::Reconnecting => DeviceState::Present,
        other => other,
    };
    Status {
        last_stop: Some(LastStop {
            scan_id: s.scan_id.clone().unwrap_or_default(),
            status: ending,
            reason: reason.to_owned(),
            dir: s.scan_dir.clone().unwrap_or_default(),
            internal: false,
            verdict: None,
            results: None,
        }),
        instrument: downgrade(s.instrument),
        stage: downgrade(s.stage),
        starts: s.starts,
        links: s.links.clone(),
        ..Status::idle()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A start after the idle daemon said what a scan waits for (the file system refused
    /// reopening it) does not carry that reason into the new scan's snapshots.
    #[test]
    fn a_start_clears_what_the_idle_daemon_waited_for() {
        let mut s = Status::idle();
        s.reason = Some("scan B-1 (/scans/B-1) waits for the file system: …".into());
        s.begin_start();
        assert_eq!((s.state, s.starts, s.reason), (State::Starting, 1, None));
    }

    #[test]
    fn status_summary_is_what_systemd_shows() {
        let mut s = Status::idle();
        assert_eq!(s.summary(), "idle");
        s.state = State::Scanning;
        s.scan_id = Some("X".into());
        s.lines_total = 31;
        s.lines_done = 11;
        s.current_line = Some(12);
        s.y_mm = Some(0.11);
        assert_eq!(s.summary(), "scan X: line 12/31, y=0.110 mm");
        s.state = State::Suspended;
        s.reason = Some("instrument absent".into());
        assert_eq!(
            s.summary(),
            "scan X: suspended, 11/31 lines done: instrument absent"
        );
        let v = serde_json::to_value(&s).unwrap();
        assert_eq!(v["state"], "suspended");
    }

    #[test]
    fn the_summary_after_the_last_line_names_no_line_past_the_end() {
        let mut s = Status::idle();
        s.state = State::Scanning;
        s.scan_id = Some("X".into());
        s.lines_total = 31;
        s.lines_done = 31;
        s.current_line = None;
        s.y_mm = Some(0.30);
        let text = s.summary();
        assert!(!text.contains("32/31"), "{text}");
        assert_eq!(text, "scan X: all 31 lines done, writing the outputs");
        // The last line itself, while traced, is still line 31/31.
        s.lines_done = 30;
        s.current_line = Some(31);
        assert_eq!(s.summary(), "scan X: line 31/31, y=0.300 mm");
    }

    #[test]
    fn last_stop_status_is_a_lowercase_word_on_the_wire() {
        let stop = LastStop {
            scan_id: "X".into(),
            status: StopStatus::Interrupted,
            reason: "shutdown".into(),
            dir: String::new(),
            internal: false,
            verdict: None,
            results: None,
        };
        let v = serde_json::to_value(&stop).unwrap();
        assert_eq!(v["status"], "interrupted");
        assert_eq!(
            v.get("internal"),
            None,
            "said only when a bug ended the scan"
        );
        let back: LastStop = serde_json::from_value(v).unwrap();
        assert_eq!(back, stop);
        let bug = LastStop {
            internal: true,
            ..stop.clone()
        };
        let v = serde_json::to_value(&bug).unwrap();
        assert_eq!(v["internal"], true);
        assert_eq!(serde_json::from_value::<LastStop>(v).unwrap(), bug);
        let mut s = Status::idle();
        s.last_stop = Some(stop);
        assert_eq!(s.summary(), "idle; last scan X: interrupted (shutdown)");
    }
}
