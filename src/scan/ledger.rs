//! The disk side of a running scan: its directory and journal, the committed lines held in
//! memory, and the incremental fitter fed from them. The runner performs the machine's
//! commit, push, record, metrics and output actions here.
//!
//! Layer 3 (session): depends on [`super::store`], [`super::journal`], [`super::outputs`],
//! [`super::metrics`], [`super::testhooks`] and [`crate::fit`].

use super::journal::{
    InterruptionRecord, Journal, JournalError, Record, StartRecord, StopRecord, StopStatus,
};
use super::line::{LineMeta, StoredLine};
use super::machine::Note;
use super::metrics::{write_metrics, ScanMetrics};
use super::outputs::{write_outputs, Characterise, Outputs, OutputsError};
use super::plan::Plan;
use super::store::{csv_name, meta_name, sync_dir, ScanStore};
use super::store_error::StoreError;
use super::testhooks::{Step, TestHooks};
use crate::fit::{FitError, FitOptions, IncrementalFitter};
use crate::profile::Profile;
use chrono::Utc;
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
}

impl Ledger {
    pub fn new(
        store: ScanStore,
        journal: Journal,
        start: StartRecord,
        hooks: Arc<TestHooks>,
        metrics_path: Option<PathBuf>,
    ) -> Ledger {
        let plan = start.plan;
        Ledger {
            id: start.scan_id.clone(),
            dir: store.root().to_path_buf(),
            store,
            journal,
            plan,
            fitter: Some(fitter_of(&plan)),
            lines: Vec::new(),
            ahead: BTreeMap::new(),
            start,
            hooks,
            metrics_path,
        }
    }

    /// Appends an interruption record; a failure is logged (the scan goes on).
    pub fn note(&mut self, n: &Note) {
        tracing::warn!(scan_id = %self.id, line = n.line.map(|l| l + 1), "interruption: {}", n.reason);
        let r = Record::Interruption(InterruptionRecord {
            reason: n.reason.clone(),
            device: n.device,
            line: n.line,
            time: Utc::now(),
            peer: n.peer,
        });
        if let Err(e) = self.journal.append(&r) {
            tracing::error!(scan_id = %self.id, "cannot record the interruption in the journal: {e}");
        }
    }

    /// Appends the stop record.
    pub fn stop(&mut self, status: StopStatus, reason: &str) -> Result<(), JournalError> {
        self.journal.append(&Record::Stop(StopRecord {
            status,
            reason: reason.to_owned(),
            time: Utc::now(),
        }))
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
        self.journal
            .append(&Record::Continue(super::journal::ContinueRecord {
                after,
                peer,
                time: Utc::now(),
            }))
    }

    /// Commits a line durably (files, then the journal record). On failure, files the
    /// journal does not vouch for are removed.
    pub fn commit(&mut self, meta: &LineMeta, profile: &Profile) -> Result<(), StoreError> {
        // The hook learns the line before any of its writes.
        self.hooks.set_line(meta.id.index);
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
    IncrementalFitter::new(FitOptions {
        degree_u: plan.degree_u,
        degree_v: plan.degree_v,
    })
}
