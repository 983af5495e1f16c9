"""The measurement chain around a model: what the input does between samples, and what
the logger does to the output before it is recorded.

A record holds the input and the output at the sample instants only. Between them the
rig set the input — a DAC's zero-order hold, a generator's smooth signal — and a model
integrated between the samples has to assume it; the logger's anti-alias or decimation
filter then shaped the output it recorded and may have delayed it. Both are part of the
model.

* The input between samples is chosen, not assumed (:data:`INPUT_CHOICES`): ``"hold"``
  (zero-order hold, a DAC), ``"linear"`` (a straight line between samples) or
  ``"bandlimited"`` (the band-limited signal through the samples: exactly the Fourier
  interpolation of a periodic record, else a Kaiser-windowed sinc whose error bound
  :func:`boucwen._core.bandlimited_error_bound` gives). The Rust core integrates both
  model classes under the choice, with the exact Jacobian
  (:class:`boucwen._core.InputPath`; :mod:`boucwen.oscillator`; the piezo model's
  ``reconstruction`` effect, :mod:`boucwen.effects.reconstruction`).
* The output end is an :class:`OutputFilter`, a FIR at the record's rate applied to the
  simulated output (and, being linear, to each column of its Jacobian).
  :func:`decimation_filter` gives the record-rate equivalent of a logger that samples
  faster and decimates through FIR filters, as the Bouc–Wen benchmark's simulator does
  (:func:`decimate_fir` is that decimation itself, for replicating such records).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._core import INPUT_CHOICES as _CHOICES
from ._core import InvalidConfig
from .checks import FloatArray, as_float_vector, check_int

__all__ = [
    "DECIMATION_BAND",
    "DECIMATION_HALF_WIDTH",
    "INPUT_CHOICES",
    "OutputFilter",
    "check_input",
    "decimate_fir",
    "decimation_filter",
    "fir_lowpass",
]

#: What the input does between samples: ``("hold", "linear", "bandlimited")``.
INPUT_CHOICES: tuple[str, ...] = tuple(_CHOICES)
#: The band [fraction of the record's rate] over which :func:`decimation_filter` matches
#: the decimation's response: 0.4 (0.8 of Nyquist; the benchmark's output has its
#: content below 300 Hz of 750 Hz, its force below 150 Hz).
DECIMATION_BAND = 0.4
#: Taps on either side of :func:`decimation_filter`'s centre: 24 match the benchmark's
#: decimation to 2.1e-9 over :data:`DECIMATION_BAND` (least squares; 16 taps: 5.5e-7).
DECIMATION_HALF_WIDTH = 24


def check_input(input: Any) -> str:
    """``input`` if it is one of :data:`INPUT_CHOICES`; :class:`boucwen.InvalidConfig` naming
    the choices otherwise."""
    if not isinstance(input, str) or input not in INPUT_CHOICES:
        raise InvalidConfig(f"input = {input!r}: what the input does between samples is one of {list(INPUT_CHOICES)}")
    return input


@dataclass(frozen=True)
class OutputFilter:
    """A FIR the logger applies to the output before recording it, at the record's rate:

        y_recorded[k] = Σⱼ taps[j] · y[k + j − center]

    The record is extended beyond its ends by point reflection about the end sample
    (2·y[0] − y[i], which keeps the value and the slope there). A filter whose taps are
    symmetric about ``center`` has no delay (a logger that compensates its filter's
    delay); any other delays the output by its group delay.

    Attributes:
        taps: the filter's taps (at least one, finite, summing to a non-zero gain).
        center: the index of the tap that weighs the sample itself (0 … len(taps) − 1).
        name: what it is, for reports.
    """

    taps: tuple[float, ...]
    center: int
    name: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        taps = as_float_vector(self.taps, "taps")
        object.__setattr__(self, "taps", tuple(float(v) for v in taps))
        object.__setattr__(self, "center", check_int("center", self.center, 0, taps.size - 1))
        if float(np.sum(taps)) == 0.0:
            raise InvalidConfig("taps: the filter's static gain (their sum) must not be 0")

    def apply(self, y: Any) -> FloatArray:
        """The recorded output of ``y`` (1-D), or of each column of a 2-D array (a
        Jacobian's, samples along axis 0), same shape."""
        a = np.asarray(y, dtype=np.float64)
        if a.ndim not in (1, 2) or a.shape[0] == 0:
            raise InvalidConfig(f"OutputFilter.apply takes samples along axis 0 (1-D or 2-D), got shape {a.shape}")
        taps = np.asarray(self.taps)
        before, after = self.center, taps.size - 1 - self.center
        n = a.shape[0]
        # Point reflection about the end samples, indices clamped for records shorter
        # than the filter.
        lo = np.clip(np.arange(before, 0, -1), 0, n - 1)
        hi = np.clip(n - 2 - np.arange(after), 0, n - 1)
        ext = np.concatenate([2.0 * a[:1] - a[lo], a, 2.0 * a[-1:] - a[hi]], axis=0)
        out = np.zeros_like(a)
        for j, t in enumerate(taps):
            out += t * ext[j : j + n]
        return out

    def gain(self, f_hz: Any, dt: float) -> FloatArray:
        """|H| at the frequencies ``f_hz`` [Hz] for samples ``dt`` [s] apart."""
        f = np.atleast_1d(np.asarray(f_hz, dtype=np.float64))
        n = np.arange(len(self.taps)) - self.center
        h = np.exp(-2j * np.pi * np.outer(f * dt, n)) @ np.asarray(self.taps)
        out: FloatArray = np.abs(h)
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"name", "taps", "center"}``."""
        return {"name": self.name, "taps": list(self.taps), "center": self.center}


def fir_lowpass(order: int, cutoff: float) -> FloatArray:
    """The linear-phase FIR of ``order`` (order + 1 taps) by the window method with a
    Hamming window, ``cutoff`` the −6 dB point as a fraction of the Nyquist frequency,
    scaled to a static gain of 1 (MATLAB's ``fir1(order, cutoff)``)."""
    order = check_int("order", order, 1)
    if not 0.0 < cutoff < 1.0:
        raise InvalidConfig(f"cutoff = {cutoff}: a fraction of the Nyquist frequency in (0, 1)")
    m = np.arange(order + 1) - order / 2.0
    ideal = cutoff * np.sinc(cutoff * m)
    taps = ideal * np.hamming(order + 1)
    out: FloatArray = taps / np.sum(taps)
    return out


def decimate_fir(x: Any, factor: int, order: int = 30) -> FloatArray:
    """``x`` decimated by ``factor`` through the FIR :func:`fir_lowpass` (``order``, cutoff
    1/factor of the Nyquist frequency) applied with its delay compensated, as MATLAB's
    ``decimate(x, factor, "fir")`` does: the record extended at both ends by point
    reflection, filtered, and every ``factor``-th sample kept from the first (output
    sample j is input sample j·factor, filtered)."""
    a = as_float_vector(x, "x")
    factor = check_int("factor", factor, 2)
    taps = fir_lowpass(order, 1.0 / factor)
    half = order // 2
    filt = OutputFilter(tuple(taps), half)
    out: FloatArray = filt.apply(a)[::factor].copy()
    return out


def decimation_filter(
    stages: Sequence[int],
    order: int = 30,
    *,
    band: float = DECIMATION_BAND,
    half_width: int = DECIMATION_HALF_WIDTH,
) -> OutputFilter:
    """The record-rate equivalent of a logger that samples ``prod(stages)`` times faster
    and decimates by each factor of ``stages`` in turn through :func:`decimate_fir`
    (``order``): the symmetric FIR of ``2·half_width + 1`` taps whose response matches,
    by least squares over 0 … ``band`` × the record's rate, the product of the stages'
    zero-phase responses there.

    The decimation's output is its response applied to the fast signal; where that signal
    has no content above ``band`` (the equivalent leaves what lies above unmatched), this
    filter applied to the record-rate samples gives it. For the Bouc–Wen benchmark
    (stages 2, 2, 5, order 30): 2.4e-4 less gain at 35 Hz, 1.3e-3 more at 150 Hz, −6 dB at
    375 Hz; matched to 2.1e-9 up to 300 Hz with the defaults.
    """
    factors = [check_int("stage", r, 2) for r in stages]
    if not factors:
        raise InvalidConfig("stages: at least one decimation factor")
    half_width = check_int("half_width", half_width, 1)
    if not 0.0 < band <= 0.5:
        raise InvalidConfig(f"band = {band}: a fraction of the record's rate in (0, 0.5]")
    nu = np.linspace(0.0, band, 40 * half_width + 1)
    response = np.ones_like(nu)
    rate = float(math.prod(factors))  # each stage's input rate, in units of the record's
    for r in factors:
        taps = fir_lowpass(order, 1.0 / r)
        offsets = np.arange(taps.size) - (taps.size - 1) / 2.0
        response *= np.cos(2.0 * np.pi * np.outer(nu / rate, offsets)) @ taps
        rate /= r
    n = np.arange(half_width + 1)
    basis = np.cos(2.0 * np.pi * np.outer(nu, n)) * np.where(n == 0, 1.0, 2.0)
    c = np.linalg.lstsq(basis, response, rcond=None)[0]
    taps = np.concatenate([c[:0:-1], c])
    label = f"decimation {' x '.join(str(r) for r in factors)} through FIR order {order}"
    return OutputFilter(tuple(float(v) for v in taps), half_width, label)
