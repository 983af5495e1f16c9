"""Measured piezo records shipped with the package.

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

Both come from Y. N. Aye and W. T. Ang (2018), MIT licence © 2019 Yan Naing Aye;
the licence text is in ``meta["licence_text"]`` and the files sit unchanged in
``boucwen/datasets/yan9a_micromanipulator/`` with their README and LICENSE.
"""

from __future__ import annotations

from importlib import resources
from typing import Any

import numpy as np

from ..record import Record

__all__ = ["DATA_DIR", "load", "names"]

#: Folder (inside this package) that holds the micromanipulator files.
DATA_DIR = "yan9a_micromanipulator"

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


def names() -> list[str]:
    """Names accepted by :func:`load`."""
    return list(_RECORDS)


def _read_text(filename: str) -> str:
    return (resources.files(__name__) / DATA_DIR / filename).read_text(encoding="utf-8")


def load(name: str) -> Record:
    """Loads a shipped record.

    Args:
        name: one of :func:`names`.

    Returns:
        A :class:`~boucwen.record.Record` with ``t`` [s] (0, 0.005, …), ``u`` = file column 1
        (command [V]), ``x`` = file column 5 (displacement [µm]), ``dt`` = 0.005 s and
        ``meta`` with keys ``source``, ``file``, ``licence``, ``licence_text``,
        ``citation``, ``units``, ``description``, ``notes`` (and ``desired`` [µm] for
        ``"micromanipulator_compensated"``).

    Raises:
        ValueError: unknown name (the message lists the available names).
    """
    if name not in _RECORDS:
        raise ValueError(f"unknown dataset {name!r}; available: {', '.join(names())}")
    filename, ncols, description, notes = _RECORDS[name]
    with resources.as_file(resources.files(__name__) / DATA_DIR / filename) as path:
        data = np.loadtxt(path, dtype=np.float64, ndmin=2)
    if data.shape[1] != ncols:
        raise ValueError(f"{filename}: expected {ncols} columns, found {data.shape[1]}")
    t = np.arange(data.shape[0], dtype=np.float64) * _DT
    meta: dict[str, Any] = {
        "source": _SOURCE,
        "file": f"{DATA_DIR}/{filename}",
        "licence": "MIT, Copyright (c) 2019 Yan Naing Aye",
        "licence_text": _read_text("LICENSE"),
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
