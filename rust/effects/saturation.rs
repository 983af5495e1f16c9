//! `saturation`: the sensor's reading is held within its range.
//!
//! ```text
//! x ← min(max(x, x_min), x_max)
//! ```
//!
//! x_min, x_max: the ends of the sensor's (or its A/D's) range \[µm\]. A hard clip,
//! the last stage of the chain. Its output is piecewise linear in x_min and x_max,
//! which a least-squares fit handles with forward differences; samples inside the
//! range do not depend on them. The inverse does not undo it: it aims at the stack's
//! displacement, which the sensor's range does not limit.

use super::Effect;
use crate::error::{Error, Result};
use crate::model::scalar::Scalar;

/// A clip of the reading to \[x_min, x_max\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Saturation {
    /// Lower end x_min \[µm\] (finite, < x_max).
    pub min_um: f64,
    /// Upper end x_max \[µm\] (finite, > x_min).
    pub max_um: f64,
}

impl Effect for Saturation {
    const NAME: &'static str = "saturation";

    fn validate(&self) -> Result<()> {
        if !self.min_um.is_finite() {
            return Err(Error::InvalidParameter {
                name: "saturation.min_um",
                value: self.min_um,
                reason: "must be finite",
            });
        }
        if !(self.max_um.is_finite() && self.max_um > self.min_um) {
            return Err(Error::InvalidParameter {
                name: "saturation.max_um",
                value: self.max_um,
                reason: "must be finite and above saturation.min_um",
            });
        }
        Ok(())
    }
}

impl Saturation {
    /// The reading \[µm\] of a sensor that sees `x` \[µm\].
    #[inline]
    pub fn apply(&self, x: f64) -> f64 {
        clip(x, self.min_um, self.max_um)
    }
}

/// `x` held within [`min`, `max`] \[µm\] (`min` < `max`), in any number type: where it
/// is clipped, the reading is the bound, with the bound's derivatives.
#[inline]
pub(crate) fn clip<S: Scalar>(x: S, min: S, max: S) -> S {
    if x.re() < min.re() {
        min
    } else if x.re() > max.re() {
        max
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clips_and_names_the_bad_end() {
        let s = Saturation { min_um: -1.0, max_um: 2.0 };
        assert_eq!([s.apply(-3.0), s.apply(0.5), s.apply(9.0)], [-1.0, 0.5, 2.0]);
        let err = Saturation { min_um: 1.0, max_um: 1.0 }.validate().unwrap_err();
        assert!(err.to_string().contains("saturation.max_um"));
        let err = Saturation { min_um: f64::NAN, max_um: 1.0 }.validate().unwrap_err();
        assert!(err.to_string().contains("saturation.min_um"));
    }
}
