//! The station on the lab's MQTT broker: its status (retained, on every change and at most
//! once a second), `online`/`offline` (the last will), and the outbox's events and results,
//! each delivered with QoS 1 and removed from the outbox only when the broker acknowledged
//! it.
//!
//! Topics, below `surfscan/<station>/`:
//!
//! | Topic | Retained | Payload |
//! |---|---|---|
//! | `status` | yes | the status as `surfscan status --json` has it, with `station` and `time` |
//! | `online` | yes | `online` at connect; `offline` at a clean stop and, as the last will, when the broker loses the station |
//! | `events` | no | `{"id","kind","scan_id","time","reason","station","scan_dir"}`, the `id` from what it reports ([`super::message_id`]) |
//! | `results` | no | a completed scan's results ([`super::results`]): `scan_id`, `recipe`, `specimen`, `verdict`, per parameter `mean`, `s`, `U`, `warnings`, `files` with SHA-256 |
//! | `commands/<client-id>` | — | read by the daemon: a control request ([`super::commands`]) |
//! | `replies/<client-id>` | no | the answer to each command, as the control socket gives it |
//!
//! The link never touches the scan: it reads the status from its watch channel and the
//! messages from the outbox on disk, and reports its own state in the status's `links`. A
//! broker that cannot be reached, refuses the credentials or presents a certificate that
//! does not verify is named there and in the log, and tried again with backoff (1 s doubling
//! to 30 s). Each connection starts a fresh client, so the outbox is the one place that knows
//! what is still to be sent: the message in flight when a connection broke is sent again,
//! with the same id. A clean stop waits for the broker's acknowledgement of the message in
//! flight (within [`STOP_DEADLINE`]) before it disconnects, so one the broker has taken is
//! removed from the outbox and not sent again at the next start.
//!
//! Commands are carried out one at a time, in their order of arrival, by a task of their own
//! ([`super::commands`]), so a command waiting for the runner never holds up the link.
//!
//! Layer 4 (process edge): depends on rumqttc, [`super::outbox`], [`super::settings`],
//! [`super::tls`], [`super::commands`] and the scan's status type.

use super::commands::{Commands, Incoming};
use super::outbox::{Message, Outbox};
use super::settings::{parse_broker_url, MqttSettings};
use crate::scan::status::{LinkStatus, Status};
use rumqttc::{
    AsyncClient, ConnectReturnCode, ConnectionError, Event, LastWill, MqttOptions, Outgoing,
    Packet, QoS, TlsConfiguration, Transport,
};
use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{mpsc, watch, Notify};
use tokio::time::Instant;

/// The link's name in the status's `links`.
pub const LINK: &str = "mqtt";
/// Least time between two status messages.
const STATUS_EVERY: Duration = Duration::from_secs(1);
/// First wait before connecting again; doubled up to [`MAX_WAIT`].
const FIRST_WAIT: Duration = Duration::from_secs(1);
const MAX_WAIT: Duration = Duration::from_secs(30);
/// How long a clean stop may take to say `offline` and disconnect.
const STOP_DEADLINE: Duration = Duration::from_secs(3);
/// Commands that may wait for the one before them; beyond, a command is dropped and logged.
const COMMANDS_WAITING: usize = 32;

/// The topic root of a station, `surfscan/<station>`.
pub fn root(station: &str) -> String {
    format!("surfscan/{station}")
}

/// The station's link to its broker.
pub struct MqttLink {
    settings: MqttSettings,
    outbox: Arc<Mutex<Outbox>>,
    wake: Arc<Notify>,
    status: watch::Sender<Status>,
    tls: Option<Arc<rustls::ClientConfig>>,
    commands: Option<Commands>,
}

/// The ends of the command task the link talks to.
struct CommandTask {
    to: mpsc::Sender<Incoming>,
    replies: mpsc::UnboundedReceiver<(String, String)>,
}

/// What a published message was, so its acknowledgement can be matched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tag {
    Other,
    Outbox(u64),
}

enum Ended {
    Shutdown,
    Lost { message: String, connected: bool },
}

/// A connection error in words, with what to do.
pub fn describe(url: &str, user: Option<&str>, e: &ConnectionError) -> String {
    match e {
        ConnectionError::ConnectionRefused(
            ConnectReturnCode::BadUserNamePassword | ConnectReturnCode::NotAuthorized,
        ) => format!(
            "the broker {url} refused the station's credentials (user {}): check [mqtt] username and the password in password-file against the broker's password file",
            user.map_or("none".to_owned(), |u| format!("{u:?}"))
        ),
        ConnectionError::ConnectionRefused(ConnectReturnCode::BadClientId) => format!(
            "the broker {url} refused the client id: set [mqtt] client-id to one the broker accepts"
        ),
        ConnectionError::ConnectionRefused(code) => {
            format!("the broker {url} refused the connection ({code:?}); trying again")
        }
        ConnectionError::Tls(t) => format!(
            "TLS with {url} failed: {t}; check that the broker's certificate chains to [mqtt] ca-file (or the system's authorities) and names the host"
        ),
        ConnectionError::Io(io) if io.kind() == std::io::ErrorKind::ConnectionRefused => format!(
            "the broker {url} is not listening (connection refused); is it running? trying again"
        ),
        ConnectionError::Io(io) => format!(
            "the connection to {url} broke: {io}{}; trying again",
            super::sandbox_hint(io)
        ),
        ConnectionError::NetworkTimeout => {
            format!("the broker {url} did not answer in time; trying again")
        }
        other => format!("the connection to {url} broke: {other}; trying again"),
    }
}

impl MqttLink {
    /// A link for these (validated) settings, delivering `outbox` (woken by `wake`) and the
    /// status of `status`, and reading `commands` when given (only a daemon takes them).
    pub fn new(
        settings: MqttSettings,
        outbox: Arc<Mutex<Outbox>>,
        wake: Arc<Notify>,
        status: watch::Sender<Status>,
        commands: Option<Commands>,
    ) -> Result<MqttLink, String> {
        let addr = parse_broker_url(&settings.url)?;
        let tls = if addr.tls {
            Some(super::tls::client_config(settings.ca_file.as_deref())?)
        } else {
            None
        };
        Ok(MqttLink {
            settings,
            outbox,
            wake,
            status,
            tls,
            commands,
        })
    }

    fn topic(&self, leaf: &str) -> String {
        format!("{}/{leaf}", root(&self.settings.station))
    }

    fn queued(&self) -> u64 {
        self.outbox.lock().map_or(0, |o| o.len())
    }

    /// Shows the link's state in the status (and logs a change).
    fn report(&self, ok: bool, message: String) {
        let link = LinkStatus {
            ok,
            message,
            queued: self.queued(),
        };
        self.status.send_if_modified(|s| {
            if s.links.get(LINK) == Some(&link) {
                return false;
            }
            if s.links.get(LINK).map(|l| (&l.message, l.ok)) != Some((&link.message, link.ok)) {
                if link.ok {
                    tracing::info!("mqtt: {}", link.message);
                } else {
                    tracing::warn!("mqtt: {}", link.message);
                }
            }
            s.links.insert(LINK.to_owned(), link);
            true
        });
    }

    fn options(&self) -> Result<MqttOptions, String> {
        let addr = parse_broker_url(&self.settings.url)?;
        let mut o = MqttOptions::new(self.settings.client_id(), addr.host, addr.port);
        o.set_keep_alive(Duration::from_secs(self.settings.keep_alive_s));
        o.set_clean_session(true);
        o.set_max_packet_size(1 << 20, 1 << 20);
        o.set_last_will(LastWill::new(
            self.topic("online"),
            "offline",
            QoS::AtLeastOnce,
            true,
        ));
        if let Some(user) = &self.settings.username {
            // Read at each connection: a corrected password file needs no restart.
            let password = self.settings.password()?.unwrap_or_default();
            o.set_credentials(user.clone(), password);
        }
        if let Some(tls) = &self.tls {
            o.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(
                tls.clone(),
            )));
        }
        Ok(o)
    }

    /// Runs until `shutdown` becomes true: connects, delivers, reconnects with backoff.
    pub async fn run(mut self, mut shutdown: watch::Receiver<bool>) {
        let mut task = self.commands.take().map(|mut c| {
            let (to, mut from) = mpsc::channel::<Incoming>(COMMANDS_WAITING);
            let (reply, replies) = mpsc::unbounded_channel();
            crate::panics::spawn_vital("the MQTT commands", async move {
                while let Some(m) = from.recv().await {
                    if let Some(r) = c.answer(m).await {
                        let _ = reply.send(r);
                    }
                }
            });
            CommandTask { to, replies }
        });
        let mut wait = FIRST_WAIT;
        self.report(false, format!("connecting to {}", self.settings.url));
        loop {
            if *shutdown.borrow() {
                return;
            }
            match self.session(&mut shutdown, task.as_mut()).await {
                Ended::Shutdown => return,
                Ended::Lost { message, connected } => {
                    if connected {
                        wait = FIRST_WAIT;
                    }
                    self.report(false, message);
                    tokio::select! {
                        _ = tokio::time::sleep(wait) => {}
                        _ = shutdown.changed() => {}
                    }
                    wait = (wait * 2).min(MAX_WAIT);
                }
            }
        }
    }

    async fn session(
        &self,
        shutdown: &mut watch::Receiver<bool>,
        mut task: Option<&mut CommandTask>,
    ) -> Ended {
        let options = match self.options() {
            Ok(o) => o,
            Err(message) => {
                return Ended::Lost {
                    message,
                    connected: false,
                }
            }
        };
        let (client, mut events) = AsyncClient::new(options, 64);
        let mut tags: VecDeque<Tag> = VecDeque::new();
        let mut sent: HashMap<u16, Tag> = HashMap::new();
        let mut connected = false;
        let mut inflight: Option<u64> = None;
        let mut status_rx = self.status.subscribe();
        let mut status_open = true;
        let mut last_status = String::new();
        let mut last_status_at: Option<Instant> = None;
        let mut status_due: Option<Instant> = None;
        loop {
            if connected && inflight.is_none() {
                match self.head().await {
                    Ok(Some(m)) => {
                        let payload = serde_json::to_vec(&m.payload).unwrap_or_default();
                        if client
                            .try_publish(self.topic(&m.topic), QoS::AtLeastOnce, false, payload)
                            .is_ok()
                        {
                            tags.push_back(Tag::Outbox(m.seq));
                            inflight = Some(m.seq);
                        }
                    }
                    Ok(None) => {}
                    Err(e) => self.report(
                        false,
                        format!("cannot read the outbox: {e}; messages wait until it can be read"),
                    ),
                }
            }
            let due = status_due.filter(|_| connected);
            tokio::select! {
                r = events.poll() => match r {
                    Ok(Event::Incoming(Packet::ConnAck(_))) => {
                        connected = true;
                        self.report(true, format!("connected to {}", self.settings.url));
                        if client.try_publish(self.topic("online"), QoS::AtLeastOnce, true, "online").is_ok() {
                            tags.push_back(Tag::Other);
                        }
                        if task.is_some() {
                            let filter = super::commands::filter(&root(&self.settings.station));
                            if let Err(e) = client.try_subscribe(filter, QoS::AtLeastOnce) {
                                tracing::error!("mqtt: cannot subscribe to the command topic: {e}; commands wait for the next connection");
                            }
                        }
                        last_status.clear();
                        status_due = Some(Instant::now());
                    }
                    Ok(ev @ (Event::Outgoing(Outgoing::Publish(_)) | Event::Incoming(Packet::PubAck(_)))) => {
                        if self.delivered(&ev, &mut tags, &mut sent).await {
                            inflight = None;
                            self.report(true, format!("connected to {}", self.settings.url));
                        }
                    }
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        if let Some(t) = task.as_deref_mut() {
                            let m = Incoming { topic: p.topic.clone(), payload: p.payload.to_vec(), retained: p.retain };
                            if t.to.try_send(m).is_err() {
                                tracing::warn!("mqtt: command on {} dropped: {COMMANDS_WAITING} commands wait already for the station's answer", p.topic);
                            }
                        }
                    }
                    Ok(_) => {}
                    Err(e) => {
                        let message = describe(&self.settings.url, self.settings.username.as_deref(), &e);
                        return Ended::Lost { message, connected };
                    }
                },
                changed = status_rx.changed(), if status_open => {
                    if changed.is_err() {
                        status_open = false;
                    } else {
                        let earliest = last_status_at.map_or_else(Instant::now, |t| t + STATUS_EVERY);
                        status_due.get_or_insert(earliest.max(Instant::now()));
                    }
                }
                _ = tokio::time::sleep_until(due.unwrap_or_else(Instant::now)), if due.is_some() => {
                    status_due = None;
                    let text = self.status_payload();
                    if text != last_status
                        && client.try_publish(self.topic("status"), QoS::AtLeastOnce, true, text.clone()).is_ok()
                    {
                        tags.push_back(Tag::Other);
                        last_status = text;
                        last_status_at = Some(Instant::now());
                    }
                }
                Some((topic, payload)) = next_reply(task.as_deref_mut()), if connected && task.is_some() => {
                    if client.try_publish(topic, QoS::AtLeastOnce, false, payload).is_ok() {
                        tags.push_back(Tag::Other);
                    }
                }
                _ = self.wake.notified() => {}
                _ = shutdown.changed() => {
                    if connected {
                        self.stop(&client, &mut events, &mut tags, &mut sent).await;
                    }
                    return Ended::Shutdown;
                }
            }
        }
    }

    /// Follows a publish going out (its packet id, for its tag) and an acknowledgement coming
    /// in: true when it acknowledged an outbox message, which is then removed from the outbox.
    async fn delivered(
        &self,
        ev: &Event,
        tags: &mut VecDeque<Tag>,
        sent: &mut HashMap<u16, Tag>,
    ) -> bool {
        match ev {
            Event::Outgoing(Outgoing::Publish(pkid)) => {
                if let Some(tag) = tags.pop_front() {
                    sent.insert(*pkid, tag);
                }
                false
            }
            Event::Incoming(Packet::PubAck(ack)) => match sent.remove(&ack.pkid) {
                Some(Tag::Outbox(seq)) => {
                    if let Err(e) = self.ack(seq).await {
                        tracing::error!("mqtt: cannot remove a delivered message from the outbox: {e}; it will be sent again");
                    }
                    true
                }
                _ => false,
            },
            _ => false,
        }
    }

    /// Says `offline` (a clean disconnect sends no last will), waits for the broker's
    /// acknowledgement of an outbox message in flight (removing it from the outbox, so the next
    /// start does not send it again), and disconnects, each within [`STOP_DEADLINE`].
    async fn stop(
        &self,
        client: &AsyncClient,
        events: &mut rumqttc::EventLoop,
        tags: &mut VecDeque<Tag>,
        sent: &mut HashMap<u16, Tag>,
    ) {
        for (leaf, payload) in [
            ("status", self.status_payload()),
            ("online", "offline".into()),
        ] {
            if client
                .try_publish(self.topic(leaf), QoS::AtLeastOnce, true, payload)
                .is_ok()
            {
                tags.push_back(Tag::Other);
            }
        }
        let outbox_in_flight = |tags: &VecDeque<Tag>, sent: &HashMap<u16, Tag>| {
            tags.iter()
                .chain(sent.values())
                .any(|t| matches!(t, Tag::Outbox(_)))
        };
        let _ = tokio::time::timeout(STOP_DEADLINE, async {
            while outbox_in_flight(tags, sent) {
                match events.poll().await {
                    Ok(ev) => {
                        self.delivered(&ev, tags, sent).await;
                    }
                    Err(_) => break,
                }
            }
        })
        .await;
        let _ = client.try_disconnect();
        let _ = tokio::time::timeout(STOP_DEADLINE, async {
            while let Ok(ev) = events.poll().await {
                if matches!(ev, Event::Outgoing(Outgoing::Disconnect)) {
                    break;
                }
            }
        })
        .await;
    }

    fn status_payload(&self) -> String {
        let status = self.status.borrow().clone();
        let mut v = serde_json::to_value(&status).unwrap_or_default();
        if let Some(o) = v.as_object_mut() {
            o.insert("station".into(), self.settings.station.clone().into());
            o.insert(
                "time".into(),
                chrono::Utc::now()
                    .to_rfc3339_opts(chrono::SecondsFormat::Millis, true)
                    .into(),
            );
        }
        v.to_string()
    }

    async fn head(&self) -> std::io::Result<Option<Message>> {
        let o = self.outbox.clone();
        let (m, damaged) = tokio::task::spawn_blocking(move || held(&o).head())
            .await
            .map_err(std::io::Error::other)??;
        for d in damaged {
            tracing::error!(
                "mqtt: an outbox message could not be read back and was set aside: {}",
                d.display()
            );
        }
        Ok(m)
    }

    async fn ack(&self, seq: u64) -> std::io::Result<()> {
        let o = self.outbox.clone();
        tokio::task::spawn_blocking(move || held(&o).ack(seq))
            .await
            .map_err(std::io::Error::other)?
    }
}

/// The outbox, locked. A panic while it was held (its files half changed, its count
/// unknown) would otherwise leave every later message unstored: the process ends instead
/// ([`crate::panics`]) and reopens the outbox from its files at the next start.
pub(super) fn held(o: &Mutex<Outbox>) -> std::sync::MutexGuard<'_, Outbox> {
    o.lock().unwrap_or_else(|_| {
        crate::panics::exit_internal("a write to the MQTT outbox", "its lock was poisoned")
    })
}

/// The command task's next reply (never, without the task).
async fn next_reply(task: Option<&mut CommandTask>) -> Option<(String, String)> {
    match task {
        Some(t) => t.replies.recv().await,
        None => std::future::pending().await,
    }
}
