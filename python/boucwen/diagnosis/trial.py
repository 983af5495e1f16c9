"""A trial: one effect added to the current model and everything refitted, in stages.

:func:`trial_fit` starts the effect where :mod:`~boucwen.diagnosis.starts` says, and
refits in two stages: a trial no better than the null trial after its first stage
(a third of the policy's ``trial_nfev``) stops there unless its start promised a cut of
``local_floor``; one whose second stage left less than ``still_falling`` of its first
stage's error without converging gets a third (it is judged where it converges, not
where its budget happened to end). An effect tried beside a partner the model lacks
(:attr:`boucwen.effects.Effect.partner`: a second resonance mode) is added with it, from
the partner's best start, where that promises ``local_floor`` more than the partner
alone.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .._core import EffectSet
from ..effects import ExtendedFit, Solved, effect_class, effects_of, solve_extended_record
from ..record import Record
from .margins import PATH, CloseCalls, Compare, at_most, decide
from .policy import DiagnosisPolicy
from .scoring import cost
from .starts import first_stage, refit_start

__all__ = ["joint_partner", "second_stage", "still_falling", "trial_fit"]


def joint_partner(name: str, present: tuple[str, ...] | list[str]) -> str | None:
    """The partner the trial of ``name`` adds with it: its
    :attr:`~boucwen.effects.Effect.partner` where the model (``present``) lacks it."""
    partner = effect_class(name).partner
    return partner if partner is not None and partner not in present else None


def second_stage(policy: DiagnosisPolicy, joint: bool) -> int:
    """Evaluations of a trial's second stage: ``trial_nfev``, ``joint_effort`` times that
    for a joint trial (an effect added with its partner: twice the unknowns, the two
    modes trading places as they part)."""
    return policy.joint_effort * policy.trial_nfev if joint else policy.trial_nfev


def still_falling(
    first_um: float, second_um: float, policy: DiagnosisPolicy, calls: CloseCalls | None = None, what: str = ""
) -> bool:
    """A trial's RMS error after its second stage (``second_um``) is at most
    ``still_falling`` times the one after its first (``first_um``, both [µm]): a trial
    still leaving a valley, which gets a third stage where it has not converged (a ratio
    within ``close_rel`` of the threshold is a close call on the path: not falling)."""
    return first_um > 0 and at_most(second_um / first_um, policy.still_falling, policy.close_rel, what, calls, PATH)


def trial_fit(
    name: str,
    record: Record,
    current: ExtendedFit,
    null: Callable[[], ExtendedFit],
    ranked: Callable[[str], tuple[list[EffectSet], float]],
    *,
    workers: int | None,
    policy: DiagnosisPolicy,
    basis: Any = None,
    calls: CloseCalls | None = None,
) -> Solved | str:
    """Adds ``name`` to ``current`` from its best start (``ranked``: the starts of an
    effect best first and what the best leaves,
    :func:`~boucwen.diagnosis.starts.ranked_starts`) and refits everything in the stages
    of the module docs. ``null`` gives the null trial's fit (it waits for the null trial
    when that runs beside this one); ``basis``: the first-order refit of the current
    model. Returns the fit, or why there is none."""
    partner = joint_partner(name, current.effects.names)
    starts, predicted = ranked(partner or name)
    cls = effect_class(name)
    if partner is not None:
        start = cls.beside(starts[0])
        alone, predicted = predicted, cost(record, current, start, basis)
        if not predicted <= (1.0 - policy.local_floor) * alone:
            return f"hopeless: {cls.joint} promise no more than the first alone"
        p0, h0 = current.params, current.h0
    else:
        began = refit_start(name, record, current, starts, workers=workers, policy=policy, calls=calls)
        if isinstance(began, str):
            return began
        p0, h0, start = began
    nfev = policy.trial_nfev
    try:
        solved = solve_extended_record(record, p0, start, h0, max_nfev=first_stage(policy), tol=policy.trial_tol)
        fr = solved.fit
        null_rms = null().rms_um

        def goes_on(c: Compare) -> bool:
            # A start whose first-order refit promises a cut goes on: its first steps
            # may still be finding their way (a second mode beside the first).
            if not null_rms > 0:
                return False
            better = c.le(fr.rms_um / null_rms, 1.0, policy.close_rel)
            return better or c.le(predicted / null_rms, 1.0 - policy.local_floor, policy.close_rel)

        if not decide(goes_on, f"{name}: trial goes on after stage 1", calls, yes="goes on", no="stopped", kind=PATH):
            return "hopeless: no better than the null trial after a third of the effort"
        if not fr.success:
            effort = second_stage(policy, joint=partner is not None)
            solved = solve_extended_record(record, fr.params, fr.effects, fr.h0, max_nfev=effort, tol=policy.trial_tol)
            went = solved.fit
            falling = still_falling(fr.rms_um, went.rms_um, policy, calls, f"{name}: still falling after stage 2")
            if not went.success and falling and null().success:
                # Still falling fast when its effort ran out: a trial judged there would
                # be credited with where it happened to stop, not with what it explains.
                solved = solve_extended_record(
                    record, went.params, went.effects, went.h0, max_nfev=nfev, tol=policy.trial_tol
                )
    except ValueError as exc:
        return str(exc)
    added = {partner, name} if partner is not None else {name}
    order = (partner, name) if partner is not None else (name,)
    fitted = {e.name: e for e in effects_of(solved.fit.effects) if e.name in added}
    for k in order:
        why = fitted[k].rejects() if k in fitted else None
        if why is not None:
            return why
    return solved
