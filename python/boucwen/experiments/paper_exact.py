"""The paper's online method on a paper-exact plant: can it reach the paper's Table 1?

``python -m boucwen.experiments.paper_exact [--out DIR] [--quick] [--windows N ...]``

The plant is the paper's model (eq. 5) and nothing else: no amplifier lag, no creep, no
electrostriction, no floor vibration. Its parameters are the paper's Table 2 row of each
frequency, switched at the paper's switch times (1 Hz to 3 s, 10 Hz to 3.3 s, 100 Hz to
3.33 s, then 200 Hz; the input of :mod:`boucwen.experiments.reproduce`), h carried across
the switches. The sensor is the paper's vibrometer: 10 kHz, white noise of 1 nm, read to
a resolution of 2 nm. The identifier (``Identifier.paper``, default
:class:`boucwen.PaperConfig`) starts from the 1 Hz row with every hysteresis parameter
(A, β, γ, n, δ) 20 % off and kv, x0 as the row gives them.

A separate module rather than a ``reproduce`` option: the bench of ``reproduce`` is a
different plant (lag, creep, vibration) scored against an offline fit, and its run
includes every other method; this one asks only whether the paper's method, as
written, identifies the paper's own model.

For each window N of the sweep the method is scored as :mod:`boucwen.evaluation`
scores every model: period-ahead (estimates frozen at the start of each period, the
model open loop over it; max |x − x̂| over the last full period of each frequency) and,
the paper's metric, one step ahead, beside persistence and the two-tap extrapolator.
The chosen N is the one with the smallest worst period-ahead error over the four
frequencies. For it: Table 2 (estimates at the end of each frequency beside the
plant's), and the share of pushes on which each of steps 1–5 ran, with the points it had
and their scatter (:func:`boucwen.experiments.reproduce.step_shares`).

Writes ``DIR/results.json`` (default ``out/paper_exact``).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .. import evaluation, plant
from .._core import Identifier, Params, simulate
from ..config import PaperConfig
from ..io import jsonable
from .reproduce import (
    PAPER_TABLE1,
    PAPER_TABLE2,
    QUICK_SEGMENTS,
    SEGMENTS,
    StepTally,
    format_step_shares,
    format_window_sweep,
    step_shares,
)

__all__ = [
    "DEFAULT_OUT",
    "HYSTERESIS_OFFSET",
    "NOISE_UM",
    "PASS_UM",
    "QUICK_WINDOWS",
    "RESOLUTION_UM",
    "WINDOWS",
    "exact_plant",
    "main",
    "run",
    "run_window",
    "start_params",
    "step_budget",
]

#: Default output directory.
DEFAULT_OUT = os.path.join("out", "paper_exact")
#: The paper's sensor: white noise [µm] (1 nm) and resolution [µm] (2 nm) at 10 kHz.
NOISE_UM = 0.001
RESOLUTION_UM = 0.002
#: The identifier starts with A, β, γ, n and δ this fraction above the 1 Hz row.
HYSTERESIS_OFFSET = 0.2
#: The paper's online row of Table 1 is at most 0.49 µm; the pass mark is 0.5 µm.
PASS_UM = 0.5
#: Windows N of the sweep [samples] (5 ms to 1 s at 10 kHz).
WINDOWS: tuple[int, ...] = (50, 100, 200, 500, 1000, 2000, 5000, 10000)
#: Windows of ``--quick`` (CI).
QUICK_WINDOWS: tuple[int, ...] = (2000,)

_NAMES = ("kv", "x0", "A", "beta", "gamma", "n", "delta")


def start_params() -> Params:
    """The 1 Hz row with every hysteresis parameter (A, β, γ, n, δ) 20 % off."""
    p = Params.paper_1hz()
    k = 1.0 + HYSTERESIS_OFFSET
    return p.replace(A=p.A * k, beta=p.beta * k, gamma=p.gamma * k, n=p.n * k, delta=p.delta * k)


def exact_plant(
    dt: float = plant.DEFAULT_DT,
    segments: Sequence[tuple[float, float]] = SEGMENTS,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[float, int, int]]]:
    """The paper's input, its model with Table 2's row per frequency, and its sensor.

    Returns ``(u [V], x_true [µm], x_measured [µm], segments)``: the model switches to
    each frequency's row at the switch (h continuous), and the reading is x_true plus
    white noise of :data:`NOISE_UM`, rounded to :data:`RESOLUTION_UM`.
    """
    _, u, segs = plant.paper_input(dt, segments)
    x = np.empty_like(u)
    h = 0.0
    for f, lo, hi in segs:
        p = Params.from_dict(PAPER_TABLE2[f"{f:g}"])
        xs, h = simulate(p, u[lo:hi], dt, h, None if lo == 0 else float(u[lo - 1]))
        x[lo:hi] = xs
    noise = NOISE_UM * np.random.default_rng(seed).standard_normal(x.size)
    measured = RESOLUTION_UM * np.round((x + noise) / RESOLUTION_UM)
    return u, x, measured, segs


def _sg_slope(v: np.ndarray, m: int, dt: float) -> np.ndarray:
    """Savitzky–Golay first derivative over 2m + 1 samples (the identifier's estimator)."""
    k = np.arange(-m, m + 1, dtype=np.float64)
    return np.convolve(v, k[::-1], mode="same") / (float(np.sum(k * k)) * dt)


def step_budget(
    u: np.ndarray,
    x_true: np.ndarray,
    x: np.ndarray,
    dt: float,
    segments: Sequence[tuple[float, int, int]],
    config: PaperConfig | None = None,
) -> dict[str, dict[str, dict[str, float]]]:
    """What steps 3 and 4 have to work with, per frequency, with the plant's own h.

    With the identifier's derivative (half-width m by ``derivative_phase`` at the
    segment's frequency) and its point selection (|u̇| above ``rate_frac``·rms(u̇), h
    above ``h_zero_frac``·hₛ), on the segment (less the stencil's edges): the
    points each step has, the signal |A − r| = |β ± γ|·hⁿ it fits the logarithm of
    (median), the noise the sensor leaves in r (rms of r from the measured x less r from
    the true x, same stencil) and the bias of the derivative (rms of r from the true x
    less the model's exact r)."""
    cfg = config if config is not None else PaperConfig()
    out: dict[str, dict[str, dict[str, float]]] = {"shape_fit": {}, "return_fit": {}}
    for f, lo, hi in segments:
        p = Params.from_dict(PAPER_TABLE2[f"{f:g}"])
        m = int(min(max(round(cfg.derivative_phase / (2 * np.pi * f * dt)), 2), cfg.max_half_width))
        sl = slice(lo + 2 * m + 1, hi - m)
        ud = _sg_slope(u, m, dt)[sl]
        xd_true = _sg_slope(x_true, m, dt)[sl]
        xd = _sg_slope(x, m, dt)[sl]
        uu = u[sl]
        h = x_true[sl] - p.kv * uu - p.x0
        h_s = (abs(p.A) / (abs(p.beta) + abs(p.gamma))) ** (1.0 / p.n)
        fast = np.abs(ud) > cfg.rate_frac * np.sqrt(np.mean(ud**2))
        for step, side, coef in (("shape_fit", 1.0, p.beta + p.gamma), ("return_fit", -1.0, p.gamma - p.beta)):
            sel = fast & (side * ud > 0) & (h > cfg.h_zero_frac * h_s)
            if not np.any(sel):
                out[step][f"{f:g}"] = {"points": 0, "signal": 0.0, "noise": 0.0, "bias": 0.0, "half_width": m}
                continue
            d = ud[sel]
            r_true = (xd_true[sel] - p.kv * d - side * p.delta * uu[sel]) / d
            r_meas = (xd[sel] - p.kv * d - side * p.delta * uu[sel]) / d
            signal = coef * np.abs(h[sel]) ** p.n  # A − r of the model
            out[step][f"{f:g}"] = {
                "points": int(sel.sum()),
                "signal": float(np.median(np.abs(signal))),
                "noise": float(np.sqrt(np.mean((r_meas - r_true) ** 2))),
                "bias": float(np.sqrt(np.mean(((p.A - r_true) - signal) ** 2))),
                "half_width": m,
            }
    return out


def run_window(
    u: np.ndarray,
    x: np.ndarray,
    dt: float,
    window: int,
    init: Params,
    segments: Sequence[tuple[float, int, int]],
) -> dict[str, Any]:
    """The paper's method with window N = `window` over the record, scored.

    Returns ``period_ahead`` and ``one_step`` (max error per frequency [µm]), ``table2``
    (the estimates at the end of each frequency) and ``steps`` (:func:`step_shares`)."""
    ident = Identifier.paper(dt, window, init)
    tally = StepTally(dt)
    ends: dict[str, dict[str, float]] = {}
    stops = {hi: f"{f:g}" for f, _, hi in segments}

    def freeze(_f: float, k0: int, p: Params, _h: float) -> None:
        if k0 in stops:
            ends[stops[k0]] = {k: float(v) for k, v in p.to_dict().items()}

    score, _, one_step = evaluation.period_ahead(ident, u, x, dt, segments, on_period=freeze, feed=tally)
    ends[f"{segments[-1][0]:g}"] = {k: float(v) for k, v in ident.params.to_dict().items()}
    return {
        "window": window,
        "period_ahead": score,
        "one_step": evaluation.one_step_scores(x, one_step, segments, dt),
        "table2": ends,
        "steps": step_shares(tally.statuses, segments),
    }


def _row(name: str, values: Sequence[float], fmt: str = "{:>9.3f}") -> str:
    return f"{name:<34}" + "".join(fmt.format(v) for v in values)


def run(
    out_dir: str | os.PathLike[str] = DEFAULT_OUT,
    *,
    quick: bool = False,
    windows: Sequence[int] | None = None,
    seed: int = 0,
    log: Callable[[str], None] | None = print,
) -> dict[str, Any]:
    """Runs the sweep, prints the tables and writes ``results.json`` (module docs)."""
    say = log or (lambda _msg: None)
    started = time.perf_counter()
    dt = plant.DEFAULT_DT
    seg_spec = QUICK_SEGMENTS if quick else SEGMENTS
    windows = tuple(windows) if windows else (QUICK_WINDOWS if quick else WINDOWS)
    u, x_true, x, segs = exact_plant(dt, seg_spec, seed)
    freqs = [f"{f:g}" for f, _, _ in segs]
    init = start_params()
    say(
        f"paper-exact plant: {u.size} samples at {1 / dt:.0f} Hz; sensor {NOISE_UM * 1e3:g} nm noise, "
        f"{RESOLUTION_UM * 1e3:g} nm resolution; start {init!r}"
    )
    sweep = {}
    for w in windows:
        sweep[str(w)] = run_window(u, x, dt, w, init, segs)
        say(f"[{time.perf_counter() - started:6.1f} s] N = {w}")
    chosen = min(sweep, key=lambda w: max(sweep[w]["period_ahead"].values()))
    best = sweep[chosen]
    baselines = evaluation.one_step_baselines(x, segs, dt)
    budget = step_budget(u, x_true, x, dt, segs)
    passed = {
        "one_step": all(best["one_step"][f] <= PASS_UM for f in freqs),
        "period_ahead": all(best["period_ahead"][f] <= PASS_UM for f in freqs),
    }
    results = {
        "plant": {
            "model": "eq. 5, Table 2 row per frequency, switched at the paper's switch times",
            "noise_um": NOISE_UM,
            "resolution_um": RESOLUTION_UM,
            "dt_s": dt,
            "segments": [{"f_hz": f, "start": lo, "stop": hi} for f, lo, hi in segs],
            "quick": quick,
            "seed": seed,
        },
        "start": {k: float(v) for k, v in init.to_dict().items()},
        "sensor_noise_check_um": float(np.std(x - x_true)),
        "windows": list(windows),
        "chosen_window": int(chosen),
        "choice": "smallest worst period-ahead error over the frequencies",
        "sweep": sweep,
        "baselines": baselines,
        "step_budget": budget,
        "pass_um": PASS_UM,
        "passed": passed,
        "paper": {"table1": PAPER_TABLE1, "table2": PAPER_TABLE2},
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "results.json", "w", encoding="utf-8") as fh:
        json.dump(jsonable(results), fh, indent=2, allow_nan=False)

    heads = "".join(f"{f + ' Hz':>9}" for f in freqs)
    say("")
    say("Window sweep: max |x - x_hat| [µm] per frequency, period-ahead | one step")
    for line in format_window_sweep(sweep, freqs):
        say(line)
    say("")
    say(f"Table 1 on the paper-exact plant, N = {chosen} [µm]")
    say(f"{'method':<34}{heads}")
    say(_row("online paper, period-ahead", [best["period_ahead"][f] for f in freqs]))
    say(_row("online paper, one step", [best["one_step"][f] for f in freqs]))
    say(_row("online (paper's Table 1)", [PAPER_TABLE1["online"][f] for f in freqs]))
    say(_row("persistence x[k-1]", [baselines["persistence"][f] for f in freqs]))
    say(_row("two-tap 2x[k-1] - x[k-2]", [baselines["two_tap"][f] for f in freqs]))
    say(
        f"pass (<= {PASS_UM} µm at every frequency): one step {passed['one_step']}, "
        f"period-ahead {passed['period_ahead']}"
    )
    say("")
    say("Table 2: estimates at the end of each frequency (plant's value, the paper's Table 2, in brackets)")
    say(f"{'f':>6}" + "".join(f"{n:>20}" for n in _NAMES))
    for f in freqs:
        est = best["table2"][f]
        say(f"{f + ' Hz':>6}" + "".join(f"{est[n]:>11.4g} ({PAPER_TABLE2[f][n]:.3g})".rjust(20) for n in _NAMES))
    say("")
    for line in format_step_shares(best["steps"], freqs):
        say(line)
    say("Median points and scatter (step's units) on the pushes it ran:")
    for step, rows in best["steps"].items():
        say(
            f"{step:<12}"
            + "".join(f"{rows[f]['points']:>9.0f}" for f in freqs)
            + "  |"
            + "".join(f"{rows[f]['noise']:>10.3g}" for f in freqs)
        )
    say("")
    say("What steps 3 and 4 fit, per frequency, with the plant's h: points, median |A - r| (signal),")
    say("rms noise of r from the sensor, rms bias of r from the derivative, derivative half-width m")
    for step, rows in budget.items():
        for f in freqs:
            b = rows[f]
            say(
                f"{step:<12}{f + ' Hz':>8}{b['points']:>8} points  signal {b['signal']:.2e}  "
                f"noise {b['noise']:.2e}  bias {b['bias']:.2e}  m = {b['half_width']}"
            )
    say(f"[{time.perf_counter() - started:6.1f} s] wrote {out / 'results.json'}")
    return results


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (module docs)."""
    ap = argparse.ArgumentParser(prog="python -m boucwen.experiments.paper_exact", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=DEFAULT_OUT, help="output directory (default %(default)s)")
    ap.add_argument("--quick", action="store_true", help="shortened record and one window (CI)")
    ap.add_argument("--windows", type=int, nargs="+", help="windows N of the sweep [samples]")
    ap.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    args = ap.parse_args(argv)
    run(args.out, quick=args.quick, windows=args.windows, seed=args.seed)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
