//! How far the model can be trusted: spikes named, folds and overshoot found, the between-line
//! hold-out verdict on a surface the lines do resolve (a smooth sine) and on one they do not
//! (uncorrelated lines), the least-squares alternative across lines, and the default fit kept
//! bit for bit the paper's.

use surfscan::config::FitSettings;
use surfscan::fit::{fit_grid, fit_grid_with, FitOptions, VMethod};
use surfscan::grid::Grid;
use surfscan::metrology::areal::{areal_params, HeightMap};
use surfscan::metrology::folds::{check_model, net_folds, FoldOptions};
use surfscan::metrology::holdout::{between_lines, SUPPORTED_BELOW_SQ};
use surfscan::metrology::outliers::{find_spikes, spike_roughness, SpikeOptions};

pub(crate) const ROWS: usize = 31;
pub(crate) const COLS: usize = 400;
pub(crate) const PX: f64 = 0.0015;
pub(crate) const PY: f64 = 0.01;

/// A small deterministic generator (splitmix64) for reproducible random grids.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Approximately Gaussian (sum of 4 uniforms), unit variance.
    fn gauss(&mut self) -> f64 {
        ((0..4).map(|_| self.next()).sum::<f64>() - 2.0) * 3.0f64.sqrt()
    }
}

fn y_mm(rows: usize) -> Vec<f64> {
    (0..rows).map(|r| r as f64 * PY).collect()
}

/// Smooth along x and y: the lines, 10 µm apart, sample a 0.25 mm wavelength in y densely
/// (25 lines per period); `cols` points a line.
pub(crate) fn sine_grid(cols: usize) -> Vec<f64> {
    (0..ROWS * cols)
        .map(|k| {
            let (x, y) = ((k % cols) as f64 * PX, (k / cols) as f64 * PY);
            3.0 * (x / 0.08 * std::f64::consts::TAU).sin()
                * (y / 0.25 * std::f64::consts::TAU).cos()
        })
        .collect()
}

/// Each line a rough profile of its own (smooth along x, correlation length a few µm),
/// independent of its neighbours; `cols` points a line.
pub(crate) fn uncorrelated_grid(seed: u64, cols: usize) -> Vec<f64> {
    let mut rng = Rng(seed);
    let mut z = Vec::with_capacity(ROWS * cols);
    for _ in 0..ROWS {
        let noise: Vec<f64> = (0..cols + 8).map(|_| rng.gauss()).collect();
        // A 9-point moving average: correlated along the line, not across.
        z.extend((0..cols).map(|i| noise[i..i + 9].iter().sum::<f64>() / 3.0));
    }
    z
}

fn sq(z: &[f64], rows: usize, cols: usize) -> f64 {
    areal_params(&HeightMap {
        heights_um: z,
        rows,
        cols,
        pitch_x_mm: PX,
        pitch_y_mm: PY,
    })
    .unwrap()
    .sq_um
}

fn verdict(z: &[f64], method: VMethod) -> surfscan::metrology::holdout::BetweenLines {
    between_lines(
        &Grid::new(z.to_vec(), COLS, PX, y_mm(ROWS)),
        FitOptions::default(),
        method,
        2,
        sq(z, ROWS, COLS),
        SUPPORTED_BELOW_SQ,
    )
    .unwrap()
}

#[test]
fn a_smooth_sine_grid_is_supported_between_lines() {
    let z = sine_grid(COLS);
    // The interpolant predicts the sine between lines to a tiny fraction of its height; the
    // least-squares refit (12 control rows scaled to the 16 lines kept: 6) less closely.
    for (method, within) in [
        (VMethod::Interpolate, 0.01),
        (VMethod::LeastSquares { control_rows: 12 }, 0.1),
    ] {
        let b = verdict(&z, method);
        assert!(b.supported, "{}", b.verdict);
        assert!(b.rms_over_sq < within, "{}", b.verdict);
        assert_eq!(b.lines.len(), 15);
        assert!(
            b.short()
                .starts_with("the model between lines is supported by the data (hold-out rms"),
            "{}",
            b.short()
        );
    }
    let fit = fit_grid(PX, &y_mm(ROWS), &z, COLS, FitOptions::default()).unwrap();
    let c = check_model(&fit.surface, &fit.params_v, &z, &FoldOptions::default());
    assert!(c.warnings().is_empty(), "{:?}", c.warnings());
}

#[test]
fn uncorrelated_lines_are_not_supported_and_the_interpolant_overshoots() {
    let z = uncorrelated_grid(7, COLS);
    let b = verdict(&z, VMethod::Interpolate);
    assert!(!b.supported, "{}", b.verdict);
    // Worse than a flat plane (which would score about 1): the interpolant swings.
    assert!(b.rms_over_sq > 1.0, "{}", b.verdict);
    assert!(
        b.short()
            .contains("not supported by the data (hold-out rms"),
        "{}",
        b.short()
    );
    // The least-squares surface across lines is still not supported, but closer to a plane.
    let ls = verdict(&z, VMethod::LeastSquares { control_rows: 8 });
    assert!(
        !ls.supported && ls.rms_um < b.rms_um,
        "{} / {}",
        ls.verdict,
        b.verdict
    );
    let fit = fit_grid(PX, &y_mm(ROWS), &z, COLS, FitOptions::default()).unwrap();
    let c = check_model(&fit.surface, &fit.params_v, &z, &FoldOptions::default());
    assert!(c.height_range.overshoot_pct > 10.0, "{:?}", c.height_range);
    assert!(
        c.warnings()
            .iter()
            .any(|w| w.starts_with("model overshoot")),
        "{:?}",
        c.warnings()
    );
}

#[test]
fn a_100_um_spike_is_named_and_the_default_surface_folds_with_a_named_warning() {
    let mut z = uncorrelated_grid(11, COLS);
    let (line, at) = (12usize, 233usize);
    z[line * COLS + at] += 100.0;
    let mut found = Vec::new();
    for r in 0..ROWS {
        let row = &z[r * COLS..(r + 1) * COLS];
        let rough = spike_roughness(row, PX, None).unwrap();
        let s = find_spikes(&rough, row, PX, &SpikeOptions::default()).unwrap();
        found.extend(s.spikes.into_iter().map(|sp| (r, sp)));
    }
    assert_eq!(found.len(), 1, "{found:?}");
    let (r, sp) = &found[0];
    assert_eq!((*r, sp.peak), (line, at));
    assert!((sp.x_mm - at as f64 * PX).abs() < 1e-12);
    assert_eq!(sp.height_um, z[line * COLS + at]);

    let fit = fit_grid(PX, &y_mm(ROWS), &z, COLS, FitOptions::default()).unwrap();
    let c = check_model(&fit.surface, &fit.params_v, &z, &FoldOptions::default());
    let w = c.warnings();
    // The spike takes a large share of u: the default surface folds, and says where.
    assert!(c.folds(), "{c:?}");
    let fold = w
        .iter()
        .find(|w| w.starts_with("model fold"))
        .expect("fold warning");
    let x = at as f64 * PX;
    let f = &c.iso_curves[0];
    assert!(
        f.range_mm[0] <= x + PX && f.range_mm[1] >= x - PX,
        "fold at {:?}, spike at x = {x}",
        f.range_mm
    );
    assert!(fold.contains("x runs backwards along u"), "{fold}");
    assert!(w.iter().any(|w| w.starts_with("control net fold")), "{w:?}");
}

/// `fit` samples the surface for folds only when its control net runs backwards somewhere:
/// on smooth grids and on grids with spikes of every size up to 150 µm, a net that runs
/// forwards everywhere never comes with a folding surface, and every folding surface has a
/// net that runs back.
#[test]
fn a_surface_folds_only_where_its_control_net_runs_back() {
    let mut rng = Rng(77);
    let (mut clean, mut folding) = (0, 0);
    for case in 0..16u64 {
        let mut z = uncorrelated_grid(100 + case, COLS);
        for _ in 0..(case % 4) {
            let at = (rng.next() * (ROWS * COLS) as f64) as usize;
            z[at] += rng.next() * 150.0;
        }
        let fit = fit_grid(PX, &y_mm(ROWS), &z, COLS, FitOptions::default()).unwrap();
        let net = net_folds(&fit.surface);
        let c = check_model(&fit.surface, &fit.params_v, &z, &FoldOptions::default());
        assert_eq!(net, c.net, "case {case}: the same net findings");
        if net.is_empty() {
            assert!(!c.folds(), "case {case}: {c:?}");
            clean += 1;
        }
        if c.folds() {
            assert!(!net.is_empty(), "case {case}");
            folding += 1;
        }
    }
    assert!(clean > 0 && folding > 0, "{clean} clean, {folding} folding");
}

#[test]
fn the_default_fit_is_the_papers_bit_for_bit() {
    // Property: for random grids (sizes, heights, spikes, unequal line spacing), the fit the
    // default [fit] settings choose is bit-identical to the paper's interpolation.
    let settings = FitSettings::default();
    let mut rng = Rng(2024);
    for case in 0..24 {
        let rows = 6 + (rng.next() * 20.0) as usize;
        let cols = 6 + (rng.next() * 200.0) as usize;
        let px = 0.0005 + rng.next() * 0.002;
        let mut y = 0.0;
        let ys: Vec<f64> = (0..rows)
            .map(|_| {
                y += 0.005 + rng.next() * 0.01;
                y
            })
            .collect();
        let scale = 0.01 + rng.next() * 20.0;
        let mut z: Vec<f64> = (0..rows * cols).map(|_| rng.gauss() * scale).collect();
        if case % 3 == 0 {
            let k = (rng.next() * (rows * cols) as f64) as usize;
            z[k] += 100.0;
        }
        let method = settings.v_method_for(rows);
        assert_eq!(method, VMethod::Interpolate);
        let options = FitOptions::degrees(settings.degree_u, settings.degree_v);
        let paper = fit_grid(px, &ys, &z, cols, FitOptions::default()).unwrap();
        let ours = fit_grid_with(px, &ys, &z, cols, options, method).unwrap();
        let bits = |s: &surfscan::nurbs::NurbsSurface| -> Vec<u64> {
            s.knots_u()
                .iter()
                .chain(s.knots_v())
                .copied()
                .chain(s.poles().flatten())
                .map(f64::to_bits)
                .collect()
        };
        assert_eq!(
            bits(&paper.surface),
            bits(&ours.surface),
            "case {case}: {rows}x{cols}"
        );
        assert_eq!(paper.params_u, ours.params_u);
        assert_eq!(paper.params_v, ours.params_v);
    }
}

/// The folding surface above through the binaries: `fit` names the fold as `analyze` does
/// (the same words), in its report and in the IGES Start section, writes the surface anyway
/// (the paper's bits) and exits 3, as `analyze` does.
#[test]
fn fit_names_a_folding_surface_as_analyze_does_and_exits_3_with_the_surface_written() {
    let dir = tempfile::tempdir().unwrap();
    let mut z = uncorrelated_grid(11, COLS);
    z[12 * COLS + 233] += 100.0;
    let csv: String = z
        .chunks(COLS)
        .map(|r| {
            r.iter()
                .map(|v| format!("{v:.6}"))
                .collect::<Vec<_>>()
                .join(",")
                + "\n"
        })
        .collect();
    let input = dir.path().join("spike.csv");
    std::fs::write(&input, csv).unwrap();
    let pitches = ["--pitch-x", &PX.to_string(), "--pitch-y", &PY.to_string()].map(str::to_owned);
    let run = |args: &[&str]| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(args)
            .arg(&input)
            .args(&pitches)
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (igs, report) = (dir.path().join("s.igs"), dir.path().join("fit.json"));
    let (code, fit_err) = run(&[
        "fit",
        "-o",
        igs.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(3), "{fit_err}");
    let fold: Vec<&str> = fit_err
        .lines()
        .filter(|l| l.starts_with("surfscan: warning: model fold: x runs backwards along u"))
        .collect();
    assert_eq!(fold.len(), 1, "{fit_err}");
    assert!(fit_err.contains("the surface folds"), "{fit_err}");
    // The report says where and by how much.
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(rep["height_map"]["folds"], true, "{}", rep["height_map"]);
    let f = &rep["height_map"]["model_checks"]["iso_curves"][0];
    let (x, lo, hi) = (
        233.0 * PX,
        f["range_mm"][0].as_f64().unwrap(),
        f["range_mm"][1].as_f64().unwrap(),
    );
    assert!(
        lo <= x + PX && hi >= x - PX,
        "fold at {lo} .. {hi}, spike at {x}"
    );
    assert!(f["back_mm"].as_f64().unwrap() > 0.0);
    // The surface is written, and its Start section says it folds.
    let text = std::fs::read_to_string(&igs).unwrap();
    let start: String = text
        .lines()
        .filter(|l| l.get(72..73) == Some("S"))
        .map(|l| l[..72].trim_end())
        .collect::<Vec<_>>()
        .join(" ");
    assert!(
        start.contains("NOT A HEIGHT MAP: the surface folds, x runs backwards along u"),
        "{start}"
    );
    let iges = surfscan::iges::reader::read_iges(text.as_bytes()).unwrap();
    assert_eq!(
        (iges.surfaces[0].count_u(), iges.surfaces[0].count_v()),
        (COLS, ROWS)
    );
    // analyze of the same file: the same fold in the same words, exit 3.
    let out = dir.path().join("analysis");
    let (code, analyze_err) = run(&["analyze", "--lc", "0.08", "--out", out.to_str().unwrap()]);
    assert_eq!(code, Some(3), "{analyze_err}");
    assert!(analyze_err.contains(fold[0]), "{analyze_err}");
}
