//! The daemon's side of the job queue: when no scan runs, what the queue's next job needs
//! (its scan to run, or a reason to wait), and, when its scan has ended, the job's ending
//! recorded.
//!
//! A job's scan runs the recipe as frozen in the job, validated with the station's
//! configuration as it is now: its plan, analysis and the measuring conditions it expects;
//! its start record names the job. The job is marked running before its scan is created, and
//! finished once its scan has ended, so a crash anywhere leaves the journals to settle it
//! ([`crate::jobs::queue`]). A job whose scan could not begin because a device is missing
//! goes back to its place and is tried again with the reconnection backoff: a condition
//! that clears by itself never consumes a night's job. A scan that ends by a shutdown
//! leaves its job running: the scan resumes at the next start. A scan whose reopening
//! was refused for its own files, or panicked, has ended (the runner records it): its job
//! ends `fail` with it, and the queue does not reopen it again. One whose reopening the file
//! system refused, or whose ending it refused to record, is left as it is, which can clear
//! by itself: its job stays running with it, and its turn reopens it again with the
//! reconnection backoff, saying why meanwhile.
//! A scan of no job the file system refused to reopen is reopened again with the same
//! backoff ([`Turn::Reopen`]); a job queued behind it waits for it, saying so. A reopening cut short by a shutdown is a shutdown's. A running job's turn
//! reopens its scan as the scan's journal says: resumed when it has not ended, continued when
//! its stop record is a failure the daemon continues by itself (the one rule the start-up
//! choice and the settling after a restart ask too:
//! [`crate::scan::ending::FailCause::continued_by_the_daemon`]): its transient budget's (once
//! its devices are present) or, in an earlier version, storage's; an ended scan (its ending
//! not yet in the queue) settles the job as
//! its journal says, as after a restart, and so does a refusal of its scan for having ended;
//! any other refusal of its scan ends the job `refused` with its scan id.
//!
//! Layer 5 (composition): depends on [`crate::jobs`], [`crate::scan`]'s choice and
//! settings, and [`super::station`].

use super::station::run_settings;
use crate::jobs::queue::{JobOutcome, JobState, Next};
use crate::jobs::recipe::Recipe;
use crate::jobs::service::QueueService;
use crate::scan::choice::{self, Asker, Decision};
use crate::scan::command::RecipeStart;
use crate::scan::command::{Peer, StartMode};
use crate::scan::ending::{End, FailCause, FailKind, FailReason};
use crate::scan::journal::{read_journal, ResumeState, JOURNAL_FILE};
use crate::scan::outcome::{NewJob, Outcome, ScanRequest};
use crate::scan::settings::RunSettings;
use crate::scan::testhooks::TestHooks;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What the daemon does with the queue when no scan runs.
pub(super) enum Turn {
    /// Run this scan for job `job`.
    Run {
        /// The job.
        job: u64,
        /// Its scan: a new one, or the one it had when the daemon stopped.
        request: ScanRequest,
        /// The runner's settings of its recipe.
        settings: Box<RunSettings>,
    },
    /// Reopen this scan of no job, which the file system refused to reopen, now that the
    /// backoff's wait is over.
    Reopen(ScanRequest),
    /// The next job cannot begin yet: why, for the status.
    Wait(String),
    /// Nothing to run.
    Nothing,
}

/// The queue's keeper and what the daemon remembers between turns.
pub(super) struct Jobs {
    /// The queue.
    pub queue: QueueService,
    config_hash: String,
    /// A job whose devices were missing is tried again at this time, with this reason shown
    /// meanwhile; the delay doubles up to the reconnection backoff's maximum.
    retry: Option<(Instant, String)>,
    delay: Duration,
    /// The last scan of no job the file system refused to reopen: reopened again with the
    /// reconnection backoff; the queue's next job waits for it.
    refused_scan: Option<RefusedScan>,
}

/// A scan of no job the file system refused to reopen, and why: reopened again at `at`,
/// `delay` after the refusal (the reconnection backoff's step).
struct RefusedScan {
    dir: PathBuf,
    why: String,
    at: Instant,
    delay: Duration,
}

impl Jobs {
    /// The daemon's queue; `config_hash` is the station file's (frozen into each scan).
    pub fn new(queue: QueueService, config_hash: String) -> Jobs {
        Jobs {
            queue,
            config_hash,
            retry: None,
            delay: Duration::ZERO,
            refused_scan: None,
        }
    }

    /// The runner's settings for a scan of `config` (a recipe's), sharing `base`'s hooks.
    fn settings_of(
        &self,
        config: &crate::config::Config,
        base: &RunSettings,
    ) -> Result<RunSettings, String> {
        let mut s = run_settings(config, self.config_hash.clone(), TestHooks::default())
            .map_err(|e| e.message)?;
        s.hooks = base.hooks.clone();
        Ok(s)
    }

    /// What the queue's next job needs now. `devices_present`: both ports are there.
    pub fn turn(&mut self, base: &RunSettings, devices_present: bool, now: Instant) -> Turn {
        if let Some(request) = self.refused_scan_due(now) {
            return Turn::Reopen(request);
        }
        let out = base.output_dir.clone();
        let (id, existing) = match self.queue.next() {
            Next::Idle => return Turn::Nothing,
            Next::Held(why) => return Turn::Wait(format!("the queue is stopped: {why}")),
            Next::WaitForLoading(id) => {
                let job = self.queue.snapshot().get(id).cloned();
                let what = job.map_or_else(|| format!("job {id}"), |j| j.describe());
                return Turn::Wait(format!(
                    "waiting for specimen to be loaded — {what}: load it, then `surfscan ready`"
                ));
            }
            Next::Start(id) => (id, None),
            Next::Continue { id, scan_id } => (id, Some(scan_id)),
        };
        if let Some((at, why)) = &self.retry {
            if now < *at {
                return Turn::Wait(why.clone());
            }
        }
        let plan = match self.queue.plan_of(id) {
            Ok(p) => p,
            Err(why) if matches!(existing, Some(Some(_))) => {
                // Its scan exists and follows the plan frozen in its journal: it is
                // continued with the station's settings.
                tracing::warn!("job {id}: {why}; its scan is continued as its journal says");
                let Some(Some(scan)) = existing else {
                    unreachable!()
                };
                return self.its_scan(id, &scan, &out, base.clone(), devices_present);
            }
            Err(why) => {
                self.end(id, refused(why));
                return Turn::Nothing;
            }
        };
        let settings = match self.settings_of(&plan.config, base) {
            Ok(s) => s,
            Err(why) => {
                self.end(id, refused(why));
                return Turn::Nothing;
            }
        };
        if let Some(Some(scan)) = existing {
            return self.its_scan(id, &scan, &out, settings, devices_present);
        }
        if !devices_present {
            return Turn::Wait(format!(
                "{} waits for the instrument and the stage to be present",
                plan.job.describe()
            ));
        }
        let r = &plan.job.request;
        let choice = match choice::choose(
            &out,
            Asker::Operator(StartMode::Auto),
            Peer::this_process(),
            (r.specimen.clone(), r.operator.clone(), r.notes.clone()),
        ) {
            Ok(c) => c,
            Err(e) => return Turn::Wait(format!("job {id} cannot begin: {e}")),
        };
        match &choice.decision {
            Decision::New { .. } => {}
            Decision::Resume(dir) | Decision::Continue(dir) if names_job(dir, id) => {
                // Its scan was created before the queue recorded it; a failed one is
                // continued (reopened as unfinished, it would be refused for having ended).
                let _ = self.queue.mark_running(id);
                let (dir, peer) = (dir.clone(), None);
                let request = match choice.decision {
                    Decision::Continue(_) => ScanRequest::Continue { dir, peer },
                    _ => ScanRequest::Resume { dir, peer },
                };
                return Turn::Run {
                    job: id,
                    request,
                    settings: Box::new(settings),
                };
            }
            Decision::Resume(dir) => {
                let refused = match &self.refused_scan {
                    Some(r) if r.dir == *dir => format!(
                        "; the file system refused reopening it ({}), and it is tried again within {} s, or by `surfscan start`",
                        r.why,
                        r.delay.as_secs()
                    ),
                    _ => String::new(),
                };
                return Turn::Wait(format!(
                    "job {id} waits: the unfinished scan {} must end first (resume it with `surfscan resume` or `surfscan start`, or abort it){refused}",
                    dir.display()
                ));
            }
            // A plain start continues only a scan an earlier version failed because the file
            // system refused a write (see the choice).
            Decision::Continue(dir) => {
                return Turn::Wait(format!(
                    "job {id} waits: the scan {} failed when the file system refused a write and is continued first (`surfscan start` continues it)",
                    dir.display()
                ))
            }
            Decision::AwaitDevices(dir) => {
                return Turn::Wait(format!(
                    "job {id} waits: the scan {} is continued first, once its devices answer again",
                    dir.display()
                ))
            }
            Decision::Nothing | Decision::Refuse(_) => {
                return Turn::Wait(format!(
                    "job {id} cannot begin: {}",
                    choice.describe(settings.plan.lines)
                ))
            }
        }
        if existing.is_none() {
            if let Err(e) = self.queue.mark_running(id) {
                return Turn::Wait(format!("job {id} cannot begin: {e}"));
            }
        }
        let request = match choice.commit() {
            Ok(Some(ScanRequest::New {
                specimen,
                operator,
                notes,
                peer,
                ..
            })) => ScanRequest::New {
                specimen,
                operator,
                notes,
                peer,
                job: Some(Box::new(plan.recipe.new_job(Some(id)))),
            },
            Ok(other) => {
                tracing::error!("job {id}: the scan choice changed under it: {other:?}");
                return Turn::Nothing;
            }
            Err(e) => return Turn::Wait(format!("job {id} cannot begin: {e}")),
        };
        tracing::info!("{}: starting its scan", plan.job.describe());
        Turn::Run {
            job: id,
            request,
            settings: Box::new(settings),
        }
    }

    /// The turn of running job `id` whose scan `scan` is in `out`, as the scan's journal
    /// says: resumed when it has not ended; continued when it failed for a cause the daemon
    /// continues by itself (its transient budget, once its devices are present; the file
    /// system refusing a write, which earlier versions ended a scan for); when it has ended
    /// otherwise (its ending not yet in the queue), the job settled as after a restart.
    fn its_scan(
        &mut self,
        id: u64,
        scan: &str,
        out: &Path,
        settings: RunSettings,
        devices_present: bool,
    ) -> Turn {
        let dir = out.join(scan);
        let stop = state_of(&dir).and_then(|s| s.stop);
        let request = match &stop {
            // Not ended, or its journal unreadable: the reopening says why.
            None => ScanRequest::Resume { dir, peer: None },
            Some(s) if s.fail_cause() == Some(FailCause::Budget) && !devices_present => {
                return Turn::Wait(format!(
                    "job {id} waits: its scan {scan} failed for its transient budget and is continued once the instrument and the stage are present"
                ))
            }
            Some(s) if s.continued_by_the_daemon() => ScanRequest::Continue { dir, peer: None },
            Some(_) => {
                return match self.settle_by_its_journal(id) {
                    // The queue changed: its next turn looks at it again.
                    Ok(()) => Turn::Nothing,
                    Err(e) => Turn::Wait(format!(
                        "job {id}: its scan {scan} has ended, and the queue could not record it: {e}"
                    )),
                }
            }
        };
        Turn::Run {
            job: id,
            request,
            settings: Box::new(settings),
        }
    }

    /// Settles the running jobs by what the journals say of their scans
    /// ([`QueueService::reconcile`]), as after a restart; the notes go to the log.
    fn settle_by_its_journal(&self, id: u64) -> Result<(), String> {
        let notes = self.queue.reconcile().map_err(|e| {
            tracing::error!("job {id}: {e}");
            e.to_string()
        })?;
        notes.iter().for_each(|n| tracing::info!("{n}"));
        Ok(())
    }

    /// Records how job `id`'s scan ended (see the module docs for what ends a job).
    pub fn settle(&mut self, id: u64, outcome: &Outcome, base: &RunSettings) {
        let scan_id = outcome
            .dir
            .as_ref()
            .and_then(|d| d.file_name())
            .map(|n| n.to_string_lossy().into_owned());
        match (&outcome.end, &scan_id) {
            // The scan resumes at the next start, or is continued by the daemon once its
            // devices answer again: the job goes on.
            (End::Shutdown, _) => {}
            (End::Fail(r), Some(_)) if r.cause() == FailCause::Budget => {}
            (End::Fail(FailReason::NotStarted(fault)), None) => {
                let why = self.back_off(base, |s| {
                    format!("job {id} waits for its devices: {fault}; tried again in {s} s")
                });
                if let Err(e) = self.queue.requeue(id, &why) {
                    tracing::error!("{e}");
                }
            }
            // The file system refused reopening its scan, which can clear by itself: the scan
            // is left as it is and the job running; its turn tries it again with backoff.
            (End::Fail(r), Some(scan)) if r.refused_by_the_file_system() => {
                self.back_off(base, |s| {
                    format!("job {id} waits: its scan {scan} could not be reopened: {r}; tried again in {s} s")
                });
            }
            // A running job's scan the runner would not reopen for having ended (its ending
            // recorded in its journal, not yet in the queue): the job ends as its journal
            // says, as after a restart, with its scan and verdict; still running after that
            // (its scan refused for another reason), it ends by the refusal.
            (End::Fail(r @ FailReason::Refused { .. }), None)
                if r.kind() == FailKind::Scan && self.running_scan(id).is_some() =>
            {
                let _ = self.settle_by_its_journal(id);
                if self.queue.status().running == Some(id) {
                    self.ends_by(id, outcome, None);
                }
            }
            _ => self.ends_by(id, outcome, scan_id),
        }
    }

    /// Ends job `id` by its scan's `outcome` (`scan_id`: the scan the outcome names).
    fn ends_by(&mut self, id: u64, outcome: &Outcome, scan_id: Option<String>) {
        self.retry = None;
        self.delay = Duration::ZERO;
        let end = &outcome.end;
        let created = scan_id.is_some();
        // A running job's scan refused for another reason than its own files (a directory
        // that is not one) is still named in the job's record.
        let scan_id = scan_id.or_else(|| self.running_scan(id));
        let verdict = outcome
            .outputs
            .as_ref()
            .and_then(|o| o.results.as_ref())
            .and_then(|r| r.verdict);
        let outcome_word = match end {
            End::Fail(FailReason::Refused { .. }) if !created => "refused".to_owned(),
            e => e.status().as_str().to_owned(),
        };
        self.end(
            id,
            JobOutcome {
                scan_id,
                outcome: outcome_word,
                verdict,
                reason: end.reason(created),
            },
        );
    }

    /// The scan recorded for running job `id`, if any.
    fn running_scan(&self, id: u64) -> Option<String> {
        match &self.queue.snapshot().get(id)?.state {
            JobState::Running { scan_id, .. } => scan_id.clone(),
            _ => None,
        }
    }

    /// Waits the next step of the backoff before the job's next try (the reconnection
    /// backoff's, doubling up to its maximum); the reason, made by `why` of the seconds, is
    /// the turn's meanwhile.
    fn back_off(&mut self, base: &RunSettings, why: impl FnOnce(u64) -> String) -> String {
        self.delay = base.backoff.next(self.delay);
        let why = why(self.delay.as_secs());
        self.retry = Some((Instant::now() + self.delay, why.clone()));
        why
    }

    /// The scan of no job the file system refused to reopen, to reopen now that its wait is
    /// over ([`Turn::Reopen`]), as the daemon reopens it at its start: while its journal has
    /// no stop record (or cannot be read: the reopening says why). One that has ended
    /// meanwhile is forgotten.
    fn refused_scan_due(&mut self, now: Instant) -> Option<ScanRequest> {
        let r = self.refused_scan.as_ref().filter(|r| now >= r.at)?;
        if state_of(&r.dir).is_some_and(|s| s.stop.is_some()) {
            self.refused_scan = None;
            return None;
        }
        Some(ScanRequest::Resume {
            dir: r.dir.clone(),
            peer: None,
        })
    }

    /// After a scan that was not started as a job (the daemon's resumption at start-up or
    /// with backoff, an operator's start): when it was the running job's scan, the job's
    /// ending is recorded; a scan the file system refused to reopen is reopened again after
    /// the backoff's next step (longer each time the same scan is refused again), and the
    /// queue's next job waits for it.
    pub fn settle_if_a_job(&mut self, outcome: &Outcome, base: &RunSettings) {
        let before = self.refused_scan.take();
        let running = self.queue.status().running;
        if let Some(id) =
            running.filter(|id| outcome.dir.as_deref().is_some_and(|d| names_job(d, *id)))
        {
            // A job's scan: its turn tries it again.
            return self.settle(id, outcome, base);
        }
        self.refused_scan = match (&outcome.end, &outcome.dir) {
            (End::Fail(r), Some(dir)) if r.refused_by_the_file_system() => {
                let waited = before
                    .filter(|b| b.dir == *dir)
                    .map_or(Duration::ZERO, |b| b.delay);
                let delay = base.backoff.next(waited);
                tracing::info!("{}: reopened again in {} s", dir.display(), delay.as_secs());
                Some(RefusedScan {
                    dir: dir.clone(),
                    why: r.to_string(),
                    at: Instant::now() + delay,
                    delay,
                })
            }
            _ => None,
        };
    }

    /// The settings and the new scan's job of `start --recipe`: the recipe's text as the
    /// control socket read it, validated with the station's configuration.
    pub fn recipe_settings(
        &self,
        r: &RecipeStart,
        base: &RunSettings,
    ) -> Result<(RunSettings, NewJob), String> {
        let station = self.queue.station();
        let recipe = Recipe::from_text(
            &r.record.recipe,
            &station
                .jobs
                .recipes
                .join(format!("{}.toml", r.record.recipe)),
            &r.record.recipe_text,
            station,
        )
        .map_err(|e| e.to_string())?;
        let config = recipe
            .config_for(station, r.y_start.map(|y| y.to_mm()))
            .map_err(|e| e.to_string())?;
        Ok((self.settings_of(&config, base)?, recipe.new_job(None)))
    }

    fn end(&self, id: u64, end: JobOutcome) {
        if let Err(e) = self.queue.finish(id, end) {
            tracing::error!("job {id}: its ending could not be recorded in the queue: {e}");
        }
    }
}

fn refused(why: String) -> JobOutcome {
    JobOutcome {
        scan_id: None,
        outcome: "refused".into(),
        verdict: None,
        reason: why,
    }
}

/// Whether the scan in `dir` was made for job `id`.
fn names_job(dir: &Path, id: u64) -> bool {
    state_of(dir).and_then(|s| s.start.job).and_then(|j| j.id) == Some(id)
}

/// What the journal of the scan in `dir` says, when it can be read.
fn state_of(dir: &Path) -> Option<ResumeState> {
    let path = dir.join(JOURNAL_FILE);
    read_journal(&path)
        .ok()
        .and_then(|r| ResumeState::from_records(&path, &r.records).ok())
}

#[cfg(test)]
mod tests {
    use super::{Jobs, Turn};
    use crate::jobs::queue::JobState;
    use crate::jobs::service::{tests::station, AddJob, QueueService};
    use crate::jobs::synthetic::{write, SyntheticScan};
    use crate::scan::choice::{self, Asker, Decision};
    use crate::scan::command::Peer;
    use crate::scan::ending::{End, FailCause, FailKind, FailReason, StopStatus};
    use crate::scan::journal::{Journal, StopRecord, JOURNAL_FILE};
    use crate::scan::outcome::{Outcome, ScanRequest};
    use crate::scan::settings::RunSettings;
    use crate::scan::testhooks::TestHooks;
    use std::path::{Path, PathBuf};
    use std::time::Instant;

    /// The station's settings, its queue in `dir` and the one job queued in it (recipe
    /// `brass`, specimen C-1).
    fn one_job(dir: &Path) -> (RunSettings, QueueService, u64) {
        let config = station(dir);
        let base =
            super::run_settings(&config, "ab".repeat(32), TestHooks::default()).expect("settings");
        let (queue, _) = QueueService::open(config).expect("queue");
        let job = queue
            .add(
                AddJob {
                    recipe: "brass".into(),
                    specimen: "C-1".into(),
                    operator: String::new(),
                    notes: String::new(),
                    y_start_mm: None,
                    needs_loading: false,
                },
                None,
            )
            .expect("added")
            .id;
        (base, queue, job)
    }

    /// A scan of 11 lines with 4 done, unfinished, in `out`: job `job`'s when given.
    fn scan_of(out: &Path, job: Option<u64>) -> (SyntheticScan, PathBuf) {
        let scan = SyntheticScan {
            id: "20261207-2200-C-1".into(),
            sequence: 1,
            started: "2026-12-07T22:00:00Z".parse().expect("a time"),
            specimen: "C-1".into(),
            recipe: Some(("brass".into(), job)),
            lines: 11,
            done: 4,
            stop: None,
            report: None,
        };
        let dir = write(out, &scan).expect("scan");
        (scan, dir)
    }

    /// Ends the scan in `dir` as an earlier version did when the file system refused a write
    /// (a `fail` stop record of cause `storage`, which a plain start continues).
    fn failed_for_storage(dir: &Path) {
        failed_for(
            dir,
            FailCause::Storage,
            "storage: write lines/0004.csv: Read-only file system (os error 30)",
        );
    }

    /// Ends the scan in `dir` by a `fail` stop record of `cause`, saying `reason`.
    fn failed_for(dir: &Path, cause: FailCause, reason: &str) {
        let stop = StopRecord {
            status: StopStatus::Fail,
            reason: reason.into(),
            cause: Some(cause),
            internal: false,
            time: "2026-12-07T22:30:00Z".parse().expect("a time"),
        };
        Journal::append_stop(&dir.join(JOURNAL_FILE), stop).expect("stopped");
    }

    /// One job running with its scan of [`scan_of`], as the queue keeper holds it after the
    /// scan began: the settings, the keeper, the job, the scan and its directory.
    fn running_with_its_scan(root: &Path) -> (RunSettings, Jobs, u64, SyntheticScan, PathBuf) {
        let (base, queue, job) = one_job(root);
        queue.mark_running(job).expect("running");
        let (scan, dir) = scan_of(&base.output_dir, Some(job));
        queue.set_scan(job, &scan.id).expect("its scan");
        (base, Jobs::new(queue, "ab".repeat(32)), job, scan, dir)
    }

    /// A queued job waits for a scan an earlier version failed because the file system
    /// refused a write (a plain start continues it, so the choice does): the wait names it as
    /// failed and how to continue it, not as an unfinished scan to resume or abort (it has
    /// ended; there is nothing to abort).
    #[test]
    fn a_job_waiting_for_a_scan_failed_for_storage_says_it_failed() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, queue, job) = one_job(tmp.path());
        let (_, dir) = scan_of(&base.output_dir, None);
        failed_for_storage(&dir);
        let mut jobs = Jobs::new(queue, "ab".repeat(32));
        let Turn::Wait(why) = jobs.turn(&base, true, Instant::now()) else {
            panic!("the job does not wait");
        };
        assert_eq!(
            why,
            format!(
                "job {job} waits: the scan {} failed when the file system refused a write and is continued first (`surfscan start` continues it)",
                dir.display()
            )
        );
    }

    /// A queued job whose own scan an earlier version failed because the file system refused
    /// a write (its scan created before the queue recorded it) has it continued, as the
    /// choice decides: reopened as an unfinished scan, it was refused for having ended, and
    /// the job ended `refused` without its scan.
    #[test]
    fn a_job_whose_own_scan_failed_for_storage_continues_it() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, queue, job) = one_job(tmp.path());
        let (_, dir) = scan_of(&base.output_dir, Some(job));
        failed_for_storage(&dir);
        let mut jobs = Jobs::new(queue, "ab".repeat(32));
        let turn = jobs.turn(&base, true, Instant::now());
        assert!(
            matches!(&turn, Turn::Run { job: j, request: ScanRequest::Continue { dir: d, peer: None }, .. } if *j == job && *d == dir),
            "not continued"
        );
    }

    /// The runner's outcome when the file system refused reopening the scan in `dir`, `why`.
    fn refused_by_the_file_system(why: &str, dir: &Path) -> Outcome {
        Outcome {
            end: End::Fail(FailReason::Refused {
                message: why.into(),
                kind: FailKind::Io,
            }),
            dir: Some(dir.to_path_buf()),
            outputs: None,
        }
    }

    /// A job's scan whose reopening the file system refused (the daemon's at its start) is
    /// left as it is, which can clear by itself: the job stays running with its scan, the
    /// queue's turn waits, naming the scan and the refusal (with its fix), for the backoff's
    /// first step, then reopens the scan again. Before, the runner's outcome did not name the
    /// scan: the job stayed running and its turn reopened the scan at once, then ended the job
    /// `refused` without its scan id.
    #[test]
    fn a_job_whose_scan_the_file_system_refused_to_reopen_waits_with_its_scan() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, mut jobs, job, scan, dir) = running_with_its_scan(tmp.path());
        let why = "the file system refused reading its lines back (EROFS: …); …; remount the output directory's file system read-write";
        let outcome = refused_by_the_file_system(why, &dir);

        let now = Instant::now();
        jobs.settle_if_a_job(&outcome, &base);
        let snapshot = jobs.queue.snapshot();
        let state = &snapshot.get(job).expect("the job").state;
        assert!(
            matches!(state, JobState::Running { scan_id: Some(s), .. } if *s == scan.id),
            "{state:?}"
        );
        let Turn::Wait(waits) = jobs.turn(&base, true, now) else {
            panic!("the scan is reopened again at once");
        };
        let step = base.backoff.initial;
        assert_eq!(
            waits,
            format!(
                "job {job} waits: its scan {} could not be reopened: {why}; tried again in {} s",
                scan.id,
                step.as_secs()
            )
        );
        let later = Instant::now() + step;
        assert!(
            matches!(jobs.turn(&base, true, later), Turn::Run { job: j, request: ScanRequest::Resume { dir: d, .. }, .. } if j == job && d == dir),
            "the scan is not reopened after the backoff"
        );
    }

    /// A job's scan whose reopening panicked, or was refused for the scan's own files (the
    /// daemon's at its start, as the runner ends it: a failure recorded, with the scan's
    /// directory) ends the job `fail` with its scan, and the queue's next turn does not
    /// reopen the scan again. Refused without its directory, as before, the job stayed
    /// running and the turn reopened its scan a second time, then ended it `refused` without
    /// its scan id.
    #[test]
    fn a_job_whose_scan_could_not_be_reopened_for_good_ends_with_its_scan() {
        for (why, kind) in [
            ("internal error: reopening the scan panicked (a bug); report this with the scan's directory and the log", FailKind::Internal),
            ("the scan cannot be reopened: reading its journal: …; nothing reopens it by itself: …", FailKind::Scan),
        ] {
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, mut jobs, job, scan, dir) = running_with_its_scan(tmp.path());
        let outcome = Outcome {
            end: End::Fail(FailReason::Refused {
                message: why.into(),
                kind,
            }),
            dir: Some(dir),
            outputs: None,
        };

        jobs.settle_if_a_job(&outcome, &base);
        let snapshot = jobs.queue.snapshot();
        let state = &snapshot.get(job).expect("the job").state;
        assert!(
            matches!(state, JobState::Finished { scan_id: Some(s), outcome, reason, .. }
                if *s == scan.id && outcome == "fail" && reason == why),
            "{state:?}"
        );
        assert!(
            matches!(jobs.turn(&base, true, Instant::now()), Turn::Nothing),
            "the scan is reopened again"
        );
        }
    }

    /// A running job whose scan has ended (its ending in its journal, not yet in the queue)
    /// is refused reopening without the scan (the runner cannot continue an ended scan):
    /// the job ends as its scan's journal says, as after a restart: `success` here, with its
    /// scan id and its report's verdict, not `refused` without its scan. A scan refused for
    /// another reason than its end (a symbolic link) still names the job's scan.
    #[test]
    fn a_running_job_whose_scan_has_ended_ends_as_its_journal_says() {
        use crate::jobs::synthetic::SyntheticReport;
        use crate::specification::rule::Verdict;
        let refusal = |message: &str| {
            Outcome::without_scan(End::Fail(FailReason::Refused {
                message: message.into(),
                kind: FailKind::Scan,
            }))
        };
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, queue, job) = one_job(tmp.path());
        queue.mark_running(job).expect("running");
        let (mut scan, _) = scan_of(&base.output_dir, Some(job));
        scan.done = scan.lines;
        scan.stop = Some(StopStatus::Success);
        scan.report = Some(SyntheticReport {
            verdict: Some(Verdict::Conforms),
            ra_um: vec![0.5; 11],
            sa_um: 0.6,
            warnings: 0,
        });
        write(&base.output_dir, &scan).expect("ended scan");
        queue.set_scan(job, &scan.id).expect("its scan");
        let mut jobs = Jobs::new(queue, "ab".repeat(32));
        jobs.settle(
            job,
            &refusal(
                "scan 20261207-2200-C-1 has ended (success: synthetic); it cannot be continued",
            ),
            &base,
        );
        let snapshot = jobs.queue.snapshot();
        let state = &snapshot.get(job).expect("the job").state;
        assert!(
            matches!(state, JobState::Finished { scan_id: Some(s), outcome, verdict: Some(Verdict::Conforms), reason, .. }
                if *s == scan.id && outcome == "success" && reason == "synthetic"),
            "{state:?}"
        );

        let tmp = tempfile::tempdir().expect("tmp");
        let (base, mut jobs, job, scan, _) = running_with_its_scan(tmp.path());
        let why = "the scan's directory is not one";
        jobs.settle(job, &refusal(why), &base);
        let snapshot = jobs.queue.snapshot();
        let state = &snapshot.get(job).expect("the job").state;
        assert!(
            matches!(state, JobState::Finished { scan_id: Some(s), outcome, reason, .. }
                if *s == scan.id && outcome == "refused" && reason == why),
            "{state:?}"
        );
    }

    /// A running job's scan that failed for its transient budget (the daemon was waiting for
    /// its devices when its continuation was refused by the file system, say) is continued
    /// at the job's turn once its devices are present, as the daemon continues such a scan,
    /// and waits for them meanwhile. Before, the turn asked to resume it as an unfinished
    /// scan, the reopening refused it for having ended, and the job ended `refused`.
    #[test]
    fn a_running_jobs_scan_failed_for_its_budget_is_continued_at_its_turn() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, mut jobs, job, scan, dir) = running_with_its_scan(tmp.path());
        failed_for(
            &dir,
            FailCause::Budget,
            "line 5: the instrument kept answering wrongly",
        );
        let Turn::Wait(waits) = jobs.turn(&base, false, Instant::now()) else {
            panic!("continued without its devices");
        };
        assert_eq!(
            waits,
            format!(
                "job {job} waits: its scan {} failed for its transient budget and is continued once the instrument and the stage are present",
                scan.id
            )
        );
        assert!(
            matches!(jobs.turn(&base, true, Instant::now()), Turn::Run { job: j, request: ScanRequest::Continue { dir: d, peer: None }, .. } if j == job && d == dir),
            "not continued"
        );
    }

    /// Whether a running job's failed scan is continued or has ended for its job is one rule,
    /// asked alike by the queue's settling after a restart, the job's turn and the daemon's
    /// start-up choice. By the fault policy's table: the daemon continues a scan that failed
    /// for its transient budget or (an earlier version's ending) because the file system
    /// refused a write, and an operator's fault ends it. Before, the settling after a restart
    /// took a `storage` failure for the scan's ending and finished the job `fail`, while the
    /// start-up choice and the job's turn continued that scan.
    #[test]
    fn a_running_jobs_failed_scan_is_continued_or_ended_by_one_rule() {
        for (cause, reason, continued) in [
            (FailCause::Budget, "line 5: transient faults since 22:10:00 outlasted the 60 s budget (3 trace(s) started); last: …", true),
            (FailCause::Storage, "storage: write lines/0004.csv: Read-only file system (os error 30)", true),
            (FailCause::Operator, "line 5: instrument: battery abnormal", false),
        ] {
            let tmp = tempfile::tempdir().expect("tmp");
            let (base, mut jobs, job, scan, dir) = running_with_its_scan(tmp.path());
            failed_for(&dir, cause, reason);

            let at_start = choice::choose(
                &base.output_dir,
                Asker::DaemonStartUp,
                Peer::this_process(),
                Default::default(),
            )
            .expect("chosen")
            .decision;
            assert_eq!(
                matches!(&at_start, Decision::Continue(d) | Decision::AwaitDevices(d) if *d == dir),
                continued,
                "{cause:?}: the start-up choice {at_start:?}"
            );

            jobs.queue.reconcile().expect("settled");
            let snapshot = jobs.queue.snapshot();
            let state = &snapshot.get(job).expect("the job").state;
            if continued {
                assert!(
                    matches!(state, JobState::Running { scan_id: Some(s), .. } if *s == scan.id),
                    "{cause:?}: settled {state:?}"
                );
                assert!(
                    matches!(jobs.turn(&base, true, Instant::now()), Turn::Run { job: j, request: ScanRequest::Continue { dir: d, peer: None }, .. } if j == job && d == dir),
                    "{cause:?}: not continued at its turn"
                );
            } else {
                assert!(
                    matches!(state, JobState::Finished { scan_id: Some(s), outcome, reason: r, .. }
                        if *s == scan.id && outcome == "fail" && r == reason),
                    "{cause:?}: settled {state:?}"
                );
            }
        }
    }

    /// A running job whose scan has ended without the queue recording it (its reopening
    /// refused for its own files and recorded so, the job's ending lost) is settled at its
    /// turn as its journal says, as after a restart: `fail` with its scan and the stop
    /// record's reason, and the scan is not reopened. Before, the turn asked to resume it as
    /// an unfinished scan.
    #[test]
    fn a_running_jobs_scan_that_has_ended_settles_the_job_at_its_turn() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, mut jobs, job, scan, dir) = running_with_its_scan(tmp.path());
        let why = "the scan cannot be reopened: reading its journal: …";
        failed_for(&dir, FailCause::Operator, why);
        let turn = jobs.turn(&base, true, Instant::now());
        assert!(
            !matches!(turn, Turn::Run { .. }),
            "the ended scan is reopened"
        );
        let snapshot = jobs.queue.snapshot();
        let state = &snapshot.get(job).expect("the job").state;
        assert!(
            matches!(state, JobState::Finished { scan_id: Some(s), outcome, reason, .. }
                if *s == scan.id && outcome == "fail" && reason == why),
            "{state:?}"
        );
    }

    /// A queued job behind a scan of no job that the file system refused to reopen at the
    /// daemon's start waits for it, and the wait says so and when it is tried again: it read
    /// only that the unfinished scan must end first. Once another outcome follows (an
    /// operator's start of it), the wait is the plain one again.
    #[test]
    fn a_job_behind_a_scan_the_file_system_refused_says_so() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, queue, job) = one_job(tmp.path());
        let (_, dir) = scan_of(&base.output_dir, None);
        let mut jobs = Jobs::new(queue, "ab".repeat(32));
        let why = "the file system refused reading its journal (EIO: …); …; check the disk";
        let refused = refused_by_the_file_system(why, &dir);
        jobs.settle_if_a_job(&refused, &base);
        let plain = format!(
            "job {job} waits: the unfinished scan {} must end first (resume it with `surfscan resume` or `surfscan start`, or abort it)",
            dir.display()
        );
        let Turn::Wait(waits) = jobs.turn(&base, true, Instant::now()) else {
            panic!("the job does not wait");
        };
        assert_eq!(
            waits,
            format!("{plain}; the file system refused reopening it ({why}), and it is tried again within {} s, or by `surfscan start`", base.backoff.initial.as_secs())
        );

        jobs.settle_if_a_job(&Outcome::without_scan(End::Shutdown), &base);
        let Turn::Wait(waits) = jobs.turn(&base, true, Instant::now()) else {
            panic!("the job does not wait");
        };
        assert_eq!(waits, plain);
    }

    /// A scan of no job the file system refused to reopen (at the daemon's start) is reopened
    /// again by the daemon after the reconnection backoff's step, as a job's scan is, the wait
    /// doubling while the same scan is refused again; one that has ended meanwhile is not.
    /// Before, it was tried again only at the next start or an operator's start: a disk that
    /// cleared at night left the station idle until morning.
    #[test]
    fn a_scan_of_no_job_the_file_system_refused_is_reopened_with_backoff() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (base, queue, _) = one_job(tmp.path());
        queue.clear(None).expect("no job");
        let (_, dir) = scan_of(&base.output_dir, None);
        let mut jobs = Jobs::new(queue, "ab".repeat(32));
        let refused = refused_by_the_file_system("the file system refused …", &dir);
        let step = base.backoff.initial;
        let reopens = |jobs: &mut Jobs, at: Instant| matches!(jobs.turn(&base, true, at), Turn::Reopen(ScanRequest::Resume { dir: d, peer: None }) if d == dir);

        let now = Instant::now();
        jobs.settle_if_a_job(&refused, &base);
        assert!(
            !reopens(&mut jobs, now),
            "reopened before the backoff's step"
        );
        assert!(
            reopens(&mut jobs, Instant::now() + step),
            "not reopened after it"
        );

        // Refused again: twice the wait.
        let now = Instant::now();
        jobs.settle_if_a_job(&refused, &base);
        assert!(!reopens(&mut jobs, now + step), "the wait did not double");
        assert!(
            reopens(&mut jobs, Instant::now() + 2 * step),
            "not reopened after twice the step"
        );

        // Ended meanwhile (its stop record written by hand, say): forgotten.
        failed_for(&dir, FailCause::Operator, "ended by hand");
        assert!(
            matches!(
                jobs.turn(&base, true, Instant::now() + 4 * step),
                Turn::Nothing
            ),
            "an ended scan is reopened"
        );
    }
}
