//! Who is asking: the page's users and their tokens (`[web] token-file`), the signed session
//! cookie a browser keeps after signing in with its token, and the checks against cross-site
//! request forgery.
//!
//! A token is never stored, logged or put in a URL: the daemon keeps SHA-256 digests of the
//! tokens, and compares digests. A session cookie is `NAME:EXPIRY:NONCE:MAC`, the MAC an
//! HMAC-SHA256 under a key derived from the user's token, so the daemon keeps no session table:
//! a signed-in page stays signed in across a restart of the daemon, and changing a user's token
//! (and restarting) ends that user's sessions. Signing out revokes the cookie's nonce until it
//! would have expired anyway.
//!
//! Requests a browser sends with the cookie can be forged by another site's page, so every
//! such request that changes anything must carry the session's CSRF token in the
//! `X-CSRF-Token` header (which a cross-site form cannot set, and a cross-site script can
//! neither read nor send without the CORS permission this server never gives) and must not
//! come from another origin (`Origin`, `Sec-Fetch-Site`). A request with a bearer token needs
//! neither: a browser never adds a bearer token by itself.
//!
//! Layer 4 (process edge): pure functions over header values and the clock's reading, plus
//! [`Users::load`], which reads the token file; depends on sha2 and ring (HMAC, random nonces).

use ring::hmac;
use ring::rand::{SecureRandom, SystemRandom};
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::sync::Mutex;

/// The name of the session cookie.
pub const COOKIE: &str = "surfscan_session";

/// The header that carries a session's CSRF token.
pub const CSRF_HEADER: &str = "x-csrf-token";

/// Shortest token accepted, characters.
pub const MIN_TOKEN_CHARS: usize = 16;

/// What a user may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Look and command (pause, resume, abort, start, …).
    Operate,
    /// Look only.
    View,
}

/// One user of the page.
#[derive(Clone)]
pub struct User {
    /// The name, as the journal records it with the user's commands.
    pub name: String,
    /// What the user may do.
    pub role: Role,
    /// SHA-256 of the token.
    digest: [u8; 32],
    /// The key of the user's session MACs, derived from the token.
    session_key: hmac::Key,
}

impl std::fmt::Debug for User {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("User")
            .field("name", &self.name)
            .field("role", &self.role)
            .finish_non_exhaustive()
    }
}

/// The users of the token file.
#[derive(Debug, Clone)]
pub struct Users {
    users: Vec<User>,
}

fn sha256(bytes: &[u8]) -> [u8; 32] {
    Sha256::digest(bytes).into()
}

/// Equal digests, compared without an early exit.
fn same(a: &[u8; 32], b: &[u8; 32]) -> bool {
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"._-@".contains(&b))
}

impl Users {
    /// Parses the token file's text: one `NAME TOKEN` or `NAME TOKEN view` line per user;
    /// blank lines and lines starting with `#` are skipped. The error names the line (never
    /// the token) and what is accepted.
    pub fn parse(text: &str) -> Result<Users, String> {
        let mut users: Vec<User> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let n = i + 1;
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = line.split_whitespace().collect();
            let (name, token, role) = match fields[..] {
                [name, token] => (name, token, Role::Operate),
                [name, token, "view"] => (name, token, Role::View),
                [name, token, "operate"] => (name, token, Role::Operate),
                [_, _, other] => {
                    return Err(format!(
                        "line {n}: the third field {other:?} is not a role; write `view` (may only look) or nothing (may operate)"
                    ))
                }
                _ => {
                    return Err(format!(
                        "line {n}: expected `NAME TOKEN` or `NAME TOKEN view` ({} fields found)",
                        fields.len()
                    ))
                }
            };
            if !valid_name(name) {
                return Err(format!(
                    "line {n}: the name {name:?} must be 1 to 64 letters, digits or . _ - @"
                ));
            }
            if token.chars().count() < MIN_TOKEN_CHARS || !token.is_ascii() {
                return Err(format!(
                    "line {n}: the token of {name} must be at least {MIN_TOKEN_CHARS} ASCII characters (e.g. the output of `openssl rand -hex 24`)"
                ));
            }
            let digest = sha256(token.as_bytes());
            if users.iter().any(|u| u.name == name) {
                return Err(format!(
                    "line {n}: {name} is named twice; one line per user"
                ));
            }
            if users.iter().any(|u| same(&u.digest, &digest)) {
                return Err(format!(
                    "line {n}: {name}'s token is another user's too; give every user a token of their own"
                ));
            }
            let mut key_material = b"surfscan web session\0".to_vec();
            key_material.extend_from_slice(token.as_bytes());
            users.push(User {
                name: name.to_owned(),
                role,
                digest,
                session_key: hmac::Key::new(hmac::HMAC_SHA256, &sha256(&key_material)),
            });
        }
        if users.is_empty() {
            return Err(
                "names no user; add a line `NAME TOKEN` (e.g. `operator $(openssl rand -hex 24)`)"
                    .into(),
            );
        }
        Ok(Users { users })
    }

    /// Reads and parses the token file, which must not be readable by others than its owner
    /// and group. The error names the file and what to do.
    pub fn load(path: &Path) -> Result<Users, String> {
        let meta = std::fs::metadata(path).map_err(|e| {
            format!(
                "cannot read the token file {}: {e}; create it with one `NAME TOKEN` line per user",
                path.display()
            )
        })?;
        let mode = meta.permissions().mode();
        if mode & 0o007 != 0 {
            return Err(format!(
                "the token file {} is readable by every user of this PC (mode {:o}); `chmod 640 {}` (owner root, group of the daemon)",
                path.display(),
                mode & 0o777,
                path.display()
            ));
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read the token file {}: {e}", path.display()))?;
        Users::parse(&text).map_err(|e| format!("the token file {}: {e}", path.display()))
    }

    /// The user whose token this is.
    pub fn by_token(&self, token: &str) -> Option<&User> {
        let digest = sha256(token.as_bytes());
        // Every digest is compared, so the time taken does not tell which user matched.
        let mut found = None;
        for u in &self.users {
            if same(&u.digest, &digest) {
                found = Some(u);
            }
        }
        found
    }

    fn by_name(&self, name: &str) -> Option<&User> {
        self.users.iter().find(|u| u.name == name)
    }

    /// How many users the file names.
    pub fn len(&self) -> usize {
        self.users.len()
    }

    /// Whether the file names no user (never, once parsed).
    pub fn is_empty(&self) -> bool {
        self.users.is_empty()
    }
}

/// A signed-in browser's session, as its cookie says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Session {
    /// The user.
    pub user: String,
    /// Seconds since the epoch after which the cookie is refused.
    pub expires: i64,
    /// The session's random nonce (hex).
    pub nonce: String,
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn mac_input(user: &str, expires: i64, nonce: &str) -> String {
    format!("session\0{user}\0{expires}\0{nonce}")
}

/// Issues and checks session cookies; remembers the sessions signed out.
pub struct Sessions {
    rng: SystemRandom,
    /// Nonces of signed-out sessions and when their cookies expire.
    revoked: Mutex<HashMap<String, i64>>,
}

impl Default for Sessions {
    fn default() -> Self {
        Sessions {
            rng: SystemRandom::new(),
            revoked: Mutex::new(HashMap::new()),
        }
    }
}

impl Sessions {
    /// A new session for `user`, valid until `expires`: the cookie's value.
    pub fn issue(&self, user: &User, expires: i64) -> Result<(String, Session), String> {
        let mut nonce = [0u8; 16];
        self.rng
            .fill(&mut nonce)
            .map_err(|_| "the system's random number source failed".to_owned())?;
        let nonce = hex(&nonce);
        let tag = hmac::sign(
            &user.session_key,
            mac_input(&user.name, expires, &nonce).as_bytes(),
        );
        let cookie = format!("{}:{expires}:{nonce}:{}", user.name, hex(tag.as_ref()));
        Ok((
            cookie,
            Session {
                user: user.name.clone(),
                expires,
                nonce,
            },
        ))
    }

    /// The session of a cookie value, if it is genuine, not expired at `now` and not signed
    /// out; with its user.
    pub fn check<'u>(
        &self,
        users: &'u Users,
        cookie: &str,
        now: i64,
    ) -> Option<(&'u User, Session)> {
        let mut parts = cookie.split(':');
        let (name, expires, nonce, mac) =
            (parts.next()?, parts.next()?, parts.next()?, parts.next()?);
        if parts.next().is_some() || nonce.len() != 32 || mac.len() != 64 {
            return None;
        }
        let expires: i64 = expires.parse().ok()?;
        if expires <= now {
            return None;
        }
        let user = users.by_name(name)?;
        let tag = unhex(mac)?;
        hmac::verify(
            &user.session_key,
            mac_input(name, expires, nonce).as_bytes(),
            &tag,
        )
        .ok()?;
        if self.signed_out().contains_key(nonce) {
            return None;
        }
        Some((
            user,
            Session {
                user: name.to_owned(),
                expires,
                nonce: nonce.to_owned(),
            },
        ))
    }

    /// The CSRF token of a session (what the page sends in [`CSRF_HEADER`]).
    pub fn csrf_token(&self, user: &User, session: &Session) -> String {
        let tag = hmac::sign(
            &user.session_key,
            format!("csrf\0{}", session.nonce).as_bytes(),
        );
        hex(tag.as_ref())
    }

    /// Signs a session out: its cookie is refused from now on. Revocations past their
    /// cookie's expiry at `now` are forgotten.
    pub fn revoke(&self, session: &Session, now: i64) {
        let mut r = self.signed_out();
        r.retain(|_, expires| *expires > now);
        r.insert(session.nonce.clone(), session.expires);
    }

    /// The signed-out sessions, also after a panic of a request that held them: each change
    /// is one map operation, so the map is whole (refusing every cookie, or forgetting the
    /// sign-outs, would leave the page unusable or open).
    fn signed_out(&self) -> std::sync::MutexGuard<'_, HashMap<String, i64>> {
        self.revoked.lock().unwrap_or_else(|p| p.into_inner())
    }
}

fn unhex(s: &str) -> Option<Vec<u8>> {
    if s.len() % 2 != 0 {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

/// The value of cookie `name` in a `Cookie` header.
pub fn cookie_value<'a>(header: &'a str, name: &str) -> Option<&'a str> {
    header.split(';').find_map(|kv| {
        let (k, v) = kv.trim().split_once('=')?;
        (k == name).then_some(v)
    })
}

/// The token of an `Authorization: Bearer …` header.
pub fn bearer(header: &str) -> Option<&str> {
    let (scheme, token) = header.trim().split_once(' ')?;
    scheme.eq_ignore_ascii_case("bearer").then(|| token.trim())
}

/// What a request says about where it comes from, for the CSRF checks.
#[derive(Debug, Clone, Copy, Default)]
pub struct Provenance<'a> {
    /// `Origin`.
    pub origin: Option<&'a str>,
    /// `Sec-Fetch-Site`.
    pub fetch_site: Option<&'a str>,
    /// `Host`.
    pub host: Option<&'a str>,
    /// Whether this server speaks HTTPS (the scheme of its own origin).
    pub tls: bool,
}

/// Whether a request comes from this server's own pages as far as the browser says: no
/// `Origin` other than this server's, no `Sec-Fetch-Site` other than `same-origin` or `none`.
/// The error says what gave it away.
pub fn same_origin(p: &Provenance<'_>) -> Result<(), String> {
    if let Some(site) = p.fetch_site {
        if site != "same-origin" && site != "none" {
            return Err(format!(
                "the browser says the request comes from another site (Sec-Fetch-Site: {site})"
            ));
        }
    }
    if let Some(origin) = p.origin {
        let scheme = if p.tls { "https" } else { "http" };
        let own = p.host.map(|h| format!("{scheme}://{h}"));
        if own.as_deref() != Some(origin) {
            return Err(format!(
                "the request comes from the page of another origin ({origin})"
            ));
        }
    }
    Ok(())
}

/// The CSRF check of a request authenticated by its session cookie that changes something:
/// it comes from this server's own page and carries the session's token.
pub fn csrf_check(p: &Provenance<'_>, sent: Option<&str>, expected: &str) -> Result<(), String> {
    same_origin(p)?;
    match sent {
        None => Err(format!("the request carries no {CSRF_HEADER} header; commands sent with the session cookie must carry the token /api/session gives")),
        Some(t) if t.len() == expected.len() && same(&sha256(t.as_bytes()), &sha256(expected.as_bytes())) => Ok(()),
        Some(_) => Err(format!("the {CSRF_HEADER} header does not match this session's token; reload the page")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str =
        "# the station's users\nalice 0123456789abcdef0123\n\nbob   fedcba9876543210fedc view\n";

    #[test]
    fn the_token_file_names_users_roles_and_tokens() {
        let users = Users::parse(FILE).unwrap();
        assert_eq!(users.len(), 2);
        let a = users.by_token("0123456789abcdef0123").unwrap();
        assert_eq!((a.name.as_str(), a.role), ("alice", Role::Operate));
        let b = users.by_token("fedcba9876543210fedc").unwrap();
        assert_eq!((b.name.as_str(), b.role), ("bob", Role::View));
        assert!(users.by_token("0123456789abcdef012").is_none());
        assert!(users.by_token("").is_none());
        // The debug form (what a log line could show) holds no token or digest.
        let shown = format!("{users:?}");
        assert!(
            !shown.contains("0123456789abcdef0123") && shown.contains("alice"),
            "{shown}"
        );
    }

    #[test]
    fn a_bad_token_file_is_refused_naming_the_line_and_never_the_token() {
        for (text, says) in [
            ("", "names no user"),
            (
                "alice short",
                "line 1: the token of alice must be at least 16",
            ),
            (
                "alice 0123456789abcdef0123 admin",
                "line 1: the third field \"admin\"",
            ),
            ("alice", "line 1: expected `NAME TOKEN`"),
            ("a/b 0123456789abcdef0123", "line 1: the name \"a/b\""),
            (
                "alice 0123456789abcdef0123\nalice 0123456789abcdef0124",
                "line 2: alice is named twice",
            ),
            (
                "alice 0123456789abcdef0123\nbob 0123456789abcdef0123",
                "line 2: bob's token is another user's",
            ),
        ] {
            let e = Users::parse(text).unwrap_err();
            assert!(e.contains(says), "{text:?}: {e}");
            assert!(!e.contains("0123456789abcdef"), "{e}");
        }
    }

    #[test]
    fn a_token_file_others_can_read_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("tokens");
        std::fs::write(&path, FILE).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = Users::load(&path).unwrap_err();
        assert!(
            e.contains("readable by every user") && e.contains("chmod 640"),
            "{e}"
        );
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).unwrap();
        assert_eq!(Users::load(&path).unwrap().len(), 2);
    }

    #[test]
    fn a_session_cookie_is_accepted_until_it_expires_is_altered_or_signed_out() {
        let users = Users::parse(FILE).unwrap();
        let sessions = Sessions::default();
        let alice = users.by_token("0123456789abcdef0123").unwrap();
        let (cookie, session) = sessions.issue(alice, 1_000).unwrap();
        assert!(!cookie.contains("0123456789abcdef0123"));
        let (u, s) = sessions.check(&users, &cookie, 999).unwrap();
        assert_eq!((u.name.as_str(), &s), ("alice", &session));
        // Expired.
        assert!(sessions.check(&users, &cookie, 1_000).is_none());
        // Another user's name, a later expiry, a changed nonce or MAC: refused.
        let parts: Vec<&str> = cookie.split(':').collect();
        let forged = [
            format!("bob:{}:{}:{}", parts[1], parts[2], parts[3]),
            format!("alice:2000:{}:{}", parts[2], parts[3]),
            format!("alice:{}:{}:{}", parts[1], "0".repeat(32), parts[3]),
            format!("alice:{}:{}:{}", parts[1], parts[2], "0".repeat(64)),
            format!("{cookie}:x"),
            "alice".to_owned(),
        ];
        for f in &forged {
            assert!(sessions.check(&users, f, 0).is_none(), "{f}");
        }
        // The same token gives the same key after a restart: a fresh Sessions accepts it.
        let restarted = Sessions::default();
        let again = Users::parse(FILE).unwrap();
        assert!(restarted.check(&again, &cookie, 0).is_some());
        // A changed token ends the session.
        let changed = Users::parse("alice 0123456789abcdef9999").unwrap();
        assert!(restarted.check(&changed, &cookie, 0).is_none());
        // Signed out.
        sessions.revoke(&session, 0);
        assert!(sessions.check(&users, &cookie, 0).is_none());
        // A request that panicked while it held the sign-outs (the page serves on): the
        // sign-out still holds, and a new session is still accepted and can sign out.
        let poisoned = std::panic::catch_unwind(|| {
            let _held = sessions.revoked.lock().unwrap();
            panic!("a request's bug");
        });
        assert!(poisoned.is_err() && sessions.revoked.is_poisoned());
        assert!(sessions.check(&users, &cookie, 0).is_none());
        let (fresh, fresh_session) = sessions.issue(alice, 1_000).unwrap();
        assert!(sessions.check(&users, &fresh, 0).is_some());
        sessions.revoke(&fresh_session, 0);
        assert!(sessions.check(&users, &fresh, 0).is_none());
    }

    #[test]
    fn the_csrf_token_belongs_to_one_session() {
        let users = Users::parse(FILE).unwrap();
        let sessions = Sessions::default();
        let alice = users.by_token("0123456789abcdef0123").unwrap();
        let (_, s1) = sessions.issue(alice, 1_000).unwrap();
        let (_, s2) = sessions.issue(alice, 1_000).unwrap();
        let (t1, t2) = (
            sessions.csrf_token(alice, &s1),
            sessions.csrf_token(alice, &s2),
        );
        assert_ne!(t1, t2);
        assert_eq!(t1, sessions.csrf_token(alice, &s1));
        let own = Provenance {
            origin: Some("http://127.0.0.1:8210"),
            fetch_site: Some("same-origin"),
            host: Some("127.0.0.1:8210"),
            tls: false,
        };
        assert_eq!(csrf_check(&own, Some(&t1), &t1), Ok(()));
        assert!(csrf_check(&own, Some(&t2), &t1)
            .unwrap_err()
            .contains("does not match"));
        assert!(csrf_check(&own, None, &t1)
            .unwrap_err()
            .contains("no x-csrf-token"));
        // Another origin, even with the right token (a script that somehow had it).
        let other = Provenance {
            origin: Some("http://127.0.0.1:9999"),
            fetch_site: Some("same-site"),
            ..own
        };
        assert!(csrf_check(&other, Some(&t1), &t1)
            .unwrap_err()
            .contains("another site"));
        let other = Provenance {
            fetch_site: None,
            ..other
        };
        assert!(csrf_check(&other, Some(&t1), &t1)
            .unwrap_err()
            .contains("another origin (http://127.0.0.1:9999)"));
        // The scheme is part of the origin.
        let tls = Provenance { tls: true, ..own };
        assert!(same_origin(&tls).is_err());
        // No Origin and no Sec-Fetch-Site (a client that is not a browser): the token decides.
        assert_eq!(csrf_check(&Provenance::default(), Some(&t1), &t1), Ok(()));
    }

    #[test]
    fn headers_are_read_leniently_but_exactly() {
        assert_eq!(bearer("Bearer abc"), Some("abc"));
        assert_eq!(bearer("bearer  abc "), Some("abc"));
        assert_eq!(bearer("Basic abc"), None);
        assert_eq!(
            cookie_value("a=1; surfscan_session=x:y; b=2", COOKIE),
            Some("x:y")
        );
        assert_eq!(cookie_value("xsurfscan_session=1", COOKIE), None);
    }
}
