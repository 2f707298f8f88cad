//! `surfscan export SCAN_DIR…`: writes completed scans' `<scan-id>.dfq` and `<scan-id>.qif`
//! into the drop directories again — the configuration's `[export]`, or those given on the
//! command line — e.g. after a drop directory was away longer than the operator wants to
//! wait, or for a scan made before `[export]` was configured. The files are the ones the
//! station writes when a scan completes ([`crate::publish::export`]), written atomically.
//!
//! Exit status: 0, 74 a scan that cannot be exported (no report) or a drop directory that
//! refused a file (named, with what to do), 78 the configuration cannot be read or has no
//! `[export]`.
//!
//! Layer 5 (composition): depends on [`crate::publish::export`] and the configuration.

use super::{CliError, Exit};
use crate::publish::export::{export_scan, Format};
use std::path::{Path, PathBuf};

/// Arguments of `surfscan export`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Station configuration; only its `[export]` table is read [default: /etc/surfscan/surfscan.toml].
    #[arg(long, value_name = "FILE", conflicts_with_all = ["dfq_dir", "qif_dir"])]
    pub config: Option<PathBuf>,
    /// Write the Q-DAS file into this directory (instead of the configuration's).
    #[arg(long, value_name = "DIR")]
    pub dfq_dir: Option<PathBuf>,
    /// Write the QIF file into this directory (instead of the configuration's).
    #[arg(long, value_name = "DIR")]
    pub qif_dir: Option<PathBuf>,
    /// The scan directories to export (each with its report.json).
    #[arg(required = true, value_name = "SCAN_DIR")]
    pub scans: Vec<PathBuf>,
}

/// Runs `surfscan export`.
pub fn run(args: Args) -> Result<(), CliError> {
    let targets: Vec<(Format, PathBuf)> = if args.dfq_dir.is_some() || args.qif_dir.is_some() {
        let mut t = Vec::new();
        if let Some(d) = args.dfq_dir {
            t.push((Format::Dfq, d));
        }
        if let Some(d) = args.qif_dir {
            t.push((Format::Qif, d));
        }
        t
    } else {
        let path = args
            .config
            .unwrap_or_else(|| PathBuf::from(super::DEFAULT_CONFIG));
        let (config, _) = super::station::load_config(&path)?;
        let x = config.export.ok_or_else(|| {
            CliError::new(
                Exit::Config,
                format!(
                    "config {}: no [export] table: add dfq-dir = \"DIR\" and/or qif-dir = \"DIR\", or give --dfq-dir/--qif-dir",
                    path.display()
                ),
            )
        })?;
        x.targets()
            .into_iter()
            .map(|(f, d)| (f, d.to_path_buf()))
            .collect()
    };
    let targets: Vec<(Format, &Path)> = targets.iter().map(|(f, d)| (*f, d.as_path())).collect();
    let mut failed = None;
    for scan in &args.scans {
        let mut done = Vec::new();
        match export_scan(scan, &targets, &mut done) {
            Ok(written) => {
                for p in written {
                    say!("{}", p.display());
                }
            }
            Err(e) => {
                tell!("surfscan export: {}: {e}", scan.display());
                failed.get_or_insert(e);
            }
        }
    }
    match failed {
        Some(e) => Err(CliError::new(
            Exit::Io,
            format!("not every scan was exported: {e}"),
        )),
        None => Ok(()),
    }
}
