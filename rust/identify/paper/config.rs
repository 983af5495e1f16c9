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
    /// |h| below this fraction of the starting model's saturation amplitude hₛ =
    /// (|A₀|/(|β₀|+|γ₀|))^(1/n₀) counts as h ≈ 0 (step 2); h above it counts as h > 0
    /// (steps 3–4) (of the window's std(x) where hₛ is undefined, |A₀| or |β₀|+|γ₀| 0).
    /// hₛ, not the window's std(x): a short window's std(x) shrinks to nanometres near
    /// the turning points, and the band to a sample or two per crossing. At the paper's
    /// 1 Hz values hₛ ≈ 1.5 µm and the band is ±0.075 µm, about 130 samples per crossing
    /// at 1 Hz and 10 kHz; the |h|ⁿ terms there are corrected with the current β, γ, n
    /// (step 2) and are at most (|β|+|γ|)·0.075ⁿ ≈ 0.8 % of |A|. Default 0.05.
    pub h_zero_frac: f64,
    /// Points with |u̇| below this fraction of the window's rms(u̇) are left out of
    /// steps 2–4: steps 3–4 divide by u̇, so near the input's turning points the noise of
    /// ẋ over a small u̇ swamps r, and step 2's rate term vanishes there. Default 0.2.
    pub rate_frac: f64,
    /// Fewest points for a sub-fit: below it a fit's scatter (and step 3's r²) says
    /// nothing, and one bad point decides it. Default 8.
    pub min_points: usize,
    /// Step 2 fits both A + kv and δ only when 1 − corr²(u̇, u) over its points
    /// exceeds this: at one frequency the crossings sit at nearly the same (u, u̇), the
    /// two columns are collinear and δ trades against A + kv (ran reduced). Default 1e-3.
    pub rank_tol: f64,
    /// Step 3 fits n only when std(ln h) over its points exceeds this: the slope n of a
    /// log–log line over a narrow range of h is set by the noise (held, no spread).
    /// Default 0.05.
    pub min_log_spread: f64,
    /// Steps 3–4 use a point only when |A − r| is at least this fraction of |A|:
    /// smaller values are a difference of two nearly equal numbers, dominated by
    /// the error of A. Default 0: with the paper's own values (β + γ)·hⁿ reaches only
    /// 2.5 % of |A| at 1 Hz, so any fraction above that empties step 3; the noise of
    /// the derivatives is gated by `noise_gate` instead.
    pub min_arg_frac: f64,
    /// Steps 3–4 use a point only when |A − r| is at least this many standard
    /// deviations of the noise of r (that of ẋ over |u̇|, ẋ's noise from the
    /// derivative's, see `derivative_phase`): a logarithm of a quantity buried in
    /// noise is mostly noise, and of the wrong sign undefined. Default 3.
    pub noise_gate: f64,
    /// The derivative estimator, which the paper leaves open: u̇ and ẋ of a window
    /// point are the Savitzky–Golay first derivative (the slope of the local
    /// least-squares line, equal to that of the local quadratic) over 2m + 1 samples
    /// centred on it, m = round(this / (ω̂·Δt)) within 2 … `max_half_width`, ω̂ =
    /// rms(u̇)/std(u) over the window (the input's angular frequency for a sine).
    /// The stencil spans ±this radians of the input's phase: for a sine the slope
    /// errs by 1 − 3(sin θ − θ cos θ)/θ³ ≈ θ²/10 (0.1 % at 0.1 rad), while white noise
    /// σ on x leaves σ/(√S·Δt) on ẋ, S = m(m+1)(2m+1)/3 (a five-point stencil, m = 2,
    /// leaves 0.32·σ/Δt: 3.2 µm/s from 1 nm at 10 kHz, against 6 nm/s at m = 160, the
    /// 1 Hz stencil). Step 3's signal, (β + γ)·hⁿ, is at most 2.5 % of A with the
    /// paper's values, so the bias must stay well below that: 0.3 rad (0.9 %) already
    /// moves n by tenths on noise-free data. A fixed m cannot serve 1 Hz and 200 Hz:
    /// what quiets the noise at one frequency biases the other. Default 0.1 rad.
    pub derivative_phase: f64,
    /// Largest derivative half-width m \[samples\]; the raw samples of 2m + 1 are held
    /// (24 bytes each), and a point enters the window m samples after it was measured.
    /// Default 500 (50 ms at 10 kHz; 1 Hz needs 160).
    pub max_half_width: usize,
    /// Step 2 updates δ only when |δ| is at least this many standard errors of
    /// its estimate (else it fits A + kv alone). Default 3.
    pub min_delta_t: f64,
    /// Step 3 fits n only when the log–log points lie on a line: squared
    /// correlation of ln h and ln|A − r| at least this; a cloud off a line has a slope
    /// that is not n (held for noise). Default 0.9.
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
    /// (2.5-fold at n = 1.52). Without it, on long noisy records steps 3–4 fed by a
    /// local line fit (short windows) or by points near h ≈ 0 give β ± γ that pass
    /// the sign test with |β|, |γ| many orders of magnitude too large. Default 4.
    pub max_hysteresis_gain: f64,
    /// Step 2 keeps a fitted δ only while the δ·u term does not outweigh the rate
    /// term on its points: |δ|·rms(u) ≤ this × |A + kv|·rms(u̇), A + kv from the fit
    /// with δ held (else it fits A + kv alone and keeps δ, as for an unresolved δ). δ·u·sgn(u̇) is the model's small
    /// asymmetry; where the crossing points span a narrow range of u (one frequency,
    /// long windows) an unbounded δ absorbs what the model misses and grows to
    /// thousands of times its size (|δ| ≈ 28 µm/(V·s) on noise-free bench data at
    /// N = 5000), and the model's h, and with it step 1, follow. Default 1.
    pub max_delta_ratio: f64,
    /// The output gate: a step's update is taken only where it does not make the
    /// window's own output error worse than holding the previous estimate. The error is
    /// Σ (x − x̂)² over the window's points, x̂ the model simulated over the window's
    /// inputs from h at its oldest point as the estimates read it there (x − kv·u − x0);
    /// an update is held ([`Reason::WorseOutput`]) when it raises that sum by more than
    /// this × k·σ̂², k the unknowns the step changes and σ̂² the window's noise variance
    /// of x (`PaperStatus::x_noise_um`²): refitting k unknowns to noise moves the sum by
    /// about k·σ̂², so a smaller rise is no evidence against the update. Steps 1
    /// (kv, x0), 2 (A, δ; A alone where it ran reduced) and 3–5 (n, β, γ) are gated in
    /// turn, each against the estimates the steps before it left. Without it the
    /// update of a window can take a model that fits the window worse than the one it
    /// replaces, and the next window starts from it: the method runs away (a period-ahead
    /// error of 969 µm at 1 Hz on the simulated bench at N = 50). `f64::INFINITY`: no
    /// gate. Default 1.
    pub output_gate: f64,
    /// Every step holds (reason [`Reason::NoSpread`]) while the window's rising points
    /// (u̇ > 0) or its falling points (u̇ < 0) span less than this fraction of the stroke,
    /// the range of u seen since the start or the last reset. The model's kv·u + x0 and
    /// its hysteresis are used over the whole loop, and a window that sees part of it
    /// cannot tell them apart: the line and the loop's width part only between the two
    /// branches over a common range of u, so a window on one branch, or over a turn with
    /// a short stretch of the other, fits a local chord. On the paper's record the
    /// Cramér–Rao bound of A from one window (docs/results.md, "What one window can
    /// tell") is above 10 % of |A| at 1 Hz for N ≤ 1000, and a window over a fraction of a
    /// slow loop fits a chord (kv = −9.4 µm/V on the simulated bench at N = 50 and 1 Hz)
    /// that its own output error prefers, so the output gate alone does not stop it. Both
    /// branches, not the window's whole span: at the start of a record the stroke seen is
    /// the first rise itself, which a window spans whole (on the simulated bench at
    /// N = 500 step 1 took such a chord in the first quarter period and held it, 1.19 µm
    /// at 1 Hz against the traditional fit's 0.48 µm); and a window of a quarter period
    /// at 100 Hz (N = 25) spans 70 % of the stroke on one branch (2.9 µm at 100 Hz against
    /// 1.24 µm). The window fit has its own gates and does not use this one. 0: no
    /// bound. Default 0.5.
    pub min_stroke_frac: f64,
    /// The window fit ([`PaperStatus::window_fit`]) runs each time this fraction of
    /// the window's points has entered since its last run (0 < this ≤ 1). It refits the
    /// whole window, O(N) work, so it runs once per slide of this fraction rather than
    /// at every push: the data change by that fraction between two runs, and the
    /// amortised cost per sample is 1/this times one run's cost per point. A smaller
    /// fraction also lets a window that lies wholly within one part of a record (a
    /// window just shorter than a frequency's part) be fitted before the part ends.
    /// Default 0.125.
    pub fit_every: f64,
    /// Largest number of Gauss–Newton (Levenberg–Marquardt) iterations of one window
    /// fit, each one simulation of the window on dual numbers (value and the eight
    /// derivatives), plus at most [`PaperConfig::FIT_TRIALS`] plain simulations for its
    /// damping. A fit that has not converged within them is carried to the next run as
    /// its starting point, so the iterations of several runs add up. A budget, not a
    /// tolerance: from one row of the paper's Table 2 to another (100 to 200 Hz) the fit
    /// takes 12 to 19 iterations, and a window in the flat valley of a slow loop (1 Hz)
    /// moves by more than a tenth of a standard error per iteration for about as many;
    /// 16 finishes most such moves in one run and the rest in the next, and one run
    /// costs about 16·(N points on duals + N in plain numbers). 0: no window fit (the
    /// paper's steps alone). Default 16.
    pub fit_iterations: usize,
    /// The window fit is taken only where it resolves the loop's gain, width and shape:
    /// kv, A and n each at least this many standard errors from 0, the standard errors
    /// σ·√diag((JᵀJ)⁻¹) of the fit itself (σ² its residual variance, J its Jacobian:
    /// the window's own Cramér–Rao bound at the estimate). At 10 each is known to 10 %
    /// at one standard error, as step 1 asks of kv (`min_line_t`); below it the window
    /// cannot tell the value from its neighbours and the estimate in use is kept
    /// (reason [`Reason::Noise`]). Default 10.
    pub min_fit_t: f64,
    /// The window fit is taken only where the model explains the window to its noise:
    /// residual standard deviation at most this × the noise of x (the least window
    /// estimate `PaperStatus::x_noise_um` seen since the start: each is an upper bound,
    /// the signal's curvature adding to it at fast inputs). A window that one parameter
    /// set cannot fit that closely holds a change of the plant (a switch of frequency
    /// inside it, on the paper's record: hundreds of nm of residual) or an effect the
    /// model lacks, and its fit has no precision to claim (reason [`Reason::Misfit`]).
    /// Under the model the residual variance over N − 8 degrees of freedom exceeds 4σ²
    /// (twice the noise) with a probability that vanishes for any window of more than a
    /// few tens of points. `f64::INFINITY`: no check. Default 2.
    pub max_misfit: f64,
}

impl PaperConfig {
    /// Smallest accepted window.
    pub const MIN_WINDOW: usize = 16;
    /// Largest accepted window (the points are held in memory, 56 bytes each).
    pub const MAX_WINDOW: usize = 10_000_000;
    /// Smallest derivative half-width: 5 points, the least for a local quadratic with
    /// a residual (the noise estimate).
    pub const MIN_HALF_WIDTH: usize = 2;
    /// Largest accepted `max_half_width` (1 s at 100 kHz).
    pub const MAX_HALF_WIDTH: usize = 100_000;
    /// Largest accepted `fit_iterations`.
    pub const MAX_FIT_ITERATIONS: usize = 1000;
    /// Damped trials of one window-fit iteration: the damping grows fourfold after each
    /// trial that does not lower the window's output error, 4⁸ ≈ 6.6·10⁴-fold at most,
    /// after which the fit has converged as far as its local model tells.
    pub const FIT_TRIALS: usize = 8;

    /// Defaults with window N = `window_len`.
    pub fn with_window(window_len: usize) -> Self {
        PaperConfig {
            window_len,
            decomposition: Decomposition::Model,
            h_zero_frac: 0.05,
            rate_frac: 0.2,
            min_points: 8,
            rank_tol: 1e-3,
            min_log_spread: 0.05,
            min_r2: 0.9,
            min_arg_frac: 0.0,
            min_line_t: 10.0,
            noise_gate: 3.0,
            derivative_phase: 0.1,
            max_half_width: 500,
            min_delta_t: 3.0,
            min_u_std_v: 1e-6,
            n_bounds: (0.5, 4.0),
            max_hysteresis_gain: 4.0,
            max_delta_ratio: 1.0,
            output_gate: 1.0,
            min_stroke_frac: 0.5,
            fit_every: 0.125,
            fit_iterations: 16,
            min_fit_t: 10.0,
            max_misfit: 2.0,
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
        if self.max_half_width < Self::MIN_HALF_WIDTH || self.max_half_width > Self::MAX_HALF_WIDTH {
            return bad("max_half_width", self.max_half_width as f64, "must be between 2 and 100 000 samples");
        }
        if !(self.derivative_phase.is_finite() && self.derivative_phase > 0.0) {
            return bad("derivative_phase", self.derivative_phase, "must be finite and > 0");
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
            ("min_stroke_frac", self.min_stroke_frac),
            ("min_fit_t", self.min_fit_t),
        ];
        if !(self.fit_every > 0.0 && self.fit_every <= 1.0) {
            return bad("fit_every", self.fit_every, "must be > 0 and <= 1");
        }
        if self.fit_iterations > Self::MAX_FIT_ITERATIONS {
            return bad("fit_iterations", self.fit_iterations as f64, "must be at most 1000");
        }
        if self.max_misfit.is_nan() || self.max_misfit <= 0.0 {
            return bad("max_misfit", self.max_misfit, "must be > 0 (inf: no check)");
        }
        if self.output_gate.is_nan() || self.output_gate < 0.0 {
            return bad("output_gate", self.output_gate, "must be >= 0 (inf: no gate)");
        }
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
