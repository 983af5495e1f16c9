"""Where a trial starts: the effect's starts ranked by the first-order refit of the
current model, and the refit of the current model to variants of the record that an
effect asks for (:meth:`boucwen.effects.Effect.refit_starts`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .._core import EffectSet, Params
from ..effects import ExtendedFit, TrialStart, candidate_starts, effect_class, fit_extended_record
from ..lsq import thread_map
from ..record import Record
from .margins import PATH, CloseCalls, at_most, first_of_best
from .policy import DiagnosisPolicy
from .scoring import cost
from .screening import decimated, screen_factor

__all__ = ["first_stage", "null_effort", "ranked_starts", "refit_start", "refits_beside_null"]


def first_stage(policy: DiagnosisPolicy) -> int:
    """Evaluations of a trial's first stage: a third of ``trial_nfev``, at least 3."""
    return max(3, policy.trial_nfev // 3)


def null_effort(policy: DiagnosisPolicy) -> int:
    """Evaluations of the null trial: both stages of a trial; the refits of the backward
    step and of the pairs get the same."""
    return first_stage(policy) + policy.trial_nfev


def ranked_starts(
    name: str,
    record: Record,
    current: ExtendedFit,
    basis: Any,
    workers: int | None,
    policy: DiagnosisPolicy,
    calls: CloseCalls | None = None,
) -> tuple[list[EffectSet], float]:
    """The starts of a trial adding ``name`` to ``current``, best first: least
    :func:`~boucwen.diagnosis.scoring.cost` beyond the first-order refit of ``basis``
    (when given), simulated side by side when there is more than one worker; and what
    the best leaves [µm] (∞ when not known: one start, or no basis). Starts whose costs
    tie with the least within ``policy.close_rel`` are taken in the order the effect
    lists them (a close call, noted in ``calls``)."""
    starts = candidate_starts(
        name, record, current.params, current.effects, current.h0, max_delay=policy.max_delay_samples
    )
    if len(starts) <= 1:
        return starts, math.inf
    costs = thread_map(lambda s: cost(record, current, s, basis), starts, workers)
    best = first_of_best(
        range(len(starts)),
        lambda k: costs[k],
        higher=False,
        margin=policy.close_rel,
        relative=True,
        decision=f"{name}: best start",
        calls=calls,
        name=lambda k: f"start {k}",
        kind=PATH,
    )
    order = [best] + [int(k) for k in np.argsort(costs, kind="stable") if k != best]
    return [starts[k] for k in order], float(costs[best]) if basis is not None else math.inf


def refits_beside_null(
    record: Record,
    current: ExtendedFit,
    variants: Sequence[Callable[[Record], Record]],
    *,
    workers: int | None,
    nfev: int,
    policy: DiagnosisPolicy,
    calls: CloseCalls | None = None,
    what: str = "",
) -> tuple[list[ExtendedFit], int, bool]:
    """The current model refitted to the record itself (the null, first) and to each
    variant of it (same effort), on the record's screened copy (a variant is made of the
    full record, then decimated as the copy is), side by side when there is more than
    one worker. Returns the refits, the index of the best variant's (of variants that
    tie within the margin, the first listed) and whether it beats the null's RMS error
    by ``policy.local_floor`` (close calls noted in ``calls``; ``what``: the effect whose
    trial starts there)."""
    q = screen_factor(record, policy)

    def refit(variant: Callable[[Record], Record] | None) -> ExtendedFit:
        made = decimated(variant(record) if variant is not None else record, q)
        return fit_extended_record(
            made, current.params, current.effects, current.h0, max_nfev=nfev, tol=policy.trial_tol
        )

    refits = thread_map(refit, [None, *variants], workers)
    best = 1 + first_of_best(
        refits[1:],
        lambda f: f.rms_um,
        higher=False,
        margin=policy.close_rel,
        relative=True,
        decision=f"{what}: best refit start",
        calls=calls,
        name=lambda f: what,
        kind=PATH,
    )
    null_rms = refits[0].rms_um
    wins = null_rms > 0 and at_most(
        refits[best].rms_um / null_rms,
        1.0 - policy.local_floor,
        policy.close_rel,
        f"{what}: refit start beats the null",
        calls,
        PATH,
    )
    return refits, best, wins


def refit_start(
    name: str,
    record: Record,
    current: ExtendedFit,
    ranked: list[EffectSet],
    *,
    workers: int | None,
    policy: DiagnosisPolicy,
    calls: CloseCalls | None = None,
) -> tuple[Params, float, EffectSet] | str:
    """Where the trial of ``name`` starts (base parameters, h0 [µm], effects): from the
    current model with the best of ``ranked`` (its starts, best first), or, where the
    effect asks for it (:meth:`boucwen.effects.Effect.refit_starts`), from the current
    model refitted to the variant of the record that fits best, where it beats the
    record itself by ``policy.local_floor``. A string: why the trial is hopeless (an
    effect whose variants must win, and none does)."""
    at = TrialStart(
        record=record,
        params=current.params,
        effects=current.effects,
        h0=current.h0,
        ranked=tuple(ranked),
        screened=screen_factor(record, policy) > 1,
        screened_refits=policy.screened_refits,
    )
    asked = effect_class(name).refit_starts(at)
    if asked is None:
        return current.params, current.h0, ranked[0]
    refits, best, wins = refits_beside_null(
        record, current, asked.variants, workers=workers, nfev=policy.trial_nfev, policy=policy, calls=calls, what=name
    )
    if wins:
        return refits[best].params, refits[best].h0, asked.starts[best - 1]
    if asked.hopeless is not None:
        return asked.hopeless[best - 1]
    return current.params, current.h0, ranked[0]
