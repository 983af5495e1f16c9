"""One round of the search: every candidate effect tried beside the null trial, each
credited against the better of the two, and the one kept (:func:`score_round`)."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

from .._core import RESONANCE_SUBSTEPS, EffectSet
from ..effects import VOCABULARY, ExtendedFit, Solved, effect_class, solve_extended_record
from ..lsq import worker_threads
from ..record import Record
from .credit import Credit, credit_of, earns
from .lookalike import GROUPS, lookalike_tests, named
from .margins import CloseCalls, at_most, first_of_best
from .policy import DiagnosisPolicy
from .scoring import Scored, refit_basis, score, solved_at
from .starts import null_effort, ranked_starts
from .trial import joint_partner, trial_fit
from .unexplained import noise_level

__all__ = ["Round", "Trial", "barred", "beyond_partner", "candidates", "lookalike_order", "pass_cost", "score_round"]


@dataclass(frozen=True, eq=False)
class Trial:
    """One effect tried in a round: its scored fit and credit, or why there is none.

    Attributes:
        name: the effect (``a+b`` for a pair).
        scored: the fit and its cross-validation, or None.
        credit: its credit against the round's reference, or None.
        rejected: why the trial gave no candidate (hopeless, no peak, cannot be fitted).
    """

    name: str
    scored: Scored | None = None
    credit: Credit | None = None
    rejected: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The trial as the report holds it: the credit and the effect's fitted
        parameters, or ``{"rejected": why}``."""
        if self.credit is None or self.scored is None:
            return {"rejected": self.rejected}
        return {**self.credit.to_dict(), "fitted": self.scored.fit.effects.to_dict().get(self.name)}


@dataclass(frozen=True, eq=False)
class Round:
    """One round of the search (:func:`score_round`).

    Attributes:
        evidence: the round's JSON evidence: ``current`` and ``null`` (their
            cross-validated errors), ``reference_rms_um`` (the lower of the two, the one
            each effect is credited against), ``trials`` (per effect, :meth:`Trial.to_dict`),
            ``competing`` (the candidates, best first), ``lookalike`` (the tests on the
            current residual), ``lookalike_decision``, ``lookalike_refused``,
            ``lookalike_barred``, where no effect earned alone the ``pairs`` tried,
            ``most_likely`` and ``kept``.
        trials: the trials, by effect.
        kept: the fit of the kept effect, or None.
        ranked: the candidates that earn their parameters, best first, with their fits.
        kept_jacobian: ∂x̂/∂z of ``kept`` over the round's record, or None.
        null: the null trial, scored over the round's record.
        reference: the better of the current model and the null trial, scored.
    """

    evidence: dict[str, Any]
    trials: dict[str, Trial]
    kept: ExtendedFit | None
    ranked: list[tuple[str, ExtendedFit]]
    kept_jacobian: Any = None
    null: Scored | None = None
    reference: Scored | None = None


def candidates(present: Sequence[str]) -> tuple[str, ...]:
    """The effects of the vocabulary a round tries beside those ``present``: every one
    not yet in the model."""
    return tuple(n for n in VOCABULARY if n not in present)


def barred(lookalike: dict[str, Any], present: set[str]) -> dict[str, str]:
    """The effects a look-alike in the model bars, with why: in a group of look-alikes
    (:data:`~boucwen.diagnosis.lookalike.GROUPS`) with a member ``present`` that bars
    the others (:attr:`~boucwen.effects.Effect.bars_lookalikes`), every other member but
    the one the group's test (``lookalike``) names on the current residual. A test that
    names none bars them only beside a member that bars also then
    (:attr:`~boucwen.effects.Effect.bars_when_undecided`)."""
    out = {}
    for test, members in GROUPS.items():
        here = [k for k in members if k in present]
        if not any(effect_class(k).bars_lookalikes for k in here):
            continue
        said = named(lookalike[test])
        if said != "none" or any(effect_class(k).bars_when_undecided for k in here):
            for k in members:
                if k != said and k not in present:
                    out[k] = f"a look-alike is in the model and the {test!r} test names {said!r}"
    return out


def beyond_partner(
    joint: Credit, partner: Credit, policy: DiagnosisPolicy, calls: CloseCalls | None = None, what: str = ""
) -> bool:
    """A joint trial (an effect added with its partner, :attr:`~boucwen.effects.Effect.partner`)
    earns its further parameters only beyond the partner alone: its cross-validated RMS
    error at most ``1 − min_gain`` times the partner's (a ratio within ``close_rel`` of
    that is a close call, noted as ``what``: not beyond)."""
    ratio = joint.cv_rms_um / partner.cv_rms_um if partner.cv_rms_um > 0 else math.inf
    return at_most(ratio, 1.0 - policy.min_gain, policy.close_rel, what, calls)


def lookalike_order(
    earning: list[str], credits: dict[str, Credit], lookalike: dict[str, Any], policy: DiagnosisPolicy
) -> tuple[list[str], dict[str, Any] | None]:
    """The effects that earn (best first) with the first two swapped where their credits
    differ by less than ``lookalike_margin``, both are of one look-alike group and the
    group's test (``lookalike``: :func:`~boucwen.diagnosis.lookalike.lookalike_tests`)
    names the second; a test that cannot choose (``"none"``, a lag the phase cannot tell
    from a delay) leaves the order to the credits. Returns the order and the decision
    (``{"test", "between", "chose"}``, or None where the test did not reorder)."""
    order = list(earning)
    if len(order) < 2:
        return order, None
    a, b = order[0], order[1]
    if not credits[a].gain_over_null - credits[b].gain_over_null < policy.lookalike_margin:
        return order, None
    for test, members in GROUPS.items():
        if a in members and b in members and named(lookalike[test], (a, b)) == b:
            order[0], order[1] = b, a
            return order, {"test": test, "between": [a, b], "chose": b}
    return order, None


def pass_cost(name: str) -> int:
    """Relative cost of a pass of the model with the effect ``name`` added: a mode
    makes the core run the chain on :data:`~boucwen._core.RESONANCE_SUBSTEPS`
    sub-intervals per sample."""
    return RESONANCE_SUBSTEPS if effect_class(name).substepped else 1


def score_round(
    record: Record,
    current: ExtendedFit,
    *,
    policy: DiagnosisPolicy,
    names: tuple[str, ...] | None = None,
    workers: int | None = None,
    say: Callable[[str], None] | None = None,
    trial_nfev: int | None = None,
    starts: dict[str, ExtendedFit] | None = None,
    current_jacobian: Any = None,
    calls: CloseCalls | None = None,
) -> Round:
    """Tries every effect of the vocabulary not yet in ``current`` (or those in
    ``names``) on ``record``: each trial (:func:`~boucwen.diagnosis.trial.trial_fit`, or
    from ``starts`` in one stage of the null trial's effort) beside the null trial,
    every model scored by blocked cross-validation, each effect credited against the
    better of the current model and the null trial (:mod:`~boucwen.diagnosis.credit`).
    Of those that earn their parameters the one of largest credit is kept: credits tied
    within the margin go to the first in the vocabulary, a look-alike in the model bars
    the others (:func:`barred`), a joint trial earns only beyond its partner alone by
    ``min_gain``, and two look-alikes within ``lookalike_margin`` are told apart by
    their group's test. ``trial_nfev`` overrides the policy's (a confirmation);
    ``current_jacobian``: ∂x̂/∂z of ``current`` over ``record`` when known.

    The null trial and the trials run side by side on ``workers`` threads (a trial only
    waits for the null trial's error at the end of its first stage), each printing its
    progress line when it ends; the result does not depend on their order."""
    if trial_nfev is not None:
        policy = policy.replace(trial_nfev=trial_nfev)
    note = say if say is not None else (lambda _msg: None)
    lock = threading.Lock()

    def tell(message: str) -> None:
        with lock:
            note(message)

    folds = policy.folds
    scored_cur = score(record, solved_at(record, current, current_jacobian), folds)
    cur_cv = scored_cur.cv
    basis = refit_basis(scored_cur.jacobian)
    null_nfev = null_effort(policy)
    noise_um = noise_level(record.x).sigma_um

    def null_trial() -> Scored:
        null = solve_extended_record(record, current.params, current.effects, current.h0, max_nfev=null_nfev)
        scored = score(record, null, folds)
        gain = 1.0 - scored.cv.rms_um / cur_cv.rms_um if cur_cv.rms_um > 0 else 0.0
        tell(f"  0 null     : CV RMS {scored.cv.rms_um:.4g} µm (current {cur_cv.rms_um:.4g} µm, gain {gain:+.1%})")
        return scored

    def reference() -> Scored:
        """The better of the current model and the null trial (the current model where
        the two tie within the margin)."""
        scored_null = null_run.result()
        return scored_null if scored_null.cv.rms_um < (1.0 - policy.close_rel) * cur_cv.rms_um else scored_cur

    def credited(scored: Scored) -> Credit:
        ref = reference()
        in_sample = min(cur_cv.in_sample_rms_um, null_run.result().cv.in_sample_rms_um)
        return credit_of(scored.cv, scored.x, ref.cv, ref.x, in_sample, noise_um, policy)

    # The starts of each effect, ranked once per round (a joint trial ranks its
    # partner's starts as the partner's trial does: whichever comes second waits).
    rank_locks = {name: threading.Lock() for name in VOCABULARY}
    rankings: dict[str, tuple[list[EffectSet], float]] = {}

    def starts_of(name: str) -> tuple[list[EffectSet], float]:
        with rank_locks[name]:
            if name not in rankings:
                rankings[name] = ranked_starts(name, record, current, basis, workers, policy, calls)
            return rankings[name]

    def trial(name: str) -> Trial:
        t0 = time.perf_counter()
        fr: Solved | str
        if starts is not None and name in starts:
            s = starts[name]
            fr = solve_extended_record(record, s.params, s.effects, s.h0, max_nfev=null_nfev, tol=policy.trial_tol)
        else:
            fr = trial_fit(
                name,
                record,
                current,
                lambda: null_run.result().fit,
                starts_of,
                workers=workers,
                policy=policy,
                basis=basis,
                calls=calls,
            )
        if isinstance(fr, str):
            tell(f"  - {name:9s}: {fr} ({time.perf_counter() - t0:.1f} s)")
            return Trial(name, rejected=fr)
        scored = score(record, fr, folds)
        c = credited(scored)
        tell(
            f"  + {name:9s}: CV RMS {scored.cv.rms_um:.4g} µm (over the null {c.gain_over_null:+.1%}, "
            f"where it acts {c.local_gain:+.1%}; {time.perf_counter() - t0:.1f} s)"
        )
        return Trial(name, scored=scored)

    todo = names if names is not None else candidates(current.effects.names)
    null_run: Future[Scored]
    with worker_threads(workers) as pool:
        if pool is None:
            null_run = Future()
            null_run.set_result(null_trial())
            outcomes = [trial(name) for name in todo]
        else:
            null_run = pool.submit(null_trial)  # first in the queue: started before any trial waits for it
            # The costliest trials start first, so that none is left running alone at
            # the end; the outcomes are read in the order of ``todo``.
            running = {name: pool.submit(trial, name) for name in sorted(todo, key=lambda k: -pass_cost(k))}
            outcomes = [running[name].result() for name in todo]
    scored_null = null_run.result()
    null_gain = 1.0 - scored_null.cv.rms_um / cur_cv.rms_um if cur_cv.rms_um > 0 else 0.0
    reference_fit = reference()
    trials = {t.name: t if t.scored is None else Trial(t.name, t.scored, credited(t.scored)) for t in outcomes}
    credits = {k: t.credit for k, t in trials.items() if t.credit is not None}
    ranked = sorted(credits, key=lambda k: -credits[k].gain_over_null)
    earning = [k for k in ranked if earns(credits[k], policy, calls, k)]
    if earning:
        # Credits that tie within the margin: the effect first in the vocabulary.
        listed = [k for k in VOCABULARY if k in earning]
        top = listed[
            first_of_best(
                listed,
                lambda k: credits[k].gain_over_null,
                higher=True,
                margin=policy.close_gain,
                relative=False,
                decision="the effect that explains most",
                calls=calls,
            )
        ]
        earning = [top] + [k for k in earning if k != top]
    lookalike = lookalike_tests(record, reference_fit.x)
    present = set(current.effects.names)
    bars = barred(lookalike, present)
    refused = {k: why for k, why in bars.items() if k in earning}
    earning = [k for k in earning if k not in bars]
    for k in [k for k in VOCABULARY if k in earning]:
        partner = joint_partner(k, tuple(present))
        joint = effect_class(k).joint
        if partner is None or partner not in earning:
            continue
        if not beyond_partner(credits[k], credits[partner], policy, calls, f"{joint} beyond one"):
            earning.remove(k)
            refused[k] = f"{joint} fit no better than one by the least gain"
    earning, decision = lookalike_order(earning, credits, lookalike, policy)
    best = earning[0] if earning else (ranked[0] if ranked else None)
    keep = bool(earning)
    evidence = {
        "current": cur_cv.to_dict(),
        "null": {**scored_null.cv.to_dict(), "gain": null_gain},
        "reference_rms_um": reference_fit.cv.rms_um,
        "trials": {k: t.to_dict() for k, t in trials.items()},
        "competing": [
            {"effect": k, "cv_rms_um": credits[k].cv_rms_um, "gain_over_null": credits[k].gain_over_null}
            for k in ranked
        ],
        "lookalike": lookalike,
        "lookalike_decision": decision,
        "lookalike_refused": refused,
        "lookalike_barred": sorted(bars),
        "most_likely": best,
        "kept": keep,
    }
    kept = trials[best].scored if keep and best is not None else None
    return Round(
        evidence=evidence,
        trials=trials,
        kept=kept.fit if kept is not None else None,
        ranked=[(k, s.fit) for k in earning if (s := trials[k].scored) is not None],
        kept_jacobian=kept.jacobian if kept is not None else None,
        null=scored_null,
        reference=reference_fit,
    )
