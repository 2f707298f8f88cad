//! The paper's incremental NURBS surface interpolation (section 2): chord-length parameters averaged over rows and columns, averaged knots, banded collocation solves.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`], [`crate::units`], [`crate::profile`]; no I/O, no tokio.
