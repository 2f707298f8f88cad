//! The disk side of the runner: the machine's immediate actions (publish, record, notify,
//! reply, metrics, stop) and its disk effects (create the scan, commit, push into the fitter,
//! write the outputs, read the free space), each effect's result as the machine's
//! [`Event`].
//!
//! Layer 3 (session): depends on [`super::ledger`], [`super::opening`], [`super::disk`],
//! [`super::channels`], [`super::machine`] and the scan's line and outputs types.

use super::channels::Control;
use super::device_ops::Held;
use super::disk::{free_bytes, outputs_bytes};
use super::ending::End;
use super::ledger::Ledger;
use super::line::{LineIdentity, LineMeta, StoredLine};
use super::machine::{Action, Event, StorageFailure};
use super::opening::{self, NewScan};
use super::outputs::{Outputs, OutputsError};
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
            Action::Publish(s) => ctl.publish(s),
            Action::Record(n) => match &mut self.ledger {
                Some(l) => l.note(&n),
                None => tracing::warn!("{}", n.reason),
            },
            Action::Notify(kind, reason) => {
                if let Some(l) = &self.ledger {
                    ctl.event(&l.id, &l.dir, kind, &reason);
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
            return storage_event(false, "internal: no scan to finish".into());
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
            Err(e) => {
                let full = e.is_io() && is_disk_full_text(&e);
                let message = if full {
                    e.to_string()
                } else {
                    format!(
                        "all lines are on disk but the outputs could not be written: {e}; run `surfscan fit {}` and `surfscan analyze {}` once the cause is cleared",
                        l.dir.display(),
                        l.dir.display()
                    )
                };
                storage_event(full, message)
            }
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
                    return storage_event(
                        false,
                        "internal: no probe report for the new scan".into(),
                    );
                };
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
                    Err(e) => storage_event(e.is_disk_full(), e.to_string()),
                }
            }
            Action::Commit { line, attempt } => {
                let (Some(l), Some(h)) = (self.ledger.as_mut(), self.held.as_ref()) else {
                    return storage_event(false, "internal: no line to commit".into());
                };
                let p = &h.traced.profile;
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
                    readout_warnings: h.traced.readout_warnings.clone(),
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
                    Err(e) => storage_event(e.is_disk_full(), e.to_string()),
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
                    return storage_event(false, "internal: no scan to finish".into());
                };
                let written = l.write_outputs(self.settings.characterise.as_deref());
                self.outputs_event(written)
            }
            Action::CheckSpace => {
                let dir = self
                    .ledger
                    .as_ref()
                    .map_or_else(|| self.settings.output_dir.clone(), |l| l.dir.clone());
                let free_bytes = free_bytes(&dir).unwrap_or_else(|e| {
                    tracing::warn!("cannot read the free space of {}: {e}", dir.display());
                    0
                });
                let outputs_bytes = self.ledger.as_ref().map_or(0, |l| outputs_bytes(&l.dir));
                Event::SpaceChecked {
                    free_bytes,
                    outputs_bytes,
                }
            }
            other => {
                tracing::error!("internal: {other:?} performed as a disk effect");
                storage_event(
                    false,
                    format!("internal: {other:?} is not a disk operation"),
                )
            }
        }
    }
}

fn storage_event(disk_full: bool, message: String) -> Event {
    Event::StorageFailed(StorageFailure { disk_full, message })
}

/// Whether an outputs error is the disk being full (the error chain carries `ENOSPC`).
fn is_disk_full_text(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(err) = cur {
        if let Some(io) = err.downcast_ref::<std::io::Error>() {
            if io.raw_os_error() == Some(libc::ENOSPC) || io.raw_os_error() == Some(libc::EDQUOT) {
                return true;
            }
        }
        cur = err.source();
    }
    false
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
        let Some((status, reason, cause)) = end.stop_record() else {
            return;
        };
        let written = l.stop(status, &reason, cause);
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
    fn a_full_disk_is_found_through_the_outputs_error_chain() {
        let full = OutputsError::Iges(SurfaceWriteError::Io {
            path: "surface.igs".into(),
            source: std::io::Error::from_raw_os_error(libc::ENOSPC),
        });
        assert!(is_disk_full_text(&full));
        let denied = OutputsError::Report {
            path: "report.json".into(),
            source: std::io::Error::from_raw_os_error(libc::EACCES),
        };
        assert!(!is_disk_full_text(&denied));
    }
}
