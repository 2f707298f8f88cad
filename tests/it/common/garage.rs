//! A real S3 server for the archive tests: Garage (`cargo install garage --version 2.5.0
//! --locked`, which `.ci/run` does), started on free loopback ports in a test's directory as
//! a single node (sqlite metadata, `replication_factor = 1`), its layout applied, a bucket
//! and a key made with its own CLI. Objects are read back with `curl --aws-sigv4`, an S3
//! client independent of the code under test.

use super::mosquitto::{on_fresh_ports, port_taken, Killed};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The bucket the tests archive into.
pub const BUCKET: &str = "lab-archive";
/// The region Garage answers for (its configuration's `s3_region`).
pub const REGION: &str = "garage";

/// A Garage server, its files and the station's key.
pub struct Garage {
    /// Its S3 endpoint, `http://127.0.0.1:PORT`.
    pub endpoint: String,
    /// The key id allowed on [`BUCKET`].
    pub key_id: String,
    /// Its secret.
    pub secret: String,
    dir: PathBuf,
    config: PathBuf,
    s3_port: u16,
    process: Option<Killed>,
}

/// The `garage` binary: on PATH or where `cargo install` puts it.
fn binary() -> PathBuf {
    let mut dirs: Vec<PathBuf> = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).collect())
        .unwrap_or_default();
    if let Some(home) = std::env::var_os("CARGO_HOME") {
        dirs.push(Path::new(&home).join("bin"));
    }
    if let Some(home) = std::env::var_os("HOME") {
        dirs.push(Path::new(&home).join(".cargo/bin"));
    }
    dirs.into_iter()
        .map(|d| d.join("garage"))
        .find(|p| p.is_file())
        .unwrap_or_else(|| {
            panic!("garage is not installed: `bash .ci/run` installs it (cargo install garage --version 2.5.0 --locked)")
        })
}

impl Garage {
    /// Writes a single-node configuration below `dir`, starts the server and makes the
    /// bucket and the key.
    pub fn start(dir: &Path) -> Garage {
        let dir = dir.join("garage");
        std::fs::create_dir_all(&dir).unwrap();
        let mut bytes = [0u8; 32];
        ring::rand::SecureRandom::fill(&ring::rand::SystemRandom::new(), &mut bytes).unwrap();
        let secret: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        let config = dir.join("garage.toml");
        // A port another process took first: Garage logs it (and exits, or serves on without
        // its S3 API, whose port then answers with the other process).
        let (mut g, id) = on_fresh_ports("garage", |[rpc_port, s3_port]| {
            let _ = std::fs::remove_file(dir.join("garage.log"));
            std::fs::write(
                &config,
                format!(
                    "metadata_dir = \"{d}/meta\"\ndata_dir = \"{d}/data\"\ndb_engine = \"sqlite\"\nreplication_factor = 1\nrpc_bind_addr = \"127.0.0.1:{rpc_port}\"\nrpc_public_addr = \"127.0.0.1:{rpc_port}\"\nrpc_secret = \"{secret}\"\n\n[s3_api]\ns3_region = \"{REGION}\"\napi_bind_addr = \"127.0.0.1:{s3_port}\"\nroot_domain = \".s3.garage.localhost\"\n",
                    d = dir.display()
                ),
            )
            .unwrap();
            let mut g = Garage {
                endpoint: format!("http://127.0.0.1:{s3_port}"),
                key_id: String::new(),
                secret: String::new(),
                dir: dir.clone(),
                config: config.clone(),
                s3_port,
                process: None,
            };
            match g.launch() {
                Ok(()) => {}
                Err(e) if port_taken(&e) => return Err(e),
                Err(e) => panic!("{e}"),
            }
            // Its node answers once it has started its servers, each bound or logged failed.
            let id = g.cli(&["node", "id", "-q"]);
            match g.log() {
                log if port_taken(&log) => Err(log),
                _ => Ok((g, id)),
            }
        });
        let id = id.trim().split('@').next().unwrap().to_owned();
        g.cli(&["layout", "assign", "-z", "dc1", "-c", "1G", &id]);
        g.cli(&["layout", "apply", "--version", "1"]);
        g.cli(&["bucket", "create", BUCKET]);
        let key = g.cli(&["key", "create", "station"]);
        let field = |name: &str| {
            key.lines()
                .find_map(|l| l.trim().strip_prefix(name))
                .map(|v| v.trim_start_matches(':').trim().to_owned())
                .unwrap_or_else(|| panic!("no {name:?} in `garage key create`: {key}"))
        };
        g.key_id = field("Key ID");
        g.secret = field("Secret key");
        g.cli(&[
            "bucket", "allow", "--read", "--write", BUCKET, "--key", "station",
        ]);
        g
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("garage.log")).unwrap_or_default()
    }

    /// Runs the CLI against the server (the server may still be settling: retried for a
    /// while); its standard output.
    fn cli(&self, args: &[&str]) -> String {
        let start = Instant::now();
        loop {
            let o: Output = Command::new(binary())
                .arg("-c")
                .arg(&self.config)
                .args(args)
                .stdin(Stdio::null())
                .output()
                .unwrap();
            if o.status.success() {
                return String::from_utf8_lossy(&o.stdout).into_owned();
            }
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "garage {args:?} failed: {}{}\nserver log:\n{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr),
                self.log()
            );
            std::thread::sleep(Duration::from_millis(250));
        }
    }

    /// Stops the server (SIGTERM); the S3 port refuses connections afterwards.
    pub fn stop(&mut self) {
        if let Some(mut p) = self.process.take() {
            let pid = nix::unistd::Pid::from_raw(p.0.id() as i32);
            nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
            let start = Instant::now();
            while p.0.try_wait().unwrap().is_none() {
                if start.elapsed() > Duration::from_secs(20) {
                    let _ = p.0.kill();
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        }
    }

    /// Starts the server again on the same ports, with what it stored.
    pub fn restart(&mut self) {
        if let Err(e) = self.launch() {
            panic!("{e}");
        }
    }

    /// Starts the server and waits until its S3 port answers; `Err` with its log (what it
    /// wrote since) when it exits first.
    fn launch(&mut self) -> Result<(), String> {
        assert!(self.process.is_none(), "garage is running");
        let from = std::fs::metadata(self.dir.join("garage.log")).map_or(0, |m| m.len() as usize);
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.dir.join("garage.log"))
            .unwrap();
        let child = Command::new(binary())
            .arg("-c")
            .arg(&self.config)
            .arg("server")
            .env("RUST_LOG", "garage=info")
            .stdin(Stdio::null())
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .unwrap();
        let mut child = Killed(child);
        let start = Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", self.s3_port)).is_err() {
            if let Some(st) = child.0.try_wait().unwrap() {
                let log = self.log();
                return Err(format!(
                    "garage exited ({st}): {}",
                    log.get(from..).unwrap_or(&log)
                ));
            }
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "garage does not listen: {}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        self.process = Some(child);
        Ok(())
    }

    /// GET of `key` in [`BUCKET`] with curl's SigV4: the body, or None for a 404.
    pub fn get(&self, key: &str) -> Option<Vec<u8>> {
        let o = self.curl(&format!("{}/{BUCKET}/{key}", self.endpoint));
        let (code, body) = o;
        match code {
            200 => Some(body),
            404 => None,
            _ => panic!("GET {key}: HTTP {code}: {}", String::from_utf8_lossy(&body)),
        }
    }

    /// Every key of [`BUCKET`] below `prefix` (ListObjectsV2, read with curl), sorted.
    pub fn list(&self, prefix: &str) -> Vec<String> {
        let (code, body) = self.curl(&format!(
            "{}/{BUCKET}?list-type=2&max-keys=1000&prefix={}",
            self.endpoint,
            // SigV4 signs the query percent-encoded, '/' included.
            prefix.replace('/', "%2F")
        ));
        let body = String::from_utf8(body).unwrap();
        assert_eq!(code, 200, "{body}");
        assert!(
            !body.contains("<IsTruncated>true"),
            "more than a page: {body}"
        );
        let mut keys: Vec<String> = body
            .split("<Key>")
            .skip(1)
            .map(|s| s.split("</Key>").next().unwrap().to_owned())
            .collect();
        keys.sort();
        keys
    }

    fn curl(&self, url: &str) -> (u16, Vec<u8>) {
        let out = self.dir.join("curl.body");
        let o = Command::new("curl")
            .args(["--silent", "--show-error", "--max-time", "30"])
            .arg("--aws-sigv4")
            .arg(format!("aws:amz:{REGION}:s3"))
            .arg("--user")
            .arg(format!("{}:{}", self.key_id, self.secret))
            // A GET has an empty body: its SHA-256, which SigV4 signs and Garage requires.
            .arg("--header")
            .arg("x-amz-content-sha256: e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855")
            .arg("--output")
            .arg(&out)
            .args(["--write-out", "%{http_code}"])
            .arg(url)
            .output()
            .expect("curl is not installed: `bash .ci/run` installs it");
        assert!(
            o.status.success(),
            "curl {url}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let code: u16 = String::from_utf8_lossy(&o.stdout).trim().parse().unwrap();
        (code, std::fs::read(&out).unwrap_or_default())
    }
}
