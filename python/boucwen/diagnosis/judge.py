"""The one judge of the diagnosis: forward validation, and the test that accepts a move
(:func:`judge`).

**The test** (:func:`gain`, :func:`judge`). For candidate c against reference r, the
per-sample loss difference on the predicted samples is d_i = e_r,i² − e_c,i² [µm²]; the
move gains ḡ = mean(d). Its sampling error is the long-run variance of d (Newey–West,
Bartlett weights) over a bandwidth B that is the *dependence length of the better
model's held-out residual* (the integrated autocorrelation time with Sokal's automatic
window): d = 2·e_r·δ − δ² (δ the difference of the predictions) varies from sample to
sample as the noise in e does, so B counts how many samples one noise excursion spans.
Under the null the candidate leaves the reference's structure and the better residual
is as dependent as the reference's, so B covers that dependence; where the candidate
explains the structure, what is left is the noise's dependence, and a gain is weighed
by its size against that noise — a large gain held by a few hundred samples after a step
counts by its size, not as one batch of sixteen (Diebold & Mariano 1995; for forecasts
of models refitted on a rolling origin, Giacomini & White 2006). The statistic
DM = ḡ / √(LRV/n) is compared with Student's t at n/B − 1 degrees of freedom (the
number of bandwidth-long stretches the predicted samples hold, less one).

A move is **accepted** when both

1. the statistic > t₁₋ₐ at a = α·2⁻ʳ/m in round r of the search, m the moves of the
   round: the rounds spend α/2, α/4, … of α (Bonferroni with weights halving from round
   to round: the first round, where the effects of largest gain are tried, spends half),
   so the family error over the whole search is at most α; and
2. ḡ ≥ ``min_share`` · (MSE_r − σ̂²): it removes at least that share of what the
   reference leaves beyond the record's noise σ̂ (the base model's form is never exact;
   a reshaping of its misfit is significant on a long record but is no effect).

Two candidates lie **within the margin** of each other when neither's gain over the
other passes condition 1 (:func:`apart`). Every decision is a :class:`Decision` (what
was compared, the gain per fold, the threshold, the verdict and why, and whether the
held-out errors came from converged refits or from their first-order screen); the report,
the confidence and the JSON read those objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from ..checks import FloatArray
from .heldout import CrossValidation
from .rules import rule

__all__ = [
    "Decision",
    "Gain",
    "apart",
    "autocovariance",
    "dependence_length",
    "gain",
    "judge",
    "least_gain",
    "level",
    "threshold",
    "within_margin",
]

#: Sokal's window constant: the autocorrelation is summed out to the first lag W with
#: W ≥ c·τ_int(W) (c = 5 keeps the truncation bias below e⁻⁵ for an exponential decay).
_SOKAL_C = 5.0


@dataclass(frozen=True)
class Gain:
    """The held-out gain of one model over another (module docs).

    Attributes:
        mean_um2: ḡ = mean of d_i = e_r,i² − e_c,i² over the samples both models predict
            from converged refits [µm²] (positive: the candidate predicts them better).
        se_um2: its standard error √(LRV/n) [µm²].
        statistic: DM = ḡ / se (0 where both are 0; ±inf where only se is).
        bandwidth: B, the dependence length of the better model's residual [samples].
        dof: the degrees of freedom n/B − 1.
        samples: n.
        fold_um2: ḡ per fold [µm²] (nan for a fold not compared).
        reference_mse_um2: the reference's held-out mean-square error on those samples [µm²].
    """

    mean_um2: float
    se_um2: float
    statistic: float
    bandwidth: int
    dof: int
    samples: int
    fold_um2: tuple[float, ...]
    reference_mse_um2: float

    @property
    def t(self) -> float:
        """The statistic (the name the decisions' JSON has always used)."""
        return self.statistic


def autocovariance(a: FloatArray, lags: int) -> FloatArray:
    """Σᵢ aᵢ·aᵢ₊ℓ for ℓ = 0 … ``lags`` (by FFT)."""
    n = a.size
    size = 1 << int(2 * n - 1).bit_length()
    spec = np.fft.rfft(a, size)
    return np.asarray(np.fft.irfft(spec * np.conj(spec), size)[: lags + 1])


def dependence_length(e: FloatArray) -> int:
    """Sokal's automatic window of ``e`` [samples] (≥ 1): the first lag W at which W ≥
    c·τ_int(W), τ_int(W) = 1 + 2·Σ_{ℓ≤W} ρ(ℓ) the integrated autocorrelation time —
    the lags over which one excursion of ``e`` stays correlated."""
    n = e.size
    if n < 4:
        return 1
    acov = autocovariance(e - np.mean(e), n - 1)
    if acov[0] <= 0:
        return 1
    rho = acov / acov[0]
    tau = 1.0
    for w in range(1, n):
        tau += 2.0 * float(rho[w])
        if w >= _SOKAL_C * tau:
            return w
    return n - 1


def gain(candidate: CrossValidation, reference: CrossValidation) -> Gain:
    """The gain of ``candidate`` over ``reference`` (module docs) on the samples both
    predict from converged refits (all nan where fewer than 3 are left)."""
    folds = candidate.folds
    usable = tuple(a and b for a, b in zip(candidate.converged, reference.converged))
    mask = folds.mask(usable)
    rc, rr = candidate.residual[mask], reference.residual[mask]
    d = rr**2 - rc**2
    per_fold = tuple(
        float(np.mean(reference.residual[folds.test(k)] ** 2 - candidate.residual[folds.test(k)] ** 2))
        if ok
        else math.nan
        for k, ok in enumerate(usable)
    )
    n = d.size
    if n < 3:
        return Gain(math.nan, math.nan, math.nan, 0, 0, n, per_fold, math.nan)
    # d = 2·e_r·δ − δ², δ = x̂_c − x̂_r the difference of the predictions: given the two
    # models, the sampling error of its mean is that of 2·Σ e·δ/n over the residual
    # process e, Var = 4/n²·Σ_ℓ w_ℓ·γ_e(ℓ)·S_δ(ℓ), γ_e the autocovariance of the better
    # model's residual, S_δ(ℓ) = Σᵢ δᵢ·δᵢ₊ℓ, Bartlett weights w_ℓ out to e's window; each
    # fold on its own (its refits are its own: the folds are independent), summed.
    overall_better = float(np.mean(rc**2)) <= float(np.mean(rr**2))
    var, terms, widest = 0.0, 0.0, 0
    for k, ok in enumerate(usable):
        if not ok:
            continue
        sl = folds.test(k)
        ck, rk = candidate.residual[sl], reference.residual[sl]
        if ck.size < 2:
            continue
        e = (ck if overall_better else rk) - np.mean(ck if overall_better else rk)
        delta = rk - ck
        lags = min(dependence_length(e), ck.size - 1)
        gamma = autocovariance(e, lags) / ck.size
        s_delta = autocovariance(delta, lags)
        weights = np.concatenate([[1.0], 2.0 * (1.0 - np.arange(1, lags + 1) / (lags + 1))])
        var += 4.0 * float(np.sum(weights * gamma * s_delta)) / n**2
        # The independent terms of e·δ in the fold: its length over their integrated
        # autocorrelation time.
        rho = (gamma / gamma[0] if gamma[0] > 0 else np.zeros_like(gamma)) * (
            s_delta / s_delta[0] if s_delta[0] > 0 else np.zeros_like(s_delta)
        )
        terms += ck.size / max(1.0, float(np.sum(weights * rho)))
        widest = max(widest, lags)
    mean = float(np.mean(d))
    se = math.sqrt(max(var, 0.0))
    stat = mean / se if se > 0 else (0.0 if mean == 0 else math.copysign(math.inf, mean))
    dof = max(int(terms) - 1, 1)
    return Gain(mean, se, stat, widest, dof, n, per_fold, float(np.mean(rr**2)))


def level(alpha: float, moves: int, round_: int = 0) -> float:
    """The level of one move's test: α·2⁻ʳ/m, r the round of the search (1, 2, …) and m
    the moves of the round (module docs): the rounds spend α, α/2, α/4, … of which the
    whole search spends at most α. ``round_`` 0: a family of its own, α/m (a validation
    record's comparisons)."""
    return alpha * 0.5 ** max(round_, 0) / max(moves, 1)


def threshold(level_: float, dof: int) -> float:
    """t₁₋ₐ(dof): the least statistic of an accepted move at level ``level_``."""
    return float(stats.t.ppf(1.0 - level_, max(dof, 1)))


@dataclass(frozen=True)
class Decision:
    """One move judged (module docs).

    Attributes:
        move: ``"add"``, ``"drop"``, ``"swap"``, ``"add_tied"`` (two effects that
            physics ties together, added at once) or ``"structure"`` (the whole model
            replaced by another structure: the hysteretic oscillator).
        effects: the effects the move adds (``"add"``, ``"add_tied"``, ``"swap"``: the
            one swapped in last) or drops (``"drop"``; ``"swap"``: the one swapped out
            first), in the vocabulary's order.
        candidate: the candidate model's effects.
        reference: the reference model's effects.
        gain: the candidate's held-out gain over the reference.
        threshold: the least statistic of an accepted move at its level and degrees of
            freedom.
        needed_um2: the least gain [µm²] of condition 2 (``min_share`` of what the
            reference leaves beyond the noise).
        accepted: both conditions hold.
        reason: the verdict in words.
        unknowns: the number of unknowns the candidate adds (negative: removes).
        exact: the held-out errors it read came from converged refits (else from their
            first-order screen, which only leaves out moves far from the threshold).
        rule: the rule that decided it (:data:`boucwen.diagnosis.rules.RULES`).
    """

    move: str
    effects: tuple[str, ...]
    candidate: tuple[str, ...]
    reference: tuple[str, ...]
    gain: Gain
    threshold: float
    needed_um2: float
    accepted: bool
    reason: str
    unknowns: int
    exact: bool = True
    rule: str = "forward_gain"

    def __post_init__(self) -> None:
        rule(self.rule)  # a decision names a rule of the registry

    @property
    def label(self) -> str:
        """The move in words, e.g. ``add creep`` or ``swap drift → creep``."""
        if self.move in ("swap", "structure"):
            return f"swap {self.effects[0]} → {self.effects[1]}"
        return f"{self.move.replace('_tied', '')} {' + '.join(self.effects)}"

    @property
    def margin(self) -> float:
        """How far the statistic is above (+) or below (−) the threshold."""
        return self.gain.statistic - self.threshold

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the move, the models, the gain per fold, the threshold and the verdict."""
        g = self.gain
        return {
            "move": self.move,
            "effects": list(self.effects),
            "candidate": list(self.candidate),
            "reference": list(self.reference),
            "gain_um2": g.mean_um2,
            "se_um2": g.se_um2,
            "t": g.statistic if math.isfinite(g.statistic) else None,
            "bandwidth": g.bandwidth,
            "dof": g.dof,
            "samples": g.samples,
            "fold_gain_um2": list(g.fold_um2),
            "reference_mse_um2": g.reference_mse_um2,
            "threshold_t": self.threshold,
            "needed_um2": self.needed_um2,
            "accepted": self.accepted,
            "reason": self.reason,
            "unknowns": self.unknowns,
            "exact": self.exact,
            "rule": self.rule,
        }


def least_gain(mse_um2: float, noise_um: float, min_share: float, resolution_um: float) -> float:
    """The least gain a move must bring [µm²] (condition 2, module docs): ``min_share`` of
    the reference's mean-square error ``mse_um2`` beyond the noise, and no less than the
    mean square of the model's own sampling-rate error ``resolution_um``."""
    return max(min_share * max(mse_um2 - noise_um**2, 0.0), resolution_um**2)


def judge(
    move: str,
    effects: tuple[str, ...],
    candidate: tuple[str, ...],
    reference: tuple[str, ...],
    g: Gain,
    *,
    level_: float,
    noise_um: float,
    min_share: float,
    unknowns: int,
    exact: bool = True,
    resolution_um: float = 0.0,
) -> Decision:
    """The verdict on a move whose candidate gains ``g`` over the reference (module
    docs), at the move's level ``level_`` (:func:`level`); ``noise_um`` the record's
    noise σ̂ [µm]; ``resolution_um`` the model's own error from stepping at the
    record's sampling interval [µm RMS] (:func:`boucwen.diagnosis.fits.resolution`): a
    gain below its mean square may be a candidate reshaping that error, and is not
    enough. A gain that cannot be computed (no fold compared) never accepts."""
    if not math.isfinite(g.mean_um2) or not math.isfinite(g.statistic):
        # A statistic that is not a number is no evidence either way: never a decision.
        why = (
            "no fold's refit converged for both models: the record cannot judge them"
            if not math.isfinite(g.mean_um2) or math.isnan(g.statistic)
            else "the two models predict the held-out samples alike (no sampling error to weigh the gain by)"
        )
        return Decision(
            move, effects, candidate, reference, g, math.nan, math.nan, False, why, unknowns, exact, "not_judgeable"
        )
    t_min = threshold(level_, g.dof)
    needed = least_gain(g.reference_mse_um2, noise_um, min_share, resolution_um)
    significant = g.statistic > t_min
    enough = g.mean_um2 >= needed and g.mean_um2 > 0
    if significant and enough:
        reason = (
            f"held-out gain {g.statistic:.3g} standard errors (> {t_min:.3g}), {_share(g, noise_um)} beyond the noise"
        )
    elif not significant:
        reason = f"held-out gain {g.statistic:.3g} standard errors, within its sampling error (≤ {t_min:.3g})"
    else:
        reason = (
            f"held-out gain significant but {_share(g, noise_um)} beyond the noise (< {min_share:.0%})"
            if needed > resolution_um**2
            else f"held-out gain significant but below the model's own sampling-rate error ({resolution_um:.2g} µm RMS)"
        )
    by = (
        "forward_gain"
        if enough or not significant
        else ("least_share" if needed > resolution_um**2 else "sampling_resolution")
    )
    return Decision(
        move, effects, candidate, reference, g, t_min, needed, significant and enough, reason, unknowns, exact, by
    )


def _share(g: Gain, noise_um: float) -> str:
    beyond = g.reference_mse_um2 - noise_um**2
    return f"{g.mean_um2 / beyond:.1%} of the error" if beyond > 0 else "none of the error (it is noise)"


def apart(a: CrossValidation, b: CrossValidation, level_: float) -> bool:
    """The record tells ``a`` and ``b`` apart: the gain of one over the other passes
    condition 1 of the rule at level ``level_`` (module docs)."""
    g = gain(a, b)
    return not math.isnan(g.statistic) and abs(g.statistic) > threshold(level_, g.dof)


def within_margin(a: CrossValidation, b: CrossValidation, level_: float) -> bool:
    """The record does not tell ``a`` from ``b``: their gain can be computed and does not
    pass condition 1 at level ``level_``. A gain that cannot be computed (no fold
    compared) is no evidence that two models are alike."""
    g = gain(a, b)
    return math.isfinite(g.statistic) and abs(g.statistic) <= threshold(level_, g.dof)
