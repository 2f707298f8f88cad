//! Replay of recorded transcripts (format v1, written by the daemon's recorder):
//!
//! ```text
//! # surfscan transcript v1
//! # instrument: …            (header lines `# key: value`)
//! <seconds since start, 6 decimals> <dir> <escaped bytes>
//! ```
//! `>` is host→device, `<` device→host. Escaping: printable ASCII except `\` as is, `\\`, `\r`,
//! `\n`, `\t`, others `\xHH`.
//!
//! Replay rule: each command is answered by the next recorded reply to the same command string
//! (a recorded command without a reply stays unanswered); when a command's recorded replies are
//! used up, its last reply is repeated. Status polls (`RDSTU00`) after a `CTSTA` follow the
//! recorded time since that `CTSTA`: the reply is the last one recorded at or before the same
//! (time-scaled) delay in the corresponding recorded trace. Depends on std only.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

/// Direction of a transcript line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// `>` host → device.
    ToDevice,
    /// `<` device → host.
    ToHost,
}

/// One recorded line.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// Seconds since the start of the recording.
    pub t_s: f64,
    /// Direction.
    pub dir: Dir,
    /// The bytes.
    pub bytes: Vec<u8>,
}

/// A parsed transcript.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Transcript {
    /// Header `key: value` pairs in order.
    pub header: Vec<(String, String)>,
    /// The recorded lines.
    pub entries: Vec<Entry>,
}

/// Errors reading a transcript; each names the line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ReplayError {
    /// The first line is not `# surfscan transcript v1`.
    #[error(
        "line 1 is {0:?}, expected \"# surfscan transcript v1\"; is this a surfscan transcript?"
    )]
    Magic(String),
    /// A data line is not `<time> <dir> <bytes>`.
    #[error("line {line}: {why}: {text:?}")]
    Line {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        why: &'static str,
        /// The line.
        text: String,
    },
}

/// Escapes bytes for a transcript line.
pub fn escape(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len());
    for &b in bytes {
        match b {
            b'\\' => s.push_str("\\\\"),
            b'\r' => s.push_str("\\r"),
            b'\n' => s.push_str("\\n"),
            b'\t' => s.push_str("\\t"),
            0x20..=0x7e => s.push(b as char),
            _ => s.push_str(&format!("\\x{b:02X}")),
        }
    }
    s
}

/// Reverses [`escape`]; `None` on a malformed escape.
pub fn unescape(s: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len());
    let mut it = s.bytes();
    while let Some(b) = it.next() {
        if b != b'\\' {
            out.push(b);
            continue;
        }
        match it.next()? {
            b'\\' => out.push(b'\\'),
            b'r' => out.push(b'\r'),
            b'n' => out.push(b'\n'),
            b't' => out.push(b'\t'),
            b'x' => {
                let hi = (it.next()? as char).to_digit(16)?;
                let lo = (it.next()? as char).to_digit(16)?;
                out.push((hi * 16 + lo) as u8);
            }
            _ => return None,
        }
    }
    Some(out)
}

impl Transcript {
    /// Parses transcript text.
    pub fn parse(text: &str) -> Result<Self, ReplayError> {
        let mut lines = text.lines().enumerate();
        match lines.next() {
            Some((_, l)) if l.trim_end() == "# surfscan transcript v1" => {}
            Some((_, l)) => return Err(ReplayError::Magic(l.to_string())),
            None => return Err(ReplayError::Magic(String::new())),
        }
        let mut t = Transcript::default();
        for (i, l) in lines {
            let line = i + 1;
            if l.trim().is_empty() {
                continue;
            }
            if let Some(h) = l.strip_prefix('#') {
                if let Some((k, v)) = h.split_once(':') {
                    t.header.push((k.trim().to_string(), v.trim().to_string()));
                }
                continue;
            }
            let bad = |why| ReplayError::Line {
                line,
                why,
                text: l.to_string(),
            };
            let mut parts = l.splitn(3, ' ');
            let t_s = parts
                .next()
                .and_then(|x| x.parse::<f64>().ok())
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad("time is not a number"))?;
            let dir = match parts.next() {
                Some(">") => Dir::ToDevice,
                Some("<") => Dir::ToHost,
                _ => return Err(bad("direction must be '>' or '<'")),
            };
            let bytes = unescape(parts.next().unwrap_or("")).ok_or_else(|| bad("bad escape"))?;
            t.entries.push(Entry { t_s, dir, bytes });
        }
        Ok(t)
    }
}

fn key(bytes: &[u8]) -> String {
    let s: String = bytes.iter().map(|&b| b as char).collect();
    s.trim_end_matches(['\r', '\n']).to_string()
}

/// Answers commands from a transcript.
#[derive(Debug, Clone)]
pub struct Replay {
    queues: HashMap<String, VecDeque<Option<Vec<u8>>>>,
    last: HashMap<String, Option<Vec<u8>>>,
    /// Per recorded trace: (seconds since CTSTA, status reply).
    polls: Vec<Vec<(f64, Vec<u8>)>>,
    trace: Option<(usize, Duration)>,
    traces_started: usize,
    time_scale: f64,
}

const STATUS: &str = "RDSTU00";
const START: &str = "CTSTA";

impl Replay {
    /// Builds a replayer; `time_scale` multiplies recorded delays (as for the emulator).
    pub fn new(t: &Transcript, time_scale: f64) -> Self {
        let mut queues: HashMap<String, VecDeque<Option<Vec<u8>>>> = HashMap::new();
        let mut polls: Vec<Vec<(f64, Vec<u8>)>> = Vec::new();
        let mut t_start: Option<f64> = None;
        let mut it = t.entries.iter().peekable();
        while let Some(e) = it.next() {
            if e.dir != Dir::ToDevice {
                continue;
            }
            let k = key(&e.bytes);
            let reply = match it.peek() {
                Some(r) if r.dir == Dir::ToHost => it.next().map(|r| r.bytes.clone()),
                _ => None,
            };
            if k == START {
                polls.push(Vec::new());
                t_start = Some(e.t_s);
            }
            match (k.as_str(), t_start, reply.as_ref(), polls.last_mut()) {
                (STATUS, Some(t0), Some(r), Some(p)) => p.push((e.t_s - t0, r.clone())),
                _ => queues.entry(k).or_default().push_back(reply),
            }
        }
        Self {
            queues,
            last: HashMap::new(),
            polls,
            trace: None,
            traces_started: 0,
            time_scale,
        }
    }

    /// The reply to `frame` at `now`, or `None` when the recording has none.
    pub fn respond(&mut self, frame: &[u8], now: Duration) -> Option<Vec<u8>> {
        let k = key(frame);
        if k == STATUS {
            if let Some((i, t0)) = self.trace {
                let polls = self.polls.get(i).or(self.polls.last())?;
                let dt = now.saturating_sub(t0).as_secs_f64();
                let scale = if self.time_scale > 0.0 {
                    self.time_scale
                } else {
                    1e-9
                };
                return polls
                    .iter()
                    .take_while(|(t, _)| t * scale <= dt)
                    .last()
                    .or(polls.first())
                    .map(|(_, r)| r.clone());
            }
        }
        if k == START {
            self.trace = Some((self.traces_started, now));
            self.traces_started += 1;
        }
        let reply = match self.queues.get_mut(&k).and_then(|q| q.pop_front()) {
            Some(r) => {
                self.last.insert(k, r.clone());
                r
            }
            None => self.last.get(&k).cloned().flatten(),
        };
        reply
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_round_trip_and_pinned_forms() {
        let raw = b"OKRa \\ 3.1\r\n\t\xb5\x00";
        let e = escape(raw);
        assert_eq!(e, "OKRa \\\\ 3.1\\r\\n\\t\\xB5\\x00");
        assert_eq!(unescape(&e).as_deref(), Some(&raw[..]));
        assert_eq!(unescape("a\\x4").as_deref(), None);
        assert_eq!(unescape("\\q"), None);
    }

    const T: &str = "# surfscan transcript v1\n# instrument: SJ-210\n# firmware: V1.00\n\
0.000000 > RDSTU00\\r\n0.010000 < OK000\\r\n\
0.100000 > CTSTA\\r\n0.110000 < OK\\r\n\
0.500000 > RDSTU00\\r\n0.510000 < OK001\\r\n\
5.000000 > RDSTU00\\r\n5.010000 < OK002\\r\n\
7.000000 > RDSTU00\\r\n7.010000 < OK000\\r\n\
7.100000 > RDRES02,01,00\\r\n7.110000 < NG033\\r\n\
7.200000 > RDRES02,01,00\\r\n7.210000 < OKRa      3.123 um\\r\n\
8.000000 > RDPSA\\r\n";

    #[test]
    fn parses_header_and_entries() {
        let t = Transcript::parse(T).unwrap();
        assert_eq!(
            t.header[0],
            ("instrument".to_string(), "SJ-210".to_string())
        );
        assert_eq!(t.entries.len(), 15);
        assert_eq!(t.entries[3].bytes, b"OK\r");
        assert!(Transcript::parse("hello\n").is_err());
        assert!(matches!(
            Transcript::parse("# surfscan transcript v1\n1.0 ? X\n"),
            Err(ReplayError::Line { line: 2, .. })
        ));
    }

    #[test]
    fn replays_in_order_and_by_time_since_ctsta() {
        let t = Transcript::parse(T).unwrap();
        let mut r = Replay::new(&t, 1.0);
        let at = |s: f64| Duration::from_secs_f64(s);
        assert_eq!(r.respond(b"RDSTU00", at(0.0)).unwrap(), b"OK000\r");
        assert_eq!(r.respond(b"CTSTA", at(10.0)).unwrap(), b"OK\r");
        // Recorded: 001 from 0.4 s after CTSTA, 002 from 4.9 s, 000 from 6.9 s.
        assert_eq!(r.respond(b"RDSTU00", at(10.1)).unwrap(), b"OK001\r");
        assert_eq!(r.respond(b"RDSTU00", at(14.0)).unwrap(), b"OK001\r");
        assert_eq!(r.respond(b"RDSTU00", at(14.95)).unwrap(), b"OK002\r");
        assert_eq!(r.respond(b"RDSTU00", at(17.0)).unwrap(), b"OK000\r");
        assert_eq!(r.respond(b"RDRES02,01,00", at(17.1)).unwrap(), b"NG033\r");
        assert_eq!(
            r.respond(b"RDRES02,01,00", at(17.2)).unwrap(),
            b"OKRa      3.123 um\r"
        );
        // Used up: the last reply repeats.
        assert_eq!(
            r.respond(b"RDRES02,01,00", at(17.3)).unwrap(),
            b"OKRa      3.123 um\r"
        );
        // Recorded without a reply; never recorded at all.
        assert_eq!(r.respond(b"RDPSA", at(18.0)), None);
        assert_eq!(r.respond(b"RDCON", at(18.0)), None);
    }
}
