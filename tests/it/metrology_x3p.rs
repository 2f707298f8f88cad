//! X3P writer: digests against their published vectors, a round trip through our reader, the
//! file read by an independent reader (surfalize; the test fails when it is missing:
//! `bash .ci/run` (tests/python/requirements.txt in .venv/)), and `main.xml` validated by
//! xmllint against the official ISO 5436-2 schema (`tests/data/x3p/`) with its MD5 files
//! checked by `md5sum -c` ([`assert_valid_x3p`], used by every test that writes an X3P file).

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
    let script = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/python/metrology_x3p_read.py");
    let out = crate::common::python()
        .arg(&script)
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "surfalize could not read the X3P (run `bash .ci/run`, which installs tests/python/requirements.txt into .venv/):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
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
    let script =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/python/x3p_write.py");
    let out = crate::common::python()
        .arg(&script)
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "x3p_write.py failed (run `bash .ci/run`, which installs tests/python/requirements.txt into .venv/):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let files: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
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

#[test]
fn analyze_reads_an_x3p_as_the_same_grid_as_its_csv() {
    // The bundled sur-2 grid as CSV and as X3P: the lines analyze reports from the X3P are
    // the CSV's, with the same numbers.
    let csv =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/sur-2.grid.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .collect();
    let cols = rows[0].len();
    let z: Vec<f64> = rows.iter().flatten().copied().collect();
    let dir = tempfile::tempdir().unwrap();
    let x3p = dir.path().join("sur-2.x3p");
    std::fs::write(
        &x3p,
        to_x3p(
            &HeightMap {
                heights_um: &z,
                rows: rows.len(),
                cols,
                pitch_x_mm: 0.003484,
                pitch_y_mm: 0.010452,
            },
            (0.25, 0.0),
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
    assert_eq!(from_x3p["lines"].as_array().unwrap().len(), rows.len());
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
    // The file's x offset is kept: report.json gives it, and the grid's X3P and the model's
    // sampled on its points start where the input did.
    assert_eq!(
        (&from_x3p["x0_mm"], &from_csv["x0_mm"]),
        (&0.25.into(), &0.0.into())
    );
    for f in ["measured", "model"] {
        let x = read_x3p(&std::fs::read(dir.path().join(format!("x3p/{f}.x3p"))).unwrap());
        let x = x.unwrap();
        assert_eq!((x.offset_x_mm, x.offset_y_mm), (0.25, 0.0), "{f}.x3p");
    }
}

#[test]
fn analyze_leaves_out_lines_with_invalid_points_of_a_foreign_x3p() {
    let dir = tempfile::tempdir().unwrap();
    let script =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/python/x3p_write.py");
    let out = crate::common::python()
        .arg(&script)
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
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
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/x3p_profile.py");
    let o = crate::common::python()
        .arg(script)
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
