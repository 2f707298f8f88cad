//! Finding the profile read-out command of a real instrument: the candidate forms, what each
//! answer means, the conclusion, the `[instrument.commands]` snippet to paste and what remains
//! when every form is refused. [`super::client::Sj210Client::probe_readout_forms`] asks the
//! instrument; this module only judges the answers.
//!
//! The SJ-210 manual documents no read-out command; the SJ-410's is `RDEVA` with an A/B
//! profile selector (`RDEVA100` total, `RDEVA1nn` blocks). The SJ-210's own `RDRES` and
//! `RDPAR` drop that selector, so its form, if it exists, may be the shorter `RDEVA00`.
//! Answers: `NG030` is "no such command" (try the next form; on all of them, the firmware has
//! none); `NG031` / `NG032` is "a known command with a wrong data form" (keep trying forms);
//! `NG101` is "no profile held" (trace a line first); `OK` with a total means the blocks are
//! read once and checked: the count against N × ⌊λc / pitch⌋
//! ([`super::sampling::expected_points`]) and the instrument's Ra against ours from the same
//! heights ([`super::sanity::check_ra`]).
//!
//! Pure (layer 1): depends on [`super::models`], [`super::ng`], [`super::sampling`] and
//! [`super::sanity`].

use super::models::CommandSpec;
use super::ng::NgCode;
use super::sampling::ExpectedPoints;
use super::sanity::{RaCheck, RepeatedBlock};
use std::fmt;

/// The forms tried first, in order: the SJ-210 grammar without selector, then the SJ-410's
/// with selector A and B.
pub const CANDIDATE_TOTALS: [&str; 3] = ["RDEVA00", "RDEVA000", "RDEVA100"];

/// One read-out form: the total command and the block template (`{n}` = count, two digits).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadoutForm {
    /// Asks for the number of points, e.g. `RDEVA100`.
    pub total: String,
    /// Asks for the next `{n}` points, e.g. `RDEVA1{n}`.
    pub block: String,
}

impl ReadoutForm {
    /// A form from its total command: one that ends in `00` has the block template with `{n}`
    /// in place of the `00` (`RDEVA100` → `RDEVA1{n}`).
    pub fn from_total(total: &str) -> Option<ReadoutForm> {
        let prefix = total.strip_suffix("00")?;
        Some(ReadoutForm {
            total: total.to_string(),
            block: format!("{prefix}{{n}}"),
        })
    }

    /// A form as the operator lists it: `TOTAL` (ending in `00`) or `TOTAL=BLOCK` with `{n}`
    /// in the block template. Both must be printable ASCII.
    pub fn parse(spec: &str) -> Result<ReadoutForm, String> {
        let form = match spec.split_once('=') {
            Some((t, b)) => ReadoutForm {
                total: t.to_string(),
                block: b.to_string(),
            },
            None => ReadoutForm::from_total(spec).ok_or_else(|| {
                format!("read-out form {spec:?} does not end in 00; give it as TOTAL=BLOCK, e.g. RDEVA100=RDEVA1{{n}}")
            })?,
        };
        let printable = |s: &str| !s.is_empty() && s.bytes().all(|b| (0x20..=0x7E).contains(&b));
        if !printable(&form.total) || !printable(&form.block) || !form.block.contains("{n}") {
            return Err(format!(
                "read-out form {spec:?}: the total and the block command must be printable ASCII and the block must hold {{n}}"
            ));
        }
        Ok(form)
    }

    /// The candidates in order, then the operator's forms (duplicates dropped).
    pub fn candidates(extra: &[ReadoutForm]) -> Vec<ReadoutForm> {
        let mut out: Vec<ReadoutForm> = CANDIDATE_TOTALS
            .iter()
            .filter_map(|t| ReadoutForm::from_total(t))
            .collect();
        for f in extra {
            if !out.contains(f) {
                out.push(f.clone());
            }
        }
        out
    }

    /// The two command specs, as a config override would set them.
    pub fn specs(&self) -> (CommandSpec, CommandSpec) {
        (
            CommandSpec {
                template: self.total.clone(),
                source: "read-out probe".into(),
            },
            CommandSpec {
                template: self.block.clone(),
                source: "read-out probe".into(),
            },
        )
    }
}

impl fmt::Display for ReadoutForm {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} / {}", self.total, self.block)
    }
}

/// What a completed read with one form showed.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadCheck {
    /// The total the instrument announced.
    pub total: u32,
    /// The count the conditions give, when they give one.
    pub expected: Option<ExpectedPoints>,
    /// The instrument's Ra against ours, when comparable.
    pub ra: Option<RaCheck>,
    /// Blocks received twice in a row.
    pub repeated_blocks: Vec<RepeatedBlock>,
}

impl ReadCheck {
    /// What is wrong with the read, empty when nothing is.
    pub fn doubts(&self) -> Vec<String> {
        let mut out = Vec::new();
        if let Some(e) = self.expected.filter(|e| e.points != self.total) {
            out.push(format!(
                "{} points read, the conditions give {e}: the pitch ({} um) or the conditions are not this profile's",
                self.total, e.pitch_um
            ));
        }
        if let Some(r) = self.ra.filter(|r| !r.agrees()) {
            out.push(format!(
                "Ra from the points {:.4} um, the instrument's {:.4} um: more than the {:.4} um tolerance apart",
                r.ours_um, r.instrument_um, r.tolerance_um
            ));
        }
        if !self.repeated_blocks.is_empty() {
            let list: Vec<String> = self
                .repeated_blocks
                .iter()
                .map(|b| b.block.to_string())
                .collect();
            out.push(format!(
                "block(s) {} repeated the block before them (the read-out cursor went back)",
                list.join(", ")
            ));
        }
        out
    }
}

/// How the instrument answered one form.
#[derive(Debug, Clone, PartialEq)]
pub enum FormVerdict {
    /// `NG030`: no such command.
    NoSuchCommand,
    /// `NG031` / `NG032`: a known command with a wrong data form.
    WrongForm(NgCode),
    /// `NG101`: the command is known but no profile is held.
    NoProfileHeld,
    /// Another NG code.
    Refused(NgCode),
    /// `OK`, but the payload is not a point count.
    NotACount(String),
    /// The conversation failed (timeout, garbled reply).
    NoAnswer(String),
    /// The total came, the blocks did not read.
    ReadFailed {
        /// The announced total.
        total: Option<u32>,
        /// What went wrong.
        error: String,
    },
    /// The profile was read; the checks are inside.
    Read(ReadCheck),
}

impl FormVerdict {
    /// One line for the operator.
    pub fn describe(&self) -> String {
        match self {
            FormVerdict::NoSuchCommand => "NG030: no such command".into(),
            FormVerdict::WrongForm(c) => format!(
                "{c}: a known command with a wrong data form ({}); keep trying forms",
                c.meaning()
            ),
            FormVerdict::NoProfileHeld => {
                "NG101: the command is known, but no profile is held; trace a line first".into()
            }
            FormVerdict::Refused(c) => format!("{c}: {}", c.meaning()),
            FormVerdict::NotACount(p) => format!("answered OK{p:?}, which is not a point count"),
            FormVerdict::NoAnswer(e) => format!("no usable answer: {e}"),
            FormVerdict::ReadFailed { total, error } => match total {
                Some(t) => format!("announced {t} points, but the blocks did not read: {error}"),
                None => format!("the read-out did not complete: {error}"),
            },
            FormVerdict::Read(c) => {
                let mut s = format!("read {} points", c.total);
                match &c.expected {
                    Some(e) if e.points == c.total => s.push_str(&format!(", as {e}")),
                    Some(_) => {}
                    None => s.push_str(" (the conditions give no count to check)"),
                }
                match &c.ra {
                    Some(r) if r.agrees() => s.push_str(&format!(
                        "; Ra {:.4} um from the points, the instrument's {:.4} um (within {:.4} um)",
                        r.ours_um, r.instrument_um, r.tolerance_um
                    )),
                    Some(_) => {}
                    None => s.push_str("; Ra not compared (no instrument Ra or not an R/P profile)"),
                }
                for d in c.doubts() {
                    s.push_str("; DOUBT: ");
                    s.push_str(&d);
                }
                s
            }
        }
    }
}

/// One form and its answer.
#[derive(Debug, Clone, PartialEq)]
pub struct FormResult {
    /// The form tried.
    pub form: ReadoutForm,
    /// How the instrument answered.
    pub verdict: FormVerdict,
}

/// What the read-out probe concludes.
#[derive(Debug, Clone, PartialEq)]
pub enum Conclusion {
    /// This form reads the profile and every check passed.
    Works(ReadoutForm),
    /// This form reads the profile, but a check failed (the doubts say which).
    WorksWithDoubts(ReadoutForm, Vec<String>),
    /// No profile is held: trace a line (status 000 or 005 after it), then probe again.
    NeedsTrace,
    /// `NG030` on every form: the firmware has no such command.
    NotSupported,
    /// No form read the profile, but not all were unknown commands.
    NoFormFound,
}

/// The whole read-out probe.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadoutProbe {
    /// Each form tried, in order (the probe stops after the first that reads).
    pub results: Vec<FormResult>,
    /// The x pitch used for the count check, µm, and where it came from.
    pub pitch: Option<(f64, String)>,
}

impl ReadoutProbe {
    /// The conclusion from the answers.
    pub fn conclusion(&self) -> Conclusion {
        if let Some(r) = self.results.iter().find_map(|r| match &r.verdict {
            FormVerdict::Read(c) => Some((r.form.clone(), c.doubts())),
            _ => None,
        }) {
            return match r {
                (form, d) if d.is_empty() => Conclusion::Works(form),
                (form, d) => Conclusion::WorksWithDoubts(form, d),
            };
        }
        if self
            .results
            .iter()
            .any(|r| r.verdict == FormVerdict::NoProfileHeld)
        {
            return Conclusion::NeedsTrace;
        }
        if !self.results.is_empty()
            && self
                .results
                .iter()
                .all(|r| r.verdict == FormVerdict::NoSuchCommand)
        {
            return Conclusion::NotSupported;
        }
        Conclusion::NoFormFound
    }

    /// The `[instrument.commands]` lines for a form that reads, `None` otherwise.
    pub fn snippet(&self) -> Option<String> {
        let form = match self.conclusion() {
            Conclusion::Works(f) | Conclusion::WorksWithDoubts(f, _) => f,
            _ => return None,
        };
        let mut s = format!(
            "[instrument.commands]\nprofile-total = \"{}\"\nprofile-block = \"{}\"\n",
            form.total, form.block
        );
        if let Some((p, source)) = &self.pitch {
            if source != "config" {
                s.push_str(&format!(
                    "# the x pitch {p} um was derived from {source}; set [instrument] pitch-x-um if the instrument states another\n"
                ));
            }
        }
        Some(s)
    }

    /// What the operator can do next, for every conclusion but [`Conclusion::Works`].
    pub fn guidance(&self) -> Option<String> {
        let capture = "capture what Mitutoyo's PC software (SJ-Tools, the USB communication tool, SURFPAK-SJ) sends when it pulls a profile: connect the PC running it to a second serial port of this station and run `surfscan probe --config FILE --passthrough /dev/ttyUSB1 --record capture.transcript` (the instrument on the configured port, the PC on the other, both at the instrument's baud and parity), pull one profile in the PC tool, stop with Ctrl-C; the transcript lists every command and reply. Then name the tool's command with `--form TOTAL=BLOCK` and run `surfscan probe --readout` again";
        match self.conclusion() {
            Conclusion::Works(_) => None,
            Conclusion::WorksWithDoubts(_, d) => Some(format!(
                "the form reads, but: {}. Check pitch-x-um and the conditions on the instrument, then probe again",
                d.join("; ")
            )),
            Conclusion::NeedsTrace => Some(
                "no profile is held: trace a line (`surfscan probe --readout --trace`, or START on the instrument and wait until it is back at 000 or 005), then probe again".into(),
            ),
            Conclusion::NotSupported => Some(format!(
                "this firmware has no RDEVA command (NG030 on every form). What remains: an SJ-310, SJ-410 or SJ-411, whose manuals document RDEVA (model = \"sj410\"); or {capture}"
            )),
            Conclusion::NoFormFound => Some(format!(
                "no form read the profile, but the command seems known (not NG030 on every form): list more forms with `--form TOTAL=BLOCK`; or {capture}"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn res(total: &str, verdict: FormVerdict) -> FormResult {
        FormResult {
            form: ReadoutForm::from_total(total).unwrap(),
            verdict,
        }
    }

    fn read(total: u32, expected: Option<u32>) -> FormVerdict {
        FormVerdict::Read(ReadCheck {
            total,
            expected: expected.map(|points| ExpectedPoints {
                points,
                sampling_lengths: 4,
                per_sampling_length: points / 4,
                lambda_c_mm: 2.5,
                pitch_um: 1.5,
            }),
            ra: Some(RaCheck {
                instrument_um: 3.308,
                ours_um: 3.308,
                tolerance_um: 0.07,
            }),
            repeated_blocks: Vec::new(),
        })
    }

    #[test]
    fn forms_from_totals_and_operator_specs() {
        let f = ReadoutForm::from_total("RDEVA100").unwrap();
        assert_eq!(f.block, "RDEVA1{n}");
        assert_eq!(ReadoutForm::from_total("RDEVA"), None);
        assert_eq!(
            ReadoutForm::parse("RDXYZ=RDXYZ{n}").unwrap(),
            ReadoutForm {
                total: "RDXYZ".into(),
                block: "RDXYZ{n}".into()
            }
        );
        assert!(ReadoutForm::parse("RDXYZ").is_err());
        assert!(ReadoutForm::parse("RDXYZ=RDXYZ").is_err());
        assert!(ReadoutForm::parse("RD\u{b5}00").is_err());
        let c = ReadoutForm::candidates(&[ReadoutForm::parse("RDEVA000").unwrap(), f.clone()]);
        let totals: Vec<&str> = c.iter().map(|f| f.total.as_str()).collect();
        assert_eq!(totals, ["RDEVA00", "RDEVA000", "RDEVA100"]);
        assert_eq!(f.specs().1.render(0, 0, 50), "RDEVA150");
    }

    #[test]
    fn conclusions() {
        let unknown = ReadoutProbe {
            results: CANDIDATE_TOTALS
                .iter()
                .map(|t| res(t, FormVerdict::NoSuchCommand))
                .collect(),
            pitch: None,
        };
        assert_eq!(unknown.conclusion(), Conclusion::NotSupported);
        assert!(unknown.snippet().is_none());
        let g = unknown.guidance().unwrap();
        assert!(g.contains("SJ-410") && g.contains("--passthrough"), "{g}");

        let third = ReadoutProbe {
            results: vec![
                res("RDEVA00", FormVerdict::WrongForm(NgCode::InvalidFormat)),
                res("RDEVA000", FormVerdict::WrongForm(NgCode::InvalidFormat)),
                res("RDEVA100", read(6664, Some(6664))),
            ],
            pitch: Some((1.5, "lambda-s 8 um".into())),
        };
        let form = ReadoutForm::from_total("RDEVA100").unwrap();
        assert_eq!(third.conclusion(), Conclusion::Works(form.clone()));
        let s = third.snippet().unwrap();
        assert!(s.starts_with("[instrument.commands]\nprofile-total = \"RDEVA100\"\nprofile-block = \"RDEVA1{n}\"\n"), "{s}");
        assert!(s.contains("pitch-x-um"), "{s}");
        assert_eq!(third.guidance(), None);
        // The snippet is valid TOML for the override table.
        let t: toml::Table = toml::from_str(&s).unwrap();
        assert!(t["instrument"]["commands"]["profile-block"].as_str() == Some("RDEVA1{n}"));

        let short = ReadoutProbe {
            results: vec![res("RDEVA00", read(1067, Some(6664)))],
            pitch: Some((1.5, "config".into())),
        };
        match short.conclusion() {
            Conclusion::WorksWithDoubts(_, d) => {
                assert!(
                    d[0].contains("1067 points read") && d[0].contains("= 6664"),
                    "{d:?}"
                )
            }
            other => panic!("{other:?}"),
        }
        assert!(!short.snippet().unwrap().contains("pitch-x-um"));

        let empty = ReadoutProbe {
            results: vec![
                res("RDEVA00", FormVerdict::NoProfileHeld),
                res("RDEVA000", FormVerdict::WrongForm(NgCode::InvalidFormat)),
            ],
            pitch: None,
        };
        assert_eq!(empty.conclusion(), Conclusion::NeedsTrace);
        let mixed = ReadoutProbe {
            results: vec![
                res("RDEVA00", FormVerdict::NoSuchCommand),
                res("RDEVA000", FormVerdict::WrongForm(NgCode::InvalidValue)),
            ],
            pitch: None,
        };
        assert_eq!(mixed.conclusion(), Conclusion::NoFormFound);
        assert!(mixed.guidance().unwrap().contains("--form"));
    }
}
