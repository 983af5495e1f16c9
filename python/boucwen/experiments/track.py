"""Closed-loop tracking with hysteresis compensation on the simulated bench.

Steps of :func:`run`:

1. **Identification** (per bench, as a user would do it): the bench is driven with
   the paper's 1 Hz sine, u = 50 − 50·cos(2πt) [V], for :data:`IDENTIFICATION_S`
   (3 s; 2 s on the generated plants) and measured; :func:`boucwen.fit` gives the
   *traditional* parameters, and the least-squares line x = k·u + c through the same
   record gives the *linear* model.
2. **References** (:func:`references`), each 0–20 µm (:data:`RANGE_UM`) at 10 kHz:
   sines x_d = 10·(1 − cos 2πft) µm at 1, 10, 50, 100 and 200 Hz, a 10 Hz triangle, a
   staircase of 1 s holds (10, 20, 5 µm; each step a 5 ms raised-cosine
   transition, since no amplifier steps in zero time) and band-limited random motion
   (seeded white noise through a zero-phase 4th-order Butterworth low-pass at 100 Hz,
   scaled to 0–20 µm).
3. **Methods** (:data:`METHODS`), each a :class:`boucwen.Compensator` (one call per
   sample, u_k = step(x_d,k, x_k−1)) within the voltage limits :data:`U_LIMITS_V`
   (−30…120 V, the operating range of a PICMA P-885 stack):

   - ``linear``: u from the linear model's straight line (open loop);
   - ``inverse_fixed``: the inverse of the traditional parameters, held fixed;
   - ``inverse_adaptive``: the inverse of the online estimates ("rpem", default
     configuration, started from the traditional parameters);
   - ``horizon_adaptive``: the same with the recommended identifier ("horizon", its
     input lag identified and inverted through the extended inverse) on the split:
     ``step`` pushes at model-step cost, the window pass runs cooperatively,
     ``refine(COOPERATIVE_INTERVALS)`` after every step (:mod:`boucwen.pacing`);
   - ``pi``: PI feedback alone, x_cmd = v, through the linear model's line, with
     kp = 0.2, ki = 3000 /s (:data:`PI_GAINS`);
   - ``pi_adaptive``: PI + adaptive inverse with kp = 0, ki = 200 /s
     (:data:`PI_ADAPTIVE_GAINS`). The identifier's offset x0, which walks to follow
     what the model misses, already acts on the error one sample later, like an
     integrator; a second integrator as strong as the PI alone's (or any
     proportional term) then makes the estimates drift in closed loop, so the PI
     here is ten times slower.

4. **Closed loop**: for every bench, reference and method a fresh
   :class:`boucwen.plant.Bench` (noise seed :func:`_noise_seed`) and a fresh
   compensator; the compensator sees the vibrometer reading of the previous sample.
5. **Metrics** (:func:`tracking_metrics`): max and RMS of |x − x_d| [µm and % of the
   reference's range], x the vibrometer reading, after one period of adaptation
   (the first period of a sine or triangle, the first hold of the staircase, the
   first 0.1 s of the random motion); and the compensator's cost per sample [ns]:
   the mean wall time of ``step`` and of ``refine`` over the run, each timed around
   the Python call (so the call's own overhead, some 100 ns, is included).
6. Both benches: the default one with its floor vibration switched off, then on
   (:data:`BENCHES`); the targets (:func:`check_targets`) are checked on the bench
   each names; the literature anchors (:data:`ANCHORS`) are printed beside.
7. **Generated plants** (:func:`generated_plant`, ``plants`` of them, seeded): the
   adaptive inverse only, each plant identified as in step 1; the median and worst
   max error per reference.
8. ``DIR/results.json`` and one figure per reference on the default bench (floor
   vibration on), ``DIR/<reference>.png``: x_d and every method's x, the error, x
   against x_d.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .. import plant
from .._core import Compensator, Params
from ..fit import FitResult, fit
from ..pacing import COOPERATIVE_INTERVALS

__all__ = [
    "ANCHORS",
    "BENCHES",
    "DEFAULT_OUT",
    "METHODS",
    "PI_ADAPTIVE_GAINS",
    "PI_GAINS",
    "RANGE_UM",
    "U_LIMITS_V",
    "Identification",
    "Method",
    "Reference",
    "check_targets",
    "closed_loop",
    "generated_plant",
    "identify",
    "references",
    "run",
    "tracking_metrics",
]

#: Default output directory of ``boucwen track``.
DEFAULT_OUT = os.path.join("out", "track")
#: Stroke every reference spans [µm].
RANGE_UM = 20.0
#: Voltage limits of every method [V]: the operating range of a PICMA P-885 stack.
U_LIMITS_V = (-30.0, 120.0)
#: Length of the identification record [s] on the two benches and on generated plants.
IDENTIFICATION_S = 3.0
IDENTIFICATION_GENERATED_S = 2.0
#: Feedback of the ``pi`` method: kp [-], ki [1/s].
PI_GAINS = {"kp": 0.2, "ki": 3000.0}
#: Feedback of the ``pi_adaptive`` method: kp [-], ki [1/s].
PI_ADAPTIVE_GAINS = {"kp": 0.0, "ki": 200.0}

#: The benches of the table: the default bench with its floor vibration off, then on.
BENCHES: dict[str, plant.BenchSettings] = {
    "vibration_off": plant.BenchSettings(vibration_um=(0.0, 0.0)),
    "vibration_on": plant.BenchSettings(),
}

#: The bench whose runs are drawn (one figure per reference).
FIGURE_BENCH = "vibration_on"

#: Published results to beat (max tracking error in % of range, before → after).
ANCHORS: tuple[dict[str, str], ...] = (
    {
        "method": "inverse multiplicative structure, Bouc-Wen (Rakotondrabe)",
        "max_error_pct": "23 -> < 2.5",
    },
    {
        "method": "discrete backlash inverse, Aye & Ang 2018 (the measured record micromanipulator_compensated)",
        "max_error_pct": "9.9 -> 3-4",
        "rms_error_pct": "3.8 -> 0.65-1.15",
    },
    {"method": "model-based dynamics inversion, at 150 Hz", "max_error_pct": "43 -> 3.4"},
)


# --------------------------------------------------------------------------- references


@dataclass(frozen=True)
class Reference:
    """One desired trajectory.

    Attributes:
        name: key in the results (e.g. ``sine_10hz``).
        label: for tables and figures.
        x_d: desired displacement [µm], one value per sample.
        adaptation: samples of the adaptation period (left out of the metrics).
        frequency_hz: the frequency of a sine or triangle [Hz] (None otherwise).
    """

    name: str
    label: str
    x_d: np.ndarray = field(repr=False)
    adaptation: int
    frequency_hz: float | None = None


#: Sines: (frequency [Hz], periods), full and --quick.
SINES = ((1.0, 2), (10.0, 3), (50.0, 5), (100.0, 5), (200.0, 10))
QUICK_SINES = ((1.0, 2), (10.0, 2), (50.0, 2), (100.0, 3), (200.0, 4))
#: Staircase levels [µm], one hold each.
STAIRCASE_LEVELS_UM = (10.0, 20.0, 5.0)
#: Staircase hold [s] (full and --quick) and transition [s].
STAIRCASE_HOLD_S, QUICK_STAIRCASE_HOLD_S, STAIRCASE_TRANSITION_S = 1.0, 0.25, 0.005
#: Random motion: length [s] (full and --quick), adaptation [s], band [Hz].
RANDOM_S, QUICK_RANDOM_S, RANDOM_ADAPTATION_S, RANDOM_BAND_HZ = 1.0, 0.3, 0.1, 100.0


def _samples(duration_s: float, dt: float) -> int:
    return round(duration_s / dt)


def _raised_cosine_steps(levels: Sequence[float], hold: int, ramp: int) -> np.ndarray:
    """Holds of ``hold`` samples; each starts with a raised cosine of ``ramp`` samples from the
    previous level (from 0 for the first), so the first sample is 0 and level i is held from
    sample i·hold + ramp on."""
    out = np.empty(hold * len(levels), dtype=np.float64)
    previous = 0.0
    shape = 0.5 - 0.5 * np.cos(np.pi * np.arange(ramp) / ramp)
    for i, level in enumerate(levels):
        seg = out[i * hold : (i + 1) * hold]
        seg[:] = level
        seg[:ramp] = previous + (level - previous) * shape
        previous = level
    return out


def references(dt: float = plant.DEFAULT_DT, quick: bool = False, seed: int = 0) -> list[Reference]:
    """The references of the experiment (module docs, step 2), each spanning 0–20 µm.

    Args:
        dt: sampling interval [s].
        quick: shorter references (fewer periods, 0.25 s holds, 0.3 s of random motion).
        seed: seed of the random motion.
    """
    out: list[Reference] = []
    for f, periods in QUICK_SINES if quick else SINES:
        period = _samples(1.0 / f, dt)
        t = np.arange(period * periods) * dt
        x_d = 0.5 * RANGE_UM * (1.0 - np.cos(2.0 * np.pi * f * t))
        out.append(Reference(f"sine_{f:g}hz", f"sine {f:g} Hz", x_d, period, f))
    f = 10.0
    period = _samples(1.0 / f, dt)
    phase = (np.arange(period * (2 if quick else 3)) % period) / period
    triangle = RANGE_UM * (1.0 - np.abs(2.0 * phase - 1.0))
    out.append(Reference("triangle_10hz", "triangle 10 Hz", triangle, period, f))
    hold = _samples(QUICK_STAIRCASE_HOLD_S if quick else STAIRCASE_HOLD_S, dt)
    stairs = _raised_cosine_steps(STAIRCASE_LEVELS_UM, hold, _samples(STAIRCASE_TRANSITION_S, dt))
    out.append(Reference("staircase", f"staircase, {hold * dt:g} s holds", stairs, hold))
    out.append(_random_reference(dt, QUICK_RANDOM_S if quick else RANDOM_S, seed))
    return out


def _random_reference(dt: float, duration_s: float, seed: int) -> Reference:
    from scipy.signal import butter, sosfiltfilt

    n = _samples(duration_s, dt)
    pad = _samples(0.2, dt)
    rng = np.random.default_rng(seed)
    sos = butter(4, RANDOM_BAND_HZ, fs=1.0 / dt, output="sos")
    motion = sosfiltfilt(sos, rng.standard_normal(n + 2 * pad))[pad:-pad]
    x_d = RANGE_UM * (motion - motion.min()) / (motion.max() - motion.min())
    label = f"random, <= {RANDOM_BAND_HZ:g} Hz"
    return Reference("random", label, x_d, _samples(RANDOM_ADAPTATION_S, dt))


# --------------------------------------------------------------------------- identification and methods


@dataclass(frozen=True)
class Identification:
    """What a user identifies on a bench before compensating.

    Attributes:
        traditional: the offline fit of the 1 Hz record (:class:`boucwen.FitResult`).
        line: the least-squares line through the same record as a hysteresis-free
            model, kv = slope [µm/V], x0 = intercept [µm], A = β = γ = δ = 0.
    """

    traditional: FitResult
    line: Params


def identify(settings: plant.BenchSettings, dt: float, duration_s: float, seed: int) -> Identification:
    """Fits the traditional model and the straight line to a 1 Hz record of the bench (module docs, step 1)."""
    _, u, _ = plant.paper_input(dt, ((1.0, duration_s),))
    rec = plant.measure(u, dt, settings, seed=seed)
    traditional = fit(rec.u, rec.x, dt, seed=seed)
    slope, intercept = np.polyfit(rec.u, rec.x, 1)
    return Identification(traditional, Params(float(slope), float(intercept), 0.0, 0.0, 0.0, 1.0, 0.0))


@dataclass(frozen=True)
class Method:
    """One compensation method.

    Attributes:
        name: key in the results.
        label: for tables and figures.
        make: builds a fresh compensator from an identification and dt [s].
        refine_intervals: ``compensator.refine(refine_intervals)`` after every step
            (the cooperative schedule of a split identifier; 0: none).
    """

    name: str
    label: str
    make: Callable[[Identification, float], Compensator] = field(repr=False)
    refine_intervals: int = 0


def _compensator(
    params: Params,
    dt: float,
    *,
    adapt: bool,
    gains: Mapping[str, float] | None = None,
    feedforward: bool = True,
    recommended: bool = False,
) -> Compensator:
    """A compensator within :data:`U_LIMITS_V` with PI gains ``{"kp": [-], "ki": [1/s]}`` (none by
    default); ``recommended``: around the recommended identifier, its window pass cooperative."""
    g = gains or {}
    return Compensator(
        params,
        dt,
        u_min=U_LIMITS_V[0],
        u_max=U_LIMITS_V[1],
        adapt=adapt,
        kp=g.get("kp", 0.0),
        ki=g.get("ki", 0.0),
        feedforward=feedforward,
        identifier="horizon" if recommended else "rpem",
        refine="cooperative" if recommended else "sync",
    )


#: The methods compared (module docs, step 3), in table order.
METHODS: tuple[Method, ...] = (
    Method("linear", "linear open loop", lambda ident, dt: _compensator(ident.line, dt, adapt=False)),
    Method(
        "inverse_fixed",
        "inverse, traditional parameters (fixed)",
        lambda ident, dt: _compensator(ident.traditional.params, dt, adapt=False),
    ),
    Method(
        "inverse_adaptive",
        "adaptive inverse",
        lambda ident, dt: _compensator(ident.traditional.params, dt, adapt=True),
    ),
    Method(
        "horizon_adaptive",
        "adaptive inverse, recommended identifier (lag inverted, cooperative)",
        lambda ident, dt: _compensator(ident.traditional.params, dt, adapt=True, recommended=True),
        COOPERATIVE_INTERVALS,
    ),
    Method(
        "pi",
        "PI feedback alone",
        lambda ident, dt: _compensator(ident.line, dt, adapt=False, gains=PI_GAINS, feedforward=False),
    ),
    Method(
        "pi_adaptive",
        "PI + adaptive inverse",
        lambda ident, dt: _compensator(ident.traditional.params, dt, adapt=True, gains=PI_ADAPTIVE_GAINS),
    ),
)


# --------------------------------------------------------------------------- loop and metrics


def closed_loop(
    compensator: Compensator,
    bench: plant.Bench,
    x_d: np.ndarray,
    refine_intervals: int = 0,
    cost_ns: dict[str, float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Runs the loop u_k = compensator.step(x_d,k, x_k−1), x_k = bench.step(u_k), with
    ``compensator.refine(refine_intervals)`` after every step when > 0.

    Args:
        cost_ns: if given, filled with the mean wall time per sample [ns] of ``step``
            ("step") and of ``refine`` ("refine"), each timed around the Python call.

    Returns:
        ``(u, x)``: the voltages [V] and the vibrometer readings [µm].
    """
    step, apply, refine = compensator.step, bench.step, compensator.refine
    clock = time.perf_counter_ns
    u_out: list[float] = []
    x_out: list[float] = []
    x_meas: float | None = None
    step_ns = refine_ns = 0
    for target in x_d.tolist():
        t0 = clock()
        u = step(target, x_meas)
        t1 = clock()
        if refine_intervals:
            refine(refine_intervals)
            refine_ns += clock() - t1
        step_ns += t1 - t0
        x_meas = apply(u)
        u_out.append(u)
        x_out.append(x_meas)
    if cost_ns is not None:
        n = max(1, len(u_out))
        cost_ns["step"] = step_ns / n
        cost_ns["refine"] = refine_ns / n
    return np.asarray(u_out), np.asarray(x_out)


def tracking_metrics(x: np.ndarray, x_d: np.ndarray, adaptation: int) -> dict[str, float]:
    """Max and RMS of |x − x_d| after the adaptation samples, in µm and in % of x_d's range."""
    e = np.asarray(x, dtype=np.float64)[adaptation:] - np.asarray(x_d, dtype=np.float64)[adaptation:]
    span = float(np.ptp(x_d))
    max_um = float(np.max(np.abs(e)))
    rms_um = float(np.sqrt(np.mean(e * e)))
    return {
        "max_um": max_um,
        "rms_um": rms_um,
        "max_pct": 100.0 * max_um / span,
        "rms_pct": 100.0 * rms_um / span,
    }


def _noise_seed(seed: int, bench_index: int, reference_index: int) -> int:
    """Seed of the vibrometer noise of one run (the same for every method)."""
    return seed + 1000 * (bench_index + 1) + reference_index


# --------------------------------------------------------------------------- targets


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else math.inf


def check_targets(table: Mapping[str, Mapping[str, Mapping[str, Mapping[str, float]]]]) -> list[dict[str, Any]]:
    """The issue's targets, checked on ``table[bench][reference][method]`` metrics.

    Every target is checked on both benches; ``required`` marks the bench it is set for.
    """
    out: list[dict[str, Any]] = []

    def add(name: str, bench: str, required: bool, value: float, limit: float, met: bool, detail: str) -> None:
        out.append(
            {
                "target": name,
                "bench": bench,
                "required": required,
                "value": value,
                "limit": limit,
                "met": bool(met),
                "detail": detail,
            }
        )

    for bench, refs in table.items():
        off = bench == "vibration_off"
        m = {ref: {meth: v["max_um"] for meth, v in r.items()} for ref, r in refs.items()}
        pct = {ref: {meth: v["max_pct"] for meth, v in r.items()} for ref, r in refs.items()}
        for f, factor in (("1", 10.0), ("100", 5.0)):
            key = f"sine_{f}hz"
            if key in m:
                ratio = _ratio(m[key]["linear"], m[key]["inverse_adaptive"])
                add(
                    f"adaptive inverse cuts the linear open loop's max error >= {factor:g}x at {f} Hz",
                    bench,
                    off,
                    ratio,
                    factor,
                    ratio >= factor,
                    f"{m[key]['linear']:.3f} -> {m[key]['inverse_adaptive']:.3f} um",
                )
        for key in sorted((k for k in refs if k.startswith("sine_") and _freq(k) >= 10.0), key=_freq):
            a, b = m[key]["inverse_adaptive"], m[key]["inverse_fixed"]
            add(
                f"adaptive inverse beats the fixed inverse at {_freq(key):g} Hz",
                bench,
                off,
                a,
                b,
                a < b,
                f"{a:.3f} vs {b:.3f} um",
            )
        for key in sorted((k for k in refs if k.startswith("sine_") and 1.0 <= _freq(k) <= 100.0), key=_freq):
            v = pct[key]["inverse_adaptive"]
            add(
                f"adaptive inverse max error <= 1 % of range at {_freq(key):g} Hz",
                bench,
                off,
                v,
                1.0,
                v <= 1.0,
                f"{m[key]['inverse_adaptive']:.3f} um",
            )
        for key in sorted((k for k in refs if k.startswith("sine_") and 1.0 <= _freq(k) <= 10.0), key=_freq):
            v = pct[key]["pi_adaptive"]
            add(
                f"PI + adaptive inverse max error <= 0.5 % of range at {_freq(key):g} Hz",
                bench,
                not off,
                v,
                0.5,
                v <= 0.5,
                f"{m[key]['pi_adaptive']:.3f} um",
            )
    return out


def _freq(key: str) -> float:
    return float(key.removeprefix("sine_").removesuffix("hz")) if key.startswith("sine_") else math.nan


# --------------------------------------------------------------------------- generated plants


def generated_plant(rng: np.random.Generator, base: plant.BenchSettings | None = None) -> plant.BenchSettings:
    """A bench the experiment was not tuned for (module docs, step 7).

    Around ``base`` (default :class:`boucwen.plant.BenchSettings`): kv, x0, A, n, δ and
    the two combinations β + γ and β − γ that keep h bounded each scaled by
    U(0.8, 1.2) (the Bouc–Wen core ±20 %); amplifier corner U(300, 1000) Hz; each
    creep gain scaled by U(0.5, 1.5); floor vibration of two tones at U(10, 40) Hz
    with random phases whose amplitudes sum to U(0.1, 0.3) µm; vibrometer noise
    U(1, 10) nm. Electrostriction, resolution and A/D stay as in ``base``.
    """
    b = base if base is not None else plant.BenchSettings()

    def scale() -> float:
        return float(rng.uniform(0.8, 1.2))

    plus = (b.beta + b.gamma) * scale()
    minus = (b.beta - b.gamma) * scale()
    total = float(rng.uniform(0.1, 0.3))
    share = float(rng.uniform(0.3, 0.7))
    return replace(
        b,
        kv=b.kv * scale(),
        x0=b.x0 * scale(),
        A=b.A * scale(),
        beta=0.5 * (plus + minus),
        gamma=0.5 * (plus - minus),
        n=b.n * scale(),
        delta=b.delta * scale(),
        amplifier_fc_hz=float(rng.uniform(300.0, 1000.0)),
        creep_gain_um_per_v=tuple(g * float(rng.uniform(0.5, 1.5)) for g in b.creep_gain_um_per_v),
        vibration_hz=tuple(float(v) for v in rng.uniform(10.0, 40.0, 2)),
        vibration_um=(total * share, total * (1.0 - share)),
        vibration_phase_rad=tuple(float(v) for v in rng.uniform(0.0, 2.0 * math.pi, 2)),
        noise_um=float(rng.uniform(0.001, 0.010)),
    )


# --------------------------------------------------------------------------- run


def _progress(progress: bool | Callable[[str], None]) -> Callable[[str], None]:
    if callable(progress):
        return progress
    if progress:
        return lambda msg: print(msg, flush=True)
    return lambda msg: None


def _run_bench(
    settings: plant.BenchSettings,
    ident: Identification,
    refs: Sequence[Reference],
    methods: Sequence[Method],
    dt: float,
    seed: int,
    bench_index: int,
) -> dict[str, dict[str, dict[str, Any]]]:
    """Every method on every reference of one bench: metrics and signals."""
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for r_index, ref in enumerate(refs):
        out[ref.name] = {}
        for method in methods:
            comp = method.make(ident, dt)
            bench = plant.Bench(dt, settings, seed=_noise_seed(seed, bench_index, r_index))
            cost: dict[str, float] = {}
            u, x = closed_loop(comp, bench, ref.x_d, method.refine_intervals, cost)
            status = comp.status
            out[ref.name][method.name] = {
                **tracking_metrics(x, ref.x_d, ref.adaptation),
                "step_ns": cost["step"],
                "refine_ns": cost["refine"],
                "clipped_samples": int(status["clipped_samples"]),
                "held_samples": int(status["held_samples"]),
                "u_range_v": [float(u.min()), float(u.max())],
                "final_params": comp.params.to_dict() if method.name.endswith("adaptive") else None,
                "_x": x,
            }
    return out


def _strip(signals: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> dict[str, dict[str, dict[str, Any]]]:
    return {
        ref: {meth: {k: v for k, v in m.items() if not k.startswith("_")} for meth, m in r.items()}
        for ref, r in signals.items()
    }


def _format_table(
    refs: Sequence[Reference], methods: Sequence[Method], table: Mapping[str, Mapping[str, Mapping[str, float]]]
) -> list[str]:
    lines = [
        "| reference | " + " | ".join(m.label for m in methods) + " |",
        "|---|" + "---|" * len(methods),
    ]
    for ref in refs:
        cells = []
        for m in methods:
            v = table[ref.name][m.name]
            cells.append(f"{v['max_um']:.3f} / {v['rms_um']:.3f} ({v['max_pct']:.2f} %)")
        lines.append(f"| {ref.label} | " + " | ".join(cells) + " |")
    return lines


def _format_costs(
    refs: Sequence[Reference], methods: Sequence[Method], table: Mapping[str, Mapping[str, Mapping[str, float]]]
) -> list[str]:
    """The adaptive compensators' cost per sample [ns], step + refine, mean over the references."""
    lines = ["compensator cost per sample [ns] (Python call included), mean over the references: step + refine"]
    for m in methods:
        if not m.name.endswith("adaptive"):
            continue
        step = float(np.mean([table[r.name][m.name]["step_ns"] for r in refs]))
        refine = float(np.mean([table[r.name][m.name]["refine_ns"] for r in refs]))
        lines.append(f"   {m.label}: {step:.0f} + {refine:.0f} ns")
    return lines


def run(
    out: str | os.PathLike[str] = DEFAULT_OUT,
    *,
    quick: bool = False,
    seed: int = 0,
    plants: int | None = None,
    figures: bool = True,
    progress: bool | Callable[[str], None] = True,
    dt: float = plant.DEFAULT_DT,
) -> dict[str, Any]:
    """Runs the experiment (module docs) and writes ``out/results.json`` and the figures.

    Args:
        out: output directory (created).
        quick: shorter references, a 2 s identification record on the two benches
            and 3 generated plants unless ``plants`` is given (for tests).
        seed: seed of the fits, the noise, the random reference and the generated plants.
        plants: number of generated plants (default 20, 3 with ``quick``; 0 = none).
        figures: write the PNG figures.
        progress: print progress and the tables (or a callable taking each line).
        dt: sampling interval [s].

    Returns:
        The content of ``results.json``.
    """
    say = _progress(progress)
    started = time.perf_counter()
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    n_plants = plants if plants is not None else (3 if quick else 20)
    if n_plants < 0:
        raise ValueError(f"plants must be >= 0, got {n_plants}")
    refs = references(dt, quick=quick, seed=seed)
    ident_s = IDENTIFICATION_GENERATED_S if quick else IDENTIFICATION_S
    results: dict[str, Any] = {
        "settings": {
            "dt_s": dt,
            "quick": quick,
            "seed": seed,
            "range_um": RANGE_UM,
            "u_limits_v": list(U_LIMITS_V),
            "identification_s": ident_s,
            "pi_gains": PI_GAINS,
            "pi_adaptive_gains": PI_ADAPTIVE_GAINS,
            "metrics": "max and RMS of |x - x_d| after the adaptation period, x = vibrometer reading; "
            "% of the reference's range",
            "references": {
                r.name: {"label": r.label, "samples": int(r.x_d.size), "adaptation_samples": r.adaptation} for r in refs
            },
            "methods": {m.name: m.label for m in METHODS},
            "refine_intervals": {m.name: m.refine_intervals for m in METHODS if m.refine_intervals},
        },
        "benches": {},
        "anchors": list(ANCHORS),
    }
    tables: dict[str, dict[str, dict[str, dict[str, float]]]] = {}
    for b_index, (bench_name, settings) in enumerate(BENCHES.items()):
        say(f"== {bench_name}: identification ({ident_s:g} s at 1 Hz)")
        ident = identify(settings, dt, ident_s, seed)
        say(f"   traditional {ident.traditional.params!r}, line kv = {ident.line.kv:.4g} um/V")
        signals = _run_bench(settings, ident, refs, METHODS, dt, seed, b_index)
        tables[bench_name] = _strip(signals)
        results["benches"][bench_name] = {
            "settings": settings.to_dict(),
            "traditional": {"params": ident.traditional.params.to_dict(), "h0_um": ident.traditional.h0},
            "line": {"kv_um_per_v": ident.line.kv, "x0_um": ident.line.x0},
            "table": tables[bench_name],
        }
        say(f"== {bench_name}: max / RMS error [um] (max in % of range), after one period of adaptation")
        for line in _format_table(refs, METHODS, tables[bench_name]):
            say(line)
        for line in _format_costs(refs, METHODS, tables[bench_name]):
            say(line)
        if figures and bench_name == FIGURE_BENCH:
            from ..plots import plot_tracking

            for ref in refs:
                runs = {m.label: signals[ref.name][m.name]["_x"] for m in METHODS}
                t = np.arange(ref.x_d.size) * dt
                title = f"{ref.label}, {bench_name.replace('_', ' ')}"
                plot_tracking(out_dir / f"{ref.name}.png", t, ref.x_d, runs, ref.adaptation, title)
    results["targets"] = check_targets(tables)
    say("== targets")
    for t in results["targets"]:
        mark = "met" if t["met"] else "MISSED"
        req = "" if t["required"] else " (not required on this bench)"
        say(f"   {mark:6s} {t['bench']}: {t['target']}: {t['detail']}{req}")
    say("== anchors (published, max error in % of range)")
    for a in ANCHORS:
        say("   " + "; ".join(f"{k}: {v}" for k, v in a.items()))
    if n_plants:
        results["generated_plants"] = _generated(refs, n_plants, dt, seed, quick, say)
    results["elapsed_s"] = time.perf_counter() - started
    with open(out_dir / "results.json", "w", encoding="utf-8") as fh:
        json.dump(results, fh, indent=2)
    say(f"wrote {out_dir / 'results.json'} ({results['elapsed_s']:.1f} s)")
    return results


def _generated(
    refs: Sequence[Reference], n_plants: int, dt: float, seed: int, quick: bool, say: Callable[[str], None]
) -> dict[str, Any]:
    """The adaptive inverse on ``n_plants`` generated plants: max error per reference, median and worst."""
    rng = np.random.default_rng(seed + 7919)
    method = next(m for m in METHODS if m.name == "inverse_adaptive")
    per_plant: list[dict[str, Any]] = []
    say(f"== adaptive inverse on {n_plants} generated plants")
    for i in range(n_plants):
        settings = generated_plant(rng)
        ident = identify(settings, dt, IDENTIFICATION_GENERATED_S, seed + 1 + i)
        table = _strip(_run_bench(settings, ident, refs, (method,), dt, seed + 1 + i, 2 + i))
        per_plant.append(
            {
                "settings": settings.to_dict(),
                "max_um": {r.name: table[r.name][method.name]["max_um"] for r in refs},
                "max_pct": {r.name: table[r.name][method.name]["max_pct"] for r in refs},
                "clipped_samples": {r.name: table[r.name][method.name]["clipped_samples"] for r in refs},
                "held_samples": {r.name: table[r.name][method.name]["held_samples"] for r in refs},
            }
        )
        worst = max(per_plant[-1]["max_pct"].values())
        clipped = [r.name for r in refs if per_plant[-1]["clipped_samples"][r.name]]
        note = f", voltage limit bound on {', '.join(clipped)}" if clipped else ""
        say(
            f"   plant {i + 1}/{n_plants}: kv {settings.kv:.3f} um/V, lag {settings.amplifier_fc_hz:.0f} Hz, "
            f"worst max error {worst:.2f} % of range{note}"
        )
    summary = {}
    header = "| reference | median max error [um] (% of range) | worst [um] (% of range) |"
    say(header + " plants clipped | worst unclipped |")
    say("|---|---|---|---|---|")
    for r in refs:
        values = np.array([p["max_um"][r.name] for p in per_plant])
        free = np.array([p["max_um"][r.name] for p in per_plant if not p["clipped_samples"][r.name]])
        span = float(np.ptp(r.x_d))
        summary[r.name] = {
            "median_max_um": float(np.median(values)),
            "worst_max_um": float(values.max()),
            "median_max_pct": 100.0 * float(np.median(values)) / span,
            "worst_max_pct": 100.0 * float(values.max()) / span,
            "plants_clipped": int(values.size - free.size),
            "worst_unclipped_max_um": float(free.max()) if free.size else None,
            "worst_unclipped_max_pct": 100.0 * float(free.max()) / span if free.size else None,
        }
        s = summary[r.name]
        unclipped = f"{s['worst_unclipped_max_um']:.3f} ({s['worst_unclipped_max_pct']:.2f} %)" if free.size else "-"
        say(
            f"| {r.label} | {s['median_max_um']:.3f} ({s['median_max_pct']:.2f} %) | "
            f"{s['worst_max_um']:.3f} ({s['worst_max_pct']:.2f} %) | {s['plants_clipped']} | {unclipped} |"
        )
    return {"plants": per_plant, "summary": summary}
