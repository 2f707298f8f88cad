//! One process per station: advisory locks (`flock`) that a `scan` or `daemon` takes at
//! start-up and holds for its whole life, on the output directory and on each device path, so
//! that a second process on the same station is refused (exit 69) with the holder's pid and
//! scan id. Root is refused too: the serial port's exclusive mode (`TIOCEXCL`) does not stop
//! root, but a `flock` binds every process alike. A lock held by a process that died (even by
//! `kill -9`) is released by the kernel with its file descriptors, so nothing is ever stale.
//!
//! - The output directory's lock is the file `.surfscan.lock` inside it. Its content (JSON)
//!   names the holder: pid, command, and the scan it runs, kept up to date with
//!   [`StationLock::set_scan`].
//! - A device cannot be locked on its own node: the serial library takes an exclusive `flock`
//!   on the port when it opens it, which our own lock on the node would block. Each device is
//!   locked instead by a file in the system's lock directory (FHS `/run/lock`) named
//!   `LCK..<device>` after the device's resolved path, in the HDB UUCP format (the pid in ten
//!   columns and a newline) that minicom, cu and similar tools honour, followed by a line
//!   naming our output directory. A `LCK..` file of another program is respected while its
//!   process has the device open, or, where that cannot be seen, while the file is root's or
//!   the daemon's user's; any other is not obeyed, with a warning naming its pid, command and
//!   owner, and taken over ([`foreign`]): `/run/lock` is writable by every local user.
//!
//! Holding the output directory's lock also makes it safe to sweep the leftovers of
//! interrupted writes there ([`StationLock::sweep_leftovers`]), and the directory is created
//! (with its parent fsynced) if missing.
//!
//! Layer 4 (process edge): depends on std, nix (flock, kill), libc (the clock tick of a
//! process's start time) and serde_json; no other module.

use nix::errno::Errno;
use nix::fcntl::{Flock, FlockArg};
use std::fs::{self, File, OpenOptions};
use std::io::{self, Read};
use std::os::unix::fs::{FileExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

mod foreign;
use foreign::{ForeignLock, Verdict};

/// Name of the lock file inside the output directory.
pub const OUTPUT_LOCK_FILE: &str = ".surfscan.lock";

/// The system's directory for device lock files (FHS).
pub const DEVICE_LOCK_DIR: &str = "/run/lock";

/// Why the station cannot be locked.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another process holds the output directory or a device.
    #[error("{what} is in use by {holder}; stop it first (systemctl stop surfscan, or end that `surfscan scan`), or use `surfscan start` to scan through the daemon")]
    Held {
        /// What is locked: "the output directory /x" or "the device /dev/ttyUSB0".
        what: String,
        /// Who holds it, for people: "surfscan daemon, pid 1234, running scan X".
        holder: String,
        /// The holder's pid, when known.
        pid: Option<u32>,
        /// The holder's scan id, when it runs one.
        scan_id: Option<String>,
    },
    /// A lock file or the output directory cannot be created or written.
    #[error("cannot {op} {path}: {source}; {hint}")]
    Io {
        /// What was being done.
        op: &'static str,
        /// The file or directory.
        path: PathBuf,
        /// The cause.
        source: io::Error,
        /// What to do.
        hint: &'static str,
    },
}

/// The holder's record in the output directory's lock file.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
struct Holder {
    pid: u32,
    command: String,
    scan_id: Option<String>,
}

/// One held lock file; the lock goes with the file descriptor.
#[derive(Debug)]
struct Held {
    path: PathBuf,
    file: Flock<File>,
}

impl Drop for Held {
    fn drop(&mut self) {
        // Remove the file while still holding the lock, so nobody takes the lock on a file
        // that is about to vanish (acquire checks that the path still names its file).
        if let (Ok(a), Ok(b)) = (fs::metadata(&self.path), self.file.metadata()) {
            if a.dev() == b.dev() && a.ino() == b.ino() {
                let _ = fs::remove_file(&self.path);
            }
        }
    }
}

/// The station's locks, held until dropped (normally: for the life of the process).
#[derive(Debug)]
pub struct StationLock {
    output: Held,
    devices: Vec<Held>,
    output_dir: PathBuf,
    holder: Mutex<Holder>,
}

fn io_err(
    op: &'static str,
    path: &Path,
    hint: &'static str,
) -> impl FnOnce(io::Error) -> LockError {
    let path = path.to_path_buf();
    move |source| LockError::Io {
        op,
        path,
        source,
        hint,
    }
}

/// Whether a process with this pid exists (a process we may not signal exists too).
pub fn pid_alive(pid: u32) -> bool {
    let Ok(raw) = i32::try_from(pid) else {
        return false;
    };
    if raw <= 0 {
        return false;
    }
    !matches!(
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(raw), None),
        Err(Errno::ESRCH)
    )
}

/// Opens lock file `path`, creating it if missing. Another user's file in a sticky
/// world-writable directory such as `/run/lock` cannot be opened with `O_CREAT` under
/// `fs.protected_regular` (`EACCES`, root too): it is then opened without, for writing, else
/// for reading (a lock is taken on any descriptor).
fn open_lock_file(path: &Path) -> io::Result<File> {
    let open = |create: bool, write: bool| {
        OpenOptions::new()
            .read(true)
            .write(write)
            .create(create)
            .truncate(false)
            .mode(0o644)
            .custom_flags(libc::O_CLOEXEC | libc::O_NOFOLLOW)
            .open(path)
    };
    match open(true, true) {
        Err(e) if e.kind() == io::ErrorKind::PermissionDenied && path.is_file() => {
            open(false, true)
                .or_else(|_| open(false, false))
                .map_err(|_| e)
        }
        other => other,
    }
}

/// Opens `path` (creating it) and takes an exclusive non-blocking lock on it. `Ok(Err(file))`:
/// the lock is held by someone else, and the file is returned for reading who.
fn try_lock(path: &Path, hint: &'static str) -> Result<Result<Held, File>, LockError> {
    loop {
        let file = open_lock_file(path).map_err(io_err("create the lock file", path, hint))?;
        let file = match Flock::lock(file, FlockArg::LockExclusiveNonblock) {
            Ok(locked) => locked,
            Err((file, Errno::EWOULDBLOCK)) => return Ok(Err(file)),
            Err((_, e)) => return Err(io_err("lock", path, hint)(io::Error::from(e))),
        };
        // The previous holder may have removed the file between our open and our lock: then
        // the lock is on a file nobody else will see, and we start over.
        let here = fs::metadata(path).ok();
        let ours = file.metadata().ok();
        match (here, ours) {
            (Some(a), Some(b)) if a.dev() == b.dev() && a.ino() == b.ino() => {
                return Ok(Ok(Held {
                    path: path.to_path_buf(),
                    file,
                }))
            }
            _ => continue,
        }
    }
}

fn read_all(mut file: &File) -> String {
    let mut s = String::new();
    let _ = file.read_to_string(&mut s);
    s
}

/// True for the errors of a full file system or an exhausted quota.
fn is_disk_full(e: &io::Error) -> bool {
    matches!(e.raw_os_error(), Some(libc::ENOSPC) | Some(libc::EDQUOT))
}

fn rewrite(held: &Held, content: &str) -> io::Result<()> {
    held.file.write_all_at(content.as_bytes(), 0)?;
    held.file.set_len(content.len() as u64)?;
    Ok(())
}

/// Creates `dir` and any missing parents, fsyncing the parent of each directory it creates so
/// the new entries survive a power cut.
pub fn create_dir_durably(dir: &Path) -> io::Result<()> {
    if dir.is_dir() {
        return Ok(());
    }
    if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
        create_dir_durably(parent)?;
    }
    match fs::create_dir(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists && dir.is_dir() => return Ok(()),
        Err(e) => return Err(e),
    }
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    File::open(parent)?.sync_all()
}

/// The `LCK..` name of a device path: its resolved path below `/dev` with `/` as `_`
/// (`/dev/ttyUSB0` → `LCK..ttyUSB0`, `/dev/pts/3` → `LCK..pts_3`).
pub fn device_lock_name(device: &Path) -> String {
    let resolved = fs::canonicalize(device).unwrap_or_else(|_| device.to_path_buf());
    let rel = resolved.strip_prefix("/dev").unwrap_or(&resolved);
    let name: String = rel
        .to_string_lossy()
        .trim_start_matches('/')
        .chars()
        .map(|c| if c == '/' { '_' } else { c })
        .collect();
    format!("LCK..{name}")
}

const DEVICE_HINT: &str = "the device locks live in /run/lock; give the daemon's user write access to it (the unit's ReadWritePaths=/run/lock)";
const OUTPUT_HINT: &str = "check that [output] dir is writable by the daemon's user";

impl StationLock {
    /// Locks `output_dir` (creating it if missing) and every device path in `devices`, for a
    /// process running `command` (`scan`, `daemon`). Device lock files go to `lock_dir`
    /// ([`DEVICE_LOCK_DIR`] on a station).
    pub fn acquire(
        command: &str,
        output_dir: &Path,
        devices: &[&Path],
        lock_dir: &Path,
    ) -> Result<StationLock, LockError> {
        create_dir_durably(output_dir).map_err(io_err(
            "create the output directory",
            output_dir,
            OUTPUT_HINT,
        ))?;
        let path = output_dir.join(OUTPUT_LOCK_FILE);
        let output = match try_lock(&path, OUTPUT_HINT)? {
            Ok(held) => held,
            Err(file) => {
                let holder: Option<Holder> = serde_json::from_str(&read_all(&file)).ok();
                return Err(held_error(
                    format!("the output directory {}", output_dir.display()),
                    holder,
                ));
            }
        };
        let holder = Holder {
            pid: std::process::id(),
            command: command.to_owned(),
            scan_id: None,
        };
        // The holder record only names who holds the lock; the flock is the lock. A full
        // disk (a scan suspended for space, then a restart) must not keep the scan from
        // resuming, so the record then stays empty until it can be written.
        match rewrite(&output, &holder_json(&holder)) {
            Ok(()) => {}
            Err(e) if is_disk_full(&e) => tracing::warn!(
                path = %path.display(),
                error = %e,
                "the disk is full: the station lock is held without naming its holder"
            ),
            Err(e) => return Err(io_err("write the lock file", &path, OUTPUT_HINT)(e)),
        }
        let mut lock = StationLock {
            output,
            devices: Vec::new(),
            output_dir: output_dir.to_path_buf(),
            holder: Mutex::new(holder),
        };
        let mut names: Vec<(String, &Path)> =
            devices.iter().map(|d| (device_lock_name(d), *d)).collect();
        // The same device named twice (two symlinks) is one lock; a fixed order keeps two
        // starting processes from each taking half.
        names.sort();
        names.dedup_by(|a, b| a.0 == b.0);
        for (name, device) in names {
            let path = lock_dir.join(&name);
            let what = || format!("the device {}", device.display());
            let held = match try_lock(&path, DEVICE_HINT)? {
                Ok(held) => {
                    // A lock file of another program (HDB content, no flock).
                    let existing = read_all(&held.file);
                    if let Some(pid) = foreign_pid(&existing).filter(|p| *p != std::process::id()) {
                        let meta = held.file.metadata().map_err(io_err(
                            "read the lock file",
                            &path,
                            DEVICE_HINT,
                        ))?;
                        let lock = ForeignLock::inspect(pid, pid_alive(pid), &meta, device);
                        match foreign::judge(&lock) {
                            Verdict::Obey => return Err(foreign_held(what(), &lock, &path)),
                            Verdict::Stale => {}
                            Verdict::Ignore(why) => not_obeyed(&path, &lock.describe(), &why),
                        }
                    }
                    held
                }
                Err(file) => {
                    let content = read_all(&file);
                    if let Some(holder) = device_holder(&content) {
                        return Err(held_error(what(), Some(holder)));
                    }
                    // Locked by a process that is not a surfscan of ours.
                    let meta = file.metadata().map_err(io_err(
                        "read the lock file",
                        &path,
                        DEVICE_HINT,
                    ))?;
                    let (who, why) = match foreign_pid(&content) {
                        Some(pid) => {
                            let lock = ForeignLock::inspect(pid, pid_alive(pid), &meta, device);
                            match foreign::judge(&lock) {
                                Verdict::Obey => return Err(foreign_held(what(), &lock, &path)),
                                Verdict::Stale => {
                                    (lock.describe(), "its process is gone".to_owned())
                                }
                                Verdict::Ignore(why) => (lock.describe(), why),
                            }
                        }
                        // Empty: another surfscan between its lock and its write, unless
                        // the file is a stranger's.
                        None if meta.uid() == 0
                            || meta.uid() == nix::unistd::geteuid().as_raw() =>
                        {
                            return Err(held_error(what(), None))
                        }
                        None => (
                            format!(
                                "a lock held on a file owned by {} that names no process",
                                foreign::user_name(meta.uid())
                            ),
                            "the file's owner is neither root nor the daemon's user".to_owned(),
                        ),
                    };
                    not_obeyed(&path, &who, &why);
                    drop(file);
                    match fs::remove_file(&path).map(|()| try_lock(&path, DEVICE_HINT)) {
                        Ok(Ok(Ok(held))) => held,
                        Ok(Err(e)) => return Err(e),
                        _ => {
                            tracing::warn!(
                                path = %path.display(),
                                "cannot replace the lock file; the device {} is used without one (its port is still opened exclusively)",
                                device.display()
                            );
                            continue;
                        }
                    }
                }
            };
            let content = format!(
                "{:>10}\nsurfscan {command} {}\n",
                std::process::id(),
                output_dir.display()
            );
            match rewrite(&held, &content) {
                Ok(()) => {}
                // Another user's file opened for reading only (fs.protected_regular): the
                // lock is held all the same.
                Err(e) if e.raw_os_error() == Some(libc::EBADF) => tracing::warn!(
                    path = %path.display(),
                    "the device's lock file is another user's and cannot be rewritten; it is held as it is"
                ),
                Err(e) => return Err(io_err("write the lock file", &path, DEVICE_HINT)(e)),
            }
            lock.devices.push(held);
        }
        Ok(lock)
    }

    /// Records the scan this process runs (or none), for whoever is refused next.
    pub fn set_scan(&self, scan_id: Option<&str>) {
        let mut h = self.holder.lock().unwrap_or_else(|e| e.into_inner());
        if h.scan_id.as_deref() == scan_id {
            return;
        }
        h.scan_id = scan_id.map(str::to_owned);
        if let Err(e) = rewrite(&self.output, &holder_json(&h)) {
            tracing::warn!(path = %self.output.path.display(), error = %e, "cannot record the scan id in the station lock");
        }
    }

    /// The output directory this lock holds.
    pub fn output_dir(&self) -> &Path {
        &self.output_dir
    }

    /// Removes what interrupted writes left in the output directory, its scan directories
    /// and their `lines/` and `rk/` (the per-line figures): files named like the project's temporary files, `.<name>.tmp<pid>`
    /// (atomic replacement) when that pid is not alive or its process started after the file was
    /// last written (the pid was reused), and `.<name>.tmp` (the scan's own
    /// durable writes, made only by the holder of this lock). Each removal is logged; the
    /// paths removed are returned.
    pub fn sweep_leftovers(&self) -> Vec<PathBuf> {
        let mut dirs = vec![self.output_dir.clone()];
        if let Ok(entries) = fs::read_dir(&self.output_dir) {
            for e in entries.flatten() {
                let p = e.path();
                if e.file_type().is_ok_and(|t| t.is_dir()) {
                    dirs.push(p.join("lines"));
                    dirs.push(p.join("rk"));
                    dirs.push(p);
                }
            }
        }
        let mut removed = Vec::new();
        for dir in dirs {
            let Ok(entries) = fs::read_dir(&dir) else {
                continue;
            };
            for e in entries.flatten() {
                if !e.file_type().is_ok_and(|t| t.is_file()) {
                    continue;
                }
                let name = e.file_name();
                let Some(pid) = leftover_pid(&name.to_string_lossy()) else {
                    continue;
                };
                let meta = e.metadata().ok();
                if let Some(pid) = pid {
                    if pid == std::process::id() {
                        continue;
                    }
                    // A live process may still be writing it, unless it started after the
                    // file was last written: then the pid was reused (after a reboot, say)
                    // and the writer is long gone.
                    if pid_alive(pid) {
                        let modified = meta.as_ref().and_then(|m| m.modified().ok());
                        if !modified.is_some_and(|m| started_after(pid, m)) {
                            continue;
                        }
                    }
                }
                let path = e.path();
                let bytes = meta.map_or(0, |m| m.len());
                match fs::remove_file(&path) {
                    Ok(()) => {
                        tracing::info!(path = %path.display(), bytes, "removed the leftover of an interrupted write");
                        removed.push(path);
                    }
                    Err(err) => {
                        tracing::warn!(path = %path.display(), error = %err, "cannot remove the leftover of an interrupted write")
                    }
                }
            }
        }
        removed
    }
}

/// Whether process `pid` certainly started after `time` (by more than the 2 s the start
/// time's rounding may blur), so it cannot have written a file last changed at `time`.
/// `false` when its start cannot be read (another system than Linux, a process gone
/// meanwhile): a file is then never taken from a process that may be writing it.
///
/// Both times are read on the wall clock, and a process's start is the boot time plus its
/// ticks since boot, where the boot time follows the clock when it is stepped. A station PC
/// without a battery-backed clock that NTP sets long after boot could therefore see a file
/// written before the step by a process still running as older than that process. The sweep
/// runs when the station lock is taken, before this process writes anything, so only a
/// `fit` or `analyze` of the operator's writing into the output directory across such a
/// step could lose its temporary file; it would then report the failed write.
fn started_after(pid: u32, time: std::time::SystemTime) -> bool {
    process_start(pid).is_some_and(|start| {
        start
            .duration_since(time)
            .is_ok_and(|d| d > std::time::Duration::from_secs(2))
    })
}

/// When process `pid` started: the boot time (`btime` of `/proc/stat`) plus its start in
/// clock ticks since boot (field 22 of `/proc/PID/stat`, counted after the command name,
/// which may itself hold spaces and parentheses).
#[cfg(target_os = "linux")]
fn process_start(pid: u32) -> Option<std::time::SystemTime> {
    let stat = fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after_comm = &stat[stat.rfind(')')? + 1..];
    let ticks: u64 = after_comm.split_whitespace().nth(19)?.parse().ok()?;
    let boot: u64 = fs::read_to_string("/proc/stat")
        .ok()?
        .lines()
        .find_map(|l| l.strip_prefix("btime "))?
        .trim()
        .parse()
        .ok()?;
    // SAFETY: sysconf reads a system constant; no memory of ours is involved.
    let per_second = u64::try_from(unsafe { libc::sysconf(libc::_SC_CLK_TCK) }).ok()?;
    if per_second == 0 {
        return None;
    }
    let since_boot = std::time::Duration::from_secs_f64(ticks as f64 / per_second as f64);
    Some(std::time::UNIX_EPOCH + std::time::Duration::from_secs(boot) + since_boot)
}

#[cfg(not(target_os = "linux"))]
fn process_start(_pid: u32) -> Option<std::time::SystemTime> {
    None
}

/// For a project temporary file name, `Some(Some(pid))` (`.<name>.tmp<pid>`) or `Some(None)`
/// (`.<name>.tmp`); `None` for anything else.
pub fn leftover_pid(name: &str) -> Option<Option<u32>> {
    let rest = name.strip_prefix('.')?;
    let at = rest.rfind(".tmp")?;
    let (stem, digits) = (&rest[..at], &rest[at + 4..]);
    if stem.is_empty() {
        return None;
    }
    if digits.is_empty() {
        return Some(None);
    }
    if !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok().map(Some)
}

fn holder_json(h: &Holder) -> String {
    serde_json::to_string(h).unwrap_or_default() + "\n"
}

/// The pid of a `LCK..` file that is not ours (HDB: the pid on the first line).
fn foreign_pid(content: &str) -> Option<u32> {
    let mut lines = content.lines();
    let pid = lines.next()?.trim().parse().ok()?;
    match lines.next() {
        Some(l) if l.starts_with("surfscan ") => None,
        _ => Some(pid),
    }
}

/// The holder named by one of our `LCK..` files, with its scan from its output directory.
fn device_holder(content: &str) -> Option<Holder> {
    let mut lines = content.lines();
    let pid: u32 = lines.next()?.trim().parse().ok()?;
    let rest = lines.next()?.strip_prefix("surfscan ")?;
    let (command, dir) = rest.split_once(' ')?;
    let from_dir: Option<Holder> = fs::read_to_string(Path::new(dir).join(OUTPUT_LOCK_FILE))
        .ok()
        .and_then(|s| serde_json::from_str(&s).ok())
        .filter(|h: &Holder| h.pid == pid);
    Some(Holder {
        pid,
        command: command.to_owned(),
        scan_id: from_dir.and_then(|h| h.scan_id),
    })
}

/// A respected foreign lock, naming its process, command and owner.
fn foreign_held(what: String, lock: &ForeignLock, path: &Path) -> LockError {
    LockError::Held {
        what,
        holder: format!("{} ({})", lock.describe(), path.display()),
        pid: Some(lock.pid),
        scan_id: None,
    }
}

/// Says that a lock file is not obeyed, and why.
fn not_obeyed(path: &Path, who: &str, why: &str) {
    tracing::warn!(
        path = %path.display(),
        "the device lock {} of {who} is not obeyed: {why}; it is taken over",
        path.display()
    );
}

fn held_error(what: String, holder: Option<Holder>) -> LockError {
    match holder {
        Some(h) => LockError::Held {
            what,
            holder: match &h.scan_id {
                Some(id) => format!("surfscan {}, pid {}, running scan {id}", h.command, h.pid),
                None => format!("surfscan {}, pid {}, no scan running", h.command, h.pid),
            },
            pid: Some(h.pid),
            scan_id: h.scan_id,
        },
        // Locked but not yet described: the holder is between its lock and its write.
        None => LockError::Held {
            what,
            holder: "another surfscan process that is starting".into(),
            pid: None,
            scan_id: None,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dead_pid() -> u32 {
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        pid
    }

    #[test]
    fn a_second_lock_on_the_output_directory_names_the_holder_and_its_scan() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("a/b/scans");
        let first = StationLock::acquire("daemon", &out, &[], tmp.path()).unwrap();
        assert!(out.is_dir(), "the missing output directory is created");
        let e = StationLock::acquire("scan", &out, &[], tmp.path()).unwrap_err();
        let LockError::Held { pid, scan_id, .. } = &e else {
            panic!("{e}")
        };
        assert_eq!((*pid, scan_id.as_deref()), (Some(std::process::id()), None));
        assert!(e.to_string().contains("surfscan daemon, pid"), "{e}");
        first.set_scan(Some("20260101T000000Z-A17"));
        let e = StationLock::acquire("scan", &out, &[], tmp.path()).unwrap_err();
        assert!(
            e.to_string().contains(&format!(
                "pid {}, running scan 20260101T000000Z-A17",
                std::process::id()
            )),
            "{e}"
        );
        // Released with the lock (a process that dies releases it the same way).
        drop(first);
        assert!(!out.join(OUTPUT_LOCK_FILE).exists());
        StationLock::acquire("scan", &out, &[], tmp.path()).unwrap();
    }

    #[test]
    fn one_device_under_two_names_is_one_lock() {
        let tmp = tempfile::tempdir().unwrap();
        let locks = tmp.path().join("lock");
        fs::create_dir(&locks).unwrap();
        let dev = tmp.path().join("ttyFAKE0");
        fs::write(&dev, b"").unwrap();
        let link = tmp.path().join("stage");
        std::os::unix::fs::symlink(&dev, &link).unwrap();
        let first = StationLock::acquire("scan", &tmp.path().join("o1"), &[&link], &locks).unwrap();
        first.set_scan(Some("S-1"));
        // Another station's output directory, the same device by its other name.
        let e =
            StationLock::acquire("daemon", &tmp.path().join("o2"), &[&dev], &locks).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("the device") && msg.contains("running scan S-1"),
            "{msg}"
        );
        // The refused attempt left the other station's output lock free again.
        assert!(!tmp.path().join("o2").join(OUTPUT_LOCK_FILE).exists());
        let name = device_lock_name(&link);
        let content = fs::read_to_string(locks.join(&name)).unwrap();
        assert_eq!(
            content.lines().next().unwrap(),
            format!("{:>10}", std::process::id())
        );
        drop(first);
        StationLock::acquire("daemon", &tmp.path().join("o2"), &[&dev], &locks).unwrap();
    }

    #[test]
    fn device_lock_names_follow_the_uucp_convention() {
        assert_eq!(device_lock_name(Path::new("/dev/ttyS0")), "LCK..ttyS0");
        assert_eq!(
            device_lock_name(Path::new("/nonexistent/x")),
            "LCK..nonexistent_x"
        );
    }

    #[test]
    fn another_programs_uucp_lock_is_respected_while_its_process_has_the_device_open() {
        let tmp = tempfile::tempdir().unwrap();
        let dev = tmp.path().join("ttyFAKE9");
        fs::write(&dev, "").unwrap();
        let dev = dev.as_path();
        let lck = tmp.path().join(device_lock_name(dev));
        // A terminal program holding the port.
        let mut child = std::process::Command::new("sleep")
            .arg("30")
            .stdin(File::open(dev).unwrap())
            .spawn()
            .unwrap();
        fs::write(&lck, format!("{:>10}\n", child.id())).unwrap();
        let e = StationLock::acquire("scan", &tmp.path().join("o"), &[dev], tmp.path());
        let _ = child.kill();
        let _ = child.wait();
        let e = e.unwrap_err();
        assert!(
            e.to_string().contains(&format!(
                "pid {} (sleep), its lock file owned by ",
                child.id()
            )),
            "{e}"
        );
        // pid 1 is alive but does not hold the port: not obeyed, taken over.
        fs::write(&lck, format!("{:>10}\n", 1)).unwrap();
        let held = StationLock::acquire("scan", &tmp.path().join("o"), &[dev], tmp.path()).unwrap();
        assert!(fs::read_to_string(&lck)
            .unwrap()
            .contains(&format!("{}\nsurfscan scan ", std::process::id())));
        drop(held);
        // A stale one (its process is gone) is taken over.
        fs::write(&lck, format!("{:>10}\n", dead_pid())).unwrap();
        let _held =
            StationLock::acquire("scan", &tmp.path().join("o"), &[dev], tmp.path()).unwrap();
    }

    #[test]
    fn a_strangers_flock_on_a_device_lock_file_is_not_obeyed() {
        let tmp = tempfile::tempdir().unwrap();
        let dev = Path::new("/nonexistent/ttyUSB8");
        let lck = tmp.path().join(device_lock_name(dev));
        fs::write(&lck, "").unwrap();
        // Owned by nobody, flocked by another process: as a local user could hold it.
        nix::unistd::chown(&lck, Some(nix::unistd::Uid::from_raw(65534)), None)
            .expect("chown needs root (run the tests as root)");
        let mut holder = std::process::Command::new("flock")
            .arg("-x")
            .arg(&lck)
            .args(["sleep", "30"])
            .spawn()
            .unwrap();
        // Wait until the lock is taken.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while Flock::lock(File::open(&lck).unwrap(), FlockArg::LockExclusiveNonblock).is_ok() {
            assert!(
                std::time::Instant::now() < deadline,
                "flock never took the lock"
            );
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        let got = StationLock::acquire("scan", &tmp.path().join("o"), &[dev], tmp.path());
        let _ = holder.kill();
        let _ = holder.wait();
        let held = got.unwrap();
        assert_eq!(held.devices.len(), 1);
        assert!(fs::read_to_string(&lck).unwrap().contains("surfscan scan "));
        // The same empty file, root's: another surfscan that is starting.
        drop(held);
        fs::write(&lck, "").unwrap();
        let file = Flock::lock(File::open(&lck).unwrap(), FlockArg::LockExclusiveNonblock).unwrap();
        let e =
            StationLock::acquire("scan", &tmp.path().join("o2"), &[dev], tmp.path()).unwrap_err();
        assert!(e.to_string().contains("another surfscan process"), "{e}");
        drop(file);
    }

    #[test]
    fn leftovers_of_interrupted_writes_are_swept_and_nothing_else() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("scans");
        let scan = out.join("20260101T000000Z-A17");
        fs::create_dir_all(scan.join("lines")).unwrap();
        fs::create_dir_all(scan.join("rk")).unwrap();
        let dead = dead_pid();
        let write = |p: PathBuf| {
            fs::write(&p, b"x").unwrap();
            p
        };
        let gone = [
            write(scan.join(format!(".surface.igs.tmp{dead}"))),
            write(scan.join("lines").join(".0003.csv.tmp")),
            write(out.join(format!(".metrics.prom.tmp{dead}"))),
            write(scan.join(format!(".bac.png.tmp{dead}"))),
            write(scan.join("rk").join(format!(".0004.svg.tmp{dead}"))),
        ];
        let kept = [
            write(scan.join("surface.igs")),
            write(scan.join("lines").join("0003.csv")),
            write(scan.join("rk").join("0004.svg")),
            // A live process's write in progress (pid 1 is always alive), and our own.
            write(scan.join(".report.json.tmp1")),
            write(scan.join(format!(".summary.csv.tmp{}", std::process::id()))),
            write(scan.join(".notes.tmpx")),
            write(scan.join(".tmp")),
            write(scan.join("journal.jsonl")),
        ];
        let lock = StationLock::acquire("scan", &out, &[], tmp.path()).unwrap();
        let mut removed = lock.sweep_leftovers();
        removed.sort();
        let mut expected = gone.to_vec();
        expected.sort();
        assert_eq!(removed, expected);
        for p in &gone {
            assert!(!p.exists(), "{p:?}");
        }
        for p in &kept {
            assert!(p.exists(), "{p:?}");
        }
        assert!(out.join(OUTPUT_LOCK_FILE).exists());
    }

    #[test]
    fn a_leftover_named_by_a_pid_reused_since_is_swept() {
        // After a reboot the pid in `.surface.igs.tmp<pid>` may belong to an unrelated
        // process started since: the file, last written before it started, is a leftover.
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("scans");
        fs::create_dir_all(&out).unwrap();
        let an_hour_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
        // Killed however the test ends.
        struct Reaped(std::process::Child);
        impl Drop for Reaped {
            fn drop(&mut self) {
                let _ = self.0.kill();
                let _ = self.0.wait();
            }
        }
        let newcomer = Reaped(
            std::process::Command::new("sleep")
                .arg("30")
                .spawn()
                .unwrap(),
        );
        let reused = out.join(format!(".surface.igs.tmp{}", newcomer.0.id()));
        // Our parent (the test runner's launcher) started before the file was written.
        let older = out.join(format!(
            ".report.json.tmp{}",
            std::os::unix::process::parent_id()
        ));
        for p in [&reused, &older] {
            fs::write(p, b"x").unwrap();
        }
        fs::File::options()
            .write(true)
            .open(&reused)
            .unwrap()
            .set_modified(an_hour_ago)
            .unwrap();
        let lock = StationLock::acquire("scan", &out, &[], tmp.path()).unwrap();
        let removed = lock.sweep_leftovers();
        drop(newcomer);
        assert_eq!(removed, vec![reused.clone()]);
        assert!(!reused.exists() && older.exists());
    }

    #[test]
    fn temporary_names_are_recognised_exactly() {
        assert_eq!(leftover_pid(".surface.igs.tmp4242"), Some(Some(4242)));
        assert_eq!(leftover_pid(".0003.csv.tmp"), Some(None));
        assert_eq!(leftover_pid("surface.igs.tmp4242"), None);
        assert_eq!(leftover_pid(".surface.igs.tmp42x"), None);
        assert_eq!(leftover_pid(".tmp"), None);
        assert_eq!(leftover_pid(".surfscan.lock"), None);
    }
}
