//! The inverse model: the voltage that makes the model produce a desired displacement.
//!
//! Per sample k, given the model's state after the previous sample (hₖ₋₁, uₖ₋₁),
//! [`Inverse::step`] solves
//!
//! ```text
//! f(u) = kv·u + x0 + Φ(hₖ₋₁, uₖ₋₁ → u) − x_d,ₖ = 0,     Φ = crate::model::advance_h
//! ```
//!
//! for uₖ within the voltage limits, then advances h with the uₖ it returns (the
//! clipped one where the limits bind). Φ is the simulator's integrator itself, so
//! `simulate(p, u)` reproduces x_d sample for sample wherever the root exists (within
//! the solver's tolerance, [`TOLERANCE_UM`]·max(1, |x_d|) µm), not one sample late.
//!
//! **Shape of f.** Between samples u is a straight line, so within an interval
//! ḣ = (A − (β·sgn(u̇)·sgn(h) + γ)·|h|^n)·u̇ + δ·u·sgn(u̇). Away from u = uₖ₋₁, f is
//! smooth with the slope of the loading branch (u > uₖ₋₁) or the unloading one
//! (u < uₖ₋₁), `kv + A − (±β·sgn(h) + γ)·|h|^n`, positive for physical parameters.
//! At u = uₖ₋₁ itself the δ term makes f jump: holding u keeps h, while the smallest
//! move changes h by δ·uₖ₋₁·Δt in the direction of the move (both for the model and
//! for the simulator). So f is monotone and continuous on each side of uₖ₋₁, with a
//! step of ±δ·uₖ₋₁·Δt there; with δ·u > 0 the step is upward and f stays monotone,
//! with δ·u < 0 it is downward and a small target may have a root on each side.
//!
//! **Solver** (bounded work, no allocation):
//! 1. *Hold.* If f(uₖ₋₁) is within the tolerance, uₖ = uₖ₋₁ (h does not move): a
//!    staircase's holds are reproduced exactly.
//! 2. *Side choice.* Each side of uₖ₋₁ is linearised with its branch slope and its
//!    one-sided value f(uₖ₋₁±) = f(uₖ₋₁) ± δ·uₖ₋₁·Δt; the sides whose linear root lies
//!    on them are searched, the nearer first.
//! 3. *Search.* From the linear root, secant (Newton with a numerical slope) steps
//!    until |f| ≤ tolerance or f changes sign, at most [`MAX_SEARCH_STEPS`] per side;
//!    a step that would pass a limit stops at the limit, and if f has not changed
//!    sign there, the limit is the answer (the sample is *clipped*).
//! 4. *Bracket.* Once f changes sign, Illinois false position inside the bracket
//!    (converges for any continuous f; superlinear on smooth f).
//!
//! At most [`MAX_EVALUATIONS`] evaluations of Φ per sample, whatever happens; on the
//! usual samples 1–3. Where the root lies beyond a limit, u is that limit and
//! [`InverseStatus::clip`] says which (even where holding u would come marginally
//! closer, as the δ step can make it: a clipped sample sits on its limit). Where no root
//! is found at all (the budget spent, or a model whose x does not rise with u), the
//! evaluated u with the smallest |f| is returned and `exact` is false.
//!
//! **Reversals.** Where x_d turns, the needed move of x may be smaller than the jump
//! |δ·uₖ₋₁|·Δt at the kink (e.g. 3.75e-5 µm at 50 V with the paper's δ at 10 kHz,
//! for about a millisecond around a turn of a slow sine). No voltage then gives x_d
//! exactly: the inverse returns the better of holding u and the smallest move across
//! the kink, the residual is at most the jump, and `exact` is false for that sample.
//! Where the needed move is larger, the root is on the side the linearisation of
//! each branch points to, so the turn itself costs nothing.
//!
//! **Jumps of the discrete map.** The integrator decides its sub-steps on values
//! ([`crate::model::integrator`]), so where the number of sub-steps changes with u (a
//! stiff interval; h crossing 0 with n < 1, where one RK4 step becomes two) x(u) jumps
//! by the difference of two discretisations of the interval: 7e-6 µm at 10 kHz for
//! n = 0.3 with h within 1e-4 µm of 0, for example. A target inside such a jump has no
//! root either: the bracket narrows onto the jump, the evaluated side nearer the target
//! is returned, `exact` is false and the residual is at most the jump.
//!
//! **First sample.** Without a previous sample the model keeps h = h0, so x = kv·u +
//! x0 + h0 is solved directly (as [`crate::Model::step`] on its first sample).

use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::model::integrator::{abs_pow, advance_h_carried};
use crate::model::{sgn, ModelState};
use crate::params::Params;
use alloc::vec;
use alloc::vec::Vec;

/// Most evaluations of the integrator per sample (the worst case of the solver).
pub const MAX_EVALUATIONS: u32 = 40;
/// Most secant steps on one side of the previous voltage before a bracket is found.
pub const MAX_SEARCH_STEPS: u32 = 12;
/// Tolerance on |model x − x_d| \[µm\], relative to max(1, |x_d| / 1 µm): a tenth of
/// a picometre per micrometre, a thousand times below the resolution of the best
/// capacitive sensors. Solving further only adds evaluations: from the branch's
/// linearisation the first secant step lands within it on most samples (85 % on the
/// paper's record at 10 kHz; within 1e-12 µm only after a second or third step).
pub const TOLERANCE_UM: f64 = 1e-7;

/// Voltage limits of the amplifier \[V\]; `-∞`/`+∞` = no limit on that side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageLimits {
    /// Lowest voltage \[V\].
    pub min_v: f64,
    /// Highest voltage \[V\].
    pub max_v: f64,
}

impl Default for VoltageLimits {
    fn default() -> Self {
        Self::NONE
    }
}

impl VoltageLimits {
    /// No limits.
    pub const NONE: VoltageLimits = VoltageLimits { min_v: f64::NEG_INFINITY, max_v: f64::INFINITY };

    /// Limits from optional bounds \[V\]: not NaN, `min_v` below +∞, `max_v` above −∞,
    /// `min_v ≤ max_v`.
    pub fn new(min_v: Option<f64>, max_v: Option<f64>) -> Result<Self> {
        let limits = VoltageLimits { min_v: min_v.unwrap_or(f64::NEG_INFINITY), max_v: max_v.unwrap_or(f64::INFINITY) };
        limits.validate()?;
        Ok(limits)
    }

    /// Checks the limits (see [`VoltageLimits::new`]).
    pub fn validate(&self) -> Result<()> {
        if self.min_v.is_nan() || self.min_v == f64::INFINITY {
            return Err(Error::InvalidConfig {
                name: "u_min",
                value: self.min_v,
                reason: "the lower voltage limit must be a number below +inf (V)",
            });
        }
        if self.max_v.is_nan() || self.max_v == f64::NEG_INFINITY {
            return Err(Error::InvalidConfig {
                name: "u_max",
                value: self.max_v,
                reason: "the upper voltage limit must be a number above -inf (V)",
            });
        }
        if self.min_v > self.max_v {
            return Err(Error::InvalidConfig {
                name: "u_max",
                value: self.max_v,
                reason: "the upper voltage limit must be >= the lower one (u_min)",
            });
        }
        Ok(())
    }

    /// `u` within the limits.
    #[inline]
    pub fn contains(&self, u: f64) -> bool {
        self.min_v <= u && u <= self.max_v
    }

    /// `u` held within the limits, and which limit bound.
    #[inline]
    pub fn clamp(&self, u: f64) -> (f64, Clip) {
        if u < self.min_v {
            (self.min_v, Clip::Low)
        } else if u > self.max_v {
            (self.max_v, Clip::High)
        } else {
            (u, Clip::None)
        }
    }
}

/// Whether a voltage limit bound on a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Clip {
    /// The sample is within the limits.
    #[default]
    None,
    /// The root lies below `min_v`: u = `min_v`.
    Low,
    /// The root lies above `max_v`: u = `max_v`.
    High,
}

impl Clip {
    /// Lower-case name, for logs and Python (`"none"`, `"low"`, `"high"`).
    pub fn name(self) -> &'static str {
        match self {
            Clip::None => "none",
            Clip::Low => "low",
            Clip::High => "high",
        }
    }
}

/// What the last [`Inverse::step`] did. Small and `Copy`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InverseStatus {
    /// Which limit bound, if any.
    pub clip: Clip,
    /// Evaluations of the integrator in this step (≤ [`MAX_EVALUATIONS`]).
    pub evaluations: u32,
    /// Model displacement minus x_d after the step \[µm\].
    pub residual_um: f64,
    /// |residual| within the tolerance.
    pub exact: bool,
    /// Samples since construction or reset.
    pub samples: u64,
    /// Samples that were clipped since construction or reset.
    pub clipped_samples: u64,
}

/// One interval's equation in the voltage w that the Bouc–Wen operator sees at the
/// end of the interval (w = u for the base model):
///
/// ```text
/// F(w) = linear·w + offset + Φ(h, w_prev → w) − 0      \[µm\]
/// ```
///
/// `offset` includes −x_d, so a root of F is a solution.
#[derive(Debug, Clone, Copy)]
pub(crate) struct IntervalEquation<'a> {
    pub p: &'a Params,
    /// h at the start of the interval \[µm\].
    pub h: f64,
    /// w at the start of the interval \[V\].
    pub w_prev: f64,
    pub dt: f64,
    /// ∂(x − h)/∂w \[µm/V\]: kv, plus what else responds to w at once.
    pub linear: f64,
    /// The rest of x − h, minus the target \[µm\].
    pub offset: f64,
    /// |h|^n at the start of the interval.
    hn: f64,
}

impl<'a> IntervalEquation<'a> {
    /// The equation of the interval from state `h` \[µm\] (whose |h|^n is `hn`, as
    /// carried) and voltage `w_prev` \[V\] over `dt` \[s\], with `linear` \[µm/V\]
    /// and `offset` \[µm\] as the fields say.
    pub fn new(p: &'a Params, h: f64, hn: f64, w_prev: f64, dt: f64, linear: f64, offset: f64) -> Self {
        IntervalEquation { p, h, w_prev, dt, linear, offset, hn }
    }

    /// F(w) \[µm\], and h \[µm\] and |h|^n at the end of the interval.
    #[inline]
    fn eval(&self, w: f64) -> (f64, f64, f64) {
        let (h, hn) = advance_h_carried(self.p, self.h, self.hn, self.w_prev, w, self.dt);
        (self.linear * w + self.offset + h, h, hn)
    }
}

/// A root of an [`IntervalEquation`] (or the best point found).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Solution {
    pub w: f64,
    /// h at the end of the interval for this w \[µm\].
    pub h: f64,
    /// |h|^n for that h.
    pub hn: f64,
    /// F(w) \[µm\].
    pub residual: f64,
    pub clip: Clip,
    pub evaluations: u32,
}

#[derive(Clone, Copy)]
struct Point {
    w: f64,
    f: f64,
}

/// The evaluated point with the smallest |F|, the answer at a limit if a limit
/// binds, and the evaluation count.
struct Search<'e, 'p> {
    eq: &'e IntervalEquation<'p>,
    tol: f64,
    evaluations: u32,
    best: Option<Solution>,
    /// The limit a promising side ran into before F changed sign.
    limit: Option<Solution>,
}

impl Search<'_, '_> {
    fn offer(&mut self, w: f64, f: f64, h: f64, hn: f64) {
        let better = match self.best {
            None => true,
            Some(b) => f.abs() < b.residual.abs(),
        };
        if better && f.is_finite() {
            self.best = Some(Solution { w, h, hn, residual: f, clip: Clip::None, evaluations: 0 });
        }
    }

    /// Evaluates F at w (None when the budget is spent).
    fn eval(&mut self, w: f64) -> Option<(Point, f64, f64)> {
        if self.evaluations >= MAX_EVALUATIONS {
            return None;
        }
        self.evaluations += 1;
        let (f, h, hn) = self.eq.eval(w);
        self.offer(w, f, h, hn);
        Some((Point { w, f }, h, hn))
    }

    /// Records that the root lies beyond a limit: the answer is u = that limit.
    fn bind(&mut self, w: f64, f: f64, (h, hn): (f64, f64), clip: Clip) {
        if self.limit.is_none() && f.is_finite() {
            self.limit = Some(Solution { w, h, hn, residual: f, clip, evaluations: 0 });
        }
    }

    fn done(&self) -> bool {
        self.best.is_some_and(|b| b.residual.abs() <= self.tol)
    }

    fn finish(self) -> Solution {
        let fallback = Solution {
            w: self.eq.w_prev,
            h: self.eq.h,
            hn: self.eq.hn,
            residual: f64::INFINITY,
            clip: Clip::None,
            evaluations: 0,
        };
        let mut s = match (self.best, self.limit) {
            (Some(b), _) if b.residual.abs() <= self.tol => b,
            (_, Some(l)) => l,
            (Some(b), None) => b,
            (None, None) => fallback,
        };
        s.evaluations = self.evaluations;
        s
    }

    /// Illinois false position in the bracket (a, b), F(a)·F(b) < 0; `a` may be the
    /// virtual one-sided point at the kink (its value is a limit, not an evaluation).
    fn refine(&mut self, mut a: Point, mut b: Point) {
        let mut fa = a.f;
        while !self.done() {
            let mut c = b.w - b.f * (b.w - a.w) / (b.f - fa);
            let (lo, hi) = if a.w < b.w { (a.w, b.w) } else { (b.w, a.w) };
            if !(c > lo && c < hi) {
                c = 0.5 * (a.w + b.w);
                if !(c > lo && c < hi) {
                    return; // the bracket is down to adjacent floats
                }
            }
            let Some((p, _, _)) = self.eval(c) else { return };
            if p.f == 0.0 {
                return;
            }
            if (p.f > 0.0) == (b.f > 0.0) {
                fa *= 0.5;
            } else {
                a = b;
                fa = b.f;
            }
            b = p;
        }
    }

    /// Searches the side σ (+1: w > w_prev, −1: w < w_prev) of the kink within
    /// [lo, hi], starting at the distance `d0` from the kink. `f_side` is F's
    /// one-sided value at the kink.
    fn side(&mut self, sigma: f64, d0: f64, f_side: f64, lo: f64, hi: f64) {
        let w0 = self.eq.w_prev;
        let (far, near, far_clip, near_clip) =
            if sigma > 0.0 { (hi, lo, Clip::High, Clip::Low) } else { (lo, hi, Clip::Low, Clip::High) };
        if sigma * (far - w0) <= 0.0 {
            // No room on this side: the last sample sat on the limit and the root lies beyond it.
            if w0 == far {
                let f0 = self.eq.linear * w0 + self.eq.offset + self.eq.h;
                self.bind(w0, f0, (self.eq.h, self.eq.hn), far_clip);
            }
            return;
        }
        let mut a = Point { w: w0, f: f_side };
        if sigma * (near - w0) > 0.0 {
            // The kink lies outside the limits: this side starts at the near limit.
            let Some((p, h, hn)) = self.eval(near) else { return };
            if self.done() {
                return;
            }
            if (p.f > 0.0) != (f_side > 0.0) {
                // The root lies between the kink and the limit, outside the limits.
                self.bind(near, p.f, (h, hn), near_clip);
                return;
            }
            a = p;
        }
        let mut w = w0 + sigma * d0;
        for _ in 0..MAX_SEARCH_STEPS {
            if sigma * (w - far) >= 0.0 {
                w = far;
            }
            if sigma * (w - a.w) <= 0.0 {
                // The secant points back: fall back to doubling the distance.
                w = a.w + sigma * (a.w - w0).abs().max(d0.abs());
                if sigma * (w - far) >= 0.0 {
                    w = far;
                }
            }
            let Some((p, h, hn)) = self.eval(w) else { return };
            if self.done() {
                return;
            }
            if (p.f > 0.0) != (a.f > 0.0) {
                self.refine(a, p);
                return;
            }
            if w == far {
                self.bind(far, p.f, (h, hn), far_clip); // F keeps its sign up to the limit
                return;
            }
            // Secant through the last two points, extrapolated to F = 0.
            let slope = (p.f - a.f) / (p.w - a.w);
            let next = p.w - p.f / slope;
            let step_max = 4.0 * (p.w - w0).abs();
            w = if next.is_finite() && sigma * (next - p.w) > 0.0 {
                p.w + sigma * (sigma * (next - p.w)).min(step_max)
            } else {
                p.w + sigma * step_max
            };
            a = p;
        }
    }
}

/// Solves an [`IntervalEquation`] for w within [lo, hi] (see the module docs).
pub(crate) fn solve(eq: &IntervalEquation<'_>, lo: f64, hi: f64, tol: f64) -> Solution {
    let mut search = Search { eq, tol, evaluations: 0, best: None, limit: None };
    let w0 = eq.w_prev;
    let f0 = eq.linear * w0 + eq.offset + eq.h;
    let hold_allowed = lo <= w0 && w0 <= hi;
    if hold_allowed {
        search.offer(w0, f0, eq.h, eq.hn);
        if search.done() {
            return search.finish();
        }
    }
    let p = eq.p;
    let jump = p.delta * w0 * eq.dt;
    let hn = eq.hn;
    let sh = sgn(eq.h);
    let slope_up = eq.linear + p.a - (p.beta * sh + p.gamma) * hn;
    let slope_down = eq.linear + p.a - (-p.beta * sh + p.gamma) * hn;
    let (f_up, f_down) = (f0 + jump, f0 - jump);
    // Distance from the kink to the linear root on each side (> 0: on that side).
    let d_up = -f_up / slope_up;
    let d_down = f_down / slope_down;
    let promising = |d: f64| d.is_finite() && d > 0.0;
    let mut sides = [(1.0, d_up, f_up), (-1.0, d_down, f_down)];
    if promising(d_down) && (!promising(d_up) || d_down < d_up) {
        sides.swap(0, 1);
    }
    for &(sigma, d, f_side) in &sides {
        if promising(d) && !search.done() {
            search.side(sigma, d, f_side, lo, hi);
        }
    }
    let any_promising = promising(d_up) || promising(d_down);
    if !search.done() && hold_allowed && !any_promising {
        // Neither side has a root: the target sits in the step at the kink (a
        // reversal, see the module docs). The smallest move lands on the one-sided value.
        for (sigma, f_side) in [(1.0, f_up), (-1.0, f_down)] {
            let best = search.best.map_or(f64::INFINITY, |b| b.residual.abs());
            if f_side.abs() < best {
                let w = w0 + sigma * 1e-12 * w0.abs().max(1.0);
                if lo <= w && w <= hi {
                    search.eval(w);
                }
            }
        }
    }
    search.finish()
}

/// The tolerance for a target x_d \[µm\].
#[inline]
pub(crate) fn tolerance(x_d: f64) -> f64 {
    TOLERANCE_UM * x_d.abs().max(1.0)
}

/// The per-sample inverse model: `step(x_d) -> u` (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Inverse {
    params: Params,
    dt: f64,
    limits: VoltageLimits,
    h0: f64,
    state: ModelState,
    /// |h|^n for the current h, carried as by the [`crate::Model`].
    hn: f64,
    status: InverseStatus,
}

impl Inverse {
    /// An inverse of the model `params` for samples `dt` \[s\] apart, starting from
    /// h = `h0` \[µm\] with no previous sample, within `limits`. `params` must lie in the
    /// admissible region ([`Params::check_admissible`]): the inverse of a model whose h
    /// runs away would command the voltage that follows it.
    pub fn new(params: Params, dt: f64, h0: f64, limits: VoltageLimits) -> Result<Self> {
        params.check_admissible()?;
        positive_dt(dt)?;
        finite_sample("h0", h0)?;
        limits.validate()?;
        Ok(Inverse {
            params,
            dt,
            limits,
            h0,
            state: ModelState { h: h0, u_prev: None },
            hn: abs_pow(h0, params.n),
            status: InverseStatus::default(),
        })
    }

    /// Takes the desired displacement `x_d` \[µm\] of the next sample and returns the
    /// voltage u \[V\] for it; the model's h advances with that u. A non-finite `x_d` is
    /// rejected and the state kept. Allocation-free; at most [`MAX_EVALUATIONS`]
    /// evaluations of the integrator.
    pub fn step(&mut self, x_d: f64) -> Result<f64> {
        finite_sample("x_d", x_d)?;
        let p = &self.params;
        let tol = tolerance(x_d);
        let (u, h, hn, residual, clip, evaluations) = match self.state.u_prev {
            None => {
                let (u, clip) = first_sample_voltage(p.kv, p.x0 + self.state.h - x_d, &self.limits);
                let residual = p.kv * u + p.x0 + self.state.h - x_d;
                (u, self.state.h, self.hn, residual, clip, 0)
            }
            Some(u_prev) => {
                let eq = IntervalEquation::new(p, self.state.h, self.hn, u_prev, self.dt, p.kv, p.x0 - x_d);
                let s = solve(&eq, self.limits.min_v, self.limits.max_v, tol);
                (s.w, s.h, s.hn, s.residual, s.clip, s.evaluations)
            }
        };
        self.state = ModelState { h, u_prev: Some(u) };
        self.hn = hn;
        let clipped = clip != Clip::None;
        self.status = InverseStatus {
            clip,
            evaluations,
            residual_um: residual,
            exact: residual.abs() <= tol,
            samples: self.status.samples + 1,
            clipped_samples: self.status.clipped_samples + u64::from(clipped),
        };
        Ok(u)
    }

    /// The model's parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Replaces the parameters (validated, in the admissible region); h and the previous
    /// voltage are kept.
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        params.check_admissible()?;
        if params.n != self.params.n {
            self.hn = abs_pow(self.state.h, params.n);
        }
        self.params = params;
        Ok(())
    }

    /// The hysteresis state h \[µm\] after the last sample.
    pub fn h(&self) -> f64 {
        self.state.h
    }

    /// The state carried between samples (h and the previous voltage).
    pub fn state(&self) -> ModelState {
        self.state
    }

    /// Restores a state (e.g. a model's or an identifier's h after the same voltages).
    pub fn set_state(&mut self, state: ModelState) -> Result<()> {
        finite_sample("h", state.h)?;
        if let Some(u) = state.u_prev {
            finite_sample("u_prev", u)?;
        }
        self.state = state;
        self.hn = abs_pow(state.h, self.params.n);
        Ok(())
    }

    /// The voltage limits.
    pub fn limits(&self) -> VoltageLimits {
        self.limits
    }

    /// Replaces the voltage limits (validated).
    pub fn set_limits(&mut self, limits: VoltageLimits) -> Result<()> {
        limits.validate()?;
        self.limits = limits;
        Ok(())
    }

    /// Sampling interval \[s\].
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The initial h \[µm\] that [`Inverse::reset`] returns to.
    pub fn h0(&self) -> f64 {
        self.h0
    }

    /// What the last step did.
    pub fn status(&self) -> InverseStatus {
        self.status
    }

    /// Restores a status taken with [`Inverse::status`] (counters included), e.g.
    /// after a snapshot.
    pub fn set_status(&mut self, status: InverseStatus) {
        self.status = status;
    }

    /// Forgets the past: h = h0, no previous sample, counters zero.
    pub fn reset(&mut self) {
        self.state = ModelState { h: self.h0, u_prev: None };
        self.hn = abs_pow(self.h0, self.params.n);
        self.status = InverseStatus::default();
    }
}

/// The first sample: x = `gain`·u + `rest` is linear in u; the root held within the
/// limits (u = 0, or the limit nearest to it, when `gain` is 0).
pub(crate) fn first_sample_voltage(gain: f64, rest: f64, limits: &VoltageLimits) -> (f64, Clip) {
    let u = -rest / gain;
    if u.is_finite() {
        limits.clamp(u)
    } else {
        (limits.clamp(0.0).0, Clip::None)
    }
}

/// Summary of a batch inversion ([`invert_into`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InvertSummary {
    /// h after the last sample \[µm\].
    pub h_final: f64,
    /// Samples where a limit bound.
    pub clipped_samples: u64,
    /// Samples whose residual exceeds the tolerance without a limit binding
    /// (targets in the step at a reversal, see the module docs).
    pub inexact_samples: u64,
    /// Largest |model x − x_d| over the record \[µm\].
    pub max_residual_um: f64,
    /// Largest number of integrator evaluations in one sample.
    pub max_evaluations: u32,
    /// Mean number of integrator evaluations per sample.
    pub mean_evaluations: f64,
}

/// Inverts a whole record: writes into `u_out` the voltages \[V\] for the desired
/// displacements `x_d` \[µm\] sampled every `dt` \[s\], from h = `h0` \[µm\]. With
/// `u_prev = Some(v)` the first interval starts at v (continue a record in chunks, as
/// [`crate::simulate_into`]). Input with a non-finite value is rejected before
/// anything is computed.
pub fn invert_into(
    params: &Params,
    x_d: &[f64],
    dt: f64,
    h0: f64,
    u_prev: Option<f64>,
    limits: VoltageLimits,
    u_out: &mut [f64],
) -> Result<InvertSummary> {
    if u_out.len() != x_d.len() {
        return Err(Error::LengthMismatch { what: "invert output", expected: x_d.len(), found: u_out.len() });
    }
    let mut inv = Inverse::new(*params, dt, h0, limits)?;
    inv.set_state(ModelState { h: h0, u_prev })?;
    for &v in x_d {
        finite_sample("x_d", v)?;
    }
    let mut summary = InvertSummary::default();
    let mut total = 0u64;
    for (u, &target) in u_out.iter_mut().zip(x_d) {
        *u = inv.step(target)?;
        let s = inv.status();
        summary.inexact_samples += u64::from(!s.exact && s.clip == Clip::None);
        summary.max_residual_um = summary.max_residual_um.max(s.residual_um.abs());
        summary.max_evaluations = summary.max_evaluations.max(s.evaluations);
        total += u64::from(s.evaluations);
    }
    summary.clipped_samples = inv.status().clipped_samples;
    summary.h_final = inv.h();
    summary.mean_evaluations = if x_d.is_empty() { 0.0 } else { total as f64 / x_d.len() as f64 };
    Ok(summary)
}

/// Allocating form of [`invert_into`]: returns `(u, summary)`.
pub fn invert(
    params: &Params,
    x_d: &[f64],
    dt: f64,
    h0: f64,
    u_prev: Option<f64>,
    limits: VoltageLimits,
) -> Result<(Vec<f64>, InvertSummary)> {
    let mut u = vec![0.0; x_d.len()];
    let summary = invert_into(params, x_d, dt, h0, u_prev, limits, &mut u)?;
    Ok((u, summary))
}

/// The largest excess of |x − x_d| \[µm\] over the solver's tolerance for x_d (≤ 0
/// where every sample is within it; rounding of the output sum aside).
#[cfg(test)]
pub(crate) fn beyond_tolerance(x: &[f64], x_d: &[f64]) -> f64 {
    x.iter().zip(x_d).map(|(a, b)| (a - b).abs() - tolerance(*b)).fold(f64::NEG_INFINITY, f64::max)
}

#[cfg(test)]
mod tests;
