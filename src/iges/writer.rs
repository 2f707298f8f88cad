//! The IGES 5.3 writer: Start, Global, Directory Entry, Parameter Data and Terminate sections
//! for one independent entity 128 (polynomial B-spline surface, form 0) per patch, in mm.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`], [`crate::extremes`] and the formatting
//! in [`super::format`];
//! a formatter over any `io::Write` (the caller picks and syncs the file).
//!
//! The Parameter Data is streamed: each entity's records are formatted in pieces (the reals
//! on worker threads started with the entity, so they run beside its header, knots and
//! weights, each reusing its pieces' buffers; packed into records in order on the calling
//! thread) and written as they come, so a file of any size needs a few MB of buffers. The Directory Entry section, which
//! precedes the data but holds each entity's line count, is written with zero counts first and
//! rewritten in place at the end (its lines have a fixed width); [`write_iges_seekable`] does
//! this on a seekable writer such as a file, [`write_iges`] on any writer through a buffer.
//! Parts and patches are planned from token counts (an upper bound on the lines of each
//! entity), never by formatting the surface first.

use super::format::{ascii_printable, hollerith, push_real, push_right, push_uint, FieldPacker};
use super::split::{split_middle_shapes, split_v_middle, split_v_middle_side, PatchShape, Side};
use super::IgesError;
use crate::extremes::min_max;
use crate::nurbs::{NurbsSurface, PoleNet, RowY};
use std::borrow::Cow;
use std::io::{self, Write};
use std::io::{Seek, SeekFrom};

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

/// Nets with at least this many poles are formatted as [`POLE_CHUNKS`] chunks, each starting
/// a fresh record (a fixed layout, so the bytes do not depend on how many cores run it).
const PARALLEL_POLES: usize = 65_536;
/// Number of chunks a large net is formatted in.
const POLE_CHUNKS: usize = 4;
/// Poles whose reals a worker formats at a time.
const PIECE_POLES: usize = 4096;
/// Records are handed on (and P lines written) in blocks of about this many bytes.
const BLOCK_BYTES: usize = 1 << 20;

/// Minimum user-intended resolution written in G19, mm (well below height resolution).
pub const MIN_RESOLUTION_MM: f64 = 1e-7;

/// The IGES texts of a piece of poles' coordinates, concatenated, with each one's length.
#[derive(Default)]
struct Tokens {
    text: Vec<u8>,
    lens: Vec<u8>,
}

/// The IGES text of one coordinate per column (x) or per row (y) of a net, with the bits it
/// was formatted from: a fitted net's x depends on the column alone and its y on the row
/// alone, so the writer formats those once and copies the text wherever a pole carries the
/// same bits (the same bits give the same text), and formats any other value itself.
struct RepeatedTexts {
    bits: Vec<u64>,
    /// `TEXT_STRIDE` bytes per entry, the first `lens[i]` of them the text.
    text: Vec<u8>,
    /// 0 for a value that is not finite (never reused: formatting it reports the pole).
    lens: Vec<u8>,
}

/// Room per reused text: any real is at most 24 bytes.
const TEXT_STRIDE: usize = 32;

impl RepeatedTexts {
    /// The texts of `values` (finite or not).
    fn of(values: impl Iterator<Item = f64>) -> RepeatedTexts {
        let (lower, _) = values.size_hint();
        let mut t = RepeatedTexts {
            bits: Vec::with_capacity(lower),
            text: Vec::with_capacity(lower * TEXT_STRIDE),
            lens: Vec::with_capacity(lower),
        };
        for v in values {
            let base = t.text.len();
            let ok = push_real(&mut t.text, v);
            let len = t.text.len() - base;
            t.text.resize(base + TEXT_STRIDE, b' ');
            t.bits.push(v.to_bits());
            // A text longer than its slot (no shortest f64 text is) was cut by the resize
            // above: it is marked unusable, so that coordinate is formatted anew.
            t.lens.push(if ok && len <= TEXT_STRIDE {
                len as u8
            } else {
                0
            });
        }
        t
    }

    /// Appends the text of entry `i` to `out` if it was formatted from `value`'s bits, and
    /// tells whether it did.
    #[inline(always)]
    fn push_if_same(&self, i: usize, value: f64, out: &mut Vec<u8>) -> bool {
        match (self.bits.get(i), self.lens.get(i)) {
            (Some(&bits), Some(&len)) if bits == value.to_bits() && len != 0 => {
                // Every remembered value has its stride-sized entry; were one missing, the
                // value would simply be formatted again.
                let Some(entry) = self
                    .text
                    .get(i * TEXT_STRIDE..)
                    .and_then(|t| t.first_chunk::<TEXT_STRIDE>())
                else {
                    return false;
                };
                // One fixed-size copy (a few register moves), then cut to the text's length.
                let end = out.len() + usize::from(len);
                out.extend_from_slice(entry);
                out.truncate(end);
                true
            }
            _ => false,
        }
    }
}

/// The reusable texts of a net: the x of row 0 per column and the y of column 0 per row.
struct NetTexts {
    count_u: usize,
    x: RepeatedTexts,
    y: RepeatedTexts,
}

impl NetTexts {
    fn of(s: &NurbsSurface) -> NetTexts {
        let net = s.net();
        let x = if net.count_v() > 0 { net.row(0).x } else { &[] };
        NetTexts {
            count_u: s.count_u(),
            x: RepeatedTexts::of(x.iter().copied()),
            y: RepeatedTexts::of(net.rows().filter(|r| !r.is_empty()).map(|r| r.y.at(0))),
        }
    }

    /// Texts that match nothing (every coordinate is formatted).
    #[cfg(test)]
    fn none(count_u: usize) -> NetTexts {
        NetTexts {
            count_u,
            x: RepeatedTexts::of(std::iter::empty()),
            y: RepeatedTexts::of(std::iter::empty()),
        }
    }
}

/// Formats every coordinate of `poles` (the first being pole `first` of its patch, whose
/// repeated texts are `texts`) into `tokens`; a non-finite coordinate is returned as (pole
/// index, value).
fn format_pole_tokens(
    poles: &[[f64; 3]],
    first: usize,
    texts: &NetTexts,
    tokens: &mut Tokens,
) -> Result<(), (usize, f64)> {
    tokens.text.clear();
    tokens.lens.clear();
    tokens.text.reserve(poles.len() * 3 * TEXT_STRIDE);
    tokens.lens.reserve(poles.len() * 3);
    let nu = texts.count_u.max(1);
    let (mut col, mut row) = (first % nu, first / nu);
    for (k, pole) in poles.iter().enumerate() {
        for (c, &value) in pole.iter().enumerate() {
            let before = tokens.text.len();
            let reused = match c {
                0 => texts.x.push_if_same(col, value, &mut tokens.text),
                1 => texts.y.push_if_same(row, value, &mut tokens.text),
                _ => false,
            };
            if !reused && !push_real(&mut tokens.text, value) {
                return Err((first + k, value));
            }
            tokens.lens.push((tokens.text.len() - before) as u8);
        }
        col += 1;
        if col == nu {
            col = 0;
            row += 1;
        }
    }
    Ok(())
}

/// The IGES texts of every pole coordinate of `s` in file order (x, y, z of each pole, v
/// outer), concatenated without delimiters, formatted on the calling thread as the writer
/// formats them (the text of a column's x and a row's y reused where the bits repeat).
/// Returns the number of coordinates. For measuring and checking the formatter; the writer
/// itself packs the same texts into records.
pub fn format_net_reals(s: &NurbsSurface, out: &mut Vec<u8>) -> Result<usize, IgesError> {
    let texts = NetTexts::of(s);
    let mut tokens = Tokens::default();
    let mut piece = Vec::with_capacity(PIECE_POLES);
    let n = s.net().len();
    for first in (0..n).step_by(PIECE_POLES) {
        piece.clear();
        s.net()
            .extend_poles(first..(first + PIECE_POLES).min(n), &mut piece);
        format_pole_tokens(&piece, first, &texts, &mut tokens).map_err(|(index, value)| {
            IgesError::NonFinite {
                patch: 0,
                what: "pole coordinate",
                index,
                value,
            }
        })?;
        out.extend_from_slice(&tokens.text);
    }
    Ok(n * 3)
}

/// Threads that format reals while the calling thread packs and writes.
fn worker_count() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, 4)
}

/// The pole pieces of a net of `count` poles laid out in chunks of `chunk` poles: each piece
/// at most [`PIECE_POLES`] poles, none crossing a chunk's end, in pole order; with whether
/// it ends its chunk.
fn pole_pieces(count: usize, chunk: usize) -> Vec<(std::ops::Range<usize>, bool)> {
    (0..count)
        .step_by(chunk.max(1))
        .flat_map(|c| {
            let end = (c + chunk.max(1)).min(count);
            (c..end)
                .step_by(PIECE_POLES)
                .map(move |k| (k..(k + PIECE_POLES).min(end), k + PIECE_POLES >= end))
        })
        .collect()
}

/// A piece's tokens, or the first non-finite coordinate in it (pole index, value).
type Formatted = Result<Tokens, (usize, f64)>;

/// Where the pieces' tokens come from, in pole order: formatted on this thread when asked
/// for, or by workers that run ahead.
enum PieceTokens {
    Here {
        buf: Vec<[f64; 3]>,
        tokens: Tokens,
    },
    /// Piece i comes from worker i % n, each at most two pieces ahead; a piece's buffers are
    /// handed back to its worker for the next one (no fresh pages per piece).
    Workers {
        ready: Vec<std::sync::mpsc::Receiver<Formatted>>,
        spent: Vec<std::sync::mpsc::Sender<Tokens>>,
        last: Option<Tokens>,
    },
}

/// Formats `piece` of `net` (its coordinates copied out first) into `tokens`.
fn format_piece(
    net: &PoleNet,
    piece: &std::ops::Range<usize>,
    texts: &NetTexts,
    buf: &mut Vec<[f64; 3]>,
    tokens: &mut Tokens,
) -> Result<(), (usize, f64)> {
    buf.clear();
    net.extend_poles(piece.clone(), buf);
    format_pole_tokens(buf, piece.start, texts, tokens)
}

impl PieceTokens {
    /// Starts formatting `pieces` of `net`: on `workers` threads of `scope` when there are
    /// several workers and pieces, else on demand on the calling thread.
    fn start<'scope, 'env>(
        scope: &'scope std::thread::Scope<'scope, 'env>,
        net: &'env PoleNet,
        pieces: &'env [(std::ops::Range<usize>, bool)],
        texts: &'env NetTexts,
        workers: usize,
    ) -> PieceTokens {
        if workers <= 1 || pieces.len() <= 1 {
            return PieceTokens::Here {
                buf: Vec::with_capacity(PIECE_POLES),
                tokens: Tokens::default(),
            };
        }
        let (mut ready, mut spent) = (Vec::new(), Vec::new());
        for w in 0..workers {
            let (tx, rx) = std::sync::mpsc::sync_channel::<Formatted>(2);
            let (back_tx, back_rx) = std::sync::mpsc::channel::<Tokens>();
            ready.push(rx);
            spent.push(back_tx);
            scope.spawn(move || {
                let mut buf = Vec::with_capacity(PIECE_POLES);
                for (piece, _) in pieces.iter().skip(w).step_by(workers) {
                    let mut tokens = back_rx.try_recv().unwrap_or_default();
                    let r = format_piece(net, piece, texts, &mut buf, &mut tokens).map(|()| tokens);
                    let failed = r.is_err();
                    // A closed channel means the consumer stopped (an error): stop too.
                    if tx.send(r).is_err() || failed {
                        return;
                    }
                }
            });
        }
        PieceTokens::Workers {
            ready,
            spent,
            last: None,
        }
    }

    /// The tokens of piece `i` (asked for in order).
    fn get(
        &mut self,
        i: usize,
        net: &PoleNet,
        pieces: &[(std::ops::Range<usize>, bool)],
        texts: &NetTexts,
        patch: usize,
    ) -> Result<&Tokens, IgesError> {
        let non_finite = |(index, value): (usize, f64)| IgesError::NonFinite {
            patch,
            what: "pole coordinate",
            index,
            value,
        };
        match self {
            PieceTokens::Here { buf, tokens } => {
                let (piece, _) = &pieces[i];
                format_piece(net, piece, texts, buf, tokens).map_err(non_finite)?;
                Ok(tokens)
            }
            PieceTokens::Workers { ready, spent, last } => {
                let n = ready.len();
                // The previous piece's buffers go back to the worker that formatted it.
                if let Some(t) = last.take() {
                    let _ = spent[(i + n - 1) % n].send(t);
                }
                let got = ready[i % n].recv().map_err(|_| {
                    IgesError::Io(io::Error::other("a formatting thread stopped early"))
                })?;
                Ok(last.insert(got.map_err(non_finite)?))
            }
        }
    }
}

/// Streams the P lines of one entity 128 through `p` (whose DE back-pointer the caller has
/// set), handing complete lines to `emit` in blocks of about [`BLOCK_BYTES`], and returns the
/// number of lines. Lines still in `p` when it returns are the caller's to hand on. The
/// layout: header, knots and weights from one record on; the poles in one chunk, or
/// [`POLE_CHUNKS`] chunks for large nets, each starting a fresh record; the parameter range on
/// a fresh record.
fn stream_entity_128(
    s: &NurbsSurface,
    patch: usize,
    workers: usize,
    p: &mut FieldPacker,
    emit: &mut dyn FnMut(&[u8]) -> Result<(), IgesError>,
) -> Result<usize, IgesError> {
    let (nu, nv) = (s.count_u(), s.count_v());
    let net = s.net();
    let count = net.len();
    let chunk = if count >= PARALLEL_POLES {
        count.div_ceil(POLE_CHUNKS)
    } else {
        count.max(1)
    };
    let texts = NetTexts::of(s);
    let pieces = pole_pieces(count, chunk);
    // The poles' reals are formatted from the start, beside the header, knots and weights.
    std::thread::scope(|scope| {
        let mut poles = PieceTokens::start(scope, net, &pieces, &texts, workers);
        let first_line = p.complete_records();
        let mut hand_on = |p: &mut FieldPacker| -> Result<(), IgesError> {
            if p.bytes() >= BLOCK_BYTES {
                p.drain_records(&mut *emit)?;
            }
            Ok(())
        };
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
            real(p, k, "u knot", i, b',')?;
        }
        for (i, &k) in s.knots_v().iter().enumerate() {
            real(p, k, "v knot", i, b',')?;
        }
        let mut weights = nu * nv;
        while weights > 0 {
            let n = weights.min(65_536);
            p.push_repeated(b"1.", b',', n);
            weights -= n;
            hand_on(p)?;
        }
        p.pad_last();
        for (i, (_, ends_chunk)) in pieces.iter().enumerate() {
            let t = poles.get(i, net, &pieces, &texts, patch)?;
            p.push_tokens(&t.text, &t.lens, b',');
            hand_on(p)?;
            if *ends_chunk {
                p.pad_last();
            }
        }
        let (ku, kv) = (s.knots_u(), s.knots_v());
        let dom = [ku[s.degree_u()], ku[nu], kv[s.degree_v()], kv[nv]];
        for (i, &d) in dom.iter().enumerate() {
            real(p, d, "parameter range", i, if i == 3 { b';' } else { b',' })?;
        }
        p.pad_last();
        hand_on(p)?;
        Ok(p.complete_records() - first_line)
    })
}

/// Splits `surface` along v until each patch's P lines are bounded by `max_lines` (from
/// token counts, [`parameter_lines_bound`]); appends (patch, its bound) in v order. A surface
/// that fits is borrowed, not copied.
fn split_to_fit<'a>(
    surface: Cow<'a, NurbsSurface>,
    max_lines: usize,
    out: &mut Vec<(Cow<'a, NurbsSurface>, usize)>,
) -> Result<(), IgesError> {
    let lines = parameter_lines_bound(&surface);
    if lines <= max_lines {
        out.push((surface, lines));
        return Ok(());
    }
    match split_v_middle(&surface) {
        Some((lower, upper)) => {
            drop(surface);
            split_to_fit(Cow::Owned(lower), max_lines, out)?;
            split_to_fit(Cow::Owned(upper), max_lines, out)
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

/// An upper bound on the P lines one entity 128 of `s` takes, from token counts alone (no
/// formatting). Every token (with its delimiter) is at most 25 bytes, so each 64-column record
/// of a segment but the last holds at least two; the weights (`1.,`) hold 21 a record; each
/// segment may end with one partial record. Exceeds the real count by at most about 60 %
/// (worst-case 17-digit tokens; about 25 % for a fit's poles).
pub fn parameter_lines_bound(s: &NurbsSurface) -> usize {
    lines_bound(
        s.count_u(),
        s.count_v(),
        s.knots_u().len(),
        s.knots_v().len(),
    )
}

/// [`parameter_lines_bound`] from the pole counts and knot vector lengths.
fn lines_bound(count_u: usize, count_v: usize, knots_u: usize, knots_v: usize) -> usize {
    let poles = count_u.saturating_mul(count_v);
    let per_record = 64 / MAX_REAL_TOKEN;
    let head_tokens = 10 + knots_u + knots_v;
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

/// How a surface is laid out in IGES files, planned from the knots and token counts alone:
/// each patch is named by the halves ([`split_v_middle`], recursively) that lead to it from the
/// surface, and [`PartPlan::part`] builds one file's patches only when it is written, so a
/// surface split into several files never has all its patches in memory at once.
#[derive(Debug, Clone)]
pub struct PartPlan<'a> {
    surface: &'a NurbsSurface,
    /// Per file, per patch: the halves taken from the surface, outermost split first.
    files: Vec<Vec<Vec<Side>>>,
}

impl<'a> PartPlan<'a> {
    /// Number of files.
    pub fn len(&self) -> usize {
        self.files.len()
    }

    /// Whether there are no files (never for a plan [`plan_layout`] returns).
    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// Patches in file `k` (0-based).
    pub fn patches_in(&self, k: usize) -> usize {
        self.files.get(k).map_or(0, Vec::len)
    }

    /// The patches of file `k` (0-based), built now: the same bits as splitting the surface
    /// recursively ([`split_v_middle`]) and keeping every patch. The whole surface is
    /// borrowed when it fits one entity.
    pub fn part(&self, k: usize) -> Result<Cow<'a, [NurbsSurface]>, IgesError> {
        let Some(paths) = self.files.get(k) else {
            return Err(IgesError::NoSurfaces);
        };
        if let [path] = paths.as_slice() {
            if path.is_empty() {
                return Ok(Cow::Borrowed(std::slice::from_ref(self.surface)));
            }
        }
        let mut patches = Vec::with_capacity(paths.len());
        for path in paths {
            let mut current = Cow::Borrowed(self.surface);
            for &side in path {
                let half = split_v_middle_side(&current, side).ok_or_else(|| {
                    IgesError::EntityTooLarge {
                        lines: parameter_lines_bound(&current),
                        max_lines: MAX_SECTION_LINES,
                        count_u: current.count_u(),
                        count_v: current.count_v(),
                    }
                })?;
                current = Cow::Owned(half);
            }
            patches.push(current.into_owned());
        }
        Ok(Cow::Owned(patches))
    }
}

/// Appends (path, bound) of each patch of a surface of shape `shape` split until each bound
/// is at most `max_lines`, in v order: [`split_to_fit`] on the knots alone.
fn layout_to_fit(
    s: &NurbsSurface,
    shape: PatchShape,
    path: &mut Vec<Side>,
    max_lines: usize,
    out: &mut Vec<(Vec<Side>, usize)>,
) -> Result<(), IgesError> {
    let lines = lines_bound(
        s.count_u(),
        shape.count_v,
        s.knots_u().len(),
        shape.knots_v.len(),
    );
    if lines <= max_lines {
        out.push((path.clone(), lines));
        return Ok(());
    }
    match split_middle_shapes(s.degree_v(), &shape) {
        Some((_, lower, upper)) => {
            for (side, half) in [(Side::Lower, lower), (Side::Upper, upper)] {
                path.push(side);
                layout_to_fit(s, half, path, max_lines, out)?;
                path.pop();
            }
            Ok(())
        }
        None => Err(IgesError::EntityTooLarge {
            lines,
            max_lines,
            count_u: s.count_u(),
            count_v: shape.count_v,
        }),
    }
}

/// Plans how `surface` is written: splits it along v into exact patches (adjacent patches
/// share their boundary pole row, so their union is exactly the surface) whose P lines are
/// bounded ([`parameter_lines_bound`]) by `opts.max_parameter_lines_per_entity` and
/// `opts.max_parameter_lines_per_file`, then groups consecutive patches greedily into files
/// whose bounds add up to at most `opts.max_parameter_lines_per_file` (never more than
/// [`MAX_SECTION_LINES`]). Nothing is formatted and no patch is built: the bounds come from
/// token counts and the patches' shapes from their knots.
pub fn plan_layout<'a>(
    surface: &'a NurbsSurface,
    opts: &IgesOptions,
) -> Result<PartPlan<'a>, IgesError> {
    let file_cap = opts
        .max_parameter_lines_per_file
        .clamp(1, MAX_SECTION_LINES);
    let entity_cap = opts.max_parameter_lines_per_entity.clamp(1, file_cap);
    let mut patches = Vec::new();
    let shape = PatchShape {
        knots_v: surface.knots_v().to_vec(),
        count_v: surface.count_v(),
    };
    layout_to_fit(surface, shape, &mut Vec::new(), entity_cap, &mut patches)?;
    let mut files = Vec::new();
    let mut current: Vec<Vec<Side>> = Vec::new();
    let mut current_lines = 0usize;
    for (path, lines) in patches {
        // Two DE lines per entity; the DE section shares the same 7-digit cap.
        let fits =
            current_lines + lines <= file_cap && 2 * (current.len() + 1) <= MAX_SECTION_LINES;
        if !current.is_empty() && !fits {
            files.push(std::mem::take(&mut current));
            current_lines = 0;
        }
        current_lines += lines;
        current.push(path);
    }
    if !current.is_empty() {
        files.push(current);
    }
    Ok(PartPlan { surface, files })
}

/// [`plan_layout`] with every file's patches built: one group per file, in v order; a surface
/// that fits one file is borrowed whole.
pub fn plan_parts<'a>(
    surface: &'a NurbsSurface,
    opts: &IgesOptions,
) -> Result<Vec<Cow<'a, [NurbsSurface]>>, IgesError> {
    let plan = plan_layout(surface, opts)?;
    (0..plan.len()).map(|k| plan.part(k)).collect()
}

/// [`plan_parts`] with every group owned.
pub fn plan_files(
    surface: &NurbsSurface,
    opts: &IgesOptions,
) -> Result<Vec<Vec<NurbsSurface>>, IgesError> {
    Ok(plan_parts(surface, opts)?
        .into_iter()
        .map(Cow::into_owned)
        .collect())
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

/// The largest |coordinate| of the poles of `net` (0 for none): the maximum is exact
/// whatever order it is taken in, so it is taken per coordinate as the net holds them (a
/// row's shared x or y once, not once per pole), each slice's from its lowest and highest.
fn max_abs_coordinate(net: &PoleNet) -> f64 {
    // Absolute values are never −0.0, so which zero `min_max` keeps does not show.
    fn max_abs(v: &[f64]) -> f64 {
        let (lo, hi) = min_max(v);
        if lo > hi {
            return 0.0;
        }
        lo.abs().max(hi.abs())
    }
    let mut m = 0.0f64;
    let mut column_x_seen = false;
    for row in net.rows() {
        if std::ptr::eq(row.x.as_ptr(), net.column_x().as_ptr()) {
            if !column_x_seen {
                m = m.max(max_abs(row.x));
                column_x_seen = true;
            }
        } else {
            m = m.max(max_abs(row.x));
        }
        m = m.max(match row.y {
            RowY::One(y) => y.abs(),
            RowY::Each(ys) => max_abs(ys),
        });
        m = m.max(max_abs(row.z));
    }
    m
}

/// The Start and Global sections as records; returns their line counts.
fn start_and_global(
    out: &mut Vec<u8>,
    surfaces: &[NurbsSurface],
    opts: &IgesOptions,
) -> (usize, usize) {
    let max_coord = surfaces
        .iter()
        .map(|s| max_abs_coordinate(s.net()))
        .fold(0.0f64, f64::max);
    let buf = out;
    // Start section.
    let start = wrap72(&opts.start_lines);
    for (i, line) in start.iter().enumerate() {
        record(buf, line.as_bytes(), b'S', i + 1);
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
        record(buf, chunk, b'G', i + 1);
    }

    (start.len(), g_lines)
}

/// The Directory Entry lines of entities 128 with the given P line counts.
fn directory(out: &mut Vec<u8>, counts: &[usize]) {
    let mut pd_pointer = 1usize;
    let mut field = Vec::with_capacity(80);
    for (k, &n) in counts.iter().enumerate() {
        field.clear();
        for v in [128, pd_pointer as i64, 0, 0, 0, 0, 0, 0] {
            push_right(&mut field, v, 8);
        }
        field.extend_from_slice(b"00000000");
        record(out, &field, b'D', 2 * k + 1);
        field.clear();
        for v in [128, 0, 0, n as i64, 0] {
            push_right(&mut field, v, 8);
        }
        field.extend_from_slice(b"                   PATCH");
        push_right(&mut field, (k + 1) as i64, 8);
        record(out, &field, b'D', 2 * k + 2);
        pd_pointer += n;
    }
}

/// The Terminate line.
fn terminate(out: &mut Vec<u8>, counts: [usize; 4]) {
    let mut t = Vec::with_capacity(72);
    for (letter, count) in [b'S', b'G', b'D', b'P'].into_iter().zip(counts) {
        t.push(letter);
        push_right(&mut t, count as i64, 7);
    }
    record(out, &t, b'T', 1);
}

/// Splits each surface into the patches one file holds (bounded by
/// `opts.max_parameter_lines_per_entity`), borrowing those that fit.
fn file_patches<'a>(
    surfaces: &'a [NurbsSurface],
    opts: &IgesOptions,
) -> Result<Vec<Cow<'a, NurbsSurface>>, IgesError> {
    if surfaces.is_empty() {
        return Err(IgesError::NoSurfaces);
    }
    let max_lines = opts
        .max_parameter_lines_per_entity
        .clamp(1, MAX_SECTION_LINES);
    let mut patches = Vec::new();
    for s in surfaces {
        split_to_fit(Cow::Borrowed(s), max_lines, &mut patches)?;
    }
    let d_lines = 2 * patches.len();
    if d_lines > MAX_SECTION_LINES {
        return Err(IgesError::SectionTooLong {
            section: 'D',
            lines: d_lines,
            max_lines: MAX_SECTION_LINES,
        });
    }
    Ok(patches.into_iter().map(|(p, _)| p).collect())
}

/// Writes `surfaces` as an IGES 5.3 file into a seekable writer (a file), streaming the
/// Parameter Data as it is formatted: one independent entity 128 per surface, or per exact
/// patch when a surface's P lines may exceed `opts.max_parameter_lines_per_entity`. The
/// Directory Entry section is rewritten in place once the line counts are known; the writer is
/// left at the end of the file. A P section longer than `opts.max_parameter_lines_per_file` is
/// an error after the fact (the caller discards what was written, as it would after a full
/// disk).
pub fn write_iges_seekable<W: Write + Seek>(
    mut w: W,
    surfaces: &[NurbsSurface],
    opts: &IgesOptions,
) -> Result<IgesStats, IgesError> {
    let patches = file_patches(surfaces, opts)?;
    let file_cap = opts
        .max_parameter_lines_per_file
        .clamp(1, MAX_SECTION_LINES);
    let origin = w.stream_position()?;
    let mut buf = Vec::with_capacity(2 * BLOCK_BYTES + 4096);
    let (s_lines, g_lines) = start_and_global(&mut buf, surfaces, opts);
    let d_offset = buf.len() as u64;
    let d_lines = 2 * patches.len();
    directory(&mut buf, &vec![0; patches.len()]);
    w.write_all(&buf)?;
    buf.clear();
    let workers = worker_count();
    // Room for a block and for what one step adds past it before it is handed on (a piece of
    // poles, at most about 0.5 MB of lines, or a batch of weights, 0.25 MB): for the nets of
    // a scan the packer never regrows, which would copy a block into pages touched for the
    // first time.
    let mut lines = FieldPacker::parameter_lines(2 * BLOCK_BYTES);
    let mut counts = Vec::with_capacity(patches.len());
    for (k, patch) in patches.iter().enumerate() {
        lines.set_back_pointer(2 * k + 1);
        let n = stream_entity_128(patch, k, workers, &mut lines, &mut |block| {
            w.write_all(block)?;
            Ok(())
        })?;
        counts.push(n);
    }
    lines.drain_records(|block| w.write_all(block))?;
    let p_lines = lines.complete_records();
    if p_lines > file_cap {
        return Err(IgesError::SectionTooLong {
            section: 'P',
            lines: p_lines,
            max_lines: file_cap,
        });
    }
    terminate(&mut buf, [s_lines, g_lines, d_lines, p_lines]);
    w.write_all(&buf)?;
    buf.clear();
    directory(&mut buf, &counts);
    w.seek(SeekFrom::Start(origin + d_offset))?;
    w.write_all(&buf)?;
    w.seek(SeekFrom::End(0))?;
    w.flush()?;
    Ok(IgesStats {
        patches: patches.len(),
        start_lines: s_lines,
        global_lines: g_lines,
        directory_lines: d_lines,
        parameter_lines: p_lines,
        bytes: 81 * (s_lines + g_lines + d_lines + p_lines + 1) as u64,
    })
}

/// Writes `surfaces` as an IGES 5.3 file into any writer (see [`write_iges_seekable`], which
/// a file should use: this one assembles the whole file in memory first, and writes nothing
/// when it fails).
pub fn write_iges<W: Write>(
    mut w: W,
    surfaces: &[NurbsSurface],
    opts: &IgesOptions,
) -> Result<IgesStats, IgesError> {
    let mut file = io::Cursor::new(Vec::new());
    let stats = write_iges_seekable(&mut file, surfaces, opts)?;
    w.write_all(file.get_ref())?;
    w.flush()?;
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::iges::format::SequenceField;
    use crate::iges::reference::{entity_128_params, ParamText};

    /// Bytes of one P line: 64 data columns, then the DE back-pointer, `P`, the sequence
    /// number and the newline.
    const LINE_BYTES: usize = 64 + crate::iges::format::P_LINE_TAIL;

    /// Turns 64-column parameter records into P lines (the writer's framing before it packed
    /// into lines directly): each is assembled in a fixed 81-byte template with the sequence
    /// number counted up in place.
    struct ParameterLines {
        line: [u8; 81],
        seq: SequenceField,
        count: usize,
    }

    impl ParameterLines {
        fn new() -> ParameterLines {
            let mut line = [b' '; 81];
            line[72] = b'P';
            line[80] = b'\n';
            ParameterLines {
                line,
                seq: SequenceField::new(),
                count: 0,
            }
        }

        /// Sets the DE back-pointer of the lines that follow.
        fn entity(&mut self, de: usize) {
            let mut back = Vec::with_capacity(8);
            push_right(&mut back, de as i64, 8);
            self.line[64..72].copy_from_slice(&back);
        }

        /// Appends the P lines of `records` (whole 64-column records) to `out`. Past the 7-digit
        /// field the sequence number wraps; the writer refuses such a file before it is used.
        fn push(&mut self, records: &[u8], out: &mut Vec<u8>) {
            for chunk in records.chunks_exact(64) {
                self.line[..64].copy_from_slice(chunk);
                self.seq.increment();
                self.line[73..80].copy_from_slice(&self.seq.digits);
                out.extend_from_slice(&self.line);
            }
            self.count += records.len() / 64;
        }
    }

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

    /// A degree-5 surface with a fit's kind of reals (17 digits, µm heights in mm, zeros).
    fn fit_like(nu: usize, nv: usize) -> NurbsSurface {
        let d = 5;
        let knots = |n: usize| {
            let mut k = vec![0.0; d + 1];
            k.extend((1..n - d).map(|j| j as f64 / (n - d) as f64));
            k.extend(vec![1.0; d + 1]);
            k
        };
        let mut poles = Vec::with_capacity(nu * nv);
        for j in 0..nv {
            for i in 0..nu {
                let (x, y) = (
                    i as f64 * 0.000_500_000_000_3,
                    j as f64 * 0.010_000_000_000_7,
                );
                let z = 1e-3 * (0.8 * (x * 157.0).sin() + 0.3 * (x * 911.0 + y * 40.0).cos());
                poles.push([x, y, z]);
            }
        }
        NurbsSurface::try_new(d, d, knots(nu), knots(nv), nu, nv, poles).unwrap()
    }

    /// The file as the writer made it before it streamed: every entity formatted into memory
    /// first ([`entity_128_params`], kept verbatim), then framed.
    fn reference_file(patches: &[NurbsSurface], opts: &IgesOptions) -> Vec<u8> {
        let texts: Vec<ParamText> = patches
            .iter()
            .enumerate()
            .map(|(k, p)| entity_128_params(p, k).unwrap())
            .collect();
        let counts: Vec<usize> = texts.iter().map(ParamText::lines).collect();
        let mut out = Vec::new();
        let (s, g) = start_and_global(&mut out, patches, opts);
        directory(&mut out, &counts);
        let mut lines = ParameterLines::new();
        for (k, t) in texts.iter().enumerate() {
            lines.entity(2 * k + 1);
            for r in t.records() {
                lines.push(r, &mut out);
            }
        }
        terminate(&mut out, [s, g, 2 * patches.len(), lines.count]);
        out
    }

    #[test]
    fn streamed_files_equal_the_formatted_in_memory_ones_byte_for_byte() {
        let opts = IgesOptions {
            start_lines: vec!["reference".into()],
            ..IgesOptions::default()
        };
        // One small entity, one above the chunking threshold (four pole chunks, several
        // pieces per worker), several patches in one file, worst-case tokens.
        let big = fit_like(PARALLEL_POLES / 16 + 7, 17);
        let cases: Vec<Vec<NurbsSurface>> = vec![
            vec![fit_like(40, 7)],
            vec![big.clone()],
            vec![fit_like(30, 9), fit_like(12, 6), longest_tokens(9, 5)],
            vec![longest_tokens(PARALLEL_POLES / 8 + 1, 8)],
            vec![
                fit_like_with_breaks(30, 9),
                fit_like_with_breaks(PARALLEL_POLES / 8 + 3, 9),
            ],
        ];
        for patches in &cases {
            let want = reference_file(patches, &opts);
            let mut got = Vec::new();
            let stats = write_iges(&mut got, patches, &opts).unwrap();
            assert!(
                got == want,
                "{} patches: streamed file differs",
                patches.len()
            );
            assert_eq!(stats.bytes, want.len() as u64);
            // One formatting thread or several: the same lines, each the reference's record
            // with its DE back-pointer and sequence number.
            let expected: Vec<u8> = patches
                .iter()
                .enumerate()
                .flat_map(|(k, p)| {
                    entity_128_params(p, k)
                        .unwrap()
                        .records()
                        .flatten()
                        .copied()
                        .collect::<Vec<u8>>()
                })
                .collect();
            for workers in [1, 2, 3] {
                let mut packer = FieldPacker::parameter_lines(0);
                let mut lines = Vec::new();
                let mut des = Vec::new();
                for (k, p) in patches.iter().enumerate() {
                    packer.set_back_pointer(2 * k + 1);
                    let n = stream_entity_128(p, k, workers, &mut packer, &mut |block| {
                        lines.extend_from_slice(block);
                        Ok(())
                    })
                    .unwrap();
                    packer.drain_records(|block| lines.extend_from_slice(block));
                    assert_eq!(n, entity_128_params(p, k).unwrap().lines());
                    des.extend(std::iter::repeat_n(2 * k + 1, n));
                }
                assert_eq!(lines.len(), LINE_BYTES * des.len());
                let data: Vec<u8> = lines
                    .chunks_exact(LINE_BYTES)
                    .flat_map(|l| l[..64].to_vec())
                    .collect();
                assert!(data == expected, "{workers} workers");
                for (i, (line, de)) in lines.chunks_exact(LINE_BYTES).zip(&des).enumerate() {
                    let tail = format!("{de:>8}P{:>7}\n", i + 1);
                    assert_eq!(&line[64..], tail.as_bytes(), "line {}", i + 1);
                }
            }
            let mut single = io::Cursor::new(Vec::new());
            write_iges_seekable(&mut single, patches, &opts).unwrap();
            assert!(single.into_inner() == want);
        }
    }

    /// [`fit_like`] with some coordinates that break the per-column x and per-row y pattern
    /// (a perturbed x in one pole, a row whose y varies, `-0.` beside `0.`, a tiny and a
    /// huge value), so a writer that reuses the text of repeated values must notice each.
    fn fit_like_with_breaks(nu: usize, nv: usize) -> NurbsSurface {
        let s = fit_like(nu, nv);
        let mut poles = s.net().to_vec();
        poles[nu + 3][0] = f64::from_bits(poles[nu + 3][0].to_bits() + 1);
        for (i, p) in poles[2 * nu..3 * nu].iter_mut().enumerate() {
            p[1] += i as f64 * 1e-9;
        }
        poles[3 * nu][0] = -0.0;
        poles[3 * nu + 1][1] = -0.0;
        poles[4 * nu + 2][0] = 1.5e-300;
        poles[4 * nu + 5][1] = -2.5e300;
        NurbsSurface::try_new(
            s.degree_u(),
            s.degree_v(),
            s.knots_u().to_vec(),
            s.knots_v().to_vec(),
            nu,
            nv,
            poles,
        )
        .unwrap()
    }

    /// SHA-256 of the file written for `patches`, in hex.
    fn file_sha256(patches: &[NurbsSurface]) -> String {
        use sha2::Digest;
        let opts = IgesOptions {
            start_lines: vec!["golden".into()],
            ..IgesOptions::default()
        };
        let mut out = Vec::new();
        write_iges(&mut out, patches, &opts).unwrap();
        sha2::Sha256::digest(&out)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    #[test]
    fn files_keep_the_bytes_the_writer_gave_before_it_reused_repeated_texts() {
        // Digests of files written by the writer that formatted every coordinate, before it
        // reused the text of a column's x and a row's y: one small entity, one past the
        // chunking threshold, and nets that break the pattern.
        let cases: [(Vec<NurbsSurface>, &str); 3] = [
            (
                vec![fit_like(40, 7)],
                "8d708d5cabf7b9487394f4a7e556be710f562326ab1378bd0351c9ea84ffa8d2",
            ),
            (
                vec![fit_like(PARALLEL_POLES / 16 + 7, 17)],
                "227a174bb9dffebdce5cb32c050eafb3c10f7a96715bd7564dda02edf4e6e079",
            ),
            (
                vec![
                    fit_like_with_breaks(30, 9),
                    fit_like_with_breaks(PARALLEL_POLES / 8 + 3, 9),
                ],
                "c9e58a039541f9b4b64d312afb3fdcee174af2dc57a109c223505169995e0c2d",
            ),
        ];
        let got: Vec<String> = cases.iter().map(|(p, _)| file_sha256(p)).collect();
        for (k, (_, want)) in cases.iter().enumerate() {
            assert_eq!(&got[k], want, "case {k}");
        }
    }

    #[test]
    fn net_reals_are_the_texts_of_each_coordinate_formatted_alone() {
        for s in [
            fit_like_with_breaks(PARALLEL_POLES / 8 + 3, 9),
            longest_tokens(9, 5),
        ] {
            let mut want = Vec::new();
            for c in s.poles().flatten() {
                assert!(push_real(&mut want, c));
            }
            let mut got = Vec::new();
            assert_eq!(format_net_reals(&s, &mut got).unwrap(), s.poles().len() * 3);
            assert!(got == want);
        }
    }

    #[test]
    fn a_non_finite_coordinate_is_named_by_its_pole() {
        // A surface refuses non-finite poles (try_new), so this guards the formatter alone:
        // the pole's index within its patch and the value come back.
        let mut poles = vec![[0.25, 1.0, -3e-4]; 10];
        poles[7][1] = f64::INFINITY;
        let mut t = Tokens::default();
        assert_eq!(
            format_pole_tokens(&poles[2..], 100, &NetTexts::none(5), &mut t),
            Err((105, f64::INFINITY))
        );
        assert_eq!(
            format_pole_tokens(&poles[..7], 0, &NetTexts::none(5), &mut t),
            Ok(())
        );
        assert_eq!(t.lens.len(), 21);
        assert_eq!(&t.text[..t.lens[0] as usize], b"0.25");
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
        // Small nets (one pole chunk) and one past the chunking threshold (four chunks).
        for (nu, nv) in [(4, 4), (37, 5), (PARALLEL_POLES / 8 + 1, 8)] {
            let s = longest_tokens(nu, nv);
            let lines = entity_128_params(&s, 0).unwrap().lines();
            let bound = parameter_lines_bound(&s);
            assert!(bound >= lines, "{nu}x{nv}: bound {bound} < {lines} lines");
            // Tight enough to be useful: within 1.6x for these worst-case tokens.
            assert!(
                bound * 10 <= lines * 16,
                "{nu}x{nv}: bound {bound} vs {lines}"
            );
        }
    }

    #[test]
    fn plans_come_from_the_bound_and_every_part_fits() {
        let s = longest_tokens(40, 16);
        let bound = parameter_lines_bound(&s);
        let opts = |cap: usize| IgesOptions {
            max_parameter_lines_per_entity: cap,
            ..IgesOptions::default()
        };
        // At the bound the surface stays whole (and borrowed); below it, it is split, and
        // each patch's real line count is within the cap.
        let plan = plan_parts(&s, &opts(bound)).unwrap();
        assert!(matches!(&plan[..], [Cow::Borrowed(g)] if g.len() == 1 && g[0] == s));
        let plan = plan_files(&s, &opts(bound - 1)).unwrap();
        let patches: Vec<&NurbsSurface> = plan.iter().flatten().collect();
        assert!(patches.len() >= 2);
        for p in patches {
            assert!(entity_128_params(p, 0).unwrap().lines() < bound);
        }
    }

    #[test]
    fn packed_p_lines_are_the_bare_records_in_their_lines() {
        // Random streams of every kind of push, including tokens that just fit or just miss
        // a record, Hollerith strings longer than a record, runs of repeated tokens that
        // start mid-record and span many records, and records ended early; packed straight
        // into lines, and packed into 64-column records then framed as the writer did before.
        let mut s: u64 = 0x853C_49E6_748F_EA9B;
        let mut next = move |n: u64| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s % n
        };
        for case in 0..300 {
            let mut packer = FieldPacker::parameter_lines(0);
            let mut records = FieldPacker::new(64);
            let mut framed = Vec::new();
            let mut frame = ParameterLines::new();
            let mut lines = Vec::new();
            let mut de = 1;
            packer.set_back_pointer(de);
            frame.entity(de);
            for _ in 0..next(60) {
                match next(7) {
                    0 => {
                        let len = 1 + next(63) as usize;
                        let token: Vec<u8> = (0..len).map(|i| b'0' + (i % 10) as u8).collect();
                        packer.push(&token, b',');
                        records.push(&token, b',');
                    }
                    1 => {
                        let len = 64 + next(100) as usize;
                        let token: Vec<u8> = (0..len).map(|i| b'A' + (i % 26) as u8).collect();
                        packer.push(&token, b';');
                        records.push(&token, b';');
                    }
                    2 => {
                        let v = f64::from_bits(next(u64::MAX));
                        let v = if v.is_finite() { v } else { 0.5 };
                        assert!(packer.push_real(v, b','));
                        assert!(records.push_real(v, b','));
                    }
                    3 => {
                        let mut text = Vec::new();
                        let mut lens = Vec::new();
                        for _ in 0..next(40) {
                            let len = 1 + next(24) as usize;
                            text.extend((0..len).map(|i| b'a' + (i % 26) as u8));
                            lens.push(len as u8);
                        }
                        packer.push_tokens(&text, &lens, b',');
                        records.push_tokens(&text, &lens, b',');
                    }
                    4 => {
                        let token: &[u8] =
                            [&b"1."[..], b"12345", b"x", &[b'7'; 63]][next(4) as usize];
                        let count = next(200) as usize;
                        packer.push_repeated(token, b',', count);
                        for _ in 0..count {
                            records.push(token, b',');
                        }
                    }
                    5 => {
                        packer.pad_last();
                        records.pad_last();
                    }
                    _ => {
                        // A new entity: the lines so far keep their back-pointer.
                        packer.pad_last();
                        records.pad_last();
                        packer.drain_records(|b| lines.extend_from_slice(b));
                        records.drain_records(|r| frame.push(r, &mut framed));
                        de += 2;
                        packer.set_back_pointer(de);
                        frame.entity(de);
                    }
                }
            }
            packer.pad_last();
            packer.drain_records(|b| lines.extend_from_slice(b));
            frame.push(&records.finish(), &mut framed);
            assert_eq!(packer.complete_records(), frame.count, "case {case}");
            assert!(lines == framed, "case {case}");
        }
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
