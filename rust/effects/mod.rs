//! Effects: small physical models around the asymmetric Bouc–Wen core.
//!
//! The signal chain, per sample interval `dt` \[s\]:
//!
//! ```text
//! u (command, V) ─► input_lag ─► u_a (on the stack, V)
//! u_a ─► Bouc–Wen, eqs. (3)+(5): s = kv(t)·u_a + h,  kv(t) = kv·(1 + gain_drift·t)
//! s ─► electrostriction: s + ε·s² ─► + x0 ─┐
//! u_a ─► creep: Σ first-order elements ─────┴─► y (stack, µm)
//! y ─► resonance (2nd order, unit static gain) ─► resonance2 (the same) ─► z (µm)
//! z + drift·t ─► delay by d samples ─► + pickup(t) ─► saturation ─► x (sensor, µm)
//! ```
//!
//! Each effect is optional; with none, the chain is the base model exactly. The
//! names of [`EffectSet::NAMES`] (`creep`, `input_lag`, `gain_drift`,
//! `electrostriction`, `resonance`, `resonance2`, `drift`, `delay`, `pickup`,
//! `saturation`, `between_samples`) are the vocabulary of the diagnosis. Every effect validates its own
//! parameters ([`Effect::validate`]) with a message that names the parameter.
//!
//! What the command does between samples is the measurement chain's input end,
//! `between_samples` ([`BetweenSamples`]: held, a straight line, band-limited); without
//! it, a straight line. For a straight line the first-order stages (lag,
//! creep) and the resonances are stepped exactly for such an input (the second mode's
//! input, the first mode's output, to within its curvature over a sub-step). With a
//! resonance, the chain runs on [`RESONANCE_SUBSTEPS`] sub-intervals per sample,
//! because the stack's displacement is not a straight line within a fast voltage step
//! (h bends) and a lightly damped resonance responds to that shape. The algebraic
//! stages (gain_drift, electrostriction, pickup, saturation) are exact at every
//! instant they are evaluated at. Everything starts at rest in equilibrium with the
//! first sample: u_a = u\[0\], c_i = g_i·u\[0\], z = y\[0\], ż = 0, no trend, the
//! delay line full of the first value.

pub mod between_samples;
pub(crate) mod chain;
pub mod creep;
pub mod delay;
pub mod drift;
pub mod electrostriction;
pub mod gain_drift;
pub mod input_lag;
pub mod jacobian;
pub mod pickup;
pub mod resonance;
pub mod resonance2;
pub mod saturation;
pub mod state;

use alloc::vec;
use alloc::vec::Vec;

pub use between_samples::BetweenSamples;
pub use creep::Creep;
pub use delay::Delay;
pub use drift::Drift;
pub use electrostriction::Electrostriction;
pub use gain_drift::GainDrift;
pub use input_lag::InputLag;
pub use pickup::Pickup;
pub use resonance::Resonance;
pub use resonance2::Resonance2;
pub use saturation::Saturation;
pub use state::ExtendedState;

use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::reconstruction::{InputPath, Reconstruction};
use core::ops::Mul;

use crate::model::scalar::Scalar;
use crate::params::Params;

use chain::{stack_output_of, Chain, Slots};

/// Sub-intervals per sample interval when a resonance is present.
pub const RESONANCE_SUBSTEPS: u32 = 4;

/// What every effect shares: a name in the diagnosis vocabulary and a validation.
pub trait Effect {
    /// The effect's name in the vocabulary ([`EffectSet::NAMES`]).
    const NAME: &'static str;
    /// Checks the parameters; the error names the offending one.
    fn validate(&self) -> Result<()>;
}

/// exp(−dt/τ).
#[inline]
pub(crate) fn first_order_coefficient(tau: f64, dt: f64) -> f64 {
    crate::math::exp(-dt / tau)
}

/// Exact step of τ·ẏ = v − y over `dt` while v moves linearly from `v0` to `v1`
/// (`decay` = exp(−dt/τ)); τ and the decay are numbers (`C` = `f64`) or carry
/// derivatives of their own (`C` = `S`).
#[inline]
pub(crate) fn first_order_step<S: Scalar + Mul<C, Output = S>, C: Copy>(
    y: S,
    v0: S,
    v1: S,
    tau: C,
    decay: C,
    dt: f64,
) -> S {
    // (v1 − v0)·τ is τ·(v1 − v0) to the bit: a product of two numbers commutes.
    let ramp = (v1 - v0) * tau / dt;
    v1 - ramp + (y - v0 + ramp) * decay
}

/// Which effects surround the base model, with their parameters.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EffectSet {
    pub creep: Option<Creep>,
    pub input_lag: Option<InputLag>,
    pub gain_drift: Option<GainDrift>,
    pub electrostriction: Option<Electrostriction>,
    pub resonance: Option<Resonance>,
    pub resonance2: Option<Resonance2>,
    pub drift: Option<Drift>,
    pub delay: Option<Delay>,
    pub pickup: Option<Pickup>,
    pub saturation: Option<Saturation>,
    pub between_samples: Option<BetweenSamples>,
}

impl EffectSet {
    /// The vocabulary, in the order of the signal chain (the measurement chain's input
    /// end last: it decides no parameter of the device).
    pub const NAMES: [&'static str; 11] = [
        Creep::NAME,
        InputLag::NAME,
        GainDrift::NAME,
        Electrostriction::NAME,
        Resonance::NAME,
        Resonance2::NAME,
        Drift::NAME,
        Delay::NAME,
        Pickup::NAME,
        Saturation::NAME,
        BetweenSamples::NAME,
    ];

    /// No effect: the base model.
    pub fn none() -> Self {
        Self::default()
    }

    /// Names of the effects present, in vocabulary order.
    pub fn names(&self) -> Vec<&'static str> {
        let present = [
            name_if(&self.creep),
            name_if(&self.input_lag),
            name_if(&self.gain_drift),
            name_if(&self.electrostriction),
            name_if(&self.resonance),
            name_if(&self.resonance2),
            name_if(&self.drift),
            name_if(&self.delay),
            name_if(&self.pickup),
            name_if(&self.saturation),
            name_if(&self.between_samples),
        ];
        present.into_iter().flatten().collect()
    }

    /// Validates every effect present.
    pub fn validate(&self) -> Result<()> {
        validate_if(&self.creep)?;
        validate_if(&self.input_lag)?;
        validate_if(&self.gain_drift)?;
        validate_if(&self.electrostriction)?;
        validate_if(&self.resonance)?;
        validate_if(&self.resonance2)?;
        validate_if(&self.drift)?;
        validate_if(&self.delay)?;
        validate_if(&self.pickup)?;
        validate_if(&self.saturation)?;
        validate_if(&self.between_samples)
    }

    /// What the command does between samples (`between_samples`; linear without it).
    pub fn input(&self) -> Reconstruction {
        self.between_samples.map_or(Reconstruction::Linear, |b| b.input)
    }

    /// The names of the effects present that are not among `supported`, for the
    /// methods that understand part of the vocabulary only.
    pub fn unsupported(&self, supported: &[&str]) -> Vec<&'static str> {
        self.names().into_iter().filter(|n| !supported.contains(n)).collect()
    }
}

/// The stack's displacement without creep \[µm\] at time `t` \[s\]: x0 + s (+ ε·s²),
/// s = kv(t)·u_a + h; [`output`] itself where neither gain_drift nor
/// electrostriction is present.
#[inline]
pub(crate) fn stack_output(params: &Params, effects: &EffectSet, ua: f64, h: f64, t: f64) -> f64 {
    let gain_drift = effects.gain_drift.map(|g| g.rate_per_s);
    let epsilon = effects.electrostriction.map(|e| e.epsilon_per_um);
    stack_output_of(params.kv, params.x0, gain_drift, epsilon, ua, h, t)
}

/// The effect's name if it is present.
fn name_if<E: Effect>(effect: &Option<E>) -> Option<&'static str> {
    effect.as_ref().map(|_| E::NAME)
}

/// Validates the effect if it is present.
fn validate_if<E: Effect>(effect: &Option<E>) -> Result<()> {
    effect.as_ref().map_or(Ok(()), Effect::validate)
}

/// The base model with its effects, one sample at a time: `step(u) -> x`.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtendedModel {
    params: Params,
    effects: EffectSet,
    chain: Chain<f64>,
}

impl ExtendedModel {
    /// A model with base parameters `params`, effects `effects`, sampling interval
    /// `dt` \[s\] and initial hysteresis state `h0` \[µm\].
    pub fn new(params: Params, effects: EffectSet, dt: f64, h0: f64) -> Result<Self> {
        params.validate()?;
        effects.validate()?;
        positive_dt(dt)?;
        finite_sample("h0", h0)?;
        let chain = Chain::new(params, &effects, dt, h0, &Slots::default())?;
        Ok(ExtendedModel { params, effects, chain })
    }

    /// Takes the commanded voltage `u` \[V\] of the next sample; returns the sensor's
    /// displacement x \[µm\]. A non-finite `u` is rejected and the state kept; so is
    /// every sample of a band-limited input between samples, which depends on later
    /// samples (simulate the record: [`simulate_extended`]).
    pub fn step(&mut self, u: f64) -> Result<f64> {
        finite_sample("u", u)?;
        if self.effects.input().needs_the_record() {
            return Err(needs_the_record());
        }
        Ok(self.chain.step(u))
    }

    /// Base parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Effects and their parameters.
    pub fn effects(&self) -> &EffectSet {
        &self.effects
    }

    /// Current hysteresis state h \[µm\].
    pub fn h(&self) -> f64 {
        self.chain.h()
    }

    /// Forgets the past (h = h0, no previous sample, t = 0).
    pub fn reset(&mut self) {
        self.chain.reset();
    }

    /// What the model carries to its next sample: a copy to continue from.
    pub fn state(&self) -> ExtendedState {
        self.chain.state()
    }

    /// Continues from `state` ([`ExtendedModel::state`] of a model with the same
    /// effects, or [`ExtendedState::initial`]); a state of other effects (another
    /// number of creep elements or delay) or with a non-finite value is rejected and
    /// the model kept.
    pub fn set_state(&mut self, state: &ExtendedState) -> Result<()> {
        self.chain.set_state(state)
    }
}

/// Simulates the base model with `effects` over a record of commanded voltages `u`
/// \[V\] sampled every `dt` \[s\], from h = `h0` \[µm\]; writes x \[µm\] into `x_out`.
/// Input with a non-finite value is rejected before anything is computed.
pub fn simulate_extended_into(
    params: &Params,
    effects: &EffectSet,
    u: &[f64],
    dt: f64,
    h0: f64,
    x_out: &mut [f64],
) -> Result<()> {
    if x_out.len() != u.len() {
        return Err(Error::LengthMismatch { what: "simulate_extended output", expected: u.len(), found: x_out.len() });
    }
    let mut model = ExtendedModel::new(*params, effects.clone(), dt, h0)?;
    let path = record_path(effects, u)?;
    for (k, (x, &v)) in x_out.iter_mut().zip(u).enumerate() {
        *x = model.chain.step_along(v, path.as_ref(), k);
    }
    Ok(())
}

/// The band-limited path of a record's commanded voltage `u` where `effects` say the
/// input is band-limited between samples (`None` otherwise); rejects a non-finite sample.
pub(crate) fn record_path(effects: &EffectSet, u: &[f64]) -> Result<Option<InputPath>> {
    for &v in u {
        finite_sample("u", v)?;
    }
    Ok(if effects.input().needs_the_record() { Some(InputPath::new(u, effects.input(), false)?) } else { None })
}

/// The error of a sample-by-sample step under a band-limited input.
fn needs_the_record() -> Error {
    Error::InvalidConfig {
        name: "between_samples",
        value: f64::from(Reconstruction::Bandlimited.code()),
        reason: "a band-limited input between samples depends on later samples: simulate the whole record",
    }
}

/// [`simulate_extended`] continuing from `state` ([`ExtendedState::initial`] for a
/// record's start); also returns the state after the last sample, so that
/// simulating a record in pieces, each from the state the previous piece returned,
/// gives the same numbers as one call, bit for bit (but for a band-limited input
/// between samples, whose path near a cut sees only its own piece).
pub fn simulate_extended_from(
    params: &Params,
    effects: &EffectSet,
    u: &[f64],
    dt: f64,
    state: &ExtendedState,
) -> Result<(Vec<f64>, ExtendedState)> {
    // The state brings its own h (checked by set_state).
    let mut model = ExtendedModel::new(*params, effects.clone(), dt, 0.0)?;
    model.set_state(state)?;
    let path = record_path(effects, u)?;
    let x = u.iter().enumerate().map(|(k, &v)| model.chain.step_along(v, path.as_ref(), k)).collect();
    Ok((x, model.state()))
}

/// Allocating form of [`simulate_extended_into`].
pub fn simulate_extended(params: &Params, effects: &EffectSet, u: &[f64], dt: f64, h0: f64) -> Result<Vec<f64>> {
    let mut x = vec![0.0; u.len()];
    simulate_extended_into(params, effects, u, dt, h0, &mut x)?;
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{paper_input, simulate};

    #[test]
    fn no_effect_is_the_base_model_exactly() {
        let dt = 1e-4;
        let u = paper_input(dt, 0.01);
        let p = Params::paper_1hz();
        let (base, _) = simulate(&p, &u, dt, 0.0, None).unwrap();
        let ext = simulate_extended(&p, &EffectSet::none(), &u, dt, 0.0).unwrap();
        assert_eq!(base, ext);
    }

    #[test]
    fn delay_and_drift_act_on_the_output_only() {
        let dt = 1e-3;
        let u: Vec<f64> = (0..500).map(|k| 50.0 + 40.0 * (k as f64 * 0.03).sin()).collect();
        let p = Params::paper_1hz();
        let base = simulate_extended(&p, &EffectSet::none(), &u, dt, 0.0).unwrap();
        let effects = EffectSet {
            delay: Some(Delay { samples: 3 }),
            drift: Some(Drift { rate_um_per_s: 2.0 }),
            ..EffectSet::none()
        };
        let x = simulate_extended(&p, &effects, &u, dt, 0.0).unwrap();
        for k in 3..u.len() {
            let want = base[k - 3] + 2.0 * (k - 3) as f64 * dt;
            assert!((x[k] - want).abs() < 1e-12);
        }
        assert_eq!(x[0], base[0]);
    }

    #[test]
    fn slow_lag_and_stiff_resonance_change_little_on_a_slow_input() {
        let dt = 1e-4;
        let u = paper_input(dt, 0.0);
        let u = &u[..20_000];
        let p = Params::paper_1hz();
        let base = simulate_extended(&p, &EffectSet::none(), u, dt, 0.0).unwrap();
        let effects = EffectSet {
            input_lag: Some(InputLag { fc_hz: 2000.0 }),
            resonance: Some(Resonance { fn_hz: 3000.0, zeta: 0.7 }),
            ..EffectSet::none()
        };
        let x = simulate_extended(&p, &effects, u, dt, 0.0).unwrap();
        let worst = x.iter().zip(&base).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        // 1 Hz, 100 V: lag ≈ 2π·1·50/(2π·2000) V ≈ 0.025 V → ≈ 0.005 µm; resonance less.
        assert!(worst < 0.02, "{worst}");
    }

    #[test]
    fn rejects_bad_effects_and_non_finite_input() {
        let p = Params::paper_1hz();
        let bad = EffectSet { input_lag: Some(InputLag { fc_hz: -1.0 }), ..EffectSet::none() };
        let err = simulate_extended(&p, &bad, &[0.0, 1.0], 1e-3, 0.0).unwrap_err();
        assert!(err.to_string().contains("input_lag.fc_hz"));
        assert!(simulate_extended(&p, &EffectSet::none(), &[0.0, f64::NAN], 1e-3, 0.0).is_err());
        let nyquist = EffectSet { resonance: Some(Resonance { fn_hz: 600.0, zeta: 0.1 }), ..EffectSet::none() };
        assert!(simulate_extended(&p, &nyquist, &[0.0, 1.0], 1e-3, 0.0).is_err());
    }

    #[test]
    fn names_follow_the_vocabulary_order() {
        let e = EffectSet {
            delay: Some(Delay { samples: 1 }),
            creep: Creep::log_spaced(0.1, 1.0, 2).ok(),
            ..EffectSet::none()
        };
        assert_eq!(e.names(), vec!["creep", "delay"]);
        let all = EffectSet {
            creep: Creep::log_spaced(0.1, 1.0, 2).ok(),
            input_lag: Some(InputLag { fc_hz: 100.0 }),
            resonance: Some(Resonance { fn_hz: 100.0, zeta: 0.1 }),
            drift: Some(Drift { rate_um_per_s: 0.0 }),
            delay: Some(Delay { samples: 1 }),
            gain_drift: Some(GainDrift { rate_per_s: 0.01 }),
            electrostriction: Some(Electrostriction { epsilon_per_um: 0.004 }),
            resonance2: Some(Resonance2 { fn_hz: 300.0, zeta: 0.2 }),
            pickup: Some(Pickup { line_hz: 50.0, sin_um: vec![0.1], cos_um: vec![0.0] }),
            saturation: Some(Saturation { min_um: -1.0, max_um: 30.0 }),
            between_samples: Some(BetweenSamples { input: Reconstruction::Hold }),
        };
        assert_eq!(all.names(), EffectSet::NAMES.to_vec());
        assert!(all.validate().is_ok());
        assert_eq!(all.unsupported(&["creep", "input_lag", "drift", "delay", "resonance", "resonance2"]).len(), 5);
    }

    fn sine_record(n: usize) -> Vec<f64> {
        (0..n).map(|k| 50.0 + 40.0 * (k as f64 * 0.02).sin()).collect()
    }

    #[test]
    fn gain_drift_and_electrostriction_shape_the_stack_output() {
        let dt = 1e-3;
        let u = sine_record(800);
        let p = Params::paper_1hz();
        let zero_h = EffectSet::none();
        // h of the base model: x − kv·u − x0.
        let base = simulate_extended(&p, &zero_h, &u, dt, 0.0).unwrap();
        let (r, eps) = (0.05, 0.004);
        let effects = EffectSet {
            gain_drift: Some(GainDrift { rate_per_s: r }),
            electrostriction: Some(Electrostriction { epsilon_per_um: eps }),
            ..EffectSet::none()
        };
        let x = simulate_extended(&p, &effects, &u, dt, 0.0).unwrap();
        for k in 0..u.len() {
            let h = base[k] - p.kv * u[k] - p.x0;
            let s = p.kv * (1.0 + r * k as f64 * dt) * u[k] + h;
            let want = p.x0 + s + eps * s * s;
            assert!((x[k] - want).abs() < 1e-12, "{k}: {} {want}", x[k]);
        }
    }

    #[test]
    fn pickup_and_saturation_act_on_the_reading_after_the_delay() {
        let dt = 1e-3;
        let u = sine_record(600);
        let p = Params::paper_1hz();
        let delayed = EffectSet { delay: Some(Delay { samples: 2 }), ..EffectSet::none() };
        let base = simulate_extended(&p, &delayed, &u, dt, 0.0).unwrap();
        let pickup = Pickup { line_hz: 60.0, sin_um: vec![0.3, 0.0, 0.05], cos_um: vec![-0.1, 0.02, 0.0] };
        let effects = EffectSet {
            pickup: Some(pickup.clone()),
            saturation: Some(Saturation { min_um: 2.0, max_um: 12.0 }),
            ..delayed
        };
        let x = simulate_extended(&p, &effects, &u, dt, 0.0).unwrap();
        let mut clipped = 0;
        for k in 0..u.len() {
            let t = k as f64 * dt;
            let w = 2.0 * core::f64::consts::PI * 60.0 * t;
            let line = 0.3 * w.sin() - 0.1 * w.cos() + 0.02 * (2.0 * w).cos() + 0.05 * (3.0 * w).sin();
            let want = (base[k] + line).clamp(2.0, 12.0);
            clipped += usize::from(want == 12.0 || want == 2.0);
            assert!((x[k] - want).abs() < 1e-9, "{k}");
        }
        assert!(clipped > 50, "{clipped}");
        let fast = EffectSet { pickup: Some(Pickup { line_hz: 200.0, ..pickup }), ..EffectSet::none() };
        assert!(simulate_extended(&p, &fast, &u, dt, 0.0).unwrap_err().to_string().contains("pickup.line_hz"));
    }

    #[test]
    fn a_second_mode_alone_is_the_first_and_two_modes_are_in_series() {
        let dt = 1e-4;
        let u = paper_input(dt, 0.0);
        let u = &u[..3000];
        let p = Params::paper_1hz();
        let one = EffectSet { resonance: Some(Resonance { fn_hz: 900.0, zeta: 0.05 }), ..EffectSet::none() };
        let two = EffectSet { resonance2: Some(Resonance2 { fn_hz: 900.0, zeta: 0.05 }), ..EffectSet::none() };
        assert_eq!(simulate_extended(&p, &one, u, dt, 0.0).unwrap(), simulate_extended(&p, &two, u, dt, 0.0).unwrap());
        // In series: modes far apart barely see each other's shape, so the output is
        // close to the first mode where the second is stiff.
        let both = EffectSet { resonance2: Some(Resonance2 { fn_hz: 4000.0, zeta: 0.7 }), ..one.clone() };
        let a = simulate_extended(&p, &one, u, dt, 0.0).unwrap();
        let b = simulate_extended(&p, &both, u, dt, 0.0).unwrap();
        let worst = a.iter().zip(&b).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst > 0.0 && worst < 0.05, "{worst}");
    }

    /// Every effect with a state: the lag, four creep elements, two modes, a delay,
    /// and the time-dependent ones (t must continue across the cut too).
    fn every_stateful_effect() -> EffectSet {
        EffectSet {
            creep: Some(Creep { tau_s: vec![0.01, 0.1, 1.0, 10.0], gain_um_per_v: vec![0.002; 4] }),
            input_lag: Some(InputLag { fc_hz: 650.0 }),
            gain_drift: Some(GainDrift { rate_per_s: 0.01 }),
            electrostriction: Some(Electrostriction { epsilon_per_um: 0.004 }),
            resonance: Some(Resonance { fn_hz: 900.0, zeta: 0.05 }),
            resonance2: Some(Resonance2 { fn_hz: 1700.0, zeta: 0.1 }),
            drift: Some(Drift { rate_um_per_s: 0.2 }),
            delay: Some(Delay { samples: 3 }),
            pickup: Some(Pickup { line_hz: 50.0, sin_um: vec![0.01], cos_um: vec![0.02] }),
            saturation: None,
            between_samples: None,
        }
    }

    #[test]
    fn a_record_in_pieces_is_the_record_in_one_call_bit_for_bit() {
        let dt = 1e-4;
        let u = paper_input(dt, 0.01);
        let p = Params::paper_1hz();
        for effects in [EffectSet::none(), every_stateful_effect()] {
            let whole = simulate_extended(&p, &effects, &u, dt, 0.3).unwrap();
            let (same, _) = simulate_extended_from(&p, &effects, &u, dt, &ExtendedState::initial(0.3)).unwrap();
            assert_eq!(same, whole);
            // Cuts at the start, in the 1 Hz part, in the 100 Hz part, one sample apart.
            let cuts = [0, 1, 12_345, 33_100, 33_101, u.len()];
            let mut state = ExtendedState::initial(0.3);
            let mut pieces = Vec::new();
            for w in cuts.windows(2) {
                let (x, next) = simulate_extended_from(&p, &effects, &u[w[0]..w[1]], dt, &state).unwrap();
                pieces.extend(x);
                state = next;
            }
            assert_eq!(pieces, whole, "{:?}", effects.names());
            assert_eq!(state.samples, u.len() as u64);
            assert_eq!(state.u_prev, u.last().copied());
        }
    }

    #[test]
    fn a_state_of_other_effects_or_with_a_non_finite_value_is_rejected() {
        let (p, dt) = (Params::paper_1hz(), 1e-4);
        let effects = every_stateful_effect();
        let (_, state) =
            simulate_extended_from(&p, &effects, &[0.0, 1.0, 2.0], dt, &ExtendedState::initial(0.0)).unwrap();
        assert_eq!(state.creep.len(), 4);
        assert_eq!(state.delay.len(), 4);
        let err = simulate_extended_from(&p, &EffectSet::none(), &[3.0], dt, &state).unwrap_err().to_string();
        assert!(err.contains("state.creep"), "{err}");
        let no_creep = EffectSet { creep: None, delay: Some(Delay { samples: 1 }), ..effects.clone() };
        let mut cut = state.clone();
        cut.creep.clear();
        let err = simulate_extended_from(&p, &no_creep, &[3.0], dt, &cut).unwrap_err().to_string();
        assert!(err.contains("state.delay"), "{err}");
        let bad = ExtendedState { h: f64::NAN, ..state.clone() };
        assert!(simulate_extended_from(&p, &effects, &[3.0], dt, &bad).is_err());
        let bad = ExtendedState { samples: 5, ..ExtendedState::initial(0.0) };
        assert!(simulate_extended_from(&p, &effects, &[3.0], dt, &bad)
            .unwrap_err()
            .to_string()
            .contains("state.samples"));
        // Other parameters: |h|^n is recomputed, not taken for another n.
        let q = Params { n: 1.3, ..p };
        let (x, _) = simulate_extended_from(&q, &effects, &[3.0, 4.0], dt, &state).unwrap();
        let mut fresh = state.clone();
        fresh.h_pow_n = None;
        assert_eq!(x, simulate_extended_from(&q, &effects, &[3.0, 4.0], dt, &fresh).unwrap().0);
    }

    #[test]
    fn the_model_gives_its_state_and_takes_one() {
        let (p, dt) = (Params::paper_1hz(), 1e-4);
        let u = sine_record(400);
        let mut a = ExtendedModel::new(p, every_stateful_effect(), dt, 0.0).unwrap();
        for &v in &u[..150] {
            a.step(v).unwrap();
        }
        let mut b = ExtendedModel::new(p, every_stateful_effect(), dt, 0.0).unwrap();
        b.set_state(&a.state()).unwrap();
        assert_eq!(b.state(), a.state());
        for &v in &u[150..] {
            assert_eq!(a.step(v).unwrap(), b.step(v).unwrap());
        }
    }
}
