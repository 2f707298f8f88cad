//! The job queue: scans a shift lines up for the night, run one after another by the daemon,
//! durable across kill -9 and power loss.
//!
//! Each job freezes the recipe's text (and its SHA-256) when it is added, with the specimen,
//! the y of its first line (a fixture holds several coupons along y) and whether a person
//! must load the specimen first. The queue is one JSON file (`queue.json` in the output
//! directory) replaced atomically and durably ([`crate::atomic`]) at every change, before the
//! change is acknowledged or acted on. Every command that changes it is also appended, with
//! the peer that sent it and the time, to `queue-log.jsonl` beside it.
//!
//! Exactly once, in order: a job is marked running (durably) before its scan is created, and
//! the scan's start record names the job ([`crate::scan::journal::StartRecord::job`]). After a
//! crash, [`Queue::reconcile`] asks the journals (the truth) what became of a running job: a
//! scan that names it and has ended finishes it; a scan that names it and has not ended (or
//! failed for a cause the daemon continues by itself) is resumed (continued); no scan naming it means none was created, and the job starts. No job is run
//! twice, none is lost, and the queued ones keep their order.
//!
//! [`Queue`] is the pure state with its transitions (tested without files); [`QueueStore`]
//! loads and saves it.
//!
//! Layer 4 (process edge): depends on [`crate::atomic`], the scan's journal vocabulary
//! ([`StopStatus`], [`Peer`]) and the verdict type; reads and writes its two files.

use crate::scan::command::Peer;
use crate::scan::journal::StopStatus;
use crate::specification::Verdict;
use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// The queue file's name in the output directory.
pub const QUEUE_FILE: &str = "queue.json";
/// The log of queue commands beside it.
pub const QUEUE_LOG: &str = "queue-log.jsonl";
/// Finished jobs kept in the file for `queue list` (the scans themselves stay in the output
/// directory and in `surfscan list`).
pub const FINISHED_KEPT: usize = 50;

/// A recipe as frozen into a job: what the job runs, whatever the file says later.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrozenRecipe {
    /// The recipe's name.
    pub name: String,
    /// The file it was read from.
    pub path: PathBuf,
    /// Its text when the job was added.
    pub text: String,
    /// SHA-256 of the text, hex.
    pub sha256: String,
}

/// What a job asks for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobRequest {
    /// The recipe, frozen.
    pub recipe: FrozenRecipe,
    /// Specimen id.
    pub specimen: String,
    /// Operator recorded with the scan.
    #[serde(default)]
    pub operator: String,
    /// Notes recorded with the scan.
    #[serde(default)]
    pub notes: String,
    /// y of the first line, mm, overriding the recipe's.
    #[serde(default)]
    pub y_start_mm: Option<f64>,
    /// The specimen must be loaded by a person first: the job waits for `surfscan ready`.
    #[serde(default)]
    pub needs_loading: bool,
}

/// Where a job is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "state", rename_all = "kebab-case")]
pub enum JobState {
    /// Waiting its turn (and, with `needs_loading`, for `surfscan ready` once it is next).
    Queued {
        /// `surfscan ready` was given for it.
        #[serde(default)]
        loaded: bool,
    },
    /// Its scan is being made. `scan_id` is `None` between marking it running and the scan's
    /// creation (a crash there leaves no scan: [`Queue::reconcile`] starts it again).
    Running {
        /// The scan, once created.
        scan_id: Option<String>,
        /// When it was marked running.
        since: DateTime<Utc>,
    },
    /// Its scan ended, or it could not begin.
    Finished {
        /// The scan, when one was created.
        scan_id: Option<String>,
        /// How: `success`, `fail`, `abort`, `abandoned`, or `refused` when it could not begin.
        outcome: String,
        /// The verdict against the recipe's specification, when it has one and the scan
        /// completed.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        verdict: Option<Verdict>,
        /// Why, for people.
        reason: String,
        /// When.
        at: DateTime<Utc>,
    },
}

/// One job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Job {
    /// Its number, never reused on this station.
    pub id: u64,
    /// What it asks for.
    #[serde(flatten)]
    pub request: JobRequest,
    /// When it was added.
    pub added_at: DateTime<Utc>,
    /// Who added it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub added_by: Option<Peer>,
    /// Where it is.
    #[serde(flatten)]
    pub state: JobState,
}

impl Job {
    /// Whether it is waiting its turn.
    pub fn is_queued(&self) -> bool {
        matches!(self.state, JobState::Queued { .. })
    }

    /// One line for people: `job 7: brass, specimen C-12 at y = 10 mm (needs loading)`.
    pub fn describe(&self) -> String {
        let r = &self.request;
        let mut s = format!(
            "job {}: recipe {}, specimen {:?}",
            self.id, r.recipe.name, r.specimen
        );
        if let Some(y) = r.y_start_mm {
            s.push_str(&format!(" from y = {y} mm"));
        }
        if r.needs_loading {
            s.push_str(" (needs loading)");
        }
        s
    }
}

/// A queue command that cannot be done.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum QueueError {
    /// No job with that number is queued or running.
    #[error("no job {0} in the queue (`surfscan queue list` shows them)")]
    NoSuchJob(u64),
    /// The job is running: it is a scan now.
    #[error(
        "job {0} is running: end its scan with `surfscan abort` (it is then recorded as aborted)"
    )]
    Running(u64),
    /// The job has finished.
    #[error("job {0} has finished; it is kept in the list for the record")]
    Finished(u64),
    /// `ready` with no job waiting for its specimen.
    #[error("no job is waiting for its specimen to be loaded")]
    NothingToLoad,
    /// `ready JOB` for a job that is not the one waiting.
    #[error("job {id} is not waiting for loading: {why}")]
    NotWaiting {
        /// The job.
        id: u64,
        /// Why not.
        why: String,
    },
    /// `queue continue` when the queue is not stopped.
    #[error("the queue is not stopped")]
    NotHeld,
}

/// What the daemon does next with the queue.
#[derive(Debug, Clone, PartialEq)]
pub enum Next {
    /// Nothing queued.
    Idle,
    /// The queue is stopped after a failed job whose recipe says so.
    Held(String),
    /// The next job waits for its specimen (`surfscan ready`).
    WaitForLoading(u64),
    /// Begin this job: mark it running, then create its scan.
    Start(u64),
    /// This job was running when the daemon stopped: continue its scan (or create it, when
    /// `scan_id` is `None`).
    Continue {
        /// The job.
        id: u64,
        /// Its scan.
        scan_id: Option<String>,
    },
}

/// How a job ended.
#[derive(Debug, Clone, PartialEq)]
pub struct JobOutcome {
    /// Its scan, when one was created.
    pub scan_id: Option<String>,
    /// `success`, `fail`, `abort`, `abandoned` (the scan's stop status), or `refused` when
    /// it could not begin (its recipe no longer valid, the instrument's conditions not the
    /// recipe's).
    pub outcome: String,
    /// The verdict, when the recipe has a specification and the scan completed.
    pub verdict: Option<Verdict>,
    /// Why, for people.
    pub reason: String,
}

/// What the journals say of the scan that names a job.
#[derive(Debug, Clone, PartialEq)]
pub struct JobScan {
    /// The scan's id.
    pub scan_id: String,
    /// Its stop record's status and reason, when it has ended for its job (a failure the
    /// daemon continues by itself does not end it:
    /// [`crate::scan::journal::StopRecord::continued_by_the_daemon`]).
    pub ended: Option<(StopStatus, String)>,
    /// Its verdict, when its report holds one.
    pub verdict: Option<Verdict>,
}

/// The queue: every job not yet finished in order, and the last finished ones.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Queue {
    /// Format version of the file (1).
    #[serde(default = "one")]
    pub version: u32,
    /// The number the next job gets.
    #[serde(default = "one_u64")]
    pub next_id: u64,
    /// Why the queue is stopped (a failed job whose recipe says `stop-on-failure`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held: Option<String>,
    /// The jobs: finished ones first (oldest first), then running and queued in order.
    pub jobs: Vec<Job>,
}

fn one() -> u32 {
    1
}
fn one_u64() -> u64 {
    1
}

impl Queue {
    /// An empty queue.
    pub fn new() -> Queue {
        Queue {
            version: 1,
            next_id: 1,
            held: None,
            jobs: Vec::new(),
        }
    }

    /// The job numbered `id`.
    pub fn get(&self, id: u64) -> Option<&Job> {
        self.jobs.iter().find(|j| j.id == id)
    }

    fn get_mut(&mut self, id: u64) -> Option<&mut Job> {
        self.jobs.iter_mut().find(|j| j.id == id)
    }

    /// The jobs not finished, in the order they run.
    pub fn pending(&self) -> impl Iterator<Item = &Job> {
        self.jobs
            .iter()
            .filter(|j| !matches!(j.state, JobState::Finished { .. }))
    }

    /// Adds a job at the end; its number.
    pub fn add(&mut self, request: JobRequest, now: DateTime<Utc>, by: Option<Peer>) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        self.jobs.push(Job {
            id,
            request,
            added_at: now,
            added_by: by,
            state: JobState::Queued { loaded: false },
        });
        id
    }

    /// Removes a queued job (a running one is a scan: abort it; a finished one stays).
    pub fn remove(&mut self, id: u64) -> Result<Job, QueueError> {
        let pos = self
            .jobs
            .iter()
            .position(|j| j.id == id)
            .ok_or(QueueError::NoSuchJob(id))?;
        match self.jobs[pos].state {
            JobState::Queued { .. } => Ok(self.jobs.remove(pos)),
            JobState::Running { .. } => Err(QueueError::Running(id)),
            JobState::Finished { .. } => Err(QueueError::Finished(id)),
        }
    }

    /// Removes every queued job (not the running one); the removed jobs.
    pub fn clear(&mut self) -> Vec<Job> {
        let (gone, kept): (Vec<Job>, Vec<Job>) = std::mem::take(&mut self.jobs)
            .into_iter()
            .partition(Job::is_queued);
        self.jobs = kept;
        gone
    }

    /// `surfscan ready [JOB]`: the specimen of the job waiting for loading (the next one) is
    /// in place. Without `id` the next job; with it, that job must be the next one.
    pub fn ready(&mut self, id: Option<u64>) -> Result<u64, QueueError> {
        let next = self.jobs.iter().find(|j| j.is_queued()).map(|j| j.id);
        let target = match (id, next) {
            (Some(id), _) if self.get(id).is_none() => return Err(QueueError::NoSuchJob(id)),
            (Some(id), Some(n)) if id != n => {
                return Err(QueueError::NotWaiting {
                    id,
                    why: format!("job {n} runs before it; give `surfscan ready` when job {id} asks for its specimen"),
                })
            }
            (Some(id), None) => {
                return Err(QueueError::NotWaiting {
                    id,
                    why: "it is not queued".into(),
                })
            }
            (_, Some(n)) => n,
            (None, None) => return Err(QueueError::NothingToLoad),
        };
        let job = self.get_mut(target).expect("found above");
        if !job.request.needs_loading {
            return Err(QueueError::NotWaiting {
                id: target,
                why: "it was queued without --needs-loading".into(),
            });
        }
        job.state = JobState::Queued { loaded: true };
        Ok(target)
    }

    /// `surfscan queue continue`: runs the jobs after a failure that stopped the queue.
    pub fn release(&mut self) -> Result<(), QueueError> {
        self.held.take().map(|_| ()).ok_or(QueueError::NotHeld)
    }

    /// What to do next: continue a running job, else wait or start the next queued one.
    pub fn next(&self) -> Next {
        if let Some(j) = self
            .jobs
            .iter()
            .find(|j| matches!(j.state, JobState::Running { .. }))
        {
            let JobState::Running { scan_id, .. } = &j.state else {
                unreachable!()
            };
            return Next::Continue {
                id: j.id,
                scan_id: scan_id.clone(),
            };
        }
        if let Some(why) = &self.held {
            return Next::Held(why.clone());
        }
        match self.jobs.iter().find(|j| j.is_queued()) {
            None => Next::Idle,
            Some(j) => match j.state {
                JobState::Queued { loaded: false } if j.request.needs_loading => {
                    Next::WaitForLoading(j.id)
                }
                _ => Next::Start(j.id),
            },
        }
    }

    /// Marks job `id` running (before its scan is created).
    pub fn mark_running(&mut self, id: u64, now: DateTime<Utc>) {
        if let Some(j) = self.get_mut(id) {
            j.state = JobState::Running {
                scan_id: None,
                since: now,
            };
        }
    }

    /// Puts running job `id`, whose scan was never created (its devices were missing), back
    /// in its place in the queue; a specimen loaded for it stays loaded.
    pub fn requeue(&mut self, id: u64) {
        if let Some(j) = self.get_mut(id) {
            if matches!(j.state, JobState::Running { scan_id: None, .. }) {
                j.state = JobState::Queued { loaded: true };
            }
        }
    }

    /// The queue in the status: jobs queued, the one running, why it is stopped.
    pub fn status(&self) -> crate::scan::status::QueueStatus {
        crate::scan::status::QueueStatus {
            queued: self.jobs.iter().filter(|j| j.is_queued()).count(),
            running: self
                .jobs
                .iter()
                .find(|j| matches!(j.state, JobState::Running { .. }))
                .map(|j| j.id),
            held: self.held.clone(),
        }
    }

    /// Records the scan created for running job `id`.
    pub fn set_scan(&mut self, id: u64, scan: &str) {
        if let Some(j) = self.get_mut(id) {
            if let JobState::Running { scan_id, .. } = &mut j.state {
                *scan_id = Some(scan.to_owned());
            }
        }
    }

    /// Records how job `id` ended. A failure (anything but `success`) of a job whose recipe
    /// says `stop-on-failure` stops the queue.
    pub fn finish(&mut self, id: u64, end: JobOutcome, stop_on_failure: bool, now: DateTime<Utc>) {
        let Some(pos) = self.jobs.iter().position(|j| j.id == id) else {
            return;
        };
        let mut job = self.jobs.remove(pos);
        if end.outcome != "success" && stop_on_failure {
            self.held = Some(format!(
                "job {id} ({}) ended {}: {}; its recipe says stop-on-failure — `surfscan queue continue` runs the next job",
                job.request.recipe.name, end.outcome, end.reason
            ));
        }
        job.state = JobState::Finished {
            scan_id: end.scan_id,
            outcome: end.outcome,
            verdict: end.verdict,
            reason: end.reason,
            at: now,
        };
        // Finished jobs go before the pending ones, newest last; the oldest are dropped.
        let finished = self
            .jobs
            .iter()
            .take_while(|j| matches!(j.state, JobState::Finished { .. }))
            .count();
        self.jobs.insert(finished, job);
        let excess = (finished + 1).saturating_sub(FINISHED_KEPT);
        self.jobs.drain(..excess);
    }

    /// After a restart: settles each running job by what the journals say of the scan that
    /// names it (`lookup`). An ended scan finishes the job; a scan not ended is recorded as
    /// its scan (to be continued); no scan leaves it to be created. Returns what changed, for
    /// the log.
    pub fn reconcile(
        &mut self,
        lookup: impl Fn(u64) -> Option<JobScan>,
        stop_on_failure: impl Fn(&Job) -> bool,
        now: DateTime<Utc>,
    ) -> Vec<String> {
        let mut notes = Vec::new();
        let running: Vec<u64> = self
            .jobs
            .iter()
            .filter(|j| matches!(j.state, JobState::Running { .. }))
            .map(|j| j.id)
            .collect();
        for id in running {
            match lookup(id) {
                Some(JobScan {
                    scan_id,
                    ended: Some((status, reason)),
                    verdict,
                }) => {
                    let stop = self.get(id).is_some_and(&stop_on_failure);
                    notes.push(format!(
                        "job {id}: its scan {scan_id} ended {} before the restart; recorded",
                        status.as_str()
                    ));
                    let end = JobOutcome {
                        scan_id: Some(scan_id),
                        outcome: status.as_str().to_owned(),
                        verdict,
                        reason,
                    };
                    self.finish(id, end, stop, now);
                }
                Some(JobScan { scan_id, .. }) => {
                    notes.push(format!("job {id}: its scan {scan_id} is continued"));
                    self.set_scan(id, &scan_id);
                }
                None => {
                    if let Some(j) = self.get_mut(id) {
                        if let JobState::Running { scan_id, .. } = &mut j.state {
                            if scan_id.take().is_some() {
                                notes.push(format!("job {id}: the scan recorded for it has no journal naming the job; it is made again"));
                            } else {
                                notes.push(format!("job {id}: no scan was created for it before the restart; it starts now"));
                            }
                        }
                    }
                }
            }
        }
        notes
    }
}

/// One queue command as `queue-log.jsonl` records it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LogEntry {
    /// When.
    pub time: DateTime<Utc>,
    /// `add`, `remove`, `clear`, `ready`, `continue`, or what the daemon did (`start`,
    /// `finish`, `reconcile`).
    pub command: String,
    /// The jobs concerned.
    pub jobs: Vec<u64>,
    /// Who sent it (`None` for the daemon's own steps).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peer: Option<Peer>,
    /// For people.
    pub detail: String,
}

/// The queue's files in a directory.
#[derive(Debug, Clone)]
pub struct QueueStore {
    dir: PathBuf,
}

/// The queue's files cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// An I/O error, with the file and what to do.
    #[error("{op} {}: {hint}", path.display())]
    Io {
        /// What was being done.
        op: &'static str,
        /// The file.
        path: PathBuf,
        /// The error and what to do about it.
        hint: String,
    },
}

impl QueueStore {
    /// The queue kept in `dir` (the station's output directory).
    pub fn new(dir: &Path) -> QueueStore {
        QueueStore {
            dir: dir.to_path_buf(),
        }
    }

    /// `queue.json`.
    pub fn path(&self) -> PathBuf {
        self.dir.join(QUEUE_FILE)
    }

    /// `queue-log.jsonl`.
    pub fn log_path(&self) -> PathBuf {
        self.dir.join(QUEUE_LOG)
    }

    /// Reads the queue (empty when there is no file). A file that is not a queue is moved
    /// aside (kept for a person, named in the returned warning) and an empty queue returned:
    /// the daemon must keep serving, and the file is written only atomically, so this is
    /// damage from outside.
    pub fn load(&self) -> Result<(Queue, Option<String>), StoreError> {
        let path = self.path();
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((Queue::new(), None)),
            Err(e) => {
                return Err(StoreError::Io {
                    op: "read",
                    path,
                    hint: e.to_string(),
                })
            }
        };
        match serde_json::from_slice::<Queue>(&bytes) {
            Ok(q) => Ok((q, None)),
            Err(e) => {
                let aside = self.dir.join(format!(
                    "queue.json.damaged-{}",
                    Utc::now().format("%Y%m%dT%H%M%SZ")
                ));
                std::fs::rename(&path, &aside).map_err(|err| StoreError::Io {
                    op: "move aside the damaged",
                    path: path.clone(),
                    hint: err.to_string(),
                })?;
                Ok((
                    Queue::new(),
                    Some(format!(
                        "the queue file {} could not be read ({e}); it is kept as {} and the queue starts empty — re-add its jobs from it",
                        path.display(),
                        aside.display()
                    )),
                ))
            }
        }
    }

    /// Writes the queue atomically and durably.
    pub fn save(&self, q: &Queue) -> Result<(), StoreError> {
        let path = self.path();
        std::fs::create_dir_all(&self.dir).map_err(|e| StoreError::Io {
            op: "create",
            path: self.dir.clone(),
            hint: crate::atomic::write_hint(&self.dir, &e),
        })?;
        crate::atomic::write_json_atomically(&path, q).map_err(|e| StoreError::Io {
            op: "write",
            path: path.clone(),
            hint: crate::atomic::write_hint(&path, &e),
        })
    }

    /// Appends one entry to the command log, durably.
    pub fn log(&self, entry: &LogEntry) -> Result<(), StoreError> {
        let path = self.log_path();
        let io = |op, e: std::io::Error| StoreError::Io {
            op,
            path: path.clone(),
            hint: crate::atomic::write_hint(&path, &e),
        };
        let mut line =
            serde_json::to_vec(entry).map_err(|e| io("encode", std::io::Error::other(e)))?;
        line.push(b'\n');
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| io("open", e))?;
        f.write_all(&line).map_err(|e| io("append to", e))?;
        f.sync_data().map_err(|e| io("sync", e))
    }
}

#[cfg(test)]
mod tests;
