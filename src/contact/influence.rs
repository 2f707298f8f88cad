//! The influence coefficient of the elastic half-space: the normal surface displacement at a
//! point due to a uniform unit pressure on one rectangular pixel (Love 1929; Johnson,
//! *Contact Mechanics*, 1985, §3.2). It is the kernel the boundary-element solver convolves
//! the pixel pressures with.
//!
//! The textbook form is a sum of four `s·ln((t + √(t² + s²)) / (t' + √(t'² + s²)))` terms;
//! far from the pixel each logarithm's argument is a ratio of two nearly equal sums or of a
//! sum and a difference that cancels, so it is evaluated here through the identity
//! `ln(t + √(t² + s²)) = ln|s| + asinh(t/|s|)`, in which the `ln|s|` parts of each pair cancel
//! exactly and `asinh` stays accurate for every sign of `t`.
//!
//! Layer 1 (pure logic): numbers in, numbers out; depends on nothing else in the crate.

/// `s · asinh(t / |s|)`, which tends to 0 as `s` → 0 for every `t`.
fn term(s: f64, t: f64) -> f64 {
    if s == 0.0 {
        0.0
    } else {
        s * (t / s.abs()).asinh()
    }
}

/// Displacement (in the length unit of the arguments) at offset (`x`, `y`) from the centre of
/// a `dx` × `dy` pixel carrying a uniform pressure of 1 on an elastic half-space of composite
/// modulus 1: multiply by `pressure / E*` (same pressure unit as `E*`).
pub fn pixel_displacement(x: f64, y: f64, dx: f64, dy: f64) -> f64 {
    let (a, b) = (dx / 2.0, dy / 2.0);
    let sum = term(x + a, y + b) - term(x + a, y - b) + term(y + b, x + a) - term(y + b, x - a)
        + term(x - a, y - b)
        - term(x - a, y + b)
        + term(y - b, x - a)
        - term(y - b, x + a);
    sum / std::f64::consts::PI
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The centre of a square pixel of side 2a sinks by (4/π)·ln(1 + √2)·(2a)·p/E*, about
    /// 2.24·p·a/E* (Johnson, eq. 3.31 with the centre of the square).
    #[test]
    fn centre_of_a_square_pixel_matches_johnson() {
        let side = 2.0;
        let expect = 4.0 / std::f64::consts::PI * (1.0 + 2f64.sqrt()).ln() * side;
        assert!((pixel_displacement(0.0, 0.0, side, side) - expect).abs() < 1e-14);
        assert!((expect / (side / 2.0) - 2.244).abs() < 1e-3);
    }

    /// Far from the pixel the load acts as a point force F = p·dx·dy, and Boussinesq's
    /// displacement is F/(π E* r).
    #[test]
    fn far_field_is_boussinesq() {
        let (dx, dy) = (0.5, 10.0);
        for &(x, y) in &[
            (3000.0, 0.0),
            (0.0, 5000.0),
            (-2000.0, 2500.0),
            (40000.0, -1.0),
        ] {
            let r: f64 = f64::hypot(x, y);
            let point = dx * dy / (std::f64::consts::PI * r);
            let got = pixel_displacement(x, y, dx, dy);
            assert!(
                ((got - point) / point).abs() < 1e-5,
                "({x}, {y}): {got} vs {point}"
            );
        }
    }

    /// The kernel is even in x and in y, and swapping the axes swaps the pixel's sides.
    #[test]
    fn symmetric_in_both_axes_and_under_transposition() {
        let (dx, dy) = (0.7, 3.1);
        for &(x, y) in &[(0.35, 0.0), (2.0, 1.55), (10.0, -7.0), (0.0, 40.0)] {
            let v = pixel_displacement(x, y, dx, dy);
            assert!((pixel_displacement(-x, y, dx, dy) - v).abs() <= 1e-14 * v.abs().max(1.0));
            assert!((pixel_displacement(x, -y, dx, dy) - v).abs() <= 1e-14 * v.abs().max(1.0));
            assert!((pixel_displacement(y, x, dy, dx) - v).abs() <= 1e-13 * v.abs().max(1.0));
        }
    }
}
