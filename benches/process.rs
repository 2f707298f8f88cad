//! Whole-process benchmark: the real `surfscan` binary on grid CSVs, timed from outside as an
//! operator would see it, beside the paper-exact banded scipy references measured in the same
//! run (the fit alone, CSV reading and imports excluded): `tests/python/fit_scipy_banded_xyz.py`
//! interpolates every point's x, y and z as the paper's P(x, y, z) does (the target's
//! reference), `tests/python/fit_scipy_banded.py` the heights only.
//!
//! `cargo bench --bench process [-- CASE...] [--instructions]` with CASE among
//! * `fit` — `surfscan fit` 31×8000, CSV in → a new IGES file fsynced; 15 runs alternating
//!   with the references, each followed by a run that replaces the file it wrote. Target: the
//!   full-xyz reference's fit time ÷ ours ≥ 1.3. Beside it, the time this disk takes to make the same
//!   bytes durable through the path `fit` writes them through (writeback started as they are
//!   written, fsync, rename): the floor of any process that must.
//! * `large` — `surfscan fit` 1000×10000 (several IGES files); 3 runs. Targets: ≤ 2.5 s and
//!   peak RSS ≤ 3 × the grid's f64 bytes (80 MB).
//! * `analyze` — `surfscan analyze` of the 31×8000 grid CSV (λc 0.8 mm filter, model, hold-out,
//!   plots, X3P); 7 runs. Target ≤ 0.3 s.
//! * `analyze-1core` — `surfscan analyze` of the 31×8000 grid against surfalize's per-line
//!   roughness of it (`tests/python/lines_surfalize.py`: each line's λc 0.8 mm Gaussian
//!   high-pass and Ra, Rq, Rz, Rsk, Rku, timed alone), both pinned to one core with `taskset`;
//!   7 runs alternating. Target: surfalize's time ÷ ours ≥ 1.3.
//! * `analyze-large` — `surfscan analyze` of the 1000×10000 grid beside `surfscan fit` of
//!   it; 3 runs. Targets: ≤ 2× the fit's wall time, peak RSS ≤ 3 × the grid's f64 bytes,
//!   report.html ≤ 5 MB, each figure file ≤ 2 MB.
//! * `scan` — `characterise_scan` (the daemon's characterisation) of 31×8000 scan directories
//!   with an R profile (no filter) and a P profile (λc filter), in-process; 5 runs each.
//!
//! Default: all six. Figures are medians; CPU time (user + system, all threads, of the child
//! from `wait4`) is printed beside wall time because the machine is shared: a run that waited
//! for a core shows it in wall time only. `--instructions` also runs each binary case once
//! under `valgrind --tool=callgrind` and prints the instruction count, the figure least moved
//! by other load (valgrind serialises threads and is slow: about a minute for `fit`).
//!
//! Without `--bench` (as under `cargo test --all-targets`) every case runs once on a small
//! grid, so the benchmark itself is checked.

use chrono::{TimeZone, Utc};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::Instant;
use surfscan::profile::{Conditions, FilterKind, NoHeights, Profile, ProfileKind};
use surfscan::report::{characterise_scan, ScanAnalysisOptions};
use surfscan::scan::faults::NoFaults;
use surfscan::scan::journal::{Journal, StartRecord};
use surfscan::scan::line::{LineIdentity, LineMeta};
use surfscan::scan::scan_id::ScanId;
use surfscan::scan::store::ScanStore;
use surfscan::units::Nm;

const PITCH_X_MM: f64 = 0.0005;
const PITCH_Y_MM: f64 = 0.01;

/// The python interpreter with numpy and scipy: `SURFSCAN_PYTHON`, else the project's `.venv`.
fn python() -> PathBuf {
    match std::env::var_os("SURFSCAN_PYTHON") {
        Some(p) => PathBuf::from(p),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python3"),
    }
}

/// Roughness-like heights in µm with four decimals, as a profiler exports them: two waves plus
/// uniform noise from an LCG. Row-major CSV, no header.
fn write_grid_csv(path: &Path, rows: usize, cols: usize) {
    use std::io::Write;
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).expect("create grid csv"));
    for l in 0..rows {
        for k in 0..cols {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5;
            let h = 1.2 * (k as f64 * 0.0123 + l as f64 * 0.3).sin()
                + 0.3 * (k as f64 * 0.21).cos()
                + 0.6 * noise;
            let sep = if k + 1 == cols { "\n" } else { "," };
            write!(out, "{h:.4}{sep}").expect("write grid csv");
        }
    }
    out.flush().expect("flush grid csv");
}

/// One finished child: wall time, CPU time (user + system) and peak resident set.
struct Run {
    wall_s: f64,
    cpu_s: f64,
    max_rss_mb: f64,
    stdout: String,
}

/// Runs `cmd` to completion and reads its resource use with `wait4`; panics with its error
/// output when it fails.
// The child is reaped by `wait4` (which std's `Child` cannot do while returning the rusage).
#[allow(clippy::zombie_processes)]
fn run(cmd: &mut Command) -> Run {
    let dir = tempfile::tempdir().expect("tempdir");
    let (out_path, err_path) = (dir.path().join("out"), dir.path().join("err"));
    let t = Instant::now();
    let child = cmd
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).expect("stdout file"))
        .stderr(std::fs::File::create(&err_path).expect("stderr file"))
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}"));
    let mut status = 0;
    // SAFETY: an all-zero rusage is a valid value of the plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: the pid is our own unwaited child; status and usage are valid and writable.
    let rc = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    let wall_s = t.elapsed().as_secs_f64();
    assert_eq!(rc, child.id() as libc::pid_t, "wait4 failed");
    let stdout = std::fs::read_to_string(&out_path).unwrap_or_default();
    if !(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0) {
        panic!(
            "{cmd:?} failed (status {status}):\n{}\n{stdout}",
            std::fs::read_to_string(&err_path).unwrap_or_default()
        );
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Run {
        wall_s,
        cpu_s: tv(usage.ru_utime) + tv(usage.ru_stime),
        max_rss_mb: usage.ru_maxrss as f64 / 1024.0,
        stdout,
    }
}

/// Instructions the command executes, counted by callgrind (`None` without valgrind).
fn instructions(cmd: &Command) -> Option<u64> {
    let dir = tempfile::tempdir().ok()?;
    let out = Command::new("valgrind")
        .arg("--tool=callgrind")
        .arg(format!(
            "--callgrind-out-file={}",
            dir.path().join("cg.out").display()
        ))
        .arg(cmd.get_program())
        .args(cmd.get_args())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stderr);
    let line = text.lines().find(|l| l.contains("Collected :"))?;
    line.rsplit(':').next()?.trim().parse().ok()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn surfscan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
}

fn fit_command(csv: &Path, out: &Path) -> Command {
    let mut c = surfscan();
    c.arg("fit")
        .arg(csv)
        .arg("--pitch-x")
        .arg(PITCH_X_MM.to_string())
        .arg("--pitch-y")
        .arg(PITCH_Y_MM.to_string())
        .arg("-o")
        .arg(out);
    c
}

/// The z-only reference (`fit_scipy_banded.py`: the heights solved, x per pole column and y
/// per pole row from one solve each).
const Z_ONLY: &str = "fit_scipy_banded.py";
/// The full reference (`fit_scipy_banded_xyz.py`: every point interpolated as (x, y, z), as
/// the paper's P(x, y, z)), which the fit's target is set against.
const FULL_XYZ: &str = "fit_scipy_banded_xyz.py";

fn reference_command(script: &str, csv: &Path) -> Command {
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/python")
        .join(script);
    let mut c = Command::new(python());
    c.arg(script)
        .arg(csv)
        .arg(PITCH_X_MM.to_string())
        .arg(PITCH_Y_MM.to_string())
        .args(["5", "5"]);
    c
}

/// A reference's own figures for its fit: (wall s, CPU s).
fn reference_fit(script: &str, csv: &Path) -> (f64, f64) {
    let r = run(&mut reference_command(script, csv));
    let v: serde_json::Value = serde_json::from_str(&r.stdout)
        .unwrap_or_else(|e| panic!("reference printed no JSON ({e}): {}", r.stdout));
    (
        v["fit_s"].as_f64().expect("fit_s"),
        v["fit_cpu_s"].as_f64().expect("fit_cpu_s"),
    )
}

fn print_instructions(name: &str, cmd: &Command, wanted: bool) {
    if !wanted {
        return;
    }
    match instructions(cmd) {
        Some(n) => println!("  {name}: {:.1} M instructions (callgrind)", n as f64 / 1e6),
        None => println!("  {name}: instruction count unavailable (valgrind missing?)"),
    }
}

fn bench_fit(dir: &Path, rows: usize, cols: usize, runs: usize, count_instructions: bool) {
    let csv = dir.join(format!("grid{rows}x{cols}.csv"));
    write_grid_csv(&csv, rows, cols);
    let out = dir.join(format!("fit{rows}x{cols}.igs"));
    let (mut wall, mut cpu, mut ref_wall, mut ref_cpu, mut replacing) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut z_wall, mut z_cpu) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        // Each timed run writes a new file, as a fit of a new grid does: the previous run's
        // output is removed first (untimed), since replacing a file also frees the old one's
        // 21 MB, which is timed on its own just after.
        match std::fs::remove_file(&out) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => panic!("remove {}: {e}", out.display()),
        }
        let r = run(&mut fit_command(&csv, &out));
        wall.push(r.wall_s);
        cpu.push(r.cpu_s);
        replacing.push(run(&mut fit_command(&csv, &out)).wall_s);
        let (w, c) = reference_fit(FULL_XYZ, &csv);
        ref_wall.push(w);
        ref_cpu.push(c);
        let (w, c) = reference_fit(Z_ONLY, &csv);
        z_wall.push(w);
        z_cpu.push(c);
    }
    let (w, c, rw, rc) = (median(wall), median(cpu), median(ref_wall), median(ref_cpu));
    println!(
        "fit {rows}x{cols} whole process, CSV in -> new IGES file fsynced (medians of {runs}): {:.1} ms wall, {:.1} ms CPU | full-xyz scipy reference fit alone {:.1} ms wall, {:.1} ms CPU | reference/ours {:.2}x wall, {:.2}x CPU (target >= 1.3x)",
        w * 1e3,
        c * 1e3,
        rw * 1e3,
        rc * 1e3,
        rw / w,
        rc / c
    );
    let (zw, zc) = (median(z_wall), median(z_cpu));
    println!(
        "  the z-only scipy reference (x per column, y per row) fit alone: {:.1} ms wall, {:.1} ms CPU; against ours {:.2}x wall, {:.2}x CPU",
        zw * 1e3,
        zc * 1e3,
        zw / w,
        zc / c
    );
    println!(
        "  replacing the previous run's file instead: {:.1} ms wall (median of {runs})",
        median(replacing) * 1e3
    );
    let (disk_s, bytes) = disk_floor(&out, runs);
    println!(
        "  the disk alone: writing the {:.1} MB IGES file durably as `fit` does (already formatted) takes {:.1} ms (median of {runs}), {:.2}x the reference fit: the whole process cannot take less",
        bytes as f64 / 1e6,
        disk_s * 1e3,
        disk_s / rw
    );
    print_instructions("surfscan fit", &fit_command(&csv, &out), count_instructions);
    print_floor(&csv, rw, disk_s, runs);
}

/// Median wall and CPU time of `f` over `runs` calls on this thread (after one call to warm
/// it up): (wall s, CPU s).
fn timed<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, f64) {
    std::hint::black_box(f());
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let (t, c) = (Instant::now(), process_cpu_s());
        std::hint::black_box(f());
        wall.push(t.elapsed().as_secs_f64());
        cpu.push(process_cpu_s() - c);
    }
    (median(wall), median(cpu))
}

/// What no `surfscan fit` of this grid can go below on this machine, from its parts measured
/// one at a time, against the time the target leaves (the reference's fit ÷ 1.3):
///
/// * the chain: the process must start, read the grid, fit it (every pole depends on every
///   line), and only then can the disk take the surface's bytes, which takes the disk floor
///   measured above even when they are ready at once;
/// * the CPU: everything `fit` computes (the parse, the fit, the exact reals of every pole,
///   the verdict between lines that issue 12's honest model prints; the residual check runs
///   only for `--report`, which the case does not ask for) plus the kernel's copy of the
///   bytes, shared by this machine's cores at best perfectly.
///
/// Each part is measured warm and alone, so both bounds are below anything a real process
/// reaches (it pays page faults, thread start-ups and contention on top).
fn print_floor(csv: &Path, reference_s: f64, disk_s: f64, runs: usize) {
    use surfscan::fit::{fit_grid, FitOptions, VMethod};
    use surfscan::metrology::areal::{sq_um, HeightMap};
    use surfscan::metrology::holdout::between_lines;
    let bytes = std::fs::read(csv).expect("read grid csv");
    let read_options = surfscan::input::ReadOptions {
        pitch_x_mm: Some(PITCH_X_MM),
        pitch_y_mm: Some(PITCH_Y_MM),
        z_unit: None,
    };
    let read = || {
        surfscan::input::read_csv(csv, bytes.clone(), &read_options)
            .expect("read grid csv")
            .grid
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    let start_s = median(
        (0..runs)
            .map(|_| run(surfscan().arg("--version")).wall_s)
            .collect(),
    );
    let (parse_s, parse_cpu) = timed(runs, read);
    let grid = read();
    let y = grid.y_mm.clone();
    let options = FitOptions::default();
    let (fit_s, fit_cpu) = timed(runs, || {
        fit_grid(PITCH_X_MM, &y, &grid.heights_um, grid.cols, options).expect("fit")
    });
    let fit = fit_grid(PITCH_X_MM, &y, &grid.heights_um, grid.cols, options).expect("fit");
    let (_, format_cpu) = timed(runs, || {
        let mut text = Vec::with_capacity(16 << 20);
        surfscan::iges::writer::format_net_reals(&fit.surface, &mut text).expect("format")
    });
    // Every 2nd line held out, as `fit` does for this grid (fewer lines hold out fewer).
    let every = surfscan::metrology::holdout::holdout_every(grid.rows(), options.degree_v)
        .expect("enough lines for the verdict");
    let (_, verdict_cpu) = timed(runs, || {
        let g = HeightMap {
            heights_um: &grid.heights_um,
            rows: grid.rows(),
            cols: grid.cols,
            pitch_x_mm: PITCH_X_MM,
            pitch_y_mm: PITCH_Y_MM,
        };
        let sq = sq_um(&g).expect("Sq");
        between_lines(&grid, options, VMethod::Interpolate, every, sq, 0.5).expect("verdict")
    });
    let (_, copy_cpu) = timed(runs, || {
        // The bytes the disk floor wrote, copied once more through a write() into the page
        // cache of a new file (not synced): the kernel's share of the CPU.
        let bytes = vec![b' '; 21 << 20];
        let path = csv.with_extension("copy");
        let mut f = std::fs::File::create(&path).expect("create");
        for piece in bytes.chunks(1 << 20) {
            std::io::Write::write_all(&mut f, piece).expect("write");
        }
        drop(f);
        std::fs::remove_file(&path).expect("remove");
    });
    let target_s = reference_s / 1.3;
    let chain = start_s + parse_s + fit_s + disk_s;
    let cpu = start_s + parse_cpu + fit_cpu + format_cpu + verdict_cpu + copy_cpu;
    println!(
        "  floor on this machine ({cores} cores), from each part warm and alone (medians of {runs}); the target leaves {:.1} ms (reference fit / 1.3):",
        target_s * 1e3
    );
    println!(
        "    chain: start {:.1} + read {:.1} + fit {:.1} + disk {:.1} = {:.1} ms ({:.0} % of what the target leaves), before any real is formatted",
        start_s * 1e3,
        parse_s * 1e3,
        fit_s * 1e3,
        disk_s * 1e3,
        chain * 1e3,
        100.0 * chain / target_s
    );
    println!(
        "    CPU: start {:.1} + read {:.1} + fit {:.1} + exact reals {:.1} + verdict between lines {:.1} + kernel copy {:.1} = {:.1} ms; on {cores} cores at least {:.1} ms ({:.0} % of what the target leaves)",
        start_s * 1e3,
        parse_cpu * 1e3,
        fit_cpu * 1e3,
        format_cpu * 1e3,
        verdict_cpu * 1e3,
        copy_cpu * 1e3,
        cpu * 1e3,
        cpu / cores * 1e3,
        100.0 * cpu / cores / target_s
    );
}

/// The time the disk takes to make `file`'s bytes durable, as `fit` must: the bytes (already
/// in memory) written into a new file beside it through the same durable path `fit` writes
/// through (`write_atomically_streamed`: writeback started as it goes, fsync, rename, the
/// directory's fsync), in the pieces `fit`'s 1 MiB buffer hands it, then removed. Returns the
/// median wall time and the byte count.
fn disk_floor(file: &Path, runs: usize) -> (f64, usize) {
    use std::io::Write;
    let bytes = std::fs::read(file).expect("read the written IGES file");
    let copy = file.with_extension("disk-floor");
    let times: Vec<f64> = (0..runs)
        .map(|_| {
            let t = Instant::now();
            surfscan::atomic::write_atomically_streamed(&copy, |w| {
                for piece in bytes.chunks(1 << 20) {
                    w.write_all(piece)?;
                }
                Ok(())
            })
            .expect("write and fsync");
            let s = t.elapsed().as_secs_f64();
            std::fs::remove_file(&copy).expect("remove");
            s
        })
        .collect();
    (median(times), bytes.len())
}

fn bench_large(dir: &Path, rows: usize, cols: usize, runs: usize, count_instructions: bool) {
    let csv = dir.join(format!("grid{rows}x{cols}.csv"));
    write_grid_csv(&csv, rows, cols);
    let out = dir.join(format!("large{rows}x{cols}.igs"));
    let grid_mb = (rows * cols * 8) as f64 / (1024.0 * 1024.0);
    let (mut wall, mut cpu, mut rss) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let r = run(&mut fit_command(&csv, &out));
        wall.push(r.wall_s);
        cpu.push(r.cpu_s);
        rss.push(r.max_rss_mb);
        for e in std::fs::read_dir(dir).expect("read bench dir").flatten() {
            if e.file_name().to_string_lossy().starts_with("large") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
    let rss = median(rss);
    println!(
        "fit {rows}x{cols} whole process (medians of {runs}): {:.2} s wall (target <= 2.5 s), {:.2} s CPU, peak RSS {rss:.0} MiB = {:.2}x the grid's {grid_mb:.0} MiB of f64 (target <= 3x)",
        median(wall),
        median(cpu),
        rss / grid_mb
    );
    print_instructions(
        "surfscan fit (large)",
        &fit_command(&csv, &out),
        count_instructions,
    );
}

/// `surfscan analyze` of a grid CSV into `out`, with the defaults (λc 0.8 mm filter).
fn analyze_command(csv: &Path, out: &Path) -> Command {
    let mut c = surfscan();
    c.arg("analyze")
        .arg(csv)
        .arg("--pitch-x")
        .arg(PITCH_X_MM.to_string())
        .arg("--pitch-y")
        .arg(PITCH_Y_MM.to_string())
        .arg("--out")
        .arg(out);
    c
}

fn bench_analyze(dir: &Path, rows: usize, cols: usize, runs: usize, count_instructions: bool) {
    let csv = dir.join(format!("grid{rows}x{cols}.csv"));
    if !csv.exists() {
        write_grid_csv(&csv, rows, cols);
    }
    let out = dir.join(format!("analyze{rows}x{cols}"));
    let command = || analyze_command(&csv, &out);
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let r = run(&mut command());
        wall.push(r.wall_s);
        cpu.push(r.cpu_s);
    }
    let report: serde_json::Value = std::fs::read_to_string(out.join("report.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    println!(
        "analyze {rows}x{cols} whole process (medians of {runs}): {:.3} s wall (target <= 0.3 s), {:.3} s CPU; stages of the last run {}",
        median(wall),
        median(cpu),
        report["timings_s"]
    );
    print_instructions("surfscan analyze", &command(), count_instructions);
}

/// The λc of `analyze`'s default filter, mm, which surfalize's per-line reference uses too.
const LAMBDA_C_MM: f64 = 0.8;

/// The core both sides of the one-core comparison are pinned to: the second when there is
/// one (the first takes more of the machine's interrupts), else the only one.
fn one_core() -> String {
    let n = std::thread::available_parallelism().map_or(1, |n| n.get());
    if n > 1 { "1" } else { "0" }.to_string()
}

/// `cmd` run by `taskset -c CORE`: the process and every thread it starts on that one core.
fn pinned(cmd: &Command) -> Command {
    let mut c = Command::new("taskset");
    c.arg("-c")
        .arg(one_core())
        .arg(cmd.get_program())
        .args(cmd.get_args());
    c
}

/// `surfscan analyze` of the grid, whole process, against surfalize's per-line roughness of
/// the same grid (`tests/python/lines_surfalize.py`: each line's Gaussian high-pass at λc and
/// Ra, Rq, Rz, Rsk, Rku; its own timing of that work alone, imports and CSV reading
/// excluded), both pinned to one core and alternating: (surfalize's time) ÷ (ours), wall and
/// CPU. Wall time on a shared machine includes waiting for the core; CPU time does not.
fn bench_analyze_one_core(dir: &Path, rows: usize, cols: usize, runs: usize) {
    let csv = dir.join(format!("grid{rows}x{cols}.csv"));
    if !csv.exists() {
        write_grid_csv(&csv, rows, cols);
    }
    let out = dir.join(format!("analyze-one-core{rows}x{cols}"));
    let mut reference = Command::new(python());
    reference
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/lines_surfalize.py"))
        .arg(&csv)
        .arg(PITCH_X_MM.to_string())
        .arg(LAMBDA_C_MM.to_string())
        .args(["--repeat", "1"]);
    let (mut wall, mut cpu, mut ref_wall, mut ref_cpu) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let r = run(&mut pinned(&analyze_command(&csv, &out)));
        wall.push(r.wall_s);
        cpu.push(r.cpu_s);
        let r = run(&mut pinned(&reference));
        let v: serde_json::Value = serde_json::from_str(&r.stdout)
            .unwrap_or_else(|e| panic!("lines_surfalize.py printed no JSON ({e}): {}", r.stdout));
        assert_eq!(v["lines"].as_u64(), Some(rows as u64), "surfalize's lines");
        ref_wall.push(v["lines_s"].as_f64().expect("lines_s"));
        ref_cpu.push(v["lines_cpu_s"].as_f64().expect("lines_cpu_s"));
    }
    let (w, c, rw, rc) = (median(wall), median(cpu), median(ref_wall), median(ref_cpu));
    println!(
        "analyze {rows}x{cols} on one core (taskset -c {}), whole process (medians of {runs}): {:.3} s wall, {:.3} s CPU | surfalize per-line λc {LAMBDA_C_MM} mm filter + Ra Rq Rz Rsk Rku alone {:.3} s wall, {:.3} s CPU | surfalize/ours {:.2}x wall, {:.2}x CPU (target >= 1.3x)",
        one_core(),
        w,
        c,
        rw,
        rc,
        rw / w,
        rc / c
    );
}

/// The largest figure file (`.png`, `.svg`) in `dir` and its `rk/`: (bytes, name).
fn largest_figure(dir: &Path) -> (u64, String) {
    let mut largest = (0, String::new());
    for d in [dir.to_path_buf(), dir.join("rk")] {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let len = e.metadata().map_or(0, |m| m.len());
            if (name.ends_with(".png") || name.ends_with(".svg")) && len > largest.0 {
                largest = (len, name);
            }
        }
    }
    largest
}

/// `surfscan analyze` of a large grid beside `surfscan fit` of the same grid: wall time
/// against the fit's, peak RSS against the grid's f64 bytes, the size of report.html and of
/// the largest figure.
fn bench_analyze_large(dir: &Path, rows: usize, cols: usize, runs: usize) {
    let csv = dir.join(format!("grid{rows}x{cols}.csv"));
    if !csv.exists() {
        write_grid_csv(&csv, rows, cols);
    }
    let out = dir.join(format!("analyze{rows}x{cols}"));
    let grid_mb = (rows * cols * 8) as f64 / (1024.0 * 1024.0);
    let (mut wall, mut cpu, mut rss, mut fit_wall) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let igs = dir.join(format!("large-analyze{rows}x{cols}.igs"));
        fit_wall.push(run(&mut fit_command(&csv, &igs)).wall_s);
        for e in std::fs::read_dir(dir).expect("read bench dir").flatten() {
            if e.file_name().to_string_lossy().starts_with("large-analyze") {
                let _ = std::fs::remove_file(e.path());
            }
        }
        let r = run(surfscan()
            .arg("analyze")
            .arg(&csv)
            .arg("--pitch-x")
            .arg(PITCH_X_MM.to_string())
            .arg("--pitch-y")
            .arg(PITCH_Y_MM.to_string())
            .arg("--out")
            .arg(&out));
        wall.push(r.wall_s);
        cpu.push(r.cpu_s);
        rss.push(r.max_rss_mb);
    }
    let (w, fw, rss) = (median(wall), median(fit_wall), median(rss));
    let html = std::fs::metadata(out.join("report.html")).map_or(0, |m| m.len());
    let (figure, figure_name) = largest_figure(&out);
    println!(
        "analyze {rows}x{cols} whole process (medians of {runs}): {w:.2} s wall = {:.2}x the fit's {fw:.2} s (target <= 2x), {:.2} s CPU, peak RSS {rss:.0} MiB = {:.2}x the grid's {grid_mb:.0} MiB of f64 (target <= 3x); report.html {:.2} MB (target <= 5 MB), largest figure {figure_name} {:.2} MB (target <= 2 MB)",
        w / fw,
        median(cpu),
        rss / grid_mb,
        html as f64 / 1e6,
        figure as f64 / 1e6
    );
    let report: serde_json::Value = std::fs::read_to_string(out.join("report.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    println!("  stages of the last run {}", report["timings_s"]);
}

/// A daemon-sized scan directory, 31 lines × `cols` points at 0.5 µm of a synthetic rough
/// profile, committed line by line through the scan store and journal as the runner does.
fn write_scan(parent: &Path, kind: ProfileKind, cols: usize) -> PathBuf {
    let start = Utc.with_ymd_and_hms(2026, 11, 30, 9, 15, 0).unwrap();
    let id = ScanId::new(start, &format!("timing {kind:?}"));
    let faults = Arc::new(NoFaults);
    let store = ScanStore::create(parent, &id, faults.clone())
        .expect("scan store")
        .0;
    let conditions = Conditions {
        standard: Some("ISO1997".into()),
        profile_kind: Some(kind),
        filter: Some(FilterKind::Gaussian),
        lambda_c_mm: Some(0.8),
        lambda_s_um: None,
        sampling_lengths: None,
        evaluation_length_mm: None,
        speed_mm_s: Some(0.5),
        raw: None,
    };
    let mut journal = Journal::create(
        store.root(),
        StartRecord {
            scan_id: id.0.clone(),
            sequence: 1,
            time: start,
            plan: surfscan::scan::plan::Plan {
                lines: 31,
                y_start_nm: Nm(0),
                y_step_nm: Nm(10_000),
                degree_u: 5,
                degree_v: 5,
                max_line_attempts: 3,
                v_method: Default::default(),
                replace_spikes: None,
                analysis: None,
            },
            config: serde_json::json!({}),
            config_hash: "0".repeat(64),
            specimen: "timing".into(),
            operator: "bench".into(),
            notes: String::new(),
            software_version: "bench".into(),
            instrument_model: "SJ-210".into(),
            firmware: "1.0".into(),
            drive_unit: "standard".into(),
            conditions: conditions.clone(),
            peer: None,
            job: None,
        },
        faults,
    )
    .expect("journal");
    for r in 0..31u32 {
        let z: Vec<f64> = (0..cols)
            .map(|i| {
                let x = i as f64 * PITCH_X_MM;
                let y = r as f64 * PITCH_Y_MM;
                let noise = ((i * 7919 + r as usize * 104_729) % 1000) as f64 / 1000.0;
                0.5 * (x * 97.0 + y * 13.0).sin()
                    + 0.2 * (x * 611.0 - y * 29.0).cos()
                    + 0.05 * noise
            })
            .collect();
        let profile = Profile {
            pitch_x_mm: PITCH_X_MM,
            heights_um: z,
            kind,
            conditions: conditions.clone(),
        };
        let meta = LineMeta {
            id: LineIdentity {
                index: r,
                y_target_nm: Nm(r as i64 * 10_000),
                y_readback_nm: None,
                attempt: 1,
                points: cols,
            },
            profile: Profile {
                pitch_x_mm: PITCH_X_MM,
                heights_um: NoHeights,
                kind,
                conditions: conditions.clone(),
            },
            results: vec![],
            readout_warnings: Vec::new(),
            started_at: start,
            finished_at: start,
        };
        store
            .commit_line(&mut journal, &meta, &profile)
            .expect("commit line");
    }
    store.root().to_path_buf()
}

/// CPU time of this process so far (all threads), s.
fn process_cpu_s() -> f64 {
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

/// The daemon's characterisation of a completed scan directory, in-process, for an R profile
/// (no λc filter) and a P profile (λc 0.8 mm per line).
fn bench_scan(dir: &Path, cols: usize, runs: usize, kinds: &[ProfileKind]) {
    for &kind in kinds {
        let scan = write_scan(dir, kind, cols);
        let (mut wall, mut cpu) = (Vec::new(), Vec::new());
        let mut stages = serde_json::Value::Null;
        for _ in 0..runs {
            let (t, c) = (Instant::now(), process_cpu_s());
            let input = surfscan::input::read(&scan, &Default::default()).expect("read scan");
            let out = characterise_scan(&input, &ScanAnalysisOptions::default())
                .expect("characterise scan");
            wall.push(t.elapsed().as_secs_f64());
            cpu.push(process_cpu_s() - c);
            assert_eq!(out.lines_used.len(), 31);
            let report: serde_json::Value = std::fs::read_to_string(&out.files.report_json)
                .ok()
                .and_then(|t| serde_json::from_str(&t).ok())
                .unwrap_or_default();
            stages = report["timings_s"].clone();
        }
        println!(
            "characterise_scan 31x{cols}, {kind:?} profile (medians of {runs}): {:.3} s wall, {:.3} s CPU; stages of the last run {stages}",
            median(wall),
            median(cpu)
        );
    }
}

fn main() {
    let full = std::env::args().any(|a| a == "--bench");
    let count_instructions = std::env::args().any(|a| a == "--instructions");
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let want = |name: &str| args.is_empty() || args.iter().any(|a| a == name);
    // Next to the build, on the disk the outputs would go to (not a RAM-backed /tmp), so the
    // fsync costs what it costs an operator.
    let base = Path::new(env!("CARGO_TARGET_TMPDIR"));
    std::fs::create_dir_all(base).expect("bench dir");
    let dir = tempfile::tempdir_in(base).expect("bench dir");
    let dir = dir.path();
    if !full {
        bench_fit(dir, 7, 60, 1, false);
        bench_large(dir, 9, 70, 1, false);
        // At least one λc (0.8 mm = 1600 points) per line.
        bench_analyze(dir, 7, 1800, 1, false);
        bench_analyze_one_core(dir, 7, 1800, 1);
        bench_analyze_large(dir, 9, 1800, 1);
        bench_scan(dir, 1800, 1, &[ProfileKind::P]);
        return;
    }
    if want("fit") {
        bench_fit(dir, 31, 8000, 15, count_instructions);
    }
    if want("large") {
        bench_large(dir, 1000, 10_000, 3, count_instructions);
    }
    if want("analyze") {
        bench_analyze(dir, 31, 8000, 7, count_instructions);
    }
    if want("analyze-1core") {
        bench_analyze_one_core(dir, 31, 8000, 7);
    }
    if want("analyze-large") {
        bench_analyze_large(dir, 1000, 10_000, 3);
    }
    if want("scan") {
        bench_scan(dir, 8000, 5, &[ProfileKind::R, ProfileKind::P]);
    }
}
