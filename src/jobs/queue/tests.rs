//! The queue's transitions, its order and what a restart makes of a running job.

use super::*;

fn at(s: u32) -> DateTime<Utc> {
    DateTime::from_timestamp(1_770_000_000 + i64::from(s), 0).unwrap()
}

fn request(specimen: &str, needs_loading: bool) -> JobRequest {
    JobRequest {
        recipe: FrozenRecipe {
            name: "brass".into(),
            path: "/etc/surfscan/recipes/brass.toml".into(),
            text: "[plan]\nlines = 6\ny-step-mm = 0.01\n".into(),
            sha256: "ab".repeat(32),
        },
        specimen: specimen.into(),
        operator: "ana".into(),
        notes: String::new(),
        y_start_mm: Some(10.0),
        needs_loading,
    }
}

fn ended(outcome: &str) -> JobOutcome {
    JobOutcome {
        scan_id: Some(format!("scan-{outcome}")),
        outcome: outcome.into(),
        verdict: None,
        reason: "why".into(),
    }
}

#[test]
fn jobs_run_in_the_order_they_were_added() {
    let mut q = Queue::new();
    assert_eq!(q.next(), Next::Idle);
    let a = q.add(request("A", false), at(0), None);
    let b = q.add(request("B", false), at(1), None);
    let c = q.add(request("C", false), at(2), None);
    assert_eq!((a, b, c), (1, 2, 3));
    assert_eq!(q.next(), Next::Start(1));
    q.mark_running(1, at(3));
    assert_eq!(
        q.next(),
        Next::Continue {
            id: 1,
            scan_id: None
        }
    );
    q.set_scan(1, "s1");
    q.finish(1, ended("success"), false, at(4));
    assert_eq!(q.next(), Next::Start(2));
    // Removing a queued job keeps the others' order; a number is never given twice.
    q.remove(2).unwrap();
    assert_eq!(q.next(), Next::Start(3));
    assert_eq!(q.add(request("D", false), at(5), None), 4);
    let pending: Vec<u64> = q.pending().map(|j| j.id).collect();
    assert_eq!(pending, vec![3, 4]);
    assert_eq!(q.remove(1), Err(QueueError::Finished(1)));
    assert_eq!(q.remove(9), Err(QueueError::NoSuchJob(9)));
    q.mark_running(3, at(6));
    assert_eq!(q.remove(3), Err(QueueError::Running(3)));
    // Clear removes the queued jobs, never the running one.
    let gone: Vec<u64> = q.clear().iter().map(|j| j.id).collect();
    assert_eq!(gone, vec![4]);
    assert!(matches!(q.next(), Next::Continue { id: 3, .. }));
}

#[test]
fn a_job_that_needs_loading_waits_for_ready_in_its_turn() {
    let mut q = Queue::new();
    q.add(request("A", false), at(0), None);
    q.add(request("B", true), at(1), None);
    // `ready` names the waiting job; before B's turn, it is refused naming the one before.
    let e = q.ready(Some(2)).unwrap_err();
    assert!(e.to_string().contains("job 1 runs before it"), "{e}");
    assert!(matches!(
        q.ready(None),
        Err(QueueError::NotWaiting { id: 1, .. })
    ));
    q.mark_running(1, at(2));
    q.finish(1, ended("success"), false, at(3));
    assert_eq!(q.next(), Next::WaitForLoading(2));
    assert_eq!(q.ready(None), Ok(2));
    assert_eq!(q.next(), Next::Start(2));
    q.mark_running(2, at(4));
    q.finish(2, ended("success"), false, at(5));
    assert_eq!(q.ready(None), Err(QueueError::NothingToLoad));
}

#[test]
fn a_failed_job_stops_the_queue_only_when_its_recipe_says_so() {
    let mut q = Queue::new();
    for s in ["A", "B", "C"] {
        q.add(request(s, false), at(0), None);
    }
    q.mark_running(1, at(1));
    q.finish(1, ended("fail"), false, at(2));
    assert_eq!(q.next(), Next::Start(2));
    q.mark_running(2, at(3));
    q.finish(2, ended("fail"), true, at(4));
    let Next::Held(why) = q.next() else {
        panic!("{:?}", q.next())
    };
    assert!(
        why.contains("job 2 (brass) ended fail") && why.contains("queue continue"),
        "{why}"
    );
    q.release().unwrap();
    assert_eq!(q.next(), Next::Start(3));
    assert_eq!(q.release(), Err(QueueError::NotHeld));
    // A success never stops it.
    q.mark_running(3, at(5));
    q.finish(3, ended("success"), true, at(6));
    assert_eq!(q.next(), Next::Idle);
}

#[test]
fn a_restart_settles_a_running_job_by_its_journal() {
    let mut q = Queue::new();
    for s in ["A", "B", "C", "D"] {
        q.add(request(s, false), at(0), None);
    }
    // Job 1: its scan ended before the crash, the queue did not record it yet.
    q.mark_running(1, at(1));
    q.set_scan(1, "s1");
    let lookup = |id: u64| match id {
        1 => Some(JobScan {
            scan_id: "s1".into(),
            ended: Some((StopStatus::Success, "complete".into())),
            verdict: Some(Verdict::Conforms),
        }),
        2 => Some(JobScan {
            scan_id: "s2".into(),
            ended: None,
            verdict: None,
        }),
        _ => None,
    };
    let notes = q.reconcile(lookup, |_| false, at(2));
    assert_eq!(notes.len(), 1, "{notes:?}");
    let j1 = q.get(1).unwrap();
    assert!(
        matches!(&j1.state, JobState::Finished { outcome, verdict: Some(Verdict::Conforms), .. } if outcome == "success"),
        "{j1:?}"
    );
    assert_eq!(q.next(), Next::Start(2));
    // Job 2: marked running, the crash came after its scan was created but before the queue
    // recorded the scan's id: the journal names the job, so the scan is continued.
    q.mark_running(2, at(3));
    q.reconcile(lookup, |_| false, at(4));
    assert_eq!(
        q.next(),
        Next::Continue {
            id: 2,
            scan_id: Some("s2".into())
        }
    );
    // Job 3 marked running, no scan names it: it is created, once.
    let mut q3 = q.clone();
    q3.finish(2, ended("success"), false, at(5));
    q3.mark_running(3, at(6));
    let notes = q3.reconcile(lookup, |_| false, at(7));
    assert!(notes[0].contains("no scan was created"), "{notes:?}");
    assert_eq!(
        q3.next(),
        Next::Continue {
            id: 3,
            scan_id: None
        }
    );
}

#[test]
fn finished_jobs_are_kept_up_to_a_bound_before_the_pending_ones() {
    let mut q = Queue::new();
    for k in 0..(FINISHED_KEPT + 5) {
        let id = q.add(request(&format!("S{k}"), false), at(0), None);
        q.add(request("later", false), at(0), None);
        q.remove(id + 1).unwrap();
        q.mark_running(id, at(1));
        q.finish(id, ended("success"), false, at(2));
    }
    q.add(request("Z", false), at(3), None);
    assert_eq!(q.jobs.len(), FINISHED_KEPT + 1);
    assert!(q.jobs.last().unwrap().is_queued());
    // The oldest were dropped, the newest finished kept in order.
    let first = q.jobs[0].id;
    assert!(q.jobs[..FINISHED_KEPT]
        .windows(2)
        .all(|w| w[0].id < w[1].id));
    assert_eq!(first, 2 * 5 + 1);
}

#[test]
fn the_store_round_trips_and_keeps_a_damaged_file_aside() {
    let dir = tempfile::tempdir().unwrap();
    let store = QueueStore::new(dir.path());
    let (q0, warn) = store.load().unwrap();
    assert_eq!((q0, warn), (Queue::new(), None));
    let mut q = Queue::new();
    q.add(
        request("A", true),
        at(0),
        Some(Peer {
            uid: 1000,
            gid: 1000,
            pid: Some(42),
            web: None,
            mqtt: None,
        }),
    );
    q.add(request("B", false), at(1), None);
    q.mark_running(2, at(2));
    q.set_scan(2, "20260101T000000Z-B");
    q.held = Some("why".into());
    store.save(&q).unwrap();
    let (back, warn) = store.load().unwrap();
    assert_eq!(back, q);
    assert_eq!(warn, None);
    // The file is for people too: the frozen recipe and the state are plain JSON.
    let text = std::fs::read_to_string(store.path()).unwrap();
    assert!(
        text.contains("\"state\": \"running\"") && text.contains("\"sha256\""),
        "{text}"
    );

    store
        .log(&LogEntry {
            time: at(3),
            command: "add".into(),
            jobs: vec![1],
            peer: Some(Peer {
                uid: 1000,
                gid: 1000,
                pid: Some(42),
                web: None,
                mqtt: None,
            }),
            detail: "job 1".into(),
        })
        .unwrap();
    let log = std::fs::read_to_string(store.log_path()).unwrap();
    let entry: LogEntry = serde_json::from_str(log.trim()).unwrap();
    assert_eq!(entry.peer.unwrap().uid, 1000);

    std::fs::write(store.path(), b"{\"jobs\": [ torn").unwrap();
    let (q, warn) = store.load().unwrap();
    assert_eq!(q, Queue::new());
    let warn = warn.unwrap();
    assert!(warn.contains("queue.json.damaged-"), "{warn}");
    let kept: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with("queue.json.damaged-")
        })
        .collect();
    assert_eq!(kept.len(), 1);
    assert_eq!(std::fs::read(kept[0].path()).unwrap(), b"{\"jobs\": [ torn");
}

#[test]
fn a_job_whose_scan_could_not_begin_goes_back_to_its_place() {
    let mut q = Queue::new();
    q.add(request("A", true), at(0), None);
    q.add(request("B", false), at(1), None);
    q.ready(None).unwrap();
    q.mark_running(1, at(2));
    assert_eq!(q.status().running, Some(1));
    q.requeue(1);
    // First again, its specimen still loaded: it starts without another `ready`.
    assert_eq!(q.next(), Next::Start(1));
    assert_eq!(
        q.status(),
        crate::scan::status::QueueStatus {
            queued: 2,
            running: None,
            held: None
        }
    );
    // A job whose scan exists is not put back: it is continued.
    q.mark_running(1, at(3));
    q.set_scan(1, "s1");
    q.requeue(1);
    assert!(matches!(
        q.next(),
        Next::Continue {
            id: 1,
            scan_id: Some(_)
        }
    ));
}
