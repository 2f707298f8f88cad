//! The station's page's HTTP API over real TCP (and TLS), against a fake scan runner that
//! answers commands and publishes status the way the real runner does: authentication on
//! everything but `/healthz`, the socket's requests mirrored, CSRF refusals, bounded and
//! timed-out connections, the scans' files.

use crate::common::control_channels;
use crate::common::http::{exchange, request, Events, Reply};
use serde_json::{json, Value};
use std::net::SocketAddr;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use surfscan::control::protocol::Message;
use surfscan::scan::command::{OperatorCommand, OperatorRequest, Peer};
use surfscan::scan::status::{State, Status};
use surfscan::web::settings::WebSettings;
use surfscan::web::{self, WebError, WebHandle};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};

const ALICE: &str = "alice-token-0123456789abcdef";
const VIC: &str = "vic-token-fedcba9876543210";

/// What the fake runner was sent.
#[derive(Default)]
struct Seen {
    commands: Vec<OperatorCommand>,
    peers: Vec<Peer>,
}

struct Station {
    dir: tempfile::TempDir,
    page: Option<WebHandle>,
    status: watch::Sender<Status>,
    seen: Arc<Mutex<Seen>>,
}

impl Station {
    fn addr(&self) -> SocketAddr {
        self.page.as_ref().unwrap().addr()
    }

    fn commands(&self) -> Vec<OperatorCommand> {
        self.seen.lock().unwrap().commands.clone()
    }

    async fn stop(mut self) {
        let page = self.page.take().unwrap();
        tokio::task::spawn_blocking(move || page.stop())
            .await
            .unwrap();
    }
}

fn scanning() -> Status {
    let mut s = Status::idle();
    s.state = State::Scanning;
    s.scan_id = Some("G-0142".into());
    s.lines_done = 11;
    s.lines_total = 31;
    s.current_line = Some(12);
    s
}

fn write_tokens(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("web-tokens");
    std::fs::write(&path, format!("alice {ALICE}\nvic {VIC} view\n")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
    path
}

fn settings(dir: &Path, extra: &str) -> WebSettings {
    let text = format!(
        "listen = \"127.0.0.1:0\"\ntoken-file = {:?}\n{extra}",
        write_tokens(dir).display().to_string()
    );
    toml::from_str(&text).unwrap()
}

/// A page served for a fake runner that pauses only a scanning scan and accepts the rest.
async fn station_with(extra: &str) -> Station {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("scans")).unwrap();
    let (status_tx, status_rx) = watch::channel(scanning());
    let (cmd_tx, mut cmd_rx) = mpsc::channel::<OperatorRequest>(4);
    let seen = Arc::new(Mutex::new(Seen::default()));
    let log = seen.clone();
    let publisher = status_tx.clone();
    tokio::spawn(async move {
        while let Some(req) = cmd_rx.recv().await {
            {
                let mut l = log.lock().unwrap();
                l.commands.push(req.command.clone());
                l.peers.push(req.peer.clone());
            }
            let state = publisher.borrow().state;
            let answer = match (&req.command, state) {
                (OperatorCommand::Pause, State::Scanning) => {
                    publisher.send_modify(|s| s.state = State::Pausing);
                    Ok("pauses once the current line is on disk".to_owned())
                }
                (OperatorCommand::Pause, _) => Err("no scan is scanning; nothing to pause".into()),
                (OperatorCommand::Start { specimen, .. }, _) => Ok(format!("starting {specimen}")),
                _ => Ok("done".into()),
            };
            let _ = req.reply.send(answer);
        }
    });
    let channels = control_channels(status_rx, cmd_tx);
    let s = settings(dir.path(), extra);
    let page = web::start(&s, channels, dir.path().join("scans")).unwrap();
    Station {
        dir,
        page: Some(page),
        status: status_tx,
        seen,
    }
}

async fn station() -> Station {
    station_with("").await
}

fn bearer(token: &str) -> String {
    format!("Bearer {token}")
}

async fn get(st: &Station, path: &str, token: &str) -> Reply {
    request(
        st.addr(),
        "GET",
        path,
        &[("authorization", &bearer(token))],
        "",
    )
    .await
}

async fn post(st: &Station, path: &str, token: &str, body: &str) -> Reply {
    request(
        st.addr(),
        "POST",
        path,
        &[("authorization", &bearer(token))],
        body,
    )
    .await
}

#[tokio::test]
async fn only_healthz_answers_without_a_token() {
    let st = station().await;
    let h = request(st.addr(), "GET", "/healthz", &[], "").await;
    assert_eq!((h.status, h.body.as_str()), (200, "ok\n"));
    for (method, path) in [
        ("GET", "/api/status"),
        ("GET", "/api/session"),
        ("GET", "/api/live"),
        ("GET", "/api/watch"),
        ("GET", "/api/scans"),
        ("GET", "/scans/G-0142/report.html"),
        ("POST", "/api/pause"),
        ("POST", "/api/abort"),
        ("POST", "/logout"),
    ] {
        let r = request(st.addr(), method, path, &[], "").await;
        assert_eq!(r.status, 401, "{method} {path}: {r:?}");
        assert_eq!(
            r.header("www-authenticate"),
            Some("Bearer realm=\"surfscan\"")
        );
        assert!(
            r.json()["message"]
                .as_str()
                .unwrap()
                .contains("not signed in"),
            "{r:?}"
        );
        // A wrong token, a wrong scheme, a forged cookie: refused just the same.
        for h in [
            ("authorization", "Bearer not-a-token-of-the-file".to_owned()),
            ("authorization", format!("Basic {ALICE}")),
            (
                "cookie",
                format!(
                    "surfscan_session=alice:99999999999:{}:{}",
                    "0".repeat(32),
                    "0".repeat(64)
                ),
            ),
        ] {
            let r = request(st.addr(), method, path, &[(h.0, &h.1)], "").await;
            assert_eq!(r.status, 401, "{method} {path} with {}: {r:?}", h.0);
        }
    }
    // No command reached the runner.
    assert!(st.commands().is_empty());
    // The page itself holds no station data and loads with its strict policy.
    let p = request(st.addr(), "GET", "/", &[], "").await;
    assert_eq!(p.status, 200);
    assert!(!p.body.contains("G-0142"));
    assert!(p
        .header("content-security-policy")
        .unwrap()
        .contains("script-src 'self'"));
    st.stop().await;
}

#[tokio::test]
async fn the_api_mirrors_the_control_socket() {
    let st = station().await;
    // GET /api/status is the socket's status message, as `surfscan status --json` prints it.
    let r = get(&st, "/api/status", ALICE).await;
    assert_eq!(r.status, 200);
    let socket_form = serde_json::to_value(Message::Status(Box::new(scanning()))).unwrap();
    assert_eq!(r.json(), socket_form);
    assert_eq!(r.header("cache-control"), Some("no-store"));

    // A command: the socket's ack, carried out for alice, recorded with her name and address.
    let r = post(&st, "/api/pause", ALICE, "").await;
    assert_eq!(r.status, 200, "{r:?}");
    assert_eq!(
        r.json(),
        json!({"class": "ack", "command": "pause", "detail": "pauses once the current line is on disk"})
    );
    let peer = st.seen.lock().unwrap().peers[0].clone();
    let web = peer.web.expect("a page's command names its user");
    assert_eq!(web.user, "alice");
    assert!(web.address.starts_with("127.0.0.1:"), "{}", web.address);
    assert_eq!(
        peer.pid,
        Some(std::process::id()),
        "carried out by the daemon's process"
    );

    // The runner's refusal: 409 with its words.
    let r = post(&st, "/api/pause", ALICE, "{}").await;
    assert_eq!(r.status, 409);
    assert_eq!(r.json()["message"], "no scan is scanning; nothing to pause");

    // A start with members, as the socket's.
    let r = post(
        &st,
        "/api/start",
        ALICE,
        r#"{"specimen":"B12","mode":"new"}"#,
    )
    .await;
    assert_eq!(
        (r.status, r.json()["detail"].clone()),
        (200, json!("starting B12"))
    );
    assert!(matches!(
        st.commands().last(),
        Some(OperatorCommand::Start { specimen, mode: surfscan::scan::command::StartMode::New, .. }) if specimen == "B12"
    ));
    let before = st.commands().len();

    // Bad requests: named, 400, nothing carried out.
    for (path, body, says) in [
        ("/api/pause", r#"{"force":true}"#, "unknown field \"force\""),
        (
            "/api/start",
            r#"{"specimen":"B","specimen":"C"}"#,
            "\"specimen\" more than once",
        ),
        (
            "/api/status",
            r#"{"class":"abort"}"#,
            "\"class\" more than once",
        ),
        ("/api/bogus", "", "unknown request class \"bogus\""),
        ("/api/start", r#"{"specimen":7}"#, "invalid request"),
        ("/api/start", "not json", "must be a JSON object"),
        ("/api/Pause", "", "is not a request class"),
    ] {
        let r = post(&st, path, ALICE, body).await;
        assert_eq!(r.status, 400, "{path} {body}: {r:?}");
        let m = r.json()["message"].as_str().unwrap().to_owned();
        assert!(m.contains(says), "{path} {body}: {m}");
    }
    // A body beyond the limit is refused before it is read whole.
    let big = format!("{{\"notes\":\"{}\"}}", "x".repeat(100 * 1024));
    assert_eq!(post(&st, "/api/start", ALICE, &big).await.status, 413);
    // A command as GET changes nothing.
    let r = get(&st, "/api/abort", ALICE).await;
    assert_eq!(r.status, 405);
    assert!(r.json()["message"]
        .as_str()
        .unwrap()
        .contains("POST /api/abort"));
    // A user who may only look sees, and cannot command.
    assert_eq!(get(&st, "/api/status", VIC).await.status, 200);
    let r = post(&st, "/api/abort", VIC, "").await;
    assert_eq!(r.status, 403);
    assert!(r.json()["message"]
        .as_str()
        .unwrap()
        .contains("vic may only look"));
    assert_eq!(st.commands().len(), before, "{:?}", st.commands());

    // The socket's watch, as a stream of status messages.
    let mut w = Events::open(st.addr(), "/api/watch", &[("authorization", &bearer(VIC))]).await;
    assert!(w.head.contains("text/event-stream"), "{}", w.head);
    let first: Value = serde_json::from_str(&w.next_named("status").await).unwrap();
    assert_eq!(first["class"], "status");
    st.status.send_modify(|s| s.lines_done = 12);
    let next: Value = serde_json::from_str(&w.next_named("status").await).unwrap();
    assert_eq!(next["lines_done"], 12);
    st.stop().await;
}

/// Signs in with `token`; the cookie and the CSRF token.
async fn sign_in(st: &Station, token: &str) -> (String, String) {
    let origin = format!("http://{}", st.addr());
    let host = st.addr().to_string();
    let r = request(
        st.addr(),
        "POST",
        "/login",
        &[
            ("host", &host),
            ("origin", &origin),
            ("sec-fetch-site", "same-origin"),
        ],
        &json!({"token": token}).to_string(),
    )
    .await;
    assert_eq!(r.status, 200, "{r:?}");
    let set = r.header("set-cookie").unwrap().to_owned();
    assert!(
        set.contains("HttpOnly") && set.contains("SameSite=Strict") && set.contains("Path=/"),
        "{set}"
    );
    assert!(!set.contains(token) && !r.body.contains(token));
    let cookie = set.split(';').next().unwrap().to_owned();
    (cookie, r.json()["csrf"].as_str().unwrap().to_owned())
}

#[tokio::test]
async fn a_session_commands_only_with_its_csrf_token_from_its_own_origin() {
    let st = station().await;
    let (cookie, csrf) = sign_in(&st, ALICE).await;
    let host = st.addr().to_string();
    let own = format!("http://{host}");
    let with = |extra: Vec<(&'static str, String)>| {
        let mut h = vec![("cookie", cookie.clone()), ("host", host.clone())];
        h.extend(extra);
        h
    };
    let send = |h: Vec<(&'static str, String)>, method: &'static str, path: &'static str| {
        let addr = st.addr();
        async move {
            let hs: Vec<(&str, &str)> = h.iter().map(|(k, v)| (*k, v.as_str())).collect();
            request(addr, method, path, &hs, "").await
        }
    };
    // The session reads, and says who it is and its CSRF token.
    let r = send(with(vec![]), "GET", "/api/session").await;
    assert_eq!(
        (
            r.json()["user"].clone(),
            r.json()["role"].clone(),
            r.json()["csrf"].clone()
        ),
        (json!("alice"), json!("operate"), json!(csrf))
    );
    assert_eq!(send(with(vec![]), "GET", "/api/status").await.status, 200);
    // Forged: what another site's page could send with the browser's cookie.
    let forged = [
        vec![],
        vec![("origin", "http://evil.example".to_owned())],
        vec![("x-csrf-token", "0".repeat(64))],
        vec![
            ("x-csrf-token", csrf.clone()),
            ("origin", "http://127.0.0.1:1".to_owned()),
        ],
        vec![
            ("x-csrf-token", csrf.clone()),
            ("sec-fetch-site", "same-site".to_owned()),
        ],
        vec![
            ("x-csrf-token", csrf.clone()),
            ("sec-fetch-site", "cross-site".to_owned()),
        ],
    ];
    for f in forged {
        let r = send(with(f.clone()), "POST", "/api/pause").await;
        assert_eq!(r.status, 403, "{f:?}: {r:?}");
        assert!(r.json()["message"]
            .as_str()
            .unwrap()
            .contains("nothing was carried out"));
    }
    assert!(st.commands().is_empty(), "{:?}", st.commands());
    // From its own page: carried out.
    let r = send(
        with(vec![
            ("x-csrf-token", csrf.clone()),
            ("origin", own.clone()),
            ("sec-fetch-site", "same-origin".to_owned()),
        ]),
        "POST",
        "/api/pause",
    )
    .await;
    assert_eq!(r.status, 200, "{r:?}");
    assert_eq!(st.commands(), vec![OperatorCommand::Pause]);
    // Sign-in from another origin is refused too.
    let r = request(
        st.addr(),
        "POST",
        "/login",
        &[("host", &host), ("origin", "http://evil.example")],
        &json!({"token": ALICE}).to_string(),
    )
    .await;
    assert_eq!(r.status, 403);
    // A wrong token: 401.
    let r = request(
        st.addr(),
        "POST",
        "/login",
        &[],
        r#"{"token":"nobody-knows-this-one"}"#,
    )
    .await;
    assert_eq!(r.status, 401);
    // Signed out: the cookie is refused from then on.
    let r = send(
        with(vec![("x-csrf-token", csrf.clone())]),
        "POST",
        "/logout",
    )
    .await;
    assert_eq!(r.status, 200);
    assert!(r.header("set-cookie").unwrap().contains("Max-Age=0"));
    assert_eq!(send(with(vec![]), "GET", "/api/status").await.status, 401);
    st.stop().await;
}

#[tokio::test]
async fn the_scans_and_their_files_are_listed_and_nothing_else_is_reachable() {
    let st = station().await;
    let out = st.dir.path().join("scans");
    // A scan directory as the scan writes it, as far as the history reads it.
    let scan = out.join("20261202T032241Z-coupon-a-17");
    std::fs::create_dir_all(scan.join("lines")).unwrap();
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/scan-e46f88d/20261202T032241Z-coupon-a-17/journal.jsonl"),
        scan.join("journal.jsonl"),
    )
    .unwrap();
    std::fs::write(scan.join("report.html"), "<h1>report</h1>").unwrap();
    std::fs::write(scan.join("surface.igs"), "IGES").unwrap();
    std::fs::write(scan.join(".report.html.tmp"), "partial").unwrap();
    std::fs::write(st.dir.path().join("secret"), "no").unwrap();

    let r = get(&st, "/api/scans", VIC).await;
    assert_eq!(r.status, 200, "{r:?}");
    let h = r.json();
    assert_eq!(h["total"], 1, "{h}");
    let s = &h["scans"][0];
    assert_eq!(s["scan_id"], "20261202T032241Z-coupon-a-17");
    let files: Vec<&str> = s["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["name"].as_str().unwrap())
        .collect();
    assert_eq!(files, ["journal.jsonl", "report.html", "surface.igs"]);

    let r = get(&st, "/scans/20261202T032241Z-coupon-a-17/report.html", VIC).await;
    assert_eq!((r.status, r.body.as_str()), (200, "<h1>report</h1>"));
    assert_eq!(r.header("content-type"), Some("text/html; charset=utf-8"));
    assert!(r
        .header("content-security-policy")
        .unwrap()
        .starts_with("sandbox"));
    let r = get(&st, "/scans/20261202T032241Z-coupon-a-17/surface.igs", VIC).await;
    assert_eq!(r.status, 200);
    assert_eq!(
        r.header("content-disposition"),
        Some("attachment; filename=\"surface.igs\"")
    );
    for path in [
        "/scans/20261202T032241Z-coupon-a-17/.report.html.tmp",
        "/scans/20261202T032241Z-coupon-a-17/..%2F..%2Fsecret",
        "/scans/..%2F/secret",
        "/scans/20261202T032241Z-coupon-a-17/lines",
        "/scans/../secret",
        "/scans/nope/report.html",
    ] {
        let r = get(&st, path, VIC).await;
        assert!(r.status == 404, "{path}: {r:?}");
        assert!(!r.body.contains("no\n") && r.body != "no", "{path}");
    }
    st.stop().await;
}

#[tokio::test]
async fn idle_and_dripping_connections_are_closed_and_the_bound_is_kept() {
    let st = station_with("max-connections = 8").await;
    let addr = st.addr();
    // Six connections that say nothing and one that drips its request a byte a second.
    let mut idle = Vec::new();
    for _ in 0..6 {
        idle.push(TcpStream::connect(addr).await.unwrap());
    }
    let mut drip = TcpStream::connect(addr).await.unwrap();
    let dripper = tokio::spawn(async move {
        let start = Instant::now();
        for b in b"GET /api/status HTTP/1.1\r\nhost: x\r\n".iter().cycle() {
            if drip.write_all(&[*b]).await.is_err() {
                return start.elapsed();
            }
            tokio::time::sleep(Duration::from_millis(500)).await;
            if start.elapsed() > Duration::from_secs(40) {
                break;
            }
        }
        start.elapsed()
    });
    tokio::time::sleep(Duration::from_millis(200)).await;
    // The eighth gets through; a ninth is told the page is busy, at once.
    let r = get(&st, "/api/status", ALICE).await;
    assert_eq!(r.status, 200);
    let extra = TcpStream::connect(addr).await.unwrap();
    let held = TcpStream::connect(addr).await.unwrap();
    let busy = exchange(
        held,
        "GET",
        "/api/status",
        &[("authorization", &bearer(ALICE))],
        "",
    )
    .await;
    assert_eq!(busy.status, 503, "{busy:?}");
    assert!(busy.json()["message"]
        .as_str()
        .unwrap()
        .contains("at most 8 connections"));
    drop(extra);
    // The silent ones are closed by the server within the header deadline (plus slack).
    let start = Instant::now();
    for mut c in idle {
        let mut b = [0u8; 64];
        let n = tokio::time::timeout(Duration::from_secs(20), c.read(&mut b))
            .await
            .expect("the server closes a silent connection")
            .unwrap_or(0);
        let _ = n;
    }
    assert!(start.elapsed() <= web::server::HEADER_TIMEOUT + Duration::from_secs(3));
    // The dripping one too: a request must arrive whole within the deadline.
    let dripped = tokio::time::timeout(Duration::from_secs(30), dripper)
        .await
        .unwrap()
        .unwrap();
    assert!(dripped < Duration::from_secs(25), "dripped for {dripped:?}");
    // And the page answers as before.
    assert_eq!(get(&st, "/api/status", ALICE).await.status, 200);
    st.stop().await;
}

#[tokio::test]
async fn over_tls_the_api_answers_and_the_cookie_is_secure() {
    let dir = tempfile::tempdir().unwrap();
    let cert = rcgen::generate_simple_self_signed(vec!["localhost".to_owned()]).unwrap();
    let (cert_pem, key_pem) = (cert.cert.pem(), cert.signing_key.serialize_pem());
    std::fs::write(dir.path().join("cert.pem"), &cert_pem).unwrap();
    std::fs::write(dir.path().join("key.pem"), &key_pem).unwrap();
    let st = station_with(&format!(
        "tls-cert = {:?}\ntls-key = {:?}",
        dir.path().join("cert.pem").display().to_string(),
        dir.path().join("key.pem").display().to_string()
    ))
    .await;
    assert!(st.page.as_ref().unwrap().url().starts_with("https://"));
    use tokio_rustls::rustls;
    let mut roots = rustls::RootCertStore::empty();
    roots.add(cert.cert.der().clone()).unwrap();
    #[allow(deprecated)]
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(Arc::new(config));
    let addr = st.addr();
    let tls = |c: tokio_rustls::TlsConnector| async move {
        let tcp = TcpStream::connect(addr).await.unwrap();
        let name = rustls::pki_types::ServerName::try_from("localhost").unwrap();
        c.connect(name, tcp).await.unwrap()
    };
    let r = exchange(tls(connector.clone()).await, "GET", "/healthz", &[], "").await;
    assert_eq!(r.status, 200);
    let r = exchange(
        tls(connector.clone()).await,
        "GET",
        "/api/status",
        &[("authorization", &bearer(ALICE))],
        "",
    )
    .await;
    assert_eq!(r.json()["state"], "scanning");
    let r = exchange(
        tls(connector.clone()).await,
        "POST",
        "/login",
        &[],
        &json!({"token": ALICE}).to_string(),
    )
    .await;
    assert!(
        r.header("set-cookie").unwrap().ends_with("; Secure"),
        "{r:?}"
    );
    // Plain HTTP to the HTTPS port gets no answer.
    let mut plain = TcpStream::connect(st.addr()).await.unwrap();
    plain
        .write_all(b"GET /healthz HTTP/1.1\r\nhost: x\r\n\r\n")
        .await
        .unwrap();
    let mut buf = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(15), plain.read_to_end(&mut buf)).await;
    assert!(!String::from_utf8_lossy(&buf).contains("ok"), "{buf:?}");
    st.stop().await;
}

#[tokio::test]
async fn a_token_file_others_can_read_a_bad_certificate_or_a_taken_port_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let (status_tx, status_rx) = watch::channel(Status::idle());
    let (cmd_tx, _cmd_rx) = mpsc::channel::<OperatorRequest>(1);
    let channels = || control_channels(status_rx.clone(), cmd_tx.clone());
    let mut s = settings(dir.path(), "");
    std::fs::set_permissions(&s.token_file, std::fs::Permissions::from_mode(0o644)).unwrap();
    let e = web::start(&s, channels(), dir.path().into()).err().unwrap();
    assert!(
        matches!(&e, WebError::Config(m) if m.contains("readable by every user")),
        "{e}"
    );
    std::fs::set_permissions(&s.token_file, std::fs::Permissions::from_mode(0o600)).unwrap();
    std::fs::write(dir.path().join("cert.pem"), "not a certificate").unwrap();
    s.tls_cert = Some(dir.path().join("cert.pem"));
    s.tls_key = Some(dir.path().join("cert.pem"));
    let e = web::start(&s, channels(), dir.path().into()).err().unwrap();
    assert!(
        matches!(&e, WebError::Config(m) if m.contains("web.tls-cert")),
        "{e}"
    );
    s.tls_cert = None;
    s.tls_key = None;
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    s.listen = taken.local_addr().unwrap().to_string();
    let e = web::start(&s, channels(), dir.path().into()).err().unwrap();
    assert!(
        matches!(&e, WebError::Listen(m) if m.contains("cannot listen on")),
        "{e}"
    );
    drop(status_tx);
}
