//! `surfscan report SCAN_DIR --pdf`: the printed report made without a browser, read back
//! with poppler (`pdfinfo`, `pdftotext`, `pdfimages`; Debian's `poppler-utils`, installed by
//! `.ci/run`) and held to what the browser's printout is held to
//! ([`crate::report_print::check_pdf`]: a few pages, "page X of Y" on each, the laboratory
//! and the result on page 1, every table's column headers on one printed line, the
//! instrument comparison in one sentence, the signature block), and beyond it: the verdict
//! and its limits' table, the plots drawn as vectors (their text is text, and the only raster
//! image is the height map's own bitmap). Bad input: no report, a report that is not one,
//! a PDF that cannot be written, no `--pdf` — each named, with its exit status.

use std::path::Path;
use std::process::{Command, Output};

fn surfscan(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(args)
        .output()
        .unwrap()
}

/// The images of `pdf` as `pdfimages -list` gives them: (width, height) of each image (soft
/// masks left out).
fn images(pdf: &Path) -> Vec<(u32, u32)> {
    let out = Command::new("pdfimages")
        .arg("-list")
        .arg(pdf)
        .output()
        .unwrap_or_else(|e| {
            panic!("pdfimages: {e}; run `bash .ci/run` or `apt-get install poppler-utils`")
        });
    assert!(out.status.success());
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .skip(2)
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f.get(2) == Some(&"image")).then(|| (f[3].parse().unwrap(), f[4].parse().unwrap()))
        })
        .collect()
}

/// Writes the PDF of `dir` with `surfscan report` (to `out`, or by default to
/// `dir/report.pdf`) and checks it as the printout is checked and as a document with vector
/// plots; returns the page size.
pub fn check_report_pdf(dir: &Path, out: Option<&Path>, lab: &str, roles: &[&str]) -> String {
    let mut args = vec!["report".as_ref(), dir.as_os_str(), "--pdf".as_ref()];
    if let Some(o) = out {
        args.extend(["-o".as_ref(), o.as_os_str()]);
    }
    let o = surfscan(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let pdf = out.map_or_else(|| dir.join("report.pdf"), Path::to_path_buf);
    assert_eq!(
        String::from_utf8_lossy(&o.stdout).trim(),
        pdf.display().to_string(),
        "the file written is named"
    );
    let size = crate::report_print::check_pdf(dir, &pdf, lab, roles);
    let text = crate::report_print::pdftotext(&pdf);
    let first = &text[..text.find("page 1 of").unwrap()];
    // The verdict and its limits first, as on the page.
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    let summary = report["specification"]["summary"].as_str().unwrap();
    let words: Vec<&str> = summary.split_whitespace().take(6).collect();
    let flat = first.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        flat.contains(&words.join(" ")),
        "the verdict {summary:?} on page 1"
    );
    assert!(
        flat.contains(
            "limit verdict values beyond undecided allowed min µm max µm U of a line % why"
        ),
        "the limits' column headers on one line on page 1"
    );
    // The plots are drawings: their own words are text in the PDF (a picture of them would
    // have none) …
    assert!(
        text.contains("Bearing area curves"),
        "the material ratio plot's title"
    );
    assert!(text.contains("Measured heights"));
    // … and the one raster image is the height map's bitmap, drawn inside its vector axes.
    let rasters = images(&pdf);
    assert_eq!(
        rasters.len(),
        1,
        "only the height map is a bitmap: {rasters:?}"
    );
    let map = std::fs::read_to_string(dir.join("heightmap.svg")).unwrap();
    assert!(
        map.contains("<image"),
        "the height map's SVG holds its bitmap"
    );
    size
}

/// A directory with the smallest report `surfscan report` prints.
fn small_report() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("report.json"),
        r#"{"kind": "grid", "input": "grid.csv", "software": "surfscan test", "lab": {"lab": "Test lab", "signatures": ["Approved by"]}}"#,
    )
    .unwrap();
    dir
}

#[test]
fn a_report_without_plots_prints_on_one_numbered_page() {
    let dir = small_report();
    let o = surfscan(&["report".as_ref(), dir.path().as_os_str(), "--pdf".as_ref()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let pdf = dir.path().join("report.pdf");
    let (pages, size) = crate::report_print::info(&pdf);
    assert_eq!(pages, 1);
    assert!(size.ends_with("(A4)"), "{size}");
    let text = crate::report_print::pdftotext(&pdf);
    for want in [
        "Test lab",
        "Surface report: grid.csv",
        "page 1 of 1",
        "Approved by",
        "written by surfscan test",
    ] {
        assert!(text.contains(want), "{want:?} not in {text}");
    }
}

#[test]
fn no_report_a_broken_one_and_an_unwritable_pdf_are_named_and_exit_74() {
    let empty = tempfile::tempdir().unwrap();
    let o = surfscan(&[
        "report".as_ref(),
        empty.path().as_os_str(),
        "--pdf".as_ref(),
    ]);
    assert_eq!(o.status.code(), Some(74));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("report.json") && err.contains("surfscan analyze"),
        "{err}"
    );
    assert!(!empty.path().join("report.pdf").exists());

    std::fs::write(empty.path().join("report.json"), "{\"kind\": ").unwrap();
    let o = surfscan(&[
        "report".as_ref(),
        empty.path().as_os_str(),
        "--pdf".as_ref(),
    ]);
    assert_eq!(o.status.code(), Some(74));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a report"));

    let dir = small_report();
    let nowhere = dir.path().join("no such directory").join("r.pdf");
    let o = surfscan(&[
        "report".as_ref(),
        dir.path().as_os_str(),
        "--pdf".as_ref(),
        "-o".as_ref(),
        nowhere.as_os_str(),
    ]);
    assert_eq!(o.status.code(), Some(74));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("r.pdf") && err.contains("-o FILE"), "{err}");

    let o = surfscan(&["report".as_ref(), dir.path().as_os_str()]);
    assert_eq!(o.status.code(), Some(2), "--pdf is the format asked for");
}
