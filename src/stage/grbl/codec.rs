//! The GRBL 1.1 / grblHAL line-message codec: real-time bytes, status reports, acks, alarms,
//! feedback and banners parsed from one line each; the absolute jog encoded; error and
//! alarm codes explained.
//!
//! Pure (layer 1): text in, values out; depends on nothing in the crate.

/// Real-time status request.
pub const RT_STATUS: u8 = b'?';
/// Real-time feed hold.
pub const RT_FEED_HOLD: u8 = b'!';
/// Real-time cycle start / resume.
pub const RT_CYCLE_START: u8 = b'~';
/// Real-time soft reset (Ctrl-X).
pub const RT_SOFT_RESET: u8 = 0x18;
/// Real-time jog cancel.
pub const RT_JOG_CANCEL: u8 = 0x85;

/// Machine state from a status report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GrblState {
    /// Idle.
    Idle,
    /// Running G-code motion.
    Run,
    /// Jogging.
    Jog,
    /// Feed hold (with sub-state).
    Hold(Option<u8>),
    /// Alarm lock.
    Alarm,
    /// Safety door (with sub-state).
    Door(Option<u8>),
    /// Check mode.
    Check,
    /// Homing.
    Home,
    /// Sleep.
    Sleep,
}

/// A parsed `<…>` status report; positions in mm.
#[derive(Debug, Clone, PartialEq)]
pub struct StatusReport {
    /// Machine state.
    pub state: GrblState,
    /// Machine position, if reported.
    pub mpos_mm: Option<[f64; 3]>,
    /// Work position, if reported.
    pub wpos_mm: Option<[f64; 3]>,
    /// Work coordinate offset, if reported.
    pub wco_mm: Option<[f64; 3]>,
    /// The real speed now, mm/min (`FS:` or `F:`), if reported.
    pub feed_mm_min: Option<f64>,
    /// Input pins that are active (`Pn:`: `X`/`Y`/`Z` limits, `P` probe, `D` door…).
    pub pins: Option<String>,
}

/// One line from the controller.
#[derive(Debug, Clone, PartialEq)]
pub enum GrblMessage {
    /// `ok`.
    Ok,
    /// `error:N`.
    Error(u16),
    /// `ALARM:N`.
    Alarm(u16),
    /// `<…>`.
    Status(StatusReport),
    /// `[MSG:…]`.
    Msg(String),
    /// `[VER:…]`.
    Ver(String),
    /// `[OPT:…]`.
    Opt(String),
    /// Other `[…]` feedback (`[GC:…]`, `[HLP:…]`…).
    Feedback(String),
    /// The start-up banner (`Grbl 1.1h ['$' for help]`, `GrblHAL 1.1f ['$' or '$HELP' for help]`).
    Banner(String),
    /// A setting as `$$` lists it: `$101=400.000`.
    Setting(u16, f64),
    /// `>…:ok` start-up block echo or another `$` line (`$N0=…`).
    Other(String),
}

fn parse_axes(s: &str) -> Option<[f64; 3]> {
    let mut out = [0.0; 3];
    let mut n = 0;
    for part in s.split(',') {
        let v: f64 = part.trim().parse().ok()?;
        if !v.is_finite() {
            return None;
        }
        if n < 3 {
            out[n] = v;
        }
        n += 1;
    }
    (n >= 3).then_some(out)
}

fn parse_state(s: &str) -> Option<GrblState> {
    let (name, sub) = match s.split_once(':') {
        Some((n, sub)) => (n, Some(sub.parse::<u8>().ok()?)),
        None => (s, None),
    };
    Some(match name {
        "Idle" => GrblState::Idle,
        "Run" => GrblState::Run,
        "Jog" => GrblState::Jog,
        "Hold" => GrblState::Hold(sub),
        "Alarm" => GrblState::Alarm,
        "Door" => GrblState::Door(sub),
        "Check" => GrblState::Check,
        "Home" => GrblState::Home,
        "Sleep" => GrblState::Sleep,
        _ => return None,
    })
}

/// Parses one line (without terminator). `None` when it is not a GRBL message.
pub fn parse_line(line: &str) -> Option<GrblMessage> {
    let line = line.trim();
    if line == "ok" {
        return Some(GrblMessage::Ok);
    }
    if let Some(n) = line.strip_prefix("error:") {
        return n.parse().ok().map(GrblMessage::Error);
    }
    if let Some(n) = line.strip_prefix("ALARM:") {
        return n.parse().ok().map(GrblMessage::Alarm);
    }
    if let Some(body) = line.strip_prefix('<').and_then(|l| l.strip_suffix('>')) {
        let mut fields = body.split('|');
        let state = parse_state(fields.next()?)?;
        let mut rep = StatusReport {
            state,
            mpos_mm: None,
            wpos_mm: None,
            wco_mm: None,
            feed_mm_min: None,
            pins: None,
        };
        for f in fields {
            if let Some(v) = f.strip_prefix("MPos:") {
                rep.mpos_mm = Some(parse_axes(v)?);
            } else if let Some(v) = f.strip_prefix("WPos:") {
                rep.wpos_mm = Some(parse_axes(v)?);
            } else if let Some(v) = f.strip_prefix("WCO:") {
                rep.wco_mm = Some(parse_axes(v)?);
            } else if let Some(v) = f.strip_prefix("FS:").or_else(|| f.strip_prefix("F:")) {
                // `FS:rate,spindle` (variable-spindle builds) or `F:rate`.
                let rate: f64 = v.split(',').next()?.trim().parse().ok()?;
                rep.feed_mm_min = rate.is_finite().then_some(rate.max(0.0));
            } else if let Some(v) = f.strip_prefix("Pn:") {
                rep.pins = Some(v.to_string());
            }
        }
        if rep.mpos_mm.is_none() && rep.wpos_mm.is_none() {
            return None;
        }
        return Some(GrblMessage::Status(rep));
    }
    if let Some(body) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
        return Some(if let Some(m) = body.strip_prefix("MSG:") {
            GrblMessage::Msg(m.to_string())
        } else if let Some(m) = body.strip_prefix("VER:") {
            GrblMessage::Ver(m.to_string())
        } else if let Some(m) = body.strip_prefix("OPT:") {
            GrblMessage::Opt(m.to_string())
        } else {
            GrblMessage::Feedback(body.to_string())
        });
    }
    let lower = line.to_ascii_lowercase();
    if (lower.starts_with("grbl ") || lower.starts_with("grblhal ")) && line.contains("for help") {
        return Some(GrblMessage::Banner(line.to_string()));
    }
    if let Some((n, v)) = parse_setting(line) {
        return Some(GrblMessage::Setting(n, v));
    }
    if line.starts_with('>') || line.starts_with('$') {
        return Some(GrblMessage::Other(line.to_string()));
    }
    None
}

/// `$N=value` with a numeric setting number (not a `$N0=` startup line).
fn parse_setting(line: &str) -> Option<(u16, f64)> {
    let (n, v) = line.strip_prefix('$')?.split_once('=')?;
    if n.is_empty() || !n.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let n: u16 = n.parse().ok()?;
    let v: f64 = v.trim().parse().ok()?;
    v.is_finite().then_some((n, v))
}

/// Encodes a jog to an absolute machine Y coordinate.
pub fn encode_jog_y(y_mm: f64, feed_mm_min: f64) -> String {
    format!("$J=G53 G90 Y{y_mm:.6} F{feed_mm_min:.3}\n")
}

/// Meaning of an `error:N` code (the ones a stage driver meets).
pub fn error_text(code: u16) -> &'static str {
    match code {
        1 => "expected command letter",
        2 => "bad number format",
        3 => "invalid '$' statement",
        5 => "homing cycle not enabled in settings ($22)",
        7 => "settings unreadable (EEPROM); restored to defaults",
        8 => "command requires Idle",
        9 => "G-code locked out during alarm or jog",
        15 => "jog target exceeds machine travel",
        10 => "soft limits need homing enabled",
        11 => "line longer than the controller's line buffer",
        16 => "invalid jog command",
        22 => "feed rate undefined",
        20..=38 => "G-code parser error",
        _ => "see the GRBL error code table",
    }
}

/// Meaning of an `ALARM:N` code.
pub fn alarm_text(code: u16) -> &'static str {
    match code {
        1 => "hard limit triggered (position probably lost)",
        2 => "soft limit: motion target exceeds travel (position kept)",
        3 => "reset while in motion (position lost)",
        4 => "probe fail",
        5 => "probe fail",
        6 => "homing fail: reset during homing",
        7 => "homing fail: door opened during homing",
        8 => "homing fail: pull-off did not clear the switch",
        9 => "homing fail: switch not found",
        _ => "unknown alarm",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_fields_in_any_order_with_substates() {
        let m = parse_line("<Hold:0|FS:0,0|WCO:0.000,-5.000,0.000|WPos:1.000,2.500,0.000>");
        assert_eq!(
            m,
            Some(GrblMessage::Status(StatusReport {
                state: GrblState::Hold(Some(0)),
                mpos_mm: None,
                wpos_mm: Some([1.0, 2.5, 0.0]),
                wco_mm: Some([0.0, -5.0, 0.0]),
                feed_mm_min: Some(0.0),
                pins: None,
            }))
        );
        let m = parse_line("<Jog|MPos:0.000,-12.345,0.000|Bf:15,128|FS:60,0>");
        assert!(
            matches!(m, Some(GrblMessage::Status(StatusReport { state: GrblState::Jog, mpos_mm: Some(p), feed_mm_min: Some(f), .. })) if p[1] == -12.345 && f == 60.0)
        );
    }

    #[test]
    fn firmware_fields_pins_overrides_and_the_no_spindle_feed() {
        // As GRBL 1.1h sends them: Pn while a switch is pressed, Ov on its own cadence, and
        // `F:` instead of `FS:` on builds without a variable spindle.
        let m = parse_line("<Alarm|MPos:0.000,0.000,0.000|F:0|Pn:Y|Ov:100,100,100>");
        let Some(GrblMessage::Status(r)) = m else {
            panic!("{m:?}")
        };
        assert_eq!(r.state, GrblState::Alarm);
        assert_eq!(r.pins.as_deref(), Some("Y"));
        assert_eq!(r.feed_mm_min, Some(0.0));
        assert_eq!(r.mpos_mm, Some([0.0, 0.0, 0.0]));
        // grblHAL with a fourth axis.
        let m = parse_line("<Idle|MPos:1.000,-2.000,3.000,4.000|FS:0,0>");
        assert!(matches!(
            m,
            Some(GrblMessage::Status(StatusReport {
                mpos_mm: Some([1.0, -2.0, 3.0]),
                ..
            }))
        ));
    }

    #[test]
    fn acks_alarms_and_feedback() {
        assert_eq!(parse_line("ok"), Some(GrblMessage::Ok));
        assert_eq!(parse_line("error:15"), Some(GrblMessage::Error(15)));
        assert_eq!(parse_line("ALARM:2"), Some(GrblMessage::Alarm(2)));
        assert_eq!(
            parse_line("[MSG:Reset to continue]"),
            Some(GrblMessage::Msg("Reset to continue".into()))
        );
        assert_eq!(
            parse_line("[VER:1.1h.20190825:y-stage]"),
            Some(GrblMessage::Ver("1.1h.20190825:y-stage".into()))
        );
        assert_eq!(
            parse_line("[OPT:V,15,128]"),
            Some(GrblMessage::Opt("V,15,128".into()))
        );
        assert!(matches!(
            parse_line("Grbl 1.1h ['$' for help]"),
            Some(GrblMessage::Banner(_))
        ));
        assert!(matches!(
            parse_line("GrblHAL 1.1f ['$' or '$HELP' for help]"),
            Some(GrblMessage::Banner(_))
        ));
        assert_eq!(
            parse_line("$101=400.000"),
            Some(GrblMessage::Setting(101, 400.0))
        );
        assert_eq!(parse_line("$22=1"), Some(GrblMessage::Setting(22, 1.0)));
        assert_eq!(parse_line("$N0="), Some(GrblMessage::Other("$N0=".into())));
        assert_eq!(
            parse_line("$101=x"),
            Some(GrblMessage::Other("$101=x".into()))
        );
    }

    #[test]
    fn garbage_is_not_a_message() {
        for bad in [
            "error:",
            "error:x",
            "ALARM:",
            "<Idle>",
            "<Flying|MPos:0,0,0>",
            "<Idle|MPos:0,0>",
            "<Idle|MPos:nan,0,0>",
            "Grbl",
            "okay",
            "",
        ] {
            assert_eq!(parse_line(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn jog_is_absolute_machine_coordinates() {
        assert_eq!(
            encode_jog_y(-0.0125, 60.0),
            "$J=G53 G90 Y-0.012500 F60.000\n"
        );
    }
}
