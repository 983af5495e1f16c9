"""The one judge of the diagnosis: blocked cross-validation, and the rule that accepts a
move (:func:`judge`).

**Held-out error.** The record is cut into ``folds`` contiguous blocks of equal length;
each block is held out in turn from a refit on the others, and every sample's held-out
residual comes from the refit without its block (:func:`boucwen.diagnosis.fits.held_out`:
each refit converged by Levenberg–Marquardt to its statistical stop, started at the
whole-record fit, the model running through the held-out block, which only leaves the
cost). Where the rest of the
record does not determine the model (the held-out block alone holds the largest
excursion of the input, say), the refit runs off along a flat valley and does not
converge: that block is left out of every comparison of that model, and of the held-out
error reported (:attr:`CrossValidation.converged`), so that no decision reads where a
refit's budget ended.

**The rule.** A move takes the current (*reference*) model to a *candidate* (one effect
added, one dropped, one swapped for another, two tied effects added together). The
held-out residuals r_c and r_r are cut into B contiguous batches (``folds ×
batches_per_fold``, nested in the folds), and each batch b gives the log ratio of the
two models' held-out mean-square errors,

    l_b = ln(MSE_r,b / MSE_c,b)

(positive where the candidate predicts the batch better). The held-out squared errors
are serially dependent (a misfit lasts a cycle of the input) and their size changes
along the record (the start of a record, a fast segment): means over batches much
longer than that dependence are nearly independent replicates, and the log ratio makes
each batch count alike, whatever its size (the log of a mean square is also nearer
Gaussian than the mean square). The move is **accepted** when both

1. l̄ > t₁₋α/m(B − 1) · s_l/√B: the candidate predicts held-out batches better by more
   than the batches' own spread can make it, at level α for the m moves of the round
   (Bonferroni; a one-sided paired t test on the batches); and
2. ḡ = MSE_r − MSE_c ≥ ``min_share`` · (MSE_r − σ̂²): it removes at least that share of
   what the reference leaves beyond the record's noise σ̂ (the base model's form is
   never exact; a reshaping of its misfit is significant on a long record but is no
   effect).

Two candidates lie **within the margin** of each other when neither's gain over the
other passes condition 1: the record does not tell them apart. Every decision is a
:class:`Decision` (what was compared, the gain per fold, the margin, the verdict and
why); the report, the confidence and the JSON read those objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from ..checks import FloatArray
from ..metrics import rms

__all__ = [
    "CrossValidation",
    "Decision",
    "Gain",
    "apart",
    "fold_slices",
    "gain",
    "judge",
    "on_common_blocks",
    "threshold",
]


def fold_slices(n: int, parts: int) -> list[slice]:
    """``parts`` contiguous slices of ``range(n)``, of lengths differing by at most one."""
    edges = np.linspace(0, n, parts + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


@dataclass(frozen=True, eq=False)
class CrossValidation:
    """The held-out residual of a model, sample by sample, and its summaries.

    Attributes:
        residual: held-out residual [µm] (each sample from the refit without its block).
        in_sample_rms_um: RMS of x − x̂ of the model fitted on the whole record [µm].
        rms_um: RMS of ``residual`` over the blocks whose refit converged [µm] (nan
            where none did).
        fold_rms_um: RMS of ``residual`` per block [µm].
        converged: per block, whether its refit converged.
    """

    residual: FloatArray
    in_sample_rms_um: float
    rms_um: float
    fold_rms_um: list[float]
    converged: tuple[bool, ...]

    @classmethod
    def of(
        cls, held: FloatArray, in_sample: FloatArray, folds: int, converged: tuple[bool, ...] | None = None
    ) -> CrossValidation:
        """The summaries of the held-out residual ``held`` [µm] over ``folds`` blocks,
        of which those ``converged`` (all when None) count."""
        ok = converged if converged is not None else (True,) * folds
        slices = fold_slices(held.size, folds)
        kept = [held[sl] for sl, c in zip(slices, ok) if c]
        overall = rms(np.concatenate(kept)) if kept else math.nan
        return cls(held, rms(in_sample), overall, [rms(held[sl]) for sl in slices], tuple(ok))

    def to_dict(self) -> dict[str, Any]:
        return {
            "rms_um": self.rms_um,
            "in_sample_rms_um": self.in_sample_rms_um,
            "fold_rms_um": self.fold_rms_um,
            "converged": list(self.converged),
        }


@dataclass(frozen=True)
class Gain:
    """The held-out gain of one model over another (module docs).

    Attributes:
        mean_um2: ḡ = MSE_r − MSE_c over the record [µm²] (positive: the candidate
            predicts the held-out samples better).
        log_ratio: l̄, the mean over the batches of ln(MSE_r,b / MSE_c,b) [-].
        se: its standard error s_l/√B [-].
        t: l̄ / se (0 where both are 0; ±inf where only se is).
        fold_um2: MSE_r − MSE_c per fold [µm²].
        reference_mse_um2: the reference's held-out mean-square error [µm²].
    """

    mean_um2: float
    log_ratio: float
    se: float
    t: float
    fold_um2: tuple[float, ...]
    reference_mse_um2: float


def gain(candidate: CrossValidation, reference: CrossValidation, folds: int, batches: int) -> Gain:
    """The gain of ``candidate`` over ``reference`` (module docs), ``batches`` batches
    nested in ``folds`` blocks, over the blocks whose refits converged for both (all nan
    where fewer than three batches are left)."""
    r2, c2 = reference.residual**2, candidate.residual**2
    per_fold = batches // folds
    ok = [a and b for a, b in zip(reference.converged, candidate.converged)]
    tiny = np.finfo(float).tiny
    ratios = np.array(
        [
            math.log(max(float(np.mean(r2[sl])), tiny) / max(float(np.mean(c2[sl])), tiny))
            for b, sl in enumerate(fold_slices(r2.size, batches))
            if ok[b // per_fold]
        ]
    )
    folds_ = tuple(float(np.mean(r2[sl]) - np.mean(c2[sl])) for sl in fold_slices(r2.size, folds))
    if ratios.size < 3:
        return Gain(math.nan, math.nan, math.nan, math.nan, folds_, math.nan)
    mean = float(np.mean(ratios))
    se = float(np.std(ratios, ddof=1)) / math.sqrt(ratios.size)
    t = mean / se if se > 0 else (0.0 if mean == 0 else math.copysign(math.inf, mean))
    kept = np.concatenate([sl_mask for sl_mask, c in zip(_masks(r2.size, folds), ok) if c])
    ref = float(np.mean(r2[kept]))
    return Gain(ref - float(np.mean(c2[kept])), mean, se, t, folds_, ref)


def _masks(n: int, parts: int) -> list[NDArray[np.intp]]:
    """The sample indices of each of ``parts`` contiguous slices of ``range(n)``."""
    return [np.arange(n)[sl] for sl in fold_slices(n, parts)]


def threshold(alpha: float, moves: int, batches: int) -> float:
    """t₁₋α/m with B − 1 degrees of freedom: the least t statistic of an accepted move
    among ``moves`` (m) of one round, ``batches`` (B) batches."""
    return float(stats.t.ppf(1.0 - alpha / max(moves, 1), batches - 1))


@dataclass(frozen=True)
class Decision:
    """One move judged (module docs).

    Attributes:
        move: ``"add"``, ``"drop"``, ``"swap"`` or ``"add_tied"`` (two effects that
            physics ties together, added at once).
        effects: the effects the move adds (``"add"``, ``"add_tied"``, ``"swap"``: the
            one swapped in last) or drops (``"drop"``; ``"swap"``: the one swapped out
            first), in the vocabulary's order.
        candidate: the candidate model's effects.
        reference: the reference model's effects.
        gain: the candidate's held-out gain over the reference.
        threshold: the least t statistic of an accepted move in its round.
        needed_um2: the least gain [µm²] of condition 2 (``min_share`` of what the
            reference leaves beyond the noise).
        accepted: both conditions hold.
        reason: the verdict in words.
        unknowns: the number of unknowns the candidate adds (negative: removes).
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

    @property
    def label(self) -> str:
        """The move in words, e.g. ``add creep`` or ``swap drift → creep``."""
        if self.move == "swap":
            return f"swap {self.effects[0]} → {self.effects[1]}"
        return f"{self.move.replace('_tied', '')} {' + '.join(self.effects)}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the move, the models, the gain per fold, the margin and the verdict."""
        g = self.gain
        return {
            "move": self.move,
            "effects": list(self.effects),
            "candidate": list(self.candidate),
            "reference": list(self.reference),
            "gain_um2": g.mean_um2,
            "log_ratio": g.log_ratio,
            "se": g.se,
            "t": g.t if math.isfinite(g.t) else None,
            "fold_gain_um2": list(g.fold_um2),
            "reference_mse_um2": g.reference_mse_um2,
            "threshold_t": self.threshold,
            "needed_um2": self.needed_um2,
            "accepted": self.accepted,
            "reason": self.reason,
            "unknowns": self.unknowns,
        }


def judge(
    move: str,
    effects: tuple[str, ...],
    candidate: tuple[str, ...],
    reference: tuple[str, ...],
    g: Gain,
    *,
    t_min: float,
    noise_um: float,
    min_share: float,
    unknowns: int,
) -> Decision:
    """The verdict on a move whose candidate gains ``g`` over the reference (module
    docs): ``t_min`` from :func:`threshold`, ``noise_um`` the record's noise σ̂ [µm]."""
    if not math.isfinite(g.mean_um2):
        return Decision(
            move,
            effects,
            candidate,
            reference,
            g,
            t_min,
            math.nan,
            False,
            "no block's refit converged for both models: the record cannot judge them",
            unknowns,
        )
    needed = min_share * max(g.reference_mse_um2 - noise_um**2, 0.0)
    significant = g.t > t_min
    enough = g.mean_um2 >= needed and g.mean_um2 > 0
    if significant and enough:
        reason = f"held-out gain {g.t:.3g} standard errors (> {t_min:.3g}), {_share(g, noise_um)} beyond the noise"
    elif not significant:
        reason = f"held-out gain {g.t:.3g} standard errors, within its sampling error (≤ {t_min:.3g})"
    else:
        reason = f"held-out gain significant but {_share(g, noise_um)} beyond the noise (< {min_share:.0%})"
    return Decision(move, effects, candidate, reference, g, t_min, needed, significant and enough, reason, unknowns)


def _share(g: Gain, noise_um: float) -> str:
    beyond = g.reference_mse_um2 - noise_um**2
    return f"{g.mean_um2 / beyond:.1%} of the error" if beyond > 0 else "none of the error (it is noise)"


def on_common_blocks(a: CrossValidation, b: CrossValidation, folds: int) -> tuple[float, float]:
    """The held-out RMS errors [µm] of ``a`` and ``b`` over the blocks whose refits
    converged for both (nan where none did): two models' unseen errors on the same
    samples."""
    slices = [sl for sl, x, y in zip(fold_slices(a.residual.size, folds), a.converged, b.converged) if x and y]
    if not slices:
        return math.nan, math.nan
    return rms(np.concatenate([a.residual[sl] for sl in slices])), rms(
        np.concatenate([b.residual[sl] for sl in slices])
    )


def apart(a: CrossValidation, b: CrossValidation, folds: int, batches: int, t_min: float) -> bool:
    """The record tells ``a`` and ``b`` apart: the gain of one over the other passes
    condition 1 of the rule (module docs)."""
    t = gain(a, b, folds, batches).t
    return math.isfinite(t) and abs(t) > t_min
