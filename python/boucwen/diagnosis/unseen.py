"""What a model predicts on data its fit did not see.

Two kinds of unseen data judge the returned model:

* **blocked cross-validation** over contiguous folds of the record itself
  (:mod:`~boucwen.diagnosis.validation`: each block predicted by the model refitted
  without it), for every record;
* a **second record of the same device** (``validate``), where the user has one: the
  model fitted on the first record simulated from the second record's voltage alone,
  with its offset and its initial hysteresis state h0 re-estimated (a different day, a
  different mounting: the offset of a piezo stage is not kept between records, and the
  state it starts in depends on what the voltage did before the record began, which
  neither record holds).

On the second record each effect must earn its place: one whose removal (the others
refitted without it on the first record) predicts the second record as well, within
the sampling error of an RMS error over its samples, is dropped (:func:`judged_on`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from .._core import EffectSet
from ..checks import FloatArray
from ..effects import ExtendedFit, simulate_chain
from ..effects.base import without
from ..metrics import max_abs, rms
from ..record import Record

__all__ = ["ValidationError", "judged_on", "prediction_error", "sampling_margin"]


@dataclass(frozen=True)
class ValidationError:
    """Errors [µm] of a model on a record it was not fitted on, with the offset
    ``offset_um`` and initial hysteresis state ``h0_um`` [µm] re-estimated."""

    rms_um: float
    max_um: float
    offset_um: float
    h0_um: float

    def to_dict(self) -> dict[str, float]:
        return {"rms_um": self.rms_um, "max_um": self.max_um, "offset_um": self.offset_um, "h0_um": self.h0_um}


def prediction_error(fit: ExtendedFit, record: Record) -> ValidationError | None:
    """The error of ``fit`` simulated over ``record``'s voltage, with the offset (the
    mean of the error) and the initial state h0 (bounded scalar search over ± the
    record's displacement span, kept only where it beats h0 = 0) that fit it best;
    None when it cannot be simulated."""

    def error(h0: float) -> tuple[FloatArray, float] | None:
        xs = simulate_chain(fit.params, fit.effects, record.u, record.dt, h0)
        if xs is None:
            return None
        offset = float(np.mean(record.x - xs))
        return record.x - xs - offset, offset

    def cost(h0: float) -> float:
        out = error(h0)
        return math.inf if out is None else rms(out[0])

    at_zero = error(0.0)
    if at_zero is None:
        return None
    span = max(float(np.ptp(record.x)), 1e-9)
    found = minimize_scalar(cost, bounds=(-span, span), method="bounded", options={"xatol": 1e-6 * span})
    h0, (err, offset) = 0.0, at_zero
    best = error(float(found.x)) if found.fun < rms(at_zero[0]) else None
    if best is not None:
        h0, (err, offset) = float(found.x), best
    return ValidationError(rms_um=rms(err), max_um=max_abs(err), offset_um=offset, h0_um=h0)


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
    predicts the unseen record as well). Returns the model, the effects left and the
    evidence (per effect: the validation RMS errors with and without it)."""
    margin = sampling_margin(len(validation))
    evidence: dict[str, Any] = {"margin": margin}
    for name in list(added):
        if name == "resonance" and "resonance2" in current.effects.names:
            continue
        with_it = prediction_error(current, validation)
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
            current = rest
            added = [k for k in added if k != name]
    return current, added, evidence
