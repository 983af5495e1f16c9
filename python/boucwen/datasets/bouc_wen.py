"""The Bouc–Wen benchmark's training record (Noël & Schoukens, 2016), read from a data
directory (the package ships no data).

``train_multisine.csv`` in the folder :data:`FOLDER` of a data directory (the one named by
``BOUCWEN_DATA``, else ``../shared/data`` beside the repository, as
:mod:`boucwen.datasets`): columns ``t_s`` [s], ``force_N`` [N], ``displacement_m`` [m];
40 960 rows at 750 Hz, 5 periods of 8192 samples of a random-phase multisine from 5 to
150 Hz, 50 N RMS, made with the benchmark's simulator (distributed in forgi86/dynonet,
MIT licence © 2020 Marco Forgione; the folder's README and LICENSE say more).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..checks import FloatArray
from . import find_file

__all__ = ["FOLDER", "PERIOD", "TRAINING_FILE", "BenchmarkRecord", "find_training", "load_training"]

#: Folder of a data directory that holds the benchmark's files.
FOLDER = "bouc-wen-benchmark"
#: The training record's file.
TRAINING_FILE = "train_multisine.csv"
#: Samples per period of the training multisine.
PERIOD = 8192


@dataclass(frozen=True, eq=False)
class BenchmarkRecord:
    """A force–displacement record.

    Attributes:
        t: time [s].
        force: applied force F [N].
        y: measured displacement [m].
        dt: sampling interval [s]: the mean spacing of ``t`` (the file's times are
            rounded to 1e-8 s).
        path: the file read.
    """

    t: FloatArray
    force: FloatArray
    y: FloatArray
    dt: float
    path: Path


def find_training() -> Path:
    """The training record's file.

    Raises:
        DataNotFoundError: in neither data directory (the message names both).
    """
    return find_file(FOLDER, TRAINING_FILE, "the Bouc-Wen benchmark's training record")


def load_training(path: str | os.PathLike[str] | None = None) -> BenchmarkRecord:
    """Reads the training record (or a file of the same columns at ``path``).

    Raises:
        DataNotFoundError: ``path`` not given and the record is in no data directory.
        ValueError: the file does not hold the three columns ``t_s, force_N,
            displacement_m`` with at least two rows.
    """
    file = find_training() if path is None else Path(path)
    try:
        data = np.loadtxt(file, delimiter=",", skiprows=1, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise ValueError(f"{file}: not the comma-separated t_s, force_N, displacement_m columns: {exc}") from None
    if data.shape[1] != 3 or data.shape[0] < 2:
        raise ValueError(f"{file}: expected 3 columns and at least 2 rows, found shape {data.shape}")
    t = np.ascontiguousarray(data[:, 0])
    dt = float((t[-1] - t[0]) / (t.size - 1))
    return BenchmarkRecord(
        t=t, force=np.ascontiguousarray(data[:, 1]), y=np.ascontiguousarray(data[:, 2]), dt=dt, path=file
    )
