"""Every number the diagnosis decides with, in one place: :class:`DiagnosisPolicy`.

The judge (:mod:`~boucwen.diagnosis.judge`) and the loop of moves
(:mod:`~boucwen.diagnosis.search`) read each number from it; :func:`boucwen.diagnose`
takes one (``policy=DiagnosisPolicy()`` by default). Each field says its unit and the
statistical or physical reason for its value. What describes one effect (its starts, its
bounds, a resonance's peak) is on the effect's class (:mod:`boucwen.effects`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from ..checks import check_int, check_number
from ..residual.unexplained import ALPHA, TOLERANCE

__all__ = ["DiagnosisPolicy"]


@dataclass(frozen=True)
class DiagnosisPolicy:
    """The numbers of the diagnosis (frozen; :meth:`replace` gives a changed copy).

    Attributes:
        folds: forward-validation folds [-] (2 … 10): the record is cut at this many
            origins and each fold, refitted on the samples before its origin, predicts
            the samples up to the next (:mod:`~boucwen.diagnosis.judge`). Four give a
            gain per quarter of what is predicted (a step, a burst, a hold each land
            in one) while the last refit still sees most of the record.
        first_origin: share [-] (0.2 … 0.8) of the record's excitation (half its
            voltage travel, half its elapsed time) before the first origin: the first
            refit must see the input's range and a step's response, and the predicted
            part must still hold a share of both. A half.
        alpha: chance [-] (1e-6 … 0.5) that the whole search accepts a move which does
            not improve the prediction of unseen samples: one move's test in round r runs
            at level α·2⁻ʳ/m, m the moves of its round (the rounds spend α/2, α/4, …;
            Bonferroni with weights, conservative: the moves of a round are correlated).
            0.05, the conventional level: a record the base model already explains gets
            no name in 19 cases of 20.
        min_share: least share [-] (0 … 1) of the current model's held-out mean-square
            error beyond the noise that a move must remove. The base model's form is
            never exact: on a long record a change of shape reshapes that misfit by a
            significant but small amount, which would not carry to another record. A
            tenth of what is left beyond the noise is an effect's worth.
        screen_band: half-width [-] (0 … 100) of the band around the threshold in which
            a decision read from the screen's held-out errors (the first Gauss–Newton
            step of each fold's refit) is confirmed by converged refits; every accepted
            move and every member of an ambiguity set are confirmed as well. Its value is
            the largest |screen − refits| of the statistic measured on the suite's
            development half (``python -m boucwen.experiments.judge_calibration``), with
            a margin.
        max_effects: most effects in a model [-] (0 … 8): each adds unknowns and a round
            of fits; no record of a piezo stack has needed more than four.
        max_delay_samples: largest whole-sample delay tried [samples] (1 … 1000). 8: a
            sensor or A/D latency of a few samples; longer delays are a lag.
        confident_share: least share [-] (0 … 1) of the base model's held-out
            mean-square error beyond the noise that the returned model must remove for
            its names to be ``confident`` where its residual is not consistent with
            noise: effects leaving more of it may be standing in for something outside
            the vocabulary (a backlash fitted in part by a creep), so their names are
            tentative. 0.9: what is left is then a small part of what was there.
        noise_alpha: significance level [-] of the tests of the residual against the
            noise (1e-12 … 0.5; :func:`boucwen.residual.unexplained`): the loop stops
            when the residual is consistent with noise at this level.
        noise_tolerance: structure beyond the noise that still counts as noise, as a
            multiple of its RMS [-] (0 … 1; 0.3 adds 4.4 % to the RMS of the noise
            alone): a model never fits a long record to the last nanometre.
    """

    folds: int = 4
    first_origin: float = 0.5
    alpha: float = 0.05
    min_share: float = 0.1
    screen_band: float = 3.0
    max_effects: int = 4
    max_delay_samples: int = 8
    confident_share: float = 0.9
    noise_alpha: float = ALPHA
    noise_tolerance: float = TOLERANCE

    def __post_init__(self) -> None:
        check_int("folds", self.folds, 2, 10)
        check_number("first_origin", self.first_origin, 0.2, 0.8)
        check_number("alpha", self.alpha, 1e-6, 0.5)
        check_number("min_share", self.min_share, 0.0, 1.0)
        check_number("screen_band", self.screen_band, 0.0, 100.0)
        check_int("max_effects", self.max_effects, 0, 8)
        check_int("max_delay_samples", self.max_delay_samples, 1, 1000)
        check_number("confident_share", self.confident_share, 0.0, 1.0)
        # The ranges :func:`~boucwen.residual.unexplained` accepts.
        check_number("noise_alpha", self.noise_alpha, 1e-12, 0.5)
        check_number("noise_tolerance", self.noise_tolerance, 0.0, 1.0)

    @property
    def rounds(self) -> int:
        """The most rounds of the search: each effect added, dropped or swapped once, and
        a last round that accepts nothing."""
        return 2 * self.max_effects + 2

    def replace(self, **changes: Any) -> DiagnosisPolicy:
        """A copy with ``changes`` (checked as the defaults are); ValueError or TypeError
        naming the field at fault, TypeError for an unknown field."""
        return DiagnosisPolicy(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, Any]:
        """``{field: value}`` (JSON-ready)."""
        return asdict(self)
