//! X3P writer: digests against their published vectors, a round trip through our reader, and
//! the file read by an independent reader (surfalize; the test fails when it is missing:
//! `bash .ci/run` (tests/python/requirements.txt in .venv/)).

use surfscan::metrology::x3p::{crc32, md5, read_x3p, to_x3p, X3pMeta};

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
        comment: "measured grid <test> & more".to_string(),
        ..X3pMeta::default()
    };
    let bytes = to_x3p(&z, rows, cols, 0.0015, 0.01, &meta).unwrap();
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
    let h: Vec<f64> = v["heights_um"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    for (a, b) in h.iter().zip(&z) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
}
