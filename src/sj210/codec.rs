//! The SJ-210 line codec: commands out as ASCII + CR, replies in as CR-terminated lines
//! classified as `OK…`, `NGnnn[,bb]` or malformed.
//!
//! Pure (layer 1): bytes in, values out; the `tokio_util` codec traits only wrap the pure
//! functions so a `Framed` stream or the client's own read loop can use them. Depends on
//! [`super::ng`] (the NG code a reply carries) only.

pub use super::ng::NgCode;
use bytes::{Buf, BufMut, Bytes, BytesMut};
use thiserror::Error;
use tokio_util::codec::{Decoder, Encoder};

/// Carriage return, the only terminator in either direction (SJ-210 manual p. 17-12).
pub const CR: u8 = b'\r';
/// Line feed: never sent by the instrument as documented, dropped wherever it appears.
pub const LF: u8 = b'\n';
/// Default maximum reply length. An `RDEVA` block of 50 values is about 500 bytes.
pub const DEFAULT_MAX_LINE: usize = 4096;

/// One reply line, classified.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// `OK` followed by the payload (possibly empty), decoded as latin-1.
    Ok(String),
    /// `NGnnn` with the optional `,bb` position of the offending data byte.
    Ng {
        /// The error code.
        code: NgCode,
        /// Position of the offending byte in the command's data, when given.
        byte_pos: Option<u8>,
    },
    /// Anything else, raw bytes kept (without the CR) for the error message.
    Malformed(Bytes),
}

/// A command that cannot be put on the wire.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum EncodeError {
    /// The command holds a byte outside printable ASCII (including CR/LF, which would split
    /// it into two commands).
    #[error("command {command:?} holds byte 0x{byte:02X} at {index}; commands are printable ASCII without CR/LF. Fix the command string in the model table or config")]
    NotPrintable {
        /// The command as given.
        command: String,
        /// Offending byte.
        byte: u8,
        /// Its index.
        index: usize,
    },
    /// The command is empty.
    #[error("empty command; the model table or config has an empty command string")]
    Empty,
    /// Writing failed.
    #[error("writing the command failed: {0}")]
    Io(String),
}

impl From<std::io::Error> for EncodeError {
    fn from(e: std::io::Error) -> Self {
        EncodeError::Io(e.to_string())
    }
}

/// Checks a command and returns its wire bytes (command + CR).
pub fn encode_command(command: &str) -> Result<Vec<u8>, EncodeError> {
    if command.is_empty() {
        return Err(EncodeError::Empty);
    }
    if let Some((index, &byte)) = command
        .as_bytes()
        .iter()
        .enumerate()
        .find(|(_, b)| !(0x20..=0x7E).contains(*b))
    {
        return Err(EncodeError::NotPrintable {
            command: command.to_string(),
            byte,
            index,
        });
    }
    let mut out = Vec::with_capacity(command.len() + 1);
    out.extend_from_slice(command.as_bytes());
    out.push(CR);
    Ok(out)
}

/// Latin-1 decoding: every byte is one char (0xB5 is `µ`), so it cannot fail.
pub fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| char::from(b)).collect()
}

/// Classifies one line (CR and LFs already removed).
pub fn classify(line: &[u8]) -> Reply {
    if let Some(payload) = line.strip_prefix(b"OK") {
        return Reply::Ok(latin1(payload));
    }
    if let Some(rest) = line.strip_prefix(b"NG") {
        let digits = |s: &[u8]| s.iter().all(u8::is_ascii_digit);
        let parse = |s: &[u8]| s.iter().fold(0u16, |acc, d| acc * 10 + u16::from(d - b'0'));
        match rest.len() {
            3 if digits(rest) => {
                return Reply::Ng {
                    code: NgCode::from_code(parse(rest)),
                    byte_pos: None,
                }
            }
            6 if digits(&rest[..3]) && rest[3] == b',' && digits(&rest[4..]) => {
                // Two digits fit in u8.
                let pos = u8::try_from(parse(&rest[4..])).unwrap_or(u8::MAX);
                return Reply::Ng {
                    code: NgCode::from_code(parse(&rest[..3])),
                    byte_pos: Some(pos),
                };
            }
            _ => {}
        }
    }
    Reply::Malformed(Bytes::copy_from_slice(line))
}

/// Escapes bytes for logs and transcripts: printable ASCII except `\\` as is, `\\\\` for a
/// backslash, `\\r` `\\n` `\\t`, everything else `\\xHH`.
pub fn escape_bytes(bytes: &[u8]) -> String {
    let mut out = String::with_capacity(bytes.len());
    for &b in bytes {
        match b {
            b'\\' => out.push_str("\\\\"),
            b'\r' => out.push_str("\\r"),
            b'\n' => out.push_str("\\n"),
            b'\t' => out.push_str("\\t"),
            0x20..=0x7E => out.push(char::from(b)),
            _ => out.push_str(&format!("\\x{b:02X}")),
        }
    }
    out
}

/// Tokio codec for the SJ-210 link: decodes [`Reply`] lines, encodes `&str` commands.
#[derive(Debug, Clone)]
pub struct Sj210Codec {
    max_line: usize,
    discarding: bool,
}

impl Default for Sj210Codec {
    fn default() -> Self {
        Sj210Codec::new(DEFAULT_MAX_LINE)
    }
}

impl Sj210Codec {
    /// A codec that reports lines longer than `max_line` bytes as malformed and resyncs at
    /// the next CR.
    pub fn new(max_line: usize) -> Sj210Codec {
        Sj210Codec {
            max_line: max_line.max(1),
            discarding: false,
        }
    }

    /// Forgets any partial line (used after draining the input).
    pub fn reset(&mut self) {
        self.discarding = false;
    }

    /// True while the rest of an over-long line is being skipped.
    pub fn is_discarding(&self) -> bool {
        self.discarding
    }
}

impl Decoder for Sj210Codec {
    type Item = Reply;
    type Error = std::io::Error;

    fn decode(&mut self, buf: &mut BytesMut) -> Result<Option<Reply>, std::io::Error> {
        loop {
            let cr = buf.iter().position(|&b| b == CR);
            if self.discarding {
                match cr {
                    Some(i) => {
                        buf.advance(i + 1);
                        self.discarding = false;
                        continue;
                    }
                    None => {
                        buf.clear();
                        return Ok(None);
                    }
                }
            }
            match cr {
                Some(i) => {
                    let raw = buf.split_to(i + 1);
                    let line: Vec<u8> = raw[..i].iter().copied().filter(|&b| b != LF).collect();
                    if line.len() > self.max_line {
                        return Ok(Some(Reply::Malformed(Bytes::from(line))));
                    }
                    return Ok(Some(classify(&line)));
                }
                None => {
                    let payload_len = buf.iter().filter(|&&b| b != LF).count();
                    if payload_len > self.max_line {
                        let line: Vec<u8> = buf.iter().copied().filter(|&b| b != LF).collect();
                        buf.clear();
                        self.discarding = true;
                        return Ok(Some(Reply::Malformed(Bytes::from(line))));
                    }
                    return Ok(None);
                }
            }
        }
    }
}

impl Encoder<&str> for Sj210Codec {
    type Error = EncodeError;

    fn encode(&mut self, item: &str, dst: &mut BytesMut) -> Result<(), EncodeError> {
        dst.put_slice(&encode_command(item)?);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(codec: &mut Sj210Codec, buf: &mut BytesMut, bytes: &[u8]) -> Vec<Reply> {
        buf.extend_from_slice(bytes);
        let mut out = Vec::new();
        while let Some(r) = codec.decode(buf).unwrap() {
            out.push(r);
        }
        out
    }

    #[test]
    fn escapes_like_the_transcript_format() {
        assert_eq!(escape_bytes(b"OK000\r"), "OK000\\r");
        assert_eq!(escape_bytes(b"a\\b\n\t\xb5 "), "a\\\\b\\n\\t\\xB5 ");
    }

    #[test]
    fn encodes_command_with_cr_only() {
        assert_eq!(encode_command("RDSJ 01").unwrap(), b"RDSJ 01\r".to_vec());
        let mut dst = BytesMut::new();
        Sj210Codec::default().encode("CTSTA", &mut dst).unwrap();
        assert_eq!(&dst[..], b"CTSTA\r");
    }

    #[test]
    fn refuses_cr_inside_and_empty_commands() {
        assert_eq!(
            encode_command("RDSTU00\rCTSTA"),
            Err(EncodeError::NotPrintable {
                command: "RDSTU00\rCTSTA".into(),
                byte: 0x0D,
                index: 7
            })
        );
        assert_eq!(encode_command(""), Err(EncodeError::Empty));
    }

    #[test]
    fn partial_line_waits_then_completes() {
        let mut c = Sj210Codec::default();
        let mut b = BytesMut::new();
        assert!(feed(&mut c, &mut b, b"OK0").is_empty());
        assert!(feed(&mut c, &mut b, b"0").is_empty());
        assert_eq!(feed(&mut c, &mut b, b"1\r"), vec![Reply::Ok("001".into())]);
        assert!(b.is_empty());
    }

    #[test]
    fn ok_with_empty_payload() {
        let mut c = Sj210Codec::default();
        let mut b = BytesMut::new();
        assert_eq!(
            feed(&mut c, &mut b, b"OK\r"),
            vec![Reply::Ok(String::new())]
        );
    }

    #[test]
    fn ng_with_and_without_byte_position() {
        let mut c = Sj210Codec::default();
        let mut b = BytesMut::new();
        assert_eq!(
            feed(&mut c, &mut b, b"NG031,05\rNG101\rNG999\r"),
            vec![
                Reply::Ng {
                    code: NgCode::InvalidFormat,
                    byte_pos: Some(5)
                },
                Reply::Ng {
                    code: NgCode::NoResults,
                    byte_pos: None
                },
                Reply::Ng {
                    code: NgCode::Other(999),
                    byte_pos: None
                },
            ]
        );
    }

    #[test]
    fn malformed_ng_and_garbage_keep_raw_bytes() {
        let mut c = Sj210Codec::default();
        let mut b = BytesMut::new();
        assert_eq!(
            feed(&mut c, &mut b, b"NG03\r\xff\x00zz\rNG031,5\r\r"),
            vec![
                Reply::Malformed(Bytes::from_static(b"NG03")),
                Reply::Malformed(Bytes::from_static(b"\xff\x00zz")),
                Reply::Malformed(Bytes::from_static(b"NG031,5")),
                Reply::Malformed(Bytes::new()),
            ]
        );
    }

    #[test]
    fn stray_lf_is_dropped_anywhere() {
        let mut c = Sj210Codec::default();
        let mut b = BytesMut::new();
        assert_eq!(
            feed(&mut c, &mut b, b"OK000\r\nOK\n001\r\n"),
            vec![Reply::Ok("000".into()), Reply::Ok("001".into())]
        );
        // A lone LF left in the buffer is not a line.
        assert!(feed(&mut c, &mut b, b"").is_empty());
    }

    #[test]
    fn latin1_micro_sign_decodes() {
        let mut c = Sj210Codec::default();
        let mut b = BytesMut::new();
        let r = feed(&mut c, &mut b, b"OKRa      3.123 \xb5m\r");
        assert_eq!(r, vec![Reply::Ok("Ra      3.123 \u{b5}m".into())]);
    }

    #[test]
    fn split_across_many_reads() {
        let mut c = Sj210Codec::default();
        let mut b = BytesMut::new();
        let mut got = Vec::new();
        for byte in b"OK000\rNG011\r" {
            got.extend(feed(&mut c, &mut b, &[*byte]));
        }
        assert_eq!(
            got,
            vec![
                Reply::Ok("000".into()),
                Reply::Ng {
                    code: NgCode::Busy,
                    byte_pos: None
                }
            ]
        );
    }

    #[test]
    fn over_long_line_is_malformed_and_resyncs_at_next_cr() {
        let mut c = Sj210Codec::new(8);
        let mut b = BytesMut::new();
        let r = feed(&mut c, &mut b, b"OK123456789");
        assert_eq!(
            r,
            vec![Reply::Malformed(Bytes::from_static(b"OK123456789"))]
        );
        assert!(c.is_discarding());
        // The rest of the long line is skipped, the next line decodes.
        assert!(feed(&mut c, &mut b, b"abcdef").is_empty());
        assert_eq!(
            feed(&mut c, &mut b, b"xyz\rOK000\r"),
            vec![Reply::Ok("000".into())]
        );
        assert!(!c.is_discarding());
    }

    #[test]
    fn over_long_complete_line_is_malformed() {
        let mut c = Sj210Codec::new(4);
        let mut b = BytesMut::new();
        assert_eq!(
            feed(&mut c, &mut b, b"OK000\rOK1\r"),
            vec![
                Reply::Malformed(Bytes::from_static(b"OK000")),
                Reply::Ok("1".into())
            ]
        );
    }

    #[test]
    fn exactly_max_line_is_accepted() {
        let mut c = Sj210Codec::new(5);
        let mut b = BytesMut::new();
        assert!(feed(&mut c, &mut b, b"OK000").is_empty());
        assert_eq!(feed(&mut c, &mut b, b"\r"), vec![Reply::Ok("000".into())]);
    }
}
