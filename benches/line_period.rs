//! The instrument's share of a scan line, each way: the real SJ-210 client (`wait_idle`, then
//! `trace_line`, as the scan runs them) against the simulator over a pseudo-terminal, paced at
//! each of the SJ-210's baud rates, with the read-out after the drive's return and during it.
//! A line's period is one such cycle at steady state: the wait for the previous return (when
//! it was read out during it), the conditions, the trace, the results and the read-out.
//!
//! The device time each way is worked out here from the simulated instrument's parameters, not
//! measured: traverse (evaluation length + λc) at 0.5 mm/s out and 1 mm/s back; the read-out's
//! and the results' bytes at the baud rate (10 bits a byte, both directions). After the
//! return: trace + return + wire; during it: trace + the longer of return and wire. What is
//! left is the software's share (command turnaround, the status seen after each end).
//!
//! `cargo bench --bench line_period [-- --speed-up S --points N --lines L --baud B]`
//! (defaults: an 8000-point profile, λc 0.8 mm × 5 at 0.5 µm; the instrument S = 10× faster
//! than real time, its pacing included; 2 lines after a first one; every SJ-210 rate). The
//! software's share is measured as it is (the wall time of a cycle less the sped-up device
//! time), not scaled: a line's period in real time is the device time plus that share.
//! Without `--bench` (as `cargo test --all-targets` runs it) one short line each way, only to
//! check that it runs.

#[path = "shared/mod.rs"]
mod shared;

use std::time::{Duration, Instant};
use surfscan::sj210::client::Sj210Client;
use surfscan::sj210::models::{CommandOverrides, ModelId, ModelTable};
use surfscan::sj210::rate_search::{readout_wire_s, LineSetting};
use surfscan::sj210::settings::ClientOptions;
use surfscan::sj210::timing::DriveSpeeds;
use surfscan::transport::{FlowControl, Parity, SerialSettings};
use surfscan_sim::data::ServedProfile;
use surfscan_sim::instrument::Conditions;
use surfscan_sim::stats::SimStats;
use surfscan_sim::{InstrumentConfig, ProfileSet, SimEvent, Simulator};

const MEASURE_MM_S: f64 = 0.5;
const RETURN_MM_S: f64 = 1.0;
const PITCH_MM: f64 = 0.0005;
const LAMBDA_C_MM: f64 = 0.8;
/// The simulated instrument's result parameters (`RDPAR` answers 09).
const PARAMETERS: u64 = 9;

struct Args {
    speed_up: f64,
    points: usize,
    lines: usize,
    bauds: Vec<u32>,
}

fn args() -> Args {
    let (speed_up, points, lines, bauds) = if shared::full_run() {
        (10.0, 8000, 2, vec![9600, 19200, 38400])
    } else {
        (100.0, 1600, 1, vec![38400])
    };
    let number = shared::number_arg;
    let points = number("--points").map_or(points, |v| v as usize);
    Args {
        speed_up: number("--speed-up").unwrap_or(speed_up).max(1.0),
        // Whole sampling lengths of λc 0.8 mm at 0.5 µm (1600 points each), 1 to 10.
        points: (points / 1600).clamp(1, 10) * 1600,
        lines: number("--lines").map_or(lines, |v| v as usize).max(1),
        bauds: number("--baud").map_or(bauds, |v| vec![v as u32]),
    }
}

/// Bytes of the results on the wire: `RDPAR` and its count, then per parameter `RDRES02,aa,00`
/// and its `OK` + name 6 + value 7 + unit 3.
fn results_bytes() -> u64 {
    6 + 5 + PARAMETERS * (14 + 2 + 6 + 7 + 3 + 1)
}

struct Measured {
    /// Wall time of each cycle at the speed-up, s.
    cycles_s: Vec<f64>,
    answered_returning: u64,
}

async fn measure(a: &Args, baud: u32, during: bool) -> Measured {
    let dir = tempfile::tempdir().expect("temp dir");
    let link = dir.path().join("sj210");
    let set = ProfileSet::new(vec![ServedProfile {
        y_mm: 0.0,
        pitch_x_mm: PITCH_MM,
        z_um: shared::rough_heights_um(a.points),
    }])
    .expect("profile");
    let cfg = InstrumentConfig {
        time_scale: 1.0 / a.speed_up,
        reads_during_return: during,
        measure_speed_mm_s: MEASURE_MM_S,
        return_speed_mm_s: RETURN_MM_S,
        conditions: Conditions {
            lambda_c_code: 2,
            sampling_lengths: (a.points / 1600) as u8,
            ..Conditions::default()
        },
        ..InstrumentConfig::default()
    };
    let mut sim = Simulator::new(&link)
        .instrument(cfg)
        .profiles(set)
        .baud(baud)
        .start()
        .expect("simulator starts");
    match tokio::time::timeout(Duration::from_secs(10), sim.next_event()).await {
        Ok(Some(SimEvent::Ready(_))) => {}
        other => panic!("simulator not ready: {other:?}"),
    }
    let stats = sim.stats();
    let port = surfscan::transport::open(&SerialSettings {
        path: link.display().to_string(),
        baud,
        parity: Parity::None,
        flow_control: FlowControl::None,
    })
    .expect("pty opens");
    let table = ModelTable::with_overrides(
        ModelId::Sj210,
        &CommandOverrides {
            profile_total: Some("RDEVA00".into()),
            profile_block: Some("RDEVA{n}".into()),
            reads_during_return: Some(during),
            ..CommandOverrides::default()
        },
    )
    .expect("table");
    // The client's view of the drive and its poll interval, sped up as the instrument is.
    let opts = ClientOptions {
        poll_interval: Duration::from_secs_f64(0.25 / a.speed_up),
        speeds: DriveSpeeds {
            measuring_mm_s: MEASURE_MM_S * a.speed_up,
            return_mm_s: RETURN_MM_S * a.speed_up,
        },
        trace_deadline: Some(Duration::from_secs(600)),
        ..ClientOptions::default()
    };
    let mut client = Sj210Client::new(port, table, opts);
    let mut cycles_s = Vec::new();
    for k in 0..=a.lines {
        let t0 = Instant::now();
        client.wait_idle().await.expect("idle");
        let line = client.trace_line().await.expect("line");
        assert_eq!(line.profile.heights_um.len(), a.points);
        // The first line has no return before it to wait for.
        if k > 0 {
            cycles_s.push(t0.elapsed().as_secs_f64());
        }
    }
    client.wait_idle().await.expect("idle at the end");
    drop(client);
    sim.shutdown().await;
    Measured {
        cycles_s,
        answered_returning: SimStats::get(&stats.reads_answered_returning),
    }
}

fn main() {
    let a = args();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    let traverse = a.points as f64 * PITCH_MM + LAMBDA_C_MM;
    let trace_s = traverse / MEASURE_MM_S;
    let return_s = traverse / RETURN_MM_S;
    println!(
        "line_period: {} points ({traverse:.1} mm traverse: trace {trace_s:.1} s, return {return_s:.1} s); \
         instrument {}x real time, the software's share as measured; median of {} lines",
        a.points, a.speed_up, a.lines
    );
    for &baud in &a.bauds {
        let setting = LineSetting {
            baud,
            parity: Parity::None,
        };
        let wire_s = readout_wire_s(a.points as u32, setting)
            + results_bytes() as f64 * 10.0 / f64::from(baud);
        let mut row = Vec::new();
        for during in [false, true] {
            let m = rt.block_on(measure(&a, baud, during));
            let device = if during {
                trace_s + return_s.max(wire_s)
            } else {
                trace_s + return_s + wire_s
            };
            let mut c = m.cycles_s.clone();
            let software = shared::median(&mut c) - device / a.speed_up;
            let period = device + software;
            row.push(period);
            println!(
                "  {baud:>5} baud, read-out {}: line period {period:.2} s = device {device:.2} s \
                 (trace {trace_s:.1} + {}) + software {:.0} ms; {} reads answered during the return",
                if during { "during the return" } else { "after the return " },
                if during {
                    format!("the longer of return {return_s:.1} and wire {wire_s:.2}")
                } else {
                    format!("return {return_s:.1} + wire {wire_s:.2}")
                },
                software * 1000.0,
                m.answered_returning
            );
        }
        println!(
            "  {baud:>5} baud: reading out during the return saves {:.2} s a line ({:.1} %)",
            row[0] - row[1],
            (row[0] - row[1]) / row[0] * 100.0
        );
    }
}
