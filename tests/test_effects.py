"""EffectSet, simulate_extended and fit_extended."""

import math
import pickle

import numpy as np
import pytest

from boucwen import EffectSet, Params, simulate, simulate_extended
from boucwen.effects import Layout, best_delay, creep_time_constants, fit_extended
from boucwen.record import validate_record
from conftest import EVERY_EFFECT, WHOLE_VOCABULARY

P = Params.paper_1hz()
DT = 1e-3


def _u(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    return 50 + 45 * np.sin(2 * np.pi * 2 * t) * np.cos(2 * np.pi * 0.3 * t) + rng.normal(0, 0.01, n)


ALL = EVERY_EFFECT


def test_round_trips_and_vocabulary():
    e = EffectSet(**ALL)
    assert e.names == ["creep", "input_lag", "resonance", "drift", "delay"]
    assert EffectSet.vocabulary == [
        *["creep", "input_lag", "gain_drift", "electrostriction", "resonance", "resonance2"],
        *["drift", "delay", "pickup", "saturation", "between_samples"],
    ]
    whole = EffectSet(**WHOLE_VOCABULARY)
    assert whole.names == EffectSet.vocabulary
    assert EffectSet.from_dict(whole.to_dict()) == whole and pickle.loads(pickle.dumps(whole)) == whole
    assert EffectSet.from_dict(e.to_dict()) == e
    assert pickle.loads(pickle.dumps(e)) == e
    assert eval(repr(e), {"EffectSet": EffectSet}) == e
    assert len(EffectSet()) == 0 and "drift" in e


@pytest.mark.parametrize(
    "kw, words",
    [
        (dict(input_lag={"fc_hz": 0.0}), "input_lag.fc_hz"),
        (dict(input_lag={"fc_hz": math.nan}), "input_lag.fc_hz"),
        (dict(resonance={"fn_hz": 100.0, "zeta": -0.1}), "resonance.zeta"),
        (dict(resonance={"fn_hz": -5.0, "zeta": 0.1}), "resonance.fn_hz"),
        (dict(delay={"samples": -1}), "delay.samples"),
        (dict(drift={"rate_um_per_s": math.inf}), "drift.rate_um_per_s"),
        (dict(creep={"tau_s": [1.0, 2.0], "gain_um_per_v": [0.1]}), "creep.gain_um_per_v"),
        (dict(creep={"tau_s": [0.0], "gain_um_per_v": [0.1]}), "creep.tau_s"),
        (dict(drift={"rate": 1.0}), "unknown parameter"),
        (dict(resonance={"fn_hz": 100.0}), "missing parameter"),
    ],
)
def test_invalid_parameters_name_the_culprit(kw, words):
    with pytest.raises(ValueError, match=words.replace(".", r"\.")):
        EffectSet(**kw)


def test_bad_types_raise_type_error():
    with pytest.raises(TypeError):
        EffectSet(drift=1.0)
    with pytest.raises(TypeError):
        EffectSet(delay={"samples": 1.5})
    with pytest.raises(ValueError, match="unknown effect"):
        EffectSet.from_dict({"hum": {}})


def test_resonance_above_nyquist_is_rejected_at_simulation():
    e = EffectSet(resonance={"fn_hz": 600.0, "zeta": 0.1})
    with pytest.raises(ValueError, match="Nyquist"):
        simulate_extended(P, e, _u(100), DT)


def test_no_effect_equals_simulate_and_delay_shifts():
    u = _u()
    base, _ = simulate(P, u, DT)
    np.testing.assert_array_equal(simulate_extended(P, EffectSet(), u, DT), base)
    np.testing.assert_array_equal(simulate_extended(P, None, u, DT), base)
    x = simulate_extended(P, EffectSet(delay={"samples": 3}, drift={"rate_um_per_s": 0.5}), u, DT)
    np.testing.assert_allclose(x[3:], base[:-3] + 0.5 * np.arange(u.size - 3) * DT, atol=1e-12)


def test_creep_step_response_matches_the_closed_form():
    # Linear core (A = β = γ = δ = 0) so that x = kv·u + creep exactly.
    p = Params(0.2, 0.0, 0.0, 0.0, 0.0, 1.5, 0.0)
    e = EffectSet(creep={"tau_s": [0.05, 0.5], "gain_um_per_v": [0.01, 0.02]})
    u = np.r_[0.0, np.full(2000, 10.0)]
    x = simulate_extended(p, e, u, DT)
    # The step takes one interval (a ramp); afterwards each element relaxes as exp(−t/τ).
    t = np.arange(1, u.size) * DT - DT

    # After the ramp an element is short of its final value g·10 by the share
    # τ/dt·(1 − exp(−dt/τ)) (exact solution of τ·ċ = g·u − c for a ramp of u).
    def short(tau):
        return tau / DT * (1 - math.exp(-DT / tau))

    want = 2.0 + sum(10 * g * (1 - short(tau) * np.exp(-t / tau)) for tau, g in ((0.05, 0.01), (0.5, 0.02)))
    np.testing.assert_allclose(x[1:], want, atol=1e-9)


def test_input_lag_gain_at_a_sine_matches_first_order():
    p = Params(1.0, 0.0, 0.0, 0.0, 0.0, 1.5, 0.0)
    f, fc = 40.0, 80.0
    t = np.arange(20000) * 1e-4
    u = np.sin(2 * np.pi * f * t)
    x = simulate_extended(p, EffectSet(input_lag={"fc_hz": fc}), u, 1e-4)
    amp = np.ptp(x[10000:]) / 2
    assert amp == pytest.approx(1 / math.sqrt(1 + (f / fc) ** 2), rel=2e-3)


def test_resonance_peak_gain_matches_second_order():
    p = Params(1.0, 0.0, 0.0, 0.0, 0.0, 1.5, 0.0)
    fn, zeta = 100.0, 0.05
    t = np.arange(40000) * 1e-4
    u = np.sin(2 * np.pi * fn * t)
    x = simulate_extended(p, EffectSet(resonance={"fn_hz": fn, "zeta": zeta}), u, 1e-4)
    assert np.ptp(x[30000:]) / 2 == pytest.approx(1 / (2 * zeta), rel=5e-3)


def test_output_is_finite_for_any_valid_effects():
    rng = np.random.default_rng(3)
    u = _u(800)
    for _ in range(20):
        e = EffectSet(
            input_lag={"fc_hz": float(np.exp(rng.uniform(-2, 8)))},
            resonance={"fn_hz": float(rng.uniform(0.1, 499)), "zeta": float(np.exp(rng.uniform(-7, 2)))},
            creep={"tau_s": list(np.exp(rng.uniform(-8, 3, 3))), "gain_um_per_v": list(rng.normal(0, 1, 3))},
        )
        assert np.all(np.isfinite(simulate_extended(P, e, u, DT)))


def test_layout_round_trips():
    e = EffectSet(**ALL)
    lay = Layout.of(e, DT, 3.0)
    v = lay.pack(P, e, 0.1)
    p2, e2, h0 = lay.unpack(v)
    assert p2 == P and h0 == 0.1
    assert e2.to_dict()["resonance"]["fn_hz"] == pytest.approx(150.0)
    assert len(v) == len(lay.labels())


def test_creep_time_constants_span_the_record():
    taus = creep_time_constants(1e-3, 5.0)
    # None slower than the record: a slower one is the record's trend.
    assert taus[0] == pytest.approx(0.01) and taus[-1] == pytest.approx(5.0)
    assert 2 <= len(taus) <= 10
    # Two per decade: 0.01 … 5 s spans 2.7 decades, 6 elements.
    assert len(taus) == 6
    assert np.allclose(np.diff(np.log10(taus)), np.log10(500.0) / 5)


def test_fit_extended_recovers_known_effects():
    u = _u(4000)
    truth = EffectSet(input_lag={"fc_hz": 60.0}, drift={"rate_um_per_s": -0.15})
    x = simulate_extended(P, truth, u, DT) + np.random.default_rng(1).normal(0, 0.002, u.size)
    start = EffectSet(input_lag={"fc_hz": 200.0}, drift={"rate_um_per_s": 0.0})
    r = fit_extended(u, x, DT, P.replace(kv=0.17), start, 0.0)
    d = r.effects.to_dict()
    assert d["input_lag"]["fc_hz"] == pytest.approx(60.0, rel=0.05)
    assert d["drift"]["rate_um_per_s"] == pytest.approx(-0.15, abs=0.01)
    assert r.rms_um < 0.003


def test_a_refit_keeps_creep_that_carries_the_gain_while_kv_is_negative():
    # A fast creep element carrying the gain with kv < 0 (as a fit mimicking a lag can
    # end): the static gain kv + Σg is positive, so the creep gains' sign bounds are
    # the positive ones and the refit starts where it is, at the truth, instead of
    # having its gains clipped to zero (an error of several µm).
    u = _u(3000)
    p = P.replace(kv=-0.04)
    creep = EffectSet(creep={"tau_s": [0.01, 0.3], "gain_um_per_v": [0.2, 0.01]})
    x = simulate_extended(p, creep, u, DT) + np.random.default_rng(2).normal(0, 0.002, u.size)
    r = fit_extended(u, x, DT, p, creep, 0.0, max_nfev=5)
    assert r.rms_um < 0.003
    assert min(r.effects.to_dict()["creep"]["gain_um_per_v"]) > 0


def test_best_delay_finds_the_shift():
    u = _u(2000)
    x = simulate_extended(P, EffectSet(delay={"samples": 3}), u, DT)
    d, rms = best_delay(validate_record(u, x, DT), P, EffectSet(), 0.0, 6)
    assert d == 3 and rms[3] < 1e-9 < rms[2]
