//! The Mitutoyo SJ-210 family driver: codec, model tables, client, capability probe, recorder.
//!
//! Layers 1–2: the codec and tables are pure; the client is generic over `AsyncRead + AsyncWrite`.
//!
//! - [`codec`]: CR-terminated lines in and out, `OK`/`NG`/malformed classification.

pub mod codec;
