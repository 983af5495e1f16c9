"""``electrostriction``: the stack's stroke grows with the square of its displacement."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

from .base import Context, Effect, Start

__all__ = ["Electrostriction"]


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
        return [cls(epsilon_per_um=0.0)]
