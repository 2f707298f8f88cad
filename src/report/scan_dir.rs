//! A scan's characterisation: the lines of a completed scan handed over by the runner (in
//! memory, with the surface it fitted), or the lines of a scan directory read back
//! (`surfscan analyze SCAN_DIR`, which fits them with the same degrees). Both go through
//! [`characterise_scan_lines`], so the same lines give the same report.
//!
//! A partial, aborted or failed scan is characterised with the complete lines it has; the
//! lines [`crate::input`] left out (one of their two files missing, not vouched for by the
//! journal) are named in its findings, which become the report's first warnings.
//!
//! Layer 4 (reporting): depends on [`crate::scan`] (its journal and line types, and the
//! [`Characterise`] contract the runner calls), [`crate::input`], [`crate::fit`] and the
//! sections.

use super::context::{Model, ModelFit, ReportContext, ScanAnalysisOptions};
use super::document::{Completeness, Report, ScanStatus, Traceability};
use super::error::ReportError;
use super::header::LabHeader;
use super::{characterise, ScanOutputs};
use crate::fit::{max_residual_mm, FitOptions};
use crate::grid::Grid;
use crate::input::scan::grid_of_lines;
use crate::input::{GridInput, InputError, Source, VouchedLines};
use crate::metrology::outliers::LineSpike;
use crate::metrology::params::Options;
use crate::metrology::surface_model::{fit_model, ModelRecipe};
use crate::numfmt::line_label;
use crate::profile::{FilterKind, ProfileKind};
use crate::scan::journal::{StartRecord, StopRecord, StopStatus};
use crate::scan::line::StoredLine;
use crate::scan::outputs::{Characterise, Characterised, CompletedScan, FitSummary, GridShape};
use crate::scan::results::ScanResults;
use crate::specification::{InstrumentUncertainty, Specification};
use std::borrow::Cow;
use std::path::Path;
use std::time::Instant;

/// The degrees to fit a scan with: each as asked for, else the scan's frozen plan (from
/// its start record), else the paper's 5.
pub fn scan_degrees(
    degree_u: Option<usize>,
    degree_v: Option<usize>,
    start: Option<&StartRecord>,
) -> FitOptions {
    let paper = FitOptions::default();
    FitOptions::degrees(
        degree_u
            .or(start.map(|s| s.plan.degree_u))
            .unwrap_or(paper.degree_u),
        degree_v
            .or(start.map(|s| s.plan.degree_v))
            .unwrap_or(paper.degree_v),
    )
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
    let plan = start.map(|s| &s.plan);
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
        (Some(lc), Some(r)) => format!("given ({lc} mm, overriding the recorded {r} mm)"),
        (Some(lc), None) => format!("given ({lc} mm; the instrument recorded none)"),
        (None, Some(r)) => format!("the instrument's recorded conditions ({r} mm)"),
        (None, None) => format!(
            "default {} mm (the instrument recorded no λc; set --lc to choose)",
            o.lambda_c_mm
        ),
    };
    o.lambda_c_mm = options.lambda_c_mm.unwrap_or(o.lambda_c_mm);
    let kind = line.meta.profile.kind;
    let unfiltered = if options.no_filter {
        Some("asked for (--no-filter)")
    } else if kind == ProfileKind::R {
        Some("the instrument exported an R profile, already λc-filtered")
    } else if line.profile.conditions.filter == Some(FilterKind::None) {
        Some("the instrument's conditions record the filter as none")
    } else {
        None
    };
    o.apply_lambda_c = unfiltered.is_none();
    let filter_reason = match unfiltered {
        Some(why) => format!("no λc filter: {why}"),
        None => {
            format!("λc filter applied: the stored profile is of kind {kind:?}, not an R profile")
        }
    };
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

/// A scan's lines as they are characterised.
#[derive(Debug, Clone, Copy)]
pub struct ScanLines<'a> {
    /// The scan directory.
    pub dir: &'a Path,
    /// The grid read from the lines.
    pub grid: &'a Grid,
    /// The lines whose files are complete.
    pub lines: &'a [StoredLine],
    /// The indices of the lines whose files are not.
    pub incomplete: &'a [u32],
    /// What the journal says of the scan, if it has one.
    pub facts: Option<ScanFacts<'a>>,
}

/// Characterises a scan's lines with `model` (the surface fitted through them) and writes the
/// files into `out`: the work behind both the runner's end of scan and
/// [`characterise_scan`].
pub fn characterise_scan_lines(
    scan_lines: ScanLines<'_>,
    model: Model<'_>,
    surface: ModelFit<'_>,
    fit: Option<FitSummary>,
    options: &ScanAnalysisOptions,
    mut warnings: Vec<String>,
) -> Result<ScanOutputs, ReportError> {
    let ScanLines {
        dir,
        grid,
        lines,
        incomplete,
        facts,
    } = scan_lines;
    let first = lines.first().ok_or_else(|| InputError::NoLines {
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
    // A line kept with a doubt about its read-out (heights beyond the detector's range, the
    // instrument's Ra disagreeing, a repeated block) is named: its heights may not be the
    // surface's.
    for l in lines {
        for w in &l.meta.readout_warnings {
            warnings.push(format!(
                "line {} was kept with a read-out warning: {w}",
                line_label(l.meta.id.index)
            ));
        }
    }
    let scan = facts.map(|f| {
        let lines_planned = f.start.plan.lines;
        let stopped_ok = match f.stop {
            Some(st) => st.status == StopStatus::Success,
            None => f.completing,
        };
        let complete =
            stopped_ok && incomplete.is_empty() && lines_planned as usize == grid.index.len();
        ScanStatus {
            status: if complete {
                Completeness::Complete
            } else {
                Completeness::Partial
            },
            stop: f.stop.cloned(),
            lines_planned,
            lines_used: grid.index.clone(),
            lines_incomplete: incomplete.to_vec(),
            lines_in_journal: f.journal_lines.to_vec(),
        }
    });
    if let Some(s) = scan.as_ref().filter(|s| s.status == Completeness::Partial) {
        warnings.push(format!(
            "partial scan ({}): characterised with the {} lines it has",
            match &s.stop {
                Some(st) => format!("stopped: {}, {}", st.status.as_str(), st.reason),
                None => "no stop record".to_string(),
            },
            grid.index.len()
        ));
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
    let mut options = options.clone();
    if let Some(f) = facts {
        let (specification, instrument) = judged_by(f.start, &mut warnings);
        options.specification = options.specification.or(specification);
        options.instrument = options.instrument.or(Some(instrument));
    }
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
        lab: options.lab.clone().unwrap_or_else(|| {
            facts
                .map(|f| LabHeader::of_frozen_config(&f.start.config))
                .unwrap_or_default()
        }),
    };
    let out = options.out_dir.clone().unwrap_or_else(|| dir.to_path_buf());
    let mut outputs = characterise(grid, model, surface, ctx, &out)?;
    outputs.incomplete_lines = incomplete.to_vec();
    Ok(outputs)
}

/// What a scan is judged by, from its start record: the limits of the recipe its job froze
/// (none without a job or limits) and the calibration uncertainty its configuration stated.
/// A frozen recipe that cannot be read again (a journal edited by hand) is named in the
/// warnings and the scan is not judged.
fn judged_by(
    start: &crate::scan::journal::StartRecord,
    warnings: &mut Vec<String>,
) -> (Option<Specification>, InstrumentUncertainty) {
    let instrument = InstrumentUncertainty {
        expanded_relative_pct: start.config["traceability"]["calibration-uncertainty-pct"].as_f64(),
    };
    let specification = start.job.as_ref().and_then(|j| {
        match Specification::of_recipe_text(&j.recipe_text) {
            Ok(s) if s.is_empty() => None,
            Ok(s) => Some(s),
            Err(e) => {
                warnings.push(format!(
                    "the specification of recipe {:?} frozen in the journal cannot be read ({e}): the scan is not judged; analyze it with the limits again",
                    j.recipe
                ));
                None
            }
        }
    });
    (specification, instrument)
}

/// Fits `grid` as `recipe` says and summarises the fit (no IGES written): the surface to
/// hand over to the characterisation (which lets it go once the model is sampled) with the
/// spikes replaced before fitting, the summary, and the seconds the fit took.
pub fn fit_for_report(
    grid: &Grid,
    recipe: &ModelRecipe,
) -> ((ModelFit<'static>, Vec<LineSpike>), Option<FitSummary>, f64) {
    let t = Instant::now();
    let fit = fit_model(grid, recipe);
    let fit_s = t.elapsed().as_secs_f64();
    let summary = fit.as_ref().ok().map(|m| {
        let f = &m.fit;
        let residual = max_residual_mm(f, grid);
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
    let handed_over = match fit {
        Ok(m) => (Ok(Cow::Owned(m.fit)), m.replaced),
        Err(e) => (Err(e), Vec::new()),
    };
    (handed_over, summary, fit_s)
}

/// Characterises the scan in `dir` (a partial, aborted or failed one with the complete lines
/// it has): fits its lines with the degrees of `options` (default: the scan's frozen plan,
/// else 5/5) and writes `report.json`, `summary.csv`, the plots, `measured.x3p` and
/// `model.x3p` into the scan directory (or `options.out_dir`). Returns the paths and the
/// warnings.
pub fn characterise_scan(
    input: &GridInput,
    options: &ScanAnalysisOptions,
) -> Result<ScanOutputs, ReportError> {
    let (dir, grid) = (Path::new(&input.described), &input.grid);
    let Source::Scan(vouched) = &input.source else {
        return Err(InputError::Usage(format!("{} is not a scan directory", dir.display())).into());
    };
    let VouchedLines {
        lines,
        incomplete,
        journal,
        ..
    } = vouched.as_ref();
    let state = journal.as_ref().ok();
    let recipe = scan_recipe(options, state.map(|s| &s.start), lines);
    let ((surface, replaced), summary, fit_s) = fit_for_report(grid, &recipe);
    let journal_lines: Vec<u32> = state
        .map(|s| s.lines.iter().map(|l| l.id.index).collect())
        .unwrap_or_default();
    let facts = state.map(|s| ScanFacts {
        start: &s.start,
        stop: s.stop.as_ref(),
        journal_lines: &journal_lines,
        completing: false,
    });
    let model = Model {
        recipe,
        replaced: &replaced,
        fit_s,
    };
    characterise_scan_lines(
        ScanLines {
            dir,
            grid,
            lines,
            incomplete,
            facts,
        },
        model,
        surface,
        summary,
        options,
        input.findings.clone(),
    )
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

/// A report in a few figures for the status, the hook and the queue: the specification's
/// verdict, the Ra and Rz means over the lines, the measured grid's Sa, the warnings.
pub fn results_of(report: &Report) -> ScanResults {
    let mean = |f| crate::report::sections::lines::finite_mean(&report.lines, f);
    ScanResults {
        verdict: report.specification.as_ref().map(|s| s.verdict),
        verdict_summary: report.specification.as_ref().map(|s| s.summary.clone()),
        ra_mean_um: mean(|l| l.params.ra_um),
        rz_mean_um: mean(|l| l.params.rz_um),
        sa_um: report.surface_grid.as_ref().map(|g| g.params.sa_um),
        warnings: report.warnings.len(),
    }
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
            replaced: scan.replaced,
            fit_s: 0.0,
        };
        let grid = grid_of_lines(scan.lines, &scan.dir.join("lines"))?;
        let out = characterise_scan_lines(
            ScanLines {
                dir: scan.dir,
                grid: &grid,
                lines: scan.lines,
                incomplete: &[],
                facts: Some(facts),
            },
            model,
            Ok(Cow::Borrowed(scan.fit)),
            Some(scan.summary.clone()),
            &options,
            Vec::new(),
        )?;
        let complete = out.complete();
        let verdict = out.verdict_line();
        let written = out.files;
        let mut files = vec![written.report_html, written.summary_csv];
        files.extend(written.plots);
        files.push(written.measured_x3p);
        files.extend(written.model_x3p);
        let results = results_of(&out.report);
        Ok(Characterised {
            files,
            warnings: out.warnings,
            complete,
            verdict,
            results: Some(results),
        })
    }
}

#[cfg(test)]
mod tests {
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
