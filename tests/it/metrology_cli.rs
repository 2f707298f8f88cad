//! `surfscan analyze` end to end on synthetic inputs with known answers.

use serde_json::Value;
use std::f64::consts::PI;
use std::process::Command;

fn surfscan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
}

/// A profile CSV of `points` points at 0.5 µm: a sine of 1 µm amplitude and 0.1 mm period
/// (200 points a period).
fn sine_profile_csv(points: usize) -> String {
    let mut csv = String::from("x_mm,z_um\n");
    for i in 0..points {
        let x = i as f64 * 0.0005;
        csv.push_str(&format!(
            "{x:.7},{:.12}\n",
            (2.0 * PI * i as f64 / 200.0).sin()
        ));
    }
    csv
}

#[test]
fn analyze_profile_csv_writes_report_and_summary() {
    let dir = tempfile::tempdir().unwrap();
    // A = 1 µm, λ = 0.1 mm, 200 points per period, 4 mm: N = 5 at λc 0.8, whole periods.
    let csv = sine_profile_csv(8000);
    let input = dir.path().join("line.csv");
    std::fs::write(&input, csv).unwrap();
    let out = dir.path().join("out");
    let run = surfscan()
        .args([
            "analyze",
            input.to_str().unwrap(),
            "--no-filter",
            "--lc",
            "0.8",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(run.status.success());
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let line = &report["lines"][0];
    // What it found is said, with 4 significant digits (the values below): Ra 0.63659, Rq
    // 0.70711, Rz 2; then the Rk family in ISO's reading, as report.json has it.
    let um = |k: &str| {
        surfscan::numfmt::fmt(
            line[k].as_f64().unwrap(),
            surfscan::numfmt::Quantity::HeightUm,
        )
    };
    assert_eq!(
        String::from_utf8_lossy(&run.stdout),
        format!(
            "{}: profile of 8000 points (4.000 mm), no λc filter: Ra 0.6366 µm, Rq 0.7071 µm, Rz 2.000 µm; Rk {} µm, Rpk {} µm, Rvk {} µm\n",
            out.join("report.json").display(),
            um("Rk_um"),
            um("Rpk_um"),
            um("Rvk_um")
        )
    );
    assert_eq!(line["index"], 0);
    // Ra = (2/M)·cot(π/M) for M = 200 samples per period (→ 2A/π); Rq = A/√2; Rz = 2A.
    let ra = 2.0 / 200.0 / (PI / 200.0).tan();
    assert!((line["Ra_um"].as_f64().unwrap() - ra).abs() < 1e-9);
    assert!((line["Rq_um"].as_f64().unwrap() - 0.5f64.sqrt()).abs() < 1e-9);
    assert!((line["Rz_um"].as_f64().unwrap() - 2.0).abs() < 1e-9);
    assert!((line["RzJIS_um"].as_f64().unwrap() - 2.0).abs() < 1e-9);
    assert!((line["RSm_um"].as_f64().unwrap() - 100.0).abs() < 1e-4);
    assert_eq!(report["recipe"]["sampling_lengths"], 5);
    // Rmr at half of Rt below the top of a sine is at its mean line: 50 % of the length.
    let rmr = line["Rmr_table"].as_array().unwrap();
    assert_eq!(rmr.len(), 11);
    assert!((rmr[5][0].as_f64().unwrap() - 1.0).abs() < 1e-9);
    assert!((rmr[5][1].as_f64().unwrap() - 50.0).abs() < 0.01);
    assert_eq!(rmr[10][1].as_f64().unwrap(), 100.0);
    assert!(report["recipe"]["definitions"]["Rz"]
        .as_str()
        .unwrap()
        .contains("ISO4287:1997"));
    let summary = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    let rows: Vec<&str> = summary.lines().collect();
    assert_eq!(rows.len(), 2);
    assert!(rows[0].starts_with("line,index,y_mm,Ra_um,Rq_um,Rz_um,RzJIS_um"));
    assert!(
        rows[0].ends_with(",A2_um_pct,instrument_Ra_um,instrument_Rq_um,instrument_Rz_um,Rda,Rc_um,RPc_per_cm,Rppi_per_inch,Rdc_um,Rmr_pct"),
        "{}",
        rows[0]
    );
    // A grid's columns: the instrument's Ra, Rq, Rz are empty (a file carries none).
    assert!(rows[1].starts_with("1,0000,0.0000,"), "{}", rows[1]);
    assert!(rows[1].contains(",,,"), "{}", rows[1]);
    // The sine has one profile element per period of 0.1 mm: RPc = 100 peaks /cm.
    let cells: Vec<&str> = rows[1].split(',').collect();
    assert_eq!(cells.len(), rows[0].split(',').count());
    assert_eq!(cells[cells.len() - 4], "100", "RPc /cm: {}", rows[1]);
}

#[test]
fn analyze_grid_csv_reports_lines_areal_and_model_bac() {
    let dir = tempfile::tempdir().unwrap();
    // 13 lines of z = A·cos(2πx/λ), 4 whole periods of 100 points plus the closing point.
    let (rows, cols, amp) = (13usize, 401usize, 0.5);
    let input = write_grid_csv(dir.path(), rows, cols, |_, c| {
        format!("{:.12}", amp * (2.0 * PI * c as f64 / 100.0).cos())
    });
    let out = dir.path().join("out");
    let status = surfscan()
        .args([
            "analyze",
            input.to_str().unwrap(),
            "--lc",
            "0.25",
            "--pitch-x",
            "0.001",
        ])
        .args(["--pitch-y", "0.01", "--curves", "5", "--out"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["lines"].as_array().unwrap().len(), rows);
    assert!((report["lines"][12]["y_mm"].as_f64().unwrap() - 0.12).abs() < 1e-12);
    // The lines are λc-filtered (a grid CSV is taken as primary profiles), the surface's
    // areal numbers are not: the report says so.
    assert!(
        report["warnings"].as_array().unwrap().iter().any(|w| w
            .as_str()
            .unwrap()
            .contains("form and waviness longer than λc are in them")),
        "{}",
        report["warnings"]
    );
    // analyze fitted the surface itself: the fit is timed in report.json and in its total.
    crate::common::assert_fit_timed(&report);
    // Levelled grid: the plane takes the samples' mean A/cols; Sz = 2A.
    let sz = report["surface_grid"]["Sz_um"].as_f64().unwrap();
    assert!((sz - 2.0 * amp).abs() < 1e-9, "Sz {sz}");
    // The model sampled at half the pitch: the cosine's extremes are data points.
    let model_sz = report["surface"]["Sz_um"].as_f64().unwrap();
    assert!(
        (model_sz - 2.0 * amp).abs() < 0.01 * amp,
        "model Sz {model_sz}"
    );
    assert_eq!(report["surface"]["bac"].as_array().unwrap().len(), 101);
    let mvm = &report["model_vs_measured"];
    assert_eq!(mvm["points_left_out"].as_array().unwrap().len(), rows);
    assert_eq!(mvm["lines_left_out"].as_array().unwrap().len(), 6); // rows 1, 3, …, 11
                                                                    // Lines are identical, so leaving one out changes nothing: the model predicts it.
    assert!(mvm["lines_left_out"][0]["max_abs_um"].as_f64().unwrap() < 1e-6);
    let bac = report["surface_grid"]["bac"].as_array().unwrap();
    assert_eq!(bac.len(), 101);
    let curves = report["surface"]["bac_curves"].as_array().unwrap();
    assert_eq!(curves.len(), 5);
    // Model curve BAC at its mean line: half the length is above (arccos(0)/π = 50 %).
    let pts = curves[2]["curve"]["points"].as_array().unwrap();
    assert_eq!(pts.len(), 101);
    let mid = &pts[50];
    assert!(mid[0].as_f64().unwrap().abs() < 0.01 * amp);
    assert!((mid[1].as_f64().unwrap() - 50.0).abs() < 1.0, "{mid}");
    assert_eq!(
        std::fs::read_to_string(out.join("summary.csv"))
            .unwrap()
            .lines()
            .count(),
        rows + 1
    );
    // Plots as PNG (signature) and SVG (one polyline per model curve plus the pooled curve).
    for name in ["bac.png", "heightmap.png", "overlay.png"] {
        let bytes = std::fs::read(out.join(name)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name}");
    }
    for name in ["measured.x3p", "model.x3p"] {
        crate::metrology_x3p::assert_valid_x3p(&out.join(name));
    }
    let measured =
        surfscan::x3p::read_x3p(&std::fs::read(out.join("measured.x3p")).unwrap()).unwrap();
    assert_eq!((measured.rows, measured.cols), (rows, cols));
    let model = surfscan::x3p::read_x3p(&std::fs::read(out.join("model.x3p")).unwrap()).unwrap();
    assert_eq!((model.rows, model.cols), (rows, 2 * cols - 1));
    assert!((model.pitch_x_mm - 0.0005).abs() < 1e-12);
    // The model passes through the data: every 2nd model column is a measured point.
    for (k, m) in model
        .heights_um
        .iter()
        .enumerate()
        .filter(|(k, _)| (k % (2 * cols - 1)) % 2 == 0)
    {
        let (r, c) = (k / (2 * cols - 1), (k % (2 * cols - 1)) / 2);
        assert!((m - measured.heights_um[r * cols + c]).abs() < 1e-6);
    }
    let svg = std::fs::read_to_string(out.join("bac.svg")).unwrap();
    assert!(svg.starts_with("<svg"));
    assert!(
        svg.matches("<polyline").count() > 5,
        "curves missing from bac.svg"
    );
    let overlay = std::fs::read_to_string(out.join("overlay.svg")).unwrap();
    assert!(
        overlay.matches("<circle").count() >= cols,
        "measured points missing"
    );
    let map = std::fs::read_to_string(out.join("heightmap.svg")).unwrap();
    // The map is one bitmap at the figure's resolution, a PNG image inside the SVG.
    assert_eq!(map.matches("<image").count(), 1);
    assert!(map.contains(r#"href="data:image/png;base64,iVBORw0KGgo"#));
}

/// Each line's Rk construction is written as an SVG, which report.html embeds; its PNG only
/// with `--line-png`, and then at the SVG's size in pixels. Analysed again without the flag,
/// the old PNGs go.
#[test]
fn per_line_figures_are_svgs_and_their_pngs_are_written_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (6usize, 401usize);
    let input = write_grid_csv(dir.path(), rows, cols, |r, c| {
        format!("{:.9}", (2.0 * PI * (c + 7 * r) as f64 / 100.0).cos())
    });
    let out = dir.path().join("out");
    for line_png in [true, false] {
        let mut cmd = surfscan();
        cmd.arg("analyze").arg(&input);
        cmd.args(["--lc", "0.25", "--pitch-x", "0.001", "--pitch-y", "0.01"]);
        cmd.args(["--curves", "3", "--out"]).arg(&out);
        if line_png {
            cmd.arg("--line-png");
        }
        assert!(cmd.status().unwrap().success());
        for k in 0..rows {
            let svg = std::fs::read_to_string(out.join(format!("rk/{k:04}.svg"))).unwrap();
            assert!(svg.contains("ISO 13565-2"), "rk/{k:04}.svg");
            let png = out.join(format!("rk/{k:04}.png"));
            assert_eq!(png.exists(), line_png, "{}", png.display());
            if line_png {
                let (w, h) = image::open(&png).unwrap().to_rgb8().dimensions();
                assert!(
                    svg.contains(&format!("width=\"{w}\" height=\"{h}\"")),
                    "{}",
                    &svg[..200]
                );
            }
        }
        // The whole-grid figures keep both.
        for name in ["bac.png", "bac.svg", "heightmap.png", "overlay.png"] {
            assert!(out.join(name).exists(), "{name}");
        }
        let html = std::fs::read_to_string(out.join("report.html")).unwrap();
        let lines: Vec<&str> = html.split("<summary>Line ").skip(1).collect();
        assert_eq!(lines.len(), rows);
        for l in lines {
            let figure = &l[..l.find("</details>").unwrap()];
            let media = figure.split("src=\"data:").nth(1).unwrap();
            // Without PNGs the SVG is embedded; with them, the smaller of the two files.
            assert!(
                media.starts_with("image/svg+xml;base64,")
                    || (line_png && media.starts_with("image/png;base64,")),
                "{}",
                &figure[..120]
            );
        }
    }
}

#[test]
fn analyze_grid_without_pitches_is_a_usage_error() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("grid.csv");
    std::fs::write(&input, "1,2,3\n4,5,6\n").unwrap();
    let out = surfscan()
        .args(["analyze", input.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--pitch-x"));
}

/// Runs `analyze` on a grid CSV of `text` (401 points at 1 µm, 10 µm between rows) and
/// returns its exit code, stderr and report.json.
fn analyze_grid_text(dir: &std::path::Path, name: &str, text: &str) -> (i32, String, Value) {
    let input = dir.join(format!("{name}.csv"));
    std::fs::write(&input, text).unwrap();
    let out = dir.join(name);
    let o = surfscan()
        .args(["analyze", input.to_str().unwrap(), "--lc", "0.08"])
        .args(["--pitch-x", "0.001", "--pitch-y", "0.01", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let report = std::fs::read_to_string(out.join("report.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(Value::Null);
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        report,
    )
}

#[test]
fn analyze_leaves_out_damaged_rows_of_a_grid_csv_and_keeps_the_others() {
    let dir = tempfile::tempdir().unwrap();
    // 9 distinct rows: each line's own parameters depend on that line alone.
    let rows: Vec<String> = (0..9)
        .map(|r| {
            (0..401)
                .map(|c| {
                    let x = c as f64 * 0.001;
                    let a = 0.3 + 0.05 * r as f64;
                    format!("{:.9}", a * (2.0 * PI * x / 0.02 + r as f64).sin())
                })
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect();
    let clean = rows.join("\n") + "\n";
    let mut damaged = rows.clone();
    damaged[2] = damaged[2].replacen(',', ",12..5,", 1); // a value that is no number
    damaged[5] = damaged[5].rsplit_once(',').unwrap().0.to_string(); // one point short
    damaged[6] = damaged[6].replacen(',', ",NaN,", 1); // a point not measured, one too many
    let (code, stderr, whole) = analyze_grid_text(dir.path(), "clean", &clean);
    assert_eq!(code, 0, "{stderr}");
    // Line 7 now has 402 values; the others 401.
    let (code, stderr, report) =
        analyze_grid_text(dir.path(), "damaged", &(damaged.join("\n") + "\n"));
    // A result of fewer lines than the input holds is partial: exit 3, "6 of 9 lines".
    assert_eq!(code, 3, "{stderr}");
    for said in [
        "3 of the input's 9 lines cannot be used",
        "the characterisation is partial: it is made from 6 of 9 lines",
        "line 3 (column 2: \"12..5\" is not a number)",
        "line 6 (it has 400 values where the rows have 401)",
        "line 7 (1 of its 402 heights are not finite",
    ] {
        assert!(stderr.contains(said), "{said:?} not in {stderr}");
    }
    assert!(
        report["warnings"]
            .to_string()
            .contains("line 6 (it has 400 values"),
        "{}",
        report["warnings"]
    );
    let lines = report["lines"].as_array().unwrap();
    let index: Vec<u64> = lines.iter().map(|l| l["index"].as_u64().unwrap()).collect();
    assert_eq!(index, vec![0, 1, 3, 4, 7, 8]);
    for l in lines {
        let k = l["index"].as_u64().unwrap() as usize;
        let y = l["y_mm"].as_f64().unwrap();
        assert!((y - k as f64 * 0.01).abs() < 1e-12, "line {k} at y {y}");
        // The same line's parameters as in the whole grid's analysis.
        let same = &whole["lines"][k];
        for p in ["Ra_um", "Rq_um", "Rz_um", "Rsk"] {
            assert_eq!(l[p], same[p], "line {k} {p}");
        }
    }
    // The surface interpolates the six rows kept: one pole row per line.
    assert_eq!(report["fit"]["poles_v"], 6, "{}", report["fit"]);
    let c = &report["characterisation"];
    assert_eq!(
        (c["complete"].as_bool(), c["lines_in_input"].as_u64()),
        (Some(false), Some(9))
    );
    let left: Vec<u64> = c["lines_left_out"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["line"].as_u64().unwrap())
        .collect();
    assert_eq!(left, vec![3, 6, 7], "the file's lines");
}

#[test]
fn analyze_of_a_grid_csv_without_a_usable_row_names_the_first_problem() {
    let dir = tempfile::tempdir().unwrap();
    let (code, stderr, _) =
        analyze_grid_text(dir.path(), "bad", "z_um,z_um\n1.5,NaN\n0.5,-0.25x\n");
    assert_eq!(code, 1, "{stderr}");
    for said in [
        "no row can be used; the first, line 2 (1 of its 2 heights are not finite",
        "a grid CSV holds one row of heights per line",
    ] {
        assert!(stderr.contains(said), "{said:?} not in {stderr}");
    }
}

#[test]
fn analyze_of_a_profile_at_a_pitch_far_below_the_cut_off_is_an_error_not_a_crash() {
    // x written in a unit far below mm (here 1e-300 mm a point): a profile far shorter than
    // λc, refused as such; the λc kernel at that pitch would be 8e299 taps.
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("x_mm,z_um\n");
    for i in 0..400 {
        csv.push_str(&format!(
            "{:e},{}\n",
            i as f64 * 1e-300,
            (i as f64 / 9.0).sin()
        ));
    }
    let input = dir.path().join("line.csv");
    std::fs::write(&input, csv).unwrap();
    let o = surfscan()
        .args(["analyze", input.to_str().unwrap(), "--out"])
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    // x in units far too small for mm is named as such before any parameter is computed.
    assert!(
        stderr.contains("the profile's x spans 3.990e-298 mm, less than 0.01 mm"),
        "{stderr}"
    );
}

#[test]
fn a_profile_csv_with_a_byte_order_mark_is_read_as_a_profile() {
    // Saved as "UTF-8 CSV" by a spreadsheet program: the mark before the header is no part
    // of it, and the file is no grid needing pitches.
    let dir = tempfile::tempdir().unwrap();
    let csv = format!("\u{feff}{}", sine_profile_csv(4000));
    let input = dir.path().join("line.csv");
    std::fs::write(&input, csv).unwrap();
    let out = dir.path().join("out");
    let o = surfscan()
        .args(["analyze", input.to_str().unwrap(), "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", crate::common::describe(&o));
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["kind"], "profile");
}

#[test]
fn analysis_flags_outside_the_configurations_ranges_are_usage_errors() {
    // λc 0 or NaN, one level, a hundred million levels (minutes of work), no curve: refused
    // before anything is read or written, naming the flag and the station key it mirrors.
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("line.csv");
    std::fs::write(&input, sine_profile_csv(4000)).unwrap();
    let out = dir.path().join("out");
    let analyze = |args: &[&str]| {
        surfscan()
            .args(["analyze", input.to_str().unwrap()])
            .args(args)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap()
    };
    for (flag, value, key) in [
        ("--lc", "0", "analysis.lambda-c-mm"),
        ("--lc", "NaN", "analysis.lambda-c-mm"),
        ("--lc", "1e300", "analysis.lambda-c-mm"),
        ("--levels", "1", "analysis.levels"),
        ("--levels", "100000000", "analysis.levels"),
        ("--curves", "0", "analysis.curves"),
    ] {
        let run = analyze(&[flag, value]);
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(err.contains(flag) && err.contains(key), "{err}");
        assert!(!out.exists(), "{flag} {value} wrote {}", out.display());
    }
    // The ends of the ranges are not refused as usage (a λc of 100 mm is then too long for
    // this 2 mm profile, which is another matter, exit 1).
    for (flag, value) in [
        ("--lc", "0.001"),
        ("--lc", "100"),
        ("--levels", "2"),
        ("--levels", "100000"),
        ("--curves", "1"),
        ("--curves", "10000"),
    ] {
        let run = analyze(&[flag, value]);
        let err = String::from_utf8_lossy(&run.stderr);
        assert_ne!(run.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(
            !err.contains("outside its valid range"),
            "{flag} {value}: {err}"
        );
    }
    // A plain value characterises the profile.
    let run = analyze(&["--lc", "0.8"]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        crate::common::describe(&run)
    );
}

/// A profile CSV's header states its units; one that says otherwise (heights in nm, a third
/// column) is refused instead of read a thousand times off or from the wrong column.
#[test]
fn a_profile_csv_whose_header_is_not_x_mm_z_um_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let body: String = sine_profile_csv(4000)
        .lines()
        .skip(1)
        .map(|l| format!("{l}\n"))
        .collect();
    for (name, text, says) in [
        (
            "xyz.csv",
            format!(
                "x_mm,y_mm,z_um\n{}",
                body.lines()
                    .map(|l| l.replacen(',', ",0.01,", 1) + "\n")
                    .collect::<String>()
            ),
            "\"x_mm,y_mm,z_um\"",
        ),
        (
            "extra.csv",
            format!(
                "x_mm,z_um\n{}",
                body.lines().map(|l| format!("{l},7\n")).collect::<String>()
            ),
            "is not two numbers",
        ),
    ] {
        let input = dir.path().join(name);
        std::fs::write(&input, text).unwrap();
        let out = dir.path().join(format!("out-{name}"));
        let run = surfscan()
            .args(["analyze", input.to_str().unwrap(), "--out"])
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains(says), "{name}: {err}");
        assert!(!out.join("report.json").exists(), "{name}");
    }
}

/// A profile CSV is searched for spikes as a grid's lines are: one point 50 µm off a 1 µm
/// sine is named, and with --outliers exclude it is bridged, so Rz is the sine's own 2 µm
/// again (the bridge of one point on a 200-point period is within 1e-3 µm of the sine).
#[test]
fn a_profile_csvs_spike_is_named_and_excluded_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let mut rows: Vec<String> = sine_profile_csv(8000).lines().map(str::to_owned).collect();
    // Point 4050 (x = 2.025 mm), at a peak of the sine: 1 + 49 µm.
    rows[1 + 4050] = format!("{:.7},50", 4050.0 * 0.0005);
    let input = dir.path().join("spike.csv");
    std::fs::write(&input, rows.join("\n") + "\n").unwrap();
    let rz = |outliers: &str| {
        let out = dir.path().join(format!("out-{outliers}"));
        let run = surfscan()
            .args([
                "analyze",
                input.to_str().unwrap(),
                "--no-filter",
                "--outliers",
            ])
            .arg(outliers)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr).into_owned();
        assert_eq!(run.status.code(), Some(0), "{err}");
        assert!(
            err.contains("spike in line 1") && err.contains("x = 2.0250 mm"),
            "{err}"
        );
        let report: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap();
        assert_eq!(report["outliers"]["policy"], outliers);
        assert_eq!(report["outliers"]["spikes"].as_array().unwrap().len(), 1);
        report["lines"][0]["Rz_um"].as_f64().unwrap()
    };
    assert!(
        rz("flag") > 10.0,
        "the spike stays in the data when only flagged"
    );
    let excluded = rz("exclude");
    assert!((excluded - 2.0).abs() < 1e-3, "Rz {excluded}");
}

/// Numbers that cannot be what the operator meant are said: with --no-filter an offset
/// profile (a sine 100 µm up) is not centred on a mean line, and a profile whose x was
/// written in µm is a kilometre long.
#[test]
fn an_uncentred_unfiltered_profile_and_an_x_in_micrometres_are_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let body: Vec<(f64, f64)> = sine_profile_csv(4000)
        .lines()
        .skip(1)
        .map(|l| {
            let (x, z) = l.split_once(',').unwrap();
            (x.parse().unwrap(), z.parse().unwrap())
        })
        .collect();
    let write = |name: &str, f: &dyn Fn(f64, f64) -> (f64, f64)| {
        let text: String = std::iter::once("x_mm,z_um\n".to_owned())
            .chain(body.iter().map(|&(x, z)| {
                let (x, z) = f(x, z);
                format!("{x:.7},{z:.12}\n")
            }))
            .collect();
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let run = |input: &std::path::Path, extra: &[&str]| {
        let out = dir.path().join("out");
        let r = surfscan()
            .args(["analyze", input.to_str().unwrap()])
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert_eq!(r.status.code(), Some(0), "{}", crate::common::describe(&r));
        String::from_utf8_lossy(&r.stderr).into_owned()
    };
    let offset = write("offset.csv", &|x, z| (x, z + 100.0));
    let err = run(&offset, &["--no-filter"]);
    assert!(err.contains("an offset or form remains"), "{err}");
    let plain = write("plain.csv", &|x, z| (x, z));
    assert!(!run(&plain, &["--no-filter"]).contains("offset or form"));
    let micrometres = write("um.csv", &|x, z| (x * 1000.0, z));
    let err = run(&micrometres, &["--lc", "100"]);
    assert!(
        err.contains("longer than any stylus traverse: check that x"),
        "{err}"
    );
    assert!(!run(&plain, &[]).contains("check that x"));
}

/// `--sampling-lengths N` evaluates the central N·λc of a longer traverse, as an instrument
/// traces N·λc plus λc for the filter: 9600 points of a 1 µm sine (4.8 mm) at λc 0.8 mm with
/// N = 5 leave 800 points out at each end, and the five 0.8 mm sections of 8 whole periods
/// give the sine's own Ra = (2/M)·cot(π/M), M = 200, and Rz = 2 µm.
#[test]
fn sampling_lengths_evaluates_the_central_sections_of_a_traverse() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("traverse.csv");
    std::fs::write(&input, sine_profile_csv(9600)).unwrap();
    let run = |extra: &[&str]| {
        let out = dir.path().join("out");
        let _ = std::fs::remove_dir_all(&out);
        let r = surfscan()
            .args([
                "analyze",
                input.to_str().unwrap(),
                "--no-filter",
                "--lc",
                "0.8",
            ])
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let report = std::fs::read_to_string(out.join("report.json"))
            .ok()
            .map(|t| serde_json::from_str::<Value>(&t).unwrap());
        (r, report)
    };
    let (r, report) = run(&["--sampling-lengths", "5"]);
    assert_eq!(r.status.code(), Some(0), "{}", crate::common::describe(&r));
    let report = report.unwrap();
    assert_eq!(report["recipe"]["sampling_lengths"], 5);
    assert_eq!(report["recipe"]["points_not_evaluated"], 1600);
    let line = &report["lines"][0];
    let ra = 2.0 / 200.0 / (PI / 200.0).tan();
    assert!(
        (line["Ra_um"].as_f64().unwrap() - ra).abs() < 1e-9,
        "{line}"
    );
    assert!(
        (line["Rz_um"].as_f64().unwrap() - 2.0).abs() < 1e-9,
        "{line}"
    );
    // More sections than the traverse holds: the profile is too short for them.
    let (r, _) = run(&["--sampling-lengths", "7"]);
    assert_eq!(r.status.code(), Some(1), "{}", crate::common::describe(&r));
    assert!(String::from_utf8_lossy(&r.stderr).contains("shorter than"));
    // None is not a number of sections.
    let (r, _) = run(&["--sampling-lengths", "0"]);
    assert_eq!(r.status.code(), Some(2));
}

/// `--no-filter` on a grid whose lines carry an offset (heights as traced, about 10 µm above
/// zero, as the sur-2 grid): every line's Ra would be that offset, so the warning names how
/// many lines are not centred and the worst; lines about zero are not warned of.
#[test]
fn no_filter_on_a_grid_of_uncentred_lines_is_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    // 6 lines of a 0.1 mm cosine, 0.5 µm amplitude; line 4 (index 3) is 10 µm up.
    let grid = |offset: f64| -> String {
        (0..6)
            .map(|r| {
                let up = if r == 3 { offset } else { 0.0 };
                (0..801)
                    .map(|c| format!("{:.9}", up + 0.5 * (2.0 * PI * c as f64 / 100.0).cos()))
                    .collect::<Vec<_>>()
                    .join(",")
                    + "\n"
            })
            .collect()
    };
    let run = |name: &str, text: &str, extra: &[&str]| {
        let input = dir.path().join(format!("{name}.csv"));
        std::fs::write(&input, text).unwrap();
        let out = dir.path().join(name);
        let o = surfscan()
            .args(["analyze", input.to_str().unwrap(), "--curves", "3"])
            .args(["--pitch-x", "0.001", "--pitch-y", "0.01", "--out"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", crate::common::describe(&o));
        let report: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap();
        (String::from_utf8_lossy(&o.stderr).into_owned(), report)
    };
    let (err, report) = run("offset", &grid(10.0), &["--no-filter"]);
    // Rq about z = 0 is √(10² + 0.5²/2) µm: the offset, not the roughness.
    let want = "1 of 6 lines are not centred (line 4: mean 10.00 µm against Rq 10.01 µm (Rp 10.50 µm, Rv -9.500 µm))";
    assert!(err.contains(want), "{err}");
    assert!(
        report["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains(want)),
        "{}",
        report["warnings"]
    );
    // Centred lines, or the λc filter applied: no such warning.
    let (err, _) = run("centred", &grid(0.0), &["--no-filter"]);
    assert!(!err.contains("not centred"), "{err}");
    let (err, _) = run("filtered", &grid(10.0), &["--lc", "0.08"]);
    assert!(!err.contains("not centred"), "{err}");
}

/// `grid.csv` in `dir`: `rows` lines of `cols` heights, `z(row, column)` each as written.
fn write_grid_csv(
    dir: &std::path::Path,
    rows: usize,
    cols: usize,
    z: impl Fn(usize, usize) -> String,
) -> std::path::PathBuf {
    let csv: String = (0..rows)
        .map(|r| (0..cols).map(|c| z(r, c)).collect::<Vec<_>>().join(",") + "\n")
        .collect();
    let input = dir.join("grid.csv");
    std::fs::write(&input, csv).unwrap();
    input
}
