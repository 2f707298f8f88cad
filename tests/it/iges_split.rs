//! Exact splitting of surfaces along v for IGES entities and files: the split that holds
//! only the rows it changes gives the bits of a split that copies the whole net per
//! insertion, and the file plan built from knots alone gives the patches of splitting the
//! surface itself.

use surfscan::iges::{
    plan_layout, plan_parts, split_v, split_v_middle, split_v_middle_side, split_v_side,
    IgesOptions, Side,
};
use surfscan::nurbs::NurbsSurface;

/// The split as it was first written: every insertion builds a whole new copy of the net.
/// The windowed split must give the same bits.
fn split_v_copying(surface: &NurbsSurface, v_split: f64) -> Option<(NurbsSurface, NurbsSurface)> {
    let q = surface.degree_v();
    let nu = surface.count_u();
    let mut knots = surface.knots_v().to_vec();
    let mut rows: Vec<Vec<[f64; 3]>> = surface
        .net()
        .to_vec()
        .chunks_exact(nu)
        .map(|r| r.to_vec())
        .collect();
    let (lo, hi) = (knots[q], knots[rows.len()]);
    if !(v_split > lo && v_split < hi) {
        return None;
    }
    loop {
        let mult = knots.iter().filter(|&&k| k == v_split).count();
        if mult >= q {
            break;
        }
        // Span k: knots[k] <= v < knots[k+1].
        let k = knots.iter().rposition(|&t| t <= v_split)?;
        let mut new_rows = Vec::with_capacity(rows.len() + 1);
        for i in 0..=rows.len() {
            if i + q <= k {
                new_rows.push(rows[i].clone());
            } else if i > k {
                new_rows.push(rows[i - 1].clone());
            } else {
                let a = (v_split - knots[i]) / (knots[i + q] - knots[i]);
                let row: Vec<[f64; 3]> = rows[i]
                    .iter()
                    .zip(&rows[i - 1])
                    .map(|(p, r)| {
                        [
                            a * p[0] + (1.0 - a) * r[0],
                            a * p[1] + (1.0 - a) * r[1],
                            a * p[2] + (1.0 - a) * r[2],
                        ]
                    })
                    .collect();
                new_rows.push(row);
            }
        }
        knots.insert(k + 1, v_split);
        rows = new_rows;
    }
    let a = knots.iter().position(|&t| t == v_split)?;
    let mut lower_knots = knots[..a + q].to_vec();
    lower_knots.push(v_split);
    let mut upper_knots = vec![v_split];
    upper_knots.extend_from_slice(&knots[a..]);
    let flat = |rs: &[Vec<[f64; 3]>]| rs.iter().flatten().copied().collect::<Vec<_>>();
    let lower = NurbsSurface::try_new(
        surface.degree_u(),
        q,
        surface.knots_u().to_vec(),
        lower_knots,
        nu,
        a,
        flat(&rows[..a]),
    )
    .ok()?;
    let upper = NurbsSurface::try_new(
        surface.degree_u(),
        q,
        surface.knots_u().to_vec(),
        upper_knots,
        nu,
        rows.len() + 1 - a,
        flat(&rows[a - 1..]),
    )
    .ok()?;
    Some((lower, upper))
}

/// A degree-(3, q) surface with uneven v knots, signed zeros and assorted magnitudes.
fn surface(nu: usize, nv: usize, q: usize, knots_v: Vec<f64>) -> NurbsSurface {
    let p = 3;
    let mut knots_u = vec![0.0; p + 1];
    for i in 1..nu - p {
        knots_u.push(i as f64 / (nu - p) as f64);
    }
    knots_u.extend(std::iter::repeat_n(1.0, p + 1));
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let poles = (0..nu * nv)
        .map(|n| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let z = ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 1e-3;
            let z = if n % 7 == 0 { -0.0 } else { z };
            [
                (n % nu) as f64 * 0.0005,
                (n / nu) as f64 * 0.01 + 1.0 / 3.0,
                z,
            ]
        })
        .collect();
    NurbsSurface::try_new(p, q, knots_u, knots_v, nu, nv, poles).unwrap()
}

fn clamped(nv: usize, q: usize, interior: &[f64]) -> Vec<f64> {
    assert_eq!(interior.len(), nv - q - 1);
    let mut k = vec![0.0; q + 1];
    k.extend_from_slice(interior);
    k.extend(std::iter::repeat_n(1.0, q + 1));
    k
}

fn same_bits(a: &NurbsSurface, b: &NurbsSurface) {
    assert_eq!((a.count_u(), a.count_v()), (b.count_u(), b.count_v()));
    let bits = |s: &NurbsSurface| -> Vec<u64> {
        s.knots_v()
            .iter()
            .copied()
            .chain(s.poles().flatten())
            .map(f64::to_bits)
            .collect()
    };
    assert_eq!(bits(a), bits(b));
    assert_eq!(a.knots_u(), b.knots_u());
}

#[test]
fn windowed_split_gives_the_bits_of_the_copying_split() {
    let even = |nv: usize, q: usize| -> Vec<f64> {
        (1..nv - q).map(|i| i as f64 / (nv - q) as f64).collect()
    };
    let cases = [
        (9, 20, 5, clamped(20, 5, &even(20, 5))),
        (6, 8, 3, clamped(8, 3, &even(8, 3))),
        // A knot already of multiplicity 2, uneven spacing.
        (7, 12, 5, clamped(12, 5, &[0.1, 0.1, 0.35, 0.6, 0.61, 0.9])),
        (5, 7, 1, clamped(7, 1, &[0.2, 0.3, 0.5, 0.7, 0.75])),
    ];
    for (nu, nv, q, knots_v) in cases {
        let s = surface(nu, nv, q, knots_v);
        let interior: Vec<f64> = s.knots_v()[q + 1..nv].to_vec();
        for v in interior {
            let (lo, hi) = split_v(&s, v).unwrap();
            let (rlo, rhi) = split_v_copying(&s, v).unwrap();
            same_bits(&lo, &rlo);
            same_bits(&hi, &rhi);
            // Splitting a patch again, as large surfaces are split recursively.
            for part in [&lo, &hi] {
                let (a, b) = (part.knots_v()[q], part.knots_v()[part.count_v()]);
                let inner: Vec<f64> = part.knots_v()[q + 1..part.count_v()]
                    .iter()
                    .copied()
                    .filter(|&k| k > a && k < b)
                    .collect();
                for w in inner {
                    let (x, y) = split_v(part, w).unwrap();
                    let (rx, ry) = split_v_copying(part, w).unwrap();
                    same_bits(&x, &rx);
                    same_bits(&y, &ry);
                }
            }
        }
        // Outside the domain, or at its ends: no split.
        assert!(split_v(&s, 0.0).is_none() && split_v(&s, 1.0).is_none());
        assert!(split_v(&s, 1.5).is_none() && split_v(&s, f64::NAN).is_none());
    }
}

/// The patches of splitting `s` in the middle recursively until each bound fits `cap`, built
/// eagerly with [`split_v_middle`] (what the file plan must reproduce).
fn split_eagerly(s: NurbsSurface, cap: usize, out: &mut Vec<NurbsSurface>) {
    if surfscan::iges::parameter_lines_bound(&s) <= cap {
        out.push(s);
        return;
    }
    let (lo, hi) = split_v_middle(&s).expect("interior knot");
    split_eagerly(lo, cap, out);
    split_eagerly(hi, cap, out);
}

#[test]
fn one_sided_splits_give_the_bits_of_the_two_sided_split() {
    let even: Vec<f64> = (1..15).map(|i| i as f64 / 15.0).collect();
    let s = surface(8, 20, 5, clamped(20, 5, &even));
    for v in [even[3], even[7], 0.123] {
        let (lo, hi) = split_v(&s, v).unwrap();
        same_bits(&split_v_side(&s, v, Side::Lower).unwrap(), &lo);
        same_bits(&split_v_side(&s, v, Side::Upper).unwrap(), &hi);
    }
    let (lo, hi) = split_v_middle(&s).unwrap();
    same_bits(&split_v_middle_side(&s, Side::Lower).unwrap(), &lo);
    same_bits(&split_v_middle_side(&s, Side::Upper).unwrap(), &hi);
}

#[test]
fn file_plan_from_knots_builds_the_patches_of_the_eager_split() {
    let even: Vec<f64> = (1..55).map(|i| (i as f64 / 55.0).powf(1.2)).collect();
    let s = surface(30, 60, 5, clamped(60, 5, &even));
    let whole = surfscan::iges::parameter_lines_bound(&s);
    for (entity_cap, file_cap) in [
        (whole / 2, whole),
        (whole / 5, whole / 3),
        (whole / 7, whole / 7),
    ] {
        let opts = IgesOptions {
            max_parameter_lines_per_entity: entity_cap,
            max_parameter_lines_per_file: file_cap,
            ..IgesOptions::default()
        };
        let mut eager = Vec::new();
        split_eagerly(s.clone(), entity_cap.min(file_cap), &mut eager);
        assert!(eager.len() >= 2, "{entity_cap}");
        let plan = plan_layout(&s, &opts).unwrap();
        let mut lazy = Vec::new();
        for k in 0..plan.len() {
            let part = plan.part(k).unwrap();
            assert_eq!(part.len(), plan.patches_in(k));
            let lines: usize = part.iter().map(surfscan::iges::parameter_lines_bound).sum();
            assert!(
                lines <= file_cap || part.len() == 1,
                "file {k}: {lines} > {file_cap}"
            );
            lazy.extend(part.iter().cloned());
        }
        assert_eq!(lazy.len(), eager.len());
        for (a, b) in lazy.iter().zip(&eager) {
            same_bits(a, b);
        }
        // plan_parts builds the same groups.
        let groups = plan_parts(&s, &opts).unwrap();
        assert_eq!(groups.len(), plan.len());
        let flat: Vec<&NurbsSurface> = groups.iter().flat_map(|g| g.iter()).collect();
        for (a, b) in flat.into_iter().zip(&eager) {
            same_bits(a, b);
        }
    }
    // A surface that fits is one file holding the surface itself.
    let plan = plan_layout(&s, &IgesOptions::default()).unwrap();
    assert_eq!(plan.len(), 1);
    assert!(matches!(
        plan.part(0).unwrap(),
        std::borrow::Cow::Borrowed(_)
    ));
    assert!(plan.part(1).is_err());
}
