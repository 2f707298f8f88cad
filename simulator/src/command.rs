//! The simulator's own parser for SJ-210-family command frames: splits the byte stream into
//! frames (CR-terminated, a stray LF tolerated) and turns each frame into a [`Command`].
//!
//! Pure: bytes in, values out; no I/O. Deliberately independent of the daemon's codec.
//! Grammar: 2-char header (`CT`/`RD`) + 3-char sub-field + data, no separators. The SJ-410's
//! one-byte A/B profile selector (`{ab}`) is recognised by the data length and reported in the
//! command, so the instrument can reject it on an SJ-210 and require it on an SJ-410.

/// Longest frame accepted before the buffer is declared overflowed (NG013).
pub const MAX_FRAME: usize = 256;

/// One command sent by the host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `CTSTA`: start a measurement, or abort the one in progress.
    Start,
    /// `CTSTP`: SJ-410 stop button.
    Stop,
    /// `CTOFFnn`: power off / auto-sleep setting.
    Off(u8),
    /// `CTESP[d]`: retract the detector.
    Retract,
    /// `CTRTN`: return the detector to the start position.
    Return,
    /// `RDSTU00`: operating status.
    Status,
    /// `RDSTU01`: battery status.
    Battery,
    /// `RDSJ 00`: drive unit type.
    DriveType,
    /// `RDSJ 01`: firmware version.
    Firmware,
    /// `RDCON{ab}`: measurement conditions.
    Conditions {
        /// SJ-410 profile selector (`0` A, `1` B), absent on the SJ-210.
        ab: Option<u8>,
    },
    /// `RDPAR{ab}`: number of customised parameters.
    ParamCount {
        /// SJ-410 profile selector.
        ab: Option<u8>,
    },
    /// `RDRES{ab}mm,aa,bb`: one result.
    Result {
        /// SJ-410 profile selector.
        ab: Option<u8>,
        /// Reply type: 00 value, 01 judgement, 02 name+value+unit.
        mode: u8,
        /// Parameter number, 1-based.
        param: u8,
        /// 00 = whole evaluation length, 01.. = per sampling length.
        index: u8,
    },
    /// `RDPSA`: detector position.
    Position,
    /// `RDEVA{ab}00`: total number of profile values.
    ProfileTotal {
        /// SJ-410 profile selector.
        ab: Option<u8>,
    },
    /// `RDEVA{ab}nn` (nn 01–50): the next block of profile values.
    ProfileBlock {
        /// SJ-410 profile selector.
        ab: Option<u8>,
        /// Number of values requested, 1–50.
        count: u8,
    },
}

/// Why a frame is not a command; each maps to the NG code the instrument answers.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    /// Unknown header or sub-field.
    #[error("illegal command {0:?} (NG030)")]
    Illegal(String),
    /// Known command, but its data has the wrong shape.
    #[error("invalid format for {command}: data {data:?} (NG031)")]
    Format {
        /// The command name (header + sub-field).
        command: String,
        /// The offending data.
        data: String,
    },
    /// Known command and shape, but a value is out of range.
    #[error("invalid value for {command}: data {data:?} (NG032)")]
    Value {
        /// The command name (header + sub-field).
        command: String,
        /// The offending data.
        data: String,
    },
    /// The frame was longer than [`MAX_FRAME`] bytes.
    #[error("frame longer than {MAX_FRAME} bytes (NG013)")]
    Overflow,
}

impl ParseError {
    /// The NG code the instrument answers with.
    pub fn ng_code(&self) -> u16 {
        match self {
            ParseError::Illegal(_) => 30,
            ParseError::Format { .. } => 31,
            ParseError::Value { .. } => 32,
            ParseError::Overflow => 13,
        }
    }
}

/// Splits a byte stream into frames: CR ends a frame, LF is tolerated as a terminator too, and
/// empty frames (e.g. the LF of a CR LF pair) are skipped.
#[derive(Debug, Default)]
pub struct FrameSplitter {
    buf: Vec<u8>,
    overflowed: bool,
}

/// One frame out of the splitter.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Frame {
    /// The bytes between terminators (terminator removed).
    Line(Vec<u8>),
    /// More than [`MAX_FRAME`] bytes arrived without a terminator; they were discarded.
    Overflow,
}

impl FrameSplitter {
    /// Creates an empty splitter.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes and returns every frame they complete.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Frame> {
        let mut out = Vec::new();
        for &b in bytes {
            if b == b'\r' || b == b'\n' {
                if self.overflowed {
                    out.push(Frame::Overflow);
                    self.overflowed = false;
                } else if !self.buf.is_empty() {
                    out.push(Frame::Line(std::mem::take(&mut self.buf)));
                }
                self.buf.clear();
            } else if self.buf.len() >= MAX_FRAME {
                self.overflowed = true;
                self.buf.clear();
            } else if !self.overflowed {
                self.buf.push(b);
            }
        }
        out
    }
}

fn two_digits(s: &str) -> Option<u8> {
    if s.len() == 2 && s.bytes().all(|b| b.is_ascii_digit()) {
        s.parse().ok()
    } else {
        None
    }
}

fn selector(s: &str) -> Option<u8> {
    match s {
        "0" => Some(0),
        "1" => Some(1),
        _ => None,
    }
}

/// Splits a leading A/B selector byte off `data`.
fn split_selector(data: &str) -> Option<(Option<u8>, &str)> {
    let ab = selector(data.get(..1)?)?;
    Some((Some(ab), data.get(1..)?))
}

/// Parses one frame (without terminator) into a command.
pub fn parse(frame: &[u8]) -> Result<Command, ParseError> {
    // Latin-1 decoding: every byte maps to one char, so garbage never fails to decode.
    let text: String = frame.iter().map(|&b| b as char).collect();
    if text.len() > MAX_FRAME {
        return Err(ParseError::Overflow);
    }
    if text.len() < 5 || !text.is_char_boundary(5) {
        return Err(ParseError::Illegal(text));
    }
    let (name, data) = text.split_at(5);
    let format = || ParseError::Format {
        command: name.to_string(),
        data: data.to_string(),
    };
    let value = || ParseError::Value {
        command: name.to_string(),
        data: data.to_string(),
    };
    let no_data = |cmd: Command| {
        if data.is_empty() {
            Ok(cmd)
        } else {
            Err(format())
        }
    };
    match name {
        "CTSTA" => no_data(Command::Start),
        "CTSTP" => no_data(Command::Stop),
        "CTRTN" => no_data(Command::Return),
        "CTESP" => match data {
            "" | "0" | "1" => Ok(Command::Retract),
            _ => Err(format()),
        },
        "CTOFF" => two_digits(data).map(Command::Off).ok_or_else(format),
        "RDSTU" => match two_digits(data) {
            Some(0) => Ok(Command::Status),
            Some(1) => Ok(Command::Battery),
            Some(_) => Err(value()),
            None => Err(format()),
        },
        "RDSJ " => match two_digits(data) {
            Some(0) => Ok(Command::DriveType),
            Some(1) => Ok(Command::Firmware),
            Some(_) => Err(value()),
            None => Err(format()),
        },
        "RDPSA" => no_data(Command::Position),
        "RDCON" | "RDPAR" => {
            let ab = if data.is_empty() {
                None
            } else {
                Some(selector(data).ok_or_else(format)?)
            };
            Ok(if name == "RDCON" {
                Command::Conditions { ab }
            } else {
                Command::ParamCount { ab }
            })
        }
        "RDRES" => {
            let (ab, rest) = match data.len() {
                8 => (None, data),
                9 => split_selector(data).ok_or_else(format)?,
                _ => return Err(format()),
            };
            let mut parts = rest.split(',');
            let mut next = || parts.next().and_then(two_digits).ok_or_else(format);
            let (mode, param, index) = (next()?, next()?, next()?);
            if mode > 2 || param == 0 {
                return Err(value());
            }
            Ok(Command::Result {
                ab,
                mode,
                param,
                index,
            })
        }
        "RDEVA" => {
            let (ab, n) = match data.len() {
                2 => (None, data),
                3 => split_selector(data).ok_or_else(format)?,
                _ => return Err(format()),
            };
            match two_digits(n) {
                Some(0) => Ok(Command::ProfileTotal { ab }),
                Some(count @ 1..=50) => Ok(Command::ProfileBlock { ab, count }),
                Some(_) => Err(value()),
                None => Err(format()),
            }
        }
        _ => Err(ParseError::Illegal(text.clone())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitter_handles_partial_crlf_and_garbage() {
        let mut s = FrameSplitter::new();
        assert!(s.push(b"RDST").is_empty());
        assert_eq!(
            s.push(b"U00\r\nCTSTA\rRD"),
            vec![
                Frame::Line(b"RDSTU00".to_vec()),
                Frame::Line(b"CTSTA".to_vec())
            ]
        );
        assert_eq!(s.push(b"PSA\n"), vec![Frame::Line(b"RDPSA".to_vec())]);
        assert!(s.push(b"\r\r\n").is_empty());
        let long = vec![b'A'; MAX_FRAME + 10];
        assert!(s.push(&long).is_empty());
        assert_eq!(s.push(b"\r"), vec![Frame::Overflow]);
        assert_eq!(s.push(b"CTRTN\r"), vec![Frame::Line(b"CTRTN".to_vec())]);
    }

    #[test]
    fn parses_documented_commands() {
        assert_eq!(parse(b"CTSTA"), Ok(Command::Start));
        assert_eq!(parse(b"RDSTU00"), Ok(Command::Status));
        assert_eq!(parse(b"RDSTU01"), Ok(Command::Battery));
        assert_eq!(parse(b"RDSJ 01"), Ok(Command::Firmware));
        assert_eq!(parse(b"CTOFF01"), Ok(Command::Off(1)));
        assert_eq!(parse(b"RDCON"), Ok(Command::Conditions { ab: None }));
        assert_eq!(parse(b"RDPAR0"), Ok(Command::ParamCount { ab: Some(0) }));
        assert_eq!(
            parse(b"RDRES02,03,00"),
            Ok(Command::Result {
                ab: None,
                mode: 2,
                param: 3,
                index: 0
            })
        );
        assert_eq!(
            parse(b"RDRES102,01,04"),
            Ok(Command::Result {
                ab: Some(1),
                mode: 2,
                param: 1,
                index: 4
            })
        );
        assert_eq!(parse(b"RDEVA00"), Ok(Command::ProfileTotal { ab: None }));
        assert_eq!(
            parse(b"RDEVA150"),
            Ok(Command::ProfileBlock {
                ab: Some(1),
                count: 50
            })
        );
    }

    #[test]
    fn rejects_with_the_right_ng_codes() {
        assert_eq!(parse(b"XYZZY").map_err(|e| e.ng_code()), Err(30));
        assert_eq!(parse(b"RD").map_err(|e| e.ng_code()), Err(30));
        assert_eq!(parse(b"\xff\xfe\x00abc").map_err(|e| e.ng_code()), Err(30));
        assert_eq!(parse(b"CTSTAX").map_err(|e| e.ng_code()), Err(31));
        assert_eq!(parse(b"RDRES02,1,00").map_err(|e| e.ng_code()), Err(31));
        assert_eq!(parse(b"RDRES03,01,00").map_err(|e| e.ng_code()), Err(32));
        assert_eq!(parse(b"RDEVA51").map_err(|e| e.ng_code()), Err(32));
        assert_eq!(parse(b"RDSTU07").map_err(|e| e.ng_code()), Err(32));
        assert_eq!(parse(b"RDEVA2").map_err(|e| e.ng_code()), Err(31));
    }
}
