//! What more than one benchmark needs: its command-line options, the demo's station
//! configuration, the median of a sample and a rough synthetic profile.
//! Included by path (`#[path = "shared/mod.rs"] mod shared;`): each benchmark is its own crate.

#![allow(dead_code)]

/// Whether `cargo bench` runs the benchmark (it passes `--bench`); without it (as `cargo test
/// --all-targets` runs every benchmark) a benchmark makes a short run, only to check that it
/// runs.
pub fn full_run() -> bool {
    std::env::args().any(|a| a == "--bench")
}

/// The number after the option `name` on the command line (`-- --lines 8`); `None` when the
/// option is not given or its value is no number.
pub fn number_arg(name: &str) -> Option<f64> {
    let args: Vec<String> = std::env::args().collect();
    args.windows(2)
        .rev()
        .find(|w| w[0] == name)
        .and_then(|w| w[1].parse().ok())
}

/// The demo's configuration (`surfscan demo`) for devices `instrument` and `stage`, scans
/// under `out`, with `lines` lines a scan.
pub fn demo_config(
    instrument: &std::path::Path,
    stage: &std::path::Path,
    out: &std::path::Path,
    lines: usize,
) -> String {
    let text = surfscan::cli::demo::demo_config(instrument, stage, out);
    assert!(
        text.contains("lines = 31"),
        "the demo's config has changed:\n{text}"
    );
    text.replace("lines = 31", &format!("lines = {lines}"))
}

/// The median of `v` (sorted in place); the mean of the middle two for an even count.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// A rough profile of `n` heights within ±150 µm, 3 decimals, every one printed in the
/// simulator's 9-character field (a deterministic sum of sines, no randomness).
pub fn rough_heights_um(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let x = i as f64;
            let z = 80.0 * (x * 0.013).sin() + 40.0 * (x * 0.171).sin() + 9.0 * (x * 1.37).cos();
            (z * 1000.0).round() / 1000.0
        })
        .collect()
}
