"""boucwen: the asymmetric Bouc–Wen model of piezoelectric-actuator hysteresis.

    x = kv·u + x0 + h                                             (3)
    dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)      (5)

u: voltage [V]; x, h: displacement [µm]; t: time [s] (Zhu, Bian & Rui,
Precision Engineering 38 (2014) 921–927).

- :class:`Params` the seven parameters; :func:`simulate` and :class:`Model` run the model;
- :class:`Identifier` identifies them online, one sample at a time (configured by
  :class:`HorizonConfig`, :class:`RpemConfig` or :class:`PaperConfig`); :class:`Bank` runs C channels per call;
- :func:`fit` identifies them offline from a record (output-error least squares);
- :func:`diagnose` finds which effects (:class:`EffectSet`) a record holds beyond the model;
- :mod:`boucwen.reference` is a plain NumPy version of the same, for reading and tests.
"""

from ._core import Bank, EffectSet, Identifier, Model, Params, __version__, paper_input, simulate, simulate_extended
from .config import HorizonConfig, PaperConfig, RpemConfig
from .diagnosis import Diagnosis, diagnose
from .fit import FitResult, fit

__all__ = [
    "Bank",
    "Diagnosis",
    "EffectSet",
    "FitResult",
    "HorizonConfig",
    "Identifier",
    "Model",
    "PaperConfig",
    "Params",
    "RpemConfig",
    "__version__",
    "diagnose",
    "fit",
    "paper_input",
    "simulate",
    "simulate_extended",
]
