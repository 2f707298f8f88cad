//! Units of the project, explicit in names and types.
//!
//! Lateral positions and pitches are millimetres (`_mm` in names, `f64`); heights are
//! micrometres (`_um`, `f64`) as the instrument reports them; stage targets are integer
//! nanometres ([`Nm`]) so that `y_start + k × step` is exact and never accumulates rounding.
//! Geometry written to IGES is in millimetres: [`um_to_mm`] is the one conversion.
//!
//! Layer 0 (vocabulary): depends on nothing else in the crate; no I/O.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Micrometres per millimetre.
pub const UM_PER_MM: f64 = 1000.0;

/// Height in µm → length in mm (the unit of the IGES file and of all geometry).
#[inline]
pub fn um_to_mm(z_um: f64) -> f64 {
    z_um / UM_PER_MM
}

/// A stage position or distance in integer nanometres.
///
/// 0.01 mm is exactly `Nm(10_000)`; a scan's targets are computed from the line index in
/// this type and rounded to device units once.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, Default,
)]
#[serde(transparent)]
pub struct Nm(pub i64);

impl Nm {
    /// Nanometres per millimetre.
    pub const PER_MM: i64 = 1_000_000;

    /// Converts millimetres to nanometres if the value is a whole number of nanometres
    /// (within 1e-6 nm of floating-point noise) and in range; `None` otherwise.
    pub fn try_from_mm(mm: f64) -> Option<Nm> {
        if !mm.is_finite() {
            return None;
        }
        let nm = mm * Self::PER_MM as f64;
        if nm.abs() > 9.0e15 {
            return None;
        }
        let rounded = nm.round();
        if (nm - rounded).abs() > 1e-6 * nm.abs().max(1.0) {
            return None;
        }
        Some(Nm(rounded as i64))
    }

    /// Rounds millimetres to the nearest nanometre (saturating on non-finite input).
    pub fn from_mm_rounded(mm: f64) -> Nm {
        let v = (mm * Self::PER_MM as f64).round();
        if v.is_nan() {
            Nm(0)
        } else {
            Nm(v.clamp(i64::MIN as f64, i64::MAX as f64) as i64)
        }
    }

    /// The value in millimetres (for display and geometry; exact for |x| < 2^53 nm).
    pub fn to_mm(self) -> f64 {
        self.0 as f64 / Self::PER_MM as f64
    }
}

impl fmt::Display for Nm {
    /// Formats as millimetres with nanometre resolution, e.g. `0.010000 mm`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sign = if self.0 < 0 { "-" } else { "" };
        let a = self.0.unsigned_abs();
        write!(f, "{sign}{}.{:06} mm", a / 1_000_000, a % 1_000_000)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hundredth_of_a_millimetre_is_exact() {
        assert_eq!(Nm::try_from_mm(0.01), Some(Nm(10_000)));
        assert_eq!(Nm::try_from_mm(-12.345678), Some(Nm(-12_345_678)));
        assert_eq!(
            Nm::try_from_mm(0.0000001),
            None,
            "0.1 nm is not a whole nanometre"
        );
        assert_eq!(Nm::try_from_mm(f64::NAN), None);
    }

    #[test]
    fn display_is_mm_with_nm_resolution() {
        assert_eq!(Nm(10_000).to_string(), "0.010000 mm");
        assert_eq!(Nm(-1_500_001).to_string(), "-1.500001 mm");
    }
}
