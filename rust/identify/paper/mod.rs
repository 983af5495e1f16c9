//! The paper's online method (Zhu, Bian & Rui 2014, section 3), made robust.
//!
//! Names follow the paper: N is `window_len`; A, β, γ, n, δ are the model's.
//!
//! Per sample k:
//! 1. **Predict** x̂ₖ = kv·uₖ + x0 + hₖ with the estimates from before the sample, h
//!    integrated by the model itself ([`crate::model::advance_h`]).
//! 2. **Window.** Sample k−2 is completed (five-point central differences u̇, ẋ
//!    need samples up to k) and enters the window of the newest N samples; the
//!    oldest leaves.
//! 3. **Step 1, kv and x0** (eqs. 6–7): limited-memory recursive least squares of
//!    y on [u, 1]: a rank-one update for the entering sample and a rank-one downdate
//!    (Sherman–Morrison) for the leaving one, started from the batch fit of the first
//!    full window and re-synchronised with the exact window sums every N samples.
//!    With [`Decomposition::Line`] (the paper, literal) y = x: the line through the
//!    loop. With [`Decomposition::Model`] (default) y = x − h_model: the line that the
//!    model's own h leaves, which is the model's kv rather than the loop's centre line
//!    (the two differ when A ≠ 0: about 0.16 vs 0.19 µm/V with the paper's values).
//!    kv and x0 are taken only while the window resolves kv (`min_line_t`).
//! 4. **Steps 2–5** from running sums of the points in the window (O(1) per sample):
//!    each sample is classified once, when it enters, with the estimates of that
//!    moment; h = x − kv·u − x0 there.
//!    - step 2 (eqs. 8–9): u̇ > 0 and |h| < `h_zero_frac`·std(x): least squares of ẋ
//!      on [u̇, u] gives A + kv and δ (ẋ is first corrected by the small
//!      |h|^n terms of eq. (5) at the point's h, with the current β, γ, n). If the two columns are nearly collinear (one
//!      frequency puts every such point at the same (u, u̇)), only A + kv is fitted
//!      and δ is kept. So is δ where δ·u would outweigh the rate term on the
//!      points (`max_delta_ratio`).
//!    - step 3 (eqs. 10–12): u̇ > 0 and h above the tolerance: r = (ḣ − δu)/u̇,
//!      ln|A − r| = ln|β+γ| + n·ln h. The sign of A − r is carried: points of each
//!      sign are summed apart and the larger group decides the sign of β + γ.
//!    - step 4 (eqs. 13–14): u̇ < 0, h above the tolerance: r = (ḣ + δu)/u̇,
//!      ln|γ−β| = mean(ln|A − r| − n·ln h), sign carried as in step 3.
//!    - step 5: β, γ from β+γ and γ−β, accepted only where h stays bounded for
//!      every input (β + γ > 0 and β − γ > 0, as in the paper's Table 2) and the
//!      hysteresis terms stay physically bounded: (|β|+|γ|)·hₛⁿ at most
//!      `max_hysteresis_gain`·|A₀| at the starting model's saturation amplitude hₛ
//!      (without it, long noisy records drive |β|, |γ| to 10³–10⁸ with β ± γ
//!      still > 0); otherwise β, γ and n are held.
//!
//!    Steps 3–4 leave out points whose |A − r| is below `min_arg_frac`·|A| (a
//!    small difference of nearly equal numbers: its logarithm is mostly error) or
//!    below `noise_gate` standard deviations of the noise of r.
//!    Points with |u̇| below `rate_frac`·rms(u̇) are left out of steps 2–4 (the
//!    ratios divide by u̇, and finite differences of noisy x are unreliable there).
//!    A sub-fit with too few points or too little spread keeps its previous estimate.

use nalgebra::{Matrix2, Vector2};

mod config;
mod snapshot;
mod status;
#[cfg(test)]
mod tests;
pub mod window;

use super::OnlineIdentifier;
use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::math;
use crate::model::{advance_h, output};
use crate::params::Params;
pub use config::{Decomposition, PaperConfig};
pub use status::{PaperStatus, SubFit};
use window::{Ring, WindowSums};

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
    /// Five-point minus three-point estimate of ẋ \[µm/s\]: mostly noise (for the
    /// noise estimate of the gate of steps 3–4).
    dx_diff: f64,
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
const U_POS: usize = 28; // step 4 (+): count, Σz, Σw
const U_NEG: usize = 31; // step 4 (−)
const SEE: usize = 34; // Σ (ẋ₅ − ẋ₃)²
const NSUMS: usize = 35;

/// Raw samples kept for the derivative stencil besides the newest one.
const RAW_HISTORY: usize = 4;

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
        c[SEE] = self.dx_diff * self.dx_diff;
        match self.class {
            Class::Unused => {}
            Class::Crossing => {
                let (d, u, xd) = (self.udot, self.u, self.a);
                c[C_CNT..C_CNT + 7].copy_from_slice(&[1.0, d * d, d * u, u * u, d * xd, u * xd, xd * xd]);
            }
            Class::Loading { positive } => {
                let at = if positive { L_POS } else { L_NEG };
                let (z, w) = (self.a, self.b);
                c[at..at + 6].copy_from_slice(&[1.0, z, z * z, w, z * w, w * w]);
            }
            Class::Unloading { positive } => {
                let at = if positive { U_POS } else { U_NEG };
                c[at..at + 3].copy_from_slice(&[1.0, self.a, self.b]);
            }
        }
        c
    }
}

/// A raw sample waiting for its successors (derivative stencil).
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// Result of step 2 for given sums and previous δ.
#[derive(Debug, Clone, Copy, PartialEq)]
struct RateFit {
    delta_in: f64,
    a_plus_kv: f64,
    delta_out: f64,
    status: SubFit,
}

/// Result of step 3 for given sums.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ShapeFit {
    n: f64,
    sum_bg: f64,
    status: SubFit,
}

/// Result of step 4 for given sums and n.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ReturnFit {
    n_in: f64,
    diff_gb: f64,
    status: SubFit,
}

/// The sub-fit results of the last refit, reused while their inputs are unchanged
/// (most samples add and remove points of at most one class). A pure cache: it is
/// not saved in snapshots, and dropping it changes no result.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct SubFitCache {
    rate: Option<RateFit>,
    shape: Option<ShapeFit>,
    ret: Option<ReturnFit>,
}

/// Step 2 (eqs. 8–9): A + kv and δ from the crossing points.
fn rate_fit(cfg: &PaperConfig, s: &[f64; NSUMS], delta: f64) -> RateFit {
    let held = RateFit { delta_in: delta, a_plus_kv: 0.0, delta_out: delta, status: SubFit::Held };
    let c = &s[C_CNT..C_CNT + 7];
    if !(c[0] >= cfg.min_points as f64 && c[1] > 0.0) {
        return held;
    }
    let det = c[1] * c[3] - c[2] * c[2];
    let well_posed = c[3] > 0.0 && det > cfg.rank_tol * c[1] * c[3];
    let (full_a_plus_kv, full_delta) =
        if well_posed { ((c[4] * c[3] - c[2] * c[5]) / det, (c[1] * c[5] - c[2] * c[4]) / det) } else { (0.0, 0.0) };
    // δ is kept only where the data resolve it: |δ| at least `min_delta_t`
    // standard errors, from the residual of the two-column fit; and only while
    // δ·u does not outweigh the rate term on the points (`max_delta_ratio`).
    let dof = c[0] - 2.0;
    let rss = (c[6] - full_a_plus_kv * c[4] - full_delta * c[5]).max(0.0);
    let se_delta = if dof > 0.0 { math::sqrt(rss / dof * c[1] / det) } else { f64::INFINITY };
    // The rate term is measured by the one-column fit (well conditioned where u̇ and
    // u are nearly collinear, when the two-column fit can trade one for the other).
    let reduced = (c[4] - delta * c[2]) / c[1];
    let bounded = full_delta.abs() * math::sqrt(c[3]) <= cfg.max_delta_ratio * reduced.abs() * math::sqrt(c[1]);
    let fit = if well_posed && full_delta.is_finite() && full_delta.abs() >= cfg.min_delta_t * se_delta && bounded {
        RateFit { delta_in: delta, a_plus_kv: full_a_plus_kv, delta_out: full_delta, status: SubFit::Ran }
    } else {
        RateFit { delta_in: delta, a_plus_kv: reduced, delta_out: delta, status: SubFit::Reduced }
    };
    if fit.a_plus_kv.is_finite() {
        fit
    } else {
        held
    }
}

/// Step 3 (eqs. 10–12): n and β + γ from the loading points of the larger sign group.
fn shape_fit(cfg: &PaperConfig, s: &[f64; NSUMS]) -> ShapeFit {
    let held = ShapeFit { n: 0.0, sum_bg: 0.0, status: SubFit::Held };
    let (at, sign) = if s[L_POS] >= s[L_NEG] { (L_POS, 1.0) } else { (L_NEG, -1.0) };
    let m = s[at];
    if m < cfg.min_points as f64 {
        return held;
    }
    let mean_z = s[at + 1] / m;
    let var_z = s[at + 2] / m - mean_z * mean_z;
    let mean_w = s[at + 3] / m;
    let cov = s[at + 4] / m - mean_z * mean_w;
    let var_w = s[at + 5] / m - mean_w * mean_w;
    let r2 = if var_z > 0.0 && var_w > 0.0 { cov * cov / (var_z * var_w) } else { 0.0 };
    if !(var_z > cfg.min_log_spread * cfg.min_log_spread && r2 >= cfg.min_r2) {
        return held;
    }
    let n = cov / var_z;
    let log_mag = (mean_w - n * mean_z).clamp(-700.0, 700.0);
    if n >= cfg.n_bounds.0 && n <= cfg.n_bounds.1 && log_mag.is_finite() {
        ShapeFit { n, sum_bg: sign * math::exp(log_mag), status: SubFit::Ran }
    } else {
        held
    }
}

/// Step 4 (eqs. 13–14): γ − β from the unloading points of the larger sign group.
fn return_fit(cfg: &PaperConfig, s: &[f64; NSUMS], n: f64) -> ReturnFit {
    let (at, sign) = if s[U_POS] >= s[U_NEG] { (U_POS, 1.0) } else { (U_NEG, -1.0) };
    let m = s[at];
    if m >= cfg.min_points as f64 {
        let log_mag = ((s[at + 2] - n * s[at + 1]) / m).clamp(-700.0, 700.0);
        if log_mag.is_finite() {
            return ReturnFit { n_in: n, diff_gb: sign * math::exp(log_mag), status: SubFit::Ran };
        }
    }
    ReturnFit { n_in: n, diff_gb: 0.0, status: SubFit::Held }
}

/// Step 5's physical bound ([`PaperConfig::max_hysteresis_gain`]): (|β|+|γ|)·hₛⁿ ≤
/// K·|A₀| with hₛ = (|A₀|/(|β₀|+|γ₀|))^(1/n₀) the starting model's saturation
/// amplitude, compared in logarithms.
fn hysteresis_bounded(cfg: &PaperConfig, init: &Params, beta: f64, gamma: f64, n: f64) -> bool {
    let (a0, s0) = (init.a.abs(), init.beta.abs() + init.gamma.abs());
    if cfg.max_hysteresis_gain == f64::INFINITY || a0 == 0.0 || s0 == 0.0 {
        return true;
    }
    let ln_hs = (math::ln(a0) - math::ln(s0)) / init.n;
    math::ln(beta.abs() + gamma.abs()) + n * ln_hs <= math::ln(cfg.max_hysteresis_gain * a0)
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
    /// The latest raw samples before the newest, oldest first.
    raw: [Option<Raw>; RAW_HISTORY],
    window: Ring<Point>,
    sums: WindowSums<NSUMS>,
    rls: LineRls,
    status: PaperStatus,
    /// Point classes that entered or left since the last refit ([`TOUCH_ALL`] after a refresh).
    touched: u8,
    cache: SubFitCache,
}

impl PaperIdentifier {
    /// An identifier for samples every `dt` \[s\], starting from `init` with model state `h0` \[µm\].
    pub fn new(dt: f64, init: Params, h0: f64, config: PaperConfig) -> Result<Self> {
        positive_dt(dt)?;
        init.validate()?;
        config.validate()?;
        finite_sample("h0", h0)?;
        Ok(PaperIdentifier {
            config,
            dt,
            init,
            h0,
            params: init,
            h_model: h0,
            raw: [None; RAW_HISTORY],
            window: Ring::with_capacity(config.window_len),
            sums: WindowSums::new(config.window_len),
            rls: LineRls { theta: Vector2::new(init.kv, init.x0), p: Matrix2::zeros(), active: false },
            status: PaperStatus::default(),
            touched: TOUCH_ALL,
            cache: SubFitCache::default(),
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

    /// Builds the window point for the middle sample, classified with the current estimates.
    /// `s` holds samples k−2, k−1, k, k+1, k+2; the point is sample k. Derivatives
    /// by the five-point central difference (error O(Δt⁴): about 1e-5 relative at
    /// 50 samples per period, where the three-point one errs by 3e-3).
    fn complete(&self, s: [Raw; 5]) -> Point {
        let p = &self.params;
        let mid = s[2];
        let twelve_dt = 12.0 * self.dt;
        let udot = (s[0].u - 8.0 * s[1].u + 8.0 * s[3].u - s[4].u) / twelve_dt;
        let xdot = (s[0].x - 8.0 * s[1].x + 8.0 * s[3].x - s[4].x) / twelve_dt;
        let dx_diff = xdot - (s[3].x - s[1].x) / (2.0 * self.dt);
        let y = match self.config.decomposition {
            Decomposition::Line => mid.x,
            Decomposition::Model => mid.x - mid.h_model,
        };
        let mut point = Point { u: mid.u, x: mid.x, y, udot, a: 0.0, b: 0.0, dx_diff, class: Class::Unused };

        let s = self.sums.get();
        let count = s[CNT];
        if count < 2.0 {
            return point;
        }
        let mean_x = s[SX] / count;
        let std_x = math::sqrt((s[SXX] / count - mean_x * mean_x).max(0.0));
        let rms_rate = math::sqrt(s[SDD] / count);
        let h_tol = self.config.h_zero_frac * std_x;
        if udot.abs() <= self.config.rate_frac * rms_rate || udot == 0.0 || h_tol == 0.0 {
            return point;
        }
        let h = mid.x - p.kv * mid.u - p.x0;
        let hdot = xdot - p.kv * udot;
        if udot > 0.0 && h.abs() < h_tol {
            // ẋ less the small |h|^n terms of eq. (5) at this h (current β, γ, n),
            // so that ẋ = (A + kv)·u̇ + δ·u holds at the point, not only at h = 0.
            let hn = if h == 0.0 { 0.0 } else { math::powf(h.abs(), p.n) };
            point.class = Class::Crossing;
            point.a = xdot + (p.beta * udot.abs() * crate::model::sgn(h) + p.gamma * udot) * hn;
        } else if h > h_tol {
            let r = if udot > 0.0 { (hdot - p.delta * mid.u) / udot } else { (hdot + p.delta * mid.u) / udot };
            let arg = p.a - r;
            // Noise of r = (ḣ ∓ δu)/u̇ is that of ẋ over |u̇|. For white noise on x,
            // var(ẋ₅) = 13·var(ẋ₅ − ẋ₃); the signal in ẋ₅ − ẋ₃ only adds to it (safe).
            let xdot_var = 13.0 * s[SEE] / count;
            let resolved = arg.abs() * udot.abs() >= self.config.noise_gate * math::sqrt(xdot_var);
            if arg.is_finite() && arg != 0.0 && arg.abs() >= self.config.min_arg_frac * p.a.abs() && resolved {
                let positive = arg > 0.0;
                point.a = math::ln(h);
                point.b = math::ln(arg.abs());
                point.class = if udot > 0.0 { Class::Loading { positive } } else { Class::Unloading { positive } };
            }
        }
        point
    }

    /// Steps 1–5 from the sums; returns the new estimates and what ran.
    fn refit(&mut self) -> (Params, PaperStatus) {
        let cfg = self.config;
        let s = self.sums.get();
        let mut p = self.params;
        let mut status = self.status;
        let count = s[CNT];

        // Step 1.
        status.line_fit = SubFit::Held;
        let var_u = s[SUU] / count - math::powi(s[SU] / count, 2);
        let excited = count >= 2.0 && var_u > cfg.min_u_std_v * cfg.min_u_std_v;
        if self.window.is_full() && excited {
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
                p.kv = kv;
                p.x0 = x0;
                status.line_fit = SubFit::Ran;
            }
        } else {
            self.rls.active = false;
        }

        // Steps 2–4, each recomputed only when its inputs changed.
        let touched = core::mem::take(&mut self.touched);
        if touched & TOUCH_CROSSING != 0 || self.cache.rate.is_some_and(|r| r.delta_in != p.delta) {
            self.cache.rate = None;
        }
        let rate = *self.cache.rate.get_or_insert_with(|| rate_fit(&cfg, s, p.delta));
        status.rate_fit = rate.status;
        if rate.status != SubFit::Held {
            p.a = rate.a_plus_kv - p.kv;
            p.delta = rate.delta_out;
        }

        if touched & TOUCH_LOADING != 0 {
            self.cache.shape = None;
        }
        let shape = *self.cache.shape.get_or_insert_with(|| shape_fit(&cfg, s));
        status.shape_fit = shape.status;
        let mut sum_bg = p.beta + p.gamma;
        if shape.status == SubFit::Ran {
            p.n = shape.n;
            sum_bg = shape.sum_bg;
        }

        if touched & TOUCH_UNLOADING != 0 || self.cache.ret.is_some_and(|r| r.n_in != p.n) {
            self.cache.ret = None;
        }
        let ret = *self.cache.ret.get_or_insert_with(|| return_fit(&cfg, s, p.n));
        status.return_fit = ret.status;
        let diff_gb = if ret.status == SubFit::Ran { ret.diff_gb } else { p.gamma - p.beta };

        // Step 5, kept only inside the region where h stays bounded for every
        // input (β + γ > 0 and β − γ > 0) and where the hysteresis terms stay
        // physically bounded (`max_hysteresis_gain`); otherwise β, γ and n are held.
        let (beta, gamma) = (0.5 * (sum_bg - diff_gb), 0.5 * (sum_bg + diff_gb));
        if beta + gamma > 0.0 && beta - gamma > 0.0 && hysteresis_bounded(&cfg, &self.init, beta, gamma, p.n) {
            p.beta = beta;
            p.gamma = gamma;
        } else {
            status.shape_fit = SubFit::Held;
            status.return_fit = SubFit::Held;
            p.n = self.params.n;
        }
        if p.validate().is_err() {
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

        // Predict with the estimates from before this sample.
        if let Some(prev) = self.raw[RAW_HISTORY - 1] {
            self.h_model = advance_h(&self.params, self.h_model, prev.u, u, self.dt);
        }
        let prediction = output(&self.params, u, self.h_model);
        let newest = Raw { u, x, h_model: self.h_model };

        let mut status = self.status;
        status.samples += 1;
        status.refreshed = false;
        if let [Some(a), Some(b), Some(c), Some(d)] = self.raw {
            let point = self.complete([a, b, c, d, newest]);
            let leaving = self.window.push(point);
            status.refreshed = self.sums.slide(&point.contribution(), leaving.map(|l| l.contribution()).as_ref());
            self.touched |= point.class.touch_bit() | leaving.map_or(0, |l| l.class.touch_bit());
            if status.refreshed {
                self.touched = TOUCH_ALL;
            }
            if self.rls.active {
                self.rls.rank_one(point.u, point.y, 1.0);
                if let Some(old) = leaving {
                    self.rls.rank_one(old.u, old.y, -1.0);
                }
            }
        }
        status.window_full = self.window.is_full();
        self.status = status;
        let (params, status) = self.refit();
        self.params = params;
        self.status = status;
        let [_, a, b, c] = self.raw;
        self.raw = [a, b, c, Some(newest)];
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
        let u_prev = self.raw[RAW_HISTORY - 1].map(|r| r.u);
        crate::model::simulate_into(&self.params, u, self.dt, self.h_model, u_prev, out).map(|_| ())
    }

    fn status(&self) -> PaperStatus {
        self.status
    }

    fn reset(&mut self) {
        self.params = self.init;
        self.h_model = self.h0;
        self.raw = [None; RAW_HISTORY];
        self.window.clear();
        self.sums.clear();
        self.rls = LineRls { theta: Vector2::new(self.init.kv, self.init.x0), p: Matrix2::zeros(), active: false };
        self.status = PaperStatus::default();
        self.touched = TOUCH_ALL;
        self.cache = SubFitCache::default();
    }
}
