"""Converged fits of the models the judge compares, and their held-out errors.

Every model a decision reads is fitted to convergence (:class:`Convergence`: the
offline fit's Levenberg–Marquardt on the core's exact Jacobian, stopped where the
remaining step is a tenth of the unknowns' standard error), never stopped by an
evaluation budget: the budget of :data:`MAX_NFEV` trial points only bounds a fit that
cannot converge, and such a fit is marked (``converged`` False) and never accepted.

A candidate adds effects to the current model from their physical starting values
(:meth:`boucwen.effects.Effect.starts`: a creep's time constants from the record's
length, a mode at the residual's spectral peak, each whole-sample delay, …) and, where
the search fitted the same effect beside another model before, from the values it took
there (a warm start). Where there are several starts (the cost has local optima: a
mode's frequency, a lag's corner, a delay), they are ranked by short fits on a copy of
the record at a few kHz (:func:`_ranked`) and the best :data:`STARTS` are each converged
on the record; the fit of least cost is the candidate. A drop refits the model without the effect from
where it is.

Their held-out errors come from :mod:`~boucwen.diagnosis.heldout`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
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
    fit_box,
    simulate_chain,
    solve_extended_record,
)
from ..effects.base import with_effect, without
from ..fit import FitResult
from ..levenberg import STATISTICAL_MARGIN
from ..metrics import rms
from ..oscillator import UNKNOWNS as OSCILLATOR_UNKNOWNS
from ..oscillator import OscillatorFit, linearised
from ..oscillator import fit as fit_oscillator
from ..oscillator import simulate as simulate_oscillator
from ..record import Record
from ..region import PAIR_NAMES, pair
from .heldout import CrossValidation, Folds, Leaveout, held_out

__all__ = [
    "BOUND_TOLERANCE",
    "FOLD_NFEV",
    "MAX_NFEV",
    "RANK_NFEV",
    "RANK_RATE_HZ",
    "RANK_SAMPLES",
    "RANK_SHORTLIST",
    "STARTS",
    "AtBound",
    "Convergence",
    "Leaveout",
    "Scored",
    "Structure",
    "add",
    "base",
    "confirmed",
    "drop",
    "held_out",
    "loop_on_bounds",
    "on_bounds",
    "oscillator",
    "refit",
    "scored",
    "solved_at",
    "starts_of",
    "swap",
]

#: Starts converged per candidate where it has several (its cost has local optima); the
#: best by the first-order refit, then the runner-up, which covers the case where the
#: current fit has bent itself to imitate the effect.
STARTS = 2
#: Trial points that bound a fit which does not converge (marked, never accepted).
MAX_NFEV = 150
#: The rate [Hz] of the copy on which a candidate's starts are ranked (every q-th
#: sample; the record itself where it is sampled slower): the screened copy's.
RANK_RATE_HZ = 2500.0
#: Most samples of that copy: a longer one is cut to its window of most voltage travel.
RANK_SAMPLES = 8192
#: Trial points of a start's ranking fit on that copy (enough to leave a start's
#: neighbourhood for its basin; it only ranks).
RANK_NFEV = 10
#: Starts fitted for the ranking, the best by the first-order refit (a lag's whole grid
#: of corners; a mode's best frequencies and dampings of its 50).
RANK_SHORTLIST = 12
#: Trial points of a fold's refit (from the whole-record fit, a few steps away when the
#: past determines the model); one that has not converged by then runs off along a
#: direction only the future determined, and its fold is left out of every comparison
#: (:mod:`~boucwen.diagnosis.judge`).
FOLD_NFEV = 60
#: Relative difference of two RMS errors within rounding of the same fit.
_SAME = 1e-9
#: An added effect that changes the fit's prediction of the record by less than this
#: share of its residual RMS changes nothing the record holds.
_UNSEEN_SHARE = 1e-3


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
            judge's fold refits are always ``"lm"``: :func:`held_out`).
        margin: the statistical stop of ``"lm"``: remaining step ≤ √margin standard
            errors.
        tol: relative change of the cost or the unknowns that stops either method.
        screen: read a held-out error from the screen (the refits' first step) where a
            decision is far from its threshold (:mod:`~boucwen.diagnosis.search`);
            False reads every one from converged refits — the judge the screen must
            agree with, for checking it.
        score: fit only the add moves whose score at the current model passes
            (:mod:`~boucwen.diagnosis.score`); False fits every move (each still
            scored and reported beside its decision: how the score is checked).
    """

    method: Literal["lm", "trf"] = "lm"
    margin: float = STATISTICAL_MARGIN
    tol: float = 1e-10
    screen: bool = True
    score: bool = True

    def tighter(self, factor: float = 10.0) -> Convergence:
        """The same solver with its stopping tolerances ``factor`` times tighter."""
        return replace(self, margin=self.margin / factor, tol=self.tol / factor)


#: The grid the model's own sampling-rate error is measured against: twice as fine as
#: the record (the difference has converged there: on the suite's clean records it is the
#: same, to 0.1 %, at 2, 4 and 8 times finer).
RESOLUTION_REFINEMENT = 2


def resolution(record: Record, fit: ExtendedFit) -> float:
    """The model's own error from stepping at the record's sampling interval [µm RMS]:
    ``fit`` run on the record's voltage and on a grid :data:`RESOLUTION_REFINEMENT` times
    finer (u a straight line between samples), compared at the samples. A device runs in
    continuous time; whatever the model's sampling changes in its output, a candidate can
    take up part of, on held-out data too, so a gain below this error's mean square is
    not evidence of an effect (:func:`boucwen.diagnosis.judge.judge`)."""
    from ..plant import simulate_oversampled  # deferred: boucwen.plant imports the effects

    try:
        coarse = simulate_oversampled(fit.params, fit.effects, record.u, record.dt, 1)
        fine = simulate_oversampled(fit.params, fit.effects, record.u, record.dt, RESOLUTION_REFINEMENT)
    except (ValueError, RuntimeError):
        return 0.0
    diff = np.asarray(fine) - np.asarray(coarse)
    return rms(diff) if np.all(np.isfinite(diff)) else 0.0


@dataclass(frozen=True, eq=False)
class Scored:
    """A converged fit of the input-driven model and its held-out error.

    Attributes:
        fit: the fit (:class:`boucwen.effects.ExtendedFit`).
        x: its simulated displacement over the record [µm].
        jacobian: ∂x̂/∂z there (one row per sample, one column per unknown).
        cv: its forward validation (the screen's or the refits': ``cv.exact``).
        converged: the whole-record fit stopped by its tolerance, not by
            :data:`MAX_NFEV` (its folds' refits: ``cv.converged``).
        leaveout: what its fold refits need (:class:`Leaveout`).
    """

    fit: ExtendedFit
    x: FloatArray
    jacobian: FloatArray
    cv: CrossValidation
    converged: bool
    leaveout: Leaveout

    @property
    def names(self) -> tuple[str, ...]:
        """The model's effects, in the vocabulary's order."""
        return tuple(self.fit.effects.names)

    @property
    def unknowns(self) -> int:
        return int(self.jacobian.shape[1])


def _layout(record: Record, effects: EffectSet) -> Layout:
    return Layout.for_record(effects, record)


def _converge(record: Record, fit: ExtendedFit, effects: EffectSet, conv: Convergence) -> Solved:
    """``fit`` with ``effects``, converged on ``record`` by ``conv`` (the Jacobian kept
    while it predicts the steps: one pass and a few simulations near the optimum)."""
    return solve_extended_record(
        record,
        fit.params,
        effects,
        fit.h0,
        max_nfev=MAX_NFEV,
        tol=conv.tol,
        method=conv.method,
        margin=conv.margin,
        reuse_jacobian=True,
    )


def _leaveout(record: Record, solved: Solved, conv: Convergence) -> Leaveout:
    """:class:`Leaveout` of an input-driven fit over ``record``."""
    fit = solved.fit
    box = fit_box(record, fit.params, fit.effects, fit.h0)
    layout = box.layout
    z = layout.pack(fit.params, fit.effects, fit.h0)
    r = record.x - solved.x

    def simulate(v: FloatArray, stop: int) -> FloatArray | None:
        return layout.simulate(v, record.u[:stop], record.dt)

    def refit(train: slice) -> tuple[FloatArray | None, bool]:
        try:
            out = solve_extended_record(
                record,
                fit.params,
                fit.effects,
                fit.h0,
                max_nfev=FOLD_NFEV,
                tol=conv.tol,
                method="lm",
                margin=conv.margin,
                reuse_jacobian=True,
                fit_until=train.stop,
                start=(r, solved.jacobian),
            )
        except ValueError:
            return None, False
        return out.x, out.fit.success

    return Leaveout(z, solved.jacobian, box.lower, box.upper, box.scale, simulate, refit, conv.margin)


def scored(
    record: Record, solved: Solved, folds: Folds, conv: Convergence, *, exact: bool = False, workers: int | None = 1
) -> Scored:
    """A converged fit with its forward validation on ``folds`` (the screen's, or with
    ``exact`` the refits')."""
    lo = _leaveout(record, solved, conv)
    cv = held_out(record, lo, solved.x, folds, exact, workers)
    return Scored(solved.fit, solved.x, solved.jacobian, cv, solved.fit.success, lo)


def confirmed(record: Record, model: Scored | Structure, workers: int | None) -> Scored | Structure:
    """``model`` with its held-out error from converged refits (itself where it has it)."""
    if model.cv.exact:
        return model
    cv = held_out(record, model.leaveout, model.x, model.cv.folds, True, workers)
    return replace(model, cv=cv)


def solved_at(record: Record, fit: ExtendedFit) -> Solved:
    """``fit`` with its simulated displacement and Jacobian over ``record``."""
    layout = _layout(record, fit.effects)
    out = layout.simulate_with_jacobian(layout.pack(fit.params, fit.effects, fit.h0), record.u, record.dt)
    if out is None:  # pragma: no cover - a fitted model can be simulated
        raise ValueError("the fitted model cannot be simulated")
    return Solved(fit=fit, x=out[0], jacobian=out[1])


def base(record: Record, offline: FitResult, conv: Convergence, folds: int, first_origin: float) -> Scored:
    """The base model: the offline fit (:func:`boucwen.fit`, its global search of
    starts) converged by ``conv`` and scored on ``folds`` forward folds, the first origin
    where the past holds ``first_origin`` of what the record tells about its unknowns
    (:class:`~boucwen.diagnosis.heldout.Folds`)."""
    start = ExtendedFit(offline.params, EffectSet(), offline.h0, offline.rms_um, offline.max_um, offline.nfev, True)
    solved = _converge(record, start, EffectSet(), conv)
    return scored(record, solved, Folds.of(record, folds, first_origin, solved.jacobian), conv)


def _first_order(record: Record, current: Scored, effects: EffectSet, added: tuple[str, ...]) -> float:
    """RMS [µm] left by the current model with ``effects`` once its unknowns and those of
    the effects ``added`` are refitted to first order: along the current model's
    Jacobian, and along each added unknown's own direction at the start (a forward
    difference of a thousandth of its typical size, one simulation each); ∞ where it
    cannot be simulated."""
    box = fit_box(record, current.fit.params, effects, current.fit.h0)
    v = box.v0
    xs = box.layout.simulate(v, record.u, record.dt)
    if xs is None:
        return math.inf
    columns = [current.jacobian, *(d[:, None] for d in box.directions(added, xs, record.u, record.dt))]
    basis = np.column_stack(columns)
    norms = np.linalg.norm(basis, axis=0)
    keep = norms > 0
    q, _ = np.linalg.qr(basis[:, keep] / norms[keep])
    r = record.x - xs
    return rms(r - q @ (q.T @ r))


def _ranking_copy(record: Record) -> Record:
    """The copy of ``record`` the starts are ranked on: every q-th sample (about
    :data:`RANK_RATE_HZ`; the record itself where it is sampled slower), and of a longer
    copy the :data:`RANK_SAMPLES` samples of most voltage travel (the model runs from the
    window's start, its h0 fitted there)."""
    q = max(1, int(1.0 / (record.dt * RANK_RATE_HZ)))
    copy = record.decimated(q) if q > 1 else record
    if len(copy) <= RANK_SAMPLES:
        return copy
    travel = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(copy.u)))])
    gained = travel[RANK_SAMPLES:] - travel[: len(copy) - RANK_SAMPLES]
    start = int(np.argmax(gained))
    return copy.part(start, start + RANK_SAMPLES)


def _ranked(record: Record, current: Scored, starts: list[EffectSet], added: tuple[str, ...]) -> list[EffectSet]:
    """``starts`` best first. A start is a local optimum's basin, and where the current
    model has bent its hysteresis to imitate the effect (a lag, an electrostriction) a
    first-order view from the bent model ranks a start that changes little first and the
    start in the effect's own basin last: only a fit from the start tells which basin it
    lies in. So the best :data:`RANK_SHORTLIST` by the first-order refit
    (:func:`_first_order`) are each fitted from the current model's values on a copy of the
    record (:func:`_ranking_copy`) for at most :data:`RANK_NFEV` trial points, and ranked by
    the cost they reach there. These fits
    only choose which starts are converged on the record; nothing is decided on them."""
    if len(starts) > RANK_SHORTLIST:
        first = [_first_order(record, current, s, added) for s in starts]
        order = sorted(range(len(starts)), key=lambda k: (first[k], k))
        starts = [starts[k] for k in order[:RANK_SHORTLIST] if math.isfinite(first[k])]
    copy = _ranking_copy(record)
    fit = current.fit

    def cost(effects: EffectSet) -> float:
        try:
            out = solve_extended_record(copy, fit.params, effects, fit.h0, max_nfev=RANK_NFEV, reuse_jacobian=True)
        except ValueError:
            return math.inf
        value = out.fit.rms_um
        return value if math.isfinite(value) else math.inf

    costs = [cost(s) for s in starts]
    order = sorted(range(len(starts)), key=lambda k: (costs[k], k))
    return [starts[k] for k in order if math.isfinite(costs[k])]


def starts_of(
    record: Record, current: Scored, names: tuple[str, ...], max_delay: int, warm: ExtendedFit | None
) -> list[EffectSet]:
    """Starting effect sets adding ``names`` to the current model: the starts of the
    last (a tied effect after its partner, from the partner's starts), and the values
    ``warm`` holds for them (module docs)."""
    fit = current.fit
    *partners, name = names
    cls = effect_class(name)
    if partners:
        first = candidate_starts(partners[0], record, fit.params, fit.effects, fit.h0, max_delay=max_delay)
        starts = [cls.beside(s) for s in first]
    else:
        starts = candidate_starts(name, record, fit.params, fit.effects, fit.h0, max_delay=max_delay)
    return starts + _warm_start(current, names, warm)


def _warm_start(current: Scored, names: tuple[str, ...], warm: ExtendedFit | None) -> list[EffectSet]:
    """The current model's effects with ``names`` at the values ``warm`` holds for them
    (none where it does not hold them all)."""
    if warm is None:
        return []
    held = {e.name: e for e in effects_of(warm.effects)}
    if not all(k in held for k in names):
        return []
    effects = current.fit.effects
    for k in names:
        effects = with_effect(effects, held[k])
    return [effects]


def add(
    record: Record,
    current: Scored,
    names: tuple[str, ...],
    conv: Convergence,
    folds: Folds,
    max_delay: int,
    *,
    dropped: Scored | None = None,
    warm: ExtendedFit | None = None,
    ranked: list[EffectSet] | None = None,
) -> Scored | str:
    """The current model with ``names`` added (to ``dropped``, the current model without
    the effect it swaps out, where the move is a swap), converged from the best
    :data:`STARTS` starts (module docs; ``warm``: a fit that held the same effects;
    ``ranked``: the starts already ranked best first, by the move's score,
    :mod:`~boucwen.diagnosis.score`) and scored by the screen; or why there is no such
    candidate (no start can be simulated, or the fitted effect is not what its name
    says: :meth:`boucwen.effects.Effect.rejects`)."""
    origin = current if dropped is None else dropped
    if ranked is not None:
        starts = ranked[:STARTS] + _warm_start(origin, names, warm)
    else:
        starts = starts_of(record, origin, names, max_delay, warm)
        if len(starts) > STARTS:
            starts = _ranked(record, origin, starts, names)[:STARTS]
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
    # An effect can always be set to change nothing (no lag, no delay, a gain of 0): a fit
    # with it that ends worse on the record than the model without it did not find it.
    if best.fit.rms_um > origin.fit.rms_um * (1.0 + _SAME):
        return (
            f"the fit with {' + '.join(names)} ends worse on the record ({best.fit.rms_um:.4g} µm) than the "
            f"model without it ({origin.fit.rms_um:.4g} µm): the effect was not found"
        )
    # An effect is named for what it does to the record: one that changes the fitted
    # model's prediction of the record by less than a thousandth of what the fit leaves (a
    # clip above every sample) is not in the record, whatever it does where the model is
    # carried beyond it.
    fit = best.fit
    rest = fit.effects
    for k in names:
        rest = without(rest, k)
    plain = simulate_chain(fit.params, rest, record.u, record.dt, fit.h0)
    if plain is not None:
        if rms(best.x - plain) < _UNSEEN_SHARE * max(fit.rms_um, 1e-300):
            return f"{' + '.join(names)} changes nothing the record holds: it is not in the record"
        for effect in effects_of(fit.effects):
            why = effect.rejects_on(record, plain) if effect.name in names else None
            if why is not None:
                return why
    return _valid(record, best, folds, conv)


def swap(
    record: Record, current: Scored, out: str, adds: tuple[str, ...], conv: Convergence, folds: Folds, max_delay: int
) -> Scored | str:
    """The current model with ``out`` swapped for ``adds`` (:func:`drop`, then
    :func:`add` to what is left), or why there is no such candidate."""
    rest = drop(record, current, out, conv, folds)
    if isinstance(rest, str):
        return rest
    return add(record, current, adds, conv, folds, max_delay, dropped=rest)


def _valid(record: Record, solved: Solved, folds: Folds, conv: Convergence) -> Scored | str:
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


def drop(record: Record, current: Scored, name: str, conv: Convergence, folds: Folds) -> Scored | str:
    """The current model without ``name``, refitted from where it is and scored."""
    try:
        solved = _converge(record, current.fit, without(current.fit.effects, name), conv)
    except ValueError as exc:
        return str(exc)
    return _valid(record, solved, folds, conv)


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
        cv: its forward validation (each fold from the oscillator refitted on its past,
            from the whole-record fit: always converged refits).
        converged: the whole-record fit converged.
        unknowns: its number of unknowns.
        leaveout: what its fold refits need.
    """

    name: str
    fit: OscillatorFit
    x: FloatArray
    cv: CrossValidation
    converged: bool
    unknowns: int
    leaveout: Leaveout

    @property
    def names(self) -> tuple[str, ...]:
        return (self.name,)


def oscillator(record: Record, folds: Folds, conv: Convergence) -> Structure | str:
    """The hysteretic oscillator fitted to ``record`` (u as the force [N], x [µm] as the
    displacement, in m for the fit) and scored like every model the judge compares (its
    held-out errors screened, confirmed by refits where a decision needs them); or why
    there is none (the fit cannot run on the record)."""
    y = record.x * 1e-6
    try:
        whole = fit_oscillator(record.u, y, record.dt)
        box, jac, run = linearised(whole, record.u, record.dt)
    except ValueError as exc:
        return f"the oscillator cannot be fitted: {exc}"
    x = whole.y * 1e6

    def simulate(z: FloatArray, stop: int) -> FloatArray | None:
        out = run(z, stop)
        return None if out is None else out * 1e6

    def refit_fold(train: slice) -> tuple[FloatArray | None, bool]:
        weights = np.zeros(len(record))
        weights[train] = 1.0
        try:
            out = fit_oscillator(record.u, y, record.dt, start=whole.params, weights=weights, max_nfev=FOLD_NFEV)
            x_k = simulate_oscillator(out.params, record.u, record.dt, out.y0, out.v0, out.z0) * 1e6
        except ValueError:
            return None, False
        return (x_k, out.success) if np.all(np.isfinite(x_k)) else (None, False)

    lo = Leaveout(box.z, jac * 1e6, box.lower, box.upper, box.scale, simulate, refit_fold, conv.margin)
    cv = held_out(record, lo, x, folds, not conv.screen)
    return Structure("oscillator", whole, x, cv, whole.success, len(OSCILLATOR_UNKNOWNS), lo)


#: A fitted unknown within this share [-] of its bound's size (at least 1) is reported on
#: the bound (``Diagnosis.at_bounds``): the record asks for more than the model allows
#: there. A millionth: the solver's own steps near a bound are far larger.
BOUND_TOLERANCE = 1e-6


def on_bounds(fit: ExtendedFit, record: Record, tolerance: float = BOUND_TOLERANCE) -> list[AtBound]:
    """The unknowns of ``fit`` that ended on a bound of the fit over ``record`` (within
    ``tolerance`` of its size, at least 1: :data:`BOUND_TOLERANCE`)."""
    layout = _layout(record, fit.effects)
    z = layout.pack(fit.params, fit.effects, fit.h0)
    lo, hi = layout.bounds()
    out: list[AtBound] = []
    for label, v, a, b in zip(layout.labels(), z, lo, hi):
        for bound, side in ((a, "lower"), (b, "upper")):
            if math.isfinite(bound) and abs(v - bound) <= tolerance * max(1.0, abs(bound)):
                out.append(AtBound(label, float(v), float(bound), side))
    return out


#: The unknowns of the base loop's shape (:meth:`boucwen.effects.Layout.labels`): its
#: exponent and the pair (β + γ, β − γ) that bends each branch.
LOOP_SHAPE = ("n", *PAIR_NAMES)

#: A bending coefficient c ∈ {β + γ, β − γ} whose term c·Xⁿ at the record's displacement
#: span X is below this share of A bends no branch the record can see: it is on its
#: bound 0 (the branch is a straight line), whatever its value.
FLAT_SHARE = 1e-3


def loop_on_bounds(fit: ExtendedFit, record: Record) -> list[AtBound]:
    """The base loop's shape unknowns (:data:`LOOP_SHAPE`) of ``fit`` on a bound of the
    fit over ``record``: the exponent n on either bound (:func:`on_bounds`), a bending
    coefficient on its bound 0 or too small to bend a branch over the record's span
    (:data:`FLAT_SHARE`). Where the base model's fit ends so, the base loop cannot take the
    record's loop: what it lacks is the loop's shape, which an effect fitted beside it
    takes up only by mistake."""
    found = {b.parameter: b for b in on_bounds(fit, record) if b.parameter in LOOP_SHAPE}
    p = fit.params
    span = max(float(np.ptp(record.x)), 1e-12)
    for name, c in zip(PAIR_NAMES, pair(p.beta, p.gamma)):
        if name not in found and abs(c) * span**p.n <= FLAT_SHARE * abs(p.A):
            found[name] = AtBound(name, float(c), 0.0, "lower")
    return [found[k] for k in LOOP_SHAPE if k in found]
