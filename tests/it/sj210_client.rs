//! Scripted conversations against the SJ-210 client, in-process over `tokio::io::duplex`.
//! A fake device asserts every command byte-for-byte and answers from the script; the
//! script must be consumed exactly, so an extra (e.g. retried) command fails the test.
//! Time is paused, so timeouts elapse instantly and deterministically.

use std::time::Duration;
use surfscan::devices::{Battery, DeviceFault, FaultClass, Instrument, ProfileReadout};
use surfscan::sj210::client::Sj210Client;
use surfscan::sj210::codec::NgCode;
use surfscan::sj210::error::{LinkError, Sj210Error};
use surfscan::sj210::models::{CommandOverrides, ModelId, ModelTable};
use surfscan::sj210::settings::ClientOptions;
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::task::JoinHandle;

/// One step: the exact command expected (without CR) and the raw reply (None = silence;
/// `Some(b"")` is not used). A reply `DROP` closes the link.
type Step = (&'static str, Option<&'static [u8]>);
const DROP: &[u8] = b"<drop>";

/// The scripted device's task: the steps it consumed, or where the script went wrong.
type DeviceTask = JoinHandle<Result<usize, String>>;

fn device(script: Vec<Step>) -> (DuplexStream, DeviceTask) {
    let (host, mut dev) = tokio::io::duplex(4096);
    let h = tokio::spawn(async move {
        for (i, (expect, reply)) in script.iter().enumerate() {
            let mut line = Vec::new();
            loop {
                let mut b = [0u8; 1];
                match dev.read(&mut b).await {
                    Ok(0) | Err(_) => {
                        return Err(format!("link closed at step {i}, expected {expect:?}"))
                    }
                    Ok(_) if b[0] == b'\r' => break,
                    Ok(_) => line.push(b[0]),
                }
            }
            let got = String::from_utf8_lossy(&line).to_string();
            if got != *expect {
                return Err(format!("step {i}: expected {expect:?}, got {got:?}"));
            }
            match reply {
                Some(r) if *r == DROP => return Ok(i + 1),
                Some(r) => dev.write_all(r).await.map_err(|e| e.to_string())?,
                None => {}
            }
        }
        // Anything sent after the script is a test failure.
        let mut b = [0u8; 64];
        match dev.read(&mut b).await {
            Ok(0) | Err(_) => Ok(script.len()),
            Ok(n) => Err(format!(
                "unexpected extra command {:?}",
                String::from_utf8_lossy(&b[..n])
            )),
        }
    });
    (host, h)
}

/// A client of `model`'s table talking to `device(script)`, the device's task and the
/// script's length (for [`finish`]).
fn scripted(model: ModelId, script: Vec<Step>) -> (Sj210Client<DuplexStream>, DeviceTask, usize) {
    let n = script.len();
    let (io, h) = device(script);
    (
        Sj210Client::new(io, ModelTable::builtin(model), opts()),
        h,
        n,
    )
}

/// A device that answers each command (without CR) by `respond(command, commands seen
/// before)`: writes to send in order, each after its delay. Its task returns the commands it
/// saw once the link closes.
fn responder(
    mut respond: impl FnMut(&str, usize) -> Vec<(Duration, &'static [u8])> + Send + 'static,
) -> (DuplexStream, JoinHandle<Vec<String>>) {
    let (io, mut dev) = tokio::io::duplex(4096);
    let device = tokio::spawn(async move {
        let mut seen = Vec::new();
        let mut line = Vec::new();
        let mut b = [0u8; 1];
        while let Ok(1) = dev.read(&mut b).await {
            if b[0] != b'\r' {
                line.push(b[0]);
                continue;
            }
            let cmd = String::from_utf8_lossy(&line).to_string();
            line.clear();
            for (delay, bytes) in respond(&cmd, seen.len()) {
                tokio::time::sleep(delay).await;
                dev.write_all(bytes).await.unwrap();
            }
            seen.push(cmd);
        }
        seen
    });
    (io, device)
}

fn opts() -> ClientOptions {
    ClientOptions {
        first_byte: Duration::from_millis(2000),
        inter_byte: Duration::from_millis(200),
        poll_interval: Duration::from_millis(250),
        start_deadline: Duration::from_millis(1000),
        read_retry_budget: Duration::from_millis(1000),
        trace_deadline: Some(Duration::from_secs(60)),
        pitch_x_um: None,
        check_point_count: true,
        detector_range_um: surfscan::sj210::settings::STANDARD_DETECTOR_RANGE_UM,
        speeds: surfscan::sj210::timing::DriveSpeeds {
            measuring_mm_s: 0.5,
            return_mm_s: 1.0,
        },
        max_line: 4096,
    }
}

/// For the scripted traces whose profiles are far shorter than their conditions' N × λc
/// (the point-count rule has its own tests).
fn short_profile_opts() -> ClientOptions {
    ClientOptions {
        check_point_count: false,
        ..opts()
    }
}

async fn finish<S>(client: Sj210Client<S>, h: DeviceTask, steps: usize)
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin,
{
    drop(client.into_inner());
    let consumed = h.await.unwrap().unwrap();
    assert_eq!(consumed, steps, "script not consumed exactly");
}

const PROBE_HEAD: [Step; 5] = [
    ("RDSJ 01", Some(b"OKV1.00\r")),
    ("RDSJ 00", Some(b"OK000\r")),
    ("RDSTU01", Some(b"OK001\r")),
    ("RDCON", Some(b"OK3120504.0012\r")),
    ("RDPAR", Some(b"OK03\r")),
];

#[tokio::test(start_paused = true)]
async fn probe_sj210_as_documented_reports_no_readout_and_low_battery() {
    let mut script = PROBE_HEAD.to_vec();
    script.push(("CTOFF01", Some(b"OK\r")));
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let r = c.probe_report().await.unwrap();
    assert_eq!(r.identity.firmware, "V1.00");
    assert_eq!(r.identity.drive_unit, "000 standard");
    assert_eq!(r.battery, Battery::Low);
    assert_eq!(r.parameter_count, 3);
    assert_eq!(r.conditions.lambda_c_mm, Some(0.8));
    assert!(r.warnings.iter().any(|w| w.contains("battery below 60")));
    // λs 2.5 µm derived from λc 0.8 mm gives the assumed 0.5 µm pitch.
    assert!(r
        .warnings
        .iter()
        .any(|w| w.contains("x pitch 0.5 um assumed")));
    match &r.profile_readout {
        ProfileReadout::Unsupported { ng_code, advice } => {
            assert_eq!(*ng_code, None);
            assert!(advice.contains("SJ-410 manual documents RDEVA"));
            assert!(advice.contains("[instrument.commands]"));
        }
        other => panic!("expected unsupported, got {other:?}"),
    }
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn probe_with_override_names_the_ng_code_and_instrument_probe_refuses() {
    let mut script = PROBE_HEAD.to_vec();
    script[2] = ("RDSTU01", Some(b"OK000\r"));
    script.push(("CTOFF01", Some(b"OK\r")));
    script.push(("RDEVA00", Some(b"NG030\r")));
    let n = script.len();
    let (io, h) = device(script);
    let o = CommandOverrides {
        profile_total: Some("RDEVA00".into()),
        profile_block: Some("RDEVA{n}".into()),
        ..Default::default()
    };
    let table = ModelTable::with_overrides(ModelId::Sj210, &o).unwrap();
    let mut c = Sj210Client::new(io, table, opts());
    let e = Instrument::probe(&mut c).await.unwrap_err();
    match &e {
        Sj210Error::ProfileUnsupported { ng_code, advice } => {
            assert_eq!(*ng_code, Some(30));
            assert!(advice.contains("NG030"), "{advice}");
            assert!(advice.contains("\"RDEVA00\""), "{advice}");
        }
        other => panic!("expected ProfileUnsupported, got {other:?}"),
    }
    assert_eq!(e.class(), FaultClass::Fatal);
    assert_eq!(e.ng_code(), Some(30));
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn battery_abnormal_is_fatal_at_probe() {
    let script: Vec<Step> = vec![
        ("RDSJ 01", Some(b"OKV1.00\r")),
        ("RDSJ 00", Some(b"OK000\r")),
        ("RDSTU01", Some(b"OK002\r")),
        ("RDCON0", Some(b"OK0302232050.500220.0030.019\r")),
        ("RDPAR0", Some(b"OK01\r")),
        ("CTOFF01", Some(b"OK\r")),
        ("RDEVA000", Some(b"OK00000\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj410, script);
    let e = Instrument::probe(&mut c).await.unwrap_err();
    assert!(matches!(e, Sj210Error::BatteryAbnormal));
    assert_eq!(e.class(), FaultClass::Fatal);
    // The client remembers it and refuses to trace without sending anything.
    assert!(matches!(
        c.trace_line().await,
        Err(Sj210Error::BatteryAbnormal)
    ));
    finish(c, h, n).await;
}

/// 120 heights: i × 0.01 − 0.5 µm, formatted as the blocks will carry them.
fn heights() -> Vec<f64> {
    (0..120).map(|i| f64::from(i) * 0.01 - 0.5).collect()
}

fn block(from: usize, n: usize) -> &'static [u8] {
    let mut s = format!("OK{n:02}");
    for v in &heights()[from..from + n] {
        s.push_str(&format!(",{v:.3}"));
    }
    s.push('\r');
    Box::leak(s.into_bytes().into_boxed_slice())
}

fn trace_script() -> Vec<Step> {
    vec![
        ("RDCON0", Some(b"OK0332132050.500220.0030.019\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("CTSTA", Some(b"OK\r")),
        ("RDSTU00", Some(b"OK001\r")),
        ("RDSTU00", Some(b"OK001\r")),
        ("RDSTU00", Some(b"OK002\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("RDPAR0", Some(b"OK02\r")),
        ("RDRES002,01,00", Some(b"NG101\r")),
        ("RDRES002,01,00", Some(b"OKRa      1.2345 um\r")),
        ("RDRES002,02,00", Some(b"OKRz     10.0000 \xb5m\r")),
    ]
}

#[tokio::test(start_paused = true)]
async fn clean_trace_reads_results_and_profile_in_blocks() {
    // Conditions read at probe time differ from those at the trace: warned and recorded.
    let mut script: Vec<Step> = vec![("RDCON0", Some(b"OK0302232050.500220.0030.019\r"))];
    script.extend(trace_script());
    script.push(("RDEVA000", Some(b"OK00120\r")));
    script.push(("RDEVA050", Some(block(0, 50))));
    script.push(("RDEVA050", Some(block(50, 50))));
    script.push(("RDEVA020", Some(block(100, 20))));
    let n = script.len();
    let (io, h) = device(script);
    let mut c = Sj210Client::new(
        io,
        ModelTable::builtin(ModelId::Sj410),
        short_profile_opts(),
    );
    c.conditions().await.unwrap();
    let line = Instrument::trace(&mut c).await.unwrap();
    assert!(
        line.warnings
            .iter()
            .any(|w| w.contains("conditions changed")),
        "{:?}",
        line.warnings
    );
    assert_eq!(
        line.profile.conditions.raw.as_deref(),
        Some("0332132050.500220.0030.019")
    );
    let expect = heights();
    assert_eq!(line.profile.heights_um.len(), 120);
    for (a, b) in line.profile.heights_um.iter().zip(&expect) {
        assert!((a - b).abs() < 5e-4, "{a} vs {b}");
    }
    // SJ-410 conditions: profile digit 3 = R-Motif → Other; λs digit 1 = 8 µm → 1.5 µm pitch
    // (ISO 3274's spacing for λs 8 µm, as Mitutoyo's own export states).
    assert_eq!(line.profile.kind, surfscan::profile::ProfileKind::Other);
    assert!((line.profile.pitch_x_mm - 0.0015).abs() < 1e-12);
    assert_eq!(line.pitch_source, "lambda-s 8 um");
    assert_eq!(line.results.len(), 2);
    assert_eq!(line.results[0].value, Some(1.2345));
    assert_eq!(line.results[1].unit, "\u{b5}m");
    // 120 × 1.5 µm = 0.18 mm against 5 × 2.5 mm = 12.5 mm: more than 1 % off.
    assert!(
        line.warnings.iter().any(|w| w.contains("12.5000 mm")),
        "{:?}",
        line.warnings
    );
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn profile_readout_restarts_once_after_a_malformed_block() {
    let mut script = trace_script();
    script.push(("RDEVA000", Some(b"OK00060\r")));
    script.push(("RDEVA050", Some(b"\xff\xfe garbage\r")));
    // Recovery: drain, one status read.
    script.push(("RDSTU00", Some(b"OK000\r")));
    script.push(("RDEVA000", Some(b"OK00060\r")));
    script.push(("RDEVA050", Some(block(0, 50))));
    script.push(("RDEVA010", Some(block(50, 10))));
    let n = script.len();
    let (io, h) = device(script);
    let mut c = Sj210Client::new(
        io,
        ModelTable::builtin(ModelId::Sj410),
        short_profile_opts(),
    );
    let line = c.trace_line().await.unwrap();
    assert_eq!(line.profile.heights_um.len(), 60);
    assert!(line.warnings.iter().any(|w| w.contains("restarted")));
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn profile_readout_failing_twice_means_retrace_and_no_block_is_retried() {
    let mut script = trace_script();
    script.push(("RDEVA000", Some(b"OK00060\r")));
    script.push(("RDEVA050", Some(b"NG011\r")));
    script.push(("RDEVA000", Some(b"OK00060\r")));
    script.push(("RDEVA050", Some(block(0, 50))));
    script.push(("RDEVA010", Some(b"OK0.0\r")));
    let (mut c, h, n) = scripted(ModelId::Sj410, script);
    let e = c.trace_line().await.unwrap_err();
    match &e {
        Sj210Error::ProfileReadoutFailed { first, second } => {
            assert!(first.contains("NG011"), "{first}");
            assert!(matches!(
                **second,
                Sj210Error::ProfileCountMismatch {
                    announced: 60,
                    received: 50
                }
            ));
        }
        other => panic!("expected ProfileReadoutFailed, got {other:?}"),
    }
    assert_eq!(e.class(), FaultClass::Transient);
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn start_refused_busy_is_not_retried() {
    let script: Vec<Step> = vec![
        ("RDCON", Some(b"OK3120504.0012\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("CTSTA", Some(b"NG011\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.trace_line().await.unwrap_err();
    assert_eq!(e.code(), Some(NgCode::Busy));
    assert!(e.to_string().contains("\"CTSTA\""));
    assert_eq!(e.class(), FaultClass::Transient);
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn never_reaching_measuring_is_stylus_not_on_workpiece() {
    // Start deadline 1000 ms, polls every 250 ms: idle at 250, 500, 750, 1000 → error.
    let script: Vec<Step> = vec![
        ("RDCON", Some(b"OK3120504.0012\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("CTSTA", Some(b"OK\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("RDSTU00", Some(b"OK000\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.trace_line().await.unwrap_err();
    assert!(
        matches!(e, Sj210Error::StylusNotOnWorkpiece { last_status: 0, waited_ms } if waited_ms >= 1000),
        "{e:?}"
    );
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn over_range_reads_the_detector_position() {
    let script: Vec<Step> = vec![
        ("RDCON", Some(b"OK3120504.0012\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("CTSTA", Some(b"OK\r")),
        ("RDSTU00", Some(b"OK001\r")),
        ("RDSTU00", Some(b"NG007\r")),
        ("RDPSA", Some(b"OK-201.5\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.trace_line().await.unwrap_err();
    assert!(
        matches!(&e, Sj210Error::OverRange { position: Some(p) } if p == "-201.5"),
        "{e:?}"
    );
    assert_eq!(e.ng_code(), Some(7));
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn retract_state_during_trace_is_named() {
    let script: Vec<Step> = vec![
        ("RDCON", Some(b"OK3120504.0012\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("CTSTA", Some(b"OK\r")),
        ("RDSTU00", Some(b"OK001\r")),
        ("RDSTU00", Some(b"OK004\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.trace_line().await.unwrap_err();
    assert!(matches!(e, Sj210Error::Retracted { status: 4 }), "{e:?}");
    assert_eq!(e.class(), FaultClass::Fatal);
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn first_byte_timeout_recovers_with_a_status_read() {
    let script: Vec<Step> = vec![("RDSJ 01", None), ("RDSTU00", Some(b"OK000\r"))];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.probe_report().await.unwrap_err();
    match &e {
        Sj210Error::Link {
            command,
            source: LinkError::FirstByteTimeout { waited_ms: 2000 },
        } => assert_eq!(command, "RDSJ 01"),
        other => panic!("{other:?}"),
    }
    // No byte at all: the instrument is silent, waited for like an unplugged one.
    assert_eq!(e.class(), FaultClass::Silent);
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn stalled_reply_is_an_inter_byte_timeout_with_the_partial_bytes() {
    let script: Vec<Step> = vec![("RDSTU00", Some(b"OK0")), ("RDSTU00", Some(b"OK000\r"))];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.status().await.unwrap_err();
    assert!(
        matches!(&e, Sj210Error::Link { source: LinkError::InterByteTimeout { partial, waited_ms: 200 }, .. } if partial == "OK0"),
        "{e:?}"
    );
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn vanished_device_is_absent() {
    let script: Vec<Step> = vec![("RDSTU00", Some(DROP))];
    let (io, h) = device(script);
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    let e = c.status().await.unwrap_err();
    assert!(
        matches!(
            &e,
            Sj210Error::Link {
                source: LinkError::Vanished { .. },
                ..
            }
        ),
        "{e:?}"
    );
    assert_eq!(e.class(), FaultClass::Absent);
    assert_eq!(h.await.unwrap().unwrap(), 1);
}

#[tokio::test(start_paused = true)]
async fn read_retry_is_bounded_by_the_budget() {
    // Budget 1000 ms, interval 250 ms: attempts at 0, 250, 500, 750, 1000 ms, then give up.
    let script: Vec<Step> = vec![("RDPAR", Some(b"NG033\r")); 5];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.parameter_count().await.unwrap_err();
    assert_eq!(e.code(), Some(NgCode::Processing));
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn abort_is_sent_only_while_measuring() {
    let script: Vec<Step> = vec![
        ("RDSTU00", Some(b"OK002\r")),
        ("RDSTU00", Some(b"OK001\r")),
        ("CTSTA", Some(b"OK\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    Instrument::abort(&mut c).await.unwrap();
    Instrument::abort(&mut c).await.unwrap();
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn ensure_idle_returns_the_detector_from_005() {
    let script: Vec<Step> = vec![
        ("RDSTU00", Some(b"OK005\r")),
        ("CTRTN", Some(b"OK\r")),
        ("RDSTU00", Some(b"OK002\r")),
        ("RDSTU00", Some(b"OK000\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    Instrument::ensure_idle(&mut c).await.unwrap();
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn parameter_calculation_error_is_recorded_without_value() {
    let script: Vec<Step> = vec![
        ("RDPAR", Some(b"OK02\r")),
        ("RDRES02,01,00", Some(b"OKRa     0.123  um\r")),
        ("RDRES02,02,00", Some(b"NG110\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let mut w = Vec::new();
    let r = c.read_results(&mut w).await.unwrap();
    assert_eq!(r[0].value, Some(0.123));
    assert_eq!(r[1].value, None);
    assert!(w[0].contains("NG110"));
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn trace_that_never_ends_hits_the_deadline() {
    let mut o = opts();
    o.trace_deadline = Some(Duration::from_millis(1000));
    // Polls at 250, 500, 750, 1000 ms all read "measuring"; the deadline is then reached.
    let script: Vec<Step> = vec![
        ("RDCON", Some(b"OK3120504.0012\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("CTSTA", Some(b"OK\r")),
        ("RDSTU00", Some(b"OK001\r")),
        ("RDSTU00", Some(b"OK001\r")),
        ("RDSTU00", Some(b"OK001\r")),
        ("RDSTU00", Some(b"OK001\r")),
    ];
    let n = script.len();
    let (io, h) = device(script);
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), o);
    let e = c.trace_line().await.unwrap_err();
    assert!(
        matches!(
            e,
            Sj210Error::TraceDeadline {
                waited_ms: 1000,
                last_status: 1
            }
        ),
        "{e:?}"
    );
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn start_with_non_empty_payload_is_a_protocol_error() {
    let script: Vec<Step> = vec![
        ("RDCON", Some(b"OK3120504.0012\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("CTSTA", Some(b"OK001\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.trace_line().await.unwrap_err();
    assert!(
        matches!(&e, Sj210Error::UnexpectedReply { command, payload, .. } if command == "CTSTA" && payload == "001"),
        "{e:?}"
    );
    finish(c, h, n).await;
}

#[tokio::test(start_paused = true)]
async fn trace_refuses_to_start_unless_idle() {
    let script: Vec<Step> = vec![
        ("RDCON", Some(b"OK3120504.0012\r")),
        ("RDSTU00", Some(b"OK005\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    let e = c.trace_line().await.unwrap_err();
    assert!(matches!(e, Sj210Error::NotIdle { status: 5, .. }), "{e:?}");
    finish(c, h, n).await;
}

/// A command whose future is dropped before its reply arrives (an operator abort or a
/// shutdown cancels it) must not leave that reply to be taken as the next command's answer.
#[tokio::test(start_paused = true)]
async fn a_reply_to_a_cancelled_command_is_not_taken_as_the_next_answer() {
    let (io, device) = responder(|cmd, _| match cmd {
        // Slow: the host gives up waiting before this arrives.
        "RDSTU00" => vec![(Duration::from_millis(500), b"OK001\r")],
        "RDSJ 01" => vec![(Duration::ZERO, b"OKV1.00\r")],
        other => panic!("unexpected command {other:?}"),
    });
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    let cancelled = tokio::time::timeout(Duration::from_millis(100), c.status()).await;
    assert!(
        cancelled.is_err(),
        "the status read should still be waiting"
    );
    // Let the late reply arrive on the link before the next command is sent.
    tokio::time::sleep(Duration::from_millis(600)).await;
    let firmware = c.command("RDSJ 01", true).await.unwrap();
    assert_eq!(firmware, "V1.00");
    drop(c);
    assert_eq!(device.await.unwrap(), ["RDSTU00", "RDSJ 01"]);
}

/// An answer that would mean "wrong model table" (an unknown conditions layout, NG030) is
/// fatal only for a command never understood on this link; after the command was answered
/// well, it is a stray or late reply: a transient fault, after which the link is resynced.
#[tokio::test(start_paused = true)]
async fn a_table_error_after_the_command_worked_is_a_stray_reply_not_a_wrong_table() {
    let script: Vec<Step> = vec![
        ("RDCON", Some(b"OK3120504.0012\r")),
        ("RDCON", Some(b"OK000\r")),
        ("RDCON", Some(b"NG030\r")),
        ("RDSTU00", Some(b"OK000\r")),
        ("RDCON", Some(b"OK3120504.0012\r")),
    ];
    let (mut c, h, n) = scripted(ModelId::Sj210, script);
    c.conditions().await.unwrap();
    let e = c.conditions().await.unwrap_err();
    assert!(matches!(e, Sj210Error::UnexpectedReply { .. }), "{e:?}");
    assert_eq!(e.class(), FaultClass::Transient);
    let e = c.conditions().await.unwrap_err();
    assert!(
        matches!(e, Sj210Error::UnexpectedReply { ref payload, .. } if payload == "NG030"),
        "{e:?}"
    );
    assert_eq!(e.class(), FaultClass::Transient);
    c.conditions().await.unwrap();
    finish(c, h, n).await;

    // On a fresh link the same answers name the table as the cause.
    for reply in [&b"OK000\r"[..], b"NG030\r"] {
        let (io, h) = device(vec![("RDCON", Some(reply))]);
        let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
        let e = c.conditions().await.unwrap_err();
        assert_eq!(e.class(), FaultClass::Fatal, "{e:?}");
        finish(c, h, 1).await;
    }
}

/// A stray or late reply that arrives between two commands (the flood of a confused device, a
/// reply later than its timeout) waits in the port's buffer, not yet read: it must be set
/// aside before the next command, or that command takes it for its answer and every later
/// answer on the link is shifted by one.
#[tokio::test(start_paused = true)]
async fn a_stray_reply_between_commands_is_not_taken_as_the_next_answer() {
    let (io, device) = responder(|cmd, seen| match cmd {
        "RDCON" if seen == 0 => vec![
            (Duration::ZERO, b"OK3120504.0012\r"),
            // Then, unasked, once the host has its answer: a status reply.
            (Duration::from_millis(200), b"OK000\r"),
        ],
        "RDCON" => vec![(Duration::ZERO, b"OK3120504.0012\r")],
        other => panic!("unexpected command {other:?}"),
    });
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    let first = c.conditions().await.unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let second = c.conditions().await.unwrap();
    assert_eq!(first, second);
    drop(c);
    assert_eq!(device.await.unwrap(), ["RDCON", "RDCON"]);
}

/// A link that stops taking the host's bytes (CTS held low, a wedged adapter; here a pipe
/// whose reader stopped): the command ends at the first-byte timeout as a named stall, its
/// recovery's status request too, and nothing hangs.
#[tokio::test(start_paused = true)]
async fn a_link_that_takes_no_bytes_ends_the_command_at_its_deadline() {
    let (io, _deaf) = tokio::io::duplex(1);
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    let t0 = tokio::time::Instant::now();
    let e = c.command("RDSTU01", true).await.unwrap_err();
    let took = t0.elapsed();
    assert!(
        matches!(
            &e,
            Sj210Error::Link {
                source: LinkError::WriteStalled(_),
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        e.to_string()
            .contains("took 1 of the command's 8 byte(s) and then none for 2000 ms"),
        "{e}"
    );
    // The command's deadline, the drain and the recovery's own status request: bounded.
    assert!(took >= Duration::from_millis(2000), "{took:?}");
    assert!(took <= Duration::from_millis(3 * 2000), "{took:?}");
    assert_eq!(e.class(), FaultClass::Silent);
}

/// The probe asks a silent port the questions a stage controller answers (the ports may be
/// swapped), but only a port that never gave a byte: an instrument that is merely late (a
/// loaded host, a slow adapter) has answered by the end of the recovery's status read, and
/// asking it too would only leave one more late reply (NG030 to the question) for the next
/// link's first command to take for its own answer, a "wrong model table" that ends a scan.
#[tokio::test(start_paused = true)]
async fn only_a_port_that_never_spoke_is_asked_whether_a_stage_is_on_it() {
    let late = Duration::from_millis(2500);
    let (io, device) = responder(move |cmd, _| match cmd {
        "RDSJ 01" => vec![(late, b"OKV1.00\r")],
        "RDSTU00" => vec![(late, b"OK000\r")],
        // The stage's question, to an SJ-210 one unknown command.
        _ => vec![(Duration::ZERO, b"NG030\r")],
    });
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    let e = c.probe().await.unwrap_err();
    assert!(
        matches!(
            &e,
            Sj210Error::Link {
                source: LinkError::FirstByteTimeout { .. },
                ..
            }
        ),
        "{e:?}"
    );
    assert_eq!(e.class(), FaultClass::Silent);
    // Let the late replies go out before the link closes.
    tokio::time::sleep(Duration::from_secs(6)).await;
    drop(c);
    assert_eq!(device.await.unwrap(), ["RDSJ 01", "RDSTU00"]);

    // A port that never says anything is asked, once, after the recovery's status read.
    let (io, device) = responder(|_, _| Vec::new());
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    let e = c.probe().await.unwrap_err();
    assert_eq!(e.class(), FaultClass::Silent, "{e:?}");
    drop(c);
    assert_eq!(device.await.unwrap(), ["RDSJ 01", "RDSTU00", "?\n/"]);
}
