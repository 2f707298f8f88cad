//! One reader for every input of the analysis commands (`fit`, `analyze`, `contact`): a scan
//! directory, a grid CSV of heights, an X3P file, a profile CSV (a grid of one line). Each
//! becomes one [`Grid`] under one bad-data policy, with the reader's findings in words:
//!
//! ```no_run
//! use surfscan::input::{read, ReadOptions};
//! let input = read("scan-dir".as_ref(), &ReadOptions::default())?;
//! for w in &input.findings {
//!     eprintln!("warning: {w}");
//! }
//! println!("{} of the input", input.grid.lines_used());
//! # Ok::<(), surfscan::input::InputError>(())
//! ```
//!
//! The policy, the same whichever command reads:
//!
//! - a line that cannot be used (a value that is not a number, a height that is not finite or
//!   beyond any surface, a number of points unlike the others'; a scan line the journal does
//!   not vouch for or with one of its two files missing; an X3P line holding invalid points)
//!   is left out and named, the other lines keep their y, nothing is filled in; the grid lists
//!   it in [`Grid::left_out`], and a result made from it is partial ("29 of 31 lines");
//! - a CSV that is not the plain format (a header line, `;` or tab separators, decimal commas,
//!   comment lines) is read as written and the reader says what it found; a number that
//!   cannot be read without guessing is refused with its line;
//! - the heights' unit is the `--z-unit` flag's ([`ReadOptions::z_unit`]), else the one a
//!   header names, else µm; a flag and a header that disagree are refused;
//! - a scale implausible for a stylus profile in µm ([`scale`]) is refused, naming the likely
//!   unit mix-up and the flag or header that fixes it, unless `--z-unit` states the unit
//!   (then it is a warning). A scan's heights are the instrument's and an X3P file's are in
//!   metres by the format: there it is a warning.
//!
//! Layer 4 (reading at the process edge): depends on [`crate::grid`], [`crate::scan`] (a scan
//! directory's store and journal) and the X3P reader of [`crate::x3p`].

pub mod profile;
pub mod rows;
pub mod scale;
pub mod scan;
pub mod text;

use crate::grid::{Grid, LeftOut};
use crate::scan::store_error::StoreError;
pub use scan::VouchedLines;
use std::path::{Path, PathBuf};
pub use text::Unit;

/// How to read an input. [`Default`]: no pitches given, the heights' unit from the file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadOptions {
    /// Pitch between a grid CSV's columns, mm (a grid CSV needs it; other inputs store their
    /// own and refuse it).
    pub pitch_x_mm: Option<f64>,
    /// Pitch between a grid CSV's rows, mm (as `pitch_x_mm`).
    pub pitch_y_mm: Option<f64>,
    /// The unit of a CSV's heights as the operator states it (`--z-unit`); `None`: a header's,
    /// else µm.
    pub z_unit: Option<Unit>,
}

/// What an input was.
#[derive(Debug)]
pub enum Source {
    /// A scan directory: the lines its journal vouches for (with their metadata) and the
    /// journal.
    Scan(Box<VouchedLines>),
    /// A grid CSV, its rows at multiples of the y pitch.
    GridCsv {
        /// The y pitch given, mm.
        pitch_y_mm: f64,
    },
    /// A profile CSV, a grid of one line.
    ProfileCsv,
    /// An X3P file.
    X3p {
        /// `SUR` or `PRF`.
        feature_type: String,
        /// Its y pitch, mm.
        pitch_y_mm: f64,
    },
}

/// An input read: the grid, what it was, how a report names it and what the reader found.
#[derive(Debug)]
pub struct GridInput {
    /// The lines used, and those left out.
    pub grid: Grid,
    /// What the input was.
    pub source: Source,
    /// The input as a report names it (an X3P file with its instrument and date).
    pub described: String,
    /// What the reader found beyond the plain format, and every line left out, in words;
    /// each is a warning for the operator.
    pub findings: Vec<String>,
}

impl GridInput {
    /// `"scan"`, `"grid"`, `"profile"` or `"x3p"`: the input's kind as a report names it.
    pub fn kind(&self) -> &'static str {
        match self.source {
            Source::Scan(_) => "scan",
            Source::GridCsv { .. } => "grid",
            Source::ProfileCsv => "profile",
            Source::X3p { .. } => "x3p",
        }
    }

    /// The pitch between the rows of a grid CSV or an X3P file, mm (a scan's lines and a
    /// profile have none).
    pub fn pitch_y_mm(&self) -> Option<f64> {
        match self.source {
            Source::GridCsv { pitch_y_mm } | Source::X3p { pitch_y_mm, .. } => Some(pitch_y_mm),
            _ => None,
        }
    }

    /// The input is one line: a profile CSV, or an X3P file of one line.
    pub fn is_profile(&self) -> bool {
        match &self.source {
            Source::ProfileCsv => true,
            Source::X3p { .. } => self.grid.lines_in_input() == 1,
            _ => false,
        }
    }
}

/// Why an input cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The file or directory cannot be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// What.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A scan directory or one of its line files cannot be read or is malformed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// No complete line to characterise.
    #[error("{dir}: no complete line to characterise (incomplete: {incomplete:?}); a scan needs at least one line with both NNNN.csv and NNNN.json")]
    NoLines {
        /// The scan directory.
        dir: PathBuf,
        /// Lines with one file only.
        incomplete: Vec<u32>,
    },
    /// The lines cannot form one grid.
    #[error("{path}: {reason}")]
    Lines {
        /// The offending file or directory.
        path: PathBuf,
        /// What differs or is wrong, with the values.
        reason: String,
    },
    /// The input does not go with the arguments (a pitch for a scan, none for a grid CSV, a
    /// unit flag against the header, a fitted surface where heights are read).
    #[error("{0}")]
    Usage(String),
}

impl InputError {
    /// The input cannot be read at all (the operating system's error): exit 74, not 1.
    pub fn is_io(&self) -> bool {
        matches!(
            self,
            InputError::Io { .. } | InputError::Store(StoreError::Io { .. })
        )
    }
}

/// What a file is, from its name and first bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// Text that may be a CSV.
    Csv,
    /// An IGES file (`.igs`/`.iges`, or 80-column lines with `S` in column 73).
    Iges,
    /// A zip archive or an `.x3p` file.
    X3p,
}

/// Classifies a file from its name and its first bytes (at least the first line).
pub fn sniff(path: &Path, head: &[u8]) -> FileKind {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if ext == "x3p" || head.starts_with(b"PK\x03\x04") {
        return FileKind::X3p;
    }
    let first = head.split(|b| *b == b'\n').next().unwrap_or(&[]);
    let first = first.strip_suffix(b"\r").unwrap_or(first);
    let iges_line = first.len() == 80 && first.get(72) == Some(&b'S');
    if ext == "igs" || ext == "iges" || iges_line {
        return FileKind::Iges;
    }
    FileKind::Csv
}

/// What the analysis commands read, for the messages.
const READS: &str = "surfscan reads a scan directory, a grid CSV of heights, a profile CSV (x_mm,z_um) or an X3P file";

/// Reads `path` — a scan directory, a grid CSV, a profile CSV or an X3P file — into one grid
/// under the module's policy.
pub fn read(path: &Path, options: &ReadOptions) -> Result<GridInput, InputError> {
    let given = |what: &str| {
        Err(InputError::Usage(format!(
            "--pitch-x/--pitch-y are for a grid CSV; {what} stores its own pitches"
        )))
    };
    if path.is_dir() {
        if options.pitch_x_mm.is_some() || options.pitch_y_mm.is_some() {
            return given("a scan directory");
        }
        if let Some(u) = options.z_unit {
            return Err(InputError::Usage(format!(
                "--z-unit {} is for a CSV; a scan's heights are in µm as the instrument gave them",
                u.flag()
            )));
        }
        let (grid, vouched, mut findings) = scan::read_scan(path)?;
        // The heights are the instrument's, in µm: an odd scale is said, not refused.
        for finding in scale::implausible(&grid, false) {
            findings.push(finding.describe("read as the instrument gave them"));
        }
        return Ok(GridInput {
            grid,
            source: Source::Scan(Box::new(vouched)),
            described: path.display().to_string(),
            findings,
        });
    }
    let bytes = std::fs::read(path).map_err(|source| InputError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    match sniff(path, &bytes) {
        FileKind::Iges => Err(InputError::Usage(format!(
            "{} is an IGES file (a fitted surface), not heights; {READS}",
            path.display()
        ))),
        FileKind::X3p => {
            if options.pitch_x_mm.is_some() || options.pitch_y_mm.is_some() {
                return given("an X3P file");
            }
            if let Some(u) = options.z_unit {
                return Err(InputError::Usage(format!(
                    "--z-unit {} is for a CSV; an X3P file states its heights in metres",
                    u.flag()
                )));
            }
            read_x3p(path, &bytes)
        }
        FileKind::Csv => read_csv(path, bytes, options),
    }
}

fn data_error(path: &Path, reason: impl Into<String>) -> InputError {
    InputError::Lines {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

/// A grid CSV or a profile CSV, from its bytes (`path` names it in the messages).
pub fn read_csv(
    path: &Path,
    bytes: Vec<u8>,
    options: &ReadOptions,
) -> Result<GridInput, InputError> {
    let mut text = String::from_utf8(bytes).map_err(|e| {
        data_error(
            path,
            format!(
                "not text (byte {} is not UTF-8); {READS}",
                e.utf8_error().valid_up_to()
            ),
        )
    })?;
    // Spreadsheet programs put a byte-order mark before "UTF-8 CSV": no part of the data.
    if text.starts_with('\u{feff}') {
        text.drain(..'\u{feff}'.len_utf8());
    }
    let layout = text::layout(&text).map_err(|e| data_error(path, e))?;
    let mut findings = layout.findings();
    let header_units = layout
        .header
        .as_ref()
        .map(|(_, h)| text::units_named(h))
        .unwrap_or_default();
    if profile::is_profile(&layout) {
        if options.pitch_x_mm.is_some() || options.pitch_y_mm.is_some() {
            return Err(InputError::Usage(
                "--pitch-x/--pitch-y are for a grid CSV; a profile CSV's x column gives its pitch"
                    .into(),
            ));
        }
        // The profile's own header line is its plain format: not a finding.
        findings.retain(|f| !f.contains("is a header"));
        let p = profile::read_profile(&text, &layout).map_err(|e| data_error(path, e))?;
        let (unit, stated) = z_unit(path, options.z_unit, p.z_unit.into_iter().collect())?;
        let mut z = p.z;
        if unit != Unit::Um {
            z.iter_mut().for_each(|v| *v *= unit.in_um());
        }
        findings.extend(unit_finding(unit, stated, p.z_unit.is_some()));
        let cols = z.len();
        let grid = Grid {
            x0_mm: p.x0_mm,
            ..Grid::new(z, cols, p.pitch_x_mm, vec![0.0])
        };
        return finish(path, grid, Source::ProfileCsv, findings, options, true);
    }
    let (Some(px), Some(py)) = (options.pitch_x_mm, options.pitch_y_mm) else {
        return Err(InputError::Usage(
            "a grid CSV needs --pitch-x MM and --pitch-y MM (a profile CSV starts with the header x_mm,z_um; a scan is a directory)".into(),
        ));
    };
    if let Some((_, h)) = &layout.header {
        let d = &layout.dialect;
        let names: Vec<String> = d.fields(h).iter().map(|f| text::column_name(f)).collect();
        if names.iter().any(|n| n == "y" || n == "profile") {
            return Err(data_error(
                path,
                format!(
                    "the header {:?} names the columns of a table of records (one point per line), not a grid of heights (one line of the surface per row); write one row of heights per traced line",
                    h.trim()
                ),
            ));
        }
    }
    let (unit, stated) = z_unit(path, options.z_unit, header_units.clone())?;
    findings.extend(unit_finding(unit, stated, !header_units.is_empty()));
    let rows = rows::read_rows(text, &layout, unit.in_um(), rows::PARALLEL_BYTES).map_err(|e| {
        data_error(
            path,
            format!("{e}; a grid CSV holds one row of heights per line"),
        )
    })?;
    let mut grid = Grid::new(
        rows.heights_um,
        rows.cols,
        px,
        rows.kept.iter().map(|&j| j as f64 * py).collect(),
    );
    grid.index = rows.kept.iter().map(|&j| j as u32).collect();
    grid.left_out = rows
        .left_out
        .into_iter()
        .map(|(_, line, why)| LeftOut {
            line: line as u64,
            file: None,
            why,
        })
        .collect();
    findings.extend(grid.left_out_warning());
    finish(
        path,
        grid,
        Source::GridCsv { pitch_y_mm: py },
        findings,
        options,
        false,
    )
}

/// How the heights' unit was decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stated {
    /// By `--z-unit`.
    Flag,
    /// By the file's header.
    Header,
    /// Nowhere: µm assumed.
    Assumed,
}

/// The heights' unit: the flag's, else the one the header names, else µm. A flag against the
/// header's unit, or a header naming several without a flag, is refused.
fn z_unit(
    path: &Path,
    flag: Option<Unit>,
    header: Vec<Unit>,
) -> Result<(Unit, Stated), InputError> {
    match (flag, header.as_slice()) {
        (Some(f), [h]) if f != *h => Err(InputError::Usage(format!(
            "--z-unit {} but the header of {} names {}: say one unit (remove the flag, or correct the header)",
            f.flag(),
            path.display(),
            h.symbol()
        ))),
        (Some(f), _) => Ok((f, Stated::Flag)),
        (None, []) => Ok((Unit::Um, Stated::Assumed)),
        (None, [h]) => Ok((*h, Stated::Header)),
        (None, several) => Err(InputError::Usage(format!(
            "the header of {} names several units ({}): say which the heights are in with --z-unit nm|um|mm",
            path.display(),
            several.iter().map(|u| u.symbol()).collect::<Vec<_>>().join(", ")
        ))),
    }
}

/// The finding for heights read in another unit than µm.
fn unit_finding(unit: Unit, stated: Stated, header: bool) -> Option<String> {
    (unit != Unit::Um).then(|| {
        format!(
            "heights in {} ({}) converted to µm",
            unit.symbol(),
            match (stated, header) {
                (Stated::Flag, _) => "--z-unit",
                (_, true) => "the header",
                _ => "assumed",
            }
        )
    })
}

/// The scale check, then the input: refused when the unit was not stated by the flag.
fn finish(
    path: &Path,
    grid: Grid,
    source: Source,
    mut findings: Vec<String>,
    options: &ReadOptions,
    profile: bool,
) -> Result<GridInput, InputError> {
    findings.extend(scale::too_long(&grid));
    let stated = options.z_unit.is_some();
    for finding in scale::implausible(&grid, profile) {
        let fix = if stated {
            format!(
                "read as given (--z-unit {})",
                options.z_unit.map_or("um", Unit::flag)
            )
        } else {
            "give the unit with --z-unit mm|um|nm (or in the header, e.g. z_mm); --z-unit um reads the heights as µm after all".to_string()
        };
        let words = finding.describe(&fix);
        if stated && !matches!(finding, scale::Implausible::XSpanTooShort(_)) {
            findings.push(words);
        } else {
            return Err(data_error(path, words));
        }
    }
    Ok(GridInput {
        grid,
        source,
        described: path.display().to_string(),
        findings,
    })
}

/// An X3P file: the grid with its own pitches, lines holding invalid points left out.
fn read_x3p(path: &Path, bytes: &[u8]) -> Result<GridInput, InputError> {
    let x = crate::x3p::read_x3p(bytes).map_err(|e| data_error(path, e.to_string()))?;
    let m = &x.meta;
    let source = [
        m.manufacturer.as_str(),
        m.model.as_str(),
        if m.serial.is_empty() { "" } else { "serial" },
        m.serial.as_str(),
    ]
    .iter()
    .filter(|s| !s.is_empty())
    .copied()
    .collect::<Vec<_>>()
    .join(" ");
    let described = format!(
        "{} (X3P {} of {} × {} points{}{})",
        path.display(),
        x.feature_type,
        x.rows,
        x.cols,
        if source.is_empty() {
            String::new()
        } else {
            format!(", {source}")
        },
        if m.date.is_empty() {
            String::new()
        } else {
            format!(", measured {}", m.date)
        }
    );
    let row = |r: usize| &x.heights_um[r * x.cols..(r + 1) * x.cols];
    let complete: Vec<usize> = (0..x.rows)
        .filter(|&r| row(r).iter().all(|v| v.is_finite()))
        .collect();
    let mut findings = Vec::new();
    if complete.len() < x.rows {
        let left: Vec<String> = (0..x.rows)
            .filter(|r| !complete.contains(r))
            .map(|r| (r + 1).to_string())
            .collect();
        findings.push(format!(
            "{} of {} points are marked invalid (not measured); lines {} hold them and were left out (nothing is filled in)",
            x.invalid_points,
            x.rows * x.cols,
            left.join(", ")
        ));
    }
    if complete.is_empty() {
        return Err(data_error(
            path,
            format!(
                "every line holds invalid (not measured) points ({} of {}); fill or crop them in the software that wrote the file, then read it again",
                x.invalid_points,
                x.rows * x.cols
            ),
        ));
    }
    let mut grid = Grid::new(
        complete
            .iter()
            .flat_map(|&r| row(r).iter().copied())
            .collect(),
        x.cols,
        x.pitch_x_mm,
        complete
            .iter()
            .map(|&r| x.offset_y_mm + r as f64 * x.pitch_y_mm)
            .collect(),
    );
    grid.x0_mm = x.offset_x_mm;
    grid.index = complete.iter().map(|&r| r as u32).collect();
    grid.left_out = (0..x.rows)
        .filter(|r| !complete.contains(r))
        .map(|r| LeftOut {
            line: r as u64 + 1,
            file: None,
            why: format!(
                "{} of its {} points invalid",
                row(r).iter().filter(|v| !v.is_finite()).count(),
                x.cols
            ),
        })
        .collect();
    // The format states metres: an odd scale is the file's, said but not refused.
    for finding in scale::implausible(&grid, x.rows == 1) {
        findings.push(finding.describe("read as the file states it (X3P heights are in metres)"));
    }
    Ok(GridInput {
        grid,
        source: Source::X3p {
            feature_type: x.feature_type,
            pitch_y_mm: x.pitch_y_mm,
        },
        described,
        findings,
    })
}
