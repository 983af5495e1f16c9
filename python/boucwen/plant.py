"""A simulated piezo bench: the source of "measured" (u, x) records.

The bench imitates the rig of Zhu, Bian & Rui (2014, section 4): a piezo stack
driven through a power amplifier, a laser Doppler vibrometer reading the
displacement, and a 16-bit A/D reading the voltage. Signal chain, per sample
interval ``dt`` [s]::

    u (command, V) ──► amplifier lag ──► u_a (on the stack, V)
    u_a ──► asymmetric Bouc–Wen, eqs. (3)+(5) ──► y = kv·u_a + h     (µm)
    y ──► electrostriction ──► y + ε·y²                               (µm)
    u_a ──► creep: Σ_i first-order elements (τ_i, g_i) ──► c        (µm)
    x_true = x0 + y + ε·y² + c                       (stack displacement, µm)
    x_true + floor vibration + white noise ──► 2 nm resolution     (measured x)
    u ──► 16-bit A/D ──► measured u

* **Amplifier**: first-order low-pass ``τ·du_a/dt = u − u_a`` with
  ``τ = 1/(2π·fc)``. The command is a straight line between samples; the lag is
  solved exactly for such an input on a grid ``oversample`` times finer than the
  sampling, and the Bouc–Wen core and the creep are run on the same fine grid.
* **Creep**: ``τ_i·dc_i/dt = g_i·u_a − c_i``, ``c = Σ c_i``, with log-spaced time
  constants (10 ms … 10 s). A 100 V step makes the stack creep on by about
  ``Σ g_i·100 V`` over the following ~30 s, a few percent of the stroke, roughly
  equally per decade of time (the usual logarithmic creep of piezo stacks).
* **Electrostrictive stroke non-linearity** (a property of the stack). The strain
  of a poled ceramic is ``S = Q·P²`` (Q the electrostrictive coefficient, P the
  polarisation), so with ``P = P_r + ΔP`` the stroke is linear in the (hysteretic)
  ΔP plus a term in ΔP²: the stack's gain grows along its stroke, the large-signal
  behaviour of soft PZT. The bench maps the Bouc–Wen displacement
  ``y = kv·u_a + h`` through ``y + ε·y²`` (``stroke_quadratic_per_um`` = ε). The
  model's output equation (3) is additive, ``kv·u + x0 + h``, and cannot represent
  a gain that depends on the hysteretic state; at one frequency an output-error fit
  absorbs most of it by bending δ, which then fails at other frequencies.
* **Floor vibration** (a property of the rig). A vibrometer measures the distance
  between its head and the target; head and stack stand on different supports,
  so building vibration (structural modes and machinery, typically 10–30 Hz) adds
  a relative motion ``Σ_k a_k·sin(2π·f_k·t + φ_k)`` to the reading. It is not
  caused by u, so no model of (u, x) can predict it: it sets a floor under every
  method's error, at every frequency.
* **Vibrometer**: white noise of standard deviation ``noise_um``, then the reading
  is rounded to multiples of ``resolution_um`` and held within ``±range_um``.
  Its 0.05 % non-linearity is not modelled.
* **A/D**: the *command* is read back (the amplifier's input, expressed in volts
  at the stack), rounded to ``2**adc_bits − 1`` steps over
  ``adc_min_v … adc_max_v`` and clipped to that span. The voltage actually on the
  stack is not measured, so the amplifier's bandwidth is a dynamic that a model
  of (u, x) does not see, as on the paper's rig.

Everything starts at rest in equilibrium with the first command sample
(``u_a = u[0]``, ``c_i = g_i·u[0]``, ``h = 0``); the vibration's phases refer to t = 0.

Calibration (defaults; ``boucwen reproduce``, seed 0): the traditional method
(output-error fit on the 1 Hz part, then held fixed) is off in steady state by
0.48 µm at 1 Hz, 0.75 µm at 10 Hz, 1.24 µm at 100 Hz and 2.96 µm at 200 Hz
(paper, Table 1: 0.47, 0.75, 1.25, 2.91 µm). Where each part comes from (same
run with one effect switched off):

* the amplifier's lag gives the growth at 100 and 200 Hz (no lag: 0.44, 0.64 µm);
* electrostriction the growth from 1 to 10 Hz: the fit absorbs it at 1 Hz by
  bending δ (0.0075 → 0.042), which is wrong at 10 Hz (without vibration:
  0.12, 0.30, 1.40, 2.76 µm);
* the floor vibration most of the 1 Hz error (without electrostriction: 0.48,
  0.44, 1.25, 2.99 µm).

With neither of the last two the fit matches the 1 Hz record to 0.04 µm: at one
frequency the seven parameters absorb creep, lag and small smooth distortions of
the loop almost exactly (a quadratic stroke term, a Prandtl–Ishlinskii play
component, stronger creep or a steady drift, each of a physical size, leave
0.05–0.3 µm), so no physically sized stack effect alone reaches 0.47 µm.

The Bouc–Wen core is integrated by :func:`boucwen.simulate`. The bench is a data
source: its settings are known here only, the identification code sees nothing
but the measured record.

For closed-loop experiments, :class:`Bench` runs the same bench one sample at a
time (``step(u) -> x``): the command of each sample is applied before its output is
read, as :func:`measure` assumes, and stepping a record gives the record
:func:`measure` returns (same seed).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ._core import Params, simulate
from .checks import FloatArray, as_float_vector, check_dt
from .record import Record

__all__ = [
    "DEFAULT_DT",
    "PAPER_SEGMENTS",
    "Bench",
    "BenchSettings",
    "floor_vibration",
    "measure",
    "paper_input",
    "true_displacement",
]

#: Default sampling interval [s] (10 kHz).
DEFAULT_DT = 1e-4

#: The paper's input as (frequency [Hz], duration [s]) pairs: 1 Hz for 3 s,
#: 10 Hz for 0.3 s, 100 Hz for 0.03 s, then 200 Hz for 0.05 s (10 periods).
PAPER_SEGMENTS: tuple[tuple[float, float], ...] = ((1.0, 3.0), (10.0, 0.3), (100.0, 0.03), (200.0, 0.05))


@dataclass(frozen=True)
class BenchSettings:
    """Every value of the simulated bench, with its unit.

    The Bouc–Wen values default to the paper's Table 2 row identified at 1 Hz.
    """

    kv: float = 0.19
    """Linear gain kv [µm/V]."""
    x0: float = 0.015
    """Offset x0 [µm]."""
    A: float = -0.072
    """Hysteresis gain A [µm/V]."""
    beta: float = 0.020
    """β [µm^(1−n)/V]."""
    gamma: float = -0.019
    """γ [µm^(1−n)/V]."""
    n: float = 1.52
    """Shape exponent n [-]."""
    delta: float = 0.0075
    """Asymmetry δ [µm/(V·s)]."""
    amplifier_fc_hz: float = 650.0
    """Corner frequency of the amplifier's first-order lag [Hz]; ``math.inf`` = no lag.

    The lag gives the growth of the traditional method's error at 100 and 200 Hz
    (module docs, "Calibration"); 650 Hz is within the few hundred hertz to a few
    kilohertz of a laboratory piezo amplifier driving a µF stack, and makes the
    command-to-stack gain 1/√(1 + (200/650)²) = 0.956 at 200 Hz."""
    creep_tau_s: tuple[float, ...] = (0.01, 0.1, 1.0, 10.0)
    """Time constants of the creep elements [s]."""
    creep_gain_um_per_v: tuple[float, ...] = (0.002, 0.002, 0.002, 0.002)
    """Static gain of each creep element [µm/V]; all zero = no creep.

    Together 0.008 µm/V, 4 % of kv: after a 100 V step the stack creeps on by
    0.8 µm (about 4.5 % of the 17.6 µm stroke), 0.2 µm per decade of time."""
    stroke_quadratic_per_um: float = 0.004
    """Electrostrictive coefficient ε [1/µm] of the stroke map ``y ↦ y + ε·y²``; 0 = none.

    With 0.004 /µm over the 0 … 17.6 µm stroke the local gain at the top is
    1 + 2·ε·17.6 = 1.14 times that at the bottom, and the curve departs from the
    straight line through its end points by at most ε·(17.6/2)² = 0.31 µm (1.8 % of
    the stroke), inside the 10–20 % rise of the large-signal d33 of soft PZT over
    a unipolar drive and the few-% non-linearity quoted for piezo stacks."""
    vibration_hz: tuple[float, ...] = (17.0, 29.0)
    """Frequencies f_k of the floor vibration between vibrometer head and stack [Hz]."""
    vibration_um: tuple[float, ...] = (0.25, 0.2)
    """Amplitudes a_k of the floor vibration [µm]; all zero (or empty) = none.

    0.25 µm at 17 Hz and 0.2 µm at 29 Hz are relative velocities of 27 and 36 µm/s
    (peak; 19 and 26 µm/s rms), below the 50 µm/s (rms, one-third octave) of the
    VC-A vibration criterion for laboratory floors: a quiet bench without an
    isolation table."""
    vibration_phase_rad: tuple[float, ...] = (0.0, 0.0)
    """Phases φ_k of the floor vibration at t = 0 [rad]."""
    noise_um: float = 0.001
    """Standard deviation of the vibrometer's white noise [µm] (1 nm)."""
    resolution_um: float = 0.002
    """Vibrometer resolution [µm] (2 nm); the reading is a multiple of it; 0 = none."""
    range_um: float = 40.0
    """Vibrometer range [µm]; readings are held within ±range_um."""
    adc_bits: int = 16
    """A/D resolution [bits]; 0 = no quantisation of u."""
    adc_min_v: float = 0.0
    """Lowest voltage the A/D reads [V] (code 0)."""
    adc_max_v: float = 100.0
    """Highest voltage the A/D reads [V] (code 2**adc_bits − 1)."""
    oversample: int = 4
    """Fine-grid points per sample interval for the lag, creep and Bouc–Wen core [-]."""

    def __post_init__(self) -> None:
        for name in (
            "kv",
            "x0",
            "A",
            "beta",
            "gamma",
            "n",
            "delta",
            "noise_um",
            "resolution_um",
            "range_um",
            "adc_min_v",
            "adc_max_v",
        ):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"BenchSettings.{name} must be a finite number, got {value!r}")
        if self.n <= 0:
            raise ValueError(f"BenchSettings.n must be > 0, got {self.n}")
        if not (self.amplifier_fc_hz > 0):
            raise ValueError(
                f"BenchSettings.amplifier_fc_hz must be > 0 Hz (math.inf = no lag), got {self.amplifier_fc_hz}"
            )
        object.__setattr__(self, "creep_tau_s", tuple(float(v) for v in self.creep_tau_s))
        object.__setattr__(self, "creep_gain_um_per_v", tuple(float(v) for v in self.creep_gain_um_per_v))
        if len(self.creep_tau_s) != len(self.creep_gain_um_per_v):
            raise ValueError(
                "BenchSettings.creep_tau_s and creep_gain_um_per_v must have the "
                f"same length, got {len(self.creep_tau_s)} and "
                f"{len(self.creep_gain_um_per_v)}"
            )
        if not all(math.isfinite(v) and v > 0 for v in self.creep_tau_s):
            raise ValueError(f"BenchSettings.creep_tau_s must be finite and > 0 s, got {self.creep_tau_s}")
        if not all(math.isfinite(v) for v in self.creep_gain_um_per_v):
            raise ValueError("BenchSettings.creep_gain_um_per_v must be finite")
        if not (isinstance(self.stroke_quadratic_per_um, (int, float)) and math.isfinite(self.stroke_quadratic_per_um)):
            raise ValueError(
                f"BenchSettings.stroke_quadratic_per_um must be a finite number, got {self.stroke_quadratic_per_um!r}"
            )
        for name in ("vibration_hz", "vibration_um", "vibration_phase_rad"):
            object.__setattr__(self, name, tuple(float(v) for v in getattr(self, name)))
            if not all(math.isfinite(v) for v in getattr(self, name)):
                raise ValueError(f"BenchSettings.{name} must be finite, got {getattr(self, name)}")
        if not (len(self.vibration_hz) == len(self.vibration_um) == len(self.vibration_phase_rad)):
            raise ValueError(
                "BenchSettings.vibration_hz, vibration_um and vibration_phase_rad "
                f"must have the same length, got {len(self.vibration_hz)}, "
                f"{len(self.vibration_um)} and {len(self.vibration_phase_rad)}"
            )
        if not all(v > 0 for v in self.vibration_hz):
            raise ValueError(f"BenchSettings.vibration_hz must be > 0 Hz, got {self.vibration_hz}")
        if self.noise_um < 0 or self.resolution_um < 0 or self.range_um <= 0:
            raise ValueError("BenchSettings: noise_um and resolution_um must be >= 0, range_um > 0")
        if not isinstance(self.adc_bits, int) or not 0 <= self.adc_bits <= 32:
            raise ValueError(f"BenchSettings.adc_bits must be an int in 0…32, got {self.adc_bits!r}")
        if self.adc_bits and not self.adc_max_v > self.adc_min_v:
            raise ValueError("BenchSettings.adc_max_v must be > adc_min_v")
        if not isinstance(self.oversample, int) or self.oversample < 1:
            raise ValueError(f"BenchSettings.oversample must be an int >= 1, got {self.oversample!r}")

    def to_dict(self) -> dict[str, Any]:
        """The settings as a plain dict (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def params(self) -> Params:
        """The Bouc–Wen core as a :class:`boucwen.Params`."""
        return Params(self.kv, self.x0, self.A, self.beta, self.gamma, self.n, self.delta)

    @property
    def adc_lsb_v(self) -> float:
        """Voltage step of one A/D code [V] (0 if the A/D does not quantise)."""
        if not self.adc_bits:
            return 0.0
        return (self.adc_max_v - self.adc_min_v) / float(2**self.adc_bits - 1)


# --------------------------------------------------------------------------- input


def paper_input(
    dt: float = DEFAULT_DT,
    durations: Sequence[tuple[float, float]] | Mapping[float, float] | None = None,
) -> tuple[FloatArray, FloatArray, list[tuple[float, int, int]]]:
    """The paper's test voltage u = 50 + 50·sin(2πf·t' − π/2) [V], f switching at minima.

    ``t'`` is the time since the start of the current segment, so every segment
    starts at u = 0 V, and because each lasts a whole number of periods u stays
    continuous across the switches.

    :func:`boucwen.paper_input` (the core's) gives the same samples for the paper's
    1/10/100 Hz durations followed by 200 Hz; this one also takes any list of
    segments (the experiment's reduced input among them), returns the times and
    segment bounds, and holds the final sample, so it is kept separate; a test
    checks that the two agree.

    Args:
        dt: sampling interval [s].
        durations: (frequency [Hz], duration [s]) pairs in order, or an ordered
            mapping {frequency: duration}; default :data:`PAPER_SEGMENTS`
            (1 Hz 3 s, 10 Hz 0.3 s, 100 Hz 0.03 s, 200 Hz 0.05 s).

    Returns:
        ``(t, u, segments)``: times [s] from 0 to the total duration inclusive,
        voltage [V], and ``(f_hz, start_index, stop_index)`` per segment (stop
        exclusive; the last segment also holds the final sample).

    Raises:
        ValueError: dt not > 0, a frequency or duration not > 0, or a duration that
            is not a whole number of periods.
    """
    dt = check_dt(dt)
    pairs = list(
        durations.items() if isinstance(durations, Mapping) else (PAPER_SEGMENTS if durations is None else durations)
    )
    if not pairs:
        raise ValueError("durations must hold at least one (frequency, duration) pair")
    starts = [0.0]
    for f, d in pairs:
        f, d = float(f), float(d)
        if not (math.isfinite(f) and f > 0 and math.isfinite(d) and d > 0):
            raise ValueError(f"frequency and duration must be finite and > 0, got ({f}, {d})")
        periods = f * d
        if abs(periods - round(periods)) > 1e-6 * max(1.0, periods) or round(periods) < 1:
            raise ValueError(
                f"{f:g} Hz for {d:g} s is {periods:.6g} periods, not a whole "
                "number; the switch would not fall on a minimum"
            )
        starts.append(starts[-1] + d)
    total = starts[-1]
    count = math.floor(total / dt + 1e-9) + 1
    t = np.arange(count, dtype=np.float64) * dt
    u = np.empty(count, dtype=np.float64)
    segments: list[tuple[float, int, int]] = []
    for i, (f, _) in enumerate(pairs):
        lo = math.ceil(starts[i] / dt - 1e-9)
        hi = count if i == len(pairs) - 1 else math.ceil(starts[i + 1] / dt - 1e-9)
        local = t[lo:hi] - starts[i]
        u[lo:hi] = 50.0 - 50.0 * np.cos(2.0 * math.pi * float(f) * local)
        segments.append((float(f), lo, hi))
    return t, u, segments


# --------------------------------------------------------------------------- bench


def _lowpass(v: FloatArray, tau: float, step: float, y0: float) -> FloatArray:
    """Exact response of τ·dy/dt = v − y to v linear between grid points [same unit as v]."""
    a = math.exp(-step / tau)
    b = tau / step * -math.expm1(-step / tau)
    c1, c0 = 1.0 - b, b - a
    vs = v.tolist()
    out = [0.0] * len(vs)
    y = y0
    out[0] = y
    prev = vs[0]
    for k in range(1, len(vs)):
        cur = vs[k]
        y = a * y + c1 * cur + c0 * prev
        out[k] = y
        prev = cur
    return np.asarray(out, dtype=np.float64)


def _respond(u: FloatArray, dt: float, s: BenchSettings) -> dict[str, FloatArray]:
    """Noise-free signals at the sample instants: u_applied [V], creep [µm], x [µm]."""
    m = s.oversample
    fine_dt = dt / m
    if m > 1:
        k = np.arange((u.size - 1) * m + 1, dtype=np.float64) / m
        u_fine = np.interp(k, np.arange(u.size, dtype=np.float64), u)
    else:
        u_fine = u
    if math.isinf(s.amplifier_fc_hz):
        ua_fine = u_fine.copy()
    else:
        ua_fine = _lowpass(u_fine, 1.0 / (2.0 * math.pi * s.amplifier_fc_hz), fine_dt, u_fine[0])
    creep_fine = np.zeros_like(ua_fine)
    for tau, gain in zip(s.creep_tau_s, s.creep_gain_um_per_v):
        if gain != 0.0:
            creep_fine += gain * _lowpass(ua_fine, tau, fine_dt, ua_fine[0])
    # The core without its offset: y = kv·u_a + h [µm], then the stroke map y + ε·y².
    bw_fine, _ = simulate(s.params().replace(x0=0.0), ua_fine, fine_dt, 0.0)
    y_fine = np.asarray(bw_fine, dtype=np.float64)
    x_fine = s.x0 + y_fine + s.stroke_quadratic_per_um * y_fine * y_fine + creep_fine
    return {"u_applied": ua_fine[::m].copy(), "creep": creep_fine[::m].copy(), "x": x_fine[::m].copy()}


def floor_vibration(t: Any, settings: BenchSettings = BenchSettings()) -> FloatArray:
    """Relative motion of vibrometer head and stack, Σ a_k·sin(2π·f_k·t + φ_k) [µm], at times t [s]."""
    times = np.asarray(t, dtype=np.float64)
    out = np.zeros_like(times)
    for f, a, phase in zip(settings.vibration_hz, settings.vibration_um, settings.vibration_phase_rad):
        if a != 0.0:
            out += a * np.sin(2.0 * math.pi * f * times + phase)
    return out


def _as_input(u: Any, dt: Any) -> tuple[FloatArray, float]:
    """The command as a float64 array and dt as a float; TypeError/ValueError otherwise."""
    if dt is None:
        raise TypeError("dt [s] is required")
    return as_float_vector(u, "u"), check_dt(dt)


def true_displacement(u: Any, dt: float = DEFAULT_DT, settings: BenchSettings = BenchSettings()) -> FloatArray:
    """Noise-free displacement x [µm] of the stack for the command u [V] sampled every dt [s].

    The floor vibration is not part of it (it moves the vibrometer, not the stack).
    Deterministic: the same input always gives the same output.
    """
    u, dt = _as_input(u, dt)
    return _respond(u, dt, settings)["x"]


def measure(u: Any, dt: float = DEFAULT_DT, settings: BenchSettings = BenchSettings(), seed: int | None = 0) -> Record:
    """Runs the bench on the command u [V] sampled every dt [s] and returns what is measured.

    Args:
        u: commanded voltage [V], 1-D.
        dt: sampling interval [s].
        settings: the bench.
        seed: seed of the vibrometer noise (same seed, same record; ``None`` = fresh).

    Returns:
        A :class:`~boucwen.record.Record` named ``"bench"``: ``t`` [s], ``u`` = the command
        as read by the A/D [V], ``x`` = the vibrometer reading [µm]. ``meta`` holds
        the settings (``settings``), ``seed``, ``units`` and, for checking only, the
        noise-free signals ``u_command`` [V], ``u_applied`` [V], ``creep`` [µm],
        ``x_true`` [µm] (the stack's displacement, :func:`true_displacement`) and
        ``vibration`` [µm] (:func:`floor_vibration`); ``x`` is their sum ``x_true +
        vibration`` plus noise, rounded to the resolution.
    """
    u, dt = _as_input(u, dt)
    s = settings
    truth = _respond(u, dt, s)
    t = np.arange(u.size, dtype=np.float64) * dt
    vibration = floor_vibration(t, s)
    rng = np.random.default_rng(seed)
    x = truth["x"] + vibration + s.noise_um * rng.standard_normal(u.size)
    if s.resolution_um > 0:
        x = s.resolution_um * np.round(x / s.resolution_um)
    x = np.clip(x, -s.range_um, s.range_um)
    if s.adc_bits:
        top = 2**s.adc_bits - 1
        lsb = s.adc_lsb_v
        code = np.clip(np.round((u - s.adc_min_v) / lsb), 0, top)
        u_read = s.adc_min_v + code * lsb
    else:
        u_read = u.copy()
    meta = {
        "source": "boucwen.plant simulated bench",
        "settings": s.to_dict(),
        "seed": seed,
        "units": {
            "t": "s",
            "u": "V (command read by the A/D)",
            "x": "µm (vibrometer)",
            "u_command": "V",
            "u_applied": "V",
            "creep": "µm",
            "x_true": "µm",
            "vibration": "µm",
        },
        "u_command": u.copy(),
        "u_applied": truth["u_applied"],
        "creep": truth["creep"],
        "x_true": truth["x"],
        "vibration": vibration,
    }
    return Record(t=t, u=u_read, x=x, dt=dt, name="bench", meta=meta)


# --------------------------------------------------------------------------- stepping


def _lowpass_coefficients(tau: float, step: float) -> tuple[float, float, float]:
    """(a, c1, c0) of :func:`_lowpass`'s step y ← a·y + c1·v_k + c0·v_k−1."""
    a = math.exp(-step / tau)
    b = tau / step * -math.expm1(-step / tau)
    return a, 1.0 - b, b - a


class Bench:
    """The simulated bench one sample at a time: ``x = bench.step(u)``.

    The same physics and the same numbers as :func:`measure`: the command u [V] of a
    sample is taken as a straight line from the previous one, runs through the
    amplifier lag, the creep, the Bouc–Wen core and the stroke map on the same fine
    grid, and the vibrometer reads the displacement at the sample instant with the
    floor vibration, the noise (drawn from ``numpy.random.default_rng(seed)`` in the
    order :func:`measure` draws it), its resolution and range. Stepping a record
    therefore returns what :func:`measure` returns for it with the same seed, to
    rounding (a test checks 1e-12 µm).

    For a control loop: the command is applied first and its output read after, so
    ``step(u_k)`` returns x_k, which a controller sees at its next sample.

    Args:
        dt: sampling interval [s].
        settings: the bench (e.g. ``BenchSettings(vibration_um=(0.0, 0.0))`` for a
            bench without floor vibration).
        seed: seed of the vibrometer noise (``None`` = fresh).

    Attributes (of the last sample, for checking only; a controller sees ``x``):
        t: time [s]; u_read: the command as read by the A/D [V]; u_applied: the
        voltage on the stack [V]; x_true: the stack's displacement [µm]; vibration:
        the floor vibration [µm]; samples: samples stepped so far.
    """

    def __init__(self, dt: float = DEFAULT_DT, settings: BenchSettings = BenchSettings(), seed: int | None = 0):
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0 s, got {dt!r}")
        from . import _core

        self.dt = float(dt)
        self.settings = settings
        self.seed = seed
        s = settings
        self._m = s.oversample
        fine_dt = self.dt / s.oversample
        self._lag = (
            None
            if math.isinf(s.amplifier_fc_hz)
            else _lowpass_coefficients(1.0 / (2.0 * math.pi * s.amplifier_fc_hz), fine_dt)
        )
        self._creep = [
            (gain, *_lowpass_coefficients(tau, fine_dt))
            for tau, gain in zip(s.creep_tau_s, s.creep_gain_um_per_v)
            if gain != 0.0
        ]
        self._vibration = [
            (2.0 * math.pi * f, a, phase)
            for f, a, phase in zip(s.vibration_hz, s.vibration_um, s.vibration_phase_rad)
            if a != 0.0
        ]
        self._core = _core.Model(_core.Params(s.kv, 0.0, s.A, s.beta, s.gamma, s.n, s.delta), fine_dt, 0.0)
        self._rng = np.random.default_rng(seed)
        self._noise: list[float] = []
        self._noise_pos = 0
        self._u_prev = 0.0
        self._ua = 0.0
        self._creep_states = [0.0] * len(self._creep)
        self.samples = 0
        self.t = 0.0
        self.u_read = math.nan
        self.u_applied = math.nan
        self.x_true = math.nan
        self.vibration = math.nan

    def _next_noise(self) -> float:
        if self._noise_pos == len(self._noise):
            self._noise = self._rng.standard_normal(4096).tolist()
            self._noise_pos = 0
        z = self._noise[self._noise_pos]
        self._noise_pos += 1
        return z

    def step(self, u: float) -> float:
        """Applies the command u [V] for the next sample; returns the vibrometer reading x [µm].

        Raises:
            ValueError: u is not a finite number (the bench is left as it was).
        """
        u = float(u)
        if not math.isfinite(u):
            raise ValueError(f"u = {u} is not finite; the sample was rejected and the bench kept")
        s = self.settings
        core = self._core.step
        creep = self._creep
        states = self._creep_states
        if self.samples == 0:
            ua = u
            for i in range(len(creep)):
                states[i] = ua
            y = core(ua)
            c = 0.0
            for i, (gain, _, _, _) in enumerate(creep):
                c += gain * states[i]
        else:
            u0, m = self._u_prev, self._m
            slope = u - u0
            ua = self._ua
            u_fine_prev = u0
            for j in range(1, m + 1):
                u_fine = u if j == m else slope * (j / m) + u0
                ua_prev = ua
                if self._lag is not None:
                    a, c1, c0 = self._lag
                    ua = a * ua + c1 * u_fine + c0 * u_fine_prev
                else:
                    ua = u_fine
                for i, (_, a, c1, c0) in enumerate(creep):
                    states[i] = a * states[i] + c1 * ua + c0 * ua_prev
                y = core(ua)
                u_fine_prev = u_fine
            c = 0.0
            for i, (gain, _, _, _) in enumerate(creep):
                c += gain * states[i]
        self._u_prev = u
        self._ua = ua
        x_true = s.x0 + y + s.stroke_quadratic_per_um * y * y + c
        t = self.samples * self.dt
        vibration = 0.0
        for w, a, phase in self._vibration:
            vibration += a * math.sin(w * t + phase)
        x = x_true + vibration + s.noise_um * self._next_noise()
        if s.resolution_um > 0:
            x = s.resolution_um * round(x / s.resolution_um)
        x = min(max(x, -s.range_um), s.range_um)
        if s.adc_bits:
            code = min(max(round((u - s.adc_min_v) / s.adc_lsb_v), 0), 2**s.adc_bits - 1)
            self.u_read = s.adc_min_v + code * s.adc_lsb_v
        else:
            self.u_read = u
        self.t = t
        self.u_applied = ua
        self.x_true = x_true
        self.vibration = vibration
        self.samples += 1
        return x
