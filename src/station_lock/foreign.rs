//! Whether another program's `LCK..` file keeps the station off a device. The lock directory
//! (`/run/lock`) is writable by every local user, so a lock file proves nothing by itself: a
//! file naming pid 1, or a stale lock of a terminal program whose pid was reused since, would
//! otherwise keep the daemon from ever starting. [`judge`] is the pure decision over what is
//! known of the file and its process ([`ForeignLock`]); [`ForeignLock::inspect`] gathers it.
//!
//! Layer 4 (process edge): depends on std, libc and nix (the user database) only.

use std::fs;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// What is known of a lock file that is not ours and of the process it names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ForeignLock {
    /// The pid the file names.
    pub pid: u32,
    /// Whether a process with that pid exists.
    pub alive: bool,
    /// The file's owner.
    pub owner_uid: u32,
    /// The user this process runs as.
    pub our_uid: u32,
    /// Whether that process has the device open; `None` when its descriptors cannot be seen
    /// (another user's process, to a daemon that is not root).
    pub has_device_open: Option<bool>,
    /// The process's command (`/proc/PID/comm`), when visible.
    pub command: Option<String>,
}

/// What the station does about a foreign lock file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// Its process is gone: a stale lock, taken over.
    Stale,
    /// Respected: the device is in use.
    Obey,
    /// Not obeyed (the reason, for a warning): the file is replaced where it can be.
    Ignore(String),
}

/// The decision, row by row:
///
/// | the named process | its descriptors | the file's owner | verdict |
/// |---|---|---|---|
/// | gone | — | — | stale, taken over |
/// | alive | visible, the device open | — | obeyed |
/// | alive | visible, the device not open | — | not obeyed (a reused pid, or a file naming a process that uses no port) |
/// | alive | not visible | root or the daemon's user | obeyed |
/// | alive | not visible | another user | not obeyed (any local user can write the lock directory) |
pub fn judge(lock: &ForeignLock) -> Verdict {
    if !lock.alive {
        return Verdict::Stale;
    }
    match lock.has_device_open {
        Some(true) => Verdict::Obey,
        Some(false) => Verdict::Ignore("that process does not have the device open".into()),
        None if lock.owner_uid == 0 || lock.owner_uid == lock.our_uid => Verdict::Obey,
        None => Verdict::Ignore(
            "the file's owner is neither root nor the daemon's user, and any local user can write the lock directory"
                .into(),
        ),
    }
}

impl ForeignLock {
    /// Gathers what is known of lock file `meta` naming `pid`, for `device`.
    pub fn inspect(pid: u32, alive: bool, meta: &fs::Metadata, device: &Path) -> ForeignLock {
        ForeignLock {
            pid,
            alive,
            owner_uid: meta.uid(),
            our_uid: nix::unistd::geteuid().as_raw(),
            has_device_open: alive.then(|| has_open(pid, device)).flatten(),
            command: fs::read_to_string(format!("/proc/{pid}/comm"))
                .ok()
                .map(|c| c.trim().to_owned())
                .filter(|c| !c.is_empty()),
        }
    }

    /// The holder for people: `pid 1234 (minicom), lock file owned by alice`.
    pub fn describe(&self) -> String {
        format!(
            "pid {} ({}), its lock file owned by {}",
            self.pid,
            self.command.as_deref().unwrap_or("command not visible"),
            user_name(self.owner_uid)
        )
    }
}

/// A user's name, or `uid N` when the user database does not know it.
pub fn user_name(uid: u32) -> String {
    match nix::unistd::User::from_uid(nix::unistd::Uid::from_raw(uid)) {
        Ok(Some(u)) => format!("{} (uid {uid})", u.name),
        _ => format!("uid {uid}"),
    }
}

/// Whether process `pid` has `device` open, from its descriptors in `/proc/PID/fd`; `None`
/// when they cannot be listed.
fn has_open(pid: u32, device: &Path) -> Option<bool> {
    let target: PathBuf = fs::canonicalize(device).unwrap_or_else(|_| device.to_path_buf());
    let fds = fs::read_dir(format!("/proc/{pid}/fd")).ok()?;
    Some(
        fds.filter_map(Result::ok)
            .filter_map(|e| fs::read_link(e.path()).ok())
            .any(|p| p == target),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lock(alive: bool, open: Option<bool>, owner: u32) -> ForeignLock {
        ForeignLock {
            pid: 4321,
            alive,
            owner_uid: owner,
            our_uid: 998,
            has_device_open: open,
            command: Some("minicom".into()),
        }
    }

    #[test]
    fn the_table_row_by_row() {
        assert_eq!(judge(&lock(false, None, 1000)), Verdict::Stale);
        assert_eq!(judge(&lock(false, Some(true), 0)), Verdict::Stale);
        assert_eq!(judge(&lock(true, Some(true), 1000)), Verdict::Obey);
        assert!(matches!(
            judge(&lock(true, Some(false), 0)),
            Verdict::Ignore(r) if r.contains("does not have the device open")
        ));
        assert_eq!(judge(&lock(true, None, 0)), Verdict::Obey);
        assert_eq!(judge(&lock(true, None, 998)), Verdict::Obey);
        assert!(matches!(
            judge(&lock(true, None, 1000)),
            Verdict::Ignore(r) if r.contains("neither root nor the daemon's user")
        ));
    }

    #[test]
    fn a_process_holding_the_device_is_seen_and_one_that_does_not_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let device = dir.path().join("ttyFAKE0");
        fs::write(&device, "").unwrap();
        let other = dir.path().join("ttyFAKE1");
        fs::write(&other, "").unwrap();
        let mut child = std::process::Command::new("sleep")
            .arg("30")
            .stdin(fs::File::open(&device).unwrap())
            .spawn()
            .unwrap();
        let pid = child.id();
        let meta = fs::metadata(&device).unwrap();
        let seen = ForeignLock::inspect(pid, true, &meta, &device);
        let not = ForeignLock::inspect(pid, true, &meta, &other);
        let _ = child.kill();
        let _ = child.wait();
        assert_eq!(seen.has_device_open, Some(true));
        assert_eq!(seen.command.as_deref(), Some("sleep"));
        assert_eq!(not.has_device_open, Some(false));
        assert!(seen
            .describe()
            .starts_with(&format!("pid {pid} (sleep), its lock file owned by ")));
    }
}
