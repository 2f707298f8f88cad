//! A part's surface specification and the verdict of a scan against it.
//!
//! - [`callout`]: one limit as a drawing writes it (`"Rz max 6.3"`), parsed or refused;
//! - [`rule`]: the 16 % and max rules (ISO 4288:1996 §5.2–5.3) under ISO 14253-1's decision
//!   rule, and the [`Verdict`];
//! - [`uncertainty`]: n, s, the uncertainty of a mean and the expanded U (GUM, k = 2);
//! - this file: a [`Specification`] (limits checked against each other) and [`judge`], the
//!   section that holds a scan's per-line values against it.
//!
//! A scan's lines are the measured values on the surface: each line's parameter over its
//! evaluation length is one value. A callout that asks for another transmission band or
//! another number of sampling lengths than the lines were evaluated with is not compared
//! (its verdict is *not decidable*, the difference named): a verdict is never stronger than
//! its values and their uncertainty allow.
//!
//! Layer 1 (pure): depends on [`crate::metrology::params`] (the per-line values),
//! [`crate::numfmt`] and `toml` (a recipe's text); no I/O.

pub mod callout;
pub mod rule;
pub mod uncertainty;

pub use callout::{Callout, CalloutError, Parameter, Rule, Side};
pub use rule::Verdict;
pub use uncertainty::{InstrumentUncertainty, Statistics};

use crate::metrology::params::RoughnessParams;
use crate::numfmt::line_number;
use rule::{decide, meets, standing, Standing, Tally};
use serde::Serialize;

/// The limits of a part's specification, each readable and consistent with the others.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Specification {
    /// The limits in the order written.
    pub limits: Vec<Callout>,
}

/// A specification that cannot be used: which limit and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("limits[{index}]: {message}")]
pub struct SpecificationError {
    /// 0-based position of the offending limit in the list.
    pub index: usize,
    /// What is wrong and what is accepted.
    pub message: String,
}

impl Specification {
    /// Parses every callout and checks them against each other: a lower limit above the
    /// upper limit of the same parameter, and the same limit twice, are refused.
    pub fn parse<S: AsRef<str>>(limits: &[S]) -> Result<Specification, SpecificationError> {
        let mut out: Vec<Callout> = Vec::with_capacity(limits.len());
        for (index, text) in limits.iter().enumerate() {
            let c: Callout =
                text.as_ref()
                    .parse()
                    .map_err(|e: CalloutError| SpecificationError {
                        index,
                        message: e.to_string(),
                    })?;
            for other in &out {
                let same_measurand = other.parameter == c.parameter
                    && other.evaluation_sampling_lengths() == c.evaluation_sampling_lengths()
                    && other.band == c.band;
                if !same_measurand {
                    continue;
                }
                if other.side == c.side && other.rule == c.rule {
                    return Err(SpecificationError {
                        index,
                        message: format!(
                            "{:?} repeats the {} {} limit of {:?}: keep one",
                            c.text,
                            side_word(c.side),
                            c.parameter_label(),
                            other.text
                        ),
                    });
                }
                let (lower, upper) = match (c.side, other.side) {
                    (Side::Lower, Side::Upper) => (&c, other),
                    (Side::Upper, Side::Lower) => (other, &c),
                    _ => continue,
                };
                if lower.limit_um >= upper.limit_um {
                    return Err(SpecificationError {
                        index,
                        message: format!(
                            "the lower limit {:?} is not below the upper limit {:?}: no surface could meet both",
                            lower.text, upper.text
                        ),
                    });
                }
            }
            out.push(c);
        }
        Ok(Specification { limits: out })
    }

    /// The limits a recipe's text holds under `[specification] limits` (a job's frozen copy,
    /// read back from a scan's journal): the same parse, the text already validated when the
    /// job was made. An error names the key and what is wrong.
    pub fn of_recipe_text(text: &str) -> Result<Specification, String> {
        let table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| e.message().to_owned())?;
        let Some(limits) = table.get("specification").and_then(|s| s.get("limits")) else {
            return Ok(Specification::default());
        };
        let limits: Vec<&str> = limits
            .as_array()
            .and_then(|a| a.iter().map(toml::Value::as_str).collect())
            .ok_or("specification.limits: not a list of callouts (\"Ra 0.8\")")?;
        Specification::parse(&limits).map_err(|e| format!("specification.{e}"))
    }

    /// Whether there is nothing to judge.
    pub fn is_empty(&self) -> bool {
        self.limits.is_empty()
    }
}

fn side_word(s: Side) -> &'static str {
    match s {
        Side::Upper => "upper",
        Side::Lower => "lower",
    }
}

/// The transmission band and evaluation length the lines' values were computed with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvaluatedBand {
    /// λc, mm.
    pub lambda_c_mm: f64,
    /// λs, µm, when known.
    pub lambda_s_um: Option<f64>,
    /// Sampling lengths per evaluation length.
    pub sampling_lengths: u32,
}

/// One line's values: its file index, its parameters and whether it was kept with a
/// warning about its read-out (its values then may not be the surface's).
#[derive(Debug, Clone, Copy)]
pub struct LineValues<'a> {
    /// The 0-based index of the line's files.
    pub index: u32,
    /// Its parameters.
    pub params: &'a RoughnessParams,
    /// Kept with a read-out warning (`ra-far-from-neighbours`, `beyond-detector-range`, …).
    pub flagged: bool,
}

/// The verdict on one limit with the figures it rests on.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LimitVerdict {
    /// The callout as written.
    pub callout: String,
    /// The parameter.
    pub parameter: Parameter,
    /// `upper` or `lower`.
    pub side: Side,
    /// `16 %` or `max`.
    pub rule: Rule,
    /// The limit, µm.
    pub limit_um: f64,
    /// The sampling lengths per evaluation length the callout asks for.
    pub sampling_lengths: u32,
    /// The verdict.
    pub verdict: Verdict,
    /// Lines with a value of the parameter (the measured values).
    pub n_values: usize,
    /// Values proven beyond the limit (beyond it by more than their U).
    pub n_beyond: usize,
    /// Values within their U of the limit (neither proven within nor beyond).
    pub n_undecided: usize,
    /// Lines the scan's plan asks for that have no entry among the lines (not traced, or
    /// left out as unusable): each counted as undecided, so that a partial scan's verdict is
    /// never stronger than the lines it has (0 for a complete scan and for a grid).
    pub n_not_measured: usize,
    /// How many values beyond the rule allows for the `n_values + n_not_measured` values the
    /// surface was to have (16 % of them, rounded down; 0 for the max rule).
    pub n_allowed: usize,
    /// The expanded uncertainty (k = 2) of one line's value, % of the value (0 when the
    /// station states none or it does not apply to the parameter).
    pub line_u_pct: f64,
    /// The smallest and largest value, µm.
    pub min_um: Option<f64>,
    /// The largest value, µm.
    pub max_um: Option<f64>,
    /// Lines (1-based, summary.csv's `line`) proven beyond the limit.
    pub lines_beyond: Vec<u64>,
    /// Lines (1-based) within their U of the limit.
    pub lines_undecided: Vec<u64>,
    /// Lines (1-based) without a value of the parameter.
    pub lines_without_value: Vec<u64>,
    /// Where the callout asks for other conditions than the lines were evaluated with
    /// (band, evaluation length); each makes the limit not decidable.
    pub conditions_differ: Vec<String>,
    /// Lines (1-based) kept with a read-out warning.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub lines_with_warnings: Vec<u64>,
    /// The verdict on the other lines alone, when some line has a read-out warning: when it
    /// differs from the verdict on all of them, the limit is not decidable.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verdict_without_them: Option<Verdict>,
    /// The verdict in words: `Rz 16 % rule: 9 of 31 lines above 6.3 µm (at most 4 allowed)`.
    pub reason: String,
}

/// The verdict of a scan against a specification: the section's typed result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpecificationVerdict {
    /// `conforms`, `does not conform` or `not decidable`.
    pub verdict: Verdict,
    /// The verdict with the reasons that decide it, for status lines:
    /// `does not conform (Rz 16 % rule: 9 of 31 lines above 6.3 µm (at most 4 allowed))`.
    pub summary: String,
    /// How conformance is decided.
    pub decision_rule: &'static str,
    /// What the verdict assumes of the instrument's uncertainty.
    pub instrument_uncertainty: String,
    /// One entry per limit, in the specification's order.
    pub limits: Vec<LimitVerdict>,
    /// The reading of the material-ratio family the lines' Rk, Rpk and Rvk were judged in
    /// (`[analysis] material-ratio`), stated by the caller that chose the values.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub material_ratio: Option<&'static str>,
}

/// The decision rule, stated in every verdict.
pub const DECISION_RULE: &str = "ISO 14253-1 default rule: conformance and non-conformance are proven only beyond the expanded uncertainty U; a value within U of a limit is undecided, counted beyond for conformance and within for non-conformance. The 16 % rule and the max rule as ISO 4288:1996 §5.2–5.3, each line's value over its evaluation length being one measured value.";

/// Where a callout's band and evaluation length differ from the lines'.
fn conditions_differ(c: &Callout, band: Option<&EvaluatedBand>) -> Vec<String> {
    let Some(b) = band else {
        return vec![
            "the lines' transmission band is not known (no λc filter applied to a primary profile): their values are not roughness parameters".to_owned(),
        ];
    };
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
    let mut out = Vec::new();
    if let Some(cb) = c.band {
        if let Some(lc) = cb.lambda_c_mm {
            if !close(lc, b.lambda_c_mm) {
                out.push(format!(
                    "the callout asks λc = {lc} mm, the lines were filtered with λc = {} mm",
                    b.lambda_c_mm
                ));
            }
        }
        if let Some(ls) = cb.lambda_s_mm {
            match b.lambda_s_um {
                Some(s) if close(ls * 1000.0, s) => {}
                Some(s) => out.push(format!(
                    "the callout asks λs = {ls} mm, the lines were filtered with λs = {} mm",
                    s / 1000.0
                )),
                None => out.push(format!(
                    "the callout asks λs = {ls} mm, the lines' λs is not recorded"
                )),
            }
        }
    }
    let n = c.evaluation_sampling_lengths();
    if n != b.sampling_lengths {
        out.push(format!(
            "{} is over {n} sampling lengths{}, the lines were evaluated over {}",
            c.parameter_label(),
            if c.sampling_lengths.is_none() {
                " (the default, none written)"
            } else {
                ""
            },
            b.sampling_lengths
        ));
    }
    out
}

fn count_phrase(k: usize, n: usize) -> String {
    if k == 0 {
        format!("none of {n} lines")
    } else {
        format!("{k} of {n} lines")
    }
}

/// Judges one limit on the lines' values.
fn judge_limit(
    c: &Callout,
    lines: &[LineValues<'_>],
    not_measured: usize,
    band: Option<&EvaluatedBand>,
    instrument: &InstrumentUncertainty,
) -> LimitVerdict {
    let scaling = match c.parameter {
        Parameter::RSm => uncertainty::Scaling::Lateral,
        _ => uncertainty::Scaling::Height,
    };
    let mut t = Tally {
        missing: not_measured,
        ..Tally::default()
    };
    let (mut beyond, mut undecided, mut without) = (Vec::new(), Vec::new(), Vec::new());
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for l in lines {
        let Some(v) = c.parameter.value(l.params).filter(|v| v.is_finite()) else {
            without.push(line_number(l.index));
            continue;
        };
        lo = lo.min(v);
        hi = hi.max(v);
        let u = instrument.expanded_of_value(v, scaling);
        let s = standing(v, u, c.limit_um, c.side);
        t.add(s);
        match s {
            Standing::Beyond => beyond.push(line_number(l.index)),
            Standing::Undecided => undecided.push(line_number(l.index)),
            Standing::Within => {}
        }
    }
    let planned = t.n + t.missing;
    let n_allowed = (0..=planned)
        .take_while(|&k| meets(c.rule, k, planned))
        .last()
        .unwrap_or(0);
    let differ = conditions_differ(c, band);
    let verdict = if differ.is_empty() {
        decide(c.rule, t)
    } else {
        Verdict::NotDecidable
    };
    let label = format!("{} {}", c.parameter_label(), c.rule.name());
    let mut reason = if t.n == 0 {
        format!("{label}: no line has a value of {}", c.parameter)
    } else {
        let mut r = format!(
            "{label}: {} {} {} µm",
            count_phrase(t.beyond, t.n),
            c.beyond_word(),
            c.limit_um
        );
        if t.undecided > 0 {
            r.push_str(&format!(", {} more within U of it", t.undecided));
        }
        if t.missing > 0 {
            r.push_str(&format!(
                ", {} of the {planned} planned lines not measured (counted as undecided)",
                t.missing
            ));
        }
        if c.rule == Rule::SixteenPercent && t.missing > 0 {
            r.push_str(&format!(" (at most {n_allowed} of {planned} allowed)"));
        } else if c.rule == Rule::SixteenPercent {
            r.push_str(&format!(" (at most {n_allowed} allowed)"));
        }
        r
    };
    if !differ.is_empty() {
        reason.push_str(&format!("; not compared: {}", differ.join("; ")));
    }
    let line_u_pct = match (instrument.expanded_relative_pct, scaling) {
        (Some(p), uncertainty::Scaling::Height) => p,
        _ => 0.0,
    };
    LimitVerdict {
        callout: c.text.clone(),
        parameter: c.parameter,
        side: c.side,
        rule: c.rule,
        limit_um: c.limit_um,
        sampling_lengths: c.evaluation_sampling_lengths(),
        verdict,
        n_values: t.n,
        n_beyond: t.beyond,
        n_undecided: t.undecided,
        n_not_measured: t.missing,
        n_allowed,
        line_u_pct,
        min_um: lo.is_finite().then_some(lo),
        max_um: hi.is_finite().then_some(hi),
        lines_beyond: beyond,
        lines_undecided: undecided,
        lines_without_value: without,
        conditions_differ: differ,
        lines_with_warnings: Vec::new(),
        verdict_without_them: None,
        reason,
    }
}

/// Judges one limit on all the lines and on those without a read-out warning: a verdict
/// that the flagged lines decide is not decidable, naming them (a verdict is never
/// stronger than the lines support).
fn judge_limit_weighing_warnings(
    c: &Callout,
    lines: &[LineValues<'_>],
    not_measured: usize,
    band: Option<&EvaluatedBand>,
    instrument: &InstrumentUncertainty,
) -> LimitVerdict {
    let mut v = judge_limit(c, lines, not_measured, band, instrument);
    let kept: Vec<LineValues<'_>> = lines.iter().filter(|l| !l.flagged).copied().collect();
    if kept.len() == lines.len() {
        return v;
    }
    let without = judge_limit(c, &kept, not_measured, band, instrument).verdict;
    v.lines_with_warnings = lines
        .iter()
        .filter(|l| l.flagged)
        .map(|l| line_number(l.index))
        .collect();
    v.verdict_without_them = Some(without);
    if without != v.verdict {
        let named: Vec<String> = v.lines_with_warnings.iter().map(u64::to_string).collect();
        v.reason.push_str(&format!(
            "; rests on line{} {} kept with a read-out warning: {} with {}, {without} without",
            if named.len() == 1 { "" } else { "s" },
            named.join(", "),
            v.verdict,
            if named.len() == 1 { "it" } else { "them" },
        ));
        v.verdict = Verdict::NotDecidable;
    }
    v
}

/// The verdict of the lines against `spec`: one [`LimitVerdict`] per limit and the scan's
/// (does not conform when any limit does not, conforms when all do, else not decidable).
/// `planned_lines` is how many lines the scan's plan asks for (`None` for a grid: the lines
/// given are the surface); the planned lines missing from `lines` count as undecided values.
/// A limit whose verdict changes when the lines kept with a read-out warning are left out
/// is not decidable.
/// `band` is what the lines were evaluated with (`None` when they are not roughness
/// profiles); `instrument` is the station's stated uncertainty.
pub fn judge(
    spec: &Specification,
    lines: &[LineValues<'_>],
    planned_lines: Option<usize>,
    band: Option<&EvaluatedBand>,
    instrument: &InstrumentUncertainty,
) -> SpecificationVerdict {
    let not_measured = planned_lines.map_or(0, |p| p.saturating_sub(lines.len()));
    let limits: Vec<LimitVerdict> = spec
        .limits
        .iter()
        .map(|c| judge_limit_weighing_warnings(c, lines, not_measured, band, instrument))
        .collect();
    let verdict = Verdict::all(limits.iter().map(|l| l.verdict));
    let deciding: Vec<&str> = limits
        .iter()
        .filter(|l| verdict == Verdict::Conforms || l.verdict == verdict)
        .map(|l| l.reason.as_str())
        .collect();
    let summary = if deciding.is_empty() {
        verdict.to_string()
    } else {
        format!("{verdict} ({})", deciding.join("; "))
    };
    SpecificationVerdict {
        verdict,
        summary,
        decision_rule: DECISION_RULE,
        instrument_uncertainty: instrument.statement(),
        limits,
        material_ratio: None,
    }
}

#[cfg(test)]
mod tests;
