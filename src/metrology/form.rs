//! A stated form removed from a traced profile by least squares: the levelling of a primary
//! profile evaluated without the λc filter (the "form-only" evaluation of `analyze
//! --form-only`), so that P parameters describe the profile about its form and not about its
//! tilt.
//!
//! The form is a straight line (levelling) or a polynomial of degree 2 to 6 in x, fitted to
//! the heights over the whole traced length (x centred and scaled to [−1, 1] for a well
//! conditioned fit, solved by SVD) and subtracted.
//!
//! Depends on [`super::MetrologyError`] and nalgebra.

use super::MetrologyError;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// The highest polynomial degree accepted.
pub const MAX_DEGREE: u8 = 6;

/// A form removed by least squares.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Form {
    /// A straight line (levelling).
    Line,
    /// A polynomial in x of this degree (2 … [`MAX_DEGREE`]).
    Polynomial(u8),
}

impl Form {
    /// Parses `line` or `polyN` (N in 2 … [`MAX_DEGREE`]); `poly1` is the line.
    pub fn parse(s: &str) -> Result<Form, String> {
        match s.trim() {
            "line" | "poly1" => Ok(Form::Line),
            t => match t.strip_prefix("poly").and_then(|d| d.parse::<u8>().ok()) {
                Some(d) if (2..=MAX_DEGREE).contains(&d) => Ok(Form::Polynomial(d)),
                _ => Err(format!(
                    "form {s:?} is not one surfscan removes; give line or poly2 … poly{MAX_DEGREE} (a least-squares polynomial of that degree in x)"
                )),
            },
        }
    }

    /// The polynomial degree (1 for the line).
    pub fn degree(self) -> u8 {
        match self {
            Form::Line => 1,
            Form::Polynomial(d) => d,
        }
    }

    /// In words, for recipes.
    pub fn describe(self) -> String {
        match self {
            Form::Line => "least-squares straight line".to_string(),
            Form::Polynomial(d) => format!("least-squares polynomial of degree {d} in x"),
        }
    }
}

/// `heights_um` (uniform pitch) minus their least-squares `form`.
pub fn remove_form(heights_um: &[f64], form: Form) -> Result<Vec<f64>, MetrologyError> {
    let n = heights_um.len();
    let terms = usize::from(form.degree()) + 1;
    if n < terms + 1 {
        return Err(MetrologyError::TooShort {
            points: n,
            length_mm: 0.0,
            sampling_length_mm: 0.0,
            min_points: terms + 1,
        });
    }
    let half = (n - 1) as f64 * 0.5;
    let u = |i: usize| (i as f64 - half) / half.max(1.0);
    let a = DMatrix::from_fn(n, terms, |i, j| u(i).powi(j as i32));
    let b = DVector::from_iterator(n, heights_um.iter().copied());
    let coef = a
        .svd(true, true)
        .solve(&b, 1e-12)
        .map_err(|_| MetrologyError::BadParameter {
            what: "form",
            value: f64::from(form.degree()),
            hint: "the least-squares form could not be solved; give a lower degree",
        })?;
    Ok(heights_um
        .iter()
        .enumerate()
        .map(|(i, z)| {
            let x = u(i);
            let fit: f64 = coef
                .iter()
                .enumerate()
                .map(|(j, c)| c * x.powi(j as i32))
                .sum();
            z - fit
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stated_form_is_removed_exactly() {
        let n = 501;
        let rough = |i: usize| 0.3 * (i as f64 * 0.9).sin();
        // A tilt and a parabola (an arc's small-angle form) on top of the roughness.
        let z: Vec<f64> = (0..n)
            .map(|i| {
                let x = i as f64 * 0.001;
                rough(i) + 5.0 + 12.0 * x - 30.0 * (x - 0.25) * (x - 0.25)
            })
            .collect();
        let line = remove_form(&z, Form::Line).unwrap();
        let parabola = remove_form(&z, Form::Polynomial(2)).unwrap();
        let rq = |v: &[f64]| (v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64).sqrt();
        let rq_rough = rq(&(0..n).map(rough).collect::<Vec<_>>());
        // The parabola is the form: what remains is the roughness (about its own mean and
        // parabola, which the sine barely has).
        assert!((rq(&parabola) - rq_rough).abs() < 0.01 * rq_rough);
        // Levelling alone leaves the curvature in.
        assert!(rq(&line) > 2.0 * rq_rough);
        // Residuals of a least-squares fit are orthogonal to the constant term.
        assert!(parabola.iter().sum::<f64>().abs() < 1e-9);
    }

    #[test]
    fn forms_are_parsed_or_refused_with_the_choices() {
        assert_eq!(Form::parse("line"), Ok(Form::Line));
        assert_eq!(Form::parse("poly3"), Ok(Form::Polynomial(3)));
        let e = Form::parse("poly9").unwrap_err();
        assert!(e.contains("line or poly2 … poly6"), "{e}");
        assert!(Form::parse("arc").is_err());
    }
}
