"""A measured record, and the one place where a record is checked.

A record is a uniformly sampled pair of signals: the voltage ``u`` [V] applied to
(or commanded for) the actuator and the displacement ``x`` [µm] it produced, with
the sample times ``t`` [s] and the sampling interval ``dt`` [s].

Every public entry point that takes data (:func:`boucwen.fit`,
:func:`boucwen.effects.fit_extended`, :func:`boucwen.diagnose`,
:func:`boucwen.diagnosis.residual_evidence`) turns its ``(u, x, dt)`` into a
:class:`Record` with :func:`validate_record` once; the layers below take the
:class:`Record` and do not check the samples again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._core import InvalidRecord
from .checks import FloatArray, as_float_vector, check_dt

__all__ = ["REST_SIGMAS", "Onset", "Record", "motion_onset", "validate_record", "validate_samples"]

#: u has left the level it starts at once it differs from its first sample by more than
#: this many standard deviations σ of its noise: u_k − u_0 at rest has a standard
#: deviation of √2·σ, so 8σ is 5.7 of those, passed by Gaussian noise alone with a
#: probability of about 1e-8 per sample (a rest of 10⁶ samples is not cut short by it).
REST_SIGMAS = 8.0
#: The band never falls below this share of the largest |u|: a record read back from
#: a CSV file holds its values to 9 significant digits (:func:`boucwen.io.write_csv`),
#: and a change of u at that rounding is no motion.
REST_ROUNDING = 1e-6


def _checked_pair(u: Any, x: Any) -> tuple[FloatArray, FloatArray]:
    u_arr = as_float_vector(u, "u")
    x_arr = as_float_vector(x, "x")
    if u_arr.size != x_arr.size:
        raise InvalidRecord(f"u and x must have the same length, got {u_arr.size} and {x_arr.size}")
    return u_arr, x_arr


def _checked(u: Any, x: Any, dt: Any) -> tuple[FloatArray, FloatArray, float]:
    u_arr, x_arr = _checked_pair(u, x)
    return u_arr, x_arr, check_dt(dt)


@dataclass(frozen=True, eq=False)
class Record:
    """A uniformly sampled measurement; building one checks it.

    Attributes:
        t: sample times [s], float64, shape (N,).
        u: actuator voltage [V], float64, shape (N,), finite.
        x: actuator displacement [µm], float64, shape (N,), finite.
        dt: sampling interval [s] (finite, > 0).
        name: short label of the record.
        meta: free-form details (source, licence, units, extra signals).

    Raises:
        TypeError: non-numeric data or dt.
        InvalidRecord: arrays not 1-D, empty, of different lengths or not finite.
        InvalidConfig: dt not finite and > 0 (both are ``ValueError``).
    """

    t: FloatArray
    u: FloatArray
    x: FloatArray
    dt: float
    name: str = ""
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        u, x, dt = _checked(self.u, self.x, self.dt)
        t = as_float_vector(self.t, "t")
        if t.shape != u.shape:
            raise InvalidRecord(f"t has {t.size} samples but u and x have {u.size}")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "dt", dt)
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "meta", dict(self.meta))

    @classmethod
    def _of_checked(cls, t: FloatArray, u: FloatArray, x: FloatArray, dt: float, name: str = "") -> Record:
        """A record of arrays that are already known to be valid (no second check)."""
        rec = object.__new__(cls)
        for key, value in (("t", t), ("u", u), ("x", x), ("dt", dt), ("name", name), ("meta", {})):
            object.__setattr__(rec, key, value)
        return rec

    def __len__(self) -> int:
        return int(self.u.size)

    @property
    def sample_rate(self) -> float:
        """Sampling rate 1/dt [Hz]."""
        return 1.0 / self.dt

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample, (N − 1)·dt [s]."""
        return self.dt * (self.u.size - 1)

    def part(self, start: int, stop: int | None = None) -> Record:
        """Samples ``start`` … ``stop − 1`` (Python slice rules) as a record, without ``meta``.

        The arrays are views of this record's; the part is valid by construction and
        not checked again. Raises :class:`boucwen.InvalidRecord` if it would be empty.
        """
        sel = slice(start, stop)
        u = self.u[sel]
        if u.size == 0:
            raise InvalidRecord(f"samples {start}:{stop} of a record of {len(self)} are empty")
        return Record._of_checked(self.t[sel], u, self.x[sel], self.dt, self.name)

    def decimated(self, factor: int) -> Record:
        """Every ``factor``-th sample (from the first), sampled every ``factor``·dt [s];
        views of this record's arrays, not checked again."""
        q = int(factor)
        if q < 1:
            raise ValueError(f"factor must be >= 1, got {factor!r}")
        return Record._of_checked(self.t[::q], self.u[::q], self.x[::q], self.dt * q, self.name)

    def realigned(self, delay_samples: int) -> Record:
        """The record with a sensor delay of ``delay_samples`` (d ≥ 0) taken out: u[k] paired with x[k + d].

        The result is d samples shorter; its times are those of u.
        """
        d = int(delay_samples)
        if not 0 <= d < len(self):
            raise ValueError(f"delay_samples must be in 0…{len(self) - 1}, got {delay_samples!r}")
        n = len(self) - d
        return Record._of_checked(self.t[:n], self.u[:n], self.x[d:], self.dt, self.name)

    def __repr__(self) -> str:
        return (
            f"Record(name={self.name!r}, samples={len(self)}, dt={self.dt!r} s, "
            f"duration={(len(self) - 1) * self.dt:.6g} s)"
        )


@dataclass(frozen=True)
class Onset:
    """Where the voltage of a record starts to move (:func:`motion_onset`).

    Attributes:
        start: the last sample at the starting level before u leaves it (0 where u moves
            from the first sample on; the record's length where it never moves).
        band_v: half-width of the starting level [V]: u within ±band_v of its first
            sample is at rest.
        noise_v: the noise level σ of u the band is made of [V] (:data:`REST_SIGMAS`).
    """

    start: int
    band_v: float
    noise_v: float

    def moves(self, samples: int) -> bool:
        """Whether u leaves its starting level within a record of ``samples`` samples."""
        return self.start < samples


def motion_onset(u: Any) -> Onset:
    """Where a voltage record that may start at rest begins to move.

    The starting level is u's first sample; u has left it at the first sample that
    differs from it by more than :data:`REST_SIGMAS` times the noise level of u
    (:func:`boucwen.residual.noise.noise_level`, the MAD of u's differences, which a
    smooth excitation does not inflate) or by :data:`REST_ROUNDING` of the largest |u|,
    whichever is larger. The onset is the sample before that one, the last at rest, so a
    fit from it sees the state the rest left.

    Raises:
        TypeError, InvalidRecord: ``u`` is not a finite, non-empty 1-D array of numbers.
    """
    from .residual.noise import noise_level  # deferred: boucwen.residual imports this module

    arr = as_float_vector(u, "u")
    sigma = noise_level(arr).sigma_um if arr.size > 8 else 0.0
    band = max(REST_SIGMAS * sigma, REST_ROUNDING * float(np.max(np.abs(arr))))
    left = np.flatnonzero(np.abs(arr - arr[0]) > band)
    start = int(left[0]) - 1 if left.size else int(arr.size)
    return Onset(max(start, 0), band, sigma)


#: The voltage's travel is counted on u smoothed over this time [s]: a millisecond, above
#: the bandwidth of any actuator drive's noise and below every effect's time scale but a
#: delay's.
TRAVEL_SMOOTHING_S = 1e-3
#: Increments of the smoothed u within this many standard deviations of their noise are
#: rest (no travel).
TRAVEL_DEADBAND = 3.0


def travel_levels(record: Record) -> tuple[FloatArray, float]:
    """The voltage smoothed over :data:`TRAVEL_SMOOTHING_S` [V] and the least difference
    of two of its samples that is travel [V]: :data:`TRAVEL_DEADBAND` standard
    deviations of such a difference under u's noise alone. A u whose differences are
    mostly zero (a command held between steps) has no noise at the sample level."""
    from scipy.ndimage import uniform_filter1d

    from .residual.noise import noise_level  # deferred: boucwen.residual imports this module

    u = record.u
    m = max(1, round(TRAVEL_SMOOTHING_S / record.dt))
    smooth: FloatArray = uniform_filter1d(u, m, mode="nearest") if m > 1 else u
    level = noise_level(u) if u.size > 8 else None
    sigma = (level.sigma_um if level is not None and level.order > 0 else 0.0) * math.sqrt(2.0) / math.sqrt(m)
    return smooth, TRAVEL_DEADBAND * sigma


def travel_steps(record: Record) -> FloatArray:
    """The voltage's travel [V] from each sample to the next (n − 1 of them): the
    increments of u smoothed over :data:`TRAVEL_SMOOTHING_S`, those within
    :data:`TRAVEL_DEADBAND` noise standard deviations of u counted as none (a rest, a
    hold): :func:`travel_levels`."""
    smooth, least = travel_levels(record)
    steps = np.abs(np.diff(smooth))
    out: FloatArray = np.where(steps > least, steps, 0.0)
    return out


def validate_record(u: Any, x: Any, dt: Any, name: str = "") -> Record:
    """Checks ``(u, x, dt)`` and returns them as a :class:`Record` with times ``k·dt`` [s].

    Args:
        u: voltage samples [V], 1-D, real, finite.
        x: displacement samples [µm], 1-D, real, finite, same length as ``u``.
        dt: sampling interval [s], finite and > 0.
        name: label of the record.

    Raises:
        TypeError: non-numeric (or complex, boolean) data, or a non-numeric ``dt``.
        ValueError: wrong dimension, empty, different lengths, non-finite values,
            or ``dt`` not finite and positive.
    """
    u_arr, x_arr, step = _checked(u, x, dt)
    t = np.arange(u_arr.size, dtype=np.float64) * step
    return Record._of_checked(t, u_arr, x_arr, step, str(name))


def validate_samples(u: Any, x: Any, dt: Any = None) -> tuple[FloatArray, FloatArray]:
    """Checks a (u, x) pair and returns it as contiguous float64 arrays.

    Args:
        u: voltage samples [V], 1-D, real, finite.
        x: displacement samples [µm], 1-D, real, finite, same length as ``u``.
        dt: optional sampling interval [s]; if given it must be finite and > 0.

    Returns:
        ``(u, x)`` as C-contiguous float64 arrays (copies only when needed).

    Raises:
        TypeError: non-numeric (or complex, boolean) data, or a non-numeric ``dt``.
        ValueError: wrong dimension, empty, different lengths, non-finite values,
            or ``dt`` not finite and positive.
    """
    u_arr, x_arr = _checked_pair(u, x)
    if dt is not None:
        check_dt(dt)
    return u_arr, x_arr
