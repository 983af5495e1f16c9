"""Effects that explain only together, tried two at a time where none earns alone
(:func:`pair_round`)."""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable

from ..effects import ExtendedFit, effect_class, solve_extended_record
from ..effects.base import params_of, set_of
from ..lsq import thread_map
from ..record import Record
from .credit import Credit, credit_of, earns
from .margins import CloseCalls, at_most, first_of_best
from .policy import DiagnosisPolicy
from .rounds import Round, Trial
from .scoring import Scored, score
from .starts import null_effort

__all__ = ["pair_earns", "pair_pool", "pair_round", "pairs_wanted"]


def pair_pool(trials: dict[str, Trial], barred: list[str], policy: DiagnosisPolicy) -> list[str]:
    """The effects paired: at most ``policy.pair_pool`` of the single ``trials`` that cut
    the in-sample error, most first, but none a look-alike in the model bars
    (``barred``) and none whose trial already adds a partner."""
    tried = [
        k
        for k, t in trials.items()
        if t.credit is not None and t.credit.in_sample_gain > 0 and effect_class(k).partner is None and k not in barred
    ]
    return sorted(tried, key=lambda k: -_credit(trials[k]).in_sample_gain)[: policy.pair_pool]


def pairs_wanted(left_rms_um: float, noise_um: float, screened: bool, policy: DiagnosisPolicy) -> bool:
    """Pairs are tried (where no effect earned alone) only on a record not ``screened``
    and only where the current model leaves at least ``pair_ratio`` times the record's
    noise (RMS errors [µm]): near the noise one of the many pairs fits its structure by
    chance."""
    return not screened and left_rms_um >= policy.pair_ratio * noise_um


def pair_earns(
    credit: Credit,
    alone: tuple[Credit, Credit],
    policy: DiagnosisPolicy,
    calls: CloseCalls | None = None,
    what: str = "",
) -> bool:
    """A pair (``credit`` against the round's reference) earns its parameters: by the
    rule of a single effect (:func:`~boucwen.diagnosis.credit.earns`), and its
    cross-validated RMS error is at most ``1 − min_gain`` times the lower of its members'
    single trials (``alone``): each member must add to the other (a ratio within
    ``close_rel`` of that is a close call: not beyond)."""
    least = min(c.cv_rms_um for c in alone)
    beyond = least > 0 and at_most(
        credit.cv_rms_um / least, 1.0 - policy.min_gain, policy.close_rel, f"{what}: beyond either alone", calls
    )
    return beyond and earns(credit, policy, calls, what)


def _credit(trial: Trial) -> Credit:
    if trial.credit is None:  # pragma: no cover - the pool holds credited trials only
        raise ValueError(f"{trial.name}: no credit")
    return trial.credit


def pair_round(
    record: Record,
    current: ExtendedFit,
    round_: Round,
    *,
    noise_um: float,
    policy: DiagnosisPolicy,
    workers: int | None,
    say: Callable[[str], None],
    calls: CloseCalls | None = None,
) -> Round | None:
    """Effects that explain only together, where none earns alone (a gain drift beside
    electrostriction: each alone bends the hysteresis to take the other's share). The
    effects of :func:`pair_pool` are added two at a time, each at its single trial's fit,
    and refitted with the null trial's effort, side by side on the ``workers`` threads.
    The pair of largest credit against the round's reference that earns its parameters
    by the rule of a single effect and cuts the cross-validated error of each of its
    members' single trials by ``min_gain`` is kept; the backward step then asks each to
    earn its place beside the other (``noise_um``: the record's noise [µm]). Adds the
    pairs' credits to ``round_``'s evidence (``pairs``); returns the round with the pair
    kept, or None when none earns."""
    trials, ref, null = round_.trials, round_.reference, round_.null
    if ref is None or null is None:
        return None
    pool = pair_pool(trials, round_.evidence["lookalike_barred"], policy)
    effort = null_effort(policy)

    def fitted(pair: tuple[str, str]) -> tuple[Scored, float] | None:
        """The pair added at its members' single fits, refitted and scored; seconds taken."""
        t0 = time.perf_counter()
        a, b = pair
        fits = {k: round_.evidence["trials"][k]["fitted"] for k in pair}
        both = set_of({**params_of(current.effects), a: fits[a], b: fits[b]})
        try:
            solved = solve_extended_record(
                record, current.params, both, current.h0, max_nfev=effort, tol=policy.trial_tol
            )
        except ValueError:
            return None
        return score(record, solved, policy.folds), time.perf_counter() - t0

    pairs = list(itertools.combinations(pool, 2))
    ref_in_sample = min(ref.cv.in_sample_rms_um, null.cv.in_sample_rms_um)
    credits: dict[str, Credit] = {}
    earning: list[tuple[str, Scored]] = []
    for (a, b), outcome in zip(pairs, thread_map(fitted, pairs, workers)):
        if outcome is None:
            continue
        scored, took = outcome
        pair = f"{a}+{b}"
        c = credits[pair] = credit_of(scored.cv, scored.x, ref.cv, ref.x, ref_in_sample, noise_um, policy)
        say(
            f"  + {pair}: CV RMS {scored.cv.rms_um:.4g} µm (over the null {c.gain_over_null:+.1%}, "
            f"where they act {c.local_gain:+.1%}; {took:.1f} s)"
        )
        if pair_earns(c, (_credit(trials[a]), _credit(trials[b])), policy, calls, pair):
            earning.append((pair, scored))
    round_.evidence["pairs"] = {k: c.to_dict() for k, c in credits.items()}
    if not earning:
        return None
    # Pairs whose credits tie within the margin: the one listed first.
    best = earning[
        first_of_best(
            earning,
            lambda e: credits[e[0]].gain_over_null,
            higher=True,
            margin=policy.close_gain,
            relative=False,
            decision="the pair that explains most",
            calls=calls,
            name=lambda e: e[0],
        )
    ]
    return Round(
        evidence={**round_.evidence, "most_likely": best[0], "kept": True},
        trials=round_.trials,
        kept=best[1].fit,
        ranked=[(best[0], best[1].fit)],
        kept_jacobian=best[1].jacobian,
        null=null,
        reference=ref,
    )
