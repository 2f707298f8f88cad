//! Section `lines`: the ISO 4287 / ISO 13565-2 parameters of every line as the instrument computes
//! them, the Rmr table, and the instrument's own results beside ours. Needs no model.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::params`] and
//! [`crate::metrology::instrument`].

use super::SectionInput;
use crate::grid::Grid;
use crate::metrology::areal;
use crate::metrology::bearing::material_ratio_pct_at;
use crate::metrology::cutoff::iso4288_check;
use crate::metrology::instrument::compare_profile;
use crate::metrology::params::{analyze_line, LineAnalysis, MaterialLevels, Options};
use crate::metrology::sj_material_ratio::sj_material_ratio;
use crate::metrology::MetrologyError;
use crate::numfmt::{line_label, line_number};
use crate::report::document::{LineReport, ReportRecipe};
use crate::report::error::{metrology, ReportError};
use std::path::PathBuf;

/// What the section produces.
#[derive(Debug, Clone)]
pub struct LinesSection {
    /// The recipe of every line (and the areal definitions).
    pub recipe: ReportRecipe,
    /// One entry per row of the grid.
    pub lines: Vec<LineReport>,
}

/// Rmr(c) at depths c = 0, 10, …, 100 % of Rt below the highest peak: `[c_um, Rmr_pct]`,
/// the material ratio of the evaluated profile's cross line, all depths from one pass.
pub fn rmr_table(a: &LineAnalysis) -> Vec<[f64; 2]> {
    let r = &a.roughness_um;
    let top = r.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let depths: [f64; 11] = std::array::from_fn(|k| a.params.rt_um * k as f64 / 10.0);
    let ratios = material_ratio_pct_at(r, depths.map(|c| top - c));
    (0..11).map(|k| [depths[k], ratios[k]]).collect()
}

/// Characterises every line, in parallel over the available cores (lines are independent).
fn analyse_lines(
    grid: &Grid,
    options: &Options,
    label: &str,
) -> Result<Vec<LineAnalysis>, ReportError> {
    let rows: Vec<&[f64]> = grid.heights_um.chunks(grid.cols.max(1)).collect();
    let results = crate::metrology::map_in_parallel(
        &rows,
        |_, z| analyze_line(z, grid.pitch_x_mm, options),
        |_| {
            Err(MetrologyError::BadParameter {
                what: "line analysis thread",
                value: f64::NAN,
                hint: "a line analysis thread panicked; report this with the input",
            })
        },
    );
    results
        .into_iter()
        .enumerate()
        .map(|(row, r)| {
            let line = line_label(grid.index_of(row));
            r.map_err(metrology(format!("{label} line {line}")))
        })
        .collect()
}

/// Runs the section on the grid as characterised; an error when a line cannot be evaluated.
/// Beside it, each row's analysis (its roughness profile draws the Rk construction).
pub fn section(input: &SectionInput<'_>) -> Result<(LinesSection, Vec<LineAnalysis>), ReportError> {
    let (grid, ctx) = (input.characterised, input.ctx);
    let analyses = analyse_lines(grid, &ctx.line_options, &ctx.input)?;
    let mut recipe = analyses.first().map(|a| a.recipe.clone()).ok_or_else(|| {
        crate::input::InputError::NoLines {
            dir: PathBuf::from(&ctx.input),
            incomplete: Vec::new(),
        }
    })?;
    recipe.definitions.extend(areal::definitions());
    let lines = analyses
        .iter()
        .enumerate()
        .map(|(row, a)| LineReport {
            index: grid.index_of(row),
            y_mm: grid.y_mm.get(row).copied().unwrap_or(f64::NAN),
            y_readback_mm: grid.y_readback_mm.get(row).copied().flatten(),
            params: a.params.clone(),
            rmr_table: rmr_table(a),
            instrument: grid.instrument.as_ref().map(|all| {
                compare_profile(
                    &a.params,
                    all.get(row).map_or(&[][..], |v| &v[..]),
                    grid.standard.get(row).and_then(|s| s.as_deref()),
                    ctx.line_options.apply_lambda_c,
                )
            }),
            model_vs_measured: None,
            readout_warnings: grid.readout_warnings.get(row).cloned().unwrap_or_default(),
            evaluation_length: a.evaluation_length.clone(),
            blank_reasons: a.blank_reasons.clone(),
            material_ratio_sj_series: sj_material_ratio(
                &a.roughness_um,
                &MaterialLevels::default(),
            )
            .ok(),
        })
        .collect();
    let section = LinesSection {
        recipe: ReportRecipe {
            lines: recipe,
            lambda_c_source: ctx.lambda_c_source.clone(),
            filter_reason: ctx.filter_reason.clone(),
            spike_rule: ctx.options.spikes.describe(),
            outliers: if ctx.options.exclude_spikes {
                "exclude"
            } else {
                "flag"
            },
            holdout_threshold_sq: ctx.options.holdout_threshold,
            material_ratio: ctx.options.material_ratio.name(),
        },
        lines,
    };
    Ok((section, analyses))
}

/// The mean of a value `f` of the lines where it is finite; `None` where it is nowhere finite
/// (the Ra and Rz a result is summed up by).
pub fn finite_mean(lines: &[LineReport], f: fn(&LineReport) -> f64) -> Option<f64> {
    let v: Vec<f64> = lines.iter().map(f).filter(|v| v.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// ISO 4288's check of λc against the result (the mean Ra and Rz of the lines): a warning
/// naming the band the result falls in when λc does not fit it; none for a form-only
/// evaluation (no λc) or without lines.
pub fn cutoff_warning(lines: &LinesSection, options: &Options) -> Option<String> {
    if options.form.is_some() || lines.lines.is_empty() {
        return None;
    }
    let mean = |f: fn(&LineReport) -> f64| finite_mean(&lines.lines, f);
    let (ra, rz) = (mean(|l| l.params.ra_um)?, mean(|l| l.params.rz_um)?);
    iso4288_check(ra, rz, options.lambda_c_mm)
        .warning
        .map(|w| match lines.lines.len() {
            1 => w,
            n => format!("{w} (mean of the {n} lines)"),
        })
}

/// Without the λc filter the heights are taken as a roughness profile about its mean line
/// (z = 0). A line is not centred when the mean of its evaluated ordinates is more than half
/// its Rq from zero, or its Rp or Rv comes out negative: an offset or form the filter would
/// have removed remains, and its Ra, Rz … measure that. Returns the mean of such a line.
fn uncentred_mean(a: &LineAnalysis) -> Option<f64> {
    let z = &a.roughness_um;
    let mean = z.iter().sum::<f64>() / z.len().max(1) as f64;
    let p = &a.params;
    (mean.abs() > 0.5 * p.rq_um || p.rp_um < 0.0 || p.rv_um < 0.0).then_some(mean)
}

/// The warning for unfiltered lines that are not centred (`uncentred_mean`): how many, the
/// worst with its mean against its Rq, and what to do; none with the λc filter or a form
/// removed. `analyses` are the lines' in the order of `lines`.
pub fn uncentred_warning(
    lines: &LinesSection,
    analyses: &[LineAnalysis],
    options: &Options,
) -> Option<String> {
    use crate::numfmt::{fmt, Quantity};
    if options.apply_lambda_c || options.form.is_some() {
        return None;
    }
    let off: Vec<(usize, f64)> = analyses
        .iter()
        .enumerate()
        .filter_map(|(k, a)| uncentred_mean(a).map(|m| (k, m)))
        .collect();
    let &(worst, mean) = off.iter().max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))?;
    let p = &analyses[worst].params;
    let which = if analyses.len() == 1 {
        "their mean is".to_owned()
    } else {
        format!(
            "{} of {} lines are not centred (line {}: mean",
            off.len(),
            analyses.len(),
            line_number(lines.lines.get(worst).map_or(worst as u32, |l| l.index))
        )
    };
    let [mean, rq, rp, rv] = [mean, p.rq_um, p.rp_um, p.rv_um].map(|v| fmt(v, Quantity::HeightUm));
    Some(format!(
        "without the λc filter (--no-filter, [analysis] no-filter) the heights are taken as a roughness profile about its mean line, but {which} {mean} µm against Rq {rq} µm (Rp {rp} µm, Rv {rv} µm){}: an offset or form remains and Ra, Rz … measure it; leave out --no-filter to apply the λc filter",
        if analyses.len() == 1 { "" } else { ")" }
    ))
}
