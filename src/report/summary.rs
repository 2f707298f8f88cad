//! `summary.csv`: one row per line with our ISO parameters and the instrument's Ra, Rq and Rz.
//!
//! Layer 4 (reporting): a formatter over the report's line entries; no I/O.

use super::document::LineReport;

fn fmt_opt(v: Option<f64>) -> String {
    v.map(|v| format!("{v}")).unwrap_or_default()
}

/// The instrument's value of `name` in our unit, from a line's comparisons.
fn instrument_value(line: &LineReport, name: &str) -> Option<f64> {
    line.instrument
        .as_ref()?
        .iter()
        .find(|c| c.name.trim().eq_ignore_ascii_case(name))
        .and_then(|c| c.instrument)
}

/// Renders `summary.csv`.
pub fn summary_csv(lines: &[LineReport]) -> String {
    let mut csv = String::from(
        "index,y_mm,Ra_um,Rq_um,Rz_um,RzJIS_um,Rp_um,Rv_um,Rt_um,Rz1max_um,Rsk,Rku,Rdq,RSm_um,Rk_um,Rpk_um,Rvk_um,Mr1_pct,Mr2_pct,A1,A2,instrument_Ra_um,instrument_Rq_um,instrument_Rz_um\n",
    );
    for l in lines {
        let p = &l.params;
        let row: Vec<String> = vec![
            l.index.to_string(),
            l.y_mm.to_string(),
            p.ra_um.to_string(),
            p.rq_um.to_string(),
            p.rz_um.to_string(),
            fmt_opt(p.rzjis_um),
            p.rp_um.to_string(),
            p.rv_um.to_string(),
            p.rt_um.to_string(),
            p.rz1max_um.to_string(),
            p.rsk.to_string(),
            p.rku.to_string(),
            p.rdq.to_string(),
            fmt_opt(p.rsm_um),
            p.rk_um.to_string(),
            p.rpk_um.to_string(),
            p.rvk_um.to_string(),
            p.mr1_pct.to_string(),
            p.mr2_pct.to_string(),
            p.a1_um_pct.to_string(),
            p.a2_um_pct.to_string(),
            fmt_opt(instrument_value(l, "Ra")),
            fmt_opt(instrument_value(l, "Rq")),
            fmt_opt(instrument_value(l, "Rz")),
        ];
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    csv
}
