"""Where a fleet's records come from, and how a worker gets one back.

A *source* is one of:

* a **folder**: every ``*.csv`` file directly in it is one record;
* a **glob** (a path with ``*``, ``?`` or ``[``; ``**`` descends into folders): every
  file it matches is one record;
* a **long table**: one CSV or Parquet file (``.csv``, ``.parquet``, ``.pq``) with the
  columns ``channel``, ``t``, ``u``, ``x`` (s, V, µm); the rows of one channel, in
  file order, are one record. Optional ``row`` and ``col`` columns place the channel
  on the mirror's grid. A single ``.csv`` file without a ``channel`` column is a
  fleet of one record.

A record file has the format of :func:`boucwen.io.read_csv` (header line, columns
``t,u,x``). The record's *channel* is the file's name without extension, or the
``channel`` value of the long table; channels must be unique within a source.

:func:`find_records` lists the records without checking their content: a bad record
(empty, NaN, wrong columns, non-uniform time) is found by :func:`load_record`, in the
worker, and becomes an error row. Only a source that cannot be read as a whole (no
such path, no records, a table without the needed columns, duplicate channels) raises.

Folder and glob records travel to the workers as paths, so with a remote scheduler the
workers must see the files at the same paths (a shared filesystem); the records of a
long table travel as arrays.

Every record carries the SHA-256 of its content (the file's bytes; for a table, the
``t, u, x`` values as float64), which keys its result: see :mod:`boucwen.fleet.store`.
"""

from __future__ import annotations

import glob
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

import numpy as np
import pandas as pd

from ..io import REQUIRED_COLUMNS, Record, read_csv, sampling_interval, sha256_file

__all__ = ["LAYOUT_COLUMNS", "TABLE_SUFFIXES", "RecordRef", "find_records", "load_record", "read_layout"]

#: File endings read as a long table.
TABLE_SUFFIXES = (".csv", ".parquet", ".pq")
#: Columns of a layout file (and the optional grid columns of a long table).
LAYOUT_COLUMNS = ("channel", "row", "col")

PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True, eq=False)
class RecordRef:
    """One record of a source, as the driver sends it to a worker.

    Attributes:
        channel: unique name of the record (file stem or the table's ``channel``).
        origin: where it comes from: the CSV path, or ``TABLE[channel=NAME]``.
        content_hash: SHA-256 (hex) of the record's content.
        path: the CSV file to read (folder and glob sources), else None.
        columns: ``{"t": [s], "u": [V], "x": [µm]}`` float64 arrays (long tables), else None.
        row, col: position on the mirror's grid (0-based), None when unknown.
    """

    channel: str
    origin: str
    content_hash: str
    path: str | None = None
    columns: dict[str, np.ndarray] | None = None
    row: int | None = None
    col: int | None = None


# --------------------------------------------------------------------------- listing


def _is_glob(text: str) -> bool:
    return any(c in text for c in "*?[")


def _has_channel_column(path: Path) -> bool:
    """True when the header line of a CSV file names a ``channel`` column."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            for line in fh:
                if line.strip():
                    return "channel" in (name.strip() for name in line.split(","))
    except (OSError, UnicodeDecodeError):
        return False  # not a table: read as a record, whose reader says what is wrong
    return False


def _file_refs(paths: list[Path], layout: dict[str, tuple[int, int]]) -> list[RecordRef]:
    seen: dict[str, Path] = {}
    refs = []
    for path in paths:
        channel = path.stem
        if channel in seen:
            raise ValueError(
                f"two records are named {channel!r}: {seen[channel]} and {path}; channel names must be unique"
            )
        seen[channel] = path
        row, col = layout.get(channel, (None, None))
        refs.append(
            RecordRef(
                channel=channel, origin=str(path), content_hash=sha256_file(path), path=str(path), row=row, col=col
            )
        )
    return refs


def _read_table(path: Path) -> pd.DataFrame:
    try:
        if path.suffix.lower() == ".csv":
            return pd.read_csv(path, skipinitialspace=True)
        return pd.read_parquet(path)
    except (OSError, ValueError, ImportError) as exc:
        raise ValueError(f"{path}: cannot be read as a table: {' '.join(str(exc).split())}") from None
    except Exception as exc:  # pyarrow's own errors (ArrowInvalid, ...) are not ValueErrors everywhere
        raise ValueError(f"{path}: cannot be read as a table: {type(exc).__name__}: {exc}") from None


def _grid_value(value: Any, what: str) -> int | None:
    if value is None or (isinstance(value, float) and np.isnan(value)) or value is pd.NA:
        return None
    number = float(value)
    if not number.is_integer() or number < 0:
        raise ValueError(f"{what} must be an integer >= 0, got {value!r}")
    return int(number)


def _table_refs(path: Path, table: pd.DataFrame, layout: dict[str, tuple[int, int]]) -> list[RecordRef]:
    table.columns = [str(c).strip() for c in table.columns]
    missing = [c for c in ("channel", *REQUIRED_COLUMNS) if c not in table.columns]
    if missing:
        found = ", ".join(repr(c) for c in table.columns)
        raise ValueError(f"{path}: a long table needs the columns channel, t, u, x; missing {missing} (found: {found})")
    if table["channel"].isna().any():
        first = int(np.flatnonzero(table["channel"].isna().to_numpy())[0])
        raise ValueError(f"{path}: row {first} has no channel")
    has_grid = "row" in table.columns and "col" in table.columns
    refs = []
    for channel, group in table.groupby(table["channel"].astype(str), sort=False):
        name = str(channel)
        columns = {c: pd.to_numeric(group[c], errors="coerce").to_numpy(dtype=np.float64) for c in REQUIRED_COLUMNS}
        digest = hashlib.sha256()
        for c in REQUIRED_COLUMNS:
            digest.update(np.ascontiguousarray(columns[c]).tobytes())
        row, col = layout.get(name, (None, None))
        if has_grid and row is None:
            row = _grid_value(group["row"].iloc[0], f"{path}: channel {name!r}: row")
            col = _grid_value(group["col"].iloc[0], f"{path}: channel {name!r}: col")
        refs.append(
            RecordRef(
                channel=name,
                origin=f"{path}[channel={name}]",
                content_hash=digest.hexdigest(),
                columns=columns,
                row=row,
                col=col,
            )
        )
    if not refs:
        raise ValueError(f"{path}: the table has no rows")
    return refs


def read_layout(path: PathLike) -> dict[str, tuple[int, int]]:
    """Reads a layout file: CSV with columns ``channel,row,col`` (grid position, 0-based).

    Returns:
        ``{channel: (row, col)}``.

    Raises:
        ValueError: unreadable file, missing columns, non-integer or negative positions,
            a channel listed twice, or two channels on one cell.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no such layout file: {path}")
    table = _read_table(path)
    table.columns = [str(c).strip() for c in table.columns]
    missing = [c for c in LAYOUT_COLUMNS if c not in table.columns]
    if missing:
        raise ValueError(f"{path}: a layout needs the columns channel, row, col; missing {missing}")
    layout: dict[str, tuple[int, int]] = {}
    cells: dict[tuple[int, int], str] = {}
    for k, (channel, row, col) in enumerate(zip(table["channel"].astype(str), table["row"], table["col"])):
        r = _grid_value(row, f"{path}: line {k + 2}: row")
        c = _grid_value(col, f"{path}: line {k + 2}: col")
        if r is None or c is None:
            raise ValueError(f"{path}: line {k + 2}: channel {channel!r} has no row or col")
        if channel in layout:
            raise ValueError(f"{path}: line {k + 2}: channel {channel!r} is listed twice")
        if (r, c) in cells:
            raise ValueError(f"{path}: line {k + 2}: channels {cells[(r, c)]!r} and {channel!r} share row {r}, col {c}")
        layout[channel] = (r, c)
        cells[(r, c)] = channel
    return layout


def find_records(source: PathLike, layout: PathLike | None = None) -> list[RecordRef]:
    """Lists the records of a source (see the module docs), with their content hashes.

    Args:
        source: a folder, a glob, or a long table (CSV or Parquet).
        layout: optional layout file (:func:`read_layout`) placing channels on the grid.

    Returns:
        One :class:`RecordRef` per record: sorted by path for folders and globs, in
        order of first appearance for a long table.

    Raises:
        ValueError: no such path, no records, an unreadable or incomplete table, or
            two records with the same channel.
    """
    text = os.fspath(source)
    grid = read_layout(layout) if layout is not None else {}
    path = Path(text).expanduser()
    if path.is_dir():
        files = sorted(p for p in path.glob("*.csv") if p.is_file())
        if not files:
            raise ValueError(f"no CSV records (*.csv) in the folder {path}")
        return _file_refs(files, grid)
    if path.is_file():
        if path.suffix.lower() not in TABLE_SUFFIXES:
            raise ValueError(f"{path}: expected a folder, a glob, or a table ending in {', '.join(TABLE_SUFFIXES)}")
        if path.suffix.lower() == ".csv" and not _has_channel_column(path):
            return _file_refs([path], grid)
        return _table_refs(path, _read_table(path), grid)
    if _is_glob(text):
        files = sorted(Path(p) for p in glob.glob(os.path.expanduser(text), recursive=True) if Path(p).is_file())
        if not files:
            raise ValueError(f"no file matches {text}")
        return _file_refs(files, grid)
    raise ValueError(f"no such folder or file: {path}")


# --------------------------------------------------------------------------- loading


def load_record(ref: RecordRef) -> Record:
    """The record behind a reference, checked as :func:`boucwen.io.read_csv` checks files.

    Raises:
        ValueError: the record is unreadable, empty, has missing columns, non-finite
            values, fewer than 3 samples or non-uniform time (the message names it).
    """
    if ref.path is not None:
        return read_csv(ref.path)
    if ref.columns is None:
        raise ValueError(f"{ref.origin}: the reference holds neither a path nor data")
    t, u, x = (ref.columns[c] for c in REQUIRED_COLUMNS)
    if t.size < 3:
        raise ValueError(f"{ref.origin}: only {t.size} samples, at least 3 are needed")
    for name, values in zip(REQUIRED_COLUMNS, (t, u, x)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise ValueError(
                f"{ref.origin}: column {name!r} is missing or not a finite number in sample {int(bad[0])} "
                f"({bad.size} of {values.size} samples)"
            )
    dt, problem = sampling_interval(t)
    if problem is not None:
        k, message = problem
        raise ValueError(f"{ref.origin}: sample {k}: {message}")
    return Record(t=t, u=u, x=x, dt=dt, name=ref.channel, meta={"origin": ref.origin})
