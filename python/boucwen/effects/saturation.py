"""``saturation``: the sensor's reading is held within its range."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from ..checks import FloatArray
from ..record import TRAVEL_SMOOTHING_S, Record, travel_levels
from .base import Context, Effect, Start

__all__ = ["START_QUANTILE", "Saturation"]

#: Share of the samples beyond each end of the second and third starts.
START_QUANTILE = 0.01


@dataclass(frozen=True)
class Saturation(Effect):
    """A hard clip of the reading, the last stage of the chain:

        x = min(max(x, x_min), x_max)

    The ends of the sensor's (or its A/D's) range. The output is piecewise linear in
    x_min and x_max (a sample inside the range does not depend on them; a clipped one
    has the bound's derivatives). The inverse does not undo it: it aims at the
    stack's displacement. A fit starts from the record's extremes and inside them
    (:meth:`starts`).

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
        """A clip reads the range's end whatever the input: it is seen where the input
        keeps moving while the reading stays there, or where holds at different
        voltages (a staircase's upper steps) all read it. One that holds neither (all it
        clips is one level held at rest, or a rest beside a step's edge: a level the
        base model's offset and the effects' own states hold as well) is no saturation.
        The input is smoothed over :data:`~boucwen.record.TRAVEL_SMOOTHING_S`, so a
        sample counts only where the whole smoothing window about it is clipped: a
        step's edge spreads its travel onto the held samples beside it."""
        from scipy.ndimage import minimum_filter1d

        clipped = (before > self.max_um) | (before < self.min_um)
        m = max(1, round(TRAVEL_SMOOTHING_S / record.dt))
        inside = minimum_filter1d(clipped.astype(np.uint8), 2 * m + 1, mode="nearest").astype(bool)
        levels, least = travel_levels(record)
        steps = np.abs(np.diff(levels))  # travel_steps, from the levels already at hand
        moving = bool(np.any(inside[:-1] & inside[1:] & (steps > least)))
        several = bool(np.any(inside)) and float(np.ptp(levels[inside])) > least
        if not (moving or several):
            return (
                "the fitted clip holds no stretch of moving input and no two input levels: it is no saturation "
                "the record shows"
            )
        return None

    @classmethod
    def starts(cls, at: Start) -> list[Saturation]:
        """The record's extremes, and each end moved to the reading's
        :data:`START_QUANTILE` (the other at its extreme). A model fitted without the
        clip follows the clipped reading, so a clip at the reading's extremes touches
        none of its prediction and the fit cannot move it (no sample depends on it);
        a clip that held a stretch of the record (a staircase's top step) holds more
        than that share of the samples, and the quantile lies inside that stretch's
        noise about the clip."""
        x = at.record.x
        lo, hi = float(x.min()), float(x.max())
        q_lo, q_hi = (float(v) for v in np.quantile(x, [START_QUANTILE, 1.0 - START_QUANTILE]))
        out = [cls(min_um=lo, max_um=hi)]
        if q_lo < q_hi:
            out += [cls(min_um=lo, max_um=q_hi), cls(min_um=q_lo, max_um=hi)]
        return out
