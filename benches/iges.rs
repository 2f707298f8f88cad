//! IGES benchmark: fits a synthetic 31×8000 roughness-like grid (0.5 µm x pitch, 10 µm y
//! pitch) and writes it as IGES to a temporary file without fsync; prints the best of several
//! runs for the fit, the write, and both together, plus the file size. Without `--bench` (as
//! under `cargo test --all-targets`) it runs once on a 31×500 grid as a smoke test.
//!
//! With `-- --large` (`cargo bench --bench iges -- --large`) it instead writes a 1000×10000
//! pole degree-5 surface (10⁷ poles, more than one IGES file holds) through `plan_files` as
//! several files and prints the file count, sizes and times; it needs a few GB of memory.
use std::time::Instant;
use surfscan::fit::{fit_grid, FitOptions};
use surfscan::iges::{plan_files, write_iges, IgesOptions};
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
    let groups = plan_files(&s, &opts).expect("plan");
    let plan_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let n = groups.len();
    for (k, g) in groups.iter().enumerate() {
        let path = dir.join(format!("large.part{}-of-{n}.igs", k + 1));
        let st = surfscan::atomic::write_atomically_without_sync(&path, |w| {
            write_iges(w, g, &opts).map_err(std::io::Error::other)
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

fn main() {
    if std::env::args().any(|a| a == "--large") {
        large();
        return;
    }
    let full = std::env::args().any(|a| a == "--bench");
    let (rows, cols, runs) = if full {
        (31usize, 8000usize, 7)
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
    let (mut best_fit, mut best_write, mut best_total, mut bytes) =
        (f64::MAX, f64::MAX, f64::MAX, 0);
    let mut best_format = f64::MAX;
    for _ in 0..runs {
        let t0 = Instant::now();
        let fit =
            fit_grid(pitch_x_mm, &y_mm, &heights_um, cols, FitOptions::default()).expect("fit");
        let t1 = Instant::now();
        let stats = surfscan::atomic::write_atomically_without_sync(&path, |w| {
            write_iges(w, std::slice::from_ref(&fit.surface), &opts).map_err(std::io::Error::other)
        })
        .expect("write");
        let t2 = Instant::now();
        let mut mem = Vec::with_capacity(stats.bytes as usize);
        write_iges(&mut mem, std::slice::from_ref(&fit.surface), &opts).expect("format");
        best_format = best_format.min(t2.elapsed().as_secs_f64());
        bytes = stats.bytes;
        best_fit = best_fit.min((t1 - t0).as_secs_f64());
        best_write = best_write.min((t2 - t1).as_secs_f64());
        best_total = best_total.min((t2 - t0).as_secs_f64());
    }
    let _ = std::fs::remove_dir_all(&dir);
    println!(
        "iges {rows}x{cols}: fit {:.1} ms, write {:.1} ms, fit+write {:.1} ms (target <= 100 ms), file {:.2} MB; formatting into memory alone {:.1} ms",
        best_fit * 1e3,
        best_write * 1e3,
        best_total * 1e3,
        bytes as f64 / 1e6,
        best_format * 1e3
    );
}
