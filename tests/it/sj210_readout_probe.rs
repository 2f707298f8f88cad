//! The read-out probe against the simulator in each of its read-out modes: the SJ-210 form
//! answered first, only the B-selector form answered (NG031 to the others), no read-out at
//! all (NG030 everywhere), no trace held yet, a count that does not fit the conditions, and
//! the whole Mitutoyo R profile under its recorded conditions. Then the `surfscan probe
//! --readout` binary (verdicts, snippet, transcript, and the snippet pasted into a config
//! really reads), and `--passthrough` relaying a PC tool's session and recording it.
//!
//! The simulator parses commands and formats replies with its own code; the expected counts
//! are worked out here from the conditions (N × ⌊λc / pitch⌋), independent of the daemon.

use std::path::{Path, PathBuf};
use std::time::Duration;
use surfscan::sj210::client::Sj210Client;
use surfscan::sj210::models::{CommandOverrides, ModelId, ModelTable};
use surfscan::sj210::ng::NgCode;
use surfscan::sj210::readout_probe::{Conclusion, FormVerdict, ReadoutForm, ReadoutProbe};
use surfscan::sj210::settings::ClientOptions;
use surfscan::transport::{self, FlowControl, Parity, SerialSettings};
use surfscan_sim::instrument::ReadoutForm as SimForm;
use surfscan_sim::{InstrumentConfig, ProfileSet, SimHandle, Simulator};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_serial::SerialStream;

const EVENT_WAIT: Duration = Duration::from_secs(10);

fn fast(cfg: InstrumentConfig) -> InstrumentConfig {
    InstrumentConfig {
        time_scale: 0.01,
        ..cfg
    }
}

async fn start(dir: &Path, cfg: InstrumentConfig, profiles: Option<ProfileSet>) -> SimHandle {
    let link = dir.join("sj210");
    let mut b = Simulator::new(&link).instrument(fast(cfg));
    if let Some(p) = profiles {
        b = b.profiles(p);
    }
    crate::common::started(b).await
}

fn client(link: &Path, table: ModelTable) -> Sj210Client<SerialStream> {
    let port = transport::open(&SerialSettings {
        path: link.display().to_string(),
        baud: 38400,
        parity: Parity::None,
        flow_control: FlowControl::None,
    })
    .unwrap();
    let opts = ClientOptions {
        poll_interval: Duration::from_millis(10),
        start_deadline: Duration::from_millis(1500),
        read_retry_budget: Duration::from_millis(300),
        trace_deadline: Some(Duration::from_secs(10)),
        ..ClientOptions::default()
    };
    Sj210Client::new(port, table, opts)
}

/// Starts a simulator, optionally traces one line, and runs the read-out probe over the
/// candidate forms with the SJ-210's built-in table (which has no read-out command).
async fn probe(cfg: InstrumentConfig, profiles: Option<ProfileSet>, trace: bool) -> ReadoutProbe {
    let dir = tempfile::tempdir().unwrap();
    let sim = start(dir.path(), cfg, profiles).await;
    let mut c = client(
        &dir.path().join("sj210"),
        ModelTable::builtin(ModelId::Sj210),
    );
    if trace {
        c.run_trace().await.unwrap();
    }
    let p = c
        .probe_readout_forms(&ReadoutForm::candidates(&[]))
        .await
        .unwrap();
    drop(c);
    sim.shutdown().await;
    p
}

fn verdicts(p: &ReadoutProbe) -> Vec<(&str, &FormVerdict)> {
    p.results
        .iter()
        .map(|r| (r.form.total.as_str(), &r.verdict))
        .collect()
}

fn form(total: &str) -> ReadoutForm {
    ReadoutForm::from_total(total).unwrap()
}

#[tokio::test]
async fn the_sj210_form_reads_first_and_the_probe_stops_there() {
    let p = probe(InstrumentConfig::default(), None, true).await;
    assert_eq!(p.results.len(), 1, "{:?}", verdicts(&p));
    assert_eq!(p.conclusion(), Conclusion::Works(form("RDEVA00")));
    match &p.results[0].verdict {
        FormVerdict::Read(c) => {
            // The first bundled window, 1067 points; arbitrary length: no count expected.
            assert_eq!(c.total, 1067);
            assert_eq!(c.expected, None);
            let ra =
                c.ra.expect("an R profile with an instrument Ra is compared");
            assert!(ra.agrees(), "{ra:?}");
            assert!(c.repeated_blocks.is_empty());
        }
        other => panic!("{other:?}"),
    }
    // λc 2.5 mm on the SJ-210 means λs 8 µm, so the pitch is 1.5 µm.
    assert_eq!(p.pitch.as_ref().map(|p| p.0), Some(1.5));
    assert!(p
        .snippet()
        .unwrap()
        .contains("profile-block = \"RDEVA{n}\""));
}

/// A form the instrument read (`RDEVA100`) does not make another form of the same mnemonic
/// (`RDEVA00`, `NG031`) a stray reply on that link: it is still a wrong form. (The probe
/// reads during the drive's return before it tries the forms; when the return had ended by
/// then, `RDEVA100` was answered first and every form after it was called "no usable
/// answer".) The same form refused after it read is a stray reply.
#[tokio::test]
async fn a_wrong_form_after_another_form_read_is_still_a_wrong_form() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = InstrumentConfig {
        readout_form: SimForm::Only(Some(1)),
        ..InstrumentConfig::default()
    };
    let sim = start(dir.path(), cfg, None).await;
    let mut c = client(
        &dir.path().join("sj210"),
        ModelTable::builtin(ModelId::Sj210),
    );
    c.run_trace().await.unwrap();
    let first = c.probe_readout_forms(&[form("RDEVA100")]).await.unwrap();
    assert!(
        matches!(verdicts(&first)[..], [("RDEVA100", FormVerdict::Read(_))]),
        "{:?}",
        verdicts(&first)
    );
    let then = c
        .probe_readout_forms(&[form("RDEVA00"), form("RDEVA000")])
        .await
        .unwrap();
    assert_eq!(
        verdicts(&then),
        [
            ("RDEVA00", &FormVerdict::WrongForm(NgCode::InvalidFormat)),
            ("RDEVA000", &FormVerdict::WrongForm(NgCode::InvalidFormat)),
        ]
    );
    drop(c);
    sim.shutdown().await;
}

#[tokio::test]
async fn only_the_b_selector_form_answers_after_two_wrong_forms() {
    let cfg = InstrumentConfig {
        readout_form: SimForm::Only(Some(1)),
        ..InstrumentConfig::default()
    };
    let p = probe(cfg, None, true).await;
    let v = verdicts(&p);
    assert_eq!(v.len(), 3, "{v:?}");
    assert_eq!(
        v[0],
        ("RDEVA00", &FormVerdict::WrongForm(NgCode::InvalidFormat))
    );
    assert_eq!(
        v[1],
        ("RDEVA000", &FormVerdict::WrongForm(NgCode::InvalidFormat))
    );
    assert!(matches!(v[2], ("RDEVA100", FormVerdict::Read(_))), "{v:?}");
    assert_eq!(p.conclusion(), Conclusion::Works(form("RDEVA100")));
    let s = p.snippet().unwrap();
    assert!(
        s.contains("profile-total = \"RDEVA100\"\nprofile-block = \"RDEVA1{n}\""),
        "{s}"
    );
}

#[tokio::test]
async fn only_the_a_selector_form_answers_after_the_sj210_form() {
    let cfg = InstrumentConfig {
        readout_form: SimForm::Only(Some(0)),
        ..InstrumentConfig::default()
    };
    let p = probe(cfg, None, true).await;
    let v = verdicts(&p);
    // Stops at the form that reads: RDEVA100 is never sent.
    assert_eq!(v.len(), 2, "{v:?}");
    assert_eq!(
        v[0],
        ("RDEVA00", &FormVerdict::WrongForm(NgCode::InvalidFormat))
    );
    assert!(matches!(v[1], ("RDEVA000", FormVerdict::Read(_))), "{v:?}");
    assert_eq!(p.conclusion(), Conclusion::Works(form("RDEVA000")));
    assert!(p
        .snippet()
        .unwrap()
        .contains("profile-total = \"RDEVA000\"\nprofile-block = \"RDEVA0{n}\""));
}

#[tokio::test]
async fn no_readout_is_ng030_on_every_form_and_the_guidance_names_what_remains() {
    let cfg = InstrumentConfig {
        profile_readout: false,
        ..InstrumentConfig::default()
    };
    let p = probe(cfg, None, true).await;
    let v = verdicts(&p);
    assert_eq!(v.len(), 3);
    assert!(
        v.iter().all(|(_, f)| **f == FormVerdict::NoSuchCommand),
        "{v:?}"
    );
    assert_eq!(p.conclusion(), Conclusion::NotSupported);
    assert_eq!(p.snippet(), None);
    let g = p.guidance().unwrap();
    assert!(g.contains("SJ-410") && g.contains("SJ-411"), "{g}");
    assert!(g.contains("--passthrough"), "{g}");
}

#[tokio::test]
async fn before_any_trace_no_profile_is_held() {
    let p = probe(InstrumentConfig::default(), None, false).await;
    let v = verdicts(&p);
    assert_eq!(v[0], ("RDEVA00", &FormVerdict::NoProfileHeld));
    assert_eq!(p.conclusion(), Conclusion::NeedsTrace);
    assert!(p.guidance().unwrap().contains("trace a line"));
}

#[tokio::test]
async fn a_count_that_does_not_fit_the_conditions_is_a_named_doubt() {
    // N 4 at λc 2.5 mm and 1.5 µm: 4 × 1666 = 6664 expected; the windows have 1067 points.
    let mut cfg = InstrumentConfig::default();
    cfg.conditions.sampling_lengths = 4;
    let p = probe(cfg, None, true).await;
    match p.conclusion() {
        Conclusion::WorksWithDoubts(f, d) => {
            assert_eq!(f, form("RDEVA00"));
            assert_eq!(d.len(), 1, "{d:?}");
            assert!(
                d[0].contains("1067 points read") && d[0].contains("6664"),
                "{d:?}"
            );
        }
        other => panic!("{other:?}"),
    }
}

#[tokio::test]
async fn the_mitutoyo_r_profile_passes_the_count_and_the_ra_check() {
    let mut cfg = InstrumentConfig::default();
    cfg.conditions.sampling_lengths = 4;
    let p = probe(cfg, Some(ProfileSet::bundled_mitutoyo_r().unwrap()), true).await;
    assert_eq!(p.conclusion(), Conclusion::Works(form("RDEVA00")));
    match &p.results[0].verdict {
        FormVerdict::Read(c) => {
            assert_eq!(c.total, 6664);
            assert_eq!(c.expected.map(|e| e.points), Some(6664));
            let ra = c.ra.unwrap();
            // The export printed Ra 3.308 µm; ours from the same heights is the same.
            assert!((ra.ours_um - 3.308).abs() < 0.0005, "{ra:?}");
            assert!(ra.agrees());
        }
        other => panic!("{other:?}"),
    }
}

async fn run_probe(args: &[&str]) -> (Option<i32>, String, String) {
    crate::common::run_probe(args, 60).await
}

fn config(dir: &Path, name: &str, link: &Path, extra: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(
        &p,
        format!(
            "[instrument]\nport = \"{}\"\nbaud = 38400\n[instrument.timeouts]\npoll-interval-ms = 20\nread-retry-budget-ms = 500\n{extra}",
            link.display()
        ),
    )
    .unwrap();
    p
}

fn sent(transcript: &str) -> Vec<String> {
    crate::common::sent_commands(transcript)
}

#[tokio::test]
async fn probe_readout_binary_prints_verdicts_and_a_snippet_that_works() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = InstrumentConfig {
        readout_form: SimForm::Only(Some(1)),
        ..InstrumentConfig::default()
    };
    let sim = start(dir.path(), cfg, None).await;
    let link = dir.path().join("sj210");
    let cfg_path = config(dir.path(), "probe.toml", &link, "");
    let record = dir.path().join("readout.transcript");
    let (code, stdout, stderr) = run_probe(&[
        "--config",
        cfg_path.to_str().unwrap(),
        "--trace",
        "--readout",
        "--record",
        record.to_str().unwrap(),
    ])
    .await;
    assert_eq!(code, Some(0), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(
        stdout.contains("readout   RDEVA00 / RDEVA{n}: NG031"),
        "{stdout}"
    );
    assert!(
        stdout.contains("readout   RDEVA000 / RDEVA0{n}: NG031"),
        "{stdout}"
    );
    assert!(
        stdout.contains("readout   RDEVA100 / RDEVA1{n}: read 1067 points"),
        "{stdout}"
    );
    assert!(
        stdout.contains("verdict   RDEVA100 reads the profile"),
        "{stdout}"
    );
    let start_at = stdout
        .find("\n[instrument.commands]\n")
        .expect("snippet printed")
        + 1;
    let snippet: String = stdout[start_at..]
        .lines()
        .take_while(|l| !l.starts_with("transcript") && !l.starts_with("next"))
        .map(|l| format!("{l}\n"))
        .collect();
    // Every exchange is in the transcript: the three totals and the blocks of the one that read.
    let text = std::fs::read_to_string(&record).unwrap();
    let cmds = sent(&text);
    for c in ["RDEVA00", "RDEVA000", "RDEVA100", "RDEVA150", "CTSTA"] {
        assert!(cmds.iter().any(|s| s == c), "{c} not in {cmds:?}");
    }
    // 1067 points: 21 blocks of 50 and one of 17, after the total.
    assert_eq!(cmds.iter().filter(|s| *s == "RDEVA150").count(), 21);
    assert!(cmds.iter().any(|s| s == "RDEVA117"), "{cmds:?}");

    // The snippet, pasted into a config, reads a line with the normal client.
    let doc: toml::Table = toml::from_str(&snippet).unwrap();
    let o: CommandOverrides = doc["instrument"]["commands"].clone().try_into().unwrap();
    let mut c = client(
        &link,
        ModelTable::with_overrides(ModelId::Sj210, &o).unwrap(),
    );
    let line = c.trace_line().await.unwrap();
    assert_eq!(line.profile.heights_um.len(), 1067);
    drop(c);
    sim.shutdown().await;

    // The transcript is a fixture: the simulator replaying it answers a second probe the
    // same way, verdict for verdict.
    let replay_dir = tempfile::tempdir().unwrap();
    let replay_link = replay_dir.path().join("sj210");
    let replay = crate::common::started(
        Simulator::new(&replay_link)
            .replay(surfscan_sim::replay::Transcript::parse(&text).unwrap(), 1.0)
            .pacing_time_scale(0.0),
    )
    .await;
    let cfg_replay = config(replay_dir.path(), "probe.toml", &replay_link, "");
    let (code, again, stderr) = run_probe(&[
        "--config",
        cfg_replay.to_str().unwrap(),
        "--trace",
        "--readout",
    ])
    .await;
    assert_eq!(code, Some(0), "stdout:\n{again}\nstderr:\n{stderr}");
    let verdicts = |out: &str| -> Vec<String> {
        out.lines()
            .filter(|l| l.starts_with("readout ") || l.starts_with("verdict "))
            .map(str::to_owned)
            .collect()
    };
    assert_eq!(verdicts(&again), verdicts(&stdout));
    assert_eq!(verdicts(&stdout).len(), 5, "{stdout}");
    replay.shutdown().await;
}

#[tokio::test]
async fn probe_readout_binary_without_any_form_exits_1_with_the_guidance() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = InstrumentConfig {
        profile_readout: false,
        ..InstrumentConfig::default()
    };
    let sim = start(dir.path(), cfg, None).await;
    let cfg_path = config(dir.path(), "probe.toml", &dir.path().join("sj210"), "");
    let (code, stdout, stderr) = run_probe(&[
        "--config",
        cfg_path.to_str().unwrap(),
        "--trace",
        "--readout",
        "--form",
        "RDEVA101=RDEVA1{n}",
    ])
    .await;
    assert_eq!(code, Some(1), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert_eq!(
        stdout.matches(": NG030: no such command").count(),
        4,
        "{stdout}"
    );
    assert!(stdout.contains("verdict   no read-out command"), "{stdout}");
    assert!(
        stdout.contains("next      ") && stdout.contains("--passthrough"),
        "{stdout}"
    );
    assert!(!stdout.contains("\n[instrument.commands]\n"), "{stdout}");
    assert!(
        stderr.contains("no profile read-out form works"),
        "{stderr}"
    );
    sim.shutdown().await;
}

#[tokio::test]
async fn passthrough_relays_the_pc_tools_session_and_records_it() {
    let dir = tempfile::tempdir().unwrap();
    let sim = start(dir.path(), InstrumentConfig::default(), None).await;
    // The PC tool's side: a second pty; the test writes what the PC software would send.
    let pc_link = dir.path().join("pc");
    let mut pc = surfscan_sim::pty::Pty::create(&pc_link).unwrap();
    let cfg_path = config(dir.path(), "probe.toml", &dir.path().join("sj210"), "");
    let record = dir.path().join("capture.transcript");
    let mut child = tokio::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["probe", "--config"])
        .arg(&cfg_path)
        .arg("--passthrough")
        .arg(&pc_link)
        .arg("--record")
        .arg(&record)
        .arg("--for-s")
        .arg("30")
        .stdout(std::process::Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .unwrap();
    let mut out = tokio::io::BufReader::new(child.stdout.take().unwrap());
    let mut first = String::new();
    tokio::time::timeout(
        EVENT_WAIT,
        tokio::io::AsyncBufReadExt::read_line(&mut out, &mut first),
    )
    .await
    .expect("the pass-through announces itself")
    .unwrap();
    assert!(first.starts_with("passthrough relaying"), "{first}");
    let mut ask = async |cmd: &[u8]| -> Vec<u8> {
        pc.write_all(cmd).await.unwrap();
        let mut reply = Vec::new();
        let mut b = [0u8; 1];
        while reply.last() != Some(&b'\r') {
            tokio::time::timeout(EVENT_WAIT, pc.read_exact(&mut b))
                .await
                .expect("a reply through the relay")
                .unwrap();
            reply.push(b[0]);
        }
        reply
    };
    assert_eq!(ask(b"RDSTU00\r").await, b"OK000\r");
    assert_eq!(ask(b"RDSJ 01\r").await, b"OKV1.00\r");
    assert_eq!(ask(b"RDEVA00\r").await, b"NG101\r");
    // The PC software goes away: the relay ends and the transcript is written.
    drop(pc);
    let status = tokio::time::timeout(Duration::from_secs(20), child.wait())
        .await
        .expect("the pass-through ends when the PC side closes")
        .unwrap();
    assert!(status.success(), "{status}");
    let text = std::fs::read_to_string(&record).unwrap();
    assert!(text.contains("# instrument: pass-through"), "{text}");
    let t = surfscan_sim::replay::Transcript::parse(&text).unwrap();
    let frames: Vec<(bool, Vec<u8>)> = t
        .entries
        .iter()
        .map(|e| {
            (
                e.dir == surfscan_sim::replay::Dir::ToDevice,
                e.bytes.clone(),
            )
        })
        .collect();
    assert_eq!(
        frames,
        vec![
            (true, b"RDSTU00\r".to_vec()),
            (false, b"OK000\r".to_vec()),
            (true, b"RDSJ 01\r".to_vec()),
            (false, b"OKV1.00\r".to_vec()),
            (true, b"RDEVA00\r".to_vec()),
            (false, b"NG101\r".to_vec()),
        ]
    );
    sim.shutdown().await;
}

/// A config whose port does not exist: a probe that got as far as opening it would exit 69,
/// so a 78 shows the value was refused before any device was touched.
fn absent_port_config(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("bad.toml");
    std::fs::write(
        &p,
        format!("[instrument]\nport = \"/nonexistent/sj210\"\n{text}"),
    )
    .unwrap();
    p
}

#[tokio::test]
async fn probe_refuses_out_of_range_instrument_values_before_opening_the_port() {
    let dir = tempfile::tempdir().unwrap();
    // The timeouts would have overflowed a deadline (a panic); the pitches make every count
    // and Ra check meaningless.
    for (text, key) in [
        ("baud = 38400\npitch-x-um = 1e-9\n", "instrument.pitch-x-um"),
        (
            "baud = 38400\npitch-x-um = 1e300\n",
            "instrument.pitch-x-um",
        ),
        (
            "baud = 38400\n[instrument.timeouts]\nfirst-byte-ms = 9000000000000000000\n",
            "instrument.timeouts.first-byte-ms",
        ),
        (
            "baud = 38400\n[instrument.timeouts]\ntrace-deadline-ms = 9000000000000000000\n",
            "instrument.timeouts.trace-deadline-ms",
        ),
        ("baud = 7\n", "instrument.baud"),
    ] {
        let cfg = absent_port_config(dir.path(), text);
        let (code, stdout, stderr) =
            run_probe(&["--config", cfg.to_str().unwrap(), "--readout"]).await;
        assert_eq!(
            code,
            Some(78),
            "{key}: stdout:\n{stdout}\nstderr:\n{stderr}"
        );
        assert!(
            stderr.contains(key) && stderr.contains("valid range"),
            "{key}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[tokio::test]
async fn probe_refuses_bad_arguments_as_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = absent_port_config(dir.path(), "baud = 38400\n");
    let cfg = cfg.to_str().unwrap();
    for (rest, says) in [
        (
            "--passthrough /dev/null --record x --for-s 1e300",
            "--for-s",
        ),
        ("--passthrough /dev/null --record x --for-s 0", "--for-s"),
        ("--passthrough /dev/null --record x --for-s nan", "--for-s"),
        ("--readout --form RDEVA", "does not end in 00"),
        ("--readout --form RDX00=RDX", "must hold {n}"),
    ] {
        let args: Vec<&str> = ["--config", cfg]
            .into_iter()
            .chain(rest.split(' '))
            .collect();
        let (code, stdout, stderr) = run_probe(&args).await;
        assert_eq!(
            code,
            Some(2),
            "{args:?}: stdout:\n{stdout}\nstderr:\n{stderr}"
        );
        assert!(stderr.contains(says), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

/// A simulator whose drive runs at a tenth of real time (a trace of the bundled window:
/// 1.6 mm + λc 2.5 mm, 0.82 s out and 0.41 s back), long enough for the reads asked during
/// the return to come back before it ends; and a config whose speeds say so.
async fn start_slow(dir: &Path, reads_during_return: bool) -> (SimHandle, PathBuf) {
    let link = dir.join("sj210");
    let sim = crate::common::started(Simulator::new(&link).instrument(InstrumentConfig {
        time_scale: 0.1,
        reads_during_return,
        ..InstrumentConfig::default()
    }))
    .await;
    let cfg = dir.join("slow.toml");
    std::fs::write(
        &cfg,
        format!(
            "[instrument]\nport = \"{}\"\nmeasuring-speed-mm-s = 5.0\nreturn-speed-mm-s = 10.0\n[instrument.timeouts]\npoll-interval-ms = 20\nread-retry-budget-ms = 2000\n",
            link.display()
        ),
    )
    .unwrap();
    (sim, cfg)
}

#[tokio::test]
async fn probe_readout_finds_an_instrument_that_answers_during_the_return_and_says_what_to_paste() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, cfg) = start_slow(dir.path(), true).await;
    let stats = sim.stats();
    let (code, stdout, stderr) =
        run_probe(&["--config", cfg.to_str().unwrap(), "--trace", "--readout"]).await;
    assert_eq!(code, Some(0), "stdout:\n{stdout}\nstderr:\n{stderr}");
    // The SJ-210 table has no read-out: the first candidate form is tried during the return.
    for read in ["RDRES02,01,00", "RDEVA00", "RDEVA50"] {
        assert!(
            stdout.contains(&format!(
                "return    {read} while the drive returned: answered"
            )),
            "{read}: {stdout}"
        );
    }
    assert!(
        stdout.contains("status after the reads: 002, still returning"),
        "{stdout}"
    );
    assert!(
        stdout.contains("answers the read-out while its drive returns"),
        "{stdout}"
    );
    // The instrument itself says the three reads came while it returned.
    assert!(
        surfscan_sim::stats::SimStats::get(&stats.reads_answered_returning) >= 3,
        "{stats:?}"
    );
    // One snippet: the read-out form and the return key, in one [instrument.commands] table
    // that parses as the config's own.
    let at = stdout.find("\n[instrument.commands]\n").expect("snippet") + 1;
    let snippet: String = stdout[at..]
        .lines()
        .take_while(|l| !l.starts_with("transcript") && !l.starts_with("next"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(
        snippet.ends_with("reads-during-return = true\n"),
        "{snippet}"
    );
    let doc: toml::Table = toml::from_str(&snippet).unwrap();
    let o: CommandOverrides = doc["instrument"]["commands"].clone().try_into().unwrap();
    let t = ModelTable::with_overrides(ModelId::Sj210, &o).unwrap();
    assert!(t.reads_during_return);
    assert_eq!(t.commands.profile_total.unwrap().template, "RDEVA00");
    sim.shutdown().await;
}

#[tokio::test]
async fn probe_readout_finds_an_instrument_that_refuses_reads_during_the_return() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, cfg) = start_slow(dir.path(), false).await;
    let stats = sim.stats();
    let (code, stdout, stderr) =
        run_probe(&["--config", cfg.to_str().unwrap(), "--trace", "--readout"]).await;
    // The read-out itself works once the drive is back.
    assert_eq!(code, Some(0), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(
        stdout.contains("return    RDRES02,01,00 while the drive returned: refused NG011"),
        "{stdout}"
    );
    assert!(
        stdout.contains(
            "refuses reads while its drive returns (NG011): leave reads-during-return off"
        ),
        "{stdout}"
    );
    assert!(
        stdout.contains("verdict   RDEVA00 reads the profile"),
        "{stdout}"
    );
    assert!(!stdout.contains("reads-during-return = true"), "{stdout}");
    assert!(surfscan_sim::stats::SimStats::get(&stats.reads_refused_returning) >= 1);
    assert_eq!(
        surfscan_sim::stats::SimStats::get(&stats.reads_answered_returning),
        0
    );
    sim.shutdown().await;
}
