//! `[web]` in the station configuration: the station's page, off unless the table is there.
//!
//! Layer 4 (process edge): serde types and their checks; reads nothing (the token file and
//! the certificate are read when the server starts, [`super::auth`], [`super::tls`]).

use serde::{Deserialize, Serialize};
use std::net::SocketAddr;
use std::path::PathBuf;

/// `[web]`: where the page listens and who may use it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct WebSettings {
    /// Address and port (default `127.0.0.1:8210`: this PC only). `0.0.0.0:8210` opens it to
    /// the lab network; then set `tls-cert` and `tls-key` too.
    #[serde(default = "d_listen")]
    pub listen: String,
    /// The users and their tokens, one `NAME TOKEN` line each (`NAME TOKEN view` for a user
    /// who may only look); readable by the daemon's user only. Required.
    pub token_file: PathBuf,
    /// The server's certificate chain (PEM); with `tls-key`, the page is served over HTTPS.
    #[serde(default)]
    pub tls_cert: Option<PathBuf>,
    /// The certificate's private key (PEM, PKCS#8, PKCS#1 or SEC1).
    #[serde(default)]
    pub tls_key: Option<PathBuf>,
    /// Connections served at once (default 256); one more is closed at once.
    #[serde(default = "d_max_connections")]
    pub max_connections: usize,
    /// How long a signed-in page stays signed in without the token, hours (default 12).
    #[serde(default = "d_session_hours")]
    pub session_hours: u32,
}

fn d_listen() -> String {
    "127.0.0.1:8210".to_owned()
}

fn d_max_connections() -> usize {
    256
}

fn d_session_hours() -> u32 {
    12
}

impl WebSettings {
    /// The listening address, checked.
    pub fn address(&self) -> Result<SocketAddr, String> {
        self.listen.parse().map_err(|_| {
            format!(
                "{:?} is not an address and port; write e.g. \"127.0.0.1:8210\" (this PC only) or \"0.0.0.0:8210\" (the lab network)",
                self.listen
            )
        })
    }

    /// The first key that is wrong, and why (the numeric keys' ranges are in
    /// [`crate::config::NUMERIC_KEYS`], checked with every other's).
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        self.address().map_err(|e| ("web.listen", e))?;
        if self.token_file.as_os_str().is_empty() {
            return Err((
                "web.token-file",
                "must name the file of the page's users and tokens, e.g. \"/etc/surfscan/web-tokens\"".into(),
            ));
        }
        match (&self.tls_cert, &self.tls_key) {
            (Some(_), None) => {
                return Err((
                    "web.tls-key",
                    "missing: tls-cert is set, so the certificate's private key must be too (or remove tls-cert to serve plain HTTP)".into(),
                ))
            }
            (None, Some(_)) => {
                return Err((
                    "web.tls-cert",
                    "missing: tls-key is set, so its certificate must be too (or remove tls-key to serve plain HTTP)".into(),
                ))
            }
            _ => {}
        }
        Ok(())
    }

    /// Whether the page is served over HTTPS.
    pub fn tls(&self) -> bool {
        self.tls_cert.is_some() && self.tls_key.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<WebSettings, String> {
        toml::from_str(text).map_err(|e| e.to_string())
    }

    #[test]
    fn the_defaults_are_loopback_and_bounded() {
        let s = parse("token-file = \"/etc/surfscan/web-tokens\"").unwrap();
        assert_eq!(s.address().unwrap(), "127.0.0.1:8210".parse().unwrap());
        assert!(s.address().unwrap().ip().is_loopback());
        assert_eq!((s.max_connections, s.session_hours), (256, 12));
        assert!(!s.tls());
        assert_eq!(s.validate(), Ok(()));
    }

    #[test]
    fn a_token_file_is_required_and_unknown_keys_refused() {
        assert!(parse("listen = \"127.0.0.1:1\"")
            .unwrap_err()
            .contains("token-file"));
        assert!(parse("token-file = \"t\"\ntoken = \"secret\"")
            .unwrap_err()
            .contains("token"));
    }

    #[test]
    fn bad_values_name_their_key() {
        let mut s = parse("token-file = \"t\"").unwrap();
        s.listen = "localhost".into();
        assert_eq!(s.validate().unwrap_err().0, "web.listen");
        s.listen = "[::1]:8210".into();
        assert_eq!(s.validate(), Ok(()));
        s.tls_cert = Some("c.pem".into());
        assert_eq!(s.validate().unwrap_err().0, "web.tls-key");
        s.tls_key = Some("k.pem".into());
        assert!(s.tls());
        // The numeric keys' ranges are checked with every other's (config::NUMERIC_KEYS).
    }
}
