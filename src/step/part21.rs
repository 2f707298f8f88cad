//! The text of an ISO 10303-21 exchange file: the header, entity instances numbered in the
//! order they are written (every reference points back to an instance already written, so a
//! reader never meets a forward reference), reals in the shortest form that reads back to the
//! same f64, strings quoted with `'` doubled.
//!
//! Layer 1 (pure logic): depends on [`crate::iges::format`] for the reals (the same `1.`,
//! `-0.25`, `1.2345E-4` syntax as IGES); writes to any `io::Write`.

use std::io::{self, Write};

/// An entity instance's number (`#n`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ref(pub usize);

/// Writes numbered entity instances to `w`.
pub struct Part21<W: Write> {
    w: W,
    next: usize,
    line: Vec<u8>,
    bytes: u64,
}

impl<W: Write> Part21<W> {
    /// Starts a file: writes the header (description, file name, time stamp, originating
    /// system, schema) and opens the data section.
    pub fn start(
        w: W,
        description: &str,
        file_name: &str,
        timestamp: &str,
        system: &str,
        schema: &str,
    ) -> io::Result<Part21<W>> {
        let mut p = Part21 {
            w,
            next: 1,
            line: Vec::with_capacity(256),
            bytes: 0,
        };
        let header = format!(
            "ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(({}),'2;1');\nFILE_NAME({},{},(''),(''),{},{},'');\nFILE_SCHEMA(({}));\nENDSEC;\nDATA;\n",
            string(description),
            string(file_name),
            string(timestamp),
            string(system),
            string(system),
            string(schema),
        );
        p.write_raw(header.as_bytes())?;
        Ok(p)
    }

    fn write_raw(&mut self, b: &[u8]) -> io::Result<()> {
        self.w.write_all(b)?;
        self.bytes += b.len() as u64;
        Ok(())
    }

    /// Writes `#n=BODY;` where `body` fills in the text after `=`, and returns `#n`.
    pub fn entity(&mut self, body: impl FnOnce(&mut Vec<u8>)) -> io::Result<Ref> {
        let id = self.next;
        self.next += 1;
        let mut line = std::mem::take(&mut self.line);
        line.clear();
        line.push(b'#');
        push_usize(&mut line, id);
        line.push(b'=');
        body(&mut line);
        line.extend_from_slice(b";\n");
        let r = self.write_raw(&line);
        self.line = line;
        r.map(|_| Ref(id))
    }

    /// Writes `#n=HEAD#a,#b,…TAIL;`, an entity whose fields besides the fixed `head` and
    /// `tail` are the references `refs`, and returns `#n`.
    pub fn linking(&mut self, head: &[u8], refs: &[Ref], tail: &[u8]) -> io::Result<Ref> {
        self.entity(|b| {
            b.extend_from_slice(head);
            joined(b, refs, reference);
            b.extend_from_slice(tail);
        })
    }

    /// A `CARTESIAN_POINT('',(x,y,z))`.
    pub fn point(&mut self, p: [f64; 3]) -> io::Result<Ref> {
        self.entity(|b| {
            b.extend_from_slice(b"CARTESIAN_POINT('',");
            reals(b, &p);
            b.push(b')');
        })
    }

    /// A `DIRECTION('',(x,y,z))`.
    pub fn direction(&mut self, d: [f64; 3]) -> io::Result<Ref> {
        self.entity(|b| {
            b.extend_from_slice(b"DIRECTION('',");
            reals(b, &d);
            b.push(b')');
        })
    }

    /// Closes the data section and the file; returns the writer and the bytes written.
    pub fn finish(mut self) -> io::Result<(W, u64, usize)> {
        self.write_raw(b"ENDSEC;\nEND-ISO-10303-21;\n")?;
        self.w.flush()?;
        Ok((self.w, self.bytes, self.next - 1))
    }
}

/// A STEP string literal: `'…'` with `'` doubled and non-ASCII or control characters
/// replaced by `?` (Part 21 strings are ISO 8859-1 without escapes here).
pub fn string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('\'');
    for c in s.chars() {
        match c {
            '\'' => out.push_str("''"),
            '\\' => out.push_str("\\\\"),
            ' '..='~' => out.push(c),
            _ => out.push('?'),
        }
    }
    out.push('\'');
    out
}

/// Appends an unsigned integer.
pub fn push_usize(b: &mut Vec<u8>, v: usize) {
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    let mut v = v;
    loop {
        i -= 1;
        buf[i] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    b.extend_from_slice(&buf[i..]);
}

/// Appends a real (the caller has checked it is finite).
pub fn real(b: &mut Vec<u8>, v: f64) {
    let ok = crate::iges::format::push_real(b, v);
    debug_assert!(ok, "STEP reals are finite");
}

/// Appends `a,b,…`, each item by `one`.
fn joined<T: Copy>(b: &mut Vec<u8>, vs: &[T], one: impl Fn(&mut Vec<u8>, T)) {
    for (k, v) in vs.iter().enumerate() {
        if k > 0 {
            b.push(b',');
        }
        one(b, *v);
    }
}

/// Appends `(a,b,…)`, each item by `one`.
fn list<T: Copy>(b: &mut Vec<u8>, vs: &[T], one: impl Fn(&mut Vec<u8>, T)) {
    b.push(b'(');
    joined(b, vs, one);
    b.push(b')');
}

/// Appends `(a,b,c)` of reals.
pub fn reals(b: &mut Vec<u8>, vs: &[f64]) {
    list(b, vs, real);
}

/// Appends `#n`.
pub fn reference(b: &mut Vec<u8>, r: Ref) {
    b.push(b'#');
    push_usize(b, r.0);
}

/// Appends `(#a,#b,…)`.
pub fn references(b: &mut Vec<u8>, rs: &[Ref]) {
    list(b, rs, reference);
}

/// Appends `(1,2,…)` of integers.
pub fn integers(b: &mut Vec<u8>, vs: &[usize]) {
    list(b, vs, push_usize);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_double_quotes_and_replace_non_ascii() {
        assert_eq!(string("it's"), "'it''s'");
        assert_eq!(string("µm"), "'?m'");
        assert_eq!(string(""), "''");
    }

    #[test]
    fn entities_are_numbered_in_order_and_reals_have_a_point() {
        let mut p =
            Part21::start(Vec::new(), "d", "f.step", "2024-01-01T00:00:00", "s", "S").unwrap();
        let a = p.point([1.0, -0.25, 1e-7]).unwrap();
        let d = p.direction([0.0, 0.0, 1.0]).unwrap();
        assert_eq!((a, d), (Ref(1), Ref(2)));
        let e = p
            .entity(|b| {
                b.extend_from_slice(b"X(");
                references(b, &[a, d]);
                b.push(b',');
                integers(b, &[6, 1, 6]);
                b.push(b')');
            })
            .unwrap();
        assert_eq!(e, Ref(3));
        assert_eq!(p.linking(b"Y('',", &[a, e], b",.T.)").unwrap(), Ref(4));
        let (bytes, n, count) = p.finish().unwrap();
        let text = String::from_utf8(bytes).unwrap();
        assert_eq!(count, 4);
        assert_eq!(n as usize, text.len());
        assert!(text.starts_with("ISO-10303-21;\nHEADER;\n"), "{text}");
        assert!(
            text.contains("#1=CARTESIAN_POINT('',(1.,-0.25,1.E-7));\n"),
            "{text}"
        );
        assert!(text.contains("#2=DIRECTION('',(0.,0.,1.));\n"), "{text}");
        assert!(text.contains("#3=X((#1,#2),(6,1,6));\n"), "{text}");
        assert!(text.contains("#4=Y('',#1,#3,.T.);\n"), "{text}");
        assert!(text.ends_with("ENDSEC;\nEND-ISO-10303-21;\n"));
    }
}
