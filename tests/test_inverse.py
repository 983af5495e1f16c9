"""The inverse model (boucwen.Inverse, boucwen.invert) and the compensator (boucwen.Compensator)."""

import copy
import math
import pickle

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import boucwen
from boucwen import Compensator, EffectSet, Inverse, Params, invert, simulate, simulate_extended
from conftest import regression_case

DT = 1e-4


def tolerance(x_d):
    """The inverse's tolerance [µm] for targets x_d [µm], plus the rounding of the output sum."""
    return boucwen.INVERSE_TOLERANCE_UM * np.maximum(1.0, np.abs(x_d)) + 1e-12


@st.composite
def monotone_params(draw):
    """Parameters whose x(u) rises on both branches away from the kink at the previous
    voltage (a physical actuator), n in [0.3, 3].

    kv + A > 0 with |A| <= 0.4 kv, and 0 < beta + gamma <= beta - gamma: h stays
    bounded and the steepest unloading slope, kv - |A|·(1 + (beta + gamma)/(beta - gamma)),
    stays above 0.2 kv.
    """
    kv = draw(st.floats(0.1, 0.3))
    a = kv * draw(st.floats(-0.4, 0.4))
    diff = draw(st.floats(1e-3, 0.08))
    total = diff * draw(st.floats(0.01, 1.0))
    n = draw(st.floats(0.3, 3.0))
    delta = draw(st.floats(-0.01, 0.01))
    x0 = draw(st.floats(-1.0, 1.0))
    return Params(kv, x0, a, 0.5 * (total + diff), 0.5 * (total - diff), n, delta)


@st.composite
def voltages(draw):
    """A smooth voltage record [V]: one to three sines around an offset, with holds."""
    n = 1500
    t = np.arange(n) * DT
    u = np.full(n, draw(st.floats(20.0, 60.0)))
    for _ in range(draw(st.integers(1, 3))):
        u += draw(st.floats(1.0, 25.0)) * np.sin(2 * np.pi * draw(st.floats(2.0, 150.0)) * t + draw(st.floats(0, 6.3)))
    for _ in range(draw(st.integers(0, 3))):
        lo = draw(st.integers(0, n - 2))
        hi = min(n, lo + draw(st.integers(1, 200)))
        u[lo:hi] = u[lo]
    return u


def assert_missed_only_in_a_step(p, u, x, x_d, *, h0=0.0, exact=None, where=None):
    """Where the model's x misses x_d beyond the tolerance, x_d sat inside a step of
    x(uₖ) that no voltage crosses (the inverse's documented bound): the δ step at the
    kink (at most 2·|δ|·max|u|·Δt), or a jump of the discrete map where the
    integrator's number of sub-steps changes with uₖ (stiff intervals; h near 0 with
    n < 1). In a jump, x(uₖ ∓ ε) − x_d change sign across the returned uₖ, and the miss
    is at most the jump. ``exact``: the inverse's per-sample flag, False on each miss;
    ``where``: the samples checked (default: all)."""
    tol = tolerance(x_d)
    kink = 2 * abs(p.delta) * np.max(np.abs(u)) * DT + tol
    missed = np.abs(x - x_d) > tol
    for k in np.flatnonzero(missed if where is None else missed & where):
        if exact is not None:
            assert not exact[k], k
        if abs(x[k] - x_d[k]) <= kink[k]:
            continue
        eps = 1e-6 * max(1.0, abs(u[k]))
        below, _ = simulate(p, np.append(u[:k], u[k] - eps), DT, h0=h0)
        above, _ = simulate(p, np.append(u[:k], u[k] + eps), DT, h0=h0)
        assert (below[k] - x_d[k]) * (above[k] - x_d[k]) < 0, (k, x[k] - x_d[k])
        assert abs(x[k] - x_d[k]) <= abs(above[k] - below[k]), (k, x[k] - x_d[k])


def _kept(name):
    """A counter-example kept in tests/regressions/, as the round trip's arguments."""
    case = regression_case(name)
    assert case["dt"] == DT
    return {"p": Params(**case["p"]), "u_true": np.array(case["u"]), "h0": case["h0"]}


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=monotone_params(), u_true=voltages(), h0=st.floats(-0.5, 0.5))
# n = 0.3: h crosses 0 at sample 1 060, where x(u) jumps by 7e-6 µm between one and two
# RK4 sub-steps and x_d falls inside the jump (the inverse returns the nearer side).
@example(**_kept("inverse_round_trip_n03"))
def test_round_trip_reproduces_x_d(p, u_true, h0):
    x_d, _ = simulate(p, u_true, DT, h0=h0)
    inv = Inverse(p, DT, h0=h0)
    u = np.empty_like(x_d)
    exact = np.empty(x_d.size, dtype=bool)
    for k, target in enumerate(x_d):
        u[k] = inv.step(float(target))
        exact[k] = inv.status["exact"]
    u_batch, h_final = invert(p, x_d, DT, h0=h0)
    np.testing.assert_array_equal(u_batch, u)
    x, h_sim = simulate(p, u, DT, h0=h0)
    assert h_final == h_sim
    assert_missed_only_in_a_step(p, u, x, x_d, h0=h0, exact=exact)
    # With δ·u < 0 the step at the kink goes down and a target near it may have a root
    # on each side; with n < 1, h = 0 is not Lipschitz and paths through it are not
    # unique. Otherwise the root is unique and the voltages are u_true's.
    if p.delta >= 0 and p.n >= 1:
        np.testing.assert_allclose(u, u_true, atol=1e-3)
        assert np.all(np.abs(x - x_d) <= tolerance(x_d))


def test_round_trip_with_small_n():
    p = Params(0.19, 0.015, -0.072, 0.05, 0.01, 0.45, 0.0075)
    t = np.arange(20_000) * DT
    u_true = 50 - 45 * np.cos(2 * np.pi * 5 * t)
    x_d, _ = simulate(p, u_true, DT)
    u, _ = invert(p, x_d, DT)
    x, _ = simulate(p, u, DT)
    assert np.all(np.abs(x - x_d) <= tolerance(x_d))
    np.testing.assert_allclose(u, u_true, atol=1e-4)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=monotone_params(), u_true=voltages(), lo=st.floats(0.0, 40.0), width=st.floats(10.0, 60.0))
def test_limits_clip_report_and_h_follows_the_clipped_voltage(p, u_true, lo, width):
    hi = lo + width
    x_d, _ = simulate(p, u_true, DT)
    inv = Inverse(p, DT, u_min=lo, u_max=hi)
    u = np.empty_like(x_d)
    clip, exact, residual = [], [], []
    for k, target in enumerate(x_d):
        u[k] = inv.step(float(target))
        s = inv.status
        clip.append(s["clip"])
        exact.append(s["exact"])
        residual.append(s["residual_um"])
    x, h = simulate(p, u, DT)
    assert h == inv.h
    assert np.all((u >= lo) & (u <= hi))
    clip = np.array(clip)
    assert inv.status["clipped_samples"] == int(np.sum(clip != "none"))
    # A clipped sample sits on its limit, and the model falls short of x_d on that side.
    assert np.all(u[clip == "low"] == lo) and np.all(u[clip == "high"] == hi)
    tol = tolerance(x_d)
    assert np.all(x[clip == "high"] <= (x_d + tol)[clip == "high"])
    assert np.all(x[clip == "low"] >= (x_d - tol)[clip == "low"])
    # The reported residual is the simulator's error, sample by sample.
    np.testing.assert_allclose(np.array(residual), x - x_d, atol=1e-9)
    free = clip == "none"
    exact = np.array(exact)
    assert np.all((np.abs(x - x_d) <= tol)[free & exact])
    # Where no limit binds and the root is missed, x_d sat inside a step of x(u).
    assert_missed_only_in_a_step(p, u, x, x_d, exact=np.array(exact), where=clip == "none")


def test_reversal_of_a_slow_sine_costs_at_most_the_step_at_the_kink():
    p = Params.paper_1hz()
    x_d = 9.0 - 8.0 * np.cos(2 * np.pi * np.arange(20_000) * DT)
    inv = Inverse(p, DT)
    u = inv.step_many(x_d)
    x, _ = simulate(p, u, DT)
    err = np.abs(x - x_d)
    tol = tolerance(x_d)
    assert np.all(err <= p.delta * np.abs(u).max() * DT + tol)
    assert 0 < np.sum(err > tol) < 200  # only around the two turns


def test_holds_are_exact():
    p = Params.paper_1hz()
    x_d = np.concatenate([np.linspace(0.0, 8.0, 300), np.full(500, 8.0), np.linspace(8.0, 3.0, 300), np.full(500, 3.0)])
    u, _ = invert(p, x_d, DT)
    x, _ = simulate(p, u, DT)
    assert np.all(np.abs(x - x_d) <= tolerance(x_d))
    assert np.all(np.diff(u[300:800]) == 0.0) and np.all(np.diff(u[1100:]) == 0.0)


def test_step_many_equals_a_loop_and_chunks_equal_one_call():
    p = Params.paper_1hz()
    x_d, _ = simulate(p, boucwen.paper_input(DT, 0.01)[:12_000], DT)
    a, b = Inverse(p, DT, u_min=0.0, u_max=90.0), Inverse(p, DT, u_min=0.0, u_max=90.0)
    many = a.step_many(x_d)
    loop = np.array([b.step(float(v)) for v in x_d])
    np.testing.assert_array_equal(many, loop)
    assert a.status == b.status and a.h == b.h
    whole, h_whole = invert(p, x_d, DT)
    first, h_first = invert(p, x_d[:5000], DT)
    second, h_second = invert(p, x_d[5000:], DT, h0=h_first, u_prev=float(first[-1]))
    # |h|^n is computed afresh at the cut: the same to the last bits.
    np.testing.assert_allclose(np.concatenate([first, second]), whole, rtol=0.0, atol=1e-9)
    assert abs(h_second - h_whole) <= 1e-12


def test_set_params_keeps_h_and_reset_forgets():
    p = Params.paper_1hz()
    inv = Inverse(p, DT, h0=0.2)
    for v in np.linspace(0.0, 5.0, 100):
        inv.step(float(v))
    h = inv.h
    inv.set_params(p.replace(kv=0.2))
    assert inv.h == h and inv.params.kv == 0.2
    inv.reset()
    assert inv.h == 0.2 and inv.status["samples"] == 0


@pytest.mark.parametrize("effects", [None, EffectSet(input_lag={"fc_hz": 650.0}, delay={"samples": 2})])
def test_pickle_and_copy_continue_exactly(effects):
    p = Params.paper_1hz()
    inv = Inverse(p, DT, 0.1, -30.0, 120.0, effects=effects)
    x_d = 9 - 8 * np.cos(2 * np.pi * 20 * np.arange(2000) * DT)
    inv.step_many(x_d[:1000])
    for other in (pickle.loads(pickle.dumps(inv)), copy.copy(inv), copy.deepcopy(inv)):
        assert other.status == inv.status and other.h == inv.h
        assert other.u_min == -30.0 and other.u_max == 120.0 and other.effects == inv.effects
        np.testing.assert_array_equal(other.step_many(x_d[1000:1100]), copy.copy(inv).step_many(x_d[1000:1100]))


def test_extended_inverse_round_trip_through_lag_creep_drift_and_delay():
    p = Params.paper_1hz()
    effects = EffectSet(
        creep={"tau_s": [0.01, 0.1, 1.0], "gain_um_per_v": [0.002, 0.002, 0.002]},
        input_lag={"fc_hz": 650.0},
        drift={"rate_um_per_s": 0.1},
        delay={"samples": 3},
    )
    u_true = 50 - 45 * np.cos(2 * np.pi * 10 * np.arange(5000) * DT)
    x_d = simulate_extended(p, effects, u_true, DT)
    u, _ = invert(p, x_d, DT, effects=effects)
    x = simulate_extended(p, effects, u, DT)
    assert np.all((np.abs(x - x_d) <= tolerance(x_d))[3:-3])
    inv = Inverse(p, DT, effects=effects)
    assert inv.preview_samples == 3


def test_bad_input_raises_and_keeps_state():
    p = Params.paper_1hz()
    inv = Inverse(p, DT, u_min=0.0, u_max=100.0)
    inv.step(1.0)
    state = pickle.dumps(inv)
    with pytest.raises(ValueError, match="x_d"):
        inv.step(math.nan)
    with pytest.raises(ValueError, match="x_d"):
        inv.step_many([1.0, math.inf])
    assert pickle.dumps(inv) == state
    with pytest.raises(ValueError, match="u_max"):
        Inverse(p, DT, u_min=5.0, u_max=1.0)
    with pytest.raises(ValueError, match="u_min"):
        Inverse(p, DT, u_min=math.nan)
    with pytest.raises(ValueError, match="dt"):
        Inverse(p, 0.0)
    with pytest.raises(ValueError, match="resonance"):
        Inverse(p, DT, effects=EffectSet(resonance={"fn_hz": 1000.0, "zeta": 0.1}))
    with pytest.raises(ValueError, match="u_prev"):
        invert(p, [1.0, 2.0], DT, u_prev=0.0, effects=EffectSet(input_lag={"fc_hz": 650.0}))
    with pytest.raises(TypeError):
        invert(p, "1,2", DT)
    with pytest.raises(ValueError, match="1-D"):
        invert(p, np.zeros((2, 2)), DT)


def test_compensator_errors_none_and_status():
    p = Params.paper_1hz()
    comp = Compensator(p, DT, u_min=-30.0, u_max=120.0, ki=100.0)
    assert math.isnan(comp.status["error_um"]) if comp.status["samples"] else True
    u0 = comp.step(1.0)
    assert comp.status["samples"] == 1 and math.isnan(comp.status["error_um"])
    comp.step(2.0, 0.9)
    assert comp.status["error_um"] == pytest.approx(0.1)
    before = copy.copy(comp)
    with pytest.raises(ValueError, match="x_meas"):
        comp.step(3.0, math.nan)
    with pytest.raises(ValueError, match="x_d"):
        comp.step(math.inf, 1.0)
    assert comp.status == before.status and comp.params == before.params
    assert comp.gains["ki"] == 100.0 and comp.gains["integral_limit_um"] is None
    assert u0 == pytest.approx((1.0 - p.x0) / p.kv)
    with pytest.raises(ValueError, match="kp"):
        Compensator(p, DT, kp=math.nan)
    with pytest.raises(ValueError, match="derivative_filter_hz"):
        Compensator(p, DT, kd=1e-4, derivative_filter_hz=0.0)


def test_compensator_adapts_to_a_plant_it_was_not_given():
    """On a model plant with other parameters, the adaptive inverse ends far below the fixed one."""
    truth = Params(0.17, 0.3, -0.06, 0.024, -0.019, 1.52, 0.0075)
    x_d = 10 - 8 * np.cos(2 * np.pi * 10 * np.arange(3000) * DT)

    def last_period_error(adapt: bool) -> float:
        comp = Compensator(Params.paper_1hz(), DT, adapt=adapt)
        plant = boucwen.Model(truth, DT)
        x_meas, err = None, []
        for target in x_d:
            x_meas = plant.step(comp.step(float(target), x_meas))
            err.append(abs(x_meas - target))
        return max(err[-1000:])

    fixed, adaptive = last_period_error(False), last_period_error(True)
    assert fixed > 0.3
    assert adaptive < 0.05 * fixed


def _track_lagged_plant(comp: Compensator, periods: int, refine: int = 0) -> float:
    """A 100 Hz sine through `comp` on the paper's model behind a 650 Hz amplifier lag,
    with `comp.refine(refine)` after every step; the last period's max error [µm]."""
    truth = Params(0.17, 0.3, -0.06, 0.024, -0.019, 1.52, 0.0075)
    model = boucwen.Model(truth, DT)
    # The lag's exact step for a command linear between samples (boucwen.effects.InputLag).
    tau = 1.0 / (2.0 * math.pi * 650.0)
    decay = math.exp(-DT / tau)
    spread = tau / DT * (1.0 - decay)
    x_d = 10 - 8 * np.cos(2 * np.pi * 100 * np.arange(100 * periods) * DT)
    x_meas, err, u_prev, ua = None, [], None, 0.0
    for target in x_d:
        u = comp.step(float(target), x_meas)
        ua = u if u_prev is None else decay * ua + (spread - decay) * u_prev + (1.0 - spread) * u
        u_prev = u
        x_meas = model.step(ua)
        err.append(abs(x_meas - target))
        comp.refine(refine)
    return max(err[-100:])


def test_compensator_on_the_recommended_identifier_inverts_its_lag_on_the_split():
    start = Params.paper_1hz()
    coop = Compensator(start, DT, u_min=-30.0, u_max=120.0, identifier="horizon", refine="cooperative")
    assert (coop.identifier, coop.refine_mode) == ("horizon", "cooperative")
    assert coop.effects is not None and coop.effects.names == ["input_lag"]
    rpem = Compensator(start, DT, u_min=-30.0, u_max=120.0)
    assert (rpem.identifier, rpem.refine_mode, rpem.effects) == ("rpem", None, None)
    starved = _track_lagged_plant(copy.copy(coop), 30)
    refined = _track_lagged_plant(coop, 30, refine=64)
    fc = coop.effects.to_dict()["input_lag"]["fc_hz"]
    assert abs(fc / 650.0 - 1.0) < 0.2, fc
    assert refined < 0.2 * starved and refined < 0.1, (refined, starved)
    assert coop.refine(0) == 0 and rpem.refine(10) == 0
    # Sync: the pass runs in every step, refine does nothing, the result is as good.
    sync = Compensator(start, DT, u_min=-30.0, u_max=120.0, identifier="horizon")
    assert sync.refine_mode == "sync"
    assert _track_lagged_plant(sync, 30, refine=64) < 0.1


def test_compensator_on_a_background_identifier_copies_with_its_own_worker():
    comp = Compensator(Params.paper_1hz(), DT, identifier="horizon", refine="background")
    assert comp.refine_mode == "background"
    _track_lagged_plant(comp, 3)
    twin = copy.deepcopy(comp)
    assert twin.refine_mode == "background" and twin.params == comp.params and twin.h == comp.h
    assert twin.status["samples"] == comp.status["samples"] == 300
    assert math.isfinite(twin.step(5.0, 4.9))


def test_compensator_identifier_choice_is_checked():
    p = Params.paper_1hz()
    with pytest.raises(ValueError, match="identifier"):
        Compensator(p, DT, identifier="paper")
    with pytest.raises(ValueError, match="rpem"):
        Compensator(p, DT, refine="cooperative")
    with pytest.raises(ValueError, match="refine"):
        Compensator(p, DT, identifier="horizon", refine="later")
    comp = Compensator(p, DT, identifier="horizon", refine="cooperative")
    with pytest.raises(ValueError, match="max_intervals"):
        comp.refine(-1)
