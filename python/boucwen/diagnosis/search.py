"""The greedy search of the diagnosis: add the effect that best explains the record's
error under blocked cross-validation, while it earns its parameters (procedure in
:mod:`boucwen.diagnosis`; every threshold from a
:class:`~boucwen.diagnosis.policy.DiagnosisPolicy`)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..checks import check_int
from ..effects import DIAGNOSIS_METHOD, VOCABULARY, ExtendedFit, effect_class, simulate_chain
from ..fit import fit_record
from ..progress import Progress, reporter
from ..record import Record, validate_record
from .backward import backward_step
from .credit import partial
from .evidence import fit_evidence
from .margins import CloseCalls
from .outcome import outcome
from .pairs import pair_round, pairs_wanted
from .policy import DiagnosisPolicy
from .rebase import fits_better, rebased
from .report import Diagnosis
from .rounds import Round, candidates, score_round
from .scoring import Scored, base_fit, solved_at
from .screening import hopeless_direction, peak_beyond, screen_copy, screenable, to_confirm
from .unexplained import Unexplained, noise_level, unexplained
from .validation import FOLDS

__all__ = ["FOLDS", "MAX_DELAY_SAMPLES", "MIN_GAIN", "TRIAL_NFEV", "diagnose", "diagnose_record"]

#: The default policy's least gain, iteration limit of a trial and largest delay
#: [samples] (:class:`~boucwen.diagnosis.policy.DiagnosisPolicy`).
MIN_GAIN = DiagnosisPolicy().min_gain
TRIAL_NFEV = DiagnosisPolicy().trial_nfev
MAX_DELAY_SAMPLES = DiagnosisPolicy().max_delay_samples


def diagnose(
    u: ArrayLike,
    x: ArrayLike,
    dt: float,
    *,
    progress: Progress = False,
    folds: int | None = None,
    min_gain: float | None = None,
    max_effects: int = 3,
    seed: int = 0,
    workers: int | None = None,
    validate: tuple[ArrayLike, ArrayLike, float] | None = None,
    policy: DiagnosisPolicy | None = None,
) -> Diagnosis:
    """Finds which effects of the vocabulary the record holds beyond the base model.

    Args:
        u: voltage [V], 1-D, finite, not constant, uniformly sampled.
        x: measured displacement [µm], same length.
        dt: sampling interval [s] (> 0).
        progress: ``True`` prints progress lines to stderr; or a callable taking a str
            (the trials' lines come from the threads that run them, one at a time).
        folds: contiguous blocks of the cross-validation (2 … 10); overrides the
            policy's.
        min_gain: least relative cut of the cross-validated RMS error an effect must
            bring to be kept (0 … 1); overrides the policy's.
        max_effects: most effects added (0 … 5).
        seed: seed of :func:`boucwen.fit`'s random starts.
        workers: threads for the trials of a round and for each fit's Jacobian
            (default: the number of CPUs; 1 runs everything in turn).
        validate: a second record of the same device, ``(u [V], x [µm], dt [s])``: each
            effect must also predict it better (:mod:`~boucwen.diagnosis.unseen`), and the
            report gives both models' errors on it.
        policy: the thresholds (:class:`~boucwen.diagnosis.policy.DiagnosisPolicy`;
            the default instance when None).

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
        min_gain=min_gain,
        max_effects=max_effects,
        seed=seed,
        workers=workers,
        validate=None if validate is None else validate_record(*validate),
        policy=policy,
    )


def _policy_of(policy: DiagnosisPolicy | None, folds: int | None, min_gain: float | None) -> DiagnosisPolicy:
    """``policy`` (the default when None) with the options given beside it."""
    if policy is not None and not isinstance(policy, DiagnosisPolicy):
        raise TypeError(f"policy must be a DiagnosisPolicy, got {type(policy).__name__}")
    chosen = policy if policy is not None else DiagnosisPolicy()
    changes: dict[str, Any] = {}
    if folds is not None:
        changes["folds"] = folds
    if min_gain is not None:
        changes["min_gain"] = min_gain
    return chosen.replace(**changes) if changes else chosen


def _screened_round(
    record: Record,
    screen: Record,
    current: ExtendedFit,
    current_jac: Any,
    policy: DiagnosisPolicy,
    opts: dict[str, Any],
) -> tuple[Round, Round, Any]:
    """A round on a screened record: the trials on the copy, then the best (and the
    runner-up within ``confirm_ratio``), the effects of whole samples of the full rate
    and, where the residual peaks beyond the copy, the modes, on the full record.
    Returns the round that decides, the screened round and the current Jacobian."""
    say = opts["say"]
    present = current.effects.names
    names = tuple(k for k in candidates(present) if not effect_class(k).full_rate_only)
    screened = score_round(screen, current, names=names, **opts)
    scores = {k: float(t["cv_rms_um"]) for k, t in screened.evidence["trials"].items() if "cv_rms_um" in t}
    fits = dict(screened.ranked)
    confirm = {k: fits[k] for k in to_confirm([k for k, _ in screened.ranked], scores, policy)}
    full_only = [k for k in candidates(present) if k not in names]
    for k in list(full_only):
        xs = simulate_chain(current.params, current.effects, record.u, record.dt, current.h0)
        if xs is None or effect_class(k).direction(xs) is None:
            continue
        solved = solved_at(record, current, current_jac)
        current_jac = solved.jacobian
        if hopeless_direction(record, solved, k, policy.folds, policy):
            say(f"  - {k:9s}: hopeless: its first-order change does not explain the residual")
            full_only.remove(k)
    modes = [k for k in VOCABULARY if effect_class(k).spectral_peak]
    if modes and all(k in names for k in modes) and peak_beyond(record, current, screen.dt, policy):
        full_only += modes
    todo = tuple(k for k in VOCABULARY if k in confirm or k in full_only)
    say(f"confirming {list(todo)} on the full record")
    if not todo:
        return screened, screened, current_jac
    round_ = score_round(
        record,
        current,
        names=todo,
        starts=confirm,
        trial_nfev=policy.confirm_nfev,
        current_jacobian=current_jac,
        **opts,
    )
    round_.evidence["screening"] = screened.evidence
    return round_, screened, current_jac


def diagnose_record(
    record: Record,
    *,
    progress: Progress = False,
    folds: int | None = None,
    min_gain: float | None = None,
    max_effects: int = 3,
    seed: int = 0,
    workers: int | None = None,
    validate: Record | None = None,
    policy: DiagnosisPolicy | None = None,
) -> Diagnosis:
    """:func:`diagnose` on a checked :class:`~boucwen.record.Record` (same options, same
    result; ``validate`` a checked record too)."""
    started = time.perf_counter()
    say = reporter(progress, "diagnose", started)
    policy = _policy_of(policy, folds, min_gain)
    max_effects_ = check_int("max_effects", max_effects, 0, 5)
    u, x, dt = record.u, record.x, record.dt
    n = u.size
    if n < 100:
        raise ValueError(f"diagnose needs at least 100 samples, got {n}")
    if not np.ptp(u) > 0:
        raise ValueError("u is constant; the diagnosis needs a varying voltage")
    screen, q = screen_copy(record, policy)
    noise_um = noise_level(x).sigma_um

    say(f"fitting the base model on {n} samples")
    base = fit_record(record, seed=seed, workers=workers, decimate=q if q > 1 else None, method=DIAGNOSIS_METHOD)
    current = base_fit(base)
    say(
        f"base model: RMS {base.rms_um:.4g} µm; {policy.folds} folds"
        + (f"; trials screened every {q}th sample" if q > 1 else "")
    )
    evidence: dict[str, Any] = {
        "folds": policy.folds,
        "screen_decimation": q,
        "min_gain": policy.min_gain,
        "local_min_gain": policy.local_min_gain,
        "policy": policy.to_dict(),
        "residual": fit_evidence(record, current, base.x_fit, policy.max_delay_samples),
        "rounds": [],
    }
    added: list[str] = []
    calls = CloseCalls()
    opts: dict[str, Any] = {"policy": policy, "workers": workers, "say": say, "calls": calls}
    # ∂x̂/∂z of the current model over the full record, once known.
    current_jac: Any = None
    # What the current model leaves, once an effect is kept.
    left_now: Unexplained | None = None
    last_null: Scored | None = None

    while len(added) < max_effects_:
        if left_now is not None and left_now.consistent_with_noise:
            say("the residual is consistent with noise: nothing left to explain")
            evidence["stopped"] = "the residual of the effects kept is consistent with noise"
            break
        say(f"round {len(added) + 1}: trying {list(candidates(current.effects.names))}")
        screened: Round | None = None
        if q == 1 or not screenable(current, screen):
            round_ = score_round(record, current, current_jacobian=current_jac, **opts)
        else:
            round_, screened, current_jac = _screened_round(record, screen, current, current_jac, policy, opts)
        left_rms = round_.evidence["current"]["in_sample_rms_um"]
        if round_.kept is None and pairs_wanted(left_rms, noise_um, q > 1, policy):
            paired = pair_round(record, current, round_, noise_um=noise_um, **opts)
            round_ = paired or round_
        evidence["rounds"].append(round_.evidence)
        if round_.kept is None:
            fresh = None
            if (
                left_now is not None
                and "rebased" not in evidence
                and partial(base.rms_um, current.rms_um, left_now, policy)
            ):
                # The effects kept explain too little: refitted once from a fresh base
                # model, the search goes on from there if that fits better.
                fresh = rebased(record, current, seed=seed, workers=workers, q=q, policy=policy)
                evidence["rebased"] = {"rms_um": current.rms_um, "fresh_rms_um": fresh.rms_um if fresh else None}
                if fresh is not None and not fits_better(fresh, current, policy):
                    fresh = None
            if fresh is None:
                say("nothing left that earns its parameters under cross-validation")
                if round_ is screened or q == 1:
                    last_null = round_.null
                break
            say(f"refitted from a fresh base model: RMS {current.rms_um:.4g} → {fresh.rms_um:.4g} µm")
            current, current_jac = fresh, None
        else:
            new = [k for k in round_.kept.effects.names if k not in current.effects.names]
            current = round_.kept
            # The kept fit's Jacobian is over the full record unless the screened round is the result.
            current_jac = None if round_ is screened else round_.kept_jacobian
            added += new
            say(f"kept {', '.join(new)}: RMS {current.rms_um:.4g} µm")
        left_now = unexplained(record, current.simulate(u, dt), alpha=policy.alpha, tolerance=policy.tolerance)

    if len(added) >= 2:
        current, added = backward_step(record, screen, current, added, evidence, null=last_null, **opts)
    return outcome(
        record, base, current, added, evidence, validate=validate, policy=policy, say=say, calls=calls, started=started
    )
