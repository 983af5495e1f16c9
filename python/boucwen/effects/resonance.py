"""``resonance``: second-order mechanical dynamics between the stack and the sensor."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray
from scipy.signal import detrend

from ..checks import FloatArray
from ..metrics import spectrum
from .base import Context, Effect, Start, simulate_chain

__all__ = ["FN_MAX_NYQUIST_FRACTION", "ZETA_BOUNDS", "Resonance"]

#: Bounds on the damping ratio ζ [-] during a fit. Above 1 the second-order element
#: has two real poles and no peak: that is a lag, not a resonance, and the diagnosis
#: must not call it one.
ZETA_BOUNDS = (1e-3, 1.0)
#: fn is kept below this fraction of the sampling rate (Nyquist = 0.5).
FN_MAX_NYQUIST_FRACTION = 0.45
#: Damping ratios started at the peak of the current residual's spectrum (a lightly
#: damped mode rings at its own frequency; the grid's nearest point may be a few
#: tenths of an octave away, too far for a sharp peak to be found from there).
PEAK_ZETAS = (0.03, 0.1)
#: The stretch [s] of the residual where a burst of ringing is looked for (a mode of
#: a few hundred Hz damped by ζ ≈ 0.05 has died out within it).
BURST_S = 0.02
#: A bin of the input's spectrum this many times its median is one of the input's lines.
INPUT_LINE = 10.0


def residual_peaks_hz(at: Start) -> list[float]:
    """Where a mode may ring [Hz], from the current model's residual r: the largest peak
    of r's spectrum over the whole record (Welch, segments of 0.25 s), away from the
    input's own lines (bins where the input's spectrum stands :data:`INPUT_LINE` × above
    its median: what the model misses there follows the input, and a mode rings at its
    own frequency); and the largest peak of r over the :data:`BURST_S` stretch where r's
    energy is largest (ringing after a step or a sharp start dies out within it, and a
    whole-record spectrum averages it away). Both above 2 % of the sampling rate and
    below :data:`FN_MAX_NYQUIST_FRACTION` of it; none when the model cannot be simulated
    or the record is too short."""
    rec = at.record
    xs = simulate_chain(at.params, at.effects, rec.u, rec.dt, at.h0)
    if xs is None or rec.u.size < 64:
        return []
    r = rec.x - xs
    band = (0.02 / rec.dt, FN_MAX_NYQUIST_FRACTION / rec.dt)
    f, pxx = spectrum(r, rec.dt)
    _, puu = spectrum(rec.u, rec.dt)
    sel = _in_band(f, band)
    if np.any(sel):
        sel &= ~(puu > INPUT_LINE * np.median(puu[sel]))
    peaks = (_largest_hz(f, pxx, sel), _burst_peak_hz(r, rec.dt, band))
    return list(dict.fromkeys(p for p in peaks if p is not None))


def _burst_peak_hz(r: FloatArray, dt: float, band: tuple[float, float]) -> float | None:
    """The largest peak within ``band`` [Hz] of the periodogram of ``r`` over the
    :data:`BURST_S` stretch (at least 64 samples) of largest energy, less its linear
    trend, zero-padded to 8× its length."""
    n = max(64, round(BURST_S / dt))
    if r.size < n:
        return None
    running = np.concatenate(([0.0], np.cumsum(r * r)))
    k = int(np.argmax(running[n:] - running[:-n]))
    f = np.fft.rfftfreq(8 * n, dt).astype(np.float64)
    power = np.abs(np.fft.rfft(detrend(r[k : k + n]), 8 * n)) ** 2
    return _largest_hz(f, power, _in_band(f, band))


def _in_band(f: FloatArray, band: tuple[float, float]) -> NDArray[np.bool_]:
    """Where the frequencies ``f`` [Hz] lie strictly within ``band`` [Hz]."""
    inside: NDArray[np.bool_] = (f > band[0]) & (f < band[1])
    return inside


def _largest_hz(f: FloatArray, power: FloatArray, keep: NDArray[np.bool_]) -> float | None:
    """The frequency [Hz] of the largest ``power`` where ``keep``; None where none is kept."""
    return float(f[keep][int(np.argmax(power[keep]))]) if np.any(keep) else None


@dataclass(frozen=True)
class Resonance(Effect):
    """A second-order low-pass of unit static gain from the stack's displacement y [µm]
    to what the sensor sees, z [µm]:

        z̈ + 2ζω·ż + ω²·z = ω²·y,     ω = 2π·fn

    A fit varies ln fn and ln ζ (which keep them positive), fn from two cycles per
    record length to :data:`FN_MAX_NYQUIST_FRACTION` of the sampling rate, ζ within
    :data:`ZETA_BOUNDS`.

    Attributes:
        fn_hz: natural frequency fn [Hz] (finite, > 0; below the Nyquist frequency
            1/(2·dt) of the record it is simulated on).
        zeta: damping ratio ζ [-] (finite, > 0).
    """

    name: ClassVar[str] = "resonance"
    signature: ClassVar[str | None] = "peak"
    substepped: ClassVar[bool] = True
    #: A second-order low-pass has a peak only for ζ below 1/√2; without one it is a lag
    #: shape the other effects describe.
    PEAK_ZETA: ClassVar[float] = 1.0 / math.sqrt(2.0)
    fn_hz: float
    zeta: float

    def unknowns(self) -> tuple[str, ...]:
        return ("ln_fn", "ln_zeta")

    def pack(self) -> tuple[float, ...]:
        return (math.log(self.fn_hz), math.log(self.zeta))

    def unpack(self, values: Sequence[float]) -> Resonance:
        return replace(self, fn_hz=math.exp(values[0]), zeta=math.exp(values[1]))

    def bounds(self, context: Context) -> tuple[tuple[float, float], ...]:
        fn = (math.log(2.0 / context.duration_s), math.log(FN_MAX_NYQUIST_FRACTION / context.dt))
        return (fn, (math.log(ZETA_BOUNDS[0]), math.log(ZETA_BOUNDS[1])))

    def typical(self, context: Context, span_u: float, span_x: float) -> tuple[float, ...]:
        return (1.0, 1.0)

    def rejects(self) -> str | None:
        """A fitted mode without a peak (ζ ≥ 1/√2) is no candidate."""
        if self.zeta >= self.PEAK_ZETA:
            return f"no resonance peak: fitted zeta {self.zeta:.3g} ≥ 1/√2"
        return None

    @classmethod
    def starts(cls, at: Start) -> list[Resonance]:
        dt, duration = at.record.dt, at.record.duration_s
        fns = np.geomspace(5.0 / duration, FN_MAX_NYQUIST_FRACTION * 0.9 / dt, 16)
        pairs = [(float(f), z) for f in fns for z in (0.03, 0.15, 0.5)]
        pairs.append((FN_MAX_NYQUIST_FRACTION * 0.98 / dt, 0.7))  # the mildest resonance
        pairs += [(peak, z) for peak in residual_peaks_hz(at) for z in PEAK_ZETAS]
        return [cls(fn_hz=f, zeta=z) for f, z in pairs]
