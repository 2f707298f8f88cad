//! The running simulator: serves a responder (emulated instrument or transcript replay) over
//! any byte stream, applies pacing and faults, and owns the instrument's pty life cycle
//! (ready → unplug → replug) behind the [`Simulator`] builder.
//!
//! Depends on every other module of the crate and on tokio. Time comes from
//! `tokio::time::Instant`, so tests can run it under paused time.
//!
//! Stage emulators plug in through [`Simulator::stage`]: the simulator creates the stage's pty,
//! links it, announces it on the ready line, and hands the pty and the shared [`YPosition`] to
//! the given serve function; the instrument then serves the line at that y.

use std::future::Future;
use std::io;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use crate::command::{Frame, FrameSplitter};
use crate::data::{DataError, ProfileSet, YPosition};
use crate::fault::{Fault, FaultKind, FaultPlan, CHATTER_PERIOD};
use crate::grbl::StageShared;
use crate::instrument::{Instrument, InstrumentConfig};
use crate::line::{HostLine, LineGate, Mismatch};
use crate::pty::{Pty, PtyError};
use crate::replay::{Replay, Transcript};
use crate::stats::SimStats;

/// Bytes written before a reply by the `garbage` fault.
pub const GARBAGE: &[u8] = b"\xfe\x00\x7f#";
/// How long after its reply an `unplug` fault closes the pty (then waits until the client has
/// read that reply, at most 1 s more).
pub const UNPLUG_GRACE: Duration = Duration::from_millis(50);
/// Pause between the two writes of a `split` reply.
pub const SPLIT_PAUSE: Duration = Duration::from_millis(20);

/// Answers frames.
#[derive(Debug)]
pub enum Responder {
    /// The emulated instrument.
    Emulate(Box<Instrument>),
    /// A recorded transcript.
    Replay(Box<Replay>),
}

impl Responder {
    /// The reply bytes for one frame at `now`, `None` for no reply.
    pub fn respond(&mut self, frame: &[u8], now: Duration) -> Option<Vec<u8>> {
        match self {
            Responder::Emulate(i) => Some(i.respond(frame, now)),
            Responder::Replay(r) => r.respond(frame, now),
        }
    }

    /// The reply with a semantic fault applied by the emulated instrument (a repeated read-out
    /// block, a skewed result); a replayed transcript answers as recorded.
    fn respond_faulted(
        &mut self,
        frame: &[u8],
        now: Duration,
        kind: &FaultKind,
    ) -> Option<Vec<u8>> {
        match (self, kind) {
            (Responder::Emulate(i), FaultKind::RepeatBlock) => {
                Some(i.respond_repeating_block(frame, now))
            }
            (Responder::Emulate(i), FaultKind::Skew(pct)) => {
                Some(i.respond_skewed(frame, now, *pct))
            }
            (Responder::Emulate(i), FaultKind::Scale(k)) => {
                Some(i.respond_scaled(frame, now, f64::from(*k)))
            }
            (r, _) => r.respond(frame, now),
        }
    }

    fn power_cycle(&mut self) {
        if let Responder::Emulate(i) = self {
            i.power_cycle();
        }
    }
}

/// Serial pacing: each reply is delayed by the transfer time at `baud` (10 bits per byte) of
/// the command that asked for it (with its terminator) and of the reply itself, multiplied by
/// `time_scale`. A pseudo-terminal delivers the command at once, so the command's own time on
/// a real wire is spent here; the exchange then ends when its last reply byte would have
/// arrived.
///
/// A timer fires up to a tick (1 ms) after its deadline, which on a fast-paced link with
/// dozens of short exchanges per profile adds more than the wire itself: so each reply is
/// timed on the wire's own timeline. How late the previous reply went out is taken off the
/// next one's start (at most [`MAX_PACING_CATCH_UP`]), and a command that arrives while the
/// previous reply is still on the wire starts after it. A reply is never sent before the
/// wire time of its exchange counted from where that timeline puts the command, so over a
/// read-out the link runs at its baud rate, not slower.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pacing {
    /// Baud rate.
    pub baud: u32,
    /// Multiplies the transfer time (0 = no pacing).
    pub time_scale: f64,
}

/// The most a reply may be sent before its own transfer time is up, to make up for the
/// previous reply sent late (below).
pub const MAX_PACING_CATCH_UP: Duration = Duration::from_millis(2);

impl Pacing {
    fn delay(&self, bytes: usize) -> Duration {
        if self.baud == 0 || self.time_scale <= 0.0 {
            return Duration::ZERO;
        }
        Duration::try_from_secs_f64(bytes as f64 * 10.0 / f64::from(self.baud) * self.time_scale)
            .unwrap_or(Duration::ZERO)
    }
}

/// Why [`serve_connection`] returned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The stream ended.
    Closed,
    /// An `unplug` fault fired: the device must vanish for this long.
    Unplug(Duration),
    /// A `deaf` fault fired: the link must take no bytes for this long.
    Deaf(Duration),
    /// Shutdown was requested.
    Shutdown,
}

/// Serves `responder` over `io` until the stream ends, an unplug fault fires or `shutdown`
/// becomes true. `epoch` is time zero of the responder's timeline. With a `gate`, a frame
/// sent at another rate than the instrument's never reaches the responder.
pub async fn serve_connection<T: AsyncRead + AsyncWrite + Unpin>(
    io: &mut T,
    responder: &mut Responder,
    faults: &mut FaultPlan,
    pacing: Pacing,
    epoch: Instant,
    shutdown: &mut watch::Receiver<bool>,
    gate: Option<&LineGate>,
) -> io::Result<Outcome> {
    let mut splitter = FrameSplitter::new();
    let mut buf = [0u8; 512];
    let clock = || Instant::now().saturating_duration_since(epoch);
    // While a `noeol` or `flood` window is open, unsolicited bytes flow between replies on a
    // steady cadence that frames arriving in between do not reset.
    let mut next_chatter: Option<Instant> = None;
    // Pacing on the wire's timeline (see [`Pacing`]): how late the last reply went out, and
    // when the wire is free of it.
    let mut late = Duration::ZERO;
    let mut wire_free: Option<Instant> = None;
    loop {
        if *shutdown.borrow() {
            return Ok(Outcome::Shutdown);
        }
        next_chatter = match (faults.chattering(clock()), next_chatter) {
            (false, _) => None,
            (true, Some(t)) => Some(t),
            (true, None) => Some(Instant::now() + CHATTER_PERIOD),
        };
        let tick = async {
            match next_chatter {
                Some(t) => tokio::time::sleep_until(t).await,
                None => std::future::pending::<()>().await,
            }
        };
        let n = tokio::select! {
            r = io.read(&mut buf) => r?,
            _ = shutdown.changed() => return Ok(Outcome::Shutdown),
            () = tick => {
                next_chatter = next_chatter.map(|t| t + CHATTER_PERIOD);
                let bytes = faults.chatter(clock());
                if !bytes.is_empty() {
                    io.write_all(&bytes).await?;
                    io.flush().await?;
                }
                continue;
            }
        };
        if n == 0 {
            return Ok(Outcome::Closed);
        }
        let arrived = Instant::now();
        for frame in splitter.push(buf.get(..n).unwrap_or(&[])) {
            let line = match frame {
                Frame::Line(l) => l,
                Frame::Overflow => {
                    io.write_all(b"NG013\r").await?;
                    continue;
                }
            };
            if let Some(noise) = gate.and_then(LineGate::garbled) {
                if !noise.is_empty() {
                    io.write_all(&noise).await?;
                    io.flush().await?;
                }
                continue;
            }
            let text: String = line.iter().map(|&b| b as char).collect();
            let now = clock();
            let verdict = faults.check_at(&text, now);
            let fault = verdict.kind;
            let reply = match &fault {
                Some(FaultKind::Ng(code)) => Some(format!("NG{code:03}\r").into_bytes()),
                Some(k @ (FaultKind::RepeatBlock | FaultKind::Skew(_) | FaultKind::Scale(_))) => {
                    responder.respond_faulted(&line, now, k)
                }
                _ => responder.respond(&line, now),
            };
            let Some(mut reply) = reply else { continue };
            if verdict.strip_line_end {
                reply.retain(|&b| b != b'\r' && b != b'\n');
            }
            let delay = pacing.delay(line.len() + 1 + reply.len());
            if delay.is_zero() {
                tokio::time::sleep(delay).await;
            } else {
                let from = arrived.checked_sub(late).unwrap_or(arrived);
                let from = wire_free.map_or(from, |w| w.max(from));
                let due = from + delay;
                wire_free = Some(due);
                if due > Instant::now() {
                    tokio::time::sleep_until(due).await;
                }
                late = Instant::now()
                    .saturating_duration_since(due)
                    .min(MAX_PACING_CATCH_UP);
            }
            match fault {
                Some(FaultKind::Drop) => {}
                Some(FaultKind::Truncate) => {
                    io.write_all(reply.get(..reply.len() / 2).unwrap_or(&[]))
                        .await?;
                }
                Some(FaultKind::Garbage) => {
                    let mut bytes = GARBAGE.to_vec();
                    bytes.extend_from_slice(&reply);
                    io.write_all(&bytes).await?;
                }
                Some(FaultKind::Split) => {
                    let (a, b) = reply.split_at(reply.len() / 2);
                    io.write_all(a).await?;
                    io.flush().await?;
                    tokio::time::sleep(SPLIT_PAUSE).await;
                    io.write_all(b).await?;
                }
                Some(FaultKind::ExtraLf) => {
                    let mut bytes = reply.clone();
                    bytes.push(b'\n');
                    io.write_all(&bytes).await?;
                }
                Some(FaultKind::Silence(d)) => {
                    tokio::time::sleep(d).await;
                    io.write_all(&reply).await?;
                }
                Some(FaultKind::Unplug(d)) => {
                    io.write_all(&reply).await?;
                    io.flush().await?;
                    return Ok(Outcome::Unplug(d));
                }
                Some(FaultKind::Deaf(d)) => return Ok(Outcome::Deaf(d)),
                Some(
                    FaultKind::Ng(_)
                    | FaultKind::RepeatBlock
                    | FaultKind::Skew(_)
                    | FaultKind::Scale(_)
                    | FaultKind::Window(..),
                )
                | None => io.write_all(&reply).await?,
            }
            io.flush().await?;
        }
    }
}

/// Events the running simulator reports (the binary prints each as one JSON line).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SimEvent {
    /// The links can be opened.
    Ready(ReadyInfo),
    /// The instrument vanished (link removed).
    Unplugged {
        /// The instrument link.
        instrument: PathBuf,
    },
    /// The instrument is back (new pty at the same link).
    Replugged {
        /// The instrument link.
        instrument: PathBuf,
    },
    /// The serve loop stopped on an I/O error.
    Failed {
        /// The error text.
        error: String,
    },
}

/// What the ready line announces.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadyInfo {
    /// Instrument link path, when an instrument is emulated.
    pub instrument: Option<PathBuf>,
    /// Stage link path, when a stage is attached.
    pub stage: Option<PathBuf>,
    /// `sj210` or `sj410`, or `replay`.
    pub model: String,
    /// Whether `RDEVA` works.
    pub profile_readout: bool,
}

impl SimEvent {
    /// The event as one JSON line (no newline).
    pub fn to_json(&self) -> String {
        let path = |p: &Path| serde_json::Value::String(p.display().to_string());
        let v = match self {
            SimEvent::Ready(r) => serde_json::json!({
                "event": "ready",
                "instrument": r.instrument.as_deref().map(path),
                "stage": r.stage.as_deref().map(path),
                "model": r.model,
                "profile_readout": r.profile_readout,
            }),
            SimEvent::Unplugged { instrument } => {
                serde_json::json!({"event": "unplugged", "instrument": path(instrument)})
            }
            SimEvent::Replugged { instrument } => {
                serde_json::json!({"event": "replugged", "instrument": path(instrument)})
            }
            SimEvent::Failed { error } => serde_json::json!({"event": "failed", "error": error}),
        };
        v.to_string()
    }
}

/// Errors starting the simulator.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A pty could not be created or linked.
    #[error(transparent)]
    Pty(#[from] PtyError),
    /// Profile data could not be loaded.
    #[error(transparent)]
    Data(#[from] DataError),
}

/// A stage emulator's serve function: gets the stage pty and the shared y position.
pub type StageServe =
    Box<dyn FnOnce(Pty, YPosition) -> Pin<Box<dyn Future<Output = io::Result<()>> + Send>> + Send>;

enum Source {
    Emulate(InstrumentConfig, Option<ProfileSet>),
    Replay(Transcript, f64),
}

/// Builder for a running simulator.
pub struct Simulator {
    instrument_link: Option<PathBuf>,
    source: Source,
    faults: Vec<Fault>,
    baud: u32,
    pacing_scale: Option<f64>,
    y: YPosition,
    stage: Option<(PathBuf, StageServe)>,
    line_check: Option<Mismatch>,
    stats: Arc<SimStats>,
}

impl std::fmt::Debug for Simulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulator")
            .field("instrument_link", &self.instrument_link)
            .field("faults", &self.faults)
            .field("baud", &self.baud)
            .field("stage", &self.stage.as_ref().map(|s| &s.0))
            .finish_non_exhaustive()
    }
}

impl Simulator {
    /// A simulator linking the instrument at `instrument_link`, emulating a default SJ-210 that
    /// serves the bundled data, at 38400 baud.
    pub fn new(instrument_link: impl Into<PathBuf>) -> Self {
        Self {
            instrument_link: Some(instrument_link.into()),
            source: Source::Emulate(InstrumentConfig::default(), None),
            faults: Vec::new(),
            baud: 38400,
            pacing_scale: None,
            y: YPosition::new(),
            stage: None,
            line_check: None,
            stats: Arc::new(SimStats::default()),
        }
    }

    /// A simulator without an instrument: attach a stage with [`Simulator::stage`],
    /// [`Simulator::grbl_stage`] or [`Simulator::zaber_stage`].
    pub fn without_instrument() -> Self {
        Self {
            instrument_link: None,
            ..Self::new(PathBuf::new())
        }
    }

    /// Attaches the simulated GRBL controller at `link`; its true position drives the
    /// instrument's profile selection. Faults are injected through `shared`.
    pub fn grbl_stage(
        self,
        link: impl Into<PathBuf>,
        cfg: crate::grbl::GrblSimConfig,
        shared: Arc<StageShared>,
    ) -> Self {
        self.stage(
            link,
            Box::new(move |pty, y| {
                shared.link_y(y);
                Box::pin(crate::grbl::serve(pty, cfg, shared))
            }),
        )
    }

    /// Attaches the simulated Zaber device at `link`; its true position drives the
    /// instrument's profile selection. Faults are injected through `shared`.
    pub fn zaber_stage(
        self,
        link: impl Into<PathBuf>,
        cfg: crate::zaber::ZaberSimConfig,
        shared: Arc<StageShared>,
    ) -> Self {
        self.stage(
            link,
            Box::new(move |pty, y| {
                shared.link_y(y);
                Box::pin(crate::zaber::serve(pty, cfg, shared))
            }),
        )
    }

    /// A lab station `speed_up` times faster than real, as the daemon's end-to-end tests and
    /// benchmarks scan it: the SJ-210 at `instrument_link` serving the bundled profiles from
    /// y = −20 mm over a 1 Mbaud link, and a GRBL stage at `stage_link` (400 steps/mm, 100 mm
    /// of travel, otherwise [`crate::grbl::GrblSimConfig::default`]) whose moves run ten
    /// times faster still, so that a line's period is the instrument's and the software's,
    /// not the stage's. Faults are injected through `shared`.
    pub fn sped_up_station(
        instrument_link: impl Into<PathBuf>,
        stage_link: impl Into<PathBuf>,
        speed_up: f64,
        shared: Arc<StageShared>,
    ) -> Result<Self, SimError> {
        let mut profiles = ProfileSet::bundled()?;
        profiles.y_first_mm = -20.0;
        let stage = crate::grbl::GrblSimConfig {
            steps_per_mm: 400.0,
            max_travel_mm: 100.0,
            time_scale: speed_up * 10.0,
            ..crate::grbl::GrblSimConfig::default()
        };
        Ok(Simulator::new(instrument_link)
            .instrument(InstrumentConfig {
                time_scale: 1.0 / speed_up,
                ..InstrumentConfig::default()
            })
            .profiles(profiles)
            .baud(1_000_000)
            .grbl_stage(stage_link, stage, shared))
    }

    /// Emulates an instrument with this configuration (keeps the profiles already set).
    pub fn instrument(mut self, cfg: InstrumentConfig) -> Self {
        let profiles = match self.source {
            Source::Emulate(_, p) => p,
            Source::Replay(..) => None,
        };
        self.source = Source::Emulate(cfg, profiles);
        self
    }

    /// Serves these profiles (default: the bundled 31 Mitutoyo R windows).
    pub fn profiles(mut self, set: ProfileSet) -> Self {
        let cfg = match self.source {
            Source::Emulate(c, _) => c,
            Source::Replay(..) => InstrumentConfig::default(),
        };
        self.source = Source::Emulate(cfg, Some(set));
        self
    }

    /// Replays a transcript instead of emulating; `time_scale` scales recorded delays.
    pub fn replay(mut self, t: Transcript, time_scale: f64) -> Self {
        self.source = Source::Replay(t, time_scale);
        self
    }

    /// Adds a wire fault.
    pub fn fault(mut self, f: Fault) -> Self {
        self.faults.push(f);
        self
    }

    /// Baud rate for pacing (pacing uses the instrument's time scale).
    pub fn baud(mut self, baud: u32) -> Self {
        self.baud = baud;
        self
    }

    /// Answers only a host whose line speed is the instrument's rate ([`Simulator::baud`]), as
    /// a real instrument set to one rate does; a host at another rate gets `mismatch`.
    pub fn line_check(mut self, mismatch: Mismatch) -> Self {
        self.line_check = Some(mismatch);
        self
    }

    /// Paces the link with its own time scale instead of the instrument's (1 = the wire's real
    /// speed): e.g. an instantaneous trace whose read-out still takes real time.
    pub fn pacing_time_scale(mut self, time_scale: f64) -> Self {
        self.pacing_scale = Some(time_scale);
        self
    }

    /// The shared stage y position the instrument reads when a stage is attached.
    pub fn y_position(&self) -> YPosition {
        self.y.clone()
    }

    /// Attaches a stage emulator: its pty is linked at `link` and `serve` runs on it.
    pub fn stage(mut self, link: impl Into<PathBuf>, serve: StageServe) -> Self {
        self.stage = Some((link.into(), serve));
        self
    }

    /// Creates the ptys and starts serving. When this returns, the links can be opened and the
    /// first event on the handle is [`SimEvent::Ready`]. Must be called within a tokio runtime
    /// (the ptys register with its reactor and the serve loop is spawned on it).
    pub fn start(self) -> Result<SimHandle, SimError> {
        let stage_attached = self.stage.is_some();
        let y = stage_attached.then(|| self.y.clone());
        let (mut responder, model, readout, time_scale) = match self.source {
            Source::Emulate(cfg, profiles) => {
                let profiles = match profiles {
                    Some(p) => p,
                    None => ProfileSet::bundled()?,
                };
                let model = match cfg.model {
                    crate::instrument::Model::Sj210 => "sj210",
                    crate::instrument::Model::Sj410 => "sj410",
                };
                let (readout, scale) = (cfg.profile_readout, cfg.time_scale);
                let inst = Instrument::new(cfg, profiles, y).with_stats(self.stats.clone());
                (Responder::Emulate(Box::new(inst)), model, readout, scale)
            }
            Source::Replay(t, scale) => (
                Responder::Replay(Box::new(Replay::new(&t, scale))),
                "replay",
                true,
                scale,
            ),
        };
        let pty = match &self.instrument_link {
            Some(l) => Some(Pty::create(l)?),
            None => None,
        };
        let mut stage_link = None;
        let mut stage_task = None;
        if let Some((link, serve)) = self.stage {
            let stage_pty = Pty::create(&link)?;
            stage_link = Some(link);
            // The serve function is called here, before the ready line: it publishes the
            // stage's start position, which the instrument's first trace already reads. The
            // pty (and with it the link) lives as long as the returned future: a vanishing
            // stage removes its link.
            let serving = serve(stage_pty, self.y.clone());
            stage_task = Some(tokio::spawn(async move {
                if let Err(e) = serving.await {
                    tracing::warn!("stage emulator stopped: {e}");
                }
            }));
        }
        let (events_tx, events) = mpsc::unbounded_channel();
        let (shutdown_tx, mut shutdown) = watch::channel(false);
        let ready = ReadyInfo {
            instrument: self.instrument_link.clone(),
            stage: stage_link,
            model: model.to_string(),
            profile_readout: readout,
        };
        let _ = events_tx.send(SimEvent::Ready(ready.clone()));
        let mut faults = FaultPlan::new(self.faults);
        let pacing = Pacing {
            baud: self.baud,
            time_scale: self.pacing_scale.unwrap_or(time_scale),
        };
        let line_check = self.line_check;
        let baud = self.baud;
        let stats = self.stats.clone();
        let gate_of = move |pty: &Pty| -> Option<LineGate> {
            let mismatch = line_check?;
            match pty.slave_dup() {
                Ok(fd) => Some(LineGate {
                    baud,
                    mismatch,
                    host: HostLine::new(fd),
                    stats: stats.clone(),
                }),
                Err(e) => {
                    tracing::warn!("cannot check the host's line speed: {e}");
                    None
                }
            }
        };
        let task = tokio::spawn(async move {
            let (Some(link), Some(mut pty)) = (self.instrument_link, pty) else {
                // Stage only: run until shutdown.
                let _ = shutdown.wait_for(|s| *s).await;
                return;
            };
            let epoch = Instant::now();
            loop {
                let gate = gate_of(&pty);
                let outcome = serve_connection(
                    &mut pty,
                    &mut responder,
                    &mut faults,
                    pacing,
                    epoch,
                    &mut shutdown,
                    gate.as_ref(),
                )
                .await;
                match outcome {
                    Ok(Outcome::Unplug(d)) => {
                        // Writes to a pty master reach the slave's queue asynchronously, and a
                        // hang-up flushes that queue: give the reply time to arrive and be read.
                        tokio::time::sleep(UNPLUG_GRACE).await;
                        pty.wait_drained(Duration::from_secs(1)).await;
                        drop(pty);
                        responder.power_cycle();
                        let _ = events_tx.send(SimEvent::Unplugged {
                            instrument: link.clone(),
                        });
                        tokio::select! {
                            _ = tokio::time::sleep(d) => {}
                            _ = shutdown.changed() => return,
                        }
                        pty = match Pty::create(&link) {
                            Ok(p) => p,
                            Err(e) => {
                                let _ = events_tx.send(SimEvent::Failed {
                                    error: e.to_string(),
                                });
                                return;
                            }
                        };
                        let _ = events_tx.send(SimEvent::Replugged {
                            instrument: link.clone(),
                        });
                    }
                    Ok(Outcome::Deaf(d)) => {
                        if let Err(e) = pty.hold_host(d).await {
                            let _ = events_tx.send(SimEvent::Failed {
                                error: e.to_string(),
                            });
                            return;
                        }
                    }
                    Ok(Outcome::Closed) | Ok(Outcome::Shutdown) => return,
                    Err(e) => {
                        let _ = events_tx.send(SimEvent::Failed {
                            error: e.to_string(),
                        });
                        return;
                    }
                }
            }
        });
        Ok(SimHandle {
            ready,
            events,
            shutdown: shutdown_tx,
            task,
            stage_task,
            stats: self.stats,
        })
    }
}

/// A running simulator. Dropping it does not stop it; call [`SimHandle::shutdown`].
#[derive(Debug)]
pub struct SimHandle {
    ready: ReadyInfo,
    /// Events in order; the first is [`SimEvent::Ready`].
    pub events: mpsc::UnboundedReceiver<SimEvent>,
    shutdown: watch::Sender<bool>,
    task: tokio::task::JoinHandle<()>,
    stage_task: Option<tokio::task::JoinHandle<()>>,
    stats: Arc<SimStats>,
}

impl SimHandle {
    /// What the emulated instrument was asked and how it answered so far.
    pub fn stats(&self) -> Arc<SimStats> {
        self.stats.clone()
    }

    /// The paths announced on the ready line.
    pub fn ready(&self) -> &ReadyInfo {
        &self.ready
    }

    /// Waits for the next event (`None` once the simulator has stopped).
    pub async fn next_event(&mut self) -> Option<SimEvent> {
        self.events.recv().await
    }

    /// Stops serving, closes the ptys and removes the links.
    pub async fn shutdown(mut self) {
        let _ = self.shutdown.send(true);
        // A reply blocked on a full pty buffer (no client reading) cannot see the signal:
        // give the loop a moment, then abort it; dropping the pty removes the link either way.
        if tokio::time::timeout(Duration::from_secs(1), &mut self.task)
            .await
            .is_err()
        {
            self.task.abort();
            let _ = (&mut self.task).await;
        }
        if let Some(t) = self.stage_task.take() {
            t.abort();
            let _ = t.await;
        }
    }
}
