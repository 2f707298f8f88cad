//! What leaves the station for the lab's systems: the scan's events through a durable outbox
//! on disk to the publishers (the MQTT broker), the completed scans to the raw-data archive
//! ([`archive`]) and as DFQ and QIF files to the lab's drop directories ([`export`]; what a
//! scan exports is read back from its directory by [`exported`] and formatted by [`dfq`] and
//! [`qif`]), and the metrics on `/metrics`, all off the scan's path.
//!
//! ```text
//! scan runner ──events──► writer task ──► outbox/mqtt/ (disk) ──► MqttLink ──► broker
//!      └──status (watch)────────────────────────────────────────────┘
//! ```
//!
//! The runner only sends an event into an unbounded channel; the writer task stores it in
//! the outbox (each publisher has its own, below `<output dir>/outbox/`) and wakes the
//! publisher, which delivers it when it can. A broker that is down delays a message, never a
//! line; a restart finds what was not yet delivered in the outbox and sends it.
//!
//! Layer 4 (process edge): depends on the configuration, the scan's events and status, and
//! the publishers below.

pub mod archive;
pub mod archive_settings;
pub mod commands;
pub mod dfq;
pub mod export;
pub mod export_settings;
pub mod exported;
pub mod metrics;
pub mod mqtt;
pub mod outbox;
pub mod qif;
pub mod results;
pub mod retention;
pub mod scan_queue;
pub mod settings;
pub mod sweep;
pub mod tls;

use crate::config::Config;
use crate::control::protocol::ControlChannels;
use crate::panics::spawn_vital;
use crate::scan::event::ScanEvent;
use crate::scan::metrics::ScanMetrics;
use crate::scan::status::{LinkStatus, Status};
use outbox::Outbox;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{mpsc, watch, Notify};
use tokio::task::JoinHandle;

/// The outbox directory of a publisher, below the output directory.
pub fn outbox_dir(config: &Config, publisher: &str) -> PathBuf {
    config.output.dir.join("outbox").join(publisher)
}

/// The running publishers of a process (none when nothing is configured).
pub struct Publishers {
    events: Option<mpsc::UnboundedSender<ScanEvent>>,
    sinks: Vec<Sink>,
    writers: Vec<JoinHandle<()>>,
    links: Vec<JoinHandle<()>>,
    stop: watch::Sender<bool>,
    scan_metrics: Option<watch::Sender<ScanMetrics>>,
}

/// A publisher's writer: where its events go, and what it knows for the start-up sweep
/// (none when it keeps no record of the scans it queued).
struct Sink {
    link: &'static str,
    tx: mpsc::UnboundedSender<ScanEvent>,
    known: Option<sweep::Known>,
}

/// What the queue `q` of `link` knows for the start-up sweep; none (and a warning) when its
/// directory cannot be read.
fn known_of<E: scan_queue::ScanEntry>(
    link: &str,
    q: &scan_queue::ScanQueue<E>,
) -> Option<sweep::Known> {
    match q.known() {
        Ok(scans) => Some(sweep::Known {
            since: q.since(),
            scans,
        }),
        Err(e) => {
            tracing::warn!(
                "{link}: cannot list {} ({e}); scans completed while the process was stopping are not looked for",
                q.dir().display()
            );
            None
        }
    }
}

/// What to do about a socket the system refused, when the refusal is the service's sandbox.
pub fn sandbox_hint(e: &std::io::Error) -> &'static str {
    if e.raw_os_error() == Some(libc::EAFNOSUPPORT) {
        " (the service's sandbox forbids network sockets: add the drop-in in systemd/README.md, RestrictAddressFamilies=AF_UNIX AF_INET AF_INET6)"
    } else {
        ""
    }
}

/// Names a part that could not start, in the log and the status's links.
pub fn fail(status: &watch::Sender<Status>, link: &str, message: String) {
    tracing::error!("{link}: {message}");
    set_link(status, link, false, message, 0);
}

/// Sets the status's entry for `link`: whether it works, what to say, how much waits.
pub fn set_link(
    status: &watch::Sender<Status>,
    link: &str,
    ok: bool,
    message: String,
    queued: u64,
) {
    status.send_modify(|s| {
        s.links.insert(
            link.to_owned(),
            LinkStatus {
                ok,
                message,
                queued,
            },
        );
    });
}

impl std::fmt::Debug for Publishers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Publishers")
            .field("links", &self.links.len())
            .finish_non_exhaustive()
    }
}

/// The id of a message about scan `scan_id`: `<station>/<scan id>/<kind>/<time>`, the kind
/// being the event's (`success`, ...) or `results`, and the time when it happened (for an
/// ending, its stop record's, to the microsecond). It is made from what the message reports,
/// not from when it was sent, so the same ending told again (by the start-up sweep, after the
/// process died before it recorded that it had stored it) has the same id, and a consumer
/// that drops a repeated id sees it once.
pub fn message_id(
    station: &str,
    scan_id: &str,
    kind: &str,
    time: chrono::DateTime<chrono::Utc>,
) -> String {
    format!(
        "{station}/{scan_id}/{kind}/{}",
        time.to_rfc3339_opts(chrono::SecondsFormat::Micros, true)
    )
}

/// The members every message about `ev` carries besides its own: its id (for `kind`), the
/// scan, when it happened, the station and the scan directory.
fn about(
    ev: &ScanEvent,
    kind: &str,
    station: &str,
    m: &mut serde_json::Map<String, serde_json::Value>,
) {
    m.insert(
        "id".into(),
        message_id(station, &ev.scan_id, kind, ev.time).into(),
    );
    m.insert("scan_id".into(), ev.scan_id.clone().into());
    m.insert(
        "time".into(),
        ev.time
            .to_rfc3339_opts(chrono::SecondsFormat::Millis, true)
            .into(),
    );
    m.insert("station".into(), station.into());
    m.insert("scan_dir".into(), ev.dir.display().to_string().into());
}

/// The JSON of an event as the publishers send it. `internal: true` only when a bug ended the
/// scan, absent otherwise, as in the stop record and the status's `last_stop`: every other
/// event is what it was before the member existed.
pub fn event_payload(ev: &ScanEvent, station: &str) -> serde_json::Map<String, serde_json::Value> {
    let mut m = serde_json::Map::new();
    m.insert("kind".into(), ev.kind.as_str().into());
    m.insert("reason".into(), ev.reason.clone().into());
    if ev.internal {
        m.insert("internal".into(), true.into());
    }
    about(ev, ev.kind.as_str(), station, &mut m);
    m
}

/// The results message of the completed scan of `ev` (see [`results`]); what could not be
/// read is logged.
fn results_message(ev: &ScanEvent, station: &str) -> serde_json::Map<String, serde_json::Value> {
    let (mut m, problems) = results::read(&ev.scan_id, &ev.dir);
    for p in problems {
        tracing::warn!(
            "mqtt: the results of scan {} lack what {p} would give",
            ev.scan_id
        );
    }
    about(ev, "results", station, &mut m);
    m
}

impl Publishers {
    /// Starts what `config` asks for, reporting into `status`'s links; `control` is where
    /// the MQTT link carries out commands (a daemon's; none for a foreground scan, which
    /// takes none). Must run inside a tokio runtime. A part that cannot start (an outbox that
    /// cannot be opened, an address already in use) is named in the log and in the status's
    /// links; the rest runs.
    pub fn start(
        config: &Config,
        status: &watch::Sender<Status>,
        control: Option<ControlChannels>,
    ) -> Publishers {
        let (stop, stop_rx) = watch::channel(false);
        let (scan_metrics, scan_metrics_rx) = watch::channel(ScanMetrics::default());
        let mut p = Publishers {
            events: None,
            sinks: Vec::new(),
            writers: Vec::new(),
            links: Vec::new(),
            stop,
            scan_metrics: None,
        };
        if let Some(listen) = &config.metrics.listen {
            match std::net::TcpListener::bind(listen)
                .and_then(|l| l.set_nonblocking(true).map(|()| l))
                .and_then(tokio::net::TcpListener::from_std)
            {
                Ok(l) => {
                    // The address bound: with port 0 the one the system picked.
                    let at = l.local_addr().map_or_else(|_| listen.clone(), |a| a.to_string());
                    tracing::info!("metrics on http://{at}/metrics");
                    p.links.push(spawn_vital("the metrics endpoint", metrics::serve(
                        l,
                        status.subscribe(),
                        scan_metrics_rx,
                        stop_rx.clone(),
                    )));
                    p.scan_metrics = Some(scan_metrics);
                }
                Err(e) => fail(
                    status,
                    "metrics",
                    format!(
                        "cannot serve /metrics on {listen}: {e}{}; is another program using the port? ([metrics] listen)",
                        sandbox_hint(&e)
                    ),
                ),
            }
        }
        if let Some(m) = &config.mqtt {
            if let Err(e) = p.start_mqtt(config, m, status, control, stop_rx.clone()) {
                fail(status, mqtt::LINK, e);
            }
        }
        if let Some(a) = &config.archive {
            if let Err(e) = p.start_archive(config, a, status, stop_rx.clone()) {
                fail(status, archive::LINK, e);
            }
        }
        if let Some(x) = &config.export {
            if let Err(e) = p.start_export(config, x, status, stop_rx) {
                fail(status, export::LINK, e);
            }
        }
        p.sweep(config);
        // One channel in, a copy of each event to every publisher's writer.
        let sinks = std::mem::take(&mut p.sinks);
        if !sinks.is_empty() {
            let (tx, mut rx) = mpsc::unbounded_channel::<ScanEvent>();
            p.writers.insert(
                0,
                spawn_vital("the publishers' events", async move {
                    while let Some(ev) = rx.recv().await {
                        for s in &sinks {
                            let _ = s.tx.send(ev.clone());
                        }
                    }
                }),
            );
            p.events = Some(tx);
        }
        p
    }

    /// Hands each publisher the success events it missed ([`sweep`]), before any new event.
    fn sweep(&self, config: &Config) {
        if self.sinks.iter().all(|s| s.known.is_none()) {
            return;
        }
        let survey = match crate::scan::journal::survey(&config.output.dir) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!("the scans could not be listed for the start-up sweep: {e}");
                return;
            }
        };
        for s in &self.sinks {
            let Some(known) = &s.known else { continue };
            for ev in sweep::missed(&survey.succeeded, known) {
                tracing::warn!(
                    "{}: scan {} succeeded, but the process stopped before it was queued; queued now",
                    s.link,
                    ev.scan_id
                );
                let _ = s.tx.send(ev);
            }
        }
    }

    fn start_archive(
        &mut self,
        config: &Config,
        a: &archive_settings::ArchiveSettings,
        status: &watch::Sender<Status>,
        stop_rx: watch::Receiver<bool>,
    ) -> Result<(), String> {
        let target = a.validate().map_err(|(key, m)| format!("{key}: {m}"))?;
        let dir = outbox_dir(config, "archive");
        let queue = archive::Queue::open(&dir).map_err(|e| {
            format!(
                "cannot open the archive queue {}: {}; nothing is archived until this is fixed and the process restarted",
                dir.display(),
                crate::atomic::write_hint(&dir, &e)
            )
        })?;
        let wake = Arc::new(Notify::new());
        let archiver = archive::Archiver::new(
            a.clone(),
            target,
            queue.clone(),
            status.clone(),
            wake.clone(),
        );
        self.links
            .push(spawn_vital("the archive", archiver.run(stop_rx)));
        self.queue_successes(
            "archive",
            known_of(archive::LINK, &queue),
            move |id, dir| queue.push(id, dir),
            wake,
            |ev, e| {
                format!(
                    "archive: scan {} could not be queued for the archive: {e}; copy {} by hand",
                    ev.scan_id,
                    ev.dir.display()
                )
            },
        );
        Ok(())
    }

    /// Queues each completed scan on disk with `push` (off the runtime's threads) and wakes
    /// the worker that drains the queue; a scan that cannot be queued is logged with
    /// `unqueued`'s words, which say what to do by hand.
    fn queue_successes<P>(
        &mut self,
        link: &'static str,
        known: Option<sweep::Known>,
        push: P,
        wake: Arc<Notify>,
        unqueued: fn(&ScanEvent, &std::io::Error) -> String,
    ) where
        P: Fn(&str, &Path) -> std::io::Result<PathBuf> + Clone + Send + Sync + 'static,
    {
        let (tx, mut rx) = mpsc::unbounded_channel::<ScanEvent>();
        self.writers.push(spawn_vital(link, async move {
            while let Some(ev) = rx.recv().await {
                if ev.kind != crate::scan::event::ScanEventKind::Success {
                    continue;
                }
                let push = push.clone();
                let (id, dir) = (ev.scan_id.clone(), ev.dir.clone());
                match tokio::task::spawn_blocking(move || push(&id, &dir)).await {
                    Ok(Ok(_)) => wake.notify_one(),
                    Ok(Err(e)) => tracing::error!("{}", unqueued(&ev, &e)),
                    Err(e) => tracing::error!("{link}: {e}"),
                }
            }
        }));
        self.sinks.push(Sink { link, tx, known });
    }

    fn start_export(
        &mut self,
        config: &Config,
        x: &export_settings::ExportSettings,
        status: &watch::Sender<Status>,
        stop_rx: watch::Receiver<bool>,
    ) -> Result<(), String> {
        let dir = outbox_dir(config, "export");
        let queue = export::Queue::open(&dir).map_err(|e| {
            format!(
                "cannot open the export queue {}: {}; nothing is exported until this is fixed and the process restarted",
                dir.display(),
                crate::atomic::write_hint(&dir, &e)
            )
        })?;
        let wake = Arc::new(Notify::new());
        let exporter =
            export::Exporter::new(x.clone(), queue.clone(), status.clone(), wake.clone());
        self.links
            .push(spawn_vital("the export", exporter.run(stop_rx)));
        self.queue_successes(
            "export",
            known_of(export::LINK, &queue),
            move |id, dir| queue.push(id, dir),
            wake,
            |ev, e| {
                format!(
                    "export: scan {} could not be queued for export: {e}; export it by hand with `surfscan export {}`",
                    ev.scan_id,
                    ev.dir.display()
                )
            },
        );
        Ok(())
    }

    fn start_mqtt(
        &mut self,
        config: &Config,
        m: &settings::MqttSettings,
        status: &watch::Sender<Status>,
        control: Option<ControlChannels>,
        stop_rx: watch::Receiver<bool>,
    ) -> Result<(), String> {
        let dir = outbox_dir(config, "mqtt");
        let outbox = Outbox::open(&dir, m.outbox_max).map_err(|e| {
            format!(
                "cannot open the outbox {}: {}; nothing is published until this is fixed and the process restarted",
                dir.display(),
                crate::atomic::write_hint(&dir, &e)
            )
        })?;
        let outbox = Arc::new(Mutex::new(outbox));
        // The scans whose results were stored in the outbox, for the start-up sweep.
        let ledger_dir = outbox_dir(config, "mqtt-results");
        let ledger = sweep::ResultsLedger::open(&ledger_dir).map_err(|e| {
            format!(
                "cannot open {}: {}; nothing is published until this is fixed and the process restarted",
                ledger_dir.display(),
                crate::atomic::write_hint(&ledger_dir, &e)
            )
        })?;
        let known = known_of(mqtt::LINK, &ledger);
        let wake = Arc::new(Notify::new());
        let commands =
            control.map(|c| commands::Commands::new(mqtt::root(&m.station), m.commands, c));
        let link = mqtt::MqttLink::new(
            m.clone(),
            outbox.clone(),
            wake.clone(),
            status.clone(),
            commands,
        )?;
        self.links
            .push(spawn_vital("the MQTT link", link.run(stop_rx)));
        let (tx, mut rx) = mpsc::unbounded_channel::<ScanEvent>();
        let station = m.station.clone();
        let status = status.clone();
        self.writers.push(spawn_vital("the MQTT outbox's writer", async move {
            while let Some(ev) = rx.recv().await {
                let o = outbox.clone();
                let (st, e) = (station.clone(), ev.clone());
                let ledger = ledger.clone();
                let stored = tokio::task::spawn_blocking(move || {
                    let success = e.kind == crate::scan::event::ScanEventKind::Success;
                    let mut messages = vec![("events", event_payload(&e, &st))];
                    if success {
                        messages.push(("results", results_message(&e, &st)));
                    }
                    let mut dropped = 0;
                    for (topic, payload) in messages {
                        dropped += mqtt::held(&o).push(topic, payload)?;
                    }
                    if success {
                        // After the outbox: a process killed between the two sends the
                        // results again (with the same ids) at its next start rather than
                        // never.
                        let entry = ledger.push(&e.scan_id, &e.dir)?;
                        ledger.finish(&entry).map_err(std::io::Error::other)?;
                    }
                    Ok::<_, std::io::Error>(dropped)
                })
                .await
                .map_err(std::io::Error::other)
                .and_then(|r| r);
                let queued = outbox.lock().map_or(0, |o| o.len());
                status.send_if_modified(|s| match s.links.get_mut(mqtt::LINK) {
                    Some(l) if l.queued != queued => {
                        l.queued = queued;
                        true
                    }
                    _ => false,
                });
                match stored {
                    Ok(dropped) if dropped > 0 => tracing::warn!(
                        "mqtt: the outbox is full; the {dropped} oldest undelivered message(s) were dropped (raise [mqtt] outbox-max or bring the broker back)"
                    ),
                    Ok(_) => {}
                    Err(e) => tracing::error!(
                        "mqtt: event {} of scan {} could not be stored in the outbox and will not be published: {e}",
                        ev.kind,
                        ev.scan_id
                    ),
                }
                wake.notify_one();
            }
        }));
        self.sinks.push(Sink {
            link: mqtt::LINK,
            tx,
            known,
        });
        Ok(())
    }

    /// Where the scan's metrics go (none without an endpoint).
    pub fn scan_metrics(&self) -> Option<watch::Sender<ScanMetrics>> {
        self.scan_metrics.clone()
    }

    /// Where events for the publishers go (none when none runs). The writer stores what
    /// arrives until every clone is dropped.
    pub fn sender(&self) -> Option<mpsc::UnboundedSender<ScanEvent>> {
        self.events.clone()
    }

    /// Stores what is still in the channel, then stops the links (each says `offline`),
    /// within `deadline` in all.
    pub async fn finish(mut self, deadline: Duration) {
        let end = tokio::time::Instant::now() + deadline;
        self.events = None;
        for w in self.writers.drain(..) {
            let _ = tokio::time::timeout_at(end, w).await;
        }
        let _ = self.stop.send(true);
        for l in self.links.drain(..) {
            let _ = tokio::time::timeout_at(end, l).await;
        }
    }
}
