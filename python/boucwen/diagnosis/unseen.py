"""What a model predicts on data its fit did not see.

Two kinds of unseen data judge the returned model:

* **forward validation** on the record itself (:mod:`~boucwen.diagnosis.judge`: each
  fold predicted by the model refitted on the record before it), for every record;
* **other records of the same device** (``validate``: one or several — another day,
  another excitation), where the user has them: the model fitted on the first record
  carried to each, every record left out whole of the fit. What is carried is the
  *device*: the hysteresis and every effect of the actuator, its amplifier and its
  mechanics. What belongs to the *record* is re-estimated on the second one, for every
  model alike: the offset (a different mounting, a different zero), a linear trend
  (thermal and sensor drift depend on the day, not on the device), the initial
  hysteresis state h0 (it depends on what the voltage did before the record began,
  which neither record holds); the record's own effects
  (:attr:`boucwen.effects.Effect.of_record`: a drift, a mains pickup whose phase is the
  record's) are left out.

On the other records each effect of the device must earn its place by the same judge
as on the first (:func:`~boucwen.diagnosis.judge.judge`, its held-out gain against its
batch-means sampling error): the model with it against the model without it (the others
refitted without it on the first record), both carried, their errors on every other
record counted together (each record's own part re-estimated on it: :func:`carried_to`);
one that does not earn its place there is dropped (:func:`judged_on`). The record's own
effects are judged on the record itself.

Where the first record could not tell an effect from its rivals, the other records settle
the set (:func:`settled`): every explanation carried there, one is refuted where another
is accepted against it by the same judge; the model keeps the explanation left (the one
the second record predicts best where several are), and a name with no rival left is no
longer tentative for want of one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from .._core import EffectSet
from ..checks import FloatArray
from ..effects import ExtendedFit, effect_class, simulate_chain
from ..effects.base import without
from ..metrics import max_abs, rms
from ..record import Record
from ..residual import noise_level
from .heldout import CrossValidation, less_record_part
from .judge import Decision, gain, judge, level
from .policy import DiagnosisPolicy

__all__ = [
    "OnValidation",
    "Unseen",
    "ValidationError",
    "carried",
    "carried_to",
    "judged_on",
    "pooled_noise",
    "prediction_error",
    "settled",
]


@dataclass(frozen=True)
class ValidationError:
    """Errors [µm] of a model carried to a record it was not fitted on (:func:`carried`),
    with what was re-estimated there: the offset ``offset_um`` [µm], the trend
    ``trend_um_per_s`` [µm/s] and the initial hysteresis state ``h0_um`` [µm]."""

    rms_um: float
    max_um: float
    offset_um: float
    trend_um_per_s: float
    h0_um: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class OnValidation:
    """The base and returned models carried to one validation record.

    Attributes:
        samples: its number of samples.
        before, after: the base and returned models' errors there (None where one
            cannot be simulated over it).
        name: the record's name (its file, or ``"record k"``).
    """

    samples: int
    before: ValidationError | None
    after: ValidationError | None
    name: str = ""

    @property
    def ratio(self) -> float:
        """The returned model's RMS error over the base model's there [-] (nan where
        either is missing): below 1, the returned model carries better."""
        if self.before is None or self.after is None or self.before.rms_um <= 0:
            return math.nan
        return self.after.rms_um / self.before.rms_um

    def to_dict(self) -> dict[str, Any]:
        """``{"name", "samples", "before", "after", "ratio"}`` (JSON-ready)."""
        return {
            "name": self.name,
            "samples": self.samples,
            "before": None if self.before is None else self.before.to_dict(),
            "after": None if self.after is None else self.after.to_dict(),
            "ratio": self.ratio,
        }


@dataclass(frozen=True)
class Unseen:
    """Errors [µm] on data the fits did not see.

    Attributes:
        folds: folds of the forward validation.
        cv_rms_before_um, cv_rms_after_um: its RMS error, base and returned models [µm],
            over the folds whose refits converged for both.
        validation: with validation records, both models carried to each, in order;
            else empty.
    """

    folds: int
    cv_rms_before_um: float
    cv_rms_after_um: float
    validation: tuple[OnValidation, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """``{"folds", "cv_rms_before_um", "cv_rms_after_um"}`` and, with validation
        records, ``"validation"``: one entry per record (JSON-ready)."""
        out: dict[str, Any] = {
            "folds": self.folds,
            "cv_rms_before_um": self.cv_rms_before_um,
            "cv_rms_after_um": self.cv_rms_after_um,
        }
        if self.validation:
            out["validation"] = [v.to_dict() for v in self.validation]
        return out


def device_part(effects: EffectSet) -> EffectSet:
    """``effects`` less the record's own (:attr:`boucwen.effects.Effect.of_record`)."""
    for name in effects.names:
        if effect_class(name).of_record:
            effects = without(effects, name)
    return effects


def carried(fit: ExtendedFit, record: Record) -> tuple[FloatArray, ValidationError] | None:
    """The displacement [µm] ``fit`` predicts over ``record`` when carried there (its
    device part, with what is the record's own re-estimated there
    (:data:`~boucwen.diagnosis.heldout.PER_RECORD`): the offset and the trend by least
    squares (:func:`~boucwen.diagnosis.heldout.less_record_part`), h0 by a bounded scalar
    search over ± the record's displacement span, kept only where it beats h0 = 0), and
    its error; None when it cannot be simulated."""
    effects = device_part(fit.effects)

    def fitted(h0: float) -> tuple[FloatArray, FloatArray] | None:
        xs = simulate_chain(fit.params, effects, record.u, record.dt, h0)
        if xs is None:
            return None
        left, offset, trend = less_record_part(record.x - xs, record.t)
        return record.x - left, np.array([offset, trend])

    def cost(h0: float) -> float:
        out = fitted(h0)
        return math.inf if out is None else rms(record.x - out[0])

    at_zero = fitted(0.0)
    if at_zero is None:
        return None
    span = max(float(np.ptp(record.x)), 1e-9)
    found = minimize_scalar(cost, bounds=(-span, span), method="bounded", options={"xatol": 1e-6 * span})
    h0, (x_hat, coef) = 0.0, at_zero
    best = fitted(float(found.x)) if found.fun < rms(record.x - at_zero[0]) else None
    if best is not None:
        h0, (x_hat, coef) = float(found.x), best
    err = record.x - x_hat
    return x_hat, ValidationError(
        rms_um=rms(err), max_um=max_abs(err), offset_um=float(coef[0]), trend_um_per_s=float(coef[1]), h0_um=h0
    )


def carried_to(fit: ExtendedFit, records: Sequence[Record]) -> FloatArray | None:
    """The residual [µm] of ``fit`` carried to each of ``records`` (:func:`carried`, each
    with its own part re-estimated there), the records one after another; None where it
    cannot be simulated over one of them."""
    out = []
    for record in records:
        one = carried(fit, record)
        if one is None:
            return None
        out.append(record.x - one[0])
    return np.concatenate(out)


def pooled_noise(records: Sequence[Record]) -> float:
    """The sensor noise [µm RMS] of ``records`` together: each record's
    (:func:`boucwen.residual.noise_level`), pooled by its samples."""
    n = sum(len(r) for r in records)
    return math.sqrt(sum(len(r) * noise_level(r.x).sigma_um ** 2 for r in records) / max(n, 1))


def prediction_error(fit: ExtendedFit, record: Record) -> ValidationError | None:
    """The error of ``fit`` carried to ``record`` (:func:`carried`); None when it cannot
    be simulated."""
    out = carried(fit, record)
    return None if out is None else out[1]


def judged_on(
    validation: Sequence[Record],
    current: ExtendedFit,
    refit_without: Callable[[ExtendedFit, str], ExtendedFit | None],
    policy: DiagnosisPolicy,
    noise_um: float,
    say: Callable[[str], None],
) -> tuple[ExtendedFit, list[Decision]]:
    """Each effect of the device in ``current`` judged on the ``validation`` records
    together (module docs): ``refit_without(model, name)`` is ``model`` refitted on the
    identification record without that effect (None where it cannot be); ``noise_um``
    the validation records' noise [µm]. Effects are judged in turn, the model updated
    after each drop. Returns the model and the decisions (``"drop"``, accepted where the
    effect is dropped)."""
    names = [
        k
        for k in current.effects.names
        if not effect_class(k).of_record and not any(effect_class(o).partner == k for o in current.effects.names)
    ]
    lvl = level(policy.alpha, len(names))
    decisions: list[Decision] = []
    # The current model's residual there, again only after a drop changes it.
    with_it = carried_to(current, validation)
    for name in names:
        rest = refit_without(current, name)
        without_it = None if rest is None else carried_to(rest, validation)
        if with_it is None or without_it is None or rest is None:
            continue
        keep_cv = CrossValidation.whole(with_it)
        rest_cv = CrossValidation.whole(without_it)
        keep = judge(
            "add",
            (name,),
            tuple(current.effects.names),
            tuple(rest.effects.names),
            gain(keep_cv, rest_cv),
            level_=lvl,
            noise_um=noise_um,
            min_share=policy.min_share,
            unknowns=0,
        )
        # A gain that cannot be computed keeps the effect: no decision from a number that is none.
        dropped = keep.rule != "not_judgeable" and not keep.accepted
        reason = (
            "on the validation records, "
            + ("it does not earn its place: " if dropped else "it earns its place or cannot be judged: ")
            + keep.reason
        )
        g = gain(rest_cv, keep_cv)
        decisions.append(
            Decision(
                "drop",
                (name,),
                tuple(rest.effects.names),
                tuple(current.effects.names),
                g,
                keep.threshold,
                keep.needed_um2,
                dropped,
                reason,
                0,
                rule="drop_earns" if keep.rule != "not_judgeable" else keep.rule,
            )
        )
        say(
            f"  validation {name:9s}: {rms(with_it):.4g} µm with it, {rms(without_it):.4g} µm without"
            + (" — dropped" if dropped else "")
        )
        if dropped:
            current, with_it = rest, without_it
    return current, decisions


def settled(
    validation: Sequence[Record],
    members: Sequence[ExtendedFit],
    labels: Sequence[str],
    policy: DiagnosisPolicy,
    noise_um: float,
    say: Callable[[str], None],
) -> tuple[tuple[int, ...], list[Decision]]:
    """The explanations (``members``, fitted on the identification record, named
    ``labels``) that the ``validation`` records do not refute: each carried there
    (:func:`carried_to`), a member is refuted where another is accepted against it by the
    judge (:func:`~boucwen.diagnosis.judge.judge`: significant at level α over the pairs,
    and at least ``min_share`` of its error beyond the noise ``noise_um`` [µm]). A member
    that cannot be carried is not refuted. Returns the indices left and the decisions
    (``"swap"`` from the refuted to the one that refutes it, accepted where it does)."""
    out = [carried_to(m, validation) for m in members]
    cvs = {i: CrossValidation.whole(o) for i, o in enumerate(out) if o is not None}
    # Each pair is tested once, in both directions at once (a two-sided test at level α
    # over the pairs: α/2 per side).
    pairs = [(i, j) for i in cvs for j in cvs if i < j]
    lvl = level(policy.alpha, 2 * max(len(pairs), 1))
    refuted: set[int] = set()
    decisions: list[Decision] = []
    for i, j in pairs:
        g = gain(cvs[j], cvs[i])
        # Oriented so that the candidate is the one that predicts the record better.
        a, b = (i, j) if g.mean_um2 >= 0 else (j, i)
        d = judge(
            "swap",
            (labels[a], labels[b]),
            (labels[b],),
            (labels[a],),
            gain(cvs[b], cvs[a]),
            level_=lvl,
            noise_um=noise_um,
            min_share=policy.min_share,
            unknowns=0,
        )
        decisions.append(replace(d, reason="on the validation records: " + d.reason))
        if d.accepted:
            refuted.add(a)
    left = tuple(i for i in range(len(members)) if i not in refuted)
    for i, o in enumerate(out):
        err = "cannot be simulated" if o is None else f"{rms(o):.4g} µm"
        say(f"  validation {labels[i]}: {err}" + (" — refuted" if i in refuted else ""))
    return left, decisions
