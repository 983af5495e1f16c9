"""Converged fits of the models the judge compares, and their held-out errors.

Every model a decision reads is fitted to convergence (:class:`Convergence`: the
offline fit's Levenberg–Marquardt on the core's exact Jacobian, stopped where the
remaining step is a tenth of the unknowns' standard error), never stopped by an
evaluation budget: the budget of :data:`MAX_NFEV` trial points only bounds a fit that
cannot converge, and such a fit is marked (``converged`` False) and never accepted.

A candidate adds effects to the current model from their physical starting values
(:meth:`boucwen.effects.Effect.starts`: a creep's time constants from the record's
length, a mode at the residual's spectral peak, each whole-sample delay, …). Where an
effect lists several starts (its cost has local optima: a mode's frequency, a lag's
corner, a delay), they are ranked by the first-order refit of the current model (one
simulation each: what a start leaves once the current unknowns are refitted along their
Jacobian) and the best :data:`STARTS` are each converged; the fit of least cost is the
candidate. A drop refits the model without the effect from where it is.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from functools import cached_property
from typing import Any, Literal

import numpy as np

from .._core import EffectSet
from ..boundedness import check_model
from ..checks import FloatArray
from ..effects import (
    ExtendedFit,
    Layout,
    Solved,
    candidate_starts,
    effect_class,
    effects_of,
    simulate_chain,
    solve_extended_record,
)
from ..effects.base import without
from ..fit import FitResult
from ..levenberg import STATISTICAL_MARGIN
from ..metrics import rms
from ..oscillator import UNKNOWNS as OSCILLATOR_UNKNOWNS
from ..oscillator import OscillatorFit
from ..oscillator import fit as fit_oscillator
from ..record import Record
from .judge import CrossValidation, fold_slices

__all__ = [
    "FOLD_NFEV",
    "MAX_NFEV",
    "STARTS",
    "AtBound",
    "Convergence",
    "Scored",
    "Structure",
    "add",
    "base",
    "drop",
    "held_out",
    "on_bounds",
    "oscillator",
    "refit",
    "scored",
    "solved_at",
]

#: Starts converged per candidate where its effect lists several (its cost has local
#: optima); the best by the first-order refit, then the runner-up, which covers the
#: case where the current fit has bent itself to imitate the effect.
STARTS = 2
#: Trial points that bound a fit which does not converge (marked, never accepted).
MAX_NFEV = 150
#: Trial points of a block's refit (from the whole-record fit, a few steps away when the
#: rest of the record determines the model); one that has not converged by then runs
#: off along a direction only the held-out block determined, and its block is left out of
#: every comparison (:mod:`~boucwen.diagnosis.judge`).
FOLD_NFEV = 60


@dataclass(frozen=True)
class AtBound:
    """An unknown of a fit that ended on a bound of the fit.

    Attributes:
        parameter: its name (:meth:`boucwen.effects.Layout.labels`, e.g. ``"creep.g1"``).
        value: its value, in its unit.
        bound: the bound it is on, same unit.
        side: ``"lower"`` or ``"upper"``.
    """

    parameter: str
    value: float
    bound: float
    side: str

    def to_dict(self) -> dict[str, Any]:
        """``{"parameter", "value", "bound", "side"}`` (JSON-ready)."""
        return asdict(self)


@dataclass(frozen=True)
class Convergence:
    """How the fits are converged.

    Attributes:
        method: ``"lm"`` (:mod:`boucwen.levenberg`, the default) or ``"trf"`` (SciPy's
            trust-region reflective method) for the fits of the models compared (the
            judge's block refits are always ``"lm"``: :func:`held_out`).
        margin: the statistical stop of ``"lm"``: remaining step ≤ √margin standard
            errors.
        tol: relative change of the cost or the unknowns that stops either method.
    """

    method: Literal["lm", "trf"] = "lm"
    margin: float = STATISTICAL_MARGIN
    tol: float = 1e-10

    def tighter(self, factor: float = 10.0) -> Convergence:
        """The same solver with its stopping tolerances ``factor`` times tighter."""
        return replace(self, margin=self.margin / factor, tol=self.tol / factor)


@dataclass(frozen=True, eq=False)
class Scored:
    """A converged fit and its held-out error.

    Attributes:
        fit: the fit (:class:`boucwen.effects.ExtendedFit`).
        x: its simulated displacement over the record [µm].
        jacobian: ∂x̂/∂z there (one row per sample, one column per unknown).
        cv: its blocked cross-validation.
        converged: the whole-record fit stopped by its tolerance, not by
            :data:`MAX_NFEV` (its blocks' refits: ``cv.converged``).
    """

    fit: ExtendedFit
    x: FloatArray
    jacobian: FloatArray
    cv: CrossValidation
    converged: bool

    @property
    def names(self) -> tuple[str, ...]:
        """The model's effects, in the vocabulary's order."""
        return tuple(self.fit.effects.names)

    @property
    def unknowns(self) -> int:
        return int(self.jacobian.shape[1])

    @cached_property
    def refit_basis(self) -> FloatArray:
        """An orthonormal basis of the span of the Jacobian's columns (scaled to unit
        norm): the first-order refit of the model's unknowns, computed once per model
        and shared by every start ranked from it."""
        norms = np.linalg.norm(self.jacobian, axis=0)
        keep = norms > 0
        q, _ = np.linalg.qr(self.jacobian[:, keep] / norms[keep])
        return np.asarray(q, dtype=np.float64)


def _layout(record: Record, effects: EffectSet) -> Layout:
    return Layout.for_record(effects, record)


def _converge(record: Record, fit: ExtendedFit, effects: EffectSet, conv: Convergence) -> Solved:
    return solve_extended_record(
        record, fit.params, effects, fit.h0, max_nfev=MAX_NFEV, tol=conv.tol, method=conv.method, margin=conv.margin
    )


def held_out(record: Record, solved: Solved, folds: int, conv: Convergence) -> CrossValidation:
    """The held-out residual [µm] of the fit ``solved``: each block's from the model
    refitted without it (from the whole-record fit, at most
    :data:`FOLD_NFEV` trial points; it starts a few steps from its optimum, so a Jacobian
    is kept while it predicts the steps), with which refits converged. The refits are
    the judge's measurement and always run Levenberg–Marquardt to ``conv``'s statistical
    stop, whatever solver fits the models: along a direction the rest of the record
    hardly determines, where a refit stops is set by its stopping rule, and the
    statistical stop is the one that stops where the record no longer resolves a step."""
    fr = solved.fit
    n = len(record)
    held = np.empty(n)
    converged = []
    for sl in fold_slices(n, folds):
        weights = np.ones(n)
        weights[sl] = 0.0
        refitted = solve_extended_record(
            record,
            fr.params,
            fr.effects,
            fr.h0,
            max_nfev=FOLD_NFEV,
            tol=conv.tol,
            method="lm",
            margin=conv.margin,
            weights=weights,
            reuse_jacobian=True,
        )
        held[sl] = record.x[sl] - refitted.x[sl]
        converged.append(refitted.fit.success)
    return CrossValidation.of(held, record.x - solved.x, folds, tuple(converged))


def scored(record: Record, solved: Solved, folds: int, conv: Convergence) -> Scored:
    """A converged fit with its blocked cross-validation over ``folds`` blocks (each
    block's model refitted by ``conv`` without it: :mod:`~boucwen.diagnosis.judge`)."""
    return Scored(solved.fit, solved.x, solved.jacobian, held_out(record, solved, folds, conv), solved.fit.success)


def solved_at(record: Record, fit: ExtendedFit) -> Solved:
    """``fit`` with its simulated displacement and Jacobian over ``record``."""
    out = _layout(record, fit.effects).simulate_with_jacobian(
        _layout(record, fit.effects).pack(fit.params, fit.effects, fit.h0), record.u, record.dt
    )
    if out is None:  # pragma: no cover - a fitted model can be simulated
        raise ValueError("the fitted model cannot be simulated")
    return Solved(fit=fit, x=out[0], jacobian=out[1])


def base(record: Record, offline: FitResult, conv: Convergence, folds: int) -> Scored:
    """The base model: the offline fit (:func:`boucwen.fit`, its global search of
    starts) converged by ``conv`` and scored."""
    start = ExtendedFit(offline.params, EffectSet(), offline.h0, offline.rms_um, offline.max_um, offline.nfev, True)
    return scored(record, _converge(record, start, EffectSet(), conv), folds, conv)


def _first_order(record: Record, current: Scored, effects: EffectSet) -> float:
    """RMS [µm] left by the current model with ``effects`` once its unknowns are refitted
    to first order along their Jacobian (∞ where it cannot be simulated)."""
    xs = simulate_chain(current.fit.params, effects, record.u, record.dt, current.fit.h0)
    if xs is None:
        return math.inf
    q = current.refit_basis
    r = record.x - xs
    return rms(r - q @ (q.T @ r))


def _starts(record: Record, current: Scored, names: tuple[str, ...], max_delay: int) -> list[EffectSet]:
    """Starting effect sets adding ``names`` to the current model: the starts of the
    last (a tied effect after its partner, from the partner's starts)."""
    fit = current.fit
    *partners, name = names
    cls = effect_class(name)
    if partners:
        first = candidate_starts(partners[0], record, fit.params, fit.effects, fit.h0, max_delay=max_delay)
        return [cls.beside(s) for s in first]
    return candidate_starts(name, record, fit.params, fit.effects, fit.h0, max_delay=max_delay)


def add(
    record: Record,
    current: Scored,
    names: tuple[str, ...],
    conv: Convergence,
    folds: int,
    max_delay: int,
    *,
    dropped: str | None = None,
) -> Scored | str:
    """The current model with ``names`` added (after ``dropped`` is taken out: a swap),
    converged from the best :data:`STARTS` starts (module docs) and scored; or why there
    is no such candidate (no start can be simulated, or the fitted effect is not what its
    name says: :meth:`boucwen.effects.Effect.rejects`)."""
    origin = current
    if dropped is not None:
        out = drop(record, current, dropped, conv, folds)
        if isinstance(out, str):
            return out
        origin = out
    starts = _starts(record, origin, names, max_delay)
    if len(starts) > STARTS:
        costs = [_first_order(record, origin, s) for s in starts]
        order = sorted(range(len(starts)), key=lambda k: (costs[k], k))
        starts = [starts[k] for k in order[:STARTS] if math.isfinite(costs[k])]
    best: Solved | None = None
    for s in starts:
        try:
            solved = _converge(record, origin.fit, s, conv)
        except ValueError:
            continue
        if best is None or solved.fit.rms_um < best.fit.rms_um:
            best = solved
    if best is None:
        return "no start can be simulated"
    return _valid(record, best, folds, conv)


def _valid(record: Record, solved: Solved, folds: int, conv: Convergence) -> Scored | str:
    """The candidate ``solved`` scored, or why it is none: an effect whose fitted values
    make it something other than its name says (:meth:`boucwen.effects.Effect.rejects`:
    a resonance without a peak), or a model that the fit kept inside the admissible
    region but that leaves the record's range on inputs within its limits
    (:func:`boucwen.boundedness.check_model`)."""
    for effect in effects_of(solved.fit.effects):
        why = effect.rejects()
        if why is not None:
            return why
    fit = solved.fit
    bounded = check_model(record, fit.params, fit.effects, fit.h0)
    if not bounded.passed:
        return f"the fitted model is not bounded over the record's range: {bounded.summary()}"
    return scored(record, solved, folds, conv)


def refit(record: Record, fit: ExtendedFit, effects: EffectSet, conv: Convergence) -> ExtendedFit | None:
    """``fit`` with ``effects`` in place of its own, converged on ``record`` (None where
    it cannot be simulated)."""
    try:
        return _converge(record, fit, effects, conv).fit
    except ValueError:
        return None


@dataclass(frozen=True, eq=False)
class Structure:
    """A model of the other structure, converged and scored: the hysteretic oscillator
    (:mod:`boucwen.oscillator`: a mass on a spring and damper whose Bouc–Wen restoring
    force is driven by its own motion, the input a force), fitted to the record with its
    input as the force and its displacement in m.

    Attributes:
        name: ``"oscillator"``.
        fit: the fit over the whole record (:class:`boucwen.oscillator.OscillatorFit`).
        x: its displacement over the record [µm].
        cv: its blocked cross-validation (each block from the oscillator refitted without
            it, from the whole-record fit).
        converged: the whole-record fit converged.
        unknowns: its number of unknowns.
    """

    name: str
    fit: OscillatorFit
    x: FloatArray
    cv: CrossValidation
    converged: bool
    unknowns: int

    @property
    def names(self) -> tuple[str, ...]:
        return (self.name,)


def oscillator(record: Record, folds: int) -> Structure | str:
    """The hysteretic oscillator fitted to ``record`` (u as the force [N], x [µm] as the
    displacement, in m for the fit) and scored like every model the judge compares; or
    why there is none (the fit cannot run on the record)."""
    n = len(record)
    y = record.x * 1e-6
    try:
        whole = fit_oscillator(record.u, y, record.dt)
    except ValueError as exc:
        return f"the oscillator cannot be fitted: {exc}"
    held = record.x - whole.y * 1e6
    converged = []
    for sl in fold_slices(n, folds):
        weights = np.ones(n)
        weights[sl] = 0.0
        try:
            refitted = fit_oscillator(record.u, y, record.dt, start=whole.params, weights=weights, max_nfev=FOLD_NFEV)
        except ValueError:
            converged.append(False)
            continue
        held[sl] = record.x[sl] - refitted.y[sl] * 1e6
        converged.append(refitted.success)
    x = whole.y * 1e6
    cv = CrossValidation.of(held, record.x - x, folds, tuple(converged))
    return Structure("oscillator", whole, x, cv, whole.success, len(OSCILLATOR_UNKNOWNS))


def on_bounds(fit: ExtendedFit, record: Record, tolerance: float) -> list[AtBound]:
    """The unknowns of ``fit`` that ended on a bound of the fit over ``record`` (within
    ``tolerance`` of its size, at least 1)."""
    layout = _layout(record, fit.effects)
    z = layout.pack(fit.params, fit.effects, fit.h0)
    lo, hi = layout.bounds()
    out: list[AtBound] = []
    for label, v, a, b in zip(layout.labels(), z, lo, hi):
        for bound, side in ((a, "lower"), (b, "upper")):
            if math.isfinite(bound) and abs(v - bound) <= tolerance * max(1.0, abs(bound)):
                out.append(AtBound(label, float(v), float(bound), side))
    return out


def drop(record: Record, current: Scored, name: str, conv: Convergence, folds: int) -> Scored | str:
    """The current model without ``name``, refitted from where it is and scored."""
    try:
        solved = _converge(record, current.fit, without(current.fit.effects, name), conv)
    except ValueError as exc:
        return str(exc)
    return _valid(record, solved, folds, conv)
