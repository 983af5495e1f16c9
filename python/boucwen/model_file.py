"""A fitted model as a file: one versioned JSON schema that every command writes and reads.

``boucwen fit … --model M.json``, ``boucwen diagnose … --model M.json`` and
``boucwen identify … --model M.json`` write it; ``boucwen invert --model M.json``,
``boucwen simulate --model M.json`` and ``boucwen identify --init M.json`` read it. In
Python, :func:`load_model` returns a :class:`SavedModel` (the piezo model) or a
:class:`SavedOscillator` (the hysteretic oscillator, :mod:`boucwen.oscillator`), and
their ``save`` writes one; each simulates itself with its effects and its measurement
chain (``simulate``).

The schema, version 2 (:data:`SCHEMA`, :data:`VERSION`), of a piezo model::

    {
      "schema": "boucwen.model",
      "version": 2,
      "structure": "piezo",
      "params": {"kv": …, "x0": …, "A": …, "beta": …, "gamma": …, "n": …, "delta": …},
      "h0_um": …,                 # the hysteresis state h at the first sample [µm]
      "effects": {"input_lag": {"fc_hz": …}, …},   # boucwen.effects.to_json's shape
      "chain": {"input": "hold", "output": null},  # the measurement chain (below)
      "dt_s": …,                  # sampling interval of the record it came from [s]
      "units": {"u": "V", "x": "µm", "t": "s", "params.kv": "µm/V", …},
      "source": {"made_by": "fit", "record": "DATA.csv", "sha256": "…", "columns": {…},
                 "samples": …, "rms_um": …, "max_um": …}
    }

and of an oscillator (force F [N] in, displacement y [m] out)::

    {
      "schema": "boucwen.model", "version": 2, "structure": "oscillator",
      "params": {"m": …, "c": …, "k": …, "alpha": …, "beta": …, "gamma": …, "delta": …, "nu": …},
      "state": {"y0_m": …, "v0_m_s": …, "z0_N": …},   # the state at the first sample
      "chain": {"input": "bandlimited", "output": {"name": …, "taps": […], "center": …}},
      "dt_s": …, "units": {"u": "N", "x": "m", …}, "source": {…}
    }

``chain`` is the measurement chain (:mod:`boucwen.measurement`): ``input``, what the
input did between samples (``"hold"``: a DAC's zero-order hold; ``"linear"``;
``"bandlimited"``), and ``output``, the logger's FIR on the output at the record's rate
(:class:`boucwen.measurement.OutputFilter`: its taps and the index of the tap on the
sample itself) or null. A piezo model's input path is its ``between_samples`` effect
(:class:`boucwen.effects.BetweenSamples`, absent for ``"linear"``): a version-2 file
carries it in ``chain.input`` only. A model with an output filter, as one with a delay,
runs only at its own sampling interval.

``units`` states the units every number is in (:data:`UNITS`, :data:`OSCILLATOR_UNITS`);
a file in other units is refused, not converted. ``source`` says where the model came
from: the command that made it, the record's path, the SHA-256 of its file, the columns
read (``{"t": …, "u": …, "x": …}``, header names or ``"column 2"``), its samples and the
model's own open-loop error on it (RMS and max |x − x̂| [µm]; an oscillator's error in
µm too, as the record holds it); each may be null.

A version-1 file (a piezo model; no ``structure`` and no ``chain``: its input path, if
any, in ``effects.between_samples``) is read as before.

Reading checks every field: a file of a newer version, a corrupt file, a field of the
wrong kind or a model outside the admissible region (whose h runs away: docs/design.md,
"The admissible region"; :meth:`boucwen.Params.check_admissible`,
:func:`boucwen.oscillator.check_admissible`) raises :class:`boucwen.InvalidParams` (a
``ValueError``) with one line that names the file and the field (``M.json: field
'params.kv': …``). A model outside the region cannot be built, so none is written either.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ._core import EffectSet, InvalidConfig, InvalidParams, Params, simulate_extended
from .checks import FloatArray, as_float_vector, check_dt
from .effects import Effect, effects_of, from_json
from .effects.base import params_of, set_of
from .measurement import INPUT_CHOICES, OutputFilter

if TYPE_CHECKING:
    from .oscillator import OscillatorFit, OscillatorParams
    from .record import Record

#: Builds the error of a field (None: of the whole file) from its message.
_Fail = Callable[[str | None, str], InvalidParams]

__all__ = [
    "OSCILLATOR_UNITS",
    "SCHEMA",
    "STRUCTURES",
    "UNITS",
    "VERSION",
    "AnyModel",
    "ModelSource",
    "SavedModel",
    "SavedOscillator",
    "load_model",
]

#: The ``schema`` field of every model file.
SCHEMA = "boucwen.model"
#: The schema version this boucwen writes; it reads this one and older.
VERSION = 2
#: The model classes a file holds (its ``structure``): the piezo model, the hysteretic
#: oscillator.
STRUCTURES = ("piezo", "oscillator")
#: The unit of each number of a piezo model's file (effect parameters carry theirs in
#: their names).
UNITS: dict[str, str] = {
    "u": "V",
    "x": "µm",
    "t": "s",
    "dt_s": "s",
    "h0_um": "µm",
    "params.kv": "µm/V",
    "params.x0": "µm",
    "params.A": "µm/V",
    "params.beta": "µm^(1-n)/V",
    "params.gamma": "µm^(1-n)/V",
    "params.n": "-",
    "params.delta": "µm/(V·s)",
}
#: The unit of each number of an oscillator's file.
OSCILLATOR_UNITS: dict[str, str] = {
    "u": "N",
    "x": "m",
    "t": "s",
    "dt_s": "s",
    "params.m": "kg",
    "params.c": "N·s/m",
    "params.k": "N/m",
    "params.alpha": "N/m",
    "params.beta": "N^(1-nu)/m",
    "params.gamma": "-",
    "params.delta": "-",
    "params.nu": "-",
    "state.y0_m": "m",
    "state.v0_m_s": "m/s",
    "state.z0_N": "N",
}
_FIELDS_V1: tuple[str, ...] = ("schema", "version", "params", "h0_um", "effects", "dt_s", "units", "source")
_FIELDS: dict[str, tuple[str, ...]] = {
    "piezo": ("schema", "version", "structure", "params", "h0_um", "effects", "chain", "dt_s", "units", "source"),
    "oscillator": ("schema", "version", "structure", "params", "state", "chain", "dt_s", "units", "source"),
}
_SOURCE_FIELDS = ("made_by", "record", "sha256", "columns", "samples", "rms_um", "max_um")
_STATE_FIELDS = ("y0_m", "v0_m_s", "z0_N")
_OUTPUT_FIELDS = ("name", "taps", "center")


@dataclass(frozen=True)
class ModelSource:
    """Where a model came from (every field may be None).

    Attributes:
        made_by: what made it: ``"fit"``, ``"diagnose"``, ``"identify"``, or another word.
        record: path of the record it was identified on, as given.
        sha256: SHA-256 of that file (64 hex digits).
        columns: the columns read, ``{"t": …, "u": …, "x": …}`` (header names, or
            ``"column N"`` for a file without a header; ``t`` None without time).
        samples: samples of the record.
        rms_um, max_um: the model's open-loop error on the record, RMS and max |x − x̂| [µm].
    """

    made_by: str | None = None
    record: str | None = None
    sha256: str | None = None
    columns: dict[str, str | None] | None = None
    samples: int | None = None
    rms_um: float | None = None
    max_um: float | None = None

    @classmethod
    def of_record(cls, rec: Record, made_by: str, x_model: FloatArray | None = None) -> ModelSource:
        """The source of a model identified on ``rec`` (a record of :func:`boucwen.io.read_csv`
        or :mod:`boucwen.datasets`): its file, the file's SHA-256, the columns read and,
        given the model's open-loop displacement ``x_model`` [µm], its error there."""
        from .io import sha256_file
        from .metrics import max_abs, rms

        path = rec.meta.get("path", rec.meta.get("file"))
        columns = rec.meta.get("read")
        if columns is None and "file" in rec.meta:  # a record of boucwen.datasets
            columns = {"t": None, "u": "column 1", "x": "column 5"}
        digest = sha256_file(path) if path is not None and Path(path).is_file() else None
        err = None if x_model is None else rec.x - x_model
        return cls(
            made_by=made_by,
            record=None if path is None else str(path),
            sha256=digest,
            columns=None if columns is None else dict(columns),
            samples=len(rec),
            rms_um=None if err is None else rms(err),
            max_um=None if err is None else max_abs(err),
        )

    def to_dict(self) -> dict[str, Any]:
        """The ``source`` field of the file."""
        return {name: getattr(self, name) for name in _SOURCE_FIELDS}


def _check_chain_rate(dt_s: float, step: float, delay: bool, output: OutputFilter | None) -> None:
    """A model that delays by whole samples or filters its output at its record's rate
    runs only at its own interval; :class:`boucwen.InvalidConfig` otherwise."""
    if math.isclose(step, dt_s, rel_tol=1e-9):
        return
    if delay:
        raise InvalidConfig(f"the model delays by whole samples of {dt_s:g} s; it cannot run at dt = {step:g} s")
    if output is not None:
        raise InvalidConfig(f"the model's output filter has taps {dt_s:g} s apart; it cannot run at dt = {step:g} s")


def _chain_dict(input: str, output: OutputFilter | None) -> dict[str, Any]:
    return {"input": input, "output": None if output is None else output.to_dict()}


@dataclass(frozen=True, eq=False)
class SavedModel:
    """A piezo model that can be written to and read from a file (the module docs give
    the schema).

    Named apart from :class:`boucwen.Model`, the per-sample model of the core.

    Attributes:
        params: the base parameters (:class:`boucwen.Params`).
        h0_um: the hysteresis state h at the first sample [µm].
        dt_s: sampling interval of the record the model came from [s].
        effects: the effects with their parameters (:class:`boucwen.EffectSet`, empty:
            none); the input path between samples is its ``between_samples`` effect
            (:attr:`input`).
        source: where it came from (:class:`ModelSource`).
        output: the logger's filter on x (:class:`boucwen.measurement.OutputFilter`), or None.
    """

    structure: ClassVar[str] = "piezo"

    params: Params
    h0_um: float
    dt_s: float
    effects: EffectSet = field(default_factory=EffectSet)
    source: ModelSource = field(default_factory=ModelSource)
    output: OutputFilter | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.params, Params):
            raise TypeError(f"params must be a boucwen.Params, got {type(self.params).__name__}")
        if not isinstance(self.effects, EffectSet):
            raise TypeError(f"effects must be a boucwen.EffectSet, got {type(self.effects).__name__}")
        if self.output is not None and not isinstance(self.output, OutputFilter):
            raise TypeError(f"output must be a boucwen.measurement.OutputFilter, got {type(self.output).__name__}")
        self.params.check_admissible()
        h0 = float(self.h0_um)
        if not math.isfinite(h0):
            raise InvalidParams(f"h0_um must be finite, got {self.h0_um!r}")
        object.__setattr__(self, "h0_um", h0)
        object.__setattr__(self, "dt_s", check_dt(self.dt_s))

    @property
    def input(self) -> str:
        """What the voltage does between samples: ``"hold"``, ``"linear"`` or
        ``"bandlimited"`` (the ``between_samples`` effect; ``"linear"`` without it)."""
        between = params_of(self.effects).get("between_samples")
        return "linear" if between is None else str(between["input"])

    @property
    def named_effects(self) -> tuple[Effect, ...]:
        """The effects as typed objects, in signal-chain order (:func:`boucwen.effects_of`)."""
        return effects_of(self.effects)

    def simulate(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        """The model's displacement x [µm] for the voltages ``u`` [V], open loop from
        ``h0_um``, with its effects (:func:`boucwen.simulate_extended`) and its output
        filter.

        Args:
            u: voltage samples [V], 1-D, finite.
            dt: sampling interval [s]; default the model's ``dt_s``. A model with a
                ``delay`` (whole samples) or an output filter only runs at its own interval.

        Raises:
            InvalidRecord: a bad ``u``; InvalidConfig: a bad ``dt``, or another
                interval than the model's for a model with a delay or an output filter.
        """
        step = self.dt_s if dt is None else check_dt(dt)
        _check_chain_rate(self.dt_s, step, "delay" in self.effects, self.output)
        x = np.asarray(simulate_extended(self.params, self.effects, as_float_vector(u, "u"), step, self.h0_um))
        return x if self.output is None else self.output.apply(x)

    def to_dict(self) -> dict[str, Any]:
        """The file's content (the module docs' schema), JSON-ready."""
        effects = params_of(self.effects)
        effects.pop("between_samples", None)
        return _document(self, {"params": self.params.to_dict(), "h0_um": self.h0_um, "effects": effects}, UNITS)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the model to ``path`` as JSON (schema version :data:`VERSION`); OSError if it cannot."""
        _save(self.to_dict(), path)

    @classmethod
    def from_dict(cls, doc: Any, where: str = "model") -> SavedModel:
        """Reads the content of a piezo model's file; :class:`boucwen.InvalidParams`
        naming ``where`` (the file) and the field at fault (an oscillator's file too)."""
        model = _from_dict(doc, where)
        if not isinstance(model, SavedModel):
            raise InvalidParams(f"{where}: field 'structure': an oscillator, not a piezo model")
        return model

    def __repr__(self) -> str:
        named = ", ".join(params_of(self.effects)) or "none"
        chain = "" if self.output is None else f", output={self.output.name or 'filter'}"
        return f"SavedModel(params={self.params!r}, h0_um={self.h0_um!r}, effects: {named}{chain}, dt_s={self.dt_s!r})"


@dataclass(frozen=True, eq=False)
class SavedOscillator:
    """A hysteretic oscillator (:mod:`boucwen.oscillator`) that can be written to and read
    from a file (the module docs give the schema): force F [N] in, displacement y [m] out.

    Attributes:
        params: the parameters (:class:`boucwen.oscillator.OscillatorParams`), in the
            oscillator's admissible region.
        y0_m, v0_m_s, z0_N: the state at the first sample: displacement [m], velocity
            [m/s], hysteretic force [N].
        dt_s: sampling interval of the record it came from [s].
        input: what the force does between samples (``"hold"``, ``"linear"``,
            ``"bandlimited"``).
        output: the logger's filter on y (:class:`boucwen.measurement.OutputFilter`), or None.
        source: where it came from (:class:`ModelSource`; its errors in µm).
    """

    structure: ClassVar[str] = "oscillator"

    params: OscillatorParams
    y0_m: float
    v0_m_s: float
    z0_N: float
    dt_s: float
    input: str = "linear"
    output: OutputFilter | None = None
    source: ModelSource = field(default_factory=ModelSource)

    def __post_init__(self) -> None:
        from .measurement import check_input
        from .oscillator import OscillatorParams, check_admissible

        if not isinstance(self.params, OscillatorParams):
            raise TypeError(f"params must be a boucwen.oscillator.OscillatorParams, got {type(self.params).__name__}")
        if self.output is not None and not isinstance(self.output, OutputFilter):
            raise TypeError(f"output must be a boucwen.measurement.OutputFilter, got {type(self.output).__name__}")
        check_admissible(self.params)
        for name in _STATE_FIELDS:
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise InvalidParams(f"{name} must be finite, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "dt_s", check_dt(self.dt_s))
        check_input(self.input)

    @classmethod
    def of_fit(cls, fit: OscillatorFit, dt: float, source: ModelSource | None = None) -> SavedOscillator:
        """The model of an :class:`boucwen.oscillator.OscillatorFit` on a record sampled
        every ``dt`` [s], with the chain it was fitted with."""
        return cls(
            fit.params,
            fit.y0,
            fit.v0,
            fit.z0,
            dt,
            fit.input,
            fit.output,
            source if source is not None else ModelSource(),
        )

    def simulate(self, u: ArrayLike, dt: float | None = None, *, periodic: bool = False) -> FloatArray:
        """The displacement y [m] for the force ``u`` [N] from the model's initial state,
        through its measurement chain (:func:`boucwen.oscillator.simulate`).

        Args:
            u: force samples [N], 1-D, finite.
            dt: sampling interval [s]; default the model's ``dt_s`` (a model with an
                output filter only runs at its own interval).
            periodic: ``u`` is a whole number of periods (a band-limited force is then
                exactly its Fourier interpolation).
        """
        from .oscillator import simulate

        step = self.dt_s if dt is None else check_dt(dt)
        _check_chain_rate(self.dt_s, step, False, self.output)
        return simulate(
            self.params,
            u,
            step,
            self.y0_m,
            self.v0_m_s,
            self.z0_N,
            input=self.input,
            periodic=periodic,
            output=self.output,
        )

    def to_dict(self) -> dict[str, Any]:
        """The file's content (the module docs' schema), JSON-ready."""
        state = {name: getattr(self, name) for name in _STATE_FIELDS}
        return _document(self, {"params": self.params.to_dict(), "state": state}, OSCILLATOR_UNITS)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the model to ``path`` as JSON (schema version :data:`VERSION`); OSError if it cannot."""
        _save(self.to_dict(), path)

    def __repr__(self) -> str:
        chain = "" if self.output is None else f", output={self.output.name or 'filter'}"
        return f"SavedOscillator(params={self.params!r}, input={self.input!r}{chain}, dt_s={self.dt_s!r})"


#: A model of either structure, as :func:`load_model` returns it.
AnyModel = SavedModel | SavedOscillator


def _document(model: AnyModel, body: dict[str, Any], units: dict[str, str]) -> dict[str, Any]:
    """A model file's content: the header, the structure's own ``body``, the chain, the
    interval, the ``units`` and the source."""
    return {
        "schema": SCHEMA,
        "version": VERSION,
        "structure": model.structure,
        **body,
        "chain": _chain_dict(model.input, model.output),
        "dt_s": model.dt_s,
        "units": dict(units),
        "source": model.source.to_dict(),
    }


def _save(doc: dict[str, Any], path: str | os.PathLike[str]) -> None:
    from .io import jsonable

    text = json.dumps(jsonable(doc), indent=2, ensure_ascii=False, allow_nan=False)
    Path(path).write_text(text + "\n", encoding="utf-8")


def _from_dict(doc: Any, where: str) -> AnyModel:
    """A model of either structure from a file's content (the module docs' schema)."""

    def fail(name: str | None, message: str) -> InvalidParams:
        return InvalidParams(f"{where}: field {name!r}: {message}" if name else f"{where}: {message}")

    if not isinstance(doc, dict):
        raise fail(None, f"not a boucwen model file: expected a JSON object, got {_kind(doc)}")
    if doc.get("schema") != SCHEMA:
        got = repr(doc["schema"]) if "schema" in doc else "none"
        raise fail("schema", f"expected {SCHEMA!r}, got {got} (not a boucwen model file)")
    version = _required(doc, "version", fail)
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise fail("version", f"expected a whole number >= 1, got {version!r}")
    if version > VERSION:
        raise fail("version", f"{version} is newer than this boucwen reads (up to {VERSION}); upgrade boucwen")
    if version == 1:
        structure, expected = "piezo", _FIELDS_V1
    else:
        structure = _required(doc, "structure", fail)
        if structure not in STRUCTURES:
            raise fail("structure", f"expected one of {', '.join(STRUCTURES)}, got {structure!r}")
        expected = _FIELDS[structure]
    unknown = [k for k in doc if k not in expected]
    if unknown:
        raise fail(unknown[0], f"unknown field; a version-{version} {structure} model has {', '.join(expected)}")

    units = _required(doc, "units", fail)
    if not isinstance(units, dict):
        raise fail("units", f"expected an object, got {_kind(units)}")
    for key, unit in (UNITS if structure == "piezo" else OSCILLATOR_UNITS).items():
        if units.get(key) != unit:
            got = repr(units[key]) if key in units else "nothing"
            raise fail(f"units.{key}", f"boucwen {structure} models are in {unit!r}, the file says {got}")
    input, output = ("linear", None) if version == 1 else _chain(_required(doc, "chain", fail), fail)
    dt = _number(doc, "dt_s", fail)
    if dt <= 0.0:
        raise fail("dt_s", f"expected a sampling interval > 0 s, got {dt!r}")
    source = _source(doc.get("source"), fail)
    raw = _required(doc, "params", fail)
    if structure == "oscillator":
        return _oscillator(doc, raw, dt, input, output, source, fail)

    if not isinstance(raw, dict):
        raise fail("params", f"expected an object of {', '.join(Params.names)}, got {_kind(raw)}")
    values = _numbers(raw, tuple(Params.names), "params", fail)
    try:
        params = Params(**values)
        # A model whose h runs away is refused, not read (docs/design.md, "The
        # admissible region").
        params.check_admissible()
    except ValueError as exc:
        raise fail("params", str(exc)) from None

    effects_doc = _required(doc, "effects", fail)
    if not isinstance(effects_doc, dict):
        raise fail("effects", f"expected an object {{effect name: {{parameter: value}}}}, got {_kind(effects_doc)}")
    if version > 1 and "between_samples" in effects_doc:
        raise fail("effects.between_samples", "a version-2 file carries the input path in 'chain.input'")
    try:
        effects = from_json(json.dumps(effects_doc))
    except (ValueError, TypeError) as exc:
        raise fail("effects", str(exc)) from None
    if input != "linear":
        effects = set_of({**params_of(effects), "between_samples": {"input": input}})
    h0 = _number(doc, "h0_um", fail)
    return SavedModel(params, h0, dt, effects, source, output)


def _oscillator(
    doc: dict[str, Any],
    raw: Any,
    dt: float,
    input: str,
    output: OutputFilter | None,
    source: ModelSource,
    fail: _Fail,
) -> SavedOscillator:
    from .oscillator import OscillatorParams, check_admissible

    names = tuple(f.name for f in fields(OscillatorParams))
    if not isinstance(raw, dict):
        raise fail("params", f"expected an object of {', '.join(names)}, got {_kind(raw)}")
    values = _numbers(raw, names, "params", fail)
    try:
        params = check_admissible(OscillatorParams(**values))
    except ValueError as exc:
        raise fail("params", str(exc)) from None
    state = _required(doc, "state", fail)
    if not isinstance(state, dict):
        raise fail("state", f"expected an object of {', '.join(_STATE_FIELDS)}, got {_kind(state)}")
    y0, v0, z0 = _numbers(state, _STATE_FIELDS, "state", fail).values()
    return SavedOscillator(params, y0, v0, z0, dt, input, output, source)


def _chain(doc: Any, fail: _Fail) -> tuple[str, OutputFilter | None]:
    """The ``chain`` field: (input path, output filter or None)."""
    if not isinstance(doc, dict):
        raise fail("chain", f"expected an object {{'input': …, 'output': …}}, got {_kind(doc)}")
    unknown = [k for k in doc if k not in ("input", "output")]
    if unknown:
        raise fail(f"chain.{unknown[0]}", "unknown field; expected input, output")
    input = _required(doc, "input", fail, "chain.")
    if input not in INPUT_CHOICES:
        raise fail("chain.input", f"expected one of {', '.join(INPUT_CHOICES)}, got {input!r}")
    out = doc.get("output")
    if out is None:
        return input, None
    if not isinstance(out, dict):
        raise fail("chain.output", f"expected an object {{'name', 'taps', 'center'}} or null, got {_kind(out)}")
    unknown = [k for k in out if k not in _OUTPUT_FIELDS]
    if unknown:
        raise fail(f"chain.output.{unknown[0]}", f"unknown field; expected {', '.join(_OUTPUT_FIELDS)}")
    taps = _required(out, "taps", fail, "chain.output.")
    if not isinstance(taps, list) or not taps or not all(_is_number(v) for v in taps):
        raise fail("chain.output.taps", f"expected a non-empty list of finite numbers, got {taps!r}")
    center = _required(out, "center", fail, "chain.output.")
    if not isinstance(center, int) or isinstance(center, bool):
        raise fail("chain.output.center", f"expected a whole number, got {center!r}")
    name = out.get("name", "")
    if not isinstance(name, str):
        raise fail("chain.output.name", f"expected text, got {name!r}")
    try:
        return input, OutputFilter(tuple(float(v) for v in taps), center, name)
    except ValueError as exc:
        raise fail("chain.output", str(exc)) from None


def load_model(path: str | os.PathLike[str]) -> AnyModel:
    """Reads a model file (the module docs give the schema): a :class:`SavedModel` (a
    piezo model) or a :class:`SavedOscillator` (its ``structure`` says which).

    Raises:
        InvalidParams: no such file, not JSON, a newer version, a field missing or of
            the wrong kind, or a model outside the admissible region; the one-line
            message names the file and the field.
    """
    where = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InvalidParams(f"no such model file: {where}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidParams(f"{where}: cannot be read as a model file: {exc}") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InvalidParams(
            f"{where}: not a boucwen model file: invalid JSON at line {exc.lineno} column {exc.colno} ({exc.msg})"
        ) from None
    return _from_dict(doc, where)


def _kind(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def _required(doc: dict[str, Any], name: str, fail: _Fail, prefix: str = "") -> Any:
    if name not in doc:
        raise fail(prefix + name, "missing")
    return doc[name]


def _is_number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


def _number(doc: dict[str, Any], name: str, fail: _Fail, prefix: str = "") -> float:
    value = _required(doc, name, fail, prefix)
    if not _is_number(value):
        raise fail(prefix + name, f"expected a finite number, got {value!r}")
    return float(value)


def _numbers(doc: dict[str, Any], names: tuple[str, ...], where: str, fail: _Fail) -> dict[str, float]:
    """The numbers ``names`` of the object ``doc`` (the field ``where``), no other key."""
    values = {name: _number(doc, name, fail, f"{where}.") for name in names}
    extra = [k for k in doc if k not in names]
    if extra:
        raise fail(f"{where}.{extra[0]}", f"unknown parameter; expected {', '.join(names)}")
    return values


def _source(doc: Any, fail: _Fail) -> ModelSource:
    if doc is None:
        return ModelSource()
    if not isinstance(doc, dict):
        raise fail("source", f"expected an object, got {_kind(doc)}")
    unknown = [k for k in doc if k not in _SOURCE_FIELDS]
    if unknown:
        raise fail(f"source.{unknown[0]}", f"unknown field; expected {', '.join(_SOURCE_FIELDS)}")
    for name in ("made_by", "record", "sha256"):
        if doc.get(name) is not None and not isinstance(doc[name], str):
            raise fail(f"source.{name}", f"expected text or null, got {doc[name]!r}")
    columns = doc.get("columns")
    if columns is not None and (
        not isinstance(columns, dict) or not all(v is None or isinstance(v, str) for v in columns.values())
    ):
        raise fail("source.columns", f"expected an object of column names, got {columns!r}")
    samples = doc.get("samples")
    if samples is not None and (not isinstance(samples, int) or isinstance(samples, bool) or samples < 1):
        raise fail("source.samples", f"expected a whole number >= 1 or null, got {samples!r}")
    errors = {k: None if doc.get(k) is None else _number(doc, k, fail, "source.") for k in ("rms_um", "max_um")}
    return ModelSource(
        made_by=doc.get("made_by"),
        record=doc.get("record"),
        sha256=doc.get("sha256"),
        columns=None if columns is None else dict(columns),
        samples=samples,
        rms_um=errors["rms_um"],
        max_um=errors["max_um"],
    )
