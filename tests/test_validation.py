"""Blocked cross-validation and the look-alike tests of the diagnosis."""

import numpy as np
import pytest
from scipy.optimize import least_squares

import boucwen
from boucwen.diagnosis.lookalike import lookalike_tests, named, phase_shape, what_it_follows
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
    assert named(out, ("delay", "input_lag")) == (out["shape"] if apart else "none")
    assert named(out, ("delay", "resonance")) == out["shape"]


def test_lookalike_tests_are_json_ready(smooth_record):
    u, xm, dt = smooth_record
    out = lookalike_tests(validate_record(u, xm, dt), xm)
    assert set(out) == {"follows", "phase"}
    assert out["phase"]["shape"] == "none"


@pytest.mark.parametrize("chirp", [0.005, 0.01])
def test_a_simulated_refit_step_scores_a_nonlinear_unknown_as_a_refit_would(chirp):
    # y = a·sin(ω t) fitted to a sine whose frequency moves by ±chirp over 10 s: each
    # block asks for its own ω, and over 50 cycles the straight line through the
    # Jacobian mispredicts what that ω does to the held-out block.
    rng = np.random.default_rng(3)
    n = 4000
    t = np.linspace(0.0, 10.0, n)
    w0 = 2 * np.pi * 5.0
    y = np.sin(w0 * (1 + chirp * (t - 5.0) / 5.0) * t) + rng.normal(0.0, 0.05, n)

    def model(z):
        return z[0] * np.sin(z[1] * t)

    z = least_squares(lambda v: y - model(v), [1.0, w0]).x
    jac = np.column_stack([np.sin(z[1] * t), z[0] * t * np.cos(z[1] * t)])
    linear = blocked_cv(jac, y - model(z), folds=4)
    simulated = blocked_cv(jac, y - model(z), folds=4, simulate=lambda dz: y - model(z + dz))
    held = np.empty(n)  # leave-a-block-out refits by least squares, for reference
    for sl in fold_slices(n, 4):
        keep = np.ones(n, dtype=bool)
        keep[sl] = False
        fitted = least_squares(lambda v, keep=keep: (y - model(v))[keep], z).x
        held[sl] = (y - model(fitted))[sl]
    exact = float(np.sqrt(np.mean(held**2)))
    assert abs(simulated.rms_um - exact) < 0.2 * abs(linear.rms_um - exact), (linear.rms_um, simulated.rms_um, exact)


def test_a_simulated_step_that_helps_no_other_block_keeps_the_fit():
    rng = np.random.default_rng(4)
    n = 1000
    design = np.column_stack([np.ones(n), np.linspace(0.0, 1.0, n)])
    y = design @ [0.5, 1.0] + rng.normal(0.0, 0.1, n)
    fitted, *_ = np.linalg.lstsq(design, y, rcond=None)
    r = y - design @ fitted
    # A model that cannot be simulated anywhere but at the fit keeps the fit's residual.
    cv = blocked_cv(design, r, folds=4, simulate=lambda dz: None)
    np.testing.assert_array_equal(cv.residual, r)
    # For a linear model the simulated step is the linear one.
    lin = blocked_cv(design, r, folds=4)
    sim = blocked_cv(design, r, folds=4, simulate=lambda dz: y - design @ (fitted + dz))
    np.testing.assert_allclose(sim.residual, lin.residual, atol=1e-12)
