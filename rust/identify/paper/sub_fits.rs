//! Steps 2–5 of the method from the window's running sums: A + kv and δ (step 2), the
//! shape β + γ and n (step 3), the return γ − β (step 4), and step 5's bound on β and γ.

use super::{PaperConfig, Reason, StepStatus, SubFit, C_CNT, L_NEG, L_POS, NSUMS, U_NEG, U_POS};
use crate::math;
use crate::params::Params;

/// Result of step 2 for given sums and previous δ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct RateFit {
    pub(super) delta_in: f64,
    pub(super) span: f64,
    pub(super) a_plus_kv: f64,
    pub(super) delta_out: f64,
    pub(super) status: StepStatus,
}

/// Result of step 3 for given sums.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ShapeFit {
    pub(super) n: f64,
    pub(super) sum_bg: f64,
    pub(super) status: StepStatus,
}

/// Result of step 4 for given sums and n.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ReturnFit {
    pub(super) n_in: f64,
    pub(super) diff_gb: f64,
    pub(super) status: StepStatus,
}

/// The sub-fit results of the last refit, reused while their inputs are unchanged
/// (most samples add and remove points of at most one class). A pure cache: it is
/// not saved in snapshots, and dropping it changes no result.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct SubFitCache {
    pub(super) rate: Option<RateFit>,
    pub(super) shape: Option<ShapeFit>,
    pub(super) ret: Option<ReturnFit>,
}

/// A point count as reported (saturating).
pub(super) fn count_u32(c: f64) -> u32 {
    if c >= u32::MAX as f64 {
        u32::MAX
    } else {
        c.max(0.0) as u32
    }
}

/// Step 2 (eqs. 8–9): A + kv and δ from the crossing points; `span` = 2m + 1, the
/// samples a derivative stencil spans (neighbouring points share their noise over it).
pub(super) fn rate_fit(cfg: &PaperConfig, s: &[f64; NSUMS], delta: f64, span: f64) -> RateFit {
    let c = &s[C_CNT..C_CNT + 7];
    let points = count_u32(c[0]);
    let held = |reason| RateFit {
        delta_in: delta,
        span,
        a_plus_kv: 0.0,
        delta_out: delta,
        status: StepStatus::held(reason, points),
    };
    if c[0] < cfg.min_points as f64 {
        return held(Reason::TooFewPoints);
    }
    if c[1] <= 0.0 {
        return held(Reason::NoSpread);
    }
    let det = c[1] * c[3] - c[2] * c[2];
    let well_posed = c[3] > 0.0 && det > cfg.rank_tol * c[1] * c[3];
    let (full_a_plus_kv, full_delta) =
        if well_posed { ((c[4] * c[3] - c[2] * c[5]) / det, (c[1] * c[5] - c[2] * c[4]) / det) } else { (0.0, 0.0) };
    // δ is kept only where the data resolve it: |δ| at least `min_delta_t`
    // standard errors, from the residual of the two-column fit; and only while
    // δ·u does not outweigh the rate term on the points (`max_delta_ratio`). The
    // derivatives of neighbouring points share their noise over a stencil of `span`
    // samples, so the points are worth about count/span independent ones: the
    // standard error is √span times that of independent points (without it, one
    // crossing of the first window at 1 Hz gives δ = 0.7, a hundred times the truth,
    // "resolved" at 3 standard errors).
    // The residual variance is floored at the derivative's own error, (θ²/10)·ẋ for a
    // sine (θ = `derivative_phase`): on noise-free records the residual is that bias
    // alone, and without the floor any δ it leaves "resolves" (δ = 0.09, twelve times
    // the truth, from the first window of the paper's noise-free 1 Hz record).
    let dof = c[0] - 2.0;
    let rss = (c[6] - full_a_plus_kv * c[4] - full_delta * c[5]).max(0.0);
    let bias2 = math::powi(math::powi(cfg.derivative_phase, 2) / 10.0, 2) * c[6] / c[0];
    let var = if dof > 0.0 { (rss / dof).max(bias2) } else { f64::INFINITY };
    let se_delta = math::sqrt(span * var * c[1] / det);
    // The rate term is measured by the one-column fit (well conditioned where u̇ and
    // u are nearly collinear, when the two-column fit can trade one for the other):
    // ẋ − δu on u̇, δ held.
    let suy = c[4] - delta * c[2];
    let reduced = suy / c[1];
    let syy = c[6] - 2.0 * delta * c[5] + delta * delta * c[3];
    let reduced_noise = math::sqrt(((syy - reduced * suy).max(0.0)) / (c[0] - 1.0).max(1.0));
    let bounded = full_delta.abs() * math::sqrt(c[3]) <= cfg.max_delta_ratio * reduced.abs() * math::sqrt(c[1]);
    let why = if !well_posed {
        Reason::NoSpread
    } else if !(full_delta.is_finite() && full_delta.abs() >= cfg.min_delta_t * se_delta) {
        Reason::Noise
    } else if !bounded {
        Reason::OutOfBounds
    } else {
        Reason::None
    };
    let fit = if why == Reason::None {
        let status = StepStatus { fit: SubFit::Ran, reason: why, points, noise: math::sqrt(rss / dof) };
        RateFit { delta_in: delta, span, a_plus_kv: full_a_plus_kv, delta_out: full_delta, status }
    } else {
        let status = StepStatus { fit: SubFit::Reduced, reason: why, points, noise: reduced_noise };
        RateFit { delta_in: delta, span, a_plus_kv: reduced, delta_out: delta, status }
    };
    if fit.a_plus_kv.is_finite() {
        fit
    } else {
        held(Reason::OutOfBounds)
    }
}

/// The larger sign group of steps 3–4 (offset of its sums, sign of A − r).
fn larger_group(s: &[f64; NSUMS], pos: usize, neg: usize) -> (usize, f64) {
    if s[pos] >= s[neg] {
        (pos, 1.0)
    } else {
        (neg, -1.0)
    }
}

/// Step 3 (eqs. 10–12): n and β + γ from the loading points of the larger sign group.
pub(super) fn shape_fit(cfg: &PaperConfig, s: &[f64; NSUMS]) -> ShapeFit {
    let (at, sign) = larger_group(s, L_POS, L_NEG);
    let m = s[at];
    let held = |reason| ShapeFit { n: 0.0, sum_bg: 0.0, status: StepStatus::held(reason, count_u32(m)) };
    if m < cfg.min_points as f64 {
        return held(Reason::TooFewPoints);
    }
    let mean_z = s[at + 1] / m;
    let var_z = s[at + 2] / m - mean_z * mean_z;
    let mean_w = s[at + 3] / m;
    let cov = s[at + 4] / m - mean_z * mean_w;
    let var_w = s[at + 5] / m - mean_w * mean_w;
    if var_z <= cfg.min_log_spread * cfg.min_log_spread {
        return held(Reason::NoSpread);
    }
    let r2 = if var_w > 0.0 { cov * cov / (var_z * var_w) } else { 0.0 };
    if r2 < cfg.min_r2 {
        return held(Reason::Noise);
    }
    let n = cov / var_z;
    let log_mag = (mean_w - n * mean_z).clamp(-700.0, 700.0);
    if !(n >= cfg.n_bounds.0 && n <= cfg.n_bounds.1 && log_mag.is_finite()) {
        return held(Reason::OutOfBounds);
    }
    let noise = math::sqrt((var_w - cov * cov / var_z).max(0.0) * m / (m - 2.0).max(1.0));
    let status = StepStatus { fit: SubFit::Ran, reason: Reason::None, points: count_u32(m), noise };
    ShapeFit { n, sum_bg: sign * math::exp(log_mag), status }
}

/// Step 4 (eqs. 13–14): γ − β from the unloading points of the larger sign group.
pub(super) fn return_fit(cfg: &PaperConfig, s: &[f64; NSUMS], n: f64) -> ReturnFit {
    let (at, sign) = larger_group(s, U_POS, U_NEG);
    let m = s[at];
    let held = |reason| ReturnFit { n_in: n, diff_gb: 0.0, status: StepStatus::held(reason, count_u32(m)) };
    if m < cfg.min_points as f64 {
        return held(Reason::TooFewPoints);
    }
    // d = ln|A − r| − n·ln h: its mean is ln|γ − β|, its scatter the noise.
    let mean_d = (s[at + 3] - n * s[at + 1]) / m;
    let mean_d2 = (s[at + 5] - 2.0 * n * s[at + 4] + n * n * s[at + 2]) / m;
    let log_mag = mean_d.clamp(-700.0, 700.0);
    if !log_mag.is_finite() {
        return held(Reason::OutOfBounds);
    }
    let noise = math::sqrt((mean_d2 - mean_d * mean_d).max(0.0) * m / (m - 1.0).max(1.0));
    let status = StepStatus { fit: SubFit::Ran, reason: Reason::None, points: count_u32(m), noise };
    ReturnFit { n_in: n, diff_gb: sign * math::exp(log_mag), status }
}

/// ln hₛ, hₛ = (|A₀|/(|β₀|+|γ₀|))^(1/n₀) the saturation amplitude of the model `init`
/// (where |h| stops growing under a monotone input); `None` when |A₀| or |β₀|+|γ₀| is 0.
pub(super) fn ln_saturation(init: &Params) -> Option<f64> {
    let (a0, s0) = (init.a.abs(), init.beta.abs() + init.gamma.abs());
    (a0 > 0.0 && s0 > 0.0).then(|| (math::ln(a0) - math::ln(s0)) / init.n)
}

/// Step 5's physical bound ([`PaperConfig::max_hysteresis_gain`]): (|β|+|γ|)·hₛⁿ ≤
/// K·|A₀| with hₛ the starting model's saturation amplitude, compared in logarithms.
pub(super) fn hysteresis_bounded(cfg: &PaperConfig, init: &Params, beta: f64, gamma: f64, n: f64) -> bool {
    match ln_saturation(init) {
        Some(ln_hs) if cfg.max_hysteresis_gain != f64::INFINITY => {
            math::ln(beta.abs() + gamma.abs()) + n * ln_hs <= math::ln(cfg.max_hysteresis_gain * init.a.abs())
        }
        _ => true,
    }
}
