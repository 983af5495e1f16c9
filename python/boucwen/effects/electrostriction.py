"""``electrostriction``: the stack's stroke grows with the square of its displacement."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from .base import Context, Effect, Start

__all__ = ["STROKE_BENDS", "Electrostriction"]

#: Shares of the record's span by which the starts of a fit bend the stroke (ε·span²).
STROKE_BENDS = (0.0, -0.03, 0.03, -0.1, 0.1, -0.3, 0.3)


@dataclass(frozen=True)
class Electrostriction(Effect):
    """A quadratic stroke map of the Bouc–Wen displacement s = kv·u_a + h [µm]:

        y = x0 + s + ε·s² + c

    (c the creep). The strain of a poled ceramic is Q·P², so the stroke is linear in
    the hysteretic polarisation change plus a term in its square: the local gain
    1 + 2ε·s grows along the stroke. The same map as the simulated bench's
    (:class:`boucwen.plant.BenchSettings` ``stroke_quadratic_per_um``).

    Attributes:
        epsilon_per_um: electrostrictive coefficient ε [1/µm] (finite).
    """

    name: ClassVar[str] = "electrostriction"
    epsilon_per_um: float

    def unknowns(self) -> tuple[str, ...]:
        return ("epsilon",)

    def pack(self) -> tuple[float, ...]:
        return (self.epsilon_per_um,)

    def unpack(self, values: Sequence[float]) -> Electrostriction:
        return replace(self, epsilon_per_um=float(values[0]))

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        # ε·span² of 1 % of the span.
        return (1e-2 / span_x,)

    @classmethod
    def starts(cls, at: Start) -> list[Electrostriction]:
        # ε·span² = b·span: the square bends the stroke by a share b of the record's
        # span. A strong electrostriction is one the base model bends its hysteresis
        # to imitate, and a trial started at ε = 0 stays in that bend.
        span = float(np.ptp(at.record.x))
        if not span > 0:
            return [cls(epsilon_per_um=0.0)]
        return [cls(epsilon_per_um=b / span) for b in STROKE_BENDS]
