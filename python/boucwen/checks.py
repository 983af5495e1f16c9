"""Argument checks shared by the Python layer: one message per kind of mistake.

Each function returns the value in its working form (float64 array, float, int) or
raises ``TypeError`` (wrong kind of value) or a named ``ValueError`` (right kind, bad
value: :class:`boucwen.InvalidRecord` for a signal, :class:`boucwen.InvalidConfig` for
dt and the options) with a one-line message that names the argument.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._core import InvalidConfig, InvalidRecord

__all__ = ["FloatArray", "as_float_vector", "check_dt", "check_finite", "check_int", "check_number"]

#: A float64 NumPy array (the working type of every signal).
FloatArray = NDArray[np.float64]


def as_float_vector(values: Any, name: str) -> FloatArray:
    """``values`` as a contiguous, finite, non-empty 1-D float64 array (copied only when needed)."""
    try:
        a = np.asarray(values)
    except Exception as exc:  # ragged nested sequences and the like
        raise InvalidRecord(f"{name} cannot be read as an array: {exc}") from None
    if a.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {a.dtype}")
    if a.ndim != 1:
        shape = "a scalar" if a.ndim == 0 else f"shape {a.shape}"
        raise InvalidRecord(f"{name} must be 1-D, got {shape}")
    if a.size == 0:
        raise InvalidRecord(f"{name} is empty")
    out: FloatArray = np.ascontiguousarray(a, dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:
        k = int(bad[0])
        raise InvalidRecord(f"{name}[{k}] is {out[k]}; all samples must be finite ({bad.size} non-finite)")
    return out


def _is_real(value: Any) -> bool:
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.integer, np.floating))


def check_dt(dt: Any) -> float:
    """The sampling interval dt [s] as a float: a real number, finite and > 0."""
    if not _is_real(dt):
        raise TypeError(f"dt must be a real number, got {type(dt).__name__}")
    value = float(dt)
    if not math.isfinite(value) or value <= 0.0:
        raise InvalidConfig(f"dt must be finite and > 0 s, got {value}")
    return value


def check_finite(name: str, value: Any) -> float:
    """A real value (``bool`` is not one) that is finite, as a float."""
    if not _is_real(value):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    out = float(value)
    if not math.isfinite(out):
        raise InvalidConfig(f"{name} must be finite, got {out}")
    return out


def check_int(name: str, value: Any, low: int, high: int | None = None) -> int:
    """An integer option (``bool`` is not one) within ``low`` … ``high`` (no upper limit if None)."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if ok and value >= low and (high is None or value <= high):
        return int(value)
    wanted = f">= {low}" if high is None else f"in {low}…{high}"
    raise InvalidConfig(f"{name} must be an integer {wanted}, got {value!r}")


def check_number(name: str, value: Any, low: float, high: float) -> float:
    """A real option (``bool`` is not one) within [``low``, ``high``]."""
    if _is_real(value) and low <= value <= high:
        return float(value)
    raise InvalidConfig(f"{name} must be a number in [{low}, {high}], got {value!r}")
