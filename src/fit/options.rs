//! The fit's options: the degrees of the surface.
//!
//! Layer 1 (pure logic): depends on nothing else in the crate.

/// Degrees of the fitted surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FitOptions {
    /// Degree along u (x, columns). The paper uses 5.
    pub degree_u: usize,
    /// Degree along v (y, rows). The paper uses 5.
    pub degree_v: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            degree_u: 5,
            degree_v: 5,
        }
    }
}
