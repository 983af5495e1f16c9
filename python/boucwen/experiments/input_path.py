"""Which input path between samples do the measured records hold? Each record fitted with
each path, its in-record and forward held-out errors side by side.

``python -m boucwen.experiments.input_path [--out DIR] [--quick]``:

* every shared piezo record (:mod:`boucwen.datasets`: ``$BOUCWEN_DATA`` or
  ``../shared/data`` beside the repository): the base model fitted on the record's first
  :data:`FIT_SHARE` (60 %, :func:`boucwen.fit`, then refitted with the input path as its
  ``between_samples`` effect, :func:`boucwen.effects.fit_extended`, for ``"hold"`` and
  ``"bandlimited"``; ``"linear"`` is the fit without it), simulated over the whole record
  from its fitted h0 so the rest continues the state; RMS |x − x̂| [µm] on the fitted
  samples (*in-record*) and on the rest (*held out*, forward);
* the Bouc–Wen benchmark's training record (:func:`boucwen.datasets.load_bouc_wen`): the
  hysteretic oscillator fitted (:func:`boucwen.oscillator.fit`) on all periods but the
  last with each input path (the record periodic) and the benchmark's output filter
  (:func:`boucwen.experiments.bouc_wen_benchmark.benchmark_chain`), and with each path
  and no filter (linear and no filter: what ``boucwen diagnose`` fits); RMS [m] on the fitted
  periods and on the last one, beside the record's noise
  (:func:`boucwen.experiments.bouc_wen_benchmark.noise_lines`).

``--quick`` fits each piezo record's first 4000 samples only and skips the benchmark.
Prints one table per record and writes ``DIR/results.json``; a record that is not on the
machine is named and skipped (exit 0).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from .. import datasets
from .._core import EffectSet, simulate_extended
from ..effects import BetweenSamples, effect_set, fit_extended
from ..fit import fit
from ..measurement import INPUT_CHOICES
from ..metrics import rms
from ..oscillator import fit as fit_oscillator
from .bouc_wen_benchmark import benchmark_chain, noise_lines, write_results

__all__ = ["DEFAULT_OUT", "FIT_SHARE", "QUICK_SAMPLES", "benchmark_rows", "main", "piezo_rows", "print_table"]

DEFAULT_OUT = "out/input_path"
#: The share of a piezo record fitted; the rest is held out (as the measured-data
#: benchmark's forward split, :data:`boucwen.experiments.measured.FIT_SHARE`).
FIT_SHARE = 0.6
#: Samples of a piezo record ``--quick`` uses.
QUICK_SAMPLES = 4000


def piezo_rows(u: Any, x: Any, dt: float, *, seed: int = 0) -> list[dict[str, Any]]:
    """One row per input path of a piezo record ``u`` [V], ``x`` [µm]: the path, the
    in-record and held-out RMS [µm], the fit's wall time [s] and whether it converged."""
    u, x = np.asarray(u, dtype=np.float64), np.asarray(x, dtype=np.float64)
    cut = int(FIT_SHARE * u.size)
    started = time.perf_counter()
    base = fit(u[:cut], x[:cut], dt, seed=seed)
    base_s = time.perf_counter() - started
    rows = []
    for input in INPUT_CHOICES:
        began = time.perf_counter()
        if input == "linear":
            params, h0, effects, ok = base.params, base.h0, EffectSet(), base.success
        else:
            effects = effect_set(BetweenSamples(input=input))
            solved = fit_extended(u[:cut], x[:cut], dt, base.params, effects, base.h0)
            params, h0, ok = solved.params, solved.h0, solved.success
        seconds = base_s + time.perf_counter() - began
        x_hat = np.asarray(simulate_extended(params, effects, u, dt, h0))
        rows.append(
            {
                "input": input,
                "in_record": rms(x[:cut] - x_hat[:cut]),
                "held_out": rms(x[cut:] - x_hat[cut:]),
                "seconds": seconds,
                "converged": bool(ok),
            }
        )
    return rows


def benchmark_rows(record: datasets.BenchmarkRecord, *, period: int = datasets.BOUC_WEN_PERIOD) -> dict[str, Any]:
    """The oscillator on the benchmark's training record with each input path, with the
    benchmark's output filter and without: rows of the path,
    the filter, the RMS [m] on the fitted periods and on the held-out last one, the fit's
    wall time [s]; with the record's noise RMS [m]."""
    periods = record.y.size // period
    cut = (periods - 1) * period
    held = slice(cut, periods * period)
    chain = benchmark_chain()
    runs: list[tuple[str, Any]] = [(input, output) for output in (chain, None) for input in INPUT_CHOICES]
    rows = []
    for input, output in runs:
        result = fit_oscillator(
            record.force[:cut], record.y[:cut], record.dt, input=input, periodic=True, output=output
        )
        y_hat = result.simulate(record.force, record.dt)
        rows.append(
            {
                "input": input,
                "output": "decimation" if output is not None else "none",
                "in_record": rms(record.y[:cut] - y_hat[:cut]),
                "held_out": rms(record.y[held] - y_hat[held]),
                "seconds": result.seconds,
                "converged": bool(result.success),
            }
        )
    lines = noise_lines(record.y, period)
    return {"rows": rows, "noise_rms_m": math.sqrt(float(np.sum(lines))) if lines.size else math.nan}


def print_table(title: str, rows: list[dict[str, Any]], unit: str, out: TextIO) -> None:
    """The rows as one table: path (and filter), in-record and held-out RMS in ``unit``."""
    print(title, file=out)
    filtered = "output" in rows[0]
    head = f"  {'input':<12}" + (f"{'output':<12}" if filtered else "")
    print(head + f"{'in-record RMS [' + unit + ']':>22}{'held-out RMS [' + unit + ']':>22}{'fit [s]':>9}", file=out)
    for r in rows:
        line = f"  {r['input']:<12}" + (f"{r['output']:<12}" if filtered else "")
        flag = "" if r["converged"] else "  (not converged)"
        line += f"{r['in_record']:>22.4g}{r['held_out']:>22.4g}{r['seconds']:>9.1f}{flag}"
        print(line, file=out)


def main(argv: Sequence[str] | None = None, out: TextIO | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.input_path",
        description="Each shared record fitted with each input path between samples (hold, linear, "
        "band-limited): in-record and forward held-out RMS side by side.",
    )
    ap.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help=f"output directory (default {DEFAULT_OUT})")
    ap.add_argument("--quick", action="store_true", help=f"first {QUICK_SAMPLES} samples of each piezo record only")
    args = ap.parse_args(argv)
    out = sys.stdout if out is None else out
    doc: dict[str, Any] = {"fit_share": FIT_SHARE, "records": {}}
    for name in datasets.names():
        try:
            rec = datasets.load(name)
        except datasets.DataNotFoundError as exc:
            print(f"{name}: skipped ({exc})", file=out)
            continue
        u, x = (rec.u[:QUICK_SAMPLES], rec.x[:QUICK_SAMPLES]) if args.quick else (rec.u, rec.x)
        rows = piezo_rows(u, x, rec.dt)
        cut = int(FIT_SHARE * u.size)
        title = (
            f"{name} ({u.size} samples, dt = {rec.dt:g} s; fitted: the first {cut}, held out: the other {u.size - cut})"
        )
        print_table(title, rows, "µm", out)
        doc["records"][name] = {"samples": int(u.size), "dt_s": rec.dt, "rows": rows}
    if not args.quick:
        try:
            bench = datasets.load_bouc_wen()
        except (datasets.DataNotFoundError, FileNotFoundError) as exc:
            print(f"bouc-wen benchmark: skipped ({exc})", file=out)
        else:
            result = benchmark_rows(bench)
            title = (
                f"Bouc-Wen benchmark training record ({bench.y.size} samples, dt = {bench.dt:.6g} s; fitted: periods "
                f"1-4, held out: period 5; the record's noise {result['noise_rms_m']:.3e} m RMS)"
            )
            print_table(title, result["rows"], "m", out)
            doc["records"]["bouc_wen_train"] = result
    path = write_results(doc, Path(args.out))
    print(f"wrote {path}", file=out)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
