"""What the last push of an online identifier did: ``Identifier.status``, one frozen
dataclass per method, mirroring the Rust structs ``PaperStatus`` (with a
``StepStatus`` per step), ``RpemStatus`` and ``HorizonStatus`` field by field.

A status is an immutable value (equality, hash, repr, pickling), built anew at each
read of ``Identifier.status``::

    s = ident.status
    if isinstance(s, boucwen.PaperStatus) and s.shape_fit.outcome == "held":
        print("step 3 held:", s.shape_fit.reason, "on", s.shape_fit.points, "points")
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["HorizonStatus", "PaperStatus", "RpemStatus", "StepOutcome", "StepReason", "StepStatus"]

StepOutcome = Literal["ran", "reduced", "held"]
"""What a step of the paper's method did: ran in full, ran on fewer unknowns (the rest
kept), or held the previous estimate."""

StepReason = Literal[
    "none",
    "window_filling",
    "no_excitation",
    "too_few_points",
    "no_spread",
    "noise",
    "out_of_bounds",
    "upstream",
    "worse_output",
    "misfit",
]
"""Why a step held or ran reduced ("none" when it ran in full): the window is not full
yet (step 1); u does not move over it (step 1); fewer points than ``min_points``; the
points do not spread enough to resolve the unknown (step 2's u̇ and u collinear, step 3's
ln h spread); the estimate is not resolved above the noise (kv, δ below their t gates,
step 3's r² below ``min_r2``); the estimate leaves the bounded region (n bounds, δ
ratio, step 5's β ± γ > 0 and hysteresis bound) or is not finite; (step 5) neither
step 3 nor step 4 gave a value to combine; or (steps 1, 2, 5) the update would make the
window's own output error worse than holding the previous estimate (the output gate,
``PaperConfig.output_gate``); or (the window fit) the model does not explain the window
to its noise, or its iterations have not converged yet (``PaperConfig.max_misfit``)."""


@dataclass(frozen=True)
class StepStatus:
    """What one step of the paper's method did in the last push."""

    outcome: StepOutcome
    """Ran, ran reduced or held."""
    reason: StepReason
    """Why it held or ran reduced ("none" when it ran in full)."""
    points: int
    """Window points the step selected (step 1: the whole window; step 5: 0)."""
    noise: float
    """Residual standard deviation of the points about the step's fit, in its regression
    units: step 1 x [µm], step 2 ẋ [µm/s], steps 3–4 ln|A − r| [-]; 0 without a fit."""


@dataclass(frozen=True)
class PaperStatus:
    """``Identifier.status`` of the paper's method (``Identifier.paper``)."""

    samples: int
    """Samples pushed since construction or reset."""
    window_full: bool
    """The window holds its full N points."""
    refreshed: bool
    """The window's running sums were recomputed exactly in this push."""
    half_width: int
    """Half-width m of the Savitzky–Golay derivative stencil of the points completed in
    this push [samples] (0: none completed)."""
    x_noise_um: float
    """Noise of x over the window, from the residuals of the local quadratic fits [µm]."""
    xdot_noise_um_s: float
    """The noise that leaves on ẋ at half-width m [µm/s]."""
    line_fit: StepStatus
    """Step 1, kv and x0 (limited-memory RLS)."""
    rate_fit: StepStatus
    """Step 2, A and δ."""
    shape_fit: StepStatus
    """Step 3, n and β + γ."""
    return_fit: StepStatus
    """Step 4, γ − β."""
    split_fit: StepStatus
    """Step 5, β and γ from β + γ and γ − β."""
    window_fit: StepStatus
    """The window fit's last run (``PaperConfig.fit_every``): every unknown of steps 1–4
    and h at the window's start from the window's own output error; ``noise`` its
    residual standard deviation [µm]; ran reduced where δ is held (not resolved)."""

    def steps(self) -> dict[str, StepStatus]:
        """The five steps and the window fit by name, in order (``line_fit`` …
        ``split_fit``, ``window_fit``)."""
        return {
            "line_fit": self.line_fit,
            "rate_fit": self.rate_fit,
            "shape_fit": self.shape_fit,
            "return_fit": self.return_fit,
            "split_fit": self.split_fit,
            "window_fit": self.window_fit,
        }


@dataclass(frozen=True)
class RpemStatus:
    """``Identifier.status`` of the rpem method (``Identifier.rpem``)."""

    samples: int
    """Samples pushed since construction or reset."""
    updated: bool
    """The estimates were updated (false on the first sample and after a dropped step)."""
    step_limited: bool
    """The trust region scaled the step down."""
    projected: bool
    """The projection onto the well-posed region moved n, β or γ."""
    trace_capped: bool
    """The bound on tr P scaled the covariance down."""
    restarted: bool
    """A non-finite step, covariance or sensitivity was dropped (P restarted)."""
    innovation_um: float
    """Prediction error e = x − x̂ of the sample [µm]."""
    trace: float
    """tr P after the push (scaled units)."""
    noise_um2: float
    """R in use: the learnt variance of the prediction error [µm²]."""


@dataclass(frozen=True)
class HorizonStatus:
    """``Identifier.status`` of the moving-horizon method (``Identifier.horizon``)."""

    samples: int
    """Samples pushed since construction or reset."""
    updated: bool
    """The estimates were updated in this push (sync: the push after a pass over the window
    caught up; cooperative: in the ``refine`` calls since the push; background: adopted
    in this push)."""
    updates: int
    """Updates since construction or reset."""
    window_samples: int
    """Samples in the window."""
    window_travel_v: float
    """Input travel over the window [V]."""
    rms_um: float
    """RMS output error of the last pass [µm]."""
    damping: float
    """Levenberg–Marquardt damping after the last update."""
    step_limited: bool
    """The trust region scaled the last update down."""
    projected: bool
    """The projection onto the well-posed region moved n, β or γ in the last update (what
    rounding and the trust region left outside after the step was held)."""
    held: bool
    """The last update's step would have left the well-posed region (n outside its bounds,
    β ± γ below the margin) and was held on its boundary."""
    behind_samples: int
    """How far the estimates in use lag the newest sample: samples pushed after the last
    one the pass of the last update ran over [samples]."""
    behind_s: float
    """The same in seconds [s]."""
