//! Section `outliers`: the spikes of every line ([`crate::metrology::outliers`]), named there
//! and in the warnings with line, x (the input's) and height. By default the data stay as measured; when
//! characterisation excludes them, the per-line and measured-grid parameters (and the
//! hold-out) use a copy of the grid with each spike bridged by the straight line between its
//! neighbours, and the files of the data (`measured.x3p`, the height map) stay as traced.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::outliers`] and [`crate::numfmt`].

use super::SectionInput;
use crate::grid::Grid;
use crate::metrology::outliers::{find_grid_spikes, LineSpike};
use crate::numfmt::{fmt, line_label, sig, Quantity};
use crate::report::document::{LineNotJudged, OutliersReport};

/// At most this many spikes are listed one by one in the warnings (all are in the report).
const LISTED: usize = 20;

/// Finds the spikes of the grid's lines on the roughness profile the lines are evaluated on
/// (the λc roughness when the lines are filtered, else the heights minus their line), as the
/// report names them: the rule, the policy (`exclude` when they are to be bridged, else
/// `flag`), every spike and the lines that could not be judged.
pub fn section(input: &SectionInput<'_>) -> OutliersReport {
    let (o, rule) = (&input.ctx.line_options, &input.ctx.options.spikes);
    let exclude = input.ctx.options.exclude_spikes;
    let (spikes, failed) =
        find_grid_spikes(input.grid, o.apply_lambda_c.then_some(o.lambda_c_mm), rule);
    OutliersReport {
        rule: rule.describe(),
        policy: if exclude { "exclude" } else { "flag" },
        spikes,
        lines_not_judged: failed
            .into_iter()
            .map(|(line, reason)| LineNotJudged { line, reason })
            .collect(),
    }
}

/// The warnings: every spike (the first [`LISTED`], then a count) with its line (1-based,
/// the file index beside it), x and height, what was done with them, and the lines that could
/// not be judged. `grid` places the points of a spike along x.
pub fn warn(o: &OutliersReport, replaced: &[LineSpike], grid: &Grid, warnings: &mut Vec<String>) {
    for s in o.spikes.iter().take(LISTED) {
        warnings.push(format!(
            "spike in line {} at x = {} mm: height {} µm, {} robust σ from the line's median roughness ({} point(s), x = {} … {} mm); {}",
            line_label(s.line),
            fmt(s.spike.x_mm, Quantity::PositionMm),
            fmt(s.spike.height_um, Quantity::HeightUm),
            sig(s.spike.deviation_sigma, 3),
            s.spike.last - s.spike.first + 1,
            fmt(grid.x_mm(s.spike.first), Quantity::PositionMm),
            fmt(grid.x_mm(s.spike.last), Quantity::PositionMm),
            match o.policy {
                "exclude" => "left out of the per-line and measured-grid parameters (bridged)",
                _ => "flagged only, the data stay as measured",
            }
        ));
    }
    if o.spikes.len() > LISTED {
        warnings.push(format!(
            "{} more spikes (report.json's outliers lists all {})",
            o.spikes.len() - LISTED,
            o.spikes.len()
        ));
    }
    if !replaced.is_empty() {
        warnings.push(format!(
            "{} spike(s) were replaced by the straight line between their neighbours before fitting, as asked for; the IGES Start section and report.json's model name them",
            replaced.len()
        ));
    }
    for l in &o.lines_not_judged {
        warnings.push(format!(
            "line {} could not be checked for spikes: {}",
            line_label(l.line),
            l.reason
        ));
    }
}
