//! Per-line overhead of a simulated scan beyond device time.
//!
//! Runs the real `surfscan scan` binary with the demo's station configuration against the
//! simulator (SJ-210 replaying the demo's 31 windows of a Mitutoyo R profile, sped up; a GRBL
//! y stage moving and settling at real speed), then reads the scan journal's line timestamps. Each line's period (from the
//! previous line's record to its own) is compared with the device time the line needs,
//! worked out here from the simulated devices' parameters, not measured from the software:
//!
//! * trace: (profile length + λc) at the measuring speed, then back at the return speed;
//! * read-out wire time: the `RDEVA` commands' and replies' bytes at the instrument's baud
//!   rate (the simulator paces both, as a real wire would);
//! * move: 0.01 mm on the planner's trapezoid (feed, `$121` acceleration);
//! * settle: the configured settle time (read back from the journal's start record).
//!
//! What is left is the software's share: polling granularity, the durable writes before the
//! stage may move, the incremental fit, command round trips. Target: ≤ 50 ms per line. It is
//! split with each line's own trace timestamps (`started_at`, `finished_at`) into the
//! instrument exchange and the rest (commit, fit, step).
//!
//! A second figure isolates the stage: 31 scan steps through the real driver and motion
//! policy over a pseudo-terminal against the simulated board at real speed, each step's time
//! beyond its trapezoid and settle.
//!
//! `cargo bench --bench scan_overhead [-- --lines N --speed-up S]` (defaults 31 lines, the
//! instrument 50× faster than real time). Short status and result replies are counted as
//! overhead, not device time, so the figure errs high.

#[path = "shared/mod.rs"]
mod shared;

use std::path::Path;
use std::process::Command;
use std::time::Duration;
use surfscan::devices::YAxis;
use surfscan::scan::journal::{read_journal, Record};
use surfscan::scan::station::open_stage;
use surfscan::stage::StageSettings;
use surfscan::units::Nm;
use surfscan_sim::grbl::{GrblSimConfig, StageShared};
use surfscan_sim::{InstrumentConfig, ProfileSet, SimEvent, SimHandle, Simulator};

/// The plan's first line, mm (GRBL machine coordinates are negative after homing).
const Y_START_MM: f64 = -20.0;
const Y_STEP_MM: f64 = 0.01;
/// The instrument's baud rate in the demo configuration.
const BAUD: u32 = 38_400;
/// Points per `RDEVA` block the client asks for (`profile-block = "RDEVA{n}"`, n ≤ 50).
const BLOCK: usize = 50;
/// The stage-alone figure's settle time, ms.
const SETTLE_MS: u64 = 20;
/// GRBL jog feed (the configuration's default), mm/min.
const FEED_MM_MIN: f64 = 60.0;
/// The simulated GRBL board's `$121`, mm/s².
const ACCEL_MM_S2: f64 = 10.0;

struct Args {
    lines: usize,
    speed_up: f64,
}

fn args() -> Args {
    Args {
        lines: shared::number_arg("--lines")
            .map_or(31, |v| v as usize)
            .clamp(6, 31),
        speed_up: shared::number_arg("--speed-up").unwrap_or(50.0),
    }
}

/// Bytes on the wire for the read-out of `n` points: `RDEVA00` + CR → `OK` + 5 digits + CR,
/// then per block of up to 50 `RDEVAnn` + CR → `OKnn` + `,` + 9 characters per value + CR.
fn readout_bytes(n: usize) -> usize {
    let mut bytes = 8 + 8;
    let mut left = n;
    while left > 0 {
        let k = left.min(BLOCK);
        bytes += 8 + 4 + 10 * k + 1;
        left -= k;
    }
    bytes
}

/// 0.01 mm on a trapezoid at `FEED_MM_MIN` and `ACCEL_MM_S2`, s.
fn step_move_s() -> f64 {
    let (d, v, a) = (Y_STEP_MM, FEED_MM_MIN / 60.0, ACCEL_MM_S2);
    if d >= v * v / a {
        d / v + v / a
    } else {
        2.0 * (d / a).sqrt()
    }
}

fn main() {
    let a = args();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(stage_alone());
    rt.block_on(run(a));
}

/// The simulated board at real speed, just powered up 1 mm above the scan's first line;
/// `shared` counts its homing cycles and moves.
fn board(sim: Simulator, link: &Path, shared: std::sync::Arc<StageShared>) -> Simulator {
    sim.grbl_stage(
        link,
        GrblSimConfig {
            backlash_mm: 0.02,
            start_mm: Y_START_MM + 1.0,
            ..GrblSimConfig::default()
        },
        shared,
    )
}

async fn ready(sim: Simulator) -> SimHandle {
    let mut h = sim.start().expect("simulator starts");
    match tokio::time::timeout(Duration::from_secs(10), h.next_event()).await {
        Ok(Some(SimEvent::Ready(_))) => h,
        other => panic!("simulator not ready: {other:?}"),
    }
}

/// 31 scan steps of the stage alone: time per step beyond trapezoid and settle.
async fn stage_alone() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let link = tmp.path().join("ystage");
    let h = ready(board(
        Simulator::without_instrument(),
        &link,
        StageShared::new(),
    ))
    .await;
    let text = format!(
        "port = {:?}\nprotocol = \"grbl\"\nsteps-per-mm = 400\nsoft-limit-min-mm = -100\n\
         soft-limit-max-mm = 0\nbacklash-mm = 0.05\nsettle-ms = {SETTLE_MS}\n\
         feed-mm-min = {FEED_MM_MIN:?}\npoll-interval-ms = 200\n",
        link.display().to_string()
    );
    let settings: StageSettings = toml::from_str(&text).expect("stage settings");
    let mut axis = open_stage(&settings).expect("opens the pty");
    axis.connect().await.expect("connects");
    axis.home().await.expect("homes");
    let y0 = Nm((Y_START_MM * 1e6) as i64);
    axis.move_to(y0).await.expect("first line");
    let device = step_move_s() + SETTLE_MS as f64 / 1000.0;
    let mut over = Vec::new();
    for k in 1..31 {
        let t0 = std::time::Instant::now();
        axis.move_to(Nm(y0.0 + k * 10_000)).await.expect("step");
        over.push((t0.elapsed().as_secs_f64() - device) * 1000.0);
    }
    h.shutdown().await;
    let max = over.iter().copied().fold(f64::MIN, f64::max);
    println!(
        "stage alone: 30 steps of 0.01 mm, device time {:.1} ms each (move {:.1} + settle {:.1}); \
         overhead median {:.1} ms, max {max:.1} ms",
        device * 1000.0,
        step_move_s() * 1000.0,
        SETTLE_MS as f64,
        shared::median(&mut over)
    );
}

async fn run(a: Args) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let inst_link = tmp.path().join("sj210");
    let stage_link = tmp.path().join("ystage");
    let out = tmp.path().join("scans");
    let mut profiles = ProfileSet::bundled().expect("bundled profiles");
    profiles.y_first_mm = Y_START_MM;
    let first = profiles.profiles().first().expect("a profile").clone();
    let instrument = InstrumentConfig {
        time_scale: 1.0 / a.speed_up,
        ..InstrumentConfig::default()
    };
    let measure_speed = instrument.measure_speed_mm_s;
    let return_speed = instrument.return_speed_mm_s;
    let lambda_c = instrument.conditions.lambda_c_mm();
    let sim = Simulator::new(&inst_link)
        .instrument(instrument)
        .profiles(profiles)
        .baud(BAUD);
    let stage = StageShared::new();
    let h = ready(board(sim, &stage_link, stage.clone())).await;
    let cfg = tmp.path().join("bench.toml");
    let text = shared::demo_config(&inst_link, &stage_link, &out, a.lines);
    assert!(text.contains(&format!("baud = {BAUD}")), "{text}");
    std::fs::write(&cfg, text).expect("config");
    let run = tokio::task::spawn_blocking(move || {
        Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["scan", "--config"])
            .arg(&cfg)
            .args(["--specimen", "bench", "--operator", "bench"])
            .output()
            .expect("surfscan scan runs")
    })
    .await
    .expect("scan task");
    h.shutdown().await;
    assert!(
        run.status.success(),
        "scan failed: {}\n{}",
        run.status,
        String::from_utf8_lossy(&run.stderr)
    );
    let dir = std::fs::read_dir(&out)
        .expect("scans dir")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.join("journal.jsonl").exists())
        .expect("a scan directory with a journal");
    let rec = read_journal(&dir.join("journal.jsonl")).expect("journal reads");
    let stage_cfg = rec.records.iter().find_map(|r| match r {
        Record::Start(s) => Some(s.config["stage"].clone()),
        _ => None,
    });
    let stage_cfg = stage_cfg.expect("a start record");
    let settle_ms = stage_cfg["settle-ms"].as_f64().expect("settle-ms recorded");
    let feed = stage_cfg["feed-mm-min"]
        .as_f64()
        .expect("feed-mm-min recorded");
    assert_eq!(feed, FEED_MM_MIN, "the move time below assumes this feed");
    let times: Vec<(u32, f64)> = rec
        .records
        .iter()
        .filter_map(|r| match r {
            Record::Line(l) => Some((l.id.index, l.time.timestamp_micros() as f64 / 1e6)),
            _ => None,
        })
        .collect();
    assert_eq!(times.len(), a.lines, "every line recorded once");

    let traverse = first.length_mm() + lambda_c;
    let trace_s = (traverse / measure_speed + traverse / return_speed) / a.speed_up;
    let wire_s = readout_bytes(first.z_um.len()) as f64 * 10.0 / f64::from(BAUD) / a.speed_up;
    let move_s = step_move_s();
    let settle_s = settle_ms / 1000.0;
    let device_s = trace_s + wire_s + move_s + settle_s;
    let mut periods = Vec::new();
    for w in times.windows(2) {
        assert_eq!(w[1].0, w[0].0 + 1, "lines in order");
        periods.push(w[1].1 - w[0].1);
    }
    // Where the overhead is: the instrument's share (trace start to profile read, against the
    // trace and wire time) from each line's own timestamps, and the rest of the period
    // (commit, fit, the step and settle) against the move and settle.
    let mut instrument_over = Vec::new();
    let mut between_over = Vec::new();
    for (w, p) in times.windows(2).zip(&periods) {
        let meta: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(format!("lines/{:04}.json", w[1].0)))
                .expect("line metadata"),
        )
        .expect("line metadata parses");
        let at = |k: &str| {
            chrono::DateTime::parse_from_rfc3339(meta[k].as_str().expect(k))
                .expect(k)
                .timestamp_micros() as f64
                / 1e6
        };
        let traced = at("finished_at") - at("started_at");
        instrument_over.push((traced - trace_s - wire_s) * 1000.0);
        between_over.push((p - traced - move_s - settle_s) * 1000.0);
    }
    let mut over: Vec<f64> = periods.iter().map(|p| (p - device_s) * 1000.0).collect();
    let mean = over.iter().sum::<f64>() / over.len() as f64;
    let max = over.iter().copied().fold(f64::MIN, f64::max);
    let med = shared::median(&mut over);
    let mut p = periods.clone();
    println!(
        "scan_overhead: {} lines, instrument {}x real time, stage at real speed",
        a.lines, a.speed_up
    );
    println!(
        "  device time per line {:.1} ms = trace {:.1} + read-out wire {:.1} ({} points) + move {:.1} + settle {:.1}",
        device_s * 1000.0,
        trace_s * 1000.0,
        wire_s * 1000.0,
        first.z_um.len(),
        move_s * 1000.0,
        settle_s * 1000.0
    );
    println!(
        "  line period median {:.1} ms over {} periods",
        shared::median(&mut p) * 1000.0,
        periods.len()
    );
    println!("  overhead per line: median {med:.1} ms, mean {mean:.1} ms, max {max:.1} ms (target <= 50 ms median)");
    println!(
        "    of which: trace start to profile read beyond trace + wire, median {:.1} ms; \
         profile read to the next trace start beyond move + settle (commit, fit, step), \
         median {:.1} ms",
        shared::median(&mut instrument_over),
        shared::median(&mut between_over)
    );
    let homes = stage
        .homing_cycles
        .load(std::sync::atomic::Ordering::SeqCst);
    let moves = stage
        .moves_started
        .load(std::sync::atomic::Ordering::SeqCst);
    println!(
        "  the board saw {homes} homing cycle(s) and {moves} moves for {} lines (home once: {})",
        a.lines,
        if homes == 1 { "yes" } else { "NO" }
    );
    println!("  target {}", if med <= 50.0 { "met" } else { "NOT met" });
}
