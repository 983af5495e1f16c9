"""The effects beyond the first five: gain_drift, electrostriction, resonance2, pickup,
saturation. Each simulated against a direct NumPy computation of its formula, and
recovered by the extended fit from a simulated record (tolerances in each test)."""

import math

import numpy as np
import pytest
from scipy import signal

from boucwen import EffectSet, Params, simulate_extended
from boucwen.effects import fit_extended
from boucwen.plant import BenchSettings, true_displacement

P = Params.paper_1hz()
DT = 1e-3
NOISE = 0.002


def _u(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    return 50 + 45 * np.sin(2 * np.pi * 2 * t) * np.cos(2 * np.pi * 0.3 * t) + rng.normal(0, 0.01, n)


def _h(u, dt=DT, p=P):
    """The base model's hysteresis state h [µm] along u."""
    return simulate_extended(p, None, u, dt) - p.kv * u - p.x0


def _noisy(x, seed=1):
    return x + np.random.default_rng(seed).normal(0, NOISE, x.size)


def test_gain_drift_and_electrostriction_are_their_formulas():
    u = _u()
    t = np.arange(u.size) * DT
    r, eps = 0.03, 0.004
    x = simulate_extended(P, EffectSet(gain_drift={"rate_per_s": r}, electrostriction={"epsilon_per_um": eps}), u, DT)
    s = P.kv * (1 + r * t) * u + _h(u)
    np.testing.assert_allclose(x, P.x0 + s + eps * s**2, rtol=0, atol=1e-12)


def test_electrostriction_explains_the_benchs_stroke_map():
    # The bench with its electrostriction alone (no lag, creep, vibration or noise).
    bench = BenchSettings(amplifier_fc_hz=math.inf, creep_gain_um_per_v=(0.0,) * 4, vibration_um=(0.0, 0.0))
    u = _u(4000)
    truth = true_displacement(u, DT, bench)
    p = bench.params()
    plain = simulate_extended(p, None, u, DT)
    model = simulate_extended(p, EffectSet(electrostriction={"epsilon_per_um": bench.stroke_quadratic_per_um}), u, DT)
    # The bench integrates h on a 4× finer grid: that, not the stroke map, is the rest.
    assert np.max(np.abs(model - truth)) < 1e-6 < 0.1 < np.max(np.abs(plain - truth))


def test_pickup_and_saturation_are_their_formulas():
    u = _u()
    t = np.arange(u.size) * DT
    base = simulate_extended(P, None, u, DT)
    a, b = [0.05, 0.0, 0.01], [-0.02, 0.03, 0.0]
    e = EffectSet(pickup={"line_hz": 60.0, "sin_um": a, "cos_um": b}, saturation={"min_um": 3.0, "max_um": 14.0})
    x = simulate_extended(P, e, u, DT)
    line = sum(
        a[k] * np.sin(2 * np.pi * (k + 1) * 60.0 * t) + b[k] * np.cos(2 * np.pi * (k + 1) * 60.0 * t) for k in range(3)
    )
    np.testing.assert_allclose(x, np.clip(base + line, 3.0, 14.0), rtol=0, atol=1e-11)
    with pytest.raises(ValueError, match=r"pickup\.line_hz.*Nyquist"):
        simulate_extended(P, EffectSet(pickup={"line_hz": 200.0, "sin_um": a, "cos_um": b}), u, DT)


def test_two_modes_are_the_fourth_order_cascade():
    p = Params(0.2, 0.0, 0.0, 0.0, 0.0, 1.5, 0.0)  # linear core: y = kv·u
    modes = [(80.0, 0.1), (250.0, 0.05)]
    u = np.r_[np.zeros(50), np.linspace(0, 40, 30), np.full(400, 40.0), 40 + 20 * np.sin(np.arange(1500) * 0.05)]
    x = simulate_extended(
        p,
        EffectSet(resonance=dict(zip(("fn_hz", "zeta"), modes[0])), resonance2=dict(zip(("fn_hz", "zeta"), modes[1]))),
        u,
        DT,
    )
    num, den = [1.0], [1.0]
    for fn, zeta in modes:
        w = 2 * np.pi * fn
        num, den = np.polymul(num, [w * w]), np.polymul(den, [1.0, 2 * zeta * w, w * w])
    t = np.arange(u.size) * DT
    _, want, _ = signal.lsim((num, den), 0.2 * u, t)  # first-order hold of y: exact
    # The second mode's input is a straight line per quarter sample: 1e-4 of the 8 µm step.
    assert np.max(np.abs(x - want)) < 1e-3, np.max(np.abs(x - want))
    alone = EffectSet(resonance2={"fn_hz": 80.0, "zeta": 0.1})
    np.testing.assert_array_equal(
        simulate_extended(p, alone, u, DT),
        simulate_extended(p, EffectSet(resonance={"fn_hz": 80.0, "zeta": 0.1}), u, DT),
    )


START = P.replace(kv=0.18)


def _fit(truth, start, u=None, params=START):
    u = _u() if u is None else u
    x = _noisy(simulate_extended(P, EffectSet(**truth), u, DT))
    r = fit_extended(u, x, DT, params, EffectSet(**start), 0.0, max_nfev=60)
    return r, r.effects.to_dict()


def test_fit_recovers_gain_drift_and_electrostriction():
    truth = dict(gain_drift={"rate_per_s": 0.03}, electrostriction={"epsilon_per_um": 0.004})
    r, d = _fit(truth, dict(gain_drift={"rate_per_s": 0.0}, electrostriction={"epsilon_per_um": 0.0}))
    assert d["gain_drift"]["rate_per_s"] == pytest.approx(0.03, rel=0.02)
    assert d["electrostriction"]["epsilon_per_um"] == pytest.approx(0.004, rel=0.02)
    assert r.rms_um < 1.5 * NOISE


def test_fit_recovers_pickup_amplitudes():
    truth = dict(pickup={"line_hz": 50.0, "sin_um": [0.08, 0.0, -0.02], "cos_um": [0.03, 0.015, 0.0]})
    start = dict(pickup={"line_hz": 50.0, "sin_um": [0.0] * 3, "cos_um": [0.0] * 3})
    r, d = _fit(truth, start)
    got = np.r_[d["pickup"]["sin_um"], d["pickup"]["cos_um"]]
    np.testing.assert_allclose(got, [0.08, 0.0, -0.02, 0.03, 0.015, 0.0], atol=5e-4)
    assert r.rms_um < 1.5 * NOISE


def test_fit_recovers_the_saturation_levels():
    # Both levels reached by the record (x spans 2.5 … 18 µm unclipped).
    truth = dict(saturation={"min_um": 3.0, "max_um": 15.0})
    r, d = _fit(truth, dict(saturation={"min_um": 2.7, "max_um": 15.4}))
    assert d["saturation"]["min_um"] == pytest.approx(3.0, abs=2e-3)
    assert d["saturation"]["max_um"] == pytest.approx(15.0, abs=2e-3)
    assert r.rms_um < 1.5 * NOISE


def test_fit_recovers_a_second_mode():
    truth = dict(resonance={"fn_hz": 80.0, "zeta": 0.1}, resonance2={"fn_hz": 250.0, "zeta": 0.05})
    start = dict(resonance={"fn_hz": 90.0, "zeta": 0.15}, resonance2={"fn_hz": 230.0, "zeta": 0.08})
    t = np.arange(3000) * DT
    u = 50 + 40 * signal.chirp(t, 1.0, t[-1], 300.0)  # excites both modes
    r, d = _fit(truth, start, u=u)
    assert d["resonance"]["fn_hz"] == pytest.approx(80.0, rel=0.01)
    assert d["resonance2"]["fn_hz"] == pytest.approx(250.0, rel=0.01)
    assert d["resonance"]["zeta"] == pytest.approx(0.1, rel=0.1)
    assert d["resonance2"]["zeta"] == pytest.approx(0.05, rel=0.1)
    assert r.rms_um < 1.5 * NOISE
