//! The queue's keeper: what it refuses, what it writes, what a restart makes of a job.

use super::*;
use crate::config::tests::MINIMAL;
use crate::jobs::queue::JobState;
use crate::jobs::synthetic::{write, SyntheticScan};
use crate::scan::journal::StopStatus;

const RECIPE: &str = r#"[plan]
lines = 11
y-step-mm = 0.01
[specification]
limits = ["Ra 0.8"]
"#;

/// The configuration's smallest station, its output and recipes in `dir` (a recipe `brass`).
pub(crate) fn station(dir: &Path) -> Config {
    let out = dir.join("out").display().to_string();
    let text = format!(
        "{}[jobs]\nrecipes = \"{}\"\n",
        MINIMAL.replace("/var/lib/surfscan/scans", &out),
        dir.join("recipes").display()
    );
    std::fs::create_dir_all(dir.join("recipes")).unwrap();
    std::fs::write(dir.join("recipes/brass.toml"), RECIPE).unwrap();
    Config::parse(Path::new("station.toml"), &text).unwrap()
}

fn add(recipe: &str, specimen: &str, y: Option<f64>) -> AddJob {
    AddJob {
        recipe: recipe.into(),
        specimen: specimen.into(),
        operator: "ana".into(),
        notes: String::new(),
        y_start_mm: y,
        needs_loading: false,
    }
}

const PEER: Peer = Peer {
    uid: 1000,
    gid: 1000,
    pid: Some(4242),
    web: None,
    mqtt: None,
};

#[test]
fn a_job_is_refused_before_it_is_queued_when_its_recipe_or_y_cannot_run() {
    let dir = tempfile::tempdir().unwrap();
    let (svc, warning) = QueueService::open(station(dir.path())).unwrap();
    assert_eq!(warning, None);
    let e = svc.add(add("bras", "C-1", None), Some(PEER)).unwrap_err();
    assert!(
        matches!(e, ServiceError::Usage(_)) && e.to_string().contains("brass"),
        "{e}"
    );
    assert_eq!(e.exit_code(), 2);
    let e = svc
        .add(add("brass", "C-1", Some(70.0)), Some(PEER))
        .unwrap_err();
    assert!(
        matches!(e, ServiceError::Usage(_)) && e.to_string().contains("--y-start-mm"),
        "{e}"
    );
    std::fs::write(
        dir.path().join("recipes/steel.toml"),
        RECIPE.replace("\"Ra 0.8\"", "\"Ra0.8x\""),
    )
    .unwrap();
    let e = svc.add(add("steel", "C-1", None), Some(PEER)).unwrap_err();
    assert_eq!(e.exit_code(), 78, "{e}");
    assert!(
        e.to_string().contains("steel.toml: specification.limits"),
        "{e}"
    );
    assert!(svc.snapshot().jobs.is_empty());
    // Nothing refused was written.
    assert!(!dir.path().join("out/queue.json").exists());
}

#[test]
fn each_change_is_on_disk_and_logged_with_its_peer_before_it_is_answered() {
    let dir = tempfile::tempdir().unwrap();
    let st = station(dir.path());
    let (svc, _) = QueueService::open(st.clone()).unwrap();
    let mut changes = svc.subscribe();
    let job = svc
        .add(add("brass", "C-1", Some(10.0)), Some(PEER))
        .unwrap();
    assert_eq!(job.id, 1);
    assert!(changes.has_changed().unwrap());
    changes.borrow_and_update();
    // The recipe is frozen: editing the file later changes nothing of the job.
    std::fs::write(
        dir.path().join("recipes/brass.toml"),
        RECIPE.replace("11", "21"),
    )
    .unwrap();
    let (again, _) = QueueService::open(st.clone()).unwrap();
    let q = again.snapshot();
    assert_eq!(q.jobs.len(), 1);
    assert_eq!(q.jobs[0].request.recipe.text, RECIPE);
    assert_eq!(q.jobs[0].added_by, Some(PEER));
    let plan = again.plan_of(1).unwrap();
    assert_eq!(
        (plan.config.scan.lines, plan.config.scan.y_start_mm),
        (11, 10.0)
    );
    svc.remove(1, Some(PEER)).unwrap();
    let log = std::fs::read_to_string(dir.path().join("out/queue-log.jsonl")).unwrap();
    let entries: Vec<LogEntry> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        entries
            .iter()
            .map(|e| e.command.as_str())
            .collect::<Vec<_>>(),
        vec!["add", "remove"]
    );
    assert!(entries.iter().all(|e| e.peer == Some(PEER)));
    // A change that cannot be written is refused and the queue stays as it was.
    std::fs::remove_dir_all(dir.path().join("out")).unwrap();
    std::fs::write(dir.path().join("out"), b"not a directory").unwrap();
    let e = svc.add(add("brass", "C-2", None), Some(PEER)).unwrap_err();
    assert_eq!(e.exit_code(), 74, "{e}");
    assert!(svc.snapshot().jobs.is_empty());
}

#[test]
fn after_a_restart_a_running_job_is_settled_by_the_journal_that_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let st = station(dir.path());
    let (svc, _) = QueueService::open(st.clone()).unwrap();
    for s in ["C-1", "C-2"] {
        svc.add(add("brass", s, None), None).unwrap();
    }
    svc.mark_running(1).unwrap();
    // The scan of job 1 was created and completed, then the daemon was killed before the
    // queue recorded either.
    let out = dir.path().join("out");
    write(
        &out,
        &SyntheticScan {
            id: "20260301T220000Z-C-1".into(),
            sequence: 1,
            started: Utc::now(),
            specimen: "C-1".into(),
            recipe: Some(("brass".into(), Some(1))),
            lines: 11,
            done: 11,
            stop: Some(StopStatus::Success),
            report: None,
        },
    )
    .unwrap();
    let (svc, _) = QueueService::open(st.clone()).unwrap();
    let notes = svc.reconcile().unwrap();
    assert!(
        notes[0].contains("ended success before the restart"),
        "{notes:?}"
    );
    let q = svc.snapshot();
    assert!(
        matches!(&q.get(1).unwrap().state, JobState::Finished { scan_id: Some(s), .. } if s == "20260301T220000Z-C-1")
    );
    assert_eq!(svc.next(), Next::Start(2));
    // A fresh queue numbers after the journals' highest job: job 1 is never given again.
    std::fs::remove_file(out.join("queue.json")).unwrap();
    let (fresh, _) = QueueService::open(st).unwrap();
    assert_eq!(fresh.add(add("brass", "C-9", None), None).unwrap().id, 2);
}
