"""Diagnosis: what is left after the base model, and which effect explains it.

:func:`diagnose` takes a record (voltage u [V], displacement x [µm], interval dt [s]),
not told what it contains, and:

1. splits it into a *fitting* part (the first ``train_fraction``, 70 % by default)
   and a *held-out* part (the rest);
2. fits the base asymmetric Bouc–Wen model on the fitting part (:func:`boucwen.fit`);
3. analyses the residual and records evidence a person can check
   (:func:`residual_evidence`): how the residual moves during holds of the voltage
   (creep), its size relative to the signal per frequency band and its regression on
   the model's rate ẋ (input lag), the peak of its spectrum (resonance), its trend
   in time (drift), the whole-sample lag that best aligns model and data (delay);
4. tries each effect of the vocabulary not yet in the model (creep, input_lag,
   resonance, drift, delay): adds it, refits everything on the fitting part
   (:func:`boucwen.effects.fit_extended`) and simulates the whole record; the most
   likely effect is the one that explains most of the *held-out* error;
5. keeps it only if it cuts the held-out RMS error by at least ``min_gain``
   (10 % by default) — an effect that only fits the noise of the fitting part does
   not earn its parameters there — and repeats from 3 until nothing is kept;
6. refits the base model and the kept effects on the whole record and reports the
   errors over the whole record, before (base model) and after (with the effects);
7. tests what the final model leaves against the noise estimated from the record and
   against what could explain it (:func:`~boucwen.diagnosis.unexplained.unexplained`):
   ``Diagnosis.unexplained`` says whether the residual is consistent with noise and,
   if not, which signals, spectral lines and time spans it follows — also when no
   effect of the vocabulary accounts for it.

In step 4 each round also refits the current model with nothing added and the same
iteration budget (the *null trial*); an effect is credited only with what it cuts
from the held-out error beyond the better of the current model and the null trial,
so that the extra iterations of a trial fit are not taken for the effect.

With no effect in the data, every trial fails step 5 and the result says so
(``effects == []``).

Modules: :mod:`~boucwen.diagnosis.evidence` (the residual statistics),
:mod:`~boucwen.diagnosis.unexplained` (what the final model leaves, step 7),
:mod:`~boucwen.diagnosis.search` (the procedure above),
:mod:`~boucwen.diagnosis.report` (:class:`Diagnosis`, its JSON and CSV files); the
figure is :func:`boucwen.plots.plot_diagnosis`.
"""

from .evidence import residual_evidence, residual_evidence_record
from .report import Diagnosis, write_predictions, write_report
from .search import MAX_DELAY_SAMPLES, MIN_GAIN, TRAIN_FRACTION, TRIAL_NFEV, diagnose, diagnose_record
from .unexplained import Unexplained, noise_level, unexplained

__all__ = [
    "MAX_DELAY_SAMPLES",
    "MIN_GAIN",
    "TRAIN_FRACTION",
    "TRIAL_NFEV",
    "Diagnosis",
    "Unexplained",
    "diagnose",
    "diagnose_record",
    "noise_level",
    "residual_evidence",
    "residual_evidence_record",
    "unexplained",
    "write_predictions",
    "write_report",
]
