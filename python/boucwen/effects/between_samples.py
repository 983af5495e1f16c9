"""``between_samples``: what the commanded voltage does between samples, the measurement
chain's input end (:mod:`boucwen.measurement`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from .base import Effect, Start

__all__ = ["BetweenSamples"]


@dataclass(frozen=True)
class BetweenSamples(Effect):
    """What the command does between its samples; without this effect, a straight line.

    * ``"hold"``: a DAC's zero-order hold: u[k−1] until the sample instant t_k, u[k]
      from then on. The input lag and creep see the held voltage over the interval; where
      the stack takes the command directly, h follows each step along the loop and the
      rate term δ·u·sgn(u̇) adds nothing over a step of no duration.
    * ``"linear"``: a straight line (the chain without the effect).
    * ``"bandlimited"``: the band-limited signal through the samples (a Kaiser-windowed
      sinc of 32 samples on either side, :func:`boucwen._core.bandlimited_error_bound`),
      the chain run on 8 sub-intervals a sample (a pass costs about 8 of one without).
      It depends on later samples: a whole record is simulated, not sample by sample.

    No fitted unknown: a fit holds the choice, and the starts try ``"hold"`` and
    ``"bandlimited"`` (the first a fit adding it tries; the caller keeps the start of
    least error). It needs the record's own samples (:attr:`Effect.full_rate_only`), and
    it is the rig's, carried to another record of the same rig. The diagnosis's search
    does not propose it (:attr:`Effect.proposed`): it is given to a fit.

    Attributes:
        input: ``"hold"``, ``"linear"`` or ``"bandlimited"``.
    """

    name: ClassVar[str] = "between_samples"
    full_rate_only: ClassVar[bool] = True
    proposed: ClassVar[bool] = False
    input: str

    @classmethod
    def starts(cls, at: Start) -> list[BetweenSamples]:
        return [cls(input="hold"), cls(input="bandlimited")]
