//! `surfscan list` on a station with 10,000 scans: synthetic scan directories (a journal of
//! 31 lines and a report each, a third of them with each verdict) in a temporary directory,
//! then the real binary's `list` timed as an operator would run it.
//!
//! `cargo bench --bench list` prints: building the index from the journals (no index yet),
//! a listing of everything with the index up to date (the target: under a second), a
//! filtered listing, and a listing after one scan changed. Without `--bench` (as
//! `cargo test --all-targets` runs it) it uses 200 scans, only to check that it runs.
//! `-- --scans N` changes the number.

#[path = "shared/mod.rs"]
mod shared;

use std::process::Command;
use std::time::Instant;
use surfscan::jobs::synthetic::{write, SyntheticReport, SyntheticScan};
use surfscan::scan::journal::StopStatus;
use surfscan::specification::Verdict;

fn synthetic(k: u64) -> SyntheticScan {
    let verdict = [
        Verdict::Conforms,
        Verdict::DoesNotConform,
        Verdict::NotDecidable,
    ][k as usize % 3];
    let started = chrono::DateTime::from_timestamp(1_760_000_000 + k as i64 * 3600, 0).unwrap();
    SyntheticScan {
        id: format!("{}-C{k:05}", started.format("%Y%m%dT%H%M%SZ")),
        sequence: k,
        started,
        specimen: format!("C{k:05}"),
        recipe: Some((
            ["brass", "steel", "al"][(k / 3) as usize % 3].to_owned(),
            Some(k),
        )),
        lines: 31,
        done: 31,
        stop: Some(StopStatus::Success),
        report: Some(SyntheticReport {
            verdict: Some(verdict),
            ra_um: (0..31).map(|i| 0.5 + f64::from(i) * 0.01).collect(),
            sa_um: 0.7,
            warnings: (k % 4) as usize,
        }),
    }
}

/// Runs `surfscan list --dir DIR ARGS`, returns seconds and lines of output.
fn list(dir: &std::path::Path, args: &[&str]) -> (f64, usize) {
    let t = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("list")
        .arg("--dir")
        .arg(dir)
        .args(args)
        .output()
        .expect("run surfscan list");
    let s = t.elapsed().as_secs_f64();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (s, out.stdout.iter().filter(|&&b| b == b'\n').count())
}

/// The median of an odd number of timings.
fn median(mut v: Vec<f64>) -> f64 {
    shared::median(&mut v)
}

fn main() {
    let full = shared::full_run();
    let n = shared::number_arg("--scans").map_or(if full { 10_000 } else { 200 }, |v| v as u64);
    let tmp = tempfile::tempdir().expect("temporary directory");
    let dir = tmp.path();
    let t = Instant::now();
    for k in 1..=n {
        write(dir, &synthetic(k)).expect("write a synthetic scan");
    }
    println!(
        "{n} synthetic scans written in {:.1} s ({})",
        t.elapsed().as_secs_f64(),
        dir.display()
    );
    let (rebuild, rows) = list(dir, &[]);
    assert_eq!(rows as u64, n + 1, "a header and one row per scan");
    println!("list with no index (built from the journals and reports): {rebuild:.3} s");
    let warm = median((0..5).map(|_| list(dir, &[]).0).collect());
    let verdict = if !full {
        "not judged without --bench"
    } else if warm < 1.0 {
        "met"
    } else {
        "MISSED"
    };
    println!("list of all {n} scans, index up to date (median of 5): {warm:.3} s; target < 1 s: {verdict}");
    let filtered = median(
        (0..5)
            .map(|_| {
                list(
                    dir,
                    &["--verdict", "does-not-conform", "--since", "2026-01-01"],
                )
                .0
            })
            .collect(),
    );
    println!("list --verdict does-not-conform --since 2026-01-01 (median of 5): {filtered:.3} s");
    let json = median((0..3).map(|_| list(dir, &["--json"]).0).collect());
    println!("list --json of all {n} scans (median of 3): {json:.3} s");
    let mut changed = synthetic(n / 2);
    changed.report.as_mut().unwrap().warnings = 9;
    write(dir, &changed).expect("rewrite one scan");
    let (one, _) = list(dir, &[]);
    println!("list after one scan's report changed: {one:.3} s");
}
