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
   has none), drop one, swap one for a rival (:mod:`~boucwen.diagnosis.search`). Score
   each add at the current model first (:mod:`~boucwen.diagnosis.score`: the score test
   of the effect's parameters, the supremum over a grid of those that exist only under
   the alternative) and fit only those whose score could pass the judge, to convergence
   from the effect's best starts by that score.
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

With other records of the device (``validate``: one or several — the recorded
experiment, another day, another excitation), each left out whole of the fit, the
explanations the first record left are settled there (one is refuted where another passes
the judge against it there; the model keeps the one left), and each effect of the device
must also earn its place there by the same judge, the model carried to each record with
that record's offset, trend and initial state re-estimated on it
(:mod:`~boucwen.diagnosis.unseen`); the report gives each record's error before and
after.

Every number is a field of :class:`~boucwen.diagnosis.policy.DiagnosisPolicy`; what
describes one effect is on its class. What the residual follows (spectral lines, spans,
the look-alike tests of :mod:`boucwen.residual`) is evidence reported beside the answer;
it never accepts or rejects. Every rule is in :mod:`~boucwen.diagnosis.rules`, each
decision naming the one that decided it. Modules: :mod:`~boucwen.diagnosis.policy` (the
numbers), :mod:`~boucwen.diagnosis.rules` (the rules and their reasons),
:mod:`~boucwen.diagnosis.heldout` (the folds and the held-out errors),
:mod:`~boucwen.diagnosis.score` (the screen before any fit),
:mod:`~boucwen.diagnosis.judge` (the test),
:mod:`~boucwen.diagnosis.fits` (converged fits of candidates),
:mod:`~boucwen.diagnosis.search` (the moves and their loop),
:mod:`~boucwen.diagnosis.outcome` (the model returned and how sure each name is),
:mod:`~boucwen.diagnosis.unseen` (errors on another record, the validation record),
:mod:`~boucwen.diagnosis.experiment` (the next experiment),
:mod:`~boucwen.diagnosis.report` (:class:`Diagnosis`, its files).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..checks import check_int
from ..fit import fit_record
from ..progress import Progress, reporter
from ..record import Record, validate_record
from ..residual import Unexplained, lookalike_tests, noise_level, residual_evidence, unexplained
from ..residual import residual_evidence_record as residual_evidence_record
from . import fits
from .experiment import Experiment
from .fits import Convergence
from .judge import Decision
from .outcome import outcome
from .policy import DiagnosisPolicy
from .report import AtBound, Diagnosis, ModelFit, NamedEffect, NamedStructure, write_predictions, write_report
from .search import search
from .unseen import OnValidation, Unseen

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
    validate: tuple[ArrayLike, ArrayLike, float] | Sequence[tuple[ArrayLike, ArrayLike, float]] | None = None,
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
        validate: other records of the same device, each ``(u [V], x [µm], dt [s])``
            (one such tuple, or a list of them): each effect must also earn its place
            on them together (:mod:`~boucwen.diagnosis.unseen`), and the report gives
            both models' errors on each.
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
        validate=_records_of(validate),
        policy=policy,
        convergence=convergence,
    )


def _records_of(
    validate: tuple[ArrayLike, ArrayLike, float] | Sequence[tuple[ArrayLike, ArrayLike, float]] | None,
) -> tuple[Record, ...]:
    """The validation records ``validate`` gives (none, one ``(u, x, dt)`` or a list of
    them), each checked; the k-th named ``"validation record k"`` (from 1)."""
    if validate is None:
        return ()
    if not isinstance(validate, (tuple, list)):
        raise TypeError(f"validate must be (u, x, dt) or a list of them, got {type(validate).__name__}")
    # One record is (u, x, dt) with dt a number; a list of records holds tuples.
    one = len(validate) == 3 and isinstance(validate[2], (int, float, np.number))
    items = [validate] if one else list(validate)
    if not items:
        raise ValueError("validate holds no record: give (u, x, dt) or a list of them, or None")
    out = []
    for k, item in enumerate(items, 1):
        if not isinstance(item, (tuple, list)) or len(item) != 3:
            raise TypeError(f"validate record {k} must be (u, x, dt)")
        u, x, dt = item
        out.append(validate_record(u, x, dt, name=f"validation record {k}"))
    return tuple(out)


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
    validate: Record | Sequence[Record] | None = None,
    policy: DiagnosisPolicy | None = None,
    convergence: Convergence | None = None,
) -> Diagnosis:
    """:func:`diagnose` on a checked :class:`~boucwen.record.Record` (same options, same
    result; ``validate`` a checked record or a sequence of them)."""
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
    others = () if validate is None else (validate,) if isinstance(validate, Record) else tuple(validate)
    return outcome(record, base, state, others, policy, conv, noise_um, say, started, workers)
