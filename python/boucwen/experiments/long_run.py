"""Long runs: do the online estimates stay sane over a million samples?

Every online method (``horizon``, ``rpem``, and ``paper`` with windows
N = :data:`PAPER_WINDOWS`) is pushed, sample by sample, through

* the paper's schedule (:data:`boucwen.plant.PAPER_SEGMENTS`: 1, 10, 100, 200 Hz;
  33 800 samples at 10 kHz) repeated :data:`REPEATS` times (1 014 001 samples), and
* :data:`RANDOM_SAMPLES` samples of band-limited random input (:func:`random_input`:
  Gaussian noise through a 4th-order Butterworth low-pass at 100 Hz, scaled so that
  0–100 V is ±3 standard deviations around 50 V and clipped to it),

each measured on the default bench (:class:`boucwen.plant.BenchSettings`: amplifier
lag, creep, electrostriction, floor vibration, 16-bit A/D on u) with vibrometer noise of
0, 1 and 5 nm (:data:`NOISE_LEVELS_UM`) and no resolution rounding (so that the noise
level is the only measurement error on x). Noise seed :data:`SEED` (+1 for the random
input's record); the random input's own seed is :data:`SEED` too.

**Start.** The traditional model: :func:`boucwen.fit` on the first 3 s of the record
(the first 1 Hz part of the schedule; seed :data:`SEED`). The fit keeps to the
admissible region (β ± γ ≥ 0: docs/design.md, "The admissible region"), but its β ± γ
may lie below the identifiers' margin and its n outside their bounds; every method is
started from it *projected* onto the identifiers' region (:func:`project`: β ± γ raised
to :data:`REGION_MARGIN`, n clamped to :data:`N_BOUNDS`, as the horizon method projects
its updates), so that the region check below holds the methods to account from the
first sample on. The traditional model itself (not projected) is the baseline.

**What is recorded** (after every push: the estimates and the model's h):

* **Region.** The estimates are in the region where the model is well posed when
  β + γ > 0, β − γ > 0 and n within :data:`N_BOUNDS`; the minima of β ± γ, the range of
  n, the largest |β| and |γ| and the number of samples outside the region.
* **Period-ahead error** (:mod:`boucwen.evaluation`): at the start of every period the
  estimates and h are frozen and the model is simulated open loop over the period;
  each frequency of each repeat is scored on its last full period and compared with
  the traditional model's open-loop error there (:func:`scores_from_record`; it gives
  exactly :func:`boucwen.evaluation.period_ahead`'s numbers, a test checks it). On the
  random input the "periods" are blocks of :data:`RANDOM_BLOCK` samples (0.1 s); the
  ratio to the traditional is taken block by block.
* **Implicit-path share**: the share of pushes whose prediction interval the model's
  integrator (``rust/model/integrator.rs``) sends to backward Euler: the core's own
  plan of every interval (:func:`implicit_intervals`) with the estimates and h
  recorded after the push before it (exactly what the identifier integrates with):
  implicit where the stiffness n·(|β|+|γ|)·|u̇|·|h|^(n−1)·Δt, at the interval's start or
  at its explicit-Euler end point when h moves by more than a tenth of itself, asks
  for more than ``MAX_SUBSTEPS`` RK4 sub-steps, or n < 1 at h = 0. An interval over
  which u holds is not integrated at all and counts as explicit. The horizon method also re-simulates
  its window (16 intervals per push, with the same estimates but the window's h);
  those intervals are not replayed.

Targets (the tracker's issue): every estimate in the region, the period-ahead error
≤ 2 × the traditional's at every frequency, ≥ 95 % of pushes on the explicit path.

``python -m boucwen.experiments.long_run [--quick] [--json FILE]`` prints the table
(one line per run, progress on stderr); ``--quick`` is the shortened version (3
repeats, 10⁵ random samples, noise 0 and 5 nm, N = 50 and 5000); ``--paper-bounds-off``
runs the paper method alone with its physical bounds (``max_hysteresis_gain``,
``max_delta_ratio``) switched off, as it ran before them (labelled ``N=…*``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from .. import evaluation, plant
from .._core import Identifier, Params, _substep_plan, simulate
from ..config import PaperConfig
from ..fit import fit
from ..io import jsonable

__all__ = [
    "BOUNDS_OFF",
    "NOISE_LEVELS_UM",
    "N_BOUNDS",
    "PAPER_WINDOWS",
    "RANDOM_SAMPLES",
    "REPEATS",
    "SEED",
    "Case",
    "Record",
    "bounds_off_cases",
    "default_cases",
    "implicit_intervals",
    "main",
    "period_bounds",
    "project",
    "quick_options",
    "random_input",
    "record_run",
    "repeated_schedule",
    "run",
    "run_case",
    "scores_from_record",
]

FloatArray = NDArray[np.float64]

#: Repeats of the paper's schedule (≥ 10⁶ samples).
REPEATS = 30
#: Samples of band-limited random input.
RANDOM_SAMPLES = 1_000_000
#: Upper band edge of the random input [Hz].
RANDOM_BAND_HZ = 100.0
#: Block of the random input's period-ahead score [samples] (0.1 s at 10 kHz).
RANDOM_BLOCK = 1000
#: Vibrometer noise levels [µm].
NOISE_LEVELS_UM: tuple[float, ...] = (0.0, 0.001, 0.005)
#: Windows N of the paper method [samples].
PAPER_WINDOWS: tuple[int, ...] = (50, 500, 5000, 100_000)
#: Seed of the records and the fits.
SEED = 0
#: n must stay within these bounds [-] (the horizon and rpem methods' bounds).
N_BOUNDS = (0.25, 4.0)
#: β ± γ of the projected starting values [µm^(1−n)/V] (the identifiers' own margin).
REGION_MARGIN = 1e-6
#: Targets: period-ahead error at most this × the traditional's; explicit share at least this.
TRADITIONAL_FACTOR = 2.0
EXPLICIT_SHARE = 0.95


@dataclass(frozen=True)
class Case:
    """One online method: ``method`` in ("horizon" — the recommended model, input lag
    identified along —, "horizon_base" — seven parameters only —, "rpem", "paper"),
    ``window`` N for "paper"."""

    method: str
    window: int | None = None
    paper_options: tuple[tuple[str, float], ...] = ()
    """Options of :class:`boucwen.PaperConfig` for "paper" (default: none changed)."""

    @property
    def label(self) -> str:
        if self.method != "paper":
            return self.method
        return f"paper N={self.window}" + ("*" if self.paper_options else "")

    def make(self, dt: float, init: Params, h0: float) -> Identifier:
        if self.method == "horizon":
            return Identifier(dt, init, h0)
        if self.method == "horizon_base":
            return Identifier.horizon(dt, init, h0)
        if self.method == "rpem":
            return Identifier.rpem(dt, init, h0)
        if self.method == "paper" and self.window is not None:
            config = PaperConfig().replace(**dict(self.paper_options)) if self.paper_options else None
            return Identifier.paper(dt, self.window, init, h0, config=config)
        raise ValueError(f"invalid case {self!r}")


#: The paper method's physical bounds switched off (``--paper-bounds-off``: how it ran before them).
BOUNDS_OFF: tuple[tuple[str, float], ...] = (("max_hysteresis_gain", math.inf), ("max_delta_ratio", math.inf))


def default_cases(windows: Sequence[int] = PAPER_WINDOWS) -> list[Case]:
    """horizon (with and without its input lag), rpem and the paper method at each window."""
    return [Case("horizon"), Case("horizon_base"), Case("rpem")] + [Case("paper", int(w)) for w in windows]


def bounds_off_cases(windows: Sequence[int] = PAPER_WINDOWS) -> list[Case]:
    """The paper method at each window with :data:`BOUNDS_OFF` (labelled ``paper N=…*``)."""
    return [Case("paper", int(w), BOUNDS_OFF) for w in windows]


# --------------------------------------------------------------------------- inputs


def repeated_schedule(repeats: int, dt: float = plant.DEFAULT_DT) -> tuple[FloatArray, list[tuple[float, int, int]]]:
    """The paper's schedule repeated `repeats` times: u [V] and the segments (f [Hz], lo, hi)."""
    _, u, segments = plant.paper_input(dt, list(plant.PAPER_SEGMENTS) * int(repeats))
    return u, segments


def random_input(
    samples: int, dt: float = plant.DEFAULT_DT, seed: int = SEED, band_hz: float = RANDOM_BAND_HZ
) -> FloatArray:
    """Band-limited random voltage [V]: white Gaussian noise through a 4th-order
    Butterworth low-pass at `band_hz` (run in once over 1 s of extra samples, then
    discarded), scaled to 50 V ± 50 V at three standard deviations and clipped to
    0–100 V (about 0.3 % of the samples are clipped)."""
    from scipy.signal import butter, sosfilt

    rng = np.random.default_rng(seed)
    settle = round(1.0 / dt)
    sos = butter(4, band_hz, btype="low", fs=1.0 / dt, output="sos")
    z = sosfilt(sos, rng.standard_normal(int(samples) + settle))[settle:]
    z = z / float(np.std(z))
    out: FloatArray = np.clip(50.0 + 50.0 * z / 3.0, 0.0, 100.0)
    return out


def bench(noise_um: float) -> plant.BenchSettings:
    """The default bench with vibrometer noise `noise_um` [µm] and no resolution rounding."""
    return replace(plant.BenchSettings(), noise_um=float(noise_um), resolution_um=0.0)


def project(p: Params, margin: float = REGION_MARGIN, n_bounds: tuple[float, float] = N_BOUNDS) -> Params:
    """`p` moved into the region where the model is well posed: n clamped to `n_bounds`,
    β + γ and β − γ raised to at least `margin` (the horizon method's projection)."""
    beta, gamma = p.beta, p.gamma
    if beta + gamma < margin:
        shift = 0.5 * (margin - (beta + gamma))
        beta, gamma = beta + shift, gamma + shift
    if beta - gamma < margin:
        shift = 0.5 * (margin - (beta - gamma))
        beta, gamma = beta + shift, gamma - shift
    return p.replace(beta=beta, gamma=gamma, n=min(max(p.n, n_bounds[0]), n_bounds[1]))


# --------------------------------------------------------------------------- one run


@dataclass
class Record:
    """What an identifier did: the estimates (rows kv, x0, A, β, γ, n, δ) and h [µm]
    after every push, with the starting values as row −1 (``params[0]``, ``h[0]``) so
    that row k + 1 holds the values after sample k."""

    params: FloatArray
    h: FloatArray
    predictions: FloatArray
    forecasts: dict[int, FloatArray] = field(default_factory=dict)
    """``Identifier.forecast`` over each requested period, by its first sample k0 (the
    model open loop from the state after sample k0 − 1, effects included)."""


def record_run(ident: Identifier, u: FloatArray, x: FloatArray, periods: Sequence[tuple[int, int]] = ()) -> Record:
    """Pushes every sample and records the estimates and h after each push, and the
    identifier's forecast over each period ``(k0, k1)`` of `periods` at its start."""
    n = u.size
    params = np.empty((n + 1, 7))
    h = np.empty(n + 1)
    pred = np.empty(n)
    params[0] = ident.params.to_array()
    h[0] = ident.h
    push = ident.push
    ends = dict(periods)
    forecasts: dict[int, FloatArray] = {}
    for k, (a, b) in enumerate(zip(u.tolist(), x.tolist())):
        if k in ends:
            forecasts[k] = ident.forecast(u[k : ends[k]])
        pred[k] = push(a, b)
        params[k + 1] = ident.params.to_array()
        h[k + 1] = ident.h
    return Record(params, h, pred, forecasts)


def period_bounds(segments: Sequence[tuple[float, int, int]], dt: float) -> list[tuple[int, int]]:
    """(k0, k1) of every period of every segment, as :func:`boucwen.evaluation.period_ahead` cuts them."""
    out = []
    for f, lo, hi in segments:
        p = evaluation.period_samples(f, dt)
        out += [(k0, min(hi, k0 + p)) for k0 in range(lo, hi, p)]
    return out


def implicit_intervals(params: FloatArray, h: FloatArray, u: FloatArray, dt: float) -> NDArray[np.bool_]:
    """For each interval u[k−1] → u[k] (k ≥ 1), whether the integrator takes the implicit
    path when it starts from estimates ``params[k−1]`` and state ``h[k−1]`` (rows as in
    :class:`Record` shifted by one: pass ``rec.params[1:-1]``, ``rec.h[1:-1]``): the
    core's own plan of each interval (``interval_plan`` in ``rust/model/integrator.rs``).
    An interval over which u holds is not integrated and is not implicit."""
    p = np.ascontiguousarray(params, dtype=np.float64)
    h0 = np.asarray(h, dtype=np.float64)
    if p.shape[0] != u.size - 1 or h0.size != u.size - 1:
        raise ValueError("params and h need one row per interval (len(u) - 1)")
    out: NDArray[np.bool_] = _substep_plan(p.ravel(), h0, u, dt) < 0
    return out


def scores_from_record(
    rec: Record, u: FloatArray, x: FloatArray, dt: float, segments: Sequence[tuple[float, int, int]]
) -> list[tuple[float, list[float], float]]:
    """Period-ahead errors from a recorded run, segment by segment: ``(f, per_period,
    score)`` with the max error [µm] of every period and of the segment's last full
    period, computed as :func:`boucwen.evaluation.period_ahead` does (frozen estimates
    and h after sample k0 − 1, open loop over the period from the interval u[k0−1] → u[k0])."""
    out: list[tuple[float, list[float], float]] = []
    for f, lo, hi in segments:
        p = evaluation.period_samples(f, dt)
        starts = list(range(lo, hi, p))
        errors: list[float] = []
        for k0 in starts:
            k1 = min(hi, k0 + p)
            if k0 in rec.forecasts:
                x_sim = rec.forecasts[k0]
            else:
                params = Params.from_array(rec.params[k0])
                u_prev = float(u[k0 - 1]) if k0 > 0 else None
                x_sim, _ = simulate(params, u[k0:k1], dt, float(rec.h[k0]), u_prev)
            errors.append(float(np.max(np.abs(x[k0:k1] - x_sim))))
        full = [e for k0, e in zip(starts, errors) if k0 + p <= hi]
        out.append((f, errors, full[-1] if full else errors[-1]))
    return out


def _traditional_scores(
    x_trad: FloatArray, x: FloatArray, dt: float, segments: Sequence[tuple[float, int, int]]
) -> list[float]:
    err = np.abs(x - x_trad)
    return [float(np.max(err[evaluation.scored_period(f, lo, hi, dt)])) for f, lo, hi in segments]


def _region(rec: Record) -> dict[str, Any]:
    p = rec.params
    total, diff, n = p[:, 3] + p[:, 4], p[:, 3] - p[:, 4], p[:, 5]
    inside = (total > 0.0) & (diff > 0.0) & (n >= N_BOUNDS[0]) & (n <= N_BOUNDS[1]) & np.all(np.isfinite(p), axis=1)
    return {
        "min_beta_plus_gamma": float(np.min(total)),
        "min_beta_minus_gamma": float(np.min(diff)),
        "n_min": float(np.min(n)),
        "n_max": float(np.max(n)),
        "max_abs_beta": float(np.max(np.abs(p[:, 3]))),
        "max_abs_gamma": float(np.max(np.abs(p[:, 4]))),
        "kv_range": [float(np.min(p[:, 0])), float(np.max(p[:, 0]))],
        "A_range": [float(np.min(p[:, 2])), float(np.max(p[:, 2]))],
        "outside": int(np.sum(~inside)),
        "ok": bool(np.all(inside)),
    }


def run_case(
    case: Case,
    u: FloatArray,
    x: FloatArray,
    dt: float,
    segments: Sequence[tuple[float, int, int]],
    start: Params,
    h0: float,
    traditional: Sequence[float],
) -> dict[str, Any]:
    """One method over one record: region, period-ahead ratios to `traditional` (its
    score per segment), implicit-path share."""
    t0 = time.perf_counter()
    rec = record_run(case.make(dt, start, h0), u, x, period_bounds(segments, dt))
    scores = scores_from_record(rec, u, x, dt, segments)
    implicit = implicit_intervals(rec.params[1:-1], rec.h[1:-1], u, dt)
    ratios: dict[str, list[float]] = {}
    for (f, _, score), trad in zip(scores, traditional):
        ratios.setdefault(evaluation.key(f), []).append(score / trad if trad > 0 else math.inf)
    per_freq: dict[str, dict[str, Any]] = {
        f: {
            "median": float(np.median(r)),
            "worst": float(np.max(r)),
            "over_2": int(np.sum(np.asarray(r) > TRADITIONAL_FACTOR)),
            "all": [float(v) for v in r] if len(r) <= 100 else [],
        }
        for f, r in ratios.items()
    }
    share = float(np.mean(implicit)) if implicit.size else 0.0
    region = _region(rec)
    return {
        "case": case.label,
        "samples": int(u.size),
        "region": region,
        "ratio_traditional": per_freq,
        "ratio_ok": all(v["worst"] <= TRADITIONAL_FACTOR for v in per_freq.values()),
        "implicit_share": share,
        "explicit_ok": 1.0 - share >= EXPLICIT_SHARE,
        "final_params": rec.params[-1].tolist(),
        "wall_s": time.perf_counter() - t0,
    }


# --------------------------------------------------------------------------- experiment


def _record_for(
    kind: str, noise_um: float, repeats: int, random_samples: int, dt: float, seed: int
) -> tuple[FloatArray, FloatArray, list[tuple[float, int, int]]]:
    if kind == "schedule":
        u_cmd, segments = repeated_schedule(repeats, dt)
        noise_seed = seed
    else:
        u_cmd = random_input(random_samples, dt, seed)
        segments = [(1.0 / (RANDOM_BLOCK * dt), 0, u_cmd.size)]
        noise_seed = seed + 1
    rec = plant.measure(u_cmd, dt, bench(noise_um), seed=noise_seed)
    return rec.u, rec.x, segments


def run(
    *,
    repeats: int = REPEATS,
    random_samples: int = RANDOM_SAMPLES,
    noise_levels: Sequence[float] = NOISE_LEVELS_UM,
    cases: Sequence[Case] | None = None,
    inputs: Sequence[str] = ("schedule", "random"),
    seed: int = SEED,
    fit_options: dict[str, Any] | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Every case on every record; returns ``{"settings": ..., "runs": [...]}`` (JSON-ready)."""
    say = progress or (lambda _msg: None)
    dt = plant.DEFAULT_DT
    cases = list(cases) if cases is not None else default_cases()
    started = time.perf_counter()
    runs: list[dict[str, Any]] = []
    for kind in inputs:
        for noise in noise_levels:
            u, x, segments = _record_for(kind, noise, repeats, random_samples, dt, seed)
            fit_n = round(3.0 / dt)
            trad = fit(u[:fit_n], x[:fit_n], dt, seed=seed, **dict(fit_options or {}))
            start = project(trad.params)
            x_trad = np.asarray(simulate(trad.params, u, dt, trad.h0)[0])
            traditional = _traditional_scores(x_trad, x, dt, segments)
            say(
                f"[{time.perf_counter() - started:6.1f} s] {kind}, noise {noise * 1e3:g} nm: {u.size} samples; "
                f"traditional {trad.params!r}, started from {start!r}"
            )
            for case in cases:
                res = run_case(case, u, x, dt, segments, start, trad.h0, traditional)
                res.update({"input": kind, "noise_um": noise})
                runs.append(res)
                say(f"[{time.perf_counter() - started:6.1f} s]   {_row(res)}")
    return {
        "settings": {
            "repeats": repeats,
            "random_samples": random_samples,
            "random_band_hz": RANDOM_BAND_HZ,
            "random_block": RANDOM_BLOCK,
            "noise_levels_um": list(noise_levels),
            "seed": seed,
            "dt_s": dt,
            "n_bounds": list(N_BOUNDS),
            "targets": {"traditional_factor": TRADITIONAL_FACTOR, "explicit_share": EXPLICIT_SHARE},
        },
        "runs": runs,
        "wall_s": time.perf_counter() - started,
    }


def _row(r: dict[str, Any]) -> str:
    reg = r["region"]
    ratios = " ".join(f"{v['worst']:>7.3g}" for v in r["ratio_traditional"].values())
    return (
        f"{r['input']:<9}{r['noise_um'] * 1e3:>4g} nm  {r['case']:<15}{r['samples']:>9}"
        f"{reg['min_beta_plus_gamma']:>11.3g}{reg['min_beta_minus_gamma']:>11.3g}"
        f"  {reg['n_min']:.2f}-{reg['n_max']:.2f}{reg['max_abs_beta']:>10.3g}"
        f"  {'yes' if reg['ok'] else 'NO ':<4}  {ratios}  {'yes' if r['ratio_ok'] else 'NO ':<4}"
        f"{100 * r['implicit_share']:>8.3f} %  {'yes' if r['explicit_ok'] else 'NO'}"
    )


def format_table(results: dict[str, Any]) -> str:
    """One line per run: region (min β ± γ, n range, max |β|, ok), worst period-ahead
    ratio to the traditional per frequency (or per 0.1 s block on the random input),
    implicit-path share."""
    lines = [
        f"{'input':<9}{'noise':>7}  {'method':<15}{'samples':>9}{'min b+g':>11}{'min b-g':>11}"
        f"  {'n range':<9}{'max|b|':>10}  {'reg.':<4}  worst period-ahead / traditional"
        f"  {'<=2':<4}{'implicit':>10}  >=95% expl.",
    ]
    for kind in dict.fromkeys(r["input"] for r in results["runs"]):
        rows = [r for r in results["runs"] if r["input"] == kind]
        freqs = " ".join(f"{f + ' Hz':>7}" for f in rows[0]["ratio_traditional"])
        lines.append(f"-- {kind} (worst ratio over {'repeats' if kind == 'schedule' else 'blocks'}: {freqs})")
        lines.extend(_row(r) for r in rows)
    lines.append(f"wall time {results['wall_s']:.0f} s")
    return "\n".join(lines)


def quick_options() -> dict[str, Any]:
    """Keyword arguments of :func:`run` for the shortened version (``--quick``, the test):
    3 repeats (101 401 samples), 10⁵ random samples, noise 0 and 5 nm, N = 50 and 5000,
    a lighter traditional fit."""
    return {
        "repeats": 3,
        "random_samples": 100_000,
        "noise_levels": (0.0, 0.005),
        "cases": default_cases((50, 5000)),
        "fit_options": {"n_candidates": 16, "n_starts": 2},
    }


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.long_run",
        description="Online methods over 10^6 samples: well-posed estimates, period-ahead error, integrator path.",
    )
    ap.add_argument("--quick", action="store_true", help="shortened version (3 repeats, 10^5 random samples)")
    ap.add_argument("--json", default=None, help="write the results to this file")
    ap.add_argument(
        "--paper-bounds-off",
        action="store_true",
        help="run only the paper method, with max_hysteresis_gain and max_delta_ratio = inf (labelled N=...*)",
    )
    args = ap.parse_args(argv)
    options = quick_options() if args.quick else {}
    if args.paper_bounds_off:
        options["cases"] = bounds_off_cases((50, 5000) if args.quick else PAPER_WINDOWS)

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    results = run(progress=progress, **options)
    print(format_table(results))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(jsonable(results), fh, indent=2, allow_nan=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
