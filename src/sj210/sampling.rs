//! How the exported profile is sampled along x: the pitch the instrument uses for a λs.
//!
//! Pure (layer 1): numbers in, numbers out; depends on nothing in the crate.

/// The exported profile's x pitch in µm for a λs in µm (2.5 → 0.5, 8 → 1, 25 → 5), `None`
/// for any other λs. C3's mapping, confirmed for 2.5 µm by SJ-410 memory-card files (C4).
pub fn pitch_from_lambda_s(lambda_s_um: f64) -> Option<f64> {
    [(2.5, 0.5), (8.0, 1.0), (25.0, 5.0)]
        .into_iter()
        .find(|(ls, _)| (lambda_s_um - ls).abs() < 1e-9)
        .map(|(_, p)| p)
}
