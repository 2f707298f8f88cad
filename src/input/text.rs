//! How a CSV file of heights is written: its separator (`,`, `;` or a tab), its decimal mark
//! (a point, or a comma where the separator is not one), comment lines (`#`), a header line
//! and the units it names. Found from the text itself and said in words when it is not the
//! plain format (`,`, decimal points, no header), so a file is read as written or refused
//! with the reason, never misread.
//!
//! Pure (no I/O), inside the reading layer: text in, a description out; depends on
//! [`crate::numbers`] only.

/// A unit of length as a file or a flag names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    /// Nanometres.
    Nm,
    /// Micrometres (µm).
    Um,
    /// Millimetres.
    Mm,
}

impl Unit {
    /// Micrometres in one of this unit.
    pub fn in_um(self) -> f64 {
        match self {
            Unit::Nm => 1e-3,
            Unit::Um => 1.0,
            Unit::Mm => 1e3,
        }
    }

    /// The unit as written: `nm`, `µm`, `mm`.
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Nm => "nm",
            Unit::Um => "µm",
            Unit::Mm => "mm",
        }
    }

    /// The unit as the `--z-unit` flag spells it (`nm`, `um`, `mm`).
    pub fn flag(self) -> &'static str {
        match self {
            Unit::Nm => "nm",
            Unit::Um => "um",
            Unit::Mm => "mm",
        }
    }
}

impl std::str::FromStr for Unit {
    type Err = String;

    /// `nm`, `um` (or `µm`) or `mm`.
    fn from_str(s: &str) -> Result<Unit, String> {
        match s.trim() {
            "nm" => Ok(Unit::Nm),
            "um" | "µm" | "μm" => Ok(Unit::Um),
            "mm" => Ok(Unit::Mm),
            other => Err(format!("{other:?} is not a height unit: give nm, um or mm")),
        }
    }
}

/// The separator and decimal mark of a CSV text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dialect {
    /// `,`, `;` or `\t`.
    pub separator: u8,
    /// Decimal commas (`1,25`): only where the separator is not a comma.
    pub decimal_comma: bool,
}

impl Dialect {
    /// `,` separated, decimal points: the format written by surfscan and most software.
    pub const PLAIN: Dialect = Dialect {
        separator: b',',
        decimal_comma: false,
    };

    /// The fields of `line`, trimmed and unquoted (a separator inside double quotes is part
    /// of the field).
    pub fn fields<'a>(&self, line: &'a str) -> Vec<&'a str> {
        let mut out = Vec::new();
        let (bytes, mut start, mut quoted) = (line.as_bytes(), 0usize, false);
        for (i, &b) in bytes.iter().enumerate() {
            if b == b'"' {
                quoted = !quoted;
            } else if b == self.separator && !quoted {
                out.push(unquote(&line[start..i]));
                start = i + 1;
            }
        }
        out.push(unquote(&line[start..]));
        out
    }

    /// One field as a number, a decimal comma read as a point; `None` when it is not one.
    pub fn number(&self, field: &str) -> Option<f64> {
        if self.decimal_comma && field.contains(',') {
            crate::numbers::parse_f64(&field.replace(',', ".")).ok()
        } else {
            crate::numbers::parse_f64(field).ok()
        }
    }
}

fn unquote(f: &str) -> &str {
    let f = f.trim();
    f.strip_prefix('"')
        .and_then(|f| f.strip_suffix('"'))
        .map_or(f, str::trim)
}

/// What the text of a CSV file is, before its values are read.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Separator and decimal mark.
    pub dialect: Dialect,
    /// The header line, when the first line that is not a comment holds no number: its
    /// 0-based line in the file and its text.
    pub header: Option<(usize, String)>,
    /// Comment lines (starting with `#`) before the data.
    pub comments: usize,
    /// 0-based line in the file where the data start.
    pub data_from: usize,
}

impl Layout {
    /// What the reader found beyond the plain format, one sentence each.
    pub fn findings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.comments > 0 {
            out.push(format!(
                "{} comment line{} (starting with #) before the data {} skipped",
                self.comments,
                if self.comments == 1 { "" } else { "s" },
                if self.comments == 1 { "was" } else { "were" }
            ));
        }
        if let Some((line, text)) = &self.header {
            out.push(format!(
                "line {} is a header ({:?}), not heights; it was skipped",
                line + 1,
                shorten(text)
            ));
        }
        match self.dialect.separator {
            b';' => out.push("values are separated by ';' (not ',')".into()),
            b'\t' => out.push("values are separated by tabs (not ',')".into()),
            _ => {}
        }
        if self.dialect.decimal_comma {
            out.push("decimal commas (1,25) are read as decimal points (1.25)".into());
        }
        out
    }
}

fn shorten(s: &str) -> String {
    let s = s.trim();
    match s.char_indices().nth(60) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s.to_string(),
    }
}

/// Lines looked at for decimal commas.
const DIALECT_LINES: usize = 1000;

/// Finds the layout of `text`: comment lines at the top, then a header if the first other
/// line holds no number; the separator from the first data line (`;` if it has one, else a
/// tab if it has one, else `,`); decimal commas where the separator is not a comma and the
/// data (their first thousand lines) hold commas. A number written with both marks (`1.234,5`) cannot be read without
/// guessing which is the decimal mark: refused with the line and the field.
pub fn layout(text: &str) -> Result<Layout, String> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let mut comments = 0;
    let mut first = None;
    for (n, l) in lines.by_ref() {
        if l.trim_start().starts_with('#') {
            comments += 1;
        } else {
            first = Some((n, l));
            break;
        }
    }
    let Some((n0, l0)) = first else {
        return Ok(Layout {
            dialect: Dialect::PLAIN,
            header: None,
            comments,
            data_from: text.lines().count(),
        });
    };
    let dialect_of = |line: &str| {
        let separator = if line.contains(';') {
            b';'
        } else if line.contains('\t') {
            b'\t'
        } else {
            b','
        };
        Dialect {
            separator,
            decimal_comma: separator != b',' && line.contains(','),
        }
    };
    // A header holds no number in any field, whichever separator it uses.
    let d0 = dialect_of(l0);
    let is_header = d0.fields(l0).iter().all(|f| d0.number(f).is_none());
    let (header, data) = if is_header {
        (Some((n0, l0.to_string())), lines.next())
    } else {
        (None, Some((n0, l0)))
    };
    let mut dialect = data.map_or(Dialect::PLAIN, |(_, l)| dialect_of(l));
    // A decimal comma may first appear on a later line (`1.5;2` then `3;4,5`).
    if dialect.separator != b',' && !dialect.decimal_comma {
        dialect.decimal_comma = text
            .lines()
            .skip(data.map_or(0, |(n, _)| n))
            .take(DIALECT_LINES)
            .any(|l| l.contains(','));
    }
    if let Some((n, l)) = data {
        if dialect.decimal_comma {
            if let Some(f) = dialect
                .fields(l)
                .into_iter()
                .find(|f| f.contains(',') && f.contains('.'))
            {
                return Err(format!(
                    "line {}: {f:?} has both a decimal point and a comma, so which one is the decimal mark cannot be told; write the numbers without a thousands separator",
                    n + 1
                ));
            }
        }
    }
    Ok(Layout {
        dialect,
        header,
        comments,
        data_from: data.map_or(text.lines().count(), |(n, _)| n),
    })
}

/// The length units a header line names, in order of first appearance, each once: `z_um`,
/// `height [nm]`, `z (mm)`, `µm`, `microns`. A unit counts only as a word of its own or after
/// `_`, `[`, `(`, `/` or a space, so `mmhg` or `summary` name none.
pub fn units_named(header: &str) -> Vec<Unit> {
    let lower = header.to_lowercase();
    let mut out = Vec::new();
    let words = lower
        .split(|c: char| !(c.is_alphanumeric() || c == 'µ' || c == 'μ'))
        .filter(|w| !w.is_empty());
    for w in words {
        // `z_um` splits at `_`; `zum` is no unit.
        let unit = match w {
            "nm" | "nanometre" | "nanometres" | "nanometer" | "nanometers" => Some(Unit::Nm),
            "um" | "µm" | "μm" | "micron" | "microns" | "micrometre" | "micrometres"
            | "micrometer" | "micrometers" => Some(Unit::Um),
            "mm" | "millimetre" | "millimetres" | "millimeter" | "millimeters" => Some(Unit::Mm),
            _ => None,
        };
        if let Some(u) = unit {
            if !out.contains(&u) {
                out.push(u);
            }
        }
    }
    out
}

/// A header field's name without its unit: `z_um` → `z`, `x [mm]` → `x`, `Height (nm)` →
/// `height`.
pub fn column_name(field: &str) -> String {
    field
        .trim()
        .to_lowercase()
        .split(['_', '[', '(', ' ', '/'])
        .next()
        .unwrap_or_default()
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plain_format_has_no_findings() {
        let l = layout("1,2,3\n4,5,6\n").unwrap();
        assert_eq!(l.dialect, Dialect::PLAIN);
        assert_eq!((l.header.clone(), l.comments, l.data_from), (None, 0, 0));
        assert!(l.findings().is_empty());
    }

    #[test]
    fn separators_decimal_commas_headers_and_comments_are_found_and_said() {
        let l = layout("# exported\n\nz [nm];z [nm]\n1,5;2,25\n").unwrap();
        assert_eq!(
            l.dialect,
            Dialect {
                separator: b';',
                decimal_comma: true
            }
        );
        assert_eq!(l.header, Some((2, "z [nm];z [nm]".into())));
        assert_eq!((l.comments, l.data_from), (1, 3));
        let f = l.findings().join(" | ");
        assert!(
            f.contains("1 comment line (starting with #) before the data was skipped"),
            "{f}"
        );
        assert!(f.contains("line 3 is a header"), "{f}");
        assert!(
            f.contains("separated by ';'") && f.contains("decimal commas"),
            "{f}"
        );
        assert_eq!(l.dialect.fields("1,5;2,25"), vec!["1,5", "2,25"]);
        assert_eq!(l.dialect.number("1,5"), Some(1.5));

        let l = layout("1.5\t-2.5\n").unwrap();
        assert_eq!(
            (l.dialect.separator, l.dialect.decimal_comma),
            (b'\t', false)
        );
        assert!(l.findings()[0].contains("tabs"));
    }

    #[test]
    fn a_number_with_both_marks_is_refused_naming_it() {
        let e = layout("1.234,5;2\n").unwrap_err();
        assert!(e.contains("line 1") && e.contains("\"1.234,5\""), "{e}");
    }

    #[test]
    fn quoted_fields_keep_their_separators() {
        let d = Dialect::PLAIN;
        assert_eq!(d.fields(r#""1,5", "2" ,3"#), vec!["1,5", "2", "3"]);
        let l = layout("\"1,5\",\"2,5\"\n").unwrap();
        // A comma inside quotes with ',' as the separator is not read as a decimal mark: the
        // field is not a number and the reader names it.
        assert_eq!(
            l.dialect.number(l.dialect.fields("\"1,5\",\"2,5\"")[0]),
            None
        );
    }

    #[test]
    fn units_are_words_of_their_own() {
        assert_eq!(units_named("z_um,z_um"), vec![Unit::Um]);
        assert_eq!(units_named("x_mm,z_nm"), vec![Unit::Mm, Unit::Nm]);
        assert_eq!(units_named("Height [µm]"), vec![Unit::Um]);
        assert_eq!(units_named("height (microns)"), vec![Unit::Um]);
        assert!(units_named("summary,mmhg,zum").is_empty());
        assert_eq!(column_name(" Height (nm)"), "height");
        assert_eq!(column_name("x_mm"), "x");
    }
}
