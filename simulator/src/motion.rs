//! Trapezoidal motion profiles for the simulated stages: accelerate at a constant rate up to a
//! peak speed, cruise, decelerate to rest exactly at the end of the distance. The GRBL planner
//! and a Zaber axis both move this way (a lone block or move ends at rest), so the simulators'
//! positions and reported speeds ramp as the real ones do.
//!
//! Pure: numbers in, numbers out, in whatever length unit the caller uses (steps, microsteps).
//! Time is in seconds of simulated time.

/// One motion from a start speed to rest over a fixed distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    distance: f64,
    v0: f64,
    peak: f64,
    accel: f64,
    decel: f64,
    t_accel: f64,
    t_cruise: f64,
    t_decel: f64,
    d_accel: f64,
    d_cruise: f64,
}

impl Profile {
    /// A move over `distance` (≥ 0) starting at speed `v0` (≥ 0), cruising at no more than
    /// `max_speed`, with acceleration `accel` (> 0; units per s²). When the distance is too
    /// short to stop from `v0` at `accel`, the deceleration is raised so that it still stops
    /// at the end. Non-finite or non-positive rates are treated as an instantaneous move.
    pub fn new(distance: f64, v0: f64, max_speed: f64, accel: f64) -> Profile {
        let d = if distance.is_finite() {
            distance.max(0.0)
        } else {
            0.0
        };
        let v0 = if v0.is_finite() { v0.max(0.0) } else { 0.0 };
        let usable = max_speed.is_finite() && max_speed > 0.0 && accel.is_finite() && accel > 0.0;
        if d == 0.0 || !usable {
            return Profile {
                distance: d,
                v0,
                peak: 0.0,
                accel: 1.0,
                decel: 1.0,
                t_accel: 0.0,
                t_cruise: 0.0,
                t_decel: 0.0,
                d_accel: 0.0,
                d_cruise: 0.0,
            };
        }
        // Too close to stop from v0 at `accel`: brake harder, straight down to rest.
        if v0 * v0 >= 2.0 * accel * d {
            let decel = v0 * v0 / (2.0 * d);
            return Profile {
                distance: d,
                v0,
                peak: v0,
                accel,
                decel,
                t_accel: 0.0,
                t_cruise: 0.0,
                t_decel: v0 / decel,
                d_accel: 0.0,
                d_cruise: 0.0,
            };
        }
        let vmax = max_speed.max(v0);
        // Triangle peak: (peak² − v0²)/2a + peak²/2a = d.
        let peak = vmax.min(((2.0 * accel * d + v0 * v0) / 2.0).sqrt());
        let d_accel = (peak * peak - v0 * v0) / (2.0 * accel);
        let d_decel = peak * peak / (2.0 * accel);
        let d_cruise = (d - d_accel - d_decel).max(0.0);
        Profile {
            distance: d,
            v0,
            peak,
            accel,
            decel: accel,
            t_accel: (peak - v0) / accel,
            t_cruise: d_cruise / peak,
            t_decel: peak / accel,
            d_accel,
            d_cruise,
        }
    }

    /// Total distance.
    pub fn distance(&self) -> f64 {
        self.distance
    }

    /// Time until rest, s.
    pub fn duration(&self) -> f64 {
        self.t_accel + self.t_cruise + self.t_decel
    }

    /// Distance covered after `t` seconds (clamped to the move).
    pub fn position(&self, t: f64) -> f64 {
        if t <= 0.0 {
            return 0.0;
        }
        if t >= self.duration() {
            return self.distance;
        }
        if t < self.t_accel {
            return self.v0 * t + self.accel * t * t / 2.0;
        }
        let t = t - self.t_accel;
        if t < self.t_cruise {
            return self.d_accel + self.peak * t;
        }
        let t = t - self.t_cruise;
        (self.d_accel + self.d_cruise + self.peak * t - self.decel * t * t / 2.0).min(self.distance)
    }

    /// Speed after `t` seconds (0 before the start and after the end).
    pub fn speed(&self, t: f64) -> f64 {
        if t < 0.0 || t >= self.duration() {
            return 0.0;
        }
        if t < self.t_accel {
            return self.v0 + self.accel * t;
        }
        let t = t - self.t_accel;
        if t < self.t_cruise {
            return self.peak;
        }
        (self.peak - self.decel * (t - self.t_cruise)).max(0.0)
    }

    /// The time at which `dist` (0 ≤ dist ≤ distance) has been covered.
    pub fn time_at(&self, dist: f64) -> f64 {
        if dist <= 0.0 {
            return 0.0;
        }
        if dist >= self.distance {
            return self.duration();
        }
        if dist <= self.d_accel {
            // v0 t + a t²/2 = dist
            let disc = (self.v0 * self.v0 + 2.0 * self.accel * dist).max(0.0);
            return (disc.sqrt() - self.v0) / self.accel;
        }
        if dist <= self.d_accel + self.d_cruise {
            return self.t_accel + (dist - self.d_accel) / self.peak;
        }
        // peak τ − decel τ²/2 = x
        let x = dist - self.d_accel - self.d_cruise;
        let disc = (self.peak * self.peak - 2.0 * self.decel * x).max(0.0);
        self.t_accel + self.t_cruise + (self.peak - disc.sqrt()) / self.decel
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_move_is_a_trapezoid() {
        // 10 mm at 1 mm/s with 10 mm/s²: 0.1 s ramps of 0.05 mm each, 9.9 mm cruise.
        let p = Profile::new(10.0, 0.0, 1.0, 10.0);
        assert!((p.duration() - (0.1 + 9.9 + 0.1)).abs() < 1e-12);
        assert!((p.position(0.1) - 0.05).abs() < 1e-12);
        assert!((p.speed(0.05) - 0.5).abs() < 1e-12);
        assert!((p.speed(5.0) - 1.0).abs() < 1e-12);
        assert!((p.position(10.0) - 9.95).abs() < 1e-12);
        assert_eq!(p.position(11.0), 10.0);
        assert_eq!(p.speed(11.0), 0.0);
    }

    #[test]
    fn short_move_is_a_triangle() {
        // 0.01 mm at 10 mm/s²: peak sqrt(a d) = sqrt(0.1), duration 2 sqrt(d/a) = 0.0632 s.
        let p = Profile::new(0.01, 0.0, 1.0, 10.0);
        assert!((p.duration() - 2.0 * (0.001f64).sqrt()).abs() < 1e-12);
        assert!((p.speed(p.duration() / 2.0) - 0.1f64.sqrt()).abs() < 1e-9);
        assert!((p.position(p.duration() / 2.0) - 0.005).abs() < 1e-12);
    }

    #[test]
    fn stopping_from_speed_takes_v_squared_over_2a() {
        let p = Profile::new(0.05, 1.0, 1.0, 10.0);
        assert!((p.duration() - 0.1).abs() < 1e-12);
        assert!((p.position(0.05) - (0.05 - 10.0 * 0.05 * 0.05 / 2.0)).abs() < 1e-12);
        // Too short to stop at 10 mm/s²: braked harder, still ends at rest on the distance.
        let p = Profile::new(0.01, 1.0, 1.0, 10.0);
        assert!((p.duration() - 0.02).abs() < 1e-12);
        assert_eq!(p.position(1.0), 0.01);
    }

    #[test]
    fn time_at_inverts_position_in_every_phase() {
        for p in [
            Profile::new(10.0, 0.0, 1.0, 10.0),
            Profile::new(0.01, 0.0, 1.0, 10.0),
            Profile::new(0.05, 1.0, 1.0, 10.0),
        ] {
            for k in 1..50 {
                let d = p.distance() * k as f64 / 50.0;
                let t = p.time_at(d);
                assert!((p.position(t) - d).abs() < 1e-9, "{p:?} at {d}");
            }
        }
    }

    #[test]
    fn degenerate_inputs_are_instant() {
        for p in [
            Profile::new(0.0, 0.0, 1.0, 10.0),
            Profile::new(5.0, 0.0, 0.0, 10.0),
            Profile::new(5.0, 0.0, 1.0, f64::NAN),
            Profile::new(f64::INFINITY, 0.0, 1.0, 10.0),
        ] {
            assert_eq!(p.duration(), 0.0, "{p:?}");
            assert_eq!(p.position(1.0), p.distance());
        }
    }
}
