"""``drift``: a slow sensor or thermal trend in time, independent of the input."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

from .base import Context, Effect, Start

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
