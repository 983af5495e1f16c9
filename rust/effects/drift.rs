//! `drift`: a slow sensor or thermal trend in time, independent of the input.
//!
//! ```text
//! x ← x + rate·t
//! ```
//!
//! t \[s\] counts from the first sample of the record; rate \[µm/s\]. The offset at
//! t = 0 is the base model's x0.

use super::Effect;
use crate::error::{Error, Result};
use crate::model::scalar::Scalar;

/// A linear trend in time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drift {
    /// Trend rate \[µm/s\] (finite).
    pub rate_um_per_s: f64,
}

impl Effect for Drift {
    const NAME: &'static str = "drift";

    fn validate(&self) -> Result<()> {
        if !self.rate_um_per_s.is_finite() {
            return Err(Error::InvalidParameter {
                name: "drift.rate_um_per_s",
                value: self.rate_um_per_s,
                reason: "must be finite",
            });
        }
        Ok(())
    }
}

impl Drift {
    /// The trend \[µm\] at time `t_s` \[s\] after the first sample.
    #[inline]
    pub fn at(&self, t_s: f64) -> f64 {
        trend(self.rate_um_per_s, t_s)
    }
}

/// The trend \[µm\] of rate `rate` \[µm/s\] at time `t_s` \[s\], in any number type.
#[inline]
pub(crate) fn trend<S: Scalar>(rate: S, t_s: f64) -> S {
    rate * t_s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn is_linear_in_time_and_rejects_nan() {
        let d = Drift { rate_um_per_s: 0.5 };
        assert_eq!(d.at(0.0), 0.0);
        assert_eq!(d.at(2.0), 1.0);
        assert!(Drift { rate_um_per_s: f64::NAN }.validate().is_err());
    }
}
