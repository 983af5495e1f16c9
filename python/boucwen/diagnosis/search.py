"""The loop of moves: floating selection under one judge.

Each round proposes every move from the current model — **add** an effect of the
vocabulary it lacks (two effects that physics ties together, a second mode beside a
first, are added at once: ``add_tied``), **drop** one it holds, **swap** one it holds for
a rival the record could not tell it from — fits every candidate to convergence
(:mod:`~boucwen.diagnosis.fits`) and judges each against the current model
(:func:`~boucwen.diagnosis.judge.judge`). Then:

* an accepted drop is taken first (the model is simpler and predicts no worse): of
  several, the effect that earns least;
* else the accepted add or swap of largest held-out gain, through its **ambiguity set**:
  the candidates of the round that the record does not tell apart from it
  (:func:`~boucwen.diagnosis.judge.apart`). The model takes the accepted member with the
  fewest unknowns, then the first in the vocabulary; the others are its rivals, reported
  with their held-out errors, and proposed as swaps in the rounds that follow;
* nothing accepted, or a residual consistent with the record's noise
  (:func:`boucwen.residual.unexplained`), ends the search.

A model the search has already held is never proposed again (floating selection cannot
cycle). What the residual follows (the look-alike tests of
:mod:`boucwen.residual.lookalike`) is reported beside each set; it never decides.

**Screening** (records of more than :data:`SCREEN_MIN_SAMPLES` samples sampled faster
than :data:`SCREEN_RATE_HZ`) wraps the fits; it never decides. Every move is first fitted
on a copy of the record holding every q-th sample, against the current model refitted
there; the move the copy ranks best (least held-out error), every move the copy cannot
tell from it, and every move it sees any held-out gain from are then fitted on the full
record as without screening (from the full record's own starts: an effect's starts may
depend on the sampling interval, a creep's shortest time constant), and the judge
decides there. Moves the copy cannot hold — an effect of whole samples of the record's
rate (:attr:`boucwen.effects.Effect.full_rate_only`), a mode where the residual's
spectral peak lies above what the copy can hold, a move with no candidate on the copy,
any move from a model the copy cannot simulate — are fitted on the full record directly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from ..effects import FN_MAX_NYQUIST_FRACTION, VOCABULARY, effect_class, simulate_chain
from ..lsq import thread_map
from ..record import Record
from ..residual import lookalike_tests, unexplained
from ..residual.evidence import spectral_peak
from ..residual.lookalike import named
from .fits import Convergence, Scored, Structure, add, drop, oscillator, refit, scored, solved_at
from .judge import Decision, apart, gain, judge, threshold
from .policy import DiagnosisPolicy

__all__ = [
    "SCREEN_MIN_SAMPLES",
    "SCREEN_RATE_HZ",
    "Move",
    "Round",
    "Search",
    "proposals",
    "rival_order",
    "screen_copy",
    "search",
    "structure_move",
    "vocabulary_order",
]

#: Records longer than this [samples] are screened: a shorter one fits fast enough.
SCREEN_MIN_SAMPLES = 50_000
#: The screened copy's rate [Hz]: above every effect of the vocabulary but a delay and a
#: high mode (which the copy does not hold: module docs), ten times the bandwidth of the
#: fastest actuator drive the records are made with.
SCREEN_RATE_HZ = 2500.0


@dataclass(frozen=True)
class Move:
    """A move from the current model.

    Attributes:
        kind: ``"add"``, ``"add_tied"``, ``"drop"`` or ``"swap"``.
        adds: effects it adds (a tied pair: the partner first).
        drops: the effect it takes out, or None.
    """

    kind: str
    adds: tuple[str, ...] = ()
    drops: str | None = None

    @property
    def effects(self) -> tuple[str, ...]:
        """What the move concerns, as :attr:`Decision.effects` lists it."""
        return ((self.drops,) if self.drops else ()) + self.adds


@dataclass(frozen=True)
class Round:
    """One round of the search.

    Attributes:
        decisions: every move judged, in the order proposed.
        taken: the decision taken, or None (the search ends).
        ambiguity: the moves the record did not tell apart from the best one (the
            taken move among them), each with the candidate's held-out RMS [µm].
        rejected: moves with no candidate, and why (no start simulated, the fitted
            effect not what its name says).
        signatures: what the look-alike tests name on the current model's residual.
        screened: with screening, the decisions on the copy (which only choose what is
            fitted on the full record).
    """

    decisions: tuple[Decision, ...]
    taken: Decision | None
    ambiguity: tuple[tuple[Decision, float], ...]
    rejected: dict[str, str]
    signatures: tuple[str, ...]
    screened: tuple[Decision, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "decisions": [d.to_dict() for d in self.decisions],
            "taken": None if self.taken is None else self.taken.label,
            "ambiguity": [{"move": d.label, "cv_rms_um": e} for d, e in self.ambiguity],
            "rejected": dict(self.rejected),
            "signatures": list(self.signatures),
            "screened": [d.to_dict() for d in self.screened],
        }


@dataclass
class Search:
    """The state and history of the search.

    Attributes:
        current: the current model.
        rounds: every round so far.
        rivals: per effect of the model, the effects the record did not tell it from.
        swaps: the swaps of the current model for a rival fitted in the last round (by
            the set of effects of each), kept for the explanations the record could not
            tell apart (:mod:`~boucwen.diagnosis.experiment`).
        stopped: why the search ended.
    """

    current: Scored
    rounds: list[Round] = field(default_factory=list)
    rivals: dict[str, set[str]] = field(default_factory=dict)
    swaps: dict[frozenset[str], Scored] = field(default_factory=dict)
    stopped: str = ""


def vocabulary_order(names: tuple[str, ...]) -> tuple[int, ...]:
    """Sort key: each name's place in the vocabulary."""
    return tuple(VOCABULARY.index(k) for k in names)


def rival_order(name: str) -> tuple[int, str]:
    """Sort key of a rival: effects in the vocabulary's order, then another structure
    (the oscillator) by name."""
    return (VOCABULARY.index(name), "") if name in VOCABULARY else (len(VOCABULARY), name)


def proposals(names: tuple[str, ...], rivals: dict[str, set[str]], max_effects: int) -> list[Move]:
    """Every move from a model holding ``names`` (module docs)."""
    moves: list[Move] = []
    if len(names) < max_effects:
        for name in VOCABULARY:
            if name in names or not effect_class(name).proposed:
                continue
            partner = effect_class(name).partner
            if partner is None or partner in names:
                moves.append(Move("add", (name,)))
            elif len(names) + 2 <= max_effects:
                moves.append(Move("add_tied", (partner, name)))
    tied_to = {effect_class(k).partner for k in names}
    moves += [Move("drop", drops=k) for k in names if k not in tied_to]
    for k in names:
        for f in sorted(rivals.get(k, ()), key=rival_order):
            if f not in VOCABULARY:
                continue
            partner = effect_class(f).partner
            if f not in names and k not in tied_to and (partner is None or partner in names):
                moves.append(Move("swap", (f,), k))
    return moves


def _candidate(record: Record, current: Scored, move: Move, conv: Convergence, policy: DiagnosisPolicy) -> Scored | str:
    if move.kind == "drop":
        assert move.drops is not None
        return drop(record, current, move.drops, conv, policy.folds)
    return add(record, current, move.adds, conv, policy.folds, policy.max_delay_samples, dropped=move.drops)


def _decide(
    move: Move, fitted: Scored, current: Scored, t_min: float, noise_um: float, policy: DiagnosisPolicy
) -> Decision:
    """The judge's verdict on ``move``. A drop is judged the other way round: the effect
    keeps its place only where the current model is accepted against the model without
    it, so the drop is accepted where that fails."""
    folds, batches = policy.folds, policy.batches
    added = fitted.unknowns - current.unknowns
    if move.kind != "drop":
        g = gain(fitted.cv, current.cv, folds, batches)
        return judge(
            move.kind,
            move.effects,
            fitted.names,
            current.names,
            g,
            t_min=t_min,
            noise_um=noise_um,
            min_share=policy.min_share,
            unknowns=added,
        )
    keep = judge(
        "add",
        move.effects,
        current.names,
        fitted.names,
        gain(current.cv, fitted.cv, folds, batches),
        t_min=t_min,
        noise_um=noise_um,
        min_share=policy.min_share,
        unknowns=-added,
    )
    reason = ("it no longer earns its place: " if not keep.accepted else "it earns its place: ") + keep.reason
    g = gain(fitted.cv, current.cv, folds, batches)
    return Decision(
        "drop", move.effects, fitted.names, current.names, g, t_min, keep.needed_um2, not keep.accepted, reason, added
    )


def screen_copy(record: Record) -> Record | None:
    """The record's screened copy (every q-th sample, about :data:`SCREEN_RATE_HZ`), or
    None where the record is not screened."""
    q = int(1.0 / (record.dt * SCREEN_RATE_HZ))
    return record.decimated(q) if len(record) > SCREEN_MIN_SAMPLES and q >= 2 else None


def _full_only(move: Move, record: Record, current: Scored, copy: Record) -> bool:
    """The copy cannot hold ``move`` (module docs)."""
    if any(effect_class(k).full_rate_only for k in move.adds):
        return True
    if any(effect_class(k).signature == "peak" for k in move.adds):
        peak = spectral_peak(record.x - current.x, record.dt)["peak_hz"]
        return bool(peak > FN_MAX_NYQUIST_FRACTION / copy.dt)
    return False


def _on_copy(copy: Record | None, current: Scored, conv: Convergence, folds: int) -> Scored | None:
    """The current model refitted and scored on the copy, or None where the copy cannot
    hold it."""
    if copy is None or any(effect_class(k).full_rate_only for k in current.names):
        return None
    fit = current.fit
    if simulate_chain(fit.params, fit.effects, copy.u, copy.dt, fit.h0) is None:
        return None
    moved = refit(copy, fit, fit.effects, conv)
    return None if moved is None else scored(copy, solved_at(copy, moved), folds, conv)


def _judged(
    record: Record,
    current: Scored,
    moves: list[Move],
    fitted: list[Scored | str],
    t_min: float,
    noise_um: float,
    policy: DiagnosisPolicy,
) -> tuple[list[tuple[Move, Decision, Scored]], dict[str, str]]:
    decisions: list[tuple[Move, Decision, Scored]] = []
    rejected: dict[str, str] = {}
    for m, f in zip(moves, fitted):
        if isinstance(f, str):
            rejected[" ".join((m.kind, *m.effects))] = f
            continue
        d = _decide(m, f, current, t_min, noise_um, policy)
        decisions.append((m, _unconverged(d) if not f.converged else d, f))
    return decisions, rejected


def _screened(
    record: Record,
    copy: Record,
    on_copy: Scored,
    current: Scored,
    moves: list[Move],
    t_min: float,
    noise_um: float,
    conv: Convergence,
    policy: DiagnosisPolicy,
    workers: int | None,
) -> tuple[list[Scored | str], list[Decision]]:
    """The full-record candidates of ``moves`` after screening (module docs): a reason
    for each move the copy leaves out, and the decisions on the copy."""
    full = [_full_only(m, record, current, copy) for m in moves]
    on = [m for m, f in zip(moves, full) if not f]
    fitted = thread_map(lambda m: _candidate(copy, on_copy, m, conv=conv, policy=policy), on, workers)
    decisions, _ = _judged(copy, on_copy, on, fitted, t_min, noise_um, policy)
    # A move with no candidate on the copy (no start simulates there, or its fit is not
    # what its name says at the copy's rate) is one the copy cannot hold.
    for m, f in zip(on, fitted):
        if isinstance(f, str):
            full[moves.index(m)] = True
    chosen: set[int] = set()
    growing = [(m, d, f) for m, d, f in decisions if m.kind != "drop"]
    if growing:
        best = min(growing, key=lambda t: _finite(t[2].cv.rms_um))
        folds, batches = policy.folds, policy.batches
        chosen |= {id(m) for m, _, f in growing if m is best[0] or not apart(f.cv, best[2].cv, folds, batches, t_min)}
    # A move the copy sees any held-out gain from goes on: an effect whose time scale is
    # near the copy's sampling interval (a lag's corner, a creep's fastest element) shows
    # only part of itself there.
    chosen |= {id(m) for m, d, _ in decisions if d.accepted or d.gain.mean_um2 > 0}

    def on_full(k: int) -> Scored | str:
        m = moves[k]
        if full[k]:
            return _candidate(record, current, m, conv=conv, policy=policy)
        if id(m) not in chosen:
            return "not among the moves the screened copy ranks first"
        return _candidate(record, current, m, conv=conv, policy=policy)

    return thread_map(on_full, list(range(len(moves))), workers), [d for _, d, _ in decisions]


def search(
    record: Record,
    base: Scored,
    *,
    noise_um: float,
    policy: DiagnosisPolicy,
    conv: Convergence,
    workers: int | None,
    say: Callable[[str], None],
) -> Search:
    """The loop of moves (module docs) from the base model ``base``."""
    state = Search(base)
    seen = {frozenset(base.names)}
    copy = screen_copy(record)
    for _ in range(2 * policy.max_effects + 2):
        current = state.current
        left = unexplained(record, current.x, alpha=policy.noise_alpha, tolerance=policy.noise_tolerance)
        if left.consistent_with_noise:
            state.stopped = "the residual is consistent with the record's noise"
            break
        moves = [
            m
            for m in proposals(current.names, state.rivals, policy.max_effects)
            if frozenset(_after(current.names, m)) not in seen
        ]
        if not moves:
            state.stopped = "no move left to try"
            break
        t_min = threshold(policy.alpha, len(moves), policy.batches)
        on_copy = _on_copy(copy, current, conv, policy.folds)
        screened: list[Decision] = []
        say(
            f"round {len(state.rounds) + 1}: {len(moves)} moves from {list(current.names) or 'the base model'}"
            + (f", screened on every {round(copy.dt / record.dt)}th sample" if on_copy is not None and copy else "")
        )
        if on_copy is not None and copy is not None:
            fitted, screened = _screened(record, copy, on_copy, current, moves, t_min, noise_um, conv, policy, workers)
        else:
            fitted = thread_map(partial(_candidate, record, current, conv=conv, policy=policy), moves, workers)
        decisions, rejected = _judged(record, current, moves, fitted, t_min, noise_um, policy)
        for _, d, f in decisions:
            verdict = "accepted" if d.accepted else "no"
            say(f"  {d.label:28s} held-out RMS {f.cv.rms_um:.4g} µm: {verdict} ({d.reason})")
        signatures = tuple(sorted(named(lookalike_tests(record, current.x))))
        round_ = _take(decisions, current, t_min, policy, state, signatures, rejected, tuple(screened))
        state.rounds.append(round_)
        state.swaps = {frozenset(f.names): f for m, _, f in decisions if m.kind == "swap"}
        if round_.taken is None:
            state.stopped = "no move is accepted"
            break
        chosen = next(f for m, d, f in decisions if d is round_.taken)
        state.current = chosen
        state.swaps = {}
        seen.add(frozenset(chosen.names))
        say(f"took {round_.taken.label}: held-out RMS {current.cv.rms_um:.4g} → {chosen.cv.rms_um:.4g} µm")
    else:
        state.stopped = "the most rounds"
    return state


def structure_move(
    record: Record,
    final: Scored,
    *,
    noise_um: float,
    policy: DiagnosisPolicy,
    say: Callable[[str], None],
) -> tuple[Structure | None, Decision | None, str]:
    """The other structure (module docs of :mod:`boucwen.diagnosis`, step 7): the
    hysteretic oscillator judged against the input-driven model the search returned,
    where that model holds a mode (an effect of signature ``"peak"``). Returns the
    oscillator, the decision (``"swap"`` input-driven → oscillator) and why it was not
    tried (empty where it was)."""
    if not any(effect_class(k).signature == "peak" for k in final.names):
        return None, None, "the input-driven model holds no mode, the mark of a mechanical structure"
    say("fitting the hysteretic oscillator (hysteresis driven by the output's motion) and its blocks")
    osc = oscillator(record, policy.folds)
    if isinstance(osc, str):
        return None, None, osc
    t_min = threshold(policy.alpha, 1, policy.batches)
    d = judge(
        "swap",
        ("input-driven", osc.name),
        osc.names,
        final.names,
        gain(osc.cv, final.cv, policy.folds, policy.batches),
        t_min=t_min,
        noise_um=noise_um,
        min_share=policy.min_share,
        unknowns=osc.unknowns - final.unknowns,
    )
    if not osc.converged:
        d = _unconverged(d)
    verdict = "accepted" if d.accepted else "no"
    say(f"  {d.label:28s} held-out RMS {osc.cv.rms_um:.4g} µm: {verdict} ({d.reason})")
    return osc, d, ""


def _finite(value: float) -> float:
    """``value``, or +∞ where it is nan (a model no block of which could be judged)."""
    return value if math.isfinite(value) else math.inf


def _after(names: tuple[str, ...], move: Move) -> set[str]:
    out = set(names) - ({move.drops} if move.drops else set())
    return out | set(move.adds)


def _unconverged(d: Decision) -> Decision:
    return Decision(
        d.move,
        d.effects,
        d.candidate,
        d.reference,
        d.gain,
        d.threshold,
        d.needed_um2,
        False,
        "the candidate's fit did not converge",
        d.unknowns,
    )


def _take(
    decisions: list[tuple[Move, Decision, Scored]],
    current: Scored,
    t_min: float,
    policy: DiagnosisPolicy,
    state: Search,
    signatures: tuple[str, ...],
    rejected: dict[str, str],
    screened: tuple[Decision, ...] = (),
) -> Round:
    """The decision the round takes and its ambiguity set (module docs); updates the
    rivals of the model's effects."""
    folds, batches = policy.folds, policy.batches
    all_decisions = tuple(d for _, d, _ in decisions)
    # Swaps the record cannot tell from the current model keep the pair rivals; swaps it
    # refutes (the current model clearly better) part them.
    for m, d, _ in decisions:
        if m.kind == "swap" and m.drops is not None:
            (f,) = m.adds
            if abs(d.gain.t) <= t_min:
                state.rivals.setdefault(m.drops, set()).add(f)
            elif d.gain.t < -t_min:
                state.rivals.get(m.drops, set()).discard(f)
    drops = [(m, d, f) for m, d, f in decisions if m.kind == "drop" and d.accepted]
    if drops:
        dropped, decision, fit = max(drops, key=lambda t: (t[1].gain.t, vocabulary_order(t[0].effects)))
        assert dropped.drops is not None
        state.rivals.pop(dropped.drops, None)
        return Round(all_decisions, decision, ((decision, fit.cv.rms_um),), rejected, signatures, screened)
    growing = [(m, d, f) for m, d, f in decisions if m.kind != "drop"]
    accepted = [t for t in growing if t[1].accepted]
    if not accepted:
        return Round(all_decisions, None, (), rejected, signatures, screened)
    best = max(accepted, key=lambda t: t[1].gain.mean_um2)
    tied = [t for t in growing if t is best or not apart(t[2].cv, best[2].cv, folds, batches, t_min)]
    eligible = [t for t in tied if t[1].accepted]
    move, decision, _ = min(eligible, key=lambda t: (t[2].unknowns, vocabulary_order(t[0].adds)))
    added = set(move.adds)
    others = {k for mm, _, _ in tied for k in mm.adds if k not in added}
    if move.drops is not None:
        # The effect swapped out stays a rival of the one swapped in.
        others.add(move.drops)
        state.rivals.pop(move.drops, None)
    for k in move.adds:
        state.rivals[k] = set(others)
    ambiguity = tuple((t[1], t[2].cv.rms_um) for t in sorted(tied, key=lambda t: _finite(t[2].cv.rms_um)))
    return Round(all_decisions, decision, ambiguity, rejected, signatures, screened)
