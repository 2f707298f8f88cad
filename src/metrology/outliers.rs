//! Isolated spikes in a traced line (dust, a stylus bounce, a bad sample), found with a robust
//! rule so that one bad line is named instead of silently ruining the surface.
//!
//! **The rule.** The line's roughness profile r (the λc Gaussian roughness when the line is a
//! primary profile, else the heights minus their least-squares straight line) is compared with
//! its own spread measured robustly: σ = 1.4826 · MAD(r), the median absolute deviation from
//! the median, scaled to equal the standard deviation of Gaussian heights (a few spikes do not
//! move it). A point is a candidate when |r − median(r)| > k·σ; consecutive candidates form a
//! run, and a run of at most `max_points` points is an isolated spike. A longer run is a
//! feature of the surface (a scratch, a step) and is not flagged. Defaults: k = 10, at most 5
//! points. For Gaussian heights |r| > 10σ has a probability of about 2e-23 per point. On the
//! real profiles of the project's data, k = 10 flags nothing on the Mitutoyo R profile
//! (6664 points) and the nanoscale Dektak trace, 4 isolated events on the Dektak trace with
//! particles, 14 on the form-tester trace that is smooth with spikes, and 4 on the 31 lines of
//! the areal map (one of them its deep pit).
//!
//! When MAD is zero (more than half of the ordinates equal, e.g. a coarsely quantised trace)
//! the mean absolute deviation × 1.2533 (again σ for Gaussian heights) is used; a line whose
//! heights are all equal has no spikes.
//!
//! Flagging changes no data. [`bridge`] replaces a spike's points by the straight line between
//! its nearest unflagged neighbours (or holds the neighbour's height at an end of the line); the
//! caller decides whether and where (characterisation, fit) and says so in its recipe.
//!
//! Depends on [`super::filter`], [`super::MetrologyError`] and [`crate::grid`] (a grid's lines).

use super::filter;
use super::{check_heights, check_pitch, MetrologyError};
use crate::grid::Grid;
use serde::Serialize;

/// 1.4826 = 1/Φ⁻¹(3/4): MAD × this is σ for Gaussian data.
pub const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// sqrt(π/2): mean absolute deviation × this is σ for Gaussian data.
const MEAN_ABS_TO_SIGMA: f64 = 1.253_314_137_315_500_3;

/// How spikes are found. [`Default`]: k = 10 robust σ, at most 5 consecutive points.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct SpikeOptions {
    /// k: a point deviating from the median of the roughness profile by more than k robust σ
    /// (1.4826 · MAD) is a candidate.
    pub threshold_sigma: f64,
    /// The longest run of consecutive candidates that counts as an isolated spike.
    pub max_points: usize,
}

impl Default for SpikeOptions {
    fn default() -> SpikeOptions {
        SpikeOptions {
            threshold_sigma: 10.0,
            max_points: 5,
        }
    }
}

impl SpikeOptions {
    /// Checks the options; the error names the field and what is accepted.
    pub fn validate(&self) -> Result<(), MetrologyError> {
        if !(self.threshold_sigma.is_finite() && self.threshold_sigma > 0.0) {
            return Err(MetrologyError::BadParameter {
                what: "spike threshold (robust σ)",
                value: self.threshold_sigma,
                hint: "give a positive number of robust standard deviations, e.g. 10",
            });
        }
        if self.max_points == 0 {
            return Err(MetrologyError::BadParameter {
                what: "spike width (points)",
                value: 0.0,
                hint: "give the longest run of points that counts as a spike, e.g. 5",
            });
        }
        Ok(())
    }

    /// The rule in words, for recipes.
    pub fn describe(&self) -> String {
        format!(
            "isolated spike: a run of at most {} consecutive points whose roughness ordinate deviates from the line's median by more than {} x 1.4826 x MAD (MAD of the line's roughness profile: the lambda-c Gaussian roughness of a primary profile, else the heights minus their least-squares line)",
            self.max_points, self.threshold_sigma
        )
    }
}

/// One isolated spike in a line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spike {
    /// First point of the run (0-based index along the line).
    pub first: usize,
    /// Last point of the run.
    pub last: usize,
    /// The point of the run farthest from the median.
    pub peak: usize,
    /// x of that point, mm: index × pitch from the line's first point, in the grid's
    /// coordinates ([`crate::grid::Grid::x_mm`]) for a spike of [`find_grid_spikes`].
    pub x_mm: f64,
    /// Its height as measured, µm.
    pub height_um: f64,
    /// Its roughness ordinate minus the line's median, µm.
    pub deviation_um: f64,
    /// The same in robust σ.
    pub deviation_sigma: f64,
}

/// The spikes of one line and the spread they were judged against.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpikeScan {
    /// Median of the roughness profile, µm.
    pub median_um: f64,
    /// Robust σ (1.4826 · MAD, or the fallback named in the module docs), µm.
    pub sigma_um: f64,
    /// k·σ, µm.
    pub threshold_um: f64,
    /// The isolated spikes, in x order.
    pub spikes: Vec<Spike>,
    /// Runs beyond the threshold longer than `max_points` (features, not flagged).
    pub long_runs: usize,
}

/// The roughness profile the rule judges: the λc Gaussian roughness when `lambda_c_mm` is
/// given (a primary profile), else the heights minus their least-squares straight line.
pub fn spike_roughness(
    heights_um: &[f64],
    pitch_mm: f64,
    lambda_c_mm: Option<f64>,
) -> Result<Vec<f64>, MetrologyError> {
    check_pitch(pitch_mm)?;
    check_heights(heights_um)?;
    if let Some(lc) = lambda_c_mm {
        return filter::roughness(heights_um, pitch_mm, lc);
    }
    let n = heights_um.len();
    if n < 2 {
        return Ok(heights_um.to_vec());
    }
    // Least-squares line on centred indices (the normal equations are diagonal).
    let c = (n - 1) as f64 / 2.0;
    let mean = heights_um.iter().sum::<f64>() / n as f64;
    let (mut sxz, mut sxx) = (0.0, 0.0);
    for (i, z) in heights_um.iter().enumerate() {
        let x = i as f64 - c;
        sxz += x * (z - mean);
        sxx += x * x;
    }
    let b = sxz / sxx;
    Ok(heights_um
        .iter()
        .enumerate()
        .map(|(i, z)| z - mean - b * (i as f64 - c))
        .collect())
}

fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    if n == 0 {
        return 0.0;
    }
    // Selection, not a sort: under `total_cmp` only identical bits compare equal, so the
    // element at n/2 and the largest one below it are exactly the sorted sequence's v[n/2]
    // and v[n/2 - 1], found in O(n) instead of O(n log n).
    let (below, mid, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    let mid = *mid;
    if n % 2 == 1 {
        mid
    } else {
        let lower = below.iter().copied().max_by(f64::total_cmp).unwrap_or(mid);
        0.5 * (lower + mid)
    }
}

/// Finds the isolated spikes of a line from its roughness profile `roughness_um` (see
/// [`spike_roughness`]); `heights_um` (the same length) gives the measured height reported for
/// each spike.
pub fn find_spikes(
    roughness_um: &[f64],
    heights_um: &[f64],
    pitch_mm: f64,
    options: &SpikeOptions,
) -> Result<SpikeScan, MetrologyError> {
    options.validate()?;
    check_pitch(pitch_mm)?;
    check_heights(roughness_um)?;
    if roughness_um.len() != heights_um.len() {
        return Err(MetrologyError::BadParameter {
            what: "roughness ordinates",
            value: roughness_um.len() as f64,
            hint: "give one roughness ordinate per measured height",
        });
    }
    let med = median(&mut roughness_um.to_vec());
    let dev: Vec<f64> = roughness_um.iter().map(|r| (r - med).abs()).collect();
    let mad = median(&mut dev.clone());
    let sigma = if mad > 0.0 {
        MAD_TO_SIGMA * mad
    } else {
        MEAN_ABS_TO_SIGMA * dev.iter().sum::<f64>() / dev.len().max(1) as f64
    };
    let threshold = options.threshold_sigma * sigma;
    let mut spikes = Vec::new();
    let mut long_runs = 0;
    if sigma > 0.0 {
        let mut i = 0;
        let n = dev.len();
        while i < n {
            if dev[i] <= threshold {
                i += 1;
                continue;
            }
            let first = i;
            while i + 1 < n && dev[i + 1] > threshold {
                i += 1;
            }
            let last = i;
            i += 1;
            if last - first + 1 > options.max_points {
                long_runs += 1;
                continue;
            }
            let peak = (first..=last)
                .max_by(|&a, &b| dev[a].total_cmp(&dev[b]))
                .unwrap_or(first);
            let deviation = roughness_um[peak] - med;
            spikes.push(Spike {
                first,
                last,
                peak,
                x_mm: peak as f64 * pitch_mm,
                height_um: heights_um[peak],
                deviation_um: deviation,
                deviation_sigma: deviation.abs() / sigma,
            });
        }
    }
    Ok(SpikeScan {
        median_um: med,
        sigma_um: sigma,
        threshold_um: threshold,
        spikes,
        long_runs,
    })
}

/// Replaces every spike's points by the straight line between the nearest points outside it
/// (at an end of the line, by the nearest point's height). Returns how many points changed.
pub fn bridge(heights_um: &mut [f64], spikes: &[Spike]) -> usize {
    let n = heights_um.len();
    let mut changed = 0;
    for s in spikes {
        if s.first > s.last || s.last >= n {
            continue;
        }
        let left = s.first.checked_sub(1);
        let right = (s.last + 1 < n).then_some(s.last + 1);
        for i in s.first..=s.last {
            let value = match (left, right) {
                (Some(a), Some(b)) => {
                    let t = (i - a) as f64 / (b - a) as f64;
                    heights_um[a] + t * (heights_um[b] - heights_um[a])
                }
                (Some(a), None) => heights_um[a],
                (None, Some(b)) => heights_um[b],
                (None, None) => continue,
            };
            heights_um[i] = value;
            changed += 1;
        }
    }
    changed
}

/// A spike with the line it was found on, as the report lists it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LineSpike {
    /// Line index (a scan's `NNNN`, a grid's row).
    pub line: u32,
    /// The spike.
    #[serde(flatten)]
    pub spike: Spike,
}

/// The spikes of every line of `grid` (named by their index, at their x in its coordinates),
/// judged on each line's roughness profile ([`spike_roughness`] with `lambda_c_mm`). A line
/// that cannot be judged (e.g. shorter than the filter needs) is named in the second list.
pub fn find_grid_spikes(
    grid: &Grid,
    lambda_c_mm: Option<f64>,
    options: &SpikeOptions,
) -> (Vec<LineSpike>, Vec<(u32, String)>) {
    let pitch_mm = grid.pitch_x_mm;
    // Lines are independent: they are judged in parallel.
    let rows: Vec<&[f64]> = grid.heights_um.chunks(grid.cols.max(1)).collect();
    let judged = super::map_in_parallel(
        &rows,
        |row, z| {
            let found = spike_roughness(z, pitch_mm, lambda_c_mm)
                .and_then(|r| find_spikes(&r, z, pitch_mm, options))
                .map_err(|e| e.to_string());
            (grid.index_of(row), found)
        },
        |row| {
            let reason = "internal: the spike check panicked; report this with the input";
            (grid.index_of(row), Err(reason.to_string()))
        },
    );
    let mut spikes = Vec::new();
    let mut failed = Vec::new();
    for (line, found) in judged {
        match found {
            Ok(s) => spikes.extend(s.spikes.into_iter().map(|spike| LineSpike { line, spike })),
            Err(e) => failed.push((line, e)),
        }
    }
    // Where the grid places them: its lines start at its x0.
    (spikes.iter_mut()).for_each(|s| s.spike.x_mm = grid.x_mm(s.spike.peak));
    (spikes, failed)
}

/// A copy of `grid` with every spike of `spikes` bridged ([`bridge`]), found by the index of
/// its line. Returns the grid and how many points changed.
pub fn bridged_grid(grid: &Grid, spikes: &[LineSpike]) -> (Grid, usize) {
    let mut out = Grid {
        heights_um: grid.heights_um.clone(),
        ..grid.layout()
    };
    let mut changed = 0;
    for (row, z) in out.heights_um.chunks_mut(grid.cols.max(1)).enumerate() {
        let line = grid.index_of(row);
        let mine: Vec<Spike> = spikes
            .iter()
            .filter(|s| s.line == line)
            .map(|s| s.spike.clone())
            .collect();
        changed += bridge(z, &mine);
    }
    (out, changed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic rough line: sum of incommensurate sines, Sq about 1 µm.
    fn rough(n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let x = i as f64;
                (x * 0.071).sin() + 0.6 * (x * 0.193 + 1.0).sin() + 0.4 * (x * 0.517 + 2.0).sin()
            })
            .collect()
    }

    #[test]
    fn a_three_point_spike_is_found_and_a_smooth_line_has_none() {
        let mut z = rough(2000);
        let clean = find_spikes(&z, &z, 0.0015, &SpikeOptions::default()).unwrap();
        assert!(clean.spikes.is_empty(), "{:?}", clean.spikes);
        for (k, h) in [(1000, 60.0), (1001, 100.0), (1002, 70.0)] {
            z[k] += h;
        }
        let r = spike_roughness(&z, 0.0015, None).unwrap();
        let s = find_spikes(&r, &z, 0.0015, &SpikeOptions::default()).unwrap();
        assert_eq!(s.spikes.len(), 1, "{s:?}");
        let sp = &s.spikes[0];
        assert_eq!((sp.first, sp.peak, sp.last), (1000, 1001, 1002));
        assert!((sp.x_mm - 1.5015).abs() < 1e-12);
        assert!((sp.height_um - z[1001]).abs() < 1e-12);
        assert!(sp.deviation_sigma > 50.0, "{sp:?}");
    }

    #[test]
    fn a_wide_excursion_is_a_feature_not_a_spike() {
        let mut z = rough(2000);
        for v in &mut z[500..520] {
            *v -= 40.0;
        }
        let s = find_spikes(&z, &z, 0.001, &SpikeOptions::default()).unwrap();
        assert!(s.spikes.is_empty());
        assert_eq!(s.long_runs, 1);
    }

    #[test]
    fn sigma_is_robust_and_falls_back_when_mad_is_zero() {
        // Gaussian-like spread unaffected by a few huge values.
        let mut z = rough(4000);
        let before = find_spikes(&z, &z, 0.001, &SpikeOptions::default())
            .unwrap()
            .sigma_um;
        z[100] = 1e4;
        z[2000] = -1e4;
        let after = find_spikes(&z, &z, 0.001, &SpikeOptions::default()).unwrap();
        assert!((after.sigma_um - before).abs() < 0.01 * before);
        assert_eq!(after.spikes.len(), 2);
        // Mostly-equal (quantised) ordinates: MAD = 0, the mean absolute deviation is used.
        let mut q = vec![0.0; 100];
        q[10] = 1.0;
        q[50] = 50.0;
        let s = find_spikes(&q, &q, 0.001, &SpikeOptions::default()).unwrap();
        assert!((s.sigma_um - MEAN_ABS_TO_SIGMA * 51.0 / 100.0).abs() < 1e-12);
        assert_eq!(s.spikes.len(), 1);
        assert_eq!(s.spikes[0].peak, 50);
        // All equal: nothing to find.
        let s = find_spikes(&[2.0; 50], &[2.0; 50], 0.001, &SpikeOptions::default()).unwrap();
        assert!(s.spikes.is_empty() && s.sigma_um == 0.0);
    }

    #[test]
    fn bridging_draws_the_line_between_the_neighbours() {
        let mut z = vec![0.0, 1.0, 50.0, 60.0, 4.0, 5.0];
        let spike = Spike {
            first: 2,
            last: 3,
            peak: 3,
            x_mm: 0.0,
            height_um: 60.0,
            deviation_um: 0.0,
            deviation_sigma: 0.0,
        };
        assert_eq!(bridge(&mut z, std::slice::from_ref(&spike)), 2);
        assert_eq!(z, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        let mut e = vec![90.0, 1.0, 2.0];
        let at_start = Spike {
            first: 0,
            last: 0,
            ..spike
        };
        bridge(&mut e, &[at_start]);
        assert_eq!(e, vec![1.0, 1.0, 2.0]);
    }

    #[test]
    fn grid_spikes_are_named_by_line_and_bridged_in_a_copy() {
        let cols = 500;
        let mut z: Vec<f64> = (0..3).flat_map(|_| rough(cols)).collect();
        z[cols + 200] += 80.0;
        let grid = Grid {
            index: vec![7, 8, 9],
            ..Grid::new(z.clone(), cols, 0.001, vec![0.0, 0.01, 0.02])
        };
        let (spikes, failed) = find_grid_spikes(&grid, None, &SpikeOptions::default());
        assert!(failed.is_empty());
        assert_eq!(spikes.len(), 1);
        assert_eq!((spikes[0].line, spikes[0].spike.peak), (8, 200));
        let (bridged, changed) = bridged_grid(&grid, &spikes);
        let bridged = bridged.heights_um;
        assert_eq!(changed, 1);
        assert_eq!(bridged[cols + 200], 0.5 * (z[cols + 199] + z[cols + 201]));
        assert!(z[cols + 200] - bridged[cols + 200] > 70.0);
        // A line too short for its filter is named, not dropped silently.
        let (_, failed) = find_grid_spikes(&grid, Some(f64::NAN), &SpikeOptions::default());
        assert_eq!(failed.len(), 3);
    }

    /// The parallel judgement gives what judging the lines one by one in row order gives: the
    /// same spikes under the same line names, the failures in line order.
    #[test]
    fn grid_spikes_in_parallel_are_the_lines_judged_one_by_one() {
        let cols = 700;
        let rows = 7;
        let mut z: Vec<f64> = (0..rows)
            .flat_map(|r| rough(cols + r).into_iter().take(cols))
            .collect();
        z[cols + 100] += 90.0;
        z[4 * cols + 650] -= 70.0;
        z[6 * cols + 3] += 60.0;
        z[6 * cols + 400] += 60.0;
        z[3 * cols + 10] = f64::NAN;
        z[5 * cols + 20] = f64::INFINITY;
        let index: Vec<u32> = (0..rows as u32).map(|r| 40 + 2 * r).collect();
        let options = SpikeOptions::default();
        let grid = Grid {
            index: index.clone(),
            ..Grid::new(z.clone(), cols, 0.001, vec![0.0; rows])
        };
        let (spikes, failed) = find_grid_spikes(&grid, None, &options);
        let mut want_spikes = Vec::new();
        let mut want_failed = Vec::new();
        for (row, line) in z.chunks(cols).zip(index.iter().copied()) {
            match spike_roughness(row, 0.001, None)
                .and_then(|r| find_spikes(&r, row, 0.001, &options))
            {
                Ok(s) => {
                    want_spikes.extend(s.spikes.into_iter().map(|spike| LineSpike { line, spike }))
                }
                Err(e) => want_failed.push((line, e.to_string())),
            }
        }
        assert_eq!(spikes, want_spikes);
        assert_eq!(failed, want_failed);
        let named: Vec<u32> = spikes.iter().map(|s| s.line).collect();
        assert_eq!(named, vec![42, 48, 52, 52]);
        let failed_lines: Vec<u32> = failed.iter().map(|f| f.0).collect();
        assert_eq!(failed_lines, vec![46, 50]);
    }

    #[test]
    fn least_squares_line_is_removed_without_a_filter() {
        let z: Vec<f64> = (0..100).map(|i| 3.0 + 0.5 * i as f64).collect();
        let r = spike_roughness(&z, 0.001, None).unwrap();
        assert!(r.iter().all(|v| v.abs() < 1e-10), "{r:?}");
        let bad = SpikeOptions {
            threshold_sigma: 0.0,
            ..SpikeOptions::default()
        };
        assert!(find_spikes(&r, &z, 0.001, &bad).is_err());
    }

    /// The median by selection is the sorted sequence's middle (or the mean of its two middle
    /// values) to the bit: odd and even lengths, repeated values, both zeros, negative values.
    #[test]
    fn median_by_selection_is_the_sorted_median_to_the_bit() {
        let sorted_median = |v: &[f64]| {
            let mut s = v.to_vec();
            s.sort_by(f64::total_cmp);
            let n = s.len();
            if n % 2 == 1 {
                s[n / 2]
            } else {
                0.5 * (s[n / 2 - 1] + s[n / 2])
            }
        };
        let mut s = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || (crate::metrology::lcg(&mut s) * (1u64 << 53) as f64) as u64;
        for n in (1..40).chain([999, 1000, 8000, 8001]) {
            for round in 0..20 {
                let v: Vec<f64> = (0..n)
                    .map(|_| {
                        let r = next();
                        match round % 4 {
                            // Few distinct values: many ties around the middle.
                            0 => (r % 5) as f64 - 2.0,
                            // Both zeros among the ties.
                            1 => [0.0, -0.0, 1.0, -1.0][(r % 4) as usize],
                            _ => r as f64 / (1u64 << 53) as f64 * 20.0 - 10.0,
                        }
                    })
                    .collect();
                let want = sorted_median(&v);
                let got = median(&mut v.clone());
                assert_eq!(got.to_bits(), want.to_bits(), "n {n}, round {round}");
            }
        }
        assert_eq!(median(&mut []), 0.0);
    }
}
