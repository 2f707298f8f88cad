//! Pseudo-terminals owned by the simulator: create one, put it in raw mode, link its slave path
//! at a stable name (e.g. `/tmp/sj210`), serve the master side asynchronously with tokio, and
//! "unplug" it (close the master, remove the link).
//!
//! Depends on `nix`/`libc` for the pty calls and on tokio's `AsyncFd`; nothing else in the crate.
//!
//! **Keeping the slave open.** When no process holds the slave side open, reading the master
//! returns `EIO` on Linux. The simulator therefore keeps its own slave descriptor open for the
//! whole life of a [`Pty`]: the instrument stays "present" between client connections (as a real
//! USB-serial device node does), and a client that closes and reopens the link finds the same
//! device. Bytes written while no client is connected stay in the pty buffer, just like bytes a
//! real instrument sends into an unconnected cable are lost or stale; clients drain on connect.

use std::io;
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::task::{ready, Context, Poll};

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use tokio::io::unix::AsyncFd;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// Errors while creating or linking a pseudo-terminal.
#[derive(Debug, thiserror::Error)]
pub enum PtyError {
    /// `openpty` or a termios call failed.
    #[error("cannot create a pseudo-terminal ({step}): {source}; check /dev/ptmx is available")]
    Create {
        /// Which call failed.
        step: &'static str,
        /// The OS error.
        source: nix::Error,
    },
    /// The link path exists and is not a symlink, so the simulator refuses to replace it.
    #[error("link path {path} exists and is not a symbolic link; choose another --*-link path or remove it")]
    LinkOccupied {
        /// The requested link path.
        path: PathBuf,
    },
    /// Creating or removing the symlink failed.
    #[error("cannot link {target} at {path}: {source}")]
    Link {
        /// The requested link path.
        path: PathBuf,
        /// The slave device path.
        target: PathBuf,
        /// The OS error.
        source: io::Error,
    },
    /// Registering the master with the tokio reactor failed (no runtime, or epoll error).
    #[error("cannot register the pty master with tokio: {0}")]
    Register(io::Error),
}

/// A pseudo-terminal whose slave is linked at a chosen path. Dropping it unplugs the device:
/// the master and the simulator's slave descriptor close and the link is removed.
#[derive(Debug)]
pub struct Pty {
    master: AsyncFd<OwnedFd>,
    // Held open on purpose; see the module documentation.
    slave: OwnedFd,
    slave_path: PathBuf,
    link: PathBuf,
}

impl Pty {
    /// Creates a raw-mode pseudo-terminal and links its slave at `link`, replacing a stale
    /// symlink there. Must be called inside a tokio runtime.
    pub fn create(link: &Path) -> Result<Self, PtyError> {
        let pair = nix::pty::openpty(None, None).map_err(|source| PtyError::Create {
            step: "openpty",
            source,
        })?;
        let mut termios = tcgetattr(pair.slave.as_fd()).map_err(|source| PtyError::Create {
            step: "tcgetattr",
            source,
        })?;
        // Raw: no echo, no CR/LF translation, byte-at-a-time reads.
        cfmakeraw(&mut termios);
        tcsetattr(pair.slave.as_fd(), SetArg::TCSANOW, &termios).map_err(|source| {
            PtyError::Create {
                step: "tcsetattr",
                source,
            }
        })?;
        // Close-on-exec on both ends: a process the simulator's host spawns (the daemon under
        // test) must not inherit them, or an "unplugged" device would stay open in it.
        for fd in [pair.master.as_raw_fd(), pair.slave.as_raw_fd()] {
            fcntl(fd, FcntlArg::F_SETFD(nix::fcntl::FdFlag::FD_CLOEXEC)).map_err(|source| {
                PtyError::Create {
                    step: "fcntl(F_SETFD)",
                    source,
                }
            })?;
        }
        let flags = fcntl(pair.master.as_raw_fd(), FcntlArg::F_GETFL).map_err(|source| {
            PtyError::Create {
                step: "fcntl(F_GETFL)",
                source,
            }
        })?;
        let flags = OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK;
        fcntl(pair.master.as_raw_fd(), FcntlArg::F_SETFL(flags)).map_err(|source| {
            PtyError::Create {
                step: "fcntl(F_SETFL)",
                source,
            }
        })?;
        let slave_path =
            nix::unistd::ttyname(pair.slave.as_fd()).map_err(|source| PtyError::Create {
                step: "ttyname",
                source,
            })?;
        link_at(link, &slave_path)?;
        // SAFETY: `OwnedFd` owns a valid descriptor that stays open until the `AsyncFd` (and with
        // it the registration) is dropped; nothing else closes or replaces it.
        let master =
            unsafe { AsyncFd::register(pair.master) }.map_err(|e| PtyError::Register(e.into()))?;
        Ok(Self {
            master,
            slave: pair.slave,
            slave_path,
            link: link.to_path_buf(),
        })
    }

    /// The `/dev/pts/N` path of the slave side.
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// The link path clients open.
    pub fn link(&self) -> &Path {
        &self.link
    }

    /// A second descriptor of the slave side, to read the line settings the client set
    /// ([`crate::line::HostLine`]).
    pub fn slave_dup(&self) -> io::Result<OwnedFd> {
        self.slave.try_clone()
    }

    /// Bytes written by the simulator that the client has not read yet (the slave's input
    /// queue, `FIONREAD`).
    pub fn unread_by_client(&self) -> io::Result<usize> {
        let mut n: libc::c_int = 0;
        // SAFETY: FIONREAD writes one c_int through the pointer, which is valid for the call;
        // the descriptor is owned by `self` and open.
        let rc = unsafe { libc::ioctl(self.slave.as_raw_fd(), libc::FIONREAD, &mut n) };
        if rc < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(usize::try_from(n).unwrap_or(0))
    }

    /// For `d`, the link takes none of the host's bytes: the slave's output is stopped by
    /// software flow control (IXON set on it, then XOFF sent to it), so the host's writes
    /// stall as they do behind CTS held low; bytes that arrive meanwhile are discarded. A host
    /// that reopens the port (its termios clears IXON) is held back again within 50 ms.
    /// Afterwards IXON is cleared, which lets the output flow again.
    pub async fn hold_host(&mut self, d: std::time::Duration) -> io::Result<()> {
        use nix::sys::termios::InputFlags;
        use tokio::io::AsyncReadExt;
        fn set_ixon(slave: &OwnedFd, on: bool) -> io::Result<()> {
            let mut t = tcgetattr(slave.as_fd()).map_err(io_err)?;
            t.input_flags.set(InputFlags::IXON, on);
            tcsetattr(slave.as_fd(), SetArg::TCSANOW, &t).map_err(io_err)
        }
        let end = tokio::time::Instant::now() + d;
        let mut buf = [0u8; 512];
        while tokio::time::Instant::now() < end {
            set_ixon(&self.slave, true)?;
            nix::unistd::write(self.master.get_ref(), &[0x13]).map_err(io_err)?;
            let left = end.saturating_duration_since(tokio::time::Instant::now());
            let _ = tokio::time::timeout(
                std::time::Duration::from_millis(50).min(left),
                self.read(&mut buf),
            )
            .await;
        }
        set_ixon(&self.slave, false)
    }

    /// Waits (up to `limit`) until the client has read everything written, so that closing the
    /// pty does not discard a reply the real device would already have transmitted.
    pub async fn wait_drained(&self, limit: std::time::Duration) {
        let deadline = tokio::time::Instant::now() + limit;
        while matches!(self.unread_by_client(), Ok(n) if n > 0)
            && tokio::time::Instant::now() < deadline
        {
            tokio::time::sleep(std::time::Duration::from_millis(5)).await;
        }
    }
}

impl Drop for Pty {
    fn drop(&mut self) {
        // Only remove the link if it still points at our slave (a newer pty may own it).
        if std::fs::read_link(&self.link).ok().as_deref() == Some(self.slave_path.as_path()) {
            let _ = std::fs::remove_file(&self.link);
        }
    }
}

fn link_at(link: &Path, target: &Path) -> Result<(), PtyError> {
    match std::fs::symlink_metadata(link) {
        Ok(meta) if meta.file_type().is_symlink() => {
            std::fs::remove_file(link).map_err(|source| PtyError::Link {
                path: link.to_path_buf(),
                target: target.to_path_buf(),
                source,
            })?;
        }
        Ok(_) => {
            return Err(PtyError::LinkOccupied {
                path: link.to_path_buf(),
            })
        }
        Err(_) => {}
    }
    std::os::unix::fs::symlink(target, link).map_err(|source| PtyError::Link {
        path: link.to_path_buf(),
        target: target.to_path_buf(),
        source,
    })
}

/// Converts a nix error into an `io::Error` (the slave stays open, so `EIO` is a real error).
fn io_err(e: nix::Error) -> io::Error {
    io::Error::from_raw_os_error(e as i32)
}

impl AsyncRead for Pty {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        loop {
            let mut guard = ready!(self.master.poll_read_ready(cx))?;
            let unfilled = buf.initialize_unfilled();
            match guard
                .try_io(|fd| nix::unistd::read(fd.get_ref().as_raw_fd(), unfilled).map_err(io_err))
            {
                Ok(Ok(n)) => {
                    buf.advance(n);
                    return Poll::Ready(Ok(()));
                }
                Ok(Err(e)) => return Poll::Ready(Err(e)),
                Err(_would_block) => continue,
            }
        }
    }
}

impl AsyncWrite for Pty {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        loop {
            let mut guard = ready!(self.master.poll_write_ready(cx))?;
            match guard.try_io(|fd| nix::unistd::write(fd.get_ref(), buf).map_err(io_err)) {
                Ok(result) => return Poll::Ready(result),
                Err(_would_block) => continue,
            }
        }
    }

    fn poll_flush(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    /// While the pty holds the host back, a non-blocking write of the host's is refused
    /// (EAGAIN: its bytes are not taken); afterwards it goes through.
    #[tokio::test]
    async fn holding_the_host_back_stops_its_writes_until_released() {
        use std::os::unix::fs::OpenOptionsExt;
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("dev");
        let mut pty = Pty::create(&link).unwrap();
        let mut host = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&link)
            .unwrap();
        let hold = std::time::Duration::from_millis(300);
        let held = tokio::spawn(async move {
            pty.hold_host(hold).await.unwrap();
            pty
        });
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        let e = std::io::Write::write(&mut host, b"CTSTA\r").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::WouldBlock, "{e}");
        let mut pty = held.await.unwrap();
        assert_eq!(std::io::Write::write(&mut host, b"RDSJ 01\r").unwrap(), 8);
        let mut got = [0u8; 8];
        pty.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"RDSJ 01\r");
    }

    #[tokio::test]
    async fn replaces_a_stale_link_refuses_a_file_and_survives_client_reconnects() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("dev");
        std::os::unix::fs::symlink("/nonexistent/stale", &link).unwrap();
        let mut pty = Pty::create(&link).unwrap();
        assert_eq!(std::fs::read_link(&link).unwrap(), pty.slave_path());

        // A client connects, writes, goes away; the next one still finds the device.
        for round in 0..2u8 {
            let mut client = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(&link)
                .unwrap();
            std::io::Write::write_all(&mut client, &[b'a' + round]).unwrap();
            let mut b = [0u8; 1];
            pty.read_exact(&mut b).await.unwrap();
            assert_eq!(b[0], b'a' + round);
            pty.write_all(b"z").await.unwrap();
            let mut r = [0u8; 1];
            std::io::Read::read_exact(&mut client, &mut r).unwrap();
            assert_eq!(&r, b"z");
        }

        let file = dir.path().join("plain");
        std::fs::write(&file, b"x").unwrap();
        assert!(matches!(
            Pty::create(&file),
            Err(PtyError::LinkOccupied { .. })
        ));
        drop(pty);
        assert!(std::fs::symlink_metadata(&link).is_err(), "drop unplugs");
    }
}
