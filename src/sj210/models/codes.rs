//! The code tables of the SJ-210 family's replies (status, battery, drive unit, and the
//! `RDCON` digits for standard, profile, filter, λc, λs), each entry citing its source.
//!
//! Pure (layer 1): depends on [`crate::sj210::sources`] only.

use crate::sj210::sources::{M1_CON, M1_STU, M2_CON};

/// One entry of a code table.
#[derive(Debug, Clone, PartialEq)]
pub struct CodeEntry {
    /// The code.
    pub code: u16,
    /// What it means.
    pub meaning: &'static str,
    /// Where it was read.
    pub source: &'static str,
}

/// One entry of a condition code table with its numeric value.
#[derive(Debug, Clone, PartialEq)]
pub struct ValueEntry {
    /// Digit in the record.
    pub code: u8,
    /// Value (mm for λc, µm for λs).
    pub value: f64,
    /// Where it was read.
    pub source: &'static str,
}

fn e(code: u16, meaning: &'static str, source: &'static str) -> CodeEntry {
    CodeEntry {
        code,
        meaning,
        source,
    }
}

fn v(code: u8, value: f64, source: &'static str) -> ValueEntry {
    ValueEntry {
        code,
        value,
        source,
    }
}

/// The meaning of `code` in a table.
pub fn lookup(t: &[CodeEntry], code: u16) -> Option<&'static str> {
    t.iter().find(|x| x.code == code).map(|x| x.meaning)
}

/// `RDSTU00` codes (the same on every model).
pub fn status_codes() -> Vec<CodeEntry> {
    vec![
        e(0, "idle", M1_STU),
        e(1, "measuring", M1_STU),
        e(2, "returning", M1_STU),
        e(3, "retracting", M1_STU),
        e(4, "retracted", M1_STU),
        e(5, "neither at origin nor retracted", M1_STU),
    ]
}

/// `RDSTU01` codes.
pub fn battery_codes() -> Vec<CodeEntry> {
    vec![
        e(0, "more than 60 %", M1_STU),
        e(1, "below 60 %", M1_STU),
        e(2, "abnormal (temperature, voltage or no battery)", M1_STU),
        e(3, "charging", M1_STU),
    ]
}

/// `RDSJ 00` codes.
pub fn drive_codes() -> Vec<CodeEntry> {
    vec![
        e(0, "standard", M1_STU),
        e(1, "transverse tracing", M1_STU),
        e(2, "retracting", M1_STU),
    ]
}

/// Standard digit → name.
pub fn standard_codes() -> Vec<CodeEntry> {
    vec![
        e(0, "JIS1982", M1_CON),
        e(1, "JIS1994", M1_CON),
        e(2, "JIS2001", M1_CON),
        e(3, "ISO1997", M1_CON),
        e(4, "ANSI", M1_CON),
        e(5, "VDA", M1_CON),
        e(6, "Free", M1_CON),
    ]
}

/// Filter digit → name.
pub fn filter_codes() -> Vec<CodeEntry> {
    vec![
        e(0, "2CR75", M1_CON),
        e(1, "PC75", M1_CON),
        e(2, "GAUSS", M1_CON),
        e(3, "None", M1_CON),
    ]
}

/// SJ-210 profile digit → name.
pub fn sj210_profile_codes() -> Vec<CodeEntry> {
    vec![
        e(0, "P", M1_CON),
        e(1, "R", M1_CON),
        e(2, "DF", M1_CON),
        e(3, "R-Motif", M1_CON),
    ]
}

/// SJ-410 profile digit → name.
pub fn sj410_profile_codes() -> Vec<CodeEntry> {
    vec![
        e(0, "P", M2_CON),
        e(1, "R", M2_CON),
        e(2, "DF", M2_CON),
        e(3, "R-Motif", M2_CON),
        e(4, "W-Motif", M2_CON),
        e(5, "W", M2_CON),
    ]
}

/// SJ-210 λc digit → mm.
pub fn sj210_lambda_c_codes() -> Vec<ValueEntry> {
    vec![
        v(0, 0.08, M1_CON),
        v(1, 0.25, M1_CON),
        v(2, 0.8, M1_CON),
        v(3, 2.5, M1_CON),
    ]
}

/// SJ-410 λc digit → mm.
pub fn sj410_lambda_c_codes() -> Vec<ValueEntry> {
    vec![
        v(0, 0.08, M2_CON),
        v(1, 0.25, M2_CON),
        v(2, 0.8, M2_CON),
        v(3, 2.5, M2_CON),
        v(4, 8.0, M2_CON),
        v(5, 25.0, M2_CON),
    ]
}

/// SJ-410 λs digit → µm (the SJ-210 record has no λs field).
pub fn sj410_lambda_s_codes() -> Vec<ValueEntry> {
    vec![v(0, 2.5, M2_CON), v(1, 8.0, M2_CON), v(2, 25.0, M2_CON)]
}
