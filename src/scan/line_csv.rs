//! The heights file of a line, `NNNN.csv`: header `x_mm,z_um`, one row per point, both
//! numbers in Rust's shortest round-trip decimal form, so reading back yields bit-identical
//! values. x starts at 0: point *i* is at *i* × pitch (Mitutoyo's own export numbers the same
//! points from one pitch to *n* pitches; see [`crate::sj210::sampling`]).
//!
//! Layer 3 (session): depends on [`crate::profile`] and [`super::store_error`]; no I/O.

use std::path::Path;

use crate::profile::Profile;

use super::store_error::StoreError;

/// Renders the heights file: header `x_mm,z_um`, one row per point, both numbers in Rust's
/// shortest round-trip decimal form, so reading back yields bit-identical values.
pub fn render_csv(profile: &Profile) -> String {
    let mut s = String::with_capacity(16 + profile.heights_um.len() * 24);
    s.push_str("x_mm,z_um\n");
    for (i, z) in profile.heights_um.iter().enumerate() {
        s.push_str(&format!("{},{}\n", profile.x_mm(i), z));
    }
    s
}

/// Parses a heights file (as written by [`render_csv`]); `path` names it in errors.
/// Returns the heights and checks the x column against `pitch_x_mm` (within 1e-9 mm).
pub fn parse_csv(path: &Path, text: &str, pitch_x_mm: f64) -> Result<Vec<f64>, StoreError> {
    let mut lines = text.lines();
    let header = lines.next().unwrap_or("");
    if header.trim_end_matches('\r') != "x_mm,z_um" {
        return Err(StoreError::CsvHeader {
            path: path.to_path_buf(),
            found: header.to_string(),
        });
    }
    let mut heights = Vec::new();
    for (n, row) in lines.enumerate() {
        let row_err = |reason: String| StoreError::CsvRow {
            path: path.to_path_buf(),
            line: n + 2,
            content: row.to_string(),
            reason,
        };
        let r = row.trim_end_matches('\r');
        let Some((x, z)) = r.split_once(',') else {
            return Err(row_err("expected two comma-separated numbers".into()));
        };
        let x: f64 = crate::numbers::parse_f64(x.trim())
            .map_err(|e| row_err(format!("x_mm is not a number: {e}")))?;
        let z: f64 = crate::numbers::parse_f64(z.trim())
            .map_err(|e| row_err(format!("z_um is not a number: {e}")))?;
        if !z.is_finite() || !x.is_finite() {
            return Err(row_err("values must be finite".into()));
        }
        let expect = heights.len() as f64 * pitch_x_mm;
        if (x - expect).abs() > 1e-9 {
            return Err(row_err(format!(
                "x_mm {x} does not match point {} × pitch {pitch_x_mm} mm = {expect}",
                heights.len()
            )));
        }
        heights.push(z);
    }
    Ok(heights)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::plan::CSV_BYTES_PER_POINT;

    #[test]
    fn csv_round_trips_bit_identically() {
        let p = Profile::new(
            0.0015,
            vec![0.1, -1.23456789012345, 1e-300, 0.30000000000000004],
        );
        let text = render_csv(&p);
        assert!(text.starts_with("x_mm,z_um\n0,0.1\n0.0015,-1.23456789012345\n"));
        let back = parse_csv(Path::new("a.csv"), &text, 0.0015).unwrap();
        assert_eq!(back, p.heights_um);
    }

    #[test]
    fn malformed_csv_names_path_line_and_content() {
        let e = parse_csv(Path::new("l/0003.csv"), "x_mm,z_um\n0,1\n0.5,abc\n", 0.5).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("l/0003.csv") && msg.contains("line 3") && msg.contains("0.5,abc"),
            "{msg}"
        );
        let e = parse_csv(Path::new("a"), "x,z\n", 0.5).unwrap_err();
        assert!(matches!(e, StoreError::CsvHeader { found, .. } if found == "x,z"));
        let e = parse_csv(Path::new("a"), "x_mm,z_um\n0,1\n0.7,2\n", 0.5).unwrap_err();
        assert!(matches!(e, StoreError::CsvRow { line: 3, .. }));
    }

    #[test]
    fn csv_budget_bounds_worst_case_rows() {
        // Pitches and heights that are not exact binary fractions print with 17 significant
        // digits; the per-point budget must still hold.
        let n = 20_000;
        let heights: Vec<f64> = (0..n).map(|i| -(i as f64) / 3.0e4 - 1.0e-7).collect();
        let p = Profile::new(0.0001, heights);
        let csv = render_csv(&p);
        assert!(
            csv.len() as u64 <= CSV_BYTES_PER_POINT * n as u64,
            "{} bytes for {n} points",
            csv.len()
        );
    }
}
