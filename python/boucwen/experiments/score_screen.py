"""The score screen checked against the full judge: does it ever lose a move the judge takes?

``python -m boucwen.experiments.score_screen [--half development|held_out] [--records N]
[--jobs J] [--out DIR]`` diagnoses records of the quick suite
(:func:`boucwen.experiments.diagnosis_suite.cases`) with every move fitted and judged
(``Convergence(score=False)``), each add move still scored at the current model
(:mod:`boucwen.diagnosis.score`). A **miss** is a move the judge accepted whose score did
not pass: the screen, switched on, would have left it unfitted. It prints one row per
record (moves scored, moves the screen would leave unfitted, the judge's acceptances,
misses, seconds) and the totals; the exit status is 1 where any move was missed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from pathlib import Path
from typing import Any

from ..diagnosis import diagnose
from ..diagnosis.fits import Convergence
from .diagnosis_suite import HALVES, SHAPES, Case, cases, half_of
from .suite_records import make_suite_record


def check_case(case: Case) -> dict[str, Any]:
    """One record diagnosed with every move fitted; each accepted add set beside its score."""
    rec = make_suite_record(
        case.effects, case.family, case.seed, fs_hz=case.fs_hz, param_set=case.param_set, noise_um=case.noise_um
    )
    t0 = time.perf_counter()
    d = diagnose(rec.u, rec.x, rec.dt, seed=case.seed, workers=1, convergence=Convergence(score=False))
    elapsed = time.perf_counter() - t0
    scored = cut = accepted = 0
    misses: list[str] = []
    for k, rnd in enumerate(d.evidence["rounds"]):
        scores = rnd["scores"]
        scored += len(scores)
        cut += sum(not s["passed"] for s in scores.values())
        for dec in rnd["decisions"]:
            label = " ".join((dec["move"], *dec["effects"]))
            if label not in scores or not dec["accepted"]:
                continue
            accepted += 1
            if not scores[label]["passed"]:
                misses.append(f"round {k + 1}: {label} ({scores[label]['reason']})")
    return {
        "seed": case.seed,
        "effects": [n for n, _ in case.effects],
        "family": case.family,
        "samples": int(rec.u.size),
        "scored": scored,
        "cut": cut,
        "accepted": accepted,
        "misses": misses,
        "named": list(d.effects),
        "elapsed_s": elapsed,
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.score_screen", description=(__doc__ or "").split("\n\n")[0]
    )
    parser.add_argument("--half", choices=HALVES, default="development", help="which half of the quick suite")
    parser.add_argument("--records", type=int, default=None, help="at most this many records (default: all)")
    parser.add_argument("--jobs", type=int, default=2, help="records diagnosed at once, one process each")
    parser.add_argument("--out", help="folder for screen.json")
    args = parser.parse_args(argv)
    todo = [c for c in cases(quick=True) if half_of(c.seed) == args.half and c.family not in SHAPES]
    todo = todo[: args.records] if args.records else todo
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) if args.jobs > 1 else nullcontext() as pool:
        results = pool.map(check_case, todo) if pool is not None else map(check_case, todo)
        print("| seed | effects | family | samples | scored | screen cuts | judge accepts | misses | s |")
        print("|---|---|---|---|---|---|---|---|---|")
        for row in results:
            rows.append(row)
            print(
                f"| {row['seed']} | {'+'.join(row['effects']) or 'none'} | {row['family']} | {row['samples']} | "
                f"{row['scored']} | {row['cut']} | {row['accepted']} | {len(row['misses'])} | "
                f"{row['elapsed_s']:.0f} |",
                flush=True,
            )
    misses = [m for r in rows for m in r["misses"]]
    print(
        f"\n{len(rows)} records, {sum(r['scored'] for r in rows)} add moves scored, "
        f"{sum(r['cut'] for r in rows)} left unfitted by the screen, {sum(r['accepted'] for r in rows)} accepted "
        f"by the judge, {len(misses)} missed; {time.perf_counter() - started:.0f} s"
    )
    for r in rows:
        for m in r["misses"]:
            print(f"  missed: seed {r['seed']} {m}")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "screen.json").write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return 1 if misses else 0


if __name__ == "__main__":
    sys.exit(main())
