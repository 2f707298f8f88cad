//! The surface a scan's outputs describe, as the user asked for it: the paper's fit by
//! default, or with the spikes of [`super::outliers`] replaced first (only when asked), and
//! with the paper's interpolation or a least-squares approximation across the lines
//! ([`crate::fit::VMethod`]). Whatever is not the paper is said: [`ModelRecipe::describe`] for
//! reports, [`ModelRecipe::start_lines`] for the IGES Start section, with every replaced
//! spike named.
//!
//! Depends on [`crate::grid`], [`crate::fit`], [`super::outliers`] and [`crate::numfmt`].

use super::outliers::{bridged_grid, find_grid_spikes, LineSpike, SpikeOptions};
use crate::fit::{fit_grid_with, FitOptions, FitResult, MethodError, VMethod};
use crate::grid::Grid;
use crate::numfmt::{fmt, line_number, Quantity};

/// How the surface is made. [`Default`]: the paper (5/5, interpolation, data as measured).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ModelRecipe {
    /// Degrees.
    pub degrees: FitOptions,
    /// Across the lines.
    pub method: VMethod,
    /// Replace the spikes this rule finds before fitting (`None`: fit the data as measured).
    pub replace_spikes: Option<SpikeOptions>,
    /// λc of the roughness profile the spike rule judges (`None`: the heights minus their
    /// least-squares line, for R profiles).
    pub lambda_c_mm: Option<f64>,
}

impl ModelRecipe {
    /// True for the paper's surface exactly (interpolation of the data as measured).
    pub fn is_paper(&self) -> bool {
        self.method == VMethod::Interpolate && self.replace_spikes.is_none()
    }

    /// One sentence for reports.
    pub fn describe(&self) -> String {
        let mut s = self.method.describe(self.degrees);
        if let Some(rule) = &self.replace_spikes {
            s.push_str(&format!(
                "; before fitting, every {}, was replaced by the straight line between its neighbours",
                rule.describe()
            ));
        }
        s
    }

    /// Lines for the IGES Start section naming the method and every replaced spike (at most
    /// 20 listed, then their count).
    pub fn start_lines(&self, replaced: &[LineSpike]) -> Vec<String> {
        let mut lines = vec![format!(
            "Across the lines: {}.",
            self.method.describe(self.degrees)
        )];
        if let Some(rule) = &self.replace_spikes {
            lines.push(format!(
                "Spikes replaced before fitting (asked for; the measured data are unchanged on disk): {} spike(s) found by the rule: {}.",
                replaced.len(),
                rule.describe()
            ));
            for s in replaced.iter().take(20) {
                lines.push(format!(
                    "Replaced: line {} (file {:04}) points {}..{} of the line (peak x = {} mm, height {} um), bridged by the straight line between its neighbours.",
                    line_number(s.line),
                    s.line,
                    s.spike.first + 1,
                    s.spike.last + 1,
                    fmt(s.spike.x_mm, Quantity::PositionMm),
                    fmt(s.spike.height_um, Quantity::HeightUm)
                ));
            }
            if replaced.len() > 20 {
                lines.push(format!(
                    "... and {} more (report.json lists all).",
                    replaced.len() - 20
                ));
            }
        }
        lines
    }
}

/// A fitted surface and the spikes replaced before fitting.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedModel {
    /// The surface with its data parameters.
    pub fit: FitResult,
    /// The spikes replaced (empty unless the recipe asks for it).
    pub replaced: Vec<LineSpike>,
}

/// Fits `grid` as `recipe` says, the surface placed in the grid's coordinates (its first
/// column at [`Grid::x0_mm`], its lines at their y), so that every position read from it is
/// one the input names.
pub fn fit_model(grid: &Grid, recipe: &ModelRecipe) -> Result<FittedModel, MethodError> {
    let (bridged, replaced) = match &recipe.replace_spikes {
        Some(rule) => {
            let (spikes, _) = find_grid_spikes(grid, recipe.lambda_c_mm, rule);
            (Some(bridged_grid(grid, &spikes).0), spikes)
        }
        None => (None, Vec::new()),
    };
    let z = &bridged.as_ref().unwrap_or(grid).heights_um;
    let mut fit = fit_grid_with(
        grid.pitch_x_mm,
        &grid.y_mm,
        z,
        grid.cols,
        recipe.degrees,
        recipe.method,
    )?;
    fit.place_at_x(grid.x0_mm);
    Ok(FittedModel { fit, replaced })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrology::test_fit;

    fn grid(rows: usize, cols: usize) -> Grid {
        let wavy = |r: usize, c: usize| (c as f64 * 0.21).sin() + 0.5 * (r as f64 * 0.7).cos();
        crate::metrology::test_grid(rows, cols, 0.002, wavy)
    }

    #[test]
    fn the_default_recipe_is_the_papers_fit() {
        let mut g = grid(8, 200);
        g.heights_um[3 * 200 + 50] += 100.0;
        let r = ModelRecipe::default();
        assert!(r.is_paper());
        let m = fit_model(&g, &r).unwrap();
        let paper = test_fit(&g);
        assert_eq!(m.fit.surface, paper.surface);
        assert_eq!(
            (&m.fit.params_u, &m.fit.params_v),
            (&paper.params_u, &paper.params_v)
        );
        assert!(m.replaced.is_empty());
        assert_eq!(r.start_lines(&[]).len(), 1);
    }

    #[test]
    fn replacing_spikes_is_asked_for_named_and_recorded() {
        let mut g = grid(8, 200);
        let clean = g.heights_um.clone();
        g.heights_um[3 * 200 + 50] += 100.0;
        let r = ModelRecipe {
            replace_spikes: Some(SpikeOptions::default()),
            ..ModelRecipe::default()
        };
        assert!(!r.is_paper());
        let m = fit_model(&g, &r).unwrap();
        assert_eq!(m.replaced.len(), 1);
        assert_eq!((m.replaced[0].line, m.replaced[0].spike.peak), (3, 50));
        // The replaced point lies on the line between its neighbours, not at the spike.
        let pt = m
            .fit
            .surface
            .evaluate(m.fit.params_u[50], m.fit.params_v[3]);
        let want = 0.5 * (clean[3 * 200 + 49] + clean[3 * 200 + 51]) / 1000.0;
        assert!((pt[2] - want).abs() < 1e-12, "{} vs {want}", pt[2]);
        let lines = r.start_lines(&m.replaced).join("\n");
        assert!(
            lines.contains("Spikes replaced before fitting")
                // 1-based for people: index 3 is line 4, point 50 the 51st.
                && lines.contains("Replaced: line 4 (file 0003) points 51..51"),
            "{lines}"
        );
        assert!(r.describe().contains("replaced by the straight line"));
    }
}
