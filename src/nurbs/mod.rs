//! The NURBS surface as a value: degrees, clamped knot vectors and the control net.
//!
//! This is the shared geometry type between the fitter (which produces it), the IGES writer
//! (which formats it) and the metrology (which evaluates it), so that none of them depends on
//! another. Weights are all 1 (the paper's choice), so the surface is polynomial.
//!
//! Directions are fixed throughout the project: u ↔ x ↔ columns of the height grid ↔ the
//! first (S) index of IGES entity 128; v ↔ y ↔ rows (traced lines) ↔ the second (T) index.
//! Coordinates are millimetres.
//!
//! Layer 0 (vocabulary): depends on nothing else in the crate; no I/O.

mod eval;
mod net;
pub use eval::{basis_funs, find_span, BSplineCurve, UBasis};
pub use net::{PoleNet, PoleRow, Poles, RowY};

use thiserror::Error;

/// Why a set of degrees, knots and poles is not a valid B-spline surface.
#[derive(Debug, Error, PartialEq)]
pub enum SurfaceError {
    /// A degree of zero is not supported (the fit needs at least degree 1).
    #[error("degree must be at least 1 (got u={degree_u}, v={degree_v})")]
    ZeroDegree {
        /// Degree along u.
        degree_u: usize,
        /// Degree along v.
        degree_v: usize,
    },
    /// Knot vector length must be poles + degree + 1.
    #[error("{direction} knot vector has {got} knots, expected {expected} (poles + degree + 1)")]
    KnotCount {
        /// "u" or "v".
        direction: &'static str,
        /// Knots given.
        got: usize,
        /// Knots required.
        expected: usize,
    },
    /// Fewer poles than degree + 1.
    #[error("{direction}: {poles} poles is fewer than degree + 1 = {needed}")]
    TooFewPoles {
        /// "u" or "v".
        direction: &'static str,
        /// Poles given.
        poles: usize,
        /// Minimum.
        needed: usize,
    },
    /// Knots must be finite and non-decreasing.
    #[error(
        "{direction} knot {index} = {value} is not finite or decreases from the previous knot"
    )]
    KnotOrder {
        /// "u" or "v".
        direction: &'static str,
        /// Index of the offending knot.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// Control net size must be count_u × count_v.
    #[error("control net has {got} poles, expected {count_u} × {count_v}")]
    NetSize {
        /// Poles given.
        got: usize,
        /// Poles along u.
        count_u: usize,
        /// Poles along v.
        count_v: usize,
    },
    /// A pole coordinate is NaN or infinite.
    #[error("pole ({i}, {j}) has a non-finite coordinate {value:?}")]
    NonFinitePole {
        /// u index.
        i: usize,
        /// v index.
        j: usize,
        /// The coordinates.
        value: [f64; 3],
    },
}

/// A non-rational (unit-weight) B-spline surface in millimetres.
///
/// Surfaces are equal when their degrees, knots and poles compare equal, whatever the layout
/// of their nets ([`PoleNet`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NurbsSurface {
    degree_u: usize,
    degree_v: usize,
    knots_u: Vec<f64>,
    knots_v: Vec<f64>,
    count_u: usize,
    count_v: usize,
    /// Poles, v-outer / u-inner: pole (i, j) is number `j * count_u + i` (the IGES order).
    net: PoleNet,
}

fn check_knots(
    direction: &'static str,
    knots: &[f64],
    poles: usize,
    degree: usize,
) -> Result<(), SurfaceError> {
    if poles < degree + 1 {
        return Err(SurfaceError::TooFewPoles {
            direction,
            poles,
            needed: degree + 1,
        });
    }
    let expected = poles + degree + 1;
    if knots.len() != expected {
        return Err(SurfaceError::KnotCount {
            direction,
            got: knots.len(),
            expected,
        });
    }
    for (index, w) in knots.windows(2).enumerate() {
        if !w[1].is_finite() || !w[0].is_finite() || w[1] < w[0] {
            return Err(SurfaceError::KnotOrder {
                direction,
                index: index + 1,
                value: w[1],
            });
        }
    }
    Ok(())
}

/// The checks of a surface's shape that need no poles: degrees and knots.
fn check_shape(
    degree_u: usize,
    degree_v: usize,
    knots_u: &[f64],
    knots_v: &[f64],
    count_u: usize,
    count_v: usize,
) -> Result<(), SurfaceError> {
    if degree_u == 0 || degree_v == 0 {
        return Err(SurfaceError::ZeroDegree { degree_u, degree_v });
    }
    check_knots("u", knots_u, count_u, degree_u)?;
    check_knots("v", knots_v, count_v, degree_v)
}

impl NurbsSurface {
    /// Builds a surface after checking every invariant (degrees, knot counts and order,
    /// net size, finite poles). `poles` is v-outer / u-inner (`j * count_u + i`); the net is
    /// kept compactly where its coordinates repeat ([`PoleNet::from_poles`]).
    pub fn try_new(
        degree_u: usize,
        degree_v: usize,
        knots_u: Vec<f64>,
        knots_v: Vec<f64>,
        count_u: usize,
        count_v: usize,
        poles: Vec<[f64; 3]>,
    ) -> Result<NurbsSurface, SurfaceError> {
        check_shape(degree_u, degree_v, &knots_u, &knots_v, count_u, count_v)?;
        if poles.len() != count_u * count_v {
            return Err(SurfaceError::NetSize {
                got: poles.len(),
                count_u,
                count_v,
            });
        }
        let net = PoleNet::from_poles(count_u, &poles);
        drop(poles);
        Self::try_from_net(degree_u, degree_v, knots_u, knots_v, count_u, count_v, net)
    }

    /// [`NurbsSurface::try_new`] from a net already built (e.g. [`PoleNet::separable`], as
    /// the fit makes it: x per column, y per row, z per pole).
    pub fn try_from_net(
        degree_u: usize,
        degree_v: usize,
        knots_u: Vec<f64>,
        knots_v: Vec<f64>,
        count_u: usize,
        count_v: usize,
        net: PoleNet,
    ) -> Result<NurbsSurface, SurfaceError> {
        check_shape(degree_u, degree_v, &knots_u, &knots_v, count_u, count_v)?;
        if net.len() != count_u * count_v || net.count_u() != count_u || net.count_v() != count_v {
            return Err(SurfaceError::NetSize {
                got: net.len(),
                count_u,
                count_v,
            });
        }
        let finite = |v: &[f64]| v.iter().fold(true, |ok, c| ok & c.is_finite());
        for (j, row) in net.rows().enumerate() {
            let y_finite = match row.y {
                RowY::One(y) => y.is_finite(),
                RowY::Each(ys) => finite(ys),
            };
            if y_finite && finite(row.x) && finite(row.z) {
                continue;
            }
            if let Some(i) = (0..row.len()).find(|&i| !row.get(i).iter().all(|c| c.is_finite())) {
                return Err(SurfaceError::NonFinitePole {
                    i,
                    j,
                    value: row.get(i),
                });
            }
        }
        Ok(NurbsSurface {
            degree_u,
            degree_v,
            knots_u,
            knots_v,
            count_u,
            count_v,
            net,
        })
    }

    /// Degree along u (x).
    pub fn degree_u(&self) -> usize {
        self.degree_u
    }
    /// Degree along v (y).
    pub fn degree_v(&self) -> usize {
        self.degree_v
    }
    /// Clamped knot vector along u, `count_u + degree_u + 1` values.
    pub fn knots_u(&self) -> &[f64] {
        &self.knots_u
    }
    /// Clamped knot vector along v, `count_v + degree_v + 1` values.
    pub fn knots_v(&self) -> &[f64] {
        &self.knots_v
    }
    /// Number of poles along u.
    pub fn count_u(&self) -> usize {
        self.count_u
    }
    /// Number of poles along v.
    pub fn count_v(&self) -> usize {
        self.count_v
    }
    /// All poles, v-outer / u-inner.
    pub fn poles(&self) -> Poles<'_> {
        self.net.iter()
    }
    /// The control net.
    pub fn net(&self) -> &PoleNet {
        &self.net
    }
    /// Pole row `j` (fixed v index).
    pub fn row(&self, j: usize) -> PoleRow<'_> {
        self.net.row(j)
    }
    /// Pole (i along u, j along v).
    pub fn pole(&self, i: usize, j: usize) -> [f64; 3] {
        self.net.pole(i, j)
    }
    /// The surface moved by `dx_mm` along x: every pole's x plus `dx_mm`, the knots as they
    /// are (the basis functions sum to 1, so every point S(u, v) moves by `dx_mm`).
    pub fn shift_x(&mut self, dx_mm: f64) {
        self.net.shift_x(dx_mm);
    }
}
