//! How close is close enough: a distance given in model units or relative to the model.

use std::fmt;

use crate::error::{Error, Result};

/// A distance bound, in model units or as a fraction of the model's bounding-box diagonal.
///
/// Users often do not know a part's size or unit, so a bound relative to the part is the
/// default; one type for every tolerance (the fit's, its mean bound, the STEP reader's chord)
/// keeps the conversion to model units in one place, done against the diagonal of the mesh
/// the bound applies to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tolerance {
    /// Model units.
    Absolute(f64),
    /// Fraction of the bounding-box diagonal.
    Relative(f64),
}

impl Tolerance {
    /// The encoder's default tolerance: 1e-3 of the bounding-box diagonal.
    pub const DEFAULT: Tolerance = Tolerance::Relative(1e-3);

    /// `value` in model units, or as a fraction of the diagonal when `relative`.
    pub fn new(value: f64, relative: bool) -> Tolerance {
        if relative {
            Tolerance::Relative(value)
        } else {
            Tolerance::Absolute(value)
        }
    }

    /// In model units, for a model whose bounding-box diagonal is `diagonal`.
    pub fn resolve(self, diagonal: f64) -> f64 {
        match self {
            Tolerance::Absolute(t) => t,
            Tolerance::Relative(f) => f * diagonal,
        }
    }

    /// The same kind of bound, `factor` times as large.
    pub fn scaled(self, factor: f64) -> Tolerance {
        match self {
            Tolerance::Absolute(t) => Tolerance::Absolute(t * factor),
            Tolerance::Relative(f) => Tolerance::Relative(f * factor),
        }
    }

    /// In model units for `diagonal`, checked to be positive and finite; `what` names the
    /// bound in the error.
    pub fn checked(self, diagonal: f64, what: &str) -> Result<f64> {
        let t = self.resolve(diagonal);
        if t > 0.0 && t.is_finite() {
            Ok(t)
        } else {
            Err(Error::Parameter(format!(
                "{what} must be positive, got {self}"
            )))
        }
    }
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance::DEFAULT
    }
}

impl fmt::Display for Tolerance {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Tolerance::Absolute(t) => write!(f, "{t}"),
            Tolerance::Relative(r) => write!(f, "{r} of the diagonal"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_bounds_scale_with_the_diagonal_and_absolute_ones_do_not() {
        assert_eq!(Tolerance::Relative(1e-3).resolve(200.0), 0.2);
        assert_eq!(Tolerance::Absolute(0.5).resolve(200.0), 0.5);
        assert_eq!(Tolerance::DEFAULT, Tolerance::default());
        assert_eq!(
            Tolerance::new(0.25, true).scaled(2.0),
            Tolerance::Relative(0.5)
        );
        assert_eq!(
            Tolerance::new(0.25, false).scaled(2.0),
            Tolerance::Absolute(0.5)
        );
    }

    #[test]
    fn a_bound_that_is_not_a_positive_distance_is_a_parameter_error() {
        for t in [
            Tolerance::Absolute(0.0),
            Tolerance::Absolute(-1.0),
            Tolerance::Relative(f64::NAN),
            Tolerance::Absolute(f64::INFINITY),
        ] {
            let e = t.checked(10.0, "tolerance").unwrap_err();
            assert!(matches!(e, Error::Parameter(_)), "{e}");
        }
        assert_eq!(Tolerance::Relative(0.5).checked(10.0, "x").unwrap(), 5.0);
    }
}
