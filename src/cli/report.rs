//! `surfscan report SCAN_DIR --pdf`: the printed report as a PDF, made on the station
//! without a browser — `SCAN_DIR/report.pdf`, or the file `-o` names — from the report a
//! characterisation wrote there (`report.json`, the plots' SVG files, the scan's journal).
//! The directory is any that `surfscan scan`, the daemon or `surfscan analyze` wrote a
//! report into.
//!
//! Exit status: 0 written (what it left out, e.g. an unreadable logo, on stderr); 74 no
//! readable `report.json` in the directory, or the PDF cannot be written where asked (both
//! named, with what to do); 2 without `--pdf`.
//!
//! Layer 5 (composition): depends on [`crate::report::render::report_pdf`] and
//! [`crate::atomic`].

use super::{CliError, Exit};
use std::io::Write as _;
use std::path::PathBuf;

/// Arguments of `surfscan report`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A directory with a report (a scan directory, or an `analyze -o` directory).
    #[arg(value_name = "SCAN_DIR")]
    pub dir: PathBuf,
    /// Write the printed report as a PDF (A4 or Letter as `[report] paper` says).
    #[arg(long, required = true)]
    pub pdf: bool,
    /// The PDF file to write [default: SCAN_DIR/report.pdf].
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
}

/// Runs `surfscan report`.
pub fn run(args: Args) -> Result<(), CliError> {
    let json_path = args.dir.join("report.json");
    let io = |m: String| CliError::new(Exit::Io, m);
    let bytes = std::fs::read(&json_path).map_err(|e| {
        io(format!(
            "{}: {e}: no report to print; `surfscan analyze {}` characterises the scan and writes one",
            json_path.display(),
            args.dir.display()
        ))
    })?;
    let report: serde_json::Value = serde_json::from_slice(&bytes).map_err(|e| {
        io(format!(
            "{}: not a report ({e}); `surfscan analyze {}` writes it again",
            json_path.display(),
            args.dir.display()
        ))
    })?;
    let (pdf, warnings) = crate::report::render::report_pdf(&args.dir, &report)
        .map_err(|e| CliError::new(Exit::Failed, format!("{}: {e}", json_path.display())))?;
    for w in warnings {
        tell!("surfscan report: {w}");
    }
    let out = args.output.unwrap_or_else(|| args.dir.join("report.pdf"));
    crate::atomic::write_atomically(&out, |f| f.write_all(&pdf)).map_err(|e| {
        io(format!(
            "{}: the PDF cannot be written ({e}); give a writable file with -o FILE",
            out.display()
        ))
    })?;
    say!("{}", out.display());
    Ok(())
}
