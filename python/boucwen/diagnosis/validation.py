"""Blocked cross-validation of a fitted model over the whole record.

The record is cut into ``folds`` contiguous blocks of equal length. Each block is held
out in turn: the model is refitted on the other blocks and its error measured on the
held-out one. Every sample is thus held out once, so that evidence anywhere in the
record — a step and its hold, a burst, the start or the end — is scored where it is.

The refit without a block is the Gauss–Newton step from the model fitted on the whole
record, taken on the other blocks only: with r = x − x̂ the residual and J = ∂x̂/∂z the
Jacobian of the simulated output in the model's unknowns z (exact, from the Rust
core's pass with the simulation), the held-out residual of block k is

    r_k − J_k·Δ_k,     Δ_k = argmin_Δ ‖r_{−k} − J_{−k}·Δ‖² + λ‖Δ‖²

with J's columns scaled to unit norm over the record and λ = :data:`RIDGE` — the
one-step approximation of leave-a-block-out refits (exact for unknowns the output
depends on linearly: offsets, creep gains, drift rates, when λ → 0). The damping keeps
the directions the other blocks hardly determine (nearly redundant hysteresis
parameters, an effect seen only in the held-out block) where the whole record put
them, as a refit started there and stopped early would. It costs one Jacobian per
model instead of one fit per block.

For unknowns the output depends on nonlinearly (a resonance's frequency and damping,
a lag's corner, the hysteresis exponent) the linear prediction r_k − J_k·Δ_k can be far
from what the step really does: a step the other blocks ask for may move a mode by
hundreds of hertz, and the straight line predicts an error on the held-out block many
times what the model there makes. Given ``simulate`` (the model's residual after a
step of its unknowns), the step is taken for real instead: the model is simulated at
z + α·Δ_k with α = 1, ½, ¼, ⅛ — the first α that lowers the error on the *other*
blocks below the whole-record fit's — and the held-out residual is that simulation's
on block k (the fit's own residual when no α does). The line search sees only the
other blocks, so the held-out block still judges a refit that never saw it; it costs
one to four simulations per block.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import FloatArray
from ..metrics import rms

__all__ = ["FOLDS", "RIDGE", "STEP_FRACTIONS", "CrossValidation", "blocked_cv", "fold_slices"]

#: Default number of contiguous folds.
FOLDS = 4
#: Damping λ of the refit step, relative to the unit norm of each scaled column.
RIDGE = 1e-3
#: Fractions α of a block's refit step tried, in turn, when the step is simulated.
STEP_FRACTIONS = (1.0, 0.5, 0.25, 0.125)

#: The residual x − x̂ [µm] of the model after a step of its unknowns (in their own
#: units, one entry per Jacobian column), or None where the model cannot be simulated.
Simulate = Callable[[FloatArray], "FloatArray | None"]


def fold_slices(n: int, folds: int) -> list[slice]:
    """``folds`` contiguous slices of ``range(n)``, of lengths differing by at most one."""
    edges = np.linspace(0, n, folds + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


@dataclass(frozen=True, eq=False)
class CrossValidation:
    """The held-out residual of a model, sample by sample, and its summaries.

    Attributes:
        residual: held-out residual [µm] (each sample from the refit without its block).
        in_sample_rms_um: RMS of x − x̂ of the model fitted on the whole record [µm].
        rms_um: RMS of ``residual`` [µm].
        fold_rms_um: RMS of ``residual`` per block [µm].
    """

    residual: FloatArray
    in_sample_rms_um: float
    rms_um: float
    fold_rms_um: list[float]

    def to_dict(self) -> dict[str, Any]:
        return {"rms_um": self.rms_um, "in_sample_rms_um": self.in_sample_rms_um, "fold_rms_um": self.fold_rms_um}


def blocked_cv(
    jacobian: FloatArray, residual: FloatArray, folds: int = FOLDS, *, simulate: Simulate | None = None
) -> CrossValidation:
    """Blocked cross-validation (module docs) of a model with residual ``residual`` =
    x − x̂ [µm] and Jacobian ``jacobian`` = ∂x̂/∂z (one row per sample); with
    ``simulate``, each block's refit step is simulated (line-searched on the other
    blocks) instead of extrapolated linearly."""
    norms = np.linalg.norm(jacobian, axis=0)
    cols = norms > 0
    j = jacobian[:, cols] / norms[cols]
    held = np.empty_like(residual)
    slices = fold_slices(residual.size, folds)
    gram = j.T @ j
    moment = j.T @ residual
    damping = RIDGE * np.eye(j.shape[1])
    for sl in slices:
        jk, rk = j[sl], residual[sl]
        step = np.linalg.solve(gram - jk.T @ jk + damping, moment - jk.T @ rk)
        if simulate is None:
            held[sl] = rk - jk @ step
            continue
        dz = np.zeros(jacobian.shape[1])
        dz[cols] = step / norms[cols]
        held[sl] = _simulated_step(residual, sl, dz, simulate)
    return CrossValidation(
        residual=held,
        in_sample_rms_um=rms(residual),
        rms_um=rms(held),
        fold_rms_um=[rms(held[sl]) for sl in slices],
    )


def _simulated_step(residual: FloatArray, held_out: slice, dz: FloatArray, simulate: Simulate) -> FloatArray:
    """The residual on ``held_out`` after the first fraction of the step ``dz`` that
    lowers the error on the other blocks (``residual``'s there when none does)."""
    others = np.ones(residual.size, dtype=bool)
    others[held_out] = False
    fitted = float(np.sum(residual[others] ** 2))
    for alpha in STEP_FRACTIONS:
        r = simulate(alpha * dz)
        if r is not None and np.all(np.isfinite(r)) and float(np.sum(r[others] ** 2)) < fitted:
            return r[held_out]
    return residual[held_out]
