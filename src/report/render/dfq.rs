//! A scan's results in the Q-DAS ASCII transfer format (a `.dfq` file: the description part
//! and the value part in one file), for the lab's SPC system.
//!
//! Written by hand: the format is lines of `Kxxxx[/i] value` key fields, and no maintained
//! Rust crate writes it. The fields used, from the Q-DAS ASCII transfer format manual
//! (AQDEF):
//!
//! | Field | Meaning | Written as |
//! |---|---|---|
//! | `K0100` | number of characteristics in the file | first line |
//! | `K1001` / `K1002` | part number / part description | the recipe's name / its description |
//! | `K2001/i` / `K2002/i` | characteristic number / description | the parameter (`Rz`) / the callouts and the band |
//! | `K2004/i` | characteristic type | `0` (variable) |
//! | `K2022/i` | decimal places | `4` |
//! | `K2101/i` | nominal value | the middle of a two-sided tolerance only (a one-sided surface limit has none) |
//! | `K2110/i` / `K2111/i` | lower / upper specification limit | the specification's limits, µm |
//! | `K2142/i` | unit | `µm` |
//! | `K0001/i` | a value (each starts a new value of characteristic *i*) | one line's value, µm |
//! | `K0004/i` | the value's date and time, `DD.MM.YYYY/HH:MM:SS` | when the line was committed, UTC |
//! | `K0006/i` | batch number | the scan id |
//! | `K0008/i` | operator | the operator |
//! | `K0014/i` | part ident | the specimen |
//!
//! Lines end with CR LF, and the text is ISO 8859-1 (the manual's character set; a character
//! outside it becomes `?`). A line without a value of a parameter has no `K0001` for it.
//!
//! Layer 4 (reporting): a pure formatter of [`Exported`]; the caller writes the bytes.

use crate::report::exported::{Characteristic, Exported};

/// Field content on one line: no line breaks, ISO 8859-1.
fn field(s: &str) -> String {
    s.chars()
        .map(|c| match c {
            '\r' | '\n' | '\t' => ' ',
            c if u32::from(c) <= 0xFF => c,
            _ => '?',
        })
        .collect::<String>()
        .trim()
        .to_owned()
}

/// A number as the value fields carry it: a decimal point, every digit of the value.
fn number(v: f64) -> String {
    format!("{v}")
}

/// `K2002`: the callouts, or the parameter and the band it was evaluated in.
fn description(c: &Characteristic, r: &Exported) -> String {
    let mut d = if c.callouts.is_empty() {
        format!("{} (ISO 21920-2)", c.parameter)
    } else {
        c.callouts.join("; ")
    };
    if let (Some(lc), Some(n)) = (r.lambda_c_mm, r.sampling_lengths) {
        d.push_str(&format!(", cut-off {lc} mm, {n} sampling lengths"));
    }
    d
}

/// The file's text, before its encoding.
pub fn dfq_text(r: &Exported) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut push = |k: &str, v: String| out.push(format!("{k} {}", field(&v)));
    push("K0100", r.characteristics.len().to_string());
    push("K1001", r.part.number.clone());
    push("K1002", r.part.description.clone());
    for (i, c) in r.characteristics.iter().enumerate() {
        let i = i + 1;
        push(&format!("K2001/{i}"), c.parameter.clone());
        push(&format!("K2002/{i}"), description(c, r));
        push(&format!("K2004/{i}"), "0".into());
        push(&format!("K2022/{i}"), "4".into());
        if let (Some(lo), Some(hi)) = (c.lower_um, c.upper_um) {
            push(&format!("K2101/{i}"), number((lo + hi) / 2.0));
        }
        if let Some(lo) = c.lower_um {
            push(&format!("K2110/{i}"), number(lo));
        }
        if let Some(hi) = c.upper_um {
            push(&format!("K2111/{i}"), number(hi));
        }
        push(&format!("K2142/{i}"), "µm".into());
    }
    for (k, line) in r.lines.iter().enumerate() {
        let when = line
            .time
            .or(r.finished_at)
            .unwrap_or(r.started_at)
            .format("%d.%m.%Y/%H:%M:%S")
            .to_string();
        for (i, c) in r.characteristics.iter().enumerate() {
            let i = i + 1;
            let Some(v) = c
                .values_um
                .get(k)
                .copied()
                .flatten()
                .filter(|v| v.is_finite())
            else {
                continue;
            };
            push(&format!("K0001/{i}"), number(v));
            push(&format!("K0004/{i}"), when.clone());
            push(&format!("K0006/{i}"), r.scan_id.clone());
            push(&format!("K0008/{i}"), r.operator.clone());
            push(&format!("K0014/{i}"), r.specimen.clone());
        }
    }
    let mut text = out.join("\r\n");
    text.push_str("\r\n");
    text
}

/// The file's bytes: [`dfq_text`] in ISO 8859-1.
pub fn dfq(r: &Exported) -> Vec<u8> {
    dfq_text(r)
        .chars()
        .map(|c| u8::try_from(u32::from(c)).unwrap_or(b'?'))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_stay_on_their_line_and_in_iso_8859_1() {
        assert_eq!(field(" a\r\nb\tc "), "a  b c");
        assert_eq!(field("µm ≤ 5"), "µm ? 5");
        let bytes: Vec<u8> = "K2142/1 µm\r\n"
            .chars()
            .map(|c| u8::try_from(u32::from(c)).unwrap_or(b'?'))
            .collect();
        assert_eq!(bytes, b"K2142/1 \xb5m\r\n");
    }
}
