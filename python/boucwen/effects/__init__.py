"""Effects: small physical models around the base model, as typed objects, and their fit.

Each effect is one frozen dataclass in its own module, its parameters as fields with
their units, declaring what the extended fit needs (:class:`Effect`): which
parameters are unknowns and in which coordinates, their bounds, typical sizes and
sign constraints, and the starting values tried when the effect is added:

============================  =====================  ===========================
class                         name                   parameters
============================  =====================  ===========================
:class:`Creep`                ``creep``              ``tau_s`` [s], ``gain_um_per_v`` [µm/V]
:class:`InputLag`             ``input_lag``          ``fc_hz`` [Hz]
:class:`GainDrift`            ``gain_drift``         ``rate_per_s`` [1/s]
:class:`Electrostriction`     ``electrostriction``   ``epsilon_per_um`` [1/µm]
:class:`Resonance`            ``resonance``          ``fn_hz`` [Hz], ``zeta`` [-]
:class:`Resonance2`           ``resonance2``         ``fn_hz`` [Hz], ``zeta`` [-]
:class:`Drift`                ``drift``              ``rate_um_per_s`` [µm/s]
:class:`Delay`                ``delay``              ``samples`` [samples]
:class:`Pickup`               ``pickup``             ``line_hz`` [Hz], ``sin_um``, ``cos_um`` [µm]
:class:`Saturation`           ``saturation``         ``min_um``, ``max_um`` [µm]
============================  =====================  ===========================

The simulation is the Rust core's (:class:`boucwen.EffectSet`,
:func:`boucwen.simulate_extended`). :func:`effect_set` and :func:`effects_of` convert
between typed effects and an :class:`boucwen.EffectSet`, :func:`to_json` and
:func:`from_json` between an :class:`boucwen.EffectSet` and JSON::

    s = effect_set(InputLag(fc_hz=650.0), Creep(tau_s=(0.05, 2.0), gain_um_per_v=(0.002, 0.001)))
    effects_of(from_json(to_json(s)))  # (Creep(...), InputLag(fc_hz=650.0))

:func:`fit_extended` fits the base model and the effects' unknowns by output error
(:mod:`boucwen.effects.fit`); its :class:`Layout` asks each effect present for its
unknowns. Adding an effect: one module here declaring its class, listed in
:data:`EFFECTS` (:mod:`boucwen.effects.registry`), and its simulation stage in the Rust
core.
"""

from .base import Context, Effect, Start, simulate_chain
from .creep import Creep, creep_time_constants
from .delay import Delay, best_delay
from .drift import Drift
from .electrostriction import Electrostriction
from .fit import (
    ExtendedFit,
    Layout,
    Solved,
    candidate_starts,
    fit_box,
    fit_extended,
    fit_extended_record,
    jacobian_extended,
    solve_extended_record,
)
from .gain_drift import GainDrift
from .input_lag import InputLag
from .pickup import LINE_FREQUENCIES_HZ, MAX_START_HARMONICS, Pickup
from .registry import EFFECTS, VOCABULARY, effect_class, effect_set, effects_of, from_json, to_json
from .resonance import FN_MAX_NYQUIST_FRACTION, ZETA_BOUNDS, Resonance
from .resonance2 import Resonance2
from .saturation import Saturation

__all__ = [
    "EFFECTS",
    "FN_MAX_NYQUIST_FRACTION",
    "LINE_FREQUENCIES_HZ",
    "MAX_START_HARMONICS",
    "VOCABULARY",
    "ZETA_BOUNDS",
    "Context",
    "Creep",
    "Delay",
    "Drift",
    "Effect",
    "Electrostriction",
    "ExtendedFit",
    "GainDrift",
    "InputLag",
    "Layout",
    "Pickup",
    "Resonance",
    "Resonance2",
    "Saturation",
    "Solved",
    "Start",
    "best_delay",
    "candidate_starts",
    "creep_time_constants",
    "effect_class",
    "effect_set",
    "effects_of",
    "fit_box",
    "fit_extended",
    "fit_extended_record",
    "from_json",
    "jacobian_extended",
    "simulate_chain",
    "solve_extended_record",
    "to_json",
]
