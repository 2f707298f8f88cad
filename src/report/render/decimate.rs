//! A plotted series reduced to what its display resolution can show: for each pixel column
//! of the plotting area, the column's first and last point and its lowest and highest, in
//! their original order (the "M4" reduction). A line through the kept points covers the
//! pixels the line through all of them covers, up to the anti-aliasing of a pixel's edge, and
//! every extreme — a spike, a deep valley — stays in the figure. A 10,000-point profile drawn
//! 900 px wide keeps at most 3,600 points, so an SVG file and the time to draw it scale with
//! the figure, not with the data.
//!
//! Only figures are decimated: the data files (X3P, IGES, the CSVs) and every number of the
//! report are computed from all the points.
//!
//! A renderer's pure helper: no I/O, no dependencies beyond `std`.

use std::borrow::Cow;

/// The points of `points` (ascending in x) worth drawing across `columns` pixel columns over
/// the x range `x_range`: all of them when there are at most four a column, else each
/// column's first, lowest, highest and last point in their original order. A point whose x
/// or height is not finite is kept and ends its column's run (a plotter breaks or skips it;
/// either way the points either side are kept with it). Points that are not in ascending x
/// are returned whole: the reduction is only sound along x.
pub fn extremes_per_column(
    points: &[(f64, f64)],
    x_range: (f64, f64),
    columns: u32,
) -> Cow<'_, [(f64, f64)]> {
    let columns = columns.max(1) as usize;
    let (x0, x1) = x_range;
    let ascending = points
        .windows(2)
        .all(|w| !(w[0].0.is_finite() && w[1].0.is_finite()) || w[0].0 <= w[1].0);
    let spans = x1 > x0; // false for an empty range and for NaN ends
    if points.len() <= 4 * columns || !spans || !ascending {
        return Cow::Borrowed(points);
    }
    let per_x = columns as f64 / (x1 - x0);
    let column_of = |x: f64| ((x - x0) * per_x).floor().clamp(0.0, (columns - 1) as f64) as usize;
    let mut kept = Vec::with_capacity(4 * columns + 4);
    // The current run: the column and the indices of its first, lowest, highest and last
    // points.
    let mut run: Option<(usize, [usize; 4])> = None;
    let flush = |run: &mut Option<(usize, [usize; 4])>, kept: &mut Vec<(f64, f64)>| {
        if let Some((_, mut idx)) = run.take() {
            idx.sort_unstable();
            for (k, &i) in idx.iter().enumerate() {
                if k == 0 || idx[k - 1] != i {
                    kept.push(points[i]);
                }
            }
        }
    };
    for (i, &(x, z)) in points.iter().enumerate() {
        if !(x.is_finite() && z.is_finite()) {
            flush(&mut run, &mut kept);
            kept.push((x, z));
            continue;
        }
        let c = column_of(x);
        match &mut run {
            Some((column, idx)) if *column == c => {
                if z < points[idx[1]].1 {
                    idx[1] = i;
                }
                if z > points[idx[2]].1 {
                    idx[2] = i;
                }
                idx[3] = i;
            }
            _ => {
                flush(&mut run, &mut kept);
                run = Some((c, [i; 4]));
            }
        }
    }
    flush(&mut run, &mut kept);
    Cow::Owned(kept)
}

/// [`extremes_per_column`] of `[a, b]` pairs drawn as `(a, b)`, e.g. a material ratio curve
/// stored `[mr %, height]`.
pub fn extremes_per_column_of_pairs(
    points: &[[f64; 2]],
    x_range: (f64, f64),
    columns: u32,
) -> Vec<(f64, f64)> {
    let as_tuples: Vec<(f64, f64)> = points.iter().map(|p| (p[0], p[1])).collect();
    extremes_per_column(&as_tuples, x_range, columns).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rough profile of `n` points over 4 mm with one spike up and one valley down.
    fn profile(n: usize) -> Vec<(f64, f64)> {
        (0..n)
            .map(|i| {
                let x = 4.0 * i as f64 / n as f64;
                let mut z = (x * 37.0).sin() + 0.3 * (x * 511.0).cos();
                if i == n / 3 {
                    z = 9.0;
                }
                if i == 2 * n / 3 + 1 {
                    z = -7.5;
                }
                (x, z)
            })
            .collect()
    }

    #[test]
    fn a_series_no_denser_than_four_points_a_column_is_drawn_whole() {
        let p = profile(400);
        let kept = extremes_per_column(&p, (0.0, 4.0), 100);
        assert!(matches!(kept, Cow::Borrowed(_)));
        assert_eq!(&*kept, &p[..]);
    }

    #[test]
    fn each_columns_first_last_lowest_and_highest_are_kept_in_order() {
        let p = profile(10_000);
        let columns = 900;
        let kept = extremes_per_column(&p, (0.0, 4.0), columns);
        assert!(kept.len() <= 4 * columns as usize, "{}", kept.len());
        assert!(kept.len() >= 2 * columns as usize, "{}", kept.len());
        // A subsequence of the original, in its order.
        let mut at = 0;
        for q in kept.iter() {
            at += 1 + p[at..]
                .iter()
                .position(|r| r == q)
                .expect("a point of the series");
        }
        // Independently: the points of each column, found by brute force.
        for c in 0..columns as usize {
            let lo = 4.0 * c as f64 / columns as f64;
            let hi = 4.0 * (c + 1) as f64 / columns as f64;
            let inside: Vec<(f64, f64)> = p
                .iter()
                .copied()
                .filter(|q| q.0 >= lo && q.0 < hi)
                .collect();
            if inside.is_empty() {
                continue;
            }
            let (min, max) =
                crate::extremes::min_max(&inside.iter().map(|q| q.1).collect::<Vec<_>>());
            let kept_here: Vec<(f64, f64)> = kept
                .iter()
                .copied()
                .filter(|q| q.0 >= lo && q.0 < hi)
                .collect();
            assert_eq!(kept_here.first(), inside.first(), "column {c}");
            assert_eq!(kept_here.last(), inside.last(), "column {c}");
            assert!(kept_here.iter().any(|q| q.1 == min), "column {c}: min");
            assert!(kept_here.iter().any(|q| q.1 == max), "column {c}: max");
        }
        // The spike and the valley are there.
        assert!(kept.iter().any(|q| q.1 == 9.0));
        assert!(kept.iter().any(|q| q.1 == -7.5));
    }

    #[test]
    fn a_gap_is_kept_and_ends_its_columns_run() {
        let mut p = profile(10_000);
        p[5000].1 = f64::NAN;
        let kept = extremes_per_column(&p, (0.0, 4.0), 50);
        let gaps: Vec<usize> = (0..kept.len()).filter(|&i| kept[i].1.is_nan()).collect();
        assert_eq!(gaps.len(), 1);
        let g = gaps[0];
        // The points either side of the gap are kept beside it.
        assert_eq!(kept[g - 1], p[4999]);
        assert_eq!(kept[g + 1], p[5001]);
    }

    #[test]
    fn points_out_of_x_order_or_an_empty_range_are_drawn_whole() {
        let mut p = profile(1000);
        p.swap(10, 11);
        assert_eq!(extremes_per_column(&p, (0.0, 4.0), 10).len(), 1000);
        let p = profile(1000);
        assert_eq!(extremes_per_column(&p, (1.0, 1.0), 10).len(), 1000);
        assert_eq!(extremes_per_column(&[], (0.0, 1.0), 0).len(), 0);
    }

    #[test]
    fn pairs_are_reduced_as_their_tuples_are() {
        let p = profile(5000);
        let pairs: Vec<[f64; 2]> = p.iter().map(|q| [q.0, q.1]).collect();
        assert_eq!(
            extremes_per_column_of_pairs(&pairs, (0.0, 4.0), 300),
            extremes_per_column(&p, (0.0, 4.0), 300).into_owned()
        );
    }
}
