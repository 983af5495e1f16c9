"""``delay``: the measurement lags the command by a whole number of samples."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .._core import EffectSet, Params
from ..metrics import rms
from ..record import Record
from .base import Effect, Start, simulate_chain, without

__all__ = ["Delay", "best_delay"]


@dataclass(frozen=True)
class Delay(Effect):
    """A pure delay: the sensor reads x[k − d] (x[0] for k < d).

    A whole number of samples is not a continuous unknown: a fit holds it fixed, and
    the starts try every delay up to :attr:`Start.max_delay`, the best-aligning one
    first (:func:`best_delay`).

    Attributes:
        samples: delay d [samples] (whole, 0 … 1000000).
    """

    name: ClassVar[str] = "delay"
    signature: ClassVar[str | None] = "delay"
    full_rate_only: ClassVar[bool] = True
    samples: int

    @classmethod
    def starts(cls, at: Start) -> list[Delay]:
        # Every whole-sample delay, the best-aligning shift first (the caller keeps the
        # start of least error).
        d, _ = best_delay(at.record, at.params, at.effects, at.h0, at.max_delay)
        first = max(d, 1)
        order = [first, *(k for k in range(1, at.max_delay + 1) if k != first)]
        return [cls(samples=k) for k in order]


def best_delay(
    record: Record, params: Params, effects: EffectSet, h0: float, max_samples: int
) -> tuple[int, dict[int, float]]:
    """The whole-sample delay d (0 … ``max_samples``) that best aligns the model with x.

    For each d, the model (with ``effects``, without any delay) is shifted by d samples
    and the RMS error [µm] of the best straight-line correction ``a·x̂ + b`` is
    taken (so that a small gain or offset change does not mask the lag). Returns
    ``(d, {d: rms})``.
    """
    xs = simulate_chain(params, without(effects, Delay.name), record.u, record.dt, h0)
    if xs is None:
        return 0, {}
    x = record.x
    rms_by_shift: dict[int, float] = {}
    for d in range(max_samples + 1):
        a = xs[: xs.size - d]
        b = x[d:]
        basis = np.column_stack([a, np.ones_like(a)])
        coef, *_ = np.linalg.lstsq(basis, b, rcond=None)
        rms_by_shift[d] = rms(b - basis @ coef)
    return min(rms_by_shift, key=rms_by_shift.__getitem__), rms_by_shift
