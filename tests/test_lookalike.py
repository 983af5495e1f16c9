"""The look-alike tests on a model's residual (boucwen.residual.lookalike): evidence, named
by signature."""

import numpy as np
import pytest

import boucwen
from boucwen.effects import effect_class
from boucwen.experiments.undeclared_records import PARAM_SETS
from boucwen.experiments.undeclared_records import test_input as make_input  # not a test
from boucwen.record import validate_record
from boucwen.residual.lookalike import lookalike_tests, named, phase_shape, what_it_follows


@pytest.fixture(scope="module")
def smooth_record():
    dt = 2e-4
    t = np.arange(20000) * dt
    u = 50 + 30 * np.sin(2 * np.pi * 3 * t) + 10 * np.sin(2 * np.pi * 41 * t) + 5 * np.sin(2 * np.pi * 97 * t)
    x = boucwen.simulate_extended(PARAM_SETS["paper_1hz"], boucwen.EffectSet(), u, dt)
    return u, x, dt


def test_creep_follows_u_and_drift_follows_time():
    u = make_input(seed=1)
    dt = 1e-3
    xm = boucwen.simulate_extended(PARAM_SETS["paper_1hz"], boucwen.EffectSet(), u, dt)
    t = np.arange(u.size) * dt
    drifting = validate_record(u, xm + 0.2 * t, dt)
    assert what_it_follows(drifting, xm)["follows"] == effect_class("drift").signature == "t"
    creep = boucwen.EffectSet(creep={"tau_s": [0.3, 3.0], "gain_um_per_v": [0.004, 0.004]})
    creeping = validate_record(u, boucwen.simulate_extended(PARAM_SETS["paper_1hz"], creep, u, dt), dt)
    assert what_it_follows(creeping, xm)["follows"] == effect_class("creep").signature
    gain = validate_record(u, xm + 0.05 * t * (xm - xm.mean()), dt)
    assert what_it_follows(gain, xm)["follows"] == effect_class("gain_drift").signature


@pytest.mark.parametrize(
    "effects, shape",
    [
        ({"delay": {"samples": 3}}, "delay"),
        ({"input_lag": {"fc_hz": 120.0}}, "input_lag"),
        ({"resonance": {"fn_hz": 150.0, "zeta": 0.05}}, "resonance"),
    ],
)
def test_phase_shape_tells_delay_lag_and_resonance_apart(smooth_record, effects, shape):
    u, xm, dt = smooth_record
    x = boucwen.simulate_extended(PARAM_SETS["paper_1hz"], boucwen.EffectSet(**effects), u, dt)
    out = phase_shape(validate_record(u, x, dt), xm)
    assert out["shape"] == effect_class(shape).signature, out
    if shape == "delay":
        assert out["delay_s"] == pytest.approx(3 * dt, rel=0.1)


@pytest.mark.parametrize(
    "effects, apart",
    [
        ({"input_lag": {"fc_hz": 120.0}}, True),
        ({"delay": {"samples": 3}}, True),
        ({"input_lag": {"fc_hz": 3000.0}}, False),
        ({"delay": {"samples": 1}}, False),
    ],
)
def test_a_lag_far_above_the_band_is_not_told_from_a_delay(smooth_record, effects, apart):
    # Below its corner a lag turns the phase by f/fc, as a delay of 1/(2π·fc) does: with
    # the input's lines at 3–97 Hz, a lag at 3 kHz and a delay of one sample (0.2 ms)
    # fit the phase alike; a lag at 120 Hz and a delay of three samples do not.
    u, xm, dt = smooth_record
    x = boucwen.simulate_extended(PARAM_SETS["paper_1hz"], boucwen.EffectSet(**effects), u, dt)
    noise = 0.005 * np.random.default_rng(0).standard_normal(u.size)
    out = phase_shape(validate_record(u, x + noise, dt), xm)
    assert out["lag_or_delay_apart"] is apart
    assert named({"phase": out}) == ({out["shape"]} if apart else set())


def test_lookalike_tests_are_json_ready(smooth_record):
    u, xm, dt = smooth_record
    out = lookalike_tests(validate_record(u, xm, dt), xm)
    assert set(out) == {"follows", "phase"}
    assert out["phase"]["shape"] == "none"
