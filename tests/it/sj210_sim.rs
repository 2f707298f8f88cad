//! End to end: the SJ-210 client, over the real serial transport, against `surfscan-sim`
//! running in-process on a pseudo-terminal. Each test starts its own simulator, waits for its
//! ready event (never a fixed sleep), and checks one path of the driver: a clean trace with
//! profile read-out, each injected fault with its named error or recovery, a model without
//! profile read-out, and the `surfscan probe` binary with its replayable transcript.
//!
//! Expected heights come from the simulator's fixture rounded to the printed decimals; expected
//! results from a plain re-computation of the simulator's documented definitions (the served
//! R profile about a zero mean line, as the instrument exports it: Ra = mean |z|, Rq = rms).
//!
//! Depends on the public API of `surfscan` (transport, `sj210`, `devices`) and of
//! `surfscan-sim` (builder, fault specs, bundled profiles, transcript reader), nothing else.

use crate::common::append_config;
use std::path::{Path, PathBuf};
use std::time::Duration;
use surfscan::devices::{
    Battery, DeviceFault, FaultClass, Instrument, ProfileReadout, ReadoutWarning, RepeatedBlock,
};
use surfscan::sj210::client::Sj210Client;
use surfscan::sj210::error::{LinkError, Sj210Error};
use surfscan::sj210::models::{CommandOverrides, ModelId, ModelTable};
use surfscan::sj210::settings::ClientOptions;
use surfscan::transport::{self, FlowControl, Parity, SerialSettings};
use surfscan_sim::{FaultSpec, InstrumentConfig, ProfileSet, SimEvent, SimHandle, Simulator};
use tokio_serial::SerialStream;

const EVENT_WAIT: Duration = Duration::from_secs(10);

fn options() -> ClientOptions {
    ClientOptions {
        first_byte: Duration::from_millis(800),
        inter_byte: Duration::from_millis(200),
        poll_interval: Duration::from_millis(10),
        start_deadline: Duration::from_millis(1500),
        read_retry_budget: Duration::from_millis(1000),
        trace_deadline: Some(Duration::from_secs(10)),
        // The x pitch is not on the wire: the config gives the fixture's.
        pitch_x_um: Some(fixture_pitch_um()),
        ..ClientOptions::default()
    }
}

fn fixture_pitch_um() -> f64 {
    ProfileSet::bundled().unwrap().profiles()[0].pitch_x_mm * 1000.0
}

fn fast_config() -> InstrumentConfig {
    InstrumentConfig {
        time_scale: 0.02,
        ..InstrumentConfig::default()
    }
}

struct Rig {
    _dir: tempfile::TempDir,
    link: PathBuf,
    sim: SimHandle,
}

/// Starts a simulator with `cfg` and the given fault specs, and waits for its ready event.
async fn start(mut cfg: InstrumentConfig, faults: &[&str]) -> Rig {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("sj210");
    let mut wire = Vec::new();
    for f in faults {
        match f.parse::<FaultSpec>().unwrap() {
            FaultSpec::Wire(w) => wire.push(w),
            FaultSpec::BatteryLow => cfg.battery = surfscan_sim::Battery::Low,
            FaultSpec::BatteryAbnormal => cfg.battery = surfscan_sim::Battery::Abnormal,
        }
    }
    let mut b = Simulator::new(&link).instrument(cfg);
    for w in wire {
        b = b.fault(w);
    }
    let mut sim = b.start().unwrap();
    match tokio::time::timeout(EVENT_WAIT, sim.next_event()).await {
        Ok(Some(SimEvent::Ready(r))) => assert_eq!(r.instrument.as_deref(), Some(link.as_path())),
        other => panic!("expected the ready event, got {other:?}"),
    }
    Rig {
        _dir: dir,
        link,
        sim,
    }
}

fn open(link: &Path) -> Sj210Client<SerialStream> {
    let port = transport::open(&SerialSettings {
        path: link.display().to_string(),
        baud: 38400,
        parity: Parity::None,
        flow_control: FlowControl::None,
    })
    .unwrap();
    Sj210Client::new(port, readout_table(), options())
}

/// The SJ-210 table with the profile read-out commands the reference suggests trying
/// (`RDEVA00` total, `RDEVAnn` blocks), set as a config override would set them.
fn readout_table() -> ModelTable {
    let o = CommandOverrides {
        profile_total: Some("RDEVA00".into()),
        profile_block: Some("RDEVA{n}".into()),
        ..CommandOverrides::default()
    };
    ModelTable::with_overrides(ModelId::Sj210, &o).unwrap()
}

/// The first bundled profile (what the first trace without a stage serves), rounded to the
/// 3 printed decimals.
fn fixture_line(index: usize) -> Vec<f64> {
    let set = ProfileSet::bundled().unwrap();
    set.profiles()[index]
        .z_um
        .iter()
        .map(|z| (z * 1000.0).round() / 1000.0)
        .collect()
}

fn ra_rq(z: &[f64]) -> (f64, f64) {
    let n = z.len() as f64;
    let ra = z.iter().map(|v| v.abs()).sum::<f64>() / n;
    let rq = (z.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    (ra, rq)
}

fn result(line: &surfscan::devices::TracedLine, name: &str) -> f64 {
    line.results
        .iter()
        .find(|r| r.name == name)
        .and_then(|r| r.value)
        .unwrap_or_else(|| panic!("no {name} in {:?}", line.results))
}

/// Checks a traced line is the `index`-th fixture line with matching results.
fn assert_line(line: &surfscan::devices::TracedLine, index: usize) {
    let expected = fixture_line(index);
    assert_eq!(line.profile.heights_um.len(), expected.len());
    for (i, (got, want)) in line.profile.heights_um.iter().zip(&expected).enumerate() {
        assert!((got - want).abs() < 5e-7, "point {i}: {got} vs {want}");
    }
    let set = ProfileSet::bundled().unwrap();
    let served = &set.profiles()[index];
    assert!(
        (line.profile.pitch_x_mm - served.pitch_x_mm).abs() < 1e-9,
        "pitch {} mm, fixture {} mm",
        line.profile.pitch_x_mm,
        served.pitch_x_mm
    );
    assert_eq!(line.pitch_source, "config");
    let (ra, rq) = ra_rq(&served.z_um);
    // Results are printed with a few decimals in 7 characters: compare to 0.5 % or 2 nm.
    let close = |a: f64, b: f64| (a - b).abs() <= (0.005 * b.abs()).max(0.002);
    assert!(
        close(result(line, "Ra"), ra),
        "Ra {} vs {ra}",
        result(line, "Ra")
    );
    assert!(
        close(result(line, "Rq"), rq),
        "Rq {} vs {rq}",
        result(line, "Rq")
    );
}

#[tokio::test]
async fn clean_trace_reads_the_fixture_profile_and_results() {
    let rig = start(fast_config(), &[]).await;
    let mut c = open(&rig.link);
    let report = c.probe().await.unwrap();
    assert_eq!(report.battery, Battery::Good);
    assert_eq!(report.identity.firmware, "V1.00");
    assert!(matches!(
        report.profile_readout,
        ProfileReadout::Supported { .. }
    ));
    assert_eq!(report.parameter_count, 9);
    let line = c.trace().await.unwrap();
    assert_line(&line, 0);
    let line2 = c.trace().await.unwrap();
    assert_line(&line2, 1);
    rig.sim.shutdown().await;
}

/// Probe, then one trace that must succeed despite `faults` and serve fixture line 0.
async fn trace_recovers(faults: &[&str]) -> surfscan::devices::TracedLine {
    let rig = start(fast_config(), faults).await;
    let mut c = open(&rig.link);
    c.probe().await.unwrap();
    let line = c
        .trace()
        .await
        .unwrap_or_else(|e| panic!("{faults:?}: {e}"));
    assert_line(&line, 0);
    rig.sim.shutdown().await;
    line
}

/// Probe, then one trace that must fail; returns the error.
async fn trace_fails(faults: &[&str]) -> Sj210Error {
    let rig = start(fast_config(), faults).await;
    let mut c = open(&rig.link);
    c.probe().await.unwrap();
    let e = match c.trace().await {
        Ok(_) => panic!("{faults:?}: the trace succeeded"),
        Err(e) => e,
    };
    rig.sim.shutdown().await;
    e
}

#[tokio::test]
async fn busy_and_not_ready_codes_on_reads_are_retried() {
    trace_recovers(&["ng:011@RDRES#1x2"]).await;
    trace_recovers(&["ng:033@RDPAR#1x1"]).await;
    trace_recovers(&["ng:101@RDRES#2x2"]).await;
}

#[tokio::test]
async fn busy_on_start_is_not_retried() {
    let e = trace_fails(&["ng:011@CTSTA"]).await;
    assert_eq!(e.code().map(|c| c.code()), Some(11), "{e}");
}

#[tokio::test]
async fn over_range_is_named_with_the_detector_position() {
    let e = trace_fails(&["ng:007@CTSTA"]).await;
    match e {
        Sj210Error::OverRange { position } => assert!(position.is_some()),
        other => panic!("expected OverRange, got {other}"),
    }
    let e = trace_fails(&["ng:007@RDSTU00%1#2"]).await;
    assert!(matches!(e, Sj210Error::OverRange { .. }), "{e}");
}

#[tokio::test]
async fn profile_block_error_restarts_the_read_out_once() {
    // NG020 on the first block: the read-out restarts from the total and succeeds.
    let line = trace_recovers(&["ng:020@RDEVA%1#2"]).await;
    assert!(
        line.warnings.iter().any(|w| w.contains("restarted")),
        "{:?}",
        line.warnings
    );
    // Errors on both attempts: the line must be re-traced, with the NG code named.
    let e = trace_fails(&["ng:020@RDEVA%1#2", "ng:020@RDEVA%1#4"]).await;
    assert!(matches!(e, Sj210Error::ProfileReadoutFailed { .. }), "{e}");
    assert_eq!(e.code().map(|c| c.code()), Some(20));
}

#[tokio::test]
async fn dropped_truncated_garbage_and_split_replies() {
    // A dropped or truncated status poll during the trace: recovery, polling goes on.
    trace_recovers(&["drop@RDSTU00%1#2"]).await;
    trace_recovers(&["truncate@RDSTU00%1#2"]).await;
    // A reply split across reads is reassembled; a stray LF is tolerated.
    trace_recovers(&["split@RDEVA%1#2x3", "split@RDRES", "lf@RDRES#2"]).await;
    // Garbage before a block reply: malformed, the read-out restarts once and succeeds.
    let line = trace_recovers(&["garbage@RDEVA%1#3"]).await;
    assert!(line.warnings.iter().any(|w| w.contains("restarted")));
    // A dropped block reply: first-byte timeout, restart, success.
    trace_recovers(&["drop@RDEVA%1#2"]).await;
}

#[tokio::test]
async fn dropped_and_truncated_read_replies_are_named() {
    let rig = start(fast_config(), &["drop@RDSJ 01", "truncate@RDCON"]).await;
    let mut c = open(&rig.link);
    match c.command("RDSJ 01", true).await {
        Err(Sj210Error::Link {
            source: LinkError::FirstByteTimeout { .. },
            ..
        }) => {}
        other => panic!("expected a first-byte timeout, got {other:?}"),
    }
    match c.command("RDCON", true).await {
        Err(Sj210Error::Link {
            source: LinkError::InterByteTimeout { partial, .. },
            ..
        }) => assert!(partial.starts_with("OK"), "{partial}"),
        other => panic!("expected an inter-byte timeout, got {other:?}"),
    }
    // After recovery the link is clean: the next reads answer normally.
    assert_eq!(c.command("RDSJ 01", true).await.unwrap(), "V1.00");
    assert_eq!(c.status().await.unwrap(), 0);
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn long_silence_times_out_then_the_link_recovers() {
    let rig = start(fast_config(), &["silence:1300@RDSTU01"]).await;
    let mut c = open(&rig.link);
    match c.command("RDSTU01", true).await {
        Err(Sj210Error::Link {
            source: LinkError::FirstByteTimeout { waited_ms },
            ..
        }) => assert_eq!(waited_ms, 800),
        other => panic!("expected a first-byte timeout, got {other:?}"),
    }
    // The late reply is drained by the recovery, not mistaken for the next answer.
    assert_eq!(c.command("RDSJ 01", true).await.unwrap(), "V1.00");
    let line = c.trace().await.unwrap();
    assert_line(&line, 0);
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn device_vanishing_mid_trace_is_absent_and_comes_back() {
    let mut rig = start(fast_config(), &["unplug:200@RDSTU00%1#2"]).await;
    let mut c = open(&rig.link);
    c.probe().await.unwrap();
    let e = c.trace().await.expect_err("the trace must fail");
    assert!(
        matches!(
            &e,
            Sj210Error::Link {
                source: LinkError::Vanished { .. },
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(e.class(), FaultClass::Absent);
    drop(c);
    let mut seen = Vec::new();
    loop {
        match tokio::time::timeout(EVENT_WAIT, rig.sim.next_event()).await {
            Ok(Some(SimEvent::Replugged { instrument })) => {
                assert_eq!(instrument, rig.link);
                break;
            }
            Ok(Some(ev)) => seen.push(ev),
            other => panic!("no replug event (saw {seen:?}): {other:?}"),
        }
    }
    assert!(
        seen.iter().any(|e| matches!(e, SimEvent::Unplugged { .. })),
        "{seen:?}"
    );
    // A fresh instrument on a new pty at the same link: probe and trace work again.
    let mut c = open(&rig.link);
    c.probe().await.unwrap();
    let line = c.trace().await.unwrap();
    assert!(!line.profile.heights_um.is_empty());
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn battery_low_warns_and_abnormal_refuses() {
    let rig = start(fast_config(), &["battery:low"]).await;
    let mut c = open(&rig.link);
    let report = c.probe().await.unwrap();
    assert_eq!(report.battery, Battery::Low);
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.to_lowercase().contains("battery")),
        "{:?}",
        report.warnings
    );
    assert_line(&c.trace().await.unwrap(), 0);
    rig.sim.shutdown().await;

    let rig = start(fast_config(), &["battery:abnormal"]).await;
    let mut c = open(&rig.link);
    let e = c.probe().await.expect_err("probe must refuse");
    assert!(matches!(e, Sj210Error::BatteryAbnormal), "{e}");
    // A trace is refused without moving the stylus.
    assert!(matches!(c.trace().await, Err(Sj210Error::BatteryAbnormal)));
    assert_eq!(c.status().await.unwrap(), 0);
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn model_without_profile_readout_fails_at_probe_naming_the_code() {
    let cfg = InstrumentConfig {
        profile_readout: false,
        ..fast_config()
    };
    let rig = start(cfg, &[]).await;
    let mut c = open(&rig.link);
    let report = c.probe_report().await.unwrap();
    match &report.profile_readout {
        ProfileReadout::Unsupported { ng_code, advice } => {
            assert_eq!(*ng_code, Some(30));
            assert!(!advice.is_empty());
        }
        other => panic!("expected unsupported, got {other:?}"),
    }
    let e = c.probe().await.expect_err("probe must refuse");
    match &e {
        Sj210Error::ProfileUnsupported { ng_code, .. } => assert_eq!(*ng_code, Some(30)),
        other => panic!("expected ProfileUnsupported, got {other}"),
    }
    assert!(e.to_string().contains("030"), "{e}");
    // The SJ-210 table as documented has no read-out command at all: said so, with the
    // operator's options, without sending anything that could fail mid-scan.
    let port = c.into_inner();
    let mut plain = Sj210Client::new(port, ModelTable::builtin(ModelId::Sj210), options());
    match plain.probe().await.expect_err("probe must refuse") {
        Sj210Error::ProfileUnsupported { ng_code, advice } => {
            assert_eq!(ng_code, None);
            assert!(advice.contains("SJ-410"), "{advice}");
            assert!(advice.contains("profile-total"), "{advice}");
        }
        other => panic!("expected ProfileUnsupported, got {other}"),
    }
    rig.sim.shutdown().await;
}

/// Runs `surfscan probe --config CONFIG --record RECORD` (the real binary) and returns its exit
/// code and standard output.
async fn run_probe_binary(config: &Path, record: &Path) -> (Option<i32>, String, String) {
    let args = [
        "--config".as_ref(),
        config.as_os_str(),
        "--record".as_ref(),
        record.as_os_str(),
    ];
    crate::common::run_probe::<&std::ffi::OsStr>(&args, 30).await
}

fn probe_config(dir: &Path, name: &str, link: &Path) -> PathBuf {
    let config = dir.join(name);
    std::fs::write(
        &config,
        format!(
            "[instrument]\nport = \"{}\"\nbaud = 38400\n[instrument.timeouts]\nfirst-byte-ms = 2000\n[instrument.commands]\nprofile-total = \"RDEVA00\"\nprofile-block = \"RDEVA{{n}}\"\n",
            link.display()
        ),
    )
    .unwrap();
    config
}

/// The commands (host → device lines) of a transcript, in order.
fn commands_of(t: &surfscan_sim::replay::Transcript) -> Vec<Vec<u8>> {
    t.entries
        .iter()
        .filter(|e| e.dir == surfscan_sim::replay::Dir::ToDevice)
        .map(|e| e.bytes.clone())
        .collect()
}

#[tokio::test]
async fn probe_binary_summarises_and_its_transcript_replays() {
    let cfg = InstrumentConfig {
        firmware: "V2.34".into(),
        ..fast_config()
    };
    let rig = start(cfg, &["battery:low"]).await;
    let dir = tempfile::tempdir().unwrap();
    let config = probe_config(dir.path(), "probe.toml", &rig.link);
    let record = dir.path().join("first.txt");
    let (code, stdout, stderr) = run_probe_binary(&config, &record).await;
    assert_eq!(code, Some(0), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(stdout.contains("V2.34"), "{stdout}");
    assert!(stdout.contains("battery   low (below 60 %)"), "{stdout}");
    assert!(stdout.contains("read-out supported"), "{stdout}");
    assert!(stdout.contains("parameters 9"), "{stdout}");
    assert!(stdout.contains("transcript written"), "{stdout}");
    rig.sim.shutdown().await;

    // The simulator parses the transcript with its own reader.
    let text = std::fs::read_to_string(&record).unwrap();
    let first = surfscan_sim::replay::Transcript::parse(&text).unwrap();
    let sent = commands_of(&first);
    assert!(sent.iter().any(|c| c.starts_with(b"RDSJ 01")), "{sent:?}");
    assert!(sent.iter().any(|c| c.starts_with(b"RDEVA00")), "{sent:?}");
    // Read-only: nothing that moves the stylus.
    assert!(!sent.iter().any(|c| c.starts_with(b"CTSTA")), "{sent:?}");
    assert!(!sent.iter().any(|c| c.starts_with(b"CTRTN")), "{sent:?}");

    // Replaying it: the same checklist runs against the recording and sees the same answers.
    let link = dir.path().join("replayed");
    let mut sim = Simulator::new(&link)
        .replay(first.clone(), 0.0)
        .start()
        .unwrap();
    match tokio::time::timeout(EVENT_WAIT, sim.next_event()).await {
        Ok(Some(SimEvent::Ready(r))) => assert_eq!(r.model, "replay"),
        other => panic!("expected the ready event, got {other:?}"),
    }
    let config = probe_config(dir.path(), "replay.toml", &link);
    let record2 = dir.path().join("second.txt");
    let (code, stdout2, stderr2) = run_probe_binary(&config, &record2).await;
    assert_eq!(code, Some(0), "stdout:\n{stdout2}\nstderr:\n{stderr2}");
    sim.shutdown().await;
    let summary = |s: &str| -> Vec<String> {
        s.lines()
            .filter(|l| !l.starts_with("link") && !l.starts_with("transcript"))
            .map(str::to_string)
            .collect()
    };
    assert_eq!(summary(&stdout2), summary(&stdout));
    let second =
        surfscan_sim::replay::Transcript::parse(&std::fs::read_to_string(&record2).unwrap())
            .unwrap();
    assert_eq!(commands_of(&second), sent);
    let replies = |t: &surfscan_sim::replay::Transcript| -> Vec<Vec<u8>> {
        t.entries
            .iter()
            .filter(|e| e.dir == surfscan_sim::replay::Dir::ToHost)
            .map(|e| e.bytes.clone())
            .collect()
    };
    assert_eq!(replies(&second), replies(&first));
}

fn open_with(link: &Path, opts: ClientOptions) -> Sj210Client<SerialStream> {
    let port = transport::open(&SerialSettings {
        path: link.display().to_string(),
        baud: 38400,
        parity: Parity::None,
        flow_control: FlowControl::None,
    })
    .unwrap();
    Sj210Client::new(port, readout_table(), opts)
}

#[tokio::test]
async fn a_point_count_that_does_not_fit_the_conditions_is_named_and_fatal() {
    let mut cfg = fast_config();
    // λc 2.5 mm × N = 5 at λs 8 µm: 5 × floor(2.5 mm / 1.5 µm) = 8330 points expected, but
    // the bundled windows have 1067.
    cfg.conditions.sampling_lengths = 5;
    let rig = start(cfg, &[]).await;
    let opts = ClientOptions {
        pitch_x_um: None,
        ..options()
    };
    let mut c = open_with(&rig.link, opts.clone());
    c.probe().await.unwrap();
    let e = c
        .trace()
        .await
        .expect_err("the count does not fit N 5 x 1666");
    match &e {
        Sj210Error::PointCount {
            mismatch,
            pitch_source,
        } => {
            assert_eq!(mismatch.received, fixture_line(0).len());
            assert_eq!(mismatch.expected.points, 8330);
            assert_eq!(mismatch.expected.per_sampling_length, 1666);
            assert!(pitch_source.contains("lambda-s"), "{pitch_source}");
        }
        other => panic!("expected PointCount, got {other}"),
    }
    assert_eq!(e.class(), FaultClass::Fatal);
    let m = e.to_string();
    assert!(m.contains("8330") && m.contains("pitch-x-um"), "{m}");
    drop(c);

    // With the check switched off the line is kept: pitch from λs 8 µm is 1.5 µm (ISO 3274),
    // and the length warning says the points do not cover N × λc.
    let mut c = open_with(
        &rig.link,
        ClientOptions {
            check_point_count: false,
            ..opts
        },
    );
    c.probe().await.unwrap();
    let line = c.trace().await.unwrap();
    assert!((line.profile.pitch_x_mm - 0.0015).abs() < 1e-12);
    assert!(
        line.pitch_source.contains("lambda-s"),
        "{}",
        line.pitch_source
    );
    let cond = &line.profile.conditions;
    assert_eq!(cond.lambda_c_mm, Some(2.5));
    assert_eq!(cond.lambda_s_um, Some(8.0));
    assert_eq!(cond.evaluation_length_mm, Some(12.5));
    assert!(
        line.warnings
            .iter()
            .any(|w| w.contains("evaluation length")),
        "{:?}",
        line.warnings
    );
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn the_mitutoyo_r_profile_under_its_conditions_is_6664_points_at_1_5_um() {
    // The simulator serves the whole bundled export under the conditions it was recorded
    // with: λc 2.5 mm, N 4 (λs 8 µm on the SJ-210). No pitch is configured: the rule gives it.
    let mut cfg = fast_config();
    cfg.conditions.sampling_lengths = 4;
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("sj210");
    let set = ProfileSet::bundled_mitutoyo_r().unwrap();
    let served: Vec<f64> = set.profiles()[0]
        .z_um
        .iter()
        .map(|z| (z * 1000.0).round() / 1000.0)
        .collect();
    let sim = crate::common::started(Simulator::new(&link).instrument(cfg).profiles(set)).await;
    let mut c = open_with(
        &link,
        ClientOptions {
            pitch_x_um: None,
            ..options()
        },
    );
    c.probe().await.unwrap();
    let line = c.trace().await.unwrap();
    assert_eq!(line.profile.heights_um.len(), 6664);
    assert_eq!(line.profile.heights_um, served);
    assert!((line.profile.pitch_x_mm - 0.0015).abs() < 1e-12);
    assert_eq!(line.profile.conditions.sampling_lengths, Some(4));
    assert!(line.warnings.is_empty(), "{:?}", line.warnings);
    // The simulator prints its results in the export's layout; the value is read by trimming.
    let (ra, _) = ra_rq(&served);
    assert!(
        (result(&line, "Ra") - ra).abs() <= 0.0005 + 1e-9,
        "Ra {}",
        result(&line, "Ra")
    );
    // Heights in ASCII "um"; the ratios Rsk and Rku without a unit.
    assert!(
        line.results.iter().all(|r| r.unit
            == if r.name.starts_with("Rsk") || r.name.starts_with("Rku") {
                ""
            } else {
                "um"
            }),
        "{:?}",
        line.results
    );
    sim.shutdown().await;
}

#[tokio::test]
async fn sj410_table_reads_the_sj410_emulation() {
    let cfg = InstrumentConfig {
        model: surfscan_sim::Model::Sj410,
        ..fast_config()
    };
    let rig = start(cfg, &[]).await;
    let port = transport::open(&SerialSettings {
        path: rig.link.display().to_string(),
        baud: 38400,
        parity: Parity::None,
        flow_control: FlowControl::None,
    })
    .unwrap();
    let mut c = Sj210Client::new(port, ModelTable::builtin(ModelId::Sj410), options());
    let report = c.probe().await.unwrap();
    assert_eq!(report.parameter_count, 9);
    let line = c.trace().await.unwrap();
    assert_line(&line, 0);
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn every_parameter_the_instrument_reports_is_in_the_line_as_printed() {
    let rig = start(fast_config(), &[]).await;
    let mut c = open(&rig.link);
    c.probe().await.unwrap();
    let line = c.trace().await.unwrap();
    // RDPAR says 9; one RDRES each, in the instrument's order, names and units as printed.
    let names: Vec<(&str, &str)> = line
        .results
        .iter()
        .map(|r| (r.name.as_str(), r.unit.as_str()))
        .collect();
    assert_eq!(names, surfscan_sim::roughness::PARAMETERS.to_vec());
    for r in &line.results {
        let printed = r.printed.as_deref().expect("printed text kept");
        // The value is the printed number; the printed text keeps its decimals.
        assert_eq!(printed.parse::<f64>().ok(), r.value, "{r:?}");
        assert!(printed.len() <= 6, "{r:?}");
        assert_eq!(r.ng_code, None);
    }
    // Independent checks of the simulator's definitions on the served heights (about zero).
    let z = fixture_line(0);
    let hi = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let lo = z.iter().copied().fold(f64::INFINITY, f64::min);
    let close = |a: f64, b: f64| (a - b).abs() <= (0.005 * b.abs()).max(0.002);
    assert!(
        close(result(&line, "Rt"), hi - lo),
        "Rt {}",
        result(&line, "Rt")
    );
    assert!(close(result(&line, "Rp"), hi), "Rp {}", result(&line, "Rp"));
    assert!(
        close(result(&line, "Rv"), -lo),
        "Rv {}",
        result(&line, "Rv")
    );
    assert!(
        line.readout_warnings.is_empty(),
        "{:?}",
        line.readout_warnings
    );
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn a_repeated_block_is_read_again_and_a_clean_second_read_kept() {
    // The 3rd block request of the first read-out answers the 2nd block again.
    let line = trace_recovers(&["repeat@RDEVA50#3"]).await;
    assert!(
        line.readout_warnings.is_empty(),
        "{:?}",
        line.readout_warnings
    );
    assert!(
        line.warnings.iter().any(|w| w.contains("read out again")
            && w.contains("repeated read-out block(s) 3 (from point 100)")),
        "{:?}",
        line.warnings
    );
    assert!(
        line.warnings
            .iter()
            .any(|w| w.contains("second read-out was clean")),
        "{:?}",
        line.warnings
    );
}

#[tokio::test]
async fn a_block_repeated_in_both_reads_is_kept_with_a_named_warning() {
    // 1067 points: 21 requests of 50 and one of 17 per read-out. The first read-out's 3rd and
    // the second read-out's 4th RDEVA50 (the 25th overall) repeat the block before them.
    let rig = start(fast_config(), &["repeat@RDEVA50#3", "repeat@RDEVA50#25"]).await;
    let mut c = open(&rig.link);
    c.probe().await.unwrap();
    let line = c.trace().await.unwrap();
    assert_eq!(
        line.readout_warnings,
        vec![ReadoutWarning::RepeatedBlock {
            blocks: vec![RepeatedBlock {
                block: 4,
                first_point: 150,
                values: 50
            }]
        }]
    );
    // The kept read-out is the second: points 150–199 repeat 100–149, later ones are shifted.
    let served = fixture_line(0);
    let h = &line.profile.heights_um;
    assert_eq!(h.len(), served.len());
    assert_eq!(h[..150], served[..150]);
    assert_eq!(h[150..200], served[100..150]);
    assert_eq!(h[200..], served[150..served.len() - 50]);
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn an_instrument_ra_that_disagrees_with_its_heights_is_kept_with_a_named_warning() {
    // The instrument's Ra answer is 20 % high; the heights are right.
    let rig = start(fast_config(), &["skew:20@RDRES02,01"]).await;
    let mut c = open(&rig.link);
    c.probe().await.unwrap();
    let line = c.trace().await.unwrap();
    let (ra, _) = ra_rq(&fixture_line(0));
    match line.readout_warnings.as_slice() {
        [ReadoutWarning::RaDisagrees {
            instrument_um,
            ours_um,
            tolerance_um,
        }] => {
            assert!(
                (instrument_um - 1.2 * ra).abs() < 0.002,
                "{instrument_um} vs {ra}"
            );
            assert!((ours_um - ra).abs() < 1e-9, "{ours_um} vs {ra}");
            // 2 % of the instrument's Ra + 0.005 µm for an R profile.
            assert!((tolerance_um - (0.02 * instrument_um + 0.005)).abs() < 1e-12);
        }
        other => panic!("expected one Ra warning, got {other:?}"),
    }
    // The profile was read a second time before the line was kept, and it is the served one.
    assert!(
        line.warnings.iter().any(|w| w.contains("read out again")),
        "{:?}",
        line.warnings
    );
    assert_eq!(line.profile.heights_um, fixture_line(0));
    rig.sim.shutdown().await;
}

#[tokio::test]
async fn a_read_out_warning_is_stored_with_the_line_it_belongs_to() {
    use crate::common::{run_scan, scan_dir, Rig, RigOptions};
    // Only the first line's instrument Ra is off; every line is kept, the first with the
    // named warning in its metadata file.
    let rig = Rig::start(RigOptions {
        lines: 4,
        faults: vec!["skew:25@RDRES02,01%1".into()],
        ..RigOptions::default()
    })
    .await;
    let o = run_scan(&rig.config("out"), &[]).await;
    assert!(o.status.success(), "{}", crate::common::describe(&o));
    let dir = scan_dir(&rig.out_dir("out"));
    let meta = |k: u32| crate::common::line_meta(&dir, k);
    let first = meta(0);
    let w = &first["readout_warnings"];
    assert_eq!(w.as_array().map(Vec::len), Some(1), "{first}");
    assert_eq!(w[0]["kind"], "ra-disagrees", "{first}");
    let (inst, ours) = (
        w[0]["instrument_um"].as_f64().unwrap(),
        w[0]["ours_um"].as_f64().unwrap(),
    );
    assert!((inst / ours - 1.25).abs() < 0.01, "{inst} vs {ours}");
    // The instrument's results are stored as printed, every one of them.
    assert_eq!(
        first["results"].as_array().map(Vec::len),
        Some(9),
        "{first}"
    );
    assert!(first["results"][0]["printed"].is_string(), "{first}");
    crate::common::assert_no_readout_warnings(&dir, 1..3);
    rig.shutdown().await;
}

/// A line served 1000× too large (heights and the instrument's own results with them, as
/// heights in nm read as µm): the Ra cross-check agrees, but the heights span far more than
/// the SJ-210's standard detector can measure (360 µm). The line is read again, then kept
/// with the named warning in its metadata and in the report; the other lines carry none.
#[tokio::test]
async fn a_line_1000_times_too_large_is_kept_with_a_named_warning_in_metadata_and_report() {
    use crate::common::{run_scan, scan_dir, Rig, RigOptions};
    let rig = Rig::start(RigOptions {
        lines: 4,
        // The third trace (line index 2).
        faults: vec!["scale:1000@CTSTA#3".into()],
        ..RigOptions::default()
    })
    .await;
    let o = run_scan(&rig.config("out"), &[]).await;
    // The scan completes; a model through a line 1000× the others' folds, so its
    // characterisation is partial and says so (exit 3).
    assert_eq!(o.status.code(), Some(3), "{}", crate::common::describe(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("scan complete"),
        "{}",
        crate::common::describe(&o)
    );
    let dir = scan_dir(&rig.out_dir("out"));
    let meta = |k: u32| crate::common::line_meta(&dir, k);
    let third = meta(2);
    let w = third["readout_warnings"].as_array().expect("warnings");
    let beyond: Vec<_> = w
        .iter()
        .filter(|w| w["kind"] == "beyond-detector-range")
        .collect();
    assert_eq!(beyond.len(), 1, "{third}");
    assert_eq!(beyond[0]["range_um"], 360.0, "{third}");
    // Independently: the stored heights (as served, 1000× the set's) span more than 360 µm.
    let csv = std::fs::read_to_string(dir.join("lines/0002.csv")).unwrap();
    let z: Vec<f64> = csv
        .lines()
        .filter_map(|l| l.split(',').next_back()?.trim().parse().ok())
        .collect();
    let span = z.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - z.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(span > 360.0, "span {span}");
    assert!(
        (beyond[0]["span_um"].as_f64().unwrap() - span).abs() < 1e-6 * span,
        "{third} vs {span}"
    );
    // The instrument's own Ra came with the heights: no Ra disagreement hid the fault.
    assert!(w.iter().all(|w| w["kind"] != "ra-disagrees"), "{third}");
    crate::common::assert_no_readout_warnings(&dir, [0, 1, 3]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    let warnings = crate::common::report_warnings(&report);
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("line 3 (0002)") && w.contains("detector's measuring range")),
        "{warnings:?}"
    );
    rig.shutdown().await;
}

/// The limit of the test recipe below: above every line's Ra as served, below the Ra of a
/// line served 10 times too large (both checked against report.json).
const RA_MAX_UM: f64 = 3.0;

/// A line served 10× too large after four good ones: within the detector's range and
/// agreeing with the instrument's own (equally scaled) Ra, so only its neighbours tell: its
/// Ra is more than 5 times the median of the lines before it. It is kept with that warning,
/// named in its metadata and the report; the lines around it carry none. The recipe's
/// `Ra1 max` limit is exceeded by that line alone: without it the part conforms, with it
/// it does not, so the verdict is "not decidable", naming line 5, in report.json, report.html,
/// summary.csv and the scan's own summary.
#[tokio::test]
async fn a_line_whose_ra_is_far_from_its_neighbours_is_kept_with_a_named_warning() {
    use crate::common::{describe, scan_command, scan_dir, Rig, RigOptions};
    let rig = Rig::start(RigOptions {
        lines: 6,
        // The fifth trace (line index 4).
        faults: vec!["scale:10@CTSTA#5".into()],
        ..RigOptions::default()
    })
    .await;
    let config = rig.config("out");
    let recipes = rig.tmp.path().join("recipes");
    std::fs::create_dir_all(&recipes).unwrap();
    std::fs::write(
        recipes.join("coupon.toml"),
        format!("[plan]\nlines = 6\ny-step-mm = 0.01\n[specification]\nlimits = [\"Ra1 max {RA_MAX_UM}\"]\n"),
    )
    .unwrap();
    append_config(
        &config,
        &format!("\n[jobs]\nrecipes = {:?}\n", recipes.display().to_string()),
    );
    let o = tokio::time::timeout(
        Duration::from_secs(120),
        scan_command(&config, &[])
            .args(["--recipe", "coupon"])
            .output(),
    )
    .await
    .expect("the scan ends within 120 s")
    .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("scan complete"), "{}", describe(&o));
    let dir = scan_dir(&rig.out_dir("out"));
    let meta = |k: u32| crate::common::line_meta(&dir, k);
    let fifth = meta(4);
    let w = fifth["readout_warnings"].as_array().expect("warnings");
    assert_eq!(w.len(), 1, "{fifth}");
    assert_eq!(w[0]["kind"], "ra-far-from-neighbours", "{fifth}");
    assert_eq!(w[0]["lines"], 4, "{fifth}");
    // Independently: the instrument's Ra of each line as stored, the fifth against the
    // median of the four before it.
    let ra = |k: u32| -> f64 {
        let m = meta(k);
        let r = m["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["name"].as_str().unwrap().eq_ignore_ascii_case("ra"))
            .unwrap()
            .clone();
        r["value"].as_f64().unwrap()
    };
    let mut before: Vec<f64> = (0..4).map(ra).collect();
    before.sort_by(f64::total_cmp);
    let median = (before[1] + before[2]) / 2.0;
    assert!(ra(4) / median > 5.0, "{} vs {median}", ra(4));
    assert!(
        (w[0]["median_um"].as_f64().unwrap() - median).abs() < 1e-9,
        "{fifth}"
    );
    crate::common::assert_no_readout_warnings(&dir, [0, 1, 2, 3, 5]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    let warnings = crate::common::report_warnings(&report);
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("line 5 (0004)") && w.contains("median Ra")),
        "{warnings:?}"
    );
    // The line was read out a second time, which gave the same Ra: the first is kept.
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(
        log.contains("reading the line out a second time")
            && log.contains("the second read-out gave the same Ra"),
        "{}",
        describe(&o)
    );
    // The verdict: line 5 alone is above the limit, and only it carries a warning.
    let lines = report["lines"].as_array().expect("report lines");
    let ours: Vec<f64> = lines.iter().map(|l| l["Ra_um"].as_f64().unwrap()).collect();
    assert!(ours[4] > RA_MAX_UM, "{ours:?}");
    for k in [0, 1, 2, 3, 5] {
        assert!(ours[k] < RA_MAX_UM, "line {k}: {ours:?}");
        assert!(lines[k].get("readout_warnings").is_none(), "{}", lines[k]);
    }
    assert_eq!(
        lines[4]["readout_warnings"][0]["kind"], "ra-far-from-neighbours",
        "{}",
        lines[4]
    );
    let spec = &report["specification"];
    assert_eq!(spec["verdict"], "not decidable", "{spec}");
    let limit = &spec["limits"][0];
    assert_eq!(limit["n_beyond"], 1, "{limit}");
    assert_eq!(
        limit["lines_with_warnings"],
        serde_json::json!([5]),
        "{limit}"
    );
    assert_eq!(limit["verdict_without_them"], "conforms", "{limit}");
    let named =
        "rests on line 5 kept with a read-out warning: does not conform with it, conforms without";
    let summary = spec["summary"].as_str().unwrap();
    assert!(
        summary.starts_with("not decidable (") && summary.contains(named),
        "{summary}"
    );
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains(named), "report.html names line 5");
    let csv = std::fs::read_to_string(dir.join("summary.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = header
        .iter()
        .position(|h| *h == "scan_verdict")
        .expect("scan_verdict");
    for row in csv.lines().skip(1) {
        assert_eq!(row.split(',').nth(col), Some("not decidable"), "{csv}");
    }
    assert!(
        stdout.contains(&format!("Ra1 max {RA_MAX_UM}: not decidable")) && stdout.contains(named),
        "{}",
        describe(&o)
    );
    // Not a failed part: the scan is complete, its exit is not "does not conform" (4).
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    rig.shutdown().await;
}

/// One garbled read-out: the fifth line's Ra answer comes back 10 times too large (the
/// heights and the trace are right). Its Ra is then far from its neighbours', so the line
/// is read out a second time; the second read-out gives another Ra and is kept, with no
/// warning left on the line, and the journal says which read-out was kept and why.
#[tokio::test]
async fn a_line_whose_ra_read_out_is_garbled_once_is_read_again_and_the_second_kept() {
    use crate::common::{run_scan, scan_dir, Rig, RigOptions};
    use surfscan::scan::journal::{read_journal, Record};
    let rig = Rig::start(RigOptions {
        lines: 6,
        // The first Ra answer during the fifth trace (line index 4): +900 %, 10 times.
        faults: vec!["skew:900@RDRES02,01%5".into()],
        ..RigOptions::default()
    })
    .await;
    let o = run_scan(&rig.config("out"), &[]).await;
    assert!(o.status.success(), "{}", crate::common::describe(&o));
    let dir = scan_dir(&rig.out_dir("out"));
    let meta = |k: u32| crate::common::line_meta(&dir, k);
    let ra = |k: u32| -> f64 {
        meta(k)["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["name"].as_str().unwrap().eq_ignore_ascii_case("ra"))
            .unwrap()["value"]
            .as_f64()
            .unwrap()
    };
    // The kept read-out is the second: its Ra is like its neighbours' and the line carries
    // no warning (neither the Ra disagreement of the first read-out nor its distance).
    crate::common::assert_no_readout_warnings(&dir, 0..6);
    let (before, kept) = ((ra(3) + ra(2)) / 2.0, ra(4));
    assert!((kept / before - 1.0).abs() < 0.5, "{kept} vs {before}");
    // The journal: one record for line 5 naming both Ra values, the first 10 times the
    // second as the fault made it.
    let records = read_journal(&dir.join("journal.jsonl")).unwrap().records;
    let notes: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::Interruption(i) if i.reason.contains("second read-out") => Some(i),
            _ => None,
        })
        .collect();
    assert_eq!(notes.len(), 1, "{records:?}");
    assert_eq!(notes[0].line, Some(4));
    let reason = &notes[0].reason;
    assert!(reason.ends_with("the second read-out is kept"), "{reason}");
    let numbers: Vec<f64> = reason
        .split_whitespace()
        .filter_map(|w| w.parse::<f64>().ok())
        .collect();
    assert_eq!(numbers.len(), 2, "{reason}");
    assert_eq!(numbers[1], kept, "{reason}");
    assert!(
        (numbers[0] / kept - 10.0).abs() < 0.01,
        "the first read-out's Ra is the skewed one: {reason}"
    );
    rig.shutdown().await;
}
