//! The areal figures shown beside the areal parameters: the power spectral densities along x
//! and y (`psd.png|svg`), the autocorrelation function along its fastest and slowest decay
//! with Sal and the slowest decay length marked (`acf.png|svg`), and an axonometric 3D view
//! of the measured surface (`surface3d.png|svg`).
//!
//! The charts keep the conventions of [`super::plots`] (its frame, font, colours, colour bar
//! and tick labels are reused, not repeated) and are drawn at display resolution: a series
//! is reduced per pixel column ([`super::decimate`]), and the 3D view is one bitmap of at most
//! [`VIEW_NODES`] nodes a side (about 2 px each), each node the mean of the points under it
//! (said in its title when it averages), with vector axes over it. So their size follows the figure,
//! not the grid.
//!
//! **The 3D view** is an orthographic (axonometric) projection: the grid turned
//! [`AZIMUTH_DEG`] about the vertical, x running to the right and away, y to the left and
//! away, and seen from [`ELEVATION_DEG`] above the horizon, so the corner at the grid's first
//! point is the nearest (labelled with its x and y in the input's coordinates, as the edges'
//! ends are). Lengths along x and y are at one scale, or the shorter side stretched by a stated
//! factor when it would be thinner than a quarter of the longer; heights are exaggerated by
//! the stated factor that makes the relief at most 40 % of the longer side. Cells are filled
//! back to front in viridis of their mean height, darkened by their slope (a level cell keeps
//! its colour exactly); the colour bar is the heights'.
//!
//! A renderer: numbers in, files out. Depends on [`super::plots`], [`super::decimate`],
//! [`super::text_cache`] (through the figure macro), [`crate::metrology`] (the curves and the
//! grid), [`crate::extremes`] and [`crate::numfmt`].

use super::decimate::extremes_per_column_of_pairs;
use super::plots::{
    chart, draw_colour_bar, ensure_font, err, exaggeration_note, font, legend, line_key,
    padded_range, plot_err, png_and_svg, points_under, replace_figure, tick, viridis, write_png,
    Frame, DATA, EXAGGERATIONS, MAP_BAR_W, MODEL,
};
use super::text_cache::TextCache;
use crate::extremes::min_max;
use crate::metrology::areal::HeightMap;
use crate::metrology::spatial::{AcfSection, Psd, SpatialCurves};
use crate::metrology::MetrologyError;
use crate::numfmt::{fmt, Quantity};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Figure size of the PSD and ACF charts.
const CHART_SIZE: (u32, u32) = (900, 560);
/// Figure size of the 3D view.
const VIEW_SIZE: (u32, u32) = (1000, 680);
/// The 3D view's turn about the vertical, degrees.
pub const AZIMUTH_DEG: f64 = 30.0;
/// The 3D view's height above the horizon, degrees.
pub const ELEVATION_DEG: f64 = 35.0;
/// Nodes of the 3D view along each side at most (finer grids are averaged).
pub const VIEW_NODES: usize = 360;
/// Free space around the projected surface inside its area, px (axis labels).
const VIEW_PAD: u32 = 56;
/// Grey of the threshold line.
const GREY: RGBColor = RGBColor(120, 120, 120);

/// The label of an ACF section in the legend.
fn section_label(s: &AcfSection, which: &str) -> String {
    match s.decay_um {
        Some(l) => format!(
            "θ = {}° ({which} decay): falls to s at {} µm",
            tick(s.direction_deg),
            fmt(l, Quantity::HeightUm)
        ),
        None => format!(
            "θ = {}° (does not fall to s within the field)",
            tick(s.direction_deg)
        ),
    }
}

fn draw_acf<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    curves: &SpatialCurves,
    s: f64,
    title: &str,
    caption: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let sections: Vec<(&AcfSection, RGBColor, &str)> = [
        curves.fastest.as_ref().map(|c| (c, DATA, "fastest")),
        curves.slowest.as_ref().map(|c| (c, MODEL, "slowest")),
    ]
    .into_iter()
    .flatten()
    .collect();
    let subtitle = format!(
        "f_ACF (ISO 25178-2) of the plane-levelled heights through zero lag, along its fastest decay (Sal) and its slowest (Str = fastest / slowest); grey: s = {}",
        tick(s)
    );
    let frame = Frame::new(root.dim_in_pixel().0, title, &subtitle, caption);
    let body = frame.draw(root)?;
    let x_hi = sections
        .iter()
        .filter_map(|(c, _, _)| c.points.last().map(|p| p[0]))
        .fold(0.0, f64::max);
    let x_hi = if x_hi > 0.0 { x_hi } else { 1.0 };
    let values = sections
        .iter()
        .flat_map(|(c, _, _)| c.points.iter().map(|p| p[1]));
    let (y_lo, _) = padded_range(values.chain([s, 1.0]), (-0.2, 1.0));
    let mut chart = chart(
        &body,
        0f64..x_hi,
        y_lo..1.05,
        ("lag τ along the direction (µm)", "f_ACF"),
        &|v| tick(*v),
    )?;
    chart
        .draw_series(LineSeries::new([(0.0, s), (x_hi, s)], GREY.stroke_width(1)))
        .map_err(err)?;
    let columns = chart.plotting_area().dim_in_pixel().0;
    for (c, colour, which) in &sections {
        let line = colour.stroke_width(2);
        chart
            .draw_series(LineSeries::new(
                extremes_per_column_of_pairs(&c.points, (0.0, x_hi), columns),
                line,
            ))
            .map_err(err)?
            .label(section_label(c, which))
            .legend(line_key(line));
        // The decay length: a vertical marker from the axis up to s, named at its top.
        if let Some(l) = c.decay_um {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(l, y_lo), (l, s)],
                    line,
                )))
                .map_err(err)?;
            let name = if *which == "fastest" {
                "Sal"
            } else {
                "slowest"
            };
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{name} {} µm", fmt(l, Quantity::HeightUm)),
                    (l, s),
                    font(13).color(colour),
                )))
                .map_err(err)?;
        }
    }
    if !sections.is_empty() {
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    Ok(())
}

/// Writes `acf.png` and `acf.svg` into `dir`: the ACF sections of `curves` with the
/// threshold `s` and each decay length marked. Returns the two paths.
pub fn plot_acf(
    dir: &Path,
    curves: &SpatialCurves,
    s: f64,
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    png_and_svg!(dir, "acf", CHART_SIZE, |root| draw_acf(
        &root, curves, s, title, caption
    ))
}

/// The points of a PSD a log–log chart can show: q > 0 and C > 0.
fn positive(psd: &Psd) -> Vec<[f64; 2]> {
    psd.q_per_um
        .iter()
        .zip(&psd.c_um3)
        .filter(|(q, c)| **q > 0.0 && **c > 0.0 && q.is_finite() && c.is_finite())
        .map(|(q, c)| [*q, *c])
        .collect()
}

fn draw_psd<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    curves: &SpatialCurves,
    title: &str,
    caption: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let series = [
        (
            positive(&curves.psd_x),
            DATA,
            "along x, mean over the lines",
        ),
        (
            positive(&curves.psd_y),
            MODEL,
            "along y, mean over the columns (across the lines)",
        ),
    ];
    let subtitle = "1D power spectral density C(q) = |Δx·DFT(z)|² / L of the plane-levelled heights (periodic Hann window scaled to mean square 1), wavevector q = 2π / wavelength";
    let frame = Frame::new(root.dim_in_pixel().0, title, subtitle, caption);
    let body = frame.draw(root)?;
    // The points' range of q (k = 0) or C (k = 1), widened by the factor `f` at both ends.
    let range = |k: usize, f: f64, fallback: (f64, f64)| {
        let all = series.iter().flat_map(|(p, _, _)| p.iter().map(|p| p[k]));
        let (lo, hi) = min_max(&all.collect::<Vec<_>>());
        if lo.is_finite() && hi > lo {
            (lo / f, hi * f)
        } else {
            fallback
        }
    };
    let ((q_lo, q_hi), (c_lo, c_hi)) = (range(0, 1.2, (1e-3, 1.0)), range(1, 2.0, (1e-6, 1.0)));
    let mut chart = chart(
        &body,
        (q_lo..q_hi).log_scale(),
        (c_lo..c_hi).log_scale(),
        ("q (1/µm, logarithmic)", "C(q) (µm³, logarithmic)"),
        &|v| format!("{v:.0e}"),
    )?;
    let columns = chart.plotting_area().dim_in_pixel().0;
    for (points, colour, label) in &series {
        if points.is_empty() {
            continue;
        }
        let line = colour.stroke_width(2);
        // Reduced per pixel column of the logarithmic axis.
        let logs: Vec<[f64; 2]> = points.iter().map(|p| [p[0].ln(), p[1]]).collect();
        let kept: Vec<(f64, f64)> =
            extremes_per_column_of_pairs(&logs, (q_lo.ln(), q_hi.ln()), columns)
                .into_iter()
                .map(|(lq, c)| (lq.exp(), c))
                .collect();
        chart
            .draw_series(LineSeries::new(kept, line))
            .map_err(err)?
            .label(*label)
            .legend(line_key(line));
    }
    legend(&mut chart, SeriesLabelPosition::LowerLeft)
}

/// Writes `psd.png` and `psd.svg` into `dir`: both PSDs of `curves` on logarithmic axes.
/// Returns the two paths.
pub fn plot_psd(
    dir: &Path,
    curves: &SpatialCurves,
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    png_and_svg!(dir, "psd", CHART_SIZE, |root| draw_psd(
        &root, curves, title, caption
    ))
}

/// The grid as the 3D view draws it: nodes (block means) and how they are placed on screen.
#[derive(Debug, Clone)]
pub struct View {
    /// Node heights, µm, `ny × nx` row-major.
    pub z_um: Vec<f64>,
    /// Nodes along x and y.
    pub nx: usize,
    /// Nodes along y.
    pub ny: usize,
    /// Each node's x and y, mm (the centre of the points it averages).
    pub x_mm: Vec<f64>,
    /// See `x_mm`.
    pub y_mm: Vec<f64>,
    /// Lowest and highest height of the grid, µm (the colour bar's range).
    pub z_range_um: (f64, f64),
    /// Stretch of x and of y (one of them 1).
    pub stretch: (f64, f64),
    /// Height exaggeration against the lateral scale.
    pub exaggeration: f64,
    /// Pixels per projected mm.
    scale: f64,
    /// Projected bounding box's left and top (mm) and the pixel they land on.
    origin: (f64, f64, f64, f64),
}

impl View {
    /// The view of `grid` fitted into `area` px (width, height) with its top-left at
    /// `at` px.
    fn of(grid: &HeightMap<'_>, area: (u32, u32), at: (f64, f64)) -> View {
        let (rows, cols) = (grid.rows, grid.cols);
        let (w_mm, h_mm) = (
            (cols.max(2) - 1) as f64 * grid.pitch_x_mm,
            (rows.max(2) - 1) as f64 * grid.pitch_y_mm,
        );
        // The shorter side stretched to at least a quarter of the longer.
        let stretch_of = |short: f64, long: f64| {
            EXAGGERATIONS
                .iter()
                .copied()
                .find(|f| short * f >= 0.25 * long)
                .unwrap_or(1.0)
        };
        let stretch = if h_mm < w_mm {
            (1.0, stretch_of(h_mm, w_mm))
        } else {
            (stretch_of(w_mm, h_mm), 1.0)
        };
        let longer = (w_mm * stretch.0).max(h_mm * stretch.1);
        let z_range_um = min_max(grid.heights_um);
        let relief_mm = (z_range_um.1 - z_range_um.0) * 1e-3;
        let exaggeration = EXAGGERATIONS
            .iter()
            .rev()
            .copied()
            .find(|f| relief_mm * f <= 0.4 * longer)
            .unwrap_or(1.0);
        let nx = cols.clamp(1, VIEW_NODES);
        let ny = rows.clamp(1, VIEW_NODES);
        let xs: Vec<(usize, usize)> = (0..nx).map(|i| points_under(i, cols, nx)).collect();
        let ys: Vec<(usize, usize)> = (0..ny).map(|j| points_under(j, rows, ny)).collect();
        let mut z_um = Vec::with_capacity(nx * ny);
        for &(a, b) in &ys {
            for &(c, d) in &xs {
                let sum: f64 = (a..b)
                    .flat_map(|r| grid.heights_um[r * cols + c..r * cols + d].iter())
                    .sum();
                z_um.push(sum / ((b - a) * (d - c)) as f64);
            }
        }
        let centre = |(a, b): (usize, usize), pitch: f64| (a + b - 1) as f64 * 0.5 * pitch;
        let mut view = View {
            z_um,
            nx,
            ny,
            x_mm: xs.iter().map(|s| centre(*s, grid.pitch_x_mm)).collect(),
            y_mm: ys.iter().map(|s| centre(*s, grid.pitch_y_mm)).collect(),
            z_range_um,
            stretch,
            exaggeration,
            scale: 1.0,
            origin: (0.0, 0.0, at.0, at.1),
        };
        // Fit the box of the whole grid (base and top) into the area.
        let corners: Vec<(f64, f64)> = [0.0, w_mm]
            .into_iter()
            .flat_map(|x| [0.0, h_mm].map(|y| (x, y)))
            .flat_map(|(x, y)| [z_range_um.0, z_range_um.1].map(|z| view.project(x, y, z)))
            .collect();
        let (p_lo, p_hi) = min_max(&corners.iter().map(|c| c.0).collect::<Vec<_>>());
        let (u_lo, u_hi) = min_max(&corners.iter().map(|c| c.1).collect::<Vec<_>>());
        let span = |lo: f64, hi: f64| if hi > lo { hi - lo } else { 1.0 };
        view.scale = (area.0 as f64 / span(p_lo, p_hi)).min(area.1 as f64 / span(u_lo, u_hi));
        view.origin = (p_lo, u_hi, at.0, at.1);
        view
    }

    /// The projection of (x mm, y mm, z µm): (to the right, up), in mm of the drawing.
    fn project(&self, x_mm: f64, y_mm: f64, z_um: f64) -> (f64, f64) {
        let (a, e) = (AZIMUTH_DEG.to_radians(), ELEVATION_DEG.to_radians());
        let (u, v) = (x_mm * self.stretch.0, y_mm * self.stretch.1);
        let h = (z_um - self.z_range_um.0) * 1e-3 * self.exaggeration;
        let right = u * a.cos() - v * a.sin();
        let away = u * a.sin() + v * a.cos();
        (right, h * e.cos() + away * e.sin())
    }

    /// Where (x mm, y mm, z µm) lands in the figure, px from its top-left.
    pub fn px(&self, x_mm: f64, y_mm: f64, z_um: f64) -> (f64, f64) {
        let (right, up) = self.project(x_mm, y_mm, z_um);
        let (p0, u0, ox, oy) = self.origin;
        (ox + (right - p0) * self.scale, oy + (u0 - up) * self.scale)
    }

    /// Distance from the viewer's side of the ground, for drawing back to front.
    fn depth(&self, x_mm: f64, y_mm: f64) -> f64 {
        let a = AZIMUTH_DEG.to_radians();
        x_mm * self.stretch.0 * a.sin() + y_mm * self.stretch.1 * a.cos()
    }

    /// Whether a node stands for more than one point.
    fn averages(&self, grid: &HeightMap<'_>) -> bool {
        self.nx < grid.cols || self.ny < grid.rows
    }

    /// The surface drawn into an RGB bitmap of `size` px whose top-left is the figure's
    /// pixel `at` (white where no surface is): cells back to front, each filled in viridis
    /// of its mean height times its slope shading.
    pub fn pixels(&self, size: (u32, u32), at: (i32, i32)) -> Vec<u8> {
        let (w, h) = (size.0 as usize, size.1 as usize);
        let mut rgb = vec![255u8; w * h * 3];
        if self.nx < 2 || self.ny < 2 {
            return rgb;
        }
        let (lo, hi) = self.z_range_um;
        let span = if hi > lo { hi - lo } else { 1.0 };
        let node = |i: usize, j: usize| {
            let z = self.z_um[j * self.nx + i];
            let (x, y) = self.px(self.x_mm[i], self.y_mm[j], z);
            (x - at.0 as f64, y - at.1 as f64, z)
        };
        let mut cells: Vec<(usize, usize)> = (0..self.ny - 1)
            .flat_map(|j| (0..self.nx - 1).map(move |i| (i, j)))
            .collect();
        let depth = |&(i, j): &(usize, usize)| {
            self.depth(
                0.5 * (self.x_mm[i] + self.x_mm[i + 1]),
                0.5 * (self.y_mm[j] + self.y_mm[j + 1]),
            )
        };
        cells.sort_by(|a, b| depth(b).total_cmp(&depth(a)));
        for (i, j) in cells {
            let c = [
                node(i, j),
                node(i + 1, j),
                node(i + 1, j + 1),
                node(i, j + 1),
            ];
            let mean = c.iter().map(|p| p.2).sum::<f64>() / 4.0;
            // The cell's normal in displayed units: its vertical share shades it.
            let to_mm = 1e-3 * self.exaggeration;
            let dx = (self.x_mm[i + 1] - self.x_mm[i]) * self.stretch.0;
            let dy = (self.y_mm[j + 1] - self.y_mm[j]) * self.stretch.1;
            let gx = 0.5 * ((c[1].2 - c[0].2) + (c[2].2 - c[3].2)) * to_mm / dx;
            let gy = 0.5 * ((c[3].2 - c[0].2) + (c[2].2 - c[1].2)) * to_mm / dy;
            let shade = 0.45 + 0.55 / (1.0 + gx * gx + gy * gy).sqrt();
            let RGBColor(r, g, b) = viridis((mean - lo) / span);
            let colour = [r, g, b].map(|v| (v as f64 * shade).round() as u8);
            for tri in [[c[0], c[1], c[2]], [c[0], c[2], c[3]]] {
                fill_triangle(&mut rgb, (w, h), tri.map(|p| (p.0, p.1)), colour);
            }
        }
        rgb
    }
}

/// Fills the pixels whose centres lie in the triangle `t` (px) with `colour`.
fn fill_triangle(rgb: &mut [u8], (w, h): (usize, usize), t: [(f64, f64); 3], colour: [u8; 3]) {
    let edge = |a: (f64, f64), b: (f64, f64), p: (f64, f64)| {
        (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0)
    };
    let area = edge(t[0], t[1], t[2]);
    if area.abs() < 1e-12 {
        return;
    }
    let (x0, x1) = min_max(&t.map(|p| p.0));
    let (y0, y1) = min_max(&t.map(|p| p.1));
    let clamp = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
    for py in clamp(y0.floor(), h)..clamp(y1.ceil() + 1.0, h) {
        for px in clamp(x0.floor(), w)..clamp(x1.ceil() + 1.0, w) {
            let p = (px as f64 + 0.5, py as f64 + 0.5);
            let inside = [
                edge(t[0], t[1], p),
                edge(t[1], t[2], p),
                edge(t[2], t[0], p),
            ]
            .iter()
            .all(|e| e * area.signum() >= -1e-9);
            if inside {
                let k = (py * w + px) * 3;
                if let Some(dst) = rgb.get_mut(k..k + 3) {
                    dst.copy_from_slice(&colour);
                }
            }
        }
    }
}

/// The 3D view's figure layout: where the surface's bitmap goes and its size.
fn view_area(frame: &Frame) -> ((u32, u32), (i32, i32)) {
    let (w, h) = VIEW_SIZE;
    let body_h = h.saturating_sub(frame.top_px() + frame.bottom_px());
    let area = (
        w.saturating_sub(MAP_BAR_W + 2 * VIEW_PAD),
        body_h.saturating_sub(2 * VIEW_PAD),
    );
    (area, (VIEW_PAD as i32, (frame.top_px() + VIEW_PAD) as i32))
}

fn draw_view<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    grid: &HeightMap<'_>,
    (x0_mm, y0_mm): (f64, f64),
    view: &View,
    frame: &Frame,
    pixels: &std::cell::OnceCell<Vec<u8>>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    frame.draw(root)?;
    let (size, at) = view_area(frame);
    let pixels = pixels.get_or_init(|| view.pixels(size, at)); // the PNG's, kept for the SVG
    let bitmap = BitMapElement::with_ref(at, size, pixels)
        .ok_or_else(|| "3D view bitmap of the wrong size".to_string())?;
    root.draw(&bitmap).map_err(err)?;
    // The axes along the two front edges of the base and up the nearest corner.
    let (lo, hi) = view.z_range_um;
    let (w_mm, h_mm) = (
        (grid.cols.max(2) - 1) as f64 * grid.pitch_x_mm,
        (grid.rows.max(2) - 1) as f64 * grid.pitch_y_mm,
    );
    let p = |x: f64, y: f64, z: f64| {
        let (a, b) = view.px(x, y, z);
        (a.round() as i32, b.round() as i32)
    };
    let o = p(0.0, 0.0, lo);
    let (x_end, y_end, z_top) = (p(w_mm, 0.0, lo), p(0.0, h_mm, lo), p(0.0, 0.0, hi));
    for end in [x_end, y_end, z_top] {
        let axis = PathElement::new(vec![o, end], BLACK.stroke_width(1));
        root.draw(&axis).map_err(err)?;
    }
    let label = |text: String, at: (i32, i32)| -> Result<(), String> {
        root.draw_text(&text, &font(13), at).map_err(err)
    };
    let (x_end_mm, y_end_mm) = (tick(x0_mm + w_mm), tick(y0_mm + h_mm));
    label(format!("x {x_end_mm} mm"), (x_end.0 - 40, x_end.1 + 8))?;
    label(format!("y {y_end_mm} mm"), (y_end.0 + 6, y_end.1 - 20))?;
    label(format!("z {} µm", tick(hi)), (z_top.0 - 48, z_top.1 - 18))?;
    let corner = format!("{}, {}, {} µm", tick(x0_mm), tick(y0_mm), tick(lo));
    label(corner, (o.0 - 30, o.1 + 6))?;
    let (w, h) = root.dim_in_pixel();
    let (_, bar) = root.split_horizontally(w.saturating_sub(MAP_BAR_W));
    let top = frame.top_px();
    let (_, bar) = bar.split_vertically(top);
    draw_colour_bar(
        &bar,
        lo,
        hi,
        "height (µm)",
        VIEW_PAD,
        h.saturating_sub(top + frame.bottom_px() + 2 * VIEW_PAD),
    )
}

/// The 3D view's subtitle: size, scales and what a colour is.
fn view_subtitle(grid: &HeightMap<'_>, view: &View) -> String {
    let stretch = match view.stretch {
        (sx, _) if sx > 1.0 => format!("x stretched ×{} against y", tick(sx)),
        (_, sy) if sy > 1.0 => format!("y stretched ×{} against x", tick(sy)),
        _ => "x and y at one scale".to_string(),
    };
    format!(
        "{} × {} mm, {} lines × {} points, heights as traced {} … {} µm; axonometric, turned {}°, seen from {}° above; {stretch}; {}",
        fmt((grid.cols.max(2) - 1) as f64 * grid.pitch_x_mm, Quantity::LengthMm),
        fmt((grid.rows.max(2) - 1) as f64 * grid.pitch_y_mm, Quantity::LengthMm),
        grid.rows,
        grid.cols,
        fmt(view.z_range_um.0, Quantity::HeightUm),
        fmt(view.z_range_um.1, Quantity::HeightUm),
        tick(AZIMUTH_DEG),
        tick(ELEVATION_DEG),
        exaggeration_note(view.exaggeration)
    )
}

/// The view [`plot_surface_view`] draws of `grid` with `title` and `caption`, and its frame.
fn view_and_frame(grid: &HeightMap<'_>, title: &str, caption: &str) -> (View, Frame) {
    // The frame's height depends on the subtitle, which depends on the view's scales, which
    // do not depend on the area: a first view for the text, the final one for its area.
    let probe = View::of(grid, (VIEW_SIZE.0, VIEW_SIZE.1), (0.0, 0.0));
    let title = if probe.averages(grid) {
        format!("{title} (each node the mean of the points under it)")
    } else {
        title.to_string()
    };
    let frame = Frame::new(VIEW_SIZE.0, &title, &view_subtitle(grid, &probe), caption);
    let (area, at) = view_area(&frame);
    (View::of(grid, area, (at.0 as f64, at.1 as f64)), frame)
}

/// Writes `surface3d.png` and `surface3d.svg` into `dir`: the axonometric view of `grid`
/// (at least 2 × 2 points), its corner and edges labelled in the input's coordinates from
/// `origin_mm` (x, y of its first point). Returns the two paths and the view drawn (where
/// each point lands).
pub fn plot_surface_view(
    dir: &Path,
    grid: &HeightMap<'_>,
    origin_mm: (f64, f64),
    title: &str,
    caption: &str,
) -> Result<([PathBuf; 2], View), MetrologyError> {
    grid.check_size(2)?;
    let (view, frame) = view_and_frame(grid, title, caption);
    let pixels = std::cell::OnceCell::new();
    let files: Result<[PathBuf; 2], MetrologyError> =
        png_and_svg!(dir, "surface3d", VIEW_SIZE, |root| draw_view(
            &root, grid, origin_mm, &view, &frame, &pixels
        ));
    Ok((files?, view))
}
