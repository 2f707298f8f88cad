//! What the characterisation is given besides the grid: how to evaluate the lines, the
//! model to describe, and what is known about the scan.
//!
//! Layer 4 (reporting): depends on [`crate::fit`], [`crate::metrology::params`], the
//! scan's frozen plan and fit summary ([`crate::scan`]) and [`crate::specification`].

use super::document::{ScanStatus, Traceability};
use crate::fit::{FitResult, MethodError, VMethod};
use crate::metrology::holdout::SUPPORTED_BELOW_SQ;
use crate::metrology::outliers::{LineSpike, SpikeOptions};
use crate::metrology::params::Options;
use crate::metrology::sj_material_ratio::MaterialRatioReading;
use crate::metrology::surface_model::ModelRecipe;
use crate::scan::outputs::FitSummary;
use crate::scan::plan::AnalysisPlan;
use crate::specification::{InstrumentUncertainty, Specification};
use std::borrow::Cow;
use std::path::PathBuf;

/// How a scan or grid is characterised. [`Default`]: 31 model curves, 101 levels, λc and
/// filter from the recorded conditions, the middle line in the overlay, the degrees of the
/// scan's frozen plan (5/5 without one), output into the scan directory.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanAnalysisOptions {
    /// Profile curves extracted from the model for the bearing area curves (paper: 31).
    pub curves: usize,
    /// Equal height levels per bearing area curve (paper: 101).
    pub levels: usize,
    /// λc in mm overriding the instrument's recorded cut-off (default `None`: the recorded
    /// λc, or 0.8 mm when none is recorded). It is also the sampling length.
    pub lambda_c_mm: Option<f64>,
    /// Never apply the λc filter (default `false`: filter primary profiles, not R profiles).
    pub no_filter: bool,
    /// Line index drawn in the measured-vs-model overlay (default `None`: the middle line used).
    pub overlay_line: Option<u32>,
    /// Degree of the model along u (default `None`: the scan's frozen plan, else 5).
    pub degree_u: Option<usize>,
    /// Degree of the model along v (default `None`: the scan's frozen plan, else 5).
    pub degree_v: Option<usize>,
    /// Where the files go (default `None`: the scan directory itself).
    pub out_dir: Option<PathBuf>,
    /// The spike rule (default: 10 robust σ, at most 5 points).
    pub spikes: SpikeOptions,
    /// Leave the spikes out of the per-line and measured-grid parameters, bridged by the
    /// straight line between their neighbours (default `false`: flag them only).
    pub exclude_spikes: bool,
    /// The model between lines is supported when the hold-out rms is at most this × Sq
    /// (default [`SUPPORTED_BELOW_SQ`]).
    pub holdout_threshold: f64,
    /// The method across the lines of the model (default `None`: the scan's frozen plan,
    /// else the paper's interpolation).
    pub v_method: Option<VMethod>,
    /// Replace the spikes before fitting (default `None`: as the scan's frozen plan says,
    /// else no).
    pub replace_spikes: Option<bool>,
    /// The laboratory's header overriding the one a scan's journal recorded (default `None`:
    /// the recorded one, for a grid none).
    pub lab: Option<super::header::LabHeader>,
    /// The specification the lines are judged against (default `None`: a scan's own, the
    /// limits of the recipe its job froze into its journal; none for a grid).
    pub specification: Option<Specification>,
    /// The instrument's stated uncertainty (default `None`: a scan's own, the
    /// `[traceability] calibration-uncertainty-pct` its journal recorded; none for a grid).
    pub instrument: Option<InstrumentUncertainty>,
    /// The reading of the material-ratio family limits are judged in (default ISO's; both
    /// readings are reported).
    pub material_ratio: MaterialRatioReading,
    /// The contact analysis to add to the report (default `None`: none).
    pub contact: Option<super::sections::contact::ContactSectionOptions>,
}

impl ScanAnalysisOptions {
    /// These options with the characterisation a scan froze in its plan: curves, levels,
    /// λc, filter, spike rule, what is done with the spikes, the hold-out threshold and the
    /// contact.
    pub fn with_frozen(self, a: &AnalysisPlan) -> ScanAnalysisOptions {
        ScanAnalysisOptions {
            curves: a.curves,
            levels: a.levels,
            lambda_c_mm: a.lambda_c_mm,
            no_filter: a.no_filter,
            spikes: a.spikes,
            exclude_spikes: a.exclude_spikes,
            holdout_threshold: a.holdout_threshold,
            material_ratio: a.material_ratio,
            contact: a
                .contact
                .as_ref()
                .map(super::sections::contact::ContactSectionOptions::of),
            ..self
        }
    }
}

impl Default for ScanAnalysisOptions {
    fn default() -> ScanAnalysisOptions {
        ScanAnalysisOptions {
            curves: 31,
            levels: 101,
            lambda_c_mm: None,
            no_filter: false,
            overlay_line: None,
            degree_u: None,
            degree_v: None,
            out_dir: None,
            spikes: SpikeOptions::default(),
            exclude_spikes: false,
            holdout_threshold: SUPPORTED_BELOW_SQ,
            v_method: None,
            replace_spikes: None,
            lab: None,
            specification: None,
            instrument: None,
            material_ratio: MaterialRatioReading::Iso,
            contact: None,
        }
    }
}

/// The fitted surface the model sections describe, with its data parameters, or why the
/// grid could not be fitted: borrowed from a caller that keeps it (the runner, which wrote
/// it), or handed over ([`Cow::Owned`]) so that the characterisation lets it go once the
/// model is sampled (a 1000×10000 grid's net is 80 MB, beside the model's autocorrelation).
pub type ModelFit<'a> = Result<Cow<'a, FitResult>, MethodError>;

/// How the surface the model sections describe was made (degrees, method across the lines,
/// spikes replaced), which the hold-out refits follow too; the surface itself is a
/// [`ModelFit`].
#[derive(Debug, Clone, Copy)]
pub struct Model<'a> {
    /// How the surface was made.
    pub recipe: ModelRecipe,
    /// The spikes replaced before fitting (empty unless the recipe asks for it).
    pub replaced: &'a [LineSpike],
    /// Seconds the caller spent fitting the surface for this report, counted in the report's
    /// timings; 0 for a surface fitted before (the runner's, fitted as its lines arrived).
    pub fit_s: f64,
}

/// Everything besides the grid and the model that goes into a report.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportContext {
    /// The input as named in the report (a file or a scan directory).
    pub input: String,
    /// `"grid"` or `"scan"`.
    pub kind: &'static str,
    /// How every line is evaluated.
    pub line_options: Options,
    /// Where λc came from, for the recipe.
    pub lambda_c_source: String,
    /// Why the λc filter was or was not applied, for the recipe.
    pub filter_reason: String,
    /// Traceability (scans).
    pub traceability: Option<Traceability>,
    /// Scan status (scans).
    pub scan: Option<ScanStatus>,
    /// Summary of the fit the model sections describe.
    pub fit: Option<FitSummary>,
    /// Model curves, levels and the overlay line.
    pub options: ScanAnalysisOptions,
    /// Warnings gathered so far (e.g. while reading the lines).
    pub warnings: Vec<String>,
    /// The laboratory's header and the printed layout (`[report]`).
    pub lab: super::header::LabHeader,
}
