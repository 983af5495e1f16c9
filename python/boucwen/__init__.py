"""boucwen: the asymmetric Bouc–Wen model of piezoelectric-actuator hysteresis.

    x = kv·u + x0 + h                                             (3)
    dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)      (5)

u: voltage [V]; x, h: displacement [µm]; t: time [s] (Zhu, Bian & Rui,
Precision Engineering 38 (2014) 921–927).

- :class:`Params` the seven parameters; :func:`simulate` and :class:`Model` run the model;
- :class:`Identifier` identifies them online, one sample at a time (configured by
  :class:`HorizonConfig`, :class:`RpemConfig` or :class:`PaperConfig`; what a push did is
  :class:`HorizonStatus`, :class:`RpemStatus` or :class:`PaperStatus`); :class:`Bank` runs C channels per call;
- :func:`fit` identifies them offline from a record (output-error least squares);
- :class:`SavedModel` is a model as a file (:func:`load_model`, :meth:`SavedModel.save`,
  one versioned JSON schema that the command line's ``--model`` writes and reads, the
  measurement chain included; :class:`SavedOscillator` the hysteretic oscillator's);
- :func:`diagnose` finds which effects (:class:`EffectSet`) a record holds beyond the model;
  each effect is a typed object (:class:`Creep`, :class:`InputLag`, :class:`GainDrift`,
  :class:`Electrostriction`, :class:`Resonance`, :class:`Resonance2`, :class:`Drift`,
  :class:`Delay`, :class:`Pickup`, :class:`Saturation`, and what the command does between
  samples, :class:`BetweenSamples`; :func:`effect_set` and :func:`effects_of` convert);
- :class:`Inverse` and :func:`invert` give the voltage for a desired displacement,
  :class:`Compensator` does so in a control loop with online identification and feedback;
- every bad input raises a ``ValueError``, named by its kind: :class:`InvalidParams`,
  :class:`InvalidConfig`, :class:`InvalidRecord`, :class:`CorruptSnapshot`,
  :class:`LengthMismatch`;
- :mod:`boucwen.reference` is a plain NumPy version of the same, for reading and tests.
"""

from . import _threads  # noqa: F401  (first: before NumPy loads)
from ._core import (
    INVERSE_TOLERANCE_UM,
    Bank,
    Compensator,
    CorruptSnapshot,
    EffectSet,
    ExtendedState,
    Identifier,
    InvalidConfig,
    InvalidParams,
    InvalidRecord,
    Inverse,
    LengthMismatch,
    Model,
    Params,
    __version__,
    invert,
    paper_input,
    simulate,
    simulate_extended,
    simulate_many,
)
from .config import HorizonConfig, PaperConfig, RpemConfig
from .diagnosis import Diagnosis, DiagnosisPolicy, ModelFit, NamedEffect, diagnose
from .effects import (
    BetweenSamples,
    Creep,
    Delay,
    Drift,
    Electrostriction,
    GainDrift,
    InputLag,
    Pickup,
    Resonance,
    Resonance2,
    Saturation,
    effect_set,
    effects_of,
)
from .fit import FitResult, fit
from .model_file import ModelSource, SavedModel, SavedOscillator, load_model
from .status import HorizonStatus, PaperStatus, RpemStatus, StepStatus

__all__ = [
    "INVERSE_TOLERANCE_UM",
    "Bank",
    "BetweenSamples",
    "Compensator",
    "CorruptSnapshot",
    "Creep",
    "Delay",
    "Diagnosis",
    "DiagnosisPolicy",
    "Drift",
    "EffectSet",
    "Electrostriction",
    "ExtendedState",
    "FitResult",
    "GainDrift",
    "HorizonConfig",
    "HorizonStatus",
    "Identifier",
    "InputLag",
    "InvalidConfig",
    "InvalidParams",
    "InvalidRecord",
    "Inverse",
    "LengthMismatch",
    "Model",
    "ModelFit",
    "ModelSource",
    "NamedEffect",
    "PaperConfig",
    "PaperStatus",
    "Params",
    "Pickup",
    "Resonance",
    "Resonance2",
    "RpemConfig",
    "RpemStatus",
    "Saturation",
    "SavedModel",
    "SavedOscillator",
    "StepStatus",
    "__version__",
    "diagnose",
    "effect_set",
    "effects_of",
    "fit",
    "invert",
    "load_model",
    "paper_input",
    "simulate",
    "simulate_extended",
    "simulate_many",
]
