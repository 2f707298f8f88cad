//! GRBL's settings store: numbers, defaults, the `$$` listing and `$N=value` writes with the
//! firmware's checks.
//!
//! Pure; depends only on [`super::GrblSimConfig`].

use super::GrblSimConfig;

/// GRBL's settings, numbered as `$$` prints them.
#[derive(Debug, Clone)]
pub(super) struct Settings(std::collections::BTreeMap<u16, f64>);

/// Settings printed as integers.
const INT_SETTINGS: [u16; 15] = [0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 32];
/// Spindle rpm settings (printed without decimals).
const RPM_SETTINGS: [u16; 2] = [30, 31];

impl Settings {
    /// GRBL 1.1's generic defaults (what a blank EEPROM is restored to).
    pub(super) fn firmware_defaults() -> Settings {
        let mut m = std::collections::BTreeMap::new();
        for (n, v) in [
            (0, 10.0),
            (1, 25.0),
            (2, 0.0),
            (3, 0.0),
            (4, 0.0),
            (5, 0.0),
            (6, 0.0),
            (10, 1.0),
            (11, 0.010),
            (12, 0.002),
            (13, 0.0),
            (20, 0.0),
            (21, 0.0),
            (22, 0.0),
            (23, 0.0),
            (24, 25.0),
            (25, 500.0),
            (26, 250.0),
            (27, 1.0),
            (30, 1000.0),
            (31, 0.0),
            (32, 0.0),
        ] {
            m.insert(n, v);
        }
        for axis in 0..3 {
            m.insert(100 + axis, 250.0);
            m.insert(110 + axis, 500.0);
            m.insert(120 + axis, 10.0);
            m.insert(130 + axis, 200.0);
        }
        Settings(m)
    }

    pub(super) fn programmed(c: &GrblSimConfig) -> Settings {
        let mut s = Settings::firmware_defaults();
        let b = |v: bool| if v { 1.0 } else { 0.0 };
        for (n, v) in [
            (10, f64::from(c.status_report_mask)),
            (20, b(c.soft_limits && c.homing_enabled)),
            (21, b(c.hard_limits)),
            (22, b(c.homing_enabled)),
            // Bit 1: the Y axis homes toward negative.
            (
                23,
                if c.home_switch_at_negative_end {
                    2.0
                } else {
                    0.0
                },
            ),
            (24, c.homing_feed_mm_min),
            (25, c.homing_seek_mm_min),
            (26, f64::from(c.homing_debounce_ms)),
            (27, c.homing_pulloff_mm),
            (101, c.steps_per_mm),
            (111, c.max_rate_mm_min),
            (121, c.acceleration_mm_s2),
            (131, c.max_travel_mm),
        ] {
            s.0.insert(n, v);
        }
        s
    }

    pub(super) fn get(&self, n: u16) -> f64 {
        self.0.get(&n).copied().unwrap_or(0.0)
    }

    pub(super) fn flag(&self, n: u16) -> bool {
        self.get(n) != 0.0
    }

    pub(super) fn steps_per_mm(&self) -> f64 {
        self.get(101)
    }

    /// `$$`: one bare `$N=value` line per setting.
    pub(super) fn listing(&self) -> String {
        let mut s = String::new();
        for (&n, &v) in &self.0 {
            if INT_SETTINGS.contains(&n) || RPM_SETTINGS.contains(&n) {
                s.push_str(&format!("${n}={}\r\n", v.trunc() as i64));
            } else {
                s.push_str(&format!("${n}={v:.3}\r\n"));
            }
        }
        s
    }

    /// `$N=value`, with GRBL's checks; the error code on refusal.
    pub(super) fn store(&mut self, n: f64, v: f64) -> Result<(), u8> {
        if v < 0.0 {
            return Err(4); // negative value
        }
        if n.fract() != 0.0 || !(0.0..=255.0).contains(&n) {
            return Err(3);
        }
        let n = n as u16;
        if !self.0.contains_key(&n) {
            return Err(3);
        }
        let int = v.trunc();
        match n {
            0 if int < 3.0 => return Err(6), // step pulse must be ≥ 3 µs
            20 if int != 0.0 && !self.flag(22) => return Err(10),
            22 if int == 0.0 => {
                self.0.insert(20, 0.0);
            }
            _ => {}
        }
        let stored = if INT_SETTINGS.contains(&n) {
            int.min(255.0)
        } else {
            v
        };
        self.0.insert(n, stored);
        Ok(())
    }
}
