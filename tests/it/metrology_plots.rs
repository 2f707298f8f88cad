//! The plots as a metrology engineer reads them: every plot as PNG and SVG, ISO words
//! (Rmr(c), Smr(c)), a key for every colour, the scale stated, the Rk construction drawn from
//! the numbers the metrology computed, and nothing drawn off the edge of the figure.
//!
//! `SURFSCAN_PLOT_DIR=DIR` keeps the figures in DIR to look at them.

use surfscan::fit::{fit_grid, FitOptions};
use surfscan::metrology::areal::{level_plane, smr_curve, HeightMap};
use surfscan::metrology::model::{model_bearing_curves_with, ModelBacOptions};
use surfscan::metrology::params::{analyze_line, rk_family_and_curve, Options};
use surfscan::report::render::plots::{
    plot_bearing_curves, plot_height_map, plot_profile_overlay, plot_rk_construction,
    AssessedProfile, FigureFiles,
};

/// A rough, plateau-honed looking profile: sines plus a deterministic noise, with deep
/// valleys every so often (so the Rk construction has both triangles).
fn profile(row: usize, cols: usize) -> Vec<f64> {
    let mut s = 0x2545_f491_4f6c_dd1du64 ^ (row as u64).wrapping_mul(0x9e37_79b9);
    (0..cols)
        .map(|i| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let noise = (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            let x = i as f64 * 0.0015;
            let valley = if (i / 37) % 9 == 0 { -2.0 } else { 0.0 };
            0.8 * (x * 40.0 + row as f64 * 0.3).sin() + 0.3 * (x * 170.0).cos() + noise + valley
        })
        .collect()
}

struct Out {
    dir: std::path::PathBuf,
    _tmp: Option<tempfile::TempDir>,
}

fn out_dir() -> Out {
    match std::env::var_os("SURFSCAN_PLOT_DIR") {
        Some(d) => {
            let dir = std::path::PathBuf::from(d);
            std::fs::create_dir_all(&dir).unwrap();
            Out { dir, _tmp: None }
        }
        None => {
            let t = tempfile::tempdir().unwrap();
            Out {
                dir: t.path().to_path_buf(),
                _tmp: Some(t),
            }
        }
    }
}

const ROWS: usize = 31;
const COLS: usize = 1067; // 1.6 mm at 1.5 µm
const PX: f64 = 0.0015;
const PY: f64 = 0.01;

fn grid() -> Vec<f64> {
    (0..ROWS).flat_map(|r| profile(r, COLS)).collect()
}

const LONG_CAPTION: &str = "specimen demo: Mitutoyo R profile windows · SJ-210 fw 1.00 (standard drive unit) · ISO1997 Gauss λc 0.8 mm λs 2.5 µm · scan 20250101T000000Z-abcdef · surfscan 0.1.0 (0123456789ab) · operator a person with a rather long name · notes: more text than fits on one line of the figure";

/// Decodes a PNG and checks that nothing is drawn in the outer 4 px of the right edge and
/// of the bottom (text that ran off the figure would touch them) while the footer holds text.
fn assert_nothing_at_the_edge(png: &std::path::Path) {
    let img = image::open(png).unwrap().to_rgb8();
    let (w, h) = img.dimensions();
    let ink = |x: u32, y: u32| {
        let p = img.get_pixel(x, y);
        p.0.iter().any(|&c| c < 200)
    };
    for y in 0..h {
        for x in w - 4..w {
            assert!(
                !ink(x, y),
                "{}: ink at the right edge ({x}, {y})",
                png.display()
            );
        }
    }
    for y in h - 3..h {
        for x in 0..w {
            assert!(
                !ink(x, y),
                "{}: ink at the bottom edge ({x}, {y})",
                png.display()
            );
        }
    }
    let footer_ink = (h - 40..h).any(|y| (0..w).any(|x| ink(x, y)));
    assert!(footer_ink, "{}: no footer text", png.display());
}

#[test]
fn every_plot_is_png_and_svg_in_iso_words_with_a_key_for_every_colour() {
    let out = out_dir();
    let z = grid();
    let y: Vec<f64> = (0..ROWS).map(|r| r as f64 * PY).collect();
    let fit = fit_grid(PX, &y, &z, COLS, FitOptions::default()).unwrap();
    let curves =
        model_bearing_curves_with(&fit.surface, &ModelBacOptions::default(), None).unwrap();
    let g = HeightMap {
        heights_um: &z,
        rows: ROWS,
        cols: COLS,
        pitch_x_mm: PX,
        pitch_y_mm: PY,
    };
    let pooled = smr_curve(&level_plane(&g).unwrap().0, g.cols, 101).unwrap();

    let [png, svg] = plot_bearing_curves(
        &out.dir,
        &curves,
        &pooled,
        "Material ratio curves",
        LONG_CAPTION,
    )
    .unwrap();
    assert_eq!(&std::fs::read(&png).unwrap()[..8], b"\x89PNG\r\n\x1a\n");
    assert_nothing_at_the_edge(&png);
    let text = std::fs::read_to_string(&svg).unwrap();
    for word in ["Rmr(c)", "Smr(c)", "curve y (mm)", "material ratio (%)"] {
        assert!(text.contains(word), "bac.svg lacks {word:?}");
    }
    assert!(!text.contains("MAR"), "bac.svg uses the non-ISO word MAR");
    assert!(text.contains(r#"font-family="sans-serif""#));
    // One polyline per model curve plus the pooled one (the legend samples are paths too).
    assert!(text.matches("<polyline").count() > curves.len());

    let [png, svg] =
        plot_height_map(&out.dir, &g, (0.0, 0.0), "Measured heights", LONG_CAPTION).unwrap();
    assert_nothing_at_the_edge(&png);
    let text = std::fs::read_to_string(&svg).unwrap();
    // 1.6 × 0.31 mm: too thin at true scale, so the stretch is stated; the colour bar is
    // labelled.
    assert!(
        text.contains("y stretched ×2 against x"),
        "{}",
        svg.display()
    );
    assert!(text.contains("height (µm)"));

    let measured: Vec<(f64, f64)> = z[..COLS]
        .iter()
        .enumerate()
        .map(|(i, v)| (i as f64 * PX, *v))
        .collect();
    let [png, svg] =
        plot_profile_overlay(&out.dir, &measured, &measured, &[], "Line 1", LONG_CAPTION).unwrap();
    assert_nothing_at_the_edge(&png);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("heights exaggerated ×"), "{}", svg.display());
    assert!(text.contains("NURBS model") && text.contains("measured"));
    assert!(!text.contains("model − measured"));
    // With a residual: its panel, labelled, below the profile.
    let residual: Vec<(f64, f64)> = measured.iter().map(|&(x, z)| (x, 0.1 * z)).collect();
    let [png, svg] = plot_profile_overlay(
        &out.dir,
        &measured,
        &measured,
        &residual,
        "Line 1 left out",
        LONG_CAPTION,
    )
    .unwrap();
    assert_nothing_at_the_edge(&png);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("model − data (µm)"), "{}", svg.display());
    assert!(text.contains("lower panel: model − measured"));

    let a = analyze_line(&z[..COLS], PX, &Options::default()).unwrap();
    let (rk, curve) = rk_family_and_curve(&a.roughness_um, 1001).unwrap();
    let assessed = AssessedProfile {
        z_um: &a.roughness_um,
        pitch_mm: PX,
        x0_mm: 0.0,
        sampling_length_mm: a.recipe.section_length_mm,
        sampling_lengths: a.recipe.sampling_lengths,
        kind: "R",
    };
    let [png, svg] = plot_rk_construction(
        FigureFiles {
            dir: &out.dir,
            stem: "rk-0000",
            png: true,
        },
        &curve,
        &rk,
        Some(&assessed),
        "Line 1 (y = 0.0000 mm): assessed profile and ISO 13565-2 Rk construction",
        LONG_CAPTION,
    )
    .unwrap();
    assert!(png.ends_with("rk-0000.png"));
    assert_nothing_at_the_edge(&png);
    let text = std::fs::read_to_string(&svg).unwrap();
    // The assessed profile above it, its sampling lengths numbered.
    let n = a.recipe.sampling_lengths;
    assert!(n >= 2, "the test needs several sampling lengths");
    assert!(
        text.contains(&format!("Assessed R profile: {n} sampling lengths of")),
        "{}",
        svg.display()
    );
    for k in 1..=n {
        assert!(text.contains(&format!("\nlr{k}\n")), "lr{k} not marked");
    }
    assert!(!text.contains(&format!("\nlr{}\n", n + 1)));
    for word in [
        "equivalent straight line",
        "40 % secant of least gradient",
        "Rpk triangle (area A1)",
        "Rvk triangle (area A2)",
        "Mr1",
        "Mr2",
        "\nµm·%\n",
    ] {
        assert!(text.contains(word), "rk svg lacks {word:?}");
    }
    // The values in the panel are the metrology's, written with 4 significant digits.
    let rk_text = surfscan::numfmt::fmt(rk.rk_um, surfscan::numfmt::Quantity::HeightUm);
    assert!(
        text.contains(&format!("\n{rk_text}\n")),
        "Rk {rk_text} missing"
    );
}

#[test]
fn rk_construction_is_consistent_with_the_parameters() {
    // The levels the plot draws are the ones Rk, Mr1 and Mr2 come from: C − D = Rk, and the
    // curve crosses C at Mr1 and D at Mr2.
    let z = profile(3, COLS);
    let a = analyze_line(&z, PX, &Options::default()).unwrap();
    let (rk, curve) = rk_family_and_curve(&a.roughness_um, 100_001).unwrap();
    assert!((rk.upper_level_um - rk.lower_level_um - rk.rk_um).abs() < 1e-12);
    assert!((rk.rk_um - a.params.material.rk.rk_um).abs() < 1e-12);
    let height_at = |mr: f64| {
        let k = (mr / 100.0 * 100_000.0).round() as usize;
        curve[k][1]
    };
    assert!((height_at(rk.mr1_pct) - rk.upper_level_um).abs() < 1e-2 * rk.rk_um);
    assert!((height_at(rk.mr2_pct) - rk.lower_level_um).abs() < 1e-2 * rk.rk_um);
    // The secant lies on the equivalent line, 40 % long, inside 0 … 100 %.
    assert!(rk.secant_start_pct >= 0.0 && rk.secant_start_pct <= 60.0);
    let line = |mr: f64| rk.upper_level_um + (rk.lower_level_um - rk.upper_level_um) * mr / 100.0;
    let s = rk.secant_start_pct;
    assert!((height_at(s) - line(s)).abs() < 1e-2 * rk.rk_um);
    assert!((height_at(s + 40.0) - line(s + 40.0)).abs() < 1e-2 * rk.rk_um);
    // The curve runs from the highest to the lowest ordinate.
    let max = a.roughness_um.iter().copied().fold(f64::MIN, f64::max);
    let min = a.roughness_um.iter().copied().fold(f64::MAX, f64::min);
    assert_eq!(curve[0], [0.0, max]);
    assert_eq!(curve[100_000], [100.0, min]);
}

/// A grid and a profile far denser than their figures: the files' size follows the figure,
/// not the data. The height map is one embedded bitmap (its title says each pixel is a mean),
/// the overlay keeps at most four points a pixel column, the spike among them.
#[test]
fn dense_data_is_drawn_at_the_figures_resolution() {
    let out = out_dir();
    let (rows, cols) = (400, 6000);
    let z: Vec<f64> = (0..rows).flat_map(|r| profile(r, cols)).collect();
    let g = HeightMap {
        heights_um: &z,
        rows,
        cols,
        pitch_x_mm: 0.0005,
        pitch_y_mm: 0.01,
    };
    let [png, svg] =
        plot_height_map(&out.dir, &g, (0.0, 0.0), "Measured heights", LONG_CAPTION).unwrap();
    assert_nothing_at_the_edge(&png);
    let text = std::fs::read_to_string(&svg).unwrap();
    // At most 776 × 520 RGB pixels, as PNG in base64: under 2 MB even incompressible; the
    // grid's 2.4 M points as rectangles took about 100 bytes each.
    assert!(
        text.len() < 2_000_000,
        "heightmap.svg of {} bytes",
        text.len()
    );
    assert_eq!(text.matches("<image").count(), 1);
    assert!(text.contains(r#"href="data:image/png;base64,iVBORw0KGgo"#));
    // The colour bar's steps only, not a rectangle per point (or per bin) of the map.
    let rects = text.matches("<rect").count();
    assert!(rects < 1000, "{rects} rectangles");
    assert!(text.contains("each pixel the mean of the points under it"));

    let spike_at = 7777;
    let measured: Vec<(f64, f64)> = (0..10_000)
        .map(|i| {
            let z = if i == spike_at { 25.0 } else { z[i % cols] };
            (i as f64 * 0.0005, z)
        })
        .collect();
    let [png, svg] =
        plot_profile_overlay(&out.dir, &measured, &measured, &measured, "Line 1", "").unwrap();
    assert_nothing_at_the_edge(&png);
    let text = std::fs::read_to_string(&svg).unwrap();
    let dots = text.matches("<circle").count();
    // The legend's dot besides the data's; the plot is under 1000 px wide.
    assert!((1000..=4001).contains(&dots), "{dots} dots");
    assert!(text.contains("first, last, lowest and highest"));
    assert!(
        text.len() < 2_000_000,
        "overlay.svg of {} bytes",
        text.len()
    );
    // The spike is drawn: the highest dot is far above the others.
    let cy: Vec<f64> = text
        .split("<circle")
        .skip(1)
        // The data's dots (radius 2), not the legend's.
        .filter(|c| c.split('>').next().is_some_and(|a| a.contains("r=\"2\"")))
        .filter_map(|c| {
            let at = c.find("cy=\"")? + 4;
            c[at..].split('"').next()?.parse().ok()
        })
        .collect();
    let top = cy.iter().copied().fold(f64::INFINITY, f64::min);
    let next = cy
        .iter()
        .copied()
        .filter(|&y| y > top)
        .fold(f64::INFINITY, f64::min);
    assert!(next - top > 50.0, "no spike drawn: top {top}, next {next}");
}
