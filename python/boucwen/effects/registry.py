"""Every effect, in signal-chain order, and the conversions between typed effects,
:class:`boucwen.EffectSet` and JSON."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from .._core import EffectSet, InvalidParams
from .base import Effect, params_of, set_of
from .between_samples import BetweenSamples
from .creep import Creep
from .delay import Delay
from .drift import Drift
from .electrostriction import Electrostriction
from .gain_drift import GainDrift
from .input_lag import InputLag
from .pickup import Pickup
from .resonance import Resonance
from .resonance2 import Resonance2
from .saturation import Saturation

__all__ = ["EFFECTS", "VOCABULARY", "effect_class", "effect_set", "effects_of", "from_json", "to_json"]

#: Every effect class, in signal-chain order (that of :data:`boucwen.EffectSet.vocabulary`).
EFFECTS: tuple[type[Effect], ...] = (
    Creep,
    InputLag,
    GainDrift,
    Electrostriction,
    Resonance,
    Resonance2,
    Drift,
    Delay,
    Pickup,
    Saturation,
    BetweenSamples,
)
#: The effect names, in signal-chain order.
VOCABULARY: tuple[str, ...] = tuple(cls.name for cls in EFFECTS)

_BY_NAME: dict[str, type[Effect]] = {cls.name: cls for cls in EFFECTS}


def effect_class(name: str) -> type[Effect]:
    """The class of the effect ``name``; :class:`boucwen.InvalidParams` if there is none."""
    try:
        return _BY_NAME[name]
    except (KeyError, TypeError):
        raise InvalidParams(f"unknown effect {name!r}; expected one of {list(VOCABULARY)}") from None


def effect_set(*effects: Effect) -> EffectSet:
    """The :class:`boucwen.EffectSet` of the given effects (any order, each at most once)."""
    params: dict[str, Any] = {}
    given: tuple[object, ...] = effects
    for effect in given:
        if not isinstance(effect, Effect):
            names = ", ".join(cls.__name__ for cls in EFFECTS)
            raise TypeError(f"effect_set takes effects ({names}), got {type(effect).__name__}")
        if effect.name in params:
            raise InvalidParams(f"effect {effect.name!r} given more than once")
        params[effect.name] = effect.to_dict()
    return set_of(params)


def effects_of(effects: EffectSet) -> tuple[Effect, ...]:
    """The effects of ``effects`` as typed objects, in signal-chain order."""
    return _typed(params_of(effects))


def _typed(params: Mapping[str, Any]) -> tuple[Effect, ...]:
    present = {name: effect_class(name).from_dict(p) for name, p in params.items()}
    return tuple(present[name] for name in VOCABULARY if name in present)


def to_json(effects: EffectSet) -> str:
    """``effects`` as a JSON object ``{effect name: {parameter: value}}`` (units in the
    parameter names, as in :meth:`boucwen.EffectSet.to_dict`)."""
    return json.dumps(params_of(effects), allow_nan=False)


def from_json(text: str) -> EffectSet:
    """Inverse of :func:`to_json`; :class:`boucwen.InvalidParams` naming the effect or parameter at fault."""
    try:
        params = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InvalidParams(f"effects: not valid JSON ({exc})") from None
    if not isinstance(params, dict):
        shape = "{effect name: {parameter: value}}"
        raise InvalidParams(f"effects: expected a JSON object {shape}, got {type(params).__name__}")
    try:
        return effect_set(*_typed(params))
    except TypeError as exc:
        raise InvalidParams(str(exc)) from None
