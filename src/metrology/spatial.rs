//! ISO 25178-2 spatial parameters of a levelled height grid (Sal, Str, Std) and the curves
//! behind them: the areal autocorrelation function and the power spectral densities along x
//! and y.
//!
//! **Autocorrelation.** f_ACF(τx, τy) of the plane-levelled heights, the unbiased linear
//! estimator: the sum of z(x, y)·z(x + τx, y + τy) over the pairs inside the grid divided by
//! their number (no wrap-around), by a zero-padded FFT; normalised to 1 at zero lag.
//!
//! **Sal and Str** (s = 0.2, ISO 25178-3's default). Along rays from zero lag every 0.5°
//! (the function is point-symmetric, so 0° ≤ θ < 180°), the ACF interpolated bilinearly
//! between lags is followed outwards in steps of a quarter of the finer pitch until it first
//! falls below s; the crossing is interpolated linearly. Sal is the shortest of those decay
//! lengths, Str the shortest over the longest. A ray that leaves the lags the grid holds
//! before decaying has no length: Sal is then the shortest of the others (none: blank, with
//! the reason), and Str is blank with the reason (its slowest decay is not in the field).
//!
//! **Std** is the angle of the largest value of the angular amplitude spectrum, in degrees
//! counter-clockwise from the +x axis with y increasing along the scan (ISO 25178-2:2021,
//! 4.3.4 with the angular amplitude density): the |DFT| of the levelled heights summed into
//! 0.5° bins of the frequency direction, folded into [0°, 180°), each bin named by its lower
//! edge. It is the direction of the dominant spatial frequency; the lay runs perpendicular to
//! it.
//!
//! **PSD along x (y).** Each line (column) windowed by the periodic Hann window scaled to mean
//! square 1, C(q) = |Δx·DFT(z)|² / L with L = n·Δx, the ±q branches averaged, q = 2πk/L, then
//! averaged over the lines (columns); heights in µm, q in 1/µm, C in µm³ — the convention of
//! SurfaceTopography's `power_spectrum_from_profile`.
//!
//! **The curves behind them** ([`SpatialCurves`], for the report's figures, not in
//! `report.json`): the ACF sampled along the fastest and the slowest decay directions (from
//! zero lag to five times the longer decay length, or the field's edge) and both PSDs.
//!
//! Memory: the ACF's lags ky ≥ 0 only (the rays of Sal and Str read no others), made in one
//! buffer of about 2·rows·cols f64 by real-to-complex transforms (see [`autocorrelation`]);
//! Std's spectrum is the lines' half spectra, rows·(cols/2 + 1) complex values. They and
//! the PSDs read the lines (columns) levelled as they go ([`Plane::level_row`]): no
//! levelled copy of the grid.
//!
//! Depends on [`super::areal`] (levelling), [`super::filter`] (FFT lengths),
//! [`super::MetrologyError`] and the FFT crates (`realfft`, `rustfft`, `bytemuck` to view
//! one buffer as both).

use super::areal::{HeightMap, Plane};
use super::filter::fft_len;
use super::MetrologyError;
use realfft::RealFftPlanner;
use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;
use serde::Serialize;
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::f64::consts::PI;

/// The ACF threshold s of Sal and Str (ISO 25178-3 default).
pub const S_THRESHOLD: f64 = 0.2;
/// Angular step of the decay rays and of Std's bins, degrees.
pub const ANGLE_STEP_DEG: f64 = 0.5;

/// The areal autocorrelation function, normalised to 1 at zero lag.
#[derive(Debug, Clone, PartialEq)]
pub struct Acf {
    /// Values at the lags ky ≥ 0 (the function is point-symmetric, f(−τ) = f(τ)),
    /// `rows × (2·cols − 1)` row-major; zero lag at `(0, cols − 1)`.
    pub values: Vec<f64>,
    /// Lines of the grid (lags −(rows − 1) … rows − 1 along y).
    pub rows: usize,
    /// Points per line (lags −(cols − 1) … cols − 1 along x).
    pub cols: usize,
    /// Lag step along x, µm.
    pub pitch_x_um: f64,
    /// Lag step along y, µm.
    pub pitch_y_um: f64,
}

impl Acf {
    /// The value at integer lags (ky, kx), `None` outside the grid's lags.
    pub fn at(&self, ky: isize, kx: isize) -> Option<f64> {
        let (r, c) = (self.rows as isize, self.cols as isize);
        if ky.abs() >= r || kx.abs() >= c {
            return None;
        }
        // f(−τ) = f(τ): the lags ky < 0 are those of (−ky, −kx).
        let (ky, kx) = if ky < 0 { (-ky, -kx) } else { (ky, kx) };
        self.values
            .get((ky * (2 * c - 1) + kx + c - 1) as usize)
            .copied()
    }

    /// Bilinear interpolation at the lag (τx, τy ≥ 0) in µm; `None` outside the lags held.
    pub fn interpolate(&self, tx_um: f64, ty_um: f64) -> Option<f64> {
        let fx = tx_um / self.pitch_x_um;
        let fy = ty_um / self.pitch_y_um;
        let (mx, my) = ((self.cols - 1) as f64, (self.rows - 1) as f64);
        if !(fx.abs() <= mx && fy.abs() <= my) {
            return None;
        }
        // ⌊f⌋ without a library call: truncated, and one less where that is above f.
        let floor = |f: f64| f as isize - isize::from((f as isize) as f64 > f);
        let (x0, y0) = (floor(fx), floor(fy));
        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
        // Corners (y0, x0) … (y0 + 1, x0 + 1); one of weight 0 is not read (may lie outside).
        let w = 2 * self.cols - 1;
        let first = usize::try_from(y0).ok()? * w + (x0 + self.cols as isize - 1) as usize;
        let v = |i: usize, weight: f64| {
            if weight == 0.0 {
                Some(0.0)
            } else {
                self.values.get(first + i).map(|a| a * weight)
            }
        };
        Some(
            v(0, (1.0 - tx) * (1.0 - ty))?
                + v(1, tx * (1.0 - ty))?
                + v(w, (1.0 - tx) * ty)?
                + v(w + 1, tx * ty)?,
        )
    }
}

/// Sal, Str and Std of a grid, with what limits them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpatialParams {
    /// Autocorrelation length (fastest decay to s), µm; `None` when the ACF decays to s in no
    /// direction within the field (`blank_reasons` says so).
    #[serde(rename = "Sal_um")]
    pub sal_um: Option<f64>,
    /// Texture aspect ratio, fastest over slowest decay length; `None` when some direction
    /// does not decay to s within the field.
    #[serde(rename = "Str")]
    pub str_ratio: Option<f64>,
    /// Texture direction, degrees in [0, 180).
    #[serde(rename = "Std_deg")]
    pub std_deg: f64,
    /// The threshold s.
    pub s: f64,
    /// Direction of the fastest decay, degrees from +x.
    pub fastest_decay_direction_deg: Option<f64>,
    /// Direction of the slowest decay, degrees from +x, when every direction decays.
    pub slowest_decay_direction_deg: Option<f64>,
    /// The longest decay length, µm, when every direction decays.
    pub slowest_decay_um: Option<f64>,
    /// Why a value is blank, by parameter name.
    pub blank_reasons: BTreeMap<String, String>,
    /// What limits the values on this grid, in words.
    pub caveats: Vec<String>,
    /// Definition id per parameter.
    pub definitions: BTreeMap<String, String>,
    /// The ACF sections and PSDs the report draws (not in `report.json`).
    #[serde(skip)]
    pub curves: SpatialCurves,
}

/// The ACF through zero lag along one direction.
#[derive(Debug, Clone, PartialEq)]
pub struct AcfSection {
    /// Direction, degrees counter-clockwise from +x.
    pub direction_deg: f64,
    /// `[lag_um, f_ACF]` from zero lag outwards, [`SECTION_POINTS`] + 1 at most.
    pub points: Vec<[f64; 2]>,
    /// Where the ACF first falls below s along it, µm (`None`: not within the field).
    pub decay_um: Option<f64>,
}

/// The curves behind Sal, Str and Std, for the figures.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SpatialCurves {
    /// Along the fastest decay (Sal's direction); `None` when the ACF decays in no direction.
    pub fastest: Option<AcfSection>,
    /// Along the slowest decay (Str's), or the first direction that does not decay within
    /// the field; `None` when that is the fastest's.
    pub slowest: Option<AcfSection>,
    /// PSD along x, averaged over the lines.
    pub psd_x: Psd,
    /// PSD along y, averaged over the columns.
    pub psd_y: Psd,
}

/// Samples of an ACF section beyond zero lag.
pub const SECTION_POINTS: usize = 1024;

/// The ACF along `deg` from zero lag to `range_um` (or the field's edge), sampled evenly.
fn section(acf: &Acf, deg: f64, range_um: f64, decay_um: Option<f64>) -> AcfSection {
    let (ct, st) = (deg.to_radians().cos(), deg.to_radians().sin());
    let points = (0..=SECTION_POINTS)
        .map_while(|k| {
            let t = range_um * k as f64 / SECTION_POINTS as f64;
            acf.interpolate(t * ct, t * st).map(|v| [t, v])
        })
        .collect();
    AcfSection {
        direction_deg: deg,
        points,
        decay_um,
    }
}

/// The definition ids of the spatial parameters.
pub fn definitions() -> BTreeMap<String, String> {
    #[rustfmt::skip]
    let more = [
        ("ACF", "ISO25178-2/f_ACF unbiased linear estimator (sum over overlapping pairs / their number, zero-padded FFT) of the plane-levelled grid, normalised to 1 at zero lag"),
        ("PSD", "1D PSD along x (y): periodic Hann window scaled to mean square 1, C(q) = |dx DFT|^2 / L, +-q averaged, mean over lines (columns), um^3 vs q = 2 pi k / L in 1/um (SurfaceTopography's convention)"),
    ];
    super::parameter_table::areal_definitions("spatial", &more)
}

/// Each column of `lines` (equal-length slices, one a row, column `first_col` of the data
/// at their index 0) run through `f` in a `len`-long buffer, zero beyond the column's
/// values; written back (the first `lines.len()` values) when `write_back`. A few adjacent
/// columns are gathered at a time, so each row's cache line is read once per block rather
/// than once per column.
fn along_columns(
    lines: &mut [&mut [Complex64]],
    first_col: usize,
    len: usize,
    write_back: bool,
    mut f: impl FnMut(usize, &mut [Complex64]),
) {
    const BLOCK: usize = 8;
    let (rows, width) = (lines.len(), lines.first().map_or(0, |l| l.len()));
    let mut block = vec![Complex64::default(); BLOCK * len];
    for k0 in (0..width).step_by(BLOCK) {
        let n = BLOCK.min(width - k0);
        for (r, line) in lines.iter().enumerate() {
            for (b, v) in line[k0..k0 + n].iter().enumerate() {
                block[b * len + r] = *v;
            }
        }
        for (b, column) in block.chunks_exact_mut(len).take(n).enumerate() {
            column[rows..].fill(Complex64::default());
            f(first_col + k0 + b, column);
        }
        if write_back {
            for (r, line) in lines.iter_mut().enumerate() {
                for (b, v) in line[k0..k0 + n].iter_mut().enumerate() {
                    *v = block[b * len + r];
                }
            }
        }
    }
}

/// The half spectrum of each line of `grid` levelled by `plane` and zero-padded to `r2c`'s
/// length, into `spectra` (one after the other); `in_place`: each line read from the start of
/// its spectrum's place, not from `grid`. The lines are split between two threads, each with
/// its own buffers: the same transforms of the same values, the same bits.
fn line_spectra(
    grid: &HeightMap<'_>,
    plane: &Plane,
    r2c: &dyn realfft::RealToComplex<f64>,
    spectra: &mut [Complex64],
    in_place: bool,
) {
    let (cols, nk) = (grid.cols, r2c.complex_len());
    let lines_of = |first: usize, spectra: &mut [Complex64]| {
        let mut line = r2c.make_input_vec();
        let mut scratch = r2c.make_scratch_vec();
        for (r, spectrum) in (first..).zip(spectra.chunks_exact_mut(nk)) {
            let heights = match in_place {
                true => &bytemuck::cast_slice(spectrum)[..cols],
                false => &grid.heights_um[r * cols..(r + 1) * cols],
            };
            plane.level_row(r, heights, &mut line[..cols]);
            line[cols..].fill(0.0);
            r2c.process_with_scratch(&mut line, spectrum, &mut scratch)
                .expect("buffer sizes come from the plan");
        }
    };
    let half = grid.rows / 2;
    let (top, bottom) = spectra.split_at_mut(half * nk);
    std::thread::scope(|s| {
        s.spawn(|| lines_of(0, top));
        lines_of(half, bottom);
    });
}

/// The areal autocorrelation function of `grid` after plane levelling.
pub fn autocorrelation(grid: &HeightMap<'_>) -> Result<Acf, MetrologyError> {
    Ok(acf_of_levelled(
        grid.heights_um.to_vec(),
        grid,
        &Plane::of(grid)?,
    ))
}

/// The ACF at lags ky ≥ 0 by a real-to-complex FFT of each line zero-padded to a 5-smooth
/// length ≥ 2·cols − 1, a complex FFT along y padded likewise, the power, the inverse along
/// y (keeping ky < rows) and a complex-to-real inverse along x. One f64 buffer holds the
/// lines' half spectra, then in place their autocorrelation along y, then the values: about
/// 2·rows·cols f64, where the full padded complex 2-D transform took eight times that. The
/// lines are levelled by `plane` as they are read. That buffer is `heights` (of a grid shaped
/// as `grid`) grown in place, each line moved to its spectrum's place: they are not held
/// beside it.
fn acf_of_levelled(mut buf: Vec<f64>, grid: &HeightMap<'_>, plane: &Plane) -> Acf {
    let (rows, cols) = (grid.rows, grid.cols);
    let (pr, pc) = (fft_len(2 * rows - 1), fft_len(2 * cols - 1));
    let nk = pc / 2 + 1;
    let mut real = RealFftPlanner::<f64>::new();
    let (r2c, c2r) = (real.plan_fft_forward(pc), real.plan_fft_inverse(pc));
    let mut complex = FftPlanner::<f64>::new();
    let (fwd, inv) = (complex.plan_fft_forward(pr), complex.plan_fft_inverse(pr));
    let mut scratch = vec![
        Complex64::default();
        r2c.get_scratch_len()
            .max(c2r.get_scratch_len())
            .max(fwd.get_inplace_scratch_len())
            .max(inv.get_inplace_scratch_len())
    ];
    let scratch_len = scratch.len();
    let mut line = vec![0.0; pc];
    buf.resize(rows * 2 * nk, 0.0);
    // Last line first: each moves later (2·nk > cols), over no line still to be moved.
    for r in (0..rows).rev() {
        buf.copy_within(r * cols..(r + 1) * cols, r * 2 * nk);
    }
    {
        // Both passes split their independent transforms (lines, then columns) between two
        // threads, each with its own small buffers: the same transforms of the same values,
        // the same bits, in about half the wall time on two cores.
        let spectra: &mut [Complex64] = bytemuck::cast_slice_mut(&mut buf);
        line_spectra(grid, plane, r2c.as_ref(), spectra, true);
        let columns_of = |first: usize, lines: &mut [&mut [Complex64]]| {
            let mut scratch = vec![Complex64::default(); scratch_len];
            along_columns(lines, first, pr, true, |_, column| {
                fwd.process_with_scratch(column, &mut scratch);
                column
                    .iter_mut()
                    .for_each(|v| *v = Complex64::new(v.norm_sqr(), 0.0));
                inv.process_with_scratch(column, &mut scratch);
            });
        };
        let half = nk / 2;
        let (mut left, mut right): (Vec<&mut [Complex64]>, Vec<&mut [Complex64]>) = spectra
            .chunks_exact_mut(nk)
            .map(|l| l.split_at_mut(half))
            .unzip();
        std::thread::scope(|s| {
            s.spawn(|| columns_of(0, &mut left));
            columns_of(half, &mut right);
        });
    }
    // Row ky of the values, (2·cols − 1) long, ends before row ky + 1 of the spectra starts
    // (2·nk ≥ 2·cols + 1): each row is copied out before its place is written.
    let scale = 1.0 / (pr * pc) as f64;
    let w = 2 * cols - 1;
    let mut row = vec![Complex64::default(); nk];
    for ky in 0..rows {
        row.copy_from_slice(&bytemuck::cast_slice::<f64, Complex64>(&buf)[ky * nk..(ky + 1) * nk]);
        // Real input has real DC and Nyquist terms; rounding leaves a trace of imaginary
        // part that the inverse real FFT refuses.
        row[0].im = 0.0;
        row[nk - 1].im = 0.0;
        c2r.process_with_scratch(&mut row, &mut line, &mut scratch)
            .expect("buffer sizes come from the plan");
        for (i, v) in buf[ky * w..(ky + 1) * w].iter_mut().enumerate() {
            let kx = i as isize - (cols as isize - 1);
            let pairs = (rows - ky) * (cols - kx.unsigned_abs());
            *v = line[kx.rem_euclid(pc as isize) as usize] * scale / pairs as f64;
        }
    }
    buf.truncate(rows * w);
    buf.shrink_to_fit();
    let zero = buf.get(cols - 1).copied().unwrap_or(0.0);
    if zero > 0.0 {
        buf.iter_mut().for_each(|v| *v /= zero);
    }
    Acf {
        values: buf,
        rows,
        cols,
        pitch_x_um: grid.pitch_x_mm * 1000.0,
        pitch_y_um: grid.pitch_y_mm * 1000.0,
    }
}

/// The decay length along the ray at `theta` (radians) to `s`, µm; `None` when the ray leaves
/// the lags before the ACF falls below `s`.
fn decay_length(acf: &Acf, theta: f64, s: f64) -> Option<f64> {
    let (ct, st) = (theta.cos(), theta.sin());
    let step = 0.25 * acf.pitch_x_um.min(acf.pitch_y_um);
    let (mut t_prev, mut v_prev) = (0.0, 1.0);
    let mut k = 1u64;
    loop {
        let t = k as f64 * step;
        let v = acf.interpolate(t * ct, t * st)?;
        if v < s {
            return Some(t_prev + (v_prev - s) / (v_prev - v) * (t - t_prev));
        }
        (t_prev, v_prev) = (t, v);
        k += 1;
    }
}

/// The angular amplitude spectrum's maximum: Std in degrees (lower edge of its 0.5° bin).
/// The DFT of real heights is Hermitian: each line's real-to-complex half spectrum holds
/// every value, and each stands for itself and for its conjugate partner at (−fy, −fx).
fn texture_direction(grid: &HeightMap<'_>, plane: &Plane) -> f64 {
    let (rows, cols) = (grid.rows, grid.cols);
    let nk = cols / 2 + 1;
    let r2c = RealFftPlanner::<f64>::new().plan_fft_forward(cols);
    let fwd = FftPlanner::<f64>::new().plan_fft_forward(rows);
    let mut scratch = vec![Complex64::default(); fwd.get_inplace_scratch_len()];
    let mut spectra = vec![Complex64::default(); rows * nk];
    line_spectra(grid, plane, r2c.as_ref(), &mut spectra, false);
    let freq = |k: usize, n: usize, d: f64| {
        (k as f64 - if k < n.div_ceil(2) { 0.0 } else { n as f64 }) / (n as f64 * d)
    };
    let bins = (180.0 / ANGLE_STEP_DEG) as usize;
    let bin = |r: usize, c: usize| {
        let fy = freq(r, rows, grid.pitch_y_mm);
        let fx = freq(c, cols, grid.pitch_x_mm);
        let t = fy.atan2(fx).to_degrees();
        // rem_euclid(180.0) without fmod for |t| < 180° (t + 0 turns −0 to 0: the same bin).
        let theta = if t.abs() < 180.0 {
            t + if t < 0.0 { 180.0 } else { 0.0 }
        } else {
            t.rem_euclid(180.0)
        };
        ((theta / ANGLE_STEP_DEG) as usize).min(bins - 1)
    };
    let mut spectrum = vec![0.0; bins];
    let mut lines: Vec<&mut [Complex64]> = spectra.chunks_exact_mut(nk).collect();
    along_columns(&mut lines, 0, rows, false, |c, column| {
        fwd.process_with_scratch(column, &mut scratch);
        // Columns 0 and cols/2 are their own partners; the others' lie outside the half.
        let partner_outside = c != 0 && 2 * c != cols;
        for (r, v) in column.iter().enumerate() {
            if r == 0 && c == 0 {
                continue;
            }
            let a = v.norm();
            spectrum[bin(r, c)] += a;
            if partner_outside {
                spectrum[bin((rows - r) % rows, cols - c)] += a;
            }
        }
    });
    let mut best = (0, f64::NEG_INFINITY);
    for (i, &v) in spectrum.iter().enumerate() {
        if v > best.1 {
            best = (i, v);
        }
    }
    best.0 as f64 * ANGLE_STEP_DEG
}

/// Sal, Str and Std of `heights` in the shape of `grid` (whose own heights are not read),
/// levelled by `plane` ([`Plane::of`] them, which checks them). The PSDs and Std come first,
/// then the ACF grows its buffer from `heights` in place: owned (a model sampled for them),
/// they are never held beside it; borrowed, they are copied then.
pub fn spatial_params(
    heights: Cow<'_, [f64]>,
    grid: &HeightMap<'_>,
    plane: &Plane,
) -> SpatialParams {
    let map = &HeightMap {
        heights_um: &heights,
        ..*grid
    };
    let (psd_x, psd_y) = (psd_along_x(map, plane), psd_along_y(map, plane));
    let std_deg = texture_direction(map, plane);
    let acf = acf_of_levelled(heights.into_owned(), grid, plane);
    let rays = (180.0 / ANGLE_STEP_DEG) as usize;
    let lengths: Vec<(f64, Option<f64>)> = (0..rays)
        .map(|i| {
            let deg = i as f64 * ANGLE_STEP_DEG;
            (deg, decay_length(&acf, deg.to_radians(), S_THRESHOLD))
        })
        .collect();
    let (dx, dy) = (acf.pitch_x_um, acf.pitch_y_um);
    let decayed = lengths.iter().filter_map(|(d, l)| l.map(|l| (*d, l)));
    let fastest = decayed
        .clone()
        .fold(None, |b: Option<(f64, f64)>, (d, l)| match b {
            Some((_, bl)) if bl <= l => b,
            _ => Some((d, l)),
        });
    let slowest = decayed.fold(None, |b: Option<(f64, f64)>, (d, l)| match b {
        Some((_, bl)) if bl >= l => b,
        _ => Some((d, l)),
    });
    let undecayed: Vec<f64> = lengths
        .iter()
        .filter(|(_, l)| l.is_none())
        .map(|p| p.0)
        .collect();
    let mut blank_reasons = BTreeMap::new();
    let mut caveats = Vec::new();
    let (wx, wy) = ((grid.cols - 1) as f64 * dx, (grid.rows - 1) as f64 * dy);
    if fastest.is_none() {
        blank_reasons.insert(
            "Sal".to_string(),
            format!("the autocorrelation does not fall to s = {S_THRESHOLD} in any direction within the field ({wx:.1} × {wy:.1} µm of lags): the field is too small for the correlation length"),
        );
    }
    let str_ratio = match (fastest, slowest, undecayed.first()) {
        (Some((_, f)), Some((_, s)), None) if s > 0.0 => Some(f / s),
        (_, _, Some(first)) => {
            blank_reasons.insert(
                "Str".to_string(),
                format!(
                    "the autocorrelation does not fall to s = {S_THRESHOLD} within the field in {} of {rays} directions (from {first}°): the slowest decay is longer than the field",
                    undecayed.len()
                ),
            );
            None
        }
        _ => None,
    };
    // The sections drawn: to five times the longer decay, or to the field's edge when a
    // direction does not decay within it.
    let slowest_drawn = match (str_ratio, undecayed.first()) {
        (Some(_), _) => slowest.map(|(d, l)| (d, Some(l))),
        (None, Some(first)) => Some((*first, None)),
        (None, None) => None,
    };
    let range_um = match slowest_drawn {
        Some((_, Some(l))) => 5.0 * l,
        _ => wx.hypot(wy),
    };
    let curves = SpatialCurves {
        fastest: fastest.map(|(d, l)| section(&acf, d, range_um, Some(l))),
        slowest: slowest_drawn
            .filter(|(d, _)| fastest.is_none_or(|(f, _)| f != *d))
            .map(|(d, l)| section(&acf, d, range_um, l)),
        psd_x,
        psd_y,
    };
    if let Some((_, sal)) = fastest {
        if sal < dy && dy > 2.0 * dx {
            caveats.push(format!(
                "Sal {sal:.2} µm is shorter than the line spacing {dy:.2} µm: the lines are barely correlated and the decay across them is interpolated between adjacent lines, so Sal and Str are limited by the line spacing, not measured"
            ));
        }
    }
    SpatialParams {
        sal_um: fastest.map(|(_, l)| l),
        str_ratio,
        std_deg,
        s: S_THRESHOLD,
        fastest_decay_direction_deg: fastest.map(|(d, _)| d),
        slowest_decay_direction_deg: str_ratio.and(slowest.map(|(d, _)| d)),
        slowest_decay_um: str_ratio.and(slowest.map(|(_, l)| l)),
        blank_reasons,
        caveats,
        definitions: definitions(),
        curves,
    }
}

/// A one-dimensional power spectral density averaged over profiles.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Psd {
    /// Wavevectors q = 2πk/L, 1/µm (k = 0 … n/2 − 1).
    pub q_per_um: Vec<f64>,
    /// C(q), µm³.
    pub c_um3: Vec<f64>,
}

/// The PSD along x, averaged over the lines of `grid` levelled by `plane` as they are read.
pub fn psd_along_x(grid: &HeightMap<'_>, plane: &Plane) -> Psd {
    let cols = grid.cols;
    psd_of_profiles(grid.rows, cols, grid.pitch_x_mm * 1000.0, |r, out| {
        plane.level_row(r, &grid.heights_um[r * cols..(r + 1) * cols], out)
    })
}

/// The PSD along y, averaged over the columns of `grid` levelled by `plane` as they are read.
pub fn psd_along_y(grid: &HeightMap<'_>, plane: &Plane) -> Psd {
    psd_of_profiles(grid.cols, grid.rows, grid.pitch_y_mm * 1000.0, |c, out| {
        for (r, o) in out.iter_mut().enumerate() {
            *o = plane.level_at(r, c, grid.heights_um[r * grid.cols + c]);
        }
    })
}

/// The mean PSD of `count` profiles of `n` heights at `pitch_um`, profile `i` levelled into
/// its buffer by `profile(i, buffer)` as it is read: no levelled copy of the grid.
fn psd_of_profiles(
    count: usize,
    n: usize,
    pitch_um: f64,
    mut profile: impl FnMut(usize, &mut [f64]),
) -> Psd {
    if n < 2 || count == 0 {
        return Psd::default();
    }
    // Periodic Hann, scaled to mean square 1.
    let mut window: Vec<f64> = (0..n)
        .map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / n as f64).cos())
        .collect();
    let norm = (n as f64 / window.iter().map(|w| w * w).sum::<f64>()).sqrt();
    window.iter_mut().for_each(|w| *w *= norm);
    let length = n as f64 * pitch_um;
    let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
    let half = n / 2;
    let mut sum = vec![0.0; half];
    let mut buf = vec![Complex64::new(0.0, 0.0); n];
    let mut scratch = vec![Complex64::new(0.0, 0.0); fft.get_inplace_scratch_len()];
    let mut p = vec![0.0; n];
    for i in 0..count {
        profile(i, &mut p);
        for ((b, z), w) in buf.iter_mut().zip(&p).zip(&window) {
            *b = Complex64::new(z * w * pitch_um, 0.0);
        }
        fft.process_with_scratch(&mut buf, &mut scratch);
        let raw = |k: usize| buf.get(k).map_or(0.0, |v| v.norm_sqr()) / length;
        for (k, s) in sum.iter_mut().enumerate() {
            *s += if k == 0 {
                raw(0)
            } else {
                0.5 * (raw(k) + raw(n - k))
            };
        }
    }
    let count = count as f64;
    Psd {
        q_per_um: (0..half).map(|k| 2.0 * PI * k as f64 / length).collect(),
        c_um3: sum.into_iter().map(|s| s / count).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrology::areal::{level_plane, test_map};

    /// The FFT estimator equals the direct sum over the overlapping pairs.
    #[test]
    fn the_acf_is_the_unbiased_sum_over_overlapping_pairs() {
        let (rows, cols) = (5usize, 13usize);
        let z: Vec<f64> = (0..rows * cols)
            .map(|k| ((k * 37 % 11) as f64 - 5.0) * 0.3 + (k as f64 * 0.7).sin())
            .collect();
        let g = test_map(&z, rows, cols, 0.001, 0.002);
        let acf = autocorrelation(&g).unwrap();
        let (l, _) = level_plane(&g).unwrap();
        let at = |r: isize, c: isize| l[(r as usize) * cols + c as usize];
        let direct = |ky: isize, kx: isize| {
            let (mut s, mut n) = (0.0, 0.0);
            for r in 0..rows as isize {
                for c in 0..cols as isize {
                    let (r2, c2) = (r + ky, c + kx);
                    if r2 >= 0 && r2 < rows as isize && c2 >= 0 && c2 < cols as isize {
                        s += at(r, c) * at(r2, c2);
                        n += 1.0;
                    }
                }
            }
            s / n
        };
        let zero = direct(0, 0);
        for ky in -4..=4 {
            for kx in -12..=12 {
                let want = direct(ky, kx) / zero;
                let got = acf.at(ky, kx).unwrap();
                assert!((got - want).abs() < 1e-12, "({ky},{kx}) {got} vs {want}");
            }
        }
    }

    /// Ridges along y (z = cos(2πx/λ)): the ACF along x is cos(2πτ/λ)-like and falls to 0.2
    /// at τ = λ·acos(0.2)/2π, while along y it never decays: Sal is that length, Str is blank,
    /// Std is 0° (the frequency points along x; the lay runs along y).
    #[test]
    fn ridges_along_y_decay_along_x_only() {
        let (rows, cols, px, py) = (21usize, 400usize, 0.001, 0.002);
        let lambda_um = 50.0;
        let z: Vec<f64> = (0..rows * cols)
            .map(|k| (2.0 * PI * (k % cols) as f64 * px * 1000.0 / lambda_um).cos())
            .collect();
        let g = test_map(&z, rows, cols, px, py);
        let p = spatial_params(g.heights_um.into(), &g, &Plane::of(&g).unwrap());
        let want = lambda_um * 0.2f64.acos() / (2.0 * PI);
        let sal = p.sal_um.unwrap();
        assert!((sal - want).abs() < 0.02 * want, "Sal {sal} vs {want}");
        assert_eq!(p.fastest_decay_direction_deg, Some(0.0));
        assert!(
            p.str_ratio.is_none() && p.blank_reasons.contains_key("Str"),
            "{p:?}"
        );
        assert_eq!(p.std_deg, 0.0);
    }

    /// A plane wave with 7 periods along x and 4 along y of a square field: its frequency
    /// points at atan(4/7) = 29.74°, in the bin from 29.5°.
    #[test]
    fn std_finds_the_direction_of_a_plane_wave() {
        let (rows, cols, p) = (128usize, 128usize, 0.001);
        let (fx, fy) = (7.0 / 128.0, 4.0 / 128.0);
        let z: Vec<f64> = (0..rows * cols)
            .map(|k| {
                let (r, c) = ((k / cols) as f64, (k % cols) as f64);
                (2.0 * PI * (fx * c + fy * r)).cos()
            })
            .collect();
        let g = test_map(&z, rows, cols, p, p);
        let s = spatial_params(g.heights_um.into(), &g, &Plane::of(&g).unwrap());
        assert_eq!(s.std_deg, 29.5);
    }

    /// A sine of k0 periods over the line: the PSD peaks at k0, at q = 2π·k0/L.
    #[test]
    fn the_psd_of_a_sine_peaks_at_its_wavevector() {
        let (rows, cols, px) = (3usize, 512usize, 0.0005);
        let k0 = 32usize;
        let z: Vec<f64> = (0..rows * cols)
            .map(|k| (2.0 * PI * k0 as f64 * (k % cols) as f64 / cols as f64).sin())
            .collect();
        let grid = test_map(&z, rows, cols, px, 0.01);
        let psd = psd_along_x(&grid, &Plane::of(&grid).unwrap());
        let (imax, _) =
            psd.c_um3
                .iter()
                .enumerate()
                .fold((0, 0.0), |b, (i, v)| if *v > b.1 { (i, *v) } else { b });
        assert_eq!(imax, k0);
        let length = cols as f64 * px * 1000.0;
        assert!((psd.q_per_um[k0] - 2.0 * PI * k0 as f64 / length).abs() < 1e-12);
    }
}
