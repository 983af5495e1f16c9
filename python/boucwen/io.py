"""Reading and writing measured records.

A record is a uniformly sampled pair of signals: the voltage ``u`` [V] applied to
(or commanded for) the actuator and the displacement ``x`` [µm] it produced,
with the sample times ``t`` [s].

CSV format read by :func:`read_csv`:

* UTF-8 text, comma-separated, one header line, then one row per sample;
* the header names the columns. The time [s], voltage [V] and displacement [µm] are
  recognised in any order and case, with or without their unit (``t_s``, ``u [V]``,
  ``x (um)``): time ``t``, ``time``; voltage ``u``, ``v``, ``voltage``; displacement
  ``x``, ``displacement``, ``disp``, ``pos``, ``position`` (:data:`COLUMN_NAMES`); a
  recognised name in another unit (``t_ms``, ``x_nm``) is an error, as are two columns
  for one quantity. A record of a mechanical structure names a **force** as its input
  (``force``, ``force_N``, ``Force [N]``: it takes the voltage's place, in N) and may give
  its displacement in m (``displacement_m``, as the Bouc–Wen benchmark's records do):
  that column is read in µm (× 1e6), and ``meta["read_units"]`` says so.
  ``columns=("T", "U", "X")`` (``--columns T,U,X``) names them instead, ``("U", "X")``
  for a record without time. Other columns are ignored;
* a file without a header line (``numpy.savetxt`` output, a logger's export: numbers
  separated by commas, or by spaces or tabs) is read with ``columns`` as 1-based
  positions, ``"2,4,3"`` (``--columns 2,4,3``: time, voltage, displacement), ``"4,3"``
  with ``dt``; without ``columns`` it is an error that says so. Positions work on a file
  with a header too;
* a record without a time column takes its sampling interval from ``dt``;
* every field of the columns read is a finite decimal number;
* at least 3 rows, the time strictly increasing and uniformly sampled — or, with
  ``resample=DT``, put on a uniform grid of step DT [s] from its first sample: u held
  from the last sample at or before each grid time (zero-order hold), x interpolated
  linearly; ``meta["resampled"]`` says how much the steps varied.

Uniform sampling means that every step ``t[k+1] - t[k]`` lies within
``1e-3·dt + 1e-8·max|t|`` of the mean step ``dt = (t[-1] - t[0]) / (N - 1)``.
The first term allows the jitter of a real clock, the second the rounding of
time stamps printed with 9 significant digits (as :func:`write_csv` does).

Every failure of a file raises :class:`boucwen.InvalidRecord` (a ``ValueError``)
with a one-line message that names the file and, where it applies, the line and
column; a bad option (``dt``, ``resample``) raises :class:`boucwen.InvalidConfig`.
"""

from __future__ import annotations

import csv
import hashlib
import math
import os
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._core import InvalidConfig, InvalidRecord
from .checks import FloatArray, check_dt
from .record import Record, validate_samples

# Record and validate_samples live in boucwen.record; they are importable from here too.
__all__ = [
    "COLUMN_NAMES",
    "REQUIRED_COLUMNS",
    "Record",
    "jsonable",
    "read_csv",
    "read_signal",
    "resample_samples",
    "sampling_interval",
    "sha256_file",
    "validate_samples",
    "write_csv",
]

#: Columns :func:`read_csv` needs: time [s], voltage [V], displacement [µm].
REQUIRED_COLUMNS = ("t", "u", "x")

#: Per column: the names recognised (any case), the units accepted after them and what
#: the column holds.
COLUMN_NAMES: dict[str, tuple[tuple[str, ...], tuple[str, ...], str]] = {
    "t": (("t", "time"), ("s", "sec"), "time [s]"),
    "u": (("u", "v", "voltage", "force"), ("v", "volt", "volts", "n", "newton", "newtons"), "voltage [V]"),
    "x": (
        ("x", "displacement", "disp", "pos", "position"),
        ("um", "µm", "μm", "micron", "microns"),
        "displacement [µm]",
    ),
}
# Units a recognised name may carry that the record cannot take as they are.
_OTHER_UNITS = {
    "t": ("ms", "us", "µs", "μs", "ns", "min", "h"),
    "u": ("mv", "kv", "µv", "uv"),
    "x": ("m", "mm", "cm", "nm", "pm"),
}
# A name and an optional unit: "x", "x_um", "x [um]", "x (um)", "x/um".
_NAME_UNIT = re.compile(r"^(?P<name>.+?)(?:\s*[\[(]\s*(?P<a>[^\])]*?)\s*[\])]|\s*[_/ ]\s*(?P<b>[^_/ ]+))?$")

#: Relative tolerance on the sampling step (see the module docs).
STEP_RTOL = 1e-3
#: Tolerance on the step relative to the largest |t| (9-digit time stamps).
STAMP_RTOL = 1e-8


# --------------------------------------------------------------------------- CSV


def _fail(path: Path, message: str, line: int | None = None) -> InvalidRecord:
    where = f"{path}: line {line}: " if line is not None else f"{path}: "
    return InvalidRecord(where + message)


def _parse_number(text: str) -> float:
    """float(text) without Python's extras (digit underscores)."""
    if "_" in text:
        raise ValueError(text)
    return float(text)


def _role(header_name: str) -> tuple[str | None, str | None]:
    """(column it is, None) for a recognised name, (column, its unit) for a recognised
    name in a unit the record cannot take, (None, None) for another column."""
    match = _NAME_UNIT.match(header_name.strip().lower())
    if match is None:  # pragma: no cover - the pattern matches every non-empty name
        return None, None
    whole = header_name.strip().lower()
    name, unit = match["name"], match["a"] if match["a"] is not None else match["b"]
    for key, (names, units, _) in COLUMN_NAMES.items():
        if whole in names or (name in names and unit in units):
            return key, None
        if name in names and unit in _OTHER_UNITS[key]:
            return key, unit
    return None, None


def _positions(names: list[str]) -> list[int] | None:
    """The 1-based column positions ``names`` spell, as 0-based indices; None if they are not all whole numbers."""
    if not all(n.isdigit() for n in names):
        return None
    return [int(n) - 1 for n in names]


def _column_list(path: Path, columns: Any, keys: tuple[str, ...]) -> list[str]:
    """The entries of ``columns`` (``"T,U,X"`` or a sequence), one per key of ``keys``, or without time."""
    names = [c.strip() for c in columns.split(",")] if isinstance(columns, str) else [str(c).strip() for c in columns]
    if len(names) not in (len(keys) - 1, len(keys)) or not all(names):
        spelled = ",".join(k.upper() for k in keys)
        raise _fail(path, f"columns must name {spelled} (or {spelled[2:]} without time), got {columns!r}")
    return names


def _given_columns(
    path: Path, header: list[str] | None, width: int, columns: Any, header_no: int, keys: tuple[str, ...]
) -> dict[str, int]:
    """Indices of the columns named by ``columns`` (``(T, U, X)`` or ``(U, X)``; generally
    one per key of ``keys`` or one fewer, without time): header names, or 1-based positions
    among the file's ``width`` columns (the only choice for a file without a header,
    ``header`` None)."""
    names = _column_list(path, columns, keys)
    chosen = keys[len(keys) - len(names) :]
    positions = _positions(names)
    if header is None or (positions is not None and not any(n in header for n in names)):
        if positions is None:
            raise _fail(
                path,
                f"has no header line, so columns (--columns) are 1-based positions such as 2,4,3; got {columns!r}",
            )
        bad = [n for n, i in zip(names, positions) if not 0 <= i < width]
        if bad:
            raise _fail(path, f"column position {bad[0]} (--columns) is not within the file's {width} columns")
        if len(set(positions)) != len(positions):
            raise _fail(path, f"columns (--columns) {columns!r} name one position twice")
        return dict(zip(chosen, positions))
    found = ", ".join(repr(h) for h in header)
    cols = {}
    for key, name in zip(chosen, names):
        hits = [i for i, h in enumerate(header) if h == name] or [
            i for i, h in enumerate(header) if h.lower() == name.lower()
        ]
        if len(hits) != 1:
            what = "is not in" if not hits else f"appears {len(hits)} times in"
            raise _fail(
                path, f"column {name!r} named by columns (--columns) {what} the header (found: {found})", header_no
            )
        cols[key] = hits[0]
    return cols


def _spelled(keys: tuple[str, ...]) -> str:
    """``T,U,X`` for the keys ``("t", "u", "x")``."""
    return ",".join(k.upper() for k in keys)


def force_record(header: list[str]) -> bool:
    """The header names a force [N] as the input (``force``, ``force_N``, ``Force [N]``):
    a record of a mechanical structure, whose displacement may be in m (SI, as the
    Bouc–Wen benchmark's records are)."""
    return any(
        (m := _NAME_UNIT.match(h.strip().lower())) is not None and m["name"] == "force" and _role(h)[0] == "u"
        for h in header
    )


def _recognised_columns(
    path: Path, header: list[str], header_no: int, keys: tuple[str, ...] = REQUIRED_COLUMNS
) -> dict[str, int]:
    """Indices of the columns of ``keys`` (time, voltage, displacement) recognised in the header."""
    hits: dict[str, list[int]] = {key: [] for key in keys}
    in_metres = force_record(header)
    for i, name in enumerate(header):
        key, unit = _role(name)
        if key not in hits:
            continue
        if unit is not None and not (in_metres and key == "x" and unit == "m"):
            raise _fail(
                path,
                f"column {name!r} is in {unit}; boucwen takes the {COLUMN_NAMES[key][2]}: convert it, "
                f"or name the columns with --columns {_spelled(keys)} (Python: columns=)",
                header_no,
            )
        hits[key].append(i)
    for key, idx in hits.items():
        if len(idx) > 1:
            names = [header[i] for i in idx]
            what = (
                f"column {names[0]!r} appears {len(idx)} times in the header"
                if len(set(names)) == 1
                else f"columns {', '.join(repr(n) for n in names)} all name the {COLUMN_NAMES[key][2]}"
            )
            raise _fail(path, f"{what}; name the columns with --columns {_spelled(keys)} (Python: columns=)", header_no)
    missing = [key for key in keys if key != "t" and not hits[key]]
    if missing:
        found = ", ".join(repr(h) for h in header)
        spelled = "; ".join(f"{key}: {', '.join(COLUMN_NAMES[key][0])}" for key in missing)
        raise _fail(
            path,
            f"missing column{'s' if len(missing) > 1 else ''} {', '.join(repr(m) for m in missing)} "
            f"(found: {found}; recognised, any case, with or without a unit: {spelled}; "
            f"or name the columns with --columns {_spelled(keys)})",
            header_no,
        )
    return {key: idx[0] for key, idx in hits.items() if idx}


def read_csv(
    path: str | os.PathLike[str],
    *,
    columns: str | tuple[str, ...] | list[str] | None = None,
    dt: float | None = None,
    resample: float | None = None,
) -> Record:
    """Reads a measured record from a CSV file (format in the module docs).

    Args:
        path: file to read.
        columns: the names of the time, voltage and displacement columns, ``(T, U, X)``
            or ``"T,U,X"``, or ``(U, X)`` for a record without time (exact names, else
            any case), or their 1-based positions (``"2,4,3"``; the only way to read a
            file without a header line); default: recognised from the header
            (:data:`COLUMN_NAMES`).
        dt: sampling interval [s] of a record without a time column.
        resample: step [s] of a uniform grid to put the record on (u held, x
            interpolated linearly), for non-uniform time stamps.

    Returns:
        A :class:`Record` with ``t`` [s], ``u`` [V], ``x`` [µm], the mean step ``dt``
        [s], ``name`` = the file name without extension and ``meta`` =
        ``{"path": ..., "columns": [...]}`` (the header; None without one), with
        ``"read": {"t": ..., "u": ..., "x": ...}`` (the header names read, or the
        positions ``"column 2"`` of a file without a header; ``t`` None without a time
        column) and, when resampled, ``"resampled"`` (:func:`resample`).

    Raises:
        InvalidRecord: for every problem with the file, naming the file and, where it
            applies, the line (1 = header) and column.
        InvalidConfig: for bad options (both are ``ValueError``).
    """
    if resample is not None:
        try:
            resample = check_dt(resample)
        except (TypeError, ValueError):
            raise InvalidConfig(f"resample must be a step in s, finite and > 0, got {resample!r}") from None
    table = _read_table(Path(path), REQUIRED_COLUMNS, columns, dt)
    path = table.path
    u, x, meta = table.values["u"], table.values["x"], table.meta
    read_x = (meta.get("read") or {}).get("x")
    if columns is None and isinstance(read_x, str) and _role(read_x) == ("x", "m"):
        # A force record's displacement in m (force_record): the record holds µm.
        x = x * 1e6
        meta["read_units"] = {"u": "N", "x": "m, read as µm (× 1e6)"}
    if table.t is None:
        return Record(
            t=np.arange(u.size, dtype=np.float64) * table.dt, u=u, x=x, dt=table.dt, name=path.stem, meta=meta
        )
    t = table.t
    step, problem = sampling_interval(t)
    if problem is not None and (resample is None or step == 0.0):
        k, message = problem
        hint = "; put it on a uniform grid with --resample DT (Python: resample=DT) [s]" if step > 0.0 else ""
        raise _fail(path, message + hint, table.line_nos[k])
    if resample is not None:
        try:
            t, u, x, meta["resampled"] = resample_samples(t, u, x, resample)
        except ValueError as exc:
            raise _fail(path, str(exc)) from None
        step = resample
    return Record(t=t, u=u, x=x, dt=step, name=path.stem, meta=meta)


def read_signal(
    path: str | os.PathLike[str],
    quantity: str,
    *,
    columns: str | tuple[str, ...] | list[str] | None = None,
    dt: float | None = None,
) -> tuple[FloatArray, FloatArray, float, dict[str, Any]]:
    """Reads one signal with its time from a CSV file: a voltage ``u`` [V] to apply or a
    desired displacement ``x`` [µm] to follow, read like :func:`read_csv` reads a record
    (the same header names, units and checks; ``columns`` ``(T, U)``/``(T, X)`` by name or
    1-based position, ``(U,)``/``(X,)`` with ``dt``; other columns ignored).

    Args:
        path: file to read.
        quantity: ``"u"`` or ``"x"``.
        columns: as for :func:`read_csv`, two entries (time, signal) or one (with ``dt``).
        dt: sampling interval [s] of a file without a time column.

    Returns:
        ``(t, values, dt, meta)``: times [s] from the file (or ``k·dt``), the signal, the
        sampling interval [s] and ``meta`` as :func:`read_csv`'s.

    Raises:
        InvalidRecord: every problem with the file; InvalidConfig: a bad ``dt``.
    """
    if quantity not in ("u", "x"):
        raise InvalidConfig(f"quantity must be 'u' or 'x', got {quantity!r}")
    table = _read_table(Path(path), ("t", quantity), columns, dt)
    values = table.values[quantity]
    if table.t is None:
        return np.arange(values.size, dtype=np.float64) * table.dt, values, table.dt, table.meta
    step, problem = sampling_interval(table.t)
    if problem is not None:
        raise _fail(table.path, problem[1], table.line_nos[problem[0]])
    return table.t, values, step, table.meta


@dataclass(frozen=True)
class _Table:
    """The columns read from a file: ``t`` (None without a time column, then ``dt``
    given), the other quantities by key, the file line of each row and the meta."""

    path: Path
    t: FloatArray | None
    values: dict[str, FloatArray]
    dt: float
    line_nos: list[int]
    meta: dict[str, Any]


def _read_table(path: Path, keys: tuple[str, ...], columns: Any, dt: float | None) -> _Table:
    """The columns of ``keys`` (``"t"`` first) of the CSV file ``path``, checked as the module docs say."""
    if dt is not None:
        dt = check_dt(dt)
    if not path.exists():
        raise InvalidRecord(f"no such file: {path}")
    if path.is_dir():
        raise _fail(path, "is a directory, not a CSV file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise _fail(path, f"not UTF-8 text (byte {exc.start})") from None
    except OSError as exc:
        raise _fail(path, f"cannot be read: {exc.strerror or exc}") from None

    lines = text.splitlines()
    first = next((i for i, s in enumerate(lines) if s.strip()), None)
    if first is None:
        raise _fail(path, f"empty file, expected a header line such as '{_spelled(keys).lower()}'")
    header_line = lines[first]
    header_no = first + 1
    numbers = re.split(r"[,;\s]+", header_line.strip())
    headerless = all(_is_number(h) for h in numbers)
    if headerless:
        if columns is None:
            raise _fail(
                path,
                f"no header line: line {header_no} holds {len(numbers)} number(s); name the columns by "
                f"1-based position with --columns (e.g. --columns {','.join(str(i + 1) for i in range(len(keys)))} "
                f"for {_spelled(keys)}; Python: columns=), or add a first line naming the comma-separated "
                f"columns (e.g. {_spelled(keys).lower()})",
                header_no,
            )
        if ";" in header_line:
            raise _fail(path, "numbers are separated by ';'; columns must be separated by ',', spaces or tabs")
        split = _comma_fields if "," in header_line else _blank_fields
        width = len(split(header_line))
        cols = _given_columns(path, None, width, columns, header_no, keys)
        body = [(i + 1, s) for i, s in enumerate(lines) if i >= first and s.strip()]
        header: list[str] = [f"column {i + 1}" for i in range(width)]
        rows_fields: Iterable[tuple[int, list[str]]] = ((n, split(s)) for n, s in body)
    else:
        if "," not in header_line:
            for sep, label in ((";", "';'"), ("\t", "tabs")):
                if sep in header_line:
                    raise _fail(
                        path,
                        f"header {header_line.strip()!r} is separated by {label}; columns must be separated by ','",
                        header_no,
                    )
            if len(header_line.split()) > 1:
                raise _fail(
                    path,
                    f"header {header_line.strip()!r} is separated by spaces; columns must be separated by ','",
                    header_no,
                )
        header = [name.strip() for name in next(csv.reader([header_line]))]
        width = len(header)
        cols = (
            _recognised_columns(path, header, header_no, keys)
            if columns is None
            else _given_columns(path, header, width, columns, header_no, keys)
        )
        body = [(i + 1, s) for i, s in enumerate(lines) if i > first and s.strip()]
        rows_fields = zip((n for n, _ in body), csv.reader(s for _, s in body))
    if "t" in cols and dt is not None:
        raise _fail(path, f"has a time column {header[cols['t']]!r}; dt (--dt) is for a record without one", header_no)
    if "t" not in cols and dt is None:
        if headerless:
            raise _fail(
                path,
                f"columns (--columns) {columns!r} name no time column; "
                "give the sampling interval with --dt DT (Python: dt=) [s]",
            )
        raise _fail(
            path,
            "no time column (t, time, t_s, … in any case); give the sampling interval with --dt DT "
            f"(Python: dt=) [s], or name the columns with --columns {_spelled(keys)}",
            header_no,
        )
    read = [key for key in keys if key in cols]
    sep_word = "fields as on the first line" if headerless else "comma-separated fields as in the header"

    rows: list[list[float]] = []
    line_nos: list[int] = []
    for line_no, fields in rows_fields:
        if len(fields) != width:
            hint = ""
            if len(fields) == 1 and (";" in fields[0] or "\t" in fields[0]):
                hint = " (the row seems to use ';' or tabs; columns must be separated by ',')"
            raise _fail(path, f"expected {width} {sep_word}, found {len(fields)}{hint}", line_no)
        values = []
        for key in read:
            name, raw = header[cols[key]], fields[cols[key]].strip()
            try:
                value = _parse_number(raw)
            except ValueError:
                raise _fail(path, f"column {name!r}: {raw!r} is not a number", line_no) from None
            if not math.isfinite(value):
                raise _fail(path, f"column {name!r}: non-finite value {raw!r}", line_no)
            values.append(value)
        rows.append(values)
        line_nos.append(line_no)

    if not rows:
        raise _fail(path, "header only, no data rows")
    if len(rows) < 3:
        raise _fail(path, f"only {len(rows)} data row{'s' if len(rows) > 1 else ''}, at least 3 are needed")

    data = np.array(rows, dtype=np.float64)
    meta: dict[str, Any] = {
        "path": str(path),
        "columns": None if headerless else header,
        "read": {key: header[cols[key]] if key in cols else None for key in keys},
    }
    by_key = {key: data[:, j].copy() for j, key in enumerate(read)}
    t = by_key.pop("t", None)
    return _Table(path, t, by_key, 0.0 if dt is None else dt, line_nos, meta)


def _comma_fields(line: str) -> list[str]:
    return line.split(",")


def _blank_fields(line: str) -> list[str]:
    return line.split()


def _is_number(text: str) -> bool:
    try:
        _parse_number(text.strip())
    except ValueError:
        return False
    return True


def resample_samples(
    t: np.ndarray, u: np.ndarray, x: np.ndarray, step: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """Puts samples at strictly increasing times ``t`` [s] on the uniform grid
    ``t[0] + k·step`` (k = 0, 1, … while within ``t[-1]``): ``u`` held from the last sample
    at or before each grid time (zero-order hold), ``x`` interpolated linearly.

    Returns:
        ``(t, u, x, info)`` on the grid; ``info`` = ``{"dt_s", "samples_before",
        "samples", "step_min_s", "step_max_s", "step_mean_s", "step_spread"}`` where the
        spread is (largest − smallest step) / mean step of the samples given.

    Raises:
        ValueError: ``step`` not finite and > 0, or so long that the grid has fewer than 3
            samples; ``t`` not strictly increasing.
    """
    step = check_dt(step)
    steps = np.diff(t)
    if np.any(steps <= 0.0):
        raise InvalidRecord("time not strictly increasing: cannot resample")
    span = float(t[-1] - t[0])
    n = math.floor(span / step * (1.0 + 1e-12)) + 1
    if n < 3:
        raise InvalidConfig(f"resample step {step:g} s leaves {n} sample(s) over the record's {span:g} s, at least 3")
    grid = t[0] + np.arange(n) * step
    # The sample at or before each grid time (a grid time a rounding below a sample's is at it).
    held = np.clip(np.searchsorted(t, grid + 1e-9 * step, side="right") - 1, 0, t.size - 1)
    mean = span / (t.size - 1)
    info = {
        "dt_s": step,
        "samples_before": int(t.size),
        "samples": n,
        "step_min_s": float(steps.min()),
        "step_max_s": float(steps.max()),
        "step_mean_s": mean,
        "step_spread": float((steps.max() - steps.min()) / mean),
    }
    return grid, np.ascontiguousarray(u[held]), np.interp(grid, t, x), info


def sampling_interval(t: np.ndarray) -> tuple[float, tuple[int, str] | None]:
    """The mean step of sample times and, if they are not uniformly sampled, why.

    Args:
        t: sample times [s], finite, 1-D, at least 2 samples.

    Returns:
        ``(dt, problem)``: the mean step ``dt = (t[-1] - t[0]) / (N - 1)`` [s] and
        ``None`` when ``t`` is strictly increasing and uniform within the tolerance of
        the module docs; otherwise ``problem = (k, message)`` with ``k`` the index of
        the first offending sample and a one-line message.
    """
    steps = np.diff(t)
    bad = np.flatnonzero(steps <= 0.0)
    if bad.size:
        k = int(bad[0])
        return 0.0, (k + 1, f"time not strictly increasing: t = {t[k + 1]!r} s after t = {t[k]!r} s")
    dt = float((t[-1] - t[0]) / (t.size - 1))
    tol = STEP_RTOL * dt + STAMP_RTOL * float(np.max(np.abs(t)))
    dev = np.abs(steps - dt)
    worst = int(np.argmax(dev))
    if dev[worst] > tol:
        return dt, (
            worst + 1,
            f"non-uniform sampling: steps from {steps.min():.6g} s to {steps.max():.6g} s around the "
            f"mean step {dt:.6g} s (spread {100.0 * (steps.max() - steps.min()) / dt:.3g}% of it; "
            f"step {steps[worst]:.9g} s here is {100.0 * dev[worst] / dt:.3g}% off, "
            f"tolerance {100.0 * tol / dt:.3g}%)",
        )
    return dt, None


def write_csv(path: str | os.PathLike[str], columns: Mapping[str, Any], *, digits: int = 9) -> None:
    """Writes equal-length 1-D columns as CSV: a header line, then rows formatted ``%.9g``.

    Args:
        path: file to create or overwrite.
        columns: ``{name: values}`` in the order the columns should appear, e.g.
            ``{"t": t, "u": u, "x": x}``. Names must be non-empty and must not contain
            commas, quotes or line breaks.
        digits: significant digits of each value (17 reads back every float64 exactly).

    Raises:
        ValueError: no columns, bad names, columns not 1-D or of different lengths.
        TypeError: non-numeric column data.
    """
    if not columns:
        raise ValueError("write_csv needs at least one column")
    names = list(columns)
    arrays = []
    for name in names:
        if not isinstance(name, str) or not name.strip() or any(c in name for c in ',"\r\n'):
            raise ValueError(
                f"bad column name {name!r}: must be a non-empty string without commas, quotes or line breaks"
            )
        a = np.asarray(columns[name])
        if a.dtype.kind not in "biuf":
            raise TypeError(f"column {name!r} must hold real numbers, got dtype {a.dtype}")
        if a.ndim != 1:
            raise ValueError(f"column {name!r} must be 1-D, got shape {a.shape}")
        arrays.append(a.astype(np.float64))
    lengths = {a.size for a in arrays}
    if len(lengths) != 1:
        sizes = ", ".join(f"{n}: {a.size}" for n, a in zip(names, arrays))
        raise ValueError(f"columns must have the same length ({sizes})")
    table = np.column_stack(arrays)
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(names) + "\n")
        np.savetxt(fh, table, fmt=f"%.{int(digits)}g", delimiter=",")


def sha256_file(path: str | os.PathLike[str]) -> str:
    """The SHA-256 of a file's bytes, as 64 hex digits (what a result records of the file it came from)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def jsonable(obj: Any) -> Any:
    """Replaces numpy scalars and non-finite floats (→ None), and objects with a
    ``to_dict`` method by its result, so that json.dumps works."""
    if hasattr(obj, "to_dict") and callable(obj.to_dict):
        return jsonable(obj.to_dict())
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj
