"""The diagnosis evaluation suite: generated records, what the diagnosis names, the
confusion table and the figures it is held to.

``python -m boucwen.experiments.diagnosis_suite [--quick] [--half H] [--out DIR]``
generates the records of :func:`cases` (:mod:`boucwen.experiments.suite_records`), runs
:func:`boucwen.diagnose` on each without telling it what is inside (one progress line
per record on stderr), and prints the confusion table — true effect set × named effect
set, per half, and how many were flagged as unexplained — and the figures.

The suite is a check, not a target. Its records are split by seed into a
*development* half (even seeds) and a *held-out* half (odd seeds): a change to the
diagnosis is looked at on the first, and the second is read only to judge it. Both are
reported side by side; a gap between them is overfitting. The figures, per half:

* ``inside_named``: records holding effects of the vocabulary (one, or a pair) whose
  named set is exactly the true one (reported, not targeted);
* ``confident_right``: of all names given with confidence ``confident``, the share
  that are effects the record holds;
* ``clean_confident``: clean records with a confident name;
* ``outside_flagged``: records holding an effect outside the vocabulary whose residual
  the diagnosis flags as not consistent with noise;
* ``truth_rises``: records where the returned model is further from the noise-free
  truth than the base model (by more than 1 %, a rise no user would call noise);
* ``median_cut``: median over the records holding effects of the vocabulary of
  RMS(base model − noise-free truth) / RMS(diagnosed model − noise-free truth);
* ``oscillator_named``: records (all piezo records, input-driven) whose returned model is
  the hysteretic oscillator;
* ``unbounded``: records whose returned model fails the boundedness check
  (:func:`boucwen.boundedness.check`: its output over the record's range leaves the
  stated multiple of the record's).

The checks of :data:`TARGETS`, on each half: no clean record gets a name, ≥ 95 % of
the confident names are right, the truth error never rises, the oscillator is never
returned, and every returned model passes the boundedness check; and on the full suite
(:func:`gap_checks`) the held-out half names the vocabulary's effects exactly within 3
points of the development half and gives effects outside the vocabulary a wrong name no
more often.

The vocabulary is the registry's at run time (:data:`boucwen.effects.VOCABULARY`): an
effect of :data:`~boucwen.experiments.suite_records.OUTSIDE_MAKERS` that the registry
holds is no longer generated outside it, and an effect of the vocabulary with no maker in
:data:`~boucwen.experiments.suite_records.VOCABULARY_MAKERS` is skipped (and said so).
Every record's seed is its index in :func:`cases`.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from collections import Counter, defaultdict
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ..diagnosis import diagnose
from ..effects import VOCABULARY
from ..lsq import worker_count
from ..metrics import rms
from . import shaped_records
from .suite_records import (
    FAMILIES,
    NOISE_UM,
    OUTSIDE_MAKERS,
    RATES_HZ,
    SIZES_UM,
    VOCABULARY_MAKERS,
    SuiteRecord,
    make_suite_record,
)
from .undeclared_records import PARAM_SETS

__all__ = [
    "HALVES",
    "TARGETS",
    "Case",
    "cases",
    "checks",
    "confusion_table",
    "figures",
    "figures_by_half",
    "gap_checks",
    "half_of",
    "main",
    "report",
    "run_case",
    "run_suite",
]

#: The checks the suite is held to: (figure, half, bound, "min" or "max").
TARGETS: tuple[tuple[str, str, float, str], ...] = (
    ("clean_confident", "development", 0.0, "max"),
    ("clean_confident", "held_out", 0.0, "max"),
    ("clean_nothing", "development", 1.0, "min"),
    ("clean_nothing", "held_out", 1.0, "min"),
    ("confident_right", "development", 0.95, "min"),
    ("confident_right", "held_out", 0.95, "min"),
    ("truth_rises", "development", 0.0, "max"),
    ("truth_rises", "held_out", 0.0, "max"),
    ("oscillator_named", "development", 0.0, "max"),
    ("oscillator_named", "held_out", 0.0, "max"),
    ("unbounded", "development", 0.0, "max"),
    ("unbounded", "held_out", 0.0, "max"),
)
#: Checks of the held-out half against the development half (the full suite's; the quick
#: subset has too few records per half for a difference of shares to mean anything):
#: effects of the vocabulary named exactly within this many points ...
NAMED_GAP = 0.03
#: The two halves of the suite, by seed parity.
HALVES = ("development", "held_out")
#: Relative rise of the truth error beyond which the returned model counts as worse.
TRUTH_RISE = 0.01


def half_of(seed: int) -> str:
    """The half of the suite a record of ``seed`` belongs to (even: development)."""
    return HALVES[seed % 2]


#: Static nonlinearities, invisible under a single step (u takes two values, which an
#: affine map of the model fits exactly): not generated under that family.
_NEEDS_MORE_THAN_TWO_LEVELS = ("electrostriction", "saturation", "cubic_sensor")


@dataclass(frozen=True)
class Case:
    """One record of the suite: its effects as (name, size [µm]) and how it is made
    (``family`` one of :data:`~boucwen.experiments.suite_records.FAMILIES`, or a shape of
    :data:`SHAPES`: a record shaped like a measured one)."""

    effects: tuple[tuple[str, float], ...]
    family: str
    seed: int
    fs_hz: float
    param_set: str
    noise_um: float


#: Records shaped like measured ones (:mod:`~boucwen.experiments.shaped_records`): the
#: first half of a stack record that rests, steps and follows a 1 Hz sine (5 kHz), and
#: the first day of a micromanipulator's hour (a walk and a hold, 10 Hz, a drift of the
#: day). The day's drift is the record's: naming it ``drift`` (the vocabulary's linear
#: trend, which holds part of it) is no wrong name.
SHAPES = ("rest_step_sine", "walk_hold")
#: Effects of each shape's records, at two sizes and clean, for each half.
_SHAPED = {
    "rest_step_sine": ((("creep", 0.08),), (("creep", 0.3),), ()),
    "walk_hold": ((("electrostriction", 0.08),), (("electrostriction", 0.3),), ()),
}


def _shaped_record(case: Case) -> SuiteRecord:
    """The record of a shaped case (:data:`SHAPES`)."""
    if case.family == "rest_step_sine":
        whole = shaped_records.rest_step_sine(case.effects, case.seed, noise_um=case.noise_um)
        half = whole.u.size // 2
        return replace(whole, u=whole.u[:half], x=whole.x[:half], x_true=whole.x_true[:half])
    return shaped_records.walk_hold_days(case.effects, case.seed, days=1, noise_um=case.noise_um)[0]


def _inside_names() -> list[str]:
    """Effects of the vocabulary generated on their own (a second resonance mode only
    beside a first: see :func:`_inside_spec`)."""
    return [n for n in VOCABULARY if n in VOCABULARY_MAKERS]


def _inside_spec(name: str, size: float) -> tuple[tuple[str, float], ...]:
    if name == "resonance2":
        return (("resonance", size), (name, size))
    return ((name, size),)


def _outside_names() -> list[str]:
    return [n for n in OUTSIDE_MAKERS if n not in VOCABULARY]


def cases(quick: bool = False) -> list[Case]:
    """The records of the suite (the quick subset with ``quick``).

    Full: clean records (3 per family); every effect of the vocabulary at each size of
    :data:`~boucwen.experiments.suite_records.SIZES_UM` under every family; every pair
    of them at 0.08 µm each; every effect outside the vocabulary at 0.08 and 0.3 µm
    under four families; a second resonance mode always beside a first; static
    nonlinearities never under a single step (a pair holding one takes the next family
    instead). Quick: two clean records, each effect of
    the vocabulary once at 0.08 µm, two pairs, three effects outside, one stack record
    shaped like a measured one. Full and quick: the records shaped like measured ones
    (:data:`SHAPES`) after the others. Rates, noise levels and parameter sets cycle with
    the record's index, which is also its seed.
    """
    specs: list[tuple[tuple[tuple[str, float], ...], str]] = []
    inside, outside = _inside_names(), _outside_names()
    fam = itertools.cycle(FAMILIES)
    if quick:
        specs += [((), "multisine"), ((), "staircase")]
        specs += [(_inside_spec(n, 0.08), _next_family(fam, n)) for n in inside]
        specs += [
            (pair, next(fam))
            for pair in list(itertools.combinations([(n, 0.08) for n in inside if n != "resonance2"], 2))[::4][:2]
        ]
        specs += [(_outside_spec(n, 0.08), f) for n, f in zip(outside[:3], ("chirp", "band_random", "triangle"))]
    else:
        specs += [((), f) for f in FAMILIES for _ in range(3)]
        specs += [
            (_inside_spec(n, s), f)
            for n in inside
            for s in SIZES_UM
            for f in FAMILIES
            if not (n in _NEEDS_MORE_THAN_TWO_LEVELS and f == "single_step")
        ]
        specs += [
            (pair, _shows(pair, next(fam)))
            for pair in itertools.combinations([(n, 0.08) for n in inside if n != "resonance2"], 2)
        ]
        for n in outside:
            fams = [f for f in FAMILIES if not (n in _NEEDS_MORE_THAN_TWO_LEVELS and f == "single_step")]
            specs += [(_outside_spec(n, s), f) for s in (0.08, 0.3) for f in fams[:: max(1, len(fams) // 2)][:2]]
    # Records shaped like measured ones: each effect set of a shape once per half (the
    # quick subset: one stack record; an hour at 10 Hz is the measured benchmark's).
    shaped = [(effects, shape) for shape in SHAPES for effects in _SHAPED[shape] for _ in HALVES]
    if quick:
        shaped = [(_SHAPED["rest_step_sine"][1], "rest_step_sine")]
    sets = list(PARAM_SETS)
    out = [
        Case(
            effects=effects,
            family=family,
            seed=k,
            fs_hz=RATES_HZ[k % len(RATES_HZ)],
            param_set=sets[k % len(sets)],
            noise_um=NOISE_UM[(k // len(RATES_HZ)) % len(NOISE_UM)],
        )
        for k, (effects, family) in enumerate(specs)
    ]
    start = len(out)
    for j, (effects, shape) in enumerate(shaped):
        k = start + j
        rate = shaped_records.STACK_RATE_HZ if shape == "rest_step_sine" else shaped_records.WALK_RATE_HZ
        out.append(Case(effects, shape, k, rate, "paper_1hz", NOISE_UM[1]))
    return out


def _next_family(fam: Iterator[str], name: str) -> str:
    """The next family of the cycle under which the effect `name` can show."""
    f = next(fam)
    while name in _NEEDS_MORE_THAN_TWO_LEVELS and f == "single_step":
        f = next(fam)
    return f


def _shows(effects: tuple[tuple[str, float], ...], family: str) -> str:
    """``family``, or the one after it in :data:`FAMILIES` when one of ``effects`` is a
    static nonlinearity that a single step cannot show."""
    if family == "single_step" and any(n in _NEEDS_MORE_THAN_TWO_LEVELS for n, _ in effects):
        return FAMILIES[(FAMILIES.index(family) + 1) % len(FAMILIES)]
    return family


def _outside_spec(name: str, size: float) -> tuple[tuple[str, float], ...]:
    return ((name, size),)


def run_case(case: Case, workers: int | None = None) -> dict[str, Any]:
    """Generates the record of ``case``, diagnoses it and scores the answer."""
    if case.family in SHAPES:
        rec = _shaped_record(case)
    else:
        rec = make_suite_record(
            case.effects, case.family, case.seed, fs_hz=case.fs_hz, param_set=case.param_set, noise_um=case.noise_um
        )
    t0 = time.perf_counter()
    d = diagnose(rec.u, rec.x, rec.dt, seed=case.seed, workers=workers)
    elapsed = time.perf_counter() - t0
    truth, named = set(rec.inside), set(d.effects)
    if case.family == "walk_hold":
        named.discard("drift")
    before, after = rms(d.x_base - rec.x_true), rms(d.x_extended - rec.x_true)
    kind = "outside" if rec.outside else ("inside" if rec.inside else "clean")
    flagged = d.unexplained is not None and not d.unexplained.consistent_with_noise
    confident = sorted(k for k, c in d.confidence.items() if c["level"] == "confident")
    return {
        "label": rec.label,
        "seed": case.seed,
        "half": half_of(case.seed),
        "kind": kind,
        "confident": confident,
        "confident_wrong": sorted(set(confident) - truth),
        "inside": sorted(rec.inside),
        "outside": sorted(rec.outside),
        "sizes_um": rec.sizes_um,
        "named": sorted(named),
        "right": named == truth if kind != "outside" else (named <= truth and flagged),
        "wrong_name": bool(named - truth),
        "flagged": flagged,
        "truth_rms_before_um": before,
        "truth_rms_after_um": after,
        "cut": before / after if after > 0 else float("inf"),
        "rms_before_um": d.rms_before_um,
        "rms_after_um": d.rms_after_um,
        "noise_est_um": d.unexplained.noise_um if d.unexplained is not None else float("nan"),
        "samples": int(rec.u.size),
        "elapsed_s": elapsed,
        "structure": None if d.structure is None else d.structure.name,
        "bounded": d.boundedness is not None and d.boundedness.passed,
        "boundedness": None if d.boundedness is None else d.boundedness.summary(),
    }


def _share(rows: list[dict[str, Any]], key: str) -> float:
    return float(np.mean([bool(r[key]) for r in rows])) if rows else float("nan")


def figures(rows: list[dict[str, Any]]) -> dict[str, float]:
    """The figures of the module's docstring over ``rows`` (one half, or any set)."""
    by = defaultdict(list)
    for r in rows:
        by[r["kind"]].append(r)
    inside, clean, outside = by["inside"], by["clean"], by["outside"]
    confident = sum(len(r["confident"]) for r in rows)
    wrong = sum(len(r["confident_wrong"]) for r in rows)
    return {
        "records": float(len(rows)),
        "inside_named": _share(inside, "right"),
        "confident_names": float(confident),
        "confident_right": 1.0 - wrong / confident if confident else float("nan"),
        "clean_confident": float(sum(bool(r["confident"]) for r in clean)),
        "clean_nothing": float(np.mean([not r["named"] for r in clean])) if clean else float("nan"),
        "outside_flagged": _share(outside, "flagged"),
        "outside_wrong_name": _share(outside, "wrong_name"),
        "truth_rises": float(
            sum(r["truth_rms_after_um"] > (1.0 + TRUTH_RISE) * r["truth_rms_before_um"] for r in rows)
        ),
        "median_cut": float(np.median([r["cut"] for r in inside])) if inside else float("nan"),
        "clean_flagged": _share(clean, "flagged"),
        "oscillator_named": float(sum(r.get("structure") is not None for r in rows)),
        "unbounded": float(sum(not r.get("bounded", True) for r in rows)),
        "inside_flagged": _share(inside, "flagged"),
    }


def figures_by_half(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """:func:`figures` of each half of the suite (:data:`HALVES`)."""
    return {h: figures([r for r in rows if r["half"] == h]) for h in HALVES}


def checks(by_half: dict[str, dict[str, float]]) -> list[tuple[str, bool]]:
    """Each check of :data:`TARGETS` as a line and whether it holds (a figure with no
    record behind it, NaN, holds vacuously and says so)."""
    out = []
    for name, h, bound, how in TARGETS:
        v = by_half[h][name]
        ok = bool(np.isnan(v)) or (v >= bound if how == "min" else v <= bound)
        sign = "≥" if how == "min" else "≤"
        out.append((f"{name} [{h}]: {v:.3g} (check {sign} {bound:g}) {'holds' if ok else 'FAILS'}", ok))
    return out


def gap_checks(by_half: dict[str, dict[str, float]]) -> list[tuple[str, bool]]:
    """The held-out half against the development half: effects of the vocabulary named
    exactly within :data:`NAMED_GAP`, and effects outside it given a wrong name no more
    often (NaN on either side holds vacuously)."""
    dev, held = by_half["development"], by_half["held_out"]
    gap = dev["inside_named"] - held["inside_named"]
    worse = held["outside_wrong_name"] - dev["outside_wrong_name"]
    named_ok = bool(np.isnan(gap)) or gap <= NAMED_GAP
    outside_ok = bool(np.isnan(worse)) or worse <= 0
    return [
        (
            f"inside_named gap (development − held_out): {gap:.3g} (check ≤ {NAMED_GAP:g}) "
            + ("holds" if named_ok else "FAILS"),
            named_ok,
        ),
        (
            f"outside_wrong_name, held_out − development: {worse:.3g} (check ≤ 0) "
            + ("holds" if outside_ok else "FAILS"),
            outside_ok,
        ),
    ]


def _set_label(names: Sequence[str], outside: Sequence[str] = ()) -> str:
    words = list(names) + [f"{n} (outside)" for n in outside]
    return "+".join(words) or "none"


def confusion_table(rows: list[dict[str, Any]]) -> str:
    """Markdown: one row per true effect set, the named sets with their counts and how
    many were flagged as unexplained."""
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[_set_label(r["inside"], r["outside"])].append(r)
    head = " | ".join(f"{h}: records, named (count), flagged" for h in HALVES)
    lines = [f"| true effects | {head} |", "|---|" + "---|" * len(HALVES)]
    for label in sorted(groups, key=lambda k: (k != "none", "(outside)" in k, "+" in k, k)):
        cells = []
        for h in HALVES:
            g = [r for r in groups[label] if r["half"] == h]
            named = Counter(_set_label(sorted(r["named"])) for r in g)
            said = ", ".join(f"{k} {v}" for k, v in named.most_common()) or "-"
            cells.append(f"{len(g)}: {said}; {sum(r['flagged'] for r in g)}")
        lines.append(f"| {label} | {' | '.join(cells)} |")
    return "\n".join(lines)


def run_suite(
    quick: bool = False, err: TextIO = sys.stderr, half: str | None = None, jobs: int | None = None
) -> list[dict[str, Any]]:
    """Runs every case, or those of one ``half`` (one progress line per record on
    ``err``), on ``jobs`` processes (default: the number of CPUs; each diagnosis on one
    thread), the records independent; returns the rows in the order of the cases."""
    todo = [c for c in cases(quick) if half is None or half_of(c.seed) == half]
    skipped = [n for n in VOCABULARY if n not in VOCABULARY_MAKERS]
    if skipped:
        print(f"no maker for the vocabulary's {skipped}: not generated", file=err, flush=True)
    count = worker_count(jobs)
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=count) if count > 1 else nullcontext() as pool:
        results = pool.map(run_case, todo, [1] * len(todo)) if pool is not None else (run_case(c, None) for c in todo)
        for k, row in enumerate(results):
            rows.append(row)
            mark = "ok" if row["right"] else "MISS"
            print(
                f"[{k + 1}/{len(todo)} {time.perf_counter() - started:7.1f} s] {row['label']}: "
                f"named {_set_label(row['named'])}, {'flagged' if row['flagged'] else 'not flagged'}, "
                f"cut {row['cut']:.3g}× ({row['elapsed_s']:.1f} s) {mark}",
                file=err,
                flush=True,
            )
    return rows


def _speed() -> int:
    rec = make_suite_record(
        (("creep", 0.1), ("input_lag", 0.1)), "multisine", 7, fs_hz=20_000.0, noise_um=0.005, duration_s=6.5
    )
    t0 = time.perf_counter()
    d = diagnose(rec.u, rec.x, rec.dt, progress=True)
    print(f"{rec.u.size} samples: {d.summary()}; {time.perf_counter() - t0:.1f} s")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.diagnosis_suite", description=(__doc__ or "").split("\n\n")[0]
    )
    parser.add_argument("--quick", action="store_true", help="the quick subset (the one CI runs)")
    parser.add_argument("--half", choices=HALVES, help="one half of the suite only (default: both)")
    parser.add_argument("--out", help="folder for rows.json and table.md")
    parser.add_argument(
        "--jobs", type=int, default=None, help="records diagnosed at once, one process each (default: the CPUs)"
    )
    parser.add_argument(
        "--speed",
        action="store_true",
        help="instead: time the diagnosis of one 130 000-sample record (20 kHz, 6.5 s multisine, "
        "creep and input_lag of 0.1 µm each, 5 nm of noise, seed 7), with its progress lines",
    )
    args = parser.parse_args(argv)
    if args.speed:
        return _speed()
    started = time.perf_counter()
    rows = run_suite(args.quick, half=args.half, jobs=args.jobs)
    wall = time.perf_counter() - started
    text, results = report(rows, wall, full=not args.quick and args.half is None)
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "rows.json").write_text(json.dumps(rows, indent=1, default=float), encoding="utf-8")
        (out / "table.md").write_text(text + "\n", encoding="utf-8")
        run = {"quick": args.quick, "half": args.half, "records": len(rows), "wall_s": wall, "table": text}
        (out / "results.json").write_text(json.dumps(run, indent=1), encoding="utf-8")
    return 0 if all(ok for _, ok in results) else 1


def report(rows: list[dict[str, Any]], wall_s: float, full: bool = False) -> tuple[str, list[tuple[str, bool]]]:
    """The printed report of a run (markdown: the confusion table, the figures of each
    half side by side, each check and whether it holds) and the checks (with
    :func:`gap_checks` for a ``full`` run of both halves)."""
    by_half = figures_by_half(rows)
    lines = [confusion_table(rows), "", f"{len(rows)} records in {wall_s:.0f} s", ""]
    lines += ["| figure | " + " | ".join(HALVES) + " |", "|---|" + "---|" * len(HALVES)]
    for name in next(iter(by_half.values())):
        lines.append(f"| {name} | " + " | ".join(f"{by_half[h][name]:.3g}" for h in HALVES) + " |")
    results = checks(by_half) + (gap_checks(by_half) if full else [])
    lines += ["", *(line for line, _ in results)]
    return "\n".join(lines), results


if __name__ == "__main__":
    sys.exit(main())
