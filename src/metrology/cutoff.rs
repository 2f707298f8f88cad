//! The ISO 4288 cut-off check: whether the λc a profile was evaluated with is the one ISO 4288
//! (Tables 1 and 2, non-periodic profiles) gives for the Ra and the Rz that came out. A result
//! outside its λc's band is a result ISO 4288 would have measured again with the band's λc
//! (its procedure: estimate, measure, and repeat at the λc the result calls for).
//!
//! | λc mm | Ra µm | Rz µm |
//! |---|---|---|
//! | 0.08 | > 0.006 … 0.02 | > 0.025 … 0.1 |
//! | 0.25 | > 0.02 … 0.1 | > 0.1 … 0.5 |
//! | 0.8 | > 0.1 … 2 | > 0.5 … 10 |
//! | 2.5 | > 2 … 10 | > 10 … 50 |
//! | 8 | > 10 … 80 | > 50 … 200 |
//!
//! Ra and Rz can fall in different bands (the paper's first specimen: Ra 1.50 µm in the
//! 0.8 mm band, Rz 10.4 µm in the 2.5 mm band); the check names each. Periodic profiles are
//! chosen by RSm (ISO 4288 Table 3) and are not checked here.
//!
//! Depends on [`crate::numfmt`] (numbers written for people).

use serde::Serialize;

/// One row of ISO 4288's tables: the λc for results in (lower, upper].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Band {
    /// The λc (and sampling length) of the band, mm.
    pub lambda_c_mm: f64,
    /// Exclusive lower limit of the result, µm.
    pub above_um: f64,
    /// Inclusive upper limit of the result, µm.
    pub up_to_um: f64,
}

const RA_BANDS: [Band; 5] = [
    band(0.08, 0.006, 0.02),
    band(0.25, 0.02, 0.1),
    band(0.8, 0.1, 2.0),
    band(2.5, 2.0, 10.0),
    band(8.0, 10.0, 80.0),
];

const RZ_BANDS: [Band; 5] = [
    band(0.08, 0.025, 0.1),
    band(0.25, 0.1, 0.5),
    band(0.8, 0.5, 10.0),
    band(2.5, 10.0, 50.0),
    band(8.0, 50.0, 200.0),
];

const fn band(lambda_c_mm: f64, above_um: f64, up_to_um: f64) -> Band {
    Band {
        lambda_c_mm,
        above_um,
        up_to_um,
    }
}

fn band_of(bands: &[Band], value_um: f64) -> Option<Band> {
    bands
        .iter()
        .find(|b| value_um > b.above_um && value_um <= b.up_to_um)
        .copied()
}

/// The check of one result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CutoffCheck {
    /// The λc evaluated with, mm.
    pub lambda_c_mm: f64,
    /// The Ra checked, µm.
    pub ra_um: f64,
    /// The Rz checked, µm.
    pub rz_um: f64,
    /// The band Ra falls in; `None` outside the tables (below 0.006 or above 80 µm).
    pub ra_band: Option<Band>,
    /// The band Rz falls in; `None` outside the tables.
    pub rz_band: Option<Band>,
    /// λc is the Ra band's.
    pub fits_ra: bool,
    /// λc is the Rz band's.
    pub fits_rz: bool,
    /// What an operator should know, when λc fits neither or only one of them.
    pub warning: Option<String>,
}

/// Checks `lambda_c_mm` against the bands of `ra_um` and `rz_um` (for a grid, the mean over its
/// lines).
pub fn iso4288_check(ra_um: f64, rz_um: f64, lambda_c_mm: f64) -> CutoffCheck {
    let ra_band = band_of(&RA_BANDS, ra_um);
    let rz_band = band_of(&RZ_BANDS, rz_um);
    let fits = |b: Option<Band>| b.is_some_and(|b| (b.lambda_c_mm - lambda_c_mm).abs() < 1e-9);
    let (fits_ra, fits_rz) = (fits(ra_band), fits(rz_band));
    let say = |name: &str, v: f64, b: Option<Band>| match b {
        Some(b) => format!(
            "{name} {} µm falls in ISO 4288's {} mm band ({name} > {} … {} µm)",
            sig(v),
            b.lambda_c_mm,
            b.above_um,
            b.up_to_um
        ),
        None => format!("{name} {} µm is outside ISO 4288's tables", sig(v)),
    };
    let one = |fits: &str, v: f64, not: &str, w: f64, b: Option<Band>| {
        format!(
            "λc {lambda_c_mm} mm fits {fits} {} µm but not {not}: {}; for an {not} specification ISO 4288 measures again at that band's λc",
            sig(v),
            say(not, w, b)
        )
    };
    let warning = match (fits_ra, fits_rz) {
        (true, true) => None,
        (false, false) => Some(format!(
            "λc {lambda_c_mm} mm does not fit the result: {} and {}; ISO 4288 measures again at the band's λc",
            say("Ra", ra_um, ra_band),
            say("Rz", rz_um, rz_band)
        )),
        (true, false) => Some(one("Ra", ra_um, "Rz", rz_um, rz_band)),
        (false, true) => Some(one("Rz", rz_um, "Ra", ra_um, ra_band)),
    };
    CutoffCheck {
        lambda_c_mm,
        ra_um,
        rz_um,
        ra_band,
        rz_band,
        fits_ra,
        fits_rz,
        warning,
    }
}

/// A height as the report quotes it (4 significant digits).
fn sig(v: f64) -> String {
    crate::numfmt::fmt(v, crate::numfmt::Quantity::HeightUm)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's first specimen: Ra 1.498 µm, Rz 10.40 µm at λc 0.8 mm.
    #[test]
    fn the_papers_first_specimen_fits_ra_but_not_rz() {
        let c = iso4288_check(1.498, 10.40, 0.8);
        assert!(c.fits_ra && !c.fits_rz);
        assert_eq!(c.rz_band.unwrap().lambda_c_mm, 2.5);
        let w = c.warning.unwrap();
        assert!(
            w.contains("Rz 10.40 µm falls in ISO 4288's 2.5 mm band"),
            "{w}"
        );
    }

    #[test]
    fn a_fitting_cutoff_says_nothing_and_a_wrong_one_names_both_bands() {
        assert!(iso4288_check(0.577, 4.56, 0.8).warning.is_none());
        let c = iso4288_check(3.3, 17.0, 0.8);
        let w = c.warning.unwrap();
        assert!(
            w.contains("2.5 mm band (Ra > 2 … 10 µm)")
                && w.contains("2.5 mm band (Rz > 10 … 50 µm)"),
            "{w}"
        );
        // Band edges: upper limits belong to the band.
        assert_eq!(iso4288_check(2.0, 10.0, 0.8).warning, None);
        assert!(iso4288_check(0.001, 0.01, 0.08)
            .warning
            .unwrap()
            .contains("outside ISO 4288's tables"));
    }
}
