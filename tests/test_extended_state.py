"""simulate_extended continues from an ExtendedState: a record in pieces is the record in one call."""

import math
import pickle

import numpy as np
import pytest

from boucwen import EffectSet, ExtendedState, Params, paper_input, simulate_extended
from conftest import WHOLE_VOCABULARY

P = Params.paper_1hz()
DT = 1e-4
# Every effect with a state (lag, creep, two modes, delay) and the time-dependent ones.
STATEFUL = EffectSet(**{k: v for k, v in WHOLE_VOCABULARY.items() if k != "saturation"})


@pytest.mark.parametrize("effects", [None, STATEFUL, EffectSet(**WHOLE_VOCABULARY)])
def test_a_record_in_pieces_is_the_record_in_one_call_bit_for_bit(effects):
    u = paper_input(DT, 0.01)
    whole = simulate_extended(P, effects, u, DT, 0.3)
    cuts = [0, 1, 12_345, 33_100, 33_101, u.size]
    state = ExtendedState(0.3)
    pieces = []
    for a, b in zip(cuts, cuts[1:]):
        x, state = simulate_extended(P, effects, u[a:b], DT, state=state)
        pieces.append(x)
    assert np.array_equal(np.concatenate(pieces), whole)
    assert state.samples == u.size and state.u_prev == u[-1]


def test_the_state_names_its_parts_and_pickles():
    start = ExtendedState(0.25)
    assert start.samples == 0 and start.u_prev is None and start.h == 0.25 and start.creep == []
    u = paper_input(DT, 0.0)
    _, state = simulate_extended(P, STATEFUL, u[:500], DT, state=start)
    assert len(state.creep) == len(WHOLE_VOCABULARY["creep"]["tau_s"])
    assert len(state.delay) == WHOLE_VOCABULARY["delay"]["samples"] + 1
    assert state.u_prev == u[499] and math.isfinite(state.h) and "samples=500" in repr(state)
    again = pickle.loads(pickle.dumps(state))
    assert again == state and again != start
    rest = u[500:900]
    x_again, _ = simulate_extended(P, STATEFUL, rest, DT, state=again)
    x_state, _ = simulate_extended(P, STATEFUL, rest, DT, state=state)
    assert np.array_equal(x_again, x_state)


def test_a_state_that_does_not_fit_is_a_value_error():
    u = paper_input(DT, 0.0)[:50]
    _, state = simulate_extended(P, STATEFUL, u, DT, state=ExtendedState())
    with pytest.raises(ValueError, match=r"state\.creep"):
        simulate_extended(P, None, u, DT, state=state)
    with pytest.raises(ValueError, match="exclusive"):
        simulate_extended(P, STATEFUL, u, DT, 0.1, state=state)
    with pytest.raises(ValueError, match="h0"):
        ExtendedState(math.nan)
    with pytest.raises(ValueError, match=r"state\.samples"):
        ExtendedState._restore(3, None, 0.0, 0.0, None, [], 0.0, (0.0, 0.0), (0.0, 0.0), [])
    with pytest.raises(TypeError):
        simulate_extended(P, None, u, DT, state=0.0)  # type: ignore[call-overload]
