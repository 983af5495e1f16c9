"""Fitting the base model together with its effects by output error.

:func:`fit_extended` minimises Σ (x_k − x̂_k)² over a record, where x̂ is *simulated*
from u alone with :func:`boucwen.simulate_extended`, by ``scipy.optimize.least_squares``
(trust-region reflective: method ``"trf"`` of :meth:`boucwen.lsq.OutputErrorProblem.solve`)
— the same approach as :func:`boucwen.fit` for the base model (whose result is the
usual starting point here).

Unknowns, in this order (see :class:`Layout`): the base model's kv [µm/V], x0 [µm], A,
β + γ, β − γ, n, δ (units of :class:`boucwen.Params`) and the initial hysteresis state
h0 [µm]; then, for each effect present in signal-chain order, the unknowns its class
declares (:meth:`~boucwen.effects.Effect.unknowns`: the creep gains, ln fc, ln fn and
ln ζ, the drift rate; the creep time constants and the delay are held fixed), with
their bounds, typical sizes and sign constraints. β + γ and β − γ are bounded below by
0: a fit cannot leave the admissible region, where h stays bounded
(:mod:`boucwen.region`), and a start outside it is refused (:class:`boucwen.InvalidParams`);
on a record (:meth:`Layout.for_record`) |δ| is kept within the limit of
:func:`boucwen.fit.record_delta_limit`, as in :func:`boucwen.fit`.

Residual, Jacobian (exact, from the Rust core in one pass with the simulation:
:func:`boucwen._core.simulate_extended_with_jacobian`, whose columns are these unknowns
in this order) and optimiser are those of :mod:`boucwen.lsq`, shared with
:func:`boucwen.fit`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._core import EffectSet, Params, simulate_extended, simulate_extended_with_jacobian
from ..checks import FloatArray
from ..fit import N_BOUNDS, record_delta_limit
from ..levenberg import STATISTICAL_MARGIN
from ..lsq import Method, OutputErrorProblem, with_jacobian_or_none
from ..metrics import max_abs, rms
from ..record import Record, validate_record
from ..region import PAIR_NAMES, SPLIT_JACOBIAN, check, pair, split
from .base import Context, Effect, Start, simulate_chain, with_effect
from .registry import effect_class, effect_set, effects_of

__all__ = [
    "Box",
    "ExtendedFit",
    "Layout",
    "Solved",
    "candidate_starts",
    "fit_box",
    "fit_extended",
    "fit_extended_record",
    "jacobian_extended",
    "solve_extended_record",
]

#: The base model's unknowns: the seven parameters, β and γ as β ± γ (the coordinates in
#: which the admissible region is a box), and h0.
_BASE = ("kv", "x0", "A", *PAIR_NAMES, "n", "delta", "h0")
#: Where β ± γ sit in the vector of unknowns (and β, γ in the core's Jacobian).
_PAIR = slice(3, 5)


@dataclass(frozen=True)
class Layout:
    """Which unknowns a fit has: the base model's, then those each effect present
    declares, in signal-chain order.

    Attributes:
        effects: the effects present (signal-chain order); their parameters that are
            not unknowns (creep τ_i, delay) stay as they are here.
        dt: sampling interval [s].
        duration_s: record length [s].
        delta_limit: the largest |δ| [µm/(V·s)] of a fit on the record
            (:func:`boucwen.fit.record_delta_limit`; inf: no limit).
    """

    effects: tuple[Effect, ...]
    dt: float
    duration_s: float
    delta_limit: float = math.inf

    @classmethod
    def of(cls, effects: EffectSet, dt: float, duration_s: float) -> Layout:
        return cls(effects=effects_of(effects), dt=float(dt), duration_s=float(duration_s))

    @classmethod
    def for_record(cls, effects: EffectSet, record: Record) -> Layout:
        """The layout of a fit of ``effects`` on ``record``, δ within its limit there."""
        dt = record.dt
        return cls(effects_of(effects), float(dt), dt * max(len(record) - 1, 1), record_delta_limit(record))

    @property
    def names(self) -> tuple[str, ...]:
        """Effect names present (vocabulary order)."""
        return tuple(e.name for e in self.effects)

    @property
    def context(self) -> Context:
        return Context(dt=self.dt, duration_s=self.duration_s)

    def labels(self) -> list[str]:
        """Name of every unknown, in vector order."""
        return [*_BASE, *(f"{e.name}.{u}" for e in self.effects for u in e.unknowns())]

    def pack(self, params: Params, effects: EffectSet, h0: float) -> FloatArray:
        """(params, effects, h0) → vector of unknowns."""
        present = effects_of(effects)
        if tuple(e.name for e in present) != self.names:
            raise ValueError(f"the layout is for the effects {list(self.names)}, got {effects.names}")
        v = [*list(params.to_array()), float(h0)]
        v[_PAIR] = pair(params.beta, params.gamma)
        for e in present:
            v += e.pack()
        return np.asarray(v, dtype=np.float64)

    def unpack(self, v: FloatArray) -> tuple[Params, EffectSet, float]:
        """Vector of unknowns → (params, effects, h0); ValueError if invalid."""
        base = np.array(v[:7], dtype=np.float64)
        base[_PAIR] = split(float(v[3]), float(v[4]))
        params = Params.from_array(base)
        h0 = float(v[7])
        i = len(_BASE)
        fitted = []
        for e in self.effects:
            k = len(e.unknowns())
            fitted.append(e.unpack(v[i : i + k].tolist()))
            i += k
        return params, effect_set(*fitted), h0

    def simulate(self, v: FloatArray, u: FloatArray, dt: float) -> FloatArray | None:
        """x [µm] of the extended model with the unknowns ``v`` over the voltage ``u``
        [V] sampled every ``dt`` [s]; None when ``v`` is invalid or cannot be simulated."""
        try:
            p, e, h0 = self.unpack(v)
        except (ValueError, OverflowError):
            return None
        return simulate_chain(p, e, u, dt, h0)

    def simulate_with_jacobian(self, v: FloatArray, u: FloatArray, dt: float) -> tuple[FloatArray, FloatArray] | None:
        """:meth:`simulate` with ∂x/∂v (one row per sample, one column per unknown), from
        one pass; None when ``v`` is invalid or cannot be simulated."""
        try:
            p, e, h0 = self.unpack(v)
        except (ValueError, OverflowError):
            return None
        out = with_jacobian_or_none(lambda: simulate_extended_with_jacobian(p, e, u, dt, h0))
        if out is not None:
            # The core's columns ∂/∂β, ∂/∂γ → ∂/∂(β + γ), ∂/∂(β − γ).
            out[1][:, _PAIR] = out[1][:, _PAIR] @ SPLIT_JACOBIAN
        return out

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper bounds of the unknowns (β ± γ ≥ 0: the admissible region; |δ|
        within :attr:`delta_limit`)."""
        base = [(-np.inf, np.inf)] * len(_BASE)
        base[3] = base[4] = (0.0, np.inf)
        base[5] = N_BOUNDS
        base[6] = (-self.delta_limit, self.delta_limit)
        return _columns(base, [b for e in self.effects for b in e.bounds(self.context)])

    def sign_bounds(self, static_gain: float) -> tuple[FloatArray, FloatArray]:
        """Further bounds that only the optimiser sees, for a model of static gain
        ``static_gain`` [µm/V] (:func:`static_gain`)."""
        base = [(-np.inf, np.inf)] * len(_BASE)
        return _columns(base, [b for e in self.effects for b in e.sign_bounds(static_gain)])

    def typical(self, span_u: float, span_x: float) -> FloatArray:
        """Least typical size of each unknown for a record whose voltage spans
        ``span_u`` [V] and displacement ``span_x`` [µm]."""
        base = {
            "kv": span_x / span_u,
            "x0": span_x,
            "A": span_x / span_u,
            PAIR_NAMES[0]: 1e-3,
            PAIR_NAMES[1]: 1e-3,
            "n": 1.0,
            "delta": 1e-3,
            "h0": 0.01 * span_x,
        }
        floors = [base[name] for name in _BASE]
        floors += [f for e in self.effects for f in e.typical(self.context, span_u, span_x)]
        return np.asarray(floors, dtype=np.float64)


def static_gain(params: Params, effects: EffectSet) -> float:
    """kv plus the creep gains [µm/V]: the displacement per volt once creep has settled,
    whose sign is the actuator's. The sign bounds of a fit are taken from it rather
    than from kv, which a fit may move through zero while a fast creep element carries
    the gain: a refit from such a fit then starts inside its own bounds."""
    creep = effects.to_dict().get("creep")
    return params.kv + (float(sum(creep["gain_um_per_v"])) if creep else 0.0)


def _columns(base: list[tuple[float, float]], effects: list[tuple[float, float]]) -> tuple[FloatArray, FloatArray]:
    lo, hi = zip(*base, *effects)
    return np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class ExtendedFit:
    """Result of :func:`fit_extended`.

    Attributes:
        params: base :class:`boucwen.Params`.
        effects: the :class:`boucwen.EffectSet` with fitted parameters.
        h0: initial hysteresis state [µm].
        rms_um, max_um: output error over the fitted samples [µm].
        nfev: number of record simulations.
        success: the optimiser reported convergence.
    """

    params: Params
    effects: EffectSet
    h0: float
    rms_um: float
    max_um: float
    nfev: int
    success: bool

    def simulate(self, u: ArrayLike, dt: float) -> FloatArray:
        """x [µm] of the fitted model for the voltage ``u`` [V]."""
        return simulate_extended(self.params, self.effects, u, dt, self.h0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters: ``{"base": {...}, "h0_um": ..., <effect>: {...}}``."""
        out: dict[str, Any] = {"base": self.params.to_dict(), "h0_um": self.h0}
        out.update(self.effects.to_dict())
        return out


class _Chain:
    """Vector of unknowns → x [µm] of the extended model over one record (or None)."""

    def __init__(self, layout: Layout, u: FloatArray, dt: float):
        self.layout, self.u, self.dt = layout, u, dt

    def __call__(self, v: FloatArray) -> FloatArray | None:
        return self.layout.simulate(v, self.u, self.dt)

    def with_jacobian(self, v: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        return self.layout.simulate_with_jacobian(v, self.u, self.dt)


class _Weighted(_Chain):
    """:class:`_Chain` with each sample's output and Jacobian row scaled by its weight."""

    def __init__(self, layout: Layout, u: FloatArray, dt: float, weights: FloatArray):
        super().__init__(layout, u, dt)
        self.weights = weights

    def __call__(self, v: FloatArray) -> FloatArray | None:
        xs = super().__call__(v)
        return None if xs is None else xs * self.weights

    def with_jacobian(self, v: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        out = super().with_jacobian(v)
        return None if out is None else (out[0] * self.weights, out[1] * self.weights[:, None])


def _typical(layout: Layout, v0: FloatArray, u: FloatArray, x: FloatArray) -> FloatArray:
    """Typical size of each unknown (the optimiser's scaling)."""
    span_u = max(float(np.ptp(u)), 1e-12)
    span_x = max(float(np.ptp(x)), 1e-12)
    return np.maximum(np.abs(v0), layout.typical(span_u, span_x))


def fit_extended(
    u: Any,
    x: Any,
    dt: float,
    params: Params,
    effects: EffectSet,
    h0: float = 0.0,
    *,
    max_nfev: int = 100,
    tol: float = 1e-10,
    method: Method = "lm",
    margin: float = STATISTICAL_MARGIN,
) -> ExtendedFit:
    """Fits the base parameters, h0 and the effects' parameters by output error.

    Args:
        u: voltage [V] (1-D, finite); x: measured displacement [µm], same length.
        dt: sampling interval [s].
        params, effects, h0: starting point (``params`` in the admissible region);
            ``effects`` also fixes which effects are present, the creep time constants
            and the delay (see the module docs).
        max_nfev: most trial points (a fit stopped there has ``success`` False).
        tol: relative change of the cost or of the unknowns that stops (``"lm"``), or
            ``xtol``/``ftol``/``gtol`` (``"trf"``).
        method: ``"lm"`` (Levenberg–Marquardt, :mod:`boucwen.levenberg`) or ``"trf"``.
        margin: the statistical stop of ``"lm"``: the remaining step at most √margin
            standard errors of the unknowns.

    Returns:
        An :class:`ExtendedFit` (errors over the given record).

    Raises:
        ValueError: invalid data or a starting point that cannot be simulated;
            :class:`boucwen.InvalidParams` for a start outside the admissible region.
    """
    record = validate_record(u, x, dt)
    return fit_extended_record(record, params, effects, h0, max_nfev=max_nfev, tol=tol, method=method, margin=margin)


@dataclass(frozen=True, eq=False)
class Solved:
    """A fit with what its optimiser computed last, at the solution.

    Attributes:
        fit: the :class:`ExtendedFit`.
        x: its simulated displacement over the fitted record [µm].
        jacobian: ∂x̂/∂z there (one row per sample, one column per unknown of the fit's
            :class:`Layout`, as :func:`jacobian_extended`).
    """

    fit: ExtendedFit
    x: FloatArray
    jacobian: FloatArray


def fit_extended_record(
    record: Record,
    params: Params,
    effects: EffectSet,
    h0: float = 0.0,
    *,
    max_nfev: int = 100,
    tol: float = 1e-10,
    method: Method = "lm",
    margin: float = STATISTICAL_MARGIN,
) -> ExtendedFit:
    """:func:`fit_extended` on a checked :class:`~boucwen.record.Record`."""
    return solve_extended_record(
        record, params, effects, h0, max_nfev=max_nfev, tol=tol, method=method, margin=margin
    ).fit


@dataclass(frozen=True, eq=False)
class Box:
    """Where a fit of a record starts and may go: its :class:`Layout`, the start ``v0``,
    the bounds ``lower`` ≤ v ≤ ``upper`` (the layout's, narrowed by the sign the
    model's static gain gives: :meth:`Layout.sign_bounds`) with ``v0`` just inside them,
    and the optimiser's scale of each unknown (``scale``)."""

    layout: Layout
    v0: FloatArray
    lower: FloatArray
    upper: FloatArray
    scale: FloatArray

    def directions(
        self, effects: tuple[str, ...], x_start: FloatArray, u: FloatArray, dt: float, share: float = 1e-3
    ) -> list[FloatArray]:
        """∂x̂/∂v at the start ``v0`` (where the model predicts ``x_start`` [µm] from ``u``
        [V]) along each unknown of the named ``effects``: a forward difference of ``share``
        of its typical size (backward where the step would leave its upper bound), one
        simulation each; the unknowns whose step cannot be simulated are left out."""
        v = self.v0
        out: list[FloatArray] = []
        for i, label in enumerate(self.layout.labels()):
            if label.split(".", 1)[0] not in effects:
                continue
            h = share * float(self.scale[i])
            moved = v.copy()
            moved[i] = v[i] + h if v[i] + h <= self.upper[i] else v[i] - h
            x2 = self.layout.simulate(moved, u, dt)
            if x2 is not None:
                out.append((x2 - x_start) / (moved[i] - v[i]))
        return out


def fit_box(record: Record, params: Params, effects: EffectSet, h0: float) -> Box:
    """The :class:`Box` of a fit of ``record`` started at (params, effects, h0)."""
    u, x = record.u, record.x
    layout = Layout.for_record(effects, record)
    v0 = layout.pack(params, effects, h0)
    lo, hi = layout.bounds()
    sign_lo, sign_hi = layout.sign_bounds(static_gain(params, effects))
    lo, hi = np.maximum(lo, sign_lo), np.minimum(hi, sign_hi)
    inside = 1e-9 * (1.0 + np.abs(np.where(np.isfinite(lo), lo, 0.0)))
    v0 = np.clip(v0, lo + inside, hi - inside)
    return Box(layout, v0, lo, hi, _typical(layout, v0, u, x))


def solve_extended_record(
    record: Record,
    params: Params,
    effects: EffectSet,
    h0: float = 0.0,
    *,
    max_nfev: int = 100,
    tol: float = 1e-10,
    method: Method = "lm",
    margin: float = STATISTICAL_MARGIN,
    weights: FloatArray | None = None,
    reuse_jacobian: bool = False,
    fit_until: int | None = None,
    start: tuple[FloatArray, FloatArray] | None = None,
) -> Solved:
    """:func:`fit_extended_record` with the fit's simulated displacement and the
    optimiser's Jacobian at the solution, for the callers that score the fit.
    ``weights`` (one per sample, 0 or 1) leaves samples out of the cost (a refit without
    a block of the record: the model still runs through them); the errors of the
    result are over every sample.
    ``reuse_jacobian``: keep a Jacobian while it predicts the steps (``"lm"``; a start
    near the optimum: :func:`boucwen.levenberg.levenberg_marquardt`).
    ``fit_until``: fit the samples before this index alone (the model simulated only that
    far while it is fitted; the bounds and scales are the whole record's), a refit on
    the record's past; ``start``: the residual x − x̂ and the Jacobian ∂x̂/∂v at the start
    over those samples, where the caller has them (``"lm"``: the first linearisation is
    not computed again)."""
    check(params)
    box = fit_box(record, params, effects, h0)
    layout, v0, lo, hi = box.layout, box.v0, box.lower, box.upper
    stop = len(record) if fit_until is None else int(fit_until)
    u, x, dt = record.u[:stop], record.x[:stop], record.dt
    chain: _Chain = _Chain(layout, u, dt) if weights is None else _Weighted(layout, u, dt, weights[:stop])
    prob = OutputErrorProblem(chain, chain.with_jacobian, x if weights is None else x * weights[:stop])
    if prob.simulate(v0) is None:
        raise ValueError("the starting point of fit_extended cannot be simulated")
    first = None if start is None else (-start[0][:stop], start[1][:stop])
    res = prob.solve(
        v0,
        lo,
        hi,
        x_scale=box.scale,
        tol=tol,
        max_nfev=max_nfev,
        method=method,
        margin=margin,
        reuse_jacobian=reuse_jacobian,
        start=first,
    )
    p, e, h = layout.unpack(res.x)
    xs = simulate_chain(p, e, record.u, dt, h)
    if xs is None:  # pragma: no cover - the optimiser never accepts a failing point
        raise ValueError("the fitted parameters cannot be simulated")
    err = record.x - xs
    fit = ExtendedFit(
        params=p,
        effects=e,
        h0=h,
        rms_um=rms(err),
        max_um=max_abs(err),
        nfev=prob.simulations,
        success=bool(res.success),
    )
    return Solved(fit=fit, x=xs, jacobian=np.asarray(res.jac, dtype=np.float64))


def jacobian_extended(record: Record, fitted: ExtendedFit) -> FloatArray:
    """∂x̂/∂z of the extended model ``fitted`` over ``record`` (one row per sample, one
    column per unknown of its :class:`Layout`; zeros if it cannot be simulated)."""
    u, dt = record.u, record.dt
    layout = Layout.of(fitted.effects, dt, dt * max(u.size - 1, 1))
    z = layout.pack(fitted.params, fitted.effects, fitted.h0)
    out = layout.simulate_with_jacobian(z, u, dt)
    return out[1] if out is not None else np.zeros((u.size, z.size))


def candidate_starts(
    name: str,
    record: Record,
    params: Params,
    effects: EffectSet,
    h0: float,
    *,
    max_delay: int = 8,
    creep_tau_s: Sequence[float] | None = None,
) -> list[EffectSet]:
    """Starting effect sets that add ``name`` to ``effects`` (a few for the nonlinear ones)."""
    at = Start(record, params, effects, h0, max_delay, None if creep_tau_s is None else tuple(creep_tau_s))
    return [with_effect(effects, start) for start in effect_class(name).starts(at)]
