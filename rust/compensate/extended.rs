//! The inverse of the base model with its effects ([`crate::effects`]).
//!
//! The chain of [`crate::effects::ExtendedModel`], per sample interval:
//!
//! ```text
//! u ─► input_lag ─► u_a ─► x0 + Q(kv(t)·u_a + h(u_a)) + creep(u_a) = y ─► + drift·t ─► delay d ─► x
//! ```
//!
//! with Q(s) = s + ε·s² (electrostriction; Q(s) = s without it) and kv(t) = kv·(1 + r·t)
//! (gain_drift; kv without it).
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
//! - **gain_drift**: kv(t_k) takes the place of kv in the sample's equation.
//! - **electrostriction**: the target of s = kv(t)·u_a + h is Q⁻¹ of the rest,
//!   s = 2q/(1 + √(1 + 4ε·q)), the root on the rising branch of Q (where q lies below
//!   Q's extreme, the extreme). Creep's immediate share depends on u_a too, so with
//!   creep the equation in s is solved again with the creep's share at the u_a found,
//!   until u_a settles (the share is a small fraction of kv: two or three passes). On the
//!   first sample the equation is a quadratic in s and is solved at once.
//! - **drift**: subtracted from the target, y_k = x_d − rate·t_k.
//! - **delay** of d samples: x_k+d = y_k, so the inverse needs the reference d samples
//!   ahead (preview): [`ExtendedInverse::step`] takes x_d,k+d, and [`invert_extended`]
//!   shifts the record (the last value is held at the end; the first d outputs of
//!   the delayed model cannot be influenced).
//! - **resonance** and **resonance2** are not inverted (their inverse, a second-order
//!   lead, is not part of this crate): an effect set with either is rejected.
//! - **pickup** and **saturation** are in the sensor's reading, not in the stack's
//!   motion: the inverse aims at the displacement before them and ignores them (the
//!   reading of the commanded motion still carries the pickup and the clip).
//!
//! With no effects the result equals [`super::Inverse`]'s.

use super::inverse::Solution;
use super::inverse::{first_sample_voltage, solve, tolerance, Clip, IntervalEquation, InverseStatus, VoltageLimits};
use crate::effects::electrostriction::quadratic_root;
use crate::effects::{
    first_order_coefficient, first_order_step, stack_output, Effect, EffectSet, Electrostriction, InputLag,
};
use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::model::integrator::{abs_pow, advance_h_carried, Drive};
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
    /// |h|^n for the state's h, carried as by the [`crate::ExtendedModel`].
    hn: f64,
    status: InverseStatus,
}

impl ExtendedInverse {
    /// An inverse of the model `params` with `effects` (no resonance) for samples
    /// `dt` \[s\] apart, from h = `h0` \[µm\], within `limits`; `params` in the admissible
    /// region ([`Params::check_admissible`]), as for [`super::Inverse::new`].
    pub fn new(params: Params, effects: EffectSet, dt: f64, h0: f64, limits: VoltageLimits) -> Result<Self> {
        params.check_admissible()?;
        effects.validate()?;
        positive_dt(dt)?;
        finite_sample("h0", h0)?;
        limits.validate()?;
        if effects.resonance.is_some() || effects.resonance2.is_some() {
            return Err(Error::InvalidConfig {
                name: "effects",
                value: f64::NAN,
                reason:
                    "a resonance is not inverted (input_lag, creep, gain_drift, electrostriction, drift and delay are)",
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
            hn: abs_pow(h0, params.n),
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
        let kv = self.effects.gain_drift.map_or(p.kv, |g| p.kv * g.factor(t));
        let electro = self.effects.electrostriction;
        let s = &mut self.state;
        let hn = &mut self.hn;
        let (u, clip, evaluations) = match s.u_prev {
            None => {
                // As ExtendedModel's first sample: u_a = u, cᵢ = gᵢ·u, h = h0.
                let (u, clip) = match electro {
                    None => first_sample_voltage(kv + gains.iter().sum::<f64>(), p.x0 + s.h - target, &self.limits),
                    Some(e) => {
                        // x0 + s + ε·s² + G·(s − h)/kv = target with s = kv·u + h.
                        let ratio = gains.iter().sum::<f64>() / kv;
                        let sv = quadratic_root(e.epsilon_per_um, 1.0 + ratio, p.x0 - ratio * s.h - target);
                        first_sample_voltage(kv, s.h - sv, &self.limits)
                    }
                };
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
                let w_lo = lag_scale * self.limits.min_v + lag_rest;
                let w_hi = lag_scale * self.limits.max_v + lag_rest;
                let sol = match electro {
                    None => {
                        let mut linear = kv;
                        let mut offset = p.x0 - target;
                        for ((c, g), step) in s.creep.iter().zip(gains).zip(&self.creep_steps) {
                            linear += g * step.w1;
                            offset += step.decay * c + g * step.w0 * s.ua_prev;
                        }
                        let eq = IntervalEquation::new(p, s.h, *hn, s.ua_prev, self.dt, linear, offset);
                        solve(&eq, w_lo, w_hi, tol)
                    }
                    Some(e) => {
                        let (mut creep_linear, mut creep_rest) = (0.0, 0.0);
                        for ((c, g), step) in s.creep.iter().zip(gains).zip(&self.creep_steps) {
                            creep_linear += g * step.w1;
                            creep_rest += step.decay * c + g * step.w0 * s.ua_prev;
                        }
                        let stroke = Stroke { kv, electro: e, rest: p.x0 + creep_rest - target, creep_linear };
                        stroke.solve(p, (s.h, *hn), s.ua_prev, self.dt, (w_lo, w_hi), tol)
                    }
                };
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
                (s.h, *hn) = advance_h_carried(&Drive::of(u_prev, u).params(p), s.h, *hn, s.ua_prev, ua, self.dt);
                for ((c, g), step) in s.creep.iter_mut().zip(gains).zip(&self.creep_steps) {
                    *c = step.advance(*c, g * s.ua_prev, g * ua, self.dt);
                }
                s.ua_prev = ua;
                (u, clip, sol.evaluations + 1)
            }
        };
        s.u_prev = Some(u);
        s.samples += 1;
        let y = stack_output(p, &self.effects, s.ua_prev, s.h, t) + s.creep.iter().sum::<f64>();
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

    /// Replaces the base parameters (validated, in the admissible region); the state is kept.
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        params.check_admissible()?;
        if params.n != self.params.n {
            self.hn = abs_pow(self.state.h, params.n);
        }
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
        self.hn = abs_pow(state.h, self.params.n);
        self.state = state;
        Ok(())
    }

    /// Replaces the input lag's corner frequency (an online estimate); the state is kept.
    /// An inverse built without a lag has none to replace (`InvalidConfig`), and a bad
    /// `lag` is rejected; either leaves the inverse as it was.
    pub fn set_input_lag(&mut self, lag: InputLag) -> Result<()> {
        lag.validate()?;
        if self.lag.is_none() {
            return Err(Error::InvalidConfig {
                name: "input_lag",
                value: lag.fc_hz,
                reason: "this inverse was built without an input lag",
            });
        }
        self.lag = Some(AffineStep::new(lag.tau_s(), self.dt));
        self.effects.input_lag = Some(lag);
        Ok(())
    }

    /// Moves the model's state to that of a model that followed the same commands (an
    /// online identifier's): h \[µm\] and the voltage on the stack `ua` \[V\] after a sample
    /// at command `u` \[V\]. The creep states and the sample count are kept. Non-finite
    /// values are rejected and the state kept. No allocation.
    pub fn follow(&mut self, h: f64, u: f64, ua: f64) -> Result<()> {
        finite_sample("h", h)?;
        finite_sample("u", u)?;
        finite_sample("ua", ua)?;
        self.hn = abs_pow(h, self.params.n);
        self.state.h = h;
        self.state.u_prev = Some(u);
        self.state.ua_prev = ua;
        Ok(())
    }

    /// The voltage on the stack u_a after the last sample \[V\] (0 before the first).
    pub fn stack_voltage(&self) -> f64 {
        self.state.ua_prev
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
        self.hn = abs_pow(self.h0, self.params.n);
        self.state.creep.iter_mut().for_each(|c| *c = 0.0);
        self.status = InverseStatus::default();
    }
}

/// Passes of [`Stroke::solve`] at most.
const MAX_STROKE_PASSES: u32 = 8;

/// The sample's equation with electrostriction: x0 + Q(kv·w + h(w)) + creep(w) = target,
/// creep(w) = `creep_linear`·w + the rest; `rest` = x0 + creep's rest − target.
struct Stroke {
    kv: f64,
    electro: Electrostriction,
    rest: f64,
    creep_linear: f64,
}

impl Stroke {
    /// Solves for w within `range`: the base equation kv·w + h(w) = Q⁻¹(−rest −
    /// creep_linear·w), w held at the last pass's value until it settles.
    /// `(h, hn)`: h \[µm\] at the start of the interval and its |h|^n.
    fn solve(&self, p: &Params, (h, hn): (f64, f64), w_prev: f64, dt: f64, range: (f64, f64), tol: f64) -> Solution {
        let mut w = w_prev;
        let mut evaluations = 0;
        let mut passes = 0;
        loop {
            let target_s = self.electro.invert(-self.rest - self.creep_linear * w);
            let eq = IntervalEquation::new(p, h, hn, w_prev, dt, self.kv, -target_s);
            let mut sol = solve(&eq, range.0, range.1, tol);
            evaluations += sol.evaluations;
            passes += 1;
            let settled = self.creep_linear == 0.0 || (sol.w - w).abs() <= 1e-13 * w.abs().max(1.0);
            if settled || passes >= MAX_STROKE_PASSES {
                sol.evaluations = evaluations;
                return sol;
            }
            w = sol.w;
        }
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
    use crate::compensate::inverse::{beyond_tolerance, invert, tolerance};
    use crate::effects::{
        simulate_extended, Creep, Delay, Drift, Electrostriction, GainDrift, InputLag, Pickup, Resonance, Resonance2,
        Saturation,
    };
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
    fn a_new_lag_estimate_and_a_followed_state_act_as_a_fresh_inverse_would() {
        let (dt, p) = (1e-4, Params::paper_1hz());
        let lag = |fc_hz| EffectSet { input_lag: Some(InputLag { fc_hz }), ..EffectSet::none() };
        let mut moved = ExtendedInverse::new(p, lag(3000.0), dt, 0.0, VoltageLimits::NONE).unwrap();
        moved.step(1.0).unwrap();
        moved.set_input_lag(InputLag { fc_hz: 650.0 }).unwrap();
        moved.follow(0.3, 12.0, 11.5).unwrap();
        assert_eq!(moved.effects().input_lag, Some(InputLag { fc_hz: 650.0 }));
        assert_eq!((moved.h(), moved.stack_voltage()), (0.3, 11.5));
        let mut fresh = ExtendedInverse::new(p, lag(650.0), dt, 0.0, VoltageLimits::NONE).unwrap();
        let samples = moved.state().samples;
        fresh
            .set_state(ExtendedInverseState { samples, u_prev: Some(12.0), ua_prev: 11.5, h: 0.3, creep: vec![] })
            .unwrap();
        for x_d in [2.0, 2.5, 3.5, 3.0] {
            assert_eq!(moved.step(x_d).unwrap().to_bits(), fresh.step(x_d).unwrap().to_bits());
        }
        // Bad values change nothing; an inverse without a lag has none to replace.
        let before = moved.clone();
        assert!(moved.follow(f64::NAN, 1.0, 1.0).is_err());
        assert!(moved.follow(0.1, 1.0, f64::INFINITY).is_err());
        assert!(moved.set_input_lag(InputLag { fc_hz: -1.0 }).is_err());
        assert_eq!(moved, before);
        let creep = EffectSet { input_lag: None, ..lag_creep_delay() };
        let mut creep_only = ExtendedInverse::new(p, creep, dt, 0.0, VoltageLimits::NONE).unwrap();
        assert!(creep_only.set_input_lag(InputLag { fc_hz: 650.0 }).is_err());
        let mut base = super::super::AnyInverse::new(p, None, dt, 0.0, VoltageLimits::NONE).unwrap();
        assert!(base.set_input_lag(InputLag { fc_hz: 650.0 }).is_err());
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
        let inner = d..x.len() - d;
        assert!(beyond_tolerance(&x[inner.clone()], &x_d[inner]) <= 1e-12, "{worst}");
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

    #[test]
    fn round_trip_through_gain_drift_and_electrostriction_with_the_rest() {
        let dt = 1e-4;
        let p = Params::paper_1hz();
        let effects = EffectSet {
            gain_drift: Some(GainDrift { rate_per_s: 0.02 }),
            electrostriction: Some(Electrostriction { epsilon_per_um: 0.004 }),
            ..lag_creep_delay()
        };
        let u_true = paper_input(dt, 0.02);
        let x_d = simulate_extended(&p, &effects, &u_true, dt, 0.0).unwrap();
        let (u, _) = invert_extended(&p, &effects, &x_d, dt, 0.0, VoltageLimits::NONE).unwrap();
        let x = simulate_extended(&p, &effects, &u, dt, 0.0).unwrap();
        let d = 2;
        let worst = (d..x.len() - d).map(|k| (x[k] - x_d[k]).abs()).fold(0.0, f64::max);
        eprintln!("gain drift + electrostriction round trip {worst:.2e} µm");
        // The tolerance holds on the stroke; x = x0 + s + ε·s² moves by (1 + 2ε·s) < 2 times as much.
        let within = (d..x.len() - d).all(|k| (x[k] - x_d[k]).abs() <= 2.0 * tolerance(x_d[k]));
        assert!(within, "{worst}");
        // Each alone, without creep (one pass of the stroke equation), from the first sample.
        for alone in [
            EffectSet { electrostriction: Some(Electrostriction { epsilon_per_um: -0.01 }), ..EffectSet::none() },
            EffectSet { gain_drift: Some(GainDrift { rate_per_s: -0.05 }), ..EffectSet::none() },
        ] {
            let x_d = simulate_extended(&p, &alone, &u_true, dt, 0.0).unwrap();
            let (u, _) = invert_extended(&p, &alone, &x_d, dt, 0.0, VoltageLimits::NONE).unwrap();
            let x = simulate_extended(&p, &alone, &u, dt, 0.0).unwrap();
            let worst = x.iter().zip(&x_d).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(beyond_tolerance(&x, &x_d) <= 1e-12, "{:?}: {worst}", alone.names());
        }
    }

    #[test]
    fn pickup_and_saturation_are_left_to_the_reading() {
        let dt = 1e-4;
        let p = Params::paper_1hz();
        let x_d: Vec<f64> = (0..3000).map(|k| 9.0 - 8.0 * (k as f64 * 0.003).cos()).collect();
        let reading = EffectSet {
            pickup: Some(Pickup { line_hz: 50.0, sin_um: vec![0.2], cos_um: vec![0.1] }),
            saturation: Some(Saturation { min_um: 0.0, max_um: 15.0 }),
            ..lag_creep_delay()
        };
        let (with, _) = invert_extended(&p, &reading, &x_d, dt, 0.0, VoltageLimits::NONE).unwrap();
        let (without, _) = invert_extended(&p, &lag_creep_delay(), &x_d, dt, 0.0, VoltageLimits::NONE).unwrap();
        assert_eq!(with, without);
        let two = EffectSet { resonance2: Some(Resonance2 { fn_hz: 1000.0, zeta: 0.1 }), ..EffectSet::none() };
        assert!(ExtendedInverse::new(p, two, 1e-4, 0.0, VoltageLimits::NONE).is_err());
    }
}
