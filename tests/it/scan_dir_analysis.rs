//! Scan directories characterised and fitted end to end: a directory is built exactly as the
//! scan daemon builds it (`ScanStore::create`, `Journal::create`, `ScanStore::commit_line`)
//! from the real `sur-2` profiles, with instrument results deliberately offset from values
//! computed here, then `surfscan analyze SCAN_DIR`, `surfscan fit SCAN_DIR` and
//! `report::characterise_scan` are checked against what was put in.

use crate::common::{json_from, reference_script};
use chrono::{TimeZone, Utc};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use surfscan::metrology::params::{analyze_line, Options};
use surfscan::profile::{
    Conditions, FilterKind, InstrumentResult, NoHeights, Profile, ProfileKind,
};
use surfscan::scan::faults::NoFaults;
use surfscan::scan::journal::{Journal, Record, StartRecord, StopRecord, StopStatus};
use surfscan::scan::line::{LineIdentity, LineMeta};
use surfscan::scan::plan::Plan;
use surfscan::scan::scan_id::ScanId;
use surfscan::scan::store::ScanStore;
use surfscan::units::Nm;

fn surfscan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
}

/// x pitch and y step of the bundled `sur-2` grid (tests/data/README.md).
const PITCH_X_MM: f64 = 0.003484;
const STEP_Y_NM: i64 = 10_452;

/// Offsets put into the instrument's results: ours − instrument must come out as these.
const RA_OFFSET_UM: f64 = 0.05;
const RZ_OFFSET_UM: f64 = -0.1;

const SPECIMEN: &str = "SUR-2 brass <B&S> #7";
const OPERATOR: &str = "J. Tester";
const NOTES: &str = "after lapping; x along the grinding marks";
const MODEL: &str = "SJ-210";
const FIRMWARE: &str = "1.234";
const DRIVE: &str = "standard drive unit 178-230";
const CONFIG_HASH: &str = "9f2c0000000000000000000000000000000000000000000000000000000000aa";
const SOFTWARE: &str = "surfscan 0.9.1-test";
const SERIAL: &str = "SJ210-00417";

fn sur2_rows() -> Vec<Vec<f64>> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/sur-2.grid.csv");
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .collect()
}

fn conditions(kind: ProfileKind) -> Conditions {
    Conditions {
        standard: Some("ISO1997".into()),
        profile_kind: Some(kind),
        filter: Some(FilterKind::Gaussian),
        lambda_c_mm: Some(0.8),
        lambda_s_um: None,
        sampling_lengths: None,
        evaluation_length_mm: None,
        speed_mm_s: Some(0.5),
        raw: None,
    }
}

/// How this test expects a P line under [`conditions`] to be evaluated.
fn expected_options() -> Options {
    Options {
        lambda_c_mm: 0.8,
        apply_lambda_c: true,
        lambda_s_um: None,
        sampling_lengths: None,
        central_sections: None,
        form: None,
    }
}

/// The frozen plan of a scan of `lines` lines at the paper's degrees.
fn plan(lines: u32) -> Plan {
    Plan {
        lines,
        y_start_nm: Nm(0),
        y_step_nm: Nm(STEP_Y_NM),
        degree_u: 5,
        degree_v: 5,
        max_line_attempts: 3,
        v_method: Default::default(),
        replace_spikes: None,
        analysis: None,
    }
}

/// Builds a scan of the given `sur-2` rows as the daemon does and returns its directory.
/// Every line's instrument results are Ra = ours − RA_OFFSET_UM (µm) and Rz = ours −
/// RZ_OFFSET_UM given in nm, plus a parameter we do not compute.
fn build_scan(
    parent: &Path,
    rows: &[usize],
    kind: ProfileKind,
    stop: Option<StopStatus>,
) -> PathBuf {
    let data = sur2_rows();
    let start = Utc.with_ymd_and_hms(2026, 11, 30, 9, 15, 0).unwrap();
    let id = ScanId::new(start, SPECIMEN);
    let faults = Arc::new(NoFaults);
    let store = ScanStore::create(parent, &id, faults.clone()).unwrap().0;
    let mut journal = Journal::create(
        store.root(),
        StartRecord {
            scan_id: id.0.clone(),
            sequence: 1,
            time: start,
            plan: plan(rows.len() as u32),
            config: json!({
                "output": { "dir": parent.display().to_string() },
                "traceability": {
                    "serial-number": SERIAL,
                    "stylus-tip-radius-um": 2.0,
                    "calibration-date": "2026-03-14",
                },
            }),
            config_hash: CONFIG_HASH.into(),
            specimen: SPECIMEN.into(),
            operator: OPERATOR.into(),
            notes: NOTES.into(),
            software_version: SOFTWARE.into(),
            instrument_model: MODEL.into(),
            firmware: FIRMWARE.into(),
            drive_unit: DRIVE.into(),
            conditions: conditions(kind),
            peer: None,
            job: None,
        },
        faults,
    )
    .unwrap();
    for &r in rows {
        let z = data[r].clone();
        let ours = analyze_line(&z, PITCH_X_MM, &expected_options())
            .unwrap()
            .params;
        let profile = Profile {
            pitch_x_mm: PITCH_X_MM,
            heights_um: z,
            kind,
            conditions: conditions(kind),
        };
        let meta = LineMeta {
            id: LineIdentity {
                index: r as u32,
                y_target_nm: Nm(r as i64 * STEP_Y_NM),
                y_readback_nm: Some(Nm(r as i64 * STEP_Y_NM + 3)),
                attempt: 1,
                points: profile.heights_um.len(),
            },
            profile: Profile {
                pitch_x_mm: PITCH_X_MM,
                heights_um: NoHeights,
                kind,
                conditions: conditions(kind),
            },
            results: vec![
                InstrumentResult {
                    name: "Ra".into(),
                    value: Some(ours.ra_um - RA_OFFSET_UM),
                    unit: "µm".into(),
                    printed: None,
                    ng_code: None,
                },
                InstrumentResult {
                    name: "Rz".into(),
                    value: Some((ours.rz_um - RZ_OFFSET_UM) * 1000.0),
                    unit: "nm".into(),
                    printed: None,
                    ng_code: None,
                },
                InstrumentResult {
                    name: "Rmr0".into(),
                    value: Some(42.0),
                    unit: "%".into(),
                    printed: None,
                    ng_code: None,
                },
            ],
            readout_warnings: Vec::new(),
            started_at: start,
            // One line read out every 7.5 minutes.
            finished_at: start + chrono::Duration::seconds(450 * (r as i64 + 1)),
        };
        store.commit_line(&mut journal, &meta, &profile).unwrap();
    }
    if let Some(status) = stop {
        journal
            .append(&Record::Stop(StopRecord {
                status,
                reason: "test".into(),
                cause: None,
                internal: false,
                time: start,
            }))
            .unwrap();
    }
    store.root().to_path_buf()
}

fn run_ok(args: &[&str]) -> std::process::Output {
    let out = surfscan().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "surfscan {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn report(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

#[test]
fn analyze_scan_dir_writes_every_file_with_traceability_and_instrument_differences() {
    let tmp = tempfile::tempdir().unwrap();
    let rows: Vec<usize> = (0..31).collect();
    let scan = build_scan(tmp.path(), &rows, ProfileKind::P, Some(StopStatus::Success));
    run_ok(&["analyze", scan.to_str().unwrap()]);

    for name in [
        "report.json",
        "summary.csv",
        "bac.png",
        "bac.svg",
        "heightmap.png",
        "heightmap.svg",
        "overlay.png",
        "overlay.svg",
        "measured.x3p",
        "model.x3p",
    ] {
        let meta = std::fs::metadata(scan.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(meta.len() > 0, "{name} is empty");
    }
    let r = report(&scan);
    assert_eq!(r["kind"], "scan");
    // The surface was fitted for this report: the fit is in the timings written to disk.
    crate::common::assert_fit_timed(&r);

    // Traceability equals what the start record holds.
    let t = &r["traceability"];
    assert_eq!(t["specimen"], SPECIMEN);
    assert_eq!(t["operator"], OPERATOR);
    assert_eq!(t["notes"], NOTES);
    assert_eq!(t["software_version"], SOFTWARE);
    assert_eq!(t["config_hash"], CONFIG_HASH);
    assert_eq!(t["instrument_model"], MODEL);
    assert_eq!(t["firmware"], FIRMWARE);
    assert_eq!(t["drive_unit"], DRIVE);
    assert_eq!(t["manufacturer"], "Mitutoyo");
    assert_eq!(t["instrument_serial"], SERIAL);
    assert_eq!(t["stylus_tip_radius_um"], 2.0);
    assert_eq!(t["calibration_date"], "2026-03-14");
    assert_eq!(t["scan_id"], scan.file_name().unwrap().to_str().unwrap());
    assert_eq!(t["conditions"]["lambda_c_mm"], 0.8);
    assert_eq!(t["conditions"]["standard"], "ISO1997");
    assert_eq!(r["scan"]["status"], "complete");
    assert_eq!(r["scan"]["stop"]["status"], "success");
    assert_eq!(r["scan"]["lines_used"].as_array().unwrap().len(), 31);

    // Lines: keys, values against an independent call, y from the metadata, and the
    // instrument's results beside ours with the known differences.
    let data = sur2_rows();
    let lines = r["lines"].as_array().unwrap();
    assert_eq!(lines.len(), 31);
    for key in [
        "index",
        "y_mm",
        "Ra_um",
        "Rq_um",
        "Rz_um",
        "RzJIS_um",
        "Rp_um",
        "Rv_um",
        "Rt_um",
        "Rz1max_um",
        "Rsk",
        "Rku",
        "RSm_um",
        "Rdq",
        "Rk_um",
        "Rpk_um",
        "Rvk_um",
        "Mr1_pct",
        "Mr2_pct",
        "A1",
        "A2",
        "Rmr_table",
        "instrument",
    ] {
        assert!(lines[7].get(key).is_some(), "line key {key} missing");
    }
    for (k, line) in lines.iter().enumerate() {
        assert_eq!(line["index"], k);
        let y = line["y_mm"].as_f64().unwrap();
        assert!(
            (y - k as f64 * STEP_Y_NM as f64 * 1e-6).abs() < 1e-15,
            "{y}"
        );
        let ours = analyze_line(&data[k], PITCH_X_MM, &expected_options())
            .unwrap()
            .params;
        assert!((line["Ra_um"].as_f64().unwrap() - ours.ra_um).abs() < 1e-12);
        assert!((line["A1"].as_f64().unwrap() - ours.material.rk.a1_um_pct).abs() < 1e-12);
        let inst = line["instrument"].as_array().unwrap();
        let by = |n: &str| inst.iter().find(|c| c["name"] == n).unwrap().clone();
        let ra = by("Ra");
        assert!(
            (ra["difference"].as_f64().unwrap() - RA_OFFSET_UM).abs() < 1e-12,
            "{ra}"
        );
        assert!((ra["ours"].as_f64().unwrap() - ours.ra_um).abs() < 1e-12);
        assert_eq!(ra["unit"], "um");
        let rz = by("Rz");
        assert!(
            (rz["difference"].as_f64().unwrap() - RZ_OFFSET_UM).abs() < 1e-9,
            "{rz}"
        );
        assert!((rz["instrument"].as_f64().unwrap() - (ours.rz_um - RZ_OFFSET_UM)).abs() < 1e-9);
        let rmr0 = by("Rmr0");
        assert!(rmr0["ours"].is_null() && rmr0["difference"].is_null());
    }

    // Surface sections and the recipe.
    for key in [
        "Sa_um", "Sq_um", "Sz_um", "Ssk", "Sku", "Sdq", "Sdr_pct", "bac",
    ] {
        assert!(r["surface"].get(key).is_some(), "surface.{key}");
        assert!(r["surface_grid"].get(key).is_some(), "surface_grid.{key}");
    }
    assert_eq!(r["surface"]["bac"].as_array().unwrap().len(), 101);
    assert_eq!(r["surface"]["bac_curves"].as_array().unwrap().len(), 31);
    assert_eq!(
        r["model_vs_measured"]["points_left_out"]
            .as_array()
            .unwrap()
            .len(),
        31
    );
    let defs = &r["recipe"]["definitions"];
    for p in ["Ra", "Rz", "RzJIS", "Rk", "A1", "A2", "Sa", "Sq", "Sdr"] {
        assert!(
            defs[p].as_str().is_some_and(|d| !d.is_empty()),
            "definition of {p}"
        );
    }
    assert_eq!(r["recipe"]["lambda_c_mm"], 0.8);
    assert!(r["recipe"]["lambda_c_source"]
        .as_str()
        .unwrap()
        .contains("recorded"));
    assert!(r["recipe"]["filter_reason"]
        .as_str()
        .unwrap()
        .contains("filter applied"));

    // summary.csv: header plus one row per line, with the instrument's Ra.
    let csv = std::fs::read_to_string(scan.join("summary.csv")).unwrap();
    let mut csv_lines = csv.lines();
    let header: Vec<&str> = csv_lines.next().unwrap().split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).unwrap();
    let rows_csv: Vec<Vec<&str>> = csv_lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows_csv.len(), 31);
    let ours5 = analyze_line(&data[5], PITCH_X_MM, &expected_options())
        .unwrap()
        .params;
    // Written with the 4 significant digits of a height, line numbers 1-based beside the
    // files' index.
    use surfscan::numfmt::{fmt, Quantity::HeightUm};
    assert_eq!(
        rows_csv[5][col("instrument_Ra_um")],
        fmt(ours5.ra_um - RA_OFFSET_UM, HeightUm)
    );
    assert_eq!(
        rows_csv[5][col("instrument_Rz_um")],
        fmt(ours5.rz_um - RZ_OFFSET_UM, HeightUm)
    );
    assert_eq!(rows_csv[5][col("Ra_um")], fmt(ours5.ra_um, HeightUm));
    // The columns summary.csv has always had keep their places (the instrument's Ra at
    // 23rd); the parameters added since follow them, with the digits of their quantity.
    assert_eq!((col("A2_um_pct"), col("instrument_Ra_um")), (21, 22));
    assert_eq!(
        &header[25..],
        [
            "Rda",
            "Rc_um",
            "RPc_per_cm",
            "Rppi_per_inch",
            "Rdc_um",
            "Rmr_pct"
        ]
    );
    use surfscan::numfmt::{fmt_opt, Quantity};
    let expect = [
        ("Rda", fmt(ours5.rda, Quantity::Ratio)),
        ("Rc_um", fmt_opt(ours5.rc_um, HeightUm)),
        ("RPc_per_cm", fmt_opt(ours5.rpc_per_cm, Quantity::PerLength)),
        (
            "Rppi_per_inch",
            fmt_opt(ours5.rppi_per_inch, Quantity::PerLength),
        ),
        ("Rdc_um", fmt(ours5.rdc_um, HeightUm)),
        ("Rmr_pct", fmt(ours5.material.rmr_pct, Quantity::Percent)),
    ];
    for (name, value) in expect {
        assert!(!value.is_empty(), "{name} has a value on this line");
        assert_eq!(rows_csv[5][col(name)], value, "{name}");
    }
    assert!(rows_csv.iter().all(|r| r.len() == header.len()));
    assert_eq!(
        (rows_csv[5][col("line")], rows_csv[5][col("index")]),
        ("6", "0005")
    );

    // Plots carry the traceability caption.
    for name in ["bac.svg", "heightmap.svg", "overlay.svg"] {
        let svg = std::fs::read_to_string(scan.join(name)).unwrap();
        assert!(svg.contains("SUR-2 brass"), "{name} lacks the specimen");
        assert!(
            svg.contains(FIRMWARE) && svg.contains(SOFTWARE),
            "{name} lacks instrument/software"
        );
        assert!(svg.contains("λc 0.8 mm"), "{name} lacks the conditions");
    }
}

#[test]
fn x3p_of_a_scan_carries_the_traceability_and_surfalize_reads_it() {
    use surfscan::x3p::read_x3p;
    let tmp = tempfile::tempdir().unwrap();
    // Lines 3 to 10 of the data: the first traced line is not at y = 0.
    let rows: Vec<usize> = (2..10).collect();
    let scan = build_scan(tmp.path(), &rows, ProfileKind::R, Some(StopStatus::Success));
    run_ok(&["analyze", scan.to_str().unwrap()]);
    let data = sur2_rows();
    for name in ["measured.x3p", "model.x3p"] {
        // Valid ISO 5436-2 with Record2 (the scan states a calibration date).
        crate::metrology_x3p::assert_valid_x3p(&scan.join(name));
        let back = read_x3p(&std::fs::read(scan.join(name)).unwrap()).unwrap();
        assert_eq!(back.meta.creator, OPERATOR, "{name}");
        assert_eq!(back.meta.model, MODEL);
        assert_eq!(back.meta.manufacturer, "Mitutoyo");
        assert_eq!(back.meta.version, FIRMWARE);
        assert_eq!(back.meta.date, "2026-11-30T09:15:00+00:00");
        // The instrument's calibration, not the scan's start; serial and stylus from the
        // configuration the scan recorded.
        assert_eq!(back.meta.calibration_date, "2026-03-14T00:00:00", "{name}");
        assert_eq!(back.meta.serial, SERIAL, "{name}");
        assert_eq!(
            back.meta.probe, "SJ-210 stylus, tip radius 2.00 µm",
            "{name}"
        );
        for part in [
            SPECIMEN,
            NOTES,
            DRIVE,
            SOFTWARE,
            CONFIG_HASH,
            "\"lambda_c_mm\":0.8",
        ] {
            assert!(
                back.meta.comment.contains(part),
                "{name}: {part} not in {:?}",
                back.meta.comment
            );
        }
        // The program is named once, by the version the scan recorded.
        assert!(
            !back.meta.comment.contains("surfscan surfscan"),
            "{name}: {:?}",
            back.meta.comment
        );
        assert_eq!(back.rows, 8);
        assert!((back.pitch_y_mm - STEP_Y_NM as f64 * 1e-6).abs() < 1e-12);
        // The CY offset is the machine y of the first line, CX the x of a line's first point
        // (a scan's lines start at 0); the increments are written without the float noise of
        // the mean pitch.
        assert!(
            (back.offset_y_mm - 2.0 * STEP_Y_NM as f64 * 1e-6).abs() < 1e-12,
            "{name}: {}",
            back.offset_y_mm
        );
        assert_eq!(back.offset_x_mm, 0.0, "{name}");
        let xml = String::from_utf8_lossy(&std::fs::read(scan.join(name)).unwrap()).to_string();
        assert!(
            xml.contains("<Increment>1.0452e-5</Increment><Offset>2.0904e-5</Offset></CY>"),
            "{name}: {xml}"
        );
    }
    let measured = read_x3p(&std::fs::read(scan.join("measured.x3p")).unwrap()).unwrap();
    assert_eq!(measured.cols, data[0].len());
    assert!((measured.heights_um[3 * measured.cols + 10] - data[5][10]).abs() < 1e-9);

    let v = json_from(reference_script("metrology_x3p_read.py").arg(scan.join("measured.x3p")));
    assert_eq!(v["rows"], 8);
    assert_eq!(v["cols"], data[0].len());
    assert!((v["heights_um"][10].as_f64().unwrap() - data[2][10]).abs() < 1e-9);

    // An R profile from the instrument is not filtered again, and the recipe says why.
    let r = report(&scan);
    assert!(
        r["recipe"]["filter_reason"]
            .as_str()
            .unwrap()
            .contains("R profile"),
        "{}",
        r["recipe"]
    );
    let unfiltered = Options {
        apply_lambda_c: false,
        ..expected_options()
    };
    let ours = analyze_line(&data[4], PITCH_X_MM, &unfiltered)
        .unwrap()
        .params;
    assert!((r["lines"][2]["Ra_um"].as_f64().unwrap() - ours.ra_um).abs() < 1e-12);
}

#[test]
fn partial_scan_is_analysed_with_the_lines_it_has_and_names_the_incomplete_one() {
    let tmp = tempfile::tempdir().unwrap();
    let rows: Vec<usize> = (0..13).collect();
    let scan = build_scan(tmp.path(), &rows, ProfileKind::P, Some(StopStatus::Abort));
    // Line 4 lost its metadata (a crash between the two renames).
    std::fs::remove_file(scan.join("lines/0004.json")).unwrap();
    let out = surfscan()
        .args(["analyze", scan.to_str().unwrap(), "--out"])
        .arg(tmp.path().join("out"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    // 12 of the 13 lines on disk: partial, exit 3, every output written.
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("warning")
            && stderr.contains("line 5 (0004.csv) has only one of its two files")
            && stderr.contains("it is made from 12 of 13 lines"),
        "{stderr}"
    );
    let r = report(&tmp.path().join("out"));
    let used: Vec<u64> = r["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["index"].as_u64().unwrap())
        .collect();
    assert_eq!(used, vec![0, 1, 2, 3, 5, 6, 7, 8, 9, 10, 11, 12]);
    assert_eq!(r["scan"]["status"], "partial");
    assert_eq!(r["scan"]["stop"]["status"], "abort");
    assert_eq!(r["scan"]["lines_incomplete"], json!([4]));
    assert_eq!(r["scan"]["lines_in_journal"].as_array().unwrap().len(), 13);
    assert!(r["warnings"].as_array().unwrap().iter().any(|w| w
        .as_str()
        .unwrap()
        .contains("line 5 (0004.csv) has only one of its two files")));
    // Line 5 keeps its own y although line 4 is missing.
    assert!(
        (r["lines"][4]["y_mm"].as_f64().unwrap() - 5.0 * STEP_Y_NM as f64 * 1e-6).abs() < 1e-15
    );
    // The hold-out refit still runs on the uneven lines and reports them by their index.
    let held: Vec<u64> = r["model_vs_measured"]["lines_left_out"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["index"].as_u64().unwrap())
        .collect();
    // Every 2nd of the 12 lines used is refitted from the others: positions 1, 3, 5, 7, 9.
    assert_eq!(held, vec![1, 3, 6, 8, 10]);
    // Each line carries its own share: line 6 was left out whole, line 5 was not.
    let line6 = &r["lines"][5]["model_vs_measured"];
    assert_eq!(line6["line_left_out"]["index"], 6);
    assert_eq!(line6["points_left_out"]["index"], 6);
    assert!(r["lines"][4]["model_vs_measured"]["line_left_out"].is_null());
    assert!(std::fs::metadata(tmp.path().join("out/model.x3p")).is_ok());
    // Nothing was written into the scan directory when --out points elsewhere.
    assert!(!scan.join("report.json").exists());
}

#[test]
fn fit_scan_dir_writes_an_iges_through_the_stored_points() {
    use surfscan::fit::{fit_grid, FitOptions};
    use surfscan::iges::reader::read_iges;
    let tmp = tempfile::tempdir().unwrap();
    // Lines 0..=7 with line 3 never traced: y is uneven and must come from the metadata.
    let rows = [0usize, 1, 2, 4, 5, 6, 7];
    let scan = build_scan(tmp.path(), &rows, ProfileKind::P, None);
    let report_path = tmp.path().join("fit.json");
    run_ok(&[
        "fit",
        scan.to_str().unwrap(),
        "--report",
        report_path.to_str().unwrap(),
    ]);
    let iges = read_iges(&std::fs::read(scan.join("surface.igs")).unwrap()).unwrap();
    assert_eq!(iges.surfaces.len(), 1);
    let s = &iges.surfaces[0];
    let data = sur2_rows();
    let cols = data[0].len();
    assert_eq!((s.count_u(), s.count_v()), (cols, rows.len()));
    let y: Vec<f64> = rows
        .iter()
        .map(|&r| r as f64 * STEP_Y_NM as f64 * 1e-6)
        .collect();
    let z: Vec<f64> = rows.iter().flat_map(|&r| data[r].clone()).collect();
    // The interpolation parameters of these points (the fitter's own, independent of the CLI
    // and the IGES round trip): the read-back surface must pass through every stored point.
    let params = fit_grid(PITCH_X_MM, &y, &z, cols, FitOptions::default()).unwrap();
    let mut worst = 0.0f64;
    for (l, &v) in params.params_v.iter().enumerate() {
        for (k, &u) in params.params_u.iter().enumerate() {
            let p = s.evaluate(u, v);
            let q = [k as f64 * PITCH_X_MM, y[l], z[l * cols + k] / 1000.0];
            for d in 0..3 {
                worst = worst.max((p[d] - q[d]).abs());
            }
        }
    }
    assert!(
        worst <= 1e-10,
        "surface misses a stored point by {worst} mm"
    );
    let rep: Value = serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    assert_eq!(rep["input_kind"], "scan");
    assert_eq!(rep["lines"], json!([0, 1, 2, 4, 5, 6, 7]));
    assert_eq!(rep["pitch_x_mm"], PITCH_X_MM);
    // Pitches belong to grid CSVs only.
    let out = surfscan()
        .args(["fit", scan.to_str().unwrap(), "--pitch-x", "0.001"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn fit_scan_dir_checks_the_journal_and_keeps_a_completed_surface() {
    let tmp = tempfile::tempdir().unwrap();
    let rows: Vec<usize> = (0..7).collect();
    let scan = build_scan(tmp.path(), &rows, ProfileKind::P, Some(StopStatus::Success));
    let scan_s = scan.to_str().unwrap();
    run_ok(&["fit", scan_s]);
    let surface = scan.join("surface.igs");
    // The surface itself: the Parameter Data section (the Global section holds the time).
    let poles = |p: &Path| -> Vec<String> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .filter(|l| l.as_bytes().get(72) == Some(&b'P'))
            .map(str::to_owned)
            .collect()
    };
    let first = poles(&surface);

    // A second fit does not replace the completed scan's surface unless asked.
    let out = surfscan().args(["fit", scan_s]).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("the surface the completed scan wrote"),
        "{stderr}"
    );
    assert!(
        stderr.contains("--force") && stderr.contains("-o"),
        "{stderr}"
    );
    let other = tmp.path().join("refit.igs");
    run_ok(&["fit", scan_s, "-o", other.to_str().unwrap()]);
    assert!(other.exists());
    run_ok(&["fit", scan_s, "--force"]);

    // A line never committed to the journal (files on disk, no record) is left out.
    let lines = scan.join("lines");
    std::fs::copy(lines.join("0006.csv"), lines.join("0020.csv")).unwrap();
    let mut meta: Value =
        serde_json::from_str(&std::fs::read_to_string(lines.join("0006.json")).unwrap()).unwrap();
    meta["index"] = json!(20);
    meta["y_target_nm"] = json!(20 * STEP_Y_NM);
    std::fs::write(lines.join("0020.json"), meta.to_string()).unwrap();
    let report_path = tmp.path().join("fit.json");
    let out = surfscan()
        .args(["fit", scan_s, "--force", "--report"])
        .arg(&report_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    // A surface of 7 of the 8 lines on disk is partial: exit 3, the surface written.
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("warning: line 21 (0020.csv) is on disk but the journal never committed it (the scan stopped before its record); it was left out")
            && stderr.contains("the surface is partial: fitted from 7 of 8 lines"),
        "{stderr}"
    );
    let rep: Value = serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    assert_eq!(rep["lines"], json!([0, 1, 2, 3, 4, 5, 6]));
    assert_eq!(poles(&surface), first, "the same lines, the same surface");
    // analyze leaves it out the same way.
    let analysis = tmp.path().join("analysis");
    let out = surfscan()
        .args(["analyze", scan_s, "--out"])
        .arg(&analysis)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(3),
        "the same exit status as fit: {stderr}"
    );
    assert!(
        stderr.contains("line 21 (0020.csv) is on disk but the journal never committed it"),
        "{stderr}"
    );
    let rep: Value =
        serde_json::from_str(&std::fs::read_to_string(analysis.join("report.json")).unwrap())
            .unwrap();
    let used: Vec<u64> = rep["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["index"].as_u64().unwrap())
        .collect();
    assert_eq!(used, vec![0, 1, 2, 3, 4, 5, 6]);

    // A height edited after the line was traced: that line is left out, named with its
    // file, and the others are fitted (one bad line does not take down the rest).
    let csv = lines.join("0002.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    // One more digit on the first height: still a valid file, a different number.
    let mut rows_text: Vec<String> = text.lines().map(str::to_owned).collect();
    rows_text[1].push('7');
    let edited = rows_text.join("\n") + "\n";
    assert_ne!(edited, text);
    std::fs::write(&csv, edited).unwrap();
    let out = surfscan()
        .args(["fit", scan_s, "--force", "--report"])
        .arg(&report_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("line 3 (")
            && stderr.contains("0002.csv) was changed after it was traced")
            && stderr.contains("it was left out"),
        "{stderr}"
    );
    let rep: Value = serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    assert_eq!(rep["lines"], json!([0, 1, 3, 4, 5, 6]));
    assert_eq!(
        rep["lines_left_out"],
        json!([
            {"line": 3, "file": "0002.csv", "why": "changed after it was traced"},
            {"line": 21, "file": "0020.csv", "why": "never committed to the journal"}
        ])
    );
    assert_ne!(poles(&surface), first, "a surface through the other lines");
    // The IGES file itself says which line its surface does not pass through.
    let iges = std::fs::read_to_string(&surface).unwrap();
    let start: String = iges
        .lines()
        .filter(|l| l.get(72..73) == Some("S"))
        .map(|l| l[..72].trim_end())
        .collect::<Vec<_>>()
        .join(" ");
    assert!(
        start.contains("Lines left out: 3 (0002.csv, changed after it was traced); 21 (0020.csv, never committed to the journal)."),
        "{start}"
    );
}

#[test]
fn a_malformed_line_file_is_a_clear_error_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let rows: Vec<usize> = (0..7).collect();
    let scan = build_scan(tmp.path(), &rows, ProfileKind::P, Some(StopStatus::Fail));
    let csv = scan.join("lines/0002.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    std::fs::write(&csv, text.replacen("\n0.003484,", "\n0.003484,12..5x", 1)).unwrap();
    // `analyze SCAN` and `fit SCAN --force`: (exit status, stderr) of each.
    let both = || {
        [
            &["analyze", scan.to_str().unwrap()][..],
            &["fit", scan.to_str().unwrap(), "--force"],
        ]
        .map(|args| {
            let out = surfscan().args(args).output().unwrap();
            let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
            assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
            (out.status.code(), stderr)
        })
    };
    // The journal's SHA-256 shows the file was damaged after it was traced: the line is left
    // out and named, and the others are characterised and fitted: partial, exit 3 in both.
    for (code, stderr) in both() {
        assert_eq!(code, Some(3), "{stderr}");
        assert!(
            stderr.contains("line 3 (") && stderr.contains("0002.csv) was changed"),
            "{stderr}"
        );
    }
    // Without a journal to check it against, the damaged file is an error naming it.
    let journal = scan.join("journal.jsonl");
    let journal_text = std::fs::read(&journal).unwrap();
    std::fs::remove_file(&journal).unwrap();
    for (code, stderr) in both() {
        assert_eq!(code, Some(1), "{stderr}");
        assert!(
            stderr.contains("0002.csv") && stderr.contains("line 3"),
            "{stderr}"
        );
    }
    std::fs::write(&journal, journal_text).unwrap();
    std::fs::write(&csv, text).unwrap();
    // A heights file that cannot be read at all (here a directory where the file was; on a
    // station a bad sector) is left out and named the same way.
    let other = scan.join("lines/0004.csv");
    let kept = std::fs::read(&other).unwrap();
    std::fs::remove_file(&other).unwrap();
    std::fs::create_dir(&other).unwrap();
    for (code, stderr) in both() {
        assert_eq!(code, Some(3), "{stderr}");
        assert!(
            stderr.contains("line 5 (") && stderr.contains("0004.csv) cannot be read"),
            "{stderr}"
        );
    }
    std::fs::remove_dir(&other).unwrap();
    std::fs::write(&other, kept).unwrap();
    // A directory that is not a scan is named as such.
    let out = surfscan()
        .args(["analyze", tmp.path().to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("not a scan directory"), "{stderr}");
    let meta = scan.join("lines/0005.json");
    std::fs::write(&meta, "{ \"index\": 5, ").unwrap();
    let out = surfscan()
        .args(["analyze", scan.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("0005.json"), "{stderr}");
}

#[test]
fn characterise_scan_reports_the_fit_it_describes_and_returns_the_paths() {
    use surfscan::report::{characterise_scan, ScanAnalysisOptions};
    let tmp = tempfile::tempdir().unwrap();
    let rows: Vec<usize> = (0..7).collect();
    let scan = build_scan(tmp.path(), &rows, ProfileKind::P, Some(StopStatus::Success));
    // v asked for, u from the frozen plan (5).
    let options = ScanAnalysisOptions {
        curves: 5,
        levels: 21,
        lambda_c_mm: Some(0.25),
        overlay_line: Some(5),
        degree_v: Some(3),
        ..ScanAnalysisOptions::default()
    };
    let input = surfscan::input::read(&scan, &Default::default()).unwrap();
    let out = characterise_scan(&input, &options).unwrap();
    // The figures drawn on this thread leave no texts behind for the next report: a daemon
    // characterising scan after scan holds no memory for the ones before.
    assert_eq!(surfscan::report::render::text_cache::remembered(), (0, 0));
    assert_eq!(out.files.report_json, scan.join("report.json"));
    assert_eq!(out.lines_used, (0..7).collect::<Vec<u32>>());
    assert!(out.incomplete_lines.is_empty());
    // Bearing curves, height map and its 3D view, PSD, ACF, overlay (PNG and SVG each), and
    // the Rk construction of each of the 7 lines (an SVG: no `[report] line-png`).
    assert_eq!(out.files.plots.len(), 12 + 7);
    assert!(out.files.report_html.exists());
    for p in out.files.plots.iter().chain([&out.files.summary_csv]) {
        assert!(p.starts_with(&scan) && p.exists(), "{}", p.display());
    }
    assert!(out.files.model_x3p.as_ref().is_some_and(|p| p.exists()));
    let r = report(&scan);
    // The fit section describes the surface of the model sections: the 7 lines.
    assert_eq!(
        (r["fit"]["degree_u"].as_u64(), r["fit"]["degree_v"].as_u64()),
        (Some(5), Some(3))
    );
    assert_eq!(r["fit"]["poles_v"], 7);
    assert_eq!(r["fit"]["grid"]["rows"], 7);
    assert!(r["fit"]["max_residual_mm"].as_f64().unwrap() < 1e-9);
    assert!(
        r["fit"]["iges_files"].as_array().unwrap().is_empty(),
        "analyze writes no IGES"
    );
    let recipe = r["surface"]["recipe"].as_str().unwrap();
    assert!(recipe.contains("degree 5/3"), "{recipe}");
    assert_eq!(r["surface"]["bac_curves"].as_array().unwrap().len(), 5);
    assert_eq!(r["surface"]["bac"].as_array().unwrap().len(), 21);
    // The override wins over the recorded 0.8 mm, and the recipe says so.
    assert_eq!(r["recipe"]["lambda_c_mm"], 0.25);
    assert!(r["recipe"]["lambda_c_source"]
        .as_str()
        .unwrap()
        .contains("overriding"));
    let data = sur2_rows();
    let ours = analyze_line(
        &data[3],
        PITCH_X_MM,
        &Options {
            lambda_c_mm: 0.25,
            ..expected_options()
        },
    )
    .unwrap()
    .params;
    assert!((r["lines"][3]["Rq_um"].as_f64().unwrap() - ours.rq_um).abs() < 1e-12);
    // The overlay draws the requested line left out of a refit, against its measured heights.
    let overlay = std::fs::read_to_string(scan.join("overlay.svg")).unwrap();
    // Index 5 is the 6th line: people count from 1, the file index is beside it.
    assert!(
        overlay.contains("Line 6 (0005, ") && overlay.contains("left out"),
        "overlay does not draw index 5 left out"
    );
}

/// The check a test page runs once loaded: every image decoded, the rows of every table with
/// an id, and every error or console message, written into the DOM for `--dump-dom`.
const CHECK_HEAD: &str = "<script>window.__e=[];addEventListener('error',function(e){__e.push(String(e.message||(e.target&&e.target.tagName)||'error'))},true);['error','warn','log'].forEach(function(k){var o=console[k];console[k]=function(){__e.push(k+': '+[].join.call(arguments,' '));o.apply(console,arguments)}});</script>";
const CHECK_BODY: &str = "<script>addEventListener('load',function(){var t={};[].forEach.call(document.querySelectorAll('table[id]'),function(x){t[x.id]=x.rows.length});var r={errors:__e,images:[].map.call(document.images,function(i){return i.complete&&i.naturalWidth>0}),tables:t};var p=document.createElement('pre');p.id='surfscan-check';p.textContent=JSON.stringify(r);document.body.appendChild(p)});</script>";

#[test]
fn the_html_report_of_a_scan_renders_in_chromium_with_its_tables_and_plots() {
    use surfscan::scan::journal::{InterruptionRecord, QuarantineRecord};
    use surfscan::scan::station::Device;
    let tmp = tempfile::tempdir().unwrap();
    let rows: Vec<usize> = (0..8).collect();
    let scan = build_scan(tmp.path(), &rows, ProfileKind::P, None);
    // What happened during the scan, as the runner records it.
    let (mut journal, recovery) =
        Journal::open(&scan.join("journal.jsonl"), Arc::new(NoFaults)).unwrap();
    let t = Utc.with_ymd_and_hms(2026, 11, 30, 9, 45, 0).unwrap();
    // Line 6 (0005) found changed on a resume: moved aside, then traced again (attempt 2).
    let mut line6 = recovery
        .records
        .iter()
        .find_map(|r| match r {
            Record::Line(l) if l.id.index == 5 => Some(l.clone()),
            _ => None,
        })
        .unwrap();
    journal
        .append(&Record::Quarantine(QuarantineRecord {
            index: 5,
            expected_sha256: line6.csv_sha256.clone(),
            found_sha256: "00".repeat(32),
            moved_to: "quarantine/0005.csv".into(),
            reason: "line 6: its heights file has SHA-256 00…, the journal's line record <x>; moved aside, it is traced again".into(),
            time: Utc.with_ymd_and_hms(2026, 11, 30, 9, 50, 0).unwrap(),
        }))
        .unwrap();
    line6.id.attempt = 2;
    line6.time = Utc.with_ymd_and_hms(2026, 11, 30, 9, 55, 0).unwrap();
    journal.append(&Record::Line(line6)).unwrap();
    for (reason, device, line) in [
        (
            "instrument unplugged <USB>",
            Some(Device::Instrument),
            Some(3),
        ),
        (
            "resumed after a restart with 4 of 8 lines on disk",
            None,
            None,
        ),
    ] {
        journal
            .append(&Record::Interruption(InterruptionRecord {
                reason: reason.into(),
                device,
                line,
                time: t,
                peer: None,
                pause: None,
            }))
            .unwrap();
    }
    journal
        .append(&Record::Stop(StopRecord {
            status: StopStatus::Success,
            reason: "all lines traced".into(),
            cause: None,
            internal: false,
            time: Utc.with_ymd_and_hms(2026, 11, 30, 10, 17, 30).unwrap(),
        }))
        .unwrap();
    drop(journal);
    run_ok(&["analyze", scan.to_str().unwrap()]);
    // report.json carries the finish and the duration too: a complete scan finished when its
    // 8th line was read out (09:15:00 + 8 × 7.5 min = 10:15:00), not when its stop record was
    // written after the outputs (10:17:30).
    let r = report(&scan);
    // The recipe names the spike rule, what was done with the spikes and the verdict's threshold.
    assert!(r["recipe"]["spike_rule"]
        .as_str()
        .unwrap()
        .contains("10 x 1.4826 x MAD"));
    assert_eq!(r["recipe"]["outliers"], "flag");
    assert_eq!(r["recipe"]["holdout_threshold_sq"], 0.5);
    let t = &r["traceability"];
    assert_eq!(t["finished_at"], "2026-11-30T10:15:00+00:00");
    assert_eq!(t["duration_s"].as_f64(), Some(3600.0));
    let page = scan.join("report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    // The result first, the warnings that qualify it next, numbers for people, the
    // journal's events and the traceability.
    let at = |s: &str| {
        html.find(s)
            .unwrap_or_else(|| panic!("report.html lacks {s:?}"))
    };
    assert!(at("id=\"result\"") < at("id=\"warnings\""));
    assert!(at("id=\"warnings\"") < at("id=\"lines\""));
    assert!(html.contains("instrument unplugged &lt;USB&gt;"));
    assert!(
        html.contains("<td>4 <span class=\"muted\">(0003)</span></td>"),
        "line 4 of the event"
    );
    assert!(
        html.contains("<td>6 <span class=\"muted\">(0005)</span></td><td class=\"t\"></td><td class=\"t\">line 6: its heights file has SHA-256 00…, the journal&#39;s line record &lt;x&gt;; moved aside, it is traced again (now quarantine/0005.csv)</td>"),
        "the line moved aside, escaped, with where it went"
    );
    assert!(html.contains("traced on attempt 2 (re-traced)"));
    assert!(html.contains("SUR-2 brass &lt;B&amp;S&gt; #7"));
    assert!(
        html.contains("<td class=\"t\">1 h 00 min</td>"),
        "duration from the journal"
    );
    assert!(!html.contains("<script"), "the report runs no script");

    // As a browser shows it: the page as written logs nothing.
    let plain = surfscan_check_render(&page);
    assert!(plain.console.is_empty(), "console: {:?}", plain.console);
    assert!(plain.dom.contains("id=\"t-lines\""));

    // With the checker added (and the report's policy relaxed for that one inline script):
    // every image decodes and every table has its rows.
    let checked = tmp.path().join("checked.html");
    let with_check = html
        .replace(
            "default-src 'none';",
            "default-src 'none'; script-src 'unsafe-inline';",
        )
        .replacen("<head>", &format!("<head>{CHECK_HEAD}"), 1)
        .replacen("</body>", &format!("{CHECK_BODY}</body>"), 1);
    std::fs::write(&checked, with_check).unwrap();
    let r = surfscan_check_render(&checked);
    let tag = "<pre id=\"surfscan-check\">";
    let start = r.dom.find(tag).expect("the check ran") + tag.len();
    let end = start + r.dom[start..].find("</pre>").unwrap();
    let check: Value = serde_json::from_str(&r.dom[start..end].replace("&quot;", "\"")).unwrap();
    assert_eq!(check["errors"], json!([]), "{check}");
    let images = check["images"].as_array().unwrap();
    // Height map, bearing curves, overlay, one Rk construction per line, and beside the
    // areal parameters the PSD, the ACF and the 3D view.
    assert_eq!(images.len(), 6 + rows.len(), "{check}");
    let areal = &html[at("id=\"t-areal\"")..];
    let figures = &areal[areal
        .find("id=\"areal-figures\"")
        .expect("the areal figures follow the areal table")..];
    let figures = &figures[..figures.find("</div>").unwrap()];
    for title in [
        "Power spectral density",
        "Autocorrelation",
        "3D view of the measured surface",
    ] {
        assert!(
            figures.contains(&format!("<figcaption>{title}</figcaption><img")),
            "{title} is not beside the areal parameters"
        );
    }
    assert!(
        images.iter().all(|i| i == true),
        "an image did not decode: {check}"
    );
    let tables = &check["tables"];
    assert_eq!(
        tables["t-lines"],
        json!(1 + rows.len() + 2),
        "header, lines, mean, s.d."
    );
    assert_eq!(
        tables["t-events"],
        json!(5),
        "header, two interruptions, the line moved aside and its re-trace"
    );
    assert!(tables["t-traceability"].as_u64().unwrap() >= 10);
    assert!(tables["t-instrument"].as_u64().unwrap() > rows.len() as u64);
    assert!(tables["t-areal"].as_u64().unwrap() >= 10);
}

fn surfscan_check_render(page: &Path) -> crate::common::chromium::Rendered {
    crate::common::chromium::render(page)
}
