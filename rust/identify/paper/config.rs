//! Tuning of the paper's identifier: every tolerance the paper leaves open.

use super::*;

/// How the linear part kv·u + x0 is separated from h in step 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Decomposition {
    /// The paper, literal: the least-squares line through the measured loop.
    Line,
    /// Default: the least-squares line through x − h, h simulated by the model.
    #[default]
    Model,
}

/// Tuning of [`PaperIdentifier`]; every tolerance the paper leaves open.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperConfig {
    /// Limited memory N \[samples\] (≥ [`PaperConfig::MIN_WINDOW`]).
    pub window_len: usize,
    /// See [`Decomposition`].
    pub decomposition: Decomposition,
    /// |h| below this fraction of the window's std(x) counts as h ≈ 0 (step 2);
    /// h above it counts as h > 0 (steps 3–4). Default 0.005.
    pub h_zero_frac: f64,
    /// Points with |u̇| below this fraction of the window's rms(u̇) are left out of
    /// steps 2–4. Default 0.2.
    pub rate_frac: f64,
    /// Fewest points for a sub-fit. Default 8.
    pub min_points: usize,
    /// Step 2 fits both A + kv and δ only when 1 − corr²(u̇, u) over its points
    /// exceeds this. Default 1e-3.
    pub rank_tol: f64,
    /// Step 3 fits n only when std(ln h) over its points exceeds this. Default 0.05.
    pub min_log_spread: f64,
    /// Steps 3–4 use a point only when |A − r| is at least this fraction of |A|:
    /// smaller values are a difference of two nearly equal numbers, dominated by
    /// the error of A and of the finite differences. Default 0.05.
    pub min_arg_frac: f64,
    /// Steps 3–4 use a point only when |A − r| is at least this many standard
    /// deviations of the noise of r (that of ẋ over |u̇|; ẋ's noise is estimated
    /// over the window from the difference of the five- and three-point
    /// derivatives). Default 3.
    pub noise_gate: f64,
    /// Step 2 updates δ only when |δ| is at least this many standard errors of
    /// its estimate (else it fits A + kv alone). Default 3.
    pub min_delta_t: f64,
    /// Step 3 fits n only when the log–log points lie on a line: squared
    /// correlation of ln h and ln|A − r| at least this. Default 0.9.
    pub min_r2: f64,
    /// Step 1 updates kv, x0 only when |kv| is at least this many standard errors
    /// of its window estimate. Default 10.
    pub min_line_t: f64,
    /// Step 1 runs only while std(u) over the window exceeds this \[V\]. Default 1e-6 V.
    pub min_u_std_v: f64,
    /// A slope outside these bounds is taken as a failed fit and n is kept. Default 0.5 to 4.
    pub n_bounds: (f64, f64),
    /// Step 5 accepts β, γ, n only while the hysteresis terms stay physically bounded:
    /// (|β|+|γ|)·hₛⁿ ≤ this × |A₀|, where hₛ = (|A₀|/(|β₀|+|γ₀|))^(1/n₀) is the
    /// saturation amplitude of the starting model (A₀, β₀, γ₀, n₀; the guard is off
    /// when |A₀| or |β₀|+|γ₀| is 0, or with `f64::INFINITY`). At the starting model's
    /// own saturation amplitude the new model's |h|ⁿ terms may be at most this many
    /// times |A₀|, i.e. its saturation amplitude may shrink at most this^(1/n)-fold
    /// (4.5-fold at n = 1.52). Without it, on long noisy records steps 3–4 fed by a
    /// local line fit (short windows) or by points near h ≈ 0 give β ± γ that pass
    /// the sign test with |β|, |γ| many orders of magnitude too large. Default 10.
    pub max_hysteresis_gain: f64,
    /// Step 2 keeps a fitted δ only while the δ·u term does not outweigh the rate
    /// term on its points: |δ|·rms(u) ≤ this × |A + kv|·rms(u̇), A + kv from the fit
    /// with δ held (else it fits A + kv alone and keeps δ, as for an unresolved δ). δ·u·sgn(u̇) is the model's small
    /// asymmetry; where the crossing points span a narrow range of u (one frequency,
    /// long windows) an unbounded δ absorbs what the model misses and grows to
    /// thousands of times its size (|δ| ≈ 28 µm/(V·s) on noise-free bench data at
    /// N = 5000), and the model's h, and with it step 1, follow. Default 1.
    pub max_delta_ratio: f64,
}

impl PaperConfig {
    /// Smallest accepted window.
    pub const MIN_WINDOW: usize = 16;
    /// Largest accepted window (the points are held in memory, 56 bytes each).
    pub const MAX_WINDOW: usize = 10_000_000;

    /// Defaults with window N = `window_len`.
    pub fn with_window(window_len: usize) -> Self {
        PaperConfig {
            window_len,
            decomposition: Decomposition::Model,
            h_zero_frac: 0.005,
            rate_frac: 0.2,
            min_points: 8,
            rank_tol: 1e-3,
            min_log_spread: 0.05,
            min_r2: 0.9,
            min_arg_frac: 0.05,
            min_line_t: 10.0,
            noise_gate: 3.0,
            min_delta_t: 3.0,
            min_u_std_v: 1e-6,
            n_bounds: (0.5, 4.0),
            max_hysteresis_gain: 4.0,
            max_delta_ratio: 1.0,
        }
    }

    /// Checks every value; the error names the offending option.
    pub fn validate(&self) -> Result<()> {
        let bad = |name, value: f64, reason| Err(Error::InvalidConfig { name, value, reason });
        if self.window_len < Self::MIN_WINDOW {
            return bad("window", self.window_len as f64, "the window must hold at least 16 samples");
        }
        if self.window_len > Self::MAX_WINDOW {
            return bad("window", self.window_len as f64, "the window may hold at most 10 000 000 samples");
        }
        if self.min_points < 2 || self.min_points > self.window_len {
            return bad("min_points", self.min_points as f64, "must be between 2 and the window length");
        }
        let fractions = [
            ("h_zero_frac", self.h_zero_frac),
            ("rate_frac", self.rate_frac),
            ("rank_tol", self.rank_tol),
            ("min_log_spread", self.min_log_spread),
            ("min_r2", self.min_r2),
            ("min_delta_t", self.min_delta_t),
            ("min_arg_frac", self.min_arg_frac),
            ("min_line_t", self.min_line_t),
            ("noise_gate", self.noise_gate),
            ("min_u_std_v", self.min_u_std_v),
        ];
        for (name, v) in fractions {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, v, "must be finite and >= 0");
            }
        }
        if self.max_delta_ratio.is_nan() || self.max_delta_ratio <= 0.0 {
            return bad("max_delta_ratio", self.max_delta_ratio, "must be > 0 (inf: no bound)");
        }
        if self.max_hysteresis_gain.is_nan() || self.max_hysteresis_gain <= 0.0 {
            return bad("max_hysteresis_gain", self.max_hysteresis_gain, "must be > 0 (inf: no bound)");
        }
        let (lo, hi) = self.n_bounds;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return bad("n_bounds", lo, "need 0 < n_min <= n_max, both finite");
        }
        Ok(())
    }
}
