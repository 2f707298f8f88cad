//! The README's main job, `surfscan demo`, run as the binary: a complete simulated 31-line
//! scan must leave the IGES, the report with the characterisation, the plots and X3P in the
//! output directory, all consistent with the stored lines.
//!
//! Depends on the `surfscan` binary and the library's readers (IGES, X3P, scan store).

use std::path::PathBuf;
use std::process::Command;
use std::sync::Arc;
use surfscan::iges::reader::read_iges;
use surfscan::scan::faults::NoFaults;
use surfscan::scan::store::ScanStore;
use surfscan::x3p::read_x3p;

#[test]
fn demo_leaves_surface_report_plots_and_x3p_of_a_complete_scan() {
    let out = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(["demo", "--speed-up", "50", "--out"])
        .arg(out.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "demo failed: {stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let dirs: Vec<PathBuf> = std::fs::read_dir(out.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("journal.jsonl").exists())
        .collect();
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    let dir = &dirs[0];
    assert!(
        stdout.contains(&dir.join("surface.igs").display().to_string()),
        "{stdout}"
    );
    // The end of the scan says what came out, not only the residual at the data points.
    assert!(
        stdout.contains("  lines    31 of 31 planned characterised\n"),
        "{stdout}"
    );
    assert!(
        stdout.contains("  Ra       ") && stdout.contains(" µm (mean "),
        "{stdout}"
    );
    assert!(
        stdout.contains("  Sa       ") && stdout.contains("(model)"),
        "{stdout}"
    );
    // The demo's recipe holds the surface to one limit it meets and one it does not: the
    // verdict, each limit's with its reason, and exit 0 all the same. Ra is about 3 µm on
    // every line, far below 6.3 µm even with the calibration's 3 %; Rz about 16 µm, above
    // 12.5 µm by more than its 3 %.
    assert!(stdout.contains("  verdict  does not conform\n"), "{stdout}");
    assert!(
        stdout
            .contains("  limit    Ra1 6.3: conforms (Ra1 16 % rule: none of 31 lines above 6.3 µm"),
        "{stdout}"
    );
    assert!(
        stdout.contains("  limit    Rz1 max 12.5: does not conform (Rz1 max rule: "),
        "{stdout}"
    );

    let store = ScanStore::open(dir, Arc::new(NoFaults)).unwrap();
    let lines = store.load_all().unwrap();
    assert_eq!(lines.lines.len(), 31);
    assert!(lines.incomplete.is_empty());
    let cols = lines.lines[0].profile.len();

    // The IGES surface has one pole per data point (interpolation), degrees 5 x 5.
    let iges = read_iges(&std::fs::read(dir.join("surface.igs")).unwrap()).unwrap();
    let s = &iges.surfaces[0];
    assert_eq!((s.degree_u(), s.degree_v()), (5, 5));
    assert_eq!((s.count_u(), s.count_v()), (cols, 31));

    // The report: one entry per line with the ISO parameters and the instrument's own values
    // beside ours; the pooled bearing area curve runs from 0 % to 100 %.
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    let rl = report["lines"].as_array().unwrap();
    assert_eq!(rl.len(), 31);
    for l in rl {
        let ra = l["Ra_um"].as_f64().unwrap();
        let rq = l["Rq_um"].as_f64().unwrap();
        assert!(ra > 0.0 && rq >= ra, "Rq ≥ Ra for any profile: {l}");
        let inst = l["instrument"].as_array().unwrap();
        let ra_inst = inst.iter().find(|c| c["name"] == "Ra").unwrap();
        let diff = ra_inst["difference"].as_f64().unwrap();
        let expect = ra - ra_inst["instrument"].as_f64().unwrap();
        assert!((diff - expect).abs() < 1e-12, "{ra_inst}");
    }
    let bac = report["surface"]["bac"].as_array().unwrap();
    let first = bac.first().unwrap()[1].as_f64().unwrap();
    let last = bac.last().unwrap()[1].as_f64().unwrap();
    assert!(
        first.abs() < 1e-9 && (last - 100.0).abs() < 1e-9,
        "{first} {last}"
    );
    assert_eq!(report["scan"]["status"], "complete");
    let spec = &report["specification"];
    assert_eq!(spec["verdict"], "does not conform", "{spec}");
    let limits = spec["limits"].as_array().unwrap();
    assert_eq!(limits[0]["verdict"], "conforms");
    assert_eq!(limits[0]["n_values"], 31);
    assert_eq!(limits[0]["n_beyond"], 0);
    // Every line's Rz is beyond 12.5 µm by more than its U (3 % of the value): counted from
    // the lines themselves.
    let rz_beyond = rl
        .iter()
        .filter(|l| l["Rz_um"].as_f64().unwrap() * (1.0 - 0.03) > 12.5)
        .count();
    assert!(rz_beyond > 0);
    assert_eq!(limits[1]["verdict"], "does not conform");
    assert_eq!(limits[1]["n_beyond"], rz_beyond, "{}", limits[1]);
    assert!(spec["instrument_uncertainty"]
        .as_str()
        .unwrap()
        .contains("3 %"));
    // The Ra mean's uncertainty from the lines themselves: s/√31 combined with the
    // calibration's 1.5 % (3 % at k = 2) of the mean, U = 2·u_c.
    let ra: Vec<f64> = rl.iter().map(|l| l["Ra_um"].as_f64().unwrap()).collect();
    let n = ra.len() as f64;
    let mean = ra.iter().sum::<f64>() / n;
    let s = (ra.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let u_c = (s / n.sqrt()).hypot(0.015 * mean);
    let u = &report["uncertainty"]["parameters"][0];
    assert_eq!(u["parameter"], "Ra_um");
    assert!(
        (u["U"].as_f64().unwrap() - 2.0 * u_c).abs() < 1e-9 * u_c,
        "{u}"
    );
    assert!(std::fs::read_to_string(dir.join("report.html"))
        .unwrap()
        .contains("<h2 id=\"verdict\">Verdict</h2>"));
    assert_eq!(report["traceability"]["instrument_model"], "sj210");
    assert!(report["fit"]["max_residual_mm"].as_f64().unwrap() <= 1e-10);

    // Spreadsheet summary: a header and one row per line.
    let summary = std::fs::read_to_string(dir.join("summary.csv")).unwrap();
    assert_eq!(summary.lines().count(), 32);
    // Its last columns: where each line stands against each limit, and the scan's verdict;
    // the Rz column says `beyond` on exactly the lines report.json names.
    let header: Vec<&str> = summary.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (ra_col, rz_col, v_col) = (
        col("limit: Ra1 6.3"),
        col("limit: Rz1 max 12.5"),
        col("scan_verdict"),
    );
    assert_eq!(v_col, header.len() - 1);
    let beyond: Vec<u64> = limits[1]["lines_beyond"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    for row in summary.lines().skip(1) {
        let cells: Vec<&str> = row.split(',').collect();
        let line: u64 = cells[0].parse().unwrap();
        assert_eq!(cells[ra_col], "within", "{row}");
        assert_eq!(cells[rz_col] == "beyond", beyond.contains(&line), "{row}");
        assert_eq!(cells[v_col], "does not conform", "{row}");
    }
    for plot in ["bac", "heightmap", "overlay"] {
        for ext in ["png", "svg"] {
            let p = dir.join(format!("{plot}.{ext}"));
            assert!(
                std::fs::metadata(&p).unwrap().len() > 1000,
                "{}",
                p.display()
            );
        }
    }
    // The footer names the software once and the demo's arbitrary evaluation length in
    // words (the instrument's N = 0), and every line has its Rk construction.
    let footer = std::fs::read_to_string(dir.join("bac.svg")).unwrap();
    assert!(
        !footer.contains("surfscan surfscan"),
        "doubled name in the footer"
    );
    assert!(footer.contains("arbitrary evaluation length"));
    assert!(!footer.contains(" N 0"));
    // Each line's as an SVG only: the PNGs are written when `[report] line-png` asks.
    for k in 0..31 {
        assert!(dir.join(format!("rk/{k:04}.svg")).exists(), "rk/{k:04}.svg");
        assert!(
            !dir.join(format!("rk/{k:04}.png")).exists(),
            "rk/{k:04}.png"
        );
    }
    assert!(std::fs::read_to_string(dir.join("report.html"))
        .unwrap()
        .contains("31 of 31 planned characterised"));
    // On paper: the demo's report printed by Chromium on the A4 of its [report] table; then
    // `analyze --config` with another laboratory, a logo, Letter and three signatures.
    let paper = tempfile::tempdir().unwrap();
    let size = crate::report_print::check_printed(
        dir,
        &paper.path().join("report.pdf"),
        "surfscan demonstration",
        &["Measured by", "Approved by"],
    );
    assert!(size.ends_with("(A4)"), "{size}");
    // The same without a browser: `surfscan report --pdf`, into the scan directory.
    let size = crate::report_pdf::check_report_pdf(
        dir,
        None,
        "surfscan demonstration",
        &["Measured by", "Approved by"],
    );
    assert!(size.ends_with("(A4)"), "{size}");
    let logo = paper.path().join("logo.svg");
    std::fs::write(
        &logo,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"40\" height=\"20\"><rect width=\"40\" height=\"20\" fill=\"#0072b2\"/></svg>",
    )
    .unwrap();
    let letter = paper.path().join("letter.toml");
    std::fs::write(
        &letter,
        crate::report_print::with_report_table(
            &std::fs::read_to_string(out.path().join("demo.toml")).unwrap(),
            &format!(
                "[report]\nlab = \"Calibration lab <B&S>\"\naddress = \"2 Gauge Street\\nSpringfield\"\nlogo = {:?}\npaper = \"Letter\"\nsignatures = [\"Measured by\", \"Checked by\", \"Approved by\"]\n",
                logo.display().to_string()
            ),
        ),
    )
    .unwrap();
    let again = paper.path().join("letter");
    let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(dir)
        .arg("--config")
        .arg(&letter)
        .arg("--out")
        .arg(&again)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(again.join("report.html")).unwrap();
    assert!(html.contains("class=\"logo\"") && html.contains("data:image/svg+xml;base64,"));
    assert!(html.contains("Calibration lab &lt;B&amp;S&gt;"));
    let size = crate::report_print::check_printed(
        &again,
        &paper.path().join("letter.pdf"),
        "Calibration lab <B&S>",
        &["Measured by", "Checked by", "Approved by"],
    );
    assert!(size.ends_with("(letter)"), "{size}");
    let size = crate::report_pdf::check_report_pdf(
        &again,
        Some(&paper.path().join("letter-surfscan.pdf")),
        "Calibration lab <B&S>",
        &["Measured by", "Checked by", "Approved by"],
    );
    assert!(size.ends_with("(letter)"), "{size}");
    // The demo's grid gives the results pinned before the characterisation was reorganised:
    // the scan's own report and surface, `fit` and `analyze` of its directory, and `analyze`
    // of its measured.x3p.
    let scan = [(dir.as_path(), "{SCAN}")];
    crate::results_unchanged::check(
        "demo",
        serde_json::json!({
            "report": crate::results_unchanged::json_file(&dir.join("report.json")),
            "iges": crate::results_unchanged::iges_fingerprint(&dir.join("surface.igs"), &scan),
        }),
        &[],
    );
    let x3p = dir.join("measured.x3p").display().to_string();
    for (name, args) in [
        (
            "fit-demo",
            vec![
                "fit",
                dir.to_str().unwrap(),
                "-o",
                "{T}/s.igs",
                "--report",
                "{T}/fit.json",
            ],
        ),
        (
            "analyze-demo",
            vec!["analyze", dir.to_str().unwrap(), "--out", "{T}/out"],
        ),
        (
            "analyze-demo-x3p",
            vec!["analyze", &x3p, "--out", "{T}/out"],
        ),
    ] {
        let t = tempfile::tempdir().unwrap();
        let args: Vec<String> = args
            .iter()
            .map(|a| a.replace("{T}", &t.path().display().to_string()))
            .collect();
        let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(&args)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        crate::results_unchanged::check(
            name,
            crate::results_unchanged::outputs_of(t.path(), &scan),
            &[],
        );
    }

    // Both X3P files the scan wrote are valid ISO 5436-2 (no calibration date: no Record2).
    for name in ["measured.x3p", "model.x3p"] {
        crate::metrology_x3p::assert_valid_x3p(&dir.join(name));
    }
    // The measured X3P holds exactly the stored heights.
    let x = read_x3p(&std::fs::read(dir.join("measured.x3p")).unwrap()).unwrap();
    assert_eq!((x.rows, x.cols), (31, cols));
    for (r, l) in lines.lines.iter().enumerate() {
        for (c, z) in l.profile.heights_um.iter().enumerate() {
            let got = x.heights_um[r * cols + c];
            assert!(
                (got - z).abs() <= 1e-9 * z.abs().max(1.0),
                "({r},{c}) {got} vs {z}"
            );
        }
    }
    // The areal cross-checks read the demo's grid from tests/data/demo.grid.csv: it must be
    // this grid.
    let fixture = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/demo.grid.csv"),
    )
    .unwrap();
    let rows: Vec<&str> = fixture.lines().filter(|l| !l.is_empty()).collect();
    assert_eq!(rows.len(), lines.lines.len());
    for (row, l) in rows.iter().zip(&lines.lines) {
        let z: Vec<f64> = row.split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!(z.len(), l.profile.heights_um.len());
        for (a, b) in z.iter().zip(&l.profile.heights_um) {
            assert!((a - b).abs() <= 1e-6, "demo.grid.csv {a} vs the demo's {b}");
        }
    }

    // The same scan as if it had lost its last 11 lines (their metadata gone): judged over
    // the 31 lines planned, the 11 counted as undecided. Ra, within its limit on all 20
    // lines, is no longer proven (11 of 31 might be beyond, more than 16 %); Rz, beyond its
    // max on lines it has, still does not conform. `analyze --recipe` with the demo's recipe
    // says so and exits 4; without it the frozen recipe judges and the exit is 3 (partial).
    for k in 20..31 {
        std::fs::remove_file(dir.join(format!("lines/{k:04}.json"))).unwrap();
    }
    let rz_beyond_20 = rl[..20]
        .iter()
        .filter(|l| l["Rz_um"].as_f64().unwrap() * (1.0 - 0.03) > 12.5)
        .count();
    let recipe = out.path().join("recipes/demo.toml");
    for (extra, exit) in [(vec![], 3), (vec!["--recipe", recipe.to_str().unwrap()], 4)] {
        let t = tempfile::tempdir().unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .args(["analyze", dir.to_str().unwrap(), "--out"])
            .arg(t.path())
            .args(&extra)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert_eq!(o.status.code(), Some(exit), "{extra:?} {stdout}");
        assert!(stdout.contains("verdict: does not conform\n"), "{stdout}");
        assert!(
            stdout.contains("  Ra1 6.3: not decidable (Ra1 16 % rule: none of 20 lines above 6.3 µm, 11 of the 31 planned lines not measured (counted as undecided) (at most 4 of 31 allowed))"),
            "{stdout}"
        );
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(t.path().join("report.json")).unwrap())
                .unwrap();
        let limits = &r["specification"]["limits"];
        assert_eq!(limits[0]["n_not_measured"], 11);
        assert_eq!(limits[1]["verdict"], "does not conform");
        assert_eq!(limits[1]["n_beyond"], rz_beyond_20);
    }
}
