//! What more than one benchmark needs: the median of a sample and a rough synthetic profile.
//! Included by path (`#[path = "shared/mod.rs"] mod shared;`): each benchmark is its own crate.

#![allow(dead_code)]

/// The median of `v` (sorted in place); the mean of the middle two for an even count.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// A rough profile of `n` heights within ±150 µm, 3 decimals, every one printed in the
/// simulator's 9-character field (a deterministic sum of sines, no randomness).
pub fn rough_heights_um(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let x = i as f64;
            let z = 80.0 * (x * 0.013).sin() + 40.0 * (x * 0.171).sin() + 9.0 * (x * 1.37).cos();
            (z * 1000.0).round() / 1000.0
        })
        .collect()
}
