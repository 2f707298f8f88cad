//! Splits a byte stream into text lines (CR, LF or CRLF terminated) with a length bound.
//!
//! Pure: no I/O, depends on nothing in the crate. [`super::link::LineLink`] feeds it.

use thiserror::Error;

/// A line that could not be framed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    /// The line grew past the bound without a terminator; its bytes were discarded.
    #[error("line longer than {max} bytes without a terminator (starts {head:?}); the link is garbled or the baud rate is wrong")]
    TooLong {
        /// The bound.
        max: usize,
        /// The first bytes of the discarded line.
        head: Vec<u8>,
    },
    /// The line is not valid text.
    #[error("line is not ASCII text: {bytes:02x?}; check the baud rate and parity")]
    NotText {
        /// The raw bytes.
        bytes: Vec<u8>,
    },
}

/// Accumulates bytes and yields complete lines without their terminators; empty lines
/// are skipped.
#[derive(Debug, Clone)]
pub struct LineFramer {
    buf: Vec<u8>,
    max: usize,
    discarding: bool,
}

impl LineFramer {
    /// A framer that refuses lines longer than `max` bytes.
    pub fn new(max: usize) -> Self {
        LineFramer {
            buf: Vec::new(),
            max,
            discarding: false,
        }
    }

    /// Drops any partial line (after a reset or a timeout).
    pub fn clear(&mut self) {
        self.buf.clear();
        self.discarding = false;
    }

    /// Feeds bytes; returns the complete lines (or framing errors) in order.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Result<String, FrameError>> {
        let mut out = Vec::new();
        for &b in bytes {
            if b == b'\n' || b == b'\r' {
                if self.discarding {
                    self.discarding = false;
                } else if !self.buf.is_empty() {
                    let line = std::mem::take(&mut self.buf);
                    if line.iter().all(|c| (0x20..0x7f).contains(c) || *c == b'\t') {
                        out.push(Ok(String::from_utf8_lossy(&line).into_owned()));
                    } else {
                        out.push(Err(FrameError::NotText { bytes: line }));
                    }
                }
                continue;
            }
            if self.discarding {
                continue;
            }
            self.buf.push(b);
            if self.buf.len() > self.max {
                let head: Vec<u8> = self.buf.iter().take(16).copied().collect();
                out.push(Err(FrameError::TooLong {
                    max: self.max,
                    head,
                }));
                self.buf.clear();
                self.discarding = true;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partial_lines_join_across_pushes() {
        let mut f = LineFramer::new(64);
        assert!(f.push(b"o").is_empty());
        assert_eq!(f.push(b"k\r\nerr"), vec![Ok("ok".to_string())]);
        assert_eq!(f.push(b"or:9\n\n"), vec![Ok("error:9".to_string())]);
    }

    #[test]
    fn over_long_line_is_discarded_up_to_its_terminator() {
        let mut f = LineFramer::new(8);
        let r = f.push(b"0123456789abcdef\nok\n");
        assert_eq!(r.len(), 2);
        assert!(matches!(&r[0], Err(FrameError::TooLong { max: 8, head }) if head.len() == 9));
        assert_eq!(r[1], Ok("ok".to_string()));
    }

    #[test]
    fn binary_garbage_is_named() {
        let mut f = LineFramer::new(64);
        let r = f.push(&[0xff, 0x00, b'o', b'\n']);
        assert_eq!(
            r,
            vec![Err(FrameError::NotText {
                bytes: vec![0xff, 0x00, b'o']
            })]
        );
    }
}
