//! The `RDCON` measurement-conditions record in the SJ-210 and SJ-410 layouts, read into
//! [`Conditions`] with the model's code tables.
//!
//! Pure (layer 1): depends on [`super`] (the model table and its error) and
//! [`crate::profile`].

use super::codes::lookup;
use super::{ModelError, ModelTable};
use crate::profile::{Conditions, FilterKind, ProfileKind};

/// Which `RDCON` record layout the model returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConditionLayout {
    /// SJ-210: standard, profile, λc, N (2), arbitrary length (5), motif, filter (M1 p.17-18).
    Sj210,
    /// SJ-410: A/B, standard, profile, filter, λs, λc, W cut-off, N (2), arbitrary length (5)
    /// (M2 p.22 CON write layout; real reply in C3).
    Sj410,
}

/// Parses an `RDCON` payload in the model's layout.
pub fn parse_conditions(t: &ModelTable, payload: &str) -> Result<Conditions, ModelError> {
    let chars: Vec<char> = payload.chars().collect();
    let bad = |what: String| ModelError::BadConditions {
        payload: payload.to_string(),
        what,
    };
    let digit = |i: usize, name: &str| -> Result<u8, ModelError> {
        chars
            .get(i)
            .and_then(|c| c.to_digit(10))
            .map(|d| d as u8)
            .ok_or_else(|| bad(format!("{name} at offset {i} is not a digit")))
    };
    let field = |from: usize, len: usize| -> Option<String> {
        chars.get(from..from + len).map(|s| s.iter().collect())
    };
    let (std_i, prof_i, lc_i, n_i, len_i, filt_i, ls_i) = match t.condition_layout {
        ConditionLayout::Sj210 => (0, 1, 2, 3, 5, Some(11), None),
        ConditionLayout::Sj410 => (1, 2, 5, 7, 9, Some(3), Some(4)),
    };
    let min_len = match t.condition_layout {
        ConditionLayout::Sj210 => 12,
        ConditionLayout::Sj410 => 14,
    };
    if chars.len() < min_len {
        return Err(bad(format!(
            "{} characters, the {:?} layout needs at least {min_len}",
            chars.len(),
            t.condition_layout
        )));
    }
    let std_code = digit(std_i, "standard")?;
    let standard = lookup(&t.standard_codes, u16::from(std_code))
        .ok_or_else(|| bad(format!("unknown standard code {std_code}")))?;
    let prof_code = digit(prof_i, "profile")?;
    let prof_name = lookup(&t.profile_codes, u16::from(prof_code))
        .ok_or_else(|| bad(format!("unknown profile code {prof_code}")))?;
    let profile_kind = match prof_name {
        "P" => ProfileKind::P,
        "R" => ProfileKind::R,
        "W" => ProfileKind::W,
        _ => ProfileKind::Other,
    };
    let lc_code = digit(lc_i, "lambda-c")?;
    let lambda_c_mm = t
        .lambda_c_codes
        .iter()
        .find(|x| x.code == lc_code)
        .map(|x| x.value)
        .ok_or_else(|| bad(format!("unknown lambda-c code {lc_code}")))?;
    let n = u32::from(digit(n_i, "N")?) * 10 + u32::from(digit(n_i + 1, "N")?);
    let arbitrary = field(len_i, 5).unwrap_or_default();
    let evaluation_length_mm = if n == 0 {
        Some(
            arbitrary
                .trim()
                .parse::<f64>()
                .map_err(|_| bad(format!("arbitrary length {arbitrary:?} is not a number")))?,
        )
    } else {
        Some(f64::from(n) * lambda_c_mm)
    };
    let filter = match filt_i {
        Some(i) => {
            let code = digit(i, "filter")?;
            Some(match lookup(&t.filter_codes, u16::from(code)) {
                Some("2CR75") => FilterKind::TwoRc,
                Some("PC75") => FilterKind::Pc75,
                Some("GAUSS") => FilterKind::Gaussian,
                Some("None") => FilterKind::None,
                _ => return Err(bad(format!("unknown filter code {code}"))),
            })
        }
        None => None,
    };
    let lambda_s_um = match ls_i {
        Some(i) => {
            let code = digit(i, "lambda-s")?;
            // Code 3 is "none" on the SJ-410 (M2); other unknown codes are errors.
            match t.lambda_s_codes.iter().find(|x| x.code == code) {
                Some(x) => Some(x.value),
                None if code == 3 => None,
                None => return Err(bad(format!("unknown lambda-s code {code}"))),
            }
        }
        // SJ-210: "λs is set according to λc" (M1); ISO 3274 pairs 2.5 µm with λc ≤ 0.8 mm
        // and 8 µm with λc 2.5 mm (inferred).
        None if lambda_c_mm <= 0.8 + 1e-9 => Some(2.5),
        None => Some(8.0),
    };
    Ok(Conditions {
        standard: Some(standard.to_string()),
        profile_kind: Some(profile_kind),
        filter,
        lambda_c_mm: Some(lambda_c_mm),
        lambda_s_um,
        sampling_lengths: Some(n),
        evaluation_length_mm,
        speed_mm_s: None,
        raw: Some(payload.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sj210::models::ModelId;

    #[test]
    fn sj210_conditions_iso_r_08_x5_gauss() {
        // standard 3 ISO1997, profile 1 R, λc 2 = 0.8, N 05, length field, motif 1, filter 2.
        let t = ModelTable::builtin(ModelId::Sj210);
        let c = t.parse_conditions("3120504.0012").unwrap();
        assert_eq!(c.standard.as_deref(), Some("ISO1997"));
        assert_eq!(c.profile_kind, Some(ProfileKind::R));
        assert_eq!(c.lambda_c_mm, Some(0.8));
        assert_eq!(c.lambda_s_um, Some(2.5));
        assert_eq!(c.sampling_lengths, Some(5));
        assert!((c.evaluation_length_mm.unwrap() - 4.0).abs() < 1e-12);
        assert_eq!(c.filter, Some(FilterKind::Gaussian));
    }

    #[test]
    fn sj210_arbitrary_length_and_lambda_s_8() {
        let t = ModelTable::builtin(ModelId::Sj210);
        let c = t.parse_conditions("3030012.5010").unwrap();
        assert_eq!(c.sampling_lengths, Some(0));
        assert_eq!(c.evaluation_length_mm, Some(12.5));
        assert_eq!(c.lambda_c_mm, Some(2.5));
        assert_eq!(c.lambda_s_um, Some(8.0));
        assert_eq!(c.profile_kind, Some(ProfileKind::P));
        assert_eq!(c.filter, Some(FilterKind::TwoRc));
    }

    #[test]
    fn sj410_conditions_from_c3_example() {
        // C3's real reply: 0 3 0 2 2 3 2 05 0.500 2 2 0.003 0.019
        let t = ModelTable::builtin(ModelId::Sj410);
        let c = t.parse_conditions("0302232050.500220.0030.019").unwrap();
        assert_eq!(c.standard.as_deref(), Some("ISO1997"));
        assert_eq!(c.profile_kind, Some(ProfileKind::P));
        assert_eq!(c.filter, Some(FilterKind::Gaussian));
        assert_eq!(c.lambda_s_um, Some(25.0));
        assert_eq!(c.lambda_c_mm, Some(2.5));
        assert_eq!(c.sampling_lengths, Some(5));
        assert!((c.evaluation_length_mm.unwrap() - 12.5).abs() < 1e-12);
    }

    #[test]
    fn short_or_bad_conditions_are_named_errors() {
        let t = ModelTable::builtin(ModelId::Sj210);
        assert!(matches!(
            t.parse_conditions("3120"),
            Err(ModelError::BadConditions { .. })
        ));
        assert!(matches!(
            t.parse_conditions("3190504.0012"),
            Err(ModelError::BadConditions { what, .. }) if what.contains("lambda-c code 9")
        ));
    }
}
