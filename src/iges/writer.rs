//! The IGES 5.3 writer: Start, Global, Directory Entry, Parameter Data and Terminate sections
//! for one independent entity 128 (polynomial B-spline surface, form 0) per patch, in mm.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] and the formatting in [`super::format`];
//! a formatter over any `io::Write` (the caller picks and syncs the file).

use super::format::{ascii_printable, hollerith, push_real, push_right, push_uint, FieldPacker};
use super::split::split_v_middle;
use super::IgesError;
use crate::nurbs::NurbsSurface;
use std::io::{self, Write};

/// Largest sequence number a section may reach (7-digit field).
pub const MAX_SECTION_LINES: usize = 9_999_999;

/// What the writer puts into the Start and Global sections, and how large an entity may get.
#[derive(Debug, Clone)]
pub struct IgesOptions {
    /// G4: the file name recorded inside the file (usually the output's file name).
    pub file_name: String,
    /// G3/G5/G12: sending system and product id (e.g. `surfscan`).
    pub sender: String,
    /// G21: author.
    pub author: String,
    /// G22: organisation.
    pub organisation: String,
    /// G18/G25: creation and last-change date, passed in so output is deterministic.
    pub timestamp: chrono::NaiveDateTime,
    /// Start section text (traceability: specimen, operator, instrument, software version).
    /// Wrapped to 72 columns.
    pub start_lines: Vec<String>,
    /// Largest number of Parameter Data lines one entity may take; larger surfaces are split
    /// along v into exact patches. Default [`MAX_SECTION_LINES`].
    pub max_parameter_lines_per_entity: usize,
    /// Largest number of Parameter Data lines one file may take (the P section's 7-digit
    /// sequence field caps it at [`MAX_SECTION_LINES`]); [`plan_files`] groups patches into
    /// as many files as needed. Default [`MAX_SECTION_LINES`].
    pub max_parameter_lines_per_file: usize,
}

impl Default for IgesOptions {
    fn default() -> Self {
        IgesOptions {
            file_name: "surface.igs".into(),
            sender: "surfscan".into(),
            author: String::new(),
            organisation: String::new(),
            timestamp: chrono::NaiveDateTime::default(),
            start_lines: Vec::new(),
            max_parameter_lines_per_entity: MAX_SECTION_LINES,
            max_parameter_lines_per_file: MAX_SECTION_LINES,
        }
    }
}

/// What was written.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct IgesStats {
    /// Number of entity 128 patches written (1 unless the surface was split).
    pub patches: usize,
    /// Start section lines.
    pub start_lines: usize,
    /// Global section lines.
    pub global_lines: usize,
    /// Directory Entry lines.
    pub directory_lines: usize,
    /// Parameter Data lines.
    pub parameter_lines: usize,
    /// Bytes written (80 columns + newline per line).
    pub bytes: u64,
}

/// Nets with at least this many poles are formatted in parallel chunks.
const PARALLEL_POLES: usize = 65_536;
/// Number of chunks a large net is formatted in (fixed, so output is reproducible).
const POLE_CHUNKS: usize = 4;

/// Minimum user-intended resolution written in G19, mm (well below height resolution).
pub const MIN_RESOLUTION_MM: f64 = 1e-7;

/// The parameter data (columns 1–64 of each P line) of one entity, as consecutive segments
/// of whole 64-column records (kept apart rather than copied into one buffer).
struct ParamText {
    segments: Vec<Vec<u8>>,
}

impl ParamText {
    /// Number of P lines.
    fn lines(&self) -> usize {
        self.segments.iter().map(|s| s.len() / 64).sum()
    }

    /// The 64-column records in order.
    fn records(&self) -> impl Iterator<Item = &[u8]> {
        self.segments.iter().flat_map(|s| s.chunks_exact(64))
    }
}

/// Formats the parameter data (columns 1–64 of each P line) of one entity 128.
fn entity_128_params(s: &NurbsSurface, patch: usize) -> Result<ParamText, IgesError> {
    let (nu, nv) = (s.count_u(), s.count_v());
    // Header, knots and weights: 3 bytes per weight and up to 25 per knot.
    let knots = s.knots_u().len() + s.knots_v().len();
    let mut p = FieldPacker::with_capacity(64, nu * nv * 3 + knots * 25 + 4096);
    let mut tok = Vec::with_capacity(32);
    let closed_u = (0..nv).all(|j| s.pole(0, j) == s.pole(nu - 1, j));
    let closed_v = (0..nu).all(|i| s.pole(i, 0) == s.pole(i, nv - 1));
    let head: [u64; 10] = [
        128,
        (nu - 1) as u64,
        (nv - 1) as u64,
        s.degree_u() as u64,
        s.degree_v() as u64,
        u64::from(closed_u),
        u64::from(closed_v),
        1, // polynomial: all weights 1
        0,
        0,
    ];
    for h in head {
        tok.clear();
        push_uint(&mut tok, h);
        p.push(&tok, b',');
    }
    let real = |p: &mut FieldPacker, v: f64, what: &'static str, index: usize, delim: u8| {
        if p.push_real(v, delim) {
            Ok(())
        } else {
            Err(IgesError::NonFinite {
                patch,
                what,
                index,
                value: v,
            })
        }
    };
    for (i, &k) in s.knots_u().iter().enumerate() {
        real(&mut p, k, "u knot", i, b',')?;
    }
    for (i, &k) in s.knots_v().iter().enumerate() {
        real(&mut p, k, "v knot", i, b',')?;
    }
    for _ in 0..nu * nv {
        p.push(b"1.", b',');
    }
    // Poles are most of the text: large nets are formatted in a fixed number of chunks on
    // scoped threads, each chunk starting a fresh record (a record may end early after any
    // delimiter), so the output does not depend on how many cores run it.
    let poles = s.poles();
    let chunk = if poles.len() >= PARALLEL_POLES {
        poles.len().div_ceil(POLE_CHUNKS)
    } else {
        poles.len().max(1)
    };
    let format_chunk = |first: usize, part: &[[f64; 3]]| -> Result<Vec<u8>, IgesError> {
        let mut q = FieldPacker::with_capacity(64, part.len() * 72 + 64);
        for (k, pole) in part.iter().enumerate() {
            for &c in pole {
                real(&mut q, c, "pole coordinate", first + k, b',')?;
            }
        }
        Ok(q.finish())
    };
    let parts: Vec<Result<Vec<u8>, IgesError>> = if poles.len() >= PARALLEL_POLES {
        std::thread::scope(|scope| {
            let handles: Vec<_> = poles
                .chunks(chunk)
                .enumerate()
                .map(|(n, part)| {
                    let f = &format_chunk;
                    scope.spawn(move || f(n * chunk, part))
                })
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join().unwrap_or_else(|_| {
                        Err(IgesError::Io(io::Error::other("formatting thread failed")))
                    })
                })
                .collect()
        })
    } else {
        vec![format_chunk(0, poles)]
    };
    // Each pole chunk starts a fresh record and so does the parameter range after them, as
    // if all were appended to one packer.
    let mut segments = Vec::with_capacity(parts.len() + 2);
    segments.push(p.finish());
    for part in parts {
        segments.push(part?);
    }
    let mut tail = FieldPacker::new(64);
    let (ku, kv) = (s.knots_u(), s.knots_v());
    let dom = [ku[s.degree_u()], ku[nu], kv[s.degree_v()], kv[nv]];
    for (i, &d) in dom.iter().enumerate() {
        real(
            &mut tail,
            d,
            "parameter range",
            i,
            if i == 3 { b';' } else { b',' },
        )?;
    }
    segments.push(tail.finish());
    Ok(ParamText { segments })
}

/// Formats `surface`, splitting it along v into exact patches until each fits in
/// `max_lines` P lines. Appends (surface P data) per patch.
fn format_patches(
    surface: &NurbsSurface,
    max_lines: usize,
    out: &mut Vec<ParamText>,
) -> Result<(), IgesError> {
    let data = entity_128_params(surface, out.len())?;
    let lines = data.lines();
    if lines <= max_lines {
        out.push(data);
        return Ok(());
    }
    drop(data);
    match split_v_middle(surface) {
        Some((lower, upper)) => {
            format_patches(&lower, max_lines, out)?;
            format_patches(&upper, max_lines, out)
        }
        None => Err(IgesError::EntityTooLarge {
            lines,
            max_lines,
            count_u: surface.count_u(),
            count_v: surface.count_v(),
        }),
    }
}

/// Splits `surface` along v until each patch needs at most `max_lines` P lines; appends
/// (patch, its P line count) in v order. Formats each candidate once to count its lines.
fn split_to_fit(
    surface: NurbsSurface,
    max_lines: usize,
    out: &mut Vec<(NurbsSurface, usize)>,
) -> Result<(), IgesError> {
    let lines = entity_128_params(&surface, out.len())?.lines();
    if lines <= max_lines {
        out.push((surface, lines));
        return Ok(());
    }
    match split_v_middle(&surface) {
        Some((lower, upper)) => {
            drop(surface);
            split_to_fit(lower, max_lines, out)?;
            split_to_fit(upper, max_lines, out)
        }
        None => Err(IgesError::EntityTooLarge {
            lines,
            max_lines,
            count_u: surface.count_u(),
            count_v: surface.count_v(),
        }),
    }
}

/// Longest real token with its delimiter: sign, 17 digits, point, `E-308`, delimiter.
const MAX_REAL_TOKEN: usize = 25;

/// An upper bound on the P lines [`entity_128_params`] takes for `s`, from token counts
/// alone. Every token (with its delimiter) is at most [`MAX_REAL_TOKEN`] bytes, so each
/// 64-column record of a segment but the last holds at least two; the weights (`1.,`)
/// hold 21 a record; each segment may end with one partial record.
fn p_lines_bound(s: &NurbsSurface) -> usize {
    let poles = s.count_u().saturating_mul(s.count_v());
    let per_record = 64 / MAX_REAL_TOKEN;
    let head_tokens = 10 + s.knots_u().len() + s.knots_v().len();
    let chunks = if poles >= PARALLEL_POLES {
        POLE_CHUNKS
    } else {
        1
    };
    head_tokens.div_ceil(per_record)
        + poles.div_ceil(64 / 3)
        + 1
        + poles.saturating_mul(3).div_ceil(per_record)
        + chunks
        + 1
}

/// Plans how `surface` is written: splits it along v into exact patches (adjacent patches
/// share their boundary pole row, so their union is exactly the surface), each needing at
/// most `opts.max_parameter_lines_per_entity` and `opts.max_parameter_lines_per_file` P lines,
/// then groups consecutive patches into files whose P sections stay within
/// `opts.max_parameter_lines_per_file` (never more than [`MAX_SECTION_LINES`]). Returns one
/// group per file, in v order; pass each group to [`write_iges`]. One group means one file.
pub fn plan_files(
    surface: &NurbsSurface,
    opts: &IgesOptions,
) -> Result<Vec<Vec<NurbsSurface>>, IgesError> {
    let file_cap = opts
        .max_parameter_lines_per_file
        .clamp(1, MAX_SECTION_LINES);
    let entity_cap = opts.max_parameter_lines_per_entity.clamp(1, file_cap);
    // Usually the whole surface fits one entity in one file by a wide margin; a bound on its
    // P lines shows that without formatting it (write_iges formats it once, later). The
    // result is the one the exact count below would give.
    if p_lines_bound(surface) <= entity_cap {
        return Ok(vec![vec![surface.clone()]]);
    }
    let mut patches = Vec::new();
    split_to_fit(surface.clone(), entity_cap, &mut patches)?;
    let mut files: Vec<Vec<NurbsSurface>> = Vec::new();
    let mut current: Vec<NurbsSurface> = Vec::new();
    let mut current_lines = 0usize;
    for (patch, lines) in patches {
        // Two DE lines per entity; the DE section shares the same 7-digit cap.
        let fits =
            current_lines + lines <= file_cap && 2 * (current.len() + 1) <= MAX_SECTION_LINES;
        if !current.is_empty() && !fits {
            files.push(std::mem::take(&mut current));
            current_lines = 0;
        }
        current_lines += lines;
        current.push(patch);
    }
    if !current.is_empty() {
        files.push(current);
    }
    Ok(files)
}

/// Wraps free text to 72 columns at spaces (hard-splitting longer words).
fn wrap72(lines: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    for line in lines {
        let text = ascii_printable(line);
        let mut cur = String::new();
        for word in text.split(' ').filter(|w| !w.is_empty()) {
            let mut word = word;
            loop {
                let sep = usize::from(!cur.is_empty());
                if cur.len() + sep + word.len() <= 72 {
                    if sep == 1 {
                        cur.push(' ');
                    }
                    cur.push_str(word);
                    break;
                }
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                    continue;
                }
                let (head, tail) = word.split_at(72);
                out.push(head.to_string());
                word = tail;
            }
        }
        out.push(cur);
    }
    if out.is_empty() {
        out.push("NURBS surface (entity 128), units mm.".into());
    }
    out
}

/// Appends one 80-column record: `data` (≤ 72 bytes, padded), section letter, sequence.
fn record(out: &mut Vec<u8>, data: &[u8], section: u8, seq: usize) {
    out.extend_from_slice(data);
    out.extend(std::iter::repeat_n(
        b' ',
        72usize.saturating_sub(data.len()),
    ));
    out.push(section);
    push_right(out, seq as i64, 7);
    out.push(b'\n');
}

fn date_stamp(t: &chrono::NaiveDateTime) -> String {
    hollerith(&t.format("%Y%m%d.%H%M%S").to_string())
}

/// Writes `surfaces` as an IGES 5.3 file: one independent entity 128 per surface (or per
/// patch when a surface needs more than `opts.max_parameter_lines_per_entity` P lines).
pub fn write_iges<W: Write>(
    w: W,
    surfaces: &[NurbsSurface],
    opts: &IgesOptions,
) -> Result<IgesStats, IgesError> {
    if surfaces.is_empty() {
        return Err(IgesError::NoSurfaces);
    }
    let file_cap = opts
        .max_parameter_lines_per_file
        .clamp(1, MAX_SECTION_LINES);
    let max_lines = opts
        .max_parameter_lines_per_entity
        .clamp(1, MAX_SECTION_LINES);
    let mut patches: Vec<ParamText> = Vec::new();
    for s in surfaces {
        format_patches(s, max_lines, &mut patches)?;
    }
    let p_lines: usize = patches.iter().map(ParamText::lines).sum();
    let d_lines = 2 * patches.len();
    if p_lines > file_cap {
        return Err(IgesError::SectionTooLong {
            section: 'P',
            lines: p_lines,
            max_lines: file_cap,
        });
    }
    if d_lines > MAX_SECTION_LINES {
        return Err(IgesError::SectionTooLong {
            section: 'D',
            lines: d_lines,
            max_lines: MAX_SECTION_LINES,
        });
    }
    let max_coord = surfaces
        .iter()
        .flat_map(|s| s.poles().iter())
        .flat_map(|p| p.iter())
        .fold(0.0f64, |m, c| m.max(c.abs()));

    let mut counter = CountingWriter { inner: w, bytes: 0 };
    let mut buf = Vec::with_capacity((1 << 21) + 128);

    // Start section.
    let start = wrap72(&opts.start_lines);
    for (i, line) in start.iter().enumerate() {
        record(&mut buf, line.as_bytes(), b'S', i + 1);
    }

    // Global section: 26 parameters.
    let mut g = FieldPacker::new(72);
    let real_tok = |v: f64| {
        let mut t = Vec::new();
        push_real(&mut t, v);
        t
    };
    let date = date_stamp(&opts.timestamp);
    let version = format!("{} {}", opts.sender, env!("CARGO_PKG_VERSION"));
    let params: Vec<Vec<u8>> = vec![
        b"1H,".to_vec(),
        b"1H;".to_vec(),
        hollerith(&opts.sender).into_bytes(),
        hollerith(&opts.file_name).into_bytes(),
        hollerith(&version).into_bytes(),
        hollerith(env!("CARGO_PKG_VERSION")).into_bytes(),
        b"32".to_vec(),
        b"38".to_vec(),
        b"6".to_vec(),
        b"308".to_vec(),
        b"15".to_vec(),
        hollerith(&opts.sender).into_bytes(),
        real_tok(1.0),
        b"2".to_vec(),
        b"2HMM".to_vec(),
        b"1".to_vec(),
        real_tok(0.0),
        date.clone().into_bytes(),
        real_tok(MIN_RESOLUTION_MM),
        real_tok(max_coord),
        hollerith(&opts.author).into_bytes(),
        hollerith(&opts.organisation).into_bytes(),
        b"11".to_vec(),
        b"0".to_vec(),
        date.into_bytes(),
        hollerith("NONE").into_bytes(),
    ];
    let last = params.len() - 1;
    for (i, p) in params.iter().enumerate() {
        // An empty string is written as an empty field (the default), not `0H`.
        let tok: &[u8] = if p.as_slice() == b"0H" { b"" } else { p };
        g.push(tok, if i == last { b';' } else { b',' });
    }
    let g_data = g.finish();
    let g_lines = g_data.len() / 72;
    for (i, chunk) in g_data.chunks_exact(72).enumerate() {
        record(&mut buf, chunk, b'G', i + 1);
    }

    // Directory entries.
    let mut pd_pointer = 1usize;
    let mut field = Vec::with_capacity(80);
    for (k, data) in patches.iter().enumerate() {
        let n = data.lines();
        field.clear();
        for v in [128, pd_pointer as i64, 0, 0, 0, 0, 0, 0] {
            push_right(&mut field, v, 8);
        }
        field.extend_from_slice(b"00000000");
        record(&mut buf, &field, b'D', 2 * k + 1);
        field.clear();
        for v in [128, 0, 0, n as i64, 0] {
            push_right(&mut field, v, 8);
        }
        field.extend_from_slice(b"                   PATCH");
        push_right(&mut field, (k + 1) as i64, 8);
        record(&mut buf, &field, b'D', 2 * k + 2);
        pd_pointer += n;
    }
    counter.write_all(&buf)?;
    buf.clear();

    // Parameter data: columns 65–72 hold the DE back-pointer.
    // Each line is assembled in a fixed 81-byte template; the sequence number is counted up
    // in its decimal digits (p_lines fits in the 7-digit field, checked above).
    let mut line = [b' '; 81];
    line[72] = b'P';
    line[80] = b'\n';
    let mut seq = SequenceField::new();
    for (k, data) in patches.iter().enumerate() {
        let mut back = Vec::with_capacity(8);
        push_right(&mut back, (2 * k + 1) as i64, 8);
        line[64..72].copy_from_slice(&back);
        for chunk in data.records() {
            line[..64].copy_from_slice(chunk);
            seq.increment();
            line[73..80].copy_from_slice(&seq.digits);
            buf.extend_from_slice(&line);
            if buf.len() >= 1 << 21 {
                counter.write_all(&buf)?;
                buf.clear();
            }
        }
    }

    // Terminate.
    let mut t = Vec::with_capacity(72);
    for (letter, count) in [
        (b'S', start.len()),
        (b'G', g_lines),
        (b'D', d_lines),
        (b'P', p_lines),
    ] {
        t.push(letter);
        push_right(&mut t, count as i64, 7);
    }
    record(&mut buf, &t, b'T', 1);
    counter.write_all(&buf)?;
    counter.flush()?;
    Ok(IgesStats {
        patches: patches.len(),
        start_lines: start.len(),
        global_lines: g_lines,
        directory_lines: d_lines,
        parameter_lines: p_lines,
        bytes: counter.bytes,
    })
}

/// A 7-column right-justified sequence number kept as text and counted up in place.
struct SequenceField {
    digits: [u8; 7],
}

impl SequenceField {
    /// The field before the first line (blank; the first increment makes it 1).
    fn new() -> SequenceField {
        SequenceField { digits: [b' '; 7] }
    }

    /// Adds one (the caller keeps the count within seven digits).
    fn increment(&mut self) {
        for d in self.digits.iter_mut().rev() {
            match *d {
                b'9' => *d = b'0',
                b' ' => {
                    *d = b'1';
                    return;
                }
                _ => {
                    *d += 1;
                    return;
                }
            }
        }
    }
}

struct CountingWriter<W> {
    inner: W,
    bytes: u64,
}

impl<W: Write> Write for CountingWriter<W> {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(b)?;
        self.bytes += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A degree-3 surface whose every real takes the longest form (`-d.dddddddddddddddE-3dd`).
    fn longest_tokens(nu: usize, nv: usize) -> NurbsSurface {
        let d = 3;
        let knots = |n: usize| {
            let mut k = vec![0.0; d + 1];
            k.extend((1..n - d).map(|j| j as f64 / (n - d) as f64 * 0.999_999_999_999_999_9));
            k.extend(vec![1.0; d + 1]);
            k
        };
        let v = -1.234_567_890_123_456_7e-300;
        NurbsSurface::try_new(d, d, knots(nu), knots(nv), nu, nv, vec![[v; 3]; nu * nv]).unwrap()
    }

    #[test]
    fn p_line_bound_is_never_below_the_real_count() {
        let mut real = Vec::new();
        assert!(crate::iges::format::push_real(
            &mut real,
            -1.234_567_890_123_456_7e-300
        ));
        assert_eq!(
            real.len() + 1,
            MAX_REAL_TOKEN,
            "{}",
            String::from_utf8_lossy(&real)
        );
        // Small nets (one pole chunk) and one past the parallel threshold (four chunks).
        for (nu, nv) in [(4, 4), (37, 5), (PARALLEL_POLES / 8 + 1, 8)] {
            let s = longest_tokens(nu, nv);
            let lines = entity_128_params(&s, 0).unwrap().lines();
            let bound = p_lines_bound(&s);
            assert!(bound >= lines, "{nu}x{nv}: bound {bound} < {lines} lines");
            // Tight enough to be useful: within 1.6x for these worst-case tokens.
            assert!(
                bound * 10 <= lines * 16,
                "{nu}x{nv}: bound {bound} vs {lines}"
            );
        }
    }

    #[test]
    fn plan_without_formatting_equals_the_exact_plan() {
        let s = longest_tokens(40, 6);
        let lines = entity_128_params(&s, 0).unwrap().lines();
        let bound = p_lines_bound(&s);
        // At the bound the shortcut answers; exactly at the real count the formatting path
        // answers; both give the surface unsplit. One line less splits it.
        for cap in [bound, lines] {
            let opts = IgesOptions {
                max_parameter_lines_per_entity: cap,
                ..IgesOptions::default()
            };
            let plan = plan_files(&s, &opts).unwrap();
            assert_eq!(plan.len(), 1);
            assert_eq!(plan[0], vec![s.clone()]);
        }
        let opts = IgesOptions {
            max_parameter_lines_per_entity: lines - 1,
            ..IgesOptions::default()
        };
        let plan = plan_files(&s, &opts).unwrap();
        assert!(plan.iter().map(Vec::len).sum::<usize>() >= 2);
    }

    #[test]
    fn sequence_field_counts_like_right_justified_decimal() {
        let mut seq = SequenceField::new();
        let mut expected = Vec::with_capacity(7);
        for n in 1..=1_000_123i64 {
            seq.increment();
            if n <= 1200 || (999_990..=1_000_010).contains(&n) || n % 9973 == 0 {
                expected.clear();
                push_right(&mut expected, n, 7);
                assert_eq!(&seq.digits[..], &expected[..], "{n}");
            }
        }
    }
}
