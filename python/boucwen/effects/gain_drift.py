"""``gain_drift``: the stack's gain kv changes slowly with time."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

from .base import Context, Effect, Start

__all__ = ["GainDrift"]


@dataclass(frozen=True)
class GainDrift(Effect):
    """kv changes linearly in time: kv(t) = kv·(1 + r·t), t [s] from the first sample.

    A temperature-like slow variation of the stack's sensitivity (self-heating under
    a sustained drive, a room warming up). Unlike :class:`Drift` (an offset ∝ t,
    whatever the voltage) it scales with u_a: the loop tilts as time goes on; unlike
    :class:`Creep` (which follows changes of the voltage with fixed time constants) it
    depends on the time since the start only. The hysteresis h is not scaled.

    Attributes:
        rate_per_s: relative rate r [1/s] (finite).
    """

    name: ClassVar[str] = "gain_drift"
    signature: ClassVar[str | None] = "t_x"
    rate_per_s: float

    def unknowns(self) -> tuple[str, ...]:
        return ("rate",)

    def pack(self) -> tuple[float, ...]:
        return (self.rate_per_s,)

    def unpack(self, values: Sequence[float]) -> GainDrift:
        return replace(self, rate_per_s=float(values[0]))

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        # 1 % of kv over the record.
        return (1e-2 / max(context.duration_s, context.dt),)

    @classmethod
    def starts(cls, at: Start) -> list[GainDrift]:
        return [cls(rate_per_s=0.0)]
