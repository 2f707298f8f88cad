//! `summary.csv`: one row per line with our ISO parameters and the instrument's Ra, Rq and Rz,
//! each value with the significant digits of its quantity.
//!
//! Layer 4 (reporting): a formatter over the report's line entries and the metrology's
//! parameters; no I/O.

use crate::metrology::parameter_table::parameter;
use crate::metrology::params::RoughnessParams;
use crate::numfmt::{fmt as nfmt, fmt_opt as nfmt_opt, line_number, Quantity};
use crate::report::document::LineReport;
use crate::specification::{LimitVerdict, SpecificationVerdict};

/// The instrument's value of `name` in our unit, from a line's comparisons.
fn instrument_value(line: &LineReport, name: &str) -> Option<f64> {
    line.instrument
        .as_ref()?
        .iter()
        .find(|c| c.name.trim().eq_ignore_ascii_case(name))
        .and_then(|c| c.instrument)
}

/// The columns every summary.csv starts with: the line, its file index, y, and the
/// parameters summary.csv has always had, in that order.
pub const LINE_HEADER: &str = "line,index,y_mm,Ra_um,Rq_um,Rz_um,RzJIS_um,Rp_um,Rv_um,Rt_um,Rz1max_um,Rsk,Rku,Rdq,RSm_um,Rk_um,Rpk_um,Rvk_um,Mr1_pct,Mr2_pct,A1_um_pct,A2_um_pct";

/// The columns after those (and after a scan's instrument columns): the parameters added
/// since, at the end so a reader that goes by position finds the others where they were.
pub const MORE_HEADER: &str = "Rda,Rc_um,RPc_per_cm,Rppi_per_inch,Rdc_um,Rmr_pct";

/// A line's value of each parameter `header` names (of [`LINE_HEADER`], [`MORE_HEADER`]),
/// with the digits the HTML report gives it; the columns that are not parameters, `line` and
/// the like, are not in the table.
pub fn cells_of<'a>(header: &'a str, p: &'a RoughnessParams) -> impl Iterator<Item = String> + 'a {
    header
        .split(',')
        .filter_map(parameter)
        .map(|t| nfmt_opt(t.of(p), t.quantity))
}

/// `summary.csv` for people and spreadsheets: one row per line, `line` 1-based and `index`
/// the NNNN of its files, every value with the significant digits of its quantity
/// ([`crate::numfmt`]; `report.json` keeps full precision). The instrument's Ra, Rq and Rz
/// follow [`LINE_HEADER`], then [`MORE_HEADER`]. A scan judged against a specification ends
/// with one column per limit (`limit: Rz max 6.3`: where the line's value stands, see
/// [`standing_cell`]) and `scan_verdict`, the scan's verdict on every row, so that rows of
/// many scans pasted together still say which surface passed.
pub fn summary_csv(lines: &[LineReport], specification: Option<&SpecificationVerdict>) -> String {
    let mut csv =
        format!("{LINE_HEADER},instrument_Ra_um,instrument_Rq_um,instrument_Rz_um,{MORE_HEADER}");
    let limits = specification.map_or(&[][..], |s| &s.limits[..]);
    for l in limits {
        csv.push(',');
        csv.push_str(&csv_field(&format!("limit: {}", l.callout)));
    }
    if specification.is_some() {
        csv.push_str(",scan_verdict");
    }
    csv.push('\n');
    for l in lines {
        let mut row = vec![
            line_number(l.index).to_string(),
            format!("{:04}", l.index),
            nfmt(l.y_mm, Quantity::PositionMm),
        ];
        row.extend(cells_of(LINE_HEADER, &l.params));
        for name in ["Ra", "Rq", "Rz"] {
            row.push(nfmt_opt(instrument_value(l, name), Quantity::HeightUm));
        }
        row.extend(cells_of(MORE_HEADER, &l.params));
        let line = line_number(l.index);
        row.extend(limits.iter().map(|v| standing_cell(v, line).to_owned()));
        if let Some(s) = specification {
            row.push(csv_field(s.verdict.as_str()));
        }
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    csv
}

/// Where line `line` (1-based) stands against one limit: `beyond` (beyond the limit by more
/// than its U), `undecided` (within U of it), `within`, `no value` (the line has no value of
/// the parameter) or `not compared` (the callout asks for another band or evaluation length
/// than the lines were evaluated with).
pub fn standing_cell(limit: &LimitVerdict, line: u64) -> &'static str {
    if !limit.conditions_differ.is_empty() {
        "not compared"
    } else if limit.lines_without_value.contains(&line) {
        "no value"
    } else if limit.lines_beyond.contains(&line) {
        "beyond"
    } else if limit.lines_undecided.contains(&line) {
        "undecided"
    } else {
        "within"
    }
}

/// A CSV field, quoted when it holds a comma, a quote or a line break (RFC 4180).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_owned()
    }
}
