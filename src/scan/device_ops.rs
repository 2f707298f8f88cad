//! The devices of a running scan as the runner performs the machine's device effects on
//! them: open and verify (probe / connect, identity against the scan's), home, ensure idle,
//! move, trace (with whether a trace really started, and a second read-out of a line whose Ra
//! is far from its neighbours'), the best-effort clean-up, and timers.
//! Each effect's result comes back as the machine's [`Event`].
//!
//! Layer 3 (session): depends on [`super::station`], [`super::machine`]'s events and actions,
//! [`super::ledger`] (the scan's identities), [`crate::devices`]' contracts and
//! [`crate::sj210::sanity`]'s neighbour rule; tokio for timeouts and timers.

use super::ledger::Ledger;
use super::machine::{Action, Event, TracedSummary};
use super::opening::{self, expected_points};
use super::station::{Device, Fault, Station};
use crate::devices::{FaultClass, Instrument, InstrumentIdentity, ProbeReport, TracedLine, YAxis};
use crate::sj210::sanity::{instrument_ra_um, ra_far_from_neighbours};
use crate::stage::policy::ScanDirection;
use crate::units::Nm;
use chrono::{DateTime, Utc};
use std::time::Duration;

/// Time allowed for the best-effort abort and stop after an operator abort or shutdown.
const CLEANUP_TIMEOUT: Duration = Duration::from_secs(10);

/// The devices of a running scan and what they reported.
pub(super) struct Hands<'s, S: Station> {
    pub(super) station: &'s mut S,
    pub(super) instrument: Option<S::Instrument>,
    pub(super) stage: Option<S::Stage>,
    pub(super) direction: ScanDirection,
    pub(super) targets: Vec<Nm>,
    /// The instrument's report at the start of a new scan.
    pub(super) probe: Option<ProbeReport>,
    /// Warnings of the start (instrument and stage), for the journal.
    pub(super) warnings: Vec<String>,
    /// The stage controller the scan started with, when known.
    pub(super) stage_identity: Option<String>,
    /// The instrument the scan started with (set once the scan has a start record).
    pub(super) identity: Option<InstrumentIdentity>,
    /// Read back by the last move.
    pub(super) readback: Option<Nm>,
    /// The instrument's Ra, µm, of the committed lines before the line to trace, in order.
    pub(super) ra_before: Vec<f64>,
    /// Devices being closed on a blocking thread: a device is opened again only once its
    /// old port is closed (the port is opened exclusively).
    pub(super) closing: Vec<(Device, tokio::task::JoinHandle<()>)>,
}

/// A traced line waiting for its commit.
pub(super) struct Held {
    pub(super) traced: TracedLine,
    /// For the journal: the line's second read-out differed from its first and was kept.
    pub(super) read_again: Option<String>,
    pub(super) readback: Option<Nm>,
    pub(super) started_at: DateTime<Utc>,
    pub(super) finished_at: DateTime<Utc>,
}

impl<S: Station> Hands<'_, S> {
    /// Performs a device effect; its result as the machine's event.
    pub(super) async fn perform(&mut self, action: &Action, held: &mut Option<Held>) -> Event {
        match action {
            Action::Open(d) => {
                self.closed(*d).await;
                match (self.open(*d).await, self.station.ports()) {
                    (
                        Event::Fault {
                            mut fault,
                            trace_started,
                        },
                        Some((i, s)),
                    ) => {
                        fault.message = crate::port_swap::name_ports(&fault.message, &i, &s);
                        Event::Fault {
                            fault,
                            trace_started,
                        }
                    }
                    (ev, _) => ev,
                }
            }
            Action::Home => {
                let Some(stage) = self.stage.as_mut() else {
                    return not_open(Device::Stage);
                };
                tracing::info!("homing the stage");
                match stage.home().await {
                    Ok(()) => Event::Homed,
                    Err(e) => fault(Device::Stage, &e),
                }
            }
            Action::EnsureIdle => {
                let Some(i) = self.instrument.as_mut() else {
                    return not_open(Device::Instrument);
                };
                match i.ensure_idle().await {
                    Ok(()) => Event::Idle,
                    Err(e) => fault(Device::Instrument, &e),
                }
            }
            Action::Move(target) => {
                let Some(stage) = self.stage.as_mut() else {
                    return not_open(Device::Stage);
                };
                match stage.move_to(*target).await {
                    Ok(a) => {
                        self.readback = Some(a.readback);
                        Event::Arrived
                    }
                    Err(e) => fault(Device::Stage, &e),
                }
            }
            Action::Trace => {
                let Some(i) = self.instrument.as_mut() else {
                    return not_open(Device::Instrument);
                };
                let before = i.traces_started();
                let started_at = Utc::now();
                match i.trace().await {
                    Ok(traced) => {
                        let (traced, read_again) = second_look(i, traced, &self.ra_before).await;
                        let p = &traced.profile;
                        let summary = TracedSummary {
                            points: p.len(),
                            pitch_x_mm: p.pitch_x_mm,
                            first_non_finite: p
                                .heights_um
                                .iter()
                                .position(|z| !z.is_finite())
                                .map(|k| (k, p.heights_um[k])),
                            conditions: p.conditions.clone(),
                            ra_um: traced
                                .results
                                .iter()
                                .find(|r| r.name.trim().eq_ignore_ascii_case("ra"))
                                .and_then(|r| r.value),
                        };
                        *held = Some(Held {
                            traced,
                            read_again,
                            readback: self.readback,
                            started_at,
                            finished_at: Utc::now(),
                        });
                        Event::Traced(summary)
                    }
                    Err(e) => {
                        // Unknown to the driver: the trace is taken as started.
                        let trace_started = match (before, i.traces_started()) {
                            (Some(b), Some(a)) => a > b,
                            _ => true,
                        };
                        Event::Fault {
                            fault: Fault::of(Device::Instrument, &e),
                            trace_started,
                        }
                    }
                }
            }
            Action::Cleanup => {
                self.cleanup().await;
                Event::CleanedUp
            }
            Action::SetTimer(d) => {
                tokio::time::sleep(*d).await;
                Event::TimerFired
            }
            other => unreachable_effect(other),
        }
    }

    /// Opens and verifies a device: at the start of a new scan its report is kept; once the
    /// scan has a start record a different instrument or controller is a fatal fault.
    pub(super) async fn open(&mut self, device: Device) -> Event {
        let fatal = |message: String| Event::Fault {
            fault: Fault {
                device,
                class: FaultClass::Fatal,
                ng_code: None,
                message,
            },
            trace_started: false,
        };
        match device {
            Device::Instrument => {
                let mut i = match self.station.open_instrument().await {
                    Ok(i) => i,
                    Err(f) => return open_fault(f),
                };
                let report = match i.probe().await {
                    Ok(r) => r,
                    Err(e) => return fault(Device::Instrument, &e),
                };
                if let Some(want) = &self.identity {
                    let got = &report.identity;
                    if got.model != want.model
                        || got.firmware != want.firmware
                        || got.drive_unit != want.drive_unit
                    {
                        return fatal(format!(
                            "a different instrument answered: model {}, firmware {:?}, drive unit {:?}; the scan started with model {}, firmware {:?}, drive unit {:?}",
                            got.model, got.firmware, got.drive_unit, want.model, want.firmware, want.drive_unit
                        ));
                    }
                } else {
                    for w in &report.warnings {
                        tracing::warn!("instrument: {w}");
                    }
                    self.warnings.extend(report.warnings.iter().cloned());
                    self.probe = Some(report);
                }
                self.instrument = Some(i);
                Event::Opened {
                    device,
                    position_trusted: true,
                }
            }
            Device::Stage => {
                let mut st = match self.station.open_stage(self.direction).await {
                    Ok(s) => s,
                    Err(f) => return open_fault(f),
                };
                let report = match st.connect().await {
                    Ok(r) => r,
                    Err(e) => return fault(Device::Stage, &e),
                };
                match &self.stage_identity {
                    Some(want) if &report.identity != want => {
                        return fatal(format!(
                        "a different stage controller answered: {:?}; the scan started with {:?}",
                        report.identity, want
                    ))
                    }
                    Some(_) => {}
                    None if self.identity.is_none() => {
                        // A new scan: its targets are checked before anything moves.
                        match st.check_targets(&self.targets) {
                            Ok(w) => {
                                for w in &w {
                                    tracing::warn!("stage: {w}");
                                }
                                // Stage warnings first, as the journal always listed them.
                                let mut all = w;
                                all.append(&mut self.warnings);
                                self.warnings = all;
                            }
                            Err(e) => return fatal(Fault::of(Device::Stage, &e).message),
                        }
                        self.stage_identity = Some(report.identity.clone());
                    }
                    None => {}
                }
                self.stage = Some(st);
                Event::Opened {
                    device,
                    position_trusted: report.position_trusted,
                }
            }
        }
    }

    /// Best-effort abort of a running measurement and stop of the stage, bounded in time.
    pub(super) async fn cleanup(&mut self) {
        if let Some(i) = self.instrument.as_mut() {
            match tokio::time::timeout(CLEANUP_TIMEOUT, i.abort()).await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => tracing::warn!("instrument abort failed: {e}"),
                Err(_) => tracing::warn!("instrument abort timed out"),
            }
        }
        if let Some(s) = self.stage.as_mut() {
            match tokio::time::timeout(CLEANUP_TIMEOUT, s.stop()).await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => tracing::warn!("stage stop failed: {e}"),
                Err(_) => tracing::warn!("stage stop timed out"),
            }
        }
    }
}

fn fault<E: crate::devices::DeviceFault>(device: Device, e: &E) -> Event {
    Event::Fault {
        fault: Fault::of(device, e),
        trace_started: false,
    }
}

fn open_fault(f: Fault) -> Event {
    Event::Fault {
        fault: f,
        trace_started: false,
    }
}

fn not_open(device: Device) -> Event {
    Event::Fault {
        fault: Fault {
            device,
            class: FaultClass::Absent,
            ng_code: None,
            message: "not connected".to_owned(),
        },
        trace_started: false,
    }
}

fn unreachable_effect(a: &Action) -> Event {
    // The machine issues only device effects here; anything else is a bug worth a loud
    // message, not a panic in a night's scan.
    tracing::error!("internal: {a:?} performed as a device effect");
    Event::Fault {
        fault: Fault {
            device: Device::Instrument,
            class: FaultClass::Fatal,
            ng_code: None,
            message: format!("internal: {a:?} is not a device operation"),
        },
        trace_started: false,
    }
}

pub(super) fn is_device_effect(a: &Action) -> bool {
    matches!(
        a,
        Action::Open(_)
            | Action::Home
            | Action::EnsureIdle
            | Action::Move(_)
            | Action::Trace
            | Action::Cleanup
            | Action::SetTimer(_)
    )
}

impl<S: Station> Hands<'_, S> {
    /// Closes a device aside ([`super::station::close_aside`]); it is opened again only once
    /// that is done.
    pub(super) fn close(&mut self, device: Device) {
        let handle = match device {
            Device::Instrument => super::station::close_aside(self.instrument.take()),
            Device::Stage => super::station::close_aside(self.stage.take()),
        };
        if let Some(h) = handle {
            self.closing.push((device, h));
        }
    }

    /// Waits until the earlier port of `device` is closed.
    async fn closed(&mut self, device: Device) {
        let (mine, others): (Vec<_>, Vec<_>) = std::mem::take(&mut self.closing)
            .into_iter()
            .partition(|(d, _)| *d == device);
        self.closing = others;
        for (_, h) in mine {
            let _ = h.await;
        }
    }

    /// Takes the identities of the scan's start record: reopened devices must match them.
    pub(super) fn attach(&mut self, l: &Ledger) {
        self.identity = Some(InstrumentIdentity {
            model: l.start.instrument_model.clone(),
            firmware: l.start.firmware.clone(),
            drive_unit: l.start.drive_unit.clone(),
        });
        self.direction = ScanDirection::of_step(l.plan.y_step_nm);
        self.targets = l.plan.targets();
    }
}

impl<S: Station> Hands<'_, S> {
    pub(super) fn points(&self) -> u64 {
        match &self.probe {
            Some(r) => {
                expected_points(self.station.expected_pitch_um(&r.conditions), &r.conditions)
            }
            None => opening::LONGEST_PROFILE_POINTS,
        }
    }
}

/// A line whose instrument Ra is far from the lines' before it
/// ([`ra_far_from_neighbours`]) is read out a second time, once: one garbled read-out
/// must not make a line look like another surface. When the second read-out gives the same
/// Ra, the first is kept (and the commit keeps the line's warning); when it differs, the
/// second is kept, with the words the journal records. A failed second read-out keeps the
/// first.
async fn second_look<I: Instrument>(
    i: &mut I,
    first: TracedLine,
    before: &[f64],
) -> (TracedLine, Option<String>) {
    let Some(ra1) = instrument_ra_um(&first.results) else {
        return (first, None);
    };
    let Some(w) = ra_far_from_neighbours(ra1, before) else {
        return (first, None);
    };
    tracing::warn!("{w}; reading the line out a second time");
    match i.read_again().await {
        Ok(Some(second)) => match instrument_ra_um(&second.results) {
            Some(ra2) if ra2 != ra1 => {
                let said = format!(
                    "the instrument's Ra read {ra1} um on the first read-out, far from the lines before it, and {ra2} um on a second: the second read-out is kept"
                );
                tracing::warn!("{said}");
                (second, Some(said))
            }
            _ => {
                tracing::info!("the second read-out gave the same Ra {ra1} um; the first is kept");
                (first, None)
            }
        },
        Ok(None) => (first, None),
        Err(e) => {
            tracing::warn!("the second read-out failed ({e}); the first is kept");
            (first, None)
        }
    }
}
