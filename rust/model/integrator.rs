//! The one integrator of eq. (5): the sub-step rule and the stages, written once,
//! generic over the number type ([`Scalar`]).
//!
//! Between two samples the voltage is taken as a straight line, so u̇ is constant
//! within a sample interval and `sgn(0) = 0` makes h stand still while u holds.
//! `|h|^(n−1)·h` is evaluated as `sgn(h)·|h|^n`, exactly 0 at h = 0 for every n > 0.
//!
//! The scheme is classic RK4 on sub-steps. An interval takes one step, or
//! [`MIN_SUBSTEPS`] where h may cross zero (|h|^n is not smooth there, and one step
//! across the kink loses order), and more as the local stiffness
//! |∂ḣ/∂h| = n·(|β|+|γ|)·|u̇|·|h|^(n−1) (at the start of the interval, and at an
//! explicit-Euler end point when h moves far in one interval) so that every sub-step
//! has |∂ḣ/∂h|·Δt ≤ [`STIFFNESS_STEP`], well inside RK4's stability region, up to
//! [`MAX_SUBSTEPS`]; stiffer intervals take [`IMPLICIT_SUBSTEPS`] backward-Euler steps
//! (Newton, at most [`NEWTON_ITERATIONS`] iterations each) instead, which are stable for
//! any stiffness. For parameters with no bounded solution (β + γ < 0 lets h run away),
//! h is held within ±[`H_LIMIT_UM`] so that the output stays finite.
//!
//! The worst case per interval is therefore bounded by construction: at most
//! 32 RK4 sub-steps (128 stage evaluations) or 32 × 4 Newton iterations.
//!
//! The rule is decided on values only, so that [`advance`] on `f64` (the model) and on
//! [`Dual`](super::scalar::Dual) (the identifiers' sensitivities) take the same
//! sub-steps, and the derivative is that of the discrete map actually computed.

use super::scalar::Scalar;
use crate::math;
use crate::params::Params;

/// RK4 sub-steps for an interval in which h may cross zero.
pub const MIN_SUBSTEPS: u32 = 2;
/// Most RK4 sub-steps per sample interval.
pub const MAX_SUBSTEPS: u32 = 32;
/// Backward-Euler sub-steps per interval when RK4 would need more than [`MAX_SUBSTEPS`].
pub const IMPLICIT_SUBSTEPS: u32 = 32;
/// Newton iterations per backward-Euler sub-step, at most.
pub const NEWTON_ITERATIONS: usize = 4;
/// Largest |∂ḣ/∂h|·Δt allowed in one RK4 sub-step (set for accuracy: stability
/// alone would allow about 2.5).
pub const STIFFNESS_STEP: f64 = 0.25;
/// |h| is held within this bound \[µm\] (no piezo stack moves a centimetre).
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
pub(crate) fn abs_pow(h: f64, n: f64) -> f64 {
    let a = h.abs();
    if a == 0.0 {
        0.0
    } else {
        math::powf(a, n)
    }
}

/// The coefficients of eq. (5), A, β, γ, n, δ, in the number type of the integration
/// (constants for the model, seeded duals for the sensitivities).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coefficients<S> {
    /// A \[µm/V\].
    pub a: S,
    /// β [µm^(1−n)/V].
    pub beta: S,
    /// γ [µm^(1−n)/V].
    pub gamma: S,
    /// n \[-\].
    pub n: S,
    /// δ \[µm/(V·s)\].
    pub delta: S,
}

impl Coefficients<f64> {
    /// The coefficients of `p` as plain numbers.
    #[inline(always)]
    pub fn of(p: &Params) -> Self {
        Coefficients { a: p.a, beta: p.beta, gamma: p.gamma, n: p.n, delta: p.delta }
    }
}

/// dh/dt of eq. (5) \[µm/s\] at hysteresis state `h` \[µm\], voltage `u` \[V\] and rate `udot` \[V/s\].
#[inline(always)]
pub fn hysteresis_rate(p: &Params, h: f64, u: f64, udot: f64) -> f64 {
    rate(&Coefficients::of(p), h, abs_pow(h, p.n), u, udot, sgn(udot))
}

/// dh/dt of eq. (5) given `hn` = |h|^n and `su` = sgn(u̇): the stage computation.
#[inline(always)]
fn rate<S: Scalar>(c: &Coefficients<S>, h: S, hn: S, u: S, udot: S, su: f64) -> S {
    let sh = sgn(h.re());
    c.a * udot - (c.beta * (udot * su) * sh + c.gamma * udot) * hn + c.delta * u * su
}

/// ∂(dh/dt)/∂h \[1/s\].
#[inline(always)]
fn rate_slope(p: &Params, h: f64, udot: f64) -> f64 {
    let a = h.abs();
    if a == 0.0 {
        return 0.0;
    }
    -(p.beta * udot.abs() + p.gamma * udot * sgn(h)) * p.n * math::powf(a, p.n - 1.0)
}

/// One backward-Euler step of length `step` (Newton, at most [`NEWTON_ITERATIONS`]
/// iterations): stable for any stiffness, used only when RK4 would need more than
/// [`MAX_SUBSTEPS`].
#[inline]
fn implicit_step(p: &Params, h0: f64, u_end: f64, udot: f64, step: f64) -> f64 {
    let mut h = h0;
    for _ in 0..NEWTON_ITERATIONS {
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

/// The sub-step rule: how many RK4 sub-steps the interval needs (`None`: more than
/// [`MAX_SUBSTEPS`], so backward Euler), given h, the rate `k1` = ḣ at the start of
/// the interval and |h|^n = `hn`.
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
            stiffness_dt = stiffness_dt.max(slope_weight * math::powf(b, p.n - 1.0));
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
        math::ceil(wanted) as u32
    };
    Some(m.max(floor))
}

/// |h|^n (and ln|h|) near a reference state h_ref by their series in
/// ε = (|h| − |h_ref|)/|h_ref|: |h|^n = |h_ref|^n·(1 + ε)^n to ε⁴, ln|h| = ln|h_ref| + ln(1 + ε) to ε⁴.
///
/// The RK4 stages of one interval sit close to its starting h, so one `powf`
/// per interval serves all of them. The series is used only for |ε| ≤
/// [`NearPower::MAX_EPS`] and the same sign of h, where the dropped ε⁵ term
/// is below 1e-10·|c₅| relative (|c₅| < 1 for 0 < n < 5); elsewhere (near
/// h = 0 in particular) the caller falls back to `powf` and `ln`.
#[derive(Clone, Copy)]
struct NearPower {
    h_ref: f64,
    inv_abs_ref: f64,
    hn_ref: f64,
    ln_ref: f64,
    c: [f64; 4],
}

impl NearPower {
    const MAX_EPS: f64 = 0.01;

    #[inline(always)]
    fn new(n: f64, h_ref: f64, hn_ref: f64, with_ln: bool) -> Self {
        let c1 = n;
        let c2 = c1 * (n - 1.0) / 2.0;
        let c3 = c2 * (n - 2.0) / 3.0;
        let c4 = c3 * (n - 3.0) / 4.0;
        let a = h_ref.abs();
        let ln_ref = if with_ln && a > 0.0 { math::ln(a) } else { 0.0 };
        NearPower { h_ref, inv_abs_ref: if a > 0.0 { 1.0 / a } else { 0.0 }, hn_ref, ln_ref, c: [c1, c2, c3, c4] }
    }

    /// ε of `h`, where the series applies.
    #[inline(always)]
    fn eps(&self, h: f64) -> Option<f64> {
        if self.inv_abs_ref == 0.0 || h * self.h_ref <= 0.0 {
            return None;
        }
        let e = (h.abs() * self.inv_abs_ref) - 1.0;
        if e.abs() > Self::MAX_EPS {
            return None;
        }
        Some(e)
    }

    #[inline(always)]
    fn power(&self, e: f64) -> f64 {
        let [c1, c2, c3, c4] = self.c;
        self.hn_ref * (1.0 + e * (c1 + e * (c2 + e * (c3 + e * c4))))
    }

    #[inline(always)]
    fn ln(&self, e: f64) -> f64 {
        self.ln_ref + e * (1.0 - e * (0.5 - e * (1.0 / 3.0 - e * 0.25)))
    }

    /// |h|^n and, when `S` carries derivatives, ln|h| (else 0).
    #[inline(always)]
    fn eval<S: Scalar>(&self, h: f64, n: f64) -> (f64, f64) {
        match self.eps(h) {
            Some(e) => (self.power(e), if S::DERIVATIVES { self.ln(e) } else { 0.0 }),
            None => {
                let a = h.abs();
                let ln = if S::DERIVATIVES && a > 0.0 { math::ln(a) } else { 0.0 };
                (abs_pow(h, n), ln)
            }
        }
    }
}

/// Advances h over one sample interval of length `dt` \[s\] while u moves linearly
/// from `u0` to `u1` \[V\]: the model's integrator. Returns the new h \[µm\]; never NaN
/// for finite input.
#[inline]
pub fn advance_h(p: &Params, h: f64, u0: f64, u1: f64, dt: f64) -> f64 {
    advance(p, &Coefficients::of(p), h, u0, u1, dt)
}

/// [`advance_h`] in any [`Scalar`]: with [`Dual`](super::scalar::Dual) numbers it
/// returns h with its derivatives with respect to whatever `c`, `h`, `u0` and `u1`
/// were seeded with. `p` holds the values of `c` (the sub-step rule and Newton's
/// iterations run on values). The value is bit for bit that of [`advance_h`].
#[inline]
pub fn advance<S: Scalar>(p: &Params, c: &Coefficients<S>, h: S, u0: S, u1: S, dt: f64) -> S {
    advance_forced(p, c, h, u0, u1, dt, None)
}

/// [`advance`] with the number of RK4 sub-steps optionally forced (for finite-difference
/// checks of the derivatives, where the rule's jumps would spoil the quotient).
#[inline(always)]
pub(crate) fn advance_forced<S: Scalar>(
    p: &Params,
    c: &Coefficients<S>,
    h: S,
    u0: S,
    u1: S,
    dt: f64,
    forced: Option<u32>,
) -> S {
    let du = u1 - u0;
    if du.re() == 0.0 {
        return h;
    }
    let udot = du / dt;
    let (hv, udv) = (h.re(), udot.re());
    let su = sgn(udv);
    let hn_v = abs_pow(hv, p.n);
    let k1_v = rate(&Coefficients::of(p), hv, hn_v, u0.re(), udv, su);
    let Some(m) = forced.or_else(|| substeps(p, hv, k1_v, hn_v, udv, dt)) else {
        let step = dt / IMPLICIT_SUBSTEPS as f64;
        let mut h = h;
        for i in 1..=IMPLICIT_SUBSTEPS {
            let u_end = u0 + udot * step * i as f64;
            let star = implicit_step(p, h.re(), u_end.re(), udv, step);
            let clamped = star.clamp(-H_LIMIT_UM, H_LIMIT_UM);
            h = if clamped != star {
                S::pinned(clamped)
            } else if S::DERIVATIVES {
                let fixed = S::cst(star);
                let a = star.abs();
                let (hn, ln) = (abs_pow(star, p.n), if a > 0.0 { math::ln(a) } else { 0.0 });
                let f_at = rate(c, fixed, fixed.abs_pow(c.n, hn, ln), u_end, udot, su);
                S::implicit(star, h, f_at, rate_slope(p, star, udv), step)
            } else {
                S::cst(star)
            };
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
    let near = NearPower::new(p.n, hv, hn_v, S::DERIVATIVES);
    let power = |x: S| {
        let (hn, ln) = near.eval::<S>(x.re(), p.n);
        x.abs_pow(c.n, hn, ln)
    };
    let mut h = h;
    for i in 0..m {
        let ua = u0 + udot * (step * i as f64);
        let um = ua + udot * half;
        let ub = ua + udot * step;
        let k1 = if i == 0 {
            rate(c, h, h.abs_pow(c.n, hn_v, near.ln_ref), u0, udot, su)
        } else {
            rate(c, h, power(h), ua, udot, su)
        };
        let s2 = h + k1 * half;
        let k2 = rate(c, s2, power(s2), um, udot, su);
        let s3 = h + k2 * half;
        let k3 = rate(c, s3, power(s3), um, udot, su);
        let s4 = h + k3 * step;
        let k4 = rate(c, s4, power(s4), ub, udot, su);
        let next = h + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (step / 6.0);
        let v = next.re();
        if v.is_finite() {
            let clamped = v.clamp(-H_LIMIT_UM, H_LIMIT_UM);
            h = if clamped == v { next } else { S::pinned(clamped) };
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_power_matches_powf_where_it_is_used() {
        for n in [0.3, 1.0, 1.52, 2.7, 4.9] {
            for h_ref in [-3.0, -0.01, 1e-3, 0.7, 12.0] {
                let near = NearPower::new(n, h_ref, abs_pow(h_ref, n), true);
                for k in -25..=25 {
                    let h = h_ref * (1.0 + 0.001 * k as f64);
                    if let Some(e) = near.eps(h) {
                        let exact = abs_pow(h, n);
                        let v = near.power(e);
                        assert!(((v - exact) / exact).abs() < 1e-9, "n={n} h={h}: {v} vs {exact}");
                        assert!((near.ln(e) - h.abs().ln()).abs() < 1e-10);
                    }
                }
                assert!(near.eps(-h_ref).is_none());
            }
        }
    }

    use crate::model::scalar::Dual;

    /// h after `u` (from h = 0) and its gradient over (A, β, γ, n, δ).
    fn run(p: &Params, u: &[f64], dt: f64) -> (f64, [f64; 5]) {
        let c = Coefficients {
            a: Dual::<5>::var(p.a, 0),
            beta: Dual::var(p.beta, 1),
            gamma: Dual::var(p.gamma, 2),
            n: Dual::var(p.n, 3),
            delta: Dual::var(p.delta, 4),
        };
        let mut h = Dual::cst(0.0);
        for w in u.windows(2) {
            let next = advance(p, &c, h, Dual::cst(w[0]), Dual::cst(w[1]), dt);
            assert_eq!(next.re, advance_h(p, h.re, w[0], w[1], dt), "the dual value is the model's h");
            h = next;
        }
        (h.re, h.du.into())
    }

    #[test]
    fn sensitivities_match_finite_differences_on_steps_holds_reversals_and_stiff_intervals() {
        let dt = 1e-4;
        let ramp = |a: f64, b: f64, k: usize| (0..k).map(move |i| a + (b - a) * i as f64 / (k - 1) as f64);
        let cases: Vec<(&str, Params, Vec<f64>)> = vec![
            // 0 -> 95 V in one sample: the end-point stiffness check sends it to more sub-steps.
            ("step", Params::paper_1hz(), vec![0.0, 95.0, 95.0]),
            ("hold", Params::paper_1hz(), ramp(0.0, 40.0, 50).chain(std::iter::repeat_n(40.0, 50)).collect()),
            ("reversal", Params::paper_1hz(), ramp(0.0, 60.0, 80).chain(ramp(60.0, 10.0, 80)).collect()),
            (
                "n < 1",
                Params { n: 0.64, ..Params::paper_1hz() },
                ramp(0.0, 50.0, 60).chain(ramp(50.0, 5.0, 60)).collect(),
            ),
            (
                "stiff",
                Params { beta: 0.4, gamma: 0.1, n: 2.5, ..Params::paper_1hz() },
                ramp(0.0, 100.0, 20).chain(ramp(100.0, 0.0, 20)).collect(),
            ),
        ];
        for (name, p, u) in cases {
            let (_, grad) = run(&p, &u, dt);
            let largest = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
            for (i, g) in grad.iter().enumerate() {
                let eps = 1e-6 * [p.a, p.beta, p.gamma, p.n, p.delta][i].abs().max(1e-3);
                let shifted = |d: f64| {
                    let mut q = p;
                    match i {
                        0 => q.a += d,
                        1 => q.beta += d,
                        2 => q.gamma += d,
                        3 => q.n += d,
                        _ => q.delta += d,
                    }
                    run(&q, &u, dt).0
                };
                let fd = (shifted(eps) - shifted(-eps)) / (2.0 * eps);
                assert!(
                    (fd - g).abs() <= 1e-4 * largest + 1e-9,
                    "{name}, coefficient {i}: dual {g}, finite difference {fd}"
                );
            }
        }
    }

    #[test]
    fn h_is_exactly_zero_at_rest_for_small_n() {
        let p = Params { n: 0.3, ..Params::paper_1hz() };
        assert_eq!(hysteresis_rate(&p, 0.0, 0.0, 0.0), 0.0);
        assert_eq!(hysteresis_rate(&p, 0.0, 10.0, 5.0), p.a * 5.0 + p.delta * 10.0);
    }
}
