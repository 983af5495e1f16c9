"""How sure the diagnosis is of each effect it names.

An effect in the returned model is

* ``confident`` when its last credit (the backward step's where there was one, else
  the round's that kept it) gains in every fold of the cross-validation, no
  look-alike of its group (:data:`~boucwen.diagnosis.lookalike.GROUPS`) earned a
  credit within :data:`~boucwen.diagnosis.search.LOOKALIKE_MARGIN` of its own in that
  round, and no close call (:mod:`~boucwen.diagnosis.margins`) concerned it;
* ``tentative`` otherwise, with the reason and, where there is one, the competing
  explanation named.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .lookalike import GROUPS

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


def _rival(name: str, gain: float, round_: dict[str, Any], margin: float) -> str | None:
    """A look-alike of ``name`` whose credit in ``round_`` came within ``margin`` of ``gain``."""
    for members in GROUPS.values():
        if name not in members:
            continue
        for other in members:
            trial = round_["trials"].get(other, {})
            if other != name and "gain_over_null" in trial and trial["gain_over_null"] > gain - margin:
                return str(other)
    return None


def _concerns(call: dict[str, Any], name: str) -> bool:
    """A close call is about ``name``: it names the effect before its colon, or chose it."""
    subject = call["decision"].split(":")[0].replace("+", " ").split()
    return name in subject or call["chose"] == name


def confidence(
    names: Sequence[str], evidence: dict[str, Any], margin: float, explained: float | None = None
) -> dict[str, dict[str, Any]]:
    """Per effect in ``names``: ``{"level": "confident" | "tentative", "why": str,
    "competing": str | None}``, read from the diagnosis's ``evidence`` (``margin``: the
    look-alike margin on credits). ``explained``: the share of the error beyond the
    noise the effects explain, where what they leave is not noise and that share is
    small (they may stand in for an effect outside the vocabulary): each is tentative."""
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
            competing = _rival(name, float(credit["gain_over_null"]) if credit else 0.0, round_, margin)
            if competing is not None:
                why.append(f"{competing} earned nearly as much")
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
