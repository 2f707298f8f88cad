//! surfscan-sim: speaks the serial protocols of the Mitutoyo SJ-210 family and of GRBL and
//! Zaber y stages over pseudo-terminals it creates, replaying recorded profiles, so the real
//! `surfscan` binary can be tested end to end without hardware.
//!
//! It parses commands with its own small parsers and computes instrument results with its own
//! simple code: it shares no protocol or metrology code with `surfscan`, so a bug cannot hide
//! by being the same on both ends.
//!
//! Layout:
//! * [`command`]: frame splitter and command parser (pure);
//! * [`roughness`]: the simplified Ra/Rq/Rz (pure);
//! * [`data`]: served profiles (three CSV formats) and line selection by stage y;
//! * [`instrument`]: the SJ-210/SJ-410 state machine, time as an input (sans-IO);
//! * [`replay`]: transcript format v1 and replay of recorded exchanges;
//! * [`fault`]: fault-injection specs;
//! * [`pty`]: the pseudo-terminals the simulator owns;
//! * [`line`]: the rate the host set on the instrument's pty, and what a host at the wrong
//!   rate gets (silence or noise);
//! * [`stats`]: counters of what the emulated instrument was asked, for tests and benches;
//! * [`server`]: the serve loop (pacing, faults, unplug/replug) and the [`Simulator`] builder.
//! * [`grbl`], [`zaber`]: the simulated y stages (motion, backlash, stage faults), attached
//!   with [`Simulator::grbl_stage`] / [`Simulator::zaber_stage`]; [`motion`]: their
//!   trapezoidal motion profiles (pure).
//! * [`station_config`]: the `surfscan` station configuration for the simulator's own links
//!   (pure).
#![warn(missing_docs)]

pub mod command;
pub mod data;
pub mod fault;
pub mod instrument;
pub mod line;
pub mod motion;
pub mod pty;
pub mod replay;
pub mod roughness;
pub mod server;
pub mod station_config;
pub mod stats;

pub use data::{ProfileSet, YPosition};
pub use fault::{Fault, FaultKind, FaultSpec};
pub use instrument::{Battery, InstrumentConfig, Model};
pub use server::{ReadyInfo, SimEvent, SimHandle, Simulator};

pub mod grbl;
pub mod zaber;
