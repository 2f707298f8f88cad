//! The Zaber ASCII codec: command encoding with optional message ids and `:CC` checksums,
//! reply/info/alert parsing, and warning flags mapped to typed stage faults.
//!
//! Pure (layer 1): text in, values out; depends on [`crate::stage::error`] and
//! [`crate::devices`] (fault classes) only.

use crate::devices::FaultClass;
use crate::stage::StageError;

/// Longitudinal redundancy check of a message body: the two's complement of the byte sum,
/// modulo 256.
pub fn lrc(body: &str) -> u8 {
    let sum = body.bytes().fold(0u8, |a, b| a.wrapping_add(b));
    sum.wrapping_neg()
}

/// Encodes `/dev axis [id] command` with an optional checksum, CRLF-terminated.
pub fn encode_command(
    device: u8,
    axis: u8,
    id: Option<u8>,
    command: &str,
    checksum: bool,
) -> String {
    let mut body = format!("{device} {axis}");
    if let Some(id) = id {
        body.push_str(&format!(" {id:02}"));
    }
    if !command.is_empty() {
        body.push(' ');
        body.push_str(command);
    }
    if checksum {
        format!("/{body}:{:02X}\r\n", lrc(&body))
    } else {
        format!("/{body}\r\n")
    }
}

/// A reply (`@`) line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    /// Device address.
    pub device: u8,
    /// Axis (0 = whole device).
    pub axis: u8,
    /// Message id, when one was sent.
    pub id: Option<u8>,
    /// `OK` (true) or `RJ` (false).
    pub accepted: bool,
    /// `BUSY` (true) or `IDLE` (false).
    pub busy: bool,
    /// Highest-priority warning flag, `None` for `--`.
    pub flag: Option<String>,
    /// The data field (return value or rejection reason).
    pub data: String,
}

/// One line from a Zaber device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ZaberMessage {
    /// `@…` reply.
    Reply(Reply),
    /// `#…` info line: device, axis, text.
    Info(u8, u8, String),
    /// `!…` alert: device, axis, busy, flag.
    Alert(u8, u8, bool, Option<String>),
}

/// Why a line could not be parsed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ZaberParseError {
    /// The checksum does not match.
    #[error("checksum mismatch in {line:?}: carried {carried:02X}, computed {computed:02X}; the link is corrupting bytes")]
    Checksum {
        /// The line.
        line: String,
        /// Checksum in the line.
        carried: u8,
        /// Checksum computed.
        computed: u8,
    },
    /// Not a Zaber message.
    #[error("not a Zaber message: {0:?}")]
    Malformed(String),
}

fn flag(s: &str) -> Result<Option<String>, ()> {
    match s {
        "--" => Ok(None),
        f if f.len() == 2 && f.bytes().all(|b| b.is_ascii_uppercase()) => Ok(Some(f.to_string())),
        _ => Err(()),
    }
}

/// Parses one line (without terminator).
pub fn parse_line(line: &str) -> Result<ZaberMessage, ZaberParseError> {
    let bad = || ZaberParseError::Malformed(line.to_string());
    let line_t = line.trim();
    let mut chars = line_t.chars();
    let kind = chars.next().ok_or_else(bad)?;
    let rest = chars.as_str();
    let body = match rest.rsplit_once(':') {
        Some((b, cc)) if cc.len() == 2 && cc.bytes().all(|c| c.is_ascii_hexdigit()) => {
            let carried = u8::from_str_radix(cc, 16).map_err(|_| bad())?;
            let computed = lrc(b);
            if carried != computed {
                return Err(ZaberParseError::Checksum {
                    line: line.to_string(),
                    carried,
                    computed,
                });
            }
            b
        }
        _ => rest,
    };
    let toks: Vec<&str> = body.split_whitespace().collect();
    let num = |i: usize| -> Result<u8, ZaberParseError> {
        toks.get(i).and_then(|t| t.parse().ok()).ok_or_else(bad)
    };
    match kind {
        '@' | '!' => {
            let device = num(0)?;
            let axis = num(1)?;
            // Optional message id: a number in third position.
            let (id, k) = match toks.get(2).and_then(|t| t.parse::<u8>().ok()) {
                Some(id) => (Some(id), 3),
                None => (None, 2),
            };
            let get = |i: usize| toks.get(i).copied().ok_or_else(bad);
            if kind == '@' {
                let accepted = match get(k)? {
                    "OK" => true,
                    "RJ" => false,
                    _ => return Err(bad()),
                };
                let busy = match get(k + 1)? {
                    "BUSY" => true,
                    "IDLE" => false,
                    _ => return Err(bad()),
                };
                let flag = flag(get(k + 2)?).map_err(|_| bad())?;
                let data = toks.get(k + 3..).map(|d| d.join(" ")).unwrap_or_default();
                Ok(ZaberMessage::Reply(Reply {
                    device,
                    axis,
                    id,
                    accepted,
                    busy,
                    flag,
                    data,
                }))
            } else {
                let busy = match get(k)? {
                    "BUSY" => true,
                    "IDLE" => false,
                    _ => return Err(bad()),
                };
                let flag = flag(get(k + 1)?).map_err(|_| bad())?;
                Ok(ZaberMessage::Alert(device, axis, busy, flag))
            }
        }
        '#' => {
            let device = num(0)?;
            let axis = num(1)?;
            Ok(ZaberMessage::Info(
                device,
                axis,
                toks.get(2..).map(|d| d.join(" ")).unwrap_or_default(),
            ))
        }
        _ => Err(bad()),
    }
}

/// What a warning flag means for the scan: `Some` for faults and position loss, `None` for
/// flags that are only logged.
pub fn flag_fault(flag: &str) -> Option<StageError> {
    let (reason, class) = match flag {
        "FS" => ("FS: stalled and stopped", FaultClass::PositionLost),
        "WL" => (
            "WL: unexpected limit switch trigger",
            FaultClass::PositionLost,
        ),
        "FE" => ("FE: limit error", FaultClass::Fatal),
        "FF" => ("FF: critical system error", FaultClass::Fatal),
        "FQ" => ("FQ: encoder error", FaultClass::Fatal),
        "FD" | "FO" => ("driver disabled", FaultClass::Fatal),
        "FV" => ("FV: supply voltage out of range", FaultClass::Fatal),
        "NI" => ("NI: movement interrupted", FaultClass::Transient),
        "WR" | "WH" => {
            return Some(StageError::PositionLost {
                reason: format!("{flag}: device not referenced (not homed)"),
            })
        }
        _ => return None,
    };
    Some(StageError::Fault {
        reason: reason.to_string(),
        class,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_with_and_without_id_and_checksum() {
        assert_eq!(
            encode_command(1, 1, None, "move abs 36283", false),
            "/1 1 move abs 36283\r\n"
        );
        assert_eq!(encode_command(1, 1, Some(0), "", false), "/1 1 00\r\n");
        // "1 0 get pos": byte sum 0x353 → 0x53 → two's complement 0xAD.
        assert_eq!(
            encode_command(1, 0, None, "get pos", true),
            "/1 0 get pos:AD\r\n"
        );
    }

    #[test]
    fn replies_with_id_flag_and_data() {
        assert_eq!(
            parse_line("@01 1 00 OK IDLE -- 36283"),
            Ok(ZaberMessage::Reply(Reply {
                device: 1,
                axis: 1,
                id: Some(0),
                accepted: true,
                busy: false,
                flag: None,
                data: "36283".into()
            }))
        );
        let r = parse_line("@01 1 12 RJ IDLE -- BADCOMMAND");
        assert!(
            matches!(r, Ok(ZaberMessage::Reply(Reply { accepted: false, ref data, id: Some(12), .. })) if data == "BADCOMMAND")
        );
        let r = parse_line("@01 1 OK BUSY FS 100");
        assert!(
            matches!(r, Ok(ZaberMessage::Reply(Reply { busy: true, flag: Some(ref f), id: None, .. })) if f == "FS")
        );
        assert_eq!(
            parse_line("!01 1 IDLE NI"),
            Ok(ZaberMessage::Alert(1, 1, false, Some("NI".into())))
        );
        assert_eq!(
            parse_line("#01 0 some info"),
            Ok(ZaberMessage::Info(1, 0, "some info".into()))
        );
    }

    #[test]
    fn checksums_are_verified() {
        // "01 0 OK IDLE -- 0": byte sum 0x373 → 0x73 → two's complement 0x8D.
        assert!(parse_line("@01 0 OK IDLE -- 0:8D").is_ok());
        assert!(matches!(
            parse_line("@01 0 OK IDLE -- 0:8E"),
            Err(ZaberParseError::Checksum {
                carried: 0x8E,
                computed: 0x8D,
                ..
            })
        ));
    }

    #[test]
    fn garbage_is_refused() {
        for bad in [
            "",
            "@",
            "@01",
            "@01 1 MAYBE IDLE -- 0",
            "@01 1 OK NAP -- 0",
            "@01 1 OK IDLE x 0",
            "%01 1 OK IDLE -- 0",
            "@999 1 OK IDLE -- 0",
        ] {
            assert!(parse_line(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn flags_map_to_fault_classes() {
        use crate::devices::DeviceFault;
        assert_eq!(
            flag_fault("FS").map(|e| e.class()),
            Some(FaultClass::PositionLost)
        );
        assert_eq!(
            flag_fault("WR").map(|e| e.class()),
            Some(FaultClass::PositionLost)
        );
        assert_eq!(
            flag_fault("WH").map(|e| e.class()),
            Some(FaultClass::PositionLost)
        );
        assert_eq!(flag_fault("FE").map(|e| e.class()), Some(FaultClass::Fatal));
        assert_eq!(
            flag_fault("NI").map(|e| e.class()),
            Some(FaultClass::Transient)
        );
        assert!(flag_fault("WT").is_none());
    }
}
