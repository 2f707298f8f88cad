//! A scan's identifier: `YYYYMMDDTHHMMSSZ-<specimen-slug>`, also its directory name.
//!
//! Layer 3 (session): depends on chrono and serde only.

use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};

/// A scan's identifier, also the name of its directory under `output.dir`.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ScanId(pub String);

impl ScanId {
    /// Builds the id from the start time and the specimen id; the specimen is reduced to
    /// `[a-z0-9-]` (runs of other characters become one `-`, at most 40 characters) and an
    /// empty result becomes `scan`.
    pub fn new(start: DateTime<Utc>, specimen: &str) -> ScanId {
        let mut slug = String::new();
        for c in specimen.chars() {
            if c.is_ascii_alphanumeric() {
                slug.push(c.to_ascii_lowercase());
            } else if !slug.is_empty() && !slug.ends_with('-') {
                slug.push('-');
            }
            if slug.len() >= 40 {
                break;
            }
        }
        let slug = slug.trim_end_matches('-');
        let slug = if slug.is_empty() { "scan" } else { slug };
        ScanId(format!("{}-{}", start.format("%Y%m%dT%H%M%SZ"), slug))
    }
}

impl std::fmt::Display for ScanId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chrono::TimeZone;

    #[test]
    fn scan_id_is_timestamp_and_slug() {
        let t = Utc.with_ymd_and_hms(2026, 3, 4, 5, 6, 7).unwrap();
        assert_eq!(
            ScanId::new(t, "Block #12 / Ra 0.4").0,
            "20260304T050607Z-block-12-ra-0-4"
        );
        assert_eq!(ScanId::new(t, "  ").0, "20260304T050607Z-scan");
    }
}
