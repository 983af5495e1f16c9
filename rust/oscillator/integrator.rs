//! The oscillator's integrator: the sub-step rule and the RK6 stages, written once,
//! generic over the number type ([`Scalar`]), so that the simulation (`f64`) and its
//! sensitivities ([`Dual`]) take the same sub-steps.
//!
//! Between two samples the force is what the record's [`crate::reconstruction`] says
//! ([`Force`]: held, a straight line, or the band-limited polynomial). An interval
//! takes as many equal sub-steps of Butcher's sixth-order Runge–Kutta method (`rk6`)
//! as the fastest of three rates asks for, decided on values at its start
//! ([`Rule::substeps`]):
//!
//! - the mass on its springs: ω² = |k + K_z|/m with K_z = α − κ·|z|^ν the tangent
//!   dz/dy of the Bouc–Wen spring, κ = β·(γ + δ) on the loading branch (sgn ẏ = sgn z)
//!   and β·(δ − γ) on the unloading one, the larger where ẏ may reverse or z cross zero
//!   within the interval; sub-steps with ω·Δt ≤ [`OSCILLATION_STEP`];
//! - the relaxation of z and of the damper: λ = ν·|κ|·|ẏ|·|z|^(ν−1) + c/m (|ẏ| taken at
//!   its largest over the interval to first order, |ẏ| + |ÿ|·Δt with ÿ at the least and
//!   the largest force of the interval), sub-steps with λ·Δt ≤ [`RELAXATION_STEP`];
//! - the force itself where it is band-limited: its content up to ω_F, sub-steps with
//!   ω_F·Δt ≤ [`FORCE_STEP`] (a held or straight-line force is integrated exactly).
//!
//! Sixth order, because the lightly damped mode amplifies a method's phase error by its
//! quality factor (about 45 for the benchmark's system) and the fast relaxation of z on
//! the unloading branch (λ up to 1900·|ẏ| /s there) asks for accuracy at every step: RK4
//! at the same sub-steps is 3e-5 of the displacement range from the converged solution,
//! this 3e-7 to 5e-7 (`rust/tests/oscillator_reference.rs`).
//!
//! |ẏ| and |z| have kinks where ẏ or z changes sign (velocity reversals, zero crossings
//! of the hysteretic force), across which any Runge–Kutta step is only second order. A
//! sub-step whose ends differ in the sign of ẏ or z is taken again in pieces split at
//! the kink (`split`), its time bracketed and refined [`KINK_REFINEMENTS`] times. Each
//! split time is computed in the number type of the integration: the sensitivities
//! include its motion with the unknowns and are those of the steps taken. The rest of
//! the sub-step is split again where it holds the other variable's kink (a reversal and
//! a zero crossing of z in one sub-step).
//!
//! At most [`MAX_SUBSTEPS`] RK6 sub-steps. An interval that would need more (parameters
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
use crate::reconstruction::{polynomial, polynomial_slope, KNOTS};
use core::ops::Mul;

/// Largest ω·Δt of one RK6 sub-step (ω the undamped angular frequency of the mass on k
/// and the Bouc–Wen spring's tangent on the branches the interval may be on).
pub const OSCILLATION_STEP: f64 = 0.2;
/// Largest λ·Δt of one RK6 sub-step (λ the relaxation rate of z plus c/m).
pub const RELAXATION_STEP: f64 = 0.2;
/// Largest ω_F·Δt of one RK6 sub-step for a force whose content reaches the angular
/// frequency ω_F (a band-limited input; a held or straight-line force within the
/// interval is integrated exactly).
pub const FORCE_STEP: f64 = 0.7;
/// Refinements of a kink's time before a sub-step is split at it (module docs): each
/// takes one RK6 step; two bring the kinks' share of the error below that of the steps.
pub const KINK_REFINEMENTS: u32 = 2;
/// Most RK6 sub-steps per sample interval.
pub const MAX_SUBSTEPS: u32 = 256;
/// Linearly implicit Euler steps of an interval that would need more than
/// [`MAX_SUBSTEPS`] RK6 sub-steps.
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
    inv_m: f64,
    c: f64,
    k: f64,
    alpha: f64,
    nu: f64,
    /// β·(γ + δ) and β·(δ − γ): the Bouc–Wen spring's tangent dz/dy = α − κ·|z|^ν on the
    /// loading (sgn ẏ = sgn z) and the unloading branch.
    kappa: [f64; 2],
    relax_c: f64,
    dt: f64,
    /// dt / OSCILLATION_STEP, dt / RELAXATION_STEP and ω_F·dt / FORCE_STEP.
    osc_scale: f64,
    relax_scale: f64,
    force_steps: f64,
}

impl Rule {
    /// The rule for `p` at sampling interval `dt` \[s\], the force's content reaching
    /// `force_omega` \[rad/s\] (0 for a force that is a straight line or held within
    /// each interval: RK6 integrates those exactly).
    pub fn new(p: &OscillatorParams, dt: f64, force_omega: f64) -> Self {
        let inv_m = 1.0 / p.m;
        Rule {
            inv_m,
            c: p.c,
            k: p.k,
            alpha: p.alpha,
            nu: p.nu,
            kappa: [p.beta * (p.gamma + p.delta), p.beta * (p.delta - p.gamma)],
            relax_c: p.c * inv_m,
            dt,
            osc_scale: dt / OSCILLATION_STEP,
            relax_scale: dt / RELAXATION_STEP,
            force_steps: force_omega * dt / FORCE_STEP,
        }
    }

    /// RK6 sub-steps for the interval from state `s` in which the force stays within
    /// `f0` … `f1` \[N\] (either order; a straight line's two ends);
    /// `None` where more than [`MAX_SUBSTEPS`] would be needed (then
    /// [`IMPLICIT_SUBSTEPS`] linearly implicit steps).
    #[inline(always)]
    pub fn substeps<const UNIT: bool>(&self, s: &State<f64>, f0: f64, f1: f64) -> Option<u32> {
        let za = s.z.abs();
        let zn = abs_pow::<UNIT>(za, self.nu);
        // |ÿ| at the start's state with the force's extremes: the force moves within the
        // interval, and from rest it alone sets the motion.
        let rest = self.c * s.v + self.k * s.y + s.z;
        let accel = (f0 - rest).abs().max((f1 - rest).abs()) * self.inv_m;
        let v_max = s.v.abs() + accel * self.dt;
        let [load, unload] = self.kappa;
        let steepest = load.abs().max(unload.abs());
        // The branch of the start holds over the interval unless ẏ may reverse or z may
        // cross zero within it; then either branch.
        let travel = (self.alpha + steepest * zn) * v_max * self.dt;
        let kappa = if s.v.abs() <= accel * self.dt || za <= travel {
            if -load > -unload {
                load
            } else {
                unload
            }
        } else if (s.v > 0.0) == (s.z > 0.0) {
            load
        } else {
            unload
        };
        let kappa_abs = if s.v.abs() <= accel * self.dt || za <= travel { steepest } else { kappa.abs() };
        let z_slope = if UNIT { 1.0 } else { math::powf(za + travel, self.nu - 1.0) };
        let omega = math::sqrt((self.k + self.alpha - kappa * zn).abs() * self.inv_m);
        let relax = kappa_abs * self.nu * v_max * z_slope + self.relax_c;
        let wanted = (omega * self.osc_scale).max(relax * self.relax_scale).max(self.force_steps);
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

/// The force over one sample interval as a function of the time t \[s\] since the
/// interval's start (t ∈ \[0, dt\]): what the input does between samples
/// ([`crate::reconstruction`]).
pub trait Force: Copy {
    /// F(t) \[N\].
    fn at(&self, t: f64) -> f64;
    /// dF/dt \[N/s\].
    fn slope(&self, t: f64) -> f64;
}

/// A held force (zero-order hold).
#[derive(Debug, Clone, Copy)]
pub struct Held(pub f64);

impl Force for Held {
    #[inline(always)]
    fn at(&self, _t: f64) -> f64 {
        self.0
    }
    #[inline(always)]
    fn slope(&self, _t: f64) -> f64 {
        0.0
    }
}

/// A force going linearly from `start` at a rate `rate` \[N/s\].
#[derive(Debug, Clone, Copy)]
pub struct Ramp {
    /// F at the interval's start \[N\].
    pub start: f64,
    /// dF/dt \[N/s\].
    pub rate: f64,
}

impl Ramp {
    /// The ramp from `f0` to `f1` \[N\] over `dt` \[s\].
    #[inline(always)]
    pub fn between(f0: f64, f1: f64, dt: f64) -> Self {
        Ramp { start: f0, rate: (f1 - f0) / dt }
    }
}

impl Force for Ramp {
    #[inline(always)]
    fn at(&self, t: f64) -> f64 {
        self.start + self.rate * t
    }
    #[inline(always)]
    fn slope(&self, _t: f64) -> f64 {
        self.rate
    }
}

/// A band-limited force over an interval: the polynomial of
/// [`crate::reconstruction::InputPath`] in x = 2t/dt − 1.
#[derive(Debug, Clone, Copy)]
pub struct Smooth<'a> {
    /// The coefficients, lowest degree first.
    pub coefficients: &'a [f64; KNOTS],
    /// 2/dt \[1/s\].
    pub scale: f64,
}

impl Force for Smooth<'_> {
    #[inline(always)]
    fn at(&self, t: f64) -> f64 {
        polynomial(self.coefficients, t * self.scale - 1.0)
    }
    #[inline(always)]
    fn slope(&self, t: f64) -> f64 {
        polynomial_slope(self.coefficients, t * self.scale - 1.0) * self.scale
    }
}

/// Advances the state over one sample interval `dt` \[s\] under `force`, in `plan` RK6
/// sub-steps, or ([`None`]) [`IMPLICIT_SUBSTEPS`] linearly implicit Euler steps (each
/// with the force at its end); `UNIT`: ν = 1 ([`abs_pow`]). A sub-step that holds a
/// kink of |ẏ| or |z| is taken again in pieces split at it (module docs).
#[inline(always)]
pub fn advance<S: Scalar, const UNIT: bool, F: Force>(
    c: &Coefficients<S>,
    s: State<S>,
    force: &F,
    dt: f64,
    plan: Option<u32>,
) -> State<S> {
    let Some(m) = plan else {
        return advance_implicit::<S, UNIT, F>(c, s, force, dt);
    };
    let step = if m == 1 { dt } else { dt / m as f64 };
    let mut s = s;
    for i in 0..m {
        let t0 = step * i as f64;
        let f = STAGE_TIME.map(|c| force.at(t0 + c * step));
        let mut next = rk6(&s, step, |state, stage| rate::<S, UNIT>(c, state, f[FORCE_OF_STAGE[stage]]));
        if let Some(kink) = crossing(&s, &next, None) {
            next = split::<S, UNIT, F>(c, &s, &next, t0, step, force, kink);
        }
        s = State {
            y: settle(next.y, s.y, Y_LIMIT_M),
            v: settle(next.v, s.v, V_LIMIT_M_S),
            z: settle(next.z, s.z, Z_LIMIT_N),
        };
    }
    s
}

/// The distinct stage times of [`rk6`] as fractions of its step.
const STAGE_TIME: [f64; 5] = [0.0, 1.0 / 3.0, 2.0 / 3.0, 0.5, 1.0];
/// The stage time (index into [`STAGE_TIME`]) of each of the seven stages.
const FORCE_OF_STAGE: [usize; 7] = [0, 1, 2, 1, 3, 3, 4];

/// Butcher's seven-stage sixth-order Runge–Kutta method (1964): c = 0, 1/3, 2/3, 1/3,
/// 1/2, 1/2, 1 and the weights 11/120, 0, 27/40, 27/40, −4/15, −4/15, 11/120. One step
/// of length `h` (a number, or a number type of the integration for a piece whose
/// length carries derivatives) from `s`, `rate_at(state, stage)` the right-hand side at
/// the stage's time.
#[inline(always)]
fn rk6<S: Scalar + Mul<H, Output = S>, H: Copy>(
    s: &State<S>,
    h: H,
    mut rate_at: impl FnMut(&State<S>, usize) -> State<S>,
) -> State<S> {
    // Each stage's state is s + h·Σ aⱼ·kⱼ, written out per component.
    macro_rules! stage {
        ($a0:expr, $k0:ident $(; $a:expr, $k:ident)*) => {
            State {
                y: s.y + ($k0.y * $a0 $(+ $k.y * $a)*) * h,
                v: s.v + ($k0.v * $a0 $(+ $k.v * $a)*) * h,
                z: s.z + ($k0.z * $a0 $(+ $k.z * $a)*) * h,
            }
        };
    }
    let k1 = rate_at(s, 0);
    let k2 = rate_at(&stage!(1.0 / 3.0, k1), 1);
    let k3 = rate_at(&stage!(2.0 / 3.0, k2), 2);
    let k4 = rate_at(&stage!(1.0 / 12.0, k1; 1.0 / 3.0, k2; -1.0 / 12.0, k3), 3);
    let k5 = rate_at(&stage!(-1.0 / 16.0, k1; 9.0 / 8.0, k2; -3.0 / 16.0, k3; -3.0 / 8.0, k4), 4);
    let k6 = rate_at(&stage!(9.0 / 8.0, k2; -3.0 / 8.0, k3; -3.0 / 4.0, k4; 0.5, k5), 5);
    let k7 = rate_at(&stage!(9.0 / 44.0, k1; -9.0 / 11.0, k2; 63.0 / 44.0, k3; 18.0 / 11.0, k4; -16.0 / 11.0, k6), 6);
    stage!(11.0 / 120.0, k1; 27.0 / 40.0, k3; 27.0 / 40.0, k4; -4.0 / 15.0, k5; -4.0 / 15.0, k6; 11.0 / 120.0, k7)
}

/// [`rk6`] over a piece of a sub-step that starts at `t0` \[s\] and lasts `h`, both in the
/// number type of the integration: the force at a stage time t carries dF/dt times
/// t's derivatives.
fn rk6_timed<S: Scalar, const UNIT: bool, F: Force>(
    c: &Coefficients<S>,
    s: &State<S>,
    t0: S,
    h: S,
    force: &F,
) -> State<S> {
    let times = STAGE_TIME.map(|f| t0 + h * f);
    rk6(s, h, |state, stage| {
        let t = times[FORCE_OF_STAGE[stage]];
        let mut r = rate::<S, UNIT>(c, state, force.at(t.re()));
        // ∂F/∂θ = F'(t)·∂t/∂θ enters v̇ as (1/m)·∂F/∂θ.
        r.v = r.v + c.inv_m * ((t - S::cst(t.re())) * force.slope(t.re()));
        r
    })
}

/// The sub-step from `s` at `t0` \[s\] of length `h`, whose RK6 step ended at `next` with
/// `kink` between, again in pieces split at the kink (module docs). The kink is
/// bracketed between a state on the start's side of it, reached by steps that do not
/// cross it, and one on the other side; its time is estimated where the straight line
/// between the two crosses zero, and that estimate refined [`KINK_REFINEMENTS`] times by
/// a step from the near state to it, which replaces one end of the bracket. The rest of
/// the sub-step is split again where it holds the other variable's kink. Every time is
/// in the number type of the integration.
#[cold]
#[inline(never)]
fn split<S: Scalar, const UNIT: bool, F: Force>(
    c: &Coefficients<S>,
    s: &State<S>,
    next: &State<S>,
    t0: f64,
    h: f64,
    force: &F,
    kink: Kink<S>,
) -> State<S> {
    let var = kink.variable;
    let side = var.of(s).re() > 0.0;
    let (mut near, mut near_t) = (*s, S::cst(t0));
    let (mut far, mut far_t) = (*next, S::cst(t0 + h));
    let mut at = near_t + (far_t - near_t) * kink.fraction;
    for _ in 0..KINK_REFINEMENTS {
        let state = rk6_timed::<S, UNIT, F>(c, &near, near_t, at - near_t, force);
        let x = var.of(&state).re();
        if x == 0.0 {
            break;
        }
        if (x > 0.0) == side {
            (near, near_t) = (state, at);
        } else {
            (far, far_t) = (state, at);
        }
        at = near_t + (far_t - near_t) * fraction(var.of(&near), var.of(&far));
    }
    let on = rk6_timed::<S, UNIT, F>(c, &near, near_t, at - near_t, force);
    let end_t = S::cst(t0 + h);
    let end = rk6_timed::<S, UNIT, F>(c, &on, at, end_t - at, force);
    match crossing(&on, &end, Some(var)) {
        Some(other) => {
            let d = at + (end_t - at) * other.fraction;
            let second = rk6_timed::<S, UNIT, F>(c, &on, at, d - at, force);
            rk6_timed::<S, UNIT, F>(c, &second, d, end_t - d, force)
        }
        None => end,
    }
}

/// Which state variable has its kink in a sub-step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Variable {
    /// ẏ (a velocity reversal: the kink of |ẏ|).
    V,
    /// z (a zero crossing of the hysteretic force: the kink of |z|).
    Z,
}

impl Variable {
    #[inline(always)]
    fn of<S: Copy>(self, s: &State<S>) -> S {
        match self {
            Variable::V => s.v,
            Variable::Z => s.z,
        }
    }
}

/// A kink within a sub-step: the fraction of the sub-step at which the straight line
/// between its two ends crosses zero, in the number type of the integration.
#[derive(Debug, Clone, Copy)]
struct Kink<S> {
    fraction: S,
    variable: Variable,
}

/// x/(x − y): where the straight line from x to y crosses zero, for x and y of opposite
/// signs (in (0, 1)).
#[inline(always)]
fn fraction<S: Scalar>(x: S, y: S) -> S {
    let d = x - y;
    let inv = 1.0 / d.re();
    x * (d * (-inv * inv)).with_re(inv)
}

/// The first kink between the states `a` and `b` at the two ends of a sub-step (ẏ or z
/// of opposite signs at the ends), other than of `after` (the variable whose kink the
/// sub-step was just split at); `None` for none.
#[inline(always)]
fn crossing<S: Scalar>(a: &State<S>, b: &State<S>, after: Option<Variable>) -> Option<Kink<S>> {
    let at = |which: Variable| {
        let (x, y) = (which.of(a), which.of(b));
        (after != Some(which) && x.re() * y.re() < 0.0).then(|| Kink { fraction: fraction(x, y), variable: which })
    };
    match (at(Variable::V), at(Variable::Z)) {
        (Some(v), Some(z)) => Some(if z.fraction.re() < v.fraction.re() { z } else { v }),
        (v, z) => v.or(z),
    }
}

/// The interval in [`IMPLICIT_SUBSTEPS`] linearly implicit Euler steps, each with the
/// force at its end (kept out of line: the RK6 path is the usual one).
#[cold]
#[inline(never)]
fn advance_implicit<S: Scalar, const UNIT: bool, F: Force>(
    c: &Coefficients<S>,
    s: State<S>,
    force: &F,
    dt: f64,
) -> State<S> {
    let h = dt / IMPLICIT_SUBSTEPS as f64;
    let mut s = s;
    for i in 1..=IMPLICIT_SUBSTEPS {
        let t = if i == IMPLICIT_SUBSTEPS { dt } else { h * i as f64 };
        s = implicit_substep::<S, UNIT>(c, s, force.at(t), h);
    }
    s
}

/// The state's values.
#[inline(always)]
pub fn values<S: Scalar>(s: &State<S>) -> State<f64> {
    State { y: s.y.re(), v: s.v.re(), z: s.z.re() }
}
