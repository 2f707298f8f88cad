//! A real Mosquitto broker for the MQTT tests, started on a free loopback port in a test's
//! directory with a password file and an ACL, `mosquitto_sub` as the independent
//! subscriber and `mosquitto_pub` as a lab's client commanding the station. The ACL is the
//! one docs/integration.md gives: a client writes only its own command topic. Both are Debian packages (`mosquitto`, `mosquitto-clients`) that `.ci/run`
//! installs. Also the loopback ports the tests' other servers are started on ([`free_ports`],
//! [`on_fresh_ports`]).

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The station's user on the broker.
pub const STATION_USER: &str = "station";
/// Its password.
pub const STATION_PASSWORD: &str = "st4tion-pw";
/// The subscriber's user (read only).
pub const WATCHER_USER: &str = "watcher";
const WATCHER_PASSWORD: &str = "w4tcher-pw";
/// A lab's client that commands stations (no topic of its own beyond the ACL's patterns).
pub const OPERATOR_USER: &str = "operator";
const OPERATOR_PASSWORD: &str = "op3rator-pw";
/// The longest the broker may take to start, to stop, or to pass on what a test waits for:
/// a guard against a hang, long enough for a loaded machine.
const DEADLINE: Duration = Duration::from_secs(90);

/// `N` different free loopback TCP ports: each held until all are picked (a port released
/// at once could be picked again for the next), then released for the caller to bind.
/// Another process may take one before the caller does: a server of ours is bound to port 0
/// instead (the daemon logs the address it bound), another program's is started with
/// [`on_fresh_ports`].
pub fn free_ports<const N: usize>() -> [u16; N] {
    let held: [TcpListener; N] = std::array::from_fn(|_| TcpListener::bind("127.0.0.1:0").unwrap());
    held.map(|l| l.local_addr().unwrap().port())
}

/// Starts another program's server (the broker, an S3 server, Prometheus) on `N` free loopback
/// ports: `start` launches it on the ports given and waits until it listens, or returns
/// `Err` (the program's words) when it could not bind one of them. A port [`free_ports`]
/// picked is released before the program binds it, so another process (the tests run in
/// parallel) may take it meanwhile: the start is then made again on fresh ports, for up to
/// [`DEADLINE`]. Any other failure is `start`'s to panic on.
pub fn on_fresh_ports<const N: usize, T>(
    what: &str,
    mut start: impl FnMut([u16; N]) -> Result<T, String>,
) -> T {
    let begun = Instant::now();
    loop {
        match start(free_ports()) {
            Ok(t) => return t,
            Err(e) if begun.elapsed() < DEADLINE => {
                eprintln!("{what} could not bind its port, trying fresh ones: {e}");
            }
            Err(e) => panic!("{what} found no free port in {} s: {e}", DEADLINE.as_secs()),
        }
    }
}

/// Whether a server's words say it could not bind its port.
pub fn port_taken(said: &str) -> bool {
    said.contains("Address already in use") || said.contains("address already in use")
}

/// A child process killed when dropped.
pub struct Killed(pub Child);

impl Drop for Killed {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// A broker and its files.
pub struct Broker {
    /// Its port on 127.0.0.1.
    pub port: u16,
    dir: PathBuf,
    process: Option<Killed>,
}

fn which(program: &str) -> PathBuf {
    for dir in ["/usr/sbin", "/usr/bin", "/usr/local/sbin", "/usr/local/bin"] {
        let p = Path::new(dir).join(program);
        if p.exists() {
            return p;
        }
    }
    panic!("{program} is not installed: `bash .ci/run` installs mosquitto and mosquitto-clients (apt-get install mosquitto mosquitto-clients)");
}

impl Broker {
    /// Writes the configuration, password file and ACL below `dir` and starts the broker.
    pub fn start(dir: &Path) -> Broker {
        let dir = dir.join("broker");
        std::fs::create_dir_all(dir.join("data")).unwrap();
        let passwd = dir.join("passwd");
        for (k, (user, pw)) in [
            (STATION_USER, STATION_PASSWORD),
            (WATCHER_USER, WATCHER_PASSWORD),
            (OPERATOR_USER, OPERATOR_PASSWORD),
        ]
        .into_iter()
        .enumerate()
        {
            let mut c = Command::new(which("mosquitto_passwd"));
            if k == 0 {
                c.arg("-c");
            }
            let st = c.arg("-b").arg(&passwd).args([user, pw]).status().unwrap();
            assert!(st.success(), "mosquitto_passwd failed");
        }
        std::fs::write(
            dir.join("acl"),
            format!(
                "pattern write surfscan/+/commands/%c\npattern read surfscan/+/replies/%c\n\nuser {STATION_USER}\ntopic readwrite surfscan/#\n\nuser {WATCHER_USER}\ntopic read surfscan/#\n"
            ),
        )
        .unwrap();
        // The broker exits naming a port another process took first.
        on_fresh_ports("mosquitto", |[port]| {
            // Started as root, mosquitto drops to the user `mosquitto`, who cannot write the
            // test's directory (its persistence and log): it stays root then (CI runs as root).
            let user = if nix::unistd::geteuid().is_root() {
                "user root\n"
            } else {
                ""
            };
            std::fs::write(
                dir.join("mosquitto.conf"),
                format!(
                    "{user}listener {port} 127.0.0.1\nallow_anonymous false\npassword_file {}\nacl_file {}\npersistence true\npersistence_location {}/\nlog_dest file {}\n",
                    passwd.display(),
                    dir.join("acl").display(),
                    dir.join("data").display(),
                    dir.join("mosquitto.log").display(),
                ),
            )
            .unwrap();
            let mut b = Broker {
                port,
                dir: dir.clone(),
                process: None,
            };
            match b.launch() {
                Ok(()) => Ok(b),
                Err(e) if port_taken(&e) => Err(e),
                Err(e) => panic!("{e}"),
            }
        })
    }

    /// The broker's URL.
    pub fn url(&self) -> String {
        format!("mqtt://127.0.0.1:{}", self.port)
    }

    /// Stops the broker (SIGTERM: it saves its persistent sessions and retained messages).
    pub fn stop(&mut self) {
        if let Some(mut p) = self.process.take() {
            let pid = nix::unistd::Pid::from_raw(p.0.id() as i32);
            nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
            let start = Instant::now();
            while p.0.try_wait().unwrap().is_none() {
                assert!(
                    start.elapsed() < DEADLINE,
                    "mosquitto does not stop: {}",
                    std::fs::read_to_string(self.dir.join("mosquitto.log")).unwrap_or_default()
                );
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }

    /// Restarts the broker with TLS on its port, with a certificate for 127.0.0.1 from
    /// [`throwaway_tls`](crate::common::throwaway_tls). Returns the CA's PEM file, the one a
    /// client must trust; no system authority knows it.
    pub fn with_tls(&mut self) -> PathBuf {
        self.stop();
        let d = self.dir.clone();
        let tls = crate::common::throwaway_tls(&d);
        let conf = d.join("mosquitto.conf");
        crate::common::append_config(
            &conf,
            &format!(
                "certfile {}\nkeyfile {}\n",
                tls.certificate.display(),
                tls.key.display()
            ),
        );
        self.restart();
        tls.ca
    }

    /// Starts the broker again on the same port, with what it saved.
    pub fn restart(&mut self) {
        if let Err(e) = self.launch() {
            panic!("{e}");
        }
    }

    /// Starts the broker and waits until it listens: until its log says it runs, which it
    /// writes once all its listeners are open (another process listening on the port would
    /// answer a connection too), or it exits naming what it could not do.
    fn launch(&mut self) -> Result<(), String> {
        assert!(self.process.is_none(), "the broker is running");
        let log = self.dir.join("mosquitto.log");
        let from = std::fs::metadata(&log).map_or(0, |m| m.len() as usize);
        let child = Command::new(which("mosquitto"))
            .arg("-c")
            .arg(self.dir.join("mosquitto.conf"))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut child = Killed(child);
        let start = Instant::now();
        loop {
            let bytes = std::fs::read(&log).unwrap_or_default();
            let said = String::from_utf8_lossy(bytes.get(from..).unwrap_or(&bytes));
            if let Some(st) = child.0.try_wait().unwrap() {
                return Err(format!("mosquitto exited ({st}): {said}"));
            }
            if said.contains(" running\n")
                && std::net::TcpStream::connect(("127.0.0.1", self.port)).is_ok()
            {
                break;
            }
            assert!(
                start.elapsed() < DEADLINE,
                "mosquitto does not listen: {said}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        self.process = Some(child);
        Ok(())
    }

    /// Starts `mosquitto_sub` as the watcher with a persistent session (client id `id`,
    /// QoS 1), writing each message as `RETAIN TOPIC PAYLOAD` to `out`. Messages published
    /// while it is away are kept for it by the broker.
    pub fn subscribe(&self, id: &str, out: &Path) -> Killed {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(out)
            .unwrap();
        let child = Command::new(which("mosquitto_sub"))
            .args(["-h", "127.0.0.1", "-p", &self.port.to_string()])
            .args(["-u", WATCHER_USER, "-P", WATCHER_PASSWORD])
            .args(["-i", id, "-c", "-q", "1", "-t", "surfscan/#"])
            .args(["-F", "%r %t %p"])
            .stdin(Stdio::null())
            .stdout(file)
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        Killed(child)
    }
}

impl Broker {
    /// Publishes `payload` on `topic` with `mosquitto_pub` as the operator with client id
    /// `client_id` (QoS 1; retained when `retain`), and waits for it to be handed over.
    pub fn publish(&self, client_id: &str, topic: &str, payload: &str, retain: bool) {
        let mut c = Command::new(which("mosquitto_pub"));
        c.args(["-h", "127.0.0.1", "-p", &self.port.to_string()])
            .args(["-u", OPERATOR_USER, "-P", OPERATOR_PASSWORD])
            .args(["-i", client_id, "-q", "1", "-t", topic, "-m", payload]);
        if retain {
            c.arg("-r");
        }
        let out = c.stdin(Stdio::null()).output().unwrap();
        assert!(
            out.status.success(),
            "mosquitto_pub failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// One message as the subscriber saw it.
#[derive(Debug, Clone)]
pub struct Seen {
    /// Retained flag.
    pub retained: bool,
    /// Topic.
    pub topic: String,
    /// Payload text.
    pub payload: String,
}

impl Seen {
    /// The payload as JSON.
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_str(&self.payload)
            .unwrap_or_else(|e| panic!("{}: not JSON ({e}): {}", self.topic, self.payload))
    }
}

/// Every message in a subscriber's output so far: the complete lines only. mosquitto_sub's
/// output is a file, written through stdio's 4 KiB buffer: a results message (about 6 KB)
/// reaches it in two writes, and a read between them sees the first part without its
/// newline, which is left for the next read.
pub fn seen(out: &Path) -> Vec<Seen> {
    crate::common::complete_lines(out)
        .lines()
        .filter_map(|l| {
            let (r, rest) = l.split_once(' ')?;
            let (topic, payload) = rest.split_once(' ').unwrap_or((rest, ""));
            Some(Seen {
                retained: r == "1",
                topic: topic.to_owned(),
                payload: payload.to_owned(),
            })
        })
        .collect()
}

/// Waits until the subscriber's messages satisfy `done`.
pub async fn wait_seen(out: &Path, what: &str, done: impl Fn(&[Seen]) -> bool) -> Vec<Seen> {
    let start = Instant::now();
    loop {
        let s = seen(out);
        if done(&s) {
            return s;
        }
        assert!(
            start.elapsed() < DEADLINE,
            "{what}: the subscriber saw {s:#?}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// A start that finds its port taken by another process is made again on a fresh port, and
/// the system's words for a taken port are recognised.
#[test]
fn a_server_whose_port_was_taken_is_started_on_a_fresh_one() {
    let mut other: Option<TcpListener> = None;
    let mut refused = Vec::new();
    let (_server, port) = on_fresh_ports("a test server", |[port]| {
        if other.is_none() {
            // Another process binds the port between its pick and the server's start.
            other = Some(TcpListener::bind(("127.0.0.1", port)).unwrap());
        }
        match TcpListener::bind(("127.0.0.1", port)) {
            Ok(l) => Ok((l, port)),
            Err(e) => {
                refused.push(e.to_string());
                Err(e.to_string())
            }
        }
    });
    let taken = other.unwrap().local_addr().unwrap().port();
    assert_ne!(port, taken);
    assert_eq!(refused.len(), 1, "{refused:?}");
    assert!(port_taken(&refused[0]), "{refused:?}");
}
