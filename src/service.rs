//! systemd service notification (sd_notify(3)): `READY=1` once start-up is done, `STATUS=`
//! lines for `systemctl status`, `WATCHDOG=1` pings and `STOPPING=1` on shutdown.
//!
//! The [`Notifier`] resolves `NOTIFY_SOCKET` and `WATCHDOG_USEC`/`WATCHDOG_PID` once, when it
//! is built, and is a no-op when the daemon does not run under systemd. Messages are worded
//! with the `sd-notify` crate's [`NotifyState`]; the datagram is sent here, so a socket can
//! also be given explicitly (tests, or a supervisor other than systemd) and abstract
//! (`@name`) sockets work. A failed notification is logged and never stops the daemon.
//!
//! Layer 4 (process edge): depends on std and `sd-notify`; nothing in the crate.

use sd_notify::NotifyState;
use std::ffi::OsStr;
use std::io;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::Duration;

/// Sends service notifications to systemd, or nothing when not under systemd.
#[derive(Debug)]
pub struct Notifier {
    target: Option<(UnixDatagram, SocketAddr)>,
    watchdog: Option<Duration>,
}

impl Notifier {
    /// A notifier that sends nothing.
    pub fn disabled() -> Notifier {
        Notifier {
            target: None,
            watchdog: None,
        }
    }

    /// The notifier systemd's environment asks for: `NOTIFY_SOCKET` (unset: no-op) and the
    /// watchdog from `WATCHDOG_USEC` when `WATCHDOG_PID` is unset or names this process.
    /// A `NOTIFY_SOCKET` that cannot be used is logged and yields a disabled notifier.
    pub fn from_env() -> Notifier {
        let socket = std::env::var_os("NOTIFY_SOCKET");
        let usec = std::env::var("WATCHDOG_USEC").ok();
        let pid = std::env::var("WATCHDOG_PID").ok();
        let watchdog = watchdog_period(usec.as_deref(), pid.as_deref(), std::process::id());
        match socket {
            None => Notifier::disabled(),
            Some(path) => match Notifier::with_socket(&path, watchdog) {
                Ok(n) => n,
                Err(e) => {
                    tracing::warn!(socket = ?path, error = %e, "NOTIFY_SOCKET is unusable; systemd will not see READY or watchdog pings");
                    Notifier::disabled()
                }
            },
        }
    }

    /// A notifier sending to `socket` (a path, or `@name` for an abstract socket), with the
    /// watchdog period systemd configured (`WatchdogSec=`), if any.
    pub fn with_socket(socket: &OsStr, watchdog: Option<Duration>) -> io::Result<Notifier> {
        let bytes = socket.as_bytes();
        let addr = match bytes.split_first() {
            None => {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidInput,
                    "empty notification socket path",
                ))
            }
            Some((b'@', name)) => abstract_addr(name)?,
            Some(_) => SocketAddr::from_pathname(socket)?,
        };
        let sock = UnixDatagram::unbound()?;
        sock.set_nonblocking(true)?;
        Ok(Notifier {
            target: Some((sock, addr)),
            watchdog,
        })
    }

    /// Whether notifications go anywhere.
    pub fn is_enabled(&self) -> bool {
        self.target.is_some()
    }

    /// The watchdog period systemd expects pings within, if the watchdog is on.
    pub fn watchdog_period(&self) -> Option<Duration> {
        self.watchdog
    }

    /// How often to call [`watchdog`](Notifier::watchdog): half the period, as sd_watchdog_enabled(3)
    /// recommends, so one late tick does not get the service killed.
    pub fn watchdog_interval(&self) -> Option<Duration> {
        self.watchdog.map(|p| p / 2)
    }

    /// `READY=1`: start-up finished (config loaded, control socket bound).
    pub fn ready(&self) {
        self.send(&[NotifyState::Ready]);
    }

    /// `STATUS=<text>` for `systemctl status`; line breaks become spaces.
    pub fn status(&self, text: &str) {
        let line = one_line(text);
        self.send(&[NotifyState::Status(&line)]);
    }

    /// `WATCHDOG=1`: the main loop is alive.
    pub fn watchdog(&self) {
        self.send(&[NotifyState::Watchdog]);
    }

    /// `STOPPING=1`: shutdown has begun.
    pub fn stopping(&self) {
        self.send(&[NotifyState::Stopping]);
    }

    fn send(&self, states: &[NotifyState<'_>]) {
        let Some((sock, addr)) = &self.target else {
            return;
        };
        let msg: String = states.iter().map(|s| format!("{s}\n")).collect();
        match sock.send_to_addr(msg.as_bytes(), addr) {
            Ok(n) if n == msg.len() => {}
            Ok(n) => tracing::warn!(sent = n, len = msg.len(), "systemd notification truncated"),
            Err(e) => tracing::warn!(
                message = msg.trim_end(),
                error = %e,
                "cannot notify systemd"
            ),
        }
    }
}

#[cfg(any(target_os = "linux", target_os = "android"))]
fn abstract_addr(name: &[u8]) -> io::Result<SocketAddr> {
    #[cfg(target_os = "android")]
    use std::os::android::net::SocketAddrExt;
    #[cfg(target_os = "linux")]
    use std::os::linux::net::SocketAddrExt;
    SocketAddr::from_abstract_name(name)
}

#[cfg(not(any(target_os = "linux", target_os = "android")))]
fn abstract_addr(_name: &[u8]) -> io::Result<SocketAddr> {
    Err(io::Error::new(
        io::ErrorKind::Unsupported,
        "abstract notification sockets exist only on Linux",
    ))
}

/// The watchdog period from `WATCHDOG_USEC`, honoured when `WATCHDOG_PID` is unset or equals
/// `own_pid` (a child that inherited the variables must not ping for its parent). A zero,
/// negative or unparsable value means no watchdog.
pub fn watchdog_period(usec: Option<&str>, pid: Option<&str>, own_pid: u32) -> Option<Duration> {
    let usec: u64 = usec?.trim().parse().ok().filter(|&u| u > 0)?;
    if let Some(pid) = pid {
        if pid.trim().parse::<u32>().ok() != Some(own_pid) {
            return None;
        }
    }
    Some(Duration::from_micros(usec))
}

fn one_line(text: &str) -> String {
    text.chars()
        .map(|c| if c == '\n' || c == '\r' { ' ' } else { c })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn watchdog_period_follows_sd_watchdog_enabled() {
        assert_eq!(
            watchdog_period(Some("60000000"), Some("42"), 42),
            Some(Duration::from_secs(60))
        );
        assert_eq!(
            watchdog_period(Some("1500000"), None, 42),
            Some(Duration::from_millis(1500))
        );
        // Inherited by a child: not ours.
        assert_eq!(watchdog_period(Some("60000000"), Some("41"), 42), None);
        assert_eq!(watchdog_period(Some("0"), None, 42), None);
        assert_eq!(watchdog_period(Some("sixty"), None, 42), None);
        assert_eq!(watchdog_period(None, Some("42"), 42), None);
    }

    #[test]
    fn explicit_socket_receives_each_message_and_status_stays_one_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notify.sock");
        let server = UnixDatagram::bind(&path).unwrap();
        server
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        let n = Notifier::with_socket(path.as_os_str(), Some(Duration::from_secs(10))).unwrap();
        assert!(n.is_enabled());
        assert_eq!(n.watchdog_interval(), Some(Duration::from_secs(5)));
        n.status("scan X: line 2/9\nsecond line");
        n.watchdog();
        let mut buf = [0u8; 256];
        let len = server.recv(&mut buf).unwrap();
        assert_eq!(&buf[..len], b"STATUS=scan X: line 2/9 second line\n");
        let len = server.recv(&mut buf).unwrap();
        assert_eq!(&buf[..len], b"WATCHDOG=1\n");
    }

    #[test]
    fn abstract_socket_is_reached_by_at_name() {
        let name = format!("surfscan-notify-test-{}", std::process::id());
        let addr = abstract_addr(name.as_bytes()).unwrap();
        let server = UnixDatagram::bind_addr(&addr).unwrap();
        server
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        let n = Notifier::with_socket(OsStr::new(&format!("@{name}")), None).unwrap();
        n.ready();
        let mut buf = [0u8; 64];
        let len = server.recv(&mut buf).unwrap();
        assert_eq!(&buf[..len], b"READY=1\n");
        assert_eq!(n.watchdog_interval(), None);
    }

    #[test]
    fn a_missing_socket_is_logged_not_fatal() {
        let n = Notifier::with_socket(OsStr::new("/nonexistent/surfscan/notify"), None).unwrap();
        // Sending fails (ENOENT); the call must return normally.
        n.ready();
        n.stopping();
        assert!(Notifier::with_socket(OsStr::new(""), None).is_err());
        assert!(!Notifier::disabled().is_enabled());
    }
}
