//! The SJ-210 family's reply payloads read into values: 3-digit codes, counts, the battery,
//! `RDRES…02` results and `RDEVA` profile blocks. The client sends and receives; these say
//! what an `OK` payload means.
//!
//! Pure (layer 1): strings in, values out. Depends on [`super::error`] (the named reply
//! error), [`crate::devices`] and [`crate::profile`] (the values).

use super::error::Sj210Error;
use crate::devices::Battery;
use crate::profile::InstrumentResult;

/// A 3-digit code payload.
pub fn parse_code(payload: &str) -> Option<u16> {
    let p = payload.trim();
    if p.len() == 3 && p.bytes().all(|b| b.is_ascii_digit()) {
        p.parse().ok()
    } else {
        None
    }
}

/// The first run of digits (C3 reads the `RDEVA` total this way).
pub fn leading_number(payload: &str) -> Option<u32> {
    let digits: String = payload
        .trim_start()
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

/// One `RDRES…02` payload: parameter name (6 characters), then the value, then the unit
/// (3 characters, right-justified), read by trimming whatever the justification: the SJ-210
/// manual shows the value right-justified (`"Ra      3.123 um"`), Mitutoyo's PC export has
/// a sign position and the number left-justified in the field (`" 3.308 "`, `" -0.144"`).
/// The value and the unit are the last two words; `width` (the model's value field, 7 on
/// the SJ-210, 8 on the SJ-410) only splits a value glued to its unit. A value that is not a
/// number (`Err110`) is `None`. The unit is kept as received (`um` in ASCII, or latin-1 `µm`).
pub fn parse_result(
    command: &str,
    payload: &str,
    width: usize,
) -> Result<InstrumentResult, Sj210Error> {
    let chars: Vec<char> = payload.chars().collect();
    let bad = || Sj210Error::UnexpectedReply {
        command: command.to_string(),
        payload: payload.to_string(),
        expected: "name (6) + value + unit (3)",
    };
    let name: String = chars.get(..6).ok_or_else(bad)?.iter().collect();
    let name = name.trim().to_string();
    let rest: String = chars.get(6..).unwrap_or(&[]).iter().collect();
    let (value, unit) = split_value_unit(&rest, width);
    if name.is_empty() || value.is_empty() {
        return Err(bad());
    }
    Ok(InstrumentResult {
        name,
        value: number(&value),
        unit,
        printed: Some(value),
        ng_code: None,
    })
}

/// A number with any spaces inside removed (a sign position may be separated from the
/// digits); `None` when it is not a finite number.
fn number(text: &str) -> Option<f64> {
    let t: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    t.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Splits the text after the name into value and unit, both trimmed.
fn split_value_unit(rest: &str, width: usize) -> (String, String) {
    let t = rest.trim();
    if let Some((v, u)) = t.rsplit_once(char::is_whitespace) {
        // A last word that is itself a number belongs to the value (no unit given).
        if number(u).is_none() {
            return (v.trim().to_string(), u.to_string());
        }
        return (t.to_string(), String::new());
    }
    if number(t).is_none() {
        // One word: a value glued to its unit at the model's field width.
        let chars: Vec<char> = rest.chars().collect();
        if let (Some(v), Some(u)) = (chars.get(..width), chars.get(width..)) {
            let v: String = v.iter().collect();
            let u: String = u.iter().collect();
            if number(&v).is_some() {
                return (v.trim().to_string(), u.trim().to_string());
            }
        }
    }
    (t.to_string(), String::new())
}

/// One profile block: a value count, then that many heights in µm. Values may be
/// separated by `,`, `;` or spaces, or be fixed 9-character fields after a 2-digit count
/// (the manual's notation). `0.0` alone is the end-of-data marker (no values).
pub fn parse_block(payload: &str) -> Result<Vec<f64>, String> {
    let p = payload.trim();
    if p.is_empty() || p == "0.0" || p == "0" || p == "00" {
        return Ok(Vec::new());
    }
    let is_sep = |c: char| c == ',' || c == ';' || c.is_whitespace();
    let tokens: Vec<String> = if p.contains(is_sep) {
        p.split(is_sep)
            .filter(|t| !t.is_empty())
            .map(str::to_string)
            .collect()
    } else {
        let chars: Vec<char> = p.chars().collect();
        let mut t = vec![chars.iter().take(2).collect::<String>()];
        let rest = chars.get(2..).unwrap_or(&[]);
        if rest.len() % 9 != 0 {
            return Err(format!(
                "{} characters after the count is not a multiple of the 9-character field",
                rest.len()
            ));
        }
        t.extend(rest.chunks(9).map(|c| c.iter().collect::<String>()));
        t
    };
    let (count, values) = tokens.split_first().ok_or("empty block")?;
    let count: usize = count
        .parse()
        .map_err(|_| format!("count field {count:?} is not an integer"))?;
    let values = values
        .iter()
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("value {t:?} is not a number"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    if values.len() != count {
        return Err(format!(
            "count field says {count}, {} values follow",
            values.len()
        ));
    }
    Ok(values)
}

/// A 2-digit parameter count (`RDPAR`), at most 99.
pub fn parse_param_count(payload: &str) -> Option<u32> {
    payload.trim().parse::<u32>().ok().filter(|n| *n <= 99)
}

/// The battery state of an `RDSTU01` code.
pub fn battery_from_code(code: u16) -> Battery {
    match code {
        0 => Battery::Good,
        1 => Battery::Low,
        2 => Battery::Abnormal,
        3 => Battery::Charging,
        other => Battery::Unknown(other),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_formats() {
        assert_eq!(
            parse_block("03,-0.100,0.200,1.5").unwrap(),
            vec![-0.1, 0.2, 1.5]
        );
        assert_eq!(parse_block("02; +0.5; -0.25").unwrap(), vec![0.5, -0.25]);
        assert_eq!(
            parse_block("02   -0.1230    4.5000").unwrap(),
            vec![-0.123, 4.5]
        );
        assert!(parse_block("02 -0001.50+00002.25").is_err());
        assert_eq!(
            parse_block("02-0001.500+0002.250").unwrap(),
            vec![-1.5, 2.25]
        );
        assert!(parse_block("0.0").unwrap().is_empty());
        assert!(parse_block("03,1.0,2.0")
            .unwrap_err()
            .contains("count field says 3"));
        assert!(parse_block("02,1.0,x").unwrap_err().contains("\"x\""));
    }

    #[test]
    fn result_fields_by_width() {
        let r = parse_result("RDRES02,01,00", "Ra      3.123 \u{b5}m", 7).unwrap();
        assert_eq!(r.name, "Ra");
        assert_eq!(r.value, Some(3.123));
        assert_eq!(r.unit, "\u{b5}m");
        let r = parse_result("RDRES002,01,00", "Rz     12.3456 um", 8).unwrap();
        assert_eq!(
            (r.name.as_str(), r.value, r.unit.as_str()),
            ("Rz", Some(12.3456), "um")
        );
        let r = parse_result("RDRES02,02,00", "Rc    Err110 um", 7).unwrap();
        assert_eq!(r.value, None);
        assert_eq!(r.printed.as_deref(), Some("Err110"));
        assert!(parse_result("RDRES02,02,00", "Ra   1", 7).is_err());
    }

    #[test]
    fn result_fields_right_and_left_justified_read_the_same() {
        // The manual's layout: value right-justified in 7, unit right-justified in 3.
        let right = parse_result("RDRES02,01,00", "Ra      3.308 um", 7).unwrap();
        // Mitutoyo's export layout: a sign position, the number left-justified.
        let left = parse_result("RDRES02,01,00", "Ra     3.308  um", 7).unwrap();
        assert_eq!(right, left);
        assert_eq!(
            (left.name.as_str(), left.value, left.unit.as_str()),
            ("Ra", Some(3.308), "um")
        );
        assert_eq!(left.printed.as_deref(), Some("3.308"));
        let neg = parse_result("RDRES02,04,00", "Rsk    -0.144   ", 7).unwrap();
        assert_eq!(
            (neg.name.as_str(), neg.value, neg.unit.as_str()),
            ("Rsk", Some(-0.144), "")
        );
        let neg_right = parse_result("RDRES02,04,00", "Rsk     -0.144   ", 7).unwrap();
        assert_eq!(neg_right, neg);
        // A sign position separated from the digits, and trailing blanks trimmed away.
        let spaced = parse_result("RDRES02,04,00", "Rsk   - 0.144", 7).unwrap();
        assert_eq!(spaced.value, Some(-0.144));
        // Percentages and a value glued to its unit at the field width.
        let mr = parse_result("RDRES02,05,00", "Rmr    45.20  %", 7).unwrap();
        assert_eq!((mr.value, mr.unit.as_str()), (Some(45.2), "%"));
        let glued = parse_result("RDRES02,01,00", "Ra      3.308um", 7).unwrap();
        assert_eq!((glued.value, glued.unit.as_str()), (Some(3.308), "um"));
    }

    #[test]
    fn codes_and_totals() {
        assert_eq!(parse_code("001"), Some(1));
        assert_eq!(parse_code("01"), None);
        assert_eq!(leading_number("08000"), Some(8000));
        assert_eq!(leading_number("x"), None);
        assert_eq!(parse_param_count(" 07"), Some(7));
        assert_eq!(parse_param_count("100"), None);
        assert_eq!(battery_from_code(2), Battery::Abnormal);
        assert_eq!(battery_from_code(9), Battery::Unknown(9));
    }
}
