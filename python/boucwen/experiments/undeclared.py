"""Records with one undeclared effect, and the table of what the diagnosis makes of them.

``python -m boucwen.experiments.undeclared [--seeds N]`` generates records —
several seeds, base parameter sets (the paper's Table 2 rows) and noise levels — each
holding one effect of the vocabulary (creep, input_lag, resonance, drift, delay) or
none, runs :func:`boucwen.diagnose` on each without telling it what is inside, and
prints one row per record: the effect put in, what was named, and the RMS error
against the *noise-free* signal [µm] before (base model) → after (with the named
effects). With ``--online`` it prints instead how the online identifier
(``method="rpem"``, started from the base fit) compares with the offline fits
(:mod:`boucwen.experiments.undeclared_online`).

The records come from :mod:`boucwen.experiments.undeclared_records`.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from typing import Any, TextIO

from .._core import EffectSet
from ..diagnosis import diagnose
from ..metrics import rms
from .undeclared_online import run_online_table
from .undeclared_records import (
    DT,
    EFFECT_RANGES,
    NOISE_LEVELS_UM,
    PARAM_SETS,
    UndeclaredRecord,
    cases,
    make_record,
    test_input,
)

# The record generator's names are importable from here too.
__all__ = [
    "DT",
    "EFFECT_RANGES",
    "NOISE_LEVELS_UM",
    "PARAM_SETS",
    "UndeclaredRecord",
    "cases",
    "main",
    "make_record",
    "run_table",
    "test_input",
]


def _describe(effects: EffectSet) -> str:
    """The effects' parameters in a few words (vocabulary order)."""
    d = effects.to_dict()
    parts = []
    if "creep" in d:
        parts.append(f"creep Σg={sum(d['creep']['gain_um_per_v']):.3g} µm/V")
    if "input_lag" in d:
        parts.append(f"fc={d['input_lag']['fc_hz']:.3g} Hz")
    if "resonance" in d:
        parts.append(f"fn={d['resonance']['fn_hz']:.3g} Hz ζ={d['resonance']['zeta']:.2g}")
    if "drift" in d:
        parts.append(f"{d['drift']['rate_um_per_s']:+.3g} µm/s")
    if "delay" in d:
        parts.append(f"d={d['delay']['samples']}")
    return ", ".join(parts) or "-"


def run_table(seeds: int = 3, out: TextIO = sys.stdout) -> list[dict[str, Any]]:
    """Runs the diagnosis on :func:`cases` and prints the table; returns its rows."""
    rows: list[dict[str, Any]] = []
    header = (
        f"{'effect':10s} {'set':11s} {'noise':>6s} {'seed':>4s}  {'true parameters':28s} "
        f"{'named':22s} {'RMS vs noise-free before → after [µm]':>38s} {'time':>6s}"
    )
    print(header, file=out)
    print("-" * len(header), file=out)
    for effect, seed, pset, noise in cases(seeds):
        rec = make_record(effect, seed, pset, noise)
        t0 = time.perf_counter()
        d = diagnose(rec.u, rec.x, rec.dt, seed=seed)
        elapsed = time.perf_counter() - t0
        before = rms(d.x_base - rec.x_true)
        after = rms(d.x_extended - rec.x_true)
        named = ",".join(d.effects) or "none"
        ok = (named == effect) and (effect == "none" or after < before)
        rows.append(
            {
                "effect": effect,
                "param_set": pset,
                "noise_um": noise,
                "seed": seed,
                "named": named,
                "rms_before_um": before,
                "rms_after_um": after,
                "elapsed_s": elapsed,
                "ok": ok,
            }
        )
        print(
            f"{effect:10s} {pset:11s} {noise * 1e3:4g}nm {seed:4d}  {_describe(rec.effects):28s} "
            f"{named:22s} {before:17.4f} → {after:<17.4f} {elapsed:5.1f}s"
            f"{'' if ok else '  MISS'}",
            file=out,
            flush=True,
        )
    hits = sum(r["ok"] for r in rows)
    print(f"{hits}/{len(rows)} records diagnosed correctly", file=out)
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.undeclared", description=(__doc__ or "").split("\n\n")[0]
    )
    parser.add_argument("--seeds", type=int, default=3, help="records per effect (default 3)")
    parser.add_argument(
        "--online",
        action="store_true",
        help="instead: RMS of the offline base, offline extended and online rpem "
        "models (markdown table; see boucwen.experiments.undeclared_online)",
    )
    args = parser.parse_args(argv)
    if args.online:
        run_online_table(args.seeds)
        return 0
    rows = run_table(args.seeds)
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
