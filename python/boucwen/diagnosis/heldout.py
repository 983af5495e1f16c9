"""Held-out data: where the record is cut, each model's errors on what its refits did not
see, and their summaries — the folds (:class:`Folds`), the forward validation of a fit
(:func:`held_out`, from :class:`Leaveout`) and its residual (:class:`CrossValidation`).
The judge (:mod:`~boucwen.diagnosis.judge`) compares two models by these; a second record
of the device is :mod:`~boucwen.diagnosis.unseen`'s.

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

**Held-out errors** (:func:`held_out`; the folds are :class:`Folds`):
each fold's model is the whole-record fit refitted on the samples before the fold's
origin, then run on through the fold. Two ways, one result up to the refits' own
convergence:

* the **screen**: the first Gauss–Newton step of that refit from the whole-record
  optimum z*, δ_k = (J_kᵀJ_k)⁺·J_kᵀ·r_k on the rows before the origin (approximate
  leave-out: Rad & Maleki 2020; the infinitesimal jackknife: Giordano et al. 2019) —
  one linear solve on the Jacobian the fit already has and one simulation per fold;
* the **refit**: Levenberg–Marquardt on those samples to its statistical stop, started
  at z* with that Jacobian (its first step is the screen's), the independent folds run
  at once on the available cores.

The search reads the screen where a decision is far from its threshold and the refits
everywhere else (:mod:`~boucwen.diagnosis.search`).

**What belongs to the record, not the device** (:data:`PER_RECORD`, one place). A user
carries the model to the device's next record and re-estimates there what is that
record's own; the held-out samples are scored the same way, alike for every model,
before their error is counted (:func:`less_record_part`):

* the record's **offset** and **straight-line trend in time**, by linear least squares
  on the record's held-out samples together (every fold's span: they are one record, one
  day, with one sensor zero and one drift): a sensor's zero, the mounting, the day's
  temperature and a sensor's settling belong to the day, not to the device, and move
  from one record to the next; a move whose gain lives in the record's own trend (a
  creep element as slow as the record, a drift's level and rate) then earns nothing,
  while one that follows the input keeps its gain. One line for the record, not one per
  fold: a line per span of a short record would also take the slow part of what the
  input drives there (a creep's response to each step, a tenth of a second long), which
  another record does not share with the day;
* the **initial state** of h and of each effect: on another record it is re-estimated
  there (:func:`boucwen.diagnosis.unseen.carried`, h0 by a scalar search); on a forward
  span it is the model's own, run from the record's start through the span's past — the
  voltage before the span is known to a user there, so the state is predicted, not
  fitted;
* the record's **own effects** (:attr:`boucwen.effects.Effect.of_record`: a drift, a mains
  pickup whose phase is the record's): left out of a model carried to another record;
  on a forward span fitted on the span's past like the device's, as a user with that
  record's past would.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import FloatArray
from ..levenberg import STATISTICAL_MARGIN, first_step
from ..lsq import thread_map
from ..metrics import rms
from ..record import Record, travel_steps

__all__ = [
    "PER_RECORD",
    "CrossValidation",
    "Folds",
    "Leaveout",
    "excitation",
    "held_out",
    "informed",
    "less_record_part",
    "on_common_folds",
]

#: Tries of the screen's step (each a quarter of the one before), as the solver's first
#: trust regions.
_SCREEN_TRIES = 4


#: What each held-out span re-estimates as its own before its error is counted (module
#: docs, "What belongs to the record"): the unknown and its reason.
PER_RECORD: dict[str, str] = {
    "offset": "a sensor's zero and the mounting differ from one record to the next",
    "trend": "the day's temperature and a sensor's settling: a straight line in time, not driven by the input",
    "initial state": "what the voltage did before the record began, which no record of the device holds",
    "the record's own effects": "a drift or a mains pickup belongs to the record (Effect.of_record)",
}

#: The trend is re-estimated from this many samples on (with fewer, the offset alone: a
#: line through two samples would leave no error to count).
_TREND_FROM = 3


def less_record_part(residual: FloatArray, t: FloatArray) -> tuple[FloatArray, float, float]:
    """``residual`` [µm] at times ``t`` [s] less the record's own part (module docs): one
    offset and one straight-line trend in time, by least squares over its finite samples
    (a nan stays nan: a sample no model predicted); the trend left out where fewer than
    three samples would leave no error to count. Returns the residual left, the offset
    [µm] at the first finite sample and the trend [µm/s] (0 where not estimated)."""
    r = np.asarray(residual, dtype=float)
    rows = np.isfinite(r)
    left = r.copy()
    if not rows.any():
        return left, 0.0, 0.0
    tt = np.asarray(t, dtype=float)
    tt = tt - float(tt[np.flatnonzero(rows)[0]])
    cols = 2 if int(rows.sum()) >= _TREND_FROM else 1
    basis = np.column_stack([np.ones(r.size), tt])[:, :cols]
    coef = np.zeros(2)
    coef[:cols] = np.linalg.lstsq(basis[rows], r[rows], rcond=None)[0]
    left[rows] = r[rows] - basis[rows] @ coef[:cols]
    return left, float(coef[0]), float(coef[1])


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
        residual: held-out residual [µm], sample by sample, less the record's offset and
            trend re-estimated on it (:func:`less_record_part`; nan before the first
            origin: no fold predicts those samples).
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


@dataclass(frozen=True, eq=False)
class Leaveout:
    """A converged fit as its fold refits need it (module docs).

    Attributes:
        z: its unknowns.
        jacobian: ∂x̂/∂z over the record [µm per unit], one row per sample.
        lower, upper: the unknowns' bounds.
        scale: each unknown's typical size (the metric of the screen's step).
        simulate: (z, stop) → x̂ [µm] over the first ``stop`` samples, or None.
        refit: train → (x̂ [µm] over the record of the model refitted on the samples
            ``train`` (a slice of the record's past), whether that refit converged), x̂
            None where it failed.
        margin: the refits' statistical stop (the screen stops where they would).
    """

    z: FloatArray
    jacobian: FloatArray
    lower: FloatArray
    upper: FloatArray
    scale: FloatArray
    simulate: Callable[[FloatArray, int], FloatArray | None]
    refit: Callable[[slice], tuple[FloatArray | None, bool]]
    margin: float = STATISTICAL_MARGIN


def _screen(lo: Leaveout, x_hat: FloatArray, r: FloatArray, train: slice, stop: int) -> FloatArray | None:
    """The screen's prediction over the first ``stop`` samples for the fold refitted on
    ``train``: the refit's first step from z* (module docs) as the solver takes it — the
    bounded Gauss–Newton step on those rows (:func:`boucwen.levenberg.first_step`; none
    where the remaining step is within the statistical margin, as the refit stops there),
    within the solver's first trust region, kept where it lowers the cost of those rows,
    else shortened to a quarter and tried again (four tries; then z* itself, where the
    refit ends when no step lowers the cost)."""
    rows = -r[train]
    cost = float(rows @ rows)
    radius = float(np.linalg.norm(lo.z / lo.scale)) or 1.0
    for _ in range(_SCREEN_TRIES):
        z1 = first_step(
            rows, lo.jacobian[train], lo.z, lo.lower, lo.upper, x_scale=lo.scale, margin=lo.margin, radius=radius
        )
        step = float(np.linalg.norm((z1 - lo.z) / lo.scale))
        if step == 0.0:
            break
        x1 = lo.simulate(z1, max(stop, train.stop))
        if x1 is not None:
            left = x1[train] - (x_hat[train] + r[train])
            if float(left @ left) < cost:
                return x1
        radius = 0.25 * step
    return x_hat[: max(stop, train.stop)]


def held_out(
    record: Record, lo: Leaveout, x_hat: FloatArray, folds: Folds, exact: bool, workers: int | None = 1
) -> CrossValidation:
    """The held-out residual [µm] of the fit ``lo`` (simulated ``x_hat`` [µm] over the
    record) on ``folds``: each fold's from the model refitted on its training samples
    (``exact``) or from the screen's step (module docs), less the record's offset and
    trend re-estimated on the held-out samples together (:func:`less_record_part`)."""
    r = record.x - x_hat
    held = np.full(r.size, np.nan)

    def one(k: int) -> tuple[FloatArray | None, bool]:
        train, stop = folds.train(k), folds.test(k).stop
        if exact:
            return lo.refit(train)
        return _screen(lo, x_hat, r, train, stop), True

    out = thread_map(one, list(range(folds.count)), workers if exact else 1)
    converged = []
    for k, (x_k, ok) in enumerate(out):
        sl = folds.test(k)
        if x_k is None:
            converged.append(False)
            continue
        held[sl] = record.x[sl] - x_k[sl]
        converged.append(ok)
    held = less_record_part(held, record.t)[0]
    return CrossValidation.of(held, r, folds, tuple(converged), exact)


def on_common_folds(a: CrossValidation, b: CrossValidation) -> tuple[float, float]:
    """The held-out RMS errors [µm] of ``a`` and ``b`` over the folds whose refits
    converged for both (nan where none did): two models' unseen errors on the same
    samples."""
    mask = a.folds.mask(tuple(x and y for x, y in zip(a.converged, b.converged)))
    if not mask.any():
        return math.nan, math.nan
    return rms(a.residual[mask]), rms(b.residual[mask])
