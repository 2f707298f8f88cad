//! Finding the link settings the instrument is set to when the configured ones get no
//! answer: which baud rate and parity to try in which order, what one attempt found, the
//! verdict, the `[instrument]` lines to paste, and how long a profile read-out takes on the
//! wire at each rate (the reason to set the fastest one).
//!
//! The instrument's baud rate and parity are set on the instrument itself (its RS-232C
//! communication setting, M1 p.17-12) and nothing on the link announces them: a host at
//! another rate or parity gets silence or line noise. `surfscan probe` asks the read-only
//! status command at each candidate in turn; this module decides the order and reads the
//! outcome.
//!
//! Pure (layer 1): depends on [`crate::transport`]'s link vocabulary, [`super::error`] and
//! [`super::client`]'s block size; no I/O.

use super::error::{LinkError, Sj210Error};
use crate::transport::Parity;
use std::fmt;

/// One combination of the link settings the instrument lets its user choose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LineSetting {
    /// Baud rate.
    pub baud: u32,
    /// Parity (8 data bits and 1 stop bit are fixed on the SJ-210 family).
    pub parity: Parity,
}

impl fmt::Display for LineSetting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} baud, parity {}", self.baud, parity_name(self.parity))
    }
}

/// The parity as the configuration spells it.
pub fn parity_name(p: Parity) -> &'static str {
    match p {
        Parity::None => "none",
        Parity::Even => "even",
        Parity::Odd => "odd",
    }
}

/// The order to try: the configured setting, then the model's other rates at the configured
/// parity (fastest first: the setting a lab most likely chose for read-out), then every rate
/// at the other parities. Each combination once.
pub fn candidates(configured: LineSetting, rates: &[u32]) -> Vec<LineSetting> {
    let mut rates: Vec<u32> = rates.to_vec();
    rates.sort_unstable_by(|a, b| b.cmp(a));
    rates.dedup();
    let parities = std::iter::once(configured.parity).chain(
        [Parity::None, Parity::Even, Parity::Odd]
            .into_iter()
            .filter(|p| *p != configured.parity),
    );
    let mut out = vec![configured];
    for parity in parities {
        for &baud in &rates {
            let s = LineSetting { baud, parity };
            if !out.contains(&s) {
                out.push(s);
            }
        }
    }
    out
}

/// What one attempt at one setting found.
#[derive(Debug, Clone, PartialEq)]
pub enum Attempt {
    /// A well-formed reply came back (`OK…` or `NG…`): the instrument is set to this.
    Answered {
        /// The status code, when the reply was an `OK` with one.
        status: Option<u16>,
    },
    /// Silence, a reply cut off, or bytes that are not a reply.
    NoAnswer {
        /// What the link did instead, for the operator.
        why: String,
    },
}

/// What the status question at one setting found: `Err` with the error when the port itself
/// went away (the search cannot go on), otherwise the attempt. Any well-formed reply is an
/// answer, an `NG` too: the instrument understood the characters, so the rate and parity are
/// right. Silence, a cut-off reply and line noise are not.
pub fn attempt_of(status: Result<u16, Sj210Error>) -> Result<Attempt, Sj210Error> {
    match status {
        Ok(code) => Ok(Attempt::Answered { status: Some(code) }),
        Err(Sj210Error::Device { .. } | Sj210Error::UnexpectedReply { .. }) => {
            Ok(Attempt::Answered { status: None })
        }
        Err(
            e @ Sj210Error::Link {
                source: LinkError::Vanished { .. } | LinkError::Encode(_),
                ..
            },
        ) => Err(e),
        Err(Sj210Error::Link { source, .. }) => Ok(Attempt::NoAnswer {
            why: source.to_string(),
        }),
        Err(e) => Ok(Attempt::NoAnswer { why: e.to_string() }),
    }
}

/// The attempts made so far, in order.
#[derive(Debug, Clone, PartialEq)]
pub struct RateSearch {
    /// The setting in the configuration.
    pub configured: LineSetting,
    /// Each setting tried and what it found.
    pub attempts: Vec<(LineSetting, Attempt)>,
}

impl RateSearch {
    /// A search that has tried nothing yet.
    pub fn new(configured: LineSetting) -> RateSearch {
        RateSearch {
            configured,
            attempts: Vec::new(),
        }
    }

    /// Records one attempt.
    pub fn record(&mut self, setting: LineSetting, attempt: Attempt) {
        self.attempts.push((setting, attempt));
    }

    /// The setting that answered, if any.
    pub fn found(&self) -> Option<LineSetting> {
        self.attempts
            .iter()
            .find(|(_, a)| matches!(a, Attempt::Answered { .. }))
            .map(|(s, _)| *s)
    }

    /// Whether the search is over: something answered.
    pub fn done(&self) -> bool {
        self.found().is_some()
    }

    /// The lines to paste into `[instrument]` when the instrument answers at another setting
    /// than the configured one (`None` when the configured one answers or nothing did).
    pub fn snippet(&self) -> Option<String> {
        let found = self.found()?;
        if found == self.configured {
            return None;
        }
        let mut s = String::new();
        if found.baud != self.configured.baud {
            s.push_str(&format!("baud = {}\n", found.baud));
        }
        if found.parity != self.configured.parity {
            s.push_str(&format!("parity = \"{}\"\n", parity_name(found.parity)));
        }
        Some(s)
    }

    /// What to check when no setting answered.
    pub fn guidance(&self) -> Option<String> {
        if self.done() {
            return None;
        }
        Some(format!(
            "the instrument answered at none of the {} settings tried. Check that it is switched on and \
             not asleep, that the cable is a straight RS-232C cable (or the instrument's USB cable) on \
             the configured port, and its RS-232C communication setting (baud rate, parity); then run \
             the probe again",
            self.attempts.len()
        ))
    }
}

/// Bytes on the wire, both directions, for the read-out of `points` heights the way the
/// client asks for them: the total (`RDEVA00` CR → `OK` + 5 digits + CR), then one block
/// command per 50 heights (`RDEVAnn` CR → `OKnn` + `,` and 9 characters per height + CR).
pub fn readout_wire_bytes(points: u32) -> u64 {
    let block = u64::from(super::client::MAX_BLOCK);
    let mut bytes = 8 + 8;
    let mut left = u64::from(points);
    while left > 0 {
        let k = left.min(block);
        bytes += 8 + 4 + 10 * k + 1;
        left -= k;
    }
    bytes
}

/// Seconds the read-out of `points` heights needs on the wire at `baud` (10 bits a byte:
/// start, 8 data, stop; a parity bit adds one more).
pub fn readout_wire_s(points: u32, setting: LineSetting) -> f64 {
    let bits = if setting.parity == Parity::None {
        10.0
    } else {
        11.0
    };
    readout_wire_bytes(points) as f64 * bits / f64::from(setting.baud.max(1))
}

/// A note when the link runs slower than the model's fastest rate: what the read-out of a
/// typical profile costs at this rate and at the fastest, so the operator knows what setting
/// the instrument (and the config) to the fastest rate saves on every line.
pub fn slower_than_fastest(setting: LineSetting, rates: &[u32], points: u32) -> Option<String> {
    let fastest = rates.iter().copied().max()?;
    if setting.baud >= fastest {
        return None;
    }
    let at = |baud| {
        readout_wire_s(
            points,
            LineSetting {
                baud,
                parity: setting.parity,
            },
        )
    };
    Some(format!(
        "the link runs at {} baud; the instrument also offers {fastest}: a {points}-point profile \
         takes {:.1} s on the wire at {} and {:.1} s at {fastest}, on every line. Set the instrument's \
         RS-232C baud rate to {fastest} and `baud = {fastest}` in [instrument]",
        setting.baud,
        at(setting.baud),
        setting.baud,
        at(fastest)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ls(baud: u32, parity: Parity) -> LineSetting {
        LineSetting { baud, parity }
    }

    #[test]
    fn the_configured_setting_comes_first_then_the_fastest_rates_then_other_parities() {
        let c = candidates(ls(9600, Parity::None), &[9600, 19200, 38400]);
        assert_eq!(
            c[..3],
            [
                ls(9600, Parity::None),
                ls(38400, Parity::None),
                ls(19200, Parity::None)
            ]
        );
        // 3 rates × 3 parities, each once.
        assert_eq!(c.len(), 9);
        assert_eq!(c[3], ls(38400, Parity::Even));
        assert_eq!(c[8], ls(9600, Parity::Odd));
        for (i, a) in c.iter().enumerate() {
            assert!(!c[i + 1..].contains(a), "{a} twice");
        }
        // A configured rate the model does not offer is still tried first, once.
        let c = candidates(ls(57600, Parity::Even), &[9600, 19200, 38400]);
        assert_eq!(c[0], ls(57600, Parity::Even));
        assert_eq!(c[1], ls(38400, Parity::Even));
        assert_eq!(c.len(), 10);
    }

    #[test]
    fn the_snippet_names_only_what_differs_from_the_configuration() {
        let mut s = RateSearch::new(ls(9600, Parity::None));
        s.record(
            ls(9600, Parity::None),
            Attempt::NoAnswer {
                why: "no reply within 2000 ms".into(),
            },
        );
        assert_eq!(s.found(), None);
        assert!(s.snippet().is_none());
        assert!(s.guidance().unwrap().contains("none of the 1 settings"));
        s.record(
            ls(38400, Parity::None),
            Attempt::Answered { status: Some(0) },
        );
        assert_eq!(s.found(), Some(ls(38400, Parity::None)));
        assert_eq!(s.snippet().as_deref(), Some("baud = 38400\n"));
        assert!(s.guidance().is_none());

        let mut p = RateSearch::new(ls(38400, Parity::None));
        p.record(ls(38400, Parity::Even), Attempt::Answered { status: None });
        assert_eq!(p.snippet().as_deref(), Some("parity = \"even\"\n"));

        let mut same = RateSearch::new(ls(38400, Parity::None));
        same.record(
            ls(38400, Parity::None),
            Attempt::Answered { status: Some(0) },
        );
        assert!(same.snippet().is_none(), "the configuration is right");
    }

    #[test]
    fn any_well_formed_reply_is_an_answer_silence_and_noise_are_not() {
        use crate::sj210::ng::NgCode;
        assert_eq!(
            attempt_of(Ok(5)).unwrap(),
            Attempt::Answered { status: Some(5) }
        );
        let ng = Sj210Error::Device {
            command: "RDSTU00".into(),
            code: NgCode::from_code(30),
            byte_pos: None,
            meaning: "illegal command",
        };
        assert_eq!(
            attempt_of(Err(ng)).unwrap(),
            Attempt::Answered { status: None }
        );
        let link = |source| Sj210Error::Link {
            command: "RDSTU00".into(),
            source,
        };
        let silent = attempt_of(Err(link(LinkError::FirstByteTimeout { waited_ms: 2000 })));
        assert!(
            matches!(&silent, Ok(Attempt::NoAnswer { why }) if why.contains("2000")),
            "{silent:?}"
        );
        let noise = attempt_of(Err(link(LinkError::InterByteTimeout {
            partial: "\\xf2\\xd3".into(),
            waited_ms: 200,
        })));
        assert!(matches!(noise, Ok(Attempt::NoAnswer { .. })), "{noise:?}");
        let garbled = attempt_of(Err(link(LinkError::Malformed { raw: "x".into() })));
        assert!(matches!(garbled, Ok(Attempt::NoAnswer { .. })));
        // The port went away: the search stops with the error.
        let gone = attempt_of(Err(link(LinkError::Vanished {
            detail: "EIO".into(),
        })));
        assert!(gone.is_err());
    }

    #[test]
    fn wire_time_of_an_8000_point_read_out_at_each_rate() {
        // 16 bytes for the total, then 160 blocks of 8 + 4 + 500 + 1 bytes.
        assert_eq!(readout_wire_bytes(8000), 16 + 160 * 513);
        // A last short block: 8 + 4 + 10 × 20 + 1.
        assert_eq!(readout_wire_bytes(120), 16 + 2 * 513 + 213);
        assert_eq!(readout_wire_bytes(0), 16);
        let s96 = readout_wire_s(8000, ls(9600, Parity::None));
        let s384 = readout_wire_s(8000, ls(38400, Parity::None));
        assert!((s96 - 82_096.0 * 10.0 / 9600.0).abs() < 1e-9, "{s96}");
        assert!((s96 - 85.5).abs() < 0.05, "{s96}");
        assert!((s384 - 21.4).abs() < 0.05, "{s384}");
        // A parity bit makes every character 11 bits.
        let even = readout_wire_s(8000, ls(38400, Parity::Even));
        assert!((even / s384 - 1.1).abs() < 1e-12);
    }

    #[test]
    fn a_link_below_the_fastest_rate_is_told_what_it_costs() {
        let rates = [9600, 19200, 38400];
        let n = slower_than_fastest(ls(9600, Parity::None), &rates, 8000).unwrap();
        assert!(n.contains("85.5 s on the wire at 9600"), "{n}");
        assert!(n.contains("21.4 s at 38400"), "{n}");
        assert!(n.contains("`baud = 38400`"), "{n}");
        assert!(slower_than_fastest(ls(38400, Parity::None), &rates, 8000).is_none());
        assert!(slower_than_fastest(ls(9600, Parity::None), &[], 8000).is_none());
    }
}
