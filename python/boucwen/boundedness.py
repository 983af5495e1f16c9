"""The boundedness check of a returned model: driven over its record's range, does its
output stay within a stated multiple of the record's?

The admissible region (:mod:`boucwen.region`; docs/design.md, "The admissible region")
bounds h for every input of a given range and slowest slew; the check runs the model
itself, effects and all, on inputs the record's own limits allow but the record need
not have held:

* **sines** over the record's full voltage range at :data:`SINE_COUNT` frequencies,
  log-spaced from two periods per record length to the record's highest excited
  frequency (:func:`highest_excited_hz`);
* **steps** between the range's ends, held for an eighth of the record (long enough for
  creep to settle) and for :data:`FAST_HOLD_SAMPLES` samples;
* **triangles** over the full range at the record's fastest slew (its largest
  |Δu|/dt) and at the slowest full-range slew the record's length allows (one period
  over the record: the δ term is largest against the dissipation at low slew).

Each probe has the record's length and interval and starts from the model's own h0 at
the range's lower end. It passes where the model can be simulated and its displacement
stays within :data:`MULTIPLE` times the record's displacement range of the record's
centre, times the steady gain of the model's own linear dynamics at the probe's
fundamental (:attr:`Subject.gain`: a mode's resonance is bounded linear dynamics, not a
runaway). :func:`check` takes any model as a :class:`Subject`; :func:`check_model`
builds it for the extended model, :func:`check_oscillator` for the hysteretic
oscillator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ._core import EffectSet, Params
from .checks import FloatArray
from .effects.base import params_of, simulate_chain
from .metrics import spectrum
from .oscillator import OscillatorFit
from .oscillator import simulate as simulate_oscillator
from .record import Record

__all__ = [
    "FAST_HOLD_SAMPLES",
    "MULTIPLE",
    "SINE_COUNT",
    "Boundedness",
    "Probe",
    "Subject",
    "check",
    "check_model",
    "check_oscillator",
    "highest_excited_hz",
]

#: The displacement of a probe may leave the record's centre by at most this many times
#: the record's displacement range (times the model's linear gain at the probe's
#: fundamental). A bounded model driven over the record's voltage range moves over about
#: the record's range; where its gains cancel on the record (kv against A, kv against a
#: fast creep element) another input may part them, and a factor ten leaves room for
#: a cancellation to a fifth on either side. A model whose h runs away reaches the
#: core's limit of 10⁴ µm, about three orders above a piezo record's range.
MULTIPLE = 10.0
#: Frequencies of the full-range sines.
SINE_COUNT = 6
#: Hold of the fast steps [samples]: a step train at about the fastest rate a record of
#: this interval can hold a level.
FAST_HOLD_SAMPLES = 10
#: The highest excited frequency is where the input's spectrum has gathered this share
#: of its power: the rest is the tail of its edges and its noise.
EXCITED_SHARE = 0.99


@dataclass(frozen=True)
class Subject:
    """A model as the check drives it.

    Attributes:
        simulate: voltage u [V] (the record's interval) → displacement [µm], or None
            where it cannot be simulated.
        gain: frequency [Hz] → the steady gain [-] of the model's own linear dynamics
            there relative to its static gain (1 for a model without modes).
    """

    simulate: Callable[[FloatArray], FloatArray | None]
    gain: Callable[[float], float]


@dataclass(frozen=True)
class Probe:
    """One input of the check and what the model did on it.

    Attributes:
        name: what the input is (``"sine 12.5 Hz"``, ``"steps 10 samples"``,
            ``"triangle 2.1e+03 V/s"``).
        peak_um: the largest distance [µm] of the model's displacement from the
            record's centre (inf where it cannot be simulated).
        allowed_um: the largest allowed [µm].
        passed: ``peak_um <= allowed_um``.
    """

    name: str
    peak_um: float
    allowed_um: float
    passed: bool

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (``peak_um`` None where the model could not be simulated)."""
        out = asdict(self)
        if not math.isfinite(self.peak_um):
            out["peak_um"] = None
        return out


@dataclass(frozen=True)
class Boundedness:
    """The result of :func:`check`.

    Attributes:
        passed: every probe passed.
        multiple: :data:`MULTIPLE`.
        centre_um, range_um: the record's displacement centre and range [µm].
        u_min_v, u_max_v: the probes' voltage range [V] (the record's).
        highest_hz: the highest sine's frequency [Hz].
        fastest_v_per_s, slowest_v_per_s: the triangles' slews [V/s].
        probes: every probe, in order (sines, steps, triangles).
    """

    passed: bool
    multiple: float
    centre_um: float
    range_um: float
    u_min_v: float
    u_max_v: float
    highest_hz: float
    fastest_v_per_s: float
    slowest_v_per_s: float
    probes: tuple[Probe, ...]

    @property
    def worst(self) -> Probe:
        """The probe of largest peak relative to its allowance."""
        return max(self.probes, key=lambda p: p.peak_um / p.allowed_um if p.allowed_um > 0 else math.inf)

    def summary(self) -> str:
        """One line: passed or not, and the worst probe."""
        w = self.worst
        verdict = "bounded" if self.passed else "NOT bounded"
        peak = f"{w.peak_um:.4g} µm" if math.isfinite(w.peak_um) else "cannot be simulated"
        return (
            f"{verdict} over the record's range: worst {w.name}, {peak} from the record's centre "
            f"(allowed {w.allowed_um:.4g} µm = {self.multiple:g} × its range × the model's gain there)"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields, the probes as a list."""
        out = {k: v for k, v in asdict(self).items() if k != "probes"}
        out["probes"] = [p.to_dict() for p in self.probes]
        out["summary"] = self.summary()
        return out


def highest_excited_hz(record: Record) -> float:
    """The frequency [Hz] below which the record's voltage holds :data:`EXCITED_SHARE` of
    its power (Welch spectrum, :func:`boucwen.metrics.spectrum`); at least two periods
    per record length and at most 0.45 of the sampling rate."""
    duration = max(record.duration_s, record.dt)
    lowest = 2.0 / duration
    try:
        f, pxx = spectrum(record.u, record.dt)
    except ValueError:
        return lowest
    total = float(np.sum(pxx))
    if not total > 0:
        return lowest
    k = int(np.searchsorted(np.cumsum(pxx), EXCITED_SHARE * total))
    return float(min(max(f[min(k, f.size - 1)], lowest), 0.45 / record.dt))


def _triangle(lo: float, hi: float, slew: float, n: int, dt: float) -> FloatArray:
    """A triangle from ``lo`` up to ``hi`` and back [V] at ``slew`` [V/s], ``n`` samples."""
    t = dt * np.arange(n)
    span = hi - lo
    phase = np.mod(t * slew, 2.0 * span)
    out: FloatArray = lo + np.where(phase <= span, phase, 2.0 * span - phase)
    return out


def _steps(lo: float, hi: float, hold: int, n: int) -> FloatArray:
    """Steps between ``lo`` and ``hi`` [V], each level held ``hold`` samples (from ``lo``)."""
    out: FloatArray = np.where((np.arange(n) // max(hold, 1)) % 2 == 0, lo, hi).astype(np.float64)
    return out


def check(record: Record, subject: Subject) -> Boundedness:
    """Drives ``subject`` with the probes of the module docs, over ``record``'s voltage
    range, length and interval, and compares its displacement with ``record``'s."""
    u, dt, n = record.u, record.dt, len(record)
    lo, hi = float(np.min(u)), float(np.max(u))
    span = hi - lo
    centre = 0.5 * float(np.max(record.x) + np.min(record.x))
    x_range = float(np.ptp(record.x))
    duration = max(record.duration_s, dt)
    t = dt * np.arange(n)
    top = highest_excited_hz(record)
    freqs = np.geomspace(min(2.0 / duration, top), top, SINE_COUNT) if top > 2.0 / duration else np.array([top])
    fastest = float(np.max(np.abs(np.diff(u)))) / dt if n > 1 else 0.0
    slowest = 2.0 * span / duration
    probes: list[tuple[str, FloatArray, float]] = []
    for f in freqs:
        probes.append((f"sine {f:.4g} Hz", lo + 0.5 * span * (1.0 - np.cos(2.0 * math.pi * f * t)), float(f)))
    slow_hold = max(n // 8, 1)
    # Steps ring after each edge, at most once more the step for a mode of unit static
    # gain (within the multiple): no gain of theirs (fundamental 0).
    probes.append((f"steps {slow_hold} samples", _steps(lo, hi, slow_hold, n), 0.0))
    probes.append((f"steps {FAST_HOLD_SAMPLES} samples", _steps(lo, hi, FAST_HOLD_SAMPLES, n), 0.0))
    for slew in dict.fromkeys((fastest, slowest)):
        if slew > 0 and span > 0:
            probes.append((f"triangle {slew:.3g} V/s", _triangle(lo, hi, slew, n, dt), slew / (2.0 * span)))
    results = []
    for name, probe_u, f0 in probes:
        # Sines and triangles take the linear gain at their fundamental.
        gain = max(1.0, subject.gain(f0)) if f0 > 0 else 1.0
        allowed = MULTIPLE * max(x_range, 1e-12) * gain
        xs = subject.simulate(probe_u)
        peak = float(np.max(np.abs(xs - centre))) if xs is not None and np.all(np.isfinite(xs)) else math.inf
        results.append(Probe(name, peak, allowed, peak <= allowed))
    return Boundedness(
        passed=all(p.passed for p in results),
        multiple=MULTIPLE,
        centre_um=centre,
        range_um=x_range,
        u_min_v=lo,
        u_max_v=hi,
        highest_hz=float(freqs[-1]),
        fastest_v_per_s=fastest,
        slowest_v_per_s=slowest,
        probes=tuple(results),
    )


def _mode_gain(f: float, fn: float, zeta: float) -> float:
    """|H(f)| of z̈ + 2ζω·ż + ω²·z = ω²·y (unit static gain) at ``f`` [Hz]."""
    r = f / fn
    return 1.0 / math.sqrt((1.0 - r * r) ** 2 + (2.0 * zeta * r) ** 2)


def check_model(record: Record, params: Params, effects: EffectSet, h0: float) -> Boundedness:
    """:func:`check` of the extended model (``params``, ``effects``, h0 [µm]), its gain
    that of its modes (``resonance``, ``resonance2``) in series."""
    modes = [p for name, p in params_of(effects).items() if name in ("resonance", "resonance2")]

    def gain(f: float) -> float:
        return math.prod(_mode_gain(f, m["fn_hz"], m["zeta"]) for m in modes)

    def simulate(u: FloatArray) -> FloatArray | None:
        return simulate_chain(params, effects, u, record.dt, h0)

    return check(record, Subject(simulate, gain))


def check_oscillator(record: Record, fit: OscillatorFit) -> Boundedness:
    """:func:`check` of a hysteretic oscillator (:class:`boucwen.oscillator.OscillatorFit`)
    fitted to ``record`` with its input as the force [N] and its displacement in m (as
    the diagnosis fits it): its displacement in µm, its gain that of the mass on the
    linear spring and the loop's initial stiffness, k + α, with the damper."""
    p = fit.params
    stiffness = p.k + p.alpha

    def gain(f: float) -> float:
        w = 2.0 * math.pi * f
        return float(stiffness / abs(complex(stiffness - p.m * w * w, p.c * w)))

    def simulate(u: FloatArray) -> FloatArray | None:
        try:
            y = simulate_oscillator(p, u, record.dt, fit.y0, fit.v0, fit.z0)
        except ValueError:
            return None
        out: FloatArray = np.asarray(y) * 1e6
        return out

    return check(record, Subject(simulate, gain))
