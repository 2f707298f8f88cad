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

/// One `RDRES…02` payload: name (6), value (width), unit (3, right-justified).
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
    let value: String = chars.get(6..6 + width).ok_or_else(bad)?.iter().collect();
    let unit: String = chars.get(6 + width..).unwrap_or(&[]).iter().collect();
    let name = name.trim().to_string();
    if name.is_empty() {
        return Err(bad());
    }
    Ok(InstrumentResult {
        name,
        value: value.trim().parse::<f64>().ok().filter(|v| v.is_finite()),
        unit: unit.trim().to_string(),
    })
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
        assert!(parse_result("RDRES02,02,00", "Ra   1", 7).is_err());
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
