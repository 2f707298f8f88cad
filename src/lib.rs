//! surfscan: unattended surface-roughness scanning with a Mitutoyo SJ-210 profiler and a
//! motorised y stage, incremental NURBS surface fitting, IGES output and characterisation.
//!
//! # Layout
//!
//! Layers, each usable without the ones above it (dependencies only point down):
//!
//! 0. Vocabulary, no I/O: [`units`] (mm, µm, integer nm), [`numfmt`] (numbers written for
//!    people), [`build_info`] (version and commit), [`profile`] (a traced line with its
//!    metadata), [`grid`] (the one grid of traced lines every analysis reads), [`nurbs`] (the
//!    surface as a value), [`devices`] (the contracts between the scan runner and the
//!    drivers), [`numbers`] (decimal numbers in CSV text, read fast), [`extremes`] (the lowest
//!    and highest of a run of numbers), [`port_swap`] (a reply in the other device's language:
//!    the ports swapped).
//! 1. Pure logic: [`fit`] (the paper's interpolation, incremental), [`iges`] (IGES 5.3
//!    writer/reader), [`metrology`] (ISO roughness, bearing area curves, areal parameters),
//!    [`specification`] (a part's limits, the 16 % and max rules, the uncertainty of a mean
//!    and the verdict), the codecs inside [`sj210`] and [`stage`].
//! 2. I/O adapters: [`transport`] (the only code that opens a serial port), the clients in
//!    [`sj210`] and [`stage`], generic over `AsyncRead + AsyncWrite`, [`atomic`] (durable
//!    file replacement, the one write primitive of the scan's files and the outputs) and
//!    [`panics`] (what a panic ends: its piece of work, or the process).
//! 3. The session: [`scan`] (plan, station, durable storage and journal, resume, the sans-IO
//!    session machine and the runner that performs its actions, the outputs of a completed
//!    scan).
//! 4. Process edges: [`config`] (the station's TOML, validated), [`telemetry`] (logging),
//!    [`input`] (the one reader of scan directories, grid and profile CSVs and X3P files),
//!    [`control`] (the operator's control socket), [`web`] (the station's page and its HTTP
//!    API, optional),
//!    [`service`] (systemd notifications), [`hook`] (the notification command),
//!    [`report`] (characterisation of a completed scan, a scan directory or a grid into
//!    report.json, report.html, summary.csv, plots and X3P, section by section; the runner
//!    reaches it through the scan's `Characterise` contract, supplied by the composition),
//!    [`pdf`] (a report's HTML page typeset as a PDF without a browser),
//!    [`station_lock`] (one process per station), [`jobs`] (recipes), [`publish`] (the scan's
//!    status and events to the lab's MQTT broker through a durable outbox, the raw-data
//!    archive, the results into the lab's SPC and QIF drop directories).
//! 5. Composition: [`cli`] (one file per subcommand) and `main.rs`.
//!
//! The simulator (`simulator/`, crate `surfscan-sim`) speaks the instrument's and the
//! stages' serial protocols with its own parsers, never this crate's codecs.

#![warn(missing_docs)]

pub mod atomic;
pub mod build_info;
pub mod cli;
pub mod config;
pub mod contact;
pub mod control;
pub mod devices;
pub mod extremes;
pub mod fit;
pub mod grid;
pub mod hook;
pub mod iges;
pub mod input;
pub mod jobs;
pub mod metrology;
pub mod numbers;
pub mod numfmt;
pub mod nurbs;
pub mod panics;
pub mod pdf;
pub mod port_swap;
pub mod profile;
pub mod publish;
pub mod report;
pub mod scan;
pub mod service;
pub mod sj210;
pub mod specification;
pub mod stage;
pub mod station_lock;
pub mod step;
pub mod telemetry;
pub mod transport;
pub mod units;
pub mod web;
pub mod x3p;
