//! The one reader's policy, through both commands that read heights: each kind of bad or
//! unusual input is named in words (a header line, `;` and tab separators, decimal commas, a
//! row of NaN, a unit in the header or from `--z-unit`, a scale implausible for a stylus
//! profile), and `surfscan fit` and `surfscan analyze` agree on the same file: the same lines,
//! the same warnings from the reader, the same exit status. A result made from fewer lines than
//! the file holds is partial in both: "N of M lines" and exit 3.
//!
//! Depends on the `surfscan` binary only; the expected values are written out by the test
//! (the heights of a grid the test makes, in other spellings).

use serde_json::Value;
use std::f64::consts::PI;
use std::path::Path;
use std::process::Command;

const ROWS: usize = 16;
const COLS: usize = 300;
const PITCH_X_MM: f64 = 0.001;
const PITCH_Y_MM: f64 = 0.01;

/// Height of point `c` of line `r`, µm: a 3 µm tilt along x and a sine of its own amplitude and
/// phase per line.
fn height_um(r: usize, c: usize) -> f64 {
    let x = c as f64 * PITCH_X_MM;
    let a = 0.3 + 0.05 * r as f64;
    10.0 * x + a * (2.0 * PI * x / 0.02 + r as f64).sin()
}

/// The grid's rows, each height written by `cell` (which takes it in µm), joined by `sep`.
fn rows(cell: impl Fn(f64) -> String, sep: &str) -> Vec<String> {
    (0..ROWS)
        .map(|r| {
            (0..COLS)
                .map(|c| cell(height_um(r, c)))
                .collect::<Vec<_>>()
                .join(sep)
        })
        .collect()
}

fn um(v: f64) -> String {
    format!("{v:.6}")
}

/// What one command did with a file.
#[derive(Debug)]
struct Run {
    code: Option<i32>,
    stderr: String,
    /// The reader's and the command's warnings, without the prefix.
    warnings: Vec<String>,
    /// The lines used, by their index in the file's rows.
    lines: Vec<u64>,
    /// Ra of each line (analyze), or the IGES file's D and P sections (fit).
    ra_um: Vec<f64>,
    surface: Option<String>,
}

fn warnings(stderr: &str) -> Vec<String> {
    stderr
        .lines()
        .filter_map(|l| l.strip_prefix("surfscan: warning: "))
        .map(str::to_owned)
        .collect()
}

fn fit(dir: &Path, input: &Path, extra: &[&str]) -> Run {
    let (out, report) = (dir.join("s.igs"), dir.join("fit.json"));
    let _ = std::fs::remove_file(&out);
    let _ = std::fs::remove_file(&report);
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("fit")
        .arg(input)
        .arg("-o")
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .args(extra)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    let rep: Value = std::fs::read_to_string(&report)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(Value::Null);
    Run {
        code: o.status.code(),
        warnings: warnings(&stderr),
        lines: rep["lines"]
            .as_array()
            .map(|a| a.iter().map(|v| v.as_u64().unwrap()).collect())
            .unwrap_or_default(),
        ra_um: Vec::new(),
        surface: std::fs::read_to_string(&out).ok().map(|t| {
            t.lines()
                .filter(|l| matches!(l.as_bytes().get(72), Some(b'D' | b'P')))
                .collect::<Vec<_>>()
                .join("\n")
        }),
        stderr,
    }
}

fn analyze(dir: &Path, input: &Path, extra: &[&str]) -> Run {
    let out = dir.join("analysis");
    let _ = std::fs::remove_dir_all(&out);
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(input)
        .args(["--lc", "0.08", "--out"])
        .arg(&out)
        .args(extra)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    let rep: Value = std::fs::read_to_string(out.join("report.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(Value::Null);
    let lines = rep["lines"].as_array().cloned().unwrap_or_default();
    Run {
        code: o.status.code(),
        warnings: warnings(&stderr),
        lines: lines.iter().map(|l| l["index"].as_u64().unwrap()).collect(),
        ra_um: lines.iter().map(|l| l["Ra_um"].as_f64().unwrap()).collect(),
        surface: None,
        stderr,
    }
}

/// Both commands on `text` (written to `name`) with the reader flags `flags`: they must agree
/// on the exit status and the lines, and every warning `fit` gives (the reader's) must be
/// among `analyze`'s. Returns (fit, analyze).
fn both(dir: &Path, name: &str, text: &str, flags: &[&str]) -> (Run, Run) {
    let input = dir.join(name);
    std::fs::write(&input, text).unwrap();
    let (px, py) = (PITCH_X_MM.to_string(), PITCH_Y_MM.to_string());
    let grid = ["--pitch-x", px.as_str(), "--pitch-y", py.as_str()];
    let flags: Vec<&str> = if text.starts_with("x_") {
        flags.to_vec()
    } else {
        [&grid[..], flags].concat()
    };
    let f = fit(dir, &input, &flags);
    let a = analyze(dir, &input, &flags);
    assert_eq!(
        f.code, a.code,
        "{name}: fit {}\nanalyze {}",
        f.stderr, a.stderr
    );
    assert_eq!(f.lines, a.lines, "{name}: the same lines");
    for w in &f.warnings {
        assert!(
            a.warnings.contains(w),
            "{name}: fit warns {w:?}, analyze does not:\n{}",
            a.stderr
        );
    }
    (f, a)
}

fn close(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= 1e-9 * x.abs().max(1.0))
}

#[test]
fn unusual_but_readable_grid_csvs_are_read_as_the_plain_one_and_said() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let plain = rows(um, ",").join("\n") + "\n";
    let (pf, pa) = both(d, "plain.csv", &plain, &[]);
    assert_eq!(
        (pf.code, pa.code),
        (Some(0), Some(0)),
        "{}\n{}",
        pf.stderr,
        pa.stderr
    );
    assert_eq!(pa.lines, (0..ROWS as u64).collect::<Vec<_>>());
    assert!(
        pf.warnings.is_empty(),
        "the plain format needs no words: {:?}",
        pf.warnings
    );

    // Each spelling of the same heights: the same surface (fit) and the same Ra per line
    // (analyze), and the reader says what it found.
    let header = format!(
        "{}\n{plain}",
        (0..COLS)
            .map(|c| format!("z{c}_um"))
            .collect::<Vec<_>>()
            .join(",")
    );
    let semicolons = rows(|v| um(v).replace('.', ","), ";").join("\n") + "\n";
    let tabs = rows(um, "\t").join("\r\n") + "\r\n";
    let comments = format!("# exported by a test\n# heights in µm\n{plain}");
    for (name, text, says) in [
        (
            "header.csv",
            header,
            vec!["line 1 is a header (\"z0_um,z1_um"],
        ),
        (
            "semicolons.csv",
            semicolons,
            vec![
                "values are separated by ';' (not ',')",
                "decimal commas (1,25) are read as decimal points (1.25)",
            ],
        ),
        (
            "tabs.csv",
            tabs,
            vec!["values are separated by tabs (not ',')"],
        ),
        (
            "comments.csv",
            comments,
            vec!["2 comment lines (starting with #) before the data were skipped"],
        ),
    ] {
        let (f, a) = both(d, name, &text, &[]);
        assert_eq!(f.code, Some(0), "{name}: {}", f.stderr);
        assert_eq!(f.surface, pf.surface, "{name}: the same surface");
        assert_eq!(a.ra_um, pa.ra_um, "{name}: the same Ra");
        for s in says {
            assert!(
                f.warnings.iter().any(|w| w.contains(s)),
                "{name}: {s:?} in {:?}",
                f.warnings
            );
        }
    }

    // Heights in nm, said by a header or by the flag: converted, the same results.
    let nm = rows(|v| format!("{:.3}", v * 1000.0), ",");
    let nm_plain = nm.join("\n") + "\n";
    let nm_header = format!("height [nm]\n{nm_plain}");
    for (name, text, flags) in [
        ("nm-header.csv", nm_header.clone(), vec![]),
        ("nm-flag.csv", nm_plain.clone(), vec!["--z-unit", "nm"]),
    ] {
        let (f, a) = both(d, name, &text, &flags);
        assert_eq!(f.code, Some(0), "{name}: {}", f.stderr);
        assert!(
            close(&a.ra_um, &pa.ra_um),
            "{name}: {:?} vs {:?}",
            a.ra_um,
            pa.ra_um
        );
        assert!(
            f.warnings.iter().any(|w| w.starts_with("heights in nm (")),
            "{name}: {:?}",
            f.warnings
        );
    }
    // A flag against the header: refused as usage, naming both.
    let (f, _) = both(d, "nm-against.csv", &nm_header, &["--z-unit", "mm"]);
    assert_eq!(f.code, Some(2), "{}", f.stderr);
    assert!(
        f.stderr.contains("--z-unit mm but the header") && f.stderr.contains("names nm"),
        "{}",
        f.stderr
    );
}

#[test]
fn heights_in_the_wrong_unit_are_refused_naming_the_mix_up_and_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, plain) = both(d, "plain.csv", &(rows(um, ",").join("\n") + "\n"), &[]);
    // In mm, read as µm: Sq of a few nm.
    let mm = rows(|v| format!("{:.9}", v / 1000.0), ",").join("\n") + "\n";
    let (f, a) = both(d, "mm.csv", &mm, &[]);
    assert_eq!(f.code, Some(1), "{}", f.stderr);
    for r in [&f, &a] {
        assert!(
            r.stderr.contains("heights in mm read as µm look like this")
                && r.stderr.contains("--z-unit mm"),
            "{}",
            r.stderr
        );
    }
    assert!(!d.join("s.igs").exists() && !d.join("analysis/report.json").exists());
    // Said with the flag, the same results as the file in µm.
    let (f, a) = both(d, "mm.csv", &mm, &["--z-unit", "mm"]);
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    assert!(
        close(&a.ra_um, &plain.ra_um),
        "{:?} vs {:?}",
        a.ra_um,
        plain.ra_um
    );
    // In nm, read as µm: a range of millimetres.
    let nm = rows(|v| format!("{:.3}", v * 1000.0), ",").join("\n") + "\n";
    let (f, _) = both(d, "nm.csv", &nm, &[]);
    assert_eq!(f.code, Some(1), "{}", f.stderr);
    assert!(
        f.stderr
            .contains("more than a stylus profiler's 2 mm: heights in nm read as µm"),
        "{}",
        f.stderr
    );
    // µm stated for heights that look like mm: read, with the warning.
    let (f, a) = both(d, "mm.csv", &mm, &["--z-unit", "um"]);
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    assert!(
        a.warnings
            .iter()
            .any(|w| w.contains("read as given (--z-unit um)")),
        "{:?}",
        a.warnings
    );
}

#[test]
fn a_row_that_cannot_be_used_leaves_a_partial_result_in_both_commands() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut r = rows(um, ",");
    r[3] = format!("NaN,{}", r[3].split_once(',').unwrap().1);
    r[9] = r[9].replacen(',', ",1.2.3,", 1);
    let (f, a) = both(d, "nan.csv", &(r.join("\n") + "\n"), &[]);
    assert_eq!(f.code, Some(3), "{}", f.stderr);
    let kept: Vec<u64> = (0..ROWS as u64).filter(|&k| k != 3 && k != 9).collect();
    assert_eq!(a.lines, kept);
    let said = "2 of the input's 16 lines cannot be used and were left out";
    for run in [&f, &a] {
        assert!(
            run.warnings.iter().any(|w| w.starts_with(said)
                && w.contains("line 4 (1 of its 300 heights are not finite")
                && w.contains("line 10 (column 2: \"1.2.3\" is not a number)")),
            "{:?}",
            run.warnings
        );
        assert!(run.stderr.contains("14 of 16 lines"), "{}", run.stderr);
    }
    // Both wrote what they could.
    assert!(f.surface.is_some() && a.ra_um.len() == 14);
}

#[test]
fn what_cannot_be_read_without_guessing_is_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let plain = rows(um, ",");
    // Thousands separators: which mark is the decimal one cannot be told.
    let mut both_marks = plain
        .iter()
        .map(|l| l.replace(',', ";"))
        .collect::<Vec<_>>();
    both_marks[0] = both_marks[0].replacen(';', ";1.234,5;", 1);
    let (f, _) = both(d, "marks.csv", &(both_marks.join("\n") + "\n"), &[]);
    assert_eq!(f.code, Some(1), "{}", f.stderr);
    assert!(
        f.stderr
            .contains("line 1: \"1.234,5\" has both a decimal point and a comma"),
        "{}",
        f.stderr
    );
    // A table of records (one point per line) is not a grid of heights.
    let table =
        "profile,y_mm,x_mm,z_um\n0,0,0,1.5\n0,0,0.001,1.25\n1,0.01,0,1.0\n1,0.01,0.001,0.5\n";
    let (f, _) = both(d, "table.csv", table, &[]);
    assert_eq!(f.code, Some(1), "{}", f.stderr);
    assert!(
        f.stderr.contains("names the columns of a table of records"),
        "{}",
        f.stderr
    );
    // A grid CSV without pitches: usage in both.
    let input = d.join("grid.csv");
    std::fs::write(&input, plain.join("\n")).unwrap();
    let f = fit(d, &input, &[]);
    let a = analyze(d, &input, &[]);
    assert_eq!(
        (f.code, a.code),
        (Some(2), Some(2)),
        "{}\n{}",
        f.stderr,
        a.stderr
    );
}

#[test]
fn a_profile_csv_in_the_wrong_unit_is_refused_and_one_in_nm_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let profile = |x_scale: f64, z: &dyn Fn(f64) -> String, header: &str| {
        let mut t = format!("{header}\n");
        for c in 0..2000 {
            let x = c as f64 * PITCH_X_MM;
            t.push_str(&format!("{:.9},{}\n", x * x_scale, z(height_um(2, c))));
        }
        t
    };
    let run = |name: &str, text: &str, flags: &[&str]| {
        let input = d.join(name);
        std::fs::write(&input, text).unwrap();
        analyze(d, &input, flags)
    };
    let plain = run(
        "um.csv",
        &profile(1.0, &|v| format!("{v:.6}"), "x_mm,z_um"),
        &[],
    );
    assert_eq!(plain.code, Some(0), "{}", plain.stderr);
    // z in mm under a header that says µm: Sq of nanometres, refused.
    let mm = run(
        "mm.csv",
        &profile(1.0, &|v| format!("{:.9}", v / 1000.0), "x_mm,z_um"),
        &[],
    );
    assert_eq!(mm.code, Some(1), "{}", mm.stderr);
    assert!(
        mm.stderr.contains("heights in mm read as µm"),
        "{}",
        mm.stderr
    );
    // A header naming nm: converted, the same Ra.
    let nm = run(
        "nm.csv",
        &profile(1.0, &|v| format!("{:.3}", v * 1000.0), "x_mm,z_nm"),
        &[],
    );
    assert_eq!(nm.code, Some(0), "{}", nm.stderr);
    assert!(
        close(&nm.ra_um, &plain.ra_um),
        "{:?} {:?}",
        nm.ra_um,
        plain.ra_um
    );
    // x in m under a header that says mm: a profile of 2 µm, refused naming the header fix.
    let m = run(
        "m.csv",
        &profile(1e-3, &|v| format!("{v:.6}"), "x_mm,z_um"),
        &[],
    );
    assert_eq!(m.code, Some(1), "{}", m.stderr);
    assert!(
        m.stderr.contains("x in µm read as mm") && m.stderr.contains("x_um"),
        "{}",
        m.stderr
    );
    // x in µm said by the header: the same Ra.
    let xum = run(
        "xum.csv",
        &profile(1000.0, &|v| format!("{v:.6}"), "x_um,z_um"),
        &[],
    );
    assert_eq!(xum.code, Some(0), "{}", xum.stderr);
    assert!(
        close(&xum.ra_um, &plain.ra_um),
        "{:?} {:?}",
        xum.ra_um,
        plain.ra_um
    );
}
