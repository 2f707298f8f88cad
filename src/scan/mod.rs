//! The scan: plan, durable line storage and journal, resume, and the runner that drives
//! instrument, stage and fitter.
//!
//! Layer 3 (session): depends on the device contracts ([`crate::devices`]) and drivers, the
//! fitter, the IGES writer and [`crate::atomic`]; never on the configuration file or the
//! control socket (the composition layer hands the runner typed [`settings`], and the socket
//! serves the runner's [`status`] and forwards [`command`]s).
//!
//! - [`plan`]: the lines to trace, the surface to fit and how the lines are characterised,
//!   frozen in the journal, and its disk estimate; [`expected`]: the measuring conditions a
//!   job expects.
//! - [`settings`]: what the runner is told by the composition layer.
//! - [`status`], [`command`], [`event`]: the snapshots the runner publishes, the operator
//!   commands it takes, the events it reports (for the notification hook).
//! - [`station`]: opening the instrument and the stage; device errors reduced to a `Fault`;
//!   [`frozen`]: the settings that shape a resumed scan's lines, taken from its start record.
//! - [`machine`]: the sans-IO session core: events (with the time) in, actions out (the
//!   transient budget, suspension, disk full, pause/abort, shutdown); [`policy`]: the fault
//!   policy as one table (fault kind × situation → reaction) the machine asks, and the
//!   backoff; [`reasons`]: the texts of faults and suspensions, apart from the decisions.
//! - [`runner`]: performs the machine's actions on devices ([`device_ops`]), disk
//!   ([`disk_ops`]) and channels;
//!   [`channels`]: its connection to the outside; [`outcome`]: what it is asked and what it
//!   returns; [`ending`]: how a scan ended, the one value the stop record, the status, the
//!   events and the exit status derive from; [`line_check`]: whether a traced line fits; [`opening`]: creating or reopening a scan directory; [`ledger`]: the
//!   running scan's journal, lines and fitter.
//! - [`store`]: the scan directory; [`line`](mod@line) and [`line_csv`]: a stored line's metadata and
//!   heights file; [`scan_id`]: the scan's name; [`store_error`]: what can go wrong there;
//!   [`disk`]: the pre-flight disk check; [`faults`]: the storage fault hook.
//! - [`journal`]: `journal.jsonl` records, torn-tail recovery, resume state.
//! - [`results`]: a completed scan's verdict, means and warnings in a few figures.
//! - [`outputs`]: what a completed scan writes from memory (IGES via [`surface_files`], with
//!   [`traceability`]; the report through the [`outputs::Characterise`] contract).
//! - [`metrics`]: the numbers a station is monitored by, as Prometheus text;
//!   [`metrics_file`]: that text written durably.
//! - [`testhooks`]: crash and full-disk injection for end-to-end tests.

pub mod channels;
pub mod choice;
pub mod command;
pub mod device_ops;
pub mod disk;
pub mod disk_ops;
pub mod ending;
pub mod event;
pub mod expected;
pub mod faults;
pub mod frozen;
pub mod journal;
pub mod ledger;
pub mod line;
pub mod line_check;
pub mod line_csv;
pub mod machine;
pub mod metrics;
pub mod metrics_file;
pub mod opening;
pub mod outcome;
pub mod outputs;
pub mod plan;
pub mod policy;
pub mod reasons;
pub mod results;
pub mod runner;
pub mod scan_id;
pub mod settings;
pub mod station;
pub mod status;
pub mod store;
pub mod store_error;
pub mod surface_files;
pub mod testhooks;
pub mod traceability;
