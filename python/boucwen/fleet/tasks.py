"""The per-record task: load one record, fit or diagnose it, return one row.

:func:`run_task` is a pure function of its arguments (it reads the record, writes
nothing) and never raises for a bad record: whatever goes wrong becomes a row with
``status = "error"`` and the message, so the rest of the fleet completes.

Columns of a row (:data:`ROW_COLUMNS`; units in the names or below):

* ``channel``, ``origin``, ``row``, ``col``: which record, from where, where on the grid;
* ``kind``: ``"fit"`` (:func:`boucwen.fit`) or ``"diagnose"`` (:func:`boucwen.diagnose`);
* ``status``: ``"ok"``; ``"not_converged"`` (fit: the optimiser stopped early, the
  values are still there); ``"error"`` (the record or the model failed; ``error``
  holds the message); ``"failed"`` is set by the driver when the task itself never
  returned (e.g. its worker died every time it ran it);
* ``samples``, ``dt_s``: record length and sampling interval [s];
* ``kv`` [µm/V], ``x0`` [µm], ``A`` [µm/V], ``beta``, ``gamma`` [µm^(1−n)/V], ``n`` [-],
  ``delta`` [µm/(V·s)], ``h0_um``: the base model's parameters (for ``diagnose``: those
  of the model with its effects);
* ``rms_before_um``, ``max_before_um``, ``rms_after_um``, ``max_after_um``: output error
  [µm] before and after. For ``fit``, *before* is the best straight line x ≈ k·u + c
  (no hysteresis) and *after* the fitted Bouc–Wen model; for ``diagnose``, *before*
  is the base model and *after* the model with the effects it added;
* ``effects``: the effects the diagnosis added, comma-separated (``""`` for none or for
  ``fit``); ``unexplained``: what the diagnosis left unexplained, as JSON text, when
  the installed :class:`boucwen.Diagnosis` reports it;
* ``success``, ``nfev``: the fit's convergence flag and simulation count;
* ``elapsed_s``: wall time of the task [s]; ``cpu_s``: CPU time its worker process spent
  meanwhile [s] (below ``elapsed_s`` when other work shares the cores); ``worker``:
  ``host:pid`` that ran it;
  ``error``: the message of an error row (``""`` otherwise).

The row's ``detail`` entry holds the full JSON report (:meth:`boucwen.FitResult.to_dict`
or :meth:`boucwen.Diagnosis.to_dict`); it goes to the per-record JSON, not the table.
"""

from __future__ import annotations

import json
import os
import socket
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .. import Params, diagnose, fit
from ..io import Record
from ..io import jsonable as _jsonable
from .source import RecordRef, load_record

__all__ = [
    "ERROR_COLUMNS",
    "KINDS",
    "PARAM_COLUMNS",
    "ROW_COLUMNS",
    "TaskOptions",
    "empty_row",
    "error_message",
    "run_task",
]

#: What a task can do with a record.
KINDS = ("fit", "diagnose")
#: Parameter columns, in :class:`boucwen.Params` order.
PARAM_COLUMNS: tuple[str, ...] = tuple(Params.names)
#: Error columns [µm].
ERROR_COLUMNS = ("rms_before_um", "max_before_um", "rms_after_um", "max_after_um")
#: Every column of a row, in table order (``detail`` is not a column).
ROW_COLUMNS: tuple[str, ...] = (
    "channel",
    "row",
    "col",
    "kind",
    "status",
    *PARAM_COLUMNS,
    "h0_um",
    *ERROR_COLUMNS,
    "effects",
    "unexplained",
    "success",
    "nfev",
    "samples",
    "dt_s",
    "elapsed_s",
    "cpu_s",
    "worker",
    "origin",
    "error",
)


@dataclass(frozen=True)
class TaskOptions:
    """What to do with each record.

    Attributes:
        kind: ``"fit"`` or ``"diagnose"``.
        seed: seed of the fit's random starts (same seed, same result).
        threads: threads of the fit's finite-difference Jacobian, per task. 1 (the
            default) because the fleet is parallel across records: one task per core
            beats one record spread over several threads, and more threads per task
            on top of one task per core would only oversubscribe the cores.
    """

    kind: str = "fit"
    seed: int = 0
    threads: int = 1

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        for name in ("seed", "threads"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < (1 if name == "threads" else 0):
                raise ValueError(f"{name} must be an integer >= {1 if name == 'threads' else 0}, got {value!r}")

    def to_dict(self) -> dict[str, Any]:
        """The options as plain values (they are part of each result's key)."""
        return asdict(self)


def error_message(exc: BaseException) -> str:
    """One line: the message of a ValueError/TypeError, else the type and the message."""
    text = " ".join(str(exc).split())
    if isinstance(exc, (ValueError, TypeError)) and text:
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _line_errors(record: Record) -> tuple[float, float]:
    """RMS and max error [µm] of the least-squares straight line x ≈ k·u + c."""
    basis = np.column_stack([record.u, np.ones_like(record.u)])
    coef, *_ = np.linalg.lstsq(basis, record.x, rcond=None)
    err = record.x - basis @ coef
    return float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err)))


def _fit_columns(record: Record, options: TaskOptions) -> dict[str, Any]:
    result = fit(record.u, record.x, record.dt, seed=options.seed, workers=options.threads)
    rms_line, max_line = _line_errors(record)
    return {
        "status": "ok" if result.success else "not_converged",
        **result.params.to_dict(),
        "h0_um": result.h0,
        "rms_before_um": rms_line,
        "max_before_um": max_line,
        "rms_after_um": result.rms_um,
        "max_after_um": result.max_um,
        "success": result.success,
        "nfev": result.nfev,
        "error": "" if result.success else result.message,
        "detail": _jsonable(result.to_dict()),
    }


def _diagnose_columns(record: Record, options: TaskOptions) -> dict[str, Any]:
    report = diagnose(record.u, record.x, record.dt, seed=options.seed, workers=options.threads)
    detail = _jsonable(report.to_dict())
    # The diagnosis may report what it left unexplained (a newer boucwen); keep it when it does.
    unexplained = getattr(report, "unexplained", None)
    if unexplained is not None:
        detail.setdefault("unexplained", _jsonable(unexplained))
    base = report.params.to_dict()
    return {
        "status": "ok",
        **{name: base.get(name) for name in PARAM_COLUMNS},
        "h0_um": report.h0_um,
        "rms_before_um": report.rms_before_um,
        "max_before_um": report.max_before_um,
        "rms_after_um": report.rms_after_um,
        "max_after_um": report.max_after_um,
        "effects": ",".join(report.effects),
        "unexplained": None if unexplained is None else json.dumps(_jsonable(unexplained), sort_keys=True),
        "success": True,
        "detail": detail,
    }


def empty_row(ref: RecordRef, options: TaskOptions) -> dict[str, Any]:
    """A row with every column, the record's identity filled in and no results."""
    row: dict[str, Any] = dict.fromkeys(ROW_COLUMNS)
    row.update(
        channel=ref.channel,
        origin=ref.origin,
        row=ref.row,
        col=ref.col,
        kind=options.kind,
        effects="",
        error="",
        detail=None,
    )
    return row


def run_task(ref: RecordRef, options: TaskOptions) -> dict[str, Any]:
    """Fits or diagnoses one record; returns its row (module docs). Never raises for bad data."""
    started, cpu_started = time.perf_counter(), time.process_time()
    row = empty_row(ref, options)
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    try:
        record = load_record(ref)
        row.update(samples=len(record), dt_s=record.dt)
        row.update(_fit_columns(record, options) if options.kind == "fit" else _diagnose_columns(record, options))
    except Exception as exc:  # a bad record (or a model failure) is a row, never a lost fleet
        row.update(status="error", error=error_message(exc))
    row["elapsed_s"] = time.perf_counter() - started
    row["cpu_s"] = time.process_time() - cpu_started
    return row
