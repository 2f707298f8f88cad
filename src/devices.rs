//! The contracts between the scan runner and the device drivers.
//!
//! The scan layer sees the profiler as an [`Instrument`] and the y axis as a [`YAxis`]
//! (the motion policy over a stage driver). Drivers classify their errors with
//! [`DeviceFault::class`] so the runner decides uniformly: suspend and reconnect when a
//! device is absent, abandon and re-trace the line on a transient fault, re-home when the
//! stage position is lost, fail the scan on a fatal fault.
//!
//! [`Device`] names the instrument or the stage wherever the scan says which one (a fault, a
//! journal's interruption record); [`Fault`] is a driver's error reduced to what the scan
//! decides on (which device, its class, the NG code, the message).
//!
//! Layer 0 (vocabulary): depends on [`crate::profile`] and [`crate::units`]; no I/O.

use crate::profile::{Conditions, InstrumentResult, Profile};
use crate::units::Nm;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Which device of the station: what a fault concerns, what an interruption record names
/// (`"instrument"` / `"stage"` in the journal).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Device {
    /// The profiler.
    Instrument,
    /// The y stage.
    Stage,
}

impl Device {
    /// `instrument` / `stage`.
    pub fn name(self) -> &'static str {
        match self {
            Device::Instrument => "instrument",
            Device::Stage => "stage",
        }
    }
}

impl fmt::Display for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How the scan layer must react to a device error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultClass {
    /// The device is gone (unplugged, EOF/EIO) or cannot be opened: suspend the scan,
    /// reconnect with backoff, re-verify identity, then re-trace the current line.
    Absent,
    /// The device says nothing: no byte came back after a command, or the link took none of
    /// the command's bytes (powered off or asleep behind its adapter, a hung adapter, flow
    /// control holding the host back). Waited for like an absent device, without a time
    /// limit: the port is closed and opened again with backoff until it answers.
    Silent,
    /// The device answered, but wrongly or not yet (garbled or cut-off reply, busy NG code,
    /// a trace or motion that does not end in time, a missed target): abandon the current
    /// line and re-trace it with backoff, within the session's transient-fault time budget.
    Transient,
    /// The stage position can no longer be trusted (reset, alarm, not referenced): re-home
    /// before the next move (a bounded number of times per line).
    PositionLost,
    /// A condition the operator must fix (battery abnormal, profile read-out unsupported,
    /// conditions changed, soft limit): the scan fails with this reason.
    Fatal,
}

/// Implemented by every driver error so the runner can react without knowing the driver.
pub trait DeviceFault: std::error::Error + Send + Sync + 'static {
    /// How the scan should react.
    fn class(&self) -> FaultClass;
    /// The instrument's NG code, when the device answered with one.
    fn ng_code(&self) -> Option<u16> {
        None
    }
}

/// A device error as the runner handles it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fault {
    /// The device.
    pub device: Device,
    /// How to react.
    pub class: FaultClass,
    /// The instrument's NG code, when it answered with one.
    pub ng_code: Option<u16>,
    /// The driver's message (names the command and the cause).
    pub message: String,
}

impl Fault {
    /// Reduces a driver error.
    pub fn of<E: DeviceFault>(device: Device, e: &E) -> Fault {
        Fault {
            device,
            class: e.class(),
            ng_code: e.ng_code(),
            message: e.to_string(),
        }
    }

    /// Whether the device said "not now": the SJ-210's busy, still processing or no
    /// results yet (NG011, NG033, NG101; `crate::sj210::ng`), as opposed to a wrong answer.
    pub fn is_busy(&self) -> bool {
        matches!(self.ng_code, Some(11 | 33 | 101))
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.device, self.message)?;
        if let Some(c) = self.ng_code {
            if !self.message.contains(&format!("NG{c:03}")) {
                write!(f, " (NG{c:03})")?;
            }
        }
        Ok(())
    }
}

/// Battery state (`RDSTU01`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Battery {
    /// More than 60 % (`000`).
    Good,
    /// Below 60 % (`001`): warn.
    Low,
    /// Abnormal: temperature, voltage or no battery (`002`): refuse to scan.
    Abnormal,
    /// Charging (`003`).
    Charging,
    /// Any other code.
    Unknown(u16),
}

/// Who the instrument is (`RDSJ 00`, `RDSJ 01`, the configured model).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InstrumentIdentity {
    /// Configured model id ("sj210", "sj220", "sj310", "sj410").
    pub model: String,
    /// Firmware version string as reported.
    pub firmware: String,
    /// Drive unit type as reported (standard, transverse, retractable).
    pub drive_unit: String,
}

/// Whether profile read-out works on this firmware, and why not when it does not.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "status")]
pub enum ProfileReadout {
    /// The safe probe (total-count request) was answered.
    Supported {
        /// Points the instrument holds now (0 before any trace).
        points_now: u32,
    },
    /// The firmware refused it: the NG code and the operator's options.
    Unsupported {
        /// NG code received, if any.
        ng_code: Option<u16>,
        /// What the operator can do.
        advice: String,
    },
}

/// What the capability probe found at connect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeReport {
    /// Identity.
    pub identity: InstrumentIdentity,
    /// Battery state.
    pub battery: Battery,
    /// Measurement conditions (`RDCON`).
    pub conditions: Conditions,
    /// Number of customised result parameters (`RDPAR`).
    pub parameter_count: u32,
    /// Profile read-out capability.
    pub profile_readout: ProfileReadout,
    /// Things an operator should know (battery low, pitch assumptions…).
    pub warnings: Vec<String>,
}

/// One completed trace: the profile and the instrument's own results.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TracedLine {
    /// The profile with pitch, kind and conditions attached.
    pub profile: Profile,
    /// Every result parameter the instrument reported (`RDPAR`, then one `RDRES…02` each),
    /// in its order; see [`InstrumentResult`] for the fields.
    pub results: Vec<InstrumentResult>,
    /// Where the x pitch came from ("config", "lambda-s 2.5 um", …).
    pub pitch_source: String,
    /// Warnings raised while tracing (length mismatch, retried reads…), for the log.
    pub warnings: Vec<String>,
    /// Doubts about the read-out that one re-read of the profile did not clear; the line is
    /// kept with them, and they belong in its stored metadata and in the report.
    pub readout_warnings: Vec<ReadoutWarning>,
}

/// A block of the profile read-out that repeated the block before it (the instrument's
/// read-out cursor went back).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RepeatedBlock {
    /// 1-based number of the block request that answered the previous block again.
    pub block: u32,
    /// 0-based index of its first height in the read-out.
    pub first_point: u32,
    /// Number of values in it.
    pub values: u32,
}

/// A named doubt about a line's profile read-out, kept with the line after one re-read of
/// the profile did not clear it. JSON: `{"kind": "repeated-block", "blocks": [...]}` or
/// `{"kind": "ra-disagrees", "instrument_um": …, "ours_um": …, "tolerance_um": …}`,
/// `{"kind": "beyond-detector-range", "span_um": …, "range_um": …}` or
/// `{"kind": "ra-unit-unknown", "unit": …}`, or (checked at commit against the lines before
/// it, with no re-read) `{"kind": "ra-far-from-neighbours", "ra_um": …, "median_um": …,
/// "lines": …, "factor": …}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum ReadoutWarning {
    /// Blocks received twice in a row: the heights after them may be shifted by a block.
    RepeatedBlock {
        /// The repeated blocks of the kept read-out.
        blocks: Vec<RepeatedBlock>,
    },
    /// The instrument's Ra and the Ra computed from the read-out heights differ by more
    /// than the tolerance (the rule is in `crate::sj210::sanity`).
    RaDisagrees {
        /// The instrument's Ra, µm.
        instrument_um: f64,
        /// Ra from the read-out heights, µm.
        ours_um: f64,
        /// The allowed difference, µm.
        tolerance_um: f64,
    },
    /// The heights span more than the detector can measure: they cannot be the surface's
    /// (heights in the wrong unit, nm read as µm).
    BeyondDetectorRange {
        /// Highest minus lowest height of the read-out, µm.
        span_um: f64,
        /// The detector's measuring range, µm (`[instrument] detector-range-um`).
        range_um: f64,
    },
    /// The instrument's Ra is in a unit this program does not know, so the heights were
    /// not checked against it.
    RaUnitUnknown {
        /// The unit as the instrument printed it.
        unit: String,
    },
    /// The instrument's Ra of this line is far from the Ra of the lines traced before it
    /// (the rule is in `crate::sj210::sanity`): heights in another unit, the stylus off the
    /// part, another surface.
    RaFarFromNeighbours {
        /// This line's Ra, µm.
        ra_um: f64,
        /// The median Ra of the lines before it, µm.
        median_um: f64,
        /// How many lines before it the median is of.
        lines: u32,
        /// The ratio beyond which a line is flagged, either way.
        factor: f64,
    },
}

impl std::fmt::Display for ReadoutWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReadoutWarning::RepeatedBlock { blocks } => {
                let list: Vec<String> = blocks
                    .iter()
                    .map(|b| format!("{} (from point {})", b.block, b.first_point))
                    .collect();
                write!(
                    f,
                    "repeated read-out block(s) {}: the instrument's read-out cursor went back, later heights may be shifted",
                    list.join(", ")
                )
            }
            ReadoutWarning::RaDisagrees {
                instrument_um,
                ours_um,
                tolerance_um,
            } => write!(
                f,
                "the instrument's Ra {instrument_um} um and Ra {ours_um:.4} um from the read-out heights differ by more than {tolerance_um:.4} um"
            ),
            ReadoutWarning::BeyondDetectorRange { span_um, range_um } => write!(
                f,
                "the heights span {span_um:.1} um, more than the detector's measuring range of {range_um} um ([instrument] detector-range-um): they cannot be the surface's (heights in the wrong unit, nm read as um?)"
            ),
            ReadoutWarning::RaFarFromNeighbours {
                ra_um,
                median_um,
                lines,
                factor,
            } => write!(
                f,
                "its Ra {ra_um} um is more than {factor} times away from the median Ra {median_um} um of the {lines} lines before it: heights in another unit, the stylus off the part or another surface?"
            ),
            ReadoutWarning::RaUnitUnknown { unit } => write!(
                f,
                "the instrument's Ra is in {unit:?}, a unit this program does not know: the heights were not checked against it"
            ),
        }
    }
}

/// The profiler as the scan runner uses it. One command is in flight at a time; control
/// commands are never retried by the implementation.
#[allow(async_fn_in_trait)]
pub trait Instrument {
    /// The driver's error type.
    type Error: DeviceFault;
    /// Capability probe: identity, battery, conditions, parameter count, auto-sleep off,
    /// profile read-out capability.
    async fn probe(&mut self) -> Result<ProbeReport, Self::Error>;
    /// Makes sure the instrument reads idle (`000`), sending the return command on `005`.
    /// The stage never moves unless this succeeded.
    async fn ensure_idle(&mut self) -> Result<(), Self::Error>;
    /// Traces one line and reads results and profile back.
    async fn trace(&mut self) -> Result<TracedLine, Self::Error>;
    /// Best-effort abort of a running measurement (only after reading "measuring").
    async fn abort(&mut self) -> Result<(), Self::Error>;
    /// Reads the results and the profile of the trace the instrument holds once more,
    /// checked as [`Instrument::trace`] checks them; `None` when the driver cannot.
    async fn read_again(&mut self) -> Result<Option<TracedLine>, Self::Error> {
        Ok(None)
    }
    /// How many traces the instrument accepted the start command of since it was opened,
    /// when the driver knows: a trace refused before it began (busy) is no attempt.
    fn traces_started(&self) -> Option<u64> {
        None
    }
}

/// What the y axis reported when it was connected and verified.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StageReport {
    /// Controller identity (`$I`, Zaber device id…).
    pub identity: String,
    /// Whether the controller's position can be trusted (homed and not reset since).
    pub position_trusted: bool,
    /// Position read back now.
    pub position: Nm,
}

/// A completed, verified move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Arrival {
    /// The absolute target.
    pub target: Nm,
    /// Position read back after settling.
    pub readback: Nm,
    /// Moves issued to get within the deadband (1 when the first landed).
    pub attempts: u32,
}

/// The y axis as the scan runner uses it: the motion policy (absolute targets, host-side
/// soft limits, unidirectional backlash approach, settle, read back, deadband, bounded
/// retries) over a GRBL or Zaber driver.
#[allow(async_fn_in_trait)]
pub trait YAxis {
    /// The driver's error type.
    type Error: DeviceFault;
    /// Checks a plan's targets before anything moves: soft limits and whether each target
    /// is exactly representable in device units. Returns warnings to record with the scan
    /// (inexact steps allowed by configuration); errors when the plan must be refused.
    fn check_targets(&self, targets: &[Nm]) -> Result<Vec<String>, Self::Error>;
    /// Opens the conversation, identifies the controller and reads its state.
    async fn connect(&mut self) -> Result<StageReport, Self::Error>;
    /// Whether the position is trusted (false after a reset, alarm or `WR`/`WH`).
    fn position_trusted(&self) -> bool;
    /// Homes the axis (the position is trusted afterwards).
    async fn home(&mut self) -> Result<(), Self::Error>;
    /// Moves to an absolute target, approaching from below (backlash taken out when the
    /// previous motion was a reverse move or is unknown), settles and verifies.
    async fn move_to(&mut self, target: Nm) -> Result<Arrival, Self::Error>;
    /// Stops any motion (best effort).
    async fn stop(&mut self) -> Result<(), Self::Error>;
}
