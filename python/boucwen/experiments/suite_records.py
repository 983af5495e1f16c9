"""The records of the diagnosis evaluation suite (:mod:`boucwen.experiments.diagnosis_suite`).

A record is an excitation family, a sampling rate (5–20 kHz), a base parameter set, a
noise level (1–20 nm) and a set of effects, each at a stated size, all drawn from
one seed:

* **excitations** (:data:`FAMILIES`): sine bursts, a staircase with holds, a single
  step, a chirp, band-limited random, a multisine, triangles, a decaying sine; all
  within 0…100 V;
* **effects of the vocabulary** are simulated by :func:`boucwen.plant.simulate_oversampled` on
  a grid 4× finer than the sampling (the input interpolated linearly), with creep
  time constants (3 ms, 30 ms, 0.3 s, 3 s) the diagnosis does not use; their
  parameters come from :data:`VOCABULARY_MAKERS`, keyed by effect name. Only the
  names the registry holds at run time (:data:`boucwen.effects.VOCABULARY`) are used;
* **effects outside the vocabulary** (:data:`OUTSIDE_MAKERS`: mechanical play
  (backlash) between the stack and the stage, a cubic sensor nonlinearity, a drift that
  settles exponentially within the record) are added in NumPy to the noise-free displacement —
  only those whose name the registry does not hold.

The **size** of an effect is the RMS [µm] of what it adds to the noise-free
displacement beyond an affine map of the displacement without it (the part a change
of the base model's gain and offset cannot absorb). Each maker turns a strength
s > 0 into the effect's parameters, its size increasing with s; the strength is found
by bisection in log s so that the size is the one asked (as near as the maker's range
allows; the size reached is recorded).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.signal import lfilter

from .._core import Params
from ..checks import FloatArray
from ..effects import VOCABULARY
from ..effects.base import set_of
from ..plant import simulate_oversampled
from .undeclared_records import PARAM_SETS

__all__ = [
    "DURATION_S",
    "FAMILIES",
    "NOISE_UM",
    "OUTSIDE_MAKERS",
    "RATES_HZ",
    "SIZES_UM",
    "VOCABULARY_MAKERS",
    "SuiteRecord",
    "excitation",
    "make_suite_record",
]

#: Excitation families.
FAMILIES = (
    "sine_bursts",
    "staircase",
    "single_step",
    "chirp",
    "band_random",
    "multisine",
    "triangle",
    "decaying_sine",
)
#: Sampling rates [Hz].
RATES_HZ = (5_000.0, 10_000.0, 20_000.0)
#: Noise levels [µm].
NOISE_UM = (0.001, 0.005, 0.02)
#: The three sizes of a single effect [µm RMS].
SIZES_UM = (0.02, 0.08, 0.3)
#: Record length [s].
DURATION_S = 1.2
_CREEP_TAU_S = (0.003, 0.03, 0.3, 3.0)
_OVERSAMPLE = 4


def excitation(family: str, fs: float, rng: np.random.Generator, duration_s: float = DURATION_S) -> FloatArray:
    """The voltage [V] of one excitation family, within 0…100 V, sampled at ``fs`` [Hz]."""
    n = round(duration_s * fs)
    t = np.arange(n) / fs
    if family == "sine_bursts":
        u = np.full(n, 20.0)
        for k, f in enumerate(rng.uniform(3.0, 80.0, 4)):
            a, b = round(n * k / 4), round(n * (k + 0.8) / 4)
            tt = t[a:b] - t[a]
            u[a:b] = 50.0 - rng.uniform(20.0, 45.0) * np.cos(2 * np.pi * f * tt) * np.sin(np.pi * tt / tt[-1]) ** 2
            u[b : round(n * (k + 1) / 4)] = 50.0
        return u
    if family == "staircase":
        levels = rng.uniform(5.0, 95.0, 8)
        return np.repeat(levels, -(-n // 8))[:n]
    if family == "single_step":
        lo, hi = rng.uniform(5.0, 30.0), rng.uniform(60.0, 95.0)
        return np.where(t < rng.uniform(0.1, 0.3) * duration_s, lo, hi)
    if family == "chirp":
        f0, f1 = rng.uniform(1.0, 3.0), rng.uniform(60.0, 150.0)
        phase = 2 * np.pi * (f0 * t + (f1 - f0) * t**2 / (2 * duration_s))
        return 50.0 - rng.uniform(30.0, 45.0) * np.cos(phase)
    if family == "band_random":
        fc = rng.uniform(20.0, 100.0)
        white = rng.normal(size=n)
        alpha = math.exp(-2 * np.pi * fc / fs)
        v = lfilter([1 - alpha], [1, -alpha], lfilter([1 - alpha], [1, -alpha], white))
        return np.asarray(np.clip(50.0 + 40.0 * v / (3.0 * np.std(v)), 0.0, 100.0))
    if family == "multisine":
        freqs = rng.uniform(1.0, 120.0, 5)
        v = sum(np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in freqs)
        return np.asarray(50.0 + 45.0 * v / np.max(np.abs(v)))
    if family == "triangle":
        f = rng.uniform(2.0, 20.0)
        return np.asarray(50.0 + rng.uniform(30.0, 45.0) * (2 * np.abs(2 * ((f * t) % 1.0) - 1.0) - 1.0))
    if family == "decaying_sine":
        f = rng.uniform(5.0, 60.0)
        tau = rng.uniform(0.2, 0.6) * duration_s
        return np.asarray(50.0 + 48.0 * np.exp(-t / tau) * np.sin(2 * np.pi * f * t))
    raise ValueError(f"unknown excitation family {family!r}; expected one of {list(FAMILIES)}")


@dataclass(frozen=True)
class _Ctx:
    """What a maker may depend on: the record's rate, length, base gain, random draws and
    the range [µm] of the displacement without effects."""

    fs: float
    duration_s: float
    kv: float
    draws: FloatArray
    x_lo: float = 0.0
    x_hi: float = 1.0


#: Strength s (> 0) → parameters of an effect of the vocabulary (size increasing with s),
#: and the range of s; keyed by effect name.
VOCABULARY_MAKERS: dict[str, tuple[Callable[[float, _Ctx], dict[str, Any]], tuple[float, float]]] = {
    "creep": (
        lambda s, c: {
            "tau_s": list(_CREEP_TAU_S),
            "gain_um_per_v": [math.copysign(s * w, c.kv) for w in c.draws[:4] / np.sum(c.draws[:4])],
        },
        (1e-5, 1.0),
    ),
    "input_lag": (lambda s, c: {"fc_hz": max(c.fs / (2.5 * s), 40.0)}, (1.0, 2000.0)),
    "resonance": (
        lambda s, c: {"fn_hz": max(0.4 * c.fs / s, 150.0), "zeta": 0.03 + 0.2 * float(c.draws[4])},
        (1.0, 2000.0),
    ),
    "drift": (lambda s, c: {"rate_um_per_s": math.copysign(s, c.draws[5] - 0.5)}, (1e-4, 10.0)),
    "delay": (lambda s, c: {"samples": min(8, max(1, round(s)))}, (1.0, 8.0)),
    "gain_drift": (lambda s, c: {"rate_per_s": math.copysign(s, c.draws[1] - 0.5)}, (1e-6, 1.0)),
    "electrostriction": (lambda s, c: {"epsilon_per_um": math.copysign(s, c.draws[2] - 0.3)}, (1e-7, 0.05)),
    "pickup": (
        lambda s, c: {
            "line_hz": 50.0 if c.draws[0] < 0.5 else 60.0,
            "sin_um": [s * math.cos(2 * math.pi * c.draws[3]), 0.0, 0.3 * s],
            "cos_um": [s * math.sin(2 * math.pi * c.draws[3]), 0.0, 0.0],
        },
        (1e-5, 10.0),
    ),
    "saturation": (
        lambda s, c: {"min_um": c.x_lo - (c.x_hi - c.x_lo), "max_um": c.x_hi - s * (c.x_hi - c.x_lo)},
        (1e-6, 0.5),
    ),
    "resonance2": (
        lambda s, c: {"fn_hz": max(0.4 * c.fs / s, 150.0), "zeta": 0.03 + 0.2 * float(c.draws[6])},
        (1.0, 2000.0),
    ),
}


def _cubic_sensor(x: FloatArray, u: FloatArray, t: FloatArray, s: float, c: _Ctx) -> FloatArray:
    # A sensor whose gain bends at the ends of its range.
    mid, half = 0.5 * (c.x_hi + c.x_lo), max(0.5 * (c.x_hi - c.x_lo), 1e-9)
    out: FloatArray = x + s * half * ((x - mid) / half) ** 3
    return out


def _settling_drift(x: FloatArray, u: FloatArray, t: FloatArray, s: float, c: _Ctx) -> FloatArray:
    # A thermal offset that settles within the record (τ 0.1–0.3 of its length).
    tau = (0.1 + 0.2 * float(c.draws[7])) * c.duration_s
    out: FloatArray = x + s * (1.0 - np.exp(-t / tau))
    return out


def _backlash(x: FloatArray, u: FloatArray, t: FloatArray, s: float, c: _Ctx) -> FloatArray:
    # Mechanical play of width s [µm] between the stack and the measured stage: the
    # stage moves only once the stack has taken up the play.
    out = np.empty_like(x)
    y = float(x[0])
    half = 0.5 * s
    for k, v in enumerate(x.tolist()):
        if v > y + half:
            y = v - half
        elif v < y - half:
            y = v + half
        out[k] = y
    return out


#: Strength s → the displacement with an effect outside the vocabulary, and the range
#: of s; keyed by the name it would have in the vocabulary.
OUTSIDE_MAKERS: dict[
    str, tuple[Callable[[FloatArray, FloatArray, FloatArray, float, _Ctx], FloatArray], tuple[float, float]]
] = {
    "backlash": (_backlash, (1e-5, 20.0)),
    "cubic_sensor": (_cubic_sensor, (1e-6, 1.0)),
    "settling_drift": (_settling_drift, (1e-5, 10.0)),
}


def size_um(with_effect: FloatArray, without: FloatArray) -> float:
    """The size of an effect [µm]: RMS of ``with_effect − without`` beyond its
    projection on an affine map of ``without``."""
    d = with_effect - without
    basis = np.column_stack([without, np.ones_like(without)])
    coef, *_ = np.linalg.lstsq(basis, d, rcond=None)
    return float(np.sqrt(np.mean((d - basis @ coef) ** 2)))


#: Points of the log-spaced grid of strengths scanned when the size at the top of a
#: maker's range is below the one asked (a size that falls again at large strengths:
#: play wider than the stroke leaves the stage still, a size of 0).
_SCAN = 25


def _strength(size_of: Callable[[float], float], lo: float, hi: float, target: float) -> tuple[float, float]:
    """The strength in [lo, hi] whose size is nearest ``target`` (bisection in log s),
    and that size.

    When the size at ``hi`` is below ``target``, a grid of :data:`_SCAN` strengths is
    scanned: the bisection runs between the first that reaches ``target`` and the one
    before it, and without one the strength of largest size is returned."""
    a, b = math.log(lo), math.log(hi)
    best = (hi, size_of(hi))
    if best[1] <= target:
        grid = [(s, size_of(s)) for s in np.geomspace(lo, hi, _SCAN).tolist()]
        above = [k for k, (_, v) in enumerate(grid) if v > target]
        if not above:
            return max([best, *grid], key=lambda sv: sv[1])
        k = above[0]
        if k == 0:
            return grid[0]
        a, b = math.log(grid[k - 1][0]), math.log(grid[k][0])
        best = grid[k]
    for _ in range(24):
        m = 0.5 * (a + b)
        s = size_of(math.exp(m))
        if abs(math.log(max(s, 1e-12) / target)) < abs(math.log(max(best[1], 1e-12) / target)):
            best = (math.exp(m), s)
        if s < target:
            a = m
        else:
            b = m
        if abs(s / target - 1.0) < 0.02:
            break
    return best


@dataclass(frozen=True, eq=False)
class SuiteRecord:
    """One generated record.

    Attributes:
        label: short description; family, fs_hz, param_set, noise_um, seed: how it was made.
        inside: effects of the vocabulary put in (names); outside: effects outside it.
        sizes_um: the size reached per effect [µm]; params: each inside effect's parameters.
        u [V], x [µm] (with noise), x_true [µm] (noise-free), dt [s].
    """

    label: str
    family: str
    fs_hz: float
    param_set: str
    noise_um: float
    seed: int
    inside: tuple[str, ...]
    outside: tuple[str, ...]
    sizes_um: dict[str, float]
    params: dict[str, Any]
    u: FloatArray
    x: FloatArray
    x_true: FloatArray
    dt: float
    notes: list[str] = field(default_factory=list)


def _simulate(params: Params, effects: dict[str, Any], u: FloatArray, dt: float) -> FloatArray:
    return simulate_oversampled(params, set_of(effects), u, dt, _OVERSAMPLE)


def make_suite_record(
    effects: Sequence[tuple[str, float]],
    family: str,
    seed: int,
    *,
    fs_hz: float = 10_000.0,
    param_set: str = "paper_1hz",
    noise_um: float = 0.005,
    duration_s: float = DURATION_S,
) -> SuiteRecord:
    """One record: ``effects`` as (name, size [µm]) pairs, each inside the vocabulary
    (:data:`VOCABULARY_MAKERS`, name in :data:`boucwen.effects.VOCABULARY`) or outside
    it (:data:`OUTSIDE_MAKERS`, name not in the vocabulary); ValueError for a name that
    is neither. ``duration_s``: record length [s]."""
    rng = np.random.default_rng(seed)
    u = excitation(family, fs_hz, rng, duration_s)
    dt = 1.0 / fs_hz
    t = np.arange(u.size, dtype=np.float64) * dt
    params = PARAM_SETS[param_set]
    x_plain = _simulate(params, {}, u, dt)
    ctx = _Ctx(
        fs=fs_hz,
        duration_s=t[-1],
        kv=params.kv,
        draws=rng.uniform(size=8),
        x_lo=float(np.min(x_plain)),
        x_hi=float(np.max(x_plain)),
    )
    inside = [(n, s) for n, s in effects if n in VOCABULARY and n in VOCABULARY_MAKERS]
    outside = [(n, s) for n, s in effects if n not in VOCABULARY and n in OUTSIDE_MAKERS]
    unknown = [n for n, _ in effects if (n, dict(effects)[n]) not in inside + outside]
    if unknown:
        raise ValueError(f"effects {unknown} are neither in the vocabulary with a maker nor outside it")
    chosen: dict[str, Any] = {}
    sizes: dict[str, float] = {}
    for name, target in inside:
        make, (lo, hi) = VOCABULARY_MAKERS[name]

        def sized(s: float, name: str = name, make: Callable[[float, _Ctx], dict[str, Any]] = make) -> float:
            return size_um(_simulate(params, {name: make(s, ctx)}, u, dt), x_plain)

        if name == "delay":  # whole samples: the nearest of 1 … 8
            s = min(range(1, 9), key=lambda k: abs(math.log(max(sized(float(k)), 1e-12) / target)))
            strength, reached = float(s), sized(float(s))
        else:
            strength, reached = _strength(sized, lo, hi, target)
        chosen[name] = make(strength, ctx)
        sizes[name] = reached
    x_in = _simulate(params, chosen, u, dt)
    x_true = x_in
    for name, target in outside:
        apply, (lo, hi) = OUTSIDE_MAKERS[name]
        base = x_true

        def sized_out(s: float, apply: Any = apply, base: FloatArray = base) -> float:
            return size_um(apply(base, u, t, s, ctx), base)

        strength, reached = _strength(sized_out, lo, hi, target)
        x_true = apply(base, u, t, strength, ctx)
        sizes[name] = reached
    x = x_true + rng.normal(0.0, noise_um, u.size)
    names = "+".join(n for n, _ in effects) or "none"
    label = f"{names} {family} {fs_hz / 1e3:g}kHz {param_set} σ={noise_um * 1e3:g}nm seed={seed}"
    return SuiteRecord(
        label=label,
        family=family,
        fs_hz=fs_hz,
        param_set=param_set,
        noise_um=noise_um,
        seed=seed,
        inside=tuple(n for n, _ in inside),
        outside=tuple(n for n, _ in outside),
        sizes_um=sizes,
        params=chosen,
        u=u,
        x=x,
        x_true=x_true,
        dt=dt,
    )
