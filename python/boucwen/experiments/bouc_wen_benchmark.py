"""The Bouc–Wen benchmark (Noël & Schoukens, 2016): the hysteretic oscillator fitted to the
training record with the benchmark's measurement chain, its last period held out.

``python -m boucwen.experiments.bouc_wen_benchmark [--out DIR] [--data PATH] [--input I]
[--output O]``:

1. reads the training record (:func:`boucwen.datasets.load_bouc_wen`; ``--data`` names another
   file of the same columns) and fits :func:`boucwen.oscillator.fit` on all its periods
   but the last (the first four of five) with the measurement chain (``--input``, default
   ``bandlimited``: the force generated at 20× the rate is, between the record's samples,
   the band-limited signal, exactly the Fourier interpolation of the periodic record;
   ``--output``, default ``decimation``: the benchmark's FIR decimation 2, 2, 5 of order
   30, :func:`benchmark_chain`), printing the fit RMS
   [m], the parameters with their standard errors and the time; the same fit with the
   force linear between samples and no filter on y beside it, as the baseline;
2. simulates the fitted model over the whole record from its fitted initial state and
   scores the last period only: the held-out RMS [m];
3. estimates the record's noise from its steady periods (all but the first, whose start
   carries the transient): per DFT line, the spread of the periods about their mean
   (Pintelon & Schoukens), whose sum over the lines is the noise's variance per sample;
4. the noise-aware figure (:func:`noise_aware`): the held-out residual's power minus the
   noise's expected power, on the lines the multisine excites and on those it does not,
   with the standard error of the difference — the model's own error on the held-out
   period with the noise taken out, and an upper bound for it;
5. checks the targets: the fit within :data:`FIT_SECONDS` s, the held-out RMS at most
   :data:`NOISE_FACTOR` × the noise; prints the published figures beside (the
   benchmark's *test* multisine, another record) and writes ``DIR/results.json`` and
   ``DIR/held_out.png`` (measured, predicted and error over the held-out period).

Exit status 0 when both targets hold, 1 when one fails (one line on stderr naming it),
2 when the data file is absent (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ..checks import FloatArray
from ..datasets import BOUC_WEN_PERIOD as PERIOD
from ..datasets import BenchmarkRecord, DataNotFoundError, load_bouc_wen
from ..io import jsonable
from ..measurement import INPUT_CHOICES, OutputFilter, decimation_filter
from ..metrics import rms
from ..oscillator import OscillatorFit, fit
from ..plots import _figure

__all__ = [
    "DECIMATION",
    "DEFAULT_OUT",
    "FIR_ORDER",
    "FIT_SECONDS",
    "NOISE_FACTOR",
    "PUBLISHED",
    "NoiseAware",
    "benchmark_chain",
    "exit_status",
    "main",
    "noise_aware",
    "noise_lines",
    "noise_rms",
    "plot_held_out",
    "report_targets",
    "run",
    "write_results",
]

DEFAULT_OUT = "out/bouc_wen_benchmark"
#: Target: the fit's wall time [s] on the project's 2-core machine.
FIT_SECONDS = 5.0
#: Target: held-out RMS at most this many times the record's noise.
NOISE_FACTOR = 2.0
#: The benchmark's decimation from its integration rate (15 kHz) to the record's: the
#: factors in order, each through a FIR of order :data:`FIR_ORDER` (MATLAB's
#: ``decimate(y, r, "fir")``).
DECIMATION = (2, 2, 5)
#: The decimation filters' order.
FIR_ORDER = 30
#: Published RMS errors [m] on the benchmark's test multisine (not this record).
PUBLISHED: tuple[tuple[str, float, str], ...] = (
    ("PNLSS", 1.87e-5, "Esfahani et al., 2017"),
    ("dynoNet", 4.52e-5, "Forgione & Piga, 2021"),
    ("best NFIR", 16.3e-5, "Belz et al., 2017"),
)


def benchmark_chain() -> OutputFilter:
    """The benchmark's logger at the record's rate: its decimation's equivalent
    (:func:`boucwen.measurement.decimation_filter` of :data:`DECIMATION`, :data:`FIR_ORDER`)."""
    return decimation_filter(DECIMATION, FIR_ORDER)


def report_targets(targets: dict[str, Any], out: TextIO) -> None:
    """One line per target ``{name: {"value", "limit", "holds"}}``."""
    for name, target in targets.items():
        verdict = "holds" if target["holds"] else "FAILS"
        print(f"target {name}: {target['value']:.3g} <= {target['limit']:g}: {verdict}", file=out)


def write_results(doc: dict[str, Any], out_dir: str | Path) -> Path:
    """``doc`` as ``out_dir/results.json`` (the folder made where missing); returns the file."""
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "results.json"
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(jsonable(doc), fh, indent=2, allow_nan=False)
    return path


def exit_status(prog: str, targets: dict[str, Any]) -> int:
    """0 when every target holds; else 1, one line on stderr naming the failed ones."""
    failed = [name for name, t in targets.items() if not t["holds"]]
    if failed:
        print(f"{prog}: target failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def noise_lines(y: FloatArray, period: int) -> FloatArray:
    """The noise's variance per DFT line of one period [m²], from the record's steady periods
    (all but the first, whose start carries the transient): for each line of the real
    DFT, Σₚ|Yₚ − Ȳ|²/(P − 1) over the P steady periods (Pintelon & Schoukens), weighted so
    that the lines sum to the noise's variance per sample (lines 1 … period/2 − 1 stand
    for their negative frequencies too). Empty with fewer than three periods."""
    periods = y.size // period
    if periods < 3:
        return np.zeros(0)
    steady = y[period : periods * period].reshape(periods - 1, period)
    spectra = np.fft.rfft(steady, axis=1)
    spread = np.sum(np.abs(spectra - spectra.mean(axis=0)) ** 2, axis=0) / (periods - 2)
    out: FloatArray = spread * _line_weights(period) / period**2
    return out


def _line_weights(period: int) -> FloatArray:
    """2 for the lines of the real DFT that stand for a pair of frequencies, 1 for the
    mean (and the Nyquist line of an even period)."""
    w = np.full(period // 2 + 1, 2.0)
    w[0] = 1.0
    if period % 2 == 0:
        w[-1] = 1.0
    return w


def noise_rms(y: FloatArray, period: int) -> float:
    """The record's noise [m]: the square root of :func:`noise_lines`' sum (NaN with fewer
    than three periods)."""
    lines = noise_lines(y, period)
    return math.sqrt(float(np.sum(lines))) if lines.size else math.nan


@dataclass(frozen=True)
class NoiseAware:
    """The held-out residual with the noise taken out (:func:`noise_aware`); mean squares
    per sample [m²] split between the lines the input excites and the others.

    Attributes:
        residual_excited, residual_other: the residual's power on each set of lines.
        noise_excited, noise_other: the noise's expected power there (:func:`noise_lines`).
        model_ms: residual − noise over all lines: the model's own error, squared.
        model_ms_se: its standard error (the sampling spread of both powers: the residual's
            noise power has variance Σ v², v the per-line noise variances, and the noise
            estimate Σ v²/(P − 1)).
    """

    residual_excited: float
    residual_other: float
    noise_excited: float
    noise_other: float
    model_ms: float
    model_ms_se: float

    @property
    def model_rms(self) -> float:
        """The model's own RMS error [m] (0 where the residual is within the noise)."""
        return math.sqrt(max(self.model_ms, 0.0))

    @property
    def upper_rms(self) -> float:
        """An upper bound [m] for :attr:`model_rms` at 97.5 % (model_ms + 1.96 standard errors)."""
        return math.sqrt(max(self.model_ms + 1.96 * self.model_ms_se, 0.0))

    def to_dict(self) -> dict[str, float]:
        """JSON-ready, with the RMS figures."""
        return {
            "residual_excited_ms": self.residual_excited,
            "residual_other_ms": self.residual_other,
            "noise_excited_ms": self.noise_excited,
            "noise_other_ms": self.noise_other,
            "model_ms": self.model_ms,
            "model_ms_se": self.model_ms_se,
            "model_rms_m": self.model_rms,
            "model_rms_upper_m": self.upper_rms,
        }


def noise_aware(residual: FloatArray, force: FloatArray, noise: FloatArray, steady_periods: int) -> NoiseAware:
    """The noise-aware figure of a one-period ``residual`` (measured − predicted [m]) of a
    periodic record: its power per DFT line minus the noise's variance there (``noise``,
    :func:`noise_lines`, from ``steady_periods`` periods), summed over the lines ``force``
    (one period) excites and over the others."""
    period = residual.size
    weights = _line_weights(period)
    power = np.abs(np.fft.rfft(residual)) ** 2 * weights / period**2
    amplitude = np.abs(np.fft.rfft(force))
    excited = amplitude > 1e-6 * float(np.max(amplitude))
    model_ms = float(np.sum(power) - np.sum(noise))
    # Each line's power is exponential (a complex Gaussian's): its variance is its
    # mean squared, per line of the pair a real line stands for.
    per_line = noise**2 / np.maximum(weights, 1.0)
    variance = float(np.sum(per_line)) * (1.0 + 1.0 / max(steady_periods - 1, 1))
    return NoiseAware(
        residual_excited=float(np.sum(power[excited])),
        residual_other=float(np.sum(power[~excited])),
        noise_excited=float(np.sum(noise[excited])),
        noise_other=float(np.sum(noise[~excited])),
        model_ms=model_ms,
        model_ms_se=math.sqrt(variance),
    )


def plot_held_out(path: Path, t: FloatArray, measured: FloatArray, predicted: FloatArray, title: str) -> None:
    """Measured and predicted displacement [m] over the held-out period, and their
    difference, to PNG ``path``."""
    fig = _figure(10.0, 5.5)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    top.plot(t, measured, color="black", linewidth=0.8, label="measured")
    top.plot(t, predicted, color="tab:red", linewidth=0.6, label="predicted (simulated from F)")
    top.set_ylabel("y [m]")
    top.legend(loc="upper right")
    top.set_title(title)
    bottom.plot(t, measured - predicted, color="tab:blue", linewidth=0.6)
    bottom.set_ylabel("error [m]")
    bottom.set_xlabel("t [s]")
    fig.savefig(path, dpi=120)


def _report_fit(label: str, result: OscillatorFit, held_rms: float, noise: float, out: TextIO) -> None:
    p, se = result.params, result.std_errors
    fitted = f"RMS {result.rms:.4e} m in {result.seconds:.2f} s ({result.nfev} simulations, {result.message})"
    print(f"\n{label}: fit {fitted}", file=out)
    print(
        f"  m = {p.m:.6g} ± {se['m']:.2g} kg, c = {p.c:.5g} ± {se['c']:.2g} N·s/m, "
        f"k = {p.k:.6g} ± {se['k']:.2g} N/m, alpha = {p.alpha:.6g} ± {se['alpha']:.2g} N/m,\n"
        f"  beta = {p.beta:.5g} 1/m (kept), gamma = {p.gamma:.5g} ± {se['gamma']:.2g}, "
        f"delta = {p.delta:.5g} ± {se['delta']:.2g}, nu = {p.nu:.5g};\n"
        f"  beta·gamma = {p.beta * p.gamma:.5g} ± {p.beta * se['gamma']:.2g} 1/m, "
        f"beta·delta = {p.beta * p.delta:.5g} ± {p.beta * se['delta']:.2g} 1/m;"
        f" y0 = {result.y0:.3e} m, v0 = {result.v0:.3e} m/s, z0 = {result.z0:.3e} N",
        file=out,
    )
    ratio = held_rms / noise if noise > 0.0 else math.inf
    print(f"  held-out period: RMS {held_rms:.4e} m = {ratio:.3f} × the noise ({noise:.4e} m)", file=out)


def run(
    record: BenchmarkRecord,
    out_dir: str | Path | None = DEFAULT_OUT,
    *,
    period: int = PERIOD,
    input: str = "bandlimited",
    output: OutputFilter | None = None,
    decimation: bool = True,
    baseline: bool = True,
    progress: bool = True,
    out: TextIO | None = None,
) -> dict[str, Any]:
    """Fits on all periods but the last, predicts the last, checks the targets (module
    docs); prints the figures to ``out`` (default stdout) and returns them (``targets``
    holds each target's value, limit and whether it holds).

    ``input`` and ``output`` are the measurement chain (``output`` None with
    ``decimation``: the benchmark's, :func:`benchmark_chain`;
    None without it: no filter on y); ``baseline`` adds the fit with the force linear
    between samples and no filter."""
    out = sys.stdout if out is None else out
    n = record.y.size
    periods = n // period
    if periods < 2:
        raise ValueError(f"{record.path}: {n} samples are fewer than two periods of {period}")
    held = slice((periods - 1) * period, periods * period)
    fit_len = held.start
    if output is None and decimation:
        output = benchmark_chain()
    chain = f"input {input} (periodic), output {output.name if output is not None else 'unfiltered'}"
    print(f"record: {record.path} ({n} samples, dt = {record.dt:.9g} s, {periods} periods of {period})", file=out)
    print(f"fit on samples 0 … {fit_len - 1} (periods 1–{periods - 1}); held out: period {periods}", file=out)
    print(f"measurement chain: {chain}", file=out)
    lines = noise_lines(record.y, period)
    noise = math.sqrt(float(np.sum(lines))) if lines.size else math.nan
    fits: dict[str, dict[str, Any]] = {}
    chains: list[tuple[str, dict[str, Any]]] = [("chain", {"input": input, "periodic": True, "output": output})]
    if baseline:
        chains.append(("baseline", {"input": "linear"}))
    predicted: dict[str, FloatArray] = {}
    for name, kwargs in chains:
        result = fit(record.force[:fit_len], record.y[:fit_len], record.dt, progress=progress, **kwargs)
        predicted[name] = result.simulate(record.force, record.dt)
        held_rms = rms(record.y[held] - predicted[name][held])
        label = chain if name == "chain" else "baseline: input linear, output unfiltered"
        _report_fit(label, result, held_rms, noise, out)
        entry: dict[str, Any] = {"fit": result.to_dict(), "held_out_rms_m": held_rms}
        if lines.size:
            aware = noise_aware(record.y[held] - predicted[name][held], record.force[held], lines, periods - 1)
            entry["noise_aware"] = aware.to_dict()
            print(
                f"  noise-aware: the residual's power on the excited lines {aware.residual_excited:.3e} m² "
                f"(noise {aware.noise_excited:.3e}), on the others {aware.residual_other:.3e} m² "
                f"(noise {aware.noise_other:.3e});\n"
                f"  the model's own error, the noise taken out: {aware.model_rms:.2e} m RMS "
                f"(≤ {aware.upper_rms:.2e} m at 97.5 %)",
                file=out,
            )
        entry["seconds"] = result.seconds
        fits[name] = entry
    main_fit = fits["chain"]
    ratio = main_fit["held_out_rms_m"] / noise if noise > 0.0 else math.inf
    print("\npublished, on the benchmark's test multisine (another record, noise-free):", file=out)
    for name, value, source in PUBLISHED:
        print(f"  {name:<10} {value:.2e} m  ({source})", file=out)
    targets = {
        "fit_seconds": {
            "value": main_fit["seconds"],
            "limit": FIT_SECONDS,
            "holds": main_fit["seconds"] <= FIT_SECONDS,
        },
        "held_out_over_noise": {"value": ratio, "limit": NOISE_FACTOR, "holds": ratio <= NOISE_FACTOR},
    }
    report_targets(targets, out)
    doc: dict[str, Any] = {
        "record": str(record.path),
        "samples": n,
        "dt_s": record.dt,
        "period": period,
        "chain": {"input": input, "periodic": True, "output": None if output is None else output.to_dict()},
        "fit": main_fit["fit"],
        "held_out_rms_m": main_fit["held_out_rms_m"],
        "noise_rms_m": noise,
        "held_out_over_noise": ratio,
        "fits": fits,
        "published_test_multisine_rms_m": {name: value for name, value, _ in PUBLISHED},
        "targets": targets,
    }
    if out_dir is not None:
        results = write_results(doc, out_dir)
        title = f"held-out period: RMS {main_fit['held_out_rms_m']:.3e} m ({ratio:.2f} × noise)"
        plot_held_out(results.parent / "held_out.png", record.t[held], record.y[held], predicted["chain"][held], title)
        print(f"wrote {results} and {results.parent / 'held_out.png'}", file=out)
    return doc


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.bouc_wen_benchmark",
        description="The hysteretic oscillator fitted to the Bouc-Wen benchmark's training record with the "
        "benchmark's measurement chain, its last period held out.",
    )
    ap.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help=f"output directory (default {DEFAULT_OUT})")
    ap.add_argument("--data", metavar="PATH", help="the record (default: train_multisine.csv in the data directory)")
    ap.add_argument("--period", type=int, default=PERIOD, help=f"samples per period (default {PERIOD})")
    ap.add_argument(
        "--input",
        choices=INPUT_CHOICES,
        default="bandlimited",
        help="what the force does between samples (default bandlimited: the record is periodic)",
    )
    ap.add_argument(
        "--output",
        choices=("decimation", "none"),
        default="decimation",
        help="the logger's filter on y (default decimation: FIR 2, 2, 5 of order 30, the benchmark's)",
    )
    ap.add_argument("--no-baseline", action="store_true", help="skip the fit with the force linear and no filter")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = ap.parse_args(argv)
    try:
        record = load_bouc_wen(args.data)
    except (DataNotFoundError, FileNotFoundError) as exc:
        print(f"{ap.prog}: {exc}", file=sys.stderr)
        return 2
    doc = run(
        record,
        args.out,
        period=args.period,
        input=args.input,
        decimation=args.output == "decimation",
        baseline=not args.no_baseline,
        progress=not args.quiet,
    )
    return exit_status(ap.prog, doc["targets"])


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
