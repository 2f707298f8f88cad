//! Sections `model_vs_measured` and `between_lines`: model versus measured — the hold-out refits (every 2nd point, every 2nd line
//! left out) made the way the model was made (degrees and method across the lines), each
//! line's share of them, and the verdict on the surface between lines: every 2nd line left
//! out, the rest refitted, the refit judged against Sq of the measured grid
//! ([`crate::metrology::holdout::between_lines`]). These refits are the only fits the report
//! makes.
//!
//! Layer 4 (reporting): depends on [`crate::metrology::holdout`].

use super::SectionInput;
use crate::grid::Grid;
use crate::metrology::holdout::{
    between_lines_given, holdout_every_or_reason, lines_left_out, points_left_out, BetweenLines,
    Holdout, HoldoutLine,
};
use crate::metrology::surface_model::ModelRecipe;
use crate::report::document::{LineHoldout, LineReport};

/// What a panic in the shared lines-left-out refit becomes.
const LINES_REFIT_PANICKED: &str =
    "internal: the between-lines refit panicked; report this with the input";

/// Both sections, on the grid as characterised with the model's recipe, judged against `sq_um`
/// (the measured grid's Sq; `None`: it has none) at the options' threshold.
pub fn section(
    input: &SectionInput<'_>,
    sq_um: Option<f64>,
) -> (Result<Holdout, String>, Result<BetweenLines, String>) {
    characterise_and_judge(
        input.characterised,
        &input.model.recipe,
        sq_um,
        input.ctx.options.holdout_threshold,
    )
}

/// Both hold-out sections: `model_vs_measured` (the refits of
/// [`holdout_with`](crate::metrology::holdout::holdout_with), the line indices mapped to the
/// grid's) and the verdict between lines
/// ([`between_lines`](crate::metrology::holdout::between_lines) with k from
/// [`holdout_every_or_reason`]; `None` for `sq_um`: the grid has no Sq), on `grid` (the grid
/// as characterised: its heights, the lines' indices). The refit they share,
/// every k-th line left out, is made once, beside the every-2nd-point refit: the same
/// computations on the same inputs, so the same results and the same errors, in the order each
/// of those functions reports them.
fn characterise_and_judge(
    grid: &Grid,
    recipe: &ModelRecipe,
    sq_um: Option<f64>,
    threshold: f64,
) -> (Result<Holdout, String>, Result<BetweenLines, String>) {
    let (degrees, method) = (recipe.degrees, recipe.method);
    let every = holdout_every_or_reason(grid.rows(), degrees.degree_v).map_err(|e| e.to_string());
    let (points, lines) = std::thread::scope(|s| {
        let lines = every
            .clone()
            .ok()
            .map(|every| s.spawn(move || lines_left_out(grid, degrees, method, every)));
        let points = points_left_out(grid, degrees, method);
        // `Err(())`: the refit panicked.
        (points, lines.map(|h| h.join().map_err(|_| ())))
    });
    let model_vs_measured = (|| {
        let points_left_out = points.map_err(|e| e.to_string())?;
        every.clone()?;
        let lines_left_out = match &lines {
            Some(Ok(Ok(held))) => held.lines.clone(),
            Some(Ok(Err(e))) => return Err(e.to_string()),
            Some(Err(())) => return Err(LINES_REFIT_PANICKED.to_string()),
            // Not reached: no k was found above.
            None => Vec::new(),
        };
        let mut h = Holdout {
            points_left_out,
            lines_left_out,
        };
        rows_to_lines(
            grid,
            h.points_left_out.iter_mut().chain(&mut h.lines_left_out),
        );
        Ok(h)
    })();
    let verdict = match sq_um {
        None => Err("the measured grid has no Sq to judge the hold-out against".to_string()),
        Some(_) if matches!(lines, Some(Err(()))) => Err(LINES_REFIT_PANICKED.to_string()),
        Some(sq_um) => every.and_then(|every| {
            between_lines_given(grid, method, every, sq_um, threshold, || match lines {
                Some(Ok(held)) => held,
                // Not reached: `every` was found above as it was for the refit.
                _ => lines_left_out(grid, degrees, method, every),
            })
            .map_err(|e| e.to_string())
        }),
    };
    (model_vs_measured, verdict)
}

/// Maps held-out rows (the hold-out's, the verdict's) to the grid's line indices.
pub fn rows_to_lines<'a>(grid: &Grid, rows: impl IntoIterator<Item = &'a mut HoldoutLine>) {
    for l in rows {
        l.index = grid.index_of(l.index) as usize;
    }
}

/// Gives every line its share of the hold-out comparison.
pub fn attach(lines: &mut [LineReport], h: &Holdout) {
    let find =
        |v: &[HoldoutLine], index: u32| v.iter().find(|l| l.index == index as usize).cloned();
    for line in lines {
        line.model_vs_measured = Some(LineHoldout {
            points_left_out: find(&h.points_left_out, line.index),
            line_left_out: find(&h.lines_left_out, line.index),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::VMethod;
    use crate::metrology::holdout::{between_lines, holdout_with};

    /// `model_vs_measured` on its own: both refits of [`holdout_with`], the line indices
    /// mapped to the grid's.
    fn characterise(grid: &Grid, recipe: &ModelRecipe) -> Result<Holdout, String> {
        let mut h = holdout_with(grid, recipe.degrees, recipe.method).map_err(|e| e.to_string())?;
        rows_to_lines(
            grid,
            h.points_left_out.iter_mut().chain(&mut h.lines_left_out),
        );
        Ok(h)
    }

    /// The verdict between lines on its own: [`between_lines`] with k from
    /// [`holdout_every_or_reason`].
    fn verdict(
        grid: &Grid,
        recipe: &ModelRecipe,
        sq_um: f64,
        threshold: f64,
    ) -> Result<BetweenLines, String> {
        holdout_every_or_reason(grid.rows(), recipe.degrees.degree_v)
            .and_then(|every| {
                between_lines(grid, recipe.degrees, recipe.method, every, sq_um, threshold)
            })
            .map_err(|e| e.to_string())
    }

    /// Lines 0.01 mm apart, indexed 3, 5, 7, … (not their rows).
    fn grid(rows: usize, cols: usize, f: impl Fn(usize, usize) -> f64) -> Grid {
        Grid {
            index: (0..rows as u32).map(|r| 3 + 2 * r).collect(),
            ..crate::metrology::test_grid(rows, cols, 0.002, f)
        }
    }

    /// The shared refit gives both sections exactly what [`characterise`] and [`verdict`]
    /// give on their own (every figure to the bit, the line indices mapped), and the same
    /// error where one fails: a good grid with either method, too few lines to leave one out,
    /// a flat grid (no Sq to judge against), no Sq, a bad threshold, a grid whose heights do
    /// not fill it, and y that does not increase.
    #[test]
    fn one_lines_refit_gives_both_sections_their_own_results() {
        let rough = |r: usize, c: usize| {
            (c as f64 * 0.37).sin() + 0.4 * ((r * 7 + c * 3) % 11) as f64 + 0.05 * r as f64
        };
        let mut short = grid(12, 50, rough);
        short.heights_um.pop();
        let mut backwards = grid(12, 40, rough);
        backwards.y_mm.swap(4, 5);
        // The paper's surface: interpolation at degrees 5/5.
        let paper = ModelRecipe::default();
        let cases: Vec<(&str, Grid, ModelRecipe, Option<f64>, f64)> = vec![
            ("rough", grid(13, 50, rough), paper, Some(1.1), 0.5),
            (
                "least squares",
                grid(15, 40, rough),
                ModelRecipe {
                    method: VMethod::LeastSquares { control_rows: 9 },
                    ..paper
                },
                Some(1.1),
                0.5,
            ),
            ("six lines", grid(6, 40, rough), paper, Some(1.0), 0.5),
            ("flat", grid(12, 40, |_, _| 0.25), paper, Some(0.0), 0.5),
            ("no Sq", grid(12, 40, rough), paper, None, 0.5),
            ("bad threshold", grid(12, 40, rough), paper, Some(1.0), -1.0),
            ("short", short, paper, Some(1.0), 0.5),
            ("backwards", backwards, paper, Some(1.0), 0.5),
        ];
        let mut seen_ok = [0; 2];
        for (what, g, recipe, sq, threshold) in cases {
            let own = (
                characterise(&g, &recipe),
                match sq {
                    Some(sq) => verdict(&g, &recipe, sq, threshold),
                    None => Err("the measured grid has no Sq to judge the hold-out against".into()),
                },
            );
            let shared = characterise_and_judge(&g, &recipe, sq, threshold);
            // Debug prints every f64 in its shortest round-trip form (−0.0 included), so equal
            // texts are equal bits.
            assert_eq!(
                format!("{:?}", shared.0),
                format!("{:?}", own.0),
                "{what}: model vs measured"
            );
            assert_eq!(
                format!("{:?}", shared.1),
                format!("{:?}", own.1),
                "{what}: verdict"
            );
            seen_ok[0] += usize::from(own.0.is_ok());
            seen_ok[1] += usize::from(own.1.is_ok());
        }
        // The good grids are judged, so both sides were compared on figures, not only errors.
        assert!(seen_ok[0] >= 3 && seen_ok[1] >= 2, "{seen_ok:?}");
    }
}
