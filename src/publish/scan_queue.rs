//! The durable queue of completed scans that the archive ([`super::archive`]) and the exports
//! ([`super::export`]) each keep below `<output dir>/outbox/<name>/`: one JSON entry per scan,
//! named `<UTC time of queueing>-<scan id>.json` so that the names sort in the order the
//! scans completed, written atomically before [`ScanQueue::push`] returns, and moved to
//! `done/` when its worker has finished with it (under a `.failed` name when set aside). What
//! an entry records of the work (the files archived, the formats written) is the worker's own
//! entry type; the layout on disk is the same for both and the same as each had before this
//! queue served both.
//!
//! The file `since` holds when the queue was first opened (RFC 3339): the scans that ended
//! after it are the worker's, so that the start-up sweep ([`super::sweep`]) queues a scan that
//! completed while the process died before its entry was written, and never the scans of the
//! time before the worker was configured.
//!
//! Layer 4 (process edge): depends on serde and the atomic writer.

use chrono::{DateTime, Utc};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::collections::HashSet;
use std::io::Write;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The longest wait between two tries while a worker's target is away.
const MAX_BACKOFF: Duration = Duration::from_secs(300);

/// The next wait after `previous` failed (1 s, doubling, at most five minutes).
pub fn next_backoff(previous: Option<Duration>) -> Duration {
    previous.map_or(Duration::from_secs(1), |d| (d * 2).min(MAX_BACKOFF))
}

/// A worker's entry for one scan.
pub trait ScanEntry: Serialize + DeserializeOwned {
    /// A new entry for the completed scan `scan_id` in `dir`, nothing done yet.
    fn queued(scan_id: &str, dir: &Path) -> Self;
}

/// The queue in one directory.
#[derive(Debug)]
pub struct ScanQueue<E> {
    dir: PathBuf,
    since: DateTime<Utc>,
    entry: PhantomData<fn() -> E>,
}

impl<E> Clone for ScanQueue<E> {
    fn clone(&self) -> Self {
        ScanQueue {
            dir: self.dir.clone(),
            since: self.since,
            entry: PhantomData,
        }
    }
}

/// The name of the file holding when the queue was first opened.
const SINCE: &str = "since";

/// When the queue in `dir` was first opened: read from its `since` file, written now when
/// there is none (or it cannot be read as a time).
fn since(dir: &Path) -> std::io::Result<DateTime<Utc>> {
    let path = dir.join(SINCE);
    if let Ok(t) = std::fs::read_to_string(&path) {
        if let Ok(t) = DateTime::parse_from_rfc3339(t.trim()) {
            return Ok(t.with_timezone(&Utc));
        }
    }
    let now = Utc::now();
    crate::atomic::write_atomically(&path, |w| {
        writeln!(
            w,
            "{}",
            now.to_rfc3339_opts(chrono::SecondsFormat::Nanos, true)
        )
    })?;
    Ok(now)
}

/// The `.json` files of `dir`, sorted by name (so oldest first).
fn entries(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json") && p.is_file())
        .collect();
    v.sort();
    Ok(v)
}

impl<E: ScanEntry> ScanQueue<E> {
    /// The queue in `dir` (created when missing).
    pub fn open(dir: &Path) -> std::io::Result<ScanQueue<E>> {
        std::fs::create_dir_all(dir.join("done"))?;
        Ok(ScanQueue {
            dir: dir.to_owned(),
            since: since(dir)?,
            entry: PhantomData,
        })
    }

    /// Its directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// When it was first opened: the scans that ended since are its worker's.
    pub fn since(&self) -> DateTime<Utc> {
        self.since
    }

    /// Adds a completed scan; durable when this returns.
    pub fn push(&self, scan_id: &str, dir: &Path) -> std::io::Result<PathBuf> {
        let now = chrono::Utc::now();
        let path = self.dir.join(format!(
            "{}-{scan_id}.json",
            now.format("%Y%m%dT%H%M%S%.9fZ")
        ));
        Self::save(&path, &E::queued(scan_id, dir)).map_err(std::io::Error::other)?;
        Ok(path)
    }

    /// The entries waiting, oldest first.
    pub fn pending(&self) -> std::io::Result<Vec<PathBuf>> {
        entries(&self.dir)
    }

    /// The entries finished with, oldest first (not those set aside).
    pub fn done(&self) -> std::io::Result<Vec<PathBuf>> {
        entries(&self.dir.join("done"))
    }

    /// The scan ids of the entries waiting, finished with or set aside.
    pub fn known(&self) -> std::io::Result<HashSet<String>> {
        let mut ids = HashSet::new();
        for d in [self.dir.clone(), self.dir.join("done")] {
            for e in std::fs::read_dir(&d)? {
                let name = e?.file_name();
                let name = name.to_string_lossy();
                let name = name.strip_suffix(".failed").unwrap_or(&name);
                // `<time>-<scan id>.json`; the time holds no `-`.
                if let Some(id) = name
                    .strip_suffix(".json")
                    .and_then(|n| n.split_once('-'))
                    .map(|(_, id)| id)
                {
                    ids.insert(id.to_owned());
                }
            }
        }
        Ok(ids)
    }

    /// The entry at `path`.
    pub fn read(path: &Path) -> Result<E, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        serde_json::from_slice(&bytes).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Writes `entry` at `path` atomically.
    pub fn save(path: &Path, entry: &E) -> Result<(), String> {
        crate::atomic::write_atomically(path, |w| {
            serde_json::to_writer_pretty(&mut *w, entry).map_err(std::io::Error::other)
        })
        .map_err(|e| {
            format!(
                "{}: {}",
                path.display(),
                crate::atomic::write_hint(path, &e)
            )
        })
    }

    /// Moves a finished entry to `done/`.
    pub fn finish(&self, path: &Path) -> Result<(), String> {
        let to = self
            .dir
            .join("done")
            .join(path.file_name().unwrap_or_default());
        std::fs::rename(path, &to).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Moves the entry of a scan that cannot be done to `done/` under a `.failed` name: kept
    /// as the record, never taken for finished work.
    pub fn set_aside(&self, path: &Path) -> Result<(), String> {
        let mut name = path.file_name().unwrap_or_default().to_owned();
        name.push(".failed");
        let to = self.dir.join("done").join(name);
        std::fs::rename(path, &to).map_err(|e| format!("{}: {e}", path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, Serialize, serde::Deserialize)]
    struct E {
        scan_id: String,
        dir: PathBuf,
    }

    impl ScanEntry for E {
        fn queued(scan_id: &str, dir: &Path) -> E {
            E {
                scan_id: scan_id.into(),
                dir: dir.into(),
            }
        }
    }

    #[test]
    fn the_backoff_doubles_up_to_five_minutes() {
        let mut d = None;
        let mut seen = Vec::new();
        for _ in 0..12 {
            let n = next_backoff(d);
            seen.push(n.as_secs());
            d = Some(n);
        }
        assert_eq!(seen, [1, 2, 4, 8, 16, 32, 64, 128, 256, 300, 300, 300]);
    }

    #[test]
    fn entries_wait_in_order_and_are_known_until_and_after_they_are_done() {
        let t = tempfile::tempdir().unwrap();
        let q: ScanQueue<E> = ScanQueue::open(t.path()).unwrap();
        let a = q.push("20260101T000000Z-a", Path::new("/s/a")).unwrap();
        let b = q.push("20260101T000001Z-b", Path::new("/s/b")).unwrap();
        assert_eq!(q.pending().unwrap(), [a.clone(), b.clone()]);
        assert_eq!(
            ScanQueue::<E>::read(&a).unwrap(),
            E::queued("20260101T000000Z-a", Path::new("/s/a"))
        );
        q.finish(&a).unwrap();
        q.set_aside(&b).unwrap();
        assert!(q.pending().unwrap().is_empty());
        assert_eq!(q.done().unwrap().len(), 1, "a set-aside entry is not done");
        let known = q.known().unwrap();
        assert_eq!(
            known,
            ["20260101T000000Z-a", "20260101T000001Z-b"]
                .map(String::from)
                .into()
        );
        // `since` is kept across openings.
        let again: ScanQueue<E> = ScanQueue::open(t.path()).unwrap();
        assert_eq!(again.since(), q.since());
    }
}
