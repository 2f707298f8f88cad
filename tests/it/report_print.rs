//! The printed report: a scan's `report.html` printed to PDF by headless Chromium (as the
//! browser's print does), read back with poppler's `pdfinfo` and `pdftotext` (Debian's
//! `poppler-utils`, installed by `.ci/run`). What a metrologist signs: a few pages on the
//! paper `[report]` names, "page X of Y" on every page agreeing with the document, the
//! laboratory's header and the result on the first page, every printed table's column
//! headers on the page (none cut off at the right margin), the instrument comparison in one
//! sentence, and the signature block.

use crate::common::tool_output;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

pub fn pdftotext(pdf: &Path) -> String {
    let mut command = Command::new("pdftotext");
    command.arg("-layout").arg(pdf).arg("-");
    String::from_utf8_lossy(&tool_output(&mut command, "poppler-utils")).into_owned()
}

/// The number of pages and the page size line of `pdfinfo`.
pub fn info(pdf: &Path) -> (usize, String) {
    let out = tool_output(Command::new("pdfinfo").arg(pdf), "poppler-utils");
    let text = String::from_utf8_lossy(&out).into_owned();
    let field = |name: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(name))
            .map(|v| v.trim().to_string())
            .unwrap_or_else(|| panic!("pdfinfo gives no {name}: {text}"))
    };
    (field("Pages:").parse().unwrap(), field("Page size:"))
}

/// The least distance, in mm, of any printed word from the paper's edge (`pdftotext -bbox`):
/// a printer leaves about 4 mm at each edge unprinted.
fn nearest_to_edge_mm(pdf: &Path) -> (f64, String) {
    let mut command = Command::new("pdftotext");
    command.arg("-bbox").arg(pdf).arg("-");
    let out = String::from_utf8_lossy(&tool_output(&mut command, "poppler-utils")).into_owned();
    let attr = |tag: &str, name: &str| -> f64 {
        let at = tag.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
        tag[at..at + tag[at..].find('"').unwrap()].parse().unwrap()
    };
    let (mut width, mut height) = (0.0, 0.0);
    let mut nearest = (f64::INFINITY, String::new());
    for tag in out.lines().map(str::trim) {
        if tag.starts_with("<page ") {
            (width, height) = (attr(tag, "width"), attr(tag, "height"));
        } else if tag.starts_with("<word ") {
            let (x0, y0) = (attr(tag, "xMin"), attr(tag, "yMin"));
            let (x1, y1) = (attr(tag, "xMax"), attr(tag, "yMax"));
            let pt = x0.min(y0).min(width - x1).min(height - y1);
            if pt < nearest.0 {
                let word = &tag[tag.find('>').unwrap() + 1..tag.rfind('<').unwrap()];
                nearest = (pt, word.to_owned());
            }
        }
    }
    assert!(nearest.0.is_finite(), "no word in {}", pdf.display());
    (nearest.0 * 25.4 / 72.0, nearest.1)
}

/// Text without tags, entities decoded, runs of white space as one space.
fn plain(s: &str) -> String {
    let mut out = String::new();
    let mut in_tag = false;
    for c in s.chars() {
        match c {
            '<' => in_tag = true,
            '>' => in_tag = false,
            c if !in_tag => out.push(c),
            _ => {}
        }
    }
    let out = out
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&amp;", "&");
    out.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The tables a printout shows (not inside a `<details>`, which print leaves out), each with
/// the texts of its heading row.
fn printed_tables(html: &str) -> Vec<(String, Vec<String>)> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(at) = html[from..].find("<table id=\"").map(|i| i + from) {
        from = at + 1;
        let before = &html[..at];
        if before.matches("<details").count() > before.matches("</details>").count() {
            continue;
        }
        // Inside a section print leaves out (sections do not nest on the page).
        if let Some(open) = before.rfind("<section") {
            if before[open..].starts_with("<section class=\"noprint\"")
                && !before[open..].contains("</section>")
            {
                continue;
            }
        }
        let id_start = at + "<table id=\"".len();
        let id = html[id_start..id_start + html[id_start..].find('"').unwrap()].to_string();
        let end = at + html[at..].find("</table>").unwrap();
        let table = &html[at..end];
        let Some(head) = table
            .find("<thead>")
            .map(|s| &table[s..s + table[s..].find("</thead>").unwrap()])
        else {
            continue;
        };
        let heads: Vec<String> = head
            .split("</th>")
            .filter_map(|cell| {
                let open = cell.rfind("<th>").or_else(|| cell.rfind("<th "))?;
                let body = &cell[open..];
                Some(plain(&body[body.find('>')? + 1..]))
            })
            .collect();
        out.push((id, heads));
    }
    out
}

/// The texts of the page's `<h2>` and `<h3>` headings.
fn headings(html: &str) -> Vec<String> {
    let mut out = Vec::new();
    for tag in ["<h2", "<h3"] {
        for (at, _) in html.match_indices(tag) {
            let start = at + html[at..].find('>').unwrap() + 1;
            let end = start + html[start..].find("</h").unwrap();
            out.push(plain(&html[start..end]));
        }
    }
    out
}

/// The comparisons with the instrument, and how many are within the report's stated
/// tolerance (2 % of the instrument's value, at least 0.005 µm, 1 % point or 0.05).
fn instrument_within(report: &Value) -> (usize, usize) {
    let mut compared = 0;
    let mut within = 0;
    for l in report["lines"].as_array().unwrap() {
        for c in l["instrument"].as_array().into_iter().flatten() {
            let (Some(i), Some(d)) = (c["instrument"].as_f64(), c["difference"].as_f64()) else {
                continue;
            };
            compared += 1;
            let floor = match c["unit"].as_str() {
                Some("um") => 0.005,
                Some("%") => 1.0,
                _ => 0.05,
            };
            if d.abs() <= (0.02 * i.abs()).max(floor) {
                within += 1;
            }
        }
    }
    (within, compared)
}

/// Prints `dir/report.html` to `pdf` and checks it as a metrologist reads it; returns the
/// page size `pdfinfo` reports.
pub fn check_printed(dir: &Path, pdf: &Path, lab: &str, roles: &[&str]) -> String {
    crate::common::chromium::print_to_pdf(&dir.join("report.html"), pdf);
    check_pdf(dir, pdf, lab, roles)
}

/// Checks `pdf`, the printed report of `dir` (by Chromium or by `surfscan report --pdf`), as
/// a metrologist reads it; returns the page size `pdfinfo` reports.
pub fn check_pdf(dir: &Path, pdf: &Path, lab: &str, roles: &[&str]) -> String {
    let page = dir.join("report.html");
    let (pages, size) = info(pdf);
    // Six, on A4 and on the shorter Letter (seven there before its margins were made 6 mm
    // less): what a metrologist signs, the rest on screen only; the screen's page printed
    // 17, the print 10 on A4 before.
    assert!(
        (2..=6).contains(&pages),
        "a few pages, not {pages} (the screen's page printed 17)"
    );
    // The running header and footer sit in the page's margin, clear of what a printer
    // cannot print (Letter's header was 3.2 mm from the top before it was set against the
    // text block).
    let (edge, word) = nearest_to_edge_mm(pdf);
    assert!(
        edge >= 5.0,
        "{word:?} {edge:.1} mm from the paper's edge ({size})"
    );
    let text = pdftotext(pdf).replace('\u{fb01}', "fi");
    // "page X of Y" on every page, Y the document's page count: the paged-media margin boxes
    // were printed and count what was printed.
    for k in 1..=pages {
        assert!(
            text.contains(&format!("page {k} of {pages}")),
            "no \"page {k} of {pages}\" in the printout"
        );
    }
    assert!(!text.contains(&format!("of {}", pages + 1)));
    let first = &text[..text.find("page 1 of").unwrap()];
    assert!(first.contains(lab), "the laboratory heads page 1");
    let result = first.find("Result").expect("the result on page 1");
    assert!(result < first.find("Warnings").unwrap_or(usize::MAX));
    assert!(first.contains("31 of 31 planned characterised"));

    let html = std::fs::read_to_string(&page).unwrap();
    let tables = printed_tables(&html);
    for id in [
        "t-lines",
        "t-lines-spacing",
        "t-lines-material",
        "t-areal",
        "t-signatures",
    ] {
        assert!(
            tables.iter().any(|(t, _)| t == id),
            "{id} is not printed: {tables:?}"
        );
    }
    let lines: Vec<String> = text
        .lines()
        .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect();
    for (id, heads) in &tables {
        // The heading row on one printed line, every column there in order: nothing cut off.
        let found = lines.iter().any(|l| {
            let mut at = 0;
            heads.iter().all(|h| match l[at..].find(h.as_str()) {
                Some(i) => {
                    at += i + h.len();
                    true
                }
                None => false,
            })
        });
        assert!(
            found,
            "{id}: its column headers {heads:?} are not on the page"
        );
    }
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    let (within, compared) = instrument_within(&report);
    assert!(compared > 0);
    assert!(
        text.contains(&format!(
            "{within} of {compared} within tolerance; largest |Δ|"
        )),
        "the instrument comparison in one sentence"
    );
    // The per-line figures of the lines the specification's limits pick (the three of
    // largest value ÷ limit, or limit ÷ value for a lower limit, a line's worst limit
    // counting), worst first, or without a limit a line has a value for, of largest, median
    // (the lower of two) and smallest Ra: said in a sentence; no other line's figure.
    let lines_json = report["lines"].as_array().unwrap();
    let sj = report["recipe"]["material_ratio"] == "instrument";
    let mut worst: Vec<(f64, u64)> = lines_json
        .iter()
        .filter_map(|l| {
            let limits = report["specification"]["limits"].as_array()?;
            let shares = limits.iter().filter_map(|c| {
                let p = c["parameter"].as_str().unwrap();
                let from = if sj && ["Rk", "Rpk", "Rvk"].contains(&p) {
                    &l["material_ratio_sj_series"]
                } else {
                    l
                };
                let v = from[format!("{p}_um")].as_f64()?;
                let limit = c["limit_um"].as_f64().unwrap();
                Some(if c["side"] == "lower" {
                    limit / v
                } else {
                    v / limit
                })
            });
            Some((shares.reduce(f64::max)?, l["index"].as_u64().unwrap()))
        })
        .collect();
    worst.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut ra: Vec<(f64, u64)> = lines_json
        .iter()
        .map(|l| (l["Ra_um"].as_f64().unwrap(), l["index"].as_u64().unwrap()))
        .collect();
    ra.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let n = ra.len();
    let flat = text.split_whitespace().collect::<Vec<_>>().join(" ");
    let printed: Vec<u64> = if worst.is_empty() {
        let printed = [ra[0].1, ra[n / 2].1, ra[n - 1].1];
        assert!(
            flat.contains(&format!(
                "On paper, the assessed profile and Rk construction of 3 of {n} lines (largest Ra: line {} ({:04}); median Ra: line {} ({:04}); smallest Ra: line {} ({:04}))",
                printed[0] + 1, printed[0], printed[1] + 1, printed[1], printed[2] + 1, printed[2]
            )),
            "which lines' figures are printed, said"
        );
        printed.to_vec()
    } else {
        let printed: Vec<u64> = worst.iter().take(3).map(|w| w.1).collect();
        let head = format!(
            "On paper, the assessed profile and Rk construction of {} of {n} lines, those nearest to or beyond the specification's limits, worst first (",
            printed.len()
        );
        let at = flat.find(&head).expect("why the lines were chosen, said") + head.len();
        let mut said = &flat[at..flat[at..].find("); every line's figure").unwrap() + at];
        for i in &printed {
            let label = format!("line {} ({i:04}): ", i + 1);
            assert!(said.starts_with(&label), "{label} next in {said}");
            said = said.split_once("; ").map_or("", |s| s.1);
        }
        printed
    };
    for l in lines_json {
        let i = l["index"].as_u64().unwrap();
        let caption = format!("Line {} ({i:04}, y =", i + 1);
        assert_eq!(
            flat.contains(&caption),
            printed.contains(&i),
            "{caption}: printed only for the lines chosen"
        );
    }
    // What the print leaves out is named once, in the sentence that says where it is.
    let left_out = &flat[flat
        .find("Not printed, in report.html: ")
        .expect("what is left out")..];
    for table in [
        "material ratio as the SJ series reads it",
        "over the whole evaluation length",
    ] {
        assert_eq!(
            flat.matches(table).count(),
            1,
            "{table}: named, not printed"
        );
        assert!(left_out.contains(table), "{table}");
    }
    // No heading is the last line of a page: each goes with what it heads.
    let headings = headings(&html);
    for (k, page) in text.split('\u{c}').take(pages).enumerate() {
        let footer = format!("page {} of {pages}", k + 1);
        let body: Vec<String> = page
            .lines()
            .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
            .filter(|l| !l.is_empty() && !l.contains(&footer))
            .collect();
        let last = body.last().map_or("", String::as_str);
        // A heading may wrap: its last line ends it.
        assert!(
            !headings.iter().any(|h| h.ends_with(last) && last.len() > 3),
            "page {}: the heading {last:?} ends the page",
            k + 1
        );
    }
    let approval = text.rfind("Approval").expect("the signature block");
    let mut at = approval;
    for r in roles {
        at += text[at..]
            .find(r)
            .unwrap_or_else(|| panic!("no {r} after Approval"));
    }
    size
}

/// A station configuration for `analyze --config`: `base` with its `[report]` table replaced.
pub fn with_report_table(base: &str, table: &str) -> String {
    let start = base.find("[report]").expect("a [report] table");
    let end = base[start + 1..]
        .find("\n[")
        .map_or(base.len(), |i| start + 1 + i + 1);
    format!("{}{table}\n{}", &base[..start], &base[end..])
}

#[test]
fn a_report_table_is_replaced_whole() {
    let base = "[a]\nx = 1\n\n[report]\nlab = \"A\"\npaper = \"A4\"\n\n[b]\ny = 2\n";
    let got = with_report_table(base, "[report]\nlab = \"B\"\n");
    assert_eq!(got, "[a]\nx = 1\n\n[report]\nlab = \"B\"\n\n[b]\ny = 2\n");
    let tail = "[a]\nx = 1\n[report]\nlab = \"A\"\n";
    assert_eq!(
        with_report_table(tail, "[report]\nlab = \"B\"\n"),
        "[a]\nx = 1\n[report]\nlab = \"B\"\n\n"
    );
}

#[test]
fn printed_tables_leave_out_the_collapsed_ones() {
    let html = "<table id=\"a\"><thead><tr><th>x &amp; y</th><th class=\"t\">b <span>µm</span></th></tr></thead></table>\
<details><summary>all</summary><table id=\"b\"><thead><tr><th>z</th></tr></thead></table></details>\
<table id=\"c\"><tr><th>k</th><td>v</td></tr></table>";
    assert_eq!(
        printed_tables(html),
        vec![(
            "a".to_string(),
            vec!["x & y".to_string(), "b µm".to_string()]
        )]
    );
}
