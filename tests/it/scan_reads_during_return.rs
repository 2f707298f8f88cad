//! A scan that reads each line out while the instrument's drive returns: the real `surfscan
//! scan` binary against the simulator, whose instrument either answers reads during the return
//! or refuses them busy. Reading out during the return changes when, never what: every run
//! stores the served heights bit for bit and the same surface; the simulator's own counters
//! say whether the reads came during the return.

use crate::common::*;
use surfscan_sim::stats::SimStats;
use surfscan_sim::InstrumentConfig;

/// The drive returns at a tenth of its speed (about 0.3 s a line at the rig's time scale),
/// so the reads asked during the return are answered before it ends.
fn slow_return(answers: bool) -> fn(InstrumentConfig) -> InstrumentConfig {
    if answers {
        |c| InstrumentConfig {
            return_speed_mm_s: 0.1,
            reads_during_return: true,
            ..c
        }
    } else {
        |c| InstrumentConfig {
            return_speed_mm_s: 0.1,
            reads_during_return: false,
            ..c
        }
    }
}

struct Run {
    surface: Vec<Vec<u64>>,
    lines: Vec<Vec<u8>>,
    answered: u64,
    refused: u64,
    log: String,
}

/// One scan of a fresh rig; `configured`: the config turns reads during the return on.
async fn scan(answers: bool, configured: bool) -> Run {
    let rig = Rig::start(RigOptions {
        instrument: slow_return(answers),
        ..RigOptions::default()
    })
    .await;
    let stats = rig.sim.as_ref().map(|s| s.stats()).expect("simulator");
    let cfg = rig.config("out");
    if configured {
        let text = std::fs::read_to_string(&cfg).unwrap();
        let on = text.replacen(
            "profile-block = \"RDEVA{n}\"\n",
            "profile-block = \"RDEVA{n}\"\nreads-during-return = true\n",
            1,
        );
        assert_ne!(on, text, "the rig's config has the read-out commands");
        std::fs::write(&cfg, on).unwrap();
    }
    let o = run_scan(&cfg, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let n = rig.options.lines;
    let dir = scan_dir(&rig.out_dir("out"));
    assert_lines_exactly(&dir, n);
    assert_journal_complete(&dir, n);
    let lines = (0..n)
        .map(|k| std::fs::read(dir.join(format!("lines/{k:04}.csv"))).unwrap())
        .collect();
    let run = Run {
        surface: surface_bits(&dir.join("surface.igs")),
        lines,
        answered: SimStats::get(&stats.reads_answered_returning),
        refused: SimStats::get(&stats.reads_refused_returning),
        log: String::from_utf8_lossy(&o.stderr).into_owned(),
    };
    rig.shutdown().await;
    run
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reading_out_during_the_return_stores_the_same_lines_and_surface() {
    // The default: reads wait for the drive, whatever the instrument would do.
    let after = scan(true, false).await;
    assert_eq!(after.answered + after.refused, 0, "no read during a return");
    // Configured, on an instrument that answers: the reads came during the returns.
    let during = scan(true, true).await;
    let lines = during.lines.len() as u64;
    // Each line's results (9 parameters) and read-out total and blocks: at least the
    // results of every line during its return.
    assert!(
        during.answered >= 9 * lines,
        "{} reads during the return for {lines} lines",
        during.answered
    );
    assert_eq!(during.refused, 0);
    assert!(!during.log.contains("refused a read"), "{}", during.log);
    // Configured, on an instrument that refuses: one refusal, said once, then reads after
    // the return for the rest of the scan.
    let refused = scan(false, true).await;
    assert_eq!(refused.answered, 0);
    assert_eq!(refused.refused, 1, "one refused read, then no more tries");
    let said: Vec<&str> = refused
        .log
        .lines()
        .filter(|l| l.contains("refused a read while its drive returned"))
        .collect();
    // Said by the driver, and recorded with the one line it happened on.
    assert_eq!(said.len(), 2, "{}", refused.log);
    assert_eq!(
        said.iter().filter(|l| l.contains(" line=")).count(),
        1,
        "{said:?}"
    );
    // The same files.
    assert_eq!(during.lines, after.lines);
    assert_eq!(refused.lines, after.lines);
    assert_eq!(during.surface, after.surface);
    assert_eq!(refused.surface, after.surface);
}
