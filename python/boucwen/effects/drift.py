"""``drift``: a slow sensor or thermal trend in time, independent of the input."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from ..checks import FloatArray
from ..record import Record, validate_record
from .base import Context, Effect, RefitStarts, Start, TrialStart, with_effect

__all__ = ["Drift"]


@dataclass(frozen=True)
class Drift(Effect):
    """A linear trend added to the displacement: x += rate·t, t [s] from the first
    sample (the offset at t = 0 is the base model's x0).

    Attributes:
        rate_um_per_s: trend rate [µm/s] (finite).
    """

    name: ClassVar[str] = "drift"
    signature: ClassVar[str | None] = "t"
    of_record: ClassVar[bool] = True
    #: Multiples of the least-squares trend of x on (1, u, t) from which a trial's refit
    #: starts (:meth:`refit_starts`): around the trend, since the base model has taken
    #: up part of it, and beyond, since its hysteresis may lean against it.
    TREND_PROFILE: ClassVar[tuple[float, ...]] = (0.5, 0.8, 1.0, 1.25)
    rate_um_per_s: float

    def unknowns(self) -> tuple[str, ...]:
        return ("rate",)

    def pack(self) -> tuple[float, ...]:
        return (self.rate_um_per_s,)

    def unpack(self, values: Sequence[float]) -> Drift:
        return replace(self, rate_um_per_s=float(values[0]))

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        return (span_x / max(context.duration_s, context.dt) * 1e-2,)

    @classmethod
    def starts(cls, at: Start) -> list[Drift]:
        return [cls(rate_um_per_s=0.0)]

    @classmethod
    def refit_starts(cls, at: TrialStart) -> RefitStarts | None:
        """The current model refitted to the record less a trend r·t for each rate r of
        :data:`TREND_PROFILE` × the least-squares trend of x on (1, u, t), the drift
        started at that rate; None where x has no trend.

        The current fit has bent its hysteresis (kv, x0, h0) to follow a trend in time,
        and a drift started at rate 0 from there stays in that bend."""
        record = at.record
        t = np.arange(record.u.size, dtype=np.float64) * record.dt
        design = np.column_stack([np.ones_like(t), record.u, t])
        trend = float(np.linalg.lstsq(design, record.x, rcond=None)[0][2])
        if trend == 0.0 or not math.isfinite(trend):
            return None
        rates = [f * trend for f in cls.TREND_PROFILE]
        return RefitStarts(
            variants=tuple(_less_trend(rate, t) for rate in rates),
            starts=tuple(with_effect(at.effects, cls(rate_um_per_s=rate)) for rate in rates),
        )


def _less_trend(rate: float, t: FloatArray) -> Callable[[Record], Record]:
    """The record less the trend ``rate`` [µm/s] × ``t`` [s]."""
    return lambda record: validate_record(record.u, record.x - rate * t, record.dt)
