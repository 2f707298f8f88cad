//! The Mitutoyo SJ-210 family driver: codec, model tables, client, capability probe, recorder.
//!
//! Layers 1–2: the codec and tables are pure; the client is generic over `AsyncRead + AsyncWrite`.
//!
//! - [`codec`]: CR-terminated lines in and out, `OK`/`NG`/malformed classification.
//! - [`models`]: per-model command strings and code tables, config overrides, `RDCON` parsing.
//! - [`settings`]: the `[instrument]` config section.

pub mod codec;
pub mod models;
pub mod settings;
