//! The disk side of a running scan: its directory and journal, the committed lines held in
//! memory, and the incremental fitter fed from them. The runner performs the machine's
//! commit, push, record, metrics and output actions here.
//!
//! Layer 3 (session): depends on [`super::store`], [`super::journal`], [`super::outputs`],
//! [`super::metrics`], [`super::testhooks`] and [`crate::fit`].

use super::journal::{InterruptionRecord, Journal, JournalError, Record, StartRecord, StopRecord};
use super::line::{LineMeta, StoredLine};
use super::machine::Note;
use super::metrics::ScanMetrics;
use super::metrics_file::write_metrics;
use super::outputs::{write_outputs, Characterise, Outputs, OutputsError};
use super::plan::Plan;
use super::store::{csv_name, meta_name, sync_dir, ScanStore};
use super::store_error::StoreError;
use super::testhooks::{Step, TestHooks};
use crate::fit::{FitError, FitOptions, IncrementalFitter};
use crate::profile::Profile;
use chrono::{DateTime, Utc};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

/// One scan's directory, journal, lines and fitter.
pub(super) struct Ledger {
    pub id: String,
    pub dir: PathBuf,
    pub store: ScanStore,
    pub journal: Journal,
    pub start: StartRecord,
    pub plan: Plan,
    /// The fitter holding `lines` (taken by the outputs, rebuilt if they must be written
    /// again).
    fitter: Option<IncrementalFitter>,
    /// The committed lines, in index order.
    pub lines: Vec<StoredLine>,
    /// Committed lines after a gap (a line moved aside at resume): each goes to the fitter
    /// right after the line before it.
    pub ahead: BTreeMap<u32, StoredLine>,
    hooks: Arc<TestHooks>,
    metrics_path: Option<PathBuf>,
    /// Interruptions whose journal append failed (a full disk, mostly: the very condition
    /// they report), oldest first, with their own times: appended before the next record.
    unrecorded: Vec<InterruptionRecord>,
    /// The time of the stop record last written (none before it, or when it could not be
    /// written): the time of the ending's event.
    pub stopped: Option<DateTime<Utc>>,
}

impl Ledger {
    pub fn new(
        store: ScanStore,
        journal: Journal,
        start: StartRecord,
        hooks: Arc<TestHooks>,
        metrics_path: Option<PathBuf>,
    ) -> Ledger {
        let plan = start.plan.clone();
        Ledger {
            id: start.scan_id.clone(),
            dir: store.root().to_path_buf(),
            store,
            journal,
            fitter: Some(fitter_of(&plan)),
            plan,
            lines: Vec::new(),
            ahead: BTreeMap::new(),
            start,
            hooks,
            metrics_path,
            unrecorded: Vec::new(),
            stopped: None,
        }
    }

    /// Appends an interruption record. One that cannot be appended (the scan goes on) is kept
    /// and appended, with its own time, before the next record of the journal, so the
    /// journal still tells what happened once the disk has room again.
    pub fn note(&mut self, n: &Note) {
        if n.is_operators() {
            tracing::info!(scan_id = %self.id, line = n.line.map(|l| l + 1), "operator: {}", n.reason);
        } else {
            tracing::warn!(scan_id = %self.id, line = n.line.map(|l| l + 1), "interruption: {}", n.reason);
        }
        self.unrecorded.push(InterruptionRecord {
            reason: n.reason.clone(),
            device: n.device,
            line: n.line,
            time: Utc::now(),
            peer: n.peer.clone(),
            pause: n.pause,
        });
        self.record_unrecorded();
    }

    /// Appends the interruptions not yet in the journal, oldest first; stops at the first
    /// that fails (logged), keeping it and those after it for the next try.
    fn record_unrecorded(&mut self) {
        while let Some(first) = self.unrecorded.first() {
            match self.journal.append(&Record::Interruption(first.clone())) {
                Ok(()) => {
                    self.unrecorded.remove(0);
                }
                Err(e) => {
                    tracing::error!(
                        scan_id = %self.id,
                        "cannot record the interruption in the journal yet ({} waiting; each is recorded with its own time once it can be): {e}",
                        self.unrecorded.len()
                    );
                    return;
                }
            }
        }
    }

    /// Appends the stop record (after any interruption still waiting to be recorded).
    pub fn stop(&mut self, words: &super::ending::StopWords) -> Result<(), JournalError> {
        self.record_unrecorded();
        let time = Utc::now();
        let written = self.journal.append(&Record::Stop(StopRecord {
            status: words.status,
            reason: words.reason.clone(),
            cause: words.cause,
            internal: words.internal,
            time,
        }));
        self.stopped = written.is_ok().then_some(time);
        written
    }

    /// Records that the failed scan is continued: its stop record no longer ends it.
    pub fn reopen_failed(
        &mut self,
        peer: Option<super::command::Peer>,
    ) -> Result<(), JournalError> {
        let after = super::journal::read_journal(self.journal.path())
            .ok()
            .and_then(|r| {
                r.records.iter().rev().find_map(|rec| match rec {
                    Record::Stop(s) => Some(s.reason.clone()),
                    _ => None,
                })
            })
            .unwrap_or_default();
        self.record_unrecorded();
        self.stopped = None;
        self.journal
            .append(&Record::Continue(super::journal::ContinueRecord {
                after,
                peer,
                time: Utc::now(),
            }))
    }

    /// The instrument's Ra, µm, of the committed lines before line `line`, in line order
    /// (for [`crate::sj210::sanity::ra_far_from_neighbours`]).
    pub fn ra_before(&self, line: u32) -> Vec<f64> {
        let mut earlier: Vec<(u32, f64)> = self
            .lines
            .iter()
            .filter(|s| s.meta.id.index < line)
            .filter_map(|s| {
                let ra = crate::sj210::sanity::instrument_ra_um(&s.meta.results)?;
                Some((s.meta.id.index, ra))
            })
            .collect();
        earlier.sort_by_key(|e| e.0);
        earlier.into_iter().map(|e| e.1).collect()
    }

    /// Commits a line durably (files, then the journal record). On failure, files the
    /// journal does not vouch for are removed.
    pub fn commit(&mut self, meta: &LineMeta, profile: &Profile) -> Result<(), StoreError> {
        // The hook learns the line before any of its writes.
        self.hooks.set_line(meta.id.index);
        self.record_unrecorded();
        if let Err(e) = self.store.commit_line(&mut self.journal, meta, profile) {
            self.discard_uncommitted(meta.id.index);
            return Err(e);
        }
        self.hooks.at(Step::AfterCommit);
        Ok(())
    }

    /// After a failed commit: when the journal holds no record of line `index` (its append
    /// failed or never happened), the line's files are removed so that nothing reading the
    /// directory (`fit`, `analyze`) takes a line the scan never committed. A record that did
    /// reach the journal (e.g. only its fsync failed) keeps the files it vouches for.
    fn discard_uncommitted(&self, index: u32) {
        let recorded = super::journal::read_journal(self.journal.path()).is_ok_and(|r| {
            r.records
                .iter()
                .any(|rec| matches!(rec, Record::Line(l) if l.id.index == index))
        });
        if recorded {
            return;
        }
        let dir = self.store.lines_dir();
        for name in [csv_name(index), meta_name(index)] {
            match std::fs::remove_file(dir.join(&name)) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => tracing::warn!(
                    scan_id = %self.id,
                    "cannot remove {} of the uncommitted line {}: {e}",
                    name,
                    index + 1
                ),
            }
        }
        let _ = sync_dir(&dir);
    }

    /// Pushes a committed line into the fitter and keeps it, then the lines committed
    /// ahead of it that follow it without a gap.
    pub fn push(&mut self, line: StoredLine) -> Result<(), FitError> {
        let mut next = Some(line);
        while let Some(line) = next.take() {
            let fitter = self.fitter.get_or_insert_with(|| fitter_of(&self.plan));
            fitter.push_line(line.y_mm(), &line.profile)?;
            let following = line.meta.id.index.saturating_add(1);
            self.lines.push(line);
            next = self.ahead.remove(&following);
        }
        Ok(())
    }

    /// Finishes the fit and writes the outputs from memory.
    pub fn write_outputs(
        &mut self,
        characterise: Option<&dyn Characterise>,
    ) -> Result<Outputs, OutputsError> {
        let fitter = match self.fitter.take() {
            Some(f) => f,
            // Taken by an earlier try whose write failed: rebuilt from the lines in memory.
            None => {
                let mut f = fitter_of(&self.plan);
                for l in &self.lines {
                    f.push_line(l.y_mm(), &l.profile)?;
                }
                f
            }
        };
        write_outputs(
            &self.dir,
            &self.start,
            &self.plan,
            fitter,
            &self.lines,
            characterise,
        )
    }

    /// Writes the metrics file, if one is configured; a failure is logged.
    pub fn metrics(&self, m: &ScanMetrics) {
        if let Some(p) = &self.metrics_path {
            if let Err(e) = write_metrics(p, m, &*self.store.faults()) {
                tracing::warn!("cannot write metrics {}: {e}", p.display());
            }
        }
    }
}

fn fitter_of(plan: &Plan) -> IncrementalFitter {
    IncrementalFitter::new(FitOptions::degrees(plan.degree_u, plan.degree_v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::faults::{StorageFaults, WriteStep};
    use crate::scan::journal::{read_journal, StopStatus};
    use crate::scan::scan_id::ScanId;
    use crate::units::Nm;
    use chrono::TimeZone;
    use std::path::Path;
    use std::sync::atomic::{AtomicBool, Ordering};

    /// A disk that refuses every journal append (ENOSPC) while `full` is set.
    #[derive(Default)]
    struct Disk {
        full: AtomicBool,
    }

    impl StorageFaults for Disk {
        fn before_write(&self, step: WriteStep, _path: &Path) -> std::io::Result<()> {
            if step == WriteStep::Journal && self.full.load(Ordering::SeqCst) {
                return Err(std::io::Error::from_raw_os_error(libc::ENOSPC));
            }
            Ok(())
        }
    }

    fn ledger(dir: &Path, disk: Arc<Disk>) -> Ledger {
        let time = Utc.with_ymd_and_hms(2026, 12, 1, 22, 0, 0).unwrap();
        let id = ScanId::new(time, "block");
        let store = ScanStore::create(dir, &id, disk.clone()).unwrap().0;
        let start = StartRecord {
            scan_id: id.0.clone(),
            sequence: 1,
            time,
            plan: Plan {
                lines: 3,
                y_start_nm: Nm(0),
                y_step_nm: Nm(10_000),
                degree_u: 5,
                degree_v: 5,
                max_line_attempts: 3,
                v_method: Default::default(),
                replace_spikes: None,
                analysis: None,
            },
            config: serde_json::json!({}),
            config_hash: "ab".repeat(32),
            specimen: "block".into(),
            operator: String::new(),
            notes: String::new(),
            software_version: "test".into(),
            instrument_model: "SJ-210".into(),
            firmware: String::new(),
            drive_unit: String::new(),
            conditions: Default::default(),
            peer: None,
            job: None,
        };
        let journal = Journal::create(store.root(), start.clone(), disk).unwrap();
        Ledger::new(store, journal, start, Arc::default(), None)
    }

    fn note(reason: &str) -> Note {
        Note {
            reason: reason.into(),
            device: None,
            line: Some(1),
            peer: None,
            pause: None,
        }
    }

    /// The journal's records after the start record, as (class, reason).
    fn records(l: &Ledger) -> Vec<(&'static str, String)> {
        read_journal(l.journal.path())
            .unwrap()
            .records
            .iter()
            .skip(1)
            .map(|r| match r {
                Record::Interruption(i) => ("interruption", i.reason.clone()),
                Record::Stop(s) => ("stop", s.reason.clone()),
                _ => ("other", String::new()),
            })
            .collect()
    }

    #[test]
    fn an_interruption_the_full_disk_refused_is_recorded_once_it_has_room() {
        let dir = tempfile::tempdir().unwrap();
        let disk = Arc::new(Disk::default());
        let mut l = ledger(dir.path(), disk.clone());
        disk.full.store(true, Ordering::SeqCst);
        l.note(&note("suspended: disk full"));
        l.note(&note("still full"));
        assert!(records(&l).is_empty(), "nothing could be written");
        let first_time = l.unrecorded[0].time;
        disk.full.store(false, Ordering::SeqCst);
        l.note(&note("space is back"));
        assert_eq!(
            records(&l),
            [
                ("interruption", "suspended: disk full".to_string()),
                ("interruption", "still full".to_string()),
                ("interruption", "space is back".to_string()),
            ]
        );
        // With the time it happened, not the time it was written.
        let state = read_journal(l.journal.path()).unwrap();
        let Record::Interruption(i) = &state.records[1] else {
            panic!("not an interruption")
        };
        assert_eq!(i.time, first_time);
        assert!(l.unrecorded.is_empty());
    }

    #[test]
    fn the_stop_record_follows_the_interruptions_waiting_to_be_recorded() {
        let dir = tempfile::tempdir().unwrap();
        let disk = Arc::new(Disk::default());
        let mut l = ledger(dir.path(), disk.clone());
        disk.full.store(true, Ordering::SeqCst);
        l.note(&note("suspended: disk full"));
        let aborted = crate::scan::ending::StopWords {
            status: StopStatus::Abort,
            reason: "aborted".into(),
            cause: None,
            internal: false,
        };
        assert!(l.stop(&aborted).is_err());
        disk.full.store(false, Ordering::SeqCst);
        l.stop(&aborted).unwrap();
        assert_eq!(
            records(&l),
            [
                ("interruption", "suspended: disk full".to_string()),
                ("stop", "aborted".to_string()),
            ]
        );
    }
}
