//! One limit of a part's surface specification, written as a drawing writes it
//! (ISO 21920-1:2021, ISO 1302:2002), and its parser.
//!
//! The accepted form, tokens separated by spaces:
//!
//! ```text
//! [U|L] [λs-λc/]PARAMETER[N] [max] LIMIT [µm]
//! ```
//!
//! - `U` (upper limit, the default) or `L` (lower limit);
//! - a transmission band in mm, `0.0025-0.8/`; either end may be left out (`-0.8/` states λc
//!   only, `0.0025-/` λs only);
//! - the parameter, with the number of sampling lengths of its evaluation length written
//!   after it (`Rz3`; none written means the default 5 of ISO 4288 / ISO 21920-3);
//! - `max` for the max rule (no measured value may exceed the limit); without it the 16 %
//!   rule applies (ISO 4288:1996 §5.2–5.3);
//! - the limit in µm, a decimal number with a point, optionally followed by `µm`.
//!
//! Examples: `"Ra 0.8"`, `"Rz max 6.3"`, `"U Ra 1.6"`, `"L Ra 0.4"`, `"0.0025-0.8/Rz3 3.2"`.
//! Anything else is refused with the reason and the accepted form: a limit is never guessed
//! (`"Ra0.8"`, a decimal comma, another unit, a parameter the scan does not compute).
//!
//! Layer 1 (pure): depends on [`crate::metrology::params`] for the per-line values a
//! parameter names; no I/O.

use crate::metrology::params::RoughnessParams;
use serde::Serialize;
use std::fmt;

/// Which side of the tolerance a limit bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// Values must not exceed the limit (`U`, the default).
    Upper,
    /// Values must not fall below the limit (`L`).
    Lower,
}

/// How many measured values may lie beyond the limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Rule {
    /// ISO 4288:1996 §5.2: the surface is acceptable when not more than 16 % of the measured
    /// values lie beyond the limit.
    #[serde(rename = "16 %")]
    SixteenPercent,
    /// ISO 4288:1996 §5.3 (`max` in the callout): none of the measured values may lie beyond
    /// the limit.
    #[serde(rename = "max")]
    Max,
}

impl Rule {
    /// `16 % rule` or `max rule`, for messages.
    pub fn name(self) -> &'static str {
        match self {
            Rule::SixteenPercent => "16 % rule",
            Rule::Max => "max rule",
        }
    }
}

/// A transmission band as a callout states it, in mm; an end not written is `None`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Band {
    /// Short-wave cut-off λs, mm.
    pub lambda_s_mm: Option<f64>,
    /// Long-wave cut-off λc, mm.
    pub lambda_c_mm: Option<f64>,
}

/// The default number of sampling lengths of an evaluation length when a callout writes
/// none (ISO 4288:1996 §4.4, ISO 21920-3).
pub const DEFAULT_SAMPLING_LENGTHS: u32 = 5;

/// A parameter a limit can be set on: the per-line profile parameters this crate computes
/// whose value is a length in µm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub enum Parameter {
    /// Arithmetic mean deviation.
    Ra,
    /// Root mean square deviation.
    Rq,
    /// Maximum peak height.
    Rp,
    /// Maximum valley depth.
    Rv,
    /// Maximum height (ISO 4287:1997 / ISO 21920-2).
    Rz,
    /// Total height.
    Rt,
    /// Largest single-section Rz.
    Rz1max,
    /// JIS ten-point height.
    RzJIS,
    /// Mean height of profile elements.
    Rc,
    /// Mean width of profile elements.
    RSm,
    /// Core roughness depth (ISO 13565-2).
    Rk,
    /// Reduced peak height.
    Rpk,
    /// Reduced valley depth.
    Rvk,
}

impl Parameter {
    /// Every parameter a limit can be set on, in the order messages list them.
    pub const ALL: [Parameter; 13] = [
        Parameter::Ra,
        Parameter::Rq,
        Parameter::Rp,
        Parameter::Rv,
        Parameter::Rz,
        Parameter::Rt,
        Parameter::Rz1max,
        Parameter::RzJIS,
        Parameter::Rc,
        Parameter::RSm,
        Parameter::Rk,
        Parameter::Rpk,
        Parameter::Rvk,
    ];

    /// The name as a drawing writes it.
    pub fn name(self) -> &'static str {
        match self {
            Parameter::Ra => "Ra",
            Parameter::Rq => "Rq",
            Parameter::Rp => "Rp",
            Parameter::Rv => "Rv",
            Parameter::Rz => "Rz",
            Parameter::Rt => "Rt",
            Parameter::Rz1max => "Rz1max",
            Parameter::RzJIS => "RzJIS",
            Parameter::Rc => "Rc",
            Parameter::RSm => "RSm",
            Parameter::Rk => "Rk",
            Parameter::Rpk => "Rpk",
            Parameter::Rvk => "Rvk",
        }
    }

    /// A line's value of this parameter, µm; `None` when the line has none (RSm, Rc and
    /// RzJIS need enough profile elements).
    pub fn value(self, p: &RoughnessParams) -> Option<f64> {
        match self {
            Parameter::Ra => Some(p.ra_um),
            Parameter::Rq => Some(p.rq_um),
            Parameter::Rp => Some(p.rp_um),
            Parameter::Rv => Some(p.rv_um),
            Parameter::Rz => Some(p.rz_um),
            Parameter::Rt => Some(p.rt_um),
            Parameter::Rz1max => Some(p.rz1max_um),
            Parameter::RzJIS => p.rzjis_um,
            Parameter::Rc => p.rc_um,
            Parameter::RSm => p.rsm_um,
            Parameter::Rk => Some(p.material.rk.rk_um),
            Parameter::Rpk => Some(p.material.rk.rpk_um),
            Parameter::Rvk => Some(p.material.rk.rvk_um),
        }
    }

    /// The largest limit that can be meant in µm: heights beyond any stylus instrument's
    /// range (the SJ-210's is 360 µm) and widths beyond the longest cut-off (8 mm) are a
    /// unit mix-up.
    fn plausible_max_um(self) -> f64 {
        match self {
            Parameter::RSm => 8000.0,
            _ => 400.0,
        }
    }

    /// The accepted names, for messages.
    pub fn names() -> String {
        Parameter::ALL.map(Parameter::name).join(", ")
    }
}

impl fmt::Display for Parameter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One limit of a specification.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Callout {
    /// The callout as written (trimmed).
    pub text: String,
    /// Upper or lower limit.
    pub side: Side,
    /// The transmission band the callout states, if any.
    pub band: Option<Band>,
    /// The parameter.
    pub parameter: Parameter,
    /// The number of sampling lengths written after the parameter (`Rz3`), `None` when
    /// none is written ([`DEFAULT_SAMPLING_LENGTHS`] applies).
    pub sampling_lengths: Option<u32>,
    /// The 16 % rule or the max rule.
    pub rule: Rule,
    /// The limit, µm.
    pub limit_um: f64,
}

impl Callout {
    /// The number of sampling lengths the callout asks for (its own, or the default 5).
    pub fn evaluation_sampling_lengths(&self) -> u32 {
        self.sampling_lengths.unwrap_or(DEFAULT_SAMPLING_LENGTHS)
    }

    /// `above` for an upper limit, `below` for a lower one.
    pub fn beyond_word(&self) -> &'static str {
        match self.side {
            Side::Upper => "above",
            Side::Lower => "below",
        }
    }

    /// The parameter with the number of sampling lengths as written: `Rz3`, `Ra`.
    pub fn parameter_label(&self) -> String {
        match self.sampling_lengths {
            Some(n) => format!("{}{n}", self.parameter),
            None => self.parameter.to_string(),
        }
    }
}

/// The accepted form, for every refusal.
pub const ACCEPTED_FORM: &str = "a limit is written [U|L] [λs-λc/]PARAMETER[N] [max] LIMIT_µm, e.g. \"Ra 0.8\", \"Rz max 6.3\", \"U Ra 1.6\", \"L Ra 0.4\", \"0.0025-0.8/Rz3 3.2\"";

/// A callout that cannot be read: the text, what is wrong, and the accepted form.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{text:?}: {problem}; {ACCEPTED_FORM}")]
pub struct CalloutError {
    /// The callout as written.
    pub text: String,
    /// What is wrong and what to write instead.
    pub problem: String,
}

/// Units a limit or a band may be mistaken in, with the factor to µm (for the hint).
const OTHER_UNITS: [(&str, f64); 7] = [
    ("mm", 1000.0),
    ("nm", 0.001),
    ("m", 1e6),
    ("in", 25_400.0),
    ("µin", 0.0254),
    ("μin", 0.0254),
    ("uin", 0.0254),
];

fn is_micrometre(unit: &str) -> bool {
    matches!(unit, "µm" | "μm" | "um")
}

/// A decimal number with a point; a comma or anything else is refused with the reason.
fn number(s: &str, what: &str) -> Result<f64, String> {
    if s.contains(',') {
        return Err(format!(
            "{what} {s:?} has a decimal comma: write it with a point ({})",
            s.replace(',', ".")
        ));
    }
    let ok = !s.is_empty()
        && s.chars().all(|c| c.is_ascii_digit() || c == '.')
        && s.chars().filter(|&c| c == '.').count() <= 1
        && s.chars().any(|c| c.is_ascii_digit());
    match s.parse::<f64>() {
        Ok(v) if ok && v.is_finite() => Ok(v),
        _ => Err(format!("{what} {s:?} is not a decimal number")),
    }
}

/// Splits `0.8µm` into the number and the unit written after it.
fn split_unit(token: &str) -> (&str, &str) {
    let end = token
        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == ','))
        .unwrap_or(token.len());
    token.split_at(end)
}

fn band(text: &str) -> Result<Band, String> {
    let Some((s, c)) = text.split_once('-') else {
        return Err(format!(
            "the transmission band {text:?} must be λs-λc in mm, e.g. \"0.0025-0.8/\" (\"-0.8/\" for λc alone)"
        ));
    };
    let end = |t: &str, what: &str| -> Result<Option<f64>, String> {
        let t = t.trim();
        if t.is_empty() {
            return Ok(None);
        }
        let (num, unit) = split_unit(t);
        if !unit.is_empty() && unit != "mm" {
            return Err(format!(
                "the band's {what} {t:?} is not in mm: a band is written in mm, e.g. 0.0025-0.8"
            ));
        }
        let v = number(num, &format!("the band's {what}"))?;
        if v <= 0.0 {
            return Err(format!("the band's {what} must be above 0 mm"));
        }
        Ok(Some(v))
    };
    let band = Band {
        lambda_s_mm: end(s, "λs")?,
        lambda_c_mm: end(c, "λc")?,
    };
    match (band.lambda_s_mm, band.lambda_c_mm) {
        (None, None) => Err(format!(
            "the transmission band {text:?} names neither λs nor λc"
        )),
        (_, Some(c)) if c > 100.0 => Err(format!(
            "the band's λc {c} mm is beyond any cut-off (0.08 to 8 mm): a band is written in mm"
        )),
        (Some(s), _) if s > 1.0 => Err(format!(
            "the band's λs {s} mm is beyond any short-wave cut-off (0.0025 to 0.025 mm): a band is written in mm"
        )),
        (Some(s), Some(c)) if s >= c => Err(format!(
            "the band's λs {s} mm must be shorter than its λc {c} mm"
        )),
        _ => Ok(band),
    }
}

/// The parameter token: a parameter name and the number of sampling lengths after it.
fn parameter(token: &str) -> Result<(Parameter, Option<u32>), String> {
    // Longest name first, so `Rz1max` and `RzJIS` are not read as `Rz` followed by text.
    let mut names: Vec<Parameter> = Parameter::ALL.to_vec();
    names.sort_by_key(|p| std::cmp::Reverse(p.name().len()));
    let found = names.into_iter().find_map(|p| {
        let n = p.name().len();
        let head = token.get(..n)?;
        (head == p.name() || head.eq_ignore_ascii_case(p.name())).then(|| (p, &token[n..]))
    });
    let Some((p, rest)) = found else {
        return Err(format!(
            "{token:?} is not a parameter a scan computes (accepted: {})",
            Parameter::names()
        ));
    };
    if rest.is_empty() {
        return Ok((p, None));
    }
    if rest.eq_ignore_ascii_case("max") {
        return Err(format!(
            "write the max rule apart from the parameter: \"{p} max …\""
        ));
    }
    if rest.contains('.') || rest.contains(',') {
        return Err(format!(
            "put a space between the parameter and the limit: \"{p} {rest}\""
        ));
    }
    match rest.parse::<u32>() {
        Ok(n) if (1..=50).contains(&n) && rest.chars().all(|c| c.is_ascii_digit()) => {
            Ok((p, Some(n)))
        }
        Ok(_) => Err(format!(
            "{token:?}: the number of sampling lengths must be 1 to 50"
        )),
        Err(_) => Err(format!(
            "{token:?} is not a parameter a scan computes (accepted: {}), optionally followed by its number of sampling lengths (Rz3)",
            Parameter::names()
        )),
    }
}

impl std::str::FromStr for Callout {
    type Err = CalloutError;

    fn from_str(text: &str) -> Result<Callout, CalloutError> {
        let text = text.trim();
        parse(text).map_err(|problem| CalloutError {
            text: text.to_owned(),
            problem,
        })
    }
}

fn parse(text: &str) -> Result<Callout, String> {
    if text.is_empty() {
        return Err("the limit is empty".into());
    }
    let mut rest = text;
    let mut side = Side::Upper;
    let word = rest.split_whitespace().next().unwrap_or("");
    if word == "U" || word == "L" {
        side = if word == "U" {
            Side::Upper
        } else {
            Side::Lower
        };
        rest = rest[1..].trim_start();
    }
    let (band, rest) = match rest.split_once('/') {
        Some((b, r)) => (Some(band(b.trim())?), r.trim_start()),
        None => (None, rest),
    };
    let mut tokens = rest.split_whitespace();
    let Some(ptoken) = tokens.next() else {
        return Err("no parameter after the band".into());
    };
    if ptoken == "U" || ptoken == "L" {
        return Err(format!(
            "{ptoken} comes first, before the band and the parameter"
        ));
    }
    let (parameter, sampling_lengths) = parameter(ptoken)?;
    let mut next = tokens.next();
    let mut rule = Rule::SixteenPercent;
    if let Some(t) = next {
        if t.eq_ignore_ascii_case("max") {
            rule = Rule::Max;
            next = tokens.next();
        } else if t.eq_ignore_ascii_case("min") {
            return Err("\"min\" is not a rule: a lower limit is written with L, e.g. \"L Ra 0.4\" (16 % rule) or \"L Ra max 0.4\" (max rule: no value below)".into());
        }
    }
    let Some(ltoken) = next else {
        return Err(format!("no limit after {ptoken}: write the limit in µm"));
    };
    if ltoken.starts_with(['-', '+']) {
        return Err(format!(
            "the limit {ltoken} must be a positive number of µm (a lower limit is written with L before the parameter)"
        ));
    }
    let (num, mut unit) = split_unit(ltoken);
    let mut tokens = tokens.peekable();
    if unit.is_empty() {
        if let Some(u) =
            tokens.next_if(|t| !t.starts_with(|c: char| c.is_ascii_digit() || c == '.'))
        {
            unit = u;
        }
    }
    if !unit.is_empty() && !is_micrometre(unit) {
        return Err(match OTHER_UNITS.iter().find(|(u, _)| *u == unit) {
            Some((u, f)) => {
                let hint = number(num, "the limit")
                    .map(|v| format!(" ({v} {u} is {} µm)", crate::numfmt::sig(v * f, 4)))
                    .unwrap_or_default();
                format!("the limit is in {u}: limits are written in µm (ISO 1302){hint}")
            }
            None => format!("{unit:?} after the limit is not a unit: limits are written in µm"),
        });
    }
    let limit_um = number(num, "the limit")?;
    if limit_um <= 0.0 {
        return Err(format!("the limit {num} µm must be above 0"));
    }
    if limit_um > parameter.plausible_max_um() {
        return Err(format!(
            "a {parameter} limit of {limit_um} µm is beyond what a stylus profile measures (at most {} µm): limits are written in µm",
            parameter.plausible_max_um()
        ));
    }
    if let Some(extra) = tokens.next() {
        return Err(format!("unexpected {extra:?} after the limit"));
    }
    Ok(Callout {
        text: text.to_owned(),
        side,
        band,
        parameter,
        sampling_lengths,
        rule,
        limit_um,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(text: &str) -> Callout {
        text.parse()
            .unwrap_or_else(|e| panic!("{text:?} refused: {e}"))
    }

    fn refused(text: &str) -> String {
        match text.parse::<Callout>() {
            Ok(c) => panic!("{text:?} accepted as {c:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn the_forms_of_the_standards_are_read() {
        let c = ok("Ra 0.8");
        assert_eq!(
            (
                c.side,
                c.band,
                c.parameter,
                c.sampling_lengths,
                c.rule,
                c.limit_um
            ),
            (
                Side::Upper,
                None,
                Parameter::Ra,
                None,
                Rule::SixteenPercent,
                0.8
            )
        );
        assert_eq!(c.evaluation_sampling_lengths(), 5);
        let c = ok("Rz max 6.3");
        assert_eq!(
            (c.parameter, c.rule, c.limit_um),
            (Parameter::Rz, Rule::Max, 6.3)
        );
        let c = ok("U Ra 1.6");
        assert_eq!((c.side, c.limit_um), (Side::Upper, 1.6));
        let c = ok("L Ra 0.4");
        assert_eq!(
            (c.side, c.parameter, c.limit_um),
            (Side::Lower, Parameter::Ra, 0.4)
        );
        let c = ok("0.0025-0.8/Rz3 3.2");
        assert_eq!(
            c.band,
            Some(Band {
                lambda_s_mm: Some(0.0025),
                lambda_c_mm: Some(0.8)
            })
        );
        assert_eq!(
            (c.parameter, c.sampling_lengths, c.limit_um),
            (Parameter::Rz, Some(3), 3.2)
        );
        assert_eq!(c.evaluation_sampling_lengths(), 3);
        assert_eq!(c.parameter_label(), "Rz3");
        assert_eq!(c.text, "0.0025-0.8/Rz3 3.2");
    }

    #[test]
    fn variants_a_drawing_may_use_are_read_alike() {
        let c = ok("  L 0.008-2.5 / Rz1max max 12.5 µm ");
        assert_eq!(
            (c.side, c.parameter, c.sampling_lengths, c.rule, c.limit_um),
            (Side::Lower, Parameter::Rz1max, None, Rule::Max, 12.5)
        );
        assert_eq!(c.band.unwrap().lambda_c_mm, Some(2.5));
        assert_eq!(ok("-0.8/Ra 0.8").band.unwrap().lambda_s_mm, None);
        assert_eq!(ok("0.0025-/Ra 0.8").band.unwrap().lambda_c_mm, None);
        assert_eq!(ok("Ra 0.8um").limit_um, 0.8);
        assert_eq!(ok("RzJIS 3.2").parameter, Parameter::RzJIS);
        assert_eq!(ok("Rsm 120").parameter, Parameter::RSm);
        assert_eq!(ok("RSm 120").parameter, Parameter::RSm);
        assert_eq!(ok("Rpk MAX 0.3").rule, Rule::Max);
        assert_eq!(ok("Rz1 4").sampling_lengths, Some(1));
        assert_eq!(ok("Ra .8").limit_um, 0.8);
    }

    #[test]
    fn malformed_callouts_are_refused_with_the_accepted_form() {
        for (text, says) in [
            ("Ra0.8x", "space between the parameter and the limit"),
            ("Ra0.8", "space between the parameter and the limit"),
            ("Ra 0,8", "decimal comma"),
            ("Ra 0.8 mm", "in mm"),
            ("Ra 800 nm", "0.8000 µm"),
            ("Ra 32 µin", "in µin"),
            ("Ra 0.8x", "not a unit"),
            ("Ra", "no limit"),
            ("Ra max", "no limit"),
            ("Ra 0", "above 0"),
            ("Ra -0.8", "positive number"),
            ("Ra 1e-1", "not a unit"),
            ("Ra 800", "beyond what a stylus profile measures"),
            ("Sa 0.8", "not a parameter a scan computes"),
            ("Wt 2", "not a parameter"),
            ("Rzmax 6.3", "write the max rule apart"),
            ("Ra min 0.4", "lower limit is written with L"),
            ("Ra 0.8 0.4", "unexpected"),
            ("X Ra 0.8", "not a parameter"),
            ("0.8/Ra 0.8", "λs-λc in mm"),
            ("-/Ra 0.8", "neither λs nor λc"),
            ("0.8-0.0025/Ra 0.8", "shorter than its λc"),
            ("2.5-800/Ra 0.8", "written in mm"),
            ("0.0025-0.8mm/Ra 0.8", ""),
            ("Rz0 3", "1 to 50"),
            ("", "empty"),
            ("0.0025-0.8/ U Ra 0.8", "comes first"),
        ] {
            if says.is_empty() {
                ok(text);
                continue;
            }
            let e = refused(text);
            assert!(e.contains(says), "{text:?}: {e}");
            assert!(e.contains("[U|L] [λs-λc/]PARAMETER[N] [max]"), "{e}");
        }
    }
}
