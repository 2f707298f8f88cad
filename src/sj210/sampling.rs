//! How the exported profile is sampled along x: the pitch the instrument uses for a λs, and
//! the number of points a trace under given conditions must deliver.
//!
//! Both rules come from a real export of Mitutoyo's own PC tool for the SJ series (an
//! SJ-Tools certificate workbook: `CUT 2.5mm`, `N 4`, `LS 8µm`, `STP 1.5`, 6664 evaluation
//! points) and agree with ISO 3274's maximum sampling spacing for each λs and with two more
//! exports of the family (960 points at λc 0.08 mm × 6; 8000 at λc 0.8 mm × 5, the SJ-301
//! memory-card example).
//!
//! x convention: the project numbers the points of a line from x = 0 (point *i* at
//! *i* × pitch). Mitutoyo's export numbers them from one pitch to *n* pitches; the heights are
//! the same, the x column is shifted by one pitch.
//!
//! Pure (layer 1): numbers in, numbers out; depends on [`crate::profile`] only.

use crate::profile::Conditions;
use std::fmt;

/// The exported profile's x pitch in µm for a λs in µm, `None` for any other λs: the ISO 3274
/// maximum sampling spacing, 2.5 → 0.5, 8 → 1.5, 25 → 5. Seen in Mitutoyo's own export
/// (`STP 1.5` at λs 8 µm) and in SJ-410 memory-card files (`Pitch 0,5` at λs 2.5 µm).
pub fn pitch_from_lambda_s(lambda_s_um: f64) -> Option<f64> {
    [(2.5, 0.5), (8.0, 1.5), (25.0, 5.0)]
        .into_iter()
        .find(|(ls, _)| (lambda_s_um - ls).abs() < 1e-9)
        .map(|(_, p)| p)
}

/// The number of points a trace delivers: N sampling lengths of ⌊λc / pitch⌋ points each.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExpectedPoints {
    /// N × points per sampling length.
    pub points: u32,
    /// N, the number of sampling lengths.
    pub sampling_lengths: u32,
    /// ⌊λc / pitch⌋.
    pub per_sampling_length: u32,
    /// λc in mm.
    pub lambda_c_mm: f64,
    /// The pitch in µm.
    pub pitch_um: f64,
}

impl fmt::Display for ExpectedPoints {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "N {} x floor(lambda-c {} mm / pitch {} um) = {} x {} = {}",
            self.sampling_lengths,
            self.lambda_c_mm,
            self.pitch_um,
            self.sampling_lengths,
            self.per_sampling_length,
            self.points
        )
    }
}

/// The point count the conditions and the pitch give, N × ⌊λc / pitch⌋ (computed in whole
/// nanometres, so 0.8 mm / 0.5 µm is exactly 1600). `None` when λc or N is unknown, when N is
/// 0 (an arbitrary evaluation length: no export of that mode has been seen, so no count is
/// expected) or when the pitch is not a positive length.
pub fn expected_points(conditions: &Conditions, pitch_um: f64) -> Option<ExpectedPoints> {
    let lambda_c_mm = conditions.lambda_c_mm?;
    let n = conditions.sampling_lengths.filter(|n| *n > 0)?;
    let lc_nm = (lambda_c_mm * 1e6).round();
    let pitch_nm = (pitch_um * 1e3).round();
    if !(lc_nm.is_finite() && pitch_nm.is_finite() && lc_nm > 0.0 && pitch_nm > 0.0) {
        return None;
    }
    let per = (lc_nm / pitch_nm).floor();
    let points = per * f64::from(n);
    if points > f64::from(u32::MAX) {
        return None;
    }
    Some(ExpectedPoints {
        points: points as u32,
        sampling_lengths: n,
        per_sampling_length: per as u32,
        lambda_c_mm,
        pitch_um,
    })
}

/// A profile whose point count is not the one its conditions give.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the profile has {received} points, but its conditions give {expected}")]
pub struct PointCountMismatch {
    /// What the conditions give.
    pub expected: ExpectedPoints,
    /// Points received.
    pub received: usize,
}

/// Checks a received point count against the conditions: `Ok` when they agree or when the
/// conditions give no count ([`expected_points`] is `None`).
pub fn check_point_count(
    conditions: &Conditions,
    pitch_um: f64,
    received: usize,
) -> Result<(), PointCountMismatch> {
    match expected_points(conditions, pitch_um) {
        Some(e) if e.points as usize != received => Err(PointCountMismatch {
            expected: e,
            received,
        }),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cond(lc: f64, n: u32) -> Conditions {
        Conditions {
            lambda_c_mm: Some(lc),
            sampling_lengths: Some(n),
            ..Conditions::default()
        }
    }

    #[test]
    fn pitch_is_the_iso_3274_spacing() {
        assert_eq!(pitch_from_lambda_s(2.5), Some(0.5));
        assert_eq!(pitch_from_lambda_s(8.0), Some(1.5));
        assert_eq!(pitch_from_lambda_s(25.0), Some(5.0));
        assert_eq!(pitch_from_lambda_s(0.8), None);
    }

    #[test]
    fn counts_of_the_three_known_exports() {
        // Mitutoyo PC tool: λc 2.5 mm, N 4, pitch 1.5 µm (λs 8 µm).
        let e = expected_points(&cond(2.5, 4), 1.5).unwrap();
        assert_eq!((e.points, e.per_sampling_length), (6664, 1666));
        // The same tool at λc 0.08 mm, N 6, pitch 0.5 µm.
        assert_eq!(expected_points(&cond(0.08, 6), 0.5).unwrap().points, 960);
        // SJ-301 memory card: λc 0.8 mm × 5 at 0.5 µm; 0.8 / 0.0005 must not floor to 1599.
        assert_eq!(expected_points(&cond(0.8, 5), 0.5).unwrap().points, 8000);
        assert_eq!(expected_points(&cond(0.25, 5), 0.5).unwrap().points, 2500);
    }

    #[test]
    fn no_count_without_n_or_lambda_c() {
        assert_eq!(expected_points(&cond(2.5, 0), 1.5), None);
        assert_eq!(expected_points(&Conditions::default(), 1.5), None);
        assert_eq!(expected_points(&cond(2.5, 4), 0.0), None);
        assert_eq!(expected_points(&cond(2.5, 4), f64::NAN), None);
        assert!(check_point_count(&cond(2.5, 0), 1.5, 1067).is_ok());
    }

    #[test]
    fn mismatch_is_named_with_the_rule() {
        assert!(check_point_count(&cond(2.5, 4), 1.5, 6664).is_ok());
        let m = check_point_count(&cond(2.5, 4), 1.0, 6664).unwrap_err();
        assert_eq!(m.expected.points, 10_000);
        let text = format!("{m}: {}", m.expected);
        assert!(text.contains("6664 points"), "{text}");
        assert!(
            text.contains("N 4 x floor(lambda-c 2.5 mm / pitch 1 um)"),
            "{text}"
        );
    }
}
