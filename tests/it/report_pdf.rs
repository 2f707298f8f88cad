//! `surfscan report SCAN_DIR --pdf`: the printed report made without a browser, read back
//! with poppler (`pdfinfo`, `pdftotext`, `pdfimages`; Debian's `poppler-utils`, installed by
//! `.ci/run`) and held to what the browser's printout is held to
//! ([`crate::report_print::check_pdf`]: a few pages, "page X of Y" on each, the laboratory
//! and the result on page 1, every table's column headers on one printed line, the
//! instrument comparison in one sentence, the signature block), and beyond it: the verdict
//! and its limits' table, the plots drawn as vectors (their text is text, and the only raster
//! image is the height map's own bitmap). Bad input: no report, a report that is not one,
//! a PDF that cannot be written, no `--pdf` — each named, with its exit status.

use crate::common::tool_output;
use std::path::Path;
use std::process::{Command, Output};

fn surfscan(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .args(args)
        .output()
        .unwrap()
}

/// The images of `pdf` as `pdfimages -list` gives them: width, height and encoding of each
/// image (soft masks left out); none asks to be interpolated (PDF/A forbids it).
fn images(pdf: &Path) -> Vec<(u32, u32, String)> {
    let out = tool_output(
        Command::new("pdfimages").arg("-list").arg(pdf),
        "poppler-utils",
    );
    String::from_utf8_lossy(&out)
        .lines()
        .skip(2)
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f.get(2) == Some(&"image")).then(|| {
                assert_eq!(f[9], "no", "an image asks to be interpolated: {l}");
                (
                    f[3].parse().unwrap(),
                    f[4].parse().unwrap(),
                    f[8].to_string(),
                )
            })
        })
        .collect()
}

/// The fonts of `pdf` as `pdffonts` lists them: name (its subset tag removed), embedded,
/// subset.
pub fn fonts(pdf: &Path) -> Vec<(String, bool, bool)> {
    let out = tool_output(Command::new("pdffonts").arg(pdf), "poppler-utils");
    String::from_utf8_lossy(&out)
        .lines()
        .skip(2)
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            let n = f.len();
            let (tag, name) = f[0].split_once('+').unwrap_or(("", f[0]));
            // A subset's name carries a tag of six capitals.
            let tagged = tag.len() == 6 && tag.chars().all(|c| c.is_ascii_uppercase());
            (
                name.to_string(),
                f[n - 5] == "yes",
                f[n - 4] == "yes" && tagged,
            )
        })
        .collect()
}

/// The PDF/A part and conformance level `pdf` claims in its XMP metadata (`pdfinfo -meta`),
/// if any.
pub fn pdfa_claim(pdf: &Path) -> Option<(String, String)> {
    let out = tool_output(
        Command::new("pdfinfo").arg("-meta").arg(pdf),
        "poppler-utils",
    );
    let xmp = String::from_utf8_lossy(&out);
    let start = xmp.find("<?xpacket")?;
    let doc = roxmltree::Document::parse(xmp[start..].trim()).unwrap();
    const NS: &str = "http://www.aiim.org/pdfa/ns/id/";
    let get = |name: &str| {
        doc.descendants().find_map(|n| {
            if n.tag_name().namespace() == Some(NS) && n.tag_name().name() == name {
                n.text().map(str::to_string)
            } else {
                n.attribute((NS, name)).map(str::to_string)
            }
        })
    };
    Some((get("part")?, get("conformance")?))
}

/// The output intents of `pdf`'s catalogue as `qpdf --json` reads them: each one's subtype
/// and the number of colour components of its destination profile.
pub fn output_intents(pdf: &Path) -> Vec<(String, i64)> {
    let mut command = Command::new("qpdf");
    command.args(["--json=2", "--json-key=qpdf"]).arg(pdf);
    let v: serde_json::Value = serde_json::from_slice(&tool_output(&mut command, "qpdf")).unwrap();
    let objects = &v["qpdf"][1];
    // A reference ("5 0 R") as what it refers to (a stream's dictionary for a stream); any
    // other value as it is.
    let get = |r: &serde_json::Value| match r.as_str().filter(|r| r.ends_with(" R")) {
        Some(r) => {
            let o = &objects[format!("obj:{r}")];
            if o["stream"].is_object() {
                o["stream"]["dict"].clone()
            } else {
                o["value"].clone()
            }
        }
        None => r.clone(),
    };
    let catalog = objects
        .as_object()
        .unwrap()
        .values()
        .map(|o| &o["value"])
        .find(|o| o["/Type"] == "/Catalog")
        .expect("a catalogue");
    get(&catalog["/OutputIntents"])
        .as_array()
        .into_iter()
        .flatten()
        .map(|r| {
            let intent = get(r);
            let profile = get(&intent["/DestOutputProfile"]);
            (
                intent["/S"].as_str().unwrap_or_default().to_string(),
                profile["/N"].as_i64().unwrap_or_default(),
            )
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
    // Headings and table headers in DejaVu Sans Bold, the configuration's hash and the scan's
    // identifier in DejaVu Sans Mono, the rest in DejaVu Sans: each embedded and subset.
    let fonts = fonts(&pdf);
    for face in ["DejaVuSans", "DejaVuSans-Bold", "DejaVuSansMono"] {
        assert!(
            fonts.contains(&(face.to_string(), true, true)),
            "{face} embedded and subset: {fonts:?}"
        );
    }
    assert!(fonts.iter().all(|f| f.1), "every font embedded: {fonts:?}");
    // An archival record: PDF/A-2b claimed in the XMP, with the sRGB (three-component) output
    // intent PDF/A requires for device colours. (veraPDF is not run: it is not packaged for
    // Debian; what it would check beyond this is krilla's validator's part.)
    assert_eq!(pdfa_claim(&pdf), Some(("2".into(), "B".into())));
    assert_eq!(output_intents(&pdf), [("/GTS_PDFA1".to_string(), 3)]);
    // The plots are drawings: their own words are text in the PDF (a picture of them would
    // have none) …
    assert!(
        text.contains("triangles have the areas A1 above C"),
        "the Rk construction's legend"
    );
    assert!(text.contains("Measured heights"));
    assert!(text.contains("Power spectral density") && text.contains("Autocorrelation"));
    // … and the only raster images are the bitmaps the height map and the 3D view hold
    // inside their vector axes: the per-line figures and every other plot are drawings.
    let rasters = images(&pdf);
    assert_eq!(rasters.len(), 2, "two bitmaps: {rasters:?}");
    for stem in ["heightmap", "surface3d"] {
        let svg = std::fs::read_to_string(dir.join(format!("{stem}.svg"))).unwrap();
        assert_eq!(
            svg.matches("<image").count(),
            1,
            "{stem}.svg holds its bitmap"
        );
    }
    for entry in std::fs::read_dir(dir.join("rk")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "svg") {
            let svg = std::fs::read_to_string(&path).unwrap();
            assert!(!svg.contains("<image"), "{}: a drawing", path.display());
        }
    }
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
    assert!(
        o.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(pdfa_claim(&pdf), Some(("2".into(), "B".into())));
}

/// A character none of the bundled fonts has cannot be in a PDF/A-2b: the same pages as a
/// plain PDF (no claim in its XMP), and a warning that names the character.
#[test]
fn a_character_no_bundled_font_has_makes_a_plain_pdf_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("report.json"),
        r#"{"kind": "grid", "input": "grid.csv", "software": "surfscan test", "lab": {"lab": "計測室 Test lab", "signatures": ["Approved by"]}}"#,
    )
    .unwrap();
    let o = surfscan(&["report".as_ref(), dir.path().as_os_str(), "--pdf".as_ref()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("the PDF is not PDF/A-2b: the bundled fonts have no glyph for \"")
            && err.contains('計'),
        "{err}"
    );
    let pdf = dir.path().join("report.pdf");
    assert_eq!(pdfa_claim(&pdf), None);
    assert!(crate::report_print::pdftotext(&pdf).contains("Test lab"));
}

/// A report headed by the logo `logo`.
fn report_with_logo(logo: &Path) -> tempfile::TempDir {
    let dir = small_report();
    let json = serde_json::json!({"kind": "grid", "input": "grid.csv", "software": "surfscan test",
        "lab": {"lab": "Test lab", "logo": logo, "signatures": ["Approved by"]}});
    std::fs::write(dir.path().join("report.json"), json.to_string()).unwrap();
    dir
}

#[test]
fn png_and_jpeg_logos_are_embedded_once_at_their_size_and_a_corrupt_one_is_left_out_with_a_warning()
{
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/logo");
    // 120 × 40 pixels each; the JPEG's own DCT data is embedded (poppler lists it as jpeg),
    // the PNG's pixels as a flate-compressed image.
    for (file, enc) in [("logo.png", "image"), ("logo.jpg", "jpeg")] {
        let dir = report_with_logo(&data.join(file));
        let o = surfscan(&["report".as_ref(), dir.path().as_os_str(), "--pdf".as_ref()]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            o.stderr.is_empty(),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        let pdf = dir.path().join("report.pdf");
        assert_eq!(images(&pdf), [(120, 40, enc.to_string())], "{file}");
        assert!(crate::report_print::pdftotext(&pdf).contains("Test lab"));
    }
    // A file that says PNG and is not one: the PDF without the logo, a warning naming the file
    // and the cause, exit 0 (the report is the record; the logo is decoration).
    let bad = tempfile::tempdir().unwrap();
    let png = bad.path().join("broken.png");
    std::fs::write(&png, b"\x89PNG\r\n\x1a\nnot a PNG after all").unwrap();
    let dir = report_with_logo(&png);
    let o = surfscan(&["report".as_ref(), dir.path().as_os_str(), "--pdf".as_ref()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(&format!(
            "[report] logo {}: its PNG cannot be read",
            png.display()
        )) && err.contains("printed without a logo"),
        "{err}"
    );
    let pdf = dir.path().join("report.pdf");
    assert!(images(&pdf).is_empty());
    assert!(crate::report_print::pdftotext(&pdf).contains("Test lab"));
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
