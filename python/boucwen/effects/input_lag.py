"""``input_lag``: the voltage on the stack lags the command (amplifier bandwidth)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from .._core import Params, simulate_extended
from ..record import Record
from .base import Context, Effect, RefitStarts, Start, TrialStart, params_of, set_of

__all__ = ["InputLag", "lagged"]


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

    @classmethod
    def refit_starts(cls, at: TrialStart) -> RefitStarts | None:
        """Where the best-ranked start is almost no lag (a corner at the sampling rate or
        above), on a record not screened: the current model refitted to the record with
        u lagged (:func:`lagged`) at each corner of the ranked starts below the sampling
        rate; else None.

        The current fit has bent its hysteresis to follow the lag (under a triangle a
        lag is an offset on each ramp, which h takes up), and every real corner added to
        that bend misfits before the refit: the first-order ranking then puts no lag
        first."""
        if at.screened:
            return None
        corners = [params_of(s)[cls.name]["fc_hz"] for s in at.ranked]
        real = [k for k, fc in enumerate(corners) if fc < 1.0 / at.record.dt]
        if not real or real[0] == 0:
            return None
        return RefitStarts(
            variants=tuple(_lagged_at(corners[k]) for k in real),
            starts=tuple(at.ranked[k] for k in real),
        )


def _lagged_at(fc_hz: float) -> Callable[[Record], Record]:
    return lambda record: lagged(record, fc_hz)


#: Base parameters whose displacement is the stack's voltage: kv = 1 µm/V, no hysteresis.
_PASS_THROUGH = Params(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)


def lagged(record: Record, fc_hz: float) -> Record:
    """``record`` with its command u [V] replaced by the stack's voltage u_a [V] behind an
    input lag of corner ``fc_hz`` [Hz], as the Rust core computes it
    (:func:`boucwen.simulate_extended`: u a straight line between samples, u_a = u[0] at
    the first sample)."""
    lag = set_of({InputLag.name: {"fc_hz": float(fc_hz)}})
    ua = simulate_extended(_PASS_THROUGH, lag, record.u, record.dt, 0.0)
    return Record._of_checked(record.t, ua, record.x, record.dt, record.name)
