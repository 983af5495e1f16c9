"""The screen of the diagnosis: every add move scored at the current model before any fit.

A converged fit of a candidate costs tens to hundreds of simulations of the record (its
starts, its Levenberg–Marquardt steps, its fold refits); most moves of a round are then
refused by the judge. The **score (Lagrange-multiplier, Rao) test** asks the same
question — does the effect explain part of what the current model leaves? — at the
current model itself, from its residual and the effect's directions there, with no fit.

**The statistic.** At the current model's optimum, with residual r = x − x̂ [µm] and
Jacobian J_b, an added effect moves the prediction along its directions D (n × q): the
derivative of x̂ along each of the effect's unknowns, and the step from x̂ to the model
with the effect at its start (a lag's corner, a mode's frequency and damping, a delay:
the value of a parameter that exists only under the alternative). Projected off what
the current model's own unknowns can already do (P = I − J_b J_b⁺) and made orthonormal
(Q), the score is s = Qᵀr and the statistic

    LM = sᵀ V⁻¹ s,

with V the scores' covariance under the null, Qᵀ Γ Q, Γ the residual's autocovariance
tapered by Bartlett weights out to its dependence length (Sokal's window) — the judge's
weights, which take the dependence of the residual into account where a sandwich over
samples would not (a direction concentrated on a step's few hundred samples has
high leverage, and a per-sample sandwich then underestimates its variance). The
autocovariance is that of the residual once the best direction is fitted to first
order (the noise's, not the structure the effect explains, as the judge weighs a gain
against the better model's residual). Under the null (the effect adds nothing) LM is χ²
with q degrees of freedom (Rao 1948; Breusch & Pagan 1980).

**Parameters that exist only under the alternative** (Davies 1987; Andrews & Ploberger
1994): where an effect has several starts — a grid of corners, of modes (the residual's
spectral peaks among them), of delays — LM is computed at each and the largest is taken.
Its null distribution is not the pointwise χ²: it is simulated from the scores' joint
normal law over the whole grid (Hansen 1996), covariance QᵀΓQ across grid points, the
supremum of s*(θ)ᵀV(θ)⁻¹s*(θ) drawn :data:`DRAWS` times with a fixed seed.

**What passes.** A move passes the screen, and gets converged fits and the judge, where
both

1. its p-value is at most :data:`SCREEN_FACTOR` times the judge's level for the move:
   the held-out statistic of an effect is smaller than its in-sample score (the judge's
   samples are fewer and its refits have seen less), so a move the judge accepts at level
   a has an in-sample score far below a; the factor is a margin for what the score
   approximates (first order, a grid, a variance from the data), and a loose screen
   costs only fits, never a decision; and
2. its first-order gain — the mean-square error the projection removes from the
   in-sample residual — is at least :data:`GAIN_SHARE` of the least gain the judge asks
   of the move (``min_share`` of the current model's error beyond the noise, and the
   model's own sampling-rate error), both in-sample: a converged fit moves further
   along the effect than its first-order step, so half is the margin.

The screen never accepts: what passes is fitted and judged as before. Its ranking of a
move's grid points chooses the starts its converged fit runs from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.signal import fftconvolve

from .._core import EffectSet
from ..checks import FloatArray
from ..effects import fit_box
from ..record import Record
from .judge import autocovariance, dependence_length

__all__ = ["DRAWS", "GAIN_SHARE", "SCREEN_FACTOR", "Score", "Scorer", "sup_test"]

#: Draws of the supremum's null (its p-value resolved to about 1/DRAWS).
DRAWS = 999
#: A move passes where its p-value is at most this many times the judge's level.
SCREEN_FACTOR = 20.0
#: ... and its first-order gain at least this share of the least gain the judge asks.
GAIN_SHARE = 0.5
#: A direction whose part outside the current model's span is below this share of its
#: size adds nothing the current model cannot do.
_OUTSIDE = 1e-7


@dataclass(frozen=True)
class Score:
    """One move's score (module docs).

    Attributes:
        statistic: the largest LM over the move's grid [-].
        dof: q at that grid point [-].
        p_value: the chance of a supremum this large under the null [-].
        gain_um2: the first-order in-sample gain at that grid point [µm²].
        needed_um2: the least first-order gain that passes [µm²].
        level: the largest p-value that passes [-].
        grid: grid points scored.
        passed: both conditions hold.
        reason: the verdict in words.
        order: the grid points (indices into the move's starts) from the largest LM down.
    """

    statistic: float
    dof: int
    p_value: float
    gain_um2: float
    needed_um2: float
    level: float
    grid: int
    passed: bool
    reason: str
    order: tuple[int, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "statistic": self.statistic,
            "dof": self.dof,
            "p_value": self.p_value,
            "gain_um2": self.gain_um2,
            "needed_um2": self.needed_um2,
            "level": self.level,
            "grid": self.grid,
            "passed": self.passed,
            "reason": self.reason,
        }


def _orthonormal(a: FloatArray, rcond: float = 1e-10) -> FloatArray:
    """An orthonormal basis of the columns of ``a`` (each scaled to unit size first),
    without the directions below ``rcond`` of the largest."""
    if a.shape[1] == 0:
        return a
    norms = np.linalg.norm(a, axis=0)
    keep = norms > 0
    if not np.any(keep):
        return a[:, :0]
    u, s, _ = np.linalg.svd(a[:, keep] / norms[keep], full_matrices=False)
    return np.asarray(u[:, s > rcond * s[0]])


class Scorer:
    """Scores moves at one current model on one record (module docs).

    Args:
        record: the record.
        x_hat: the current model's prediction over it [µm].
        jacobian: the current model's Jacobian there (one row per sample).
        params, h0: the current model's base parameters and h0 [µm] (its effects are in
            each start).
    """

    def __init__(self, record: Record, x_hat: FloatArray, jacobian: FloatArray, params: Any, h0: float) -> None:
        self.record, self.x_hat, self.params, self.h0 = record, x_hat, params, h0
        self.r = record.x - x_hat
        self.basis = _orthonormal(jacobian)
        self.mse = float(np.mean(self.r**2))

    def _outside(self, d: FloatArray) -> FloatArray:
        """``d``'s columns projected off the current model's span, those left outside it."""
        left = d - self.basis @ (self.basis.T @ d)
        size = np.linalg.norm(d, axis=0)
        return np.asarray(left[:, np.linalg.norm(left, axis=0) > _OUTSIDE * np.maximum(size, 1e-300)])

    def directions(self, start: EffectSet, added: tuple[str, ...]) -> FloatArray | None:
        """D at one start (module docs): the step from x̂ to the start where the start
        changes the prediction (a corner, a mode, a delay: the parameter under the
        alternative fixed at a grid point, the step its one direction), else — an effect
        started at its neutral value, a creep's or a drift's gains at 0 — the derivative
        along each unknown of the ``added`` effects
        (:meth:`boucwen.effects.fit.Box.directions`); None where the start cannot be
        simulated."""
        rec = self.record
        box = fit_box(rec, self.params, start, self.h0)
        xs = box.layout.simulate(box.v0, rec.u, rec.dt)
        if xs is None or not np.all(np.isfinite(xs)):
            return None
        step = xs - self.x_hat
        if float(np.linalg.norm(step)) > _OUTSIDE * float(np.linalg.norm(self.x_hat)):
            return step[:, None]
        columns = [d for d in box.directions(added, xs, rec.u, rec.dt) if np.all(np.isfinite(d))]
        return np.column_stack(columns) if columns else step[:, None]

    def score(
        self, starts: list[EffectSet], added: tuple[str, ...], level: float, needed_um2: float
    ) -> tuple[Score, list[EffectSet]]:
        """The move's :class:`Score` over its ``starts`` (the grid) at the judge's
        ``level`` and least gain ``needed_um2`` [µm²], and the starts ranked by LM
        (those that cannot be simulated left out)."""
        grid: list[tuple[int, FloatArray]] = []
        for k, s in enumerate(starts):
            d = self.directions(s, added)
            if d is None:
                continue
            q = _orthonormal(self._outside(d))
            if q.shape[1]:
                grid.append((k, q))
        passes_level = min(1.0, SCREEN_FACTOR * level)
        needed = GAIN_SHARE * needed_um2
        if not grid:
            why = "its directions lie within what the current model can already do (or cannot be simulated)"
            return Score(0.0, 0, 1.0, 0.0, needed, passes_level, 0, False, why), []
        lm, p_value, gains = sup_test(self.r, [q for _, q in grid])
        k_best = int(np.argmax(lm))
        stat, gain = lm[k_best], gains[k_best]
        significant = p_value <= passes_level
        enough = gain >= needed
        if significant and enough:
            why = f"score {stat:.3g} (p = {p_value:.3g} ≤ {passes_level:.3g}), first-order gain {_share(gain, needed)}"
        elif not significant:
            why = f"score {stat:.3g} within its sampling error (p = {p_value:.3g} > {passes_level:.3g}): not fitted"
        else:
            why = f"score {stat:.3g} significant but its first-order gain is {_share(gain, needed)}: not fitted"
        order = tuple(grid[i][0] for i in sorted(range(len(grid)), key=lambda i: (-lm[i], i)))
        dof = int(grid[k_best][1].shape[1])
        result = Score(stat, dof, p_value, gain, needed, passes_level, len(grid), significant and enough, why, order)
        return result, [starts[k] for k in order]


def sup_test(r: FloatArray, grid: list[FloatArray], draws: int = DRAWS) -> tuple[list[float], float, list[float]]:
    """The score test over a grid (module docs): ``r`` the residual [µm], ``grid`` one
    orthonormal basis (n × q, off the current model's span) per grid point. Returns the
    LM statistic at each grid point, the p-value of their supremum from ``draws`` draws
    of the scores' joint null (a fixed seed), and each point's first-order gain (the
    mean square its projection removes from ``r``) [µm²]."""
    n = r.size
    q_all = np.column_stack(grid)
    s_all = q_all.T @ r
    sizes = [q.shape[1] for q in grid]
    edges = np.concatenate([[0], np.cumsum(sizes)])
    gains = [float(s_all[a:b] @ s_all[a:b]) / n for a, b in zip(edges[:-1], edges[1:])]
    # The noise's autocovariance from the residual once the best direction is fitted,
    # Bartlett-tapered out to its dependence length (the judge's weights).
    best = int(np.argmax(gains))
    a, b = edges[best], edges[best + 1]
    e = r - q_all[:, a:b] @ s_all[a:b]
    e = e - np.mean(e)
    lags = max(0, min(dependence_length(e), n - 1))
    gamma = autocovariance(e, lags) / n * (1.0 - np.arange(lags + 1) / (lags + 1))
    kernel = np.concatenate([gamma[:0:-1], gamma])
    # The scores' covariance under the null: Qᵀ Γ Q, Γ the tapered Toeplitz covariance.
    gq = fftconvolve(q_all, kernel[:, None], mode="same", axes=0) if lags else gamma[0] * q_all
    omega = q_all.T @ gq
    omega = 0.5 * (omega + omega.T)
    lm: list[float] = []
    inverse_roots: list[FloatArray | None] = []
    for a, b in zip(edges[:-1], edges[1:]):
        block = omega[a:b, a:b]
        try:
            chol = np.linalg.cholesky(block)
        except np.linalg.LinAlgError:
            lm.append(0.0)
            inverse_roots.append(None)
            continue
        sw = np.linalg.solve(chol, s_all[a:b])
        lm.append(float(sw @ sw))
        inverse_roots.append(chol)
    # Draws of the supremum under the null: scores jointly normal with covariance Ω.
    w, v = np.linalg.eigh(omega)
    root = v * np.sqrt(np.clip(w, 0.0, None))
    drawn = np.random.default_rng(0).standard_normal((draws, omega.shape[0])) @ root.T
    sup = np.zeros(draws)
    for (a, b), root_k in zip(zip(edges[:-1], edges[1:]), inverse_roots):
        if root_k is None:
            continue
        white = np.linalg.solve(root_k, drawn[:, a:b].T)
        sup = np.maximum(sup, np.sum(white**2, axis=0))
    p_value = float((1 + np.sum(sup >= max(lm))) / (draws + 1))
    return lm, p_value, gains


def _share(gain: float, needed: float) -> str:
    """The first-order gain against the least that passes, in words."""
    if needed <= 0:
        return f"{math.sqrt(max(gain, 0.0)):.3g} µm RMS"
    return f"{gain / needed:.3g}× the least that passes"
