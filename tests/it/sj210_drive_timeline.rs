//! The client against a scripted drive that runs on (paused) time: when the status is asked
//! during a trace and its return, and what is read while the drive returns. The device
//! answers every command from the time since `CTSTA` and records when each came, so the
//! tests assert the moments, not only the order.
//!
//! Where the table says reads are answered during the return, the line is read then and the
//! next wait for idle asks the status when the return is expected to end; a firmware that
//! refuses them busy is read after the return, from then on.
//!
//! Conditions `3120504.0012`: λc 0.8 mm, N 5, 4 mm evaluation length; the traverse is 4.8 mm
//! (one λc of pre- and post-travel), 9.6 s at 0.5 mm/s and 4.8 s back at 1 mm/s — worked out
//! here from the conditions, as the client must.

use std::sync::{Arc, Mutex};
use std::time::Duration;
use surfscan::sj210::client::Sj210Client;
use surfscan::sj210::models::{CommandOverrides, ModelId, ModelTable};
use surfscan::sj210::settings::ClientOptions;
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::time::Instant;

const CONDITIONS: &[u8] = b"OK3120504.0012\r";
const MEASURE_MS: u64 = 9600;
const RETURN_MS: u64 = 4800;

/// How the scripted drive behaves.
#[derive(Clone, Copy)]
struct Drive {
    /// Measuring ends this long after `CTSTA`, ms.
    measure_ms: u64,
    /// The drive is back this long after `CTSTA`, ms.
    back_ms: u64,
    /// Whether reads are answered while the drive returns (else `NG011`).
    reads_during_return: bool,
}

impl Drive {
    fn on_time(reads_during_return: bool) -> Drive {
        Drive {
            measure_ms: MEASURE_MS,
            back_ms: MEASURE_MS + RETURN_MS,
            reads_during_return,
        }
    }
}

/// One command as the device saw it: ms since `CTSTA` (`None` before it), the command, the
/// status or reply it gave.
type Seen = (Option<u64>, String, String);

fn drive(d: Drive) -> (DuplexStream, Arc<Mutex<Vec<Seen>>>) {
    let (io, mut dev) = tokio::io::duplex(1 << 16);
    let seen = Arc::new(Mutex::new(Vec::new()));
    let log = seen.clone();
    tokio::spawn(async move {
        let mut started: Option<Instant> = None;
        let mut line = Vec::new();
        let mut b = [0u8; 1];
        while let Ok(1) = dev.read(&mut b).await {
            if b[0] != b'\r' {
                line.push(b[0]);
                continue;
            }
            let cmd = String::from_utf8_lossy(&line).to_string();
            line.clear();
            let t = started.map(|s| s.elapsed().as_millis() as u64);
            let status = match t {
                None => "000",
                Some(t) if t < d.measure_ms => "001",
                Some(t) if t < d.back_ms => "002",
                Some(_) => "000",
            };
            let busy = status == "001" || (status == "002" && !d.reads_during_return);
            let reply: String = match cmd.as_str() {
                "RDCON" => String::from_utf8_lossy(CONDITIONS).into_owned(),
                "RDSTU00" => format!("OK{status}\r"),
                "CTSTA" => {
                    started = Some(Instant::now());
                    "OK\r".into()
                }
                _ if busy => "NG011\r".into(),
                "RDPAR" => "OK01\r".into(),
                "RDRES02,01,00" => "OKRa      1.234 um\r".into(),
                "RDEVA00" => "OK00003\r".into(),
                "RDEVA03" => "OK03,    0.125,   -0.250,    0.500\r".into(),
                other => panic!("unexpected command {other:?}"),
            };
            log.lock()
                .unwrap()
                .push((t, cmd, reply.trim_end().to_string()));
            dev.write_all(reply.as_bytes()).await.unwrap();
        }
    });
    (io, seen)
}

fn opts() -> ClientOptions {
    ClientOptions {
        poll_interval: Duration::from_millis(250),
        start_deadline: Duration::from_millis(1000),
        ..ClientOptions::default()
    }
}

/// When the status was first seen reading `reply` after the start, ms.
fn first(seen: &[Seen], reply: &str) -> u64 {
    seen.iter()
        .find(|(t, c, r)| t.is_some() && c == "RDSTU00" && r == reply)
        .and_then(|(t, ..)| *t)
        .unwrap_or_else(|| panic!("{reply} never seen: {seen:?}"))
}

#[tokio::test(start_paused = true)]
async fn the_status_is_asked_when_the_trace_and_its_return_are_expected_to_end() {
    let (io, seen) = drive(Drive::on_time(false));
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    c.conditions().await.unwrap();
    let t0 = Instant::now();
    c.run_trace().await.unwrap();
    let seen = seen.lock().unwrap().clone();
    // Seen the moment each phase ends, not on the 250 ms grid (which would be 9750 and
    // 14 500: the grid has no poll at 9600 after 9500, nor at 14 400 after 14 350).
    assert_eq!(first(&seen, "OK002"), MEASURE_MS);
    assert_eq!(first(&seen, "OK000"), MEASURE_MS + RETURN_MS);
    assert_eq!(t0.elapsed(), Duration::from_millis(MEASURE_MS + RETURN_MS));
    // Until each expected end, the plain interval: the polls still watch the drive.
    let polls: Vec<u64> = seen
        .iter()
        .filter(|(t, c, _)| t.is_some() && c == "RDSTU00")
        .filter_map(|(t, ..)| *t)
        .collect();
    assert_eq!(polls[..3], [250, 500, 750]);
    assert!(
        polls.contains(&9500) && polls.contains(&14_350),
        "{polls:?}"
    );
    assert_eq!(polls.len(), 38 + 1 + 19 + 1, "{polls:?}");
}

#[tokio::test(start_paused = true)]
async fn a_drive_slower_than_its_speed_is_seen_within_the_back_off() {
    // 40 ms late out, and back 40 ms after its own return time.
    let (io, seen) = drive(Drive {
        measure_ms: MEASURE_MS + 40,
        back_ms: MEASURE_MS + 40 + RETURN_MS,
        reads_during_return: false,
    });
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    c.conditions().await.unwrap();
    c.run_trace().await.unwrap();
    let seen = seen.lock().unwrap().clone();
    // Polls at 9600, 9620 (measuring), 9660 (returning): 20 ms after it turned.
    assert_eq!(first(&seen, "OK002"), MEASURE_MS + 60);
    // The return reckoned from 9620, the last poll that saw it measuring: asked at 14 420
    // (still returning), then 20 ms later, at 14 440, the moment it is back.
    assert_eq!(first(&seen, "OK000"), MEASURE_MS + 40 + RETURN_MS);
}

#[tokio::test(start_paused = true)]
async fn without_the_conditions_the_status_is_asked_on_the_interval() {
    // No RDCON read first: the client knows no traverse, so it keeps to the 250 ms grid.
    let (io, seen) = drive(Drive::on_time(false));
    let mut c = Sj210Client::new(io, ModelTable::builtin(ModelId::Sj210), opts());
    c.run_trace().await.unwrap();
    let seen = seen.lock().unwrap().clone();
    assert_eq!(first(&seen, "OK002"), 9750);
    assert_eq!(first(&seen, "OK000"), 14_500);
}

/// The SJ-210 table with the read-out configured, reading during the return when `during`.
fn table(during: bool) -> ModelTable {
    let o = CommandOverrides {
        profile_total: Some("RDEVA00".into()),
        profile_block: Some("RDEVA{n}".into()),
        reads_during_return: Some(during),
        ..CommandOverrides::default()
    };
    ModelTable::with_overrides(ModelId::Sj210, &o).unwrap()
}

/// Three points do not make N × λc / pitch: the count rule has its own tests.
fn line_opts() -> ClientOptions {
    ClientOptions {
        check_point_count: false,
        ..opts()
    }
}

/// The read commands and when they came, ms since `CTSTA`.
fn reads(seen: &[Seen]) -> Vec<(u64, String, String)> {
    seen.iter()
        .filter(|(t, c, _)| t.is_some() && c.starts_with("RD") && c != "RDSTU00" && c != "RDCON")
        .map(|(t, c, r)| (t.unwrap_or(0), c.clone(), r.clone()))
        .collect()
}

const HEIGHTS: [f64; 3] = [0.125, -0.25, 0.5];

#[tokio::test(start_paused = true)]
async fn the_line_is_read_while_the_drive_returns_and_the_next_idle_is_asked_when_it_is_back() {
    let (io, seen) = drive(Drive::on_time(true));
    let mut c = Sj210Client::new(io, table(true), line_opts());
    let t0 = Instant::now();
    let line = c.trace_line().await.unwrap();
    // The whole line is in hand when measuring ends, 4.8 s before the drive is back.
    assert_eq!(t0.elapsed(), Duration::from_millis(MEASURE_MS));
    assert_eq!(line.profile.heights_um, HEIGHTS);
    assert_eq!(line.results[0].value, Some(1.234));
    let during = reads(&seen.lock().unwrap());
    // RDPAR, one RDRES, the total and one block.
    assert_eq!(during.len(), 4, "{during:?}");
    assert!(
        during
            .iter()
            .all(|(t, _, r)| *t == MEASURE_MS && r.starts_with("OK")),
        "{during:?}"
    );
    // The stage may move only once the drive is back: asked exactly then.
    c.wait_idle().await.unwrap();
    assert_eq!(t0.elapsed(), Duration::from_millis(MEASURE_MS + RETURN_MS));
    let seen = seen.lock().unwrap().clone();
    assert_eq!(first(&seen, "OK000"), MEASURE_MS + RETURN_MS);
}

#[tokio::test(start_paused = true)]
async fn a_firmware_that_refuses_reads_during_the_return_is_read_after_it_from_then_on() {
    let (io, seen) = drive(Drive::on_time(false));
    let mut c = Sj210Client::new(io, table(true), line_opts());
    let t0 = Instant::now();
    let line = c.trace_line().await.unwrap();
    // Refused busy at 9600, read once the drive was back: the same line.
    assert_eq!(t0.elapsed(), Duration::from_millis(MEASURE_MS + RETURN_MS));
    assert_eq!(line.profile.heights_um, HEIGHTS);
    assert_eq!(line.results[0].value, Some(1.234));
    let said: Vec<&String> = line
        .warnings
        .iter()
        .filter(|w| w.contains("refused a read while its drive returned"))
        .collect();
    assert_eq!(said.len(), 1, "{:?}", line.warnings);
    assert!(said[0].contains("NG011"), "{said:?}");
    assert!(said[0].contains("remove reads-during-return"), "{said:?}");
    let first_trace = reads(&seen.lock().unwrap());
    // One refused read (not retried), then the four reads after the return.
    assert_eq!(first_trace[0], (MEASURE_MS, "RDPAR".into(), "NG011".into()));
    assert_eq!(first_trace.len(), 5, "{first_trace:?}");
    assert!(first_trace[1..]
        .iter()
        .all(|(t, _, r)| *t == MEASURE_MS + RETURN_MS && r.starts_with("OK")));
    // The next line: no read is tried during its return, and nothing more is said.
    seen.lock().unwrap().clear();
    c.wait_idle().await.unwrap();
    let line = c.trace_line().await.unwrap();
    assert!(
        !line.warnings.iter().any(|w| w.contains("refused a read")),
        "{:?}",
        line.warnings
    );
    let second = reads(&seen.lock().unwrap());
    assert_eq!(second.len(), 4, "{second:?}");
    assert!(second.iter().all(|(t, ..)| *t == MEASURE_MS + RETURN_MS));
}

#[tokio::test(start_paused = true)]
async fn reads_wait_for_the_drive_unless_the_table_says_otherwise() {
    // An instrument that would answer during the return, with the table's default (off):
    // nothing is read before the drive is back.
    let (io, seen) = drive(Drive::on_time(true));
    let mut c = Sj210Client::new(io, table(false), line_opts());
    let t0 = Instant::now();
    let line = c.trace_line().await.unwrap();
    assert_eq!(t0.elapsed(), Duration::from_millis(MEASURE_MS + RETURN_MS));
    assert_eq!(line.profile.heights_um, HEIGHTS);
    let r = reads(&seen.lock().unwrap());
    assert!(
        r.iter().all(|(t, ..)| *t == MEASURE_MS + RETURN_MS),
        "{r:?}"
    );
}
