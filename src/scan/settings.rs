//! What the scan runner is told by the composition layer: the plan of a new scan and the
//! station's settings that concern the session, already validated and typed. The runner never
//! sees the configuration file; the frozen copy of it in the start record is opaque
//! traceability.
//!
//! Layer 3 (session): depends on [`super::plan`], [`super::policy`] (the backoff),
//! [`super::outputs`] and [`super::testhooks`].

use super::outputs::Characterise;
use super::plan::Plan;
use super::policy::Backoff;
use super::testhooks::TestHooks;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// What the runner needs besides devices and control.
#[derive(Clone)]
pub struct RunSettings {
    /// The plan of a new scan (a resumed scan follows the plan frozen in its journal).
    pub plan: Plan,
    /// Directory holding one sub-directory per scan (created if missing).
    pub output_dir: PathBuf,
    /// Home the stage before the first line of a new scan even when its position is trusted.
    pub home_on_start: bool,
    /// Baud rate of the instrument's link, for the pre-flight estimate of a line's duration.
    pub instrument_baud: u32,
    /// Backoff of reconnection tries, transient retries and free-space checks.
    pub backoff: Backoff,
    /// How long transient faults may go on, from the first one since the last committed
    /// line, before the scan fails (`[scan] transient-budget-s`).
    pub transient_budget: Duration,
    /// The longest one device operation can take (a trace with its read-out at the link's
    /// baud, a move, a home): one that outlasts it is stuck, and the watchdog goes unfed.
    pub longest_effect: Duration,
    /// The Prometheus textfile written after every line, if any.
    pub metrics_file: Option<PathBuf>,
    /// The configuration as loaded, frozen into the start record for traceability (opaque
    /// to the session: it follows `plan`, never this copy).
    pub config: serde_json::Value,
    /// SHA-256 of the configuration file, hex.
    pub config_hash: String,
    /// Fault injection (tests only; none in production).
    pub hooks: Arc<TestHooks>,
    /// The characterisation run when a scan completes (none: the report holds the fit and
    /// the instrument's own results only).
    pub characterise: Option<Arc<dyn Characterise>>,
}

impl std::fmt::Debug for RunSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunSettings")
            .field("plan", &self.plan)
            .field("output_dir", &self.output_dir)
            .field("home_on_start", &self.home_on_start)
            .field("instrument_baud", &self.instrument_baud)
            .field("backoff", &self.backoff)
            .field("transient_budget", &self.transient_budget)
            .field("longest_effect", &self.longest_effect)
            .field("metrics_file", &self.metrics_file)
            .field("config_hash", &self.config_hash)
            .field("hooks", &self.hooks)
            .field("characterise", &self.characterise.is_some())
            .finish_non_exhaustive()
    }
}
