"""The end of a diagnosis: the effects judged on a second record, the final refit, what
it leaves, its errors on unseen data and how sure each name is (:func:`outcome`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from .._core import EffectSet
from ..effects import ExtendedFit, fit_extended_record
from ..fit import FitResult
from ..io import jsonable
from ..metrics import max_abs, rms
from ..record import Record
from .confidence import confidence
from .credit import Credit, earns, explained_share, partial
from .margins import PATH, CloseCalls
from .policy import DiagnosisPolicy
from .report import Diagnosis, ModelFit
from .scoring import base_fit, cv_rms, on_bounds
from .starts import null_effort
from .unexplained import unexplained
from .unseen import OnValidation, Unseen, judged_on, prediction_error

__all__ = ["final_refit", "outcome"]


def final_refit(record: Record, current: ExtendedFit, policy: DiagnosisPolicy) -> ExtendedFit:
    """The kept effects refitted on the whole record from the search's fit, at most
    ``final_nfev`` evaluations (a polish: the trials converged, or nearly)."""
    return fit_extended_record(record, current.params, current.effects, current.h0, max_nfev=policy.final_nfev)


def outcome(
    record: Record,
    base: FitResult,
    current: ExtendedFit,
    added: list[str],
    evidence: dict[str, Any],
    *,
    validate: Record | None,
    policy: DiagnosisPolicy,
    say: Callable[[str], None],
    calls: CloseCalls,
    started: float,
) -> Diagnosis:
    """The :class:`~boucwen.diagnosis.Diagnosis` of ``record`` whose search ended with
    ``current`` holding the effects ``added`` (the base model's fit ``base``; the
    search's ``evidence``, completed here): with a second record (``validate``) each
    effect must also predict it better; the kept effects refitted on the whole record
    (``final_nfev``); what they leave, and whether it makes them tentative
    (``partial_share``); the errors on unseen data; the confidence of each name; the
    parameters on a bound. ``started``: :func:`time.perf_counter` at the start."""
    u, x, dt = record.u, record.x, record.dt
    x_base = base.x_fit
    if validate is not None and added:
        say(f"judging {', '.join(added)} on the validation record ({len(validate)} samples)")

        def refit(effects: EffectSet) -> ExtendedFit:
            return fit_extended_record(
                record, current.params, effects, current.h0, max_nfev=null_effort(policy), tol=policy.trial_tol
            )

        current, added, evidence["validation"] = judged_on(validate, current, added, refit, say)
    if added:
        say("refitting on the whole record")
        ext = final_refit(record, current, policy)
        x_ext = ext.simulate(u, dt)
        returned = ModelFit(ext.params, ext.h0)
        effect_set = ext.effects
    else:
        x_ext = x_base.copy()
        returned = ModelFit(base.params, base.h0)
        effect_set = EffectSet()
    left = unexplained(record, x_ext, alpha=policy.alpha, tolerance=policy.tolerance)
    share = explained_share(rms(x - x_base), rms(x - x_ext), left.noise_um)
    evidence["explained_share"] = share
    is_partial = bool(added) and partial(rms(x - x_base), rms(x - x_ext), left, policy)
    if is_partial:
        # The effects earned their parameters on unseen data and stay in the model;
        # what they leave is not noise, so they may stand in for something else
        # (their confidence says so, and ``unexplained`` what is left).
        say(f"{', '.join(added)}: {share:.0%} of the error beyond the noise explained; the rest is unexplained")
        evidence["partial"] = {"effects": list(added), "explained_share": share, "rms_um": rms(x - x_ext)}
    plain = base_fit(base)
    final = ext if added else plain
    cv_before = cv_rms(record, plain, policy.folds)
    on_validation = (
        OnValidation(len(validate), prediction_error(plain, validate), prediction_error(final, validate))
        if validate is not None
        else None
    )
    unseen = Unseen(
        folds=policy.folds,
        cv_rms_before_um=cv_before,
        cv_rms_after_um=cv_rms(record, final, policy.folds) if added else cv_before,
        validation=on_validation,
    )
    evidence["unseen"] = unseen.to_dict()
    err_b, err_e = x - x_base, x - x_ext
    say(left.summary())
    evidence["close_calls"] = calls.to_list()
    on_answer = sorted({c["decision"] for c in evidence["close_calls"] if c["kind"] != PATH})
    if on_answer:
        say(f"close call(s) on the answer, decided by the margin rule: {', '.join(on_answer)}")
    evidence["elapsed_s"] = time.perf_counter() - started
    result = Diagnosis(
        effects=added,
        rms_before_um=rms(err_b),
        max_before_um=max_abs(err_b),
        rms_after_um=rms(err_e),
        max_after_um=max_abs(err_e),
        params=returned.params,
        h0_um=returned.h0_um,
        base_only=ModelFit(base.params, base.h0),
        evidence=jsonable(evidence),
        x_base=x_base,
        x_extended=x_ext,
        effect_set=effect_set,
        unexplained=left,
        confidence=confidence(
            added,
            evidence,
            policy.lookalike_margin,
            explained=share if is_partial else None,
            earns=lambda trial: earns(Credit.from_dict(trial), policy),
        ),
        at_bounds=on_bounds(final, record, policy),
        unseen=unseen,
    )
    say(result.summary())
    return result
