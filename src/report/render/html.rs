//! `report.html`: the report a person opens. One self-contained file (styles inline, the
//! plots embedded as data URIs, no script, nothing fetched; a Content-Security-Policy says
//! so to the browser), rendered from the report as `report.json` holds it and, for a scan,
//! the journal's record of what happened during it.
//!
//! Order, most urgent first: the laboratory's header (`[report]`); the result in brief; the
//! warnings that qualify it; traceability; what happened
//! during the scan (interruptions, re-traces, resumes, the stop); the plots; the areal
//! parameters of the model and of the measured grid; the per-line ISO parameters (one table
//! per parameter family, so each fits a page); the instrument's own results beside ours in
//! one sentence with the exceptions (every comparison in a collapsed table); the model
//! checked against data it was not fitted to; the recipe every number was computed with; the
//! signature block. [`super::print`] lays it out for paper. Numbers carry the
//! significant digits of their quantity ([`crate::numfmt`]); line numbers are 1-based with
//! the index of the files they are stored in; `report.json` keeps full precision.
//!
//! The renderer reads the serialized report (its field names are the report's documented
//! contract), so every field any section adds is there to show without a second data model.
//!
//! Layer 4 (reporting): depends on the scan's journal records ([`crate::scan::journal`]),
//! [`crate::specification`] (a mean and its s.d.) and [`crate::numfmt`]; returns text, the
//! caller writes it.

use super::print;
use crate::metrology::parameter_table::{parameter, Parameter, Scaling, Source, AREAL, PARAMETERS};
use crate::numfmt::{duration, fmt, line_number, sig, Quantity};
use crate::scan::journal::ResumeState;
use crate::specification::uncertainty::{statistics, InstrumentUncertainty};
use base64::Engine as _;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::Path;

/// One plot to embed: a title, and the PNG or SVG bytes with their media type.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Figure {
    /// Caption shown above the image (and its alt text).
    pub title: String,
    /// `image/png` or `image/svg+xml`.
    pub media_type: &'static str,
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// Shown collapsed (the per-line figures) rather than open.
    pub collapsed: bool,
    /// On paper: an open figure only when set; a collapsed one (a per-line figure) too, those
    /// of the lines [`print::printed_lines`] names.
    pub printed: bool,
    /// Not embedded but linked: the figure's file, relative to the report (`bytes` is then
    /// empty). Per-line figures beyond what a page of a few MB holds are linked.
    pub link: Option<String>,
    /// Shown beside the areal parameters (the PSD, the ACF, the 3D view) rather than with
    /// the plots.
    pub beside_areal: bool,
}

impl Figure {
    /// A plot read from disk: its SVG file when `vector` and there is one, else the smaller of
    /// its PNG and SVG files (text-heavy plots are smaller as SVG, maps as PNG); `None` when
    /// neither can be read.
    pub fn from_files(
        title: impl Into<String>,
        png: &Path,
        svg: &Path,
        vector: bool,
    ) -> Option<Figure> {
        let svg = std::fs::read(svg).ok();
        let png = (!vector || svg.is_none()).then(|| std::fs::read(png).ok());
        let (media_type, bytes) = match (png.flatten(), svg) {
            (Some(p), Some(s)) if s.len() < p.len() => ("image/svg+xml", s),
            (Some(p), _) => ("image/png", p),
            (None, Some(s)) => ("image/svg+xml", s),
            (None, None) => return None,
        };
        Some(Figure {
            title: title.into(),
            media_type,
            bytes,
            ..Figure::default()
        })
    }

    /// The figure's bytes as a `data:` URI, for an `<img>` element's `src`.
    pub fn data_uri(&self) -> String {
        let data = base64::engine::general_purpose::STANDARD.encode(&self.bytes);
        format!("data:{};base64,{data}", self.media_type)
    }
}

/// Text escaped for HTML and XML element content and attribute values (`report.html`, the
/// QIF document); control characters other than newline and tab, which XML does not allow,
/// are left out.
pub fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if c.is_control() && c != '\n' && c != '\t' => {}
            c => out.push(c),
        }
    }
    out
}

const STYLE: &str = "
body{font-family:'DejaVu Sans',Verdana,sans-serif;margin:2em auto;max-width:1150px;padding:0 1em;color:#222;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.2em}h2{font-size:1.25em;margin-top:1.8em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}
th,td{border:1px solid #ccc;padding:.2em .5em;text-align:right;vertical-align:top}
th{background:#f2f2f2}td.t,th.t{text-align:left}
.warn{background:#fff4e5;border-left:4px solid #d55e00;padding:.5em 1em}
.ok{background:#eef7f1;border-left:4px solid #009e73;padding:.5em 1em}
.bad{background:#fdecea;border-left:4px solid #b2182b;padding:.5em 1em}
.flag{color:#b00;font-weight:bold}.muted{color:#666}
figure{margin:1em 0}figcaption{font-weight:bold;margin-bottom:.3em}
.areal-figures{display:flex;flex-wrap:wrap;gap:1em}.areal-figures figure{flex:1 1 45%;min-width:320px;margin:0}
img{max-width:100%;height:auto;border:1px solid #ddd}
.scroll{overflow-x:auto}summary{cursor:pointer;margin:.3em 0}
h3{font-size:1em;margin:.8em 0 .2em}
.lab-header{display:flex;gap:1em;align-items:center;margin-bottom:.6em;padding-bottom:.4em}
.lab-header img.logo{max-height:18mm;max-width:50mm;border:none}.lab-name{font-weight:bold;font-size:1.15em}
tr.sign td{height:2.6em;min-width:10em}.printonly{display:none}
";

/// The tolerance of the instrument-vs-ours flag for a unit: 2 % of the instrument's value,
/// at least 0.005 µm, 1 % point or 0.05 (dimensionless) — about what the instrument's
/// display resolution and the filter's end treatment account for.
pub fn tolerance(instrument: f64, unit: &str) -> f64 {
    (0.02 * instrument.abs()).max(quantity(unit).2)
}

/// The digits, the unit as people read it and the floor of the [`tolerance`] of an
/// instrument's value in `unit`.
fn quantity(unit: &str) -> (Quantity, &str, f64) {
    match unit {
        "um" | "µm" => (Quantity::HeightUm, "µm", 0.005),
        "%" => (Quantity::Percent, unit, 1.0),
        _ => (Quantity::Ratio, unit, 0.05),
    }
}

/// Mean and sample standard deviation as the uncertainty section makes them (NaN for no
/// values, a s.d. of 0 for one).
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let none = InstrumentUncertainty::default();
    match statistics(v.iter().copied(), Scaling::Other, &none) {
        Some(s) => (s.mean, s.s.unwrap_or(0.0)),
        None => (f64::NAN, f64::NAN),
    }
}

/// A line as a person names it: `3` and the index of its files, `0002`.
fn line_label(index: u64) -> String {
    let number = u32::try_from(index).map_or(index + 1, line_number);
    format!("{number} <span class=\"muted\">({index:04})</span>")
}

fn text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Null => String::new(),
        v => v.to_string(),
    }
}

fn num(v: &Value, q: Quantity) -> String {
    v.as_f64().map(|x| fmt(x, q)).unwrap_or_default()
}

fn kv(h: &mut String, key: &str, value_html: &str) {
    let _ = writeln!(
        h,
        "<tr><th class=\"t\">{}</th><td class=\"t\">{value_html}</td></tr>",
        esc(key)
    );
}

fn row(h: &mut String, cells: &[(&str, String)]) {
    h.push_str("<tr>");
    for (class, c) in cells {
        if class.is_empty() {
            let _ = write!(h, "<td>{c}</td>");
        } else {
            let _ = write!(h, "<td class=\"{class}\">{c}</td>");
        }
    }
    h.push_str("</tr>\n");
}

/// The per-line tables, one per parameter family (so that each fits a printed page):
/// element id, heading, columns.
const LINE_FAMILIES: &[(&str, &str, std::ops::Range<usize>)] = &[
    ("t-lines", "amplitude", 0..10),
    ("t-lines-spacing", "spacing and slope", 10..16),
    ("t-lines-material", "material ratio (ISO 13565-2)", 16..25),
    (
        "t-lines-sj",
        "material ratio as the SJ series reads it (ordinates counted, 100-level curve)",
        25..33,
    ),
    (
        "t-lines-ln",
        "over the whole evaluation length (ISO 21920-2) beside the sampling-length means",
        33..41,
    ),
];

/// Per-line columns, report key, heading and quantity: every parameter of the table, then
/// the SJ series' reading of the material-ratio family, then Ra, Rq, Rsk and Rku over the
/// whole evaluation length each beside its sampling-length mean.
fn line_columns() -> Vec<(String, String, Quantity)> {
    let column = |p: &Parameter| (p.key.to_owned(), p.heading(), p.quantity);
    let mut columns: Vec<_> = PARAMETERS.iter().map(column).collect();
    for p in PARAMETERS {
        if let Source::Family(_) = p.source {
            // Its percentages to three decimals, as the instrument prints them.
            let q = match p.quantity {
                Quantity::Percent => Quantity::InstrumentPercent,
                q => q,
            };
            let key = format!("material_ratio_sj_series.{}", p.key);
            columns.push((key, p.heading(), q));
        }
    }
    for p in ["Ra", "Rq", "Rsk", "Rku"].into_iter().filter_map(parameter) {
        let key = p
            .key
            .replacen(p.stem(), &format!("evaluation_length.{}_ln", p.stem()), 1);
        let head = format!("{} ln {}", p.name, p.unit).trim_end().to_owned();
        columns.extend([(key, head, p.quantity), column(p)]);
    }
    columns
}

/// The recipe's name of the parameter a column's `key` holds (`Rk_um` and
/// `material_ratio_sj_series.Rk_um` → `Rk`): its definition id and its blank reason's name.
/// `None` for a value the table does not define (`evaluation_length.Ra_ln_um`).
fn stem(key: &str) -> Option<&'static str> {
    let member = key.rsplit('.').next().unwrap_or(key);
    PARAMETERS
        .iter()
        .find(|p| p.key == member)
        .map(Parameter::stem)
}

/// The value at `key` of `v`, a `.` stepping into a member (`evaluation_length.Rq_ln_um`).
fn field<'a>(v: &'a Value, key: &str) -> &'a Value {
    key.split('.').fold(v, |v, k| &v[k])
}

/// The model's verdict (whether the data support the surface between the lines) in short,
/// where the report carries one.
pub fn verdict(report: &Value) -> Option<String> {
    report["between_lines"]["summary"]
        .as_str()
        .filter(|s| !s.is_empty())
        .map(str::to_owned)
}

/// The result in a few `(what, value)` pairs: lines characterised (of those planned), the
/// Ra range with mean and s.d., Sa of the model and of the measured grid, the verdict.
pub fn result_summary(report: &Value) -> Vec<(&'static str, String)> {
    let mut out = Vec::new();
    if let Some(v) = report["specification"]["verdict"].as_str() {
        out.push(("verdict", v.to_owned()));
        let limits = &report["specification"]["limits"];
        for l in limits.as_array().into_iter().flatten() {
            out.push((
                "limit",
                format!(
                    "{}: {} ({})",
                    text(&l["callout"]),
                    text(&l["verdict"]),
                    text(&l["reason"])
                ),
            ));
        }
    }
    let ra: Vec<f64> = report["lines"]
        .as_array()
        .map(|l| l.iter().filter_map(|l| l["Ra_um"].as_f64()).collect())
        .unwrap_or_default();
    let planned = report["scan"]["lines_planned"]
        .as_u64()
        .map(|n| format!(" of {n} planned"))
        .unwrap_or_default();
    out.push(("lines", format!("{}{planned} characterised", ra.len())));
    if !ra.is_empty() {
        let ((lo, hi), (m, sd)) = (crate::extremes::min_max(&ra), mean_sd(&ra));
        let [lo, hi, m, sd] = [lo, hi, m, sd].map(|v| fmt(v, Quantity::HeightUm));
        let ra = format!("{lo} … {hi} µm (mean {m} µm, s.d. {sd} µm)");
        out.push(("Ra", ra));
    }
    let table_1: Vec<&str> = report["uncertainty"]["table_1"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default();
    if !table_1.is_empty() {
        out.push(("mean ± s", table_1.join(", ")));
    }
    let sa: Vec<String> = [("model", "surface"), ("measured grid", "surface_grid")]
        .iter()
        .filter_map(|(name, key)| {
            report[*key]["Sa_um"]
                .as_f64()
                .map(|v| format!("{} µm ({name})", fmt(v, Quantity::HeightUm)))
        })
        .collect();
    if !sa.is_empty() {
        out.push(("Sa", sa.join(", ")));
    }
    if let Some(v) = verdict(report) {
        out.push(("model", v));
    }
    out
}

/// What the report is of: the specimen and the scan, or the input.
pub fn title(report: &Value) -> String {
    let t = &report["traceability"];
    match (t["specimen"].as_str(), t["scan_id"].as_str()) {
        (Some(s), Some(id)) if !s.is_empty() => format!("{s} — scan {id}"),
        (_, Some(id)) => format!("scan {id}"),
        _ => text(&report["input"]),
    }
}

/// Renders the report, once. `report` is the report as serialized into `report.json`; `journal`
/// the scan's journal when it could be read; `figures` (open) are embedded in order, then the
/// per-line figures `per_line` gives for the bytes the page takes without them.
pub fn render(
    report: &Value,
    journal: Option<&ResumeState>,
    figures: &[Figure],
    logo: Option<&Figure>,
    per_line: impl FnOnce(usize) -> Vec<Figure>,
) -> String {
    let mut h = String::with_capacity(64 * 1024);
    let title = title(report);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; img-src data:; style-src 'unsafe-inline'\">\n<title>Surface report: {t}</title>\n<style>{STYLE}{page}</style>\n</head>\n<body>\n{header}<h1>Surface report: {t}</h1>\n",
        t = esc(&title),
        page = print::page_style(report, &title),
        header = print::lab_header(report, logo),
    );
    let status = match report["scan"]["status"].as_str() {
        Some(s) => format!("{s} scan"),
        None => text(&report["kind"]),
    };
    // On paper where the origin is not the first point's x = 0 (an X3P file's offsets).
    let offset = report["kind"] == "x3p" || report["x0_mm"].as_f64().is_some_and(|x| x != 0.0);
    let _ = writeln!(
        h,
        "<p class=\"muted\">{} · {} · written by {}</p>\n<p class=\"muted{}\" id=\"positions\">Positions: {}.</p>",
        esc(&text(&report["input"])),
        esc(&status),
        esc(&text(&report["software"])),
        if offset { "" } else { " noprint" },
        esc(&text(&report["positions"]))
    );
    specification(&mut h, report);
    h.push_str("<h2 id=\"result\">Result</h2>\n<table id=\"t-result\">\n");
    for (k, v) in result_summary(report) {
        kv(&mut h, k, &esc(&v));
    }
    h.push_str("</table>\n");
    warnings(&mut h, report);
    uncertainty(&mut h, report);
    traceability(&mut h, report);
    if let Some(j) = journal {
        events(&mut h, j);
    }
    let (areal_figures, others): (Vec<Figure>, Vec<Figure>) =
        figures.iter().cloned().partition(|f| f.beside_areal);
    let at = h.len();
    areal(&mut h, report, &areal_figures);
    lines(&mut h, report);
    instrument(&mut h, report);
    holdout(&mut h, report);
    contact(&mut h, report);
    recipe(&mut h, report);
    let families =
        (LINE_FAMILIES.iter()).filter(|f| report["lines"].is_array() && !on_paper(report, f.0));
    let left_out: Vec<String> = (figures.iter().filter(|f| !f.collapsed && !f.printed))
        .map(|f| format!("the figure “{}”", f.title))
        .chain(families.map(|f| format!("the per-line table “{}”", f.1)))
        .collect();
    if !left_out.is_empty() {
        let _ = writeln!(
            h,
            "<p class=\"printonly\" id=\"left-out\">Not printed, in report.html: {}.</p>",
            left_out.join("; ")
        );
    }
    h.push_str(&print::signatures(report));
    h.push_str("</body>\n</html>\n");
    // The plots go in last, where they stand, so that the per-line figures are given the bytes
    // the rest of the page takes: the page is made once.
    let heading = "<h2 id=\"plots\">Plots</h2>\n";
    let mut plots = String::new();
    embed(&mut plots, &others);
    let per_line = per_line(h.len() + plots.len() + heading.len() * usize::from(!plots.is_empty()));
    if let (false, Some(s)) = (per_line.is_empty(), print::printed_lines_sentence(report)) {
        let _ = writeln!(plots, "<p>{}</p>", esc(&s));
    }
    embed(&mut plots, &per_line);
    if !plots.is_empty() {
        plots.insert_str(0, heading);
    }
    h.insert_str(at, &plots);
    h
}

/// The verdict against the specification, first: what the report is read for.
fn specification(h: &mut String, report: &Value) {
    let spec = &report["specification"];
    let Some(summary) = spec["summary"].as_str() else {
        return;
    };
    let class = match spec["verdict"].as_str() {
        Some("conforms") => "ok",
        Some("does not conform") => "bad",
        _ => "warn",
    };
    let _ = writeln!(
        h,
        "<h2 id=\"verdict\">Verdict</h2>\n<p id=\"p-verdict\" class=\"{class}\"><strong>{}</strong></p>\n<table id=\"t-verdict\">\n<tr><th class=\"t\">limit</th><th class=\"t\">verdict</th><th>values</th><th>beyond</th><th>undecided</th><th>allowed</th><th>min µm</th><th>max µm</th><th>U of a line %</th><th class=\"t\">why</th></tr>",
        esc(summary)
    );
    for l in spec["limits"].as_array().map_or(&[][..], |a| &a[..]) {
        let count = |k: &str| l[k].as_u64().map(|n| n.to_string()).unwrap_or_default();
        let mut why = text(&l["reason"]);
        for d in l["conditions_differ"].as_array().into_iter().flatten() {
            why.push_str("; ");
            why.push_str(&text(d));
        }
        let mut cells = vec![
            ("t", esc(&text(&l["callout"]))),
            ("t", esc(&text(&l["verdict"]))),
        ];
        cells.extend(["n_values", "n_beyond", "n_undecided", "n_allowed"].map(|k| ("", count(k))));
        let (um, pct) = (Quantity::HeightUm, Quantity::Percent);
        for (k, q) in [("min_um", um), ("max_um", um), ("line_u_pct", pct)] {
            cells.push(("", num(&l[k], q)));
        }
        cells.push(("t", esc(&why)));
        row(h, &cells);
    }
    let _ = writeln!(
        h,
        "</table>\n<p class=\"muted\">{} {}</p>",
        esc(&text(&spec["decision_rule"])),
        esc(&text(&spec["instrument_uncertainty"]))
    );
}

/// Every line parameter's mean with its uncertainty; of one line, why there is none.
fn uncertainty(h: &mut String, report: &Value) {
    let u = &report["uncertainty"];
    let params = u["parameters"].as_array().map_or(&[][..], |a| &a[..]);
    if params.is_empty() {
        return;
    }
    h.push_str("<h2 id=\"uncertainty\">Means and their uncertainty</h2>\n");
    let why = if params.iter().all(|p| p["n"].as_u64() < Some(2)) {
        "One line: its values are those of the per-line tables; a mean over lines, their spread s and an uncertainty from it need two lines or more."
    } else {
        h.push_str("<table id=\"t-uncertainty\">\n<tr><th class=\"t\">parameter</th><th>n</th><th>mean</th><th>s</th><th>u of the mean</th><th>u instrument</th><th>u<sub>c</sub></th><th>U (k = 2)</th></tr>\n");
        for p in params {
            let name = text(&p["parameter"]);
            let (label, q) =
                parameter(&name).map_or((name, Quantity::Ratio), |t| (t.heading(), t.quantity));
            let n = p["n"].as_u64().map(|n| n.to_string());
            let mut cells = vec![("t", esc(&label)), ("", n.unwrap_or_default())];
            for k in ["mean", "s", "u_mean", "u_instrument", "u_c", "U"] {
                cells.push(("", num(&p[k], q)));
            }
            row(h, &cells);
        }
        h.push_str("</table>\n");
        "s over the lines, u of the mean s/√n, the instrument's u from its calibration, u<sub>c</sub> combined (GUM), U = 2·u<sub>c</sub>."
    };
    let _ = writeln!(
        h,
        "<p class=\"muted\">{why} {}</p>",
        esc(&text(&u["instrument"]))
    );
}

fn warnings(h: &mut String, report: &Value) {
    h.push_str("<h2 id=\"warnings\">Warnings</h2>\n");
    let mut all: Vec<String> = report["warnings"]
        .as_array()
        .map(|w| w.iter().map(text).collect())
        .unwrap_or_default();
    // A section the line count rules out is said once, in the report's warnings.
    let not_possible = report["characterisation"]["sections_not_possible"].to_string();
    for (what, key) in [
        ("model surface", "surface"),
        ("measured grid", "surface_grid"),
        ("model against measured", "model_vs_measured"),
    ] {
        if let Some(e) = report[format!("{key}_error")].as_str() {
            if !all.iter().any(|w| w.contains(e))
                && !not_possible.contains(&format!("\"section\":\"{key}\""))
            {
                all.push(format!("no {what} results: {e}"));
            }
        }
    }
    if all.is_empty() {
        h.push_str("<p class=\"ok\" id=\"no-warnings\">None.</p>\n");
    } else {
        h.push_str("<div class=\"warn\"><ul id=\"warning-list\">\n");
        for w in &all {
            let _ = writeln!(h, "<li>{}</li>", esc(w));
        }
        h.push_str("</ul></div>\n");
    }
}

fn traceability(h: &mut String, report: &Value) {
    let t = &report["traceability"];
    if t.is_null() {
        return;
    }
    h.push_str("<h2 id=\"traceability\">Traceability</h2>\n<table id=\"t-traceability\">\n");
    let id = esc(&text(&t["scan_id"]));
    kv(h, "scan", &format!("<code>{id}</code>"));
    for k in ["specimen", "operator", "notes"] {
        kv(h, k, &esc(&text(&t[k])));
    }
    let started = print::to_the_second(&text(&t["started_at"]));
    kv(h, "started", &esc(&started));
    match t["finished_at"].as_str() {
        Some(stop) => {
            kv(h, "finished", &esc(&print::to_the_second(stop)));
            // A stop recorded before the start (the clock set back) lasted 0 s.
            if let Some(d) = t["duration_s"].as_f64().and_then(|d| duration(d.max(0.0))) {
                kv(h, "duration", &esc(&d));
            }
        }
        None => kv(
            h,
            "finished",
            "<span class=\"muted\">no stop record (still running, or stopped without one)</span>",
        ),
    }
    let na = "<span class=\"muted\">not recorded</span>";
    let or_na = |v: &Value| {
        let s = text(v);
        if s.is_empty() {
            na.to_string()
        } else {
            esc(&s)
        }
    };
    kv(h, "instrument", &or_na(&t["instrument_model"]));
    kv(h, "manufacturer", &or_na(&t["manufacturer"]));
    kv(h, "serial number", &or_na(&t["instrument_serial"]));
    kv(h, "firmware", &or_na(&t["firmware"]));
    kv(h, "drive unit", &or_na(&t["drive_unit"]));
    let tip_um = t["stylus_tip_radius_um"].as_f64();
    let tip = tip_um.map(|r| sig(r, 3) + " µm");
    kv(h, "stylus tip radius", &or_na(&tip.into()));
    kv(h, "calibration date", &or_na(&t["calibration_date"]));
    let c = &t["conditions"];
    let mut cond = Vec::new();
    if let Some(s) = c["standard"].as_str() {
        cond.push(format!("standard {s}"));
    }
    if let Some(f) = c["filter"].as_str() {
        cond.push(format!("filter {f}"));
    }
    if let Some(l) = c["lambda_c_mm"].as_f64() {
        cond.push(format!("λc {} mm", sig(l, 3)));
    }
    if let Some(l) = c["lambda_s_um"].as_f64() {
        cond.push(format!("λs {} µm", sig(l, 3)));
    }
    match c["sampling_lengths"].as_u64() {
        Some(0) => cond.push("arbitrary evaluation length".into()),
        Some(n) => cond.push(format!("N = {n}")),
        None => {}
    }
    kv(h, "conditions", &or_na(&cond.join(", ").into()));
    kv(h, "scanned by", &or_na(&t["software_version"]));
    let hash = esc(&text(&t["config_hash"]));
    kv(h, "configuration", &format!("sha256 <code>{hash}</code>"));
    h.push_str("</table>\n");
}

fn events(h: &mut String, j: &ResumeState) {
    h.push_str("<h2 id=\"events\">During the scan</h2>\n");
    let retraced: Vec<_> = j.lines.iter().filter(|l| l.id.attempt > 1).collect();
    if j.interruptions.is_empty() && retraced.is_empty() && j.quarantined.is_empty() {
        h.push_str(
            "<p class=\"ok\" id=\"no-events\">No interruption, re-trace, resume or line moved aside: every line was traced on its first attempt.</p>\n",
        );
    } else {
        h.push_str("<table id=\"t-events\">\n<thead><tr><th class=\"t\">time (UTC)</th><th>line</th><th class=\"t\">device</th><th class=\"t\">what</th></tr></thead>\n");
        let mut rows: Vec<(chrono::DateTime<chrono::Utc>, String, String, String)> = j
            .interruptions
            .iter()
            .map(|i| {
                (
                    i.time,
                    i.line.map(|l| line_label(u64::from(l))).unwrap_or_default(),
                    i.device.map(|d| d.name()).unwrap_or("").to_string(),
                    esc(&i.reason),
                )
            })
            .collect();
        // A committed line whose file no longer matched its record when the scan resumed:
        // moved aside (both hashes are in the journal) and traced again. The reason says so.
        rows.extend(j.quarantined.iter().map(|q| {
            (
                q.time,
                line_label(u64::from(q.index)),
                String::new(),
                esc(&format!("{} (now {})", q.reason, q.moved_to)),
            )
        }));
        rows.extend(retraced.iter().map(|l| {
            (
                l.time,
                line_label(u64::from(l.id.index)),
                String::new(),
                format!("traced on attempt {} (re-traced)", l.id.attempt),
            )
        }));
        rows.sort_by_key(|r| r.0);
        for (time, line, dev, what) in rows {
            row(
                h,
                &[
                    ("t", esc(&time.format("%Y-%m-%d %H:%M:%S").to_string())),
                    ("", line),
                    ("t", dev),
                    ("t", what),
                ],
            );
        }
        h.push_str("</table>\n");
    }
    if !j.duplicates.is_empty() {
        let _ = writeln!(
            h,
            "<p>Lines recorded more than once (the first record is used): {}.</p>",
            j.duplicates
                .iter()
                .map(|&i| line_label(u64::from(i)))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some(stop) = &j.stop {
        let _ = writeln!(
            h,
            "<p>Stopped {}: {} ({}).</p>",
            esc(&stop.time.format("%Y-%m-%d %H:%M:%S UTC").to_string()),
            esc(&format!("{:?}", stop.status).to_lowercase()),
            esc(&stop.reason)
        );
    }
}

/// Each figure as an embedded image (or a link to its file), in order.
fn embed(h: &mut String, figures: &[Figure]) {
    for f in figures {
        let img = match &f.link {
            Some(href) => format!(
                "<p class=\"muted\">Not embedded, to keep this page small: <a href=\"{h}\">{h}</a> beside this report.</p>",
                h = esc(href)
            ),
            None => format!("<img alt=\"{}\" src=\"{}\">", esc(&f.title), f.data_uri()),
        };
        if f.collapsed {
            let _ = writeln!(
                h,
                "<details{}><summary>{}</summary><figure>{img}</figure></details>",
                if f.printed { " class=\"print\"" } else { "" },
                esc(&f.title)
            );
        } else {
            let _ = writeln!(
                h,
                "<figure{}><figcaption>{}</figcaption>{img}</figure>",
                if f.printed { "" } else { " class=\"noprint\"" },
                esc(&f.title)
            );
        }
    }
}

fn areal(h: &mut String, report: &Value, figures: &[Figure]) {
    let cols: Vec<(&str, &Value)> = [
        ("model surface", &report["surface"]),
        ("measured grid", &report["surface_grid"]),
    ]
    .into_iter()
    .filter(|(_, v)| v.is_object())
    .collect();
    if cols.is_empty() {
        return;
    }
    h.push_str("<h2 id=\"areal\">Areal parameters (ISO 25178-2)</h2>\n<table id=\"t-areal\">\n<thead><tr><th class=\"t\">parameter</th>");
    for (n, _) in &cols {
        let _ = write!(h, "<th>{n}</th>");
    }
    h.push_str("</tr></thead>\n");
    for p in AREAL {
        let mut cells = vec![("t", esc(p.heading))];
        for (_, s) in &cols {
            cells.push(("", num(field(s, p.key), p.quantity)));
        }
        row(h, &cells);
    }
    h.push_str("</table>\n<ul>\n");
    for (n, s) in &cols {
        let _ = writeln!(h, "<li><b>{n}</b>: {}</li>", esc(&text(&s["recipe"])));
        if let Some(r) = s["bac_curves_recipe"].as_str() {
            let _ = writeln!(h, "<li><b>{n}, bearing curves</b>: {}</li>", esc(r));
        }
        for part in ["functional", "spatial"] {
            if let Some(e) = s[part]["error"].as_str() {
                let _ = writeln!(
                    h,
                    "<li><b>{n}, {part} parameters</b>: not computed: {}</li>",
                    esc(e)
                );
            }
        }
        for (name, why) in s["spatial"]["blank_reasons"]
            .as_object()
            .into_iter()
            .flatten()
        {
            let _ = writeln!(
                h,
                "<li><b>{n}, {}</b> blank: {}</li>",
                esc(name),
                esc(why.as_str().unwrap_or(""))
            );
        }
        for c in s["spatial"]["caveats"].as_array().into_iter().flatten() {
            let _ = writeln!(h, "<li><b>{n}</b>: {}</li>", esc(c.as_str().unwrap_or("")));
        }
    }
    h.push_str("</ul>\n");
    if !figures.is_empty() {
        h.push_str("<div id=\"areal-figures\" class=\"areal-figures\">\n");
        embed(h, figures);
        h.push_str("</div>\n");
    }
}

/// A line's value at `key`, or for a blank one a dash with its reason as the tooltip (the
/// reasons are listed under the tables).
fn blank_or(line: &Value, key: &str, q: Quantity) -> String {
    let v = field(line, key);
    if v.is_number() {
        return num(v, q);
    }
    match stem(key).and_then(|s| line["blank_reasons"][s].as_str()) {
        Some(why) => format!("<span class=\"blank\" title=\"{}\">—*</span>", esc(why)),
        None => String::new(),
    }
}

/// Every blank cell's reason, line by line.
fn blank_reasons(h: &mut String, lines: &[Value]) {
    let mut items = Vec::new();
    for l in lines {
        for (name, why) in l["blank_reasons"].as_object().into_iter().flatten() {
            items.push(format!(
                "<li>line {}: {} — {}</li>",
                line_label(l["index"].as_u64().unwrap_or(0)),
                esc(name),
                esc(why.as_str().unwrap_or(""))
            ));
        }
    }
    if !items.is_empty() {
        let _ = writeln!(
            h,
            "<p>—* a blank value, and why:</p>\n<ul id=\"blank-reasons\">\n{}\n</ul>",
            items.join("\n")
        );
    }
}

/// Whether the per-line family `id` is printed: those a verdict reads (the material ratio in
/// the recipe's reading); the other reading and the whole-length values on screen only.
fn on_paper(report: &Value, id: &str) -> bool {
    let sj = report["recipe"]["material_ratio"] == "instrument";
    match id {
        "t-lines-material" => !sj,
        "t-lines-sj" => sj,
        _ => id != "t-lines-ln",
    }
}

fn lines(h: &mut String, report: &Value) {
    let Some(lines) = report["lines"].as_array() else {
        return;
    };
    h.push_str("<h2 id=\"lines\">Per line (ISO 4287, ISO 13565-2)</h2>\n");
    let definitions = &report["recipe"]["definitions"];
    // A column's definition: its parameter's, the SJ series' reading of it said so.
    let definition = |key: &str| {
        let d = definitions[stem(key)?].as_str()?;
        Some(if key.starts_with("material_ratio_sj_series.") {
            format!("{d}; here as the SJ series reads it (ordinates counted, 100-level curve)")
        } else {
            d.to_owned()
        })
    };
    let all = line_columns();
    for (id, family, range) in LINE_FAMILIES {
        let columns = &all[range.clone()];
        let _ = write!(
            h,
            "<section{}><h3>{family}</h3>\n<div class=\"scroll\"><table id=\"{id}\">\n<thead><tr><th>line</th><th>y mm</th>",
            if on_paper(report, id) { "" } else { " class=\"noprint\"" }
        );
        for (key, head, _) in columns {
            let title = definition(key).map(|d| format!(" title=\"{}\"", esc(&d)));
            let _ = write!(h, "<th{}>{}</th>", title.unwrap_or_default(), esc(head));
        }
        h.push_str("</tr></thead>\n");
        for l in lines {
            let mut cells = vec![
                ("", line_label(l["index"].as_u64().unwrap_or(0))),
                ("", num(&l["y_mm"], Quantity::PositionMm)),
            ];
            for (key, _, q) in columns {
                cells.push(("", blank_or(l, key, *q)));
            }
            row(h, &cells);
        }
        for (name, mean) in [("mean", true), ("s.d.", false)] {
            let mut cells = vec![("t", format!("<b>{name}</b>")), ("", String::new())];
            for (key, _, q) in columns {
                let v: Vec<f64> = lines
                    .iter()
                    .filter_map(|l| field(l, key).as_f64())
                    .collect();
                let (m, sd) = mean_sd(&v);
                let cell = if v.is_empty() {
                    String::new()
                } else {
                    fmt(if mean { m } else { sd }, *q)
                };
                cells.push(("", cell));
            }
            row(h, &cells);
        }
        h.push_str("</table></div></section>\n");
    }
    blank_reasons(h, lines);
    // Rδc and Rmr depend on levels chosen per instrument and recipe: said on the page, not
    // only in a heading's tooltip.
    let levels: Vec<String> = (["Rdc", "Rmr"].into_iter().filter_map(parameter))
        .filter_map(|p| definition(p.key).map(|d| format!("{}: {}", p.name, esc(&d))))
        .collect();
    if !levels.is_empty() {
        let _ = writeln!(h, "<p id=\"line-levels\">{}.</p>", levels.join("; "));
    }
}

/// One comparison of the instrument's result with ours, as the page shows it.
struct Comparison {
    line: String,
    name: String,
    cells: [String; 4],
    /// |ours − instrument| ÷ tolerance, `None` when not compared.
    share: Option<f64>,
    /// |ours − instrument| with its unit.
    abs_diff: String,
}

fn comparisons(lines: &[Value]) -> Vec<Comparison> {
    let mut out = Vec::new();
    for l in lines {
        for c in l["instrument"].as_array().into_iter().flatten() {
            let unit = c["unit"].as_str().unwrap_or("");
            let (q, u, _) = quantity(unit);
            let [inst, ours, diff] = ["instrument", "ours", "difference"].map(|k| c[k].as_f64());
            let tol = inst.map(|i| tolerance(i, unit));
            let name = text(&c["name"]).trim().to_string();
            let name = match c["compared_with"].as_str() {
                Some(w) if !w.eq_ignore_ascii_case(&name) => format!("{name} (ours: {w})"),
                _ => name,
            };
            let with_unit = |v: Option<f64>, q: Quantity| {
                v.map(|v| format!("{} {u}", fmt(v, q))).unwrap_or_default()
            };
            out.push(Comparison {
                line: line_label(l["index"].as_u64().unwrap_or(0)),
                name,
                cells: [
                    with_unit(inst, q),
                    with_unit(ours, q),
                    with_unit(diff, Quantity::Difference),
                    with_unit(tol, Quantity::Difference),
                ],
                share: match (diff, tol) {
                    (Some(d), Some(t)) if t > 0.0 => Some(d.abs() / t),
                    _ => None,
                },
                abs_diff: with_unit(diff.map(f64::abs), Quantity::Difference),
            });
        }
    }
    out
}

fn comparison_table(h: &mut String, id: &str, rows: &[&Comparison]) {
    let _ = write!(
        h,
        "<div class=\"scroll\"><table id=\"{id}\">\n<thead><tr><th>line</th><th class=\"t\">parameter</th><th>instrument</th><th>ours</th><th>ours − instrument</th><th>tolerance</th><th class=\"t\">within</th></tr></thead>\n"
    );
    for c in rows {
        let within = match c.share {
            Some(s) if s <= 1.0 => "yes".to_string(),
            Some(_) => "<span class=\"flag\">NO</span>".to_string(),
            None => "<span class=\"muted\">not compared</span>".to_string(),
        };
        let mut cells = vec![("", c.line.clone()), ("t", esc(&c.name))];
        cells.extend(c.cells.iter().map(|v| ("", v.clone())));
        cells.push(("t", within));
        row(h, &cells);
    }
    h.push_str("</table></div>\n");
}

/// The instrument's results beside ours: one sentence for all of them (how many within the
/// tolerance, the largest difference relative to its tolerance), the exceptions in a table,
/// and every comparison in a collapsed table a screen can open (left off paper).
fn instrument(h: &mut String, report: &Value) {
    let Some(lines) = report["lines"].as_array() else {
        return;
    };
    let all = comparisons(lines);
    if all.is_empty() {
        return;
    }
    h.push_str("<h2 id=\"instrument\">The instrument's results beside ours</h2>\n<p>Flagged when |ours − instrument| exceeds 2 % of the instrument's value, or 0.005 µm, 1 % point or 0.05 for dimensionless parameters, whichever is larger.</p>\n");
    let compared: Vec<&Comparison> = all.iter().filter(|c| c.share.is_some()).collect();
    let within = compared
        .iter()
        .filter(|c| c.share.is_some_and(|s| s <= 1.0))
        .count();
    let flagged = compared.len() - within;
    let largest = compared
        .iter()
        .max_by(|a, b| a.share.unwrap_or(0.0).total_cmp(&b.share.unwrap_or(0.0)));
    let mut sentence = format!("{within} of {} within tolerance", compared.len());
    if let Some(c) = largest {
        let _ = write!(
            sentence,
            "; largest |Δ| relative to its tolerance: {} {} (line {})",
            esc(&c.name),
            c.abs_diff,
            c.line
        );
    }
    let not_compared = all.len() - compared.len();
    if not_compared > 0 {
        let _ = write!(sentence, "; {not_compared} not compared");
    }
    let _ = writeln!(h, "<p id=\"instrument-summary\"><b>{sentence}.</b></p>");
    let exceptions: Vec<&Comparison> = all
        .iter()
        .filter(|c| c.share.is_none_or(|s| s > 1.0))
        .collect();
    if !exceptions.is_empty() {
        h.push_str("<p>The exceptions:</p>\n");
        comparison_table(h, "t-instrument-exceptions", &exceptions);
    }
    let _ = writeln!(
        h,
        "<details class=\"noprint\"><summary>All {} comparisons</summary>",
        all.len()
    );
    comparison_table(h, "t-instrument", &all.iter().collect::<Vec<_>>());
    h.push_str("</details>\n");
    let _ = writeln!(
        h,
        "<p id=\"instrument-flagged\">{flagged} comparison(s) outside the tolerance.</p>"
    );
}

fn holdout(h: &mut String, report: &Value) {
    let m = &report["model_vs_measured"];
    let b = &report["between_lines"];
    if !m.is_object() && !b.is_object() {
        return;
    }
    h.push_str("<h2 id=\"model\">The model against data it was not fitted to</h2>\n");
    if let Some(v) = b["verdict"].as_str() {
        let _ = writeln!(h, "<p id=\"verdict\"><b>{}</b></p>", esc(v));
    }
    let r = &report["model_checks"]["height_range"];
    if let (Some(lo), Some(hi), Some(mlo), Some(mhi), Some(pct)) = (
        r["model_min_um"].as_f64(),
        r["model_max_um"].as_f64(),
        r["measured_min_um"].as_f64(),
        r["measured_max_um"].as_f64(),
        r["overshoot_pct"].as_f64(),
    ) {
        let [lo, hi, mlo, mhi] = [lo, hi, mlo, mhi].map(|v| fmt(v, Quantity::HeightUm));
        let _ = writeln!(
            h,
            "<p id=\"height-range\">Sampled densely, the model spans {lo} … {hi} µm where the measured heights span {mlo} … {mhi} µm ({} % beyond the measured range).</p>",
            fmt(pct, Quantity::Percent)
        );
    }
    let a = &report["anisotropy"];
    if let (Some(ratio), Some(r), Some(share), Some(dom)) = (
        a["pitch_ratio_y_over_x"].as_f64(),
        a["line_correlation_at_pitch_y"].as_f64(),
        a["sdq_y_share_pct"].as_f64(),
        a["dominant"].as_str(),
    ) {
        let _ = writeln!(
            h,
            "<p id=\"anisotropy\">The lines are {} × the x pitch apart; neighbouring lines correlate at r = {}; the slopes along {} dominate Sdq and Sdr ({} % of Sdq² comes from dz/dy, across the lines).</p>",
            sig(ratio, 3),
            sig(r, 2),
            esc(dom),
            fmt(share, Quantity::Percent)
        );
    }
    if !m.is_object() {
        return;
    }
    h.push_str("<table id=\"t-model\">\n<thead><tr><th class=\"t\">left out and predicted</th><th>lines</th><th>largest |model − measured| µm</th><th>largest rms µm</th></tr></thead>\n");
    for (what, key) in [
        ("every 2nd point of each line", "points_left_out"),
        ("every 2nd line", "lines_left_out"),
    ] {
        let v = m[key].as_array().cloned().unwrap_or_default();
        let max = |k: &str| {
            v.iter()
                .filter_map(|l| l[k].as_f64())
                .fold(f64::NAN, f64::max)
        };
        row(
            h,
            &[
                ("t", esc(what)),
                ("", v.len().to_string()),
                ("", fmt(max("max_abs_um"), Quantity::HeightUm)),
                ("", fmt(max("rms_um"), Quantity::HeightUm)),
            ],
        );
    }
    h.push_str("</table>\n");
}

/// The contact section: the load–area curve of the measured grid and, beside it, of the
/// model between lines with the verdict between lines.
fn contact(h: &mut String, report: &Value) {
    let c = &report["contact"];
    if !c.is_object() {
        return;
    }
    h.push_str("<h2 id=\"contact\">Contact with a flat</h2>\n");
    let hardness = c["hardness_gpa"]
        .as_f64()
        .map_or("elastic".to_string(), |v| {
            format!("perfectly plastic at a hardness of {} GPa", sig(v, 4))
        });
    let or_dash = |v: &Value, f: fn(f64) -> String| v.as_f64().map_or("—".to_string(), f);
    let plain: fn(f64) -> String = |v| v.to_string();
    let sig4: fn(f64) -> String = |v| sig(v, 4);
    let body = |b: &Value| {
        let [e, nu] = ["young_gpa", "poisson"].map(|k| or_dash(&b[k], plain));
        format!("E {e} GPa, ν {nu}")
    };
    let counter = match &c["counter_body"] {
        b if b.is_object() => format!("an elastic flat ({})", body(b)),
        _ => "a rigid flat".to_string(),
    };
    let _ = writeln!(
        h,
        "<p id=\"contact-bodies\">The specimen ({}) against {}: composite modulus E* = {} GPa, {}; heights levelled by their least-squares plane.</p>",
        esc(&body(&c["specimen"])),
        esc(&counter),
        or_dash(&c["effective_modulus_gpa"], sig4),
        esc(&hardness)
    );
    let m = &c["model"];
    if let Some(v) = m["verdict"].as_str() {
        let supported = m["supported"].as_bool() == Some(true);
        let _ = writeln!(
            h,
            "<p id=\"contact-verdict\"{}>The model between lines: <b>{}</b>{}</p>",
            if supported { "" } else { " class=\"bad\"" },
            esc(v),
            if supported {
                ""
            } else {
                " The contact of the model below is computed on a surface the data do not support."
            }
        );
    }
    h.push_str("<table id=\"t-contact\">\n<thead><tr><th class=\"t\">surface</th><th>nominal MPa</th><th>area %</th><th>mean gap µm</th><th>mean contact MPa</th><th>patches</th><th>flowing %</th><th class=\"t\">resolved</th></tr></thead>\n");
    for (what, s) in [("measured grid", &c["measured"]), ("model", &m["contact"])] {
        let Some(points) = s["curve"].as_array() else {
            continue;
        };
        let label = format!(
            "{what} ({} × {}, y pitch {} mm)",
            s["rows"].as_u64().unwrap_or(0),
            s["cols"].as_u64().unwrap_or(0),
            or_dash(&s["pitch_y_mm"], sig4)
        );
        for p in points {
            let num = |k: &str| p[k].as_f64().unwrap_or(f64::NAN);
            row(
                h,
                &[
                    ("t", esc(&label)),
                    ("", sig(num("nominal_pressure_mpa"), 4)),
                    ("", fmt(100.0 * num("area_fraction"), Quantity::Percent)),
                    ("", fmt(num("mean_gap_um"), Quantity::HeightUm)),
                    ("", sig(num("mean_contact_pressure_mpa"), 4)),
                    ("", p["patches"].as_u64().unwrap_or(0).to_string()),
                    ("", fmt(100.0 * num("plastic_fraction"), Quantity::Percent)),
                    ("t", if p["resolved"] == true { "yes" } else { "no" }.into()),
                ],
            );
        }
    }
    h.push_str("</table>\n");
    if let Some(e) = c["measured_error"].as_str() {
        let _ = writeln!(
            h,
            "<p class=\"bad\">The measured grid's contact: {}</p>",
            esc(e)
        );
    }
    if let Some(e) = m["error"].as_str() {
        let _ = writeln!(h, "<p class=\"bad\">The model's contact: {}</p>", esc(e));
    }
}

fn recipe(h: &mut String, report: &Value) {
    let r = &report["recipe"];
    h.push_str("<h2 id=\"recipe\">Recipe</h2>\n<table id=\"t-recipe\">\n");
    kv(h, "standard", &esc(&text(&r["standard"])));
    kv(h, "filter", &esc(&text(&r["filter"])));
    kv(h, "why", &esc(&text(&r["filter_reason"])));
    kv(h, "end treatment", &esc(&text(&r["end_treatment"])));
    let lc = r["lambda_c_mm"].as_f64().map(|v| sig(v, 3));
    let lc_source = esc(&text(&r["lambda_c_source"]));
    let lc = format!("{} mm — {lc_source}", lc.unwrap_or_default());
    kv(h, "λc (sampling length)", &lc);
    let ls = r["lambda_s_um"].as_f64().map(|v| sig(v, 3) + " µm");
    let not_applied = "not applied by this software";
    kv(h, "λs", &ls.unwrap_or_else(|| not_applied.into()));
    let (n, rule) = (&r["sampling_lengths"], &r["sampling_lengths_rule"]);
    let n_rule = format!("{} — {}", text(n), esc(&text(rule)));
    kv(h, "sampling lengths N", &n_rule);
    let points = text(&r["points_per_section"]);
    kv(h, "points per sampling length", &points);
    kv(h, "points not evaluated", &text(&r["points_not_evaluated"]));
    let pitch = num(&r["pitch_mm"], Quantity::LengthMm);
    kv(h, "pitch", &format!("{pitch} mm"));
    kv(h, "mean line", &esc(&text(&r["mean_line"])));
    // A single profile has no model between lines to describe.
    let profile = report["kind"] == "profile";
    if !profile {
        kv(h, "surface", &esc(&text(&report["model"]["description"])));
    }
    let spikes = match r["outliers"].as_str() {
        Some("exclude") => "excluded (bridged) from the per-line and measured-grid parameters",
        _ => "flagged only, the data as measured",
    };
    let spikes = format!("{} — {spikes}", text(&r["spike_rule"]));
    kv(h, "spikes", &esc(&spikes));
    if let Some(t) = r["holdout_threshold_sq"].as_f64().filter(|_| !profile) {
        let t = sig(t, 2);
        let rule = format!("supported by the data when the hold-out rms is at most {t} × Sq");
        kv(h, "model between lines", &esc(&rule));
    }
    h.push_str("</table>\n");
    if let Some(defs) = r["definitions"].as_object() {
        h.push_str("<details><summary>Definition of every parameter</summary><table id=\"t-definitions\">\n");
        for (k, v) in defs {
            kv(h, k, &esc(&text(v)));
        }
        h.push_str("</table></details>\n");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_per_line_families_hold_every_column_once_in_order() {
        let mut next = 0;
        for (_, _, r) in LINE_FAMILIES {
            assert_eq!(r.start, next);
            assert!(r.len() <= 10, "a family of at most 10 columns fits a page");
            for (k, _, _) in &line_columns()[r.clone()] {
                let stem = k.split('.').next().unwrap();
                assert!(
                    stem == *k || ["material_ratio_sj_series", "evaluation_length"].contains(&stem),
                    "{k}"
                );
            }
            next = r.end;
        }
        assert_eq!(next, line_columns().len());
    }

    #[test]
    fn the_instrument_comparison_is_one_sentence_and_its_exceptions() {
        let cmp = |name: &str, inst: f64, ours: f64| serde_json::json!({"name": name, "unit": "um", "instrument": inst, "ours": ours, "difference": ours - inst});
        let report = serde_json::json!({"lines": [
            {"index": 0, "instrument": [cmp("Ra", 1.0, 1.001), cmp("Rz", 5.0, 5.5)]},
            {"index": 1, "instrument": [cmp("Ra", 1.0, 1.0005), {"name": "RzJIS", "unit": "um", "instrument": null}]},
        ]});
        let mut h = String::new();
        instrument(&mut h, &report);
        assert!(
            h.contains("2 of 3 within tolerance; largest |Δ| relative to its tolerance: Rz 0.5"),
            "{h}"
        );
        assert!(h.contains("; 1 not compared."), "{h}");
        let exceptions =
            &h[h.find("t-instrument-exceptions").unwrap()..h.find("<details").unwrap()];
        assert_eq!(exceptions.matches("<tr>").count(), 1 + 2, "{exceptions}");
        assert!(
            exceptions.contains("Rz")
                && exceptions.contains("RzJIS")
                && !exceptions.contains(">Ra<")
        );
        assert!(h.contains("All 4 comparisons"));
    }

    #[test]
    fn text_is_escaped() {
        assert_eq!(
            esc("<B&S> \"x\" 'y'"),
            "&lt;B&amp;S&gt; &quot;x&quot; &#39;y&#39;"
        );
    }

    #[test]
    fn the_tolerance_has_a_floor_per_unit() {
        assert_eq!(tolerance(10.0, "um"), 0.2);
        assert_eq!(tolerance(0.1, "um"), 0.005);
        assert_eq!(tolerance(50.0, "%"), 1.0);
        assert_eq!(tolerance(0.2, ""), 0.05);
    }

    /// Every single-number parameter a line carries in report.json has a column in the
    /// per-line table, and every column names a key the line has: a parameter added to the
    /// report, or a key misspelt here, would otherwise leave the table short or blank.
    #[test]
    fn the_line_table_shows_every_scalar_line_parameter() {
        // 4 mm of a 0.1 mm-period wave with a second tone, 0.5 µm pitch: every parameter,
        // RSm and its element family included, has a value.
        let heights: Vec<f64> = (0..8000)
            .map(|k| {
                let x = k as f64 * 0.0005;
                (x / 0.1 * std::f64::consts::TAU).sin() + 0.3 * (x / 0.037).cos()
            })
            .collect();
        let a = crate::metrology::params::analyze_line(
            &heights,
            0.0005,
            &crate::metrology::params::Options::default(),
        )
        .unwrap();
        let params = serde_json::to_value(&a.params).unwrap();
        let params = params.as_object().unwrap();
        let scalar: Vec<&String> = params
            .iter()
            .filter(|(_, v)| v.is_number() || v.is_null())
            .map(|(k, _)| k)
            .collect();
        assert!(scalar.len() >= 20, "{scalar:?}");
        // The columns of the line's own parameters (a `.` steps into another member).
        let columns = line_columns();
        let shown: Vec<&str> = columns
            .iter()
            .map(|(k, _, _)| k.as_str())
            .filter(|k| !k.contains('.'))
            .collect();
        for k in &scalar {
            assert!(shown.contains(&k.as_str()), "{k} has no column");
        }
        for k in &shown {
            assert!(
                params.get(*k).is_some_and(|v| v.is_number()),
                "column {k} is not a number of the line"
            );
        }
        // And the page shows them, RPc among them; the means' table names them alike (a key
        // the table does not hold stands as it is).
        let mut line = serde_json::Value::Object(params.clone());
        line["index"] = 0.into();
        line["y_mm"] = 0.0.into();
        let means =
            serde_json::json!([{"parameter": "A1", "n": 2}, {"parameter": "Sx_um", "n": 2}]);
        let report = serde_json::json!({"kind": "grid", "lines": [line], "uncertainty": {"parameters": means}});
        let h = render(&report, None, &[], None, |_| Vec::new());
        let rpc = params["RPc_per_cm"].as_f64().unwrap();
        assert!(h.contains("<th>RPc /cm</th>"));
        assert!(h.contains(&format!("<td>{}</td>", fmt(rpc, Quantity::PerLength))));
        assert!(h.contains("<td class=\"t\">A1 µm·%</td>") && h.contains(">Sx_um</td>"));
    }

    /// The per-line headings carry the recipe's definitions, and the levels of Rδc and Rmr
    /// are stated under the table: the same numbers mean different things at other levels.
    #[test]
    fn the_line_table_states_the_definitions_and_the_levels_of_rdc_and_rmr() {
        let report = serde_json::json!({
            "kind": "grid",
            "recipe": {"definitions": {
                "Ra": "ISO4287:1997/Ra <mean>",
                "Rdc": "Rdc = C(Rmr1) - C(Rmr2); levels 10% and 25%",
                "Rmr": "Rmr at C(Rmr0) - Rdc; Rmr0 = 0%, Rdc = 0.10 um",
            }},
            "lines": [{"index": 0, "y_mm": 0.0, "Ra_um": 0.5, "Rdc_um": 0.2, "Rmr_pct": 12.0}],
        });
        let h = render(&report, None, &[], None, |_| Vec::new());
        assert!(
            h.contains("<th title=\"ISO4287:1997/Ra &lt;mean&gt;\">Ra µm</th>"),
            "{h}"
        );
        assert!(
            h.contains("<th>Rq µm</th>"),
            "a heading without a definition stays plain"
        );
        assert!(h.contains(
            "<p id=\"line-levels\">Rδc: Rdc = C(Rmr1) - C(Rmr2); levels 10% and 25%; Rmr: Rmr at C(Rmr0) - Rdc; Rmr0 = 0%, Rdc = 0.10 um.</p>"
        ), "{h}");
        // Without a recipe, no sentence of levels.
        let bare = serde_json::json!({"kind": "grid", "lines": [{"index": 0, "y_mm": 0.0}]});
        assert!(!render(&bare, None, &[], None, |_| Vec::new()).contains("line-levels"));
    }

    /// Every parameter heading of every per-line table carries the recipe's definition of
    /// its parameter: the SJ series' reading too (its keys are members of
    /// `material_ratio_sj_series`, whose stem is no parameter's name).
    #[test]
    fn every_line_heading_with_a_definition_has_its_tooltip_the_sj_readings_included() {
        let definitions = crate::metrology::params::definitions();
        let report = serde_json::json!({
            "kind": "grid",
            "recipe": {"definitions": definitions, "material_ratio": "iso"},
            "lines": [{"index": 0, "y_mm": 0.0}],
        });
        let h = render(&report, None, &[], None, |_| Vec::new());
        let table = |id: &str| {
            let start = h.find(&format!("<table id=\"{id}\">")).expect(id);
            h[start..][..h[start..].find("</thead>").unwrap()].to_owned()
        };
        let heads = |id: &str| table(id).matches("<th title=\"").count();
        for p in PARAMETERS
            .iter()
            .filter(|p| matches!(p.source, Source::Family(_)))
        {
            let th = format!("<th title=\"{}", esc(&definitions[p.stem()]));
            let sj = table("t-lines-sj");
            assert!(sj.contains(&th), "the SJ series' {} has no tooltip", p.key);
        }
        assert_eq!(
            heads("t-lines-sj"),
            8,
            "Rmr, Rk, Rpk, Rvk, Mr1, Mr2, A1, A2"
        );
        assert!(table("t-lines-sj").contains("as the SJ series reads it"));
        assert_eq!(
            heads("t-lines") + heads("t-lines-spacing") + heads("t-lines-material"),
            PARAMETERS.len(),
            "one tooltip per parameter, none on a column the recipe does not define"
        );
        assert_eq!(
            heads("t-lines-ln"),
            4,
            "Ra, Rq, Rsk, Rku beside their ln values"
        );
    }

    #[test]
    fn a_report_renders_its_result_then_its_warnings_and_numbers_for_people() {
        let report = serde_json::json!({
            "software": "surfscan 0.1.0 (commit abc)",
            "input": "/scans/x",
            "kind": "scan",
            "warnings": ["line 4 <left out>"],
            "lines": [
                {"index": 0, "y_mm": 0.0, "Ra_um": 0.0045000000000000005,
                 "instrument": [{"name": "Ra", "instrument": 0.5, "ours": 0.6, "difference": 0.1, "compared_with": "Ra", "unit": "um"}]},
                {"index": 1, "y_mm": 0.01, "Ra_um": 0.5}
            ],
            "model_vs_measured": {"points_left_out": [], "lines_left_out": []},
            "between_lines": {"summary": "the model between lines is not supported by the data",
                              "verdict": "the model between lines is not supported by the data: every 2nd line left out"},
            "model_checks": {"height_range": {"model_min_um": -21.4, "model_max_um": 19.0,
                             "measured_min_um": -13.1, "measured_max_um": 9.1, "overshoot_pct": 82.0}},
            "model": {"description": "global B-spline interpolation (the paper)"},
            "recipe": {"lambda_c_mm": 0.8, "spike_rule": "isolated spike: at most 5 points", "outliers": "flag",
                       "holdout_threshold_sq": 0.5}
        });
        let h = render(&report, None, &[], None, |_| Vec::new());
        // The result first (what is signed), the warnings that qualify it right after.
        let warn = h.find("id=\"warnings\"").unwrap();
        assert!(h.find("id=\"result\"").unwrap() < warn);
        assert!(warn < h.find("id=\"traceability\"").unwrap_or(usize::MAX));
        assert!(warn < h.find("id=\"lines\"").unwrap());
        assert!(h.contains("line 4 &lt;left out&gt;"));
        assert!(h.contains("<td>0.004500</td>"), "4 significant digits");
        assert!(!h.contains("0.0045000000000000005"));
        // 1-based line numbers with the file index beside them.
        assert!(h.contains("<td>1 <span class=\"muted\">(0000)</span></td>"));
        // 0.1 µm off on 0.5 µm: outside 2 % / 0.005 µm.
        assert!(h.contains("<span class=\"flag\">NO</span>"));
        assert!(h.contains("1 comparison(s) outside the tolerance"));
        assert!(h.contains("not supported by the data"));
        // The verdict in full, the model's height range against the data's, and the recipe of
        // the model and of the spikes.
        assert!(h.contains(
            "<b>the model between lines is not supported by the data: every 2nd line left out</b>"
        ));
        assert!(h.contains("the model spans -21.40 … 19.00 µm where the measured heights span -13.10 … 9.100 µm (82.0 % beyond"));
        assert!(h.contains("global B-spline interpolation (the paper)"));
        assert!(h.contains("isolated spike: at most 5 points — flagged only, the data as measured"));
        assert!(h.contains("at most 0.50 × Sq"));
        assert!(!h.contains("<script"), "no script in the report");
    }
}
