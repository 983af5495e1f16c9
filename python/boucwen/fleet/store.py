"""The result folder of a fleet run: per-record JSON keyed by content, the table, atomic writes.

Layout of ``DIR``::

    DIR/records/<channel>.json   one per record: its row, its key and the full report
    DIR/results.parquet          the table, one row per record of the source
    DIR/results.csv              the same table as CSV
    DIR/outliers.csv             the flagged rows (see boucwen.fleet.outliers)
    DIR/fleet.png                the fleet figure (see boucwen.fleet.plots)
    DIR/run.json                 the last run: counts, wall time, records per second, cluster

A record's **key** is the SHA-256 of the task's options and the record's content hash
(:func:`result_key`). A record is *done* when its JSON exists, holds the same key and
a status other than ``"failed"`` (the task never returned, e.g. its worker died each
time): re-running the same command then skips it, so an interrupted run resumes where
it stopped. A changed record, or other options, give another key and a new result.

Every file is written **atomically** (:func:`atomic_write`): to a temporary file in the
same folder, flushed to disk, then renamed over the target, so a reader (or a run
killed in the middle) sees the old file or the new one, never a part of one.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Callable

import pandas as pd

from ..io import jsonable as _jsonable
from .source import RecordRef
from .tasks import ROW_COLUMNS, TaskOptions

__all__ = ["ResultStore", "atomic_write", "atomic_write_text", "file_name", "result_key"]

#: Version of the per-record JSON layout.
RECORD_FORMAT = 1


def atomic_write(path: str | os.PathLike[str], write: Callable[[Path], None]) -> None:
    """Calls ``write(tmp)`` on a temporary file beside ``path``, then renames it to ``path``.

    The temporary file keeps ``path``'s extension (writers that infer the format from it
    still work), is flushed to disk before the rename and removed if ``write`` fails.
    """
    target = Path(path)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Writes UTF-8 text atomically (:func:`atomic_write`)."""

    def write(tmp: Path) -> None:
        tmp.write_text(text, encoding="utf-8")

    atomic_write(path, write)


def result_key(ref: RecordRef, options: TaskOptions) -> str:
    """SHA-256 (hex) of the task options and the record's content: what a result is for."""
    text = json.dumps({"options": options.to_dict(), "content": ref.content_hash}, sort_keys=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def file_name(channel: str) -> str:
    """A file name for a channel: itself when it is plain, else a cleaned form plus a hash."""
    clean = re.sub(r"[^A-Za-z0-9._-]", "_", channel).lstrip(".") or "_"
    if clean == channel and len(clean) <= 120:
        return clean
    return f"{clean[:100]}-{hashlib.sha256(channel.encode('utf-8')).hexdigest()[:12]}"


class ResultStore:
    """The result folder ``DIR`` (module docs); creates it and ``DIR/records``."""

    def __init__(self, out: str | os.PathLike[str]):
        self.root = Path(out).expanduser()
        if self.root.exists() and not self.root.is_dir():
            raise ValueError(f"--out {self.root} exists and is not a folder")
        self.records = self.root / "records"
        self.records.mkdir(parents=True, exist_ok=True)

    def record_path(self, channel: str) -> Path:
        """Where the JSON of a channel goes."""
        return self.records / f"{file_name(channel)}.json"

    def read(self, channel: str) -> dict[str, Any] | None:
        """The stored JSON of a channel, or None when absent or unreadable."""
        path = self.record_path(channel)
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return doc if isinstance(doc, dict) else None

    def is_done(self, channel: str, key: str) -> bool:
        """True when the channel's stored result has this key and did not fail."""
        doc = self.read(channel)
        return doc is not None and doc.get("key") == key and doc.get("row", {}).get("status") != "failed"

    def write(self, row: dict[str, Any], key: str) -> None:
        """Stores one row (with its ``detail``) under its channel, atomically."""
        detail = row.get("detail")
        doc = {
            "format": RECORD_FORMAT,
            "key": key,
            "row": {c: row.get(c) for c in ROW_COLUMNS},
            "detail": detail,
        }
        text = json.dumps(_jsonable(doc), indent=1, allow_nan=False)
        atomic_write_text(self.record_path(row["channel"]), text + "\n")

    def table(self, channels: Iterable[str]) -> pd.DataFrame:
        """The stored rows of these channels, in this order (a channel without a result is left out)."""
        rows = []
        for channel in channels:
            doc = self.read(channel)
            if doc is not None and isinstance(doc.get("row"), dict):
                rows.append(doc["row"])
        table = pd.DataFrame(rows, columns=list(ROW_COLUMNS))
        for column in ("row", "col", "nfev", "samples"):
            table[column] = pd.array(table[column], dtype="Int64")
        table["success"] = pd.array(table["success"], dtype="boolean")
        for column in ("channel", "kind", "status", "effects", "unexplained", "worker", "origin", "error"):
            table[column] = table[column].astype(object)
        return table

    def write_table(self, table: pd.DataFrame, stem: str = "results") -> tuple[Path, Path]:
        """Writes ``stem.parquet`` and ``stem.csv`` atomically; returns their paths."""
        parquet, csv = self.root / f"{stem}.parquet", self.root / f"{stem}.csv"
        atomic_write(parquet, lambda tmp: table.to_parquet(tmp, index=False))
        atomic_write(csv, lambda tmp: table.to_csv(tmp, index=False))
        return parquet, csv
