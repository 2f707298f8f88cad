//! IGES benchmark: fits a synthetic 31×8000 roughness-like grid (0.5 µm x pitch, 10 µm y
//! pitch) and writes it as IGES to a temporary file without fsync; prints the medians of 11
//! runs for the fit, the write, and both together (and the best), the CPU time of fit+write
//! summed over threads (what one core would spend), plus the file size. Without `--bench` (as
//! under `cargo test --all-targets`) it runs once on a 31×500 grid as a smoke test.
//!
//! With `-- --large` (`cargo bench --bench iges -- --large`) it instead writes a 1000×10000
//! pole degree-5 surface (10⁷ poles, more than one IGES file holds) through `plan_files` as
//! several files and prints the file count, sizes and times; it needs a few GB of memory.
use std::time::Instant;
use surfscan::fit::{fit_grid, FitOptions};
use surfscan::iges::{plan_parts, write_iges, write_iges_seekable, IgesOptions};
use surfscan::nurbs::NurbsSurface;

/// 1000 rows (v) × 10000 columns (u) of poles on a 0.5 µm × 10 µm grid, degree 5 × 5.
fn large_surface() -> NurbsSurface {
    let (nu, nv, d) = (10_000usize, 1000usize, 5usize);
    let knots = |n: usize| {
        let mut k = vec![0.0; d + 1];
        k.extend((1..n - d).map(|j| j as f64 / (n - d) as f64));
        k.extend(vec![1.0; d + 1]);
        k
    };
    let mut poles = Vec::with_capacity(nu * nv);
    for j in 0..nv {
        for i in 0..nu {
            // Poles of a real fit carry 17 significant digits; so do these.
            let (x, y) = (
                i as f64 * 0.000_500_000_000_3,
                j as f64 * 0.010_000_000_000_7,
            );
            let z = 1e-3 * (0.8 * (x * 157.0).sin() + 0.3 * (x * 911.0 + y * 40.0).cos());
            poles.push([x, y, z]);
        }
    }
    NurbsSurface::try_new(d, d, knots(nu), knots(nv), nu, nv, poles).expect("surface")
}

fn large() {
    let s = large_surface();
    let dir = std::env::temp_dir().join(format!("surfscan-iges-large-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let opts = IgesOptions {
        start_lines: vec!["benchmark surface".into()],
        ..IgesOptions::default()
    };
    let t0 = Instant::now();
    let groups = plan_parts(&s, &opts).expect("plan");
    let plan_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let n = groups.len();
    for (k, g) in groups.iter().enumerate() {
        let path = dir.join(format!("large.part{}-of-{n}.igs", k + 1));
        let st = surfscan::atomic::write_atomically_without_sync(&path, |w| {
            write_iges_seekable(w, g, &opts).map_err(std::io::Error::other)
        })
        .expect("write");
        println!(
            "  part {} of {n}: {} patches, {} P lines, {:.1} MB",
            k + 1,
            st.patches,
            st.parameter_lines,
            st.bytes as f64 / 1e6
        );
    }
    let write_s = t1.elapsed().as_secs_f64();
    let _ = std::fs::remove_dir_all(&dir);
    println!(
        "iges 1000x10000 poles: {n} files, plan {:.1} s, write {:.1} s",
        plan_s, write_s
    );
}

/// CPU time of this process so far, s, summed over all threads: the time the work would
/// take on one core, and meaningful on a loaded machine where wall time is not.
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

fn main() {
    if std::env::args().any(|a| a == "--large") {
        large();
        return;
    }
    let full = std::env::args().any(|a| a == "--bench");
    let (rows, cols, runs) = if full {
        (31usize, 8000usize, 11)
    } else {
        (31, 500, 1)
    };
    let pitch_x_mm = 0.0005;
    let y_mm: Vec<f64> = (0..rows).map(|r| r as f64 * 0.01).collect();
    let mut heights_um = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            let x = c as f64 * pitch_x_mm;
            let y = r as f64 * 0.01;
            heights_um.push(0.8 * (x * 157.0).sin() + 0.3 * (x * 911.0 + y * 40.0).cos());
        }
    }
    let dir = std::env::temp_dir().join(format!("surfscan-iges-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("bench.igs");
    let opts = IgesOptions {
        start_lines: vec!["benchmark surface".into()],
        ..IgesOptions::default()
    };
    let (mut fit_s, mut write_s, mut total_s, mut cpu, mut format_s) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut bytes, mut digest) = (0, 0u64);
    for _ in 0..runs {
        let c0 = cpu_s();
        let t0 = Instant::now();
        let fit =
            fit_grid(pitch_x_mm, &y_mm, &heights_um, cols, FitOptions::default()).expect("fit");
        let t1 = Instant::now();
        let stats = surfscan::atomic::write_atomically_without_sync(&path, |w| {
            write_iges_seekable(w, std::slice::from_ref(&fit.surface), &opts)
                .map_err(std::io::Error::other)
        })
        .expect("write");
        let t2 = Instant::now();
        cpu.push(cpu_s() - c0);
        let mut mem = Vec::with_capacity(stats.bytes as usize);
        write_iges(&mut mem, std::slice::from_ref(&fit.surface), &opts).expect("format");
        format_s.push(t2.elapsed().as_secs_f64());
        if digest == 0 {
            // FNV-1a of the file's bytes: equal digests mean byte-identical output.
            digest = mem.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
                (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
            });
        }
        bytes = stats.bytes;
        fit_s.push((t1 - t0).as_secs_f64());
        write_s.push((t2 - t1).as_secs_f64());
        total_s.push((t2 - t0).as_secs_f64());
    }
    // The reals alone: every pole coordinate of the fit formatted into one buffer.
    let fit = fit_grid(pitch_x_mm, &y_mm, &heights_um, cols, FitOptions::default()).expect("fit");
    let reals: Vec<f64> = fit.surface.poles().flatten().collect();
    let mut text = Vec::with_capacity(reals.len() * 24);
    let (mut real_wall, mut real_cpu) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        text.clear();
        let (t, c) = (Instant::now(), cpu_s());
        for &v in &reals {
            surfscan::iges::format::push_real(&mut text, v);
        }
        real_wall.push(t.elapsed().as_secs_f64());
        real_cpu.push(cpu_s() - c);
    }
    // The same coordinates through the writer's formatting (one thread): a fitted net's x
    // is the same down each column and its y along each row, so their texts are reused.
    let (mut net_wall, mut net_cpu) = (Vec::new(), Vec::new());
    let mut net_text = Vec::with_capacity(reals.len() * 24);
    for _ in 0..runs {
        net_text.clear();
        let (t, c) = (Instant::now(), cpu_s());
        surfscan::iges::writer::format_net_reals(&fit.surface, &mut net_text).expect("format");
        net_wall.push(t.elapsed().as_secs_f64());
        net_cpu.push(cpu_s() - c);
    }
    assert!(
        net_text == text,
        "the writer's texts differ from push_real's"
    );
    let per = |v: Vec<f64>| median(v) / reals.len() as f64 * 1e9;
    println!(
        "iges reals as the writer formats a fitted net (x per column, y per row reused): {:.1} ns wall, {:.1} ns CPU each (median of {runs}; target <= 20 ns)",
        per(net_wall),
        per(net_cpu)
    );
    println!(
        "iges reals, each formatted alone (push_real): {} pole coordinates, {:.1} ns wall, {:.1} ns CPU each (median of {runs}), {:.1} bytes each",
        reals.len(),
        per(real_wall),
        per(real_cpu),
        text.len() as f64 / reals.len() as f64
    );
    let best = total_s.iter().copied().fold(f64::MAX, f64::min);
    let _ = std::fs::remove_dir_all(&dir);
    println!(
        "iges {rows}x{cols} (medians of {runs}): fit {:.1} ms, write {:.1} ms, fit+write {:.1} ms (best {:.1}; target <= 100 ms), CPU of fit+write (all threads) {:.1} ms, file {:.2} MB (digest {digest:016x}); formatting into memory alone {:.1} ms",
        median(fit_s) * 1e3,
        median(write_s) * 1e3,
        median(total_s) * 1e3,
        best * 1e3,
        median(cpu) * 1e3,
        bytes as f64 / 1e6,
        median(format_s) * 1e3
    );
}
