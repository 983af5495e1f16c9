"""The loop of moves (boucwen.diagnosis.search) on constructed candidates: what it
proposes, which move a round takes, the ambiguity set and its rivals, the loop's stops,
and the two faults it once had (a second mode swapped in without its first; a drop
accepted on a gain no fold could give); the fits are replaced by constructed held-out
residuals."""

import importlib
import math

import numpy as np
import pytest

from boucwen import DiagnosisPolicy, EffectSet, Params
from boucwen.diagnosis.fits import Convergence, Scored
from boucwen.diagnosis.heldout import CrossValidation, Folds, Leaveout
from boucwen.diagnosis.search import OSCILLATOR, Move, Search, _decide, _Round, _take, proposals, search
from boucwen.effects import ExtendedFit
from boucwen.record import validate_record

# The module (the package exports its function of the same name).
search_module = importlib.import_module("boucwen.diagnosis.search")
POLICY = DiagnosisPolicy()
N = 3200
FOLDS = Folds(N, (1600, 2000, 2400, 2800))
_OK = (True,) * FOLDS.count
NOISE = np.random.default_rng(0).normal(0.0, 0.01, N)
_NONE = np.zeros(0)
_LEAVEOUT = Leaveout(_NONE, np.zeros((0, 0)), _NONE, _NONE, _NONE, lambda z, stop: None, lambda until: (None, False))

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


def _cv(residual, converged=_OK):
    return CrossValidation.of(residual, residual, FOLDS, converged, True)


def _scored(names, scale, unknowns=8, phase=0.0, converged=True, cv_converged=_OK):
    """A model holding ``names`` whose held-out residual is the noise plus ``scale`` × a
    misfit that lasts the whole record (of its own ``phase``: two models of equal error
    whose misfits differ in shape)."""
    effects = EffectSet(**{k: _PARAMS[k] for k in names})
    residual = NOISE + scale * np.sin(np.arange(N) * 0.01 + phase)
    fit = ExtendedFit(Params.paper_1hz(), effects, 0.0, float(np.std(residual)), 0.0, 0, converged)
    return Scored(fit, np.zeros(N), np.zeros((N, unknowns)), _cv(residual, cv_converged), converged, _LEAVEOUT)


def _round(current, candidates, state=None):
    moves = [m for m, _ in candidates]
    rnd = _Round(None, current, moves, [c for _, c in candidates], 0.01, POLICY, 1)
    rnd.settle()
    state = state or Search(current, current)
    return _take(rnd, state, (), {}), state


def test_proposals_add_each_missing_effect_a_tied_pair_drops_swaps_and_the_other_structure():
    moves = proposals((), {}, 4)
    adds = {m.adds for m in moves if m.kind == "add"}
    assert ("creep",) in adds and ("resonance",) in adds and ("resonance2",) not in adds
    assert Move("add_tied", ("resonance", "resonance2")) in moves
    assert Move("structure", (OSCILLATOR,)) in moves
    assert not [m for m in moves if m.kind in ("drop", "swap")]
    moves = proposals(("resonance", "resonance2", "creep"), {"creep": {"drift"}}, 4)
    # A mode with its second beside it is not dropped alone; the second is.
    assert {m.drops for m in moves if m.kind == "drop"} == {"resonance2", "creep"}
    assert Move("swap", ("drift",), "creep") in moves
    assert ("resonance2",) not in {m.adds for m in moves}
    # The most effects: nothing more is added, drops and swaps stay.
    full = proposals(("creep", "drift", "delay", "pickup"), {"creep": {"gain_drift"}}, 4)
    assert not [m for m in full if m.kind in ("add", "add_tied")]
    assert Move("swap", ("gain_drift",), "creep") in full


def test_a_second_mode_is_never_swapped_in_for_its_own_first():
    # The first mode's rival is the second: swapping it in would leave a second mode
    # without its first (the partner is looked up in the model the rival joins).
    moves = proposals(("resonance",), {"resonance": {"resonance2", "creep"}}, 4)
    swaps = [m for m in moves if m.kind == "swap"]
    assert [m.adds for m in swaps] == [("creep",)]
    assert Move("add", ("resonance2",)) in moves


def test_a_round_takes_the_move_no_other_beats_and_reports_what_it_cannot_tell_apart():
    current = _scored((), 0.1)
    creep = _scored(("creep",), 0.02, 9)
    drift = _scored(("drift",), 0.02, 9, phase=0.001)
    lag = _scored(("input_lag",), 0.06, 9)
    round_, state = _round(
        current,
        [(Move("add", ("creep",)), creep), (Move("add", ("drift",)), drift), (Move("add", ("input_lag",)), lag)],
    )
    assert round_.taken is not None and round_.taken.effects in (("creep",), ("drift",))
    tied = {d.effects for d, _ in round_.ambiguity}
    assert tied == {("creep",), ("drift",)}
    taken = round_.taken.effects[0]
    other = "drift" if taken == "creep" else "creep"
    assert state.rivals[taken] == {other}


def test_a_candidate_an_other_accepted_one_beats_is_not_taken():
    current = _scored((), 0.1)
    close = _scored(("creep",), 0.01, 9)
    better = _scored(("drift",), 0.0, 9)
    round_, _ = _round(current, [(Move("add", ("creep",)), close), (Move("add", ("drift",)), better)])
    assert round_.taken is not None and round_.taken.effects == ("drift",)


def test_of_a_set_the_member_with_fewer_unknowns_is_taken():
    current = _scored((), 0.1)
    many = _scored(("creep",), 0.02, 12)
    few = _scored(("drift",), 0.02, 9, phase=0.001)
    round_, _ = _round(current, [(Move("add", ("creep",)), many), (Move("add", ("drift",)), few)])
    assert round_.taken is not None and round_.taken.effects == ("drift",)


def test_an_accepted_drop_is_taken_before_any_add():
    current = _scored(("creep", "drift"), 0.02, 10)
    without = _scored(("creep",), 0.02, 9, phase=0.001)
    add = _scored(("creep", "drift", "delay"), 0.0, 11)
    round_, _ = _round(current, [(Move("drop", drops="drift"), without), (Move("add", ("delay",)), add)])
    assert round_.taken is not None and round_.taken.move == "drop"


def test_a_needed_effect_is_not_dropped():
    current = _scored(("creep",), 0.0, 9)
    without = _scored((), 0.1)
    round_, _ = _round(current, [(Move("drop", drops="creep"), without)])
    assert round_.taken is None
    assert not round_.decisions[0].accepted and "earns its place" in round_.decisions[0].reason


def test_a_drop_on_a_gain_no_fold_could_give_is_not_accepted():
    # No fold of the model without the effect converged: the record cannot judge the
    # drop, and the model keeps its effect.
    current = _scored(("creep",), 0.0, 9)
    without = _scored((), 0.1, cv_converged=(False,) * FOLDS.count)
    d = _decide(Move("drop", drops="creep"), without, current, 0.01, POLICY, 1e-3)
    assert math.isnan(d.gain.statistic) and not d.accepted and "kept" in d.reason


def test_a_swap_the_record_refutes_parts_the_rivals():
    current = _scored(("creep",), 0.0, 9)
    worse = _scored(("drift",), 0.1, 9)
    state = Search(current, current, rivals={"creep": {"drift"}})
    _round(current, [(Move("swap", ("drift",), "creep"), worse)], state)
    assert state.rivals == {"creep": set()}


@pytest.mark.parametrize("kind", ["add", "drop"])
def test_a_candidate_whose_fit_did_not_converge_is_never_accepted(kind):
    current = _scored(("creep",), 0.1, 9)
    good_names = ("creep", "drift") if kind == "add" else ()
    unconverged = _scored(good_names, 0.01, 10, converged=False)
    move = Move("add", ("drift",)) if kind == "add" else Move("drop", drops="creep")
    d = _decide(move, unconverged, current, 0.01, POLICY, 1e-3)
    assert not d.accepted and "did not converge" in d.reason


def test_the_loop_adds_while_a_move_is_accepted_never_revisits_a_model_and_stops(monkeypatch):
    # A constructed world: creep explains most, then the input lag the rest; the record is
    # left at its noise. The fits are replaced by these held-out errors.
    dt = 1e-3
    u = 50.0 + 40.0 * np.sin(np.arange(N) * 0.01)
    record = validate_record(u, 0.2 * u + np.sin(np.arange(N) * 0.01), dt)
    levels = {frozenset(): 1.0, frozenset({"creep"}): 0.1, frozenset({"creep", "input_lag"}): 0.0}
    tried = []

    def candidate(rec, current, move, conv, policy, folds, fitted, workers, warm=None, ranked=None):
        if move.kind == "structure":
            return _scored((), 3.0)
        names = (set(current.names) - {move.drops}) | set(move.adds)
        tried.append(frozenset(names))
        scale = levels.get(frozenset(names), 2.0)
        s = _scored(tuple(sorted(names)), scale, 8 + len(names))
        # The returned model's prediction: the record less what its level leaves.
        x = record.x - NOISE - scale * np.sin(np.arange(N) * 0.01)
        return Scored(s.fit, x, s.jacobian, s.cv, True, _LEAVEOUT)

    monkeypatch.setattr(search_module, "_candidate", candidate)
    base = candidate(record, _scored((), 0.0), Move("add", ()), None, None, None, None, None)
    tried.clear()
    # Every move fitted (the score screen reads the fits this test replaces).
    conv = Convergence(score=False)
    state = search(record, base, noise_um=0.01, policy=POLICY, conv=conv, workers=1, say=lambda s: None)
    assert set(state.current.names) == {"creep", "input_lag"}
    assert [r.taken.label for r in state.rounds if r.taken] == ["add creep", "add input_lag"]
    assert frozenset() not in tried  # the base model is never proposed again
    assert "noise" in state.stopped or "no move" in state.stopped


def test_two_tied_effects_added_at_once_have_no_rival_when_none_is_within_the_margin():
    current = _scored((), 0.1)
    both = _scored(("resonance", "resonance2"), 0.01, 12)
    lag = _scored(("input_lag",), 0.08, 9)
    round_, state = _round(
        current, [(Move("add_tied", ("resonance", "resonance2")), both), (Move("add", ("input_lag",)), lag)]
    )
    assert round_.taken is not None and round_.taken.move == "add_tied"
    assert state.rivals == {"resonance": set(), "resonance2": set()}


def test_the_other_structure_waits_while_an_input_driven_move_is_accepted():
    # The oscillator predicts best, but an input-driven move is accepted too: that class
    # is still improving, and the structure (which ends the search) waits.
    current = _scored(("resonance",), 0.1, 10)
    osc = _scored((), 0.0, 10)
    lag = _scored(("resonance", "input_lag"), 0.05, 11)
    round_, _ = _round(current, [(Move("structure", (OSCILLATOR,)), osc), (Move("add", ("input_lag",)), lag)])
    assert round_.taken is not None and round_.taken.move == "add" and round_.taken.effects == ("input_lag",)


def test_the_other_structure_taken_keeps_the_input_driven_effects_as_its_rivals():
    current = _scored(("resonance",), 0.1, 10)
    osc = _scored((), 0.0, 10)
    lag = _scored(("resonance", "input_lag"), 0.1, 11, phase=0.3)  # no better than the current model
    round_, state = _round(current, [(Move("structure", (OSCILLATOR,)), osc), (Move("add", ("input_lag",)), lag)])
    assert round_.taken is not None and round_.taken.move == "structure"
    assert OSCILLATOR in state.rivals["resonance"]


def test_another_structure_as_a_rival_sorts_after_the_effects_and_is_never_swapped_in():
    from boucwen.diagnosis.search import rival_order

    assert sorted({"oscillator", "delay", "creep"}, key=rival_order) == ["creep", "delay", "oscillator"]
    moves = proposals(("resonance",), {"resonance": {"oscillator", "creep"}}, 4)
    swaps = [m for m in moves if m.kind == "swap"]
    assert [m.adds for m in swaps] == [("creep",)]
