"""``resonance2``: a second mechanical mode, in series after ``resonance``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from .._core import EffectSet
from .base import params_of, with_effect
from .resonance import Resonance

__all__ = ["Resonance2"]


@dataclass(frozen=True)
class Resonance2(Resonance):
    """A second second-order low-pass of unit static gain, after :class:`Resonance`:

        z̈₂ + 2ζ₂ω₂·ż₂ + ω₂²·z₂ = ω₂²·z,     ω₂ = 2π·fn₂

    z: the first mode's output (the stack's displacement where there is no
    ``resonance``) [µm]; z₂: what the sensor sees [µm]. Two modes in series give two
    peaks (a stack on a flexure, a sensor target on a bracket). Unknowns, bounds and
    starts are those of :class:`Resonance`.

    Attributes:
        fn_hz: natural frequency fn₂ [Hz] (finite, > 0; below the Nyquist frequency).
        zeta: damping ratio ζ₂ [-] (finite, > 0).
    """

    name: ClassVar[str] = "resonance2"
    partner: ClassVar[str | None] = Resonance.name
    joint: ClassVar[str] = "two modes"
    #: The joint trial starts the second mode at this multiple of the first's frequency:
    #: distinct, so that the two can part (two peaks close together, or a double peak).
    SPLIT: ClassVar[float] = 1.05

    @classmethod
    def beside(cls, partner_start: EffectSet) -> EffectSet:
        """Both modes: the first at its best start, the second at :data:`SPLIT` × its
        frequency with the same damping."""
        mode = params_of(partner_start)[Resonance.name]
        return with_effect(partner_start, cls(fn_hz=cls.SPLIT * mode["fn_hz"], zeta=mode["zeta"]))
