//! A scan's characterisation: the lines of a completed scan handed over by the runner (in
//! memory, with the surface it fitted), or the lines of a scan directory read back
//! (`surfscan analyze SCAN_DIR`, which fits them with the same degrees). Both go through
//! [`characterise_scan_lines`], so the same lines give the same report.
//!
//! A partial, aborted or failed scan is characterised with the complete lines it has; lines
//! with only one of their two files are named in a warning, and so are the lines the journal
//! does not vouch for (a file changed since it was traced, a line never committed), which are
//! left out before they are read ([`load_vouched_lines`]). A line file that matches its
//! record but cannot be read is an error naming the file.
//!
//! Layer 4 (reporting): depends on [`crate::scan`] (its journal, store and line types, and
//! the [`Characterise`] contract the runner calls), [`crate::fit`] and the sections.

use super::context::{Model, ReportContext, ScanAnalysisOptions};
use super::document::{Completeness, ScanStatus, Traceability};
use super::error::ReportError;
use super::grid::LineGrid;
use super::{characterise, ScanOutputs};
use crate::fit::{max_residual_mm, FitOptions, MethodError};
use crate::metrology::params::Options;
use crate::metrology::surface_model::{fit_model, FittedModel, ModelRecipe};
use crate::numfmt::line_label;
use crate::profile::{FilterKind, ProfileKind};
use crate::scan::faults::NoFaults;
use crate::scan::journal::{
    read_journal, ResumeState, StartRecord, StopRecord, StopStatus, JOURNAL_FILE,
};
use crate::scan::line::StoredLine;
use crate::scan::outputs::{Characterise, Characterised, CompletedScan, FitSummary, GridShape};
use crate::scan::store::ScanStore;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// Why a complete line of a scan is left out: its journal does not vouch for it as it is.
#[derive(Debug, Clone, PartialEq)]
pub enum NotVouched {
    /// On disk, but the journal never committed it (the scan stopped before its record).
    Uncommitted,
    /// Its heights file differs from its journal record.
    Changed {
        /// The file's SHA-256.
        file_sha256: String,
        /// The journal's.
        journal_sha256: String,
    },
    /// Its heights file cannot be read (a bad sector, no permission), with why.
    Unreadable(String),
}

impl NotVouched {
    /// The reason in a few words, as the IGES Start section and `fit --report` give it.
    pub fn short(&self) -> &'static str {
        match self {
            NotVouched::Uncommitted => "never committed to the journal",
            NotVouched::Changed { .. } => "changed after it was traced",
            NotVouched::Unreadable(_) => "cannot be read",
        }
    }
}

/// A line of a scan left out, as `fit --report` lists it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LeftOut {
    /// 1-based line number.
    pub line: u64,
    /// Its heights file, as named in `lines/`.
    pub file: String,
    /// Why, in a few words.
    pub why: &'static str,
}

impl LeftOut {
    fn of(index: u32, why: &'static str) -> LeftOut {
        LeftOut {
            line: crate::numfmt::line_number(index),
            file: crate::scan::store::csv_name(index),
            why,
        }
    }
}

/// Line indices as a person reads them: 1-based, each with the heights file it is stored
/// in, `21 (0020.csv), 22 (0021.csv)`.
pub fn line_files(indices: &[u32]) -> String {
    indices
        .iter()
        .map(|&i| {
            format!(
                "{} ({})",
                crate::numfmt::line_number(i),
                crate::scan::store::csv_name(i)
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The warning for `count` lines (`list`) on disk that the journal never committed.
pub fn uncommitted_lines_warning(list: &str, count: usize) -> String {
    let (noun, are, them, their, were) = if count == 1 {
        ("line", "is", "it", "its", "it was")
    } else {
        ("lines", "are", "them", "their", "they were")
    };
    format!(
        "{noun} {list} {are} on disk but the journal never committed {them} (the scan stopped before {their} record); {were} left out"
    )
}

/// Checks the heights file of each line of `index` in `store` against the SHA-256 its
/// journal record holds (`state`): the lines without a record, whose file changed since, or
/// whose file cannot be read, each with why. A journal that cannot be read vouches for
/// nothing and leaves nothing out.
fn not_vouched(
    store: &ScanStore,
    state: Option<&ResumeState>,
    index: &[u32],
) -> Vec<(u32, NotVouched)> {
    let Some(state) = state else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for &i in index {
        let Some(record) = state.lines.iter().find(|l| l.id.index == i) else {
            out.push((i, NotVouched::Uncommitted));
            continue;
        };
        let why = match store.heights_sha256(i) {
            Ok(sha) if sha == record.csv_sha256 => continue,
            Ok(sha) => NotVouched::Changed {
                file_sha256: sha,
                journal_sha256: record.csv_sha256.clone(),
            },
            Err(e) => NotVouched::Unreadable(e.to_string()),
        };
        out.push((i, why));
    }
    out
}

/// How many lines of scan directory `dir` have both their files (0 when it is not a scan
/// directory): a count, without reading a line.
pub fn complete_line_count(dir: &Path) -> usize {
    ScanStore::open(dir, Arc::new(NoFaults))
        .and_then(|s| s.stored_indices())
        .map_or(0, |(complete, _)| complete.len())
}

/// The lines of a scan directory that its journal vouches for, read after their check.
#[derive(Debug)]
pub struct VouchedLines {
    /// The complete lines whose heights file is as the journal recorded it (every complete
    /// line when the journal cannot be read), in index order.
    pub lines: Vec<StoredLine>,
    /// Indices with only one of their two files (not read).
    pub incomplete: Vec<u32>,
    /// The complete lines the journal does not vouch for (not read), each with why.
    pub not_vouched: Vec<(u32, NotVouched)>,
    /// The journal, or why it cannot be read.
    pub journal: Result<ResumeState, crate::scan::journal::JournalError>,
}

impl VouchedLines {
    /// The warnings for the lines the journal does not vouch for, in the operator's words,
    /// each naming what to do.
    pub fn warnings(&self, lines_dir: &Path) -> Vec<String> {
        let uncommitted: Vec<u32> = self
            .not_vouched
            .iter()
            .filter(|(_, why)| *why == NotVouched::Uncommitted)
            .map(|(i, _)| *i)
            .collect();
        let mut out = Vec::new();
        if !uncommitted.is_empty() {
            out.push(uncommitted_lines_warning(
                &line_files(&uncommitted),
                uncommitted.len(),
            ));
        }
        let file = |i: u32| lines_dir.join(crate::scan::store::csv_name(i));
        // The changed lines first, then the unreadable ones.
        for (i, why) in &self.not_vouched {
            if let NotVouched::Changed {
                file_sha256,
                journal_sha256,
            } = why
            {
                out.push(format!(
                    "line {} ({}) was changed after it was traced: its SHA-256 {file_sha256} differs from the journal's {journal_sha256}; it was left out (restore the file to use it, or fit the edited heights as a grid CSV)",
                    crate::numfmt::line_number(*i),
                    file(*i).display()
                ));
            }
        }
        for (i, why) in &self.not_vouched {
            if let NotVouched::Unreadable(e) = why {
                out.push(format!(
                    "line {} ({}) cannot be read ({e}); it was left out (check the disk and the file's permissions)",
                    crate::numfmt::line_number(*i),
                    file(*i).display()
                ));
            }
        }
        out
    }

    /// Every line left out, incomplete or not vouched for, in line order.
    pub fn left_out(&self) -> Vec<LeftOut> {
        let mut out: Vec<LeftOut> = self
            .incomplete
            .iter()
            .map(|&i| LeftOut::of(i, "one of its two files missing"))
            .chain(
                self.not_vouched
                    .iter()
                    .map(|(i, why)| LeftOut::of(*i, why.short())),
            )
            .collect();
        out.sort_by_key(|l| l.line);
        out
    }

    /// The scan stopped with success, by its journal.
    pub fn completed(&self) -> bool {
        self.journal.as_ref().is_ok_and(|s| {
            s.stop
                .as_ref()
                .is_some_and(|s| s.status == StopStatus::Success)
        })
    }
}

/// The complete lines of scan directory `dir` checked against its journal before they are
/// read: a line file changed since it was traced (a bit flip, an
/// edit) or never committed is left out and named, never characterised as measured, and
/// one bad line does not take down the others. A file that matches its record and still
/// cannot be read is an error naming it. Without a readable journal every complete line is
/// read as it is.
pub fn load_vouched_lines(dir: &Path) -> Result<VouchedLines, ReportError> {
    if !dir.join("lines").is_dir() {
        return Err(ReportError::Lines {
            path: dir.to_path_buf(),
            reason: "is not a scan directory: it has no lines/ folder (a scan holds lines/NNNN.csv + NNNN.json and journal.jsonl)".to_string(),
        });
    }
    let store = ScanStore::open(dir, Arc::new(NoFaults))?;
    let (complete, incomplete) = store.stored_indices()?;
    let complete: Vec<u32> = complete.into_iter().collect();
    let journal = read_scan_journal(dir);
    let not_vouched = not_vouched(&store, journal.as_ref().ok(), &complete);
    let lines = complete
        .iter()
        .filter(|&&i| !not_vouched.iter().any(|(j, _)| *j == i))
        .map(|&i| store.load_line(i))
        .collect::<Result<Vec<_>, _>>()?;
    let vouched = VouchedLines {
        lines,
        incomplete: incomplete.into_iter().collect(),
        not_vouched,
        journal,
    };
    if vouched.lines.is_empty() {
        return Err(if complete.is_empty() {
            ReportError::NoLines {
                dir: dir.to_path_buf(),
                incomplete: vouched.incomplete,
            }
        } else {
            ReportError::Lines {
                path: dir.to_path_buf(),
                reason: format!(
                    "no line is as its journal recorded it: {}",
                    vouched.warnings(&dir.join("lines")).join("; ")
                ),
            }
        });
    }
    Ok(vouched)
}

/// The journal of a scan directory, when it can be read.
pub fn read_scan_journal(dir: &Path) -> Result<ResumeState, crate::scan::journal::JournalError> {
    let path = dir.join(JOURNAL_FILE);
    read_journal(&path).and_then(|rec| ResumeState::from_records(&path, &rec.records))
}

/// The degrees to fit a scan with: each as asked for, else the scan's frozen plan (from
/// its start record), else the paper's 5.
pub fn scan_degrees(
    degree_u: Option<usize>,
    degree_v: Option<usize>,
    start: Option<&StartRecord>,
) -> FitOptions {
    let paper = FitOptions::default();
    FitOptions {
        degree_u: degree_u
            .or(start.map(|s| s.plan.degree_u))
            .unwrap_or(paper.degree_u),
        degree_v: degree_v
            .or(start.map(|s| s.plan.degree_v))
            .unwrap_or(paper.degree_v),
    }
}

/// How to fit a scan's `lines`: degrees by [`scan_degrees`], the method across the lines and
/// the spike replacement as `options` ask, else as the scan's frozen plan says, else the
/// paper (interpolation, data as measured). Replaced spikes are found with `options.spikes`
/// (the plan's own rule when the plan asks for the replacement and `options` do not say).
pub fn scan_recipe(
    options: &ScanAnalysisOptions,
    start: Option<&StartRecord>,
    lines: &[StoredLine],
) -> ModelRecipe {
    let degrees = scan_degrees(options.degree_u, options.degree_v, start);
    let plan = start.map(|s| s.plan);
    let method = options
        .v_method
        .or(plan.map(|p| p.v_method))
        .unwrap_or_default();
    let replace_spikes = match options.replace_spikes {
        Some(true) => Some(options.spikes),
        Some(false) => None,
        None => plan.and_then(|p| p.replace_spikes),
    };
    let lambda_c_mm = lines.first().and_then(|l| {
        let (o, _, _) = scan_line_options(l, options);
        o.apply_lambda_c.then_some(o.lambda_c_mm)
    });
    ModelRecipe {
        degrees,
        method,
        replace_spikes,
        lambda_c_mm,
    }
}

/// How the lines of a scan are evaluated: λc from the override, else the recorded
/// conditions, else 0.8 mm; the λc filter unless `no_filter`, the profile is an R profile
/// (already λc-filtered by the instrument) or the recorded filter is none. Returns the
/// options and, for the recipe, where λc came from and why the filter was or was not applied.
pub fn scan_line_options(
    line: &StoredLine,
    options: &ScanAnalysisOptions,
) -> (Options, String, String) {
    let mut o = Options::from_profile(&line.profile);
    let recorded = line.profile.conditions.lambda_c_mm;
    let lambda_c_source = match (options.lambda_c_mm, recorded) {
        (Some(lc), Some(r)) => {
            o.lambda_c_mm = lc;
            format!("given ({lc} mm, overriding the recorded {r} mm)")
        }
        (Some(lc), None) => {
            o.lambda_c_mm = lc;
            format!("given ({lc} mm; the instrument recorded none)")
        }
        (None, Some(r)) => format!("the instrument's recorded conditions ({r} mm)"),
        (None, None) => format!(
            "default {} mm (the instrument recorded no λc; set --lc to choose)",
            o.lambda_c_mm
        ),
    };
    let kind = line.meta.profile.kind;
    let (apply, filter_reason) = if options.no_filter {
        (false, "no λc filter: asked for (--no-filter)".to_string())
    } else if kind == ProfileKind::R {
        (
            false,
            "no λc filter: the instrument exported an R profile, already λc-filtered".to_string(),
        )
    } else if line.profile.conditions.filter == Some(FilterKind::None) {
        (
            false,
            "no λc filter: the instrument's conditions record the filter as none".to_string(),
        )
    } else {
        (
            true,
            format!("λc filter applied: the stored profile is of kind {kind:?}, not an R profile"),
        )
    };
    o.apply_lambda_c = apply;
    (o, lambda_c_source, filter_reason)
}

/// What is known about the scan whose lines are characterised.
#[derive(Debug, Clone, Copy)]
pub struct ScanFacts<'a> {
    /// The start record (traceability, the frozen plan).
    pub start: &'a StartRecord,
    /// The stop record, if the scan has one.
    pub stop: Option<&'a StopRecord>,
    /// Line indices the journal records as completed.
    pub journal_lines: &'a [u32],
    /// The runner is completing the scan (every planned line on disk; its success stop
    /// record follows this report), so no stop record yet does not make it partial.
    pub completing: bool,
}

/// Characterises a scan's lines with `model` (the surface fitted through them) and writes the
/// files into `out`: the work behind both the runner's end of scan and
/// [`characterise_scan`].
#[allow(clippy::too_many_arguments)]
pub fn characterise_scan_lines(
    dir: &Path,
    lines: &[StoredLine],
    incomplete: &[u32],
    facts: Option<ScanFacts<'_>>,
    model: Model<'_>,
    fit: Option<FitSummary>,
    options: &ScanAnalysisOptions,
    mut warnings: Vec<String>,
) -> Result<ScanOutputs, ReportError> {
    let grid = LineGrid::of_scan(lines, &dir.join("lines"))?;
    if !incomplete.is_empty() {
        let labels: Vec<String> = incomplete.iter().map(|&i| line_label(i)).collect();
        warnings.push(incomplete_lines_warning(
            &labels.join(", "),
            incomplete.len(),
            &dir.join("lines"),
        ));
    }
    let first = lines.first().ok_or_else(|| ReportError::NoLines {
        dir: dir.to_path_buf(),
        incomplete: incomplete.to_vec(),
    })?;
    let (line_options, lambda_c_source, filter_reason) = scan_line_options(first, options);
    if let Some(l) = lines.iter().find(|l| {
        l.meta.profile.conditions != first.meta.profile.conditions
            || l.meta.profile.kind != first.meta.profile.kind
    }) {
        warnings.push(format!(
            "line {} was traced under other conditions than line {}; every line is evaluated as line {} ({})",
            line_label(l.meta.id.index),
            line_label(first.meta.id.index),
            line_label(first.meta.id.index),
            filter_reason
        ));
    }
    let lines_used: Vec<u32> = grid.index.clone();
    let scan = facts.map(|f| {
        let lines_planned = f.start.plan.lines;
        let stopped_ok = match f.stop {
            Some(st) => st.status == StopStatus::Success,
            None => f.completing,
        };
        let complete =
            stopped_ok && incomplete.is_empty() && lines_planned as usize == lines_used.len();
        ScanStatus {
            status: if complete {
                Completeness::Complete
            } else {
                Completeness::Partial
            },
            stop: f.stop.cloned(),
            lines_planned,
            lines_used: lines_used.clone(),
            lines_incomplete: incomplete.to_vec(),
            lines_in_journal: f.journal_lines.to_vec(),
        }
    });
    if let Some(s) = &scan {
        if s.status == Completeness::Partial {
            warnings.push(format!(
                "partial scan ({}): characterised with the {} lines it has",
                match &s.stop {
                    Some(st) => format!("stopped: {}, {}", st.status.as_str(), st.reason),
                    None => "no stop record".to_string(),
                },
                lines_used.len()
            ));
        }
    }
    // A complete scan finished when its last line was read out (the runner writing its
    // outputs and `analyze` reading the directory afterwards give the same time); one that
    // stopped otherwise, when its stop record says.
    let last_line = lines.iter().map(|l| l.meta.finished_at).max();
    let finished_at = facts.and_then(|f| match f.stop {
        Some(s) if s.status != StopStatus::Success => Some(s.time),
        Some(s) => last_line.or(Some(s.time)),
        None if f.completing => last_line,
        None => None,
    });
    let ctx = ReportContext {
        input: dir.display().to_string(),
        kind: "scan",
        line_options,
        lambda_c_source,
        filter_reason,
        traceability: facts.map(|f| Traceability::of_scan(f.start, finished_at)),
        scan,
        fit,
        options: options.clone(),
        warnings,
    };
    let out = options.out_dir.clone().unwrap_or_else(|| dir.to_path_buf());
    let mut outputs = characterise(&grid, model, ctx, &out)?;
    outputs.incomplete_lines = incomplete.to_vec();
    Ok(outputs)
}

/// Fits `grid` as `recipe` says and summarises the fit (no IGES written).
pub fn fit_for_report(
    grid: &LineGrid,
    recipe: &ModelRecipe,
) -> (Result<FittedModel, MethodError>, Option<FitSummary>, f64) {
    let t = Instant::now();
    let fit = fit_model(
        &grid.heights_um,
        grid.cols,
        &grid.index,
        grid.pitch_x_mm,
        &grid.y_mm,
        recipe,
    );
    let fit_s = t.elapsed().as_secs_f64();
    let summary = fit.as_ref().ok().map(|m| {
        let f = &m.fit;
        let residual = max_residual_mm(f, grid.pitch_x_mm, &grid.y_mm, &grid.heights_um, grid.cols);
        FitSummary::new(
            f,
            GridShape {
                rows: grid.rows(),
                cols: grid.cols,
            },
            residual,
            fit_s,
            Vec::new(),
            None,
        )
    });
    (fit, summary, fit_s)
}

/// Characterises the scan in `dir` (a partial, aborted or failed one with the complete lines
/// it has): fits its lines with the degrees of `options` (default: the scan's frozen plan,
/// else 5/5) and writes `report.json`, `summary.csv`, the plots, `measured.x3p` and
/// `model.x3p` into the scan directory (or `options.out_dir`). Returns the paths and the
/// warnings.
pub fn characterise_scan(
    dir: &Path,
    options: &ScanAnalysisOptions,
) -> Result<ScanOutputs, ReportError> {
    let t = Instant::now();
    // Only what the journal vouches for is characterised, as `fit` fits it; the others are
    // named.
    let vouched = load_vouched_lines(dir)?;
    let mut warnings = vouched.warnings(&dir.join("lines"));
    if let Err(e) = &vouched.journal {
        warnings.push(format!("no traceability: the journal cannot be used ({e})"));
    }
    let VouchedLines {
        lines,
        incomplete,
        journal,
        ..
    } = vouched;
    let state = journal.as_ref().ok();
    let recipe = scan_recipe(options, state.as_ref().map(|s| &s.start), &lines);
    let grid = LineGrid::of_scan(&lines, &dir.join("lines"))?;
    let (fitted, summary, fit_s) = fit_for_report(&grid, &recipe);
    drop(grid);
    let journal_lines: Vec<u32> = state
        .as_ref()
        .map(|s| s.lines.iter().map(|l| l.id.index).collect())
        .unwrap_or_default();
    let facts = state.as_ref().map(|s| ScanFacts {
        start: &s.start,
        stop: s.stop.as_ref(),
        journal_lines: &journal_lines,
        completing: false,
    });
    let model = Model {
        recipe,
        fit: fitted.as_ref().map(|m| &m.fit),
        replaced: fitted.as_ref().map_or(&[][..], |m| &m.replaced[..]),
        fit_s,
    };
    let load_s = t.elapsed().as_secs_f64() - fit_s;
    let mut outputs = characterise_scan_lines(
        dir,
        &lines,
        &incomplete,
        facts,
        model,
        summary,
        options,
        warnings,
    )?;
    outputs.elapsed_s += load_s;
    Ok(outputs)
}

/// The characterisation the runner calls when a scan completes: the scan's lines as it holds
/// them, the surface it fitted and wrote as IGES, and `[analysis]`'s options.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanCharacteriser {
    /// Curves, levels, λc, filter and spikes for a scan whose plan froze none (journals of
    /// older versions); a plan's frozen analysis wins over them. The degrees are the scan's
    /// own surface's.
    pub options: ScanAnalysisOptions,
}

impl Characterise for ScanCharacteriser {
    fn characterise(
        &self,
        scan: &CompletedScan<'_>,
    ) -> Result<Characterised, Box<dyn std::error::Error + Send + Sync>> {
        let journal_lines: Vec<u32> = scan.lines.iter().map(|l| l.meta.id.index).collect();
        let options = match &scan.start.plan.analysis {
            Some(a) => self.options.clone().with_frozen(a),
            None => self.options.clone(),
        };
        let facts = ScanFacts {
            start: scan.start,
            stop: None,
            journal_lines: &journal_lines,
            completing: true,
        };
        let model = Model {
            recipe: scan.recipe,
            fit: Ok(scan.fit),
            replaced: scan.replaced,
            fit_s: 0.0,
        };
        let out = characterise_scan_lines(
            scan.dir,
            scan.lines,
            &[],
            Some(facts),
            model,
            Some(scan.summary.clone()),
            &options,
            Vec::new(),
        )?;
        let complete = out.complete();
        let verdict = out.verdict_line();
        let mut files = vec![out.report_html, out.summary_csv];
        files.extend(out.plots);
        files.extend(out.measured_x3p);
        files.extend(out.model_x3p);
        Ok(Characterised {
            files,
            warnings: out.warnings,
            complete,
            verdict,
        })
    }
}

/// The warning for `count` lines (listed in `list`) that have only one of their two files in
/// `lines_dir` and were left out, in the singular for one.
pub fn incomplete_lines_warning(list: &str, count: usize, lines_dir: &Path) -> String {
    let (noun, has, their, were) = if count == 1 {
        ("line", "has", "its", "was")
    } else {
        ("lines", "have", "their", "were")
    };
    format!(
        "{noun} {list} {has} only one of {their} two files in {} and {were} left out",
        lines_dir.display()
    )
}

#[cfg(test)]
mod tests {

    #[test]
    fn lines_the_journal_never_committed_are_counted_in_the_warning() {
        assert_eq!(
            super::uncommitted_lines_warning("21 (0020.csv)", 1),
            "line 21 (0020.csv) is on disk but the journal never committed it (the scan stopped before its record); it was left out"
        );
        assert_eq!(
            super::uncommitted_lines_warning("21, 22", 2),
            "lines 21, 22 are on disk but the journal never committed them (the scan stopped before their record); they were left out"
        );
    }

    #[test]
    fn a_single_incomplete_line_is_named_in_the_singular() {
        let d = std::path::Path::new("/scan/lines");
        assert_eq!(
            super::incomplete_lines_warning("6 (0005.csv)", 1, d),
            "line 6 (0005.csv) has only one of its two files in /scan/lines and was left out"
        );
        assert_eq!(
            super::incomplete_lines_warning("6, 7", 2, d),
            "lines 6, 7 have only one of their two files in /scan/lines and were left out"
        );
    }
    use super::*;
    use crate::profile::{Conditions, NoHeights, Profile};
    use crate::scan::line::{LineIdentity, LineMeta};
    use crate::units::Nm;

    fn line(kind: ProfileKind, lambda_c_mm: Option<f64>, filter: Option<FilterKind>) -> StoredLine {
        let conditions = Conditions {
            lambda_c_mm,
            filter,
            ..Conditions::default()
        };
        let t = chrono::Utc::now();
        StoredLine {
            meta: LineMeta {
                id: LineIdentity {
                    index: 0,
                    y_target_nm: Nm(0),
                    y_readback_nm: None,
                    attempt: 1,
                    points: 3,
                },
                profile: Profile {
                    pitch_x_mm: 0.001,
                    heights_um: NoHeights,
                    kind,
                    conditions: conditions.clone(),
                },
                results: Vec::new(),
                readout_warnings: Vec::new(),
                started_at: t,
                finished_at: t,
            },
            profile: Profile {
                pitch_x_mm: 0.001,
                heights_um: vec![0.0; 3],
                kind,
                conditions,
            },
        }
    }

    #[test]
    fn the_recorded_kind_and_filter_decide_and_the_options_override() {
        let defaults = ScanAnalysisOptions::default();
        let (o, src, why) = scan_line_options(&line(ProfileKind::P, Some(2.5), None), &defaults);
        assert!(o.apply_lambda_c && o.lambda_c_mm == 2.5, "{o:?}");
        assert!(
            src.contains("recorded") && why.contains("applied"),
            "{src} / {why}"
        );

        let (o, _, why) = scan_line_options(&line(ProfileKind::R, Some(0.8), None), &defaults);
        assert!(!o.apply_lambda_c && why.contains("R profile"), "{why}");

        let (o, _, why) = scan_line_options(
            &line(ProfileKind::P, None, Some(FilterKind::None)),
            &defaults,
        );
        assert!(!o.apply_lambda_c && why.contains("none"), "{why}");

        let (o, src, _) = scan_line_options(&line(ProfileKind::P, None, None), &defaults);
        assert!(o.lambda_c_mm == 0.8 && src.contains("default"), "{src}");

        let forced = ScanAnalysisOptions {
            lambda_c_mm: Some(0.25),
            no_filter: true,
            ..ScanAnalysisOptions::default()
        };
        let (o, src, why) = scan_line_options(&line(ProfileKind::P, Some(0.8), None), &forced);
        assert!(!o.apply_lambda_c && o.lambda_c_mm == 0.25, "{o:?}");
        assert!(src.contains("overriding the recorded 0.8"), "{src}");
        assert!(why.contains("--no-filter"), "{why}");
    }
}
