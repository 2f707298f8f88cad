//! X3P writer: digests against their published vectors, a round trip through our reader, the
//! file read by an independent reader (surfalize; the test fails when it is missing:
//! `bash .ci/run` (tests/python/requirements.txt in .venv/)), and `main.xml` validated by
//! xmllint against the official ISO 5436-2 schema (`tests/data/x3p/`) with its MD5 files
//! checked by `md5sum -c` ([`assert_valid_x3p`], used by every test that writes an X3P file).

use crate::common::{json_from, reference_script};
use std::path::Path;
use std::process::Command;
use surfscan::metrology::areal::HeightMap;
use surfscan::x3p::{crc32, md5, read_x3p, to_x3p, X3pMeta};

/// `z` as `rows` lines of `cols` points, 1.5 µm apart along x and 10 µm along y.
fn map(z: &[f64], rows: usize, cols: usize) -> HeightMap<'_> {
    HeightMap {
        heights_um: z,
        rows,
        cols,
        pitch_x_mm: 0.0015,
        pitch_y_mm: 0.01,
    }
}

/// Unpacks `file` with Python's zipfile (not our reader), validates `main.xml` against the
/// ISO 5436-2 schema with xmllint, checks `md5checksum.hex` with `md5sum -c` and the point
/// data's MD5 in `main.xml` against `md5sum` of the binary it links.
pub fn assert_valid_x3p(file: &Path) {
    let dir = tempfile::tempdir().unwrap();
    let o = crate::common::python()
        .args([
            "-c",
            "import sys, zipfile; zipfile.ZipFile(sys.argv[1]).extractall(sys.argv[2])",
        ])
        .arg(file)
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{} is not a zip archive Python can unpack: {}",
        file.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    crate::common::assert_validates(
        &dir.path().join("main.xml"),
        "tests/data/x3p/iso5436_2.xsd",
        &format!("ISO 5436-2 (the main.xml of {})", file.display()),
    );
    let o = Command::new("md5sum")
        .args(["-c", "md5checksum.hex"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{}: md5sum -c md5checksum.hex: {}{}",
        file.display(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let xml = std::fs::read_to_string(dir.path().join("main.xml")).unwrap();
    let link = xml
        .split("<PointDataLink>")
        .nth(1)
        .and_then(|s| s.split("</PointDataLink>").next())
        .unwrap();
    let o = Command::new("md5sum")
        .arg(dir.path().join(link))
        .output()
        .unwrap();
    let sum = String::from_utf8_lossy(&o.stdout)[..32].to_string();
    assert!(
        xml.contains(&format!(
            "<MD5ChecksumPointData>{sum}</MD5ChecksumPointData>"
        )),
        "{}: {link} has MD5 {sum}, main.xml says otherwise",
        file.display()
    );
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|v| format!("{v:02x}")).collect()
}

#[test]
fn digests_match_published_vectors() {
    // RFC 1321 appendix A.5.
    assert_eq!(hex(&md5(b"")), "d41d8cd98f00b204e9800998ecf8427e");
    assert_eq!(hex(&md5(b"abc")), "900150983cd24fb0d6963f7d28e17f72");
    assert_eq!(
        hex(&md5(
            b"12345678901234567890123456789012345678901234567890123456789012345678901234567890"
        )),
        "57edf4a22be3c955ac49da2e2107b67a"
    );
    // The CRC-32 check value.
    assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
}

fn grid() -> (Vec<f64>, usize, usize) {
    let (rows, cols) = (5usize, 7usize);
    let z = (0..rows * cols)
        .map(|k| (k as f64 * 0.37).sin() * 1.5 - 0.25)
        .collect();
    (z, rows, cols)
}

#[test]
fn x3p_round_trips_and_surfalize_reads_it() {
    let (z, rows, cols) = grid();
    let meta = X3pMeta {
        date: "2026-11-30T09:15:00.123456789Z".into(),
        calibration_date: "2026-03-14".into(),
        comment: "measured grid <test> & more".to_string(),
        ..X3pMeta::default()
    };
    let bytes = to_x3p(&map(&z, rows, cols), (0.0, 0.0), &meta).unwrap();
    let back = read_x3p(&bytes).unwrap();
    assert_eq!((back.rows, back.cols), (rows, cols));
    // Record2 comes back unescaped; empty fields were written as "not available".
    assert_eq!(back.meta.comment, "measured grid <test> & more");
    assert_eq!(back.meta.creator, "");
    assert!((back.pitch_x_mm - 0.0015).abs() < 1e-15);
    assert!((back.pitch_y_mm - 0.01).abs() < 1e-15);
    for (a, b) in back.heights_um.iter().zip(&z) {
        assert!((a - b).abs() < 1e-12);
    }
    // A flipped byte in the data is caught by the MD5.
    let mut bad = bytes.clone();
    let at = bad.windows(4).position(|w| w == b"PK\x03\x04").unwrap() + 200;
    bad[at] ^= 0xff;
    assert!(read_x3p(&bad).is_err());

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("grid.x3p");
    std::fs::write(&path, &bytes).unwrap();
    let v = json_from(reference_script("metrology_x3p_read.py").arg(&path));
    assert_eq!(v["rows"], rows);
    assert_eq!(v["cols"], cols);
    assert!((v["step_x_um"].as_f64().unwrap() - 1.5).abs() < 1e-9);
    assert!((v["step_y_um"].as_f64().unwrap() - 10.0).abs() < 1e-9);
    let h = heights_um(&v);
    for (a, b) in h.iter().zip(&z) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
}

#[test]
fn x3p_files_of_other_software_are_read() {
    // Written by surfalize and by a script that follows ISO 25178-72 with Python's zipfile
    // (deflated entries, int16 with z scaling, a validity mask, a DataList profile); the
    // script reports what it put in.
    let dir = tempfile::tempdir().unwrap();
    let files = json_from(reference_script("x3p_write.py").arg(dir.path()));
    let files = files.as_object().unwrap();
    assert_eq!(files.len(), 4);
    for (name, want) in files {
        let bytes = std::fs::read(dir.path().join(name)).unwrap();
        let got = read_x3p(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(got.rows as u64, want["rows"].as_u64().unwrap(), "{name}");
        assert_eq!(got.cols as u64, want["cols"].as_u64().unwrap(), "{name}");
        let rel = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
        assert!(
            rel(got.pitch_x_mm, want["pitch_x_mm"].as_f64().unwrap()),
            "{name}"
        );
        assert!(
            rel(got.pitch_y_mm, want["pitch_y_mm"].as_f64().unwrap()),
            "{name}"
        );
        let heights = want["heights_um"].as_array().unwrap();
        assert_eq!(got.heights_um.len(), heights.len(), "{name}");
        let mut invalid = 0;
        for (k, (g, w)) in got.heights_um.iter().zip(heights).enumerate() {
            match w.as_f64() {
                None => {
                    invalid += 1;
                    assert!(g.is_nan(), "{name} point {k}: {g}, expected invalid");
                }
                Some(w) => assert!(
                    (g - w).abs() <= 1e-9 * w.abs().max(1.0),
                    "{name} point {k}: {g} vs {w}"
                ),
            }
        }
        assert_eq!(got.invalid_points, invalid, "{name}");
    }
    let int16 = read_x3p(&std::fs::read(dir.path().join("int16-valid.x3p")).unwrap()).unwrap();
    assert_eq!(int16.invalid_points, 1);
    assert_eq!(int16.meta.creator, "A. Person & Co");
    assert_eq!(int16.meta.manufacturer, "Example Optics");
    assert_eq!(int16.meta.serial, "SN 42");
    assert_eq!(int16.meta.calibration_date, "2024-01-31T00:00:00");
    assert_eq!(int16.meta.probe, "50x objective");
    let profile =
        read_x3p(&std::fs::read(dir.path().join("profile-datalist.x3p")).unwrap()).unwrap();
    assert_eq!(profile.feature_type, "PRF");
}

#[test]
fn damaged_or_unsupported_x3p_files_are_named_clearly() {
    let (z, rows, cols) = grid();
    let bytes = to_x3p(&map(&z, rows, cols), (0.0, 0.0), &X3pMeta::default()).unwrap();
    let e = read_x3p(&bytes[..bytes.len() / 2]).unwrap_err().to_string();
    assert!(e.contains("not a readable X3P file"), "{e}");
    let e = read_x3p(b"x_mm,z_um\n0,1\n").unwrap_err().to_string();
    assert!(e.contains("not a zip archive"), "{e}");
}

#[test]
fn calibration_date_and_manufacturer_are_what_the_caller_gives() {
    let (z, rows, cols) = grid();
    let meta = X3pMeta {
        date: "2026-11-30T09:15:00+00:00".into(),
        calibration_date: "2026-03-14".into(),
        manufacturer: "Mitutoyo".into(),
        model: "SJ-210".into(),
        serial: "123456".into(),
        probe: "SJ-210 stylus, tip radius 2 µm".into(),
        ..X3pMeta::default()
    };
    let back = read_x3p(&to_x3p(&map(&z, rows, cols), (0.0, 0.0), &meta).unwrap()).unwrap();
    // The calibration date, not the scan's start; a plain date becomes an xsd:dateTime.
    assert_eq!(back.meta.calibration_date, "2026-03-14T00:00:00");
    assert_eq!(back.meta.date, "2026-11-30T09:15:00+00:00");
    assert_eq!(back.meta.manufacturer, "Mitutoyo");
    assert_eq!(back.meta.serial, "123456");
    assert_eq!(back.meta.probe, "SJ-210 stylus, tip radius 2 µm");
    // Unknown: no CalibrationDate at all (no made-up date a reader could take for a real
    // one); ISO 5436-2 requires one in Record2, so Record2 is left out.
    let unknown = X3pMeta {
        calibration_date: String::new(),
        ..meta
    };
    let bytes = to_x3p(&map(&z, rows, cols), (0.0, 0.0), &unknown).unwrap();
    assert!(!main_xml(&bytes).contains("CalibrationDate"));
    assert!(!main_xml(&bytes).contains("Record2"));
    assert_eq!(read_x3p(&bytes).unwrap().meta, X3pMeta::default());
}

#[test]
fn every_x3p_written_validates_against_iso_5436_2() {
    // With Record2 (escaped text, a fractional-second date, a plain calibration date), without
    // it, and a grid whose first line sits at negative y: each main.xml validates, each MD5
    // file checks.
    let (z, rows, cols) = grid();
    let full = X3pMeta {
        date: "2026-11-30T09:15:00.123456789+00:00".into(),
        calibration_date: "2026-03-14".into(),
        creator: "A. Person & <Co>".into(),
        manufacturer: "Mitutoyo".into(),
        model: "SJ-210".into(),
        serial: "".into(),
        version: "1.00".into(),
        probe: "SJ-210 stylus, tip radius 2 µm".into(),
        comment: "measured heights \"as traced\"".into(),
    };
    let dir = tempfile::tempdir().unwrap();
    for (name, meta, origin_mm) in [
        ("full.x3p", full.clone(), (0.0, 0.0)),
        ("bare.x3p", X3pMeta::default(), (0.0015, -20.0)),
        (
            "undated.x3p",
            X3pMeta {
                calibration_date: String::new(),
                ..full
            },
            (-1.5, 12.34),
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(
            &path,
            to_x3p(&map(&z, rows, cols), origin_mm, &meta).unwrap(),
        )
        .unwrap();
        assert_valid_x3p(&path);
    }
    // The check catches a file the schema refuses: Record2 without its CalibrationDate (what
    // this writer wrote before).
    let bytes = to_x3p(&map(&z, rows, cols), (0.0, 0.0), &X3pMeta::default()).unwrap();
    let xml = main_xml(&bytes) + "</p:ISO5436_2>\n";
    let broken = crate::common::edited(
        &xml,
        "<Record3>",
        "<Record2><Date>2026-11-30T09:15:00Z</Date><Instrument><Manufacturer>M</Manufacturer><Model>S</Model><Serial>1</Serial><Version>1</Version></Instrument><ProbingSystem><Type>Contacting</Type><Identification>x</Identification></ProbingSystem></Record2><Record3>",
    );
    let path = dir.path().join("main.xml");
    std::fs::write(&path, broken).unwrap();
    let o = Command::new("xmllint")
        .args(["--noout", "--schema"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/x3p/iso5436_2.xsd"))
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        !o.status.success() && String::from_utf8_lossy(&o.stderr).contains("CalibrationDate"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// main.xml of an archive we wrote (stored, so its text is in the bytes as it is).
fn main_xml(bytes: &[u8]) -> String {
    let text = String::from_utf8_lossy(bytes);
    let start = text.find("<?xml").unwrap();
    let end = text.find("</p:ISO5436_2>").unwrap();
    text[start..end].to_string()
}

#[test]
fn axes_carry_the_first_point_s_x_the_machine_y_of_the_first_line_and_exact_pitches() {
    // 31 lines stepped 0.01 mm from y = 12.34 mm: their mean pitch carries float noise
    // (12.64 − 12.34 is not 0.3 in binary), which the file must not.
    let (z, _, cols) = grid();
    let y: Vec<f64> = (0..31).map(|k| 12.34 + k as f64 * 0.01).collect();
    let (pitch_y_mm, _) = surfscan::grid::mean_pitch_y(&y);
    assert_ne!(pitch_y_mm, 0.01, "the test needs a noisy mean pitch");
    let z: Vec<f64> = (0..31).flat_map(|_| z[..cols].to_vec()).collect();
    let bytes = to_x3p(
        &HeightMap {
            heights_um: &z,
            rows: 31,
            cols,
            pitch_x_mm: 0.0015,
            pitch_y_mm,
        },
        (0.0015, y[0]),
        &X3pMeta::default(),
    )
    .unwrap();
    let xml = main_xml(&bytes);
    assert!(xml.contains("<CX><AxisType>I</AxisType><DataType>D</DataType><Increment>1.5e-6</Increment><Offset>1.5e-6</Offset></CX>"), "{xml}");
    assert!(xml.contains("<CY><AxisType>I</AxisType><DataType>D</DataType><Increment>1e-5</Increment><Offset>1.234e-2</Offset></CY>"), "{xml}");
    let back = read_x3p(&bytes).unwrap();
    assert!(
        (back.offset_y_mm - 12.34).abs() < 1e-12 && (back.offset_x_mm - 0.0015).abs() < 1e-15,
        "{} {}",
        back.offset_x_mm,
        back.offset_y_mm
    );
    assert!((back.pitch_y_mm - 0.01).abs() < 1e-15);
    // A non-finite first x or y is refused, not written.
    for origin_mm in [(0.0, f64::NAN), (f64::INFINITY, 0.0)] {
        assert!(to_x3p(&map(&z, 31, cols), origin_mm, &X3pMeta::default()).is_err());
    }
}

fn sur_2_csv() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/sur-2.grid.csv")
}

/// The bundled sur-2 grid's heights, lines and points per line.
fn sur_2() -> (Vec<f64>, usize, usize) {
    let text = std::fs::read_to_string(sur_2_csv()).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .collect();
    let z = rows.iter().flatten().copied().collect();
    (z, rows.len(), rows[0].len())
}

#[test]
fn analyze_reads_an_x3p_as_the_same_grid_as_its_csv() {
    // The bundled sur-2 grid as CSV and as X3P: the lines analyze reports from the X3P are
    // the CSV's, with the same numbers.
    let csv = sur_2_csv();
    let (z, rows, cols) = sur_2();
    let dir = tempfile::tempdir().unwrap();
    let x3p = dir.path().join("sur-2.x3p");
    std::fs::write(
        &x3p,
        to_x3p(
            &HeightMap {
                heights_um: &z,
                rows,
                cols,
                pitch_x_mm: 0.003484,
                pitch_y_mm: 0.010452,
            },
            (0.25, -20.0),
            &X3pMeta::default(),
        )
        .unwrap(),
    )
    .unwrap();
    let run = |input: &std::path::Path, out: &str, extra: &[&str]| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .arg("analyze")
            .arg(input)
            .args(["--out", dir.path().join(out).to_str().unwrap()])
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(
            &std::fs::read(dir.path().join(out).join("report.json")).unwrap(),
        )
        .unwrap();
        (r, String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let (from_csv, _) = run(
        &csv,
        "csv",
        &["--pitch-x", "0.003484", "--pitch-y", "0.010452"],
    );
    let (from_x3p, _) = run(&x3p, "x3p", &[]);
    assert_eq!(from_x3p["kind"], "x3p");
    assert_eq!(from_x3p["lines"].as_array().unwrap().len(), rows);
    for (a, b) in from_csv["lines"]
        .as_array()
        .unwrap()
        .iter()
        .zip(from_x3p["lines"].as_array().unwrap())
    {
        // Heights go through metres in the file: equal to rounding.
        let (ra, rb) = (a["Ra_um"].as_f64().unwrap(), b["Ra_um"].as_f64().unwrap());
        assert!((ra - rb).abs() <= 1e-12 * ra, "{ra} vs {rb}");
    }
    assert!(std::fs::metadata(dir.path().join("x3p/heightmap.png")).is_ok());
    // The file's offsets are kept: report.json gives x's, and the grid's X3P and the model's
    // sampled on its points start where the input did (x and y).
    assert_eq!(
        (&from_x3p["x0_mm"], &from_csv["x0_mm"]),
        (&0.25.into(), &0.0.into())
    );
    for f in ["measured", "model"] {
        let x = read_x3p(&std::fs::read(dir.path().join(format!("x3p/{f}.x3p"))).unwrap());
        let x = x.unwrap();
        assert_eq!((x.offset_x_mm, x.offset_y_mm), (0.25, -20.0), "{f}.x3p");
    }
}

#[test]
fn analyze_leaves_out_lines_with_invalid_points_of_a_foreign_x3p() {
    let dir = tempfile::tempdir().unwrap();
    json_from(reference_script("x3p_write.py").arg(dir.path()));
    // 5 lines × 200 points at 2 µm, NaN on lines 2 and 5: three lines characterised.
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(dir.path().join("surfalize-f-nan.x3p"))
        .args([
            "--lc",
            "0.08",
            "--out",
            dir.path().join("r").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    // Made from 3 of the file's 5 lines: partial, exit 3, every output written.
    assert_eq!(o.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("lines 2, 5 hold them and were left out")
            && stderr.contains("it is made from 3 of 5 lines"),
        "{stderr}"
    );
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("r/report.json")).unwrap()).unwrap();
    let idx: Vec<u64> = r["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["index"].as_u64().unwrap())
        .collect();
    assert_eq!(idx, vec![0, 2, 3]);
}

/// `tests/python/x3p_profile.py` (x3pio, a reader and writer independent of ours) with `args`;
/// its JSON output when it prints any.
fn x3pio(args: &[&std::ffi::OsStr]) -> Option<serde_json::Value> {
    let o = reference_script("x3p_profile.py")
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "x3pio failed on {args:?} (run `bash .ci/run`, which installs tests/python/requirements.txt into .venv/):\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    (!o.stdout.is_empty()).then(|| serde_json::from_slice(&o.stdout).unwrap())
}

/// A height read back from f64 metres: the one written to a few ulps (µm → m → µm rounds twice).
fn assert_same_heights(got: &[f64], want: &[f64], reader: &str) {
    assert_eq!(got.len(), want.len(), "{reader}");
    for (a, b) in got.iter().zip(want) {
        assert!(
            (a - b).abs() <= 4.0 * f64::EPSILON * b.abs(),
            "{reader}: {a} read back for {b}"
        );
    }
}

#[test]
fn a_one_line_grid_is_written_as_a_profile_that_an_independent_reader_reads() {
    let z = crate::common::mitutoyo_r_profile();
    let bytes = to_x3p(&map(&z, 1, z.len()), (0.0, 0.0), &X3pMeta::default()).unwrap();
    let xml = main_xml(&bytes);
    assert!(xml.contains("<FeatureType>PRF</FeatureType>"), "{xml}");
    assert!(
        xml.contains("<SizeX>6664</SizeX><SizeY>1</SizeY><SizeZ>1</SizeZ>"),
        "{xml}"
    );
    // Two lines or more stay a surface.
    let two = to_x3p(&map(&z[..20], 2, 10), (0.0, 0.0), &X3pMeta::default()).unwrap();
    assert!(main_xml(&two).contains("<FeatureType>SUR</FeatureType>"));

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("profile.x3p");
    std::fs::write(&file, &bytes).unwrap();
    assert_valid_x3p(&file);
    let back = read_x3p(&bytes).unwrap();
    assert_eq!(
        (back.feature_type.as_str(), back.rows, back.cols),
        ("PRF", 1, 6664)
    );
    assert!((back.pitch_x_mm - 0.0015).abs() < 1e-15);
    assert_same_heights(&back.heights_um, &z, "our reader");
    let v = x3pio(&["read".as_ref(), file.as_os_str()]).unwrap();
    assert_eq!(
        (v["kind"].as_str(), v["points"].as_u64()),
        (Some("Profile"), Some(6664))
    );
    assert!(
        (v["step_x_um"].as_f64().unwrap() - 1.5).abs() < 1e-9,
        "{}",
        v["step_x_um"]
    );
    let h = heights_um(&v);
    assert_same_heights(&h, &z, "x3pio");
}

/// Every number of `v` with its path (`a/b/0`), in document order.
fn numbers(v: &serde_json::Value, path: String, out: &mut Vec<(String, f64)>) {
    match v {
        serde_json::Value::Number(n) => out.push((path, n.as_f64().unwrap())),
        serde_json::Value::Array(a) => a
            .iter()
            .enumerate()
            .for_each(|(i, x)| numbers(x, format!("{path}/{i}"), out)),
        serde_json::Value::Object(m) => m
            .iter()
            .for_each(|(k, x)| numbers(x, format!("{path}/{k}"), out)),
        _ => {}
    }
}

#[test]
fn a_profile_read_from_a_profile_x3p_is_the_line_of_its_csv() {
    // The Mitutoyo export analysed as the instrument evaluated it (an R profile, λc 2.5 mm),
    // then its own measured.x3p, then a PRF file x3pio writes of the same CSV: the one line
    // each gives has every number of the CSV's line to 1e-12, the SJ reading's Rpk at the
    // printed 2.912 µm.
    let csv = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/real/mitutoyo_surftest_R.x_mm_z_um.csv");
    let dir = tempfile::tempdir().unwrap();
    let run = |input: &Path, out: &str| {
        let out = dir.path().join(out);
        let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .arg("analyze")
            .arg(input)
            .args(["--no-filter", "--lc", "2.5", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
        assert_eq!(r["kind"], "profile", "{input:?}");
        assert_eq!(r["lines"].as_array().unwrap().len(), 1, "{input:?}");
        r
    };
    let from_csv = run(&csv, "csv");
    let ours = dir.path().join("csv/measured.x3p");
    assert_valid_x3p(&ours);
    assert!(main_xml(&std::fs::read(&ours).unwrap()).contains("<FeatureType>PRF</FeatureType>"));
    // The CSV's x starts at 0.0015 mm, and so does the file's, for our reader and x3pio's.
    let back = read_x3p(&std::fs::read(&ours).unwrap()).unwrap();
    assert_eq!((back.offset_x_mm, back.offset_y_mm), (0.0015, 0.0));
    let v = x3pio(&["read".as_ref(), ours.as_os_str()]).unwrap();
    assert!(
        (v["first_x_um"].as_f64().unwrap() - 1.5).abs() < 1e-9,
        "{v}"
    );
    let theirs = dir.path().join("x3pio.x3p");
    x3pio(&["write".as_ref(), csv.as_os_str(), theirs.as_os_str()]);
    let mut want = Vec::new();
    numbers(&from_csv["lines"][0], String::new(), &mut want);
    assert!(want.len() > 200, "{} numbers", want.len());
    for (input, out) in [(&ours, "ours"), (&theirs, "theirs")] {
        let r = run(input, out);
        let mut got = Vec::new();
        numbers(&r["lines"][0], String::new(), &mut got);
        assert_eq!(got.len(), want.len(), "{out}");
        for ((p, a), (q, b)) in got.iter().zip(&want) {
            assert_eq!(p, q, "{out}");
            assert!(
                (a - b).abs() <= 1e-12 * b.abs().max(1e-3),
                "{out} {p}: {a}, the CSV's {b}"
            );
        }
        let rpk = r["lines"][0]["material_ratio_sj_series"]["Rpk_um"]
            .as_f64()
            .unwrap();
        assert!((rpk - 2.912).abs() <= 1e-3, "{out}: SJ Rpk {rpk}");
    }
}

/// The `heights_um` array of a reader's JSON output.
fn heights_um(v: &serde_json::Value) -> Vec<f64> {
    let h = v["heights_um"].as_array().unwrap();
    h.iter().map(|x| x.as_f64().unwrap()).collect()
}

/// Every position (a number after `x =`, `y =`, `(x`, or after `…`/`→` in such a range) that
/// `b` names where `a` names the same words is `a`'s plus `offset_mm` (x, y), to the 4
/// decimals positions are printed with (and `slack_mm`); every other number is `a`'s (to the last printed
/// digit), every word the same. Returns how many x and y positions were compared.
fn positions_moved_by(a: &str, b: &str, offset_mm: [f64; 2], slack_mm: [f64; 2]) -> [usize; 2] {
    let number = |t: &str| -> Option<f64> {
        let t = t.trim_start_matches('(');
        t.trim_end_matches([',', ';', ':', ')']).parse().ok()
    };
    let (ta, tb): (Vec<&str>, Vec<&str>) = (
        a.split_whitespace().collect(),
        b.split_whitespace().collect(),
    );
    assert_eq!(ta.len(), tb.len(), "{a}\n{b}");
    let (mut axis, mut range, mut counts) = (None, None, [0, 0]);
    for (wa, wb) in ta.iter().zip(&tb) {
        let word = wa.trim_start_matches('(');
        (axis, range) = match (word, number(wa), number(wb)) {
            ("x" | "y", ..) => (Some(usize::from(word == "y")), None),
            ("=", ..) if axis.is_some() => (axis, None),
            ("…" | "→", ..) if range.is_some() => (range, None),
            (_, Some(va), Some(vb)) => match axis {
                Some(k) => {
                    assert!(
                        (vb - va - offset_mm[k]).abs() <= 1.01e-4 + slack_mm[k],
                        "{} {va} → {vb}, not moved by {} mm in\n{a}\n{b}",
                        ["x", "y"][k],
                        offset_mm[k]
                    );
                    counts[k] += 1;
                    (None, (!wa.ends_with([',', ';', ':', ')'])).then_some(k))
                }
                None => {
                    assert!(
                        (vb - va).abs() <= 1e-3 * va.abs().max(1e-3),
                        "{wa} → {wb} in\n{a}\n{b}"
                    );
                    (None, None)
                }
            },
            _ => {
                assert_eq!(wa, wb, "in\n{a}\n{b}");
                (None, None)
            }
        };
    }
    counts
}

/// An X3P file places its data where the machine measured them (CX and CY offsets): the
/// positions `analyze` names are in its coordinates. Two grids, each written as X3P twice:
/// the sur-2 grid (spikes, the model's overshoot) at offsets (0, 0) and (0.25, −20) mm, and
/// 31 uncorrelated lines of 400 points with a 100 µm spike in line 13 (a spike, a fold of the
/// surface and of its control net, an overshoot) at (0, −20) and (0.25, −20) mm: every x
/// named in the warnings on stderr, in report.json and in report.html of the second file must
/// be the first's + 0.25 mm and every y the first's + the y offset between them (the offsets
/// written into the files). The folding grid keeps its y offset, and the y of its model's
/// places may be anywhere on the grid: all 121 of its iso-curves fold by the same amount to
/// rounding, and which is the worst (whose y is named) changes with the rounding of x moved.
/// The figures move with them: the overlay's and the height map's x axes, the height map's y.
#[test]
fn analyze_names_positions_in_the_x3p_files_coordinates() {
    use crate::model_honesty::{uncorrelated_grid, COLS, PX, PY, ROWS};
    let (z, rows, cols) = sur_2();
    let sur_2 = map_of(&z, rows, cols, 0.003484, 0.010452);
    let kinds = ["spike in line", "model overshoot"];
    positions_move(&sur_2, &[], [[0.0, 0.0], [0.25, -20.0]], &kinds, 0.0);
    let mut z = uncorrelated_grid(11, COLS);
    z[12 * COLS + 233] += 100.0;
    let folding = map_of(&z, ROWS, COLS, PX, PY);
    let kinds = [
        "spike in line",
        "model fold",
        "control net fold",
        "model overshoot",
    ];
    positions_move(
        &folding,
        &["--lc", "0.08"],
        [[0.0, -20.0], [0.25, -20.0]],
        &kinds,
        (ROWS - 1) as f64 * PY,
    );
}

fn map_of(z: &[f64], rows: usize, cols: usize, pitch_x_mm: f64, pitch_y_mm: f64) -> HeightMap<'_> {
    HeightMap {
        heights_um: z,
        rows,
        cols,
        pitch_x_mm,
        pitch_y_mm,
    }
}

/// `map` written as X3P at each of `origins` and analyzed (with `extra`): the positions the
/// second names are the first's moved by the difference of the origins, and every kind of
/// warning of `kinds` names some.
fn positions_move(
    map: &HeightMap<'_>,
    extra: &[&str],
    origins: [[f64; 2]; 2],
    kinds: &[&str],
    slack_y_mm: f64,
) {
    let slack = [0.0, slack_y_mm];
    let dir = tempfile::tempdir().unwrap();
    let offset_mm = [origins[1][0] - origins[0][0], origins[1][1] - origins[0][1]];
    let run = |name: &str, origin: [f64; 2]| {
        let x3p = dir.path().join(format!("{name}.x3p"));
        std::fs::write(
            &x3p,
            to_x3p(map, (origin[0], origin[1]), &X3pMeta::default()).unwrap(),
        )
        .unwrap();
        let out = dir.path().join(name);
        let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .arg("analyze")
            .arg(&x3p)
            .arg("--out")
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(
            o.status.code().is_some_and(|c| c == 0 || c == 3),
            "{stderr}"
        );
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
        let html = std::fs::read_to_string(out.join("report.html")).unwrap();
        (report, stderr, html)
    };
    let (a, a_err, a_html) = run("first", origins[0]);
    let (b, b_err, b_html) = run("second", origins[1]);
    let warnings = |r: &serde_json::Value| -> Vec<String> {
        r["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w.as_str().unwrap().to_string())
            .collect()
    };
    let (wa, wb) = (warnings(&a), warnings(&b));
    // Every kind of position the grid gives rise to is named.
    for kind in kinds {
        assert!(
            wb.iter().any(|w| w.starts_with(kind)),
            "no {kind:?} in {wb:#?}"
        );
    }
    // report.json's warnings, the same on stderr, and in report.html's warnings.
    let in_html = |h: &str| {
        let from = h.find("id=\"warnings\"").unwrap();
        let section = &h[from..from + h[from..].find("<h2").unwrap_or(h.len() - from)];
        let mut text = String::new();
        let mut tag = false;
        for c in section.chars() {
            match c {
                '<' => (tag, text) = (true, text + " "),
                '>' => tag = false,
                c if !tag => text.push(c),
                _ => {}
            }
        }
        text.replace("&#39;", "'")
            .replace("&quot;", "\"")
            .replace("&amp;", "&")
    };
    let on_stderr = |s: &str| -> String {
        s.lines()
            .filter(|l| l.starts_with("surfscan: warning: "))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let mut named = [0, 0];
    for (x, y) in [
        (wa.join("\n"), wb.join("\n")),
        (on_stderr(&a_err), on_stderr(&b_err)),
        (in_html(&a_html), in_html(&b_html)),
    ] {
        let [nx, ny] = positions_moved_by(&x, &y, offset_mm, slack);
        assert!(nx >= 5 && ny >= 2, "{nx} x and {ny} y positions in\n{y}");
        named = [named[0] + nx, named[1] + ny];
    }
    // report.json's numbers, unrounded: the spikes' x, the model's checks, the lines' y.
    // Two runs' arrays, item by item.
    fn pairs<'v>(
        a: &'v serde_json::Value,
        b: &'v serde_json::Value,
    ) -> impl Iterator<Item = (&'v serde_json::Value, &'v serde_json::Value)> {
        a.as_array().unwrap().iter().zip(b.as_array().unwrap())
    }
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    let moved = |va: &serde_json::Value, vb: &serde_json::Value, k: usize, tol: f64| {
        assert!((f(vb) - f(va) - offset_mm[k]).abs() <= tol, "{va} → {vb}");
    };
    let (sa, sb) = (&a["outliers"]["spikes"], &b["outliers"]["spikes"]);
    assert!(!sb.as_array().unwrap().is_empty());
    for (s, t) in pairs(sa, sb) {
        moved(&s["x_mm"], &t["x_mm"], 0, 1e-12);
    }
    for (la, lb) in pairs(&a["lines"], &b["lines"]) {
        moved(&la["y_mm"], &lb["y_mm"], 1, 1e-12);
    }
    // The model is fitted to the same heights: its checks name the same places, moved (to
    // 1 nm: the fit at y −20 mm rounds differently).
    let (ca, cb) = (&a["model_checks"], &b["model_checks"]);
    for at in ["model_max_at_mm", "model_min_at_mm"] {
        for k in 0..2 {
            moved(
                &ca["height_range"][at][k],
                &cb["height_range"][at][k],
                k,
                1e-6 + slack[k],
            );
        }
    }
    for (fa, fb) in pairs(&ca["iso_curves"], &cb["iso_curves"]) {
        let along = usize::from(fa["direction"] == "v");
        for k in 0..2 {
            moved(
                &fa["range_mm"][k],
                &fb["range_mm"][k],
                along,
                1e-6 + slack[along],
            );
        }
        moved(
            &fa["at_mm"],
            &fb["at_mm"],
            1 - along,
            1e-6 + slack[1 - along],
        );
    }
    for (na, nb) in pairs(&ca["net"], &cb["net"]) {
        let along = usize::from(na["direction"] == "v");
        moved(&na["from_mm"], &nb["from_mm"], along, 1e-6 + slack[along]);
        moved(&na["to_mm"], &nb["to_mm"], along, 1e-6 + slack[along]);
    }
    let folds = |k: &str| !cb[k].as_array().unwrap().is_empty();
    assert_eq!(
        kinds.contains(&"model fold"),
        folds("iso_curves") && folds("net")
    );
    // The report says which origin its positions use (a model that folds has no model.x3p:
    // `analyze_reads_an_x3p_as_the_same_grid_as_its_csv` checks it keeps the offsets).
    let origin = "each line's first point at x = 0.2500 mm (the file's x offset)";
    assert!(
        b["positions"].as_str().unwrap().contains(origin),
        "{}",
        b["positions"]
    );
    assert!(b_html.replace("&#39;", "'").contains(origin));
    // The figures' x axes: the overlay's (and its residual panel's) and the height map's;
    // the height map's y axis.
    let figure = |run: &str, svg: &str| std::fs::read_to_string(dir.path().join(run).join(svg));
    for svg in ["overlay.svg", "heightmap.svg"] {
        let (a, b) = (
            figure("first", svg).unwrap(),
            figure("second", svg).unwrap(),
        );
        x_axes_moved(&a, &b, offset_mm[0]);
    }
    let (a, b) = (
        figure("first", "heightmap.svg"),
        figure("second", "heightmap.svg"),
    );
    map_y_axis_moved(&a.unwrap(), &b.unwrap(), offset_mm[1]);
    // The 3D view's labels: its nearest corner (the first point) and the ends of its x and y
    // edges, in the file's coordinates, to the 4 significant digits they are printed with.
    let (a, b) = (
        view_labels(&figure("first", "surface3d.svg").unwrap()),
        view_labels(&figure("second", "surface3d.svg").unwrap()),
    );
    for (k, moved) in [0, 1, 0, 1].into_iter().enumerate() {
        let want = a[k] + offset_mm[moved];
        assert!(
            (b[k] - want).abs() <= 0.01,
            "{b:?} against {a:?} + {offset_mm:?}"
        );
    }
}

/// The 3D view's corner label ("x, y, z µm") and its edges' ("x … mm", "y … mm"), as
/// [corner x, corner y, x edge's end, y edge's end].
fn view_labels(svg: &str) -> [f64; 4] {
    let texts: Vec<&str> = (svg.split("<text ").skip(1))
        .filter_map(|t| Some(t.split('>').nth(1)?.split('<').next()?.trim()))
        .collect();
    let number = |s: &str| s.trim().parse::<f64>().unwrap();
    let edge = |axis: &str| {
        let t = texts
            .iter()
            .find(|t| t.starts_with(axis) && t.ends_with(" mm"));
        number(&t.unwrap()[2..t.unwrap().len() - 3])
    };
    let corner: Vec<f64> = (texts.iter().find(|t| t.matches(", ").count() == 2))
        .unwrap()
        .split(", ")
        .take(2)
        .map(number)
        .collect();
    [corner[0], corner[1], edge("x "), edge("y ")]
}

#[test]
fn the_assessed_profile_is_drawn_where_its_evaluation_length_lies_on_the_line() {
    // 1067 points at 2.5 µm, λc 0.8 mm: L/λc = 3.33, the central 3 × 320 points evaluated,
    // (1067 − 960) / 2 = 53 left out before them. The same lines cropped to those 960 points
    // (L/λc = 2.997, within 1 % of 3: all evaluated from the first): the full lines' profile
    // axis is the cropped one's moved by 53 × 0.0025 = 0.1325 mm.
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/demo.grid.csv"),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let profile = |name: &str, from: usize, to: usize| {
        let lines: Vec<String> = (text.lines().take(3))
            .map(|l| l.split(',').collect::<Vec<_>>()[from..to].join(","))
            .collect();
        let csv = dir.path().join(format!("{name}.csv"));
        std::fs::write(&csv, lines.join("\n")).unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .arg("analyze")
            .arg(&csv)
            .args([
                "--pitch-x",
                "0.0025",
                "--pitch-y",
                "0.05",
                "--lc",
                "0.8",
                "--out",
            ])
            .arg(dir.path().join(name))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let svg = std::fs::read_to_string(dir.path().join(name).join("rk/0000.svg")).unwrap();
        // The assessed profile, drawn before the Rk construction.
        svg[..svg.find("height c (µm)").unwrap()].to_string()
    };
    x_axes_moved(
        &profile("cropped", 53, 1013),
        &profile("full", 0, 1067),
        0.1325,
    );
}

/// The x axes of two drawings of one figure, `b`'s data `offset_mm` further along x: the
/// pixel of each of `b`'s tick labels is where `a`'s ticks put its value − `offset_mm`
/// (linear between `a`'s first and last tick of the same axis; to the pixel, as SVG rounds).
fn x_axes_moved(a: &str, b: &str, offset_mm: f64) {
    ticks_moved(
        &tick_labels(a, "middle"),
        &tick_labels(b, "middle"),
        offset_mm,
    );
}

/// The y axis of two drawings of one map, `b`'s data `offset_mm` further along y, as
/// [`x_axes_moved`]: the map's y axis is its leftmost column of right-aligned numbers (the
/// colour bar's, which must not move, lie right of the map).
fn map_y_axis_moved(a: &str, b: &str, offset_mm: f64) {
    let y_axis = |svg: &str| {
        let mut columns: Vec<_> = tick_labels(svg, "end").into_iter().collect();
        columns.sort_by(|(x, _), (y, _)| x.parse::<f64>().unwrap().total_cmp(&y.parse().unwrap()));
        columns.into_iter().take(1).collect()
    };
    ticks_moved(&y_axis(a), &y_axis(b), offset_mm);
}

/// The numbers of `svg` drawn with `anchor` ("middle": an x axis's, centred under their tick;
/// "end": a y axis's, right-aligned beside it), grouped by the pixel they share across the
/// axis (a row for x, a column for y), as (value, pixel along the axis).
fn tick_labels(svg: &str, anchor: &str) -> std::collections::BTreeMap<String, Vec<(f64, f64)>> {
    let (across, along) = if anchor == "end" {
        ("x", "y")
    } else {
        ("y", "x")
    };
    let mut axes = std::collections::BTreeMap::<String, Vec<(f64, f64)>>::new();
    for t in svg.split("<text ").skip(1) {
        let attr = |k: &str| t.split(&format!("{k}=\"")).nth(1)?.split('"').next();
        let text = t.split('>').nth(1).and_then(|s| s.split('<').next());
        let value = text.and_then(|s| s.trim().parse::<f64>().ok());
        if let (Some(v), true, Some(key), Some(p)) = (
            value,
            attr("text-anchor") == Some(anchor),
            attr(across),
            attr(along),
        ) {
            axes.entry(key.to_string())
                .or_default()
                .push((v, p.parse().unwrap()));
        }
    }
    axes
}

/// Each of `b`'s axes (as [`tick_labels`]) against `a`'s at the same pixel across: every label
/// of `b` at the pixel where `a`'s first and last label put its value − `offset_mm`.
fn ticks_moved(
    a: &std::collections::BTreeMap<String, Vec<(f64, f64)>>,
    b: &std::collections::BTreeMap<String, Vec<(f64, f64)>>,
    offset_mm: f64,
) {
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    assert!(!a.is_empty());
    for (across, ticks) in b {
        let (&(v0, p0), &(v1, p1)) = (a[across].first().unwrap(), a[across].last().unwrap());
        assert!(ticks.len() >= 3, "{ticks:?}");
        for &(v, p) in ticks {
            let want = p0 + (v - offset_mm - v0) * (p1 - p0) / (v1 - v0);
            assert!(
                (p - want).abs() <= 1.0,
                "tick {v} at {p} px, not {want}: {ticks:?} vs {:?}",
                a[across]
            );
        }
    }
}

#[test]
fn contact_draws_its_pressure_map_in_the_x3p_files_coordinates() {
    // The first 160 points of each line of sur-2, enough for a map's axes, written at (0, 0)
    // and at (0.25, −20) mm: the second's x and y axes are the first's moved by the offsets.
    let (z, rows, cols) = sur_2();
    let z: Vec<f64> = z.chunks(cols).flat_map(|l| &l[..160]).copied().collect();
    let map = map_of(&z, rows, 160, 0.003484, 0.010452);
    let dir = tempfile::tempdir().unwrap();
    let pressure_map = |name: &str, origin_mm: (f64, f64)| {
        let x3p = dir.path().join(format!("{name}.x3p"));
        let bytes = to_x3p(&map, origin_mm, &X3pMeta::default()).unwrap();
        std::fs::write(&x3p, bytes).unwrap();
        let out = dir.path().join(name);
        let o = Command::new(env!("CARGO_BIN_EXE_surfscan"))
            .arg("contact")
            .arg(&x3p)
            .args(["--young", "100", "--poisson", "0.34", "--pressures", "5"])
            .args(["--map-pressure", "5", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read_to_string(out.join("pressure.svg")).unwrap()
    };
    let (a, b) = (
        pressure_map("at-0", (0.0, 0.0)),
        pressure_map("at-0.25", (0.25, -20.0)),
    );
    x_axes_moved(&a, &b, 0.25);
    map_y_axis_moved(&a, &b, -20.0);
}
