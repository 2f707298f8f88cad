//! The raw-data archive: each completed scan directory copied to the lab's object store (S3
//! or a `file://` directory) off the scan's path, every object read back and its SHA-256
//! compared, a `MANIFEST.sha256` (the `sha256sum -c` format) written last.
//!
//! ```text
//! success event ──► queue entry in outbox/archive/ (disk) ──► Archiver ──► store
//!                   (what is verified is recorded in it)      backoff while the store is away
//! ```
//!
//! The queue entry of a scan lists each file once it is uploaded and verified, so a restart
//! continues where the last process stopped; a finished entry moves to `outbox/archive/done/`
//! (the record that the archive holds a verified copy). Nothing on the station is deleted
//! unless `delete-after-days` says so, and then only after the copy is verified again
//! ([`super::retention`] decides).
//!
//! Layer 4 (process edge): depends on object_store, the status's links and the atomic writer.

use super::archive_settings::{read_secret, ArchiveSettings, Target};
use super::retention;
use super::scan_queue::next_backoff;
use crate::scan::status::Status;
use object_store::path::Path as ObjectPath;
use object_store::{ObjectStore, PutPayload};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{watch, Notify};

/// The name of the archive in the status's links.
pub const LINK: &str = "archive";

/// The object listing every file of a scan with its SHA-256, written last.
pub const MANIFEST: &str = "MANIFEST.sha256";

/// How long one request may take before it counts as failed.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(120);

/// One file archived and verified.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Archived {
    /// Path inside the scan directory, `/`-separated.
    pub path: String,
    /// Its size.
    pub bytes: u64,
    /// Its SHA-256, lower-case hex.
    pub sha256: String,
}

/// A scan waiting for the archive, and how far it got.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Entry {
    /// The scan id (the objects' folder).
    pub scan_id: String,
    /// The scan directory on the station.
    pub dir: PathBuf,
    /// The files archived and verified so far.
    #[serde(default)]
    pub files: Vec<Archived>,
    /// When the scan directory was deleted from the station under `delete-after-days`
    /// (RFC 3339), after its archived copy was verified again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deleted: Option<String>,
}

/// The `sha256sum` text of `files`: `HASH  PATH` lines, sorted by path.
pub fn manifest_text(files: &[Archived]) -> String {
    let mut sorted: Vec<&Archived> = files.iter().collect();
    sorted.sort_by(|a, b| a.path.cmp(&b.path));
    sorted
        .iter()
        .map(|f| format!("{}  {}\n", f.sha256, f.path))
        .collect()
}

/// Every regular file below `dir`, as `/`-separated relative paths, sorted. Links are not
/// followed (a scan's own files are regular).
pub fn scan_files(dir: &Path) -> std::io::Result<Vec<String>> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) -> std::io::Result<()> {
        for e in std::fs::read_dir(dir)? {
            let e = e?;
            let t = e.file_type()?;
            if t.is_dir() {
                walk(root, &e.path(), out)?;
            } else if t.is_file() {
                let rel = e.path();
                let rel = rel.strip_prefix(root).unwrap_or(&rel);
                out.push(
                    rel.components()
                        .map(|c| c.as_os_str().to_string_lossy())
                        .collect::<Vec<_>>()
                        .join("/"),
                );
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out)?;
    out.sort();
    Ok(out)
}

fn sha256_hex(bytes: &[u8]) -> String {
    crate::scan::store::hex_sha256(bytes)
}

/// The store behind `[archive]`, and the prefix of every object.
/// The HTTP client's deadlines for every request to the store.
fn client_options() -> object_store::ClientOptions {
    object_store::ClientOptions::new()
        .with_timeout(REQUEST_TIMEOUT)
        .with_connect_timeout(Duration::from_secs(10))
}

fn open_store(
    s: &ArchiveSettings,
    target: &Target,
) -> Result<(Arc<dyn ObjectStore>, String), String> {
    match target {
        Target::S3 { bucket, prefix } => {
            let mut b = object_store::aws::AmazonS3Builder::from_env()
                .with_bucket_name(bucket)
                .with_region(s.region.clone().unwrap_or_else(|| "us-east-1".into()))
                .with_client_options(client_options())
                .with_retry(object_store::RetryConfig {
                    max_retries: 2,
                    retry_timeout: Duration::from_secs(30),
                    ..Default::default()
                });
            if let Some(e) = &s.endpoint {
                b = b
                    .with_endpoint(e.trim_end_matches('/'))
                    .with_allow_http(e.starts_with("http://"));
            }
            if let Some(ca) = &s.ca_file {
                let pem = std::fs::read(ca).map_err(|e| {
                    format!("cannot read {} ([archive] ca-file): {e}", ca.display())
                })?;
                let certificates = object_store::Certificate::from_pem_bundle(&pem)
                    .map_err(|e| format!("{} ([archive] ca-file): {e}", ca.display()))?;
                let mut options = client_options();
                for c in certificates {
                    options = options.with_root_certificate(c);
                }
                b = b.with_client_options(options);
            }
            if let (Some(id), Some(f)) = (&s.access_key_id, &s.secret_access_key_file) {
                b = b
                    .with_access_key_id(id)
                    .with_secret_access_key(read_secret(f)?);
            }
            let store = b.build().map_err(|e| e.to_string())?;
            Ok((Arc::new(store), prefix.clone()))
        }
        Target::File(dir) => {
            // Never created here: a directory missing is a share not mounted, and creating it
            // would fill the station's own disk instead.
            if !dir.is_dir() {
                return Err(format!(
                    "{} is not a directory; is the share mounted? ([archive] url)",
                    dir.display()
                ));
            }
            let store = object_store::local::LocalFileSystem::new_with_prefix(dir)
                .map_err(|e| e.to_string())?;
            Ok((Arc::new(store), String::new()))
        }
    }
}

/// The queue of scans to archive on disk ([`super::scan_queue`]).
pub type Queue = super::scan_queue::ScanQueue<Entry>;

impl super::scan_queue::ScanEntry for Entry {
    fn queued(scan_id: &str, dir: &Path) -> Entry {
        Entry {
            scan_id: scan_id.to_owned(),
            dir: dir.to_owned(),
            files: Vec::new(),
            deleted: None,
        }
    }
}

/// What went wrong with one scan: the store (try again later) or the scan itself (a
/// directory gone; set aside, the others go on).
enum Failure {
    Store(String),
    Scan(String),
}

/// The task that empties the queue into the store.
pub struct Archiver {
    settings: ArchiveSettings,
    target: Target,
    queue: Queue,
    status: watch::Sender<Status>,
    wake: Arc<Notify>,
}

impl Archiver {
    /// An archiver for `settings` (already validated) over `queue`.
    pub fn new(
        settings: ArchiveSettings,
        target: Target,
        queue: Queue,
        status: watch::Sender<Status>,
        wake: Arc<Notify>,
    ) -> Archiver {
        Archiver {
            settings,
            target,
            queue,
            status,
            wake,
        }
    }

    fn report(&self, ok: bool, message: String) {
        let queued = self.queue.pending().map_or(0, |p| p.len() as u64);
        super::set_link(&self.status, LINK, ok, message, queued);
    }

    /// Archives until `stop` becomes true: the queue oldest first, waiting with backoff while
    /// the store is away and for `wake` when the queue is empty.
    pub async fn run(self, mut stop: watch::Receiver<bool>) {
        let mut backoff: Option<Duration> = None;
        self.report(true, format!("archiving to {}", self.settings.url));
        loop {
            if *stop.borrow() {
                return;
            }
            let wait = match self.drain().await {
                Ok(()) => {
                    backoff = None;
                    None
                }
                Err(e) => {
                    let d = next_backoff(backoff);
                    backoff = Some(d);
                    let message = format!("{e}; trying again in {} s", d.as_secs());
                    tracing::warn!("archive: {message}");
                    self.report(false, message);
                    Some(d)
                }
            };
            let sleep = tokio::time::sleep(wait.unwrap_or(Duration::from_secs(3600)));
            tokio::select! {
                _ = stop.wait_for(|v| *v) => return,
                () = self.wake.notified() => {}
                () = sleep => {}
            }
        }
    }

    /// Archives every entry waiting; the first store error ends the round.
    async fn drain(&self) -> Result<(), String> {
        let pending = self
            .queue
            .pending()
            .map_err(|e| format!("cannot read the archive queue: {e}"))?;
        let mut opened = None;
        if !pending.is_empty() {
            let (store, prefix) = open_store(&self.settings, &self.target)?;
            for path in pending {
                self.archive_entry(&*store, &prefix, &path).await?;
            }
            opened = Some((store, prefix));
        }
        let due = self.due_for_deletion();
        if due.is_empty() {
            return Ok(());
        }
        let (store, prefix) = match opened {
            Some(o) => o,
            None => open_store(&self.settings, &self.target)?,
        };
        self.prune(&*store, &prefix, due).await
    }

    /// Archives the scan of the queue entry at `path`; only a store error is returned.
    async fn archive_entry(
        &self,
        store: &dyn ObjectStore,
        prefix: &str,
        path: &Path,
    ) -> Result<(), String> {
        match self.archive_one(store, prefix, path).await {
            Ok(entry) => {
                self.queue.finish(path)?;
                let bytes: u64 = entry.files.iter().map(|f| f.bytes).sum();
                tracing::info!(
                    "archive: scan {} archived and verified ({} files, {bytes} bytes) in {}",
                    entry.scan_id,
                    entry.files.len(),
                    self.settings.url
                );
                self.report(true, format!("scan {} archived", entry.scan_id));
            }
            Err(Failure::Scan(e)) => {
                // The scan cannot be archived as it is (its directory is gone): set aside
                // so that it does not hold up the others; the entry says what it was.
                tracing::error!(
                    "archive: {e}; this scan is left out of the archive (its entry is kept in {})",
                    self.queue.dir().join("done").display()
                );
                self.queue.set_aside(path)?;
                self.report(false, e);
            }
            Err(Failure::Store(e)) => return Err(e),
        }
        Ok(())
    }

    /// The record entries whose scans `delete-after-days` lets go now and are still on the
    /// station (none without the setting).
    fn due_for_deletion(&self) -> Vec<(PathBuf, Entry)> {
        let Some(days) = self.settings.delete_after_days else {
            return Vec::new();
        };
        let now = chrono::Utc::now();
        let done = match self.queue.done() {
            Ok(d) => d,
            Err(e) => {
                tracing::warn!("archive: cannot read the archive's record: {e}");
                return Vec::new();
            }
        };
        done.into_iter()
            .filter(|p| {
                let name = p.file_name().unwrap_or_default().to_string_lossy();
                retention::completed_at(&name).is_some_and(|t| retention::due(t, now, days))
            })
            .filter_map(|p| Queue::read(&p).ok().map(|e| (p, e)))
            .filter(|(_, e)| e.deleted.is_none() && e.dir.is_dir())
            .collect()
    }

    /// Deletes from the station the scan directories `delete-after-days` old whose archived
    /// copy is verified again now: the manifest read back names each file with the SHA-256
    /// the file has on the station, and each object read back has it. A copy that does not
    /// verify keeps its scan (named in the log and the status); a store error ends the round.
    async fn prune(
        &self,
        store: &dyn ObjectStore,
        prefix: &str,
        due: Vec<(PathBuf, Entry)>,
    ) -> Result<(), String> {
        let days = self.settings.delete_after_days.unwrap_or(0);
        let now = chrono::Utc::now();
        for (path, mut entry) in due {
            match self.verify_copy(store, prefix, &entry).await {
                Ok(()) => {}
                Err(Failure::Store(e)) => return Err(e),
                Err(Failure::Scan(e)) => {
                    let message = format!(
                        "scan {} is kept on the station: {e}; archive it again or remove it by hand",
                        entry.scan_id
                    );
                    tracing::error!("archive: {message}");
                    self.report(false, message);
                    continue;
                }
            }
            let dir = entry.dir.clone();
            tokio::task::spawn_blocking(move || std::fs::remove_dir_all(dir))
                .await
                .map_err(|e| e.to_string())?
                .map_err(|e| {
                    format!(
                        "scan {}: cannot delete {}: {e}",
                        entry.scan_id,
                        entry.dir.display()
                    )
                })?;
            entry.deleted = Some(now.to_rfc3339());
            Queue::save(&path, &entry)?;
            tracing::info!(
                "archive: scan {} deleted from the station ({}), {days} days after it completed; its copy in {} was verified again",
                entry.scan_id,
                entry.dir.display(),
                self.settings.url
            );
            self.report(
                true,
                format!(
                    "scan {} deleted from the station (verified copy in the archive)",
                    entry.scan_id
                ),
            );
        }
        Ok(())
    }

    /// Reads the manifest of `entry` back from the store and checks it against the scan
    /// directory as it is now, then every object against the manifest.
    async fn verify_copy(
        &self,
        store: &dyn ObjectStore,
        prefix: &str,
        entry: &Entry,
    ) -> Result<(), Failure> {
        let object = |rel: &str| object_path(prefix, &entry.scan_id, rel);
        let text = get_bytes(store, &object(MANIFEST)).await?;
        let manifest = retention::parse_manifest(&String::from_utf8_lossy(&text))
            .map_err(|e| Failure::Scan(format!("its archived {MANIFEST}: {e}")))?;
        let dir = entry.dir.clone();
        let local = tokio::task::spawn_blocking(move || local_hashes(&dir))
            .await
            .map_err(|e| Failure::Scan(e.to_string()))?
            .map_err(|e| Failure::Scan(format!("cannot read {}: {e}", entry.dir.display())))?;
        retention::matches(&local, &manifest).map_err(Failure::Scan)?;
        for (rel, want) in &manifest {
            let got = sha256_hex(&get_bytes(store, &object(rel)).await?);
            if &got != want {
                return Err(Failure::Scan(format!(
                    "the archived {rel} has SHA-256 {got}, not {want} as its manifest says"
                )));
            }
        }
        Ok(())
    }

    async fn archive_one(
        &self,
        store: &dyn ObjectStore,
        prefix: &str,
        path: &Path,
    ) -> Result<Entry, Failure> {
        let mut entry = Queue::read(path).map_err(Failure::Scan)?;
        let dir = entry.dir.clone();
        let files = tokio::task::spawn_blocking(move || scan_files(&dir))
            .await
            .map_err(|e| Failure::Scan(e.to_string()))?
            .map_err(|e| {
                Failure::Scan(format!(
                    "scan {}: cannot list {}: {e}",
                    entry.scan_id,
                    entry.dir.display()
                ))
            })?;
        let object = |rel: &str| object_path(prefix, &entry.scan_id, rel);
        for rel in files {
            if entry.files.iter().any(|f| f.path == rel) {
                continue;
            }
            let bytes = tokio::fs::read(entry.dir.join(&rel)).await.map_err(|e| {
                Failure::Scan(format!("scan {}: cannot read {rel}: {e}", entry.scan_id))
            })?;
            let sha256 = put_verified(store, &object(&rel), bytes.clone().into()).await?;
            entry.files.push(Archived {
                path: rel,
                bytes: bytes.len() as u64,
                sha256,
            });
            Queue::save(path, &entry).map_err(Failure::Store)?;
        }
        let manifest = manifest_text(&entry.files);
        put_verified(store, &object(MANIFEST), manifest.into_bytes().into()).await?;
        Ok(entry)
    }
}

/// The object of file `rel` of scan `scan_id` below `prefix`.
fn object_path(prefix: &str, scan_id: &str, rel: &str) -> ObjectPath {
    if prefix.is_empty() {
        ObjectPath::from(format!("{scan_id}/{rel}"))
    } else {
        ObjectPath::from(format!("{prefix}/{scan_id}/{rel}"))
    }
}

/// Path → SHA-256 of every file below `dir`, read now.
fn local_hashes(dir: &Path) -> std::io::Result<BTreeMap<String, String>> {
    scan_files(dir)?
        .into_iter()
        .map(|rel| {
            let bytes = std::fs::read(dir.join(&rel))?;
            Ok((rel, sha256_hex(&bytes)))
        })
        .collect()
}

/// The bytes of the object at `at`; an object missing is the copy's fault, anything else
/// the store's.
async fn get_bytes(store: &dyn ObjectStore, at: &ObjectPath) -> Result<bytes::Bytes, Failure> {
    let got = tokio::time::timeout(REQUEST_TIMEOUT, async {
        store.get(at).await?.bytes().await
    })
    .await
    .map_err(|_| {
        Failure::Store(format!(
            "reading {at} took longer than {} s",
            REQUEST_TIMEOUT.as_secs()
        ))
    })?;
    match got {
        Ok(b) => Ok(b),
        Err(object_store::Error::NotFound { .. }) => {
            Err(Failure::Scan(format!("{at} is missing from the archive")))
        }
        Err(e) => Err(Failure::Store(store_error("reading", at, &e))),
    }
}

/// What went wrong with a request, and what to check: a refused key names the two keys that
/// make it, a bucket not found names the URL, anything else (the server away, a timeout, a
/// full store) the endpoint.
fn store_error(what: &str, at: &ObjectPath, e: &object_store::Error) -> String {
    // The cause of a failed connection (a certificate refused, a port closed) is at the end of
    // the error's chain, not in its own text.
    let mut cause = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        let text = s.to_string();
        if !cause.contains(&text) {
            cause = format!("{cause}: {text}");
        }
        source = s.source();
    }
    let hint = match e {
        _ if cause.contains("certificate") => {
            "the store's TLS certificate does not verify: check that it chains to [archive] ca-file (or the system's authorities) and names the host of [archive] endpoint"
        }
        object_store::Error::PermissionDenied { .. } | object_store::Error::Unauthenticated { .. } => {
            "the store refused the key: check [archive] access-key-id and the secret in secret-access-key-file, and that the key may write the bucket"
        }
        object_store::Error::NotFound { .. } => {
            "not found: check that the bucket in [archive] url exists"
        }
        _ => "is the store reachable? check [archive] url and endpoint",
    };
    format!("{what} {at}: {hint} ({cause})")
}

/// Puts `bytes` at `at`, reads the object back and compares the SHA-256; returns it.
async fn put_verified(
    store: &dyn ObjectStore,
    at: &ObjectPath,
    bytes: bytes::Bytes,
) -> Result<String, Failure> {
    let want = sha256_hex(&bytes);
    let deadline = |what: &str| {
        format!(
            "{what} {at} took longer than {} s",
            REQUEST_TIMEOUT.as_secs()
        )
    };
    tokio::time::timeout(
        REQUEST_TIMEOUT,
        store.put(at, PutPayload::from_bytes(bytes)),
    )
    .await
    .map_err(|_| Failure::Store(deadline("storing")))?
    .map_err(|e| Failure::Store(store_error("storing", at, &e)))?;
    let back = tokio::time::timeout(REQUEST_TIMEOUT, async {
        store.get(at).await?.bytes().await
    })
    .await
    .map_err(|_| Failure::Store(deadline("reading back")))?
    .map_err(|e| Failure::Store(store_error("reading back", at, &e)))?;
    let got = sha256_hex(&back);
    if got != want {
        return Err(Failure::Store(format!(
            "{at} read back differs from what was stored (SHA-256 {got}, not {want})"
        )));
    }
    Ok(want)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_manifest_is_what_sha256sum_checks() {
        let files = vec![
            Archived {
                path: "report.json".into(),
                bytes: 3,
                sha256: "b".repeat(64),
            },
            Archived {
                path: "lines/0001.csv".into(),
                bytes: 1,
                sha256: "a".repeat(64),
            },
        ];
        assert_eq!(
            manifest_text(&files),
            format!(
                "{}  lines/0001.csv\n{}  report.json\n",
                "a".repeat(64),
                "b".repeat(64)
            )
        );
    }

    #[test]
    fn a_scan_directory_is_listed_recursively_without_links() {
        let t = tempfile::tempdir().unwrap();
        std::fs::create_dir(t.path().join("lines")).unwrap();
        std::fs::write(t.path().join("lines/0002.csv"), "2").unwrap();
        std::fs::write(t.path().join("journal.jsonl"), "j").unwrap();
        std::os::unix::fs::symlink("/etc/passwd", t.path().join("link")).unwrap();
        assert_eq!(
            scan_files(t.path()).unwrap(),
            ["journal.jsonl", "lines/0002.csv"]
        );
    }
}
