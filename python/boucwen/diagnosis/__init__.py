"""Diagnosis: which effects a record holds beyond the base model, judged on unseen data.

:func:`diagnose` takes a record (voltage u [V], displacement x [µm], interval dt [s]),
not told what it contains, and selects a model by one loop under one judge:

1. **Fit the base model** to convergence (:func:`boucwen.fit`'s global search of
   starts, then Levenberg–Marquardt on the core's exact Jacobian to the statistical
   stop: :mod:`~boucwen.diagnosis.fits`).
2. **Score it on unseen data**: forward validation over ``folds`` origins, each fold
   predicted by the model refitted on the record before it (:mod:`~boucwen.diagnosis.judge`).
3. **Propose every move** from the current model: add an effect of the vocabulary
   (:data:`boucwen.effects.VOCABULARY`; a second mode with the first where the model
   has none), drop one, swap one for a rival (:mod:`~boucwen.diagnosis.search`). Fit
   each candidate to convergence from the effect's physical starts (several where it has
   local optima).
4. **Judge each move** by the same test (:mod:`~boucwen.diagnosis.judge`): each fold,
   refitted on the record's past before its origin, predicts the samples after it
   (forward validation, origins placed by the record's excitation: half its voltage
   travel, half its elapsed time); the per-sample loss difference d_i = e_ref,i² −
   e_cand,i² must exceed its Newey–West standard error (bandwidth: the dependence length
   of the better model's residual) by t₁₋ₐ with a = α/(R·m), the family error over the
   whole search at most α, and remove at least ``min_share`` of the reference's held-out
   error beyond the record's noise (an effect, not a reshaping of the base model's
   misfit). A drop is accepted where the effect no longer passes that test against the
   model without it. Each held-out error is first screened (the first Gauss–Newton step
   of each fold's refit) and read from converged refits wherever a decision could go
   either way.
5. **Take one move**: an accepted drop first; else the accepted add or swap of largest
   statistic — through its **ambiguity set**, the candidates the record cannot tell from
   it (neither's gain over the other passes the test): the model takes the accepted
   member with the fewest unknowns, then the largest statistic; the others are its
   rivals, reported with their held-out errors and tried as swaps later.
6. **Repeat** from 3 until no move is accepted. Where the residual is consistent with
   the record's noise (:func:`boucwen.residual.unexplained`) a round proposes only the
   drops and the other structure, and the search ends where none is accepted. A model already held is never
   proposed again.
7. **The other structure** is one more move of every round: the input-driven model
   replaced by the hysteretic oscillator (:mod:`boucwen.oscillator`: the hysteresis
   driven by the output's motion, the input a force), fitted once and judged by the same
   test against the current model. Taken, it is the returned model, and the effects of
   the input-driven model it replaced keep it as their rival.
8. **Report**: the returned model's errors before and after, what it leaves
   (``unexplained``), the held-out errors of the base and returned models (``unseen``),
   each name ``confident`` only where it has no rival and the model removes at least
   ``confident_share`` of the base model's error beyond the noise (else ``tentative``,
   with the rivals), every decision typed (``decisions``), the parameters on a bound,
   and whether the returned model stays bounded over the record's range
   (``boundedness``, :func:`boucwen.boundedness.check`; every fit keeps to the admissible
   region, and a candidate that fails the check is no candidate).

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
from ..checks import check_int
from ..effects import effects_of
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
from .judge import Decision, on_common_folds
from .policy import DiagnosisPolicy
from .report import AtBound, Diagnosis, ModelFit, NamedEffect, NamedStructure, write_predictions, write_report
from .search import OSCILLATOR, Search, rival_order, search
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
        folds: folds of the forward validation (2 … 10); overrides the
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
    base = fits.base(record, offline, conv, policy.folds, policy.first_origin)
    forward = base.cv.folds
    say(
        f"base model: RMS {base.fit.rms_um:.4g} µm, held-out {base.cv.rms_um:.4g} µm "
        f"({forward.count} forward folds from sample {forward.tested.start})"
    )
    state = search(
        record,
        base,
        noise_um=noise_um,
        policy=policy,
        conv=conv,
        workers=workers,
        say=say,
    )
    say(f"search ended: {state.stopped}")
    return _outcome(record, base, state, validate, policy, conv, noise_um, say, started, workers)


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
    workers: int | None,
) -> Diagnosis:
    """The :class:`Diagnosis` of the search ``state``: the model judged on the validation
    record, its errors, what it leaves, how sure each name is."""
    decisions = [d for r in state.rounds for d in r.decisions]
    final = state.input_driven
    other = state.current if isinstance(state.current, Structure) else None
    rivals = {k: set(v) for k, v in state.rivals.items()}
    swaps = dict(state.swaps)
    on_validation: list[Decision] = []
    if validate is not None and other is None:
        final, rivals, swaps, on_validation = _settle(record, validate, final, rivals, swaps, policy, conv, say)
    if validate is not None and other is None and final.names:
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
            final = fits.scored(record, fits.solved_at(record, kept), final.cv.folds, conv, exact=True, workers=workers)
    returned: Scored | Structure = other if other is not None else final
    returned = fits.confirmed(record, returned, workers)
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
    named = tuple(
        _named(e, rivals, final, left, share, policy) for e in effects_of(final.fit.effects) if e.name in added
    )
    named = tuple(sorted(named, key=lambda e: added.index(e.name)))
    structure = None if other is None else _structure(other, rivals)
    if other is not None:
        # The effects of the input-driven model the oscillator refutes are its rival's.
        why = "the hysteretic oscillator predicts the record better: this effect is the refuted input-driven model's"
        named = tuple(
            replace(e, level="tentative", why=why, rivals=tuple(sorted({*e.rivals, other.name}, key=rival_order)))
            for e in named
        )
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
    the swaps still fitted from it, and the decisions. The model keeps the returned
    explanation where the validation record does not refute it; else, of those it leaves
    (which it cannot tell apart), the simplest, then the one whose gain over the refuted
    model has the largest statistic."""
    members = explanations(record, final, rivals, swaps, conv, policy)
    if len(members) < 2:
        return final, rivals, swaps, []
    say(f"settling {', '.join(m.label for m in members)} on the validation record")
    left, decisions = settled(
        validate, [m.fit for m in members], [m.label for m in members], policy, noise_level(validate.x).sigma_um, say
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
    say(f"the validation record refutes {members[0].label}: the model takes {chosen.label}")
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
            f"the model removes {share:.0%} of the base model's error beyond the noise (the least of its held-out "
            "share and, before the first origin where no fold predicts, its in-sample share) and leaves a residual "
            "that is not noise: the effects may stand in for something outside the vocabulary",
        )
    return NamedEffect(effect, "confident", "no rival within the judge's margin; the model explains the record")
