"""How sure the diagnosis is of each effect it names.

An effect in the returned model is

* ``confident`` when its last credit (the backward step's where there was one, else
  the round's that kept it) gains in every fold of the cross-validation; no other
  effect left out of the model also earned its parameters in the round that kept it
  (the record explains itself two ways and the ranking chose), unless a look-alike
  test (:data:`~boucwen.diagnosis.lookalike.GROUPS`) named this one over it; no
  look-alike of its group earned a credit within the look-alike margin of its own;
  no close call (:mod:`~boucwen.diagnosis.margins`) concerned it; and the effects
  explain the record to its noise (``explained``);
* ``tentative`` otherwise, with the reason and, where there is one, the competing
  explanation named.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from .lookalike import GROUPS, named

__all__ = ["confidence"]


def _kept_credit(name: str, evidence: dict[str, Any]) -> tuple[dict[str, Any] | None, dict[str, Any] | None]:
    """The credit that last kept ``name`` and the round that kept it (None where not found)."""
    for round_ in evidence.get("rounds", []):
        kept = round_.get("most_likely")
        if not round_.get("kept") or kept is None:
            continue
        members = kept.split("+")
        if name in members:
            credit = round_["pairs"][kept] if len(members) > 1 else round_["trials"].get(name)
            return credit, round_
    return None, None


def _separated(name: str, other: str, round_: dict[str, Any]) -> bool:
    """A look-alike test of ``round_`` names ``name`` where it chooses between the two."""
    tests = round_.get("lookalike", {})
    return any(
        name in members and other in members and test in tests and named(tests[test], (name, other)) == name
        for test, members in GROUPS.items()
    )


def _rival(
    name: str,
    gain: float,
    round_: dict[str, Any],
    margin: float,
    model: Sequence[str],
    earns: Callable[[dict[str, Any]], bool],
) -> str | None:
    """The competing explanation of ``name`` in the round that kept it: a look-alike
    whose credit came within ``margin`` of ``gain``, or the effect of largest credit
    that also earned its parameters (``earns``) and is not in the ``model``, where no
    look-alike test separated the two."""
    for members in GROUPS.values():
        if name not in members:
            continue
        for other in members:
            trial = round_["trials"].get(other, {})
            if other != name and "gain_over_null" in trial and trial["gain_over_null"] > gain - margin:
                return str(other)
    others = [
        (t["gain_over_null"], k)
        for k, t in round_["trials"].items()
        if k != name and k not in model and "gain_over_null" in t and earns(t) and not _separated(name, k, round_)
    ]
    return str(max(others)[1]) if others else None


def _concerns(call: dict[str, Any], name: str) -> bool:
    """A close call is about ``name``: it names the effect before its colon, or chose it."""
    subject = call["decision"].split(":")[0].replace("+", " ").split()
    return name in subject or call["chose"] == name


def confidence(
    names: Sequence[str],
    evidence: dict[str, Any],
    margin: float,
    explained: float | None = None,
    earns: Callable[[dict[str, Any]], bool] = lambda _trial: False,
) -> dict[str, dict[str, Any]]:
    """Per effect in ``names``: ``{"level": "confident" | "tentative", "why": str,
    "competing": str | None}``, read from the diagnosis's ``evidence`` (``margin``: the
    look-alike margin on credits). ``explained``: the share of the error beyond the
    noise the effects explain, where what they leave is not noise and that share is
    small (they may stand in for an effect outside the vocabulary): each is tentative.
    ``earns``: the acceptance rule on a trial's credit (competing explanations)."""
    out: dict[str, dict[str, Any]] = {}
    calls = evidence.get("close_calls", [])
    for name in names:
        credit, round_ = _kept_credit(name, evidence)
        last = evidence.get("pruned", {}).get(name, credit)
        why: list[str] = []
        competing = None
        if last is None or round_ is None:
            why.append("no credit recorded")
        else:
            if not min(last["fold_gains"]) > 0:
                why.append("does not gain in every fold")
            gain = float(credit["gain_over_null"]) if credit else 0.0
            competing = _rival(name, gain, round_, margin, names, earns)
            if competing is not None:
                why.append(f"{competing} also explains the record (it earned its parameters in the same round)")
        close = [c["decision"] for c in calls if _concerns(c, name)]
        if close:
            why.append("close call: " + "; ".join(close))
        if explained is not None:
            why.append(f"the effects explain {explained:.0%} of the error beyond the noise; the rest is unexplained")
        out[name] = {
            "level": "tentative" if why else "confident",
            "why": "; ".join(why) if why else "gains in every fold, no look-alike near it",
            "competing": competing,
        }
    return out
