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
//! [`MAX_SUBSTEPS`]. Backward Euler (Newton, at most [`NEWTON_ITERATIONS`] iterations a
//! step), stable for any stiffness, takes the stiffer intervals: an interval that
//! would need more than [`TRIAL_ABOVE_SUBSTEPS`] RK4 sub-steps first tries it over the
//! whole interval and over two half steps, and keeps the two half steps where the two
//! ends agree to [`IMPLICIT_TOLERANCE_UM`] (h on its slow manifold, the usual stiff
//! interval); otherwise it takes its RK4 sub-steps, or [`IMPLICIT_SUBSTEPS`]
//! backward-Euler steps beyond [`MAX_SUBSTEPS`]. For parameters with no bounded
//! solution (β + γ < 0 lets h run away), h is held within ±[`H_LIMIT_UM`] so that the
//! output stays finite.
//!
//! The worst case per interval is therefore bounded by construction: the trial's
//! 3 × 4 Newton iterations, then at most 32 RK4 sub-steps (128 stage evaluations) or
//! 32 × 4 Newton iterations.
//!
//! The rule is decided on values only, so that [`advance`] on `f64` (the model) and on
//! [`Dual`] (the identifiers' sensitivities) take the same
//! sub-steps, and the derivative is that of the discrete map actually computed.

use nalgebra::SVector;

use super::lanes::Lanes;
use super::scalar::{abs_pow_slope, Dual, Scalar};
use crate::math;
use crate::params::Params;
use near_power::NearPower;

mod near_power;

/// RK4 sub-steps for an interval in which h may cross zero.
pub const MIN_SUBSTEPS: u32 = 2;
/// Most RK4 sub-steps per sample interval.
pub const MAX_SUBSTEPS: u32 = 32;
/// Backward-Euler sub-steps per interval when RK4 would need more than [`MAX_SUBSTEPS`]
/// and the two-step trial does not meet [`IMPLICIT_TOLERANCE_UM`].
pub const IMPLICIT_SUBSTEPS: u32 = 32;
/// Largest difference \[µm\] between a stiff interval's backward-Euler end in one step
/// and in two half steps at which the two half steps are kept (0.1 nm: ten times below
/// the noise of the quietest displacement sensors).
pub const IMPLICIT_TOLERANCE_UM: f64 = 1e-4;
/// RK4 sub-steps beyond which an interval first tries two backward-Euler steps.
pub const TRIAL_ABOVE_SUBSTEPS: u32 = 16;
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

/// h held within ±[`H_LIMIT_UM`].
#[inline(always)]
fn clamp_h(h: f64) -> f64 {
    h.clamp(-H_LIMIT_UM, H_LIMIT_UM)
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

impl<const M: usize> Coefficients<Dual<M>> {
    /// The coefficients of `p` as independent variables: A, β, γ, n, δ at derivative
    /// slots `first` … `first + 4`.
    #[inline(always)]
    pub fn seeded(p: &Params, first: usize) -> Self {
        Coefficients {
            a: Dual::var(p.a, first),
            beta: Dual::var(p.beta, first + 1),
            gamma: Dual::var(p.gamma, first + 2),
            n: Dual::var(p.n, first + 3),
            delta: Dual::var(p.delta, first + 4),
        }
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
    c.a * udot - (times_sgn(c.beta * (udot * su), h.re()) + c.gamma * udot) * hn + c.delta * u * su
}

/// x·sgn(v), by a sign change where sgn(v) = ±1 (the same number: multiplying by ±1 is
/// exact).
#[inline(always)]
fn times_sgn<S: Scalar>(x: S, v: f64) -> S {
    if v > 0.0 {
        x
    } else if v < 0.0 {
        -x
    } else {
        x * 0.0
    }
}

/// What the stages need of the coefficients: |x|^n and the rate of eq. (5). Implemented
/// by [`Coefficients`] (any coefficients) and by [`Seeded`] (the coefficients as the
/// independent variables of the sensitivities, with the same results at less cost).
pub(crate) trait Law<S: Scalar> {
    /// |x|^n given `hn` = |x.re|^n and `ln_abs` = ln|x.re| (see [`Scalar::abs_pow`]).
    fn power(&self, x: S, hn: f64, ln_abs: f64) -> S;
    /// dh/dt at state `h` with `hn` = |h|^n, voltage `u`, rate `udot` and `su` = sgn(u̇).
    fn rate(&self, h: S, hn: S, u: S, udot: S, su: f64) -> S;
    /// u̇ = `du` / `dt` for the change `du` = u₁ − u₀ of the voltage over an interval.
    #[inline(always)]
    fn per_second(&self, du: S, dt: f64) -> S {
        du / dt
    }
}

impl<S: Scalar> Law<S> for Coefficients<S> {
    #[inline(always)]
    fn power(&self, x: S, hn: f64, ln_abs: f64) -> S {
        x.abs_pow(self.n, hn, ln_abs)
    }
    #[inline(always)]
    fn rate(&self, h: S, hn: S, u: S, udot: S, su: f64) -> S {
        rate(self, h, hn, u, udot, su)
    }
}

/// The coefficients A, β, γ, n, δ seeded as the independent variables at derivative
/// slots `FIRST` … `FIRST + 4` ([`Coefficients::seeded`]), for voltages whose
/// derivatives are zero outside slot `INPUT` (everywhere if `INPUT` ≥ M).
///
/// Each derivative slot is computed by the operations [`Coefficients`] performs on
/// that slot, less the terms that are a zero derivative of a coefficient or of the
/// voltage times a finite value: the same numbers, up to the sign of a zero,
/// wherever the stage's values are finite (the integrator discards any sub-step
/// whose value is not). Per stage that is two multiplications a slot and a few on
/// the seeded slots, instead of some twenty-five a slot.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Seeded<const M: usize, const FIRST: usize, const INPUT: usize> {
    a: f64,
    beta: f64,
    gamma: f64,
    n: f64,
    delta: f64,
    /// sgn(u̇) of the δ term is kept (the command moves) or replaced by 0 ([`Drive`]).
    drive: Drive,
}

impl<const M: usize, const FIRST: usize, const INPUT: usize> Seeded<M, FIRST, INPUT> {
    const LAYOUT: () = assert!(
        FIRST + 5 <= M && (INPUT < FIRST || INPUT >= FIRST + 5),
        "five seeded slots within M, the input slot outside them"
    );

    /// The seeded coefficients of `p` for voltages with derivatives `du0` and `du1`;
    /// `None` when those are non-zero outside slot `INPUT` (then the seeded
    /// [`Coefficients`] serve).
    #[inline(always)]
    pub(crate) fn new(p: &Params, du0: &SVector<f64, M>, du1: &SVector<f64, M>, drive: Drive) -> Option<Self> {
        let () = Self::LAYOUT;
        for j in 0..M {
            // NaN counts as non-zero.
            if j != INPUT && !(du0[j] == 0.0 && du1[j] == 0.0) {
                return None;
            }
        }
        Some(Seeded { a: p.a, beta: p.beta, gamma: p.gamma, n: p.n, delta: p.delta, drive })
    }
}

impl<const M: usize, const FIRST: usize, const INPUT: usize> Law<Dual<M>> for Seeded<M, FIRST, INPUT> {
    /// [`Scalar::abs_pow`] with ∂n = 1 at the slot of n and 0 elsewhere.
    #[inline(always)]
    fn power(&self, x: Dual<M>, hn: f64, ln_abs: f64) -> Dual<M> {
        let Some(signed) = abs_pow_slope(x.re, self.n, hn) else {
            return Dual::cst(0.0);
        };
        let dn = hn * ln_abs;
        let mut du = x.du;
        for (j, v) in du.iter_mut().enumerate() {
            *v = if j == FIRST + 3 { *v * signed + dn } else { *v * signed };
        }
        Dual::new(hn, du)
    }

    /// The voltages' derivatives are 0 outside `INPUT`, and so are those of u̇.
    #[inline(always)]
    fn per_second(&self, du: Dual<M>, dt: f64) -> Dual<M> {
        let mut udot = Dual::cst(du.re / dt);
        if INPUT < M {
            udot.du[INPUT] = du.du[INPUT] / dt;
        }
        udot
    }

    /// The operations of [`rate`] on [`Dual`] numbers, slot by slot (see the type's
    /// docs); a − b is written −b + a and −(a + b) as −b + (−a), which round alike.
    #[inline(always)]
    fn rate(&self, h: Dual<M>, hn: Dual<M>, u: Dual<M>, udot: Dual<M>, su: f64) -> Dual<M> {
        let sh = sgn(h.re);
        // The values, in the order of `rate`: t1 − t5·hn + t9.
        let w = udot.re * su;
        let t1 = self.a * udot.re;
        let t5 = self.beta * w * sh + self.gamma * udot.re;
        let sd = self.drive.delta_sign(su);
        let t9 = self.delta * u.re * sd;
        let re = t1 - t5 * hn.re + t9;
        // Every slot has −∂hn·t5; A adds ∂t1 = u̇, β −(∂t5 = w·sh)·hn, γ −(∂t5 = u̇)·hn,
        // δ ∂t9 = u·sgn(u̇), the input slot all its terms.
        let mut du = hn.du;
        for (j, v) in du.iter_mut().enumerate() {
            let y = -(*v * t5);
            *v = if j == FIRST {
                y + udot.re
            } else if j == FIRST + 1 {
                y + -((w * sh) * hn.re)
            } else if j == FIRST + 2 {
                y + -(udot.re * hn.re)
            } else if j == FIRST + 4 {
                y + u.re * sd
            } else if j == INPUT {
                let d = udot.du[j];
                let dt5 = d * su * self.beta * sh + d * self.gamma;
                ((y + -(dt5 * hn.re)) + d * self.a) + u.du[j] * self.delta * sd
            } else {
                y
            };
        }
        Dual::new(re, du)
    }
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

/// The values of a stiff interval's trial by backward Euler: the whole interval in one
/// step, and in two half steps (`mid`, `end`; before clamping to ±[`H_LIMIT_UM`], as the
/// sub-steps take them). The two agree to [`IMPLICIT_TOLERANCE_UM`] where h follows its
/// slow manifold (the usual stiff interval, h near the loop's branch); where h moves far
/// within the interval they do not, and the interval takes [`IMPLICIT_SUBSTEPS`] steps.
struct ImplicitTrial {
    mid: f64,
    end: f64,
    whole: f64,
}

impl ImplicitTrial {
    /// The trial from h = `h0` at voltage `u0` \[V\], rate `udot` \[V/s\], over `dt` \[s\]; the
    /// voltages at the step ends are computed as the sub-steps compute them.
    #[inline]
    fn new(p: &Params, h0: f64, u0: f64, udot: f64, dt: f64) -> Self {
        let half = dt / 2.0;
        let whole = implicit_step(p, h0, u0 + udot * dt, udot, dt);
        let mid = implicit_step(p, h0, u0 + udot * half, udot, half);
        let end = implicit_step(p, clamp_h(mid), u0 + udot * half * 2.0, udot, half);
        ImplicitTrial { mid, end, whole }
    }

    /// Whether the one-step and two-step ends agree to [`IMPLICIT_TOLERANCE_UM`] (the
    /// difference estimates the two-step end's error: backward Euler is first order).
    #[inline]
    fn agrees(&self) -> bool {
        (clamp_h(self.whole) - clamp_h(self.end)).abs() <= IMPLICIT_TOLERANCE_UM
    }
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

/// The integrator's plan for the interval `u0` → `u1` \[V\] of length `dt` \[s\] from
/// h \[µm\] (the rule [`advance_h`] applies at the interval's start): `Some(0)` where u
/// holds (no integration), `Some(m)` for m RK4 sub-steps, `None` where the interval is
/// too stiff for [`MAX_SUBSTEPS`] and takes the implicit path. For experiments that
/// count the stiff intervals of an identifier's estimates.
pub fn interval_plan(p: &Params, h: f64, u0: f64, u1: f64, dt: f64) -> Option<u32> {
    let du = u1 - u0;
    if du == 0.0 {
        return Some(0);
    }
    let udot = du / dt;
    let hn = abs_pow(h, p.n);
    let k1 = rate(&Coefficients::of(p), h, hn, u0, udot, sgn(udot));
    substeps(p, h, k1, hn, udot, dt)
}

/// Advances h over one sample interval of length `dt` \[s\] while u moves linearly
/// from `u0` to `u1` \[V\]: the model's integrator. Returns the new h \[µm\]; never NaN
/// for finite input.
#[inline]
pub fn advance_h(p: &Params, h: f64, u0: f64, u1: f64, dt: f64) -> f64 {
    advance(p, &Coefficients::of(p), h, u0, u1, dt)
}

/// [`advance_h`] in any [`Scalar`]: with [`Dual`] numbers it
/// returns h with its derivatives with respect to whatever `c`, `h`, `u0` and `u1`
/// were seeded with. `p` holds the values of `c` (the sub-step rule and Newton's
/// iterations run on values). The value is bit for bit that of [`advance_h`].
#[inline]
pub fn advance<S: Scalar>(p: &Params, c: &Coefficients<S>, h: S, u0: S, u1: S, dt: f64) -> S {
    advance_forced(p, c, h, u0, u1, dt, None)
}

/// [`advance`] on [`Dual`] numbers with the coefficients of `p` seeded at derivative
/// slots `FIRST` … `FIRST + 4` ([`Coefficients::seeded`]): by [`Seeded`] where the
/// voltages' derivatives allow it, else by the seeded [`Coefficients`]. `forced` as in
/// [`advance_forced`].
#[inline(always)]
pub(crate) fn advance_seeded<const M: usize, const FIRST: usize, const INPUT: usize>(
    p: &Params,
    h: Dual<M>,
    u0: Dual<M>,
    u1: Dual<M>,
    dt: f64,
    forced: Option<u32>,
    drive: Drive,
) -> Dual<M> {
    advance_seeded_carrying::<M, FIRST, INPUT>(p, h, None, u0, u1, dt, forced, drive).0
}

/// |h|^n and ln|h| of a state, carried from one interval to the next.
pub(crate) type Power = (f64, f64);

/// Whether the *command* moves over an interval, which decides whether the δ term of
/// eq. (5) acts there.
///
/// δ·u·sgn(u̇) is the paper's term for a moving drive: unlike A·u̇, β and γ (each
/// proportional to |u̇|, so that a short approach adds a short stretch of loop), it adds
/// δ·u [µm/s] for as long as u̇ ≠ 0, however slowly u moves. With the voltage on the
/// stack straight from the command, a hold stops it at once (u̇ = 0). Behind an input
/// lag the stack's voltage approaches a held command exponentially and, in exact
/// arithmetic, never arrives: the term would integrate δ·u for the whole hold, and in
/// floating point it stops only when u_a reaches u to the last bit — an amount of h set
/// by the rounding of u (about 36 τ of δ·u). So the term follows the command: it acts
/// over an interval in which the command moves, with the sign of the stack's motion
/// (the same numbers as before wherever the stack's voltage is the command's); while
/// the command holds, the stack's settling still moves h through A, β and γ, and the
/// δ term is off, as in the model without a lag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Drive {
    /// The command moves over the interval: the δ term acts.
    Moving,
    /// The command holds (the stack's voltage may still settle): no δ term.
    Held,
}

impl Drive {
    /// The drive over an interval in which the command moves from `u0` to `u1` \[V\].
    #[inline(always)]
    pub(crate) fn of(u0: f64, u1: f64) -> Self {
        if u0 == u1 {
            Drive::Held
        } else {
            Drive::Moving
        }
    }

    /// The sign the δ term takes, given sgn(u̇) = `su` of the stack's voltage.
    #[inline(always)]
    fn delta_sign(self, su: f64) -> f64 {
        match self {
            Drive::Moving => su,
            Drive::Held => 0.0,
        }
    }

    /// `p` with δ = 0 where the term is off (the value only: the plain-number paths).
    #[inline(always)]
    pub(crate) fn params(self, p: &Params) -> Params {
        match self {
            Drive::Moving => *p,
            Drive::Held => Params { delta: 0.0, ..*p },
        }
    }
}

/// [`advance_seeded`] given (|h|^n, ln|h|) at the start (`None`: computed), also
/// returning them at the end where the interval's series gives them (as
/// [`advance_h_carried`] does for |h|^n): a run of intervals on the same parameters
/// (a pass over a window) then calls `powf` and `ln` only where h moves fast or near 0.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn advance_seeded_carrying<const M: usize, const FIRST: usize, const INPUT: usize>(
    p: &Params,
    h: Dual<M>,
    power: Option<Power>,
    u0: Dual<M>,
    u1: Dual<M>,
    dt: f64,
    forced: Option<u32>,
    drive: Drive,
) -> (Dual<M>, Option<Power>) {
    match Seeded::<M, FIRST, INPUT>::new(p, &u0.du, &u1.du, drive) {
        Some(law) => advance_from_power(p, &law, h, power, u0, u1, dt, forced),
        None => {
            let mut law = Coefficients::seeded(p, FIRST);
            if drive == Drive::Held {
                law.delta = Dual::cst(0.0);
            }
            advance_from_power(p, &law, h, power, u0, u1, dt, forced)
        }
    }
}

/// [`advance_h`] given `hn` = |h|^n at the start, also returning |h|^n at the end: the
/// per-sample paths (the [`Model`](super::Model), [`simulate`](super::simulate), the
/// inverse, the banks) carry |h|^n from one interval to the next instead of calling
/// `powf` at every sample.
///
/// The end's |h|^n comes from the interval's series ([`NearPower`]) where h moved by at
/// most [`NearPower::CARRY_EPS`] (0.1 %) of itself, else from `powf`: there the series'
/// dropped ε⁵ term is at the level of rounding, so the carried value stays within
/// rounding of |h|^n over holds and slow motion, and is computed afresh wherever h
/// moves fast or near zero (every crossing).
#[inline]
pub(crate) fn advance_h_carried(p: &Params, h: f64, hn: f64, u0: f64, u1: f64, dt: f64) -> (f64, f64) {
    let (next, carried) = advance_h_carrying(p, h, hn, u0, u1, dt);
    (next, carried.unwrap_or_else(|| abs_pow(next, p.n)))
}

/// [`advance_h_carried`] with the end's |h|^n left to the caller (`None`) where the
/// series does not give it: a bank computes those after all its channels have moved.
#[inline]
pub(crate) fn advance_h_carrying(p: &Params, h: f64, hn: f64, u0: f64, u1: f64, dt: f64) -> (f64, Option<f64>) {
    let (next, carried) = advance_from_power(p, &Coefficients::of(p), h, Some((hn, 0.0)), u0, u1, dt, None);
    (next, carried.map(|(hn, _)| hn))
}

/// The coefficients A, β, γ, n, δ of one channel, or of [`super::lanes::WIDTH`]
/// channels side by side, for [`advance_h_lanes`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct LaneCoefficients<L> {
    pub(crate) a: L,
    pub(crate) beta: L,
    pub(crate) gamma: L,
    pub(crate) n: L,
    pub(crate) delta: L,
}

/// [`advance_h_carrying`] for the usual interval only, written without branches so that
/// a loop over many channels runs in SIMD lanes (the bank): one RK4 step, h away from
/// zero and not crossing it, the stiffness within one sub-step's bound, every stage's
/// |h|^n on the interval's series. Returns (h, |h|^n, ok) per lane: where `ok` the same
/// numbers as [`advance_h_carrying`] (|h|^n NaN where that leaves it to the caller);
/// elsewhere the other values are meaningless (call [`advance_h_carrying`]).
///
/// Each operation is the one [`advance_from_power`] performs on that interval (the
/// sub-step rule, [`NearPower`], the stages), so the bits are the same.
#[inline(always)]
pub(crate) fn advance_h_lanes<L: Lanes>(
    p: &LaneCoefficients<L>,
    h: L,
    hn: L,
    u0: L,
    u1: L,
    dt: f64,
) -> (L, L, L::Mask) {
    let (zero, one) = (L::splat(0.0), L::splat(1.0));
    let dt_l = L::splat(dt);
    let du = u1 - u0;
    let udot = du / dt_l;
    let su = L::select(udot.gt(zero), one, L::select(udot.lt(zero), L::splat(-1.0), zero));
    let sh = L::select(h.gt(zero), one, L::splat(-1.0));
    // The terms of `rate` that do not change within the interval (the stages keep h's
    // sign): x·sgn(h) is a sign change, as in `times_sgn`.
    let t1 = p.a * udot;
    let bg = (p.beta * (udot * su)) * sh + p.gamma * udot;
    let rate = |power: L, u: L| t1 - bg * power + p.delta * u * su;
    let k1 = rate(hn, u0);
    // The sub-step rule's usual case: one step.
    let a = h.abs();
    let slope = p.n * (p.beta.abs() + p.gamma.abs());
    let stiffness_dt = slope * udot.abs() * dt_l * (hn / a);
    let h_end = h + dt_l * k1;
    let one_step = a.gt(zero)
        & (h_end - h).abs().le(L::splat(0.1) * a)
        & (h_end * h).gt(zero)
        & (stiffness_dt / L::splat(STIFFNESS_STEP)).le(one);
    // NearPower::new with h_ref = h.
    let inv_ref = one / h;
    let near = NearPower { inv_ref, hn_ref: hn, ln_ref: zero, a: NearPower::coefficients(p.n, hn) };
    let power = |e: L| near.power(e);
    let on_series = |e: L| e.abs().le(L::splat(NearPower::<L>::MAX_EPS));
    let step = dt_l;
    let half = L::splat(0.5) * step;
    let (e_half, e_step) = (inv_ref * half, inv_ref * step);
    let ua = u0 + udot * (step * zero);
    let (um, ub) = (ua + udot * half, ua + udot * step);
    let e2 = zero + k1 * e_half;
    let k2 = rate(power(e2), um);
    let e3 = zero + k2 * e_half;
    let k3 = rate(power(e3), um);
    let e4 = zero + k3 * e_step;
    let k4 = rate(power(e4), ub);
    let next = h + (k1 + k2 * L::splat(2.0) + k3 * L::splat(2.0) + k4) * (step / L::splat(6.0));
    let ok = one_step & on_series(e2) & on_series(e3) & on_series(e4) & next.abs().le(L::splat(H_LIMIT_UM));
    let e = (next - h) * inv_ref;
    let carried = L::select(e.abs().le(L::splat(NearPower::<L>::CARRY_EPS)), power(e), L::splat(f64::NAN));
    let held = du.eq(zero);
    (L::select(held, h, next), L::select(held, hn, carried), held | ok)
}

/// h after `m` backward-Euler sub-steps over the interval from h at voltage `u0` \[V\]
/// at rate `udot` \[V/s\], with the derivatives of what is computed; for `m` = 2 the
/// sub-steps' values are those of `trial`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn implicit_interval<S: Scalar, L: Law<S>>(
    p: &Params,
    c: &L,
    h: S,
    u0: S,
    udot: S,
    dt: f64,
    m: u32,
    trial: Option<&ImplicitTrial>,
) -> S {
    let udv = udot.re();
    let su = sgn(udv);
    let step = dt / m as f64;
    let mut h = h;
    for i in 1..=m {
        let u_end = u0 + udot * step * i as f64;
        let star = match (trial, i) {
            (Some(t), 1) => t.mid,
            (Some(t), _) => t.end,
            (None, _) => implicit_step(p, h.re(), u_end.re(), udv, step),
        };
        let clamped = clamp_h(star);
        h = if clamped != star {
            S::pinned(clamped)
        } else if S::DERIVATIVES {
            let fixed = S::cst(star);
            let a = star.abs();
            let (hn, ln) = (abs_pow(star, p.n), if a > 0.0 { math::ln(a) } else { 0.0 });
            let f_at = c.rate(fixed, c.power(fixed, hn, ln), u_end, udot, su);
            S::implicit(star, h, f_at, rate_slope(p, star, udv), step)
        } else {
            S::cst(star)
        };
    }
    h
}

/// [`advance`] with the number of RK4 sub-steps optionally forced (for finite-difference
/// checks of the derivatives, where the rule's jumps would spoil the quotient).
#[inline(always)]
pub(crate) fn advance_forced<S: Scalar, L: Law<S>>(
    p: &Params,
    c: &L,
    h: S,
    u0: S,
    u1: S,
    dt: f64,
    forced: Option<u32>,
) -> S {
    advance_from_power(p, c, h, None, u0, u1, dt, forced).0
}

/// [`advance_forced`] with |h|^n and ln|h| at the start given (`power`; ln read only
/// when `S` carries derivatives) or computed (`None`). Returns h at the end and, where
/// the interval's series applies there, its |h|^n and ln|h| (ln 0 without derivatives;
/// `None`: compute them; the start's own when h did not move).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn advance_from_power<S: Scalar, L: Law<S>>(
    p: &Params,
    c: &L,
    h: S,
    power: Option<Power>,
    u0: S,
    u1: S,
    dt: f64,
    forced: Option<u32>,
) -> (S, Option<Power>) {
    let du = u1 - u0;
    if du.re() == 0.0 {
        return (h, power);
    }
    let udot = c.per_second(du, dt);
    let (hv, udv) = (h.re(), udot.re());
    let su = sgn(udv);
    let (hn_v, ln_start) = match power {
        Some((hn, ln)) => (hn, S::DERIVATIVES.then_some(ln)),
        None => (abs_pow(hv, p.n), None),
    };
    let k1_v = rate(&Coefficients::of(p), hv, hn_v, u0.re(), udv, su);
    let planned = forced.or_else(|| substeps(p, hv, k1_v, hn_v, udv, dt));
    let m = match planned {
        Some(m) if forced.is_some() || m <= TRIAL_ABOVE_SUBSTEPS => m,
        _ => {
            let trial = ImplicitTrial::new(p, hv, u0.re(), udv, dt);
            if trial.agrees() {
                return (implicit_interval(p, c, h, u0, udot, dt, 2, Some(&trial)), None);
            }
            match planned {
                Some(m) => m,
                None => return (implicit_interval(p, c, h, u0, udot, dt, IMPLICIT_SUBSTEPS, None), None),
            }
        }
    };
    // dt/1 and dt/2 are exact: skip the division on the usual intervals.
    let step = match m {
        1 => dt,
        2 => 0.5 * dt,
        _ => dt / m as f64,
    };
    let half = 0.5 * step;
    let near = NearPower::new(p.n, hv, hn_v, ln_start, S::DERIVATIVES);
    // ε per unit rate of the stage states h + half·k and h + step·k.
    let (e_half, e_step) = (near.inv_ref * half, near.inv_ref * step);
    let mut h = h;
    // ε of the sub-step's start (0 for the first: it is the reference).
    let mut e = 0.0;
    for i in 0..m {
        let ua = u0 + udot * (step * i as f64);
        let um = ua + udot * half;
        let ub = ua + udot * step;
        let k1 = if i == 0 {
            c.rate(h, c.power(h, hn_v, near.ln_ref), u0, udot, su)
        } else {
            c.rate(h, near.power_at(c, h, e, p.n), ua, udot, su)
        };
        let s2 = h + k1 * half;
        let k2 = c.rate(s2, near.power_at(c, s2, e + k1.re() * e_half, p.n), um, udot, su);
        let s3 = h + k2 * half;
        let k3 = c.rate(s3, near.power_at(c, s3, e + k2.re() * e_half, p.n), um, udot, su);
        let s4 = h + k3 * step;
        let k4 = c.rate(s4, near.power_at(c, s4, e + k3.re() * e_step, p.n), ub, udot, su);
        let next = h + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (step / 6.0);
        let v = next.re();
        if v.is_finite() {
            let clamped = clamp_h(v);
            h = if clamped == v { next } else { S::pinned(clamped) };
        }
        e = (h.re() - hv) * near.inv_ref;
    }
    let carried = near.inv_ref != 0.0 && e.abs() <= NearPower::<f64>::CARRY_EPS;
    (h, carried.then(|| (near.power(e), if S::DERIVATIVES { near.ln(e) } else { 0.0 })))
}

#[cfg(test)]
mod tests;
