//! The simulator's own, deliberately simple roughness calculation for `RDRES` answers.
//!
//! Simplified on purpose (it is not ISO 4287 nor the daemon's metrology): no filtering, no form
//! removal; the mean line is zero for an R profile (served as the instrument exports it,
//! already relative to its filter mean line) and otherwise the arithmetic mean of the whole
//! profile as served; Ra, Rq, Rsk and Rku are taken about that line over the whole profile; Rz,
//! Rp and Rv are means over N equal sampling lengths of (highest − lowest), highest and
//! −lowest; Rz1max the largest sampling length's Rz; Rt highest − lowest over the whole profile.
//! Per-sampling-length values (`bb` = 1..N) use the same mean line.
//! Pure; depends on nothing.

/// The customised parameters reported, in `RDRES aa` order (1-based): name and unit, as an
/// SJ-210 with a typical customised set prints them.
pub const PARAMETERS: [(&str, &str); 9] = [
    ("Ra", "um"),
    ("Rq", "um"),
    ("Rz", "um"),
    ("Rp", "um"),
    ("Rv", "um"),
    ("Rt", "um"),
    ("Rsk", ""),
    ("Rku", ""),
    ("Rz1max", "um"),
];

/// The parameters for the whole profile and per sampling length, in [`PARAMETERS`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct Roughness {
    /// Values over the evaluation length.
    pub total: [f64; 9],
    /// Values per sampling length.
    pub per_segment: Vec<[f64; 9]>,
}

/// Ra, Rq, Rz, Rp, Rv, Rt, Rsk, Rku, Rz1max of one stretch about `mean` (Rz1max = Rz here).
fn stats(z: &[f64], mean: f64) -> [f64; 9] {
    if z.is_empty() {
        return [0.0; 9];
    }
    let n = z.len() as f64;
    let ra = z.iter().map(|v| (v - mean).abs()).sum::<f64>() / n;
    let m2 = z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let rq = m2.sqrt();
    let m3 = z.iter().map(|v| (v - mean).powi(3)).sum::<f64>() / n;
    let m4 = z.iter().map(|v| (v - mean).powi(4)).sum::<f64>() / n;
    let (rsk, rku) = if rq > 0.0 {
        (m3 / rq.powi(3), m4 / m2.powi(2))
    } else {
        (0.0, 0.0)
    };
    let hi = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let lo = z.iter().copied().fold(f64::INFINITY, f64::min);
    let (rp, rv) = (hi - mean, mean - lo);
    [ra, rq, hi - lo, rp, rv, hi - lo, rsk, rku, hi - lo]
}

impl Roughness {
    /// Computes the parameters of `z_um` with `segments` (≥ 1) sampling lengths, about a
    /// mean line at zero (`about_zero`, an R profile) or at the profile's arithmetic mean.
    /// Over the evaluation length: Ra, Rq, Rsk, Rku of the whole profile; Rz, Rp, Rv the
    /// mean of the sampling lengths' values; Rz1max their largest Rz; Rt highest − lowest.
    pub fn compute(z_um: &[f64], segments: usize, about_zero: bool) -> Self {
        let segments = segments.max(1);
        let mean = if z_um.is_empty() || about_zero {
            0.0
        } else {
            z_um.iter().sum::<f64>() / z_um.len() as f64
        };
        let n = z_um.len();
        let per_segment: Vec<[f64; 9]> = (0..segments)
            .map(|k| {
                let a = k * n / segments;
                let b = (k + 1) * n / segments;
                stats(z_um.get(a..b).unwrap_or(&[]), mean)
            })
            .collect();
        let mut total = stats(z_um, mean);
        let avg = |i: usize| per_segment.iter().map(|s| s[i]).sum::<f64>() / segments as f64;
        total[2] = avg(2);
        total[3] = avg(3);
        total[4] = avg(4);
        total[8] = per_segment
            .iter()
            .map(|s| s[2])
            .fold(f64::NEG_INFINITY, f64::max);
        Self { total, per_segment }
    }

    /// Value of parameter `param` (0-based) for `index` 0 (whole) or 1..=N (sampling length).
    pub fn value(&self, param: usize, index: usize) -> Option<f64> {
        if index == 0 {
            self.total.get(param).copied()
        } else {
            self.per_segment.get(index - 1)?.get(param).copied()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_wave_closed_forms() {
        // ±a square wave: Ra = Rq = a; Rz = 2a per segment.
        let z: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 1.5 } else { -1.5 })
            .collect();
        let r = Roughness::compute(&z, 5, false);
        assert_eq!(Roughness::compute(&z, 5, true), r);
        assert!((r.total[0] - 1.5).abs() < 1e-12);
        assert!((r.total[1] - 1.5).abs() < 1e-12);
        assert!((r.total[2] - 3.0).abs() < 1e-12);
        assert_eq!(r.per_segment.len(), 5);
        assert_eq!(r.value(2, 5), Some(3.0));
        assert_eq!(r.value(2, 6), None);
        // Rp = Rv = a, Rt = Rz1max = 2a, Rsk = 0, Rku = 1 for a symmetric two-level wave.
        assert!((r.total[3] - 1.5).abs() < 1e-12 && (r.total[4] - 1.5).abs() < 1e-12);
        assert!((r.total[5] - 3.0).abs() < 1e-12 && (r.total[8] - 3.0).abs() < 1e-12);
        assert!(r.total[6].abs() < 1e-12 && (r.total[7] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rz_averages_segment_peak_to_valley_and_offset_is_ignored() {
        // Segment 1: 10 + {0,2} (pv 2); segment 2: 10 + {0,6} (pv 6) → Rz 4; mean 12,
        // deviations -2,0,-2,4 → Ra = 2, Rq = sqrt(6).
        let r = Roughness::compute(&[10.0, 12.0, 10.0, 16.0], 2, false);
        assert!((r.total[2] - 4.0).abs() < 1e-12);
        // Rt over the whole profile is 6, Rz1max the larger segment's 6; Rp = mean(0, 4) = 2.
        assert!((r.total[5] - 6.0).abs() < 1e-12 && (r.total[8] - 6.0).abs() < 1e-12);
        assert!((r.total[3] - 2.0).abs() < 1e-12);
        assert!((r.total[0] - 2.0).abs() < 1e-12);
        assert!((r.total[1] - 6f64.sqrt()).abs() < 1e-12);
        // About a zero mean line (an R profile) the offset counts: Ra = 12, Rz unchanged.
        let r = Roughness::compute(&[10.0, 12.0, 10.0, 16.0], 2, true);
        assert!((r.total[0] - 12.0).abs() < 1e-12);
        assert!((r.total[2] - 4.0).abs() < 1e-12);
    }
}
