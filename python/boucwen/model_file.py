"""A fitted model as a file: one versioned JSON schema that every command writes and reads.

``boucwen fit … --model M.json``, ``boucwen diagnose … --model M.json`` and
``boucwen identify … --model M.json`` write it; ``boucwen invert --model M.json`` and
``boucwen simulate --model M.json`` read it. In Python, :func:`load_model` returns a
:class:`SavedModel` and :meth:`SavedModel.save` writes one; the model simulates itself
with its effects (:meth:`SavedModel.simulate`).

The schema, version 1 (:data:`SCHEMA`, :data:`VERSION`)::

    {
      "schema": "boucwen.model",
      "version": 1,
      "params": {"kv": …, "x0": …, "A": …, "beta": …, "gamma": …, "n": …, "delta": …},
      "h0_um": …,                 # the hysteresis state h at the first sample [µm]
      "effects": {"input_lag": {"fc_hz": …}, …},   # boucwen.effects.to_json's shape
      "dt_s": …,                  # sampling interval of the record it came from [s]
      "units": {"u": "V", "x": "µm", "t": "s", "params.kv": "µm/V", …},
      "source": {"made_by": "fit", "record": "DATA.csv", "sha256": "…", "columns": {…},
                 "samples": …, "rms_um": …, "max_um": …}
    }

``units`` states the units every number is in (:data:`UNITS`); a file in other units is
refused, not converted. ``source`` says where the model came from: the command that
made it, the record's path, the SHA-256 of its file, the columns read (``{"t": …,
"u": …, "x": …}``, header names or ``"column 2"``), its samples and the model's own
open-loop error on it (RMS and max |x − x̂| [µm]); each may be null.

Reading checks every field: a file of a newer version, a corrupt file, a field of the
wrong kind or a model outside the admissible region (whose h runs away: docs/design.md,
"The admissible region"; :meth:`boucwen.Params.check_admissible`) raises
:class:`boucwen.InvalidParams` (a ``ValueError``) with one line that names the file and
the field (``M.json: field 'params.kv': …``). A :class:`SavedModel` outside the region
cannot be built, so none is written either.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
from numpy.typing import ArrayLike

from ._core import EffectSet, InvalidConfig, InvalidParams, Params, simulate_extended
from .checks import FloatArray, as_float_vector, check_dt
from .effects import Effect, effects_of, from_json
from .effects.base import params_of

if TYPE_CHECKING:
    from .record import Record

#: Builds the error of a field (None: of the whole file) from its message.
_Fail = Callable[[str | None, str], InvalidParams]

__all__ = ["SCHEMA", "UNITS", "VERSION", "ModelSource", "SavedModel", "load_model"]

#: The ``schema`` field of every model file.
SCHEMA = "boucwen.model"
#: The schema version this boucwen writes; it reads this one and older.
VERSION = 1
#: The unit of each number of the file (effect parameters carry theirs in their names).
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
_FIELDS = ("schema", "version", "params", "h0_um", "effects", "dt_s", "units", "source")
_SOURCE_FIELDS = ("made_by", "record", "sha256", "columns", "samples", "rms_um", "max_um")


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


@dataclass(frozen=True, eq=False)
class SavedModel:
    """A model that can be written to and read from a file (the module docs give the schema).

    Named apart from :class:`boucwen.Model`, the per-sample model of the core.

    Attributes:
        params: the base parameters (:class:`boucwen.Params`).
        h0_um: the hysteresis state h at the first sample [µm].
        dt_s: sampling interval of the record the model came from [s].
        effects: the effects with their parameters (:class:`boucwen.EffectSet`, empty: none).
        source: where it came from (:class:`ModelSource`).
    """

    params: Params
    h0_um: float
    dt_s: float
    effects: EffectSet = field(default_factory=EffectSet)
    source: ModelSource = field(default_factory=ModelSource)

    def __post_init__(self) -> None:
        if not isinstance(self.params, Params):
            raise TypeError(f"params must be a boucwen.Params, got {type(self.params).__name__}")
        if not isinstance(self.effects, EffectSet):
            raise TypeError(f"effects must be a boucwen.EffectSet, got {type(self.effects).__name__}")
        self.params.check_admissible()
        h0 = float(self.h0_um)
        if not math.isfinite(h0):
            raise InvalidParams(f"h0_um must be finite, got {self.h0_um!r}")
        object.__setattr__(self, "h0_um", h0)
        object.__setattr__(self, "dt_s", check_dt(self.dt_s))

    @property
    def named_effects(self) -> tuple[Effect, ...]:
        """The effects as typed objects, in signal-chain order (:func:`boucwen.effects_of`)."""
        return effects_of(self.effects)

    def simulate(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        """The model's displacement x [µm] for the voltages ``u`` [V], open loop from
        ``h0_um``, with its effects (:func:`boucwen.simulate_extended`).

        Args:
            u: voltage samples [V], 1-D, finite.
            dt: sampling interval [s]; default the model's ``dt_s``. A model with a
                ``delay`` (whole samples) only runs at its own interval.

        Raises:
            InvalidRecord: a bad ``u``; InvalidConfig: a bad ``dt``, or another
                interval than the model's for a model with a delay.
        """
        step = self.dt_s if dt is None else check_dt(dt)
        if "delay" in self.effects and not math.isclose(step, self.dt_s, rel_tol=1e-9):
            raise InvalidConfig(
                f"the model delays by whole samples of {self.dt_s:g} s; it cannot run at dt = {step:g} s"
            )
        return np.asarray(simulate_extended(self.params, self.effects, as_float_vector(u, "u"), step, self.h0_um))

    def to_dict(self) -> dict[str, Any]:
        """The file's content (the module docs' schema), JSON-ready."""
        return {
            "schema": SCHEMA,
            "version": VERSION,
            "params": self.params.to_dict(),
            "h0_um": self.h0_um,
            "effects": params_of(self.effects),
            "dt_s": self.dt_s,
            "units": dict(UNITS),
            "source": self.source.to_dict(),
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the model to ``path`` as JSON (schema version :data:`VERSION`); OSError if it cannot."""
        from .io import jsonable

        text = json.dumps(jsonable(self.to_dict()), indent=2, ensure_ascii=False, allow_nan=False)
        Path(path).write_text(text + "\n", encoding="utf-8")

    @classmethod
    def from_dict(cls, doc: Any, where: str = "model") -> SavedModel:
        """Reads the content of a model file; :class:`boucwen.InvalidParams` naming
        ``where`` (the file) and the field at fault."""

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
        unknown = [k for k in doc if k not in _FIELDS]
        if unknown:
            raise fail(unknown[0], f"unknown field; a version-{VERSION} model has {', '.join(_FIELDS)}")

        units = _required(doc, "units", fail)
        if not isinstance(units, dict):
            raise fail("units", f"expected an object, got {_kind(units)}")
        for key, unit in UNITS.items():
            if units.get(key) != unit:
                got = repr(units[key]) if key in units else "nothing"
                raise fail(f"units.{key}", f"boucwen models are in {unit!r}, the file says {got}")

        raw = _required(doc, "params", fail)
        if not isinstance(raw, dict):
            raise fail("params", f"expected an object of {', '.join(Params.names)}, got {_kind(raw)}")
        values: dict[str, float] = {}
        for name in Params.names:
            values[name] = _number(raw, name, fail, "params.")
        extra = [k for k in raw if k not in Params.names]
        if extra:
            raise fail(f"params.{extra[0]}", f"unknown parameter; expected {', '.join(Params.names)}")
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
        try:
            effects = from_json(json.dumps(effects_doc))
        except (ValueError, TypeError) as exc:
            raise fail("effects", str(exc)) from None

        h0 = _number(doc, "h0_um", fail)
        dt = _number(doc, "dt_s", fail)
        if dt <= 0.0:
            raise fail("dt_s", f"expected a sampling interval > 0 s, got {dt!r}")
        return cls(params, h0, dt, effects, _source(doc.get("source"), fail))

    def __repr__(self) -> str:
        named = ", ".join(params_of(self.effects)) or "none"
        return f"SavedModel(params={self.params!r}, h0_um={self.h0_um!r}, effects: {named}, dt_s={self.dt_s!r})"


def load_model(path: str | os.PathLike[str]) -> SavedModel:
    """Reads a model file (the module docs give the schema).

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
    return SavedModel.from_dict(doc, where)


def _kind(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def _required(doc: dict[str, Any], name: str, fail: _Fail) -> Any:
    if name not in doc:
        raise fail(name, "missing")
    return doc[name]


def _number(doc: dict[str, Any], name: str, fail: _Fail, prefix: str = "") -> float:
    if name not in doc:
        raise fail(prefix + name, "missing")
    value = doc[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise fail(prefix + name, f"expected a finite number, got {value!r}")
    return float(value)


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
