"""Generated records that hold one undeclared effect each (or none).

The input (:func:`test_input`) repeats a pattern three times with random levels: fast
steps followed by holds, a full-range slow sweep, minor loops, sine bursts at
2–60 Hz. Every part of a record thus holds the same kinds of motion.

Records are simulated with :func:`boucwen.plant.simulate_oversampled` on a grid 8× finer than
the sampling (the input interpolated linearly) and then sampled, with creep time
constants (0.01, 0.1, 1, 10 s) that differ from the ones the diagnosis uses, so
the diagnosis never sees its own discretisation. Effect sizes are drawn from the
ranges in :data:`EFFECT_RANGES`. Used by :mod:`boucwen.experiments.undeclared` (the
diagnosis table) and :mod:`boucwen.experiments.undeclared_online` (online
identification).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._core import EffectSet, Params
from ..checks import FloatArray
from ..plant import simulate_oversampled

__all__ = [
    "DT",
    "EFFECT_RANGES",
    "NOISE_LEVELS_UM",
    "PARAM_SETS",
    "UndeclaredRecord",
    "cases",
    "make_record",
    "test_input",
]

#: Sampling interval of the generated records [s] (1 kHz).
DT = 1e-3
#: Base parameter sets: the paper's Table 2 rows at 1, 100 and 200 Hz.
PARAM_SETS: dict[str, Params] = {
    "paper_1hz": Params(0.19, 0.015, -0.072, 0.020, -0.019, 1.52, 0.0075),
    "paper_100hz": Params(0.18, 0.021, -0.072, 0.023, -0.018, 1.51, 0.0063),
    "paper_200hz": Params(0.16, 0.013, -0.10, 0.015, -0.005, 1.68, 0.0045),
}
#: White measurement-noise levels [µm].
NOISE_LEVELS_UM = (0.001, 0.005, 0.02)
#: Ranges the effect parameters are drawn from (uniform; log-uniform for fc, fn).
EFFECT_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "creep": {"total_gain_um_per_v": (0.006, 0.015)},
    "input_lag": {"fc_hz": (30.0, 120.0)},
    "resonance": {"fn_hz": (60.0, 200.0), "zeta": (0.03, 0.15)},
    "drift": {"abs_rate_um_per_s": (0.1, 0.3)},
    "delay": {"samples": (2, 5)},
}
_CREEP_TAU_S = (0.01, 0.1, 1.0, 10.0)
_OVERSAMPLE = 8


def test_input(dt: float = DT, seed: int = 0, repeats: int = 3) -> FloatArray:
    """A test voltage [V] within 0…100 V: ``repeats`` copies of a randomised pattern.

    Each pattern: step and hold at a low level, step up and hold, a slow full-range
    sweep (2 Hz), minor loops (5 Hz, ±10–15 V around a random level), sine bursts at
    20 Hz and 60 Hz, step down and hold. Steps take one sample interval.
    """
    rng = np.random.default_rng(seed)
    pieces: list[FloatArray] = [np.array([20.0])]

    def hold(seconds: float) -> None:
        pieces.append(np.full(max(1, round(seconds / dt)), pieces[-1][-1]))

    def step(level: float) -> None:
        pieces.append(np.array([level]))

    def burst(freq: float, centre: float, amp: float, cycles: float) -> None:
        step(centre - amp)
        m = round(cycles / freq / dt)
        t = np.arange(1, m + 1) * dt
        pieces.append(centre - amp * np.cos(2 * np.pi * freq * t))

    for _ in range(repeats):
        step(rng.uniform(5, 25))
        hold(0.25)
        step(rng.uniform(70, 95))
        hold(0.3)
        burst(2.0, 50.0, 48.0, 1.0)
        hold(0.1)
        burst(5.0, rng.uniform(35, 65), rng.uniform(10, 15), 3.0)
        burst(20.0, 50.0, rng.uniform(25, 40), 4.0)
        hold(0.1)
        burst(60.0, rng.uniform(40, 60), rng.uniform(15, 25), 6.0)
        step(rng.uniform(20, 40))
        hold(0.25)
    return np.concatenate(pieces)


@dataclass(frozen=True, eq=False)
class UndeclaredRecord:
    """A generated record.

    Attributes:
        effect: the effect put in ("none" for none).
        u: voltage [V]; x: measured displacement [µm] (with noise); x_true: noise-free [µm].
        dt: sampling interval [s].
        params: base :class:`Params`; effects: the :class:`EffectSet` used; noise_um.
        label: short description for tables.
    """

    effect: str
    u: FloatArray
    x: FloatArray
    x_true: FloatArray
    dt: float
    params: Params
    effects: EffectSet
    noise_um: float
    label: str


def _draw_effect(effect: str, rng: np.random.Generator) -> dict[str, Any]:
    """EffectSet keyword arguments for ``effect``, its parameters drawn from :data:`EFFECT_RANGES`."""
    if effect == "none":
        return {}
    r = EFFECT_RANGES.get(effect)
    if r is None:
        raise ValueError(f"unknown effect {effect!r}; expected 'none' or one of {list(EFFECT_RANGES)}")
    if effect == "creep":
        total = rng.uniform(*r["total_gain_um_per_v"])
        w = rng.dirichlet(np.ones(len(_CREEP_TAU_S)) * 3.0)
        return {"creep": {"tau_s": list(_CREEP_TAU_S), "gain_um_per_v": list(total * w)}}
    if effect == "input_lag":
        lo, hi = r["fc_hz"]
        return {"input_lag": {"fc_hz": float(math.exp(rng.uniform(math.log(lo), math.log(hi))))}}
    if effect == "resonance":
        lo, hi = r["fn_hz"]
        return {
            "resonance": {
                "fn_hz": float(math.exp(rng.uniform(math.log(lo), math.log(hi)))),
                "zeta": float(rng.uniform(*r["zeta"])),
            }
        }
    if effect == "drift":
        return {"drift": {"rate_um_per_s": float(rng.choice([-1, 1]) * rng.uniform(*r["abs_rate_um_per_s"]))}}
    if effect == "delay":
        lo, hi = r["samples"]
        return {"delay": {"samples": int(rng.integers(int(lo), int(hi) + 1))}}
    raise ValueError(f"unknown effect {effect!r}")  # pragma: no cover - EFFECT_RANGES names the effects above


def make_record(
    effect: str, seed: int = 0, param_set: str = "paper_1hz", noise_um: float = 0.005, dt: float = DT
) -> UndeclaredRecord:
    """One record holding ``effect`` (a vocabulary name or "none").

    Effect parameters are drawn with ``seed`` from :data:`EFFECT_RANGES`; the input is
    :func:`test_input` with the same seed.
    """
    if param_set not in PARAM_SETS:
        raise ValueError(f"unknown param_set {param_set!r}; expected one of {list(PARAM_SETS)}")
    rng = np.random.default_rng(10_000 + seed)
    kw = _draw_effect(effect, rng)
    u = test_input(dt, seed)
    params = PARAM_SETS[param_set]
    x_true = simulate_oversampled(params, EffectSet(**kw), u, dt, _OVERSAMPLE)
    x = x_true + rng.normal(0.0, noise_um, x_true.size)
    label = f"{effect} {param_set} σ={noise_um * 1e3:g}nm seed={seed}"
    return UndeclaredRecord(
        effect=effect,
        u=u,
        x=x,
        x_true=np.ascontiguousarray(x_true),
        dt=dt,
        params=params,
        effects=EffectSet(**kw),
        noise_um=noise_um,
        label=label,
    )


def cases(seeds: int = 3) -> list[tuple[str, int, str, float]]:
    """(effect, seed, param_set, noise_um) for the table: every effect and "none",
    ``seeds`` seeds each, cycling through parameter sets and noise levels."""
    out: list[tuple[str, int, str, float]] = []
    sets = list(PARAM_SETS)
    for effect in ("none", "creep", "input_lag", "resonance", "drift", "delay"):
        for s in range(seeds):
            out.append((effect, s, sets[s % len(sets)], NOISE_LEVELS_UM[s % len(NOISE_LEVELS_UM)]))
    return out
