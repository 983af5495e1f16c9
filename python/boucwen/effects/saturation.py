"""``saturation``: the sensor's reading is held within its range."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from ..checks import FloatArray
from ..record import Record, travel_steps
from .base import Context, Effect, Start

__all__ = ["Saturation"]


@dataclass(frozen=True)
class Saturation(Effect):
    """A hard clip of the reading, the last stage of the chain:

        x = min(max(x, x_min), x_max)

    The ends of the sensor's (or its A/D's) range. The output is piecewise linear in
    x_min and x_max (a sample inside the range does not depend on them; a clipped one
    has the bound's derivatives). The inverse does not undo it: it aims at the
    stack's displacement. A fit starts from the record's extremes.

    Attributes:
        min_um: lower end x_min [µm] (finite).
        max_um: upper end x_max [µm] (finite, > x_min).
    """

    name: ClassVar[str] = "saturation"
    min_um: float
    max_um: float

    def unknowns(self) -> tuple[str, ...]:
        return ("min", "max")

    def pack(self) -> tuple[float, ...]:
        return (self.min_um, self.max_um)

    def unpack(self, values: Sequence[float]) -> Saturation:
        return replace(self, min_um=float(values[0]), max_um=float(values[1]))

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        return (1e-2 * span_x, 1e-2 * span_x)

    def rejects_on(self, record: Record, before: FloatArray) -> str | None:
        """A clip is seen where the motion runs into the range's end: one that no sample
        of a moving voltage reaches (all it clips is held at rest, a level the base
        model's offset holds) is no saturation."""
        clipped = (before > self.max_um) | (before < self.min_um)
        steps = travel_steps(record)
        moving = np.concatenate([[False], steps > 0]) | np.concatenate([steps > 0, [False]])
        if not np.any(clipped & moving):
            return "the fitted clip holds no moving sample: it is no saturation the record shows"
        return None

    @classmethod
    def starts(cls, at: Start) -> list[Saturation]:
        x = at.record.x
        return [cls(min_um=float(x.min()), max_um=float(x.max()))]
