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
  ``τ = 1/(2π·fc)``. The command is a straight line between samples; the stack's
  physics (lag, Bouc–Wen core, creep, electrostriction) is the core's effect chain,
  :func:`boucwen.simulate_extended` with :meth:`BenchSettings.effects`, run on a grid
  ``oversample`` times finer than the sampling (the lag's output bends within a
  sample, and the core follows the bend) and read at the sample instants.
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

The stack is simulated by the core (:func:`boucwen.simulate_extended`); the bench
adds only what is not the stack's: floor vibration, vibrometer and A/D. It is a data
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

from . import _core
from ._core import EffectSet, ExtendedState, Params, simulate_extended
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
    "simulate_oversampled",
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
    """Fine-grid points per sample interval the stack's chain is run on [-]."""

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

    def effects(self) -> EffectSet:
        """The stack's effects in the core's vocabulary: the amplifier's ``input_lag``
        (none for ``math.inf``), the ``creep`` elements (none if every gain is zero) and
        the ``electrostriction`` (none for ε = 0)."""
        fc, tau, gain, quadratic = (
            self.amplifier_fc_hz,
            self.creep_tau_s,
            self.creep_gain_um_per_v,
            self.stroke_quadratic_per_um,
        )
        return EffectSet(
            input_lag=None if math.isinf(fc) else {"fc_hz": fc},
            creep={"tau_s": list(tau), "gain_um_per_v": list(gain)} if any(gain) else None,
            electrostriction={"epsilon_per_um": quadratic} if quadratic != 0.0 else None,
        )

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

    The samples are the core's :func:`boucwen.paper_input` for these segments; this
    adds the times and each segment's bounds. ``t'`` is the time since the start of the
    current segment, so every segment starts at u = 0 V, and because each lasts a whole
    number of periods u stays continuous across the switches.

    Args:
        dt: sampling interval [s].
        durations: (frequency [Hz], duration [s]) pairs in order, or an ordered
            mapping {frequency: duration}; default :data:`PAPER_SEGMENTS`
            (1 Hz 3 s, 10 Hz 0.3 s, 100 Hz 0.03 s, 200 Hz 0.05 s).

    Returns:
        ``(t, u, segments)``: times [s] k·dt from 0 (round(T/dt) samples, T the total
        duration), voltage [V], and ``(f_hz, start_index, stop_index)`` per segment
        (stop exclusive).

    Raises:
        ValueError: dt not > 0, a frequency or duration not > 0, or a duration that
            is not a whole number of periods.
    """
    dt = check_dt(dt)
    given = PAPER_SEGMENTS if durations is None else durations
    pairs = [(float(f), float(d)) for f, d in (given.items() if isinstance(given, Mapping) else given)]
    u = np.asarray(_core.paper_input(dt, segments=pairs), dtype=np.float64)
    t = np.arange(u.size, dtype=np.float64) * dt
    # A segment's first sample is the first at or after its start (to 1e-12 s), the start
    # the sum of the durations before it rounded once, as the core takes them.
    starts = np.array([math.fsum(d for _, d in pairs[:i]) for i in range(len(pairs) + 1)])
    bounds = np.searchsorted(t, starts - 1e-12).tolist()
    bounds[-1] = u.size
    return t, u, [(f, int(bounds[i]), int(bounds[i + 1])) for i, (f, _) in enumerate(pairs)]


# --------------------------------------------------------------------------- bench


def _fine_grid(u: FloatArray, m: int) -> FloatArray:
    """The straight line between samples at m points per interval: u[0], then for each
    interval the m − 1 points inside it and its end sample [V]."""
    if m == 1:
        return u
    frac = np.arange(1, m, dtype=np.float64) / m
    inside = u[:-1, None] + (u[1:] - u[:-1])[:, None] * frac
    return np.concatenate([u[:1], np.column_stack([inside, u[1:]]).ravel()])


def simulate_oversampled(params: Params, effects: EffectSet, u: FloatArray, dt: float, m: int) -> FloatArray:
    """x [µm] at the sample instants of :func:`boucwen.simulate_extended` run on a grid
    ``m`` times finer than the sampling interval ``dt`` [s], u [V] a straight line
    between samples: the simulated record of a plant whose dynamics act between the
    samples (the lag's and the creep's output bend within an interval). A delay of d
    samples is m·d points of the fine grid."""
    chain = effects.to_dict()
    if "delay" in chain and m > 1:
        chain["delay"] = {"samples": int(chain["delay"]["samples"]) * m}
        effects = EffectSet.from_dict(chain)
    x = simulate_extended(params, effects, _fine_grid(u, m), dt / m)
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64)[::m])


def _respond(u: FloatArray, dt: float, s: BenchSettings) -> FloatArray:
    """Noise-free displacement of the stack x [µm] at the sample instants
    (:func:`simulate_oversampled` every ``oversample``-th point)."""
    return simulate_oversampled(s.params(), s.effects(), u, dt, s.oversample)


def floor_vibration(t: Any, settings: BenchSettings = BenchSettings()) -> FloatArray:
    """Relative motion of vibrometer head and stack, Σ a_k·sin(2π·f_k·t + φ_k) [µm], at times t [s]."""
    times = np.asarray(t, dtype=np.float64)
    out = np.zeros_like(times)
    for f, a, phase in zip(settings.vibration_hz, settings.vibration_um, settings.vibration_phase_rad):
        if a != 0.0:
            out += a * np.sin(2.0 * math.pi * f * times + phase)
    return out


def _read_displacement(x: FloatArray, s: BenchSettings) -> FloatArray:
    """What the vibrometer shows for the displacement x [µm] (vibration and noise
    included): rounded to its resolution and held within its range [µm]."""
    if s.resolution_um > 0:
        x = s.resolution_um * np.round(x / s.resolution_um)
    return np.asarray(np.clip(x, -s.range_um, s.range_um), dtype=np.float64)


def _read_voltage(u: FloatArray, s: BenchSettings) -> FloatArray:
    """The command as the A/D reads it [V]: rounded to its codes and clipped to its span."""
    if not s.adc_bits:
        return np.array(u, dtype=np.float64)
    code = np.clip(np.round((u - s.adc_min_v) / s.adc_lsb_v), 0, 2**s.adc_bits - 1)
    return np.asarray(s.adc_min_v + code * s.adc_lsb_v, dtype=np.float64)


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
    return _respond(u, dt, settings)


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
        noise-free signals ``u_command`` [V], ``x_true`` [µm] (the stack's displacement, :func:`true_displacement`) and
        ``vibration`` [µm] (:func:`floor_vibration`); ``x`` is their sum ``x_true +
        vibration`` plus noise, rounded to the resolution.
    """
    u, dt = _as_input(u, dt)
    s = settings
    x_true = _respond(u, dt, s)
    t = np.arange(u.size, dtype=np.float64) * dt
    vibration = floor_vibration(t, s)
    rng = np.random.default_rng(seed)
    x = _read_displacement(x_true + vibration + s.noise_um * rng.standard_normal(u.size), s)
    u_read = _read_voltage(u, s)
    meta = {
        "source": "boucwen.plant simulated bench",
        "settings": s.to_dict(),
        "seed": seed,
        "units": {
            "t": "s",
            "u": "V (command read by the A/D)",
            "x": "µm (vibrometer)",
            "u_command": "V",
            "x_true": "µm",
            "vibration": "µm",
        },
        "u_command": u.copy(),
        "x_true": x_true,
        "vibration": vibration,
    }
    return Record(t=t, u=u_read, x=x, dt=dt, name="bench", meta=meta)


# --------------------------------------------------------------------------- stepping


class Bench:
    """The simulated bench one sample at a time: ``x = bench.step(u)``.

    The same physics and the same numbers as :func:`measure`: the command u [V] of a
    sample is taken as a straight line from the previous one on the same fine grid,
    the core's chain (:func:`boucwen.simulate_extended`) continues over it from the
    state the previous sample left (:class:`boucwen.ExtendedState`), and the
    vibrometer reads the displacement at the sample instant with the floor vibration,
    the noise (drawn from ``numpy.random.default_rng(seed)`` in the order
    :func:`measure` draws it), its resolution and range. Stepping a record therefore
    returns what :func:`measure` returns for it with the same seed, bit for bit.

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
        self.dt = float(dt)
        self.settings = settings
        self.seed = seed
        self._params = settings.params()
        self._effects = settings.effects()
        self._state = ExtendedState()
        self._rng = np.random.default_rng(seed)
        self._noise: list[float] = []
        self._noise_pos = 0
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
        m = s.oversample
        previous = self._state.u_prev
        fine = np.array([u]) if previous is None else _fine_grid(np.array([previous, u]), m)[1:]
        x_fine, self._state = simulate_extended(self._params, self._effects, fine, self.dt / m, state=self._state)
        x_true = float(x_fine[-1])
        t = self.samples * self.dt
        vibration = float(floor_vibration(np.array([t]), s)[0])
        x = float(_read_displacement(np.array([x_true + vibration + s.noise_um * self._next_noise()]), s)[0])
        self.u_read = float(_read_voltage(np.array([u]), s)[0])
        self.t = t
        self.u_applied = self._state.ua
        self.x_true = x_true
        self.vibration = vibration
        self.samples += 1
        return x
