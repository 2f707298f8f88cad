//! Contact mechanics of a measured surface: the surface pressed against a rigid flat (or two
//! elastic bodies through their composite modulus) as an elastic half-space, solved by
//! FFT-accelerated boundary elements on the grid — non-periodic (zero padding), with the
//! grid's own x and y pitches — by Polonsky and Keer's constrained conjugate gradient,
//! optionally perfectly plastic at a hardness. This is the paper's further work ("direct
//! application to micro-contact analysis found in friction and wear").
//!
//! # Layout
//!
//! - [`influence`]: the displacement under a uniformly loaded pixel (Love's solution).
//! - [`halfspace`]: the operator u = K p by zero-padded FFT convolution.
//! - [`solver`]: the constrained conjugate gradient at one load.
//! - [`patches`]: connected contact patches.
//! - [`modulus`]: the composite modulus of two bodies, with range checks.
//! - [`curve`]: the load–area curve and the map of one load, with the resolution verdict.
//! - [`settings`]: `[contact]` of a station or recipe, as a scan's plan freezes it.
//! - [`error`]: why an analysis is refused.
//!
//! Units: heights µm, pitches mm at the boundary (µm inside), pressures MPa, moduli and
//! hardness GPa at the boundary (MPa inside).
//!
//! Layer 1 (pure logic): numbers in, values out; depends only on the FFT crates and serde
//! (toml in the tests).
//! No I/O.

pub mod curve;
pub mod error;
pub mod halfspace;
pub mod influence;
pub mod modulus;
pub mod patches;
pub mod settings;
pub mod solver;

pub use curve::{
    check_options, contact_curve, ContactCurve, ContactGrid, ContactMap, ContactOptions,
    CurvePoint, DEFAULT_PRESSURES_MPA,
};
pub use error::{ContactError, MAX_HARDNESS_GPA, MIN_HARDNESS_GPA};
pub use modulus::{effective_modulus_gpa, Body};
pub use settings::ContactSettings;
pub use solver::{Solution, SolveOptions};
