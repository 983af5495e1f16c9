"""The backward step: each effect kept is asked to earn its place beside those kept
after it, and a look-alike kept before its partner is swapped for the one the group's
test names (:func:`backward_step`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .._core import EffectSet
from ..effects import ExtendedFit, effect_class, solve_extended_record
from ..effects.base import without
from ..record import Record
from .credit import Credit, credit_of, earns
from .lookalike import GROUPS, TESTS, named
from .margins import CloseCalls, at_least, first_of_best
from .policy import DiagnosisPolicy
from .scoring import Scored, refit_basis, score
from .screening import screenable
from .starts import null_effort, ranked_starts
from .trial import trial_fit
from .unexplained import noise_level

__all__ = ["backward_step", "look_alike_swap", "swap_group", "takes_place"]


def _credit(model: Scored, rest: Scored, noise_um: float, policy: DiagnosisPolicy) -> Credit:
    """The credit of ``model`` against ``rest`` (the others refitted without an effect)."""
    return credit_of(model.cv, model.x, rest.cv, rest.x, rest.cv.in_sample_rms_um, noise_um, policy)


def backward_step(
    record: Record,
    screen: Record,
    current: ExtendedFit,
    added: list[str],
    evidence: dict[str, Any],
    *,
    null: Scored | None,
    policy: DiagnosisPolicy,
    workers: int | None,
    say: Callable[[str], None],
    calls: CloseCalls | None = None,
) -> tuple[ExtendedFit, list[str]]:
    """Each effect kept, in the order kept, is taken out and the others refitted with
    the null trial's effort; one that the model with it, refitted alike, does not earn
    against that refit by the rule that kept it was a passenger (a look-alike kept first
    whose work a later effect does, or an effect credited with what those kept before it
    had not yet converged to) and is dropped. One that earns its place may still be a
    look-alike of the right effect, kept before its partner was in the model: it is
    swapped where :func:`look_alike_swap` finds the other. On the screened copy when the
    model can be simulated there (else on the record). A partner is not taken out while
    the effect tried beside it is in. ``null``: the model with them all so refitted, on
    the copy used, when the last round has it. Returns the model and the effects left;
    ``evidence["pruned"]`` gets each credit (and any swap)."""
    simulable = screenable(current, screen)
    on = screen if simulable else record
    effort = null_effort(policy)

    def refit(effects: EffectSet) -> Scored:
        solved = solve_extended_record(on, current.params, effects, current.h0, max_nfev=effort)
        return score(on, solved, policy.folds)

    full = null if null is not None and simulable else refit(current.effects)
    noise_um = noise_level(on.x).sigma_um
    credits: dict[str, Any] = {}
    for name in list(added):
        if any(effect_class(k).partner == name for k in current.effects.names):
            continue
        rest = refit(without(current.effects, name))
        c = _credit(full, rest, noise_um, policy)
        credits[name] = c.to_dict()
        say(
            f"  backward {name:9s}: over the others refitted without it {c.gain_over_null:+.1%}, "
            f"where it acts {c.local_gain:+.1%}"
        )
        if not earns(c, policy, calls, f"backward {name}"):
            say(f"dropped {name}: it does not earn its parameters beside the effects kept after it")
            current, full = rest.fit, rest
            added = [k for k in added if k != name]
            continue
        swap = look_alike_swap(
            on,
            name,
            rest,
            c,
            full_rate=on is record,
            every=screen is record,
            policy=policy,
            workers=workers,
            calls=calls,
        )
        if swap is not None:
            other, scored, c_other, said = swap
            credits[name]["swapped_for"] = {other: {**c_other.to_dict(), "test_named": said}}
            say(
                f"swapped {name} for {other}, which earns {c_other.gain_over_null:+.1%} in its place "
                f"({name}: {c.gain_over_null:+.1%}; the look-alike test names {said})"
            )
            current, full = scored.fit, scored
            added = [other if k == name else k for k in added]
    evidence["pruned"] = credits
    return current, added


def swap_group(name: str, full_rate: bool) -> tuple[str, tuple[str, ...]] | None:
    """The look-alike test and the members ``name`` may be swapped for: those of its
    group that are :attr:`~boucwen.effects.Effect.swappable`, where it is one; a group
    holding an effect of whole samples of the record's rate only on the record itself
    (``full_rate``), not on a screened copy. None where it is not swapped (a mode: its
    peak is its own evidence)."""
    if not effect_class(name).swappable:
        return None
    for test, members in GROUPS.items():
        if name in members:
            group = tuple(k for k in members if effect_class(k).swappable)
            if full_rate or not any(effect_class(k).full_rate_only for k in group):
                return test, group
    return None


def takes_place(
    other: Credit,
    kept: Credit,
    named_by_test: bool,
    policy: DiagnosisPolicy,
    calls: CloseCalls | None = None,
    what: str = "",
) -> bool:
    """A look-alike (credit ``other``) takes the place of a kept effect (credit ``kept``,
    both against the others refitted without it): it earns its parameters, and its
    credit is at least the kept one's, or, where the group's test names it
    (``named_by_test``), within ``lookalike_margin`` below (a credit within
    ``close_gain`` of that floor is a close call, noted as ``what``: it does not take the
    place)."""
    floor = kept.gain_over_null - (policy.lookalike_margin if named_by_test else 0.0)
    takes = at_least(other.gain_over_null, floor, policy.close_gain, what, calls)
    return earns(other, policy, calls, what) and takes


def look_alike_swap(
    on: Record,
    name: str,
    rest: Scored,
    credit: Credit,
    *,
    full_rate: bool,
    every: bool,
    policy: DiagnosisPolicy,
    workers: int | None,
    calls: CloseCalls | None = None,
) -> tuple[str, Scored, Credit, str] | None:
    """For a kept ``name`` (credited with ``credit`` against ``rest``, the others
    refitted without it) of a swappable group (:func:`swap_group`): the look-alike that
    the group's test names on the residual of ``rest``, tried in its place from
    ``rest`` like a trial, with its scored fit, credit and what the test named, where it
    earns its parameters and its credit is within ``lookalike_margin`` of ``name``'s or
    above; else None. With ``every`` (a record short enough not to be screened) each
    other member of the group is tried too, and one the test does not name takes the
    place only with a credit above ``name``'s; the best credit wins."""
    found = swap_group(name, full_rate)
    if found is None:
        return None
    test, group = found
    said = named(TESTS[test](on, rest.x), group)
    others = [k for k in group if k != name and k not in rest.fit.effects.names and (every or k == said)]
    basis = refit_basis(rest.jacobian) if others else None
    noise_um = noise_level(on.x).sigma_um
    earning: list[tuple[str, Scored, Credit, str]] = []
    for other in others:
        fr = trial_fit(
            other,
            on,
            rest.fit,
            lambda: rest.fit,
            lambda n: ranked_starts(n, on, rest.fit, basis, workers, policy, calls),
            workers=workers,
            policy=policy,
            basis=basis,
            calls=calls,
        )
        if isinstance(fr, str):
            continue
        scored = score(on, fr, policy.folds)
        c = _credit(scored, rest, noise_um, policy)
        if takes_place(c, credit, other == said, policy, calls, f"{other} in place of {name}"):
            earning.append((other, scored, c, said))
    if not earning:
        return None
    return earning[
        first_of_best(
            earning,
            lambda e: e[2].gain_over_null,
            higher=True,
            margin=policy.close_gain,
            relative=False,
            decision=f"the look-alike in place of {name}",
            calls=calls,
            name=lambda e: e[0],
        )
    ]
