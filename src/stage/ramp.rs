//! How long a move takes: a trapezoidal speed profile (accelerate at a constant rate to the
//! feed, cruise, decelerate to rest), as the controllers' planners run a lone move. Used to
//! poll a moving stage again when it should have arrived, not a fixed interval later.
//!
//! Pure (layer 1): numbers in, a duration out.

use std::time::Duration;

/// How late after the planned end of a move its status is polled: the USB round trip and the
/// stepper's last segment.
pub const POLL_MARGIN: Duration = Duration::from_millis(5);
/// The shortest wait between two polls of a move that is still running.
pub const MIN_POLL_GAP: Duration = Duration::from_millis(20);

/// Time to cover `distance` (mm, ≥ 0) from speed `v0` (mm/s) to rest, cruising at no more
/// than `feed` (mm/s), with acceleration `accel` (mm/s²; `None` or not positive: no ramp,
/// `distance / feed`). Zero for an empty move or a feed that is not positive, and (see
/// [`estimate`]) for one longer than [`LONGEST_ESTIMATE`].
pub fn move_time(distance: f64, v0: f64, feed: f64, accel: Option<f64>) -> Duration {
    estimate(move_secs(distance, v0, feed, accel))
}

/// Time to brake from `speed` (mm/s) to rest at `accel` (mm/s²): `speed / accel`; zero
/// without a positive acceleration, and (see [`estimate`]) for one longer than
/// [`LONGEST_ESTIMATE`].
pub fn braking_time(speed: f64, accel: Option<f64>) -> Duration {
    accel
        .filter(|a| a.is_finite() && *a > 0.0)
        .map_or(Duration::ZERO, |a| estimate(speed / a))
}

/// The longest time a move or a stop is predicted to take. A controller's reply can carry any
/// number (a `$121` or `$111` of 1e-17 parses), and a prediction is added to the clock: one
/// of 10¹⁹ s would overflow it.
pub const LONGEST_ESTIMATE: Duration = Duration::from_secs(30 * 24 * 3600);

/// `secs` as a duration; zero (no prediction: the stage is polled at once, and the move's own
/// deadline still bounds the wait) when it is not a number, negative or beyond
/// [`LONGEST_ESTIMATE`].
fn estimate(secs: f64) -> Duration {
    Duration::try_from_secs_f64(secs)
        .ok()
        .filter(|d| *d <= LONGEST_ESTIMATE)
        .unwrap_or(Duration::ZERO)
}

fn move_secs(d: f64, v0: f64, feed: f64, accel: Option<f64>) -> f64 {
    if !(d.is_finite() && d > 0.0 && feed.is_finite() && feed > 0.0) {
        return 0.0;
    }
    let v0 = if v0.is_finite() { v0.max(0.0) } else { 0.0 };
    let Some(a) = accel.filter(|a| a.is_finite() && *a > 0.0) else {
        return d / feed;
    };
    if v0 * v0 >= 2.0 * a * d {
        // Already braking for the end: straight down to rest over d.
        return 2.0 * d / v0;
    }
    let vmax = feed.max(v0);
    let peak = vmax.min(((2.0 * a * d + v0 * v0) / 2.0).sqrt());
    let d_ramps = (peak * peak - v0 * v0) / (2.0 * a) + peak * peak / (2.0 * a);
    (peak - v0) / a + peak / a + (d - d_ramps).max(0.0) / peak
}

#[cfg(test)]
mod tests {
    use super::*;

    fn secs(d: f64, v0: f64, feed: f64, a: Option<f64>) -> f64 {
        move_time(d, v0, feed, a).as_secs_f64()
    }

    #[test]
    fn a_scan_step_is_a_triangle_dominated_by_the_ramp() {
        // 0.01 mm at 1 mm/s (60 mm/min) and 10 mm/s²: it never reaches the feed; peak
        // sqrt(a d) = 0.316 mm/s, 2·sqrt(d/a) = 63.2 ms, six times d/feed.
        assert!((secs(0.01, 0.0, 1.0, Some(10.0)) - 0.063_245_553).abs() < 1e-6);
        assert!((secs(0.01, 0.0, 1.0, None) - 0.01).abs() < 1e-12);
    }

    #[test]
    fn a_long_move_adds_one_ramp_time_to_distance_over_feed() {
        // 10 mm at 1 mm/s, 10 mm/s²: 0.1 s ramps covering 0.05 mm each → 10 + 0.1 s.
        assert!((secs(10.0, 0.0, 1.0, Some(10.0)) - 10.1).abs() < 1e-9);
    }

    #[test]
    fn from_speed_it_is_the_remaining_cruise_plus_the_stop() {
        // At 1 mm/s with 1 mm left: 0.95 mm cruise + 0.1 s stop over 0.05 mm.
        assert!((secs(1.0, 1.0, 1.0, Some(10.0)) - 1.05).abs() < 1e-9);
        // Already braking: 0.05 mm left at 1 mm/s stops in 0.1 s.
        assert!((secs(0.05, 1.0, 1.0, Some(10.0)) - 0.1).abs() < 1e-9);
    }

    #[test]
    fn nonsense_is_zero_not_a_panic() {
        for (d, v0, f, a) in [
            (0.0, 0.0, 1.0, Some(1.0)),
            (-1.0, 0.0, 1.0, Some(1.0)),
            (1.0, 0.0, 0.0, Some(1.0)),
            (f64::NAN, 0.0, 1.0, None),
            (1.0, f64::NAN, 1.0, Some(f64::INFINITY)),
        ] {
            let t = move_time(d, v0, f, a);
            assert!(t <= Duration::from_secs(1), "{d} {v0} {f} {a:?}: {t:?}");
        }
        assert_eq!(move_time(1e300, 0.0, 1e-300, None), Duration::ZERO);
    }

    /// Settings a controller's reply may carry: whatever they are, the prediction can be
    /// added to the clock. 10 mm at a feed of 1e-18 mm/s (a `$111` of 6e-17 mm/min) would be
    /// 10¹⁹ s, a representable duration that overflows an `Instant`.
    #[test]
    fn a_prediction_from_absurd_settings_is_zero_and_never_overflows_the_clock() {
        let now = std::time::Instant::now();
        for t in [
            move_time(10.0, 0.0, 1e-18, None),
            move_time(10.0, 0.0, 1e-18, Some(1e-300)),
            move_time(10.0, 1e-9, 1.0, Some(1e-30)),
            braking_time(1666.0, Some(1e-300)),
            braking_time(1666.0, Some(1e-16)),
        ] {
            assert_eq!(t, Duration::ZERO);
            let _ = now + t;
        }
        assert_eq!(braking_time(1.0, Some(10.0)), Duration::from_millis(100));
        assert_eq!(braking_time(1.0, Some(0.0)), Duration::ZERO);
        assert_eq!(braking_time(1.0, None), Duration::ZERO);
        // Thirty days is still a prediction; a second more is none.
        assert_eq!(braking_time(2_592_000.0, Some(1.0)), LONGEST_ESTIMATE);
        assert_eq!(braking_time(2_592_001.0, Some(1.0)), Duration::ZERO);
    }
}
