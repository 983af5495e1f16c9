"""The next experiment, verified on simulated plants: does the designed input settle the
look-alikes a first record leaves tied?

``python -m boucwen.experiments.experiment_design [--half H] [--seeds N] [--out DIR]``
(about 10 s a case on two cores; 48 cases by default)

For each effect of the look-alike families (:data:`LOOKALIKES`: creep, input lag and
electrostriction under one slow sine; drift, gain drift and creep; delay and input lag)
and each seed, a plant is made by the generated suite's makers
(:func:`~boucwen.experiments.suite_records.make_suite_record`: the base parameters, the
effect at a stated size, the noise) and:

1. a **first record** is simulated on a single slow sine (5 Hz, 20…80 V, 1.2 s at
   5 kHz, the plant on a grid 4× finer) and diagnosed;
   Each plant's effect size and noise level cycle with its seed (:data:`SIZES_UM`,
   :data:`NOISE_UM`);
2. where the true effect ends **tied** (named with rivals, or a rival of the name), the
   diagnosis designs the next experiment (:meth:`boucwen.diagnosis.Diagnosis.next_experiment`,
   same length, the first record's limits), and the designed and generic inputs'
   closest-pair separations are recorded;
3. the plant is simulated on the designed input (new noise), and the first record is
   diagnosed again with that one as ``validate``: the set is settled there.

Per half (seeds split by parity, like the suite: even seeds are the development half,
odd ones held out), it reports the share of tied cases where the true effect ends
``confident``, the number of wrong ``confident`` names, and the median ratio of the
designed to the generic separation. Targets (on each half): ≥ 90 % settled right,
no wrong confident name, median ratio ≥ 3. Exit code 1 when a target fails.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..diagnosis import diagnose
from ..effects.base import set_of
from ..plant import simulate_oversampled
from ..progress import reporter
from .suite_records import make_suite_record
from .undeclared_records import PARAM_SETS

__all__ = ["LOOKALIKES", "TARGETS", "main", "run_case", "summarise"]

#: The effects whose look-alikes a single slow sine leaves tied, by family.
LOOKALIKES = {
    "creep / input lag / electrostriction": ("creep", "input_lag", "electrostriction"),
    "drift / gain drift / creep": ("drift", "gain_drift"),
    "delay / input lag": ("delay",),
}
#: The first record: rate [Hz], length [s], sine frequency [Hz], levels [V].
FS_HZ = 5_000.0
DURATION_S = 1.2
SINE_HZ = 5.0
LEVELS_V = (20.0, 80.0)
#: Effect sizes [µm RMS] and noise levels [µm] of the plants: seed s takes size
#: ``SIZES_UM[(s // 2) % 2]`` and noise ``NOISE_UM[(s // 4) % 2]``, so that each half meets
#: every pair of them (the smaller effect in the larger noise is where look-alikes tie).
SIZES_UM = (0.02, 0.08)
NOISE_UM = (0.005, 0.02)
#: The plant is simulated on a grid this many times finer than the record's.
OVERSAMPLE = 4
#: Targets per half: share of tied cases settled right, wrong confident names, median
#: ratio of designed to generic separation.
TARGETS = {"settled_right": 0.9, "wrong_confident": 0, "median_ratio": 3.0}
HALVES = ("development", "held_out")


def _first_input() -> np.ndarray:
    t = np.arange(round(DURATION_S * FS_HZ)) / FS_HZ
    lo, hi = LEVELS_V
    return np.asarray(0.5 * (lo + hi) - 0.5 * (hi - lo) * np.cos(2 * math.pi * SINE_HZ * t))


def _tied(d: Any, truth: str) -> bool:
    return any(e.rivals and (e.name == truth or truth in e.rivals) for e in d.named_effects)


def _confident(d: Any) -> list[str]:
    return [e.name for e in d.named_effects if e.level == "confident"]


def run_case(effect: str, seed: int) -> dict[str, Any]:
    """One plant: its first record, the designed experiment, the settled diagnosis."""
    size, noise = SIZES_UM[(seed // 2) % 2], NOISE_UM[(seed // 4) % 2]
    rec = make_suite_record([(effect, size)], "multisine", seed, fs_hz=FS_HZ, noise_um=noise)
    params = PARAM_SETS[rec.param_set]
    rng = np.random.default_rng(10_000 + seed)
    dt = 1.0 / FS_HZ

    def plant(u: np.ndarray) -> np.ndarray:
        x = simulate_oversampled(params, set_of(rec.params), u, dt, OVERSAMPLE)
        return np.asarray(x + rng.normal(0.0, noise, u.size))

    u_a = _first_input()
    x_a = plant(u_a)
    first = diagnose(u_a, x_a, dt)
    row: dict[str, Any] = {
        "effect": effect,
        "seed": seed,
        "half": HALVES[seed % 2],
        "size_um": size,
        "noise_um": noise,
        "first_named": {e.name: [e.level, list(e.rivals)] for e in first.named_effects},
        "tied": _tied(first, effect),
    }
    if not row["tied"]:
        row["first_right"] = effect in _confident(first) or effect in first.effects
        return row
    exp = first.next_experiment(duration_s=DURATION_S)
    row.update(
        explanations=[m.label for m in exp.explanations],
        designed=exp.min_separation,
        generic=exp.generic_min_separation,
        generic_kind=exp.generic_kind,
        features=[f.detail for f in exp.features],
    )
    x_b = plant(exp.u)
    settled = diagnose(u_a, x_a, dt, validate=(exp.u, x_b, dt))
    confident = _confident(settled)
    row.update(
        settled_named={e.name: [e.level, list(e.rivals)] for e in settled.named_effects},
        right=effect in confident,
        wrong_confident=[k for k in confident if k != effect],
    )
    return row


def summarise(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per half: cases, tied cases, share settled right, wrong confident names, median
    designed / generic separation."""
    out: dict[str, dict[str, float]] = {}
    for half in HALVES:
        tied = [r for r in rows if r["half"] == half and r["tied"]]
        ratios = [r["designed"] / r["generic"] for r in tied if r["generic"] > 0]
        out[half] = {
            "cases": float(sum(r["half"] == half for r in rows)),
            "tied": float(len(tied)),
            "settled_right": float(np.mean([r["right"] for r in tied])) if tied else math.nan,
            "wrong_confident": float(sum(len(r["wrong_confident"]) for r in tied)),
            "median_ratio": float(np.median(ratios)) if ratios else math.nan,
            "median_designed": float(np.median([r["designed"] for r in tied])) if tied else math.nan,
            "median_generic": float(np.median([r["generic"] for r in tied])) if tied else math.nan,
        }
    return out


def table(rows: Sequence[dict[str, Any]]) -> str:
    """The cases as a Markdown table."""
    lines = [
        "| effect | seed | half | first record | explanations | designed σ̂ | generic σ̂ | settled | right |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        first = ", ".join(f"{k} ({v[0]}{'; ' + '/'.join(v[1]) if v[1] else ''})" for k, v in r["first_named"].items())
        if not r["tied"]:
            lines.append(f"| {r['effect']} | {r['seed']} | {r['half']} | {first or 'none'} | not tied | | | | |")
            continue
        settled = ", ".join(f"{k} ({v[0]})" for k, v in r["settled_named"].items())
        lines.append(
            f"| {r['effect']} | {r['seed']} | {r['half']} | {first} | {' / '.join(r['explanations'])} | "
            f"{r['designed']:.3g} | {r['generic']:.3g} ({r['generic_kind']}) | {settled or 'none'} | "
            f"{'yes' if r['right'] else 'no'} |"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.experiment_design", description=(__doc__ or "").split("\n\n")[0]
    )
    parser.add_argument("--half", choices=HALVES, help="one half only (default: both)")
    parser.add_argument("--seeds", type=int, default=8, help="seeds per effect (default 8: four per half)")
    parser.add_argument("--out", help="folder for rows.json and table.md")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    say = reporter(True, "experiment_design", started)
    rows = []
    effects = [e for group in LOOKALIKES.values() for e in group]
    for effect in effects:
        for seed in range(args.seeds):
            if args.half is not None and HALVES[seed % 2] != args.half:
                continue
            row = run_case(effect, seed)
            rows.append(row)
            if row["tied"]:
                say(
                    f"{effect} seed {seed}: {' / '.join(row['explanations'])}; designed {row['designed']:.3g} σ̂, "
                    f"generic {row['generic']:.3g} σ̂; settled {row['settled_named']}"
                )
            else:
                say(f"{effect} seed {seed}: not tied on the first record ({row['first_named']})")
    figures = summarise(rows)
    text = table(rows) + "\n\n" + json.dumps(figures, indent=1)
    print(text)
    halves = [args.half] if args.half else list(HALVES)
    failed = []
    for half in halves:
        f = figures[half]
        if not f["tied"]:
            continue
        if not f["settled_right"] >= TARGETS["settled_right"]:
            failed.append(f"{half}: settled right {f['settled_right']:.2f} < {TARGETS['settled_right']}")
        if f["wrong_confident"] > TARGETS["wrong_confident"]:
            failed.append(f"{half}: {f['wrong_confident']:.0f} wrong confident names")
        if not f["median_ratio"] >= TARGETS["median_ratio"]:
            failed.append(f"{half}: median ratio {f['median_ratio']:.2f} < {TARGETS['median_ratio']}")
    for line in failed:
        print(f"target fails: {line}")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "rows.json").write_text(json.dumps(rows, indent=1, default=float), encoding="utf-8")
        (out / "table.md").write_text(text + "\n", encoding="utf-8")
    print(f"wall {time.perf_counter() - started:.0f} s", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
