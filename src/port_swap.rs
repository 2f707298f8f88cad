//! Whether a reply one device's driver cannot read is in the other device's language: the
//! SJ-210's `OKnnn`/`NGnnn` on the stage's port, a GRBL or Zaber line on the instrument's.
//! Then the ports are swapped in the configuration (or the cables at the PC), and the message
//! says so instead of blaming the baud rate and parity.
//!
//! Layer 0 (vocabulary): pure functions of the reply's text; depends on nothing.

/// The hint for a swapped configuration, appended to the driver's own message.
pub const SWAPPED: &str = "the instrument's and the stage's ports look swapped: exchange [instrument] port and [stage] port (see `ls -l /dev/serial/by-id/`)";

/// `message` with [`SWAPPED`] spelled out with the configured ports: both values and the
/// keys that hold them, to be exchanged.
pub fn name_ports(message: &str, instrument_port: &str, stage_port: &str) -> String {
    message.replace(
        SWAPPED,
        &format!(
            "the instrument's and the stage's ports look swapped (a device answers in the other one's language): exchange the values of [instrument] port = {instrument_port:?} and [stage] port = {stage_port:?} in the configuration, or the cables at the PC (see `ls -l /dev/serial/by-id/`)"
        ),
    )
}

/// Whether `reply` (as received, escaped or not) is a y stage controller's line: GRBL's
/// `ok`, `error:N`, `ALARM:N`, its banner, a status report or a bracketed message; a Zaber
/// ASCII reply (`@01 1 OK …`), alert (`!01 …`) or info line (`#01 …`).
pub fn is_stage_reply(reply: &str) -> bool {
    let r = reply.trim();
    let numbered =
        |rest: &str| rest.len() >= 2 && rest.as_bytes()[..2].iter().all(u8::is_ascii_digit);
    r == "ok"
        || r.strip_prefix("error:")
            .is_some_and(|n| n.parse::<u16>().is_ok())
        || r.strip_prefix("ALARM:")
            .is_some_and(|n| n.parse::<u16>().is_ok())
        || r.starts_with("Grbl ")
        || (r.starts_with('<') && r.ends_with('>') && r.contains('|'))
        || (r.starts_with("[MSG:") || r.starts_with("[VER:") || r.starts_with("[OPT:"))
        || ["@", "!", "#"]
            .iter()
            .any(|p| r.strip_prefix(p).is_some_and(numbered))
}

/// Whether `reply` is the SJ-210's: `OK` or `NG` and three digits (a result may follow).
pub fn is_instrument_reply(reply: &str) -> bool {
    let r = reply.trim().as_bytes();
    r.len() >= 5
        && (r.starts_with(b"OK") || r.starts_with(b"NG"))
        && r[2..5].iter().all(u8::is_ascii_digit)
}

/// The advice for a reply the instrument's driver cannot read.
pub fn instrument_port_hint(reply: &str) -> &'static str {
    if is_stage_reply(reply) {
        SWAPPED
    } else {
        "check baud and parity"
    }
}

/// The advice appended to a line the stage's driver cannot read, if it is the instrument's.
pub fn stage_port_hint(reply: &str) -> &'static str {
    if is_instrument_reply(reply) {
        SWAPPED
    } else {
        ""
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_controllers_lines_are_told_from_the_instruments() {
        for stage in [
            "ok",
            "error:2",
            "ALARM:2",
            "Grbl 1.1h ['$' for help]",
            "<Idle|MPos:0.000,-5.000,0.000|FS:0,0>",
            "[MSG:'$H'|'$X' to unlock]",
            "@01 1 OK IDLE -- 0",
            "!01 1 IDLE --",
            "#01 1 comment",
        ] {
            assert!(is_stage_reply(stage), "{stage}");
            assert!(!is_instrument_reply(stage), "{stage}");
            assert_eq!(instrument_port_hint(stage), SWAPPED, "{stage}");
        }
        for instrument in ["OK000", "NG011", "NG031,05", "OK001 1.234"] {
            assert!(is_instrument_reply(instrument), "{instrument}");
            assert!(!is_stage_reply(instrument), "{instrument}");
            assert_eq!(stage_port_hint(instrument), SWAPPED, "{instrument}");
        }
        let named = name_ports(
            &format!("malformed reply \"ok\" ({SWAPPED})"),
            "/dev/ttyUSB0",
            "/dev/ttyACM0",
        );
        assert!(
            named.contains("exchange the values of [instrument] port = \"/dev/ttyUSB0\" and [stage] port = \"/dev/ttyACM0\" in the configuration"),
            "{named}"
        );
        assert_eq!(name_ports("no reply", "/a", "/b"), "no reply");
        // Noise (a wrong baud rate) is neither: the usual advice, no swap named.
        for noise in ["\\xff\\x00zz", "NG03", "okay", "error:x", "", "@A1"] {
            assert!(
                !is_stage_reply(noise) && !is_instrument_reply(noise),
                "{noise}"
            );
            assert_eq!(instrument_port_hint(noise), "check baud and parity");
            assert_eq!(stage_port_hint(noise), "");
        }
    }
}
