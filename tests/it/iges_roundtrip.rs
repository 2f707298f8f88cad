//! IGES writer/reader: byte layout rules, bit-exact round trip, refusal of bad values, and
//! exact patch splitting (checked against an independent de Boor evaluation).
use surfscan::iges::{
    parameter_lines_bound, plan_files, read_iges, split_v, write_iges, IgesError, IgesOptions,
};
use surfscan::nurbs::NurbsSurface;

fn opts() -> IgesOptions {
    IgesOptions {
        file_name: "test.igs".into(),
        author: "Operator Name".into(),
        organisation: "Lab".into(),
        timestamp: chrono::NaiveDate::from_ymd_opt(2026, 11, 22)
            .unwrap()
            .and_hms_opt(7, 5, 9)
            .unwrap(),
        start_lines: vec![
            "specimen: sur-2".into(),
            "a very long traceability line ".repeat(5),
        ],
        ..IgesOptions::default()
    }
}

/// A degree (3, 2) surface over an irregular clamped grid with awkward pole values.
fn surface(nu: usize, nv: usize) -> NurbsSurface {
    let (p, q) = (3, 2);
    let knots = |n: usize, d: usize| {
        let mut k = vec![0.0; d + 1];
        for j in 1..n - d {
            k.push((j as f64 / (n - d) as f64).powf(1.3));
        }
        k.extend(vec![1.0; d + 1]);
        k
    };
    let mut poles = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let x = i as f64 * 0.003484;
            let y = j as f64 * 0.010452;
            poles.push([x, y, 1e-4 * ((i * 7 + j * 13) as f64).sin() / 3.0]);
        }
    }
    NurbsSurface::try_new(p, q, knots(nu, p), knots(nv, q), nu, nv, poles).unwrap()
}

/// Independent evaluation: de Boor's algorithm per direction (not the crate's evaluator).
fn de_boor(degree: usize, knots: &[f64], ctrl: &[[f64; 3]], t: f64) -> [f64; 3] {
    let n = ctrl.len();
    let mut k = degree;
    while k + 1 < n && knots[k + 1] <= t {
        k += 1;
    }
    let mut d: Vec<[f64; 3]> = (0..=degree).map(|j| ctrl[j + k - degree]).collect();
    for r in 1..=degree {
        for j in (r..=degree).rev() {
            let i = j + k - degree;
            let a = (t - knots[i]) / (knots[i + degree + 1 - r] - knots[i]);
            let prev = d[j - 1];
            for (c, pc) in d[j].iter_mut().zip(prev) {
                *c = (1.0 - a) * pc + a * *c;
            }
        }
    }
    d[degree]
}

fn eval(s: &NurbsSurface, u: f64, v: f64) -> [f64; 3] {
    let cols: Vec<[f64; 3]> = (0..s.count_v())
        .map(|j| {
            let row = &s.net().to_vec()[j * s.count_u()..(j + 1) * s.count_u()];
            de_boor(s.degree_u(), s.knots_u(), row, u)
        })
        .collect();
    de_boor(s.degree_v(), s.knots_v(), &cols, v)
}

#[test]
fn every_record_is_80_columns_with_per_section_sequences() {
    let mut out = Vec::new();
    let stats = write_iges(&mut out, &[surface(9, 6)], &opts()).unwrap();
    let text = String::from_utf8(out.clone()).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(stats.bytes as usize, out.len());
    let mut seq = std::collections::HashMap::new();
    for l in &lines {
        assert_eq!(l.len(), 80, "{l:?}");
        let letter = &l[72..73];
        let n: usize = l[73..].trim().parse().unwrap();
        let e = seq.entry(letter.to_string()).or_insert(0);
        *e += 1;
        assert_eq!(n, *e, "{l}");
    }
    // Start text wrapped to 72 columns at spaces: the 150-character line takes 3 records
    // (71, 72 and the remaining characters), so 4 in all.
    assert_eq!(seq["S"], 4);
    assert_eq!(seq["D"], 2);
    let t = lines.last().unwrap();
    assert_eq!(
        &t[..32],
        format!("S      4G{:>7}D      2P{:>7}", seq["G"], seq["P"])
    );
    // Global: delimiters, units MM, version 11, date stamp.
    let g: String = lines
        .iter()
        .filter(|l| &l[72..73] == "G")
        .map(|l| &l[..72])
        .collect();
    assert!(g.starts_with("1H,,1H;,8Hsurfscan,8Htest.igs,"), "{g}");
    assert!(g.contains(",2,2HMM,"), "{g}");
    assert!(g.contains("15H20261122.070509"), "{g}");
    assert!(g.contains(",1.E-7,"), "{g}");
    assert!(g.contains("13HOperator Name,3HLab,11,0,"), "{g}");
    // DE: entity 128 right-justified, PD pointer 1, back-pointer 1 on every P line.
    let d1 = lines.iter().find(|l| &l[72..73] == "D").unwrap();
    assert_eq!(&d1[..16], "     128       1");
    for l in lines.iter().filter(|l| &l[72..73] == "P") {
        assert_eq!(&l[64..72], "       1");
        let data = l[..64].trim_end();
        assert!(
            data.ends_with(',') || data.ends_with(';'),
            "break after a delimiter: {l}"
        );
    }
    // Header: K1=8, K2=5, M1=3, M2=2, PROP 0,0,1,0,0.
    let p1 = lines.iter().find(|l| &l[72..73] == "P").unwrap();
    assert!(p1.starts_with("128,8,5,3,2,0,0,1,0,0,0.,0.,0.,0.,"), "{p1}");
}

#[test]
fn write_read_round_trip_is_bit_identical() {
    let s = surface(23, 11);
    let mut out = Vec::new();
    write_iges(&mut out, std::slice::from_ref(&s), &opts()).unwrap();
    let file = read_iges(&out).unwrap();
    assert_eq!(file.surfaces.len(), 1);
    let r = &file.surfaces[0];
    assert_eq!(r.degree_u(), 3);
    assert_eq!(r.degree_v(), 2);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(r.knots_u()), bits(s.knots_u()));
    assert_eq!(bits(r.knots_v()), bits(s.knots_v()));
    let pb = |s: &NurbsSurface| s.poles().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(pb(r), pb(&s));
    assert_eq!(file.global[14], "MM");
    assert_eq!(file.global[22], "11");
    assert_eq!(file.start_lines[0], "specimen: sur-2");
}

#[test]
fn reader_rejects_structural_damage() {
    let mut out = Vec::new();
    write_iges(&mut out, &[surface(9, 6)], &opts()).unwrap();
    let text = String::from_utf8(out).unwrap();
    // 81 columns.
    let bad = text.replacen("\n", " \n", 1);
    assert!(matches!(
        read_iges(bad.as_bytes()),
        Err(IgesError::Structure { line: 1, .. })
    ));
    // Wrong terminate count.
    let t = text.lines().last().unwrap();
    let bad = text.replace(t, &format!("S      9{}", &t[8..]));
    assert_ne!(bad, text);
    assert!(read_iges(bad.as_bytes()).is_err(), "terminate count");
    // Wrong DE line count for the entity.
    let d2 = text.lines().find(|l| l.ends_with("D      2")).unwrap();
    let n: usize = d2[24..32].trim().parse().unwrap();
    let bad = text.replace(d2, &format!("{}{:>8}{}", &d2[..24], n - 1, &d2[32..]));
    assert_ne!(bad, text);
    assert!(read_iges(bad.as_bytes()).is_err(), "DE line count");
    // A pole written as NaN-like text.
    let p3 = text.lines().find(|l| l.ends_with("P      3")).unwrap();
    let bad = text.replace(p3, &p3.replacen("0.", "N.", 1));
    assert_ne!(bad, text);
    assert!(read_iges(bad.as_bytes()).is_err(), "bad real");
}

#[test]
fn splitting_is_exact_and_shares_the_boundary_row() {
    let s = surface(12, 17);
    let v_split = s.knots_v()[8];
    let (lo, hi) = split_v(&s, v_split).unwrap();
    assert_eq!(lo.knots_v().last(), Some(&v_split));
    assert_eq!(hi.knots_v().first(), Some(&v_split));
    let last_lo = &lo.net().to_vec()[(lo.count_v() - 1) * lo.count_u()..];
    assert_eq!(last_lo, &hi.net().to_vec()[..hi.count_u()]);
    for a in 0..=20 {
        let u = a as f64 / 20.0;
        for b in 0..=40 {
            let v = b as f64 / 40.0;
            let part = if v <= v_split { &lo } else { &hi };
            let (e, g) = (eval(&s, u, v), eval(part, u, v));
            for c in 0..3 {
                assert!(
                    (e[c] - g[c]).abs() <= 1e-15 * (1.0 + e[c].abs()),
                    "{u} {v}: {e:?} vs {g:?}"
                );
            }
        }
    }
}

#[test]
fn writer_splits_large_surfaces_into_exact_patches() {
    let s = surface(30, 40);
    let mut one = Vec::new();
    let whole = write_iges(&mut one, std::slice::from_ref(&s), &opts()).unwrap();
    let limit = whole.parameter_lines / 3;
    let mut out = Vec::new();
    let stats = write_iges(
        &mut out,
        std::slice::from_ref(&s),
        &IgesOptions {
            max_parameter_lines_per_entity: limit,
            ..opts()
        },
    )
    .unwrap();
    assert!(stats.patches >= 3, "{stats:?}");
    let file = read_iges(&out).unwrap();
    assert_eq!(file.surfaces.len(), stats.patches);
    for w in file.surfaces.windows(2) {
        assert_eq!(w[0].knots_v().last(), w[1].knots_v().first());
    }
    for p in &file.surfaces {
        let (v0, v1) = (p.knots_v()[0], *p.knots_v().last().unwrap());
        for a in 0..=10 {
            for b in 0..=10 {
                let (u, v) = (a as f64 / 10.0, v0 + (v1 - v0) * b as f64 / 10.0);
                let (e, g) = (eval(&s, u, v), eval(p, u, v));
                for c in 0..3 {
                    assert!((e[c] - g[c]).abs() <= 1e-14, "{u} {v}: {e:?} vs {g:?}");
                }
            }
        }
    }
}

#[test]
fn refuses_a_limit_that_cannot_be_met() {
    let s = surface(30, 3);
    let r = write_iges(
        Vec::new(),
        &[s],
        &IgesOptions {
            max_parameter_lines_per_entity: 2,
            ..opts()
        },
    );
    assert!(matches!(r, Err(IgesError::EntityTooLarge { .. })), "{r:?}");
}

#[test]
fn reader_rejects_garbage_and_absurd_sizes_without_panicking() {
    assert!(read_iges(b"").is_err());
    assert!(read_iges(b"hello\n").is_err());
    let mut out = Vec::new();
    write_iges(&mut out, &[surface(9, 6)], &opts()).unwrap();
    let text = String::from_utf8(out).unwrap();
    let p1 = text.lines().find(|l| l.ends_with("P      1")).unwrap();
    // K1 = u64::MAX: the size arithmetic must not overflow. Cut back to 64 data columns.
    let huge = p1.replacen("128,8,5,", "128,18446744073709551615,5,", 1);
    let fixed = format!("{}{}", &huge[..64], &p1[64..]);
    let bad = text.replace(p1, &fixed);
    assert!(matches!(
        read_iges(bad.as_bytes()),
        Err(IgesError::Parameter { .. })
    ));
}

#[test]
fn large_nets_formatted_in_parallel_chunks_round_trip_bit_identical() {
    // 300 × 250 = 75 000 poles: above the parallel-formatting threshold.
    let s = surface(300, 250);
    let mut out = Vec::new();
    let stats = write_iges(&mut out, std::slice::from_ref(&s), &opts()).unwrap();
    assert_eq!(stats.patches, 1);
    let r = &read_iges(&out).unwrap().surfaces[0];
    let pb = |s: &NurbsSurface| s.poles().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(pb(r), pb(&s));
    assert_eq!(r.knots_v(), s.knots_v());
}

/// A fitted 60×25 grid (degree 5×5) of a wavy height field.
fn fitted_surface() -> NurbsSurface {
    use surfscan::fit::{FitOptions, IncrementalFitter};
    let mut f = IncrementalFitter::new(FitOptions::degrees(5, 5));
    for r in 0..60 {
        let row: Vec<f64> = (0..25)
            .map(|c| 0.8 * ((c as f64) * 0.37 + (r as f64) * 0.21).sin() + 0.01 * (r * c) as f64)
            .collect();
        f.push_row(r as f64 * 0.05, 0.02, &row).unwrap();
    }
    f.finish().unwrap().surface
}

/// P lines `write_iges` reports for `patches` written as one file with no caps.
fn p_lines(patches: &[NurbsSurface]) -> usize {
    write_iges(Vec::new(), patches, &opts())
        .unwrap()
        .parameter_lines
}

/// The bound on P lines the planner works from (token counts, no formatting).
fn bound(patches: &[NurbsSurface]) -> usize {
    patches.iter().map(parameter_lines_bound).sum()
}

#[test]
fn plan_files_groups_exact_patches_into_capped_files_that_read_back() {
    let s = fitted_surface();
    let whole = bound(std::slice::from_ref(&s));
    // Entities of at most a sixth of the surface: one file holds them all without a file cap.
    let entity_cap = whole / 6;
    let one = plan_files(
        &s,
        &IgesOptions {
            max_parameter_lines_per_entity: entity_cap,
            ..opts()
        },
    )
    .unwrap();
    assert_eq!(one.len(), 1);
    let sizes: Vec<usize> = one[0]
        .iter()
        .map(|p| bound(std::slice::from_ref(p)))
        .collect();
    let (total, largest) = (sizes.iter().sum::<usize>(), *sizes.iter().max().unwrap());
    // A file cap of total/3 + largest patch: greedy filling leaves each closed file with more
    // than total/3 lines, so at most 3 files; and since it is below total/2 (the largest
    // patch is under total/6), two files cannot hold everything: exactly 3.
    assert!(largest < total / 6, "{sizes:?}");
    let file_cap = total / 3 + largest;
    let o = IgesOptions {
        max_parameter_lines_per_entity: entity_cap,
        max_parameter_lines_per_file: file_cap,
        ..opts()
    };
    let groups = plan_files(&s, &o).unwrap();
    assert_eq!(
        groups.len(),
        3,
        "{:?}",
        groups.iter().map(|g| g.len()).collect::<Vec<_>>()
    );
    // Writing the whole surface in one file under the same caps is refused with a named error.
    let r = write_iges(Vec::new(), std::slice::from_ref(&s), &o);
    assert!(
        matches!(r, Err(IgesError::SectionTooLong { section: 'P', max_lines, .. }) if max_lines == file_cap),
        "{r:?}"
    );
    let mut read_back: Vec<Vec<NurbsSurface>> = Vec::new();
    for (k, g) in groups.iter().enumerate() {
        // Each entity and each file stays within its cap; greedy grouping leaves no room for
        // the next file's first patch.
        for p in g {
            assert!(p_lines(std::slice::from_ref(p)) <= entity_cap);
        }
        let lines = p_lines(g);
        assert!(
            lines <= bound(g) && bound(g) <= file_cap,
            "file {k}: {lines} > {file_cap}"
        );
        if let Some(next) = groups.get(k + 1) {
            assert!(bound(g) + bound(&next[..1]) > file_cap);
        }
        let mut out = Vec::new();
        let st = write_iges(&mut out, g, &o).unwrap();
        assert_eq!(st.parameter_lines, lines);
        assert_eq!(st.patches, g.len());
        let file = read_iges(&out).unwrap();
        assert_eq!(file.surfaces.len(), g.len());
        for (a, b) in file.surfaces.iter().zip(g) {
            assert_eq!(a, b, "file {k} does not read back bit-identical");
        }
        read_back.push(file.surfaces);
    }
    let all: Vec<&NurbsSurface> = read_back.iter().flatten().collect();
    let nu = s.count_u();
    // v ranges tile the domain; adjacent patches (also across files) share the boundary row.
    let (q, nv) = (s.degree_v(), s.count_v());
    assert_eq!(all[0].knots_v()[0], s.knots_v()[q]);
    assert_eq!(
        *all.last().unwrap().knots_v().last().unwrap(),
        s.knots_v()[nv]
    );
    for w in all.windows(2) {
        assert_eq!(w[0].knots_v().last(), w[1].knots_v().first());
        let top = &w[0].net().to_vec()[(w[0].count_v() - 1) * nu..];
        let bottom = &w[1].net().to_vec()[..nu];
        assert_eq!(top, bottom);
    }
    // Each patch evaluates like the original over its v range, by the crate's evaluator and
    // by the independent de Boor evaluation.
    let (u0, u1) = (s.knots_u()[s.degree_u()], s.knots_u()[nu]);
    for p in &all {
        let (v0, v1) = (p.knots_v()[0], *p.knots_v().last().unwrap());
        for a in 0..=12 {
            for b in 0..=12 {
                let u = u0 + (u1 - u0) * a as f64 / 12.0;
                let v = v0 + (v1 - v0) * b as f64 / 12.0;
                let (e, g, d) = (s.evaluate(u, v), p.evaluate(u, v), eval(p, u, v));
                for c in 0..3 {
                    assert!((e[c] - g[c]).abs() <= 1e-12, "{u} {v}: {e:?} vs {g:?}");
                    assert!((e[c] - d[c]).abs() <= 1e-12, "{u} {v}: {e:?} vs {d:?}");
                }
            }
        }
    }
}

#[test]
fn plan_files_keeps_a_surface_that_fits_in_one_file_whole() {
    let s = surface(30, 40);
    let groups = plan_files(&s, &opts()).unwrap();
    assert_eq!(groups.len(), 1);
    assert_eq!(groups[0], vec![s]);
}
