//! The load–area curve of a height grid: the contact solved at each requested nominal
//! pressure (ascending, each solve starting from the previous load's pressures), reduced to
//! the numbers a tribologist reads — real contact area fraction, mean gap, mean contact
//! pressure, number of patches — plus the pressure field at one chosen load for the maps.
//!
//! Definitions (the `contact.json` contract): the nominal pressure is the load divided by the
//! grid's projected area, one pixel per point (columns × x pitch by rows × y pitch); the area
//! fraction is the fraction of points carrying pressure; the mean gap is averaged over all
//! points, a point in contact (or flowing at the hardness) counting as zero; the mean contact
//! pressure is the load over the contact area.
//!
//! Resolution is judged per load from the patches: a load at which more than half of the
//! contact points are isolated single points is **not resolved** (the grid samples the
//! asperities too coarsely for their contact to be computed); when no requested load is
//! resolved the analysis is refused ([`ContactError::Unresolved`]). How much of the contact
//! lies in patches one line wide is reported beside it: across lines a scan resolves contact
//! only at its line spacing.
//!
//! Layer 1 (pure logic): depends on the sibling modules; no I/O.

use super::halfspace::HalfSpace;
use super::modulus::{effective_modulus_gpa, Body};
use super::patches::patches;
use super::solver::{solve, SolveOptions};
use super::{ContactError, MAX_HARDNESS_GPA, MIN_HARDNESS_GPA};
use serde::Serialize;

/// Fewest points along either axis of a grid whose contact is computed.
pub const MIN_POINTS_PER_AXIS: usize = 4;

/// Above this fraction of contact points in single-point patches a load is not resolved.
pub const UNRESOLVED_SINGLE_POINT_FRACTION: f64 = 0.5;

/// The default nominal pressures, MPa: a decade and a half below and above the pressures
/// of bolted and press-fit joints.
pub const DEFAULT_PRESSURES_MPA: [f64; 7] = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0];

/// A height grid as the contact solver sees it.
#[derive(Debug, Clone, Copy)]
pub struct ContactGrid<'a> {
    /// Heights, µm, row-major (one row per traced line).
    pub heights_um: &'a [f64],
    /// Rows (lines along y).
    pub rows: usize,
    /// Columns (points along x).
    pub cols: usize,
    /// Pitch along x, mm.
    pub pitch_x_mm: f64,
    /// Pitch between rows, mm.
    pub pitch_y_mm: f64,
}

/// What to compute.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactOptions {
    /// The measured body (default steel, [`Body::STEEL`]).
    pub specimen: Body,
    /// The counter-body: `None` (default) is a rigid flat.
    pub counter: Option<Body>,
    /// Hardness of a perfectly plastic specimen, GPa; `None` (default) is purely elastic.
    pub hardness_gpa: Option<f64>,
    /// Nominal pressures, MPa (default [`DEFAULT_PRESSURES_MPA`]); solved in ascending order,
    /// duplicates once.
    pub pressures_mpa: Vec<f64>,
    /// The load whose pressure field is kept for the maps (default: the middle of the sorted
    /// list); added to the curve when it is not among the pressures.
    pub map_pressure_mpa: Option<f64>,
    /// Solver limits and tolerances.
    pub solve: SolveOptions,
}

impl Default for ContactOptions {
    fn default() -> Self {
        ContactOptions {
            specimen: Body::STEEL,
            counter: None,
            hardness_gpa: None,
            pressures_mpa: DEFAULT_PRESSURES_MPA.to_vec(),
            map_pressure_mpa: None,
            solve: SolveOptions::default(),
        }
    }
}

/// One point of the load–area curve.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurvePoint {
    /// Load over the projected area, MPa.
    pub nominal_pressure_mpa: f64,
    /// Fraction of points in contact.
    pub area_fraction: f64,
    /// Mean gap over all points (0 in contact), µm.
    pub mean_gap_um: f64,
    /// Load over the real contact area, MPa.
    pub mean_contact_pressure_mpa: f64,
    /// Connected contact patches (4-connectivity).
    pub patches: usize,
    /// Fraction of points flowing at the hardness (0 when elastic).
    pub plastic_fraction: f64,
    /// Approach of the flat beyond first touch of the highest point, µm.
    pub approach_um: f64,
    /// Fraction of contact points that are isolated single points.
    pub single_point_patch_fraction: f64,
    /// Fraction of contact points in patches one line wide.
    pub single_line_patch_fraction: f64,
    /// Whether the grid resolves the contact at this load (single-point fraction ≤ 0.5).
    pub resolved: bool,
    /// Solver iterations.
    pub iterations: usize,
}

/// The pressure field at the map load.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactMap {
    /// The load it belongs to, MPa.
    pub nominal_pressure_mpa: f64,
    /// Pixel pressures, MPa, row-major (0 outside the contact).
    pub pressure_mpa: Vec<f64>,
}

/// The result of [`contact_curve`].
#[derive(Debug, Clone, PartialEq)]
pub struct ContactCurve {
    /// E* used, GPa.
    pub effective_modulus_gpa: f64,
    /// Hardness used, GPa (None: elastic).
    pub hardness_gpa: Option<f64>,
    /// The curve, ascending in pressure.
    pub points: Vec<CurvePoint>,
    /// The field at the map load.
    pub map: ContactMap,
    /// The padded grid the convolutions ran on, (rows, columns).
    pub padded: (usize, usize),
}

/// Checks the grid: shape, pitches, finite heights, size.
pub fn check_grid(grid: &ContactGrid<'_>) -> Result<(), ContactError> {
    let ContactGrid {
        heights_um,
        rows,
        cols,
        pitch_x_mm,
        pitch_y_mm,
    } = *grid;
    for (axis, pitch_mm) in [("x", pitch_x_mm), ("y", pitch_y_mm)] {
        if !(pitch_mm.is_finite() && pitch_mm > 0.0) {
            return Err(ContactError::Pitch { axis, pitch_mm });
        }
    }
    if heights_um.len() != rows * cols {
        return Err(ContactError::Shape {
            rows,
            cols,
            len: heights_um.len(),
        });
    }
    if let Some(i) = heights_um.iter().position(|h| !h.is_finite()) {
        return Err(ContactError::Height {
            row: i / cols,
            col: i % cols,
            value: heights_um[i],
        });
    }
    if rows < MIN_POINTS_PER_AXIS || cols < MIN_POINTS_PER_AXIS {
        return Err(ContactError::TooSmall {
            rows,
            cols,
            min: MIN_POINTS_PER_AXIS,
        });
    }
    Ok(())
}

/// The sorted, de-duplicated pressures to solve (the map load included), checked against
/// each other and the hardness.
fn pressures(opts: &ContactOptions) -> Result<(Vec<f64>, f64), ContactError> {
    // The bodies are checked where they are made; again here for options built from stored
    // values (a scan's frozen plan).
    Body::try_new("specimen", opts.specimen.young_gpa, opts.specimen.poisson)?;
    if let Some(c) = opts.counter {
        Body::try_new("counter-body", c.young_gpa, c.poisson)?;
    }
    let mut list = opts.pressures_mpa.clone();
    if list.is_empty() {
        return Err(ContactError::Pressure {
            pressure_mpa: f64::NAN,
        });
    }
    if let Some(&bad) = list.iter().find(|p| !(p.is_finite() && **p > 0.0)) {
        return Err(ContactError::Pressure { pressure_mpa: bad });
    }
    list.sort_by(f64::total_cmp);
    list.dedup();
    let map = match opts.map_pressure_mpa {
        Some(m) if !(m.is_finite() && m > 0.0) => {
            return Err(ContactError::Pressure { pressure_mpa: m })
        }
        Some(m) => m,
        None => list[(list.len() - 1) / 2],
    };
    if !list.contains(&map) {
        list.push(map);
        list.sort_by(f64::total_cmp);
    }
    if let Some(h) = opts.hardness_gpa {
        if !(h.is_finite() && (MIN_HARDNESS_GPA..=MAX_HARDNESS_GPA).contains(&h)) {
            return Err(ContactError::Hardness { hardness_gpa: h });
        }
        let hardness_mpa = h * 1000.0;
        if let Some(&p) = list.iter().find(|&&p| p >= hardness_mpa) {
            return Err(ContactError::BeyondHardness {
                pressure_mpa: p,
                hardness_mpa,
            });
        }
    }
    Ok((list, map))
}

/// Checks the bodies, the loads, the map load and the hardness of `opts`, as
/// [`contact_curve`] does before it solves anything.
pub fn check_options(opts: &ContactOptions) -> Result<(), ContactError> {
    pressures(opts).map(|_| ())
}

/// Solves the contact of `grid` at every pressure of `opts` (see the module doc).
pub fn contact_curve(
    grid: &ContactGrid<'_>,
    opts: &ContactOptions,
) -> Result<ContactCurve, ContactError> {
    check_grid(grid)?;
    let (list, map_at) = pressures(opts)?;
    let (lo, hi) = grid
        .heights_um
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(h), b.max(h))
        });
    if hi == lo {
        // A flat surface touches everywhere at once.
        return Err(ContactError::FullContact {
            pressure_mpa: list[0],
            last_partial_mpa: None,
        });
    }
    let e_gpa = effective_modulus_gpa(opts.specimen, opts.counter);
    let (rows, cols) = (grid.rows, grid.cols);
    let n = rows * cols;
    let mut space = HalfSpace::new(
        rows,
        cols,
        grid.pitch_x_mm * 1000.0,
        grid.pitch_y_mm * 1000.0,
        e_gpa * 1000.0,
    );
    let hardness_mpa = opts.hardness_gpa.map(|h| h * 1000.0);
    let mut points = Vec::with_capacity(list.len());
    let mut previous: Option<Vec<f64>> = None;
    let mut map = None;
    for &pressure_mpa in &list {
        let sol = solve(
            &mut space,
            grid.heights_um,
            pressure_mpa,
            hardness_mpa,
            previous.as_deref(),
            &opts.solve,
        )
        .map_err(|state| ContactError::NotConverged {
            pressure_mpa,
            state,
        })?;
        let mask: Vec<bool> = sol.pressure_mpa.iter().map(|&p| p > 0.0).collect();
        let contact = mask.iter().filter(|&&c| c).count();
        if contact == n {
            return Err(ContactError::FullContact {
                pressure_mpa,
                last_partial_mpa: points.last().map(|p: &CurvePoint| p.nominal_pressure_mpa),
            });
        }
        let flowing =
            hardness_mpa.map_or(0, |h| sol.pressure_mpa.iter().filter(|&&p| p >= h).count());
        let mean_gap_um = sol.gap_um.iter().map(|g| g.max(0.0)).sum::<f64>() / n as f64;
        let area_fraction = contact as f64 / n as f64;
        let found = patches(&mask, rows, cols);
        let single = found.single_point_fraction();
        points.push(CurvePoint {
            nominal_pressure_mpa: pressure_mpa,
            area_fraction,
            mean_gap_um,
            mean_contact_pressure_mpa: if contact > 0 {
                pressure_mpa / area_fraction
            } else {
                0.0
            },
            patches: found.count(),
            plastic_fraction: flowing as f64 / n as f64,
            approach_um: sol.approach_um,
            single_point_patch_fraction: single,
            single_line_patch_fraction: found.single_row_fraction(),
            resolved: single <= UNRESOLVED_SINGLE_POINT_FRACTION,
            iterations: sol.iterations,
        });
        if pressure_mpa == map_at {
            map = Some(ContactMap {
                nominal_pressure_mpa: pressure_mpa,
                pressure_mpa: sol.pressure_mpa.clone(),
            });
        }
        previous = Some(sol.pressure_mpa);
    }
    if points.iter().all(|p| !p.resolved) {
        return Err(ContactError::Unresolved {
            rows,
            cols,
            pitch_x_mm: grid.pitch_x_mm,
            pitch_y_mm: grid.pitch_y_mm,
            single_point_fraction: points.last().map_or(1.0, |p| p.single_point_patch_fraction),
        });
    }
    Ok(ContactCurve {
        effective_modulus_gpa: e_gpa,
        hardness_gpa: opts.hardness_gpa,
        points,
        map: map.expect("the map pressure is in the list"),
        padded: space.padded(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hertz: a paraboloid z = −r²/(2R) pressed by F has a contact radius
    /// a = (3FR/(4E*))^(1/3), a peak pressure p0 = 3F/(2πa²), an approach δ = a²/R and the
    /// pressure p0·√(1 − r²/a²). Checked on a square and on an anisotropic grid (pitches 4:1,
    /// as a scan's are) of the same 64 µm × 64 µm area; discretisation errors of a contact
    /// 30 points wide are a few per cent.
    #[test]
    fn hertz_sphere_on_square_and_anisotropic_grids() {
        for (cols, rows) in [(64usize, 64usize), (128, 32)] {
            let (dx, dy) = (64.0 / cols as f64, 64.0 / rows as f64); // µm
            let radius = 1e4; // µm (R = 10 mm)
            let e_star = 1e5; // MPa
            let (xc, yc) = ((cols / 2) as f64 * dx, (rows / 2) as f64 * dy);
            let h: Vec<f64> = (0..rows * cols)
                .map(|i| {
                    let (x, y) = ((i % cols) as f64 * dx - xc, (i / cols) as f64 * dy - yc);
                    -(x * x + y * y) / (2.0 * radius)
                })
                .collect();
            let a_target: f64 = 15.0; // µm
            let force = 4.0 * e_star * a_target.powi(3) / (3.0 * radius); // MPa·µm²
            let nominal = force / (64.0 * 64.0);
            let grid = ContactGrid {
                heights_um: &h,
                rows,
                cols,
                pitch_x_mm: dx / 1000.0,
                pitch_y_mm: dy / 1000.0,
            };
            // E* = 100 GPa from a body with ν = 0.
            let opts = ContactOptions {
                specimen: Body::try_new("specimen", 100.0, 0.0).unwrap(),
                pressures_mpa: vec![nominal],
                ..ContactOptions::default()
            };
            let curve = contact_curve(&grid, &opts).unwrap();
            let point = &curve.points[0];
            let area = point.area_fraction * 64.0 * 64.0;
            let a = (area / std::f64::consts::PI).sqrt();
            assert!(
                (a - a_target).abs() / a_target < 0.03,
                "{cols}×{rows}: a = {a}"
            );
            let delta = a_target * a_target / radius;
            assert!(
                (point.approach_um - delta).abs() / delta < 0.03,
                "δ = {}",
                point.approach_um
            );
            assert_eq!(point.patches, 1);
            let p0 = 3.0 * force / (2.0 * std::f64::consts::PI * a_target * a_target);
            let p = &curve.map.pressure_mpa;
            let peak = p.iter().cloned().fold(0.0, f64::max);
            assert!((peak - p0).abs() / p0 < 0.03, "peak {peak} vs {p0}");
            // The profile inside 0.8 a, pointwise within 4 % of p0.
            for (i, &pi) in p.iter().enumerate() {
                let (x, y) = ((i % cols) as f64 * dx - xc, (i / cols) as f64 * dy - yc);
                let r2 = (x * x + y * y) / (a_target * a_target);
                if r2 < 0.64 {
                    let want = p0 * (1.0 - r2).sqrt();
                    assert!(
                        (pi - want).abs() < 0.04 * p0,
                        "p({x}, {y}) = {pi} vs {want}"
                    );
                }
            }
        }
    }

    fn noise(rows: usize, cols: usize) -> Vec<f64> {
        (0..rows * cols)
            .map(|i| ((i * 2654435761usize) % 1000) as f64 / 1000.0)
            .collect()
    }

    fn grid(h: &[f64], rows: usize, cols: usize) -> ContactGrid<'_> {
        ContactGrid {
            heights_um: h,
            rows,
            cols,
            pitch_x_mm: 0.001,
            pitch_y_mm: 0.01,
        }
    }

    #[test]
    fn bad_grids_are_named() {
        let h = noise(8, 8);
        let opts = ContactOptions::default();
        let mut g = grid(&h, 8, 8);
        g.pitch_y_mm = 0.0;
        assert!(matches!(
            contact_curve(&g, &opts),
            Err(ContactError::Pitch { axis: "y", .. })
        ));
        let g = grid(&h[..60], 8, 8);
        assert!(matches!(
            contact_curve(&g, &opts),
            Err(ContactError::Shape { len: 60, .. })
        ));
        let mut bad = h.clone();
        bad[13] = f64::NAN;
        assert!(matches!(
            contact_curve(&grid(&bad, 8, 8), &opts),
            Err(ContactError::Height { row: 1, col: 5, .. })
        ));
        let e = contact_curve(&grid(&h[..24], 3, 8), &opts).unwrap_err();
        assert!(matches!(
            e,
            ContactError::TooSmall {
                rows: 3,
                cols: 8,
                min: 4
            }
        ));
        assert!(
            e.to_string().contains("too small to resolve contact"),
            "{e}"
        );
    }

    #[test]
    fn bad_loads_and_hardness_are_named() {
        let h = noise(8, 8);
        let g = grid(&h, 8, 8);
        for bad in [vec![], vec![1.0, -2.0], vec![f64::NAN]] {
            let opts = ContactOptions {
                pressures_mpa: bad,
                ..ContactOptions::default()
            };
            assert!(matches!(
                contact_curve(&g, &opts),
                Err(ContactError::Pressure { .. })
            ));
        }
        let opts = ContactOptions {
            hardness_gpa: Some(0.0),
            ..ContactOptions::default()
        };
        assert!(matches!(
            contact_curve(&g, &opts),
            Err(ContactError::Hardness { .. })
        ));
        // 100 MPa (the default list's top) on a 0.05 GPa surface: beyond full contact.
        let opts = ContactOptions {
            hardness_gpa: Some(0.05),
            ..ContactOptions::default()
        };
        let e = contact_curve(&g, &opts).unwrap_err();
        assert_eq!(
            e,
            ContactError::BeyondHardness {
                pressure_mpa: 50.0,
                hardness_mpa: 50.0
            }
        );
        assert!(e.to_string().contains("beyond full contact"), "{e}");
    }

    /// A flat surface is in full contact at any load; a rough one at a huge load.
    #[test]
    fn full_contact_is_named_with_the_last_open_load() {
        let flat = vec![1.0; 64];
        let e = contact_curve(&grid(&flat, 8, 8), &ContactOptions::default()).unwrap_err();
        assert_eq!(
            e,
            ContactError::FullContact {
                pressure_mpa: 1.0,
                last_partial_mpa: None
            }
        );
        let h: Vec<f64> = noise(8, 8).iter().map(|v| v * 0.01).collect();
        let opts = ContactOptions {
            pressures_mpa: vec![1.0, 1e6],
            ..ContactOptions::default()
        };
        match contact_curve(&grid(&h, 8, 8), &opts).unwrap_err() {
            ContactError::FullContact {
                pressure_mpa,
                last_partial_mpa,
            } => {
                assert_eq!(pressure_mpa, 1e6);
                assert_eq!(last_partial_mpa, Some(1.0));
            }
            other => panic!("{other}"),
        }
    }

    /// Uncorrelated heights touch at isolated points at every low load: refused as too
    /// coarse, with the numbers.
    #[test]
    fn uncorrelated_heights_are_too_coarse_to_resolve() {
        let (rows, cols) = (16, 16);
        let h = noise(rows, cols);
        let opts = ContactOptions {
            pressures_mpa: vec![0.01, 0.1],
            ..ContactOptions::default()
        };
        let e = contact_curve(&grid(&h, rows, cols), &opts).unwrap_err();
        assert!(
            matches!(
                e,
                ContactError::Unresolved {
                    rows: 16,
                    cols: 16,
                    ..
                }
            ),
            "{e}"
        );
        assert!(
            e.to_string().contains("too coarse to resolve contact"),
            "{e}"
        );
    }

    /// The map belongs to the chosen load, which joins the curve when not listed.
    #[test]
    fn map_load_joins_the_curve() {
        let (rows, cols) = (8, 32);
        let h: Vec<f64> = (0..rows * cols)
            .map(|i| ((i % cols) as f64 * 0.3).sin() + (i / cols) as f64 * 0.01)
            .collect();
        let opts = ContactOptions {
            pressures_mpa: vec![10.0, 1.0],
            map_pressure_mpa: Some(5.0),
            ..ContactOptions::default()
        };
        let c = contact_curve(&grid(&h, rows, cols), &opts).unwrap();
        let loads: Vec<f64> = c.points.iter().map(|p| p.nominal_pressure_mpa).collect();
        assert_eq!(loads, vec![1.0, 5.0, 10.0]);
        assert_eq!(c.map.nominal_pressure_mpa, 5.0);
        let mean: f64 = c.map.pressure_mpa.iter().sum::<f64>() / (rows * cols) as f64;
        assert!((mean - 5.0).abs() < 1e-6);
        // More load, more area, less gap.
        let areas: Vec<f64> = c.points.iter().map(|p| p.area_fraction).collect();
        assert!(
            areas[0] <= areas[1] && areas[1] <= areas[2] && areas[0] < areas[2],
            "{areas:?}"
        );
        assert!(c
            .points
            .windows(2)
            .all(|w| w[1].mean_gap_um < w[0].mean_gap_um));
    }
}
