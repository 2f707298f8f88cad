//! The characterisation's results are pinned: every number of `report.json` (and of `fit
//! --report`) and the geometry of the IGES file, for the real data sets in `tests/data` and
//! the demo's grid, as the program gave them at the commit named in each fixture
//! (`tests/data/results/NAME.json`, captured before the characterisation was reorganised into
//! one reader and one pipeline). A reorganisation must not change a result; a change that is
//! meant to change one re-captures that fixture in the same commit and says why.
//!
//! Compared: every number, boolean and null at its place in the JSON (keys the program added
//! since are free; strings, the timings and what a case lists as changed on purpose are not
//! compared), the SHA-256 of the IGES Directory Entry and Parameter Data sections (the
//! surface, byte for byte) and the Start section's words (paths and the scan's time
//! replaced).
//!
//! `SURFSCAN_CAPTURE_RESULTS=1 cargo test --test it results_unchanged` writes the fixtures
//! instead of comparing (only to pin a deliberate change of results).

use serde_json::Value;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The bundled data, `tests/data`.
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

fn fixture_path(name: &str) -> PathBuf {
    data_dir().join("results").join(format!("{name}.json"))
}

fn capturing() -> bool {
    std::env::var_os("SURFSCAN_CAPTURE_RESULTS").is_some_and(|v| v == "1")
}

/// `v` without its timings and a scan's duration (they differ from run to run).
pub fn pruned(mut v: Value) -> Value {
    fn walk(v: &mut Value) {
        match v {
            Value::Object(m) => {
                m.remove("timings_s");
                // The demo's scan takes as long as the machine lets it.
                m.remove("duration_s");
                m.values_mut().for_each(walk);
            }
            Value::Array(a) => a.iter_mut().for_each(walk),
            _ => {}
        }
    }
    walk(&mut v);
    v
}

/// A scan directory's name starts with its start time (`20261206T030229Z-…`): replaced, so
/// two runs of the demo read alike.
fn without_scan_times(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = String::with_capacity(s.len());
    let mut i = 0;
    while i < b.len() {
        let stamp = b.len() >= i + 16
            && b[i..i + 8].iter().all(u8::is_ascii_digit)
            && b[i + 8] == b'T'
            && b[i + 9..i + 15].iter().all(u8::is_ascii_digit)
            && b[i + 15] == b'Z';
        if stamp {
            out.push_str("{TIME}");
            i += 16;
        } else {
            let c = s[i..].chars().next().unwrap();
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

/// A word of the Start section that differs from run to run or commit to commit as a
/// placeholder: a commit or a hash (hexadecimal, 12 digits or more), a start time
/// (`2026-12-06T03:09:39.796473825+00:00`).
fn volatile_word(w: &str) -> String {
    let core = w.trim_matches(|c: char| "();,.".contains(c));
    let hex = core.len() >= 12 && core.bytes().all(|b| b.is_ascii_hexdigit());
    let time = core.len() >= 19 && core.as_bytes()[4] == b'-' && core.as_bytes()[10] == b'T';
    match (hex, time) {
        (true, _) => w.replace(core, "{HEX}"),
        (_, true) => w.replace(core, "{TIME}"),
        _ => w.to_string(),
    }
}

/// The IGES file's fingerprint: the SHA-256 of its D and P sections and the words of its
/// Start section, whitespace runs as one space, `paths` as placeholders.
pub fn iges_fingerprint(path: &Path, paths: &[(&Path, &str)]) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut dp = Sha256::new();
    let mut start = String::new();
    for line in text.lines() {
        match line.as_bytes().get(72) {
            Some(b'D') | Some(b'P') => {
                dp.update(line.as_bytes());
                dp.update(b"\n");
            }
            // The writer breaks the Start text at a space; a line filled to column 72 has
            // none left before its sequence field, so the lines are joined with one (the data
            // directory's length, which differs between checkouts, decides where lines fill).
            Some(b'S') => {
                start.push_str(&line[..72]);
                start.push(' ');
            }
            _ => {}
        }
    }
    let mut start = start.split_whitespace().collect::<Vec<_>>().join(" ");
    for (p, name) in paths {
        start = start.replace(&p.display().to_string(), name);
    }
    let start: Vec<String> = without_scan_times(&start)
        .split(' ')
        .map(volatile_word)
        .collect();
    let dp: String = dp.finalize().iter().map(|b| format!("{b:02x}")).collect();
    serde_json::json!({ "dp_sha256": dp, "start": start.join(" ") })
}

/// Every difference between `want` (the fixture) and `got` at `path` and below: numbers,
/// booleans and nulls must be equal, arrays as long (but for lists of words); strings are not
/// compared, except the words of the IGES Start section.
fn differences(path: &str, want: &Value, got: Option<&Value>, out: &mut Vec<String>) {
    let Some(got) = got else {
        if !matches!(want, Value::String(_)) || path.ends_with("/iges/start") {
            out.push(format!("{path}: missing (was {})", short(want)));
        }
        return;
    };
    match (want, got) {
        (Value::Object(w), Value::Object(g)) => {
            for (k, wv) in w {
                differences(&format!("{path}/{k}"), wv, g.get(k), out);
            }
        }
        (Value::Array(w), Value::Array(g)) => {
            // Words (the warnings) are not results: their number is free.
            let words = |a: &[Value]| a.iter().all(Value::is_string);
            if words(w) && words(g) {
                return;
            }
            if w.len() != g.len() {
                out.push(format!("{path}: {} elements, was {}", g.len(), w.len()));
            }
            for (k, wv) in w.iter().enumerate() {
                differences(&format!("{path}/{k}"), wv, g.get(k), out);
            }
        }
        // The Start section's words are compared without their spacing: fixtures captured
        // before the lines were joined with a space hold words run together where a line was
        // filled to column 72, which depends on the length of the checkout's path.
        (Value::String(a), Value::String(b))
            if !path.ends_with("/iges/start") || without_spaces(a) == without_spaces(b) => {}
        (Value::String(_), _) if !path.ends_with("/iges/start") => {}
        (Value::Number(a), Value::Number(b)) if a.as_f64() == b.as_f64() => {}
        (a, b) if a == b => {}
        (a, b) => out.push(format!("{path}: {} (was {})", short(b), short(a))),
    }
}

fn without_spaces(s: &str) -> String {
    s.chars().filter(|c| !c.is_whitespace()).collect()
}

fn short(v: &Value) -> String {
    let s = v.to_string();
    if s.len() > 80 {
        format!(
            "{}…",
            &s[..s.char_indices().nth(77).map_or(s.len(), |(i, _)| i)]
        )
    } else {
        s
    }
}

/// Compares `got` (pruned outputs of one case) with the fixture `name`, leaving out the
/// places in `changed` (each a path prefix such as `/report/characterisation/complete`,
/// changed on purpose since the capture); or, when capturing, writes the fixture.
pub fn check(name: &str, got: Value, changed: &[&str]) {
    let path = fixture_path(name);
    if capturing() {
        let mut v = got;
        v["captured_at"] = Value::String(
            String::from_utf8(
                Command::new("git")
                    .args(["rev-parse", "--short", "HEAD"])
                    .current_dir(env!("CARGO_MANIFEST_DIR"))
                    .output()
                    .unwrap()
                    .stdout,
            )
            .unwrap()
            .trim()
            .to_string(),
        );
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, serde_json::to_string(&v).unwrap() + "\n").unwrap();
        return;
    }
    let want: Value = serde_json::from_str(
        &std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap();
    let mut diffs = Vec::new();
    differences("", &want, Some(&got), &mut diffs);
    diffs.retain(|d| {
        !changed
            .iter()
            .any(|c| d.starts_with(&format!("{c}/")) || d.starts_with(&format!("{c}:")))
    });
    assert!(
        diffs.is_empty(),
        "{name}: {} results differ from {} (captured at {}):\n{}",
        diffs.len(),
        path.display(),
        want["captured_at"],
        diffs
            .iter()
            .take(40)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}

/// A JSON file's content, pruned.
pub fn json_file(path: &Path) -> Value {
    pruned(
        serde_json::from_str(
            &std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        )
        .unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
}

/// One command of the comparison.
struct Case {
    name: &'static str,
    /// The subcommand and its arguments; `{T}` is the case's temporary directory, `{D}`
    /// `tests/data`.
    args: &'static [&'static str],
    /// Arguments added since the capture (flags that did not exist then), with why.
    added: &'static [&'static str],
    /// Copy `tests/data/scan-e46f88d`'s scan into `{T}/scan` first.
    scan: bool,
    /// The exit status now.
    exit: i32,
    /// Places changed on purpose since the capture.
    changed: &'static [&'static str],
}

const SUR2: &[&str] = &[
    "{D}/sur-2.grid.csv",
    "--pitch-x",
    "0.003484",
    "--pitch-y",
    "0.010452",
];

fn cases() -> Vec<Case> {
    let analyze = |name, input: &'static str, extra: &'static [&'static str]| Case {
        name,
        args: Box::leak(
            [&["analyze", input, "--out", "{T}/out"][..], extra]
                .concat()
                .into_boxed_slice(),
        ),
        added: &[],
        scan: false,
        exit: 0,
        changed: &[],
    };
    let with = |args: &[&'static str], extra: &[&'static str]| -> &'static [&'static str] {
        Box::leak([args, extra].concat().into_boxed_slice())
    };
    vec![
        analyze(
            "analyze-mitutoyo",
            "{D}/real/mitutoyo_surftest_R.x_mm_z_um.csv",
            &[],
        ),
        analyze(
            "analyze-mitutoyo-r-profile",
            "{D}/real/mitutoyo_surftest_R.x_mm_z_um.csv",
            &["--no-filter", "--lc", "2.5"],
        ),
        analyze("analyze-dektak-1", "{D}/real/dektak-1.x_mm_z_um.csv", &[]),
        analyze("analyze-hfm-1", "{D}/real/hfm-1.x_mm_z_um.csv", &[]),
        Case {
            // Real nanoscale data (Sq 2.8 nm): read only when the unit is stated.
            added: &["--z-unit", "um"],
            ..analyze(
                "analyze-opdx-3",
                "{D}/real/opdx-3.x_mm_z_um.csv",
                &["--lc", "0.008"],
            )
        },
        Case {
            name: "analyze-sur-2",
            args: with(&["analyze", "--out", "{T}/out"], SUR2),
            ..analyze("", "", &[])
        },
        Case {
            name: "analyze-sur-2-excluded-least-squares",
            args: with(
                &[
                    "analyze",
                    "--out",
                    "{T}/out",
                    "--outliers",
                    "exclude",
                    "--replace-spikes",
                ],
                &[SUR2, &["--v-method", "least-squares", "--degree-v", "3"]].concat(),
            ),
            ..analyze("", "", &[])
        },
        Case {
            name: "fit-sur-2",
            args: with(
                &["fit", "-o", "{T}/s.igs", "--report", "{T}/fit.json"],
                SUR2,
            ),
            ..analyze("", "", &[])
        },
        Case {
            name: "fit-sur-2-least-squares-compared",
            args: with(
                &[
                    "fit",
                    "-o",
                    "{T}/s.igs",
                    "--report",
                    "{T}/fit.json",
                    "--compare",
                ],
                &[SUR2, &["--v-method", "least-squares", "--replace-spikes"]].concat(),
            ),
            ..analyze("", "", &[])
        },
        Case {
            name: "analyze-scan-e46f88d",
            args: &["analyze", "{T}/scan", "--out", "{T}/out"],
            scan: true,
            ..analyze("", "", &[])
        },
        Case {
            name: "fit-scan-e46f88d",
            args: &[
                "fit",
                "{T}/scan",
                "-o",
                "{T}/s.igs",
                "--report",
                "{T}/fit.json",
            ],
            scan: true,
            ..analyze("", "", &[])
        },
    ]
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dest = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dest);
        } else {
            std::fs::copy(e.path(), dest).unwrap();
        }
    }
}

/// The outputs in `t` that the fixtures pin: `out/report.json`, the fit report `fit.json`
/// and the IGES file `s.igs` (its Start section with `t`, `tests/data` and `iges_paths` as
/// placeholders).
pub fn outputs_of(t: &Path, iges_paths: &[(&Path, &str)]) -> Value {
    let mut got = serde_json::Map::new();
    for (key, file) in [("report", "out/report.json"), ("fit_report", "fit.json")] {
        let p = t.join(file);
        if p.exists() {
            got.insert(key.into(), json_file(&p));
        }
    }
    let igs = t.join("s.igs");
    if igs.exists() {
        let data = data_dir();
        let mut paths = vec![(data.as_path(), "{D}"), (t, "{T}")];
        paths.extend_from_slice(iges_paths);
        got.insert("iges".into(), iges_fingerprint(&igs, &paths));
    }
    Value::Object(got)
}

#[test]
fn reports_and_surfaces_of_the_real_data_are_as_captured() {
    let data = data_dir();
    for case in cases() {
        let t = tempfile::tempdir().unwrap();
        let scan_src = data.join("scan-e46f88d/20261202T032241Z-coupon-a-17");
        if case.scan {
            copy_dir(&scan_src, &t.path().join("scan"));
        }
        let fill = |a: &str| {
            a.replace("{T}", &t.path().display().to_string())
                .replace("{D}", &data.display().to_string())
        };
        let mut args: Vec<String> = case.args.iter().map(|a| fill(a)).collect();
        if !capturing() {
            args.extend(case.added.iter().map(|a| fill(a)));
        }
        let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(&args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(
            o.status.code(),
            Some(case.exit),
            "{}: {args:?}\n{stderr}",
            case.name
        );
        let mut got = outputs_of(t.path(), &[]);
        got["exit"] = Value::from(o.status.code().unwrap_or(-1));
        got["args"] = Value::from(case.args.to_vec());
        let mut changed = case.changed.to_vec();
        changed.push("/exit");
        check(case.name, got, &changed);
    }
}
