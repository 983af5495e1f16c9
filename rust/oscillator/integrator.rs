//! The oscillator's integrator: the sub-step rule and the RK4 stages, written once,
//! generic over the number type ([`Scalar`]), so that the simulation (`f64`) and its
//! sensitivities ([`Dual`]) take the same sub-steps.
//!
//! Between two samples the force is a straight line (first-order hold). An interval
//! takes as many equal RK4 sub-steps as the faster of two rates asks for, decided on
//! values at its start ([`Rule::substeps`]):
//!
//! - the mass on its springs: ω² = (k + K_z)/m with K_z = α + β·(|γ|+|δ|)·|z|^ν the
//!   largest slope ∂ż/∂ẏ of the Bouc–Wen spring, sub-steps with ω·Δt ≤ [`OSCILLATION_STEP`];
//! - the relaxation of z and of the damper: λ = β·ν·(|γ|+|δ|)·|ẏ|·|z|^(ν−1) + c/m
//!   (|ẏ| taken at its largest over the interval to first order, |ẏ| + |ÿ|·Δt with ÿ
//!   at either end's force),
//!   sub-steps with λ·Δt ≤ [`RELAXATION_STEP`].
//!
//! |ẏ| and |z| have kinks where ẏ or z changes sign (velocity reversals, zero crossings
//! of the hysteretic force), across which RK4 is only second order. A sub-step whose ends
//! differ in the sign of ẏ or z is taken again in up to three pieces, the kink (the zero
//! of the straight line between the ends) within the middle one, an eighth of the
//! sub-step wide ([`KINK_SPLIT`]). The pieces lie on a fixed grid: a decision on values,
//! constant while the unknowns move a little, so the sensitivities stay those of the
//! steps taken. On the benchmark's input this took the error from 1.4e-6 m to 4.4e-8 m
//! at the same sub-steps, and allows fewer of them (1.4e-7 m with ω·Δt ≤ 0.2, λ·Δt ≤ 0.4).
//!
//! At most [`MAX_SUBSTEPS`] RK4 sub-steps. An interval that would need more (parameters
//! far outside the benchmark's at this sampling rate, or a runaway motion) takes
//! [`IMPLICIT_SUBSTEPS`] linearly implicit Euler steps instead (s ← s + h·(I − h·J)⁻¹·f,
//! J = ∂f/∂s at the step's start, in the number type of the integration so that the
//! sensitivities are those of the step taken): first order, but stable for any
//! stiffness of the spring–mass mode and of the relaxation of z. Where J has a growing
//! mode (a loop with γ + δ < 0 on its loading branch, a negative slope of the Bouc–Wen
//! spring) that mode is stepped explicitly: its growth is the model's. The states are
//! held within ±[`Y_LIMIT_M`], ±[`V_LIMIT_M_S`], ±[`Z_LIMIT_N`] and a sub-step whose result
//! is not finite keeps the state it started from, so that no parameter set gives a
//! non-finite output.

use super::OscillatorParams;
use crate::math;
use crate::model::integrator::sgn;
use crate::model::scalar::{Dual, Scalar};

/// Largest ω·Δt of one RK4 sub-step (ω the undamped angular frequency of the mass on k
/// and the Bouc–Wen spring's steepest slope).
pub const OSCILLATION_STEP: f64 = 0.2;
/// Largest λ·Δt of one RK4 sub-step (λ the relaxation rate of z plus c/m).
pub const RELAXATION_STEP: f64 = 0.4;
/// A sub-step in which ẏ or z changes sign is taken again in pieces, the kink within one
/// of this fraction of the sub-step (module docs): RK4 is only second order across a kink.
pub const KINK_SPLIT: u32 = 8;
/// Most RK4 sub-steps per sample interval.
pub const MAX_SUBSTEPS: u32 = 256;
/// Linearly implicit Euler steps of an interval that would need more than
/// [`MAX_SUBSTEPS`] RK4 sub-steps.
pub const IMPLICIT_SUBSTEPS: u32 = 64;
/// |y| is held within this bound \[m\].
pub const Y_LIMIT_M: f64 = 1.0e3;
/// |ẏ| is held within this bound \[m/s\].
pub const V_LIMIT_M_S: f64 = 1.0e6;
/// |z| is held within this bound \[N\].
pub const Z_LIMIT_N: f64 = 1.0e12;

/// The state (y \[m\], ẏ \[m/s\], z \[N\]) in the number type of the integration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct State<S> {
    /// Displacement y \[m\].
    pub y: S,
    /// Velocity ẏ \[m/s\].
    pub v: S,
    /// Hysteretic force z \[N\].
    pub z: S,
}

impl<S: Scalar> State<S> {
    #[inline(always)]
    fn plus(self, d: State<S>, h: f64) -> Self {
        State { y: self.y + d.y * h, v: self.v + d.v * h, z: self.z + d.z * h }
    }
}

/// The coefficients in the number type of the integration, in the products the stages
/// use: 1/m, c/m, k/m, α, β·γ, β·δ, ν (constants for the simulation, seeded duals for the
/// sensitivities).
#[derive(Debug, Clone, Copy)]
pub struct Coefficients<S> {
    /// 1/m \[1/kg\].
    pub inv_m: S,
    /// c/m \[1/s\].
    pub c_m: S,
    /// k/m \[1/s²\].
    pub k_m: S,
    /// α \[N/m\].
    pub alpha: S,
    /// β·γ \[N^(1−ν)/m\].
    pub beta_gamma: S,
    /// β·δ \[N^(1−ν)/m\].
    pub beta_delta: S,
    /// ν \[-\].
    pub nu: S,
}

impl Coefficients<f64> {
    /// The coefficients of `p` as plain numbers.
    #[inline(always)]
    pub fn of(p: &OscillatorParams) -> Self {
        let inv_m = 1.0 / p.m;
        Coefficients {
            inv_m,
            c_m: p.c * inv_m,
            k_m: p.k * inv_m,
            alpha: p.alpha,
            beta_gamma: p.beta * p.gamma,
            beta_delta: p.beta * p.delta,
            nu: p.nu,
        }
    }
}

impl<const M: usize> Coefficients<Dual<M>> {
    /// The coefficients of `p` with m, c, k, α, γ, δ, ν the independent variables at
    /// slots 0 … 6 (β a constant: it enters only as β·γ and β·δ).
    #[inline(always)]
    pub fn seeded(p: &OscillatorParams) -> Self {
        let inv = 1.0 / p.m;
        let inv_m = Dual::slope(inv, 0, -inv * inv);
        Coefficients {
            inv_m,
            c_m: Dual::var(p.c, 1) * inv_m,
            k_m: Dual::var(p.k, 2) * inv_m,
            alpha: Dual::var(p.alpha, 3),
            beta_gamma: Dual::var(p.gamma, 4) * p.beta,
            beta_delta: Dual::var(p.delta, 5) * p.beta,
            nu: Dual::var(p.nu, 6),
        }
    }
}

/// |z|^ν, exactly 0 at z = 0; |z| itself where `UNIT` (ν = 1: no `powf`).
///
/// `UNIT` is a type-level flag, decided once per call of the simulator, not a test of ν
/// here: `if ν == 1 { |z| } else { powf(|z|, ν) }` is folded by the optimiser into the
/// `powf` call (both arms agree at ν = 1), which would cost a `powf` at every stage.
#[inline(always)]
pub fn abs_pow<const UNIT: bool>(z: f64, nu: f64) -> f64 {
    let a = z.abs();
    if UNIT {
        a
    } else if a == 0.0 {
        0.0
    } else {
        math::powf(a, nu)
    }
}

/// The time derivative of the state at state `s` and force `f` \[N\]; `UNIT`: ν = 1
/// ([`abs_pow`]).
#[inline(always)]
pub fn rate<S: Scalar, const UNIT: bool>(c: &Coefficients<S>, s: &State<S>, f: f64) -> State<S> {
    let (zv, vv) = (s.z.re(), s.v.re());
    let hn = abs_pow::<UNIT>(zv, c.nu.re());
    let ln = if S::DERIVATIVES && zv != 0.0 { math::ln(zv.abs()) } else { 0.0 };
    let zn = s.z.abs_pow(c.nu, hn, ln);
    let sv = sgn(vv);
    let sz = sgn(zv);
    // |ẏ|·|z|^(ν−1)·z = |ẏ|·sgn(z)·|z|^ν = ẏ·sgn(ẏ)·sgn(z)·|z|^ν.
    let zdot = c.alpha * s.v - zn * (c.beta_gamma * s.v * (sv * sz) + c.beta_delta * s.v);
    let vdot = c.inv_m * f - c.c_m * s.v - c.k_m * s.y - c.inv_m * s.z;
    State { y: s.v, v: vdot, z: zdot }
}

/// The sub-step rule (module docs) for one parameter set and sampling interval, its
/// constants computed once.
#[derive(Debug, Clone, Copy)]
pub struct Rule {
    spread: f64,
    inv_m: f64,
    c: f64,
    k: f64,
    springs: f64,
    nu: f64,
    relax_c: f64,
    dt: f64,
    /// dt / OSCILLATION_STEP and dt / RELAXATION_STEP.
    osc_scale: f64,
    relax_scale: f64,
}

impl Rule {
    /// The rule for `p` at sampling interval `dt` \[s\].
    pub fn new(p: &OscillatorParams, dt: f64) -> Self {
        let inv_m = 1.0 / p.m;
        Rule {
            spread: p.beta * (p.gamma.abs() + p.delta.abs()),
            inv_m,
            c: p.c,
            k: p.k,
            springs: p.k + p.alpha,
            nu: p.nu,
            relax_c: p.c * inv_m,
            dt,
            osc_scale: dt / OSCILLATION_STEP,
            relax_scale: dt / RELAXATION_STEP,
        }
    }

    /// RK4 sub-steps for the interval from state `s` with force `f0` \[N\] at its start and
    /// `f1` at its end;
    /// `None` where more than [`MAX_SUBSTEPS`] would be needed (then
    /// [`IMPLICIT_SUBSTEPS`] linearly implicit steps).
    #[inline(always)]
    pub fn substeps<const UNIT: bool>(&self, s: &State<f64>, f0: f64, f1: f64) -> Option<u32> {
        let za = s.z.abs();
        let zn = abs_pow::<UNIT>(za, self.nu);
        let omega = math::sqrt((self.springs + self.spread * zn) * self.inv_m);
        // |ÿ| at the start's state with either end's force: the force moves within the
        // interval, and from rest it alone sets the motion.
        let rest = self.c * s.v + self.k * s.y + s.z;
        let accel = (f0 - rest).abs().max((f1 - rest).abs()) * self.inv_m;
        let v_max = s.v.abs() + accel * self.dt;
        let z_slope = if UNIT {
            1.0
        } else {
            let reach = za + (self.springs - self.k + self.spread * zn) * v_max * self.dt;
            math::powf(reach, self.nu - 1.0)
        };
        let relax = self.spread * self.nu * v_max * z_slope + self.relax_c;
        let wanted = (omega * self.osc_scale).max(relax * self.relax_scale);
        if wanted <= 1.0 {
            Some(1)
        } else if wanted.is_nan() || wanted > MAX_SUBSTEPS as f64 {
            None
        } else {
            Some(math::ceil(wanted) as u32)
        }
    }
}

/// 1/d for d with d.re ≥ 1.
#[inline(always)]
fn recip<S: Scalar>(d: S) -> S {
    let inv = 1.0 / d.re();
    (d * (-inv * inv)).with_re(inv)
}

/// One linearly implicit Euler step of length `h` \[s\] from `s` with force `f` \[N\]
/// (module docs). The 3×3 system (I − h·J)·x = f(s) is solved by elimination: x_y =
/// f_y + h·x_v, x_z = q·(f_z + h·J_zv·x_v) with q = 1/(1 − h·J_zz), and x_v from the
/// velocity row; a pivot below 1 (a growing mode) is taken as 1.
#[inline(always)]
fn implicit_substep<S: Scalar, const UNIT: bool>(c: &Coefficients<S>, s: State<S>, f: f64, h: f64) -> State<S> {
    let d = rate::<S, UNIT>(c, &s, f);
    let (zv, vv) = (s.z.re(), s.v.re());
    let (sv, sz) = (sgn(vv), sgn(zv));
    let nu = c.nu.re();
    let hn = abs_pow::<UNIT>(zv, nu);
    let ln = if S::DERIVATIVES && zv != 0.0 { math::ln(zv.abs()) } else { 0.0 };
    let zn = s.z.abs_pow(c.nu, hn, ln);
    // ∂ż/∂ẏ = α − β·|z|^ν·(γ·sgn(ẏ)·sgn(z) + δ); ∂ż/∂z = −β·ν·|z|^(ν−1)·(γ·|ẏ| + δ·ẏ·sgn(z)).
    let j_zv = c.alpha - zn * (c.beta_gamma * (sv * sz) + c.beta_delta);
    let slope = if zv == 0.0 { 0.0 } else { nu * hn / zv.abs() };
    let j_zz = -(c.nu * (c.beta_gamma * s.v * sv + c.beta_delta * s.v * sz)) * slope;
    let pivot_z = S::cst(1.0) - j_zz * h;
    let q = if pivot_z.re() >= 1.0 { recip(pivot_z) } else { S::cst(1.0) };
    let pivot_v = S::cst(1.0) + (c.c_m + c.k_m * h + q * j_zv * c.inv_m * h) * h;
    let rhs = d.v - (c.k_m * d.y + c.inv_m * q * d.z) * h;
    let x_v = if pivot_v.re() >= 1.0 { rhs * recip(pivot_v) } else { rhs };
    let x_y = d.y + x_v * h;
    let x_z = (d.z + j_zv * x_v * h) * q;
    let next = s.plus(State { y: x_y, v: x_v, z: x_z }, h);
    State { y: settle(next.y, s.y, Y_LIMIT_M), v: settle(next.v, s.v, V_LIMIT_M_S), z: settle(next.z, s.z, Z_LIMIT_N) }
}

/// `next` held within ±`limit`, or `prev` where `next` is not finite; a held value no
/// longer depends on the unknowns, nor does a value whose derivatives overflowed (a
/// runaway motion: the sensitivities grow faster than the state).
#[inline(always)]
fn settle<S: Scalar>(next: S, prev: S, limit: f64) -> S {
    let v = next.re();
    if !v.is_finite() {
        prev
    } else if v.abs() > limit || !next.all_finite() {
        S::pinned(v.clamp(-limit, limit))
    } else {
        next
    }
}

/// Advances the state over one sample interval `dt` \[s\] in which the force goes
/// linearly from `f0` to `f1` \[N\], in `plan` RK4 sub-steps, or ([`None`])
/// [`IMPLICIT_SUBSTEPS`] linearly implicit Euler steps (each with the force at its end);
/// `UNIT`: ν = 1 ([`abs_pow`]).
#[inline(always)]
pub fn advance<S: Scalar, const UNIT: bool>(
    c: &Coefficients<S>,
    s: State<S>,
    f0: f64,
    f1: f64,
    dt: f64,
    plan: Option<u32>,
) -> State<S> {
    let Some(m) = plan else {
        return advance_implicit::<S, UNIT>(c, s, f0, f1, dt);
    };
    let step = if m == 1 { dt } else { dt / m as f64 };
    let slope = (f1 - f0) / dt;
    let force = |t: f64| f0 + slope * t;
    let mut s = s;
    for i in 0..m {
        let t0 = step * i as f64;
        let mut next = rk4::<S, UNIT>(c, &s, t0, step, &force);
        if let Some(j) = crossing(&s, &next) {
            // The step again in up to three pieces, the kink within the middle one,
            // an eighth of the step: [0, j/8], [j/8, (j+1)/8], [(j+1)/8, 1].
            let (a, b) = (j as f64 / KINK_SPLIT as f64 * step, (j + 1) as f64 / KINK_SPLIT as f64 * step);
            let mut piece = s;
            if j > 0 {
                piece = rk4::<S, UNIT>(c, &piece, t0, a, &force);
            }
            piece = rk4::<S, UNIT>(c, &piece, t0 + a, b - a, &force);
            if j + 1 < KINK_SPLIT {
                piece = rk4::<S, UNIT>(c, &piece, t0 + b, step - b, &force);
            }
            next = piece;
        }
        s = State {
            y: settle(next.y, s.y, Y_LIMIT_M),
            v: settle(next.v, s.v, V_LIMIT_M_S),
            z: settle(next.z, s.z, Z_LIMIT_N),
        };
    }
    s
}

/// One RK4 step of length `h` from `s` at time `t0` within the interval.
#[inline(always)]
fn rk4<S: Scalar, const UNIT: bool>(
    c: &Coefficients<S>,
    s: &State<S>,
    t0: f64,
    h: f64,
    force: &impl Fn(f64) -> f64,
) -> State<S> {
    let half = 0.5 * h;
    let (fa, fm, fb) = (force(t0), force(t0 + half), force(t0 + h));
    let k1 = rate::<S, UNIT>(c, s, fa);
    let k2 = rate::<S, UNIT>(c, &s.plus(k1, half), fm);
    let k3 = rate::<S, UNIT>(c, &s.plus(k2, half), fm);
    let k4 = rate::<S, UNIT>(c, &s.plus(k3, h), fb);
    let w = h / 6.0;
    State {
        y: s.y + (k1.y + k2.y * 2.0 + k3.y * 2.0 + k4.y) * w,
        v: s.v + (k1.v + k2.v * 2.0 + k3.v * 2.0 + k4.v) * w,
        z: s.z + (k1.z + k2.z * 2.0 + k3.z * 2.0 + k4.z) * w,
    }
}

/// Where within a step ẏ or z changes sign (the kinks of |ẏ| and |z|): the index j <
/// [`KINK_SPLIT`] of the piece of the step that holds the first zero of the straight line
/// between the two ends; `None` for no sign change. A whole index, so that the pieces
/// do not move with the unknowns and the sensitivities are those of the steps taken.
#[inline(always)]
fn crossing<S: Scalar>(a: &State<S>, b: &State<S>) -> Option<u32> {
    let at = |x: f64, y: f64| if x * y < 0.0 { x / (x - y) } else { 1.0 };
    let frac = at(a.v.re(), b.v.re()).min(at(a.z.re(), b.z.re()));
    (frac < 1.0).then(|| ((frac * KINK_SPLIT as f64) as u32).min(KINK_SPLIT - 1))
}

/// The interval in [`IMPLICIT_SUBSTEPS`] linearly implicit Euler steps, each with the
/// force at its end (kept out of line: the RK4 path is the usual one).
#[cold]
#[inline(never)]
fn advance_implicit<S: Scalar, const UNIT: bool>(
    c: &Coefficients<S>,
    s: State<S>,
    f0: f64,
    f1: f64,
    dt: f64,
) -> State<S> {
    let h = dt / IMPLICIT_SUBSTEPS as f64;
    let slope = (f1 - f0) / dt;
    let mut s = s;
    for i in 1..=IMPLICIT_SUBSTEPS {
        let f = if i == IMPLICIT_SUBSTEPS { f1 } else { f0 + slope * (h * i as f64) };
        s = implicit_substep::<S, UNIT>(c, s, f, h);
    }
    s
}

/// The state's values.
#[inline(always)]
pub fn values<S: Scalar>(s: &State<S>) -> State<f64> {
    State { y: s.y.re(), v: s.v.re(), z: s.z.re() }
}
