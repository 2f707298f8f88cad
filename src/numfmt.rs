//! Numbers for people: a value written with the significant digits its quantity deserves, not
//! the 17 digits that round-trip an `f64` (`0.0045000000000000005`). Used wherever a person
//! reads a number: summary.csv, the HTML report, plot labels and messages. Machine-readable
//! outputs (report.json, the journal) keep full precision and never go through here.
//!
//! Layer 0 (vocabulary): depends on nothing.

/// How many significant digits a kind of quantity is written with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// Heights and height parameters in µm (Ra, Rz, Rk, Sa, …): 4 significant digits, about
    /// the resolution of the instrument's display.
    HeightUm,
    /// Material ratios and other percentages (Mr1, Rmr(c), Smr): 3 significant digits.
    Percent,
    /// Material ratios as the SJ series prints them (Mr1 5.822 %, Rmr 0.030 %): 3 decimal
    /// places.
    InstrumentPercent,
    /// Dimensionless shape parameters (Rsk, Rku, Rdq, Sdq): 3 significant digits.
    Ratio,
    /// Areas of the Rk construction (A1, A2, µm·%): 3 significant digits.
    Area,
    /// Lateral positions in mm (y of a line, x range): 4 decimal places (0.1 µm).
    PositionMm,
    /// Pitches and lengths in mm (pitch, λc, lr): 4 significant digits.
    LengthMm,
    /// Differences between two results (ours − instrument): 2 significant digits.
    Difference,
    /// Durations in seconds: 3 significant digits.
    Seconds,
    /// Counts per unit length (RPc per cm, Rppi per inch): 3 significant digits.
    PerLength,
}

impl Quantity {
    /// Significant digits (or, for [`Quantity::PositionMm`] and
    /// [`Quantity::InstrumentPercent`], decimal places).
    pub fn digits(self) -> usize {
        match self {
            Quantity::HeightUm | Quantity::LengthMm | Quantity::PositionMm => 4,
            Quantity::InstrumentPercent
            | Quantity::Percent
            | Quantity::Ratio
            | Quantity::Area
            | Quantity::Seconds
            | Quantity::PerLength => 3,
            Quantity::Difference => 2,
        }
    }
}

/// `v` written for a person as quantity `q`: significant digits per [`Quantity::digits`]
/// (decimal places for positions and the instrument's percentages), plain decimal notation between 1e-4 and 1e6, exponent
/// notation outside; `NaN`, `inf` and `-inf` as such. Trailing zeros are kept: they are
/// significant.
pub fn fmt(v: f64, q: Quantity) -> String {
    if matches!(q, Quantity::PositionMm | Quantity::InstrumentPercent) {
        if !v.is_finite() {
            return non_finite(v);
        }
        let s = format!("{v:.*}", q.digits());
        return negative_zero(s);
    }
    sig(v, q.digits())
}

/// `v` with `n` significant digits (at least 1), as [`fmt`] describes.
pub fn sig(v: f64, n: usize) -> String {
    if !v.is_finite() {
        return non_finite(v);
    }
    let n = n.max(1);
    if v == 0.0 {
        return if n > 1 {
            format!("0.{}", "0".repeat(n - 1))
        } else {
            "0".to_string()
        };
    }
    // Round first, then decide the notation from the rounded value (0.99996 → 1.000).
    let e = format!("{:.*e}", n - 1, v);
    let exp: i32 = e
        .rsplit_once('e')
        .and_then(|(_, x)| x.parse().ok())
        .unwrap_or(0);
    if !(-4..6).contains(&exp) {
        return e;
    }
    let decimals = (n as i32 - 1 - exp).max(0) as usize;
    let rounded: f64 = e.parse().unwrap_or(v);
    negative_zero(format!("{rounded:.decimals$}"))
}

fn non_finite(v: f64) -> String {
    if v.is_nan() {
        "NaN".to_string()
    } else if v > 0.0 {
        "inf".to_string()
    } else {
        "-inf".to_string()
    }
}

/// `-0.000` is written `0.000`: a person reads the sign as meaningful.
fn negative_zero(s: String) -> String {
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

/// [`fmt`] of an optional value; `None` is the empty string (an empty CSV field).
pub fn fmt_opt(v: Option<f64>, q: Quantity) -> String {
    v.map(|v| fmt(v, q)).unwrap_or_default()
}

/// A line number as a person reads it: the 0-based storage index plus one.
pub fn line_number(index: u32) -> u64 {
    u64::from(index) + 1
}

/// A line as a person names it: its 1-based number with the file index beside it,
/// `7 (0006)`.
pub fn line_label(index: u32) -> String {
    format!("{} ({index:04})", line_number(index))
}

/// A duration for people, rounded to the second: `45 s`, `12 min 30 s`, `2 h 05 min`; `None`
/// for a negative or non-finite one.
pub fn duration(seconds: f64) -> Option<String> {
    if !seconds.is_finite() || seconds < 0.0 {
        return None;
    }
    let s = seconds.round() as u64;
    Some(if s < 60 {
        format!("{s} s")
    } else if s < 3600 {
        format!("{} min {:02} s", s / 60, s % 60)
    } else {
        format!("{} h {:02} min", s / 3600, (s % 3600) / 60)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_are_rounded_into_units() {
        assert_eq!(duration(44.6).as_deref(), Some("45 s"));
        assert_eq!(duration(60.0).as_deref(), Some("1 min 00 s"));
        assert_eq!(duration(7530.0).as_deref(), Some("2 h 05 min"));
        assert_eq!(duration(-1.0), None);
        assert_eq!(duration(f64::NAN), None);
    }

    #[test]
    fn float_noise_is_not_printed() {
        assert_eq!(sig(0.0045000000000000005, 3), "0.00450");
        assert_eq!(fmt(0.1 + 0.2, Quantity::HeightUm), "0.3000");
    }

    #[test]
    fn significant_digits_cover_the_decades() {
        assert_eq!(sig(1.23456, 4), "1.235");
        assert_eq!(sig(12.3456, 4), "12.35");
        assert_eq!(sig(123456.0, 4), "123500");
        assert_eq!(sig(1234567.0, 4), "1.235e6");
        assert_eq!(sig(99999.0, 4), "100000");
        assert_eq!(sig(0.99996, 4), "1.000");
        assert_eq!(sig(0.000123456, 3), "0.000123");
        assert_eq!(sig(0.0000123456, 3), "1.23e-5");
        assert_eq!(sig(-2.5, 2), "-2.5");
        assert_eq!(sig(0.0, 3), "0.00");
        assert_eq!(sig(7.0, 1), "7");
    }

    #[test]
    fn positions_have_fixed_decimals_and_no_negative_zero() {
        assert_eq!(fmt(0.01 * 3.0, Quantity::PositionMm), "0.0300");
        assert_eq!(fmt(-20.0, Quantity::PositionMm), "-20.0000");
        assert_eq!(fmt(-0.00001, Quantity::PositionMm), "0.0000");
        assert_eq!(sig(-0.00001, 1), "-1e-5");
    }

    #[test]
    fn non_finite_values_are_named() {
        assert_eq!(sig(f64::NAN, 3), "NaN");
        assert_eq!(fmt(f64::INFINITY, Quantity::PositionMm), "inf");
        assert_eq!(fmt_opt(None, Quantity::Percent), "");
        assert_eq!(fmt_opt(Some(87.345), Quantity::Percent), "87.3");
    }

    #[test]
    fn line_numbers_start_at_one() {
        assert_eq!(line_number(0), 1);
        assert_eq!(line_number(30), 31);
    }
}
