//! The daemon's keeper of the job queue: the one owner of [`Queue`] and its files, serving
//! the operator's queue commands (from the control socket, while a scan runs or not) and the
//! daemon's own steps (start, scan created, finished, settle after a restart).
//!
//! Every change is made on a copy, written durably, logged with its peer, and only then
//! becomes the queue and is answered: what the operator is told is on disk. A change that
//! cannot be written (a full disk) is refused and the queue stays as it was. Subscribers
//! ([`QueueService::subscribe`]) learn of every change, so an idle daemon starts a job the
//! moment it is added or its specimen is loaded.
//!
//! A job added is validated here against the recipe file as it is now and the station's
//! configuration the daemon runs with: an unknown name or a bad `--y-start-mm` is refused
//! as a usage error, a recipe that is not valid as a configuration error, before the job is
//! queued — never discovered when its turn comes at night.
//!
//! Layer 4 (process edge): depends on [`super::queue`], [`super::recipe`],
//! [`super::index`] and the configuration; blocking (file writes with fsync): async callers
//! use `tokio::task::spawn_blocking`.

use super::index::ScanIndex;
use super::queue::{
    FrozenRecipe, Job, JobOutcome, JobRequest, JobScan, LogEntry, Next, Queue, QueueError,
    QueueStore,
};
use super::recipe::{Recipe, RecipeError};
use crate::config::Config;
use crate::scan::command::Peer;
use crate::scan::journal::{read_journal, ResumeState, JOURNAL_FILE};
use chrono::Utc;
use std::path::Path;
use std::sync::{Arc, Mutex};
use tokio::sync::watch;

/// A queue command that was not carried out, with the exit status its command line gives.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ServiceError {
    /// What the operator typed cannot be done (an unknown recipe, a job that is not there):
    /// exit 2.
    #[error("{0}")]
    Usage(String),
    /// The recipe file is not valid: exit 78.
    #[error("{0}")]
    Config(String),
    /// The queue could not be written: exit 74; nothing changed.
    #[error("{0}")]
    Io(String),
}

impl ServiceError {
    /// The command line's exit status for this refusal.
    pub fn exit_code(&self) -> u8 {
        match self {
            ServiceError::Usage(_) => 2,
            ServiceError::Config(_) => 78,
            ServiceError::Io(_) => 74,
        }
    }
}

impl From<QueueError> for ServiceError {
    fn from(e: QueueError) -> ServiceError {
        ServiceError::Usage(e.to_string())
    }
}

impl From<RecipeError> for ServiceError {
    fn from(e: RecipeError) -> ServiceError {
        if e.is_usage() {
            ServiceError::Usage(e.to_string())
        } else {
            ServiceError::Config(e.to_string())
        }
    }
}

/// `surfscan queue add`'s request.
#[derive(Debug, Clone, PartialEq)]
pub struct AddJob {
    /// Recipe name.
    pub recipe: String,
    /// Specimen id.
    pub specimen: String,
    /// Operator.
    pub operator: String,
    /// Notes.
    pub notes: String,
    /// y of the first line, mm (overrides the recipe's).
    pub y_start_mm: Option<f64>,
    /// Wait for `surfscan ready` before the job starts.
    pub needs_loading: bool,
}

struct Inner {
    queue: Mutex<Queue>,
    store: QueueStore,
    station: Config,
    changed: watch::Sender<u64>,
}

/// The queue's keeper; cheap to clone (shared).
#[derive(Clone)]
pub struct QueueService {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for QueueService {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QueueService")
            .field("store", &self.inner.store)
            .finish_non_exhaustive()
    }
}

/// A recipe as a job runs it: the frozen text validated with the station's configuration,
/// and the configuration with its plan and analysis.
#[derive(Debug, Clone)]
pub struct JobPlan {
    /// The job.
    pub job: Job,
    /// Its recipe, from the frozen text.
    pub recipe: Recipe,
    /// The station's configuration with the recipe's plan (the job's y start) and analysis.
    pub config: Config,
}

impl QueueService {
    /// Opens the queue kept in the station's output directory. A fresh queue (none yet, or
    /// a damaged one moved aside, named in the returned warning) numbers its jobs after the
    /// highest job any journal there names, so a number is never given twice.
    pub fn open(station: Config) -> Result<(QueueService, Option<String>), ServiceError> {
        let store = QueueStore::new(&station.output.dir);
        let (mut queue, warning) = store.load().map_err(|e| ServiceError::Io(e.to_string()))?;
        if queue.jobs.is_empty() {
            let highest = highest_job_in_journals(&station.output.dir);
            queue.next_id = queue.next_id.max(highest + 1);
        }
        let (changed, _) = watch::channel(0);
        Ok((
            QueueService {
                inner: Arc::new(Inner {
                    queue: Mutex::new(queue),
                    store,
                    station,
                    changed,
                }),
            },
            warning,
        ))
    }

    /// Notified (the counter changes) on every change of the queue.
    pub fn subscribe(&self) -> watch::Receiver<u64> {
        self.inner.changed.subscribe()
    }

    /// The queue as it is.
    pub fn snapshot(&self) -> Queue {
        self.lock().clone()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Queue> {
        // A panic of a request that held the lock (the daemon serves on, `crate::panics`)
        // leaves the last whole queue: a change is made to a copy, written, and only then
        // made the queue.
        self.inner
            .queue
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Applies `change` to a copy, writes it, logs `command`, then makes it the queue.
    fn change<T>(
        &self,
        command: &str,
        peer: Option<Peer>,
        change: impl FnOnce(&mut Queue) -> Result<(T, Vec<u64>, String), ServiceError>,
    ) -> Result<T, ServiceError> {
        let mut q = self.lock();
        let mut copy = q.clone();
        let (out, jobs, detail) = change(&mut copy)?;
        self.inner
            .store
            .save(&copy)
            .map_err(|e| ServiceError::Io(format!("{e}; the queue is unchanged")))?;
        *q = copy;
        drop(q);
        match &peer {
            Some(p) => tracing::info!(uid = p.uid, pid = ?p.pid, "queue {command}: {detail}"),
            None => tracing::info!("queue {command}: {detail}"),
        }
        let entry = LogEntry {
            time: Utc::now(),
            command: command.to_owned(),
            jobs,
            peer,
            detail,
        };
        if let Err(e) = self.inner.store.log(&entry) {
            tracing::warn!("{e}; the queue itself was written");
        }
        self.inner.changed.send_modify(|n| *n += 1);
        Ok(out)
    }

    /// `surfscan queue add`: validates the recipe (as it is now) with the station's
    /// configuration and the job's y, freezes it and queues the job.
    pub fn add(&self, req: AddJob, peer: Option<Peer>) -> Result<Job, ServiceError> {
        let dir = &self.inner.station.jobs.recipes;
        let recipe = Recipe::load(dir, &req.recipe, &self.inner.station)?;
        recipe.config_for(&self.inner.station, req.y_start_mm)?;
        let request = JobRequest {
            recipe: FrozenRecipe {
                name: recipe.name.clone(),
                path: recipe.path.clone(),
                text: recipe.text.clone(),
                sha256: recipe.sha256.clone(),
            },
            specimen: req.specimen,
            operator: req.operator,
            notes: req.notes,
            y_start_mm: req.y_start_mm,
            needs_loading: req.needs_loading,
        };
        self.change("add", peer.clone(), |q| {
            let id = q.add(request, Utc::now(), peer);
            let job = q.get(id).expect("just added").clone();
            let detail = format!(
                "{} (recipe sha256 {})",
                job.describe(),
                &job.request.recipe.sha256[..12]
            );
            Ok((job, vec![id], detail))
        })
    }

    /// `surfscan start --recipe NAME [--y-start-mm Y]`: the recipe read and validated now
    /// (as for a job) and frozen for the start; no queue number.
    pub fn recipe_start(
        &self,
        name: &str,
        y_start_mm: Option<f64>,
    ) -> Result<crate::scan::command::RecipeStart, ServiceError> {
        let recipe = Recipe::load(&self.inner.station.jobs.recipes, name, &self.inner.station)?;
        recipe.config_for(&self.inner.station, y_start_mm)?;
        let y_start = match y_start_mm {
            None => None,
            Some(y) => Some(crate::units::Nm::try_from_mm(y).ok_or_else(|| {
                ServiceError::Usage(format!(
                    "--y-start-mm {y} is not a whole number of nanometres; round it"
                ))
            })?),
        };
        Ok(crate::scan::command::RecipeStart {
            record: recipe.job_record(None),
            y_start,
        })
    }

    /// The station's configuration the daemon runs with.
    pub fn station(&self) -> &Config {
        &self.inner.station
    }

    /// `surfscan queue remove JOB`.
    pub fn remove(&self, id: u64, peer: Option<Peer>) -> Result<Job, ServiceError> {
        self.change("remove", peer, |q| {
            let job = q.remove(id)?;
            let d = job.describe();
            Ok((job, vec![id], d))
        })
    }

    /// `surfscan queue clear`: every queued job (not the running one).
    pub fn clear(&self, peer: Option<Peer>) -> Result<Vec<Job>, ServiceError> {
        self.change("clear", peer, |q| {
            let gone = q.clear();
            let ids: Vec<u64> = gone.iter().map(|j| j.id).collect();
            let d = format!("{} queued jobs removed", ids.len());
            Ok((gone, ids, d))
        })
    }

    /// `surfscan ready [JOB]`.
    pub fn ready(&self, id: Option<u64>, peer: Option<Peer>) -> Result<u64, ServiceError> {
        self.change("ready", peer, |q| {
            let id = q.ready(id)?;
            Ok((id, vec![id], format!("job {id}: specimen loaded")))
        })
    }

    /// `surfscan queue continue`.
    pub fn release(&self, peer: Option<Peer>) -> Result<(), ServiceError> {
        self.change("continue", peer, |q| {
            q.release()?;
            Ok(((), Vec::new(), "the queue runs on".to_owned()))
        })
    }

    /// What the daemon does next.
    pub fn next(&self) -> Next {
        self.lock().next()
    }

    /// Marks job `id` running before its scan is created.
    pub fn mark_running(&self, id: u64) -> Result<(), ServiceError> {
        self.change("start", None, |q| {
            q.mark_running(id, Utc::now());
            Ok(((), vec![id], format!("job {id} running")))
        })
    }

    /// Puts job `id` back in its place: its scan could not be created (a device missing).
    pub fn requeue(&self, id: u64, why: &str) -> Result<(), ServiceError> {
        self.change("requeue", None, |q| {
            q.requeue(id);
            Ok(((), vec![id], format!("job {id} waits: {why}")))
        })
    }

    /// The queue in the status.
    pub fn status(&self) -> crate::scan::status::QueueStatus {
        self.lock().status()
    }

    /// Records the scan created for job `id`.
    pub fn set_scan(&self, id: u64, scan_id: &str) -> Result<(), ServiceError> {
        self.change("scan", None, |q| {
            q.set_scan(id, scan_id);
            Ok(((), vec![id], format!("job {id}: scan {scan_id}")))
        })
    }

    /// Records how job `id` ended; a failure stops the queue when its recipe says so.
    pub fn finish(&self, id: u64, end: JobOutcome) -> Result<(), ServiceError> {
        let stop = self.lock().get(id).is_some_and(|j| self.stop_on_failure(j));
        self.change("finish", None, |q| {
            let detail = format!(
                "job {id} ended {}{}: {}",
                end.outcome,
                end.verdict.map(|v| format!(", {v}")).unwrap_or_default(),
                end.reason
            );
            q.finish(id, end, stop, Utc::now());
            Ok(((), vec![id], detail))
        })
    }

    fn stop_on_failure(&self, job: &Job) -> bool {
        // The frozen recipe decides; one that no longer parses was refused at its start and
        // is stopped on (the safe side).
        toml::from_str::<super::recipe::RecipeFile>(&job.request.recipe.text)
            .map_or(true, |r| r.queue.stop_on_failure)
    }

    /// After a restart: settles a running job by what the journals say of the scan that
    /// names it (see [`Queue::reconcile`]).
    pub fn reconcile(&self) -> Result<Vec<String>, ServiceError> {
        let out = self.inner.station.output.dir.clone();
        let running: Vec<(u64, Option<String>)> = self
            .lock()
            .jobs
            .iter()
            .filter_map(|j| match &j.state {
                super::queue::JobState::Running { scan_id, .. } => Some((j.id, scan_id.clone())),
                _ => None,
            })
            .collect();
        if running.is_empty() {
            return Ok(Vec::new());
        }
        let scans: Vec<(u64, Option<JobScan>)> = running
            .into_iter()
            .map(|(id, scan)| (id, find_job_scan(&out, id, scan.as_deref())))
            .collect();
        let this = self.clone();
        self.change("reconcile", None, |q| {
            let notes = q.reconcile(
                |id| {
                    scans
                        .iter()
                        .find(|(j, _)| *j == id)
                        .and_then(|(_, s)| s.clone())
                },
                |j| this.stop_on_failure(j),
                Utc::now(),
            );
            let ids = scans.iter().map(|(id, _)| *id).collect();
            let detail = notes.join("; ");
            Ok((notes, ids, detail))
        })
    }

    /// Job `id`'s recipe from its frozen text, validated with the station's configuration
    /// as it is now, and that configuration with the recipe's plan; the reason when it
    /// cannot run.
    pub fn plan_of(&self, id: u64) -> Result<JobPlan, String> {
        let job = self
            .lock()
            .get(id)
            .cloned()
            .ok_or_else(|| format!("no job {id}"))?;
        let r = &job.request.recipe;
        let recipe =
            Recipe::from_text(&r.name, &r.path, &r.text, &self.inner.station).map_err(|e| {
                format!(
                    "its recipe as frozen is not valid with the station's configuration now: {e}"
                )
            })?;
        let config = recipe
            .config_for(&self.inner.station, job.request.y_start_mm)
            .map_err(|e| e.to_string())?;
        Ok(JobPlan {
            job,
            recipe,
            config,
        })
    }
}

/// The highest job number any journal under `out` names (0 for none), from the scan index.
fn highest_job_in_journals(out: &Path) -> u64 {
    let Ok((index, _)) = ScanIndex::open_refreshed(out) else {
        return 0;
    };
    index
        .query(&Default::default())
        .map(|rows| rows.iter().filter_map(|r| r.job).max().unwrap_or(0))
        .unwrap_or(0)
}

/// The scan that names job `id`: the recorded one when its journal does, else the newest
/// the scan index finds naming it.
fn find_job_scan(out: &Path, id: u64, recorded: Option<&str>) -> Option<JobScan> {
    let read = |dir_name: &str| -> Option<JobScan> {
        let jpath = out.join(dir_name).join(JOURNAL_FILE);
        let rec = read_journal(&jpath).ok()?;
        let st = ResumeState::from_records(&jpath, &rec.records).ok()?;
        if st.start.job.as_ref().and_then(|j| j.id) != Some(id) {
            return None;
        }
        let verdict = super::index::read_entry(dir_name, &out.join(dir_name))
            .ok()
            .and_then(|(e, _)| e.verdict);
        Some(JobScan {
            scan_id: dir_name.to_owned(),
            // A failure the daemon continues by itself (its transient budget, an earlier
            // version's storage error) does not end the job, as its turn continues the scan.
            ended: st
                .stop
                .filter(|s| !s.continued_by_the_daemon())
                .map(|s| (s.status, s.reason)),
            verdict,
        })
    };
    if let Some(found) = recorded.and_then(read) {
        return Some(found);
    }
    let (index, _) = ScanIndex::open_refreshed(out).ok()?;
    let rows = index.query(&Default::default()).ok()?;
    rows.iter()
        .rev()
        .filter(|r| r.job == Some(id))
        .find_map(|r| read(&r.scan_id))
}

#[cfg(test)]
pub(crate) mod tests;
