//! `surfscan probe` finding the baud rate the instrument is set to: the real binary against
//! the simulator over a pseudo-terminal, the simulator answering only a host at its own rate
//! (silence or line noise otherwise, as a real instrument gives), and the line it prints pasted
//! into the config really reaching the instrument. Nothing but the status command is sent
//! while searching.

use std::path::{Path, PathBuf};
use surfscan_sim::line::Mismatch;
use surfscan_sim::stats::SimStats;
use surfscan_sim::{InstrumentConfig, SimHandle, Simulator};

async fn start(dir: &Path, baud: u32, mismatch: Mismatch) -> SimHandle {
    crate::common::started(
        Simulator::new(dir.join("sj210"))
            .instrument(InstrumentConfig {
                time_scale: 0.01,
                ..InstrumentConfig::default()
            })
            .baud(baud)
            .line_check(mismatch),
    )
    .await
}

/// A probe config at `baud`, with short timeouts so each silent rate costs little.
fn config(dir: &Path, baud: u32) -> PathBuf {
    let p = dir.join(format!("probe-{baud}.toml"));
    std::fs::write(
        &p,
        format!(
            "[instrument]\nport = \"{}\"\nbaud = {baud}\n[instrument.timeouts]\nfirst-byte-ms = 300\ninter-byte-ms = 100\n",
            dir.join("sj210").display()
        ),
    )
    .unwrap();
    p
}

async fn probe(config: &Path, record: &Path) -> (Option<i32>, String, String) {
    let args = [
        "--config".as_ref(),
        config.as_os_str(),
        "--record".as_ref(),
        record.as_os_str(),
    ];
    crate::common::run_probe::<&std::ffi::OsStr>(&args, 90).await
}

/// The commands the probe sent, from its transcript.
fn sent(record: &Path) -> Vec<String> {
    crate::common::sent_commands(&std::fs::read_to_string(record).unwrap())
}

/// The lines printed under the `snippet` line.
fn snippet(stdout: &str) -> String {
    let at = stdout.find("snippet").expect("a snippet is printed");
    stdout[at..]
        .lines()
        .skip(1)
        .take_while(|l| !l.is_empty() && !l.contains("  "))
        .map(|l| format!("{l}\n"))
        .collect()
}

#[tokio::test]
async fn a_silent_link_at_the_configured_rate_is_searched_and_the_pasted_line_works() {
    let dir = tempfile::tempdir().unwrap();
    let sim = start(dir.path(), 38400, Mismatch::Silent).await;
    let stats = sim.stats();
    let cfg = config(dir.path(), 9600);
    let record = dir.path().join("search.transcript");
    let (code, stdout, stderr) = probe(&cfg, &record).await;
    // The checklist ran at the rate found, and the exit status says the config is wrong.
    assert_eq!(code, Some(78), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(
        stdout.contains("no answer at 9600 baud, parity none (no reply within 300 ms"),
        "{stdout}"
    );
    assert!(
        stdout.contains("rate      38400 baud, parity none: the instrument answers"),
        "{stdout}"
    );
    assert!(stdout.contains("identity  model sj210"), "{stdout}");
    let paste = snippet(&stdout);
    assert_eq!(paste, "baud = 38400\n", "{stdout}");
    assert!(
        stderr.contains("set baud = 38400 in [instrument]"),
        "{stderr}"
    );
    // At 9600 the instrument saw noise: nothing it was asked happened.
    assert!(SimStats::get(&stats.frames_at_wrong_rate) >= 1);
    // The search asked nothing but the status; the transcript says where the link answered.
    let cmds = sent(&record);
    let first_other = cmds.iter().position(|c| c != "RDSTU00").unwrap();
    assert!(first_other >= 3, "{cmds:?}");
    assert!(!cmds.iter().any(|c| c.starts_with("CT") && c != "CTOFF01"));
    let text = std::fs::read_to_string(&record).unwrap();
    assert!(text.contains("at 38400 baud, parity none"), "{text}");

    // The printed line pasted into the config: the probe reaches the instrument at once.
    let fixed = dir.path().join("fixed.toml");
    std::fs::write(
        &fixed,
        crate::common::edited(
            &std::fs::read_to_string(&cfg).unwrap(),
            "baud = 9600\n",
            &paste,
        ),
    )
    .unwrap();
    let before = SimStats::get(&stats.frames_at_wrong_rate);
    let (code, stdout, stderr) = probe(&fixed, &dir.path().join("fixed.transcript")).await;
    assert_eq!(code, Some(0), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(!stdout.contains("no answer"), "{stdout}");
    assert!(!stdout.contains("snippet"), "{stdout}");
    assert_eq!(SimStats::get(&stats.frames_at_wrong_rate), before);
    sim.shutdown().await;
}

#[tokio::test]
async fn line_noise_is_no_answer_and_a_slow_rate_found_is_told_what_it_costs() {
    let dir = tempfile::tempdir().unwrap();
    let sim = start(dir.path(), 19200, Mismatch::Noise).await;
    let cfg = config(dir.path(), 9600);
    let record = dir.path().join("noise.transcript");
    let (code, stdout, stderr) = probe(&cfg, &record).await;
    assert_eq!(code, Some(78), "stdout:\n{stdout}\nstderr:\n{stderr}");
    // 38400 is tried before 19200 (fastest first) and answers with noise only.
    let at_38400 = stdout
        .lines()
        .find(|l| l.starts_with("rate      38400 baud"))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(at_38400.contains("no answer"), "{at_38400}");
    assert!(
        stdout.contains("rate      19200 baud, parity none: the instrument answers"),
        "{stdout}"
    );
    assert_eq!(snippet(&stdout), "baud = 19200\n", "{stdout}");
    // 8000 points: 82 096 bytes of 10 bits, 42.8 s at 19200 and 21.4 s at 38400.
    assert!(
        stdout.contains("takes 42.8 s on the wire at 19200 and 21.4 s at 38400"),
        "{stdout}"
    );
    sim.shutdown().await;
}

#[tokio::test]
async fn an_instrument_at_no_rate_of_the_model_is_a_named_outcome_not_a_hang() {
    let dir = tempfile::tempdir().unwrap();
    // 57600 is an SJ-410 rate; an SJ-210 configuration never tries it.
    let sim = start(dir.path(), 57600, Mismatch::Silent).await;
    let cfg = config(dir.path(), 9600);
    let record = dir.path().join("none.transcript");
    let (code, stdout, stderr) = probe(&cfg, &record).await;
    assert_eq!(code, Some(69), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(
        stderr.contains("answered at none of the 9 settings tried"),
        "{stderr}"
    );
    for rate in ["38400", "19200"] {
        for parity in ["none", "even", "odd"] {
            assert!(
                stdout.contains(&format!(
                    "rate      {rate} baud, parity {parity}: no answer"
                )),
                "{rate} {parity}: {stdout}"
            );
        }
    }
    // Every attempt is in the transcript, and it is nothing but status questions.
    let cmds = sent(&record);
    assert!(cmds.len() >= 9, "{cmds:?}");
    assert!(cmds.iter().all(|c| c == "RDSTU00"), "{cmds:?}");
    sim.shutdown().await;
}
