//! What a push of the paper's identifier did.

/// Outcome of one step in a push.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SubFit {
    /// The previous estimate was kept ([`StepStatus::reason`] says why).
    #[default]
    Held,
    /// Ran on a reduced set of unknowns; the rest was kept ([`StepStatus::reason`] says why).
    Reduced,
    /// Ran in full.
    Ran,
}

impl SubFit {
    /// Lower-case name, for logs and Python.
    pub fn name(self) -> &'static str {
        match self {
            SubFit::Held => "held",
            SubFit::Reduced => "reduced",
            SubFit::Ran => "ran",
        }
    }
}

/// Why a step held or ran reduced ([`Reason::None`] when it ran in full).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Reason {
    /// It ran in full.
    #[default]
    None,
    /// The window does not hold its N samples yet (step 1, the window fit).
    WindowFilling,
    /// The input does not move over the window (step 1: std(u) below `min_u_std_v`).
    NoExcitation,
    /// Fewer usable points than `min_points` in the window.
    TooFewPoints,
    /// The points do not spread enough to resolve the unknown (step 2: u̇ and u
    /// collinear, `rank_tol`; step 3: ln h spread below `min_log_spread`; every step:
    /// the window's rising or falling points span less than `min_stroke_frac` of the
    /// stroke).
    NoSpread,
    /// The estimate is not resolved above the noise (step 1: |kv| below `min_line_t`
    /// standard errors; step 2: δ below `min_delta_t` standard errors; step 3: the
    /// log–log points not on a line, r² below `min_r2`; the window fit: kv, A or n
    /// below `min_fit_t` standard errors, or, ran reduced, δ below `min_delta_t`).
    Noise,
    /// The estimate leaves the bounded region (n outside `n_bounds`; step 2: δ·u
    /// outweighs the rate term, `max_delta_ratio`; step 5: β + γ ≤ 0, β − γ ≤ 0 or the
    /// hysteresis bound `max_hysteresis_gain`; the window fit: the same bounds), or is
    /// not finite.
    OutOfBounds,
    /// Step 5 only: neither step 3 nor step 4 gave a new value to combine.
    Upstream,
    /// The update would make the window's own output error worse than holding the
    /// previous estimate (the output gate, `PaperConfig::output_gate`; steps 1, 2 and 5).
    WorseOutput,
    /// The window fit only: the model does not explain the window to its noise (residual
    /// above `max_misfit` × the noise of x), or its iterations have not converged yet.
    Misfit,
}

impl Reason {
    /// Snake-case name, for logs and Python ("none" when the step ran in full).
    pub fn name(self) -> &'static str {
        match self {
            Reason::None => "none",
            Reason::WindowFilling => "window_filling",
            Reason::NoExcitation => "no_excitation",
            Reason::TooFewPoints => "too_few_points",
            Reason::NoSpread => "no_spread",
            Reason::Noise => "noise",
            Reason::OutOfBounds => "out_of_bounds",
            Reason::Upstream => "upstream",
            Reason::WorseOutput => "worse_output",
            Reason::Misfit => "misfit",
        }
    }

    /// Every reason, in code order (the code is the position).
    pub const ALL: [Reason; 10] = [
        Reason::None,
        Reason::WindowFilling,
        Reason::NoExcitation,
        Reason::TooFewPoints,
        Reason::NoSpread,
        Reason::Noise,
        Reason::OutOfBounds,
        Reason::Upstream,
        Reason::WorseOutput,
        Reason::Misfit,
    ];
}

/// What one step did in a push: its outcome, why it held or ran reduced, the window
/// points it had and the scatter of those points about its fit.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepStatus {
    /// Ran, ran reduced or held.
    pub fit: SubFit,
    /// Why it held or ran reduced.
    pub reason: Reason,
    /// Window points the step selected (step 1: the whole window; step 5: 0).
    pub points: u32,
    /// Residual standard deviation of the points about the step's fit, in the step's
    /// regression units: step 1 and the window fit x \[µm\]; step 2 ẋ \[µm/s\]; steps
    /// 3–4 ln|A − r| \[-\]; 0 where there was no fit (too few points, step 5).
    pub noise: f64,
}

impl StepStatus {
    /// A step that held for `reason` with `points` points.
    pub(crate) fn held(reason: Reason, points: u32) -> Self {
        StepStatus { fit: SubFit::Held, reason, points, noise: 0.0 }
    }
}

/// What the last `push` did. Small and `Copy`: reading it never allocates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PaperStatus {
    /// Samples pushed since construction or reset.
    pub samples: u64,
    /// The window holds its full N samples.
    pub window_full: bool,
    /// The window sums were refreshed exactly during this push.
    pub refreshed: bool,
    /// Half-width m of the derivative (Savitzky–Golay) stencil of the points
    /// completed in this push \[samples\] (0: none completed).
    pub half_width: u32,
    /// Standard deviation of the noise of x over the window, from the residuals of the
    /// local quadratic fits \[µm\] (an upper bound: the signal's own curvature adds).
    pub x_noise_um: f64,
    /// The noise it leaves in ẋ (and u̇, in its units) at half-width m: x_noise_um /
    /// (√S·Δt), S = m(m+1)(2m+1)/3 \[µm/s\].
    pub xdot_noise_um_s: f64,
    /// Step 1, kv and x0 (limited-memory RLS).
    pub line_fit: StepStatus,
    /// Step 2, A and δ.
    pub rate_fit: StepStatus,
    /// Step 3, n and β + γ.
    pub shape_fit: StepStatus,
    /// Step 4, γ − β.
    pub return_fit: StepStatus,
    /// Step 5, β and γ from β + γ and γ − β (n from step 3 is taken with them).
    pub split_fit: StepStatus,
    /// The window fit (`PaperConfig::fit_every`): kv, x0, A, β, γ, n, δ and h at the
    /// window's start from the window's own output error, on its last run (it runs once
    /// per slide of `fit_every` × N points; between runs this is what the last one did).
    /// `points` the window's points, `noise` the residual standard deviation \[µm\].
    /// Ran reduced: δ held (not resolved).
    pub window_fit: StepStatus,
}
