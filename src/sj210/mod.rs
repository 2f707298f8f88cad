//! The Mitutoyo SJ-210 family driver: codec, model tables, client, capability probe, recorder.
//!
//! Layers 1–2: the codec and tables are pure; the client is generic over `AsyncRead + AsyncWrite`.
//!
//! - [`codec`]: CR-terminated lines in and out, `OK`/`NG`/malformed classification.
//! - [`models`]: per-model command strings and code tables, config overrides, `RDCON` parsing.
//! - [`error`]: the two-layer error (conversation failed / instrument said NG) and trace failures.
//! - [`client`]: the client over any byte stream, probe and trace; implements `Instrument`.
//! - [`recorder`]: tees a conversation into a replayable transcript (format v1).
//! - [`settings`]: the `[instrument]` config section.

pub mod client;
pub mod codec;
pub mod error;
pub mod models;
pub mod recorder;
pub mod settings;
