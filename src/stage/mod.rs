//! The y stage: GRBL and Zaber drivers behind a thin `Stage` trait, and the shared motion policy.
//!
//! Layers 1–2: codecs are pure; drivers are generic over `AsyncRead + AsyncWrite`.
