"""Configuration of the online identifiers: frozen dataclasses that mirror the Rust
structs ``RpemConfig`` and ``PaperConfig`` field by field.

The defaults come from the Rust core (one place for each value); a config is
validated when it is built (:class:`boucwen.InvalidConfig`, a ``ValueError``, naming
the offending option)::

    cfg = boucwen.RpemConfig(memory_travel_v=600.0)
    ident = boucwen.Identifier.rpem(dt, init, config=cfg)
    ident = boucwen.Identifier.paper(dt, 1000, init, config=boucwen.PaperConfig(decomposition="line"))

Configs are immutable values (equality, hash, repr, pickling); ``ident.config`` gives
back the one an identifier runs with, equal to the one it was given.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal

from . import _core

_RPEM: dict[str, Any] = _core._config_defaults("rpem")
_PAPER: dict[str, Any] = _core._config_defaults("paper")
_HORIZON: dict[str, Any] = _core._config_defaults("horizon")


@dataclass(frozen=True)
class HorizonConfig:
    """Tuning of the moving-horizon method (``Identifier.horizon``); see the Rust docs
    of ``HorizonConfig``. Units in the names: V."""

    memory_travel_v: float = _HORIZON["memory_travel_v"]
    """Length of the window in input travel [V] (300 V: 1.5 periods of a 0–100 V sine)."""
    recent_factor: float = _HORIZON["recent_factor"]
    """The window holds at most this × the samples of the newest half of the memory's
    travel (slow samples leave within a period after the input speeds up; inf: no limit)."""
    max_window: int = _HORIZON["max_window"]
    """Most samples the window holds (allocated at construction)."""
    samples_per_push: int = _HORIZON["samples_per_push"]
    """Samples of the window's simulation run per push."""
    min_pass_fraction: float = _HORIZON["min_pass_fraction"]
    """A pass leads to an update only when it spans this fraction of the memory."""
    ridge: float = _HORIZON["ridge"]
    """Relative Tikhonov weight on the normal equations."""
    damping: float = _HORIZON["damping"]
    """Initial Levenberg–Marquardt damping (relative)."""
    max_step: float = _HORIZON["max_step"]
    """Largest change of a parameter in one update, as a fraction of its scale."""
    n_bounds: tuple[float, float] = _HORIZON["n_bounds"]
    """n is held within these bounds [-]."""
    fc_bounds_hz: tuple[float, float] = _HORIZON["fc_bounds_hz"]
    """With an identified input lag, its corner frequency is held within these bounds [Hz]."""
    margin: float = _HORIZON["margin"]
    """β + γ and β − γ are held at or above this [µm^(1−n)/V] (> 0: inside the admissible
    region, where the δ term is dissipated on both branches of the loop)."""
    scales: tuple[float, ...] = tuple(_HORIZON["scales"])
    """Scale of kv, x0, A, β, γ, n, δ and of the window's initial h [µm]."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "n_bounds", tuple(self.n_bounds))
        object.__setattr__(self, "fc_bounds_hz", tuple(self.fc_bounds_hz))
        object.__setattr__(self, "scales", tuple(self.scales))
        _core._validate_config("horizon", self)

    def replace(self, **changes: Any) -> HorizonConfig:
        """A copy with some options changed (validated)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class RpemConfig:
    """Tuning of the output-error method (``Identifier.rpem``); see the Rust docs of
    ``RpemConfig`` for each option's role. Units in the names: V, µm, Hz."""

    forgetting: float = _RPEM["forgetting"]
    """Forgetting factor per sample λ ∈ (0, 1] (1: none; see memory_travel_v)."""
    memory_travel_v: float = _RPEM["memory_travel_v"]
    """Memory measured in input travel [V]: weight falls by exp(−|Δu|/memory) per interval."""
    p0: float = _RPEM["p0"]
    """Initial covariance of the scaled parameters θᵢ/scaleᵢ."""
    offset_walk_um: float = _RPEM["offset_walk_um"]
    """Random walk of the offset x0 [µm per sample, standard deviation]."""
    p0_effects: float = _RPEM["p0_effects"]
    """Initial covariance of the effects' coordinates (ln fc, creep gains' logits)."""
    noise_um2: float = _RPEM["noise_um2"]
    """R: the least variance of the prediction error [µm²]; R is learnt above it."""
    noise_memory_samples: float = _RPEM["noise_memory_samples"]
    """Memory of the running mean of squared prediction errors R follows above noise_um2 [samples]; inf: fixed."""
    max_trace: float = _RPEM["max_trace"]
    """Bound on tr P (scaled units)."""
    max_step: float = _RPEM["max_step"]
    """Largest change of any parameter in one sample, as a fraction of its scale."""
    max_offset_step_um: float = _RPEM["max_offset_step_um"]
    """Largest change of the offset x0 in one sample [µm]."""
    n_bounds: tuple[float, float] = _RPEM["n_bounds"]
    """n is held within these bounds [-]."""
    margin: float = _RPEM["margin"]
    """β + γ and β − γ are held at or above this [µm^(1−n)/V] (> 0: inside the admissible
    region, where the δ term is dissipated on both branches of the loop)."""
    scales: tuple[float, ...] = tuple(_RPEM["scales"])
    """Scale of kv, x0, A, β, γ, n, δ in their units (the update works on θᵢ/scaleᵢ)."""
    creep_gain_scale_um_per_v: float = _RPEM["creep_gain_scale_um_per_v"]
    """Scale of the creep gains [µm/V]."""
    creep_gain_max_um_per_v: float = _RPEM["creep_gain_max_um_per_v"]
    """Each creep gain is held within [0, this] [µm/V]."""
    fc_bounds_hz: tuple[float, float] = _RPEM["fc_bounds_hz"]
    """The input lag's corner frequency is held within these bounds [Hz]."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "n_bounds", tuple(self.n_bounds))
        object.__setattr__(self, "scales", tuple(self.scales))
        object.__setattr__(self, "fc_bounds_hz", tuple(self.fc_bounds_hz))
        _core._validate_config("rpem", self)

    def replace(self, **changes: Any) -> RpemConfig:
        """A copy with some options changed (validated)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class PaperConfig:
    """Tuning of the paper's method (``Identifier.paper``): every tolerance the paper
    leaves open; see the Rust docs of ``PaperConfig``. The window N is an argument of
    ``Identifier.paper`` itself."""

    decomposition: Literal["model", "line"] = _PAPER["decomposition"]
    """How kv·u + x0 is separated from h in step 1: "model" (x − h_model) or "line" (the paper's)."""
    h_zero_frac: float = _PAPER["h_zero_frac"]
    """|h| below this fraction of the starting model's saturation amplitude
    (|A₀|/(|β₀|+|γ₀|))^(1/n₀) counts as h ≈ 0 (step 2), above it as h > 0 (steps 3–4)."""
    rate_frac: float = _PAPER["rate_frac"]
    """Points with |u̇| below this fraction of the window's rms(u̇) are left out of steps 2–4."""
    min_points: int = _PAPER["min_points"]
    """Fewest points for a sub-fit."""
    rank_tol: float = _PAPER["rank_tol"]
    """Step 2 fits δ only when 1 − corr²(u̇, u) exceeds this."""
    min_log_spread: float = _PAPER["min_log_spread"]
    """Step 3 fits n only when std(ln h) exceeds this."""
    min_arg_frac: float = _PAPER["min_arg_frac"]
    """Steps 3–4 use a point only when |A − r| ≥ this fraction of |A|."""
    noise_gate: float = _PAPER["noise_gate"]
    """Steps 3–4 use a point only when |A − r| ≥ this many standard deviations of r's noise."""
    derivative_phase: float = _PAPER["derivative_phase"]
    """u̇, ẋ are Savitzky–Golay derivatives over 2m + 1 samples, m spanning ± this much of
    the input's phase (ω̂ = rms(u̇)/std(u) over the window), within 2 … max_half_width [rad]."""
    max_half_width: int = _PAPER["max_half_width"]
    """Largest derivative half-width m [samples] (a point enters the window m samples late)."""
    min_delta_t: float = _PAPER["min_delta_t"]
    """Step 2 updates δ only when |δ| ≥ this many standard errors."""
    min_r2: float = _PAPER["min_r2"]
    """Step 3 fits n only when the log–log points have r² ≥ this."""
    min_line_t: float = _PAPER["min_line_t"]
    """Step 1 updates kv, x0 only when |kv| ≥ this many standard errors."""
    min_u_std_v: float = _PAPER["min_u_std_v"]
    """Step 1 runs only while std(u) over the window exceeds this [V]."""
    n_bounds: tuple[float, float] = _PAPER["n_bounds"]
    """A fitted n outside these bounds is taken as a failed fit [-]."""
    max_hysteresis_gain: float = _PAPER["max_hysteresis_gain"]
    """Step 5 keeps β, γ, n only while (|β|+|γ|)·hₛⁿ ≤ this × |A₀|, hₛ = (|A₀|/(|β₀|+|γ₀|))^(1/n₀)
    the starting model's saturation amplitude (``math.inf``: no bound)."""
    max_delta_ratio: float = _PAPER["max_delta_ratio"]
    """Step 2 keeps a fitted δ only while |δ|·rms(u) ≤ this × |A + kv|·rms(u̇) over its points."""
    output_gate: float = _PAPER["output_gate"]
    """A step's update is held (reason "worse_output") when it raises the window's own
    output error Σ(x − x̂)² (the model simulated over the window from h at its oldest
    point) by more than this × k·σ̂² over holding, k the unknowns it changes, σ̂² the
    window's noise variance of x (``math.inf``: no gate)."""
    min_stroke_frac: float = _PAPER["min_stroke_frac"]
    """Every step holds (reason "no_spread") while the window's rising points or its
    falling points span less than this fraction of the range of u seen since the start
    (0: no bound; the window fit has its own gates)."""
    fit_every: float = _PAPER["fit_every"]
    """The window fit (``PaperStatus.window_fit``: kv, x0, A, β, γ, n, δ and h at the
    window's start by least squares on the window's own output error) runs each time
    this fraction of the window's points has entered since its last run (0 < this ≤ 1)."""
    fit_iterations: int = _PAPER["fit_iterations"]
    """Largest number of Gauss–Newton iterations of one window fit (a fit not converged
    continues in the next run); 0: no window fit, the paper's steps alone."""
    min_fit_t: float = _PAPER["min_fit_t"]
    """The window fit is taken only where kv, A and n are each at least this many of its
    standard errors from 0 (else held, reason "noise")."""
    max_misfit: float = _PAPER["max_misfit"]
    """The window fit is taken only where its residual standard deviation is at most this
    × the window's noise of x (else held, reason "misfit"; ``math.inf``: no check)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "n_bounds", tuple(self.n_bounds))
        _core._validate_config("paper", self)

    def replace(self, **changes: Any) -> PaperConfig:
        """A copy with some options changed (validated)."""
        return dataclasses.replace(self, **changes)
