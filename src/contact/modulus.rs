//! The composite (contact) modulus of two elastic bodies: 1/E* = (1 − ν₁²)/E₁ + (1 − ν₂²)/E₂
//! (Johnson 1985, eq. 4.22). A rigid counter-body contributes nothing. The contact of two
//! rough elastic bodies maps onto that of one rough body with modulus E* against a rigid flat
//! (the half-space approximation behind every boundary-element contact solver).
//!
//! Range checks keep the input to what a surface in a roughness lab can be: Young's moduli
//! from 0.001 GPa (soft elastomers) to 1500 GPa (above diamond's ~1050), Poisson's ratios
//! from 0 to 0.5 (incompressible).
//!
//! Layer 1 (pure logic): depends on [`super::ContactError`].

use super::ContactError;

/// Smallest accepted Young's modulus, GPa.
pub const MIN_YOUNG_GPA: f64 = 1e-3;
/// Largest accepted Young's modulus, GPa.
pub const MAX_YOUNG_GPA: f64 = 1500.0;

/// One elastic body: Young's modulus and Poisson's ratio.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Body {
    /// Young's modulus, GPa.
    pub young_gpa: f64,
    /// Poisson's ratio.
    pub poisson: f64,
}

impl Body {
    /// The default specimen: steel, E = 210 GPa, ν = 0.30.
    pub const STEEL: Body = Body {
        young_gpa: 210.0,
        poisson: 0.30,
    };

    /// A body with its values checked; `which` names it in the error ("specimen",
    /// "counter-body").
    pub fn try_new(
        which: &'static str,
        young_gpa: f64,
        poisson: f64,
    ) -> Result<Body, ContactError> {
        if !(young_gpa.is_finite() && (MIN_YOUNG_GPA..=MAX_YOUNG_GPA).contains(&young_gpa)) {
            return Err(ContactError::Young {
                body: which,
                young_gpa,
            });
        }
        if !(poisson.is_finite() && (0.0..=0.5).contains(&poisson)) {
            return Err(ContactError::Poisson {
                body: which,
                poisson,
            });
        }
        Ok(Body { young_gpa, poisson })
    }

    /// The counter-body of `young_gpa` (`None`: a rigid flat) and `poisson` (`None`: steel's
    /// 0.30), checked.
    pub fn counter(
        young_gpa: Option<f64>,
        poisson: Option<f64>,
    ) -> Result<Option<Body>, ContactError> {
        young_gpa
            .map(|e| Body::try_new("counter-body", e, poisson.unwrap_or(Body::STEEL.poisson)))
            .transpose()
    }

    /// (1 − ν²)/E, 1/GPa.
    fn compliance(&self) -> f64 {
        (1.0 - self.poisson * self.poisson) / self.young_gpa
    }
}

/// E* (GPa) of `specimen` against `counter` (`None`: a rigid flat).
pub fn effective_modulus_gpa(specimen: Body, counter: Option<Body>) -> f64 {
    1.0 / (specimen.compliance() + counter.map_or(0.0, |c| c.compliance()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steel_on_rigid_and_steel_on_steel() {
        let e = effective_modulus_gpa(Body::STEEL, None);
        assert!((e - 210.0 / 0.91).abs() < 1e-9);
        // Two equal bodies halve it.
        let e2 = effective_modulus_gpa(Body::STEEL, Some(Body::STEEL));
        assert!((e2 - 105.0 / 0.91).abs() < 1e-9);
        // Brass (100 GPa, 0.34) on sapphire (400 GPa, 0.29): 1/(0.8844/100 + 0.9159/400).
        let b = Body::try_new("specimen", 100.0, 0.34).unwrap();
        let s = Body::try_new("counter-body", 400.0, 0.29).unwrap();
        let want = 1.0 / (0.8844 / 100.0 + 0.9159 / 400.0);
        assert!((effective_modulus_gpa(b, Some(s)) - want).abs() < 1e-9);
    }

    #[test]
    fn out_of_range_values_are_named() {
        for (e, nu) in [(0.0, 0.3), (-5.0, 0.3), (2000.0, 0.3), (f64::NAN, 0.3)] {
            assert!(matches!(
                Body::try_new("specimen", e, nu),
                Err(ContactError::Young {
                    body: "specimen",
                    ..
                })
            ));
        }
        for nu in [-0.1, 0.51, f64::INFINITY] {
            assert!(matches!(
                Body::try_new("counter-body", 100.0, nu),
                Err(ContactError::Poisson {
                    body: "counter-body",
                    ..
                })
            ));
        }
        let msg = Body::try_new("specimen", 2e6, 0.3).unwrap_err().to_string();
        assert!(msg.contains("2000000") && msg.contains("GPa"), "{msg}");
    }
}
