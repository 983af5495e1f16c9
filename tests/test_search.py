"""The loop of moves (boucwen.diagnosis.search) on constructed candidates: what it
proposes, which move a round takes, the ambiguity set and its rivals, and the loop's
stops; the fits are replaced by constructed held-out residuals."""

import importlib

import numpy as np
import pytest

from boucwen import DiagnosisPolicy, EffectSet, Params
from boucwen.diagnosis.fits import Convergence, Scored
from boucwen.diagnosis.judge import CrossValidation, threshold
from boucwen.diagnosis.search import Move, Search, _decide, _take, proposals, search
from boucwen.effects import ExtendedFit
from boucwen.record import validate_record

# The module (the package exports its function of the same name).
search_module = importlib.import_module("boucwen.diagnosis.search")
POLICY = DiagnosisPolicy()
N = 3200
NOISE = np.random.default_rng(0).normal(0.0, 0.01, N)


def _scored(names, scale, unknowns=8, phase=0.0):
    """A model holding ``names`` whose held-out residual is the noise plus ``scale`` × a
    misfit that lasts the whole record (of its own ``phase``: two models of equal error
    whose misfits differ in shape)."""
    effects = EffectSet(**{k: _PARAMS[k] for k in names})
    residual = NOISE + scale * np.sin(np.arange(N) * 0.01 + phase)
    cv = CrossValidation.of(residual, residual, POLICY.folds)
    fit = ExtendedFit(Params.paper_1hz(), effects, 0.0, float(np.std(residual)), 0.0, 0, True)
    return Scored(fit, np.zeros(N), np.zeros((N, unknowns)), cv, True)


_PARAMS = {
    "creep": {"tau_s": [0.1], "gain_um_per_v": [0.001]},
    "drift": {"rate_um_per_s": 0.1},
    "gain_drift": {"rate_per_s": 0.01},
    "input_lag": {"fc_hz": 100.0},
    "resonance": {"fn_hz": 100.0, "zeta": 0.1},
    "resonance2": {"fn_hz": 150.0, "zeta": 0.1},
    "electrostriction": {"epsilon_per_um": 1e-4},
    "delay": {"samples": 2},
    "pickup": {"line_hz": 50.0, "sin_um": [0.01], "cos_um": [0.0]},
    "saturation": {"min_um": -1e3, "max_um": 1e3},
}


def test_proposals_add_each_missing_effect_a_tied_pair_drops_and_swaps_for_rivals():
    moves = proposals((), {}, 4)
    adds = {m.adds for m in moves if m.kind == "add"}
    assert ("creep",) in adds and ("resonance",) in adds and ("resonance2",) not in adds
    assert Move("add_tied", ("resonance", "resonance2")) in moves
    assert not [m for m in moves if m.kind in ("drop", "swap")]
    moves = proposals(("resonance", "resonance2", "creep"), {"creep": {"drift"}}, 4)
    # A mode with its second beside it is not dropped alone; the second is.
    assert {m.drops for m in moves if m.kind == "drop"} == {"resonance2", "creep"}
    assert Move("swap", ("drift",), "creep") in moves
    assert ("resonance2",) not in {m.adds for m in moves}
    # The most effects: nothing more is added, drops and swaps stay.
    assert not [m for m in proposals(("creep", "drift"), {}, 2) if m.kind.startswith("add")]


def _round(current, candidates):
    t_min = threshold(POLICY.alpha, len(candidates), POLICY.batches)
    decisions = [(m, _decide(m, f, current, t_min, 0.01, POLICY), f) for m, f in candidates]
    state = Search(current)
    return _take(decisions, current, t_min, POLICY, state, (), {}), state


def test_a_round_takes_the_largest_accepted_gain_and_reports_what_it_cannot_tell_apart():
    current = _scored((), 0.1)
    creep, drift, lag = (
        _scored(("creep",), 0.02, 9),
        _scored(("drift",), 0.0201, 9, 1.3),
        _scored(("input_lag",), 0.08, 9),
    )
    round_, state = _round(
        current,
        [(Move("add", ("creep",)), creep), (Move("add", ("drift",)), drift), (Move("add", ("input_lag",)), lag)],
    )
    assert round_.taken is not None and round_.taken.accepted
    # Creep and drift predict alike: one set; the first in the vocabulary of equal
    # unknowns is taken, the other is its rival. The input lag, far worse, is not in it.
    assert {d.effects for d, _ in round_.ambiguity} == {("creep",), ("drift",)}
    assert round_.taken.effects == ("creep",)
    assert state.rivals == {"creep": {"drift"}}


def test_of_a_set_the_member_with_fewer_unknowns_is_taken():
    current = _scored((), 0.1)
    many, few = _scored(("creep",), 0.02, 12), _scored(("drift",), 0.0201, 9, 1.3)
    round_, _ = _round(current, [(Move("add", ("creep",)), many), (Move("add", ("drift",)), few)])
    assert round_.taken is not None and round_.taken.effects == ("drift",)


def test_an_accepted_drop_is_taken_before_any_add():
    current = _scored(("creep", "drift"), 0.02, 10)
    without_drift = _scored(("creep",), 0.02, 9)  # predicts as well: the drift no longer earns
    better = _scored(("creep", "drift", "input_lag"), 0.001, 11)
    round_, _ = _round(current, [(Move("drop", drops="drift"), without_drift), (Move("add", ("input_lag",)), better)])
    assert round_.taken is not None and round_.taken.move == "drop" and round_.taken.effects == ("drift",)


def test_a_needed_effect_is_not_dropped():
    current = _scored(("creep",), 0.02, 9)
    worse = _scored((), 0.1)
    round_, _ = _round(current, [(Move("drop", drops="creep"), worse)])
    assert round_.taken is None
    [d] = round_.decisions
    assert not d.accepted and "earns its place" in d.reason


def test_a_swap_the_record_refutes_parts_the_rivals():
    current = _scored(("creep",), 0.02, 9)
    t_min = threshold(POLICY.alpha, 1, POLICY.batches)
    m = Move("swap", ("drift",), "creep")
    worse = _scored(("drift",), 0.1, 9)
    state = Search(current, rivals={"creep": {"drift"}})
    _take([(m, _decide(m, worse, current, t_min, 0.01, POLICY), worse)], current, t_min, POLICY, state, (), {})
    assert state.rivals == {"creep": set()}


def test_the_loop_adds_while_a_move_is_accepted_never_revisits_a_model_and_stops(monkeypatch):
    # A constructed world: creep explains most, then the input lag the rest; the record is
    # left at its noise. The fits are replaced by these held-out errors.
    dt = 1e-3
    u = 50.0 + 40.0 * np.sin(np.arange(N) * 0.01)
    record = validate_record(u, 0.2 * u + np.sin(np.arange(N) * 0.01), dt)
    levels = {frozenset(): 1.0, frozenset({"creep"}): 0.1, frozenset({"creep", "input_lag"}): 0.0}
    tried = []

    def candidate(rec, current, move, *, conv=None, policy=None):
        names = (set(current.names) - {move.drops}) | set(move.adds)
        tried.append(frozenset(names))
        scale = levels.get(frozenset(names), 2.0)
        s = _scored(tuple(sorted(names)), scale, 8 + len(names))
        # The returned model's prediction: the record less what its level leaves.
        return Scored(s.fit, record.x - NOISE - scale * np.sin(np.arange(N) * 0.01), s.jacobian, s.cv, True)

    monkeypatch.setattr(search_module, "_candidate", candidate)
    base = candidate(record, _scored((), 0.0), Move("add", ()))
    tried.clear()
    state = search(record, base, noise_um=0.01, policy=POLICY, conv=Convergence(), workers=1, say=lambda s: None)
    assert set(state.current.names) == {"creep", "input_lag"}
    assert [r.taken.label for r in state.rounds if r.taken] == ["add creep", "add input_lag"]
    assert frozenset() not in tried  # the base model is never proposed again
    assert "noise" in state.stopped or "no move" in state.stopped


@pytest.mark.parametrize("kind", ["add", "drop"])
def test_a_candidate_whose_fit_did_not_converge_is_never_accepted(kind):
    current = _scored(("creep",), 0.1, 9)
    good = _scored(("creep", "drift") if kind == "add" else (), 0.01, 10)
    unconverged = Scored(good.fit, good.x, good.jacobian, good.cv, False)
    move = Move("add", ("drift",)) if kind == "add" else Move("drop", drops="creep")
    t_min = threshold(POLICY.alpha, 1, POLICY.batches)
    decisions, _ = search_module._judged(None, current, [move], [unconverged], t_min, 0.01, POLICY)
    [(_, d, _)] = decisions
    assert not d.accepted and "did not converge" in d.reason


def test_with_one_effect_kept_its_drop_and_its_swaps_are_proposed():
    moves = proposals(("creep",), {"creep": {"drift", "gain_drift"}}, 4)
    assert Move("drop", drops="creep") in moves
    assert {m.adds for m in moves if m.kind == "swap"} == {("gain_drift",), ("drift",)}


def test_two_tied_effects_added_at_once_have_no_rival_when_none_is_within_the_margin():
    current = _scored((), 0.1)
    both = _scored(("resonance", "resonance2"), 0.01, 12)
    lag = _scored(("input_lag",), 0.08, 9)
    round_, state = _round(
        current, [(Move("add_tied", ("resonance", "resonance2")), both), (Move("add", ("input_lag",)), lag)]
    )
    assert round_.taken is not None and round_.taken.move == "add_tied"
    assert state.rivals == {"resonance": set(), "resonance2": set()}


def test_another_structure_as_a_rival_sorts_after_the_effects_and_is_never_swapped_in():
    # The oscillator within the judge's margin of a mode is the mode's rival: it is
    # reported (after the effects) but is no effect to swap into the model.
    from boucwen.diagnosis.search import rival_order

    assert sorted({"oscillator", "delay", "creep"}, key=rival_order) == ["creep", "delay", "oscillator"]
    moves = proposals(("resonance",), {"resonance": {"oscillator", "creep"}}, 4)
    swaps = [m for m in moves if m.kind == "swap"]
    assert [m.adds for m in swaps] == [("creep",)]
