//! `gain_drift`: the stack's gain kv changes slowly with time.
//!
//! ```text
//! kv(t) = kv·(1 + r·t)
//! ```
//!
//! t \[s\] counts from the first sample of the record; r \[1/s\] is the relative change
//! of kv per second. It stands for a temperature-like slow variation of the stack's
//! sensitivity (self-heating under a sustained drive, a room that warms up, ageing of
//! the poling). Unlike `drift` (an offset ∝ t, independent of u) it scales with the
//! voltage: the loop tilts as time goes on; unlike `creep` (which follows changes of
//! u, with fixed time constants) it depends on the time since the start only. The
//! hysteresis h is not scaled. Algebraic in t: exact at every instant.

use super::Effect;
use crate::error::{Error, Result};
use crate::model::scalar::Scalar;

/// A linear change of kv in time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GainDrift {
    /// Relative rate r \[1/s\] (finite).
    pub rate_per_s: f64,
}

impl Effect for GainDrift {
    const NAME: &'static str = "gain_drift";

    fn validate(&self) -> Result<()> {
        if !self.rate_per_s.is_finite() {
            return Err(Error::InvalidParameter {
                name: "gain_drift.rate_per_s",
                value: self.rate_per_s,
                reason: "must be finite",
            });
        }
        Ok(())
    }
}

impl GainDrift {
    /// kv(t)/kv = 1 + r·t \[-\] at time `t_s` \[s\] after the first sample.
    #[inline]
    pub fn factor(&self, t_s: f64) -> f64 {
        gain_factor(self.rate_per_s, t_s)
    }
}

/// 1 + r·t \[-\] for the rate r = `rate` \[1/s\] at time `t_s` \[s\], in any number type.
#[inline]
pub(crate) fn gain_factor<S: Scalar>(rate: S, t_s: f64) -> S {
    S::cst(1.0) + rate * t_s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn is_linear_in_time_and_rejects_nan() {
        let g = GainDrift { rate_per_s: 0.01 };
        assert_eq!(g.factor(0.0), 1.0);
        assert!((g.factor(10.0) - 1.1).abs() < 1e-15);
        let err = GainDrift { rate_per_s: f64::INFINITY }.validate().unwrap_err();
        assert!(err.to_string().contains("gain_drift.rate_per_s"));
    }
}
