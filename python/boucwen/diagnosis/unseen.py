"""What a model predicts on data its fit did not see.

Two kinds of unseen data judge the returned model:

* **blocked cross-validation** over contiguous folds of the record itself
  (:mod:`~boucwen.diagnosis.validation`: each block predicted by the model refitted
  without it), for every record;
* a **second record of the same device** (``validate``), where the user has one: the
  model fitted on the first record carried to the second. What is carried is the
  *device*: the hysteresis and every effect of the actuator, its amplifier and its
  mechanics. What belongs to the *record* is re-estimated on the second one, for every
  model alike: the offset (a different mounting, a different zero), a linear trend
  (thermal and sensor drift depend on the day, not on the device), the initial
  hysteresis state h0 (it depends on what the voltage did before the record began,
  which neither record holds); the record's own effects, :data:`RECORD_EFFECTS`
  (a drift, a mains pickup whose phase is the record's), are left out.

On the second record each effect of the device must earn its place: one whose removal
(the others refitted without it on the first record) predicts the second record as
well, within the sampling error of an RMS error over its samples, is dropped
(:func:`judged_on`); the record's own effects are judged on the record itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from .._core import EffectSet
from ..checks import FloatArray
from ..effects import ExtendedFit, simulate_chain
from ..effects.base import without
from ..metrics import max_abs, rms
from ..record import Record

__all__ = [
    "RECORD_EFFECTS",
    "OnValidation",
    "Unseen",
    "ValidationError",
    "carried",
    "judged_on",
    "prediction_error",
    "sampling_margin",
]

#: Effects of the record rather than of the device: not carried to another record.
RECORD_EFFECTS = ("drift", "pickup")


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
    """The base and returned models carried to the validation record.

    Attributes:
        samples: its number of samples.
        before, after: the base and returned models' errors there (None where one
            cannot be simulated over it).
    """

    samples: int
    before: ValidationError | None
    after: ValidationError | None

    def to_dict(self) -> dict[str, Any]:
        """``{"samples", "before", "after"}`` (JSON-ready)."""
        return {
            "samples": self.samples,
            "before": None if self.before is None else self.before.to_dict(),
            "after": None if self.after is None else self.after.to_dict(),
        }


@dataclass(frozen=True)
class Unseen:
    """Errors [µm] on data the fits did not see.

    Attributes:
        folds: contiguous folds of the blocked cross-validation.
        cv_rms_before_um, cv_rms_after_um: its RMS error, base and returned models [µm].
        validation: with a validation record, both models carried to it; else None.
    """

    folds: int
    cv_rms_before_um: float
    cv_rms_after_um: float
    validation: OnValidation | None = None

    def to_dict(self) -> dict[str, Any]:
        """``{"folds", "cv_rms_before_um", "cv_rms_after_um"}`` and, with a validation
        record, ``"validation"`` (JSON-ready)."""
        out: dict[str, Any] = {
            "folds": self.folds,
            "cv_rms_before_um": self.cv_rms_before_um,
            "cv_rms_after_um": self.cv_rms_after_um,
        }
        if self.validation is not None:
            out["validation"] = self.validation.to_dict()
        return out


def device_part(effects: EffectSet) -> EffectSet:
    """``effects`` less the record's own (:data:`RECORD_EFFECTS`)."""
    for name in RECORD_EFFECTS:
        if name in effects.names:
            effects = without(effects, name)
    return effects


def carried(fit: ExtendedFit, record: Record) -> tuple[FloatArray, ValidationError] | None:
    """The displacement [µm] ``fit`` predicts over ``record`` when carried there (its
    device part, with the offset, the trend and h0 of ``record`` re-estimated by least
    squares: h0 by a bounded scalar search over ± the record's displacement span, kept
    only where it beats h0 = 0), and its error; None when it cannot be simulated."""
    effects = device_part(fit.effects)
    basis = np.column_stack([np.ones(len(record)), record.t - record.t[0]])

    def fitted(h0: float) -> tuple[FloatArray, FloatArray] | None:
        xs = simulate_chain(fit.params, effects, record.u, record.dt, h0)
        if xs is None:
            return None
        coef = np.linalg.lstsq(basis, record.x - xs, rcond=None)[0]
        return xs + basis @ coef, coef

    def cost(h0: float) -> float:
        out = fitted(h0)
        return math.inf if out is None else rms(record.x - out[0])

    at_zero = fitted(0.0)
    if at_zero is None:
        return None
    span = max(float(np.ptp(record.x)), 1e-9)
    found = minimize_scalar(cost, bounds=(-span, span), method="bounded", options={"xatol": 1e-6 * span})
    h0, (x_hat, coef) = 0.0, at_zero
    best = fitted(float(found.x)) if found.fun < cost(0.0) else None
    if best is not None:
        h0, (x_hat, coef) = float(found.x), best
    err = record.x - x_hat
    return x_hat, ValidationError(
        rms_um=rms(err), max_um=max_abs(err), offset_um=float(coef[0]), trend_um_per_s=float(coef[1]), h0_um=h0
    )


def prediction_error(fit: ExtendedFit, record: Record) -> ValidationError | None:
    """The error of ``fit`` carried to ``record`` (:func:`carried`); None when it cannot
    be simulated."""
    out = carried(fit, record)
    return None if out is None else out[1]


def sampling_margin(samples: int) -> float:
    """Relative sampling error of an RMS error estimated over ``samples`` samples
    (1/√(2N) for Gaussian errors): two models whose RMS errors on the same record differ
    by less than this fraction are not told apart by that record."""
    return 1.0 / math.sqrt(2.0 * max(samples, 1))


def judged_on(
    validation: Record,
    current: ExtendedFit,
    added: list[str],
    refit: Callable[[EffectSet], ExtendedFit],
    say: Callable[[str], None],
) -> tuple[ExtendedFit, list[str], dict[str, Any]]:
    """Each effect in ``added`` judged on the ``validation`` record: the model with
    the others only (``refit``: the model refitted on the identification record with
    the effects given) against ``current``; an effect whose removal does not raise the
    validation error by more than :func:`sampling_margin` is dropped (the simpler model
    predicts the unseen record as well). The record's own effects
    (:data:`RECORD_EFFECTS`) are not judged there. Returns the model, the effects left
    and the evidence (per effect: the validation RMS errors with and without it)."""
    margin = sampling_margin(len(validation))
    evidence: dict[str, Any] = {"margin": margin}
    # The current model's error there changes only when an effect is dropped.
    with_it = prediction_error(current, validation)
    for name in list(added):
        if name in RECORD_EFFECTS or (name == "resonance" and "resonance2" in current.effects.names):
            continue
        rest = refit(without(current.effects, name))
        without_it = prediction_error(rest, validation)
        if with_it is None or without_it is None:
            continue
        earns = without_it.rms_um > (1.0 + margin) * with_it.rms_um
        evidence[name] = {"with_rms_um": with_it.rms_um, "without_rms_um": without_it.rms_um, "kept": earns}
        say(
            f"  validation {name:9s}: {with_it.rms_um:.4g} µm with it, {without_it.rms_um:.4g} µm without"
            + ("" if earns else " — dropped")
        )
        if not earns:
            current, with_it = rest, without_it
            added = [k for k in added if k != name]
    return current, added, evidence
