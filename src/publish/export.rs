//! Results into the lab's quality systems: each completed scan's `<scan-id>.dfq` (Q-DAS, for
//! SPC) and `<scan-id>.qif` (QIF 3.0 Results) written into the configured drop directories,
//! off the scan's path.
//!
//! ```text
//! success event ──► queue entry in outbox/export/ (disk) ──► Exporter ──► dfq-dir, qif-dir
//!                   (the formats written are recorded in it)  backoff while a directory is away
//! ```
//!
//! Each file is rendered from the scan directory ([`Exported::read`]) and written atomically
//! (a temporary `.<name>.tmp<pid>` in the drop directory, fsynced, renamed), so a file
//! watcher never reads half a file. A drop directory that is missing (a share not mounted:
//! it is never created here), read-only or full is named in the status's `links.export` and
//! the log and tried again after 1 s, doubling to 5 minutes; the scans go on, and a restart
//! continues from the queue. A finished entry moves to `outbox/export/done/`.
//! [`export_scan`] is the same rendering and writing for `surfscan export`.
//!
//! Layer 4 (process edge): depends on the report's renderers, the status's links and the
//! atomic writer.

use super::export_settings::ExportSettings;
use super::exported::Exported;
use super::scan_queue::next_backoff;
use super::{dfq::dfq, qif::qif};
use crate::scan::status::Status;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{watch, Notify};

/// The name of the exports in the status's links.
pub const LINK: &str = "export";

/// A file format the lab's systems take.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// Q-DAS ASCII transfer format, `.dfq`.
    Dfq,
    /// QIF 3.0 Results, `.qif`.
    Qif,
}

impl Format {
    /// The file extension, also the format's name.
    pub fn ext(self) -> &'static str {
        match self {
            Format::Dfq => "dfq",
            Format::Qif => "qif",
        }
    }

    /// The configuration key of its directory.
    pub fn key(self) -> &'static str {
        match self {
            Format::Dfq => "[export] dfq-dir",
            Format::Qif => "[export] qif-dir",
        }
    }

    /// The file's bytes.
    pub fn render(self, r: &Exported) -> Vec<u8> {
        match self {
            Format::Dfq => dfq(r),
            Format::Qif => qif(r).into_bytes(),
        }
    }
}

/// What went wrong: the drop directory (try again later) or the scan itself (it cannot be
/// exported as it is: no report; set aside, the others go on).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Failure {
    /// The directories of these formats refused their files: why, each.
    Targets(Vec<(Format, String)>),
    /// The scan has nothing to export.
    Scan(String),
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Failure::Targets(t) => f.write_str(
                &t.iter()
                    .map(|(_, m)| m.as_str())
                    .collect::<Vec<_>>()
                    .join("; "),
            ),
            Failure::Scan(m) => f.write_str(m),
        }
    }
}

/// Writes `bytes` as `dir/name` atomically; the error names the directory, its key and
/// what to do.
pub fn drop_file(format: Format, dir: &Path, name: &str, bytes: &[u8]) -> Result<PathBuf, Failure> {
    // Never created here: a directory missing is a share not mounted, or the other system
    // not installed, and creating it would hide that.
    if !dir.is_dir() {
        return Err(Failure::Targets(vec![(
            format,
            format!(
                "{} is not a directory; is the share mounted, or the other system's drop directory created? ({})",
                dir.display(),
                format.key()
            ),
        )]));
    }
    let path = dir.join(name);
    crate::atomic::write_regular_atomically(&path, |w| w.write_all(bytes)).map_err(|e| {
        Failure::Targets(vec![(
            format,
            format!(
                "cannot write {}: {} ({})",
                path.display(),
                crate::atomic::write_hint(dir, &e),
                format.key()
            ),
        )])
    })?;
    Ok(path)
}

/// Renders the scan in `scan_dir` and writes it into each of `targets` not in `done`,
/// adding each format written to `done`. Every target is tried; those that failed are
/// returned together.
pub fn export_scan(
    scan_dir: &Path,
    targets: &[(Format, &Path)],
    done: &mut Vec<Format>,
) -> Result<Vec<PathBuf>, Failure> {
    let todo: Vec<&(Format, &Path)> = targets.iter().filter(|(f, _)| !done.contains(f)).collect();
    if todo.is_empty() {
        return Ok(Vec::new());
    }
    let r = Exported::read(scan_dir).map_err(Failure::Scan)?;
    let mut written = Vec::new();
    let mut failed = Vec::new();
    for (format, dir) in todo {
        let name = format!("{}.{}", r.scan_id, format.ext());
        match drop_file(*format, dir, &name, &format.render(&r)) {
            Ok(p) => {
                done.push(*format);
                written.push(p);
            }
            Err(Failure::Targets(t)) => failed.extend(t),
            Err(e) => return Err(e),
        }
    }
    if failed.is_empty() {
        Ok(written)
    } else {
        Err(Failure::Targets(failed))
    }
}

/// A scan waiting for its exports, and which are written.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Entry {
    /// The scan id.
    pub scan_id: String,
    /// The scan directory.
    pub dir: PathBuf,
    /// The formats written so far.
    #[serde(default)]
    pub done: Vec<Format>,
    /// Why the scan could not be exported, when it was set aside.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The queue of scans to export on disk ([`super::scan_queue`]).
pub type Queue = super::scan_queue::ScanQueue<Entry>;

impl super::scan_queue::ScanEntry for Entry {
    fn queued(scan_id: &str, dir: &Path) -> Entry {
        Entry {
            scan_id: scan_id.to_owned(),
            dir: dir.to_owned(),
            done: Vec::new(),
            error: None,
        }
    }
}

impl Queue {
    /// Exports every entry waiting into `targets`. A format whose directory failed is not
    /// tried again in this round (the other goes on); the failures (one per format) are
    /// returned together, else the scans exported.
    pub fn drain(&self, targets: &[(Format, &Path)]) -> Result<Vec<String>, String> {
        let pending = self
            .pending()
            .map_err(|e| format!("cannot read the export queue {}: {e}", self.dir().display()))?;
        let mut failed: Vec<Format> = Vec::new();
        let mut errors: Vec<String> = Vec::new();
        let mut exported = Vec::new();
        for path in pending {
            let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            let mut entry: Entry = match serde_json::from_slice(&bytes) {
                Ok(e) => e,
                Err(e) => {
                    tracing::error!(
                        "export: {} is not an export entry ({e}); set aside",
                        path.display()
                    );
                    self.finish(&path)?;
                    continue;
                }
            };
            let live: Vec<(Format, &Path)> = targets
                .iter()
                .filter(|(f, _)| !failed.contains(f))
                .copied()
                .collect();
            let before = entry.done.len();
            let result = export_scan(&entry.dir, &live, &mut entry.done);
            let all_done = targets.iter().all(|(f, _)| entry.done.contains(f));
            match result {
                Err(Failure::Scan(e)) => {
                    tracing::error!(
                        "export: scan {}: {e}; it is left out of the exports (its entry is kept in {})",
                        entry.scan_id,
                        self.dir().join("done").display()
                    );
                    entry.error = Some(e);
                    Self::save(&path, &entry)?;
                    self.finish(&path)?;
                    continue;
                }
                Err(Failure::Targets(t)) => {
                    for (f, e) in t {
                        failed.push(f);
                        errors.push(e);
                    }
                }
                Ok(_) => {}
            }
            if all_done {
                self.finish(&path)?;
                tracing::info!(
                    "export: scan {} written ({})",
                    entry.scan_id,
                    targets
                        .iter()
                        .map(|(f, d)| format!("{}/{}.{}", d.display(), entry.scan_id, f.ext()))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                exported.push(entry.scan_id);
            } else if entry.done.len() != before {
                Self::save(&path, &entry)?;
            }
        }
        if errors.is_empty() {
            Ok(exported)
        } else {
            Err(errors.join("; "))
        }
    }
}

/// The task that empties the queue into the drop directories.
pub struct Exporter {
    settings: ExportSettings,
    queue: Queue,
    status: watch::Sender<Status>,
    wake: Arc<Notify>,
}

impl Exporter {
    /// An exporter for `settings` (already validated) over `queue`.
    pub fn new(
        settings: ExportSettings,
        queue: Queue,
        status: watch::Sender<Status>,
        wake: Arc<Notify>,
    ) -> Exporter {
        Exporter {
            settings,
            queue,
            status,
            wake,
        }
    }

    fn report(&self, ok: bool, message: String) {
        let queued = self.queue.pending().map_or(0, |p| p.len() as u64);
        super::set_link(&self.status, LINK, ok, message, queued);
    }

    async fn round(&self) -> Result<Vec<String>, String> {
        let queue = self.queue.clone();
        let settings = self.settings.clone();
        tokio::task::spawn_blocking(move || queue.drain(&settings.targets()))
            .await
            .map_err(|e| e.to_string())?
    }

    /// Exports until `stop` becomes true (a last round then, so that a scan that has just
    /// completed is written before a foreground `scan` exits): the queue oldest first,
    /// waiting with backoff while a directory is away and for `wake` when the queue is
    /// empty.
    pub async fn run(self, mut stop: watch::Receiver<bool>) {
        let mut backoff: Option<Duration> = None;
        let dirs = self
            .settings
            .targets()
            .iter()
            .map(|(_, d)| d.display().to_string())
            .collect::<Vec<_>>()
            .join(" and ");
        self.report(true, format!("exporting to {dirs}"));
        loop {
            let stopping = *stop.borrow();
            let wait = match self.round().await {
                Ok(done) => {
                    backoff = None;
                    if let Some(last) = done.last() {
                        self.report(true, format!("scan {last} exported to {dirs}"));
                    }
                    None
                }
                Err(e) => {
                    let d = next_backoff(backoff);
                    backoff = Some(d);
                    let message = format!("{e}; trying again in {} s", d.as_secs());
                    tracing::warn!("export: {message}");
                    self.report(false, message);
                    Some(d)
                }
            };
            if stopping {
                return;
            }
            let sleep = tokio::time::sleep(wait.unwrap_or(Duration::from_secs(3600)));
            tokio::select! {
                _ = stop.wait_for(|v| *v) => {}
                () = self.wake.notified() => {}
                () = sleep => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_drop_directory_is_named_with_its_key_and_never_created() {
        let t = tempfile::tempdir().unwrap();
        let gone = t.path().join("spc");
        let e = drop_file(Format::Dfq, &gone, "x.dfq", b"K0100 0\r\n").unwrap_err();
        let Failure::Targets(t) = e else {
            panic!("{e:?}")
        };
        let [(Format::Dfq, m)] = &t[..] else {
            panic!("{t:?}")
        };
        assert!(
            m.contains(&gone.display().to_string()) && m.contains("[export] dfq-dir"),
            "{m}"
        );
        assert!(!gone.exists());
    }

    #[test]
    fn a_drop_leaves_only_the_complete_file() {
        let t = tempfile::tempdir().unwrap();
        let p = drop_file(Format::Qif, t.path(), "s.qif", b"<x/>").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"<x/>");
        let names: Vec<_> = std::fs::read_dir(t.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["s.qif"]);
    }
}
