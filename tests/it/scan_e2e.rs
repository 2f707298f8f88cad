//! End-to-end scans: the real `surfscan scan` binary as a child process against the
//! simulator started in this process (SJ-210 and GRBL stage on pseudo-terminals), through
//! crashes at every durability step, a torn journal, an unplugged instrument, a reset stage,
//! a full disk, SIGTERM, NG codes and bad configurations. The simulator's profile set is the
//! independent reference for every stored height.

use crate::common::*;
use std::time::Duration;
use surfscan::scan::faults::NoFaults;
use surfscan::scan::journal::{Journal, Record, ResumeState, StopStatus};
use surfscan::scan::store::ScanStore;
use surfscan_sim::grbl::StageFault;

/// The paper's parameters, computed here from the stored points independently of the
/// fitter: chord-length parameters of every row (resp. column), averaged.
fn chord_params(points: &[Vec<[f64; 3]>]) -> (Vec<f64>, Vec<f64>) {
    let rows = points.len();
    let cols = points[0].len();
    let dist = |a: [f64; 3], b: [f64; 3]| {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    let chord = |seq: Vec<[f64; 3]>| -> Vec<f64> {
        let mut acc = vec![0.0];
        for w in seq.windows(2) {
            let last = *acc.last().unwrap_or(&0.0);
            acc.push(last + dist(w[0], w[1]));
        }
        let total = *acc.last().unwrap_or(&1.0);
        acc.iter().map(|a| a / total).collect()
    };
    let mut u = vec![0.0; cols];
    for row in points {
        for (k, p) in chord(row.clone()).into_iter().enumerate() {
            u[k] += p / rows as f64;
        }
    }
    let mut v = vec![0.0; rows];
    for c in 0..cols {
        let col: Vec<[f64; 3]> = points.iter().map(|r| r[c]).collect();
        for (l, p) in chord(col).into_iter().enumerate() {
            v[l] += p / cols as f64;
        }
    }
    (u, v)
}

/// A complete scan: lines, journal, surface and report.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_complete_scan_stores_the_served_lines_and_a_surface_through_them() {
    let rig = Rig::start(RigOptions::default()).await;
    let n = rig.options.lines;
    let cfg = rig.config("out");
    let o = run_scan(&cfg, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    // The log went to a pipe, not a terminal: plain text, no colour escapes.
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("scan started in"), "{log}");
    assert!(
        !log.contains('\x1b'),
        "ANSI escapes in a log written to a pipe: {log:?}"
    );
    let dir = scan_dir(&rig.out_dir("out"));
    assert_lines_exactly(&dir, n);
    let records = assert_journal_complete(&dir, n);
    match records.first() {
        Some(Record::Start(s)) => {
            assert_eq!(s.specimen, "coupon A-17");
            assert_eq!(s.operator, "R. Tester");
        }
        other => panic!("{other:?}"),
    }
    // The carriage ends truly at the last target (backlash included).
    assert_eq!(rig.stage.true_position_nm(), target_nm(n - 1));

    // The surface: degrees and pole counts of the grid, through every stored point.
    let iges = dir.join("surface.igs");
    let file = surfscan::iges::reader::read_iges(&std::fs::read(&iges).unwrap()).unwrap();
    assert_eq!(file.surfaces.len(), 1);
    let s = &file.surfaces[0];
    assert_eq!((s.degree_u(), s.degree_v()), (5, 3));
    assert_eq!((s.count_u(), s.count_v()), (POINTS, n));
    let points: Vec<Vec<[f64; 3]>> = (0..n)
        .map(|k| {
            let y = target_nm(k) as f64 / 1e6;
            served_heights_um(k)
                .iter()
                .enumerate()
                .map(|(i, z)| [i as f64 * PITCH_X_MM, y, z / 1000.0])
                .collect()
        })
        .collect();
    let (u, v) = chord_params(&points);
    let mut worst = 0.0f64;
    for (l, row) in points.iter().enumerate() {
        for (k, p) in row.iter().enumerate() {
            let e = s.evaluate(u[k], v[l]);
            for d in 0..3 {
                worst = worst.max((e[d] - p[d]).abs());
            }
        }
    }
    assert!(
        worst <= 1e-10,
        "surface misses a stored point by {worst} mm"
    );

    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["traceability"]["specimen"], "coupon A-17");
    assert_eq!(report["traceability"]["operator"], "R. Tester");
    assert_eq!(report["traceability"]["instrument_model"], "sj210");
    assert_eq!(report["fit"]["poles_u"], POINTS as u64);
    assert_eq!(report["fit"]["poles_v"], n as u64);
    assert_eq!(report["lines"].as_array().map(Vec::len), Some(n));
    rig.shutdown().await;
}

/// Every number in a JSON value, in document order.
fn numbers(v: &serde_json::Value) -> Vec<f64> {
    match v {
        serde_json::Value::Number(n) => vec![n.as_f64().unwrap_or(f64::NAN)],
        serde_json::Value::Array(a) => a.iter().flat_map(numbers).collect(),
        serde_json::Value::Object(o) => o.values().flat_map(numbers).collect(),
        _ => Vec::new(),
    }
}

/// The x (resp. y) of the interpolating surface depends on u (resp. v) only, because every
/// line shares the x positions and every point of a line its y: the u where x = `x_mm` and
/// the v where y = `y_mm`, by bisection (both increase along their parameter).
fn parameter_where(s: &surfscan::nurbs::NurbsSurface, axis: usize, target: f64) -> f64 {
    let at = |t: f64| {
        if axis == 0 {
            s.evaluate(t, 0.5)[0]
        } else {
            s.evaluate(0.5, t)[1]
        }
    };
    let (mut a, mut b) = (0.0f64, 1.0f64);
    for _ in 0..200 {
        let m = 0.5 * (a + b);
        if at(m) < target {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

/// Regression: the report refitted the lines at 5/5 whatever `[fit]` said, so with other
/// degrees its model sections and `model.x3p` described another surface than `surface.igs`.
/// At 3/3 the report, the X3P of the model and the IGES must describe one surface, and
/// `surfscan analyze` of the directory must give the runner's report.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_at_degree_3_reports_and_samples_the_surface_it_wrote() {
    let rig = Rig::start(RigOptions {
        degrees: (3, 3),
        ..RigOptions::default()
    })
    .await;
    let n = rig.options.lines;
    let o = run_scan(&rig.config("out"), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let dir = scan_dir(&rig.out_dir("out"));

    let file = surfscan::iges::reader::read_iges(&std::fs::read(dir.join("surface.igs")).unwrap())
        .unwrap();
    assert_eq!(file.surfaces.len(), 1);
    let s = &file.surfaces[0];
    assert_eq!((s.degree_u(), s.degree_v()), (3, 3));

    // model.x3p: the IGES surface at x = i * pitch/2 on every data line, evaluated here.
    let x3p = surfscan::x3p::read_x3p(&std::fs::read(dir.join("model.x3p")).unwrap()).unwrap();
    assert_eq!((x3p.rows, x3p.cols), (n, 2 * POINTS - 1));
    let mut worst = 0.0f64;
    for l in 0..n {
        let v = parameter_where(s, 1, target_nm(l) as f64 / 1e6);
        for i in 0..x3p.cols {
            let u = parameter_where(s, 0, i as f64 * PITCH_X_MM / 2.0);
            let z_um = s.evaluate(u, v)[2] * 1000.0;
            worst = worst.max((x3p.heights_um[l * x3p.cols + i] - z_um).abs());
        }
    }
    assert!(worst < 1e-6, "model.x3p is {worst} µm off the IGES surface");

    // The model sections: the surface's degrees, and the paper's bearing curves of the
    // IGES surface itself.
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["fit"]["degree_u"], 3);
    assert_eq!(report["fit"]["degree_v"], 3);
    let recipe = report["surface"]["recipe"].as_str().unwrap_or_default();
    assert!(recipe.contains("degree 3/3"), "{recipe}");
    let curves = surfscan::metrology::model::model_bearing_curves_with(
        s,
        &surfscan::metrology::model::ModelBacOptions::default(),
        None,
    )
    .unwrap();
    // The IGES text carries the poles to the last digit of their decimal form; the curves
    // of the surface read back agree with the report's to far below a nanometre.
    let (ours, theirs) = (
        numbers(&report["surface"]["bac_curves"]),
        numbers(&serde_json::to_value(&curves).unwrap()),
    );
    assert_eq!(ours.len(), theirs.len());
    let worst = ours
        .iter()
        .zip(&theirs)
        .fold(0.0f64, |w, (a, b)| w.max((a - b).abs()));
    assert!(
        worst < 1e-9,
        "the report's bearing curves are {worst} off those of surface.igs"
    );

    // `surfscan analyze` of the directory (degrees from the frozen plan) gives the same report
    // and the same X3P files as the runner wrote from memory.
    let again = rig.tmp.path().join("again");
    let a = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(&dir)
        .arg("--out")
        .arg(&again)
        .output()
        .unwrap();
    assert!(a.status.success(), "{}", describe(&a));
    let second: serde_json::Value =
        serde_json::from_slice(&std::fs::read(again.join("report.json")).unwrap()).unwrap();
    for key in [
        "recipe",
        "lines",
        "surface",
        "surface_grid",
        "model_vs_measured",
        "traceability",
        "warnings",
    ] {
        assert_eq!(report[key], second[key], "report.json: {key} differs");
    }
    assert_eq!(
        report["fit"]["max_residual_mm"],
        second["fit"]["max_residual_mm"]
    );
    for f in ["model.x3p", "measured.x3p", "summary.csv"] {
        assert!(
            std::fs::read(dir.join(f)).unwrap() == std::fs::read(again.join(f)).unwrap(),
            "{f} differs"
        );
    }
    rig.shutdown().await;
}

/// `[analysis]` as a station might set it, every key away from its default.
const ANALYSIS: &str = "\n[analysis]\ncurves = 9\nlevels = 41\nlambda-c-mm = 0.08\nno-filter = true\noutliers = \"exclude\"\nspike-threshold-sigma = 4.0\nspike-max-points = 3\nholdout-threshold = 0.9\nmaterial-ratio = \"instrument\"\n";

/// report.json without what differs between two runs of the same characterisation: the
/// timings, the input's and the files' paths, the IGES files (only the runner writes them)
/// and the scan's stop record (the runner reports before it writes it).
fn comparable(mut v: serde_json::Value, dirs: &[&std::path::Path]) -> serde_json::Value {
    fn walk(v: &mut serde_json::Value, dirs: &[String]) {
        match v {
            serde_json::Value::Object(m) => {
                for k in ["timings_s", "input", "files", "iges_files", "stop"] {
                    m.remove(k);
                }
                m.values_mut().for_each(|x| walk(x, dirs));
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(|x| walk(x, dirs)),
            serde_json::Value::String(s) => {
                for d in dirs {
                    *s = s.replace(d.as_str(), "<dir>");
                }
            }
            _ => {}
        }
    }
    let dirs: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
    walk(&mut v, &dirs);
    v
}

/// The paths at which two JSON values differ (at most 20).
fn differences(a: &serde_json::Value, b: &serde_json::Value, at: &str, out: &mut Vec<String>) {
    use serde_json::Value::{Array, Object};
    if out.len() >= 20 {
        return;
    }
    match (a, b) {
        (Object(x), Object(y)) => {
            for k in x.keys().chain(y.keys().filter(|k| !x.contains_key(*k))) {
                let null = serde_json::Value::Null;
                let (p, q) = (x.get(k).unwrap_or(&null), y.get(k).unwrap_or(&null));
                differences(p, q, &format!("{at}.{k}"), out);
            }
        }
        (Array(x), Array(y)) if x.len() == y.len() => {
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                differences(p, q, &format!("{at}[{i}]"), out);
            }
        }
        _ if a != b => out.push(format!("{at}: {a} vs {b}")),
        _ => {}
    }
}

fn analyze_into(dir: &std::path::Path, out: &std::path::Path) -> serde_json::Value {
    let a = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(dir)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(a.status.success(), "{}", describe(&a));
    serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap()
}

/// A scan run with a non-default `[analysis]` freezes it in its plan: `analyze` of its
/// directory gives the runner's report (all but timings and paths) without being told the
/// settings, and a journal without them (as older versions wrote) is analysed with the
/// defaults, which give another report.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn analyze_of_a_scan_directory_uses_the_analysis_settings_the_scan_ran_with() {
    let rig = Rig::start(RigOptions::default()).await;
    let o = run_scan(&rig.config_with("out", ANALYSIS), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let dir = scan_dir(&rig.out_dir("out"));
    let runner: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    // The runner characterised with the station's settings.
    assert_eq!(
        runner["recipe"]["outliers"], "exclude",
        "{}",
        runner["recipe"]
    );
    assert_eq!(runner["recipe"]["holdout_threshold_sq"], 0.9);
    assert_eq!(runner["recipe"]["material_ratio"], "instrument");
    assert!(
        runner["recipe"]["lambda_c_source"]
            .as_str()
            .is_some_and(|s| s.contains("0.08")),
        "{}",
        runner["recipe"]
    );

    let again = rig.tmp.path().join("again");
    let second = analyze_into(&dir, &again);
    let mut differ = Vec::new();
    differences(
        &comparable(runner.clone(), &[&dir, &again]),
        &comparable(second, &[&dir, &again]),
        "report",
        &mut differ,
    );
    assert!(
        differ.is_empty(),
        "analyze of the directory differs from the runner's report (runner vs analyze): {differ:#?}"
    );

    // The same directory with the settings taken out of its start record.
    let old = rig.tmp.path().join("old").join(dir.file_name().unwrap());
    std::fs::create_dir_all(old.join("lines")).unwrap();
    for e in std::fs::read_dir(dir.join("lines")).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), old.join("lines").join(e.file_name())).unwrap();
    }
    let (records, _) = journal(&dir);
    let mut bytes = Vec::new();
    for mut r in records {
        if let Record::Start(s) = &mut r {
            assert!(s.plan.analysis.is_some(), "the plan froze [analysis]");
            s.plan.analysis = None;
        }
        bytes.extend(surfscan::scan::journal::encode_record(&r).unwrap());
        bytes.push(b'\n');
    }
    std::fs::write(old.join("journal.jsonl"), bytes).unwrap();
    let defaults = analyze_into(&old, &rig.tmp.path().join("defaults"));
    assert_eq!(defaults["recipe"]["outliers"], "flag");
    assert_eq!(defaults["recipe"]["holdout_threshold_sq"], 0.5);
    assert_eq!(defaults["recipe"]["material_ratio"], "iso");
    for key in ["recipe", "surface", "between_lines"] {
        assert_ne!(
            defaults[key], runner[key],
            "{key}: the default settings give the same section"
        );
    }
    rig.shutdown().await;
}

/// Runs an uninterrupted scan on `rig` into `out` and returns its surface's bits.
async fn reference_surface(rig: &Rig, out: &str) -> Vec<Vec<u64>> {
    let o = run_scan(&rig.config(out), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let dir = scan_dir(&rig.out_dir(out));
    assert_journal_complete(&dir, rig.options.lines);
    surface_bits(&dir.join("surface.igs"))
}

/// What a crash at `step` of line `k` must leave behind, before the rerun.
fn assert_crash_left(dir: &std::path::Path, k: usize, step: &str) {
    let lines = dir.join("lines");
    let csv = lines.join(format!("{k:04}.csv")).exists();
    let json = lines.join(format!("{k:04}.json")).exists();
    let rec = surfscan::scan::journal::read_journal(&dir.join("journal.jsonl")).unwrap();
    let indices = line_record_indices(&rec.records);
    assert!(
        !rec.records.iter().any(|r| matches!(r, Record::Stop(_))),
        "{step}: no stop record after a crash"
    );
    let (want_csv, want_json, want_records) = match step {
        "before-csv" => (false, false, k),
        "before-json" => (true, false, k),
        "before-journal" => (true, true, k),
        "after-commit" => (true, true, k + 1),
        other => panic!("{other}"),
    };
    assert_eq!(
        (csv, json),
        (want_csv, want_json),
        "{step}: files of line {k}"
    );
    assert_eq!(
        indices,
        (0..want_records as u32).collect::<Vec<_>>(),
        "{step}: line records"
    );
}

/// `kill -9` at each durability step of line 3, then a rerun: every line exactly once and
/// the surface bit-identical to an uninterrupted run's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crash_at_every_durability_step_resumes_to_the_same_surface() {
    const K: usize = 3;
    let reference = {
        let rig = Rig::start(RigOptions::default()).await;
        let r = reference_surface(&rig, "reference").await;
        rig.shutdown().await;
        r
    };
    let runs = [
        "before-csv",
        "before-json",
        "before-journal",
        "after-commit",
    ]
    .map(|step| {
        let reference = reference.clone();
        async move {
            let rig = Rig::start(RigOptions::default()).await;
            let cfg = rig.config("out");
            let point = format!("{K}:{step}");
            let o = run_scan(&cfg, &[("SURFSCAN_TEST_CRASH", &point)]).await;
            assert!(
                !o.status.success() && o.status.code().is_none(),
                "{step}: the process must abort: {}",
                describe(&o)
            );
            let dir = scan_dir(&rig.out_dir("out"));
            assert_crash_left(&dir, K, step);
            let o = run_scan(&cfg, &[]).await;
            assert!(o.status.success(), "{step}: rerun {}", describe(&o));
            assert_eq!(
                scan_dir(&rig.out_dir("out")),
                dir,
                "{step}: same scan resumed"
            );
            assert_lines_exactly(&dir, rig.options.lines);
            assert_journal_complete(&dir, rig.options.lines);
            assert_eq!(
                surface_bits(&dir.join("surface.igs")),
                reference,
                "{step}: surface differs from the uninterrupted run's"
            );
            rig.shutdown().await;
        }
    });
    futures::future::join_all(runs).await;
}

/// A journal cut at every byte offset of its last record: recovery keeps exactly the
/// complete records (checked in-process for every offset), and the binary resumes a few
/// representative cuts to the uninterrupted run's surface.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_journal_torn_anywhere_in_its_last_record_resumes_cleanly() {
    const K: usize = 3;
    let rig = Rig::start(RigOptions::default()).await;
    let n = rig.options.lines;
    let reference = async {
        let rig = Rig::start(RigOptions::default()).await;
        let r = reference_surface(&rig, "reference").await;
        rig.shutdown().await;
        r
    };
    let (partial_cfg, point) = (rig.config("partial"), format!("{K}:after-commit"));
    let env = [("SURFSCAN_TEST_CRASH", point.as_str())];
    let crashed = run_scan(&partial_cfg, &env);
    let (reference, o) = futures::join!(reference, crashed);
    assert!(o.status.code().is_none(), "{}", describe(&o));
    let partial = scan_dir(&rig.out_dir("partial"));
    let bytes = std::fs::read(partial.join("journal.jsonl")).unwrap();
    assert_eq!(bytes.last(), Some(&b'\n'));
    let last_start = bytes[..bytes.len() - 1]
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |p| p + 1);
    let last: Record = serde_json::from_slice(&bytes[last_start..]).unwrap();
    assert!(
        matches!(&last, Record::Line(l) if l.id.index == K as u32),
        "last record is line {K}'s: {last:?}"
    );

    // Every cut, in-process.
    let scratch = tempfile::tempdir().unwrap();
    let jpath = scratch.path().join("journal.jsonl");
    for cut in last_start..=bytes.len() {
        std::fs::write(&jpath, &bytes[..cut]).unwrap();
        let (_journal, rec) = Journal::open(&jpath, std::sync::Arc::new(NoFaults)).unwrap();
        let state = ResumeState::from_records(&jpath, &rec.records).unwrap();
        let kept = if cut == bytes.len() { K + 1 } else { K };
        assert_eq!(
            state.completed().into_iter().collect::<Vec<_>>(),
            (0..kept as u32).collect::<Vec<_>>(),
            "cut at byte {cut}"
        );
        let torn = if cut == bytes.len() {
            0
        } else {
            cut - last_start
        };
        assert_eq!(rec.torn_bytes as usize, torn, "cut at byte {cut}");
        assert_eq!(
            std::fs::metadata(&jpath).unwrap().len() as usize,
            if cut == bytes.len() { cut } else { last_start },
            "cut at byte {cut}: the torn tail is truncated on disk"
        );
        // The lines the journal keeps load and match their recorded hashes.
        let store = ScanStore::open(&partial, std::sync::Arc::new(NoFaults)).unwrap();
        assert_eq!(store.load_committed(&state.lines).unwrap().len(), kept);
    }

    // Representative cuts through the binary: inside the class tag, mid-record, and the
    // complete record without its newline.
    let len = bytes.len();
    let runs = [last_start + 3, (last_start + len) / 2, len - 1].map(|cut| {
        let (partial, bytes, reference) = (&partial, &bytes, &reference);
        async move {
            let rig = Rig::start(RigOptions::default()).await;
            let target = rig.out_dir("out").join(partial.file_name().unwrap());
            copy_dir(partial, &target);
            std::fs::write(target.join("journal.jsonl"), &bytes[..cut]).unwrap();
            let o = run_scan(&rig.config("out"), &[]).await;
            assert!(o.status.success(), "cut at {cut}: {}", describe(&o));
            assert_eq!(scan_dir(&rig.out_dir("out")), target);
            assert_lines_exactly(&target, n);
            assert_journal_complete(&target, n);
            assert_eq!(
                &surface_bits(&target.join("surface.igs")),
                reference,
                "cut at {cut}"
            );
            rig.shutdown().await;
        }
    });
    futures::future::join_all(runs).await;
    rig.shutdown().await;
}

/// The stop record of a journal, if any.
fn stop_record(records: &[Record]) -> Option<surfscan::scan::journal::StopRecord> {
    records.iter().find_map(|r| match r {
        Record::Stop(s) => Some(s.clone()),
        _ => None,
    })
}

/// A bad configuration is refused with exit 78 and a message naming the key, before any
/// scan directory exists.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_configuration_exits_78_naming_the_key() {
    let rig = Rig::start(RigOptions::default()).await;
    let good = std::fs::read_to_string(rig.config("out")).unwrap();
    let cases = [
        (
            "unknown key",
            edited(&good, "[scan]\n", "[scan]\nline-count = 8\n"),
            "line-count",
        ),
        (
            "too few lines for degree-v 3",
            edited(&good, "lines = 8", "lines = 3"),
            "scan.lines",
        ),
        (
            "inexact step",
            edited(&good, "y-step-mm = 0.01", "y-step-mm = 0.0100004"),
            "scan.y-step-mm",
        ),
    ];
    for (what, text, key) in cases {
        assert_ne!(text, good, "{what}: the edit applies");
        let path = rig.tmp.path().join("bad.toml");
        std::fs::write(&path, text).unwrap();
        let o = run_scan(&path, &[]).await;
        assert_eq!(o.status.code(), Some(78), "{what}: {}", describe(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(key), "{what}: message names {key}: {err}");
        assert!(!rig.out_dir("out").exists(), "{what}: nothing was started");
    }
    rig.shutdown().await;
}

/// A full disk while line 3 is written suspends the scan instead of ending it: no stop
/// record but `success`, the refused write named in an interruption with the space the
/// remaining lines need, no half line left behind, and every line once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_during_a_line_suspends_and_the_scan_goes_on_when_space_returns() {
    const K: usize = 3;
    let runs = ["before-csv", "before-json", "before-journal"].map(|step| async move {
        let rig = Rig::start(RigOptions::default()).await;
        let n = rig.options.lines;
        let point = format!("{K}:{step}");
        let o = run_scan(&rig.config("out"), &[("SURFSCAN_TEST_ENOSPC", &point)]).await;
        assert!(o.status.success(), "{step}: {}", describe(&o));
        let dir = scan_dir(&rig.out_dir("out"));
        let records = assert_journal_complete(&dir, n);
        assert_eq!(
            line_record_indices(&records),
            (0..n as u32).collect::<Vec<_>>(),
            "{step}: every line once"
        );
        let notes = interruptions(&records);
        assert!(
            notes.iter().any(
                |r| r.starts_with("suspended: disk full while writing line 4")
                    && r.contains("the remaining lines need about")
            ),
            "{step}: {notes:?}"
        );
        assert!(
            notes.iter().any(|r| r.starts_with("space is back")),
            "{step}: {notes:?}"
        );
        assert_lines_exactly(&dir, n);
        let store = ScanStore::open(&dir, std::sync::Arc::new(NoFaults)).unwrap();
        assert_eq!(store.load_all().unwrap().lines.len(), n, "{step}");
        rig.shutdown().await;
    });
    futures::future::join_all(runs).await;
}

/// SIGTERM mid-scan: non-zero exit without a stop record but with an interruption; the rerun
/// completes with every line once and the uninterrupted run's surface.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_mid_scan_leaves_it_resumable() {
    let rig = Rig::start(RigOptions::default()).await;
    let n = rig.options.lines;
    let reference = tokio::spawn(async {
        let rig = Rig::start(RigOptions::default()).await;
        let r = reference_surface(&rig, "reference").await;
        rig.shutdown().await;
        r
    });
    let cfg = rig.config("out");
    let child = scan_command(&cfg, &[]).spawn().unwrap();
    let out = rig.out_dir("out");
    wait_until(Duration::from_secs(60), "three committed lines", || {
        committed_lines(&out) >= 3
    })
    .await;
    let pid = nix::unistd::Pid::from_raw(child.id().unwrap() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
    let o = tokio::time::timeout(Duration::from_secs(60), child.wait_with_output())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", describe(&o));
    let dir = scan_dir(&out);
    let (records, state) = journal(&dir);
    assert!(
        stop_record(&records).is_none(),
        "no stop record: {records:?}"
    );
    let done = state.lines.len();
    assert!((3..n).contains(&done), "{done} lines before the signal");
    assert!(
        interruptions(&records)
            .iter()
            .any(|r| r.contains("shutdown")),
        "{:?}",
        interruptions(&records)
    );
    let o = run_scan(&cfg, &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    assert_lines_exactly(&dir, n);
    assert_journal_complete(&dir, n);
    let reference = reference.await.expect("reference run");
    assert_eq!(surface_bits(&dir.join("surface.igs")), reference);
    rig.shutdown().await;
}

/// NG011 (busy) on the start of line 3's trace: while it lasts the line is retried with
/// backoff inside the `[scan] transient-budget-s` budget, and a start the instrument refused
/// is no attempt; only a busy spell longer than the budget fails the scan, naming the code.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ng_codes_on_a_trace_are_retried_within_the_transient_budget() {
    let exhausted = async {
        let rig = Rig::start(RigOptions {
            faults: vec!["ng:011@CTSTA#3x1000".into()],
            extra_scan: "transient-budget-s = 2\n".into(),
            ..RigOptions::default()
        })
        .await;
        let o = run_scan(&rig.config("out"), &[]).await;
        assert_eq!(o.status.code(), Some(1), "{}", describe(&o));
        let dir = scan_dir(&rig.out_dir("out"));
        let (records, _) = journal(&dir);
        let stop = stop_record(&records).expect("stop record");
        assert_eq!(stop.status, StopStatus::Fail);
        assert!(
            stop.reason.contains("NG011")
                && stop.reason.contains("line 3")
                && stop.reason.contains("2 s budget"),
            "{}",
            stop.reason
        );
        assert_eq!(line_record_indices(&records), vec![0, 1]);
        assert_lines_exactly(&dir, 2);
        rig.shutdown().await;
    };
    let recovered = async {
        let rig = Rig::start(RigOptions {
            faults: vec!["ng:011@CTSTA#3x2".into()],
            ..RigOptions::default()
        })
        .await;
        let n = rig.options.lines;
        let o = run_scan(&rig.config("out"), &[]).await;
        assert!(o.status.success(), "{}", describe(&o));
        let dir = scan_dir(&rig.out_dir("out"));
        assert_lines_exactly(&dir, n);
        let records = assert_journal_complete(&dir, n);
        let attempts: Vec<u32> = records
            .iter()
            .filter_map(|r| match r {
                Record::Line(l) => Some(l.id.attempt),
                _ => None,
            })
            .collect();
        // The two refused starts never began a trace: line 3 is still its first attempt.
        assert_eq!(attempts, vec![1; n]);
        let suspended = interruptions(&records)
            .into_iter()
            .filter(|r| r.starts_with("suspended: instrument busy since") && r.contains("NG011"))
            .count();
        assert_eq!(suspended, 2);
        rig.shutdown().await;
    };
    futures::join!(exhausted, recovered);
}

/// The instrument unplugged mid-trace and back: the scan suspends, records it, and
/// completes without duplicating the line.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_instrument_unplugged_mid_trace_suspends_and_the_scan_completes() {
    let rig = Rig::start(RigOptions {
        faults: vec!["unplug:300@CTSTA#3".into()],
        ..RigOptions::default()
    })
    .await;
    let n = rig.options.lines;
    let o = run_scan(&rig.config("out"), &[]).await;
    assert!(o.status.success(), "{}", describe(&o));
    let dir = scan_dir(&rig.out_dir("out"));
    assert_lines_exactly(&dir, n);
    let records = assert_journal_complete(&dir, n);
    let notes = interruptions(&records);
    let pos = |pat: &str| notes.iter().position(|r| r.contains(pat));
    let (abandoned, gone, back) = (
        pos("line 3 abandoned: instrument"),
        pos("instrument unavailable"),
        pos("instrument back"),
    );
    assert!(
        matches!((abandoned, gone, back), (Some(a), Some(g), Some(b)) if a < g && g < b),
        "line 3 abandoned, suspended, then back: {notes:?}"
    );
    rig.shutdown().await;
}

/// A scan in which the stage gets `fault` after three committed lines: it must complete with
/// every line, a journal note for which `recorded` holds (`what` in the message), and the
/// carriage truly at the last target (the served heights prove it was at every one).
async fn stage_fault_mid_scan_is_recovered(
    fault: StageFault,
    recorded: impl Fn(&str) -> bool,
    what: &str,
) {
    let rig = Rig::start(RigOptions::default()).await;
    let n = rig.options.lines;
    let cfg = rig.config("out");
    let child = scan_command(&cfg, &[]).spawn().unwrap();
    let out = rig.out_dir("out");
    wait_until(Duration::from_secs(60), "three committed lines", || {
        committed_lines(&out) >= 3
    })
    .await;
    rig.stage.inject(fault);
    let o = tokio::time::timeout(Duration::from_secs(120), child.wait_with_output())
        .await
        .unwrap()
        .unwrap();
    assert!(o.status.success(), "{}", describe(&o));
    let dir = scan_dir(&out);
    assert_lines_exactly(&dir, n);
    let records = assert_journal_complete(&dir, n);
    let notes = interruptions(&records);
    assert!(notes.iter().any(|r| recorded(r)), "{what}: {notes:?}");
    assert_eq!(rig.stage.true_position_nm(), target_nm(n - 1));
    rig.shutdown().await;
}

/// The stage controller resets (banner, position lost) mid-scan: the runner re-homes and
/// completes; the served heights prove the carriage was truly at every target.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stage_reset_mid_scan_rehomes_and_completes() {
    stage_fault_mid_scan_is_recovered(
        StageFault::ResetBanner,
        |r| r.contains("re-homing"),
        "a re-homing is recorded",
    )
    .await;
}

/// A one-off `ALARM:2` (soft limit) on a target inside the limits, as a controller whose
/// position went stale gives it: the scan re-homes once, moves again and completes, where it
/// used to end; the served heights prove the carriage was truly at every target.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_one_off_alarm_2_inside_the_limits_rehomes_and_completes() {
    stage_fault_mid_scan_is_recovered(
        StageFault::Alarm2,
        |r| r.contains("ALARM:2") && r.contains("re-homing"),
        "the stale position and its re-homing are recorded",
    )
    .await;
}

/// The terminal a foreground scan was started from goes away mid-scan (an SSH session that
/// dropped at night): SIGHUP arrives and nothing reads its output any more. The scan goes
/// on to the last line and its outputs, exit 0, instead of dying on the hang-up or aborting
/// on a write to a closed pipe.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_foreground_scan_outlives_the_terminal_it_was_started_from() {
    let rig = Rig::start(RigOptions::default()).await;
    let n = rig.options.lines;
    let cfg = rig.config("out");
    // Standard output and error are a pipe whose reader has already gone.
    let writer = crate::common::unread_pipe();
    let mut child = scan_command(&cfg, &[])
        .stdout(std::process::Stdio::from(writer.try_clone().unwrap()))
        .stderr(std::process::Stdio::from(writer))
        .spawn()
        .unwrap();
    let out = rig.out_dir("out");
    wait_until(Duration::from_secs(60), "a committed line", || {
        committed_lines(&out) >= 1
    })
    .await;
    assert!(
        committed_lines(&out) < n,
        "the scan ended before the hang-up could reach it mid-scan"
    );
    let pid = nix::unistd::Pid::from_raw(child.id().unwrap() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGHUP).unwrap();
    let status = tokio::time::timeout(Duration::from_secs(120), child.wait())
        .await
        .unwrap()
        .unwrap();
    assert!(status.success(), "the scan ended with {status}");
    let dir = scan_dir(&out);
    assert_lines_exactly(&dir, n);
    assert_journal_complete(&dir, n);
    assert!(dir.join("surface.igs").exists() && dir.join("report.json").exists());
    rig.shutdown().await;
}
