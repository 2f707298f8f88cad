//! The honest model end to end through the real binary: a grid with a 100 µm spike keeps
//! every line's parameters, names the spike and the fold, writes the data's files and exits 3
//! (partial characterisation); a smooth sine grid is supported between lines and uncorrelated
//! lines are not, and the summaries say so; spikes are replaced for the fit only when asked
//! and then named in the IGES Start section; `fit --compare` prints the alternatives; the
//! default IGES surface is the paper's fit bit for bit; the model section's two orders (on
//! one core and on more) give the same files.

use crate::model_honesty::{sine_grid, uncorrelated_grid};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};
use surfscan::fit::{fit_grid, FitOptions};
use surfscan::iges::reader::read_iges;

const ROWS: usize = 31;
const COLS: usize = 300;
const PX: f64 = 0.0015;
const PY: f64 = 0.01;

fn surfscan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
}

fn write_grid(path: &Path, z: &[f64]) {
    let text: String = z
        .chunks(COLS)
        .map(|row| {
            let mut l = row
                .iter()
                .map(|v| format!("{v:?}"))
                .collect::<Vec<_>>()
                .join(",");
            l.push('\n');
            l
        })
        .collect();
    std::fs::write(path, text).unwrap();
}

fn analyze(grid: &Path, out: &Path, extra: &[&str]) -> Output {
    analyze_by(surfscan(), grid, out, extra)
}

/// [`analyze`] run by `program` (surfscan, or a command that runs it with its own arguments).
fn analyze_by(mut program: Command, grid: &Path, out: &Path, extra: &[&str]) -> Output {
    program
        .arg("analyze")
        .arg(grid)
        .args(["--pitch-x", &PX.to_string(), "--pitch-y", &PY.to_string()])
        .args([
            "--no-filter",
            "--lc",
            "0.08",
            "--curves",
            "5",
            "--levels",
            "21",
            "--out",
        ])
        .arg(out)
        .args(extra)
        .output()
        .expect("surfscan (or taskset, util-linux) starts")
}

fn report(dir: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap()
}

fn text(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn a_100_um_spike_keeps_every_lines_parameters_names_the_spike_and_exits_partial() {
    let dir = tempfile::tempdir().unwrap();
    let mut z = uncorrelated_grid(3, COLS);
    let (line, at) = (12usize, 150usize);
    z[line * COLS + at] += 100.0;
    let grid = dir.path().join("spike.csv");
    write_grid(&grid, &z);
    let out = dir.path().join("out");
    let o = analyze(&grid, &out, &[]);
    let (stdout, stderr) = text(&o);
    let r = report(&out);
    let warnings: Vec<&str> = r["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect();
    // Per-line parameters for every line, the measured grid's areal parameters and files.
    let lines = r["lines"].as_array().unwrap();
    assert_eq!(lines.len(), ROWS);
    assert!(lines
        .iter()
        .all(|l| l["Ra_um"].as_f64().is_some_and(f64::is_finite)));
    assert!(r["surface_grid"]["Sq_um"].as_f64().is_some());
    for f in [
        "measured.x3p",
        "heightmap.png",
        "summary.csv",
        "overlay.png",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // The spike, named with line, x and height, in the report and the warnings.
    let spikes = r["outliers"]["spikes"].as_array().unwrap();
    assert_eq!(spikes.len(), 1, "{spikes:?}");
    assert_eq!(spikes[0]["line"], 12);
    assert_eq!(spikes[0]["peak"], at);
    assert!((spikes[0]["x_mm"].as_f64().unwrap() - at as f64 * PX).abs() < 1e-12);
    // serde_json reads floats to within an ulp (no float_roundtrip feature).
    assert!((spikes[0]["height_um"].as_f64().unwrap() - z[line * COLS + at]).abs() < 1e-9);
    assert_eq!(r["outliers"]["policy"], "flag");
    assert!(
        warnings
            .iter()
            .any(|w| w.starts_with("spike in line 13 (0012) at x = 0.2250 mm")),
        "{warnings:?}"
    );
    // The data stay as measured (flag only): line 12's Rt includes the spike.
    assert!(lines[line]["Rt_um"].as_f64().unwrap() > 90.0);
    // No fold in the default surface, or a named one; a fold leaves no model surface and
    // makes the characterisation partial, exit 3, said in the summary.
    let folds = !r["model_checks"]["iso_curves"]
        .as_array()
        .unwrap()
        .is_empty();
    if folds {
        assert!(
            warnings
                .iter()
                .any(|w| w.starts_with("model fold: x runs backwards")),
            "{warnings:?}"
        );
        assert_eq!(r["characterisation"]["complete"], false);
        assert_eq!(o.status.code(), Some(3), "{stderr}");
        assert!(
            stderr.contains("the characterisation is partial"),
            "{stderr}"
        );
        assert!(!out.join("model.x3p").exists());
    } else {
        assert!(!warnings.iter().any(|w| w.starts_with("model fold")));
    }
    assert!(stdout.contains("between lines is"), "{stdout}");
}

#[test]
fn analyze_says_a_sine_grid_is_supported_and_uncorrelated_lines_are_not() {
    let dir = tempfile::tempdir().unwrap();
    for (name, z, supported) in [
        ("sine", sine_grid(COLS), true),
        ("noise", uncorrelated_grid(5, COLS), false),
    ] {
        let grid = dir.path().join(format!("{name}.csv"));
        write_grid(&grid, &z);
        let out = dir.path().join(name);
        let o = analyze(&grid, &out, &[]);
        let (stdout, stderr) = text(&o);
        assert_eq!(o.status.code(), Some(0), "{name}: {stderr}");
        let r = report(&out);
        let b = &r["between_lines"];
        assert_eq!(b["supported"], supported, "{name}: {b}");
        let word = if supported {
            "the model between lines is supported by the data (hold-out rms"
        } else {
            "the model between lines is not supported by the data (hold-out rms"
        };
        assert!(stdout.contains(word), "{name}: {stdout}");
        // The figure printed is the report's.
        let ratio = b["rms_over_sq"].as_f64().unwrap();
        assert!(
            stdout.contains(&format!("= {} × Sq)", surfscan::numfmt::sig(ratio, 2))),
            "{stdout}"
        );
        assert!(r["characterisation"]["complete"].as_bool().unwrap());
        // The anisotropy caveats are stated either way.
        let a = &r["anisotropy"];
        assert!((a["pitch_ratio_y_over_x"].as_f64().unwrap() - PY / PX).abs() < 1e-9);
        if supported {
            // cos(2π · 0.01 / 0.25) = 0.97 for the y factor alone; the x factor's sign
            // changes lower the pooled correlation a little.
            assert!(
                a["line_correlation_at_pitch_y"].as_f64().unwrap() > 0.8,
                "{a}"
            );
        } else {
            assert!(
                a["line_correlation_at_pitch_y"].as_f64().unwrap().abs() < 0.2,
                "{a}"
            );
        }
    }
}

/// Too few lines for a section is not a failure: 4 lines at degree v 3 fit but leave none to
/// hold out, 3 lines at the paper's degree 5 cannot be fitted at all. Both say what is missing
/// and why, and exit 0; the same grid with a fold exits 3 (above).
#[test]
fn sections_the_line_count_rules_out_are_named_but_not_a_partial_characterisation() {
    let dir = tempfile::tempdir().unwrap();
    let z = sine_grid(COLS);
    for (lines, degree_v, missing) in [
        (4usize, "3", &["model_vs_measured", "between_lines"][..]),
        (
            3,
            "5",
            &["surface", "model_vs_measured", "between_lines"][..],
        ),
    ] {
        let grid = dir.path().join(format!("{lines}.csv"));
        write_grid(&grid, &z[..lines * COLS]);
        let out = dir.path().join(format!("out{lines}"));
        let o = analyze(&grid, &out, &["--degree-v", degree_v]);
        let (stdout, stderr) = text(&o);
        assert_eq!(o.status.code(), Some(0), "{lines} lines: {stderr}");
        let r = report(&out);
        let c = &r["characterisation"];
        assert_eq!(c["complete"], true, "{c}");
        assert!(c["failed_sections"].as_array().unwrap().is_empty(), "{c}");
        // One field of each section the line count rules out.
        let not_possible = |field: &str| -> Vec<&str> {
            c["sections_not_possible"]
                .as_array()
                .unwrap()
                .iter()
                .filter_map(|f| f[field].as_str())
                .collect()
        };
        assert_eq!(not_possible("section"), missing, "{c}");
        for m in missing {
            let said = format!("{m} not made ({lines} lines are too few)");
            assert!(stderr.contains(&said), "{said}: {stderr}");
        }
        // One condition, one reason: with 4 lines at degree v 3 the refit of the 3 lines kept
        // has no more than degree v + 1 = 4, and both hold-out sections say so in one wording.
        if lines == 4 {
            let reasons = not_possible("reason");
            let want = "4 lines cannot verify the surface between them: leaving one out leaves at most degree-v + 1 = 4 for the refit";
            assert!(
                reasons.len() == 2 && reasons.iter().all(|r| r.starts_with(want)),
                "{reasons:?}"
            );
        }
        assert!(
            stdout.contains("no verdict on the model between lines"),
            "{stdout}"
        );
        // The lines are characterised whatever the model could do.
        assert_eq!(r["lines"].as_array().unwrap().len(), lines);
        assert!(out.join("measured.x3p").exists());
        assert_eq!(out.join("model.x3p").exists(), lines == 4);
    }
}

#[test]
fn spikes_are_replaced_for_the_fit_only_when_asked_and_then_named() {
    let dir = tempfile::tempdir().unwrap();
    let mut z = uncorrelated_grid(9, COLS);
    z[7 * COLS + 40] -= 100.0;
    let grid = dir.path().join("spike.csv");
    write_grid(&grid, &z);
    let fit = |name: &str, extra: &[&str]| {
        let igs = dir.path().join(format!("{name}.igs"));
        let rep = dir.path().join(format!("{name}.json"));
        let o = surfscan()
            .arg("fit")
            .arg(&grid)
            .args([
                "--pitch-x",
                &PX.to_string(),
                "--pitch-y",
                &PY.to_string(),
                "-o",
            ])
            .arg(&igs)
            .arg("--report")
            .arg(&rep)
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let file = read_iges(&std::fs::read(&igs).unwrap()).unwrap();
        let report: Value = serde_json::from_slice(&std::fs::read(&rep).unwrap()).unwrap();
        (
            file,
            report,
            String::from_utf8_lossy(&o.stdout).into_owned(),
        )
    };
    // Default: the paper's surface through the data as measured, bit for bit.
    let (plain, plain_report, stdout) = fit("plain", &[]);
    let y: Vec<f64> = (0..ROWS).map(|r| r as f64 * PY).collect();
    let paper = fit_grid(PX, &y, &z, COLS, FitOptions::default()).unwrap();
    assert_eq!(plain.surfaces.len(), 1);
    let bits = |s: &surfscan::nurbs::NurbsSurface| -> Vec<u64> {
        s.poles().flatten().map(|v| v.to_bits()).collect()
    };
    assert_eq!(bits(&plain.surfaces[0]), bits(&paper.surface));
    assert!(!plain.start_lines.join(" ").contains("Spikes replaced"));
    assert!(plain_report["model"]["spikes_replaced"]
        .as_array()
        .unwrap()
        .is_empty());
    assert!(stdout.contains("between lines is"), "{stdout}");
    assert!(!stdout.contains("max residual"), "{stdout}");

    // Asked for: the spike is bridged before fitting and named in the Start section.
    let (replaced, report, _) = fit("replaced", &["--replace-spikes"]);
    let start = replaced.start_lines.join(" ");
    assert!(start.contains("Spikes replaced before fitting"), "{start}");
    // 1-based, the file index beside it.
    assert!(
        start.contains("line 8 (file 0007) points 41..41"),
        "{start}"
    );
    let named = report["model"]["spikes_replaced"].as_array().unwrap();
    assert_eq!(named.len(), 1);
    assert_eq!(
        (named[0]["line"].as_u64(), named[0]["peak"].as_u64()),
        (Some(7), Some(40))
    );
    let mut bridged = z.clone();
    bridged[7 * COLS + 40] = 0.5 * (z[7 * COLS + 39] + z[7 * COLS + 41]);
    let expected = fit_grid(PX, &y, &bridged, COLS, FitOptions::default()).unwrap();
    assert_eq!(bits(&replaced.surfaces[0]), bits(&expected.surface));

    // The least-squares method is named in the Start section and the report.
    let (ls, report, _) = fit(
        "ls",
        &["--v-method", "least-squares", "--v-control-rows", "8"],
    );
    assert_eq!(ls.surfaces[0].count_v(), 8);
    assert!(ls
        .start_lines
        .join(" ")
        .contains("least squares across the lines with 8 control rows"));
    assert_eq!(report["model"]["v_method"]["method"], "least-squares");
    assert_eq!(report["between_lines"]["method"], "least-squares");
}

#[test]
fn fit_compare_prints_the_alternatives_side_by_side() {
    let dir = tempfile::tempdir().unwrap();
    let grid = dir.path().join("sine.csv");
    write_grid(&grid, &sine_grid(COLS));
    let o = surfscan()
        .arg("fit")
        .arg(&grid)
        .args([
            "--pitch-x",
            &PX.to_string(),
            "--pitch-y",
            &PY.to_string(),
            "-o",
        ])
        .arg(dir.path().join("s.igs"))
        .arg("--compare")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table: Vec<&str> = stdout
        .lines()
        .skip_while(|l| !l.starts_with("method across the lines"))
        .collect();
    assert!(table.len() >= 5, "{stdout}");
    assert!(table[1].starts_with("interpolate (the paper)") && table[1].ends_with("supported"));
    assert!(
        table
            .iter()
            .filter(|l| l.starts_with("least-squares"))
            .count()
            >= 4,
        "{stdout}"
    );
}

/// A station scan with `[fit] v-method = "least-squares"` and `outliers = "replace"`: the IGES
/// Start section, report.json and the end-of-scan summary name the method, and the summary
/// gives the verdict instead of the residual at the data points.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_writes_the_configured_method_and_prints_the_verdict() {
    use crate::common::*;
    let rig = Rig::start(RigOptions::default()).await;
    let cfg = rig.config("out");
    edit_file(
        &cfg,
        "[output]",
        "v-method = \"least-squares\"\noutliers = \"replace\"\n\n[output]",
    );
    let o = run_scan(&cfg, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("  the model between lines is"), "{stdout}");
    assert!(!stdout.contains("largest residual"), "{stdout}");
    let dir = scan_dir(&rig.out_dir("out"));
    let iges = read_iges(&std::fs::read(dir.join("surface.igs")).unwrap()).unwrap();
    let start = iges.start_lines.join(" ");
    assert!(
        start.contains("least squares across the lines with 4 control rows"),
        "{start}"
    );
    assert!(
        start.contains("least-squares approximation across them"),
        "{start}"
    );
    assert!(start.is_ascii(), "{start}");
    assert!(start.contains("Spikes replaced before fitting"), "{start}");
    // A quarter of the 8 lines, at least degree-v + 1 = 4 control rows.
    assert_eq!(iges.surfaces[0].count_v(), 4);
    let r = report(&dir);
    assert_eq!(r["model"]["v_method"]["method"], "least-squares");
    assert_eq!(r["model"]["v_method"]["control_rows"], 4);
    assert_eq!(r["between_lines"]["method"], "least-squares");
    assert!(r["model"]["description"]
        .as_str()
        .unwrap()
        .contains("replaced by the straight line"));
    rig.shutdown().await;
}

/// Every file below `dir` (relative path, bytes), report.json without its timings.
fn outputs(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                todo.push(p);
                continue;
            }
            let name = p.strip_prefix(dir).unwrap().display().to_string();
            let mut bytes = std::fs::read(&p).unwrap();
            if name == "report.json" {
                let r: Value = serde_json::from_slice(&bytes).unwrap();
                bytes = crate::results_unchanged::pruned(r).to_string().into_bytes();
            }
            files.push((name, bytes));
        }
    }
    files.sort();
    files
}

/// With a second core the model section makes a small model's areal parameters while the
/// grid's sections run; with one (or for a large model) it makes them after, once the
/// overlay is drawn. The order changes no result: `analyze` pinned to one core (`taskset -c
/// 0`; the program's count of cores follows the affinity) and free on this machine's cores
/// gives the same files, byte for byte (report.json but for its timings), model.x3p and the
/// overlay, made from the model's samples in the one order and the other, among them. On the
/// two cores `.ci/run` is sized for, the two runs take the two orders.
#[test]
fn the_model_sections_order_changes_no_result() {
    let dir = tempfile::tempdir().unwrap();
    let grid = dir.path().join("sine.csv");
    write_grid(&grid, &sine_grid(COLS));
    let (free, pinned) = (dir.path().join("free"), dir.path().join("pinned"));
    let o = analyze(&grid, &free, &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o).1);
    let mut taskset = Command::new("taskset");
    taskset.args(["-c", "0", env!("CARGO_BIN_EXE_surfscan")]);
    let o = analyze_by(taskset, &grid, &pinned, &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o).1);
    let (a, b) = (outputs(&free), outputs(&pinned));
    let names = |f: &[(String, Vec<u8>)]| f.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    assert_eq!(names(&a), names(&b));
    assert!(
        names(&a).contains(&"model.x3p".to_string()),
        "{:?}",
        names(&a)
    );
    assert!(
        names(&a).contains(&"overlay.svg".to_string()),
        "{:?}",
        names(&a)
    );
    for ((name, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{name} differs between the two orders");
    }
}
