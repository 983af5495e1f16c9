"""The loop of moves: floating selection under one judge.

Each round proposes every move from the current model — **add** an effect of the
vocabulary it lacks (two effects that physics ties together, a second mode beside a
first, are added at once: ``add_tied``), **drop** one it holds, **swap** one it holds for
a rival the record could not tell it from, and **the other structure**: the whole
input-driven model replaced by the hysteretic oscillator (the hysteresis inside a
structure's own dynamics, driven by its motion; :mod:`boucwen.oscillator`) — fits every
candidate to convergence (:mod:`~boucwen.diagnosis.fits`) and judges each against the
current model (:func:`~boucwen.diagnosis.judge.judge`). Then:

* an accepted drop is taken first (the model is simpler and predicts no worse): of
  several, the effect that earns least (the smallest statistic for keeping it);
* else the accepted add or swap of largest statistic, through its **ambiguity set**:
  the candidates of the round that the record does not tell apart from it
  (:func:`~boucwen.diagnosis.judge.apart`). The model takes the accepted member with the
  fewest unknowns (the one-standard-error rule), then the largest statistic; the others
  are its rivals, reported with their held-out errors, and proposed as swaps in the
  rounds that follow;
* nothing accepted ends the search. A residual consistent with the record's noise
  (:func:`boucwen.residual.unexplained`) leaves nothing to add: that round proposes
  only the drops (an effect added early may be redundant beside one added later) and
  the other structure, and the search ends where none is accepted. A model of the
  other structure proposes no move: the search ends there.

A model the search has already held is never proposed again (floating selection cannot
cycle). Every fit is kept by its set of effects for the whole search (a drop back to a
model held before reads that model's fit; an effect added again beside another model
starts from the values it took before). What the residual follows (the look-alike tests
of :mod:`boucwen.residual.lookalike`) is reported beside each set; it never decides.

**Scored before fitted.** Each add move is first scored at the current model
(:mod:`~boucwen.diagnosis.score`): only a move whose score could pass the judge is
fitted; the others are listed among the round's rejected moves with their score. Drops
are fitted before the swaps that start from them, once a round.

**Exactness where it decides.** Each candidate's held-out errors first come from the
screen (the first Gauss–Newton step of each fold's refit); a decision is read from
converged refits wherever it could change what the round takes — the move it would
take, every accepted drop, every move whose statistic lies within ``screen_band`` of its
threshold, every candidate that might share the best one's ambiguity set — and from the
screen only where it is far from the threshold. With ``Convergence(screen=False)`` every
decision reads converged refits.

**Screening on a copy** (records of more than :data:`SCREEN_MIN_SAMPLES` samples sampled
faster than :data:`SCREEN_RATE_HZ`) wraps the fits; it never decides. Every move is first
fitted on a copy of the record holding every q-th sample, against the current model
refitted there; the move the copy ranks best, every move the copy cannot tell from it,
and every move it sees any held-out gain from are then fitted on the full record as
without screening, and the judge decides there. Moves the copy cannot hold — an effect
of whole samples of the record's rate (:attr:`boucwen.effects.Effect.full_rate_only`), a
mode where the residual's spectral peak lies above what the copy can hold, a move with
no candidate on the copy, any move from a model the copy cannot simulate — are fitted on
the full record directly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any, Union

from .._core import EffectSet
from ..effects import FN_MAX_NYQUIST_FRACTION, VOCABULARY, effect_class, simulate_chain
from ..lsq import thread_map
from ..record import Record
from ..residual import lookalike_tests, unexplained
from ..residual.evidence import spectral_peak
from ..residual.lookalike import named
from . import fits
from .fits import Convergence, Scored, Structure
from .heldout import Folds
from .judge import Decision, apart, gain, judge, least_gain, level, threshold, within_margin
from .policy import DiagnosisPolicy
from .score import Score, Scorer

__all__ = [
    "OSCILLATOR",
    "SCREEN_MIN_SAMPLES",
    "SCREEN_RATE_HZ",
    "Model",
    "Move",
    "Round",
    "Search",
    "proposals",
    "rival_order",
    "screen_copy",
    "search",
    "vocabulary_order",
]

#: Records longer than this [samples] are screened: a shorter one fits fast enough.
SCREEN_MIN_SAMPLES = 50_000
#: The screened copy's rate [Hz]: above every effect of the vocabulary but a delay and a
#: high mode (which the copy does not hold: module docs), ten times the bandwidth of the
#: fastest actuator drive the records are made with.
SCREEN_RATE_HZ = 2500.0
#: The name of the other structure's move.
OSCILLATOR = "oscillator"

#: A model the search holds: the input-driven model with its effects, or the other
#: structure.
Model = Union[Scored, Structure]


@dataclass(frozen=True)
class Move:
    """A move from the current model.

    Attributes:
        kind: ``"add"``, ``"add_tied"``, ``"drop"``, ``"swap"`` or ``"structure"``.
        adds: effects it adds (a tied pair: the partner first); ``("oscillator",)`` for
            the structure.
        drops: the effect it takes out, or None.
    """

    kind: str
    adds: tuple[str, ...] = ()
    drops: str | None = None

    @property
    def label(self) -> str:
        """The move in words, as :attr:`Decision.label` and the round's rejected moves say it."""
        return " ".join((self.kind, *self.effects))

    @property
    def effects(self) -> tuple[str, ...]:
        """What the move concerns, as :attr:`Decision.effects` lists it."""
        if self.kind == "structure":
            return ("input-driven", *self.adds)
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
        screened: with screening on a copy, the decisions on the copy (which only choose
            what is fitted on the full record).
        scores: each add move's score at the current model (:mod:`~boucwen.diagnosis.score`),
            by the move's label; a move whose score did not pass was not fitted.
    """

    decisions: tuple[Decision, ...]
    taken: Decision | None
    ambiguity: tuple[tuple[Decision, float], ...]
    rejected: dict[str, str]
    signatures: tuple[str, ...]
    screened: tuple[Decision, ...] = ()
    scores: dict[str, Score] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "decisions": [d.to_dict() for d in self.decisions],
            "taken": None if self.taken is None else self.taken.label,
            "ambiguity": [{"move": d.label, "cv_rms_um": e} for d, e in self.ambiguity],
            "rejected": dict(self.rejected),
            "signatures": list(self.signatures),
            "screened": [d.to_dict() for d in self.screened],
            "scores": {k: v.to_dict() for k, v in self.scores.items()},
        }


@dataclass
class Search:
    """The state and history of the search.

    Attributes:
        current: the current model.
        input_driven: the last input-driven model the search held (the current one,
            unless the other structure was taken).
        rounds: every round so far.
        rivals: per effect of the model, the effects (or the other structure) the record
            did not tell it from.
        swaps: the swaps of the current model for a rival fitted in the last round (by
            the set of effects of each), kept for the explanations the record could not
            tell apart (:mod:`~boucwen.diagnosis.experiment`).
        fitted: every model fitted, by its set of effects (the other structure by its
            name).
        stopped: why the search ended.
    """

    current: Model
    input_driven: Scored
    rounds: list[Round] = field(default_factory=list)
    rivals: dict[str, set[str]] = field(default_factory=dict)
    swaps: dict[frozenset[str], Scored] = field(default_factory=dict)
    fitted: dict[frozenset[str], Model | str] = field(default_factory=dict)
    stopped: str = ""


def vocabulary_order(names: tuple[str, ...]) -> tuple[int, ...]:
    """Sort key: each name's place in the vocabulary (another structure after it)."""
    return tuple(rival_order(k)[0] for k in names)


def rival_order(name: str) -> tuple[int, str]:
    """Sort key of a rival: effects in the vocabulary's order, then another structure
    (the oscillator) by name."""
    return (VOCABULARY.index(name), "") if name in VOCABULARY else (len(VOCABULARY), name)


def proposals(names: tuple[str, ...], rivals: dict[str, set[str]], max_effects: int) -> list[Move]:
    """Every move from an input-driven model holding ``names`` (module docs)."""
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
        rest = set(names) - {k}
        for f in sorted(rivals.get(k, ()), key=rival_order):
            if f not in VOCABULARY or f in names or k in tied_to:
                continue
            partner = effect_class(f).partner
            # A tied effect needs its partner in the model it joins, not in the one it leaves.
            if partner is None or partner in rest:
                moves.append(Move("swap", (f,), k))
    moves.append(Move("structure", (OSCILLATOR,)))
    return moves


def _after(names: tuple[str, ...], move: Move) -> frozenset[str]:
    """The effect set a move leads to (the other structure: its name)."""
    if move.kind == "structure":
        return frozenset(move.adds)
    out = set(names) - ({move.drops} if move.drops else set())
    return frozenset(out | set(move.adds))


def _warm(fitted: dict[frozenset[str], Model | str], adds: tuple[str, ...]) -> Any:
    """The most recent fit of the search that held every effect of ``adds`` (its values
    start the same effects beside another model), or None."""
    for model in reversed(list(fitted.values())):
        if isinstance(model, Scored) and set(adds) <= set(model.names):
            return model.fit
    return None


def _candidate(
    record: Record,
    current: Scored,
    move: Move,
    conv: Convergence,
    policy: DiagnosisPolicy,
    folds: Folds,
    fitted: dict[frozenset[str], Model | str],
    workers: int | None,
    warm: Any = None,
    ranked: list[EffectSet] | None = None,
) -> Model | str:
    """The candidate of ``move`` from ``current`` on ``record`` (from ``fitted`` where the
    search holds it), or why there is none; ``warm``: a fit of the same model elsewhere
    (on the screened copy) whose values start it, beside the starts of the search's own
    fits; ``ranked``: the move's starts ranked by its score."""
    key = _after(current.names, move)
    if key in fitted:
        return fitted[key]
    if move.kind == "structure":
        return fits.oscillator(record, folds, conv)
    if move.kind == "drop":
        assert move.drops is not None
        return fits.drop(record, current, move.drops, conv, folds)
    origin: Model | str = current
    if move.drops is not None:
        rest = _after(current.names, Move("drop", drops=move.drops))
        origin = fitted.get(rest) or fits.drop(record, current, move.drops, conv, folds)
        if isinstance(origin, str):
            return origin
        if not isinstance(origin, Scored):  # pragma: no cover - a drop is input-driven
            return "the model without it is not input-driven"
    return fits.add(
        record,
        current,
        move.adds,
        conv,
        folds,
        policy.max_delay_samples,
        dropped=origin if isinstance(origin, Scored) and move.drops is not None else None,
        warm=warm if warm is not None else _warm(fitted, move.adds),
        ranked=ranked,
    )


def _decide(
    move: Move,
    fitted: Model,
    current: Model,
    noise_um: float,
    policy: DiagnosisPolicy,
    lvl: float,
    resolution_um: float = 0.0,
) -> Decision:
    """The judge's verdict on ``move`` at level ``lvl``. A drop is judged the other way
    round: the effect keeps its place only where the current model is accepted against
    the model without it, so the drop is accepted where that fails — and only where that
    comparison could be made (a gain that cannot be computed keeps the model as it is)."""
    added = fitted.unknowns - current.unknowns
    exact = fitted.cv.exact and current.cv.exact
    if move.kind != "drop":
        d = judge(
            move.kind,
            move.effects,
            fitted.names,
            current.names,
            gain(fitted.cv, current.cv),
            level_=lvl,
            noise_um=noise_um,
            min_share=policy.min_share,
            unknowns=added,
            exact=exact,
            resolution_um=resolution_um,
        )
    else:
        keep = judge(
            "add",
            move.effects,
            current.names,
            fitted.names,
            gain(current.cv, fitted.cv),
            level_=lvl,
            noise_um=noise_um,
            min_share=policy.min_share,
            unknowns=-added,
            exact=exact,
            resolution_um=resolution_um,
        )
        judged = math.isfinite(keep.gain.statistic)
        if not judged:
            reason = "kept: " + keep.reason
        else:
            reason = ("it no longer earns its place: " if not keep.accepted else "it earns its place: ") + keep.reason
        d = Decision(
            "drop",
            move.effects,
            fitted.names,
            current.names,
            gain(fitted.cv, current.cv),
            keep.threshold,
            keep.needed_um2,
            judged and not keep.accepted,
            reason,
            added,
            exact,
            "drop_earns" if judged else keep.rule,
        )
    if not fitted.converged:
        d = Decision(
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
            d.exact,
            "converged",
        )
    return d


def _near(d: Decision, move: Move, band: float) -> bool:
    """The screen may have decided ``d`` wrongly where it matters: an accepted drop,
    a statistic within the band of its threshold, or one not computed."""
    stat = d.gain.statistic
    if move.kind == "drop":
        # The statistic of keeping the effect is minus the drop's.
        stat = -stat
    if not math.isfinite(stat) or not math.isfinite(d.threshold):
        return True
    # An accepted drop is taken before any add; an accepted add far above its threshold
    # is confirmed only where it may be taken or share the taken move's ambiguity set
    # (_Round.settle): beaten clearly by the best, its verdict changes nothing.
    return (d.accepted and move.kind == "drop") or abs(stat - d.threshold) <= band


def screen_copy(record: Record) -> Record | None:
    """The record's screened copy (every q-th sample, about :data:`SCREEN_RATE_HZ`), or
    None where the record is not screened."""
    q = int(1.0 / (record.dt * SCREEN_RATE_HZ))
    return record.decimated(q) if len(record) > SCREEN_MIN_SAMPLES and q >= 2 else None


def _full_only(move: Move, record: Record, current: Scored, copy: Record) -> bool:
    """The copy cannot hold ``move`` (module docs)."""
    if move.kind == "structure":
        return True
    if any(effect_class(k).full_rate_only for k in move.adds):
        return True
    if any(effect_class(k).signature == "peak" for k in move.adds):
        peak = spectral_peak(record.x - current.x, record.dt)["peak_hz"]
        return bool(peak > FN_MAX_NYQUIST_FRACTION / copy.dt)
    return False


@dataclass
class _Judged:
    """A round's moves with their candidates and decisions (one place to update them)."""

    moves: list[Move]
    candidates: list[Model | str]
    decisions: dict[int, Decision] = field(default_factory=dict)

    def rows(self) -> list[tuple[Move, Decision, Model]]:
        return [
            (m, self.decisions[k], c)
            for k, (m, c) in enumerate(zip(self.moves, self.candidates))
            if k in self.decisions and not isinstance(c, str)
        ]


class _Round:
    """One round on one record: the candidates fitted, judged, confirmed where it counts."""

    def __init__(
        self,
        record: Record,
        current: Model,
        moves: list[Move],
        candidates: list[Model | str],
        noise_um: float,
        policy: DiagnosisPolicy,
        workers: int | None,
        screen: bool = True,
        round_: int = 1,
        resolution_um: float = 0.0,
    ):
        self.record, self.noise_um, self.policy, self.workers = record, noise_um, policy, workers
        self.resolution_um = resolution_um
        self.screen = screen
        self.current = current
        self.level = level(policy.alpha, len(moves), round_)
        self.judged = _Judged(moves, candidates)

    def confirm(self, model: Model) -> Model:
        return fits.confirmed(self.record, model, self.workers)

    def decide(self) -> None:
        j = self.judged
        for k, (m, c) in enumerate(zip(j.moves, j.candidates)):
            if not isinstance(c, str):
                j.decisions[k] = _decide(m, c, self.current, self.noise_um, self.policy, self.level, self.resolution_um)

    def settle(self) -> None:
        """Decide every move, then confirm by refits each decision the screen may have
        decided wrongly and each candidate that may share the best one's ambiguity set,
        until none is left (module docs)."""
        j, band = self.judged, self.policy.screen_band
        if not self.screen:
            self.current = self.confirm(self.current)
            j.candidates = [c if isinstance(c, str) else self.confirm(c) for c in j.candidates]
        self.decide()
        for _ in range(len(j.moves) + 1):
            todo = {k for k, d in j.decisions.items() if not d.exact and _near(d, j.moves[k], band)}
            best = self.best()
            if best is not None:
                bcv = j.candidates[best]
                assert not isinstance(bcv, str)
                for k, d in j.decisions.items():
                    c = j.candidates[k]
                    if d.exact or j.moves[k].kind == "drop" or isinstance(c, str):
                        continue
                    g = gain(c.cv, bcv.cv)
                    if not math.isfinite(g.statistic) or abs(g.statistic) <= d.threshold + band:
                        todo.add(k)
                if not j.decisions[best].exact:
                    todo.add(best)
            if not todo:
                break
            self.current = self.confirm(self.current)
            for k in sorted(todo):
                c = j.candidates[k]
                if not isinstance(c, str):
                    j.candidates[k] = self.confirm(c)
            self.decide()

    def best(self) -> int | None:
        """The move the round would take before its ambiguity set (its index): of the
        accepted adds, swaps and structures, one that no other beats by the judge's
        test in a direct comparison — from the largest statistic against the current
        model, on to any accepted candidate that passes the test against it."""
        j = self.judged
        accepted = [
            k
            for k, d in j.decisions.items()
            if j.moves[k].kind != "drop" and d.accepted and not isinstance(j.candidates[k], str)
        ]
        if not accepted:
            return None
        # The other structure ends the search, so it is compared with the input-driven
        # model at its best: while an input-driven move is still accepted, that class
        # is still improving, and the structure waits for a later round (it is proposed
        # every round). A step record's relaxation (creep, a lag) is otherwise taken
        # for an overdamped mode of the oscillator against the bare base model.
        driven = [k for k in accepted if j.moves[k].kind != "structure"]
        accepted = driven or accepted
        best = max(accepted, key=lambda k: (j.decisions[k].gain.statistic, -k))
        for _ in range(len(accepted)):
            bcv = self._model(best).cv
            beaten = [(gain(self._model(k).cv, bcv), k) for k in accepted if k != best]
            beaten = [(g, k) for g, k in beaten if g.statistic > threshold(self.level, g.dof)]
            if not beaten:
                break
            best = max(beaten, key=lambda gk: (gk[0].statistic, -gk[1]))[1]
        return best

    def _model(self, k: int) -> Model:
        c = self.judged.candidates[k]
        assert not isinstance(c, str)
        return c


def _scored_moves(
    record: Record,
    current: Scored,
    moves: list[Move],
    state: Search,
    policy: DiagnosisPolicy,
    noise_um: float,
    resolution_um: float,
    round_: int,
) -> tuple[dict[int, Score], dict[int, list[EffectSet]]]:
    """Each add move's score at the current model (:mod:`~boucwen.diagnosis.score`) and
    its starts ranked by it, by the move's index."""
    scorer = Scorer(record, current.x, current.jacobian, current.fit.params, current.fit.h0)
    lvl = level(policy.alpha, len(moves), round_)
    # In-sample, as the score is: the current model's own mean-square error.
    needed = least_gain(current.fit.rms_um**2, noise_um, policy.min_share, resolution_um)
    scores: dict[int, Score] = {}
    ranked: dict[int, list[EffectSet]] = {}
    for k, m in enumerate(moves):
        if m.kind not in ("add", "add_tied"):
            continue
        starts = fits.starts_of(record, current, m.adds, policy.max_delay_samples, _warm(state.fitted, m.adds))
        scores[k], ranked[k] = scorer.score(starts, m.adds, lvl, needed)
    return scores, ranked


def _fitted_move(
    record: Record,
    current: Scored,
    moves: list[Move],
    unscored: dict[int, str],
    wanted: list[bool],
    copied: list[Any],
    ranked: dict[int, list[EffectSet]],
    conv: Convergence,
    policy: DiagnosisPolicy,
    folds: Folds,
    state: Search,
    k: int,
) -> Model | str:
    """Move ``k``'s candidate, or why it has none: its score did not pass, the screened
    copy did not rank it, or :func:`_candidate`'s reason."""
    if k in unscored:
        return unscored[k]
    if not wanted[k]:
        return "not among the moves the screened copy ranks first"
    return _candidate(record, current, moves[k], conv, policy, folds, state.fitted, 1, copied[k], ranked.get(k))


def _on_copy(copy: Record | None, current: Model, conv: Convergence, policy: DiagnosisPolicy) -> Scored | None:
    """The current model refitted and scored on the copy, or None where the copy cannot
    hold it."""
    if copy is None or not isinstance(current, Scored) or any(effect_class(k).full_rate_only for k in current.names):
        return None
    fit = current.fit
    if simulate_chain(fit.params, fit.effects, copy.u, copy.dt, fit.h0) is None:
        return None
    moved = fits.refit(copy, fit, fit.effects, conv)
    if moved is None:
        return None
    solved = fits.solved_at(copy, moved)
    return fits.scored(copy, solved, Folds.of(copy, policy.folds, policy.first_origin, solved.jacobian), conv)


def _chosen_on_copy(
    copy: Record,
    on_copy: Scored,
    current: Scored,
    record: Record,
    moves: list[Move],
    conv: Convergence,
    policy: DiagnosisPolicy,
    noise_um: float,
    workers: int | None,
    round_: int,
    resolution_um: float = 0.0,
) -> tuple[list[bool], list[Decision], list[Any]]:
    """Which moves the full record fits (module docs), the decisions on the copy, and
    each move's fit on the copy (None where it has none) to start the full record's."""
    full = [_full_only(m, record, current, copy) for m in moves]
    on = [k for k, f in enumerate(full) if not f]
    folds = on_copy.cv.folds
    cache: dict[frozenset[str], Model | str] = {}
    fitted = thread_map(lambda k: _candidate(copy, on_copy, moves[k], conv, policy, folds, cache, None), on, workers)
    rnd = _Round(copy, on_copy, [moves[k] for k in on], fitted, noise_um, policy, workers, True, round_, resolution_um)
    rnd.decide()
    chosen = set()
    # A move with no candidate on the copy is one the copy cannot hold.
    for k, f in zip(on, fitted):
        if isinstance(f, str):
            full[k] = True
    rows = rnd.judged.rows()
    growing = [(i, m, d, f) for i, (m, d, f) in enumerate(rows) if m.kind != "drop"]
    index = {id(m): k for k, m in enumerate(moves)}
    if growing:
        best = min(growing, key=lambda t: _finite(t[3].cv.rms_um))
        for _, m, _, f in growing:
            if m is best[1] or not apart(f.cv, best[3].cv, rnd.level):
                chosen.add(index[id(m)])
    # A move the copy sees any held-out gain from goes on: an effect whose time scale is
    # near the copy's sampling interval (a lag's corner, a creep's fastest element) shows
    # only part of itself there.
    chosen |= {index[id(m)] for m, d, _ in rows if d.accepted or d.gain.mean_um2 > 0}
    starts: list[Any] = [None] * len(moves)
    for k, f in zip(on, fitted):
        if isinstance(f, Scored):
            starts[k] = f.fit
    return [f or k in chosen for k, f in enumerate(full)], [d for _, d, _ in rows], starts


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
    """The loop of moves (module docs) from the base model ``base``.

    Each round judges its moves against the current model's own sampling-rate error
    (:func:`boucwen.diagnosis.fits.resolution`, below which a gain is not enough:
    :func:`boucwen.diagnosis.judge.judge`), measured on the current model: what a
    candidate can take up is the current model's error, and its stepping error is that of
    the current model's parameters, not of a model fitted before the effects it now holds
    (a base model that absorbs a drift has other parameters, and steps differently)."""
    state = Search(base, base)
    state.fitted[frozenset(base.names)] = base
    seen = {frozenset(base.names)}
    folds = base.cv.folds
    copy = screen_copy(record)
    for _ in range(policy.rounds):
        current = state.current
        if not isinstance(current, Scored):
            state.stopped = "the other structure proposes no move"
            break
        left = unexplained(record, current.x, alpha=policy.noise_alpha, tolerance=policy.noise_tolerance)
        # A residual consistent with the noise leaves nothing to add, but an effect added
        # early may have been made redundant by one added later (it took part of what the
        # later one explains), and the other structure is a whole model the returned one
        # must still beat: the search stops after a round of drops and the structure.
        quiet = left.consistent_with_noise
        resolution_um = fits.resolution(record, current.fit)
        moves = [
            m
            for m in proposals(current.names, state.rivals, policy.max_effects)
            if _after(current.names, m) not in seen and (m.kind in ("drop", "structure") or not quiet)
        ]
        if not moves:
            state.stopped = "the residual is consistent with the record's noise" if quiet else "no move left to try"
            break
        round_no = len(state.rounds) + 1
        scores, ranked = _scored_moves(record, current, moves, state, policy, noise_um, resolution_um, round_no)
        # A move whose score does not pass is not fitted (with conv.score off, every move is).
        unscored = {k: f"not fitted: {sc.reason}" for k, sc in scores.items() if conv.score and not sc.passed}
        on_copy = _on_copy(copy, current, conv, policy)
        screened: list[Decision] = []
        say(
            f"round {len(state.rounds) + 1}: {len(moves)} moves from {list(current.names) or 'the base model'}"
            + (f", screened on every {round(copy.dt / record.dt)}th sample" if on_copy is not None and copy else "")
        )
        wanted = [k not in unscored for k in range(len(moves))]
        copied: list[Any] = [None] * len(moves)
        kept = [k for k in range(len(moves)) if wanted[k]]
        if on_copy is not None and copy is not None and kept:
            on, screened, starts_on = _chosen_on_copy(
                copy,
                on_copy,
                current,
                record,
                [moves[k] for k in kept],
                conv,
                policy,
                noise_um,
                workers,
                round_no,
                resolution_um,
            )
            for k, w, c in zip(kept, on, starts_on):
                wanted[k], copied[k] = w, c

        job = partial(
            _fitted_move, record, current, moves, unscored, wanted, copied, ranked, conv, policy, folds, state
        )
        # Drops first: a swap starts from its drop, fitted once in the round.
        drops = [k for k, m in enumerate(moves) if m.kind == "drop"]
        candidates: list[Model | str] = [""] * len(moves)
        for k, c in zip(drops, thread_map(job, drops, workers)):
            candidates[k] = c
            if not isinstance(c, str):
                state.fitted[_after(current.names, moves[k])] = c
        rest = [k for k in range(len(moves)) if k not in drops]
        for k, c in zip(rest, thread_map(job, rest, workers)):
            candidates[k] = c
        rnd = _Round(
            record,
            current,
            moves,
            candidates,
            noise_um,
            policy,
            workers,
            conv.screen,
            round_no,
            resolution_um,
        )
        rnd.settle()
        # The round's fits, confirmed where it confirmed them, kept for the rest of the search.
        confirmed_current = rnd.current
        assert isinstance(confirmed_current, Scored)
        state.current = state.input_driven = current = confirmed_current
        state.fitted[frozenset(current.names)] = current
        for k, c in enumerate(rnd.judged.candidates):
            if not isinstance(c, str):
                state.fitted[_after(current.names, moves[k])] = c
        rows = rnd.judged.rows()
        for _, d, f in rows:
            verdict = "accepted" if d.accepted else "no"
            how = "" if d.exact else ", screened"
            say(f"  {d.label:28s} held-out RMS {f.cv.rms_um:.4g} µm: {verdict} ({d.reason}{how})")
        rejected = {m.label: c for m, c in zip(moves, rnd.judged.candidates) if isinstance(c, str)}
        for k in unscored:
            say(f"  {moves[k].label:28s} {unscored[k]}")
        signatures = tuple(sorted(named(lookalike_tests(record, current.x))))
        round_ = _take(rnd, state, signatures, rejected, tuple(screened))
        round_ = replace(round_, scores={moves[k].label: sc for k, sc in scores.items()})
        state.rounds.append(round_)
        state.swaps = {frozenset(f.names): f for m, _, f in rows if m.kind == "swap" and isinstance(f, Scored)}
        if round_.taken is None:
            state.stopped = "the residual is consistent with the record's noise" if quiet else "no move is accepted"
            break
        chosen = next(f for m, d, f in rows if d is round_.taken)
        state.current = chosen
        if isinstance(chosen, Scored):
            state.input_driven = chosen
        state.swaps = {}
        seen.add(frozenset(chosen.names))
        say(f"took {round_.taken.label}: held-out RMS {current.cv.rms_um:.4g} → {chosen.cv.rms_um:.4g} µm")
    else:
        state.stopped = "the most rounds"
    return state


def _finite(value: float) -> float:
    """``value``, or +∞ where it is nan (a model no fold of which could be judged)."""
    return value if math.isfinite(value) else math.inf


def _take(
    rnd: _Round,
    state: Search,
    signatures: tuple[str, ...],
    rejected: dict[str, str],
    screened: tuple[Decision, ...] = (),
) -> Round:
    """The decision the round takes and its ambiguity set (module docs); updates the
    rivals of the model's effects."""
    rows = rnd.judged.rows()
    all_decisions = tuple(d for _, d, _ in rows)
    # Swaps the record cannot tell from the current model keep the pair rivals; swaps it
    # refutes (the current model clearly better) part them.
    for m, d, _ in rows:
        if m.kind == "swap" and m.drops is not None:
            (f,) = m.adds
            if abs(d.gain.statistic) <= d.threshold:
                state.rivals.setdefault(m.drops, set()).add(f)
            elif d.gain.statistic < -d.threshold:
                state.rivals.get(m.drops, set()).discard(f)
    drops = [(m, d, f) for m, d, f in rows if m.kind == "drop" and d.accepted]
    if drops:
        # The effect that earns least: the largest statistic of the model without it.
        dropped, decision, fit = max(drops, key=lambda t: (t[1].gain.statistic, vocabulary_order(t[0].effects)))
        assert dropped.drops is not None
        state.rivals.pop(dropped.drops, None)
        return Round(all_decisions, decision, ((decision, fit.cv.rms_um),), rejected, signatures, screened)
    best_k = rnd.best()
    if best_k is None:
        return Round(all_decisions, None, (), rejected, signatures, screened)
    j = rnd.judged
    best = j.candidates[best_k]
    assert not isinstance(best, str)
    growing = [(m, d, f) for m, d, f in rows if m.kind != "drop"]
    # The ambiguity set: what the record cannot tell from the best, on a comparison it
    # could make; a candidate whose fit did not converge is no one's rival.
    tied = [t for t in growing if t[2] is best or (t[2].converged and within_margin(t[2].cv, best.cv, rnd.level))]
    # The structure is taken only as the round's best (Round.best: it waits while an
    # input-driven move is accepted); within the set it stays the taken move's rival.
    structure_best = j.moves[best_k].kind == "structure"
    eligible = [t for t in tied if t[1].accepted and (structure_best or t[0].kind != "structure")]
    move, decision, _ = min(eligible, key=lambda t: (t[2].unknowns, -t[1].gain.statistic))
    added = set(move.adds)
    others = {k for mm, _, _ in tied for k in mm.adds if k not in added}
    if move.drops is not None:
        # The effect swapped out stays a rival of the one swapped in.
        others.add(move.drops)
        state.rivals.pop(move.drops, None)
    if move.kind == "structure":
        # The effects of the input-driven model the structure refutes keep it as a rival.
        for k in rnd.current.names:
            state.rivals.setdefault(k, set()).add(OSCILLATOR)
    for k in move.adds:
        state.rivals[k] = set(others)
    ambiguity = tuple((t[1], t[2].cv.rms_um) for t in sorted(tied, key=lambda t: _finite(t[2].cv.rms_um)))
    return Round(all_decisions, decision, ambiguity, rejected, signatures, screened)
