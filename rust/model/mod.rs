//! The asymmetric Bouc–Wen operator, its integrator and the per-sample model.
//!
//! ```text
//! x(t)  = kv·u(t) + x0 + h(t)                                   (3)
//! dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)    (5)
//! ```
//!
//! - [`integrator`]: the one integrator of eq. (5) (sub-step rule and stages), generic
//!   over the number type so that the sensitivities take the same steps;
//! - [`scalar`]: `f64` and the forward-mode [`scalar::Dual`] it runs on;
//! - `lanes`: several channels side by side, for the integrator's branch-free path (the bank);
//! - here: the output equation, the per-sample [`Model`], [`simulate`] and the paper's input.

pub mod integrator;
pub(crate) mod lanes;
pub mod scalar;

use alloc::vec;
use alloc::vec::Vec;

use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::format::{corrupt, Reader, Snapshot, Writer, KIND_MODEL};
use crate::math;
use crate::params::Params;

use integrator::{abs_pow, advance_h_carried};
pub use integrator::{
    advance, advance_h, hysteresis_rate, interval_plan, sgn, Coefficients, H_LIMIT_UM, IMPLICIT_SUBSTEPS,
    IMPLICIT_TOLERANCE_UM, MAX_SUBSTEPS, MIN_SUBSTEPS, NEWTON_ITERATIONS, STIFFNESS_STEP, TRIAL_ABOVE_SUBSTEPS,
};

/// Output equation (3): x = kv·u + x0 + h \[µm\].
#[inline(always)]
pub fn output(p: &Params, u: f64, h: f64) -> f64 {
    p.kv * u + p.x0 + h
}

/// The state a [`Model`] carries between samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelState {
    /// Hysteresis state h \[µm\] at the last sample.
    pub h: f64,
    /// The last voltage \[V\]; `None` before the first sample.
    pub u_prev: Option<f64>,
}

/// A per-sample model for control loops: `step(u) -> x`.
///
/// The first sample has no predecessor, so h keeps its initial value there; each
/// later sample integrates eq. (5) from the previous voltage to the new one.
///
/// |h|^n is carried from sample to sample: from the interval's series where h moved by
/// at most 0.1 % of itself (within rounding of `powf`), else by `powf`. It is computed
/// afresh from h wherever the state or the parameters are set, and saved in
/// snapshots, so a restored model continues bit for bit.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    params: Params,
    dt: f64,
    state: ModelState,
    /// |h|^n for the current h.
    hn: f64,
}

impl Model {
    /// A model with parameters `params`, sampling interval `dt` \[s\] and initial h `h0` \[µm\].
    pub fn new(params: Params, dt: f64, h0: f64) -> Result<Self> {
        params.validate()?;
        positive_dt(dt)?;
        finite_sample("h0", h0)?;
        Ok(Model { params, dt, state: ModelState { h: h0, u_prev: None }, hn: abs_pow(h0, params.n) })
    }

    /// Takes the voltage `u` \[V\] of the next sample and returns the displacement x \[µm\].
    /// A non-finite `u` is rejected and the state kept. Allocation-free.
    #[inline]
    pub fn step(&mut self, u: f64) -> Result<f64> {
        finite_sample("u", u)?;
        Ok(self.step_finite(u))
    }

    /// [`Model::step`] for a `u` known to be finite.
    #[inline(always)]
    fn step_finite(&mut self, u: f64) -> f64 {
        if let Some(u_prev) = self.state.u_prev {
            (self.state.h, self.hn) = advance_h_carried(&self.params, self.state.h, self.hn, u_prev, u, self.dt);
        }
        self.state.u_prev = Some(u);
        output(&self.params, u, self.state.h)
    }

    /// Current parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Replaces the parameters (validated); the state is kept.
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        params.validate()?;
        if params.n != self.params.n {
            self.hn = abs_pow(self.state.h, params.n);
        }
        self.params = params;
        Ok(())
    }

    /// Sampling interval \[s\].
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Current hysteresis state h \[µm\].
    pub fn h(&self) -> f64 {
        self.state.h
    }

    /// The state carried between samples.
    pub fn state(&self) -> ModelState {
        self.state
    }

    /// Restores a state taken with [`Model::state`].
    pub fn set_state(&mut self, state: ModelState) -> Result<()> {
        finite_sample("h", state.h)?;
        if let Some(u) = state.u_prev {
            finite_sample("u_prev", u)?;
        }
        self.state = state;
        self.hn = abs_pow(state.h, self.params.n);
        Ok(())
    }

    /// Sets the carried |h|^n (a bank channel handed over as a single model).
    pub(crate) fn set_carried_power(&mut self, hn: f64) {
        self.hn = hn;
    }

    /// Forgets the past: h = `h0`, no previous sample.
    pub fn reset(&mut self, h0: f64) -> Result<()> {
        self.set_state(ModelState { h: h0, u_prev: None })
    }
}

/// Simulates a whole record into `x_out` and returns the final h \[µm\].
///
/// `x_out[k] = kv·u[k] + x0 + h[k]`. With `u_prev = None`, h\[0\] = `h0`; with
/// `Some(v)`, the first interval runs from v to u\[0\] starting at h = `h0`, so a long
/// record can be streamed in chunks (pass the previous chunk's final h and last u)
/// with the result of one call to the last bits: |h|^n, carried from sample to sample
/// within a call, is computed afresh from h at a cut (a few ulps of x at most; a
/// [`Model`] carries it and continues bit for bit). Input with a non-finite value is
/// rejected before anything is computed.
pub fn simulate_into(
    params: &Params,
    u: &[f64],
    dt: f64,
    h0: f64,
    u_prev: Option<f64>,
    x_out: &mut [f64],
) -> Result<f64> {
    if x_out.len() != u.len() {
        return Err(Error::LengthMismatch { what: "simulate output", expected: u.len(), found: x_out.len() });
    }
    let mut model = Model::new(*params, dt, h0)?;
    model.set_state(ModelState { h: h0, u_prev })?;
    for &v in u {
        finite_sample("u", v)?;
    }
    let (p, mut h, mut hn) = (&model.params, model.state.h, model.hn);
    let mut last = u_prev;
    for (x, &v) in x_out.iter_mut().zip(u) {
        if let Some(w) = last {
            (h, hn) = advance_h_carried(p, h, hn, w, v, dt);
        }
        last = Some(v);
        *x = output(p, v, h);
    }
    Ok(h)
}

/// Allocating form of [`simulate_into`]: returns `(x, h_final)`.
pub fn simulate(params: &Params, u: &[f64], dt: f64, h0: f64, u_prev: Option<f64>) -> Result<(Vec<f64>, f64)> {
    let mut x = vec![0.0; u.len()];
    let h = simulate_into(params, u, dt, h0, u_prev, &mut x)?;
    Ok((x, h))
}

/// The paper's input, u = 50 + 50·sin(2πft − π/2), sampled every `dt` \[s\], with
/// f = 1 Hz for t < 3 s, 10 Hz up to 3.3 s, 100 Hz up to 3.33 s and 200 Hz for
/// `tail_s` seconds after that: [`sine_segments`] of [`paper_segments`].
pub fn paper_input(dt: f64, tail_s: f64) -> Vec<f64> {
    sine_segments(dt, &paper_segments(tail_s))
}

/// The paper's segments as (frequency \[Hz\], duration \[s\]) pairs: 1 Hz for 3 s,
/// 10 Hz for 0.3 s, 100 Hz for 0.03 s, 200 Hz for `tail_s`.
pub fn paper_segments(tail_s: f64) -> [(f64, f64); 4] {
    [(1.0, 3.0), (10.0, 0.3), (100.0, 0.03), (200.0, tail_s)]
}

/// u = 50 + 50·sin(2πf·(t − t_i) − π/2) \[V\] at t = k·dt \[s\], k = 0 … round(T/dt) − 1
/// (T the total duration), where segment i of `segments` ((f \[Hz\], duration \[s\])
/// pairs, in order) starts at t_i, the sum of the durations before it (rounded once). A
/// segment of a whole number of periods ends on a minimum (u = 0), where the next one
/// starts, so u is continuous; the caller checks that (the sample of a segment's start
/// is taken within 1e-12 s).
pub fn sine_segments(dt: f64, segments: &[(f64, f64)]) -> Vec<f64> {
    // The starts and the total as compensated (Neumaier) sums: the double nearest the
    // exact sum of the durations, so that 3 + 0.3 + 0.03 s is the double of 3.33 s.
    let mut starts = Vec::with_capacity(segments.len());
    let (mut sum, mut carry) = (0.0_f64, 0.0_f64);
    for &(_, d) in segments {
        starts.push(sum + carry);
        let next = sum + d;
        carry += if sum.abs() >= d.abs() { (sum - next) + d } else { (d - next) + sum };
        sum = next;
    }
    let total = sum + carry;
    let count = math::round(total / dt) as usize;
    (0..count)
        .map(|k| {
            let t = k as f64 * dt;
            let (f, start) = segments
                .iter()
                .zip(&starts)
                .rev()
                .find(|&(_, &start)| t >= start - 1e-12)
                .map_or((segments[0].0, 0.0), |(&(f, _), &start)| (f, start));
            50.0 + 50.0 * math::sin(2.0 * core::f64::consts::PI * f * (t - start) - core::f64::consts::FRAC_PI_2)
        })
        .collect()
}

impl Snapshot for Model {
    fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new(KIND_MODEL);
        w.params(self.params());
        w.f64(self.dt());
        let s = self.state();
        w.f64(s.h);
        w.opt_f64(s.u_prev);
        w.f64(self.hn);
        w.finish()
    }

    fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let mut r = Reader::new(bytes, KIND_MODEL)?;
        let params = r.params()?;
        let at = r.offset();
        let dt = r.f64()?;
        let h = r.finite()?;
        let u_prev = r.opt_f64()?;
        let at_hn = r.offset();
        let hn = r.finite()?;
        r.end()?;
        let mut m = Model::new(params, dt, h).map_err(|_| corrupt(at, "snapshot holds an invalid time step"))?;
        m.set_state(ModelState { h, u_prev })?;
        // The carried |h|^n is h's own to rounding (see `advance_h_carried`).
        if (hn - m.hn).abs() > 1e-9 * m.hn {
            return Err(corrupt(at_hn, "snapshot holds an |h|^n that is not that of its h"));
        }
        m.hn = hn;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference: RK4 with 1000× finer steps (2000 sub-steps per sample).
    fn fine(p: &Params, u: &[f64], dt: f64) -> Vec<f64> {
        let fine_dt = dt / 2000.0;
        let mut h = 0.0;
        let mut x = vec![output(p, u[0], h)];
        for w in u.windows(2) {
            let udot = (w[1] - w[0]) / dt;
            for i in 0..2000 {
                let ua = w[0] + udot * fine_dt * i as f64;
                let k1 = hysteresis_rate(p, h, ua, udot);
                let k2 = hysteresis_rate(p, h + 0.5 * fine_dt * k1, ua + 0.5 * udot * fine_dt, udot);
                let k3 = hysteresis_rate(p, h + 0.5 * fine_dt * k2, ua + 0.5 * udot * fine_dt, udot);
                let k4 = hysteresis_rate(p, h + fine_dt * k3, ua + udot * fine_dt, udot);
                h += fine_dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
            }
            x.push(output(p, w[1], h));
        }
        x
    }

    #[test]
    fn matches_a_1000x_finer_solution_on_the_paper_input() {
        let dt = 1e-4;
        let u = paper_input(dt, 0.02);
        let p = Params::paper_1hz();
        let (x, _) = simulate(&p, &u, dt, 0.0, None).unwrap();
        let reference = fine(&p, &u, dt);
        let worst = x.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        eprintln!("max deviation from the 1000x finer solution: {worst:.3e} µm");
        assert!(worst <= 1e-4, "max deviation {worst} µm");
    }

    #[test]
    fn chunks_give_the_same_result_as_one_call() {
        let dt = 1e-4;
        let u = paper_input(dt, 0.01);
        let p = Params::paper_1hz();
        let (whole, h_whole) = simulate(&p, &u, dt, 0.0, None).unwrap();
        let (a, h_a) = simulate(&p, &u[..1234], dt, 0.0, None).unwrap();
        let (b, h_b) = simulate(&p, &u[1234..], dt, h_a, Some(u[1233])).unwrap();
        // |h|^n is computed afresh at the cut: the same to the last bits.
        let worst = [a, b].concat().iter().zip(&whole).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(worst <= 1e-12 && (h_b - h_whole).abs() <= 1e-12, "{worst}");
    }

    #[test]
    fn the_carried_power_stays_within_rounding_of_powf() {
        // Slow motion (the 1 Hz part at 100 kHz, h moving ≤ 0.1 % a sample almost
        // everywhere): |h|^n is carried across most samples and must not drift.
        let dt = 1e-5;
        let u = paper_input(dt, 0.0);
        let mut m = Model::new(Params::paper_1hz(), dt, 0.0).unwrap();
        let (mut carried, mut worst) = (0usize, 0.0f64);
        for &v in &u[..300_000] {
            let h_before = m.h();
            m.step(v).unwrap();
            let exact = abs_pow(m.h(), m.params.n);
            carried += usize::from(m.h() != h_before && m.hn != exact);
            if exact > 0.0 {
                worst = worst.max((m.hn - exact).abs() / exact);
            }
        }
        eprintln!("carried {carried} of 300000, worst relative {worst:e}");
        assert!(carried > 10_000, "{carried}");
        assert!(worst <= 1e-13, "{worst:e}");
    }

    #[test]
    fn runaway_parameters_stay_finite() {
        let p = Params { beta: -0.5, gamma: -0.5, n: 3.0, ..Params::paper_1hz() };
        let u = paper_input(1e-4, 0.01);
        let (x, h) = simulate(&p, &u, 1e-4, 0.0, None).unwrap();
        assert!(x.iter().all(|v| v.is_finite()) && h.abs() <= H_LIMIT_UM);
    }

    #[test]
    fn rejects_non_finite_input_and_keeps_state() {
        let mut m = Model::new(Params::paper_1hz(), 1e-4, 0.0).unwrap();
        m.step(1.0).unwrap();
        m.step(2.0).unwrap();
        let before = m.clone();
        assert!(m.step(f64::NAN).is_err());
        assert_eq!(m, before);
    }

    #[test]
    fn model_round_trips_and_rejects_garbage() {
        let mut m = Model::new(Params::paper_1hz(), 1e-4, 0.0).unwrap();
        for k in 0..100 {
            m.step((k as f64 * 0.1).sin() * 40.0).unwrap();
        }
        let bytes = m.to_bytes();
        let r = Model::from_bytes(&bytes).unwrap();
        assert_eq!(r, m);
        for cut in 0..bytes.len() {
            assert!(Model::from_bytes(&bytes[..cut]).is_err());
        }
        let mut bad = bytes.clone();
        bad[6 + 5 * 8..6 + 6 * 8].copy_from_slice(&(-1.0f64).to_bits().to_le_bytes()); // n = -1
        assert!(Model::from_bytes(&bad).is_err());
        let mut bad = bytes.clone();
        let end = bad.len();
        bad[end - 8..].copy_from_slice(&(2.0 * m.hn).to_bits().to_le_bytes()); // |h|^n not h's
        assert!(Model::from_bytes(&bad).is_err());
        assert!(crate::identify::AnyIdentifier::from_snapshot(&bytes).is_err());
    }
}
