//! The figures beside the areal parameters, checked against what they must show: on a grid
//! whose texture is known (a cosine of wavelength 50 µm along x, the same on every line), the
//! ACF figure's Sal marker stands at the Sal of report.json, which is where the cosine's
//! autocorrelation cos(2πτ/λ) falls to s = 0.2, and the PSD along x peaks at q = 2π/λ; the 3D
//! view puts a grid's highest and lowest heights where the stated axonometric projection
//! puts them, in the colours of the top and bottom of its colour bar. Positions in the SVG
//! files are read through their own tick labels, so the checks hold whatever the layout.

use serde_json::Value;
use std::path::Path;
use std::process::Command;
use surfscan::metrology::areal::HeightMap;
use surfscan::report::render::areal_plots::{plot_surface_view, AZIMUTH_DEG, ELEVATION_DEG};
use surfscan::report::render::plots::viridis;

/// Wavelength of the test texture along x, µm.
const WAVELENGTH_UM: f64 = 50.0;

/// `<polyline ... stroke="COLOUR" ... points="..."/>` point lists of `svg`.
fn polylines(svg: &str, colour: &str) -> Vec<Vec<(f64, f64)>> {
    svg.split("<polyline")
        .skip(1)
        .filter(|p| p.contains(&format!("stroke=\"{colour}\"")))
        .filter_map(|p| {
            let pts = p.split("points=\"").nth(1)?.split('"').next()?;
            Some(
                pts.split_whitespace()
                    .filter_map(|xy| {
                        let (x, y) = xy.split_once(',')?;
                        Some((x.parse().ok()?, y.parse().ok()?))
                    })
                    .collect(),
            )
        })
        .collect()
}

/// The x axis's tick labels: (value, x px) of every centred text below the plot whose
/// content is a number (`parse` reads the label).
fn x_ticks(svg: &str, parse: impl Fn(&str) -> Option<f64>) -> Vec<(f64, f64)> {
    svg.split("<text")
        .skip(1)
        .filter(|t| t.contains("text-anchor=\"middle\"") && t.contains("dy=\"0.76em\""))
        .filter(|t| !t.contains("rotate("))
        .filter_map(|t| {
            let x: f64 = t.split("x=\"").nth(1)?.split('"').next()?.parse().ok()?;
            let content = t.split('>').nth(1)?.split('<').next()?.trim();
            Some((parse(content)?, x))
        })
        .collect()
}

/// The linear map value → px through the first and last of `ticks`.
fn axis(ticks: &[(f64, f64)]) -> impl Fn(f64) -> f64 {
    assert!(ticks.len() >= 2, "too few tick labels: {ticks:?}");
    let (a, b) = (ticks[0], ticks[ticks.len() - 1]);
    move |v| a.1 + (v - a.0) / (b.0 - a.0) * (b.1 - a.1)
}

#[test]
fn the_acf_marks_sal_where_the_texture_decays_and_the_psd_peaks_at_its_wavelength() {
    let dir = tempfile::tempdir().unwrap();
    // 20 lines 10 µm apart, 500 points 1 µm apart: ten whole periods along x.
    let (rows, cols, pitch_x_um) = (20usize, 500usize, 1.0);
    let csv: String = (0..rows)
        .map(|_| {
            (0..cols)
                .map(|i| {
                    let x = i as f64 * pitch_x_um;
                    format!(
                        "{:.6}",
                        (2.0 * std::f64::consts::PI * x / WAVELENGTH_UM).cos()
                    )
                })
                .collect::<Vec<_>>()
                .join(",")
                + "\n"
        })
        .collect();
    let grid = dir.path().join("cosine.csv");
    std::fs::write(&grid, csv).unwrap();
    let out = dir.path().join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["analyze", grid.to_str().unwrap(), "--pitch-x", "0.001"])
        .args(["--pitch-y", "0.01", "--lc", "0.25", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        o.status.code() != Some(2) && out.join("report.json").exists(),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let report: Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let sal = report["surface_grid"]["spatial"]["Sal_um"]
        .as_f64()
        .unwrap();
    // cos(2πτ/λ) = 0.2 at τ = λ·acos(0.2)/2π: 10.9 µm. The estimator over the overlap of a
    // finite field adds a term of order λ/(2π·L) = 1.6 % (half the mean of cos(2k·x + kτ)
    // over the overlapping x), so within 2 %.
    let expected = WAVELENGTH_UM * 0.2f64.acos() / (2.0 * std::f64::consts::PI);
    assert!(
        (sal - expected).abs() < 0.02 * expected,
        "Sal {sal} µm, the cosine's decay {expected} µm"
    );
    assert_eq!(
        report["surface_grid"]["spatial"]["fastest_decay_direction_deg"],
        0.0
    );

    // The ACF figure: the blue vertical marker stands at Sal on the lag axis.
    let acf = std::fs::read_to_string(out.join("acf.svg")).unwrap();
    let lag_px = axis(&x_ticks(&acf, |s| s.parse().ok()));
    let markers: Vec<f64> = polylines(&acf, "#0072B2")
        .into_iter()
        .filter(|p| p.len() == 2 && p[0].0 == p[1].0 && p[0].1 != p[1].1)
        .map(|p| p[0].0)
        .collect();
    assert_eq!(markers.len(), 1, "one Sal marker: {markers:?}");
    assert!(
        (markers[0] - lag_px(sal)).abs() <= 1.0,
        "the Sal marker is at x = {} px, Sal {sal} µm is at {} px",
        markers[0],
        lag_px(sal)
    );
    assert!(acf.contains(&format!(
        "Sal {}",
        surfscan::numfmt::fmt(sal, surfscan::numfmt::Quantity::HeightUm)
    )));

    // The PSD figure: the x curve's highest point is at q = 2π/λ (logarithmic axis).
    let psd = std::fs::read_to_string(out.join("psd.svg")).unwrap();
    let log_px = axis(
        &x_ticks(&psd, |s| s.parse::<f64>().ok().filter(|v| *v > 0.0))
            .into_iter()
            .map(|(v, x)| (v.log10(), x))
            .collect::<Vec<_>>(),
    );
    let curve = polylines(&psd, "#0072B2")
        .into_iter()
        .max_by_key(|p| p.len())
        .unwrap();
    let peak = curve.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    let q = 2.0 * std::f64::consts::PI / WAVELENGTH_UM;
    assert!(
        (peak.0 - log_px(q.log10())).abs() <= 2.0,
        "the PSD along x peaks at x = {} px, q = 2π/λ = {q} 1/µm is at {} px",
        peak.0,
        log_px(q.log10())
    );
    // Display resolution: every figure well within the 2 MB a plot may take.
    for name in ["acf", "psd", "surface3d"] {
        for ext in ["png", "svg"] {
            let size = std::fs::metadata(out.join(format!("{name}.{ext}")))
                .unwrap()
                .len();
            assert!(size < 2_000_000, "{name}.{ext} is {size} bytes");
        }
    }
}

/// The pixel of `png` at (x, y), RGB.
fn pixel(png: &Path, (x, y): (f64, f64)) -> [u8; 3] {
    let img = image::open(png).unwrap().to_rgb8();
    img.get_pixel(x.floor() as u32, y.floor() as u32).0
}

#[test]
fn the_3d_view_puts_the_highest_and_lowest_heights_where_its_projection_says() {
    // 40 lines × 60 points 10 µm apart, level at 0 but for a plateau at +9 µm at the back
    // right and a shallow wide pit at −1 µm at the front left (the nearest corner is x 0,
    // y 0), so both are seen from the stated viewpoint.
    let (rows, cols, pitch) = (40usize, 60usize, 0.01);
    let mut z = vec![0.0; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            if (28..=36).contains(&r) && (44..=55).contains(&c) {
                z[r * cols + c] = 9.0;
            }
            if (2..=17).contains(&r) && (3..=20).contains(&c) {
                z[r * cols + c] = -1.0;
            }
        }
    }
    let grid = HeightMap {
        heights_um: &z,
        rows,
        cols,
        pitch_x_mm: pitch,
        pitch_y_mm: pitch,
    };
    let dir = tempfile::tempdir().unwrap();
    let ([png, svg], view) =
        plot_surface_view(dir.path(), &grid, (0.0, 0.0), "Test surface", "caption").unwrap();
    assert!(svg.exists());
    // One node per point: nothing averaged.
    assert_eq!((view.nx, view.ny), (cols, rows));
    let close = |a: [u8; 3], b: [u8; 3]| a.iter().zip(b).all(|(x, y)| x.abs_diff(y) <= 2);
    let colour = |t: f64| {
        let c = viridis(t);
        [c.0, c.1, c.2]
    };
    // The plateau's and the pit's centres, at their heights.
    let top = view.px(49.5 * pitch, 32.0 * pitch, 9.0);
    let bottom = view.px(11.5 * pitch, 9.5 * pitch, -1.0);
    assert!(
        close(pixel(&png, top), colour(1.0)),
        "the highest heights at {top:?} are {:?}, not the top of the colour bar",
        pixel(&png, top)
    );
    assert!(
        close(pixel(&png, bottom), colour(0.0)),
        "the lowest heights at {bottom:?} are {:?}, not the bottom of the colour bar",
        pixel(&png, bottom)
    );
    // The projection is the stated one: along x the base rises to the right by
    // tan(azimuth)·sin(elevation) (screen y grows downwards), along y it rises to the left
    // by sin(elevation)/tan(azimuth); heights go straight up.
    let (a, e) = (AZIMUTH_DEG.to_radians(), ELEVATION_DEG.to_radians());
    let o = view.px(0.0, 0.0, -1.0);
    let x_end = view.px(0.59, 0.0, -1.0);
    let y_end = view.px(0.0, 0.39, -1.0);
    let up = view.px(0.0, 0.0, 9.0);
    assert!(
        ((o.1 - x_end.1) / (x_end.0 - o.0) - a.tan() * e.sin()).abs() < 1e-9,
        "{o:?} → {x_end:?}"
    );
    assert!(
        ((o.1 - y_end.1) / (o.0 - y_end.0) - e.sin() / a.tan()).abs() < 1e-9,
        "{o:?} → {y_end:?}"
    );
    assert!((up.0 - o.0).abs() < 1e-9 && up.1 < o.1);
    // The plateau stands up and to the right of the pit, as seen from the front left.
    assert!(top.0 > bottom.0 && top.1 < bottom.1);
}
