//! systemd notifications from the environment systemd sets up: one test function, because
//! `NOTIFY_SOCKET` and `WATCHDOG_*` are process-wide.

use std::os::unix::net::UnixDatagram;
use std::time::Duration;
use surfscan::service::Notifier;

fn recv(sock: &UnixDatagram) -> String {
    let mut buf = [0u8; 512];
    let n = sock.recv(&mut buf).expect("a notification datagram");
    String::from_utf8(buf[..n].to_vec()).unwrap()
}

#[test]
fn notifications_reach_the_socket_named_by_the_environment() {
    let _env = crate::process_state();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("notify");
    let sock = UnixDatagram::bind(&path).unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(2))).unwrap();

    // As systemd starts a unit with WatchdogSec=3s.
    std::env::set_var("NOTIFY_SOCKET", &path);
    std::env::set_var("WATCHDOG_USEC", "3000000");
    std::env::set_var("WATCHDOG_PID", std::process::id().to_string());
    let n = Notifier::from_env();
    assert!(n.is_enabled());
    assert_eq!(n.watchdog_period(), Some(Duration::from_secs(3)));
    assert_eq!(n.watchdog_interval(), Some(Duration::from_millis(1500)));
    n.ready();
    n.status("scan G-0142: line 12/31, y=0.110 mm");
    n.watchdog();
    n.stopping();
    assert_eq!(recv(&sock), "READY=1\n");
    assert_eq!(recv(&sock), "STATUS=scan G-0142: line 12/31, y=0.110 mm\n");
    assert_eq!(recv(&sock), "WATCHDOG=1\n");
    assert_eq!(recv(&sock), "STOPPING=1\n");

    // The watchdog variables belong to another process (inherited): no watchdog.
    std::env::set_var("WATCHDOG_PID", (std::process::id() + 1).to_string());
    assert_eq!(Notifier::from_env().watchdog_interval(), None);

    // Not under systemd: nothing is sent, nothing fails.
    std::env::remove_var("NOTIFY_SOCKET");
    std::env::remove_var("WATCHDOG_USEC");
    std::env::remove_var("WATCHDOG_PID");
    let off = Notifier::from_env();
    assert!(!off.is_enabled());
    assert_eq!(off.watchdog_interval(), None);
    off.ready();
    off.watchdog();
    sock.set_nonblocking(true).unwrap();
    let mut buf = [0u8; 64];
    let err = sock.recv(&mut buf).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::WouldBlock);
}
