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
}
