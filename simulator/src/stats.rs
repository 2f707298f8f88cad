//! Counters of what the emulated instrument was asked and how it answered, shared with the
//! simulator's host (a test or a benchmark): what the wire alone does not show, such as
//! whether a read-out came while the drive was returning.
//!
//! Depends on nothing else in the crate.

use std::sync::atomic::{AtomicU64, Ordering};

/// Counters, each only ever incremented.
#[derive(Debug, Default)]
pub struct SimStats {
    /// Frames that arrived while the host's line speed differed from the instrument's.
    pub frames_at_wrong_rate: AtomicU64,
    /// Result or profile reads answered while the drive was returning.
    pub reads_answered_returning: AtomicU64,
    /// Result or profile reads refused busy (`NG011`) while the drive was returning.
    pub reads_refused_returning: AtomicU64,
}

impl SimStats {
    /// Adds one to a counter.
    pub fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// A counter's value.
    pub fn get(counter: &AtomicU64) -> u64 {
        counter.load(Ordering::Relaxed)
    }
}
