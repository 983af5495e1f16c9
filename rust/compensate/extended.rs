//! The inverse of the base model with its effects ([`crate::effects`]).
//!
//! The chain of [`crate::effects::ExtendedModel`], per sample interval:
//!
//! ```text
//! u ─► input_lag ─► u_a ─► kv·u_a + x0 + h(u_a) + creep(u_a) = y ─► + drift·t ─► delay d ─► x
//! ```
//!
//! Which effects are inverted, and how:
//!
//! - **input_lag** (amplifier bandwidth): the lag's exact step for a command that is
//!   a straight line between samples is affine in the new command,
//!   u_a,k = c₁·u_k + c₀·u_k−1 + e^(−Δt/τ)·u_a,k−1 with c₁ > 0. The voltage on the
//!   stack that gives x_d is solved for first (as the base inverse does for u), then
//!   u_k = (u_a,k − c₀·u_k−1 − e^(−Δt/τ)·u_a,k−1)/c₁: a lead that puts u_a exactly
//!   where it is wanted at each sample. The lead is bounded: u is held within the
//!   voltage limits, and the lag then follows the clipped command (u_a and h are
//!   advanced with the u actually returned). Its gain at the Nyquist frequency is
//!   (1 + e^(−Δt/τ))/(c₁ − c₀), 72 for a 650 Hz lag at 10 kHz: reference noise at
//!   that frequency is amplified as much.
//! - **creep**: each element's step is affine in u_a,k too, so its immediate share
//!   Σ gᵢ·(1 − spreadᵢ) joins kv in the equation and the rest of its state joins the
//!   offset; the root is found with the same solver and integrator as the base
//!   inverse ([`crate::compensate::inverse`]).
//! - **drift**: subtracted from the target, y_k = x_d − rate·t_k.
//! - **delay** of d samples: x_k+d = y_k, so the inverse needs the reference d samples
//!   ahead (preview): [`ExtendedInverse::step`] takes x_d,k+d, and [`invert_extended`]
//!   shifts the record (the last value is held at the end; the first d outputs of
//!   the delayed model cannot be influenced).
//! - **resonance** is not inverted (its inverse, a second-order lead, is not part of
//!   this crate): an effect set with a resonance is rejected.
//!
//! With no effects the result equals [`super::Inverse`]'s.

use super::inverse::{first_sample_voltage, solve, tolerance, Clip, IntervalEquation, InverseStatus, VoltageLimits};
use crate::effects::{first_order_coefficient, first_order_step, EffectSet};
use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::model::{advance_h, output};
use crate::params::Params;
use alloc::vec;
use alloc::vec::Vec;

/// The state an [`ExtendedInverse`] carries between samples.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExtendedInverseState {
    /// Samples since construction or reset (t = samples·Δt for the drift).
    pub samples: u64,
    /// The last command u \[V\]; `None` before the first sample.
    pub u_prev: Option<f64>,
    /// The last voltage on the stack u_a \[V\].
    pub ua_prev: f64,
    /// Hysteresis state h \[µm\].
    pub h: f64,
    /// Creep elements' displacements cᵢ \[µm\] (one per element).
    pub creep: Vec<f64>,
}

/// Per-interval constants of a first-order element: exp(−Δt/τ) and the weights of
/// the step's affine form y₁ = decay·y₀ + w0·v₀ + w1·v₁.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AffineStep {
    tau: f64,
    decay: f64,
    w0: f64,
    w1: f64,
}

impl AffineStep {
    fn new(tau: f64, dt: f64) -> Self {
        let decay = first_order_coefficient(tau, dt);
        let spread = tau / dt * (1.0 - decay);
        AffineStep { tau, decay, w0: spread - decay, w1: 1.0 - spread }
    }

    /// The element's exact step, as the model takes it ([`first_order_step`]).
    #[inline]
    fn advance(&self, y: f64, v0: f64, v1: f64, dt: f64) -> f64 {
        first_order_step(y, v0, v1, self.tau, self.decay, dt)
    }
}

/// The inverse of the extended model (see the module docs): `step(x_d ahead) -> u`.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtendedInverse {
    params: Params,
    effects: EffectSet,
    dt: f64,
    limits: VoltageLimits,
    h0: f64,
    lag: Option<AffineStep>,
    creep_steps: Vec<AffineStep>,
    state: ExtendedInverseState,
    status: InverseStatus,
}

impl ExtendedInverse {
    /// An inverse of the model `params` with `effects` (no resonance) for samples
    /// `dt` \[s\] apart, from h = `h0` \[µm\], within `limits`.
    pub fn new(params: Params, effects: EffectSet, dt: f64, h0: f64, limits: VoltageLimits) -> Result<Self> {
        params.validate()?;
        effects.validate()?;
        positive_dt(dt)?;
        finite_sample("h0", h0)?;
        limits.validate()?;
        if effects.resonance.is_some() {
            return Err(Error::InvalidConfig {
                name: "effects",
                value: f64::NAN,
                reason: "a resonance is not inverted (input_lag, creep, drift and delay are)",
            });
        }
        let lag = effects.input_lag.map(|l| AffineStep::new(l.tau_s(), dt));
        let creep_steps: Vec<AffineStep> = effects
            .creep
            .as_ref()
            .map(|c| c.tau_s.iter().map(|&tau| AffineStep::new(tau, dt)).collect())
            .unwrap_or_default();
        let state = ExtendedInverseState { h: h0, creep: vec![0.0; creep_steps.len()], ..Default::default() };
        Ok(ExtendedInverse {
            params,
            effects,
            dt,
            limits,
            h0,
            lag,
            creep_steps,
            state,
            status: InverseStatus::default(),
        })
    }

    /// The delay d \[samples\]: `step` takes the reference this many samples ahead.
    pub fn preview_samples(&self) -> usize {
        self.effects.delay.map_or(0, |d| d.samples)
    }

    /// Takes the desired displacement `x_d_ahead` \[µm\] of sample k + d (d =
    /// [`ExtendedInverse::preview_samples`]) and returns the command u_k \[V\]. A
    /// non-finite value is rejected and the state kept. No allocation.
    pub fn step(&mut self, x_d_ahead: f64) -> Result<f64> {
        finite_sample("x_d", x_d_ahead)?;
        let p = &self.params;
        let t = self.state.samples as f64 * self.dt;
        let target = x_d_ahead - self.effects.drift.map_or(0.0, |d| d.at(t));
        let tol = tolerance(x_d_ahead);
        let gains: &[f64] = self.effects.creep.as_ref().map_or(&[], |c| &c.gain_um_per_v);
        let s = &mut self.state;
        let (u, clip, evaluations) = match s.u_prev {
            None => {
                // As ExtendedModel's first sample: u_a = u, cᵢ = gᵢ·u, h = h0.
                let gain = p.kv + gains.iter().sum::<f64>();
                let (u, clip) = first_sample_voltage(gain, p.x0 + s.h - target, &self.limits);
                s.ua_prev = u;
                for (c, g) in s.creep.iter_mut().zip(gains) {
                    *c = g * u;
                }
                (u, clip, 0)
            }
            Some(u_prev) => {
                // u_a = lag_scale·u + lag_rest (u_a = u without a lag).
                let (lag_scale, lag_rest) = match self.lag {
                    Some(l) => (l.w1, l.w0 * u_prev + l.decay * s.ua_prev),
                    None => (1.0, 0.0),
                };
                let mut linear = p.kv;
                let mut offset = p.x0 - target;
                for ((c, g), step) in s.creep.iter().zip(gains).zip(&self.creep_steps) {
                    linear += g * step.w1;
                    offset += step.decay * c + g * step.w0 * s.ua_prev;
                }
                let eq = IntervalEquation { p, h: s.h, w_prev: s.ua_prev, dt: self.dt, linear, offset };
                let w_lo = lag_scale * self.limits.min_v + lag_rest;
                let w_hi = lag_scale * self.limits.max_v + lag_rest;
                let sol = solve(&eq, w_lo, w_hi, tol);
                // A hold of a settled lag (u_a = u) is the command held: exact, no rounding.
                let settled_hold = sol.w == s.ua_prev && s.ua_prev == u_prev;
                let wanted = if settled_hold { u_prev } else { (sol.w - lag_rest) / lag_scale };
                let (u, clip_u) = self.limits.clamp(wanted);
                let clip = if clip_u != Clip::None { clip_u } else { sol.clip };
                // Advance the chain with the command actually returned, as the model does.
                let ua = match self.lag {
                    Some(l) => l.advance(s.ua_prev, u_prev, u, self.dt),
                    None => u,
                };
                s.h = advance_h(p, s.h, s.ua_prev, ua, self.dt);
                for ((c, g), step) in s.creep.iter_mut().zip(gains).zip(&self.creep_steps) {
                    *c = step.advance(*c, g * s.ua_prev, g * ua, self.dt);
                }
                s.ua_prev = ua;
                (u, clip, sol.evaluations + 1)
            }
        };
        s.u_prev = Some(u);
        s.samples += 1;
        let y = output(p, s.ua_prev, s.h) + s.creep.iter().sum::<f64>();
        let residual = y - target;
        self.status = InverseStatus {
            clip,
            evaluations,
            residual_um: residual,
            exact: residual.abs() <= tol,
            samples: self.status.samples + 1,
            clipped_samples: self.status.clipped_samples + u64::from(clip != Clip::None),
        };
        Ok(u)
    }

    /// Base parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Effects and their parameters.
    pub fn effects(&self) -> &EffectSet {
        &self.effects
    }

    /// Replaces the base parameters (validated); the state is kept.
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        params.validate()?;
        self.params = params;
        Ok(())
    }

    /// Hysteresis state h \[µm\].
    pub fn h(&self) -> f64 {
        self.state.h
    }

    /// Sampling interval \[s\].
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The initial h \[µm\].
    pub fn h0(&self) -> f64 {
        self.h0
    }

    /// The voltage limits.
    pub fn limits(&self) -> VoltageLimits {
        self.limits
    }

    /// What the last step did.
    pub fn status(&self) -> InverseStatus {
        self.status
    }

    /// The state carried between samples (allocates a copy of the creep states).
    pub fn state(&self) -> ExtendedInverseState {
        self.state.clone()
    }

    /// Restores a state taken with [`ExtendedInverse::state`] (validated).
    pub fn set_state(&mut self, state: ExtendedInverseState) -> Result<()> {
        if state.creep.len() != self.creep_steps.len() {
            return Err(Error::LengthMismatch {
                what: "creep states (one per creep element)",
                expected: self.creep_steps.len(),
                found: state.creep.len(),
            });
        }
        finite_sample("h", state.h)?;
        finite_sample("ua_prev", state.ua_prev)?;
        if let Some(u) = state.u_prev {
            finite_sample("u_prev", u)?;
        }
        for &c in &state.creep {
            finite_sample("creep", c)?;
        }
        self.state = state;
        Ok(())
    }

    /// Restores a status taken with [`ExtendedInverse::status`] (counters included).
    pub fn set_status(&mut self, status: InverseStatus) {
        self.status = status;
    }

    /// Forgets the past: h = h0, no previous sample, t = 0, counters zero.
    pub fn reset(&mut self) {
        self.state.samples = 0;
        self.state.u_prev = None;
        self.state.ua_prev = 0.0;
        self.state.h = self.h0;
        self.state.creep.iter_mut().for_each(|c| *c = 0.0);
        self.status = InverseStatus::default();
    }
}

/// Inverts a whole record through the extended model: the commands u \[V\] for the
/// desired sensor readings `x_d` \[µm\] sampled every `dt` \[s\], from h = `h0` \[µm\].
/// With a delay of d samples the reference is read d samples ahead (the last value
/// held). Returns `(u, h_final)`. A non-finite value is rejected before anything is computed.
pub fn invert_extended(
    params: &Params,
    effects: &EffectSet,
    x_d: &[f64],
    dt: f64,
    h0: f64,
    limits: VoltageLimits,
) -> Result<(Vec<f64>, f64)> {
    let mut inv = ExtendedInverse::new(*params, effects.clone(), dt, h0, limits)?;
    for &v in x_d {
        finite_sample("x_d", v)?;
    }
    let d = inv.preview_samples();
    let mut u = Vec::with_capacity(x_d.len());
    for k in 0..x_d.len() {
        u.push(inv.step(x_d[(k + d).min(x_d.len() - 1)])?);
    }
    Ok((u, inv.h()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compensate::inverse::invert;
    use crate::effects::{simulate_extended, Creep, Delay, Drift, InputLag, Resonance};
    use crate::model::paper_input;

    fn lag_creep_delay() -> EffectSet {
        let mut creep = Creep::log_spaced(0.01, 10.0, 4).unwrap();
        creep.gain_um_per_v = vec![0.002; 4];
        EffectSet {
            creep: Some(creep),
            input_lag: Some(InputLag { fc_hz: 650.0 }),
            drift: Some(Drift { rate_um_per_s: 0.05 }),
            delay: Some(Delay { samples: 2 }),
            ..EffectSet::none()
        }
    }

    #[test]
    fn round_trip_through_lag_creep_drift_and_delay() {
        let dt = 1e-4;
        let p = Params::paper_1hz();
        let effects = lag_creep_delay();
        let u_true = paper_input(dt, 0.02);
        let x_d = simulate_extended(&p, &effects, &u_true, dt, 0.0).unwrap();
        let (u, h) = invert_extended(&p, &effects, &x_d, dt, 0.0, VoltageLimits::NONE).unwrap();
        let x = simulate_extended(&p, &effects, &u, dt, 0.0).unwrap();
        let d = 2;
        let worst = (d..x.len()).map(|k| (x[k] - x_d[k]).abs()).fold(0.0, f64::max);
        eprintln!("extended round trip {worst:.2e} µm, h {h}");
        // The last d samples were inverted against the held last value.
        let worst_inner = (d..x.len() - d).map(|k| (x[k] - x_d[k]).abs()).fold(0.0, f64::max);
        assert!(worst_inner <= 1e-9, "{worst_inner}");
    }

    #[test]
    fn no_effects_is_the_base_inverse() {
        let dt = 1e-4;
        let p = Params::paper_1hz();
        let x_d: Vec<f64> = (0..5000).map(|k| 9.0 - 8.0 * (k as f64 * 0.003).cos()).collect();
        let (base, s) = invert(&p, &x_d, dt, 0.1, None, VoltageLimits::NONE).unwrap();
        let (ext, h) = invert_extended(&p, &EffectSet::none(), &x_d, dt, 0.1, VoltageLimits::NONE).unwrap();
        assert_eq!(base, ext);
        assert_eq!(s.h_final, h);
    }

    #[test]
    fn limits_bind_on_the_command_and_the_chain_follows() {
        let dt = 1e-4;
        let p = Params::paper_1hz();
        let effects = EffectSet { input_lag: Some(InputLag { fc_hz: 300.0 }), ..EffectSet::none() };
        // A fast sine asks the lead for more than 0…100 V.
        let x_d: Vec<f64> =
            (0..2000).map(|k| 9.0 - 8.0 * (2.0 * std::f64::consts::PI * 200.0 * k as f64 * dt).cos()).collect();
        let limits = VoltageLimits::new(Some(0.0), Some(100.0)).unwrap();
        let mut inv = ExtendedInverse::new(p, effects.clone(), dt, 0.0, limits).unwrap();
        let mut u = Vec::new();
        for &v in &x_d {
            u.push(inv.step(v).unwrap());
        }
        assert!(inv.status().clipped_samples > 0);
        assert!(u.iter().all(|v| (0.0..=100.0).contains(v)));
        let x = simulate_extended(&p, &effects, &u, dt, 0.0).unwrap();
        // The inverse's own chain is the model's: the reported residuals are the errors.
        let mut inv2 = ExtendedInverse::new(p, effects, dt, 0.0, limits).unwrap();
        for (k, &v) in x_d.iter().enumerate() {
            inv2.step(v).unwrap();
            assert!((inv2.status().residual_um - (x[k] - v)).abs() < 1e-9);
        }
    }

    #[test]
    fn rejects_a_resonance_and_bad_samples() {
        let p = Params::paper_1hz();
        let res = EffectSet { resonance: Some(Resonance { fn_hz: 1000.0, zeta: 0.1 }), ..EffectSet::none() };
        assert!(ExtendedInverse::new(p, res, 1e-4, 0.0, VoltageLimits::NONE).is_err());
        let mut inv = ExtendedInverse::new(p, lag_creep_delay(), 1e-4, 0.0, VoltageLimits::NONE).unwrap();
        inv.step(1.0).unwrap();
        let before = inv.clone();
        assert!(inv.step(f64::NAN).is_err());
        assert_eq!(inv, before);
    }
}
