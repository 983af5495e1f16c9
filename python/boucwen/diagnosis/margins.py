"""Decisions with margins: a choice closer than the arithmetic can tell is made by a
stated rule, and recorded.

The diagnosis decides by comparing numbers that come out of fits: a credit against a
threshold, two credits against each other, a trial's error against the null trial's,
the first-order costs of two starts. Those numbers carry the last bits of the
arithmetic that made them (the BLAS kernel the machine picks, its number of threads,
the order of a sum; a record read back from a CSV file with one digit fewer), and a
fit that stops in a long, flat valley carries them further. A choice whose two sides
are closer than that could go either way on another machine.

So every such comparison is made with a margin. Where the two sides lie within it the
choice is *close*: it is not left to the last bits but made by the rule stated at each
call, always the simpler side —

* an effect does not earn its parameters (the model without it is kept);
* of effects, or starts, that tie, the one listed first is taken (the vocabulary's
  fixed order; a trial's starts from the current model outward);
* a trial that ties with the null trial is no better than it;

and it is noted in :class:`CloseCalls`, which the report lists (``close_calls``), so
that a user sees which parts of the answer another machine could give differently.

The margins (:data:`CLOSE_GAIN`, :data:`CLOSE_REL`) are far above what floating-point
differences move those numbers by and far below what any decision is about: a credit is
a relative cut of an RMS error, and 1e-4 of an error of 20 nm is 2 pm, a hundredth of
the resolution of the best capacitive sensors.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any, TypeVar

__all__ = [
    "ANSWER",
    "CLOSE_GAIN",
    "CLOSE_REL",
    "PATH",
    "CloseCall",
    "CloseCalls",
    "Compare",
    "at_least",
    "at_most",
    "decide",
    "first_of_best",
]

#: Margin on a credit (a relative cut of an RMS error, so a fraction): two credits, or
#: a credit and its threshold, closer than this are a close call.
CLOSE_GAIN = 1e-4
#: Relative margin on an error [µm] (or a first-order cost): two errors within this
#: fraction of the larger are a close call.
CLOSE_REL = 1e-4

T = TypeVar("T")


#: A close call on what the answer holds: an effect kept or not, which one, a swap.
ANSWER = "answer"
#: A close call on a trial's way there: its start, whether it goes on after a stage.
PATH = "path"


@dataclass(frozen=True)
class CloseCall:
    """A choice closer than its margin, decided by the margin rule.

    Attributes:
        decision: what was decided.
        value, against: the two numbers compared (in the decision's unit).
        chose: what the rule chose.
        kind: :data:`ANSWER` (what the answer holds) or :data:`PATH` (a trial's way there).
    """

    decision: str
    value: float
    against: float
    chose: str
    kind: str = ANSWER

    def to_dict(self) -> dict[str, Any]:
        """``{"decision", "value", "against", "chose", "kind"}`` (JSON-ready)."""
        return asdict(self)


class CloseCalls:
    """The close calls of one diagnosis (thread-safe: the trials of a round run side by
    side): each a :class:`CloseCall`."""

    def __init__(self) -> None:
        self._items: list[CloseCall] = []
        self._lock = threading.Lock()

    def note(self, decision: str, value: float, against: float, chose: str, kind: str = ANSWER) -> None:
        """Records one close call."""
        call = CloseCall(decision, float(value), float(against), chose, kind)
        with self._lock:
            self._items.append(call)

    def to_list(self) -> list[dict[str, Any]]:
        """The calls so far as dicts (:meth:`CloseCall.to_dict`), sorted by decision (the
        order of threads is not the record's)."""
        with self._lock:
            calls = sorted(self._items, key=lambda c: (c.decision, c.value, c.against))
        return [c.to_dict() for c in calls]

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)


class Compare:
    """Comparisons with a margin, read one way: ``strict`` takes a value within the
    margin of its threshold as failing the comparison, otherwise as passing it. A rule
    written so that passing comparisons lead to the more complex side, evaluated both
    ways (:func:`decide`), tells whether a close comparison decided it; the comparisons
    that were close are kept in ``close``."""

    def __init__(self, strict: bool) -> None:
        self.strict = strict
        self.close: list[tuple[float, float]] = []

    def ge(self, value: float, threshold: float, margin: float = CLOSE_GAIN) -> bool:
        """``value ≥ threshold``, a value within ``margin`` of it read as this compare says."""
        if abs(value - threshold) < margin:
            self.close.append((value, threshold))
            return not self.strict
        return value >= threshold

    def le(self, value: float, threshold: float, margin: float = CLOSE_GAIN) -> bool:
        """``value ≤ threshold``, a value within ``margin`` of it read as this compare says."""
        if abs(value - threshold) < margin:
            self.close.append((value, threshold))
            return not self.strict
        return value <= threshold


def decide(
    rule: Callable[[Compare], bool],
    decision: str,
    calls: CloseCalls | None,
    *,
    yes: str = "yes",
    no: str = "no",
    kind: str = ANSWER,
) -> bool:
    """``rule`` evaluated with its comparisons read strictly and leniently; where the two
    differ the decision is close: it is False (the simpler side, ``rule`` being the
    condition for the more complex one) and noted in ``calls`` as ``decision`` of
    ``kind`` (``yes``/``no`` name the two sides in the record)."""
    strict, lenient = Compare(strict=True), Compare(strict=False)
    outcome = rule(strict)
    if outcome == rule(lenient):
        return outcome
    if calls is not None:
        value, against = strict.close[0]
        calls.note(decision, value, against, no, kind)
    return False


def at_least(
    value: float, threshold: float, margin: float, decision: str, calls: CloseCalls | None, kind: str = ANSWER
) -> bool:
    """``value ≥ threshold`` as one decision (:func:`decide`): False where close."""
    return decide(lambda c: c.ge(value, threshold, margin), decision, calls, kind=kind)


def at_most(
    value: float, threshold: float, margin: float, decision: str, calls: CloseCalls | None, kind: str = ANSWER
) -> bool:
    """``value ≤ threshold`` as one decision (:func:`decide`): False where close."""
    return decide(lambda c: c.le(value, threshold, margin), decision, calls, kind=kind)


def first_of_best(
    items: Sequence[T],
    score: Callable[[T], float],
    *,
    higher: bool,
    margin: float,
    relative: bool,
    decision: str,
    calls: CloseCalls | None,
    name: Callable[[T], str] = str,
    kind: str = ANSWER,
) -> int:
    """Index of the best of ``items`` by ``score`` (the highest when ``higher``), where
    those within ``margin`` of the best (relative to its magnitude when ``relative``)
    tie and the first listed of them wins; a tie is noted in ``calls``. ``items`` must
    not be empty."""
    values = [float(score(it)) for it in items]
    best = max(values) if higher else min(values)
    width = margin * abs(best) if relative else margin
    tied = [k for k, v in enumerate(values) if abs(v - best) <= width]
    chosen = tied[0]
    if len(tied) > 1 and calls is not None:
        other = next(k for k in tied if k != chosen)
        calls.note(decision, values[chosen], values[other], name(items[chosen]), kind)
    return chosen
