"""Reading and writing measured records.

A record is a uniformly sampled pair of signals: the voltage ``u`` [V] applied to
(or commanded for) the actuator and the displacement ``x`` [µm] it produced,
with the sample times ``t`` [s].

CSV format read by :func:`read_csv`:

* UTF-8 text, comma-separated, one header line, then one row per sample;
* the header names the columns; ``t``, ``u`` and ``x`` must be present (any order,
  names compared after stripping spaces, case-sensitive), other columns are ignored;
* every field of the three columns is a finite decimal number;
* at least 3 rows, ``t`` strictly increasing and uniformly sampled.

Uniform sampling means that every step ``t[k+1] - t[k]`` lies within
``1e-3·dt + 1e-8·max|t|`` of the mean step ``dt = (t[-1] - t[0]) / (N - 1)``.
The first term allows the jitter of a real clock, the second the rounding of
time stamps printed with 9 significant digits (as :func:`write_csv` does).

Every failure raises :class:`ValueError` with a one-line message that names the
file and, where it applies, the line and column.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .record import Record, validate_samples

# Record and validate_samples live in boucwen.record; they are importable from here too.
__all__ = ["REQUIRED_COLUMNS", "Record", "read_csv", "sampling_interval", "validate_samples", "write_csv"]

#: Columns :func:`read_csv` needs: time [s], voltage [V], displacement [µm].
REQUIRED_COLUMNS = ("t", "u", "x")

#: Relative tolerance on the sampling step (see the module docs).
STEP_RTOL = 1e-3
#: Tolerance on the step relative to the largest |t| (9-digit time stamps).
STAMP_RTOL = 1e-8


# --------------------------------------------------------------------------- CSV


def _fail(path: Path, message: str, line: int | None = None) -> ValueError:
    where = f"{path}: line {line}: " if line is not None else f"{path}: "
    return ValueError(where + message)


def _parse_number(text: str) -> float:
    """float(text) without Python's extras (digit underscores)."""
    if "_" in text:
        raise ValueError(text)
    return float(text)


def read_csv(path: str | os.PathLike[str]) -> Record:
    """Reads a measured record from a CSV file (format in the module docs).

    Args:
        path: file to read.

    Returns:
        A :class:`Record` with ``t`` [s], ``u`` [V], ``x`` [µm], the mean step ``dt``
        [s], ``name`` = the file name without extension and ``meta`` =
        ``{"path": ..., "columns": [...]}``.

    Raises:
        ValueError: for every problem with the file, naming the file and, where it
            applies, the line (1 = header) and column.
    """
    path = Path(path)
    if not path.exists():
        raise ValueError(f"no such file: {path}")
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
        raise _fail(path, "empty file, expected a header line such as 't,u,x'")
    header_line = lines[first]
    header_no = first + 1
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
    for name in REQUIRED_COLUMNS:
        if header.count(name) > 1:
            raise _fail(path, f"column {name!r} appears {header.count(name)} times in the header", header_no)
    missing = [name for name in REQUIRED_COLUMNS if name not in header]
    if missing:
        found = ", ".join(repr(h) for h in header)
        raise _fail(
            path,
            f"missing column{'s' if len(missing) > 1 else ''} {', '.join(repr(m) for m in missing)} (found: {found})",
            header_no,
        )
    cols = {name: header.index(name) for name in REQUIRED_COLUMNS}
    width = len(header)

    rows: list[tuple[float, float, float]] = []
    line_nos: list[int] = []
    body = [(i + 1, s) for i, s in enumerate(lines) if i > first and s.strip()]
    for line_no, fields in zip((n for n, _ in body), csv.reader(s for _, s in body)):
        if len(fields) != width:
            hint = ""
            if len(fields) == 1 and (";" in fields[0] or "\t" in fields[0]):
                hint = " (the row seems to use ';' or tabs; columns must be separated by ',')"
            raise _fail(
                path, f"expected {width} comma-separated fields as in the header, found {len(fields)}{hint}", line_no
            )
        values = []
        for name in REQUIRED_COLUMNS:
            raw = fields[cols[name]].strip()
            try:
                value = _parse_number(raw)
            except ValueError:
                raise _fail(path, f"column {name!r}: {raw!r} is not a number", line_no) from None
            if not math.isfinite(value):
                raise _fail(path, f"column {name!r}: non-finite value {raw!r}", line_no)
            values.append(value)
        rows.append((values[0], values[1], values[2]))
        line_nos.append(line_no)

    if not rows:
        raise _fail(path, "header only, no data rows")
    if len(rows) < 3:
        raise _fail(path, f"only {len(rows)} data row{'s' if len(rows) > 1 else ''}, at least 3 are needed")

    data = np.array(rows, dtype=np.float64)
    t, u, x = data[:, 0].copy(), data[:, 1].copy(), data[:, 2].copy()
    dt, problem = sampling_interval(t)
    if problem is not None:
        k, message = problem
        raise _fail(path, message, line_nos[k])
    return Record(t=t, u=u, x=x, dt=dt, name=path.stem, meta={"path": str(path), "columns": header})


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
            f"non-uniform sampling: step {steps[worst]:.9g} s differs from the "
            f"mean step {dt:.9g} s by {100.0 * dev[worst] / dt:.3g}% "
            f"(tolerance {100.0 * tol / dt:.3g}%)",
        )
    return dt, None


def write_csv(path: str | os.PathLike[str], columns: Mapping[str, Any]) -> None:
    """Writes equal-length 1-D columns as CSV: a header line, then rows formatted ``%.9g``.

    Args:
        path: file to create or overwrite.
        columns: ``{name: values}`` in the order the columns should appear, e.g.
            ``{"t": t, "u": u, "x": x}``. Names must be non-empty and must not contain
            commas, quotes or line breaks.

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
        np.savetxt(fh, table, fmt="%.9g", delimiter=",")
