//! Model versus measured, honestly: an interpolant matches its data points by construction, so
//! the surface is refitted with every 2nd point of each line left out (and, separately, every
//! k-th line left out) and evaluated at the held-out points; max and RMS differences per line.
//!
//! **The verdict between lines** ([`between_lines`]): every k-th line (k = 2 by default: lines
//! 1, 3, 5, …) is left out, the remaining lines are refitted with the chosen method across the
//! lines, and the refit is evaluated at the held-out lines' y and the data x (held-out lines
//! outside the refitted y range are not extrapolated to). The pooled rms of model − measured
//! over those lines, divided by Sq of the measured grid, decides: the model between lines is
//! **supported** by the data when rms ≤ [`SUPPORTED_BELOW_SQ`] × Sq (0.5: the refit then
//! predicts at least 75 % of the height variance at lines it never saw; a flat plane predicts
//! none and scores about 1, an interpolant between uncorrelated lines about 1.4–1.7), else
//! **not supported**. The test is conservative: a held-out line is one pitch from the nearest
//! refitted lines, where a point of the full model is at most half a pitch from a measured
//! line. One deep pit or spike on a held-out line can decide the pooled rms; that is why the
//! spikes are reported beside the verdict (and bridged first when characterisation excludes
//! them).
//!
//! Depends on [`crate::grid`] (the lines), [`crate::fit`] (refits), [`super::model`]
//! (sampling), [`crate::nurbs`] and [`crate::numfmt`] (the figures in the verdict's words).

use super::model::sample_model_grid;
use super::MetrologyError;
use crate::fit::{fit_grid_with, FitOptions, FitResult, VMethod};
use crate::grid::Grid;
use crate::numfmt::{fmt, sig, Quantity};
use serde::Serialize;

/// The largest hold-out rms, in units of Sq, for which the model between lines is supported.
pub const SUPPORTED_BELOW_SQ: f64 = 0.5;

/// Every how many lines one is left out for `rows` lines and a refit of degree `degree_v`:
/// 2 (every 2nd line) when the other half can carry the refit, else the smallest k that
/// keeps degree_v + 1 lines and still holds one out between kept lines (7 lines at degree 5:
/// every 4th, i.e. line 3 alone); `None` when no line can be held out (at most
/// degree_v + 1 lines).
pub fn holdout_every(rows: usize, degree_v: usize) -> Option<usize> {
    (2..=rows).find(|&k| {
        let held: Vec<usize> = (0..rows).filter(|r| r % k == k - 1).collect();
        let kept = rows - held.len();
        let last_kept = (0..rows).rev().find(|r| r % k != k - 1).unwrap_or(0);
        kept > degree_v && held.iter().any(|&r| r > 0 && r < last_kept)
    })
}

/// [`holdout_every`], or why no line can be held out, in the words `fit` and the report both
/// print for the hold-outs and the verdict between lines.
pub fn holdout_every_or_reason(rows: usize, degree_v: usize) -> Result<usize, MetrologyError> {
    holdout_every(rows, degree_v).ok_or(MetrologyError::NoLineToHoldOut { rows, degree_v })
}

/// Differences at the held-out points of one line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HoldoutLine {
    /// Line index in the full grid.
    pub index: usize,
    /// y of the line, mm.
    pub y_mm: f64,
    /// Held-out points compared on this line.
    pub points: usize,
    /// Largest |model − measured|, µm.
    pub max_abs_um: f64,
    /// RMS of model − measured, µm.
    pub rms_um: f64,
}

/// Both hold-out comparisons.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Holdout {
    /// Every 2nd point (odd columns) of every line left out, per line.
    pub points_left_out: Vec<HoldoutLine>,
    /// Every k-th line left out (k = 2 unless too few lines remain for the refit, see
    /// [`holdout_every`]), per held-out line inside the kept range.
    pub lines_left_out: Vec<HoldoutLine>,
}

fn stats(index: usize, y_mm: f64, model: &[f64], measured: &[f64]) -> HoldoutLine {
    let d: Vec<f64> = model.iter().zip(measured).map(|(m, z)| m - z).collect();
    let n = d.len().max(1) as f64;
    HoldoutLine {
        index,
        y_mm,
        points: d.len(),
        max_abs_um: d.iter().fold(0.0, |a, v| a.max(v.abs())),
        rms_um: (d.iter().map(|v| v * v).sum::<f64>() / n).sqrt(),
    }
}

fn check_grid(grid: &Grid) -> Result<(), MetrologyError> {
    super::check_pitch(grid.pitch_x_mm)?;
    let (rows, cols, got) = (grid.y_mm.len(), grid.cols, grid.heights_um.len());
    if let Some(w) = grid.y_mm.windows(2).find(|w| !matches!(w, [a, b] if b > a)) {
        return Err(MetrologyError::BadParameter {
            what: "y (mm) of a line",
            value: w.get(1).copied().unwrap_or(f64::NAN),
            hint: "line y values must be finite and strictly increasing",
        });
    }
    if rows.checked_mul(cols) != Some(got) {
        return Err(MetrologyError::GridSize {
            rows,
            cols,
            expected: rows.saturating_mul(cols),
            got,
        });
    }
    Ok(())
}

/// Runs both hold-out refits on a row-major grid (heights µm, one row per line at `y_mm[j]`,
/// increasing; the lines need not be equally spaced, e.g. a scan with a line missing), with
/// `method` across the lines for both refits.
pub fn holdout_with(
    grid: &Grid,
    options: FitOptions,
    method: VMethod,
) -> Result<Holdout, MetrologyError> {
    let points_left_out = points_left_out(grid, options, method)?;
    let every = holdout_every_or_reason(grid.rows(), options.degree_v)?;
    let lines_left_out = lines_left_out(grid, options, method, every)?.lines;
    Ok(Holdout {
        points_left_out,
        lines_left_out,
    })
}

/// The first refit of [`holdout_with`]: every 2nd point of each line left out, the even
/// columns fitted at twice the pitch and the model compared at the odd ones, per line.
pub fn points_left_out(
    grid: &Grid,
    options: FitOptions,
    method: VMethod,
) -> Result<Vec<HoldoutLine>, MetrologyError> {
    check_grid(grid)?;
    let (rows, cols, pitch_x_mm, y) = (grid.rows(), grid.cols, grid.pitch_x_mm, &grid.y_mm[..]);

    // Every 2nd point of each line out: fit the even columns at twice the pitch.
    let kept_cols = cols.div_ceil(2);
    let sub: Vec<f64> = (0..rows)
        .flat_map(|r| grid.row(r).iter().step_by(2).copied().collect::<Vec<f64>>())
        .collect();
    let fit = fit_grid_with(2.0 * pitch_x_mm, y, &sub, kept_cols, options, method)?;
    let held = (cols.saturating_sub(1)) / 2;
    let model = sample_model_grid(
        &fit.surface,
        &fit.params_v,
        pitch_x_mm,
        2.0 * pitch_x_mm,
        held,
    )?;
    Ok((0..rows)
        .map(|r| {
            let measured: Vec<f64> = grid
                .row(r)
                .iter()
                .skip(1)
                .step_by(2)
                .take(held)
                .copied()
                .collect();
            let m = model.get(r * held..(r + 1) * held).unwrap_or(&[]);
            stats(r, y.get(r).copied().unwrap_or(0.0), m, &measured)
        })
        .collect())
}

/// The v where the surface's y equals `target` (y depends on v only; bisection of y(0, v)),
/// or an error when y(v) does not reach it (a fold across the lines).
fn v_at_y(surface: &crate::nurbs::NurbsSurface, target: f64) -> Result<f64, MetrologyError> {
    let v = super::bisect(0.0, 1.0, |m| surface.evaluate(0.0, m)[1] < target);
    let y = surface.evaluate(0.0, v)[1];
    if (y - target).abs() > 1e-9 * target.abs().max(1.0) {
        return Err(MetrologyError::BadParameter {
            what: "y (mm) not reached by the refitted surface",
            value: target,
            hint: "the refit's y does not increase monotonically across the lines (a fold); the model between lines cannot be compared there",
        });
    }
    Ok(v)
}

/// The method of a refit through `kept` of `rows` lines: a least-squares surface keeps its
/// lines per control row (control rows scaled by kept/rows, at least degree_v + 1), as the
/// interpolant keeps one pole row per line, so a refit has the full model's smoothing.
fn refit_method(method: VMethod, rows: usize, kept: usize, degree_v: usize) -> VMethod {
    match method {
        VMethod::LeastSquares { control_rows } => {
            let scaled = (control_rows as f64 * kept as f64 / rows.max(1) as f64).round() as usize;
            VMethod::LeastSquares {
                control_rows: scaled.max(degree_v + 1).min(kept),
            }
        }
        m => m,
    }
}

/// The surface refitted through the rows of `grid` that `keep` keeps, with `method` across
/// them as [`refit_method`] scales it, and the rows kept.
fn refit_keeping(
    grid: &Grid,
    options: FitOptions,
    method: VMethod,
    keep: impl Fn(usize) -> bool,
) -> Result<(FitResult, Vec<usize>), MetrologyError> {
    let kept: Vec<usize> = (0..grid.rows()).filter(|&r| keep(r)).collect();
    let ky: Vec<f64> = kept
        .iter()
        .map(|&r| grid.y_mm.get(r).copied().unwrap_or(f64::NAN))
        .collect();
    let method = refit_method(method, grid.rows(), kept.len(), options.degree_v);
    // The kept lines' copy is freed as soon as the refit has them.
    let sub: Vec<f64> = kept.iter().flat_map(|&r| grid.row(r)).copied().collect();
    let fit = fit_grid_with(grid.pitch_x_mm, &ky, &sub, grid.cols, options, method)?;
    Ok((fit, kept))
}

/// The refit that both [`holdout_with`] (its second part) and [`between_lines`] make: every
/// `every`-th line left out (rows every−1, 2·every−1, …), the others refitted with `method`
/// across the lines (least squares with the control rows scaled as [`refit_method`] says),
/// and per held-out line inside the kept y range its statistics and the model's heights at
/// its x. A caller that needs both computes it once and hands it to [`between_lines_given`].
pub fn lines_left_out(
    grid: &Grid,
    options: FitOptions,
    method: VMethod,
    every: usize,
) -> Result<HeldLines, MetrologyError> {
    check_grid(grid)?;
    let (cols, pitch_x_mm, y_mm) = (grid.cols, grid.pitch_x_mm, &grid.y_mm[..]);
    if every < 2 {
        return Err(MetrologyError::BadParameter {
            what: "hold-out: every k-th line",
            value: every as f64,
            hint: "leave out every 2nd line or fewer (k ≥ 2)",
        });
    }
    let is_held = |r: usize| r % every == every - 1;
    let (fit, kept_rows) = refit_keeping(grid, options, method, |r| !is_held(r))?;
    let (first_kept, last_kept) = (
        kept_rows.first().copied().unwrap_or(0),
        kept_rows.last().copied().unwrap_or(0),
    );
    // The held-out lines' v first, then one sampling of all of them (x(u) is inverted once,
    // not once per line; each line's heights are the bits a sampling of it alone gives). A
    // line whose v is not found ends the list: the lines before it are sampled first, so an
    // error of theirs is reported before it, as a line-by-line pass would.
    let mut held = Vec::new();
    let mut vs = Vec::new();
    let mut unreached = None;
    for r in (first_kept + 1..last_kept).filter(|&r| is_held(r)) {
        let target = y_mm.get(r).copied().unwrap_or(f64::NAN);
        match v_at_y(&fit.surface, target) {
            Ok(v) => {
                held.push((r, target));
                vs.push(v);
            }
            Err(e) => {
                unreached = Some(e);
                break;
            }
        }
    }
    let mut out = HeldLines {
        lines: Vec::with_capacity(held.len()),
        model_um: Vec::new(),
        cols,
    };
    if !vs.is_empty() {
        // The sampled heights are kept as sampled, line after line (no copy per line).
        out.model_um = sample_model_grid(&fit.surface, &vs, 0.0, pitch_x_mm, cols)?;
        for (&(r, target), m) in held.iter().zip(out.model_um.chunks_exact(cols.max(1))) {
            out.lines.push(stats(r, target, m, grid.row(r)));
        }
    }
    match unreached {
        Some(e) => Err(e),
        None => Ok(out),
    }
}

/// The model at line `row` refitted without it (all other lines kept, `method` across the
/// lines), sampled at the line's y and the data x: what an overlay of that line shows, with
/// the line's statistics against it. The line must lie between two others (no
/// extrapolation).
pub fn model_without_line(
    grid: &Grid,
    options: FitOptions,
    method: VMethod,
    row: usize,
) -> Result<(HoldoutLine, Vec<f64>), MetrologyError> {
    check_grid(grid)?;
    if row == 0 || row + 1 >= grid.rows() {
        return Err(MetrologyError::BadParameter {
            what: "line to leave out (row)",
            value: row as f64,
            hint: "only a line between two others can be left out and predicted",
        });
    }
    let (fit, _) = refit_keeping(grid, options, method, |r| r != row)?;
    let y = grid.y_mm[row];
    let v = v_at_y(&fit.surface, y)?;
    let model = sample_model_grid(&fit.surface, &[v], 0.0, grid.pitch_x_mm, grid.cols)?;
    Ok((stats(row, y, &model, grid.row(row)), model))
}

/// The lines-left-out refit at its held-out lines: their statistics, and the refit's heights
/// at their x, line after line.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldLines {
    /// Per held-out line inside the kept y range (index = the row).
    pub lines: Vec<HoldoutLine>,
    /// The refit's heights, µm: `cols` per line of `lines`, in their order.
    pub model_um: Vec<f64>,
    /// Heights per line.
    pub cols: usize,
}

/// The between-line hold-out and its verdict (module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BetweenLines {
    /// `interpolate` or `least-squares`.
    pub method: &'static str,
    /// The method across the lines, with its control rows when least squares.
    pub v_method: VMethod,
    /// Every k-th line was left out.
    pub every: usize,
    /// Held-out lines compared (indices as given to [`between_lines`]).
    pub lines: Vec<HoldoutLine>,
    /// Points compared, pooled.
    pub points: usize,
    /// Pooled rms of model − measured at the held-out lines, µm.
    pub rms_um: f64,
    /// Largest |model − measured| there, µm.
    pub max_abs_um: f64,
    /// Sq of the measured grid it is judged against, µm.
    pub sq_um: f64,
    /// rms / Sq.
    pub rms_over_sq: f64,
    /// The threshold on rms / Sq.
    pub threshold: f64,
    /// rms / Sq ≤ threshold.
    pub supported: bool,
    /// The short verdict ([`BetweenLines::short`]), for summaries.
    pub summary: String,
    /// The verdict in one sentence.
    pub verdict: String,
    /// The model's heights at the held-out lines, µm: `model_cols` per line of `lines`, in
    /// their order, at the data x; not serialised (the report plots one of them; see
    /// [`BetweenLines::model_line`]).
    #[serde(skip)]
    pub model_um: Vec<f64>,
    /// Heights per line in `model_um`.
    #[serde(skip)]
    pub model_cols: usize,
}

impl BetweenLines {
    /// The model's heights at the `k`-th held-out line (`lines[k]`), µm; `None` past the
    /// lines or once `model_um` has been dropped.
    pub fn model_line(&self, k: usize) -> Option<&[f64]> {
        let n = self.model_cols;
        self.model_um
            .get(k.checked_mul(n)?..k.checked_add(1)?.checked_mul(n)?)
    }

    /// The short verdict: "supported / not supported by the data (hold-out rms X µm = Y × Sq)".
    pub fn short(&self) -> String {
        format!(
            "the model between lines is {} by the data (hold-out rms {} µm = {} × Sq)",
            if self.supported {
                "supported"
            } else {
                "not supported"
            },
            fmt(self.rms_um, Quantity::HeightUm),
            sig(self.rms_over_sq, 2)
        )
    }

    /// The verdict in one line for a terminal, or that there is none (and why, when known).
    pub fn line(verdict: Result<&Self, Option<&str>>) -> String {
        match verdict {
            Ok(b) => b.short(),
            Err(Some(why)) => format!("no verdict on the model between lines: {why}"),
            Err(None) => "no verdict on the model between lines".to_string(),
        }
    }
}

/// `2nd`, `3rd`, `11th`: how the verdict names every k-th line.
pub fn ordinal(k: usize) -> String {
    let suffix = match (k % 10, k % 100) {
        (1, 11) | (2, 12) | (3, 13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{k}{suffix}")
}

/// Leaves every `every`-th line out, refits with `method` and judges the refit at the held-out
/// lines against `sq_um` (Sq of the measured grid) and `threshold` (on rms / Sq; the default is
/// [`SUPPORTED_BELOW_SQ`]).
pub fn between_lines(
    grid: &Grid,
    options: FitOptions,
    method: VMethod,
    every: usize,
    sq_um: f64,
    threshold: f64,
) -> Result<BetweenLines, MetrologyError> {
    between_lines_given(grid, method, every, sq_um, threshold, || {
        lines_left_out(grid, options, method, every)
    })
}

/// [`between_lines`] with its refit made by `held` (the result of [`lines_left_out`] with the
/// same grid, `method` and `every`), called only once the grid, `sq_um` and `threshold` have
/// passed their checks, so that the errors come in the same order.
pub fn between_lines_given(
    grid: &Grid,
    method: VMethod,
    every: usize,
    sq_um: f64,
    threshold: f64,
    held: impl FnOnce() -> Result<HeldLines, MetrologyError>,
) -> Result<BetweenLines, MetrologyError> {
    check_grid(grid)?;

    if !(sq_um.is_finite() && sq_um > 0.0) {
        return Err(MetrologyError::BadParameter {
            what: "Sq (µm) of the measured grid",
            value: sq_um,
            hint: "a flat grid has nothing to predict between lines; the verdict needs Sq > 0",
        });
    }
    if !(threshold.is_finite() && threshold > 0.0) {
        return Err(MetrologyError::BadParameter {
            what: "hold-out threshold (× Sq)",
            value: threshold,
            hint: "give a positive multiple of Sq, e.g. 0.3",
        });
    }
    let held = held()?;
    if held.lines.is_empty() {
        return Err(MetrologyError::BadParameter {
            what: "lines inside the refitted range",
            value: 0.0,
            hint: "too few lines to leave some out and refit the rest; trace more lines",
        });
    }
    let (mut sum2, mut points, mut max_abs) = (0.0f64, 0usize, 0.0f64);
    for line in &held.lines {
        sum2 += line.rms_um * line.rms_um * line.points as f64;
        points += line.points;
        max_abs = max_abs.max(line.max_abs_um);
    }
    let rms = (sum2 / points.max(1) as f64).sqrt();
    let ratio = rms / sq_um;
    let supported = ratio <= threshold;
    let HeldLines {
        lines,
        model_um,
        cols: model_cols,
    } = held;
    let mut out = BetweenLines {
        method: method.name(),
        v_method: method,
        every,
        points,
        rms_um: rms,
        max_abs_um: max_abs,
        sq_um,
        rms_over_sq: ratio,
        threshold,
        supported,
        summary: String::new(),
        verdict: String::new(),
        model_um,
        model_cols,
        lines,
    };
    out.summary = out.short();
    let [rms, max_abs, sq] = [rms, max_abs, sq_um].map(|v| fmt(v, Quantity::HeightUm));
    out.verdict = format!(
        "{}: every {} line left out ({} lines) and the rest refitted ({}), the refit misses them by {rms} µm rms and {max_abs} µm at worst, against Sq {sq} µm; supported means rms ≤ {threshold} × Sq",
        out.summary,
        ordinal(every),
        out.lines.len(),
        method.name(),
    );
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::metrology::test_grid as grid;

    /// [`between_lines`] with the default fit, interpolating in v.
    fn held_out(
        g: &Grid,
        every: usize,
        sq: f64,
        threshold: f64,
    ) -> Result<BetweenLines, MetrologyError> {
        between_lines(
            g,
            FitOptions::default(),
            VMethod::Interpolate,
            every,
            sq,
            threshold,
        )
    }

    #[test]
    fn every_kth_line_is_held_out_inside_the_kept_range() {
        let g = grid(14, 40, 0.002, |r, c| {
            (c as f64 * 0.2).sin() + 0.1 * r as f64
        });
        let b = held_out(&g, 3, 1.0, SUPPORTED_BELOW_SQ).unwrap();
        let held: Vec<usize> = b.lines.iter().map(|l| l.index).collect();
        // Rows 2, 5, 8, 11 are left out; 13 is kept, so 11 lies inside the kept range.
        assert_eq!(held, vec![2, 5, 8, 11]);
        // The refit's heights, one line of 40 per held-out line, in their order.
        assert_eq!(b.model_um.len(), 4 * 40);
        assert_eq!(b.model_line(3), Some(&b.model_um[120..160]));
        assert_eq!(b.model_line(4), None);
        assert_eq!(b.points, 4 * 40);
        assert!(b.supported, "{}", b.verdict);
        assert!(b.verdict.contains("every 3rd line"), "{}", b.verdict);
    }

    #[test]
    fn held_out_lines_sampled_together_equal_each_sampled_alone_to_the_bit() {
        // The refit is sampled at all held-out lines in one call; each line's heights must
        // be those a sampling of that line alone gives (the model an overlay shows).
        let g = grid(15, 64, 0.0005, |r, c| {
            (c as f64 * 0.21 + r as f64 * 0.7).sin() + 0.05 * ((r * 64 + c) % 7) as f64
        });
        let (y, z) = (&g.y_mm, &g.heights_um);
        let held = lines_left_out(&g, FitOptions::default(), VMethod::Interpolate, 2).unwrap();
        let kept: Vec<usize> = (0..15).filter(|r| r % 2 == 0).collect();
        let sub: Vec<f64> = kept.iter().flat_map(|&r| g.row(r)).copied().collect();
        let ky: Vec<f64> = kept.iter().map(|&r| y[r]).collect();
        let fit = fit_grid_with(
            0.0005,
            &ky,
            &sub,
            64,
            FitOptions::default(),
            VMethod::Interpolate,
        )
        .unwrap();
        assert_eq!(held.lines.len(), 7);
        assert_eq!(held.model_um.len(), 7 * 64);
        for (line, model) in held.lines.iter().zip(held.model_um.chunks_exact(64)) {
            let v = v_at_y(&fit.surface, line.y_mm).unwrap();
            let alone = sample_model_grid(&fit.surface, &[v], 0.0, 0.0005, 64).unwrap();
            let bits = |m: &[f64]| m.iter().map(|h| h.to_bits()).collect::<Vec<u64>>();
            assert_eq!(bits(model), bits(&alone), "line {}", line.index);
            assert_eq!(
                *line,
                stats(line.index, line.y_mm, &alone, &z[line.index * 64..][..64])
            );
        }
    }

    #[test]
    fn few_lines_hold_out_every_kth_and_too_few_none() {
        assert_eq!(holdout_every(31, 5), Some(2));
        assert_eq!(holdout_every(12, 5), Some(2));
        assert_eq!(holdout_every(8, 5), Some(3));
        assert_eq!(holdout_every(7, 5), Some(4));
        assert_eq!(holdout_every(6, 5), None);
        assert_eq!(holdout_every(5, 3), Some(3));
    }

    #[test]
    fn pooled_rms_decides_against_the_threshold() {
        // Lines alternate +1/−1: a held-out (odd) line is −1 where every refitted line is +1.
        let g = grid(13, 30, 0.002, |r, _| if r % 2 == 0 { 1.0 } else { -1.0 });
        let b = held_out(&g, 2, 1.0, SUPPORTED_BELOW_SQ).unwrap();
        assert!(
            (b.rms_um - 2.0).abs() < 1e-9 && (b.max_abs_um - 2.0).abs() < 1e-9,
            "{b:?}"
        );
        assert!(!b.supported);
        assert!(
            b.short()
                .contains("not supported by the data (hold-out rms 2.000 µm = 2.0 × Sq)"),
            "{}",
            b.short()
        );
        assert!(held_out(&g, 1, 1.0, 0.3).is_err());
        assert!(held_out(&g, 2, 0.0, 0.3).is_err());
    }
}
