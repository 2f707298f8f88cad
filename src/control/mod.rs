//! The operator's control channel: a Unix socket speaking JSON lines.
//!
//! - [`protocol`]: the wire messages (every message has a `class`) and the server's side of the
//!   in-process contract with the runner (a command channel with replies, a watch channel of
//!   the status snapshots the runner publishes, [`crate::scan::status`]).
//! - [`server`]: binds the socket (refusing a live daemon's, replacing a stale one) and serves
//!   greetings, status, watch streams and forwarded commands with bounded writes and waits.
//! - [`dispatch`]: one request carried out (a status, or a command forwarded to the runner
//!   with a bounded wait), shared by the socket and the station's page ([`crate::web`]).
//! - [`client`]: the command line's side: greeting check, requests, raw lines for `--json`.
//!
//! Layer 4 (process edge): depends on tokio, serde and the scan's status and command types; the
//! scan never depends on this module.

pub mod client;
pub mod dispatch;
pub mod protocol;
pub mod server;
