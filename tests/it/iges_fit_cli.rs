//! `surfscan fit` end to end through the real binary: output directory creation, a readable
//! IGES file whose surface interpolates the grid, the JSON report, and exit codes for bad input.
use std::process::Command;

fn surfscan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
}

/// Heights (µm) of the tilted plane z_mm = 0.5·x_mm + 0.25·y_mm. Interpolation is linear in
/// the data, so the poles and every surface point satisfy the same plane equation.
fn plane_grid(rows: usize, cols: usize, px: f64, py: f64) -> String {
    let mut s = String::new();
    for r in 0..rows {
        let line: Vec<String> = (0..cols)
            .map(|c| format!("{}", 1000.0 * (0.5 * c as f64 * px + 0.25 * r as f64 * py)))
            .collect();
        s.push_str(&line.join(","));
        s.push('\n');
    }
    s
}

#[test]
fn fits_a_plane_and_writes_iges_and_report_into_new_directories() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("plane.csv");
    std::fs::write(&input, plane_grid(7, 12, 0.01, 0.02)).unwrap();
    let out = dir.path().join("new/sub/plane.igs");
    let report = dir.path().join("rep/fit.json");
    let st = surfscan()
        .args(["fit"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .args(["--pitch-x", "0.01", "--pitch-y", "0.02", "--report"])
        .arg(&report)
        .output()
        .unwrap();
    assert!(st.status.success(), "{}", crate::common::describe(&st));
    let file = surfscan::iges::read_iges(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(file.surfaces.len(), 1);
    let s = &file.surfaces[0];
    assert_eq!((s.count_u(), s.count_v()), (12, 7));
    for a in 0..=8 {
        for b in 0..=8 {
            let p = s.evaluate(a as f64 / 8.0, b as f64 / 8.0);
            assert!((p[2] - (0.5 * p[0] + 0.25 * p[1])).abs() < 1e-12, "{p:?}");
        }
    }
    // Corners are the corner data points (clamped interpolant).
    let c = s.evaluate(1.0, 1.0);
    assert!(
        (c[0] - 0.11).abs() < 1e-14 && (c[1] - 0.12).abs() < 1e-14,
        "{c:?}"
    );
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(rep["grid"]["rows"], 7);
    assert_eq!(rep["grid"]["cols"], 12);
    assert_eq!(rep["knots_u_len"], 18);
    assert_eq!(rep["knots_v_len"], 13);
    assert_eq!(rep["patches"], 1);
    assert_eq!(rep["iges_bytes"], std::fs::metadata(&out).unwrap().len());
    assert!(rep["max_residual_mm"].as_f64().unwrap() < 1e-12);
    assert!(rep["timings_s"]["write_iges"].as_f64().unwrap() >= 0.0);
}

#[test]
fn malformed_csv_names_line_and_column_and_exits_1() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bad.csv");
    std::fs::write(&input, "1,2,3,4,5,6\n1,2,oops,4,5,6\n").unwrap();
    let st = surfscan()
        .arg("fit")
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("x.igs"))
        .args(["--pitch-x", "0.01", "--pitch-y", "0.01"])
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(1));
    let err = String::from_utf8_lossy(&st.stderr);
    // The row is left out, named by its line and column; one line is too few to fit.
    assert!(
        err.contains("line 2 (column 3: \"oops\" is not a number)")
            && err.contains("1 lines is fewer than degree_v + 1"),
        "{err}"
    );
    assert!(!dir.path().join("x.igs").exists());
}

#[test]
fn a_grid_csv_with_a_byte_order_mark_is_read_and_one_not_utf8_exits_1_naming_the_byte() {
    let dir = tempfile::tempdir().unwrap();
    let grid = plane_grid(7, 9, 0.01, 0.02);
    let fit = |name: &str, bytes: &[u8]| {
        let input = dir.path().join(format!("{name}.csv"));
        std::fs::write(&input, bytes).unwrap();
        let out = dir.path().join(format!("{name}.igs"));
        let o = surfscan()
            .arg("fit")
            .arg(&input)
            .arg("-o")
            .arg(&out)
            .args(["--pitch-x", "0.01", "--pitch-y", "0.02"])
            .output()
            .unwrap();
        let data = std::fs::read_to_string(&out).ok().map(|t| {
            // The Directory Entry and Parameter Data sections: the surface itself.
            t.lines()
                .filter(|l| matches!(l.as_bytes().get(72), Some(b'D' | b'P')))
                .collect::<Vec<_>>()
                .join("\n")
        });
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
            data,
        )
    };
    let (code, err, plain) = fit("plain", grid.as_bytes());
    assert_eq!(code, Some(0), "{err}");
    // "UTF-8 CSV" as spreadsheet programs save it: the same surface.
    let (code, err, bom) = fit("bom", &[b"\xEF\xBB\xBF", grid.as_bytes()].concat());
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(bom, plain);
    // A Latin-1 byte in the second row: not a grid CSV, not an I/O error.
    let mut bytes = grid.into_bytes();
    let at = bytes.iter().position(|&b| b == b'\n').unwrap() + 2;
    bytes[at] = 0xE9;
    let (code, err, out) = fit("latin1", &bytes);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains(&format!("not text (byte {at} is not UTF-8)")),
        "{err}"
    );
    assert_eq!(out, None);
}

#[test]
fn a_limit_of_zero_iges_lines_is_a_usage_error_not_a_limit_of_one() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("plane.csv");
    std::fs::write(&input, plane_grid(7, 9, 0.01, 0.02)).unwrap();
    for flag in ["--max-iges-lines-per-file", "--max-iges-lines-per-entity"] {
        let o = surfscan()
            .arg("fit")
            .arg(&input)
            .arg("-o")
            .arg(dir.path().join("x.igs"))
            .args(["--pitch-x", "0.01", "--pitch-y", "0.02", flag, "0"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains(&format!("{flag} must be at least 1")), "{err}");
        assert!(!err.contains("limit 1"), "{err}");
        assert!(!dir.path().join("x.igs").exists());
    }
}

#[test]
fn missing_input_exits_74_and_bad_pitch_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let st = surfscan()
        .arg("fit")
        .arg(dir.path().join("absent.csv"))
        .args(["-o", "x.igs", "--pitch-x", "0.01", "--pitch-y", "0.01"])
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(74));
    let st = surfscan()
        .arg("fit")
        .arg(dir.path().join("absent.csv"))
        .args(["-o", "x.igs", "--pitch-x", "0", "--pitch-y", "0.01"])
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
}

#[test]
fn a_surface_too_large_for_one_file_is_written_as_named_parts_with_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("plane.csv");
    std::fs::write(&input, plane_grid(80, 10, 0.01, 0.02)).unwrap();
    let run = |out: &std::path::Path, report: &std::path::Path, caps: &[String]| {
        let st = surfscan()
            .arg("fit")
            .arg(&input)
            .arg("-o")
            .arg(out)
            .args(["--pitch-x", "0.01", "--pitch-y", "0.02", "--report"])
            .arg(report)
            .args(caps)
            .output()
            .unwrap();
        assert!(st.status.success(), "{}", crate::common::describe(&st));
        let rep: serde_json::Value =
            serde_json::from_slice(&std::fs::read(report).unwrap()).unwrap();
        (String::from_utf8_lossy(&st.stdout).into_owned(), rep)
    };
    // Whole surface in one entity, then split into entities of at most a sixth of it (parts
    // and patches are planned from the bound on their P lines, from token counts).
    let one = dir.path().join("one.igs");
    let _ = run(&one, &dir.path().join("one.json"), &[]);
    let whole_surface = surfscan::iges::read_iges(&std::fs::read(&one).unwrap())
        .unwrap()
        .surfaces
        .remove(0);
    let whole = surfscan::iges::parameter_lines_bound(&whole_surface);
    let entity_cap = (whole / 6).to_string();
    let split = dir.path().join("split.igs");
    let (_, rep) = run(
        &split,
        &dir.path().join("split.json"),
        &["--max-iges-lines-per-entity".into(), entity_cap.clone()],
    );
    assert_eq!(rep["iges_files"].as_array().unwrap().len(), 1);
    let patches = surfscan::iges::read_iges(&std::fs::read(&split).unwrap())
        .unwrap()
        .surfaces;
    let sizes: Vec<usize> = patches
        .iter()
        .map(surfscan::iges::parameter_lines_bound)
        .collect();
    let (total, largest) = (sizes.iter().sum::<usize>(), *sizes.iter().max().unwrap());
    // total/3 + largest < total/2 lines per file: greedy grouping needs exactly 3 files.
    assert!(largest < total / 6, "{sizes:?}");
    let file_cap = (total / 3 + largest).to_string();

    let out = dir.path().join("parts/plane.igs");
    let report = dir.path().join("parts.json");
    let (stdout, rep) = run(
        &out,
        &report,
        &[
            "--max-iges-lines-per-entity".into(),
            entity_cap,
            "--max-iges-lines-per-file".into(),
            file_cap,
        ],
    );
    assert!(!out.exists(), "the single-file name must not be written");
    assert!(stdout.contains("wrote 3 files"), "{stdout}");
    assert!(stdout.contains("plane.part1-of-3.igs"), "{stdout}");
    let files = rep["iges_files"].as_array().unwrap();
    assert_eq!(files.len(), 3);
    let mut all = Vec::new();
    let mut bytes = 0;
    for (k, f) in files.iter().enumerate() {
        let path = dir
            .path()
            .join(format!("parts/plane.part{}-of-3.igs", k + 1));
        assert_eq!(f["path"], path.display().to_string());
        let data = std::fs::read(&path).unwrap();
        assert_eq!(f["bytes"], data.len() as u64);
        bytes += data.len() as u64;
        let file = surfscan::iges::read_iges(&data).unwrap();
        assert_eq!(f["patches"], file.surfaces.len());
        let start = file.start_lines.join(" ");
        let (v0, v1) = (
            f["v_range"][0].as_f64().unwrap(),
            f["v_range"][1].as_f64().unwrap(),
        );
        assert!(
            start.contains(&format!("part {} of 3, v range [{v0}, {v1}]", k + 1)),
            "{start}"
        );
        assert_eq!(file.surfaces[0].knots_v()[0], v0);
        assert_eq!(*file.surfaces.last().unwrap().knots_v().last().unwrap(), v1);
        all.extend(file.surfaces);
    }
    assert_eq!(rep["iges_bytes"], bytes);
    assert_eq!(rep["patches"], all.len());
    // Parts tile v in order from 0 to 1, and every patch lies on the fitted plane.
    assert_eq!(all[0].knots_v()[0], 0.0);
    assert_eq!(*all.last().unwrap().knots_v().last().unwrap(), 1.0);
    for w in all.windows(2) {
        assert_eq!(w[0].knots_v().last(), w[1].knots_v().first());
    }
    for p in &all {
        let (v0, v1) = (p.knots_v()[0], *p.knots_v().last().unwrap());
        for a in 0..=6 {
            for b in 0..=6 {
                let q = p.evaluate(a as f64 / 6.0, v0 + (v1 - v0) * b as f64 / 6.0);
                assert!((q[2] - (0.5 * q[0] + 0.25 * q[1])).abs() < 1e-12, "{q:?}");
            }
        }
    }
    // The top corner is the last data point (y = 79 · 0.02 mm).
    let c = all.last().unwrap().evaluate(1.0, 1.0);
    assert!(
        (c[0] - 0.09).abs() < 1e-12 && (c[1] - 1.58).abs() < 1e-12,
        "{c:?}"
    );
}

/// `fit -o` onto a character device (a node like `/dev/null`, made with mknod in a temporary
/// directory): the surface is written into the device, which stays a character device; the
/// old writer renamed a regular file over it.
#[test]
fn fit_onto_a_character_device_writes_into_it_and_leaves_it_a_device() {
    use std::os::unix::fs::{FileTypeExt, MetadataExt};
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("plane.csv");
    std::fs::write(&input, plane_grid(7, 12, 0.01, 0.02)).unwrap();
    let node = dir.path().join("null");
    let c = std::ffi::CString::new(node.as_os_str().as_encoded_bytes()).unwrap();
    // The same device as /dev/null: major 1, minor 3. CI runs as root; without the
    // capability this fails loudly rather than skip.
    // SAFETY: mknod on a NUL-terminated path.
    let made = unsafe { libc::mknod(c.as_ptr(), libc::S_IFCHR | 0o666, libc::makedev(1, 3)) };
    assert_eq!(
        made,
        0,
        "mknod needs CAP_MKNOD (run the tests as root): {}",
        std::io::Error::last_os_error()
    );
    let st = surfscan()
        .arg("fit")
        .arg(&input)
        .arg("-o")
        .arg(&node)
        .args(["--pitch-x", "0.01", "--pitch-y", "0.02"])
        .output()
        .unwrap();
    assert!(st.status.success(), "{}", crate::common::describe(&st));
    let meta = std::fs::symlink_metadata(&node).unwrap();
    assert!(meta.file_type().is_char_device(), "{meta:?}");
    assert_eq!(meta.rdev(), libc::makedev(1, 3));
    // Nothing else was left in the directory (no temporary file beside the node).
    let mut names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(names, ["null", "plane.csv"]);
}

/// `fit -o -`: the IGES file alone on standard output (it reads back as the surface), the
/// summary on standard error.
#[test]
fn fit_onto_standard_output_keeps_the_summary_off_it() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("plane.csv");
    std::fs::write(&input, plane_grid(7, 12, 0.01, 0.02)).unwrap();
    let st = surfscan()
        .arg("fit")
        .arg(&input)
        .args(["-o", "-", "--pitch-x", "0.01", "--pitch-y", "0.02"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&st.stderr);
    assert!(st.status.success(), "{stderr}");
    let file = surfscan::iges::read_iges(&st.stdout).unwrap();
    assert_eq!(file.surfaces.len(), 1);
    assert_eq!(
        (file.surfaces[0].count_u(), file.surfaces[0].count_v()),
        (12, 7)
    );
    assert!(stderr.contains("7x12 grid"), "{stderr}");
    // No file named "-" was made.
    assert!(!dir.path().join("-").exists());
}

#[test]
fn an_input_other_than_a_scan_without_o_is_named_with_its_article_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let z = [0.0, 1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 4.0, 2.0, 3.0, 4.0, 5.0];
    let map = surfscan::metrology::areal::HeightMap {
        heights_um: &z,
        rows: 3,
        cols: 4,
        pitch_x_mm: 0.01,
        pitch_y_mm: 0.02,
    };
    let x3p = surfscan::x3p::to_x3p(&map, (0.0, 0.0), &surfscan::x3p::X3pMeta::default());
    std::fs::write(dir.path().join("in.x3p"), x3p.unwrap()).unwrap();
    std::fs::write(dir.path().join("in.csv"), plane_grid(3, 4, 0.01, 0.02)).unwrap();
    let pitches = ["--pitch-x", "0.01", "--pitch-y", "0.02"];
    for (file, kind, extra) in [
        ("in.x3p", "an X3P file", &[][..]),
        ("in.csv", "a grid CSV", &pitches[..]),
    ] {
        let o = surfscan()
            .current_dir(dir.path())
            .args(["fit", file])
            .args(extra)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        let sentence =
            format!("{kind} needs -o OUT.igs (only a scan directory has a default output)");
        assert_eq!(err, format!("surfscan: {sentence}\n"));
        let mut names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        names.sort();
        assert_eq!(names, ["in.csv", "in.x3p"], "{file}");
    }
}
