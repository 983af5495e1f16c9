"""Diagnosis: which effects a record holds beyond the base model, judged on unseen data.

:func:`diagnose` takes a record (voltage u [V], displacement x [µm], interval dt [s]),
not told what it contains, and selects a model by one loop under one judge:

1. **Fit the base model** to convergence (:func:`boucwen.fit`'s global search of
   starts, then Levenberg–Marquardt on the core's exact Jacobian to the statistical
   stop: :mod:`~boucwen.diagnosis.fits`).
2. **Score it on unseen data**: blocked cross-validation over ``folds`` contiguous
   blocks, each held out from a refit on the others (:mod:`~boucwen.diagnosis.judge`).
3. **Propose every move** from the current model: add an effect of the vocabulary
   (:data:`boucwen.effects.VOCABULARY`; a second mode with the first where the model
   has none), drop one, swap one for a rival (:mod:`~boucwen.diagnosis.search`). Fit
   each candidate to convergence from the effect's physical starts (several where it has
   local optima).
4. **Judge each move** by the same rule: the fold-paired held-out gain
   d_i = r_ref,i² − r_cand,i² must exceed t₁₋α/m times its batch-means standard error
   (a real improvement at level α over the round's m moves), and remove at least
   ``min_share`` of the reference's held-out error beyond the record's noise (an effect,
   not a reshaping of the base model's misfit). A drop is accepted where the effect no
   longer passes that rule against the model without it.
5. **Take one move**: an accepted drop first; else the accepted add or swap of largest
   gain — through its **ambiguity set**, the candidates the record cannot tell from it
   (neither's gain over the other passes the rule's first condition): the model takes
   the accepted member with the fewest unknowns, then the first in the vocabulary; the
   others are its rivals, reported with their held-out errors and tried as swaps later.
6. **Repeat** from 3 until no move is accepted or the residual is consistent with the
   record's noise (:func:`boucwen.residual.unexplained`). A model already held is never
   proposed again.
7. **The other structure**: where the input-driven model the loop returns holds a mode
   (an effect of signature ``"peak"``: the mark of a mechanical structure), the
   hysteretic oscillator (:mod:`boucwen.oscillator`: the hysteresis driven by the
   output's motion, the input a force) is fitted and scored the same way and judged by
   the same rule against that model; accepted and explaining the record
   (``confident_share`` of the error beyond the noise, or a residual of noise: a change
   of model class is a claim about the mechanics that a partial fit cannot carry), it is
   the returned model; accepted but partial, or within the judge's margin, it is the
   mode's rival. Without a mode, an
   output-driven hysteresis reduces to a static one that the input-driven model holds.
8. **Report**: the returned model's errors before and after, what it leaves
   (``unexplained``), the held-out errors of the base and returned models (``unseen``),
   each name ``confident`` only where it has no rival and the model explains at least
   ``confident_share`` of the error beyond the noise (else ``tentative``, with the rivals),
   every decision typed (``decisions``), the parameters on a bound, and whether the
   returned model stays bounded over the record's range (``boundedness``,
   :func:`boucwen.boundedness.check`; every fit keeps to the admissible region, and a
   candidate that fails the check is no candidate).

9. **Where the record cannot decide**, design the experiment that can
   (:meth:`Diagnosis.next_experiment`, :mod:`~boucwen.diagnosis.experiment`): the input,
   within the record's limits, on which the explanations it left (each tentative name
   and its rivals) predict most differently.

With a second record of the device (``validate``; the recorded experiment, or any other),
the explanations the first record left are settled there (one is refuted where another
passes the judge against it there; the model keeps the one left), and each effect of the
device must also earn its place there by the same judge (:mod:`~boucwen.diagnosis.unseen`).

Every number is a field of :class:`~boucwen.diagnosis.policy.DiagnosisPolicy`; what
describes one effect is on its class. What the residual follows (spectral lines, spans,
the look-alike tests of :mod:`boucwen.residual`) is evidence reported beside the answer;
it never accepts or rejects. Modules: :mod:`~boucwen.diagnosis.policy` (the numbers),
:mod:`~boucwen.diagnosis.judge` (held-out errors and the rule),
:mod:`~boucwen.diagnosis.fits` (converged fits of candidates),
:mod:`~boucwen.diagnosis.search` (the moves and their loop),
:mod:`~boucwen.diagnosis.unseen` (errors on unseen data, the validation record),
:mod:`~boucwen.diagnosis.experiment` (the next experiment),
:mod:`~boucwen.diagnosis.report` (:class:`Diagnosis`, its files).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._core import EffectSet
from ..boundedness import check_model, check_oscillator
from ..checks import FloatArray, check_int
from ..effects import effect_class, effects_of
from ..effects.base import without
from ..fit import fit_record
from ..io import jsonable
from ..metrics import max_abs, rms
from ..progress import Progress, reporter
from ..record import Record, validate_record
from ..residual import Unexplained, fit_evidence, lookalike_tests, noise_level, residual_evidence, unexplained
from ..residual import residual_evidence_record as residual_evidence_record
from . import fits
from .experiment import Experiment, Explained, explanations
from .fits import Convergence, Scored, Structure
from .judge import Decision, on_common_blocks
from .policy import DiagnosisPolicy
from .report import AtBound, Diagnosis, ModelFit, NamedEffect, NamedStructure, write_predictions, write_report
from .search import Search, rival_order, search, structure_move
from .unseen import OnValidation, Unseen, judged_on, prediction_error, settled

__all__ = [
    "AtBound",
    "Convergence",
    "Decision",
    "Diagnosis",
    "DiagnosisPolicy",
    "Experiment",
    "ModelFit",
    "NamedEffect",
    "NamedStructure",
    "OnValidation",
    "Unexplained",
    "Unseen",
    "diagnose",
    "diagnose_record",
    "lookalike_tests",
    "noise_level",
    "residual_evidence",
    "residual_evidence_record",
    "unexplained",
    "write_predictions",
    "write_report",
]


def diagnose(
    u: ArrayLike,
    x: ArrayLike,
    dt: float,
    *,
    progress: Progress = False,
    folds: int | None = None,
    max_effects: int | None = None,
    seed: int = 0,
    workers: int | None = None,
    validate: tuple[ArrayLike, ArrayLike, float] | None = None,
    policy: DiagnosisPolicy | None = None,
    convergence: Convergence | None = None,
) -> Diagnosis:
    """Finds which effects of the vocabulary the record holds beyond the base model.

    Args:
        u: voltage [V], 1-D, finite, not constant, uniformly sampled.
        x: measured displacement [µm], same length.
        dt: sampling interval [s] (> 0).
        progress: ``True`` prints progress lines to stderr; or a callable taking a str.
        folds: contiguous blocks of the cross-validation (2 … 10); overrides the
            policy's.
        max_effects: most effects in the returned model (0 … 8); overrides the policy's.
        seed: seed of :func:`boucwen.fit`'s random starts.
        workers: threads for the candidates of a round (default: the number of CPUs; 1
            runs everything in turn).
        validate: a second record of the same device, ``(u [V], x [µm], dt [s])``: each
            effect must also earn its place there (:mod:`~boucwen.diagnosis.unseen`),
            and the report gives both models' errors on it.
        policy: the numbers (:class:`~boucwen.diagnosis.policy.DiagnosisPolicy`; the
            default instance when None).
        convergence: how the fits are converged (:class:`~boucwen.diagnosis.fits.Convergence`;
            Levenberg–Marquardt to a tenth of a standard error when None).

    Returns:
        A :class:`~boucwen.diagnosis.Diagnosis`; the procedure is described in
        :mod:`boucwen.diagnosis`.

    Raises:
        TypeError, ValueError: bad data or options (precise message).
    """
    return diagnose_record(
        validate_record(u, x, dt),
        progress=progress,
        folds=folds,
        max_effects=max_effects,
        seed=seed,
        workers=workers,
        validate=None if validate is None else validate_record(*validate),
        policy=policy,
        convergence=convergence,
    )


def _policy_of(policy: DiagnosisPolicy | None, folds: int | None, max_effects: int | None) -> DiagnosisPolicy:
    """``policy`` (the default when None) with the options given beside it."""
    if policy is not None and not isinstance(policy, DiagnosisPolicy):
        raise TypeError(f"policy must be a DiagnosisPolicy, got {type(policy).__name__}")
    chosen = policy if policy is not None else DiagnosisPolicy()
    changes: dict[str, Any] = {}
    if folds is not None:
        changes["folds"] = folds
    if max_effects is not None:
        changes["max_effects"] = check_int("max_effects", max_effects, 0, 8)
    return chosen.replace(**changes) if changes else chosen


def diagnose_record(
    record: Record,
    *,
    progress: Progress = False,
    folds: int | None = None,
    max_effects: int | None = None,
    seed: int = 0,
    workers: int | None = None,
    validate: Record | None = None,
    policy: DiagnosisPolicy | None = None,
    convergence: Convergence | None = None,
) -> Diagnosis:
    """:func:`diagnose` on a checked :class:`~boucwen.record.Record` (same options, same
    result; ``validate`` a checked record too)."""
    started = time.perf_counter()
    say = reporter(progress, "diagnose", started)
    policy = _policy_of(policy, folds, max_effects)
    conv = convergence if convergence is not None else Convergence()
    if not isinstance(conv, Convergence):
        raise TypeError(f"convergence must be a Convergence, got {type(conv).__name__}")
    n = len(record)
    if n < 100:
        raise ValueError(f"diagnose needs at least 100 samples, got {n}")
    if not np.ptp(record.u) > 0:
        raise ValueError("u is constant; the diagnosis needs a varying voltage")
    noise_um = noise_level(record.x).sigma_um

    say(f"fitting the base model on {n} samples")
    offline = fit_record(record, seed=seed, workers=workers, method=conv.method)
    base = fits.base(record, offline, conv, policy.folds)
    say(f"base model: RMS {base.fit.rms_um:.4g} µm, held-out {base.cv.rms_um:.4g} µm ({policy.folds} folds)")
    state = search(record, base, noise_um=noise_um, policy=policy, conv=conv, workers=workers, say=say)
    say(f"search ended: {state.stopped}")
    return _outcome(record, base, state, validate, policy, conv, noise_um, say, started)


def _outcome(
    record: Record,
    base: Scored,
    state: Search,
    validate: Record | None,
    policy: DiagnosisPolicy,
    conv: Convergence,
    noise_um: float,
    say: Any,
    started: float,
) -> Diagnosis:
    """The :class:`Diagnosis` of the search ``state``: the model judged on the validation
    record, its errors, what it leaves, how sure each name is."""
    decisions = [d for r in state.rounds for d in r.decisions]
    final = state.current
    rivals = {k: set(v) for k, v in state.rivals.items()}
    swaps = dict(state.swaps)
    on_validation: list[Decision] = []
    if validate is not None:
        final, rivals, swaps, on_validation = _settle(record, validate, final, rivals, swaps, policy, conv, say)
    if validate is not None and final.names:
        say(f"judging {', '.join(final.names)} on the validation record ({len(validate)} samples)")
        kept, judged = judged_on(
            validate,
            final.fit,
            lambda model, name: fits.refit(record, model, without(model.effects, name), conv),
            policy,
            noise_level(validate.x).sigma_um,
            say,
        )
        on_validation += judged
        if kept.effects.names != final.fit.effects.names:
            final = fits.scored(record, fits.solved_at(record, kept), policy.folds, conv)
    osc, osc_decision, osc_skipped = structure_move(record, final, noise_um=noise_um, policy=policy, say=say)
    if osc_decision is not None:
        decisions.append(osc_decision)
    # A change of model class is a claim about the mechanics (the hysteresis inside the
    # structure's own dynamics, not in the actuator): the oscillator is returned only where
    # the judge accepts it and it explains the record (``confident_share`` of the error
    # beyond the noise, or a residual of noise). Accepted but partial, or within the
    # judge's margin, it is the mode's rival.
    accepted = osc is not None and osc_decision is not None and osc_decision.accepted
    osc_left = (
        unexplained(record, osc.x, alpha=policy.noise_alpha, tolerance=policy.noise_tolerance)
        if accepted and osc is not None
        else None
    )
    osc_explains = (
        osc is not None
        and osc_left is not None
        and (
            osc_left.consistent_with_noise
            or _explained(record.x - base.x, record.x - osc.x, noise_um) >= policy.confident_share
        )
    )
    other = osc if osc_explains else None
    if (
        osc is not None
        and osc_decision is not None
        and other is None
        and (accepted or abs(osc_decision.gain.t) <= osc_decision.threshold)
    ):
        # The record does not tell the oscillator from the input-driven model's mode.
        for k in final.names:
            if effect_class(k).signature == "peak":
                rivals.setdefault(k, set()).add(osc.name)
    returned_x, returned_cv = (other.x, other.cv) if other is not None else (final.x, final.cv)
    x = record.x
    err_b, err_e = x - base.x, x - returned_x
    left = (
        osc_left
        if other is not None and osc_left is not None
        else unexplained(record, returned_x, alpha=policy.noise_alpha, tolerance=policy.noise_tolerance)
    )
    share = _explained(err_b, err_e, noise_um)
    added = _order_added(state, final.names)
    named = tuple(
        _named(e, rivals, final, left, share, policy) for e in effects_of(final.fit.effects) if e.name in added
    )
    named = tuple(sorted(named, key=lambda e: added.index(e.name)))
    structure = None if other is None else _structure(other)
    if other is not None:
        # The effects of the input-driven model the oscillator refutes are its rival's.
        why = "the hysteretic oscillator predicts the record better: this effect is the refuted input-driven model's"
        named = tuple(replace(e, level="tentative", why=why, rivals=(*e.rivals, other.name)) for e in named)
    cv_before, cv_after = on_common_blocks(base.cv, returned_cv, policy.folds)
    unseen = Unseen(
        folds=policy.folds,
        cv_rms_before_um=cv_before,
        cv_rms_after_um=cv_after,
        validation=(
            OnValidation(len(validate), prediction_error(base.fit, validate), prediction_error(final.fit, validate))
            if validate is not None
            else None
        ),
    )
    evidence: dict[str, Any] = {
        "policy": policy.to_dict(),
        "convergence": {"method": conv.method, "margin": conv.margin, "tol": conv.tol},
        "noise_um": noise_um,
        "residual": fit_evidence(record, base.fit, base.x, policy.max_delay_samples),
        "rounds": [r.to_dict() for r in state.rounds],
        "stopped": state.stopped,
        "validation": [d.to_dict() for d in on_validation],
        "explained_share": share,
        "unseen": unseen.to_dict(),
        "lookalike": lookalike_tests(record, returned_x),
        "structure": (
            {"tried": False, "why": osc_skipped}
            if osc is None
            else {"tried": True, "held_out_rms_um": osc.cv.rms_um, "fit": osc.fit.to_dict()}
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
        named_effects=named,
        decisions=(*decisions, *on_validation),
        taken=tuple(r.taken for r in state.rounds if r.taken is not None),
        at_bounds=fits.on_bounds(final.fit, record, policy.bound_tolerance),
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


def _order_added(state: Search, names: tuple[str, ...]) -> list[str]:
    """``names`` in the order the search added them."""
    order: list[str] = []
    for r in state.rounds:
        if r.taken is not None and r.taken.move != "drop":
            order += [k for k in r.taken.effects if k not in order]
    return [k for k in order if k in names] + [k for k in names if k not in order]


def _settle(
    record: Record,
    validate: Record,
    final: Scored,
    rivals: dict[str, set[str]],
    swaps: dict[frozenset[str], Scored],
    policy: DiagnosisPolicy,
    conv: Convergence,
    say: Any,
) -> tuple[Scored, dict[str, set[str]], dict[frozenset[str], Scored], list[Decision]]:
    """The explanations the record could not tell apart, settled on the validation
    record (:func:`~boucwen.diagnosis.unseen.settled`): the model kept, its rivals left,
    the swaps still fitted from it, and the decisions."""
    members = explanations(record, final, rivals, swaps, conv, policy)
    if len(members) < 2:
        return final, rivals, swaps, []
    say(f"settling {', '.join(m.label for m in members)} on the validation record")
    left, decisions = settled(
        validate, [m.fit for m in members], [m.label for m in members], policy, noise_level(validate.x).sigma_um, say
    )

    def error(i: int) -> float:
        e = prediction_error(members[i].fit, validate)
        return math.inf if e is None else e.rms_um

    keep = 0 if 0 in left else min(left, key=error)
    chosen = members[keep]
    if chosen.replaces is None or chosen.scored is None:
        kept = {
            k: {m.replaces[1] for i, m in enumerate(members) if i in left and m.replaces and m.replaces[0] == k}
            for k in rivals
        }
        return final, kept, {k: v for k, v in swaps.items() if any(m.scored is v for m in members)}, decisions
    out, into = chosen.replaces
    say(f"the validation record refutes {members[0].label}: the model takes {chosen.label}")
    left_for = {
        m.replaces[1] for i, m in enumerate(members) if i in left and i != keep and m.replaces and m.replaces[0] == out
    }
    return chosen.scored, {into: left_for}, {}, decisions


def _explained(err_before: FloatArray, err_after: FloatArray, noise_um: float) -> float:
    """The share of the error beyond the noise [µm] that the model of residual
    ``err_after`` explains, against the base model's ``err_before`` [-]."""
    beyond_before = max(float(np.mean(err_before**2)) - noise_um**2, 0.0)
    beyond_after = max(float(np.mean(err_after**2)) - noise_um**2, 0.0)
    return 1.0 - beyond_after / beyond_before if beyond_before > 0 else 1.0


def _structure(osc: Structure) -> NamedStructure:
    """The oscillator returned (module docs, step 7): it passed the judge against the
    input-driven model, so that model is not within its margin, and it explains the
    record, the condition of its return."""
    why = "it predicts held-out blocks better than the best input-driven model beyond that model's margin"
    return NamedStructure(osc.name, "confident", why, osc.fit, osc.cv.rms_um)


def _named(
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
            f"the model explains {share:.0%} of the error beyond the noise and leaves a residual that is not "
            "noise: the effects may stand in for something outside the vocabulary",
        )
    return NamedEffect(effect, "confident", "no rival within the judge's margin; the model explains the record")
