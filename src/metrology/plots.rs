//! Plots a person would rather look at than read, as PNG and SVG (plotters): all bearing area
//! curves in one graph (like the paper's Figure 8) and a height map of a grid.
//!
//! The only file-writing part of the metrology: the caller gives the directory. Depends on
//! [`super::model`] (the curves), [`super::areal::Grid`] and [`super::MetrologyError`].

use super::areal::Grid;
use super::model::ModelCurveBac;
use super::MetrologyError;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

fn plot_err(path: &Path, e: impl std::fmt::Display) -> MetrologyError {
    MetrologyError::Plot {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Fills the area white and, for a non-empty caption, writes it as one small line at the
/// bottom (traceability: specimen, instrument, conditions, software); returns the area above.
fn with_caption<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    caption: &str,
) -> Result<DrawingArea<DB, Shift>, String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    if caption.trim().is_empty() {
        return Ok(root.clone());
    }
    let (_, h) = root.dim_in_pixel();
    let (upper, lower) = root.split_vertically(h.saturating_sub(CAPTION_PX));
    let style = TextStyle::from(("sans-serif", 13).into_font()).color(&BLACK);
    lower
        .draw_text(caption, &style, (10, 5))
        .map_err(|e| e.to_string())?;
    Ok(upper)
}

/// Height of the caption line in pixels.
const CAPTION_PX: u32 = 24;

/// Largest number of columns drawn in a height map; wider grids are averaged over bins of
/// equal width first (stated in the map's title), which keeps a 31 × 8000 scan's SVG small.
pub const MAX_MAP_COLUMNS: usize = 800;

fn draw_bac<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    curves: &[ModelCurveBac],
    pooled: &[[f64; 2]],
    title: &str,
    caption: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let root = &with_caption(root, caption)?;
    let all = curves
        .iter()
        .flat_map(|c| c.curve.points.iter())
        .chain(pooled.iter());
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
        (lo.min(p[0]), hi.max(p[0]))
    });
    let (lo, hi) = if lo.is_finite() && hi > lo {
        (lo, hi)
    } else {
        (-1.0, 1.0)
    };
    let pad = 0.05 * (hi - lo);
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..100f64, (lo - pad)..(hi + pad))
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("material area ratio MAR (%)")
        .y_desc("height from mean line (µm)")
        .draw()
        .map_err(|e| e.to_string())?;
    let n = curves.len().max(1);
    for (k, c) in curves.iter().enumerate() {
        let colour = HSLColor(0.66 * k as f64 / n as f64, 0.7, 0.45);
        chart
            .draw_series(LineSeries::new(
                c.curve.points.iter().map(|p| (p[1], p[0])),
                colour.stroke_width(1),
            ))
            .map_err(|e| e.to_string())?;
    }
    if !pooled.is_empty() {
        chart
            .draw_series(LineSeries::new(
                pooled.iter().map(|p| (p[1], p[0])),
                BLACK.stroke_width(3),
            ))
            .map_err(|e| e.to_string())?
            .label("pooled")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(3)));
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}

/// Writes `bac.png` and `bac.svg` into `dir`: every curve's MAR(h) thin and coloured, the pooled
/// curve thick and black; `caption` (may be empty) is written as a line below the graph.
/// Returns the two paths.
pub fn plot_bearing_curves(
    dir: &Path,
    curves: &[ModelCurveBac],
    pooled: &[[f64; 2]],
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    let png = dir.join("bac.png");
    let svg = dir.join("bac.svg");
    {
        let root = BitMapBackend::new(&png, (900, 600)).into_drawing_area();
        draw_bac(&root, curves, pooled, title, caption).map_err(|e| plot_err(&png, e))?;
    }
    {
        let root = SVGBackend::new(&svg, (900, 600)).into_drawing_area();
        draw_bac(&root, curves, pooled, title, caption).map_err(|e| plot_err(&svg, e))?;
    }
    Ok([png, svg])
}

fn draw_map<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    grid: &Grid<'_>,
    title: &str,
    caption: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let (z, rows, cols) = (grid.heights_um, grid.rows, grid.cols);
    let (pitch_x_mm, pitch_y_mm) = (grid.pitch_x_mm, grid.pitch_y_mm);
    let root = &with_caption(root, caption)?;
    let (lo, hi) = z
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let span = if hi > lo { hi - lo } else { 1.0 };
    let w = cols as f64 * pitch_x_mm;
    let h = rows as f64 * pitch_y_mm;
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("{title} (height {lo:.3} … {hi:.3} µm, blue → red)"),
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..w, 0f64..h)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .draw()
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(z.iter().enumerate().map(|(k, v)| {
            let (r, c) = ((k / cols) as f64, (k % cols) as f64);
            let t = (v - lo) / span;
            let colour = HSLColor(0.66 * (1.0 - t), 0.85, 0.5);
            Rectangle::new(
                [
                    (c * pitch_x_mm, r * pitch_y_mm),
                    ((c + 1.0) * pitch_x_mm, (r + 1.0) * pitch_y_mm),
                ],
                colour.filled(),
            )
        }))
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

/// Writes `heightmap.png` and `heightmap.svg` into `dir` for a row-major grid (heights µm);
/// more than [`MAX_MAP_COLUMNS`] columns are averaged over bins first. `caption` (may be
/// empty) is written as a line below the map.
pub fn plot_height_map(
    dir: &Path,
    grid: &Grid<'_>,
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    let (heights_um, rows, cols) = (grid.heights_um, grid.rows, grid.cols);
    let (pitch_x_mm, pitch_y_mm) = (grid.pitch_x_mm, grid.pitch_y_mm);
    if rows.checked_mul(cols) != Some(heights_um.len()) || rows == 0 || cols == 0 {
        return Err(MetrologyError::GridSize {
            rows,
            cols,
            expected: rows.saturating_mul(cols),
            got: heights_um.len(),
        });
    }
    super::check_pitch(pitch_x_mm)?;
    super::check_pitch(pitch_y_mm)?;
    let (binned, cols, pitch_x_mm, title) = if cols > MAX_MAP_COLUMNS {
        let bin = cols.div_ceil(MAX_MAP_COLUMNS);
        let out_cols = cols / bin;
        let z: Vec<f64> = (0..rows * out_cols)
            .map(|k| {
                let (r, c) = (k / out_cols, k % out_cols);
                let start = r * cols + c * bin;
                let part = heights_um.get(start..start + bin).unwrap_or(&[]);
                part.iter().sum::<f64>() / part.len().max(1) as f64
            })
            .collect();
        (
            std::borrow::Cow::Owned(z),
            out_cols,
            pitch_x_mm * bin as f64,
            format!("{title}, means of {bin} points along x"),
        )
    } else {
        (
            std::borrow::Cow::Borrowed(heights_um),
            cols,
            pitch_x_mm,
            title.to_string(),
        )
    };
    let shown = Grid {
        heights_um: &binned,
        rows,
        cols,
        pitch_x_mm,
        pitch_y_mm,
    };
    let title = title.as_str();
    let png = dir.join("heightmap.png");
    let svg = dir.join("heightmap.svg");
    {
        let root = BitMapBackend::new(&png, (1000, 500)).into_drawing_area();
        draw_map(&root, &shown, title, caption).map_err(|e| plot_err(&png, e))?;
    }
    {
        let root = SVGBackend::new(&svg, (1000, 500)).into_drawing_area();
        draw_map(&root, &shown, title, caption).map_err(|e| plot_err(&svg, e))?;
    }
    Ok([png, svg])
}

fn draw_overlay<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    measured: &[(f64, f64)],
    model: &[(f64, f64)],
    title: &str,
    caption: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let root = &with_caption(root, caption)?;
    let pts = measured.iter().chain(model.iter());
    let (x0, x1, z0, z1) = pts.fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), p| (a.min(p.0), b.max(p.0), c.min(p.1), d.max(p.1)),
    );
    let (x0, x1) = if x1 > x0 { (x0, x1) } else { (0.0, 1.0) };
    let (z0, z1) = if z1 > z0 {
        (z0, z1)
    } else {
        (z0 - 1.0, z0 + 1.0)
    };
    let pad = 0.05 * (z1 - z0);
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, (z0 - pad)..(z1 + pad))
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("x (mm)")
        .y_desc("height (µm)")
        .draw()
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(LineSeries::new(model.iter().copied(), RED.stroke_width(1)))
        .map_err(|e| e.to_string())?
        .label("NURBS model")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    chart
        .draw_series(
            measured
                .iter()
                .map(|&(x, z)| Circle::new((x, z), 2, BLUE.filled())),
        )
        .map_err(|e| e.to_string())?
        .label("measured")
        .legend(|(x, y)| Circle::new((x + 10, y), 3, BLUE.filled()));
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE)
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

/// Writes `overlay.png` and `overlay.svg` into `dir`: measured points of a line as dots and the
/// model's curve through them, as `(x_mm, z_um)` pairs; `caption` (may be empty) is written as
/// a line below the graph.
pub fn plot_profile_overlay(
    dir: &Path,
    measured: &[(f64, f64)],
    model: &[(f64, f64)],
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    let png = dir.join("overlay.png");
    let svg = dir.join("overlay.svg");
    {
        let root = BitMapBackend::new(&png, (1000, 500)).into_drawing_area();
        draw_overlay(&root, measured, model, title, caption).map_err(|e| plot_err(&png, e))?;
    }
    {
        let root = SVGBackend::new(&svg, (1000, 500)).into_drawing_area();
        draw_overlay(&root, measured, model, title, caption).map_err(|e| plot_err(&svg, e))?;
    }
    Ok([png, svg])
}
