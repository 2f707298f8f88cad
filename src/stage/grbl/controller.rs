//! What a GRBL board's `$$` settings say, and whether the driver's configuration agrees with
//! them: steps per mm (`$101`), report units (`$13`), homing (`$22`, `$27`), soft limits and
//! travel (`$20`, `$131`, with `$23` and the build's `HOMING_FORCE_SET_ORIGIN`), the Y axis's
//! maximum rate and acceleration (`$111`, `$121`) and the status report mask (`$10`).
//!
//! Pure (layer 1): parsed settings in, a verdict out; depends on [`crate::stage::StageError`].

use crate::stage::StageError;
use std::collections::BTreeMap;

/// What a board's `$I` says of how its firmware was built, as far as the driver needs it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BuildOptions {
    /// Built with `HOMING_FORCE_SET_ORIGIN` (`Z` among the `[OPT:…]` letters).
    pub force_set_origin: bool,
}

impl BuildOptions {
    /// From the text of an `[OPT:…]` line after `OPT:`: the option letters, then the planner
    /// blocks and the serial buffer size, comma-separated (e.g. `VZ,15,128`).
    pub fn from_opt(opt: &str) -> BuildOptions {
        let letters = opt.split(',').next().unwrap_or("");
        BuildOptions {
            force_set_origin: letters.contains('Z'),
        }
    }
}

/// The settings a GRBL board reported, by number.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ControllerSettings(BTreeMap<u16, f64>);

impl ControllerSettings {
    /// Settings from `(number, value)` pairs, as `$$` lists them.
    pub fn from_pairs(pairs: impl IntoIterator<Item = (u16, f64)>) -> Self {
        ControllerSettings(pairs.into_iter().collect())
    }

    /// One setting, when reported.
    pub fn get(&self, n: u16) -> Option<f64> {
        self.0.get(&n).copied()
    }

    fn flag(&self, n: u16) -> Option<bool> {
        self.get(n).map(|v| v != 0.0)
    }

    /// `$101`: Y steps per mm.
    pub fn steps_per_mm(&self) -> Option<f64> {
        self.get(101)
    }

    /// `$22`: the homing cycle is enabled.
    pub fn homing_enabled(&self) -> Option<bool> {
        self.flag(22)
    }

    /// `$27`: homing pull-off, mm (where the axis stands after `$H`: MPos −pull-off).
    pub fn pulloff_mm(&self) -> Option<f64> {
        self.get(27)
    }

    /// `$111`: Y maximum rate, mm/min (jog feeds above it are capped).
    pub fn max_rate_mm_min(&self) -> Option<f64> {
        self.get(111).filter(|v| v.is_finite() && *v > 0.0)
    }

    /// `$121`: Y acceleration, mm/s².
    pub fn acceleration_mm_s2(&self) -> Option<f64> {
        self.get(121).filter(|v| v.is_finite() && *v > 0.0)
    }

    /// `$10` bit 0: status reports carry `MPos` (otherwise `WPos`, needing `WCO`).
    pub fn reports_mpos(&self) -> Option<bool> {
        self.get(10).map(|v| (v as u32) & 1 != 0)
    }

    /// `$23` bit 1: the Y axis homes toward −Y (its switch at the low end of the travel).
    pub fn y_homes_toward_negative(&self) -> Option<bool> {
        self.get(23).map(|v| (v as u32) & 2 != 0)
    }

    /// The machine travel the board itself enforces, mm, when soft limits (`$20`, which needs
    /// homing) are on; `None` when it enforces none. GRBL 1.1 refuses a target outside
    /// [−`$131`, 0] whichever way the axis homes, except in a build with
    /// `HOMING_FORCE_SET_ORIGIN` (`build`): there homing sets the origin at the switch, and an
    /// axis that homes toward negative (`$23`) is held to [0, `$131`].
    pub fn enforced_travel_mm(&self, build: BuildOptions) -> Option<(f64, f64)> {
        let soft = self.flag(20)? && self.flag(22)?;
        let travel = self.get(131)?;
        if !(soft && travel.is_finite() && travel > 0.0) {
            return None;
        }
        if build.force_set_origin && self.y_homes_toward_negative() == Some(true) {
            Some((0.0, travel))
        } else {
            Some((-travel, 0.0))
        }
    }

    /// Checks the driver's configuration against the board. An error names the setting
    /// and what to change; the warnings are facts the operator should know.
    pub fn check(&self, steps_per_mm: f64, feed_mm_min: f64) -> Result<Vec<String>, StageError> {
        let mut warnings = Vec::new();
        match self.steps_per_mm() {
            Some(spm) if (spm - steps_per_mm).abs() > 1e-9 * steps_per_mm.abs().max(1.0) => {
                return Err(StageError::ControllerSetup(format!(
                    "the controller's $101 is {spm} steps/mm but stage.steps-per-mm is \
                     {steps_per_mm}: every move would be scaled by {:.4}. Set the one that is \
                     wrong (a board whose settings were reset to GRBL's defaults reports \
                     $101=250)",
                    steps_per_mm / spm
                )))
            }
            Some(_) => {}
            None => warnings.push(
                "the controller did not report $101 (steps/mm); stage.steps-per-mm is trusted \
                 unchecked"
                    .into(),
            ),
        }
        if self.flag(13) == Some(true) {
            return Err(StageError::ControllerSetup(
                "the controller reports positions in inches ($13=1); set $13=0 on the \
                 controller"
                    .into(),
            ));
        }
        if let Some(max) = self.max_rate_mm_min() {
            if feed_mm_min > max {
                warnings.push(format!(
                    "stage.feed-mm-min {feed_mm_min} is above the controller's $111 = {max} \
                     mm/min; the controller moves at {max}"
                ));
            }
        }
        if self.homing_enabled() == Some(false) {
            warnings.push(
                "the controller's homing cycle is disabled ($22=0): its position cannot be \
                 referenced to a switch"
                    .into(),
            );
        }
        Ok(warnings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn board() -> ControllerSettings {
        ControllerSettings::from_pairs([
            (10, 1.0),
            (13, 0.0),
            (20, 1.0),
            (22, 1.0),
            (27, 1.0),
            (101, 400.0),
            (111, 500.0),
            (121, 10.0),
            (131, 200.0),
        ])
    }

    #[test]
    fn a_matching_board_passes_and_exposes_its_travel_and_ramp() {
        let b = board();
        assert_eq!(b.check(400.0, 60.0).unwrap(), Vec::<String>::new());
        assert_eq!(
            b.enforced_travel_mm(BuildOptions::default()),
            Some((-200.0, 0.0))
        );
        assert_eq!(b.acceleration_mm_s2(), Some(10.0));
        assert_eq!(b.pulloff_mm(), Some(1.0));
        assert_eq!(b.reports_mpos(), Some(true));
    }

    #[test]
    fn wrong_steps_per_mm_and_inch_reports_are_refused_by_name() {
        let e = board().check(250.0, 60.0).unwrap_err();
        assert!(e.to_string().contains("$101 is 400"), "{e}");
        let mut inch = board();
        inch.0.insert(13, 1.0);
        assert!(inch
            .check(400.0, 60.0)
            .unwrap_err()
            .to_string()
            .contains("$13=1"));
    }

    #[test]
    fn fast_feed_and_disabled_homing_are_warnings_and_no_soft_limits_no_travel() {
        let mut b = board();
        b.0.insert(22, 0.0);
        let w = b.check(400.0, 600.0).unwrap();
        assert!(w.iter().any(|w| w.contains("$111")), "{w:?}");
        assert!(w.iter().any(|w| w.contains("$22=0")), "{w:?}");
        // Soft limits need homing: without it the board enforces no travel.
        let force = BuildOptions {
            force_set_origin: true,
        };
        for build in [BuildOptions::default(), force] {
            assert_eq!(b.enforced_travel_mm(build), None);
            assert_eq!(
                ControllerSettings::default().enforced_travel_mm(build),
                None
            );
        }
    }

    /// GRBL 1.1's soft-limit check (`system_check_travel_limits`): [−$131, 0] for either
    /// homing direction, unless the build forces the origin at the switch, when an axis
    /// homing toward negative ($23 bit 1 for Y) is held to [0, $131]. Bits of other axes do
    /// not move Y's travel.
    #[test]
    fn the_travel_follows_the_homing_direction_only_in_a_force_origin_build() {
        let force = BuildOptions::from_opt("VZ,15,128");
        assert!(force.force_set_origin);
        assert_eq!(BuildOptions::from_opt("V,15,128"), BuildOptions::default());
        // The counts after the letters are numbers, never an option.
        assert_eq!(BuildOptions::from_opt(",15,128"), BuildOptions::default());
        let with_dir = |mask: f64| {
            let mut b = board();
            b.0.insert(23, mask);
            b
        };
        let plain = BuildOptions::default();
        for mask in [0.0, 1.0, 2.0, 3.0, 7.0] {
            let b = with_dir(mask);
            assert_eq!(
                b.enforced_travel_mm(plain),
                Some((-200.0, 0.0)),
                "$23={mask}"
            );
        }
        for (mask, y_inverted) in [
            (0.0, false),
            (1.0, false),
            (4.0, false),
            (2.0, true),
            (7.0, true),
        ] {
            let b = with_dir(mask);
            assert_eq!(b.y_homes_toward_negative(), Some(y_inverted), "$23={mask}");
            let want = if y_inverted {
                (0.0, 200.0)
            } else {
                (-200.0, 0.0)
            };
            assert_eq!(b.enforced_travel_mm(force), Some(want), "$23={mask}");
        }
        // A board that does not report $23 is taken as homing toward positive.
        assert_eq!(board().enforced_travel_mm(force), Some((-200.0, 0.0)));
    }
}
