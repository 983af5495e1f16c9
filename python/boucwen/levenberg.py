"""Levenberg–Marquardt for the output-error fits, stopped by the record's statistics.

Minimises ½‖r(z)‖² over z within box bounds, where r is a residual with one row per
sample (µm) and ∂r/∂z comes from one pass of the core (:mod:`boucwen.lsq`). Each
linearisation gives the normal equations H = JᵀJ, g = Jᵀr (p×p and p, p ≤ a few tens),
diagonalised once in the metric of ``x_scale`` (S = diag x_scale). A step minimises
the linear model within a trust region ‖S⁻¹δ‖ ≤ Δ: δ solves (H + μ·S⁻²)·δ = −g, with
μ = 0 when the Gauss–Newton step fits in the region and otherwise the μ that puts the
step on its edge (Moré's form of Levenberg–Marquardt; the p×p eigendecomposition gives
δ for any μ). The residual at z + δ is simulated and the step kept when the cost
falls; Δ shrinks to a quarter of a step whose cost fell by less than a quarter of the
fall it predicted, and doubles after one that went as predicted to the region's edge.
The region starts at Δ = ‖S⁻¹z0‖ (1 for z0 = 0): a first step may change the unknowns
by their own size. Unknowns at a bound whose step would leave it are held there.
No factorisation of J itself: an iteration costs the pass and one simulation.

**When to stop.** With noise of variance σ² on the samples, the unknowns' covariance
is σ²·H⁻¹ and the Gauss–Newton step δ = −H⁻¹g moves them by a Mahalanobis distance
d with d² = gᵀH⁻¹g / σ² (in standard errors, squared). The solver stops when
d² ≤ ``margin`` (default :data:`STATISTICAL_MARGIN`: the remaining step is at most a
tenth of a standard error), with σ² estimated from the residual, σ̂² = ‖r‖²/(rows − p):
further iterations would move the unknowns by less than the record can resolve and
change the cost by at most ``margin``·σ̂², far below any difference a decision between
models is made on. The same margin on the fall each step achieves stops it too: three
accepted steps in a row that each lower ‖r‖² by less than ``margin``·σ̂² (a curved valley,
along which the Gauss–Newton step keeps predicting a fall it never gives; SciPy's ``trf``
is stopped the same way, its ``ftol``). ``tol`` stops it earlier on noise-free records (relative change of
the cost or of the scaled unknowns below ``tol``); ``max_nfev`` bounds the number of
trial points.

``reuse_jacobian`` keeps the last Jacobian while it predicts the fall of the cost to
within 25 % and each step leaves at most a quarter of the remaining decrease of the
one before (a chord iteration, with a fresh linearisation wherever the cost surface
bends away from it or the iteration slows): near the optimum (the stages of
:func:`boucwen.fit`) one pass and a few simulations instead of a pass per step. The
remaining step is then judged on that Jacobian, computed on this record at a point a
step or two away (exact to first order in the distance moved); a failed step computes
a fresh one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import lsq_linear

from .checks import FloatArray

__all__ = ["STATISTICAL_MARGIN", "Solution", "first_step", "levenberg_marquardt"]

#: Default stop: the remaining Gauss–Newton step is at most √0.01 = 0.1 standard error.
STATISTICAL_MARGIN = 0.01

#: With ``reuse_jacobian``, the Jacobian is kept after a step whose cost fell by at
#: least this fraction of the fall it predicted (the linearisation still holds there).
_KEEP_RHO = 0.75

#: A kept Jacobian is replaced once a step inside the trust region leaves more than
#: this share of the remaining decrease of the step before (its chord iteration
#: converges linearly, at a rate set by how far the Jacobian has drifted; a fresh one
#: converges quadratically).
_CHORD_RATE = 0.25

#: Accepted steps in a row, each lowering the cost by less than the statistical margin,
#: that stop the solver as converged: along a curved valley the Gauss–Newton step keeps
#: predicting a fall the record would resolve while the steps achieve less than it can.
_STALLED = 3

#: Eigenvalues of the scaled H below this fraction of the largest are directions the
#: record does not determine: no Gauss–Newton step along them.
_RCOND = 1e-13

BoolArray = NDArray[np.bool_]
Residual = Callable[[FloatArray], FloatArray]
Linearise = Callable[[FloatArray], Optional[tuple[FloatArray, FloatArray]]]


@dataclass(frozen=True, eq=False)
class Solution:
    """The end point of :func:`levenberg_marquardt`.

    Attributes:
        x: the unknowns.
        cost: ½‖r(x)‖² [µm²].
        jac: ∂r/∂z at ``x`` (with ``reuse_jacobian``: at the last point linearised).
        nfev: trial points simulated.
        njev: linearisations (passes with the Jacobian).
        success: stopped by the statistical margin or ``tol``, not by ``max_nfev``.
        message: why it stopped.
    """

    x: FloatArray
    cost: float
    jac: FloatArray
    nfev: int
    njev: int
    success: bool
    message: str


class _Normal:
    """The normal equations H = JᵀJ of one linearisation in the metric of S =
    diag(scale), diagonalised once: S·H·S = V·diag(w)·Vᵀ."""

    def __init__(self, jac: FloatArray, scale: FloatArray):
        with np.errstate(over="ignore", invalid="ignore"):
            self.h = jac.T @ jac
        if not np.all(np.isfinite(self.h)):
            # A finite Jacobian whose products overflow: no step can be solved from it.
            raise FloatingPointError("the normal equations overflow")
        self.scale = scale
        w, self.v = np.linalg.eigh(self.h * scale[:, None] * scale[None, :])
        self.w = np.maximum(w, 0.0)
        self.determined = self.w > _RCOND * max(float(self.w[-1]), 1e-300)

    def within(self, g: FloatArray, radius: float) -> tuple[FloatArray, float]:
        """(δ, μ): the minimiser of the linear model with ‖S⁻¹δ‖ ≤ ``radius`` (for
        ``radius`` = ∞ the Gauss–Newton step −H⁺g, minimum-norm where H is singular), to
        10 % of the radius on the edge (Newton on 1/‖S⁻¹δ(μ)‖, which is nearly linear in μ)."""
        c = self.v.T @ (g * self.scale)
        gn = np.where(self.determined, c / np.where(self.determined, self.w, 1.0), 0.0)
        if float(np.linalg.norm(gn)) <= radius:
            return -self.scale * (self.v @ gn), 0.0
        mu = 0.0
        for _ in range(30):
            # At μ = 0 the undetermined directions take no step (as Gauss–Newton).
            d = self.w + mu if mu > 0.0 else np.where(self.determined, self.w, np.inf)
            p = c / d
            norm = float(np.linalg.norm(p))
            if abs(norm - radius) <= 0.1 * radius:
                break
            q2 = float(np.sum(c * c / d**3))
            mu = max(mu + (norm / radius - 1.0) * norm * norm / max(q2, 1e-300), 0.0)
            if mu == 0.0:
                # Below every determined eigenvalue's scale: start from the smallest.
                mu = float(np.min(self.w[self.determined])) if self.determined.any() else 1.0
        d = self.w + mu if mu > 0.0 else np.where(self.determined, self.w, np.inf)
        step: FloatArray = -self.scale * (self.v @ (c / d))
        return step, mu


def _held(step: FloatArray, at_lower: BoolArray, at_upper: BoolArray) -> BoolArray:
    """The unknowns at a bound whose step would leave it."""
    out: BoolArray = (at_lower & (step < 0.0)) | (at_upper & (step > 0.0))
    return out


def _bounded(
    normal: _Normal, jac: FloatArray, g: FloatArray, radius: float, at_lower: BoolArray, at_upper: BoolArray
) -> FloatArray:
    """The trust-region step with the unknowns that would leave their bound held there
    (re-solved on the others until none would, at most p times)."""
    step = normal.within(g, radius)[0]
    free = np.ones(g.size, dtype=bool)
    for _ in range(g.size):
        leaving = free & _held(step, at_lower, at_upper)
        if not leaving.any():
            break
        free &= ~leaving
        step = np.zeros(g.size)
        if not free.any():
            break
        step[free] = _Normal(jac[:, free], normal.scale[free]).within(g[free], radius)[0]
    return step


def _within(lower: FloatArray, upper: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The bounds the iterates keep to: a hair inside ``lower`` and ``upper``."""
    span = np.where(np.isfinite(lower) & np.isfinite(upper), upper - lower, np.inf)
    lo = lower + np.minimum(1e-10 * (1.0 + np.abs(np.where(np.isfinite(lower), lower, 0.0))), 0.25 * span)
    hi = upper - np.minimum(1e-10 * (1.0 + np.abs(np.where(np.isfinite(upper), upper, 0.0))), 0.25 * span)
    return lo, hi


def _remaining(normal: _Normal, jac: FloatArray, g: FloatArray, at_lower: BoolArray, at_upper: BoolArray) -> float:
    """The fall of the cost the Gauss–Newton step predicts, the unknowns that would leave
    their bound held there."""
    gauss_newton = normal.within(g, np.inf)[0]
    if _held(gauss_newton, at_lower, at_upper).any():
        gauss_newton = _bounded(normal, jac, g, np.inf, at_lower, at_upper)
    return float(-(g @ gauss_newton))


def first_step(
    r: FloatArray,
    jac: FloatArray,
    z0: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    *,
    x_scale: FloatArray | float,
    margin: float = STATISTICAL_MARGIN,
    radius: float = np.inf,
) -> FloatArray:
    """The minimiser of the linear model ‖r + ∂r/∂z·δ‖² within the bounds, from ``z0``
    (r and ∂r/∂z given there): ``z0`` itself where the remaining step is already within
    the statistical margin (:func:`levenberg_marquardt` stops there), else the
    Gauss–Newton step within the bounds (bounded-variable least squares on the p × p
    normal equations, the directions the rows do not determine left alone), shortened
    to ‖S⁻¹δ‖ ≤ ``radius`` (S = diag ``x_scale``). No simulation: the first-order view of
    a refit from ``z0``."""
    lo, hi = _within(lower, upper)
    z = np.clip(np.asarray(z0, dtype=np.float64), lo, hi)
    scale = np.array(np.broadcast_to(np.asarray(x_scale, dtype=np.float64), z.shape))
    normal = _Normal(jac, scale)
    g = jac.T @ r
    cost = 0.5 * float(r @ r)
    if _remaining(normal, jac, g, z <= lo, z >= hi) <= margin * 2.0 * cost / max(r.size - z.size, 1):
        return z
    # ‖r + J·S·y‖² = yᵀ(SHS)y + 2(Sg)ᵀy + ‖r‖², with SHS = V·diag(w)·Vᵀ: the least-squares
    # problem ‖diag(√w)·Vᵀ·y + diag(1/√w)·Vᵀ·S·g‖² over the determined directions, with
    # the bounds on y = δ/S (bounded-variable least squares on a p × p problem).
    keep = normal.determined
    root = np.sqrt(normal.w[keep])
    a = root[:, None] * normal.v[:, keep].T
    b = -(normal.v[:, keep].T @ (g * scale)) / root
    box = lsq_linear(a, b, bounds=((lo - z) / scale, (hi - z) / scale), method="bvls")
    y = np.asarray(box.x, dtype=np.float64)
    length = float(np.linalg.norm(y))
    if length > radius:
        y *= radius / length
    out: FloatArray = np.clip(z + scale * y, lo, hi)
    return out


def levenberg_marquardt(
    residual: Residual,
    linearise: Linearise,
    z0: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    *,
    x_scale: FloatArray | float,
    tol: float,
    max_nfev: int,
    margin: float = STATISTICAL_MARGIN,
    reuse_jacobian: bool = False,
    start: tuple[FloatArray, FloatArray] | None = None,
) -> Solution:
    """Minimises ½‖r(z)‖² from ``z0`` within [lower, upper] (module docs).

    Args:
        residual: z → r(z), a large residual where z cannot be simulated.
        linearise: z → (r(z), ∂r/∂z) from one pass, or None.
        z0: start (moved inside the bounds).
        lower, upper: bounds (±inf for none).
        x_scale: typical size of each unknown (the trust region's metric).
        tol: relative change of the cost or of the scaled unknowns that stops.
        max_nfev: largest number of trial points.
        margin: the statistical stop, in squared standard errors (module docs).
        reuse_jacobian: keep the Jacobian while it predicts the fall of the cost.
        start: (r, ∂r/∂z) at ``z0`` where the caller has them (a refit from a fit whose
            Jacobian is known): the first linearisation is not computed again. With
            ``reuse_jacobian`` it is kept while it predicts the steps, as any other.
    """
    lo, hi = _within(lower, upper)
    z = np.clip(np.asarray(z0, dtype=np.float64), lo, hi)
    p = z.size
    scale = np.array(np.broadcast_to(np.asarray(x_scale, dtype=np.float64), z.shape))
    radius = float(np.linalg.norm(z / scale)) or 1.0
    first = start if start is not None else linearise(z)
    njev, nfev = (0 if start is not None else 1), 0
    if first is None:
        r = residual(z)
        return Solution(
            z, 0.5 * float(r @ r), np.zeros((r.size, p)), nfev, njev, False, "the start cannot be simulated"
        )
    r, jac = first
    cost = 0.5 * float(r @ r)
    fresh = True
    try:
        normal = _Normal(jac, scale)
    except FloatingPointError:
        return Solution(z, cost, jac, nfev, njev, False, "the start cannot be linearised")
    message, success = f"{max_nfev} trial points, the limit", False
    last_remaining = np.inf
    stalled = 0

    def refresh() -> bool:
        nonlocal r, jac, normal, fresh, njev
        out = linearise(z)
        njev += 1
        if out is None:  # pragma: no cover - z was simulated just before
            return False
        try:
            fresh_normal = _Normal(out[1], scale)
        except FloatingPointError:
            return False
        r, jac = out
        normal, fresh = fresh_normal, True
        return True

    while True:
        g = jac.T @ r
        at_lower, at_upper = z <= lo, z >= hi
        remaining = _remaining(normal, jac, g, at_lower, at_upper)
        if remaining <= margin * 2.0 * cost / max(r.size - p, 1):
            message, success = "the remaining step is within the statistical margin", True
            break
        if nfev >= max_nfev:
            break
        if not fresh and remaining > _CHORD_RATE * last_remaining:
            # The kept Jacobian converges too slowly from here: a fresh one.
            if not refresh():  # pragma: no cover - z was simulated just before
                message = "the accepted point cannot be linearised"
                break
            last_remaining = np.inf
            continue
        last_remaining = remaining
        step = _bounded(normal, jac, g, radius, at_lower, at_upper)
        trial = np.clip(z + step, lo, hi)
        step = trial - z
        r_new = residual(trial)
        nfev += 1
        cost_new = 0.5 * float(r_new @ r_new)
        predicted = -float(g @ step) - 0.5 * float(step @ (normal.h @ step))
        actual = cost - cost_new
        scaled_norm = float(np.linalg.norm(step / scale))
        if scaled_norm >= 0.95 * radius:
            # A step held to the trust region leaves much of the decrease whatever the
            # Jacobian: it says nothing of how fast the kept one converges.
            last_remaining = np.inf
        rho = actual / predicted if predicted > 0.0 else -1.0
        if rho < 0.25:
            radius = 0.25 * scaled_norm if scaled_norm > 0.0 else 0.25 * radius
        elif rho > 0.75 and scaled_norm >= 0.95 * radius:
            radius = max(radius, 2.0 * scaled_norm)
        if actual > 0.0 and predicted > 0.0:
            small_cost = actual <= tol * cost
            small_step = scaled_norm <= tol * (tol + float(np.linalg.norm(z / scale)))
            # The fall the record resolves: the statistical margin on the achieved fall,
            # as on the predicted one (a curved valley predicts falls it never gives).
            stalled = stalled + 1 if 2.0 * actual <= margin * 2.0 * cost_new / max(r_new.size - p, 1) else 0
            z, r, cost = trial, r_new, cost_new
            if stalled >= _STALLED:
                message, success = "the cost no longer falls by what the record resolves", True
                if not (reuse_jacobian and rho >= _KEEP_RHO):
                    refresh()
                break
            keep = reuse_jacobian and rho >= _KEEP_RHO
            if small_cost or small_step:
                message = "relative change of the cost below tol" if small_cost else "relative step below tol"
                success = True
                if not keep:
                    refresh()
                break
            if keep:
                fresh = False
            elif not refresh():  # pragma: no cover - z was simulated just before
                message = "the accepted point cannot be linearised"
                break
        else:
            if not fresh:
                refresh()
            if radius <= 1e-15 * (1.0 + float(np.linalg.norm(z / scale))):
                message, success = "no step lowers the cost", fresh
                break
    return Solution(z, cost, jac, nfev, njev, success, message)
