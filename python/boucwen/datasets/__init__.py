"""Measured piezo records, read from a data directory (the package ships no data).

Available records (see :func:`names`):

``"micromanipulator"``
    ``Model_Vi_Do.dat``: a piezoelectric micromanipulator driven by a 1 Hz sine,
    8027 samples at 200 Hz (about 40 s). ``u`` is the actuator input command [V]
    (0 … 3.6 V; the amplifier gain to the stack is not stated), ``x`` the
    capacitive-sensor displacement [µm] (about −123 … −74 µm).

``"micromanipulator_compensated"``
    ``Test_Vi_Do_Di.dat``: the same actuator with the authors' inverse hysteresis
    compensation in the loop, 14155 samples at 200 Hz. ``u`` is the compensator's
    command [V], ``x`` the displacement [µm], ``meta["desired"]`` the desired
    displacement [µm] (±20 µm). The sensor reading appears one sample late.

Both come from Y. N. Aye and W. T. Ang (2018), MIT licence © 2019 Yan Naing Aye; the
files sit unchanged, with their README and LICENSE (``meta["licence_text"]``), in the
folder :data:`FOLDER` of a data directory: the one named by the environment variable
:data:`ENV_VAR` (``BOUCWEN_DATA``), else ``../shared/data`` beside the repository
(the nearest folder above the working directory or the package holding a
``pyproject.toml``), when it exists. :func:`find` raises :class:`DataNotFoundError`,
naming both places, when neither holds the record.

The Bouc–Wen benchmark's training record (Noël & Schoukens, 2016) is read the same way
from the folder :data:`BOUC_WEN_FOLDER` (:func:`load_bouc_wen`): ``train_multisine.csv``,
columns ``t_s`` [s], ``force_N`` [N], ``displacement_m`` [m]; 40 960 rows at 750 Hz, 5
periods of 8192 samples of a random-phase multisine from 5 to 150 Hz, 50 N RMS, made with
the benchmark's simulator (distributed in forgi86/dynonet, MIT licence © 2020 Marco
Forgione; the folder's README and LICENSE say more).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..checks import FloatArray
from ..record import Record

__all__ = [
    "BOUC_WEN_FILE",
    "BOUC_WEN_FOLDER",
    "BOUC_WEN_PERIOD",
    "ENV_VAR",
    "FOLDER",
    "BenchmarkRecord",
    "DataNotFoundError",
    "available",
    "data_dirs",
    "find",
    "find_bouc_wen",
    "find_file",
    "load",
    "load_bouc_wen",
    "name_of_file",
    "names",
]

#: Environment variable naming the data directory.
ENV_VAR = "BOUCWEN_DATA"
#: Folder of a data directory that holds the micromanipulator files.
FOLDER = "yan9a-piezo-micromanipulator"
#: Folder of a data directory that holds the Bouc–Wen benchmark's files.
BOUC_WEN_FOLDER = "bouc-wen-benchmark"
#: The Bouc–Wen benchmark's training record.
BOUC_WEN_FILE = "train_multisine.csv"
#: Samples per period of the Bouc–Wen benchmark's training multisine.
BOUC_WEN_PERIOD = 8192

_DT = 0.005  # s, 200 Hz
_SOURCE = "github.com/yan9a/DiscreteBacklashOperator, commit 79fd060, folder MatLabCode/DiscreteBacklashModel/"
_CITATION = (
    'Y. N. Aye and W. T. Ang, "A Discrete Backlash Operator for Identification and '
    'Compensation of Hysteresis and Non-linearity for Piezoelectric Micromanipulator", '
    "Int. Conf. on Science and Technology for Sustainable Development, Yangon, 2018."
)

# name -> (file, number of columns, description, extra notes)
_RECORDS = {
    "micromanipulator": (
        "Model_Vi_Do.dat",
        7,
        "piezoelectric micromanipulator, 1 Hz sine command, about 40 cycles",
        "start-up transient in the first cycle; the per-cycle mean of x drifts by about "
        "1.2 µm over the record (creep or drift)",
    ),
    "micromanipulator_compensated": (
        "Test_Vi_Do_Di.dat",
        11,
        "the same actuator with the authors' inverse hysteresis compensation in the loop",
        "the sensor reading appears one sample late (phase lag 1); meta['desired'] holds "
        "the desired displacement [µm] (file column 9)",
    ),
}


class DataNotFoundError(FileNotFoundError):
    """A record is in neither data directory (the message names both places)."""


def names() -> list[str]:
    """Names accepted by :func:`load`."""
    return list(_RECORDS)


def _shared_data_dir() -> Path:
    """``../shared/data`` beside the repository: the nearest folder holding a
    ``pyproject.toml`` above the working directory, else above this package."""
    for start in (Path.cwd(), Path(__file__).resolve().parent):
        for folder in (start, *start.parents):
            if (folder / "pyproject.toml").is_file():
                return folder.parent / "shared" / "data"
    return Path.cwd().parent / "shared" / "data"


def data_dirs() -> list[tuple[str, Path | None]]:
    """The places searched, in order: ``(label, folder)``, folder None when ``BOUCWEN_DATA`` is not set."""
    env = os.environ.get(ENV_VAR, "").strip()
    return [
        (f"${ENV_VAR}", Path(env).expanduser() if env else None),
        ("../shared/data beside the repository", _shared_data_dir()),
    ]


def find(name: str) -> Path:
    """The file of record ``name`` in the first data directory that holds it.

    Raises:
        ValueError: unknown name (the message lists the available names).
        DataNotFoundError: neither ``$BOUCWEN_DATA/<FOLDER>/`` nor
            ``../shared/data/<FOLDER>/`` holds the file (the message names both).
    """
    if name not in _RECORDS:
        raise ValueError(f"unknown dataset {name!r}; available: {', '.join(names())}")
    return find_file(FOLDER, _RECORDS[name][0], f"dataset {name!r}")


def find_file(folder: str, filename: str, what: str) -> Path:
    """The file ``folder/filename`` in the first data directory that holds it.

    Raises:
        DataNotFoundError: neither ``$BOUCWEN_DATA/<folder>/`` nor
            ``../shared/data/<folder>/`` holds the file (the message names both and
            starts with ``what``).
    """
    looked = []
    for label, base in data_dirs():
        if base is None:
            looked.append(f"{label}/{folder}/ ({ENV_VAR} not set)")
            continue
        path = base / folder / filename
        if path.is_file():
            return path
        looked.append(f"{label}/{folder}/ ({base / folder}: {'no such file' if base.is_dir() else 'no such folder'})")
    raise DataNotFoundError(
        f"{what} ({filename}) not found: looked in {' and in '.join(looked)}; "
        f"set {ENV_VAR} to a folder holding {folder}/{filename}"
    )


def available(name: str) -> bool:
    """Whether :func:`find` finds record ``name``."""
    try:
        find(name)
    except DataNotFoundError:
        return False
    return True


def name_of_file(path: str | os.PathLike[str]) -> str | None:
    """The name of the record whose file is ``path`` (by file name), or None."""
    filename = Path(path).name
    return next((name for name, spec in _RECORDS.items() if spec[0] == filename), None)


def load(name: str, path: str | os.PathLike[str] | None = None) -> Record:
    """Loads a measured record.

    Args:
        name: one of :func:`names`.
        path: the record's file; default :func:`find` ``(name)``. Its folder's
            ``LICENSE`` fills ``meta["licence_text"]`` (empty when absent).

    Returns:
        A :class:`~boucwen.record.Record` with ``t`` [s] (0, 0.005, …), ``u`` = file column 1
        (command [V]), ``x`` = file column 5 (displacement [µm]), ``dt`` = 0.005 s and
        ``meta`` with keys ``source``, ``file``, ``licence``, ``licence_text``,
        ``citation``, ``units``, ``description``, ``notes`` (and ``desired`` [µm] for
        ``"micromanipulator_compensated"``).

    Raises:
        ValueError: unknown name (the message lists the available names), or a file
            of another shape.
        DataNotFoundError: ``path`` not given and the record is in no data directory.
    """
    file = find(name) if path is None else Path(path)
    if name not in _RECORDS:  # a path was given with an unknown name
        raise ValueError(f"unknown dataset {name!r}; available: {', '.join(names())}")
    filename, ncols, description, notes = _RECORDS[name]
    try:
        data = np.loadtxt(file, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise ValueError(f"{file}: not the whitespace-separated numbers of {filename}: {exc}") from None
    if data.shape[1] != ncols:
        raise ValueError(f"{file}: expected the {ncols} columns of {filename}, found {data.shape[1]}")
    licence = file.parent / "LICENSE"
    t = np.arange(data.shape[0], dtype=np.float64) * _DT
    meta: dict[str, Any] = {
        "source": _SOURCE,
        "file": str(file),
        "licence": "MIT, Copyright (c) 2019 Yan Naing Aye",
        "licence_text": licence.read_text(encoding="utf-8") if licence.is_file() else "",
        "citation": _CITATION,
        "units": {
            "t": "s",
            "u": "V (actuator input command, before the amplifier)",
            "x": "µm (capacitive sensor)",
            "dt": "s",
        },
        "description": description,
        "notes": notes,
    }
    if name == "micromanipulator_compensated":
        meta["desired"] = np.ascontiguousarray(data[:, 8])
        meta["units"]["desired"] = "µm"
    return Record(t=t, u=data[:, 0], x=data[:, 4], dt=_DT, name=name, meta=meta)


@dataclass(frozen=True, eq=False)
class BenchmarkRecord:
    """A force–displacement record (:func:`load_bouc_wen`).

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


def find_bouc_wen() -> Path:
    """The training record's file.

    Raises:
        DataNotFoundError: in neither data directory (the message names both).
    """
    return find_file(BOUC_WEN_FOLDER, BOUC_WEN_FILE, "the Bouc-Wen benchmark's training record")


def load_bouc_wen(path: str | os.PathLike[str] | None = None) -> BenchmarkRecord:
    """Reads the training record (or a file of the same columns at ``path``).

    Raises:
        DataNotFoundError: ``path`` not given and the record is in no data directory.
        ValueError: the file does not hold the three columns ``t_s, force_N,
            displacement_m`` with at least two rows.
    """
    file = find_bouc_wen() if path is None else Path(path)
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
