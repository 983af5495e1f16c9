//! The signal chain of [`super::ExtendedModel`], written once, generic over the number
//! type: on `f64` it is the model, on [`Dual`] numbers it carries the derivatives of
//! the output with respect to the unknowns of a fit ([`super::jacobian`]).
//!
//! The hysteresis state h depends on A, β, γ, n, δ, h0 and (through the voltage on the
//! stack) ln fc only, so on duals it is integrated on [`NarrowDual`] — those seven
//! slots, the first seven of every wide layout ([`Slots`]) — and the stages after it
//! run on the full width.

use alloc::vec;
use alloc::vec::Vec;

use super::creep::CreepStage;
use super::delay::DelayLine;
use super::drift::trend;
use super::electrostriction::bend;
use super::gain_drift::gain_factor;
use super::input_lag::LagStage;
use super::pickup::line_pickup;
use super::resonance::{mode_stage_seeded, ModeNames, ResonanceStage};
use super::saturation::clip;
use super::state::ExtendedState;
use super::{EffectSet, RESONANCE_SUBSTEPS};
use crate::error::Result;
use crate::model::integrator::{abs_pow, advance_h_carrying, advance_seeded_carrying, Drive, Power};
use crate::model::scalar::{Dual, Scalar};
use crate::params::Params;
use crate::reconstruction::{InputPath, Reconstruction, KNOTS, PIECES};

/// Derivative slots of the hysteresis state: A, β, γ, n, δ, h0, ln fc.
pub(crate) const NARROW: usize = 7;
/// The duals h is integrated on.
pub(crate) type NarrowDual = Dual<NARROW>;
/// Slot of the first of A, β, γ, n, δ.
const SLOT_A: usize = 0;
/// Slot of h0.
pub(crate) const SLOT_H0: usize = 5;
/// Slot of ln fc of the input lag (the only derivative a voltage on the stack has).
pub(crate) const SLOT_LN_FC: usize = 6;
/// Slot of kv.
pub(crate) const SLOT_KV: usize = 7;
/// Slot of x0.
pub(crate) const SLOT_X0: usize = 8;
/// Slots every layout has (the base model's eight unknowns and ln fc).
pub(crate) const FIXED_SLOTS: usize = 9;

/// Derivative slots of the effects' unknowns after the fixed ones, in signal-chain
/// order: the first slot of each present effect's block.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Slots {
    /// The creep gains g_i.
    pub(crate) creep: usize,
    /// The gain_drift rate.
    pub(crate) gain_drift: usize,
    /// The electrostriction ε.
    pub(crate) epsilon: usize,
    /// ln fn, ln ζ of the first mode.
    pub(crate) resonance: usize,
    /// ln fn, ln ζ of the second mode.
    pub(crate) resonance2: usize,
    /// The drift rate.
    pub(crate) drift: usize,
    /// The pickup's sine amplitudes, then its cosine amplitudes.
    pub(crate) pickup: usize,
    /// The saturation's min, max.
    pub(crate) saturation: usize,
    /// Slots in all.
    pub(crate) total: usize,
}

impl Slots {
    /// The slots of the unknowns of `effects`.
    pub(crate) fn of(effects: &EffectSet) -> Self {
        let mut next = FIXED_SLOTS;
        let mut take = |count: usize| {
            let first = next;
            next += count;
            first
        };
        let creep = take(effects.creep.as_ref().map_or(0, |c| c.tau_s.len()));
        let gain_drift = take(usize::from(effects.gain_drift.is_some()));
        let epsilon = take(usize::from(effects.electrostriction.is_some()));
        let resonance = take(if effects.resonance.is_some() { 2 } else { 0 });
        let resonance2 = take(if effects.resonance2.is_some() { 2 } else { 0 });
        let drift = take(usize::from(effects.drift.is_some()));
        let pickup = take(effects.pickup.as_ref().map_or(0, |p| 2 * p.harmonics()));
        let saturation = take(if effects.saturation.is_some() { 2 } else { 0 });
        Slots { creep, gain_drift, epsilon, resonance, resonance2, drift, pickup, saturation, total: next }
    }
}

/// A number type the chain runs on: how a parameter enters it and how h advances.
pub(crate) trait ChainScalar: Scalar {
    /// The parameter value `v` as an unknown at derivative slot `slot` (`f64`: `v`).
    fn unknown(v: f64, slot: usize) -> Self;
    /// The input lag's stage for sub-intervals of `dt` \[s\], ln fc at [`SLOT_LN_FC`].
    fn lag_stage(lag: &super::InputLag, dt: f64) -> LagStage<Self>;
    /// The stage of the mode `(fn [Hz], ζ)` for sub-intervals of `dt` \[s\], ln fn and
    /// ln ζ at `slots`.
    fn mode_stage(mode: (f64, f64), dt: f64, names: ModeNames, slots: (usize, usize)) -> Result<ResonanceStage<Self>>;
    /// h after one interval of `dt` \[s\] in which u_a moves linearly from `ua0` to `ua1`
    /// \[V\], given |h|^n and ln|h| at the start (`None`: computed); also returns them at
    /// the end where the integrator carries them.
    fn advance_h(
        p: &Params,
        h: Self,
        power: Option<Power>,
        ua0: Self,
        ua1: Self,
        dt: f64,
        drive: Drive,
    ) -> (Self, Option<Power>);
}

impl ChainScalar for f64 {
    #[inline(always)]
    fn unknown(v: f64, _slot: usize) -> Self {
        v
    }
    fn lag_stage(lag: &super::InputLag, dt: f64) -> LagStage {
        lag.stage(dt)
    }
    fn mode_stage(mode: (f64, f64), dt: f64, names: ModeNames, _slots: (usize, usize)) -> Result<ResonanceStage> {
        super::resonance::mode_stage(mode.0, mode.1, dt, names)
    }
    /// The model's integrator, |h|^n carried as by [`crate::Model`].
    #[inline(always)]
    fn advance_h(
        p: &Params,
        h: f64,
        power: Option<Power>,
        ua0: f64,
        ua1: f64,
        dt: f64,
        drive: Drive,
    ) -> (f64, Option<Power>) {
        let hn = power.map_or_else(|| abs_pow(h, p.n), |(hn, _)| hn);
        let (next, carried) = advance_h_carrying(&drive.params(p), h, hn, ua0, ua1, dt);
        (next, Some((carried.unwrap_or_else(|| abs_pow(next, p.n)), 0.0)))
    }
}

/// What the command does over one sample interval.
enum Between {
    /// A straight line from the last sample to this one.
    Line,
    /// The last sample held, this one taken at the interval's end.
    Hold,
    /// Straight lines through the band-limited values at the [`KNOTS`] points of the
    /// interval.
    Knots([f64; KNOTS]),
}

/// The first [`NARROW`] slots of a wide dual.
#[inline(always)]
fn narrow<const M: usize>(v: Dual<M>) -> NarrowDual {
    NarrowDual::new(v.re, v.du.fixed_rows::<NARROW>(0).into_owned())
}

/// A narrow dual in the first [`NARROW`] slots of a wide one.
#[inline(always)]
fn widen<const M: usize>(v: NarrowDual) -> Dual<M> {
    let mut w = Dual::<M>::cst(v.re);
    w.du.fixed_rows_mut::<NARROW>(0).copy_from(&v.du);
    w
}

impl<const M: usize> ChainScalar for Dual<M> {
    #[inline(always)]
    fn unknown(v: f64, slot: usize) -> Self {
        Dual::var(v, slot)
    }
    fn lag_stage(lag: &super::InputLag, dt: f64) -> LagStage<Self> {
        LagStage::seeded(lag, dt, SLOT_LN_FC)
    }
    fn mode_stage(mode: (f64, f64), dt: f64, names: ModeNames, slots: (usize, usize)) -> Result<ResonanceStage<Self>> {
        mode_stage_seeded(mode.0, mode.1, dt, names, slots)
    }
    /// The integrator on [`NarrowDual`]s with A, β, γ, n, δ seeded at their slots and
    /// the voltage's derivative at [`SLOT_LN_FC`].
    #[inline(always)]
    fn advance_h(
        p: &Params,
        h: Self,
        power: Option<Power>,
        ua0: Self,
        ua1: Self,
        dt: f64,
        drive: Drive,
    ) -> (Self, Option<Power>) {
        let (next, carried) = advance_seeded_carrying::<NARROW, SLOT_A, SLOT_LN_FC>(
            p,
            narrow(h),
            power,
            narrow(ua0),
            narrow(ua1),
            dt,
            None,
            drive,
        );
        (widen(next), carried)
    }
}

/// The chain's parameters in the number type `S`, its state, and its step.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Chain<S> {
    params: Params,
    dt: f64,
    kv: S,
    x0: S,
    h0: S,
    /// What the command does between samples.
    input: Reconstruction,
    substeps: u32,
    lag: Option<LagStage<S>>,
    creep: Option<CreepStage<S>>,
    gain_drift: Option<S>,
    epsilon: Option<S>,
    resonance: Option<ResonanceStage<S>>,
    resonance2: Option<ResonanceStage<S>>,
    drift: Option<S>,
    /// The line frequency \[Hz\] and the sine and cosine amplitudes \[µm\].
    pickup: Option<(f64, Vec<S>, Vec<S>)>,
    /// min, max \[µm\].
    saturation: Option<(S, S)>,
    delay: DelayLine<S>,
    // state
    started: bool,
    samples: u64,
    u_prev: f64,
    ua_prev: S,
    h: S,
    /// |h|^n and ln|h| for the current h where carried.
    power: Option<Power>,
    creep_states: Vec<S>,
    y_prev: S,
    z: [S; 2],
    z2: [S; 2],
}

impl<S: ChainScalar> Chain<S> {
    /// The chain of `params` and `effects` (both validated by the caller) for samples
    /// every `dt` \[s\] from h = `h0` \[µm\], the unknowns at `slots`.
    pub(crate) fn new(params: Params, effects: &EffectSet, dt: f64, h0: f64, slots: &Slots) -> Result<Self> {
        let resonant = effects.resonance.is_some() || effects.resonance2.is_some();
        let input = effects.input();
        let substeps = if input == Reconstruction::Bandlimited {
            PIECES as u32
        } else if resonant {
            RESONANCE_SUBSTEPS
        } else {
            1
        };
        let dt_sub = dt / substeps as f64;
        let mode = |fn_hz: f64, zeta: f64, names: ModeNames, first: usize| -> Result<ResonanceStage<S>> {
            S::mode_stage((fn_hz, zeta), dt, names, (first, first + 1))?; // fn below the samples' Nyquist frequency
            S::mode_stage((fn_hz, zeta), dt_sub, names, (first, first + 1))
        };
        let resonance = match &effects.resonance {
            Some(r) => Some(mode(r.fn_hz, r.zeta, super::resonance::NAMES, slots.resonance)?),
            None => None,
        };
        let resonance2 = match &effects.resonance2 {
            Some(r) => Some(mode(r.fn_hz, r.zeta, super::resonance2::NAMES, slots.resonance2)?),
            None => None,
        };
        if let Some(p) = &effects.pickup {
            p.check_sampling(dt)?;
        }
        let creep = effects.creep.as_ref().map(|c| c.stage(dt_sub, |i, g| S::unknown(g, slots.creep + i)));
        let unknowns = |values: &[f64], first: usize| -> Vec<S> {
            values.iter().enumerate().map(|(i, &v)| S::unknown(v, first + i)).collect()
        };
        let h0 = S::unknown(h0, SLOT_H0);
        Ok(Chain {
            params,
            dt,
            kv: S::unknown(params.kv, SLOT_KV),
            x0: S::unknown(params.x0, SLOT_X0),
            h0,
            input,
            substeps,
            lag: effects.input_lag.map(|l| S::lag_stage(&l, dt_sub)),
            creep_states: vec![S::cst(0.0); effects.creep.as_ref().map_or(0, |c| c.tau_s.len())],
            creep,
            gain_drift: effects.gain_drift.map(|g| S::unknown(g.rate_per_s, slots.gain_drift)),
            epsilon: effects.electrostriction.map(|e| S::unknown(e.epsilon_per_um, slots.epsilon)),
            resonance,
            resonance2,
            drift: effects.drift.map(|d| S::unknown(d.rate_um_per_s, slots.drift)),
            pickup: effects.pickup.as_ref().map(|p| {
                let k = p.harmonics();
                (p.line_hz, unknowns(&p.sin_um, slots.pickup), unknowns(&p.cos_um, slots.pickup + k))
            }),
            saturation: effects
                .saturation
                .map(|s| (S::unknown(s.min_um, slots.saturation), S::unknown(s.max_um, slots.saturation + 1))),
            delay: DelayLine::new(effects.delay.map_or(0, |d| d.samples)),
            started: false,
            samples: 0,
            u_prev: 0.0,
            ua_prev: S::cst(0.0),
            h: h0,
            power: None,
            y_prev: S::cst(0.0),
            z: [S::cst(0.0); 2],
            z2: [S::cst(0.0); 2],
        })
    }

    /// The current hysteresis state h \[µm\].
    pub(crate) fn h(&self) -> S {
        self.h
    }

    /// The stack's displacement without creep \[µm\] at time `t` \[s\]: x0 + s (+ ε·s²),
    /// s = kv(t)·u_a + h; the output equation (3) itself where neither gain_drift nor
    /// electrostriction is present.
    #[inline]
    fn stack_output(&self, ua: S, h: S, t: f64) -> S {
        stack_output_of(self.kv, self.x0, self.gain_drift, self.epsilon, ua, h, t)
    }

    /// Takes the commanded voltage `u` \[V\] (finite) of the next sample; returns the
    /// sensor's displacement x \[µm\]. The command between the samples is held or a
    /// straight line (a band-limited one needs the record: [`Chain::step_along`]).
    pub(crate) fn step(&mut self, u: f64) -> S {
        match self.input {
            Reconstruction::Hold => self.step_between(u, Between::Hold),
            _ => self.step_between(u, Between::Line),
        }
    }

    /// [`Chain::step`] for sample `k` of a record whose band-limited `path` (the
    /// command's, where the input between samples is band-limited) gives the command
    /// between samples.
    pub(crate) fn step_along(&mut self, u: f64, path: Option<&InputPath>, k: usize) -> S {
        match path {
            // The first sample of a record that continues a state runs from the state's
            // last command, which the path does not hold: a straight line there.
            Some(path) if k >= 1 => self.step_between(u, Between::Knots(path.knots(k))),
            Some(_) => self.step_between(u, Between::Line),
            None => self.step(u),
        }
    }

    /// The step of [`Chain::step`] with the command between the samples given.
    fn step_between(&mut self, u: f64, between: Between) -> S {
        let t = self.samples as f64 * self.dt;
        let y = if !self.started {
            self.started = true;
            let ua = S::cst(u);
            if let Some(c) = &self.creep {
                self.creep_states = c.rest(ua);
            }
            self.ua_prev = ua;
            let creep = self.creep_states.iter().fold(S::cst(0.0), |a, &c| a + c);
            let y = self.stack_output(ua, self.h, t) + creep;
            self.z = [y, S::cst(0.0)];
            self.z2 = self.z;
            y
        } else {
            let m = self.substeps;
            let dt_sub = self.dt / m as f64;
            let mut y = self.y_prev;
            let t_prev = t - self.dt;
            let mut c = self.creep_states.iter().fold(S::cst(0.0), |a, &c| a + c);
            for j in 1..=m {
                let (u0, u1) = match &between {
                    Between::Line => {
                        let u0 = self.u_prev + (u - self.u_prev) * ((j - 1) as f64 / m as f64);
                        (u0, if j == m { u } else { self.u_prev + (u - self.u_prev) * (j as f64 / m as f64) })
                    }
                    Between::Hold => (self.u_prev, self.u_prev),
                    Between::Knots(knots) => (knots[j as usize - 1], knots[j as usize]),
                };
                let ua = match &self.lag {
                    Some(lag) => lag.advance(self.ua_prev, S::cst(u0), S::cst(u1), dt_sub),
                    None => S::cst(u1),
                };
                let drive = Drive::of(u0, u1);
                (self.h, self.power) = S::advance_h(&self.params, self.h, self.power, self.ua_prev, ua, dt_sub, drive);
                c = match &self.creep {
                    Some(creep) => creep.advance(&mut self.creep_states, self.ua_prev, ua, dt_sub),
                    None => S::cst(0.0),
                };
                let t_j = if j == m { t } else { t_prev + self.dt * (j as f64 / m as f64) };
                let y_next = self.stack_output(ua, self.h, t_j) + c;
                let z_prev = self.z[0];
                self.z = match &self.resonance {
                    Some(r) => r.advance(self.z, y, y_next),
                    None => [y_next, S::cst(0.0)],
                };
                if let Some(r) = &self.resonance2 {
                    self.z2 = r.advance(self.z2, z_prev, self.z[0]);
                }
                self.ua_prev = ua;
                y = y_next;
            }
            if matches!(between, Between::Hold) && self.lag.is_none() && u != self.u_prev {
                // The held command steps to u at t_k and the stack with it: h follows the
                // step along the loop (the δ term, a rate, adds nothing in no time); the
                // creep and the modes, continuous, do not move in no time.
                let ua = S::cst(u);
                (self.h, self.power) =
                    S::advance_h(&self.params, self.h, self.power, self.ua_prev, ua, dt_sub, Drive::Held);
                self.ua_prev = ua;
                y = self.stack_output(ua, self.h, t) + c;
                if self.resonance.is_none() {
                    self.z = [y, S::cst(0.0)];
                }
            }
            y
        };
        self.u_prev = u;
        self.y_prev = y;
        self.samples += 1;
        let drift = self.drift.map_or(S::cst(0.0), |rate| trend(rate, t));
        let z = if self.resonance2.is_some() { self.z2[0] } else { self.z[0] };
        let mut x = self.delay.push(z + drift);
        if let Some((line_hz, sin_um, cos_um)) = &self.pickup {
            x = x + line_pickup(*line_hz, sin_um, cos_um, t);
        }
        if let Some((min, max)) = self.saturation {
            x = clip(x, min, max);
        }
        x
    }

    /// The same chain (effects, dt and the unknowns' slots kept) from the Bouc–Wen
    /// parameters `params` (validated by the caller) and h = `h0` \[µm\], the past
    /// forgotten: what [`Chain::new`] gives, without allocating (a fit's evaluations
    /// reuse one chain).
    pub(crate) fn restart(&mut self, params: Params, h0: f64) {
        self.params = params;
        self.kv = S::unknown(params.kv, SLOT_KV);
        self.x0 = S::unknown(params.x0, SLOT_X0);
        self.h0 = S::unknown(h0, SLOT_H0);
        self.reset();
    }

    /// Forgets the past (h = h0, no previous sample, t = 0).
    pub(crate) fn reset(&mut self) {
        self.started = false;
        self.samples = 0;
        self.h = self.h0;
        self.power = None;
        self.creep_states.iter_mut().for_each(|c| *c = S::cst(0.0));
        self.delay.reset();
    }
}

impl Chain<f64> {
    /// What the chain carries to the next sample.
    pub(crate) fn state(&self) -> ExtendedState {
        if !self.started {
            return ExtendedState { samples: self.samples, ..ExtendedState::initial(self.h) };
        }
        ExtendedState {
            samples: self.samples,
            u_prev: Some(self.u_prev),
            ua: self.ua_prev,
            h: self.h,
            h_pow_n: self.power.map(|(hn, _)| (self.params.n, hn)),
            creep: self.creep_states.clone(),
            y: self.y_prev,
            resonance: self.z,
            resonance2: self.z2,
            delay: self.delay.values(),
        }
    }

    /// Takes `state` (made by [`Chain::state`] for the same effects, or
    /// [`ExtendedState::initial`]); the next [`Chain::step`] continues from it.
    pub(crate) fn set_state(&mut self, state: &ExtendedState) -> Result<()> {
        state.check(self.creep_states.len(), self.delay.samples())?;
        self.samples = state.samples;
        self.h = state.h;
        self.power = match state.h_pow_n {
            Some((n, hn)) if n == self.params.n => Some((hn, 0.0)),
            _ => None,
        };
        match state.u_prev {
            None => {
                self.started = false;
                self.creep_states.iter_mut().for_each(|c| *c = 0.0);
                self.delay.reset();
            }
            Some(u_prev) => {
                self.started = true;
                self.u_prev = u_prev;
                self.ua_prev = state.ua;
                self.creep_states.copy_from_slice(&state.creep);
                self.y_prev = state.y;
                self.z = state.resonance;
                self.z2 = state.resonance2;
                self.delay.set_values(&state.delay);
            }
        }
        Ok(())
    }
}

/// The stack's displacement without creep \[µm\] at time `t` \[s\] for the gain `kv`
/// \[µm/V\], offset `x0` \[µm\], gain_drift rate and electrostriction ε where present,
/// voltage on the stack `ua` \[V\] and hysteresis state `h` \[µm\]: see
/// [`super::stack_output`].
#[inline]
pub(crate) fn stack_output_of<S: Scalar>(
    kv: S,
    x0: S,
    gain_drift: Option<S>,
    epsilon: Option<S>,
    ua: S,
    h: S,
    t: f64,
) -> S {
    if gain_drift.is_none() && epsilon.is_none() {
        return kv * ua + x0 + h;
    }
    let kv = gain_drift.map_or(kv, |rate| kv * gain_factor(rate, t));
    let s = kv * ua + h;
    x0 + epsilon.map_or(s, |e| bend(e, s))
}
