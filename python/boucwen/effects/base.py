"""What every effect declares, and what the declarations are asked with.

An effect is a frozen dataclass deriving from :class:`Effect`: its fields are its
parameters, named as in :meth:`boucwen.EffectSet.to_dict`, and its methods say what
the extended fit needs to know about it:

* :meth:`Effect.unknowns`, :meth:`Effect.pack`, :meth:`Effect.unpack`: which of its
  parameters are fitted, in which coordinates (the others stay fixed);
* :meth:`Effect.bounds`: the bounds of those unknowns (where the model can be
  simulated); :meth:`Effect.sign_bounds`: further bounds the optimiser adds;
* :meth:`Effect.typical`: the typical size of each unknown (the floor of its scale in
  the optimiser);
* :meth:`Effect.starts`: the starting values tried when the effect is added to a fit.

and what the diagnosis needs to know about it when it tries the effect on a record
(the search itself names no effect; see :mod:`boucwen.diagnosis`):

* :attr:`Effect.partner`, :meth:`Effect.beside`: an effect tried beside another, whose
  trial adds both while the model lacks the other (a second resonance mode);
* :meth:`Effect.rejects`: a fitted value that makes the effect no candidate (a
  resonance without a peak);
* :attr:`Effect.signature`: what the look-alike tests call the residual it leaves
  (evidence, reported; :mod:`boucwen.residual.lookalike`);
* :attr:`Effect.of_record`: it belongs to the record, not to the device (not carried
  to another record).

The simulation itself is the Rust core's (:func:`boucwen.simulate_extended`), which
also validates the parameters: building an effect checks it there, so that an effect
that exists can be simulated.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, ClassVar, TypeVar, cast

from .._core import EffectSet, InvalidParams, Params, simulate_extended
from ..checks import FloatArray
from ..lsq import finite_or_none
from ..record import Record

__all__ = [
    "UNBOUNDED",
    "Context",
    "Effect",
    "Start",
    "params_of",
    "set_of",
    "simulate_chain",
    "with_effect",
    "without",
]

E = TypeVar("E", bound="Effect")

#: The bounds of an unbounded unknown.
UNBOUNDED: tuple[float, float] = (-math.inf, math.inf)


@dataclass(frozen=True)
class Context:
    """The record the unknowns are fitted on.

    Attributes:
        dt: sampling interval [s].
        duration_s: record length [s].
    """

    dt: float
    duration_s: float


@dataclass(frozen=True, eq=False)
class Start:
    """The fit an effect is about to be added to (what its starting values depend on).

    Attributes:
        record: the record fitted.
        params, effects, h0: the current fit (base parameters, effects, h0 [µm]).
        max_delay: largest delay tried [samples].
        creep_tau_s: the creep time constants [s] to use, or None for the default
            (:func:`boucwen.effects.creep_time_constants`).
    """

    record: Record
    params: Params
    effects: EffectSet
    h0: float
    max_delay: int = 8
    creep_tau_s: tuple[float, ...] | None = None


@dataclass(frozen=True)
class Effect(ABC):
    """An effect: a frozen dataclass of its parameters (see the module docs).

    Building one validates its parameters with the Rust core (ValueError or TypeError
    naming the parameter, e.g. ``input_lag.fc_hz``) and stores them as the core holds
    them: floats, tuples of floats, whole samples. The defaults of the methods below
    are those of an effect with no fitted unknown.
    """

    #: The effect's name in :data:`boucwen.EffectSet.vocabulary`.
    name: ClassVar[str]
    #: The effect this one is tried beside (None: any model); while the model lacks it,
    #: the trial of this one adds both (:meth:`beside`), under the name ``joint``.
    partner: ClassVar[str | None] = None
    joint: ClassVar[str] = ""
    #: What the look-alike tests (:mod:`boucwen.residual.lookalike`) call the residual
    #: this effect leaves behind when it is missing: a signal the residual follows
    #: (``lowpass_u``, ``t``, ``t_x``) or a shape of its phase (``delay``, ``lag``,
    #: ``peak``); None where no test speaks of it. Evidence only, reported beside the
    #: diagnosis's answer.
    signature: ClassVar[str | None] = None
    #: Its parameters need the record's full rate (a delay's whole samples; a lag's
    #: corner, which may lie above a decimated copy's band): a decimated copy of the
    #: record cannot hold it, so it is fitted on the full record only.
    full_rate_only: ClassVar[bool] = False
    #: It belongs to the record, not to the device (a drift, a mains pickup whose phase
    #: is the record's): not carried to another record of the device.
    of_record: ClassVar[bool] = False
    #: In the chain, it makes the core run every stage on
    #: :data:`boucwen._core.RESONANCE_SUBSTEPS` sub-intervals per sample (a mode), so a
    #: pass with it costs that many times one without.
    substepped: ClassVar[bool] = False

    def __post_init__(self) -> None:
        raw = {f.name: getattr(self, f.name) for f in fields(self)}
        checked = params_of(set_of({self.name: raw}))[self.name]
        for key, value in checked.items():
            object.__setattr__(self, key, tuple(value) if isinstance(value, list) else value)

    def to_dict(self) -> dict[str, Any]:
        """``{parameter: value}``, as in :meth:`boucwen.EffectSet.to_dict`."""
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls: type[E], params: Mapping[str, Any]) -> E:
        """Inverse of :meth:`to_dict`; :class:`boucwen.InvalidParams` for a missing or unknown parameter."""
        keys = [f.name for f in fields(cls)]
        if not isinstance(params, Mapping):
            raise TypeError(f"{cls.name} must be a dict with keys {keys}, got {type(params).__name__}")
        for key in params:
            if key not in keys:
                raise InvalidParams(f"{cls.name}: unknown parameter {key!r}; expected {keys}")
        for key in keys:
            if key not in params:
                raise InvalidParams(f"{cls.name}: missing parameter {key!r}")
        return cls(**params)

    def unknowns(self) -> tuple[str, ...]:
        """Names of the fitted unknowns (``<name>.`` is prefixed in a fit's labels)."""
        return ()

    def pack(self) -> tuple[float, ...]:
        """The unknowns' values, in the order of :meth:`unknowns`."""
        return ()

    def unpack(self: E, values: Sequence[float]) -> E:
        """This effect with the unknowns set to ``values``; ValueError if invalid."""
        return self

    def bounds(self, context: Context) -> tuple[tuple[float, float], ...]:
        """(lower, upper) of each unknown, for the optimiser."""
        return tuple(UNBOUNDED for _ in self.unknowns())

    def sign_bounds(self, static_gain: float) -> tuple[tuple[float, float], ...]:
        """(lower, upper) of each unknown that only the optimiser sees, given the
        model's static gain [µm/V] (kv plus the creep gains: the displacement per volt
        once creep has settled, whose sign is the actuator's)."""
        return tuple(UNBOUNDED for _ in self.unknowns())

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        """Least typical size of each unknown, given the record's peak-to-peak voltage
        ``span_u`` [V] and displacement ``span_x`` [µm]."""
        return ()

    @classmethod
    @abstractmethod
    def starts(cls: type[E], at: Start) -> list[E]:
        """The starting values tried when this effect is added to the fit ``at``
        (the caller keeps the one of least error)."""

    @classmethod
    def beside(cls, partner_start: EffectSet) -> EffectSet:
        """The start of the joint trial (:attr:`partner`), from the partner's best start."""
        return partner_start

    def rejects(self) -> str | None:
        """Why the fitted effect is no candidate (the trial is recorded, not credited),
        or None."""
        return None

    def rejects_on(self, record: Record, before: FloatArray) -> str | None:
        """Why the fitted effect is no candidate on ``record``, where the fitted model
        without this effect predicts ``before`` [µm] (what the effect acts on), or None."""
        return None


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def params_of(effects: EffectSet) -> dict[str, dict[str, Any]]:
    """:meth:`boucwen.EffectSet.to_dict`, keyed by any effect name."""
    return cast("dict[str, dict[str, Any]]", effects.to_dict())


def set_of(params: Mapping[str, Any]) -> EffectSet:
    """:meth:`boucwen.EffectSet.from_dict` of a dict whose keys are known at run time."""
    return EffectSet.from_dict(cast(Any, params))


def with_effect(effects: EffectSet, effect: Effect) -> EffectSet:
    """``effects`` with ``effect`` added, or replacing the one of its name."""
    return set_of({**params_of(effects), effect.name: effect.to_dict()})


def without(effects: EffectSet, name: str) -> EffectSet:
    """``effects`` without the effect ``name`` (if present)."""
    return set_of({k: v for k, v in params_of(effects).items() if k != name})


def simulate_chain(params: Params, effects: EffectSet, u: FloatArray, dt: float, h0: float) -> FloatArray | None:
    """:func:`boucwen.simulate_extended` [µm], or None if the values cannot be simulated."""
    return finite_or_none(lambda: simulate_extended(params, effects, u, dt, h0))
