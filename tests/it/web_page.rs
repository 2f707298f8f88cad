//! The station's page in headless Chromium against the real `surfscan daemon` and the
//! simulator: sign in, start a scan from the page and watch it to completion (the line
//! counter and the height map advance, the result shows), pause and resume from the page
//! (the journal names the page's user), a request without the session and another site's
//! forged commands refused, a hundred open event streams that never read while
//! the scan runs, and the page saying the daemon is away while it restarts, then carrying on
//! (its updates and its commands) with the restarted daemon;
//! a job queued from the page that waits for its specimen, is marked loaded from the page and
//! runs to its verdict (another job removed, an unknown recipe refused), each command in the
//! queue's log with its user; a page that cannot listen leaves the station scanning.
//!
//! Depends on the daemon rig of `daemon_e2e`, the DevTools driver and the HTTP test client.

use crate::common::append_config;
use crate::common::cdp::{Browser, Tab};
use crate::common::http::{request, Events};
use crate::daemon_e2e::{
    notify_until, records, rig, scan_dir, sigterm, spawn_daemon, spawn_daemon_to, start_scan,
    status, wait_exit, wait_status, Daemon, Rig, LINES,
};
use serde_json::json;
use std::os::unix::fs::PermissionsExt;
use std::time::Duration;
use surfscan::scan::ending::StopStatus;
use surfscan::scan::journal::Record;
use surfscan::scan::status::State;

const ALICE: &str = "alice-page-token-5f0c2a9e77d1";
const WAIT: Duration = Duration::from_secs(90);

/// The page on a loopback port the system picks (a port picked here and let go could be
/// taken by another process before the daemon binds it): [`page_addr`] reads which.
const ANY_PORT: &str = "127.0.0.1:0";

/// Adds `[web]` listening on `listen` to the rig's configuration, alice may operate.
fn with_page(r: &Rig, listen: &str) {
    let tokens = r.dir.path().join("web-tokens");
    std::fs::write(&tokens, format!("alice {ALICE}\n")).unwrap();
    std::fs::set_permissions(&tokens, std::fs::Permissions::from_mode(0o600)).unwrap();
    append_config(
        &r.config,
        &format!(
            "\n[web]\nlisten = \"{listen}\"\ntoken-file = {:?}\n",
            tokens.display().to_string()
        ),
    );
}

/// The daemon with its log in the rig's `daemon.log` (appended to).
fn spawn_logged(r: &Rig) -> Daemon {
    spawn_daemon_to(r, crate::common::appending(&crate::daemon_e2e::log_path(r)))
}

/// The page's address as the daemon's log last named it, once it has.
fn page_addr(r: &Rig) -> std::net::SocketAddr {
    crate::daemon_e2e::logged_address(r, "the station's page is at http://")
}

/// Serves, on another port of the same host, a page that tries to pause the station at
/// `target` with the visitor's cookie: a script's `fetch` and a form posted by itself.
fn forging_site(target: std::net::SocketAddr) -> std::net::SocketAddr {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let page = format!(
        r#"<!doctype html><form id="f" method="POST" action="http://{target}/api/pause" enctype="text/plain"><input name='{{"a":"' value='"}}'></form>
<script>
fetch("http://{target}/api/pause", {{method: "POST", mode: "no-cors", credentials: "include", headers: {{"content-type": "text/plain"}}, body: "{{}}"}})
  .catch(() => null)
  .finally(() => document.getElementById("f").submit());
</script>"#
    );
    std::thread::spawn(move || {
        for stream in listener.incoming().take(8) {
            let Ok(mut s) = stream else { continue };
            let mut buf = [0u8; 4096];
            let _ = std::io::Read::read(&mut s, &mut buf);
            let reply = format!(
                "HTTP/1.1 200 OK\r\ncontent-type: text/html\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{page}",
                page.len()
            );
            let _ = std::io::Write::write_all(&mut s, reply.as_bytes());
        }
    });
    addr
}

/// A recipe held to a mirror finish: the simulated turned surface does not conform. The
/// traces are one sampling length long, so the callout says `Ra1`.
const MIRROR: &str = r#"description = "a coupon held to a mirror finish"
[plan]
lines = 4
y-step-mm = 0.01
[specification]
limits = ["Ra1 max 0.001"]
"#;

/// Adds the recipe directory with `mirror.toml` to the rig's configuration.
fn with_recipes(r: &Rig) {
    let dir = r.dir.path().join("recipes");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("mirror.toml"), MIRROR).unwrap();
    append_config(
        &r.config,
        &format!("\n[jobs]\nrecipes = {:?}\n", dir.display().to_string()),
    );
}

/// Opens the page and signs in as alice; before, the page shows the sign-in form and
/// nothing of the station.
fn sign_in(b: &mut Browser, addr: std::net::SocketAddr) -> Tab {
    let tab = b.open(&format!("http://{addr}/"));
    b.wait_for(
        &tab,
        "the sign-in form",
        &format!("{}.hidden", el("login")),
        WAIT,
        |v| v == &json!(false),
    );
    assert_eq!(b.eval(&tab, &format!("{}.hidden", el("main"))), json!(true));
    b.eval(
        &tab,
        &format!(
            "{}.value = {ALICE:?}; {}.requestSubmit(); true",
            el("token"),
            el("login-form")
        ),
    );
    wait_text(b, &tab, "who", "alice");
    tab
}

/// `document.getElementById(id)` in the page's script.
fn el(id: &str) -> String {
    format!("document.getElementById({id:?})")
}

fn text_of(b: &mut Browser, tab: &Tab, id: &str) -> String {
    b.eval(tab, &format!("{}.textContent", el(id)))
        .as_str()
        .unwrap_or_default()
        .to_owned()
}

fn wait_text(b: &mut Browser, tab: &Tab, id: &str, want: &str) -> String {
    let v = b.wait_for(
        tab,
        &format!("#{id} showing {want:?}"),
        &format!("{}.textContent", el(id)),
        WAIT,
        |v| v.as_str().is_some_and(|s| s.contains(want)),
    );
    v.as_str().unwrap().to_owned()
}

fn click(b: &mut Browser, tab: &Tab, id: &str) {
    let done = b.eval(
        tab,
        &format!(
            "{}.disabled === false && ({}.click(), true)",
            el(id),
            el(id)
        ),
    );
    assert_eq!(done, json!(true), "#{id} is not there or disabled");
}

/// The page's line counter and the map's committed rows.
fn progress(b: &mut Browser, tab: &Tab) -> (u64, u64) {
    let v = b.eval(
        tab,
        &format!(
            "[Number({}.dataset.k || 0), Number({}.dataset.rows || 0)]",
            el("line"),
            el("map")
        ),
    );
    (v[0].as_u64().unwrap_or(0), v[1].as_u64().unwrap_or(0))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_started_paused_and_resumed_from_the_page_is_watched_to_its_result() {
    let r = rig().await;
    with_page(&r, ANY_PORT);
    let mut d = spawn_logged(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    let addr = page_addr(&r);

    let mut b = Browser::launch();
    let tab = sign_in(&mut b, addr);
    wait_text(&mut b, &tab, "state", "idle");
    assert_eq!(
        b.eval(&tab, &format!("{}.dataset.state", el("link"))),
        json!("live")
    );
    // The same request without the session (no cookie, no token) is refused.
    assert_eq!(
        b.eval(
            &tab,
            "fetch('/api/status', {credentials: 'omit'}).then(r => r.status)"
        ),
        json!(401)
    );
    assert_eq!(
        b.eval(&tab, "fetch('/api/status').then(r => r.status)"),
        json!(200)
    );
    // The token is not kept in the page.
    assert_eq!(b.eval(&tab, &format!("{}.value", el("token"))), json!(""));

    // A hundred more pages' streams, opened and never read, for the whole scan.
    let mut streams = Vec::new();
    for _ in 0..100 {
        streams.push(
            Events::open(
                addr,
                "/api/live",
                &[("authorization", &format!("Bearer {ALICE}"))],
            )
            .await,
        );
    }
    assert!(
        streams.iter().all(|s| s.head.contains(" 200 ")),
        "{}",
        streams[0].head
    );

    // Start from the page.
    b.eval(
        &tab,
        &format!(
            "{}.value = 'B-12'; {}.value = 'ana'; {}.requestSubmit(); true",
            el("specimen"),
            el("operator"),
            el("start-form")
        ),
    );
    wait_text(&mut b, &tab, "state", "scanning");
    // The counter and the map advance line by line.
    let mut seen = vec![progress(&mut b, &tab)];
    b.wait_for(
        &tab,
        "two lines on the map",
        &format!("Number({}.dataset.rows)", el("map")),
        WAIT,
        |v| v.as_u64().is_some_and(|n| n >= 2),
    );
    seen.push(progress(&mut b, &tab));
    let caption = text_of(&mut b, &tab, "map-caption");
    assert!(caption.contains(&format!("of {LINES} lines")), "{caption}");

    // Another site's page in the same browser, which holds alice's session cookie: a page on
    // another port of the same host is the same site, so the browser sends the cookie with
    // its requests. Its script's POST and its form's are refused, and nothing pauses.
    let evil = forging_site(addr);
    let forger = b.open(&format!("http://{evil}/"));
    let refused = b.wait_for(
        &forger,
        "the forged form's answer",
        "document.body && document.body.innerText",
        WAIT,
        |v| v.as_str().is_some_and(|t| t.contains("\"class\"")),
    );
    let refused = refused.as_str().unwrap();
    assert!(
        refused.contains("\"class\":\"error\"")
            && refused.contains("pause refused: ")
            && refused.contains("nothing was carried out"),
        "{refused}"
    );
    let st = status(&r).await;
    assert_eq!(
        st.state,
        State::Scanning,
        "a forged command took effect: {st:?}"
    );

    // Pause from the page: effective once the line in hand is on disk.
    click(&mut b, &tab, "pause");
    wait_text(&mut b, &tab, "state", "paused");
    let paused = progress(&mut b, &tab);
    seen.push(paused);
    assert!(text_of(&mut b, &tab, "reply")
        .to_lowercase()
        .contains("paus"));
    assert_eq!(
        b.eval(&tab, &format!("{}.disabled", el("resume"))),
        json!(false)
    );
    // Resume from the page.
    click(&mut b, &tab, "resume");
    b.wait_for(
        &tab,
        "a line after the resume",
        &format!("Number({}.dataset.rows)", el("map")),
        WAIT,
        |v| v.as_u64().is_some_and(|n| n > paused.1),
    );
    seen.push(progress(&mut b, &tab));

    // To its end: idle, the whole map, the result of this scan.
    wait_text(&mut b, &tab, "state", "idle");
    let dir = scan_dir(&r);
    let id = dir.file_name().unwrap().to_string_lossy().into_owned();
    b.wait_for(
        &tab,
        "the result",
        &format!("{}.dataset.scan", el("result")),
        WAIT,
        |v| v.as_str() == Some(id.as_str()),
    );
    let result = text_of(&mut b, &tab, "result");
    assert!(
        result.contains(&format!("{LINES} of {LINES} lines")),
        "{result}"
    );
    assert!(result.contains("(success, "), "{result}");
    // No specification in the daemon's configuration: no verdict, and the page says so.
    assert_eq!(
        b.eval(&tab, "document.getElementById('verdict').dataset.verdict"),
        json!("")
    );
    assert!(
        result.contains("no specification given, no verdict"),
        "{result}"
    );
    let ra: f64 = result
        .split("Ra (mean of the lines) ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no Ra in {result}"));
    assert!(ra > 0.0, "{result}");
    assert_eq!(progress(&mut b, &tab).1, u64::from(LINES));
    // The counter never went back, and moved.
    seen.push(progress(&mut b, &tab));
    assert!(seen.windows(2).all(|w| w[0].1 <= w[1].1), "{seen:?}");
    assert!(seen.first().unwrap().1 < seen.last().unwrap().1, "{seen:?}");

    // The history lists the scan with a link to its report.
    b.wait_for(
        &tab,
        "the history's report link",
        &format!(
            "Array.from({}.querySelectorAll('a')).map(a => a.getAttribute('href')).join(' ')",
            el("history")
        ),
        WAIT,
        |v| {
            v.as_str()
                .is_some_and(|s| s.contains(&format!("/scans/{id}/report.html")))
        },
    );

    // The journal names alice for the pause and the resume, with where she was.
    let recs = records(&dir);
    let by_page: Vec<(String, String)> = recs
        .iter()
        .filter_map(|r| match r {
            Record::Interruption(i) => {
                let w = i.peer.as_ref()?.web.as_ref()?;
                Some((i.reason.clone(), w.user.clone()))
            }
            _ => None,
        })
        .collect();
    // Exactly one pause: the page's own, none of the forged ones.
    let pauses: Vec<_> = by_page
        .iter()
        .filter(|(why, _)| why.starts_with("pause requested by"))
        .collect();
    assert_eq!(pauses.len(), 1, "{by_page:?}");
    assert!(
        pauses[0]
            .0
            .starts_with("pause requested by web user alice from 127.0.0.1:")
            && pauses[0].1 == "alice",
        "{by_page:?}"
    );
    assert!(
        by_page
            .iter()
            .any(|(why, who)| why.starts_with("resumed by the operator") && who == "alice"),
        "{by_page:?}"
    );
    let start = match &recs[0] {
        Record::Start(s) => s,
        other => panic!("{other:?}"),
    };
    assert_eq!(
        start
            .peer
            .as_ref()
            .and_then(|p| p.web.as_ref())
            .map(|w| w.user.as_str()),
        Some("alice")
    );
    // The hundred streams left unread through the scan are still open and, read now,
    // bring the scan's end (each stream sends the latest status, not a backlog).
    for s in &mut streams {
        loop {
            let data = s.next_named("status").await;
            if data.contains("\"success\"") {
                break;
            }
        }
    }
    drop(streams);

    // The daemon restarts: the page says it is away, then carries on signed in.
    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    b.wait_for(
        &tab,
        "the page saying the daemon is away",
        &format!("{}.dataset.state", el("link")),
        WAIT,
        |v| v == &json!("down"),
    );
    assert!(text_of(&mut b, &tab, "link").contains("not reachable"));
    // The page carries on at its address: the restarted daemon binds the same port.
    crate::common::edit_file(
        &r.config,
        &format!("listen = \"{ANY_PORT}\""),
        &format!("listen = \"{addr}\""),
    );
    let mut d = spawn_logged(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    assert_eq!(page_addr(&r), addr);
    b.wait_for(
        &tab,
        "the page live again",
        &format!("{}.dataset.state", el("link")),
        WAIT,
        |v| v == &json!("live"),
    );
    assert_eq!(
        b.eval(&tab, &format!("{}.hidden", el("main"))),
        json!(false)
    );
    wait_text(&mut b, &tab, "state", "idle");
    // Without a token or session nothing but /healthz answers on the restarted daemon.
    assert_eq!(
        request(addr, "GET", "/api/status", &[], "").await.status,
        401
    );
    let h = request(addr, "GET", "/healthz", &[], "").await;
    assert_eq!((h.status, h.body.as_str()), (200, "ok\n"));
    // Its updates and commands carry on with the restarted daemon: a scan started now shows
    // line by line, and the page pauses and aborts it.
    start_scan(&r, "B-14").await;
    wait_text(&mut b, &tab, "state", "scanning");
    b.wait_for(
        &tab,
        "the new scan's first line on the map",
        &format!(
            "{}.dataset.scan !== {id:?} && Number({}.dataset.rows)",
            el("map"),
            el("map")
        ),
        WAIT,
        |v| v.as_u64().is_some_and(|n| n >= 1),
    );
    click(&mut b, &tab, "pause");
    wait_text(&mut b, &tab, "state", "paused");
    click(&mut b, &tab, "abort");
    click(&mut b, &tab, "abort-yes");
    wait_text(&mut b, &tab, "state", "idle");
    let last = status(&r).await.last_stop.expect("the aborted scan's stop");
    assert_eq!(last.status, StopStatus::Abort, "{last:?}");
    assert_ne!(last.scan_id, id);

    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    r.sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_that_cannot_listen_is_named_and_the_station_scans_on() {
    let r = rig().await;
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap();
    with_page(&r, &addr.to_string());
    let mut d = spawn_daemon(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    let s = status(&r).await;
    let link = s.links.get("web").expect("the page named among the links");
    assert!(!link.ok, "{link:?}");
    assert!(
        link.message.contains(&format!("cannot listen on {addr}"))
            && link.message.contains("another program may use the port"),
        "{link:?}"
    );
    start_scan(&r, "B-13").await;
    wait_status(&r, "a line on disk without the page", |s| s.lines_done >= 1).await;
    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    r.sim.shutdown().await;
}

/// The script that reads the queue's row of job `id` on the page: its state, its state's
/// text and verdict, and the ids of its buttons (`null` when the row is not there).
fn job_row(id: u64) -> String {
    format!(
        "(() => {{ const tr = document.querySelector('#queue tr[data-job=\"{id}\"]'); \
         if (!tr) return null; const st = tr.querySelector('.job-state'); \
         return {{state: tr.dataset.state, text: st.textContent, verdict: st.dataset.verdict || null, \
         buttons: Array.from(tr.querySelectorAll('button')).map(b => b.id)}}; }})()"
    )
}

fn wait_row(
    b: &mut Browser,
    tab: &Tab,
    id: u64,
    what: &str,
    f: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    b.wait_for(tab, what, &job_row(id), WAIT, f)
}

/// Fills the page's queue form and submits it.
fn queue_from_page(b: &mut Browser, tab: &Tab, recipe: &str, specimen: &str, loading: bool) {
    b.eval(
        tab,
        &format!(
            "{}.value = {recipe:?}; {}.value = {specimen:?}; {}.checked = {loading}; {}.requestSubmit(); true",
            el("queue-recipe"),
            el("queue-specimen"),
            el("queue-loading"),
            el("queue-form")
        ),
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_queued_from_the_page_waits_for_its_specimen_then_runs_to_its_verdict() {
    let r = rig().await;
    with_page(&r, ANY_PORT);
    with_recipes(&r);
    let mut d = spawn_logged(&r);
    notify_until(&r, &mut d, |m| m.contains("READY=1"));
    let addr = page_addr(&r);
    let mut b = Browser::launch();
    let tab = sign_in(&mut b, addr);
    b.wait_for(
        &tab,
        "the queue on the page",
        &format!("{}.hidden", el("queue-card")),
        WAIT,
        |v| v == &json!(false),
    );

    // A recipe the station does not have: refused with its cause, nothing queued.
    queue_from_page(&mut b, &tab, "no-such-recipe", "C-6", false);
    b.wait_for(
        &tab,
        "the refusal of an unknown recipe",
        &format!("{}.dataset.class", el("queue-reply")),
        WAIT,
        |v| v == &json!("refused"),
    );
    let why = text_of(&mut b, &tab, "queue-reply");
    assert!(why.contains("no-such-recipe"), "{why}");

    // Job 1 waits for its specimen; job 2, behind it, is removed from the page.
    queue_from_page(&mut b, &tab, "mirror", "C-7", true);
    let row = wait_row(&mut b, &tab, 1, "job 1 on the page", |v| !v.is_null());
    assert_eq!(row["state"], json!("queued"), "{row}");
    assert!(
        row["text"]
            .as_str()
            .unwrap()
            .contains("waits for its specimen to be loaded"),
        "{row}"
    );
    assert_eq!(row["buttons"], json!(["ready-1", "remove-1"]), "{row}");
    wait_text(&mut b, &tab, "state", "waiting");
    queue_from_page(&mut b, &tab, "mirror", "C-8", false);
    let row = wait_row(&mut b, &tab, 2, "job 2 on the page", |v| !v.is_null());
    assert_eq!(row["buttons"], json!(["remove-2"]), "{row}");
    click(&mut b, &tab, "remove-2");
    wait_row(&mut b, &tab, 2, "job 2 gone from the page", |v| v.is_null());
    wait_text(&mut b, &tab, "queue-reply", "removed job 2");
    // Still waiting: nothing started without the specimen.
    assert_eq!(status(&r).await.state, State::Waiting);
    assert!(std::fs::read_dir(r.out())
        .unwrap()
        .filter_map(Result::ok)
        .all(|e| !e.path().join("journal.jsonl").exists()));

    // Specimen loaded, from the page: the job runs, and the live view names it.
    click(&mut b, &tab, "ready-1");
    wait_text(&mut b, &tab, "job", "job 1: recipe mirror, specimen C-7");
    wait_row(&mut b, &tab, 1, "job 1 running", |v| {
        v["state"] == json!("running")
    });

    // Its scan ends: the verdict against the recipe in the live view, the queue and the
    // history.
    let v = b.wait_for(
        &tab,
        "the verdict in the live view",
        "document.getElementById('verdict') && document.getElementById('verdict').dataset.verdict",
        WAIT,
        |v| v.as_str().is_some_and(|s| !s.is_empty()),
    );
    assert_eq!(v, json!("does not conform"));
    let result = text_of(&mut b, &tab, "result");
    assert!(
        result.contains("recipe mirror, job 1") && result.contains("4 of 4 lines"),
        "{result}"
    );
    // The summary names the limit the surface fails.
    assert!(result.contains("Ra1"), "{result}");
    let row = wait_row(&mut b, &tab, 1, "job 1 finished", |v| {
        v["state"] == json!("finished")
    });
    assert_eq!(row["verdict"], json!("does not conform"), "{row}");
    assert!(
        row["text"]
            .as_str()
            .unwrap()
            .starts_with("success, does not conform"),
        "{row}"
    );
    assert_eq!(row["buttons"], json!([]), "{row}");
    let history = b.wait_for(
        &tab,
        "the verdict in the history",
        "Array.from(document.querySelectorAll('#history tbody tr')).map(tr => tr.innerText).join('\\n')",
        WAIT,
        |v| v.as_str().is_some_and(|s| s.contains("does not conform")),
    );
    assert!(history.as_str().unwrap().contains("mirror"), "{history}");

    // The queue's log names alice, with where she was, for each of her commands.
    let log = crate::common::complete_lines(&r.out().join("queue-log.jsonl"));
    let by_alice: Vec<(String, Vec<u64>)> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|e| e["peer"]["web"]["user"] == json!("alice"))
        .map(|e| {
            let from = e["peer"]["web"]["address"].as_str().unwrap_or_default();
            assert!(from.starts_with("127.0.0.1:"), "{e}");
            (
                e["command"].as_str().unwrap().to_owned(),
                serde_json::from_value(e["jobs"].clone()).unwrap(),
            )
        })
        .collect();
    assert_eq!(
        by_alice,
        vec![
            ("add".to_owned(), vec![1]),
            ("add".to_owned(), vec![2]),
            ("remove".to_owned(), vec![2]),
            ("ready".to_owned(), vec![1]),
        ],
        "{log}"
    );
    // The scan is job 1's, of the recipe.
    let dir = scan_dir(&r);
    match &records(&dir)[0] {
        Record::Start(s) => {
            let job = s.job.as_ref().expect("the start names the job");
            assert_eq!((job.id, job.recipe.as_str()), (Some(1), "mirror"));
        }
        other => panic!("{other:?}"),
    }

    // A scan started from the page by recipe and specimen, outside the queue, then paused
    // (so that it cannot end by itself meanwhile) and aborted from the page after its
    // confirmation.
    b.eval(
        &tab,
        &format!(
            "{}.value = 'mirror'; {}.value = 'C-9'; {}.requestSubmit(); true",
            el("start-recipe"),
            el("specimen"),
            el("start-form")
        ),
    );
    wait_text(&mut b, &tab, "state", "scanning");
    click(&mut b, &tab, "pause");
    wait_text(&mut b, &tab, "state", "paused");
    click(&mut b, &tab, "abort");
    assert_eq!(
        b.eval(&tab, &format!("{}.hidden", el("abort-confirm"))),
        json!(false)
    );
    click(&mut b, &tab, "abort-yes");
    wait_text(&mut b, &tab, "reply", "abort: ");
    wait_text(&mut b, &tab, "state", "idle");
    let mut dirs: Vec<_> = std::fs::read_dir(r.out())
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.join("journal.jsonl").exists())
        .collect();
    dirs.sort();
    assert_eq!(dirs.len(), 2, "{dirs:?}");
    let recs = records(&dirs[1]);
    let Record::Start(start) = &recs[0] else {
        panic!("{:?}", recs[0])
    };
    assert_eq!(start.specimen, "C-9");
    let job = start.job.as_ref().expect("the start names the recipe");
    assert_eq!((job.id, job.recipe.as_str()), (None, "mirror"));
    assert_eq!(
        start
            .peer
            .as_ref()
            .and_then(|p| p.web.as_ref())
            .map(|w| w.user.as_str()),
        Some("alice")
    );
    let stop = recs.iter().rev().find_map(|r| match r {
        Record::Stop(s) => Some(s.status),
        _ => None,
    });
    assert_eq!(stop, Some(StopStatus::Abort), "{recs:?}");

    sigterm(&d);
    assert!(wait_exit(&mut d).success());
    r.sim.shutdown().await;
}
