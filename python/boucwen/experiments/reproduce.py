"""The paper's experiment (Zhu, Bian & Rui 2014, section 4) on the simulated bench.

Steps of :func:`run`:

1. **Input.** u = 50 + 50·sin(2πf·t − π/2) [V] from :func:`boucwen.plant.paper_input`
   at the bench's sampling interval (:data:`boucwen.plant.DEFAULT_DT`, 10 kHz):
   1 Hz for 3 s, 10 Hz for 0.3 s, 100 Hz for 0.03 s, then 200 Hz for **0.1 s
   (20 periods)** — longer than the paper's Fig. 8 (which ends about 15 ms after
   the switch) so that the 200 Hz steady state is reached by every method.
2. **Measurement.** :func:`boucwen.plant.measure` with the default
   :class:`boucwen.plant.BenchSettings` (or the ones given).
3. **Traditional method.** :func:`boucwen.fit` on the 1 Hz part; its parameters
   and h0 are then held fixed and simulated over the whole record.
4. **Online methods** (:data:`ONLINE_METHODS`), each started from the traditional
   values and pushed the whole record sample by sample.
5. **Table 1** — the headline — scores every method as a *model*, period-ahead
   (:mod:`boucwen.evaluation`): at the start of each period the estimates and the
   model's h are frozen and the model runs open loop over the period; beside it the
   **refit oracle** (an offline fit on the two periods before the scored one) and the
   best fixed parameters per frequency. **Table 1b** is the one-step-ahead error,
   printed beside two predictors with no model (persistence and the two-tap
   extrapolator), which a one-step figure must beat to mean anything.
   **Table 2**: the online estimates at the end of each frequency, beside the paper's.
   Adaptation times after each switch, from the period-ahead errors. For the paper's
   method, the share of pushes on which each of its five steps ran, per frequency, and
   why it held (``paper_steps``, :func:`step_shares`).
6. ``DIR/results.json``, ``DIR/predictions.npz`` (every signal the tables and
   figures are computed from) and the figures ``DIR/fig6_1_to_10hz.png``,
   ``fig7_10_to_100hz.png``, ``fig8_100_to_200hz.png``, ``fig9_loops.png``.

Definitions:

* **Steady state** of a frequency: its last full period (for 200 Hz the last
  period of the record). Table 1 is the maximum of |x − x̂| there, x̂ the frozen
  model's open-loop prediction of that period.
* **Adaptation time** after a switch (or after the start, for 1 Hz): split the
  segment into whole periods; it is the time from the switch to the start of the
  first period from which on *every* period's maximum |x − x̂| stays within
  :data:`ADAPTATION_FACTOR` (1.5) × the steady-state value. 0 means the error never
  left that band; the time is a whole number of periods of the new frequency.
* **Window** (limited memory N) of the paper method: by default one period of
  the highest input frequency (50 samples = 5 ms at 10 kHz and 200 Hz). The paper
  reports an adaptive state of about one period of the new frequency after each
  switch; a limited-memory estimate rests entirely on data of the new frequency
  only once N samples have passed, so N can be at most about one period of the
  fastest frequency. ``results.json`` also holds a sweep over N of the paper
  method (``window_sweep``)
  so the sensitivity to this choice is on record.
* **Best fixed parameters per frequency** (``best_fixed_per_frequency``): the
  traditional fit repeated on each frequency's own data, evaluated on its steady
  state. No method that adapts the seven parameters can do better in steady
  state, so it separates the model's structural error from the identifier's.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from .. import evaluation, plant
from .._core import EffectSet, Identifier, Params, simulate, simulate_extended
from ..config import HorizonConfig, PaperConfig, RpemConfig
from ..fit import FitResult, fit
from ..io import jsonable
from ..pacing import COOPERATIVE_INTERVALS, REFINE_MODES, PacedFeed, RefineMode, feed_for, realtime
from ..status import PaperStatus

if TYPE_CHECKING:
    from .._core import _IdentifierMethod

__all__ = [
    "ADAPTATION_FACTOR",
    "ADAPTATION_RULE",
    "DEFAULT_OUT",
    "ONLINE_METHODS",
    "PAPER_STEPS",
    "PAPER_TABLE1",
    "PAPER_TABLE2",
    "QUICK_SEGMENTS",
    "SEGMENTS",
    "STEADY_STATE",
    "OnlineMethod",
    "StepTally",
    "adaptation_times",
    "available_online_methods",
    "default_online_method",
    "default_window",
    "fixed_parameter_prediction",
    "format_step_shares",
    "format_window_sweep",
    "refine_variants",
    "run",
    "steady_state_slice",
    "step_shares",
    "table1_from_predictions",
]

#: Default output directory of ``boucwen reproduce``.
DEFAULT_OUT = os.path.join("out", "reproduce")

#: The experiment's input: (frequency [Hz], duration [s]); 200 Hz for 0.1 s = 20 periods.
SEGMENTS: tuple[tuple[float, float], ...] = ((1.0, 3.0), (10.0, 0.3), (100.0, 0.03), (200.0, 0.1))
#: Reduced input for ``--quick`` (tests, smoke runs): 1 s, 0.1 s, 0.02 s, 0.02 s.
QUICK_SEGMENTS: tuple[tuple[float, float], ...] = ((1.0, 1.0), (10.0, 0.1), (100.0, 0.02), (200.0, 0.02))

#: Paper, Table 1: maximum absolute error in steady state [µm].
PAPER_TABLE1: dict[str, dict[str, float]] = {
    "traditional": {"1": 0.47, "10": 0.75, "100": 1.25, "200": 2.91},
    "online": {"1": 0.47, "10": 0.48, "100": 0.45, "200": 0.49},
}
#: Paper, Table 2: the online estimates at each frequency (units of :class:`Params`).
PAPER_TABLE2: dict[str, dict[str, float]] = {
    "1": {"kv": 0.19, "x0": 0.015, "A": -0.072, "beta": 0.020, "gamma": -0.019, "n": 1.52, "delta": 0.0075},
    "10": {"kv": 0.18, "x0": 0.017, "A": -0.072, "beta": 0.025, "gamma": -0.021, "n": 1.53, "delta": 0.0067},
    "100": {"kv": 0.18, "x0": 0.021, "A": -0.072, "beta": 0.023, "gamma": -0.018, "n": 1.51, "delta": 0.0063},
    "200": {"kv": 0.16, "x0": 0.013, "A": -0.10, "beta": 0.015, "gamma": -0.005, "n": 1.68, "delta": 0.0045},
}

#: Band of the adaptation rule: per-period maximum error within this × steady state.
ADAPTATION_FACTOR = 1.5
METRIC = (
    "period-ahead: at the start of every period the online estimates and the model's h are "
    "frozen and the model is simulated open loop over the period; the score of a frequency is "
    "max |x - x_hat| over its last full period. One-step-ahead errors (each sample predicted "
    "from all samples before it) are a second table, beside two predictors with no model"
)
STEADY_STATE = (
    "the last full period of each frequency (for the last frequency, the last "
    "period of the record); Table 1 is max |x - x_hat| over it"
)
ADAPTATION_RULE = (
    f"time from the switch (or from the start, for the first frequency) to the "
    f"start of the first whole period of the new frequency from which on every "
    f"period's max |x - x_hat| stays within {ADAPTATION_FACTOR} x the steady-state "
    f"value; a whole number of periods"
)

_PARAM_NAMES = ("kv", "x0", "A", "beta", "gamma", "n", "delta")


# --------------------------------------------------------------------------- methods


@dataclass(frozen=True)
class OnlineMethod:
    """One online identifier in the comparison.

    Attributes:
        label: key suffix in the results (``online_<label>``).
        method: the ``method`` argument of :class:`boucwen.Identifier`.
        options: extra keyword arguments of :class:`boucwen.Identifier`.
        description: one line for the printed tables.
        refine: where the recommended identifier's window pass runs ("sync",
            "cooperative", "background"; see :mod:`boucwen.pacing` for how each is fed).
    """

    label: str
    method: _IdentifierMethod
    options: Mapping[str, Any] = field(default_factory=dict)
    description: str = ""
    refine: RefineMode = "sync"


#: Every online method the experiment compares, in print order. Methods the
#: installed library does not offer (Identifier raises ValueError) are skipped.
ONLINE_METHODS: tuple[OnlineMethod, ...] = (
    OnlineMethod(
        "horizon", "horizon", {}, "moving-horizon output-error least squares, input lag identified (library default)"
    ),
    OnlineMethod("horizon_base", "horizon", {}, "moving-horizon output-error least squares, seven parameters only"),
    OnlineMethod("rpem", "rpem", {}, "recursive prediction-error (output-error) method"),
    OnlineMethod("paper", "paper", {}, "paper's method, kv/x0 from x - h_model"),
    OnlineMethod(
        "paper_literal", "paper", {"decomposition": "line"}, "paper's method, kv/x0 = line through the loop (literal)"
    ),
)


def _make_identifier(m: OnlineMethod, dt: float, window: int, init: Params, h0: float) -> Identifier:
    if m.method == "paper":
        return Identifier.paper(dt, window, init, h0, config=PaperConfig(**dict(m.options)))
    if m.method == "rpem":
        return Identifier.rpem(dt, init, h0, config=RpemConfig(**dict(m.options)))
    config = HorizonConfig(**dict(m.options))
    if m.label.startswith("horizon") and m.label != "horizon_base":
        return Identifier(dt, init, h0, config=config, refine=m.refine)
    return Identifier.horizon(dt, init, h0, config=config)


def refine_variants(modes: Sequence[str]) -> list[OnlineMethod]:
    """The library default ("horizon") with its window pass run in each mode of `modes`
    other than "sync" (which is the ``horizon`` row itself): labels ``horizon_cooperative``
    (``refine(COOPERATIVE_INTERVALS)`` after every push) and ``horizon_background`` (the
    record replayed at its own sample rate, the pass on a worker thread)."""
    what = {
        "cooperative": f"refine({COOPERATIVE_INTERVALS}) after every push",
        "background": "worker thread, the record replayed at its own sample rate",
    }
    return [
        OnlineMethod(f"horizon_{mode}", "horizon", {}, f"library default, window pass {mode}: {what[mode]}", mode)
        for mode in REFINE_MODES
        if mode in modes and mode != "sync"
    ]


def available_online_methods(
    dt: float = plant.DEFAULT_DT, window: int = 50, init: Params | None = None
) -> list[OnlineMethod]:
    """The entries of :data:`ONLINE_METHODS` that :class:`boucwen.Identifier` accepts."""
    init = init if init is not None else Params.paper_1hz()
    out = []
    for m in ONLINE_METHODS:
        try:
            _make_identifier(m, dt, window, init, 0.0)
        except (ValueError, TypeError):
            continue
        out.append(m)
    return out


def default_online_method(labels: Sequence[str]) -> str:
    """The library's default online method, reported as ``online``: the first of
    "horizon", "rpem", "paper" that is available."""
    return next((m for m in ("horizon", "rpem", "paper") if m in labels), labels[0])


def default_window(segments: Sequence[tuple[float, int, int]], dt: float) -> int:
    """One period of the highest frequency [samples], at least 16 (see the module docs)."""
    fmax = max(f for f, _, _ in segments)
    return max(16, round(1.0 / (fmax * dt)))


# --------------------------------------------------------------------------- paper's steps

#: The five steps of the paper's method and the window fit, as :class:`boucwen.PaperStatus`
#: names them (the window fit's status is that of its last run: it runs once per slide of
#: ``PaperConfig.fit_every`` of the window).
PAPER_STEPS: tuple[str, ...] = ("line_fit", "rate_fit", "shape_fit", "return_fit", "split_fit", "window_fit")


@dataclass
class StepTally(PacedFeed):
    """Pushes the samples one at a time, as fast as it goes, and keeps the status of
    every push of the paper's method (``statuses[k]`` after sample k; other methods'
    statuses are not kept)."""

    paced: bool = False
    statuses: list[PaperStatus] = field(default_factory=list)

    def push_many(self, ident: Identifier, u: Any, x: Any) -> np.ndarray:
        ua = np.ascontiguousarray(u, dtype=np.float64)
        xa = np.ascontiguousarray(x, dtype=np.float64)
        out = np.empty_like(ua)
        for i, (a, b) in enumerate(zip(ua.tolist(), xa.tolist())):
            out[i] = ident.push(a, b)
            status = ident.status
            if isinstance(status, PaperStatus):
                self.statuses.append(status)
        self.samples += ua.size
        return out


def step_shares(
    statuses: Sequence[PaperStatus], segments: Sequence[tuple[float, int, int]]
) -> dict[str, dict[str, dict[str, Any]]]:
    """Per step of the paper's method and per frequency: the share of pushes on which it
    ran in full (``ran``), ran reduced (``reduced``) and held (``held``), the share of
    pushes held or reduced for each reason (``reasons``), and the median points and
    noise of the pushes on which it ran or ran reduced (``points``, ``noise``; NaN if
    never). ``statuses[k]`` is the status after sample k."""
    out: dict[str, dict[str, dict[str, Any]]] = {step: {} for step in PAPER_STEPS}
    for f, lo, hi in segments:
        part = statuses[lo:hi]
        total = max(1, len(part))
        for step in PAPER_STEPS:
            rows = [getattr(s, step) for s in part]
            used = [r for r in rows if r.outcome != "held"]
            reasons: dict[str, float] = {}
            for r in rows:
                if r.reason != "none":
                    reasons[r.reason] = reasons.get(r.reason, 0.0) + 1.0 / total
            out[step][_key(f)] = {
                "ran": sum(r.outcome == "ran" for r in rows) / total,
                "reduced": sum(r.outcome == "reduced" for r in rows) / total,
                "held": sum(r.outcome == "held" for r in rows) / total,
                "reasons": reasons,
                "points": float(np.median([r.points for r in used])) if used else float("nan"),
                "noise": float(np.median([r.noise for r in used])) if used else float("nan"),
            }
    return out


def format_step_shares(shares: Mapping[str, Mapping[str, Mapping[str, Any]]], freqs: Sequence[str]) -> list[str]:
    """Lines of a table: per step, the share of pushes on which it ran (in full +
    reduced) per frequency, and the main reason it held."""
    heads = [f"{f} Hz" for f in freqs]
    lines = [
        "Share of pushes on which each step of the paper's method ran (in full + reduced); main reasons",
        f"{'step':<12}" + "".join(f"{h:>9}" for h in heads) + "   held or reduced because (mean share)",
    ]
    for step in PAPER_STEPS:
        rows = shares[step]
        reasons: dict[str, float] = {}
        for f in freqs:
            for why, v in rows[f]["reasons"].items():
                reasons[why] = reasons.get(why, 0.0) + v / len(freqs)
        why_text = ", ".join(f"{k} {v:.2f}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1])[:3])
        lines.append(
            f"{step:<12}" + "".join(f"{rows[f]['ran'] + rows[f]['reduced']:>9.3f}" for f in freqs) + f"   {why_text}"
        )
    return lines


# --------------------------------------------------------------------------- metrics


def _period(f: float, dt: float) -> int:
    return max(1, round(1.0 / (f * dt)))


def steady_state_slice(f: float, lo: int, hi: int, dt: float) -> slice:
    """Samples of the steady state of a segment [lo, hi): its last full period."""
    return slice(max(lo, hi - _period(f, dt)), hi)


def _key(f: float) -> str:
    return f"{f:g}"


def table1_from_predictions(
    x: np.ndarray,
    predictions: Mapping[str, np.ndarray],
    segments: Sequence[tuple[float, int, int]],
    dt: float,
) -> dict[str, dict[str, float]]:
    """Table 1: ``{label: {"1": max|x − x̂| in steady state [µm], ...}}``."""
    return {
        label: {_key(f): float(np.max(np.abs(x - pred)[steady_state_slice(f, lo, hi, dt)])) for f, lo, hi in segments}
        for label, pred in predictions.items()
    }


def adaptation_times(
    x: np.ndarray,
    pred: np.ndarray,
    segments: Sequence[tuple[float, int, int]],
    dt: float,
    factor: float = ADAPTATION_FACTOR,
) -> dict[str, dict[str, float]]:
    """Adaptation time per segment (see the module docs): ``{"1": {"s": …, "periods": …}, …}``."""
    err = np.abs(x - pred)
    out: dict[str, dict[str, float]] = {}
    for f, lo, hi in segments:
        p = _period(f, dt)
        count = max(1, (hi - lo) // p)
        maxima = np.array([np.max(err[lo + k * p : min(hi, lo + (k + 1) * p)]) for k in range(count)])
        steady = float(np.max(err[steady_state_slice(f, lo, hi, dt)]))
        bad = np.flatnonzero(maxima > factor * steady)
        first_good = int(bad[-1]) + 1 if bad.size else 0
        out[_key(f)] = {"s": first_good * p * dt, "periods": first_good}
    return out


# --------------------------------------------------------------------------- run


def _params_dict(p: Params) -> dict[str, float]:
    return {k: float(v) for k, v in p.to_dict().items()}


def _run_online(
    m: OnlineMethod,
    u: np.ndarray,
    x: np.ndarray,
    dt: float,
    window: int,
    init: Params,
    h0: float,
    segments: Sequence[tuple[float, int, int]],
    real_time: bool = False,
) -> dict[str, Any]:
    """Runs one online method over the record and scores it (see :mod:`boucwen.evaluation`);
    with `real_time`, a paced replay (and its worker) runs under SCHED_FIFO where granted
    (:func:`boucwen.pacing.realtime`).

    Returns a dict with ``period_ahead`` (score per frequency [µm]), ``per_period``
    (every period's max error), ``one_step`` and ``trace`` (the one-step and the
    period-ahead predictions [µm]), ``estimates`` (the parameters at the end of each
    frequency, Table 2) and, for the paper's method, ``steps`` (:func:`step_shares`)."""
    freezes: list[tuple[int, Params, EffectSet | None]] = []
    trace = np.empty_like(x)
    tally = StepTally(dt) if m.method == "paper" else None
    feed = tally if tally is not None else feed_for(m.refine, dt)
    started = time.perf_counter()
    with realtime() if real_time and feed is not None and feed.paced else nullcontext(False) as granted:
        ident = _make_identifier(m, dt, window, init, h0)
        score, per_period, one_step = evaluation.period_ahead(
            ident,
            u,
            x,
            dt,
            segments,
            on_period=lambda _f, k0, p, _h: freezes.append((k0, p, ident.effects)),
            trace=trace,
            feed=feed,
        )
    status = ident.status
    updates = getattr(status, "updates", None)
    behind = getattr(status, "behind_samples", None)
    replay = {
        "refine": m.refine,
        "real_time": granted,
        "paced": bool(feed is not None and feed.paced),
        "refine_intervals_per_push": feed.refine_intervals if feed is not None else 0,
        "late_samples": feed.late_samples if feed is not None else 0,
        "max_late_s": feed.max_late_s if feed is not None else 0.0,
        "wall_s": time.perf_counter() - started,
        "updates": updates,
        "behind_samples_at_end": behind,
    }
    estimates = {}
    effects: dict[str, EffectSet | None] = {}
    for i, (f, _, hi) in enumerate(segments):
        last = (0, ident.params, ident.effects)
        after = next((fr for fr in freezes if fr[0] == hi), last) if i + 1 < len(segments) else last
        estimates[_key(f)] = _params_dict(after[1])
        effects[_key(f)] = after[2]
    return {
        "effects": effects,
        "period_ahead": score,
        "per_period": per_period,
        "one_step": one_step,
        "trace": trace,
        "estimates": estimates,
        "replay": replay,
        "steps": step_shares(tally.statuses, segments) if tally is not None else None,
    }


def adaptation_from_periods(
    per_period: Mapping[str, Sequence[float]], segments: Sequence[tuple[float, int, int]], dt: float
) -> dict[str, dict[str, float]]:
    """Adaptation time per frequency from the period-ahead errors of its periods (see the module docs)."""
    out: dict[str, dict[str, float]] = {}
    for f, lo, hi in segments:
        p = _period(f, dt)
        errs = list(per_period[_key(f)])
        full = errs[: max(1, (hi - lo) // p)]
        steady = full[-1]
        bad = [i for i, e in enumerate(full) if e > ADAPTATION_FACTOR * steady]
        first_good = bad[-1] + 1 if bad else 0
        out[_key(f)] = {"s": first_good * p * dt, "periods": first_good}
    return out


def fixed_parameter_prediction(
    u: np.ndarray,
    dt: float,
    estimates: Mapping[str, Mapping[str, float]],
    segments: Sequence[tuple[float, int, int]],
    h0: float,
    effects: Mapping[str, EffectSet | None] | None = None,
) -> np.ndarray:
    """The model run with *fixed* parameters per frequency, as in the paper's Fig. 9.

    For each segment, the model with that segment's end-of-frequency estimates
    (Table 2, with the effects identified along, e.g. the input lag, when given) is
    simulated from t = 0 (h[0] = ``h0``) to the end of the segment; the
    returned array holds, on each segment, that simulation [µm]. A parameter set
    that cannot be simulated gives NaN on its segment.
    """
    out = np.full(u.shape, np.nan)
    for f, lo, hi in segments:
        try:
            p = Params.from_dict(dict(estimates[_key(f)]))
            e = effects.get(_key(f)) if effects is not None else None
            xs = simulate_extended(p, e, u[:hi], dt, h0) if e else simulate(p, u[:hi], dt, h0)[0]
        except ValueError:
            continue
        out[lo:hi] = np.asarray(xs)[lo:hi]
    return out


def _fmt_row(name: str, values: Sequence[float | None], width: int = 9, fmt: str = "{:.3f}") -> str:
    """One table row; a missing value (None or NaN) prints as a dash."""
    cells = ("-" if v is None or not np.isfinite(v) else fmt.format(v) for v in values)
    return f"{name:<34}" + "".join(f"{c:>{width}}" for c in cells)


def _print_tables(
    log: Callable[[str], None],
    freqs: Sequence[str],
    results: Mapping[str, Any],
    labels: Sequence[str],
    descriptions: Mapping[str, str],
    adapt: Mapping[str, Mapping[str, Mapping[str, float]]],
) -> None:
    heads = [f"{f} Hz" for f in freqs]
    t1, t1s, base = results["table1"], results["table1_one_step"], results["baselines"]
    log("")
    log("Table 1  period-ahead error: max |x - x_hat| [µm] over the last full period, model open loop")
    log(f"{'method':<34}" + "".join(f"{h:>9}" for h in heads))
    log(_fmt_row("traditional (this bench)", [t1["traditional"][f] for f in freqs]))
    log(_fmt_row("traditional (paper)", [PAPER_TABLE1["traditional"][f] for f in freqs]))
    for label in labels:
        log(_fmt_row(f"online_{label}", [t1[f"online_{label}"][f] for f in freqs]))
    log(_fmt_row("online (paper)", [PAPER_TABLE1["online"][f] for f in freqs]))
    log(_fmt_row("refit oracle (2 past periods)", [results["refit_oracle"][f] for f in freqs]))
    best = results.get("best_fixed_per_frequency") or {}
    if best:
        log(_fmt_row("best fixed params (in-sample)", [best[f] for f in freqs]))
    log("")
    log("Table 1b one-step-ahead error [µm], same periods, beside predictors with no model")
    log(f"{'method':<34}" + "".join(f"{h:>9}" for h in heads))
    for label in labels:
        log(_fmt_row(f"online_{label}, one step", [t1s[f"online_{label}"][f] for f in freqs]))
    log(_fmt_row("persistence x[k-1]", [base["persistence"][f] for f in freqs]))
    log(_fmt_row("two-tap 2x[k-1] - x[k-2]", [base["two_tap"][f] for f in freqs]))
    log("")
    log("Same, model run with the Table 2 estimates held fixed per frequency from t = 0 (Fig. 9):")
    for label in labels:
        log(_fmt_row(f"online_{label}, fixed", [results["table1_fixed"][f"online_{label}"][f] for f in freqs]))
    for label in labels:
        log(f"  online_{label}: {descriptions[label]}")
    log("")
    log("Adaptation time after each switch [s] (periods of the new frequency), period-ahead errors")
    for label in labels:
        a = adapt[f"online_{label}"]
        log(
            f"{'online_' + label:<34}"
            + "".join(f"{a[f]['s']:>9.4f}" for f in freqs)
            + "   ("
            + ", ".join(f"{a[f]['periods']}" for f in freqs)
            + ")"
        )
    log("")
    log("Table 2  online estimates at the end of each frequency (paper's value in brackets)")
    for label in labels:
        log(f"online_{label}:")
        log(f"{'f':>6}" + "".join(f"{n:>20}" for n in _PARAM_NAMES))
        for f in freqs:
            est = results["table2"][f"online_{label}"][f]
            log(
                f"{f + ' Hz':>6}"
                + "".join(f"{est[n]:>11.4g} ({PAPER_TABLE2[f][n]:.3g})".rjust(20) for n in _PARAM_NAMES)
            )
    sweep = results.get("window_sweep") or {}
    if sweep:
        log("")
        log("Window sweep, online_paper: error [µm] per frequency (period-ahead | one step)")
        for line in format_window_sweep(sweep, freqs):
            log(line)
    log("")


def format_window_sweep(sweep: Mapping[str, Mapping[str, Mapping[str, float]]], freqs: Sequence[str]) -> list[str]:
    """One line per window N: the period-ahead and the one-step error per frequency [µm]."""
    return [
        _fmt_row(f"N = {w}", [rows["period_ahead"][f] for f in freqs])
        + "  |"
        + "".join(f"{rows['one_step'][f]:>9.3f}" for f in freqs)
        for w, rows in sweep.items()
    ]


def run(
    out_dir: str | os.PathLike[str] = DEFAULT_OUT,
    *,
    quick: bool = False,
    window: int | None = None,
    seed: int = 0,
    settings: plant.BenchSettings | None = None,
    figures: bool = True,
    log: Callable[[str], None] | None = print,
    refine: Sequence[str] = ("sync",),
    real_time: bool = False,
) -> dict[str, Any]:
    """Runs the experiment and writes ``results.json``, ``predictions.npz`` and the figures.

    Args:
        out_dir: output directory (created if needed).
        quick: reduced input (:data:`QUICK_SEGMENTS`), a lighter fit, no window sweep
            and no per-frequency refits: for tests and smoke runs.
        window: limited memory N [samples] of the windowed online methods; default
            :func:`default_window`.
        seed: seed of the bench's noise and of the fit's random starts.
        settings: the bench (default :class:`boucwen.plant.BenchSettings`).
        figures: write the PNG figures.
        log: where progress and tables go (``None``: silent).
        refine: modes of the library default's window pass to run besides "sync" (the
            ``horizon`` row): "cooperative", "background" (:func:`refine_variants`);
            Table 1 of every mode is printed side by side with the sync one and kept
            in ``results["refine_modes"]``.
        real_time: run the paced replay and its worker under SCHED_FIFO (where granted,
            :func:`boucwen.pacing.realtime`): on a busy host, the extra core the
            background mode is meant to have.

    Returns:
        The content of ``results.json`` as a dict.

    Raises:
        ValueError: bad window; OSError: the directory cannot be written.
    """
    say = log or (lambda _msg: None)
    started = time.perf_counter()

    def step(msg: str) -> None:
        say(f"[{time.perf_counter() - started:6.1f} s] {msg}")

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    settings = settings if settings is not None else plant.BenchSettings()
    dt = plant.DEFAULT_DT
    seg_spec = QUICK_SEGMENTS if quick else SEGMENTS
    t, u_cmd, segments = plant.paper_input(dt, seg_spec)
    if window is None:
        window = default_window(segments, dt)
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 16:
        raise ValueError(f"window must be an integer >= 16 samples, got {window!r}")
    window = int(window)
    freqs = [_key(f) for f, _, _ in segments]

    step(
        f"measuring {t.size} samples at {1 / dt:.0f} Hz on the simulated bench "
        f"({', '.join(f'{f:g} Hz for {d:g} s' for f, d in seg_spec)})"
    )
    rec = plant.measure(u_cmd, dt, settings, seed=seed)
    u, x = rec.u, rec.x

    _, lo1, hi1 = segments[0]
    step(f"traditional method: output-error fit on the {freqs[0]} Hz part ({hi1 - lo1} samples)")
    fit_opts: dict[str, Any] = {"n_candidates": 16, "n_starts": 2} if quick else {}
    trad: FitResult = fit(u[lo1:hi1], x[lo1:hi1], dt, seed=seed, **fit_opts)
    step(
        f"  {trad.params!r}, h0 = {trad.h0:.4g} µm; rms {trad.rms_um:.4g} µm, max "
        f"{trad.max_um:.4g} µm, {trad.nfev} simulations, {trad.elapsed_s:.2f} s"
    )
    x_trad, _ = simulate(trad.params, u, dt, trad.h0)
    x_trad = np.asarray(x_trad)

    methods = available_online_methods(dt, window, trad.params)
    if any(m.label == "horizon" for m in methods):
        methods += refine_variants(refine)
    labels = [m.label for m in methods]
    default = default_online_method(labels)
    one_step: dict[str, np.ndarray] = {}
    traces: dict[str, np.ndarray] = {"traditional": x_trad}
    table1: dict[str, dict[str, float]] = {
        "traditional": evaluation.fixed_model(trad.params, trad.h0, u, x, dt, segments)
    }
    table2: dict[str, dict[str, dict[str, float]]] = {}
    per_period: dict[str, dict[str, list[float]]] = {}
    effects_at_end: dict[str, Mapping[str, EffectSet | None]] = {}
    replays: dict[str, dict[str, Any]] = {}
    paper_steps: dict[str, Any] = {}
    for m in methods:
        step(f"online method {m.label!r}" + (f" (window {window} samples)" if m.method == "paper" else ""))
        r = _run_online(m, u, x, dt, window, trad.params, trad.h0, segments, real_time)
        key = f"online_{m.label}"
        if m.label == "horizon" or m.refine != "sync":
            replays[m.refine] = {**r["replay"], "table1": r["period_ahead"]}
        one_step[key], traces[key] = r["one_step"], r["trace"]
        table1[key], table2[key], per_period[key] = r["period_ahead"], r["estimates"], r["per_period"]
        effects_at_end[key] = r["effects"]
        if r["steps"] is not None:
            paper_steps[key] = r["steps"]
    skipped = [m.label for m in ONLINE_METHODS if m.label not in labels]
    if skipped:
        step(f"online methods not available in this build: {', '.join(skipped)}")
    table1["online"] = table1[f"online_{default}"]
    table2["online"] = table2[f"online_{default}"]
    table2["traditional"] = {f: _params_dict(trad.params) for f in freqs}
    table1_one_step = table1_from_predictions(x, one_step, segments, dt)
    table1_one_step["online"] = table1_one_step[f"online_{default}"]
    baselines = evaluation.one_step_baselines(x, segments, dt)

    step("fixed-parameter check: the model with each frequency's Table 2 estimates")
    fixed = {
        f"online_{lab}": fixed_parameter_prediction(
            u, dt, table2[f"online_{lab}"], segments, trad.h0, effects_at_end[f"online_{lab}"]
        )
        for lab in labels
    }
    table1_fixed = table1_from_predictions(x, fixed, segments, dt)
    table1_fixed["online"] = table1_fixed[f"online_{default}"]
    adapt = {f"online_{lab}": adaptation_from_periods(per_period[f"online_{lab}"], segments, dt) for lab in labels}
    adapt["online"] = adapt[f"online_{default}"]

    step("refit oracle: an offline fit on the two periods before each scored period")
    oracle = evaluation.refit_oracle(u, x, dt, segments, init=trad.params, seed=seed)
    sweep: dict[str, dict[str, dict[str, float]]] = {}
    best_fixed: dict[str, float] = {}
    if not quick:
        # The sweep is over the limited memory N, so it runs the windowed method.
        dm = next(m for m in methods if m.label == "paper")
        # Up to 2000 samples: the paper method's output gate simulates the window at every
        # push (O(N) per sample), and a longer window holds more than one frequency in
        # every part after the 10 Hz one (3000 samples).
        windows = [w for w in (25, 50, 100, 200, 500, 1000, 2000) if w >= 16]
        step(f"window sweep of online_{dm.label}: N = {', '.join(map(str, windows))} samples")
        for w in windows:
            r = _run_online(dm, u, x, dt, w, trad.params, trad.h0, segments)
            sweep[str(w)] = {
                "period_ahead": r["period_ahead"],
                "one_step": table1_from_predictions(x, {"p": r["one_step"]}, segments, dt)["p"],
            }
        step("best fixed parameters per frequency: the traditional fit on each frequency's data")
        for f, lo, hi in segments:
            fr = fit(u[lo:hi], x[lo:hi], dt, init=trad.params, seed=seed)
            ss = steady_state_slice(f, lo, hi, dt)
            best_fixed[_key(f)] = float(np.max(np.abs(x[ss] - fr.x_fit[ss.start - lo : ss.stop - lo])))

    # The paper method's window for the headline row: the sweep's N whose worst
    # period-ahead error, as a ratio to the traditional fit's, is smallest.
    ratios = {w: [r["period_ahead"][f] / table1["traditional"][f] for f in freqs] for w, r in sweep.items()}
    worst_ratio = {w: max(v) for w, v in ratios.items()}
    mean_ratio = {w: sum(v) / len(v) for w, v in ratios.items()}
    # Where the gates hold every update at some frequency the worst ratio is the
    # traditional fit's own, 1, at several N: the mean over the frequencies then tells
    # the N where the updates the method does take help most.
    paper_window = {
        "chosen": int(min(sweep, key=lambda w: (worst_ratio[w], mean_ratio[w]))) if sweep else window,
        "rule": "the window of the sweep with the smallest worst period-ahead ratio to the traditional fit, "
        "ties broken by the smallest mean ratio",
        "worst_ratio_to_traditional": worst_ratio,
        "mean_ratio_to_traditional": mean_ratio,
    }
    results: dict[str, Any] = {
        "paper_window": paper_window,
        "table1": table1,
        "table1_one_step": table1_one_step,
        "baselines": baselines,
        "refit_oracle": oracle,
        "table2": table2,
        "table1_fixed": table1_fixed,
        "per_period": per_period,
        "metric": METRIC,
        "paper": {"table1": PAPER_TABLE1, "table2": PAPER_TABLE2},
        "plant": settings.to_dict(),
        "steady_state": STEADY_STATE,
        "adaptation_rule": ADAPTATION_RULE,
        "adaptation_time_s": {k: {f: v[f]["s"] for f in freqs} for k, v in adapt.items()},
        "adaptation_periods": {k: {f: v[f]["periods"] for f in freqs} for k, v in adapt.items()},
        "default_online_method": default,
        "online_methods": {
            m.label: {"method": m.method, "options": dict(m.options), "description": m.description} for m in methods
        },
        "window": {
            "samples": window,
            "s": window * dt,
            "rule": "one period of the highest input frequency (see boucwen.experiments.reproduce)",
        },
        "input": {
            "dt_s": dt,
            "segments": [
                {"f_hz": f, "duration_s": d, "start": lo, "stop": hi} for (f, d), (_, lo, hi) in zip(seg_spec, segments)
            ],
            "quick": quick,
            "seed": seed,
        },
        "traditional_fit": trad.to_dict(),
        "window_sweep": sweep,
        "best_fixed_per_frequency": best_fixed,
        "refine_modes": replays,
        "paper_steps": paper_steps,
    }

    results = jsonable(results)
    with open(out / "results.json", "w", encoding="utf-8") as fh:
        json.dump(results, fh, indent=2, allow_nan=False)
    arrays: dict[str, Any] = {
        "t": t,
        "u": u,
        "x": x,
        "dt": np.float64(dt),
        "segments": np.array([[f, lo, hi] for f, lo, hi in segments], dtype=np.float64),
        **{f"x_{k}": v for k, v in one_step.items()},
        **{f"x_period_ahead_{k}": v for k, v in traces.items()},
        **{f"x_fixed_{k}": v for k, v in fixed.items()},
    }
    np.savez_compressed(out / "predictions.npz", **arrays)

    if figures:
        step("figures")
        _figures(out, t, u, x, traces, fixed, segments, dt)
    _print_tables(
        say,
        freqs,
        results,
        labels,
        {m.label: m.description for m in methods},
        adapt,
    )
    if len(replays) > 1:
        for line in format_refine_modes(replays, freqs):
            say(line)
    for key, shares in paper_steps.items():
        say("")
        say(f"{key} (window {window} samples):")
        for line in format_step_shares(shares, freqs):
            say(line)
    say(f"online = online_{default}; steady state = {STEADY_STATE}")
    step(f"wrote {out / 'results.json'}, {out / 'predictions.npz'} and the figures")
    return results


def format_refine_modes(replays: Mapping[str, Mapping[str, Any]], freqs: Sequence[str]) -> list[str]:
    """Table 1 of the library default in each mode of its window pass, side by side with
    the synchronous one: max error [µm] per frequency and its ratio to sync, with how
    the record was fed (paced or not, refine schedule, late samples)."""
    sync = replays["sync"]["table1"]
    heads = [f"{f} Hz" for f in freqs]
    lines = [
        "",
        "Table 1 by window-pass mode (library default): period-ahead max error [µm]; ratio to sync",
        f"{'mode':<13}" + "".join(f"{h:>9}" for h in heads) + "".join(f"{'/' + h:>10}" for h in heads) + "  fed",
    ]
    for mode, r in replays.items():
        t1 = r["table1"]
        if r["paced"]:
            policy = ", SCHED_FIFO" if r["real_time"] else ""
            fed = f"paced 1/dt{policy}, {r['late_samples']} late (max {1e3 * r['max_late_s']:.2f} ms)"
        elif r["refine_intervals_per_push"]:
            fed = f"refine({r['refine_intervals_per_push']}) after every push"
        else:
            fed = "push_many"
        lines.append(
            f"{mode:<13}"
            + "".join(f"{t1[f]:>9.3f}" for f in freqs)
            + "".join(f"{t1[f] / sync[f]:>10.3f}" for f in freqs)
            + f"  {fed}; {r['updates']} updates, behind {r['behind_samples_at_end']} samples at the end"
        )
    return lines


def _figures(
    out: Path,
    t: np.ndarray,
    u: np.ndarray,
    x: np.ndarray,
    predictions: Mapping[str, np.ndarray],
    fixed: Mapping[str, np.ndarray],
    segments: Sequence[tuple[float, int, int]],
    dt: float,
) -> None:
    from ..plots import plot_loops, plot_switch

    names = ["fig6_1_to_10hz.png", "fig7_10_to_100hz.png", "fig8_100_to_200hz.png"]
    for k in range(1, len(segments)):
        f_old, lo_old, _ = segments[k - 1]
        f_new, lo, hi = segments[k]
        t_sw = t[lo]
        before = min(2.0 / f_old, t_sw - t[lo_old])
        after = min(6.0 / f_new, t[hi - 1] - t_sw)
        name = names[k - 1] if k - 1 < len(names) else f"fig_switch_{k}.png"
        plot_switch(
            out / name,
            t,
            x,
            predictions,
            t_sw,
            (t_sw - before, t_sw + after),
            f"frequency switch {f_old:g} Hz → {f_new:g} Hz at t = {t_sw:g} s",
        )
    windows = [(f"{f:g} Hz, steady state", steady_state_slice(f, lo, hi, dt)) for f, lo, hi in segments]
    loops = {"traditional": predictions["traditional"]}
    loops.update({f"{k} (Table 2 values, fixed)": v for k, v in fixed.items()})
    plot_loops(out / "fig9_loops.png", u, x, loops, windows)
