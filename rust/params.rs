//! The seven parameters of the asymmetric Bouc–Wen model.
//!
//! Names follow the paper (Zhu, Bian & Rui 2014, eqs. 3 and 5):
//!
//! ```text
//! x(t)  = kv·u(t) + x0 + h(t)
//! dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)
//! ```
//!
//! with u in volts, x and h in micrometres and t in seconds, so that
//! `kv` is in µm/V, `x0` in µm, `A` in µm/V, `β` and `γ` in µm^(1−n)/V,
//! `n` is dimensionless and `δ` is in µm/(V·s).

use crate::error::{Error, Result};

/// Parameters of the asymmetric Bouc–Wen model (see the module docs for units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Linear gain kv \[µm/V\].
    pub kv: f64,
    /// Offset x0 \[µm\].
    pub x0: f64,
    /// Hysteresis gain A \[µm/V\].
    pub a: f64,
    /// β [µm^(1−n)/V], weight of the |u̇|·|h|^(n−1)·h term.
    pub beta: f64,
    /// γ [µm^(1−n)/V], weight of the u̇·|h|^n term.
    pub gamma: f64,
    /// Shape exponent n (dimensionless, > 0).
    pub n: f64,
    /// Asymmetry δ \[µm/(V·s)\], weight of the u·sgn(u̇) term.
    pub delta: f64,
}

impl Params {
    /// Parameter names, in the order of [`Params::to_array`].
    pub const NAMES: [&'static str; 7] = ["kv", "x0", "A", "beta", "gamma", "n", "delta"];

    /// Builds and validates a parameter set.
    pub fn new(kv: f64, x0: f64, a: f64, beta: f64, gamma: f64, n: f64, delta: f64) -> Result<Self> {
        let p = Params { kv, x0, a, beta, gamma, n, delta };
        p.validate()?;
        Ok(p)
    }

    /// The paper's Table 2 values identified at 1 Hz on a P-885.51 stack.
    pub const fn paper_1hz() -> Self {
        Params { kv: 0.19, x0: 0.015, a: -0.072, beta: 0.020, gamma: -0.019, n: 1.52, delta: 0.0075 }
    }

    /// All values finite and `n > 0`.
    pub fn validate(&self) -> Result<()> {
        for (name, value) in Self::NAMES.iter().zip(self.to_array()) {
            if !value.is_finite() {
                return Err(Error::InvalidParameter { name, value, reason: "must be finite" });
            }
        }
        if self.n <= 0.0 {
            return Err(Error::InvalidParameter { name: "n", value: self.n, reason: "must be > 0" });
        }
        Ok(())
    }

    /// The admissible region, where h stays bounded (docs/design.md, "The admissible
    /// region"): [`Params::validate`], and β + γ ≥ 0 and β − γ ≥ 0, both > 0 where
    /// δ ≠ 0. With β + γ < 0 h escapes along a rising voltage once it passes
    /// (|A|/|β + γ|)^(1/n) (within a finite travel for n > 1); with β − γ < 0 the same
    /// along a falling one; with δ ≠ 0 each branch must dissipate, or the δ term pumps h
    /// without limit. The error names the combination and its value.
    pub fn check_admissible(&self) -> Result<()> {
        self.validate()?;
        let strict = self.delta != 0.0;
        for (name, value) in [("beta + gamma", self.beta + self.gamma), ("beta - gamma", self.beta - self.gamma)] {
            if value < 0.0 {
                return Err(Error::InvalidParameter {
                    name,
                    value,
                    reason:
                        "must be >= 0: h runs away on one branch of the loop (the admissible region, docs/design.md)",
                });
            }
            if strict && value <= 0.0 {
                return Err(Error::InvalidParameter {
                    name,
                    value,
                    reason: "must be > 0 where delta != 0: the delta term pumps h without limit on a branch that does \
                             not dissipate (the admissible region, docs/design.md)",
                });
            }
        }
        Ok(())
    }

    /// `[kv, x0, A, beta, gamma, n, delta]`.
    pub fn to_array(&self) -> [f64; 7] {
        [self.kv, self.x0, self.a, self.beta, self.gamma, self.n, self.delta]
    }

    /// Inverse of [`Params::to_array`], validated.
    pub fn from_array(v: [f64; 7]) -> Result<Self> {
        Self::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_through_array() {
        let p = Params::paper_1hz();
        assert_eq!(Params::from_array(p.to_array()).unwrap(), p);
    }

    #[test]
    fn rejects_non_positive_n_and_non_finite_values() {
        let mut v = Params::paper_1hz().to_array();
        v[5] = 0.0;
        assert!(matches!(Params::from_array(v), Err(Error::InvalidParameter { name: "n", .. })));
        let mut v = Params::paper_1hz().to_array();
        v[3] = f64::NAN;
        assert!(matches!(Params::from_array(v), Err(Error::InvalidParameter { name: "beta", .. })));
    }

    #[test]
    fn admissible_region() {
        assert!(Params::paper_1hz().check_admissible().is_ok());
        // A linear model: no hysteresis, no delta.
        let linear = Params { a: 0.0, beta: 0.0, gamma: 0.0, delta: 0.0, ..Params::paper_1hz() };
        assert!(linear.check_admissible().is_ok());
        // The same with delta: nothing dissipates what the delta term adds.
        let pumped = Params { delta: 0.01, ..linear };
        assert!(matches!(pumped.check_admissible(), Err(Error::InvalidParameter { name: "beta + gamma", .. })));
        // A fitted model that ran away: beta + gamma < 0, n = 6.
        let runaway = Params { kv: 0.057, x0: 0.0, a: -0.043, beta: 0.0018, gamma: -0.026, n: 6.0, delta: 0.0 };
        let err = runaway.check_admissible().unwrap_err();
        assert!(matches!(err, Error::InvalidParameter { name: "beta + gamma", .. }));
        let mirrored = Params { gamma: 0.026, ..runaway };
        assert!(matches!(mirrored.check_admissible(), Err(Error::InvalidParameter { name: "beta - gamma", .. })));
    }
}
