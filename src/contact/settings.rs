//! `[contact]`: the contact analysis a scan's outputs include — in the station's
//! configuration and in a recipe (which overrides its keys), frozen into each scan's plan
//! with the rest of its characterisation, so that a resumed scan and `surfscan analyze` of
//! its directory compute the contact the scan was started with.
//!
//! ```toml
//! [contact]
//! enabled = true                 # default false: no contact section
//! pressures-mpa = [1, 10, 100]   # default 1, 2, 5, 10, 20, 50, 100
//! young-gpa = 210.0              # the specimen (default steel: 210 GPa, ν 0.30)
//! poisson = 0.30
//! young2-gpa = 70.0              # the counter-body; absent: a rigid flat
//! poisson2 = 0.33                # default 0.30; needs young2-gpa
//! hardness-gpa = 2.0             # absent: purely elastic
//! model-pitch-y-mm = 0.002       # also the model sampled at this y spacing between lines
//! ```
//!
//! The numeric ranges are the station configuration's (`config::NUMERIC_KEYS`); what relates
//! the keys (the loads to the hardness, `poisson2` to `young2-gpa`) is checked by
//! [`ContactSettings::check`], which names the key.
//!
//! Layer 1 (pure logic): depends on the sibling modules and serde.

use super::{Body, ContactError, ContactOptions, DEFAULT_PRESSURES_MPA};
use serde::{Deserialize, Serialize};

/// `[contact]` as written (and as a scan's plan freezes it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct ContactSettings {
    /// Include the contact section in a scan's outputs (default false).
    #[serde(default)]
    pub enabled: bool,
    /// Nominal pressures, MPa.
    #[serde(default = "d_pressures")]
    pub pressures_mpa: Vec<f64>,
    /// Young's modulus of the specimen, GPa.
    #[serde(default = "d_young")]
    pub young_gpa: f64,
    /// Poisson's ratio of the specimen.
    #[serde(default = "d_poisson")]
    pub poisson: f64,
    /// Young's modulus of the counter-body, GPa (`None`: a rigid flat).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub young2_gpa: Option<f64>,
    /// Poisson's ratio of the counter-body (`None`: 0.30).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub poisson2: Option<f64>,
    /// Hardness of a perfectly plastic specimen, GPa (`None`: elastic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hardness_gpa: Option<f64>,
    /// Also the contact of the model sampled at this y spacing between the lines, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_pitch_y_mm: Option<f64>,
}

fn d_pressures() -> Vec<f64> {
    DEFAULT_PRESSURES_MPA.to_vec()
}
fn d_young() -> f64 {
    Body::STEEL.young_gpa
}
fn d_poisson() -> f64 {
    Body::STEEL.poisson
}

impl Default for ContactSettings {
    fn default() -> Self {
        ContactSettings {
            enabled: false,
            pressures_mpa: d_pressures(),
            young_gpa: d_young(),
            poisson: d_poisson(),
            young2_gpa: None,
            poisson2: None,
            hardness_gpa: None,
            model_pitch_y_mm: None,
        }
    }
}

impl ContactSettings {
    /// The solver's options of these settings, as given (checked by [`Self::check`], and again
    /// by the solver before it solves).
    pub fn options(&self) -> ContactOptions {
        ContactOptions {
            specimen: Body {
                young_gpa: self.young_gpa,
                poisson: self.poisson,
            },
            counter: self.young2_gpa.map(|young_gpa| Body {
                young_gpa,
                poisson: self.poisson2.unwrap_or(Body::STEEL.poisson),
            }),
            hardness_gpa: self.hardness_gpa,
            pressures_mpa: self.pressures_mpa.clone(),
            ..ContactOptions::default()
        }
    }

    /// Checks the values and their relations; the error names the key (as
    /// `contact.KEY`) and says why.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if self.poisson2.is_some() && self.young2_gpa.is_none() {
            return Err((
                "contact.poisson2",
                "is the counter-body's Poisson's ratio and needs young2-gpa (its Young's modulus); without both the counter-body is a rigid flat".into(),
            ));
        }
        if let Some(s) = self.model_pitch_y_mm {
            if !(s.is_finite() && s > 0.0) {
                return Err((
                    "contact.model-pitch-y-mm",
                    format!("{s} mm: the model's y spacing must be a positive length"),
                ));
            }
        }
        super::check_options(&self.options()).map_err(|e| {
            let key = match e {
                ContactError::Young {
                    body: "specimen", ..
                } => "contact.young-gpa",
                ContactError::Young { .. } => "contact.young2-gpa",
                ContactError::Poisson {
                    body: "specimen", ..
                } => "contact.poisson",
                ContactError::Poisson { .. } => "contact.poisson2",
                ContactError::Hardness { .. } => "contact.hardness-gpa",
                _ => "contact.pressures-mpa",
            };
            (key, e.to_string())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> ContactSettings {
        toml::from_str(text).unwrap()
    }

    #[test]
    fn defaults_are_steel_on_a_rigid_flat_at_the_default_loads_and_off() {
        let s = parse("");
        assert!(!s.enabled);
        let o = s.options();
        assert_eq!(o.specimen, Body::STEEL);
        assert_eq!(o.counter, None);
        assert_eq!(o.hardness_gpa, None);
        assert_eq!(o.pressures_mpa, DEFAULT_PRESSURES_MPA.to_vec());
        assert_eq!(s.check(), Ok(()));
    }

    #[test]
    fn the_counter_body_takes_steels_ratio_unless_given() {
        let o = parse("young2-gpa = 70.0").options();
        assert_eq!(
            o.counter,
            Some(Body {
                young_gpa: 70.0,
                poisson: 0.30
            })
        );
        let o = parse("young2-gpa = 70.0\npoisson2 = 0.33").options();
        assert_eq!(o.counter.map(|c| c.poisson), Some(0.33));
    }

    #[test]
    fn each_bad_value_names_its_key() {
        for (text, key, says) in [
            ("young-gpa = 0.0", "contact.young-gpa", "specimen"),
            ("poisson = 0.6", "contact.poisson", "specimen"),
            ("young2-gpa = 2000.0", "contact.young2-gpa", "counter-body"),
            (
                "young2-gpa = 70.0\npoisson2 = -0.1",
                "contact.poisson2",
                "counter-body",
            ),
            ("poisson2 = 0.3", "contact.poisson2", "young2-gpa"),
            ("hardness-gpa = 500.0", "contact.hardness-gpa", "500"),
            ("pressures-mpa = [10, -5]", "contact.pressures-mpa", "-5"),
            ("pressures-mpa = []", "contact.pressures-mpa", "NaN"),
            (
                "hardness-gpa = 0.05\npressures-mpa = [10, 100]",
                "contact.pressures-mpa",
                "beyond full contact",
            ),
            (
                "model-pitch-y-mm = 0.0",
                "contact.model-pitch-y-mm",
                "positive",
            ),
        ] {
            let (k, msg) = parse(text).check().unwrap_err();
            assert_eq!(k, key, "{text}: {msg}");
            assert!(msg.contains(says), "{text}: {msg}");
        }
    }

    #[test]
    fn unknown_keys_are_refused() {
        let e = toml::from_str::<ContactSettings>("youngs-gpa = 1.0").unwrap_err();
        assert!(e.to_string().contains("youngs-gpa"), "{e}");
    }
}
