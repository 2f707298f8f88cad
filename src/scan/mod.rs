//! The scan: plan, durable line storage and journal, resume, and the runner that drives instrument, stage and fitter.
//!
//! Layer 3: depends on the device contracts ([`crate::devices`]), the fitter and the IGES writer.
//!
//! - [`store`]: the scan directory, durable line files, reading lines back, pre-flight disk check.
//! - [`journal`]: `journal.jsonl` records, torn-tail recovery, resume state.
//! - [`metrics`]: the Prometheus text-format metrics file.

pub mod hook;
pub mod journal;
pub mod metrics;
pub mod store;
