"""``creep``: slow relaxation of the stack after a change of the voltage."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from .base import Context, Effect, Start

__all__ = ["Creep", "creep_time_constants"]


#: Creep elements per decade of time constant. A stack's creep follows a continuous
#: spectrum of relaxation times (its step response grows about linearly in log t); a
#: sum of first-order elements follows such a spectrum where their time constants lie
#: closer than a decade apart. At one per decade a creep whose times fall between the
#: elements leaves a slow ripple that a drift or a gain drift takes up on held-out data
#: (a generated creep at 0.003 … 3 s, fitted with elements at 0.001, 0.0077, 0.06,
#: 0.46, 3.6 s: a drift beside it gained 6.1 standard errors); at two per decade it
#: gains nothing (−2.1).
CREEP_ELEMENTS_PER_DECADE = 2


def creep_time_constants(dt: float, duration_s: float, max_count: int = 10) -> list[float]:
    """Log-spaced creep time constants τ_i [s] for a record of ``duration_s`` [s].

    From 10·dt (faster elements look like part of kv) to the record's length,
    :data:`CREEP_ELEMENTS_PER_DECADE` per decade, between 2 and ``max_count``.

    No element is slower than the span its fit sees: over a span T an element of
    τ ≫ T answers a step by g·t/τ, a straight line in time that the record's own trend
    (:data:`boucwen.diagnosis.heldout.PER_RECORD`: a day's temperature, a sensor's
    settling) makes as well; the record cannot tell the device's creep there from the
    day's drift, and a fit that holds such an element carries the day's trend to the
    next record. The creep still running at the end of a record is that trend's to take.
    """
    lo = 10.0 * dt
    hi = max(duration_s, 2.0 * lo)
    count = int(min(max_count, max(2, round(CREEP_ELEMENTS_PER_DECADE * math.log10(hi / lo)) + 1)))
    return [float(v) for v in np.geomspace(lo, hi, count)]


@dataclass(frozen=True)
class Creep(Effect):
    """Creep as a sum of first-order elements with fixed time constants:

        τ_i·ċ_i = g_i·u_a − c_i,     x += Σ_i c_i

    u_a: voltage on the stack [V]; c_i [µm]. With log-spaced τ_i the step response
    grows roughly linearly in log(t). Each element starts in equilibrium with the
    first voltage.

    A fit holds the τ_i fixed (see :func:`creep_time_constants`) and fits the gains,
    on which the output depends linearly; they share the sign of the static gain
    kv + Σ g_i (creep continues the motion a voltage step started; kv alone may take
    either sign when a fast element carries much of the gain).

    Attributes:
        tau_s: time constants τ_i [s] (finite, > 0; 1 to 16 of them).
        gain_um_per_v: static gains g_i [µm/V] (finite; one per time constant).
    """

    name: ClassVar[str] = "creep"
    signature: ClassVar[str | None] = "lowpass_u"
    tau_s: tuple[float, ...]
    gain_um_per_v: tuple[float, ...]

    def unknowns(self) -> tuple[str, ...]:
        return tuple(f"gain[{i}]" for i in range(len(self.tau_s)))

    def pack(self) -> tuple[float, ...]:
        return self.gain_um_per_v

    def unpack(self, values: Sequence[float]) -> Creep:
        return replace(self, gain_um_per_v=tuple(float(g) for g in values))

    def sign_bounds(self, static_gain: float) -> tuple[tuple[float, float], ...]:
        same_sign = (0.0, math.inf) if static_gain >= 0 else (-math.inf, 0.0)
        return tuple(same_sign for _ in self.tau_s)

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        return tuple(0.01 * span_x / span_u for _ in self.tau_s)

    @classmethod
    def starts(cls, at: Start) -> list[Creep]:
        record = at.record
        taus = at.creep_tau_s if at.creep_tau_s is not None else creep_time_constants(record.dt, record.duration_s)
        return [cls(tau_s=tuple(taus), gain_um_per_v=(0.0,) * len(taus))]
