"""Error measures of a residual (e.g. x − x̂ [µm]); the result has the unit of the input."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["max_abs", "rms"]


def rms(values: ArrayLike) -> float:
    """Root mean square of ``values`` (0.0 for an empty array)."""
    v = np.asarray(values, dtype=np.float64)
    return float(np.sqrt(np.mean(v**2))) if v.size else 0.0


def max_abs(values: ArrayLike) -> float:
    """Largest absolute value of ``values`` (0.0 for an empty array)."""
    v = np.asarray(values, dtype=np.float64)
    return float(np.max(np.abs(v))) if v.size else 0.0
