//! `[mqtt]` in the station configuration: where the broker is, who the station is there, and
//! how much may wait on disk while the broker is away; validated when the configuration is
//! read, so a wrong value stops the start (exit 78) with the key named.
//!
//! Layer 4 (process edge): serde types and their checks; reads the password file only to
//! check it can be read.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

fn default_outbox_max() -> u64 {
    10_000
}

fn default_keep_alive_s() -> u64 {
    30
}

/// `[mqtt]`: the station's link to the lab's MQTT broker.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct MqttSettings {
    /// `mqtt://HOST:PORT` (plain TCP, port 1883 by default) or `mqtts://HOST:PORT` (TLS,
    /// 8883 by default).
    pub url: String,
    /// The station's name in the topics, `surfscan/<station>/…`: letters, digits, `-`, `_`.
    pub station: String,
    /// The user name the broker knows the station by (none: an anonymous connection).
    #[serde(default)]
    pub username: Option<String>,
    /// A file holding the password (its first line), so the configuration itself, which is
    /// recorded with every scan, holds no secret.
    #[serde(default)]
    pub password_file: Option<PathBuf>,
    /// The MQTT client id; `surfscan-<station>` by default.
    #[serde(default)]
    pub client_id: Option<String>,
    /// PEM file of the certificate authorities a `mqtts://` broker's certificate must chain
    /// to; the system's (`/etc/ssl/certs`) by default.
    #[serde(default)]
    pub ca_file: Option<PathBuf>,
    /// Events and results kept on disk while the broker is away; the oldest event is dropped
    /// (and the drop logged) beyond this many.
    #[serde(default = "default_outbox_max")]
    pub outbox_max: u64,
    /// MQTT keep-alive, seconds: how soon a broker notices the station is gone and publishes
    /// its last will.
    #[serde(default = "default_keep_alive_s")]
    pub keep_alive_s: u64,
    /// Whether the daemon carries out commands (start, pause, resume, abort, the queue's)
    /// published on `surfscan/<station>/commands/<client-id>`; when false, each is refused
    /// with a reply and nothing happens. Only with a broker ACL that lets a client write its
    /// own command topic alone (docs/integration.md).
    #[serde(default)]
    pub commands: bool,
}

/// The broker's address as read from `url`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BrokerAddress {
    /// Host name or address (without brackets for IPv6).
    pub host: String,
    /// TCP port.
    pub port: u16,
    /// TLS (`mqtts://`).
    pub tls: bool,
}

/// Reads `mqtt://HOST[:PORT]` or `mqtts://HOST[:PORT]`.
pub fn parse_broker_url(url: &str) -> Result<BrokerAddress, String> {
    let (tls, rest) = if let Some(r) = url.strip_prefix("mqtts://") {
        (true, r)
    } else if let Some(r) = url.strip_prefix("mqtt://") {
        (false, r)
    } else {
        return Err(format!(
            "{url:?} is not an MQTT URL; write mqtt://HOST:PORT (plain) or mqtts://HOST:PORT (TLS)"
        ));
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if rest.contains('/') || rest.contains('@') {
        return Err(format!(
            "{url:?}: only a host and a port belong in the URL (user and password are [mqtt] username and password-file)"
        ));
    }
    let default_port = if tls { 8883 } else { 1883 };
    let (host, port) = if let Some(r) = rest.strip_prefix('[') {
        let (h, after) = r
            .split_once(']')
            .ok_or_else(|| format!("{url:?}: an IPv6 address needs its closing ']'"))?;
        match after.strip_prefix(':') {
            Some(p) => (h, Some(p)),
            None if after.is_empty() => (h, None),
            None => return Err(format!("{url:?}: unexpected {after:?} after the address")),
        }
    } else {
        match rest.rsplit_once(':') {
            Some((h, p)) => (h, Some(p)),
            None => (rest, None),
        }
    };
    if host.is_empty() {
        return Err(format!("{url:?} names no host"));
    }
    let port = match port {
        None => default_port,
        Some(p) => p
            .parse::<u16>()
            .ok()
            .filter(|p| *p > 0)
            .ok_or_else(|| format!("{url:?}: the port must be a number from 1 to 65535"))?,
    };
    Ok(BrokerAddress {
        host: host.to_owned(),
        port,
        tls,
    })
}

/// True for a name that may stand as one MQTT topic level and in a file name.
pub fn is_topic_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

impl MqttSettings {
    /// The client id the station connects with.
    pub fn client_id(&self) -> String {
        self.client_id
            .clone()
            .unwrap_or_else(|| format!("surfscan-{}", self.station))
    }

    /// The password (first line of `password-file`), if one is configured.
    pub fn password(&self) -> Result<Option<String>, String> {
        let Some(p) = &self.password_file else {
            return Ok(None);
        };
        let text = std::fs::read_to_string(p).map_err(|e| {
            format!(
                "cannot read {}: {e}; the file must be readable by the surfscan user",
                p.display()
            )
        })?;
        let line = text.lines().next().unwrap_or("").trim_end_matches('\r');
        if line.is_empty() {
            return Err(format!(
                "{} is empty; its first line must be the password",
                p.display()
            ));
        }
        Ok(Some(line.to_owned()))
    }

    /// Checks every key but the numeric ones (their ranges are in
    /// [`crate::config::NUMERIC_KEYS`]); the error names the key (`mqtt.url`) and what to do.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let addr = parse_broker_url(&self.url).map_err(|e| ("mqtt.url", e))?;
        if !is_topic_name(&self.station) {
            return Err((
                "mqtt.station",
                format!(
                    "{:?} cannot be a topic level: use 1 to 64 letters, digits, '-' or '_'",
                    self.station
                ),
            ));
        }
        if let Some(id) = &self.client_id {
            if !is_topic_name(id) {
                return Err((
                    "mqtt.client-id",
                    format!("{id:?}: use 1 to 64 letters, digits, '-' or '_'"),
                ));
            }
        }
        if self.password_file.is_some() && self.username.is_none() {
            return Err((
                "mqtt.password-file",
                "a password needs a user name: set [mqtt] username too".into(),
            ));
        }
        self.password().map_err(|e| ("mqtt.password-file", e))?;
        if let Some(ca) = &self.ca_file {
            if !addr.tls {
                return Err((
                    "mqtt.ca-file",
                    format!(
                        "a CA file applies to mqtts:// only; {} is plain MQTT",
                        self.url
                    ),
                ));
            }
            let pem = std::fs::read(ca)
                .map_err(|e| ("mqtt.ca-file", format!("cannot read {}: {e}", ca.display())))?;
            if super::tls::certificates(&pem).is_empty() {
                return Err((
                    "mqtt.ca-file",
                    format!("{} holds no PEM certificate", ca.display()),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broker_urls_are_read_with_their_default_ports() {
        let a = parse_broker_url("mqtt://broker.lab:1884").unwrap();
        assert_eq!(
            (a.host.as_str(), a.port, a.tls),
            ("broker.lab", 1884, false)
        );
        let a = parse_broker_url("mqtts://broker.lab").unwrap();
        assert_eq!((a.host.as_str(), a.port, a.tls), ("broker.lab", 8883, true));
        let a = parse_broker_url("mqtt://[::1]:1900/").unwrap();
        assert_eq!((a.host.as_str(), a.port), ("::1", 1900));
        assert_eq!(parse_broker_url("mqtt://h").unwrap().port, 1883);
        for bad in [
            "http://h:1883",
            "mqtt://",
            "mqtt://h:0",
            "mqtt://h:99999",
            "mqtt://u:p@h",
            "mqtt://h/x",
        ] {
            assert!(parse_broker_url(bad).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn a_station_name_must_stand_as_one_topic_level() {
        assert!(is_topic_name("line-3_station"));
        for bad in ["", "a/b", "a+", "#", "a b", &"x".repeat(65)] {
            assert!(!is_topic_name(bad), "{bad:?} accepted");
        }
    }
}
