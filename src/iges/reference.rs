//! The Parameter Data formatter as it was before the writer streamed: every entity formatted
//! into memory (the poles of a large net in four chunks on threads), then framed. Kept for the
//! tests only, which hold the streaming writer to these bytes.
//!
//! Layer 1 (pure logic), test-only.

use super::format::{push_uint, FieldPacker};
use super::IgesError;
use crate::nurbs::NurbsSurface;
use std::io;

/// Nets with at least this many poles are formatted in parallel chunks.
const PARALLEL_POLES: usize = 65_536;
/// Number of chunks a large net is formatted in (fixed, so output is reproducible).
const POLE_CHUNKS: usize = 4;

/// The parameter data (columns 1–64 of each P line) of one entity, as consecutive segments
/// of whole 64-column records (kept apart rather than copied into one buffer).
pub(crate) struct ParamText {
    segments: Vec<Vec<u8>>,
}

impl ParamText {
    /// Number of P lines.
    pub(crate) fn lines(&self) -> usize {
        self.segments.iter().map(|s| s.len() / 64).sum()
    }

    /// The 64-column records in order.
    pub(crate) fn records(&self) -> impl Iterator<Item = &[u8]> {
        self.segments.iter().flat_map(|s| s.chunks_exact(64))
    }
}

/// Formats the parameter data (columns 1–64 of each P line) of one entity 128.
pub(crate) fn entity_128_params(s: &NurbsSurface, patch: usize) -> Result<ParamText, IgesError> {
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
    let poles = s.net().to_vec();
    let poles = poles.as_slice();
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
