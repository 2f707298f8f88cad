//! The control-socket server: binds the Unix socket (refusing to steal a live daemon's,
//! replacing a stale one), greets every connection, answers `status`, streams `watch`, and
//! forwards operator commands to the scan runner with a bounded wait for its answer.
//!
//! Every write to a client is bounded in time: a client that does not read (a stuck `watch`
//! terminal, a suspended pipe) is disconnected instead of having messages queued for it, so
//! no client can make the daemon's memory grow or delay the others. Status is read from a
//! `watch` channel, which keeps only the latest snapshot, so a watcher that falls behind
//! skips intermediate snapshots rather than accumulating them.
//!
//! The operator always gets through: a client that sends no complete request within
//! [`ServerOptions::request_timeout`] of connecting (or of its last answer) is dropped, and a
//! watcher is exempt only while it watches; watchers may hold all but
//! [`ServerOptions::reserved_for_requests`] of the slots; and when every slot is taken, the
//! connection that has waited longest without sending a request makes room for the new one.
//! Requests are checked strictly (an unknown field is refused, not ignored), each command
//! carries the sender's credentials from the kernel ([`Peer`]) to the runner, and
//! [`ServerOptions::allowed_groups`] narrows who may command; status and watch stay open to
//! everyone who can open the socket.
//!
//! Layer 4 (process edge): depends on [`super::protocol`], the scan's status and command types,
//! tokio and tokio-util's codec, nix for group names, and libc for the peer's groups
//! (`SO_PEERGROUPS`, which no crate wraps).

use super::dispatch::{dispatch, status_with_queue};
use super::protocol::{ControlChannels, Message, Request, PROTOCOL_VERSION};
use crate::scan::command::Peer;
use bytes::{Buf, BytesMut};
use futures::StreamExt;
use serde::Deserialize;
use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::os::unix::io::AsRawFd;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::io::AsyncWriteExt;
use tokio::net::unix::OwnedWriteHalf;
use tokio::net::{UnixListener, UnixStream};
use tokio::sync::Notify;
use tokio::task::JoinSet;
use tokio::time::Instant;
use tokio_util::codec::{Decoder, FramedRead};

/// Mode of the control socket: the daemon's user and group (operators join the group).
pub const SOCKET_MODE: u32 = 0o660;

/// Limits of the server; [`ServerOptions::default`] documents the values the daemon uses.
#[derive(Debug, Clone)]
pub struct ServerOptions {
    /// Longest request line accepted, bytes (default 64 KiB). Longer lines are discarded up to
    /// their newline and answered with an error; the connection stays usable.
    pub max_line_bytes: usize,
    /// How long one write to a client may take before that client is disconnected
    /// (default 2 s).
    pub write_timeout: Duration,
    /// How long to wait for the runner to answer a forwarded command (default 10 s).
    pub reply_timeout: Duration,
    /// Connections served at once (default 32). When all are taken, the one that has waited
    /// longest without sending a request is dropped for the newcomer; when none is waiting
    /// (all watch or have a request in progress), the newcomer gets an error and is closed.
    pub max_connections: usize,
    /// How long a client may take to send a complete request line after the greeting or
    /// after its last answer (default 5 s) before it is told so and dropped. A client
    /// dripping bytes without a newline is dropped just the same; watchers are exempt.
    pub request_timeout: Duration,
    /// Slots of `max_connections` that watchers may not take (default 4), so status and
    /// commands get through however many watchers there are.
    pub reserved_for_requests: usize,
    /// Group ids whose members may command (start, pause, resume, abort): the peer's primary
    /// or supplementary groups as the kernel reports them for the connection. `None`
    /// (default): everyone who can open the socket.
    pub allowed_groups: Option<Vec<u32>>,
}

impl Default for ServerOptions {
    fn default() -> ServerOptions {
        ServerOptions {
            max_line_bytes: 64 * 1024,
            write_timeout: Duration::from_secs(2),
            reply_timeout: Duration::from_secs(10),
            max_connections: 32,
            request_timeout: Duration::from_secs(5),
            reserved_for_requests: 4,
            allowed_groups: None,
        }
    }
}

/// Why the control socket could not be set up. Each message names the path and what to do.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// The socket's directory is missing and could not be created.
    #[error("cannot create the control socket's directory {dir}: {source}; create it (the unit's RuntimeDirectory=surfscan does) or set [control] socket to a writable place")]
    CreateDir {
        /// The directory.
        dir: PathBuf,
        /// The cause.
        source: io::Error,
    },
    /// Something that is not a socket sits at the socket path.
    #[error(
        "{path} exists and is not a socket; remove it or set [control] socket to another path"
    )]
    NotASocket {
        /// The path.
        path: PathBuf,
    },
    /// Another process answers on the socket.
    #[error("another surfscan daemon is running: {path} answers connections; stop it (systemctl stop surfscan) or set [control] socket to another path")]
    AlreadyRunning {
        /// The path.
        path: PathBuf,
    },
    /// The existing socket could not be checked for a live daemon.
    #[error("cannot tell whether a daemon is listening on {path}: {source}; check its owner and permissions, stop any daemon using it, then remove it")]
    Probe {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
    /// A stale socket file could not be removed.
    #[error("cannot remove the stale control socket {path}: {source}; remove it by hand")]
    RemoveStale {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
    /// Binding failed.
    #[error("cannot bind the control socket {path}: {source}; check that its directory is writable by the daemon's user or set [control] socket to another path")]
    Bind {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
    /// The socket's mode could not be set.
    #[error("cannot set mode 0660 on the control socket {path}: {source}")]
    Permissions {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
}

/// A bound control socket, ready to [`serve`](ControlServer::serve).
#[derive(Debug)]
pub struct ControlServer {
    listener: UnixListener,
    path: PathBuf,
    /// Inode of the socket file this server created, so shutdown removes only its own file.
    inode: Option<(u64, u64)>,
    options: ServerOptions,
}

/// Binds the control socket at `path` with [`ServerOptions::default`].
pub async fn bind(path: &Path) -> Result<ControlServer, ControlError> {
    bind_with_options(path, ServerOptions::default()).await
}

/// Binds the control socket at `path`: creates the parent directory if missing, refuses if
/// a live daemon answers on an existing socket, removes a stale one, binds and sets mode
/// [`SOCKET_MODE`].
pub async fn bind_with_options(
    path: &Path,
    options: ServerOptions,
) -> Result<ControlServer, ControlError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.exists() {
            std::fs::create_dir_all(dir).map_err(|source| ControlError::CreateDir {
                dir: dir.to_owned(),
                source,
            })?;
        }
    }
    match std::fs::symlink_metadata(path) {
        Ok(meta) if !meta.file_type().is_socket() => {
            return Err(ControlError::NotASocket {
                path: path.to_owned(),
            })
        }
        Ok(_) => clear_stale(path).await?,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(source) => {
            return Err(ControlError::Probe {
                path: path.to_owned(),
                source,
            })
        }
    }
    let listener = UnixListener::bind(path).map_err(|source| {
        if source.kind() == io::ErrorKind::AddrInUse {
            ControlError::AlreadyRunning {
                path: path.to_owned(),
            }
        } else {
            ControlError::Bind {
                path: path.to_owned(),
                source,
            }
        }
    })?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(SOCKET_MODE)).map_err(
        |source| ControlError::Permissions {
            path: path.to_owned(),
            source,
        },
    )?;
    let inode = std::fs::symlink_metadata(path)
        .ok()
        .map(|m| (m.dev(), m.ino()));
    tracing::info!(socket = %path.display(), "control socket bound");
    Ok(ControlServer {
        listener,
        path: path.to_owned(),
        inode,
        options,
    })
}

/// The group ids of `[control] allowed-groups`: each entry is a group name, or a numeric id
/// taken as it is. An unknown name is an error naming it.
pub fn resolve_groups(names: &[String]) -> Result<Vec<u32>, String> {
    names
        .iter()
        .map(|name| {
            if let Ok(gid) = name.trim().parse::<u32>() {
                return Ok(gid);
            }
            match nix::unistd::Group::from_name(name.trim()) {
                Ok(Some(g)) => Ok(g.gid.as_raw()),
                Ok(None) => Err(format!(
                    "no group named {name:?} on this system; create it (groupadd) or correct the name"
                )),
                Err(e) => Err(format!("cannot look up group {name:?}: {e}")),
            }
        })
        .collect()
}

/// An existing socket file: refuse if something answers, remove it if nothing does.
async fn clear_stale(path: &Path) -> Result<(), ControlError> {
    let probe = tokio::time::timeout(Duration::from_secs(2), UnixStream::connect(path)).await;
    match probe {
        Ok(Ok(_live)) => Err(ControlError::AlreadyRunning {
            path: path.to_owned(),
        }),
        Ok(Err(e)) if e.kind() == io::ErrorKind::ConnectionRefused => {
            tracing::info!(socket = %path.display(), "removing stale control socket (nothing answers)");
            match std::fs::remove_file(path) {
                Ok(()) => Ok(()),
                Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
                Err(source) => Err(ControlError::RemoveStale {
                    path: path.to_owned(),
                    source,
                }),
            }
        }
        Ok(Err(e)) if e.kind() == io::ErrorKind::NotFound => Ok(()),
        Ok(Err(source)) => Err(ControlError::Probe {
            path: path.to_owned(),
            source,
        }),
        Err(_elapsed) => Err(ControlError::Probe {
            path: path.to_owned(),
            source: io::Error::new(
                io::ErrorKind::TimedOut,
                "a process accepts connections but did not complete one within 2 s",
            ),
        }),
    }
}

impl ControlServer {
    /// Where the socket is.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Accepts connections until `shutdown` completes, then closes every connection and
    /// removes the socket file (if it is still the one this server created).
    pub async fn serve(self, channels: ControlChannels, shutdown: impl Future<Output = ()>) {
        let ControlServer {
            listener,
            path,
            inode,
            options,
        } = self;
        let slots = Arc::new(Slots::new(&options));
        let options = Arc::new(options);
        let mut connections = JoinSet::new();
        tokio::pin!(shutdown);
        loop {
            tokio::select! {
                () = &mut shutdown => break,
                Some(_) = connections.join_next(), if !connections.is_empty() => {}
                accepted = listener.accept() => match accepted {
                    Ok((stream, _)) => {
                        let slot = Slots::admit(&slots);
                        let channels = channels.clone();
                        let options = Arc::clone(&options);
                        connections.spawn(async move {
                            match slot {
                                Some(slot) => serve_connection(stream, slot, channels, &options).await,
                                None => refuse_busy(stream, &options).await,
                            }
                        });
                    }
                    Err(e) => {
                        // EMFILE and the like: back off instead of spinning.
                        tracing::warn!(error = %e, "control socket: accept failed");
                        tokio::time::sleep(Duration::from_millis(100)).await;
                    }
                },
            }
        }
        connections.shutdown().await;
        drop(listener);
        let ours = std::fs::symlink_metadata(&path)
            .ok()
            .map(|m| (m.dev(), m.ino()));
        if ours.is_some() && ours == inode {
            if let Err(e) = std::fs::remove_file(&path) {
                tracing::warn!(socket = %path.display(), error = %e, "cannot remove the control socket");
            }
        }
        tracing::info!(socket = %path.display(), "control socket closed");
    }
}

/// The connection slots: who holds one, who is waiting for a request (and since when), who
/// watches. The lock is held only for table updates, never across an await.
struct Slots {
    max: usize,
    max_watchers: usize,
    table: Mutex<SlotTable>,
}

#[derive(Default)]
struct SlotTable {
    next_id: u64,
    held: HashMap<u64, SlotState>,
}

struct SlotState {
    /// Waiting for a request since then; `None` while a request is handled.
    waiting_since: Option<Instant>,
    watching: bool,
    /// Told when the slot is taken from this connection for a newcomer.
    evict: Arc<Notify>,
}

/// A connection's slot, given back when it is dropped.
struct Slot {
    id: u64,
    slots: Arc<Slots>,
    evict: Arc<Notify>,
}

impl Slots {
    fn new(options: &ServerOptions) -> Slots {
        Slots {
            max: options.max_connections,
            max_watchers: options
                .max_connections
                .saturating_sub(options.reserved_for_requests),
            table: Mutex::new(SlotTable::default()),
        }
    }

    fn table(&self) -> std::sync::MutexGuard<'_, SlotTable> {
        // The table stays consistent even if a holder panicked: every update is one insert
        // or remove or field store.
        self.table.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A slot for a new connection: a free one, else the one of the connection that has
    /// waited longest for a request (that connection is told to go), else none.
    fn admit(slots: &Arc<Slots>) -> Option<Slot> {
        let mut t = slots.table();
        if t.held.len() >= slots.max {
            let victim = t
                .held
                .iter()
                .filter(|(_, s)| !s.watching)
                .filter_map(|(id, s)| s.waiting_since.map(|since| (since, *id)))
                .min()
                .map(|(_, id)| id)?;
            if let Some(v) = t.held.remove(&victim) {
                v.evict.notify_one();
            }
        }
        let id = t.next_id;
        t.next_id += 1;
        let evict = Arc::new(Notify::new());
        t.held.insert(
            id,
            SlotState {
                waiting_since: None,
                watching: false,
                evict: Arc::clone(&evict),
            },
        );
        Some(Slot {
            id,
            slots: Arc::clone(slots),
            evict,
        })
    }
}

impl Slot {
    /// Marks the connection as waiting for a request (it may be evicted) or not.
    fn waiting(&self, waiting: bool) {
        if let Some(s) = self.slots.table().held.get_mut(&self.id) {
            s.waiting_since = waiting.then(Instant::now);
        }
    }

    /// Makes the connection a watcher if the watchers' share of the slots allows it.
    fn start_watching(&self) -> bool {
        let mut t = self.slots.table();
        let watchers = t.held.values().filter(|s| s.watching).count();
        match t.held.get_mut(&self.id) {
            Some(s) if s.watching => true,
            Some(s) if watchers < self.slots.max_watchers => {
                s.watching = true;
                true
            }
            _ => false,
        }
    }

    /// Completes when the slot has been given to a newcomer.
    async fn evicted(&self) {
        self.evict.notified().await;
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.slots.table().held.remove(&self.id);
    }
}

/// A client beyond `max_connections`: one error, then close.
async fn refuse_busy(stream: UnixStream, options: &ServerOptions) {
    let (_, mut writer) = stream.into_split();
    let msg = Message::Error {
        message: format!(
            "the daemon already serves {} control connections, all watching or with a request in progress; close some (stray `surfscan status --watch`?) and retry",
            options.max_connections
        ),
    };
    let _ = send(&mut writer, &msg, options.write_timeout).await;
}

/// Why a connection ended early.
#[derive(Debug)]
enum Closed {
    /// A write did not complete within the bound.
    Slow,
    /// No complete request within the bound.
    Idle,
    /// Its slot was given to a newcomer while it sent nothing.
    Evicted,
    /// The client went away or the socket failed.
    Io(io::Error),
}

/// The peer's identity as the kernel recorded it when it connected.
#[derive(Debug, Clone)]
struct PeerInfo {
    peer: Peer,
    /// Primary and supplementary groups; `None` when they cannot be read.
    groups: Option<Vec<u32>>,
}

fn peer_info(stream: &UnixStream) -> Option<PeerInfo> {
    let cred = stream.peer_cred().ok()?;
    let peer = Peer {
        uid: cred.uid(),
        gid: cred.gid(),
        pid: cred.pid().and_then(|p| u32::try_from(p).ok()),
        web: None,
        mqtt: None,
    };
    let groups = peer_groups(stream.as_raw_fd()).ok().map(|mut g| {
        g.push(peer.gid);
        g.sort_unstable();
        g.dedup();
        g
    });
    Some(PeerInfo { peer, groups })
}

/// `SO_PEERGROUPS` (Linux 4.13): the supplementary groups of the peer's credentials at
/// connect time. The number is the asm-generic one, which libc does not export; the
/// architectures with their own socket numbering (mips, sparc) and other systems fall back to
/// the primary group alone.
const SO_PEERGROUPS: Option<libc::c_int> = if cfg!(all(
    target_os = "linux",
    not(any(
        target_arch = "mips",
        target_arch = "mips64",
        target_arch = "sparc",
        target_arch = "sparc64"
    ))
)) {
    Some(59)
} else {
    None
};

fn peer_groups(fd: std::os::unix::io::RawFd) -> io::Result<Vec<u32>> {
    let Some(option) = SO_PEERGROUPS else {
        return Err(io::Error::from(io::ErrorKind::Unsupported));
    };
    let gid_size = std::mem::size_of::<libc::gid_t>();
    let mut capacity = 64usize;
    loop {
        let mut buf: Vec<libc::gid_t> = vec![0; capacity];
        let mut len = (capacity * gid_size) as libc::socklen_t;
        // SAFETY: `buf` holds `len` bytes; the kernel writes at most `len` bytes into it and
        // stores the length it needs (or wrote) in `len`.
        let r = unsafe {
            libc::getsockopt(
                fd,
                libc::SOL_SOCKET,
                option,
                buf.as_mut_ptr().cast(),
                &mut len,
            )
        };
        let needed = len as usize / gid_size;
        if r == 0 {
            buf.truncate(needed);
            return Ok(buf);
        }
        let e = io::Error::last_os_error();
        if e.raw_os_error() == Some(libc::ERANGE) && needed > capacity {
            capacity = needed;
            continue;
        }
        return Err(e);
    }
}

/// Whether the peer may command under `allowed`: one of its groups is listed. Without its
/// supplementary groups only the primary group counts.
fn may_command(info: Option<&PeerInfo>, allowed: &[u32]) -> bool {
    let Some(info) = info else { return false };
    match &info.groups {
        Some(groups) => groups.iter().any(|g| allowed.contains(g)),
        None => allowed.contains(&info.peer.gid),
    }
}

async fn serve_connection(
    stream: UnixStream,
    slot: Slot,
    mut channels: ControlChannels,
    options: &ServerOptions,
) {
    let peer = peer_info(&stream);
    let (reader, mut writer) = stream.into_split();
    let mut lines = FramedRead::new(reader, RequestCodec::new(options.max_line_bytes));
    let hello = Message::Hello {
        protocol: PROTOCOL_VERSION,
        software: format!("surfscan {}", env!("CARGO_PKG_VERSION")),
        pid: std::process::id(),
    };
    let mut watching = false;
    // Watchers see the queue's changes too (a job added during a scan).
    let mut queue_changes = channels.queue.as_ref().map(|q| q.subscribe());
    let result: Result<(), Closed> = async {
        send(&mut writer, &hello, options.write_timeout).await?;
        let mut deadline = Instant::now() + options.request_timeout;
        slot.waiting(true);
        loop {
            tokio::select! {
                () = slot.evicted(), if !watching => return Err(Closed::Evicted),
                () = tokio::time::sleep_until(deadline), if !watching => return Err(Closed::Idle),
                frame = lines.next() => match frame {
                    None => return Ok(()),
                    Some(Err(e)) => return Err(Closed::Io(e)),
                    Some(Ok(frame)) => {
                        slot.waiting(false);
                        let ctx = Context { slot: &slot, peer: peer.as_ref(), options };
                        let reply = answer(frame, &mut channels, &mut watching, &ctx).await;
                        send(&mut writer, &reply, options.write_timeout).await?;
                        deadline = Instant::now() + options.request_timeout;
                        slot.waiting(!watching);
                    }
                },
                changed = async { queue_changes.as_mut().expect("guarded").changed().await }, if watching && queue_changes.is_some() => {
                    match changed {
                        Ok(()) => send(&mut writer, &status_with_queue(&mut channels, false), options.write_timeout).await?,
                        // The queue's keeper is gone (the daemon is stopping).
                        Err(_) => queue_changes = None,
                    }
                }
                changed = channels.status.changed(), if watching => {
                    let msg = match changed {
                        Ok(()) => status_with_queue(&mut channels, true),
                        Err(_) => {
                            watching = false;
                            Message::Error { message: "the scan runner stopped publishing status (the daemon is shutting down); reconnect when it is back".into() }
                        }
                    };
                    send(&mut writer, &msg, options.write_timeout).await?;
                }
            }
        }
    }
    .await;
    let farewell = |message: String| Message::Error { message };
    match result {
        Ok(()) => tracing::debug!("control client disconnected"),
        Err(Closed::Slow) => tracing::warn!(
            timeout_ms = options.write_timeout.as_millis() as u64,
            watching,
            "control client dropped: it did not read its messages in time"
        ),
        Err(Closed::Idle) => {
            tracing::info!(
                timeout_ms = options.request_timeout.as_millis() as u64,
                "control client dropped: no complete request in time"
            );
            let msg = farewell(format!(
                "no complete request within {} s; the connection is closed (send one JSON object per line, ending in a newline)",
                options.request_timeout.as_secs_f64()
            ));
            let _ = send(&mut writer, &msg, options.write_timeout).await;
        }
        Err(Closed::Evicted) => {
            tracing::info!("control client dropped: its slot went to a new connection");
            let msg = farewell(format!(
                "all {} control connections were taken and this one had sent no request, so it was closed to let another client in; send the request right after connecting",
                options.max_connections
            ));
            let _ = send(&mut writer, &msg, options.write_timeout).await;
        }
        Err(Closed::Io(e)) => tracing::debug!(error = %e, "control connection ended"),
    }
}

/// What [`answer`] needs to know about the connection.
struct Context<'a> {
    slot: &'a Slot,
    peer: Option<&'a PeerInfo>,
    options: &'a ServerOptions,
}

/// The reply to one request line.
async fn answer(
    frame: Frame,
    channels: &mut ControlChannels,
    watching: &mut bool,
    ctx: &Context<'_>,
) -> Message {
    let options = ctx.options;
    let line = match frame {
        Frame::Line(line) => line,
        Frame::TooLong => {
            let limit = options.max_line_bytes;
            return Message::Error {
                message: format!(
                    "request line longer than {limit} bytes was discarded; send one JSON object per line"
                ),
            };
        }
        Frame::NotUtf8 => {
            return Message::Error {
                message: "request line is not UTF-8 text; send one JSON object per line".into(),
            }
        }
    };
    let request = match parse_request(&line) {
        Ok(r) => r,
        Err(message) => return message,
    };
    if matches!(request, Request::Watch) {
        if !ctx.slot.start_watching() {
            return Message::Error {
                message: format!(
                    "{} clients already watch, the most this daemon allows (the other slots are kept for requests); close a stray `surfscan status --watch` and retry",
                    options.max_connections.saturating_sub(options.reserved_for_requests)
                ),
            };
        }
        *watching = true;
        return status_with_queue(channels, true);
    }
    dispatch(
        request,
        channels,
        |name| authorised(name, ctx),
        options.reply_timeout,
    )
    .await
}

/// The peer of a command, when it may command: its credentials are known and, with
/// `[control] allowed-groups`, it is in one of them; else the refusal to send back.
fn authorised(name: &str, ctx: &Context<'_>) -> Result<Peer, Message> {
    let Some(info) = ctx.peer else {
        return Err(Message::Error {
            message: format!("{name} refused: the kernel did not say who sent it (SO_PEERCRED failed), so it cannot be recorded"),
        });
    };
    if let Some(allowed) = &ctx.options.allowed_groups {
        if !may_command(Some(info), allowed) {
            tracing::warn!(uid = info.peer.uid, pid = ?info.peer.pid, command = name, "control command refused: not in [control] allowed-groups");
            let groups = match &info.groups {
                Some(g) => format!("groups {g:?}"),
                None => format!("primary group {}", info.peer.gid),
            };
            return Err(Message::Error {
                message: format!(
                    "{name} refused: uid {} ({groups}) is in none of the groups [control] allowed-groups names (gids {allowed:?}); status and watch stay open, ask the station's administrator to add you to one of them",
                    info.peer.uid
                ),
            });
        }
    }
    Ok(info.peer.clone())
}

/// Parses one request line strictly: besides what serde refuses (an unknown class, a
/// misspelt `start` field), a field the request's class does not have is refused too, e.g.
/// `{"class":"pause","force":true}` (serde's `deny_unknown_fields` does not reach the
/// field-less classes of an internally tagged enum). The known fields are those the request
/// has when serialised, so a field added to a request is known without a second list.
pub fn parse_request(line: &str) -> Result<Request, Message> {
    let value: serde_json::Value = serde_json::from_str(line).map_err(|e| malformed(line, &e))?;
    // JSON readers keep the last of a repeated key, so `{"class":"status","class":"abort"}`
    // would be an abort; a request naming a field twice is refused instead.
    if let Some(key) = repeated_key(line) {
        return Err(Message::Error {
            message: format!(
                "the request names {key:?} more than once; send each field once, and nothing is carried out"
            ),
        });
    }
    let request = Request::deserialize(&value).map_err(|e| malformed(line, &e))?;
    let known = serde_json::to_value(&request).unwrap_or_default();
    if let (Some(given), Some(known)) = (value.as_object(), known.as_object()) {
        if let Some(unknown) = given.keys().find(|k| !known.contains_key(*k)) {
            let class = known.get("class").and_then(|c| c.as_str()).unwrap_or("?");
            let mut fields: Vec<&str> = known
                .keys()
                .map(String::as_str)
                .filter(|k| *k != "class")
                .collect();
            fields.sort_unstable();
            let takes = if fields.is_empty() {
                "takes no fields besides class".to_owned()
            } else {
                format!("takes {}", fields.join(", "))
            };
            return Err(Message::Error {
                message: format!(
                    "unknown field {unknown:?} in a {class} request; {class} {takes}, and nothing is carried out"
                ),
            });
        }
    }
    Ok(request)
}

/// The first key a JSON object line names twice at its top level (requests are flat), if
/// any. `serde_json` keeps the last of repeated keys without a word, so the keys are walked
/// here one by one.
fn repeated_key(line: &str) -> Option<String> {
    use serde::de::{Deserializer, IgnoredAny, MapAccess, Visitor};
    struct Keys;
    impl<'de> Visitor<'de> for Keys {
        type Value = Option<String>;
        fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("a JSON object")
        }
        fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Option<String>, A::Error> {
            let mut seen = std::collections::HashSet::new();
            while let Some(key) = map.next_key::<String>()? {
                map.next_value::<IgnoredAny>()?;
                if !seen.insert(key.clone()) {
                    return Ok(Some(key));
                }
            }
            Ok(None)
        }
    }
    serde_json::Deserializer::from_str(line)
        .deserialize_map(Keys)
        .ok()
        .flatten()
}

/// The error for a line that is not a valid request, naming what was wrong.
fn malformed(line: &str, e: &serde_json::Error) -> Message {
    const CLASSES: &str = "status, watch, pause, resume, abort, start";
    let class = serde_json::from_str::<serde_json::Value>(line)
        .ok()
        .and_then(|v| v.get("class").and_then(|c| c.as_str()).map(str::to_owned));
    let message = match (e.classify(), class) {
        (serde_json::error::Category::Data, Some(class))
            if !CLASSES.split(", ").any(|c| c == class) =>
        {
            format!("unknown request class {class:?}; the daemon accepts {CLASSES}")
        }
        (serde_json::error::Category::Data, _) => {
            format!("invalid request: {e}; requests are JSON objects with a class ({CLASSES})")
        }
        _ => format!("request is not valid JSON: {e}; send one JSON object per line"),
    };
    Message::Error { message }
}

/// Writes one message as a JSON line, giving up after `timeout`.
async fn send(writer: &mut OwnedWriteHalf, msg: &Message, timeout: Duration) -> Result<(), Closed> {
    let mut line = serde_json::to_vec(msg).map_err(|e| Closed::Io(io::Error::other(e)))?;
    line.push(b'\n');
    match tokio::time::timeout(timeout, writer.write_all(&line)).await {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(Closed::Io(e)),
        Err(_elapsed) => Err(Closed::Slow),
    }
}

/// One request line as the codec delivers it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Frame {
    /// A line without its terminator (`\n` or `\r\n`); blank lines are skipped.
    Line(String),
    /// A line longer than the limit; it has been discarded up to its newline.
    TooLong,
    /// A line that is not UTF-8.
    NotUtf8,
}

/// Splits the request stream into lines of bounded length. Unlike tokio-util's
/// `LinesCodec`, an oversized or non-UTF-8 line is an item, not a stream error, so the
/// connection carries on with the next line.
#[derive(Debug)]
pub struct RequestCodec {
    max_line_bytes: usize,
    /// Inside an oversized line: drop bytes up to the next newline.
    discarding: bool,
    /// Bytes already searched for a newline.
    searched: usize,
}

impl RequestCodec {
    /// A codec accepting lines up to `max_line_bytes` (terminator excluded).
    pub fn new(max_line_bytes: usize) -> RequestCodec {
        RequestCodec {
            max_line_bytes,
            discarding: false,
            searched: 0,
        }
    }

    fn frame(&self, raw: &[u8]) -> Option<Frame> {
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        if raw.len() > self.max_line_bytes {
            return Some(Frame::TooLong);
        }
        match std::str::from_utf8(raw) {
            Ok(s) if s.trim().is_empty() => None,
            Ok(s) => Some(Frame::Line(s.to_owned())),
            Err(_) => Some(Frame::NotUtf8),
        }
    }
}

impl Decoder for RequestCodec {
    type Item = Frame;
    type Error = io::Error;

    fn decode(&mut self, buf: &mut BytesMut) -> Result<Option<Frame>, io::Error> {
        loop {
            let newline = buf[self.searched..]
                .iter()
                .position(|&b| b == b'\n')
                .map(|i| self.searched + i);
            match newline {
                Some(end) => {
                    self.searched = 0;
                    if self.discarding {
                        self.discarding = false;
                        buf.advance(end + 1);
                        continue;
                    }
                    let line = buf.split_to(end + 1);
                    match self.frame(&line[..end]) {
                        Some(frame) => return Ok(Some(frame)),
                        None => continue,
                    }
                }
                None if self.discarding => {
                    buf.clear();
                    self.searched = 0;
                    return Ok(None);
                }
                // +1 leaves room for a `\r` before the newline.
                None if buf.len() > self.max_line_bytes + 1 => {
                    buf.clear();
                    self.searched = 0;
                    self.discarding = true;
                    return Ok(Some(Frame::TooLong));
                }
                None => {
                    self.searched = buf.len();
                    return Ok(None);
                }
            }
        }
    }

    fn decode_eof(&mut self, buf: &mut BytesMut) -> Result<Option<Frame>, io::Error> {
        if let Some(frame) = self.decode(buf)? {
            return Ok(Some(frame));
        }
        self.searched = 0;
        if self.discarding || buf.is_empty() {
            self.discarding = false;
            buf.clear();
            return Ok(None);
        }
        // A last request without its newline.
        let rest = buf.split_to(buf.len());
        Ok(self.frame(&rest))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode_all(codec: &mut RequestCodec, chunks: &[&[u8]]) -> Vec<Frame> {
        let mut buf = BytesMut::new();
        let mut out = Vec::new();
        for c in chunks {
            buf.extend_from_slice(c);
            while let Some(f) = codec.decode(&mut buf).unwrap() {
                out.push(f);
            }
        }
        while let Some(f) = codec.decode_eof(&mut buf).unwrap() {
            out.push(f);
        }
        out
    }

    #[test]
    fn lines_split_across_reads_and_crlf_and_blank_lines() {
        let mut c = RequestCodec::new(64);
        let frames = decode_all(
            &mut c,
            &[
                b"{\"class\":",
                b"\"status\"}\r\n\n  \r\n{\"class\":\"pause\"}\n{\"cl",
            ],
        );
        assert_eq!(
            frames,
            vec![
                Frame::Line(r#"{"class":"status"}"#.into()),
                Frame::Line(r#"{"class":"pause"}"#.into()),
                Frame::Line(r#"{"cl"#.into()),
            ]
        );
    }

    #[test]
    fn oversized_line_is_reported_once_and_the_next_line_survives() {
        let mut c = RequestCodec::new(8);
        let long = [b'x'; 20];
        let frames = decode_all(&mut c, &[&long, &long, b"tail\nok\n"]);
        assert_eq!(frames, vec![Frame::TooLong, Frame::Line("ok".into())]);
        // Oversized but complete within one read.
        let mut c = RequestCodec::new(8);
        let frames = decode_all(&mut c, &[b"0123456789\nfine\n"]);
        assert_eq!(frames, vec![Frame::TooLong, Frame::Line("fine".into())]);
        // Exactly at the limit, with CRLF.
        let mut c = RequestCodec::new(8);
        let frames = decode_all(&mut c, &[b"01234567", b"\r\n"]);
        assert_eq!(frames, vec![Frame::Line("01234567".into())]);
    }

    #[test]
    fn garbage_bytes_are_an_item_not_an_error() {
        let mut c = RequestCodec::new(64);
        let frames = decode_all(&mut c, &[b"\xff\xfe\n{}\n"]);
        assert_eq!(frames, vec![Frame::NotUtf8, Frame::Line("{}".into())]);
    }

    #[test]
    fn a_field_named_twice_is_refused_not_taken_from_its_last_value() {
        for (line, key) in [
            (r#"{"class":"status","class":"abort"}"#, "class"),
            (
                r#"{"class":"start","specimen":"A","specimen":"B"}"#,
                "specimen",
            ),
        ] {
            let Err(Message::Error { message }) = parse_request(line) else {
                panic!("{line} accepted")
            };
            assert!(
                message.contains(&format!("{key:?} more than once")),
                "{message}"
            );
        }
        // A request naming each field once passes.
        assert!(parse_request(r#"{"class":"abort"}"#).is_ok());
    }

    #[test]
    fn an_unknown_field_is_refused_on_every_class() {
        for (line, field) in [
            (r#"{"class":"pause","force":true}"#, "force"),
            (r#"{"class":"status","verbose":1}"#, "verbose"),
            (r#"{"class":"watch","every":1}"#, "every"),
            (r#"{"class":"resume","all":1}"#, "all"),
            (r#"{"class":"abort","now":1}"#, "now"),
            (r#"{"class":"start","specimen":"B","force":1}"#, "force"),
        ] {
            let Err(Message::Error { message }) = parse_request(line) else {
                panic!("{line} accepted")
            };
            assert!(
                message.contains("unknown field") && message.contains(field),
                "{message}"
            );
        }
        let Err(Message::Error { message }) = parse_request(r#"{"class":"pause","force":true}"#)
        else {
            panic!()
        };
        assert!(
            message.contains("\"force\"") && message.contains("takes no fields"),
            "{message}"
        );
        assert_eq!(
            parse_request(r#"{"class":"pause"}"#).unwrap(),
            Request::Pause
        );
        assert!(matches!(
            parse_request(r#"{"class":"start","notes":"n"}"#).unwrap(),
            Request::Start { notes, .. } if notes == "n"
        ));
    }

    #[test]
    fn groups_are_resolved_by_name_or_number() {
        assert_eq!(
            resolve_groups(&["root".into(), "4242".into()]).unwrap(),
            vec![0, 4242]
        );
        let e = resolve_groups(&["no-such-group-here".into()]).unwrap_err();
        assert!(e.contains("no group named \"no-such-group-here\""), "{e}");
    }

    #[test]
    fn malformed_requests_are_named() {
        let bad_json = serde_json::from_str::<Request>("{nope").unwrap_err();
        let Message::Error { message } = malformed("{nope", &bad_json) else {
            panic!("not an error")
        };
        assert!(message.contains("not valid JSON"), "{message}");
        let line = r#"{"class":"raw","cmd":"CTSTA"}"#;
        let e = serde_json::from_str::<Request>(line).unwrap_err();
        let Message::Error { message } = malformed(line, &e) else {
            panic!("not an error")
        };
        assert!(
            message.contains("unknown request class \"raw\""),
            "{message}"
        );
        let line = r#"{"class":"start","specimn":"B"}"#;
        let e = serde_json::from_str::<Request>(line).unwrap_err();
        let Message::Error { message } = malformed(line, &e) else {
            panic!("not an error")
        };
        assert!(message.contains("specimn"), "{message}");
    }
}
