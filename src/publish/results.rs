//! The results message of a completed scan (`surfscan/<station>/results`): what a lab's
//! systems need without fetching the scan directory — the recipe and specimen, the verdict
//! against the recipe's specification, each line parameter's mean with its standard
//! deviation and expanded uncertainty U, the report's warnings, and the scan's output files
//! with their SHA-256 so that a consumer can check a copy it fetches.
//!
//! Everything is read back from what the scan left on disk (the journal's start record and
//! `report.json`, the files themselves), so the message says what the files say; it is built
//! off the scan's path by the publisher's writer and kept in the outbox like the events.
//!
//! Layer 4 (process edge): depends on the journal's types and serde_json; [`read`] does the
//! blocking file I/O, [`payload`] is pure.

use crate::scan::journal::{read_journal, Record, StartRecord};
use serde_json::{json, Map, Value};
use std::path::Path;

/// One output file of a scan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutputFile {
    /// Its name in the scan directory.
    pub name: String,
    /// Its size.
    pub bytes: u64,
    /// Its SHA-256, lower-case hex.
    pub sha256: String,
}

/// The results message of scan `scan_id` from its start record, its `report.json` (parsed)
/// and its output files. Members that the scan does not have are `null`: `recipe` for a scan
/// of the station's own plan, `verdict` without a specification, `parameters` without a
/// report.
pub fn payload(
    scan_id: &str,
    start: Option<&StartRecord>,
    report: Option<&Value>,
    files: &[OutputFile],
) -> Map<String, Value> {
    let job = start.and_then(|s| s.job.as_ref());
    let spec = report
        .map(|r| &r["specification"])
        .filter(|v| v.is_object());
    let parameters: Option<Vec<Value>> = report
        .and_then(|r| r["uncertainty"]["parameters"].as_array())
        .map(|ps| {
            ps.iter()
                .map(|p| {
                    json!({
                        "parameter": p["parameter"],
                        "n": p["n"],
                        "mean": p["mean"],
                        "s": p["s"],
                        "U": p["U"],
                        "k": p["k"],
                    })
                })
                .collect()
        });
    let mut m = Map::new();
    m.insert("scan_id".into(), scan_id.into());
    m.insert("recipe".into(), json!(job.map(|j| &j.recipe)));
    m.insert("recipe_sha256".into(), json!(job.map(|j| &j.recipe_sha256)));
    m.insert("job".into(), json!(job.and_then(|j| j.id)));
    m.insert("specimen".into(), json!(start.map(|s| &s.specimen)));
    m.insert("operator".into(), json!(start.map(|s| &s.operator)));
    m.insert(
        "verdict".into(),
        spec.map_or(Value::Null, |s| s["verdict"].clone()),
    );
    m.insert(
        "verdict_summary".into(),
        spec.map_or(Value::Null, |s| s["summary"].clone()),
    );
    m.insert(
        "limits".into(),
        spec.map_or(Value::Null, |s| s["limits"].clone()),
    );
    m.insert("parameters".into(), json!(parameters));
    m.insert(
        "warnings".into(),
        report.map_or(json!([]), |r| r["warnings"].clone()),
    );
    m.insert(
        "files".into(),
        files
            .iter()
            .map(|f| json!({"name": f.name, "bytes": f.bytes, "sha256": f.sha256}))
            .collect(),
    );
    m
}

/// The regular files at the top of a scan directory (its products and journal; the line
/// files below `lines/` are raw data, which the archive keeps), sorted by name, with their
/// SHA-256; temporary files (a leading `.`) are left out.
pub fn output_files(dir: &Path) -> std::io::Result<Vec<OutputFile>> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir)? {
        let e = e?;
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || !e.file_type()?.is_file() {
            continue;
        }
        let bytes = std::fs::read(e.path())?;
        out.push(OutputFile {
            sha256: crate::scan::store::hex_sha256(&bytes),
            bytes: bytes.len() as u64,
            name,
        });
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// Reads what the results message of the scan in `dir` needs and builds it. A journal or a
/// report that cannot be read leaves its members `null` (and is named in the error list
/// returned beside the message) rather than holding back the rest.
pub fn read(scan_id: &str, dir: &Path) -> (Map<String, Value>, Vec<String>) {
    let mut problems = Vec::new();
    let start = match read_journal(&dir.join("journal.jsonl")) {
        Ok(r) => r.records.into_iter().find_map(|r| match r {
            Record::Start(s) => Some(*s),
            _ => None,
        }),
        Err(e) => {
            problems.push(e.to_string());
            None
        }
    };
    let report = match std::fs::read(dir.join("report.json")) {
        Ok(b) => match serde_json::from_slice::<Value>(&b) {
            Ok(v) => Some(v),
            Err(e) => {
                problems.push(format!("{}: {e}", dir.join("report.json").display()));
                None
            }
        },
        Err(e) => {
            problems.push(format!("{}: {e}", dir.join("report.json").display()));
            None
        }
    };
    let files = output_files(dir).unwrap_or_else(|e| {
        problems.push(format!("{}: {e}", dir.display()));
        Vec::new()
    });
    (
        payload(scan_id, start.as_ref(), report.as_ref(), &files),
        problems,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_message_takes_the_verdict_and_the_statistics_from_the_report() {
        let report = json!({
            "specification": {"verdict": "does not conform", "summary": "does not conform (Ra max rule)", "limits": [{"parameter": "Ra_um"}]},
            "uncertainty": {"parameters": [
                {"parameter": "Ra_um", "n": 5, "mean": 0.61, "s": 0.02, "u_mean": 0.009, "U": 0.05, "k": 2.0, "scaling": "x"}
            ]},
            "warnings": ["a warning"],
        });
        let files = [OutputFile {
            name: "report.json".into(),
            bytes: 7,
            sha256: "a".repeat(64),
        }];
        let m = payload("S1", None, Some(&report), &files);
        assert_eq!(m["verdict"], "does not conform");
        assert_eq!(m["verdict_summary"], "does not conform (Ra max rule)");
        assert_eq!(
            m["parameters"],
            json!([{"parameter": "Ra_um", "n": 5, "mean": 0.61, "s": 0.02, "U": 0.05, "k": 2.0}])
        );
        assert_eq!(m["warnings"], json!(["a warning"]));
        assert_eq!(m["files"][0]["sha256"], "a".repeat(64));
        assert_eq!(m["recipe"], Value::Null);
        assert_eq!(m["specimen"], Value::Null);
        // Without a specification there is no verdict, and no report means no parameters.
        let m = payload("S1", None, Some(&json!({"specification": null})), &[]);
        assert_eq!(m["verdict"], Value::Null);
        let m = payload("S1", None, None, &[]);
        assert_eq!(m["parameters"], Value::Null);
        assert_eq!(m["warnings"], json!([]));
    }

    #[test]
    fn output_files_are_the_top_level_files_without_temporaries() {
        let t = tempfile::tempdir().unwrap();
        std::fs::create_dir(t.path().join("lines")).unwrap();
        std::fs::write(t.path().join("lines/0001.csv"), "1").unwrap();
        std::fs::write(t.path().join("report.json"), "{}").unwrap();
        std::fs::write(t.path().join(".report.json.tmp"), "{").unwrap();
        std::fs::write(t.path().join("journal.jsonl"), "abc").unwrap();
        let f = output_files(t.path()).unwrap();
        let names: Vec<&str> = f.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["journal.jsonl", "report.json"]);
        // SHA-256("abc"), FIPS 180-2's first example.
        assert_eq!(
            f[0].sha256,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(f[0].bytes, 3);
    }
}
