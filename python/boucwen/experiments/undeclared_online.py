"""Online identification on the records with undeclared effects.

``python -m boucwen.experiments.undeclared --online [--seeds N]`` takes the records of
:mod:`boucwen.experiments.undeclared_records` (one effect of the vocabulary each, or none),
and compares three models of each against the *noise-free* signal:

- **offline base**: :func:`boucwen.fit` of the base model on the whole record;
- **offline extended**: :func:`boucwen.diagnose`'s final fit, the base model with
  the effects it named, on the whole record;
- **online rpem**: ``Identifier.rpem`` with its default tuning, started
  from the offline base fit (parameters and h0) and pushed through the record one
  sample at a time; its error is that of the prediction ``push`` returns, made
  with the estimates from before each sample (one step ahead, h simulated, never
  taken from the measurement). It is told nothing about the effect: its offset x0,
  a random walk, absorbs what the base model does not describe.

RMS errors [µm] are given over the record after a start-up of :data:`START_UP_S`
and over its last 30 % (the part the diagnosis held out while it searched).
"""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

import numpy as np

from .._core import Identifier
from ..diagnosis import diagnose
from ..fit import fit
from ..metrics import rms
from .undeclared_records import cases, make_record

__all__ = ["HELD_OUT_FRACTION", "START_UP_S", "online_rows", "run_online_table"]

#: Samples of the first START_UP_S [s] are left out of every RMS (the online
#: identifier's h and covariance settle; the same span for all three models).
START_UP_S = 0.5
#: Share of the record at its end reported separately.
HELD_OUT_FRACTION = 0.3


def online_rows(seeds: int = 1) -> list[dict[str, Any]]:
    """One dict per record of :func:`boucwen.experiments.undeclared_records.cases`: the
    effect, the effects the diagnosis named, and the RMS errors [µm] of the three
    models after the start-up (``*_rms_um``) and over the last 30 % (``*_tail_um``)."""
    rows: list[dict[str, Any]] = []
    for effect, seed, pset, noise in cases(seeds):
        rec = make_record(effect, seed, pset, noise)
        t0 = time.perf_counter()
        base = fit(rec.u, rec.x, rec.dt, seed=seed)
        d = diagnose(rec.u, rec.x, rec.dt, seed=seed)
        t1 = time.perf_counter()
        ident = Identifier.rpem(rec.dt, base.params, h0=base.h0)
        x_online = ident.push_many(rec.u, rec.x)
        t2 = time.perf_counter()
        n = rec.u.size
        start = round(START_UP_S / rec.dt)
        tail = round((1.0 - HELD_OUT_FRACTION) * n)
        row: dict[str, Any] = {
            "effect": effect,
            "param_set": pset,
            "noise_um": noise,
            "seed": seed,
            "named": ",".join(d.effects) or "none",
            "offline_s": t1 - t0,
            "online_s": t2 - t1,
        }
        for key, xm in (("base", base.x_fit), ("extended", d.x_extended), ("rpem", x_online)):
            err = np.asarray(xm) - rec.x_true
            row[f"{key}_rms_um"] = rms(err[start:])
            row[f"{key}_tail_um"] = rms(err[tail:])
        rows.append(row)
    return rows


def run_online_table(seeds: int = 1, out: TextIO = sys.stdout) -> list[dict[str, Any]]:
    """Runs :func:`online_rows` and prints a markdown table; returns the rows."""
    rows = online_rows(seeds)
    print(
        f"RMS error against the noise-free signal [µm], after the first {START_UP_S:g} s "
        f"| over the last {HELD_OUT_FRACTION:.0%} of the record",
        file=out,
    )
    print("", file=out)
    print("| effect | set | noise | seed | named | offline base | offline extended | online rpem |", file=out)
    print("|---|---|---|---|---|---|---|---|", file=out)
    for r in rows:
        cells = [f"{r[f'{k}_rms_um']:.4f} \\| {r[f'{k}_tail_um']:.4f}" for k in ("base", "extended", "rpem")]
        print(
            f"| {r['effect']} | {r['param_set']} | {r['noise_um'] * 1e3:g} nm | {r['seed']} | {r['named']} | "
            + " | ".join(cells)
            + " |",
            file=out,
            flush=True,
        )
    better = sum(r["rpem_rms_um"] < r["extended_rms_um"] for r in rows)
    print("", file=out)
    print(
        f"online rpem below the offline extended fit on {better}/{len(rows)} records "
        f"(after the start-up); online time per record "
        f"{np.mean([r['online_s'] for r in rows]):.2f} s",
        file=out,
    )
    return rows
