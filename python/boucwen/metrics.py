"""Error measures of a residual (e.g. x − x̂ [µm]); the result has the unit of the input.
Also its power spectrum as the residual analyses read it (:func:`spectrum`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.signal import welch

__all__ = ["max_abs", "rms", "spectrum"]


def rms(values: ArrayLike) -> float:
    """Root mean square of ``values`` (0.0 for an empty array)."""
    v = np.asarray(values, dtype=np.float64)
    return float(np.sqrt(np.mean(v**2))) if v.size else 0.0


def max_abs(values: ArrayLike) -> float:
    """Largest absolute value of ``values`` (0.0 for an empty array)."""
    v = np.asarray(values, dtype=np.float64)
    return float(np.max(np.abs(v))) if v.size else 0.0


def spectrum(values: ArrayLike, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch power spectral density of ``values`` less their mean, sampled every ``dt``
    [s], in segments of 0.25 s (at least 64 samples, at most all of them): the
    frequencies [Hz] and the density [unit²/Hz]. Raises ``ValueError`` when there are too
    few samples for a segment."""
    v = np.asarray(values, dtype=np.float64)
    f, pxx = welch(v - v.mean(), fs=1.0 / dt, nperseg=min(v.size, max(64, int(0.25 / dt))))
    return f, pxx
