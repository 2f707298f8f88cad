//! Decimal numbers in text files (the grid and profile CSVs), read fast and exactly.
//!
//! The parsing itself is `fast-float2` (a maintained port of Lemire's fast_float, correctly
//! rounded like `str::parse::<f64>`); what is written here is only how a CSV line is walked
//! (fields, blanks, delimiters) so that one pass over the bytes suffices. Whatever the fast
//! path does not recognise as plainly valid — a non-finite value, an empty field, Unicode
//! blanks, anything the parser stops short on — returns `None`, and callers then take their
//! `str::parse` path, which decides and words the error exactly as before. So the values are
//! those of `str::parse` to the bit, and no input gets a different answer.
//!
//! Layer 0 (vocabulary): depends on nothing else in the crate; no I/O.

use std::num::ParseFloatError;

/// `s.parse::<f64>()`, with finite values read by the fast parser (the same value to the bit)
/// and everything else (errors, infinities, NaN) left to `str::parse`.
pub fn parse_f64(s: &str) -> Result<f64, ParseFloatError> {
    match fast_float2::parse::<f64, _>(s) {
        Ok(v) if v.is_finite() => Ok(v),
        _ => s.parse(),
    }
}

/// ASCII blanks a field may carry around its number (what `str::trim` removes, restricted to
/// the two that occur in practice; others send the line to the slow path).
#[inline]
fn is_blank(b: u8) -> bool {
    b == b' ' || b == b'\t'
}

/// Writes the finite numbers of one `,`-separated line to the front of `out` and returns how
/// many there were, or returns `None` when the line is anything but finite numbers with
/// optional spaces or tabs around them, or has more numbers than `out` has room for (what
/// was written is then to be ignored). `None` means "decide with `str::parse`", never
/// "invalid".
pub fn parse_csv_line(line: &[u8], out: &mut [f64]) -> Option<usize> {
    let mut n = 0;
    let mut rest = line;
    loop {
        while let [b, tail @ ..] = rest {
            if !is_blank(*b) {
                break;
            }
            rest = tail;
        }
        let (value, used) = fast_float2::parse_partial::<f64, _>(rest).ok()?;
        if used == 0 || !value.is_finite() {
            return None;
        }
        *out.get_mut(n)? = value;
        n += 1;
        rest = &rest[used..];
        while let [b, tail @ ..] = rest {
            if !is_blank(*b) {
                break;
            }
            rest = tail;
        }
        match rest {
            [] => return Some(n),
            [b',', tail @ ..] => rest = tail,
            _ => return None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tokens at the edges of the decimal grammar: signs, points without digits on one side,
    /// exponents of every shape, long mantissas, under- and overflow, non-numbers.
    const TOKENS: &[&str] = &[
        "0", "-0", "+0", "1", "+1", "-1", "1.", ".5", "-.5", "+.5", ".", "-", "+", "1.5",
        "-12.25", "1e5", "1E5", "1e+5", "1e-5", "1.e5", ".5e-3", "1e", "1e+", "e5", "1.2.3",
        "0.1", "0.30000000000000004", "1234567890123456789012345678901234567890",
        "0.000000000000000000000000000001234567890123456789", "1e308", "1e309", "-1e309",
        "1e-320", "1e-400", "2.2250738585072014e-308", "4.9406564584124654e-324", "inf",
        "-inf", "+inf", "infinity", "Infinity", "INF", "nan", "NaN", "-nan", "+nan", "0x10",
        "1_000", "1,5", " 1", "1 ", "", "١", "1e0001", "00012", "-00.0100", "9007199254740993",
        "179769313486231570000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000.0",
    ];

    #[test]
    fn single_values_equal_std_parse_to_the_bit_or_its_error() {
        let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut tokens: Vec<String> = TOKENS.iter().map(|t| t.to_string()).collect();
        for _ in 0..20000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let v = f64::from_bits(s);
            tokens.push(format!("{v}"));
            tokens.push(format!("{v:e}"));
            tokens.push(format!("{:.4}", (s % 2_000_000) as f64 / 1000.0 - 1000.0));
        }
        for t in &tokens {
            let ours = parse_f64(t);
            let std = t.parse::<f64>();
            match (ours, std) {
                (Ok(a), Ok(b)) => assert!(
                    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                    "{t:?}: {a} vs {b}"
                ),
                (Err(a), Err(b)) => assert_eq!(a, b, "{t:?}"),
                (a, b) => panic!("{t:?}: {a:?} vs std {b:?}"),
            }
        }
    }

    /// The slow path the callers take: split at ',', trim, `str::parse`.
    fn by_std(line: &str) -> Option<Vec<f64>> {
        line.split(',')
            .map(|f| f.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect()
    }

    #[test]
    fn lines_the_fast_path_accepts_are_read_as_std_reads_them() {
        let mut lines: Vec<String> = Vec::new();
        for a in TOKENS {
            for b in ["2.5", " 3", "", "x", "1e-7\t"] {
                lines.push(format!("{a},{b}"));
                lines.push(format!("{b},{a}"));
                lines.push(format!(" {a} "));
            }
        }
        lines.extend(
            [
                "1,2,3",
                "1,,3",
                ",",
                "1,",
                ",1",
                "1, 2 ,\t3",
                "1;2",
                "1 2",
                "1,2\r",
                "-0.1234,5",
                "\u{a0}1,2",
            ]
            .map(String::from),
        );
        for line in &lines {
            // Room for one number per comma and one more: as many as any line can hold.
            let mut out = vec![42.0; line.matches(',').count() + 2];
            // `None` leaves the line to `str::parse`: whatever it wrote is ignored.
            if let Some(n) = parse_csv_line(line.as_bytes(), &mut out) {
                let std = by_std(line).unwrap_or_else(|| {
                    panic!("{line:?}: the fast path accepts what str::parse refuses")
                });
                assert_eq!(n, std.len(), "{line:?}");
                assert_eq!(out[n], 42.0, "{line:?}: written past its numbers");
                for (a, b) in out.iter().zip(&std) {
                    assert_eq!(a.to_bits(), b.to_bits(), "{line:?}");
                }
            }
        }
        // Plain data lines are taken by the fast path; a line with more numbers than room is
        // not.
        let mut out = [0.0; 4];
        assert_eq!(parse_csv_line(b"-0.1234,5,1e-3, 7.5", &mut out), Some(4));
        assert_eq!(out, [-0.1234, 5.0, 1e-3, 7.5]);
        assert_eq!(parse_csv_line(b"1,2,3,4,5", &mut out), None);
    }
}
