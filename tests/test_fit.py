"""boucwen.fit: the traditional (offline, output-error) identification."""

import dataclasses

import numpy as np
import pytest

import boucwen
from boucwen import FitResult, Params, fit, simulate

TRUE = Params.paper_1hz()
DT = 5e-4  # 2 kHz keeps the tests fast; the fit does not depend on the rate


def paper_record(periods=3, h0=0.0, params=TRUE, dt=DT):
    """u = 50 − 50·cos(2πt) [V] at 1 Hz and the model's noise-free x [µm]."""
    t = np.arange(round(periods / dt)) * dt
    u = 50.0 - 50.0 * np.cos(2.0 * np.pi * t)
    x, _ = simulate(params, u, dt, h0)
    return u, np.asarray(x)


def rel_err(p, q):
    a, b = p.to_dict(), q.to_dict()
    return {k: abs(a[k] - b[k]) / abs(b[k]) for k in a}


def test_exports():
    assert boucwen.fit is fit
    assert boucwen.FitResult is FitResult


def test_noise_free_recovers_parameters_and_h0():
    # h0 = 0.5 µm: the initial transient is what makes h0 identifiable.
    u, x = paper_record(h0=0.5)
    r = fit(u, x, DT)
    assert r.success, r.message
    # Noise-free data: the output error must vanish to the optimiser's tolerance
    # (1e-6 µm is ~1e-7 of the 17.6 µm stroke).
    assert r.rms_um < 1e-6 and r.max_um < 1e-5
    # Parameters to 1e-5 relative (x0 is 0.015 µm, so 1e-5 relative is 0.15 pm... use abs).
    err = rel_err(r.params, TRUE)
    for name in ("kv", "A", "beta", "gamma", "n", "delta"):
        assert err[name] < 1e-5, (name, err)
    assert abs(r.params.x0 - TRUE.x0) < 1e-5
    assert abs(r.h0 - 0.5) < 1e-5
    np.testing.assert_allclose(r.x_fit, x, atol=1e-5)


def test_noisy_data_within_tolerance():
    # 10 nm white noise (5x the vibrometer's resolution) on 6000 samples.
    u, x = paper_record()
    rng = np.random.default_rng(5)
    sigma = 0.01
    r = fit(u, x + sigma * rng.standard_normal(x.size), DT)
    assert r.success, r.message
    # The residual is the noise: RMS within 10 % of sigma.
    assert 0.9 * sigma < r.rms_um < 1.1 * sigma
    # The fitted model reproduces the noise-free displacement to 10 nm (the noise level).
    assert np.max(np.abs(r.x_fit - x)) < 0.01
    # Parameters: 2 % for kv, A, β, γ, n; 10 % for δ (the smallest effect); x0, h0 to 20 nm.
    err = rel_err(r.params, TRUE)
    for name in ("kv", "A", "beta", "gamma", "n"):
        assert err[name] < 0.02, (name, err)
    assert err["delta"] < 0.10, err
    assert abs(r.params.x0 - TRUE.x0) < 0.02
    assert abs(r.h0) < 0.02


def test_result_does_not_depend_on_the_random_starts():
    u, x = paper_record(periods=2)
    a = fit(u, x, DT, seed=1)
    b = fit(u, x, DT, seed=7, n_starts=2, n_candidates=8)
    for name in ("kv", "A", "beta", "gamma", "n", "delta"):
        assert rel_err(a.params, b.params)[name] < 1e-5


def test_init_far_from_truth_and_no_global_stage():
    # Only the given start, 30 % off in every nonlinear parameter.
    u, x = paper_record(periods=2)
    init = TRUE.replace(A=-0.05, beta=0.026, gamma=-0.013, n=1.9, delta=0.005)
    r = fit(u, x, DT, init=init, n_candidates=0)
    assert r.rms_um < 1e-5
    assert rel_err(r.params, TRUE)["n"] < 1e-4


def test_fixed_h0():
    u, x = paper_record(periods=2, h0=0.0)
    r = fit(u, x, DT, h0=0.0)
    assert r.h0 == 0.0
    assert r.rms_um < 1e-6


def test_result_type():
    u, x = paper_record(periods=1)
    r = fit(u, x, DT, n_starts=1, n_candidates=4)
    assert isinstance(r, FitResult) and isinstance(r.params, Params)
    assert r.x_fit.shape == x.shape and r.nfev > 0 and isinstance(r.message, str)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.h0 = 1.0
    d = r.to_dict()
    assert set(d["params"]) == {"kv", "x0", "A", "beta", "gamma", "n", "delta"}
    assert d["rms_um"] == r.rms_um
    assert "FitResult(" in repr(r)


def test_bench_record_fits_to_its_noise():
    # The simulated bench at 1 Hz without the effects that are there to defeat a
    # one-frequency fit (floor vibration, electrostriction): its creep and amplifier
    # lag are not in the model either, but at 1 Hz the fit absorbs them and the
    # residual stays near the measurement noise (0.1 µm bound).
    from boucwen import plant

    _, u, _ = plant.paper_input(1e-4, [(1.0, 1.0)])
    settings = plant.BenchSettings(vibration_um=(0.0, 0.0), stroke_quadratic_per_um=0.0)
    rec = plant.measure(u, settings=settings)
    r = fit(rec.u, rec.x, rec.dt)
    assert r.success
    assert r.max_um < 0.1


@pytest.mark.parametrize(
    "u, x, dt, exc",
    [
        ([0.0, 1.0, 2.0] * 10, [0.0] * 29, 1e-3, ValueError),  # lengths differ
        (np.zeros((4, 8)), np.zeros((4, 8)), 1e-3, ValueError),  # not 1-D
        (["a"] * 20, [0.0] * 20, 1e-3, TypeError),  # not numbers
        ([0.0, np.nan] * 10, [0.0] * 20, 1e-3, ValueError),  # NaN
        (np.linspace(0, 1, 20), np.zeros(20), 0.0, ValueError),  # dt = 0
        (np.linspace(0, 1, 20), np.zeros(20), -1e-3, ValueError),  # dt < 0
        (np.linspace(0, 1, 20), np.zeros(20), "0.1", TypeError),  # dt not a number
        (np.ones(20), np.zeros(20), 1e-3, ValueError),  # constant u
        (np.linspace(0, 1, 5), np.zeros(5), 1e-3, ValueError),  # too short
    ],
)
def test_bad_input(u, x, dt, exc):
    with pytest.raises(exc):
        fit(u, x, dt)


def test_bad_options():
    u, x = paper_record(periods=1)
    with pytest.raises(TypeError):
        fit(u, x, DT, init=[0.19, 0.0, -0.07, 0.02, -0.02, 1.5, 0.007])
    with pytest.raises(ValueError):
        fit(u, x, DT, n_starts=0)
    with pytest.raises(ValueError):
        fit(u, x, DT, h0=float("nan"))
    with pytest.raises(ValueError):
        fit(u, x, DT, decimate=0)


def test_the_trf_solver_reaches_the_same_fit_and_a_bad_method_is_refused():
    u = np.asarray(boucwen.paper_input(1e-4, 0.05))[:12_000]
    x = boucwen.simulate(Params.paper_1hz(), u, 1e-4)[0] + 2e-3 * np.random.default_rng(3).standard_normal(u.size)
    lm = boucwen.fit(u, x, 1e-4)
    trf = boucwen.fit(u, x, 1e-4, method="trf")
    # Both at the noise: the same optimum within the statistical margin's share of it.
    assert lm.rms_um == pytest.approx(trf.rms_um, rel=1e-4)
    assert lm.rms_um == pytest.approx(2e-3, rel=0.05)
    with pytest.raises(boucwen.InvalidConfig, match="method"):
        boucwen.fit(u, x, 1e-4, method="newton")
