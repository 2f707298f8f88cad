//! What a fit returns: the surface, the data parameters it interpolates at, and the time per
//! stage.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`].

use crate::nurbs::NurbsSurface;

/// Seconds spent per stage of a fit.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FitTimings {
    /// Chord lengths and parameters (summed over `push_line` calls plus the final averaging).
    pub params_s: f64,
    /// Knot vectors, collocation matrices and their factorisations.
    pub knots_factor_s: f64,
    /// Solves along u (one per row).
    pub solve_u_s: f64,
    /// Solves along v (all columns at once) and assembly of the control net.
    pub solve_v_s: f64,
}

impl FitTimings {
    /// Sum of all stages.
    pub fn total_s(&self) -> f64 {
        self.params_s + self.knots_factor_s + self.solve_u_s + self.solve_v_s
    }
}

/// A fitted surface with its data parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct FitResult {
    /// The interpolating surface (mm).
    pub surface: NurbsSurface,
    /// Averaged parameters ū_k of the columns.
    pub params_u: Vec<f64>,
    /// Averaged parameters v̄_l of the rows.
    pub params_v: Vec<f64>,
    /// Time per stage.
    pub timings: FitTimings,
    /// x of the data's first column, mm: the surface is fitted from x = 0 and then placed
    /// there ([`FitResult::place_at_x`]); 0 until it is.
    pub x0_mm: f64,
}

impl FitResult {
    /// Places the surface where the data's first column is, `x0_mm` along x. The fit is made
    /// from x = 0: its chord-length parameters and knots depend on differences of x alone,
    /// and the poles' x solve interpolates x with basis functions that sum to 1, so a fit
    /// from `x0_mm` would give the same surface moved by `x0_mm` (to rounding).
    pub fn place_at_x(&mut self, x0_mm: f64) {
        // A zero offset leaves every bit as fitted (even a pole x of −0).
        if x0_mm != 0.0 {
            self.surface.shift_x(x0_mm);
            self.x0_mm = x0_mm;
        }
    }
}
