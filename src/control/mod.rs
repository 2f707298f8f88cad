//! The operator's control channel: a Unix socket speaking JSON lines.
//!
//! - [`protocol`]: the wire messages (every message has a `class`), the status snapshot the
//!   scan runner publishes, and the in-process contract between the socket server and the
//!   runner (a command channel with replies, a watch channel of status).
//! - [`server`]: binds the socket (refusing a live daemon's, replacing a stale one) and serves
//!   greetings, status, watch streams and forwarded commands with bounded writes and waits.
//! - [`client`]: the command line's side: greeting check, requests, raw lines for `--json`.
//!
//! Layer 4 (process edge): depends on tokio channels and serde; the runner depends on
//! [`protocol`], never the other way round.

pub mod client;
pub mod protocol;
pub mod server;
