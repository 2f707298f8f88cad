//! `surfscan check-config [FILE | --config FILE]`: validates a station configuration exactly as the daemon
//! and `scan` load it (every table, every key, the plan), and every recipe in its `[jobs]
//! recipes` directory as a start would read it, without opening any device, and prints what
//! it would do. Device paths that are absent or are not device nodes are noted
//! (a device may be plugged in later); a port that is a regular file, a directory or another
//! node that can never be a serial port makes the file invalid, and so does an
//! `output.dir` on a tree that keeps no files (`/proc`, `/sys`, `/dev`) or a control socket
//! inside it.
//!
//! With `--require-devices` an absent device is not a note but a failure (exit 69): the
//! package's install script starts the service only on a configuration whose ports are
//! there, so a fresh install with the example's placeholder ports stays stopped.
//!
//! Exit status: 0 valid (notes are printed on standard error), 78 invalid or unreadable,
//! with the message naming the file, the key and the fix, 69 valid but a configured device
//! is absent (only with `--require-devices`).
//!
//! Layer 5 (composition): depends on [`crate::config`], [`crate::jobs::recipe`],
//! [`crate::transport`] and [`super::station`] (the configuration loaded as the commands that
//! run the station load it).

use super::station::load_config;
use super::{CliError, Exit, DEFAULT_CONFIG};
use crate::config::Config;
use crate::numfmt::{fmt, Quantity};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Arguments of `surfscan check-config`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Station configuration (TOML) [default: /etc/surfscan/surfscan.toml].
    #[arg(value_name = "CONFIG", conflicts_with = "config_flag")]
    pub config: Option<PathBuf>,
    /// The same file, given the way `scan`, `daemon` and the operator's commands take it.
    #[arg(long = "config", value_name = "FILE", id = "config_flag")]
    pub config_flag: Option<PathBuf>,
    /// Fail (exit 69) when a configured device is absent, instead of noting it: the ports
    /// are configured and plugged in.
    #[arg(long)]
    pub require_devices: bool,
}

impl Args {
    /// The file to check: the one given either way, else the station's default.
    pub fn path(&self) -> PathBuf {
        self.config
            .clone()
            .or_else(|| self.config_flag.clone())
            .unwrap_or_else(|| PathBuf::from(DEFAULT_CONFIG))
    }
}

/// The name a setting has in the file (its serde name), e.g. `sj210`, `grbl`.
fn name<T: serde::Serialize + std::fmt::Debug>(v: &T) -> String {
    serde_json::to_value(v)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| format!("{v:?}"))
}

/// What the configuration asks for, for people.
pub fn summary(config: &Config) -> String {
    let mut out = String::new();
    let i = &config.instrument;
    let _ = writeln!(
        out,
        "  instrument  {} on {} at {} baud",
        name(&i.model),
        i.port,
        i.baud
    );
    let s = &config.stage;
    let _ = writeln!(
        out,
        "  stage       {} on {} at {} baud",
        name(&s.protocol),
        s.port,
        s.baud
    );
    let sc = &config.scan;
    let _ = writeln!(
        out,
        "  scan        {} lines from y = {} mm in steps of {} mm",
        sc.lines,
        fmt(sc.y_start_mm, Quantity::PositionMm),
        fmt(sc.y_step_mm, Quantity::PositionMm)
    );
    let _ = writeln!(out, "  output      {}", config.output.dir.display());
    let _ = writeln!(out, "  control     {}", config.control.socket.display());
    out
}

/// The path as the kernel would resolve it: its longest existing ancestor made canonical
/// (links followed), the rest as written.
fn resolved(path: &Path) -> PathBuf {
    let mut rest = Vec::new();
    let mut head = path;
    loop {
        if let Ok(c) = std::fs::canonicalize(head) {
            return rest.iter().rev().fold(c, |acc, part| acc.join(part));
        }
        match (head.parent(), head.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_owned());
                head = parent;
            }
            _ => return path.to_path_buf(),
        }
    }
}

/// The kernel's own trees, which hold no storage: a scan written there is lost or refused.
const NOT_STORAGE: [(nix::sys::statfs::FsType, &str); 9] = {
    use nix::sys::statfs::*;
    [
        (PROC_SUPER_MAGIC, "proc (the kernel's view of processes)"),
        (SYSFS_MAGIC, "sysfs (the kernel's view of devices)"),
        (DEVPTS_SUPER_MAGIC, "devpts (terminals)"),
        (CGROUP_SUPER_MAGIC, "cgroup"),
        (CGROUP2_SUPER_MAGIC, "cgroup2"),
        (DEBUGFS_MAGIC, "debugfs"),
        (TRACEFS_MAGIC, "tracefs"),
        (SECURITYFS_MAGIC, "securityfs"),
        (BPF_FS_MAGIC, "bpf"),
    ]
};

/// `output.dir` on storage and the control socket outside it: the directory (or, before it
/// exists, its nearest existing ancestor) must be a directory on a file system that keeps
/// files, not `/proc`, `/sys` or `/dev`; the socket must not lie inside the scans' tree,
/// which is listed, archived and copied as scans.
pub fn check_paths(config: &Config) -> Result<(), String> {
    let out = &config.output.dir;
    let real = resolved(out);
    let mut existing = real.as_path();
    while !existing.exists() {
        match existing.parent() {
            Some(p) => existing = p,
            None => break,
        }
    }
    let not_storage = |what: &str| {
        format!(
            "output.dir = {} lies on {what}, which keeps no files; name a directory on the station's disk, e.g. \"/var/lib/surfscan/scans\"",
            out.display()
        )
    };
    if real.starts_with("/dev") && !real.starts_with("/dev/shm") {
        return Err(not_storage("/dev (device nodes)"));
    }
    if let Ok(st) = nix::sys::statfs::statfs(existing) {
        let ty = st.filesystem_type();
        if let Some((_, name)) = NOT_STORAGE.iter().find(|(t, _)| *t == ty) {
            return Err(not_storage(&format!("a {name} file system")));
        }
    }
    if existing == real && !real.is_dir() {
        return Err(format!(
            "output.dir = {} is not a directory; name the directory the scans are written to",
            out.display()
        ));
    }
    let socket = resolved(&config.control.socket);
    if socket.starts_with(&real) {
        return Err(format!(
            "control.socket = {} lies inside output.dir = {}, the scans' tree (listed, archived and copied as scans); put it elsewhere, e.g. \"/run/surfscan/control.sock\"",
            config.control.socket.display(),
            out.display()
        ));
    }
    Ok(())
}

/// The device paths checked: notes for absent devices, or the first port that can never be
/// a serial device as an error. The output and socket paths are checked first
/// ([`check_paths`]).
pub fn check_ports(config: &Config) -> Result<Vec<String>, String> {
    check_paths(config)?;
    // One device under two names (a udev link and its node) is the same port too.
    let resolve = |p: &str| std::fs::canonicalize(p).unwrap_or_else(|_| p.into());
    let (instrument, stage) = (&config.instrument.port, &config.stage.port);
    if resolve(instrument) == resolve(stage) {
        return Err(format!(
            "[instrument] port {instrument} and [stage] port {stage} are the same device; each device needs its own port (see `ls -l /dev/serial/by-id/`)"
        ));
    }
    let mut notes = Vec::new();
    for (what, port) in [
        ("instrument", &config.instrument.port),
        ("stage", &config.stage.port),
    ] {
        match crate::transport::check_device_node(port) {
            Ok(()) => {}
            Err(e) if e.is_absent() => notes.push(format!(
                "[{what}] port {port} is not present now (plug the device in, or correct the path)"
            )),
            Err(e) => return Err(format!("[{what}] port: {e}")),
        }
    }
    Ok(notes)
}

/// The configuration at `path` loaded as [`load_config`] loads it, its ports checked by
/// [`check_ports`]: with its hash and the notes on absent devices, or exit 78 naming the file.
pub fn load_checked(path: &Path) -> Result<(Config, String, Vec<String>), CliError> {
    let (config, hash) = load_config(path)?;
    let notes = check_ports(&config)
        .map_err(|e| CliError::new(Exit::Config, format!("config {}: {e}", path.display())))?;
    Ok((config, hash, notes))
}

/// Every recipe of the station's `[jobs] recipes` directory, read and validated as a start
/// reads it: their lines for people and notes, or the first invalid one (exit 78).
pub fn check_recipes(config: &Config) -> Result<(String, Vec<String>), CliError> {
    let dir = &config.jobs.recipes;
    let names = crate::jobs::recipe::names(dir).map_err(|e| {
        CliError::new(
            Exit::Config,
            format!(
                "[jobs] recipes = {}: cannot list the directory: {e}",
                dir.display()
            ),
        )
    })?;
    let mut notes = Vec::new();
    if names.is_empty() {
        notes.push(format!(
            "[jobs] recipes: no recipe (NAME.toml) in {}; scans run the station's [scan] plan",
            dir.display()
        ));
    }
    let mut out = String::new();
    for name in names {
        let r = crate::jobs::recipe::Recipe::load(dir, &name, config)
            .map_err(|e| CliError::new(Exit::Config, e.to_string()))?;
        let _ = writeln!(out, "  recipe      {name}: {}", r.summary(config));
    }
    Ok((out, notes))
}

/// Runs `surfscan check-config`.
pub fn run(args: Args) -> Result<(), CliError> {
    let path = args.path();
    let (config, hash, notes) = load_checked(&path)?;
    if args.require_devices {
        if let Some(absent) = notes.first() {
            return Err(CliError::new(
                Exit::Unavailable,
                format!("config {}: valid, but {absent}", path.display()),
            ));
        }
    }
    say!(
        "{}: valid (sha256 {})",
        path.display(),
        hash.get(..12).unwrap_or(&hash)
    );
    say_text!("{}", summary(&config));
    let (recipes, recipe_notes) = check_recipes(&config)?;
    say_text!("{recipes}");
    for note in notes.into_iter().chain(recipe_notes) {
        tell!("surfscan: note: {note}");
    }
    Ok(())
}
