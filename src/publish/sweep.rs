//! The start-up sweep: a scan whose journal says it succeeded, but whose success event never
//! reached a publisher's queue on disk (the process was killed between the journal's stop
//! record and the queue's entry), is handed to that publisher at start-up as if its event had
//! just come. A publisher knows the scans it has queued (its [`super::scan_queue`], or the
//! MQTT link's ledger of results queued) and since when it runs: scans that ended before
//! it was configured are not its.
//!
//! Layer 4 (process edge): a pure choice over the journals' survey; the publishers send.

use super::scan_queue::{ScanEntry, ScanQueue};
use crate::scan::event::{ScanEvent, ScanEventKind};
use crate::scan::journal::Succeeded;
use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// A scan whose results message the MQTT link stored in its outbox.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ResultsQueued {
    /// The scan id.
    pub scan_id: String,
    /// The scan directory.
    pub dir: PathBuf,
}

impl ScanEntry for ResultsQueued {
    fn queued(scan_id: &str, dir: &Path) -> ResultsQueued {
        ResultsQueued {
            scan_id: scan_id.to_owned(),
            dir: dir.to_owned(),
        }
    }
}

/// The MQTT link's record of the scans whose results it stored (`outbox/mqtt-results/`, each
/// entry finished as soon as it is written): what it knows for the sweep.
pub type ResultsLedger = ScanQueue<ResultsQueued>;

/// What a publisher knows at start-up: since when it runs, and the scan ids it has queued.
#[derive(Debug, Clone)]
pub struct Known {
    /// When its queue was first opened.
    pub since: DateTime<Utc>,
    /// The scans it has queued (waiting, done or set aside).
    pub scans: HashSet<String>,
}

/// The success events a publisher missed: the scans that succeeded at or after `known.since`
/// and that it has not queued, in the order they ended.
pub fn missed(succeeded: &[Succeeded], known: &Known) -> Vec<ScanEvent> {
    let mut v: Vec<&Succeeded> = succeeded
        .iter()
        .filter(|s| s.ended >= known.since && !known.scans.contains(&s.scan_id))
        .collect();
    v.sort_by(|a, b| (a.ended, &a.scan_id).cmp(&(b.ended, &b.scan_id)));
    v.into_iter()
        .map(|s| ScanEvent {
            scan_id: s.scan_id.clone(),
            dir: s.dir.clone(),
            kind: ScanEventKind::Success,
            reason: s.reason.clone(),
            time: s.ended,
            // A success, which no bug ends (`End::is_internal`): its stop record has no
            // `internal`, and its live event said false too.
            internal: false,
            results: None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(id: &str, ended: &str) -> Succeeded {
        Succeeded {
            dir: PathBuf::from(format!("/scans/{id}")),
            scan_id: id.into(),
            ended: ended.parse().unwrap(),
            reason: "all lines traced".into(),
        }
    }

    #[test]
    fn only_scans_ended_since_and_not_queued_are_missed_in_the_order_they_ended() {
        let scans = [
            ok("c", "2026-03-01T10:00:00Z"),
            ok("old", "2026-01-01T00:00:00Z"),
            ok("queued", "2026-03-01T09:00:00Z"),
            ok("b", "2026-03-01T08:00:00Z"),
        ];
        let known = Known {
            since: "2026-02-01T00:00:00Z".parse().unwrap(),
            scans: ["queued".to_owned()].into(),
        };
        let m = missed(&scans, &known);
        let ids: Vec<&str> = m.iter().map(|e| e.scan_id.as_str()).collect();
        assert_eq!(ids, ["b", "c"]);
        assert!(m.iter().all(|e| e.kind == ScanEventKind::Success));
        assert_eq!(m[0].dir, PathBuf::from("/scans/b"));
        assert_eq!(m[0].reason, "all lines traced");
        // The stop record's time, which the live event carried too: the same message id.
        assert_eq!(m[0].time, scans[3].ended);
    }
}
