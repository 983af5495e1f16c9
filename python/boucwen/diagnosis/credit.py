"""What a trial is credited with, and when that earns the effect its parameters.

A model (a trial: the current model with an effect added) is compared with a
*reference*, the better of the current model and the null trial (the current model
refitted with the trial's effort and nothing added), under blocked cross-validation
(:mod:`~boucwen.diagnosis.validation`). :func:`credit_of` gives the :class:`Credit`;
:func:`earns` applies the acceptance rule of the :class:`~boucwen.diagnosis.policy.DiagnosisPolicy`
to it. :func:`explained_share` and :func:`partial` say how much of the error beyond the
noise a model removes, and whether what it leaves makes its effects tentative.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..checks import FloatArray
from ..metrics import rms
from .margins import CloseCalls, Compare, at_least, decide
from .policy import DiagnosisPolicy
from .unexplained import Unexplained
from .validation import CrossValidation

__all__ = ["Credit", "credit_of", "earns", "explained_share", "partial"]


@dataclass(frozen=True)
class Credit:
    """What a model is credited with against a reference (all errors RMS [µm], gains
    relative cuts [-], positive when the model is better).

    Attributes:
        cv_rms_um: the model's cross-validated error.
        in_sample_rms_um: its in-sample error.
        cv_gain: cut of the cross-validated error against the reference's.
        in_sample_gain: cut of the in-sample error against the reference's (the lower of
            the current model's and the null trial's).
        gain_over_null: the credit: ``cv_gain``, but no more than ``in_sample_gain`` (an
            effect that fits the record no better than the model without it is not
            credited with block refits that happen to extrapolate better with one more
            unknown beside them).
        fold_gains: cut of the cross-validated error per fold.
        local_gain: cut of the cross-validated error on the samples where the model
            differs most from the reference (the policy's ``local_share``).
        noise_share: share of the reference's in-sample mean-square error beyond the
            record's noise that the model removes (:func:`explained_share`).
    """

    cv_rms_um: float
    in_sample_rms_um: float
    cv_gain: float
    in_sample_gain: float
    gain_over_null: float
    fold_gains: tuple[float, ...]
    local_gain: float
    noise_share: float

    def to_dict(self) -> dict[str, Any]:
        """The credit as the report holds it (``fold_gains`` a list)."""
        return {**asdict(self), "fold_gains": list(self.fold_gains)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Credit:
        """The credit of a report's trial (its other keys, e.g. ``fitted``, ignored);
        KeyError naming a missing field."""
        return cls(
            cv_rms_um=float(d["cv_rms_um"]),
            in_sample_rms_um=float(d["in_sample_rms_um"]),
            cv_gain=float(d["cv_gain"]),
            in_sample_gain=float(d["in_sample_gain"]),
            gain_over_null=float(d["gain_over_null"]),
            fold_gains=tuple(float(g) for g in d["fold_gains"]),
            local_gain=float(d["local_gain"]),
            noise_share=float(d["noise_share"]),
        )


def credit_of(
    cv: CrossValidation,
    x: FloatArray,
    reference: CrossValidation,
    x_reference: FloatArray,
    ref_in_sample: float,
    noise_um: float,
    policy: DiagnosisPolicy,
) -> Credit:
    """The credit of a model (cross-validation ``cv``, prediction ``x`` [µm]) against a
    reference (``reference``, ``x_reference``), whose in-sample error is taken as
    ``ref_in_sample`` [µm]; ``noise_um``: the record's noise [µm]."""
    acts = np.abs(x - x_reference)
    k = max(1, round(policy.local_share * acts.size))
    where = np.argpartition(acts, acts.size - k)[acts.size - k :]
    local_ref = rms(reference.residual[where])
    ref_rms = reference.rms_um
    cv_gain = 1.0 - cv.rms_um / ref_rms if ref_rms > 0 else 0.0
    in_sample_gain = 1.0 - cv.in_sample_rms_um / ref_in_sample if ref_in_sample > 0 else 0.0
    return Credit(
        cv_rms_um=cv.rms_um,
        in_sample_rms_um=cv.in_sample_rms_um,
        cv_gain=cv_gain,
        in_sample_gain=in_sample_gain,
        gain_over_null=min(cv_gain, in_sample_gain),
        fold_gains=tuple(1.0 - a / b if b > 0 else 0.0 for a, b in zip(cv.fold_rms_um, reference.fold_rms_um)),
        local_gain=1.0 - rms(cv.residual[where]) / local_ref if local_ref > 0 else 0.0,
        noise_share=explained_share(ref_in_sample, cv.in_sample_rms_um, noise_um),
    )


def earns(c: Credit, policy: DiagnosisPolicy, calls: CloseCalls | None = None, what: str = "") -> bool:
    """The credit ``c`` earns the effect its parameters: a cut of at least
    ``policy.min_gain`` overall; or ``local_min_gain`` where it acts with ``local_floor``
    overall; or ``partial_share`` of the error beyond the noise with ``local_floor``
    overall and a gain in every fold. Each comparison with the margin
    ``policy.close_gain``: a credit it decides does not earn (a close call noted in
    ``calls`` as ``what``)."""

    def rule(cmp: Compare) -> bool:
        gain, margin = c.gain_over_null, policy.close_gain
        overall = cmp.ge(gain, policy.min_gain, margin)
        local = cmp.ge(c.local_gain, policy.local_min_gain, margin) and cmp.ge(gain, policy.local_floor, margin)
        folds = cmp.ge(min(c.fold_gains), 0.0, margin) and min(c.fold_gains) > 0
        to_noise = (
            cmp.ge(c.noise_share, policy.partial_share, margin) and cmp.ge(gain, policy.local_floor, margin) and folds
        )
        return overall or local or to_noise

    return decide(rule, f"{what}: earns its parameters", calls, yes="earns", no="does not earn")


def explained_share(before_um: float, after_um: float, noise_um: float) -> float:
    """Share of the mean-square error beyond the noise that a model removes:
    1 − (after² − σ²)/(before² − σ²), RMS errors and noise σ in µm (1 when ``before``
    is no more than the noise)."""
    excess = before_um**2 - noise_um**2
    if not excess > 0:
        return 1.0
    return 1.0 - max(after_um**2 - noise_um**2, 0.0) / excess


def partial(before_um: float, after_um: float, left: Unexplained, policy: DiagnosisPolicy) -> bool:
    """The effects kept leave a residual ``left`` not consistent with noise and remove
    less than ``policy.partial_share`` of the base model's mean-square error beyond the
    noise (RMS errors before and after [µm]); a share within the margin of it counts as
    less (the simpler report)."""
    share = explained_share(before_um, after_um, left.noise_um)
    return not left.consistent_with_noise and not at_least(share, policy.partial_share, policy.close_gain, "", None)
