"""The one judge of the diagnosis: forward validation, and the test that accepts a move
(:func:`judge`).

**Held-out error: forward in time** (:class:`Folds`). What a user relies on is the model
predicting data it has not seen: later in the record, and on another record. The record
is cut at K origins o₁ < … < o_K; fold k is refitted on the samples before its origin
alone, [0, o_k), and predicts the samples from o_k to the next origin (the last fold to
the end), the model running from the record's start on its own state through them.
Every sample after o₁ is predicted once, each by a model that has seen only its past
(rolling-origin evaluation; Tashman 2000, Bergmeir, Hyndman & Koo 2018). Two reasons
for forward rather than interleaved folds:

* a slow effect fitted beside a held-out segment's neighbours on both sides (creep with
  a long time constant, a gain drift, a static nonlinearity driven by a slow input)
  can take up the record's own slow drift, which runs continuously across the segment
  and which another day does not share; fitted on the past alone it must *predict* that
  drift, which it can only do where the input drives it;
* a measured record rests, steps once, oscillates and holds: the refit needs the step
  and enough of what follows to see a step response by, and the samples that test it
  are the ones after.

**Where the origins lie.** The vocabulary holds effects that the input's travel reveals
(the hysteresis, a static nonlinearity, a lag, a mode, a delay) and effects that elapsed
time reveals (creep, a drift, a gain drift). The origins are the quantiles of the record's
*excitation* M(k) = ½·E(k)/E(n) + ½·k/n, half its voltage travel so far (E: the total
variation of u, smoothed over a millisecond and counted beyond its noise, so that a rest
adds nothing) and half its elapsed time: o₁ where M reaches ``first_origin`` (½: the
first refit holds half of both), the others evenly in M after it. A rest adds time but
no travel, so a record that rests for two thirds of its length and then oscillates has
its first origin in the oscillation, after the step; a long final hold is tested for
what elapsed time reveals. The first origin also holds at least a share
``first_origin`` of the travel, so that the first refit has seen the step.

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
from ..metrics import rms
from ..record import Record, travel_steps

__all__ = [
    "CrossValidation",
    "Decision",
    "Folds",
    "Gain",
    "apart",
    "dependence_length",
    "excitation",
    "gain",
    "judge",
    "level",
    "on_common_folds",
    "threshold",
]

#: Sokal's window constant: the autocorrelation is summed out to the first lag W with
#: W ≥ c·τ_int(W) (c = 5 keeps the truncation bias below e⁻⁵ for an exponential decay).
_SOKAL_C = 5.0


def excitation(record: Record) -> FloatArray:
    """The record's excitation so far, M(k) for k = 0 … n − 1 (module docs): half its
    voltage travel share (:func:`boucwen.record.travel_steps`: a rest adds none), half
    its elapsed time share, rising from 0 to 1."""
    n = len(record)
    travel = np.concatenate([[0.0], np.cumsum(travel_steps(record))])
    total = float(travel[-1])
    share = travel / total if total > 0 else np.zeros(n)
    return np.asarray(0.5 * share + 0.5 * np.arange(n) / max(n - 1, 1))


#: Eigenvalues of the record's information below this share of the largest belong to
#: directions the record does not determine: the share of them the past holds is not
#: asked for.
_INFO_RCOND = 1e-10


def informed(jacobian: FloatArray, share: float) -> int:
    """The first sample k such that the samples before it hold on average ``share`` of
    the information the whole record holds about each unknown: tr((JᵀJ)⁻¹·J_[0,k)ᵀJ_[0,k))
    / p reaches ``share`` (over the directions JᵀJ determines, p of them; ``jacobian`` J,
    one row per sample). The average, not the least: an unknown that only the record's
    last burst tells about (a rate term, a fast mode) would otherwise push the origin to
    the end, while the refits before it leave that unknown where the whole record put
    it."""
    n, p = jacobian.shape
    if p == 0 or n < 2:
        return int(min(max(1, round(share * n)), max(n - 1, 1)))
    w, v = np.linalg.eigh(jacobian.T @ jacobian)
    keep = w > _INFO_RCOND * max(float(w[-1]), 1e-300)
    z = jacobian @ (v[:, keep] / np.sqrt(w[keep]))
    # Each sample's share of the information, summed over the directions: its leverage.
    leverage = np.sum(z * z, axis=1) / z.shape[1]
    k = int(np.searchsorted(np.cumsum(leverage), share - 1e-12, side="left")) + 1
    return int(min(max(k, 1), n - 1))


@dataclass(frozen=True)
class Folds:
    """The forward-validation folds of a record (module docs).

    Attributes:
        n: samples of the record.
        origins: o₁ < … < o_K: fold k is refitted on [0, o_k) and predicts [o_k, o_k+1)
            (the last fold to the end).
    """

    n: int
    origins: tuple[int, ...]

    @classmethod
    def of(cls, record: Record, count: int, first_origin: float, jacobian: FloatArray) -> Folds:
        """``count`` folds of ``record`` (module docs): the first origin where the past
        holds on average a share ``first_origin`` of what the record tells about each
        unknown of the model whose Jacobian over the record is ``jacobian`` (the base
        model), the others evenly in the record's excitation after it; fewer where the
        record cannot hold them (each fold predicts at least one sample)."""
        n = len(record)
        first = informed(jacobian, first_origin)
        level = excitation(record)
        targets = level[first] + (1.0 - level[first]) * np.arange(1, count) / count
        origins = [first, *(int(np.searchsorted(level, q, side="left")) for q in targets)]
        kept: list[int] = []
        for o in origins:
            o = max(o, kept[-1] + 1 if kept else 1)
            if o < n:
                kept.append(o)
        return cls(n, tuple(kept))

    @property
    def count(self) -> int:
        return len(self.origins)

    def train(self, k: int) -> slice:
        """The samples fold ``k`` is refitted on: the record before its origin."""
        return slice(0, self.origins[k])

    def test(self, k: int) -> slice:
        """The samples fold ``k`` predicts."""
        stop = self.origins[k + 1] if k + 1 < len(self.origins) else self.n
        return slice(self.origins[k], stop)

    @property
    def tested(self) -> slice:
        """Every predicted sample: from the first origin to the end."""
        return slice(self.origins[0] if self.origins else self.n, self.n)

    def mask(self, usable: tuple[bool, ...]) -> FloatArray:
        """A boolean mask over the record of the samples predicted by the folds that are
        ``usable``."""
        out = np.zeros(self.n, dtype=bool)
        for k, ok in enumerate(usable):
            if ok:
                out[self.test(k)] = True
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"n": self.n, "origins": list(self.origins)}


@dataclass(frozen=True, eq=False)
class CrossValidation:
    """The held-out residual of a model and its summaries.

    Attributes:
        residual: held-out residual [µm], sample by sample (nan before the first origin:
            no fold predicts those samples).
        folds: the folds.
        in_sample_rms_um: RMS of x − x̂ of the model fitted on the whole record [µm].
        rms_um: RMS of ``residual`` over the folds whose refit converged [µm] (nan where
            none did).
        fold_rms_um: RMS of ``residual`` per fold [µm].
        converged: per fold, whether its refit converged (a first-order screen counts as
            converged: it is confirmed by refits where a decision depends on it).
        exact: the refits were converged (else their first-order screen).
    """

    residual: FloatArray
    folds: Folds
    in_sample_rms_um: float
    rms_um: float
    fold_rms_um: list[float]
    converged: tuple[bool, ...]
    exact: bool

    @classmethod
    def of(
        cls, held: FloatArray, in_sample: FloatArray, folds: Folds, converged: tuple[bool, ...], exact: bool
    ) -> CrossValidation:
        """The summaries of the held-out residual ``held`` [µm] over ``folds``, of which
        those ``converged`` count."""
        mask = folds.mask(converged)
        overall = rms(held[mask]) if mask.any() else math.nan
        per_fold = [rms(held[folds.test(k)]) for k in range(folds.count)]
        return cls(held, folds, rms(in_sample), overall, per_fold, tuple(converged), exact)

    @classmethod
    def whole(cls, residual: FloatArray) -> CrossValidation:
        """A residual every sample of which is unseen (a model carried to another
        record) as one fold."""
        folds = Folds(residual.size, (0,))
        return cls.of(residual, residual, folds, (True,), True)

    def to_dict(self) -> dict[str, Any]:
        return {
            "rms_um": self.rms_um,
            "in_sample_rms_um": self.in_sample_rms_um,
            "fold_rms_um": self.fold_rms_um,
            "converged": list(self.converged),
            "origins": list(self.folds.origins),
            "exact": self.exact,
        }


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


def _autocovariance(a: FloatArray, lags: int) -> FloatArray:
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
    acov = _autocovariance(e - np.mean(e), n - 1)
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
        gamma = _autocovariance(e, lags) / ck.size
        s_delta = _autocovariance(delta, lags)
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
        }


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
) -> Decision:
    """The verdict on a move whose candidate gains ``g`` over the reference (module
    docs), at the move's level ``level_`` (:func:`level`); ``noise_um`` the record's
    noise σ̂ [µm]. A gain that cannot be computed (no fold compared) never accepts."""
    if not math.isfinite(g.mean_um2) or math.isnan(g.statistic):
        return Decision(
            move,
            effects,
            candidate,
            reference,
            g,
            math.nan,
            math.nan,
            False,
            "no fold's refit converged for both models: the record cannot judge them",
            unknowns,
            exact,
        )
    t_min = threshold(level_, g.dof)
    needed = min_share * max(g.reference_mse_um2 - noise_um**2, 0.0)
    significant = g.statistic > t_min
    enough = g.mean_um2 >= needed and g.mean_um2 > 0
    if significant and enough:
        reason = (
            f"held-out gain {g.statistic:.3g} standard errors (> {t_min:.3g}), {_share(g, noise_um)} beyond the noise"
        )
    elif not significant:
        reason = f"held-out gain {g.statistic:.3g} standard errors, within its sampling error (≤ {t_min:.3g})"
    else:
        reason = f"held-out gain significant but {_share(g, noise_um)} beyond the noise (< {min_share:.0%})"
    return Decision(
        move, effects, candidate, reference, g, t_min, needed, significant and enough, reason, unknowns, exact
    )


def _share(g: Gain, noise_um: float) -> str:
    beyond = g.reference_mse_um2 - noise_um**2
    return f"{g.mean_um2 / beyond:.1%} of the error" if beyond > 0 else "none of the error (it is noise)"


def on_common_folds(a: CrossValidation, b: CrossValidation) -> tuple[float, float]:
    """The held-out RMS errors [µm] of ``a`` and ``b`` over the folds whose refits
    converged for both (nan where none did): two models' unseen errors on the same
    samples."""
    mask = a.folds.mask(tuple(x and y for x, y in zip(a.converged, b.converged)))
    if not mask.any():
        return math.nan, math.nan
    return rms(a.residual[mask]), rms(b.residual[mask])


def apart(a: CrossValidation, b: CrossValidation, level_: float) -> bool:
    """The record tells ``a`` and ``b`` apart: the gain of one over the other passes
    condition 1 of the rule at level ``level_`` (module docs)."""
    g = gain(a, b)
    return not math.isnan(g.statistic) and abs(g.statistic) > threshold(level_, g.dof)
