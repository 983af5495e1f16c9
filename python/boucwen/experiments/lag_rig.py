"""A generated rig of a positioner on a real-time controller: a model diagnosed on a
PRBS record, carried to the rig's other records.

The rig is the simulated bench (:mod:`boucwen.plant`: the paper's stack with creep,
electrostriction, floor vibration, 1 nm of sensor noise, 16-bit voltage reading) behind
a fast amplifier lag, τ = :data:`LAG_TAU_S` (1 ms): the lag that a diagnosis can take for
a creep element of millisecond time constant. Its records, 2 s each at 10 kHz
(:func:`rig_records`):

* ``prbs``: a two-level pseudo-random binary sequence clocked at the sampling rate
  between 40 and 60 V (the identification record: it keeps h to a small loop);
* ``sine 50 Hz``, ``sine 100 Hz``: 30–70 V;
* ``triangle``: 10 Hz, 20–80 V;
* ``large sine``: 10 Hz, 0–100 V (the whole range).

:func:`run` diagnoses the PRBS record (:func:`boucwen.diagnose`, not told what it holds),
carries the base model and the returned model to every other record as the measured
benchmark does (:func:`boucwen.experiments.measured.predictions`: the device carried,
offset, trend and h0 re-estimated there), and checks that the returned model is never
worse there than :data:`CARRIED_LIMIT` (1.05) times the base model's RMS error, and that
it passes the boundedness check (:mod:`boucwen.boundedness`). A model that ran away on
the sines (β + γ < 0 fitted on the PRBS record's small loop) would fail both.

``python -m boucwen.experiments.lag_rig [--json FILE]`` prints one line per record and
whether the check holds (exit status 1 where it does not).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, TextIO

import numpy as np

from .. import plant
from ..checks import FloatArray
from ..diagnosis import diagnose
from ..metrics import rms
from ..record import Record
from .measured import Case, predictions

__all__ = ["CARRIED_LIMIT", "DT", "DURATION_S", "LAG_TAU_S", "main", "rig_records", "run"]

#: Sampling interval [s] (10 kHz).
DT = 1e-4
#: Length of each record [s].
DURATION_S = 2.0
#: The amplifier's time constant [s] (corner 1/(2π·τ) = 159 Hz).
LAG_TAU_S = 1e-3
#: The returned model carried to another record of the rig may have at most this times
#: the base model's RMS error there.
CARRIED_LIMIT = 1.05
#: Seed of the PRBS and of the sensor noise.
SEED = 0


def _sine(f_hz: float, lo: float, hi: float, t: FloatArray) -> FloatArray:
    out: FloatArray = lo + 0.5 * (hi - lo) * (1.0 - np.cos(2.0 * math.pi * f_hz * t))
    return out


def _triangle(f_hz: float, lo: float, hi: float, t: FloatArray) -> FloatArray:
    phase = np.mod(t * f_hz, 1.0)
    out: FloatArray = lo + (hi - lo) * (1.0 - np.abs(2.0 * phase - 1.0))
    return out


def rig_records(seed: int = SEED) -> dict[str, Record]:
    """The rig's records (module docs), measured on the bench with the fast lag."""
    settings = replace(plant.BenchSettings(), amplifier_fc_hz=1.0 / (2.0 * math.pi * LAG_TAU_S))
    n = round(DURATION_S / DT)
    t: FloatArray = np.arange(n, dtype=np.float64) * DT
    rng = np.random.default_rng(seed)
    inputs = {
        "prbs": np.where(rng.random(n) < 0.5, 40.0, 60.0),
        "sine 50 Hz": _sine(50.0, 30.0, 70.0, t),
        "sine 100 Hz": _sine(100.0, 30.0, 70.0, t),
        "triangle": _triangle(10.0, 20.0, 80.0, t),
        "large sine": _sine(10.0, 0.0, 100.0, t),
    }
    out = {}
    for k, (name, u) in enumerate(inputs.items()):
        rec = plant.measure(u, DT, settings, seed=seed + k)
        out[name] = replace(rec, name=name)
    return out


def run(seed: int = SEED, out: TextIO = sys.stdout, workers: int | None = None) -> dict[str, Any]:
    """Diagnoses the rig's PRBS record and carries both models to the others (module
    docs); prints one line per record and returns a JSON-able dict."""
    records = rig_records(seed)
    fitted = records.pop("prbs")
    result = diagnose(fitted.u, fitted.x, fitted.dt, seed=seed, workers=workers)
    print(f"prbs: {result.summary()}", file=out)
    if result.boundedness is not None:
        print(f"returned model: {result.boundedness.summary()}", file=out)
    rows: list[dict[str, Any]] = []
    ratios: list[float] = []
    for name, rec in records.items():
        pred = predictions(result, Case(f"prbs → {name}", fitted, rec, continued=False))
        base, returned = rms(rec.x - pred["x_base"]), rms(rec.x - pred["x_returned"])
        ratio = returned / base if base > 0 else math.inf
        rows.append({"record": name, "base_rms_um": base, "returned_rms_um": returned, "ratio": ratio})
        ratios.append(ratio)
        print(f"{name:<12} base {base:.4f} µm, returned {returned:.4f} µm ({ratio:.3f}×)", file=out)
    worst = max(ratios)
    bounded = result.boundedness is not None and result.boundedness.passed
    holds = worst <= CARRIED_LIMIT and bounded
    print(
        f"carried: worst {worst:.3f}× the base model (check ≤ {CARRIED_LIMIT:g}×), "
        f"{'bounded' if bounded else 'NOT bounded'}: {'holds' if holds else 'FAILS'}",
        file=out,
    )
    return {
        "effects": list(result.effects),
        "params": result.to_dict()["params"],
        "boundedness": None if result.boundedness is None else result.boundedness.to_dict(),
        "records": rows,
        "worst_ratio": worst,
        "holds": holds,
        "seed": seed,
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m boucwen.experiments.lag_rig", description=__doc__.split("\n")[0])
    parser.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    parser.add_argument("--seed", type=int, default=SEED, help="seed of the PRBS and the noise")
    args = parser.parse_args(argv)
    doc = run(args.seed)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=2, allow_nan=False)
    return 0 if doc["holds"] else 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
