//! The block solid: the fitted surface as the top face of a closed B-rep whose four sides
//! are planes through the surface's boundary curves and whose bottom is the plane a given
//! depth below the surface's lowest point.
//!
//! Topology (u ↔ x, v ↔ y as everywhere in the crate): top corners T00 = S(0,0), T10 = S(1,0),
//! T11 = S(1,1), T01 = S(0,1) and the bottom corners B.. below them; edges are the four
//! boundary curves of the top (the rows and columns of boundary poles with the surface's own
//! knots, exact because the knots are clamped), four vertical lines and four bottom lines;
//! each face's loop runs counter-clockwise seen from outside, so every edge is used once in
//! each direction. A surface whose x or y decreases with its parameter is written with every
//! loop reversed and the top face's sense flipped, so the outward normal is always up.
//!
//! Layer 1 (pure logic): depends on [`super::part21`] and [`crate::nurbs`].

use super::part21::{
    integers, push_usize, real, reals, reference, references, string, Part21, Ref,
};
use super::StepError;
use crate::nurbs::NurbsSurface;
use std::io::Write;

/// What to write besides the geometry.
#[derive(Debug, Clone, PartialEq)]
pub struct StepOptions {
    /// Depth of the block from the surface's lowest point to the flat bottom, mm.
    pub depth_mm: f64,
    /// The file's name as recorded in its header.
    pub file_name: String,
    /// The header's time stamp (ISO 8601).
    pub timestamp: String,
    /// The product's name (what a CAD tree shows).
    pub product_name: String,
    /// The header's description.
    pub description: String,
    /// The lowest measured height, mm, when the surface interpolates data: the surface passes
    /// through it, so its lowest point is no higher (the sampling of [`lowest_point_mm`] need
    /// not meet the data's parameters).
    pub lowest_data_z_mm: Option<f64>,
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct SolidStats {
    /// Bytes written.
    pub bytes: u64,
    /// Entity instances written.
    pub entities: usize,
    /// The surface's lowest point found ([`lowest_point_mm`], or the lowest measured height
    /// when lower), mm.
    pub lowest_z_mm: f64,
    /// z of the flat bottom, mm.
    pub bottom_z_mm: f64,
    /// The block's extent: x range and y range, mm.
    pub x_mm: [f64; 2],
    /// y range, mm.
    pub y_mm: [f64; 2],
}

/// Parameters at which the lowest point is looked for: every knot span cut into this many
/// equal parts along each direction.
pub const SAMPLES_PER_SPAN: usize = 4;

/// The surface's lowest z, mm: the least of its values at [`SAMPLES_PER_SPAN`] + 1 evenly
/// spaced parameters in every knot span along u and along v. A degree-5 piece varies smoothly
/// within its span; the true minimum can lie below this by a small fraction of the span's
/// height range (the bottom is checked against the control net, which bounds the surface,
/// before anything is written).
pub fn lowest_point_mm(surface: &NurbsSurface) -> f64 {
    let params = |knots: &[f64]| {
        let mut out = Vec::new();
        for w in knots.windows(2) {
            if w[1] > w[0] {
                for k in 0..SAMPLES_PER_SPAN {
                    out.push(w[0] + (w[1] - w[0]) * k as f64 / SAMPLES_PER_SPAN as f64);
                }
            }
        }
        out.push(*knots.last().expect("clamped knots"));
        out
    };
    let us = params(surface.knots_u());
    let vs = params(surface.knots_v());
    // Row by row, so a large surface never holds all the samples at once.
    let mut lowest = f64::INFINITY;
    for v in vs {
        for p in surface.evaluate_grid(&us, &[v]) {
            lowest = lowest.min(p[2]);
        }
    }
    lowest
}

/// Distinct knots and their multiplicities.
fn knots_and_multiplicities(knots: &[f64]) -> (Vec<f64>, Vec<usize>) {
    let (mut values, mut mults) = (Vec::new(), Vec::new());
    for &k in knots {
        if values.last() == Some(&k) {
            *mults.last_mut().expect("a value has a count") += 1;
        } else {
            values.push(k);
            mults.push(1);
        }
    }
    (values, mults)
}

/// Spread of one coordinate over a run of poles.
fn spread(poles: impl Iterator<Item = [f64; 3]>, axis: usize) -> (f64, f64) {
    poles.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
        (lo.min(p[axis]), hi.max(p[axis]))
    })
}

/// Writes the block under `surface` as a STEP AP214 file to `w` (see the module doc).
pub fn write_solid_step<W: Write>(
    w: W,
    surface: &NurbsSurface,
    opts: &StepOptions,
) -> Result<SolidStats, StepError> {
    let depth = opts.depth_mm;
    if !(depth.is_finite() && depth > 0.0) {
        return Err(StepError::Depth { depth_mm: depth });
    }
    let (nu, nv) = (surface.count_u(), surface.count_v());
    let mut pole_lo = f64::INFINITY;
    for j in 0..nv {
        for i in 0..nu {
            let p = surface.pole(i, j);
            if !p.iter().all(|c| c.is_finite()) {
                return Err(StepError::NonFinite { i, j });
            }
            pole_lo = pole_lo.min(p[2]);
        }
    }
    let t00 = surface.pole(0, 0);
    let t10 = surface.pole(nu - 1, 0);
    let t01 = surface.pole(0, nv - 1);
    let (x0, x1, y0, y1) = (t00[0], t10[0], t00[1], t01[1]);
    let extent = (x1 - x0).abs().max((y1 - y0).abs());
    if x1 == x0 || y1 == y0 {
        return Err(StepError::Degenerate {
            x_mm: x1 - x0,
            y_mm: y1 - y0,
        });
    }
    // The boundaries must lie in the planes of the sides (exactly, for a fitted net).
    let tol = 1e-12 * extent.max(1.0);
    let checks: [(&'static str, &'static str, Vec<[f64; 3]>, usize); 4] = [
        (
            "first line",
            "y",
            (0..nu).map(|i| surface.pole(i, 0)).collect(),
            1,
        ),
        (
            "last line",
            "y",
            (0..nu).map(|i| surface.pole(i, nv - 1)).collect(),
            1,
        ),
        (
            "x start",
            "x",
            (0..nv).map(|j| surface.pole(0, j)).collect(),
            0,
        ),
        (
            "x end",
            "x",
            (0..nv).map(|j| surface.pole(nu - 1, j)).collect(),
            0,
        ),
    ];
    for (edge, axis, poles, k) in &checks {
        let (lo, hi) = spread(poles.iter().copied(), *k);
        if hi - lo > tol {
            return Err(StepError::Boundary {
                edge,
                axis,
                spread_mm: hi - lo,
            });
        }
    }
    let lowest = lowest_point_mm(surface).min(opts.lowest_data_z_mm.unwrap_or(f64::INFINITY));
    let bottom = lowest - depth;
    if bottom >= pole_lo {
        return Err(StepError::TooShallow {
            depth_mm: depth,
            bottom_mm: bottom,
            pole_mm: pole_lo,
        });
    }
    // Reversed when x or (exclusively) y decreases with the parameter: see the module doc.
    let mirrored = (x1 - x0) * (y1 - y0) < 0.0;

    let mut f = Part21::start(
        w,
        &opts.description,
        &opts.file_name,
        &opts.timestamp,
        &format!("surfscan {}", env!("CARGO_PKG_VERSION")),
        "AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }",
    )?;
    // Product structure and units (millimetre, radian, steradian; uncertainty 1e-7 mm).
    let app = f.entity(|b| b.extend_from_slice(b"APPLICATION_CONTEXT('automotive design')"))?;
    f.linking(
        b"APPLICATION_PROTOCOL_DEFINITION('international standard','automotive_design',2000,",
        &[app],
        b")",
    )?;
    let pctx = f.linking(b"PRODUCT_CONTEXT('',", &[app], b",'mechanical')")?;
    let name = string(&opts.product_name);
    let head = format!("PRODUCT({name},{name},'',(");
    let product = f.linking(head.as_bytes(), &[pctx], b"))")?;
    f.linking(
        b"PRODUCT_RELATED_PRODUCT_CATEGORY('part',$,(",
        &[product],
        b"))",
    )?;
    let formation = f.linking(b"PRODUCT_DEFINITION_FORMATION('','',", &[product], b")")?;
    let dctx = f.linking(
        b"PRODUCT_DEFINITION_CONTEXT('part definition',",
        &[app],
        b",'design')",
    )?;
    let definition = f.linking(b"PRODUCT_DEFINITION('design','',", &[formation, dctx], b")")?;
    let shape = f.linking(b"PRODUCT_DEFINITION_SHAPE('','',", &[definition], b")")?;
    let mm =
        f.entity(|b| b.extend_from_slice(b"(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT(.MILLI.,.METRE.))"))?;
    let rad =
        f.entity(|b| b.extend_from_slice(b"(NAMED_UNIT(*)PLANE_ANGLE_UNIT()SI_UNIT($,.RADIAN.))"))?;
    let sr = f.entity(|b| {
        b.extend_from_slice(b"(NAMED_UNIT(*)SI_UNIT($,.STERADIAN.)SOLID_ANGLE_UNIT())")
    })?;
    let unc = f.linking(
        b"UNCERTAINTY_MEASURE_WITH_UNIT(LENGTH_MEASURE(1.E-7),",
        &[mm],
        b",'distance_accuracy_value','confusion accuracy')",
    )?;
    let gctx = f.entity(|b| {
        b.extend_from_slice(
            b"(GEOMETRIC_REPRESENTATION_CONTEXT(3)GLOBAL_UNCERTAINTY_ASSIGNED_CONTEXT((",
        );
        reference(b, unc);
        b.extend_from_slice(b"))GLOBAL_UNIT_ASSIGNED_CONTEXT(");
        references(b, &[mm, rad, sr]);
        b.extend_from_slice(b")REPRESENTATION_CONTEXT('',''))");
    })?;

    // Geometry: the top surface.
    let mut pole_refs = vec![Ref(0); nu * nv];
    for i in 0..nu {
        for j in 0..nv {
            pole_refs[i * nv + j] = f.point(surface.pole(i, j))?;
        }
    }
    let (ku, mu) = knots_and_multiplicities(surface.knots_u());
    let (kv, mv) = knots_and_multiplicities(surface.knots_v());
    let (du, dv) = (surface.degree_u(), surface.degree_v());
    let top_surface = f.entity(|b| {
        b.extend_from_slice(b"B_SPLINE_SURFACE_WITH_KNOTS('',");
        push_usize(b, du);
        b.push(b',');
        push_usize(b, dv);
        b.extend_from_slice(b",(");
        for i in 0..nu {
            if i > 0 {
                b.push(b',');
            }
            references(b, &pole_refs[i * nv..(i + 1) * nv]);
        }
        b.extend_from_slice(b"),.UNSPECIFIED.,.F.,.F.,.F.,");
        integers(b, &mu);
        b.push(b',');
        integers(b, &mv);
        b.push(b',');
        reals(b, &ku);
        b.push(b',');
        reals(b, &kv);
        b.extend_from_slice(b",.UNSPECIFIED.)");
    })?;
    // Its boundary curves, sharing the surface's poles.
    let c_v0 = bspline_curve(
        &mut f,
        (0..nu).map(|i| pole_refs[i * nv]).collect(),
        du,
        &ku,
        &mu,
    )?;
    let c_v1 = bspline_curve(
        &mut f,
        (0..nu).map(|i| pole_refs[i * nv + nv - 1]).collect(),
        du,
        &ku,
        &mu,
    )?;
    let c_u0 = bspline_curve(&mut f, pole_refs[..nv].to_vec(), dv, &kv, &mv)?;
    let c_u1 = bspline_curve(&mut f, pole_refs[(nu - 1) * nv..].to_vec(), dv, &kv, &mv)?;

    // Vertices.
    let top = [t00, t10, surface.pole(nu - 1, nv - 1), t01];
    let mut tv = [Ref(0); 4];
    let mut bv = [Ref(0); 4];
    let mut bp = [Ref(0); 4];
    for k in 0..4 {
        let corner = match k {
            0 => 0,
            1 => (nu - 1) * nv,
            2 => nu * nv - 1,
            _ => nv - 1,
        };
        tv[k] = f.linking(b"VERTEX_POINT('',", &[pole_refs[corner]], b")")?;
        bp[k] = f.point([top[k][0], top[k][1], bottom])?;
        bv[k] = f.linking(b"VERTEX_POINT('',", &[bp[k]], b")")?;
    }
    // Straight edges: a LINE through the start point along the edge.
    let bottom_pts: Vec<[f64; 3]> = top.iter().map(|p| [p[0], p[1], bottom]).collect();
    // Vertical edges B_k → T_k.
    let mut vert = [Ref(0); 4];
    for k in 0..4 {
        vert[k] = line_edge(&mut f, bv[k], tv[k], bottom_pts[k], top[k])?;
    }
    // Bottom edges: 0→1 (y0), 1→2 (x1), 3→2 (y1), 0→3 (x0).
    let b01 = line_edge(&mut f, bv[0], bv[1], bottom_pts[0], bottom_pts[1])?;
    let b12 = line_edge(&mut f, bv[1], bv[2], bottom_pts[1], bottom_pts[2])?;
    let b32 = line_edge(&mut f, bv[3], bv[2], bottom_pts[3], bottom_pts[2])?;
    let b03 = line_edge(&mut f, bv[0], bv[3], bottom_pts[0], bottom_pts[3])?;
    // Top edges along the boundary curves: T00→T10 (v=0), T10→T11 (u=1), T01→T11 (v=1),
    // T00→T01 (u=0).
    let e_v0 = edge(&mut f, tv[0], tv[1], c_v0)?;
    let e_u1 = edge(&mut f, tv[1], tv[2], c_u1)?;
    let e_v1 = edge(&mut f, tv[3], tv[2], c_v1)?;
    let e_u0 = edge(&mut f, tv[0], tv[3], c_u0)?;

    // Faces: loops as (edge, traversed along it) counter-clockwise seen from outside for a
    // surface whose x and y grow with u and v.
    let mut faces = Vec::with_capacity(6);
    let top_loop = [(e_v0, true), (e_u1, true), (e_v1, false), (e_u0, false)];
    faces.push(face(&mut f, &top_loop, mirrored, top_surface, !mirrored)?);
    let sx = (x1 - x0).signum();
    let sy = (y1 - y0).signum();
    // Bottom (outward −z): B0→B3→B2→B1.
    let side = plane(&mut f, bottom_pts[0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0])?;
    let bottom_loop = [(b03, true), (b32, true), (b12, false), (b01, false)];
    faces.push(face(&mut f, &bottom_loop, mirrored, side, true)?);
    // Side y = y0 (outward −y·sy): B0→B1→T1→T0.
    let side = plane(&mut f, bottom_pts[0], [0.0, -sy, 0.0], [1.0, 0.0, 0.0])?;
    let l = [
        (b01, true),
        (vert[1], true),
        (e_v0, false),
        (vert[0], false),
    ];
    faces.push(face(&mut f, &l, mirrored, side, true)?);
    // Side x = x1 (outward +x·sx): B1→B2→T2→T1.
    let side = plane(&mut f, bottom_pts[1], [sx, 0.0, 0.0], [0.0, 1.0, 0.0])?;
    let l = [
        (b12, true),
        (vert[2], true),
        (e_u1, false),
        (vert[1], false),
    ];
    faces.push(face(&mut f, &l, mirrored, side, true)?);
    // Side y = y1 (outward +y·sy): B2→B3→T3→T2.
    let side = plane(&mut f, bottom_pts[3], [0.0, sy, 0.0], [1.0, 0.0, 0.0])?;
    let l = [
        (b32, false),
        (vert[3], true),
        (e_v1, true),
        (vert[2], false),
    ];
    faces.push(face(&mut f, &l, mirrored, side, true)?);
    // Side x = x0 (outward −x·sx): B3→B0→T0→T3.
    let side = plane(&mut f, bottom_pts[0], [-sx, 0.0, 0.0], [0.0, 1.0, 0.0])?;
    let l = [
        (b03, false),
        (vert[0], true),
        (e_u0, true),
        (vert[3], false),
    ];
    faces.push(face(&mut f, &l, mirrored, side, true)?);

    let shell = f.linking(b"CLOSED_SHELL('',(", &faces, b"))")?;
    let brep = f.linking(
        format!("MANIFOLD_SOLID_BREP({name},").as_bytes(),
        &[shell],
        b")",
    )?;
    let origin = placement(&mut f, [0.0; 3], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])?;
    let rep = f.entity(|b| {
        b.extend_from_slice(b"ADVANCED_BREP_SHAPE_REPRESENTATION('',");
        references(b, &[brep, origin]);
        b.push(b',');
        reference(b, gctx);
        b.push(b')');
    })?;
    f.linking(b"SHAPE_DEFINITION_REPRESENTATION(", &[shape, rep], b")")?;
    let (_, bytes, entities) = f.finish()?;
    Ok(SolidStats {
        bytes,
        entities,
        lowest_z_mm: lowest,
        bottom_z_mm: bottom,
        x_mm: [x0.min(x1), x0.max(x1)],
        y_mm: [y0.min(y1), y0.max(y1)],
    })
}

/// A `B_SPLINE_CURVE_WITH_KNOTS` through the poles `poles`.
fn bspline_curve<W: Write>(
    f: &mut Part21<W>,
    poles: Vec<Ref>,
    degree: usize,
    knots: &[f64],
    mults: &[usize],
) -> std::io::Result<Ref> {
    f.entity(|b| {
        b.extend_from_slice(b"B_SPLINE_CURVE_WITH_KNOTS('',");
        push_usize(b, degree);
        b.push(b',');
        references(b, &poles);
        b.extend_from_slice(b",.UNSPECIFIED.,.F.,.F.,");
        integers(b, mults);
        b.push(b',');
        reals(b, knots);
        b.extend_from_slice(b",.UNSPECIFIED.)");
    })
}

/// An `AXIS2_PLACEMENT_3D` at `origin` with axis `normal` and reference direction `refdir`.
fn placement<W: Write>(
    f: &mut Part21<W>,
    origin: [f64; 3],
    normal: [f64; 3],
    refdir: [f64; 3],
) -> std::io::Result<Ref> {
    let o = f.point(origin)?;
    let n = f.direction(normal)?;
    let r = f.direction(refdir)?;
    f.linking(b"AXIS2_PLACEMENT_3D('',", &[o, n, r], b")")
}

/// A `PLANE` through `origin` with normal `normal`.
fn plane<W: Write>(
    f: &mut Part21<W>,
    origin: [f64; 3],
    normal: [f64; 3],
    refdir: [f64; 3],
) -> std::io::Result<Ref> {
    let a = placement(f, origin, normal, refdir)?;
    f.linking(b"PLANE('',", &[a], b")")
}

/// An edge from `start` (at `a`) to `end` (at `z`) along a `LINE` through `a`.
fn line_edge<W: Write>(
    f: &mut Part21<W>,
    start: Ref,
    end: Ref,
    a: [f64; 3],
    z: [f64; 3],
) -> std::io::Result<Ref> {
    let d = [z[0] - a[0], z[1] - a[1], z[2] - a[2]];
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let origin = f.point(a)?;
    let dir = f.direction([d[0] / len, d[1] / len, d[2] / len])?;
    let vec = f.entity(|b| {
        b.extend_from_slice(b"VECTOR('',");
        reference(b, dir);
        b.push(b',');
        real(b, 1.0);
        b.push(b')');
    })?;
    let line = f.linking(b"LINE('',", &[origin, vec], b")")?;
    edge(f, start, end, line)
}

/// An `EDGE_CURVE` from `start` to `end` along `curve` (in the curve's own direction).
fn edge<W: Write>(f: &mut Part21<W>, start: Ref, end: Ref, curve: Ref) -> std::io::Result<Ref> {
    f.linking(b"EDGE_CURVE('',", &[start, end, curve], b",.T.)")
}

/// An `ADVANCED_FACE` on `surface` bounded by the loop `edges` (reversed, each edge's
/// direction flipped, when `mirrored`); `same_sense` says whether the face's outward normal
/// is the surface's own.
fn face<W: Write>(
    f: &mut Part21<W>,
    edges: &[(Ref, bool)],
    mirrored: bool,
    surface: Ref,
    same_sense: bool,
) -> std::io::Result<Ref> {
    let mut oriented = Vec::with_capacity(edges.len());
    let order: Vec<(Ref, bool)> = if mirrored {
        edges.iter().rev().map(|&(e, fwd)| (e, !fwd)).collect()
    } else {
        edges.to_vec()
    };
    for (e, forward) in order {
        let sense: &[u8] = if forward { b",.T.)" } else { b",.F.)" };
        oriented.push(f.linking(b"ORIENTED_EDGE('',*,*,", &[e], sense)?);
    }
    let lp = f.linking(b"EDGE_LOOP('',(", &oriented, b"))")?;
    let bound = f.linking(b"FACE_OUTER_BOUND('',", &[lp], b",.T.)")?;
    f.entity(|b| {
        b.extend_from_slice(b"ADVANCED_FACE('',(");
        reference(b, bound);
        b.extend_from_slice(b"),");
        reference(b, surface);
        b.extend_from_slice(if same_sense { b",.T.)" } else { b",.F.)" });
    })
}
