//! STEP (ISO 10303-21, AP214 `AUTOMOTIVE_DESIGN`) output of an FE-ready solid: the fitted
//! surface as the top face of a closed block of a given depth under the specimen's area, as
//! one `MANIFOLD_SOLID_BREP` that ABAQUS, ANSYS, LS-DYNA, gmsh and every CAD system import.
//!
//! * [`part21`]: the exchange-file text (header, numbered entities, reals, lists).
//! * [`solid`]: the block's B-rep — six faces (the B-spline top, four planar sides bounded
//!   by the top's boundary curves, a planar bottom), twelve edges, eight vertices — and
//!   [`write_solid_step`].
//!
//! **Why by hand.** The truck project's `truck-stepio` writes STEP from `truck-modeling`
//! shapes, B-spline surfaces included. Using it would mean depending on truck's geometry,
//! topology, modeling, polymesh and assembly crates (and, for its reader half, `ruststep`)
//! — several tens of thousands of lines and a second NURBS type to convert the fit into —
//! to emit a solid whose topology here is fixed and tiny, while the large part of the file
//! (the surface's control net, 250 000 poles for a 31 × 8000 scan) is exactly the entity this
//! crate already formats for IGES. As with the IGES writer, the entities are few, their
//! layout is specified by ISO 10303-42/-514, and the output is checked by an independent
//! reader: OpenCascade loads it, finds it a valid closed solid and measures its volume, and
//! gmsh meshes it (`tests/it/step_occt.rs`).
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`] and the reals of [`crate::iges::format`];
//! writes to any `io::Write`, never opens files.

pub mod part21;
pub mod solid;

pub use solid::{lowest_point_mm, write_solid_step, SolidStats, StepOptions};

use thiserror::Error;

/// Why a solid cannot be written.
#[derive(Debug, Error)]
pub enum StepError {
    /// Writing failed.
    #[error("writing STEP failed: {0}")]
    Io(#[from] std::io::Error),
    /// The depth is not a positive finite number.
    #[error("solid depth {depth_mm} mm is not a positive finite number; give the block's depth below the surface's lowest point in mm (e.g. 0.1)")]
    Depth {
        /// The offending depth.
        depth_mm: f64,
    },
    /// A control point is not finite.
    #[error("pole ({i}, {j}) of the surface is not finite; refusing to write it")]
    NonFinite {
        /// u index.
        i: usize,
        /// v index.
        j: usize,
    },
    /// A boundary of the surface does not lie in one plane x = const or y = const: the
    /// block's sides could not be planar.
    #[error("the surface's {edge} boundary is not straight in plan view (its poles' {axis} varies by {spread_mm:e} mm); only a surface fitted on a rectangular grid makes a block")]
    Boundary {
        /// Which boundary ("first line", "last line", "x start", "x end").
        edge: &'static str,
        /// The coordinate that should be constant.
        axis: &'static str,
        /// How much it varies.
        spread_mm: f64,
    },
    /// The surface covers no area (its x or y extent is zero).
    #[error("the surface spans {x_mm} mm × {y_mm} mm: no area to put a block under")]
    Degenerate {
        /// Extent along x.
        x_mm: f64,
        /// Extent along y.
        y_mm: f64,
    },
    /// The bottom would cut the surface's control net: the top face might touch it.
    #[error("a bottom {depth_mm} mm below the surface's lowest point (z = {bottom_mm} mm) is above its lowest control point (z = {pole_mm} mm), so the top face could reach the bottom; give a larger depth")]
    TooShallow {
        /// The requested depth.
        depth_mm: f64,
        /// z of the bottom.
        bottom_mm: f64,
        /// z of the lowest pole.
        pole_mm: f64,
    },
}
