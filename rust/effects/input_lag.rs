//! `input_lag`: the voltage on the stack lags the command (amplifier bandwidth).
//!
//! ```text
//! τ·du_a/dt = u − u_a,   τ = 1/(2π·fc)
//! ```
//!
//! u: commanded voltage \[V\]; u_a: voltage on the stack \[V\]; fc: corner frequency \[Hz\].
//! The command is a straight line between samples, for which the step below is exact.

use super::{first_order_coefficient, first_order_step, Effect};
use crate::error::{Error, Result};
use crate::model::scalar::{Dual, Scalar};

/// First-order low-pass between the command and the stack.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputLag {
    /// Corner frequency fc \[Hz\] (> 0, finite).
    pub fc_hz: f64,
}

impl Effect for InputLag {
    const NAME: &'static str = "input_lag";

    fn validate(&self) -> Result<()> {
        if !(self.fc_hz.is_finite() && self.fc_hz > 0.0) {
            return Err(Error::InvalidParameter {
                name: "input_lag.fc_hz",
                value: self.fc_hz,
                reason: "the corner frequency must be finite and > 0 Hz",
            });
        }
        Ok(())
    }
}

impl InputLag {
    /// Time constant τ = 1/(2π·fc) \[s\].
    pub fn tau_s(&self) -> f64 {
        1.0 / (2.0 * core::f64::consts::PI * self.fc_hz)
    }

    /// The per-sample coefficients for a sampling interval `dt` \[s\].
    pub(crate) fn stage(&self, dt: f64) -> LagStage {
        LagStage { tau: self.tau_s(), decay: first_order_coefficient(self.tau_s(), dt) }
    }
}

/// The discretised filter: `decay = exp(−dt/τ)`, in the number type of the run
/// (`f64`, or duals carrying ∂/∂ln fc: [`LagStage::seeded`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LagStage<S = f64> {
    tau: S,
    decay: S,
}

impl<S: Scalar> LagStage<S> {
    /// u_a after one interval in which u moves linearly from `u0` to `u1`.
    #[inline]
    pub(crate) fn advance(&self, ua: S, u0: S, u1: S, dt: f64) -> S {
        first_order_step(ua, u0, u1, self.tau, self.decay, dt)
    }
}

impl<const M: usize> LagStage<Dual<M>> {
    /// The stage of `lag` for interval `dt` \[s\] with τ and the decay carrying their
    /// derivatives over ln fc at derivative slot `slot` (∂τ/∂ln fc = −τ, so
    /// ∂decay/∂ln fc = −decay·dt/τ).
    pub(crate) fn seeded(lag: &InputLag, dt: f64, slot: usize) -> Self {
        let LagStage { tau, decay } = lag.stage(dt);
        LagStage { tau: Dual::slope(tau, slot, -tau), decay: Dual::slope(decay, slot, -decay * dt / tau) }
    }
}

impl LagStage {
    /// exp(−dt/τ): how a derivative of u_a carried into an interval leaves it.
    #[inline]
    pub(crate) fn decay(&self) -> f64 {
        self.decay
    }

    /// ∂u_a/∂ln fc of [`Self::advance`] itself, from `ua` (u_a at the interval's
    /// start) with u moving linearly from `u0` to `u1`.
    #[inline]
    pub(crate) fn ln_fc_slope(&self, ua: f64, u0: f64, u1: f64, dt: f64) -> f64 {
        let r = self.tau * (u1 - u0) / dt;
        // ∂τ/∂ln fc = −τ, so ∂r/∂ln fc = −r and ∂decay/∂ln fc = −decay·dt/τ.
        r - r * self.decay - (ua - u0 + r) * self.decay * dt / self.tau
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::EffectSet;
    use crate::params::Params;

    #[test]
    fn matches_a_fine_euler_solution_on_a_ramp() {
        let lag = InputLag { fc_hz: 50.0 };
        let dt = 1e-3;
        let stage = lag.stage(dt);
        let exact = stage.advance(0.0, 0.0, 1.0, dt);
        let (mut y, m) = (0.0, 100_000);
        let h = dt / m as f64;
        for i in 0..m {
            let u = (i as f64 + 0.5) * h / dt;
            y += h * (u - y) / lag.tau_s();
        }
        // Forward Euler with 1e5 steps is first order: its own error is about 2e-7 here.
        assert!((exact - y).abs() < 1e-6, "{exact} vs {y}");
    }

    /// A sine, then a hold of `hold` samples at the voltage it stopped at.
    fn sine_then_hold(dt: f64, hold: usize) -> Vec<f64> {
        let mut u: Vec<f64> =
            (0..800).map(|k| 2.0 + 1.5 * (2.0 * core::f64::consts::PI * k as f64 * dt).sin()).collect();
        let last = *u.last().unwrap();
        u.extend(core::iter::repeat_n(last, hold));
        u
    }

    /// Behind the lag a hold still moves h while the stack's voltage settles (A, β, γ),
    /// but the δ term does not integrate δ·u through the settling tail ([`Drive`]): ten
    /// time constants into the hold the displacement has stopped (to 1 nm). Before,
    /// the term ran until u_a met u to the last bit, about 36 τ: δ·u·26 τ ≈ 2.5 µm
    /// after ten time constants with these parameters.
    ///
    /// [`Drive`]: crate::model::integrator::Drive
    #[test]
    fn a_hold_behind_the_lag_stops_within_ten_time_constants() {
        let p = Params { kv: 14.6, x0: -122.0, a: -2.72, beta: 0.108, gamma: -0.026, n: 2.52, delta: -2.43 };
        let lag = InputLag { fc_hz: 7.95 };
        let dt = 0.005;
        let u = sine_then_hold(dt, 1000);
        let effects = EffectSet { input_lag: Some(lag), ..EffectSet::none() };
        let x = crate::effects::simulate_extended(&p, &effects, &u, dt, 0.0).unwrap();
        let settled = 800 + (10.0 * lag.tau_s() / dt).ceil() as usize;
        let moved = (x[x.len() - 1] - x[settled]).abs();
        assert!(moved < 1e-3, "the displacement still moved {moved} µm after ten time constants of the hold");
        // The settling itself is there: the first samples of the hold move.
        assert!((x[801] - x[800]).abs() > 1e-3);
    }

    #[test]
    fn rejects_non_positive_corner() {
        assert!(InputLag { fc_hz: 0.0 }.validate().is_err());
        assert!(InputLag { fc_hz: f64::NAN }.validate().is_err());
    }
}
