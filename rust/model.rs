//! The asymmetric Bouc–Wen operator, its integrator and the per-sample model.
//!
//! ```text
//! x(t)  = kv·u(t) + x0 + h(t)                                   (3)
//! dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)    (5)
//! ```
//!
//! Between two samples the voltage is taken as a straight line, so u̇ is constant
//! within a sample interval and `sgn(0) = 0` makes h stand still while u holds.
//! `|h|^(n−1)·h` is evaluated as `sgn(h)·|h|^n`, exactly 0 at h = 0 for every n > 0.
//!
//! The integrator is classic RK4 on sub-steps. An interval takes one step, or
//! [`MIN_SUBSTEPS`] where h may cross zero (|h|^n is not smooth there, and one step
//! across the kink loses order), and more as the local stiffness
//! |∂ḣ/∂h| = n·(|β|+|γ|)·|u̇|·|h|^(n−1) (at the start of the interval, and at an
//! explicit-Euler end point when h moves far in one interval) so that every sub-step has
//! |∂ḣ/∂h|·Δt ≤ [`STIFFNESS_STEP`], well inside RK4's stability region, up to
//! [`MAX_SUBSTEPS`]; stiffer intervals take [`IMPLICIT_SUBSTEPS`] backward-Euler
//! steps (Newton, at most 4 iterations each) instead, which are stable for any stiffness. For parameters with no bounded solution (β + γ < 0 lets h
//! run away), h is held within ±[`H_LIMIT_UM`] so that the output stays finite.

use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::params::Params;

/// RK4 sub-steps for an interval in which h may cross zero.
pub const MIN_SUBSTEPS: u32 = 2;
/// Most RK4 sub-steps per sample interval.
pub const MAX_SUBSTEPS: u32 = 32;
/// Backward-Euler sub-steps per interval when RK4 would need more than [`MAX_SUBSTEPS`].
pub const IMPLICIT_SUBSTEPS: u32 = 32;
/// Largest |∂ḣ/∂h|·Δt allowed in one RK4 sub-step (set for accuracy: stability
/// alone would allow about 2.5).
pub const STIFFNESS_STEP: f64 = 0.25;
/// |h| is held within this bound [µm] (no piezo stack moves a centimetre).
pub const H_LIMIT_UM: f64 = 1.0e4;

/// sgn with sgn(0) = 0.
#[inline(always)]
pub fn sgn(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// |h|^n, exactly 0 at h = 0.
#[inline(always)]
fn abs_pow(h: f64, n: f64) -> f64 {
    let a = h.abs();
    if a == 0.0 {
        0.0
    } else {
        a.powf(n)
    }
}

/// dh/dt of eq. (5) [µm/s] at hysteresis state `h` [µm], voltage `u` [V] and rate `udot` [V/s].
#[inline(always)]
pub fn hysteresis_rate(p: &Params, h: f64, u: f64, udot: f64) -> f64 {
    let hn = abs_pow(h, p.n);
    p.a * udot - (p.beta * udot.abs() * sgn(h) + p.gamma * udot) * hn + p.delta * u * sgn(udot)
}

/// ∂(dh/dt)/∂h [1/s].
#[inline(always)]
fn rate_slope(p: &Params, h: f64, udot: f64) -> f64 {
    let a = h.abs();
    if a == 0.0 {
        return 0.0;
    }
    -(p.beta * udot.abs() + p.gamma * udot * sgn(h)) * p.n * a.powf(p.n - 1.0)
}

/// One backward-Euler step of length `step` (Newton, a few iterations): stable for
/// any stiffness, used only when RK4 would need more than [`MAX_SUBSTEPS`].
#[inline]
fn implicit_step(p: &Params, h0: f64, u_end: f64, udot: f64, step: f64) -> f64 {
    let mut h = h0;
    for _ in 0..4 {
        let g = h - h0 - step * hysteresis_rate(p, h, u_end, udot);
        let dg = (1.0 - step * rate_slope(p, h, udot)).max(1.0);
        let next = h - g / dg;
        if !next.is_finite() {
            break;
        }
        let done = (next - h).abs() <= 1e-12 * (1.0 + h.abs());
        h = next;
        if done {
            break;
        }
    }
    h
}

/// How many RK4 sub-steps the interval needs (`None`: more than [`MAX_SUBSTEPS`]),
/// given h, the rate `k1` = ḣ at the start of the interval and |h|^n = `hn`.
#[inline(always)]
fn substeps(p: &Params, h: f64, k1: f64, hn: f64, udot: f64, dt: f64) -> Option<u32> {
    let a = h.abs();
    let slope_weight = p.n * (p.beta.abs() + p.gamma.abs()) * udot.abs() * dt;
    let mut stiffness_dt = if a > 0.0 {
        slope_weight * (hn / a)
    } else if p.n < 1.0 {
        f64::INFINITY
    } else if p.n == 1.0 {
        slope_weight
    } else {
        0.0
    };
    // Where h may move by more than a tenth of itself in the interval, the
    // stiffness at its start says little: take the larger of it and the
    // stiffness at the explicit-Euler end point.
    let h_end = h + dt * k1;
    if (h_end - h).abs() > 0.1 * a {
        let b = h_end.abs();
        if b > 0.0 {
            stiffness_dt = stiffness_dt.max(slope_weight * b.powf(p.n - 1.0));
        }
    }
    // |h|^n is not smooth at h = 0: an interval where h may cross zero gets
    // MIN_SUBSTEPS sub-steps, the others one, unless stiffness asks for more.
    let may_cross = h == 0.0 || h_end * h <= 0.0;
    let floor = if may_cross { MIN_SUBSTEPS } else { 1 };
    let wanted = stiffness_dt / STIFFNESS_STEP;
    // ceil(wanted), with the usual cases decided by comparisons (no libm call).
    let m = if wanted <= 1.0 {
        1
    } else if wanted <= 2.0 {
        2
    } else if wanted.is_nan() || wanted > MAX_SUBSTEPS as f64 {
        return None;
    } else {
        wanted.ceil() as u32
    };
    Some(m.max(floor))
}

/// dh/dt of eq. (5) and |h|^n, at the start of an interval.
#[inline(always)]
fn rate_and_power(p: &Params, h: f64, u: f64, udot: f64) -> (f64, f64) {
    let hn = abs_pow(h, p.n);
    (p.a * udot - (p.beta * udot.abs() * sgn(h) + p.gamma * udot) * hn + p.delta * u * sgn(udot), hn)
}

/// |h|^n near a reference state h_ref by its binomial series,
/// |h|^n = |h_ref|^n·(1 + ε)^n with ε = (|h| − |h_ref|)/|h_ref|, to ε⁴.
///
/// The RK4 stages of one interval sit close to its starting h, so one `powf`
/// per interval serves all of them. The series is used only for |ε| ≤
/// [`NearPower::MAX_EPS`] and the same sign of h, where the dropped ε⁵ term
/// is below 1e-10·|c₅| relative (|c₅| < 1 for 0 < n < 5); elsewhere (near
/// h = 0 in particular) the caller falls back to `powf`.
#[derive(Clone, Copy)]
struct NearPower {
    h_ref: f64,
    inv_abs_ref: f64,
    hn_ref: f64,
    c: [f64; 4],
}

impl NearPower {
    const MAX_EPS: f64 = 0.01;

    #[inline(always)]
    fn new(n: f64, h_ref: f64, hn_ref: f64) -> Self {
        let c1 = n;
        let c2 = c1 * (n - 1.0) / 2.0;
        let c3 = c2 * (n - 2.0) / 3.0;
        let c4 = c3 * (n - 3.0) / 4.0;
        let a = h_ref.abs();
        NearPower { h_ref, inv_abs_ref: if a > 0.0 { 1.0 / a } else { 0.0 }, hn_ref, c: [c1, c2, c3, c4] }
    }

    #[inline(always)]
    fn eval(&self, h: f64) -> Option<f64> {
        if self.inv_abs_ref == 0.0 || h * self.h_ref <= 0.0 {
            return None;
        }
        let e = (h.abs() * self.inv_abs_ref) - 1.0;
        if e.abs() > Self::MAX_EPS {
            return None;
        }
        let [c1, c2, c3, c4] = self.c;
        Some(self.hn_ref * (1.0 + e * (c1 + e * (c2 + e * (c3 + e * c4)))))
    }
}

/// Advances h over one sample interval of length `dt` [s] while u moves linearly
/// from `u0` to `u1` [V]. Returns the new h [µm]; never NaN for finite input.
#[inline]
pub fn advance_h(p: &Params, h: f64, u0: f64, u1: f64, dt: f64) -> f64 {
    let du = u1 - u0;
    if du == 0.0 {
        return h;
    }
    let udot = du / dt;
    let (k1_first, hn) = rate_and_power(p, h, u0, udot);
    let Some(m) = substeps(p, h, k1_first, hn, udot, dt) else {
        let step = dt / IMPLICIT_SUBSTEPS as f64;
        let mut h = h;
        for i in 1..=IMPLICIT_SUBSTEPS {
            h = implicit_step(p, h, u0 + udot * step * i as f64, udot, step).clamp(-H_LIMIT_UM, H_LIMIT_UM);
        }
        return h;
    };
    // dt/1 and dt/2 are exact: skip the division on the usual intervals.
    let step = match m {
        1 => dt,
        2 => 0.5 * dt,
        _ => dt / m as f64,
    };
    let half = 0.5 * step;
    let near = NearPower::new(p.n, h, hn);
    let rate = |h: f64, u: f64| {
        let hn = near.eval(h).unwrap_or_else(|| abs_pow(h, p.n));
        p.a * udot - (p.beta * udot.abs() * sgn(h) + p.gamma * udot) * hn + p.delta * u * sgn(udot)
    };
    let mut h = h;
    for i in 0..m {
        let ua = u0 + udot * (step * i as f64);
        let um = ua + udot * half;
        let ub = ua + udot * step;
        let k1 = if i == 0 { k1_first } else { rate(h, ua) };
        let k2 = rate(h + half * k1, um);
        let k3 = rate(h + half * k2, um);
        let k4 = rate(h + step * k3, ub);
        let next = h + step / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        h = if next.is_finite() { next.clamp(-H_LIMIT_UM, H_LIMIT_UM) } else { h };
    }
    h
}

/// Output equation (3): x = kv·u + x0 + h [µm].
#[inline(always)]
pub fn output(p: &Params, u: f64, h: f64) -> f64 {
    p.kv * u + p.x0 + h
}

/// The state a [`Model`] carries between samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelState {
    /// Hysteresis state h [µm] at the last sample.
    pub h: f64,
    /// The last voltage [V]; `None` before the first sample.
    pub u_prev: Option<f64>,
}

/// A per-sample model for control loops: `step(u) -> x`.
///
/// The first sample has no predecessor, so h keeps its initial value there; each
/// later sample integrates eq. (5) from the previous voltage to the new one.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    params: Params,
    dt: f64,
    state: ModelState,
}

impl Model {
    /// A model with parameters `params`, sampling interval `dt` [s] and initial h `h0` [µm].
    pub fn new(params: Params, dt: f64, h0: f64) -> Result<Self> {
        params.validate()?;
        positive_dt(dt)?;
        finite_sample("h0", h0)?;
        Ok(Model { params, dt, state: ModelState { h: h0, u_prev: None } })
    }

    /// Takes the voltage `u` [V] of the next sample and returns the displacement x [µm].
    /// A non-finite `u` is rejected and the state kept. Allocation-free.
    #[inline]
    pub fn step(&mut self, u: f64) -> Result<f64> {
        finite_sample("u", u)?;
        if let Some(u_prev) = self.state.u_prev {
            self.state.h = advance_h(&self.params, self.state.h, u_prev, u, self.dt);
        }
        self.state.u_prev = Some(u);
        Ok(output(&self.params, u, self.state.h))
    }

    /// Current parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Replaces the parameters (validated); the state is kept.
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        params.validate()?;
        self.params = params;
        Ok(())
    }

    /// Sampling interval [s].
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Current hysteresis state h [µm].
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
        Ok(())
    }

    /// Forgets the past: h = `h0`, no previous sample.
    pub fn reset(&mut self, h0: f64) -> Result<()> {
        self.set_state(ModelState { h: h0, u_prev: None })
    }
}

/// Simulates a whole record into `x_out` and returns the final h [µm].
///
/// `x_out[k] = kv·u[k] + x0 + h[k]`. With `u_prev = None`, h[0] = `h0`; with
/// `Some(v)`, the first interval runs from v to u[0] starting at h = `h0`, so a long
/// record can be streamed in chunks (pass the previous chunk's final h and last u)
/// with the same result as one call. Input with a non-finite value is rejected
/// before anything is computed.
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
    for (x, &v) in x_out.iter_mut().zip(u) {
        *x = model.step(v)?;
    }
    Ok(model.h())
}

/// Allocating form of [`simulate_into`]: returns `(x, h_final)`.
pub fn simulate(params: &Params, u: &[f64], dt: f64, h0: f64, u_prev: Option<f64>) -> Result<(Vec<f64>, f64)> {
    let mut x = vec![0.0; u.len()];
    let h = simulate_into(params, u, dt, h0, u_prev, &mut x)?;
    Ok((x, h))
}

/// The paper's input, u = 50 + 50·sin(2πft − π/2), sampled every `dt` [s], with
/// f = 1 Hz for t < 3 s, 10 Hz up to 3.3 s, 100 Hz up to 3.33 s and 200 Hz for
/// `tail_s` seconds after that. Each switch falls on a minimum (u = 0), so the
/// phase restarts there and u is continuous.
pub fn paper_input(dt: f64, tail_s: f64) -> Vec<f64> {
    let segments = [(1.0, 0.0, 3.0), (10.0, 3.0, 3.3), (100.0, 3.3, 3.33), (200.0, 3.33, 3.33 + tail_s)];
    let total = ((3.33 + tail_s) / dt).round() as usize;
    (0..total)
        .map(|k| {
            let t = k as f64 * dt;
            let (f, start) = segments
                .iter()
                .rev()
                .find(|(_, start, _)| t >= start - 1e-12)
                .map(|&(f, start, _)| (f, start))
                .unwrap_or((1.0, 0.0));
            50.0 + 50.0 * (2.0 * std::f64::consts::PI * f * (t - start) - std::f64::consts::FRAC_PI_2).sin()
        })
        .collect()
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
    fn series_power_matches_powf_where_it_is_used() {
        for n in [0.3, 1.0, 1.52, 2.7, 4.9] {
            for h_ref in [-3.0, -0.01, 1e-3, 0.7, 12.0] {
                let near = NearPower::new(n, h_ref, abs_pow(h_ref, n));
                for k in -25..=25 {
                    let h = h_ref * (1.0 + 0.001 * k as f64);
                    if let Some(v) = near.eval(h) {
                        let exact = abs_pow(h, n);
                        assert!(((v - exact) / exact).abs() < 1e-9, "n={n} h={h}: {v} vs {exact}");
                    }
                }
                assert!(near.eval(-h_ref).is_none());
            }
        }
    }

    #[test]
    fn h_is_exactly_zero_at_rest_for_small_n() {
        let p = Params { n: 0.3, ..Params::paper_1hz() };
        assert_eq!(hysteresis_rate(&p, 0.0, 0.0, 0.0), 0.0);
        assert_eq!(hysteresis_rate(&p, 0.0, 10.0, 5.0), p.a * 5.0 + p.delta * 10.0);
    }

    #[test]
    fn chunks_give_the_same_result_as_one_call() {
        let dt = 1e-4;
        let u = paper_input(dt, 0.01);
        let p = Params::paper_1hz();
        let (whole, h_whole) = simulate(&p, &u, dt, 0.0, None).unwrap();
        let (a, h_a) = simulate(&p, &u[..1234], dt, 0.0, None).unwrap();
        let (b, h_b) = simulate(&p, &u[1234..], dt, h_a, Some(u[1233])).unwrap();
        assert_eq!([a, b].concat(), whole);
        assert_eq!(h_b, h_whole);
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
}
