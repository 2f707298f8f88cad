//! The Mitutoyo SJ-210 family driver.
//!
//! Pure (layer 1), bytes and strings in, values out:
//! - [`codec`]: CR-terminated lines in and out, `OK`/`NG`/malformed classification.
//! - [`ng`]: the NG code table (one for every model) and [`ng::NgCode`].
//! - [`replies`]: what an `OK` payload means (codes, counts, results, profile blocks).
//! - [`sampling`]: the x pitch of the exported profile and the point count a trace must have.
//! - [`timing`]: how long a trace's phases take, when to ask the status, the deadline.
//! - [`sanity`]: checks of a read-out (repeated blocks, the instrument's Ra against ours).
//! - [`readout_probe`]: judging the candidate read-out forms and what to configure.
//! - [`return_reads`]: judging whether reads are answered while the drive returns.
//! - [`rate_search`]: the baud rates and parities to try when the configured ones get no
//!   answer, the lines to paste, and a read-out's wire time at each rate.
//! - [`models`]: per-model command strings and code tables, config overrides, `RDCON`.
//! - [`sources`]: the documents the tables cite.
//! - [`error`]: the two-layer error (conversation failed / instrument said NG) and trace
//!   failures.
//!
//! I/O adapters (layer 2), generic over `AsyncRead + AsyncWrite`:
//! - [`client`]: the client, probe and trace; implements `Instrument`.
//! - [`recorder`]: tees a conversation into a replayable transcript (format v1).
//!
//! Settings (layer 4): [`settings`], the `[instrument]` config section.

pub mod client;
pub mod codec;
pub mod error;
pub mod models;
pub mod ng;
pub mod rate_search;
pub mod readout_probe;
pub mod recorder;
pub mod replies;
pub mod return_reads;
pub mod sampling;
pub mod sanity;
pub mod settings;
pub mod sources;
pub mod timing;
