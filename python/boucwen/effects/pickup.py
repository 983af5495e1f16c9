"""``pickup``: the sensor's signal picks up the power line and its harmonics."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from ..checks import FloatArray
from .base import Context, Effect, Start, simulate_chain

__all__ = ["LINE_FREQUENCIES_HZ", "MAX_START_HARMONICS", "Pickup"]

#: The line frequencies a fit tries [Hz].
LINE_FREQUENCIES_HZ = (50.0, 60.0)
#: Harmonics K of a start (fewer where k·f_line reaches the Nyquist frequency).
MAX_START_HARMONICS = 3


@dataclass(frozen=True)
class Pickup(Effect):
    """Line-frequency pickup added to the reading, harmonics k = 1 … K:

        x += Σ_k a_k·sin(2π·k·f_line·t) + b_k·cos(2π·k·f_line·t)

    t [s] from the first sample. Electrical interference on the sensor's cable or
    electronics: in the reading only, not in the stack's motion (the inverse ignores
    it). f_line and K are fixed; the amplitudes, on which x depends linearly, are the
    unknowns. The starts try 50 and 60 Hz, with up to :data:`MAX_START_HARMONICS`
    harmonics below the Nyquist frequency, their amplitudes the least-squares fit of
    the current model's residual (so that the start of the right line frequency is
    the one of least error).

    Attributes:
        line_hz: line frequency f_line [Hz] (finite, > 0; K·f_line below the Nyquist
            frequency 1/(2·dt) of the record it is simulated on).
        sin_um: a_k [µm], k = 1 … K (finite; 1 to 8 of them).
        cos_um: b_k [µm] (finite; one per a_k).
    """

    name: ClassVar[str] = "pickup"
    of_record: ClassVar[bool] = True
    line_hz: float
    sin_um: tuple[float, ...]
    cos_um: tuple[float, ...]

    def unknowns(self) -> tuple[str, ...]:
        k = range(1, len(self.sin_um) + 1)
        return (*(f"sin[{i}]" for i in k), *(f"cos[{i}]" for i in k))

    def pack(self) -> tuple[float, ...]:
        return (*self.sin_um, *self.cos_um)

    def unpack(self, values: Sequence[float]) -> Pickup:
        k = len(self.sin_um)
        return replace(self, sin_um=tuple(float(v) for v in values[:k]), cos_um=tuple(float(v) for v in values[k:]))

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        return tuple(1e-2 * span_x for _ in range(2 * len(self.sin_um)))

    @classmethod
    def starts(cls, at: Start) -> list[Pickup]:
        record = at.record
        nyquist = 0.5 / record.dt
        xs = simulate_chain(at.params, at.effects, record.u, record.dt, at.h0)
        residual = None if xs is None else record.x - xs
        out = []
        for f in LINE_FREQUENCIES_HZ:
            k = min(MAX_START_HARMONICS, math.ceil(nyquist / f) - 1)
            if k >= 1:
                out.append(cls.fitted(f, k, record.t, residual))
        if not out:
            # Both lines above the Nyquist frequency: the alias of 60 Hz (then 50 Hz).
            for f in reversed(LINE_FREQUENCIES_HZ):
                alias = abs(f - round(f * record.dt) / record.dt)
                if 0.0 < alias < nyquist:
                    out.append(cls.fitted(alias, 1, record.t, residual))
                    break
        if not out:
            # Every line aliases to 0 or to the Nyquist frequency (a constant, or a sign
            # alternating at the Nyquist frequency): one line at a quarter of the rate.
            out.append(cls.fitted(0.5 * nyquist, 1, record.t, residual))
        return out

    @classmethod
    def fitted(cls, line_hz: float, harmonics: int, t: FloatArray, residual: FloatArray | None) -> Pickup:
        """The pickup at ``line_hz`` [Hz] with ``harmonics`` harmonics whose amplitudes
        [µm] fit ``residual`` [µm] at times ``t`` [s] best (zeros without one)."""
        if residual is None:
            return cls(line_hz=line_hz, sin_um=(0.0,) * harmonics, cos_um=(0.0,) * harmonics)
        phase = 2.0 * math.pi * line_hz * np.outer(t, np.arange(1, harmonics + 1))
        basis = np.column_stack([np.sin(phase), np.cos(phase)])
        coef, *_ = np.linalg.lstsq(basis, residual - residual.mean(), rcond=None)
        return cls(line_hz=line_hz, sin_um=tuple(coef[:harmonics].tolist()), cos_um=tuple(coef[harmonics:].tolist()))
