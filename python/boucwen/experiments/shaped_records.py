"""Generated records shaped like measured ones: rest, a step, holds, and days.

A measured record is not a stationary excitation over its whole length. It starts at
rest, steps once and then oscillates, holds between tests, and carries the evidence of
a slow effect in a few seconds of a long record; a long one also carries the drift of
its day, which the input does not drive and which another day does not share. Two
shapes, each drawn from one seed:

* :func:`rest_step_sine` — a piezo stack logged at 5 kHz: 3.3 s at rest, then a step to
  a slow (1 Hz) sine, 10 s in all, with creep (the stack's relaxation after each
  change of voltage). The diagnosis sees the first half (the rest, the step and the
  first cycles) and is judged on the second half, which continues it.
* :func:`walk_hold_days` — a micromanipulator logged for an hour and resampled to
  10 Hz: 30 min of a smoothed random walk of the voltage, then a 30 min hold, with a
  static nonlinearity of the stack (electrostriction) and a slow drift of the day (a
  thermal wander, a few smooth components of periods 15–120 min and a trend), the
  logger's sample instants jittered. Several days share the device (parameters and
  effects) and differ in their walk and their drift; a model diagnosed on one day is
  judged on the others.

Both are simulated by :func:`boucwen.plant.simulate_oversampled` (the dynamics act
between the samples) and take their effects' parameters from the suite's makers
(:data:`~boucwen.experiments.suite_records.VOCABULARY_MAKERS`, sized as the suite sizes
an effect), so a record is described as the suite describes one
(:class:`~boucwen.experiments.suite_records.SuiteRecord`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.signal import lfilter

from .._core import Params
from ..checks import FloatArray
from ..effects.base import set_of
from ..plant import simulate_oversampled
from .suite_records import VOCABULARY_MAKERS, SuiteRecord, _Ctx, _strength, size_um
from .undeclared_records import PARAM_SETS

__all__ = [
    "DAY_DRIFT_UM",
    "HOLD_S",
    "REST_S",
    "STACK_DURATION_S",
    "STACK_RATE_HZ",
    "WALK_PARAMS",
    "WALK_RATE_HZ",
    "WALK_S",
    "rest_step_sine",
    "walk_hold_days",
]

#: The stack record: rate [Hz], length [s], the rest before the step [s].
STACK_RATE_HZ = 5_000.0
STACK_DURATION_S = 10.0
REST_S = 3.3
#: The micromanipulator's hour: rate [Hz] after resampling, the walk and the hold [s].
WALK_RATE_HZ = 10.0
WALK_S = 1800.0
HOLD_S = 1800.0
#: The micromanipulator's device: the paper's 1 Hz row without its rate-dependent term
#: (δ = 0). The δ·u·sgn(u̇) term describes the rate dependence measured at 1–200 Hz; on
#: a walk of seconds it would drive h by δ·u/|u̇| per volt wherever the walk slows, tens
#: of µm, which no stack does at rest: the quasi-static device is rate-independent.
WALK_PARAMS = Params.from_array([*PARAM_SETS["paper_1hz"].to_array()[:6], 0.0])
#: RMS of the drift of the day [µm] (its smooth components and trend together).
DAY_DRIFT_UM = 0.15
#: Noise of the logged voltage [V] (a measured channel, not the command).
_U_NOISE_V = 0.002
#: Fine grid of the simulation, points per sample interval.
_OVERSAMPLE = 4
#: Standard deviation of the logger's sample instants, a share of the interval.
_JITTER = 0.1


def _sized(
    params: Params, name: str, size: float, u: FloatArray, dt: float, ctx: _Ctx, x_plain: FloatArray
) -> tuple[dict[str, Any], float]:
    """The parameters of effect ``name`` whose size on ``u`` is ``size`` [µm] (the
    suite's maker and its bisection), and the size reached."""
    make, (lo, hi) = VOCABULARY_MAKERS[name]

    def sized(s: float) -> float:
        return size_um(simulate_oversampled(params, set_of({name: make(s, ctx)}), u, dt, _OVERSAMPLE), x_plain)

    strength, reached = _strength(sized, lo, hi, size)
    return make(strength, ctx), reached


def _device(
    params: Params, effects: Sequence[tuple[str, float]], u: FloatArray, dt: float, rng: np.random.Generator
) -> tuple[dict[str, Any], dict[str, float], FloatArray]:
    """The device's effects sized on ``u`` (each alone, as the suite sizes them), their
    sizes, and the displacement without them [µm]."""
    x_plain = simulate_oversampled(params, set_of({}), u, dt, _OVERSAMPLE)
    ctx = _Ctx(
        fs=1.0 / dt,
        duration_s=dt * (u.size - 1),
        kv=params.kv,
        draws=rng.uniform(size=8),
        x_lo=float(np.min(x_plain)),
        x_hi=float(np.max(x_plain)),
    )
    chosen: dict[str, Any] = {}
    sizes: dict[str, float] = {}
    for name, size in effects:
        chosen[name], sizes[name] = _sized(params, name, size, u, dt, ctx, x_plain)
    return chosen, sizes, x_plain


def rest_step_sine(
    effects: Sequence[tuple[str, float]],
    seed: int,
    *,
    param_set: str = "paper_1hz",
    noise_um: float = 0.005,
    fs_hz: float = STACK_RATE_HZ,
    duration_s: float = STACK_DURATION_S,
    rest_s: float = REST_S,
) -> SuiteRecord:
    """A stack record (module docs): rest at a low voltage for ``rest_s`` [s], then a
    step to the middle of the range and a 1 Hz sine about it (amplitude and rest level
    drawn from ``seed``), ``effects`` as (name, size [µm]) pairs of the vocabulary,
    white noise of ``noise_um`` [µm] on x and 2 mV on the logged u."""
    rng = np.random.default_rng(seed)
    n = round(duration_s * fs_hz)
    dt = 1.0 / fs_hz
    t = np.arange(n) * dt
    u_rest, amplitude = rng.uniform(2.0, 15.0), rng.uniform(30.0, 45.0)
    moving = t >= rest_s
    u = np.where(moving, 50.0 + amplitude * np.sin(2.0 * math.pi * 1.0 * (t - rest_s)), u_rest)
    params = PARAM_SETS[param_set]
    chosen, sizes, _ = _device(params, effects, u, dt, rng)
    x_true = simulate_oversampled(params, set_of(chosen), u, dt, _OVERSAMPLE)
    u_logged = u + rng.normal(0.0, _U_NOISE_V, n)
    x = x_true + rng.normal(0.0, noise_um, n)
    names = "+".join(k for k, _ in effects) or "none"
    return SuiteRecord(
        label=f"{names} rest_step_sine {fs_hz / 1e3:g}kHz {param_set} σ={noise_um * 1e3:g}nm seed={seed}",
        family="rest_step_sine",
        fs_hz=fs_hz,
        param_set=param_set,
        noise_um=noise_um,
        seed=seed,
        inside=tuple(k for k, _ in effects),
        outside=(),
        sizes_um=sizes,
        params=chosen,
        u=u_logged,
        x=x,
        x_true=x_true,
        dt=dt,
        notes=[f"rest {rest_s:g} s at {u_rest:.3g} V, then a step to a 1 Hz sine of {amplitude:.3g} V about 50 V"],
    )


def _walk(n: int, dt: float, rng: np.random.Generator) -> FloatArray:
    """A smoothed random walk of ``n`` samples [V] within 5…95 V: Gaussian increments
    summed, low-passed twice (time constant 5–20 s), scaled to the range."""
    tau = rng.uniform(5.0, 20.0)
    alpha = math.exp(-dt / tau)
    v = lfilter([1 - alpha], [1, -alpha], lfilter([1 - alpha], [1, -alpha], np.cumsum(rng.normal(size=n))))
    v = v - v.min()
    return np.asarray(5.0 + 90.0 * v / max(float(v.max()), 1e-12))


def _day_drift(t: FloatArray, rng: np.random.Generator, rms_um: float) -> FloatArray:
    """The drift of one day [µm] at times ``t`` [s]: three smooth components of periods
    15–120 min with random phases and a trend, scaled to ``rms_um`` about its start."""
    d: FloatArray = rng.normal() * t / t[-1]
    for period in rng.uniform(900.0, 7200.0, 3):
        d = d + rng.normal() * np.sin(2.0 * math.pi * t / period + rng.uniform(0.0, 2.0 * math.pi))
    d = d - d[0]
    return np.asarray(rms_um * d / max(float(np.sqrt(np.mean(d**2))), 1e-12))


def walk_hold_days(
    effects: Sequence[tuple[str, float]],
    seed: int,
    days: int = 4,
    *,
    params: Params = WALK_PARAMS,
    noise_um: float = 0.005,
    drift_um: float = DAY_DRIFT_UM,
    fs_hz: float = WALK_RATE_HZ,
    walk_s: float = WALK_S,
    hold_s: float = HOLD_S,
) -> list[SuiteRecord]:
    """``days`` records of one device (module docs): each a smoothed random walk of
    ``walk_s`` [s] then a hold of ``hold_s`` [s] at its last value, logged at ``fs_hz``
    with the sample instants jittered (σ = a tenth of the interval), the drift of its
    day (RMS ``drift_um`` [µm]) and white noise of ``noise_um`` [µm]. The device's
    ``effects`` (name, size [µm]) are sized on the first day and shared by all."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / fs_hz
    n_walk, n_hold = round(walk_s * fs_hz), round(hold_s * fs_hz)
    chosen: dict[str, Any] | None = None
    sizes: dict[str, float] = {}
    out: list[SuiteRecord] = []
    for day in range(days):
        walk = _walk(n_walk, dt, rng)
        u = np.concatenate([walk, np.full(n_hold, walk[-1])])
        if chosen is None:
            chosen, sizes, _ = _device(params, effects, u, dt, rng)
        n = u.size
        t = np.arange(n, dtype=np.float64) * dt
        # The device on a fine grid; the logger reads x at jittered instants.
        fine_dt = dt / _OVERSAMPLE
        u_fine = np.interp(np.arange((n - 1) * _OVERSAMPLE + 1) * fine_dt, t, u)
        x_fine = simulate_oversampled(params, set_of(chosen), u_fine, fine_dt, 1)
        fine_t = np.arange(u_fine.size) * fine_dt
        at = np.clip(t + rng.normal(0.0, _JITTER * dt, n), 0.0, t[-1])
        x_true = np.interp(at, fine_t, x_fine) + _day_drift(t, rng, drift_um)
        x = x_true + rng.normal(0.0, noise_um, n)
        names = "+".join(k for k, _ in effects) or "none"
        out.append(
            SuiteRecord(
                label=f"{names} walk_hold day {day + 1} {fs_hz:g}Hz σ={noise_um * 1e3:g}nm seed={seed}",
                family="walk_hold",
                fs_hz=fs_hz,
                param_set="quasi_static",
                noise_um=noise_um,
                seed=seed,
                inside=tuple(k for k, _ in effects),
                outside=("day_drift",),
                sizes_um={**sizes, "day_drift": drift_um},
                params=chosen,
                u=u,
                x=x,
                x_true=x_true,
                dt=dt,
                notes=[f"day {day + 1} of {days}: walk {walk_s:g} s, hold {hold_s:g} s, jitter σ {_JITTER:g}·dt"],
            )
        )
    return out
