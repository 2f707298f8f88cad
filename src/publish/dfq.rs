//! A scan's results in the Q-DAS ASCII transfer format (a `.dfq` file: the description part
//! and the value part in one file), for the lab's SPC system.
//!
//! Written by hand: the format is lines of `Kxxxx[/i] value` key fields, and no maintained
//! Rust crate writes it. The fields used (type and length as Hexagon, Q-DAS's maker,
//! publishes them; see the sources below):
//!
//! | Field | Meaning (type, length) | Written as |
//! |---|---|---|
//! | `K0100` | total number of characteristics in the file (I5) | first line |
//! | `K1001` / `K1002` | part number (AN 30) / part description (AN 80) | the recipe's name / its description |
//! | `K2001/i` / `K2002/i` | characteristic number (40) / description (80) | the parameter (`Rz`) / the callouts and the band |
//! | `K2004/i` | characteristic type (`0` variable) | `0` |
//! | `K2022/i` | decimal places | `4` |
//! | `K2101/i` | nominal value | the middle of a two-sided tolerance only (a one-sided surface limit has none) |
//! | `K2110/i` / `K2111/i` | lower / upper specification limit | the specification's limits, µm |
//! | `K2142/i` | unit | `µm` |
//! | `K0001/i` | measured value (F 22; each starts a new value of characteristic *i*) | one line's value, µm |
//! | `K0004/i` | the value's date and time, `DD.MM.YYYY/HH:MM:SS` | when the line was committed, UTC |
//! | `K0006/i` | batch number (AN 14) | the scan's start, `YYYYMMDDHHMMSS` (the scan id's time: the whole id does not fit) |
//! | `K0008/i` | operator (I10: a number of the operator catalogue) | the operator, only when it is such a number |
//! | `K0009/i` | text (AN 255) | `scan <scan id>`, and `; operator <name>` for an operator given by name |
//! | `K0014/i` | part ident (AN 40) | the specimen |
//!
//! A text longer than its field is cut to the field's length (whole characters), so a Q-DAS
//! import neither refuses nor cuts it in its own way; the full texts are in report.json.
//!
//! Sources (the Q-DAS ASCII transfer format manual itself was not found as a public
//! document): the field list with types and lengths of Hexagon's PC-DMIS Q-DAS Configurator,
//! "Supported K-Fields" (docs.hexagonmi.com/pcdmis/2022.1/en/helpcenter/mergedprojects/
//! qdasconfigurator/Supported_K-Fields.htm: K0001, K0004, K0006 AN 14, K0008 I10, K0009 AN
//! 255, K0014 AN 40, K0100, K1001 AN 30, K1002 AN 80); Hexagon's Q-DAS community wiki, data
//! format pages "Characteristic fields K2xxx and K8xxx" (K2001 40, K2002 80, K2004, K2022),
//! "Defined contents K2xxx" (K2004 `0` variable) and "Defined contents K00xx" (K0004's
//! `DD.MM.YYYY/HH:MM:SS`), qa.nexus.hexagon.com/community/public/q-das/w/data-format/. K2101,
//! K2110, K2111, K2142: Q-DAS's reference-manual example QDAS_1AD.DFQ (github.com/zwq00000/
//! AQDEF-Sharp, Examples/ENG/GC/Reference_manual/): nominal 20.300, limits 20.180 and 20.420
//! (nominal ∓ the K2112/K2113 allowance 0.120), unit `mm`; diribet/aqdef-tools agrees (its
//! KKeyRepository.java: K2101 nominal, K2110/K2111 absolute limits). No Q-DAS product read ours yet.
//! Lines end with CR LF, and the text is ISO 8859-1 (the manual's character set; a character
//! outside it becomes `?`). A line without a value of a parameter has no `K0001` for it.
//!
//! Layer 4 (the lab's systems): a pure formatter of [`Exported`]; the caller writes the bytes.

use super::exported::{decimal, Characteristic, Exported};

/// Field content on one line: no line breaks, ISO 8859-1, at most `max` characters.
fn field(s: &str, max: usize) -> String {
    let one_line: String = s
        .chars()
        .map(|c| match c {
            '\r' | '\n' | '\t' => ' ',
            c if u32::from(c) <= 0xFF => c,
            _ => '?',
        })
        .collect();
    one_line
        .trim()
        .chars()
        .take(max)
        .collect::<String>()
        .trim_end()
        .to_owned()
}

/// The longest text a field takes (characters); none for the fields without a text limit.
fn max_chars(key: &str) -> usize {
    match key.split('/').next().unwrap_or(key) {
        "K1001" => 30,
        "K1002" | "K2002" => 80,
        "K2001" | "K0014" => 40,
        "K0006" => 14,
        "K0009" => 255,
        _ => usize::MAX,
    }
}

/// `K0006`: the batch, the scan's start `YYYYMMDDHHMMSS` from its id
/// (`YYYYMMDDTHHMMSSZ-slug`); an id of another shape is cut to the field.
fn batch(scan_id: &str) -> String {
    let time = scan_id.split('-').next().unwrap_or(scan_id);
    let digits: String = time.chars().filter(char::is_ascii_digit).collect();
    if digits.len() == 14 {
        digits
    } else {
        scan_id.to_owned()
    }
}

/// `K0008`: an operator given as a number of the operator catalogue (I10).
fn operator_number(operator: &str) -> Option<&str> {
    let o = operator.trim();
    (!o.is_empty() && o.len() <= 10 && o.chars().all(|c| c.is_ascii_digit())).then_some(o)
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
    let mut push = |k: &str, v: String| out.push(format!("{k} {}", field(&v, max_chars(k))));
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
            push(&format!("K2101/{i}"), decimal((lo + hi) / 2.0));
        }
        if let Some(lo) = c.lower_um {
            push(&format!("K2110/{i}"), decimal(lo));
        }
        if let Some(hi) = c.upper_um {
            push(&format!("K2111/{i}"), decimal(hi));
        }
        push(&format!("K2142/{i}"), "µm".into());
    }
    let text = match operator_number(&r.operator) {
        None if !r.operator.trim().is_empty() => {
            format!("scan {}; operator {}", r.scan_id, r.operator.trim())
        }
        _ => format!("scan {}", r.scan_id),
    };
    for (k, line) in r.lines.iter().enumerate() {
        let when = line
            .time
            .or(r.finished_at)
            .unwrap_or(r.started_at)
            .format("%d.%m.%Y/%H:%M:%S")
            .to_string();
        for (i, c) in r.characteristics.iter().enumerate() {
            let i = i + 1;
            let Some(v) = c.values_um.get(k).copied().flatten() else {
                continue;
            };
            push(&format!("K0001/{i}"), decimal(v));
            push(&format!("K0004/{i}"), when.clone());
            push(&format!("K0006/{i}"), batch(&r.scan_id));
            if let Some(n) = operator_number(&r.operator) {
                push(&format!("K0008/{i}"), n.to_owned());
            }
            push(&format!("K0009/{i}"), text.clone());
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
        assert_eq!(field(" a\r\nb\tc ", usize::MAX), "a  b c");
        assert_eq!(field("µm ≤ 5", usize::MAX), "µm ? 5");
        let bytes: Vec<u8> = "K2142/1 µm\r\n"
            .chars()
            .map(|c| u8::try_from(u32::from(c)).unwrap_or(b'?'))
            .collect();
        assert_eq!(bytes, b"K2142/1 \xb5m\r\n");
    }

    #[test]
    fn texts_fit_their_fields_and_the_batch_is_the_scan_s_start() {
        // 14 characters, whole ones (µ is one), no trailing space left by the cut.
        assert_eq!(field("coupon µ-17 of the left flank", 14), "coupon µ-17 of");
        assert_eq!(field("abcdefghijklm xyz", 14), "abcdefghijklm");
        assert_eq!(max_chars("K0006/3"), 14);
        assert_eq!(max_chars("K0001/3"), usize::MAX);
        assert_eq!(batch("20261206T123430Z-coupon-a-17"), "20261206123430");
        assert_eq!(batch("old-style"), "old-style");
        assert_eq!(operator_number(" 4711 "), Some("4711"));
        assert_eq!(operator_number("R. Tester"), None);
        assert_eq!(operator_number("12345678901"), None);
    }
}
