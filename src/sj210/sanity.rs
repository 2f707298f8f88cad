//! Sanity checks of a profile read-out against itself and against the instrument's own
//! results: a block received twice in a row (the instrument's read-out cursor went back), and
//! the instrument's Ra against Ra computed here from the same heights.
//!
//! # The Ra rule
//!
//! Ours is the project's metrology ([`crate::metrology::params::analyze_profile`]: ISO 4287
//! Ra per sampling length, lr-mean, with the line's recorded conditions). It must agree with
//! the instrument's `Ra` to within
//!
//! - **2 % of the instrument's Ra + 0.005 µm for an R profile**: the instrument exported the
//!   heights it evaluated, relative to its own mean line, so the only differences are the
//!   printed resolution of the heights and of Ra (0.001 µm each) and where the sampling
//!   lengths split. Mitutoyo's own export agrees to the last printed digit (Ra 3.308 µm both);
//! - **10 % + 0.005 µm for a P profile**: we apply the ISO 16610-21 Gaussian λc filter
//!   ourselves, and the instrument filtered its primary profile with pre- and post-travel we
//!   never receive, so the ends of the mean line differ.
//!
//! Other profile kinds (W, motif, DF) are not compared, nor is a line without an instrument
//! `Ra` or too short for our evaluation; an `Ra` in µin or inches is converted, one in a unit
//! not known here is named ([`ra_unit_unknown`]).
//!
//! # The detector's range
//!
//! Heights whose span (highest minus lowest) is wider than the detector's measuring range
//! (the SJ-210's standard detector: 360 µm) cannot be the surface's: heights in the wrong
//! unit (nm read as µm makes them 1000× too large, and the instrument's own Ra with them, so
//! the Ra rule alone would not see it). A larger disagreement means the heights are not
//! the ones the instrument evaluated (another trace's, a shifted or repeated block, wrong
//! units).
//!
//! # Repeated blocks
//!
//! Two consecutive blocks with the same values, in the same order, are one block received
//! twice. A block whose values are all equal (a flat or clipped stretch) can legitimately
//! repeat and is not counted.
//!
//! Pure (layer 1): depends on [`crate::metrology`], [`crate::profile`] and [`crate::devices`]
//! (the warning types a line carries).

use crate::devices::ReadoutWarning;
pub use crate::devices::RepeatedBlock;
use crate::metrology::params::analyze_profile;
use crate::profile::{InstrumentResult, Profile, ProfileKind};
use serde::{Deserialize, Serialize};

/// Relative part of the Ra tolerance for an R profile.
pub const RA_REL_TOL_R: f64 = 0.02;
/// Relative part of the Ra tolerance for a P profile.
pub const RA_REL_TOL_P: f64 = 0.10;
/// Absolute part of the Ra tolerance, µm.
pub const RA_ABS_TOL_UM: f64 = 0.005;

/// The instrument's Ra against ours from the same heights.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RaCheck {
    /// The instrument's Ra, µm.
    pub instrument_um: f64,
    /// Ours from the read-out heights, µm.
    pub ours_um: f64,
    /// The allowed difference, µm (see the module docs).
    pub tolerance_um: f64,
}

impl RaCheck {
    /// |ours − instrument| ≤ tolerance.
    pub fn agrees(&self) -> bool {
        (self.ours_um - self.instrument_um).abs() <= self.tolerance_um
    }
}

/// How far, as a ratio either way, a line's Ra may be from the median Ra of the lines
/// before it. Ra across one part's surface varies by tens of percent, a lay or a feature by
/// a few times; a factor of 5 is none of that but a read-out in another unit (×1000), the
/// stylus lifted off the part or another surface.
pub const NEIGHBOUR_RA_FACTOR: f64 = 5.0;

/// At least this many lines before it are needed to judge a line against its neighbours;
/// the median is of at most [`NEIGHBOUR_RA_WINDOW`] of them, the latest.
pub const NEIGHBOUR_RA_MIN_LINES: usize = 3;

/// The most lines before it a line's Ra is compared with (the latest).
pub const NEIGHBOUR_RA_WINDOW: usize = 5;

/// The warning for a line whose Ra `ra_um` is more than [`NEIGHBOUR_RA_FACTOR`] times away
/// from the median of `before` (the Ra of the lines traced before it, oldest first; the
/// latest [`NEIGHBOUR_RA_WINDOW`] count), when at least [`NEIGHBOUR_RA_MIN_LINES`] are known.
pub fn ra_far_from_neighbours(ra_um: f64, before: &[f64]) -> Option<ReadoutWarning> {
    let mut window: Vec<f64> = before
        .iter()
        .rev()
        .take(NEIGHBOUR_RA_WINDOW)
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if window.len() < NEIGHBOUR_RA_MIN_LINES || !ra_um.is_finite() {
        return None;
    }
    window.sort_by(f64::total_cmp);
    let n = window.len();
    let median_um = if n % 2 == 1 {
        window[n / 2]
    } else {
        (window[n / 2 - 1] + window[n / 2]) / 2.0
    };
    let far = if median_um > 0.0 && ra_um > 0.0 {
        ra_um / median_um > NEIGHBOUR_RA_FACTOR || median_um / ra_um > NEIGHBOUR_RA_FACTOR
    } else {
        // A zero Ra beside non-zero ones (or the reverse): nothing was measured.
        (median_um > 0.0) != (ra_um > 0.0)
    };
    far.then_some(ReadoutWarning::RaFarFromNeighbours {
        ra_um,
        median_um,
        lines: n as u32,
        factor: NEIGHBOUR_RA_FACTOR,
    })
}

/// The instrument's `Ra` in µm among its results, when it reported one with a value.
pub fn instrument_ra_um(results: &[InstrumentResult]) -> Option<f64> {
    let r = results
        .iter()
        .find(|r| r.name.trim().eq_ignore_ascii_case("ra"))?;
    let v = r.value?;
    Some(v * micrometres_per(&r.unit)?)
}

/// µm per unit of a result's `unit` as the instrument prints it (µm, nm, mm, µin, in);
/// `None` for a unit this program does not know.
fn micrometres_per(unit: &str) -> Option<f64> {
    match unit.trim() {
        "um" | "µm" | "μm" | "" => Some(1.0),
        "nm" => Some(0.001),
        "mm" => Some(1000.0),
        "uin" | "µin" | "μin" | "uinch" | "µinch" | "μinch" => Some(0.0254),
        "in" | "inch" => Some(25_400.0),
        _ => None,
    }
}

/// The unit of the instrument's `Ra`, when it has a value in a unit this program does not
/// know (so it cannot be compared with the heights, which must be said).
pub fn ra_unit_unknown(results: &[InstrumentResult]) -> Option<String> {
    let r = results
        .iter()
        .find(|r| r.name.trim().eq_ignore_ascii_case("ra"))?;
    r.value?;
    micrometres_per(&r.unit)
        .is_none()
        .then(|| r.unit.trim().to_owned())
}

/// The span (highest minus lowest) of the finite `heights_um`, when it is wider than a
/// detector of `range_um` can measure.
pub fn span_beyond_range(heights_um: &[f64], range_um: f64) -> Option<f64> {
    let (lo, hi) = heights_um
        .iter()
        .filter(|h| h.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| {
            (lo.min(h), hi.max(h))
        });
    let span = hi - lo;
    (span.is_finite() && span > range_um).then_some(span)
}

/// Compares the instrument's Ra with ours from `profile`; `None` when it cannot be compared
/// (no instrument Ra, a profile kind other than R or P, or too short to evaluate).
pub fn check_ra(profile: &Profile, results: &[InstrumentResult]) -> Option<RaCheck> {
    let instrument_um = instrument_ra_um(results)?;
    let kind = profile.conditions.profile_kind.unwrap_or(profile.kind);
    let rel = match kind {
        ProfileKind::R => RA_REL_TOL_R,
        ProfileKind::P => RA_REL_TOL_P,
        ProfileKind::W | ProfileKind::Other => return None,
    };
    let ours_um = analyze_profile(profile).ok()?.params.ra_um;
    Some(RaCheck {
        instrument_um,
        ours_um,
        tolerance_um: rel * instrument_um.abs() + RA_ABS_TOL_UM,
    })
}

/// True when `block` is `previous` received again: same length (at least 2 values), same
/// values in the same order, and not all equal.
pub fn is_repeated_block(previous: &[f64], block: &[f64]) -> bool {
    block.len() >= 2 && previous == block && block.iter().any(|v| v != &block[0])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::Conditions;

    fn r(name: &str, v: Option<f64>, unit: &str) -> InstrumentResult {
        InstrumentResult {
            name: name.into(),
            value: v,
            unit: unit.into(),
            printed: v.map(|v| v.to_string()),
            ng_code: None,
        }
    }

    #[test]
    fn inch_results_are_compared_and_an_unknown_unit_is_named() {
        // 100 µin = 2.54 µm.
        let got = instrument_ra_um(&[r("Ra", Some(100.0), "uin")]).unwrap();
        assert!((got - 2.54).abs() < 1e-12, "{got}");
        assert!((instrument_ra_um(&[r("Ra", Some(0.0001), "in")]).unwrap() - 2.54).abs() < 1e-9);
        assert_eq!(ra_unit_unknown(&[r("Ra", Some(100.0), "uin")]), None);
        assert_eq!(
            ra_unit_unknown(&[r("Ra", Some(1.0), "furlong")]).as_deref(),
            Some("furlong")
        );
        assert_eq!(instrument_ra_um(&[r("Ra", Some(1.0), "furlong")]), None);
        // No value: nothing to compare, nothing to say.
        assert_eq!(ra_unit_unknown(&[r("Ra", None, "furlong")]), None);
    }

    #[test]
    fn a_span_wider_than_the_detector_is_found() {
        // Within ±180 µm: 360 µm exactly is possible.
        assert_eq!(span_beyond_range(&[-200.0, 160.0, 0.0], 360.0), None);
        assert_eq!(
            span_beyond_range(&[-1945.0, 2100.0, f64::NAN], 360.0),
            Some(4045.0)
        );
        assert_eq!(span_beyond_range(&[], 360.0), None);
    }

    fn r_profile(z: Vec<f64>) -> Profile {
        Profile {
            pitch_x_mm: 0.0015,
            heights_um: z,
            kind: ProfileKind::R,
            conditions: Conditions {
                profile_kind: Some(ProfileKind::R),
                lambda_c_mm: Some(0.08),
                sampling_lengths: Some(1),
                ..Conditions::default()
            },
        }
    }

    #[test]
    fn instrument_ra_by_name_and_unit() {
        let res = [r("Rq", Some(2.0), "um"), r(" RA ", Some(1.5), "\u{b5}m")];
        assert_eq!(instrument_ra_um(&res), Some(1.5));
        assert_eq!(instrument_ra_um(&[r("Ra", Some(1500.0), "nm")]), Some(1.5));
        assert_eq!(instrument_ra_um(&[r("Ra", None, "um")]), None);
        // Inches are converted (the SJ-210 can be set to inch units), not skipped.
        assert_eq!(
            instrument_ra_um(&[r("Ra", Some(1.0), "in")]),
            Some(25_400.0)
        );
    }

    #[test]
    fn ra_of_a_square_wave_agrees_and_a_wrong_one_does_not() {
        // ±2 µm square wave, about zero: Ra = 2 µm exactly.
        let z: Vec<f64> = (0..60)
            .map(|i| if i % 2 == 0 { 2.0 } else { -2.0 })
            .collect();
        let p = r_profile(z);
        let ok = check_ra(&p, &[r("Ra", Some(2.0), "um")]).unwrap();
        assert!((ok.ours_um - 2.0).abs() < 1e-12);
        assert!((ok.tolerance_um - (0.04 + 0.005)).abs() < 1e-12);
        assert!(ok.agrees());
        // 2.04 is inside 2 % + 5 nm of 2.0; 2.06 is not.
        assert!(check_ra(&p, &[r("Ra", Some(2.04), "um")]).unwrap().agrees());
        assert!(!check_ra(&p, &[r("Ra", Some(2.1), "um")]).unwrap().agrees());
        let mut w = p.clone();
        w.conditions.profile_kind = Some(ProfileKind::W);
        assert_eq!(check_ra(&w, &[r("Ra", Some(2.0), "um")]), None);
        assert_eq!(check_ra(&p, &[]), None);
    }

    #[test]
    fn repeated_blocks_but_not_flat_ones() {
        assert!(is_repeated_block(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]));
        assert!(!is_repeated_block(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.5]));
        assert!(!is_repeated_block(&[1.0, 2.0], &[1.0, 2.0, 3.0]));
        assert!(!is_repeated_block(&[0.0, 0.0, 0.0], &[0.0, 0.0, 0.0]));
        assert!(!is_repeated_block(&[4.0], &[4.0]));
        assert!(!is_repeated_block(&[], &[]));
    }

    #[test]
    fn a_line_far_from_its_neighbours_ra_is_flagged_either_way() {
        let before = [1.0, 1.2, 0.9, 1.1];
        // Median of the four: 1.05 µm.
        assert_eq!(ra_far_from_neighbours(1.5, &before), None);
        assert_eq!(ra_far_from_neighbours(5.0, &before), None, "4.8 times");
        match ra_far_from_neighbours(1050.0, &before) {
            Some(ReadoutWarning::RaFarFromNeighbours {
                median_um, lines, ..
            }) => {
                assert!((median_um - 1.05).abs() < 1e-12);
                assert_eq!(lines, 4);
            }
            other => panic!("{other:?}"),
        }
        assert!(
            ra_far_from_neighbours(0.2, &before).is_some(),
            "5.25 times smaller"
        );
        assert!(ra_far_from_neighbours(0.0, &before).is_some());
        // Too few lines before it to judge.
        assert_eq!(ra_far_from_neighbours(1000.0, &[1.0, 1.0]), None);
        // Only the latest five count: the old, rougher lines are outside the window.
        let drift = [50.0, 50.0, 50.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        assert!(ra_far_from_neighbours(50.0, &drift).is_some());
        // One wild line among them does not move the median.
        assert_eq!(ra_far_from_neighbours(1.0, &[1.0, 1000.0, 1.1, 0.9]), None);
    }
}
