"""The outcome of the search: the model returned, its errors, how sure each name is.

:func:`outcome` turns the search's state (:class:`~boucwen.diagnosis.search.Search`) into
the :class:`~boucwen.diagnosis.report.Diagnosis`: the explanations a validation record
settles, the returned model's errors in-sample and held out (read from the fits the
search holds, confirmed by refits where the search left them screened), what its
residual leaves, and each name's confidence (:data:`~boucwen.diagnosis.rules.RULES`,
``confident_share``).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

from .._core import EffectSet
from ..boundedness import check_model, check_oscillator
from ..effects import effects_of
from ..effects.base import without
from ..io import jsonable
from ..metrics import max_abs, rms
from ..record import Record
from ..residual import Unexplained, fit_evidence, lookalike_tests, unexplained
from . import fits
from .experiment import Explained, explanations
from .fits import Convergence, Scored, Structure
from .heldout import on_common_folds
from .judge import Decision
from .policy import DiagnosisPolicy
from .report import Diagnosis, ModelFit, NamedEffect, NamedStructure
from .search import OSCILLATOR, Search, rival_order
from .unseen import OnValidation, Unseen, judged_on, pooled_noise, prediction_error, settled

__all__ = ["named", "outcome"]


def outcome(
    record: Record,
    base: Scored,
    state: Search,
    validate: tuple[Record, ...],
    policy: DiagnosisPolicy,
    conv: Convergence,
    noise_um: float,
    say: Any,
    started: float,
    workers: int | None,
) -> Diagnosis:
    """The :class:`Diagnosis` of the search ``state``: the model judged on the validation
    records (``validate``, none or several), its errors, what it leaves, how sure each
    name is."""
    decisions = [d for r in state.rounds for d in r.decisions]
    final = state.input_driven
    other = state.current if isinstance(state.current, Structure) else None
    rivals = {k: set(v) for k, v in state.rivals.items()}
    swaps = dict(state.swaps)
    on_validation: list[Decision] = []
    if validate and other is None:
        final, rivals, swaps, on_validation = _settle(record, validate, final, rivals, swaps, policy, conv, say)
    if validate and other is None and final.names:
        samples = sum(len(v) for v in validate)
        say(f"judging {', '.join(final.names)} on {len(validate)} validation record(s) ({samples} samples)")
        kept, judged = judged_on(
            validate,
            final.fit,
            lambda model, name: fits.refit(record, model, without(model.effects, name), conv),
            policy,
            pooled_noise(validate),
            say,
        )
        on_validation += judged
        if kept.effects.names != final.fit.effects.names:
            final = fits.scored(record, fits.solved_at(record, kept), final.cv.folds, conv, exact=True, workers=workers)
    returned: Scored | Structure = other if other is not None else final
    returned = fits.confirmed(record, returned, workers)
    # The search holds the base model, confirmed where a round confirmed it.
    held = state.fitted.get(frozenset(base.names))
    base = held if isinstance(held, Scored) else base
    base = fits.confirmed(record, base, workers)  # type: ignore[assignment]
    returned_x, returned_cv = returned.x, returned.cv
    x = record.x
    err_b, err_e = x - base.x, x - returned_x
    left = unexplained(record, returned_x, alpha=policy.noise_alpha, tolerance=policy.noise_tolerance)
    cv_before, cv_after = on_common_folds(base.cv, returned_cv)
    # The share of the error beyond the noise the model removes: on the samples the folds
    # predict, held out; on those before the first origin, which no fold predicts, the
    # only evidence is in-sample. Names are confident where both are large.
    first = base.cv.folds.tested.start
    held_share = _explained(cv_before, cv_after, noise_um)
    prefix_share = _explained(rms(err_b[:first]), rms(err_e[:first]), noise_um) if first > 0 else 1.0
    share = min(held_share, prefix_share)
    added = _order_added(state, final.names)
    named_ = tuple(
        named(e, rivals, final, left, share, policy) for e in effects_of(final.fit.effects) if e.name in added
    )
    names = tuple(sorted(named_, key=lambda e: added.index(e.name)))
    structure = None if other is None else _structure(other, rivals)
    if other is not None:
        # The effects of the input-driven model the oscillator refutes are its rival's.
        why = "the hysteretic oscillator predicts the record better: this effect is the refuted input-driven model's"
        names = tuple(
            replace(e, level="tentative", why=why, rivals=tuple(sorted({*e.rivals, other.name}, key=rival_order)))
            for e in names
        )
    unseen = Unseen(
        folds=policy.folds,
        cv_rms_before_um=cv_before,
        cv_rms_after_um=cv_after,
        validation=tuple(
            OnValidation(len(v), prediction_error(base.fit, v), prediction_error(final.fit, v), v.name)
            for v in validate
        ),
    )
    evidence: dict[str, Any] = {
        "policy": policy.to_dict(),
        "convergence": {"method": conv.method, "margin": conv.margin, "tol": conv.tol},
        "noise_um": noise_um,
        "folds": base.cv.folds.to_dict(),
        "residual": fit_evidence(record, base.fit, base.x, policy.max_delay_samples),
        "rounds": [r.to_dict() for r in state.rounds],
        "stopped": state.stopped,
        "validation": [d.to_dict() for d in on_validation],
        "explained_share": share,
        "explained_share_held_out": held_share,
        "explained_share_before_first_origin": prefix_share,
        "unseen": unseen.to_dict(),
        "lookalike": lookalike_tests(record, returned_x),
        "structure": (
            {"tried": False, "why": "no round proposed it"}
            if not isinstance(state.fitted.get(frozenset({OSCILLATOR})), Structure)
            else _structure_evidence(state.fitted[frozenset({OSCILLATOR})])
        ),
        "elapsed_s": time.perf_counter() - started,
    }
    say(left.summary())
    result = Diagnosis(
        effects=list(added),
        rms_before_um=rms(err_b),
        max_before_um=max_abs(err_b),
        rms_after_um=rms(err_e),
        max_after_um=max_abs(err_e),
        params=final.fit.params,
        h0_um=final.fit.h0,
        base_only=ModelFit(base.fit.params, base.fit.h0),
        evidence=jsonable(evidence),
        x_base=base.x,
        x_extended=returned_x,
        effect_set=final.fit.effects if final.names else EffectSet(),
        unexplained=left,
        named_effects=names,
        decisions=(*decisions, *on_validation),
        taken=tuple(r.taken for r in state.rounds if r.taken is not None),
        at_bounds=fits.on_bounds(final.fit, record),
        base_loop=fits.loop_on_bounds(base.fit, record),
        unseen=unseen,
        explained=Explained(record, final, rivals, swaps, conv, policy, noise_um),
        structure=structure,
        boundedness=(
            check_oscillator(record, other.fit)
            if other is not None
            else check_model(record, final.fit.params, final.fit.effects, final.fit.h0)
        ),
    )
    say(result.summary())
    return result


def _structure_evidence(model: Any) -> dict[str, Any]:
    """What the JSON says of the other structure where a round fitted it."""
    if not isinstance(model, Structure):
        return {"tried": True, "why": str(model)}
    return {"tried": True, "held_out_rms_um": model.cv.rms_um, "fit": model.fit.to_dict()}


def _order_added(state: Search, names: tuple[str, ...]) -> list[str]:
    """``names`` in the order the search added them."""
    order: list[str] = []
    for r in state.rounds:
        if r.taken is not None and r.taken.move not in ("drop", "structure"):
            order += [k for k in r.taken.effects if k not in order]
    return [k for k in order if k in names] + [k for k in names if k not in order]


def _settle(
    record: Record,
    validate: tuple[Record, ...],
    final: Scored,
    rivals: dict[str, set[str]],
    swaps: dict[frozenset[str], Scored],
    policy: DiagnosisPolicy,
    conv: Convergence,
    say: Any,
) -> tuple[Scored, dict[str, set[str]], dict[frozenset[str], Scored], list[Decision]]:
    """The explanations the record could not tell apart, settled on the validation
    records (:func:`~boucwen.diagnosis.unseen.settled`): the model kept, its rivals left,
    the swaps still fitted from it, and the decisions. The model keeps the returned
    explanation where the validation record does not refute it; else, of those it leaves
    (which it cannot tell apart), the simplest, then the one whose gain over the refuted
    model has the largest statistic."""
    members = explanations(record, final, rivals, swaps, conv, policy)
    if len(members) < 2:
        return final, rivals, swaps, []
    say(f"settling {', '.join(m.label for m in members)} on the validation records")
    left, decisions = settled(
        validate, [m.fit for m in members], [m.label for m in members], policy, pooled_noise(validate), say
    )
    if 0 in left:
        keep = 0
    else:

        def statistic(i: int) -> float:
            for d in decisions:
                if d.candidate == (members[i].label,) and d.reference == (members[0].label,):
                    return d.gain.statistic
                if d.reference == (members[i].label,) and d.candidate == (members[0].label,):
                    return -d.gain.statistic
            return -math.inf

        keep = min(left, key=lambda i: (len(members[i].effects), -statistic(i)))
    chosen = members[keep]
    if chosen.replaces is None or chosen.scored is None:
        kept = {
            k: {m.replaces[1] for i, m in enumerate(members) if i in left and m.replaces and m.replaces[0] == k}
            for k in rivals
        }
        return final, kept, {k: v for k, v in swaps.items() if any(m.scored is v for m in members)}, decisions
    out, into = chosen.replaces
    say(f"the validation records refute {members[0].label}: the model takes {chosen.label}")
    left_for = {
        m.replaces[1] for i, m in enumerate(members) if i in left and i != keep and m.replaces and m.replaces[0] == out
    }
    return chosen.scored, {into: left_for}, {}, decisions


def _explained(before_um: float, after_um: float, noise_um: float) -> float:
    """The share of the base model's held-out mean-square error beyond the noise [µm]
    that the returned model removes (held-out RMS ``before_um`` → ``after_um``) [-]."""
    beyond_before = max(before_um**2 - noise_um**2, 0.0)
    beyond_after = max(after_um**2 - noise_um**2, 0.0)
    if not math.isfinite(beyond_before) or not math.isfinite(beyond_after):
        return 0.0
    return 1.0 - beyond_after / beyond_before if beyond_before > 0 else 1.0


def _structure(osc: Structure, rivals: dict[str, set[str]]) -> NamedStructure:
    """The other structure returned: the search took it, so it passed the test against
    the input-driven model it replaced; ``confident`` where no input-driven effect was
    left within its margin."""
    tied = sorted(rivals.get(osc.name, set()), key=rival_order)
    if tied:
        why = "the record does not tell it from the input-driven model with " + ", ".join(tied)
        return NamedStructure(osc.name, "tentative", why, osc.fit, osc.cv.rms_um)
    why = "it predicts unseen samples better than the input-driven model beyond that model's margin"
    return NamedStructure(osc.name, "confident", why, osc.fit, osc.cv.rms_um)


def named(
    effect: Any,
    rivals_of: dict[str, set[str]],
    final: Scored,
    left: Unexplained,
    share: float,
    policy: DiagnosisPolicy,
) -> NamedEffect:
    """An effect of the returned model with its confidence (module docs, step 8)."""
    rivals = tuple(sorted(rivals_of.get(effect.name, set()) - set(final.names), key=rival_order))
    if rivals:
        return NamedEffect(
            effect, "tentative", "the record does not tell it from its rivals (within the judge's margin)", rivals
        )
    if not final.converged:
        return NamedEffect(effect, "tentative", "the returned model's fit did not converge")
    if not left.consistent_with_noise and share < policy.confident_share:
        return NamedEffect(
            effect,
            "tentative",
            f"the model removes {share:.0%} of the base model's error beyond the noise (the least of its held-out "
            "share and, before the first origin where no fold predicts, its in-sample share) and leaves a residual "
            "that is not noise: the effects may stand in for something outside the vocabulary",
        )
    return NamedEffect(effect, "confident", "no rival within the judge's margin; the model explains the record")
