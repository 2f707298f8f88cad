//! Low-level IGES text: reals in shortest round-trip form with `.` and `E`, Hollerith
//! strings, right-justified integers, and the packing of free-format parameters into
//! fixed-width records that break only after a delimiter.
//!
//! Layer 1 (pure logic): no dependencies inside the crate; writes into byte buffers.

/// Room reserved for a height-band real (`-d.` + 16 digits + `E-z` is 22 bytes).
const HEIGHT_TEXT_MAX: usize = 32;

/// Appends `value` to `out` as an IGES real: the shortest decimal that reads back to the same
/// f64, always with a `.`, with an upper-case `E` exponent when that is shorter than the plain
/// form (`1.`, `0.`, `-0.25`, `1.2345E-4`, `1.E-7`). Returns `false` (and appends nothing) for
/// NaN or infinity.
pub fn push_real(out: &mut Vec<u8>, value: f64) -> bool {
    if !value.is_finite() {
        return false;
    }
    let mut buf = zmij::Buffer::new();
    let text = buf.format_finite(value).as_bytes();
    // Fastest path, decided by magnitude alone: for 1e-3 <= |v| < 1e15 the formatter writes
    // the plain decimal (`12.5`, `-0.0012345`: at most two zeros after the point, which is
    // never longer than the exponent form), with a trailing `.0` only for integers, which
    // the general path below shortens (`100.`, `1.E3`).
    let magnitude = value.abs();
    if (1e-3..1e15).contains(&magnitude) && text.last() != Some(&b'0') {
        push_short(out, text);
        return true;
    }
    // Second fast path, the magnitude of most fitted heights in mm: for 1e-5 <= |v| < 1e-3
    // the formatter writes `0.000ddd` or `0.0000ddd`, and the exponent form `d.ddE-4` is
    // always shorter.
    if (1e-5..1e-3).contains(&magnitude) {
        let negative = usize::from(value.is_sign_negative());
        let body = &text[negative..];
        // Zeros after the point: 3 from 1e-4 up, else 4. The shortest digits read back to the
        // value, so they lie on the same side of 0.0001 as it does; the count is taken from the
        // magnitude (no loop over the text to mispredict) and checked against the text.
        let zeros = 3 + usize::from(magnitude < 1e-4);
        // `0.000` then, for 4 zeros, one more `0`; then a non-zero digit and at most 16 more
        // (fixed-size comparisons: a slice comparison of varying length is a `memcmp` call).
        let head_ok = body
            .first_chunk::<6>()
            .is_some_and(|h| h[..5] == *b"0.000" && (h[5] == b'0') == (zeros == 4));
        let Some((&lead, rest)) = body
            .get(2 + zeros..)
            .filter(|_| head_ok)
            .and_then(|sig| sig.split_first())
            .filter(|(&d, rest)| d != b'0' && rest.len() <= 16)
        else {
            reformat(out, text);
            return true;
        };
        // The text is `[-]d.dddE-z`, written straight into `out`: at most 17 significant
        // digits, so 1 + 1 + 1 + 16 + 3 = 22 bytes.
        out.reserve(HEIGHT_TEXT_MAX);
        let len = out.len();
        let n = negative + 2 + rest.len() + 3;
        // SAFETY: `reserve` leaves HEIGHT_TEXT_MAX (32) writable bytes from `len`; the writes
        // below cover [len, len + n) with n <= 22 (`rest` is at most 16 bytes, checked above,
        // and `copy_at_most_16` writes exactly its length), all before `set_len`.
        unsafe {
            let dst = out.as_mut_ptr().add(len);
            *dst = b'-';
            *dst.add(negative) = lead;
            *dst.add(negative + 1) = b'.';
            copy_at_most_16(rest, dst.add(negative + 2));
            let e = dst.add(negative + 2 + rest.len());
            *e = b'E';
            *e.add(1) = b'-';
            *e.add(2) = b'0' + (zeros + 1) as u8;
            out.set_len(len + n);
        }
        return true;
    }
    reformat(out, text);
    true
}

/// Appends the IGES form of `text`, a finite value in any shape a shortest-digits formatter
/// produces (`-12.5`, `0.00085`, `1.0`, `1e-7`, `1.5e+20`).
fn reformat(out: &mut Vec<u8>, text: &[u8]) {
    // Fast paths for the plain decimals the formatter gives for everyday magnitudes.
    let (sign, body) = match text.split_first() {
        Some((b'-', rest)) => (&b"-"[..], rest),
        _ => (&b""[..], text),
    };
    if body.contains(&b'.')
        && body.last().is_some_and(|&c| c != b'0' && c != b'.')
        && body.iter().all(|&c| c != b'e' && c != b'E')
    {
        if !body.starts_with(b"0.0") {
            // `12.5`, `0.53`: already valid and shorter than any exponent form.
            out.extend_from_slice(text);
            return;
        }
        // `0.000123`: z zeros after the point, then the significant digits.
        let z = body[2..].iter().take_while(|&&c| c == b'0').count();
        let sig = &body[2 + z..];
        if z <= 2 {
            out.extend_from_slice(text);
        } else {
            out.extend_from_slice(sign);
            out.push(sig[0]);
            out.push(b'.');
            out.extend_from_slice(&sig[1..]);
            out.extend_from_slice(b"E-");
            push_uint(out, z as u64 + 1);
        }
        return;
    }
    // Decompose whatever shape the shortest-digits formatter produced into sign, significant
    // digits and a decimal exponent, so the IGES form does not depend on its style.
    let (negative, body) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, text),
    };
    let (mantissa, exp_part) = match body.iter().position(|&c| c == b'e' || c == b'E') {
        Some(i) => (&body[..i], &body[i + 1..]),
        None => (body, &b""[..]),
    };
    let mut exp10: i32 = 0;
    if !exp_part.is_empty() {
        let (sign, digits) = match exp_part.split_first() {
            Some((b'-', d)) => (-1, d),
            Some((b'+', d)) => (1, d),
            _ => (1, exp_part),
        };
        let mut e = 0i32;
        for &d in digits {
            e = e * 10 + i32::from(d - b'0');
        }
        exp10 = sign * e;
    }
    let mut digits = [0u8; 40];
    let mut n = 0usize;
    let mut point: Option<usize> = None;
    for &c in mantissa {
        if c == b'.' {
            point = Some(n);
        } else if n < digits.len() {
            digits[n] = c;
            n += 1;
        }
    }
    let int_len = point.unwrap_or(n) as i32;
    // Strip leading zeros (adjusting nothing: they sit before the point or after it as
    // position shifts) and trailing zeros.
    let mut start = 0usize;
    while start < n && digits[start] == b'0' {
        start += 1;
    }
    let mut end = n;
    while end > start && digits[end - 1] == b'0' {
        end -= 1;
    }
    if negative {
        out.push(b'-');
    }
    if start == end {
        out.extend_from_slice(b"0.");
        return;
    }
    let sig = &digits[start..end];
    // value = 0.d1d2..dk × 10^dec, where dec counts the digit positions before the point.
    let dec = int_len - start as i32 + exp10;
    let k = sig.len() as i32;
    // Plain form length: dec >= k: k + (dec - k) zeros + "."; 0 < dec < k: k + 1;
    // dec <= 0: "0." + (-dec) zeros + k.
    let plain_len = if dec >= k {
        dec + 1
    } else if dec > 0 {
        k + 1
    } else {
        2 - dec + k
    };
    let sci_exp = dec - 1;
    let exp_len = if sci_exp < 0 { 1 } else { 0 } + decimal_len(sci_exp.unsigned_abs());
    let sci_len = k + 2 + exp_len as i32;
    if plain_len <= sci_len {
        if dec >= k {
            out.extend_from_slice(sig);
            out.extend(std::iter::repeat_n(b'0', (dec - k) as usize));
            out.push(b'.');
        } else if dec > 0 {
            out.extend_from_slice(&sig[..dec as usize]);
            out.push(b'.');
            out.extend_from_slice(&sig[dec as usize..]);
        } else {
            out.extend_from_slice(b"0.");
            out.extend(std::iter::repeat_n(b'0', (-dec) as usize));
            out.extend_from_slice(sig);
        }
    } else {
        out.push(sig[0]);
        out.push(b'.');
        out.extend_from_slice(&sig[1..]);
        out.push(b'E');
        if sci_exp < 0 {
            out.push(b'-');
        }
        push_uint(out, sci_exp.unsigned_abs() as u64);
    }
}

/// Appends `bytes` (at most 32, as any formatted f64 is; longer input falls back to an
/// ordinary copy) with one capacity check and fixed-size copies, inlined into the formatter:
/// a real's text is appended without a call.
#[inline(always)]
fn push_short(out: &mut Vec<u8>, bytes: &[u8]) {
    let n = bytes.len();
    if n > 32 {
        out.extend_from_slice(bytes);
        return;
    }
    out.reserve(32);
    let len = out.len();
    // SAFETY: `reserve(32)` guarantees 32 writable bytes from `len`, and `n <= 32`;
    // `set_len` then covers exactly the bytes written.
    unsafe {
        copy_at_most_32(bytes, out.as_mut_ptr().add(len));
        out.set_len(len + n);
    }
}

/// Appends `bytes` (at most 32) and then `last`, with one capacity check and fixed-size copies:
/// the packing of tokens into records, the formatter's innermost loop, is written by hand here
/// because `extend_from_slice` of a short slice costs a `memcpy` call and a second check.
#[inline]
pub(crate) fn push_short_then(out: &mut Vec<u8>, bytes: &[u8], last: u8) {
    let n = bytes.len();
    assert!(n <= 32);
    out.reserve(33);
    let len = out.len();
    // SAFETY: `reserve(33)` guarantees 33 writable bytes from `len`, and `n <= 32`; `set_len`
    // then covers exactly the bytes written.
    unsafe {
        let dst = out.as_mut_ptr().add(len);
        copy_at_most_32(bytes, dst);
        *dst.add(n) = last;
        out.set_len(len + n + 1);
    }
}

/// Copies `bytes` (at most 16) to `dst`: the 8 to 16 bytes of most significands in one branch
/// of two overlapping 8-byte copies (a fitted height's 15 or 16 digits after the first do not
/// alternate between branches as they would at the 16-byte step of [`copy_at_most_32`]).
///
/// # Safety
/// `bytes.len() <= 16` and `dst` is valid for writing `bytes.len()` bytes that do not overlap
/// `bytes`.
#[inline(always)]
unsafe fn copy_at_most_16(bytes: &[u8], dst: *mut u8) {
    let (src, n) = (bytes.as_ptr(), bytes.len());
    // SAFETY: each copy reads within `bytes` and writes within [dst, dst + n), as the caller
    // guarantees room for.
    unsafe {
        if n >= 8 {
            std::ptr::copy_nonoverlapping(src, dst, 8);
            std::ptr::copy_nonoverlapping(src.add(n - 8), dst.add(n - 8), 8);
        } else if n >= 4 {
            std::ptr::copy_nonoverlapping(src, dst, 4);
            std::ptr::copy_nonoverlapping(src.add(n - 4), dst.add(n - 4), 4);
        } else {
            for i in 0..n {
                *dst.add(i) = *src.add(i);
            }
        }
    }
}

/// Copies `bytes` (at most 32) to `dst` with fixed-size copies: two overlapping copies of a
/// power-of-two size cover every length in its range.
///
/// # Safety
/// `bytes.len() <= 32` and `dst` is valid for writing `bytes.len()` bytes that do not overlap
/// `bytes`.
#[inline(always)]
unsafe fn copy_at_most_32(bytes: &[u8], dst: *mut u8) {
    let (src, n) = (bytes.as_ptr(), bytes.len());
    // SAFETY: each copy reads within `bytes` and writes within [dst, dst + n), as the caller
    // guarantees room for; below 16 bytes the caller's guarantee is `copy_at_most_16`'s.
    unsafe {
        if n >= 16 {
            std::ptr::copy_nonoverlapping(src, dst, 16);
            std::ptr::copy_nonoverlapping(src.add(n - 16), dst.add(n - 16), 16);
        } else {
            copy_at_most_16(bytes, dst);
        }
    }
}

fn decimal_len(mut v: u32) -> u32 {
    let mut n = 1;
    while v >= 10 {
        v /= 10;
        n += 1;
    }
    n
}

/// Appends an unsigned integer in decimal.
pub fn push_uint(out: &mut Vec<u8>, mut v: u64) {
    let mut tmp = [0u8; 20];
    let mut i = tmp.len();
    loop {
        i -= 1;
        tmp[i] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    out.extend_from_slice(&tmp[i..]);
}

/// Appends a signed integer in decimal.
pub fn push_int(out: &mut Vec<u8>, v: i64) {
    if v < 0 {
        out.push(b'-');
    }
    push_uint(out, v.unsigned_abs());
}

/// Appends `v` right-justified in a field of `width` columns (wider numbers take more room;
/// callers keep values within their fields).
pub fn push_right(out: &mut Vec<u8>, v: i64, width: usize) {
    let mut tmp = [0u8; 20];
    let mut i = tmp.len();
    let mut m = v.unsigned_abs();
    loop {
        i -= 1;
        tmp[i] = b'0' + (m % 10) as u8;
        m /= 10;
        if m == 0 {
            break;
        }
    }
    if v < 0 {
        i -= 1;
        tmp[i] = b'-';
    }
    let digits = &tmp[i..];
    out.extend(std::iter::repeat_n(
        b' ',
        width.saturating_sub(digits.len()),
    ));
    out.extend_from_slice(digits);
}

/// `text` reduced to printable ASCII (others become `?`), as IGES strings require.
pub fn ascii_printable(text: &str) -> String {
    text.chars()
        .map(|c| if (' '..='~').contains(&c) { c } else { '?' })
        .collect()
}

/// A Hollerith string `nH…` for `text` (made printable ASCII first).
pub fn hollerith(text: &str) -> String {
    let t = ascii_printable(text);
    format!("{}H{}", t.len(), t)
}

/// Packs free-format tokens into fixed-width data fields, breaking only after a delimiter.
///
/// Each token is pushed together with the delimiter that follows it, so a number is never
/// split from its delimiter nor across records. Hollerith strings longer than a whole field
/// may continue on the next record (the only split IGES allows).
///
/// Records are either bare (`width` bytes each, [`FieldPacker::new`]) or finished P lines
/// ([`FieldPacker::parameter_lines`]): each 64-column record followed by its DE back-pointer,
/// `P`, the sequence number counted up in place and the newline, so a record is written
/// once, in its line, instead of packed and then copied into a line.
#[derive(Debug)]
pub struct FieldPacker {
    width: usize,
    /// Records written so far; the last one may still be filling (from `line_start`).
    data: Vec<u8>,
    line_start: usize,
    /// What follows each record's data in a P line, if the records are P lines.
    frame: Option<LineFrame>,
    /// Records completed so far, those handed on included.
    completed: usize,
}

/// A record's worth of blanks to pad with.
const SPACES: [u8; 64] = [b' '; 64];

/// Bytes after the 64 data columns of a P line: the DE back-pointer (8), `P`, the sequence
/// number (7), the newline.
pub const P_LINE_TAIL: usize = 17;

/// Columns 65–80 and the newline of the P lines being packed.
#[derive(Debug)]
struct LineFrame {
    /// Columns 65–72: the DE back-pointer.
    back: [u8; 8],
    /// Column 73 (`P`) and columns 74–80 (the sequence number) as one little-endian word, the
    /// last digit in its top byte: counting up is one addition nine times in ten, and the
    /// tail is stored as whole words instead of bytes that are then read back wider.
    seq: u64,
}

/// `P` and a blank sequence field (before the first line).
const P_BLANK_SEQUENCE: u64 = u64::from_le_bytes(*b"P       ");

/// The word of [`LineFrame::seq`] for the next line.
#[inline]
fn next_sequence(word: u64) -> u64 {
    let last = (word >> 56) as u8;
    if last.is_ascii_digit() && last != b'9' {
        return word + (1 << 56);
    }
    let mut bytes = word.to_le_bytes();
    let mut field = SequenceField {
        digits: [
            bytes[1], bytes[2], bytes[3], bytes[4], bytes[5], bytes[6], bytes[7],
        ],
    };
    field.increment();
    bytes[1..].copy_from_slice(&field.digits);
    u64::from_le_bytes(bytes)
}

/// A 7-column right-justified sequence number kept as text and counted up in place.
#[derive(Debug)]
pub(crate) struct SequenceField {
    pub(crate) digits: [u8; 7],
}

impl SequenceField {
    /// The field before the first line (blank; the first increment makes it 1).
    #[cfg(test)]
    pub(crate) fn new() -> SequenceField {
        SequenceField { digits: [b' '; 7] }
    }

    /// Adds one. Past seven digits it wraps; the writer refuses such a file before it is
    /// used.
    pub(crate) fn increment(&mut self) {
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

impl FieldPacker {
    /// A packer for records of `width` data columns (64 in P, 72 in G).
    pub fn new(width: usize) -> FieldPacker {
        FieldPacker::with_capacity(width, 0)
    }

    /// Like [`FieldPacker::new`], reserving `bytes` for the records.
    pub fn with_capacity(width: usize, bytes: usize) -> FieldPacker {
        FieldPacker {
            width,
            data: Vec::with_capacity(bytes),
            line_start: 0,
            frame: None,
            completed: 0,
        }
    }

    /// A packer of finished P lines (64 data columns each), numbered from 1, reserving
    /// `bytes`; the DE back-pointer is set by [`FieldPacker::set_back_pointer`].
    pub fn parameter_lines(bytes: usize) -> FieldPacker {
        FieldPacker {
            frame: Some(LineFrame {
                back: [b' '; 8],
                seq: P_BLANK_SEQUENCE,
            }),
            ..FieldPacker::with_capacity(64, bytes)
        }
    }

    /// Sets the DE back-pointer (columns 65–72) of the P lines completed from now on; no
    /// effect on bare records.
    pub fn set_back_pointer(&mut self, de: usize) {
        if let Some(f) = &mut self.frame {
            let mut back = Vec::with_capacity(8);
            push_right(&mut back, de as i64, 8);
            f.back.copy_from_slice(&back);
        }
    }

    /// Adds `token` followed by `delimiter`; starts a new record first if they do not fit.
    pub fn push(&mut self, token: &[u8], delimiter: u8) {
        let need = token.len() + 1;
        let used = self.data.len() - self.line_start;
        if used + need > self.width {
            if need <= self.width {
                self.pad_line();
            } else {
                // Only Hollerith strings can be this long: fill records with it.
                let mut rest = token;
                loop {
                    let room = self.width - (self.data.len() - self.line_start);
                    if rest.len() < room {
                        break;
                    }
                    self.data.extend_from_slice(&rest[..room]);
                    rest = &rest[room..];
                    self.pad_line();
                }
                self.data.extend_from_slice(rest);
                self.data.push(delimiter);
                return;
            }
        }
        push_short(&mut self.data, token);
        self.data.push(delimiter);
    }

    /// Adds pre-formatted tokens (`lens[i]` bytes each, concatenated in `text`), each followed
    /// by `delimiter`: exactly what one [`FieldPacker::push`] per token gives, in one loop
    /// that checks capacity once per token.
    pub fn push_tokens(&mut self, text: &[u8], lens: &[u8], delimiter: u8) {
        let mut at = 0usize;
        for &len in lens {
            let n = usize::from(len);
            let token = &text[at..at + n];
            at += n;
            if n + 1 > self.width {
                self.push(token, delimiter);
                continue;
            }
            if self.data.len() - self.line_start + n + 1 > self.width {
                self.pad_line();
            }
            push_short_then(&mut self.data, token, delimiter);
        }
    }

    /// Adds `count` copies of `token` followed by `delimiter`: exactly what one
    /// [`FieldPacker::push`] per copy gives, with the whole records between the first and
    /// the last copied from one record.
    pub fn push_repeated(&mut self, token: &[u8], delimiter: u8, count: usize) {
        let need = token.len() + 1;
        if need > self.width {
            for _ in 0..count {
                self.push(token, delimiter);
            }
            return;
        }
        let mut left = count;
        // The record being filled takes what fits (at least one copy when it is empty).
        while left > 0 && self.data.len() - self.line_start + need <= self.width {
            self.data.extend_from_slice(token);
            self.data.push(delimiter);
            left -= 1;
        }
        if left == 0 {
            return;
        }
        // Each further record holds `per` copies; the last one stays open, as after single
        // pushes.
        let per = self.width / need;
        let mut record = vec![b' '; per * need];
        for slot in record.chunks_exact_mut(need) {
            slot[..token.len()].copy_from_slice(token);
            slot[token.len()] = delimiter;
        }
        loop {
            self.pad_line();
            let n = left.min(per);
            self.data.extend_from_slice(&record[..n * need]);
            left -= n;
            if left == 0 {
                return;
            }
        }
    }

    /// Adds a real (see [`push_real`]) followed by `delimiter`, formatting it in place.
    /// Returns `false` (adding nothing) for NaN or infinity.
    pub fn push_real(&mut self, value: f64, delimiter: u8) -> bool {
        let before = self.data.len();
        if !push_real(&mut self.data, value) {
            return false;
        }
        self.data.push(delimiter);
        if self.data.len() - self.line_start > self.width {
            let mut tmp = [0u8; 64];
            let len = self.data.len() - before;
            tmp[..len].copy_from_slice(&self.data[before..]);
            self.data.truncate(before);
            self.pad_line();
            self.data.extend_from_slice(&tmp[..len]);
        }
        true
    }

    /// Bytes held: the complete records not yet drained and the one being filled.
    pub fn bytes(&self) -> usize {
        self.data.len()
    }

    /// Pads the record being filled to the full width, so that what follows starts a new one.
    pub fn pad_last(&mut self) {
        if self.data.len() > self.line_start {
            self.pad_line();
        }
    }

    /// Hands the complete records (or P lines) to `f` and keeps only the record being
    /// filled, so a long entity can be written as it is packed.
    pub fn drain_records<R>(&mut self, f: impl FnOnce(&[u8]) -> R) -> R {
        let r = f(&self.data[..self.line_start]);
        self.data.drain(..self.line_start);
        self.line_start = 0;
        r
    }

    /// Completes the record being filled: padded to the full width, then, for a P line, its
    /// columns 65–80 and the newline.
    #[inline]
    fn pad_line(&mut self) {
        let (len, end) = (self.data.len(), self.line_start + self.width);
        if self.width <= SPACES.len() {
            // One fixed-size store of spaces (its part past the record lands in spare
            // capacity and is overwritten or never read) instead of a fill of variable length.
            self.data.reserve(SPACES.len() + P_LINE_TAIL);
            // SAFETY: `reserve` leaves at least 64 writable bytes from `len`; `end - len` is
            // at most the width (≤ 64), so [len, end) is written with spaces before `set_len`
            // makes it part of the vector.
            unsafe {
                let dst = self.data.as_mut_ptr().add(len);
                std::ptr::copy_nonoverlapping(SPACES.as_ptr(), dst, SPACES.len());
                self.data.set_len(end);
            }
        } else {
            self.data.resize(end, b' ');
        }
        if let Some(f) = &mut self.frame {
            f.seq = next_sequence(f.seq);
            self.data.reserve(P_LINE_TAIL);
            let len = self.data.len();
            // SAFETY: `reserve` leaves P_LINE_TAIL writable bytes from `len`; all of them are
            // written before `set_len` makes them part of the vector.
            unsafe {
                let dst = self.data.as_mut_ptr().add(len);
                dst.cast::<[u8; 8]>().write_unaligned(f.back);
                dst.add(8)
                    .cast::<[u8; 8]>()
                    .write_unaligned(f.seq.to_le_bytes());
                *dst.add(16) = b'\n';
                self.data.set_len(len + P_LINE_TAIL);
            }
        }
        self.line_start = self.data.len();
        self.completed += 1;
    }

    /// Number of records completed so far (those handed on included).
    pub fn complete_records(&self) -> usize {
        self.completed
    }

    /// Number of complete records so far plus the one being filled.
    pub fn records(&self) -> usize {
        self.completed + usize::from(self.data.len() > self.line_start)
    }

    /// Finishes the last record and returns the records not yet drained.
    pub fn finish(mut self) -> Vec<u8> {
        if self.data.len() > self.line_start {
            self.pad_line();
        }
        self.data
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn real(v: f64) -> String {
        let mut out = Vec::new();
        assert!(push_real(&mut out, v));
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn reals_have_point_and_upper_case_exponent() {
        assert_eq!(real(1.0), "1.");
        assert_eq!(real(0.0), "0.");
        assert_eq!(real(-0.0), "-0.");
        assert_eq!(real(0.25), "0.25");
        assert_eq!(real(-12.5), "-12.5");
        assert_eq!(real(1e-7), "1.E-7");
        assert_eq!(real(1.2345e-4), "1.2345E-4");
        assert_eq!(real(0.012), "0.012");
        assert_eq!(real(1e20), "1.E20");
        assert_eq!(real(100.0), "100.");
        assert_eq!(real(123456.0), "123456.");
        assert_eq!(real(0.00085), "8.5E-4");
        assert_eq!(real(-0.00085), "-8.5E-4");
        assert_eq!(real(0.0085), "0.0085");
        assert_eq!(real(0.00123456789), "0.00123456789");
    }

    #[test]
    fn reals_refuse_non_finite() {
        let mut out = Vec::new();
        assert!(!push_real(&mut out, f64::NAN));
        assert!(!push_real(&mut out, f64::INFINITY));
        assert!(out.is_empty());
    }

    #[test]
    fn reals_round_trip_bit_exact() {
        // A deterministic spread of magnitudes and bit patterns (xorshift).
        let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..20000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let v = f64::from_bits(s);
            if !v.is_finite() {
                continue;
            }
            let t = real(v);
            assert!(t.contains('.'), "{t}");
            assert!(!t.contains('e'), "{t}");
            let back: f64 = t.parse().unwrap();
            assert_eq!(back.to_bits(), v.to_bits(), "{v:e} -> {t}");
        }
        for v in [
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            5e-324,
            0.1,
            1.0 / 3.0,
        ] {
            let back: f64 = real(v).parse().unwrap();
            assert_eq!(back.to_bits(), v.to_bits());
        }
    }

    /// The IGES form built independently from std's shortest digits (`{:e}`): the plain
    /// decimal unless the `d.dddE±x` form is strictly shorter.
    fn reference_real(v: f64) -> String {
        let sci = format!("{:e}", v.abs());
        let (mant, exp) = sci.split_once('e').unwrap();
        let exp: i32 = exp.parse().unwrap();
        let digits: String = mant.chars().filter(|c| *c != '.').collect();
        let k = digits.len() as i32;
        let dec = exp + 1; // digits before the point
        let plain = if dec >= k {
            format!("{digits}{}.", "0".repeat((dec - k) as usize))
        } else if dec > 0 {
            format!("{}.{}", &digits[..dec as usize], &digits[dec as usize..])
        } else {
            format!("0.{}{digits}", "0".repeat((-dec) as usize))
        };
        let sci = format!("{}.{}E{exp}", &digits[..1], &digits[1..]);
        let body = if sci.len() < plain.len() { sci } else { plain };
        if v.is_sign_negative() {
            format!("-{body}")
        } else {
            body
        }
    }

    #[test]
    fn reals_match_a_reference_built_from_std_digits() {
        // Every magnitude the poles of a fit take and the edges of the fast path: 1e-3 and
        // 1e15 and their neighbours, integers (`100.`, `1.E3`), 17-digit values.
        let mut values = vec![1e-3, 1e15, 1000.0, 100.0, 1e14, 123456789012345.0, 0.0];
        for v in [1e-3f64, 1e15, 1e-2, 1e-4, 1e-5] {
            values.push(f64::from_bits(v.to_bits() - 1));
            values.push(f64::from_bits(v.to_bits() + 1));
        }
        let mut s: u64 = 0x2545_F491_4F6C_DD1D;
        for _ in 0..20000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let unit = (s >> 11) as f64 / (1u64 << 53) as f64;
            let exp = (s % 23) as i32 - 6;
            values.push(unit * 10f64.powi(exp));
            values.push((s % 100_000) as f64 * 10f64.powi(exp - 3));
        }
        for v in values {
            for v in [v, -v] {
                let fast = real(v);
                // The fast path gives what the general path gives for the same digits.
                let mut general = Vec::new();
                reformat(
                    &mut general,
                    zmij::Buffer::new().format_finite(v).as_bytes(),
                );
                assert_eq!(fast.as_bytes(), general, "{v:e}");
                // Same form and length as the reference (shortest digits may differ in the
                // last place when two candidates are equally close), and it reads back.
                let reference = reference_real(v);
                assert_eq!(fast.len(), reference.len(), "{v:e}: {fast} vs {reference}");
                assert_eq!(fast.contains('E'), reference.contains('E'), "{v:e}");
                assert_eq!(
                    fast.parse::<f64>().unwrap().to_bits(),
                    v.to_bits(),
                    "{fast}"
                );
            }
        }
    }

    #[test]
    fn height_band_reals_are_written_in_place_as_the_general_path_writes_them() {
        // The magnitudes of fitted heights in mm (1e-5 <= |v| < 1e-3) are written straight
        // into the buffer: appended one after another to a buffer that already holds text,
        // they must be what the general path writes, byte for byte, and nothing before them
        // may change. Short (`1.5E-4`) and 17-digit texts, both signs, the band's edges.
        let mut values = vec![1e-5, 1e-4, 9.999999999999999e-4];
        values.push(f64::from_bits(1e-5f64.to_bits() + 1));
        values.push(f64::from_bits(1e-3f64.to_bits() - 1));
        let mut s: u64 = 0x1234_5678_9ABC_DEF1;
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let unit = 1.0 + 9.0 * ((s >> 11) as f64 / (1u64 << 53) as f64);
            let exp = if s & 1 == 0 { -4 } else { -5 };
            values.push(unit * 10f64.powi(exp));
            values.push(((s >> 20) % 10_000) as f64 * 10f64.powi(exp - 3));
        }
        let (mut fast, mut general) = (b"P,".to_vec(), b"P,".to_vec());
        let mut count = 0;
        for v in values {
            for v in [v, -v] {
                if !(1e-5..1e-3).contains(&v.abs()) {
                    continue;
                }
                assert!(push_real(&mut fast, v));
                fast.push(b',');
                reformat(
                    &mut general,
                    zmij::Buffer::new().format_finite(v).as_bytes(),
                );
                general.push(b',');
                count += 1;
            }
        }
        assert!(count > 700_000, "{count}");
        assert!(
            fast == general,
            "the in-place texts differ from the general path's"
        );
        // Spot checks written out by hand.
        for (v, t) in [(1.5e-4, "1.5E-4"), (-2.25e-5, "-2.25E-5"), (1e-4, "1.E-4")] {
            assert_eq!(real(v), t);
        }
    }

    #[test]
    fn short_copies_append_exactly_the_bytes() {
        let src: Vec<u8> = (0..40u8).map(|b| b'A' + b).collect();
        for n in 0..=40 {
            let mut out = b"xy".to_vec();
            push_short(&mut out, &src[..n]);
            assert_eq!(&out[..2], b"xy");
            assert_eq!(&out[2..], &src[..n], "length {n}");
            let mut out = b"xy".to_vec();
            if n <= 32 {
                push_short_then(&mut out, &src[..n], b';');
                assert_eq!(&out[2..2 + n], &src[..n], "length {n}");
                assert_eq!(&out[2 + n..], b";");
            }
        }
    }

    #[test]
    fn the_sequence_word_counts_like_the_sequence_field() {
        let mut word = P_BLANK_SEQUENCE;
        let mut field = SequenceField::new();
        for n in 1..=1_000_100u32 {
            word = next_sequence(word);
            field.increment();
            let bytes = word.to_le_bytes();
            assert_eq!(bytes[0], b'P');
            assert_eq!(bytes[1..], field.digits, "{n}");
        }
    }

    #[test]
    fn hollerith_counts_characters() {
        assert_eq!(hollerith("MM"), "2HMM");
        assert_eq!(hollerith("a,b;"), "4Ha,b;");
        assert_eq!(hollerith("µm"), "2H?m");
    }

    #[test]
    fn packer_breaks_only_after_delimiters() {
        let mut p = FieldPacker::new(10);
        for t in ["1234", "5678", "9"] {
            p.push(t.as_bytes(), b',');
        }
        assert_eq!(p.finish(), b"1234,5678,9,        ".to_vec());
        let mut p = FieldPacker::new(10);
        assert!(p.push_real(0.125, b','));
        assert!(p.push_real(0.375, b','));
        assert!(p.push_real(2.5, b';'));
        assert!(!p.push_real(f64::NAN, b';'));
        assert_eq!(p.finish(), b"0.125,    0.375,2.5;".to_vec());
        let mut p = FieldPacker::new(8);
        p.push(b"12HABCDEFGHIJKL", b';');
        assert_eq!(p.finish(), b"12HABCDEFGHIJKL;".to_vec());
    }
}
