//! The printed report: what `report.html` adds for paper — the page (A4 or Letter, margins,
//! "page X of Y" and the report's name in the CSS paged-media margin boxes, which Chromium
//! prints), the laboratory's header from `[report]`, the print rules (tables repeat their
//! heading rows and keep rows whole, figures stay whole, what only a screen can use is left
//! out) and the signature block a metrologist signs.
//!
//! The page's running header and footer are CSS strings: the report's words are escaped for
//! a CSS string inside a `<style>` element ([`css_string`]).
//!
//! Layer 4 (reporting): depends on [`super::html`]'s escaping and figures; returns text.

use super::html::{esc, Figure};
use crate::numfmt::{fmt, Quantity};
use serde_json::Value;
use std::fmt::Write as _;

/// `s` as a CSS string literal (quotes included) that is safe inside `<style>`: quotes,
/// backslashes, line breaks and `<` (which could close the element) as CSS escapes.
pub fn css_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' | '\\' | '<' | '>' | '&' => {
                let _ = write!(out, "\\{:x} ", c as u32);
            }
            '\n' | '\r' => out.push(' '),
            c if c.is_control() => {}
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// The page rules and the print media rules: `title` runs along the top of every page,
/// the laboratory (when `[report]` names one) on the left, "page X of Y" at the bottom.
pub fn page_style(report: &Value, title: &str) -> String {
    // Letter, 17.6 mm shorter, has 6 mm less margin at top and bottom (text block 258 mm, A4's
    // 264); the running texts sit against the text block, clear of a printer's unprinted edge.
    let (size, margin) = match report["lab"]["paper"].as_str() {
        Some("Letter") => ("letter", "10mm 13mm 11mm"),
        _ => ("A4", "16mm 13mm 17mm"),
    };
    let (left, software) = running(report);
    format!(
        "@page{{size:{size};margin:{margin} 13mm;\
@top-left{{content:{left};font-size:8pt;color:#555;vertical-align:bottom}}\
@top-right{{content:{title};font-size:8pt;color:#555;vertical-align:bottom}}\
@bottom-left{{content:{software};font-size:7pt;color:#777;vertical-align:top}}\
@bottom-right{{content:\"page \" counter(page) \" of \" counter(pages);font-size:8pt;vertical-align:top}}}}\n\
@media print{{\
body{{max-width:none;margin:0;padding:0;font-size:9pt;line-height:1.3}}\
h1{{font-size:14pt}}h2{{font-size:11pt;margin-top:1.1em}}h2,h3,figcaption{{break-after:avoid}}\
table{{font-size:7.5pt;line-height:1.15;margin:.4em 0}}th,td{{padding:0 .3em}}\
thead{{display:table-header-group}}tr{{break-inside:avoid}}\
.scroll{{overflow:visible}}\
figure{{break-inside:avoid;margin:.5em 0}}img{{max-height:70mm;max-width:100%}}\
.areal-figures{{gap:.5em}}.areal-figures figure{{flex:1 1 30%;min-width:0}}.areal-figures img{{max-height:48mm}}\
details:not(.print),.noprint{{display:none}}\
details.print{{display:inline-block;width:32.5%;vertical-align:top}}details.print::details-content{{content-visibility:visible;display:block}}details.print>summary{{list-style:none;font-weight:bold}}\
.keep{{break-inside:avoid}}.printonly{{display:block}}#blank-reasons{{columns:2;column-gap:1.5em;font-size:8pt}}\
.signatures{{break-inside:avoid;margin-top:1.5em}}\
.lab-header{{border-bottom:1px solid #999}}\
}}\n",
        left = css_string(left),
        title = css_string(title),
        software = css_string(&software),
    )
}

/// The words the page runs with besides its title: the laboratory (or "Surface report")
/// at the top left, the software that wrote it at the bottom left.
pub fn running(report: &Value) -> (&str, String) {
    let left = report["lab"]["lab"]
        .as_str()
        .filter(|s| !s.is_empty())
        .unwrap_or("Surface report");
    let software = report["software"].as_str().unwrap_or("surfscan");
    (left, format!("written by {software}"))
}

/// The laboratory's header (name, address lines, logo) when `[report]` names a laboratory
/// or a logo; empty otherwise.
pub fn lab_header(report: &Value, logo: Option<&Figure>) -> String {
    let [name, address] = ["lab", "address"].map(|k| report["lab"][k].as_str().unwrap_or(""));
    if name.is_empty() && address.is_empty() && logo.is_none() {
        return String::new();
    }
    let mut h = String::from("<header class=\"lab-header\" id=\"lab-header\">");
    if let Some(f) = logo {
        let _ = write!(
            h,
            "<img class=\"logo\" alt=\"{} logo\" src=\"{}\">",
            esc(name),
            f.data_uri()
        );
    }
    h.push_str("<div>");
    if !name.is_empty() {
        let _ = write!(h, "<div class=\"lab-name\">{}</div>", esc(name));
    }
    for l in address.lines().filter(|l| !l.trim().is_empty()) {
        let _ = write!(h, "<div class=\"muted\">{}</div>", esc(l.trim()));
    }
    h.push_str("</div></header>\n");
    h
}

/// The signature block: one row per role of `[report] signatures` with room for the name,
/// the signature and the date; empty when the list is.
pub fn signatures(report: &Value) -> String {
    let roles: Vec<&str> = report["lab"]["signatures"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default();
    if roles.is_empty() {
        return String::new();
    }
    let mut h = String::from(
        "<section class=\"signatures\" id=\"signatures\">\n<h2 id=\"approval\">Approval</h2>\n<table id=\"t-signatures\">\n<thead><tr><th class=\"t\">role</th><th class=\"t\">name</th><th class=\"t\">signature</th><th class=\"t\">date</th></tr></thead>\n",
    );
    for r in roles {
        let _ = writeln!(
            h,
            "<tr class=\"sign\"><td class=\"t\">{}</td><td></td><td></td><td></td></tr>",
            esc(r)
        );
    }
    h.push_str("</table>\n</section>\n");
    h
}

/// A time for people: an RFC 3339 time to the second (`2026-11-30 10:15:00 UTC`, or with
/// its offset when not UTC); the text as given when it is not one.
pub fn to_the_second(s: &str) -> String {
    match chrono::DateTime::parse_from_rfc3339(s) {
        Ok(t) if t.offset().local_minus_utc() == 0 => t.format("%Y-%m-%d %H:%M:%S UTC").to_string(),
        Ok(t) => t.format("%Y-%m-%d %H:%M:%S %:z").to_string(),
        Err(_) => s.to_string(),
    }
}

/// The lines whose assessed profile and Rk construction a print shows, by file index, each
/// with the words naming it and why, and how they were chosen. Against a specification, the
/// three nearest to or beyond its limits, worst first (by value ÷ limit for an upper limit,
/// limit ÷ value for a lower one, a line's worst limit counting): the lines a verdict turns
/// on. Without one, those of largest, median (the lower of two) and smallest Ra, each once:
/// the lines that bound the result. Every line when there are at most three. The rest are
/// in `report.html` (opened on screen) and in `rk/NNNN.svg` beside it.
pub fn printed_lines(report: &Value) -> (Vec<(u32, String)>, &'static str) {
    let lines = report["lines"].as_array().map_or(&[][..], Vec::as_slice);
    // The lines `key` gives a value, largest first (equal ones in line order), with its words.
    let ranked = |key: &dyn Fn(&Value) -> Option<(f64, String)>| {
        let mut r: Vec<(f64, u32, String)> = (lines.iter())
            .filter_map(|l| Some((key(l)?, l["index"].as_u64()?.try_into().ok()?)))
            .map(|((k, why), i)| (k, i, why))
            .collect();
        r.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        r
    };
    let label = crate::numfmt::line_label;
    let worst = ranked(&|l| nearest_limit(report, l));
    if !worst.is_empty() {
        let out = worst.into_iter().take(3);
        let out = out.map(|(_, i, why)| (i, format!("line {}: {why}", label(i))));
        let how = ", those nearest to or beyond the specification's limits, worst first";
        return (out.collect(), how);
    }
    let ra = ranked(&|l| Some((l["Ra_um"].as_f64()?, String::new())));
    let n = ra.len();
    let mut out: Vec<(u32, String)> = Vec::with_capacity(3);
    for (k, why) in [
        (0, "largest"),
        (n / 2, "median"),
        (n.max(1) - 1, "smallest"),
    ] {
        if let Some(&(_, i, _)) = ra.get(k).filter(|r| out.iter().all(|p| p.0 != r.1)) {
            out.push((i, format!("{why} Ra: line {}", label(i))));
        }
    }
    (out, "")
}

/// How near `line` comes to the specification's limits: the largest value ÷ limit (upper) or
/// limit ÷ value (lower; ∞ for a 0, the worst) over the limits, above 1 beyond it, and the
/// words ("Rz 22.06 µm against Rz1 max 12.5"); `None` without a limit the line has a value for.
/// Rk, Rpk and Rvk are read as the recipe's material ratio reading reads them.
fn nearest_limit(report: &Value, line: &Value) -> Option<(f64, String)> {
    let sj = report["recipe"]["material_ratio"] == "instrument";
    (report["specification"]["limits"].as_array()?.iter())
        .filter_map(|c| {
            let p = c["parameter"].as_str()?;
            let reading = match p {
                "Rk" | "Rpk" | "Rvk" if sj => &line["material_ratio_sj_series"],
                _ => line,
            };
            let v = reading[format!("{p}_um")].as_f64()?;
            let limit = c["limit_um"].as_f64()?;
            let share = if c["side"] == "lower" {
                limit / v
            } else {
                v / limit
            };
            let callout = c["callout"].as_str()?;
            let why = format!("{p} {} µm against {callout}", fmt(v, Quantity::HeightUm));
            (!share.is_nan()).then_some((share, why))
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

/// The sentence above the per-line figures saying which of them a print shows and why (none
/// when no line is chosen).
pub fn printed_lines_sentence(report: &Value) -> Option<String> {
    let n = report["lines"].as_array().map_or(0, Vec::len);
    let (printed, how) = printed_lines(report);
    let which: Vec<&str> = printed.iter().map(|p| p.1.as_str()).collect();
    (!which.is_empty()).then(|| format!(
        "On paper, the assessed profile and Rk construction of {} of {n} lines{how} ({}); every line's figure is in report.html and in rk/ beside it.",
        which.len(),
        which.join("; ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_printed_lines_are_the_worst_against_the_specification_or_those_that_bound_ra() {
        let lines = |ra: &[f64]| {
            let l: Vec<Value> = (ra.iter().enumerate())
                .map(|(i, r)| json!({"index": i + 10, "Ra_um": r, "Rz_um": 10.0 - r}))
                .collect();
            json!({ "lines": l })
        };
        let indices = |r: &Value| printed_lines(r).0.iter().map(|p| p.0).collect::<Vec<_>>();
        let five = lines(&[3.0, 1.0, 5.0, 2.0, 4.0]);
        assert_eq!(indices(&five), [12, 10, 11]);
        // Of an even count, the lower middle value; equal values by line order; each once.
        assert_eq!(indices(&lines(&[1.0, 2.0, 2.0, 4.0])), [13, 12, 10]);
        assert_eq!(indices(&lines(&[1.0, 2.0])), [11, 10]);
        assert_eq!(indices(&lines(&[])), [0u32; 0]);
        assert_eq!(printed_lines_sentence(&json!({})), None);
        let s = printed_lines_sentence(&five).unwrap();
        assert!(s.contains("3 of 5 lines (largest Ra: line 13 (0012); median Ra: line 11 (0010); smallest Ra: line 12 (0011))"), "{s}");
        // Against Ra ≤ 1, Rz ≤ 10 and Rpk ≥ 2: line 15's Rpk 1.25 in the SJ series' reading
        // the recipe asks for (2 ÷ 1.25 = 1.6; ISO's 4 would be within), line 12's Ra 1.2,
        // line 14's Rz 9.9 (0.99); without a limit any line has a value for, by Ra.
        let mut r = lines(&[0.5, 1.2, 0.2, 0.1, 0.3]);
        r["lines"][4]["Rpk_um"] = json!(4.0);
        r["lines"][4]["material_ratio_sj_series"] = json!({"Rpk_um": 1.25});
        r["recipe"] = json!({"material_ratio": "instrument"});
        let limit = |c: &str, p: &str, side: &str, l: f64| json!({"callout": c, "parameter": p, "side": side, "limit_um": l});
        r["specification"]["limits"] = json!([
            limit("Ra 1", "Ra", "upper", 1.0),
            limit("Rz max 10", "Rz", "upper", 10.0),
            limit("L Rpk 2", "Rpk", "lower", 2.0)
        ]);
        let (printed, how) = printed_lines(&r);
        assert_eq!(indices(&r), [14, 11, 13]);
        assert_eq!(printed[0].1, "line 15 (0014): Rpk 1.250 µm against L Rpk 2");
        assert_eq!(
            printed[2].1,
            "line 14 (0013): Rz 9.900 µm against Rz max 10"
        );
        assert!(how.contains("nearest to or beyond the specification's limits, worst first"));
        let s = printed_lines_sentence(&r).unwrap();
        assert!(s.contains("3 of 5 lines, those nearest"), "{s}");
        r["lines"][2]["material_ratio_sj_series"] = json!({"Rpk_um": 0.0});
        // Rpk 0 under L Rpk 2 is beyond it without end: the worst, not skipped.
        assert_eq!(indices(&r), [12, 14, 11]);
        r["specification"]["limits"] = json!([limit("Rc 1", "Rc", "upper", 1.0)]);
        assert_eq!(printed_lines(&r).0[0].1, "largest Ra: line 12 (0011)");
    }

    #[test]
    fn css_strings_cannot_leave_the_string_or_the_style_element() {
        assert_eq!(css_string("Lab \"A\""), "\"Lab \\22 A\\22 \"");
        let s = css_string("</style><script>x</script>\\\n");
        assert!(!s.contains('<') && !s.contains('\n'), "{s}");
        assert_eq!(s.matches('"').count(), 2, "{s}");
    }

    #[test]
    fn the_page_follows_the_paper_and_numbers_its_pages() {
        let letter = page_style(&json!({"lab": {"lab": "Lab", "paper": "Letter"}}), "scan 1");
        assert!(letter.contains("size:letter;margin:10mm 13mm 11mm 13mm;"));
        assert!(letter.contains("counter(page) \" of \" counter(pages)"));
        assert!(letter.contains("content:\"Lab\""));
        let a4 = page_style(&json!({}), "scan 1");
        assert!(a4.contains("size:A4;margin:16mm") && a4.contains("content:\"Surface report\""));
    }

    #[test]
    fn the_header_and_the_signatures_follow_the_report_table() {
        let r = json!({"lab": {"lab": "Lab <1>", "address": "1 Road\nTown", "signatures": ["Measured by", "Approved by"]}});
        let h = lab_header(&r, None);
        assert!(h.contains("Lab &lt;1&gt;") && h.contains(">Town<"), "{h}");
        assert_eq!(lab_header(&json!({"lab": {"lab": ""}}), None), "");
        let s = signatures(&r);
        assert_eq!(s.matches("class=\"sign\"").count(), 2);
        assert!(s.find("Measured by").unwrap() < s.find("Approved by").unwrap());
        assert_eq!(signatures(&json!({"lab": {"signatures": []}})), "");
    }

    #[test]
    fn times_for_people_stop_at_the_second() {
        assert_eq!(
            to_the_second("2026-11-30T10:15:00.123456789Z"),
            "2026-11-30 10:15:00 UTC"
        );
        assert_eq!(
            to_the_second("2026-11-30T10:15:00.9+01:00"),
            "2026-11-30 10:15:00 +01:00"
        );
        assert_eq!(to_the_second("not a time"), "not a time");
    }
}
