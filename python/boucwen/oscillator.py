"""The hysteretic oscillator: simulation and output-error fit.

A mass on a linear spring and damper with a Bouc–Wen spring driven by the mass's own
motion (the hysteretic benchmark of Noël & Schoukens, 2016)::

    m·ÿ + c·ẏ + k·y + z = F
    ż = α·ẏ − β·(γ·|ẏ|·|z|^(ν−1)·z + δ·ẏ·|z|^ν)

F: applied force [N]; y: displacement [m]; z: hysteretic force [N]; t: time [s]. A
second model class beside the piezo model of :mod:`boucwen.fit` (whose hysteresis is
driven by the input): the Rust core integrates it (F linear between samples, RK4 with
sub-steps set by the spring–mass mode and by the relaxation of z, linearly implicit
Euler where those would be too many) and gives the exact Jacobian of y from the same
pass (``_core.oscillator_simulate_with_jacobian``).

* :class:`OscillatorParams`: the eight parameters, validated, with their units.
* :func:`simulate`: y [m] from F [N].
* :func:`fit`: the output-error fit (Levenberg–Marquardt of :mod:`boucwen.levenberg` on
  the exact Jacobian) from physically scaled starts; :class:`OscillatorFit` its result.

Units follow the record's: F in N, y in m, dt in s. Nothing is rescaled on the way in or
out (the fit scales its unknowns internally for the conditioning of its steps only).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ._core import (
    OSCILLATOR_UNKNOWNS,
    InvalidParams,
    InvalidRecord,
    oscillator_simulate,
    oscillator_simulate_with_jacobian,
)
from .checks import FloatArray, as_float_vector, check_dt, check_finite, check_int
from .effects.resonance import FN_MAX_NYQUIST_FRACTION
from .levenberg import levenberg_marquardt
from .metrics import rms
from .progress import Progress, reporter

__all__ = ["NU_BOUNDS", "UNKNOWNS", "OscillatorFit", "OscillatorParams", "check_admissible", "fit", "simulate"]

#: The exponent's domain [-] (the core's: below 1 the relaxation of z is infinitely
#: stiff at z = 0).
NU_BOUNDS = (1.0, 10.0)
#: The unknowns of the fit, in the order of the Jacobian's columns: the parameters but β
#: (it enters only as β·γ and β·δ) and the initial state y0 [m], v0 [m/s], z0 [N].
UNKNOWNS: tuple[str, ...] = tuple(OSCILLATOR_UNKNOWNS)

#: Samples of the stretch the start candidates are scored on.
_SCORE_LEN = 8192


@dataclass(frozen=True)
class OscillatorParams:
    """The parameters of the hysteretic oscillator (module docs).

    Attributes:
        m: mass [kg], > 0.
        c: viscous damping [N·s/m], ≥ 0.
        k: linear stiffness [N/m], ≥ 0.
        alpha: initial stiffness of the Bouc–Wen spring α [N/m], > 0.
        beta: β [N^(1−ν)/m] (1/m for ν = 1), > 0: the scale of γ and δ (only β·γ and β·δ
            enter the model; a fit keeps β as given and identifies γ and δ).
        gamma: γ [-], finite.
        delta: δ [-], finite.
        nu: exponent ν [-], in [1, 10].

    Raises:
        InvalidParams (a ValueError): a value out of its domain; the message names it.
    """

    m: float
    c: float
    k: float
    alpha: float
    beta: float
    gamma: float
    delta: float
    nu: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise TypeError(f"{f.name} must be a real number, got {type(value).__name__}")
            object.__setattr__(self, f.name, float(value))
        rules = (
            ("m", self.m > 0.0, "the mass must be > 0 kg"),
            ("c", self.c >= 0.0, "the damping must be >= 0 N·s/m"),
            ("k", self.k >= 0.0, "the stiffness must be >= 0 N/m"),
            ("alpha", self.alpha > 0.0, "the Bouc-Wen spring's stiffness must be > 0 N/m"),
            ("beta", self.beta > 0.0, "must be > 0 (the sign of the loop is gamma's and delta's)"),
            ("nu", NU_BOUNDS[0] <= self.nu <= NU_BOUNDS[1], "must be in [1, 10]"),
        )
        for f in fields(self):
            value = getattr(self, f.name)
            if not math.isfinite(value):
                raise InvalidParams(f"invalid parameter {f.name} = {value}: must be finite")
        for name, ok, reason in rules:
            if not ok:
                raise InvalidParams(f"invalid parameter {name} = {getattr(self, name)}: {reason}")

    @classmethod
    def benchmark(cls) -> OscillatorParams:
        """The values of the benchmark's simulator (Noël & Schoukens 2016): m = 2 kg,
        c = 10 N·s/m, k = 5e4 N/m, α = 5e4 N/m, β = 1e3 1/m, γ = 0.8, δ = −1.1, ν = 1."""
        return cls(m=2.0, c=10.0, k=5e4, alpha=5e4, beta=1e3, gamma=0.8, delta=-1.1, nu=1.0)

    def to_list(self) -> list[float]:
        """``[m, c, k, alpha, beta, gamma, delta, nu]`` (the core's order)."""
        return [getattr(self, f.name) for f in fields(self)]

    def to_dict(self) -> dict[str, float]:
        """``{name: value}`` in SI units (kg, N·s/m, N/m, N/m, N^(1−ν)/m, -, -, -)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def simulate(
    params: OscillatorParams,
    F: Any,
    dt: float,
    y0: float = 0.0,
    v0: float = 0.0,
    z0: float = 0.0,
) -> FloatArray:
    """The displacement y [m] of the oscillator driven by the force ``F`` [N].

    Args:
        params: the model.
        F: force samples [N], ``dt`` [s] apart, taken as linear between samples.
        dt: sampling interval [s].
        y0, v0, z0: the state at sample 0: displacement [m], velocity [m/s], hysteretic
            force [N].

    Returns:
        y [m], one value per sample of ``F`` (y[0] = ``y0``).

    Raises:
        InvalidRecord: ``F`` empty, not 1-D, or with a NaN or infinite sample.
        InvalidConfig: ``dt`` not finite and > 0, or a non-finite initial state.
    """
    force = as_float_vector(F, "F")
    dt = check_dt(dt)
    state = [check_finite(name, value) for name, value in (("y0", y0), ("v0", v0), ("z0", z0))]
    y: FloatArray = oscillator_simulate(params.to_list(), force, dt, *state)
    return y


@dataclass(frozen=True, eq=False)
class OscillatorFit:
    """Result of :func:`fit`.

    Attributes:
        params: the identified :class:`OscillatorParams` (β as started).
        y0, v0, z0: the identified initial state: displacement [m], velocity [m/s],
            hysteretic force [N].
        y: the simulated displacement [m] of the fitted model over the record.
        rms: RMS output error [m] over the samples of weight 1.
        nfev: simulations of the record (trial points and Jacobian passes, start
            scoring included).
        success: the solver stopped by its statistical margin or its tolerance (converged),
            not by ``max_nfev``.
        message: why the solver stopped.
        seconds: wall time of the fit [s].
        jacobian: ∂y/∂θ [m per unit of θ] at the end point, shape (samples, 10), the
            columns :data:`UNKNOWNS`; None unless asked for.
    """

    params: OscillatorParams
    y0: float
    v0: float
    z0: float
    y: FloatArray
    rms: float
    nfev: int
    success: bool
    message: str
    seconds: float
    jacobian: FloatArray | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (without ``y`` and ``jacobian``)."""
        return {
            "params": self.params.to_dict(),
            "y0_m": self.y0,
            "v0_m_s": self.v0,
            "z0_N": self.z0,
            "rms_m": self.rms,
            "nfev": self.nfev,
            "success": self.success,
            "message": self.message,
            "seconds": self.seconds,
        }


# --------------------------------------------------------------------------- starts


def _frequency_response(F: FloatArray, y: FloatArray, dt: float) -> tuple[float, float, float]:
    """(K [N/m], m [kg], c [N·s/m]) of the second-order FRF 1/(K − m·ω² + i·c·ω) fitted to
    the record's H1 estimate S_Fy/S_FF (Welch, segments of a quarter of the record, at
    most 4096 samples) on the lines where the force has at least 1e-3 of its peak power:
    least squares of |1 − (K − m·ω² + i·c·ω)·H|², linear in (K, m, c). K is the linear
    spring and the Bouc–Wen spring's equivalent stiffness at the record's amplitude, c the
    damper and the loop's equivalent damping."""
    from scipy import signal

    fs = 1.0 / dt
    nper = int(min(4096, max(64, F.size // 4), F.size))
    f, s_ff = signal.welch(F, fs, nperseg=nper)
    _, s_fy = signal.csd(F, y, fs, nperseg=nper)
    band = (s_ff > 1e-3 * float(np.max(s_ff))) & (f > 0.0)
    w = 2.0 * np.pi * f[band]
    h = s_fy[band] / s_ff[band]
    a = np.concatenate(
        [
            np.stack([h.real, -(w**2) * h.real, -w * h.imag], axis=1),
            np.stack([h.imag, -(w**2) * h.imag, w * h.real], axis=1),
        ]
    )
    b = np.concatenate([np.ones_like(w), np.zeros_like(w)])
    k_eq, m, c = np.linalg.lstsq(a, b, rcond=None)[0]
    return float(k_eq), float(m), float(c)


def _candidates(F: FloatArray, y: FloatArray, dt: float) -> list[OscillatorParams]:
    """Physically scaled starts (ν = 1).

    m from the FRF (:func:`_frequency_response`); its stiffness K shared between k and the
    Bouc–Wen spring, and α from the part that is the spring's: at the record's amplitude
    the loop's secant slope is below its initial slope α, taken 1 or 2 times that part; c
    a tenth or a half of the FRF's damping (the rest is the loop's). β = 1/(2·std y) [1/m],
    so that β·|y| ~ 1 over a half-swing and γ, δ are of order 1: γ + δ (the loading
    branch: > 0 saturates, < 0 stiffens) and γ − δ (the unloading branch's extra
    stiffness) on a small grid.
    """
    k_eq, m, c = _frequency_response(F, y, dt)
    scale_y = float(np.std(y)) or 1.0
    m = m if math.isfinite(m) and m > 0.0 else 1.0
    k_eq = k_eq if math.isfinite(k_eq) and k_eq > 0.0 else m * (2.0 * math.pi * 0.1 / dt) ** 2
    c = c if math.isfinite(c) and c > 0.0 else 0.1 * math.sqrt(k_eq * m)
    beta = 1.0 / (2.0 * scale_y)
    out = []
    for share in (0.3, 0.5, 0.7):
        for gain in (1.0, 2.0):
            for c_share in (0.1, 0.5):
                for plus, minus in ((0.5, 1.0), (-0.3, 2.0), (0.0, 0.5), (1.0, 3.0)):
                    out.append(
                        OscillatorParams(
                            m=m,
                            c=c_share * c,
                            k=(1.0 - share) * k_eq,
                            alpha=gain * share * k_eq,
                            beta=beta,
                            gamma=0.5 * (plus + minus),
                            delta=0.5 * (plus - minus),
                            nu=1.0,
                        )
                    )
    return out


# --------------------------------------------------------------------------- fit


#: ∂(γ, δ)/∂(γ, γ − δ): the core's Jacobian columns ∂/∂γ, ∂/∂δ times this give the
#: fit's ∂/∂γ (γ − δ held) and ∂/∂(γ − δ).
_REGION_JACOBIAN: FloatArray = np.array([[1.0, 0.0], [1.0, -1.0]])


def check_admissible(p: OscillatorParams) -> OscillatorParams:
    """``p`` if it is in the oscillator's admissible region (docs/design.md, "The admissible
    region"): γ ≥ 0 (the loop's irreversible term dissipates: with γ < 0 it runs the other
    way and feeds energy in every cycle) and γ − δ ≥ 0 (the unloading branch stiffens:
    otherwise z grows against the motion once past (α/(β·(δ − γ)))^(1/ν)); else
    :class:`boucwen.InvalidParams` naming the combination."""
    for name, value in (("gamma", p.gamma), ("gamma - delta", p.gamma - p.delta)):
        if value < 0.0:
            raise InvalidParams(
                f"invalid parameter {name} = {value}: must be >= 0: the loop feeds the motion energy "
                "(the admissible region, docs/design.md)"
            )
    return p


def _unknowns(p: OscillatorParams, state: Sequence[float]) -> FloatArray:
    """The fit's unknowns: m, c, k, α, γ, γ − δ (the admissible region is γ ≥ 0, γ − δ ≥ 0),
    ν and the initial state."""
    return np.array([p.m, p.c, p.k, p.alpha, p.gamma, p.gamma - p.delta, p.nu, *state], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Box:
    """The fit's unknowns about a model and where they may go.

    Attributes:
        z: the unknowns (:func:`_unknowns`: m, c, k, α, γ, γ − δ, ν, y0, v0, z0).
        lower, upper: their bounds: the admissible region (γ ≥ 0, γ − δ ≥ 0), ν within
            :data:`NU_BOUNDS`, and the mode within what the record can show.
        scale: each unknown's typical size (the solver's metric).
        beta: β, held (not identified: only β·γ and β·δ are).
    """

    z: FloatArray
    lower: FloatArray
    upper: FloatArray
    scale: FloatArray
    beta: float


def _box(p: OscillatorParams, state: Sequence[float], y: FloatArray, dt: float) -> Box:
    """The :class:`Box` of a fit about ``p`` and ``state`` of a displacement ``y`` [m]
    sampled every ``dt`` [s]."""
    z0 = _unknowns(p, state)
    amplitude = float(np.std(y)) or 1.0
    velocity = amplitude / dt * 0.1
    x_scale = np.abs(z0)
    x_scale[4:6] = np.maximum(x_scale[4:6], 0.1)
    x_scale[6] = 1.0
    x_scale[7:] = (amplitude, velocity, max(p.alpha * amplitude, 1e-12))
    # The mode stays within what the record can show (ω² = (k + α)/m at most that of
    # FN_MAX_NYQUIST_FRACTION of the sampling rate, the bound of a resonance effect): a
    # mode above it cannot be identified from the record, and the integrator would take
    # ever more sub-steps to follow it. The box holds m above the mass that puts the
    # model's stiffness there.
    omega_max = 2.0 * math.pi * FN_MAX_NYQUIST_FRACTION / dt
    m_min = max(1e-9 * p.m, (p.k + p.alpha) / omega_max**2)
    lower = np.array([m_min, 0.0, 0.0, 1e-9 * p.alpha, 0.0, 0.0, NU_BOUNDS[0], *[-np.inf] * 3])
    z0[0] = max(z0[0], m_min)
    upper = np.array([np.inf] * 6 + [NU_BOUNDS[1]] + [np.inf] * 3)
    return Box(z0, lower, upper, x_scale, p.beta)


def linearised(
    fit: OscillatorFit, F: Any, dt: float
) -> tuple[Box, FloatArray, Callable[[FloatArray, int], FloatArray | None]]:
    """A fitted oscillator in the fit's own unknowns, for a first-order view of refits
    from it: its :class:`Box`, the Jacobian ∂y/∂z [m per unit] over ``F`` (columns in
    the box's order), and z, stop → y [m] over the first ``stop`` samples (None where it
    cannot be simulated)."""
    force = as_float_vector(F, "F")
    box = _box(fit.params, (fit.y0, fit.v0, fit.z0), fit.y, dt)
    jac = oscillator_simulate_with_jacobian(fit.params.to_list(), force, dt, fit.y0, fit.v0, fit.z0)[1]
    jac[:, 4:6] = jac[:, 4:6] @ _REGION_JACOBIAN

    def run(z: FloatArray, stop: int) -> FloatArray | None:
        try:
            out = np.asarray(
                oscillator_simulate(_params(z, box.beta).to_list(), force[:stop], dt, *(float(v) for v in z[7:])),
                dtype=np.float64,
            )
        except ValueError:
            return None
        return out if bool(np.all(np.isfinite(out))) else None

    return box, np.asarray(jac, dtype=np.float64), run


def _params(z: FloatArray, beta: float) -> OscillatorParams:
    m, c, k, alpha, gamma, minus, nu = (float(v) for v in z[:7])
    return OscillatorParams(m=m, c=c, k=k, alpha=alpha, beta=beta, gamma=gamma, delta=gamma - minus, nu=nu)


def fit(
    F: Any,
    y: Any,
    dt: float,
    *,
    start: OscillatorParams | None = None,
    weights: Any = None,
    max_nfev: int = 200,
    progress: Progress = False,
    jacobian: bool = False,
) -> OscillatorFit:
    """Fits the oscillator to a record by output error: the model simulated from ``F``
    alone, never from the measured y.

    Minimises Σ wₖ·(yₖ − ŷₖ)² over m, c, k, α, γ, δ, ν and the initial state (y0, v0, z0),
    within the admissible region (γ ≥ 0 and γ − δ ≥ 0, the unknowns γ and γ − δ bounded
    below by 0: :func:`check_admissible`), by Levenberg–Marquardt
    (:func:`boucwen.levenberg.levenberg_marquardt`, stopped where the remaining step is
    within a tenth of a standard error) on the exact Jacobian from the core's dual pass.
    **β is not identified**: it appears only in the products β·γ and β·δ, so it stays at
    its start value and γ, δ carry the loop's shape.

    Starts: without ``start``, the candidates of :func:`_candidates` (the linear part from
    the record's frequency response, the hysteresis on a physically scaled grid, β =
    1/(2·std y)) are scored by one simulation each on the first 8192 samples, and the
    best is refined (the whole record where those samples all have weight 0); with
    ``start``, that model alone (a refit, e.g. of another fold).
    Internally the unknowns are scaled by their start values; inputs and outputs are in
    N, m and s.

    Args:
        F: force [N], one sample per ``dt``.
        y: measured displacement [m], same length.
        dt: sampling interval [s].
        start: the model to start from (its β is kept; in the admissible region); None
            for the data-driven starts.
        weights: per-sample weights (0 or 1: a 0 leaves the sample out of the cost, e.g.
            a held-out block); None for all ones.
        max_nfev: most trial points of the solver.
        progress: True prints progress lines to stderr; a callable receives them.
        jacobian: keep ∂y/∂θ at the end point in the result.

    Returns:
        :class:`OscillatorFit`.

    Raises:
        InvalidRecord: F or y empty, of different lengths, or with a non-finite sample;
            weights of another length, negative, non-finite, or all zero.
        InvalidConfig: dt not finite and > 0; max_nfev < 1.
        InvalidParams: a ``start`` outside the admissible region.
    """
    started = time.perf_counter()
    say = reporter(progress, "oscillator.fit", started)
    force = as_float_vector(F, "F")
    meas = as_float_vector(y, "y")
    if force.size != meas.size:
        raise InvalidRecord(f"F and y must have the same length, got {force.size} and {meas.size}")
    dt = check_dt(dt)
    max_nfev = check_int("max_nfev", max_nfev, 1)
    if weights is None:
        w = np.ones(force.size)
    else:
        w = as_float_vector(weights, "weights")
        if w.size != force.size:
            raise InvalidRecord(f"weights must have one value per sample ({force.size}), got {w.size}")
        if np.any(w < 0.0) or not np.any(w > 0.0):
            raise InvalidRecord("weights must be >= 0 with at least one > 0")
    kept = w > 0.0
    nfev = 0
    if start is not None:
        check_admissible(start)

    if start is None:
        # The first 8192 samples, or the whole record where those are all left out.
        n_score = min(_SCORE_LEN, force.size) if np.any(kept[:_SCORE_LEN]) else force.size
        candidates = _candidates(force[kept], meas[kept], dt)
        best, best_cost = candidates[0], math.inf
        for cand in candidates:
            r = w[:n_score] * (oscillator_simulate(cand.to_list(), force[:n_score], dt) - meas[:n_score])
            nfev += 1
            cost = float(r @ r)
            if math.isfinite(cost) and cost < best_cost:
                best, best_cost = cand, cost
        say(f"{len(candidates)} starts scored on {n_score} samples; best RMS {math.sqrt(best_cost / n_score):.3e} m")
        start = best
    beta = start.beta
    box = _box(start, (0.0, 0.0, 0.0), meas[kept], dt)
    z0, lower, upper, x_scale = box.z, box.lower, box.upper, box.scale
    amplitude = float(np.std(meas[kept])) or 1.0

    def run(z: FloatArray) -> FloatArray | None:
        try:
            out: FloatArray = oscillator_simulate(_params(z, beta).to_list(), force, dt, *(float(v) for v in z[7:]))
        except ValueError:
            return None
        return out

    def residual(z: FloatArray) -> FloatArray:
        nonlocal nfev
        nfev += 1
        sim = run(z)
        if sim is None or not np.all(np.isfinite(sim)):
            return np.full(force.size, 1e3 * amplitude)
        out: FloatArray = w * (sim - meas)
        return out

    def linearise(z: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        nonlocal nfev
        nfev += 1
        try:
            sim, jac = oscillator_simulate_with_jacobian(
                _params(z, beta).to_list(), force, dt, *(float(v) for v in z[7:])
            )
        except ValueError:
            return None
        if not (np.all(np.isfinite(sim)) and np.all(np.isfinite(jac))):
            return None
        say(f"pass {nfev}: RMS {rms((sim - meas)[kept]):.4e} m")
        jac[:, 4:6] = jac[:, 4:6] @ _REGION_JACOBIAN
        return w * (sim - meas), w[:, None] * jac

    sol = levenberg_marquardt(
        residual, linearise, z0, lower, upper, x_scale=x_scale, tol=1e-10, max_nfev=max_nfev, reuse_jacobian=True
    )
    params = _params(sol.x, beta)
    state = tuple(float(v) for v in sol.x[7:])
    y_fit = simulate(params, force, dt, *state)
    err = rms((y_fit - meas)[kept])
    jac = None
    if jacobian:
        jac = oscillator_simulate_with_jacobian(params.to_list(), force, dt, *state)[1]
    seconds = time.perf_counter() - started
    say(f"done: RMS {err:.4e} m, {nfev} simulations, {sol.message}")
    return OscillatorFit(
        params=params,
        y0=state[0],
        v0=state[1],
        z0=state[2],
        y=y_fit,
        rms=err,
        nfev=nfev,
        success=bool(sol.success) and math.isfinite(err),
        message=sol.message,
        seconds=seconds,
        jacobian=jac,
    )
