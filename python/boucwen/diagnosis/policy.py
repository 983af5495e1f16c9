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
        folds: contiguous blocks of the blocked cross-validation [-] (2 … 10). Each
            block is held out in turn from a refit on the others, so every sample is
            scored out of sample once; four leave three quarters of the record to refit
            on (the refit must still see the input's range and its slow effects), and
            contiguous blocks keep the serial dependence of a record inside a block
            (Bergmeir & Benítez 2012: shuffled folds of a time series leak).
        batches_per_fold: contiguous batches each block is cut into for the sampling
            error of a gain [-] (1 … 64). The held-out squared errors are serially
            dependent (a misfit lasts a cycle of the input); means over batches much
            longer than that dependence are nearly independent, and their spread gives
            the standard error of the mean gain (the batch-means estimator). 4 per
            block: 16 batches, a t statistic with 15 degrees of freedom, batches still a
            sixteenth of the record.
        alpha: chance [-] (1e-6 … 0.5) that a round accepts a move which does not
            improve the held-out error: the threshold of one move's t statistic is
            t₁₋α/m with m the moves of the round (Bonferroni), so the round as a whole
            keeps that rate however many moves it tries (conservatively: the moves of a
            round are correlated). 0.05, the conventional level: a round on a record
            the current model already explains accepts nothing in 19 cases of 20.
        min_share: least share [-] (0 … 1) of the current model's held-out mean-square
            error beyond the noise that a move must remove. The base model's form is
            never exact: on a long record a change of shape reshapes that misfit by a
            significant but small amount, which would not carry to another record. A
            tenth of what is left beyond the noise is an effect's worth.
        max_effects: most effects in a model [-] (0 … 8): each adds unknowns and a round
            of fits; no record of a piezo stack has needed more than four.
        max_delay_samples: largest whole-sample delay tried [samples] (1 … 1000). 8: a
            sensor or A/D latency of a few samples; longer delays are a lag.
        bound_tolerance: a fitted unknown within this share [-] of its bound's size (at
            least 1) is reported on the bound (``Diagnosis.at_bounds``): the record asks
            for more than the model allows there.
        confident_share: least share [-] (0 … 1) of the base model's mean-square error
            beyond the noise that the returned model must explain for its names to be
            ``confident`` where its residual is not consistent with noise: effects
            leaving more of it may be standing in for something outside the
            vocabulary (a backlash fitted in part by a creep), so their names are
            tentative. 0.9: what is left is then a small part of what was there.
        noise_alpha: significance level [-] of the tests of the residual against the
            noise (1e-12 … 0.5; :func:`boucwen.residual.unexplained`): the loop stops
            when the residual is consistent with noise at this level.
        noise_tolerance: structure beyond the noise that still counts as noise, as a
            multiple of its RMS [-] (0 … 1; 0.3 adds 4.4 % to the RMS of the noise
            alone): a model never fits a long record to the last nanometre.
    """

    folds: int = 4
    batches_per_fold: int = 4
    alpha: float = 0.05
    min_share: float = 0.1
    max_effects: int = 4
    max_delay_samples: int = 8
    bound_tolerance: float = 1e-6
    confident_share: float = 0.9
    noise_alpha: float = ALPHA
    noise_tolerance: float = TOLERANCE

    def __post_init__(self) -> None:
        check_int("folds", self.folds, 2, 10)
        check_int("batches_per_fold", self.batches_per_fold, 1, 64)
        check_number("alpha", self.alpha, 1e-6, 0.5)
        check_number("min_share", self.min_share, 0.0, 1.0)
        check_int("max_effects", self.max_effects, 0, 8)
        check_int("max_delay_samples", self.max_delay_samples, 1, 1000)
        check_number("bound_tolerance", self.bound_tolerance, 0.0, 0.5)
        check_number("confident_share", self.confident_share, 0.0, 1.0)
        # The ranges :func:`~boucwen.residual.unexplained` accepts.
        check_number("noise_alpha", self.noise_alpha, 1e-12, 0.5)
        check_number("noise_tolerance", self.noise_tolerance, 0.0, 1.0)
        if self.folds * self.batches_per_fold < 3:
            raise ValueError(
                f"folds × batches_per_fold must be at least 3 (a standard error needs two degrees "
                f"of freedom), got {self.folds} × {self.batches_per_fold}"
            )

    @property
    def batches(self) -> int:
        """Batches of the sampling error over the whole record."""
        return self.folds * self.batches_per_fold

    def replace(self, **changes: Any) -> DiagnosisPolicy:
        """A copy with ``changes`` (checked as the defaults are); ValueError or TypeError
        naming the field at fault, TypeError for an unknown field."""
        return DiagnosisPolicy(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, Any]:
        """``{field: value}`` (JSON-ready)."""
        return asdict(self)
