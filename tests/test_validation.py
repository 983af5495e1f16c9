"""Blocked cross-validation and the look-alike tests of the diagnosis."""

import numpy as np
import pytest

import boucwen
from boucwen.diagnosis.lookalike import lookalike_tests, phase_shape, what_it_follows
from boucwen.diagnosis.validation import blocked_cv, fold_slices
from boucwen.experiments.undeclared_records import PARAM_SETS
from boucwen.experiments.undeclared_records import test_input as make_input  # not a test
from boucwen.record import validate_record


def test_fold_slices_cover_the_record_once():
    slices = fold_slices(1003, 4)
    assert [s.start for s in slices] == [0, *[s.stop for s in slices[:-1]]]
    assert slices[-1].stop == 1003
    assert max(s.stop - s.start for s in slices) - min(s.stop - s.start for s in slices) <= 1


def test_blocked_cv_is_the_refit_without_each_block_for_a_linear_model():
    rng = np.random.default_rng(0)
    n = 4000
    t = np.linspace(0.0, 1.0, n)
    design = np.column_stack([np.ones(n), t, np.sin(7 * t)])
    y = design @ [1.0, -2.0, 0.5] + rng.normal(0.0, 0.1, n)
    fitted, *_ = np.linalg.lstsq(design, y, rcond=None)
    cv = blocked_cv(design, y - design @ fitted, folds=4)
    exact = np.empty(n)
    for sl in fold_slices(n, 4):
        keep = np.ones(n, dtype=bool)
        keep[sl] = False
        beta, *_ = np.linalg.lstsq(design[keep], y[keep], rcond=None)
        exact[sl] = y[sl] - design[sl] @ beta
    assert cv.rms_um == pytest.approx(float(np.sqrt(np.mean(exact**2))), rel=0.02)
    assert cv.rms_um > cv.in_sample_rms_um
    # A column that only fits noise earns nothing held out.
    noise_col = np.column_stack([design, rng.normal(size=n)])
    fitted2, *_ = np.linalg.lstsq(noise_col, y, rcond=None)
    cv2 = blocked_cv(noise_col, y - noise_col @ fitted2, folds=4)
    assert cv2.in_sample_rms_um < cv.in_sample_rms_um
    assert cv2.rms_um > 0.999 * cv.rms_um


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
    assert what_it_follows(drifting, xm)["follows"] == "drift"
    creep = boucwen.EffectSet(creep={"tau_s": [0.3, 3.0], "gain_um_per_v": [0.004, 0.004]})
    creeping = validate_record(u, boucwen.simulate_extended(PARAM_SETS["paper_1hz"], creep, u, dt), dt)
    assert what_it_follows(creeping, xm)["follows"] == "creep"
    gain = validate_record(u, xm + 0.05 * t * (xm - xm.mean()), dt)
    assert what_it_follows(gain, xm)["follows"] == "gain_drift"


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
    assert out["shape"] == shape, out
    if shape == "delay":
        assert out["delay_s"] == pytest.approx(3 * dt, rel=0.1)


def test_lookalike_tests_are_json_ready(smooth_record):
    u, xm, dt = smooth_record
    out = lookalike_tests(validate_record(u, xm, dt), xm)
    assert set(out) == {"follows", "phase"}
    assert out["phase"]["shape"] == "none"
