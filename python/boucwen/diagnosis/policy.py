"""Every threshold of the diagnosis, in one place: :class:`DiagnosisPolicy`.

The search (:mod:`boucwen.diagnosis.search`) takes a policy and reads each number from
it; :func:`boucwen.diagnose` takes one too (``policy=DiagnosisPolicy()`` by default).
Each field says its unit and why it has its value. The margins of the decisions are
:mod:`~boucwen.diagnosis.margins`' (:data:`~boucwen.diagnosis.margins.CLOSE_GAIN`,
:data:`~boucwen.diagnosis.margins.CLOSE_REL`, the defaults of ``close_gain`` and
``close_rel`` here); the verdict on the residual is
:mod:`~boucwen.diagnosis.unexplained`'s (``alpha`` and ``tolerance`` here are its
defaults). Thresholds that describe one effect (a resonance has a peak only below
ζ = 1/√2; the rates a drift trial starts from) are on the effect classes
(:mod:`boucwen.effects`), and those of the look-alike tests in
:mod:`~boucwen.diagnosis.lookalike`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from ..checks import check_int, check_number
from .margins import CLOSE_GAIN, CLOSE_REL
from .unexplained import ALPHA, TOLERANCE
from .validation import FOLDS

__all__ = ["DiagnosisPolicy"]


@dataclass(frozen=True)
class DiagnosisPolicy:
    """The thresholds of the diagnosis (frozen; :meth:`replace` gives a changed copy).

    Acceptance (what earns an effect its parameters, :func:`~boucwen.diagnosis.credit.earns`):

    Attributes:
        folds: contiguous blocks of the blocked cross-validation [-] (2 … 10). Four
            blocks leave three quarters of the record to refit on, so a step and its
            hold, a burst or the end of a drift fall in a block scored out of sample.
        min_gain: least relative cut of the cross-validated RMS error for an effect to
            earn its parameters [-] (0 … 1). 10 %: an effect of two or three unknowns
            must cut the error on unseen data by more than refitting the same model
            with more effort or a different local optimum does (the null trial moves the
            error by a few per cent).
        local_min_gain: least cut [-] of the cross-validated error on the
            ``local_share`` of samples the effect changes most, for evidence that is
            local (a step and its hold, a burst). 30 %: three times ``min_gain``, since
            a tenth of the samples carries a tenth of the weight of a chance fit.
        local_share: share of the samples [-] where an effect acts most, on which
            ``local_min_gain`` is asked. A tenth: a hold after a step, a burst.
        local_floor: least overall cut [-] that every other route to acceptance asks
            too (local evidence, to the noise), and the least cut a trial's start must
            promise to go on after its first stage. 3 %: above the null trial's typical
            move, below ``min_gain``.
        partial_share: share [-] of the mean-square error beyond the noise an effect
            (or the effects kept) must remove to be credited to the noise (an effect
            near the noise cannot cut the RMS error by ``min_gain``: the noise stays),
            and below which what the effects leave makes them tentative. 9/10: what is
            left is then at most a tenth of the excess, 0.3× the noise's RMS for an
            excess of the noise's size, the ``tolerance`` of the verdict.

    Effort of the fits:

    Attributes:
        trial_nfev: evaluations of a trial's second stage [-] (its first stage gets a
            third, at least 3). 12: a trial only has to show what the effect explains,
            not converge; the null trial gets both stages' (16), so that the extra
            iterations of a trial are not credited to the effect.
        trial_tol: tolerance of a trial fit [-] (it stops once an iteration gains less
            than this share): 1e-5, far below any credit a decision reads.
        still_falling: a trial whose second stage left less than this share [-] of the
            RMS error its first stage left, without converging, gets a third stage. 0.5:
            an error halved in twelve evaluations is a trial still leaving a valley,
            judged where it converges, not where its budget ended.
        joint_effort: multiple [-] of ``trial_nfev`` a joint trial's second stage gets
            (an effect tried beside its partner, both added: four unknowns, the two
            modes trading places as they part). 5.
        final_nfev: evaluations of the final refit of the kept effects on the whole
            record [-]. 10: from a converged trial, a polish.
        rebase_nfev: evaluations of the refit of the kept effects from a fresh base
            model [-]. 20: from a new base fit the effects start far from their values.
        max_delay_samples: largest whole-sample delay tried [samples]. 8: a sensor
            chain's latency at the suite's rates (up to 0.4 ms at 20 kHz).

    Rounds and look-alikes:

    Attributes:
        lookalike_margin: two trials of one look-alike group whose credits differ by
            less than this [-] are told apart by the group's test, not by the scores.
            One point: two look-alikes fitting the same record differ by less than the
            refits' own scatter.
        pair_pool: where no effect earns alone, at most this many single trials [-]
            (those that cut the in-sample error most) are tried two at a time. 4: six
            pairs, the effort of a round.
        pair_ratio: ... only where the current model leaves at least this multiple [-]
            of the record's noise (RMS). 2: near the noise one of the many pairs fits
            its structure by chance.

    Screening (records too long to try every effect on in full):

    Attributes:
        screen_min_samples: records of more than this many samples [-] ...
        screen_rate_hz: ... sampled faster than this rate [Hz] are screened on a copy
            decimated to about it. 2.5 kHz over 50 000 samples keeps a round within
            the 15 s budget of a long record; the decision is taken on the full record.
        confirm: screened effects confirmed on the full record per round [-]. 2: the
            best and the runner-up, where two look-alikes may trade places.
        confirm_ratio: a screened effect other than the best is confirmed only if its
            cross-validated error is within this factor [-] of the best's. 1.25.
        confirm_nfev: evaluations of a confirmation [-] (from the screened fit). 6.
        peak_over_median: a mode is also tried on the full record when the current
            residual's spectrum peaks this many times over its median [-] above what
            the screened copy can hold. 10: a line, not a bump of the noise.
        screened_refits: variants of the record a refit start tries on a screened
            record [-] (the best-ranked; every one otherwise). 2.

    Reporting:

    Attributes:
        bound_tolerance: a fitted unknown within this share [-] of its bound's size
            (at least 1) is reported on the bound. 1e-6: far below any physical change,
            far above the optimiser's margin from the bound (1e-9).
        close_gain: margin on a credit [-]: a credit within it of its threshold or of
            another credit is a close call (:mod:`~boucwen.diagnosis.margins`).
        close_rel: relative margin on an error or a first-order cost [-].
        alpha: significance level of the tests on the final residual [-] (1e-12 … 0.5;
            :func:`~boucwen.diagnosis.unexplained.unexplained`).
        tolerance: structure beyond the noise, as a multiple of its RMS [-] (0 … 1), that
            still counts as consistent with noise (0.3 adds 4.4 % to the RMS of the noise).
    """

    folds: int = FOLDS
    min_gain: float = 0.10
    local_min_gain: float = 0.30
    local_share: float = 0.1
    local_floor: float = 0.03
    partial_share: float = 0.9
    trial_nfev: int = 12
    trial_tol: float = 1e-5
    still_falling: float = 0.5
    joint_effort: int = 5
    final_nfev: int = 10
    rebase_nfev: int = 20
    max_delay_samples: int = 8
    lookalike_margin: float = 0.01
    pair_pool: int = 4
    pair_ratio: float = 2.0
    screen_min_samples: int = 50_000
    screen_rate_hz: float = 2500.0
    confirm: int = 2
    confirm_ratio: float = 1.25
    confirm_nfev: int = 6
    peak_over_median: float = 10.0
    screened_refits: int = 2
    bound_tolerance: float = 1e-6
    close_gain: float = CLOSE_GAIN
    close_rel: float = CLOSE_REL
    alpha: float = ALPHA
    tolerance: float = TOLERANCE

    def __post_init__(self) -> None:
        check_int("folds", self.folds, 2, 10)
        for name in ("min_gain", "local_min_gain", "local_share", "local_floor", "partial_share", "still_falling"):
            check_number(name, getattr(self, name), 0.0, 1.0)
        for name in ("trial_nfev", "joint_effort", "final_nfev", "rebase_nfev", "confirm", "confirm_nfev"):
            check_int(name, getattr(self, name), 1, 10_000)
        for name in ("pair_pool", "screened_refits"):
            check_int(name, getattr(self, name), 1, 100)
        check_int("max_delay_samples", self.max_delay_samples, 1, 1000)
        check_int("screen_min_samples", self.screen_min_samples, 100, 10**9)
        check_number("screen_rate_hz", self.screen_rate_hz, 1e-6, 1e9)
        check_number("confirm_ratio", self.confirm_ratio, 1.0, 100.0)
        check_number("pair_ratio", self.pair_ratio, 0.0, 1e6)
        check_number("peak_over_median", self.peak_over_median, 1.0, 1e12)
        check_number("lookalike_margin", self.lookalike_margin, 0.0, 1.0)
        for name in ("trial_tol", "bound_tolerance", "close_gain", "close_rel"):
            check_number(name, getattr(self, name), 0.0, 0.5)
        # The ranges :func:`~boucwen.diagnosis.unexplained.unexplained` accepts.
        check_number("alpha", self.alpha, 1e-12, 0.5)
        check_number("tolerance", self.tolerance, 0.0, 1.0)

    def replace(self, **changes: Any) -> DiagnosisPolicy:
        """A copy with ``changes`` (checked as the defaults are); ValueError or TypeError
        naming the field at fault, TypeError for an unknown field."""
        return DiagnosisPolicy(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, Any]:
        """``{field: value}`` (JSON-ready)."""
        return asdict(self)
