//! Section `uncertainty` and `specification`: every per-line parameter's mean with its uncertainty (n, s,
//! the uncertainty of the mean, combined with the instrument's stated calibration
//! uncertainty, U at k = 2; the paper's Table 1 `mean ± s` for Ra, Rq, Rz) and, when the
//! scan is held to a specification, the verdict of its lines against each limit.
//!
//! The figures and the verdict are [`crate::specification`]'s pure functions; this section
//! only hands them the lines as the [`lines`](super::lines) section evaluated them, the band
//! they were evaluated in, and the specification and instrument uncertainty of the context.
//!
//! Layer 4 (reporting): depends on [`crate::specification`], [`crate::metrology::params`]
//! and the report's line entries.

use super::lines::LinesSection;
use super::SectionInput;
use crate::metrology::parameter_table::parameter;
use crate::metrology::params::Recipe;
use crate::metrology::sj_material_ratio::MaterialRatioReading;
use crate::report::document::LineReport;
use crate::specification::uncertainty::{all_statistics, mean_pm_s, Statistics};
use crate::specification::{
    judge, EvaluatedBand, InstrumentUncertainty, LineValues, Specification, SpecificationVerdict,
};
use serde::Serialize;

/// The means of the per-line parameters with their uncertainty.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UncertaintyReport {
    /// What the figures assume of the instrument's uncertainty.
    pub instrument: String,
    /// The paper's Table 1 form for Ra, Rq and Rz: `Ra 0.5770 ± 0.03100 µm` (mean ± s).
    pub table_1: Vec<String>,
    /// One entry per parameter a line has, in report.json's order of the line parameters.
    pub parameters: Vec<ParameterStatistics>,
}

/// One parameter's mean and uncertainty.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterStatistics {
    /// The name of the line parameter in report.json (`Ra_um`).
    pub parameter: &'static str,
    /// n, mean, s, u of the mean, the instrument's u, u_c, U, k.
    #[serde(flatten)]
    pub statistics: Statistics,
}

/// What the section adds to the report.
#[derive(Debug, Clone, PartialEq)]
pub struct SpecificationSection {
    /// The verdict, when there is a specification.
    pub verdict: Option<SpecificationVerdict>,
    /// The means with their uncertainty.
    pub uncertainty: UncertaintyReport,
}

/// The band the lines' values were computed in: `None` for P parameters (a form-only
/// evaluation), which no roughness callout speaks of.
fn band_of(recipe: &Recipe) -> Option<EvaluatedBand> {
    (recipe.profile == "R").then_some(EvaluatedBand {
        lambda_c_mm: recipe.lambda_c_mm,
        lambda_s_um: recipe.lambda_s_um,
        sampling_lengths: recipe.sampling_lengths,
    })
}

/// Runs the section over the lines of the [`lines`](super::lines) section, against the
/// context's specification.
pub fn section(input: &SectionInput<'_>, lines: &LinesSection) -> SpecificationSection {
    let options = &input.ctx.options;
    characterise(
        &lines.lines,
        input.ctx.scan.as_ref().map(|s| s.lines_planned as usize),
        &lines.recipe.lines,
        options.specification.as_ref(),
        &options.instrument.unwrap_or_default(),
        options.material_ratio,
    )
}

/// The section over `lines` as evaluated under `recipe`, of a scan whose plan asks for
/// `planned_lines` (`None` for a grid); limits on the material-ratio family are judged in
/// `reading` (the means and their uncertainty stay ISO's, the instrument's reading being
/// reported beside them per line).
pub fn characterise(
    lines: &[LineReport],
    planned_lines: Option<usize>,
    recipe: &Recipe,
    specification: Option<&Specification>,
    instrument: &InstrumentUncertainty,
    reading: MaterialRatioReading,
) -> SpecificationSection {
    let params: Vec<_> = lines.iter().map(|l| &l.params).collect();
    let parameters: Vec<ParameterStatistics> = all_statistics(&params, instrument)
        .into_iter()
        .map(|(parameter, statistics)| ParameterStatistics {
            parameter,
            statistics,
        })
        .collect();
    let table_1 = (["Ra", "Rq", "Rz"].into_iter().filter_map(parameter))
        .filter_map(|q| {
            let p = parameters.iter().find(|p| p.parameter == q.key)?;
            Some(mean_pm_s(q.name, &p.statistics, q.unit))
        })
        .collect();
    let verdict = specification.filter(|s| !s.is_empty()).map(|s| {
        let read: Vec<_> = lines
            .iter()
            .map(|l| reading.applied(&l.params, l.material_ratio_sj_series.as_ref()))
            .collect();
        let values: Vec<LineValues<'_>> = lines
            .iter()
            .zip(&read)
            .map(|(l, params)| LineValues {
                index: l.index,
                params,
                flagged: !l.readout_warnings.is_empty(),
            })
            .collect();
        let band = band_of(recipe);
        let mut v = judge(s, &values, planned_lines, band.as_ref(), instrument);
        v.material_ratio = Some(reading.statement());
        let on_material_ratio = s.limits.iter().any(|c| {
            use crate::specification::Parameter::{Rk, Rpk, Rvk};
            matches!(c.parameter, Rk | Rpk | Rvk)
        });
        if on_material_ratio && reading == MaterialRatioReading::Instrument {
            v.summary
                .push_str(" [Rk, Rpk, Rvk as the SJ series reads them]");
        }
        v
    });
    SpecificationSection {
        verdict,
        uncertainty: UncertaintyReport {
            instrument: instrument.statement(),
            table_1,
            parameters,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrology::params::{analyze_profile, LineAnalysis, RoughnessParams};
    use crate::specification::Verdict;

    /// The section of `lines` of a grid, no instrument uncertainty stated.
    fn judged(
        lines: &[LineReport],
        recipe: &Recipe,
        spec: Option<&Specification>,
        reading: MaterialRatioReading,
    ) -> SpecificationSection {
        let none = InstrumentUncertainty::default();
        characterise(lines, None, recipe, spec, &none, reading)
    }

    fn line(index: u32, ra: f64, a: &LineAnalysis) -> LineReport {
        LineReport {
            index,
            y_mm: index as f64 * 0.01,
            y_readback_mm: None,
            params: RoughnessParams {
                ra_um: ra,
                ..a.params.clone()
            },
            rmr_table: Vec::new(),
            evaluation_length: a.evaluation_length.clone(),
            blank_reasons: a.blank_reasons.clone(),
            material_ratio_sj_series: None,
            instrument: None,
            model_vs_measured: None,
            readout_warnings: Vec::new(),
        }
    }

    #[test]
    fn the_lines_are_judged_in_their_band_and_p_parameters_are_not_compared() {
        // A real line's analysis gives the recipe (λc, N) and the other parameters.
        let heights: Vec<f64> = (0..2667)
            .map(|i| (i as f64 * 0.0015 * std::f64::consts::TAU / 0.1).sin())
            .collect();
        let profile = crate::profile::Profile::new(0.0015, heights);
        let a = analyze_profile(&profile).unwrap();
        let n = a.recipe.sampling_lengths;
        let lines: Vec<LineReport> = [0.5, 0.7, 0.9]
            .iter()
            .enumerate()
            .map(|(i, ra)| line(i as u32, *ra, &a))
            .collect();
        let spec = Specification::parse(&[format!("Ra{n} max 0.8")]).unwrap();
        let iso = MaterialRatioReading::Iso;
        let s = judged(&lines, &a.recipe, Some(&spec), iso);
        let v = s.verdict.unwrap();
        // Line 3 (index 2) is above 0.8 µm: the max rule fails, no uncertainty stated.
        assert_eq!(v.verdict, Verdict::DoesNotConform);
        assert_eq!(v.limits[0].lines_beyond, vec![3]);
        // Mean 0.7, s = 0.2, u = 0.2/√3; Table 1 with mean ± s.
        let ra = &s.uncertainty.parameters[0];
        assert_eq!(ra.parameter, "Ra_um");
        assert!((ra.statistics.mean - 0.7).abs() < 1e-12);
        assert!((ra.statistics.s.unwrap() - 0.2).abs() < 1e-12);
        assert!((ra.statistics.u_mean.unwrap() - 0.2 / 3f64.sqrt()).abs() < 1e-12);
        assert!(
            s.uncertainty.table_1[0].starts_with("Ra 0.7000 ± 0.2000 µm"),
            "{:?}",
            s.uncertainty.table_1
        );
        // The same values as P parameters (a form-only evaluation): no roughness band.
        let mut p = a.recipe.clone();
        p.profile = "P";
        let v = judged(&lines, &p, Some(&spec), iso).verdict.unwrap();
        assert_eq!(v.verdict, Verdict::NotDecidable);
        // Without a specification: the uncertainty only.
        assert!(judged(&lines, &a.recipe, None, iso).verdict.is_none());
    }

    /// The Mitutoyo export (an R profile, λc 2.5 mm): ISO's Rpk 2.722 µm, the SJ series'
    /// 2.912 µm (its display). A limit of 2.8 µm between them conforms in ISO's reading and
    /// does not in the instrument's; the verdict says which reading it used.
    #[test]
    fn a_limit_on_rpk_is_judged_in_the_reading_asked_for() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/real/mitutoyo_surftest_R.x_mm_z_um.csv"
        );
        let g = crate::input::read(path.as_ref(), &Default::default())
            .unwrap()
            .grid;
        let options = crate::metrology::params::Options {
            lambda_c_mm: 2.5,
            apply_lambda_c: false,
            ..Default::default()
        };
        let a =
            crate::metrology::params::analyze_line(&g.heights_um, g.pitch_x_mm, &options).unwrap();
        let mut l = line(0, a.params.ra_um, &a);
        l.material_ratio_sj_series = Some(
            crate::metrology::sj_material_ratio::sj_material_ratio(
                &a.roughness_um,
                &Default::default(),
            )
            .unwrap(),
        );
        assert!(l.params.material.rk.rpk_um < 2.8);
        let n = a.recipe.sampling_lengths;
        let spec = Specification::parse(&[format!("Rpk{n} max 2.8")]).unwrap();
        let line = std::slice::from_ref(&l);
        let verdict = |reading| {
            judged(line, &a.recipe, Some(&spec), reading)
                .verdict
                .unwrap()
        };
        let iso = verdict(MaterialRatioReading::Iso);
        assert_eq!(iso.verdict, Verdict::Conforms, "{iso:?}");
        assert_eq!(
            iso.material_ratio,
            Some(MaterialRatioReading::Iso.statement())
        );
        let sj = verdict(MaterialRatioReading::Instrument);
        assert_eq!(sj.verdict, Verdict::DoesNotConform, "{sj:?}");
        assert!(sj
            .summary
            .ends_with("[Rk, Rpk, Rvk as the SJ series reads them]"));
        assert_eq!(
            sj.material_ratio,
            Some(MaterialRatioReading::Instrument.statement())
        );
        // The means and their uncertainty stay ISO's whichever reading judges.
        let rpk = |reading| {
            judged(line, &a.recipe, None, reading)
                .uncertainty
                .parameters
                .into_iter()
                .find(|p| p.parameter == "Rpk_um")
                .unwrap()
                .statistics
                .mean
        };
        assert_eq!(
            rpk(MaterialRatioReading::Iso),
            rpk(MaterialRatioReading::Instrument)
        );
    }
}
