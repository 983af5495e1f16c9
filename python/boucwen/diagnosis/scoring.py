"""A fit scored over a record: its simulation, Jacobian and blocked cross-validation,
and the first-order refit the starts of a trial are ranked by."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .._core import EffectSet
from ..checks import FloatArray
from ..effects import ExtendedFit, Layout, Solved, jacobian_extended, simulate_chain
from ..fit import FitResult
from ..metrics import rms
from ..record import Record
from .policy import DiagnosisPolicy
from .validation import CrossValidation, blocked_cv

__all__ = ["AtBound", "Scored", "base_fit", "cost", "cv_rms", "on_bounds", "refit_basis", "score", "solved_at"]


@dataclass(frozen=True, eq=False)
class Scored:
    """A fit and its blocked cross-validation over a record.

    Attributes:
        fit: the fit.
        cv: its blocked cross-validation (:func:`~boucwen.diagnosis.validation.blocked_cv`).
        x: its simulated displacement [µm].
        jacobian: ∂x̂/∂z (one row per sample, one column per unknown of its layout).
    """

    fit: ExtendedFit
    cv: CrossValidation
    x: FloatArray
    jacobian: FloatArray


def solved_at(record: Record, fr: ExtendedFit, jacobian: Any = None) -> Solved:
    """``fr`` with its simulated displacement and Jacobian over ``record`` (a fit made
    elsewhere, or on another copy of the record); ``jacobian``, when given, is that
    Jacobian, already known."""
    xs = simulate_chain(fr.params, fr.effects, record.u, record.dt, fr.h0)
    if xs is None:  # pragma: no cover - a fitted model can be simulated
        raise ValueError("the fitted model cannot be simulated")
    jac = jacobian_extended(record, fr) if jacobian is None else jacobian
    return Solved(fit=fr, x=xs, jacobian=jac)


def score(record: Record, solved: Solved, folds: int) -> Scored:
    """A fit over ``record`` and its blocked cross-validation over ``folds`` blocks
    (each block's refit step simulated)."""
    fr = solved.fit
    layout = Layout.of(fr.effects, record.dt, record.dt * max(record.u.size - 1, 1))
    z = layout.pack(fr.params, fr.effects, fr.h0)

    def stepped(dz: Any) -> Any:
        xs = layout.simulate(z + dz, record.u, record.dt)
        return None if xs is None else record.x - xs

    cv = blocked_cv(solved.jacobian, record.x - solved.x, folds, simulate=stepped)
    return Scored(fr, cv, solved.x, solved.jacobian)


def refit_basis(jacobian: FloatArray) -> FloatArray:
    """An orthonormal basis of the span of the current model's Jacobian (its columns
    scaled to unit norm): the first-order refit of the current model's unknowns."""
    norms = np.linalg.norm(jacobian, axis=0)
    keep = norms > 0
    q, _ = np.linalg.qr(jacobian[:, keep] / norms[keep])
    return q


def cost(record: Record, current: ExtendedFit, effects: EffectSet, basis: Any = None) -> float:
    """RMS error [µm] of the current model with ``effects``; with ``basis``
    (:func:`refit_basis`), what is left of it beyond the first-order refit of the
    current model's unknowns (the current fit has bent itself to follow what the
    effect describes; the refit undoes that to first order)."""
    xs = simulate_chain(current.params, effects, record.u, record.dt, current.h0)
    if xs is None:
        return math.inf
    r = record.x - xs
    if basis is not None:
        r = r - basis @ (basis.T @ r)
    return rms(r)


def cv_rms(record: Record, fit: ExtendedFit, folds: int) -> float:
    """The blocked cross-validated RMS error [µm] of ``fit`` over ``record``."""
    return score(record, solved_at(record, fit), folds).cv.rms_um


def base_fit(base: FitResult) -> ExtendedFit:
    """The base model's fit as an extended fit with no effect."""
    return ExtendedFit(base.params, EffectSet(), base.h0, base.rms_um, base.max_um, base.nfev, base.success)


@dataclass(frozen=True)
class AtBound:
    """An unknown of a fit that ended on a bound of the fit.

    Attributes:
        parameter: its name (:meth:`boucwen.effects.Layout.labels`, e.g. ``"creep.g1"``).
        value: its value, in its unit.
        bound: the bound it is on, same unit.
        side: ``"lower"`` or ``"upper"``.
    """

    parameter: str
    value: float
    bound: float
    side: str

    def to_dict(self) -> dict[str, Any]:
        """``{"parameter", "value", "bound", "side"}`` (JSON-ready)."""
        return asdict(self)


def on_bounds(fit: ExtendedFit, record: Record, policy: DiagnosisPolicy | None = None) -> list[AtBound]:
    """The unknowns of ``fit`` that ended on a bound of the fit over ``record`` (within
    the policy's ``bound_tolerance`` of its size, at least 1)."""
    tol = (policy or DiagnosisPolicy()).bound_tolerance
    layout = Layout.of(fit.effects, record.dt, record.dt * max(len(record) - 1, 1))
    z = layout.pack(fit.params, fit.effects, fit.h0)
    lo, hi = layout.bounds()
    out: list[AtBound] = []
    for label, v, a, b in zip(layout.labels(), z, lo, hi):
        for bound, side in ((a, "lower"), (b, "upper")):
            if math.isfinite(bound) and abs(v - bound) <= tol * max(1.0, abs(bound)):
                out.append(AtBound(label, float(v), float(bound), side))
    return out
