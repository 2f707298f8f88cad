//! The notification hook with Apprise (Debian package `apprise`) as docs/integration.md
//! gives it: the `surfscan daemon` binary runs the documented command after a recipe's scan,
//! and Apprise delivers to a `json://` target, a small HTTP receiver written here, whose
//! message must carry the scan id, its ending and its verdict.

use crate::daemon_e2e::{self as e2e};
use std::io::{BufRead as _, BufReader, Read as _, Write as _};
use std::net::TcpListener;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use surfscan::scan::ending::StopStatus;
use surfscan::scan::status::State;

/// A recipe whose limit no turned surface meets: its scan succeeds and does not conform.
const MIRROR: &str = r#"description = "held to a mirror finish"
[plan]
lines = 5
y-step-mm = 0.01
[specification]
limits = ["Ra1 max 0.001"]
"#;

/// Accepts HTTP requests on a loopback port and keeps each body; answers 200.
fn receiver() -> (u16, Arc<Mutex<Vec<String>>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let bodies = Arc::new(Mutex::new(Vec::new()));
    let keep = bodies.clone();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let _ = stream.set_read_timeout(Some(Duration::from_secs(10)));
            let mut reader = BufReader::new(stream.try_clone().unwrap());
            let mut length = 0usize;
            loop {
                let mut line = String::new();
                if reader.read_line(&mut line).unwrap_or(0) == 0 || line == "\r\n" {
                    break;
                }
                if let Some((k, v)) = line.split_once(':') {
                    if k.eq_ignore_ascii_case("content-length") {
                        length = v.trim().parse().unwrap_or(0);
                    }
                }
            }
            let mut body = vec![0; length];
            if reader.read_exact(&mut body).is_ok() {
                keep.lock()
                    .unwrap()
                    .push(String::from_utf8_lossy(&body).into_owned());
            }
            let _ = stream
                .write_all(b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\nConnection: close\r\n\r\n");
        }
    });
    (port, bodies)
}

/// The hook of docs/integration.md, with the Apprise URL of `port`.
fn apprise_hook(config: &Path, recipes: &Path, port: u16) {
    let text = std::fs::read_to_string(config).unwrap();
    let start = text
        .find("[notify]\ncommand = ")
        .expect("the rig has a hook");
    let end = start + text[start..].find('\n').unwrap() + 1;
    let end = end + text[end..].find('\n').unwrap() + 1;
    let script = format!(
        "apprise --title \"surfscan: scan $SURFSCAN_SCAN_ID $SURFSCAN_STATUS\" --body \"${{SURFSCAN_VERDICT_SUMMARY:-$SURFSCAN_REASON}}\" json://127.0.0.1:{port}/"
    );
    let text = format!(
        "{}[notify]\ncommand = [\"/bin/sh\", \"-c\", {script:?}]\n{}\n[jobs]\nrecipes = {:?}\n",
        &text[..start],
        &text[end..],
        recipes.display().to_string()
    );
    std::fs::write(config, text).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn apprise_delivers_the_scan_s_ending_and_verdict_to_a_json_target() {
    assert!(
        Path::new("/usr/bin/apprise").exists() || which_apprise(),
        "apprise is not installed: `bash .ci/run` installs it (apt-get install apprise)"
    );
    let r = e2e::rig().await;
    let recipes = r.dir.path().join("recipes");
    std::fs::create_dir(&recipes).unwrap();
    std::fs::write(recipes.join("mirror.toml"), MIRROR).unwrap();
    let (port, bodies) = receiver();
    apprise_hook(&r.config, &recipes, port);
    let mut d = crate::mqtt_broker::spawn_logged(&r);
    crate::mqtt_broker::wait_socket(&r).await;
    surfscan::control::client::ControlClient::connect(&r.socket)
        .await
        .unwrap()
        .request(&surfscan::control::protocol::Request::Start {
            specimen: "coupon-9".into(),
            operator: String::new(),
            notes: String::new(),
            mode: surfscan::scan::command::StartMode::Auto,
            recipe: Some("mirror".into()),
            y_start_mm: None,
        })
        .await
        .unwrap();
    let ended = e2e::wait_status(&r, "scan ended", |s| {
        s.state == State::Idle && s.last_stop.is_some()
    })
    .await;
    let stop = ended.last_stop.unwrap();
    assert_eq!(stop.status, StopStatus::Success, "{}", stop.reason);
    let start = std::time::Instant::now();
    let message = loop {
        let found = bodies
            .lock()
            .unwrap()
            .iter()
            .map(|b| serde_json::from_str::<serde_json::Value>(b).unwrap())
            .find(|m| {
                m["title"]
                    .as_str()
                    .is_some_and(|t| t.contains(&stop.scan_id) && t.contains("success"))
            });
        if let Some(m) = found {
            break m;
        }
        assert!(
            start.elapsed() < e2e::DEADLINE,
            "no Apprise message for the scan's success; received {:?}; daemon log: {}",
            bodies.lock().unwrap(),
            std::fs::read_to_string(r.dir.path().join("daemon.log")).unwrap_or_default()
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    let body = message["message"].as_str().unwrap();
    assert!(
        body.contains("does not conform") && body.contains("Ra1 max rule"),
        "{message}"
    );
    e2e::sigterm(&d);
    e2e::wait_exit(&mut d);
}

fn which_apprise() -> bool {
    std::process::Command::new("sh")
        .args(["-c", "command -v apprise"])
        .output()
        .is_ok_and(|o| o.status.success())
}
