//! Retention: the decisions behind deleting a scan directory from the station, which happens
//! only when `[archive] delete-after-days` says so, the scan is that old, and the archive
//! holds a verified copy — its `MANIFEST.sha256` read back from the store names every file
//! the station has with the same SHA-256 as the file on the station's disk now, and every
//! object read back has that SHA-256. The archiver does the reading and the deleting; here
//! are the pure parts.
//!
//! Layer 4 (process edge), pure: depends on chrono only.

use chrono::{DateTime, NaiveDateTime, TimeDelta, Utc};
use std::collections::BTreeMap;

/// When the scan of an archive queue entry completed: the time its entry's file name starts
/// with (`20261206T091500.123456789Z-<scan id>.json`).
pub fn completed_at(entry_name: &str) -> Option<DateTime<Utc>> {
    let stamp = entry_name.split('-').next()?;
    let stamp = stamp.strip_suffix('Z')?;
    NaiveDateTime::parse_from_str(stamp, "%Y%m%dT%H%M%S%.f")
        .ok()
        .map(|t| t.and_utc())
}

/// Whether a scan completed at `completed` may leave the station at `now` after `days`.
pub fn due(completed: DateTime<Utc>, now: DateTime<Utc>, days: u32) -> bool {
    now.signed_duration_since(completed) >= TimeDelta::days(i64::from(days))
}

/// The `sha256sum` lines of a manifest as path → hash; a line of another form is an error
/// (a manifest that cannot be read never lets anything be deleted).
pub fn parse_manifest(text: &str) -> Result<BTreeMap<String, String>, String> {
    let mut out = BTreeMap::new();
    for (k, line) in text.lines().enumerate() {
        let (hash, path) = line
            .split_once("  ")
            .ok_or_else(|| format!("line {} is not `HASH  PATH`", k + 1))?;
        let hex = hash.len() == 64 && hash.bytes().all(|b| b.is_ascii_hexdigit());
        if !hex || path.is_empty() {
            return Err(format!("line {} is not `HASH  PATH`", k + 1));
        }
        if out
            .insert(path.to_owned(), hash.to_ascii_lowercase())
            .is_some()
        {
            return Err(format!("{path} is named twice"));
        }
    }
    Ok(out)
}

/// Checks that `manifest` (from the archive) names exactly the station's files `local`
/// (path → SHA-256 of the file as it is now) with the same hashes; the first difference.
pub fn matches(
    local: &BTreeMap<String, String>,
    manifest: &BTreeMap<String, String>,
) -> Result<(), String> {
    for (path, hash) in local {
        match manifest.get(path) {
            None => return Err(format!("{path} is not in the archive's manifest")),
            Some(h) if h != hash => {
                return Err(format!(
                "{path} on the station (SHA-256 {hash}) differs from the archive's manifest ({h})"
            ))
            }
            Some(_) => {}
        }
    }
    if let Some(path) = manifest.keys().find(|p| !local.contains_key(*p)) {
        return Err(format!(
            "the archive's manifest names {path}, which the station does not have"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_completion_time_is_read_from_the_entry_name() {
        let t = completed_at("20261206T091500.123456789Z-20261206-091200-s1.json").unwrap();
        assert_eq!(t.to_rfc3339(), "2026-12-06T09:15:00.123456789+00:00");
        assert!(completed_at("notes.json").is_none());
    }

    #[test]
    fn a_scan_is_due_once_it_is_as_old_as_the_setting_and_not_before() {
        let done = completed_at("20261201T000000.0Z-x.json").unwrap();
        let at = |s: &str| DateTime::parse_from_rfc3339(s).unwrap().to_utc();
        assert!(!due(done, at("2026-12-30T23:59:59Z"), 30));
        assert!(due(done, at("2026-12-31T00:00:00Z"), 30));
        assert!(due(done, done, 0));
        // A clock set back never deletes early.
        assert!(!due(done, at("2026-11-30T00:00:00Z"), 0));
    }

    #[test]
    fn only_a_manifest_naming_the_same_files_with_the_same_hashes_matches() {
        let (a, b) = ("a".repeat(64), "b".repeat(64));
        let m = parse_manifest(&format!("{a}  journal.jsonl\n{b}  lines/0001.csv\n")).unwrap();
        let local: BTreeMap<String, String> = [
            ("journal.jsonl".to_owned(), a.clone()),
            ("lines/0001.csv".to_owned(), b.clone()),
        ]
        .into();
        assert_eq!(matches(&local, &m), Ok(()));
        let mut changed = local.clone();
        changed.insert("journal.jsonl".into(), b.clone());
        assert!(matches(&changed, &m).unwrap_err().contains("differs"));
        let mut more = local.clone();
        more.insert("report.json".into(), a.clone());
        assert!(matches(&more, &m).unwrap_err().contains("report.json"));
        let mut fewer = local.clone();
        fewer.remove("lines/0001.csv");
        assert!(matches(&fewer, &m).unwrap_err().contains("lines/0001.csv"));
        assert!(parse_manifest("abc  x\n").is_err());
        assert!(parse_manifest(&format!("{a} x\n")).is_err());
        assert!(parse_manifest(&format!("{a}  x\n{b}  x\n")).is_err());
    }
}
