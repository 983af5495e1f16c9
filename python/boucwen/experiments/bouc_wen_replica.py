"""A replica of the Bouc–Wen benchmark (Noël & Schoukens, 2016) built from its published
definition, with its noise-free test record, so that a fit can be checked against the
true parameters and the prediction against the noise-free truth.

The definition (the benchmark's example script and description):

* the force: a random-phase multisine of :data:`RMS_N` N RMS with lines from
  :data:`BAND_HZ` (5 to 150 Hz), generated at :data:`UPSAMPLE` × the record's
  :data:`RATE_HZ` (15 kHz), :data:`PERIOD` samples per period at the record's rate: at
  15 kHz its lines are those of the 163 840-sample period from ⌊5/f_res⌋ to ⌈150/f_res⌉,
  each of unit amplitude and a uniformly random phase, the sum scaled to 50 N RMS; the
  record's force is every 20th sample;
* the system: :meth:`boucwen.oscillator.OscillatorParams.benchmark` (m = 2 kg,
  c = 10 N·s/m, k = 5e4 N/m, α = 5e4 N/m, β = 1e3 1/m, γ = 0.8, δ = −1.1, ν = 1),
  integrated from rest at 15 kHz by Newmark's scheme (a = 0.5, b = 0.25;
  :func:`boucwen._core.oscillator_newmark`, z by the trapezoidal rule: the benchmark's
  simulator is p-code, and does not say);
* the noise: Gaussian, band-limited to :data:`NOISE_BAND_HZ` (0–375 Hz), of
  :data:`NOISE_RMS_M` (8e-6 m) RMS, added at 15 kHz before decimation (the shared
  training record's noise falls near 375 Hz as the decimation's filter does, so it
  passed through it);
* the logger: decimation by 2, 2 and 5 through FIR filters of order :data:`FIR_ORDER`
  (30), MATLAB's ``decimate(y, r, "fir")`` (:func:`boucwen.measurement.decimate_fir`),
  one period more simulated and dropped after decimation for its edge;
* the training record: :data:`PERIODS` (5) periods; the test record: one steady
  period of another multisine of the same kind, noise-free (the benchmark's test
  multisine is such a period).

``python -m boucwen.experiments.bouc_wen_replica [--out DIR] [--seed S]`` builds the
replica, fits the oscillator on its training record with the benchmark's measurement
chain (the force band-limited and periodic, the decimation's filter on y) and with the
force linear between samples, prints the parameters beside the truth in standard
errors and the test record's prediction error, and checks the targets:
:data:`SE_LIMIT` standard errors for each parameter and :data:`TEST_RMS_LIMIT_M` for
the noise-free test multisine.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from .._core import oscillator_newmark
from ..checks import FloatArray
from ..measurement import decimate_fir
from ..metrics import rms
from ..oscillator import OscillatorFit, OscillatorParams, fit
from .bouc_wen_benchmark import DECIMATION, FIR_ORDER, benchmark_chain, exit_status, report_targets, write_results

__all__ = [
    "BAND_HZ",
    "NOISE_BAND_HZ",
    "NOISE_RMS_M",
    "PERIOD",
    "PERIODS",
    "RATE_HZ",
    "RMS_N",
    "SE_LIMIT",
    "TEST_RMS_LIMIT_M",
    "UPSAMPLE",
    "Replica",
    "deviations",
    "main",
    "multisine",
    "record",
    "replica",
    "run",
    "steady_prediction",
]

#: The record's sampling rate [Hz].
RATE_HZ = 750.0
#: The integration runs at this many times the record's rate.
UPSAMPLE = 20
#: Samples per period at the record's rate.
PERIOD = 8192
#: Periods of the training record.
PERIODS = 5
#: The multisine's band [Hz].
BAND_HZ = (5.0, 150.0)
#: The multisine's RMS [N].
RMS_N = 50.0
#: The noise's RMS [m], before the decimation's filter.
NOISE_RMS_M = 8e-6
#: The noise's band [Hz].
NOISE_BAND_HZ = 375.0
#: Target: every fitted parameter within this many standard errors of the truth (3: a
#: normal estimate is outside with probability 0.27 %).
SE_LIMIT = 3.0
#: Target: RMS error [m] of the fitted model on the noise-free test multisine.
TEST_RMS_LIMIT_M = 2e-7
#: Seeds of the training multisine, its noise and the test multisine (any would do).
SEEDS = (2016, 7, 1)


@dataclass(frozen=True, eq=False)
class Replica:
    """The replica's records.

    Attributes:
        force, y: the training record: force [N] and measured displacement [m].
        y_clean: the training record's displacement without its noise [m].
        test_force, test_y: the test record: one steady period of force [N] and its
            noise-free displacement [m].
        dt: sampling interval [s].
        noise_rms_m: the RMS of the noise in ``y`` [m] (after the decimation's filter).
    """

    force: FloatArray
    y: FloatArray
    y_clean: FloatArray
    test_force: FloatArray
    test_y: FloatArray
    dt: float
    noise_rms_m: float


def multisine(seed: int, period: int = PERIOD) -> FloatArray:
    """One period of the benchmark's multisine at 15 kHz [N] (module docs):
    ``period`` × :data:`UPSAMPLE` samples."""
    n = period * UPSAMPLE
    resolution = RATE_HZ * UPSAMPLE / n
    lines = np.arange(1, math.ceil(BAND_HZ[1] / resolution) + 1)
    lines = lines[lines >= math.floor(BAND_HZ[0] / resolution)]
    spectrum = np.zeros(n, dtype=np.complex128)
    spectrum[lines] = np.exp(2j * np.pi * np.random.default_rng(seed).random(lines.size))
    u = 2.0 * np.real(np.fft.ifft(spectrum))
    out: FloatArray = RMS_N * u / np.std(u, ddof=1)
    return out


def _noise(n: int, seed: int) -> FloatArray:
    """Gaussian noise of :data:`NOISE_RMS_M` RMS band-limited to :data:`NOISE_BAND_HZ`, at
    15 kHz: white noise with the lines above the band removed, scaled to the RMS."""
    white = np.random.default_rng(seed).normal(size=n)
    spectrum = np.fft.rfft(white)
    f = np.fft.rfftfreq(n, 1.0 / (RATE_HZ * UPSAMPLE))
    spectrum[f > NOISE_BAND_HZ] = 0.0
    band = np.fft.irfft(spectrum, n)
    out: FloatArray = NOISE_RMS_M * band / rms(band)
    return out


def _decimated(y: FloatArray) -> FloatArray:
    for r in DECIMATION:
        y = decimate_fir(y, r, FIR_ORDER)
    return y


def record(
    seed: int, periods: int, noise_seed: int | None, params: OscillatorParams | None = None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``periods`` periods of the benchmark's simulation of the multisine of ``seed``:
    (force [N], y [m], y without noise [m]) at the record's rate (``noise_seed`` None: no
    noise, y is the noise-free one)."""
    p = OscillatorParams.benchmark() if params is None else params
    one = multisine(seed)
    fine = np.tile(one, periods + 1)
    y_fine = oscillator_newmark(p.to_list(), fine, 1.0 / (RATE_HZ * UPSAMPLE))
    keep = periods * PERIOD
    clean = _decimated(y_fine)[:keep]
    y = clean if noise_seed is None else _decimated(y_fine + _noise(fine.size, noise_seed))[:keep]
    return fine[::UPSAMPLE][:keep].copy(), y, clean


def replica(seeds: Sequence[int] = SEEDS) -> Replica:
    """The replica's training and test records (module docs), from the seeds of the
    training multisine, its noise and the test multisine."""
    train, noise, test = seeds
    force, y, clean = record(train, PERIODS, noise)
    test_force, _, test_clean = record(test, 2, None)
    return Replica(
        force=force,
        y=y,
        y_clean=clean,
        test_force=test_force[PERIOD:],
        test_y=test_clean[PERIOD:],
        dt=1.0 / RATE_HZ,
        noise_rms_m=rms(y - clean),
    )


def steady_prediction(result: OscillatorFit, force: FloatArray, dt: float) -> FloatArray:
    """The fitted model's steady-state response to the periodic ``force`` (one period):
    two periods simulated, the second kept (the mode's decay time 2m/c is 0.4 s, a
    period 10.9 s)."""
    twice = np.tile(force, 2)
    return result.simulate(twice, dt)[force.size :]


def run(seeds: Sequence[int] = SEEDS, out_dir: str | Path | None = None, out: TextIO | None = None) -> dict[str, Any]:
    """Builds the replica, fits it with and without the benchmark's measurement chain,
    prints and returns the figures (module docs)."""
    out = sys.stdout if out is None else out
    started = time.perf_counter()
    rep = replica(seeds)
    print(
        f"replica: {rep.force.size} samples at {RATE_HZ:g} Hz, noise {rep.noise_rms_m:.3e} m RMS after the "
        f"decimation ({NOISE_RMS_M:g} m before), built in {time.perf_counter() - started:.1f} s",
        file=out,
    )
    truth = OscillatorParams.benchmark()
    doc: dict[str, Any] = {"seeds": list(seeds), "noise_rms_m": rep.noise_rms_m, "fits": {}}
    for label, kwargs in (
        ("bandlimited, decimation filter", {"input": "bandlimited", "periodic": True, "output": benchmark_chain()}),
        ("linear", {"input": "linear"}),
    ):
        result = fit(rep.force, rep.y, rep.dt, **kwargs)
        predicted = steady_prediction(result, rep.test_force, rep.dt)
        test_rms = rms(predicted - rep.test_y)
        off = deviations(result, truth)
        worst = max(abs(v) for v in off.values())
        fitted = f"fit RMS {result.rms:.4e} m in {result.seconds:.2f} s"
        print(f"\n{label}: {fitted}; test multisine {test_rms:.3e} m", file=out)
        for name, d in off.items():
            print(f"  {name:<12} {_value(result, name):>12.6g} ± {_se(result, name):.3g}  ({d:+.2f} SE)", file=out)
        doc["fits"][label] = {
            "fit": result.to_dict(),
            "deviation_in_se": off,
            "worst_deviation_in_se": worst,
            "test_rms_m": test_rms,
        }
    main_fit = doc["fits"]["bandlimited, decimation filter"]
    doc["targets"] = {
        "parameters_within_se": {
            "value": main_fit["worst_deviation_in_se"],
            "limit": SE_LIMIT,
            "holds": main_fit["worst_deviation_in_se"] <= SE_LIMIT,
        },
        "test_rms_m": {
            "value": main_fit["test_rms_m"],
            "limit": TEST_RMS_LIMIT_M,
            "holds": main_fit["test_rms_m"] <= TEST_RMS_LIMIT_M,
        },
    }
    report_targets(doc["targets"], out)
    if out_dir is not None:
        print(f"wrote {write_results(doc, out_dir)}", file=out)
    return doc


#: The fitted quantities compared with the truth: the parameters of the fit (β is held,
#: so γ and δ are compared as the products β·γ and β·δ the model holds).
_COMPARED = ("m", "c", "k", "alpha", "beta*gamma", "beta*delta")


def _value(result: OscillatorFit, name: str) -> float:
    p = result.params
    if name == "beta*gamma":
        return p.beta * p.gamma
    if name == "beta*delta":
        return p.beta * p.delta
    return float(getattr(p, name))


def _se(result: OscillatorFit, name: str) -> float:
    if name.startswith("beta*"):
        return result.params.beta * result.std_errors[name[5:]]
    return result.std_errors[name]


def deviations(result: OscillatorFit, truth: OscillatorParams) -> dict[str, float]:
    """(fitted − true) / standard error of each quantity of :data:`_COMPARED`."""
    true = {
        "m": truth.m,
        "c": truth.c,
        "k": truth.k,
        "alpha": truth.alpha,
        "beta*gamma": truth.beta * truth.gamma,
        "beta*delta": truth.beta * truth.delta,
    }
    return {name: (_value(result, name) - true[name]) / _se(result, name) for name in _COMPARED}


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.bouc_wen_replica",
        description="A replica of the Bouc-Wen benchmark from its published definition: the fit's parameters "
        "against the truth and its prediction of the noise-free test multisine.",
    )
    ap.add_argument("--out", default="out/bouc_wen_replica", metavar="DIR", help="output directory")
    ap.add_argument("--seed", type=int, nargs=3, default=list(SEEDS), metavar=("TRAIN", "NOISE", "TEST"))
    args = ap.parse_args(argv)
    doc = run(tuple(args.seed), args.out)
    return exit_status(ap.prog, doc["targets"])


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
