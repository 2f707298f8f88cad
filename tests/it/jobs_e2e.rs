//! End to end: the job queue of the real `surfscan daemon` against the simulator — jobs of a
//! recipe run one after another, each at its own y, a job that needs loading waits for
//! `surfscan ready`, and the queue survives `kill -9` at random moments: every job runs
//! once, in order, and a job that needs loading never starts without `ready`, across
//! restarts.
//!
//! Depends on the `surfscan` binary, the `surfscan_sim` library and the control client.

use crate::common::{demo_config_at, edited};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use surfscan::control::client::ControlClient;
use surfscan::control::protocol::{Message, Request};
use surfscan::jobs::queue::{JobState, Queue};
use surfscan::scan::journal::{read_journal, ResumeState, StopStatus};
use surfscan::scan::status::{State, Status};
use surfscan::specification::Verdict;
use surfscan_sim::grbl::StageShared;
use surfscan_sim::{SimHandle, Simulator};

const SPEED_UP: f64 = 50.0;
const LINES: u32 = 5;
const KILL_MIN_MS: u64 = 300;
const KILL_MAX_MS: u64 = 6_000;
const DEADLINE: Duration = Duration::from_secs(240);

struct Rig {
    dir: tempfile::TempDir,
    _sim: SimHandle,
    config: PathBuf,
    socket: PathBuf,
}

impl Rig {
    fn out(&self) -> PathBuf {
        self.dir.path().join("scans")
    }
}

// The simulated traces are one sampling length long: the callouts say so (`Ra1`), as a
// drawing for such a short surface would; with the default five, the verdict would be not
// decidable (a test of the section itself).
const RECIPE: &str = r#"description = "a coupon of the fixture"
[plan]
lines = 5
y-step-mm = 0.01
[specification]
limits = ["Ra1 50", "Rz1 max 400"]
"#;

/// The fourth coupon is held to a limit no turned surface meets: its scan succeeds and does
/// not conform, and the queue goes on regardless.
const TIGHT: &str = r#"description = "a coupon held to a mirror finish"
[plan]
lines = 5
y-step-mm = 0.01
[specification]
limits = ["Ra1 max 0.001"]
"#;

async fn rig(recipes: &[(&str, &str)]) -> Rig {
    let dir = tempfile::tempdir().unwrap();
    let inst = dir.path().join("sj210");
    let stage = dir.path().join("ystage");
    let sim = crate::common::started(
        Simulator::sped_up_station(&inst, &stage, SPEED_UP, StageShared::new()).unwrap(),
    )
    .await;
    let scans = dir.path().join("scans");
    let socket = dir.path().join("run").join("control.sock");
    let recipes_dir = dir.path().join("recipes");
    std::fs::create_dir_all(&recipes_dir).unwrap();
    for (name, text) in recipes {
        std::fs::write(recipes_dir.join(format!("{name}.toml")), text).unwrap();
    }
    let text = edited(
        &demo_config_at(&inst, &stage, &scans, &socket),
        "lines = 31",
        &format!("lines = {LINES}"),
    );
    let text = format!(
        "{text}\n[fit]\ndegree-v = 3\n[jobs]\nrecipes = {:?}\n[notify]\ncommand = [\"/bin/sh\", \"-c\", \"env | grep ^SURFSCAN_ | sort >> {}; echo >> {}\"]\n",
        recipes_dir.display().to_string(),
        dir.path().join("hook.log").display(),
        dir.path().join("hook.log").display(),
    );
    let config = dir.path().join("station.toml");
    std::fs::write(&config, text).unwrap();
    Rig {
        dir,
        _sim: sim,
        config,
        socket,
    }
}

/// The daemon process; killed if the test fails before it exits.
struct Daemon(Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn spawn_daemon(r: &Rig) -> Daemon {
    Daemon(
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["daemon", "--config"])
            .arg(&r.config)
            .env("SURFSCAN_TEST_LOCK_DIR", r.dir.path())
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(crate::common::appending(&r.dir.path().join("daemon.log")))
            .spawn()
            .unwrap(),
    )
}

/// `kill -9` and wait for it to be gone.
fn kill_9(mut d: Daemon) {
    d.0.kill().unwrap();
    d.0.wait().unwrap();
}

/// One request, answered; `None` while the daemon is not (yet) listening.
async fn ask(r: &Rig, req: &Request) -> Option<Message> {
    let mut c = ControlClient::connect(&r.socket).await.ok()?;
    c.request(req).await.ok().map(|m| m.message)
}

async fn status(r: &Rig) -> Option<Status> {
    match ask(r, &Request::Status).await? {
        Message::Status(s) => Some(*s),
        other => panic!("expected status, got {other:?}"),
    }
}

async fn queue(r: &Rig) -> Option<Queue> {
    match ask(r, &Request::QueueList).await? {
        Message::Queue(q) => Some(*q),
        other => panic!("expected the queue, got {other:?}"),
    }
}

async fn wait_for<T>(r: &Rig, what: &str, mut f: impl FnMut(&Status, &Queue) -> Option<T>) -> T {
    let start = Instant::now();
    loop {
        if let (Some(s), Some(q)) = (status(r).await, queue(r).await) {
            if let Some(v) = f(&s, &q) {
                return v;
            }
            assert!(
                start.elapsed() < DEADLINE,
                "{what}: last status {s:?}, queue {q:?}\n{}",
                daemon_log(r)
            );
        } else {
            assert!(
                start.elapsed() < DEADLINE,
                "{what}: the daemon never answered\n{}",
                daemon_log(r)
            );
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn daemon_log(r: &Rig) -> String {
    let text = std::fs::read_to_string(r.dir.path().join("daemon.log")).unwrap_or_default();
    let tail: Vec<&str> = text.lines().rev().take(40).collect();
    tail.into_iter().rev().collect::<Vec<_>>().join("\n")
}

fn add(recipe: &str, specimen: &str, y: f64, needs_loading: bool) -> Request {
    Request::QueueAdd {
        recipe: recipe.into(),
        specimen: specimen.into(),
        operator: "night shift".into(),
        notes: String::new(),
        y_start_mm: Some(y),
        needs_loading,
    }
}

/// Every scan directory's start record and ending, by start order.
fn scans(out: &Path) -> Vec<(String, ResumeState)> {
    let mut v: Vec<(String, ResumeState)> = std::fs::read_dir(out)
        .unwrap()
        .filter_map(|e| {
            let dir = e.unwrap().path();
            let j = dir.join("journal.jsonl");
            let rec = read_journal(&j).ok()?;
            let st = ResumeState::from_records(&j, &rec.records).ok()?;
            Some((dir.file_name().unwrap().to_string_lossy().into_owned(), st))
        })
        .collect();
    v.sort_by_key(|(_, s)| s.start.sequence);
    v
}

/// A small deterministic generator for the kill moments (the seed is printed, so a failure
/// can be replayed with `SURFSCAN_TEST_SEED`).
struct Moments(u64);

impl Moments {
    fn next_ms(&mut self, lo: u64, hi: u64) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        lo + self.0 % (hi - lo)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_queue_runs_every_job_once_in_order_through_kill_9_at_random_moments() {
    let seed: u64 = std::env::var("SURFSCAN_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_nanos() as u64
                | 1
        });
    eprintln!("kill moments: SURFSCAN_TEST_SEED={seed}");
    let mut moments = Moments(seed);
    let r = rig(&[("coupon", RECIPE), ("tight", TIGHT)]).await;
    let mut d = spawn_daemon(&r);
    // A fixture of four coupons along y; the third is loaded by hand.
    let ys = [-20.0, -18.0, -16.0, -14.0];
    for (k, y) in ys.iter().enumerate() {
        let recipe = if k == 3 { "tight" } else { "coupon" };
        let req = add(recipe, &format!("C-{}", k + 1), *y, k == 2);
        let reply = loop {
            if let Some(m) = ask(&r, &req).await {
                break m;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        };
        assert!(matches!(reply, Message::Ack { .. }), "{reply:?}");
    }
    // Kill at random moments until the third job waits for its specimen.
    let mut kills = 0;
    loop {
        let waiting = status(&r).await.is_some_and(|s| s.state == State::Waiting);
        if waiting {
            break;
        }
        tokio::time::sleep(Duration::from_millis(
            moments.next_ms(KILL_MIN_MS, KILL_MAX_MS),
        ))
        .await;
        if status(&r).await.is_some_and(|s| s.state == State::Waiting) {
            break;
        }
        kill_9(d);
        kills += 1;
        d = spawn_daemon(&r);
        assert!(
            kills < 60,
            "too many restarts without progress\n{}",
            daemon_log(&r)
        );
    }
    let s = wait_for(&r, "job 3 waiting", |s, q| {
        (s.state == State::Waiting && q.pending().next().map(|j| j.id) == Some(3))
            .then(|| s.clone())
    })
    .await;
    assert!(
        s.reason
            .as_deref()
            .unwrap_or("")
            .contains("specimen \"C-3\""),
        "{s:?}"
    );
    // Across a restart it still waits: nothing starts without `ready`.
    kill_9(d);
    d = spawn_daemon(&r);
    let s = wait_for(&r, "waiting again after the restart", |s, _| {
        (s.state == State::Waiting).then(|| s.clone())
    })
    .await;
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(status(&r).await.unwrap().state, State::Waiting, "{s:?}");
    assert_eq!(
        scans(&r.out()).len(),
        2,
        "only the first two jobs have scans before `ready`"
    );
    let ready_at = chrono::Utc::now();
    let reply = ask(&r, &Request::Ready { job: None }).await.unwrap();
    assert!(matches!(reply, Message::Ack { .. }), "{reply:?}");
    // More kills at random moments until every job has finished.
    loop {
        let done = queue(&r)
            .await
            .is_some_and(|q| q.pending().next().is_none());
        if done {
            break;
        }
        tokio::time::sleep(Duration::from_millis(
            moments.next_ms(KILL_MIN_MS, KILL_MAX_MS),
        ))
        .await;
        if queue(&r)
            .await
            .is_some_and(|q| q.pending().next().is_none())
        {
            break;
        }
        kill_9(d);
        kills += 1;
        d = spawn_daemon(&r);
        assert!(
            kills < 120,
            "too many restarts without progress\n{}",
            daemon_log(&r)
        );
    }
    eprintln!("{kills} kill -9");
    let q = queue(&r).await.unwrap();
    // Every job finished once, successfully, in the order it was added.
    let finished: Vec<(u64, String, Option<String>)> = q
        .jobs
        .iter()
        .map(|j| match &j.state {
            JobState::Finished {
                outcome, scan_id, ..
            } => (j.id, outcome.clone(), scan_id.clone()),
            other => panic!("job {} not finished: {other:?}", j.id),
        })
        .collect();
    assert_eq!(
        finished
            .iter()
            .map(|f| (f.0, f.1.as_str()))
            .collect::<Vec<_>>(),
        vec![
            (1, "success"),
            (2, "success"),
            (3, "success"),
            (4, "success")
        ],
        "{q:?}"
    );
    // One scan per job, each complete, naming its job, at its own y, in job order.
    let all = scans(&r.out());
    for (dir, st) in &all {
        let took = st
            .stop
            .as_ref()
            .map(|s| (s.time - st.start.time).num_milliseconds());
        eprintln!("{dir}: {took:?} ms from its start record to its stop record");
    }
    assert_eq!(
        all.len(),
        4,
        "{:?}",
        all.iter().map(|a| &a.0).collect::<Vec<_>>()
    );
    for (k, (dir, st)) in all.iter().enumerate() {
        let job = st
            .start
            .job
            .as_ref()
            .expect("the start record names the job");
        assert_eq!(job.id, Some(k as u64 + 1), "{dir}");
        let (name, text) = if k == 3 {
            ("tight", TIGHT)
        } else {
            ("coupon", RECIPE)
        };
        assert_eq!(job.recipe, name);
        assert_eq!(job.recipe_text, text);
        assert_eq!(st.start.plan.lines, LINES);
        assert_eq!(st.start.plan.y_start_nm.0, (ys[k] * 1e6) as i64, "{dir}");
        assert_eq!(st.completed().len() as u32, LINES, "{dir}");
        assert_eq!(
            st.stop.as_ref().map(|s| s.status),
            Some(StopStatus::Success),
            "{dir}"
        );
        assert_eq!(Some(dir), finished[k].2.as_ref());
    }
    // Each scan's verdict against its recipe's specification, recorded with its job: the
    // fixture's coupons conform, the one held to a mirror finish does not, and its job still
    // ended in success without stopping the queue.
    let verdicts: Vec<Option<Verdict>> = q
        .jobs
        .iter()
        .map(|j| match &j.state {
            JobState::Finished { verdict, .. } => *verdict,
            _ => None,
        })
        .collect();
    assert_eq!(
        verdicts,
        vec![
            Some(Verdict::Conforms),
            Some(Verdict::Conforms),
            Some(Verdict::Conforms),
            Some(Verdict::DoesNotConform)
        ],
        "{:?}",
        status(&r).await.and_then(|s| s.last_stop)
    );
    // The status says the last scan's verdict with its reason.
    let last = status(&r).await.unwrap().last_stop.expect("a last scan");
    assert_eq!(last.scan_id, all[3].0);
    let line = last.verdict.clone().unwrap_or_default();
    assert!(
        line.starts_with("success, ")
            && line.contains(": does not conform (Ra1 max rule: 5 of 5 lines above 0.001 µm"),
        "{last:?}"
    );
    assert_eq!(
        last.results.as_ref().and_then(|r| r.verdict),
        Some(Verdict::DoesNotConform),
        "{last:?}"
    );
    // The hook saw it (the hook runs after the job is recorded: wait for it). A scan may
    // have suspended before (a device busy after a kill): its success is the block sought.
    let hook_log = r.dir.path().join("hook.log");
    let id_line = format!("SURFSCAN_SCAN_ID={}\n", all[3].0);
    // A block is whole once the hook's blank line follows it (`sort` writes it first; a
    // read while it is written may see only its first part).
    let success = |t: &str| -> Option<String> {
        t.split_inclusive("\n\n")
            .filter(|b| b.ends_with("\n\n"))
            .find(|b| b.contains(&id_line) && b.contains("SURFSCAN_STATUS=success\n"))
            .map(str::to_owned)
    };
    let until = Instant::now() + DEADLINE;
    let last_hook = loop {
        let t = std::fs::read_to_string(&hook_log).unwrap_or_default();
        if let Some(b) = success(&t) {
            break b;
        }
        assert!(
            Instant::now() < until,
            "no hook for the success of {}:\n{t}",
            all[3].0
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert!(
        last_hook.contains("SURFSCAN_VERDICT=does not conform\n"),
        "{last_hook}"
    );
    assert!(
        last_hook.contains(
            "SURFSCAN_VERDICT_SUMMARY=does not conform (Ra1 max rule: 5 of 5 lines above 0.001 µm"
        ),
        "{last_hook}"
    );
    // `surfscan list` reads them back from the index, filtered by verdict.
    let listed = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["list", "--json", "--verdict", "conforms", "--config"])
        .arg(&r.config)
        .output()
        .unwrap();
    assert_eq!(listed.status.code(), Some(0), "{listed:?}");
    let rows: serde_json::Value = serde_json::from_slice(&listed.stdout).unwrap();
    let ids: Vec<&str> = rows
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["scan_id"].as_str().unwrap())
        .collect();
    assert_eq!(ids, [&all[0].0, &all[1].0, &all[2].0], "{rows}");
    // The job that needed loading began only after `ready`.
    assert!(
        all[2].1.start.time > ready_at,
        "{:?} vs {ready_at}",
        all[2].1.start.time
    );
    // Every queue command is in the log with who sent it.
    let log = crate::common::complete_lines(&r.out().join("queue-log.jsonl"));
    let adds: Vec<serde_json::Value> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|e| e["command"] == "add" || e["command"] == "ready")
        .collect();
    assert_eq!(adds.len(), 5, "{log}");
    let me = nix::unistd::geteuid().as_raw();
    assert!(adds.iter().all(|e| e["peer"]["uid"] == me), "{log}");
    drop(d);
}

/// `surfscan scan --recipe` in the foreground: a part that does not conform completes its
/// scan and exits 4 (not 0–3), the verdict and each limit's reason printed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_foreground_scan_of_a_part_that_does_not_conform_exits_4() {
    let r = rig(&[("tight", TIGHT)]).await;
    let config = r.config.clone();
    let lock_dir = r.dir.path().to_path_buf();
    let o = tokio::task::spawn_blocking(move || {
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["scan", "--recipe", "tight", "--specimen", "M-1", "--config"])
            .arg(&config)
            .env("SURFSCAN_TEST_LOCK_DIR", &lock_dir)
            .stdin(Stdio::null())
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(4), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("  verdict  does not conform\n")
            && stdout.contains("  limit    Ra1 max 0.001: does not conform (Ra1 max rule: 5 of 5 lines above 0.001 µm"),
        "{stdout}"
    );
    assert!(
        stderr.contains("the part does not conform to its specification"),
        "{stderr}"
    );
    // The scan itself is complete: every line on disk, the stop record a success.
    let all = scans(&r.out());
    assert_eq!(all.len(), 1);
    assert_eq!(all[0].1.completed().len() as u32, LINES);
    assert_eq!(
        all[0].1.stop.as_ref().map(|s| s.status),
        Some(StopStatus::Success)
    );
}

/// A recipe whose `[contact]` is enabled: brass (100 GPa, ν 0.34) against an aluminium flat
/// (70 GPa, ν 0.33) at two loads.
const CONTACT: &str = r#"description = "a coupon whose contact the lab wants"
[plan]
lines = 5
y-step-mm = 0.01
[contact]
enabled = true
pressures-mpa = [5.0, 50.0]
young-gpa = 100.0
poisson = 0.34
young2-gpa = 70.0
poisson2 = 0.33
"#;

/// `surfscan scan --recipe` with an enabled `[contact]`: the scan's own outputs hold the
/// contact (contact.json, its figures, report.json's section and report.html's table), the
/// plan froze it, and `analyze` of the scan directory computes the same contact without
/// being asked; a recipe with a malformed `[contact]` is refused (exit 78) naming the key,
/// before any scan starts.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recipes_contact_is_in_the_scans_outputs_and_frozen_in_its_plan() {
    let bad = edited(CONTACT, "young-gpa = 100.0", "young-gpa = -1.0");
    let r = rig(&[("contact", CONTACT), ("bad", &bad)]).await;
    let run = |args: Vec<String>| {
        let config = r.config.clone();
        let lock_dir = r.dir.path().to_path_buf();
        tokio::task::spawn_blocking(move || {
            Command::new(env!("CARGO_BIN_EXE_surfscan"))
                .args(&args)
                .arg("--config")
                .arg(&config)
                .env("SURFSCAN_TEST_LOCK_DIR", &lock_dir)
                .stdin(Stdio::null())
                .output()
                .unwrap()
        })
    };
    let scan = |recipe: &str| {
        ["scan", "--recipe", recipe, "--specimen", "K-1"]
            .map(String::from)
            .to_vec()
    };
    let o = run(scan("bad")).await.unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(78), "{stderr}");
    assert!(
        stderr.contains("contact.young-gpa") && stderr.contains("-1"),
        "{stderr}"
    );
    assert!(
        scans(&r.out()).is_empty(),
        "a refused recipe started a scan"
    );

    let o = run(scan("contact")).await.unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        matches!(o.status.code(), Some(0) | Some(3)),
        "{stdout}\n{stderr}"
    );
    let all = scans(&r.out());
    assert_eq!(all.len(), 1);
    let (name, state) = &all[0];
    assert_eq!(state.completed().len() as u32, LINES);
    // The plan froze the recipe's [contact] over the station's defaults.
    let frozen = state.start.plan.analysis.as_ref().unwrap();
    let c = frozen
        .contact
        .as_ref()
        .expect("the contact frozen in the plan");
    assert_eq!((c.young_gpa, c.young2_gpa), (100.0, Some(70.0)));
    assert_eq!(c.pressures_mpa, vec![5.0, 50.0]);

    let dir = r.out().join(name);
    let read = |p: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap()
    };
    let contact = read(&dir.join("contact.json"));
    // 1/E* = (1 − 0.34²)/100 + (1 − 0.33²)/70 (Johnson eq. 4.22).
    let e_star = 1.0 / ((1.0 - 0.34 * 0.34) / 100.0 + (1.0 - 0.33 * 0.33) / 70.0);
    let e = contact["effective_modulus_gpa"].as_f64().unwrap();
    assert!((e - e_star).abs() < 1e-9 * e_star, "{e} vs {e_star}");
    let curve = contact["curve"].as_array().unwrap();
    assert_eq!(curve.len(), 2, "{contact}");
    let area = |p: &serde_json::Value| p["area_fraction"].as_f64().unwrap();
    let gap = |p: &serde_json::Value| p["mean_gap_um"].as_f64().unwrap();
    // More load, more contact and a closer gap; never the whole grid.
    assert!(
        0.0 < area(&curve[0]) && area(&curve[0]) < area(&curve[1]) && area(&curve[1]) < 1.0,
        "{contact}"
    );
    assert!(
        gap(&curve[0]) > gap(&curve[1]) && gap(&curve[1]) > 0.0,
        "{contact}"
    );
    assert_eq!(contact["grid"]["rows"], LINES, "{contact}");
    for f in [
        "load_area.png",
        "load_area.svg",
        "pressure.png",
        "pressure.svg",
    ] {
        assert!(dir.join(f).is_file(), "{f} in the scan directory");
    }
    let report = read(&dir.join("report.json"));
    assert_eq!(report["contact"]["measured"]["curve"], contact["curve"]);
    assert_eq!(report["contact"]["counter_body"]["young_gpa"], 70.0);
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains("id=\"t-contact\"") && html.contains("Contact: load–area curve"),
        "the contact's table and figure in report.html"
    );

    // `analyze` of the scan directory follows the frozen plan: the same contact, unasked.
    let again = r.dir.path().join("again");
    let mut args = vec!["analyze".to_string(), dir.display().to_string()];
    args.extend(["--out".to_string(), again.display().to_string()]);
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(&args)
        .output()
        .unwrap();
    assert!(
        matches!(o.status.code(), Some(0) | Some(3)),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(read(&again.join("contact.json"))["curve"], contact["curve"]);
}
