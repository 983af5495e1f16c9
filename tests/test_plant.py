"""The simulated piezo bench (boucwen.plant)."""

import dataclasses
import math

import numpy as np
import pytest

from boucwen import plant
from boucwen.plant import BenchSettings, paper_input

DT = 1e-4


# ----------------------------------------------------------------------------- no extension needed

def test_paper_input_segments_and_continuity():
    t, u, segments = paper_input(DT)
    assert [f for f, _, _ in segments] == [1.0, 10.0, 100.0, 200.0]
    assert [(lo, hi) for _, lo, hi in segments] == [
        (0, 30000), (30000, 33000), (33000, 33300), (33300, 33801)]
    assert t.shape == u.shape == (33801,)
    assert t[-1] == pytest.approx(3.38)
    np.testing.assert_allclose(np.diff(t), DT, rtol=1e-9)
    assert u.min() >= 0.0 and u.max() <= 100.0
    assert u.max() == pytest.approx(100.0, abs=1e-9)
    # every switch is on a minimum and u has no jump there
    steepest = 50 * 2 * math.pi * 200 * DT  # largest step within the 200 Hz part [V]
    for (f_prev, _, _), (_, lo, _) in zip([(None, 0, 0)] + segments[:-1], segments):
        assert u[lo] == pytest.approx(0.0, abs=1e-9)
        if lo:  # one sample before the switch the previous sine is just short of its minimum
            assert u[lo - 1] == pytest.approx(50 * (1 - math.cos(2 * math.pi * f_prev * DT)),
                                              rel=1e-6)
    assert np.abs(np.diff(u)).max() <= steepest * (1 + 1e-9)
    assert u[-1] == pytest.approx(0.0, abs=1e-9)


def test_paper_input_formula():
    t, u, _ = paper_input(DT)
    k = np.arange(0, 30000, 997)
    np.testing.assert_allclose(u[k], 50 + 50 * np.sin(2 * np.pi * t[k] - np.pi / 2), atol=1e-9)
    k = np.arange(33300, 33801, 7)
    np.testing.assert_allclose(u[k], 50 + 50 * np.sin(2 * np.pi * 200 * (t[k] - 3.33) - np.pi / 2),
                               atol=1e-9)


def test_paper_input_custom_and_invalid():
    t, u, seg = paper_input(1e-3, [(1.0, 2.0), (200.0, 0.02)])
    assert seg == [(1.0, 0, 2000), (200.0, 2000, 2021)]
    _, _, seg2 = paper_input(1e-3, {1.0: 2.0, 200.0: 0.02})
    assert seg2 == seg
    with pytest.raises(ValueError, match="whole"):
        paper_input(DT, [(1.0, 3.0), (200.0, 0.0525)])
    with pytest.raises(ValueError, match="dt"):
        paper_input(0.0)
    with pytest.raises(ValueError, match="> 0"):
        paper_input(DT, [(-1.0, 1.0)])


def test_settings_defaults_and_dict():
    s = BenchSettings()
    assert (s.kv, s.x0, s.A, s.beta, s.gamma, s.n, s.delta) == (
        0.19, 0.015, -0.072, 0.020, -0.019, 1.52, 0.0075)
    d = s.to_dict()
    assert d["creep_tau_s"] == [0.01, 0.1, 1.0, 10.0]
    assert set(d) == {f.name for f in dataclasses.fields(BenchSettings)}
    assert BenchSettings(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}) == s
    assert s.adc_lsb_v == pytest.approx(100.0 / 65535)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.kv = 0.2


@pytest.mark.parametrize("change", [
    {"amplifier_fc_hz": 0.0}, {"creep_tau_s": (0.1,)}, {"creep_tau_s": (0.0, 1, 2, 3)},
    {"noise_um": -1.0}, {"oversample": 0}, {"adc_bits": 40}, {"n": 0.0}, {"kv": math.nan},
    {"adc_min_v": 100.0},
])
def test_settings_rejects(change):
    with pytest.raises(ValueError):
        BenchSettings(**change)


def test_lowpass_is_exact_for_a_ramp_and_has_first_order_gain():
    tau, step = 3e-4, 2.5e-5
    t = np.arange(4001) * step
    y = plant._lowpass(7.0 * t, tau, step, 0.0)
    np.testing.assert_allclose(y, 7.0 * (t - tau * (1 - np.exp(-t / tau))), atol=1e-12)
    f = 200.0
    t = np.arange(200001) * step
    y = plant._lowpass(np.sin(2 * np.pi * f * t), tau, step, 0.0)
    gain = np.ptp(y[-int(1 / f / step):]) / 2
    assert gain == pytest.approx(1 / math.hypot(1, 2 * np.pi * f * tau), rel=1e-3)


# ----------------------------------------------------------------------------- with the extension

@pytest.fixture(scope="module")
def bench():
    pytest.importorskip("boucwen._core")
    t, u, segments = paper_input(DT)
    rec = plant.measure(u, DT, seed=0)
    return u, segments, rec


def _last_period(segments, f_wanted, size):
    for f, lo, hi in segments:
        if f == f_wanted:
            end = hi if hi < size else hi - 1
            return slice(end - int(round(1 / f / DT)), end + 1)
    raise KeyError(f_wanted)


def test_measure_record(bench):
    u, _, rec = bench
    assert rec.name == "bench" and len(rec) == u.size and rec.dt == DT
    assert rec.meta["settings"] == BenchSettings().to_dict()
    assert rec.meta["seed"] == 0
    np.testing.assert_array_equal(rec.meta["u_command"], u)
    # the bench spans about 0 … 18 µm (paper: about 0 … 17.6 µm for the 1 Hz model)
    assert -0.5 < rec.x.min() < 0.5 and 16 < rec.x.max() < 20


def test_quantisation(bench):
    u, _, rec = bench
    steps = rec.x / 0.002
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)  # 2 nm resolution
    lsb = 100.0 / 65535
    codes = rec.u / lsb
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-6)  # 16-bit A/D over 0…100 V
    assert np.abs(rec.u - u).max() <= lsb / 2 * (1 + 1e-9)
    noise = rec.x - rec.meta["x_true"]
    assert 0.8e-3 < noise.std() < 1.3e-3  # 1 nm noise + 2 nm steps [µm]
    assert np.abs(noise).max() < 0.01


def test_noise_free_output_is_deterministic(bench):
    u, _, rec = bench
    x1 = plant.true_displacement(u, DT)
    x2 = plant.true_displacement(u, DT, BenchSettings())
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(x1, rec.meta["x_true"])


def test_seed_reproducibility(bench):
    u, _, rec = bench
    again = plant.measure(u, DT, seed=0)
    np.testing.assert_array_equal(again.x, rec.x)
    np.testing.assert_array_equal(again.u, rec.u)
    other = plant.measure(u, DT, seed=1)
    assert not np.array_equal(other.x, rec.x)
    np.testing.assert_array_equal(other.meta["x_true"], rec.meta["x_true"])


def test_noise_and_quantisers_can_be_switched_off(bench):
    u, _, rec = bench
    clean = BenchSettings(noise_um=0.0, resolution_um=0.0, adc_bits=0)
    r = plant.measure(u, DT, clean, seed=3)
    np.testing.assert_array_equal(r.x, rec.meta["x_true"])
    np.testing.assert_array_equal(r.u, u)


def test_lag_shrinks_the_loop_at_200_hz_not_at_1_hz(bench):
    u, segments, rec = bench
    no_lag = plant.true_displacement(u, DT, BenchSettings(amplifier_fc_hz=math.inf))
    x = rec.meta["x_true"]
    fc = BenchSettings().amplifier_fc_hz
    p1 = _last_period(segments, 1.0, u.size)
    p200 = _last_period(segments, 200.0, u.size)
    ratio_1 = np.ptp(x[p1]) / np.ptp(no_lag[p1])
    ratio_200 = np.ptp(x[p200]) / np.ptp(no_lag[p200])
    assert ratio_1 == pytest.approx(1.0, abs=2e-3)
    assert ratio_200 < 0.98
    assert np.ptp(x[p200]) < np.ptp(x[p1]) - 0.5
    # the applied voltage is the command through a first-order lag
    ua = rec.meta["u_applied"][p200]
    assert np.ptp(ua) / 100.0 == pytest.approx(1 / math.hypot(1, 200 / fc), rel=5e-3)


def test_creep_follows_its_elements():
    pytest.importorskip("boucwen._core")
    dt = 1e-3
    u = np.full(30001, 100.0)
    u[0] = 0.0  # a 100 V step, ramped over the first millisecond
    s = BenchSettings()
    creep = plant.measure(u, dt, s).meta["creep"]
    t = np.arange(u.size) * dt
    want = sum(g * 100.0 * (1 - np.exp(-(t - dt / 2) / tau))
               for tau, g in zip(s.creep_tau_s, s.creep_gain_um_per_v))
    k = t >= 0.5
    np.testing.assert_allclose(creep[k], want[k], rtol=2e-3)
    # a few percent of the stroke over seconds
    stroke = 100.0 * s.kv
    assert 0.01 < (creep[np.searchsorted(t, 10.0)] - creep[np.searchsorted(t, 0.1)]) / stroke < 0.06


def test_oversampling_converges(bench):
    u, _, rec = bench
    fine = plant.true_displacement(u, DT, BenchSettings(oversample=16))
    assert np.abs(fine - rec.meta["x_true"]).max() < 0.01  # µm
