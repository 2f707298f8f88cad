//! Jobs: what a lab asks of a station beyond one scan of the configured plan.
//!
//! - [`recipe`]: named recipe files (plan, measuring conditions, analysis, specification),
//!   validated against the station's configuration;
//! - [`queue`]: the durable job queue the daemon runs one job after another from;
//! - [`index`]: the SQLite index of the station's scans behind `surfscan list`, rebuilt from
//!   the journals; [`synthetic`]: scan directories for its tests and benchmark;
//! - [`service`]: the daemon's keeper of the queue, serving the operator's queue commands.
//!
//! Layer 4 (process edge): depends on [`crate::config`], [`crate::specification`] and the
//! scan's vocabulary; reads and writes files of its own.

pub mod index;
pub mod queue;
pub mod recipe;
pub mod service;
pub mod synthetic;
