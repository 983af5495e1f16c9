"""Diagnosis: what is left after the base model, and which effect explains it.

:func:`diagnose` takes a record (voltage u [V], displacement x [µm], interval dt [s]),
not told what it contains, and:

1. fits the base asymmetric Bouc–Wen model on the whole record (:func:`boucwen.fit`);
2. analyses the residual and records evidence a person can check
   (:func:`residual_evidence`): how the residual moves during holds of the voltage
   (creep), its size relative to the signal per frequency band and its regression on
   the model's rate ẋ (input lag), the peak of its spectrum (resonance), its trend
   in time (drift), the whole-sample lag that best aligns model and data (delay);
3. tries each effect of the vocabulary (:data:`boucwen.effects.VOCABULARY`, read from
   the registry at run time) not yet in the model: adds it and refits everything on
   the whole record with a small iteration budget (a *trial*), from the start of the
   effect's that fits best once the current model's unknowns are refitted to first
   order (the current fit has bent itself to follow what the effect describes: a
   delay starts from the model refitted to the record shifted by whole samples, a
   drift from it refitted to the record less a trend, an input lag whose best start
   is almost none, on a record not screened, from it refitted to u lagged at each
   corner of its grid; a resonance also starts at the peak of the residual's spectrum
   over the record and over the 20 ms stretch where its energy is largest, where a
   mode rings after a step or a sharp start); a trial no better than the null trial
   (step 5) after a third of its budget stops there, unless that first-order refit
   promised a cut of at least 3 %, and one whose second stage left less than half the
   error of its first, without converging, gets a third (it is judged where it
   converges, not where its budget happened to end); a second resonance mode is
   tried beside a first, and while the model has none its
   trial adds both at once (two peaks close together, or one double peak, which a
   lone mode cannot fit), kept over the lone mode only when it beats it by
   ``min_gain``;
4. scores every model by **blocked cross-validation** over the whole record
   (:mod:`~boucwen.diagnosis.validation`): the record is cut into ``folds`` contiguous
   blocks (4 by default), each held out in turn from a refit on the others, so that
   evidence anywhere in the record — a step and its hold, a burst, the end of a
   drift — is scored where it is; the refit without a block is one Gauss–Newton step
   from the whole-record fit, *simulated* (line-searched on the other blocks), not
   extrapolated along the Jacobian: a mode's frequency or a lag's corner is too
   nonlinear for the straight line;
5. compares each trial with the *null trial*, the current model refitted with the same
   effort and nothing added: an effect is credited only with the cut of the
   cross-validated RMS error beyond the better of the two, capped by the cut of the
   in-sample error (``gain_over_null``), so that the extra iterations of a trial are
   not taken for the effect, nor are block refits that extrapolate better with one
   more unknown beside them. It earns its
   parameters when that cut is at least ``min_gain`` (10 %), or — for evidence that is
   local — when it cuts the cross-validated error by at least 30 % on the 10 % of
   samples it changes most and by at least 3 % overall, or — near the noise, where the
   RMS error cannot fall by 10 % — when it removes 9/10 of the in-sample mean-square
   error beyond the record's noise, cuts the error by at least 3 % and gains in every
   fold;
6. of the effects that earn their parameters the one of largest credit is
   kept; when the first two belong to one group of look-alikes (creep / drift / gain
   drift; delay / input lag / resonance) and their credits differ by less than
   1 point, the group's test decides (:mod:`~boucwen.diagnosis.lookalike`: creep
   follows u, a drift follows time; a delay has a flat group delay, a lag does not —
   told apart only where one fits the phase 10 % better: below its corner a lag turns
   the phase as a delay does).
   Once creep, drift or gain drift is in the model, another of the three is kept only
   when that test on the current residual names it. Then it repeats from 3 until
   nothing earns its parameters, or what the effects kept leave is consistent with
   noise (step 8's test). When nothing more earns its parameters but the effects kept
   would not be named (step 8: too little of the error explained), they are refitted
   once from a base model fitted afresh to the record less what they add (the base
   model, fitted without them, may sit in a basin where its hysteresis imitates them;
   ``evidence["rebased"]``); if that fits better, the search goes on from there.
   Last, a backward step: each effect kept is taken out and the others refitted with
   the null trial's effort; one that the model with it does not earn against that
   refit (same rule) was a passenger — a look-alike kept first whose work a later
   effect does, or an effect credited with what those kept before it had not yet
   converged to — and is dropped (``evidence["pruned"]``); a kept creep, drift or gain
   drift (or delay or input lag) whose residual without it the group's test attributes
   to another member is swapped for that one where it earns as much, within 1 point
   (on a record short enough not to be screened every other member is tried, and one
   the test does not name is swapped in where it earns more);
7. refits the base model and the kept effects on the whole record and reports the
   errors, before (base model) and after (with the effects);
8. tests what the final model leaves against the noise estimated from the record and
   against what could explain it (:func:`~boucwen.diagnosis.unexplained.unexplained`):
   ``Diagnosis.unexplained`` says whether the residual is consistent with noise and,
   if not, which signals, spectral lines and time spans it follows — also when no
   effect of the vocabulary accounts for it. The returned model holds every effect
   that earned its parameters on unseen data, whatever stays unexplained: the residual
   is reported beside the names, never instead of them;
9. reports how sure it is and what the model predicts of data it did not see: each
   named effect is ``confident`` or ``tentative`` with the reason and the competing
   explanation (:mod:`~boucwen.diagnosis.confidence`; tentative, among other reasons,
   where the effects leave a residual not consistent with noise and remove less than
   9/10 of the base model's mean-square error beyond it: they may stand in for
   something the vocabulary does not hold, ``evidence["partial"]``); the blocked
   cross-validated error of the base model and of the returned one, and, given a
   second record of the same device (``validate``), both models' errors on it, where
   each effect must also earn its place (:mod:`~boucwen.diagnosis.unseen`); the
   parameters that ended on a bound of the fit (``at_bounds``).

Every comparison behind a decision is made with a margin
(:mod:`~boucwen.diagnosis.margins`): where two choices are closer than the arithmetic
can tell (a credit within 1e-4 of its threshold or of another credit, two errors
within 1e-4 of each other), the simpler side is taken by a stated rule, and the report
lists the call (``close_calls``), so that the answer does not depend on the machine's
BLAS kernel, its number of threads or the last bits of the record.

Long records (more than 50 000 samples) sampled faster than 5 kHz are *screened* (for
speed): the trials of step 3 run on a copy holding every q-th sample (about 2.5 kHz),
and the best screened effect
— with the second when its cross-validated error is within 25 % of the best's —
is tried again, with its own null trial, on the full record, where the decision is
taken; so are ``delay`` (whole samples of the full rate; the refits that compare its
shifts run on the shifted record's screened copy) and, when the residual's spectrum
peaks above what the copy can hold, ``resonance``. Once the model holds what the copy
cannot (a resonance above its Nyquist frequency, or a delay, whose whole samples are the
full rate's), the rounds and the backward step run on the full record.

The null trial and the trials of a round are independent: they run side by side on
``workers`` threads (the simulations release the GIL), each printing its progress line
when it ends; the result does not depend on the order they end in.

Each round of the report (``evidence["rounds"]``) lists the competing explanations with
their scores (overall, per fold, where they act), the null trial, the look-alike
tests' outcomes and, when screened, the screening round.

With no effect in the data, every trial fails step 5 and the result says so
(``effects == []``).

Every threshold of the procedure is a field of a
:class:`~boucwen.diagnosis.policy.DiagnosisPolicy` (``diagnose(..., policy=...)``), and
what is particular to one effect (its starts, its partner, what makes it no candidate,
its look-alikes) is declared on its class (:class:`boucwen.effects.Effect`): the search
names no effect.

Modules: :mod:`~boucwen.diagnosis.policy` (the thresholds),
:mod:`~boucwen.diagnosis.search` (the procedure above, its loop of rounds),
:mod:`~boucwen.diagnosis.rounds` (one round: its trials, the one kept),
:mod:`~boucwen.diagnosis.trial` (a trial's stages), :mod:`~boucwen.diagnosis.starts`
(where a trial starts), :mod:`~boucwen.diagnosis.credit` (what a trial is credited with,
and when that earns its parameters), :mod:`~boucwen.diagnosis.pairs` (effects that
explain only together), :mod:`~boucwen.diagnosis.backward` (the backward step),
:mod:`~boucwen.diagnosis.screening` (long records), :mod:`~boucwen.diagnosis.scoring`
(a fit scored), :mod:`~boucwen.diagnosis.outcome` (the end: final refit, unseen data,
confidence), :mod:`~boucwen.diagnosis.evidence` (the residual statistics),
:mod:`~boucwen.diagnosis.validation` (blocked cross-validation),
:mod:`~boucwen.diagnosis.lookalike` (the tests that tell look-alikes apart),
:mod:`~boucwen.diagnosis.unexplained` (what the final model leaves, step 8, with
:mod:`~boucwen.diagnosis.noise`, :mod:`~boucwen.diagnosis.lines` and
:mod:`~boucwen.diagnosis.spans`), :mod:`~boucwen.diagnosis.margins` (decisions with
margins), :mod:`~boucwen.diagnosis.confidence` (how sure each name is),
:mod:`~boucwen.diagnosis.unseen` (errors on unseen data),
:mod:`~boucwen.diagnosis.report` (:class:`Diagnosis`, its JSON and CSV files); the
figure is :func:`boucwen.plots.plot_diagnosis`.
"""

from .evidence import residual_evidence, residual_evidence_record
from .lookalike import lookalike_tests
from .margins import CloseCall
from .policy import DiagnosisPolicy
from .report import Diagnosis, ModelFit, NamedEffect, write_predictions, write_report
from .scoring import AtBound
from .search import FOLDS, MAX_DELAY_SAMPLES, MIN_GAIN, TRIAL_NFEV, diagnose, diagnose_record
from .unexplained import Unexplained, noise_level, unexplained
from .unseen import OnValidation, Unseen

__all__ = [
    "FOLDS",
    "MAX_DELAY_SAMPLES",
    "MIN_GAIN",
    "TRIAL_NFEV",
    "AtBound",
    "CloseCall",
    "Diagnosis",
    "DiagnosisPolicy",
    "ModelFit",
    "NamedEffect",
    "OnValidation",
    "Unexplained",
    "Unseen",
    "diagnose",
    "diagnose_record",
    "lookalike_tests",
    "noise_level",
    "residual_evidence",
    "residual_evidence_record",
    "unexplained",
    "write_predictions",
    "write_report",
]
