//! Fault injection: which frames get a faulty reply, parsed from `--fault SPEC` strings.
//!
//! Pure; depends on nothing else in the crate. Spec grammar: `KIND[:ARG]@COMMAND[%T][#N][xK]` —
//! the fault hits the N-th (1-based, default 1) and the following K−1 (default K = 1) frames
//! that start with `COMMAND`; with `%T`, only frames sent during trace T count (trace T begins
//! with the T-th `CTSTA` frame and lasts until the next one). Kinds:
//! * `ng:CODE` — answer `NGCODE` instead of the command (e.g. `ng:011@RDRES#1x3`,
//!   `ng:007@CTSTA#2`); the instrument does not see the command;
//! * `drop` — the instrument handles the command but the reply is lost;
//! * `truncate` — only the first half of the reply, no CR;
//! * `garbage` — non-ASCII bytes written before the reply;
//! * `split` — the reply is written in two writes with a short pause between;
//! * `silence:MS` — the reply comes after MS milliseconds of silence;
//! * `lf` — an extra LF after the reply's CR;
//! * `deaf:MS` — no reply, and for MS milliseconds the link takes none of the host's bytes
//!   (software flow control holds the host back, as CTS held low or a wedged adapter
//!   would): the host's writes stall; what it sent before is discarded;
//! * `unplug:MS` — the reply is sent, then the device vanishes (pty closed, link removed) and
//!   comes back after MS milliseconds as a freshly powered-up instrument (e.g.
//!   `unplug:2000@CTSTA#2`: vanishes mid-trace 2);
//! * `repeat` — an `RDEVA` block request is answered with the previous block again (the
//!   read-out cursor went back one block), e.g. `repeat@RDEVA50#3`;
//! * `skew:PCT` — an `RDRES` answer's value is off by PCT percent (signed), so the
//!   instrument's result disagrees with its own heights, e.g. `skew:20@RDRES02,01`;
//! * `scale:K` — the trace a `CTSTA` starts is served with its heights, and so its results,
//!   K times too large (heights in the wrong unit), e.g. `scale:1000@CTSTA#3`.
//!
//! Time windows: the matching frame opens a window of MS milliseconds (of the serve loop's
//! clock) during which the fault applies to every frame and to the idle line (no `xK`):
//! * `busy:MS` — every frame is answered `NG011` (busy); the instrument does not see it,
//!   e.g. `busy:15000@CTSTA#2`;
//! * `noeol:MS` — replies come without their line end, and between them the line carries
//!   printable bytes without a line end ([`NOEOL_FILLER`] every [`CHATTER_PERIOD`]);
//! * `flood:MS` — stray reply lines nobody asked for ([`STRAY_REPLIES`], in turn, one every
//!   [`CHATTER_PERIOD`]) besides the real replies.
//!
//! Battery states are instrument settings, also given as faults: `battery:low`,
//! `battery:abnormal`.

use std::time::Duration;

/// What happens to the reply of a matching frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FaultKind {
    /// Reply `NGcode` instead.
    Ng(u16),
    /// No reply.
    Drop,
    /// First half of the reply only.
    Truncate,
    /// Garbage bytes before the reply.
    Garbage,
    /// Reply in two writes.
    Split,
    /// Delay before the reply.
    Silence(Duration),
    /// An extra `\n` after the reply.
    ExtraLf,
    /// Reply, then unplug for the given time.
    Unplug(Duration),
    /// No reply, and the link takes no bytes for the given time.
    Deaf(Duration),
    /// An `RDEVA` block answered with the previous block again.
    RepeatBlock,
    /// An `RDRES` value off by this many percent.
    Skew(i32),
    /// The trace this `CTSTA` starts is served with every height (and so every result)
    /// multiplied by this factor: heights in the wrong unit (nm read as µm is 1000).
    Scale(u32),
    /// Opens a time window of this length (see [`Window`]).
    Window(Window, Duration),
}

/// What a time-window fault does while its window is open.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Window {
    /// Every frame is answered `NG011`.
    Busy,
    /// Replies lose their line end; filler bytes without a line end flow between them.
    NoLineEnd,
    /// Stray reply lines flow between the real replies.
    Flood,
}

/// How often a `noeol` or `flood` window writes its unsolicited bytes.
pub const CHATTER_PERIOD: Duration = Duration::from_millis(20);
/// What a `noeol` window writes every [`CHATTER_PERIOD`]: printable, no CR or LF.
pub const NOEOL_FILLER: &[u8] = b"0.000,  ";
/// The stray lines a `flood` window writes, in turn: well-formed replies to no command.
pub const STRAY_REPLIES: [&[u8]; 3] = [b"OK\r", b"NG030\r", b"NG011\r"];

/// What the serve loop does to one frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Verdict {
    /// The fault hitting this frame, if any ([`FaultKind::Window`] never appears here: an
    /// open `busy` window shows as `Ng(11)`).
    pub kind: Option<FaultKind>,
    /// Whether the reply loses its line end (a `noeol` window is open).
    pub strip_line_end: bool,
}

/// One fault rule.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fault {
    /// What to do.
    pub kind: FaultKind,
    /// Frames starting with this text are counted.
    pub command: String,
    /// First matching occurrence hit, 1-based.
    pub first: u32,
    /// Number of consecutive occurrences hit.
    pub count: u32,
    /// Only frames during this trace (1-based) count.
    pub trace: Option<u32>,
}

/// A parsed `--fault` argument: a wire fault or a battery state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FaultSpec {
    /// A rule applied to replies.
    Wire(Fault),
    /// `battery:low`.
    BatteryLow,
    /// `battery:abnormal`.
    BatteryAbnormal,
}

/// A fault spec that could not be parsed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("bad fault spec {spec:?}: {why}; expected KIND[:ARG]@COMMAND[%TRACE][#N][xK] (kinds ng:CODE, drop, truncate, garbage, split, lf, silence:MS, deaf:MS, unplug:MS, repeat, skew:PCT; windows busy:MS, noeol:MS, flood:MS without xK) or battery:low|abnormal")]
pub struct FaultSpecError {
    /// The spec as given.
    pub spec: String,
    /// What is wrong.
    pub why: String,
}

impl std::str::FromStr for FaultSpec {
    type Err = FaultSpecError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let err = |why: &str| FaultSpecError {
            spec: spec.to_string(),
            why: why.to_string(),
        };
        match spec {
            "battery:low" => return Ok(FaultSpec::BatteryLow),
            "battery:abnormal" => return Ok(FaultSpec::BatteryAbnormal),
            _ => {}
        }
        let (kind, target) = spec
            .split_once('@')
            .ok_or_else(|| err("missing '@COMMAND'"))?;
        let (name, arg) = match kind.split_once(':') {
            Some((n, a)) => (n, Some(a)),
            None => (kind, None),
        };
        let millis = |a: Option<&str>| -> Result<Duration, FaultSpecError> {
            a.and_then(|a| a.parse::<u64>().ok())
                .map(Duration::from_millis)
                .ok_or_else(|| err("this kind needs a duration in milliseconds, e.g. silence:2000"))
        };
        let kind = match name {
            "ng" => {
                let code = arg
                    .filter(|a| a.len() == 3)
                    .and_then(|a| a.parse::<u16>().ok())
                    .ok_or_else(|| err("ng needs a 3-digit code, e.g. ng:011"))?;
                FaultKind::Ng(code)
            }
            "drop" => FaultKind::Drop,
            "truncate" => FaultKind::Truncate,
            "garbage" => FaultKind::Garbage,
            "split" => FaultKind::Split,
            "silence" => FaultKind::Silence(millis(arg)?),
            "lf" => FaultKind::ExtraLf,
            "unplug" => FaultKind::Unplug(millis(arg)?),
            "deaf" => FaultKind::Deaf(millis(arg)?),
            "repeat" => FaultKind::RepeatBlock,
            "skew" => FaultKind::Skew(
                arg.and_then(|a| a.parse::<i32>().ok())
                    .filter(|p| (-99..=1000).contains(p))
                    .ok_or_else(|| err("skew needs a percentage from -99 to 1000, e.g. skew:20"))?,
            ),
            "scale" => FaultKind::Scale(
                arg.and_then(|a| a.parse::<u32>().ok())
                    .filter(|k| (1..=1_000_000).contains(k))
                    .ok_or_else(|| {
                        err("scale needs a factor from 1 to 1000000, e.g. scale:1000")
                    })?,
            ),
            "busy" => FaultKind::Window(Window::Busy, millis(arg)?),
            "noeol" => FaultKind::Window(Window::NoLineEnd, millis(arg)?),
            "flood" => FaultKind::Window(Window::Flood, millis(arg)?),
            _ => return Err(err("unknown kind")),
        };
        let (rest, count) = match target.rsplit_once('x') {
            Some((r, k)) if !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()) => {
                (r, k.parse::<u32>().map_err(|_| err("bad count after 'x'"))?)
            }
            _ => (target, 1),
        };
        let (rest, first) = match rest.rsplit_once('#') {
            Some((c, n)) => (
                c,
                n.parse::<u32>()
                    .map_err(|_| err("bad occurrence after '#'"))?,
            ),
            None => (rest, 1),
        };
        let (command, trace) = match rest.rsplit_once('%') {
            Some((c, t)) => (
                c,
                Some(
                    t.parse::<u32>()
                        .map_err(|_| err("bad trace number after '%'"))?,
                ),
            ),
            None => (rest, None),
        };
        if command.is_empty() || first == 0 || count == 0 || trace == Some(0) {
            return Err(err(
                "command must be non-empty; trace, occurrence and count at least 1",
            ));
        }
        if matches!(kind, FaultKind::Window(..)) && count != 1 {
            return Err(err(
                "a time window is opened by one frame: no count 'xK' (make the window longer)",
            ));
        }
        Ok(FaultSpec::Wire(Fault {
            kind,
            command: command.to_string(),
            first,
            count,
            trace,
        }))
    }
}

/// The rules of one run with their occurrence counters and open time windows.
#[derive(Debug, Clone, Default)]
pub struct FaultPlan {
    rules: Vec<(Fault, u32)>,
    traces: u32,
    /// Open windows: what, and until when (on the caller's clock).
    windows: Vec<(Window, Duration)>,
    /// Stray lines written so far (selects the next of [`STRAY_REPLIES`]).
    strays: usize,
}

impl FaultPlan {
    /// A plan from rules.
    pub fn new(rules: Vec<Fault>) -> Self {
        Self {
            rules: rules.into_iter().map(|f| (f, 0)).collect(),
            traces: 0,
            windows: Vec::new(),
            strays: 0,
        }
    }

    /// Counts `frame` (received at `now` on the serve loop's clock) against every rule, opens
    /// the window of a window fault it hits, and says what happens to it: an open `busy`
    /// window answers `NG011` before any other fault; otherwise the first rule that hits.
    pub fn check_at(&mut self, frame: &str, now: Duration) -> Verdict {
        let hit = self.check(frame);
        if let Some(FaultKind::Window(w, d)) = hit {
            self.windows.push((w, now.saturating_add(d)));
        }
        let hit = hit.filter(|k| !matches!(k, FaultKind::Window(..)));
        let kind = if self.window_open(Window::Busy, now) {
            Some(FaultKind::Ng(11))
        } else {
            hit
        };
        Verdict {
            kind,
            strip_line_end: self.window_open(Window::NoLineEnd, now),
        }
    }

    /// Whether a window of this kind is open at `now` (it closes at its end, exclusive).
    pub fn window_open(&self, w: Window, now: Duration) -> bool {
        self.windows.iter().any(|&(k, until)| k == w && now < until)
    }

    /// Whether unsolicited bytes flow at `now` (a `noeol` or `flood` window is open).
    pub fn chattering(&self, now: Duration) -> bool {
        self.window_open(Window::NoLineEnd, now) || self.window_open(Window::Flood, now)
    }

    /// The unsolicited bytes of one [`CHATTER_PERIOD`] at `now`: the next stray line of an
    /// open `flood` window and the filler of an open `noeol` window (a stray line loses its
    /// line end too while both are open); empty when neither is open.
    pub fn chatter(&mut self, now: Duration) -> Vec<u8> {
        let mut out = Vec::new();
        if self.window_open(Window::Flood, now) {
            let stray = STRAY_REPLIES
                .get(self.strays % STRAY_REPLIES.len())
                .copied()
                .unwrap_or_default();
            self.strays = self.strays.wrapping_add(1);
            out.extend_from_slice(stray);
        }
        if self.window_open(Window::NoLineEnd, now) {
            out.retain(|&b| b != b'\r' && b != b'\n');
            out.extend_from_slice(NOEOL_FILLER);
        }
        out
    }

    /// Counts `frame` against every rule and returns the first fault that hits it.
    pub fn check(&mut self, frame: &str) -> Option<FaultKind> {
        if frame.starts_with("CTSTA") {
            self.traces = self.traces.saturating_add(1);
        }
        let mut hit = None;
        for (rule, seen) in &mut self.rules {
            let in_trace = rule.trace.is_none_or(|t| t == self.traces);
            if in_trace && frame.starts_with(rule.command.as_str()) {
                *seen += 1;
                let last = rule.first.saturating_add(rule.count);
                if hit.is_none() && *seen >= rule.first && *seen < last {
                    hit = Some(rule.kind.clone());
                }
            }
        }
        hit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wire(s: &str) -> Fault {
        match s.parse::<FaultSpec>() {
            Ok(FaultSpec::Wire(f)) => f,
            other => panic!("{s}: {other:?}"),
        }
    }

    #[test]
    fn parses_specs() {
        let f = wire("ng:011@RDRES#2x3");
        assert_eq!(
            (f.kind, f.command.as_str(), f.first, f.count),
            (FaultKind::Ng(11), "RDRES", 2, 3)
        );
        assert_eq!(wire("drop@RDSJ 01").command, "RDSJ 01");
        assert_eq!(
            wire("unplug:1500@CTSTA#2").kind,
            FaultKind::Unplug(Duration::from_millis(1500))
        );
        assert_eq!("battery:low".parse(), Ok(FaultSpec::BatteryLow));
        assert!("ng:11@RDRES".parse::<FaultSpec>().is_err());
        assert!("silence@RDRES".parse::<FaultSpec>().is_err());
        assert!("boom@RDRES".parse::<FaultSpec>().is_err());
        assert!("drop".parse::<FaultSpec>().is_err());
        assert!("drop@RDRES#0".parse::<FaultSpec>().is_err());
        assert_eq!(wire("repeat@RDEVA50#3").kind, FaultKind::RepeatBlock);
        assert_eq!(wire("skew:-30@RDRES02,01").kind, FaultKind::Skew(-30));
        assert_eq!(wire("scale:1000@CTSTA#3").kind, FaultKind::Scale(1000));
        assert!("skew@RDRES".parse::<FaultSpec>().is_err());
        assert!("skew:-100@RDRES".parse::<FaultSpec>().is_err());
    }

    #[test]
    fn trace_filter_counts_only_within_that_trace() {
        let f = wire("ng:101@RDRES%2#2x2");
        assert_eq!((f.trace, f.first, f.count), (Some(2), 2, 2));
        assert!("drop@RDRES%0".parse::<FaultSpec>().is_err());
        let mut p = FaultPlan::new(vec![f, wire("lf@RDSTU00%1")]);
        assert_eq!(p.check("RDRES02,01,00"), None);
        assert_eq!(p.check("CTSTA"), None);
        assert_eq!(p.check("RDSTU00"), Some(FaultKind::ExtraLf));
        assert_eq!(p.check("RDRES02,01,00"), None);
        assert_eq!(p.check("RDRES02,02,00"), None);
        assert_eq!(p.check("CTSTA"), None);
        assert_eq!(p.check("RDSTU00"), None);
        assert_eq!(p.check("RDRES02,01,00"), None);
        assert_eq!(p.check("RDRES02,02,00"), Some(FaultKind::Ng(101)));
        assert_eq!(p.check("RDRES02,03,00"), Some(FaultKind::Ng(101)));
        assert_eq!(p.check("RDRES02,01,00"), None);
        assert_eq!(p.check("CTSTA"), None);
        assert_eq!(p.check("RDRES02,02,00"), None);
    }

    #[test]
    fn window_specs_parse_and_refuse_a_count() {
        assert_eq!(
            wire("busy:15000@CTSTA#2").kind,
            FaultKind::Window(Window::Busy, Duration::from_secs(15))
        );
        assert_eq!(
            wire("noeol:500@RDEVA%3").kind,
            FaultKind::Window(Window::NoLineEnd, Duration::from_millis(500))
        );
        assert_eq!(
            wire("flood:30000@RDSTU").kind,
            FaultKind::Window(Window::Flood, Duration::from_secs(30))
        );
        assert!("busy@CTSTA".parse::<FaultSpec>().is_err());
        assert!("flood:100@CTSTAx2".parse::<FaultSpec>().is_err());
    }

    #[test]
    fn a_busy_window_answers_ng011_to_every_frame_until_it_closes() {
        let ms = Duration::from_millis;
        let mut p = FaultPlan::new(vec![wire("busy:1000@CTSTA#2"), wire("drop@RDRES#1")]);
        let v = |k: Option<FaultKind>| Verdict {
            kind: k,
            strip_line_end: false,
        };
        assert_eq!(p.check_at("CTSTA", ms(0)), v(None));
        assert_eq!(p.check_at("RDSTU00", ms(100)), v(None));
        // The second CTSTA opens the window and is itself refused.
        assert_eq!(p.check_at("CTSTA", ms(200)), v(Some(FaultKind::Ng(11))));
        assert_eq!(p.check_at("RDSTU00", ms(700)), v(Some(FaultKind::Ng(11))));
        // Busy wins over another rule hitting the same frame.
        assert_eq!(
            p.check_at("RDRES02,01", ms(1199)),
            v(Some(FaultKind::Ng(11)))
        );
        assert!(!p.chattering(ms(500)));
        // Closed at 200 + 1000 ms.
        assert_eq!(p.check_at("CTSTA", ms(1200)), v(None));
        assert!(!p.window_open(Window::Busy, ms(1200)));
    }

    #[test]
    fn noeol_and_flood_windows_strip_line_ends_and_chatter() {
        let ms = Duration::from_millis;
        let mut p = FaultPlan::new(vec![wire("noeol:100@RDSTU#1"), wire("flood:300@RDRES")]);
        assert!(p.chatter(ms(0)).is_empty());
        let v = p.check_at("RDSTU00", ms(10));
        assert!(v.strip_line_end && v.kind.is_none());
        assert_eq!(p.chatter(ms(20)), NOEOL_FILLER);
        assert!(p.check_at("RDRES02,01", ms(50)).strip_line_end);
        // Both open: the stray line loses its CR, the filler follows.
        assert_eq!(p.chatter(ms(60)), b"OK0.000,  ".to_vec());
        // noeol closed at 110: stray lines in turn, with their CR.
        assert!(!p.check_at("RDSTU00", ms(110)).strip_line_end);
        assert_eq!(p.chatter(ms(120)), b"NG030\r".to_vec());
        assert_eq!(p.chatter(ms(140)), b"NG011\r".to_vec());
        assert_eq!(p.chatter(ms(160)), b"OK\r".to_vec());
        assert!(p.chattering(ms(349)));
        assert!(!p.chattering(ms(350)));
        assert!(p.chatter(ms(350)).is_empty());
    }

    #[test]
    fn plan_hits_the_chosen_occurrences_only() {
        let mut p = FaultPlan::new(vec![wire("ng:033@RDRES#2x2"), wire("drop@RDSTU00")]);
        assert_eq!(p.check("RDRES02,01,00"), None);
        assert_eq!(p.check("RDSTU00"), Some(FaultKind::Drop));
        assert_eq!(p.check("RDRES02,02,00"), Some(FaultKind::Ng(33)));
        assert_eq!(p.check("RDSTU00"), None);
        assert_eq!(p.check("RDRES02,03,00"), Some(FaultKind::Ng(33)));
        assert_eq!(p.check("RDRES02,01,00"), None);
    }
}
