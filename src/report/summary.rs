//! `summary.csv`: one row per line with our ISO parameters and the instrument's Ra, Rq and Rz,
//! each value with the significant digits of its quantity.
//!
//! Layer 4 (reporting): a formatter over the report's line entries; no I/O.

use super::document::LineReport;
use crate::numfmt::{fmt as nfmt, fmt_opt as nfmt_opt, line_number, Quantity};

/// The instrument's value of `name` in our unit, from a line's comparisons.
fn instrument_value(line: &LineReport, name: &str) -> Option<f64> {
    line.instrument
        .as_ref()?
        .iter()
        .find(|c| c.name.trim().eq_ignore_ascii_case(name))
        .and_then(|c| c.instrument)
}

/// `summary.csv` for people and spreadsheets: one row per line, `line` 1-based and `index`
/// the NNNN of its files, every value with the significant digits of its quantity
/// ([`crate::numfmt`]; `report.json` keeps full precision).
pub fn summary_csv(lines: &[LineReport]) -> String {
    use Quantity::{Area, HeightUm as H, Percent, PositionMm, Ratio};
    let mut csv = String::from(
        "line,index,y_mm,Ra_um,Rq_um,Rz_um,RzJIS_um,Rp_um,Rv_um,Rt_um,Rz1max_um,Rsk,Rku,Rdq,RSm_um,Rk_um,Rpk_um,Rvk_um,Mr1_pct,Mr2_pct,A1_um_pct,A2_um_pct,instrument_Ra_um,instrument_Rq_um,instrument_Rz_um\n",
    );
    for l in lines {
        let p = &l.params;
        let row: Vec<String> = vec![
            line_number(l.index).to_string(),
            format!("{:04}", l.index),
            nfmt(l.y_mm, PositionMm),
            nfmt(p.ra_um, H),
            nfmt(p.rq_um, H),
            nfmt(p.rz_um, H),
            nfmt_opt(p.rzjis_um, H),
            nfmt(p.rp_um, H),
            nfmt(p.rv_um, H),
            nfmt(p.rt_um, H),
            nfmt(p.rz1max_um, H),
            nfmt(p.rsk, Ratio),
            nfmt(p.rku, Ratio),
            nfmt(p.rdq, Ratio),
            nfmt_opt(p.rsm_um, H),
            nfmt(p.rk_um, H),
            nfmt(p.rpk_um, H),
            nfmt(p.rvk_um, H),
            nfmt(p.mr1_pct, Percent),
            nfmt(p.mr2_pct, Percent),
            nfmt(p.a1_um_pct, Area),
            nfmt(p.a2_um_pct, Area),
            nfmt_opt(instrument_value(l, "Ra"), H),
            nfmt_opt(instrument_value(l, "Rq"), H),
            nfmt_opt(instrument_value(l, "Rz"), H),
        ];
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    csv
}
