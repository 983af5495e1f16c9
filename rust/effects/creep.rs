//! `creep`: slow relaxation of the stack after a change of the voltage.
//!
//! A sum of first-order elements with fixed time constants τ_i and gains g_i:
//!
//! ```text
//! τ_i·dc_i/dt = g_i·u_a − c_i,     c = Σ_i c_i   (added to x)
//! ```
//!
//! u_a: voltage on the stack \[V\]; c: creep displacement \[µm\]; τ_i \[s\]; g_i \[µm/V\].
//! With log-spaced τ_i the step response grows roughly linearly in log(t), the usual
//! creep law of piezo stacks. For fixed τ_i the output is linear in the gains, which
//! makes them cheap to fit. Each element starts in equilibrium with the first voltage.

use alloc::vec;
use alloc::vec::Vec;

use super::{first_order_coefficient, first_order_step, Effect};
use crate::error::{Error, Result};
use crate::model::scalar::Scalar;

/// Largest number of creep elements.
pub const MAX_ELEMENTS: usize = 16;

/// Creep as a sum of first-order elements.
#[derive(Debug, Clone, PartialEq)]
pub struct Creep {
    /// Time constants τ_i \[s\] (finite, > 0).
    pub tau_s: Vec<f64>,
    /// Static gains g_i \[µm/V\] (finite; same length as `tau_s`).
    pub gain_um_per_v: Vec<f64>,
}

impl Effect for Creep {
    const NAME: &'static str = "creep";

    fn validate(&self) -> Result<()> {
        if self.tau_s.len() != self.gain_um_per_v.len() {
            return Err(Error::LengthMismatch {
                what: "creep.gain_um_per_v (one gain per time constant)",
                expected: self.tau_s.len(),
                found: self.gain_um_per_v.len(),
            });
        }
        if self.tau_s.is_empty() || self.tau_s.len() > MAX_ELEMENTS {
            return Err(Error::InvalidParameter {
                name: "creep.tau_s",
                value: self.tau_s.len() as f64,
                reason: "creep needs between 1 and 16 elements",
            });
        }
        for &tau in &self.tau_s {
            if !(tau.is_finite() && tau > 0.0) {
                return Err(Error::InvalidParameter {
                    name: "creep.tau_s",
                    value: tau,
                    reason: "every time constant must be finite and > 0 s",
                });
            }
        }
        for &g in &self.gain_um_per_v {
            if !g.is_finite() {
                return Err(Error::InvalidParameter {
                    name: "creep.gain_um_per_v",
                    value: g,
                    reason: "must be finite",
                });
            }
        }
        Ok(())
    }
}

impl Creep {
    /// `count` time constants log-spaced from `tau_min_s` to `tau_max_s` \[s\], all gains 0.
    pub fn log_spaced(tau_min_s: f64, tau_max_s: f64, count: usize) -> Result<Self> {
        if !(tau_min_s.is_finite() && tau_min_s > 0.0 && tau_max_s.is_finite() && tau_max_s >= tau_min_s) {
            return Err(Error::InvalidConfig {
                name: "creep tau range",
                value: tau_max_s,
                reason: "need finite 0 < tau_min_s <= tau_max_s",
            });
        }
        let tau_s: Vec<f64> = (0..count)
            .map(|i| {
                let f = if count > 1 { i as f64 / (count - 1) as f64 } else { 0.0 };
                tau_min_s * crate::math::powf(tau_max_s / tau_min_s, f)
            })
            .collect();
        let creep = Creep { gain_um_per_v: vec![0.0; tau_s.len()], tau_s };
        creep.validate()?;
        Ok(creep)
    }

    /// Σ g_i \[µm/V\]: the creep's share of the static gain.
    pub fn total_gain(&self) -> f64 {
        self.gain_um_per_v.iter().sum()
    }

    /// The elements for sub-intervals of `dt` \[s\], each gain g_i made an `S` by
    /// `gain(i, g_i)` (seeded as an unknown of a fit, or kept a number).
    pub(crate) fn stage<S: Scalar>(&self, dt: f64, gain: impl Fn(usize, f64) -> S) -> CreepStage<S> {
        CreepStage {
            tau_s: self.tau_s.clone(),
            gains: self.gain_um_per_v.iter().enumerate().map(|(i, &g)| gain(i, g)).collect(),
            decays: self.tau_s.iter().map(|&tau| first_order_coefficient(tau, dt)).collect(),
        }
    }
}

/// The creep elements of one run: fixed time constants and their decays over a
/// sub-interval, gains in the number type of the run.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CreepStage<S = f64> {
    tau_s: Vec<f64>,
    gains: Vec<S>,
    decays: Vec<f64>,
}

impl<S: Scalar> CreepStage<S> {
    /// Each element in equilibrium with the voltage `ua` \[V\]: c_i = g_i·u_a.
    pub(crate) fn rest(&self, ua: S) -> Vec<S> {
        self.gains.iter().map(|&g| g * ua).collect()
    }

    /// Advances every element over one interval in which u_a moves linearly from
    /// `ua0` to `ua1` \[V\] and returns c \[µm\].
    #[inline]
    pub(crate) fn advance(&self, states: &mut [S], ua0: S, ua1: S, dt: f64) -> S {
        let mut total = S::cst(0.0);
        for (((c, &tau), &g), &decay) in states.iter_mut().zip(&self.tau_s).zip(&self.gains).zip(&self.decays) {
            *c = first_order_step(*c, g * ua0, g * ua1, tau, decay, dt);
            total = total + *c;
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_response_grows_with_log_time_and_settles_at_the_total_gain() {
        let mut creep = Creep::log_spaced(0.01, 10.0, 4).unwrap();
        creep.gain_um_per_v = vec![0.01; 4];
        let dt = 1e-3;
        let stage = creep.stage(dt, |_, g| g);
        let mut states = vec![0.0; 4];
        let mut c = stage.advance(&mut states, 0.0, 1.0, dt);
        let mut at = Vec::new();
        for k in 2..=100_000 {
            c = stage.advance(&mut states, 1.0, 1.0, dt);
            if [10, 100, 1000, 10_000].contains(&k) {
                at.push(c);
            }
        }
        assert!(at.windows(2).all(|w| w[1] > w[0]));
        assert!((c - 0.04).abs() < 1e-3, "{c}");
    }

    #[test]
    fn rejects_mismatched_lengths_and_bad_time_constants() {
        let c = Creep { tau_s: vec![1.0, 2.0], gain_um_per_v: vec![0.0] };
        assert!(matches!(c.validate(), Err(Error::LengthMismatch { .. })));
        let c = Creep { tau_s: vec![-1.0], gain_um_per_v: vec![0.0] };
        assert!(matches!(c.validate(), Err(Error::InvalidParameter { name: "creep.tau_s", .. })));
    }
}
