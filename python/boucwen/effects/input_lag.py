"""``input_lag``: the voltage on the stack lags the command (amplifier bandwidth)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from .base import Context, Effect, Start

__all__ = ["InputLag"]


@dataclass(frozen=True)
class InputLag(Effect):
    """A first-order low-pass between the command u [V] and the stack's voltage u_a [V]:

        τ·u̇_a = u − u_a,     τ = 1/(2π·fc)

    A fit varies ln fc (which keeps fc positive), from one cycle per record length to
    ten times the sampling rate.

    Attributes:
        fc_hz: corner frequency fc [Hz] (finite, > 0).
    """

    name: ClassVar[str] = "input_lag"
    signature: ClassVar[str | None] = "lag"
    full_rate_only: ClassVar[bool] = True
    fc_hz: float

    def unknowns(self) -> tuple[str, ...]:
        return ("ln_fc",)

    def pack(self) -> tuple[float, ...]:
        return (math.log(self.fc_hz),)

    def unpack(self, values: Sequence[float]) -> InputLag:
        return replace(self, fc_hz=math.exp(values[0]))

    def bounds(self, context: Context) -> tuple[tuple[float, float], ...]:
        return ((math.log(1.0 / context.duration_s), math.log(10.0 / context.dt)),)

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        return (1.0,)

    @classmethod
    def starts(cls, at: Start) -> list[InputLag]:
        dt, duration = at.record.dt, at.record.duration_s
        # The last start is nearly no lag at all (fc = 5/dt).
        fcs = np.append(np.geomspace(max(2.0 / duration, 0.5), 2.0 / dt, 10), 5.0 / dt)
        return [cls(fc_hz=float(f)) for f in fcs]
