"""The judge calibrated: how often it accepts a move that does not improve, and how far
its screen is from its refits.

``python -m boucwen.experiments.judge_calibration [--records N] [--out DIR]`` generates
records of the suite's **development half** only (even seeds;
:mod:`~boucwen.experiments.suite_records`, the shaped records of
:mod:`~boucwen.experiments.shaped_records` among them) of two kinds:

* **clean** records (the base model is the truth), judged from the base model;
* records whose effect is **already in the model**: a record holding one effect of the
  vocabulary, judged from the base model with that effect, fitted to convergence.

From each such reference every add move of the vocabulary is fitted to convergence and
judged twice (:mod:`boucwen.diagnosis.judge`): on the screen's held-out errors (the
first Gauss–Newton step of each fold's refit) and on converged refits. Nothing such a
move adds is in the record, so every acceptance is a false accept. It prints

1. the **false-accept rate per move** of the judge at the nominal level α (one move's
   test at α, no correction for the moves of a round or the rounds of a search, and the
   judge's second condition: a gain beyond a tenth of the error beyond the noise and
   beyond the reference model's own sampling-rate error,
   :func:`boucwen.diagnosis.fits.resolution`), beside α — the rate must not exceed it;
   the share of moves the test alone finds significant at α; and the number the full
   rule accepts at the search's own level (both conditions, α/(R·m)). The test alone
   is not held to α: the reference steps at the record's interval where the record was
   made on a finer grid, so a move can truly predict part of that stepping error on
   held-out data (a staircase's steps at 20 kHz leave 29 nm RMS of it), and the
   second condition is what refuses such a gain;
   The rate is printed with its exact (Clopper–Pearson) 95 % interval over the moves;
2. the share of these moves whose **score** (:mod:`boucwen.diagnosis.score`) passes, so
   would be fitted at all, and how many of the judge's false accepts the score would have
   left unfitted;
3. the distribution of the **screen's error** on the statistic, screen − refits, over
   every move judged: its quantiles and largest magnitude, the band
   (:attr:`boucwen.DiagnosisPolicy.screen_band`) it supports, and how many decisions
   the screen would have taken differently outside that band (none may).

Writes ``DIR/calibration.json`` with every judged move.
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
from scipy import stats

from ..diagnosis import DiagnosisPolicy
from ..diagnosis import fits as fitting
from ..diagnosis.heldout import Folds
from ..diagnosis.judge import gain, least_gain, threshold
from ..diagnosis.judge import level as move_level
from ..diagnosis.score import Scorer
from ..diagnosis.search import Move, proposals
from ..effects import VOCABULARY
from ..fit import fit_record
from ..record import validate_record
from ..residual import noise_level
from .suite_records import FAMILIES, NOISE_UM, RATES_HZ, VOCABULARY_MAKERS, make_suite_record
from .undeclared_records import PARAM_SETS

__all__ = ["DEFAULT_OUT", "NOMINAL_ALPHA", "calibration_cases", "clopper_pearson", "judge_moves", "main", "summary"]

DEFAULT_OUT = "out/judge_calibration"
#: The level the false-accept rate per move is held to.
NOMINAL_ALPHA = 0.05
#: Effects whose records serve as "already in the model" references (a second mode is
#: judged beside its first as the search proposes it, not on its own).
_ALREADY = tuple(k for k in VOCABULARY if k in VOCABULARY_MAKERS and k != "resonance2")


def calibration_cases(records: int) -> list[dict[str, Any]]:
    """``records`` cases of the development half (even seeds): alternately clean and
    holding one effect of the vocabulary, families, rates, noise levels and parameter
    sets cycling with the seed."""
    out = []
    sets = list(PARAM_SETS)
    for k in range(records):
        seed = 2 * k
        effect = None if k % 2 == 0 else _ALREADY[(k // 2) % len(_ALREADY)]
        out.append(
            {
                "seed": seed,
                "effects": () if effect is None else ((effect, 0.08),),
                "family": FAMILIES[(k // 2) % len(FAMILIES)] if effect is None else FAMILIES[(k // 2 + 3) % 8],
                "fs_hz": RATES_HZ[k % len(RATES_HZ)],
                "noise_um": NOISE_UM[(k // len(RATES_HZ)) % len(NOISE_UM)],
                "param_set": sets[k % len(sets)],
            }
        )
    return out


def judge_moves(case: dict[str, Any], policy: DiagnosisPolicy, workers: int | None = None) -> list[dict[str, Any]]:
    """Every add move from the case's reference model (module docs), judged on the
    screen and on refits; one row per move."""
    if (
        case["family"] == "single_step"
        and case["effects"]
        and case["effects"][0][0] in ("electrostriction", "saturation")
    ):
        case = {**case, "family": "staircase"}
    rec = make_suite_record(
        case["effects"],
        case["family"],
        case["seed"],
        fs_hz=case["fs_hz"],
        param_set=case["param_set"],
        noise_um=case["noise_um"],
    )
    record = validate_record(rec.u, rec.x, rec.dt)
    conv = fitting.Convergence()
    offline = fit_record(record, seed=case["seed"], workers=workers)
    reference: Any = fitting.base(record, offline, conv, policy.folds, policy.first_origin)
    folds = reference.cv.folds
    for name, _ in case["effects"]:
        got = fitting.add(record, reference, (name,), conv, folds, policy.max_delay_samples)
        if isinstance(got, str):
            return []
        reference = got
    noise = noise_level(record.x).sigma_um
    moves = [m for m in proposals(reference.names, {}, policy.max_effects) if m.kind in ("add", "add_tied")]
    lvl = move_level(policy.alpha, len(moves), 1)
    ref_exact = fitting.confirmed(record, reference, workers)
    resolution_um = fitting.resolution(record, reference.fit)
    scorer = Scorer(record, reference.x, reference.jacobian, reference.fit.params, reference.fit.h0)
    needed_in = least_gain(reference.fit.rms_um**2, noise, policy.min_share, resolution_um)
    rows = []
    for m in moves:
        starts = fitting.starts_of(record, reference, m.adds, policy.max_delay_samples, None)
        score, _ = scorer.score(starts, m.adds, lvl, needed_in)
        cand = _fitted(record, reference, m, conv, folds, policy)
        if cand is None:
            continue
        exact = fitting.confirmed(record, cand, workers)
        g_screen, g_exact = gain(cand.cv, reference.cv), gain(exact.cv, ref_exact.cv)
        needed = least_gain(g_exact.reference_mse_um2, noise, policy.min_share, resolution_um)
        rows.append(
            {
                "record": rec.label,
                "truth": list(rec.inside),
                "reference": list(reference.names),
                "move": " + ".join(m.adds),
                "converged": bool(cand.converged),
                "screen": g_screen.statistic,
                "exact": g_exact.statistic,
                "dof": g_exact.dof,
                "gain_um2": g_exact.mean_um2,
                "resolution_um": resolution_um,
                "bandwidth": g_exact.bandwidth,
                "nominal_threshold": threshold(NOMINAL_ALPHA, g_exact.dof),
                "search_threshold": threshold(lvl, g_exact.dof),
                "screen_threshold": threshold(lvl, g_screen.dof),
                "enough": bool(g_exact.mean_um2 >= needed and g_exact.mean_um2 > 0),
                "score_p": score.p_value,
                "score_passed": bool(score.passed),
            }
        )
    return rows


def _fitted(
    record: Any, reference: Any, move: Move, conv: Any, folds: Folds, policy: DiagnosisPolicy
) -> fitting.Scored | None:
    out = fitting.add(record, reference, move.adds, conv, folds, policy.max_delay_samples)
    return None if isinstance(out, str) else out


def _finite(rows: list[dict[str, Any]], key: str) -> list[dict[str, Any]]:
    return [r for r in rows if r["converged"] and math.isfinite(r[key])]


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper–Pearson) interval of a rate of ``k`` in ``n`` [-]."""
    if n == 0:
        return math.nan, math.nan
    tail = (1.0 - confidence) / 2.0
    low = float(stats.beta.ppf(tail, k, n - k + 1)) if k > 0 else 0.0
    high = float(stats.beta.ppf(1.0 - tail, k + 1, n - k)) if k < n else 1.0
    return low, high


def summary(rows: list[dict[str, Any]], band: float) -> dict[str, Any]:
    """The figures of module docs over ``rows`` (:func:`judge_moves`'s), the screen's band
    ``band``."""
    judged = _finite(rows, "exact")
    alone = [r["exact"] > r["nominal_threshold"] for r in judged]
    nominal = [a and r["enough"] for a, r in zip(alone, judged)]
    full = [r["exact"] > r["search_threshold"] and r["enough"] for r in judged]
    both = [r for r in judged if math.isfinite(r["screen"])]
    diff = np.array([r["screen"] - r["exact"] for r in both]) if both else np.zeros(0)
    # A decision the screen takes without confirmation: outside the band of the threshold
    # and not accepted. It differs from the refits' where the refits accept it.
    missed = [
        r
        for r in both
        if r["screen"] <= r["screen_threshold"] - band and r["exact"] > r["search_threshold"] and r["enough"]
    ]
    records = len({r["record"] for r in rows})
    accepted = int(np.sum(nominal))
    low, high = clopper_pearson(accepted, len(nominal))
    return {
        "records": records,
        "moves": len(judged),
        "nominal_alpha": NOMINAL_ALPHA,
        "false_accept_rate_nominal": float(np.mean(nominal)) if nominal else math.nan,
        "false_accept_rate_interval_95": [low, high],
        "score_passed_rate": float(np.mean([r.get("score_passed", True) for r in judged])) if judged else math.nan,
        "false_accepts_the_score_leaves_unfitted": int(
            sum(n and not r.get("score_passed", True) for n, r in zip(nominal, judged))
        ),
        "significant_rate_nominal": float(np.mean(alone)) if alone else math.nan,
        "false_accepts_full_rule": int(np.sum(full)),
        "screen_minus_exact": {
            "moves": int(diff.size),
            "quantiles": {
                str(q): float(np.quantile(diff, q)) if diff.size else math.nan for q in (0.01, 0.05, 0.5, 0.95, 0.99)
            },
            "max_abs": float(np.max(np.abs(diff))) if diff.size else math.nan,
        },
        "band": band,
        "decisions_the_band_misses": len(missed),
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m boucwen.experiments.judge_calibration", description=(__doc__ or "").split("\n\n")[0]
    )
    parser.add_argument("--records", type=int, default=40, help="records of the development half (default 40)")
    parser.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help=f"output folder (default {DEFAULT_OUT})")
    args = parser.parse_args(argv)
    policy = DiagnosisPolicy()
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    for k, case in enumerate(calibration_cases(args.records)):
        got = judge_moves(case, policy)
        rows += got
        print(
            f"[{k + 1}/{args.records} {time.perf_counter() - started:6.0f} s] seed {case['seed']} "
            f"{case['effects'] or 'clean'} {case['family']}: {len(got)} moves",
            file=sys.stderr,
            flush=True,
        )
    result = summary(rows, policy.screen_band)
    print(json.dumps(result, indent=1))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "calibration.json").write_text(json.dumps({"summary": result, "rows": rows}, indent=1), encoding="utf-8")
    held = result["false_accept_rate_nominal"] <= NOMINAL_ALPHA and result["decisions_the_band_misses"] == 0
    return 0 if held else 1


if __name__ == "__main__":
    sys.exit(main())
