//! The scan: plan, durable line storage and journal, resume, and the runner that drives instrument, stage and fitter.
//!
//! Layer 3: depends on the device contracts ([`crate::devices`]), the fitter, the IGES writer,
//! the status types of [`crate::control::protocol`] and the settings of [`crate::config`].
//!
//! - [`plan`]: the lines to trace and the surface to fit, frozen in the journal.
//! - [`station`]: opening the instrument and the stage; device errors reduced to a `Fault`.
//! - [`runner`]: one scan, new or resumed, to its end: per-line durability, faults by class,
//!   suspension and reconnection, pause/abort, shutdown.
//! - [`store`]: the scan directory, durable line files, reading lines back, pre-flight disk check.
//! - [`journal`]: `journal.jsonl` records, torn-tail recovery, resume state.
//! - [`outputs`]: IGES and report of a completed scan.
//! - [`metrics`]: the Prometheus text-format metrics file.
//! - [`hook`]: the notification command run when a scan completes, fails or suspends.
//! - [`testhooks`]: crash and full-disk injection for end-to-end tests.

pub mod hook;
pub mod journal;
pub mod metrics;
pub mod outputs;
pub mod plan;
pub mod runner;
pub mod station;
pub mod store;
pub mod testhooks;
