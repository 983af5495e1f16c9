//! The paper's online method (Zhu, Bian & Rui 2014, section 3), made robust.
//!
//! Names follow the paper: N is `window_len`; A, β, γ, n, δ are the model's.
//!
//! Per sample k:
//! 1. **Predict** x̂ₖ = kv·uₖ + x0 + hₖ with the estimates from before the sample, h
//!    integrated by the model itself ([`crate::model::advance_h`]).
//! 2. **Derivatives and window.** The paper leaves the derivative estimate open. Here
//!    u̇ and ẋ of sample j are the Savitzky–Golay first derivative over the 2m + 1
//!    samples centred on it (the slope of the local least-squares line, which equals
//!    that of the local quadratic), m set from the input's frequency over the window
//!    ([`PaperConfig::derivative_phase`]): about ±0.3 rad of its phase, 2 samples at
//!    200 Hz and 10 kHz, up to [`PaperConfig::max_half_width`] at 1 Hz. The residual of
//!    the local quadratic fit at the centre measures the noise of x (σ²·(1 − w₀) for
//!    white noise, w₀ the centre weight), and the noise it leaves on ẋ is σ/(√S·Δt),
//!    S = m(m+1)(2m+1)/3. Sample j is completed, and enters the window of the newest N
//!    points, once sample j + m has arrived; the oldest point leaves.
//! 3. **Step 1, kv and x0** (eqs. 6–7): limited-memory recursive least squares of
//!    y on [u, 1]: a rank-one update for the entering point and a rank-one downdate
//!    (Sherman–Morrison) for the leaving one, started from the batch fit of the first
//!    full window and re-synchronised with the exact window sums every N points.
//!    With [`Decomposition::Line`] (the paper, literal) y = x: the line through the
//!    loop. With [`Decomposition::Model`] (default) y = x − h_model: the line that the
//!    model's own h leaves, which is the model's kv rather than the loop's centre line
//!    (the two differ when A ≠ 0: about 0.16 vs 0.19 µm/V with the paper's values).
//!    kv and x0 are taken only while the window resolves kv (`min_line_t`).
//! 4. **Steps 2–5** from running sums of the points in the window (O(1) per point):
//!    each point is classified once, when it enters, with the estimates of that
//!    moment; h = x − kv·u − x0 there.
//!    - step 2 (eqs. 8–9): u̇ > 0 and |h| < `h_zero_frac`·std(x): least squares of ẋ
//!      on [u̇, u] gives A + kv and δ (ẋ is first corrected by the small
//!      |h|^n terms of eq. (5) at the point's h, with the current β, γ, n). If the two
//!      columns are nearly collinear (one frequency puts every such point at the same
//!      (u, u̇)), only A + kv is fitted and δ is kept (ran reduced). So is δ where
//!      δ·u would outweigh the rate term on the points (`max_delta_ratio`).
//!    - step 3 (eqs. 10–12): u̇ > 0 and h above the tolerance: r = (ḣ − δu)/u̇,
//!      ln|A − r| = ln|β+γ| + n·ln h. The sign of A − r is carried: points of each
//!      sign are summed apart and the larger group decides the sign of β + γ.
//!    - step 4 (eqs. 13–14): u̇ < 0, h above the tolerance: r = (ḣ + δu)/u̇,
//!      ln|γ−β| = mean(ln|A − r| − n·ln h), sign carried as in step 3.
//!    - step 5 (eqs. 15–16): β, γ from β+γ and γ−β, accepted only where h stays
//!      bounded for every input (β + γ > 0 and β − γ > 0, as in the paper's Table 2)
//!      and the hysteresis terms stay physically bounded: (|β|+|γ|)·hₛⁿ at most
//!      `max_hysteresis_gain`·|A₀| at the starting model's saturation amplitude hₛ
//!      (without it, long noisy records drive |β|, |γ| to 10³–10⁸ with β ± γ
//!      still > 0); otherwise β, γ and n are held.
//!
//!    Steps 3–4 leave out points whose |A − r| is below `min_arg_frac`·|A| or below
//!    `noise_gate` standard deviations of the noise of r (that of ẋ over |u̇|).
//!    Points with |u̇| below `rate_frac`·rms(u̇) are left out of steps 2–4 (the
//!    ratios divide by u̇). A step with too few points or too little spread keeps its
//!    previous estimate; [`PaperStatus`] says, for each step, whether it ran, ran
//!    reduced or held, why, on how many points and with what scatter.
//!
//!    Two rules hold an update that would make the model worse: the output gate
//!    ([`PaperConfig::output_gate`]: steps 1, 2 and 5 each against the window's own
//!    output error) and the stroke bound ([`PaperConfig::min_stroke_frac`]: every step
//!    holds while the window's rising or falling points span too little of the stroke).
//! 5. **The window fit** (module `window_fit`, once per slide of `fit_every`·N points): the
//!    unknowns of steps 1–4 (and h at the window's start) jointly, by least squares on
//!    the window's own output error, at the precision the window's data allow; taken
//!    where the model explains the window to its noise and resolves kv, A and n
//!    ([`PaperStatus::window_fit`]). Where taken, the model's h follows it.

use alloc::vec::Vec;
use nalgebra::{Matrix2, Vector2};

mod config;
mod output_gate;
mod snapshot;
mod status;
mod sub_fits;
#[cfg(test)]
mod tests;
pub mod window;
mod window_fit;

use super::OnlineIdentifier;
use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::math;
use crate::model::{advance_h, output};
use crate::params::Params;
pub use config::{Decomposition, PaperConfig};
use output_gate::{Gate, Scratch};
pub use status::{PaperStatus, Reason, StepStatus, SubFit};
use sub_fits::{count_u32, hysteresis_bounded, ln_saturation, rate_fit, return_fit, shape_fit, SubFitCache};
use window::{Ring, SlidingRange, WindowSums};

/// Which sub-fit a window point feeds, decided when it enters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
enum Class {
    #[default]
    Unused,
    /// u̇ > 0, h ≈ 0 (step 2).
    Crossing,
    /// u̇ > 0, h > 0, sign of A − r (step 3).
    Loading { positive: bool },
    /// u̇ < 0, h > 0, sign of A − r (step 4).
    Unloading { positive: bool },
}

/// One completed window point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Point {
    u: f64,
    x: f64,
    /// Regressand of step 1 (x, or x − h_model).
    y: f64,
    udot: f64,
    /// ẋ for step 2; ln h for steps 3–4.
    a: f64,
    /// ln|A − r| for steps 3–4.
    b: f64,
    /// Estimate of the variance of the noise of x from this point's local quadratic
    /// fit \[µm²\] (window mean: the noise of the derivatives).
    noise2: f64,
    class: Class,
}

// Layout of the running sums.
const CNT: usize = 0;
const SU: usize = 1;
const SUU: usize = 2;
const SY: usize = 3;
const SUY: usize = 4;
const SX: usize = 5;
const SXX: usize = 6;
const SDD: usize = 7; // Σ u̇²
const SYY: usize = 8;
const C_CNT: usize = 9; // step 2: count, Σu̇², Σu̇u, Σu², Σu̇ẋ, Σuẋ, Σẋ²
const L_POS: usize = 16; // step 3 (+): count, Σz, Σz², Σw, Σzw, Σw²
const L_NEG: usize = 22; // step 3 (−)
const U_POS: usize = 28; // step 4 (+): count, Σz, Σz², Σw, Σzw, Σw²
const U_NEG: usize = 34; // step 4 (−)
const SEE: usize = 40; // Σ noise²
const NSUMS: usize = 41;

impl Point {
    /// Contribution of the point to every running sum (a pure function of the point,
    /// so that removing it subtracts exactly what adding it added).
    fn contribution(&self) -> [f64; NSUMS] {
        let mut c = [0.0; NSUMS];
        c[CNT] = 1.0;
        c[SU] = self.u;
        c[SUU] = self.u * self.u;
        c[SY] = self.y;
        c[SUY] = self.u * self.y;
        c[SX] = self.x;
        c[SXX] = self.x * self.x;
        c[SDD] = self.udot * self.udot;
        c[SYY] = self.y * self.y;
        c[SEE] = self.noise2;
        match self.class {
            Class::Unused => {}
            Class::Crossing => {
                let (d, u, xd) = (self.udot, self.u, self.a);
                c[C_CNT..C_CNT + 7].copy_from_slice(&[1.0, d * d, d * u, u * u, d * xd, u * xd, xd * xd]);
            }
            Class::Loading { positive } | Class::Unloading { positive } => {
                let at = match self.class {
                    Class::Loading { .. } if positive => L_POS,
                    Class::Loading { .. } => L_NEG,
                    _ if positive => U_POS,
                    _ => U_NEG,
                };
                let (z, w) = (self.a, self.b);
                c[at..at + 6].copy_from_slice(&[1.0, z, z * z, w, z * w, w * w]);
            }
        }
        c
    }
}

/// A raw sample waiting for its successors (derivative stencil).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Raw {
    u: f64,
    x: f64,
    h_model: f64,
}

/// Limited-memory RLS of y on φ = [u, 1] (eqs. 6–7).
#[derive(Debug, Clone, Copy, PartialEq)]
struct LineRls {
    theta: Vector2<f64>,
    p: Matrix2<f64>,
    active: bool,
}

impl LineRls {
    /// Batch least squares from the window sums; `None` if singular.
    fn from_sums(s: &[f64; NSUMS]) -> Option<Self> {
        let gram = Matrix2::new(s[SUU], s[SU], s[SU], s[CNT]);
        let p = gram.try_inverse()?;
        let theta = p * Vector2::new(s[SUY], s[SY]);
        (theta.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())).then_some(LineRls {
            theta,
            p,
            active: true,
        })
    }

    /// Rank-one update (sign = +1) or downdate (sign = −1) for the point (u, y).
    #[inline]
    fn rank_one(&mut self, u: f64, y: f64, sign: f64) {
        let phi = Vector2::new(u, 1.0);
        let p_phi = self.p * phi;
        let denom = sign + phi.dot(&p_phi);
        if denom.abs() < 1e-12 || !denom.is_finite() {
            self.active = false;
            return;
        }
        let gain = p_phi / denom;
        let innovation = y - phi.dot(&self.theta);
        self.theta += gain * innovation;
        self.p -= gain * p_phi.transpose();
    }
}

/// Bits of [`PaperIdentifier::touched`]: which point classes entered or left.
const TOUCH_CROSSING: u8 = 1;
const TOUCH_LOADING: u8 = 2;
const TOUCH_UNLOADING: u8 = 4;
const TOUCH_ALL: u8 = 7;

impl Class {
    fn touch_bit(self) -> u8 {
        match self {
            Class::Unused => 0,
            Class::Crossing => TOUCH_CROSSING,
            Class::Loading { .. } => TOUCH_LOADING,
            Class::Unloading { .. } => TOUCH_UNLOADING,
        }
    }
}

/// Savitzky–Golay sums of a stencil of half-width m: S = Σₖ k² over −m … m, and the
/// centre weight w₀ of the local quadratic's value with its numerator constant c₀ and
/// denominator (weights wₖ = (c₀ − 15k²)/den).
fn stencil(m: usize) -> (f64, f64, f64) {
    let mf = m as f64;
    let s2 = mf * (mf + 1.0) * (2.0 * mf + 1.0) / 3.0;
    let c0 = 3.0 * (3.0 * mf * mf + 3.0 * mf - 1.0);
    let den = (2.0 * mf - 1.0) * (2.0 * mf + 1.0) * (2.0 * mf + 3.0);
    (s2, c0, den)
}

/// The paper's online identifier (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct PaperIdentifier {
    config: PaperConfig,
    dt: f64,
    init: Params,
    h0: f64,
    params: Params,
    h_model: f64,
    /// The newest raw samples (2·`max_half_width` + 1 of them), oldest first.
    raw: Ring<Raw>,
    /// Index of the next sample to complete into a window point.
    next: u64,
    /// Window points entered since construction or reset.
    entered: u64,
    window: Ring<Point>,
    sums: WindowSums<NSUMS>,
    rls: LineRls,
    status: PaperStatus,
    /// Point classes that entered or left since the last refit ([`TOUCH_ALL`] after a refresh).
    touched: u8,
    cache: SubFitCache,
    scratch: Scratch,
    /// Least and greatest u seen since construction or reset \[V\] (the stroke).
    u_seen: (f64, f64),
    /// Least and greatest u of the window's rising and falling points \[V\] (the
    /// stroke bound, [`PaperConfig::min_stroke_frac`]; empty where it is off). Rebuilt
    /// from the window's points on restore.
    spans: [SlidingRange; 2],
    /// Window points entered since the window fit last ran.
    since_fit: u64,
    /// The least window noise variance of x seen with a full window \[µm²\] (∞ before):
    /// the window fit's noise ([`PaperConfig::max_misfit`]). Each window's estimate is an
    /// upper bound of the sensor's noise, the signal's curvature adding to it the more
    /// the faster the input (about 1.2 nm at 1 and 10 Hz, 8.5 nm at 100 Hz on the
    /// paper-exact plant of 1.15 nm), and the sensor's noise does not depend on the
    /// input: the least bound seen is the tightest.
    noise_floor2: f64,
    /// The last window fit's result where it was not taken (the next run may start
    /// from it).
    fit_carry: Option<Params>,
    fit_buffers: FitScratch,
}

/// The window fit's buffers ([`window_fit::FitBuffers`]): a pure cache, not saved in
/// snapshots, never compared.
#[derive(Debug, Clone, Default)]
struct FitScratch(window_fit::FitBuffers);

impl PartialEq for FitScratch {
    fn eq(&self, _other: &Self) -> bool {
        true
    }
}

impl PaperIdentifier {
    /// An identifier for samples every `dt` \[s\], starting from `init` with model state
    /// `h0` \[µm\]; `init` must lie in the admissible region ([`Params::check_admissible`];
    /// refused otherwise), which step 5 keeps to.
    pub fn new(dt: f64, init: Params, h0: f64, config: PaperConfig) -> Result<Self> {
        positive_dt(dt)?;
        init.check_admissible()?;
        config.validate()?;
        finite_sample("h0", h0)?;
        Ok(PaperIdentifier {
            config,
            dt,
            init,
            h0,
            params: init,
            h_model: h0,
            raw: Ring::with_capacity(2 * config.max_half_width + 1),
            next: 0,
            entered: 0,
            window: Ring::with_capacity(config.window_len),
            sums: WindowSums::new(config.window_len),
            rls: LineRls { theta: Vector2::new(init.kv, init.x0), p: Matrix2::zeros(), active: false },
            status: PaperStatus::default(),
            touched: TOUCH_ALL,
            cache: SubFitCache::default(),
            // Sized here where the output gate is on, so that no push allocates.
            scratch: if config.output_gate == f64::INFINITY {
                Scratch::default()
            } else {
                Scratch { u: Vec::with_capacity(config.window_len), x: Vec::with_capacity(config.window_len) }
            },
            u_seen: (f64::INFINITY, f64::NEG_INFINITY),
            // Sized here where the stroke bound is on, so that no push allocates.
            spans: {
                let len = if config.min_stroke_frac > 0.0 { config.window_len } else { 0 };
                [SlidingRange::new(len), SlidingRange::new(len)]
            },
            since_fit: 0,
            noise_floor2: f64::INFINITY,
            fit_carry: None,
            // Made here where the window fit runs, so that no push allocates.
            fit_buffers: FitScratch(if config.fit_iterations > 0 {
                window_fit::FitBuffers::new(config.window_len, init, dt)
            } else {
                window_fit::FitBuffers::default()
            }),
        })
    }

    /// The tuning in use.
    pub fn config(&self) -> &PaperConfig {
        &self.config
    }

    /// kv, x0 as the RLS recursion holds them and as an exact least-squares fit of
    /// the window gives them (for cross-checks); `None` while step 1 is inactive.
    pub fn line_fit_check(&self) -> Option<([f64; 2], [f64; 2])> {
        let exact = LineRls::from_sums(self.sums.get())?;
        self.rls.active.then(|| ([self.rls.theta[0], self.rls.theta[1]], [exact.theta[0], exact.theta[1]]))
    }

    /// The window sums as kept and as recomputed from the stored points: the largest
    /// relative difference (for drift checks; O(N)).
    pub fn sums_drift(&self) -> f64 {
        let mut exact = [0.0; NSUMS];
        for p in self.window.iter() {
            for (e, c) in exact.iter_mut().zip(p.contribution()) {
                *e += c;
            }
        }
        let kept = self.sums.get();
        exact.iter().zip(kept).map(|(e, k)| if *e == 0.0 { k.abs() } else { ((k - e) / e).abs() }).fold(0.0, f64::max)
    }

    /// Half-width m of the derivative stencil from the window (see
    /// [`PaperConfig::derivative_phase`]); the largest until the window is full (its
    /// statistics do not tell the input's frequency yet, and the points of a small m,
    /// ten times noisier, would weigh as much as the rest in the first full window's
    /// fits) and where the rule gives none (no motion).
    fn half_width(&self) -> usize {
        let (lo, hi) = (PaperConfig::MIN_HALF_WIDTH, self.config.max_half_width);
        let s = self.sums.get();
        let count = s[CNT];
        if !self.window.is_full() {
            return hi;
        }
        let var_u = s[SUU] / count - math::powi(s[SU] / count, 2);
        let omega = math::sqrt(s[SDD] / count) / math::sqrt(var_u.max(0.0));
        let m = math::round(self.config.derivative_phase / (omega * self.dt));
        if m.is_finite() && m < hi as f64 {
            (m.max(0.0) as usize).max(lo)
        } else {
            hi
        }
    }

    /// The window's estimate of the variance of the noise of x \[µm²\] (0 while empty).
    fn x_noise2(&self) -> f64 {
        let s = self.sums.get();
        if s[CNT] > 0.0 {
            (s[SEE] / s[CNT]).max(0.0)
        } else {
            0.0
        }
    }

    /// Builds the window point of raw sample `c` (its position in `self.raw`) with the
    /// derivative stencil of half-width `m` (`m` samples on each side are held),
    /// classified with the current estimates.
    fn complete(&self, c: usize, m: usize) -> Point {
        let p = &self.params;
        let raw = |i: usize| self.raw.get(i).copied().unwrap_or_default();
        let mid = raw(c);
        let (mut su, mut sx, mut qx0, mut qx2) = (0.0, 0.0, 0.0, 0.0);
        for k in 1..=m {
            let (after, before) = (raw(c + k), raw(c - k));
            let kf = k as f64;
            su += kf * (after.u - before.u);
            sx += kf * (after.x - before.x);
            qx0 += after.x + before.x;
            qx2 += kf * kf * (after.x + before.x);
        }
        let (s2, c0, den) = stencil(m);
        let udot = su / (s2 * self.dt);
        let xdot = sx / (s2 * self.dt);
        // Residual of the local quadratic at the centre: variance σ²·(1 − w₀) for
        // white noise of variance σ² (the weights' squares sum to w₀).
        let smooth = (c0 * (qx0 + mid.x) - 15.0 * qx2) / den;
        let w0 = c0 / den;
        let noise2 = math::powi(mid.x - smooth, 2) / (1.0 - w0);
        let y = match self.config.decomposition {
            Decomposition::Line => mid.x,
            Decomposition::Model => mid.x - mid.h_model,
        };
        let mut point = Point { u: mid.u, x: mid.x, y, udot, a: 0.0, b: 0.0, noise2, class: Class::Unused };

        // Points that enter before the window is full stay unclassified (they serve
        // step 1 and the window's statistics only): their stencils were not yet set by
        // the input's frequency (the first samples of a record have a short one, the
        // rest the largest), and a mix of the two biases the first fits of steps 2–4.
        if !self.window.is_full() {
            return point;
        }
        let s = self.sums.get();
        let count = s[CNT];
        let mean_x = s[SX] / count;
        let std_x = math::sqrt((s[SXX] / count - mean_x * mean_x).max(0.0));
        let rms_rate = math::sqrt(s[SDD] / count);
        let h_tol = self.config.h_zero_frac * ln_saturation(&self.init).map_or(std_x, math::exp);
        if udot.abs() <= self.config.rate_frac * rms_rate || udot == 0.0 || h_tol == 0.0 {
            return point;
        }
        let h = mid.x - p.kv * mid.u - p.x0;
        let hdot = xdot - p.kv * udot;
        // Noise of ẋ at this point: σ/(√S·Δt) for its stencil.
        let xdot_noise = math::sqrt(self.x_noise2() / (s2 * self.dt * self.dt));
        if udot > 0.0 && h.abs() < h_tol {
            // Step 2 regresses ẋ: a point whose ẋ is within `noise_gate` noise
            // deviations of 0 (the input's turning points) carries no rate.
            if xdot.abs() < self.config.noise_gate * xdot_noise {
                return point;
            }
            // ẋ less the small |h|^n terms of eq. (5) at this h (current β, γ, n),
            // so that ẋ = (A + kv)·u̇ + δ·u holds at the point, not only at h = 0.
            let hn = if h == 0.0 { 0.0 } else { math::powf(h.abs(), p.n) };
            point.class = Class::Crossing;
            point.a = xdot + (p.beta * udot.abs() * crate::model::sgn(h) + p.gamma * udot) * hn;
        } else if h > h_tol {
            let r = if udot > 0.0 { (hdot - p.delta * mid.u) / udot } else { (hdot + p.delta * mid.u) / udot };
            let arg = p.a - r;
            // Noise of r = (ḣ ∓ δu)/u̇ is that of ẋ over |u̇|.
            let resolved = arg.abs() * udot.abs() >= self.config.noise_gate * xdot_noise;
            if arg.is_finite() && arg != 0.0 && arg.abs() >= self.config.min_arg_frac * p.a.abs() && resolved {
                let positive = arg > 0.0;
                point.a = math::ln(h);
                point.b = math::ln(arg.abs());
                point.class = if udot > 0.0 { Class::Loading { positive } } else { Class::Unloading { positive } };
            }
        }
        point
    }

    /// Slides the stroke bound's spans of u to window point number `seq` (from 0 since
    /// construction or reset), the point `q`: a point where u moves enters the span of
    /// its branch (rising where u̇ > 0, falling where u̇ < 0).
    fn slide_spans(&mut self, seq: u64, q: &Point) {
        let branch = (q.udot != 0.0).then_some((q.udot < 0.0) as usize);
        for (b, span) in self.spans.iter_mut().enumerate() {
            span.slide(seq, (branch == Some(b)).then_some(q.u));
        }
    }

    /// The window fit (module `window_fit`, [`PaperConfig::fit_every`]), when due: once the
    /// window is full, each time `fit_every`·N points have entered since its last run.
    /// Where it is taken, the model's h follows it: the fit's h at the window's newest
    /// point, carried over the samples not yet in the window with the new estimates.
    fn window_fit(&mut self) {
        let cfg = self.config;
        if cfg.fit_iterations == 0 {
            self.status.window_fit = StepStatus::held(Reason::None, 0);
            return;
        }
        if !self.window.is_full() {
            self.status.window_fit = StepStatus::held(Reason::WindowFilling, count_u32(self.window.len() as f64));
            return;
        }
        self.noise_floor2 = self.noise_floor2.min(self.x_noise2());
        let every = math::ceil(cfg.fit_every * cfg.window_len as f64).max(1.0);
        if (self.since_fit as f64) < every {
            return;
        }
        self.since_fit = 0;
        let noise2 = self.noise_floor2;
        let run = window_fit::Run {
            cfg: &cfg,
            init: &self.init,
            dt: self.dt,
            held: self.params,
            carried: self.fit_carry,
            noise2,
        };
        let out = window_fit::run(&run, &self.window, &mut self.fit_buffers.0);
        self.status.window_fit = out.status;
        self.fit_carry = out.carry;
        let Some((p, h_end)) = out.taken else {
            return;
        };
        self.params = p;
        // The window's newest point is the raw sample `next − 1`; the raw samples after
        // it wait for their stencils.
        let first = self.status.samples - self.raw.len() as u64;
        let mut h = h_end;
        let from = (self.next.saturating_sub(first) as usize).max(1);
        for i in from..self.raw.len() {
            let Some(before) = self.raw.get(i - 1).map(|r| r.u) else {
                break;
            };
            let Some(now) = self.raw.get_mut(i) else {
                break;
            };
            h = advance_h(&p, h, before, now.u, self.dt);
            now.h_model = h;
        }
        self.h_model = h;
    }

    /// Steps 1–5 from the sums; returns the new estimates and what ran.
    fn refit(&mut self) -> (Params, PaperStatus) {
        let cfg = self.config;
        let s = self.sums.get();
        let mut p = self.params;
        let mut status = self.status;
        let count = s[CNT];
        // The output gate (`output_gate`): each step's update against the estimates the
        // steps before it left, on the window's own output error.
        let mut gate = Gate {
            on: cfg.output_gate != f64::INFINITY,
            filled: false,
            held_sse: None,
            per_unknown: cfg.output_gate * self.x_noise2(),
        };

        // A window whose rising or falling points span too little of the stroke holds
        // every step (`min_stroke_frac`).
        if self.window.is_full() && cfg.min_stroke_frac > 0.0 {
            let spans = self.spans.each_ref().map(SlidingRange::range);
            // (An input that has never moved is step 1's to report: no excitation.)
            let stroke = self.u_seen.1 - self.u_seen.0;
            if stroke > 0.0 && !spans.iter().all(|&(lo, hi)| hi - lo >= cfg.min_stroke_frac * stroke) {
                let narrow = StepStatus::held(Reason::NoSpread, count_u32(count));
                let none = StepStatus::held(Reason::NoSpread, 0);
                (status.line_fit, status.rate_fit, status.shape_fit, status.return_fit, status.split_fit) =
                    (narrow, none, none, none, none);
                return (p, status);
            }
        }

        // Step 1.
        let var_u = s[SUU] / count - math::powi(s[SU] / count, 2);
        let excited = count >= 2.0 && var_u > cfg.min_u_std_v * cfg.min_u_std_v;
        status.line_fit = StepStatus::held(Reason::WindowFilling, count_u32(count));
        if !self.window.is_full() {
            self.rls.active = false;
        } else if !excited {
            self.rls.active = false;
            status.line_fit.reason = Reason::NoExcitation;
        } else {
            if !self.rls.active || status.refreshed {
                if let Some(fresh) = LineRls::from_sums(s) {
                    self.rls = fresh;
                }
            }
            // The window must resolve kv: |kv| at least `min_line_t` standard errors
            // (a short window where u barely moves, e.g. at a turning point, does not).
            let (kv, x0) = (self.rls.theta[0], self.rls.theta[1]);
            let rss = (s[SYY] - kv * s[SUY] - x0 * s[SY]).max(0.0);
            let se_kv = if count > 2.0 { math::sqrt(rss / (count - 2.0) / (count * var_u)) } else { f64::INFINITY };
            if self.rls.active && kv.abs() >= cfg.min_line_t * se_kv {
                let candidate = Params { kv, x0, ..p };
                if gate.accepts(&self.window, &mut self.scratch, self.dt, &p, &candidate, 2.0) {
                    p = candidate;
                    let noise = math::sqrt(rss / (count - 2.0));
                    status.line_fit =
                        StepStatus { fit: SubFit::Ran, reason: Reason::None, points: count_u32(count), noise };
                } else {
                    status.line_fit.reason = Reason::WorseOutput;
                }
            } else {
                status.line_fit.reason = Reason::Noise;
            }
        }

        // Steps 2–5 wait, as step 1 does, for the window's N points: the paper starts
        // from the batch fit of the first N samples (eq. 7), and a sub-fit on the first
        // few points of a record fits noise (they sit at the input's turning point, where
        // u̇ is below the noise of the derivatives) and its estimate feeds every later one.
        if !self.window.is_full() {
            let filling = StepStatus::held(Reason::WindowFilling, 0);
            (status.rate_fit, status.shape_fit, status.return_fit, status.split_fit) =
                (filling, filling, filling, filling);
            return (p, status);
        }

        // Steps 2–4, each recomputed only when its inputs changed.
        let touched = core::mem::take(&mut self.touched);
        if touched & TOUCH_CROSSING != 0 || self.cache.rate.is_some_and(|r| r.delta_in != p.delta) {
            self.cache.rate = None;
        }
        let span = (2 * self.half_width() + 1) as f64;
        if self.cache.rate.is_some_and(|r| r.span != span) {
            self.cache.rate = None;
        }
        let rate = *self.cache.rate.get_or_insert_with(|| rate_fit(&cfg, s, p.delta, span));
        status.rate_fit = rate.status;
        if rate.status.fit != SubFit::Held {
            let candidate = Params { a: rate.a_plus_kv - p.kv, delta: rate.delta_out, ..p };
            let unknowns = if rate.status.fit == SubFit::Ran { 2.0 } else { 1.0 };
            if gate.accepts(&self.window, &mut self.scratch, self.dt, &p, &candidate, unknowns) {
                p = candidate;
            } else {
                status.rate_fit = StepStatus::held(Reason::WorseOutput, rate.status.points);
            }
        }

        if touched & TOUCH_LOADING != 0 {
            self.cache.shape = None;
        }
        let shape = *self.cache.shape.get_or_insert_with(|| shape_fit(&cfg, s));
        status.shape_fit = shape.status;
        let shape_ran = shape.status.fit == SubFit::Ran;
        let (n, sum_bg) = if shape_ran { (shape.n, shape.sum_bg) } else { (p.n, p.beta + p.gamma) };

        if touched & TOUCH_UNLOADING != 0 || self.cache.ret.is_some_and(|r| r.n_in != n) {
            self.cache.ret = None;
        }
        let ret = *self.cache.ret.get_or_insert_with(|| return_fit(&cfg, s, n));
        status.return_fit = ret.status;
        let ret_ran = ret.status.fit == SubFit::Ran;
        let diff_gb = if ret_ran { ret.diff_gb } else { p.gamma - p.beta };

        // Step 5, kept only inside the region where h stays bounded for every
        // input (β + γ > 0 and β − γ > 0) and where the hysteresis terms stay
        // physically bounded (`max_hysteresis_gain`); otherwise β, γ and n are held.
        let (beta, gamma) = (0.5 * (sum_bg - diff_gb), 0.5 * (sum_bg + diff_gb));
        if !(shape_ran || ret_ran) {
            status.split_fit = StepStatus::held(Reason::Upstream, 0);
        } else if beta + gamma > 0.0 && beta - gamma > 0.0 && hysteresis_bounded(&cfg, &self.init, beta, gamma, n) {
            let candidate = Params { beta, gamma, n, ..p };
            if gate.accepts(&self.window, &mut self.scratch, self.dt, &p, &candidate, 3.0) {
                p = candidate;
                status.split_fit = StepStatus { fit: SubFit::Ran, ..StepStatus::default() };
            } else {
                status.split_fit = StepStatus::held(Reason::WorseOutput, 0);
            }
        } else {
            status.split_fit = StepStatus::held(Reason::OutOfBounds, 0);
        }
        // Whatever the steps gave must stay in the admissible region (a δ from step 2
        // beside β ± γ = 0 would not be dissipated): else the estimates are held.
        if p.check_admissible().is_err() {
            status.split_fit = StepStatus::held(Reason::OutOfBounds, 0);
            return (self.params, status);
        }
        (p, status)
    }
}

impl OnlineIdentifier for PaperIdentifier {
    type Status = PaperStatus;

    fn push(&mut self, u: f64, x: f64) -> Result<f64> {
        finite_sample("u", u)?;
        finite_sample("x", x)?;

        self.u_seen = (self.u_seen.0.min(u), self.u_seen.1.max(u));
        // Predict with the estimates from before this sample.
        if let Some(prev) = self.raw.last() {
            self.h_model = advance_h(&self.params, self.h_model, prev.u, u, self.dt);
        }
        let prediction = output(&self.params, u, self.h_model);
        let newest = self.status.samples;
        self.raw.push(Raw { u, x, h_model: self.h_model });

        let mut status = self.status;
        status.samples += 1;
        status.refreshed = false;
        status.half_width = 0;
        // Complete every sample whose stencil of half-width m is now held (none while
        // m grows, several at once when it shrinks; each sample exactly once, in order).
        let m = self.half_width();
        let first = status.samples - self.raw.len() as u64;
        while self.next + m as u64 <= newest {
            let j = self.next;
            self.next += 1;
            // Only the first samples of a record lack m samples before them.
            let mj = m.min(j.saturating_sub(first) as usize);
            if j < first || mj < PaperConfig::MIN_HALF_WIDTH {
                continue;
            }
            let point = self.complete((j - first) as usize, mj);
            let leaving = self.window.push(point);
            self.slide_spans(self.entered, &point);
            self.entered += 1;
            status.half_width = m as u32;
            self.since_fit += 1;
            if self.sums.slide(&point.contribution(), leaving.map(|l| l.contribution()).as_ref()) {
                status.refreshed = true;
                self.touched = TOUCH_ALL;
            }
            self.touched |= point.class.touch_bit() | leaving.map_or(0, |l| l.class.touch_bit());
            if self.rls.active {
                self.rls.rank_one(point.u, point.y, 1.0);
                if let Some(old) = leaving {
                    self.rls.rank_one(old.u, old.y, -1.0);
                }
            }
        }
        status.window_full = self.window.is_full();
        let (s2, _, _) = stencil(m);
        status.x_noise_um = math::sqrt(self.x_noise2());
        status.xdot_noise_um_s = status.x_noise_um / (math::sqrt(s2) * self.dt);
        self.status = status;
        let (params, status) = self.refit();
        self.params = params;
        self.status = status;
        self.window_fit();
        Ok(prediction)
    }

    fn params(&self) -> Params {
        self.params
    }

    fn h(&self) -> f64 {
        self.h_model
    }

    fn forecast_into(&self, u: &[f64], out: &mut [f64]) -> Result<()> {
        super::check_forecast(u, out)?;
        let u_prev = self.raw.last().map(|r| r.u);
        crate::model::simulate_into(&self.params, u, self.dt, self.h_model, u_prev, out).map(|_| ())
    }

    fn status(&self) -> PaperStatus {
        self.status
    }

    fn reset(&mut self) {
        self.params = self.init;
        self.h_model = self.h0;
        self.raw.clear();
        self.next = 0;
        self.entered = 0;
        self.window.clear();
        self.sums.clear();
        self.rls = LineRls { theta: Vector2::new(self.init.kv, self.init.x0), p: Matrix2::zeros(), active: false };
        self.status = PaperStatus::default();
        self.touched = TOUCH_ALL;
        self.cache = SubFitCache::default();
        self.u_seen = (f64::INFINITY, f64::NEG_INFINITY);
        self.spans.iter_mut().for_each(SlidingRange::clear);
        self.since_fit = 0;
        self.noise_floor2 = f64::INFINITY;
        self.fit_carry = None;
    }
}
