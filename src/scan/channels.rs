//! The runner's connection to the outside: operator commands in (each with its reply
//! channel), shutdown, status snapshots out, the systemd watchdog, and scan events for the
//! notification hook.
//!
//! Layer 3 (session): depends on tokio's channels and the session's command, status and
//! event types.

use super::command::OperatorRequest;
use super::event::ScanEvent;
use super::metrics::ScanMetrics;
use super::status::Status;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, watch};

/// The runner's connection to the outside: commands in, status out, watchdog, shutdown.
pub struct Control {
    /// Operator commands (from the control socket; a closed channel means none).
    pub commands: mpsc::Receiver<OperatorRequest>,
    /// Becomes `true` on SIGTERM/SIGINT.
    pub shutdown: watch::Receiver<bool>,
    /// Where status snapshots are published.
    pub status: watch::Sender<Status>,
    /// Called at `watchdog_interval` from inside the scan loop (systemd `WATCHDOG=1`).
    pub watchdog: Option<(Duration, Arc<dyn Fn() + Send + Sync>)>,
    /// Scan events (started, suspended, resumed, complete, fail, abort) for the
    /// notification hook and the publishers.
    pub events: Option<mpsc::UnboundedSender<ScanEvent>>,
    /// The scan's metrics as they change, for the `/metrics` endpoint.
    pub metrics: Option<watch::Sender<ScanMetrics>>,
}

impl std::fmt::Debug for Control {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Control")
            .field("watchdog", &self.watchdog.as_ref().map(|w| w.0))
            .finish_non_exhaustive()
    }
}

impl Control {
    /// A control with the given channels, no watchdog and no event sink.
    pub fn new(
        commands: mpsc::Receiver<OperatorRequest>,
        shutdown: watch::Receiver<bool>,
        status: watch::Sender<Status>,
    ) -> Control {
        Control {
            commands,
            shutdown,
            status,
            watchdog: None,
            events: None,
            metrics: None,
        }
    }

    /// Publishes a snapshot. The links' states are the publishers' and stay as they are.
    pub(super) fn publish(&self, mut s: Status) {
        self.status.send_modify(|cur| {
            s.links = std::mem::take(&mut cur.links);
            *cur = s;
        });
    }

    /// Tells the notification hook and the publishers.
    pub(super) fn event(&self, event: ScanEvent) {
        if let Some(tx) = &self.events {
            let _ = tx.send(event);
        }
    }

    /// Hands the scan's metrics to the endpoint.
    pub(super) fn metrics(&self, m: &ScanMetrics) {
        if let Some(tx) = &self.metrics {
            tx.send_replace(m.clone());
        }
    }

    /// True once SIGTERM/SIGINT arrived.
    pub(super) fn shutting_down(&self) -> bool {
        *self.shutdown.borrow()
    }

    /// The watchdog ticker (hourly, i.e. idle, without a watchdog).
    pub(super) fn watchdog_tick(&self) -> tokio::time::Interval {
        let period = self
            .watchdog
            .as_ref()
            .map_or(Duration::from_secs(3600), |w| w.0);
        tokio::time::interval(period)
    }

    /// Feeds the watchdog.
    pub(super) fn pet(&self) {
        if let Some((_, f)) = &self.watchdog {
            f();
        }
    }
}
