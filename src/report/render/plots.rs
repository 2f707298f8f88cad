//! Plots a metrologist would put in a report, as PNG and SVG (plotters): the material ratio
//! curves of the model's profile curves with the pooled areal Smr(c) (like the paper's
//! Figure 8), a height map of a grid, a measured-vs-model profile, and the ISO 13565-2 Rk
//! construction of one line.
//!
//! Conventions every plot keeps:
//! * the text is drawn with DejaVu Sans, bundled into the binary (`assets/fonts/`, licence
//!   beside it), so every glyph (µ, λ, ·) renders the same on any machine; the SVG files name
//!   the generic `sans-serif` family and are laid out with the bundled font's metrics;
//! * colours are the perceptual, colour-blind safe viridis map, and every colour has a key (a
//!   labelled colour bar or a legend entry);
//! * a map is drawn to true scale, or the exaggeration of its shorter axis is stated on it;
//! * ISO vocabulary: Rmr(c) for a profile's material ratio, Smr(c) for the areal one;
//! * the title and the traceability footer wrap rather than run off the edge;
//! * a series is drawn at the figure's resolution: more than four points a pixel column are
//!   reduced to each column's first, last, lowest and highest ([`super::decimate`]), and a
//!   map is one bitmap of the pixels it covers, so the files' size and the drawing time follow
//!   the figure, not the data.
//!
//! A renderer: numbers in, files out, into the directory the caller gives. Depends on
//! [`crate::metrology`] (the curves, the height map, the Rk family, the checks of a grid and
//! its errors), [`super::text_cache`] (the PNGs' text memo), [`super::decimate`] (the series
//! at display resolution), [`crate::extremes`], [`crate::numfmt`] and
//! [`crate::atomic`] (each file replaced whole); plotters draws, and `image` encodes the PNG
//! files.

use super::decimate::{extremes_per_column, extremes_per_column_of_pairs};
use super::text_cache::TextCache;
use crate::extremes::min_max;
use crate::metrology::areal::HeightMap;
use crate::metrology::model::ModelCurveBac;
use crate::metrology::parameter_table::parameter;
use crate::metrology::params::RkFamily;
use crate::metrology::MetrologyError;
use crate::numfmt::{fmt, Quantity};
use plotters::chart::MeshStyle;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// DejaVu Sans 2.37, unmodified (Bitstream Vera licence, `assets/fonts/LICENSE-DejaVu.txt`).
const FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

/// The family the bundled font is registered under: the generic name, so the SVG files ask
/// their viewer for a sans-serif face rather than one it may not have.
const FAMILY: &str = "sans-serif";

/// Registers the bundled font with plotters, once per process.
pub(super) fn ensure_font() -> Result<(), String> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *REGISTERED
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err("the bundled font cannot be read (assets/fonts/DejaVuSans.ttf is damaged)".into())
    }
}

/// A drawing error as the text a figure's error carries ([`plot_err`] adds the file).
pub(super) fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

pub(super) fn plot_err(path: &Path, e: impl std::fmt::Display) -> MetrologyError {
    MetrologyError::Plot {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// The bundled font at `size` px. The font is registered first: plotters binds a style to
/// its font when the style is made, so a style made before registration (e.g. to lay out a
/// frame before any figure is drawn) would measure every text as 0 px wide. A font that
/// cannot be registered is reported where the figure is drawn ([`ensure_font`]).
pub(super) fn font(size: u32) -> TextStyle<'static> {
    let _ = ensure_font();
    TextStyle::from((FAMILY, size).into_font()).color(&BLACK)
}

/// An axis tick label: up to 4 significant digits without trailing zeros (a tick's zeros
/// carry no precision), float noise around zero written as 0.
pub(super) fn tick(v: f64) -> String {
    if v.abs() < 1e-12 {
        return "0".to_string();
    }
    let s = crate::numfmt::sig(v, 4);
    if s.contains('e') || !s.contains('.') {
        return s;
    }
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// The mesh every chart here draws on `chart`: the axes described as `x_desc` and `y_desc`,
/// labels in the bundled font, ticks written by [`tick`], a light grid. A caller adds what
/// its chart differs in (label counts, no grid) before drawing it.
fn mesh<'a, 'b, X, Y, DB>(
    chart: &'b mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    x_desc: &'b str,
    y_desc: &'b str,
) -> MeshStyle<'a, 'b, X, Y, DB>
where
    DB: DrawingBackend,
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let mut style = chart.configure_mesh();
    style
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(font(13))
        .axis_desc_style(font(14))
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .light_line_style(RGBColor(235, 235, 235));
    style
}

/// [`tick`] as plotters' label formatter.
fn tick_label(v: &f64) -> String {
    tick(*v)
}

/// Dark blue of the measured data and curves (Okabe–Ito "blue").
pub(super) const DATA: RGBColor = RGBColor(0, 114, 178);
/// Vermillion of the model and of constructions (Okabe–Ito).
pub(super) const MODEL: RGBColor = RGBColor(213, 94, 0);
/// Bluish green (Okabe–Ito) for the second construction element.
const SECOND: RGBColor = RGBColor(0, 158, 115);

/// The viridis colour at `t` in [0, 1] (clamped; NaN is the low end).
pub fn viridis(t: f64) -> RGBColor {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    ViridisRGB.get_color(t as f32)
}

/// Width of `text` in `style`, px (from the bundled font's metrics).
fn text_width(text: &str, style: &TextStyle<'_>) -> u32 {
    style.font.box_size(text).map(|(w, _)| w).unwrap_or(0)
}

/// Greedy word wrap of `text` into lines no wider than `width` px in `style`; a word wider
/// than the line goes on a line of its own.
fn wrap(text: &str, style: &TextStyle<'_>, width: u32) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut cur = String::new();
    for word in text.split_whitespace() {
        let candidate = if cur.is_empty() {
            word.to_string()
        } else {
            format!("{cur} {word}")
        };
        // A separator (`·`) ends the line it follows rather than starting the next.
        let separator = word.chars().all(|c| !c.is_alphanumeric());
        if cur.is_empty() || separator || text_width(&candidate, style) <= width {
            cur = candidate;
        } else {
            lines.push(std::mem::replace(&mut cur, word.to_string()));
        }
    }
    if !cur.is_empty() {
        lines.push(cur);
    }
    lines
}

/// [`wrap`] of `text` in the bundled font at `px`, remembered: a report draws every figure
/// twice (PNG and SVG) and its Rk figures share one subtitle and one footer, so the same
/// texts come back at the same size and width, and measuring them word by word is most of
/// the cost of a frame. std has no bounded memo; this one is cleared past 64 entries, so a
/// long-running daemon's titles cannot grow it.
fn wrapped(text: &str, px: u32, width: u32) -> Vec<String> {
    type Memo = std::collections::HashMap<(String, u32, u32), Vec<String>>;
    static MEMO: std::sync::LazyLock<std::sync::Mutex<Memo>> =
        std::sync::LazyLock::new(|| std::sync::Mutex::new(Memo::new()));
    let key = (text.to_string(), px, width);
    if let Some(lines) = MEMO.lock().ok().and_then(|m| m.get(&key).cloned()) {
        return lines;
    }
    let lines = wrap(text, &font(px), width);
    if let Ok(mut m) = MEMO.lock() {
        if m.len() >= 64 {
            m.clear();
        }
        m.insert(key, lines.clone());
    }
    lines
}

/// Title size, subtitle size, footer size and the line spacing factor.
const TITLE_PX: u32 = 20;
const SUBTITLE_PX: u32 = 14;
const FOOTER_PX: u32 = 12;
const SIDE_PAD: u32 = 12;

/// Lines of the title band and of the footer, wrapped to the figure's width.
pub(super) struct Frame {
    title: Vec<String>,
    subtitle: Vec<String>,
    footer: Vec<String>,
}

impl Frame {
    /// The frame of a figure `figure_w` px wide.
    pub(super) fn new(figure_w: u32, title: &str, subtitle: &str, footer: &str) -> Frame {
        let width = figure_w.saturating_sub(2 * SIDE_PAD);
        Frame {
            title: wrapped(title, TITLE_PX, width),
            subtitle: wrapped(subtitle, SUBTITLE_PX, width),
            footer: wrapped(footer, FOOTER_PX, width),
        }
    }

    pub(super) fn top_px(&self) -> u32 {
        8 + self.title.len() as u32 * (TITLE_PX + 6)
            + self.subtitle.len() as u32 * (SUBTITLE_PX + 5)
    }

    pub(super) fn bottom_px(&self) -> u32 {
        if self.footer.is_empty() {
            4
        } else {
            8 + self.footer.len() as u32 * (FOOTER_PX + 5)
        }
    }

    /// Fills the area white, draws the title band and the footer, returns the body between.
    pub(super) fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<DrawingArea<DB, Shift>, String>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE).map_err(err)?;
        // Lines of text `px` high and `gap` apart from `y` down; returns the y below them.
        let text = |lines: &[String], px: u32, colour: RGBColor, gap: u32, mut y: i32| {
            for l in lines {
                root.draw_text(l, &font(px).color(&colour), (SIDE_PAD as i32, y))
                    .map_err(err)?;
                y += (px + gap) as i32;
            }
            Ok::<i32, String>(y)
        };
        let grey = RGBColor(60, 60, 60);
        let y = text(&self.title, TITLE_PX, BLACK, 6, 8)?;
        text(&self.subtitle, SUBTITLE_PX, grey, 5, y)?;
        let (_, h) = root.dim_in_pixel();
        let y = h.saturating_sub(self.bottom_px()) as i32 + 6;
        text(&self.footer, FOOTER_PX, grey, 5, y)?;
        let body_h = h
            .saturating_sub(self.top_px())
            .saturating_sub(self.bottom_px());
        let (_, rest) = root.split_vertically(self.top_px());
        let (body, _) = rest.split_vertically(body_h);
        Ok(body)
    }
}

/// A vertical colour bar for values `lo..hi` with its label, filling `area`; `margin_top`
/// and `plot_h` align the bar with the plotting area beside it.
pub(super) fn draw_colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    lo: f64,
    hi: f64,
    label: &str,
    margin_top: u32,
    plot_h: u32,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let (w, _) = area.dim_in_pixel();
    let (_, below) = area.split_vertically(margin_top);
    let (bar_area, _) = below.split_vertically(plot_h);
    let (hi, lo_) = if hi > lo { (hi, lo) } else { (lo + 1.0, lo) };
    let mut bar = ChartBuilder::on(&bar_area)
        .margin_left(24)
        .margin_right(w.saturating_sub(24 + 22 + 90))
        .right_y_label_area_size(90)
        .build_cartesian_2d(0f64..1f64, lo_..hi)
        .map_err(err)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(6)
        .y_label_style(font(12))
        .y_label_formatter(&tick_label)
        .y_desc(label)
        .axis_desc_style(font(13))
        .draw()
        .map_err(err)?;
    let steps = 128;
    bar.draw_series((0..steps).map(|k| {
        let a = lo_ + (hi - lo_) * k as f64 / steps as f64;
        let b = lo_ + (hi - lo_) * (k + 1) as f64 / steps as f64;
        Rectangle::new(
            [(0.0, a), (1.0, b)],
            viridis((k as f64 + 0.5) / steps as f64).filled(),
        )
    }))
    .map_err(err)?;
    bar.draw_series(std::iter::once(Rectangle::new(
        [(0.0, lo_), (1.0, hi)],
        BLACK.stroke_width(1),
    )))
    .map_err(err)?;
    Ok(())
}

/// Writes `STEM.png` and `STEM.svg` into `DIR`, running the drawing expression once with
/// `root` a bitmap area and once with `root` an SVG area (the drawing code is generic over
/// the backend; a closure cannot be). Returns the two paths from the enclosing function.
/// With `png: false` after the size only the SVG is drawn and written (and an old PNG removed).
macro_rules! png_and_svg {
    ($dir:expr, $stem:expr, $size:expr, |$root:ident| $draw:expr) => {
        png_and_svg!($dir, $stem, $size, png: true, |$root| $draw)
    };
    ($dir:expr, $stem:expr, $size:expr, png: $with_png:expr, |$root:ident| $draw:expr) => {{
        let png = $dir.join(format!("{}.png", $stem));
        let svg = $dir.join(format!("{}.svg", $stem));
        ensure_font().map_err(|e| plot_err(&png, e))?;
        if $with_png {
            let (w, h): (u32, u32) = $size;
            let mut rgb = vec![0u8; w as usize * h as usize * 3];
            {
                // Texts repeated across figures are rasterised once per thread (the same
                // pixels).
                let bitmap = BitMapBackend::with_buffer(&mut rgb, (w, h));
                let $root = TextCache::new(bitmap).into_drawing_area();
                let drawn: Result<(), String> = $draw;
                drawn.map_err(|e| plot_err(&png, e))?;
                $root.present().map_err(|e| plot_err(&png, e))?;
            }
            write_png(&png, &rgb, (w, h))?;
        } else {
            // A PNG an earlier analysis left would show other results than the new SVG.
            crate::report::render::remove_if_there(&png).map_err(|e| plot_err(&png, e))?;
        }
        {
            let mut text = String::new();
            {
                let $root = SVGBackend::with_string(&mut text, $size).into_drawing_area();
                let drawn: Result<(), String> = $draw;
                drawn.map_err(|e| plot_err(&svg, e))?;
                $root.present().map_err(|e| plot_err(&svg, e))?;
            }
            // plotters names an embedded bitmap's type `png`; a data URL's is `image/png`.
            let text = text.replace(
                r#"href="data:png;base64,"#,
                r#"href="data:image/png;base64,"#,
            );
            replace_figure(&svg, |w| std::io::Write::write_all(w, text.as_bytes()))?;
        }
        Ok([png, svg])
    }};
}
pub(super) use png_and_svg;

/// Writes an RGB bitmap as `path`: fast deflate, every row Paeth-filtered.
///
/// The pixels are those plotters draws; only their encoding is chosen here. Per-row adaptive
/// filtering (plotters' own `present`, through `image`'s default) tries all five PNG filters
/// on every row: on the 34 figures of a 31-line analysis (white ground, thin lines, flat
/// colour fields) it took 693 M instructions against 421 M for 6.3 MB of files against
/// 7.3 MB. The file is replaced whole ([`replace_figure`]).
pub(super) fn write_png(path: &Path, rgb: &[u8], (w, h): (u32, u32)) -> Result<(), MetrologyError> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    replace_figure(path, |out| {
        PngEncoder::new_with_quality(out, CompressionType::Fast, FilterType::Paeth)
            .write_image(rgb, w, h, image::ColorType::Rgb8)
            .map_err(std::io::Error::other)
    })
}

/// Writes a figure file through a temporary file beside it, renamed over `path` once it is
/// complete and flushed: a write that fails (a full disk) or is interrupted leaves the
/// previous figure, never part of one, and a reader of the old file keeps it whole. Not
/// fsynced: a figure is derived, made again by `surfscan analyze`, and 34 fsyncs would cost
/// an analysis more than all its other writes.
pub(super) fn replace_figure(
    path: &Path,
    body: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), MetrologyError> {
    crate::atomic::write_atomically_without_sync(path, body).map_err(|e| plot_err(path, e))
}

/// The range of `values` padded by 5 % (a unit range around a constant, `fallback` when
/// there is none).
pub(super) fn padded_range(values: impl Iterator<Item = f64>, fallback: (f64, f64)) -> (f64, f64) {
    let finite: Vec<f64> = values.filter(|v| v.is_finite()).collect();
    let (lo, hi) = min_max(&finite);
    if !(lo.is_finite() && hi.is_finite()) {
        return fallback;
    }
    if hi > lo {
        let pad = 0.05 * (hi - lo);
        (lo - pad, hi + pad)
    } else {
        (lo - 1.0, hi + 1.0)
    }
}

/// Figure size of the bearing area curve plot.
const BAC_SIZE: (u32, u32) = (1000, 640);

/// The margin and the x label area of a chart ([`chart`]), in pixels.
const CHART_MARGIN: u32 = 12;
const CHART_X_AREA: u32 = 50;

/// Draws the legend of `chart`'s labelled series at `position`, boxed on white.
pub(super) fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .position(position)
        .label_font(font(13))
        .border_style(BLACK)
        .background_style(WHITE.mix(0.9))
        .draw()
        .map_err(err)
}

/// A legend's key for a series drawn as a line in `style`: a stroke 24 px long.
pub(super) fn line_key(style: ShapeStyle) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style)
}

/// A chart of [`chart`]: its coordinates those of its two ranges.
pub(super) type Chart<'a, DB, X, Y> = ChartContext<
    'a,
    DB,
    Cartesian2d<<X as AsRangedCoord>::CoordDescType, <Y as AsRangedCoord>::CoordDescType>,
>;

/// A chart on `area` with the figures' margin, label areas and light mesh, over `x` and `y`
/// (linear ranges or `.log_scale()` ones), its axes described by `desc` (x, y), the x ticks
/// labelled by [`tick`] and the y ticks by `y_tick`. Every chart of the figures is built here.
pub(super) fn chart<'a, DB, X, Y>(
    area: &'a DrawingArea<DB, Shift>,
    x: X,
    y: Y,
    (x_desc, y_desc): (&str, &str),
    y_tick: &dyn Fn(&f64) -> String,
) -> Result<Chart<'a, DB, X, Y>, String>
where
    DB: DrawingBackend,
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let mut chart = ChartBuilder::on(area)
        .margin(CHART_MARGIN)
        .x_label_area_size(CHART_X_AREA)
        .y_label_area_size(80)
        .build_cartesian_2d(x, y)
        .map_err(err)?;
    mesh(&mut chart, x_desc, y_desc)
        .y_label_formatter(y_tick)
        .draw()
        .map_err(err)?;
    Ok(chart)
}

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
    let subtitle = if curves.is_empty() {
        "Areal material ratio Smr(c) of the measured grid (ISO 25178-2); heights c from the mean plane".to_string()
    } else {
        format!(
            "Thin: Rmr(c) of each of the {} profile curves of the model, coloured by the curve's y (bar); thick black: areal Smr(c) pooled over the surface (ISO 25178-2)",
            curves.len()
        )
    };
    let frame = Frame::new(root.dim_in_pixel().0, title, &subtitle, caption);
    let body = frame.draw(root)?;
    let (bw, _) = body.dim_in_pixel();
    let bar_w = if curves.is_empty() { 0 } else { MAP_BAR_W };
    let (plot_area, bar_area) = body.split_horizontally(bw.saturating_sub(bar_w));
    let all = curves
        .iter()
        .flat_map(|c| c.curve.points.iter())
        .chain(pooled.iter())
        .map(|p| p[0]);
    let (lo, hi) = padded_range(all, (-1.0, 1.0));
    let mut chart = chart(
        &plot_area,
        0f64..100f64,
        lo..hi,
        ("material ratio (%)", "height c from the mean line (µm)"),
        &|v| tick(*v),
    )?;
    let (y_lo, y_hi) = min_max(&curves.iter().map(|c| c.y_mm).collect::<Vec<_>>());
    let y_span = if y_hi > y_lo { y_hi - y_lo } else { 1.0 };
    let columns = chart.plotting_area().dim_in_pixel().0;
    // Drawn as (material ratio, height): decimated along the material ratio.
    let drawn = |points: &[[f64; 2]]| {
        let swapped: Vec<[f64; 2]> = points.iter().map(|p| [p[1], p[0]]).collect();
        extremes_per_column_of_pairs(&swapped, (0.0, 100.0), columns)
    };
    for (k, c) in curves.iter().enumerate() {
        let colour = viridis((c.y_mm - y_lo) / y_span);
        let series = chart
            .draw_series(LineSeries::new(
                drawn(&c.curve.points),
                colour.stroke_width(1),
            ))
            .map_err(err)?;
        if k == 0 {
            series
                .label("Rmr(c) of one model profile curve (colour: its y)")
                .legend(line_key(viridis(0.5).stroke_width(2)));
        }
    }
    if !pooled.is_empty() {
        chart
            .draw_series(LineSeries::new(drawn(pooled), BLACK.stroke_width(3)))
            .map_err(err)?
            .label(if curves.is_empty() {
                "Smr(c), measured grid"
            } else {
                "Smr(c), pooled over the model surface"
            })
            .legend(line_key(BLACK.stroke_width(3)));
    }
    if !curves.is_empty() || !pooled.is_empty() {
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    if !curves.is_empty() {
        let plot_h = plot_area
            .dim_in_pixel()
            .1
            .saturating_sub(2 * CHART_MARGIN + CHART_X_AREA);
        draw_colour_bar(&bar_area, y_lo, y_hi, "curve y (mm)", CHART_MARGIN, plot_h)?;
    }
    Ok(())
}

/// Writes `bac.png` and `bac.svg` into `dir`: every model curve's Rmr(c) thin and coloured
/// by its y (with a colour bar), the pooled areal Smr(c) thick and black; `caption` (may be
/// empty) is the traceability footer. Returns the two paths.
pub fn plot_bearing_curves(
    dir: &Path,
    curves: &[ModelCurveBac],
    pooled: &[[f64; 2]],
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    png_and_svg!(dir, "bac", BAC_SIZE, |root| draw_bac(
        &root, curves, pooled, title, caption
    ))
}

/// One point of a load–area curve as drawn: nominal pressure (MPa), real contact area (%),
/// and whether the grid resolves the contact at that load.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadAreaPoint {
    /// Nominal pressure, MPa.
    pub nominal_pressure_mpa: f64,
    /// Real contact area, % of the nominal area.
    pub area_pct: f64,
    /// Whether the grid resolves the contact at this load.
    pub resolved: bool,
}

/// Writes `load_area.png` and `load_area.svg` into `dir`: the real contact area against the
/// nominal pressure (logarithmic), a filled dot per resolved load and a hollow one where the
/// grid does not resolve the contact; `subtitle` says what was pressed against what.
pub fn plot_load_area(
    dir: &Path,
    points: &[LoadAreaPoint],
    title: &str,
    subtitle: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    png_and_svg!(dir, "load_area", BAC_SIZE, |root| draw_load_area(
        &root, points, title, subtitle, caption
    ))
}

fn draw_load_area<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    points: &[LoadAreaPoint],
    title: &str,
    subtitle: &str,
    caption: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let frame = Frame::new(root.dim_in_pixel().0, title, subtitle, caption);
    let body = frame.draw(root)?;
    let pressures = points.iter().map(|p| p.nominal_pressure_mpa);
    let (p_lo, p_hi) = min_max(
        &pressures
            .filter(|p| p.is_finite() && *p > 0.0)
            .collect::<Vec<_>>(),
    );
    let (p_lo, p_hi) = if p_lo.is_finite() {
        (p_lo / 1.5, p_hi * 1.5)
    } else {
        (0.1, 1000.0)
    };
    let (_, a_hi) = padded_range(points.iter().map(|p| p.area_pct).chain([0.0]), (0.0, 100.0));
    let mut chart = chart(
        &body,
        (p_lo..p_hi).log_scale(),
        0f64..a_hi.min(100.0),
        (
            "nominal pressure (MPa, logarithmic)",
            "real contact area (% of the nominal area)",
        ),
        &|v| tick(*v),
    )?;
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|p| (p.nominal_pressure_mpa, p.area_pct)),
            DATA.stroke_width(2),
        ))
        .map_err(err)?;
    chart
        .draw_series(
            points
                .iter()
                .filter(|p| p.resolved)
                .map(|p| Circle::new((p.nominal_pressure_mpa, p.area_pct), 4, DATA.filled())),
        )
        .map_err(err)?
        .label("resolved by the grid")
        .legend(|(x, y)| Circle::new((x + 12, y), 4, DATA.filled()));
    if points.iter().any(|p| !p.resolved) {
        chart
            .draw_series(points.iter().filter(|p| !p.resolved).map(|p| {
                Circle::new(
                    (p.nominal_pressure_mpa, p.area_pct),
                    4,
                    MODEL.stroke_width(2),
                )
            }))
            .map_err(err)?
            .label("not resolved: most contact points are isolated single points")
            .legend(|(x, y)| Circle::new((x + 12, y), 4, MODEL.stroke_width(2)));
    }
    legend(&mut chart, SeriesLabelPosition::UpperLeft)
}

/// Exaggerations offered for the shorter axis of a map that would be too thin at true scale.
pub(super) const EXAGGERATIONS: [f64; 12] = [
    1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0,
];

/// How a map of `w_mm` × `h_mm` is drawn: plotting-area pixels and the exaggeration of y
/// (`> 1`: y is stretched) or of x (`< 1`: x is stretched by the reciprocal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapScale {
    /// Width of the plotting area, px.
    pub plot_w: u32,
    /// Height of the plotting area, px.
    pub plot_h: u32,
    /// Pixels per mm along y over pixels per mm along x (1 = true scale).
    pub y_over_x: f64,
}

/// The plotting-area size and exaggeration for a map of `w_mm` × `h_mm`: true scale when the
/// shorter side gets at least `min_px` within `max_w` × `max_h`, else the smallest
/// exaggeration of [`EXAGGERATIONS`] that gives it `min_px`.
pub fn map_scale(w_mm: f64, h_mm: f64, max_w: u32, max_h: u32, min_px: u32) -> MapScale {
    let ratio = h_mm / w_mm;
    let pick = |true_px: f64| {
        EXAGGERATIONS
            .iter()
            .copied()
            .find(|f| true_px * f >= min_px as f64)
            .unwrap_or(EXAGGERATIONS[EXAGGERATIONS.len() - 1])
    };
    if ratio <= max_h as f64 / max_w as f64 {
        let f = pick(max_w as f64 * ratio);
        let plot_h = (max_w as f64 * ratio * f).round().clamp(1.0, max_h as f64) as u32;
        MapScale {
            plot_w: max_w,
            plot_h,
            y_over_x: f,
        }
    } else {
        let f = pick(max_h as f64 / ratio);
        let plot_w = (max_h as f64 / ratio * f).round().clamp(1.0, max_w as f64) as u32;
        MapScale {
            plot_w,
            plot_h: max_h,
            y_over_x: 1.0 / f,
        }
    }
}

/// Margins and label areas of the map (px).
const MAP_MARGIN: u32 = 14;
const MAP_X_AREA: u32 = 50;
const MAP_Y_AREA: u32 = 70;
pub(super) const MAP_BAR_W: u32 = 150;
const MAP_WIDTH: u32 = 1000;

fn map_note(scale: &MapScale) -> String {
    if scale.y_over_x == 1.0 {
        "true scale: x and y drawn 1:1".to_string()
    } else if scale.y_over_x > 1.0 {
        format!(
            "not to scale: y stretched ×{} against x",
            fmt(scale.y_over_x, Quantity::Ratio).trim_end_matches(".00")
        )
    } else {
        format!(
            "not to scale: x stretched ×{} against y",
            fmt(1.0 / scale.y_over_x, Quantity::Ratio).trim_end_matches(".00")
        )
    }
}

/// What a map shows: its files' stem, the values' name and unit in the subtitle, the colour
/// bar's label.
#[derive(Debug, Clone, Copy)]
pub struct MapValues<'a> {
    /// The files are `<stem>.png` and `<stem>.svg`.
    pub stem: &'a str,
    /// The values in the subtitle's range ("heights").
    pub name: &'a str,
    /// Their unit ("µm").
    pub unit: &'a str,
    /// The colour bar's label ("height (µm)").
    pub bar: &'a str,
}

/// A height map's values.
const HEIGHTS: MapValues<'static> = MapValues {
    stem: "heightmap",
    name: "heights",
    unit: "µm",
    bar: "height (µm)",
};

/// The subtitle of a map: size, points, value range and scale.
fn map_subtitle(grid: &HeightMap<'_>, values: &MapValues<'_>, scale: &MapScale) -> String {
    let (lo, hi) = min_max(grid.heights_um);
    format!(
        "{} × {} mm, {} lines × {} points; {} {} … {} {}; {}",
        fmt(grid.cols as f64 * grid.pitch_x_mm, Quantity::LengthMm),
        fmt(grid.rows as f64 * grid.pitch_y_mm, Quantity::LengthMm),
        grid.rows,
        grid.cols,
        values.name,
        fmt(lo, Quantity::HeightUm),
        fmt(hi, Quantity::HeightUm),
        values.unit,
        map_note(scale)
    )
}

/// The points `a..b` along an axis of `n` (at least one) under pixel `p` of `px`: those whose
/// cells start within it, else the one point under it.
pub(super) fn points_under(p: usize, n: usize, px: usize) -> (usize, usize) {
    let a = (p * n / px).min(n - 1);
    (a, ((p + 1) * n / px).clamp(a + 1, n))
}

/// The pixels of a height map `width` × `height` px over the whole grid, row 0 of the
/// bitmap at the grid's last line (y up): each pixel the mean of the points whose cells
/// start within it (the one point under it when the grid is coarser than the pixels), in
/// viridis over `lo..hi`. RGB, row-major.
fn map_pixels(grid: &HeightMap<'_>, (width, height): (u32, u32), (lo, hi): (f64, f64)) -> Vec<u8> {
    let (z, rows, cols) = (grid.heights_um, grid.rows, grid.cols);
    let (w, h) = (width.max(1) as usize, height.max(1) as usize);
    // Each line's sums over the pixel columns, then the lines under each pixel row.
    let columns: Vec<(usize, usize)> = (0..w).map(|i| points_under(i, cols, w)).collect();
    let mut sums = vec![0.0; rows * w];
    for (r, line) in z.chunks_exact(cols).enumerate() {
        for (i, &(a, b)) in columns.iter().enumerate() {
            sums[r * w + i] = line[a..b].iter().sum();
        }
    }
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut rgb = Vec::with_capacity(w * h * 3);
    for j in 0..h {
        let (a, b) = points_under(j, rows, h);
        // Pixel row 0 is the top of the map: the last lines.
        let (a, b) = (rows - b, rows - a);
        for (i, &(c0, c1)) in columns.iter().enumerate() {
            let total: f64 = (a..b).map(|r| sums[r * w + i]).sum();
            let mean = total / ((b - a) * (c1 - c0)) as f64;
            let RGBColor(r, g, bl) = viridis((mean - lo) / span);
            rgb.extend_from_slice(&[r, g, bl]);
        }
    }
    rgb
}

/// Whether a map `width` × `height` px shows more than one point in some pixel.
fn map_is_averaged(grid: &HeightMap<'_>, (width, height): (u32, u32)) -> bool {
    grid.cols > width as usize || grid.rows > height as usize
}

fn draw_map<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    grid: &HeightMap<'_>,
    (x0_mm, y0_mm): (f64, f64),
    bar: &str,
    scale: &MapScale,
    frame: &Frame,
    pixels: &std::cell::OnceCell<Vec<u8>>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let (lo, hi) = min_max(grid.heights_um);
    let (w, h) = (
        grid.cols as f64 * grid.pitch_x_mm,
        grid.rows as f64 * grid.pitch_y_mm,
    );
    let body = frame.draw(root)?;
    let chart_w = scale.plot_w + MAP_Y_AREA + 2 * MAP_MARGIN;
    let (chart_area, rest) = body.split_horizontally(chart_w);
    let (chart_area, _) = chart_area.split_vertically(scale.plot_h + 2 * MAP_MARGIN + MAP_X_AREA);
    let (bar_area, _) = rest.split_horizontally(MAP_BAR_W);
    // Axis ranges chosen so that one pixel is the same length along x and y (times the
    // stated exaggeration), whatever the rounding of the pixel counts.
    let mm_per_px_x = w / scale.plot_w as f64;
    let y_top = scale.plot_h as f64 * mm_per_px_x / scale.y_over_x;
    let mut chart = ChartBuilder::on(&chart_area)
        .margin(MAP_MARGIN)
        .x_label_area_size(MAP_X_AREA)
        .y_label_area_size(MAP_Y_AREA)
        .build_cartesian_2d(x0_mm..x0_mm + w, y0_mm..y0_mm + y_top.max(h))
        .map_err(err)?;
    mesh(&mut chart, "x (mm)", "y (mm)")
        .disable_mesh()
        .x_labels(8)
        .y_labels(4)
        .draw()
        .map_err(err)?;
    // The map as one bitmap at the pixels it covers from the grid's top left corner to its
    // bottom right (at least one each way), the figure's not the grid's (an SVG embeds it as
    // one PNG image): made for the PNG, kept for the SVG (one size, the same chart).
    let (x1_mm, y1_mm) = (x0_mm + w, y0_mm + h);
    let (left, top) = chart.backend_coord(&(x0_mm, y1_mm));
    let (right, bottom) = chart.backend_coord(&(x1_mm, y0_mm));
    let size = ((right - left).max(1) as u32, (bottom - top).max(1) as u32);
    let pixels = pixels.get_or_init(|| map_pixels(grid, size, (lo, hi)));
    let bitmap = BitMapElement::with_ref((x0_mm, y1_mm), size, pixels)
        .ok_or_else(|| "height map bitmap of the wrong size".to_string())?;
    chart.plotting_area().draw(&bitmap).map_err(err)?;
    draw_colour_bar(
        &bar_area,
        lo,
        hi,
        bar,
        MAP_MARGIN,
        scale.plot_h.max(MAP_MIN_BAR_H),
    )
}

/// The colour bar is at least this tall even beside a thin map, px.
const MAP_MIN_BAR_H: u32 = 160;

/// Writes `heightmap.png` and `heightmap.svg` into `dir` for a row-major grid (heights µm)
/// in viridis with a colour bar, to true scale or with the exaggeration stated. The map is
/// drawn at the figure's resolution: where a pixel covers several points it shows their mean
/// (said in the title); the subtitle's range and the colour bar are the points' own.
/// `caption` (may be empty) is the traceability footer; x and y start at `origin_mm` (the
/// input's coordinates, [`crate::grid::Grid::origin_mm`]).
pub fn plot_height_map(
    dir: &Path,
    grid: &HeightMap<'_>,
    origin_mm: (f64, f64),
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    plot_map(dir, grid, origin_mm, &HEIGHTS, title, caption)
}

/// Writes `<values.stem>.png|svg` into `dir`: a map of any row-major values (the heights of
/// [`HeightMap`] read as the values named by `values`, from `origin_mm`) drawn as
/// [`plot_height_map`] draws heights.
pub fn plot_map(
    dir: &Path,
    grid: &HeightMap<'_>,
    origin_mm: (f64, f64),
    values: &MapValues<'_>,
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    grid.check_size(1)?;
    let (w_mm, h_mm) = (
        grid.cols as f64 * grid.pitch_x_mm,
        grid.rows as f64 * grid.pitch_y_mm,
    );
    let max_w = MAP_WIDTH - MAP_BAR_W - MAP_Y_AREA - 2 * MAP_MARGIN;
    let scale = map_scale(w_mm, h_mm, max_w, 520, 160);
    let title = if map_is_averaged(grid, (scale.plot_w, scale.plot_h)) {
        format!("{title} (each pixel the mean of the points under it)")
    } else {
        title.to_string()
    };
    let frame = Frame::new(
        MAP_WIDTH,
        &title,
        &map_subtitle(grid, values, &scale),
        caption,
    );
    let height = frame.top_px()
        + frame.bottom_px()
        + scale.plot_h.max(MAP_MIN_BAR_H)
        + 2 * MAP_MARGIN
        + MAP_X_AREA;
    let pixels = std::cell::OnceCell::new();
    png_and_svg!(dir, values.stem, (MAP_WIDTH, height), |root| draw_map(
        &root, grid, origin_mm, values.bar, &scale, &frame, &pixels
    ))
}

/// Pixels per µm of height over pixels per µm of length in a profile plot of `x_span_mm`
/// across `plot_w` px and `z_span_um` across `plot_h` px.
fn vertical_exaggeration(x_span_mm: f64, z_span_um: f64, plot_w: u32, plot_h: u32) -> f64 {
    let per_um_x = plot_w as f64 / (x_span_mm * 1000.0);
    let per_um_z = plot_h as f64 / z_span_um;
    per_um_z / per_um_x
}

pub(super) fn exaggeration_note(e: f64) -> String {
    if (e - 1.0).abs() < 0.005 {
        "heights and lengths at the same scale".to_string()
    } else {
        format!(
            "heights exaggerated ×{} against lengths (µm vs mm axes)",
            crate::numfmt::sig(e, 2)
        )
    }
}

/// Figure size of a profile plot.
const PROFILE_SIZE: (u32, u32) = (1000, 520);
/// Figure size of a profile plot with its residual panel.
const PROFILE_WITH_RESIDUAL_SIZE: (u32, u32) = (1000, 680);

fn draw_overlay<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    measured: &[(f64, f64)],
    model: &[(f64, f64)],
    residual: &[(f64, f64)],
    title: &str,
    caption: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    // The x range is not padded: a profile starts and ends at its data.
    let xs = measured.iter().chain(model).chain(residual).map(|p| p.0);
    let (x0, x1) = min_max(&xs.filter(|x| x.is_finite()).collect::<Vec<_>>());
    let (x0, x1) = if x1 > x0 { (x0, x1) } else { (0.0, 1.0) };
    let (z0, z1) = padded_range(measured.iter().chain(model).map(|p| p.1), (-1.0, 1.0));
    let probe_frame = |subtitle: &str| Frame::new(root.dim_in_pixel().0, title, subtitle, caption);
    let (margin, x_area, y_area) = (CHART_MARGIN, CHART_X_AREA, 80u32);
    // With a residual panel the profile takes the upper 65 % of the body and names x only
    // once, below the residual.
    let share = |h: u32| if residual.is_empty() { h } else { h * 65 / 100 };
    let upper_x_area = if residual.is_empty() { x_area } else { 28 };
    let plot_size = |frame: &Frame| {
        let (w, h) = root.dim_in_pixel();
        let body = h.saturating_sub(frame.top_px() + frame.bottom_px());
        (
            w.saturating_sub(2 * margin + y_area),
            share(body).saturating_sub(2 * margin + upper_x_area),
        )
    };
    let first = probe_frame("measured points and the model's curve");
    let (pw, ph) = plot_size(&first);
    let e = vertical_exaggeration(x1 - x0, z1 - z0, pw, ph);
    // At the figure's resolution: each pixel column's first, last, lowest and highest.
    let measured = extremes_per_column(measured, (x0, x1), pw);
    let model = extremes_per_column(model, (x0, x1), pw);
    let residual = extremes_per_column(residual, (x0, x1), pw);
    let dots = if matches!(measured, std::borrow::Cow::Owned(_)) {
        "Dots: the measured heights (of each pixel column, the first, last, lowest and highest)"
    } else {
        "Dots: the measured heights"
    };
    let frame = probe_frame(&if residual.is_empty() {
        format!(
            "{dots}; line: the NURBS model evaluated between them; {}",
            exaggeration_note(e)
        )
    } else {
        format!(
            "{dots}; line: the NURBS model at this line; lower panel: model − measured at the measured x; {}",
            exaggeration_note(e)
        )
    });
    let body = frame.draw(root)?;
    let (upper, lower) = if residual.is_empty() {
        (body, None)
    } else {
        let (_, h) = body.dim_in_pixel();
        let (u, l) = body.split_vertically(share(h));
        (u, Some(l))
    };
    let mut chart = ChartBuilder::on(&upper)
        .margin(margin)
        .x_label_area_size(upper_x_area)
        .y_label_area_size(y_area)
        .build_cartesian_2d(x0..x1, z0..z1)
        .map_err(err)?;
    mesh(
        &mut chart,
        if residual.is_empty() { "x (mm)" } else { "" },
        "height (µm)",
    )
    .draw()
    .map_err(err)?;
    chart
        .draw_series(LineSeries::new(
            model.iter().copied(),
            MODEL.stroke_width(1),
        ))
        .map_err(err)?
        .label("NURBS model")
        .legend(line_key(MODEL.stroke_width(2)));
    chart
        .draw_series(
            measured
                .iter()
                .map(|&(x, z)| Circle::new((x, z), 2, DATA.filled())),
        )
        .map_err(err)?
        .label("measured")
        .legend(|(x, y)| Circle::new((x + 12, y), 3, DATA.filled()));
    legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    if let Some(lower) = lower {
        // Symmetric about zero, so the sign of a miss reads at a glance.
        let r = residual
            .iter()
            .map(|p| p.1.abs())
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max);
        let r = if r > 0.0 { 1.05 * r } else { 1.0 };
        let mut res = ChartBuilder::on(&lower)
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(x0..x1, -r..r)
            .map_err(err)?;
        mesh(&mut res, "x (mm)", "model − data (µm)")
            .y_labels(5)
            .draw()
            .map_err(err)?;
        res.draw_series(LineSeries::new(
            [(x0, 0.0), (x1, 0.0)],
            BLACK.stroke_width(1),
        ))
        .map_err(err)?;
        res.draw_series(LineSeries::new(
            residual.iter().copied(),
            MODEL.stroke_width(1),
        ))
        .map_err(err)?;
    }
    Ok(())
}

/// Writes `overlay.png` and `overlay.svg` into `dir`, the paper's Figure 2 made honest:
/// a line's measured heights as dots and the model's curve at that line, as `(x_mm, z_um)`
/// pairs, the height exaggeration stated; when `residual` (`(x_mm, model − measured µm)`) is
/// not empty, a panel below shows it. The caller says in `title` what the model is (the
/// report draws the surface refitted without this line, so the curve is a prediction, not an
/// interpolation through the dots). `caption` (may be empty) is the traceability footer.
pub fn plot_profile_overlay(
    dir: &Path,
    measured: &[(f64, f64)],
    model: &[(f64, f64)],
    residual: &[(f64, f64)],
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    let size = if residual.is_empty() {
        PROFILE_SIZE
    } else {
        PROFILE_WITH_RESIDUAL_SIZE
    };
    png_and_svg!(dir, "overlay", size, |root| draw_overlay(
        &root, measured, model, residual, title, caption
    ))
}

/// Figure size of the Rk construction.
const RK_SIZE: (u32, u32) = (1000, 560);
/// The height added above the Rk construction for the assessed profile.
const RK_PROFILE_H: u32 = 340;
/// Width of the Rk plot's side panel holding the values.
const RK_PANEL_W: u32 = 220;

/// A line's assessed profile as the report draws it above its Rk construction: the
/// evaluated ordinates (µm, about the mean line), their pitch, and the sampling lengths.
#[derive(Debug, Clone, Copy)]
pub struct AssessedProfile<'a> {
    /// The evaluated ordinates, evaluation length only.
    pub z_um: &'a [f64],
    /// Their pitch, mm.
    pub pitch_mm: f64,
    /// x of the first, mm, in the input's coordinates.
    pub x0_mm: f64,
    /// The sampling length, mm.
    pub sampling_length_mm: f64,
    /// How many sampling lengths the evaluation length holds.
    pub sampling_lengths: u32,
    /// `R` (roughness) or `P` (primary, form removed).
    pub kind: &'static str,
}

/// The assessed profile on `area`: the ordinates at display resolution (extremes kept), the
/// mean line, and the sampling lengths marked and numbered.
fn draw_assessed_profile<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &AssessedProfile<'_>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let length = p.z_um.len().saturating_sub(1) as f64 * p.pitch_mm;
    let (x0, x1) = (p.x0_mm, p.x0_mm + length);
    let (lo, hi) = padded_range(p.z_um.iter().copied(), (-1.0, 1.0));
    let mut chart = ChartBuilder::on(area)
        .margin(CHART_MARGIN)
        .x_label_area_size(CHART_X_AREA)
        .y_label_area_size(80)
        .caption(
            format!(
                "Assessed {} profile: {} sampling length{} of {} mm, evaluation length {} mm",
                p.kind,
                p.sampling_lengths,
                if p.sampling_lengths == 1 { "" } else { "s" },
                fmt(p.sampling_length_mm, Quantity::LengthMm),
                fmt(length, Quantity::LengthMm)
            ),
            font(14),
        )
        .build_cartesian_2d(x0..x0 + length.max(p.pitch_mm), lo..hi)
        .map_err(err)?;
    mesh(&mut chart, "x (mm)", "height (µm)")
        .draw()
        .map_err(err)?;
    let grey = RGBColor(110, 110, 110);
    chart
        .draw_series(LineSeries::new(
            [(x0, 0.0), (x1, 0.0)],
            grey.stroke_width(1),
        ))
        .map_err(err)?;
    let points = crate::report::sections::overlay::along_x(p.z_um, x0, p.pitch_mm);
    let columns = area.dim_in_pixel().0;
    chart
        .draw_series(LineSeries::new(
            extremes_per_column(&points, (x0, x1), columns)
                .iter()
                .copied(),
            DATA.stroke_width(1),
        ))
        .map_err(err)?;
    let tag = font(13).color(&grey);
    for k in 0..p.sampling_lengths {
        let from = x0 + f64::from(k) * p.sampling_length_mm;
        if k > 0 {
            chart
                .draw_series(DashedLineSeries::new(
                    [(from, lo), (from, hi)],
                    6,
                    4,
                    grey.stroke_width(1),
                ))
                .map_err(err)?;
        }
        chart
            .draw_series(std::iter::once(Text::new(
                format!("lr{}", k + 1),
                (from + 0.5 * p.sampling_length_mm, hi),
                tag.clone(),
            )))
            .map_err(err)?;
    }
    Ok(())
}

fn draw_rk<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    curve: &[[f64; 2]],
    rk: &RkFamily,
    profile: Option<&AssessedProfile<'_>>,
    title: &str,
    caption: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let (c, d) = (rk.upper_level_um, rk.lower_level_um);
    let frame = Frame::new(
        root.dim_in_pixel().0,
        title,
        "ISO 13565-2: the equivalent straight line is the 40 % secant of least gradient of the material ratio curve, extended to 0 % (level C) and 100 % (level D); the triangles have the areas A1 above C and A2 below D",
        caption,
    );
    let body = frame.draw(root)?;
    // The assessed profile above its construction, as an instrument prints them.
    let body = match profile {
        Some(p) => {
            let (_, h) = body.dim_in_pixel();
            let (top, rest) = body.split_vertically(h * 2 / 5);
            draw_assessed_profile(&top, p)?;
            rest
        }
        None => body,
    };
    let (bw, _) = body.dim_in_pixel();
    let (plot_area, panel) = body.split_horizontally(bw.saturating_sub(RK_PANEL_W));
    let heights = curve
        .iter()
        .map(|p| p[1])
        .chain([c + rk.rpk_um, d - rk.rvk_um, c, d]);
    let (lo, hi) = padded_range(heights, (-1.0, 1.0));
    let mut chart = chart(
        &plot_area,
        0f64..100f64,
        lo..hi,
        ("material ratio Rmr (%)", "height c (µm)"),
        &|v| tick(*v),
    )?;
    // Rpk and Rvk triangles (areas equal to A1 and A2).
    chart
        .draw_series(std::iter::once(Polygon::new(
            vec![(0.0, c), (0.0, c + rk.rpk_um), (rk.mr1_pct, c)],
            MODEL.mix(0.25).filled(),
        )))
        .map_err(err)?
        .label("Rpk triangle (area A1)")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 24, y + 5)], MODEL.mix(0.25).filled()));
    chart
        .draw_series(std::iter::once(Polygon::new(
            vec![(rk.mr2_pct, d), (100.0, d), (100.0, d - rk.rvk_um)],
            SECOND.mix(0.25).filled(),
        )))
        .map_err(err)?
        .label("Rvk triangle (area A2)")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 24, y + 5)], SECOND.mix(0.25).filled()));
    // Levels C and D, and Mr1, Mr2.
    let grey = RGBColor(110, 110, 110);
    for ends in [
        [(0.0, c), (100.0, c)],
        [(0.0, d), (100.0, d)],
        [(rk.mr1_pct, lo), (rk.mr1_pct, c)],
        [(rk.mr2_pct, lo), (rk.mr2_pct, d)],
    ] {
        chart
            .draw_series(DashedLineSeries::new(ends, 6, 4, grey.stroke_width(1)))
            .map_err(err)?;
    }
    // The material ratio curve.
    let columns = chart.plotting_area().dim_in_pixel().0;
    chart
        .draw_series(LineSeries::new(
            extremes_per_column_of_pairs(curve, (0.0, 100.0), columns),
            DATA.stroke_width(2),
        ))
        .map_err(err)?
        .label("material ratio curve of the line")
        .legend(line_key(DATA.stroke_width(2)));
    // The equivalent straight line, with the 40 % secant it is the extension of.
    chart
        .draw_series(LineSeries::new(
            [(0.0, c), (100.0, d)],
            MODEL.stroke_width(1),
        ))
        .map_err(err)?
        .label("equivalent straight line")
        .legend(line_key(MODEL.stroke_width(1)));
    let s = rk.secant_start_pct;
    let at = |mr: f64| c + (d - c) * mr / 100.0;
    chart
        .draw_series(LineSeries::new(
            [(s, at(s)), (s + 40.0, at(s + 40.0))],
            MODEL.stroke_width(4),
        ))
        .map_err(err)?
        .label("40 % secant of least gradient")
        .legend(line_key(MODEL.stroke_width(4)));
    let tag = font(13).color(&grey);
    for (text, x, y) in [
        ("C", 50.0, c),
        ("D", 50.0, d),
        ("Mr1", rk.mr1_pct, lo),
        ("Mr2", rk.mr2_pct, lo),
    ] {
        let (px, py) = chart.backend_coord(&(x, y));
        let (dx, dy) = if text.starts_with("Mr") {
            (3, -18)
        } else {
            (0, -17)
        };
        root.draw_text(text, &tag, (px + dx, py + dy))
            .map_err(err)?;
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    // The values, in the side panel.
    // The Rk family named, in units and digits, as the parameter table says; the levels C, D.
    let family = [
        ("Rk", rk.rk_um),
        ("Rpk", rk.rpk_um),
        ("Rvk", rk.rvk_um),
        ("Mr1", rk.mr1_pct),
        ("Mr2", rk.mr2_pct),
        ("A1", rk.a1_um_pct),
        ("A2", rk.a2_um_pct),
    ];
    let named = |(s, v): (&str, f64)| parameter(s).map(|t| (t.name, fmt(v, t.quantity), t.unit));
    let levels = [("C", c), ("D", d)].map(|(n, v)| (n, fmt(v, Quantity::HeightUm), "µm"));
    let rows = family.into_iter().filter_map(named).chain(levels);
    let mut y = 24;
    panel
        .draw_text("ISO 13565-2", &font(15), (10, y))
        .map_err(err)?;
    y += 28;
    for (name, value, unit) in rows {
        panel.draw_text(name, &font(14), (10, y)).map_err(err)?;
        let value_style = font(14);
        let (vw, _) = panel
            .estimate_text_size(&value, &value_style)
            .map_err(err)?;
        panel
            .draw_text(&value, &value_style, (140 - vw as i32, y))
            .map_err(err)?;
        panel.draw_text(unit, &font(14), (148, y)).map_err(err)?;
        y += 22;
    }
    Ok(())
}

/// Where a figure is written: `dir/stem.svg`, and `dir/stem.png` when `png` (else a PNG
/// there is removed).
#[allow(missing_docs)]
#[derive(Debug, Clone, Copy)]
pub struct FigureFiles<'a> {
    pub dir: &'a Path,
    pub stem: &'a str,
    pub png: bool,
}

/// Writes `STEM.png` and `STEM.svg` into `dir`: the ISO 13565-2 construction of one line —
/// its material ratio curve (`[mr_pct, height_um]` pairs, e.g. from
/// [`crate::metrology::params::rk_family_and_curve`]), the equivalent straight line and its 40 %
/// secant, the levels C and D, Mr1 and Mr2, and the Rpk/Rvk triangles — with the values in a
/// side panel, below the line's assessed profile with its sampling lengths when `profile` is
/// given. `caption` (may be empty) is the traceability footer. Without `to.png` only the
/// SVG is written (the PNG's path is still returned, first).
pub fn plot_rk_construction(
    to: FigureFiles<'_>,
    curve: &[[f64; 2]],
    rk: &RkFamily,
    profile: Option<&AssessedProfile<'_>>,
    title: &str,
    caption: &str,
) -> Result<[PathBuf; 2], MetrologyError> {
    let size = match profile {
        Some(_) => (RK_SIZE.0, RK_SIZE.1 + RK_PROFILE_H),
        None => RK_SIZE,
    };
    png_and_svg!(to.dir, to.stem, size, png: to.png, |root| draw_rk(
        &root, curve, rk, profile, title, caption
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thin_map_states_its_exaggeration_and_a_square_one_is_true_scale() {
        // The demo's 1.6 × 0.3 mm grid in a 776 px wide area: 145 px at true scale.
        let s = map_scale(1.6, 0.3, 776, 520, 160);
        assert_eq!(s.y_over_x, 2.0);
        assert_eq!(s.plot_w, 776);
        assert_eq!(s.plot_h, 291);
        assert!(map_note(&s).contains("y stretched ×2"), "{}", map_note(&s));
        let s = map_scale(1.0, 0.5, 776, 520, 160);
        assert_eq!((s.y_over_x, s.plot_h), (1.0, 388));
        assert_eq!(map_note(&s), "true scale: x and y drawn 1:1");
        // A tall grid: the x axis gets the exaggeration.
        let s = map_scale(0.01, 2.0, 776, 520, 160);
        assert_eq!(s.plot_h, 520);
        assert!(s.y_over_x < 1.0 && s.plot_w >= 160, "{s:?}");
        assert!(map_note(&s).contains("x stretched"), "{}", map_note(&s));
    }

    /// A 4 × 6 grid on 3 × 2 pixels: each pixel the mean of a 2 × 2 block, the top pixel row
    /// the last lines (y up); on 12 × 8 pixels each point fills a 2 × 2 block of pixels.
    #[test]
    fn a_map_pixel_is_the_mean_of_the_points_under_it_with_the_last_line_on_top() {
        #[rustfmt::skip]
        let z = [
            0.0, 0.0, 4.0, 4.0, 8.0, 8.0,
            0.0, 0.0, 4.0, 4.0, 8.0, 8.0,
            1.0, 3.0, 2.0, 2.0, 6.0, 10.0,
            3.0, 1.0, 2.0, 2.0, 6.0, 10.0,
        ];
        let grid = crate::metrology::areal::test_map(&z, 4, 6, 0.001, 0.001);
        let colour = |v: f64| {
            let RGBColor(r, g, b) = viridis(v / 10.0);
            [r, g, b]
        };
        let px = map_pixels(&grid, (3, 2), (0.0, 10.0));
        let want: Vec<u8> = [2.0, 2.0, 8.0, 0.0, 4.0, 8.0]
            .into_iter()
            .flat_map(colour)
            .collect();
        assert_eq!(px, want);
        assert!(map_is_averaged(&grid, (3, 2)));
        let fine = map_pixels(&grid, (12, 8), (0.0, 10.0));
        assert!(!map_is_averaged(&grid, (12, 8)));
        assert_eq!(fine.len(), 12 * 8 * 3);
        // Pixel (x 2, y 0): the last line's second point, 1.0; (x 11, y 7): the first line's
        // last point, 8.0.
        assert_eq!(&fine[2 * 3..2 * 3 + 3], &colour(1.0));
        assert_eq!(
            &fine[(7 * 12 + 11) * 3..(7 * 12 + 11) * 3 + 3],
            &colour(8.0)
        );
    }

    #[test]
    fn profile_exaggeration_is_pixels_per_micrometre_compared() {
        // 1 mm across 1000 px and 1 µm across 1 px: the same pixels per µm.
        assert!((vertical_exaggeration(1.0, 1.0, 1000, 1) - 1.0).abs() < 1e-12);
        // 1.6 mm across 800 px, 4 µm across 400 px: 100 px/µm against 0.5 px/µm.
        assert!((vertical_exaggeration(1.6, 4.0, 800, 400) - 200.0).abs() < 1e-9);
    }

    /// An Rk figure and texts at every anchor, turned, clipped, half and fully transparent.
    fn draw_test_figure<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>)
    where
        DB::ErrorType: 'static,
    {
        use plotters::style::text_anchor::{HPos, Pos, VPos};
        let z: Vec<f64> = (0..4000)
            .map(|k| (k as f64 * 0.013).sin() + 0.3 * (k as f64 * 0.37).cos())
            .collect();
        let (rk, curve) = crate::metrology::params::rk_family_and_curve(&z, 1001).unwrap();
        draw_rk(
            root,
            &curve,
            &rk,
            None,
            "Line 3 (0002, y = 0.02 mm): Rk",
            "specimen A · surfscan",
        )
        .unwrap();
        let turned = [
            FontTransform::None,
            FontTransform::Rotate90,
            FontTransform::Rotate270,
        ];
        for (k, t) in turned.into_iter().enumerate() {
            for (i, (hp, vp)) in [
                (HPos::Left, VPos::Top),
                (HPos::Center, VPos::Center),
                (HPos::Right, VPos::Bottom),
            ]
            .into_iter()
            .enumerate()
            {
                let colour = RGBColor(200, 30, 90).mix(0.5 + 0.25 * i as f64);
                let style = font(17)
                    .transform(t.clone())
                    .pos(Pos::new(hp, vp))
                    .color(&colour);
                let at = (40 + 300 * k as i32, 60 + 150 * i as i32);
                root.draw_text("µm Rk 0.1 % λc", &style, at).unwrap();
            }
        }
        // Partly off the figure, and invisible.
        let (w, h) = root.dim_in_pixel();
        root.draw_text("off the edge µ", &font(30), (w as i32 - 60, h as i32 - 10))
            .unwrap();
        root.draw_text("invisible", &font(30).color(&BLACK.mix(0.0)), (100, 100))
            .unwrap();
    }

    /// The test figure's RGB pixels, drawn on the plain bitmap or through the text memo.
    fn figure_pixels(cached: bool) -> Vec<u8> {
        ensure_font().unwrap();
        let (w, h) = RK_SIZE;
        let mut buf = vec![0u8; (w * h * 3) as usize];
        {
            let bitmap = BitMapBackend::with_buffer(&mut buf, (w, h));
            if cached {
                let root = TextCache::new(bitmap).into_drawing_area();
                draw_test_figure(&root);
                root.present().unwrap();
            } else {
                let root = bitmap.into_drawing_area();
                draw_test_figure(&root);
                root.present().unwrap();
            }
        }
        buf
    }

    /// Texts drawn from the memo, the first time and again, give the plain bitmap's pixels.
    #[test]
    fn the_text_memo_draws_the_plain_bitmaps_pixels() {
        let plain = figure_pixels(false);
        let first = figure_pixels(true);
        let again = figure_pixels(true);
        let differing = |a: &[u8]| a.iter().zip(&plain).filter(|(x, y)| x != y).count();
        assert_eq!(differing(&first), 0, "first use of the memo");
        assert_eq!(differing(&again), 0, "drawn from the memo");
        assert!(plain.iter().any(|&v| v != 255), "the figure drew something");
    }

    /// The test figure written as a figure is: its PNG and SVG through [`png_and_svg`].
    fn write_test_figure(dir: &Path) -> Result<[PathBuf; 2], MetrologyError> {
        png_and_svg!(dir, "test", RK_SIZE, |root| {
            draw_test_figure(&root);
            Ok(())
        })
    }

    /// The filter byte of every row of an 8-bit RGB PNG, read from its chunks.
    fn row_filters(png: &[u8]) -> Vec<u8> {
        let (mut at, mut idat, mut width) = (8, Vec::new(), 0usize);
        while at + 12 <= png.len() {
            let n = u32::from_be_bytes(png[at..at + 4].try_into().unwrap()) as usize;
            let (kind, data) = (&png[at + 4..at + 8], &png[at + 8..at + 8 + n]);
            if kind == b"IHDR" {
                width = u32::from_be_bytes(data[..4].try_into().unwrap()) as usize;
                assert_eq!(&data[8..10], &[8, 2], "8-bit RGB");
            } else if kind == b"IDAT" {
                idat.extend_from_slice(data);
            }
            at += 12 + n;
        }
        let raw = miniz_oxide::inflate::decompress_to_vec_zlib(&idat).unwrap();
        raw.chunks(1 + 3 * width).map(|row| row[0]).collect()
    }

    /// A figure's PNG holds the pixels plotters drew, as a decoder reads them back, every
    /// row Paeth-filtered (the encoding [`write_png`] chooses for speed).
    #[test]
    fn a_figures_png_holds_the_drawn_pixels_paeth_filtered() {
        let dir = tempfile::tempdir().unwrap();
        let [png, svg] = write_test_figure(dir.path()).unwrap();
        let decoded = image::open(&png).unwrap().to_rgb8();
        assert_eq!(decoded.dimensions(), RK_SIZE);
        let drawn = figure_pixels(false);
        let differing = decoded.as_raw().iter().zip(&drawn).filter(|(a, b)| a != b);
        assert_eq!(differing.count(), 0, "pixels differ from the drawn bitmap");
        let filters = row_filters(&std::fs::read(&png).unwrap());
        assert_eq!(filters.len(), RK_SIZE.1 as usize);
        assert!(filters.iter().all(|&f| f == 4), "{filters:?}");
        assert!(std::fs::read_to_string(svg).unwrap().contains("<svg"));
    }

    /// A figure is replaced whole, never rewritten in place: a reader that holds the previous
    /// files (here hard links to them) keeps them as they were, the new files are complete, and
    /// no temporary file is left beside them. Writing in place (`File::create` on the path)
    /// would truncate and rewrite the linked files.
    #[test]
    fn figures_are_replaced_whole_not_rewritten_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let keep = tempfile::tempdir_in(dir.path()).unwrap();
        let mut held = Vec::new();
        for name in ["test.png", "test.svg"] {
            let (path, link) = (dir.path().join(name), keep.path().join(name));
            std::fs::write(&path, b"the previous figure").unwrap();
            std::fs::hard_link(&path, &link).unwrap();
            held.push((path, link));
        }
        let [png, svg] = write_test_figure(dir.path()).unwrap();
        for (path, link) in &held {
            let old = std::fs::read(link).unwrap();
            assert!(
                old == b"the previous figure",
                "{link:?} was rewritten in place ({} bytes)",
                old.len()
            );
            assert!(std::fs::read(path).unwrap() != old, "{path:?} not replaced");
        }
        let decoded = image::open(&png).unwrap().to_rgb8();
        assert!(
            decoded.as_raw() == &figure_pixels(false),
            "PNG pixels differ"
        );
        // The SVG is plotters' own text, as its file target would have written it.
        let by_plotters = dir.path().join("by-plotters.svg");
        {
            let root = SVGBackend::new(&by_plotters, RK_SIZE).into_drawing_area();
            draw_test_figure(&root);
            root.present().unwrap();
        }
        let (ours, theirs) = (
            std::fs::read(&svg).unwrap(),
            std::fs::read(&by_plotters).unwrap(),
        );
        assert!(
            ours == theirs,
            "SVG of {} bytes, plotters' {}",
            ours.len(),
            theirs.len()
        );
        let mut names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        let keep_name = keep
            .path()
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let mut want = vec![
            "by-plotters.svg".to_string(),
            keep_name,
            "test.png".to_string(),
            "test.svg".to_string(),
        ];
        want.sort();
        assert_eq!(names, want);
    }

    /// A figure that cannot be written names its file.
    #[test]
    fn a_figure_that_cannot_be_written_names_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let gone = dir.path().join("no such directory");
        let e = write_test_figure(&gone).unwrap_err().to_string();
        assert!(e.contains("no such directory/test.png"), "{e}");
        assert!(e.contains("free space"), "{e}");
    }

    /// Renders `text` in the bundled font into a small RGB buffer.
    fn render(text: &str) -> Vec<u8> {
        ensure_font().unwrap();
        let mut buf = vec![255u8; 80 * 40 * 3];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (80, 40)).into_drawing_area();
            root.draw_text(text, &font(24), (5, 5)).unwrap();
            root.present().unwrap();
        }
        buf
    }

    #[test]
    fn the_bundled_font_draws_micro_and_lambda_not_a_missing_glyph_box() {
        let blank = vec![255u8; 80 * 40 * 3];
        // U+E000 is a private-use code point the font has no glyph for.
        let missing = render("\u{e000}");
        for text in ["µ", "λ", "·", "Å"] {
            let drawn = render(text);
            assert_ne!(drawn, blank, "{text} drew nothing");
            assert_ne!(drawn, missing, "{text} drew the missing-glyph box");
        }
        assert_ne!(render("µ"), render("λ"));
    }

    #[test]
    fn long_text_wraps_within_the_width() {
        ensure_font().unwrap();
        let style = font(FOOTER_PX);
        let text = "specimen A-17 · SJ-210 fw 2.00 (standard drive unit) · ISO1997 Gauss λc 0.8 mm λs 2.5 µm · scan 20250101T000000Z · surfscan 0.1.0 · and some more words to force a wrap";
        let lines = wrap(text, &style, 400);
        assert!(lines.len() >= 3, "{lines:?}");
        for l in &lines {
            assert!(text_width(l, &style) <= 400, "{l:?} is wider than 400 px");
        }
        assert_eq!(
            lines.join(" "),
            text.split_whitespace().collect::<Vec<_>>().join(" ")
        );
    }

    /// The remembered wrap is the wrap: on first and repeated use, at other sizes and widths,
    /// and after more distinct texts than the memo keeps.
    #[test]
    fn remembered_wrap_is_the_wrap() {
        ensure_font().unwrap();
        let text = "ISO 13565-2: the equivalent straight line is the 40 % secant of least gradient of the material ratio curve, extended to 0 % (level C) and 100 % (level D)";
        for round in 0..3 {
            for (px, width) in [
                (FOOTER_PX, 400),
                (SUBTITLE_PX, 400),
                (SUBTITLE_PX, 976),
                (TITLE_PX, 250),
            ] {
                assert_eq!(
                    wrapped(text, px, width),
                    wrap(text, &font(px), width),
                    "round {round}, {px} px, {width} px wide"
                );
            }
        }
        for k in 0..150 {
            let t = format!(
                "line {k} of the grid, y = {} mm: measured and model",
                k as f64 * 0.01
            );
            assert_eq!(
                wrapped(&t, TITLE_PX, 200),
                wrap(&t, &font(TITLE_PX), 200),
                "{t}"
            );
            assert_eq!(
                wrapped(&t, TITLE_PX, 200),
                wrap(&t, &font(TITLE_PX), 200),
                "{t}"
            );
        }
        assert_eq!(
            wrapped(text, FOOTER_PX, 400),
            wrap(text, &font(FOOTER_PX), 400)
        );
        assert!(wrapped(text, FOOTER_PX, 400).len() >= 2);
    }

    #[test]
    fn ticks_drop_insignificant_zeros_and_float_noise() {
        assert_eq!(tick(0.30000000000000004), "0.3");
        assert_eq!(tick(-1.3877787807814457e-17), "0");
        assert_eq!(tick(100.0), "100");
        assert_eq!(tick(-2.5), "-2.5");
        assert_eq!(tick(1.0e7), "1.000e7");
    }

    #[test]
    fn viridis_runs_from_dark_violet_to_yellow() {
        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(254, 232, 37));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
        assert_eq!(viridis(7.0), viridis(1.0));
        // Perceptual order: lightness (the green channel here) rises throughout.
        let g: Vec<u8> = (0..=10).map(|k| viridis(k as f64 / 10.0).1).collect();
        assert!(g.windows(2).all(|w| w[0] < w[1]), "{g:?}");
    }
}
