//! The disk side of the runner: the machine's immediate actions (publish, record, notify,
//! reply, metrics, stop) and its disk effects (create the scan, commit, push into the fitter,
//! write the outputs, read the free space), each effect's result as the machine's
//! [`Event`].
//!
//! Layer 3 (session): depends on [`super::ledger`], [`super::opening`], [`super::disk`],
//! [`super::channels`], [`super::machine`], the scan's line, outputs and event types, and
//! [`crate::sj210::sanity`] (a committed line's Ra against the lines before it).

use super::channels::Control;
use super::device_ops::Held;
use super::disk::{free_space, outputs_bytes};
use super::ending::End;
use super::event::ScanEvent;
use super::ledger::Ledger;
use super::line::{LineIdentity, LineMeta, StoredLine};
use super::machine::{Action, Event, Note, StorageFailure};
use super::opening::{self, NewScan};
use super::outputs::{Outputs, OutputsError};
use super::policy::StorageClass;
use super::settings::RunSettings;
use crate::devices::ProbeReport;

/// The executor's state besides the devices.
pub(super) struct Books<'a> {
    pub(super) settings: &'a RunSettings,
    pub(super) ledger: Option<Ledger>,
    pub(super) new_scan: Option<NewScan>,
    pub(super) held: Option<Held>,
    /// The metadata of the held line once it is committed, for its push into the fitter.
    pub(super) committed: Option<LineMeta>,
    pub(super) outputs: Option<Outputs>,
    /// The reply channel of the command being fed.
    pub(super) reply: Option<tokio::sync::oneshot::Sender<Result<String, String>>>,
    pub(super) end: Option<End>,
    /// Why the stop record could not be written.
    pub(super) stop_error: Option<String>,
}

impl Books<'_> {
    /// Performs an immediate action.
    pub(super) fn immediate(&mut self, ctl: &Control, a: Action) {
        match a {
            Action::Publish(mut s) => {
                // A completed scan's last stop carries what its characterisation found.
                if let (Some(stop), Some(o)) = (s.last_stop.as_mut(), &self.outputs) {
                    if stop.status == super::ending::StopStatus::Success {
                        stop.verdict = o.results.as_ref().map(|r| r.line(stop.status.as_str()));
                        stop.results = o.results.clone().map(Box::new);
                    }
                }
                ctl.publish(s)
            }
            Action::Record(n) => match &mut self.ledger {
                Some(l) => l.note(&n),
                None if n.is_operators() => tracing::info!("operator: {}", n.reason),
                None => tracing::warn!("{}", n.reason),
            },
            Action::Notify(kind, reason) => {
                if let Some(l) = &self.ledger {
                    let results = self.outputs.as_ref().and_then(|o| o.results.clone());
                    // An ending is told after its `Stop`: its time is the stop record's, and
                    // a bug is said as the stop record says it.
                    let time = l
                        .stopped
                        .filter(|_| kind.is_ending())
                        .unwrap_or_else(chrono::Utc::now);
                    let internal = self.end.as_ref().is_some_and(|e| e.tells_internal(kind));
                    ctl.event(ScanEvent {
                        scan_id: l.id.clone(),
                        dir: l.dir.clone(),
                        kind,
                        reason,
                        time,
                        internal,
                        results,
                    });
                }
            }
            Action::Reply(r) => {
                if let Some(tx) = self.reply.take() {
                    let _ = tx.send(r);
                }
            }
            Action::Metrics(m) => {
                if let Some(l) = &self.ledger {
                    l.metrics(&m);
                }
                ctl.metrics(&m);
            }
            Action::Stop(end) => {
                self.write_stop(&end);
                self.end = Some(end);
            }
            Action::Close(_) | Action::Cancel => {}
            other => tracing::error!("internal: {other:?} performed as an immediate action"),
        }
    }

    /// The machine's event for the outputs written (or not) by the scan's ledger.
    pub(super) fn outputs_event(&mut self, written: Result<Outputs, OutputsError>) -> Event {
        let Some(l) = self.ledger.as_ref() else {
            return internal("internal: no scan to finish");
        };
        match written {
            Ok(outputs) => {
                let summary = format!(
                    "{} lines; surface {}",
                    l.plan.lines,
                    outputs
                        .iges
                        .first()
                        .map(|p| p.display().to_string())
                        .unwrap_or_default()
                );
                self.outputs = Some(outputs);
                Event::OutputsWritten { summary }
            }
            Err(e) if e.is_io() => Event::StorageFailed(storage_failure(&e)),
            Err(e) => internal(&format!(
                "all lines are on disk but the outputs could not be made: {e}; run `surfscan fit {}` and `surfscan analyze {}` to see why",
                l.dir.display(),
                l.dir.display()
            )),
        }
    }

    /// Performs a disk effect.
    pub(super) fn disk(
        &mut self,
        a: &Action,
        probe: Option<&ProbeReport>,
        station_points: u64,
    ) -> Event {
        match a {
            Action::CreateScan => {
                let (Some(who), Some(report)) = (self.new_scan.take(), probe) else {
                    return internal("internal: no probe report for the new scan");
                };
                if let Some(job) = &who.job {
                    let differ = job.expected.mismatches(&report.conditions);
                    if !differ.is_empty() {
                        return Event::CreateRefused(format!(
                            "the instrument is not set as recipe {} expects: {}; set it so (or correct the recipe) and start again",
                            job.record.recipe,
                            differ.join("; ")
                        ));
                    }
                }
                match opening::create(self.settings, who, report, station_points) {
                    Ok(l) => {
                        let ev = Event::Created {
                            scan_id: l.id.clone(),
                            dir: l.dir.display().to_string(),
                            conditions: l.start.conditions.clone(),
                            points_per_line: station_points,
                        };
                        self.ledger = Some(l);
                        ev
                    }
                    Err(e) => Event::StorageFailed(storage_failure(&e)),
                }
            }
            Action::Commit { line, attempt } => {
                // A second read-out that replaced the first is said in the journal, once.
                if let (Some(l), Some(h)) = (self.ledger.as_mut(), self.held.as_mut()) {
                    if let Some(reason) = h.read_again.take() {
                        l.note(&Note {
                            reason,
                            device: Some(crate::devices::Device::Instrument),
                            line: Some(*line),
                            peer: None,
                            pause: None,
                        });
                    }
                }
                let (Some(l), Some(h)) = (self.ledger.as_mut(), self.held.as_ref()) else {
                    return internal("internal: no line to commit");
                };
                let p = &h.traced.profile;
                // The line's Ra against the lines before it (the line was read out a second
                // time when the first read-out's was far: this is the one kept).
                let mut readout_warnings = h.traced.readout_warnings.clone();
                if let Some(ra) = crate::sj210::sanity::instrument_ra_um(&h.traced.results) {
                    let before = l.ra_before(*line);
                    if let Some(w) = crate::sj210::sanity::ra_far_from_neighbours(ra, &before) {
                        tracing::warn!(scan_id = %l.id, line = line + 1, "line kept with a read-out warning: {w}");
                        readout_warnings.push(w);
                    }
                }
                let meta = LineMeta {
                    id: LineIdentity {
                        index: *line,
                        y_target_nm: l.plan.target(*line),
                        y_readback_nm: h.readback,
                        attempt: *attempt,
                        points: p.len(),
                    },
                    profile: p.header(),
                    results: h.traced.results.clone(),
                    readout_warnings,
                    started_at: h.started_at,
                    finished_at: h.finished_at,
                };
                for w in &h.traced.warnings {
                    tracing::warn!(scan_id = %l.id, line = line + 1, "{w}");
                }
                match l.commit(&meta, p) {
                    Ok(()) => {
                        self.committed = Some(meta);
                        Event::Committed
                    }
                    Err(e) => Event::StorageFailed(storage_failure(&e)),
                }
            }
            Action::Push { line } => {
                let (Some(l), Some(h), Some(meta)) = (
                    self.ledger.as_mut(),
                    self.held.take(),
                    self.committed.take().filter(|m| m.id.index == *line),
                ) else {
                    return Event::PushRefused("internal: no committed line to push".into());
                };
                // The line as committed (its metadata file's contents) with its profile.
                let meta_line = StoredLine {
                    meta,
                    profile: h.traced.profile,
                };
                let y_mm = meta_line.y_mm();
                match l.push(meta_line) {
                    Ok(()) => {
                        tracing::info!(
                            scan_id = %l.id,
                            line = line + 1,
                            y_mm,
                            "line {}/{} on disk",
                            line + 1,
                            l.plan.lines
                        );
                        Event::Pushed
                    }
                    Err(e) => Event::PushRefused(e.to_string()),
                }
            }
            Action::WriteOutputs => {
                let Some(l) = self.ledger.as_mut() else {
                    return internal("internal: no scan to finish");
                };
                let written = l.write_outputs(self.settings.characterise.as_deref());
                self.outputs_event(written)
            }
            Action::CheckSpace => {
                let dir = self
                    .ledger
                    .as_ref()
                    .map_or_else(|| self.settings.output_dir.clone(), |l| l.dir.clone());
                let (free_bytes, free_inodes) = free_space(&dir).unwrap_or_else(|e| {
                    tracing::warn!("cannot read the free space of {}: {e}", dir.display());
                    (0, 0)
                });
                let outputs_bytes = self.ledger.as_ref().map_or(0, |l| outputs_bytes(&l.dir));
                Event::SpaceChecked {
                    free_bytes,
                    free_inodes,
                    outputs_bytes,
                }
            }
            other => {
                tracing::error!("internal: {other:?} performed as a disk effect");
                internal(&format!("internal: {other:?} is not a disk operation"))
            }
        }
    }
}

/// A failed write that no file system refused (an internal error, outputs the lines cannot
/// make).
fn internal(message: &str) -> Event {
    Event::StorageFailed(StorageFailure::not_storage(message.to_owned()))
}

/// How the file system refused a write, from the error chain: its first operating-system
/// error; a full disk (`ENOSPC`, `EDQUOT`, or the pre-flight finding too little room) apart.
fn storage_failure(e: &(dyn std::error::Error + 'static)) -> StorageFailure {
    use super::store_error::StoreError;
    let too_small = |err: &(dyn std::error::Error + 'static)| {
        matches!(
            err.downcast_ref(),
            Some(StoreError::DiskTooSmall { .. } | StoreError::TooFewInodes { .. })
        )
    };
    if std::iter::successors(Some(e), |e| e.source()).any(too_small) {
        return StorageFailure::full(e.to_string());
    }
    let errno = super::store_error::os_error(e);
    let class = match errno {
        Some(libc::ENOSPC | libc::EDQUOT) => StorageClass::Full,
        _ => StorageClass::Refused,
    };
    StorageFailure {
        class: Some(class),
        errno,
        message: e.to_string(),
    }
}

impl Books<'_> {
    /// The journal's account of the end, written when the machine stops (before the
    /// notification hook hears of it): the stop record, or for a shutdown the interruption
    /// that leaves the scan resumable.
    pub(super) fn write_stop(&mut self, end: &End) {
        let Some(l) = self.ledger.as_mut() else {
            return;
        };
        if let End::Fail(r) = end {
            tracing::error!(scan_id = %l.id, "scan failed: {r}");
        }
        // After a shutdown the machine recorded the interruption: no stop record, the scan
        // resumes.
        let Some(words) = end.stop_record() else {
            return;
        };
        let written = l.stop(&words);
        if let Err(e) = written {
            tracing::error!(scan_id = %l.id, "cannot write the stop record: {e}");
            self.stop_error = Some(e.to_string());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::outputs::OutputsError;
    use crate::scan::surface_files::SurfaceWriteError;

    #[test]
    fn a_refused_write_is_classed_by_the_first_os_error_of_its_chain() {
        let full = OutputsError::Iges(SurfaceWriteError::Io {
            path: "surface.igs".into(),
            source: std::io::Error::from_raw_os_error(libc::ENOSPC),
        });
        let f = storage_failure(&full);
        assert_eq!(
            (f.class, f.errno),
            (Some(StorageClass::Full), Some(libc::ENOSPC))
        );
        let denied = OutputsError::Report {
            path: "report.json".into(),
            source: std::io::Error::from_raw_os_error(libc::EROFS),
        };
        let f = storage_failure(&denied);
        assert_eq!(
            (f.class, f.errno),
            (Some(StorageClass::Refused), Some(libc::EROFS))
        );
        assert!(f.message.contains("report.json"), "{}", f.message);
        let line = crate::scan::store_error::StoreError::Io {
            op: "write",
            path: "lines/0003.csv".into(),
            source: std::io::Error::from_raw_os_error(libc::EDQUOT),
        };
        assert_eq!(storage_failure(&line).class, Some(StorageClass::Full));
        let small = crate::scan::store_error::StoreError::DiskTooSmall {
            path: "/out".into(),
            needed_bytes: 10,
            available_bytes: 1,
        };
        assert_eq!(storage_failure(&small).class, Some(StorageClass::Full));
    }
}
