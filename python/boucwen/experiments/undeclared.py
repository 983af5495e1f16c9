"""Records with one undeclared effect, and the table of what the diagnosis makes of them.

``python -m boucwen.experiments.undeclared [--quick] [--seeds N]`` generates records —
several seeds, base parameter sets (the paper's Table 2 rows) and noise levels — each
holding one effect of the vocabulary (creep, input_lag, resonance, drift, delay) or
none, runs :func:`boucwen.diagnose` on each without telling it what is inside, and
prints one row per record: the effect put in, what was named, and the RMS error
against the *noise-free* signal [µm] before (base model) → after (with the named
effects). With ``--online`` it prints instead how the online identifier
(``method="rpem"``, started from the base fit) compares with the offline fits
(:mod:`boucwen.experiments.undeclared_online`).

The input (:func:`test_input`) repeats a pattern three times with random levels: fast
steps followed by holds, a full-range slow sweep, minor loops, sine bursts at
2–60 Hz. The held-out last 30 % of the record thus holds the same kinds of motion as
the fitting part.

Records are simulated with :func:`boucwen.simulate_extended` on a grid 8× finer than
the sampling (the input interpolated linearly) and then sampled, with creep time
constants (0.01, 0.1, 1, 10 s) that differ from the ones the diagnosis uses, so
the diagnosis never sees its own discretisation. Effect sizes are drawn from the
ranges in :data:`EFFECT_RANGES`.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .._core import EffectSet, Params, simulate_extended

__all__ = [
    "test_input",
    "make_record",
    "UndeclaredRecord",
    "run_table",
    "PARAM_SETS",
    "NOISE_LEVELS_UM",
    "EFFECT_RANGES",
    "DT",
    "main",
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


def test_input(dt: float = DT, seed: int = 0, repeats: int = 3) -> np.ndarray:
    """A test voltage [V] within 0…100 V: ``repeats`` copies of a randomised pattern.

    Each pattern: step and hold at a low level, step up and hold, a slow full-range
    sweep (2 Hz), minor loops (5 Hz, ±10–15 V around a random level), sine bursts at
    20 Hz and 60 Hz, step down and hold. Steps take one sample interval.
    """
    rng = np.random.default_rng(seed)
    pieces: list[np.ndarray] = [np.array([20.0])]

    def hold(seconds: float) -> None:
        pieces.append(np.full(max(1, int(round(seconds / dt))), pieces[-1][-1]))

    def step(level: float) -> None:
        pieces.append(np.array([level]))

    def burst(freq: float, centre: float, amp: float, cycles: float) -> None:
        step(centre - amp)
        m = int(round(cycles / freq / dt))
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
    u: np.ndarray
    x: np.ndarray
    x_true: np.ndarray
    dt: float
    params: Params
    effects: EffectSet
    noise_um: float
    label: str


def _draw_effect(effect: str, rng: np.random.Generator, dt: float) -> dict[str, Any]:
    r = EFFECT_RANGES.get(effect)
    if effect == "none":
        return {}
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
        return {"delay": {"samples": int(rng.integers(lo, hi + 1))}}
    raise ValueError(f"unknown effect {effect!r}")


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
    kw = _draw_effect(effect, rng, dt)
    u = test_input(dt, seed)
    params = PARAM_SETS[param_set]
    fine_dt = dt / _OVERSAMPLE
    t_fine = np.arange((u.size - 1) * _OVERSAMPLE + 1) * fine_dt
    u_fine = np.interp(t_fine, np.arange(u.size) * dt, u)
    fine_kw = dict(kw)
    if "delay" in fine_kw:
        fine_kw["delay"] = {"samples": kw["delay"]["samples"] * _OVERSAMPLE}
    x_true = simulate_extended(params, EffectSet(**fine_kw), u_fine, fine_dt)[::_OVERSAMPLE]
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


def _describe(effects: EffectSet) -> str:
    d = effects.to_dict()
    parts = []
    for name, v in d.items():
        if name == "creep":
            parts.append(f"creep Σg={sum(v['gain_um_per_v']):.3g} µm/V")
        elif name == "input_lag":
            parts.append(f"fc={v['fc_hz']:.3g} Hz")
        elif name == "resonance":
            parts.append(f"fn={v['fn_hz']:.3g} Hz ζ={v['zeta']:.2g}")
        elif name == "drift":
            parts.append(f"{v['rate_um_per_s']:+.3g} µm/s")
        elif name == "delay":
            parts.append(f"d={v['samples']}")
    return ", ".join(parts) or "-"


def cases(seeds: int = 3) -> list[tuple[str, int, str, float]]:
    """(effect, seed, param_set, noise_um) for the table: every effect and "none",
    ``seeds`` seeds each, cycling through parameter sets and noise levels."""
    out = []
    sets = list(PARAM_SETS)
    for effect in ("none", "creep", "input_lag", "resonance", "drift", "delay"):
        for s in range(seeds):
            out.append((effect, s, sets[s % len(sets)], NOISE_LEVELS_UM[s % len(NOISE_LEVELS_UM)]))
    return out


def run_table(seeds: int = 3, out=sys.stdout) -> list[dict[str, Any]]:
    """Runs the diagnosis on :func:`cases` and prints the table; returns its rows."""
    from ..diagnose import diagnose

    rows = []
    header = (
        f"{'effect':10s} {'set':11s} {'noise':>6s} {'seed':>4s}  {'true parameters':28s} "
        f"{'named':22s} {'RMS vs noise-free before → after [µm]':>38s} {'time':>6s}"
    )
    print(header, file=out)
    print("-" * len(header), file=out)
    for effect, seed, pset, noise in cases(seeds):
        rec = make_record(effect, seed, pset, noise)
        t0 = time.perf_counter()
        d = diagnose(rec.u, rec.x, rec.dt, seed=seed)
        elapsed = time.perf_counter() - t0
        before = float(np.sqrt(np.mean((d.x_base - rec.x_true) ** 2)))
        after = float(np.sqrt(np.mean((d.x_extended - rec.x_true) ** 2)))
        named = ",".join(d.effects) or "none"
        ok = (named == effect) and (effect == "none" or after < before)
        rows.append(
            {
                "effect": effect,
                "param_set": pset,
                "noise_um": noise,
                "seed": seed,
                "named": named,
                "rms_before_um": before,
                "rms_after_um": after,
                "elapsed_s": elapsed,
                "ok": ok,
            }
        )
        print(
            f"{effect:10s} {pset:11s} {noise * 1e3:4g}nm {seed:4d}  {_describe(rec.effects):28s} "
            f"{named:22s} {before:17.4f} → {after:<17.4f} {elapsed:5.1f}s"
            f"{'' if ok else '  MISS'}",
            file=out,
            flush=True,
        )
    hits = sum(r["ok"] for r in rows)
    print(f"{hits}/{len(rows)} records diagnosed correctly", file=out)
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.undeclared", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--seeds", type=int, default=3, help="records per effect (default 3)")
    parser.add_argument(
        "--online",
        action="store_true",
        help="instead: RMS of the offline base, offline extended and online rpem "
        "models (markdown table; see boucwen.experiments.undeclared_online)",
    )
    args = parser.parse_args(argv)
    if args.online:
        from .undeclared_online import run_online_table

        run_online_table(args.seeds)
        return 0
    rows = run_table(args.seeds)
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
