//! Fit benchmark: throughput of the paper's surface interpolation on synthetic roughness-like
//! grids, the time `finish()` takes after the last line of a 31-line scan, and peak memory.
//!
//! `cargo bench --bench fit [-- CASE...]` with CASE among `31x2000`, `31x8000`, `1000x10000`,
//! `finish`, `residual` (the residual check and the CSV
//! parse of a 31×8000 grid) (default: all). Figures are medians of several runs (21 for the small grids, 5 for
//! the large one); the fit is single-threaded, so they are one core's figures.

use std::time::Instant;
use surfscan::fit::{fit_grid, max_residual_mm, FitOptions, FitResult, IncrementalFitter};

/// Runs per large case (a 10⁷-point fit takes a quarter of a second).
const RUNS: usize = 5;
/// Runs per small case: enough that the median is stable on a machine shared with builds.
const SMALL_RUNS: usize = 21;
const PITCH_X_MM: f64 = 0.0005;
const PITCH_Y_MM: f64 = 0.01;

/// Roughness-like heights in µm, row-major: two waves plus uniform noise from an LCG.
fn synthetic_grid(rows: usize, cols: usize) -> Vec<f64> {
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut out = Vec::with_capacity(rows * cols);
    for l in 0..rows {
        for k in 0..cols {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5;
            out.push(
                1.2 * (k as f64 * 0.0123 + l as f64 * 0.3).sin()
                    + 0.3 * (k as f64 * 0.21).cos()
                    + 0.6 * noise,
            );
        }
    }
    out
}

fn y_positions(rows: usize) -> Vec<f64> {
    (0..rows).map(|l| l as f64 * PITCH_Y_MM).collect()
}

/// CPU time of this process so far, s (all threads; with one thread, one core's work). It
/// leaves out time spent waiting for the CPU, so it stays meaningful on a loaded machine.
fn cpu_s() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return f64::NAN;
    }
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Peak resident set size of this process in MB (VmHWM), if readable.
fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// The fit alone: one `fit_grid` call, timed from the caller's side (wall s, CPU s).
fn fit_once(y: &[f64], h: &[f64], cols: usize) -> (FitResult, f64, f64) {
    let (t, c) = (Instant::now(), cpu_s());
    let r = fit_grid(PITCH_X_MM, y, h, cols, FitOptions::default()).expect("fit");
    (r, t.elapsed().as_secs_f64(), cpu_s() - c)
}

/// Consumer of a fitted surface after the fit (output stages are timed here, separately).
fn after_fit(_result: &FitResult) {}

/// FNV-1a (one 64-bit word per step) over the bits of the knots and poles: equal digests mean bit-identical surfaces,
/// so a change that should only make the fit faster can be checked against the old build.
fn digest(r: &FitResult) -> u64 {
    let s = &r.surface;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let values = s
        .knots_u()
        .iter()
        .chain(s.knots_v())
        .copied()
        .chain(s.poles().flatten());
    for v in values {
        h = (h ^ v.to_bits()).wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn bench_grid(rows: usize, cols: usize) {
    let runs = if rows * cols >= 1_000_000 {
        RUNS
    } else {
        SMALL_RUNS
    };
    let h = synthetic_grid(rows, cols);
    let y = y_positions(rows);
    let points = (rows * cols) as f64;
    let (mut wall, mut params, mut factor, mut su, mut sv) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut sum = 0;
    let mut cpu = Vec::new();
    for _ in 0..runs {
        let (r, w, c) = fit_once(&y, &h, cols);
        cpu.push(c);
        if sum == 0 {
            sum = digest(&r);
        }
        wall.push(w);
        params.push(r.timings.params_s);
        factor.push(r.timings.knots_factor_s);
        su.push(r.timings.solve_u_s);
        sv.push(r.timings.solve_v_s);
        after_fit(&r);
    }
    let w = median(wall);
    println!(
        "{rows}x{cols}: fit {:.4} s wall (median of {runs}), {:.1} M points/s, CPU {:.4} s ({:.1} M points/s) | params {:.4} s, knots+factor {:.5} s, solve_u {:.4} s, solve_v+assemble {:.4} s | digest {sum:016x}",
        w,
        points / w / 1e6,
        median(cpu.clone()),
        points / median(cpu) / 1e6,
        median(params),
        median(factor),
        median(su),
        median(sv)
    );
}

/// The residual check of a 31×8000 fit (distance of every data point to the surface), and
/// reading the same grid from CSV text with four-decimal heights.
fn bench_residual_and_csv(rows: usize, cols: usize, runs: usize) {
    let h = synthetic_grid(rows, cols);
    let y = y_positions(rows);
    let (r, _, _) = fit_once(&y, &h, cols);
    let grid = surfscan::grid::Grid::new(h.clone(), cols, PITCH_X_MM, y.clone());
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    let mut worst = 0.0;
    for _ in 0..runs {
        let (t, c) = (Instant::now(), cpu_s());
        worst = max_residual_mm(&r, &grid);
        wall.push(t.elapsed().as_secs_f64());
        cpu.push(cpu_s() - c);
    }
    println!(
        "{rows}x{cols} residual check: {:.2} ms wall, {:.2} ms CPU (median of {runs}; target <= 2 ms), max residual {worst:.3e} mm",
        median(wall) * 1e3,
        median(cpu) * 1e3
    );
    let mut text = String::with_capacity(rows * cols * 8);
    for row in h.chunks_exact(cols) {
        for (k, v) in row.iter().enumerate() {
            use std::fmt::Write;
            let sep = if k + 1 == cols { '\n' } else { ',' };
            let _ = write!(text, "{v:.4}{sep}");
        }
    }
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    let options = surfscan::input::ReadOptions {
        pitch_x_mm: Some(0.0005),
        pitch_y_mm: Some(0.01),
        z_unit: None,
    };
    for _ in 0..runs {
        let bytes = text.clone().into_bytes();
        let (t, c) = (Instant::now(), cpu_s());
        let g = surfscan::input::read_csv(std::path::Path::new("bench.csv"), bytes, &options)
            .expect("parse")
            .grid;
        wall.push(t.elapsed().as_secs_f64());
        cpu.push(cpu_s() - c);
        assert_eq!(g.heights_um.len(), rows * cols);
    }
    let n = (rows * cols) as f64;
    println!(
        "{rows}x{cols} grid CSV parse ({:.1} MB): {:.2} ms wall, {:.2} ms CPU, {:.1} ns per number (median of {runs})",
        text.len() as f64 / 1e6,
        median(wall.clone()) * 1e3,
        median(cpu) * 1e3,
        median(wall) / n * 1e9
    );
}

fn bench_finish() {
    let (rows, cols) = (31, 8000);
    let h = synthetic_grid(rows, cols);
    let y = y_positions(rows);
    let mut fitter = IncrementalFitter::new(FitOptions::default());
    for (row, &yy) in h.chunks_exact(cols).zip(&y).take(rows - 1) {
        fitter.push_row(yy, PITCH_X_MM, row).expect("push");
    }
    let last = &h[(rows - 1) * cols..];
    let (mut push, mut finish, mut finish_cpu) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..SMALL_RUNS {
        let mut f = fitter.clone();
        let t = Instant::now();
        f.push_row(y[rows - 1], PITCH_X_MM, last).expect("push");
        push.push(t.elapsed().as_secs_f64());
        let (t, c) = (Instant::now(), cpu_s());
        let r = f.finish().expect("finish");
        finish.push(t.elapsed().as_secs_f64());
        finish_cpu.push(cpu_s() - c);
        after_fit(&r);
    }
    println!(
        "31x8000 incremental: push_line(31st) {:.2} ms, finish() {:.2} ms, CPU {:.2} ms (medians of {SMALL_RUNS})",
        median(push) * 1e3,
        median(finish) * 1e3,
        median(finish_cpu) * 1e3
    );
}

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --all-targets` does not. Under the test
    // runner the debug build would spend minutes on the large grids, so it only checks that
    // the benchmark runs on the small grid.
    if !std::env::args().any(|a| a == "--bench") {
        bench_grid(31, 2000);
        bench_residual_and_csv(7, 300, 1);
        return;
    }
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let want = |name: &str| args.is_empty() || args.iter().any(|a| a == name);
    if want("31x2000") {
        bench_grid(31, 2000);
    }
    if want("31x8000") {
        bench_grid(31, 8000);
    }
    if want("residual") {
        bench_residual_and_csv(31, 8000, SMALL_RUNS);
    }
    if want("finish") {
        bench_finish();
    }
    if want("1000x10000") {
        bench_grid(1000, 10000);
        match peak_rss_mb() {
            Some(mb) => println!("peak RSS after 1000x10000: {mb:.0} MB (VmHWM)"),
            None => println!("peak RSS: /proc/self/status not readable"),
        }
    }
}
