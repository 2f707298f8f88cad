//! A strict reader for the IGES files [`super::write_iges`] produces: checks 80-column records,
//! section order and letters, per-section sequence numbers, Terminate counts, Directory Entry
//! pairs, P pointers, line counts and back-pointers, then rebuilds each entity 128 as a
//! [`NurbsSurface`].
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`]; reads a byte slice.

use super::IgesError;
use crate::nurbs::NurbsSurface;

/// A parsed file.
#[derive(Debug, Clone)]
pub struct IgesFile {
    /// Start section text (columns 1–72, trailing blanks removed).
    pub start_lines: Vec<String>,
    /// Global parameters as written (Hollerith strings decoded, others as text).
    pub global: Vec<String>,
    /// Every entity 128, in directory order.
    pub surfaces: Vec<NurbsSurface>,
}

fn err(line: usize, message: impl Into<String>) -> IgesError {
    IgesError::Structure {
        line,
        message: message.into(),
    }
}

/// Splits free-format parameter text into fields, decoding Hollerith strings. Stops at the
/// record delimiter `;`.
fn fields(text: &[u8]) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    let mut i = 0;
    let mut cur = String::new();
    loop {
        while i < text.len() && text[i] == b' ' {
            i += 1;
        }
        // Hollerith: digits followed by H.
        let digits_end = text[i..]
            .iter()
            .position(|c| !c.is_ascii_digit())
            .map_or(text.len(), |p| i + p);
        if digits_end > i && digits_end < text.len() && text[digits_end] == b'H' {
            let n: usize = std::str::from_utf8(&text[i..digits_end])
                .ok()
                .and_then(|s| s.parse().ok())
                .ok_or("bad Hollerith count")?;
            let start = digits_end + 1;
            // A count near usize::MAX must not wrap around past the end.
            let end = start.saturating_add(n);
            if end > text.len() {
                return Err(format!(
                    "Hollerith string of {n} characters runs past the end"
                ));
            }
            cur.push_str(&String::from_utf8_lossy(&text[start..end]));
            i = end;
            while i < text.len() && text[i] == b' ' {
                i += 1;
            }
        } else {
            let begin = i;
            while i < text.len() && text[i] != b',' && text[i] != b';' {
                i += 1;
            }
            cur.push_str(String::from_utf8_lossy(&text[begin..i]).trim());
        }
        match text.get(i) {
            Some(b',') => {
                out.push(std::mem::take(&mut cur));
                i += 1;
            }
            Some(b';') => {
                out.push(cur);
                return Ok(out);
            }
            Some(c) => return Err(format!("unexpected {:?} after a parameter", *c as char)),
            None => return Err("parameters end without the record delimiter ';'".into()),
        }
    }
}

fn parse_int(s: &str, de: usize, what: &str) -> Result<usize, IgesError> {
    s.trim().parse::<usize>().map_err(|_| IgesError::Parameter {
        de,
        message: format!("{what} {s:?} is not a non-negative integer"),
    })
}

fn parse_real(s: &str, de: usize, what: &str, index: usize) -> Result<f64, IgesError> {
    let t = s.trim();
    let ok = !t.is_empty()
        && t.bytes()
            .all(|c| c.is_ascii_digit() || matches!(c, b'+' | b'-' | b'.' | b'E' | b'D'));
    let v = if ok {
        t.replace('D', "E").parse::<f64>().ok()
    } else {
        None
    };
    match v {
        Some(v) if v.is_finite() => Ok(v),
        _ => Err(IgesError::Parameter {
            de,
            message: format!("{what} {index} is {t:?}, not a finite real"),
        }),
    }
}

/// Reads and checks a whole file.
pub fn read_iges(bytes: &[u8]) -> Result<IgesFile, IgesError> {
    let mut sections: [Vec<(usize, &[u8])>; 5] = Default::default();
    let order = b"SGDPT";
    let mut current = 0usize;
    let mut lines = bytes.split(|&c| c == b'\n').peekable();
    let mut lineno = 0usize;
    while let Some(raw) = lines.next() {
        lineno += 1;
        if raw.is_empty() && lines.peek().is_none() {
            break;
        }
        let line = raw.strip_suffix(b"\r").unwrap_or(raw);
        if line.len() != 80 {
            return Err(err(
                lineno,
                format!("record has {} columns, IGES needs exactly 80", line.len()),
            ));
        }
        let letter = line[72];
        let idx = order.iter().position(|&c| c == letter).ok_or_else(|| {
            err(
                lineno,
                format!(
                    "column 73 is {:?}, not a section letter S/G/D/P/T",
                    letter as char
                ),
            )
        })?;
        if idx < current {
            return Err(err(
                lineno,
                format!(
                    "section {} after section {}",
                    letter as char, order[current] as char
                ),
            ));
        }
        current = idx;
        let seq_text = std::str::from_utf8(&line[73..]).unwrap_or("").trim();
        let seq: usize = seq_text.parse().map_err(|_| {
            err(
                lineno,
                format!("sequence number {seq_text:?} is not a number"),
            )
        })?;
        let expected = sections[idx].len() + 1;
        if seq != expected {
            return Err(err(
                lineno,
                format!(
                    "sequence number {seq} in section {}, expected {expected}",
                    letter as char
                ),
            ));
        }
        sections[idx].push((lineno, line));
    }
    let [s, g, d, p, t] = &sections;
    if s.is_empty() || g.is_empty() || t.len() != 1 {
        return Err(err(
            lineno,
            format!(
                "needs at least one S and G line and exactly one T line (found S {}, G {}, T {})",
                s.len(),
                g.len(),
                t.len()
            ),
        ));
    }
    let (t_line, t_rec) = t[0];
    let counts = [s.len(), g.len(), d.len(), p.len()];
    for (k, &letter) in b"SGDP".iter().enumerate() {
        let f = &t_rec[8 * k..8 * k + 8];
        let n: Option<usize> = (f[0] == letter)
            .then(|| std::str::from_utf8(&f[1..]).ok()?.trim().parse().ok())
            .flatten();
        if n != Some(counts[k]) {
            return Err(err(
                t_line,
                format!(
                    "terminate field {:?} does not match the {} {} lines present",
                    String::from_utf8_lossy(f),
                    counts[k],
                    letter as char
                ),
            ));
        }
    }
    let start_lines = s
        .iter()
        .map(|(_, l)| String::from_utf8_lossy(&l[..72]).trim_end().to_string())
        .collect();
    let g_text: Vec<u8> = g
        .iter()
        .flat_map(|(_, l)| l[..72].iter().copied())
        .collect();
    let global = fields(&g_text).map_err(|m| err(g[0].0, format!("global section: {m}")))?;
    if global.len() < 25 {
        return Err(err(
            g[0].0,
            format!(
                "global section has {} parameters, IGES 5.3 needs 25 or 26",
                global.len()
            ),
        ));
    }
    if d.len() % 2 != 0 {
        return Err(err(
            d.last().map_or(lineno, |x| x.0),
            "directory section has an odd number of lines",
        ));
    }
    let mut surfaces = Vec::new();
    let mut next_p = 1usize;
    for pair in d.chunks_exact(2) {
        let (l1, r1) = pair[0];
        let de = 2 * surfaces.len() + 1;
        let f = |r: &[u8], k: usize| -> String {
            String::from_utf8_lossy(&r[8 * k..8 * k + 8])
                .trim()
                .to_string()
        };
        let num = |r: &[u8], k: usize, line: usize| -> Result<usize, IgesError> {
            f(r, k).parse().map_err(|_| {
                err(
                    line,
                    format!("directory field {} is {:?}, not a number", k + 1, f(r, k)),
                )
            })
        };
        let (l2, r2) = pair[1];
        let kind = num(r1, 0, l1)?;
        if kind != 128 || num(r2, 0, l2)? != 128 {
            return Err(err(
                l1,
                format!("entity type {kind} is not supported (only 128)"),
            ));
        }
        let ptr = num(r1, 1, l1)?;
        let count = num(r2, 3, l2)?;
        if ptr != next_p || count == 0 || ptr + count - 1 > p.len() {
            return Err(err(l1, format!(
                "parameter pointer {ptr} with {count} lines does not continue the P section at {next_p} ({} P lines)",
                p.len()
            )));
        }
        next_p = ptr + count;
        let mut text = Vec::with_capacity(64 * count);
        for &(pl, rec) in &p[ptr - 1..ptr - 1 + count] {
            let back = std::str::from_utf8(&rec[64..72]).unwrap_or("").trim();
            if back.parse::<usize>().ok() != Some(de) {
                return Err(err(
                    pl,
                    format!("back-pointer {back:?} does not name its directory entry {de}"),
                ));
            }
            text.extend_from_slice(&rec[..64]);
        }
        let params = fields(&text).map_err(|m| IgesError::Parameter { de, message: m })?;
        surfaces.push(surface_128(&params, de)?);
    }
    if next_p != p.len() + 1 {
        return Err(err(
            lineno,
            format!(
                "{} P lines are not claimed by any directory entry",
                p.len() + 1 - next_p
            ),
        ));
    }
    Ok(IgesFile {
        start_lines,
        global,
        surfaces,
    })
}

fn surface_128(params: &[String], de: usize) -> Result<NurbsSurface, IgesError> {
    let perr = |message: String| IgesError::Parameter { de, message };
    if params.len() < 10 {
        return Err(perr(format!("only {} parameters", params.len())));
    }
    let k1 = parse_int(&params[1], de, "K1")?;
    let k2 = parse_int(&params[2], de, "K2")?;
    let m1 = parse_int(&params[3], de, "M1")?;
    let m2 = parse_int(&params[4], de, "M2")?;
    let sizes = (|| {
        let (nu, nv) = (k1.checked_add(1)?, k2.checked_add(1)?);
        let a = k1.checked_add(m1)?.checked_add(2)?;
        let b = k2.checked_add(m2)?.checked_add(2)?;
        let c = nu.checked_mul(nv)?;
        let expected = a
            .checked_add(b)?
            .checked_add(c.checked_mul(4)?)?
            .checked_add(14)?;
        Some((nu, nv, a, b, c, expected))
    })();
    let Some((nu, nv, a, b, c, expected)) = sizes else {
        return Err(perr(format!(
            "K1={k1}, K2={k2}, M1={m1}, M2={m2} are too large"
        )));
    };
    if params.len() != expected {
        return Err(perr(format!(
            "{} parameters, entity 128 with K1={k1}, K2={k2}, M1={m1}, M2={m2} needs {expected}",
            params.len()
        )));
    }
    let mut it = params[10..].iter().enumerate();
    let mut take = |n: usize, what: &str| -> Result<Vec<f64>, IgesError> {
        (0..n)
            .map(|_| {
                let (i, s) = it
                    .next()
                    .ok_or_else(|| perr("parameters end early".into()))?;
                parse_real(s, de, what, i)
            })
            .collect()
    };
    let ku = take(a, "u knot")?;
    let kv = take(b, "v knot")?;
    let w = take(c, "weight")?;
    if let Some(i) = w.iter().position(|&x| x != 1.0) {
        return Err(perr(format!(
            "weight {i} is {}, only polynomial surfaces are supported",
            w[i]
        )));
    }
    let xyz = take(3 * c, "pole coordinate")?;
    let poles = xyz.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    NurbsSurface::try_new(m1, m2, ku, kv, nu, nv, poles).map_err(|e| perr(e.to_string()))
}
