//! The acceptance rules for a surface's measured values (ISO 4288:1996 §5.2–5.3, ISO
//! 21920-3) under the decision rule of ISO 14253-1: conformance and non-conformance are
//! proven only beyond the expanded uncertainty.
//!
//! Each measured value (one line's parameter over its evaluation length) stands within the
//! limit, beyond it, or — when the limit lies inside its uncertainty interval `value ± U` —
//! undecided. The 16 % rule accepts a surface when not more than 16 % of its values lie
//! beyond the limit; the max rule when none does. The surface then
//!
//! - **conforms** when the rule is met even with every undecided value counted beyond;
//! - **does not conform** when the rule is broken even with every undecided value counted
//!   within;
//! - is **not decidable** otherwise (and when there is no value at all).
//!
//! A scan that ended before its last line (or whose reader left lines out) has fewer values
//! than the surface it was planned to measure: each planned line without a value is counted
//! as undecided too, over the planned count. A partial scan therefore conforms only if its
//! surface would conform whatever the missing lines hold, and does not conform only if it
//! would not whatever they hold; under the max rule it never conforms.
//!
//! With U = 0 no value is undecided: a value exactly at an upper limit does not exceed it,
//! and exactly 16 % of the values beyond still meets the 16 % rule ("not more than").
//!
//! Layer 1 (pure): depends on [`super::callout`] only.

use super::callout::{Rule, Side};
use serde::Serialize;
use std::fmt;

/// The verdict on one limit or a whole specification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
pub enum Verdict {
    /// Conformance is proven beyond the uncertainty.
    #[serde(rename = "conforms")]
    Conforms,
    /// Non-conformance is proven beyond the uncertainty.
    #[serde(rename = "does not conform")]
    DoesNotConform,
    /// Neither is proven (values within the uncertainty of the limit decide it, no values,
    /// or the values are not those the callout asks for).
    #[serde(rename = "not decidable")]
    NotDecidable,
}

impl Verdict {
    /// `conforms`, `does not conform` or `not decidable`, as report.json spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Conforms => "conforms",
            Verdict::DoesNotConform => "does not conform",
            Verdict::NotDecidable => "not decidable",
        }
    }

    /// The verdict named `s` ([`Verdict::as_str`], in any case, with spaces, dashes or
    /// underscores between the words: `does-not-conform` on a command line).
    pub fn parse(s: &str) -> Option<Verdict> {
        let norm = s.trim().to_ascii_lowercase().replace(['-', '_'], " ");
        [
            Verdict::Conforms,
            Verdict::DoesNotConform,
            Verdict::NotDecidable,
        ]
        .into_iter()
        .find(|v| v.as_str() == norm)
    }

    /// The verdict of several limits together: does not conform when any limit does not,
    /// conforms when every limit does, not decidable otherwise (and for no limit at all).
    pub fn all(verdicts: impl IntoIterator<Item = Verdict>) -> Verdict {
        let mut any = false;
        let mut all_conform = true;
        for v in verdicts {
            any = true;
            match v {
                Verdict::DoesNotConform => return Verdict::DoesNotConform,
                Verdict::NotDecidable => all_conform = false,
                Verdict::Conforms => {}
            }
        }
        if any && all_conform {
            Verdict::Conforms
        } else {
            Verdict::NotDecidable
        }
    }
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Where one measured value stands against a limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Standing {
    /// `value ± U` lies entirely on the allowed side (touching the limit at most).
    Within,
    /// The limit lies inside `value ± U`.
    Undecided,
    /// `value ± U` lies entirely beyond the limit.
    Beyond,
}

/// Where `value` with expanded uncertainty `u` (≥ 0) stands against `limit` on `side`.
pub fn standing(value: f64, u: f64, limit: f64, side: Side) -> Standing {
    let excess = match side {
        Side::Upper => value - limit,
        Side::Lower => limit - value,
    };
    if excess - u > 0.0 {
        Standing::Beyond
    } else if excess + u <= 0.0 {
        Standing::Within
    } else {
        Standing::Undecided
    }
}

/// How a surface's values stand against a limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Tally {
    /// Measured values.
    pub n: usize,
    /// Values proven beyond the limit.
    pub beyond: usize,
    /// Values whose uncertainty interval holds the limit.
    pub undecided: usize,
    /// Values the plan asked for that were not measured (lines not traced, or left out):
    /// undecided, beside the `n` measured.
    pub missing: usize,
}

impl Tally {
    /// Counts one value's standing.
    pub fn add(&mut self, s: Standing) {
        self.n += 1;
        match s {
            Standing::Beyond => self.beyond += 1,
            Standing::Undecided => self.undecided += 1,
            Standing::Within => {}
        }
    }
}

/// Whether `beyond` of `n` values meet the rule.
pub fn meets(rule: Rule, beyond: usize, n: usize) -> bool {
    match rule {
        // "Not more than 16 %", in integers so that exactly 16 % is exactly at the rule.
        Rule::SixteenPercent => 100 * beyond as u128 <= 16 * n as u128,
        Rule::Max => beyond == 0,
    }
}

/// The verdict of `rule` on a tally, by ISO 14253-1's default decision rule, over the
/// `n + missing` values the surface was to have.
pub fn decide(rule: Rule, t: Tally) -> Verdict {
    let planned = t.n + t.missing;
    if t.n == 0 {
        Verdict::NotDecidable
    } else if meets(rule, t.beyond + t.undecided + t.missing, planned) {
        Verdict::Conforms
    } else if !meets(rule, t.beyond, planned) {
        Verdict::DoesNotConform
    } else {
        Verdict::NotDecidable
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Rule::{Max, SixteenPercent as P16};
    use Verdict::{Conforms as C, DoesNotConform as NC, NotDecidable as ND};

    /// A tally of `n` measured values, `beyond` and `undecided` of them, `missing` not measured.
    fn counts(n: usize, beyond: usize, undecided: usize, missing: usize) -> Tally {
        Tally {
            n,
            beyond,
            undecided,
            missing,
        }
    }

    fn tally(values: &[f64], u: f64, limit: f64, side: Side) -> Tally {
        let mut t = Tally::default();
        for &v in values {
            t.add(standing(v, u, limit, side));
        }
        t
    }

    #[test]
    fn sixteen_percent_of_a_count_is_met_exactly_at_sixteen_percent() {
        // 16 % of 25 is 4: 4 beyond meets the rule, 5 (20 %) does not.
        assert!(meets(P16, 4, 25));
        assert!(!meets(P16, 5, 25));
        // 16 % of 50 is 8.
        assert!(meets(P16, 8, 50));
        assert!(!meets(P16, 9, 50));
        // 16 % of 31 is 4.96: 4 lines (12.9 %) meet it, 5 (16.1 %) do not.
        assert!(meets(P16, 4, 31));
        assert!(!meets(P16, 5, 31));
        // 16 % of 6 is 0.96: one value of six beyond (16.7 %) breaks the rule.
        assert!(meets(P16, 0, 6));
        assert!(!meets(P16, 1, 6));
        // 16 % of 100 is 16.
        assert!(meets(P16, 16, 100));
        assert!(!meets(P16, 17, 100));
        assert!(meets(Max, 0, 31));
        assert!(!meets(Max, 1, 31));
    }

    #[test]
    fn hand_computed_surfaces_under_both_rules() {
        // 25 values of Ra against an upper limit of 0.8 µm, U = 0: 21 at 0.70, four at
        // 0.85 (exactly 16 %).
        let mut v = vec![0.70; 21];
        v.extend([0.85; 4]);
        let t = tally(&v, 0.0, 0.8, Side::Upper);
        assert_eq!((t.n, t.beyond, t.undecided), (25, 4, 0));
        assert_eq!(decide(P16, t), C);
        assert_eq!(decide(Max, t), NC);
        // A fifth value above (20 %): the 16 % rule is broken.
        v[0] = 0.81;
        assert_eq!(decide(P16, tally(&v, 0.0, 0.8, Side::Upper)), NC);
        // A value exactly at the limit does not exceed it.
        let t = tally(&[0.8, 0.5, 0.6], 0.0, 0.8, Side::Upper);
        assert_eq!((t.beyond, t.undecided), (0, 0));
        assert_eq!(decide(Max, t), C);
        // Lower limit 0.4 µm: 0.39 is beyond, 0.4 is not.
        let t = tally(&[0.39, 0.4, 0.5, 0.6, 0.7, 0.8], 0.0, 0.4, Side::Lower);
        assert_eq!((t.n, t.beyond), (6, 1));
        assert_eq!(decide(P16, t), NC, "1 of 6 is 16.7 %");
        assert_eq!(decide(Max, t), NC);
        assert_eq!(
            decide(P16, Tally::default()),
            ND,
            "no values decide nothing"
        );
    }

    #[test]
    fn near_the_limit_a_value_is_undecided_and_the_verdict_with_it() {
        // Upper limit 6.3 µm, U = 0.2 µm per value.
        assert_eq!(standing(6.0, 0.2, 6.3, Side::Upper), Standing::Within);
        assert_eq!(
            standing(6.1, 0.2, 6.3, Side::Upper),
            Standing::Within,
            "6.1 + 0.2 reaches 6.3, does not exceed it"
        );
        assert_eq!(standing(6.2, 0.2, 6.3, Side::Upper), Standing::Undecided);
        assert_eq!(standing(6.3, 0.2, 6.3, Side::Upper), Standing::Undecided);
        assert_eq!(standing(6.45, 0.2, 6.3, Side::Upper), Standing::Undecided);
        assert_eq!(standing(6.6, 0.2, 6.3, Side::Upper), Standing::Beyond);
        assert_eq!(standing(0.35, 0.1, 0.4, Side::Lower), Standing::Undecided);
        assert_eq!(standing(0.25, 0.1, 0.4, Side::Lower), Standing::Beyond);

        // 25 values: 3 proven above, 2 undecided. Counted beyond: 5 of 25 (20 %) breaks
        // the rule; counted within: 3 of 25 (12 %) meets it. Not decidable.
        let t = counts(25, 3, 2, 0);
        assert_eq!(decide(P16, t), ND);
        // 1 undecided: 4 of 25 at worst is exactly 16 %: conforms.
        assert_eq!(decide(P16, counts(25, 3, 1, 0)), C);
        // 5 proven above: 20 % whatever the undecided ones are.
        assert_eq!(decide(P16, counts(25, 5, 7, 0)), NC);
        // The max rule: one undecided value and none proven beyond is not decidable; one
        // proven beyond does not conform.
        assert_eq!(decide(Max, counts(25, 0, 1, 0)), ND);
        assert_eq!(decide(Max, counts(25, 1, 3, 0)), NC);
        assert_eq!(decide(Max, counts(25, 0, 0, 0)), C);

        // The same values with and without an uncertainty: what U = 0 calls conforming
        // is not decidable once U holds the limit.
        let v = [6.25, 6.0, 5.9, 5.5, 5.8];
        assert_eq!(decide(Max, tally(&v, 0.0, 6.3, Side::Upper)), C);
        assert_eq!(decide(Max, tally(&v, 0.1, 6.3, Side::Upper)), ND);
    }

    #[test]
    fn a_partial_scan_counts_its_missing_lines_as_undecided() {
        // 31 lines planned, 20 traced, none beyond: under the 16 % rule, 11 lines that might
        // all be beyond are 35 % of 31, so it is not decidable; the traced 20 alone would
        // conform.
        assert_eq!(decide(P16, counts(20, 0, 0, 0)), C);
        assert_eq!(decide(P16, counts(20, 0, 0, 11)), ND);
        // 28 of 31 traced, one beyond: 1 + 3 = 4 of 31 (12.9 %) meets the rule whatever the
        // three missing hold; one more undecided value (5 of 31, 16.1 %) leaves it open.
        assert_eq!(decide(P16, counts(28, 1, 0, 3)), C);
        assert_eq!(decide(P16, counts(28, 1, 1, 3)), ND);
        // 20 of 31 traced, 5 beyond: 5 of 31 (16.1 %) breaks the rule even if the 11 missing
        // are all within, so it does not conform; 4 beyond (4 of 31, 12.9 %) might still
        // conform, though 4 of the 20 traced (20 %) would not.
        assert_eq!(decide(P16, counts(20, 5, 0, 11)), NC);
        assert_eq!(decide(P16, counts(20, 4, 0, 11)), ND);
        assert_eq!(decide(P16, counts(20, 4, 0, 0)), NC);
        // The max rule: one value beyond decides it; a missing line keeps it from conforming.
        assert_eq!(decide(Max, counts(30, 1, 0, 1)), NC);
        assert_eq!(decide(Max, counts(30, 0, 0, 1)), ND);
        assert_eq!(decide(Max, counts(31, 0, 0, 0)), C);
        // No value at all decides nothing.
        assert_eq!(decide(P16, counts(0, 0, 0, 31)), ND);
    }

    #[test]
    fn the_verdicts_of_several_limits_combine() {
        assert_eq!(Verdict::all([C, C]), C);
        assert_eq!(Verdict::all([C, ND]), ND);
        assert_eq!(Verdict::all([ND, NC, C]), NC);
        assert_eq!(Verdict::all([]), ND);
        assert_eq!(serde_json::to_string(&NC).unwrap(), "\"does not conform\"");
        for v in [C, NC, ND] {
            assert_eq!(Verdict::parse(v.as_str()), Some(v));
        }
        assert_eq!(Verdict::parse("not-decidable"), Some(ND));
        assert_eq!(Verdict::parse("ok"), None);
    }
}
