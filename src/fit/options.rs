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

impl FitOptions {
    /// The options of degree `degree_u` along u and `degree_v` along v.
    pub const fn degrees(degree_u: usize, degree_v: usize) -> FitOptions {
        FitOptions { degree_u, degree_v }
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions::degrees(5, 5)
    }
}
