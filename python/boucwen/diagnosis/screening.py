"""Screening a long record: its decimated copy, and what the copy can and cannot hold.

Records of more than ``screen_min_samples`` samples sampled faster than
``screen_rate_hz`` (:class:`~boucwen.diagnosis.policy.DiagnosisPolicy`) are screened:
the trials run on a copy holding every q-th sample, and the best are confirmed on the
full record. An effect whose parameters are whole samples of the record's rate
(:attr:`boucwen.effects.Effect.full_rate_only`) is tried on the full record only, and a
model holding one is not screened; a mode the copy cannot hold is tried on the full
record too.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..effects import FN_MAX_NYQUIST_FRACTION, ExtendedFit, Solved, effect_class, simulate_chain
from ..record import Record, validate_record
from .evidence import spectral_peak
from .policy import DiagnosisPolicy
from .validation import blocked_cv

__all__ = [
    "decimated",
    "hopeless_direction",
    "peak_beyond",
    "screen_copy",
    "screen_factor",
    "screenable",
    "to_confirm",
]


def screen_factor(record: Record, policy: DiagnosisPolicy) -> int:
    """The decimation q of the record's screened copy (1 when it is not screened)."""
    q = max(1, int(1.0 / (record.dt * policy.screen_rate_hz)))
    return 1 if len(record) <= policy.screen_min_samples else q


def decimated(record: Record, q: int) -> Record:
    """Every ``q``-th sample of the record, from the first (the record itself for q = 1)."""
    return record if q == 1 else validate_record(record.u[::q], record.x[::q], record.dt * q)


def to_confirm(ranked: Sequence[str], cv_rms_um: Mapping[str, float], policy: DiagnosisPolicy) -> list[str]:
    """The screened effects confirmed on the full record: of those that earned on the
    copy (``ranked``, best first), at most ``confirm``, each with a cross-validated RMS
    error (``cv_rms_um`` [µm], by effect) within ``confirm_ratio`` times the best's."""
    chosen = list(ranked[: policy.confirm])
    if not chosen:
        return []
    best = cv_rms_um[chosen[0]]
    return [k for k in chosen if cv_rms_um[k] <= policy.confirm_ratio * best]


def screen_copy(record: Record, policy: DiagnosisPolicy) -> tuple[Record, int]:
    """The record decimated to about the policy's ``screen_rate_hz`` (every q-th sample,
    :func:`screen_factor`), and q (the record itself and 1 when it is not screened)."""
    q = screen_factor(record, policy)
    return decimated(record, q), q


def screenable(current: ExtendedFit, screen: Record) -> bool:
    """The current model means on the screened copy what it means on the record: it
    simulates there (a mode above the copy's Nyquist frequency does not), and it holds
    no effect of whole samples of the record's rate, which the copy's samples are not."""
    if any(effect_class(k).full_rate_only for k in current.effects.names):
        return False
    return simulate_chain(current.params, current.effects, screen.u, screen.dt, current.h0) is not None


def peak_beyond(record: Record, current: ExtendedFit, screen_dt: float, policy: DiagnosisPolicy) -> bool:
    """The current model's residual has a spectral peak (``policy.peak_over_median``
    over the spectrum's median) above the highest mode the screened copy (interval
    ``screen_dt`` [s]) can hold."""
    xs = simulate_chain(current.params, current.effects, record.u, record.dt, current.h0)
    if xs is None:  # pragma: no cover - a fitted model can be simulated
        return False
    peak = spectral_peak(record.x - xs, record.dt)
    return bool(
        peak["peak_hz"] > FN_MAX_NYQUIST_FRACTION / screen_dt and peak["peak_over_median"] > policy.peak_over_median
    )


def hopeless_direction(record: Record, current: Solved, name: str, folds: int, policy: DiagnosisPolicy) -> bool:
    """The effect ``name`` cannot earn its parameters beside ``current`` (over
    ``record``): the first-order change it makes (:meth:`boucwen.effects.Effect.direction`)
    added as one more column of the Jacobian cuts the cross-validated error by less than
    ``policy.local_floor``. False where the effect declares no such change."""
    column = effect_class(name).direction(current.x)
    if column is None:
        return False
    cv = blocked_cv(current.jacobian, record.x - current.x, folds)
    with_it = blocked_cv(np.column_stack([current.jacobian, column]), record.x - current.x, folds)
    return bool(with_it.rms_um > (1.0 - policy.local_floor) * cv.rms_um)
